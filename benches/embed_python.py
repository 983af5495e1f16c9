#!/usr/bin/env python3
"""Per-call cost from Python of the per-sample and per-frame paths, in one run.

    python benches/embed_python.py

Data as in ``cargo bench --bench latency``: the paper's input at 10 kHz, repeated,
measured through the paper's 1 Hz model with 1–5 nm of noise. Prints ns per call of
``Identifier.push`` (rpem, the default method) and ``Model.step`` in a Python loop,
ns per sample of ``Identifier.push_many``, and ns per frame of ``Bank.push_many`` at
C = 256; the best of five repeats each. As the Rust bench, it pins itself to the
last core and asks for SCHED_FIFO (Linux, where permitted), so that both run under
the same conditions; compare with the mean column of the Rust latency table.
"""

from __future__ import annotations

import os
import time

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


def main() -> None:
    print(real_time())
    p = Params.paper_1hz()
    n = 200_000
    u, x = record(n)
    ul, xl = u.tolist(), x.tolist()

    def push_loop() -> None:
        ident = Identifier(DT, p)
        push = ident.push
        for a, b in zip(ul, xl):
            push(a, b)

    def step_loop() -> None:
        step = Model(p, DT).step
        for a in ul:
            step(a)

    t_push = best(push_loop) / n * 1e9
    t_step = best(step_loop) / n * 1e9
    t_many = best(lambda: Identifier(DT, p).push_many(u, x)) / n * 1e9
    channels, frames = 256, 2_000
    ub = np.stack([np.roll(u[: frames + 977 * channels], -977 * c)[:frames] for c in range(channels)], axis=1)
    xb = np.stack([np.roll(x[: frames + 977 * channels], -977 * c)[:frames] for c in range(channels)], axis=1)
    t_bank = best(lambda: Bank(channels, DT, p).push_many(ub, xb), repeats=3) / frames * 1e9
    print(f"Identifier.push (rpem) from a Python loop: {t_push:.0f} ns per call (target ≤ 300)")
    print(f"Model.step from a Python loop: {t_step:.0f} ns per call")
    print(f"Identifier.push_many (rpem): {t_many:.0f} ns per sample (target ≤ 1.3× the Rust mean per push)")
    print(f"Bank.push_many, C = {channels} rpem: {t_bank:.0f} ns per frame ({t_bank / channels:.0f} per channel)")


if __name__ == "__main__":
    main()
