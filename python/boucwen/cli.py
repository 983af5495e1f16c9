"""Command line: ``boucwen <subcommand> ...``.

Subcommands:

* ``boucwen fit DATA.csv [--json OUT.json]``: the traditional offline fit of a
  record (CSV with a header line naming the time, voltage and displacement in s, V, µm:
  ``t_s,u_V,x_um``, ``time,voltage,displacement``, … any case, see
  :func:`boucwen.io.read_csv`; other columns ignored); prints the parameters and the
  output error in µm. Record options (``fit`` and ``diagnose``): ``--columns T,U,X``
  names the columns (``U,X`` without time), ``--dt DT`` gives the sampling interval of a
  record without time, ``--resample DT`` puts non-uniform time stamps on a uniform grid.
  A file of :mod:`boucwen.datasets` (e.g. ``Model_Vi_Do.dat``) is read as that record.
* ``boucwen reproduce [--out DIR] [--quick]``: the paper's experiment on the
  simulated bench (:mod:`boucwen.experiments.reproduce`).
* ``boucwen diagnose (DATA.csv | --dataset NAME) [--json REPORT.json] [--predictions PRED.csv]
  [--plot FIG.png]``: which effects the base model misses (:mod:`boucwen.diagnosis`);
  prints the report, writes the files asked for.
* ``boucwen batch fit|diagnose SOURCE --out DIR [--scheduler ADDRESS] [--workers N]
  [--layout CSV]``: a fleet of records on Dask (:mod:`boucwen.batch`; exit code 1 when a
  record ended as an error or did not converge; needs ``pip install boucwen[fleet]``).
* ``boucwen track [--out DIR] [--quick] [--plants N]``: closed-loop tracking with
  hysteresis compensation on the simulated bench (:mod:`boucwen.experiments.track`).

Exit codes: 0 success; 1 ``fit`` finished without converging (the result is still
printed and written), or a ``batch`` record did; 2 error (a missing optional
dependency included). Every error (bad file, bad data, unwritable output)
ends the program with exit code 2 and a single line ``boucwen <subcommand>: error: <message>`` on stderr.

Adding a subcommand: write ``_add_<name>(subparsers)`` that creates its parser and
sets ``handler=`` to a function ``(args) -> int``, and append it to
:data:`SUBCOMMANDS`.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Callable, NoReturn

__all__ = ["SUBCOMMANDS", "build_parser", "main"]

EXIT_OK = 0
EXIT_ERROR = 2
#: ``boucwen fit`` ran but the optimiser stopped before convergence (result still printed).
EXIT_NOT_CONVERGED = 1


class _UsageError(Exception):
    """Raised by the parser instead of printing usage and calling sys.exit."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise _UsageError(f"{self.prog}: error: {message}")


if TYPE_CHECKING:
    from .record import Record

    # What ``add_subparsers`` returns; each subcommand adds its parser to it.
    _Subparsers = argparse._SubParsersAction[_Parser]


# --------------------------------------------------------------------------- records

_DATA_HELP = (
    "CSV file with a header line naming the time [s], voltage [V] and displacement [um] "
    "(t_s,u_V,x_um; time,voltage,displacement; ... any case), or a file of boucwen.datasets"
)


def _add_record_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--columns",
        metavar="T,U,X",
        default=None,
        help="names of the time, voltage and displacement columns (U,X for a record without time); "
        "default: recognised from the header",
    )
    p.add_argument(
        "--dt", type=float, metavar="DT", default=None, help="sampling interval [s] of a record without time"
    )
    p.add_argument(
        "--resample",
        type=float,
        metavar="DT",
        default=None,
        help="put non-uniform time stamps on a uniform grid of step DT [s] (u held, x interpolated linearly)",
    )


def _read_record(args: argparse.Namespace, path: str | None = None) -> Record:
    """The record of ``path`` (default ``args.data``): a file of :mod:`boucwen.datasets`
    by its name, else a CSV file read with the record options of ``args``."""
    from . import datasets
    from .io import read_csv

    path = args.data if path is None else path
    name = datasets.name_of_file(path)
    if name is not None and args.columns is None and args.dt is None and args.resample is None:
        rec = datasets.load(name, path)
        print(f"{path}: the measured record {name!r} of boucwen.datasets (u = column 1 [V], x = column 5 [um])")
        return rec
    rec = read_csv(path, columns=args.columns, dt=args.dt, resample=args.resample)
    read = rec.meta["read"]
    if read != {"t": "t", "u": "u", "x": "x"}:
        t_col = f"t = {read['t']!r} [s]" if read["t"] is not None else f"no time column, dt = {rec.dt:.6g} s"
        print(f"{path}: {t_col}, u = {read['u']!r} [V], x = {read['x']!r} [um]")
    info = rec.meta.get("resampled")
    if info is not None:
        print(
            f"resampled to dt = {info['dt_s']:.6g} s ({info['samples_before']} -> {info['samples']} samples): "
            f"the steps ran from {info['step_min_s']:.6g} to {info['step_max_s']:.6g} s, "
            f"spread {100.0 * info['step_spread']:.3g}% of their mean {info['step_mean_s']:.6g} s"
        )
    return rec


def _source(args: argparse.Namespace, rec: Record) -> dict[str, Any]:
    """Where a record came from, for the JSON files."""
    doc: dict[str, Any] = {"path": str(args.data)}
    for key in ("read", "resampled"):
        if key in rec.meta:
            doc[key] = rec.meta[key]
    return doc


# --------------------------------------------------------------------------- fit


def _cmd_fit(args: argparse.Namespace) -> int:
    from .fit import fit

    _prepare_output(args.json)
    rec = _read_record(args)
    result = fit(rec.u, rec.x, rec.dt, n_starts=args.starts, seed=args.seed, progress=args.progress)
    p = result.params
    print(f"{rec.name}: {len(rec)} samples, dt = {rec.dt:.6g} s")
    print(f"  kv    = {p.kv:.6g} µm/V")
    print(f"  x0    = {p.x0:.6g} µm")
    print(f"  A     = {p.A:.6g} µm/V")
    print(f"  beta  = {p.beta:.6g} µm^(1-n)/V")
    print(f"  gamma = {p.gamma:.6g} µm^(1-n)/V")
    print(f"  n     = {p.n:.6g}")
    print(f"  delta = {p.delta:.6g} µm/(V·s)")
    print(f"  h0    = {result.h0:.6g} µm")
    print(f"output error: rms {result.rms_um:.4g} µm, max {result.max_um:.4g} µm")
    print(
        f"{'converged' if result.success else 'NOT converged'}: {result.message} "
        f"({result.nfev} simulations, {result.elapsed_s:.2f} s)"
    )
    if args.json:
        doc = result.to_dict()
        doc["data"] = {**_source(args, rec), "samples": len(rec), "dt_s": rec.dt}
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(doc, fh, indent=2)
        print(f"wrote {args.json}")
    return EXIT_OK if result.success else EXIT_NOT_CONVERGED


def _add_fit(sub: _Subparsers) -> None:
    p = sub.add_parser(
        "fit",
        help="offline output-error fit of a CSV record (t, u, x)",
        description="Identifies the seven parameters and h0 of the asymmetric "
        "Bouc-Wen model from a CSV record with columns t [s], u [V], "
        "x [um] by output-error least squares.",
    )
    p.add_argument("data", help=_DATA_HELP)
    _add_record_options(p)
    p.add_argument("--json", metavar="OUT.json", help="also write the result as JSON")
    p.add_argument("--starts", type=int, default=4, help="local starts (default 4)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random starts (default 0)")
    p.add_argument("--progress", action="store_true", help="print progress to stderr")
    p.set_defaults(handler=_cmd_fit)


# --------------------------------------------------------------------------- reproduce


def _cmd_reproduce(args: argparse.Namespace) -> int:
    from .experiments.reproduce import run
    from .pacing import refine_modes

    run(
        args.out,
        quick=args.quick,
        window=args.window,
        seed=args.seed,
        figures=not args.no_figures,
        refine=refine_modes(args.refine),
        real_time=args.realtime,
    )
    return EXIT_OK


def _add_reproduce(sub: _Subparsers) -> None:
    from .experiments.reproduce import DEFAULT_OUT

    p = sub.add_parser(
        "reproduce",
        help="the paper's experiment on the simulated bench",
        description="Runs the paper's experiment (1 -> 10 -> 100 -> 200 Hz) on the "
        "simulated bench: traditional fit vs online identification, "
        "Tables 1-2, Figs. 6-9.",
    )
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help=f"output directory (default {DEFAULT_OUT})")
    p.add_argument("--quick", action="store_true", help="reduced input, for smoke tests")
    p.add_argument(
        "--window",
        type=int,
        default=None,
        help="limited memory N of the online method [samples] (default: one period of the highest frequency)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of noise and fit (default 0)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument(
        "--refine",
        default="sync",
        metavar="MODES",
        help="where the default method's window pass runs: sync, cooperative, background (the record "
        "replayed at its own sample rate), a comma-separated list or all; the modes' Table 1 side by side "
        "(default sync)",
    )
    p.add_argument(
        "--realtime",
        action="store_true",
        help="run the paced replay and its worker under SCHED_FIFO (needs the privilege)",
    )
    p.set_defaults(handler=_cmd_reproduce)


# --------------------------------------------------------------------------- diagnose


def _prepare_output(path: str | None) -> None:
    """Creates the folder of an output file, before any long work (OSError if it cannot)."""
    if path:
        from pathlib import Path

        Path(path).expanduser().resolve().parent.mkdir(parents=True, exist_ok=True)


def _cmd_diagnose(args: argparse.Namespace) -> int:
    from .diagnosis import diagnose, write_predictions, write_report
    from .plots import plot_diagnosis

    for path in (args.json, args.predictions, args.plot):
        _prepare_output(path)

    if (args.data is None) == (args.dataset is None):
        raise ValueError("give either DATA.csv or --dataset NAME (exactly one)")
    if args.dataset is not None:
        if args.columns is not None or args.dt is not None or args.resample is not None:
            raise ValueError("--columns, --dt and --resample are for DATA.csv, not --dataset")
        from .datasets import load

        rec = load(args.dataset)
        source: dict[str, Any] = {"dataset": args.dataset}
    else:
        rec = _read_record(args)
        source = _source(args, rec)
    if "citation" in rec.meta:
        source.update(citation=rec.meta["citation"], licence=rec.meta["licence"])
    val = None if args.validate is None else _read_record(args, args.validate)
    result = diagnose(
        rec.u,
        rec.x,
        rec.dt,
        progress=args.progress,
        seed=args.seed,
        validate=None if val is None else (val.u, val.x, val.dt),
    )
    print(f"{rec.name}: {len(rec)} samples, dt = {rec.dt:.6g} s")
    print(f"effects: {', '.join(result.effects) if result.effects else 'none (base model only)'}")
    for e in result.named_effects:
        rival = f"; the record does not tell it from {e.competing}" if e.competing else ""
        print(f"  {e.name}: {e.level} ({e.why}{rival})")
    print(f"error before (base model): rms {result.rms_before_um:.4g} um, max {result.max_before_um:.4g} um")
    after = f"with {', '.join(result.effects)}" if result.effects else "base model only, nothing added"
    print(f"error after ({after}): rms {result.rms_after_um:.4g} um, max {result.max_after_um:.4g} um")
    unseen = result.unseen
    if unseen is not None:
        print(
            f"unseen data ({unseen.folds}-fold blocked cross-validation): rms {unseen.cv_rms_before_um:.4g} um "
            f"(base model) -> {unseen.cv_rms_after_um:.4g} um (returned model)"
        )
        on_val = unseen.validation
        if on_val is not None and on_val.before is not None and on_val.after is not None:
            print(
                f"validation record {args.validate} ({on_val.samples} samples, "
                "offset and initial state re-estimated): "
                f"rms {on_val.before.rms_um:.4g} um (base model) -> {on_val.after.rms_um:.4g} um"
            )
    for b in result.at_bounds:
        print(f"on a bound of the fit: {b.parameter} = {b.value:.4g} ({b.side} bound {b.bound:.4g})")
    taken = [x for x in result.decisions if x.accepted]
    print(f"moves judged: {len(result.decisions)}, taken: {', '.join(x.label for x in taken) or 'none'}")
    if result.unexplained is not None:
        print(result.unexplained.summary())
    if args.json:
        write_report(result, args.json, data={**source, "samples": len(rec), "dt_s": rec.dt})
        print(f"wrote {args.json}")
    if args.predictions:
        write_predictions(result, rec.t, rec.x, args.predictions)
        print(f"wrote {args.predictions}")
    if args.plot:
        plot_diagnosis(result, rec.t, rec.u, rec.x, args.plot, title=rec.name)
        print(f"wrote {args.plot}")
    return EXIT_OK


def _add_diagnose(sub: _Subparsers) -> None:
    p = sub.add_parser(
        "diagnose",
        help="find which effect the base model misses in a record",
        description="Fits the base model, then adds, drops and swaps effects of the "
        "vocabulary while a move improves the error on held-out blocks of the record "
        "(blocked cross-validation, every fit converged) by more than its sampling "
        "error; reports the error before and after [um], the rivals the record cannot "
        "tell apart, and what is left unexplained.",
    )
    p.add_argument("data", nargs="?", default=None, help=_DATA_HELP)
    _add_record_options(p)
    p.add_argument(
        "--dataset",
        metavar="NAME",
        default=None,
        help="use a measured record of boucwen.datasets (in $BOUCWEN_DATA or ../shared/data) instead of a file "
        "(e.g. micromanipulator)",
    )
    p.add_argument("--json", metavar="REPORT.json", default=None, help="also write the report here")
    p.add_argument("--predictions", metavar="PRED.csv", default=None, help="also write t,x,x_base,x_extended here")
    p.add_argument(
        "--plot", metavar="FIG.png", default=None, help="also draw the residual before and after, and the loops"
    )
    p.add_argument(
        "--validate",
        metavar="B.csv",
        default=None,
        help="a second record of the same device (read like DATA): each effect must also predict it better, "
        "and the report gives both models' errors on it",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the base fit's starts (default 0)")
    p.add_argument("--progress", action="store_true", help="print progress to stderr")
    p.set_defaults(handler=_cmd_diagnose)


# --------------------------------------------------------------------------- batch


def _cmd_batch(args: argparse.Namespace) -> int:
    from .batch import run_fleet, summary  # ImportError naming `pip install boucwen[fleet]` without the extra

    table = run_fleet(
        args.kind,
        args.source,
        args.out,
        layout=args.layout,
        scheduler=args.scheduler,
        workers=args.workers,
        seed=args.seed,
        figure=not args.no_figure,
        progress=not args.quiet,
    )
    print(summary(table))
    return EXIT_OK if bool((table["status"] == "ok").all()) else EXIT_NOT_CONVERGED


def _add_batch(sub: _Subparsers) -> None:
    p = sub.add_parser(
        "batch",
        help="fit or diagnose a fleet of records on Dask",
        description="Fits or diagnoses every record of SOURCE (a folder or glob of CSV records t,u,x, "
        "or one long CSV/Parquet table with a channel column), one Dask task per record, on a local "
        "cluster or the scheduler at --scheduler. Writes a table (Parquet, CSV), per-record JSON, the "
        "outliers and a fleet figure into --out; a re-run skips the records already done. Exit code 1 "
        "when some record ended as an error or did not converge (its row says why).",
    )
    p.add_argument("kind", choices=("fit", "diagnose"), help="what to do with each record")
    p.add_argument("source", metavar="SOURCE", help="folder, glob (quoted) or long table of records")
    p.add_argument("--out", required=True, metavar="DIR", help="result folder (created)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler to use (default: a local cluster)")
    p.add_argument("--workers", type=int, metavar="N", help="local worker processes, 1 thread each (default: CPUs)")
    p.add_argument("--layout", metavar="CSV", help="channel,row,col of each record on the mirror's grid (maps)")
    p.add_argument("--seed", type=int, default=0, help="seed of the fits' random starts (default 0)")
    p.add_argument("--no-figure", action="store_true", help="skip DIR/fleet.png")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(handler=_cmd_batch)


# --------------------------------------------------------------------------- track


def _cmd_track(args: argparse.Namespace) -> int:
    from .experiments.track import run

    run(args.out, quick=args.quick, seed=args.seed, plants=args.plants, figures=not args.no_figures)
    return EXIT_OK


def _add_track(sub: _Subparsers) -> None:
    from .experiments.track import DEFAULT_OUT

    p = sub.add_parser(
        "track",
        help="closed-loop tracking with hysteresis compensation on the simulated bench",
        description="Tracks sines (1-200 Hz), a triangle, a staircase and band-limited random "
        "motion (0-20 um) on the simulated bench with five methods (linear open loop, fixed "
        "inverse, adaptive inverse, PI alone, PI + adaptive inverse), with the floor vibration "
        "off and on, then the adaptive inverse on generated plants; writes results.json and "
        "one figure per reference.",
    )
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help=f"output directory (default {DEFAULT_OUT})")
    p.add_argument("--quick", action="store_true", help="shorter references and 3 generated plants, for smoke tests")
    p.add_argument("--plants", type=int, default=None, help="generated plants (default 20, 3 with --quick)")
    p.add_argument("--seed", type=int, default=0, help="seed of fits, noise, random reference and plants (default 0)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.set_defaults(handler=_cmd_track)


# --------------------------------------------------------------------------- main

#: One registration function per subcommand, in help order.
SUBCOMMANDS: list[Callable[[_Subparsers], None]] = [_add_fit, _add_reproduce, _add_diagnose, _add_batch, _add_track]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand of :data:`SUBCOMMANDS`."""
    parser = _Parser(prog="boucwen", description="Asymmetric Bouc-Wen hysteresis of piezoelectric actuators.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for add in SUBCOMMANDS:
        add(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``boucwen`` script; returns the exit code."""
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
    except _UsageError as exc:
        print(str(exc).splitlines()[0] if str(exc) else "boucwen: error", file=sys.stderr)
        return EXIT_ERROR
    except SystemExit as exc:  # --help / --version
        return int(exc.code or 0)
    try:
        return int(args.handler(args))
    except (ValueError, TypeError, OSError, ImportError) as exc:
        message = " ".join(str(exc).split()) or type(exc).__name__
        print(f"boucwen {args.command}: error: {message}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print(f"boucwen {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
