#!/usr/bin/env python3
"""Side-by-side speed of boucwen's Rust core against plain NumPy/SciPy, in one run.

    python benches/compare.py            # about a minute; prints a markdown table
    python benches/compare.py --out out/compare   # also writes results.json there, from
                                                  # which experiments.report writes the
                                                  # table of docs/results.md

Every row uses the same data: the paper's input (1 Hz for 3 s, then 10, 100 and
200 Hz) sampled at 10 kHz, its simulated response with the paper's parameters and
1 nm of noise. Each figure is the median of several repeats (one for the slow
pure-Python rows).

Rows:
- ``Model.step``, ``Inverse.step`` and ``Compensator.step`` called from Python in a loop
  (the paper record's displacement back to voltages; the compensator adapting, with PI,
  in a closed loop around a ``Model`` plant whose step is included);
- ``Identifier.push`` called from Python in a loop, ``push_many`` on arrays (each
  online method this build offers), and the NumPy reference identifier
  (:mod:`boucwen.reference`, O(N) per sample by design) on the same samples;
- ``simulate`` against :func:`boucwen.reference.simulate` (plain RK4, one step per
  sample, in pure Python) and against ``scipy.integrate.solve_ivp`` tuned to the same
  accuracy (the loosest tolerance whose error against a 200-sub-step RK4
  solution is within 1e-4 µm, the accuracy the tests ask of ``simulate``, or
  ``simulate``'s own error if larger; ``simulate`` is far more accurate than
  that, so the ratio is a lower bound);
- the wall time of :func:`boucwen.fit` on the record's first 30 000 samples (1 Hz)
  with 2 nm of noise, with its local solver (Levenberg–Marquardt on the core's
  Jacobian) and with SciPy's trust-region reflective solver in its place.

Missing optional pieces (the reference module, the fit, SciPy) are skipped with a
message.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import statistics
import sys
import time
from typing import Any, Callable

import numpy as np

import boucwen
from boucwen import Identifier, Params

DT = 1e-4
WINDOW = 1_000


def median_time(fn: Callable[[], Any], repeats: int) -> float:
    """Median wall time [s] of ``repeats`` calls (after one warm-up call when repeats > 1)."""
    if repeats > 1:
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def page_faults() -> int:
    """Page faults of this process so far (first touches of fresh memory), or -1 where
    the platform does not count them."""
    try:
        import resource
    except ImportError:  # pragma: no cover - not on Unix
        return -1
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_minflt)


def fault_note(faults: list[int]) -> str:
    """The median page faults per call, for a note ("" where not counted)."""
    if not faults or min(faults) < 0:
        return ""
    return f", {int(statistics.median(faults)):,} page faults"


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} CPUs, Python {platform.python_version()}, NumPy {np.__version__}"


def optional(name: str) -> Any:
    try:
        return __import__(name, fromlist=["*"])
    except ImportError as exc:
        print(f"note: {name} not available ({exc}); its rows are skipped", file=sys.stderr)
        return None


def _make(method: str, params: Params) -> Identifier:
    """An identifier of `method` with its defaults (the paper's with N = WINDOW)."""
    if method == "paper":
        return Identifier.paper(DT, WINDOW, params)
    return Identifier.rpem(DT, params) if method == "rpem" else Identifier.horizon(DT, params)


def methods() -> list[str]:
    found = []
    for method in ("horizon", "rpem", "paper"):
        try:
            _make(method, Params.paper_1hz())
        except ValueError:
            continue
        found.append(method)
    return found


class Table:
    def __init__(self) -> None:
        self.rows: list[tuple[str, str, str, str]] = []

    def add(self, what: str, figure: str, ratio: str = "", note: str = "") -> None:
        self.rows.append((what, figure, ratio, note))
        print(f"  {what}: {figure} {ratio} {note}", file=sys.stderr, flush=True)

    def markdown(self) -> str:
        head = "| what | figure | ratio | note |\n|---|---:|---:|---|\n"
        return head + "\n".join(f"| {a} | {b} | {c} | {d} |" for a, b, c, d in self.rows)


def ns(seconds: float, samples: int) -> str:
    return f"{seconds / samples * 1e9:,.0f} ns/sample"


def rate(seconds: float, samples: int) -> str:
    return f"{samples / seconds / 1e6:.1f} M samples/s"


def push_loop(method: str, params: Params, u: np.ndarray, x: np.ndarray) -> None:
    """A fresh identifier fed one ``push`` at a time from a Python loop."""
    ident = _make(method, params)
    push = ident.push
    for uk, xk in zip(u.tolist(), x.tolist()):
        push(uk, xk)


def push_many(method: str, params: Params, u: np.ndarray, x: np.ndarray) -> None:
    """A fresh identifier fed the whole record by one ``push_many``."""
    _make(method, params).push_many(u, x)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="repeats of each fast figure (median; default 5)")
    parser.add_argument("--out", help="folder for results.json (the table, for experiments.report)")
    args = parser.parse_args(argv)
    reps = max(1, args.repeats)

    reference = optional("boucwen.reference")
    params = Params.paper_1hz()
    u = np.asarray(boucwen.paper_input(DT, 0.05))
    x_clean, _ = boucwen.simulate(params, u, DT)
    x = x_clean + 1e-3 * np.random.default_rng(0).standard_normal(u.size)
    n = u.size
    table = Table()
    print(f"{n} samples at dt = {DT} s; machine: {machine()}", file=sys.stderr)

    # ---------------------------------------------------------------- online identification
    ref_samples = 3_000
    for method in methods():
        t_loop = median_time(functools.partial(push_loop, method, params, u, x), reps)
        t_many = median_time(functools.partial(push_many, method, params, u, x), reps)
        table.add(
            f"`Identifier.push` from Python ({method}, N = {WINDOW})",
            ns(t_loop, n),
            note="per call, the Python loop included; target ≤ 500 ns",
        )
        table.add(
            f"`Identifier.push_many` ({method}, N = {WINDOW})",
            ns(t_many, n),
            f"{rate(t_many, n)}",
            "target ≥ 10 M samples/s",
        )
        if method == "paper" and reference is not None:

            def ref_loop() -> None:
                ident = reference.PaperIdentifier(DT, WINDOW, params)
                for uk, xk in zip(u[:ref_samples].tolist(), x[:ref_samples].tolist()):
                    ident.push(uk, xk)

            t_ref = median_time(ref_loop, 1)
            per_ref = t_ref / ref_samples
            table.add(
                f"NumPy reference `PaperIdentifier.push` (N = {WINDOW})",
                ns(t_ref, ref_samples),
                f"{per_ref / (t_many / n):,.0f}× `push_many`, {per_ref / (t_loop / n):,.0f}× `push`",
                f"first {ref_samples} samples; recomputes the window, O(N) per sample",
            )

    # ---------------------------------------------------------------- compensation
    def inverse_loop() -> None:
        step = boucwen.Inverse(params, DT, u_min=-30.0, u_max=120.0).step
        for xk in x_clean.tolist():
            step(xk)

    def model_loop() -> None:
        step = boucwen.Model(params, DT).step
        for uk in u.tolist():
            step(uk)

    def compensator_loop() -> None:
        start = params.replace(kv=0.2, A=-0.08)
        step = boucwen.Compensator(start, DT, u_min=-30.0, u_max=120.0, ki=200.0).step
        plant = boucwen.Model(params, DT).step
        x_meas = None
        for xk in x_clean.tolist():
            x_meas = plant(step(xk, x_meas))

    t_inv = median_time(inverse_loop, reps)
    t_model = median_time(model_loop, reps)
    t_comp = median_time(compensator_loop, reps)
    table.add("`Model.step` from Python", ns(t_model, n), note="per call, the Python loop included")
    table.add(
        "`Inverse.step` from Python",
        ns(t_inv, n),
        f"{t_inv / t_model:.1f}× `Model.step`",
        "per call, the Python loop included; the paper record's x back to u",
    )
    table.add(
        "`Compensator.step` from Python (adaptive + PI)",
        ns(t_comp, n),
        f"{t_comp / t_model:.1f}× `Model.step`",
        "per call; rpem push + inverse + PI, in a loop around a `Model.step` plant (included)",
    )

    # ---------------------------------------------------------------- simulation
    t_sim = median_time(lambda: boucwen.simulate(params, u, DT), max(reps, 9))
    table.add("`simulate` (Rust)", ns(t_sim, n), rate(t_sim, n), "paper input; target ≥ 10 M samples/s")
    if reference is not None:
        t_ref_sim = median_time(lambda: reference.simulate(params, u, DT, substeps=1, sequential=True), 1)
        table.add(
            "`reference.simulate` (NumPy/Python)",
            ns(t_ref_sim, n),
            f"{t_ref_sim / t_sim:,.0f}× `simulate`",
            "plain RK4, one step per sample",
        )

    scipy_integrate = optional("scipy.integrate")
    if scipy_integrate is not None and reference is not None:
        m = 10_000  # 1 s of the 1 Hz part, one full loop, kept short for the slow solver
        us = u[:m]
        fine, _ = reference.simulate(params, us, DT, substeps=200)
        xs, _ = boucwen.simulate(params, us, DT)
        err_rust = float(np.max(np.abs(xs - fine)))
        # solve_ivp cannot integrate across the kinks of u̇ at every sample as closely as
        # simulate does; it is given the accuracy the model tests ask of simulate
        # (1e-4 µm) or simulate's own error, whichever is larger, so its ratio is a lower bound.
        target = max(err_rust, 1e-4)
        t_sim_m = median_time(lambda: boucwen.simulate(params, us, DT), max(reps, 9))
        t_grid = np.arange(m) * DT
        slopes = np.diff(us) / DT
        p = params

        def rhs(t: float, h: np.ndarray) -> np.ndarray:
            k = min(int(t / DT), m - 2)
            udot = float(slopes[k])
            uu = float(us[k]) + udot * (t - k * DT)
            hh = float(h[0])
            hn = abs(hh) ** p.n
            sh = (hh > 0) - (hh < 0)
            su = (udot > 0) - (udot < 0)
            return np.array([p.A * udot - (p.beta * abs(udot) * sh + p.gamma * udot) * hn + p.delta * uu * su])

        chosen = None
        for rtol in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9):
            start = time.perf_counter()
            sol = scipy_integrate.solve_ivp(
                rhs, (0.0, t_grid[-1]), [0.0], method="RK45", t_eval=t_grid, rtol=rtol, atol=rtol * 1e-3, max_step=DT
            )
            elapsed = time.perf_counter() - start
            if not sol.success:
                continue
            xi = p.kv * us + p.x0 + sol.y[0]
            err = float(np.max(np.abs(xi - fine)))
            chosen = (rtol, err, elapsed, sol.nfev)
            if err <= target:
                break
        if chosen is not None:
            rtol, err, elapsed, nfev = chosen
            table.add(
                "`scipy.integrate.solve_ivp` (RK45)",
                ns(elapsed, m),
                f"{elapsed / t_sim_m:,.0f}× `simulate`",
                f"rtol {rtol:g}: max error {err:.1e} µm (target {target:.0e} µm; `simulate`: {err_rust:.1e} µm); "
                f"first {m} samples, {nfev / m:.1f} evaluations per sample, max_step = dt (u̇ jumps at every sample)",
            )

    # ---------------------------------------------------------------- offline fit
    fit_module = optional("boucwen.fit")
    if fit_module is not None:
        m = 30_000
        # The paper's 1 Hz record at the vibrometer's 2 nm resolution.
        uf = u[:m]
        xf = x_clean[:m] + 2e-3 * np.random.default_rng(1).standard_normal(m)
        fits = {}
        for method in ("lm", "trf"):
            times, faults = [], []
            for _ in range(max(reps, 5)):
                before = page_faults()
                start = time.perf_counter()
                result = fit_module.fit(uf, xf, DT, method=method)
                times.append(time.perf_counter() - start)
                faults.append(page_faults() - before)
            fits[method] = (float(np.median(times)), min(times), result, faults)
        t_fit, t_min, result, faults = fits["lm"]
        t_trf, trf_min, trf, trf_faults = fits["trf"]
        table.add(
            f"`boucwen.fit`, {m} samples, 2 nm noise",
            f"{t_fit * 1e3:.0f} ms",
            note=f"median of {max(reps, 5)} (min {t_min * 1e3:.0f} ms); {result.nfev} simulations and passes, "
            f"rms error {result.rms_um:.4g} µm{fault_note(faults)}; target ≤ 40 ms",
        )
        table.add(
            'same fit, SciPy `trf` local solver (`method="trf"`)',
            f"{t_trf * 1e3:.0f} ms",
            f"{t_trf / t_fit:.1f}× `boucwen.fit`",
            f"min {trf_min * 1e3:.0f} ms; {trf.nfev} simulations and passes, rms error {trf.rms_um:.4g} µm"
            f"{fault_note(trf_faults)}",
        )

    caption = f"Measured with `python benches/compare.py` on {machine()}; boucwen {boucwen.__version__}."
    print()
    print(caption)
    print()
    print(table.markdown())
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        path = os.path.join(args.out, "results.json")
        with open(path, "w", encoding="utf-8") as fh:
            json.dump({"caption": caption, "rows": [list(row) for row in table.rows]}, fh, indent=1)
        print(f"wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
