"""Fitting the base model together with its effects by output error.

The effects themselves (creep, input_lag, resonance, drift, delay) are small
physical models in the Rust core, see :class:`boucwen.EffectSet` and
:func:`boucwen.simulate_extended`. This module holds the one place where their
parameters are fitted from data: :func:`fit_extended` minimises
Σ (x_k − x̂_k)² over a record, where x̂ is *simulated* from u alone with
:func:`boucwen.simulate_extended`, by ``scipy.optimize.least_squares`` — the same
approach as :func:`boucwen.fit` for the base model (whose result is the usual
starting point here).

Unknowns, in this order (see :class:`Layout`):

* the base model: kv [µm/V], x0 [µm], A, β, γ, n, δ (units of :class:`boucwen.Params`),
  and the initial hysteresis state h0 [µm];
* ``creep``: one gain g_i [µm/V] per fixed time constant τ_i (log-spaced, see
  :func:`creep_time_constants`); the output is linear in the gains, which share the
  sign of kv (creep continues the motion a step started);
* ``input_lag``: ln fc (fc [Hz]);
* ``resonance``: ln fn (fn [Hz]) and ln ζ;
* ``drift``: rate [µm/s];
* ``delay``: none — a whole number of samples is not a continuous unknown; it is
  chosen by :func:`best_delay` and held fixed.

Log coordinates keep fc, fn and ζ positive; fn stays below 0.45/dt (Nyquist is
0.5/dt). Residual, Jacobian (forward differences in threads) and optimiser are
those of :mod:`boucwen.lsq`, shared with :func:`boucwen.fit`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ._core import EffectSet, Params, simulate_extended
from .checks import FloatArray
from .fit import N_BOUNDS
from .lsq import OutputErrorProblem, finite_or_none, jacobian_threads
from .metrics import max_abs, rms
from .record import Record, validate_record

__all__ = [
    "FN_MAX_NYQUIST_FRACTION",
    "VOCABULARY",
    "ZETA_BOUNDS",
    "ExtendedFit",
    "Layout",
    "best_delay",
    "candidate_starts",
    "creep_time_constants",
    "fit_extended",
    "fit_extended_record",
    "simulate_chain",
]

#: The effect names, in signal-chain order.
VOCABULARY: tuple[str, ...] = tuple(EffectSet.vocabulary)
#: Bounds on the damping ratio ζ [-] during a fit. Above 1 the second-order element
#: has two real poles and no peak: that is a lag, not a resonance, and the diagnosis
#: must not call it one.
ZETA_BOUNDS = (1e-3, 1.0)
#: fn is kept below this fraction of the sampling rate (Nyquist = 0.5).
FN_MAX_NYQUIST_FRACTION = 0.45


def creep_time_constants(dt: float, duration_s: float, max_count: int = 5) -> list[float]:
    """Log-spaced creep time constants τ_i [s] for a record of ``duration_s`` [s].

    From 10·dt (faster elements look like part of kv) to three times the record's
    length (the creep that is still running at the end of the record), about one per
    decade, between 2 and ``max_count``.
    """
    lo = 10.0 * dt
    hi = max(3.0 * duration_s, 2.0 * lo)
    count = int(min(max_count, max(2, round(math.log10(hi / lo)) + 1)))
    return [float(v) for v in np.geomspace(lo, hi, count)]


@dataclass(frozen=True)
class Layout:
    """Which unknowns a fit has: the effect names present, fixed creep τ_i and delay.

    Attributes:
        names: effect names present (vocabulary order).
        creep_tau_s: the fixed creep time constants [s] (empty without creep).
        delay_samples: the fixed delay [samples] (0 without delay).
        dt: sampling interval [s] (bounds fn below Nyquist).
        duration_s: record length [s] (bounds fc from below).
    """

    names: tuple[str, ...]
    creep_tau_s: tuple[float, ...]
    delay_samples: int
    dt: float
    duration_s: float

    @classmethod
    def of(cls, effects: EffectSet, dt: float, duration_s: float) -> Layout:
        d = effects.to_dict()
        return cls(
            names=tuple(effects.names),
            creep_tau_s=tuple(d["creep"]["tau_s"]) if "creep" in d else (),
            delay_samples=int(d["delay"]["samples"]) if "delay" in d else 0,
            dt=float(dt),
            duration_s=float(duration_s),
        )

    def labels(self) -> list[str]:
        """Name of every unknown, in vector order."""
        out = [*list(Params.names), "h0"]
        if "creep" in self.names:
            out += [f"creep.gain[{i}]" for i in range(len(self.creep_tau_s))]
        if "input_lag" in self.names:
            out.append("input_lag.ln_fc")
        if "resonance" in self.names:
            out += ["resonance.ln_fn", "resonance.ln_zeta"]
        if "drift" in self.names:
            out.append("drift.rate")
        return out

    def pack(self, params: Params, effects: EffectSet, h0: float) -> FloatArray:
        """(params, effects, h0) → vector of unknowns."""
        d = effects.to_dict()
        v = [*list(params.to_array()), float(h0)]
        if "creep" in self.names:
            v += list(d["creep"]["gain_um_per_v"])
        if "input_lag" in self.names:
            v.append(math.log(d["input_lag"]["fc_hz"]))
        if "resonance" in self.names:
            v += [math.log(d["resonance"]["fn_hz"]), math.log(d["resonance"]["zeta"])]
        if "drift" in self.names:
            v.append(d["drift"]["rate_um_per_s"])
        return np.asarray(v, dtype=np.float64)

    def unpack(self, v: FloatArray) -> tuple[Params, EffectSet, float]:
        """Vector of unknowns → (params, effects, h0); ValueError if invalid."""
        params = Params.from_array(v[:7])
        h0 = float(v[7])
        i = 8
        kw: dict[str, Any] = {}
        if "creep" in self.names:
            k = len(self.creep_tau_s)
            kw["creep"] = {"tau_s": list(self.creep_tau_s), "gain_um_per_v": [float(g) for g in v[i : i + k]]}
            i += k
        if "input_lag" in self.names:
            kw["input_lag"] = {"fc_hz": float(math.exp(v[i]))}
            i += 1
        if "resonance" in self.names:
            kw["resonance"] = {"fn_hz": float(math.exp(v[i])), "zeta": float(math.exp(v[i + 1]))}
            i += 2
        if "drift" in self.names:
            kw["drift"] = {"rate_um_per_s": float(v[i])}
            i += 1
        if "delay" in self.names:
            kw["delay"] = {"samples": self.delay_samples}
        return params, EffectSet(**kw), h0

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        labels = self.labels()
        lo = np.full(len(labels), -np.inf)
        hi = np.full(len(labels), np.inf)
        lo[5], hi[5] = N_BOUNDS
        for j, name in enumerate(labels):
            if name == "input_lag.ln_fc":
                lo[j], hi[j] = math.log(1.0 / self.duration_s), math.log(10.0 / self.dt)
            elif name == "resonance.ln_fn":
                lo[j], hi[j] = math.log(2.0 / self.duration_s), math.log(FN_MAX_NYQUIST_FRACTION / self.dt)
            elif name == "resonance.ln_zeta":
                lo[j], hi[j] = math.log(ZETA_BOUNDS[0]), math.log(ZETA_BOUNDS[1])
        return lo, hi


@dataclass(frozen=True, eq=False)
class ExtendedFit:
    """Result of :func:`fit_extended`.

    Attributes:
        params: base :class:`boucwen.Params`.
        effects: the :class:`boucwen.EffectSet` with fitted parameters.
        h0: initial hysteresis state [µm].
        rms_um, max_um: output error over the fitted samples [µm].
        nfev: number of record simulations.
        success: the optimiser reported convergence.
    """

    params: Params
    effects: EffectSet
    h0: float
    rms_um: float
    max_um: float
    nfev: int
    success: bool

    def simulate(self, u: ArrayLike, dt: float) -> FloatArray:
        """x [µm] of the fitted model for the voltage ``u`` [V]."""
        return simulate_extended(self.params, self.effects, u, dt, self.h0)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters: ``{"base": {...}, "h0_um": ..., <effect>: {...}}``."""
        out: dict[str, Any] = {"base": self.params.to_dict(), "h0_um": self.h0}
        out.update(self.effects.to_dict())
        return out


def simulate_chain(params: Params, effects: EffectSet, u: FloatArray, dt: float, h0: float) -> FloatArray | None:
    """:func:`boucwen.simulate_extended` [µm], or None if the values cannot be simulated."""
    return finite_or_none(lambda: simulate_extended(params, effects, u, dt, h0))


class _Chain:
    """Vector of unknowns → x [µm] of the extended model over one record (or None)."""

    def __init__(self, layout: Layout, u: FloatArray, dt: float):
        self.layout, self.u, self.dt = layout, u, dt

    def __call__(self, v: FloatArray) -> FloatArray | None:
        try:
            p, e, h0 = self.layout.unpack(v)
        except (ValueError, OverflowError):
            return None
        return simulate_chain(p, e, self.u, self.dt, h0)


def _typical(layout: Layout, v0: FloatArray, u: FloatArray, x: FloatArray, dt: float) -> FloatArray:
    """Typical size of each unknown (sets the difference steps and the scaling)."""
    span_u = max(float(np.ptp(u)), 1e-12)
    span_x = max(float(np.ptp(x)), 1e-12)
    labels = layout.labels()
    typ: FloatArray = np.abs(v0).copy()
    floors = {
        "kv": span_x / span_u,
        "x0": span_x,
        "A": span_x / span_u,
        "beta": 1e-3,
        "gamma": 1e-3,
        "n": 1.0,
        "delta": 1e-3,
        "h0": 0.01 * span_x,
        "drift.rate": span_x / max(layout.duration_s, dt) * 1e-2,
    }
    for j, name in enumerate(labels):
        floor = floors.get(name)
        if name.startswith("creep.gain"):
            floor = 0.01 * span_x / span_u
        if name.startswith(("input_lag.", "resonance.")):
            floor = 1.0
        typ[j] = max(typ[j], floor if floor is not None else 1e-6)
    return typ


def fit_extended(
    u: Any,
    x: Any,
    dt: float,
    params: Params,
    effects: EffectSet,
    h0: float = 0.0,
    *,
    max_nfev: int = 40,
    tol: float = 1e-8,
    workers: int | None = None,
) -> ExtendedFit:
    """Fits the base parameters, h0 and the effects' parameters by output error.

    Args:
        u: voltage [V] (1-D, finite); x: measured displacement [µm], same length.
        dt: sampling interval [s].
        params, effects, h0: starting point; ``effects`` also fixes which effects are
            present, the creep time constants and the delay (see the module docs).
        max_nfev: iteration limit of ``least_squares``.
        tol: ``xtol``/``ftol``/``gtol`` of ``least_squares``.
        workers: threads for the Jacobian columns (default: the number of CPUs).

    Returns:
        An :class:`ExtendedFit` (errors over the given record).

    Raises:
        ValueError: invalid data or a starting point that cannot be simulated.
    """
    record = validate_record(u, x, dt)
    return fit_extended_record(record, params, effects, h0, max_nfev=max_nfev, tol=tol, workers=workers)


def fit_extended_record(
    record: Record,
    params: Params,
    effects: EffectSet,
    h0: float = 0.0,
    *,
    max_nfev: int = 40,
    tol: float = 1e-8,
    workers: int | None = None,
) -> ExtendedFit:
    """:func:`fit_extended` on a checked :class:`~boucwen.record.Record`."""
    u, x, dt = record.u, record.x, record.dt
    layout = Layout.of(effects, dt, dt * max(u.size - 1, 1))
    v0 = layout.pack(params, effects, h0)
    lo, hi = layout.bounds()
    # The Jacobian steps backwards only at the layout's own bounds (fc, fn below
    # Nyquist); the sign bounds of the creep gains below need no such care, since
    # any sign can be simulated.
    step_upper = layout.bounds()[1]
    # Creep continues the motion a voltage step started: its gains share the sign of kv.
    for j, label in enumerate(layout.labels()):
        if label.startswith("creep.gain"):
            if params.kv >= 0:
                lo[j] = 0.0
            else:
                hi[j] = 0.0
    margin = 1e-9 * (1.0 + np.abs(np.where(np.isfinite(lo), lo, 0.0)))
    v0 = np.clip(v0, lo + margin, hi - margin)
    typ = _typical(layout, v0, u, x, dt)
    with jacobian_threads(workers) as pool:
        prob = OutputErrorProblem(_Chain(layout, u, dt), x, typical=typ, upper=step_upper, pool=pool)
        if prob.simulate(v0) is None:
            raise ValueError("the starting point of fit_extended cannot be simulated")
        res = prob.solve(v0, lo, hi, x_scale=typ, tol=tol, max_nfev=max_nfev)
        p, e, h = layout.unpack(res.x)
        xs = simulate_chain(p, e, u, dt, h)
    if xs is None:  # pragma: no cover - the optimiser never accepts a failing point
        raise ValueError("the fitted parameters cannot be simulated")
    err = x - xs
    return ExtendedFit(
        params=p,
        effects=e,
        h0=h,
        rms_um=rms(err),
        max_um=max_abs(err),
        nfev=prob.simulations,
        success=bool(res.success),
    )


def best_delay(
    record: Record, params: Params, effects: EffectSet, h0: float, max_samples: int
) -> tuple[int, dict[int, float]]:
    """The whole-sample delay d (0 … ``max_samples``) that best aligns the model with x.

    For each d, the model (with ``effects``, without any delay) is shifted by d samples
    and the RMS error [µm] of the best straight-line correction ``a·x̂ + b`` is
    taken (so that a small gain or offset change does not mask the lag). Returns
    ``(d, {d: rms})``.
    """
    xs = simulate_chain(params, _with(effects, delay=None), record.u, record.dt, h0)
    if xs is None:
        return 0, {}
    x = record.x
    rms_by_shift: dict[int, float] = {}
    for d in range(max_samples + 1):
        a = xs[: xs.size - d]
        b = x[d:]
        basis = np.column_stack([a, np.ones_like(a)])
        coef, *_ = np.linalg.lstsq(basis, b, rcond=None)
        rms_by_shift[d] = rms(b - basis @ coef)
    return min(rms_by_shift, key=rms_by_shift.__getitem__), rms_by_shift


def _with(effects: EffectSet, **changes: Any) -> EffectSet:
    """``effects`` with some effects added or replaced (a dict) or removed (None)."""
    kw: dict[str, Any] = dict(effects.to_dict())
    for name, value in changes.items():
        if value is None:
            kw.pop(name, None)
        else:
            kw[name] = value
    return EffectSet(**kw)


def candidate_starts(
    name: str,
    record: Record,
    params: Params,
    effects: EffectSet,
    h0: float,
    *,
    max_delay: int = 8,
    creep_tau_s: Sequence[float] | None = None,
) -> list[EffectSet]:
    """Starting effect sets that add ``name`` to ``effects`` (a few for the nonlinear ones)."""
    dt = record.dt
    duration = record.duration_s
    if name == "creep":
        taus = list(creep_tau_s) if creep_tau_s is not None else creep_time_constants(dt, duration)
        return [_with(effects, creep={"tau_s": taus, "gain_um_per_v": [0.0] * len(taus)})]
    if name == "drift":
        return [_with(effects, drift={"rate_um_per_s": 0.0})]
    if name == "input_lag":
        # The last start is nearly no lag at all (fc = 5/dt).
        fcs = np.append(np.geomspace(max(2.0 / duration, 0.5), 2.0 / dt, 10), 5.0 / dt)
        return [_with(effects, input_lag={"fc_hz": float(f)}) for f in fcs]
    if name == "resonance":
        fns = np.geomspace(max(5.0 / duration, 0.02 / dt), FN_MAX_NYQUIST_FRACTION * 0.9 / dt, 8)
        pairs = [(float(f), z) for f in fns for z in (0.03, 0.15, 0.5)]
        pairs.append((FN_MAX_NYQUIST_FRACTION * 0.98 / dt, 0.7))  # the mildest resonance
        return [_with(effects, resonance={"fn_hz": f, "zeta": z}) for f, z in pairs]
    if name == "delay":
        # Every whole-sample delay, the best-aligning shift first (the caller keeps the
        # start of least error).
        d, _ = best_delay(record, params, effects, h0, max_delay)
        first = max(d, 1)
        order = [first, *(k for k in range(1, max_delay + 1) if k != first)]
        return [_with(effects, delay={"samples": k}) for k in order]
    raise ValueError(f"unknown effect {name!r}; expected one of {list(VOCABULARY)}")
