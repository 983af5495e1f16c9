"""The shell path end to end: fit/diagnose --model, identify, invert, simulate, --version.

The measured record (``Model_Vi_Do.dat`` of :mod:`boucwen.datasets`) is used where it is
found; without it those tests skip and say where it was looked for.
"""

import json
import re
import subprocess
import sys

import numpy as np
import pytest

import boucwen
from boucwen import Identifier, Params, datasets, load_model, simulate
from boucwen.cli import main
from boucwen.io import read_csv, write_csv
from boucwen.metrics import max_abs, rms


def _table(path):
    """The columns of a CSV written by the command line, by name."""
    with open(path, encoding="utf-8") as fh:
        names = fh.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, i] for i, name in enumerate(names)}


def _as_written(values):
    """``values`` as the CSV files hold them (9 significant digits, :func:`boucwen.io.write_csv`)."""
    return np.array([float(f"{v:.9g}") for v in values])


def _one_error_line(capsys, code, expected=2):
    assert code == expected
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.fixture(scope="module")
def measured():
    """The path of the measured record, or a skip naming where it was looked for."""
    try:
        return datasets.find("micromanipulator")
    except datasets.DataNotFoundError as exc:
        pytest.skip(f"measured data not on this machine: {exc}")


@pytest.fixture(scope="module")
def fitted(measured, tmp_path_factory):
    path = tmp_path_factory.mktemp("fit") / "F.json"
    assert main(["fit", str(measured), "--model", str(path)]) == 0
    return path


@pytest.fixture(scope="module")
def diagnosed(measured, tmp_path_factory):
    path = tmp_path_factory.mktemp("diagnose") / "D.json"
    assert main(["diagnose", str(measured), "--model", str(path)]) == 0
    return path


@pytest.fixture(scope="module")
def target(measured, tmp_path_factory):
    """The measured displacement as a target trajectory (t_s, x_um)."""
    rec = datasets.load("micromanipulator", measured)
    path = tmp_path_factory.mktemp("target") / "XD.csv"
    write_csv(path, {"t_s": rec.t, "x_um": rec.x})
    return path


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"boucwen {boucwen.__version__}"


# --------------------------------------------------------------------------- the model file


@pytest.mark.slow  # the diagnosis of the measured record (a module fixture)
def test_fit_and_diagnose_write_the_same_schema(measured, fitted, diagnosed):
    rec = datasets.load("micromanipulator", measured)
    for path, made_by in ((fitted, "fit"), (diagnosed, "diagnose")):
        model = load_model(path)
        assert model.source.made_by == made_by and model.source.samples == len(rec)
        assert model.source.record == str(measured) and model.dt_s == rec.dt
        # The error it records is the model's own, run open loop on the record.
        x = model.simulate(rec.u)
        assert model.source.rms_um == pytest.approx(rms(rec.x - x), rel=1e-9)
    assert len(load_model(fitted).effects) == 0
    assert len(load_model(diagnosed).effects) > 0


# --------------------------------------------------------------------------- identify


@pytest.mark.parametrize("method", ["horizon", "rpem", "paper"])
def test_identify_matches_push_many(measured, fitted, tmp_path, capsys, method):
    trace, final = tmp_path / "trace.csv", tmp_path / "final.json"
    argv = ["identify", str(measured), "--init", str(fitted), "--method", method, "--out", str(trace)]
    assert main([*argv, "--model", str(final)]) == 0
    out = capsys.readouterr().out
    rec = datasets.load("micromanipulator", measured)
    init = load_model(fitted)
    if method == "horizon":
        ident = Identifier(rec.dt, init.params, init.h0_um)
    elif method == "rpem":
        ident = Identifier.rpem(rec.dt, init.params, init.h0_um)
    else:
        ident = Identifier.paper(rec.dt, round(1.0 / rec.dt), init.params, init.h0_um)
    expected = ident.push_many(rec.u, rec.x)
    columns = _table(trace)
    np.testing.assert_array_equal(columns["x_pred_um"], _as_written(expected))
    np.testing.assert_array_equal(columns["t_s"].size, len(rec))
    for i, name in enumerate(Params.names):  # the estimates after the last sample
        assert columns[name][-1] == _as_written(ident.params.to_array()[i : i + 1])[0]
    assert load_model(final).params == ident.params
    assert "status.samples" in columns and columns["status.samples"][-1] == len(rec)
    # The block-ahead errors printed are those of the trace's columns, block by block.
    block = round(0.1 / rec.dt)
    starts = np.arange(0, len(rec), block)
    ident_blocks = np.maximum.reduceat(np.abs(rec.x - columns["x_block_um"]), starts)
    fixed_blocks = np.maximum.reduceat(np.abs(rec.x - columns["x_fixed_um"]), starts)
    np.testing.assert_array_equal(columns["x_fixed_um"], _as_written(init.simulate(rec.u)))
    printed = re.findall(r"median (\S+)\s+worst (\S+)", out)
    assert len(printed) == 2
    for (median, worst), blocks in zip(printed, (ident_blocks, fixed_blocks)):
        assert float(median) == pytest.approx(np.median(blocks), rel=1e-3)
        assert float(worst) == pytest.approx(np.max(blocks), rel=1e-3)


def test_identify_without_init_fits_the_start_and_plots(measured, tmp_path, capsys):
    trace, figure = tmp_path / "trace.csv", tmp_path / "fig.png"
    assert main(["identify", str(measured), "--out", str(trace), "--plot", str(figure)]) == 0
    out = capsys.readouterr().out
    assert "starting model: boucwen.fit on samples 0 to 1604 (1605 samples" in out
    assert "blocks from t = 8.1 s" in out  # the starting fit's samples are not scored
    assert figure.stat().st_size > 10_000 and "input_lag.fc_hz" in _table(trace)


# --------------------------------------------------------------------------- invert, simulate


@pytest.mark.slow  # the diagnosis of the measured record (a module fixture)
def test_diagnose_invert_simulate_within_the_fit_error(diagnosed, target, tmp_path, capsys):
    u_csv, x_csv = tmp_path / "U.csv", tmp_path / "X.csv"
    argv = ["invert", "--model", str(diagnosed), "--target", str(target), "--out", str(u_csv)]
    assert main([*argv, "--u-min", "0", "--u-max", "3.6"]) == 0
    out = capsys.readouterr().out
    model = load_model(diagnosed)
    cols = _table(u_csv)
    err = cols["x_model_um"] - cols["x_d_um"]
    # Past the model's start-up from its initial state (its modes and delay line start at
    # rest, which no voltage undoes): the first 1 % of the samples.
    settled = err[err.size // 100 :]
    assert rms(settled) <= model.source.rms_um and max_abs(settled) <= model.source.max_um
    assert "target reached on" in out
    assert f"rms {rms(err):.4g} µm, max {max_abs(err):.4g} µm" in out
    assert "u_min = 0 V on" in out and "u_max = 3.6 V on" in out
    assert np.all((cols["u_V"] >= 0.0) & (cols["u_V"] <= 3.6))
    assert main(["simulate", "--model", str(diagnosed), str(u_csv), "--out", str(x_csv)]) == 0
    np.testing.assert_allclose(read_csv(x_csv).x, cols["x_model_um"], rtol=1e-8)


def test_fit_invert_says_where_the_base_model_cannot_follow(fitted, target, tmp_path, capsys):
    # The base model fitted on this record bends its branches to stand in for the
    # amplifier's lag: x does not rise with u after a reversal, and no voltage follows
    # the target there. The command says where and why.
    u_csv = tmp_path / "U.csv"
    assert main(["invert", "--model", str(fitted), "--target", str(target), "--out", str(u_csv)]) == 0
    out = capsys.readouterr().out
    cols = _table(u_csv)
    err = cols["x_model_um"] - cols["x_d_um"]
    assert max_abs(err) > load_model(fitted).source.max_um  # it really cannot follow
    missed = re.search(r"missed on (\d+) \(0 of them with u on a limit\)", out)
    assert missed is not None and int(missed.group(1)) > 0
    assert "why the others are missed: its branch slope" in out


def test_fit_invert_within_the_fit_error_on_a_physical_model(tmp_path, capsys):
    dt = 5e-4
    t = np.arange(4000) * dt
    u = 50.0 - 50.0 * np.cos(2.0 * np.pi * t)
    x, _ = simulate(Params.paper_1hz(), u, dt)
    x = x + np.random.default_rng(0).normal(0.0, 0.01, x.size)
    write_csv(tmp_path / "rec.csv", {"t": t, "u": u, "x": x})
    write_csv(tmp_path / "xd.csv", {"t": t, "x": 2.0 + 8.0 * np.sin(2.0 * np.pi * 2.0 * t) ** 2})
    assert main(["fit", str(tmp_path / "rec.csv"), "--model", str(tmp_path / "m.json")]) == 0
    argv = ["invert", "--model", str(tmp_path / "m.json"), "--target", str(tmp_path / "xd.csv")]
    assert main([*argv, "--out", str(tmp_path / "u.csv")]) == 0
    cols = _table(tmp_path / "u.csv")
    err = cols["x_model_um"] - cols["x_d_um"]
    model = load_model(tmp_path / "m.json")
    assert max_abs(err) <= model.source.rms_um


def test_invert_reports_limit_hits(tmp_path, capsys):
    dt = 1e-3
    model = boucwen.SavedModel(Params.paper_1hz(), 0.0, dt)
    model.save(tmp_path / "m.json")
    t = np.arange(1000) * dt
    write_csv(tmp_path / "xd.csv", {"t": t, "x": 10.0 * np.sin(2 * np.pi * t) ** 2})
    argv = ["invert", "--model", str(tmp_path / "m.json"), "--target", str(tmp_path / "xd.csv")]
    code = main([*argv, "--out", str(tmp_path / "u.csv"), "--u-max", "30"])
    out = capsys.readouterr().out
    u = _table(tmp_path / "u.csv")["u_V"]
    hits = int(np.count_nonzero(u >= 30.0))
    assert code == 0 and hits > 0
    assert f"u_max = 30 V on {hits} samples" in out


# --------------------------------------------------------------------------- bad input: one line, exit 2


@pytest.fixture
def files(tmp_path):
    model = boucwen.SavedModel(Params.paper_1hz(), 0.0, 1e-3)
    model.save(tmp_path / "m.json")
    newer = model.to_dict() | {"version": 99}
    (tmp_path / "newer.json").write_text(json.dumps(newer), encoding="utf-8")
    (tmp_path / "broken.json").write_text('{"schema": "boucwen.model", "version": 1', encoding="utf-8")
    t = np.arange(50) * 1e-3
    write_csv(tmp_path / "xd.csv", {"t": t, "x": t})
    write_csv(tmp_path / "u.csv", {"t": t, "u": t})
    write_csv(tmp_path / "rec.csv", {"t": t, "u": t, "x": t})
    np.savetxt(tmp_path / "plain.txt", np.column_stack([t, t]))
    return tmp_path


@pytest.mark.parametrize(
    "argv, words",
    [
        (["invert", "--model", "{d}/newer.json", "--target", "{d}/xd.csv", "--out", "{d}/o.csv"], ["'version'"]),
        (["invert", "--model", "{d}/broken.json", "--target", "{d}/xd.csv", "--out", "{d}/o.csv"], ["invalid JSON"]),
        (["invert", "--model", "{d}/none.json", "--target", "{d}/xd.csv", "--out", "{d}/o.csv"], ["no such"]),
        (["invert", "--model", "{d}/m.json", "--target", "{d}/plain.txt", "--out", "{d}/o.csv"], ["--columns"]),
        (["invert", "--model", "{d}/m.json", "--target", "{d}/u.csv", "--out", "{d}/o.csv"], ["missing column 'x'"]),
        (
            [
                "invert",
                "--model",
                "{d}/m.json",
                "--target",
                "{d}/xd.csv",
                "--out",
                "{d}/o.csv",
                "--u-min",
                "5",
                "--u-max",
                "1",
            ],
            ["u_min"],
        ),
        (["invert", "--model", "{d}/m.json", "--out", "{d}/o.csv"], ["--target"]),
        (["simulate", "--model", "{d}/m.json", "{d}/xd.csv", "--out", "{d}/o.csv"], ["missing column 'u'"]),
        (["simulate", "--model", "{d}/m.json", "{d}/none.csv", "--out", "{d}/o.csv"], ["no such file"]),
        (["identify", "{d}/rec.csv"], ["--out"]),
        (["identify", "{d}/rec.csv", "--out", "{d}/o.csv", "--method", "rpem", "--refine", "background"], ["refine"]),
        (["identify", "{d}/rec.csv", "--out", "{d}/o.csv", "--init", "{d}/newer.json"], ["newer"]),
        (["identify", "{d}/rec.csv", "--out", "{d}/o.csv", "--init", "{d}/m.json", "--block", "1"], ["block"]),
        (["identify", "{d}/plain.txt", "--out", "{d}/o.csv"], ["no header line"]),
        (["fit", "{d}/plain.txt", "--columns", "1,2,5"], ["position 5"]),
    ],
)
def test_bad_input_one_line(files, capsys, argv, words):
    err = _one_error_line(capsys, main([a.format(d=files) for a in argv]))
    for word in words:
        assert word in err, (word, err)
    assert not (files / "o.csv").exists()


def test_bad_model_file_in_a_real_process(files):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "boucwen.cli",
            "simulate",
            "--model",
            str(files / "newer.json"),
            str(files / "u.csv"),
            "--out",
            str(files / "o.csv"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    assert "newer.json: field 'version': 99 is newer" in proc.stderr


def test_identify_cooperative_follows_its_schedule(tmp_path):
    # refine("cooperative") runs the window pass in refine(COOPERATIVE_INTERVALS) after every push.
    from boucwen.pacing import COOPERATIVE_INTERVALS

    dt = 1e-3
    u = 50.0 - 50.0 * np.cos(2.0 * np.pi * np.arange(3000) * dt)
    x, _ = simulate(Params.paper_1hz(), u, dt)
    write_csv(tmp_path / "rec.csv", {"t": np.arange(u.size) * dt, "u": u, "x": x})
    start = boucwen.SavedModel(Params.paper_1hz().replace(kv=0.17), 0.0, dt)
    start.save(tmp_path / "m.json")
    argv = ["identify", str(tmp_path / "rec.csv"), "--init", str(tmp_path / "m.json"), "--refine", "cooperative"]
    assert main([*argv, "--out", str(tmp_path / "trace.csv")]) == 0
    rec = read_csv(tmp_path / "rec.csv")  # its dt: the mean step of the time column as written
    ident = Identifier(rec.dt, start.params, 0.0, refine="cooperative")
    expected = []
    for a, b in zip(rec.u, rec.x):
        expected.append(ident.push(a, b))
        ident.refine(COOPERATIVE_INTERVALS)
    np.testing.assert_array_equal(_table(tmp_path / "trace.csv")["x_pred_um"], _as_written(expected))
    assert _table(tmp_path / "trace.csv")["kv"][-1] == _as_written([ident.params.kv])[0] != 0.17
