"""The hysteretic oscillator (boucwen.oscillator): the input between samples (the
band-limited path against the Fourier interpolation and the stated bound), argument
checks, the Jacobian, the fit on generated records, weights, and the benchmark command on
a short generated record. The simulator against a converged reference is
rust/tests/oscillator_reference.rs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from boucwen import _core, oscillator
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


# The simulator's accuracy is proven against a converged reference (event-located RK4 at
# 128x the rate) in rust/tests/oscillator_reference.rs: within 1e-6 of the displacement
# range for each of hold, linear and band-limited.


def test_the_band_limited_force_of_a_periodic_record_is_its_fourier_interpolation():
    force = multisine(512, 2, seed=9)
    path = _core.InputPath(force, "bandlimited", periodic=True)
    values = path.values(8)
    # The trigonometric polynomial through the samples, on a grid 8 times finer.
    spectrum = np.fft.rfft(force)
    fine = np.fft.irfft(spectrum, n=8 * force.size) * 8
    np.testing.assert_allclose(values, fine[: values.size], rtol=0, atol=1e-9 * np.max(np.abs(force)))
    assert path.band * (1 / DT) == pytest.approx(150.0, abs=2.0)
    hold = _core.InputPath(force, "hold").values(4)
    assert np.array_equal(hold[1:5], np.repeat(force[0], 4)) and hold[5] == force[1]


def test_a_record_that_is_not_periodic_is_rebuilt_within_the_stated_bound():
    t = np.arange(600) * DT
    f = np.sin(2 * np.pi * 37.3 * t) + 0.4 * np.cos(2 * np.pi * 121.7 * t + 0.3)
    path = _core.InputPath(f, "bandlimited", periodic=False)
    fine_t = np.arange((f.size - 1) * 8 + 1) * DT / 8
    exact = np.sin(2 * np.pi * 37.3 * fine_t) + 0.4 * np.cos(2 * np.pi * 121.7 * fine_t + 0.3)
    inner = slice(32 * 8, (f.size - 32) * 8)
    bound = _core.bandlimited_error_bound(121.7 / 375.0) * 1.4
    assert np.max(np.abs(path.values(8) - exact)[inner]) <= bound


def test_the_inputs_between_samples_differ_as_they_should():
    force = multisine(1024, 2, seed=4)
    y = {
        name: oscillator.simulate(TRUE, force, DT, input=name, periodic=True)
        for name in ("hold", "linear", "bandlimited")
    }
    span = np.ptp(y["linear"])
    # A hold is about half a sample late: far off the others; linear and band-limited
    # differ by the curvature of the force between samples, a few 1e-3 of the range.
    assert np.max(np.abs(y["hold"] - y["linear"])) > 0.05 * span
    assert 1e-4 * span < np.max(np.abs(y["bandlimited"] - y["linear"])) < 2e-2 * span
    with pytest.raises(ValueError, match="hold"):
        oscillator.simulate(TRUE, force, DT, input="cubic")
    path = _core.InputPath(force, "bandlimited", periodic=True)
    assert np.array_equal(_core.oscillator_simulate(TRUE.to_list(), path, DT), y["bandlimited"])
    with pytest.raises(ValueError, match="InputPath"):
        _core.oscillator_simulate(TRUE.to_list(), path, DT, input="linear")


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
    for chain in ({"input": "linear"}, {"input": "bandlimited", "periodic": True}):
        y, jac = _core.oscillator_simulate_with_jacobian(TRUE.to_list(), force, DT, **chain)
        assert jac.shape == (force.size, len(oscillator.UNKNOWNS)) and oscillator.UNKNOWNS[0] == "m"
        assert np.array_equal(y, oscillator.simulate(TRUE, force, DT, **chain))
        for j, name in enumerate(("m", "c", "k", "alpha", "gamma", "delta")):
            eps = 1e-7 * abs(getattr(TRUE, name))
            shifted = [OscillatorParams(**{**TRUE.to_dict(), name: getattr(TRUE, name) + d * eps}) for d in (1, -1)]
            up, down = (oscillator.simulate(q, force, DT, **chain) for q in shifted)
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
    chain = {"input": "bandlimited", "periodic": True, "output": bouc_wen_benchmark.benchmark_chain()}
    y = oscillator.simulate(TRUE, force, DT, **chain) + noise * np.random.default_rng(5).standard_normal(force.size)
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
    # The record was made with the chain: the noise-aware bound is a fraction of the
    # noise; the baseline (force linear, no filter) leaves its own error of the chain.
    aware = doc["fits"]["chain"]["noise_aware"]
    assert aware["model_rms_upper_m"] < 0.5 * noise
    assert doc["fits"]["baseline"]["noise_aware"]["model_rms_m"] > aware["model_rms_upper_m"]
    assert set(doc["fit"]["std_errors"]) == set(oscillator.UNKNOWNS)
    assert (out / "held_out.png").stat().st_size > 0
    assert "PNLSS" in printed and "another record" in printed and "noise taken out" in printed


def test_the_benchmark_command_without_its_data_says_so_in_one_line(tmp_path, capsys):
    status = bouc_wen_benchmark.main(["--data", str(tmp_path / "absent.csv"), "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and "absent.csv" in err and "Traceback" not in err
