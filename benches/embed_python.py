#!/usr/bin/env python3
"""Per-call cost from Python of the per-sample and per-frame paths, in one run.

    python benches/embed_python.py

Data as in ``cargo bench --bench latency``: the paper's input at 10 kHz, repeated,
measured through the paper's 1 Hz model with 1–5 nm of noise. Prints ns per call of
``Identifier.push`` (rpem; the recommended identifier in its three refine modes:
sync, cooperative with ``refine`` not called in the loop, background with its
worker) and ``Model.step`` in a Python loop,
ns per sample of ``Identifier.push_many``, and ns per frame of ``Bank.push_many`` at
C = 256; the best of five repeats each. As the Rust bench, it pins itself to the
last core and asks for SCHED_FIFO (Linux, where permitted), so that both run under
the same conditions; compare with the mean column of the Rust latency table.
"""

from __future__ import annotations

import os
import time
from typing import Callable

import numpy as np

import boucwen
from boucwen import Bank, Identifier, Model, Params

DT = 1e-4


def record(n: int) -> tuple[np.ndarray, np.ndarray]:
    one = boucwen.paper_input(DT, 0.05)
    u = np.resize(one, n)
    x, _ = boucwen.simulate(Params.paper_1hz(), u, DT)
    rng = np.random.default_rng(1)
    sigma = 1e-3 * (1 + (np.arange(n) // one.size) % 5)
    return u, x + sigma * rng.standard_normal(n)


def best(fn, repeats: int = 5) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def real_time() -> str:
    """Pins the process to the last core and asks for SCHED_FIFO; says what it got."""
    if not hasattr(os, "sched_setaffinity"):
        return "not pinned"
    core = (os.cpu_count() or 1) - 1
    os.sched_setaffinity(0, {core})
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
        return f"pinned to core {core}, SCHED_FIFO priority 10"
    except PermissionError:
        return f"pinned to core {core}, normal scheduling (SCHED_FIFO not permitted)"


def beside(make: Callable[[], Identifier]) -> Identifier:
    """Builds with this thread on the first core, so that the worker thread it starts
    runs beside the loop's core, not on it; then pins back to the last core."""
    if not hasattr(os, "sched_setaffinity") or (os.cpu_count() or 1) < 2:
        return make()
    os.sched_setaffinity(0, {0})
    try:
        return make()
    finally:
        os.sched_setaffinity(0, {(os.cpu_count() or 1) - 1})


def main() -> None:
    print(real_time())
    p = Params.paper_1hz()
    n = 200_000
    u, x = record(n)
    ul, xl = u.tolist(), x.tolist()
    makers: dict[str, Callable[[], Identifier]] = {
        "rpem": lambda: Identifier.rpem(DT, p),
        "default (horizon, input lag)": lambda: Identifier(DT, p),
        "default, refine=cooperative": lambda: Identifier(DT, p, refine="cooperative"),
        "default, refine=background": lambda: beside(lambda: Identifier(DT, p, refine="background")),
    }

    def push_loop(make: Callable[[], Identifier]) -> None:
        push = make().push
        for a, b in zip(ul, xl):
            push(a, b)

    def step_loop() -> None:
        step = Model(p, DT).step
        for a in ul:
            step(a)

    rows = []
    for name, make in makers.items():
        t_push = best(lambda make=make: push_loop(make)) / n * 1e9
        t_many = best(lambda make=make: make().push_many(u, x)) / n * 1e9
        rows.append((name, t_push, t_many))
    t_step = best(step_loop) / n * 1e9
    channels, frames = 256, 2_000
    ub = np.stack([np.roll(u[: frames + 977 * channels], -977 * c)[:frames] for c in range(channels)], axis=1)
    xb = np.stack([np.roll(x[: frames + 977 * channels], -977 * c)[:frames] for c in range(channels)], axis=1)
    t_bank = best(lambda: Bank(channels, DT, p).push_many(ub, xb), repeats=3) / frames * 1e9
    print(f"{'per sample [ns]':<30}{'push (Python loop)':>20}{'push_many':>12}{'loop / many':>13}")
    for name, t_push, t_many in rows:
        print(f"{name:<30}{t_push:>20.0f}{t_many:>12.0f}{t_push / t_many:>13.2f}")
    print(
        "targets: rpem push and the recommended identifier's push (cooperative, background) from Python <= 300 ns; "
        "push_many within 1.3x the Rust push (cargo bench --bench latency)"
    )
    print(f"Model.step from a Python loop: {t_step:.0f} ns per call")
    print(f"Bank.push_many, C = {channels} rpem: {t_bank:.0f} ns per frame ({t_bank / channels:.0f} per channel)")


if __name__ == "__main__":
    main()
