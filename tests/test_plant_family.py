"""boucwen.experiments.plant_family: the generator and the machinery, on two plants and a
shortened schedule (the targets are reported by the experiment, not asserted here)."""

import json
import math

import numpy as np
import pytest

from boucwen import plant
from boucwen.experiments import plant_family as pf

# 1 Hz for two periods, so that the oracle has one period before the scored one.
SHORT = ((1.0, 2.0), (10.0, 0.2), (100.0, 0.03), (200.0, 0.02))
FREQS = ["1", "10", "100", "200"]


def test_generate_is_seeded_and_within_the_stated_ranges():
    a, b = pf.generate(25, 7), pf.generate(25, 7)
    assert a == b
    assert pf.generate(25, 8) != a
    base = plant.BenchSettings()
    for s in a:
        for name in ("kv", "x0", "A", "n", "delta", "stroke_quadratic_per_um"):
            ratio = getattr(s, name) / getattr(base, name)
            assert 0.8 <= ratio <= 1.2, (name, ratio)
        assert 0.8 <= (s.beta + s.gamma) / (base.beta + base.gamma) <= 1.2
        assert 0.8 <= (s.beta - s.gamma) / (base.beta - base.gamma) <= 1.2
        assert s.beta + s.gamma > 0 and s.beta - s.gamma > 0
        assert 300.0 <= s.amplifier_fc_hz <= 1000.0
        for g, g0 in zip(s.creep_gain_um_per_v, base.creep_gain_um_per_v):
            assert 0.5 <= g / g0 <= 2.0
        assert len(s.vibration_um) == 2
        assert all(0.1 <= v <= 0.3 for v in s.vibration_um)
        assert all(10.0 <= v <= 40.0 for v in s.vibration_hz)
        assert all(0.0 <= v <= 2 * math.pi for v in s.vibration_phase_rad)
        assert 0.001 <= s.noise_um <= 0.010
    # The draws spread over their ranges (not, say, all at one end).
    fc = np.array([s.amplifier_fc_hz for s in a])
    assert fc.min() < 500.0 < 800.0 < fc.max()
    with pytest.raises(ValueError, match="count"):
        pf.generate(-1, 0)


def test_two_plants_on_a_short_schedule(tmp_path):
    lines = []
    res = pf.run(
        2,
        seed=3,
        bench=False,
        durations=SHORT,
        fit_options={"n_candidates": 8, "n_starts": 1},
        out_dir=tmp_path,
        progress=lines.append,
    )
    assert len(lines) == 2 and all("seed" in line for line in lines)
    assert res["bench"] is None and len(res["plants"]) == 2
    seeds = [p["seed"] for p in res["plants"]]
    assert seeds == [pf.measure_seed(3, 0), pf.measure_seed(3, 1)] and len(set(seeds)) == 2
    for p in res["plants"]:
        assert list(p["oracle"]) == FREQS and list(p["traditional"]) == FREQS
        for f in FREQS:
            assert 0.0 < p["oracle"][f] < 100.0 and 0.0 < p["traditional"][f] < 100.0
        assert set(p["methods"]) == set(pf.METHODS)
        for m in p["methods"].values():
            for f in FREQS:
                assert math.isfinite(m["score"][f]) and m["score"][f] > 0
                assert m["ratio_oracle"][f] == pytest.approx(m["score"][f] / p["oracle"][f], rel=1e-12)
                assert m["ratio_traditional"][f] == pytest.approx(m["score"][f] / p["traditional"][f], rel=1e-12)
                # The worst period after the first includes the scored (last) one.
                assert m["after_first"][f] >= m["score"][f]
    # The two plants are different benches and give different records.
    assert res["plants"][0]["settings"] != res["plants"][1]["settings"]
    assert res["plants"][0]["oracle"] != res["plants"][1]["oracle"]
    summary = res["summary"]
    for m in pf.METHODS:
        for f in FREQS:
            row = summary[m][f]
            ratios = [p["methods"][m]["ratio_oracle"][f] for p in res["plants"]]
            assert row["ratio_oracle"]["worst"] == max(ratios)
            assert row["ratio_oracle"]["median"] == pytest.approx(float(np.median(ratios)))
            assert 0 <= row["meets_plant_target"] <= 2 and row["plants"] == 2
    saved = json.loads((tmp_path / "results.json").read_text(encoding="utf-8"))
    assert saved["summary"] == json.loads(json.dumps(summary))
    assert (tmp_path / "ratios.png").stat().st_size > 10_000
    table = pf.format_table(res)
    for m in pf.METHODS:
        assert sum(line.split()[:1] == [m] for line in table.splitlines()) == len(FREQS)


def test_the_default_method_in_each_refine_mode_side_by_side():
    methods = ("horizon", *pf.REFINE_METHODS)
    res = pf.run(
        1, seed=3, methods=methods, bench=False, durations=SHORT, fit_options={"n_candidates": 8, "n_starts": 1}
    )
    (p,) = res["plants"]
    assert set(p["methods"]) == set(methods)
    replay = p["replay"]
    assert not replay["horizon_cooperative"]["paced"] and replay["horizon_cooperative"]["refine_intervals_per_push"] > 0
    assert replay["horizon_background"]["paced"] and replay["horizon_background"]["late_samples"] >= 0
    lines = pf.format_refine_modes(res)
    assert [line.split()[0] for line in lines[2:]] == ["sync", "cooperative", "background"]
    sync = res["summary"]["horizon"]["10"]["ratio_oracle"]["median"]
    assert lines[2].split()[2] == f"{sync:.3f}" and lines[2].split()[5] == "1.000"
    # Cooperative with a schedule in intervals is deterministic: a second plant run agrees.
    again = pf.run_plant(
        pf.generate(1, 3)[0],
        pf.measure_seed(3, 0),
        methods=("horizon_cooperative",),
        durations=SHORT,
        fit_options={"n_candidates": 8, "n_starts": 1},
    )
    assert again["methods"]["horizon_cooperative"]["score"] == p["methods"]["horizon_cooperative"]["score"]
    assert pf.format_refine_modes({**res, "summary": {"horizon": res["summary"]["horizon"]}}) == []
