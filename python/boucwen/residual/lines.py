"""Spectral lines of a residual against the median of the neighbouring bins, labelled
where the input explains them (:func:`spectral_lines`); frequencies in Hz."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import stats
from scipy.signal import welch

from ..checks import FloatArray

__all__ = ["MAINS_HZ", "MAX_HARMONIC", "spectral_lines"]

#: Mains frequencies looked for [Hz].
MAINS_HZ = (50.0, 60.0)
#: Harmonics of a periodic input up to this number are labelled as such even where the
#: input itself holds no line (the hysteresis makes them); higher ones only where it does.
MAX_HARMONIC = 20


def _welch_dof(segments: int, overlap_corr: float = 0.167) -> float:
    """Equivalent χ² degrees of freedom of a Welch estimate (Hann, 50 % overlap)."""
    k = max(1, segments)
    return 2.0 * k * k / (k + 2.0 * (k - 1) * overlap_corr**2)


def _local_floor(pxx: FloatArray, df: float) -> FloatArray:
    """Median of each bin's neighbours within ±2 Hz (at least ±8 bins), the bin and its
    two neighbours on each side left out (0 where too few neighbours).

    The bins whose whole neighbourhood lies inside the spectrum are taken together
    (one median per row of a sliding window); the few near either end one by one."""
    half = max(8, round(2.0 / df)) if df > 0 else 8
    m = pxx.size
    out = np.zeros_like(pxx)
    inner = np.arange(half, m - half)
    if inner.size:
        win = np.lib.stride_tricks.sliding_window_view(pxx, 2 * half + 1)
        neigh = np.concatenate([win[:, : half - 2], win[:, half + 3 :]], axis=1)
        out[inner] = np.median(neigh, axis=1)
    for i in (i for i in range(m) if i < half or i >= m - half):
        lo, hi = max(0, i - half), min(m, i + half + 1)
        edge = np.concatenate([pxx[lo : max(lo, i - 2)], pxx[min(hi, i + 3) : hi]])
        if edge.size >= 4:
            out[i] = float(np.median(edge))
    return out


def _input_fundamental(u: FloatArray, dt: float) -> tuple[float, float]:
    """(f0 [Hz], share of u's AC power at the harmonics of f0): the input's fundamental.

    f0 is the peak of u's zero-padded periodogram (8×); the share counts the
    periodogram within ±1.5 bins of every k·f0 below Nyquist.
    """
    n = u.size
    uc = u - u.mean()
    if n < 16 or not float(uc @ uc) > 0:
        return 0.0, 0.0
    pad = 8 * n
    spec = np.abs(np.fft.rfft(uc, n=pad)) ** 2
    freqs = np.fft.rfftfreq(pad, dt)
    lowest = 2.0 / (n * dt)
    sel = freqs >= lowest
    if not np.any(sel):
        return 0.0, 0.0
    f0 = float(freqs[sel][int(np.argmax(spec[sel]))])
    power = np.abs(np.fft.rfft(uc)) ** 2
    f = np.fft.rfftfreq(n, dt)
    bin_hz = 1.0 / (n * dt)
    k = np.round(f / f0)
    near = (k >= 1) & (np.abs(f - k * f0) <= 1.5 * bin_hz)
    total = float(power[1:].sum())
    return f0, float(power[near].sum() / total) if total > 0 else 0.0


def _mains_label(freq: float, fs: float, tol: float) -> str:
    """``"mains 50 Hz"``, ``"mains 50 Hz ×3"`` (a harmonic), ``"… (aliased)"``, or ``""``.

    Harmonics up to the 10th below Nyquist, aliases of harmonics up to the 5th above
    it (not when the alias falls within 1 Hz of 0 Hz); a line matches within ``tol``
    or 0.3 % of the mains harmonic (the grid's frequency wanders by about ±0.1 Hz).
    """
    for base in MAINS_HZ:
        for m in range(1, 11):
            true = m * base
            if true <= fs / 2.0:
                seen, aliased = true, False
            elif m <= 5:
                seen, aliased = abs(((true + fs / 2.0) % fs) - fs / 2.0), True
                if seen < 1.0:
                    continue
            else:
                continue
            if abs(freq - seen) <= max(tol, 0.003 * true):
                label = f"mains {base:g} Hz" + (f" ×{m}" if m > 1 else "")
                return label + (" (aliased)" if aliased else "")
    return ""


def spectral_lines(
    r: FloatArray, u: FloatArray, dt: float, alpha: float, max_lines: int = 10
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Significant spectral lines of r, and how the spectrum was taken."""
    n = r.size
    fs = 1.0 / dt
    # About 8 half-overlapping segments, finer than 0.1 Hz only for very long records.
    nper = int(min(n, max(64, min(round(10.0 * fs), (2 * n) // 9))))
    noverlap = nper // 2
    segments = 1 + (n - nper) // (nper - noverlap)
    f, pxx = welch(r - r.mean(), fs=fs, window="hann", nperseg=nper, noverlap=noverlap, detrend="constant")
    df = float(f[1] - f[0]) if f.size > 1 else fs
    nu = _welch_dof(segments)
    med_bias = float(stats.chi2.ppf(0.5, nu) / nu)
    f0, periodic_share = _input_fundamental(u, dt)
    periodic = periodic_share >= 0.9
    info: dict[str, Any] = {
        "resolution_hz": df,
        "segments": segments,
        "dof": nu,
        "input_fundamental_hz": f0,
        "input_periodic_share": periodic_share,
    }
    first = 2  # below 2 bins the window's DC leakage dominates
    tested = max(1, f.size - first)
    _, pu = welch(u - u.mean(), fs=fs, window="hann", nperseg=nper, noverlap=noverlap, detrend="constant")
    floor_r = _local_floor(pxx, df) / med_bias
    floor_u = _local_floor(pu, df) / med_bias
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio_u = np.where(floor_u > 0, pu / floor_u, 0.0)
    input_line = stats.chi2.sf(nu * ratio_u, nu) * tested < alpha
    input_line[:first] = False
    # Candidates: local maxima above a positive floor; their p-values in one call.
    peak = np.zeros(f.size, dtype=bool)
    peak[first:] = floor_r[first:] > 0
    peak[first:] &= pxx[first:] >= pxx[first - 1 : -1]
    peak[first:-1] &= pxx[first:-1] >= pxx[first + 1 :]
    cand = np.flatnonzero(peak)
    ratios = pxx[cand] / floor_r[cand]
    p_values = stats.chi2.sf(nu * ratios, nu)
    out: list[dict[str, Any]] = []
    for i, ratio_i, p_i in zip(cand.tolist(), ratios, p_values):
        floor = float(floor_r[i])
        ratio = float(ratio_i)
        p_adj = min(1.0, float(p_i) * tested)
        if p_adj >= alpha:
            continue
        a, b = max(0, i - 2), min(f.size, i + 3)
        excess = np.clip(pxx[a:b] - floor, 0.0, None)
        power = float(excess.sum() * df)
        freq = float((f[a:b] * excess).sum() / excess.sum()) if excess.sum() > 0 else float(f[i])
        in_input = bool(input_line[i - 1 : i + 2].any())
        label = ""
        if periodic and f0 > 0:
            k = round(freq / f0)
            if k >= 1 and abs(freq - k * f0) <= df and (k <= MAX_HARMONIC or in_input):
                label = f"input harmonic {k}"
        if not label and in_input:
            label = "in the input"
        mains = _mains_label(freq, fs, 1.5 * df)
        if mains:
            label = f"{label}; {mains}" if label else mains
        out.append(
            {
                "freq_hz": freq,
                "amplitude_um": math.sqrt(2.0 * power),
                "over_local_median": ratio,
                "p": p_adj,
                "label": label,
                "from_input": label.startswith(("input harmonic", "in the input")),
            }
        )
    out.sort(key=lambda d: -d["amplitude_um"])
    return out[:max_lines], info
