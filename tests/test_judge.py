"""The judge of the diagnosis (boucwen.diagnosis.judge): forward folds placed by the
record's information and excitation, the test of a move on dependent data, and the
screen of the held-out errors against converged refits."""

import numpy as np
import pytest

from boucwen import EffectSet, Params, simulate_extended
from boucwen.diagnosis import fits
from boucwen.diagnosis.heldout import CrossValidation, Folds, excitation, informed, less_record_part
from boucwen.diagnosis.judge import apart, dependence_length, gain, judge, level, threshold
from boucwen.effects import ExtendedFit, solve_extended_record
from boucwen.record import validate_record


def _folds(n, origins):
    return Folds(n, tuple(origins))


def _cv(residual, folds=None, converged=None, exact=True):
    r = np.asarray(residual, dtype=float)
    folds = folds or _folds(r.size, (0,))
    ok = converged if converged is not None else (True,) * folds.count
    return CrossValidation.of(r, r, folds, ok, exact)


def _judge(g, lvl=1e-3, noise_um=0.0, min_share=0.1):
    return judge("add", ("x",), ("x",), (), g, level_=lvl, noise_um=noise_um, min_share=min_share, unknowns=1)


def test_folds_predict_every_sample_after_the_first_origin_once_each_from_its_past():
    folds = _folds(1000, (400, 550, 700, 850))
    covered = np.zeros(1000, dtype=int)
    for k in range(folds.count):
        covered[folds.test(k)] += 1
        # A fold is refitted on the record before what it predicts.
        assert folds.train(k) == slice(0, folds.test(k).start)
    assert (covered[:400] == 0).all() and (covered[400:] == 1).all()
    assert folds.tested == slice(400, 1000) and folds.count == 4
    assert folds.mask((True, False, True, True)).sum() == 600 - 150


def test_a_rest_adds_no_excitation_and_a_step_adds_its_jump():
    dt, n = 1e-3, 4000
    u = np.where(np.arange(n) < 3000, 10.0, 50.0)
    u = u + np.random.default_rng(0).normal(0.0, 0.002, n)  # a logged voltage: noise at rest too
    m = excitation(validate_record(u, np.zeros(n), dt))
    assert m[0] == 0.0 and m[-1] == pytest.approx(1.0)
    assert np.all(np.diff(m) >= 0)
    # Before the step only time counts (half of M), after it the travel is all there.
    assert m[2990] == pytest.approx(0.5 * 2990 / (n - 1), abs=1e-3)
    assert m[3010] - m[2990] == pytest.approx(0.5 + 0.5 * 20 / (n - 1), abs=1e-3)


def test_the_first_origin_holds_on_average_the_asked_share_of_the_information_about_each_unknown():
    rng = np.random.default_rng(1)
    n = 2000
    # Two unknowns: one told by every sample, one only by the last quarter.
    jac = np.column_stack([np.ones(n), np.where(np.arange(n) >= 1500, rng.normal(size=n), 0.0)])
    k = informed(jac, 0.5)
    # Shares at k: the first k/n, the second (k − 1500)/500 once past 1500; their mean is ½.
    first, second = k / n, max(0.0, (k - 1500) / 500)
    assert 0.5 * (first + second) == pytest.approx(0.5, abs=0.02)
    assert 1500 < k < 1750
    record = validate_record(np.linspace(0.0, 10.0, n), np.zeros(n), 1e-3)
    folds = Folds.of(record, 4, 0.5, jac)
    assert folds.origins[0] == k and folds.count == 4 and list(folds.origins) == sorted(set(folds.origins))


def test_the_dependence_length_of_white_noise_is_short_and_grows_with_correlation():
    rng = np.random.default_rng(2)
    white = rng.normal(size=20000)
    assert dependence_length(white) <= 8
    phi = 0.95
    ar = np.zeros(20000)
    for i in range(1, ar.size):
        ar[i] = phi * ar[i - 1] + white[i]
    # τ_int of an AR(1) is (1 + φ)/(1 − φ) = 39; Sokal's window is about five times it.
    assert 100 <= dependence_length(ar) <= 400


def test_the_gain_is_the_mean_loss_difference_with_the_noise_of_e_times_delta():
    rng = np.random.default_rng(3)
    n = 4000
    delta = 0.05 * np.sin(np.linspace(0.0, 40.0, n))
    cand = rng.normal(0.0, 0.01, n)
    ref = cand + delta
    g = gain(_cv(cand), _cv(ref))
    assert g.mean_um2 == pytest.approx(np.mean(ref**2 - cand**2))
    assert g.reference_mse_um2 == pytest.approx(np.mean(ref**2))
    # White e: Var(mean d) = 4·σ²·Σδ²/n² up to the window's few lags.
    expected = 2.0 * np.std(cand) * np.sqrt(np.sum(delta**2)) / n
    assert g.se_um2 == pytest.approx(expected, rel=0.1)
    assert g.statistic == pytest.approx(g.mean_um2 / g.se_um2)
    assert g.dof > n / 10
    flipped = gain(_cv(ref), _cv(cand))
    assert flipped.mean_um2 == pytest.approx(-g.mean_um2) and flipped.statistic == pytest.approx(-g.statistic)


def test_under_the_null_the_test_accepts_at_most_its_level_on_white_and_correlated_noise():
    # Two models that predict equally well (a spurious difference δ of either sign), the
    # residual white or autocorrelated: the share of accepts at level 5 % stays near 5 %.
    rng = np.random.default_rng(4)
    n, trials, lvl = 3000, 400, 0.05
    for phi in (0.0, 0.9):
        accepts = 0
        for _ in range(trials):
            w = rng.normal(0.0, 0.01, n)
            e = w.copy()
            for i in range(1, n):
                e[i] = phi * e[i - 1] + w[i]
            delta = 0.002 * rng.normal() * np.sin(np.linspace(0.0, rng.uniform(5, 50), n) + rng.uniform(0, 6))
            g = gain(_cv(e - delta / 2), _cv(e + delta / 2))
            accepts += g.statistic > threshold(lvl, g.dof)
        assert accepts / trials <= lvl + 0.03


def test_a_large_gain_held_by_one_transient_counts_by_its_size():
    # The evidence of a step's relaxation lies in a few hundred samples of a long record:
    # against white noise it is significant (the issue of a t over sixteen batches).
    rng = np.random.default_rng(5)
    n = 20000
    noise = rng.normal(0.0, 0.005, n)
    relax = np.zeros(n)
    relax[10000:10400] = 0.05 * np.exp(-np.arange(400) / 100.0)
    g = gain(_cv(noise), _cv(noise + relax))
    assert g.statistic > threshold(level(0.05, 12, 4), g.dof)


def test_a_slow_gain_that_follows_a_slow_residual_is_weighed_by_few_independent_terms():
    # A candidate that bends with a slow drift the reference leaves: the drift's own
    # dependence makes the gain a few independent terms, not thousands.
    rng = np.random.default_rng(6)
    n = 20000
    t = np.linspace(0.0, 1.0, n)
    drift = 0.05 * np.sin(2 * np.pi * 1.5 * t + 1.0)
    white = rng.normal(0.0, 0.005, n)
    ref = drift + white
    cand = drift * 0.8 + white
    g = gain(_cv(cand), _cv(ref))
    fast = gain(_cv(white), _cv(white + 0.2 * drift * np.sign(np.sin(2 * np.pi * 400 * t))))
    assert g.dof < 100 < fast.dof


def test_min_share_a_significant_gain_must_remove_a_share_of_the_error_beyond_the_noise():
    rng = np.random.default_rng(7)
    n = 8000
    noise = rng.normal(0.0, 0.01, n)
    misfit = 0.05 * np.sin(np.linspace(0, 30, n))
    ref = noise + misfit
    small = noise + 0.97 * misfit
    g = gain(_cv(small), _cv(ref))
    verdict = _judge(g, noise_um=0.01)
    assert g.statistic > verdict.threshold and not verdict.accepted and "beyond the noise" in verdict.reason
    assert _judge(gain(_cv(noise + 0.3 * misfit), _cv(ref)), noise_um=0.01).accepted


def test_a_gain_no_fold_can_give_never_accepts():
    ref, cand = np.ones(100), np.zeros(100)
    folds = Folds(100, (50,))
    none = gain(_cv(cand, folds, (False,)), _cv(ref, folds))
    verdict = _judge(none)
    assert not verdict.accepted and "cannot judge" in verdict.reason


def test_a_fold_whose_refit_did_not_converge_is_left_out_of_the_comparison():
    rng = np.random.default_rng(8)
    folds = Folds(2000, (0, 1000))
    ref, cand = rng.normal(0.0, 2.0, 2000), rng.normal(0.0, 1.0, 2000)
    left = gain(_cv(cand, folds), _cv(ref, folds, (False, True)))
    assert left.samples == 1000
    assert left.mean_um2 == pytest.approx(np.mean(ref[1000:] ** 2) - np.mean(cand[1000:] ** 2))
    assert np.isnan(left.fold_um2[0])


def test_the_level_spends_alpha_over_every_move_of_every_round():
    assert level(0.05, 10, 1) == pytest.approx(0.05 / 20) and level(0.05, 10, 3) == pytest.approx(0.05 / 80)
    # However many rounds a search takes, of however many moves, it spends at most α.
    assert sum(level(0.05, m, r) * m for r, m in enumerate([11, 12, 9, 13, 10, 8, 12, 11, 10, 9], start=1)) < 0.05
    assert threshold(level(0.05, 20, 1), 1000) > threshold(level(0.05, 10, 1), 1000)
    assert level(0.05, 4) == pytest.approx(0.05 / 4)
    assert threshold(0.01, 5) > threshold(0.01, 1000)


def test_two_candidates_within_the_margin_are_not_apart():
    rng = np.random.default_rng(9)
    n = 4000
    noise = rng.normal(0.0, 0.01, n)
    a, b = noise + 1e-4, noise - 1e-4
    assert not apart(_cv(a), _cv(b), 1e-3)
    assert apart(_cv(noise), _cv(noise + 0.05 * np.sin(np.linspace(0, 50, n))), 1e-3)


def _record_with_drift(seed=5):
    rng = np.random.default_rng(seed)
    dt, n = 1e-3, 3000
    t = np.arange(n) * dt
    u = 50.0 + 40.0 * np.sin(2 * np.pi * 2 * t)
    drift = EffectSet(drift={"rate_um_per_s": 0.3})
    x = simulate_extended(Params.paper_1hz(), drift, u, dt) + rng.normal(0.0, 0.005, n)
    return validate_record(u, x, dt), drift


def test_the_held_out_error_is_that_of_refits_on_the_past_written_out_here():
    record, drift = _record_with_drift()
    conv = fits.Convergence()
    fit = fits.refit(record, ExtendedFit(Params.paper_1hz(), drift, 0.0, 0, 0, 0, True), drift, conv)
    solved = fits.solved_at(record, fit)
    folds = Folds.of(record, 4, 0.5, solved.jacobian)
    model = fits.scored(record, solved, folds, conv, exact=True)
    expected = np.full(len(record), np.nan)
    for k in range(folds.count):
        weights = np.zeros(len(record))
        weights[folds.train(k)] = 1.0
        out = solve_extended_record(record, fit.params, fit.effects, fit.h0, max_nfev=200, weights=weights)
        sl = folds.test(k)
        expected[sl] = record.x[sl] - out.x[sl]
    # Counted as a user carries the model: less the record's offset and trend there.
    expected = less_record_part(expected, record.t)[0]
    np.testing.assert_allclose(model.cv.residual, expected, atol=2e-3 * float(np.std(record.x)))
    assert all(model.cv.converged) and folds.count == 4
    assert np.isnan(model.cv.residual[: folds.origins[0]]).all()
    # The screen (the refit's first step) lands where the refits do on this record.
    screened = fits.scored(record, solved, folds, conv)
    assert not screened.cv.exact and model.cv.exact
    assert screened.cv.rms_um == pytest.approx(model.cv.rms_um, rel=0.02)


def test_the_records_own_offset_and_trend_are_taken_out_and_what_the_input_drives_is_left():
    t = np.arange(2000) * 1e-3
    driven = 0.3 * np.sin(2 * np.pi * 7 * t)
    r = np.where(t >= 0.5, driven + 0.4 - 0.2 * t, np.nan)  # nan: no fold predicts there
    left, offset, trend = less_record_part(r, t)
    assert np.isnan(left[t < 0.5]).all()
    assert offset == pytest.approx(0.4 - 0.2 * 0.5, abs=0.01) and trend == pytest.approx(-0.2, abs=0.02)
    # What follows the input stays (a line takes out almost none of it).
    np.testing.assert_allclose(left[t >= 0.5], driven[t >= 0.5], atol=0.02)
    # Two samples: the offset alone, so that an error is left to count.
    left2, _, trend2 = less_record_part(np.array([1.0, 2.0]), np.array([0.0, 1.0]))
    assert trend2 == 0.0 and left2 == pytest.approx([-0.5, 0.5])
    assert np.isnan(less_record_part(np.full(3, np.nan), np.arange(3.0))[0]).all()
