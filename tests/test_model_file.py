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
    _refused(tmp_path, _broken(_doc(model), change), words)


def _refused(tmp_path, doc, words):
    """``doc`` written to a file is refused in one line that names the file and ``words``."""
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
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


# --------------------------------------------------------------------------- the measurement chain (version 2)

from boucwen.cli import main  # noqa: E402
from boucwen.effects import BetweenSamples  # noqa: E402
from boucwen.io import read_csv, write_csv  # noqa: E402
from boucwen.measurement import OutputFilter, decimation_filter  # noqa: E402
from boucwen.model_file import SavedOscillator  # noqa: E402
from boucwen.oscillator import OscillatorParams  # noqa: E402
from boucwen.oscillator import simulate as simulate_oscillator  # noqa: E402

DT = 1e-4


def _piezo(input, output=None):
    effects = effect_set(InputLag(fc_hz=650.0), BetweenSamples(input=input))
    return SavedModel(Params.paper_1hz(), 0.25, DT, effects, ModelSource(made_by="fit"), output)


def _oscillator():
    p = OscillatorParams.benchmark()
    fir = decimation_filter((2, 2, 5))
    return SavedOscillator(p, 1e-5, 0.0, 0.5, 1 / 750, "bandlimited", fir, ModelSource(made_by="diagnose"))


def _force(n=1500, dt=1 / 750):
    t = np.arange(n) * dt
    return 40.0 * np.sin(2 * np.pi * 5.0 * t) + 20.0 * np.sin(2 * np.pi * 37.0 * t + 1.0)


@pytest.mark.parametrize("input", ["hold", "bandlimited"])
def test_the_chain_is_carried_in_its_own_field(tmp_path, input):
    fir = OutputFilter((0.25, 0.5, 0.25), 1, "smooth")
    model = _piezo(input, fir)
    path = tmp_path / "m.json"
    model.save(path)
    doc = json.loads(path.read_text(encoding="utf-8"))
    assert doc["version"] == 2 and doc["structure"] == "piezo"
    assert doc["chain"] == {"input": input, "output": {"name": "smooth", "taps": [0.25, 0.5, 0.25], "center": 1}}
    assert "between_samples" not in doc["effects"]
    back = load_model(path)
    assert isinstance(back, SavedModel) and back.input == input and back.output == fir
    u = boucwen.paper_input(DT)[:2000]
    expected = fir.apply(boucwen.simulate_extended(model.params, model.effects, u, DT, 0.25))
    np.testing.assert_array_equal(back.simulate(u), expected)
    with pytest.raises(InvalidConfig, match="output filter"):
        back.simulate(u, 2 * DT)


def test_a_version_1_file_is_read_with_its_input_path(tmp_path):
    doc = _doc(_piezo("hold"))
    doc["version"] = 1
    del doc["structure"], doc["chain"]
    doc["effects"]["between_samples"] = {"input": "hold"}
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    back = load_model(path)
    assert back.input == "hold" and back.output is None


def test_an_oscillator_round_trip_simulates_as_the_oscillator(tmp_path):
    model = _oscillator()
    path = tmp_path / "osc.json"
    model.save(path)
    doc = json.loads(path.read_text(encoding="utf-8"))
    assert doc["structure"] == "oscillator" and doc["units"]["x"] == "m" and doc["state"]["z0_N"] == 0.5
    back = load_model(path)
    assert isinstance(back, SavedOscillator) and back.params == model.params and back.output == model.output
    force = _force()
    expected = simulate_oscillator(
        model.params, force, 1 / 750, 1e-5, 0.0, 0.5, input="bandlimited", output=model.output
    )
    np.testing.assert_array_equal(back.simulate(force), expected)


def _run_simulate(model, u, dt, tmp_path, capsys, extra=()):
    path, u_csv, out = tmp_path / "m.json", tmp_path / "u.csv", tmp_path / "x.csv"
    model.save(path)
    write_csv(u_csv, {"t_s": np.arange(u.size) * dt, "u_V": u}, digits=17)
    assert main(["simulate", "--model", str(path), str(u_csv), "--out", str(out), *extra]) == 0
    capsys.readouterr()
    return np.loadtxt(out, delimiter=",", skiprows=1)[:, 2]


@pytest.mark.parametrize("input", ["hold", "bandlimited"])
def test_simulate_on_the_command_line_is_the_python_model(tmp_path, capsys, input):
    model = _piezo(input, OutputFilter((0.2, 0.6, 0.2), 1))
    u = boucwen.paper_input(DT)[:3000]
    x = _run_simulate(model, u, DT, tmp_path, capsys)
    expected = model.simulate(u)
    assert np.max(np.abs(x - expected)) <= 1e-12 * np.ptp(expected)


def test_simulate_on_the_command_line_runs_an_oscillator_through_its_filter(tmp_path, capsys):
    model = _oscillator()
    force = _force()
    y = _run_simulate(model, force, 1 / 750, tmp_path, capsys, ["--periodic"])
    expected = model.simulate(force, periodic=True)
    assert np.max(np.abs(y - expected)) <= 1e-12 * np.ptp(expected)
    assert not np.allclose(expected, model.simulate(force), rtol=0, atol=1e-9 * np.ptp(expected))


@pytest.mark.parametrize(
    "change, words",
    [
        (lambda d: d["chain"].update(input="cubic"), ["field 'chain.input'", "hold, linear, bandlimited"]),
        (lambda d: d.pop("chain"), ["field 'chain'", "missing"]),
        (lambda d: d["chain"].update(output={"taps": [], "center": 0}), ["field 'chain.output.taps'"]),
        (lambda d: d["chain"].update(output={"taps": [1.0], "center": 3}), ["field 'chain.output'", "center"]),
        (lambda d: d["chain"].update(output={"taps": [1.0, -1.0], "center": 0}), ["chain.output", "gain"]),
        (lambda d: d["chain"].update(output=[1.0]), ["field 'chain.output'", "or null"]),
        (lambda d: d["chain"].update(filter=None), ["field 'chain.filter'", "unknown field"]),
        (lambda d: d["effects"].update(between_samples={"input": "hold"}), ["effects.between_samples", "chain.input"]),
        (lambda d: d.update(structure="beam"), ["field 'structure'", "piezo, oscillator"]),
        (lambda d: d.pop("structure"), ["field 'structure'", "missing"]),
    ],
)
def test_a_broken_chain_names_the_field(tmp_path, change, words):
    _refused(tmp_path, _broken(_doc(_piezo("hold")), change), words)


@pytest.mark.parametrize(
    "change, words",
    [
        (lambda d: d["state"].pop("v0_m_s"), ["field 'state.v0_m_s'", "missing"]),
        (lambda d: d["params"].update(gamma=-0.5), ["field 'params'", "gamma"]),
        (lambda d: d["params"].update(m=0.0), ["field 'params'", "mass"]),
        (lambda d: d["units"].update(x="µm"), ["field 'units.x'", "'m'"]),
        (lambda d: d.update(h0_um=0.0), ["field 'h0_um'", "unknown field", "oscillator"]),
    ],
)
def test_a_broken_oscillator_names_the_field(tmp_path, change, words):
    _refused(tmp_path, _broken(_doc(_oscillator()), change), words)


def test_the_command_line_refuses_a_bad_file_in_one_line(tmp_path, capsys):
    path, u_csv = tmp_path / "m.json", tmp_path / "u.csv"
    path.write_text(json.dumps(_broken(_doc(_piezo("hold")), lambda d: d["chain"].update(input=3))), encoding="utf-8")
    write_csv(u_csv, {"t_s": np.arange(10) * DT, "u_V": np.ones(10)})
    assert main(["simulate", "--model", str(path), str(u_csv), "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "chain.input" in err and "Traceback" not in err


@pytest.mark.parametrize("command", ["invert", "identify"])
def test_an_oscillator_is_not_inverted_nor_identified_online(tmp_path, capsys, command):
    path, csv = tmp_path / "osc.json", tmp_path / "d.csv"
    _oscillator().save(path)
    write_csv(csv, {"t_s": np.arange(100) * DT, "u_V": np.ones(100), "x_um": np.ones(100)})
    argv = {
        "invert": ["invert", "--model", str(path), "--target", str(csv), "--out", str(tmp_path / "u.csv")],
        "identify": ["identify", str(csv), "--init", str(path), "--out", str(tmp_path / "t.csv")],
    }[command]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "oscillator" in err and "piezo model" in err


@pytest.mark.parametrize("lag", [False, True])
def test_invert_gives_a_held_model_a_command_to_hold(tmp_path, capsys, lag):
    effects = [InputLag(fc_hz=650.0)] if lag else []
    model = SavedModel(Params.paper_1hz(), 0.0, DT, effect_set(*effects, BetweenSamples(input="hold")))
    path, target, u_csv = tmp_path / "m.json", tmp_path / "xd.csv", tmp_path / "u.csv"
    model.save(path)
    x_d = model.simulate(boucwen.paper_input(DT)[:4000])
    write_csv(target, {"t_s": np.arange(x_d.size) * DT, "x_um": x_d}, digits=17)
    assert main(["invert", "--model", str(path), "--target", str(target), "--out", str(u_csv)]) == 0
    out = capsys.readouterr().out
    assert "between_samples (hold): a command for a DAC to hold" in out
    u = read_csv(u_csv, columns=("t_s", "u_V", "x_model_um")).u
    # Held by the model's DAC, the command meets the target at every sample ...
    tolerance = boucwen.INVERSE_TOLERANCE_UM * np.maximum(1.0, np.abs(x_d))
    assert np.all(np.abs(model.simulate(u) - x_d) <= tolerance)
    # ... where the straight-line inverse's command, held, misses it.
    straight = boucwen.invert(model.params, x_d, DT, 0.0, effects=effect_set(*effects))[0]
    assert np.max(np.abs(model.simulate(straight) - x_d)) > 100 * np.max(tolerance)
