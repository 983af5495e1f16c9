"""The greedy search of the diagnosis: add the effect that best explains the record's
error under blocked cross-validation, while it earns its parameters (procedure in
:mod:`boucwen.diagnosis`)."""

from __future__ import annotations

import itertools
import math
import threading
import time
from collections.abc import Sequence
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike
from scipy.signal import lfilter, lfilter_zi

from .._core import EffectSet, Params
from ..checks import check_int, check_number
from ..effects import (
    FN_MAX_NYQUIST_FRACTION,
    VOCABULARY,
    Drift,
    ExtendedFit,
    Layout,
    Resonance2,
    Solved,
    candidate_starts,
    fit_extended_record,
    jacobian_extended,
    simulate_chain,
    solve_extended_record,
)
from ..effects.base import params_of, set_of, with_effect, without
from ..fit import FitResult, fit_record
from ..io import jsonable
from ..lsq import thread_map, worker_threads
from ..metrics import max_abs, rms
from ..progress import Progress, reporter
from ..record import Record, validate_record
from .confidence import confidence
from .evidence import delay_evidence, residual_evidence_record
from .lookalike import GROUPS, lookalike_tests, named, phase_shape, what_it_follows
from .margins import CLOSE_GAIN, CLOSE_REL, PATH, CloseCalls, Compare, at_least, at_most, decide, first_of_best
from .report import Diagnosis
from .unexplained import Unexplained, noise_level, unexplained
from .unseen import judged_on, prediction_error
from .validation import FOLDS, CrossValidation, blocked_cv

__all__ = [
    "FOLDS",
    "LOCAL_MIN_GAIN",
    "MAX_DELAY_SAMPLES",
    "MIN_GAIN",
    "SCREEN_RATE_HZ",
    "TRIAL_NFEV",
    "Round",
    "candidates",
    "diagnose",
    "diagnose_record",
    "score_round",
]

#: Default least relative cut of the cross-validated RMS error an effect must bring.
MIN_GAIN = 0.10
#: An effect whose evidence is local is also kept when it cuts the cross-validated
#: error by this much where it acts (the LOCAL_SHARE of samples it changes most) and
#: by LOCAL_FLOOR overall.
LOCAL_MIN_GAIN = 0.30
LOCAL_SHARE = 0.1
LOCAL_FLOOR = 0.03
#: Iteration limit of each trial fit (a trial only has to show what the effect explains).
TRIAL_NFEV = 12
#: Tolerance of a trial fit (it stops once an iteration gains less than this share).
TRIAL_TOL = 1e-5
#: Records of more than SCREEN_MIN_SAMPLES samples, sampled faster than
#: SCREEN_RATE_HZ [Hz], are screened on a copy decimated to about that rate; the best
#: screened effects are then confirmed on the full record.
SCREEN_RATE_HZ = 2500.0
SCREEN_MIN_SAMPLES = 50_000
#: Screened effects confirmed on the full record per round, and the iteration limit
#: of a confirmation (it starts from the screened fit) and of the null trial beside it.
CONFIRM = 2
#: A screened effect other than the best is confirmed only if its cross-validated
#: error is within this factor of the best one's.
CONFIRM_RATIO = 1.25
#: A resonance is also tried on the full record when the current residual's spectrum
#: peaks, this many times over its median, above what the screened copy can hold.
PEAK_OVER_MEDIAN = 10.0
CONFIRM_NFEV = 6
#: Iteration limit of the final refit of the kept effects on the whole record.
FINAL_NFEV = 10
#: Two trials of one look-alike group whose credited gains differ by less than this
#: are told apart by the group's test (:mod:`boucwen.diagnosis.lookalike`).
LOOKALIKE_MARGIN = 0.01
#: A fitted resonance of at least this damping has no peak and is not a candidate.
PEAK_ZETA = 1.0 / math.sqrt(2.0)
#: Groups of look-alikes (:data:`~boucwen.diagnosis.lookalike.GROUPS`) whose member
#: already in the model bars another unless the group's test on the current residual
#: names that other: what the first member leaves resembles the others. A test that
#: names none of them bars them only beside creep, which leaves a slow relaxation of
#: its own (its time constants are fixed); a drift or a gain drift, exact forms,
#: leave none that would be mistaken for the other.
FOLLOWS_GUARDED = ("follows",)
#: Effects that leave a residual not consistent with noise are named only when they
#: remove at least this share of the base model's mean-square error beyond the noise
#: (:func:`_explained_share`); otherwise they are a partial fit of something else.
PARTIAL_SHARE = 0.9
#: A trial adding both resonance modes at once starts the second at this multiple of
#: the first's frequency (distinct, so that the two can part).
SECOND_MODE_SPLIT = 1.05
#: ... and its second stage has this many times a trial's evaluations (four unknowns
#: added, the two modes trading places as they part).
PAIR_EFFORT = 5
#: A trial whose second stage ended with less than this share of the RMS error its
#: first stage left, without converging, gets a third stage (:func:`_trial_fit`).
STILL_FALLING = 0.5
#: Look-alikes the backward step may swap for one another (:func:`_look_alike_swap`).
SWAP_FOLLOWS = GROUPS["follows"]
SWAP_PHASE = ("delay", "input_lag")
#: Where no effect earns alone, the effects whose single trials cut the in-sample error
#: most, at most this many, are tried two at a time (:func:`_pair_round`).
PAIR_POOL = 4
#: ... where what the current model leaves is at least this multiple of the noise
#: (RMS): near the noise, one of the many pairs fits its structure by chance.
PAIR_RATIO = 2.0
#: Whole-sample delays whose shifted base fit a delay trial compares, the best by the
#: first-order refit, on a screened record (on one not screened: every delay up to
#: :data:`MAX_DELAY_SAMPLES`, :func:`_delay_starts`).
DELAY_STARTS = 2
#: Iteration limit of the refit of a kept effect from a fresh base model (:func:`_rebased`).
REBASE_NFEV = 20
#: Largest delay tried [samples].
MAX_DELAY_SAMPLES = 8
#: Multiples of the least-squares trend of x on (1, u, t) from which a drift trial's
#: base refit starts (:func:`_drift_start`).
DRIFT_PROFILE = (0.5, 0.8, 1.0, 1.25)


def _solved_at(record: Record, fr: ExtendedFit, jacobian: Any = None) -> Solved:
    """``fr`` with its simulated displacement and Jacobian over ``record`` (a fit made
    elsewhere, or on another copy of the record); ``jacobian``, when given, is that
    Jacobian, already known."""
    xs = simulate_chain(fr.params, fr.effects, record.u, record.dt, fr.h0)
    if xs is None:  # pragma: no cover - a fitted model can be simulated
        raise ValueError("the fitted model cannot be simulated")
    jac = jacobian_extended(record, fr) if jacobian is None else jacobian
    return Solved(fit=fr, x=xs, jacobian=jac)


def _refit_basis(jacobian: Any) -> Any:
    """An orthonormal basis of the span of the current model's Jacobian (its columns
    scaled to unit norm): the first-order refit of the current model's unknowns."""
    norms = np.linalg.norm(jacobian, axis=0)
    keep = norms > 0
    q, _ = np.linalg.qr(jacobian[:, keep] / norms[keep])
    return q


@dataclass(frozen=True, eq=False)
class _Scored:
    fit: ExtendedFit
    cv: CrossValidation
    x: Any
    jacobian: Any


def _scored(record: Record, solved: Solved, folds: int) -> _Scored:
    """A fit over ``record`` and its blocked cross-validation (each block's refit step
    simulated)."""
    fr = solved.fit
    layout = Layout.of(fr.effects, record.dt, record.dt * max(record.u.size - 1, 1))
    z = layout.pack(fr.params, fr.effects, fr.h0)

    def stepped(dz: Any) -> Any:
        xs = layout.simulate(z + dz, record.u, record.dt)
        return None if xs is None else record.x - xs

    cv = blocked_cv(solved.jacobian, record.x - solved.x, folds, simulate=stepped)
    return _Scored(fr, cv, solved.x, solved.jacobian)


def _ranked_starts(
    name: str,
    record: Record,
    current: ExtendedFit,
    basis: Any,
    workers: int | None,
    calls: CloseCalls | None = None,
) -> tuple[list[EffectSet], float]:
    """The starts of a trial adding ``name`` to ``current``, best first: least
    :func:`_cost` beyond the first-order refit of ``basis`` (when given), simulated side
    by side when there is more than one worker; and what the best leaves [µm] (∞ when
    not known: one start, or no basis). Starts whose costs tie with the least within
    :data:`~boucwen.diagnosis.margins.CLOSE_REL` are taken in the order the effect
    lists them (a close call, noted in ``calls``)."""
    starts = candidate_starts(name, record, current.params, current.effects, current.h0, max_delay=MAX_DELAY_SAMPLES)
    if len(starts) <= 1:
        return starts, math.inf
    costs = thread_map(lambda s: _cost(record, current, s, basis), starts, workers)
    best = first_of_best(
        range(len(starts)),
        lambda k: costs[k],
        higher=False,
        margin=CLOSE_REL,
        relative=True,
        decision=f"{name}: best start",
        calls=calls,
        name=lambda k: f"start {k}",
        kind=PATH,
    )
    order = [best] + [int(k) for k in np.argsort(costs, kind="stable") if k != best]
    return [starts[k] for k in order], float(costs[best]) if basis is not None else math.inf


def _trial_fit(
    name: str,
    record: Record,
    current: ExtendedFit,
    null: Callable[[], ExtendedFit],
    ranked: Callable[[str], tuple[list[EffectSet], float]],
    *,
    workers: int | None,
    trial_nfev: int,
    basis: Any = None,
    calls: CloseCalls | None = None,
) -> Solved | str:
    """Adds ``name`` to ``current`` from its best start (``ranked``: the starts of an
    effect best first and what the best leaves, :func:`_ranked_starts`) and refits
    everything, in two stages: a trial no better than the null trial after a third of
    ``trial_nfev`` evaluations is stopped there unless its best start promises a cut
    of at least :data:`LOCAL_FLOOR` beyond the first-order refit of ``basis``, the others
    go on for ``trial_nfev`` more (the second stage restarts the optimiser's trust
    region, which spends evaluations). A trial whose second stage left less than
    :data:`STILL_FALLING` of its first stage's error without converging gets a third,
    where the null trial converged within its effort (else the third stage could be
    credited with convergence the null trial was denied). ``null`` gives the null
    trial's fit (it waits for the null trial when that runs beside this one). Returns the
    fit, or why there is none."""
    pair = _two_modes(name, current)
    starts, predicted = ranked("resonance" if pair else name)
    starts = starts[: _delay_starts(record) if name == "delay" else 1]
    p0, h0, start = current.params, current.h0, starts[0]
    if pair:
        # Two modes where the data hold two peaks close together (or one double peak),
        # which a lone mode cannot fit: the second starts beside the first's best
        # start, and goes on only where it promises more than that start alone.
        mode = start.to_dict()["resonance"]
        start = with_effect(start, Resonance2(fn_hz=SECOND_MODE_SPLIT * mode["fn_hz"], zeta=mode["zeta"]))
        alone, predicted = predicted, _cost(record, current, start, basis)
        if not predicted <= (1.0 - LOCAL_FLOOR) * alone:
            return "hopeless: two modes promise no more than the first alone"
    if name == "delay":
        shift = _delay_shift(record, current, starts, workers=workers, nfev=trial_nfev, calls=calls)
        if isinstance(shift, str):
            return shift
        p0, h0, start = shift
    elif name == "drift":
        p0, h0, start = _drift_start(record, current, start, workers=workers, nfev=trial_nfev, calls=calls)
    elif name == "input_lag" and _screen_factor(record) == 1:
        # Ten refits: on a record not screened, as every whole-sample delay is.
        lag = _lag_start(record, current, ranked(name)[0], workers=workers, nfev=trial_nfev, calls=calls)
        if lag is not None:
            p0, h0, start = lag
    first = _first_stage(trial_nfev)
    try:
        solved = solve_extended_record(record, p0, start, h0, max_nfev=first, tol=TRIAL_TOL)
        fr = solved.fit
        null_rms = null().rms_um

        def goes_on(c: Compare) -> bool:
            # A start whose first-order refit promises a cut goes on: its first steps
            # may still be finding their way (a second mode beside the first).
            if not null_rms > 0:
                return False
            better = c.le(fr.rms_um / null_rms, 1.0, CLOSE_REL)
            return better or c.le(predicted / null_rms, 1.0 - LOCAL_FLOOR, CLOSE_REL)

        if not decide(goes_on, f"{name}: trial goes on after stage 1", calls, yes="goes on", no="stopped", kind=PATH):
            return "hopeless: no better than the null trial after a third of the effort"
        if not fr.success:
            solved = solve_extended_record(
                record,
                fr.params,
                fr.effects,
                fr.h0,
                max_nfev=PAIR_EFFORT * trial_nfev if pair else trial_nfev,
                tol=TRIAL_TOL,
            )
            went = solved.fit
            falling = fr.rms_um > 0 and at_most(
                went.rms_um / fr.rms_um, STILL_FALLING, CLOSE_REL, f"{name}: still falling after stage 2", calls, PATH
            )
            if not went.success and falling and null().success:
                # Still falling fast when its effort ran out: a trial judged there would
                # be credited with where it happened to stop, not with what it explains.
                solved = solve_extended_record(
                    record, went.params, went.effects, went.h0, max_nfev=trial_nfev, tol=TRIAL_TOL
                )
    except ValueError as exc:
        return str(exc)
    fitted: dict[str, Any] = dict(solved.fit.effects.to_dict())
    for got in [fitted.get(k) for k in (("resonance", name) if pair else (name,))]:
        if isinstance(got, dict) and "zeta" in got and got["zeta"] >= PEAK_ZETA:
            # A second-order low-pass (either resonance mode) has a peak only for ζ < 1/√2:
            # without one it is a lag shape the other effects describe; recorded, but not
            # a candidate.
            return f"no resonance peak: fitted zeta {got['zeta']:.3g} ≥ 1/√2"
    return solved


def _delay_starts(record: Record) -> int:
    """How many whole-sample delays a delay trial refits the current model to the record
    shifted by (:func:`_delay_shift`): the :data:`DELAY_STARTS` best by the first-order
    refit on a screened record, every one on a record not screened. That refit ranks the
    delays poorly where the base model has absorbed the delay: under a triangle (|u̇|
    constant, where a delay is an offset the hysteresis takes up, except at the
    reversals) its cost rises from 1 sample on while the delay is 8."""
    return DELAY_STARTS if _screen_factor(record) > 1 else MAX_DELAY_SAMPLES


def _first_stage(trial_nfev: int) -> int:
    """Evaluations of a trial's first stage (:func:`_trial_fit`); the null trial gets
    both stages' (:func:`_null_effort`)."""
    return max(3, trial_nfev // 3)


def _null_effort(trial_nfev: int = TRIAL_NFEV) -> int:
    """Evaluations of the null trial: both stages of a trial of ``trial_nfev``; the
    refits of the backward step and the pairs get the same."""
    return _first_stage(trial_nfev) + trial_nfev


def _refits_beside_null(
    record: Record,
    current: ExtendedFit,
    variants: Sequence[Callable[[Record], Record]],
    *,
    workers: int | None,
    nfev: int,
    calls: CloseCalls | None = None,
    what: str = "",
) -> tuple[list[ExtendedFit], int, bool]:
    """The current model refitted to the record itself (the null, first) and to each
    variant of it (same effort), on the record's screened copy (:func:`_screen_copy`:
    a variant is made of the full record, then decimated as the copy is), side by side
    when there is more than one worker. Returns the refits, the index of the best
    variant's (of variants that tie within the margin, the first listed) and whether it
    beats the null's RMS error by :data:`LOCAL_FLOOR` (close calls noted in ``calls``,
    ``what``: the effect whose trial starts there)."""
    q = _screen_factor(record)

    def refit(variant: Callable[[Record], Record] | None) -> ExtendedFit:
        made = _decimated(variant(record) if variant is not None else record, q)
        return fit_extended_record(made, current.params, current.effects, current.h0, max_nfev=nfev, tol=TRIAL_TOL)

    refits = thread_map(refit, [None, *variants], workers)
    best = 1 + first_of_best(
        refits[1:],
        lambda f: f.rms_um,
        higher=False,
        margin=CLOSE_REL,
        relative=True,
        decision=f"{what}: best refit start",
        calls=calls,
        name=lambda f: what,
        kind=PATH,
    )
    null_rms = refits[0].rms_um
    wins = null_rms > 0 and at_most(
        refits[best].rms_um / null_rms, 1.0 - LOCAL_FLOOR, CLOSE_REL, f"{what}: refit start beats the null", calls, PATH
    )
    return refits, best, wins


def _delay_shift(
    record: Record,
    current: ExtendedFit,
    starts: list[EffectSet],
    *,
    workers: int | None,
    nfev: int,
    calls: CloseCalls | None = None,
) -> tuple[Params, float, EffectSet] | str:
    """The current model refitted to the record shifted by each delay of ``starts`` and,
    as the null, not shifted (:func:`_refits_beside_null`): the base parameters, h0 and
    the start of the best shift, or why the delay is hopeless (no shift beats the
    unshifted fit by :data:`LOCAL_FLOOR`).

    The current fit has bent itself to follow the lag; a delay of d samples is the
    model fitted to the record shifted by d, which starts the delay trial right. A
    screened record is shifted first and then decimated: the refits (of a model
    without the delay, to a record shifted in time by whole samples) are compared on
    its screened copy."""
    delays = [s.to_dict()["delay"]["samples"] for s in starts]
    variants = [lambda r, d=d: r.realigned(d) for d in delays]
    refits, best, wins = _refits_beside_null(
        record, current, variants, workers=workers, nfev=nfev, calls=calls, what="delay"
    )
    if not wins:
        return f"hopeless: the best shift ({delays[best - 1]} samples) fits no better than none"
    return refits[best].params, refits[best].h0, starts[best - 1]


def _lagged(record: Record, fc_hz: float) -> Record:
    """``record`` with its command u passed through an input lag of corner ``fc_hz``
    [Hz] (the core's discretisation: u a straight line between samples, u_a = u[0] at
    the first sample)."""
    a = math.exp(-2.0 * math.pi * fc_hz * record.dt)
    c = 1.0 / (2.0 * math.pi * fc_hz * record.dt)
    b = np.array([1.0 - c * (1.0 - a), c * (1.0 - a) - a])
    den = np.array([1.0, -a])
    ua, _ = lfilter(b, den, record.u, zi=lfilter_zi(b, den) * record.u[0])
    return Record._of_checked(record.t, ua, record.x, record.dt, record.name)


def _lag_start(
    record: Record,
    current: ExtendedFit,
    starts: list[EffectSet],
    *,
    workers: int | None,
    nfev: int,
    calls: CloseCalls | None = None,
) -> tuple[Params, float, EffectSet] | None:
    """Where an input-lag trial starts when its best-ranked start (``starts``, best
    first) is almost no lag (a corner at the sampling rate or above): the current model
    refitted to the record with u lagged at each corner of ``starts`` below the sampling
    rate, beside the null (:func:`_refits_beside_null`); the base parameters, h0 and the
    start of the best, or None when the best start is a real lag or no refit fits better
    by :data:`LOCAL_FLOOR`.

    The current fit has bent its hysteresis to follow the lag (under a triangle a lag
    is an offset on each ramp, which h takes up), and every real corner added to that
    bend misfits before the refit: the first-order ranking then puts no lag first."""
    corners = [s.to_dict()["input_lag"]["fc_hz"] for s in starts]
    real = [k for k, fc in enumerate(corners) if fc < 1.0 / record.dt]
    if not real or real[0] == 0:
        return None
    variants = [lambda r, fc=corners[k]: _lagged(r, fc) for k in real]
    refits, best, wins = _refits_beside_null(
        record, current, variants, workers=workers, nfev=nfev, calls=calls, what="input_lag"
    )
    return (refits[best].params, refits[best].h0, starts[real[best - 1]]) if wins else None


def _drift_start(
    record: Record,
    current: ExtendedFit,
    start: EffectSet,
    *,
    workers: int | None,
    nfev: int,
    calls: CloseCalls | None = None,
) -> tuple[Params, float, EffectSet]:
    """Where a drift trial starts: the current model refitted to the record less a trend
    r·t for each rate r of :data:`DRIFT_PROFILE` × the least-squares trend of x on
    (1, u, t), beside the null (:func:`_refits_beside_null`); the base parameters, h0
    and drift of the best, or the current fit with ``start`` when no trend fits better
    by :data:`LOCAL_FLOOR` (or x has no trend).

    The current fit has bent its hysteresis (kv, x0, h0) to follow a trend in time,
    and a drift started at rate 0 from there stays in that bend; the model refitted to
    the record less a trend starts the trial at the trend."""
    t = np.arange(record.u.size) * record.dt
    design = np.column_stack([np.ones_like(t), record.u, t])
    trend = float(np.linalg.lstsq(design, record.x, rcond=None)[0][2])
    if trend == 0.0 or not math.isfinite(trend):
        return current.params, current.h0, start
    rates = [f * trend for f in DRIFT_PROFILE]
    variants = [lambda r, rate=rate: validate_record(r.u, r.x - rate * t, r.dt) for rate in rates]
    refits, best, wins = _refits_beside_null(
        record, current, variants, workers=workers, nfev=nfev, calls=calls, what="drift"
    )
    if not wins:
        return current.params, current.h0, start
    fitted = refits[best]
    return fitted.params, fitted.h0, with_effect(current.effects, Drift(rate_um_per_s=rates[best - 1]))


def _credit(
    trial: _Scored, reference: _Scored, ref_rms: float, ref_in_sample: float, noise_um: float
) -> dict[str, Any]:
    """What a trial is credited with against the reference (the better of the current
    model and the null trial): overall, per fold and where it acts. ``gain_over_null``
    is the cut of the cross-validated error (against ``ref_rms``), but no more than the
    cut of the in-sample error against ``ref_in_sample`` (the lower of the current
    model's and the null trial's): an effect that fits the record no better than the
    model without it is not credited with refits of the blocks that happen to
    extrapolate better with one more unknown beside them. ``noise_share``: the share of
    the reference's in-sample mean-square error beyond the record's noise ``noise_um``
    [µm] that the trial removes (:func:`_explained_share`)."""
    cv, ref = trial.cv, reference.cv
    acts = np.abs(trial.x - reference.x)
    k = max(1, round(LOCAL_SHARE * acts.size))
    where = np.argpartition(acts, acts.size - k)[acts.size - k :]
    local_ref = rms(ref.residual[where])
    cv_gain = 1.0 - cv.rms_um / ref_rms if ref_rms > 0 else 0.0
    in_sample_gain = 1.0 - cv.in_sample_rms_um / ref_in_sample if ref_in_sample > 0 else 0.0
    return {
        "cv_rms_um": cv.rms_um,
        "in_sample_rms_um": cv.in_sample_rms_um,
        "cv_gain": cv_gain,
        "in_sample_gain": in_sample_gain,
        "gain_over_null": min(cv_gain, in_sample_gain),
        "fold_gains": [1.0 - a / b if b > 0 else 0.0 for a, b in zip(cv.fold_rms_um, ref.fold_rms_um)],
        "local_gain": 1.0 - rms(cv.residual[where]) / local_ref if local_ref > 0 else 0.0,
        "noise_share": _explained_share(ref_in_sample, cv.in_sample_rms_um, noise_um),
    }


def _earns(c: dict[str, Any], min_gain: float, calls: CloseCalls | None = None, what: str = "") -> bool:
    """A credit ``c`` (:func:`_credit`) earns its parameters: a cut of at least
    ``min_gain`` overall, or :data:`LOCAL_MIN_GAIN` where it acts with
    :data:`LOCAL_FLOOR` overall, or :data:`PARTIAL_SHARE` of the error beyond the noise
    with :data:`LOCAL_FLOOR` overall and a gain in every fold. Each comparison with
    the margin of :mod:`~boucwen.diagnosis.margins`: a credit it decides does not earn
    (a close call noted in ``calls`` as ``what``)."""

    def rule(cmp: Compare) -> bool:
        gain = c["gain_over_null"]
        overall = cmp.ge(gain, min_gain)
        local = cmp.ge(c["local_gain"], LOCAL_MIN_GAIN) and cmp.ge(gain, LOCAL_FLOOR)
        folds = cmp.ge(min(c["fold_gains"]), 0.0) and min(c["fold_gains"]) > 0
        to_noise = cmp.ge(c["noise_share"], PARTIAL_SHARE) and cmp.ge(gain, LOCAL_FLOOR) and folds
        return overall or local or to_noise

    return decide(rule, f"{what}: earns its parameters", calls, yes="earns", no="does not earn")


@dataclass(frozen=True, eq=False)
class Round:
    """One round of the search (:func:`score_round`).

    Attributes:
        evidence: the round's JSON evidence: ``current`` and ``null`` (the current model,
            and it refitted with the trials' effort and nothing added: their
            cross-validated errors, ``cv_rms_um`` and ``fold_rms_um``), ``reference_rms_um``
            (the lower of the two, the one each effect is credited against), ``trials``
            (per effect: ``cv_rms_um``, ``gain_over_null``, ``fold_gains``, ``local_gain``,
            ``fitted``, or why it is not a candidate), ``competing`` (the candidates,
            best first, with their scores), ``lookalike`` (the tests of
            :mod:`~boucwen.diagnosis.lookalike` on the current residual and, where
            they decided, ``lookalike_decision``; the effects a look-alike in the model
            bars, ``lookalike_barred``), where no effect earned alone the ``pairs``
            tried (:func:`_pair_round`), ``most_likely`` and ``kept``.
        kept: the fit of the kept effect, or None.
        ranked: the candidates' fits, best first (those that earn their parameters).
        kept_jacobian: ∂x̂/∂z of ``kept`` over the round's record (µm per unit of each
            unknown of its :class:`~boucwen.effects.Layout`), or None.
        null: the null trial, scored over the round's record.
        reference: the better of the current model and the null trial (the one each
            effect is credited against), scored over the round's record.
    """

    evidence: dict[str, Any]
    kept: ExtendedFit | None
    ranked: list[tuple[str, ExtendedFit]]
    kept_jacobian: Any = None
    null: _Scored | None = None
    reference: _Scored | None = None


def candidates(present: Sequence[str]) -> tuple[str, ...]:
    """The effects of the vocabulary a round tries beside those `present`: every one not
    yet in the model (``resonance2`` without ``resonance``: both modes at once, see
    :func:`_trial_fit`)."""
    return tuple(n for n in VOCABULARY if n not in present)


def _two_modes(name: str, current: ExtendedFit) -> bool:
    """The trial of ``name`` adds both resonance modes at once: ``resonance2`` while the
    model has no ``resonance``."""
    return name == "resonance2" and "resonance" not in current.effects.names


def score_round(
    record: Record,
    current: ExtendedFit,
    *,
    names: tuple[str, ...] | None = None,
    folds: int = FOLDS,
    min_gain: float = MIN_GAIN,
    seed: int = 0,
    workers: int | None = None,
    say: Callable[[str], None] | None = None,
    trial_nfev: int = TRIAL_NFEV,
    starts: dict[str, ExtendedFit] | None = None,
    current_jacobian: Any = None,
    calls: CloseCalls | None = None,
) -> Round:
    """Tries every effect of the vocabulary not yet in ``current`` (or those in
    ``names``) on ``record``.

    Each trial adds one effect and refits everything on the whole record (in the two
    stages of :func:`_trial_fit`, or from ``starts`` in one of as many evaluations);
    the *null trial* refits ``current`` with the most a trial gets and nothing added.
    Every model is scored by blocked cross-validation
    (:mod:`~boucwen.diagnosis.validation`), and an effect is credited only with the cut
    of the cross-validated RMS error beyond both the current model and the null trial
    (``gain_over_null``), overall and where it acts (``local_gain``); it earns its
    parameters when the first is at least ``min_gain``, or the second at least
    :data:`LOCAL_MIN_GAIN` with the first at least :data:`LOCAL_FLOOR`, or when it
    removes :data:`PARTIAL_SHARE` of the error beyond the record's noise
    (``noise_share``) with the first at least :data:`LOCAL_FLOOR` and a gain in every
    fold (an effect near the noise cannot cut the RMS error by more). ``starts``
    gives, per effect, a fit to start its trial from instead of its own starts;
    ``current_jacobian``, ∂x̂/∂z of ``current`` over ``record`` when already known
    (:attr:`Round.kept_jacobian` of the round that kept it on the same record).
    ``calls`` records the round's close calls (:mod:`~boucwen.diagnosis.margins`).

    The null trial and the trials are independent (a trial only waits for the null
    trial's error at the end of its first stage): with more than one worker they run
    side by side, as many at a time as ``workers``, each with its own Jacobian threads
    (the simulations release the GIL), each printing its progress line when it ends.
    The result does not depend on their order.
    """
    note = say if say is not None else (lambda _msg: None)
    lock = threading.Lock()

    def tell(message: str) -> None:
        with lock:
            note(message)

    scored_cur = _scored(record, _solved_at(record, current, current_jacobian), folds)
    cur_cv = scored_cur.cv
    basis = _refit_basis(scored_cur.jacobian)
    null_nfev = _null_effort(trial_nfev)
    noise_um = noise_level(record.x).sigma_um

    def null_trial() -> _Scored:
        null = solve_extended_record(record, current.params, current.effects, current.h0, max_nfev=null_nfev)
        scored = _scored(record, null, folds)
        gain = 1.0 - scored.cv.rms_um / cur_cv.rms_um if cur_cv.rms_um > 0 else 0.0
        tell(f"  0 null     : CV RMS {scored.cv.rms_um:.4g} µm (current {cur_cv.rms_um:.4g} µm, gain {gain:+.1%})")
        return scored

    def reference() -> _Scored:
        """The better of the current model and the null trial (waits for the latter);
        the current model where the two tie within the margin."""
        scored_null = null_run.result()
        return scored_null if scored_null.cv.rms_um < (1.0 - CLOSE_REL) * cur_cv.rms_um else scored_cur

    def in_sample_reference() -> float:
        """The lower in-sample RMS error [µm] of the current model and the null trial."""
        return min(cur_cv.in_sample_rms_um, null_run.result().cv.in_sample_rms_um)

    # The starts of each effect, ranked once per round (the two-mode trial ranks the
    # first mode's starts as the lone mode's trial does: whichever comes second waits).
    rank_locks = {name: threading.Lock() for name in VOCABULARY}
    rankings: dict[str, tuple[list[EffectSet], float]] = {}

    def starts_of(name: str) -> tuple[list[EffectSet], float]:
        with rank_locks[name]:
            if name not in rankings:
                rankings[name] = _ranked_starts(name, record, current, basis, workers, calls)
            return rankings[name]

    def trial(name: str) -> _Scored | str:
        t0 = time.perf_counter()
        if starts is not None and name in starts:
            s = starts[name]
            fr: Solved | str = solve_extended_record(
                record, s.params, s.effects, s.h0, max_nfev=null_nfev, tol=TRIAL_TOL
            )
        else:
            fr = _trial_fit(
                name,
                record,
                current,
                lambda: null_run.result().fit,
                starts_of,
                workers=workers,
                trial_nfev=trial_nfev,
                basis=basis,
                calls=calls,
            )
        if isinstance(fr, str):
            tell(f"  - {name:9s}: {fr} ({time.perf_counter() - t0:.1f} s)")
            return fr
        scored = _scored(record, fr, folds)
        ref = reference()
        c = _credit(scored, ref, ref.cv.rms_um, in_sample_reference(), noise_um)
        tell(
            f"  + {name:9s}: CV RMS {scored.cv.rms_um:.4g} µm (over the null {c['gain_over_null']:+.1%}, "
            f"where it acts {c['local_gain']:+.1%}; {time.perf_counter() - t0:.1f} s)"
        )
        return scored

    todo = names if names is not None else candidates(current.effects.names)
    null_run: Future[_Scored]
    with worker_threads(workers) as pool:
        if pool is None:
            null_run = Future()
            null_run.set_result(null_trial())
            outcomes = [trial(name) for name in todo]
        else:
            null_run = pool.submit(null_trial)  # first in the queue: started before any trial waits for it
            outcomes = list(pool.map(trial, todo))
    scored_null = null_run.result()
    null_cv = scored_null.cv
    null_gain = 1.0 - null_cv.rms_um / cur_cv.rms_um if cur_cv.rms_um > 0 else 0.0
    reference_fit = reference()
    ref_rms = reference_fit.cv.rms_um
    trials: dict[str, dict[str, Any]] = {}
    fits: dict[str, _Scored] = {}
    for name, outcome in zip(todo, outcomes):
        if isinstance(outcome, str):
            trials[name] = {"rejected": outcome}
            continue
        fits[name] = outcome
        trials[name] = {
            **_credit(outcome, reference_fit, ref_rms, in_sample_reference(), noise_um),
            "fitted": outcome.fit.effects.to_dict().get(name),
        }
    ranked = sorted(fits, key=lambda k: -trials[k]["gain_over_null"])
    earning = [k for k in ranked if _earns(trials[k], min_gain, calls, k)]
    if earning:
        # Credits that tie within the margin: the effect first in the vocabulary.
        listed = [k for k in VOCABULARY if k in earning]
        top = listed[
            first_of_best(
                listed,
                lambda k: trials[k]["gain_over_null"],
                higher=True,
                margin=CLOSE_GAIN,
                relative=False,
                decision="the effect that explains most",
                calls=calls,
            )
        ]
        earning = [top] + [k for k in earning if k != top]
    lookalike = lookalike_tests(record, reference_fit.x)
    present = set(current.effects.names)
    barred = _barred(lookalike, present)
    refused = {k: why for k, why in barred.items() if k in earning}
    earning = [k for k in earning if k not in barred]
    pair, lone = trials.get("resonance2", {}), trials.get("resonance", {})
    if (
        "resonance" in earning
        and "resonance2" in earning
        and "resonance" not in present
        and not at_most(pair["cv_rms_um"] / lone["cv_rms_um"], 1.0 - min_gain, CLOSE_REL, "two modes beyond one", calls)
    ):
        # Both modes at once earn their two more parameters only beyond the lone mode.
        earning.remove("resonance2")
        refused["resonance2"] = "two modes fit no better than one by the least gain"
    decision = None
    if len(earning) >= 2:
        a, b = earning[0], earning[1]
        close = trials[a]["gain_over_null"] - trials[b]["gain_over_null"] < LOOKALIKE_MARGIN
        for test, members in GROUPS.items():
            if close and a in members and b in members and named(lookalike[test], (a, b)) == b:
                earning[0], earning[1] = b, a
                decision = {"test": test, "between": [a, b], "chose": b}
    best = earning[0] if earning else (ranked[0] if ranked else None)
    keep = bool(earning)
    evidence = {
        "current": cur_cv.to_dict(),
        "null": {**null_cv.to_dict(), "gain": null_gain},
        "reference_rms_um": ref_rms,
        "trials": trials,
        "competing": [
            {"effect": k, "cv_rms_um": trials[k]["cv_rms_um"], "gain_over_null": trials[k]["gain_over_null"]}
            for k in ranked
        ],
        "lookalike": lookalike,
        "lookalike_decision": decision,
        "lookalike_refused": refused,
        "lookalike_barred": sorted(barred),
        "most_likely": best,
        "kept": keep,
    }
    return Round(
        evidence=evidence,
        kept=fits[best].fit if keep and best is not None else None,
        ranked=[(k, fits[k].fit) for k in earning],
        kept_jacobian=fits[best].jacobian if keep and best is not None else None,
        null=scored_null,
        reference=reference_fit,
    )


def _pair_round(
    record: Record,
    current: ExtendedFit,
    round_: Round,
    *,
    noise_um: float,
    folds: int,
    min_gain: float,
    workers: int | None,
    say: Callable[[str], None],
    calls: CloseCalls | None = None,
) -> Round | None:
    """Effects that explain only together, where none earns alone (a gain drift beside
    electrostriction: each alone bends the hysteresis to take the other's share, and
    extrapolates worse than the model without it). The :data:`PAIR_POOL` effects whose
    single trials in ``round_`` cut the in-sample error most are added two at a time,
    each at its single trial's fit, and refitted with the null trial's effort, side by
    side on the ``workers`` threads (an effect a look-alike in the model bars is not
    paired). The pair with the largest credit against the round's reference that earns
    its parameters by the rule of a single effect (:func:`_earns`) and cuts the
    cross-validated error of each of its members' single trials by ``min_gain`` (two
    effects earn their second parameter only beyond either alone) is kept; the backward
    step then asks each to earn its place beside the other (``noise_um``: the record's
    noise [µm], :func:`noise_level`, for the credit's ``noise_share``). Adds the pairs'
    credits to ``round_``'s evidence (``pairs``); returns the round with the pair kept, or
    None when none earns."""
    trials, ref, null = round_.evidence["trials"], round_.reference, round_.null
    if ref is None or null is None:
        return None
    barred = round_.evidence["lookalike_barred"]
    tried = [
        k
        for k, t in trials.items()
        if "fitted" in t and t["in_sample_gain"] > 0 and k != "resonance2" and k not in barred
    ]
    pool = sorted(tried, key=lambda k: -trials[k]["in_sample_gain"])[:PAIR_POOL]
    effort = _null_effort()

    def fitted(pair: tuple[str, str]) -> tuple[_Scored, float] | None:
        """The pair added at its members' single fits, refitted and scored; seconds taken."""
        t0 = time.perf_counter()
        a, b = pair
        both = set_of({**params_of(current.effects), a: trials[a]["fitted"], b: trials[b]["fitted"]})
        try:
            solved = solve_extended_record(record, current.params, both, current.h0, max_nfev=effort, tol=TRIAL_TOL)
        except ValueError:
            return None
        return _scored(record, solved, folds), time.perf_counter() - t0

    pairs = list(itertools.combinations(pool, 2))
    ref_in_sample = min(ref.cv.in_sample_rms_um, null.cv.in_sample_rms_um)
    credits: dict[str, Any] = {}
    earning: list[tuple[str, _Scored]] = []
    for (a, b), outcome in zip(pairs, thread_map(fitted, pairs, workers)):
        if outcome is None:
            continue
        scored, took = outcome
        pair = f"{a}+{b}"
        c = credits[pair] = _credit(scored, ref, ref.cv.rms_um, ref_in_sample, noise_um)
        say(
            f"  + {pair}: CV RMS {scored.cv.rms_um:.4g} µm (over the null {c['gain_over_null']:+.1%}, "
            f"where they act {c['local_gain']:+.1%}; {took:.1f} s)"
        )
        alone = min(trials[a]["cv_rms_um"], trials[b]["cv_rms_um"])
        beyond = alone > 0 and at_most(
            scored.cv.rms_um / alone, 1.0 - min_gain, CLOSE_REL, f"{pair}: beyond either alone", calls
        )
        if beyond and _earns(c, min_gain, calls, pair):
            earning.append((pair, scored))
    round_.evidence["pairs"] = credits
    if not earning:
        return None
    # Pairs whose credits tie within the margin: the one listed first.
    best = earning[
        first_of_best(
            earning,
            lambda e: credits[e[0]]["gain_over_null"],
            higher=True,
            margin=CLOSE_GAIN,
            relative=False,
            decision="the pair that explains most",
            calls=calls,
            name=lambda e: e[0],
        )
    ]
    return Round(
        evidence={**round_.evidence, "most_likely": best[0], "kept": True},
        kept=best[1].fit,
        ranked=[(best[0], best[1].fit)],
        kept_jacobian=best[1].jacobian,
        null=null,
        reference=ref,
    )


def _barred(lookalike: dict[str, Any], present: set[str]) -> dict[str, str]:
    """The effects a look-alike in the model bars (:data:`FOLLOWS_GUARDED`), with why:
    the other members of a guarded group with a member ``present``, but the one the
    group's test (``lookalike``, :func:`lookalike_tests`) names on the current residual.
    A test that names none bars them only beside creep."""
    barred = {}
    for test in FOLLOWS_GUARDED:
        members, said = GROUPS[test], named(lookalike[test])
        if present & set(members) and (said != "none" or "creep" in present):
            for k in members:
                if k != said and k not in present:
                    barred[k] = f"a look-alike is in the model and the {test!r} test names {said!r}"
    return barred


def _delay_hopeless(record: Record, current: Solved, folds: int) -> bool:
    """A delay cannot earn its parameters: adding the model's rate ẋ̂ (the first-order
    change a small delay makes) as one more column of the Jacobian of ``current`` (over
    ``record``) cuts the cross-validated error by less than :data:`LOCAL_FLOOR`."""
    xs = current.x
    cv = blocked_cv(current.jacobian, record.x - xs, folds)
    with_rate = blocked_cv(np.column_stack([current.jacobian, np.gradient(xs)]), record.x - xs, folds)
    return bool(with_rate.rms_um > (1.0 - LOCAL_FLOOR) * cv.rms_um)


def _cost(record: Record, current: ExtendedFit, effects: EffectSet, basis: Any = None) -> float:
    """RMS error [µm] of the current model with ``effects``; with ``basis`` (of
    :func:`_refit_basis`), what is left of it beyond the first-order refit of the
    current model's unknowns (the current fit has bent itself to follow what the
    effect describes; the refit undoes that to first order)."""
    xs = simulate_chain(current.params, effects, record.u, record.dt, current.h0)
    if xs is None:
        return math.inf
    r = record.x - xs
    if basis is not None:
        r = r - basis @ (basis.T @ r)
    return rms(r)


def _rebased(record: Record, kept: ExtendedFit, *, seed: int, workers: int | None, q: int) -> ExtendedFit | None:
    """``kept`` refitted from a fresh base model: the base model fitted from scratch
    (global stage and all) on the record less what the kept effects add to the kept
    base model, then everything refitted from there. A base model fitted without the
    effect may have found a basin where its hysteresis imitates the effect (the rate
    term δ·u·sgn(u̇) integrating into a drift, kv and A cancelling); the trial that
    adds the effect starts in that basin and a few iterations do not leave it. None
    when the fresh start cannot be simulated or fitted."""
    u, dt = record.u, record.dt
    with_effects = simulate_chain(kept.params, kept.effects, u, dt, kept.h0)
    without = simulate_chain(kept.params, EffectSet(), u, dt, kept.h0)
    if with_effects is None or without is None:
        return None
    try:
        plain = validate_record(u, record.x - (with_effects - without), dt)
        base = fit_record(plain, seed=seed, workers=workers, decimate=q if q > 1 else None)
        return fit_extended_record(record, base.params, kept.effects, base.h0, max_nfev=REBASE_NFEV, tol=TRIAL_TOL)
    except ValueError:
        return None


def _partial(before_um: float, after_um: float, left: Unexplained) -> bool:
    """The model with the effects kept leaves a residual ``left`` not consistent with
    noise and removes less than :data:`PARTIAL_SHARE` of the base model's mean-square
    error beyond the noise (RMS errors before and after [µm]); a share within the
    margin of it counts as less (the simpler report: nothing named)."""
    share = _explained_share(before_um, after_um, left.noise_um)
    return not left.consistent_with_noise and not at_least(share, PARTIAL_SHARE, CLOSE_GAIN, "", None)


def _explained_share(before_um: float, after_um: float, noise_um: float) -> float:
    """Share of the base model's mean-square error beyond the noise that the effects
    remove: 1 − (after² − σ²)/(before² − σ²), RMS errors and noise σ in µm (1 when the
    base model already leaves no more than the noise)."""
    excess = before_um**2 - noise_um**2
    if not excess > 0:
        return 1.0
    return 1.0 - max(after_um**2 - noise_um**2, 0.0) / excess


def _backward_step(
    record: Record,
    screen: Record,
    current: ExtendedFit,
    added: list[str],
    evidence: dict[str, Any],
    *,
    null: _Scored | None,
    folds: int,
    min_gain: float,
    workers: int | None,
    say: Callable[[str], None],
    calls: CloseCalls | None = None,
) -> tuple[ExtendedFit, list[str]]:
    """The backward step: each effect kept, in the order kept, is taken out and the
    others refitted with the null trial's effort; an effect that the model with it,
    refitted alike, does not earn against that refit by the rule that kept it
    (:func:`_earns`) was a passenger: a look-alike kept first whose work a later effect
    does, or an effect credited with what the effects kept before it had not yet
    converged to. It is dropped. One that earns its place may still be a look-alike
    of the right effect, kept before its partner was in the model: it is swapped
    where :func:`_look_alike_swap` finds the other. On the screened copy when the
    model can be simulated there (else on the record). The first mode of a resonance
    is not taken out while the second is in. ``null``: the model with them all so
    refitted, on the copy used, when the last round has it. Returns the model and the
    effects left; ``evidence["pruned"]`` gets each credit (and any swap)."""
    simulable = _screenable(current, screen)
    on = screen if simulable else record
    effort = _null_effort()

    def refit(effects: EffectSet) -> _Scored:
        solved = solve_extended_record(on, current.params, effects, current.h0, max_nfev=effort)
        return _scored(on, solved, folds)

    full = null if null is not None and simulable else refit(current.effects)
    noise_um = noise_level(on.x).sigma_um
    credits: dict[str, Any] = {}
    for name in list(added):
        if name == "resonance" and "resonance2" in current.effects.names:
            continue
        rest = refit(without(current.effects, name))
        c = _credit(full, rest, rest.cv.rms_um, rest.cv.in_sample_rms_um, noise_um)
        credits[name] = c
        say(
            f"  backward {name:9s}: over the others refitted without it {c['gain_over_null']:+.1%}, "
            f"where it acts {c['local_gain']:+.1%}"
        )
        if not _earns(c, min_gain, calls, f"backward {name}"):
            say(f"dropped {name}: it does not earn its parameters beside the effects kept after it")
            current, full = rest.fit, rest
            added = [k for k in added if k != name]
            continue
        swap = _look_alike_swap(
            on,
            name,
            rest,
            c,
            phase=on is record,
            every=screen is record,
            min_gain=min_gain,
            folds=folds,
            workers=workers,
            calls=calls,
        )
        if swap is not None:
            other, scored, c_other = swap
            c["swapped_for"] = {other: c_other}
            say(
                f"swapped {name} for {other}, which earns {c_other['gain_over_null']:+.1%} in its place "
                f"({name}: {c['gain_over_null']:+.1%}; the look-alike test names {c_other['test_named']})"
            )
            current, full = scored.fit, scored
            added = [other if k == name else k for k in added]
    evidence["pruned"] = credits
    return current, added


def _look_alike_swap(
    on: Record,
    name: str,
    rest: _Scored,
    credit: dict[str, Any],
    *,
    phase: bool,
    every: bool,
    min_gain: float,
    folds: int,
    workers: int | None,
    calls: CloseCalls | None = None,
) -> tuple[str, _Scored, dict[str, Any]] | None:
    """For a kept creep, drift or gain drift, or a kept delay or input lag (``name``,
    credited with ``credit`` against ``rest``, the others refitted without it): the
    look-alike that the group's test names on the residual of ``rest``
    (:mod:`~boucwen.diagnosis.lookalike`), tried in its place from ``rest`` like a
    trial, with its scored fit and credit, where it earns its parameters and its
    credit is within :data:`LOOKALIKE_MARGIN` of ``name``'s or above (its credit records
    what the test named, ``test_named``); else None. With ``every`` (a record short
    enough not to be screened) each other member of the group is tried too, and one the
    test does not name takes the place only with a credit above ``name``'s; the best
    credit wins. A look-alike kept in an earlier round,
    before the effect it was paired with was in the model, is thus told apart the way a
    round tells two apart. (The resonance modes are not swapped: their peak is its own
    evidence. Delay and input lag only where ``phase``: on the record itself, not on a
    screened copy, where a delay of whole samples is not the record's.)"""
    if name in SWAP_FOLLOWS:
        group, said = SWAP_FOLLOWS, named(what_it_follows(on, rest.x))
    elif name in SWAP_PHASE and phase:
        group, said = SWAP_PHASE, named(phase_shape(on, rest.x), SWAP_PHASE)
    else:
        return None
    others = [k for k in group if k != name and k not in rest.fit.effects.names and (every or k == said)]
    basis = _refit_basis(rest.jacobian) if others else None
    noise_um = noise_level(on.x).sigma_um
    earning: list[tuple[str, _Scored, dict[str, Any]]] = []
    for other in others:
        fr = _trial_fit(
            other,
            on,
            rest.fit,
            lambda: rest.fit,
            lambda n: _ranked_starts(n, on, rest.fit, basis, workers, calls),
            workers=workers,
            trial_nfev=TRIAL_NFEV,
            basis=basis,
            calls=calls,
        )
        if isinstance(fr, str):
            continue
        scored = _scored(on, fr, folds)
        c = _credit(scored, rest, rest.cv.rms_um, rest.cv.in_sample_rms_um, noise_um)
        floor = credit["gain_over_null"] - (LOOKALIKE_MARGIN if other == said else 0.0)
        takes = at_least(c["gain_over_null"], floor, CLOSE_GAIN, f"{other} in place of {name}", calls)
        if _earns(c, min_gain, calls, f"{other} in place of {name}") and takes:
            earning.append((other, scored, {**c, "test_named": said}))
    if not earning:
        return None
    return earning[
        first_of_best(
            earning,
            lambda e: e[2]["gain_over_null"],
            higher=True,
            margin=CLOSE_GAIN,
            relative=False,
            decision=f"the look-alike in place of {name}",
            calls=calls,
            name=lambda e: e[0],
        )
    ]


def _peak_beyond(record: Record, current: ExtendedFit, screen_dt: float) -> bool:
    """The current model's residual has a spectral peak (:data:`PEAK_OVER_MEDIAN`) above
    the highest resonance the screened copy (interval ``screen_dt``) can hold."""
    xs = simulate_chain(current.params, current.effects, record.u, record.dt, current.h0)
    if xs is None:  # pragma: no cover - a fitted model can be simulated
        return False
    peak = residual_evidence_record(record, xs)["resonance"]
    return bool(peak["peak_hz"] > FN_MAX_NYQUIST_FRACTION / screen_dt and peak["peak_over_median"] > PEAK_OVER_MEDIAN)


def _base_fit(base: FitResult) -> ExtendedFit:
    """The base model's fit as an extended fit with no effect."""
    return ExtendedFit(base.params, EffectSet(), base.h0, base.rms_um, base.max_um, base.nfev, base.success)


def _cv_rms(record: Record, fit: ExtendedFit, folds: int) -> float:
    """The blocked cross-validated RMS error [µm] of ``fit`` over ``record``: what it
    predicts of each block when refitted without it (:mod:`~boucwen.diagnosis.validation`)."""
    return _scored(record, _solved_at(record, fit), folds).cv.rms_um


def on_bounds(fit: ExtendedFit, record: Record) -> list[dict[str, Any]]:
    """The unknowns of ``fit`` that ended on a bound of the fit over ``record``
    (within 1e-6 of its size): ``{"parameter", "value", "bound", "side"}`` each."""
    layout = Layout.of(fit.effects, record.dt, record.dt * max(len(record) - 1, 1))
    z = layout.pack(fit.params, fit.effects, fit.h0)
    lo, hi = layout.bounds()
    out = []
    for label, v, a, b in zip(layout.labels(), z, lo, hi):
        for bound, side in ((a, "lower"), (b, "upper")):
            if math.isfinite(bound) and abs(v - bound) <= 1e-6 * max(1.0, abs(bound)):
                out.append({"parameter": label, "value": float(v), "bound": float(bound), "side": side})
    return out


def _screenable(current: ExtendedFit, screen: Record) -> bool:
    """The current model means on the screened copy what it means on the record: it
    simulates there (a resonance above the copy's Nyquist frequency does not), and it
    holds no delay (whole samples of the record, which the copy's samples are not)."""
    if "delay" in current.effects.names:
        return False
    return simulate_chain(current.params, current.effects, screen.u, screen.dt, current.h0) is not None


def _screen_factor(record: Record) -> int:
    """The decimation q of the record's screened copy (1 when it is not screened)."""
    q = max(1, int(1.0 / (record.dt * SCREEN_RATE_HZ)))
    return 1 if len(record) <= SCREEN_MIN_SAMPLES else q


def _screen_copy(record: Record) -> tuple[Record, int]:
    """The record decimated to about :data:`SCREEN_RATE_HZ` (every q-th sample,
    :func:`_screen_factor`), and q (the record itself and 1 when it is not screened)."""
    q = _screen_factor(record)
    return _decimated(record, q), q


def _decimated(record: Record, q: int) -> Record:
    """Every ``q``-th sample of the record, from the first (the record itself for q = 1)."""
    return record if q == 1 else validate_record(record.u[::q], record.x[::q], record.dt * q)


def diagnose(
    u: ArrayLike,
    x: ArrayLike,
    dt: float,
    *,
    progress: Progress = False,
    folds: int = FOLDS,
    min_gain: float = MIN_GAIN,
    max_effects: int = 3,
    seed: int = 0,
    workers: int | None = None,
    validate: tuple[ArrayLike, ArrayLike, float] | None = None,
) -> Diagnosis:
    """Finds which effects of the vocabulary the record holds beyond the base model.

    Args:
        u: voltage [V], 1-D, finite, not constant, uniformly sampled.
        x: measured displacement [µm], same length.
        dt: sampling interval [s] (> 0).
        progress: ``True`` prints progress lines to stderr; or a callable taking a str
            (the trials' lines come from the threads that run them, one at a time).
        folds: contiguous blocks of the cross-validation (2 … 10).
        min_gain: least relative cut of the cross-validated RMS error an effect must
            bring to be kept (0 … 1).
        max_effects: most effects added (0 … 5).
        seed: seed of :func:`boucwen.fit`'s random starts.
        workers: threads for the trials of a round and for each fit's Jacobian
            (default: the number of CPUs; 1 runs everything in turn).
        validate: a second record of the same device, ``(u [V], x [µm], dt [s])``: each
            effect must also predict it better (:mod:`~boucwen.diagnosis.unseen`), and the
            report gives both models' errors on it.

    Returns:
        A :class:`~boucwen.diagnosis.Diagnosis`; the procedure is described in
        :mod:`boucwen.diagnosis`.

    Raises:
        TypeError, ValueError: bad data or options (precise message).
    """
    return diagnose_record(
        validate_record(u, x, dt),
        progress=progress,
        folds=folds,
        min_gain=min_gain,
        max_effects=max_effects,
        seed=seed,
        workers=workers,
        validate=None if validate is None else validate_record(*validate),
    )


def diagnose_record(
    record: Record,
    *,
    progress: Progress = False,
    folds: int = FOLDS,
    min_gain: float = MIN_GAIN,
    max_effects: int = 3,
    seed: int = 0,
    workers: int | None = None,
    validate: Record | None = None,
) -> Diagnosis:
    """:func:`diagnose` on a checked :class:`~boucwen.record.Record` (same options, same
    result; ``validate`` a checked record too)."""
    started = time.perf_counter()
    say = reporter(progress, "diagnose", started)
    folds = check_int("folds", folds, 2, 10)
    min_gain = check_number("min_gain", min_gain, 0.0, 1.0)
    max_effects = check_int("max_effects", max_effects, 0, 5)
    u, x, dt = record.u, record.x, record.dt
    n = u.size
    if n < 100:
        raise ValueError(f"diagnose needs at least 100 samples, got {n}")
    if not np.ptp(u) > 0:
        raise ValueError("u is constant; the diagnosis needs a varying voltage")
    screen, q = _screen_copy(record)
    noise_um = noise_level(x).sigma_um

    say(f"fitting the base model on {n} samples")
    base = fit_record(record, seed=seed, workers=workers, decimate=q if q > 1 else None)
    current = _base_fit(base)
    x_base = base.x_fit
    say(
        f"base model: RMS {base.rms_um:.4g} µm; {folds} folds"
        + (f"; trials screened every {q}th sample" if q > 1 else "")
    )
    evidence: dict[str, Any] = {
        "folds": folds,
        "screen_decimation": q,
        "min_gain": min_gain,
        "local_min_gain": LOCAL_MIN_GAIN,
        "residual": residual_evidence_record(record, x_base),
        "rounds": [],
    }
    evidence["residual"]["delay"] = delay_evidence(record, current, MAX_DELAY_SAMPLES)
    added: list[str] = []
    calls = CloseCalls()
    opts: dict[str, Any] = {
        "folds": folds,
        "min_gain": min_gain,
        "seed": seed,
        "workers": workers,
        "say": say,
        "calls": calls,
    }
    # ∂x̂/∂z of the current model over the full record, once known (a round on the
    # full record that keeps an effect has it).
    current_jac: Any = None
    # What the current model leaves, once an effect is kept.
    left_now: Unexplained | None = None
    last_null: _Scored | None = None

    while len(added) < max_effects:
        if left_now is not None and left_now.consistent_with_noise:
            # What the effects kept leave is noise: nothing is left for another to explain.
            say("the residual is consistent with noise: nothing left to explain")
            evidence["stopped"] = "the residual of the effects kept is consistent with noise"
            break
        say(f"round {len(added) + 1}: trying {list(candidates(current.effects.names))}")
        screened: Round | None = None
        if q == 1 or not _screenable(current, screen):
            # Not screened, or the model holds what the screened copy cannot (a
            # resonance above its Nyquist frequency, a delay): every trial on the full
            # record.
            round_ = score_round(record, current, current_jacobian=current_jac, **opts)
        else:
            names = tuple(k for k in candidates(current.effects.names) if k != "delay")
            screened = score_round(screen, current, names=names, **opts)
            ranked = screened.ranked[:CONFIRM]
            scores = screened.evidence["trials"]
            confirm = {
                k: f for k, f in ranked if scores[k]["cv_rms_um"] <= CONFIRM_RATIO * scores[ranked[0][0]]["cv_rms_um"]
            }
            full_only = [k for k in candidates(current.effects.names) if k not in names]
            if "delay" in full_only:
                solved = _solved_at(record, current, current_jac)
                current_jac = solved.jacobian
                if _delay_hopeless(record, solved, folds):
                    say("  - delay    : hopeless: the model's rate does not explain the residual")
                    full_only.remove("delay")
            if "resonance" in names and _peak_beyond(record, current, screen.dt):
                full_only += ["resonance", "resonance2"]
            todo = tuple(k for k in VOCABULARY if k in confirm or k in full_only)
            say(f"confirming {list(todo)} on the full record")
            round_ = (
                score_round(
                    record,
                    current,
                    names=todo,
                    starts=confirm,
                    trial_nfev=CONFIRM_NFEV,
                    current_jacobian=current_jac,
                    **opts,
                )
                if todo
                else screened
            )
            if todo:
                round_.evidence["screening"] = screened.evidence
        left_rms = round_.evidence["current"]["in_sample_rms_um"]  # over the full record where q == 1
        if round_.kept is None and q == 1 and left_rms >= PAIR_RATIO * noise_um:
            round_ = (
                _pair_round(
                    record,
                    current,
                    round_,
                    noise_um=noise_um,
                    folds=folds,
                    min_gain=min_gain,
                    workers=workers,
                    say=say,
                    calls=calls,
                )
                or round_
            )
        evidence["rounds"].append(round_.evidence)
        if round_.kept is None:
            fresh = None
            if left_now is not None and "rebased" not in evidence and _partial(base.rms_um, current.rms_um, left_now):
                # The effects kept explain too little to be named: refitted once from a
                # fresh base model, the search goes on from there if that fits better.
                fresh = _rebased(record, current, seed=seed, workers=workers, q=q)
                evidence["rebased"] = {"rms_um": current.rms_um, "fresh_rms_um": fresh.rms_um if fresh else None}
                if fresh is not None and not fresh.rms_um < (1.0 - CLOSE_REL) * current.rms_um:
                    fresh = None
            if fresh is None:
                say("nothing left that earns its parameters under cross-validation")
                if round_ is screened or q == 1:
                    # The current model refitted with the null trial's effort, on the copy
                    # the backward step uses.
                    last_null = round_.null
                break
            say(f"refitted from a fresh base model: RMS {current.rms_um:.4g} → {fresh.rms_um:.4g} µm")
            current, current_jac = fresh, None
        else:
            new = [k for k in round_.kept.effects.names if k not in current.effects.names]
            current = round_.kept
            # The kept fit's Jacobian is over the full record unless the screened round is the result.
            current_jac = None if round_ is screened else round_.kept_jacobian
            added += new
            say(f"kept {', '.join(new)}: RMS {current.rms_um:.4g} µm")
        left_now = unexplained(record, current.simulate(u, dt))

    if len(added) >= 2:
        current, added = _backward_step(
            record,
            screen,
            current,
            added,
            evidence,
            null=last_null,
            folds=folds,
            min_gain=min_gain,
            workers=workers,
            say=say,
            calls=calls,
        )
    if validate is not None and added:
        say(f"judging {', '.join(added)} on the validation record ({len(validate)} samples)")

        def refit(effects: EffectSet) -> ExtendedFit:
            return fit_extended_record(
                record, current.params, effects, current.h0, max_nfev=_null_effort(), tol=TRIAL_TOL
            )

        current, added, evidence["validation"] = judged_on(validate, current, added, refit, say)
    if added:
        say("refitting on the whole record")
        ext = fit_extended_record(record, current.params, current.effects, current.h0, max_nfev=FINAL_NFEV)
        x_ext = ext.simulate(u, dt)
        params = ext.to_dict()
        effect_set = ext.effects
    else:
        x_ext = x_base.copy()
        params = {"base": base.params.to_dict(), "h0_um": base.h0}
        effect_set = EffectSet()
    left = unexplained(record, x_ext)
    share = _explained_share(rms(x - x_base), rms(x - x_ext), left.noise_um)
    evidence["explained_share"] = share
    partial = bool(added) and _partial(rms(x - x_base), rms(x - x_ext), left)
    if partial:
        # The effects earned their parameters on unseen data and stay in the model;
        # what they leave is not noise, so they may stand in for something else
        # (their confidence says so, and ``unexplained`` what is left).
        say(f"{', '.join(added)}: {share:.0%} of the error beyond the noise explained; the rest is unexplained")
        evidence["partial"] = {"effects": list(added), "explained_share": share, "rms_um": rms(x - x_ext)}
    base_fit = _base_fit(base)
    final = ext if added else base_fit
    cv_before = _cv_rms(record, base_fit, folds)
    unseen: dict[str, Any] = {
        "folds": folds,
        "cv_rms_before_um": cv_before,
        "cv_rms_after_um": _cv_rms(record, final, folds) if added else cv_before,
    }
    if validate is not None:
        on_val_base, on_val = prediction_error(base_fit, validate), prediction_error(final, validate)
        unseen["validation"] = {
            "samples": len(validate),
            "before": None if on_val_base is None else on_val_base.to_dict(),
            "after": None if on_val is None else on_val.to_dict(),
        }
    evidence["unseen"] = unseen
    params["base_only"] = {"base": base.params.to_dict(), "h0_um": base.h0}
    err_b, err_e = x - x_base, x - x_ext
    say(left.summary())
    evidence["close_calls"] = calls.to_list()
    on_answer = sorted({c["decision"] for c in calls.to_list() if c["kind"] != PATH})
    if on_answer:
        say(f"close call(s) on the answer, decided by the margin rule: {', '.join(on_answer)}")
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
        confidence=confidence(
            added,
            evidence,
            LOOKALIKE_MARGIN,
            explained=share if partial else None,
            earns=lambda trial: _earns(trial, min_gain),
        ),
        at_bounds=on_bounds(final, record),
    )
    say(result.summary())
    return result
