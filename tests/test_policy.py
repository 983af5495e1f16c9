"""The diagnosis's policy (boucwen.diagnosis.policy): every number documented, refused by
name when invalid, and the one the diagnosis uses and reports; each number's effect is
tested where it acts (tests/test_judge.py, tests/test_search.py)."""

import dataclasses
import re

import numpy as np
import pytest

from boucwen import DiagnosisPolicy, EffectSet, Params, diagnose, simulate_extended
from boucwen.diagnosis.fits import BOUND_TOLERANCE, on_bounds
from boucwen.effects import ExtendedFit, Resonance, Resonance2
from boucwen.record import validate_record

POLICY = DiagnosisPolicy()


def _documented_fields(doc: str) -> list[str]:
    """The names documented in the Attributes section: each at the start of its line."""
    return re.findall(r"^\s{8}(\w+): ", doc, flags=re.MULTILINE)


def test_the_default_policy_is_frozen_small_documented_and_serialisable():
    with pytest.raises(dataclasses.FrozenInstanceError):
        POLICY.alpha = 0.2  # type: ignore[misc]
    fields = [f.name for f in dataclasses.fields(DiagnosisPolicy)]
    assert len(fields) <= 10
    # Each field documented once, as its own entry (not found inside another's name).
    assert _documented_fields(DiagnosisPolicy.__doc__ or "") == fields
    assert DiagnosisPolicy(**POLICY.to_dict()) == POLICY


def test_the_field_check_does_not_accept_a_name_inside_another():
    doc = "Attributes:\n        bound_tolerance: x\n        alpha_max: y\n"
    assert "tolerance" not in _documented_fields(doc) and "alpha" not in _documented_fields(doc)


@pytest.mark.parametrize(
    "change, words",
    [
        (dict(min_share=1.5), "min_share"),
        (dict(folds=1), "folds"),
        (dict(first_origin=0.9), "first_origin"),
        (dict(screen_band=-1.0), "screen_band"),
        (dict(alpha=0.0), "alpha"),
        (dict(max_effects=9), "max_effects"),
        (dict(confident_share=-0.1), "confident_share"),
        (dict(noise_alpha=0.0), "noise_alpha"),
        (dict(noise_tolerance=2.0), "noise_tolerance"),
    ],
)
def test_a_bad_policy_field_is_refused_by_name(change, words):
    with pytest.raises(ValueError, match=words):
        POLICY.replace(**change)


def test_an_unknown_field_is_refused():
    with pytest.raises(TypeError, match="min_gain"):
        POLICY.replace(min_gain=0.1)


def test_diagnose_refuses_a_policy_of_another_type():
    u = np.sin(np.linspace(0, 20, 500))
    with pytest.raises(TypeError, match="DiagnosisPolicy"):
        diagnose(u, 0.2 * u, 1e-3, policy={"alpha": 0.1})  # type: ignore[arg-type]


def test_bound_tolerance_reports_a_parameter_on_its_bound():
    record = validate_record(np.sin(np.arange(500) * 0.05), np.zeros(500), 1e-3)
    p = Params.paper_1hz().replace(n=6.0)  # the base fit's upper bound on n
    on = on_bounds(ExtendedFit(p, EffectSet(), 0.0, 0.0, 0.0, 0, True), record, BOUND_TOLERANCE)
    assert [(b.parameter, b.side) for b in on] == [("n", "upper")]
    near = ExtendedFit(p.replace(n=6.0 - 1e-3), EffectSet(), 0.0, 0.0, 0.0, 0, True)
    assert on_bounds(near, record, BOUND_TOLERANCE) == []
    assert on_bounds(near, record, 1e-3) != []


def test_a_mode_without_a_peak_is_no_candidate_and_a_second_starts_beside_the_first():
    assert Resonance(fn_hz=100.0, zeta=0.7).rejects() is None
    assert "no resonance peak" in (Resonance(fn_hz=100.0, zeta=0.71).rejects() or "")
    both = Resonance2.beside(EffectSet(resonance={"fn_hz": 100.0, "zeta": 0.05}))
    assert both.to_dict()["resonance2"] == pytest.approx({"fn_hz": 100.0 * Resonance2.SPLIT, "zeta": 0.05})
    assert Resonance2.partner == "resonance"


def test_the_policy_given_is_the_one_the_diagnosis_uses_and_reports():
    # A small clean record (1 kHz, 0.6 s); the folds of the policy score it.
    rng = np.random.default_rng(3)
    dt, n = 1e-3, 600
    t = np.arange(n) * dt
    u = 50.0 + 40.0 * np.sin(2 * np.pi * 2 * t)
    x = simulate_extended(Params.paper_1hz(), EffectSet(), u, dt) + rng.normal(0.0, 0.005, n)
    policy = POLICY.replace(folds=3, max_effects=1)
    d = diagnose(u, x, dt, policy=policy, workers=1)
    assert d.evidence["policy"] == policy.to_dict()
    assert d.to_dict()["unseen"]["folds"] == 3
    assert all(len(x.gain.fold_um2) == 3 for x in d.decisions)
