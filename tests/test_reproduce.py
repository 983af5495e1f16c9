"""boucwen reproduce: the paper's experiment on the simulated bench (quick mode)."""

import json

import numpy as np
import pytest

from boucwen import plant
from boucwen.experiments import reproduce as rp

FREQS = ["1", "10", "100", "200"]


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    lines = []
    results = rp.run(out, quick=True, log=lines.append)
    return out, results, lines


def test_results_json_layout(quick_run):
    out, results, _ = quick_run
    on_disk = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert on_disk == json.loads(json.dumps(results))
    t1 = on_disk["table1"]
    labels = [m.label for m in rp.available_online_methods()]
    assert "paper" in labels and "paper_literal" in labels
    for key in ["traditional", "online"] + [f"online_{lab}" for lab in labels]:
        assert set(t1[key]) == set(FREQS), key
        assert all(np.isfinite(v) and v >= 0 for v in t1[key].values())
    default = rp.default_online_method(labels)
    assert on_disk["default_online_method"] == default
    assert t1["online"] == t1[f"online_{default}"]
    for key in [f"online_{lab}" for lab in labels]:
        assert set(on_disk["table2"][key]) == set(FREQS)
        for est in on_disk["table2"][key].values():
            assert set(est) == {"kv", "x0", "A", "beta", "gamma", "n", "delta"}
    assert on_disk["plant"] == plant.BenchSettings().to_dict()
    assert isinstance(on_disk["steady_state"], str) and on_disk["steady_state"]
    assert set(on_disk["adaptation_time_s"]["online"]) == set(FREQS)
    assert on_disk["paper"]["table1"] == rp.PAPER_TABLE1


def test_tables_agree_with_saved_predictions(quick_run):
    # Recompute Table 1 from the arrays the figures are drawn from, independently of
    # the module's helper: max |x - x_hat| over the last full period of each segment.
    out, results, _ = quick_run
    data = np.load(out / "predictions.npz")
    x, dt = data["x"], float(data["dt"])
    assert x.size == data["u"].size == data["t"].size
    for f, _, hi in data["segments"]:
        period = round(1.0 / (f * dt))
        ss = slice(int(hi) - period, int(hi))
        key = f"{f:g}"
        for label, row in results["table1"].items():
            if label == "online":
                label = f"online_{results['default_online_method']}"
            # Table 1 is period-ahead: the frozen models' open-loop predictions.
            expect = np.max(np.abs(x[ss] - data[f"x_period_ahead_{label}"][ss]))
            assert row[key] == pytest.approx(expect, abs=1e-12), (label, key)
        for label, row in results["table1_one_step"].items():
            if label == "online":
                label = f"online_{results['default_online_method']}"
            expect = np.max(np.abs(x[ss] - data[f"x_{label}"][ss]))
            assert row[key] == pytest.approx(expect, abs=1e-12), (label, key)
        # The model-free baselines, recomputed.
        prev = np.concatenate([x[:1], x[:-1]])
        assert results["baselines"]["persistence"][key] == pytest.approx(np.max(np.abs(x[ss] - prev[ss])), abs=1e-12)
        two_tap = np.concatenate([x[:2], 2 * x[1:-1] - x[:-2]])
        assert results["baselines"]["two_tap"][key] == pytest.approx(np.max(np.abs(x[ss] - two_tap[ss])), abs=1e-12)
        for label, row in results["table1_fixed"].items():
            if label == "online":
                continue
            expect = np.max(np.abs(x[ss] - data[f"x_fixed_{label}"][ss]))
            if row[key] is None:  # that parameter set could not be simulated
                assert np.isnan(expect)
            else:
                assert row[key] == pytest.approx(expect, abs=1e-12), (label, key)


def test_traditional_prediction_is_the_fit_simulated(quick_run):
    from boucwen import Params, simulate

    out, results, _ = quick_run
    data = np.load(out / "predictions.npz")
    fit = results["traditional_fit"]
    x, _ = simulate(Params.from_dict(fit["params"]), data["u"], float(data["dt"]), fit["h0_um"])
    np.testing.assert_allclose(data["x_period_ahead_traditional"], x, rtol=0, atol=1e-12)
    # Its steady-state error at 1 Hz is where it was fitted: the smallest of its row.
    row = results["table1"]["traditional"]
    assert row["1"] <= min(row.values()) + 1e-12


def test_table2_is_what_the_online_identifier_ends_with(quick_run):
    from boucwen import Identifier, Params

    out, results, _ = quick_run
    data = np.load(out / "predictions.npz")
    fit = results["traditional_fit"]
    ident = Identifier.paper(
        float(data["dt"]), results["window"]["samples"], Params.from_dict(fit["params"]), fit["h0_um"]
    )
    pred = ident.push_many(data["u"], data["x"])
    np.testing.assert_array_equal(pred, data["x_online_paper"])
    assert ident.params.to_dict() == pytest.approx(results["table2"]["online_paper"]["200"])


def test_figures_written(quick_run):
    out, _, _ = quick_run
    for name in ["fig6_1_to_10hz.png", "fig7_10_to_100hz.png", "fig8_100_to_200hz.png", "fig9_loops.png"]:
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, name


def test_prints_tables_and_progress(quick_run):
    _, _, lines = quick_run
    text = "\n".join(lines)
    assert "Table 1" in text and "Table 2" in text
    assert "traditional (paper)" in text and "online (paper)" in text
    assert sum("[" in line and " s] " in line for line in lines) >= 3  # progress lines


def test_adaptation_times_rule():
    dt = 1e-3
    f = 100.0  # 10 samples per period
    segments = [(f, 0, 50)]
    x = np.zeros(50)
    # Per-period maxima 10, 5, 1, 1.2, 1 (steady state 1): first period from which on all
    # stay within 1.5x is the third (index 2).
    maxima = [10.0, 5.0, 1.0, 1.2, 1.0]
    pred = np.concatenate([np.full(10, -m) for m in maxima])
    a = rp.adaptation_times(x, pred, segments, dt)
    assert a["100"]["periods"] == 2
    assert a["100"]["s"] == pytest.approx(0.02)
    # A late excursion above the band moves the adaptation time past it.
    maxima = [1.0, 1.0, 5.0, 1.0, 1.0]
    pred = np.concatenate([np.full(10, -m) for m in maxima])
    assert rp.adaptation_times(x, pred, segments, dt)["100"]["periods"] == 3
    assert rp.adaptation_times(x, np.full(50, -1.0), segments, dt)["100"]["periods"] == 0


def test_steady_state_is_last_period():
    s = rp.steady_state_slice(10.0, 30000, 33000, 1e-4)
    assert (s.start, s.stop) == (32000, 33000)


def test_method_choice():
    assert rp.default_online_method(["paper", "paper_literal"]) == "paper"
    assert rp.default_online_method(["paper", "rpem"]) == "rpem"
    assert rp.default_window([(1.0, 0, 1), (200.0, 1, 2)], 1e-4) == 50


def test_bad_window(tmp_path):
    with pytest.raises(ValueError):
        rp.run(tmp_path, quick=True, window=3, figures=False, log=None)


def test_refine_modes_side_by_side(tmp_path):
    lines = []
    res = rp.run(tmp_path, quick=True, figures=False, log=lines.append, refine=("sync", "cooperative", "background"))
    modes = res["refine_modes"]
    assert list(modes) == ["sync", "cooperative", "background"]
    assert modes["sync"]["table1"] == res["table1"]["online_horizon"]
    for mode in ("cooperative", "background"):
        assert modes[mode]["table1"] == res["table1"][f"online_horizon_{mode}"]
        assert all(0.0 < v < 10.0 for v in modes[mode]["table1"].values())
    assert modes["background"]["paced"] and not modes["cooperative"]["paced"]
    # The paced replay takes the record's own time at least.
    samples = sum(round(d / plant.DEFAULT_DT) for _, d in rp.QUICK_SEGMENTS)
    assert modes["background"]["wall_s"] >= (samples - 1) * plant.DEFAULT_DT
    head = next(i for i, line in enumerate(lines) if line.startswith("Table 1 by window-pass mode"))
    assert [line.split()[0] for line in lines[head + 2 : head + 5]] == ["sync", "cooperative", "background"]
    assert rp.refine_variants(["sync"]) == []
