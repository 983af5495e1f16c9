"""Feeding an online identifier as a control loop would: one sample per sampling interval.

The recommended identifier's window pass can run outside ``push`` (``refine="cooperative"``
or ``"background"``, see :class:`boucwen.Identifier`). How good its model is then depends
on how much the pass gets done between two samples, so replaying a record with
``push_many`` (as fast as the CPU goes) says nothing about a loop: a background worker
would fall far behind a replay that pushes a sample every 200 ns.

:class:`PacedFeed` replays a record at its own sample rate: sample k of the record is
pushed no earlier than ``origin + k·dt`` (a busy wait on :func:`time.perf_counter_ns`,
as a loop that waits for its next sampling instant), one sample at a time. The clock
runs on across calls (the schedule is absolute), so work done between two calls (an
evaluation's forecast) makes the next samples late, as a loop with a backlog would
push them at once; the feed counts them. With ``refine_intervals`` it also runs the
cooperative schedule: ``refine(refine_intervals)`` after every push, in the time left
before the next sample.

Python keeps up with 10 kHz: a push of the split identifier and a clock read take a
few µs of the 100 µs interval. Lateness comes from the host (preemption by other
processes), and is reported in :attr:`PacedFeed.late_samples` and
:attr:`PacedFeed.max_late_s`.

Units: dt and lateness in seconds, u [V], x [µm].
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._core import Identifier

__all__ = [
    "COOPERATIVE_INTERVALS",
    "REFINE_MODES",
    "PacedFeed",
    "RefineMode",
    "feed_for",
    "realtime",
    "refine_mode",
    "refine_modes",
]


@dataclass
class PacedFeed:
    """Pushes samples into an identifier at their own times (module docs).

    Attributes:
        dt: sampling interval [s] (> 0).
        paced: wait for each sample's time (False: push at once, for the modes whose
            results do not depend on time: "sync", and "cooperative" with a schedule
            in intervals).
        refine_intervals: after every push, ``ident.refine(refine_intervals)`` (the
            cooperative schedule; 0: none).
        samples: samples pushed so far (the schedule's index).
        late_samples: samples pushed more than one interval after their time.
        max_late_s: the largest delay of a push after its time [s].
    """

    dt: float
    paced: bool = True
    refine_intervals: int = 0
    samples: int = 0
    late_samples: int = 0
    max_late_s: float = 0.0
    _origin_ns: int | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dt) and self.dt > 0.0):
            raise ValueError(f"invalid dt = {self.dt!r}: must be finite and > 0 s")
        r = self.refine_intervals
        if isinstance(r, bool) or not isinstance(r, (int, np.integer)) or r < 0:
            raise ValueError(f"invalid refine_intervals = {r!r}: must be an integer >= 0")

    def push_many(self, ident: Identifier, u: ArrayLike, x: ArrayLike) -> NDArray[np.float64]:
        """Pushes ``u[i], x[i]`` one by one, sample i of this call at its time on the
        feed's clock (started at the first sample ever pushed); returns the predictions
        [µm]. Non-finite values raise ValueError before any sample is pushed."""
        ua = np.ascontiguousarray(u, dtype=np.float64)
        xa = np.ascontiguousarray(x, dtype=np.float64)
        if ua.ndim != 1 or ua.shape != xa.shape:
            raise ValueError(f"u and x must be 1-D arrays of the same length, got {ua.shape} and {xa.shape}")
        if not (np.all(np.isfinite(ua)) and np.all(np.isfinite(xa))):
            raise ValueError("u and x must be finite (NaN or infinite value found)")
        out = np.empty_like(ua)
        dt_ns = self.dt * 1e9
        clock = time.perf_counter_ns
        push, refine, budget = ident.push, ident.refine, int(self.refine_intervals)
        if self._origin_ns is None:
            self._origin_ns = clock()
        origin, k0 = self._origin_ns, self.samples
        late, worst = 0, 0
        for i, (a, b) in enumerate(zip(ua.tolist(), xa.tolist())):
            if self.paced:
                due = origin + round((k0 + i) * dt_ns)
                now = clock()
                while now < due:
                    now = clock()
                behind = now - due
                if behind > dt_ns:
                    late += 1
                worst = max(worst, behind)
            out[i] = push(a, b)
            if budget:
                refine(budget)
        self.samples += ua.size
        self.late_samples += late
        self.max_late_s = max(self.max_late_s, worst * 1e-9)
        return out


#: A mode of the window pass (the ``refine`` argument of :class:`boucwen.Identifier`).
RefineMode = Literal["sync", "cooperative", "background"]
#: Where the recommended identifier's window pass runs (``refine`` of :class:`boucwen.Identifier`).
REFINE_MODES: tuple[RefineMode, ...] = ("sync", "cooperative", "background")
#: The cooperative schedule of the experiments: ``refine(COOPERATIVE_INTERVALS)`` after every
#: push. At 10 kHz that is about 32 × 0.25 µs = 8 µs of each 100 µs interval, twice the
#: window pass's share in a synchronous push (16 intervals), so that the pass keeps up
#: with the carrying of each update to the newest sample as well.
COOPERATIVE_INTERVALS = 32


def refine_mode(name: str) -> RefineMode:
    """`name` as a :data:`RefineMode`; ValueError if it is none."""
    if name not in REFINE_MODES:
        raise ValueError(f"invalid refine = {name!r}: expected one of {REFINE_MODES}")
    return name


def refine_modes(arg: str) -> tuple[RefineMode, ...]:
    """The modes named by a command-line value: ``"all"`` or a comma-separated subset of
    :data:`REFINE_MODES`, in that order. ValueError on an unknown name."""
    names = [s.strip() for s in arg.split(",") if s.strip()]
    if names == ["all"]:
        return REFINE_MODES
    bad = [n for n in names if n not in REFINE_MODES]
    if bad or not names:
        raise ValueError(f"invalid refine = {arg!r}: expected 'all' or a comma-separated subset of {REFINE_MODES}")
    return tuple(m for m in REFINE_MODES if m in names)


def feed_for(refine: str, dt: float) -> PacedFeed | None:
    """How the experiments feed an identifier whose pass runs as `refine` says: "sync"
    with ``push_many`` (None), "cooperative" with the stated schedule
    (:data:`COOPERATIVE_INTERVALS` after every push; its results do not depend on time,
    so it is not paced), "background" paced at the record's own rate `dt` [s]."""
    if refine == "sync":
        return None
    if refine == "cooperative":
        return PacedFeed(dt, paced=False, refine_intervals=COOPERATIVE_INTERVALS)
    if refine == "background":
        return PacedFeed(dt)
    raise ValueError(f"invalid refine = {refine!r}: expected one of {REFINE_MODES}")


@contextmanager
def realtime(priority: int = 10) -> Iterator[bool]:
    """The calling thread, and the threads it starts meanwhile (a background identifier's
    worker), under the real-time policy SCHED_FIFO at `priority` while inside, as a
    control loop and its refinement would run: on a host shared with other work the
    paced replay and the worker then each get a core. Yields whether the policy was
    granted (it needs the privilege; elsewhere nothing changes). Linux only."""
    try:
        policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, OSError):
        yield False
        return
    try:
        yield True
    finally:
        os.sched_setscheduler(0, policy, param)
