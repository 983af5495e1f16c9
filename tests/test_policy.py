"""The rules of the diagnosis's policy (boucwen.diagnosis.policy), each on constructed
numbers or a small constructed record: every test fails if its rule is broken."""

import dataclasses
import math

import numpy as np
import pytest

from boucwen import DiagnosisPolicy, EffectSet, Params, diagnose, simulate_extended
from boucwen.diagnosis.backward import swap_group
from boucwen.diagnosis.credit import Credit, credit_of, earns, explained_share, partial
from boucwen.diagnosis.evidence import spectral_peak
from boucwen.diagnosis.margins import CloseCalls
from boucwen.diagnosis.pairs import pair_pool
from boucwen.diagnosis.rounds import Trial, barred
from boucwen.diagnosis.scoring import on_bounds
from boucwen.diagnosis.screening import decimated, peak_beyond, screen_factor, screenable
from boucwen.diagnosis.starts import first_stage, null_effort, ranked_starts
from boucwen.diagnosis.unexplained import unexplained
from boucwen.diagnosis.validation import CrossValidation
from boucwen.effects import (
    Delay,
    Drift,
    ExtendedFit,
    InputLag,
    Resonance,
    Resonance2,
    TrialStart,
    candidate_starts,
    lagged,
)
from boucwen.record import validate_record

POLICY = DiagnosisPolicy()


def _credit(gain=0.0, local=0.0, share=0.0, folds=(0.05, 0.05, 0.05, 0.05), in_sample=None):
    return Credit(
        cv_rms_um=1.0,
        in_sample_rms_um=1.0,
        cv_gain=gain,
        in_sample_gain=gain if in_sample is None else in_sample,
        gain_over_null=gain,
        fold_gains=tuple(folds),
        local_gain=local,
        noise_share=share,
    )


def test_the_default_policy_is_frozen_documented_and_serialisable():
    with pytest.raises(dataclasses.FrozenInstanceError):
        POLICY.min_gain = 0.2  # type: ignore[misc]
    doc = DiagnosisPolicy.__doc__ or ""
    for field in dataclasses.fields(DiagnosisPolicy):
        assert f"{field.name}:" in doc, field.name
    assert DiagnosisPolicy(**POLICY.to_dict()) == POLICY


@pytest.mark.parametrize(
    "change, words",
    [
        (dict(min_gain=1.5), "min_gain"),
        (dict(folds=1), "folds"),
        (dict(trial_nfev=0), "trial_nfev"),
        (dict(confirm_ratio=0.5), "confirm_ratio"),
        (dict(close_gain=-1e-4), "close_gain"),
        (dict(alpha=0.0), "alpha"),
        (dict(tolerance=2.0), "tolerance"),
    ],
)
def test_a_bad_policy_field_is_refused_by_name(change, words):
    with pytest.raises(ValueError, match=words):
        POLICY.replace(**change)


def test_diagnose_refuses_a_policy_of_another_type():
    u = np.sin(np.linspace(0, 20, 500))
    with pytest.raises(TypeError, match="DiagnosisPolicy"):
        diagnose(u, 0.2 * u, 1e-3, policy={"min_gain": 0.1})  # type: ignore[arg-type]


def test_min_gain_an_overall_cut_earns_its_parameters():
    assert earns(_credit(gain=POLICY.min_gain + 0.01), POLICY)
    assert not earns(_credit(gain=POLICY.min_gain - 0.01), POLICY)
    # The policy is read, not a constant: a higher least gain refuses the same credit.
    assert not earns(_credit(gain=0.11), POLICY.replace(min_gain=0.2))


def test_local_min_gain_with_local_floor_earns_for_local_evidence():
    local = POLICY.local_min_gain + 0.01
    assert earns(_credit(gain=POLICY.local_floor + 0.01, local=local), POLICY)
    assert not earns(_credit(gain=POLICY.local_floor - 0.01, local=local), POLICY)
    assert not earns(_credit(gain=POLICY.local_floor + 0.01, local=POLICY.local_min_gain - 0.01), POLICY)


def test_partial_share_earns_to_the_noise_only_with_every_fold_and_the_floor():
    share = POLICY.partial_share + 0.01
    assert earns(_credit(gain=0.05, share=share), POLICY)
    assert not earns(_credit(gain=0.05, share=share, folds=(0.2, 0.01, -0.01, 0.01)), POLICY)
    assert not earns(_credit(gain=0.05, share=POLICY.partial_share - 0.01), POLICY)
    assert not earns(_credit(gain=POLICY.local_floor - 0.01, share=share), POLICY)


def test_close_gain_a_credit_within_the_margin_does_not_earn_and_is_noted():
    calls = CloseCalls()
    assert not earns(_credit(gain=POLICY.min_gain + POLICY.close_gain / 2), POLICY, calls, "creep")
    assert [c["decision"] for c in calls.to_list()] == ["creep: earns its parameters"]
    assert earns(_credit(gain=POLICY.min_gain + 2 * POLICY.close_gain), POLICY)


def test_the_credit_is_the_lesser_of_the_cross_validated_and_in_sample_cuts():
    n = 400
    ref = CrossValidation(np.full(n, 1.0), 1.0, 1.0, [1.0] * 4)
    # Better out of sample (block refits that extrapolate better), no better in sample.
    model = CrossValidation(np.full(n, 0.5), 0.99, 0.5, [0.5] * 4)
    c = credit_of(model, np.zeros(n), ref, np.zeros(n), 1.0, 0.0, POLICY)
    assert c.cv_gain == pytest.approx(0.5) and c.gain_over_null == pytest.approx(0.01)
    assert c.fold_gains == pytest.approx((0.5,) * 4)
    assert Credit.from_dict({**c.to_dict(), "fitted": {}}) == c


def test_local_share_the_local_gain_is_read_where_the_model_acts_most():
    n = 1000
    acts = np.zeros(n)
    acts[:100] = 1.0  # the model differs from the reference on a tenth of the samples
    ref_residual = np.full(n, 0.1)
    ref_residual[:100] = 1.0
    ref = CrossValidation(ref_residual, 0.3, float(np.sqrt(np.mean(ref_residual**2))), [0.3] * 4)
    model_residual = ref_residual.copy()
    model_residual[:100] = 0.1  # ... and removes the error there
    model = CrossValidation(model_residual, 0.1, 0.1, [0.1] * 4)
    c = credit_of(model, acts, ref, np.zeros(n), 0.3, 0.0, POLICY)
    assert c.local_gain == pytest.approx(0.9)
    wider = credit_of(model, acts, ref, np.zeros(n), 0.3, 0.0, POLICY.replace(local_share=0.5))
    assert wider.local_gain < 0.9


def test_explained_share_counts_the_error_beyond_the_noise():
    assert explained_share(2.0, 1.0, 1.0) == pytest.approx(1.0)
    assert explained_share(math.sqrt(5.0), math.sqrt(3.0), 1.0) == pytest.approx(0.5)
    assert explained_share(1.0, 0.5, 1.0) == 1.0  # nothing beyond the noise to explain


def test_partial_share_what_the_effects_leave_makes_them_tentative():
    rng = np.random.default_rng(0)
    n, noise = 4000, 0.01
    t = np.arange(n) * 1e-3
    u = np.sin(2 * np.pi * t)
    x = rng.normal(0.0, noise, n)
    record = validate_record(u, x, 1e-3)
    structured = unexplained(record, -0.05 * np.sin(2 * np.pi * 7 * t))
    white = unexplained(record, np.zeros(n))
    assert not structured.consistent_with_noise and white.consistent_with_noise
    before = 10.0 * noise
    kept_most = math.sqrt(noise**2 + 0.05 * (before**2 - noise**2))  # 95 % explained
    kept_little = math.sqrt(noise**2 + 0.5 * (before**2 - noise**2))  # 50 % explained
    assert partial(before, kept_little, structured, POLICY)
    assert not partial(before, kept_most, structured, POLICY)
    assert not partial(before, kept_little, white, POLICY)


def test_trial_nfev_sets_the_stages_and_the_null_trials_effort():
    assert first_stage(POLICY) == 4 and null_effort(POLICY) == 16
    assert first_stage(POLICY.replace(trial_nfev=6)) == 3  # at least 3
    assert null_effort(POLICY.replace(trial_nfev=30)) == 40


def test_screen_min_samples_and_screen_rate_hz_decide_the_screening():
    short = validate_record(np.sin(np.arange(1000) * 0.01), np.zeros(1000), 1e-4)
    assert screen_factor(short, POLICY) == 1
    assert screen_factor(short, POLICY.replace(screen_min_samples=500)) == 4  # 10 kHz → 2.5 kHz
    assert screen_factor(short, POLICY.replace(screen_min_samples=500, screen_rate_hz=5000.0)) == 2
    copy = decimated(short, 4)
    assert len(copy) == 250 and copy.dt == pytest.approx(4e-4)


def test_a_model_with_an_effect_of_whole_samples_is_not_screened():
    # A delay of d samples is d samples of the full rate; on the screened copy the same
    # model would delay by d·q.
    n = 2000
    u = np.sin(np.arange(n) * 0.01)
    screen = decimated(validate_record(u, 0.2 * u, 1e-4), 4)
    p = Params.paper_1hz()
    plain = ExtendedFit(p, EffectSet(drift={"rate_um_per_s": 0.1}), 0.0, 0.0, 0.0, 0, True)
    delayed = ExtendedFit(p, EffectSet(delay={"samples": 2}), 0.0, 0.0, 0.0, 0, True)
    assert screenable(plain, screen) and not screenable(delayed, screen)


def _test(said):
    return {"follows": {"follows": said}, "phase": {"shape": "none"}}


def test_a_look_alike_in_the_model_bars_the_others_the_test_does_not_name():
    assert set(barred(_test("none"), {"creep"})) == {"drift", "gain_drift"}
    assert set(barred(_test("drift"), {"creep"})) == {"gain_drift"}
    assert set(barred(_test("drift"), {"gain_drift"})) == {"creep"}
    # An undecided test bars only beside creep, whose fixed time constants leave a
    # relaxation of its own.
    assert barred(_test("none"), {"gain_drift"}) == {}
    assert barred(_test("none"), {"resonance"}) == {}


def test_look_alikes_are_swapped_within_their_group_and_a_delay_only_at_the_full_rate():
    assert swap_group("creep", full_rate=False) == ("follows", ("creep", "drift", "gain_drift"))
    assert swap_group("input_lag", full_rate=True) == ("phase", ("delay", "input_lag"))
    assert swap_group("input_lag", full_rate=False) is None
    assert swap_group("resonance", full_rate=True) is None  # a peak is its own evidence


def test_pair_pool_holds_the_best_in_sample_cuts_but_no_barred_or_joint_trial():
    fits = {
        k: Trial(k, credit=_credit(in_sample=g))
        for k, g in [
            ("creep", 0.05),
            ("drift", 0.04),
            ("gain_drift", 0.03),
            ("saturation", 0.02),
            ("pickup", 0.01),
            ("resonance2", 0.5),
            ("delay", -0.1),
        ]
    }
    # Trial.credit without a fit: the pool reads credits only.
    assert pair_pool(fits, [], POLICY) == ["creep", "drift", "gain_drift", "saturation"]
    assert pair_pool(fits, ["drift"], POLICY) == ["creep", "gain_drift", "saturation", "pickup"]
    assert pair_pool(fits, [], POLICY.replace(pair_pool=2)) == ["creep", "drift"]


def test_bound_tolerance_reports_a_parameter_on_its_bound():
    record = validate_record(np.sin(np.arange(500) * 0.05), np.zeros(500), 1e-3)
    p = Params.paper_1hz().replace(n=6.0)  # the base fit's upper bound on n
    on = on_bounds(ExtendedFit(p, EffectSet(), 0.0, 0.0, 0.0, 0, True), record)
    assert [(b.parameter, b.side) for b in on] == [("n", "upper")]
    near = ExtendedFit(p.replace(n=6.0 - 1e-3), EffectSet(), 0.0, 0.0, 0.0, 0, True)
    assert on_bounds(near, record) == []
    assert on_bounds(near, record, POLICY.replace(bound_tolerance=1e-3)) != []


def _start(record, ranked, screened):
    p = Params.paper_1hz()
    return TrialStart(record, p, EffectSet(), 0.0, tuple(ranked), screened, POLICY.screened_refits)


def test_a_delay_trial_refits_every_whole_sample_shift_unless_screened():
    n = 1000
    u = np.sin(np.arange(n) * 0.02)
    record = validate_record(u, 0.2 * u, 1e-4)
    ranked = candidate_starts("delay", record, Params.paper_1hz(), EffectSet(), 0.0, max_delay=8)
    full = Delay.refit_starts(_start(record, ranked, screened=False))
    assert len(full.variants) == 8 and full.hopeless is not None
    screened = Delay.refit_starts(_start(record, ranked, screened=True))
    assert len(screened.variants) == POLICY.screened_refits
    d = ranked[0].to_dict()["delay"]["samples"]
    shifted = full.variants[0](record)
    assert len(shifted) == n - d and np.array_equal(shifted.x, record.x[d:])


def test_a_drift_trial_starts_from_the_record_less_multiples_of_its_trend():
    n = 1000
    t = np.arange(n) * 1e-3
    u = np.sin(2 * np.pi * 3 * t)
    record = validate_record(u, 0.2 * u + 0.5 * t, 1e-3)
    asked = Drift.refit_starts(_start(record, [], screened=False))
    assert asked is not None
    rates = [s.to_dict()["drift"]["rate_um_per_s"] for s in asked.starts]
    assert rates == pytest.approx([f * 0.5 for f in Drift.TREND_PROFILE], rel=1e-6)
    assert np.allclose(asked.variants[2](record).x, 0.2 * u)
    still = validate_record(u, np.zeros(n), 1e-3)  # x without any trend
    assert Drift.refit_starts(_start(still, [], screened=False)) is None


def test_an_input_lag_trial_refits_to_lagged_u_only_when_its_best_start_is_no_lag():
    n = 1000
    u = np.sin(np.arange(n) * 0.02)
    record = validate_record(u, 0.2 * u, 1e-4)
    corners = [1e6, 50.0, 500.0]  # the best-ranked first: almost no lag (above 1/dt)
    ranked = [EffectSet(input_lag={"fc_hz": fc}) for fc in corners]
    asked = InputLag.refit_starts(_start(record, ranked, screened=False))
    assert asked is not None and len(asked.variants) == 2
    assert InputLag.refit_starts(_start(record, ranked, screened=True)) is None
    assert InputLag.refit_starts(_start(record, ranked[1:], screened=False)) is None


def test_u_lagged_for_a_trial_start_is_the_cores_input_lag():
    dt, fc = 1e-4, 70.0
    t = np.arange(3000) * dt
    u = np.sin(2 * np.pi * 40 * t) + 0.3 * np.sign(np.sin(2 * np.pi * 7 * t))
    record = validate_record(u, u, dt)
    p = Params.paper_1hz()
    with_lag = simulate_extended(p, EffectSet(input_lag={"fc_hz": fc}), u, dt)
    behind = lagged(record, fc)
    assert np.array_equal(behind.x, record.x) and behind.u[0] == u[0]
    # The same u_a (the core integrates the hysteresis over finer steps within a
    # sample, where its u_a is not a straight line).
    assert np.max(np.abs(simulate_extended(p, EffectSet(), behind.u, dt) - with_lag)) < 1e-3 * np.ptp(with_lag)


def test_a_mode_without_a_peak_is_no_candidate_and_a_second_starts_beside_the_first():
    assert Resonance(fn_hz=100.0, zeta=0.7).rejects() is None
    assert "no resonance peak" in (Resonance(fn_hz=100.0, zeta=0.71).rejects() or "")
    both = Resonance2.beside(EffectSet(resonance={"fn_hz": 100.0, "zeta": 0.05}))
    assert both.to_dict()["resonance2"] == pytest.approx({"fn_hz": 100.0 * Resonance2.SPLIT, "zeta": 0.05})
    assert Resonance2.partner == "resonance"


def test_peak_over_median_a_line_above_what_the_screened_copy_holds_sends_the_modes_to_the_full_record():
    dt, n = 1e-4, 20_000
    t = np.arange(n) * dt
    u = 50.0 + 40.0 * np.sin(2 * np.pi * 5 * t)
    p = Params.paper_1hz()
    line = 0.05 * np.sin(2 * np.pi * 3000.0 * t)  # 0.3 of the sampling rate
    noise = np.random.default_rng(1).normal(0.0, 0.005, n)
    record = validate_record(u, simulate_extended(p, EffectSet(), u, dt) + line + noise, dt)
    current = ExtendedFit(p, EffectSet(), 0.0, 0.0, 0.0, 0, True)
    peak = spectral_peak(line + noise, dt)
    assert peak["peak_hz"] == pytest.approx(3000.0, rel=0.01)
    screen_dt = 4 * dt  # a copy of every 4th sample holds modes up to 0.45/(4·dt) = 1125 Hz
    assert peak_beyond(record, current, screen_dt, POLICY)
    above = POLICY.replace(peak_over_median=1.01 * peak["peak_over_median"])
    assert not peak_beyond(record, current, screen_dt, above)
    assert not peak_beyond(record, current, dt, POLICY)  # the full rate holds it


def test_max_delay_samples_bounds_the_delays_a_trial_ranks():
    n = 600
    u = np.sin(np.arange(n) * 0.02)
    record = validate_record(u, 0.2 * u, 1e-4)
    current = ExtendedFit(Params.paper_1hz(), EffectSet(), 0.0, 0.0, 0.0, 0, True)
    ranked, _ = ranked_starts("delay", record, current, None, 1, POLICY.replace(max_delay_samples=3))
    assert sorted(s.to_dict()["delay"]["samples"] for s in ranked) == [1, 2, 3]


def test_the_policy_given_is_the_one_the_diagnosis_uses_and_reports():
    # A small clean record (1 kHz, 0.6 s): nothing to name; the folds of the policy score it.
    rng = np.random.default_rng(3)
    dt, n = 1e-3, 600
    t = np.arange(n) * dt
    u = 50.0 + 40.0 * np.sin(2 * np.pi * 2 * t)
    x = simulate_extended(Params.paper_1hz(), EffectSet(), u, dt) + rng.normal(0.0, 0.005, n)
    policy = POLICY.replace(folds=3)
    d = diagnose(u, x, dt, policy=policy, max_effects=1, workers=1)
    assert d.evidence["policy"] == policy.to_dict() and d.evidence["folds"] == 3
    assert len(d.evidence["rounds"][0]["null"]["fold_rms_um"]) == 3
    assert d.to_dict()["unseen"]["folds"] == 3
