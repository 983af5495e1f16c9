"""The hysteretic oscillator (boucwen.oscillator): the core against a fine-step reference
written here, argument checks, the fit on generated records, weights, and the benchmark
command on a short generated record."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from boucwen import _core, datasets, oscillator
from boucwen.experiments import bouc_wen_benchmark
from boucwen.oscillator import OscillatorParams

DT = 1.0 / 750.0
TRUE = OscillatorParams.benchmark()


def multisine(period: int, periods: int, seed: int = 1, rms: float = 50.0) -> np.ndarray:
    """A random-phase multisine [N] with lines from 5 to 150 Hz, ``periods`` periods."""
    rng = np.random.default_rng(seed)
    lines = np.arange(max(1, round(5.0 * period * DT)), round(150.0 * period * DT) + 1)
    spectrum = np.zeros(period // 2 + 1, dtype=complex)
    spectrum[lines] = np.exp(2j * np.pi * rng.random(lines.size))
    one = np.fft.irfft(spectrum, n=period)
    return np.tile(one * rms / np.sqrt(np.mean(one**2)), periods)


def rk4_reference(p: OscillatorParams, force: np.ndarray, dt: float, fine: int = 20) -> np.ndarray:
    """Plain RK4 at ``fine`` × the rate, F linearly interpolated: an independent
    reference (Python floats, no sub-step rule)."""
    m, c, k, a, b, g, d, nu = p.to_list()

    def rate(y: float, v: float, z: float, f: float) -> tuple[float, float, float]:
        zn = abs(z) ** nu
        zdot = a * v - b * (g * abs(v) * abs(z) ** (nu - 1.0) * z + d * v * zn)
        return v, (f - c * v - k * y - z) / m, zdot

    h = dt / fine
    y = v = z = 0.0
    out = [0.0]
    for f0, f1 in zip(force[:-1].tolist(), force[1:].tolist()):
        for i in range(fine):
            fa = f0 + (f1 - f0) * i / fine
            fm = f0 + (f1 - f0) * (i + 0.5) / fine
            fb = f0 + (f1 - f0) * (i + 1) / fine
            k1 = rate(y, v, z, fa)
            k2 = rate(y + 0.5 * h * k1[0], v + 0.5 * h * k1[1], z + 0.5 * h * k1[2], fm)
            k3 = rate(y + 0.5 * h * k2[0], v + 0.5 * h * k2[1], z + 0.5 * h * k2[2], fm)
            k4 = rate(y + h * k3[0], v + h * k3[1], z + h * k3[2], fb)
            y += h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            v += h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            z += h / 6.0 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
        out.append(y)
    return np.array(out)


# Plain RK4 is second order across the kinks of |ẏ| and |z|: the 20×-rate reference is
# itself about 2e-5 of the range from the converged solution (the core, which takes the
# kinks in pieces, 3e-5).
REFERENCE_TOLERANCE = 1e-4


def _agreement(force: np.ndarray) -> float:
    y = oscillator.simulate(TRUE, force, DT)
    ref = rk4_reference(TRUE, force, DT)
    return float(np.max(np.abs(y - ref)) / np.ptp(ref))


def test_the_core_agrees_with_a_fine_step_rk4_on_a_generated_multisine():
    worst = _agreement(multisine(2048, 2))
    print(f"max deviation from RK4 at 20x the rate: {worst:.2e} of the range")
    assert worst <= REFERENCE_TOLERANCE


def test_the_core_agrees_with_a_fine_step_rk4_on_the_training_records_input():
    if not _training_available():
        pytest.skip("the Bouc-Wen benchmark's training record is not on this machine")
    force = datasets.load_bouc_wen().force[:4096]
    worst = _agreement(force)
    print(f"max deviation from RK4 at 20x the rate: {worst:.2e} of the range")
    assert worst <= REFERENCE_TOLERANCE


def _training_available() -> bool:
    try:
        datasets.find_bouc_wen()
    except FileNotFoundError:
        return False
    return True


@pytest.mark.parametrize(
    "name, value",
    [("m", 0.0), ("c", -1.0), ("k", -1.0), ("alpha", 0.0), ("beta", -1.0), ("gamma", math.nan), ("nu", 0.5)],
)
def test_bad_parameters_raise_value_error_naming_them(name, value):
    with pytest.raises(ValueError, match=rf"\b{name}\b"):
        OscillatorParams(**{**TRUE.to_dict(), name: value})
    values = {**TRUE.to_dict(), name: value}
    with pytest.raises(ValueError, match=rf"\b{name}\b"):
        _core.oscillator_simulate(list(values.values()), np.zeros(4), DT)


def test_bad_input_raises_value_error():
    force = multisine(256, 1)
    force[7] = math.nan
    with pytest.raises(ValueError, match=r"F\[7\]"):
        oscillator.simulate(TRUE, force, DT)
    with pytest.raises(ValueError, match="F = NaN"):
        _core.oscillator_simulate(TRUE.to_list(), force, DT)
    with pytest.raises(ValueError, match="dt"):
        oscillator.simulate(TRUE, np.zeros(4), 0.0)
    with pytest.raises(ValueError, match="dt"):
        _core.oscillator_simulate(TRUE.to_list(), np.zeros(4), -1.0)
    with pytest.raises(ValueError, match="8 parameters"):
        _core.oscillator_simulate(TRUE.to_list()[:7], np.zeros(4), DT)
    with pytest.raises(ValueError, match="z0"):
        _core.oscillator_simulate(TRUE.to_list(), np.zeros(4), DT, z0=math.inf)
    with pytest.raises(ValueError, match="same length"):
        oscillator.fit(np.zeros(10), np.zeros(11), DT)
    with pytest.raises(ValueError, match="weights"):
        oscillator.fit(np.zeros(10), np.zeros(10), DT, weights=np.ones(9))


def test_the_jacobian_matches_finite_differences():
    force = multisine(512, 1)
    y, jac = _core.oscillator_simulate_with_jacobian(TRUE.to_list(), force, DT)
    assert jac.shape == (force.size, len(oscillator.UNKNOWNS)) and oscillator.UNKNOWNS[0] == "m"
    assert np.array_equal(y, oscillator.simulate(TRUE, force, DT))
    for j, name in enumerate(("m", "c", "k", "alpha", "gamma", "delta")):
        eps = 1e-7 * abs(getattr(TRUE, name))
        up = oscillator.simulate(OscillatorParams(**{**TRUE.to_dict(), name: getattr(TRUE, name) + eps}), force, DT)
        down = oscillator.simulate(OscillatorParams(**{**TRUE.to_dict(), name: getattr(TRUE, name) - eps}), force, DT)
        fd = (up - down) / (2 * eps)
        assert np.median(np.abs(fd - jac[:, j])) <= 1e-4 * np.max(np.abs(jac[:, j])), name


def _record(noise: float, periods: int = 2, period: int = 2048, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    force = multisine(period, periods, seed=seed)
    y = oscillator.simulate(TRUE, force, DT)
    return force, y + noise * np.random.default_rng(seed).standard_normal(y.size)


def _products(p: OscillatorParams) -> np.ndarray:
    """What the record determines: m, c, k, α, β·γ, β·δ."""
    return np.array([p.m, p.c, p.k, p.alpha, p.beta * p.gamma, p.beta * p.delta])


def test_the_fit_recovers_the_parameters_of_a_noise_free_record():
    force, y = _record(0.0)
    result = oscillator.fit(force, y, DT)
    assert result.success
    assert result.rms <= 1e-8
    np.testing.assert_allclose(_products(result.params), _products(TRUE), rtol=1e-3)
    assert result.params.nu == pytest.approx(1.0, abs=1e-3)


def test_the_fit_on_a_noisy_record_reaches_the_noise_and_is_quick():
    noise = 1e-5
    force, y = _record(noise)
    result = oscillator.fit(force, y, DT, jacobian=True)
    assert result.success and result.seconds < 10.0
    assert result.rms <= 1.05 * noise
    np.testing.assert_allclose(_products(result.params), _products(TRUE), rtol=0.05)
    assert result.jacobian is not None and result.jacobian.shape == (force.size, 10)
    refit = oscillator.fit(force, y, DT, start=result.params)
    assert refit.params.beta == result.params.beta
    # From the fitted parameters (and a state at rest): within the statistical stop.
    assert refit.rms <= result.rms * (1 + 1e-4) and refit.nfev < result.nfev


def test_weights_leave_samples_out_of_the_cost():
    force, y = _record(1e-6)
    spoiled = y.copy()
    block = slice(1000, 1600)
    spoiled[block] += 2e-3
    weights = np.ones(y.size)
    weights[block] = 0.0
    result = oscillator.fit(force, spoiled, DT, weights=weights)
    np.testing.assert_allclose(_products(result.params), _products(TRUE), rtol=0.01)
    # The left-out block is predicted, not fitted: its error is the spoiling offset.
    assert np.mean(spoiled[block] - result.y[block]) == pytest.approx(2e-3, rel=0.01)
    assert result.rms <= 2e-6


def test_the_benchmark_command_on_a_short_generated_record(tmp_path, capsys):
    period, noise = 1024, 2e-6
    force = multisine(period, 4, seed=5)
    y = oscillator.simulate(TRUE, force, DT) + noise * np.random.default_rng(5).standard_normal(force.size)
    t = np.arange(force.size) * DT
    path = tmp_path / "record.csv"
    np.savetxt(path, np.column_stack([t, force, y]), delimiter=",", header="t_s,force_N,displacement_m", comments="")
    out = tmp_path / "out"
    status = bouc_wen_benchmark.main(["--data", str(path), "--period", str(period), "--out", str(out), "--quiet"])
    printed = capsys.readouterr().out
    assert status == 0, printed
    doc = json.loads((out / "results.json").read_text())
    assert doc["noise_rms_m"] == pytest.approx(noise, rel=0.1)
    assert doc["held_out_over_noise"] <= 1.5
    assert (out / "held_out.png").stat().st_size > 0
    assert "PNLSS" in printed and "another record" in printed


def test_the_benchmark_command_without_its_data_says_so_in_one_line(tmp_path, capsys):
    status = bouc_wen_benchmark.main(["--data", str(tmp_path / "absent.csv"), "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and "absent.csv" in err and "Traceback" not in err
