"""The admissible region (boucwen.region; docs/design.md, "The admissible region"): the
rule, the bounds it guarantees (property tests), and a fitted model that ran away —
β + γ < 0, n = 6 — refused at fit time, at load time, by the inverse and by the online
identifiers."""

import json
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from boucwen import (
    EffectSet,
    Identifier,
    InvalidParams,
    Params,
    fit,
    invert,
    load_model,
    simulate,
    simulate_extended,
)
from boucwen.boundedness import check_model
from boucwen.cli import main
from boucwen.effects import Layout, fit_extended
from boucwen.model_file import SavedModel
from boucwen.record import Record
from boucwen.region import hysteresis_bound, pair, travel_bound

DT = 1e-4
#: A model a fit returned on a PRBS record of a real-time positioner (β + γ = −0.0242,
#: n = 6 on the fit's bound): for a rising voltage and h > 0,
#: dh/dt = u̇·(A + 0.0242·h⁶), which escapes once h > (0.043/0.0242)^(1/6) = 1.10 µm.
RUNAWAY = Params(0.057, 0.0, -0.043, 0.0018, -0.026, 6.0, 0.0)
#: An initial state past the escape level (a state another record leaves behind).
ESCAPED_H0 = 1.2
#: The core holds h within ±1e4 µm so that a runaway stays finite.
H_LIMIT_UM = 1e4


def triangle(n, slew, lo=0.0, hi=100.0):
    """A triangle from ``lo`` up to ``hi`` and back [V] at ``slew`` [V/s], n samples."""
    span = hi - lo
    phase = np.mod(np.arange(n) * DT * slew, 2.0 * span)
    return lo + np.where(phase <= span, phase, 2.0 * span - phase)


def prbs(n, seed, lo, hi, hold=10):
    """A two-level random sequence held ``hold`` samples per level [V]."""
    levels = np.random.default_rng(seed).choice([lo, hi], n // hold + 1)
    return np.repeat(levels, hold)[:n]


def h_of(p, u, h0):
    x, _ = simulate(p, u, DT, h0)
    return x - p.kv * u - p.x0


@pytest.fixture(scope="module")
def runaway_record():
    """The runaway model on a PRBS of 40–60 V at 10 kHz (its h stays below the escape
    level), 1 nm of noise: a record a bounded model fits as well as the runaway."""
    u = prbs(5000, 0, 40.0, 60.0)
    x = simulate(RUNAWAY, u, DT, 0.0)[0] + 1e-3 * np.random.default_rng(1).standard_normal(u.size)
    return Record(t=np.arange(u.size) * DT, u=u, x=x, dt=DT, name="runaway")


def test_the_runaway_runs_away():
    # The construction is a real runaway: a fast rising triangle from an escaped state
    # drives h to the core's limit, while on the PRBS record it stays bounded.
    assert np.max(np.abs(h_of(RUNAWAY, triangle(2000, 2e4), ESCAPED_H0))) >= H_LIMIT_UM
    assert np.max(np.abs(h_of(RUNAWAY, prbs(5000, 0, 40.0, 60.0), 0.0))) < 1.1


def test_the_rule():
    Params.paper_1hz().check_admissible()
    linear = Params(0.2, 0.0, 0.0, 0.0, 0.0, 1.5, 0.0)
    linear.check_admissible()
    with pytest.raises(InvalidParams, match=r"beta \+ gamma = 0"):
        linear.replace(delta=0.01).check_admissible()
    with pytest.raises(InvalidParams, match=r"beta \+ gamma = -0\.024") as err:
        RUNAWAY.check_admissible()
    assert "\n" not in str(err.value)
    with pytest.raises(InvalidParams, match="beta - gamma"):
        RUNAWAY.replace(gamma=0.026).check_admissible()


def test_fits_refuse_a_runaway_start(runaway_record):
    r = runaway_record
    with pytest.raises(InvalidParams, match=r"beta \+ gamma"):
        fit(r.u, r.x, DT, init=RUNAWAY)
    with pytest.raises(InvalidParams, match=r"beta \+ gamma"):
        fit_extended(r.u, r.x, DT, RUNAWAY, EffectSet())


def test_the_fit_stays_in_the_region_where_the_record_came_from_a_runaway(runaway_record):
    r = runaway_record
    result = fit(r.u, r.x, DT, n_candidates=16, seed=0)
    p = result.params
    p.check_admissible()
    plus, minus = pair(p.beta, p.gamma)
    assert plus >= 0.0 and minus >= 0.0
    # It fits the record about as well as the model that made it (the noise is 1 nm).
    assert result.rms_um < 0.05
    # And stays bounded where the runaway does not: the fast triangle, even from the
    # escaped state, stays within the region's bound.
    u = triangle(2000, 2e4)
    for h0 in (result.h0, ESCAPED_H0):
        bound = hysteresis_bound(p, h0, 100.0, 2e4) if p.delta != 0.0 else travel_bound(p, h0, 100.0)
        assert np.max(np.abs(h_of(p, u, h0))) <= bound * (1 + 1e-6)
    # The check tells the runaway apart: its fast triangle reaches the core's limit.
    runaway = check_model(r, RUNAWAY, EffectSet(), ESCAPED_H0)
    assert not runaway.passed and runaway.worst.peak_um >= H_LIMIT_UM
    fitted = check_model(r, p, EffectSet(), result.h0)
    assert all(probe.peak_um < H_LIMIT_UM for probe in fitted.probes)


def test_the_extended_fit_keeps_to_the_region(runaway_record):
    r = runaway_record
    start = Params(0.05, 0.0, -0.04, 0.001, 0.0005, 2.0, 0.0)
    fitted = fit_extended(r.u, r.x, DT, start, EffectSet(creep={"tau_s": [1e-3, 0.1], "gain_um_per_v": [0.0, 0.0]}))
    fitted.params.check_admissible()
    layout = Layout.of(fitted.effects, DT, r.duration_s)
    assert layout.labels()[3:5] == ["beta_plus_gamma", "beta_minus_gamma"]
    lo, _ = layout.bounds()
    assert lo[3] == 0.0 and lo[4] == 0.0


def test_the_layout_jacobian_is_that_of_beta_plus_and_minus_gamma(runaway_record):
    r = runaway_record
    p = Params.paper_1hz()
    layout = Layout.of(EffectSet(), DT, r.duration_s)
    v = layout.pack(p, EffectSet(), 0.1)
    assert v[3] == pytest.approx(p.beta + p.gamma) and v[4] == pytest.approx(p.beta - p.gamma)
    back, _, _ = layout.unpack(v)
    assert back.beta == pytest.approx(p.beta) and back.gamma == pytest.approx(p.gamma)
    u = r.u[:2000]
    _, jac = layout.simulate_with_jacobian(v, u, DT)
    for k in (3, 4):
        step = 1e-6
        up, down = v.copy(), v.copy()
        up[k] += step
        down[k] -= step
        numeric = (layout.simulate(up, u, DT) - layout.simulate(down, u, DT)) / (2 * step)
        assert np.max(np.abs(numeric - jac[:, k])) <= 1e-4 * max(np.max(np.abs(numeric)), 1e-9)


def test_the_loader_and_the_cli_refuse_a_runaway_file(tmp_path):
    with pytest.raises(InvalidParams, match=r"beta \+ gamma"):
        SavedModel(RUNAWAY, 0.0, DT)
    path = tmp_path / "runaway.json"
    doc = SavedModel(Params.paper_1hz(), 0.0, DT).to_dict()
    doc["params"] = RUNAWAY.to_dict()
    path.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(InvalidParams) as err:
        load_model(path)
    message = str(err.value)
    assert "\n" not in message and str(path) in message and "'params'" in message and "beta + gamma" in message
    u_csv = tmp_path / "u.csv"
    u_csv.write_text("t,u\n" + "\n".join(f"{k * DT},{v}" for k, v in enumerate(triangle(200, 2e4))), encoding="utf-8")
    for argv in (
        ["simulate", "--model", str(path), str(u_csv), "--out", str(tmp_path / "x.csv")],
        ["invert", "--model", str(path), "--target", str(u_csv), "--out", str(tmp_path / "u2.csv")],
    ):
        assert main(argv) == 2


def test_the_cli_says_one_line(tmp_path, capsys):
    path = tmp_path / "runaway.json"
    doc = SavedModel(Params.paper_1hz(), 0.0, DT).to_dict()
    doc["params"] = RUNAWAY.to_dict()
    path.write_text(json.dumps(doc), encoding="utf-8")
    u_csv = tmp_path / "u.csv"
    u_csv.write_text("t,u\n0,0\n0.0001,1\n0.0002,2\n", encoding="utf-8")
    assert main(["simulate", "--model", str(path), str(u_csv), "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "beta + gamma" in err and "Traceback" not in err


def test_the_inverse_refuses_a_runaway():
    with pytest.raises(InvalidParams, match=r"beta \+ gamma"):
        invert(RUNAWAY, np.linspace(0.0, 5.0, 100), DT)


@pytest.mark.parametrize(
    "make",
    [
        lambda p: Identifier(DT, p),
        lambda p: Identifier.horizon(DT, p),
        lambda p: Identifier.rpem(DT, p),
        lambda p: Identifier.paper(DT, 500, p),
    ],
    ids=["default", "horizon", "rpem", "paper"],
)
def test_the_identifiers_refuse_a_runaway_start(make):
    with pytest.raises(InvalidParams, match=r"beta \+ gamma"):
        make(RUNAWAY)


@pytest.mark.parametrize("method", ["horizon", "rpem"])
def test_the_identifiers_keep_to_the_region_on_the_runaways_record(runaway_record, method):
    r = runaway_record
    start = Params(0.05, 0.0, -0.04, 0.001, 0.0005, 2.0, 0.0)
    ident = getattr(Identifier, method)(DT, start)
    margin = ident.config.margin
    stopped_at_edge = 0
    for u, x in zip(r.u, r.x):
        ident.push(float(u), float(x))
        p = ident.params
        plus, minus = pair(p.beta, p.gamma)
        assert plus >= margin * (1 - 1e-9) and minus >= margin * (1 - 1e-9)
        s = ident.status
        stopped_at_edge += bool(s.projected or getattr(s, "held", False))
    # The record asks for β + γ < 0: the updates meet the region's edge, and the status
    # says so.
    assert stopped_at_edge > 0


# --------------------------------------------------------------------------- properties


@st.composite
def admissible(draw):
    """Parameters in the region: β ± γ > 0 (log-uniform over three decades), n in
    [1, 4] (below 1 see :func:`test_below_n_1_a_stiff_interval_can_overshoot`), A and δ
    of either sign (δ = 0 for a third of the draws)."""
    plus = 10 ** draw(st.floats(-3.0, 0.0))
    minus = 10 ** draw(st.floats(-3.0, 0.0))
    beta, gamma = 0.5 * (plus + minus), 0.5 * (plus - minus)
    a = draw(st.floats(-0.3, 0.3))
    n = draw(st.floats(1.0, 4.0))
    delta = draw(st.one_of(st.just(0.0), st.floats(-0.05, 0.05)))
    return Params(draw(st.floats(0.0, 0.3)), draw(st.floats(-1.0, 1.0)), a, beta, gamma, n, delta)


def bounded_input(seed, n, u_max, slew):
    """A random voltage within ±u_max [V]: each interval holds (a fifth of them) or
    moves by at least slew·dt, never beyond the range."""
    rng = np.random.default_rng(seed)
    step_min = slew * DT
    u = np.empty(n)
    u[0] = rng.uniform(-u_max, u_max)
    for k in range(1, n):
        if rng.random() < 0.2:
            u[k] = u[k - 1]
            continue
        d = rng.uniform(step_min, max(step_min, min(20.0 * step_min, u_max)))
        d = d if rng.random() < 0.5 else -d
        u[k] = u[k - 1] + d if abs(u[k - 1] + d) <= u_max else u[k - 1] - d
    return u


@given(
    p=admissible(),
    h0=st.floats(-2.0, 2.0),
    seed=st.integers(0, 2**31 - 1),
    u_max=st.floats(1.0, 100.0),
    slew=st.floats(10.0, 1e5),
)
def test_h_stays_within_the_regions_bound(p, h0, seed, u_max, slew):
    slew = min(slew, u_max / DT)  # one interval can move at most across the range
    u = bounded_input(seed, 1500, u_max, slew)
    h = h_of(p, u, h0)
    assert np.all(np.isfinite(h))
    # The slowest slew of the input while it moves (holds are free).
    moves = np.abs(np.diff(u))
    slowest = float(np.min(moves[moves > 0])) / DT if np.any(moves > 0) else slew
    bound = hysteresis_bound(p, h0, float(np.max(np.abs(u))), slowest)
    tol = 1e-6 * max(bound, 1.0)
    assert np.max(np.abs(h)) <= bound + tol
    if p.delta == 0.0:
        assert np.max(np.abs(h)) <= travel_bound(p, h0, float(np.ptp(u))) + tol


@given(
    p=admissible(),
    h0=st.floats(-2.0, 2.0),
    seed=st.integers(0, 2**31 - 1),
    fc=st.floats(20.0, 4000.0),
    gains=st.lists(st.floats(-0.1, 0.1), min_size=1, max_size=3),
)
def test_the_chain_with_creep_and_a_lag_stays_bounded(p, h0, seed, fc, gains):
    # With δ = 0 the hysteresis is rate-independent: behind the lag it sees u_a, within
    # the command's range, so |h| ≤ |h0| + |A|·span; each creep element stays within its
    # gain times the voltage.
    p = p.replace(delta=0.0)
    u_max = 100.0
    u = bounded_input(seed, 1500, u_max, 1e3)
    taus = [10.0 ** (-3 + k) for k in range(len(gains))]
    effects = EffectSet(input_lag={"fc_hz": fc}, creep={"tau_s": taus, "gain_um_per_v": gains})
    x = np.asarray(simulate_extended(p, effects, u, DT, h0))
    assert np.all(np.isfinite(x))
    bound = abs(p.kv) * u_max + abs(p.x0) + travel_bound(p, h0, float(np.ptp(u))) + sum(abs(g) for g in gains) * u_max
    assert np.max(np.abs(x)) <= bound * (1 + 1e-6) + 1e-9


def test_the_saturation_bound_is_reached():
    # The bound is not loose: a slow full-range sweep takes h to within a percent of hs.
    p = Params.paper_1hz().replace(delta=0.0)
    hs = (abs(p.A) / (p.beta - p.gamma)) ** (1.0 / p.n)
    u = np.concatenate([np.linspace(0.0, 100.0, 5000), np.linspace(100.0, 0.0, 5000)])
    h = h_of(p, u, 0.0)
    assert hysteresis_bound(p, 0.0, 100.0, 100.0 / (5000 * DT)) == pytest.approx(hs)
    assert 0.95 * hs <= np.max(np.abs(h)) <= hs * (1 + 1e-9)
    assert math.isfinite(hs)


@pytest.mark.xfail(
    strict=True,
    reason="known: for n < 1 the slope n·|h|^(n−1) is unbounded at h = 0, and an interval whose move "
    "is many times the saturation level (A·Δu = 9 hₛ here) takes the implicit step, whose Newton "
    "iterations can end on the wrong side of zero: h lands 36 hₛ (8.8 nm) off, still within the "
    "travel bound, back on the loop a sample later",
)
def test_below_n_1_a_stiff_interval_can_overshoot():
    p = Params(0.0, 0.0, 0.015625, 0.55, 0.45, 0.5, 0.0)
    u = bounded_input(0, 1500, 3.0, 1452.0)
    h = h_of(p, u, 0.0)
    assert np.max(np.abs(h)) <= travel_bound(p, 0.0, float(np.ptp(u)))
    assert np.max(np.abs(h)) <= hysteresis_bound(p, 0.0, 3.0, 1452.0) * (1 + 1e-6)
