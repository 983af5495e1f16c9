"""Judging models on data their fit did not see (boucwen.diagnosis.unseen) and the
diagnosis's report of it."""

import math

import numpy as np
import pytest

from boucwen import DiagnosisPolicy, EffectSet, Params, diagnose, simulate_extended
from boucwen.diagnosis.unseen import judged_on, prediction_error
from boucwen.effects import ExtendedFit
from boucwen.record import validate_record

DT = 2e-4


def _voltage(n, seed):
    """A voltage record [V] of two sines and a step, different for each seed."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    u = 50 + 30 * np.sin(2 * np.pi * rng.uniform(2, 6) * t) + 10 * np.sin(2 * np.pi * rng.uniform(20, 40) * t)
    u[n // 2 :] += 5.0
    return u


def _fit(effects):
    p = Params.paper_1hz()
    return ExtendedFit(p, effects, 0.0, 0.0, 0.0, 0, True)


def test_a_prediction_is_judged_with_its_offset_reestimated():
    p = Params.paper_1hz()
    u = _voltage(4000, 1)
    x = simulate_extended(p, EffectSet(), u, DT) + 0.5
    err = prediction_error(_fit(EffectSet()), validate_record(u, x, DT))
    assert err is not None
    assert math.isclose(err.offset_um, 0.5, abs_tol=1e-9) and err.rms_um < 1e-9


def test_on_a_second_record_an_effect_that_predicts_nothing_is_dropped_and_one_that_does_is_kept():
    # The record holds an input lag; the model also holds an electrostriction too small
    # to matter (a device effect: judged there, and dropped) and a drift (the record's
    # own: not judged on another record).
    p = Params.paper_1hz()
    lag = EffectSet(input_lag={"fc_hz": 30.0})
    u = _voltage(6000, 2)
    x = simulate_extended(p, lag, u, DT) + np.random.default_rng(3).normal(0, 0.002, u.size)
    validation = validate_record(u, x, DT)
    model = EffectSet(
        input_lag={"fc_hz": 30.0}, electrostriction={"epsilon_per_um": 1e-12}, drift={"rate_um_per_s": 0.1}
    )
    said = []

    def without(fit, name):
        return _fit(EffectSet(**{k: v for k, v in fit.effects.to_dict().items() if k != name}))

    fit, decisions = judged_on([validation], _fit(model), without, DiagnosisPolicy(), 0.002, said.append)
    assert sorted(fit.effects.names) == ["drift", "input_lag"]
    judged = {d.effects: d for d in decisions}
    # The record's own effect is not judged there; each device effect by the judge.
    assert set(judged) == {("input_lag",), ("electrostriction",)}
    assert not judged[("input_lag",)].accepted  # its drop refused: it earns its place
    assert judged[("electrostriction",)].accepted and "does not earn" in judged[("electrostriction",)].reason
    assert judged[("input_lag",)].gain.mean_um2 < 0 and len(said) == 2


def test_a_model_carried_to_another_record_leaves_the_records_own_effects_behind():
    # A drift and a pickup belong to the record: carried to another record the model
    # predicts it from its device part, the other record's offset and trend re-estimated.
    p = Params.paper_1hz()
    u = _voltage(5000, 7)
    t = np.arange(u.size) * DT
    x = simulate_extended(p, EffectSet(), u, DT) + 0.3 - 0.2 * t
    pickup = {"line_hz": 50.0, "sin_um": [0.1, 0.0], "cos_um": [0.0, 0.0]}
    model = EffectSet(drift={"rate_um_per_s": 5.0}, pickup=pickup)
    err = prediction_error(_fit(model), validate_record(u, x, DT))
    assert err is not None and err.rms_um < 1e-6
    assert math.isclose(err.offset_um, 0.3, abs_tol=1e-6) and math.isclose(err.trend_um_per_s, -0.2, abs_tol=1e-5)


def test_a_diagnosis_reports_its_errors_on_unseen_data_and_on_each_validation_record():
    # Two other records of the device: another excitation with another offset, and a
    # third with its own trend (another day); each is carried with its own re-estimated.
    p = Params.paper_1hz()
    lag = EffectSet(input_lag={"fc_hz": 40.0})
    rng = np.random.default_rng(4)
    u1, u2, u3 = _voltage(6000, 5), _voltage(6000, 6), _voltage(5000, 8)
    t3 = np.arange(u3.size) * DT
    x1 = simulate_extended(p, lag, u1, DT) + rng.normal(0, 0.003, u1.size)
    x2 = simulate_extended(p, lag, u2, DT) + 0.2 + rng.normal(0, 0.003, u2.size)
    x3 = simulate_extended(p, lag, u3, DT) - 0.1 + 0.5 * t3 + rng.normal(0, 0.003, u3.size)
    d = diagnose(u1, x1, DT, validate=[(u2, x2, DT), (u3, x3, DT)], seed=1)
    assert "input_lag" in d.effects, d.summary()
    unseen = d.unseen
    assert unseen is not None and unseen.cv_rms_after_um < 0.5 * unseen.cv_rms_before_um
    assert [v.samples for v in unseen.validation] == [6000, 5000]
    for val in unseen.validation:
        assert val.before is not None and val.after is not None
        assert val.after.rms_um < 0.5 * val.before.rms_um and val.ratio < 0.5
    second, third = unseen.validation
    assert math.isclose(second.after.offset_um, 0.2, abs_tol=0.02)
    assert math.isclose(third.after.trend_um_per_s, 0.5, abs_tol=0.05)
    assert "validation record 1 RMS" in d.summary() and "validation record 2 RMS" in d.summary()
    doc = d.to_dict()["unseen"]
    assert doc == unseen.to_dict() and [v["after"]["rms_um"] for v in doc["validation"]] == [
        v.after.rms_um for v in unseen.validation
    ]


def test_validation_records_are_checked_one_by_one():
    u = _voltage(2000, 9)
    x = 0.2 * u
    with pytest.raises(TypeError, match="validate record 2 must be"):
        diagnose(u, x, DT, validate=[(u, x, DT), (u, x)])
    with pytest.raises(ValueError, match="holds no record"):
        diagnose(u, x, DT, validate=[])
