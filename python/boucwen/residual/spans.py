"""Time spans where a residual's energy concentrates, and where they sit
(:func:`residual_spans`); times in s."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import stats

from ..checks import FloatArray
from ..metrics import rms
from ..record import Record

__all__ = ["residual_spans"]


def _steps_and_reversals(u: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Indices of steps of u (one-sample jumps ≥ 5 % of its range) and of its reversals
    (turning points of a zigzag with a 5 % threshold)."""
    span = float(np.ptp(u))
    if not span > 0:
        return np.zeros(0), np.zeros(0)
    du = np.diff(u)
    steps = np.flatnonzero(np.abs(du) >= 0.05 * span) + 1
    thr = 0.05 * span
    turns: list[int] = []
    direction, hi_i, lo_i, ext_i = 0, 0, 0, 0
    for k in range(1, u.size):
        if direction == 0:
            hi_i = k if u[k] > u[hi_i] else hi_i
            lo_i = k if u[k] < u[lo_i] else lo_i
            if u[hi_i] - u[lo_i] >= thr:
                direction = 1 if hi_i > lo_i else -1
                ext_i = hi_i if direction == 1 else lo_i
        elif direction == 1:
            if u[k] > u[ext_i]:
                ext_i = k
            elif u[ext_i] - u[k] >= thr:
                turns.append(ext_i)
                direction, ext_i = -1, k
        elif u[k] < u[ext_i]:
            ext_i = k
        elif u[k] - u[ext_i] >= thr:
            turns.append(ext_i)
            direction, ext_i = 1, k
    return steps.astype(np.float64), np.asarray(turns, dtype=np.float64)


def residual_spans(
    r: FloatArray, record: Record, prediction: FloatArray, sigma: float, alpha: float, max_spans: int = 5
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Time spans where r's energy concentrates, and the windowing used."""
    n, dt = r.size, record.dt
    w = max(8, round(0.025 / dt))
    nw = n // w
    info: dict[str, Any] = {"window_s": w * dt, "threshold_um": 0.0, "energy_share": 0.0, "time_share": 0.0}
    if nw < 4:
        return [], info
    wr = np.sqrt(np.mean(r[: nw * w].reshape(nw, w) ** 2, axis=1))
    noise_thr = sigma * math.sqrt(stats.chi2.isf(alpha / nw, w) / w) if sigma > 0 else 0.0
    thr = max(noise_thr, 2.0 * float(np.median(wr)))
    info["threshold_um"] = thr
    hot = wr > thr
    steps, turns = _steps_and_reversals(record.u)
    ranks = stats.rankdata(prediction) / prediction.size
    total = float(r @ r)
    spans: list[dict[str, Any]] = []
    j = 0
    while j < nw:
        if not hot[j]:
            j += 1
            continue
        k = j
        while k + 1 < nw and (hot[k + 1] or (k + 2 < nw and hot[k + 2])):
            k += 1
        a, b = j * w, (k + 1) * w
        seg = r[a:b]
        rank = float(np.mean(ranks[a:b]))
        where = []
        if a == 0:
            where.append("at the start")
        if steps.size and np.any((steps >= a - w) & (steps <= a + w)):
            where.append("after a step")
        if turns.size and np.any((turns >= a - w) & (turns <= a + w)):
            where.append("after a reversal")
        if rank >= 0.9:
            where.append("top of x̂ range")
        elif rank <= 0.1:
            where.append("bottom of x̂ range")
        spans.append(
            {
                "t_start_s": float(record.t[a]),
                "t_stop_s": float(record.t[min(b, n) - 1]),
                "rms_um": rms(seg),
                "energy_share": float(seg @ seg) / total if total > 0 else 0.0,
                "x_hat_percentile": rank,
                "where": where,
            }
        )
        j = k + 1
    info["energy_share"] = float(sum(s["energy_share"] for s in spans))
    info["time_share"] = float(sum(s["t_stop_s"] - s["t_start_s"] + dt for s in spans) / (n * dt))
    info["count"] = len(spans)
    spans.sort(key=lambda s: -s["energy_share"])
    return spans[:max_spans], info
