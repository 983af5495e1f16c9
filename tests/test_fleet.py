"""Fleets on Dask (boucwen.batch, boucwen.fleet, `boucwen batch`): a small generated mirror,
bad records as error rows, resume, atomic writes, a worker killed mid-run, outliers.

The fleet extra (Dask distributed, pandas, pyarrow) is installed in CI
(scripts/setup_env.sh installs .[test,fleet]); these tests import it unconditionally.
"""

import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pandas as pd
import pytest
from distributed import Client, LocalCluster

from boucwen import Params
from boucwen.batch import diagnose_many, fit_many
from boucwen.cli import main
from boucwen.fleet.generate import compare, write_fleet
from boucwen.fleet.outliers import THRESHOLD, attention_list, flag_outliers, robust_z
from boucwen.fleet.source import find_records, read_layout
from boucwen.fleet.store import ResultStore, atomic_write, atomic_write_text
from boucwen.io import read_csv, write_csv

# A 4 × 4 mirror with one actuator of each defect, records of one test pattern (2.4 s at
# 1 kHz, about 0.1 s per fit).
DEFECTS = {"creep": 1, "clipping": 1, "dead": 1}


@pytest.fixture(scope="module")
def mirror(tmp_path_factory):
    root = tmp_path_factory.mktemp("mirror")
    actuators = write_fleet(root, rows=4, cols=4, seed=3, repeats=1, defects=DEFECTS)
    return root, actuators


def _two_workers():
    """Two single-threaded worker processes on the loopback interface (HTTP server on any free port)."""
    return LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=":0")


@pytest.fixture(scope="module")
def client():
    """A client on two workers (see _two_workers), shared by the tests of this module."""
    with _two_workers() as cluster, Client(cluster) as c:
        yield c


def _copy_records(src_dir, dst_dir, names):
    dst_dir.mkdir(parents=True, exist_ok=True)
    for name in names:
        (dst_dir / f"{name}.csv").write_bytes((src_dir / f"{name}.csv").read_bytes())
    return dst_dir


def _json_files(out):
    return sorted((out / "records").glob("*.json"))


# ----------------------------------------------------------------------------- the mirror


def test_small_mirror_fit_finds_every_defect_and_writes_every_output(mirror, client, tmp_path):
    root, actuators = mirror
    out = tmp_path / "res"
    table = fit_many(root / "records", out, layout=root / "layout.csv", client=client, progress=False)

    channels = [a.channel for a in actuators]
    assert list(table["channel"]) == channels  # one row per record, in source order
    assert table["channel"].is_unique
    assert set(table["status"]) <= {"ok", "not_converged"}
    assert table["row"].tolist() == [a.row for a in actuators]
    sound = table[~table["channel"].isin([a.channel for a in actuators if a.defect])]
    assert (sound["status"] == "ok").all()
    # The Bouc-Wen fit explains most of what a straight line leaves on sound actuators.
    assert (sound["rms_after_um"] < 0.5 * sound["rms_before_um"]).all()
    assert (table["elapsed_s"] > 0).all()

    # Outliers against the truth: every defect found, no sound actuator flagged.
    report = compare(table, root / "truth.csv")
    assert report["found"] == len(DEFECTS), report
    assert report["false_positives"] == [], report
    dead = next(a.channel for a in actuators if a.defect == "dead")
    dead_row = table.set_index("channel").loc[dead]
    assert dead_row["z_kv"] < -THRESHOLD and "kv z=" in dead_row["outlier_reason"]

    # Files: table (Parquet and CSV agree), per-record JSON, outlier list, figure, run summary.
    parquet = pd.read_parquet(out / "results.parquet")
    csv = pd.read_csv(out / "results.csv")
    assert list(parquet["channel"]) == channels == list(csv["channel"])
    np.testing.assert_allclose(parquet["kv"], table["kv"])
    np.testing.assert_allclose(csv["rms_after_um"], table["rms_after_um"], rtol=1e-12)
    assert len(_json_files(out)) == len(channels)
    doc = json.loads((out / "records" / f"{channels[0]}.json").read_text(encoding="utf-8"))
    assert doc["row"]["channel"] == channels[0] and len(doc["key"]) == 64
    assert doc["detail"]["params"]["kv"] == pytest.approx(table["kv"].iloc[0])
    listed = pd.read_csv(out / "outliers.csv")
    assert set(listed["channel"]) == {a.channel for a in actuators if a.defect}
    assert (out / "fleet.png").stat().st_size > 10_000
    run = json.loads((out / "run.json").read_text(encoding="utf-8"))
    assert run["computed"] == len(channels) and run["skipped"] == 0 and run["records_per_s"] > 0


def test_long_table_source_matches_the_folder_and_carries_the_grid(mirror, client, tmp_path):
    root, actuators = mirror
    picked = [a for a in actuators[:3]]
    frames = []
    for a in picked:
        rec = read_csv(root / "records" / f"{a.channel}.csv")
        frames.append(
            pd.DataFrame({"channel": a.channel, "row": a.row, "col": a.col, "t": rec.t, "u": rec.u, "x": rec.x})
        )
    path = tmp_path / "mirror.parquet"
    pd.concat(frames, ignore_index=True).to_parquet(path)

    refs = find_records(path)
    assert [r.channel for r in refs] == [a.channel for a in picked]
    assert [(r.row, r.col) for r in refs] == [(a.row, a.col) for a in picked]
    table = fit_many(path, tmp_path / "res", client=client, progress=False, figure=False)
    folder = fit_many(
        _copy_records(root / "records", tmp_path / "three", [a.channel for a in picked]),
        tmp_path / "res_folder",
        client=client,
        progress=False,
        figure=False,
    )
    # The same samples give the same fit, whichever way they arrive.
    np.testing.assert_allclose(table["kv"], folder["kv"], rtol=1e-9)
    np.testing.assert_allclose(table["rms_after_um"], folder["rms_after_um"], rtol=1e-9)


# ----------------------------------------------------------------------------- bad records


def test_bad_records_become_error_rows_and_the_rest_completes(mirror, client, tmp_path):
    root, actuators = mirror
    src = _copy_records(root / "records", tmp_path / "src", [actuators[0].channel, actuators[1].channel])
    good = read_csv(src / f"{actuators[0].channel}.csv")
    (src / "empty.csv").write_text("", encoding="utf-8")
    write_csv(src / "wrong_columns.csv", {"t": good.t, "u": good.u, "y": good.x})
    x_nan = good.x.copy()
    x_nan[100] = np.nan
    with open(src / "nan.csv", "w", encoding="utf-8") as fh:
        fh.write("t,u,x\n")
        fh.writelines(f"{t:.9g},{u:.9g},{x:.9g}\n" for t, u, x in zip(good.t, good.u, x_nan))
    t_gap = good.t.copy()
    t_gap[500:] += 0.01
    write_csv(src / "time_gap.csv", {"t": t_gap, "u": good.u, "x": good.x})
    write_csv(src / "constant_u.csv", {"t": good.t, "u": np.full_like(good.u, 50.0), "x": good.x})

    table = fit_many(src, tmp_path / "res", client=client, progress=False, figure=False).set_index("channel")
    assert len(table) == 7
    expected = {
        "empty": "empty file",
        "wrong_columns": "missing column 'x'",
        "nan": "non-finite value",
        "time_gap": "non-uniform sampling",
        "constant_u": "u is constant",
    }
    for name, words in expected.items():
        assert table.loc[name, "status"] == "error", name
        assert words in table.loc[name, "error"], (name, table.loc[name, "error"])
        assert pd.isna(table.loc[name, "kv"])
        assert not table.loc[name, "outlier"]
    for a in actuators[:2]:
        assert table.loc[a.channel, "status"] == "ok"
    listed = attention_list(table.reset_index())
    assert set(expected) <= set(listed["channel"])

    # The same faults in a long table: NaN samples and too few rows are error rows too.
    frame = pd.DataFrame({"channel": "good", "t": good.t, "u": good.u, "x": good.x})
    bad = frame.iloc[:200].assign(channel="holes")
    bad.loc[bad.index[50], "u"] = np.nan
    short = frame.iloc[:2].assign(channel="short")
    path = tmp_path / "table.csv"
    pd.concat([frame, bad, short]).to_csv(path, index=False)
    table = fit_many(path, tmp_path / "res_table", client=client, progress=False, figure=False).set_index("channel")
    assert table.loc["good", "status"] == "ok"
    assert table.loc["holes", "status"] == "error" and "column 'u'" in table.loc["holes", "error"]
    assert table.loc["short", "status"] == "error" and "at least 3" in table.loc["short", "error"]


def test_sources_that_cannot_be_read_raise_value_errors(tmp_path, mirror):
    root, _ = mirror
    with pytest.raises(ValueError, match="no such folder or file"):
        find_records(tmp_path / "absent")
    (tmp_path / "empty_dir").mkdir()
    with pytest.raises(ValueError, match="no CSV records"):
        find_records(tmp_path / "empty_dir")
    with pytest.raises(ValueError, match="no file matches"):
        find_records(str(tmp_path / "nothing*" / "*.csv"))
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for d in ("a", "b"):
        (tmp_path / d / "same.csv").write_text("t,u,x\n0,0,0\n1,1,1\n2,2,2\n", encoding="utf-8")
    with pytest.raises(ValueError, match="two records are named 'same'"):
        find_records(str(tmp_path / "*" / "same.csv"))
    pd.DataFrame({"channel": ["a"], "t": [0.0], "u": [1.0]}).to_parquet(tmp_path / "t.parquet")
    with pytest.raises(ValueError, match=r"missing \['x'\]"):
        find_records(tmp_path / "t.parquet")
    (tmp_path / "layout.csv").write_text("channel,row,col\na,0,0\nb,0,0\n", encoding="utf-8")
    with pytest.raises(ValueError, match="share row 0, col 0"):
        read_layout(tmp_path / "layout.csv")
    assert read_layout(root / "layout.csv")["r01c02"] == (1, 2)
    with pytest.raises(ValueError, match="workers must be an integer >= 1"):
        fit_many(root / "records", tmp_path / "x", workers=0)
    with pytest.raises(ValueError, match="kind must be one of"):
        from boucwen.batch import run_fleet

        run_fleet("smooth", root / "records", tmp_path / "x")


# ----------------------------------------------------------------------------- resume


def test_rerun_skips_done_records_and_redoes_changed_or_failed_ones(mirror, client, tmp_path):
    root, actuators = mirror
    names = [a.channel for a in actuators[:4]]
    src = _copy_records(root / "records", tmp_path / "src", names)
    out = tmp_path / "res"
    first = fit_many(src, out, client=client, progress=False, figure=False)
    assert first.attrs["run"]["computed"] == 4
    stamps = {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in _json_files(out)}

    again = fit_many(src, out, client=client, progress=False, figure=False)
    assert again.attrs["run"]["skipped"] == 4 and again.attrs["run"]["computed"] == 0
    assert {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in _json_files(out)} == stamps
    pd.testing.assert_frame_equal(first, again)

    # A changed record, a result that failed and a lost result are done again; the rest is not.
    rec = read_csv(src / f"{names[0]}.csv")
    write_csv(src / f"{names[0]}.csv", {"t": rec.t, "u": rec.u, "x": rec.x + 0.5})
    store = ResultStore(out)
    doc = store.read(names[1])
    doc["row"]["status"] = "failed"
    atomic_write_text(store.record_path(names[1]), json.dumps(doc))
    store.record_path(names[2]).unlink()
    third = fit_many(src, out, client=client, progress=False, figure=False)
    assert third.attrs["run"]["skipped"] == 1 and third.attrs["run"]["computed"] == 3
    assert store.record_path(names[3]).read_bytes() == stamps[f"{names[3]}.json"][1]
    assert third["x0"].iloc[0] == pytest.approx(first["x0"].iloc[0] + 0.5, abs=0.05)
    assert (third["status"] == "ok").all() and len(third) == 4

    # Other options (here the seed) are other results: nothing is skipped.
    fourth = fit_many(src, out, client=client, seed=1, progress=False, figure=False)
    assert fourth.attrs["run"]["computed"] == 4


def test_interrupted_run_resumes_from_what_was_stored(mirror, client, tmp_path, monkeypatch):
    """A run stopped after two results (KeyboardInterrupt in the driver) keeps them; the re-run does the rest."""
    root, actuators = mirror
    names = [a.channel for a in actuators[:6]]
    src = _copy_records(root / "records", tmp_path / "src", names)
    out = tmp_path / "res"
    store_write = ResultStore.write
    written = []

    def write_then_stop(self, row, key):
        store_write(self, row, key)
        written.append(row["channel"])
        if len(written) == 2:
            raise KeyboardInterrupt

    monkeypatch.setattr(ResultStore, "write", write_then_stop)
    with pytest.raises(KeyboardInterrupt):
        fit_many(src, out, client=client, progress=False, figure=False)
    monkeypatch.setattr(ResultStore, "write", store_write)
    assert len(_json_files(out)) == 2
    table = fit_many(src, out, client=client, progress=False, figure=False)
    assert table.attrs["run"]["skipped"] == 2 and table.attrs["run"]["computed"] == 4
    assert sorted(table["channel"]) == sorted(names) and (table["status"] == "ok").all()


# ----------------------------------------------------------------------------- atomic writes


def test_atomic_write_never_leaves_a_partial_file(tmp_path):
    target = tmp_path / "results.csv"
    target.write_text("old complete content\n", encoding="utf-8")

    def failing_writer(tmp):
        tmp.write_text("new but only half", encoding="utf-8")
        assert target.read_text(encoding="utf-8") == "old complete content\n"  # not touched while writing
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        atomic_write(target, failing_writer)
    assert target.read_text(encoding="utf-8") == "old complete content\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.csv"]  # no temporary file left

    atomic_write(target, lambda tmp: tmp.write_text("new\n", encoding="utf-8"))
    assert target.read_text(encoding="utf-8") == "new\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.csv"]

    seen = []
    atomic_write(tmp_path / "fig.png", lambda tmp: seen.append(tmp.suffix) or tmp.write_bytes(b"png"))
    assert seen == [".png"]  # writers that infer the format from the name still work


def test_store_writes_each_result_atomically(tmp_path, monkeypatch):
    """Replacing is the only way a result file changes: os.replace of a complete temporary file."""
    store = ResultStore(tmp_path / "res")
    replaced = []
    real_replace = os.replace

    def spy(src, dst):
        with open(src, encoding="utf-8") as fh:
            replaced.append((json.load(fh)["row"]["channel"], os.path.basename(dst)))
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", spy)
    row = {"channel": "ch/1", "status": "ok", "kv": np.float64(0.19), "n": float("nan"), "detail": {"a": np.int64(2)}}
    store.write(row, "k" * 64)
    assert len(replaced) == 1 and replaced[0][0] == "ch/1"
    doc = store.read("ch/1")
    assert doc["row"]["kv"] == 0.19 and doc["row"]["n"] is None and doc["detail"] == {"a": 2}
    assert store.record_path("ch/1").parent == store.records  # a channel name never escapes the folder
    assert [p.name for p in store.records.iterdir()] == [store.record_path("ch/1").name]


# ----------------------------------------------------------------------------- killed worker


def test_killing_a_worker_mid_run_loses_and_duplicates_nothing(tmp_path):
    # Longer records (4 test patterns, ≈0.3-0.6 s per fit) so that the kill lands mid-run.
    src = tmp_path / "long"
    write_fleet(src, rows=3, cols=4, seed=5, repeats=4, defects={})
    channels = [r.channel for r in find_records(src / "records")]
    out = tmp_path / "res"
    killed = {}

    with _two_workers() as cluster, Client(cluster) as c:
        pids = c.run(os.getpid)

        def kill_one_when_running():
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline and len(list((out / "records").glob("*.json"))) < 2:
                time.sleep(0.02)
            victim = next(iter(pids))
            killed["running"] = c.processing(workers=[victim])[victim]
            killed["done_before"] = len(list((out / "records").glob("*.json")))
            os.kill(pids[victim], signal.SIGKILL)
            killed["pid"] = pids[victim]

        killer = threading.Thread(target=kill_one_when_running)
        killer.start()
        table = fit_many(src / "records", out, client=c, progress=False, figure=False)
        killer.join()

    assert killed["running"], "the killed worker was not running a task"
    assert killed["done_before"] < len(channels) - 2, killed  # the run was far from its end
    assert sorted(table["channel"]) == sorted(channels)  # nothing lost, nothing twice
    assert table["channel"].is_unique
    assert (table["status"] == "ok").all(), table[["channel", "status", "error"]]
    assert len(_json_files(out)) == len(channels)
    # The records the dead worker held are among those finished once each: redone, not lost.
    held = {ch for key in killed["running"] for ch in channels if f"-{ch}-" in str(key)}
    assert held, killed


# ----------------------------------------------------------------------------- outliers


def test_robust_z_ignores_the_wild_values_it_flags():
    rng = np.random.default_rng(0)
    values = np.concatenate([rng.normal(10.0, 0.1, 200), [50.0, -30.0], [np.nan]])
    z = robust_z(values)
    assert abs(np.nanmedian(z[:200])) < 0.2 and 0.8 < np.nanstd(z[:200]) < 1.2
    assert z[200] > 100 and z[201] < -100 and np.isnan(z[202])
    # More than half equal: the mean absolute deviation takes over; all equal: zero.
    z = robust_z(np.array([1.0, 1.0, 1.0, 1.0, 2.0]))
    assert z[-1] == pytest.approx(1.0 / (1.2533 * 0.2)) and np.all(z[:4] == 0.0)
    assert np.all(robust_z(np.full(5, 3.0)) == 0.0)


def test_flag_outliers_scores_errors_in_log_and_skips_error_rows():
    n = 40
    table = pd.DataFrame(
        {
            "channel": [f"c{k}" for k in range(n)],
            "status": ["ok"] * (n - 1) + ["error"],
            "kv": np.linspace(0.18, 0.20, n),
            "rms_after_um": np.full(n, 0.1) * np.linspace(0.9, 1.1, n),
        }
    )
    table.loc[5, "rms_after_um"] = 0.5  # five times the typical error
    table.loc[n - 1, "kv"] = 99.0  # an error row's leftovers are not scored
    flagged = flag_outliers(table, columns=("kv", "rms_after_um"))
    assert flagged["outlier"].tolist() == [k == 5 for k in range(n)]
    assert flagged.loc[5, "outlier_reason"].startswith("rms_after_um z=+")
    assert np.isnan(flagged.loc[n - 1, "z_kv"])
    with pytest.raises(ValueError, match="threshold"):
        flag_outliers(table, threshold=0)


# ----------------------------------------------------------------------------- diagnose, CLI


@pytest.fixture(scope="module")
def two_diagnosed(mirror, client, tmp_path_factory):
    """A sound actuator and the creep actuator as one long table, diagnosed by
    diagnose_many: (the table by channel, the creep actuator, the results folder)."""
    root, actuators = mirror
    creep = next(a for a in actuators if a.defect == "creep")
    sound = next(a for a in actuators if not a.defect)
    frames = []
    for a in (sound, creep):
        rec = read_csv(root / "records" / f"{a.channel}.csv")
        frames.append(pd.DataFrame({"channel": a.channel, "t": rec.t, "u": rec.u, "x": rec.x}))
    tmp_path = tmp_path_factory.mktemp("two")
    path = tmp_path / "two.csv"
    pd.concat(frames).to_csv(path, index=False)
    table = diagnose_many(path, tmp_path / "res", client=client, progress=False, figure=False).set_index("channel")
    return table, creep, tmp_path / "res"


def test_diagnose_many_on_a_long_table(two_diagnosed):
    table, creep, res = two_diagnosed
    assert (table["kind"] == "diagnose").all() and (table["status"] == "ok").all()
    assert (table["rms_after_um"] <= table["rms_before_um"] + 1e-12).all()
    doc = json.loads((res / "records" / f"{creep.channel}.json").read_text(encoding="utf-8"))
    assert doc["detail"]["effects"] == table.loc[creep.channel, "effects"].split(",")


@pytest.mark.xfail(
    strict=True,
    reason="known: on this record the refit without the first block leaves h0 undetermined (it runs to "
    "199 µm, the block's held-out RMS 119 µm, the base model's cross-validation 60 µm), so the judge's "
    "gains here follow that block and the named set follows the solver's path: creep while the fits "
    "could leave the admissible region, saturation (tentative) since they keep to it",
)
def test_diagnose_many_names_the_creep(two_diagnosed):
    table, creep, _ = two_diagnosed
    assert "creep" in table.loc[creep.channel, "effects"].split(",")


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "boucwen.cli", *map(str, args)], capture_output=True, text=True, timeout=300
    )


def _one_line_error(code, stderr, *words):
    assert code == 2, (code, stderr)
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    for word in words:
        assert word in lines[0], lines[0]


def test_cli_batch_fit_runs_prints_and_resumes(mirror, tmp_path, capsys):
    root, actuators = mirror
    names = [a.channel for a in actuators if not a.defect][:2]
    src = _copy_records(root / "records", tmp_path / "src", names)
    out = tmp_path / "res"
    proc = _cli("batch", "fit", src, "--out", out, "--workers", "1", "--no-figure")
    assert proc.returncode == 0, proc.stderr
    assert "local Dask cluster: 1 worker process × 1 thread" in proc.stderr
    assert "batch fit: 2/2 records" in proc.stderr and "records/s" in proc.stderr
    assert "2 records: 2 ok" in proc.stdout and "no outlier, no error" in proc.stdout
    assert len(pd.read_parquet(out / "results.parquet")) == 2

    (src / "broken.csv").write_text("t,u,x\n", encoding="utf-8")
    assert main(["batch", "fit", str(src), "--out", str(out), "--workers", "1", "--no-figure"]) == 1
    captured = capsys.readouterr()
    assert "3 records: 1 error, 2 ok (2 already done, 1 computed" in captured.out
    assert "broken: error:" in captured.out and "header only" in captured.out
    assert main(["batch", "fit", str(src), "--out", str(out), "--quiet", "--no-figure"]) == 1
    captured = capsys.readouterr()
    assert "(3 already done, 0 computed)" in captured.out and captured.err == ""


def test_cli_batch_errors_are_one_line_with_exit_code_2(tmp_path, mirror, capsys):
    root, _ = mirror
    records, out = str(root / "records"), str(tmp_path / "o")
    (tmp_path / "file").write_text("x", encoding="utf-8")
    cases = [
        (["batch", "fit", str(tmp_path / "absent"), "--out", out], "no such folder or file"),
        (["batch", "fit", records, "--out", out, "--workers", "0"], "workers"),
        (
            ["batch", "fit", records, "--out", out, "--scheduler", "tcp://127.0.0.1:1", "--workers", "2"],
            "local cluster",
        ),
        (["batch", "fit", records, "--out", out, "--scheduler", "no-port"], "cannot connect to the Dask scheduler"),
        (["batch", "smooth", records, "--out", out], "invalid choice"),
        (["batch", "fit", records, "--out", str(tmp_path / "file")], "not a folder"),
    ]
    for argv, words in cases:
        code = main(argv)
        _one_line_error(code, capsys.readouterr().err, words)


def test_without_the_fleet_extra_batch_names_the_install_command():
    code = (
        "import sys; sys.modules['pandas'] = None\n"
        "import boucwen, boucwen.cli\n"
        "assert not any(m in sys.modules for m in ('dask', 'distributed', 'pyarrow')), 'core imports the extra'\n"
        "try:\n"
        "    import boucwen.batch\n"
        "except ImportError as exc:\n"
        "    print(exc)\n"
        "sys.exit(boucwen.cli.main(['batch', 'fit', 'x', '--out', 'y']))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert "pip install boucwen[fleet]" in proc.stdout and "missing: pandas" in proc.stdout
    _one_line_error(proc.returncode, proc.stderr, "pip install boucwen[fleet]")


def test_progress_line_counts_rate_and_time_left():
    import io

    from boucwen.fleet.progress import Progress, format_duration

    stream = io.StringIO()
    bar = Progress("batch fit", total=10, skipped=4, stream=stream)
    bar.start()
    bar.started -= 2.0  # two records in two seconds: 1 record/s, 4 left
    bar.update()
    bar.update(error=True)
    line = bar.line()
    assert line.startswith("batch fit: 6/10 records (4 already done), 1 error, ")
    assert "records/s" in line and line.endswith("s left")
    assert 0.9 < bar.rate < 1.1 and format_duration(4 / bar.rate) in line
    assert stream.getvalue().splitlines()[0].startswith("batch fit: 5/10 records")  # not a terminal: full lines
    assert [format_duration(s) for s in (42, 185, 7620, float("inf"))] == ["42s", "3m05s", "2h07m", "?"]


def test_connects_to_a_running_scheduler_by_address(mirror, client, tmp_path):
    root, actuators = mirror
    src = _copy_records(root / "records", tmp_path / "src", [a.channel for a in actuators[:2]])
    table = fit_many(src, tmp_path / "res", scheduler=client.scheduler.address, progress=False, figure=False)
    assert (table["status"] == "ok").all()
    assert table.attrs["run"]["cluster"]["scheduler"] == client.scheduler.address
    assert table.attrs["run"]["cluster"]["workers"] == 2


def test_task_keeps_what_the_diagnosis_left_unexplained(mirror, monkeypatch):
    """A diagnosis that reports `unexplained` gets it into the row (as JSON) and the JSON detail."""
    from types import SimpleNamespace

    from boucwen.fleet import tasks
    from boucwen.fleet.source import find_records

    root, _ = mirror
    ref = find_records(root / "records")[0]
    report = SimpleNamespace(
        params=Params.paper_1hz(),
        h0_um=0.0,
        rms_before_um=0.3,
        max_before_um=1.0,
        rms_after_um=0.2,
        max_after_um=0.8,
        effects=["creep"],
        unexplained={"rms_um": 0.15, "note": "start-up transient"},
        to_dict=lambda: {"effects": ["creep"]},
    )
    monkeypatch.setattr(tasks, "diagnose", lambda *a, **k: report)
    row = tasks.run_task(ref, tasks.TaskOptions(kind="diagnose"))
    assert row["status"] == "ok" and row["effects"] == "creep"
    assert json.loads(row["unexplained"]) == report.unexplained
    assert row["detail"]["unexplained"] == report.unexplained
    del report.unexplained  # an older Diagnosis: no such field, no column value
    row = tasks.run_task(ref, tasks.TaskOptions(kind="diagnose"))
    assert row["status"] == "ok" and row["unexplained"] is None
