"""The input-path experiment (boucwen.experiments.input_path): each record fitted with each
input path between samples, in-record and held-out errors side by side."""

import io
import json

import numpy as np

from boucwen import EffectSet, Params, simulate_extended
from boucwen.experiments import input_path


def _record(input):
    dt = 1e-3
    t = np.arange(3000) * dt
    u = 50 - 40 * np.cos(2 * np.pi * 7 * t) + 5 * np.sin(2 * np.pi * 31 * t)
    effects = EffectSet(between_samples={"input": input}) if input != "linear" else EffectSet()
    x = simulate_extended(Params.paper_1hz(), effects, u, dt)
    return u, x + np.random.default_rng(0).normal(0.0, 0.002, u.size), dt


def test_each_path_is_fitted_and_the_records_own_reaches_the_noise():
    for input in ("hold", "linear"):
        u, x, dt = _record(input)
        rows = {r["input"]: r for r in input_path.piezo_rows(u, x, dt)}
        assert list(rows) == ["hold", "linear", "bandlimited"]
        assert all(r["converged"] for r in rows.values())
        # The fit with the rig's own path reaches the noise (2 nm), in the record and after it.
        assert rows[input]["in_record"] < 0.0021 and rows[input]["held_out"] < 0.0021
    # A command that moves between the samples is not a held one: the hold misses the δ
    # term over each interval. (The other way round the base model's δ absorbs it.)
    assert rows["hold"]["held_out"] > 1.3 * rows["linear"]["held_out"]


def test_the_command_prints_one_table_per_record_and_writes_them(tmp_path, monkeypatch):
    u, x, dt = _record("linear")
    monkeypatch.setattr(input_path.datasets, "names", lambda: ["generated"])

    class Rec:
        pass

    rec = Rec()
    rec.u, rec.x, rec.dt = u, x, dt
    monkeypatch.setattr(input_path.datasets, "load", lambda name: rec)
    out = io.StringIO()
    assert input_path.main(["--quick", "--out", str(tmp_path)], out=out) == 0
    text = out.getvalue()
    assert "generated (3000 samples" in text and "held-out RMS [µm]" in text
    doc = json.loads((tmp_path / "results.json").read_text(encoding="utf-8"))
    assert [r["input"] for r in doc["records"]["generated"]["rows"]] == ["hold", "linear", "bandlimited"]
