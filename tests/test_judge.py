"""The judge of the diagnosis (boucwen.diagnosis.judge): blocked cross-validation and the
rule that accepts a move, on constructed numbers and records; its held-out errors
against true refits on the measured records."""

import numpy as np
import pytest

from boucwen import EffectSet, Params, datasets, diagnose, simulate_extended
from boucwen.diagnosis import fits
from boucwen.diagnosis.judge import CrossValidation, apart, fold_slices, gain, judge, threshold
from boucwen.effects import ExtendedFit, solve_extended_record
from boucwen.record import validate_record

FOLDS, BATCHES = 4, 16


def _cv(residual):
    return CrossValidation.of(np.asarray(residual, dtype=float), np.asarray(residual, dtype=float), FOLDS)


def _judge(g, t_min=3.0, noise_um=0.0, min_share=0.1):
    return judge("add", ("x",), ("x",), (), g, t_min=t_min, noise_um=noise_um, min_share=min_share, unknowns=1)


def test_fold_slices_cover_the_record_once():
    slices = fold_slices(1003, 4)
    assert [s.start for s in slices] == [0, *[s.stop for s in slices[:-1]]]
    assert slices[-1].stop == 1003
    assert max(s.stop - s.start for s in slices) - min(s.stop - s.start for s in slices) <= 1


def _plain_refits(record, fit, folds):
    """Each block's held-out residual from the model refitted without it, written out
    here from the extended fit alone, and whether each refit converged."""
    n = len(record)
    held, ok = np.empty(n), []
    for sl in fold_slices(n, folds):
        weights = np.ones(n)
        weights[sl] = 0.0
        out = solve_extended_record(record, fit.params, fit.effects, fit.h0, max_nfev=200, weights=weights)
        held[sl] = record.x[sl] - out.x[sl]
        ok.append(out.fit.success)
    return held, ok


def test_the_held_out_error_is_that_of_refits_without_each_block():
    # A paper-model record with a drift, 1 kHz.
    rng = np.random.default_rng(5)
    dt, n = 1e-3, 3000
    t = np.arange(n) * dt
    u = 50.0 + 40.0 * np.sin(2 * np.pi * 2 * t)
    drift = EffectSet(drift={"rate_um_per_s": 0.3})
    x = simulate_extended(Params.paper_1hz(), drift, u, dt) + rng.normal(0.0, 0.005, n)
    record = validate_record(u, x, dt)
    conv = fits.Convergence()
    fit = fits.refit(record, ExtendedFit(Params.paper_1hz(), drift, 0.0, 0, 0, 0, True), drift, conv)
    model = fits.scored(record, fits.solved_at(record, fit), 4, conv)
    held, ok = _plain_refits(record, fit, 4)
    assert all(ok) and all(model.cv.converged)
    np.testing.assert_allclose(model.cv.residual, held, atol=1e-3 * float(np.std(x)))
    assert model.cv.rms_um > model.cv.in_sample_rms_um
    # A block of pure offset added to the record is not absorbed by a model that did not
    # see it.
    bumped = x.copy()
    bumped[:750] += 0.05
    rec2 = validate_record(u, bumped, dt)
    m2 = fits.scored(rec2, fits.solved_at(rec2, fits.refit(rec2, fit, drift, conv)), 4, conv)
    assert m2.cv.fold_rms_um[0] > 2 * m2.cv.in_sample_rms_um


def test_a_block_whose_refit_does_not_converge_is_left_out_of_the_comparison():
    rng = np.random.default_rng(6)
    n = 1600
    ref, cand = rng.normal(0.0, 2.0, n), rng.normal(0.0, 1.0, n)
    both = gain(_cv(cand), _cv(ref), FOLDS, BATCHES)
    bad = CrossValidation.of(ref, ref, FOLDS, (False, True, True, True))
    left = gain(_cv(cand), bad, FOLDS, BATCHES)
    keep = np.concatenate([np.arange(n)[sl] for sl in fold_slices(n, FOLDS)[1:]])
    assert left.mean_um2 == pytest.approx(np.mean(ref[keep] ** 2) - np.mean(cand[keep] ** 2))
    assert left.mean_um2 != pytest.approx(both.mean_um2)
    assert bad.rms_um == pytest.approx(np.sqrt(np.mean(ref[keep] ** 2)))
    none = CrossValidation.of(ref, ref, FOLDS, (False,) * FOLDS)
    verdict = _judge(gain(_cv(cand), none, FOLDS, BATCHES))
    assert not verdict.accepted and "cannot judge" in verdict.reason


def test_the_gain_is_the_mean_log_ratio_over_batches_with_its_batch_means_error():
    rng = np.random.default_rng(0)
    n = 1600
    ref = rng.normal(0.0, 2.0, n)
    cand = rng.normal(0.0, 1.0, n)
    g = gain(_cv(cand), _cv(ref), FOLDS, BATCHES)
    batches = fold_slices(n, BATCHES)
    ratios = [np.log(np.mean(ref[b] ** 2) / np.mean(cand[b] ** 2)) for b in batches]
    assert g.log_ratio == pytest.approx(np.mean(ratios))
    assert g.se == pytest.approx(np.std(ratios, ddof=1) / np.sqrt(BATCHES))
    assert g.t == pytest.approx(g.log_ratio / g.se)
    assert g.mean_um2 == pytest.approx(np.mean(ref**2) - np.mean(cand**2))
    assert len(g.fold_um2) == FOLDS and sum(g.fold_um2) == pytest.approx(FOLDS * g.mean_um2, rel=1e-9)
    # Swapping the two models flips the sign.
    back = gain(_cv(ref), _cv(cand), FOLDS, BATCHES)
    assert back.t == pytest.approx(-g.t) and back.mean_um2 == pytest.approx(-g.mean_um2)


def test_a_gain_in_one_batch_is_not_significant_but_a_gain_in_every_batch_is():
    rng = np.random.default_rng(1)
    n = 1600
    ref = rng.normal(0.0, 1.0, n)
    local = ref.copy()
    local[:100] *= 0.1  # one batch of sixteen predicted better
    everywhere = 0.7 * ref
    t_min = threshold(0.05, 10, BATCHES)
    assert not _judge(gain(_cv(local), _cv(ref), FOLDS, BATCHES), t_min).accepted
    assert _judge(gain(_cv(everywhere), _cv(ref), FOLDS, BATCHES), t_min).accepted


def test_min_share_a_significant_gain_must_remove_a_share_of_the_error_beyond_the_noise():
    rng = np.random.default_rng(2)
    n = 1600
    noise = rng.normal(0.0, 1.0, n)
    ref = noise + 0.5 * np.sin(np.arange(n) * 0.3)  # beyond the noise: 0.125 µm²
    small = noise + 0.49 * np.sin(np.arange(n) * 0.3)  # removes 4 % of it
    large = noise + 0.2 * np.sin(np.arange(n) * 0.3)  # removes 84 % of it
    t_min = 2.0
    g_small = gain(_cv(small), _cv(ref), FOLDS, BATCHES)
    g_large = gain(_cv(large), _cv(ref), FOLDS, BATCHES)
    assert g_small.t > t_min and g_large.t > t_min
    verdict = _judge(g_small, t_min, noise_um=1.0)
    assert not verdict.accepted and "beyond the noise" in verdict.reason
    assert _judge(g_small, t_min, noise_um=1.0, min_share=0.01).accepted
    assert _judge(g_large, t_min, noise_um=1.0).accepted


def test_the_threshold_rises_with_the_moves_of_a_round_and_falls_with_alpha():
    assert threshold(0.05, 10, 16) > threshold(0.05, 1, 16) > threshold(0.2, 1, 16)
    # One move at level α: the one-sided t quantile.
    from scipy import stats

    assert threshold(0.05, 1, 16) == pytest.approx(stats.t.ppf(0.95, 15))


def test_two_candidates_within_the_margin_are_not_apart():
    rng = np.random.default_rng(3)
    n = 1600
    a = rng.normal(0.0, 1.0, n)
    b = a * (1.0 + 0.01 * rng.normal(size=n))
    far = 3.0 * a
    assert not apart(_cv(a), _cv(b), FOLDS, BATCHES, 3.0)
    assert apart(_cv(a), _cv(far), FOLDS, BATCHES, 3.0)
    assert apart(_cv(far), _cv(a), FOLDS, BATCHES, 3.0)


@pytest.mark.parametrize("name", ["micromanipulator", "micromanipulator_compensated"])
def test_the_reported_unseen_error_agrees_with_true_refits_on_measured_records(name):
    try:
        rec = datasets.load(name)
    except datasets.DataNotFoundError as exc:
        pytest.skip(str(exc))
    record = validate_record(rec.u, rec.x, rec.dt)
    d = diagnose(record.u, record.x, record.dt)
    base = ExtendedFit(d.base_only.params, EffectSet(), d.base_only.h0_um, 0, 0, 0, True)
    final = ExtendedFit(d.params, d.effect_set, d.h0_um, 0, 0, 0, True)
    (held_base, ok_base), (held_final, ok_final) = _plain_refits(record, base, 4), _plain_refits(record, final, 4)
    # The report compares the two models on the blocks where both refits converge (where
    # one does not, the rest of the record does not determine that model); at most one
    # block of four may be left out.
    kept = [k for k in range(4) if ok_base[k] and ok_final[k]]
    assert len(kept) >= 3, (name, ok_base, ok_final)
    slices = fold_slices(len(record), 4)
    for held, reported in ((held_base, d.unseen.cv_rms_before_um), (held_final, d.unseen.cv_rms_after_um)):
        refitted = np.sqrt(np.mean(np.concatenate([held[slices[k]] for k in kept]) ** 2))
        assert reported == pytest.approx(refitted, rel=0.05), (name, reported, refitted)
