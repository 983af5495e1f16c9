"""The boucwen command line: exit codes, one-line errors, fit and reproduce."""

import json
import subprocess
import sys

import numpy as np
import pytest

from boucwen import Params, simulate
from boucwen.cli import main
from boucwen.io import write_csv


def run_cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "boucwen.cli", *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=300
    )


def assert_one_line_error(proc):
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "error" in lines[0]


@pytest.fixture
def good_csv(tmp_path):
    dt = 5e-4
    t = np.arange(4000) * dt
    u = 50.0 - 50.0 * np.cos(2.0 * np.pi * t)
    x, _ = simulate(Params.paper_1hz(), u, dt)
    path = tmp_path / "loop.csv"
    write_csv(path, {"t": t, "u": u, "x": x, "extra": np.zeros_like(t)})
    return path


def test_fit_prints_and_writes_json(good_csv, tmp_path):
    out = tmp_path / "fit.json"
    proc = run_cli("fit", good_csv, "--json", out)
    assert proc.returncode == 0, proc.stderr
    assert "kv" in proc.stdout and "µm" in proc.stdout
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert doc["params"]["kv"] == pytest.approx(0.19, rel=1e-5)
    assert doc["params"]["n"] == pytest.approx(1.52, rel=1e-5)
    assert doc["rms_um"] < 1e-5 and doc["success"] is True


@pytest.mark.parametrize(
    "content",
    [
        "t,u,x\n0,1,2\n0.1,oops,3\n0.2,1,2\n",  # not a number
        "t,u\n0,1\n0.1,2\n0.2,3\n",  # missing column
        "",  # empty
        "t,u,x\n0,1,2\n0.1,2,3\n0.2,2,3\n0.3,2,3\n0.4,2,3\n0.5,2,3\n",  # too short for fit
    ],
)
def test_fit_bad_csv(tmp_path, content):
    path = tmp_path / "bad.csv"
    path.write_text(content, encoding="utf-8")
    assert_one_line_error(run_cli("fit", path))


def test_fit_missing_file(tmp_path):
    assert_one_line_error(run_cli("fit", tmp_path / "nope.csv"))


def test_fit_json_unwritable(good_csv, tmp_path):
    # The output's folder cannot be created: a regular file stands in its path.
    (tmp_path / "file").write_text("")
    assert_one_line_error(run_cli("fit", good_csv, "--json", tmp_path / "file" / "dir" / "x.json"))


def test_missing_output_folders_are_created(good_csv, tmp_path):
    out = tmp_path / "new" / "dir" / "x.json"
    proc = run_cli("fit", good_csv, "--json", out)
    assert proc.returncode in (0, 1) and out.exists(), proc.stderr


@pytest.mark.parametrize(
    "argv", [[], ["frobnicate"], ["fit"], ["fit", "a.csv", "--bogus"], ["reproduce", "--window", "many"]]
)
def test_usage_errors(argv):
    assert_one_line_error(run_cli(*argv))


def test_reproduce_bad_window(tmp_path):
    assert_one_line_error(run_cli("reproduce", "--quick", "--no-figures", "--window", "3", "--out", tmp_path))


def test_reproduce_out_is_a_file(tmp_path):
    target = tmp_path / "file"
    target.write_text("x", encoding="utf-8")
    assert_one_line_error(run_cli("reproduce", "--quick", "--no-figures", "--out", target))


def test_help_exits_zero(capsys):
    assert main(["--help"]) == 0
    assert "reproduce" in capsys.readouterr().out


def test_reproduce_quick_in_process(tmp_path, capsys):
    assert main(["reproduce", "--quick", "--no-figures", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "results.json").exists()
    assert "Table 1" in capsys.readouterr().out


# --------------------------------------------------------------------------- diagnose: records as they come


@pytest.fixture(scope="module")
def drift_samples():
    from boucwen.experiments.undeclared_records import make_record

    rec = make_record("drift", 0, "paper_1hz", 0.005)
    return np.arange(rec.u.size) * rec.dt, rec.u, rec.x


def _csv(path, header, columns):
    write_csv(path, dict(zip(header.split(","), columns)))
    return path


@pytest.mark.parametrize(
    "header, options, says",
    [
        ("t_s,u_V,x_um", [], "t = 't_s' [s], u = 'u_V' [V], x = 'x_um' [um]"),
        ("Voltage,Displacement", ["--dt", "0.001"], "no time column, dt = 0.001 s"),
        ("stamp,cmd,gap", ["--columns", "stamp,cmd,gap"], "t = 'stamp' [s], u = 'cmd' [V]"),
    ],
)
def test_diagnose_prints_the_report_without_output_files(tmp_path, capsys, drift_samples, header, options, says):
    t, u, x = drift_samples
    columns = (t, u, x) if header.count(",") == 2 else (u, x)
    path = _csv(tmp_path / "rec.csv", header, columns)
    assert main(["diagnose", str(path), *options]) == 0
    out = capsys.readouterr().out
    assert says in out
    assert "effects: drift" in out and "error before (base model)" in out and "residual:" in out
    assert "wrote" not in out and sorted(p.name for p in tmp_path.iterdir()) == ["rec.csv"]


def test_diagnose_judges_on_validation_records_and_prints_unseen_errors(tmp_path, capsys, drift_samples):
    # The second half of the record as two more records of the same device.
    t, u, x = drift_samples
    half, three = t.size // 2, 3 * t.size // 4
    a = _csv(tmp_path / "a.csv", "t_s,u_V,x_um", (t[:half], u[:half], x[:half]))
    b = _csv(tmp_path / "b.csv", "t_s,u_V,x_um", (t[half:three] - t[half], u[half:three], x[half:three]))
    c = _csv(tmp_path / "c.csv", "t_s,u_V,x_um", (t[three:] - t[three], u[three:], x[three:]))
    assert main(["diagnose", str(a), "--validate", str(b), "--validate", str(c)]) == 0
    out = capsys.readouterr().out
    assert "unseen data (4 forward folds)" in out
    for path, samples in ((b, three - half), (c, t.size - three)):
        assert f"validation record {path} ({samples} samples, offset, trend and initial state re-estimated)" in out
    assert "drift: confident" in out or "drift: tentative" in out


def test_diagnose_resamples_non_uniform_time_when_asked(tmp_path, capsys, drift_samples):
    t, u, x = drift_samples
    jittered = t + np.random.default_rng(0).uniform(-0.2e-3, 0.2e-3, t.size) * (np.arange(t.size) % 3 == 1)
    path = _csv(tmp_path / "jitter.csv", "t,u,x", (jittered, u, x))
    proc = run_cli("diagnose", path)
    assert_one_line_error(proc)
    assert "non-uniform sampling: steps from" in proc.stderr and "--resample DT" in proc.stderr
    report = tmp_path / "r.json"
    assert main(["diagnose", str(path), "--resample", "0.001", "--json", str(report)]) == 0
    out = capsys.readouterr().out
    assert "resampled to dt = 0.001 s" in out and "spread" in out and "effects: drift" in out
    resampled = json.loads(report.read_text(encoding="utf-8"))["data"]["resampled"]
    assert resampled["dt_s"] == 0.001 and 0.3 < resampled["step_spread"] < 0.4


@pytest.mark.parametrize(
    "content, options, words",
    [
        ("t_ms,u,x\n0,1,2\n1,2,3\n2,3,4\n", [], "'t_ms' is in ms"),
        ("t,u,pos_nm\n0,1,2\n1,2,3\n2,3,4\n", [], "'pos_nm' is in nm"),
        ("t,u,voltage,x\n0,1,1,2\n1,2,2,3\n2,3,3,4\n", [], "all name the voltage"),
        ("t,u\n0,1\n1,2\n2,3\n", [], "missing column 'x'"),
        ("u,x\n1,2\n2,3\n3,4\n", [], "no time column"),
        ("t,u,x\n0,1,2\n1,2,3\n2,3,4\n", ["--dt", "0.1"], "has a time column 't'"),
        ("t,u,x\n0,1,2\n1,2,3\n2,3,4\n", ["--columns", "t,volts,x"], "'volts' named by columns"),
        ("t,u,x\n0,1,2\n1,2,3\n2,3,4\n", ["--resample", "0"], "resample must be a step"),
        ("t,u,x\n0,1,2\n1,2,3\n2,3,4\n", ["--dt", "fast"], "invalid float value"),
        ("1.8\t0\t-123\n1.9\t0\t-120\n", [], "no header line"),
    ],
)
def test_diagnose_bad_record_one_line(tmp_path, content, options, words):
    path = tmp_path / "bad.csv"
    path.write_text(content, encoding="utf-8")
    proc = run_cli("diagnose", path, *options)
    assert_one_line_error(proc)
    assert words in proc.stderr, proc.stderr


def test_diagnose_dataset_options_and_missing_data(tmp_path, monkeypatch, capsys):
    from boucwen import datasets

    assert main(["diagnose", "--dataset", "micromanipulator", "--dt", "0.1"]) == 2
    assert "not --dataset" in capsys.readouterr().err
    monkeypatch.setenv("BOUCWEN_DATA", str(tmp_path))
    monkeypatch.setattr(datasets, "_shared_data_dir", lambda: tmp_path / "none")
    assert main(["diagnose", "--dataset", "micromanipulator"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "$BOUCWEN_DATA" in err and "../shared/data" in err


def test_a_dataset_file_is_read_as_its_record(tmp_path, capsys):
    # A file named as one of boucwen.datasets' (whitespace-separated, no header) is that record.
    dt = 0.005
    t = np.arange(2000) * dt
    u = 1.8 - 1.8 * np.cos(2 * np.pi * t)
    x, _ = simulate(Params.paper_1hz(), u, dt)
    table = np.column_stack([u, *np.zeros((3, t.size)), x, np.zeros((2, t.size)).T])
    path = tmp_path / "Model_Vi_Do.dat"
    np.savetxt(path, table, fmt="%.6f", delimiter="\t")
    assert main(["fit", str(path)]) in (0, 1)
    out = capsys.readouterr().out
    assert "the measured record 'micromanipulator'" in out and "2000 samples, dt = 0.005 s" in out


def test_plot_legend_says_base_model_only_when_nothing_was_added(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    from boucwen import Params
    from boucwen.diagnosis import Diagnosis, ModelFit
    from boucwen.plots import plot_diagnosis

    legends = []
    monkeypatch.setattr(
        Figure,
        "savefig",
        lambda fig, *a, **k: legends.append([t.get_text() for ax in fig.axes for t in ax.get_legend().get_texts()]),
    )
    t = np.arange(200) * 1e-3
    u, x = np.sin(t), np.cos(t)
    for effects in ([], ["drift"]):
        p = Params.paper_1hz()
        d = Diagnosis(effects, 0.1, 0.2, 0.05, 0.1, p, 0.0, ModelFit(p, 0.0), {}, x_base=x + 0.01, x_extended=x + 0.005)
        plot_diagnosis(d, t, u, x, tmp_path / "f.png")
    nothing, drift = legends
    assert any(text.startswith("base model only") for text in nothing)
    assert not any("none" in text or "with" in text for text in nothing)
    assert any(text.startswith("with drift") for text in drift)
