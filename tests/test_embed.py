"""The channel bank from Python, and the C interface: its example program, compiled with
the system C compiler, gives the Python results to the last bit on the same record."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import boucwen
from boucwen import Bank, Identifier, Inverse, Model, Params

ROOT = Path(__file__).resolve().parent.parent
DT = 1e-4
PAPER = Params.paper_1hz()


def _record(channels: int, frames: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(T, C) voltages and measurements: the paper input, offset per channel, through a
    model with per-channel parameters, plus 1–5 nm of noise."""
    rng = np.random.default_rng(seed)
    base = boucwen.paper_input(DT, 0.05)
    u = np.empty((frames, channels))
    x = np.empty((frames, channels))
    for c in range(channels):
        start = (c * 977) % (base.size - frames)
        u[:, c] = base[start : start + frames] * (1.0 - 0.02 * c)
        p = PAPER.replace(kv=0.19 + 0.005 * c)
        x[:, c] = boucwen.simulate(p, u[:, c], DT)[0] + rng.normal(0.0, 1e-3 + 1e-3 * (c % 5), frames)
    return u, x


@pytest.mark.parametrize("method", ["rpem", "paper"])
def test_each_bank_channel_equals_a_single_identifier_bit_for_bit(method):
    u, x = _record(4, 3000)
    if method == "rpem":
        bank = Bank(4, DT, PAPER)
        single = [Identifier.rpem(DT, PAPER) for _ in range(4)]
    else:
        bank = Bank.paper(4, DT, 300, PAPER)
        single = [Identifier.paper(DT, 300, PAPER) for _ in range(4)]
    assert (bank.method, bank.channels) == (method, 4)
    head = np.stack([bank.push(u[t], x[t]) for t in range(10)])
    rest = bank.push_many(u[10:], x[10:])
    got = np.concatenate([head, rest])
    assert got.shape == u.shape
    for c in range(4):
        want = single[c].push_many(u[:, c], x[:, c])
        np.testing.assert_array_equal(got[:, c], want)
        assert bank.params(c) == single[c].params


def test_bank_models_equal_single_models_and_adopt_the_estimates():
    u, x = _record(3, 2000)
    bank = Bank(3, DT, PAPER)
    xm = bank.step_models_many(u)
    for c in range(3):
        model = Model(PAPER, DT)
        np.testing.assert_array_equal(xm[:, c], [model.step(float(v)) for v in u[:, c]])
    bank.push_many(u, x)
    bank.adopt_estimates()
    assert all(bank.model_params(c) == bank.params(c) for c in range(3))
    assert bank.model_params(0) != PAPER


def test_bank_rejects_bad_frames_and_keeps_its_state():
    u, x = _record(2, 100)
    bank = Bank(2, DT, PAPER)
    bank.push_many(u[:50], x[:50])
    bad = u[50:60].copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        bank.push_many(bad, x[50:60])
    with pytest.raises(ValueError, match="shape"):
        bank.push_many(u[50:60, :1], x[50:60, :1])
    with pytest.raises(ValueError):
        bank.push([1.0, 2.0, 3.0], [0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="channels"):
        Bank(0, DT, PAPER)
    with pytest.raises(IndexError):
        bank.params(2)
    twin = Bank(2, DT, PAPER)
    twin.push_many(u[:50], x[:50])
    np.testing.assert_array_equal(bank.push_many(u[50:], x[50:]), twin.push_many(u[50:], x[50:]))


def test_bank_feedforward_is_a_single_inverse_per_channel():
    u, x = _record(3, 2000, seed=5)
    bank = Bank(3, DT, PAPER)
    bank.set_voltage_limits(0.0, 100.0)
    singles = [Inverse(PAPER, DT, u_min=0.0, u_max=100.0) for _ in range(3)]
    for t in range(u.shape[0]):
        bank.push(u[t], x[t])
        if t == 999:
            bank.adopt_estimates()
            for c, single in enumerate(singles):
                assert bank.inverse_params(c) == bank.params(c)  # admissible here: adopted
                single.set_params(bank.inverse_params(c))
        expected = [single.step(float(v)) for single, v in zip(singles, x[t])]
        np.testing.assert_array_equal(bank.feedforward(x[t]), expected)
    assert bank.inverse_params(1) != PAPER  # the inverses took the estimates
    with pytest.raises(ValueError, match="x_d"):
        bank.feedforward([1.0, float("nan"), 2.0])
    with pytest.raises(ValueError):
        bank.set_voltage_limits(10.0, 0.0)


# -- the C interface ------------------------------------------------------------------


@pytest.fixture(scope="module")
def c_example(tmp_path_factory) -> Path:
    cc = shutil.which(os.environ.get("CC", "cc"))
    cargo = shutil.which("cargo")
    if cc is None or cargo is None:
        pytest.skip("needs a C compiler and cargo")
    # The C library in the cargo profile of $BOUCWEN_CARGO_PROFILE (scripts/test.sh: the one its
    # Rust tests were built in, so this build is theirs; default release).
    profile = os.environ.get("BOUCWEN_CARGO_PROFILE", "release")
    subprocess.run([cargo, "build", "--profile", profile, "--features", "ffi", "--lib"], cwd=ROOT, check=True)
    lib = ROOT / "target" / profile
    exe = tmp_path_factory.mktemp("c") / "identify"
    subprocess.run(
        [
            cc,
            "-O2",
            "-Wall",
            "-Wextra",
            "-Werror",
            f"-I{ROOT / 'include'}",
            str(ROOT / "examples/c/identify.c"),
            f"-L{lib}",
            "-lboucwen",
            f"-Wl,-rpath,{lib}",
            "-o",
            str(exe),
        ],
        check=True,
    )
    return exe


def test_c_example_matches_python_to_the_last_bit(c_example, tmp_path):
    u, x = _record(1, 4000, seed=11)
    u, x = u[:, 0], x[:, 0]
    record = tmp_path / "record.txt"
    record.write_text("".join(f"{a!r} {b!r}\n" for a, b in zip(u.tolist(), x.tolist())))
    run = subprocess.run([str(c_example), str(record)], capture_output=True, text=True, check=True)
    lines = run.stdout.splitlines()
    table = np.array([[float(v) for v in line.split()] for line in lines[:-2]])
    estimates = [float(v) for v in lines[-2].split()]
    horizon_estimates = [float(v) for v in lines[-1].split()]

    model = Model(PAPER, DT)
    np.testing.assert_array_equal(table[:, 0], [model.step(float(v)) for v in u])
    rpem = Identifier.rpem(DT, PAPER)
    np.testing.assert_array_equal(table[:, 1], rpem.push_many(u, x))
    paper = Identifier.paper(DT, 200, PAPER)
    np.testing.assert_array_equal(table[:, 2], paper.push_many(u, x))
    bank = Bank(3, DT, PAPER)
    scale = 1.0 - 0.1 * np.arange(3)
    bu = u[:, None] * scale[None, :]
    bx = x[:, None] + 0.01 * np.arange(3)[None, :]
    np.testing.assert_array_equal(table[:, 3:6], bank.push_many(bu, bx))
    np.testing.assert_array_equal(estimates, rpem.params.to_array())
    horizon = Identifier(DT, PAPER)  # the recommended model, lag from fc = 0.3/dt
    np.testing.assert_array_equal(table[:, 6], horizon.push_many(u, x))
    fc = horizon.effects.to_dict()["input_lag"]["fc_hz"]
    np.testing.assert_array_equal(horizon_estimates, [*horizon.params.to_array(), fc])
    inverse = Inverse(PAPER, DT)
    np.testing.assert_array_equal(table[:, 7], [inverse.step(float(v)) for v in x])
