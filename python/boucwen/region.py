"""The admissible region: where the asymmetric Bouc–Wen model keeps h bounded.

While the voltage moves one way (s = sgn(u̇) ≠ 0), w = s·h obeys

    dw/dt = |u̇|·g(w) + δ·u,    g(w) = A − (β + γ)·wⁿ (w ≥ 0),  A + (β − γ)·|w|ⁿ (w < 0)

and h holds while u holds. With β + γ ≥ 0 and β − γ ≥ 0 g is non-increasing and h stays
bounded; with either negative it escapes along one branch once it is driven far enough;
the δ term, the one not proportional to |u̇|, is dissipated only where both are > 0, and
only for inputs that do not creep (docs/design.md, "The admissible region", derives it).

* :func:`check` raises :class:`boucwen.InvalidParams` outside the region (the rule is the
  core's, :meth:`boucwen.Params.check_admissible`).
* :func:`pair`, :func:`split`: the coordinates the fits use, (β + γ, β − γ), in which the
  region is a box (both ≥ 0); :data:`SPLIT_JACOBIAN` turns ∂/∂(β, γ) into ∂/∂(β + γ, β − γ).
* :func:`hysteresis_bound`: the bound on |h| the region guarantees for an input of a
  given voltage range and slowest slew.
* :func:`delta_limit`: how large a fit lets δ grow on a record (:data:`DELTA_RATIO`).
"""

from __future__ import annotations

import math

import numpy as np

from ._core import Params
from .checks import FloatArray

__all__ = [
    "DELTA_RATIO",
    "PAIR_NAMES",
    "SPLIT_JACOBIAN",
    "check",
    "delta_limit",
    "hysteresis_bound",
    "pair",
    "split",
    "travel_bound",
]

#: The names of the fits' coordinates (β + γ, β − γ), in place of ``beta`` and ``gamma``.
PAIR_NAMES = ("beta_plus_gamma", "beta_minus_gamma")

#: At the slowest full-range sweep a record's length allows (v = 2·span/T: one triangle
#: over the record), a fit's δ term may add at most this many times what the loop's
#: slope adds per volt (|δ|·max|u|/v ≤ ratio × slope). δ·u·sgn(u̇) is the model's small
#: asymmetry (at the paper's 1 Hz record, 3 s long, its δ·U/v is 0.16 of |A|); a fit that
#: makes it many times the rate term there uses it for something else — on a staircase,
#: the δ·u·dt of each fast step as a level-dependent jump — and on a slow input of the
#: range the term then drives h alone. Within the ratio, A + δ·u/|u̇| grows at most
#: (1 + ratio)-fold at that sweep and hₛ with it (1 + ratio)^(1/n)-fold (5× at n = 1.5),
#: inside the boundedness check's multiple (:mod:`boucwen.boundedness`).
DELTA_RATIO = 10.0

#: ∂(β, γ)/∂(β + γ, β − γ): the columns ∂/∂β, ∂/∂γ of a Jacobian times this give
#: ∂/∂(β + γ), ∂/∂(β − γ).
SPLIT_JACOBIAN: FloatArray = np.array([[0.5, 0.5], [0.5, -0.5]])


def check(params: Params) -> Params:
    """``params`` if they are in the admissible region; else :class:`boucwen.InvalidParams`
    with one line naming the combination and its value."""
    params.check_admissible()
    return params


def pair(beta: float, gamma: float) -> tuple[float, float]:
    """(β + γ, β − γ) [µm^(1−n)/V]."""
    return beta + gamma, beta - gamma


def split(plus: float, minus: float) -> tuple[float, float]:
    """(β, γ) [µm^(1−n)/V] from (β + γ, β − γ): the inverse of :func:`pair`."""
    return 0.5 * (plus + minus), 0.5 * (plus - minus)


def travel_bound(params: Params, h0: float, u_span_v: float) -> float:
    """|h| [µm] never exceeds this for δ = 0 and any input whose voltage spans at most
    ``u_span_v`` [V]: |h0| + |A|·span (on the way up h rises by at most |A| per volt
    and on the way down falls by at least that much once past max(h0, 0)). Requires
    the region (ValueError otherwise) and δ = 0 (the δ term adds a rate-dependent part:
    :func:`hysteresis_bound`)."""
    check(params)
    if params.delta != 0.0:
        raise ValueError("travel_bound holds for delta = 0 only; use hysteresis_bound")
    return abs(h0) + abs(params.A) * u_span_v


def hysteresis_bound(params: Params, h0: float, u_max_abs_v: float, slowest_slew_v_per_s: float) -> float:
    """|h| [µm] never exceeds this for any input with |u| ≤ ``u_max_abs_v`` [V] that moves
    at a slew of at least ``slowest_slew_v_per_s`` [V/s] whenever it moves (holds are
    free: the δ term is off while u holds):

        max(|h0|, H),  H = max(((A + |δ|·U/v)₊/(β + γ))^(1/n), ((−A + |δ|·U/v)₊/(β − γ))^(1/n))

    (the saturation bound with A replaced by the extremes of A + δ·u/|u̇|). ``inf`` where
    a branch the bound needs does not dissipate (β + γ = 0 or β − γ = 0 with a positive
    numerator). Every second an input spends moving slower than v adds at most |δ|·U µm.
    Requires the region (ValueError otherwise)."""
    check(params)
    if not (slowest_slew_v_per_s > 0.0 and u_max_abs_v >= 0.0):
        raise ValueError("the slowest slew must be > 0 V/s and the voltage bound >= 0 V")
    pumped = abs(params.delta) * u_max_abs_v / slowest_slew_v_per_s
    plus, minus = pair(params.beta, params.gamma)
    levels = [abs(h0)]
    for drive, dissipation in ((params.A + pumped, plus), (-params.A + pumped, minus)):
        if drive <= 0.0:
            continue
        if dissipation <= 0.0:
            return math.inf
        levels.append((drive / dissipation) ** (1.0 / params.n))
    return max(levels)


def delta_limit(slope_um_per_v: float, u_span_v: float, u_max_abs_v: float, duration_s: float) -> float:
    """The largest |δ| [µm/(V·s)] a fit allows on a record whose voltage spans
    ``u_span_v`` [V] with |u| ≤ ``u_max_abs_v`` over ``duration_s`` [s], its loop's slope
    ``slope_um_per_v`` [µm/V] (:data:`DELTA_RATIO`); ``inf`` for a record at 0 V."""
    if not (u_max_abs_v > 0.0 and duration_s > 0.0):
        return math.inf
    slowest = 2.0 * u_span_v / duration_s
    return DELTA_RATIO * abs(slope_um_per_v) * slowest / u_max_abs_v
