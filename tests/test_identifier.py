"""boucwen.Identifier (the paper's online method): streaming contract, bad samples,
constant input, and adaptation on data simulated from known parameters."""

import math

import numpy as np
import pytest

import boucwen
from boucwen import Params
from conftest import make_identifier

DT = 1e-4  # 10 kHz
PAPER = Params.paper_1hz()

# Steady-state stretches of the paper's input, each starting one period of its
# frequency after the switch (the paper's "adaptive state"), in seconds.
SEGMENTS = {1: (2.0, 3.0), 10: (3.1, 3.3), 100: (3.31, 3.33), 200: (3.335, 3.38)}


@pytest.fixture(scope="module")
def paper_record():
    u = boucwen.paper_input(DT, 0.05)
    x, _ = boucwen.simulate(PAPER, u, DT)
    return u, x


def _segment_errors(pred, x):
    t = np.arange(x.size) * DT
    return {f: float(np.max(np.abs(pred - x)[(t >= a) & (t < b)])) for f, (a, b) in SEGMENTS.items()}


def _noisy_loop(samples=3000, dt=1e-3, seed=0):
    """A 1 Hz then 3 Hz loop simulated with the paper's parameters, plus 2 nm noise."""
    k = np.arange(samples)
    f = np.where(k < samples // 2, 1.0, 3.0)
    u = 50.0 + 50.0 * np.sin(2 * np.pi * np.cumsum(f) * dt - np.pi / 2)
    x, _ = boucwen.simulate(PAPER, u, dt)
    return u, x + 0.002 * np.random.default_rng(seed).standard_normal(samples)


def _same_state(a, b):
    assert a.params == b.params
    assert a.h == b.h
    assert a.status == b.status


# -- the streaming contract ---------------------------------------------------------


@pytest.mark.parametrize("decomposition", ["model", "line"])
def test_push_many_equals_a_loop_of_push(decomposition):
    u, x = _noisy_loop()
    one = make_identifier("paper", 1e-3, 200, PAPER, decomposition=decomposition)
    many = make_identifier("paper", 1e-3, 200, PAPER, decomposition=decomposition)
    looped = np.array([one.push(float(a), float(b)) for a, b in zip(u, x)])
    # in uneven chunks, to cover the boundaries too
    chunks = [many.push_many(u[a:b], x[a:b]) for a, b in [(0, 1), (1, 777), (777, 778), (778, u.size)]]
    np.testing.assert_array_equal(np.concatenate(chunks), looped)
    _same_state(one, many)
    assert isinstance(one.status, boucwen.PaperStatus) and one.status.samples == u.size


def test_first_prediction_uses_the_initial_estimates_and_h0():
    ident = make_identifier("paper", DT, 64, PAPER, h0=0.3)
    assert ident.push(10.0, 123.0) == PAPER.kv * 10.0 + PAPER.x0 + 0.3
    assert ident.h == 0.3  # the first sample has no predecessor to integrate from
    assert ident.method == "paper"


def test_reset_returns_to_the_state_after_construction(paper_record):
    u, x = paper_record
    fresh, used = make_identifier("paper", DT, 500, PAPER), make_identifier("paper", DT, 500, PAPER)
    used.push_many(u[:3000], x[:3000])
    used.reset()
    _same_state(used, fresh)
    np.testing.assert_array_equal(used.push_many(u[:1500], x[:1500]), fresh.push_many(u[:1500], x[:1500]))


# -- bad samples leave no trace -----------------------------------------------------


@pytest.mark.parametrize("bad_u, bad_x", [(math.nan, 1.0), (1.0, math.nan), (math.inf, 1.0), (1.0, -math.inf)])
def test_non_finite_sample_raises_and_changes_nothing(bad_u, bad_x):
    u, x = _noisy_loop(samples=1500)
    ident = make_identifier("paper", 1e-3, 200, PAPER)
    twin = make_identifier("paper", 1e-3, 200, PAPER)
    ident.push_many(u[:1000], x[:1000])
    twin.push_many(u[:1000], x[:1000])
    with pytest.raises(ValueError, match="not finite"):
        ident.push(bad_u, bad_x)
    _same_state(ident, twin)
    # The next predictions are those of an identifier that never saw the bad sample.
    np.testing.assert_array_equal(ident.push_many(u[1000:], x[1000:]), twin.push_many(u[1000:], x[1000:]))
    _same_state(ident, twin)


def test_push_many_with_a_non_finite_value_anywhere_rejects_the_whole_call():
    u, x = _noisy_loop(samples=1500)
    ident, twin = make_identifier("paper", 1e-3, 200, PAPER), make_identifier("paper", 1e-3, 200, PAPER)
    ident.push_many(u[:700], x[:700])
    twin.push_many(u[:700], x[:700])
    bad = x[700:].copy()
    bad[-1] = math.nan  # the very last value: nothing before it may be used either
    with pytest.raises(ValueError, match=r"\bx\b"):
        ident.push_many(u[700:], bad)
    _same_state(ident, twin)
    with pytest.raises(ValueError):
        ident.push_many(u[700:], x[701:])  # lengths differ
    _same_state(ident, twin)
    np.testing.assert_array_equal(ident.push_many(u[700:], x[700:]), twin.push_many(u[700:], x[700:]))


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(dt=0.0), "dt"),
        (dict(dt=math.nan), "dt"),
        (dict(window=15), "window"),
        (dict(h0=math.inf), "h0"),
        (dict(decomposition="circle"), "decomposition"),
        (dict(min_points=1), "min_points"),
        (dict(min_points=10_000), "min_points"),
        (dict(h_zero_frac=-0.1), "h_zero_frac"),
        (dict(rate_frac=math.nan), "rate_frac"),
        (dict(min_r2=math.inf), "min_r2"),
        (dict(n_bounds=(2.0, 1.0)), "n_bounds"),
        (dict(n_bounds=(0.0, 1.0)), "n_bounds"),
    ],
)
def test_bad_configuration_raises_value_error_naming_it(kwargs, word):
    args = dict(dt=DT, window=100, init=PAPER)
    args.update(kwargs)
    with pytest.raises(ValueError, match=word):
        make_identifier("paper", **args)


# -- constant input -------------------------------------------------------------------


def test_long_constant_input_from_the_start_gives_no_nan_and_keeps_the_initial_estimates():
    ident = make_identifier("paper", DT, 1000, PAPER)
    pred = ident.push_many(np.full(100_000, 20.0), np.full(100_000, 3.8))
    assert np.all(np.isfinite(pred))
    assert ident.params == PAPER
    assert np.all(pred == PAPER.kv * 20.0 + PAPER.x0)  # h stands still while u holds
    status = ident.status
    assert status.window_full
    assert [s.outcome for s in status.steps().values()] == ["held"] * 6
    assert status.line_fit.reason == "no_excitation"


@pytest.mark.parametrize("window", [1000, 10_000])
def test_constant_input_after_a_loop_holds_the_estimates(paper_record, window):
    u, x = paper_record
    ident = make_identifier("paper", DT, window, PAPER)
    ident.push_many(u[:20_000], x[:20_000])
    u_hold, x_hold = float(u[19_999]), float(x[19_999])
    # While the old points leave the window the estimates may still move; once
    # the window holds only the constant sample, nothing may change any more.
    ident.push_many(np.full(window + 2, u_hold), np.full(window + 2, x_hold))
    settled, h = ident.params, ident.h
    pred = ident.push_many(np.full(100_000, u_hold), np.full(100_000, x_hold))
    assert np.all(np.isfinite(pred)) and np.all(pred == pred[0])
    assert ident.params == settled and ident.h == h
    assert all(math.isfinite(v) for v in settled.to_array())


# -- adaptation ------------------------------------------------------------------------


def test_started_from_the_known_parameters_with_n_held_it_keeps_the_error_below_the_papers(
    paper_record,
):
    """Data simulated with the paper's 1 Hz parameters over the paper's input (1 → 10 →
    100 → 200 Hz); the identifier starts from those parameters, N = 10 000 (one 1 Hz
    period), n held (``n_bounds`` pinned: step 3 is where the method breaks, see
    ``test_on_exact_data_the_truth_stays_an_estimate_of_the_truth``). Measured maximum
    error per segment after one period of adaptation: 0.016, 0.256, 0.444, 0.377 µm
    (at 100 and 200 Hz the 1 s window still holds mostly older points); asserted ≤ 0.5
    µm, the paper's online figure (0.45–0.49 µm in its Table 1)."""
    u, x = paper_record
    ident = make_identifier("paper", DT, 10_000, PAPER, n_bounds=(PAPER.n, PAPER.n))
    errors = _segment_errors(ident.push_many(u, x), x)
    print("max |prediction - x| per frequency [um]:", {f: round(e, 4) for f, e in errors.items()})
    assert all(e <= 0.5 for e in errors.values()), errors
    assert errors[1] <= 0.05, errors
    assert all(math.isfinite(v) for v in ident.params.to_array())


def test_on_exact_data_the_truth_stays_an_estimate_of_the_truth(paper_record):
    """Exact data, started from the truth, N = 10 000. The paper's steps as it writes them
    (no output gate, stroke bound or window fit) move n away: step 3 fits ln|A − r| where
    A − r = (β + γ)·hⁿ is at most 2.5 % of |A| with the paper's values, so the error of A
    from steps 1–2 bends the log–log line. With the defaults every estimate stays within
    20 % of the truth."""
    u, x = paper_record
    steps = make_identifier("paper", DT, 10_000, PAPER, output_gate=math.inf, min_stroke_frac=0.0, fit_iterations=0)
    steps.push_many(u, x)
    assert abs(steps.params.n - PAPER.n) > 0.2, steps.params
    ident = make_identifier("paper", DT, 10_000, PAPER)
    ident.push_many(u, x)
    np.testing.assert_allclose(ident.params.to_array(), PAPER.to_array(), rtol=0.2, atol=1e-3)


TABLE_2 = {
    1: PAPER,
    10: Params(kv=0.18, x0=0.017, A=-0.072, beta=0.025, gamma=-0.021, n=1.53, delta=0.0067),
    100: Params(kv=0.18, x0=0.021, A=-0.072, beta=0.023, gamma=-0.018, n=1.51, delta=0.0063),
    200: Params(kv=0.16, x0=0.013, A=-0.10, beta=0.015, gamma=-0.005, n=1.68, delta=0.0045),
}


@pytest.mark.xfail(
    strict=True,
    reason="limitation of the paper's method: with the paper's Table 2 parameters switching "
    "with the frequency, its estimates at 200 Hz must come from a window wholly in the 200 Hz "
    "part (500 samples on this record), shorter than N = 2000, so its error there stays above "
    "1 µm (docs/results.md, 'What one N needs'); method='rpem' follows the switch (about 0.09 µm)",
)
def test_tracks_parameters_that_change_with_the_frequency():
    u = boucwen.paper_input(DT, 0.05)
    t = np.arange(u.size) * DT
    starts = {1: 0.0, 10: 3.0, 100: 3.3, 200: 3.33}
    ends = {1: 3.0, 10: 3.3, 100: 3.33, 200: math.inf}
    parts, h, u_prev = [], 0.0, None
    for f in (1, 10, 100, 200):
        sel = (t >= starts[f] - 1e-12) & (t < ends[f] - 1e-12)
        part, h = boucwen.simulate(TABLE_2[f], u[sel], DT, h0=h, u_prev=u_prev)
        parts.append(part)
        u_prev = float(u[sel][-1])
    x = np.concatenate(parts)
    ident = make_identifier("paper", DT, 2000, PAPER)
    errors = _segment_errors(ident.push_many(u, x), x)
    assert all(e <= 0.5 for e in errors.values()), errors


def test_on_the_bench_the_output_gate_holds_a_window_that_would_have_diverged():
    """The simulated bench (lag, creep, vibration: a plant the model does not hold), the
    paper's method at N = 500 from the paper's 1 Hz row. Without the output gate and the
    stroke bound its updates take models that fit the window worse than the ones they
    replace, or local chords of a slow loop, and the period-ahead error runs to tens of
    µm; with them (the defaults) every frequency stays within 2× of holding the starting
    model, and the status says where each held."""
    from boucwen import evaluation, plant
    from boucwen.experiments.reproduce import SEGMENTS, StepTally

    dt = plant.DEFAULT_DT
    _, u_cmd, segs = plant.paper_input(dt, SEGMENTS)
    rec = plant.measure(u_cmd, dt, plant.BenchSettings(), seed=0)
    init = Params.paper_1hz()

    def scored(**options):
        ident = boucwen.Identifier.paper(dt, 500, init, config=boucwen.PaperConfig(**options))
        tally = StepTally(dt)
        score, _, _ = evaluation.period_ahead(ident, rec.u, rec.x, dt, segs, feed=tally)
        return score, tally.statuses

    free, _ = scored(output_gate=math.inf, min_stroke_frac=0.0)
    gated, statuses = scored()
    held = evaluation.fixed_model(init, 0.0, rec.u, rec.x, dt, segs)
    assert max(free.values()) > 10.0, free
    for f in held:
        assert gated[f] <= 2.0 * held[f], (f, gated, held)
    assert any(s.line_fit.reason == "worse_output" or s.split_fit.reason == "worse_output" for s in statuses)
    assert any(s.line_fit.reason == "no_spread" for s in statuses)
