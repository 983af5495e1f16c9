"""The inverse of a piezo model whose command a DAC holds between samples.

A digital rig drives its amplifier through a DAC that holds each sample: u[k] from t_k
to t_{k+1}, a staircase (the model's ``between_samples`` effect ``"hold"``,
:mod:`boucwen.measurement`). The core's inverse (:func:`boucwen.invert`) takes the
command as a straight line between samples; here the command is solved against the held
staircase itself, so the model run on it with ``"hold"`` meets the target at the sample
instants:

* Where the stack takes the command directly (no ``input_lag``), the held step at t_k
  moves h along the loop at once (without the rate term δ, a step takes no time), and
  x at t_k depends on u[k]: u[k] is solved from x_d[k]. Between the samples the
  voltage, and with it x (but for creep, which the next sample's solve takes in), stays.
* Through an amplifier lag, the stack's voltage is continuous: x at t_k depends on the
  voltage held over [t_{k−1}, t_k) and not on u[k]. The command leads the target by one
  sample: u[k] is solved from x_d[k+1] (the last command repeats the one before; the
  held first sample from rest holds x at x_d[1] too).
* A ``delay`` of d samples reads the target d samples ahead, as the core's inverse does
  (the last value held at the end); ``pickup`` and ``saturation`` are in the sensor's
  reading and are ignored (the inverse aims at the motion before them); ``resonance``
  and ``resonance2`` are not inverted here (``boucwen invert`` inverts the modes on the
  target before).

Per sample, the equation x(u) = target is solved from the previous command by secant
steps on the model's own chain (:func:`boucwen.simulate_extended` from the state the
previous sample left, so the model run on the whole command reproduces each sample
bit for bit), then by Illinois false position once bracketed, to within
:data:`boucwen.INVERSE_TOLERANCE_UM`·max(1, |x_d|) µm, the voltage limits clipping it.
Units: u [V], x [µm], dt [s].
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from ._core import INVERSE_TOLERANCE_UM, EffectSet, ExtendedState, InvalidConfig, Params, simulate_extended
from .checks import FloatArray, as_float_vector, check_dt
from .effects.base import params_of, set_of

__all__ = ["invert_held"]

#: Secant steps on the first side before the search gives up a bracket.
_SEARCH_STEPS = 12
#: Most evaluations of the chain per sample in the bracket.
_BRACKET_STEPS = 40


def invert_held(
    params: Params,
    effects: EffectSet,
    x_d: ArrayLike,
    dt: float,
    h0: float = 0.0,
    *,
    u_min: float | None = None,
    u_max: float | None = None,
) -> FloatArray:
    """The command u [V] a DAC holds between samples that makes the model ``params`` with
    ``effects`` (run with ``between_samples`` ``"hold"``) follow ``x_d`` [µm] from h =
    ``h0`` [µm] (the module docs say how), within ``u_min`` … ``u_max`` [V].

    Raises:
        InvalidRecord: a bad ``x_d``; InvalidConfig: a bad ``dt``, limits u_min > u_max,
            or a resonance among the effects.
    """
    target = as_float_vector(x_d, "x_d")
    dt = check_dt(dt)
    lo = -math.inf if u_min is None else float(u_min)
    hi = math.inf if u_max is None else float(u_max)
    if lo > hi:
        raise InvalidConfig(f"u_min = {u_min} V is above u_max = {u_max} V")
    present = params_of(effects)
    modes = [name for name in ("resonance", "resonance2") if name in present]
    if modes:
        raise InvalidConfig(f"{', '.join(modes)}: not inverted here; invert the modes on the target first")
    delay = int(present.pop("delay", {"samples": 0})["samples"])
    for name in ("pickup", "saturation"):
        present.pop(name, None)
    present["between_samples"] = {"input": "hold"}
    chain = set_of(present)
    lag = present.get("input_lag")
    ahead = 0 if lag is None else 1
    n = target.size
    wanted = target[np.minimum(np.arange(n) + delay + ahead, n - 1)]
    # The slope of x(u) on a branch at h = 0, through the lag's share of one interval.
    share = 1.0 if lag is None else -math.expm1(-2.0 * math.pi * float(lag["fc_hz"]) * dt)
    slope = max(params.kv + params.A, 1e-12) * share

    state = ExtendedState(h0)
    u = np.empty(n)
    prev = min(max(0.0, lo), hi)
    for k in range(n):
        want = float(wanted[k])

        def miss(v: float, state: ExtendedState = state, want: float = want) -> float:
            x = simulate_extended(params, chain, np.full(1 + ahead, v), dt, state=state)[0]
            return float(x[-1]) - want

        prev = _root(miss, prev, slope, lo, hi, INVERSE_TOLERANCE_UM * max(1.0, abs(want)))
        u[k] = prev
        state = simulate_extended(params, chain, u[k : k + 1], dt, state=state)[1]
    return u


def _root(f: Callable[[float], float], a: float, slope: float, lo: float, hi: float, tol: float) -> float:
    """A root of ``f`` (rising) within [lo, hi], searched from ``a`` with the slope
    ``slope`` first; the limit where the root lies beyond it; the point of least |f|
    where none is found."""

    def clip(v: float) -> float:
        return min(max(v, lo), hi)

    fa = f(a)
    best = (abs(fa), a)
    if best[0] <= tol:
        return a
    b = clip(a - fa / slope)
    steps = 0
    while True:
        if b == a:  # on a limit, the root beyond it
            return b
        fb = f(b)
        best = min(best, (abs(fb), b))
        if best[0] <= tol or (fa < 0.0) != (fb < 0.0) or steps == _SEARCH_STEPS:
            break
        secant = (fb - fa) / (b - a)
        a, fa = b, fb
        b = clip(b - fb / (secant if secant > 0.0 and math.isfinite(secant) else slope))
        steps += 1
    if best[0] <= tol or (fa < 0.0) == (fb < 0.0):
        return best[1]
    # Illinois false position inside the bracket [a, b].
    for _ in range(_BRACKET_STEPS):
        c = (a * fb - b * fa) / (fb - fa)
        fc = f(c)
        best = min(best, (abs(fc), c))
        if best[0] <= tol:
            break
        if (fc < 0.0) != (fb < 0.0):
            a, fa = b, fb
        else:
            fa /= 2.0
        b, fb = c, fc
    return best[1]
