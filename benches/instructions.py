#!/usr/bin/env python3
"""Instructions per sample of the Python-side speed figures, counted by callgrind.

    python benches/instructions.py                 # every workload (a few minutes)
    python benches/instructions.py simulate fit    # some of them

Wall times on a shared host move with the load; the count of instructions a workload
executes does not (it moves with the code, the compiler and the libraries). Each
workload is the one of the same row of ``benches/compare.py``, on the same data (the
paper's input at 10 kHz, 33 800 samples, 1 nm of noise; the fit on its first 30 000
samples with 2 nm): ``simulate``; ``horizon_push_many`` (``Identifier.horizon(...)
.push_many``, the window pass in sync); ``rpem_push`` (``Identifier.rpem(...).push``
from a Python loop, the loop included); ``fit`` (``boucwen.fit``, its threads' work
summed).

Each workload runs under ``valgrind --tool=callgrind`` twice, once with one repeat and
once with three, in a fresh interpreter; the difference of the two totals over two
repeats is the workload's own count (start-up, imports and data cancel), printed per
sample (per call for ``fit``). Run it against two builds to compare them: the figure
moves with the code, not with the machine's load.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
from typing import Any, Callable

import numpy as np

DT = 1e-4
#: The samples of the fit's record (the first 30 000 of the paper's input: its 1 Hz part).
FIT_SAMPLES = 30_000


def _data() -> tuple[Any, Any, Any, Any]:
    import boucwen

    params = boucwen.Params.paper_1hz()
    u = np.asarray(boucwen.paper_input(DT, 0.05))
    x_clean, _ = boucwen.simulate(params, u, DT)
    x = x_clean + 1e-3 * np.random.default_rng(0).standard_normal(u.size)
    return params, u, x_clean, x


def workloads() -> dict[str, tuple[Callable[[], Callable[[], object]], Callable[[int], int]]]:
    """Name → (a builder of the call to count, the samples one call processes for an
    input of n samples)."""

    def simulate() -> Callable[[], object]:
        import boucwen

        params, u, _, _ = _data()
        return lambda: boucwen.simulate(params, u, DT)

    def horizon_push_many() -> Callable[[], object]:
        from boucwen import Identifier

        params, u, _, x = _data()
        return lambda: Identifier.horizon(DT, params).push_many(u, x)

    def rpem_push() -> Callable[[], object]:
        from boucwen import Identifier

        params, u, _, x = _data()
        ul, xl = u.tolist(), x.tolist()

        def loop() -> None:
            push = Identifier.rpem(DT, params).push
            for a, b in zip(ul, xl):
                push(a, b)

        return loop

    def fit() -> Callable[[], object]:
        import boucwen

        _, u, x_clean, _ = _data()
        xf = x_clean[:FIT_SAMPLES] + 2e-3 * np.random.default_rng(1).standard_normal(FIT_SAMPLES)
        return lambda: boucwen.fit(u[:FIT_SAMPLES], xf, DT)

    def samples(n: int) -> int:
        return n

    return {
        "simulate": (simulate, samples),
        "horizon_push_many": (horizon_push_many, samples),
        "rpem_push": (rpem_push, samples),
        "fit": (fit, lambda n: 1),
    }


def _run(name: str, repeats: int) -> None:
    """Runs workload ``name`` ``repeats`` times (what callgrind counts)."""
    call = workloads()[name][0]()
    for _ in range(repeats):
        call()


def _count(name: str, repeats: int) -> int:
    """Instructions of a fresh interpreter running ``name`` ``repeats`` times."""
    proc = subprocess.run(
        [
            "valgrind",
            "--tool=callgrind",
            "--callgrind-out-file=/dev/null",
            sys.executable,
            __file__,
            "--run",
            name,
            "--repeats",
            str(repeats),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    found = re.search(r"Collected\s*:\s*(\d+)", proc.stderr)
    if proc.returncode != 0 or found is None:
        raise RuntimeError(f"callgrind on {name} failed ({proc.returncode}): {proc.stderr[-2000:]}")
    return int(found.group(1))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("names", nargs="*", help=f"workloads (default all: {', '.join(workloads())})")
    parser.add_argument("--run", metavar="NAME", help=argparse.SUPPRESS)
    parser.add_argument("--repeats", type=int, default=1, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.run:
        _run(args.run, args.repeats)
        return 0
    if shutil.which("valgrind") is None:
        print("valgrind is not on PATH (apt-get install valgrind)", file=sys.stderr)
        return 2
    table = workloads()
    names = args.names or list(table)
    unknown = [n for n in names if n not in table]
    if unknown:
        parser.error(f"unknown workload(s) {', '.join(unknown)}; choose from {', '.join(table)}")
    import boucwen

    n = int(np.asarray(boucwen.paper_input(DT, 0.05)).size)
    print(f"boucwen {boucwen.__version__} from {boucwen.__file__}")
    for name in names:
        one, three = _count(name, 1), _count(name, 3)
        per_call = (three - one) / 2.0
        units = table[name][1](FIT_SAMPLES if name == "fit" else n)
        unit = "call" if name == "fit" else "sample"
        print(f"{name}: {per_call / units:,.0f} instructions per {unit} ({one:,} and {three:,} in total)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
