"""The paper's method on the paper-exact plant (``python -m boucwen.experiments.paper_exact``),
on the shortened record: every step runs, every push says what each step did, and the
record shows where the method breaks; the paper's figures as the experiment reads them,
and what one window N would need on the paper's record."""

import json

import numpy as np
import pytest

import boucwen
from boucwen.experiments import paper_exact
from boucwen.experiments.reproduce import PAPER_STEPS, PAPER_TABLE2, SEGMENTS


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("paper_exact")
    return paper_exact.run(out, quick=True, log=None), out


def test_the_plant_is_the_papers_model_and_sensor():
    u, x_true, x, segs = paper_exact.exact_plant(1e-4, ((1.0, 1.0), (10.0, 0.1)), seed=3)
    # The 1 Hz part is the 1 Hz row simulated alone; the reading is x + noise on a 2 nm grid.
    x1, h1 = boucwen.simulate(boucwen.Params.from_dict(PAPER_TABLE2["1"]), u[:10_000], 1e-4)
    np.testing.assert_array_equal(x_true[:10_000], x1)
    x2, _ = boucwen.simulate(boucwen.Params.from_dict(PAPER_TABLE2["10"]), u[10_000:], 1e-4, h1, u[9_999])
    np.testing.assert_array_equal(x_true[10_000:], x2)
    np.testing.assert_allclose(x / paper_exact.RESOLUTION_UM, np.round(x / paper_exact.RESOLUTION_UM), atol=1e-6)
    assert 0.9e-3 < np.std(x - x_true) < 1.3e-3  # 1 nm noise and the 2 nm grid's 0.58 nm
    assert [s[0] for s in segs] == [1.0, 10.0]


def test_start_is_the_1hz_row_with_the_hysteresis_parameters_20_percent_off():
    p, s = boucwen.Params.paper_1hz(), paper_exact.start_params()
    assert (s.kv, s.x0) == (p.kv, p.x0)
    for name in ("A", "beta", "gamma", "n", "delta"):
        assert getattr(s, name) == pytest.approx(1.2 * getattr(p, name))


def test_every_step_runs_and_says_why_it_held(quick):
    results, out = quick
    assert json.loads((out / "results.json").read_text())["chosen_window"] == results["chosen_window"]
    steps = results["sweep"][str(results["chosen_window"])]["steps"]
    for step in PAPER_STEPS:
        shares = steps[step]
        # Gave an update on some pushes of the record (taken, or held by the output gate
        # as worse than holding) ... except step 3, whose log-log points are off a line
        # on this record (the break the docs trace).
        proposed = max(r["ran"] + r["reduced"] + r["reasons"].get("worse_output", 0.0) for r in shares.values())
        assert proposed > 0.0 or step == "shape_fit", (step, shares)
        for f, r in shares.items():
            assert r["ran"] + r["reduced"] + r["held"] == pytest.approx(1.0)
            # ... and every push on which it held or ran reduced gave a reason.
            assert sum(r["reasons"].values()) == pytest.approx(r["held"] + r["reduced"]), (step, f, r)


def test_the_record_shows_where_the_method_breaks(quick):
    results, _ = quick
    # With the plant's own h and A, the sensor leaves step 3 a usable signal at 100 and
    # 200 Hz (|A − r| many times the noise of r); the break is upstream, in A and h.
    for f in ("100", "200"):
        b = results["step_budget"]["shape_fit"][f]
        assert b["points"] > 0 and b["signal"] > 5.0 * b["noise"], (f, b)
    chosen = results["sweep"][str(results["chosen_window"])]
    for f in ("1", "10", "100", "200"):
        assert np.isfinite(chosen["period_ahead"][f]) and np.isfinite(chosen["one_step"][f])
        assert set(chosen["table2"][f]) == {"kv", "x0", "A", "beta", "gamma", "n", "delta"}


def test_the_second_plant_reads_with_the_other_quantiser():
    spec = ((10.0, 0.2),)
    _, x_true, x, _ = paper_exact.exact_plant(1e-4, spec, **paper_exact.SECOND_PLANT)
    _, x_true0, x0, _ = paper_exact.exact_plant(1e-4, spec)
    np.testing.assert_array_equal(x_true, x_true0)
    q = paper_exact.RESOLUTION_UM
    # Mid-riser: every reading is an odd multiple of half the resolution.
    np.testing.assert_allclose(x / q - 0.5, np.round(x / q - 0.5), atol=1e-6)
    assert not np.array_equal(x, x0)
    assert 0.9e-3 < np.std(x - x_true) < 1.3e-3
    with pytest.raises(ValueError, match="quantiser"):
        paper_exact.exact_plant(1e-4, spec, quantiser="dither")


def test_the_bound_falls_as_one_over_root_n_over_whole_periods_and_is_infinite_on_a_chord():
    # 200 Hz at 10 kHz: 50 samples a period; four periods carry four times the
    # information of one, so every bound halves (the unknowns are then fixed by each
    # period alike).
    one, four = paper_exact.window_bound(200.0, 50), paper_exact.window_bound(200.0, 200)
    for q in paper_exact.BOUND_QUANTITIES:
        assert four[q] == pytest.approx(one[q] / 2.0, rel=0.05), q
    # 5 ms of a 1 Hz loop is a chord: the window cannot separate the unknowns.
    assert all(v == float("inf") for v in paper_exact.window_bound(1.0, 50).values())
    # The bound is in the units of the parameters and at the record's noise: A from one
    # 200 Hz period to about 1e-4 µm/V with 1.15 nm noise.
    assert 1e-5 < one["A"] < 1e-3
    assert paper_exact.record_noise_um() == pytest.approx(1.1547e-3, rel=1e-3)


def test_the_papers_figures_need_the_one_step_error_and_table_2():
    truth = PAPER_TABLE2["200"]
    run = {"one_step": {"200": 0.3}, "table2": {"200": dict(truth)}}
    assert paper_exact.meets(run, "200") == {"one_step": True, "table2": True, "both": True}
    # A 20 % off fails Table 2 whatever the one-step error; n 0.25 off as well.
    for change in ({"A": truth["A"] * 1.2}, {"n": truth["n"] + 0.25}, {"kv": truth["kv"] * 0.85}):
        off = {"one_step": {"200": 0.3}, "table2": {"200": {**truth, **change}}}
        assert paper_exact.meets(off, "200") == {"one_step": True, "table2": False, "both": False}, change
    late = {"one_step": {"200": 0.6}, "table2": {"200": dict(truth)}}
    assert paper_exact.meets(late, "200")["both"] is False


def test_on_the_papers_record_no_one_window_serves_1_and_200_hz():
    # The 1 Hz bound resolves A only from a window longer than the 200 Hz part can hold
    # a fitted window of, and what either would need follows from the bound.
    _, _, segs = boucwen.plant.paper_input(1e-4, SEGMENTS)
    nd = paper_exact.needs(segs)
    assert nd["n_min"] is not None and nd["n_min"] > nd["n_max"], nd
    assert nd["bound_A_slow"][str(nd["n_min"])] <= nd["resolve_A"] < nd["bound_A_slow_at_n_max"]
    assert nd["fast_part_needed"] > nd["fast_part_samples"]
    assert 0.0 < nd["noise_needed_um"] < paper_exact.record_noise_um()
