"""Output-error least squares: the one engine behind :func:`boucwen.fit` and
:func:`boucwen.effects.fit_extended`.

Both fits minimise the *output* error of a model simulated from the voltage alone,

    r(z) = P·(s(z) − y)        (µm; one row per sample)

over their unknowns z, where s(z) is the simulated signal, y the measured one and
P either the identity or the projection off span{basis} (the variable projection of
:func:`boucwen.fit`, whose linear part is solved separately). An optional
:class:`Ridge` row pulls one unknown towards 0. The engine owns what the two fits
share:

* the residual, from one simulation, and its Jacobian P·∂s/∂z, from one pass of the
  Rust core that returns the simulated signal with its exact derivatives
  (:func:`boucwen._core.simulate_extended_with_jacobian`, with or without effects:
  forward-mode automatic differentiation through the same integrator);
* a residual of :data:`FAIL_RESIDUAL_UM` for a point that cannot be simulated, so
  the optimiser backs away from it;
* the count of simulations, and the minimisation, by one of two methods
  (:data:`Method`): ``"lm"``, :func:`boucwen.levenberg.levenberg_marquardt`
  (trust-region Levenberg–Marquardt on the normal equations, a pass of the core per
  linearisation or fewer, stopped where the remaining step is a small fraction of the
  unknowns' standard error: :func:`boucwen.fit`), or ``"trf"``,
  ``scipy.optimize.least_squares``'s trust-region reflective method (one tolerance for
  ``xtol``, ``ftol`` and ``gtol``: :func:`boucwen.effects.fit_extended`, whose
  budget-limited trials in the diagnosis were validated with it);
* threads for independent simulations (:func:`worker_threads`, :func:`thread_map`:
  the fit's candidates, the diagnosis's trials; the simulators release the GIL).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Callable, Literal, Optional, TypeVar

import numpy as np
from scipy.optimize import least_squares

from .checks import FloatArray, check_int
from .levenberg import STATISTICAL_MARGIN, Solution, levenberg_marquardt

__all__ = [
    "FAIL_RESIDUAL_UM",
    "ManySimulator",
    "Method",
    "OutputErrorProblem",
    "Ridge",
    "Simulator",
    "SimulatorWithJacobian",
    "Solution",
    "finite_or_none",
    "orthonormal",
    "thread_map",
    "with_jacobian_or_none",
    "worker_count",
    "worker_threads",
]

#: Residual value [µm] returned for a point that cannot be simulated.
FAIL_RESIDUAL_UM = 1e6

#: Unknowns → simulated signal [µm], or None when they cannot be simulated.
Simulator = Callable[[FloatArray], Optional[FloatArray]]
#: Unknowns → (simulated signal [µm], its Jacobian ∂s/∂z: one row per sample, one column
#: per unknown; a new array, which the engine projects in place), or None when they
#: cannot be simulated.
SimulatorWithJacobian = Callable[[FloatArray], Optional[tuple[FloatArray, FloatArray]]]
#: Several unknowns → the simulated signal of each [µm] (None where one cannot be
#: simulated), in one batch.
ManySimulator = Callable[[Sequence[FloatArray]], list[Optional[FloatArray]]]

#: The minimisation methods of :meth:`OutputErrorProblem.solve` (module docs).
Method = Literal["lm", "trf"]

T = TypeVar("T")
R = TypeVar("R")


def finite_or_none(run: Callable[[], Any]) -> FloatArray | None:
    """The float64 array ``run()`` returns, or None if it raises ValueError or
    OverflowError or returns a non-finite value."""
    try:
        out = np.asarray(run(), dtype=np.float64)
    except (ValueError, OverflowError):
        return None
    return out if bool(np.all(np.isfinite(out))) else None


def with_jacobian_or_none(run: Callable[[], tuple[Any, Any]]) -> tuple[FloatArray, FloatArray] | None:
    """The pair of float64 arrays (signal, Jacobian) ``run()`` returns, or None if it
    raises ValueError or OverflowError or either holds a non-finite value."""
    try:
        s, jac = run()
    except (ValueError, OverflowError):
        return None
    s, jac = np.asarray(s, dtype=np.float64), np.asarray(jac, dtype=np.float64)
    return (s, jac) if bool(np.all(np.isfinite(s)) and np.all(np.isfinite(jac))) else None


def worker_count(workers: int | None) -> int:
    """``workers``, or the number of CPUs for None. ValueError if ``workers`` is not None
    or an integer >= 1."""
    return (os.cpu_count() or 1) if workers is None else check_int("workers", workers, 1)


@contextmanager
def worker_threads(workers: int | None) -> Iterator[ThreadPoolExecutor | None]:
    """A thread pool for independent simulations (:func:`thread_map`, the fit's
    candidates, the diagnosis's trials): ``workers`` threads (default: the number of
    CPUs), or None when that is one; shut down on exit. ValueError if ``workers`` is
    not None or an integer >= 1."""
    count = worker_count(workers)
    pool = ThreadPoolExecutor(max_workers=count) if count > 1 else None
    try:
        yield pool
    finally:
        if pool is not None:
            pool.shutdown()


def thread_map(fn: Callable[[T], R], items: Sequence[T], workers: int | None) -> list[R]:
    """``[fn(item) for item in items]``, run in a pool of :func:`worker_threads`
    (``workers`` threads; in turn for one): for independent work whose simulations
    release the GIL."""
    with worker_threads(workers) as pool:
        return list(pool.map(fn, items)) if pool is not None else [fn(item) for item in items]


def orthonormal(basis: FloatArray) -> FloatArray:
    """An orthonormal basis of the span of the columns of ``basis`` (rows × k, k small,
    columns independent): Gram–Schmidt with each column orthogonalised twice, which
    keeps it orthogonal to rounding; a C-ordered rows × k array."""
    q = np.array(basis, dtype=np.float64, order="F", copy=True)
    for j in range(q.shape[1]):
        for _ in range(2):
            for i in range(j):
                q[:, j] -= (q[:, i] @ q[:, j]) * q[:, i]
        q[:, j] /= np.linalg.norm(q[:, j])
    return np.ascontiguousarray(q)


@dataclass(frozen=True)
class Ridge:
    """The residual row ``weight · z[index] · scale`` [µm]: a weak pull of one unknown
    (``z[index]·scale`` in its own unit) towards 0."""

    index: int
    weight: float
    scale: float


class OutputErrorProblem:
    """``r(z) = P·(simulate(z) − target)`` (plus an optional ridge row), its Jacobian and
    its minimisation (module docs).

    Args:
        simulate: unknowns → simulated signal, same length as ``target`` [µm], or None.
        simulate_with_jacobian: unknowns → (that signal, ∂signal/∂z), or None.
        target: the measured signal [µm].
        basis: columns whose span is projected out of the residual (variable
            projection), or None.
        ridge: an extra residual row, or None.
        simulate_many: several unknowns → their simulated signals (each or None) in
            one batch, for :meth:`costs`; None to run ``simulate`` in threads.
    """

    def __init__(
        self,
        simulate: Simulator,
        simulate_with_jacobian: SimulatorWithJacobian,
        target: FloatArray,
        *,
        basis: FloatArray | None = None,
        ridge: Ridge | None = None,
        simulate_many: ManySimulator | None = None,
    ):
        self._simulate = simulate
        self._simulate_many = simulate_many
        self._simulate_with_jacobian = simulate_with_jacobian
        self.target = target
        self.ridge = ridge
        self._q: FloatArray | None = orthonormal(basis) if basis is not None else None
        self._rows = target.size + (1 if ridge is not None else 0)
        self._lock = threading.Lock()
        self._count = 0

    @property
    def simulations(self) -> int:
        """Number of simulations run so far (residuals, Jacobian passes, direct calls)."""
        return self._count

    def _counted(self) -> None:
        with self._lock:
            self._count += 1

    def simulate(self, z: FloatArray) -> FloatArray | None:
        """The simulated signal [µm] at ``z`` (counted), or None."""
        self._counted()
        return self._simulate(z)

    def _project(self, v: FloatArray) -> FloatArray:
        """P·v, overwriting ``v`` (an array this problem owns)."""
        if self._q is not None:
            v -= self._q @ (self._q.T @ v)
        return v

    def residual(self, z: FloatArray) -> FloatArray:
        """r(z) [µm]; every row :data:`FAIL_RESIDUAL_UM` where z cannot be simulated."""
        s = self.simulate(z)
        if s is None:
            return np.full(self._rows, FAIL_RESIDUAL_UM)
        return self._residual_of(s, z)

    def _residual_of(self, s: FloatArray, z: FloatArray) -> FloatArray:
        """r(z) from the signal ``s`` simulated at z: P·(s − target), the ridge row appended."""
        r = self._project(s - self.target)
        if self.ridge is None:
            return r
        return np.append(r, self.ridge.weight * z[self.ridge.index] * self.ridge.scale)

    def linearise(self, z: FloatArray) -> tuple[FloatArray, FloatArray] | None:
        """(r(z), ∂r/∂z = P·∂s/∂z) from one simulation with the Jacobian, or None where z
        cannot be simulated. The simulator's Jacobian array is projected in place."""
        self._counted()
        out = self._simulate_with_jacobian(z)
        if out is None:
            return None
        s, ds = out
        return self._residual_of(s, z), self._jacobian_rows(ds)

    def _jacobian_rows(self, ds: FloatArray) -> FloatArray:
        """P·ds with the ridge row appended (``ds`` projected in place when no row is added)."""
        if self.ridge is None:
            return self._project(np.require(ds, requirements=["C", "W"]))
        jac = np.empty((self._rows, ds.shape[1]))
        jac[: self.target.size] = ds
        self._project(jac[: self.target.size])
        jac[-1] = 0.0
        jac[-1, self.ridge.index] = self.ridge.weight * self.ridge.scale
        return jac

    def jacobian(self, z: FloatArray) -> FloatArray:
        """∂r/∂z (zeros where z cannot be simulated), from :meth:`linearise`."""
        out = self.linearise(z)
        return out[1] if out is not None else np.zeros((self._rows, z.size))

    def cost(self, z: FloatArray) -> float:
        """Σ r(z)² [µm²]."""
        r = self.residual(z)
        return float(r @ r)

    def costs(self, zs: Sequence[FloatArray], workers: int | None = None) -> list[float]:
        """Σ r(z)² [µm²] for each z of ``zs``: one batch of simulations where the
        problem has a ``simulate_many``, else :meth:`cost` in ``workers`` threads."""
        if self._simulate_many is None:
            return thread_map(self.cost, zs, workers)
        with self._lock:
            self._count += len(zs)
        out = []
        for z, s in zip(zs, self._simulate_many(zs)):
            if s is None:
                out.append(float(self._rows) * FAIL_RESIDUAL_UM**2)
                continue
            r = self._residual_of(s, z)
            out.append(float(r @ r))
        return out

    def solve(
        self,
        z0: FloatArray,
        lower: FloatArray,
        upper: FloatArray,
        *,
        x_scale: FloatArray | float,
        tol: float,
        max_nfev: int,
        method: Method = "lm",
        margin: float = STATISTICAL_MARGIN,
        reuse_jacobian: bool = False,
        start: tuple[FloatArray, FloatArray] | None = None,
    ) -> Solution:
        """Minimises ½‖r‖² from ``z0`` within [lower, upper] by ``method`` (module
        docs); ``margin`` is the statistical stop of
        :func:`~boucwen.levenberg.levenberg_marquardt` (for "trf", its ``ftol``: a relative
        fall of the cost below margin/(rows − p)); ``reuse_jacobian`` and ``start`` (r and
        ∂r/∂z at ``z0``, already computed) are "lm"'s."""
        if method == "trf":
            # The same statistical stop as "lm": a step that lowers the cost by less than
            # ``margin`` times the noise variance σ̂² = cost/(rows − p) moves the unknowns by
            # less than the record resolves (and along a flat valley, by an amount no
            # record determines).
            statistical = margin / max(self._rows - z0.size, 1)
            res = least_squares(
                self.residual,
                z0,
                jac=self.jacobian,
                bounds=(lower, upper),
                method="trf",
                x_scale=x_scale,
                xtol=tol,
                ftol=max(tol, statistical),
                gtol=tol,
                max_nfev=max_nfev,
            )
            jac = np.asarray(res.jac, dtype=np.float64)
            return Solution(res.x, float(res.cost), jac, int(res.nfev), int(res.njev), bool(res.success), res.message)
        if method != "lm":
            raise ValueError(f"method must be 'lm' or 'trf', got {method!r}")
        return levenberg_marquardt(
            self.residual,
            self.linearise,
            z0,
            lower,
            upper,
            x_scale=x_scale,
            tol=tol,
            max_nfev=max_nfev,
            margin=margin,
            reuse_jacobian=reuse_jacobian,
            start=start,
        )
