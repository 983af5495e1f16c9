"""How a model is scored: open loop, period by period, beside the simplest baselines.

A model is judged by what it predicts *open loop*. The **period-ahead error** of an
online identifier is measured like this: at the start of every period of the input,
its estimates and its model's state h are frozen, the model is simulated open loop
over that period, and the largest |x − x̂| over the period is recorded. A frequency's
score is that of its last full period (after at least one period of adaptation).

A one-step-ahead prediction (each sample predicted with everything up to the one
before) says little about the model: :func:`one_step_baselines` gives the errors of
two predictors with no model at all, persistence x̂ₖ = xₖ₋₁ and the two-tap
extrapolator x̂ₖ = 2xₖ₋₁ − xₖ₋₂, to print beside it.

:func:`refit_oracle` is the reference for the period-ahead error: at the start of the
scored period, an offline output-error fit (:func:`boucwen.fit`) on the two periods
just before it, simulated open loop over the scored period — what unlimited
computation could do with the same past data.

Units: u [V], x [µm], dt [s], frequencies [Hz]; errors [µm].
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from ._core import Identifier, Params, simulate
from .fit import fit
from .pacing import PacedFeed

Segments = Sequence[tuple[float, int, int]]
"""(frequency [Hz], first sample, stop sample) per constant-frequency part of a record."""

FloatArray = NDArray[np.float64]


def period_samples(f_hz: float, dt: float) -> int:
    """Samples in one period of `f_hz` [Hz] at interval `dt` [s] (at least 1)."""
    return max(1, round(1.0 / (f_hz * dt)))


def scored_period(f_hz: float, lo: int, hi: int, dt: float) -> slice:
    """The samples a frequency is scored on: the last full period of its segment [lo, hi)."""
    return slice(max(lo, hi - period_samples(f_hz, dt)), hi)


def key(f_hz: float) -> str:
    """The results' key of a frequency: "1", "10", "100", "200"."""
    return f"{f_hz:g}"


def period_ahead(
    ident: Identifier,
    u: FloatArray,
    x: FloatArray,
    dt: float,
    segments: Segments,
    on_period: Callable[[float, int, Params, float], None] | None = None,
    trace: FloatArray | None = None,
    feed: PacedFeed | None = None,
) -> tuple[dict[str, float], dict[str, list[float]], FloatArray]:
    """Runs `ident` over the record and scores its model period-ahead.

    At the start k₀ of every whole period (and of every segment) the identifier's
    estimates and state (after sample k₀ − 1) are frozen and its model is simulated open
    loop over the period (``ident.forecast``: from h, with the interval from u[k₀−1] to
    u[k₀] included, and with the effects the identifier identifies, e.g. the default
    method's input lag).

    Args:
        ident: a fresh online identifier (it is pushed every sample of the record).
        u, x: the record [V], [µm].
        dt: sampling interval [s].
        segments: the record's constant-frequency parts.
        on_period: called as ``on_period(f_hz, k0, params, h)`` at every freeze.
        trace: if given (same length as x), filled with the period-ahead predictions:
            on every period, the frozen model's open-loop simulation [µm].
        feed: how the samples are pushed (:class:`boucwen.pacing.PacedFeed`: at the
            record's own sample rate, with a cooperative refine schedule); default
            ``ident.push_many``, as fast as it goes.

    Returns:
        ``(score, per_period, one_step)``: the max error [µm] of each frequency's
        last full period; the max error of every period, in order, per frequency;
        and the identifier's one-step-ahead predictions [µm].
    """
    push_many = ident.push_many if feed is None else (lambda a, b: feed.push_many(ident, a, b))
    one_step = np.empty_like(x)
    per_period: dict[str, list[float]] = {}
    score: dict[str, float] = {}
    done = 0
    for f, lo, hi in segments:
        p = period_samples(f, dt)
        errors: list[float] = []
        starts = list(range(lo, hi, p))
        for k0 in starts:
            k1 = min(hi, k0 + p)
            if k0 > done:
                one_step[done:k0] = push_many(u[done:k0], x[done:k0])
                done = k0
            if on_period is not None:
                on_period(f, k0, ident.params, ident.h)
            x_sim = ident.forecast(u[k0:k1])
            if trace is not None:
                trace[k0:k1] = x_sim
            errors.append(float(np.max(np.abs(x[k0:k1] - x_sim))))
        one_step[done:hi] = push_many(u[done:hi], x[done:hi])
        done = hi
        per_period[key(f)] = errors
        full = [e for k0, e in zip(starts, errors) if k0 + p <= hi]
        score[key(f)] = full[-1] if full else errors[-1]
    return score, per_period, one_step


def fixed_model(
    params: Params, h0: float, u: FloatArray, x: FloatArray, dt: float, segments: Segments
) -> dict[str, float]:
    """Period-ahead score of a model with fixed parameters: its open-loop simulation
    over the whole record (its h at a period start is its own simulated h) [µm]."""
    x_sim, _ = simulate(params, u, dt, h0)
    err = np.abs(x - np.asarray(x_sim))
    return {key(f): float(np.max(err[scored_period(f, lo, hi, dt)])) for f, lo, hi in segments}


def one_step_scores(x: FloatArray, pred: FloatArray, segments: Segments, dt: float) -> dict[str, float]:
    """Max |x − x̂| [µm] of one-step-ahead predictions over each frequency's last full period."""
    err = np.abs(x - pred)
    return {key(f): float(np.max(err[scored_period(f, lo, hi, dt)])) for f, lo, hi in segments}


def one_step_baselines(x: FloatArray, segments: Segments, dt: float) -> dict[str, dict[str, float]]:
    """One-step-ahead errors of two predictors with no model [µm]: ``persistence``
    (x̂ₖ = xₖ₋₁) and ``two_tap`` (x̂ₖ = 2xₖ₋₁ − xₖ₋₂), on each frequency's last full period."""
    persistence = np.concatenate([x[:1], x[:-1]])
    two_tap = np.concatenate([x[:2], 2.0 * x[1:-1] - x[:-2]])
    return {
        "persistence": one_step_scores(x, persistence, segments, dt),
        "two_tap": one_step_scores(x, two_tap, segments, dt),
    }


def refit_oracle(
    u: FloatArray, x: FloatArray, dt: float, segments: Segments, init: Params | None = None, seed: int = 0
) -> dict[str, float]:
    """Period-ahead error of refitting offline on the two periods before the scored one [µm].

    For each frequency, :func:`boucwen.fit` on the two periods just before the last
    full period (starting from `init` when given), then the fitted model simulated
    from its fitted h0 over those two periods and on over the scored one; the score is
    the max error over the scored period (NaN where the record holds less than one
    period before it).
    """
    out: dict[str, float] = {}
    for f, lo, hi in segments:
        p = period_samples(f, dt)
        scored = scored_period(f, lo, hi, dt)
        start = max(0, scored.start - 2 * p)
        past = slice(start, scored.start)
        if scored.start - start < p:
            out[key(f)] = float("nan")  # not a period of past data in the record
            continue
        result = fit(u[past], x[past], dt, init=init, seed=seed)
        x_sim, _ = simulate(result.params, u[start : scored.stop], dt, result.h0)
        out[key(f)] = float(np.max(np.abs(x[scored] - np.asarray(x_sim)[scored.start - start :])))
    return out
