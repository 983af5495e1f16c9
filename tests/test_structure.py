"""The other structure, found and not told: the diagnosis returns the hysteretic
oscillator where the hysteresis is driven by the output's motion (a generated record,
and the Bouc–Wen benchmark's training record, shortened, through the shell), and reads a
force record's columns in their units; on a piezo record it is one more move, judged and
refuted. That piezo records never get the oscillator is checked on the generated suite
(tests/test_diagnosis_suite.py, check ``oscillator_named``) and on the measured records (the measured benchmark's target
``piezo_records_input_driven``)."""

import json
from pathlib import Path

import numpy as np
import pytest

from boucwen import SavedOscillator, diagnose, load_model
from boucwen.cli import main
from boucwen.datasets import data_dirs
from boucwen.io import read_csv
from boucwen.metrics import rms
from boucwen.oscillator import OscillatorParams, simulate


def _benchmark() -> Path | None:
    """The benchmark's training record where the data folders hold it."""
    for _, folder in data_dirs():
        if folder is not None and (folder / "bouc-wen-benchmark" / "train_multisine.csv").is_file():
            return folder / "bouc-wen-benchmark" / "train_multisine.csv"
    return None


FS = 750.0


def _multisine(n, seed):
    """A random-phase multisine force [N], 5–150 Hz, 50 N RMS (as the benchmark's)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    f = np.arange(5.0, 150.0, FS / n * 8)
    wave = np.sum(np.sin(2 * np.pi * f[:, None] * t[None, :] + rng.uniform(0, 2 * np.pi, f.size)[:, None]), axis=0)
    return 50.0 * wave / np.std(wave)


def test_a_record_whose_hysteresis_follows_its_own_motion_is_returned_as_the_oscillator():
    n = 4096
    force = _multisine(n, 3)
    y = simulate(OscillatorParams.benchmark(), force, 1.0 / FS)
    noise_m = 0.02 * np.std(y)
    x_um = (y + np.random.default_rng(4).normal(0.0, noise_m, n)) * 1e6
    d = diagnose(force, x_um, 1.0 / FS)
    assert d.structure is not None and d.structure.name == "oscillator", d.summary()
    assert d.structure.level == "confident", d.structure.why
    # Against the input-driven model: its effects are the refuted rival's, tentative.
    assert all(e.level == "tentative" and "oscillator" in e.rivals for e in d.named_effects)
    assert d.rms_after_um < 2.0 * noise_m * 1e6 < d.rms_before_um / 10
    # Proposed every round, it waits while an input-driven move is still accepted, and is
    # taken once: the last structure decision.
    swap = [x for x in d.decisions if x.candidate == ("oscillator",)]
    assert swap[-1].accepted and [x for x in d.taken if x.move == "structure"] == [swap[-1]]
    p = d.structure.fit.params
    assert p.k == pytest.approx(OscillatorParams.benchmark().k, rel=0.05)
    assert d.to_dict()["structure"]["name"] == "oscillator"


def test_the_benchmark_record_from_the_shell_names_the_oscillator(tmp_path, capsys):
    path = _benchmark()
    if path is None:
        pytest.skip(f"the Bouc–Wen benchmark's training record is in none of {[str(f) for _, f in data_dirs()]}")
    lines = path.read_text(encoding="utf-8").splitlines()
    short = tmp_path / "train_short.csv"
    short.write_text("\n".join(lines[: 1 + 4096]) + "\n", encoding="utf-8")
    report, model = tmp_path / "r.json", tmp_path / "m.json"
    assert main(["diagnose", str(short), "--json", str(report), "--model", str(model)]) == 0
    out = capsys.readouterr().out
    assert "input: force [N]; displacement: 'displacement_m' [m, read as µm (× 1e6)]" in out
    assert "model fitted: hysteretic oscillator" in out
    doc = json.loads(report.read_text(encoding="utf-8"))
    assert doc["structure"]["name"] == "oscillator" and doc["structure"]["level"] == "confident"
    # Before: the input-driven base model; after: the oscillator, within 2× the noise.
    assert doc["rms_after_um"] < doc["rms_before_um"] / 20
    assert doc["rms_after_um"] < 2.0 * doc["evidence"]["noise_um"]
    # The model file holds the oscillator, which simulates to the error it records.
    saved = load_model(model)
    assert isinstance(saved, SavedOscillator) and saved.source.made_by == "diagnose"
    rec = read_csv(short)
    assert saved.source.rms_um == pytest.approx(doc["rms_after_um"], rel=1e-9)
    assert rms(rec.x - saved.simulate(rec.u) * 1e6) == pytest.approx(doc["rms_after_um"], rel=1e-9)


def test_a_piezo_record_keeps_the_input_driven_model_the_oscillator_tried_and_refuted():
    from boucwen import EffectSet, Params, simulate_extended

    dt = 1e-4
    t = np.arange(6000) * dt
    u = 50 - 40 * np.cos(2 * np.pi * 10 * t)
    x = simulate_extended(Params.paper_1hz(), EffectSet(creep={"tau_s": [0.02], "gain_um_per_v": [0.01]}), u, dt)
    d = diagnose(u, x + np.random.default_rng(1).normal(0, 0.005, u.size), dt)
    assert d.structure is None and "creep" in d.effects
    # The other structure is one more move of every round: judged, never taken, and
    # refuted against the model returned.
    tried = [x for x in d.decisions if x.move == "structure"]
    assert tried and not tried[-1].accepted and tried[-1].gain.statistic < 0
    assert all(x.move != "structure" for x in d.taken)
    assert d.evidence["structure"]["tried"] is True
