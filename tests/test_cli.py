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
