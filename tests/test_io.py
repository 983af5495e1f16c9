"""Reading and writing records (boucwen.io) and the measured datasets."""

from importlib import resources

import numpy as np
import pytest

from boucwen import datasets
from boucwen.io import Record, read_csv, validate_samples, write_csv


def _write(tmp_path, text, name="rec.csv", mode="w"):
    path = tmp_path / name
    if mode == "wb":
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


def _rows(n=5, dt=0.001):
    return "".join(f"{k * dt!r},{k * 0.5},{k * 0.1}\n" for k in range(n))


def _expect(path, *words):
    with pytest.raises(ValueError) as info:
        read_csv(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert str(path) in msg
    for word in words:
        assert word in msg, f"{word!r} not in {msg!r}"
    return msg


# ----------------------------------------------------------------------------- good files


def test_round_trip(tmp_path):
    dt = 1e-4
    t = np.arange(2000) * dt
    u = 50 - 50 * np.cos(2 * np.pi * 10 * t)
    x = 0.19 * u + 0.015 + 1e-3 * np.sin(t)
    path = tmp_path / "bench run.csv"
    write_csv(path, {"x": x, "extra": -t, "u": u, "t": t})
    rec = read_csv(path)
    assert isinstance(rec, Record)
    assert rec.name == "bench run"
    assert len(rec) == 2000
    assert rec.dt == pytest.approx(dt, rel=1e-9)
    assert rec.sample_rate == pytest.approx(1e4, rel=1e-9)
    for got, want in ((rec.t, t), (rec.u, u), (rec.x, x)):
        assert got.dtype == np.float64 and got.flags.c_contiguous
        np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-12)
    assert rec.meta["columns"] == ["x", "extra", "u", "t"]


def test_writes_header_and_9_digits(tmp_path):
    path = tmp_path / "a.csv"
    write_csv(path, {"t": [0.0, 0.1, 0.2], "u": [1 / 3, 2.0, 3.0], "x": [1e-12, 2.0, 3.0]})
    lines = path.read_text().splitlines()
    assert lines[0] == "t,u,x"
    assert lines[1] == "0,0.333333333,1e-12"


def test_tolerates_spaces_bom_blank_lines_and_small_jitter(tmp_path):
    text = "\ufeff t , u , x \n0.0, 1, 2\n\n0.0010000005, 2, 3\n0.002, 3, 4\n"
    rec = read_csv(_write(tmp_path, text))
    np.testing.assert_array_equal(rec.u, [1, 2, 3])
    assert rec.dt == pytest.approx(0.001)


def test_long_record_with_9_digit_time_stamps(tmp_path):
    t = 1000.0 + np.arange(500) * 1e-4
    path = tmp_path / "late.csv"
    write_csv(path, {"t": t, "u": np.ones(500), "x": np.zeros(500)})
    assert read_csv(path).dt == pytest.approx(1e-4, rel=1e-3)


# ----------------------------------------------------------------------------- bad files


def test_missing_file(tmp_path):
    path = tmp_path / "nope.csv"
    with pytest.raises(ValueError, match="no such file") as info:
        read_csv(path)
    assert str(path) in str(info.value)


def test_directory(tmp_path):
    _expect(tmp_path, "directory")


def test_empty_file(tmp_path):
    _expect(_write(tmp_path, ""), "empty")
    _expect(_write(tmp_path, "\n \n", name="blank.csv"), "empty")


def test_header_only(tmp_path):
    _expect(_write(tmp_path, "t,u,x\n"), "header only")


def test_missing_column(tmp_path):
    msg = _expect(_write(tmp_path, "t,u,y\n" + _rows()), "line 1", "missing column 'x'", "found")
    assert "'y'" in msg
    _expect(_write(tmp_path, "time,u\n0,1\n", name="b.csv"), "missing column 'x'", "'time'", "pos", "--columns")


def test_duplicate_column(tmp_path):
    _expect(_write(tmp_path, "t,u,x,u\n" + "0,1,2,3\n1,1,2,3\n2,1,2,3\n"), "'u'", "2 times")


@pytest.mark.parametrize("sep,word", [(";", "';'"), ("\t", "tabs"), (" ", "spaces")])
def test_wrong_delimiter_in_header(tmp_path, sep, word):
    text = sep.join("tux") + "\n" + _rows().replace(",", sep)
    _expect(_write(tmp_path, text), "line 1", word, "','")


def test_wrong_delimiter_in_rows(tmp_path):
    _expect(_write(tmp_path, "t,u,x\n0;1;2\n"), "line 2", "expected 3", "';'")


def test_wrong_number_of_fields(tmp_path):
    _expect(_write(tmp_path, "t,u,x\n0,1,2\n0.1,1\n0.2,1,2\n"), "line 3", "expected 3", "found 2")


def test_text_in_number_field(tmp_path):
    text = "t,u,x\n0,1,2\n0.1,abc,2\n0.2,1,2\n"
    _expect(_write(tmp_path, text), "line 3", "column 'u'", "'abc'", "not a number")
    text = "t,u,x\n0,1,2\n0.1,1,\n0.2,1,2\n"
    _expect(_write(tmp_path, text, name="b.csv"), "line 3", "column 'x'", "not a number")
    text = "t,u,x\n0,1,2\n0.1,1_000,2\n0.2,1,2\n"
    _expect(_write(tmp_path, text, name="c.csv"), "line 3", "column 'u'", "not a number")


@pytest.mark.parametrize("bad", ["nan", "inf", "-Infinity"])
def test_non_finite(tmp_path, bad):
    text = f"t,u,x\n0,1,2\n0.1,1,{bad}\n0.2,1,2\n"
    _expect(_write(tmp_path, text), "line 3", "column 'x'", "non-finite")


def test_too_few_rows(tmp_path):
    _expect(_write(tmp_path, "t,u,x\n0,1,2\n0.1,1,2\n"), "only 2 data rows", "at least 3")


@pytest.mark.parametrize("times,line", [((0, 0.1, 0.1, 0.3), 4), ((0, 0.1, 0.05, 0.3), 4)])
def test_time_not_increasing(tmp_path, times, line):
    text = "t,u,x\n" + "".join(f"{t},1,2\n" for t in times)
    _expect(_write(tmp_path, text), f"line {line}", "strictly increasing")


def test_non_uniform_sampling(tmp_path):
    text = "t,u,x\n" + "".join(f"{t},1,2\n" for t in (0, 0.1, 0.2, 0.35, 0.4))
    _expect(_write(tmp_path, text), "non-uniform", "line 5", "tolerance")


def test_no_header_line(tmp_path):
    _expect(_write(tmp_path, "0.0 1 2\n" + _rows()), "no header line", "line 1", "t,u,x")
    _expect(_write(tmp_path, _rows(), name="b.csv"), "no header line", "3 number(s)")


# ----------------------------------------------------------------------------- column names, dt, resampling


@pytest.mark.parametrize(
    "header",
    [
        "t_s,u_V,x_um",
        "Time,Voltage,Displacement",
        "TIME_S,V,POS",
        "t [s],u (V),x [µm]",
        "time (s),voltage_v,position_um",
        "T,U,X",
        "x/um,t/s,u/V",
    ],
)
def test_recognises_headers_with_units_in_any_case(tmp_path, header):
    names = header.split(",")
    order = [{"t": "t", "u": "u", "v": "u", "x": "x", "d": "x", "p": "x"}[h.strip().lower()[0]] for h in names]
    rows = "".join(",".join(str({"t": k * 0.01, "u": 2.0 * k, "x": -k}[o]) for o in order) + "\n" for k in range(5))
    rec = read_csv(_write(tmp_path, header + "\n" + rows))
    np.testing.assert_array_equal(rec.u, [0, 2, 4, 6, 8])
    np.testing.assert_array_equal(rec.x, [0, -1, -2, -3, -4])
    assert rec.dt == pytest.approx(0.01)
    assert rec.meta["read"] == {k: names[order.index(k)].strip() for k in "tux"}


@pytest.mark.parametrize(
    "header,words",
    [
        ("t_ms,u,x", ["'t_ms' is in ms", "time [s]", "--columns"]),
        ("t,u,x_nm", ["'x_nm' is in nm", "displacement [µm]"]),
        ("t,u_mV,x", ["'u_mV' is in mv", "voltage [V]"]),
        ("t,u,voltage,x", ["'u', 'voltage' all name the voltage [V]", "--columns T,U,X"]),
        ("time,t,u,x", ["'time', 't' all name the time [s]"]),
    ],
)
def test_unit_and_ambiguous_headers(tmp_path, header, words):
    width = header.count(",") + 1
    rows = "".join(",".join([str(k * 0.1)] * width) + "\n" for k in range(4))
    _expect(_write(tmp_path, header + "\n" + rows), "line 1", *words)


def test_columns_named(tmp_path):
    path = _write(tmp_path, "stamp,cmd,gap,other\n" + "".join(f"{k * 0.5},{k},{-k},9\n" for k in range(4)))
    _expect(path, "missing columns 'u', 'x'", "'stamp'")
    rec = read_csv(path, columns="stamp,CMD,gap")
    np.testing.assert_array_equal(rec.u, [0, 1, 2, 3])
    assert rec.dt == 0.5 and rec.meta["read"] == {"t": "stamp", "u": "cmd", "x": "gap"}
    rec = read_csv(path, columns=("cmd", "gap"), dt=0.25)
    np.testing.assert_array_equal(rec.t, [0, 0.25, 0.5, 0.75])
    assert rec.meta["read"]["t"] is None
    with pytest.raises(ValueError, match=r"column 'volts' named by columns \(--columns\) is not in the header"):
        read_csv(path, columns="stamp,volts,gap")
    with pytest.raises(ValueError, match="columns must name T,U,X"):
        read_csv(path, columns="stamp")


def test_record_without_time_takes_dt(tmp_path):
    path = _write(tmp_path, "u,x\n" + "".join(f"{k},{2 * k}\n" for k in range(5)))
    _expect(path, "no time column", "--dt DT", "dt=")
    rec = read_csv(path, dt=0.002)
    assert rec.dt == 0.002 and rec.t[-1] == pytest.approx(0.008) and len(rec) == 5
    with pytest.raises(ValueError, match="dt must be finite and > 0"):
        read_csv(path, dt=-1.0)
    timed = _write(tmp_path, "t,u,x\n" + _rows(), name="timed.csv")
    with pytest.raises(ValueError, match="has a time column 't'; dt"):
        read_csv(timed, dt=0.001)


def _jittered(tmp_path):
    t = [0.0, 0.1, 0.25, 0.3, 0.4, 0.52, 0.6]
    u = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    x = [0.0, 10.0, 25.0, 30.0, 40.0, 52.0, 60.0]
    return _write(tmp_path, "t,u,x\n" + "".join(f"{a},{b},{c}\n" for a, b, c in zip(t, u, x)))


def test_non_uniform_time_says_how_and_offers_resampling(tmp_path):
    msg = _expect(_jittered(tmp_path), "non-uniform", "from 0.05 s to 0.15 s", "mean step 0.1 s", "spread 100%")
    assert "--resample DT" in msg and "resample=DT" in msg and "line 4" in msg


def test_resample_holds_u_and_interpolates_x(tmp_path):
    rec = read_csv(_jittered(tmp_path), resample=0.05)
    np.testing.assert_allclose(rec.t, np.arange(13) * 0.05)
    # u: the last sample at or before each grid time; x: linear between samples (here x = 100 t).
    np.testing.assert_array_equal(rec.u, [0, 0, 1, 1, 1, 2, 3, 3, 4, 4, 4, 5, 6])
    np.testing.assert_allclose(rec.x, 100.0 * rec.t, atol=1e-9)
    assert rec.dt == 0.05
    info = rec.meta["resampled"]
    assert info["samples_before"] == 7 and info["samples"] == 13
    assert info["step_min_s"] == pytest.approx(0.05) and info["step_max_s"] == pytest.approx(0.15)
    assert info["step_spread"] == pytest.approx(1.0)
    for bad, words in ((0.0, "resample must be a step in s"), (0.5, "leaves 2 sample(s)")):
        with pytest.raises(ValueError) as err:
            read_csv(_jittered(tmp_path), resample=bad)
        assert words in str(err.value)
    decreasing = _write(tmp_path, "t,u,x\n0,1,2\n0.2,1,2\n0.1,1,2\n", name="dec.csv")
    msg = _expect(decreasing, "strictly increasing")
    assert "--resample" not in msg
    with pytest.raises(ValueError, match="strictly increasing"):
        read_csv(decreasing, resample=0.05)


def test_not_utf8(tmp_path):
    _expect(_write(tmp_path, b"t,u,x\n0,1,\xff\n", mode="wb"), "UTF-8")


# ----------------------------------------------------------------------------- writing


def test_write_csv_rejects_bad_input(tmp_path):
    path = tmp_path / "w.csv"
    with pytest.raises(ValueError, match="same length"):
        write_csv(path, {"t": [0, 1, 2], "u": [0, 1]})
    with pytest.raises(ValueError, match="column name"):
        write_csv(path, {"a,b": [0, 1]})
    with pytest.raises(ValueError, match="1-D"):
        write_csv(path, {"t": np.zeros((2, 2))})
    with pytest.raises(ValueError, match="at least one"):
        write_csv(path, {})
    with pytest.raises(TypeError, match="real numbers"):
        write_csv(path, {"t": ["a", "b"]})


# ----------------------------------------------------------------------------- arrays


def test_validate_samples_converts():
    u_in = np.arange(10, dtype=np.int32)
    x_in = np.linspace(0, 1, 20)[::2]
    u, x = validate_samples(u_in, x_in, 1e-3)
    assert u.dtype == np.float64 and x.dtype == np.float64
    assert u.flags.c_contiguous and x.flags.c_contiguous
    np.testing.assert_array_equal(u, u_in)
    np.testing.assert_array_equal(x, x_in)
    u2, _ = validate_samples([1.0, 2.0], (3, 4))
    np.testing.assert_array_equal(u2, [1.0, 2.0])


@pytest.mark.parametrize(
    "u,x,dt,exc,words",
    [
        (["a", "b"], [1, 2], None, TypeError, "u must hold real numbers"),
        ([1, 2], [1 + 1j, 2], None, TypeError, "x must hold real numbers"),
        ([True, False], [1, 2], None, TypeError, "u must hold real numbers"),
        (1.0, [1.0], None, ValueError, "u must be 1-D, got a scalar"),
        (np.zeros((2, 3)), np.zeros(6), None, ValueError, "shape (2, 3)"),
        ([], [], None, ValueError, "u is empty"),
        ([1, 2, 3], [1, 2], None, ValueError, "same length, got 3 and 2"),
        ([1, np.nan, 3], [1, 2, 3], None, ValueError, "u[1] is nan"),
        ([1, 2, 3], [1, 2, np.inf], None, ValueError, "x[2] is inf"),
        ([1, 2], [1, 2], 0.0, ValueError, "dt must be finite and > 0"),
        ([1, 2], [1, 2], -1e-3, ValueError, "dt must be finite and > 0"),
        ([1, 2], [1, 2], float("nan"), ValueError, "dt must be finite"),
        ([1, 2], [1, 2], "0.1", TypeError, "dt must be a real number"),
        ([1, 2], [1, 2], True, TypeError, "dt must be a real number"),
    ],
)
def test_validate_samples_rejects(u, x, dt, exc, words):
    with pytest.raises(exc) as info:
        validate_samples(u, x, dt)
    assert words in str(info.value)


def test_record_checks_lengths():
    with pytest.raises(ValueError, match="t has 2 samples"):
        Record(t=[0.0, 1.0], u=[1.0, 2.0, 3.0], x=[1.0, 2.0, 3.0], dt=1.0)


# ----------------------------------------------------------------------------- datasets


def _dataset(name):
    """The measured record, or a skip naming where it was looked for (on this machine and CI it is there)."""
    try:
        return datasets.load(name)
    except datasets.DataNotFoundError as exc:
        pytest.skip(f"measured data not on this machine: {exc}")


def test_dataset_names():
    assert datasets.names() == ["micromanipulator", "micromanipulator_compensated"]


def test_unknown_dataset_lists_names():
    with pytest.raises(ValueError, match="micromanipulator, micromanipulator_compensated"):
        datasets.load("piezo")


def test_package_ships_no_data():
    assert not [
        p.name
        for p in resources.files("boucwen.datasets").iterdir()
        if p.name != "__init__.py" and "cache" not in p.name
    ]


def test_missing_data_names_both_places(tmp_path, monkeypatch):
    monkeypatch.setenv("BOUCWEN_DATA", str(tmp_path / "data"))
    monkeypatch.setattr(datasets, "_shared_data_dir", lambda: tmp_path / "shared" / "data")
    with pytest.raises(datasets.DataNotFoundError) as info:
        datasets.load("micromanipulator")
    msg = str(info.value)
    assert "\n" not in msg and "Model_Vi_Do.dat" in msg
    assert "$BOUCWEN_DATA/yan9a-piezo-micromanipulator/" in msg and str(tmp_path / "data") in msg
    assert "../shared/data beside the repository" in msg and str(tmp_path / "shared" / "data") in msg
    assert not datasets.available("micromanipulator")
    monkeypatch.delenv("BOUCWEN_DATA")
    with pytest.raises(datasets.DataNotFoundError, match="BOUCWEN_DATA not set"):
        datasets.find("micromanipulator")


def test_data_directory_from_environment(tmp_path, monkeypatch):
    folder = tmp_path / datasets.FOLDER
    folder.mkdir()
    (folder / "Model_Vi_Do.dat").write_text("".join(f"{k * 0.1}\t0\t0\t0\t{-k}\t0\t0\n" for k in range(5)))
    (folder / "LICENSE").write_text("MIT License (test)")
    monkeypatch.setenv("BOUCWEN_DATA", str(tmp_path))
    rec = datasets.load("micromanipulator")
    assert len(rec) == 5 and rec.x[4] == -4.0 and rec.meta["licence_text"] == "MIT License (test)"
    assert rec.meta["file"] == str(folder / "Model_Vi_Do.dat")
    (folder / "Model_Vi_Do.dat").write_text("1 2 3\n4 5 6\n")
    with pytest.raises(ValueError, match=r"expected the 7 columns of Model_Vi_Do\.dat, found 3"):
        datasets.load("micromanipulator")


def test_shared_data_beside_the_repository(tmp_path, monkeypatch):
    repo = tmp_path / "repo" / "sub"
    repo.mkdir(parents=True)
    (tmp_path / "repo" / "pyproject.toml").write_text("")
    monkeypatch.chdir(repo)
    monkeypatch.delenv("BOUCWEN_DATA", raising=False)
    assert datasets.data_dirs()[1][1] == tmp_path / "shared" / "data"


def test_name_of_file():
    assert datasets.name_of_file("../shared/data/yan9a-piezo-micromanipulator/Test_Vi_Do_Di.dat") == (
        "micromanipulator_compensated"
    )
    assert datasets.name_of_file("loop.csv") is None


def test_micromanipulator():
    rec = _dataset("micromanipulator")
    assert len(rec) == 8027
    assert rec.dt == 0.005
    assert rec.t[0] == 0.0 and rec.t[-1] == pytest.approx(8026 * 0.005)
    assert rec.u.min() == pytest.approx(0.0, abs=1e-9)
    assert rec.u.max() == pytest.approx(3.6, abs=1e-6)
    assert -124 < rec.x.min() < -122 and -75 < rec.x.max() < -73  # µm
    assert rec.u[0] == pytest.approx(1.8) and rec.x[0] == pytest.approx(-123.059139)
    meta = rec.meta
    assert "MIT" in meta["licence"] and "MIT License" in meta["licence_text"]
    assert "Aye" in meta["citation"] and "2018" in meta["citation"]
    assert meta["units"]["x"].startswith("µm") and meta["units"]["u"].startswith("V")
    assert "DiscreteBacklashOperator" in meta["source"]


def test_micromanipulator_compensated():
    rec = _dataset("micromanipulator_compensated")
    assert len(rec) == 14155
    assert rec.dt == 0.005
    desired = rec.meta["desired"]
    assert desired.shape == (14155,)
    assert desired[1] == pytest.approx(0.628215)
    assert 19 < np.abs(desired).max() < 21  # µm
    assert rec.u[0] == pytest.approx(1.830003) and rec.x[0] == pytest.approx(-121.662284)
    assert rec.meta["units"]["desired"] == "µm"


# ----------------------------------------------------------------------------- files without a header line


@pytest.mark.parametrize("delimiter", [" ", ",", "\t"])
def test_headerless_file_read_by_position(tmp_path, delimiter):
    t = np.arange(6) * 0.01
    table = np.column_stack([np.zeros(6), t, -t * 10.0, t * 100.0])  # 0, time, x, u
    path = tmp_path / "log.txt"
    np.savetxt(path, table, delimiter=delimiter)
    rec = read_csv(path, columns="2,4,3")
    np.testing.assert_allclose(rec.t, t)
    np.testing.assert_allclose(rec.u, t * 100.0)
    np.testing.assert_allclose(rec.x, -t * 10.0)
    assert rec.dt == pytest.approx(0.01)
    assert rec.meta["read"] == {"t": "column 2", "u": "column 4", "x": "column 3"}
    rec = read_csv(path, columns=("4", "3"), dt=0.5)
    assert rec.dt == 0.5 and rec.meta["read"]["t"] is None


def test_headerless_file_without_columns_says_so(tmp_path):
    path = tmp_path / "log.txt"
    np.savetxt(path, np.ones((4, 3)))
    msg = _expect(path, "no header line", "--columns", "1-based position")
    assert "3 number(s)" in msg


@pytest.mark.parametrize(
    "columns, dt, words",
    [
        ("t,u,x", None, ["no header line", "1-based positions"]),
        ("1,2,9", None, ["position 9", "3 columns"]),
        ("0,1,2", None, ["position 0"]),
        ("1,1,2", None, ["one position twice"]),
        ("2,3", None, ["name no time column", "--dt"]),
    ],
)
def test_headerless_bad_positions(tmp_path, columns, dt, words):
    path = tmp_path / "log.txt"
    np.savetxt(path, np.column_stack([np.arange(4) * 0.1, np.ones(4), np.ones(4)]))
    with pytest.raises(ValueError) as info:
        read_csv(path, columns=columns, dt=dt)
    for word in words:
        assert word in str(info.value), (word, str(info.value))


def test_positions_on_a_file_with_a_header(tmp_path):
    path = _write(tmp_path, "stamp,cmd,gap\n" + "".join(f"{k * 0.5},{k},{-k}\n" for k in range(4)))
    rec = read_csv(path, columns="1,2,3")
    np.testing.assert_array_equal(rec.x, [0, -1, -2, -3])
    assert rec.meta["read"] == {"t": "stamp", "u": "cmd", "x": "gap"}


def test_read_signal_takes_one_quantity(tmp_path):
    from boucwen.io import read_signal

    path = _write(tmp_path, "t_s,x_um,other\n" + "".join(f"{k * 0.1},{k * 2.0},7\n" for k in range(5)))
    t, x, dt, meta = read_signal(path, "x")
    np.testing.assert_allclose(t, np.arange(5) * 0.1)
    np.testing.assert_array_equal(x, [0, 2, 4, 6, 8])
    assert dt == pytest.approx(0.1) and meta["read"] == {"t": "t_s", "x": "x_um"}
    with pytest.raises(ValueError, match="missing column 'u'"):
        read_signal(path, "u")
