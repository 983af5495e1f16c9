"""The model file (boucwen.model_file): one versioned schema, written and read back, and its errors."""

import json

import numpy as np
import pytest

import boucwen
from boucwen import Creep, Delay, InputLag, InvalidConfig, InvalidParams, Params, effect_set, load_model
from boucwen.model_file import SCHEMA, VERSION, ModelSource, SavedModel


@pytest.fixture
def model():
    effects = effect_set(InputLag(fc_hz=650.0), Creep(tau_s=(0.05, 2.0), gain_um_per_v=(0.002, 0.001)))
    source = ModelSource(made_by="fit", record="rec.csv", sha256="ab" * 32, columns={"t": "t", "u": "u", "x": "x"})
    return SavedModel(Params.paper_1hz(), 0.25, 1e-4, effects, source)


def test_round_trip_keeps_every_value(model, tmp_path):
    path = tmp_path / "m.json"
    model.save(path)
    doc = json.loads(path.read_text(encoding="utf-8"))
    assert doc["schema"] == SCHEMA and doc["version"] == VERSION
    assert doc["units"]["params.kv"] == "µm/V" and doc["units"]["x"] == "µm"
    back = load_model(path)
    assert back.params == model.params and back.h0_um == model.h0_um and back.dt_s == model.dt_s
    assert back.effects.to_dict() == model.effects.to_dict()
    assert back.source == model.source
    assert [e.name for e in back.named_effects] == ["creep", "input_lag"]


def test_simulates_itself_with_its_effects(model):
    u = boucwen.paper_input(1e-4)[:3000]
    expected = boucwen.simulate_extended(model.params, model.effects, u, 1e-4, 0.25)
    np.testing.assert_array_equal(model.simulate(u), expected)
    np.testing.assert_array_equal(model.simulate(u, 1e-4), expected)
    # The effects count: without them the model runs differently.
    assert np.max(np.abs(expected - boucwen.simulate(model.params, u, 1e-4, 0.25)[0])) > 1e-3


def test_a_delay_runs_only_at_its_own_interval():
    m = SavedModel(Params.paper_1hz(), 0.0, 1e-4, effect_set(Delay(samples=2)))
    with pytest.raises(InvalidConfig, match="whole samples"):
        m.simulate(np.ones(10), 2e-4)


def _doc(model):
    return json.loads(json.dumps(model.to_dict()))


def _broken(doc, change):
    change(doc)
    return doc


@pytest.mark.parametrize(
    "change, words",
    [
        (lambda d: d.update(version=VERSION + 1), ["field 'version'", "newer", "upgrade"]),
        (lambda d: d.update(version="1"), ["field 'version'", "whole number"]),
        (lambda d: d.update(schema="other"), ["field 'schema'", "boucwen.model"]),
        (lambda d: d.pop("schema"), ["field 'schema'", "got none"]),
        (lambda d: d["params"].pop("kv"), ["field 'params.kv'", "missing"]),
        (lambda d: d["params"].update(n="two"), ["field 'params.n'", "finite number"]),
        (lambda d: d["params"].update(nn=1.0), ["field 'params.nn'", "unknown parameter"]),
        (lambda d: d["params"].update(n=-1.0), ["field 'params'", "n"]),
        (lambda d: d.update(h0_um=None), ["field 'h0_um'", "finite number"]),
        (lambda d: d.pop("dt_s"), ["field 'dt_s'", "missing"]),
        (lambda d: d.update(dt_s=0.0), ["field 'dt_s'", "> 0"]),
        (lambda d: d["effects"].update(wobble={}), ["field 'effects'", "unknown effect 'wobble'"]),
        (lambda d: d["effects"]["input_lag"].update(fc_hz=-5.0), ["field 'effects'", "fc_hz"]),
        (lambda d: d["effects"]["input_lag"].pop("fc_hz"), ["field 'effects'", "missing parameter 'fc_hz'"]),
        (lambda d: d.update(effects=[]), ["field 'effects'", "expected an object"]),
        (lambda d: d["units"].update(x="nm"), ["field 'units.x'", "'µm'", "'nm'"]),
        (lambda d: d.update(colour="blue"), ["field 'colour'", "unknown field"]),
        (lambda d: d["source"].update(samples=-3), ["field 'source.samples'"]),
        (lambda d: d["source"].update(rms_um="small"), ["field 'source.rms_um'"]),
    ],
)
def test_a_hand_broken_file_names_the_field(model, tmp_path, change, words):
    path = tmp_path / "m.json"
    path.write_text(json.dumps(_broken(_doc(model), change)), encoding="utf-8")
    with pytest.raises(InvalidParams) as info:
        load_model(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    for word in words:
        assert word in message, (word, message)


@pytest.mark.parametrize(
    "text, words",
    [
        ('{"schema": "boucwen.model", "version": 1,', ["invalid JSON", "line 1"]),
        ("[1, 2]", ["expected a JSON object", "list"]),
        ("", ["invalid JSON"]),
    ],
)
def test_a_corrupt_file_says_so(tmp_path, text, words):
    path = tmp_path / "m.json"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InvalidParams) as info:
        load_model(path)
    for word in words:
        assert word in str(info.value)


def test_a_missing_file(tmp_path):
    with pytest.raises(InvalidParams, match="no such model file"):
        load_model(tmp_path / "none.json")


def test_the_source_records_the_file_and_the_error(tmp_path):
    from boucwen.io import read_csv, sha256_file, write_csv

    dt = 1e-3
    u = 50.0 - 50.0 * np.cos(2 * np.pi * np.arange(500) * dt)
    x, _ = boucwen.simulate(Params.paper_1hz(), u, dt)
    path = tmp_path / "rec.csv"
    write_csv(path, {"t_s": np.arange(500) * dt, "u_V": u, "x_um": x})
    rec = read_csv(path)
    source = ModelSource.of_record(rec, "fit", x + 0.5)
    assert source.sha256 == sha256_file(path) and len(source.sha256) == 64
    assert source.columns == {"t": "t_s", "u": "u_V", "x": "x_um"} and source.samples == 500
    assert source.rms_um == pytest.approx(0.5) and source.max_um == pytest.approx(0.5)
