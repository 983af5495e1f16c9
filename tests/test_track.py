"""The closed-loop tracking experiment (boucwen track): a quick run and its parts."""

import json

import numpy as np
import pytest

from boucwen import plant
from boucwen.cli import main
from boucwen.experiments import track


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("track")
    code = main(["track", "--out", str(out), "--quick", "--plants", "1", "--no-figures"])
    assert code == 0
    with open(out / "results.json", encoding="utf-8") as fh:
        return json.load(fh)


@pytest.mark.slow  # the tracking experiment (a module fixture)
def test_required_targets_hold(quick_run):
    required = [t for t in quick_run["targets"] if t["required"]]
    # >= 10x and >= 5x, beats the fixed inverse at 10/50/100/200 Hz, <= 1 % at 1-100 Hz
    # (vibration off); PI + adaptive <= 0.5 % at 1 and 10 Hz (vibration on).
    assert len(required) == 2 + 4 + 4 + 2
    missed = [f"{t['bench']}: {t['target']} ({t['detail']})" for t in required if not t["met"]]
    assert not missed, missed


@pytest.mark.slow  # the tracking experiment (a module fixture)
def test_results_hold_every_method_reference_and_bench(quick_run):
    refs = track.references(quick=True)
    for bench in track.BENCHES:
        table = quick_run["benches"][bench]["table"]
        assert set(table) == {r.name for r in refs}
        for ref in refs:
            assert set(table[ref.name]) == {m.name for m in track.METHODS}
            for v in table[ref.name].values():
                assert 0 <= v["rms_um"] <= v["max_um"] < 50
                assert v["max_pct"] == pytest.approx(100 * v["max_um"] / np.ptp(ref.x_d), rel=1e-9)
                assert track.U_LIMITS_V[0] <= v["u_range_v"][0] <= v["u_range_v"][1] <= track.U_LIMITS_V[1]
    plants = quick_run["generated_plants"]
    assert len(plants["plants"]) == 1
    for s in plants["summary"].values():
        assert s["median_max_um"] <= s["worst_max_um"]


def test_references_span_the_range_and_start_at_rest():
    for ref in track.references(quick=False):
        assert np.ptp(ref.x_d) == pytest.approx(track.RANGE_UM, rel=1e-9)
        assert ref.x_d.min() == pytest.approx(0.0, abs=1e-9)
        assert 0 < ref.adaptation < ref.x_d.size
    stairs = next(r for r in track.references() if r.name == "staircase")
    hold = stairs.adaptation
    for i, level in enumerate(track.STAIRCASE_LEVELS_UM):
        np.testing.assert_array_equal(stairs.x_d[i * hold + 50 : (i + 1) * hold], level)
    assert stairs.x_d[0] == 0.0
    rnd = next(r for r in track.references() if r.name == "random")
    # Zero-phase 4th-order Butterworth at 100 Hz: |H| = 1/(1 + (f/100 Hz)^8) = 1.5e-4 at 300 Hz.
    spectrum = np.abs(np.fft.rfft((rnd.x_d - rnd.x_d.mean()) * np.hanning(rnd.x_d.size)))
    f = np.fft.rfftfreq(rnd.x_d.size, 1e-4)
    assert spectrum[f > 300].max() < 1e-3 * spectrum.max()


def test_metrics_leave_out_the_adaptation_period():
    x_d = np.linspace(0.0, 20.0, 100)
    x = x_d.copy()
    x[:10] += 5.0
    x[50] += 0.2
    m = track.tracking_metrics(x, x_d, 10)
    assert m["max_um"] == pytest.approx(0.2)
    assert m["max_pct"] == pytest.approx(1.0)
    assert m["rms_um"] == pytest.approx(0.2 / np.sqrt(90))


def test_generated_plants_keep_h_bounded_and_stay_in_their_ranges():
    rng = np.random.default_rng(3)
    base = plant.BenchSettings()
    for _ in range(50):
        s = track.generated_plant(rng)
        assert s.beta + s.gamma > 0 and s.beta - s.gamma > 0
        assert 0.8 * base.kv <= s.kv <= 1.2 * base.kv
        assert 300 <= s.amplifier_fc_hz <= 1000
        assert 0.1 <= sum(s.vibration_um) <= 0.3
        assert 0.001 <= s.noise_um <= 0.010


def test_bad_arguments_exit_with_code_2(tmp_path, capsys):
    assert main(["track", "--out", str(tmp_path), "--plants", "-1", "--quick", "--no-figures"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("boucwen track: error:")
