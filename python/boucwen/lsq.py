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
* the count of simulations, and the call of ``scipy.optimize.least_squares``
  (trust-region reflective, one tolerance for ``xtol``, ``ftol`` and ``gtol``);
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
from typing import Any, Callable, Optional, TypeVar

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from .checks import FloatArray, check_int

__all__ = [
    "FAIL_RESIDUAL_UM",
    "OutputErrorProblem",
    "Ridge",
    "Simulator",
    "SimulatorWithJacobian",
    "finite_or_none",
    "thread_map",
    "with_jacobian_or_none",
    "worker_threads",
]

#: Residual value [µm] returned for a point that cannot be simulated.
FAIL_RESIDUAL_UM = 1e6

#: Unknowns → simulated signal [µm], or None when they cannot be simulated.
Simulator = Callable[[FloatArray], Optional[FloatArray]]
#: Unknowns → (simulated signal [µm], its Jacobian ∂s/∂z: one row per sample, one column
#: per unknown), or None when they cannot be simulated.
SimulatorWithJacobian = Callable[[FloatArray], Optional[tuple[FloatArray, FloatArray]]]

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


@contextmanager
def worker_threads(workers: int | None) -> Iterator[ThreadPoolExecutor | None]:
    """A thread pool for independent simulations (:func:`thread_map`, the fit's
    candidates, the diagnosis's trials): ``workers`` threads (default: the number of
    CPUs), or None when that is one; shut down on exit. ValueError if ``workers`` is
    not None or an integer >= 1."""
    count = (os.cpu_count() or 1) if workers is None else check_int("workers", workers, 1)
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
    """

    def __init__(
        self,
        simulate: Simulator,
        simulate_with_jacobian: SimulatorWithJacobian,
        target: FloatArray,
        *,
        basis: FloatArray | None = None,
        ridge: Ridge | None = None,
    ):
        self._simulate = simulate
        self._simulate_with_jacobian = simulate_with_jacobian
        self.target = target
        self.ridge = ridge
        self._q: FloatArray | None = np.linalg.qr(basis)[0] if basis is not None else None
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
        if self._q is None:
            return v
        out: FloatArray = v - self._q @ (self._q.T @ v)
        return out

    def residual(self, z: FloatArray) -> FloatArray:
        """r(z) [µm]; every row :data:`FAIL_RESIDUAL_UM` where z cannot be simulated."""
        s = self.simulate(z)
        if s is None:
            return np.full(self._rows, FAIL_RESIDUAL_UM)
        r = self._project(s - self.target)
        if self.ridge is not None:
            r = np.append(r, self.ridge.weight * z[self.ridge.index] * self.ridge.scale)
        return r

    def jacobian(self, z: FloatArray) -> FloatArray:
        """∂r/∂z = P·∂s/∂z from one simulation with the Jacobian (zeros where z cannot
        be simulated)."""
        self._counted()
        out = self._simulate_with_jacobian(z)
        jac = np.zeros((self._rows, z.size))
        if out is None:
            return jac
        jac[: self.target.size] = self._project(out[1])
        if self.ridge is not None:
            jac[-1, self.ridge.index] = self.ridge.weight * self.ridge.scale
        return jac

    def cost(self, z: FloatArray) -> float:
        """Σ r(z)² [µm²]."""
        r = self.residual(z)
        return float(r @ r)

    def solve(
        self,
        z0: FloatArray,
        lower: FloatArray,
        upper: FloatArray,
        *,
        x_scale: FloatArray | float,
        tol: float,
        max_nfev: int,
    ) -> OptimizeResult:
        """``scipy.optimize.least_squares`` (trf) from ``z0`` within [lower, upper]."""
        return least_squares(
            self.residual,
            z0,
            jac=self.jacobian,
            bounds=(lower, upper),
            method="trf",
            x_scale=x_scale,
            xtol=tol,
            ftol=tol,
            gtol=tol,
            max_nfev=max_nfev,
        )
