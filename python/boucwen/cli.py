"""Command line: ``boucwen <subcommand> ...``.

Subcommands:

* ``boucwen fit DATA.csv [--json OUT.json]``: the traditional offline fit of a
  record (CSV with a header line naming the time, voltage and displacement in s, V, µm:
  ``t_s,u_V,x_um``, ``time,voltage,displacement``, … any case, see
  :func:`boucwen.io.read_csv`; other columns ignored); prints the parameters and the
  output error in µm. Record options (``fit`` and ``diagnose``): ``--columns T,U,X``
  names the columns (``U,X`` without time) or gives their 1-based positions (a file without
  a header line: ``--columns 2,4,3``), ``--dt DT`` gives the sampling interval of a
  record without time, ``--resample DT`` puts non-uniform time stamps on a uniform grid.
  A file of :mod:`boucwen.datasets` (e.g. ``Model_Vi_Do.dat``) is read as that record.
* ``boucwen identify DATA.csv [--method horizon|rpem|paper] [--refine sync|cooperative|background]
  [--init M.json | --init-length S] --out TRACE.csv [--plot FIG.png] [--model M.json]``:
  replays a record through the online identifier (:mod:`boucwen.replay`); writes each
  sample's prediction, estimates and status; prints the block-ahead error of the
  identified model beside the fixed starting model's. Without ``--init`` the starting
  model is fitted on the record's first stretch with excitation (from where u starts to
  move, :func:`boucwen.record.motion_onset`), and the samples it used are printed.
* ``boucwen invert --model M.json --target XD.csv --out U.csv [--u-min V] [--u-max V]``:
  the feedforward voltage for a desired displacement, through the model's effects where
  they have an inverse; prints the predicted tracking error, the limit hits and the
  samples the model cannot reach (and why, where the model's branch slope says so). A
  model whose command a DAC holds (``between_samples`` ``"hold"``) gets a command meant
  to be held, solved against the staircase (:mod:`boucwen.held_inverse`).
* ``boucwen simulate --model M.json U.csv --out X.csv [--periodic]``: a model file (a
  piezo model or a hysteretic oscillator) run open loop through its measurement chain.
* ``--model M.json`` of ``fit``, ``diagnose`` and ``identify`` writes the model file
  (:mod:`boucwen.model_file`); ``boucwen --version`` prints the version.
* ``boucwen reproduce [--out DIR] [--quick]``: the paper's experiment on the
  simulated bench (:mod:`boucwen.experiments.reproduce`).
* ``boucwen diagnose (DATA.csv | --dataset NAME) [--json REPORT.json] [--predictions PRED.csv]
  [--plot FIG.png] [--validate B.csv] [--next-experiment E.csv [--duration S]]``: which
  effects the base model misses (:mod:`boucwen.diagnosis`); prints the report, writes
  the files asked for; with ``--next-experiment``, the input that tells apart the rivals
  the record left (:mod:`boucwen.diagnosis.experiment`), to record and pass back as
  ``--validate``.
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
    import numpy as np
    from numpy.typing import NDArray

    from .checks import FloatArray
    from .model_file import AnyModel, SavedModel
    from .record import Record

    # What ``add_subparsers`` returns; each subcommand adds its parser to it.
    _Subparsers = argparse._SubParsersAction[_Parser]


# --------------------------------------------------------------------------- records

_DATA_HELP = (
    "CSV file with a header line naming the time [s], voltage [V] and displacement [um] "
    "(t_s,u_V,x_um; time,voltage,displacement; ... any case), a file without a header read with --columns "
    "by position, or a file of boucwen.datasets"
)


_MODEL_HELP = "also write the model file (boucwen.model JSON, read by --model and --init of the other commands)"


def _add_signal_options(p: argparse.ArgumentParser, spelled: str = "T,U,X", what: str = "record") -> None:
    """``--columns`` and ``--dt``: how a CSV file's columns are found."""
    names = {"T,U,X": "time, voltage and displacement", "T,U": "time and voltage", "T,X": "time and displacement"}
    p.add_argument(
        "--columns",
        metavar=spelled,
        default=None,
        help=f"the {names[spelled]} columns, by header name or 1-based position ({spelled[2:]} without time); "
        "positions are the only way to read a file without a header line; default: recognised from the header",
    )
    p.add_argument(
        "--dt", type=float, metavar="DT", default=None, help=f"sampling interval [s] of a {what} without time"
    )


def _add_record_options(p: argparse.ArgumentParser) -> None:
    _add_signal_options(p)
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
        units = rec.meta.get("read_units", {"u": "V", "x": "um"})
        print(f"{path}: {t_col}, u = {read['u']!r} [{units['u']}], x = {read['x']!r} [{units['x']}]")
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
    _prepare_output(args.model)
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
    if args.model:
        from ._core import EffectSet
        from .model_file import ModelSource, SavedModel

        model = SavedModel(
            result.params, result.h0, rec.dt, EffectSet(), ModelSource.of_record(rec, "fit", result.x_fit)
        )
        model.save(args.model)
        print(f"wrote {args.model} (the model file: boucwen invert/simulate/identify --model/--init read it)")
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
    p.add_argument("--model", metavar="M.json", help=_MODEL_HELP)
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

    for path in (args.json, args.predictions, args.plot, args.model, args.next_experiment, args.experiment_plot):
        _prepare_output(path)
    if args.experiment_plot and not args.next_experiment:
        raise ValueError("--experiment-plot draws the experiment of --next-experiment E.csv: give both")

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
    vals = [_read_record(args, path) for path in args.validate or ()]
    if args.next_experiment:
        from .diagnosis.experiment import Limits

        Limits.of(rec, args.duration, args.u_min, args.u_max, args.max_slew, None)  # bad limits fail before the work
    result = diagnose(
        rec.u,
        rec.x,
        rec.dt,
        progress=args.progress,
        seed=args.seed,
        validate=[(v.u, v.x, v.dt) for v in vals] or None,
    )
    print(f"{rec.name}: {len(rec)} samples, dt = {rec.dt:.6g} s")
    units = rec.meta.get("read_units")
    if units:
        print(f"input: force [{units['u']}]; displacement: {rec.meta['read']['x']!r} [{units['x']}]")
    structure = result.structure
    if structure is not None:
        p = structure.fit.params
        print(
            "model fitted: hysteretic oscillator m·ÿ + c·ẏ + k·y + z = F, z Bouc–Wen in ẏ "
            f"({structure.level}: {structure.why})"
        )
        print(
            f"  m = {p.m:.5g} kg, c = {p.c:.5g} N·s/m, k = {p.k:.5g} N/m, alpha = {p.alpha:.5g} N/m, "
            f"beta = {p.beta:.5g}, gamma = {p.gamma:.5g}, delta = {p.delta:.5g}, nu = {p.nu:.5g}"
        )
        print(f"input-driven rival's effects: {', '.join(result.effects) if result.effects else 'none'}")
    else:
        print("model fitted: asymmetric Bouc–Wen driven by the input (x = kv·u + x0 + h), with its effects")
        print(f"effects: {', '.join(result.effects) if result.effects else 'none (base model only)'}")
    for e in result.named_effects:
        rival = f"; rivals: {', '.join(e.rivals)}" if e.rivals else ""
        print(f"  {e.name}: {e.level} ({e.why}{rival})")
    print(f"error before (base model): rms {result.rms_before_um:.4g} um, max {result.max_before_um:.4g} um")
    after = (
        "hysteretic oscillator"
        if structure is not None
        else f"with {', '.join(result.effects)}"
        if result.effects
        else "base model only, nothing added"
    )
    print(f"error after ({after}): rms {result.rms_after_um:.4g} um, max {result.max_after_um:.4g} um")
    unseen = result.unseen
    if unseen is not None:
        print(
            f"unseen data ({unseen.folds} forward folds): rms {unseen.cv_rms_before_um:.4g} um "
            f"(base model) -> {unseen.cv_rms_after_um:.4g} um (returned model)"
        )
        for path, on_val in zip(args.validate or (), unseen.validation):
            if on_val.before is not None and on_val.after is not None:
                print(
                    f"validation record {path} ({on_val.samples} samples, "
                    "offset, trend and initial state re-estimated): "
                    f"rms {on_val.before.rms_um:.4g} um (base model) -> {on_val.after.rms_um:.4g} um "
                    f"({on_val.ratio:.3g}x)"
                )
    for b in result.at_bounds:
        print(f"on a bound of the fit: {b.parameter} = {b.value:.4g} ({b.side} bound {b.bound:.4g})")
    if result.base_loop:
        print(result.base_loop_summary())
    if result.boundedness is not None:
        print(f"returned model: {result.boundedness.summary()}")
    taken = ", ".join(x.label for x in result.taken) or "none"
    print(f"moves judged: {len(result.decisions)}; taken, in order: {taken}")
    if result.unexplained is not None:
        print(result.unexplained.summary())
    data = {**source, "samples": len(rec), "dt_s": rec.dt}
    if args.next_experiment:
        experiment = result.next_experiment(args.duration, args.u_min, args.u_max, args.max_slew)
        print("next experiment: " + experiment.summary())
        data["next_experiment"] = experiment.to_dict()
        if experiment.ambiguous:
            experiment.write_csv(args.next_experiment)
            print(
                f"wrote {args.next_experiment} (t_s,u_V: {experiment.u.size} samples; record it, then rerun with "
                f"--validate)"
            )
            if args.experiment_plot:
                experiment.plot(args.experiment_plot)
                print(f"wrote {args.experiment_plot}")
    if args.json:
        write_report(result, args.json, data=data)
        print(f"wrote {args.json}")
    if args.predictions:
        write_predictions(result, rec.t, rec.x, args.predictions)
        print(f"wrote {args.predictions}")
    if args.plot:
        plot_diagnosis(result, rec.t, rec.u, rec.x, args.plot, title=rec.name)
        print(f"wrote {args.plot}")
    if args.model:
        from .model_file import ModelSource, SavedModel, SavedOscillator

        origin = ModelSource.of_record(rec, "diagnose", result.x_extended)
        if structure is not None:
            SavedOscillator.of_fit(structure.fit, rec.dt, origin).save(args.model)
            what = "the hysteretic oscillator: force [N] in, displacement [m] out; boucwen simulate runs it"
        else:
            SavedModel(result.params, result.h0_um, rec.dt, result.effect_set, origin).save(args.model)
            what = "the returned model, with its effects"
        print(f"wrote {args.model} ({what})")
    return EXIT_OK


def _add_diagnose(sub: _Subparsers) -> None:
    p = sub.add_parser(
        "diagnose",
        help="find which effect the base model misses in a record",
        description="Fits the base model, then adds, drops and swaps effects of the "
        "vocabulary (or replaces the model by the hysteretic oscillator) while a move "
        "improves the prediction of samples its refits did not see (each fold refitted on "
        "the record before it) by more than its sampling error; reports the error before "
        "and after [um], the rivals the record cannot tell apart, and what is left "
        "unexplained.",
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
        "--model", metavar="M.json", default=None, help=_MODEL_HELP + " (the returned model, its effects included)"
    )
    p.add_argument(
        "--plot", metavar="FIG.png", default=None, help="also draw the residual before and after, and the loops"
    )
    p.add_argument(
        "--validate",
        metavar="B.csv",
        action="append",
        default=None,
        help="another record of the same device (read like DATA; repeat for several: other days, other "
        "excitations): each effect must also predict them better, each with its offset, trend and initial "
        "state re-estimated, and the report gives both models' errors on each",
    )
    p.add_argument(
        "--next-experiment",
        metavar="E.csv",
        default=None,
        help="where the record leaves rivals, write the input (t_s,u_V) that separates them best, and print "
        "the predicted separations in units of the record's noise",
    )
    p.add_argument("--duration", type=float, default=60.0, metavar="S", help="the experiment's length [s] (60)")
    p.add_argument("--u-min", type=float, default=None, metavar="V", help="its lowest voltage (the record's)")
    p.add_argument("--u-max", type=float, default=None, metavar="V", help="its highest voltage (the record's)")
    p.add_argument("--max-slew", type=float, default=None, metavar="V/S", help="its fastest slew [V/s] (the record's)")
    p.add_argument(
        "--experiment-plot",
        metavar="FIG.png",
        default=None,
        help="draw the explanations' predictions on the designed and on a generic input",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the base fit's starts (default 0)")
    p.add_argument("--progress", action="store_true", help="print progress to stderr")
    p.set_defaults(handler=_cmd_diagnose)


# --------------------------------------------------------------------------- identify

#: Length of the stretch fitted offline for the starting model of ``identify`` without
#: ``--init``, as a share of the record's duration (``--init-length`` sets it in s): a
#: fifth leaves most of the record to score the online identifier on, and on a record of
#: a few periods of its input it holds at least one of them.
IDENTIFY_INIT_SHARE = 0.2


def _load_model(path: str) -> AnyModel:
    from .model_file import SavedOscillator, load_model

    model = load_model(path)
    made = f", made by {model.source.made_by}" if model.source.made_by else ""
    record = f" on {model.source.record}" if model.source.record else ""
    filtered = f", output filter {model.output.name or 'FIR'} ({len(model.output.taps)} taps)" if model.output else ""
    chain = f"input {model.input} between samples{filtered}"
    if isinstance(model, SavedOscillator):
        print(f"{path}: hysteretic oscillator{made}{record}; {chain}; dt = {model.dt_s:.6g} s")
        return model
    named = ", ".join(e.name for e in model.named_effects if e.name != "between_samples") or "none"
    print(f"{path}: model{made}{record}; effects: {named}; {chain}; dt = {model.dt_s:.6g} s")
    return model


def _load_piezo(path: str, command: str) -> SavedModel:
    """The piezo model of a model file; a one-line error for an oscillator's."""
    from ._core import InvalidParams
    from .model_file import SavedOscillator

    model = _load_model(path)
    if isinstance(model, SavedOscillator):
        raise InvalidParams(
            f"{path}: a hysteretic oscillator (force in, displacement out); boucwen {command} takes a piezo model"
        )
    return model


def _starting_fit(args: argparse.Namespace, rec: Record) -> tuple[SavedModel, int]:
    """The starting model of ``identify`` without ``--init``: :func:`boucwen.fit` on the
    record's first stretch with excitation (from the last sample at rest before u first
    moves, :func:`boucwen.record.motion_onset`, ``--init-length`` seconds long), and the
    sample after that stretch (the scores leave the stretch out). Says what it used."""
    from ._core import EffectSet, InvalidConfig, InvalidRecord
    from .fit import fit
    from .model_file import ModelSource, SavedModel
    from .record import motion_onset

    n = len(rec)
    onset = motion_onset(rec.u)
    if not onset.moves(n):
        raise InvalidRecord(
            f"u stays within ±{onset.band_v:.3g} V of its first sample over the whole record "
            "(at rest): the starting fit needs a varying voltage (or give --init M.json)"
        )
    if args.init_length is None:
        length_s = IDENTIFY_INIT_SHARE * n * rec.dt
        chosen = f"{IDENTIFY_INIT_SHARE:.0%} of the record's duration; set it with --init-length S"
    else:
        if not args.init_length > 0.0:
            raise InvalidConfig(f"--init-length must be > 0 s, got {args.init_length!r}")
        length_s, chosen = args.init_length, "--init-length"
    start = onset.start
    stop = min(n, start + max(1, round(length_s / rec.dt)))
    if stop - start < 16:
        raise InvalidConfig(
            f"the starting fit's stretch holds {stop - start} samples (from sample {start}, where u starts to move); "
            "it needs at least 16: give a longer --init-length or --init M.json"
        )
    if onset.start > 0:
        print(
            f"u at rest for the first {onset.start + 1} samples (t = {rec.t[0]:.6g} to {rec.t[onset.start]:.6g} s, "
            f"within ±{onset.band_v:.3g} V of {rec.u[0]:.6g} V); it starts to move after sample {onset.start}"
        )
    result = fit(rec.u[start:stop], rec.x[start:stop], rec.dt, seed=args.seed, progress=args.progress)
    init = SavedModel(result.params, result.h0, rec.dt, EffectSet(), ModelSource.of_record(rec, "fit"))
    print(
        f"starting model: boucwen.fit on samples {start} to {stop - 1} ({stop - start} samples, "
        f"t = {rec.t[start]:.6g} to {rec.t[stop - 1]:.6g} s: {(stop - start) * rec.dt:.6g} s from where u starts to "
        f"move, {chosen}), output error rms {result.rms_um:.4g} µm there; it is also the fixed model "
        "(give one with --init M.json)"
    )
    return init, stop


def _cmd_identify(args: argparse.Namespace) -> int:
    import numpy as np

    from .io import write_csv
    from .metrics import max_abs, rms
    from .pacing import refine_mode
    from .replay import check_options, replay

    for path in (args.out, args.plot, args.model):
        _prepare_output(path)
    refine = refine_mode(args.refine)
    check_options(args.method, refine, args.window)
    if args.init is not None and args.init_length is not None:
        raise ValueError("--init-length sets the starting fit's stretch; --init M.json gives the model instead")
    rec = _read_record(args)
    n = len(rec)
    print(f"{rec.name}: {n} samples, dt = {rec.dt:.6g} s")
    if args.init is not None:
        init = _load_piezo(args.init, "identify --init")
        _check_rate(init, rec.dt)
        scored_from = 0
    else:
        init, scored_from = _starting_fit(args, rec)
    if refine == "background":
        print(f"background refine: the record is replayed at its own sample rate ({rec.duration_s:.1f} s)")
    r, dropped = replay(rec, init, method=args.method, refine=refine, window=args.window, block=args.block)
    if dropped:
        print(
            f"the {args.method} method does not identify {', '.join(dropped)}: left out of the online model, "
            "which starts from parameters fitted with them (the fixed model keeps them)"
        )
    blocks = r.block_starts()
    scored = blocks >= scored_from
    if not np.any(scored):
        scored = blocks >= 0
    ident, fixed = r.block_errors[scored], r.fixed_block_errors[scored]
    first = float(rec.t[blocks[scored][0]])
    print(
        f"block-ahead error [µm]: max |x - x̂| over each block of {r.block} samples ({r.block * rec.dt:.6g} s), "
        f"the estimates and state frozen at its start and run open loop; {ident.size} blocks from t = {first:.6g} s"
    )
    label = f"identified ({args.method}{', ' + refine if args.method == 'horizon' else ''})"
    width = max(len(label), len("fixed (starting model)"))
    for name, e in ((label, ident), ("fixed (starting model)", fixed)):
        print(f"  {name:<{width}}  median {np.median(e):.4g}  worst {np.max(e):.4g}  last block {e[-1]:.4g}")
    better = float(np.mean(ident < fixed))
    print(f"  the identified model is better on {100.0 * better:.0f} % of these blocks")
    one = rec.x - r.one_step
    print(f"one-step prediction (each sample before it is used): rms {rms(one):.4g} µm, max {max_abs(one):.4g} µm")
    if r.late_samples:
        print(f"{r.late_samples} samples were pushed more than one interval late (the host was busy)")
    final = r.final
    estimates = ", ".join(f"{k} = {v:.5g}" for k, v in final.params.to_dict().items())
    lag = "".join(f"; {k} = {v[-1]:.5g}" for k, v in r.effects.items())
    print(f"final estimates: {estimates}{lag}")

    columns: dict[str, Any] = {
        "t_s": rec.t,
        "u_V": rec.u,
        "x_um": rec.x,
        "x_pred_um": r.one_step,
        "x_block_um": r.block_ahead,
        "x_fixed_um": r.fixed,
    }
    from ._core import Params

    columns.update({name: r.params[:, i] for i, name in enumerate(Params.names)})
    columns.update(r.effects)
    columns.update({f"status.{k}": v for k, v in r.status.items()})
    write_csv(args.out, columns)
    print(f"wrote {args.out} (per sample: prediction, block-ahead run, fixed model, estimates, status)")
    if args.plot:
        from .plots import plot_identify

        plot_identify(r, rec.t, rec.x, args.plot, title=f"{rec.name}, {args.method}")
        print(f"wrote {args.plot}")
    if args.model:
        final.save(args.model)
        print(f"wrote {args.model} (the final model; h0 the starting model's)")
    return EXIT_OK


def _add_identify(sub: _Subparsers) -> None:
    from .replay import BLOCK_S, METHODS

    p = sub.add_parser(
        "identify",
        help="replay a logged record through the online identifier",
        description="Pushes the record sample by sample through an online identifier (as a control loop "
        "would) and writes each sample's prediction, estimates and status. Prints the block-ahead error "
        "of the identified model beside the fixed starting model's: at the start of each block the "
        "estimates and state are frozen and run open loop over the block (the tables' metric).",
    )
    p.add_argument("data", help=_DATA_HELP)
    _add_record_options(p)
    p.add_argument("--method", choices=METHODS, default="horizon", help="online method (default horizon)")
    p.add_argument(
        "--refine",
        choices=("sync", "cooperative", "background"),
        default="sync",
        help="where the horizon method's window pass runs (default sync; background replays the record "
        "at its own sample rate)",
    )
    p.add_argument(
        "--init",
        metavar="M.json",
        default=None,
        help="starting (and fixed) model; default: boucwen.fit on the record's first stretch with excitation "
        "(from where u starts to move, --init-length long), which the scores then leave out",
    )
    p.add_argument(
        "--init-length",
        type=float,
        metavar="S",
        default=None,
        help=f"length of the starting fit's stretch [s] (default {100 * IDENTIFY_INIT_SHARE:g} %% of the record's "
        "duration)",
    )
    p.add_argument("--out", required=True, metavar="TRACE.csv", help="per-sample trace (written)")
    p.add_argument("--plot", metavar="FIG.png", default=None, help="also draw the estimates and the errors over time")
    p.add_argument("--model", metavar="M.json", default=None, help="also write the final model as a model file")
    p.add_argument(
        "--block",
        type=int,
        metavar="N",
        default=None,
        help=f"samples per block of the block-ahead error (default {BLOCK_S:g} s of samples)",
    )
    p.add_argument(
        "--window", type=int, metavar="N", default=None, help="the paper method's window [samples] (default 1 s)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the starting fit (default 0)")
    p.add_argument("--progress", action="store_true", help="the starting fit's progress on stderr")
    p.set_defaults(handler=_cmd_identify)


# --------------------------------------------------------------------------- invert, simulate


def _read_signal(
    args: argparse.Namespace, path: str, quantity: str, unit: str | None = None
) -> tuple[FloatArray, FloatArray, float]:
    from .io import read_signal

    t, values, dt, meta = read_signal(path, quantity, columns=args.columns, dt=args.dt)
    read = meta["read"]
    t_col = f"t = {read['t']!r} [s]" if read["t"] is not None else f"no time column, dt = {dt:.6g} s"
    unit = unit or ("V" if quantity == "u" else "um")
    print(f"{path}: {values.size} samples, {t_col}, {quantity} = {read[quantity]!r} [{unit}]")
    return t, values, dt


def _check_rate(model: AnyModel, dt: float) -> None:
    import math

    if not math.isclose(dt, model.dt_s, rel_tol=1e-6):
        print(f"note: sampled every {dt:.6g} s; the model's record every {model.dt_s:.6g} s")


def _cmd_invert(args: argparse.Namespace) -> int:
    import numpy as np

    from ._core import invert
    from .effects.base import params_of, set_of
    from .io import write_csv
    from .metrics import max_abs, rms

    _prepare_output(args.out)
    model = _load_piezo(args.model, "invert")
    t, x_d, dt = _read_signal(args, args.target, "x")
    _check_rate(model, dt)
    present = params_of(model.effects)
    modes = [k for k in present if k in _MODES]
    no_inverse: list[str] = []
    ignored = [k for k in present if k in _READING_ONLY]
    if modes:
        print(f"{', '.join(modes)}: inverted by the mode's own inverse on the target (x_d + 2ζ/ω·ẋ_d + ẍ_d/ω²)")
    if ignored:
        print(f"{', '.join(ignored)}: in the reading only; the inverse ignores it (the predicted error includes it)")
    if model.output is not None:
        print(
            "output filter: the logger's, in the reading only; the inverse ignores it (the predicted error includes it)"
        )
    if model.input == "bandlimited":
        print(
            "between_samples (bandlimited): the inverse takes the command as a straight line between samples "
            "(the predicted error, the model run on the voltage, includes the difference)"
        )
    inverted = set_of({k: v for k, v in present.items() if k not in (*_MODES, "between_samples")})
    ahead = _through_modes(x_d, dt, [present[k] for k in modes], present.get("drift"))
    if model.input == "hold":
        from .held_inverse import invert_held

        lead = " (through the input lag: each command leads its target by one sample)" if "input_lag" in present else ""
        print(f"between_samples (hold): a command for a DAC to hold, solved against the held staircase{lead}")
        u = invert_held(model.params, inverted, ahead, dt, model.h0_um, u_min=args.u_min, u_max=args.u_max)
    else:
        u, _ = invert(model.params, ahead, dt, model.h0_um, u_min=args.u_min, u_max=args.u_max, effects=inverted)
    x_model = model.simulate(u, dt)
    err = x_model - x_d
    print(f"voltage: {np.min(u):.4g} to {np.max(u):.4g} V over {u.size} samples")
    print(f"predicted tracking error (the model run on this voltage): rms {rms(err):.4g} µm, max {max_abs(err):.4g} µm")
    clipped = np.zeros(u.size, dtype=bool)
    hits = []
    for name, limit in (("u_min", args.u_min), ("u_max", args.u_max)):
        if limit is not None:
            hit = u <= limit if name == "u_min" else u >= limit
            clipped |= hit
            count = int(np.count_nonzero(hit))
            hits.append(f"{name} = {limit:g} V on {count} samples ({100.0 * count / u.size:.3g} %)")
    print(f"voltage limits hit: {'; '.join(hits) if hits else 'none given (--u-min, --u-max)'}")
    missed = _missed(model, u, x_d, err, dt)
    count = int(np.count_nonzero(missed))
    on_limit = int(np.count_nonzero(missed & clipped))
    print(
        f"target reached on {u.size - count} of {u.size} samples"
        + (f"; missed on {count} ({on_limit} of them with u on a limit)" if count else "")
    )
    if count > on_limit:
        print(f"why the others are missed: {_why_missed(model, u, dt, no_inverse + ignored)}")
    # Every digit of u: the model's rate term follows the sign of each step of u, however small.
    write_csv(args.out, {"t_s": t, "u_V": u, "x_d_um": x_d, "x_model_um": x_model}, digits=17)
    print(f"wrote {args.out} (t, u, the target and the model's displacement)")
    return EXIT_OK


def _missed(model: SavedModel, u: FloatArray, x_d: FloatArray, err: FloatArray, dt: float) -> NDArray[np.bool_]:
    """Samples the model does not reach on ``u``: off the target by more than the inverse's
    tolerance and the step |δ·u|·dt a reversal may leave (:class:`boucwen.Inverse`)."""
    import numpy as np

    from ._core import INVERSE_TOLERANCE_UM

    allowed = INVERSE_TOLERANCE_UM * np.maximum(1.0, np.abs(x_d)) + np.abs(model.params.delta * u) * dt
    return np.abs(err) > allowed + 1e-12


def _why_missed(model: SavedModel, u: FloatArray, dt: float, left_out: list[str]) -> str:
    """Why a model's inverse may miss: the effects it left out or, for the base model, the
    samples where its branch slope kv + A − (β·sgn(u̇)·sgn(h) + γ)·|h|^n is not positive
    (x does not rise with u)."""
    import numpy as np

    if left_out:
        return f"the effects the inverse leaves out ({', '.join(left_out)}) move x off it"
    if len(model.effects):
        return "the model's x_model_um in the output shows where"
    p = model.params
    h = model.simulate(u, dt) - p.kv * u - p.x0
    du = np.sign(np.diff(u, prepend=u[0]))
    slope = p.kv + p.A - (p.beta * du * np.sign(h) + p.gamma) * np.abs(h) ** p.n
    falling = int(np.count_nonzero((slope <= 0.0) & (du != 0.0)))
    if not falling:
        return "the model's x_model_um in the output shows where"
    return (
        f"its branch slope kv + A - (beta*sgn(du)*sgn(h) + gamma)*|h|^n is not positive on {falling} samples, "
        "so x does not rise with u there (a base model standing in for a lag of the amplifier bends so; "
        "boucwen diagnose --model gives a model with the lag, whose inverse leads the voltage)"
    )


#: The mechanical modes (inverted on the target, before the core's inverse), and the
#: effects the inverse ignores (in the sensor's reading only).
_MODES = ("resonance", "resonance2")
_READING_ONLY = ("pickup", "saturation")


def _through_modes(
    x_d: FloatArray, dt: float, modes: list[dict[str, float]], drift: dict[str, float] | None
) -> FloatArray:
    """The displacement before the modes that makes them output ``x_d`` [µm]: each mode
    ẍ/ω² + 2ζ/ω·ẋ + x = y inverted, y = x_d + 2ζ/ω·ẋ_d + ẍ_d/ω² (derivatives by central
    differences; a stable second-order low-pass has this exact inverse, with no delay).
    A drift, added after the modes, is taken off the rate first (its ramp passes the
    modes unchanged but for 2ζ/ω times its rate)."""
    import numpy as np

    out = np.asarray(x_d, dtype=np.float64)
    rate = float(drift["rate_um_per_s"]) if drift else 0.0
    for mode in modes:
        w = 2.0 * np.pi * float(mode["fn_hz"])
        zeta = float(mode["zeta"])
        v = np.gradient(out, dt)
        a = np.gradient(v, dt)
        out = out + 2.0 * zeta / w * (v - rate) + a / w**2
    return out


def _add_invert(sub: _Subparsers) -> None:
    p = sub.add_parser(
        "invert",
        help="the feedforward voltage that makes the model follow a target displacement",
        description="Inverts the model (its effects included where they have an inverse: input lag, creep, "
        "gain drift, electrostriction, drift, delay) sample by sample for a desired displacement, "
        "within the voltage limits; prints the model's predicted tracking error and the limit hits.",
    )
    p.add_argument("--model", required=True, metavar="M.json", help="model file (boucwen fit/diagnose --model)")
    p.add_argument(
        "--target",
        required=True,
        metavar="XD.csv",
        help="desired displacement [um]: a CSV with time [s] and displacement columns (t,x; any name read by "
        "boucwen fit), or named or positioned by --columns",
    )
    _add_signal_options(p, "T,X", "target")
    p.add_argument(
        "--out", required=True, metavar="U.csv", help="voltage to apply (written: t_s,u_V,x_d_um,x_model_um)"
    )
    p.add_argument("--u-min", type=float, metavar="V", default=None, help="lowest voltage [V]")
    p.add_argument("--u-max", type=float, metavar="V", default=None, help="highest voltage [V]")
    p.set_defaults(handler=_cmd_invert)


def _cmd_simulate(args: argparse.Namespace) -> int:
    import numpy as np

    from .io import write_csv
    from .model_file import SavedOscillator

    _prepare_output(args.out)
    model = _load_model(args.model)
    if isinstance(model, SavedOscillator):
        t, force, dt = _read_signal(args, args.data, "u", unit="N")
        _check_rate(model, dt)
        y = model.simulate(force, dt, periodic=args.periodic)
        print(f"displacement: {np.min(y):.4g} to {np.max(y):.4g} m over {y.size} samples (from the model's state)")
        # Every digit: a file run through the command gives the model's output itself.
        write_csv(args.out, {"t_s": t, "force_N": force, "y_m": y}, digits=17)
    else:
        if args.periodic:
            raise ValueError("--periodic is for an oscillator's force; a piezo model's voltage path is its own")
        t, u, dt = _read_signal(args, args.data, "u")
        _check_rate(model, dt)
        x = model.simulate(u, dt)
        print(f"displacement: {np.min(x):.4g} to {np.max(x):.4g} µm over {x.size} samples (open loop, from h0)")
        write_csv(args.out, {"t_s": t, "u_V": u, "x_um": x}, digits=17)
    print(f"wrote {args.out}")
    return EXIT_OK


def _add_simulate(sub: _Subparsers) -> None:
    p = sub.add_parser(
        "simulate",
        help="run a model open loop on a voltage (or an oscillator on a force)",
        description="Runs the model of a model file, with its effects and its measurement chain (the input "
        "between samples, the logger's output filter), open loop from its initial state on the voltage of a CSV "
        "file; writes t_s,u_V,x_um (every digit). An oscillator's file takes a force [N] and writes "
        "t_s,force_N,y_m.",
    )
    p.add_argument("--model", required=True, metavar="M.json", help="model file (boucwen fit/diagnose --model)")
    p.add_argument(
        "data",
        metavar="U.csv",
        help="voltage [V] (an oscillator: force [N]): a CSV with time [s] and input columns (t,u; any name read "
        "by boucwen fit, e.g. boucwen invert's output), or named or positioned by --columns",
    )
    _add_signal_options(p, "T,U", "voltage file")
    p.add_argument(
        "--out", required=True, metavar="X.csv", help="displacement (written: t_s,u_V,x_um; t_s,force_N,y_m)"
    )
    p.add_argument(
        "--periodic",
        action="store_true",
        help="an oscillator's force is a whole number of periods (its band-limited path is then exactly the "
        "Fourier interpolation)",
    )
    p.set_defaults(handler=_cmd_simulate)


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
SUBCOMMANDS: list[Callable[[_Subparsers], None]] = [
    _add_fit,
    _add_diagnose,
    _add_identify,
    _add_invert,
    _add_simulate,
    _add_reproduce,
    _add_batch,
    _add_track,
]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand of :data:`SUBCOMMANDS`."""
    from ._core import __version__

    parser = _Parser(prog="boucwen", description="Asymmetric Bouc-Wen hysteresis of piezoelectric actuators.")
    parser.add_argument("--version", action="version", version=f"boucwen {__version__}")
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
