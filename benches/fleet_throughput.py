"""Fleet throughput: records per second of `boucwen.batch.fit_many` with 1, 2 and 4 local workers.

    python benches/fleet_throughput.py [--rows 8 --cols 8] [--repeats 2] [--workers 1,2,4] [--rounds 1]

Generates a mirror of rows × cols actuators (:mod:`boucwen.fleet.generate`, the records of
the full 32 × 32 fleet: two test patterns, 4 815 samples at 1 kHz), then fits it once per
worker count on a fresh local cluster (one single-threaded process per worker) and prints
one table: cluster start-up [s], compute time from the first submission to the last
result [s], records per second, the speed-up over one worker, the CPU time one record
takes [s] and the share of the cores the workers got (their CPU time over compute time
× min(workers, CPUs)). The machine's load average is printed as the runs go: on a shared
machine other work takes cores too, which the last column shows. With ``--rounds R`` the
sequence of worker counts is run R times and the median is shown.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from boucwen.batch import fit_many
from boucwen.fleet.generate import write_fleet


def load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f}, {five:.2f}, {fifteen:.2f} (1, 5, 15 min) on {os.cpu_count()} CPUs"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=8)
    parser.add_argument("--cols", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=2, help="test patterns per record (default 2, as the fleet)")
    parser.add_argument("--workers", default="1,2,4", help="worker counts, comma-separated (default 1,2,4)")
    parser.add_argument("--rounds", type=int, default=1, help="repetitions of the whole sequence (median shown)")
    args = parser.parse_args(argv)
    counts = [int(w) for w in args.workers.split(",")]

    with tempfile.TemporaryDirectory(prefix="boucwen-fleet-bench-") as tmp:
        root = Path(tmp)
        started = time.perf_counter()
        write_fleet(root / "mirror", rows=args.rows, cols=args.cols, repeats=args.repeats)
        records = args.rows * args.cols
        print(f"{records} records generated in {time.perf_counter() - started:.1f} s; {load()}", flush=True)
        runs: dict[int, list[dict]] = {w: [] for w in counts}
        for r in range(args.rounds):
            for w in counts:
                table = fit_many(
                    root / "mirror" / "records", root / f"out-{w}-{r}", workers=w, progress=False, figure=False
                )
                info = dict(table.attrs["run"])
                info["cpu_s"] = float(table["cpu_s"].sum())
                info["cpu_per_record_s"] = float(table["cpu_s"].median())
                info["core_share"] = info["cpu_s"] / (info["compute_s"] * min(w, os.cpu_count() or 1))
                runs[w].append(info)
                print(
                    f"  round {r + 1}, {w} worker{'s' if w > 1 else ''}: {info['records_per_s']:.2f} records/s "
                    f"({info['compute_s']:.1f} s, {info['core_share']:.0%} of the cores); {load()}",
                    flush=True,
                )
        print(f"after: {load()}")

    base = statistics.median(i["records_per_s"] for i in runs[counts[0]])
    print()
    print(
        f"| workers (1 thread each) | records | start-up [s] | compute [s] | records/s | speed-up vs {counts[0]} "
        "| CPU per record [s] | share of the cores got |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for w in counts:

        def med(name: str, w: int = w) -> float:
            return statistics.median(i[name] for i in runs[w])

        rate = med("records_per_s")
        print(
            f"| {w} | {records} | {med('startup_s'):.1f} | {med('compute_s'):.1f} | {rate:.2f} | {rate / base:.2f}× "
            f"| {med('cpu_per_record_s'):.2f} | {med('core_share'):.0%} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
