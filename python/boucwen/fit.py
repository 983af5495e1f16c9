"""Offline ("traditional") identification: output-error least squares.

Given a record of voltage u [V] and displacement x [µm] sampled every dt [s],
:func:`fit` finds the seven parameters of the asymmetric Bouc–Wen model

    x = kv·u + x0 + h                                             (3)
    dh/dt = A·u̇ − β·|u̇|·|h|^(n−1)·h − γ·u̇·|h|^n + δ·u·sgn(u̇)      (5)

and the initial state h0 = h[0] [µm] that minimise the output error
Σ (x_k − x̂_k)², where x̂ is *simulated* from u alone (the Rust integrator behind
:func:`boucwen.simulate`), never computed from the measured x. Names A, β, γ, n,
δ follow the paper (Zhu, Bian & Rui 2014); units as in :class:`boucwen.Params`.

How it works:

* **Separable least squares.** h depends on (A, β, γ, n, δ, h0) only, and x̂ is
  linear in (kv, x0). For given nonlinear parameters the best (kv, x0) is the
  linear least-squares fit of x − h on [u, 1]; the optimiser only sees the
  residual projected off span{u, 1} (variable projection), six unknowns instead
  of eight and no starting point needed for kv, x0.
* **The admissible region.** The unknowns are β + γ and β − γ rather than β and γ,
  each bounded below by 0, so that the solver cannot leave the region where h stays
  bounded (:mod:`boucwen.region`; docs/design.md, "The admissible region"). A start
  outside it (``init``) is refused.
* **Scaling.** Every unknown is divided by a scale derived from the record (the
  loop's slope for A, its half-width for h0, A/half-width^1.5 for β and γ — √2 times
  that for β ± γ, so that the scaled pair is an orthogonal transform of the scaled
  (β, γ) and a step inside the region is the same in either — the half-width per
  volt-second of travel for δ), so that β, γ ~ 1e-2 and δ ~ 1e-3 weigh like A and n.
* **Global stage, then local.** ``n_candidates`` random points around those
  scales (sign of A either way, n in [1, 2.5], β and γ set from a saturation
  level of h between 0.3 and 3 half-widths, δ of either sign) are scored by one
  simulation each on a decimated copy of the record; the best ``n_starts`` (plus
  ``init`` if given) are refined by the local solver (bounds keep n in ``N_BOUNDS``
  and β ± γ ≥ 0) on the decimated record, and the best
  of those is refined on the full record. Residual, Jacobian (exact, from the Rust
  core in one pass with the simulation) and optimiser are those of :mod:`boucwen.lsq`,
  shared with :func:`boucwen.effects.fit_extended`.
* **x0 and h0.** They trade off: a different h0 shifts h until the hysteresis
  forgets it (about half a cycle), which x0 partly absorbs. h0 is fitted from that
  initial transient; a weak pull of weight ``H0_RIDGE`` towards 0 keeps it defined
  when the record carries no information on it (e.g. it starts in periodic steady
  state). Pass ``h0=0.0`` (or any value) to fix it instead.
* **δ within its limit.** The δ term acts per second of motion, not per volt
  (docs/design.md, "The admissible region"), so a δ the record's fast moves ask for drives
  h on a slow input of the same range. δ is kept within :func:`record_delta_limit`: at
  the slowest full-range sweep the record's length allows, the term may add at most
  :data:`~boucwen.region.DELTA_RATIO` times what the loop's slope adds per volt (beyond,
  it stands in for something else and drives h alone on slow inputs).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._core import InvalidConfig, InvalidRecord, Params, simulate, simulate_extended_with_jacobian, simulate_many
from .checks import FloatArray, check_finite, check_int
from .levenberg import STATISTICAL_MARGIN
from .lsq import (
    Method,
    OutputErrorProblem,
    Ridge,
    Solution,
    finite_or_none,
    with_jacobian_or_none,
    worker_count,
    worker_threads,
)
from .metrics import max_abs, rms
from .progress import Progress, reporter
from .record import Record, validate_record
from .region import SPLIT_JACOBIAN, check, delta_limit, pair, split

__all__ = ["H0_RIDGE", "N_BOUNDS", "FitResult", "fit", "fit_record", "record_delta_limit"]

#: Bounds on the exponent n [-] during the fit.
N_BOUNDS = (0.2, 6.0)
#: Weight [-] of the residual row ``H0_RIDGE · h0`` that pulls h0 towards 0 µm.
H0_RIDGE = 1e-3
#: Target length of the decimated record used by the global stage [samples].
_COARSE_LEN = 3000
#: Largest change of u between decimated samples, as a fraction of the span of u.
_COARSE_DU = 0.03

#: Two local runs whose costs agree to this relative tolerance found the same optimum.
_SAME_COST = 1e-4
#: The local runs on the decimated record stop where the remaining step is within half a
#: standard error of that record's fit (the full record's stage: a tenth of its own,
#: :data:`~boucwen.levenberg.STATISTICAL_MARGIN`). The decimated record's optimum lies
#: about one such standard error from the full record's, which the full-record stage
#: reaches from it, so refining it further buys nothing. At most _SAME_COST·(N − p): a
#: run stopped there is above its optimum by at most margin/(N − p) of the cost, so two
#: runs to one optimum still agree within _SAME_COST.
_COARSE_MARGIN = 0.25


@dataclass(frozen=True, eq=False)
class FitResult:
    """Result of :func:`fit`.

    Attributes:
        params: the identified :class:`boucwen.Params` (kv µm/V, x0 µm, A µm/V,
            β and γ µm^(1−n)/V, n, δ µm/(V·s)).
        h0: the identified initial hysteresis state h[0] [µm].
        rms_um: root-mean-square output error [µm] of ``x_fit`` against the data.
        max_um: maximum absolute output error [µm].
        success: the local optimiser reported convergence and the error is finite.
        message: the optimiser's message, with the stage it comes from.
        nfev: number of record simulations, all stages and Jacobian passes included.
        x_fit: the simulated displacement [µm] of the fitted model, same length as x.
        elapsed_s: wall time of the fit [s].
    """

    params: Params
    h0: float
    rms_um: float
    max_um: float
    success: bool
    message: str
    nfev: int
    x_fit: FloatArray
    elapsed_s: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (without ``x_fit``)."""
        return {
            "params": self.params.to_dict(),
            "h0_um": self.h0,
            "rms_um": self.rms_um,
            "max_um": self.max_um,
            "success": self.success,
            "message": self.message,
            "nfev": self.nfev,
            "elapsed_s": self.elapsed_s,
        }

    def __repr__(self) -> str:
        return (
            f"FitResult(params={self.params!r}, h0={self.h0!r}, rms_um={self.rms_um:.4g}, "
            f"max_um={self.max_um:.4g}, success={self.success}, nfev={self.nfev})"
        )


# --------------------------------------------------------------------------- problem


class _Hysteresis:
    """The nonlinear part of the separable problem: scaled unknowns z → h [µm].

    z holds (A, β + γ, β − γ, n, δ, h0) divided by ``scale`` (without h0 when it is
    fixed); :meth:`theta` turns it into (A, β, γ, n, δ, h0).
    """

    def __init__(self, u: FloatArray, dt: float, scale: FloatArray, fixed_h0: float | None):
        self.u, self.dt, self.scale, self.fixed_h0 = u, dt, scale, fixed_h0
        # The last (unknowns, h) simulated: the optimiser's last point is simulated
        # already (one tuple, replaced whole, so threads read a consistent pair).
        self._last: tuple[bytes, FloatArray] | None = None

    def _remember(self, z: FloatArray, h: FloatArray | None) -> FloatArray | None:
        if h is not None:
            self._last = (z.tobytes(), h)
        return h

    def simulated(self, z: FloatArray) -> FloatArray | None:
        """h [µm] for z: the last simulation's if it was at z, else a new one."""
        last = self._last
        return last[1] if last is not None and last[0] == z.tobytes() else self(z)

    @property
    def nvar(self) -> int:
        """Number of unknowns: 5 with h0 fixed, else 6."""
        return 5 if self.fixed_h0 is not None else 6

    def theta(self, z: FloatArray) -> FloatArray:
        """Scaled unknowns → (A, β, γ, n, δ, h0)."""
        th = np.empty(6)
        th[: self.nvar] = z[: self.nvar] * self.scale[: self.nvar]
        th[1], th[2] = split(th[1], th[2])
        if self.fixed_h0 is not None:
            th[5] = self.fixed_h0
        return th

    def _params(self, th: FloatArray) -> Params:
        """The model with (A, β, γ, n, δ) of ``th`` and kv = x0 = 0, whose output is h."""
        return Params(0.0, 0.0, th[0], th[1], th[2], th[3], th[4])

    def __call__(self, z: FloatArray) -> FloatArray | None:
        """h [µm] simulated for the unknowns z, or None if they cannot be simulated."""
        th = self.theta(z)
        return self._remember(z, finite_or_none(lambda: simulate(self._params(th), self.u, self.dt, float(th[5]))[0]))

    def many(self, zs: Sequence[FloatArray]) -> list[FloatArray | None]:
        """h [µm] for each z of ``zs`` (None where one cannot be simulated), in one
        call of :func:`boucwen.simulate_many` when they share h0."""
        thetas = [self.theta(z) for z in zs]
        if not thetas or any(th[5] != thetas[0][5] for th in thetas):
            return [self(z) for z in zs]
        hs = finite_or_none(
            lambda: simulate_many([self._params(th) for th in thetas], self.u, self.dt, float(thetas[0][5]))
        )
        if hs is not None:
            return list(hs)
        # Some set diverged: the finite rows stand, each checked alone.
        return [self(z) for z in zs]

    def with_jacobian(self, z: FloatArray) -> tuple[FloatArray, FloatArray] | None:
        """(h [µm], ∂h/∂z) for the unknowns z, from one pass, or None if they cannot be
        simulated."""
        th = self.theta(z)
        params, h0 = self._params(th), float(th[5])
        out = with_jacobian_or_none(lambda: simulate_extended_with_jacobian(params, None, self.u, self.dt, h0))
        if out is None:
            return None
        h, jac = out
        self._remember(z, h)
        # Columns kv, x0, A, β, γ, n, δ, h0 of the core; β, γ turned into β ± γ, and
        # z = θ / scale (in place: no second array of the record's length).
        ds = jac[:, 2 : 2 + self.nvar]
        ds[:, 1:3] = ds[:, 1:3] @ SPLIT_JACOBIAN
        ds *= self.scale[: self.nvar]
        return h, ds


def _problem(record: Record, scale: FloatArray, fixed_h0: float | None) -> tuple[OutputErrorProblem, _Hysteresis]:
    """The variable-projection problem on one (possibly decimated) record."""
    hysteresis = _Hysteresis(record.u, record.dt, scale, fixed_h0)
    ridge = Ridge(index=5, weight=H0_RIDGE, scale=float(scale[5])) if fixed_h0 is None else None
    basis = np.column_stack([record.u, np.ones_like(record.u)])
    problem = OutputErrorProblem(
        hysteresis, hysteresis.with_jacobian, record.x, basis=basis, ridge=ridge, simulate_many=hysteresis.many
    )
    return problem, hysteresis


def _line(u: FloatArray, y: FloatArray) -> tuple[float, float]:
    """(slope, intercept) of the least-squares line y ≈ slope·u + intercept (u not
    constant): the normal equations of the two columns [u, 1], solved about the mean."""
    u_mean, y_mean = float(np.mean(u)), float(np.mean(y))
    du = u - u_mean
    slope = float(du @ (y - y_mean)) / float(du @ du)
    return slope, y_mean - slope * u_mean


def _linear_part(record: Record, h: FloatArray) -> tuple[float, float]:
    """(kv, x0) of the least-squares fit of x − h on [u, 1]."""
    return _line(record.u, record.x - h)


# --------------------------------------------------------------------------- guesses


def _scales(u: FloatArray, x: FloatArray, dt: float) -> FloatArray:
    """Scale of (A, β + γ, β − γ, n, δ, h0) derived from the record."""
    slope, intercept = _line(u, x)
    resid = x - (slope * u + intercept)
    span_x = float(np.ptp(x))
    half_width = max(0.5 * float(np.ptp(resid)), 1e-6 * max(span_x, 1e-12), 1e-12)
    span_u = float(np.ptp(u))
    s_a = max(abs(float(slope)), half_width / span_u)
    s_bg = s_a / half_width**1.5
    # Time the voltage spends moving one way: record duration / number of reversals.
    du = np.diff(u)
    du = du[np.abs(du) > 1e-9 * span_u]
    reversals = int(np.count_nonzero(np.diff(np.sign(du)) != 0)) if du.size > 1 else 0
    duration = dt * (u.size - 1)
    t_half = duration / max(1, reversals)
    u_level = max(float(np.mean(np.abs(u))), 0.5 * span_u)
    s_delta = half_width / (u_level * t_half)
    # β ± γ at √2 times the scale of β and γ: the scaled pair is an orthogonal transform
    # of the scaled (β, γ), so the trust region's metric is the same in either.
    s_pair = math.sqrt(2.0) * s_bg
    return np.array([s_a, s_pair, s_pair, 1.0, s_delta, half_width])


def record_delta_limit(record: Record) -> float:
    """The largest |δ| [µm/(V·s)] a fit allows on ``record``: :func:`boucwen.region.delta_limit`
    with the record's loop slope scale (that of A in :func:`fit`)."""
    u = record.u
    slope = float(_scales(u, record.x, record.dt)[0])
    return delta_limit(slope, float(np.ptp(u)), float(np.max(np.abs(u))), record.duration_s)


def _candidates(rng: np.random.Generator, count: int, half_width: float) -> FloatArray:
    """Random starting points in scaled units (A, β + γ, β − γ, n, δ, h0)."""
    z = np.zeros((count, 6))
    mag = np.exp(rng.uniform(math.log(0.05), math.log(2.0), count))
    z[:, 0] = rng.choice([-1.0, 1.0], count) * mag
    z[:, 3] = rng.uniform(1.0, 2.5, count)
    # Saturation level of h (in half-widths) → size of β, γ: |A| / hs^n, in scaled units
    # (the β scale already divides by half_width^1.5).
    hs = np.exp(rng.uniform(math.log(0.3), math.log(3.0), count))
    sigma = mag / hs ** z[:, 3] * half_width ** (1.5 - z[:, 3])
    # β > |γ| (β + γ > 0 and β − γ > 0): inside the admissible region, h stays bounded.
    beta = sigma * rng.uniform(0.05, 1.0, count)
    gamma = beta * rng.uniform(-0.95, 0.95, count)
    # (β, γ) in units of their scale → (β ± γ) in units of √2 times it.
    z[:, 1], z[:, 2] = (beta + gamma) / math.sqrt(2.0), (beta - gamma) / math.sqrt(2.0)
    z[:, 4] = rng.uniform(-1.0, 1.0, count)
    return z


def _decimation(u: FloatArray) -> int:
    q = max(1, u.size // _COARSE_LEN)
    span = float(np.ptp(u))
    while q > 1:
        if float(np.max(np.abs(u[q:] - u[:-q]))) <= _COARSE_DU * span and u.size // q >= 200:
            break
        q //= 2
    return q


# --------------------------------------------------------------------------- fit


def _local(
    problem: OutputErrorProblem,
    nvar: int,
    z0: FloatArray,
    max_nfev: int,
    tol: float,
    method: Method,
    margin: float = STATISTICAL_MARGIN,
    delta_limit: float = math.inf,
) -> Solution:
    """The local solver ``method`` from ``z0`` (n kept in :data:`N_BOUNDS`, β ± γ ≥ 0: the
    admissible region, |δ| ≤ ``delta_limit`` in scaled units); with ``"lm"``, a Jacobian
    is kept while it predicts the steps and the run stops where the remaining step is
    within ``margin`` squared standard errors (:mod:`boucwen.levenberg`)."""
    lb = np.full(nvar, -np.inf)
    ub = np.full(nvar, np.inf)
    lb[1] = lb[2] = 0.0
    lb[3], ub[3] = N_BOUNDS
    lb[4], ub[4] = -delta_limit, delta_limit
    z0 = z0[:nvar].copy()
    z0[3] = min(max(z0[3], N_BOUNDS[0] + 1e-9), N_BOUNDS[1] - 1e-9)
    # A start on the region's edge (β ± γ = 0: a linear start) just inside it; a δ beyond
    # its limit at it.
    z0[1:3] = np.maximum(z0[1:3], 1e-9)
    z0[4] = min(max(z0[4], -delta_limit * (1 - 1e-9)), delta_limit * (1 - 1e-9))
    return problem.solve(
        z0, lb, ub, x_scale=1.0, tol=tol, max_nfev=max_nfev, method=method, margin=margin, reuse_jacobian=True
    )


def fit(
    u: Any,
    x: Any,
    dt: float,
    *,
    init: Params | None = None,
    h0: float | None = None,
    n_starts: int = 4,
    n_candidates: int = 32,
    seed: int = 0,
    max_nfev: int = 40,
    decimate: int | None = None,
    workers: int | None = None,
    progress: Progress = False,
    method: Method = "lm",
) -> FitResult:
    """Identifies the seven parameters and h0 from a record by output-error least squares.

    Args:
        u: voltage samples [V], 1-D, finite, not constant, at least 16 samples.
        x: measured displacement [µm], same length as ``u``.
        dt: sampling interval [s] (> 0); u is taken as linear between samples.
        init: optional starting parameters (e.g. from an earlier fit), in the
            admissible region (:mod:`boucwen.region`); always among the starts of the
            local stage.
        h0: ``None`` (default) to identify h[0] [µm]; a number to fix it.
        n_starts: how many of the best global candidates are refined locally (≥ 1).
        n_candidates: random candidates scored in the global stage (≥ 0).
        seed: seed of the random candidates (same seed, same result).
        max_nfev: iteration limit of each local least-squares run.
        decimate: keep every ``decimate``-th sample for the global stage; ``None``
            chooses it so that the coarse record has about 3000 samples and u moves
            less than 3 % of its span between them; 1 disables decimation.
        workers: threads scoring the global stage's candidates (default: the number
            of CPUs).
        progress: ``True`` to print progress lines to stderr, or a callable taking a str.
        method: the local solver: ``"lm"`` (:mod:`boucwen.levenberg`, the default) or
            ``"trf"`` (SciPy's trust-region reflective, a pass of the core per accepted
            step and a full-record stage from scratch: slower, for comparison).

    Returns:
        A :class:`FitResult`.

    Raises:
        TypeError: non-numeric data or dt, or ``init`` not a Params.
        ValueError: bad shapes, lengths, non-finite values, dt not > 0, constant u,
            fewer than 16 samples, or bad option values; ``InvalidParams`` for an
            ``init`` outside the admissible region.
    """
    return fit_record(
        validate_record(u, x, dt),
        init=init,
        h0=h0,
        n_starts=n_starts,
        n_candidates=n_candidates,
        seed=seed,
        max_nfev=max_nfev,
        decimate=decimate,
        workers=workers,
        progress=progress,
        method=method,
    )


def fit_record(
    record: Record,
    *,
    init: Params | None = None,
    h0: float | None = None,
    n_starts: int = 4,
    n_candidates: int = 32,
    seed: int = 0,
    max_nfev: int = 40,
    decimate: int | None = None,
    workers: int | None = None,
    progress: Progress = False,
    method: Method = "lm",
) -> FitResult:
    """:func:`fit` on a checked :class:`~boucwen.record.Record` (same options, same result)."""
    started = time.perf_counter()
    if record.u.size < 16:
        raise InvalidRecord(f"fit needs at least 16 samples, got {record.u.size}")
    if not np.ptp(record.u) > 0:
        raise InvalidRecord("u is constant; the fit needs a varying voltage")
    if init is not None and not isinstance(init, Params):
        raise TypeError(f"init must be a boucwen.Params, got {type(init).__name__}")
    if init is not None:
        check(init)
    if h0 is not None:
        h0 = check_finite("h0", h0)
    check_int("n_starts", n_starts, 1)
    check_int("n_candidates", n_candidates, 0)
    check_int("max_nfev", max_nfev, 1)
    if method not in ("lm", "trf"):
        raise InvalidConfig(f"method must be 'lm' or 'trf', got {method!r}")
    if decimate is not None:
        check_int("decimate", decimate, 1)
    say = reporter(progress, "fit", started, width=5)

    u, x, dt = record.u, record.x, record.dt
    scale = _scales(u, x, dt)
    q = decimate if decimate is not None else _decimation(u)
    # How far δ may go (scaled).
    delta_z = record_delta_limit(record) / scale[4]
    with worker_threads(workers) as pool:
        full, hysteresis = _problem(record, scale, h0)
        coarse_record = record if q == 1 else record.decimated(q)
        coarse = full if q == 1 else _problem(coarse_record, scale, h0)[0]
        coarse_u_size = len(coarse_record)
        nvar = hysteresis.nvar

        # Global stage: score random candidates with one simulation each.
        rng = np.random.default_rng(seed)
        cands = _candidates(rng, n_candidates, scale[5])
        if h0 is not None:
            cands[:, 5] = h0 / scale[5]
        starts: list[FloatArray] = []
        if init is not None:
            plus, minus = pair(init.beta, init.gamma)
            zi = np.array([init.A, plus, minus, init.n, init.delta, h0 if h0 is not None else 0.0]) / scale
            starts.append(zi)
        if n_candidates:
            say(f"scoring {n_candidates} candidates on {coarse_u_size} samples (every {q}th)")
            rows = [c[:nvar] for c in cands]
            costs = coarse.costs(rows)
            order = np.argsort(costs)
            starts.extend(cands[i] for i in order[:n_starts])

        # Local stage on the coarse record, as many starts at a time as there are
        # workers; the results are read in the order of the starts, so the outcome does
        # not depend on the number of workers. Stops early once a second start lands on
        # the best cost found so far.
        batch = worker_count(workers)
        margin = min(_COARSE_MARGIN, _SAME_COST * (coarse_u_size - nvar)) if coarse is not full else STATISTICAL_MARGIN
        best: Solution | None = None
        confirmed = False
        for first in range(0, len(starts), batch):
            group = starts[first : first + batch]

            def local(z0: FloatArray) -> Solution:
                return _local(coarse, nvar, z0, max_nfev, 1e-8, method, margin, delta_z)

            results = list(pool.map(local, group)) if pool is not None and len(group) > 1 else [local(z) for z in group]
            for k, res in enumerate(results, start=first):
                fit_rms = math.sqrt(2.0 * res.cost / coarse_u_size)
                say(f"start {k + 1}/{len(starts)}: rms {fit_rms:.4g} µm after {res.nfev} steps")
                if best is not None and abs(res.cost - best.cost) <= _SAME_COST * max(best.cost, 1e-300):
                    confirmed = True
                # A later start replaces the best only beyond _SAME_COST: within it the
                # two are the same optimum, and the earlier start keeps it whichever way
                # the last bits of the arithmetic fall.
                if best is None or res.cost < (1.0 - _SAME_COST) * best.cost:
                    best = res
                if confirmed:
                    break
            if confirmed:
                if first + batch < len(starts) or k + 1 < len(starts):
                    say("optimum reached from two starts; skipping the rest")
                break
        if best is None:  # pragma: no cover - n_starts >= 1 or init gives at least one start
            raise ValueError("no starting point for the local stage")

        # Refinement on the full record, from the coarse optimum: near the full
        # record's, so one pass and a step or two usually reach it.
        if coarse is not full:
            say(f"refining on {u.size} samples")
            final = _local(full, nvar, best.x, max_nfev, 1e-10, method, delta_limit=delta_z)
            say(f"full record: {final.nfev} steps")
            stage = "full record"
        else:
            final = best
            stage = "record"
        th = hysteresis.theta(final.x)
        h = hysteresis.simulated(final.x)
        if h is None:  # pragma: no cover - the optimiser never accepts a failing point
            raise ValueError("the fitted parameters cannot be simulated")
        kv, x0 = _linear_part(record, h)
        params = Params(kv, x0, *th[:5])
        x_fit = kv * u + x0 + h
        err = x - x_fit
        nfev = full.simulations + (coarse.simulations if coarse is not full else 0)
    rms_um = rms(err)
    max_um = max_abs(err)
    success = bool(final.success) and math.isfinite(rms_um)
    elapsed = time.perf_counter() - started
    say(f"done in {elapsed:.2f} s: rms {rms_um:.4g} µm, max {max_um:.4g} µm")
    return FitResult(
        params=params,
        h0=float(th[5]),
        rms_um=rms_um,
        max_um=max_um,
        success=success,
        message=f"{stage}: {final.message}",
        nfev=int(nfev),
        x_fit=x_fit,
        elapsed_s=elapsed,
    )
