"""boucwen.reference: its own soundness, and the Rust identifier against it."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import boucwen
from boucwen import Params, reference
from conftest import make_identifier

PAPER = Params.paper_1hz()


# -- the reference itself -----------------------------------------------------------


def test_params_from_any_form_and_validation():
    as_ref = reference.RefParams.from_any(PAPER)
    assert reference.RefParams.from_any(PAPER.to_dict()) == as_ref
    assert reference.RefParams.from_any(list(PAPER.to_array())) == as_ref
    np.testing.assert_array_equal(as_ref.to_array(), PAPER.to_array())
    with pytest.raises(ValueError, match=r"\bbeta\b"):
        reference.RefParams.from_any({**PAPER.to_dict(), "beta": math.nan})
    with pytest.raises(ValueError, match=r"\bn\b"):
        reference.RefParams.from_any({**PAPER.to_dict(), "n": 0.0})
    with pytest.raises(ValueError, match="7"):
        reference.RefParams.from_any([1.0, 2.0])


def test_parareal_gives_the_step_by_step_solution():
    u = boucwen.paper_input(1e-4, 0.01)[32_900:33_500]  # 100 and 200 Hz: h crosses zero often
    seq, h_seq = reference.simulate(PAPER, u, 1e-4, h0=0.4, u_prev=0.0, substeps=100, sequential=True)
    par, h_par = reference.simulate(PAPER, u, 1e-4, h0=0.4, u_prev=0.0, substeps=100)
    # Both are the same RK4 steps; parareal stops at a residual of 1e-13 µm per interval.
    assert np.max(np.abs(seq - par)) <= 1e-10
    assert abs(h_seq - h_par) <= 1e-10


def test_halving_the_step_at_least_halves_the_change():
    """What the tests' tolerances rest on (conftest.reference_pair): on the fast part of
    the paper's record, where h crosses zero often, each halving of the step shrinks the
    change by more than 2 (RK4 on smooth parts: 16)."""
    u = boucwen.paper_input(1e-4, 0.01)[33_000:]
    x = [reference.simulate(PAPER, u, 1e-4, substeps=m)[0] for m in (4, 8, 16, 32, 64)]
    changes = [float(np.max(np.abs(a - b))) for a, b in zip(x, x[1:])]
    print("changes [µm]:", changes)
    assert all(later < 0.5 * earlier for earlier, later in zip(changes, changes[1:])), changes


def test_the_rate_is_equation_5():
    p = reference.RefParams.from_any(PAPER)
    for h, u, udot in [(0.7, 40.0, 300.0), (-0.7, 40.0, -300.0), (0.0, 10.0, 5.0), (0.3, 0.0, 0.0)]:
        want = (
            p.A * udot
            - p.beta * abs(udot) * abs(h) ** (p.n - 1) * h * (h != 0)
            - p.gamma * udot * abs(h) ** p.n
            + p.delta * u * np.sign(udot)
        )
        assert reference.hysteresis_rate(p, h, u, udot) == pytest.approx(want, rel=1e-15, abs=1e-15)


@settings(max_examples=20, deadline=None)
@given(cut=st.integers(0, 400), h0=st.floats(-1.0, 1.0))
def test_reference_simulate_streams_in_chunks(cut, h0):
    u = boucwen.paper_input(1e-4, 0.0)[30_000:30_400]
    step = dict(substeps=8, sequential=True)
    whole, h_whole = reference.simulate(PAPER, u, 1e-4, h0=h0, **step)
    a, h_a = reference.simulate(PAPER, u[:cut], 1e-4, h0=h0, **step)
    b, h_b = reference.simulate(PAPER, u[cut:], 1e-4, h0=h_a, u_prev=float(u[cut - 1]) if cut else None, **step)
    # Only h is carried from one step to the next: the same numbers, bit for bit.
    np.testing.assert_array_equal(np.concatenate([a, b]), whole)
    assert h_b == h_whole


def test_reference_rejects_bad_input():
    with pytest.raises(ValueError, match=r"\bu\b"):
        reference.simulate(PAPER, [0.0, math.nan], 1e-4)
    with pytest.raises(ValueError, match="dt"):
        reference.simulate(PAPER, [0.0, 1.0], 0.0)
    ident = reference.PaperIdentifier(1e-3, 64, PAPER)
    ident.push(1.0, 0.2)
    with pytest.raises(ValueError, match=r"\bx\b"):
        ident.push(2.0, math.inf)
    assert ident.status.samples == 1
    with pytest.raises(ValueError, match="window"):
        reference.PaperIdentifier(1e-3, 8, PAPER)


# -- the Rust identifier against the reference ----------------------------------------

# The two differ in rounding only: the Rust core keeps running window sums
# (refreshed exactly every N samples) and a recursive least-squares line fit
# (re-synchronised every N samples; its own tests bound the drift from the exact fit
# at 1e-8 relative), the reference recomputes every sum and the exact fit at each
# sample. With |u| ≤ 100 V a 1e-8 relative error in kv, x0 moves a prediction by at
# most ~1e-6 µm; observed differences are 1e-13 to 1e-11 µm. The tolerances below
# leave room for that rounding but not for a different decision: any sample
# classified differently, or a sub-fit that runs in one and not the other, shows as a
# status mismatch or a jump far above them.
PREDICTION_TOL_UM = 1e-7
PARAMS_RTOL = 1e-6


def _noisy_two_frequency_loop(samples, dt, seed=0):
    k = np.arange(samples)
    f = np.where(k < samples // 2, 1.0, 3.0)
    u = 50.0 + 50.0 * np.sin(2 * np.pi * np.cumsum(f) * dt - np.pi / 2)
    x, _ = boucwen.simulate(PAPER, u, dt)
    return u, x + 0.002 * np.random.default_rng(seed).standard_normal(samples)


ALL_FITS = {"line_fit", "rate_fit", "shape_fit", "return_fit", "split_fit"}
# The reference restates the paper's steps, not the window fit: the core without it.
STEPS_ONLY = dict(fit_iterations=0)
# Looser tolerances so that every step runs on the record of the comparisons (started
# from the truth, the output gate holds most updates: it has its own comparison below).
LOOSE = dict(min_r2=0.0, noise_gate=0.0, h_zero_frac=0.2, n_bounds=(0.01, 50.0), output_gate=math.inf)
NO_GATE = dict(output_gate=math.inf)


def _same_status(k, fast, slow):
    """The same decisions (outcome, reason, points of every step; the derivative's
    half-width) and the same scatter to rounding; ``refreshed`` is the core's own."""
    assert (fast.samples, fast.window_full, fast.half_width) == (slow.samples, slow.window_full, slow.half_width), k
    for name, a in fast.steps().items():
        b = getattr(slow, name)
        assert (a.outcome, a.reason, a.points) == (b.outcome, b.reason, b.points), (k, name, a, b)
        assert a.noise == pytest.approx(b.noise, rel=1e-6, abs=1e-9), (k, name, a, b)
    assert fast.x_noise_um == pytest.approx(slow.x_noise_um, rel=1e-6, abs=1e-12), k


@pytest.mark.parametrize(
    "dt, window, decomposition, init, options, must_run",
    [
        (2e-3, 400, "model", PAPER.replace(kv=0.17, A=-0.06), {}, {"line_fit", "return_fit"}),
        (2e-3, 400, "line", PAPER, NO_GATE, {"line_fit", "rate_fit", "return_fit"}),
        (1e-3, 300, "model", PAPER, {}, {"line_fit", "return_fit"}),
        # Looser tolerances so that every sub-fit runs, steps 2 and 3 included.
        (2e-3, 400, "model", PAPER, LOOSE, ALL_FITS),
    ],
)
def test_rust_identifier_agrees_with_the_reference(dt, window, decomposition, init, options, must_run):
    u, x = _noisy_two_frequency_loop(2500, dt)
    fast = make_identifier("paper", dt, window, init, decomposition=decomposition, **options, **STEPS_ONLY)
    slow = reference.PaperIdentifier(dt, window, init, decomposition=decomposition, **options)
    worst = 0.0
    ran = set()
    for k, (a, b) in enumerate(zip(u.tolist(), x.tolist())):
        pf, ps = fast.push(a, b), slow.push(a, b)
        worst = max(worst, abs(pf - ps))
        status = fast.status
        _same_status(k, status, slow.status)
        ran.update(key for key, v in status.steps().items() if v.outcome in ("ran", "reduced"))
    print(f"max |rust - reference| prediction: {worst:.2e} um")
    assert worst <= PREDICTION_TOL_UM
    np.testing.assert_allclose(fast.params.to_array(), slow.params.to_array(), rtol=PARAMS_RTOL, atol=1e-12)
    assert abs(fast.h - slow.h) <= PREDICTION_TOL_UM
    # The comparison covered the sub-fits, not only the prediction with fixed estimates.
    assert must_run <= ran, ran


def test_rust_identifier_agrees_with_the_reference_where_the_bounds_hold_estimates():
    """Tight physical bounds (step 5's max_hysteresis_gain, step 2's max_delta_ratio), so
    that both hold estimates on this record: the two implementations still agree sample
    by sample, and the bounds did change the outcome."""
    dt, window = 2e-3, 400
    u, x = _noisy_two_frequency_loop(2500, dt)
    loose = LOOSE
    bounds = dict(max_hysteresis_gain=1.2, max_delta_ratio=0.05)
    fast = make_identifier("paper", dt, window, PAPER, **loose, **bounds, **STEPS_ONLY)
    slow = reference.PaperIdentifier(dt, window, PAPER, **loose, **bounds)
    free = make_identifier(
        "paper", dt, window, PAPER, **loose, max_hysteresis_gain=math.inf, max_delta_ratio=math.inf, **STEPS_ONLY
    )
    worst, apart = 0.0, 0.0
    for k, (a, b) in enumerate(zip(u.tolist(), x.tolist())):
        pf, ps = fast.push(a, b), slow.push(a, b)
        worst = max(worst, abs(pf - ps))
        apart = max(apart, abs(pf - free.push(a, b)))
        _same_status(k, fast.status, slow.status)
    assert worst <= PREDICTION_TOL_UM
    np.testing.assert_allclose(fast.params.to_array(), slow.params.to_array(), rtol=PARAMS_RTOL, atol=1e-12)
    # The bounds decided something: δ stayed at its start, and the predictions moved.
    assert fast.params.delta == PAPER.delta != free.params.delta
    assert apart > 1e3 * PREDICTION_TOL_UM


def test_rust_identifier_agrees_with_the_reference_where_the_output_gate_holds():
    """The output gate on: started from the truth with the literal line decomposition
    (whose kv is the loop's centre line, not the model's), the gate holds step 1 on
    the window's own output error; the two implementations take the same decisions
    sample by sample, and the gate did decide (reason "worse_output")."""
    dt, window = 2e-3, 400
    u, x = _noisy_two_frequency_loop(2500, dt)
    fast = make_identifier("paper", dt, window, PAPER, decomposition="line", **STEPS_ONLY)
    slow = reference.PaperIdentifier(dt, window, PAPER, decomposition="line")
    worst, held = 0.0, set()
    for k, (a, b) in enumerate(zip(u.tolist(), x.tolist())):
        pf, ps = fast.push(a, b), slow.push(a, b)
        worst = max(worst, abs(pf - ps))
        _same_status(k, fast.status, slow.status)
        held.update(name for name, v in fast.status.steps().items() if v.reason == "worse_output")
    assert worst <= PREDICTION_TOL_UM
    np.testing.assert_allclose(fast.params.to_array(), slow.params.to_array(), rtol=PARAMS_RTOL, atol=1e-12)
    assert "line_fit" in held, held
