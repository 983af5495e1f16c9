"""Wall and CPU time of `boucwen.diagnose` on long records, beside a baseline run.

    python benches/diagnosis_speed.py [--records NAME,...] [--out DIR] [--baseline FILE] [--repeat N]

The records (``--records``, default all that are here):

* ``multisine_20k``: 20 000 samples at 10 kHz, a 2 s multisine, creep and an input lag of
  0.1 µm each, 5 nm of noise (seed 7): a record of a positioning rig's length;
* ``bouc_wen_train``: the Bouc–Wen benchmark's training record (40 960 samples at 750 Hz,
  force in N and displacement in m read in µm), where the data directory holds it
  (:func:`boucwen.datasets.load_bouc_wen`);

* ``multisine_130k``: the record of ``python -m boucwen.experiments.diagnosis_suite
  --speed`` — 130 000 samples at 20 kHz, a 6.5 s multisine, creep and an input lag of
  0.1 µm each, 5 nm of noise (seed 7);
* ``oscillator_40k``: 40 000 samples at 750 Hz of a force-driven hysteretic oscillator,
  m·ÿ + c·ẏ + k·y + z = F, ż = α·ẏ − β·(γ·|ẏ|·|z|^(ν−1)·z + δ·ẏ·|z|^ν), with the
  parameters of the Noël & Schoukens benchmark (m = 2 kg, c = 10 N·s/m, k = 5e4 N/m,
  α = 5e4 N/m, β = 1e3 /m, γ = 0.8, δ = −1.1, ν = 1), F a random-phase multisine of
  lines 5–150 Hz at 50 N RMS (seed 0), y integrated by RK4 at 20× the sampling rate and
  read in µm with 7 µm of white noise: a record the piezo base model (u = F) fits at
  about 20× its noise.

The script makes both records itself, from NumPy and the package's generator of
the suite's records, so it runs against any version of the package: run it on the
previous release with ``--out`` and give that file as ``--baseline`` to print both side
by side (the ratio is baseline / this run). Times are the median of ``--repeat`` runs
(default 1) on the release build installed.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import boucwen
from boucwen.experiments.suite_records import make_suite_record

#: The benchmark's oscillator: m [kg], c [N·s/m], k [N/m], α [N/m], β [1/m], γ, δ, ν.
OSCILLATOR = {"m": 2.0, "c": 10.0, "k": 5e4, "alpha": 5e4, "beta": 1e3, "gamma": 0.8, "delta": -1.1, "nu": 1.0}


def multisine_20k() -> tuple[np.ndarray, np.ndarray, float]:
    rec = make_suite_record(
        (("creep", 0.1), ("input_lag", 0.1)), "multisine", 7, fs_hz=10_000.0, noise_um=0.005, duration_s=2.0
    )
    return rec.u, rec.x, rec.dt


def bouc_wen_train() -> tuple[np.ndarray, np.ndarray, float] | None:
    """The shared training record (force [N], displacement [µm]), or None where the data
    directory does not hold it."""
    from boucwen import datasets

    try:
        rec = datasets.load_bouc_wen()
    except datasets.DataNotFoundError:
        return None
    return rec.force, rec.y * 1e6, rec.dt


def multisine_130k() -> tuple[np.ndarray, np.ndarray, float]:
    rec = make_suite_record(
        (("creep", 0.1), ("input_lag", 0.1)), "multisine", 7, fs_hz=20_000.0, noise_um=0.005, duration_s=6.5
    )
    return rec.u, rec.x, rec.dt


def oscillator_40k(
    n: int = 40_000, fs_hz: float = 750.0, noise_um: float = 7.0, substeps: int = 20
) -> tuple[np.ndarray, np.ndarray, float]:
    """The hysteretic oscillator's record (module docs): force [N] and displacement [µm],
    integrated by classical RK4 at ``substeps`` × the sampling rate (the force a straight
    line between its samples)."""
    rng = np.random.default_rng(0)
    duration = n / fs_hz
    lines = np.arange(np.ceil(5.0 * duration), np.floor(150.0 * duration) + 1) / duration
    phases = rng.uniform(0.0, 2 * np.pi, lines.size)
    t = np.arange(n) / fs_hz
    force = np.sqrt(2.0 / lines.size) * 50.0 * np.sin(2 * np.pi * np.outer(t, lines) + phases).sum(axis=1)
    m, c, k = OSCILLATOR["m"], OSCILLATOR["c"], OSCILLATOR["k"]
    alpha, beta, gamma, delta, nu = (OSCILLATOR[key] for key in ("alpha", "beta", "gamma", "delta", "nu"))

    def rhs(f: float, y: float, v: float, z: float) -> tuple[float, float, float]:
        az = abs(z)
        dz = alpha * v - beta * (gamma * abs(v) * az ** (nu - 1.0) * z + delta * v * az**nu)
        return v, (f - c * v - k * y - z) / m, dz

    h = 1.0 / (fs_hz * substeps)
    y = v = z = 0.0
    out = np.empty(n)
    for i in range(n):
        out[i] = y
        f0 = float(force[i])
        f1 = float(force[i + 1]) if i + 1 < n else f0
        for s in range(substeps):
            fa = f0 + (f1 - f0) * s / substeps
            fm = f0 + (f1 - f0) * (s + 0.5) / substeps
            fb = f0 + (f1 - f0) * (s + 1) / substeps
            k1 = rhs(fa, y, v, z)
            k2 = rhs(fm, y + 0.5 * h * k1[0], v + 0.5 * h * k1[1], z + 0.5 * h * k1[2])
            k3 = rhs(fm, y + 0.5 * h * k2[0], v + 0.5 * h * k2[1], z + 0.5 * h * k2[2])
            k4 = rhs(fb, y + h * k3[0], v + h * k3[1], z + h * k3[2])
            y += h / 6.0 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            v += h / 6.0 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            z += h / 6.0 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
    return force, out * 1e6 + rng.normal(0.0, noise_um, n), 1.0 / fs_hz


RECORDS = {
    "multisine_20k": multisine_20k,
    "bouc_wen_train": bouc_wen_train,
    "multisine_130k": multisine_130k,
    "oscillator_40k": oscillator_40k,
}


def run(repeat: int, names: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {"version": getattr(boucwen, "__version__", "?"), "records": {}}
    for name in names:
        made = RECORDS[name]()
        if made is None:
            print(f"{name}: not on this machine, skipped", file=sys.stderr, flush=True)
            continue
        u, x, dt = made
        times, cpus, answer = [], [], ""
        for _ in range(repeat):
            t0, c0 = time.perf_counter(), time.process_time()
            d = boucwen.diagnose(u, x, dt)
            times.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
            answer = d.summary()
        wall, cpu = statistics.median(times), statistics.median(cpus)
        out["records"][name] = {"samples": int(u.size), "time_s": wall, "cpu_s": cpu, "answer": answer}
        print(f"{name}: {u.size} samples, {wall:.1f} s ({cpu:.1f} s CPU): {answer}", file=sys.stderr, flush=True)
    return out


def table(now: dict[str, Any], baseline: dict[str, Any] | None) -> str:
    lines = [
        "| record | samples | baseline [s] (CPU) | this run [s] (CPU) | ratio (CPU) | answer (this run) |",
        "|---|---|---|---|---|---|",
    ]
    for name, row in now["records"].items():
        base = (baseline or {}).get("records", {}).get(name)
        cpu = row.get("cpu_s", float("nan"))
        before = f"{base['time_s']:.1f} ({base.get('cpu_s', float('nan')):.1f})" if base else "-"
        ratio = f"{base['time_s'] / row['time_s']:.2f}× ({base.get('cpu_s', float('nan')) / cpu:.2f}×)" if base else "-"
        lines.append(
            f"| {name} | {row['samples']} | {before} | {row['time_s']:.1f} ({cpu:.1f}) | {ratio} | {row['answer']} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--out", help="folder for results.json")
    ap.add_argument("--baseline", help="results.json of a baseline run, printed beside this one")
    ap.add_argument("--repeat", type=int, default=1, help="runs per record (the median is reported)")
    ap.add_argument("--records", default=",".join(RECORDS), help=f"comma-separated, of {', '.join(RECORDS)}")
    args = ap.parse_args(argv)
    names = [n.strip() for n in args.records.split(",") if n.strip()]
    unknown = [n for n in names if n not in RECORDS]
    if unknown:
        print(f"diagnosis_speed: no record {unknown[0]!r} (records: {', '.join(RECORDS)})", file=sys.stderr)
        return 2
    baseline = json.loads(Path(args.baseline).read_text(encoding="utf-8")) if args.baseline else None
    now = run(max(1, args.repeat), names)
    now["table"] = table(now, baseline)
    print(now["table"])
    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        (Path(args.out) / "results.json").write_text(json.dumps(now, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
