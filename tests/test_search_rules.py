"""The rules of the diagnosis's search, each on constructed numbers or a small constructed
record: a trial's stages, the joint trial of two modes, look-alikes told apart, pairs,
swaps in the backward step, confirmations of a screened round, the refit from a fresh
base model and the final refit. Every test fails if its rule is broken."""

import math

import numpy as np
import pytest

from boucwen import DiagnosisPolicy, EffectSet, Params, diagnose, simulate_extended
from boucwen.diagnosis.backward import takes_place
from boucwen.diagnosis.credit import Credit, credit_of, earns
from boucwen.diagnosis.margins import CloseCalls
from boucwen.diagnosis.outcome import final_refit
from boucwen.diagnosis.pairs import pair_earns, pairs_wanted
from boucwen.diagnosis.rebase import fits_better, rebased
from boucwen.diagnosis.rounds import beyond_partner, lookalike_order, score_round
from boucwen.diagnosis.screening import to_confirm
from boucwen.diagnosis.trial import second_stage, still_falling
from boucwen.diagnosis.validation import CrossValidation
from boucwen.effects import ExtendedFit, fit_extended_record

POLICY = DiagnosisPolicy()
P = Params.paper_1hz()
NOISE_UM = 0.005  # the noise of the drift record (tests/conftest.py)


def _credit(gain=0.0, cv_rms=1.0, folds=(0.05, 0.05, 0.05, 0.05), share=0.0, local=0.0):
    return Credit(
        cv_rms_um=cv_rms,
        in_sample_rms_um=cv_rms,
        cv_gain=gain,
        in_sample_gain=gain,
        gain_over_null=gain,
        fold_gains=tuple(folds),
        local_gain=local,
        noise_share=share,
    )


# --- A trial's stages ---------------------------------------------------------------


def test_still_falling_a_trial_that_halved_its_error_in_its_second_stage_goes_on():
    assert still_falling(0.2, 0.09, POLICY)
    assert not still_falling(0.2, 0.11, POLICY)
    assert still_falling(0.2, 0.11, POLICY.replace(still_falling=0.6))
    assert not still_falling(0.0, 0.0, POLICY)  # nothing left to fall from
    # A ratio within close_rel of the threshold is a close call on the path: not falling.
    calls = CloseCalls()
    assert not still_falling(1.0, POLICY.still_falling * (1 + POLICY.close_rel / 2), POLICY, calls, "drift")
    assert [(c["decision"], c["kind"]) for c in calls.to_list()] == [("drift", "path")]


def test_joint_effort_a_joint_trials_second_stage_gets_a_multiple_of_a_trials():
    assert second_stage(POLICY, joint=False) == POLICY.trial_nfev
    assert second_stage(POLICY, joint=True) == POLICY.joint_effort * POLICY.trial_nfev
    assert second_stage(POLICY.replace(joint_effort=2), joint=True) == 2 * POLICY.trial_nfev


def test_trial_tol_a_looser_tolerance_stops_a_fit_sooner_with_the_same_effect(drift_record):
    # The trial_tol given to the fits of a round: a tolerance far looser than the default
    # ends the fit in fewer evaluations; both find the drift.
    current = ExtendedFit(P, EffectSet(), 0.0, 1.0, 1.0, 0, True)
    start = {"drift": fit_extended_record(drift_record, P, EffectSet(drift={"rate_um_per_s": 1.5}), 0.0, max_nfev=2)}
    fits = {}
    for tol in (POLICY.trial_tol, 0.3):
        policy = POLICY.replace(trial_tol=tol)
        round_ = score_round(drift_record, current, policy=policy, names=("drift",), starts=start, workers=1)
        scored = round_.trials["drift"].scored
        assert scored is not None
        fits[tol] = scored.fit
    tight, loose = fits[POLICY.trial_tol], fits[0.3]
    assert loose.nfev < tight.nfev
    assert tight.effects.to_dict()["drift"]["rate_um_per_s"] == pytest.approx(2.0, rel=0.05)
    assert loose.effects.to_dict()["drift"]["rate_um_per_s"] == pytest.approx(2.0, rel=0.2)


# --- Two modes beyond one -------------------------------------------------------------


def test_two_modes_earn_their_further_parameters_only_beyond_one_by_the_least_gain():
    one = _credit(gain=0.3, cv_rms=1.0)
    assert beyond_partner(_credit(gain=0.4, cv_rms=0.85), one, POLICY)
    assert not beyond_partner(_credit(gain=0.35, cv_rms=0.95), one, POLICY)
    assert beyond_partner(_credit(gain=0.35, cv_rms=0.95), one, POLICY.replace(min_gain=0.04))
    # close_rel: a ratio within it of 1 − min_gain is a close call, decided as not beyond.
    calls = CloseCalls()
    near = (1.0 - POLICY.min_gain) * (1.0 - POLICY.close_rel / 2)
    assert not beyond_partner(_credit(gain=0.4, cv_rms=near), one, POLICY, calls, "two modes beyond one")
    assert [c["decision"] for c in calls.to_list()] == ["two modes beyond one"]
    assert beyond_partner(_credit(gain=0.4, cv_rms=near), one, POLICY.replace(close_rel=0.0))


# --- Look-alikes told apart by their test ----------------------------------------------


def test_lookalike_margin_the_test_reorders_only_credits_closer_than_it():
    # The test's outcomes on constructed records: tests/test_validation.py (a lag far
    # above the band is not told from a delay); here what the round does with them.
    credits = {"input_lag": _credit(gain=0.235), "delay": _credit(gain=0.225), "creep": _credit(gain=0.2)}
    said_delay = {"phase": {"shape": "delay", "lag_or_delay_apart": True}, "follows": {"follows": "none"}}
    undecided = {"phase": {"shape": "delay", "lag_or_delay_apart": False}, "follows": {"follows": "none"}}
    order, decision = lookalike_order(["input_lag", "delay", "creep"], credits, said_delay, POLICY)
    assert order == ["delay", "input_lag", "creep"]
    assert decision == {"test": "phase", "between": ["input_lag", "delay"], "chose": "delay"}
    # A test that cannot tell the two apart leaves the choice to the credits.
    assert lookalike_order(["input_lag", "delay"], credits, undecided, POLICY) == (["input_lag", "delay"], None)
    # Credits further apart than the margin: the credits decide.
    assert lookalike_order(["input_lag", "delay"], credits, said_delay, POLICY.replace(lookalike_margin=0.005)) == (
        ["input_lag", "delay"],
        None,
    )
    # Effects of different groups are not reordered by a test.
    follows_creep = {"phase": {"shape": "none"}, "follows": {"follows": "creep"}}
    assert lookalike_order(["delay", "creep"], credits, follows_creep, POLICY.replace(lookalike_margin=0.1))[1] is None


def test_a_look_alike_takes_the_place_of_a_kept_effect_by_its_credit_or_the_test():
    kept = _credit(gain=0.3)
    margin = POLICY.lookalike_margin
    just_below = _credit(gain=0.3 - margin / 2)
    assert takes_place(just_below, kept, True, POLICY)  # named by the test: within the margin
    assert not takes_place(just_below, kept, False, POLICY)  # not named: it must do better
    assert takes_place(_credit(gain=0.31), kept, False, POLICY)
    assert not takes_place(_credit(gain=0.3 - 2 * margin), kept, True, POLICY)
    assert takes_place(_credit(gain=0.3 - 2 * margin), kept, True, POLICY.replace(lookalike_margin=3 * margin))
    # It must earn its parameters too, however it compares with the kept effect.
    weak = _credit(gain=0.05)
    assert not takes_place(weak, _credit(gain=0.04), False, POLICY)


# --- An effect that leaves only the noise -------------------------------------------------


def test_an_effect_that_leaves_only_the_noise_is_credited_with_the_error_beyond_it():
    # The reference leaves 0.4σ of structure beside a noise of σ = 1: the model that
    # removes it all cuts the RMS error by 7 % only (the noise stays), below the least
    # gain, but it removes all of the error beyond the noise, in every fold, and earns.
    n, sigma = 400, 1.0
    excess = 0.4 * sigma
    ref_rms = math.hypot(sigma, excess)
    ref = CrossValidation(np.full(n, ref_rms), ref_rms, ref_rms, [ref_rms] * 4)
    model = CrossValidation(np.full(n, sigma), sigma, sigma, [sigma] * 4)
    c = credit_of(model, np.zeros(n), ref, np.zeros(n), ref_rms, sigma, POLICY)
    assert POLICY.local_floor < c.gain_over_null < POLICY.min_gain
    assert c.noise_share == pytest.approx(1.0)
    assert earns(c, POLICY)
    # The same cut where the record's noise is not known to be σ is not enough.
    blind = credit_of(model, np.zeros(n), ref, np.zeros(n), ref_rms, 0.0, POLICY)
    assert blind.noise_share < POLICY.partial_share and not earns(blind, POLICY)


# --- Pairs ------------------------------------------------------------------------------


def test_pair_ratio_pairs_are_tried_only_well_above_the_noise_and_not_screened():
    assert pairs_wanted(2.1 * NOISE_UM, NOISE_UM, False, POLICY)
    assert not pairs_wanted(1.9 * NOISE_UM, NOISE_UM, False, POLICY)
    assert not pairs_wanted(2.1 * NOISE_UM, NOISE_UM, True, POLICY)
    assert not pairs_wanted(2.1 * NOISE_UM, NOISE_UM, False, POLICY.replace(pair_ratio=3.0))


def test_a_pair_earns_by_the_single_rule_and_beyond_either_member_alone():
    alone = (_credit(gain=0.02, cv_rms=1.0), _credit(gain=0.05, cv_rms=0.95))
    assert pair_earns(_credit(gain=0.2, cv_rms=0.8), alone, POLICY)
    # No better than the better member alone by the least gain: the other adds nothing.
    assert not pair_earns(_credit(gain=0.2, cv_rms=0.9), alone, POLICY)
    # Beyond both, but not earning by the rule of a single effect.
    assert not pair_earns(_credit(gain=0.02, cv_rms=0.8), alone, POLICY)


# --- Confirmations of a screened round ---------------------------------------------------------


def test_confirm_and_confirm_ratio_choose_what_a_screened_round_confirms():
    cv = {"drift": 1.0, "creep": 1.2, "gain_drift": 1.22, "delay": 2.0}
    ranked = ["drift", "creep", "gain_drift", "delay"]
    assert to_confirm(ranked, cv, POLICY) == ["drift", "creep"]
    assert to_confirm(ranked, cv, POLICY.replace(confirm=1)) == ["drift"]
    assert to_confirm(ranked, cv, POLICY.replace(confirm=4)) == ["drift", "creep", "gain_drift"]
    assert to_confirm(ranked, cv, POLICY.replace(confirm_ratio=1.1)) == ["drift"]
    assert to_confirm([], cv, POLICY) == []


def test_confirm_nfev_bounds_a_confirmations_effort(drift_record):
    # A confirmation is a round from given starts with trial_nfev = confirm_nfev (the fit
    # from the start gets the null trial's effort at that trial_nfev): a smaller one does
    # fewer evaluations and keeps the same effect.
    current = ExtendedFit(P, EffectSet(), 0.0, 1.0, 1.0, 0, True)
    off = P.replace(kv=1.2 * P.kv)
    start = {"drift": ExtendedFit(off, EffectSet(drift={"rate_um_per_s": 0.5}), 0.0, 1.0, 1.0, 0, True)}
    nfev = {}
    for k in (POLICY.confirm_nfev, 1):
        round_ = score_round(
            drift_record, current, policy=POLICY, names=("drift",), starts=start, trial_nfev=k, workers=1
        )
        scored = round_.trials["drift"].scored
        assert scored is not None and round_.evidence["most_likely"] == "drift"
        nfev[k] = scored.fit.nfev
    assert nfev[1] < nfev[POLICY.confirm_nfev]


# --- The refit from a fresh base model, the final refit --------------------------------------


def test_rebase_refits_the_effects_kept_from_a_base_model_fitted_without_them(drift_record):
    # The kept model holds the right drift beside a base model bent out of shape (kv
    # and A off by a quarter): fitted afresh to the record less what the drift adds,
    # the base model is found again, and the refit leaves the noise.
    bent = P.replace(kv=1.25 * P.kv, A=0.75 * P.A)
    drift = EffectSet(drift={"rate_um_per_s": 2.0})
    x_kept = simulate_extended(bent, drift, drift_record.u, drift_record.dt)
    rms_kept = float(np.sqrt(np.mean((drift_record.x - x_kept) ** 2)))
    kept = ExtendedFit(bent, drift, 0.0, rms_kept, 0.0, 0, True)
    fresh = rebased(drift_record, kept, seed=0, workers=1, q=1, policy=POLICY)
    assert fresh is not None and fresh.rms_um < 2 * NOISE_UM < rms_kept
    assert fresh.effects.to_dict()["drift"]["rate_um_per_s"] == pytest.approx(2.0, rel=0.05)
    assert fits_better(fresh, kept, POLICY) and not fits_better(kept, kept, POLICY)
    # rebase_nfev bounds the refit: a smaller one does fewer evaluations.
    short = rebased(drift_record, kept, seed=0, workers=1, q=1, policy=POLICY.replace(rebase_nfev=2))
    assert short is not None and short.nfev < fresh.nfev


def test_final_nfev_bounds_the_final_refit(drift_record):
    start = fit_extended_record(drift_record, P, EffectSet(drift={"rate_um_per_s": 1.0}), 0.0, max_nfev=2)
    polished = final_refit(drift_record, start, POLICY)
    assert polished.rms_um < start.rms_um
    once = final_refit(drift_record, start, POLICY.replace(final_nfev=1))
    assert once.nfev < polished.nfev


# --- The verdict on what is left -------------------------------------------------------------


def test_alpha_and_tolerance_of_the_policy_decide_the_verdict_on_the_residual():
    # A clean record (1 kHz, 2 s) with a 50 Hz line of 0.4× the noise's RMS beside the
    # noise: nothing added (max_effects=0), the verdict on the base model's residual.
    # Beyond the default tolerance (0.3× the noise) at p between 1e-4 and the default
    # alpha (0.01): structure by default, noise at alpha = 1e-4 or at tolerance 1.
    rng = np.random.default_rng(5)
    dt, n = 1e-3, 2000
    t = np.arange(n) * dt
    u = 50.0 + 40.0 * np.sin(2 * np.pi * 2 * t)
    line = 0.4 * NOISE_UM * math.sqrt(2) * np.sin(2 * np.pi * 50 * t)
    x = simulate_extended(P, EffectSet(), u, dt) + line + rng.normal(0.0, NOISE_UM, n)
    verdicts = {}
    for name, policy in [
        ("default", POLICY),
        ("alpha", POLICY.replace(alpha=1e-4)),
        ("tolerance", POLICY.replace(tolerance=1.0)),
    ]:
        left = diagnose(u, x, dt, max_effects=0, workers=1, policy=policy).unexplained
        assert left is not None and left.alpha == policy.alpha
        verdicts[name] = (left.consistent_with_noise, left.p_value)
    assert verdicts["default"][0] is False and 1e-4 < verdicts["default"][1] < POLICY.alpha
    assert verdicts["alpha"][0] is True and verdicts["tolerance"][0] is True
