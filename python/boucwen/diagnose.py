"""Diagnosis: what is left after the base model, and which effect explains it.

:func:`diagnose` takes a record (voltage u [V], displacement x [µm], interval dt [s]),
not told what it contains, and:

1. splits it into a *fitting* part (the first ``train_fraction``, 70 % by default)
   and a *held-out* part (the rest);
2. fits the base asymmetric Bouc–Wen model on the fitting part (:func:`boucwen.fit`);
3. analyses the residual and records evidence a person can check
   (:func:`residual_evidence`): how the residual moves during holds of the voltage
   (creep), its size relative to the signal per frequency band and its regression on
   the model's rate ẋ (input lag), the peak of its spectrum (resonance), its trend
   in time (drift), the whole-sample lag that best aligns model and data (delay);
4. tries each effect of the vocabulary not yet in the model (creep, input_lag,
   resonance, drift, delay): adds it, refits everything on the fitting part
   (:func:`boucwen.effects.fit_extended`) and simulates the whole record; the most
   likely effect is the one that explains most of the *held-out* error;
5. keeps it only if it cuts the held-out RMS error by at least ``min_gain``
   (10 % by default) — an effect that only fits the noise of the fitting part does
   not earn its parameters there — and repeats from 3 until nothing is kept;
6. refits the base model and the kept effects on the whole record and reports the
   errors over the whole record, before (base model) and after (with the effects).

With no effect in the data, every trial fails step 5 and the result says so
(``effects == []``).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ._core import EffectSet
from .effects import VOCABULARY, ZETA_BOUNDS, ExtendedFit, best_delay, candidate_starts, fit_extended, simulate_chain
from .fit import fit
from .io import validate_samples

__all__ = ["diagnose", "Diagnosis", "residual_evidence", "MIN_GAIN", "TRAIN_FRACTION"]

#: Default fraction of the record (from its start) used for fitting.
TRAIN_FRACTION = 0.7
#: Default least relative cut of the held-out RMS error an effect must bring.
MIN_GAIN = 0.10
#: Iteration limit of each trial fit (a trial only has to show what the effect explains).
TRIAL_NFEV = 20
#: Largest delay tried [samples].
MAX_DELAY_SAMPLES = 8


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of :func:`diagnose`.

    Attributes:
        effects: names of the effects added, in the order added ([] when none).
        rms_before, max_before: RMS and maximum absolute error [µm] of the base model
            fitted on the whole record.
        rms_after, max_after: the same with the effects added (equal to *before* when
            none was added).
        params: ``{"base": {kv, x0, A, beta, gamma, n, delta}, "h0_um": …, <effect>:
            {…}, "base_only": {"base": {...}, "h0_um": …}}`` — the extended model's
            values and, under ``base_only``, the base model's.
        evidence: what the decision rests on (see :func:`diagnose`).
        x_base, x_extended: displacement [µm] of the two models over the record.
        effect_set: the fitted :class:`boucwen.EffectSet`.
    """

    effects: list[str]
    rms_before: float
    max_before: float
    rms_after: float
    max_after: float
    params: dict[str, Any]
    evidence: dict[str, Any]
    x_base: np.ndarray
    x_extended: np.ndarray
    effect_set: EffectSet = field(default_factory=EffectSet)

    def to_dict(self) -> dict[str, Any]:
        """The JSON report (without the arrays)."""
        return {
            "effects": list(self.effects),
            "rms_before": self.rms_before,
            "max_before": self.max_before,
            "rms_after": self.rms_after,
            "max_after": self.max_after,
            "params": self.params,
            "evidence": self.evidence,
        }

    def summary(self) -> str:
        """One line: effects and errors."""
        named = ", ".join(self.effects) if self.effects else "none"
        return (
            f"effects: {named}; RMS {self.rms_before:.4g} → {self.rms_after:.4g} µm, "
            f"max {self.max_before:.4g} → {self.max_after:.4g} µm"
        )

    def __repr__(self) -> str:
        return f"Diagnosis({self.summary()})"


# --------------------------------------------------------------------------- evidence


def _noise_sigma(r: np.ndarray) -> float:
    """Robust white-noise level [µm] from first differences (MAD)."""
    d = np.diff(r)
    if d.size == 0:
        return 0.0
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))


def _holds(u: np.ndarray, dt: float, min_s: float = 0.05) -> list[tuple[int, int]]:
    """Index ranges [start, stop) where u stays constant for at least ``min_s`` [s]."""
    tol = 1e-6 * max(float(np.ptp(u)), 1e-12)
    still = np.abs(np.diff(u)) <= tol
    out = []
    k = 0
    n = still.size
    min_len = max(5, int(round(min_s / dt)))
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


def _band_ratios(r: np.ndarray, xm: np.ndarray, dt: float) -> list[list[float]]:
    """Per octave band: [f_lo, f_hi, rms(residual)/rms(model)] from the FFT."""
    n = r.size
    freqs = np.fft.rfftfreq(n, dt)
    R = np.abs(np.fft.rfft(r - r.mean()))
    X = np.abs(np.fft.rfft(xm - xm.mean()))
    f_lo = 4.0 / (n * dt)
    out = []
    while f_lo < 0.5 / dt:
        f_hi = min(2.0 * f_lo, 0.5 / dt)
        sel = (freqs >= f_lo) & (freqs < f_hi)
        x_pow = float(np.sum(X[sel] ** 2))
        if x_pow > 1e-12 * float(np.sum(X**2)):
            out.append([f_lo, f_hi, float(math.sqrt(np.sum(R[sel] ** 2) / x_pow))])
        f_lo = f_hi
    return out


def residual_evidence(u: Any, x: Any, x_model: Any, dt: float) -> dict[str, Any]:
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
    * ``delay``: the whole-sample shift d ≥ 0 of the model that best aligns it with x,
      and the RMS error [µm] per shift.
    """
    u, x = validate_samples(u, x, dt)
    xm = np.ascontiguousarray(x_model, dtype=np.float64)
    r = x - xm
    n = r.size
    t = np.arange(n) * dt
    ev: dict[str, Any] = {"rms_um": float(np.sqrt(np.mean(r**2))), "noise_um": _noise_sigma(r)}

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
        "hold_change_rms_um": float(np.sqrt(np.mean(np.square(changes)))) if changes else 0.0,
        "corr_with_step": corr,
    }

    xdot = np.gradient(xm, dt)
    denom = float(xdot @ xdot)
    tau = float(-(r - r.mean()) @ xdot / denom) if denom > 0 else 0.0
    c = float(np.corrcoef(r, xdot)[0, 1]) if np.std(r) > 0 and np.std(xdot) > 0 else 0.0
    ev["input_lag"] = {"lag_s": tau, "corr_with_rate": -c, "band_ratio": _band_ratios(r, xm, dt)}

    try:
        from scipy.signal import welch

        f, pxx = welch(r - r.mean(), fs=1.0 / dt, nperseg=min(n, max(64, int(0.25 / dt))))
        sel = f > max(4.0 * f[1] if f.size > 1 else 0.0, 0.02 / dt)
        if np.any(sel) and np.median(pxx[sel]) > 0:
            k = int(np.argmax(pxx[sel]))
            ev["resonance"] = {
                "peak_hz": float(f[sel][k]),
                "peak_over_median": float(pxx[sel][k] / np.median(pxx[sel])),
            }
        else:
            ev["resonance"] = {"peak_hz": 0.0, "peak_over_median": 0.0}
    except ValueError:  # pragma: no cover - record shorter than a segment
        ev["resonance"] = {"peak_hz": 0.0, "peak_over_median": 0.0}

    basis = np.column_stack([t, np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(basis, r, rcond=None)
    var = float(np.var(r))
    explained = float(np.var(basis @ coef) / var) if var > 0 else 0.0
    ev["drift"] = {"slope_um_per_s": float(coef[0]), "variance_share": explained}
    return ev


def _delay_evidence(u, x, dt, fitres: ExtendedFit) -> dict[str, Any]:
    d, rms = best_delay(u, x, dt, fitres.params, fitres.effects, fitres.h0, MAX_DELAY_SAMPLES)
    return {"best_shift_samples": d, "rms_by_shift_um": {str(k): v for k, v in rms.items()}}


# --------------------------------------------------------------------------- diagnosis


def _say_factory(progress: bool | Callable[[str], None], started: float) -> Callable[[str], None]:
    if progress is True:

        def say(msg: str) -> None:
            print(f"diagnose: [{time.perf_counter() - started:6.2f} s] {msg}", file=sys.stderr, flush=True)

        return say
    if callable(progress):
        return progress
    return lambda msg: None


def _rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(v**2))) if v.size else 0.0


def diagnose(
    u: Any,
    x: Any,
    dt: float,
    *,
    progress: bool | Callable[[str], None] = False,
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
        A :class:`Diagnosis`; the procedure is described in the module docs.

    Raises:
        TypeError, ValueError: bad data or options (precise message).
    """
    started = time.perf_counter()
    say = _say_factory(progress, started)
    u, x = validate_samples(u, x, dt)
    if isinstance(dt, bool) or not isinstance(dt, (int, float, np.integer, np.floating)):
        raise TypeError(f"dt must be a real number, got {type(dt).__name__}")
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0 s, got {dt}")
    for name, value, lo, hi in (("train_fraction", train_fraction, 0.3, 0.95), ("min_gain", min_gain, 0.0, 1.0)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
            raise ValueError(f"{name} must be a number in [{lo}, {hi}], got {value!r}")
    if isinstance(max_effects, bool) or not isinstance(max_effects, int) or not 0 <= max_effects <= 5:
        raise ValueError(f"max_effects must be an integer in 0…5, got {max_effects!r}")
    n = u.size
    nt = int(round(train_fraction * n))
    if nt < 64 or n - nt < 16:
        raise ValueError(f"diagnose needs at least 100 samples, got {n}")
    if not np.ptp(u[:nt]) > 0:
        raise ValueError("u is constant over the fitting part; the diagnosis needs a varying voltage")
    u_tr, x_tr = u[:nt], x[:nt]

    def heldout(fr: ExtendedFit) -> tuple[float, np.ndarray]:
        xs = simulate_chain(fr.params, fr.effects, u, dt, fr.h0)
        if xs is None:
            return math.inf, np.full(n, np.nan)
        return _rms((x - xs)[nt:]), xs

    say(f"fitting the base model on the first {nt} of {n} samples")
    base_tr = fit(u_tr, x_tr, dt, seed=seed, workers=workers)
    current = fit_extended(u_tr, x_tr, dt, base_tr.params, EffectSet(), base_tr.h0, max_nfev=100, workers=workers)
    cur_held, cur_x = heldout(current)
    say(f"base model: fitting-part RMS {current.rms_um:.4g} µm, held-out RMS {cur_held:.4g} µm")
    evidence: dict[str, Any] = {
        "train_samples": nt,
        "heldout_samples": n - nt,
        "min_gain": min_gain,
        "residual": residual_evidence(u, x, cur_x, dt),
        "rounds": [],
    }
    evidence["residual"]["delay"] = _delay_evidence(u, x, dt, current)
    added: list[str] = []

    while len(added) < max_effects:
        trials: dict[str, dict[str, Any]] = {}
        fits: dict[str, ExtendedFit] = {}
        for name in VOCABULARY:
            if name in current.effects.names:
                continue
            starts = candidate_starts(
                name, u_tr, x_tr, dt, current.params, current.effects, current.h0, max_delay=MAX_DELAY_SAMPLES
            )
            if len(starts) > 1:
                costs = []
                for s in starts:
                    xs = simulate_chain(current.params, s, u_tr, dt, current.h0)
                    costs.append(math.inf if xs is None else _rms(xs - x_tr))
                starts = [starts[int(np.argmin(costs))]]
            p0, h0 = current.params, current.h0
            if name == "delay":
                # The base fit has bent itself to follow the lag; a delay of d samples is
                # the base model fitted to the record shifted by d, which starts it right.
                d = int(starts[0].to_dict()["delay"]["samples"])
                shifted = fit(u_tr[:-d], x_tr[d:], dt, init=current.params, seed=seed, workers=workers)
                p0, h0 = shifted.params, shifted.h0
            try:
                fr = fit_extended(u_tr, x_tr, dt, p0, starts[0], h0, max_nfev=TRIAL_NFEV, workers=workers)
            except ValueError as exc:
                trials[name] = {"error": str(exc)}
                continue
            held, _ = heldout(fr)
            trials[name] = {
                "train_rms_um": fr.rms_um,
                "heldout_rms_um": held,
                "heldout_gain": 1.0 - held / cur_held if cur_held > 0 else 0.0,
                "fitted": fr.effects.to_dict().get(name),
            }
            if name == "resonance" and fr.effects.to_dict()["resonance"]["zeta"] >= 0.99 * ZETA_BOUNDS[1]:
                # Critically damped or more: no peak, so not a resonance (a lag shape
                # the other effects describe); recorded, but not a candidate.
                trials[name]["rejected"] = "no resonance peak: fitted zeta at its bound of 1"
                say(f"  - {name:9s}: fitted zeta at its bound (no peak): not a resonance")
                continue
            fits[name] = fr
            say(f"  + {name:9s}: held-out RMS {held:.4g} µm (gain {trials[name]['heldout_gain']:+.1%})")
        ranked = sorted(fits, key=lambda k: trials[k]["heldout_rms_um"])
        best = ranked[0] if ranked else None
        keep = best is not None and trials[best]["heldout_gain"] >= min_gain
        evidence["rounds"].append(
            {"heldout_rms_um": cur_held, "trials": trials, "most_likely": best, "kept": bool(keep)}
        )
        if not keep:
            say("nothing left that earns its parameters on the held-out part")
            break
        assert best is not None
        current = fits[best]
        cur_held, cur_x = heldout(current)
        added.append(best)
        say(f"kept {best}: held-out RMS {cur_held:.4g} µm")

    say("refitting on the whole record")
    base_all = fit(u, x, dt, init=base_tr.params, n_candidates=0, n_starts=1, seed=seed, workers=workers)
    x_base = base_all.x_fit
    if added:
        ext = fit_extended(u, x, dt, current.params, current.effects, current.h0, workers=workers)
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
        rms_before=_rms(err_b),
        max_before=float(np.max(np.abs(err_b))),
        rms_after=_rms(err_e),
        max_after=float(np.max(np.abs(err_e))),
        params=params,
        evidence=_jsonable(evidence),
        x_base=x_base,
        x_extended=x_ext,
        effect_set=effect_set,
    )
    say(result.summary())
    return result


def _jsonable(obj: Any) -> Any:
    """Replaces numpy scalars and non-finite floats (→ None) so that json.dumps works."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


# --------------------------------------------------------------------------- outputs


def write_report(result: Diagnosis, path: Any, data: dict[str, Any] | None = None) -> None:
    """Writes the JSON report (:meth:`Diagnosis.to_dict`, plus ``data`` if given)."""
    import json

    doc = result.to_dict()
    if data is not None:
        doc["data"] = data
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=2, allow_nan=False)


def write_predictions(result: Diagnosis, t: Any, x: Any, path: Any) -> None:
    """Writes ``t,x,x_base,x_extended`` (s, µm) with a header line, one row per sample."""
    from .io import write_csv

    write_csv(path, {"t": t, "x": x, "x_base": result.x_base, "x_extended": result.x_extended})


def plot_diagnosis(result: Diagnosis, t: Any, u: Any, x: Any, path: Any, title: str = "") -> None:
    """PNG: (a) the residual before and after against time, (b) the loops x(u)
    measured and of both models, (c) the spectrum of both residuals."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    t, u, x = (np.asarray(v, dtype=np.float64) for v in (t, u, x))
    fig = Figure(figsize=(11.0, 7.5), layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 2)
    ax_r = fig.add_subplot(grid[0, :])
    ax_l = fig.add_subplot(grid[1, 0])
    ax_s = fig.add_subplot(grid[1, 1])
    named = ", ".join(result.effects) if result.effects else "none"
    ax_r.plot(
        t,
        x - result.x_base,
        linewidth=0.7,
        color="tab:red",
        label=f"base model (RMS {result.rms_before:.3g} µm, max {result.max_before:.3g} µm)",
    )
    ax_r.plot(
        t,
        x - result.x_extended,
        linewidth=0.7,
        color="tab:blue",
        label=f"with {named} (RMS {result.rms_after:.3g} µm, max {result.max_after:.3g} µm)",
    )
    ax_r.axhline(0.0, color="grey", linewidth=0.5)
    ax_r.set_xlabel("time t [s]")
    ax_r.set_ylabel("error x − x̂ [µm]")
    ax_r.set_title(f"(a) residual before and after{': ' + title if title else ''}")
    ax_r.legend(loc="upper right", fontsize=8)
    ax_r.grid(True, alpha=0.3)
    ax_l.plot(u, x, color="black", linewidth=1.2, label="measured")
    ax_l.plot(u, result.x_base, color="tab:red", linewidth=0.7, linestyle="--", label="base model")
    ax_l.plot(u, result.x_extended, color="tab:blue", linewidth=0.7, linestyle=":", label=f"with {named}")
    ax_l.set_xlabel("voltage u [V]")
    ax_l.set_ylabel("displacement x [µm]")
    ax_l.set_title("(b) loops")
    ax_l.legend(loc="upper left", fontsize=8)
    ax_l.grid(True, alpha=0.3)
    dt = float(t[1] - t[0]) if t.size > 1 else 1.0
    freqs = np.fft.rfftfreq(t.size, dt)[1:]
    for err, color, label in (
        (x - result.x_base, "tab:red", "base model"),
        (x - result.x_extended, "tab:blue", f"with {named}"),
    ):
        amp = np.abs(np.fft.rfft(err - err.mean()))[1:] * 2.0 / t.size
        ax_s.loglog(freqs, np.maximum(amp, 1e-12), color=color, linewidth=0.6, label=label)
    ax_s.set_xlabel("frequency [Hz]")
    ax_s.set_ylabel("residual amplitude [µm]")
    ax_s.set_title("(c) residual spectrum")
    ax_s.legend(loc="lower left", fontsize=8)
    ax_s.grid(True, alpha=0.3, which="both")
    fig.savefig(path, dpi=110)
