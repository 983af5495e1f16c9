"""Checkable statistics of the residual of a model, one group per effect of the vocabulary."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..checks import FloatArray, as_float_vector
from ..effects import Delay, ExtendedFit, best_delay
from ..metrics import rms, spectrum
from ..record import Record, validate_record
from .unexplained import noise_level

__all__ = ["delay_evidence", "fit_evidence", "residual_evidence", "residual_evidence_record", "spectral_peak"]


def _holds(u: FloatArray, dt: float, min_s: float = 0.05) -> list[tuple[int, int]]:
    """Index ranges [start, stop) where u stays constant for at least ``min_s`` [s]."""
    tol = 1e-6 * max(float(np.ptp(u)), 1e-12)
    still = np.abs(np.diff(u)) <= tol
    out = []
    k = 0
    n = still.size
    min_len = max(5, round(min_s / dt))
    while k < n:
        if still[k]:
            j = k
            while j < n and still[j]:
                j += 1
            if j - k + 1 >= min_len:
                out.append((k, j + 1))
            k = j
        else:
            k += 1
    return out


def _band_ratios(r: FloatArray, xm: FloatArray, dt: float) -> list[list[float]]:
    """Per octave band: [f_lo, f_hi, rms(residual)/rms(model)] from the FFT."""
    n = r.size
    freqs = np.fft.rfftfreq(n, dt)
    r_amp = np.abs(np.fft.rfft(r - r.mean()))
    x_amp = np.abs(np.fft.rfft(xm - xm.mean()))
    f_lo = 4.0 / (n * dt)
    out = []
    while f_lo < 0.5 / dt:
        f_hi = min(2.0 * f_lo, 0.5 / dt)
        sel = (freqs >= f_lo) & (freqs < f_hi)
        x_pow = float(np.sum(x_amp[sel] ** 2))
        if x_pow > 1e-12 * float(np.sum(x_amp**2)):
            out.append([f_lo, f_hi, float(math.sqrt(np.sum(r_amp[sel] ** 2) / x_pow))])
        f_lo = f_hi
    return out


def residual_evidence(u: ArrayLike, x: ArrayLike, x_model: ArrayLike, dt: float) -> dict[str, Any]:
    """Checkable statistics of the residual r = x − x_model [µm], one group per effect.

    * ``noise_um``: white-noise level from first differences (robust).
    * ``creep``: over the holds of u (u constant for ≥ 50 ms): their number, the RMS
      change of r from the start to the end of a hold [µm] and the correlation of that
      change with the change of u just before the hold (creep follows the step).
    * ``input_lag``: ``lag_s`` from the regression r ≈ −τ·ẋ_model (a lag τ [s] of the
      response), its correlation, and ``band_ratio`` = [f_lo, f_hi, rms r / rms
      x_model] per octave band (a lag makes the ratio grow ∝ f).
    * ``resonance``: frequency [Hz] of the largest peak of the residual spectrum above
      the lowest bands and its height over the spectrum's median.
    * ``drift``: slope [µm/s] of r against time and the share of r's variance it explains.

    Args:
        u: voltage [V]; x: measured displacement [µm]; x_model: the model's
            displacement [µm]; all 1-D, finite, of one length.
        dt: sampling interval [s].

    Raises:
        TypeError, ValueError: bad data (precise message).
    """
    record = validate_record(u, x, dt)
    xm = as_float_vector(x_model, "x_model")
    if xm.size != len(record):
        raise ValueError(f"x_model has {xm.size} samples but u and x have {len(record)}")
    return residual_evidence_record(record, xm)


def residual_evidence_record(record: Record, x_model: FloatArray) -> dict[str, Any]:
    """:func:`residual_evidence` on a checked record and a model output of its length."""
    u, x, dt = record.u, record.x, record.dt
    xm = x_model
    r = x - xm
    n = r.size
    t = np.arange(n) * dt
    # The record's noise as the decisions take it (one estimate, reported and used).
    ev: dict[str, Any] = {"rms_um": rms(r), "noise_um": noise_level(x).sigma_um}

    holds = _holds(u, dt)
    changes, steps = [], []
    for a, b in holds:
        w = max(2, min(10, (b - a) // 5))
        skip = min((b - a) // 4, max(2, int(0.005 / dt)))
        changes.append(float(np.mean(r[b - w : b]) - np.mean(r[a + skip : a + skip + w])))
        back = max(0, a - max(1, int(0.1 / dt)))
        steps.append(float(u[a] - u[back]))
    corr = (
        float(np.corrcoef(changes, steps)[0, 1])
        if len(changes) >= 3 and np.std(steps) > 0 and np.std(changes) > 0
        else 0.0
    )
    ev["creep"] = {
        "holds": len(holds),
        "hold_change_rms_um": rms(changes),
        "corr_with_step": corr,
    }

    xdot = np.gradient(xm, dt)
    denom = float(xdot @ xdot)
    tau = float(-(r - r.mean()) @ xdot / denom) if denom > 0 else 0.0
    c = float(np.corrcoef(r, xdot)[0, 1]) if np.std(r) > 0 and np.std(xdot) > 0 else 0.0
    ev["input_lag"] = {"lag_s": tau, "corr_with_rate": -c, "band_ratio": _band_ratios(r, xm, dt)}

    ev["resonance"] = spectral_peak(r, dt)

    basis = np.column_stack([t, np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(basis, r, rcond=None)
    var = float(np.var(r))
    explained = float(np.var(basis @ coef) / var) if var > 0 else 0.0
    ev["drift"] = {"slope_um_per_s": float(coef[0]), "variance_share": explained}
    return ev


def spectral_peak(r: FloatArray, dt: float) -> dict[str, float]:
    """The largest peak of the residual ``r``'s spectrum [µm] above 2 % of the sampling
    rate (1/``dt`` [s]) and four bins: ``{"peak_hz", "peak_over_median"}`` (its power over
    the median of those bins; zeros where there is none)."""
    try:
        f, pxx = spectrum(r, dt)
    except ValueError:  # pragma: no cover - record shorter than a segment
        return {"peak_hz": 0.0, "peak_over_median": 0.0}
    sel = f > max(4.0 * f[1] if f.size > 1 else 0.0, 0.02 / dt)
    if np.any(sel) and np.median(pxx[sel]) > 0:
        k = int(np.argmax(pxx[sel]))
        return {"peak_hz": float(f[sel][k]), "peak_over_median": float(pxx[sel][k] / np.median(pxx[sel]))}
    return {"peak_hz": 0.0, "peak_over_median": 0.0}


def fit_evidence(record: Record, fitted: ExtendedFit, x_model: FloatArray, max_samples: int) -> dict[str, Any]:
    """:func:`residual_evidence_record` of the fit ``fitted`` (prediction ``x_model``
    [µm]), with the whole-sample shift that best aligns it with x
    (:func:`delay_evidence`, up to ``max_samples``)."""
    ev = residual_evidence_record(record, x_model)
    ev[Delay.name] = delay_evidence(record, fitted, max_samples)
    return ev


def delay_evidence(record: Record, fitted: ExtendedFit, max_samples: int) -> dict[str, Any]:
    """``delay``: the whole-sample shift d ≥ 0 (up to ``max_samples``) of the fitted model
    that best aligns it with x, and the RMS error [µm] per shift."""
    d, by_shift = best_delay(record, fitted.params, fitted.effects, fitted.h0, max_samples)
    return {"best_shift_samples": d, "rms_by_shift_um": {str(k): v for k, v in by_shift.items()}}
