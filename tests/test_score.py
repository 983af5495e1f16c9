"""The score screen of the diagnosis (boucwen.diagnosis.score): its supremum test holds its
level on dependent noise, finds a direction of the grid, and the search fits only the
moves whose score passes."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.signal import lfilter

from boucwen.diagnosis.judge import Gain, judge
from boucwen.diagnosis.report import finite_document
from boucwen.diagnosis.score import GAIN_SHARE, SCREEN_FACTOR, Scorer, sup_test
from boucwen.effects import candidate_starts
from boucwen.experiments.suite_records import make_suite_record
from boucwen.fit import fit_record
from boucwen.record import validate_record

N = 4000


def _grid(rng: np.random.Generator, points: int = 12) -> tuple[np.ndarray, list[np.ndarray]]:
    """A current model's span (3 columns) and a grid of one-column directions off it: a
    random input low-passed at corners from slow to fast (neighbours correlated, as a
    lag's corners are)."""
    u = np.cumsum(rng.standard_normal(N))
    u -= u.mean()
    base, _ = np.linalg.qr(np.column_stack([np.ones(N), u, np.linspace(-1, 1, N)]))
    grid = []
    for a in np.geomspace(0.5, 0.995, points):
        d = lfilter([1 - a], [1, -a], u) - u
        d -= base @ (base.T @ d)
        grid.append((d / np.linalg.norm(d))[:, None])
    return base, grid


def _ar1(rng: np.random.Generator, phi: float = 0.8) -> np.ndarray:
    return np.asarray(lfilter([1.0], [1.0, -phi], rng.standard_normal(N)))


def test_supremum_holds_its_level_on_dependent_noise() -> None:
    """Under the null (the residual is AR(1) noise, no direction of the grid in it), the
    supremum's p-value falls below 0.05 in at most about 5 % of records."""
    rng = np.random.default_rng(1)
    _, grid = _grid(rng)
    ps = [sup_test(_ar1(rng), grid, draws=499)[1] for _ in range(200)]
    rate = float(np.mean(np.asarray(ps) <= 0.05))
    # 0.05 with 2.5 binomial standard errors of 200 draws above it.
    assert rate <= 0.05 + 2.5 * math.sqrt(0.05 * 0.95 / 200), rate
    assert rate >= 0.005, rate


def test_supremum_finds_a_direction_of_the_grid() -> None:
    """A residual holding one grid point's direction (a quarter of the noise's RMS per
    sample over the record) is found: in white noise at that grid point or a
    neighbour, in AR(1) noise wherever its coloured noise weighs it most."""
    rng = np.random.default_rng(2)
    _, grid = _grid(rng)
    found = located = 0
    for _ in range(20):
        for phi in (0.0, 0.8):
            noise = _ar1(rng, phi)
            r = noise + 0.25 * np.std(noise) * math.sqrt(N) * grid[7][:, 0]
            lm, p, _ = sup_test(r, grid, draws=499)
            found += p <= 0.01
            located += phi == 0.0 and int(np.argmax(lm)) in (6, 7, 8)
    assert found >= 38
    assert located >= 18


@pytest.fixture(scope="module")
def creep_record() -> tuple:
    rec = make_suite_record((("creep", 0.1),), "multisine", 3, fs_hz=5_000.0, duration_s=1.0)
    record = validate_record(rec.u, rec.x, rec.dt)
    base = fit_record(record, seed=0, workers=1)
    return record, base


def _scorer(record, base) -> Scorer:  # type: ignore[no-untyped-def]
    from boucwen._core import EffectSet
    from boucwen.effects import Layout

    layout = Layout.for_record(EffectSet(), record)
    out = layout.simulate_with_jacobian(layout.pack(base.params, EffectSet(), base.h0), record.u, record.dt)
    assert out is not None
    return Scorer(record, out[0], out[1], base.params, base.h0)


def test_creep_left_by_the_base_model_passes_and_a_clip_above_every_sample_does_not(creep_record) -> None:  # type: ignore[no-untyped-def]
    from boucwen._core import EffectSet

    record, base = creep_record
    scorer = _scorer(record, base)
    needed = 0.1 * max(scorer.mse - 0.005**2, 0.0)
    starts = candidate_starts("creep", record, base.params, EffectSet(), base.h0)
    score, ranked = scorer.score(starts, ("creep",), 0.002, needed)
    assert score.passed, score.reason
    assert score.p_value <= SCREEN_FACTOR * 0.002
    assert score.gain_um2 >= GAIN_SHARE * needed
    assert len(ranked) == score.grid
    clip = candidate_starts("pickup", record, base.params, EffectSet(), base.h0)
    other, _ = scorer.score(clip, ("pickup",), 0.002, needed)
    assert not other.passed
    assert "not fitted" in other.reason


def test_a_non_finite_statistic_is_never_a_decision() -> None:
    for mean, se, stat in ((math.nan, math.nan, math.nan), (0.0, 0.0, math.inf), (1.0, 0.0, math.inf)):
        g = Gain(mean, se, stat, 1, 10, 100, (mean,), 1.0)
        d = judge("add", ("creep",), ("creep",), (), g, level_=0.01, noise_um=0.0, min_share=0.1, unknowns=1)
        assert not d.accepted
        assert d.reason


def test_the_report_is_finite_or_says_why() -> None:
    doc = {"decisions": [{"t": np.float64(np.inf), "gain_um2": math.nan, "n": np.int64(3)}], "rms_um": 0.1}
    out = finite_document(doc)
    text = json.dumps(out, allow_nan=False)
    assert json.loads(text)["decisions"][0]["t"] is None
    paths = {e["path"]: e for e in out["non_finite"]}
    assert set(paths) == {"decisions[0].t", "decisions[0].gain_um2"}
    assert all(e["why"] for e in out["non_finite"])
    assert paths["decisions[0].t"]["value"] == "inf"


@pytest.mark.slow
def test_the_report_of_a_record_with_sensor_dropouts_is_written(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Three 50 ms dropouts of the sensor (it reads 0) in a 10 kHz record: the shell's
    diagnosis writes its JSON report and predictions, every figure finite or null with
    its reason."""
    from boucwen.cli import main
    from boucwen.io import write_csv

    rec = make_suite_record((), "multisine", 5, fs_hz=10_000.0, duration_s=0.6)
    x = rec.x.copy()
    for start in (0.1, 0.3, 0.45):
        k = round(start / rec.dt)
        x[k : k + round(0.05 / rec.dt)] = 0.0
    path = tmp_path / "dropouts.csv"
    write_csv(path, {"t_s": np.arange(x.size) * rec.dt, "u_V": rec.u, "x_um": x})
    report, predictions = tmp_path / "report.json", tmp_path / "predictions.csv"
    assert main(["diagnose", str(path), "--json", str(report), "--predictions", str(predictions)]) == 0
    doc = json.loads(report.read_text(encoding="utf-8"))
    assert isinstance(doc["non_finite"], list)
    assert all(e["why"] and e["path"] for e in doc["non_finite"])
    assert predictions.stat().st_size > 0
