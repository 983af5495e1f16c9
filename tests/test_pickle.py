"""State survives a restart: Identifier, Model and Params pickle, and a restored
object continues bit for bit like the original."""

from __future__ import annotations

import contextlib
import copy
import pickle

import numpy as np
import pytest

import boucwen
from boucwen import Identifier, Model, Params
from conftest import make_identifier

DT = 1e-4


def _record(n: int = 12_000) -> tuple[np.ndarray, np.ndarray]:
    u = np.asarray(boucwen.paper_input(DT, 0.05))[:n]
    x, _ = boucwen.simulate(Params.paper_1hz(), u, DT)
    rng = np.random.default_rng(3)
    return u, x + 1e-3 * rng.standard_normal(u.size)


def _methods() -> list[str]:
    """The online methods this build offers (probing keeps the test valid as methods are added)."""
    found = []
    for method in ("paper", "rpem"):
        try:
            make_identifier(method, DT, 64, Params.paper_1hz())
        except ValueError:
            continue
        found.append(method)
    return found


@pytest.mark.parametrize("cut", [0, 1, 2, 3, 500, 1001, 1002, 2003, 9_999])
def test_unpickled_identifier_continues_bit_for_bit(cut: int) -> None:
    u, x = _record()
    original = Identifier.paper(DT, 1000, Params.paper_1hz(), h0=0.05)
    original.push_many(u[:cut], x[:cut])
    data = pickle.dumps(original, protocol=pickle.HIGHEST_PROTOCOL)
    restored = pickle.loads(data)
    assert isinstance(restored, Identifier)
    assert restored.params == original.params
    assert restored.h == original.h
    assert restored.status == original.status
    # One-by-one on the original, in one call on the copy: identical bits.
    a = np.array([original.push(float(uk), float(xk)) for uk, xk in zip(u[cut:], x[cut:])])
    b = restored.push_many(u[cut:], x[cut:])
    np.testing.assert_array_equal(a.view(np.uint64), b.view(np.uint64))
    assert restored.params == original.params
    assert pickle.dumps(restored) == pickle.dumps(original)


def _rpem(with_effects: bool) -> Identifier:
    """An rpem identifier with a tuning of its own, and optionally an input lag and creep."""
    extra = {}
    if with_effects:
        extra["effects"] = boucwen.EffectSet(
            input_lag={"fc_hz": 800.0}, creep={"tau_s": [0.01, 0.3], "gain_um_per_v": [0.001, 0.0005]}
        )
    return make_identifier(
        "rpem",
        DT,
        16,
        Params.paper_1hz().replace(n=1.7),
        h0=0.05,
        memory_travel_v=800.0,
        offset_walk_um=0.02,
        noise_um2=2e-4,
        **extra,
    )


@pytest.mark.parametrize("with_effects", [False, True], ids=["base", "lag+creep"])
@pytest.mark.parametrize("cut", [0, 1, 2, 3, 1001, 9_999])
def test_unpickled_rpem_identifier_continues_bit_for_bit(cut: int, with_effects: bool) -> None:
    u, x = _record()
    original = _rpem(with_effects)
    original.push_many(u[:cut], x[:cut])
    data = pickle.dumps(original, protocol=pickle.HIGHEST_PROTOCOL)
    restored = pickle.loads(data)
    assert isinstance(restored, Identifier) and restored.method == "rpem"
    assert restored.params == original.params
    assert restored.effects == original.effects
    assert restored.h == original.h
    assert restored.status == original.status
    a = np.array([original.push(float(uk), float(xk)) for uk, xk in zip(u[cut:], x[cut:])])
    b = restored.push_many(u[cut:], x[cut:])
    np.testing.assert_array_equal(a.view(np.uint64), b.view(np.uint64))
    assert restored.params == original.params
    assert restored.effects == original.effects
    assert pickle.dumps(restored) == pickle.dumps(original)


def test_rpem_snapshot_keeps_the_configuration() -> None:
    # A restored identifier with another tuning would drift apart from the original.
    u, x = _record(4000)
    tuned = make_identifier("rpem", DT, 16, Params.paper_1hz(), max_step=0.002, p0=1e-4)
    tuned.push_many(u[:2000], x[:2000])
    restored = pickle.loads(pickle.dumps(tuned))
    default = make_identifier("rpem", DT, 16, Params.paper_1hz())
    default.push_many(u[:2000], x[:2000])
    assert pickle.dumps(default) != pickle.dumps(tuned)
    y_tuned, y_restored = tuned.push_many(u[2000:], x[2000:]), restored.push_many(u[2000:], x[2000:])
    np.testing.assert_array_equal(y_tuned, y_restored)
    assert not np.array_equal(y_restored, default.push_many(u[2000:], x[2000:]))


@pytest.mark.parametrize("with_effects", [False, True], ids=["base", "lag+creep"])
def test_rpem_truncated_and_flipped_snapshots_never_crash(with_effects: bool) -> None:
    u, x = _record(2000)
    ident = _rpem(with_effects)
    ident.push_many(u, x)
    restore, (data,) = ident.__reduce__()
    assert restore(data).params == ident.params
    for end in range(0, len(data), 13):
        with pytest.raises(ValueError, match="snapshot"):
            restore(data[:end])
    with pytest.raises(ValueError, match="snapshot"):
        restore(data + b"\x00")
    rng = np.random.default_rng(1)
    for _ in range(300):
        flipped = bytearray(data)
        flipped[int(rng.integers(len(data)))] ^= 1 << int(rng.integers(8))
        try:
            restored = restore(bytes(flipped))
        except ValueError:
            continue
        restored.push_many(u[:50], x[:50])  # a valid, different state keeps running


@pytest.mark.parametrize("method", _methods())
def test_copy_and_deepcopy_are_independent(method: str) -> None:
    u, x = _record(3000)
    original = make_identifier(method, DT, 500, Params.paper_1hz())
    original.push_many(u[:1500], x[:1500])
    for clone in (copy.copy(original), copy.deepcopy(original)):
        assert clone is not original
        y1 = clone.push_many(u[1500:], x[1500:])
        assert original.status.samples == 1500
        y2 = copy.copy(original).push_many(u[1500:], x[1500:])
        np.testing.assert_array_equal(y1, y2)


@pytest.mark.parametrize("method", ["paper", "rpem"])
def test_every_method_pickles(method: str) -> None:
    assert method in _methods()
    restored = pickle.loads(pickle.dumps(make_identifier(method, DT, 64, Params.paper_1hz())))
    assert restored.method == method


def test_model_pickle_continues_bit_for_bit() -> None:
    u, _ = _record(5000)
    original = Model(Params.paper_1hz(), DT, h0=0.2)
    for v in u[:2500]:
        original.step(float(v))
    restored = pickle.loads(pickle.dumps(original))
    assert restored.h == original.h and restored.dt == original.dt and restored.params == original.params
    for v in u[2500:]:
        assert original.step(float(v)) == restored.step(float(v))
    fresh = pickle.loads(pickle.dumps(Model(Params.paper_1hz(), DT)))
    assert fresh.step(10.0) == Model(Params.paper_1hz(), DT).step(10.0)


def test_params_pickle_round_trips() -> None:
    p = Params(0.2, -0.01, -0.07, 0.02, -0.019, 1.5, 0.0075)
    assert pickle.loads(pickle.dumps(p)) == p


@pytest.mark.parametrize(
    "garbage",
    [b"", b"BWSN", b"not a snapshot at all", b"BWSN\x01\x02" + b"\x00" * 10, b"BWSN\x09\x02" + b"\x00" * 400],
)
def test_corrupt_snapshot_is_a_value_error(garbage: bytes) -> None:
    with pytest.raises(ValueError, match="snapshot"):
        Identifier._from_snapshot(garbage)


def test_truncated_and_flipped_snapshots_never_crash() -> None:
    u, x = _record(2000)
    ident = Identifier.paper(DT, 300, Params.paper_1hz())
    ident.push_many(u, x)
    restore, (data,) = ident.__reduce__()
    assert restore(data).params == ident.params
    for end in range(0, len(data), 37):
        with pytest.raises(ValueError):
            restore(data[:end])
    rng = np.random.default_rng(0)
    for _ in range(200):
        flipped = bytearray(data)
        flipped[int(rng.integers(len(data)))] ^= 1 << int(rng.integers(8))
        with contextlib.suppress(ValueError):  # a flipped bit in a float is a valid, different state
            restore(bytes(flipped))
    with pytest.raises(TypeError):
        restore("a string")
