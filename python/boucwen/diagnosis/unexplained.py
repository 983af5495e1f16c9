"""What a model leaves unexplained: its residual tested against the noise and against
what could explain it.

:func:`unexplained` takes a record and a model's prediction x̂ [µm] of it and looks at
the residual r = x − x̂:

* **noise level** σ̂ [µm], estimated from the record itself (not from the residual):
  see :func:`noise_level`;
* **verdict**: is r consistent with white noise of level σ̂? Any fitted model leaves
  some structure (a record of thousands of samples reveals a misfit far below the
  noise), so the question asked is whether the structure beyond the noise is larger
  than ``tolerance`` × σ̂ in RMS (0.3 by default). Two one-sided tests, combined
  (Bonferroni, twice the smaller p-value): the variance of r against
  (1 + tolerance²)·σ̂² (F-test, σ̂² counted with the equivalent degrees of freedom of
  its estimator) and whiteness — the largest |autocorrelation| of r at lags 1…4
  against tolerance²/(1 + tolerance²), the autocorrelation structure of that share
  would give (normal approximation, sd 1/√N, union bound over the lags); this one does
  not depend on σ̂. ``consistent_with_noise`` is ``p_value ≥ alpha``. A Ljung–Box test
  without tolerance is reported beside it;
* **signals**: regression of r on each candidate signal (u, u̇, u², x̂, |u̇|, t), each
  after removing its mean; R² and the F-test p-value of each. u² is taken beyond u
  (its part orthogonal to 1 and u), since the base model already fits any straight
  line in u;
* **lines**: peaks of r's Welch spectrum over the whole band against the median of
  the neighbouring bins, with a χ² p-value (Bonferroni over the bins). Lines the
  input explains are labelled and not counted as unexplained: harmonics of the
  input's fundamental when the input is periodic (up to the 20th, or any where the
  input itself has a line), ``input harmonic k``, and lines the input's own spectrum
  holds, ``in the input``. Lines at mains frequencies (50, 60 Hz and harmonics, also
  when aliased) are labelled ``mains``;
* **spans**: time spans where r's energy concentrates (windowed RMS above both the
  level white noise of σ̂ reaches by chance and twice the median windowed RMS), with
  where they sit: after a step or a reversal of u, at the top or bottom of x̂'s range.

All levels in µm, times in s, frequencies in Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats
from scipy.signal import welch

from ..checks import FloatArray, as_float_vector, check_number
from ..metrics import rms
from ..record import Record

__all__ = ["ALPHA", "MAINS_HZ", "TOLERANCE", "NoiseLevel", "Unexplained", "noise_level", "unexplained"]

#: Default significance level of every test here.
ALPHA = 0.01
#: Mains frequencies looked for [Hz].
MAINS_HZ = (50.0, 60.0)
#: Structure in the residual up to this RMS, as a multiple of the noise level, still
#: counts as consistent with noise (0.3 adds 4.4 % to the RMS of the noise alone).
TOLERANCE = 0.3
#: Lags of the whiteness test of the verdict.
WHITENESS_LAGS = 4
#: Least share of the residual's variance a signal must explain to be named.
MIN_R2 = 0.05
#: Harmonics of a periodic input up to this number are labelled as such even where the
#: input itself holds no line (the hysteresis makes them); higher ones only where it does.
MAX_HARMONIC = 20
#: The spans are named in the summary when they hold at least this share of the
#: residual's energy and SPAN_CONCENTRATION times their share of the time.
MIN_SPAN_SHARE = 0.1
SPAN_CONCENTRATION = 3.0
#: Highest order of the difference operator used by :func:`noise_level`.
MAX_DIFF_ORDER = 4
#: Asymptotic efficiency of the MAD scale estimator against the standard deviation
#: for Gaussian data (its variance is 1/0.368 times larger).
_MAD_EFFICIENCY = 0.3675


@dataclass(frozen=True)
class NoiseLevel:
    """The noise level of a record and how it was obtained.

    Attributes:
        sigma_um: standard deviation of the white measurement noise [µm].
        order: order k of the difference operator that gave it (0: quantisation floor).
        dof: equivalent degrees of freedom of σ̂² (its variance is 2σ⁴/dof).
        estimator: one sentence naming the estimator.
    """

    sigma_um: float
    order: int
    dof: float
    estimator: str


def _binomial_filter(k: int) -> FloatArray:
    """Coefficients of the k-th difference operator (−1)^j·C(k, j)."""
    return np.array([(-1.0) ** j * math.comb(k, j) for j in range(k + 1)])


def noise_level(x: FloatArray) -> NoiseLevel:
    """White measurement-noise level of a displacement record, from x alone.

    Estimator: for k = 1 … 4, the k-th difference Δᵏx of the samples is taken and
    its spread measured by the median absolute deviation (MAD) scaled to a standard
    deviation (×1.4826) and divided by √C(2k, k), the gain of Δᵏ on white noise; σ̂ is
    the smallest of the four.

    Assumptions: the noise is white (independent samples) and Gaussian-like; the
    displacement itself is smooth on the scale of a few samples, so that Δᵏ removes
    it (Δᵏ annihilates polynomials of degree < k; a sine of frequency f is scaled by
    (2·sin(π·f·dt))ᵏ), except at a minority of samples (steps, fast bursts) which the
    median ignores. The smallest of the four is the one least inflated by the
    signal; taking the minimum biases σ̂ low by about its own scatter (≈ 1.2/√N).
    A record whose differences are mostly zero (coarse quantisation) gets the
    quantisation floor q/√12, q the smallest non-zero |Δx| (``order`` 0).
    """
    n = x.size
    best = NoiseLevel(math.inf, 1, 1.0, "")
    for k in range(1, MAX_DIFF_ORDER + 1):
        if n - k < 8:
            break
        d = np.diff(x, k)
        mad = float(np.median(np.abs(d - np.median(d))))
        sigma = 1.4826 * mad / math.sqrt(math.comb(2 * k, k))
        if sigma < best.sigma_um:
            c = _binomial_filter(k)
            acf = np.correlate(c, c, mode="full")[k:] / float(c @ c)
            inflation = 1.0 + 2.0 * float(np.sum(acf[1:] ** 2))
            dof = max(1.0, _MAD_EFFICIENCY * (n - k) / inflation)
            best = NoiseLevel(
                sigma,
                k,
                dof,
                f"MAD of the order-{k} differences of x, scaled by 1.4826/√C({2 * k},{k}) "
                f"(smallest over orders 1…{MAX_DIFF_ORDER})",
            )
    if not best.sigma_um > 0:
        steps = np.abs(np.diff(x))
        steps = steps[steps > 0]
        q = float(steps.min()) if steps.size else 0.0
        best = NoiseLevel(
            q / math.sqrt(12.0), 0, max(1.0, float(steps.size)), "quantisation floor q/√12 (differences mostly zero)"
        )
    return best


def _autocorrelation(r: FloatArray, lags: int) -> FloatArray:
    """Sample autocorrelations ρ_1 … ρ_lags of ``r`` (zeros for a constant r)."""
    n = r.size
    c = r - r.mean()
    denom = float(c @ c)
    lags = max(0, min(lags, n - 1))
    if denom <= 0:
        return np.zeros(lags)
    return np.array([float(c[: n - j] @ c[j:]) / denom for j in range(1, lags + 1)])


def _ljung_box(r: FloatArray, lags: int) -> tuple[float, float]:
    """Ljung–Box statistic Q of ``r`` over ``lags`` lags and its χ² p-value."""
    n = r.size
    acf = _autocorrelation(r, lags)
    if acf.size == 0 or not np.any(acf):
        return 0.0, 1.0
    q = float(n * (n + 2) * np.sum(acf**2 / (n - np.arange(1, acf.size + 1))))
    return q, float(stats.chi2.sf(q, acf.size))


def _signals(record: Record, prediction: FloatArray) -> dict[str, FloatArray]:
    """Candidate signals a residual may follow, by name."""
    u, dt = record.u, record.dt
    udot = np.gradient(u, dt) if u.size > 1 else np.zeros_like(u)
    basis = np.column_stack([np.ones_like(u), u])
    coef, *_ = np.linalg.lstsq(basis, u**2, rcond=None)
    return {
        "u": u,
        "u_dot": udot,
        "u^2": u**2 - basis @ coef,
        "x_hat": prediction,
        "|u_dot|": np.abs(udot),
        "t": np.arange(u.size) * dt,
    }


def _regressions(r: FloatArray, signals: dict[str, FloatArray]) -> list[dict[str, Any]]:
    """R² and F-test p-value of r on each signal alone (both without their means)."""
    n = r.size
    rc = r - r.mean()
    rr = float(rc @ rc)
    out: list[dict[str, Any]] = []
    for name, s in signals.items():
        sc = s - s.mean()
        ss = float(sc @ sc)
        if ss <= 1e-24 * max(1.0, float(s @ s)) or rr <= 0 or n < 3:
            out.append({"signal": name, "r2": 0.0, "p": 1.0, "slope": 0.0})
            continue
        r2 = min(1.0, float(sc @ rc) ** 2 / (ss * rr))
        f_stat = r2 * (n - 2) / max(1.0 - r2, 1e-300)
        out.append({"signal": name, "r2": r2, "p": float(stats.f.sf(f_stat, 1, n - 2)), "slope": float(sc @ rc) / ss})
    out.sort(key=lambda d: -d["r2"])
    return out


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


def _lines(
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


def _spans(
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


def _line_words(lines: list[dict[str, Any]]) -> str:
    """``"line at 50 Hz (mains 50 Hz)"`` / ``"lines at …"`` for up to three lines."""
    words = ", ".join(f"{ln['freq_hz']:.3g} Hz" + (f" ({ln['label']})" if ln["label"] else "") for ln in lines[:3])
    return ("line at " if len(lines) == 1 else "lines at ") + words


def _fmt_p(p: float) -> str:
    return "p < 1e-6" if p < 1e-6 else f"p = {p:.2g}"


@dataclass(frozen=True)
class Unexplained:
    """What a model leaves unexplained in a record (:func:`unexplained`).

    Attributes:
        rms_um: RMS of the residual r = x − x̂ [µm].
        noise_um: noise level σ̂ estimated from x [µm]; ``noise_estimator`` says how.
        ratio_to_noise: rms_um / noise_um.
        consistent_with_noise: the residual passes both tests at level ``alpha``.
        p_value: combined p-value (twice the smaller of the two tests', at most 1).
        tests: ``{"variance": {...}, "whiteness": {...}}`` with each test's statistic,
            degrees of freedom and p-value.
        signals: per candidate signal ``{"signal", "r2", "p", "slope"}``, largest R² first.
        correlates_with: signals with R² ≥ 5 % and p < alpha / (number of signals).
        lines: significant spectral lines ``{"freq_hz", "amplitude_um", "over_local_median",
            "p", "label", "from_input"}``, largest first; ``from_input`` marks harmonics of
            the input's fundamental and lines the input itself holds.
        spans: time spans where the residual concentrates ``{"t_start_s", "t_stop_s",
            "rms_um", "energy_share", "x_hat_percentile", "where"}``, most energy first.
        spectrum, windows: how the spectrum and the windowed RMS were taken.
        alpha: significance level used.
    """

    rms_um: float
    noise_um: float
    noise_estimator: str
    ratio_to_noise: float
    consistent_with_noise: bool
    p_value: float
    tests: dict[str, Any] = field(default_factory=dict)
    signals: list[dict[str, Any]] = field(default_factory=list)
    correlates_with: list[str] = field(default_factory=list)
    lines: list[dict[str, Any]] = field(default_factory=list)
    spans: list[dict[str, Any]] = field(default_factory=list)
    spectrum: dict[str, Any] = field(default_factory=dict)
    windows: dict[str, Any] = field(default_factory=dict)
    alpha: float = ALPHA

    @property
    def unexplained_lines(self) -> list[dict[str, Any]]:
        """The lines that are not harmonics of the input."""
        return [ln for ln in self.lines if not ln["from_input"]]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (plus ``summary``)."""
        return {
            "rms_um": self.rms_um,
            "noise_um": self.noise_um,
            "noise_estimator": self.noise_estimator,
            "ratio_to_noise": self.ratio_to_noise,
            "consistent_with_noise": self.consistent_with_noise,
            "p_value": self.p_value,
            "alpha": self.alpha,
            "tests": self.tests,
            "signals": self.signals,
            "correlates_with": list(self.correlates_with),
            "lines": self.lines,
            "spans": self.spans,
            "spectrum": self.spectrum,
            "windows": self.windows,
            "summary": self.summary(),
        }

    def summary(self) -> str:
        """One line: size against the noise, the verdict and what the residual follows."""
        head = f"residual: {self.rms_um:.3g} µm RMS = {self.ratio_to_noise:.3g}× the noise ({self.noise_um:.2g} µm); "
        if self.consistent_with_noise:
            head += f"consistent with noise ({_fmt_p(self.p_value)})"
            lines = self.unexplained_lines
            if lines:
                tol = self.tests.get("tolerance", TOLERANCE)
                head += f"; below {tol:g}× the noise: " + _line_words(lines)
            return head
        parts = []
        r2 = {s["signal"]: s["r2"] for s in self.signals}
        names = {"u^2": "u²", "u_dot": "u̇", "|u_dot|": "|u̇|", "x_hat": "x̂"}
        if self.correlates_with:
            parts.append(
                "correlates with " + ", ".join(f"{names.get(s, s)} (R² {r2[s]:.2g})" for s in self.correlates_with[:3])
            )
        lines = self.unexplained_lines
        if lines:
            parts.append(_line_words(lines))
        white = self.tests.get("whiteness", {})
        if not parts and white.get("p", 1.0) < self.alpha:
            parts.append(f"correlated from sample to sample (|ρ| up to {white.get('max_abs_rho', 0.0):.2g})")
        share = self.windows.get("energy_share", 0.0)
        time_share = self.windows.get("time_share", 0.0)
        if self.spans and share >= MIN_SPAN_SHARE and share >= SPAN_CONCENTRATION * time_share:
            weight: dict[str, float] = {}
            for span in self.spans:
                for tag in span["where"]:
                    weight[tag] = weight.get(tag, 0.0) + span["energy_share"]
            listed = sum(span["energy_share"] for span in self.spans)
            # Where most of the listed spans' energy sits (tags of at least a third of it).
            where = [tag for tag in sorted(weight, key=lambda k: -weight[k]) if weight[tag] >= listed / 3.0]
            parts.append(
                f"{share:.0%} of its energy in {self.windows.get('count', len(self.spans))} span(s) "
                f"({time_share:.0%} of the time)" + (f", {', '.join(where)}" if where else "")
            )
        tail = "; ".join(parts) if parts else "no candidate signal, line or span accounts for it"
        return head + f"not consistent with noise ({_fmt_p(self.p_value)}): " + tail


def unexplained(
    record: Record,
    prediction: Any,
    *,
    alpha: float = ALPHA,
    tolerance: float = TOLERANCE,
    lags: int | None = None,
) -> Unexplained:
    """Tests the residual of ``prediction`` on ``record`` against the noise and against
    what could explain it (see the module docs).

    Args:
        record: the measured record (u [V], x [µm], dt [s]).
        prediction: the model's displacement x̂ [µm], one value per sample.
        alpha: significance level of every test (0 … 0.5).
        tolerance: RMS of structure, as a multiple of σ̂, that still counts as
            consistent with noise (0 … 1).
        lags: lags of the Ljung–Box statistic reported beside the verdict (default
            min(20, N/10)).

    Returns:
        An :class:`Unexplained`.

    Raises:
        TypeError, ValueError: a prediction of the wrong length or not finite, bad alpha.
    """
    alpha = check_number("alpha", alpha, 1e-12, 0.5)
    tolerance = check_number("tolerance", tolerance, 0.0, 1.0)
    xm = as_float_vector(prediction, "prediction")
    if xm.size != len(record):
        raise ValueError(f"prediction has {xm.size} samples but the record has {len(record)}")
    x = record.x
    r = x - xm
    n = r.size
    noise = noise_level(x)
    sigma = noise.sigma_um
    r_rms = rms(r)
    var_r = float(np.var(r, ddof=1)) if n > 1 else 0.0
    ratio_var = var_r / sigma**2 if sigma > 0 else math.inf
    share = tolerance**2 / (1.0 + tolerance**2)
    p_var = (
        float(stats.f.sf(ratio_var / (1.0 + tolerance**2), max(1, n - 1), noise.dof))
        if math.isfinite(ratio_var)
        else 0.0
    )
    acf = _autocorrelation(r, WHITENESS_LAGS)
    rho = float(np.max(np.abs(acf))) if acf.size else 0.0
    p_white = min(1.0, acf.size * float(stats.norm.sf((rho - share) * math.sqrt(n)))) if acf.size else 1.0
    m = int(lags) if lags is not None else int(min(20, max(1, n // 10)))
    q, p_lb = _ljung_box(r, m)
    p = min(1.0, 2.0 * min(p_var, p_white))
    tests = {
        "tolerance": tolerance,
        "variance": {
            "ratio": ratio_var,
            "dof": [n - 1, noise.dof],
            "p": p_var,
            "test": "one-sided F-test of var(r) against (1 + tolerance²)·σ̂²",
        },
        "whiteness": {
            "max_abs_rho": rho,
            "lags": int(acf.size),
            "p": p_white,
            "test": "largest |autocorrelation| at lags 1…4 against tolerance²/(1 + tolerance²), "
            "normal approximation, union bound over the lags",
        },
        "ljung_box": {
            "q": q,
            "lags": m,
            "p": p_lb,
            "test": "Ljung–Box without tolerance (any structure, however small; not part of the verdict)",
        },
    }
    signals = _regressions(r, _signals(record, xm))
    cut = alpha / max(1, len(signals))
    correlates = [s["signal"] for s in signals if s["r2"] >= MIN_R2 and s["p"] < cut]
    lines, spectrum = _lines(r, record.u, record.dt, alpha)
    spans, windows = _spans(r, record, xm, sigma, alpha)
    return Unexplained(
        rms_um=r_rms,
        noise_um=sigma,
        noise_estimator=noise.estimator,
        ratio_to_noise=r_rms / sigma if sigma > 0 else math.inf,
        consistent_with_noise=bool(p >= alpha),
        p_value=p,
        tests=tests,
        signals=signals,
        correlates_with=correlates,
        lines=lines,
        spans=spans,
        spectrum=spectrum,
        windows=windows,
        alpha=alpha,
    )
