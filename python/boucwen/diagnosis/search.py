"""The greedy search of the diagnosis: add the effect that best explains the held-out
error, while it earns its parameters (procedure in :mod:`boucwen.diagnosis`)."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._core import EffectSet
from ..checks import FloatArray, check_int, check_number
from ..effects import VOCABULARY, ZETA_BOUNDS, ExtendedFit, candidate_starts, fit_extended_record, simulate_chain
from ..fit import fit_record
from ..metrics import max_abs, rms
from ..progress import Progress, reporter
from ..record import Record, validate_record
from .evidence import delay_evidence, residual_evidence_record
from .report import Diagnosis, jsonable

__all__ = ["MAX_DELAY_SAMPLES", "MIN_GAIN", "TRAIN_FRACTION", "TRIAL_NFEV", "diagnose", "diagnose_record"]

#: Default fraction of the record (from its start) used for fitting.
TRAIN_FRACTION = 0.7
#: Default least relative cut of the held-out RMS error an effect must bring.
MIN_GAIN = 0.10
#: Iteration limit of each trial fit (a trial only has to show what the effect explains).
TRIAL_NFEV = 20
#: Largest delay tried [samples].
MAX_DELAY_SAMPLES = 8


def diagnose(
    u: ArrayLike,
    x: ArrayLike,
    dt: float,
    *,
    progress: Progress = False,
    train_fraction: float = TRAIN_FRACTION,
    min_gain: float = MIN_GAIN,
    max_effects: int = 3,
    seed: int = 0,
    workers: int | None = None,
) -> Diagnosis:
    """Finds which effects of the vocabulary the record holds beyond the base model.

    Args:
        u: voltage [V], 1-D, finite, not constant, uniformly sampled.
        x: measured displacement [µm], same length.
        dt: sampling interval [s] (> 0).
        progress: ``True`` prints progress lines to stderr; or a callable taking a str.
        train_fraction: share of the record (from its start) used for fitting during
            the search; the rest is held out (0.3 … 0.95).
        min_gain: least relative cut of the held-out RMS error an effect must bring
            to be kept (0 … 1).
        max_effects: most effects added (0 … 5).
        seed: seed of :func:`boucwen.fit`'s random starts.
        workers: threads for the Jacobians (default: the number of CPUs).

    Returns:
        A :class:`~boucwen.diagnosis.Diagnosis`; the procedure is described in
        :mod:`boucwen.diagnosis`.

    Raises:
        TypeError, ValueError: bad data or options (precise message).
    """
    return diagnose_record(
        validate_record(u, x, dt),
        progress=progress,
        train_fraction=train_fraction,
        min_gain=min_gain,
        max_effects=max_effects,
        seed=seed,
        workers=workers,
    )


def diagnose_record(
    record: Record,
    *,
    progress: Progress = False,
    train_fraction: float = TRAIN_FRACTION,
    min_gain: float = MIN_GAIN,
    max_effects: int = 3,
    seed: int = 0,
    workers: int | None = None,
) -> Diagnosis:
    """:func:`diagnose` on a checked :class:`~boucwen.record.Record` (same options, same result)."""
    started = time.perf_counter()
    say = reporter(progress, "diagnose", started)
    train_fraction = check_number("train_fraction", train_fraction, 0.3, 0.95)
    min_gain = check_number("min_gain", min_gain, 0.0, 1.0)
    max_effects = check_int("max_effects", max_effects, 0, 5)
    u, x, dt = record.u, record.x, record.dt
    n = u.size
    nt = round(train_fraction * n)
    if nt < 64 or n - nt < 16:
        raise ValueError(f"diagnose needs at least 100 samples, got {n}")
    if not np.ptp(u[:nt]) > 0:
        raise ValueError("u is constant over the fitting part; the diagnosis needs a varying voltage")
    train = record.part(0, nt)

    def heldout(fr: ExtendedFit) -> tuple[float, FloatArray]:
        xs = simulate_chain(fr.params, fr.effects, u, dt, fr.h0)
        if xs is None:
            return math.inf, np.full(n, np.nan)
        return rms((x - xs)[nt:]), xs

    say(f"fitting the base model on the first {nt} of {n} samples")
    base_tr = fit_record(train, seed=seed, workers=workers)
    current = fit_extended_record(train, base_tr.params, EffectSet(), base_tr.h0, max_nfev=100, workers=workers)
    cur_held, cur_x = heldout(current)
    say(f"base model: fitting-part RMS {current.rms_um:.4g} µm, held-out RMS {cur_held:.4g} µm")
    evidence: dict[str, Any] = {
        "train_samples": nt,
        "heldout_samples": n - nt,
        "min_gain": min_gain,
        "residual": residual_evidence_record(record, cur_x),
        "rounds": [],
    }
    evidence["residual"]["delay"] = delay_evidence(record, current, MAX_DELAY_SAMPLES)
    added: list[str] = []

    while len(added) < max_effects:
        trials: dict[str, dict[str, Any]] = {}
        fits: dict[str, ExtendedFit] = {}
        for name in VOCABULARY:
            if name in current.effects.names:
                continue
            starts = candidate_starts(
                name, train, current.params, current.effects, current.h0, max_delay=MAX_DELAY_SAMPLES
            )
            if len(starts) > 1:
                costs = []
                for s in starts:
                    xs = simulate_chain(current.params, s, train.u, dt, current.h0)
                    costs.append(math.inf if xs is None else rms(xs - train.x))
                starts = [starts[int(np.argmin(costs))]]
            p0, h0 = current.params, current.h0
            start_effects = starts[0]
            delay = start_effects.to_dict().get("delay")
            if name == "delay" and delay is not None:
                # The base fit has bent itself to follow the lag; a delay of d samples is
                # the base model fitted to the record shifted by d, which starts it right.
                shifted = fit_record(train.realigned(delay["samples"]), init=current.params, seed=seed, workers=workers)
                p0, h0 = shifted.params, shifted.h0
            try:
                fr = fit_extended_record(train, p0, start_effects, h0, max_nfev=TRIAL_NFEV, workers=workers)
            except ValueError as exc:
                trials[name] = {"error": str(exc)}
                continue
            held, _ = heldout(fr)
            gain = 1.0 - held / cur_held if cur_held > 0 else 0.0
            fitted = fr.effects.to_dict()
            trials[name] = {
                "train_rms_um": fr.rms_um,
                "heldout_rms_um": held,
                "heldout_gain": gain,
                "fitted": dict(fitted).get(name),
            }
            resonance = fitted.get("resonance")
            if name == "resonance" and resonance is not None and resonance["zeta"] >= 0.99 * ZETA_BOUNDS[1]:
                # Critically damped or more: no peak, so not a resonance (a lag shape
                # the other effects describe); recorded, but not a candidate.
                trials[name]["rejected"] = "no resonance peak: fitted zeta at its bound of 1"
                say(f"  - {name:9s}: fitted zeta at its bound (no peak): not a resonance")
                continue
            fits[name] = fr
            say(f"  + {name:9s}: held-out RMS {held:.4g} µm (gain {gain:+.1%})")
        ranked = sorted(fits, key=lambda k: trials[k]["heldout_rms_um"])
        best = ranked[0] if ranked else None
        keep = best is not None and trials[best]["heldout_gain"] >= min_gain
        evidence["rounds"].append(
            {"heldout_rms_um": cur_held, "trials": trials, "most_likely": best, "kept": bool(keep)}
        )
        if best is None or not keep:
            say("nothing left that earns its parameters on the held-out part")
            break
        current = fits[best]
        cur_held, cur_x = heldout(current)
        added.append(best)
        say(f"kept {best}: held-out RMS {cur_held:.4g} µm")

    say("refitting on the whole record")
    base_all = fit_record(record, init=base_tr.params, n_candidates=0, n_starts=1, seed=seed, workers=workers)
    x_base = base_all.x_fit
    if added:
        ext = fit_extended_record(record, current.params, current.effects, current.h0, workers=workers)
        x_ext = ext.simulate(u, dt)
        params = ext.to_dict()
        effect_set = ext.effects
    else:
        x_ext = x_base.copy()
        params = {"base": base_all.params.to_dict(), "h0_um": base_all.h0}
        effect_set = EffectSet()
    params["base_only"] = {"base": base_all.params.to_dict(), "h0_um": base_all.h0}
    err_b, err_e = x - x_base, x - x_ext
    evidence["elapsed_s"] = time.perf_counter() - started
    result = Diagnosis(
        effects=added,
        rms_before=rms(err_b),
        max_before=max_abs(err_b),
        rms_after=rms(err_e),
        max_after=max_abs(err_e),
        params=params,
        evidence=jsonable(evidence),
        x_base=x_base,
        x_extended=x_ext,
        effect_set=effect_set,
    )
    say(result.summary())
    return result
