"""A model diagnosed on a PRBS record behind a fast amplifier lag, carried to the rig's
sines and triangles (boucwen.experiments.lag_rig): never worse than 1.05× the base model
there, and bounded."""

import io

import pytest

from boucwen.experiments import lag_rig


@pytest.mark.slow
def test_the_diagnosed_model_carried_to_the_rigs_other_records():
    out = io.StringIO()
    doc = lag_rig.run(out=out)
    assert doc["holds"], out.getvalue()
    assert {r["record"] for r in doc["records"]} == {"sine 50 Hz", "sine 100 Hz", "triangle", "large sine"}
    assert all(r["ratio"] <= lag_rig.CARRIED_LIMIT for r in doc["records"]), out.getvalue()
    assert doc["boundedness"]["passed"]
    base = doc["params"]["base"]
    assert base["beta"] + base["gamma"] >= 0.0 and base["beta"] - base["gamma"] >= 0.0


def test_the_rigs_records():
    records = lag_rig.rig_records()
    assert list(records) == ["prbs", "sine 50 Hz", "sine 100 Hz", "triangle", "large sine"]
    for rec in records.values():
        assert len(rec) == round(lag_rig.DURATION_S / lag_rig.DT) and rec.dt == lag_rig.DT
    prbs = records["prbs"]
    assert set(prbs.meta["u_command"].tolist()) == {40.0, 60.0}
    assert records["large sine"].u.min() < 1.0 and records["large sine"].u.max() > 99.0
