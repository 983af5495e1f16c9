"""What a model leaves unexplained: its residual tested against the noise and against
what could explain it.

:func:`unexplained` takes a record and a model's prediction x̂ [µm] of it and looks at
the residual r = x − x̂:

* **noise level** σ̂ [µm], estimated from the record itself (not from the residual):
  see :func:`~boucwen.residual.noise.noise_level`;
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

from ..checks import FloatArray, as_float_vector, check_number
from ..metrics import rms
from ..record import Record
from .lines import MAINS_HZ, spectral_lines
from .noise import NoiseLevel, noise_level
from .spans import residual_spans

__all__ = ["ALPHA", "MAINS_HZ", "TOLERANCE", "NoiseLevel", "Unexplained", "noise_level", "unexplained"]

#: Default significance level of every test here.
ALPHA = 0.01
#: Structure in the residual up to this RMS, as a multiple of the noise level, still
#: counts as consistent with noise (0.3 adds 4.4 % to the RMS of the noise alone).
TOLERANCE = 0.3
#: Lags of the whiteness test of the verdict.
WHITENESS_LAGS = 4
#: Least share of the residual's variance a signal must explain to be named.
MIN_R2 = 0.05
#: The spans are named in the summary when they hold at least this share of the
#: residual's energy and SPAN_CONCENTRATION times their share of the time.
MIN_SPAN_SHARE = 0.1
SPAN_CONCENTRATION = 3.0


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
    lines, spectrum = spectral_lines(r, record.u, record.dt, alpha)
    spans, windows = residual_spans(r, record, xm, sigma, alpha)
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
