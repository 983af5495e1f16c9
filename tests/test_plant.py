"""The simulated piezo bench (boucwen.plant)."""

import dataclasses
import math

import numpy as np
import pytest

from boucwen import plant
from boucwen.plant import BenchSettings, paper_input

DT = 1e-4


# ----------------------------------------------------------------------------- no extension needed


def test_paper_input_segments_and_continuity():
    t, u, segments = paper_input(DT)
    assert [f for f, _, _ in segments] == [1.0, 10.0, 100.0, 200.0]
    assert [(lo, hi) for _, lo, hi in segments] == [(0, 30000), (30000, 33000), (33000, 33300), (33300, 33800)]
    assert t.shape == u.shape == (33800,)
    assert t[-1] == pytest.approx(3.38 - DT)
    np.testing.assert_allclose(np.diff(t), DT, rtol=1e-9)
    assert u.min() >= 0.0 and u.max() <= 100.0
    assert u.max() == pytest.approx(100.0, abs=1e-9)
    # every switch is on a minimum and u has no jump there
    steepest = 50 * 2 * math.pi * 200 * DT  # largest step within the 200 Hz part [V]
    for (f_prev, _, _), (_, lo, _) in zip([(None, 0, 0), *segments[:-1]], segments):
        assert u[lo] == pytest.approx(0.0, abs=1e-9)
        if lo:  # one sample before the switch the previous sine is just short of its minimum
            assert u[lo - 1] == pytest.approx(50 * (1 - math.cos(2 * math.pi * f_prev * DT)), rel=1e-6)
    assert np.abs(np.diff(u)).max() <= steepest * (1 + 1e-9)
    assert u[-1] == pytest.approx(50 * (1 - math.cos(2 * math.pi * 200 * DT)), rel=1e-6)  # just short of 0 V


def test_paper_input_formula():
    t, u, _ = paper_input(DT)
    k = np.arange(0, 30000, 997)
    np.testing.assert_allclose(u[k], 50 + 50 * np.sin(2 * np.pi * t[k] - np.pi / 2), atol=1e-9)
    k = np.arange(33300, 33800, 7)
    np.testing.assert_allclose(u[k], 50 + 50 * np.sin(2 * np.pi * 200 * (t[k] - 3.33) - np.pi / 2), atol=1e-9)


def test_paper_input_custom_and_invalid():
    _, _, seg = paper_input(1e-3, [(1.0, 2.0), (200.0, 0.02)])
    assert seg == [(1.0, 0, 2000), (200.0, 2000, 2020)]
    _, _, seg2 = paper_input(1e-3, {1.0: 2.0, 200.0: 0.02})
    assert seg2 == seg
    with pytest.raises(ValueError, match="whole"):
        paper_input(DT, [(1.0, 3.0), (200.0, 0.0525)])
    with pytest.raises(ValueError, match="dt"):
        paper_input(0.0)
    with pytest.raises(ValueError, match="> 0"):
        paper_input(DT, [(-1.0, 1.0)])


def test_settings_defaults_and_dict():
    s = BenchSettings()
    assert (s.kv, s.x0, s.A, s.beta, s.gamma, s.n, s.delta) == (0.19, 0.015, -0.072, 0.020, -0.019, 1.52, 0.0075)
    d = s.to_dict()
    assert d["creep_tau_s"] == [0.01, 0.1, 1.0, 10.0]
    assert d["vibration_hz"] == [17.0, 29.0] and d["vibration_um"] == [0.25, 0.2]
    assert s.stroke_quadratic_per_um == 0.004 and s.amplifier_fc_hz == 650.0
    assert set(d) == {f.name for f in dataclasses.fields(BenchSettings)}
    assert BenchSettings(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}) == s
    assert s.adc_lsb_v == pytest.approx(100.0 / 65535)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.kv = 0.2


@pytest.mark.parametrize(
    "change",
    [
        {"amplifier_fc_hz": 0.0},
        {"creep_tau_s": (0.1,)},
        {"creep_tau_s": (0.0, 1, 2, 3)},
        {"noise_um": -1.0},
        {"oversample": 0},
        {"adc_bits": 40},
        {"n": 0.0},
        {"kv": math.nan},
        {"adc_min_v": 100.0},
        {"stroke_quadratic_per_um": math.inf},
        {"stroke_quadratic_per_um": "0.004"},
        {"vibration_hz": (17.0,)},
        {"vibration_phase_rad": (0.0,)},
        {"vibration_hz": (0.0, 29.0)},
        {"vibration_um": (math.nan, 0.1)},
    ],
)
def test_settings_rejects(change):
    with pytest.raises(ValueError):
        BenchSettings(**change)


# ----------------------------------------------------------------------------- with the extension


@pytest.fixture(scope="module")
def bench():
    pytest.importorskip("boucwen._core")
    _, u, segments = paper_input(DT)
    rec = plant.measure(u, DT, seed=0)
    return u, segments, rec


def _applied_voltage(u, settings):
    """The voltage on the stack [V]: the core's chain with the bench's lag and a unit
    gain, no hysteresis (A = β = γ = δ = 0 keeps h at 0), so x = u_a."""
    from boucwen import EffectSet, Params, simulate_extended

    lag = EffectSet(input_lag={"fc_hz": settings.amplifier_fc_hz})
    return simulate_extended(Params(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0), lag, u, DT)


def _creep(u, dt, settings):
    """The creep part of the stack's displacement [µm]: the displacement less that of
    the same bench without creep (creep adds to the stack, nothing else depends on it)."""
    zero = tuple(0.0 for _ in settings.creep_gain_um_per_v)
    still = dataclasses.replace(settings, creep_gain_um_per_v=zero)
    return plant.true_displacement(u, dt, settings) - plant.true_displacement(u, dt, still)


def _last_period(segments, f_wanted, size):
    for f, _, hi in segments:
        if f == f_wanted:
            end = hi if hi < size else hi - 1
            return slice(end - round(1 / f / DT), end + 1)
    raise KeyError(f_wanted)


def test_measure_record(bench):
    u, _, rec = bench
    assert rec.name == "bench" and len(rec) == u.size and rec.dt == DT
    assert rec.meta["settings"] == BenchSettings().to_dict()
    assert rec.meta["seed"] == 0
    np.testing.assert_array_equal(rec.meta["u_command"], u)
    # the bench spans about 0 … 18 µm (paper: about 0 … 17.6 µm for the 1 Hz model)
    assert -0.5 < rec.x.min() < 0.5 and 16 < rec.x.max() < 20


def test_quantisation(bench):
    u, _, rec = bench
    steps = rec.x / 0.002
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)  # 2 nm resolution
    lsb = 100.0 / 65535
    codes = rec.u / lsb
    np.testing.assert_allclose(codes, np.round(codes), atol=1e-6)  # 16-bit A/D over 0…100 V
    assert np.abs(rec.u - u).max() <= lsb / 2 * (1 + 1e-9)
    noise = rec.x - rec.meta["x_true"] - rec.meta["vibration"]
    assert 0.8e-3 < noise.std() < 1.3e-3  # 1 nm noise + 2 nm steps [µm]
    assert np.abs(noise).max() < 0.01


def test_noise_free_output_is_deterministic(bench):
    u, _, rec = bench
    x1 = plant.true_displacement(u, DT)
    x2 = plant.true_displacement(u, DT, BenchSettings())
    np.testing.assert_array_equal(x1, x2)
    np.testing.assert_array_equal(x1, rec.meta["x_true"])


def test_seed_reproducibility(bench):
    u, _, rec = bench
    again = plant.measure(u, DT, seed=0)
    np.testing.assert_array_equal(again.x, rec.x)
    np.testing.assert_array_equal(again.u, rec.u)
    other = plant.measure(u, DT, seed=1)
    assert not np.array_equal(other.x, rec.x)
    np.testing.assert_array_equal(other.meta["x_true"], rec.meta["x_true"])


def test_noise_and_quantisers_can_be_switched_off(bench):
    u, _, rec = bench
    clean = BenchSettings(noise_um=0.0, resolution_um=0.0, adc_bits=0)
    r = plant.measure(u, DT, clean, seed=3)
    np.testing.assert_array_equal(r.x, rec.meta["x_true"] + rec.meta["vibration"])
    np.testing.assert_array_equal(r.u, u)
    still = dataclasses.replace(clean, vibration_um=(0.0, 0.0))
    r = plant.measure(u, DT, still, seed=3)
    np.testing.assert_array_equal(r.x, rec.meta["x_true"])
    np.testing.assert_array_equal(r.meta["vibration"], 0.0)
    none = dataclasses.replace(clean, vibration_hz=(), vibration_um=(), vibration_phase_rad=())
    np.testing.assert_array_equal(plant.measure(u, DT, none).x, rec.meta["x_true"])


def test_lag_shrinks_the_loop_at_200_hz_not_at_1_hz(bench):
    u, segments, rec = bench
    no_lag = plant.true_displacement(u, DT, BenchSettings(amplifier_fc_hz=math.inf))
    x = rec.meta["x_true"]
    fc = BenchSettings().amplifier_fc_hz
    p1 = _last_period(segments, 1.0, u.size)
    p200 = _last_period(segments, 200.0, u.size)
    ratio_1 = np.ptp(x[p1]) / np.ptp(no_lag[p1])
    ratio_200 = np.ptp(x[p200]) / np.ptp(no_lag[p200])
    assert ratio_1 == pytest.approx(1.0, abs=2e-3)
    assert ratio_200 < 0.98
    assert np.ptp(x[p200]) < np.ptp(x[p1]) - 0.5
    # the applied voltage is the command through a first-order lag
    ua = _applied_voltage(u, BenchSettings())[p200]
    assert np.ptp(ua) / 100.0 == pytest.approx(1 / math.hypot(1, 200 / fc), rel=5e-3)


def test_creep_follows_its_elements():
    pytest.importorskip("boucwen._core")
    dt = 1e-3
    u = np.full(30001, 100.0)
    u[0] = 0.0  # a 100 V step, ramped over the first millisecond
    s = BenchSettings()
    creep = _creep(u, dt, s)
    t = np.arange(u.size) * dt
    want = sum(g * 100.0 * (1 - np.exp(-(t - dt / 2) / tau)) for tau, g in zip(s.creep_tau_s, s.creep_gain_um_per_v))
    k = t >= 0.5
    np.testing.assert_allclose(creep[k], want[k], rtol=2e-3)
    # a few percent of the stroke over seconds
    stroke = 100.0 * s.kv
    assert 0.01 < (creep[np.searchsorted(t, 10.0)] - creep[np.searchsorted(t, 0.1)]) / stroke < 0.06


def test_oversampling_converges(bench):
    u, _, rec = bench
    fine = plant.true_displacement(u, DT, BenchSettings(oversample=16))
    assert np.abs(fine - rec.meta["x_true"]).max() < 0.01  # µm


def test_oversampled_simulation_keeps_a_delay_in_samples():
    """A delay of d samples is m·d fine points: the output of the chain with it is the
    output without it, d samples later (from rest, the first value held)."""
    from boucwen import EffectSet, Params, simulate_extended

    t = np.arange(2000) * DT
    u = 50.0 + 40.0 * np.sin(2 * np.pi * 7.0 * t)
    params = Params.paper_1hz()
    lag = {"input_lag": {"fc_hz": 400.0}}
    plain = plant.simulate_oversampled(params, EffectSet(**lag), u, DT, 4)
    late = plant.simulate_oversampled(params, EffectSet(**lag, delay={"samples": 3}), u, DT, 4)
    np.testing.assert_array_equal(late[3:], plain[:-3])
    np.testing.assert_array_equal(late[:3], plain[0])
    # m = 1 is the core's own simulation.
    np.testing.assert_array_equal(
        plant.simulate_oversampled(params, EffectSet(**lag), u, DT, 1),
        simulate_extended(params, EffectSet(**lag), u, DT),
    )


def test_paper_input_is_the_cores():
    core = pytest.importorskip("boucwen._core")
    for dt, tail in [(1e-4, 0.05), (2.5e-5, 0.1)]:
        _, u, _ = paper_input(dt, [(1.0, 3.0), (10.0, 0.3), (100.0, 0.03), (200.0, tail)])
        np.testing.assert_array_equal(u, core.paper_input(dt, tail))


# ----------------------------------------------------------------------------- added effects


def test_electrostriction_is_quadratic_in_the_bouc_wen_displacement(bench):
    u, segments, rec = bench
    s = BenchSettings()
    linear = plant.true_displacement(u, DT, dataclasses.replace(s, stroke_quadratic_per_um=0.0))
    y = linear - s.x0 - _creep(u, DT, s)  # kv·u_a + h [µm]
    np.testing.assert_allclose(rec.meta["x_true"] - linear, s.stroke_quadratic_per_um * y * y, rtol=1e-9, atol=1e-12)
    # The stack's gain grows along the stroke: the local slope dx/du on the rising branch
    # of the last 1 Hz period is higher near the top than near the bottom, by the factor
    # 1 + 2·ε·Δy that the quadratic map predicts (the hysteresis is the same in both).
    p1 = _last_period(segments, 1.0, u.size)
    ua, x, xl = _applied_voltage(u, s)[p1], rec.meta["x_true"][p1], linear[p1]
    rising = np.flatnonzero(np.diff(ua) > 0)
    lo = rising[(ua[rising] > 20) & (ua[rising] < 30)]
    hi = rising[(ua[rising] > 70) & (ua[rising] < 80)]

    def slope(sig, k):
        return np.polyfit(ua[k], sig[k], 1)[0]

    gain_rise = (slope(x, hi) / slope(xl, hi)) / (slope(x, lo) / slope(xl, lo))
    y1 = y[p1]
    expect = (1 + 2 * s.stroke_quadratic_per_um * y1[hi].mean()) / (1 + 2 * s.stroke_quadratic_per_um * y1[lo].mean())
    assert gain_rise == pytest.approx(expect, rel=2e-3)
    assert gain_rise > 1.05
    # a few percent of the stroke away from the straight line through the end points
    bow = (rec.meta["x_true"] - linear)[p1]
    stroke = np.ptp(linear[p1])
    assert 0.01 < (bow.max() - bow.min()) / stroke / 4 < 0.03


def test_floor_vibration_is_the_documented_tones(bench):
    _, _, rec = bench
    s = BenchSettings()
    t = rec.t
    want = sum(
        a * np.sin(2 * np.pi * f * t + ph) for f, a, ph in zip(s.vibration_hz, s.vibration_um, s.vibration_phase_rad)
    )
    np.testing.assert_allclose(rec.meta["vibration"], want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(plant.floor_vibration(t, s), want, rtol=0, atol=1e-12)
    # it is in the reading, not in the stack: the spectrum of x − x_true has the two
    # lines at their amplitudes, and nothing else above the noise
    d = rec.x - rec.meta["x_true"]
    k = slice(0, 30000)  # 3 s: whole number of periods of 17 and 29 Hz
    spec = 2 * np.abs(np.fft.rfft(d[k])) / d[k].size
    freqs = np.fft.rfftfreq(d[k].size, DT)
    for f, a in zip(s.vibration_hz, s.vibration_um):
        assert spec[np.argmin(np.abs(freqs - f))] == pytest.approx(a, rel=0.02)
    others = np.ones(spec.size, bool)
    for f in s.vibration_hz:
        others[np.abs(freqs - f) < 1.0] = False
    assert spec[others].max() < 0.005
    # a relative velocity below the VC-A criterion (50 µm/s rms)
    v = np.diff(rec.meta["vibration"]) / DT
    assert v.std() < 50.0


@pytest.fixture(scope="module")
def traditional():
    """The traditional method on the bench: fitted on the 1 Hz part, held fixed."""
    core = pytest.importorskip("boucwen._core")
    from boucwen.fit import fit

    def run(settings):
        _, u, segments = paper_input(DT, [(1.0, 3.0), (10.0, 0.3), (100.0, 0.03), (200.0, 0.1)])
        rec = plant.measure(u, DT, settings, seed=0)
        _, lo, hi = segments[0]
        r = fit(rec.u[lo:hi], rec.x[lo:hi], DT, seed=0)
        xh, _ = core.simulate(r.params, rec.u, DT, r.h0)
        err = np.abs(rec.x - np.asarray(xh))
        out = {}
        for f, _, hi in segments:
            n = round(1 / f / DT)
            out[f] = float(err[hi - n : hi].max())  # last full period
        return out

    return run


def test_calibration_traditional_errors_in_the_papers_regime(traditional):
    # Paper, Table 1 (traditional): 0.47, 0.75, 1.25, 2.91 µm.
    row = traditional(BenchSettings())
    assert 0.35 < row[1.0] < 0.65
    assert 0.5 < row[10.0] < 0.9
    assert 1.0 < row[100.0] < 1.6
    assert 2.5 < row[200.0] < 3.4
    assert row[1.0] < row[10.0] < row[100.0] < row[200.0]


def test_calibration_each_effect_does_its_part(traditional):
    s = BenchSettings()
    # Without vibration and electrostriction the fit absorbs the bench at 1 Hz.
    bare = traditional(dataclasses.replace(s, vibration_um=(0.0, 0.0), stroke_quadratic_per_um=0.0))
    assert bare[1.0] < 0.1
    # Electrostriction alone: absorbed at 1 Hz (δ bends to fit it), not at 10 Hz.
    quad = traditional(dataclasses.replace(s, vibration_um=(0.0, 0.0)))
    assert quad[10.0] > 1.4 * bare[10.0] and quad[10.0] > 2 * quad[1.0]
