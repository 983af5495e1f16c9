"""boucwen.experiments.long_run: its tools, and the shortened long run (the
experiment's ``--quick`` version: 3 repeats of the paper's schedule and 10⁵ samples
of band-limited random input, noise 0 and 5 nm, every method: 1.6·10⁶ pushes in all).

The shortened run takes about a minute (marked ``slow``; CI runs it). Its three
targets are asserted per method: every estimate in the region where the model is well
posed, ≥ 95 % of pushes on the integrator's explicit path, and the period-ahead error
≤ 2 × the traditional model's on every repeat and frequency. The last one does not
hold for the paper method with its short window N = 50 (see the xfail reason); that
case is a strict xfail, so a change that makes it hold shows up. With N = 5000 it holds. Over the full 30 repeats
(``python -m boucwen.experiments.long_run``) both horizon forms hold all three; rpem
misses the 2 x at 1 and 10 Hz on 4 of the 30 repeats (transient episodes after the
200 Hz parts, worst 9.7 x, median 1.14 x); three repeats do not show that.
"""

import math

import numpy as np
import pytest

import boucwen
from boucwen import evaluation, plant
from boucwen.experiments import long_run as lr

DT = plant.DEFAULT_DT


def test_scores_from_a_recorded_run_are_those_of_period_ahead():
    u_cmd, segments = lr.repeated_schedule(1)
    rec = plant.measure(u_cmd, DT, lr.bench(0.001), seed=4)
    init = boucwen.Params.paper_1hz()
    for case in lr.default_cases((50,)):
        run = lr.record_run(case.make(DT, init, 0.0), rec.u, rec.x, lr.period_bounds(segments, DT))
        ours = lr.scores_from_record(run, rec.u, rec.x, DT, segments)
        score, per_period, one_step = evaluation.period_ahead(case.make(DT, init, 0.0), rec.u, rec.x, DT, segments)
        np.testing.assert_array_equal(run.predictions, one_step)
        for f, errors, s in ours:
            assert per_period[evaluation.key(f)] == errors
            assert score[evaluation.key(f)] == s


def test_random_input_is_band_limited_within_0_to_100_v():
    u = lr.random_input(200_000, DT, seed=2)
    assert u.size == 200_000 and u.min() >= 0.0 and u.max() <= 100.0
    assert abs(u.mean() - 50.0) < 2.0 and 14.0 < u.std() < 18.0
    assert np.mean((u == 0.0) | (u == 100.0)) < 0.01
    spectrum = np.abs(np.fft.rfft(u - u.mean())) ** 2
    freqs = np.fft.rfftfreq(u.size, DT)
    # A 4th-order low-pass at 100 Hz: about 9 % of the power above 100 Hz, 0.1 % above 200 Hz.
    assert spectrum[freqs > 100.0].sum() < 0.15 * spectrum.sum()
    assert spectrum[freqs > 300.0].sum() < 1e-3 * spectrum.sum()
    np.testing.assert_array_equal(u, lr.random_input(200_000, DT, seed=2))


def test_the_paper_method_keeps_delta_bounded_on_the_bench():
    """On noise-free bench data at 1 Hz (windows of 0.1 to 1 s) step 2's two-column fit
    trades A + kv for δ; without max_delta_ratio δ goes beyond ten times the scale the
    rate term allows (≈ 0.4 µm/(V·s), below), with it δ stays where δ·u does not
    outweigh the rate term. The paper's steps alone (no output gate, stroke bound or
    window fit, which hold or replace such updates for reasons of their own), so that
    the bound is what is measured."""
    u_cmd, _ = lr.repeated_schedule(1)
    rec = plant.measure(u_cmd[:30_000], DT, lr.bench(0.0), seed=0)
    trad = boucwen.fit(rec.u, rec.x, DT, seed=0, n_candidates=16, n_starts=2)
    start = lr.project(trad.params)
    for window in (1000, 5000):
        largest = {}
        for bound in (math.inf, boucwen.PaperConfig().max_delta_ratio):
            config = boucwen.PaperConfig(
                max_delta_ratio=bound, output_gate=math.inf, min_stroke_frac=0.0, fit_iterations=0
            )
            run = lr.record_run(boucwen.Identifier.paper(DT, window, start, trad.h0, config=config), rec.u, rec.x)
            largest[bound] = float(np.max(np.abs(run.params[:, 6])))
        # At 1 Hz over 0–100 V, |A + kv|·rms(u̇)/rms(u) ≈ 0.11 µm/V · 3.6 /s ≈ 0.4 µm/(V·s):
        # unbounded, δ goes past ten times that; bounded, it stays within a few times it
        # (the bound compares δ·u with the rate term sample by sample, not in rms).
        assert largest[math.inf] > 10 * 0.4, largest
        assert largest[1.0] < 3 * 0.4, largest


@pytest.fixture(scope="module")
def quick_run():
    return lr.run(**lr.quick_options())


CASES = [c.label for c in lr.quick_options()["cases"]]
PAPER_REASON = (
    "paper method, N = 50: kv, x0 are a local line through a short window (kv from -21 to 22 µm/V), "
    "and the period-ahead error at 1 Hz is many times the traditional's"
)


def _xfail(label):
    # With the window fit (a short Gauss–Newton fit of the window's samples beside the
    # paper's steps) the long window N = 5000 holds the 2 x; the short one does not.
    if label == "paper N=50":
        return pytest.mark.xfail(strict=True, reason=PAPER_REASON)
    return ()


def _runs(results, label):
    runs = [r for r in results["runs"] if r["case"] == label]
    assert {(r["input"], r["noise_um"]) for r in runs} == {
        ("schedule", 0.0),
        ("schedule", 0.005),
        ("random", 0.0),
        ("random", 0.005),
    }
    return runs


@pytest.mark.slow
@pytest.mark.parametrize("label", CASES)
def test_estimates_stay_where_the_model_is_well_posed(quick_run, label):
    for r in _runs(quick_run, label):
        reg = r["region"]
        assert reg["ok"], (r["input"], r["noise_um"], reg)
        assert reg["min_beta_plus_gamma"] > 0 and reg["min_beta_minus_gamma"] > 0
        assert lr.N_BOUNDS[0] <= reg["n_min"] <= reg["n_max"] <= lr.N_BOUNDS[1]


@pytest.mark.slow
@pytest.mark.parametrize("label", CASES)
def test_at_least_95_percent_of_pushes_take_the_explicit_path(quick_run, label):
    for r in _runs(quick_run, label):
        assert 1.0 - r["implicit_share"] >= 0.95, (r["input"], r["noise_um"], r["implicit_share"])


@pytest.mark.slow
@pytest.mark.parametrize("label", [pytest.param(c, marks=_xfail(c)) for c in CASES])
def test_period_ahead_error_within_twice_the_traditional(quick_run, label):
    for r in _runs(quick_run, label):
        worst = {f: v["worst"] for f, v in r["ratio_traditional"].items()}
        assert all(v <= 2.0 for v in worst.values()), (r["input"], r["noise_um"], worst)
