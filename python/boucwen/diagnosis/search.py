"""The greedy search of the diagnosis: add the effect that best explains the held-out
error, while it earns its parameters (procedure in :mod:`boucwen.diagnosis`)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable

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
from .unexplained import unexplained

__all__ = [
    "MAX_DELAY_SAMPLES",
    "MIN_GAIN",
    "TRAIN_FRACTION",
    "TRIAL_NFEV",
    "Round",
    "diagnose",
    "diagnose_record",
    "score_round",
]

#: Default fraction of the record (from its start) used for fitting.
TRAIN_FRACTION = 0.7
#: Default least relative cut of the held-out RMS error an effect must bring.
MIN_GAIN = 0.10
#: Iteration limit of each trial fit (a trial only has to show what the effect explains).
TRIAL_NFEV = 20
#: Largest delay tried [samples].
MAX_DELAY_SAMPLES = 8


def _heldout(fr: ExtendedFit, record: Record, nt: int) -> tuple[float, FloatArray]:
    """RMS error [µm] of a fit over the held-out samples ``nt …``, and its x̂ over the record."""
    xs = simulate_chain(fr.params, fr.effects, record.u, record.dt, fr.h0)
    if xs is None:
        return math.inf, np.full(len(record), np.nan)
    return rms((record.x - xs)[nt:]), xs


@dataclass(frozen=True, eq=False)
class Round:
    """One round of the search (:func:`score_round`).

    Attributes:
        evidence: the round's JSON evidence: ``heldout_rms_um`` of the current model,
            ``null`` (the current model refitted with the trials' effort and nothing
            added: ``train_rms_um``, ``heldout_rms_um``, ``heldout_gain``), ``reference_rms_um``
            (the lower of the two held-out errors, the one each effect is credited
            against), ``trials`` (per effect: ``heldout_gain`` against the current model,
            ``gain_over_null`` against the reference, …), ``most_likely`` and ``kept``.
        kept: the fit of the kept effect, or None.
    """

    evidence: dict[str, Any]
    kept: ExtendedFit | None


def score_round(
    record: Record,
    nt: int,
    current: ExtendedFit,
    *,
    min_gain: float = MIN_GAIN,
    seed: int = 0,
    workers: int | None = None,
    say: Callable[[str], None] | None = None,
    cur_held: float | None = None,
    trial_nfev: int = TRIAL_NFEV,
) -> Round:
    """Tries every effect not yet in ``current`` on the first ``nt`` samples of ``record``.

    Each trial adds one effect and refits everything for at most ``trial_nfev``
    iterations; the *null trial* refits ``current`` with the same budget and nothing
    added. An effect is credited only with the cut of the held-out RMS error beyond
    both the current model and the null trial (``gain_over_null``), so that the
    convergence the extra iterations bring is not taken for the effect; it is kept
    when that credit is at least ``min_gain``.
    """
    note = say if say is not None else (lambda _msg: None)
    train = record.part(0, nt)
    dt = record.dt
    if cur_held is None:
        cur_held, _ = _heldout(current, record, nt)
    null = fit_extended_record(train, current.params, current.effects, current.h0, max_nfev=trial_nfev, workers=workers)
    null_held, _ = _heldout(null, record, nt)
    reference = min(cur_held, null_held)
    note(f"  0 null     : held-out RMS {null_held:.4g} µm (gain {1.0 - null_held / cur_held:+.1%})")
    trials: dict[str, dict[str, Any]] = {}
    fits: dict[str, ExtendedFit] = {}
    for name in VOCABULARY:
        if name in current.effects.names:
            continue
        starts = candidate_starts(name, train, current.params, current.effects, current.h0, max_delay=MAX_DELAY_SAMPLES)
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
            fr = fit_extended_record(train, p0, start_effects, h0, max_nfev=trial_nfev, workers=workers)
        except ValueError as exc:
            trials[name] = {"error": str(exc)}
            continue
        held, _ = _heldout(fr, record, nt)
        gain = 1.0 - held / cur_held if cur_held > 0 else 0.0
        credited = 1.0 - held / reference if reference > 0 else 0.0
        fitted = fr.effects.to_dict()
        trials[name] = {
            "train_rms_um": fr.rms_um,
            "heldout_rms_um": held,
            "heldout_gain": gain,
            "gain_over_null": credited,
            "fitted": dict(fitted).get(name),
        }
        resonance = fitted.get("resonance")
        if name == "resonance" and resonance is not None and resonance["zeta"] >= 0.99 * ZETA_BOUNDS[1]:
            # Critically damped or more: no peak, so not a resonance (a lag shape
            # the other effects describe); recorded, but not a candidate.
            trials[name]["rejected"] = "no resonance peak: fitted zeta at its bound of 1"
            note(f"  - {name:9s}: fitted zeta at its bound (no peak): not a resonance")
            continue
        fits[name] = fr
        note(f"  + {name:9s}: held-out RMS {held:.4g} µm (gain {gain:+.1%}, over the null {credited:+.1%})")
    ranked = sorted(fits, key=lambda k: trials[k]["heldout_rms_um"])
    best = ranked[0] if ranked else None
    keep = best is not None and trials[best]["gain_over_null"] >= min_gain
    evidence = {
        "heldout_rms_um": cur_held,
        "null": {
            "train_rms_um": null.rms_um,
            "heldout_rms_um": null_held,
            "heldout_gain": 1.0 - null_held / cur_held if cur_held > 0 else 0.0,
        },
        "reference_rms_um": reference,
        "trials": trials,
        "most_likely": best,
        "kept": bool(keep),
    }
    return Round(evidence=evidence, kept=fits[best] if keep and best is not None else None)


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
        return _heldout(fr, record, nt)

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
        round_ = score_round(
            record, nt, current, min_gain=min_gain, seed=seed, workers=workers, say=say, cur_held=cur_held
        )
        evidence["rounds"].append(round_.evidence)
        if round_.kept is None:
            say("nothing left that earns its parameters on the held-out part")
            break
        current = round_.kept
        cur_held, cur_x = heldout(current)
        added.append(round_.evidence["most_likely"])
        say(f"kept {added[-1]}: held-out RMS {cur_held:.4g} µm")

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
    left = unexplained(record, x_ext)
    say(left.summary())
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
        unexplained=left,
    )
    say(result.summary())
    return result
