"""A generated piezo deformable mirror: a grid of actuators, each tested on the simulated bench.

``python -m boucwen.fleet.generate --out DIR`` writes a 32 × 32 mirror (1 024 records)::

    DIR/records/rRRcCC.csv   one record per actuator: t [s], u [V], x [µm] at 1 kHz
    DIR/layout.csv           channel,row,col (for the maps of `boucwen batch --layout`)
    DIR/truth.csv            each actuator's true settings and defect ("" when sound)

and ``python -m boucwen.fleet.generate --out DIR --compare RES`` compares the outliers
that ``boucwen batch fit DIR/records --layout DIR/layout.csv --out RES`` flagged with the
truth. ``--rows``, ``--cols`` and ``--repeats`` make a smaller mirror and shorter
records (the tests use 4 × 4 and one repeat).

**Actuators.** Each record is :func:`boucwen.plant.measure` of one actuator: the bench
of :data:`NOMINAL` (the paper's 1 Hz parameters, a 650 Hz amplifier, creep,
electrostriction; a quiet test stand with 0.02 µm of floor vibration) with its values
spread around the nominal. Each spread is a smooth random field over the mirror (white
noise through a Gaussian filter of :data:`CORRELATION_LENGTH` actuator pitches, the
way a ceramic lot or a bonding layer varies across a plate) plus a share
:data:`INDIVIDUAL_SHARE` of independent per-actuator variation, scaled to a relative
standard deviation :data:`SPREAD`. β and γ share one field so that β ± γ keep their
signs (h stays bounded).

**Defects** (:data:`DEFECTS`, placed at random cells): ``creep``: the creep gains
:data:`CREEP_FACTOR` times the nominal (a depoled or badly bonded stack); ``clipping``:
the displacement saturates at :data:`CLIP_UM` (a mechanical stop or a sensor at the end
of its range); ``dead``: the stack does not move (open connection), the sensor reads
the offset, vibration and noise.

**Test signal.** Every actuator gets the same voltage, as on a production line:
:func:`boucwen.experiments.undeclared.test_input` (steps and holds, a full-range sweep,
minor loops, bursts at 5–60 Hz within 0–100 V) with ``repeats`` copies of its pattern,
sampled at 1 kHz (about 2.4 s per repeat).
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter

from ..experiments.undeclared import test_input
from ..io import write_csv
from ..plant import BenchSettings, measure

__all__ = [
    "CLIP_UM",
    "CORRELATION_LENGTH",
    "CREEP_FACTOR",
    "DEFECTS",
    "DT",
    "INDIVIDUAL_SHARE",
    "NOMINAL",
    "SPREAD",
    "Actuator",
    "compare",
    "main",
    "make_mirror",
    "write_fleet",
]

#: Sampling interval of the records [s] (1 kHz).
DT = 1e-3
#: Seed of the test voltage (the same for every actuator).
INPUT_SEED = 7
#: The nominal actuator and test stand.
NOMINAL = BenchSettings(vibration_um=(0.02, 0.015))
#: Relative standard deviation of each spread value across the mirror.
SPREAD: dict[str, float] = {
    "kv": 0.04,
    "A": 0.05,
    "hysteresis": 0.08,  # β and γ together
    "n": 0.02,
    "delta": 0.08,
    "amplifier_fc_hz": 0.08,
    "creep": 0.10,
    "x0": 0.5,
}
#: Correlation length of the spread (σ of the Gaussian filter) [actuator pitches].
CORRELATION_LENGTH = 6.0
#: Share of each spread's variance that is independent from actuator to actuator.
INDIVIDUAL_SHARE = 0.2
#: Defects of the default mirror: {kind: count}.
DEFECTS: dict[str, int] = {"creep": 2, "clipping": 2, "dead": 1}
#: Creep gains of a ``creep`` defect, relative to the nominal.
CREEP_FACTOR = 8.0
#: Saturation of a ``clipping`` defect [µm] (the sound stroke reaches about 19 µm).
CLIP_UM = 12.0
#: Defect kinds.
DEFECT_KINDS = ("creep", "clipping", "dead")


@dataclass(frozen=True)
class Actuator:
    """One actuator of the mirror: name, grid position, bench settings, defect ("" if sound)."""

    channel: str
    row: int
    col: int
    settings: BenchSettings
    defect: str
    seed: int


def _field(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Unit-variance spread over the grid: smooth field plus an independent share."""
    # White noise on a canvas wider than the mirror by 4σ on each side, filtered and cut
    # back: every actuator, edge or centre, sees the same stationary process. Filtered
    # unit white noise has the standard deviation 1/(2·√π·σ) (the root of the sum of the
    # kernel's squared weights); dividing by it, not by the grid's own spread, keeps a
    # small mirror a sample of the same process as a large one.
    pad = math.ceil(4.0 * CORRELATION_LENGTH)
    canvas = rng.standard_normal((shape[0] + 2 * pad, shape[1] + 2 * pad))
    smooth = np.asarray(gaussian_filter(canvas, CORRELATION_LENGTH, mode="constant"), dtype=np.float64)[
        pad:-pad, pad:-pad
    ]
    smooth *= 2.0 * math.sqrt(math.pi) * CORRELATION_LENGTH
    white = rng.standard_normal(shape)
    return math.sqrt(1.0 - INDIVIDUAL_SHARE) * smooth + math.sqrt(INDIVIDUAL_SHARE) * white


def _defective(settings: BenchSettings, defect: str) -> BenchSettings:
    if defect == "creep":
        return replace(settings, creep_gain_um_per_v=tuple(CREEP_FACTOR * g for g in settings.creep_gain_um_per_v))
    if defect == "clipping":
        return replace(settings, range_um=CLIP_UM)
    if defect == "dead":
        return replace(
            settings,
            kv=0.0,
            A=0.0,
            beta=0.0,
            gamma=0.0,
            delta=0.0,
            creep_gain_um_per_v=tuple(0.0 for _ in settings.creep_gain_um_per_v),
            stroke_quadratic_per_um=0.0,
        )
    raise ValueError(f"unknown defect {defect!r}; expected one of {', '.join(DEFECT_KINDS)}")


def make_mirror(rows: int = 32, cols: int = 32, seed: int = 0, defects: dict[str, int] | None = None) -> list[Actuator]:
    """The actuators of a ``rows`` × ``cols`` mirror (module docs), row by row.

    Raises:
        ValueError: a size below 1, an unknown defect, or more defects than actuators.
    """
    for name, value in (("rows", rows), ("cols", cols)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    defects = dict(DEFECTS if defects is None else defects)
    for kind, count in defects.items():
        if kind not in DEFECT_KINDS:
            raise ValueError(f"unknown defect {kind!r}; expected one of {', '.join(DEFECT_KINDS)}")
        if isinstance(count, bool) or not isinstance(count, int) or count < 0:
            raise ValueError(f"defect count of {kind!r} must be an integer >= 0, got {count!r}")
    total = sum(defects.values())
    if total > rows * cols:
        raise ValueError(f"{total} defects do not fit on {rows} × {cols} actuators")
    rng = np.random.default_rng(seed)
    shape = (rows, cols)
    fields = {name: _field(rng, shape) for name in SPREAD}
    cells = rng.choice(rows * cols, size=total, replace=False)
    defect_at = {int(cell): kind for cell, kind in zip(cells, (k for k, c in defects.items() for _ in range(c)))}
    n0 = NOMINAL
    actuators = []
    for r in range(rows):
        for c in range(cols):

            def scaled(name: str, value: float, r: int = r, c: int = c) -> float:
                return value * (1.0 + SPREAD[name] * float(fields[name][r, c]))

            hyst = 1.0 + SPREAD["hysteresis"] * float(fields["hysteresis"][r, c])
            creep = 1.0 + SPREAD["creep"] * float(fields["creep"][r, c])
            settings = replace(
                n0,
                kv=scaled("kv", n0.kv),
                x0=scaled("x0", n0.x0),
                A=scaled("A", n0.A),
                beta=n0.beta * hyst,
                gamma=n0.gamma * hyst,
                n=scaled("n", n0.n),
                delta=scaled("delta", n0.delta),
                amplifier_fc_hz=scaled("amplifier_fc_hz", n0.amplifier_fc_hz),
                creep_gain_um_per_v=tuple(g * creep for g in n0.creep_gain_um_per_v),
                vibration_phase_rad=tuple(float(p) for p in rng.uniform(0.0, 2.0 * math.pi, len(n0.vibration_hz))),
            )
            defect = defect_at.get(r * cols + c, "")
            if defect:
                settings = _defective(settings, defect)
            actuators.append(Actuator(f"r{r:02d}c{c:02d}", r, c, settings, defect, seed=seed * 100_003 + r * cols + c))
    return actuators


def _write_rows(path: Path, header: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
    with open(path, "w", encoding="utf-8", newline="") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(header)
        writer.writerows(rows)


TRUTH_COLUMNS = (
    "channel",
    "row",
    "col",
    "defect",
    "kv",
    "x0",
    "A",
    "beta",
    "gamma",
    "n",
    "delta",
    "amplifier_fc_hz",
    "creep_total_um_per_v",
    "range_um",
)


def write_fleet(
    out: str | os.PathLike[str],
    rows: int = 32,
    cols: int = 32,
    seed: int = 0,
    repeats: int = 2,
    defects: dict[str, int] | None = None,
    table: bool = False,
    progress: bool = False,
) -> list[Actuator]:
    """Simulates the mirror and writes it to ``out`` (module docs).

    Args:
        out: folder to create or fill.
        rows, cols: grid size.
        seed: seed of the spread, the defect cells and the noise.
        repeats: copies of the test pattern per record (record length ≈ 2.4 s each).
        defects: ``{kind: count}``; default :data:`DEFECTS`.
        table: instead of ``records/``, write one long table ``table.parquet`` with the
            columns channel, row, col, t, u, x (needs pandas and pyarrow).
        progress: print a line every 64 actuators to stderr.

    Returns:
        The actuators written.
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise ValueError(f"repeats must be an integer >= 1, got {repeats!r}")
    actuators = make_mirror(rows, cols, seed, defects)
    root = Path(out)
    records = root / "records"
    (root if table else records).mkdir(parents=True, exist_ok=True)
    u = test_input(DT, seed=INPUT_SEED, repeats=repeats)
    t = np.arange(u.size) * DT
    long_parts = []
    started = time.perf_counter()
    for k, act in enumerate(actuators):
        rec = measure(u, DT, act.settings, seed=act.seed)
        if table:
            long_parts.append((act, rec.u, rec.x))
        else:
            write_csv(records / f"{act.channel}.csv", {"t": t, "u": rec.u, "x": rec.x})
        if progress and ((k + 1) % 64 == 0 or k + 1 == len(actuators)):
            print(
                f"generate: {k + 1}/{len(actuators)} actuators, {time.perf_counter() - started:.0f} s", file=sys.stderr
            )
    if table:
        import pandas as pd

        frame = pd.concat(
            [
                pd.DataFrame({"channel": act.channel, "row": act.row, "col": act.col, "t": t, "u": ur, "x": xr})
                for act, ur, xr in long_parts
            ],
            ignore_index=True,
        )
        frame.to_parquet(root / "table.parquet", index=False)
    _write_rows(root / "layout.csv", ("channel", "row", "col"), [(a.channel, a.row, a.col) for a in actuators])
    truth = []
    for a in actuators:
        s = a.settings
        truth.append(
            (
                a.channel,
                a.row,
                a.col,
                a.defect,
                *(f"{getattr(s, name):.9g}" for name in ("kv", "x0", "A", "beta", "gamma", "n", "delta")),
                f"{s.amplifier_fc_hz:.9g}",
                f"{sum(s.creep_gain_um_per_v):.9g}",
                f"{s.range_um:.9g}",
            )
        )
    _write_rows(root / "truth.csv", TRUTH_COLUMNS, truth)
    return actuators


def compare(results: Any, truth: Any) -> dict[str, Any]:
    """What the fleet run flagged against the truth.

    Args:
        results: the table of a run (DataFrame with ``channel``, ``status``, ``outlier``,
            ``outlier_reason``) or the path of its ``results.parquet``.
        truth: DataFrame with ``channel`` and ``defect`` or the path of ``truth.csv``.

    Returns:
        ``{"defects": [{channel, defect, flagged, reason}], "found": n, "missed": [...],
        "false_positives": [{channel, reason}], "records": n}``; an error row of a
        defective channel counts as found (it is listed for a look), one of a sound
        channel as a false positive.
    """
    import pandas as pd

    res = results if isinstance(results, pd.DataFrame) else pd.read_parquet(results)
    tru = truth if isinstance(truth, pd.DataFrame) else pd.read_csv(truth, keep_default_na=False)
    merged = res.merge(tru[["channel", "defect"]], on="channel", how="inner")
    merged["defect"] = merged["defect"].fillna("").astype(str)
    broken = ~merged["status"].isin(("ok", "not_converged"))
    flagged = merged["outlier"].astype(bool) | broken
    reason = [
        str(r.outlier_reason) if bool(r.outlier) else f"{r.status}: {r.error}" if b else ""
        for r, b in zip(merged.itertuples(index=False), broken)
    ]
    merged["flagged"], merged["reason"] = flagged, reason
    bad = merged[merged["defect"] != ""]
    sound = merged[(merged["defect"] == "") & merged["flagged"]]
    return {
        "records": len(merged),
        "defects": [
            {"channel": r.channel, "defect": r.defect, "flagged": bool(r.flagged), "reason": r.reason}
            for r in bad.itertuples(index=False)
        ],
        "found": int(bad["flagged"].sum()),
        "missed": [str(c) for c in bad.loc[~bad["flagged"], "channel"]],
        "false_positives": [{"channel": r.channel, "reason": r.reason} for r in sound.itertuples(index=False)],
    }


def _parse_defects(text: str) -> dict[str, int]:
    out: dict[str, int] = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        kind, _, count = part.partition("=")
        try:
            out[kind.strip()] = int(count) if count else 1
        except ValueError:
            raise ValueError(f"--defects: {part!r} is not KIND=COUNT") from None
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m boucwen.fleet.generate``; returns the exit code (2 with one line on stderr on error)."""
    parser = argparse.ArgumentParser(
        prog="python -m boucwen.fleet.generate",
        description="Writes a generated piezo mirror (records, layout, truth), or compares a run's outliers with it.",
    )
    parser.add_argument("--out", required=True, metavar="DIR", help="the mirror's folder")
    parser.add_argument("--rows", type=int, default=32, help="grid rows (default 32)")
    parser.add_argument("--cols", type=int, default=32, help="grid columns (default 32)")
    parser.add_argument(
        "--repeats", type=int, default=2, help="test-pattern copies per record, ≈2.4 s each (default 2)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    parser.add_argument(
        "--defects",
        default=",".join(f"{k}={v}" for k, v in DEFECTS.items()),
        help="KIND=COUNT,... among creep, clipping, dead (default %(default)s)",
    )
    parser.add_argument("--table", action="store_true", help="write one long table.parquet instead of records/")
    parser.add_argument("--compare", metavar="RES", help="instead: compare RES/results.parquet with DIR/truth.csv")
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    try:
        if args.compare:
            report = compare(Path(args.compare) / "results.parquet", Path(args.out) / "truth.csv")
            print(f"{report['records']} records; defective channels found: {report['found']}/{len(report['defects'])}")
            for d in report["defects"]:
                print(f"  {d['channel']} {d['defect']:9s} {'FOUND' if d['flagged'] else 'missed'}  {d['reason']}")
            print(f"sound channels flagged (false positives): {len(report['false_positives'])}")
            for fp in report["false_positives"]:
                print(f"  {fp['channel']}  {fp['reason']}")
            return 0
        started = time.perf_counter()
        acts = write_fleet(
            args.out, args.rows, args.cols, args.seed, args.repeats, _parse_defects(args.defects), args.table, True
        )
        where = Path(args.out) / ("table.parquet" if args.table else "records")
        print(f"wrote {len(acts)} actuators to {where} in {time.perf_counter() - started:.1f} s")
        for a in acts:
            if a.defect:
                print(f"  defect {a.defect:9s} at {a.channel}")
        return 0
    except (ValueError, OSError) as exc:
        print(f"generate: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
