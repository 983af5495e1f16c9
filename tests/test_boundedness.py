"""The boundedness check of a returned model (boucwen.boundedness)."""

import json
import math

import numpy as np
import pytest

from boucwen import EffectSet, Params, oscillator, simulate_extended
from boucwen.boundedness import MULTIPLE, Subject, check, check_model, check_oscillator, highest_excited_hz
from boucwen.oscillator import OscillatorFit, OscillatorParams
from boucwen.record import Record

DT = 1e-4


def sine_record(f_hz=5.0, n=10000):
    t = np.arange(n) * DT
    u = 50.0 - 50.0 * np.cos(2 * np.pi * f_hz * t)
    x = np.asarray(simulate_extended(Params.paper_1hz(), EffectSet(), u, DT, 0.0))
    return Record(t=t, u=u, x=x, dt=DT, name="sine")


def test_the_model_of_a_record_passes():
    rec = sine_record()
    result = check_model(rec, Params.paper_1hz(), EffectSet(), 0.0)
    assert result.passed, result.summary()
    names = [p.name for p in result.probes]
    assert sum(n.startswith("sine") for n in names) >= 2 and any(n.startswith("steps") for n in names)
    assert sum(n.startswith("triangle") for n in names) == 2
    assert result.u_min_v == pytest.approx(0.0) and result.u_max_v == pytest.approx(100.0)
    assert result.range_um == pytest.approx(float(np.ptp(rec.x)))
    # Every probe's peak is the model's own distance from the record's centre.
    assert all(0.0 < p.peak_um <= p.allowed_um for p in result.probes)
    doc = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    assert doc["passed"] and doc["summary"].startswith("bounded") and len(doc["probes"]) == len(result.probes)


def test_the_highest_excited_frequency_is_the_inputs():
    assert highest_excited_hz(sine_record(5.0)) == pytest.approx(5.0, abs=4.0)
    assert highest_excited_hz(sine_record(200.0)) == pytest.approx(200.0, rel=0.1)


def test_a_model_that_leaves_the_records_range_fails():
    rec = sine_record()
    # Twenty times the multiple in gain: bounded, but far beyond the multiple of the
    # record's range the check allows.
    big = Params.paper_1hz().replace(kv=20 * MULTIPLE * 0.19)
    result = check_model(rec, big, EffectSet(), 0.0)
    assert not result.passed and result.summary().startswith("NOT bounded")
    # A model that cannot be simulated fails with an infinite peak.
    broken = check(rec, Subject(lambda u: None, lambda f: 1.0))
    assert not broken.passed and all(math.isinf(p.peak_um) for p in broken.probes)
    assert json.loads(json.dumps(broken.to_dict(), allow_nan=False))["probes"][0]["peak_um"] is None


def test_a_lightly_damped_mode_is_allowed_its_resonance():
    # A mode at 80 Hz with ζ = 0.05 rings at 10× on a sine at its frequency: the model's own
    # linear dynamics, within the allowance scaled by its gain there.
    effects = EffectSet(resonance={"fn_hz": 80.0, "zeta": 0.05})
    t = np.arange(20000) * DT
    u = 50.0 - 50.0 * np.cos(2 * np.pi * 80.0 * t) * (t < 0.2)
    x = np.asarray(simulate_extended(Params.paper_1hz(), effects, u, DT, 0.0))
    rec = Record(t=t, u=u, x=x, dt=DT, name="mode")
    result = check_model(rec, Params.paper_1hz(), effects, 0.0)
    assert result.passed, result.summary()
    assert max(p.allowed_um for p in result.probes) > MULTIPLE * result.range_um


def test_the_oscillator_of_the_benchmark_passes():
    p = OscillatorParams.benchmark()
    t = np.arange(8000) * (1 / 750)
    force = 50.0 * np.sin(2 * np.pi * 7.0 * t) + 20.0 * np.sin(2 * np.pi * 31.0 * t)
    y = oscillator.simulate(p, force, 1 / 750)

    fit = OscillatorFit(params=p, y0=0.0, v0=0.0, z0=0.0, y=y, rms=0.0, nfev=0, success=True, message="", seconds=0.0)
    rec = Record(t=t, u=force, x=y * 1e6, dt=1 / 750, name="force")
    result = check_oscillator(rec, fit)
    assert result.passed, result.summary()
    assert result.range_um == pytest.approx(1e6 * float(np.ptp(y)))
