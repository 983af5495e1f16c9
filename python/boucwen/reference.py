"""Plain NumPy/Python versions of the simulator and of the paper's identifier.

Written to be read and to check the Rust core against, not for speed. Names
follow the paper (Zhu, Bian & Rui, Precision Engineering 38 (2014) 921–927)::

    x     = kv·u + x0 + h                                           (3)
    dh/dt = A·u̇ − β·|u̇|·|h|^(n−1)·h − γ·u̇·|h|^n + δ·u·sgn(u̇)        (5)

u: voltage [V]; x, h: displacement [µm]; t: time [s]; kv [µm/V], x0 [µm],
A [µm/V], β and γ [µm^(1−n)/V], n [-], δ [µm/(V·s)].

- :func:`simulate` integrates eq. (5) by classic RK4 with a fixed number of equal
  steps per sample interval (u a straight line between samples), written from the
  equation and nothing else: no step control, no implicit steps, no quantity carried
  from one step to the next but h. Its error is RK4's at its step, so a test that
  compares the Rust core with it takes its tolerance from that step (halving the step
  bounds the reference's own error), not from the core's sub-step rules.
- :class:`PaperIdentifier` is the paper's online method with the same guards
  and the same decisions as the Rust ``PaperIdentifier``, but every window
  statistic is recomputed from the stored window points at each sample (O(N)
  per sample) instead of being kept as running sums, and step 1 is an exact
  least-squares fit of the window instead of a recursive one. Its model's h comes
  from the core's integrator (:func:`boucwen.simulate`): the identification method is
  what it restates. It restates the paper's five steps and their gates, not the window
  fit (``PaperConfig.fit_iterations``): it is the Rust identifier with
  ``fit_iterations=0``, and its ``status.window_fit`` always says held. The results
  therefore differ from that Rust identifier by rounding only.

Parameters may be given as a :class:`boucwen.Params`, a mapping with the keys
``kv, x0, A, beta, gamma, n, delta`` or a sequence of the seven values in that
order.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._core import Params
from ._core import simulate as core_simulate
from .status import PaperStatus, StepStatus

__all__ = [
    "DEFAULT_SUBSTEPS",
    "PaperIdentifier",
    "RefParams",
    "advance_h",
    "advance_intervals",
    "hysteresis_rate",
    "simulate",
]

#: RK4 steps per sample interval of :func:`simulate` by default.
DEFAULT_SUBSTEPS = 64

NAMES = ("kv", "x0", "A", "beta", "gamma", "n", "delta")


class RefParams(NamedTuple):
    """The seven parameters as plain floats (units in the module docs)."""

    kv: float
    x0: float
    A: float
    beta: float
    gamma: float
    n: float
    delta: float

    @classmethod
    def from_any(cls, params: Any) -> RefParams:
        """From a :class:`boucwen.Params`, a mapping or a sequence of 7 values; validated."""
        if isinstance(params, Mapping):
            values = [params[name] for name in NAMES]
        elif all(hasattr(params, name) for name in NAMES):
            values = [getattr(params, name) for name in NAMES]
        else:
            values = list(params)
            if len(values) != 7:
                raise ValueError(f"expected 7 values {NAMES}, got {len(values)}")
        p = cls(*(float(v) for v in values))
        p.validate()
        return p

    def validate(self) -> None:
        """All values finite and n > 0, else ValueError naming the parameter."""
        for name, value in zip(NAMES, self):
            if not math.isfinite(value):
                raise ValueError(f"invalid parameter {name} = {value}: must be finite")
        if self.n <= 0.0:
            raise ValueError(f"invalid parameter n = {self.n}: must be > 0")

    def is_valid(self) -> bool:
        try:
            self.validate()
        except ValueError:
            return False
        return True

    def to_array(self) -> NDArray[np.float64]:
        """``[kv, x0, A, beta, gamma, n, delta]``."""
        return np.array(self, dtype=np.float64)


# ---------------------------------------------------------------------------
# Small helpers.


def _pow(base: float, exponent: float) -> float:
    """base**exponent for base ≥ 0, +inf on overflow (Python raises instead)."""
    try:
        return float(base**exponent)
    except OverflowError:
        return math.inf


def _sgn(v: float) -> float:
    """sgn with sgn(0) = 0."""
    if v > 0.0:
        return 1.0
    if v < 0.0:
        return -1.0
    return 0.0


def _finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"sample {name} = {value} is not finite; the sample was rejected and the state kept")
    return value


def _positive_dt(dt: float) -> float:
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError(f"invalid dt = {dt}: the sampling interval must be finite and > 0 (seconds)")
    return dt


def _samples(values: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        _finite(name, arr[bad[0]])
    return arr


def _substeps(substeps: int) -> int:
    m = int(substeps)
    if m < 1:
        raise ValueError(f"invalid substeps = {substeps}: must be >= 1")
    return m


# ---------------------------------------------------------------------------
# The model, from its equations.


def hysteresis_rate(p: RefParams, h: float, u: float, udot: float) -> float:
    """dh/dt of eq. (5) [µm/s] at state h [µm], voltage u [V] and rate u̇ [V/s].

    |h|^(n−1)·h is written sgn(h)·|h|^n, its value for every h ≠ 0 and 0 at h = 0
    (where |h|^(n−1) alone is infinite for n < 1).
    """
    hn = _pow(abs(h), p.n)
    return p.A * udot - p.beta * abs(udot) * _sgn(h) * hn - p.gamma * udot * hn + p.delta * u * _sgn(udot)


def _rates(p: RefParams, h: NDArray[np.float64], u: NDArray[np.float64], udot: NDArray[np.float64]) -> NDArray[Any]:
    """:func:`hysteresis_rate` over arrays (each interval its own h, u, u̇)."""
    hn = np.abs(h) ** p.n
    return p.A * udot - p.beta * np.abs(udot) * np.sign(h) * hn - p.gamma * udot * hn + p.delta * u * np.sign(udot)


def _rk4(rate: Callable[[Any, Any], Any], h: Any, u0: Any, udot: Any, dt: float, m: int) -> Any:
    """``m`` classic RK4 steps of dh/dt = rate(h, u) over dt [s] while u = u0 + u̇·t, on
    floats or on arrays (one interval per element)."""
    step = dt / m
    for i in range(m):
        t0 = step * i
        k1 = rate(h, u0 + udot * t0)
        k2 = rate(h + 0.5 * step * k1, u0 + udot * (t0 + 0.5 * step))
        k3 = rate(h + 0.5 * step * k2, u0 + udot * (t0 + 0.5 * step))
        k4 = rate(h + step * k3, u0 + udot * (t0 + step))
        h = h + step / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return h


def advance_h(p: RefParams, h: float, u0: float, u1: float, dt: float, substeps: int = DEFAULT_SUBSTEPS) -> float:
    """h [µm] after one sample interval dt [s] in which u goes linearly from u0 to u1 [V]:
    classic RK4 with ``substeps`` equal steps."""
    udot = (u1 - u0) / dt
    return float(_rk4(lambda hh, uu: hysteresis_rate(p, hh, uu, udot), h, u0, udot, dt, _substeps(substeps)))


def advance_intervals(
    p: RefParams, h: NDArray[np.float64], u0: NDArray[np.float64], u1: NDArray[np.float64], dt: float, m: int
) -> NDArray[np.float64]:
    """:func:`advance_h` over every interval at once (interval j from u0[j] to u1[j] [V],
    starting at h[j] [µm]), ``m`` RK4 steps each: the same steps, on arrays; returns h
    at the intervals' ends [µm]."""
    udot = (u1 - u0) / dt
    with np.errstate(over="ignore", invalid="ignore"):
        end: NDArray[np.float64] = _rk4(lambda hh, uu: _rates(p, hh, uu, udot), h, u0, udot, dt, m)
    return end


def simulate(
    params: Any,
    u: ArrayLike,
    dt: float,
    h0: float = 0.0,
    u_prev: float | None = None,
    substeps: int = DEFAULT_SUBSTEPS,
    *,
    sequential: bool = False,
) -> tuple[NDArray[np.float64], float]:
    """Simulates a record by classic RK4 with ``substeps`` fixed steps per sample interval;
    returns ``(x, h_final)``, x [µm], h_final [µm].

    Same contract as :func:`boucwen.simulate`: u [V] piecewise linear between samples
    dt [s] apart; with ``u_prev=None`` h[0] = h0 [µm], otherwise the first interval
    runs from u_prev to u[0]. No other rule: no step control, no implicit steps, no
    bound on h, so it is meant for parameters whose solution is smooth and bounded
    (e.g. the paper's), and its error is that of RK4 at step dt/substeps.

    With ``sequential=True`` the intervals are stepped one after the other in pure
    Python (about 4 µs per RK4 step). By default the same numbers come from parareal
    iteration: the steps of *all* intervals run at once on NumPy arrays from the
    current guess of h at each sample, and a sequential sweep of one RK4 step per
    interval carries the corrections forward. Its fixed point is exactly the
    sequential solution (h[k+1] = F(h[k]), F being ``substeps`` RK4 steps); the
    iteration stops when max |h[k+1] − F(h[k])| ≤ 1e-13 µm and falls back to the
    sequential loop if that is not reached in 12 iterations.
    """
    p = RefParams.from_any(params)
    dt = _positive_dt(dt)
    m = _substeps(substeps)
    h0 = _finite("h0", h0)
    if u_prev is not None:
        u_prev = _finite("u_prev", u_prev)
    u_arr = _samples(u, "u")
    # The voltage at every sample point; h_at[k] belongs to points[k].
    points = u_arr if u_prev is None else np.concatenate(([u_prev], u_arr))
    h_at = None if sequential else _parareal(p, points, dt, h0, m)
    if h_at is None:
        h_at = np.empty_like(points)
        h = h0
        for k in range(points.size):
            if k:
                h = advance_h(p, h, float(points[k - 1]), float(points[k]), dt, m)
            h_at[k] = h
    if u_prev is not None:
        h_at = h_at[1:]
    if h_at.size == 0:
        return np.empty(0), h0
    return p.kv * u_arr + p.x0 + h_at, float(h_at[-1])


def _parareal(
    p: RefParams, points: NDArray[np.float64], dt: float, h0: float, m: int, tol: float = 1e-13, max_iter: int = 12
) -> NDArray[np.float64] | None:
    """The sequential solution of :func:`simulate` by parareal iteration; None if it does
    not converge."""
    count = points.size
    if count < 2:
        return np.full(count, h0)
    u_from, u_to = points[:-1].tolist(), points[1:].tolist()

    def coarse(h_start: float, j: int) -> float:
        return advance_h(p, h_start, u_from[j], u_to[j], dt, 1)

    h_at = np.empty(count)
    h_at[0] = h0
    coarse_old = np.empty(count - 1)
    with np.errstate(over="ignore", invalid="ignore"):
        try:
            for j in range(count - 1):  # first guess: the coarse rule alone
                coarse_old[j] = coarse(float(h_at[j]), j)
                h_at[j + 1] = coarse_old[j]
            for _ in range(max_iter):
                fine = advance_intervals(p, h_at[:-1], points[:-1], points[1:], dt, m)
                if not np.all(np.isfinite(fine)):
                    return None
                if np.max(np.abs(h_at[1:] - fine)) <= tol:
                    h_at[1:] = fine
                    return h_at
                # h[j+1] = G(h_new[j]) + F(h_old[j]) − G(h_old[j])
                for j in range(count - 1):
                    g_new = coarse(float(h_at[j]), j)
                    h_at[j + 1] = g_new + fine[j] - coarse_old[j]
                    coarse_old[j] = g_new
        except (OverflowError, ValueError):
            return None
    return None


# ---------------------------------------------------------------------------
# The paper's online identifier.

_UNUSED, _CROSSING, _LOADING, _UNLOADING = "unused", "crossing", "loading", "unloading"
_MIN_HALF_WIDTH = 2


@dataclass(frozen=True)
class _Point:
    """One completed window point, classified when it entered."""

    u: float
    x: float
    y: float  # regressand of step 1: x, or x − h_model
    udot: float
    a: float  # ẋ (crossing) or ln h (loading / unloading)
    b: float  # ln|A − r| (loading / unloading)
    noise2: float  # estimate of the variance of the noise of x from the local quadratic [µm²]
    kind: str = _UNUSED
    positive: bool = True  # sign of A − r (loading / unloading)


@dataclass(frozen=True)
class _Raw:
    u: float
    x: float
    h_model: float


def _step(outcome: str = "held", reason: str = "none", points: int = 0, noise: float = 0.0) -> StepStatus:
    return StepStatus(outcome, reason, int(points), float(noise))  # type: ignore[arg-type]


class PaperIdentifier:
    """The paper's online identifier, O(N) per sample (see the module docs).

    Mirrors ``boucwen.Identifier.paper``: ``push(u, x)`` predicts
    x̂ = kv·u + x0 + h [µm] with the estimates from before the sample and the
    model's own simulated h, then completes every sample whose Savitzky–Golay
    derivative stencil of half-width m is held (m from the window: ``derivative_phase``
    over the input's angular frequency), lets each enter the window of the newest
    ``window`` points and refits steps 1–5. Options and their defaults are those of the
    Rust ``PaperConfig``.
    """

    def __init__(
        self,
        dt: float,
        window: int,
        init: Any,
        h0: float = 0.0,
        *,
        decomposition: str = "model",
        h_zero_frac: float = 0.05,
        rate_frac: float = 0.2,
        min_points: int = 8,
        rank_tol: float = 1e-3,
        min_log_spread: float = 0.05,
        min_r2: float = 0.9,
        min_arg_frac: float = 0.0,
        min_line_t: float = 10.0,
        noise_gate: float = 3.0,
        derivative_phase: float = 0.1,
        max_half_width: int = 500,
        min_delta_t: float = 3.0,
        min_u_std_v: float = 1e-6,
        n_bounds: tuple[float, float] = (0.5, 4.0),
        max_hysteresis_gain: float = 4.0,
        max_delta_ratio: float = 1.0,
        output_gate: float = 1.0,
        min_stroke_frac: float = 0.5,
    ) -> None:
        self.dt = _positive_dt(dt)
        self.init = RefParams.from_any(init)
        self.h0 = _finite("h0", h0)
        if int(window) < 16:
            raise ValueError(f"invalid window = {window}: the window must hold at least 16 samples")
        self.window_len = int(window)
        if decomposition not in ("model", "line"):
            raise ValueError(f'invalid decomposition = {decomposition!r}: expected "model" or "line"')
        self.decomposition = decomposition
        if not 2 <= int(min_points) <= self.window_len:
            raise ValueError(f"invalid min_points = {min_points}: must be between 2 and the window length")
        self.min_points = int(min_points)
        if not _MIN_HALF_WIDTH <= int(max_half_width) <= 100_000:
            raise ValueError(f"invalid max_half_width = {max_half_width}: must be between 2 and 100 000 samples")
        self.max_half_width = int(max_half_width)
        if not (math.isfinite(derivative_phase) and derivative_phase > 0.0):
            raise ValueError(f"invalid derivative_phase = {derivative_phase}: must be finite and > 0")
        self.derivative_phase = float(derivative_phase)
        for name, v in [
            ("h_zero_frac", h_zero_frac),
            ("rate_frac", rate_frac),
            ("rank_tol", rank_tol),
            ("min_log_spread", min_log_spread),
            ("min_r2", min_r2),
            ("min_delta_t", min_delta_t),
            ("min_arg_frac", min_arg_frac),
            ("min_line_t", min_line_t),
            ("noise_gate", noise_gate),
            ("min_u_std_v", min_u_std_v),
            ("min_stroke_frac", min_stroke_frac),
        ]:
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"invalid {name} = {v}: must be finite and >= 0")
        lo, hi = n_bounds
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 < lo <= hi):
            raise ValueError(f"invalid n_bounds = {lo}: need 0 < n_min <= n_max, both finite")
        self.h_zero_frac = float(h_zero_frac)
        self.rate_frac = float(rate_frac)
        self.rank_tol = float(rank_tol)
        self.min_log_spread = float(min_log_spread)
        self.min_r2 = float(min_r2)
        self.min_delta_t = float(min_delta_t)
        self.min_arg_frac = float(min_arg_frac)
        self.min_line_t = float(min_line_t)
        self.noise_gate = float(noise_gate)
        self.min_u_std_v = float(min_u_std_v)
        if not max_hysteresis_gain > 0.0:
            raise ValueError(f"invalid max_hysteresis_gain = {max_hysteresis_gain}: must be > 0 (inf: no bound)")
        self.n_bounds = (float(lo), float(hi))
        if not max_delta_ratio > 0.0:
            raise ValueError(f"invalid max_delta_ratio = {max_delta_ratio}: must be > 0 (inf: no bound)")
        self.max_hysteresis_gain = float(max_hysteresis_gain)
        self.max_delta_ratio = float(max_delta_ratio)
        if math.isnan(output_gate) or output_gate < 0.0:
            raise ValueError(f"invalid output_gate = {output_gate}: must be >= 0 (inf: no gate)")
        self.output_gate = float(output_gate)
        self.min_stroke_frac = float(min_stroke_frac)
        self.reset()

    # -- public -----------------------------------------------------------

    def reset(self) -> None:
        """Back to the state right after construction."""
        self._params = self.init
        self._h = self.h0
        self._raw: deque[_Raw] = deque(maxlen=2 * self.max_half_width + 1)  # newest raw samples
        self._samples = 0
        self._next = 0  # index of the next sample to complete
        self._window: deque[_Point] = deque(maxlen=self.window_len)
        self._u_seen = (math.inf, -math.inf)  # least and greatest u seen (the stroke)
        held = _step()
        self._status = PaperStatus(0, False, False, 0, 0.0, 0.0, held, held, held, held, held, held)

    @property
    def params(self) -> RefParams:
        """The current estimates."""
        return self._params

    @property
    def h(self) -> float:
        """The model's hysteresis state h [µm] after the last sample."""
        return self._h

    @property
    def status(self) -> PaperStatus:
        """What the last push did, as ``Identifier.status`` (``refreshed`` always False:
        this class keeps no running sums)."""
        return self._status

    def push(self, u: float, x: float) -> float:
        """Takes u [V] and measured x [µm]; returns the prediction [µm] made before using x."""
        u = _finite("u", u)
        x = _finite("x", x)
        self._u_seen = (min(self._u_seen[0], u), max(self._u_seen[1], u))
        p = self._params
        if self._raw:
            # The model's own h from the core's integrator: the identification method
            # is what this class restates, not the integrator (checked on its own
            # against :func:`simulate`).
            _, self._h = core_simulate(Params(*p), [u], self.dt, self._h, self._raw[-1].u)
        prediction = p.kv * u + p.x0 + self._h
        newest = self._samples
        self._raw.append(_Raw(u, x, self._h))
        self._samples += 1

        m = self._half_width()
        first = self._samples - len(self._raw)
        completed = False
        while self._next + m <= newest:
            j = self._next
            self._next += 1
            mj = min(m, j - first)
            if j < first or mj < _MIN_HALF_WIDTH:
                continue
            self._window.append(self._complete(j - first, mj))  # the oldest leaves once N are held
            completed = True
        x_noise = math.sqrt(self._x_noise2())
        s2 = m * (m + 1.0) * (2.0 * m + 1.0) / 3.0
        self._status = dataclasses.replace(
            self._status,
            samples=self._samples,
            window_full=len(self._window) == self.window_len,
            half_width=m if completed else 0,
            x_noise_um=x_noise,
            xdot_noise_um_s=x_noise / (math.sqrt(s2) * self.dt),
        )
        self._refit()
        return prediction

    def push_many(self, u: ArrayLike, x: ArrayLike) -> NDArray[np.float64]:
        """``push`` over arrays; a non-finite value anywhere raises before any sample is used."""
        u_arr = _samples(u, "u")
        x_arr = _samples(x, "x")
        if x_arr.shape != u_arr.shape:
            raise ValueError(f"x (same length as u): expected length {u_arr.size}, found {x_arr.size}")
        return np.array([self.push(a, b) for a, b in zip(u_arr.tolist(), x_arr.tolist())])

    # -- the method ---------------------------------------------------------

    def _window_columns(self) -> dict[str, NDArray[Any]]:
        pts = list(self._window)
        cols: dict[str, NDArray[Any]] = {
            name: np.array([getattr(q, name) for q in pts], dtype=np.float64)
            for name in ("u", "x", "y", "udot", "a", "b", "noise2")
        }
        cols["kind"] = np.array([q.kind for q in pts], dtype=object)
        cols["positive"] = np.array([q.positive for q in pts], dtype=bool)
        return cols

    def _half_width(self) -> int:
        """m = round(derivative_phase / (ω̂·Δt)) within 2 … max_half_width, ω̂ =
        rms(u̇)/std(u) over the window; the largest until the window is full and where
        undefined."""
        if len(self._window) < self.window_len:
            return self.max_half_width
        w = self._window_columns()
        var_u = float(np.mean(w["u"] ** 2)) - float(np.mean(w["u"])) ** 2
        rms, sd = math.sqrt(float(np.mean(w["udot"] ** 2))), math.sqrt(max(var_u, 0.0))
        omega = rms / sd if sd > 0.0 else (math.inf if rms > 0.0 else math.nan)
        m = self.derivative_phase / (omega * self.dt) if omega > 0.0 else math.inf
        m = math.floor(m + 0.5) if math.isfinite(m) else m
        return max(int(m), _MIN_HALF_WIDTH) if math.isfinite(m) and m < self.max_half_width else self.max_half_width

    def _x_noise2(self) -> float:
        return max(float(np.mean([q.noise2 for q in self._window])), 0.0) if self._window else 0.0

    def _ln_saturation(self) -> float | None:
        """ln hₛ, hₛ = (|A₀|/(|β₀|+|γ₀|))^(1/n₀) of the starting model (None if undefined)."""
        a0, s0 = abs(self.init.A), abs(self.init.beta) + abs(self.init.gamma)
        return (math.log(a0) - math.log(s0)) / self.init.n if a0 > 0.0 and s0 > 0.0 else None

    def _complete(self, c: int, m: int) -> _Point:
        """The window point of raw sample ``c`` (position in the raw history) with a stencil
        of half-width m, classified with the current estimates and the statistics of the
        window before it enters. u̇, ẋ: the Savitzky–Golay first derivative; the noise of x
        from the residual of the local quadratic at the centre."""
        p = self._params
        raw = list(self._raw)
        mid = raw[c]
        k = np.arange(1, m + 1, dtype=np.float64)
        after, before = raw[c + 1 : c + m + 1], raw[c - m : c][::-1]
        ua = np.array([r.u for r in after]) - np.array([r.u for r in before])
        xa = np.array([r.x for r in after]) - np.array([r.x for r in before])
        xs = np.array([r.x for r in after]) + np.array([r.x for r in before])
        s2 = m * (m + 1.0) * (2.0 * m + 1.0) / 3.0
        udot = float(np.sum(k * ua)) / (s2 * self.dt)
        xdot = float(np.sum(k * xa)) / (s2 * self.dt)
        c0 = 3.0 * (3.0 * m * m + 3.0 * m - 1.0)
        den = (2.0 * m - 1.0) * (2.0 * m + 1.0) * (2.0 * m + 3.0)
        smooth = (c0 * (float(np.sum(xs)) + mid.x) - 15.0 * float(np.sum(k * k * xs))) / den
        noise2 = (mid.x - smooth) ** 2 / (1.0 - c0 / den)
        y = mid.x if self.decomposition == "line" else mid.x - mid.h_model
        unused = _Point(mid.u, mid.x, y, udot, 0.0, 0.0, noise2)
        if len(self._window) < self.window_len:  # classified only once the window is full
            return unused
        w = self._window_columns()
        std_x = float(np.std(w["x"]))
        rms_rate = math.sqrt(float(np.mean(w["udot"] ** 2)))
        ln_hs = self._ln_saturation()
        h_tol = self.h_zero_frac * (std_x if ln_hs is None else math.exp(ln_hs))
        if abs(udot) <= self.rate_frac * rms_rate or udot == 0.0 or h_tol == 0.0:
            return unused
        h = mid.x - p.kv * mid.u - p.x0
        hdot = xdot - p.kv * udot
        xdot_noise = math.sqrt(self._x_noise2() / (s2 * self.dt * self.dt))
        if udot > 0.0 and abs(h) < h_tol:  # step 2 point: u̇ > 0, h ≈ 0, ẋ above its noise
            if abs(xdot) < self.noise_gate * xdot_noise:
                return unused
            # ẋ less the small |h|^n terms of eq. (5) at this h (current β, γ, n).
            hn = 0.0 if h == 0.0 else _pow(abs(h), p.n)
            xdot_c = xdot + (p.beta * abs(udot) * _sgn(h) + p.gamma * udot) * hn
            return _Point(mid.u, mid.x, y, udot, xdot_c, 0.0, noise2, _CROSSING)
        if h > h_tol:
            # Loading (u̇ > 0): r = (ḣ − δu)/u̇ = A − (β+γ)hⁿ.
            # Unloading (u̇ < 0): r = (ḣ + δu)/u̇ = A − (γ−β)hⁿ.
            r = (hdot - p.delta * mid.u) / udot if udot > 0.0 else (hdot + p.delta * mid.u) / udot
            arg = p.A - r
            # |A − r| below min_arg_frac·|A|, or |A − r|·|u̇| below noise_gate noise
            # standard deviations of ẋ, is left out.
            resolved = abs(arg) * abs(udot) >= self.noise_gate * xdot_noise
            if math.isfinite(arg) and arg != 0.0 and abs(arg) >= self.min_arg_frac * abs(p.A) and resolved:
                kind = _LOADING if udot > 0.0 else _UNLOADING
                return _Point(mid.u, mid.x, y, udot, math.log(h), math.log(abs(arg)), noise2, kind, arg > 0.0)
        return unused

    def _hysteresis_bounded(self, beta: float, gamma: float, n: float) -> bool:
        """(|β|+|γ|)·hₛⁿ ≤ max_hysteresis_gain·|A₀|, hₛ the starting model's saturation
        amplitude, compared in logarithms (off when hₛ is undefined)."""
        ln_hs = self._ln_saturation()
        if math.isinf(self.max_hysteresis_gain) or ln_hs is None:
            return True
        total = abs(beta) + abs(gamma)
        ln_total = math.log(total) if total > 0.0 else -math.inf
        return ln_total + n * ln_hs <= math.log(self.max_hysteresis_gain * abs(self.init.A))

    def _window_sse(self, p: dict[str, float]) -> float:
        """The window's own output error of the estimates ``p``: Σ (x − x̂)² over the
        window's points, x̂ the model simulated over the window's inputs from h at the
        oldest point as ``p`` reads it there (x − kv·u − x0); inf where it cannot be
        simulated or leaves the finite numbers."""
        pts = list(self._window)
        h0 = pts[0].x - p["kv"] * pts[0].u - p["x0"]
        try:
            xs, _ = core_simulate(Params(*RefParams(**p)), np.array([q.u for q in pts]), self.dt, h0)
        except ValueError:
            return math.inf
        sse = 0.0
        for q, v in zip(pts, xs.tolist()):
            e = q.x - v
            sse = sse + e * e
        return sse if math.isfinite(sse) else math.inf

    def _gate(self, held: dict[str, float], candidate: dict[str, float], k: float, memo: list[float]) -> bool:
        """The output gate: whether ``candidate`` (changing ``k`` unknowns of ``held``) is
        taken, i.e. it raises the window's output error by at most output_gate·k·σ̂²;
        ``memo`` holds the error of the estimates taken so far (empty until needed)."""
        if self.output_gate == math.inf or candidate == held:
            return True
        if not memo:
            memo.append(self._window_sse(held))
        before, after = memo[0], self._window_sse(candidate)
        per_unknown = self.output_gate * self._x_noise2()
        taken = math.isfinite(after) and (before == math.inf or after <= before + k * per_unknown)
        if taken:
            memo[0] = after
        return taken

    def _refit(self) -> None:
        p = self._params._asdict()
        w = self._window_columns()
        count = len(self._window)
        steps: dict[str, StepStatus] = {}
        memo: list[float] = []  # the output gate's error of the estimates taken so far

        # A window whose rising or falling points span too little of the stroke holds
        # every step (min_stroke_frac).
        if count == self.window_len and self.min_stroke_frac > 0.0:
            # (An input that has never moved is step 1's to report: no excitation.)
            stroke = self._u_seen[1] - self._u_seen[0]
            branches = ([q.u for q in self._window if q.udot > 0.0], [q.u for q in self._window if q.udot < 0.0])
            if stroke > 0.0 and not all(b and max(b) - min(b) >= self.min_stroke_frac * stroke for b in branches):
                none = _step(reason="no_spread")
                steps.update(line_fit=_step(reason="no_spread", points=count), rate_fit=none)
                steps.update(shape_fit=none, return_fit=none, split_fit=none)
                self._finish(p, steps)
                return

        # Step 1: kv, x0 = least squares of y on [u, 1] over the full window.
        excited = count >= 2 and float(np.var(w["u"])) > self.min_u_std_v**2
        steps["line_fit"] = _step(reason="window_filling", points=count)
        if count == self.window_len and not excited:
            steps["line_fit"] = _step(reason="no_excitation", points=count)
        elif count == self.window_len:
            steps["line_fit"] = _step(reason="noise", points=count)
            gram = np.array([[np.sum(w["u"] ** 2), np.sum(w["u"])], [np.sum(w["u"]), count]])
            rhs = np.array([np.sum(w["u"] * w["y"]), np.sum(w["y"])])
            if np.linalg.det(gram) != 0.0:
                theta = np.linalg.solve(gram, rhs)
                kv, x0 = float(theta[0]), float(theta[1])
                # kv must be resolved: |kv| ≥ min_line_t standard errors.
                rss = max(float(np.sum(w["y"] ** 2)) - kv * float(rhs[0]) - x0 * float(rhs[1]), 0.0)
                var_u = float(np.mean(w["u"] ** 2)) - float(np.mean(w["u"])) ** 2
                se_kv = math.sqrt(rss / (count - 2.0) / (count * var_u)) if count > 2 else math.inf
                if np.all(np.isfinite(theta)) and abs(kv) >= self.min_line_t * se_kv:
                    candidate = {**p, "kv": kv, "x0": x0}
                    if self._gate(p, candidate, 2.0, memo):
                        p = candidate
                        steps["line_fit"] = _step("ran", points=count, noise=math.sqrt(rss / (count - 2.0)))
                    else:
                        steps["line_fit"] = _step(reason="worse_output", points=count)

        if count < self.window_len:  # steps 2–5 wait for the window's N points
            filling = _step(reason="window_filling")
            steps.update(rate_fit=filling, shape_fit=filling, return_fit=filling, split_fit=filling)
            self._finish(p, steps)
            return
        kind = w["kind"]

        # Step 2 (eqs. 8–9): ẋ = (A + kv)·u̇ + δ·u on the crossing points.
        sel = kind == _CROSSING
        npts = int(sel.sum())
        d, uu, xd = w["udot"][sel], w["u"][sel], w["a"][sel]
        c1, c2, c3 = float(np.sum(d * d)), float(np.sum(d * uu)), float(np.sum(uu * uu))
        if npts < self.min_points:
            steps["rate_fit"] = _step(reason="too_few_points", points=npts)
        elif c1 <= 0.0:
            steps["rate_fit"] = _step(reason="no_spread", points=npts)
        else:
            c4, c5, c6 = float(np.sum(d * xd)), float(np.sum(uu * xd)), float(np.sum(xd * xd))
            det = c1 * c3 - c2 * c2
            well_posed = c3 > 0.0 and det > self.rank_tol * c1 * c3
            full_a, full_delta = ((c4 * c3 - c2 * c5) / det, (c1 * c5 - c2 * c4) / det) if well_posed else (0.0, 0.0)
            # δ only where resolved: |δ| ≥ min_delta_t standard errors of the two-column fit,
            # inflated by the stencil's span (neighbouring derivatives share their noise),
            # and δ·u not outweighing the rate term on the points (max_delta_ratio).
            span = 2.0 * self._half_width() + 1.0
            # The residual variance floored at the derivative's own error, (θ²/10)·ẋ.
            dof = npts - 2.0
            rss = max(c6 - full_a * c4 - full_delta * c5, 0.0)
            bias2 = (self.derivative_phase**2 / 10.0) ** 2 * c6 / npts
            var = max(rss / dof, bias2) if dof > 0.0 else math.inf
            se_delta = math.sqrt(span * var * c1 / det) if well_posed else math.inf
            # The rate term from the fit with δ held.
            suy = c4 - p["delta"] * c2
            reduced = suy / c1
            syy = c6 - 2.0 * p["delta"] * c5 + p["delta"] ** 2 * c3
            reduced_noise = math.sqrt(max(syy - reduced * suy, 0.0) / max(npts - 1.0, 1.0))
            bounded = abs(full_delta) * math.sqrt(c3) <= self.max_delta_ratio * abs(reduced) * math.sqrt(c1)
            if not well_posed:
                why = "no_spread"
            elif not (math.isfinite(full_delta) and abs(full_delta) >= self.min_delta_t * se_delta):
                why = "noise"
            elif not bounded:
                why = "out_of_bounds"
            else:
                why = "none"
            if why == "none":
                a_plus_kv = full_a
                steps["rate_fit"] = _step("ran", points=npts, noise=math.sqrt(rss / dof))
                new_delta = full_delta
            else:
                a_plus_kv = reduced
                steps["rate_fit"] = _step("reduced", why, npts, reduced_noise)
                new_delta = p["delta"]
            if math.isfinite(a_plus_kv):
                candidate = {**p, "A": a_plus_kv - p["kv"], "delta": new_delta}
                if not self._gate(p, candidate, 2.0 if why == "none" else 1.0, memo):
                    steps["rate_fit"] = _step(reason="worse_output", points=npts)
                else:
                    p = candidate
            else:
                steps["rate_fit"] = _step(reason="out_of_bounds", points=npts)

        # Step 3 (eqs. 10–12): ln|A − r| = ln|β+γ| + n·ln h on the loading points
        # of the larger sign group.
        sum_bg = p["beta"] + p["gamma"]
        n_new = p["n"]
        pos = (kind == _LOADING) & w["positive"]
        neg = (kind == _LOADING) & ~w["positive"]
        sel, sign = (pos, 1.0) if pos.sum() >= neg.sum() else (neg, -1.0)
        npts = int(sel.sum())
        steps["shape_fit"] = _step(reason="too_few_points", points=npts)
        if npts >= self.min_points:
            z, wv = w["a"][sel], w["b"][sel]
            var_z = float(np.var(z))
            var_w = float(np.var(wv))
            cov = float(np.mean((z - z.mean()) * (wv - wv.mean())))
            r2 = cov * cov / (var_z * var_w) if var_z > 0.0 and var_w > 0.0 else 0.0
            n = cov / var_z if var_z > 0.0 else 0.0
            log_mag = min(max(float(wv.mean()) - n * float(z.mean()), -700.0), 700.0)
            if var_z <= self.min_log_spread**2:
                steps["shape_fit"] = _step(reason="no_spread", points=npts)
            elif r2 < self.min_r2:
                steps["shape_fit"] = _step(reason="noise", points=npts)
            elif not (self.n_bounds[0] <= n <= self.n_bounds[1] and math.isfinite(log_mag)):
                steps["shape_fit"] = _step(reason="out_of_bounds", points=npts)
            else:
                n_new = n
                sum_bg = sign * math.exp(log_mag)
                noise = math.sqrt(max(var_w - cov * cov / var_z, 0.0) * npts / max(npts - 2.0, 1.0))
                steps["shape_fit"] = _step("ran", points=npts, noise=noise)

        # Step 4 (eqs. 13–14): ln|γ−β| = mean(ln|A − r| − n·ln h) on the unloading points.
        diff_gb = p["gamma"] - p["beta"]
        pos = (kind == _UNLOADING) & w["positive"]
        neg = (kind == _UNLOADING) & ~w["positive"]
        sel, sign = (pos, 1.0) if pos.sum() >= neg.sum() else (neg, -1.0)
        npts = int(sel.sum())
        steps["return_fit"] = _step(reason="too_few_points", points=npts)
        if npts >= self.min_points:
            dd = w["b"][sel] - n_new * w["a"][sel]
            log_mag = min(max(float(np.mean(dd)), -700.0), 700.0)
            if math.isfinite(log_mag):
                diff_gb = sign * math.exp(log_mag)
                noise = math.sqrt(float(np.var(dd)) * npts / max(npts - 1.0, 1.0))
                steps["return_fit"] = _step("ran", points=npts, noise=noise)
            else:
                steps["return_fit"] = _step(reason="out_of_bounds", points=npts)

        # Step 5 (eqs. 15–16), accepted only where h stays bounded for every
        # input (β + γ > 0 and β − γ > 0) and the hysteresis terms stay physically
        # bounded (max_hysteresis_gain); otherwise β, γ and n are held.
        beta, gamma = 0.5 * (sum_bg - diff_gb), 0.5 * (sum_bg + diff_gb)
        if steps["shape_fit"].outcome != "ran" and steps["return_fit"].outcome != "ran":
            steps["split_fit"] = _step(reason="upstream")
        elif beta + gamma > 0.0 and beta - gamma > 0.0 and self._hysteresis_bounded(beta, gamma, n_new):
            candidate = {**p, "beta": beta, "gamma": gamma, "n": n_new}
            if self._gate(p, candidate, 3.0, memo):
                p = candidate
                steps["split_fit"] = _step("ran")
            else:
                steps["split_fit"] = _step(reason="worse_output")
        else:
            steps["split_fit"] = _step(reason="out_of_bounds")
        self._finish(p, steps)

    def _finish(self, p: dict[str, float], steps: dict[str, StepStatus]) -> None:
        new = RefParams(**p)
        if new.is_valid():
            self._params = new
        else:
            steps["split_fit"] = _step(reason="out_of_bounds")
        self._status = dataclasses.replace(self._status, **steps)  # type: ignore[arg-type]
