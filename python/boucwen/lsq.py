"""Output-error least squares: the one engine behind :func:`boucwen.fit` and
:func:`boucwen.effects.fit_extended`.

Both fits minimise the *output* error of a model simulated from the voltage alone,

    r(z) = P·(s(z) − y)        (µm; one row per sample)

over their unknowns z, where s(z) is the simulated signal, y the measured one and
P either the identity or the projection off span{basis} (the variable projection of
:func:`boucwen.fit`, whose linear part is solved separately). An optional
:class:`Ridge` row pulls one unknown towards 0. The engine owns what the two fits
share:

* the residual and its Jacobian by forward differences, one simulation per unknown,
  run in threads (the simulators release the GIL) — a step goes backwards where a
  forward one would leave the unknown's upper bound;
* a cache of the last simulation (``least_squares`` asks for the residual and the
  Jacobian at the same point);
* a residual of :data:`FAIL_RESIDUAL_UM` for a point that cannot be simulated, so
  the optimiser backs away from it;
* the count of simulations, and the call of ``scipy.optimize.least_squares``
  (trust-region reflective, one tolerance for ``xtol``, ``ftol`` and ``gtol``).
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
    "FD_STEP",
    "OutputErrorProblem",
    "Ridge",
    "Simulator",
    "finite_or_none",
    "jacobian_threads",
    "thread_map",
]

#: Forward-difference step, relative to max(|z_i|, typical_i) (the simulators are
#: smooth to ~1e-7 there).
FD_STEP = 1e-6
#: Residual value [µm] returned for a point that cannot be simulated.
FAIL_RESIDUAL_UM = 1e6

#: Unknowns → simulated signal [µm], or None when they cannot be simulated.
Simulator = Callable[[FloatArray], Optional[FloatArray]]

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


@contextmanager
def jacobian_threads(workers: int | None) -> Iterator[ThreadPoolExecutor | None]:
    """A thread pool for the Jacobian columns (or other independent simulations:
    :func:`thread_map`, the diagnosis's trials): ``workers`` threads (default: the
    number of CPUs), or None when that is one; shut down on exit. ValueError if
    ``workers`` is not None or an integer >= 1."""
    count = (os.cpu_count() or 1) if workers is None else check_int("workers", workers, 1)
    pool = ThreadPoolExecutor(max_workers=count) if count > 1 else None
    try:
        yield pool
    finally:
        if pool is not None:
            pool.shutdown()


def thread_map(fn: Callable[[T], R], items: Sequence[T], workers: int | None) -> list[R]:
    """``[fn(item) for item in items]``, run in a pool of :func:`jacobian_threads`
    (``workers`` threads; in turn for one): for independent work whose simulations
    release the GIL."""
    with jacobian_threads(workers) as pool:
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
        target: the measured signal [µm].
        typical: typical size of each unknown (array or one value), the floor of the
            difference step ``FD_STEP · max(|z_i|, typical_i)``.
        upper: upper bounds of the unknowns; where ``z_i + step`` would exceed one,
            that column steps backwards. None: always forwards.
        basis: columns whose span is projected out of the residual (variable
            projection), or None.
        ridge: an extra residual row, or None.
        pool: threads for the Jacobian columns, or None to run them in turn.
        constant: ``{i: c}``: the unknowns z_i whose column of ∂s/∂z is the constant c at
            every sample (an offset of the output: c = 1), taken as such, not simulated.
    """

    def __init__(
        self,
        simulate: Simulator,
        target: FloatArray,
        *,
        typical: FloatArray | float = 1.0,
        upper: FloatArray | None = None,
        basis: FloatArray | None = None,
        ridge: Ridge | None = None,
        pool: ThreadPoolExecutor | None = None,
        constant: dict[int, float] | None = None,
    ):
        self._simulate = simulate
        self.target = target
        self.typical = typical
        self.upper = upper
        self.ridge = ridge
        self.pool = pool
        self.constant = dict(constant or {})
        self._q: FloatArray | None = np.linalg.qr(basis)[0] if basis is not None else None
        self._rows = target.size + (1 if ridge is not None else 0)
        self._lock = threading.Lock()
        self._count = 0
        self._cache: tuple[bytes, FloatArray | None] | None = None

    @property
    def simulations(self) -> int:
        """Number of simulations run so far (residuals, Jacobian columns, direct calls)."""
        return self._count

    def simulate(self, z: FloatArray) -> FloatArray | None:
        """The simulated signal [µm] at ``z`` (counted, not cached), or None."""
        with self._lock:
            self._count += 1
        return self._simulate(z)

    def _simulated(self, z: FloatArray) -> FloatArray | None:
        key = z.tobytes()
        cached = self._cache  # one read: other threads may replace it meanwhile
        if cached is not None and cached[0] == key:
            return cached[1]
        out = self.simulate(z)
        self._cache = (key, out)
        return out

    def _project(self, v: FloatArray) -> FloatArray:
        if self._q is None:
            return v
        out: FloatArray = v - self._q @ (self._q.T @ v)
        return out

    def residual(self, z: FloatArray) -> FloatArray:
        """r(z) [µm]; every row :data:`FAIL_RESIDUAL_UM` where z cannot be simulated."""
        s = self._simulated(z)
        if s is None:
            return np.full(self._rows, FAIL_RESIDUAL_UM)
        r = self._project(s - self.target)
        if self.ridge is not None:
            r = np.append(r, self.ridge.weight * z[self.ridge.index] * self.ridge.scale)
        return r

    def jacobian(self, z: FloatArray) -> FloatArray:
        """∂r/∂z by forward differences (zeros where z cannot be simulated); each column
        is simulated, differenced and projected in the pool's threads."""
        base = self._simulated(z)
        steps = FD_STEP * np.maximum(np.abs(z), self.typical)
        upper = self.upper
        jac = np.zeros((self._rows, z.size), order="F")  # filled column by column
        n = self.target.size

        def column(i: int) -> None:
            if i in self.constant:
                jac[:n, i] = self._project(np.full(n, self.constant[i]))
                return
            step = float(steps[i]) if upper is None or z[i] + steps[i] <= upper[i] else -float(steps[i])
            zi = z.copy()
            zi[i] += step
            si = self.simulate(zi)
            if si is not None and base is not None:
                jac[:n, i] = self._project((si - base) / step)

        idx = range(z.size)
        if self.pool is not None:
            list(self.pool.map(column, idx))
        else:
            for i in idx:
                column(i)
        if base is None:
            return np.zeros((self._rows, z.size))
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
