"""Diagnosis on records whose effect is not declared to it, and the CLI.

Each generated record (boucwen.experiments.undeclared) holds one effect of the
vocabulary, or none, simulated on a grid 8× finer than the sampling with creep time
constants the diagnosis does not use. The diagnosis is not told what is inside: it
must name the effect and cut the RMS error against the noise-free signal; on clean
records it must add nothing. The larger table is printed by
``python -m boucwen.experiments.undeclared``. The records of the generated suite here
are tested by properties of the answer (the effect named, or its rivals reported; never
a wrong name given as confident; the error against the truth cut); the judge and the
loop are tested on constructed numbers and records (tests/test_judge.py,
tests/test_search.py, tests/test_policy.py).
"""

import json

import numpy as np
import pytest

from boucwen import Drift, Params, diagnose, simulate, simulate_extended
from boucwen.cli import main
from boucwen.diagnosis import residual_evidence
from boucwen.effects import VOCABULARY, effect_class
from boucwen.experiments.undeclared_records import make_record
from boucwen.experiments.undeclared_records import test_input as make_input  # not a test
from boucwen.io import jsonable, read_csv, write_csv

# (effect, seed, base parameter set, noise [µm]): one record per effect, two clean ones.
CASES = [
    ("none", 0, "paper_1hz", 0.005),
    ("none", 1, "paper_200hz", 0.02),
    ("creep", 0, "paper_1hz", 0.005),
    ("input_lag", 1, "paper_100hz", 0.005),
    ("resonance", 2, "paper_200hz", 0.005),
    ("drift", 1, "paper_100hz", 0.02),
    ("delay", 2, "paper_1hz", 0.001),
]


def _rms(v):
    return float(np.sqrt(np.mean(np.square(v))))


@pytest.mark.parametrize("effect, seed, pset, noise", CASES)
def test_names_the_undeclared_effect_and_cuts_the_error(effect, seed, pset, noise):
    rec = make_record(effect, seed, pset, noise)
    d = diagnose(rec.u, rec.x, rec.dt)
    before = _rms(d.x_base - rec.x_true)
    after = _rms(d.x_extended - rec.x_true)
    if effect == "none":
        assert d.effects == []
        assert after == before
        assert d.rms_after_um == d.rms_before_um
        return
    # The effect is named, or one of its rivals is, with the effect among the rivals.
    named = {e.name: e for e in d.named_effects}
    assert effect in named or any(effect in e.rivals for e in named.values()), d.summary()
    for e in d.named_effects:
        assert e.name == effect or e.level == "tentative", d.summary()
    assert after < 0.5 * before, (before, after)
    assert d.rms_after_um < d.rms_before_um


def test_result_fields_and_json():
    rec = make_record("drift", 0, "paper_1hz", 0.005)
    d = diagnose(rec.u, rec.x, rec.dt)
    doc = json.loads(json.dumps(d.to_dict()))
    assert set(doc) == {
        "non_finite",
        "effects",
        "rms_before_um",
        "max_before_um",
        "rms_after_um",
        "max_after_um",
        "params",
        "evidence",
        "unexplained",
        "confidence",
        "decisions",
        "unseen",
        "at_bounds",
        "base_loop_on_bounds",
        "structure",
        "boundedness",
    }
    assert doc["structure"] is None  # a piezo record: the input-driven model
    # The returned model driven over the record's range stays within the stated multiple
    # of it, and the report says so, probe by probe.
    assert d.boundedness is not None and d.boundedness.passed
    assert doc["boundedness"] == json.loads(json.dumps(d.boundedness.to_dict()))
    assert doc["boundedness"]["passed"] and len(doc["boundedness"]["probes"]) >= 4
    assert doc["effects"] == ["drift"], d.summary()
    assert doc["confidence"]["drift"]["level"] in ("confident", "tentative")
    assert doc["unseen"]["cv_rms_after_um"] < doc["unseen"]["cv_rms_before_um"]
    # What is left: the noise the record was made with, estimated from x alone, and a
    # verdict on it (tests/test_unexplained.py tests the verdict itself).
    left = doc["unexplained"]
    assert left["noise_um"] == pytest.approx(rec.noise_um, rel=0.15)
    assert isinstance(left["consistent_with_noise"], bool) and 0.0 <= left["p_value"] <= 1.0
    assert left["rms_um"] == pytest.approx(d.rms_after_um)
    assert left["summary"] == d.unexplained.summary()
    # Every decision typed, and in the report as the same dicts; the round that took the
    # drift lists every move it judged, each with its gain per fold, and every move it
    # proposed is either judged or listed with why it had no candidate (here the creep:
    # its fit beside the trend ends with no creep).
    assert doc["decisions"] == [x.to_dict() for x in d.decisions]
    first = doc["evidence"]["rounds"][0]
    assert first["taken"] == "add drift"
    judged = {tuple(x["effects"]) for x in first["decisions"]}
    assert ("drift",) in judged and ("input-driven", "oscillator") in judged
    rejected = {key.split()[-1] for key in first["rejected"]}
    proposed = {name for name in VOCABULARY if name != "resonance2" and effect_class(name).proposed}
    assert proposed <= {e[-1] for e in judged} | rejected, (judged, first["rejected"])
    assert all(len(x["fold_gain_um2"]) == doc["evidence"]["policy"]["folds"] for x in first["decisions"])
    taken = next(x for x in d.decisions if x.move == "add" and x.effects == ("drift",))
    assert taken.accepted and taken.gain.t > taken.threshold and taken.gain.mean_um2 >= taken.needed_um2
    assert doc["params"]["drift"]["rate_um_per_s"] == pytest.approx(
        rec.effects.to_dict()["drift"]["rate_um_per_s"], rel=0.05
    )
    assert "base" in doc["params"] and "base_only" in doc["params"]
    # Typed: the returned model (base parameters, h0, effects) and the base model alone
    # replay the two predictions; each effect named, typed, with its confidence.
    assert isinstance(d.params, Params) and doc["params"]["base"] == d.params.to_dict()
    assert doc["params"]["h0_um"] == d.h0_um and doc["params"]["base_only"] == d.base_only.to_dict()
    np.testing.assert_allclose(simulate_extended(d.params, d.effect_set, rec.u, rec.dt, d.h0_um), d.x_extended)
    np.testing.assert_allclose(simulate(d.base_only.params, rec.u, rec.dt, d.base_only.h0_um)[0], d.x_base)
    [named] = d.named_effects
    assert jsonable(named) == {"effect": "drift", "params": doc["params"]["drift"], **doc["confidence"]["drift"]}
    assert isinstance(named.effect, Drift) and named.name == "drift"
    assert named.effect.rate_um_per_s == doc["params"]["drift"]["rate_um_per_s"]
    assert d.x_base.shape == d.x_extended.shape == rec.u.shape
    assert d.unseen is not None and d.unseen.folds == doc["evidence"]["policy"]["folds"]
    assert doc["unseen"] == d.unseen.to_dict()
    assert doc["at_bounds"] == [b.to_dict() for b in d.at_bounds]
    assert doc["base_loop_on_bounds"] == [b.to_dict() for b in d.base_loop]


def test_evidence_points_the_right_way():
    u = make_input(seed=0)
    t = np.arange(u.size) * 1e-3
    xm = 0.2 * u
    # A trend in time shows in the drift group, not as creep after steps.
    ev = residual_evidence(u, xm + 0.3 * t, xm, 1e-3)
    assert ev["drift"]["slope_um_per_s"] == pytest.approx(0.3, rel=1e-6)
    assert ev["drift"]["variance_share"] > 0.99
    # A lag of the response: r ≈ −τ·ẋ with τ = 2 ms (smooth input, no steps).
    u = 50 + 20 * np.sin(2 * np.pi * 3 * t) + 20 * np.sin(2 * np.pi * 17 * t)
    xm = 0.2 * u
    lagged = np.interp(t - 0.002, t, xm)
    ev = residual_evidence(u, lagged, xm, 1e-3)
    assert ev["input_lag"]["lag_s"] == pytest.approx(0.002, rel=0.2)
    ratios = [r for _, _, r in ev["input_lag"]["band_ratio"]]
    assert ratios[-1] > ratios[0]


@pytest.mark.parametrize(
    "kw, words",
    [
        (dict(folds=1), "folds"),
        (dict(max_effects=9), "max_effects"),
    ],
)
def test_bad_options(kw, words):
    u = make_input()[:500]
    with pytest.raises(ValueError, match=words):
        diagnose(u, 0.2 * u, 1e-3, **kw)


def test_bad_data():
    with pytest.raises(ValueError, match="same length"):
        diagnose(np.zeros(200), np.zeros(100), 1e-3)
    with pytest.raises(ValueError, match="constant"):
        diagnose(np.zeros(200), np.zeros(200), 1e-3)
    with pytest.raises(ValueError, match="dt"):
        diagnose(np.arange(200.0), np.arange(200.0), 0.0)


def test_cli_writes_report_predictions_and_plot(tmp_path, capsys):
    rec = make_record("delay", 0, "paper_1hz", 0.002)
    t = np.arange(rec.u.size) * rec.dt
    data = tmp_path / "data.csv"
    write_csv(data, {"t": t, "u": rec.u, "x": rec.x, "extra": np.zeros_like(t)})
    report, pred, fig = tmp_path / "r.json", tmp_path / "p.csv", tmp_path / "f.png"
    code = main(["diagnose", str(data), "--json", str(report), "--predictions", str(pred), "--plot", str(fig)])
    assert code == 0
    out = capsys.readouterr().out
    assert "residual:" in out and "consistent with noise" in out
    doc = json.loads(report.read_text())
    assert doc["effects"] == ["delay"]
    assert doc["rms_after_um"] < doc["rms_before_um"]
    header = pred.read_text().splitlines()[0]
    assert header == "t,x,x_base,x_extended"
    table = np.loadtxt(pred, delimiter=",", skiprows=1)
    assert table.shape == (t.size, 4)
    np.testing.assert_allclose(table[:, 1], read_csv(data).x, rtol=1e-8)
    assert fig.stat().st_size > 10_000


@pytest.mark.parametrize(
    "argv_tail, words",
    [
        (["missing.csv"], "no such file"),
        ([], "exactly one"),
        (["--dataset", "nope"], "unknown dataset"),
    ],
)
def test_cli_bad_input_exits_2_with_one_line(tmp_path, capsys, argv_tail, words):
    argv = [
        "diagnose",
        *[str(tmp_path / a) if a.endswith(".csv") else a for a in argv_tail],
        "--json",
        str(tmp_path / "r.json"),
        "--predictions",
        str(tmp_path / "p.csv"),
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err and "Traceback" not in err


def test_cli_bad_csv_exits_2(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,u\n0,1\n1,2\n2,3\n")
    assert (
        main(["diagnose", str(bad), "--json", str(tmp_path / "r.json"), "--predictions", str(tmp_path / "p.csv")]) == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("boucwen diagnose: error:") and err.count("\n") == 1
