"""Smoke test of an installed boucwen wheel.

scripts/wheel.sh runs it in a fresh virtual environment holding the wheel and its
dependencies from PyPI, with no cargo or rustc on PATH, from a folder outside the
repository (so the source tree's python/ cannot be imported). It checks the import, the
simulation, the online identifier, the offline fit and the command line.
"""

import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import boucwen


def check(ok: bool, what: str) -> None:
    if not ok:
        raise SystemExit(f"wheel smoke test failed: {what}")
    print(f"  ok: {what}")


def run(*args: str, cwd: Path) -> str:
    proc = subprocess.run(list(args), capture_output=True, text=True, cwd=cwd, timeout=300)
    if proc.returncode != 0:
        raise SystemExit(f"wheel smoke test failed: {' '.join(args)} exited {proc.returncode}\n{proc.stderr}")
    return proc.stdout


def main() -> None:
    started = time.perf_counter()
    for tool in ("cargo", "rustc"):
        check(shutil.which(tool) is None, f"no {tool} on PATH")
    where = Path(boucwen.__file__).resolve()
    check(Path(sys.prefix).resolve() in where.parents, f"boucwen {boucwen.__version__} imported from {where.parent}")

    # A short record of the paper's 1 Hz model: a 1 Hz cosine, 2 s at 2 kHz.
    p = boucwen.Params.paper_1hz()
    dt = 5e-4
    t = np.arange(4000) * dt
    u = 50.0 - 50.0 * np.cos(2.0 * np.pi * t)
    x, h_final = boucwen.simulate(p, u, dt)
    check(x.shape == u.shape and bool(np.all(np.isfinite(x))), f"simulate: {x.size} samples, h_final {h_final:.3f} µm")

    ident = boucwen.Identifier(dt, p)
    x_hat = np.array([ident.push(float(uk), float(xk)) for uk, xk in zip(u, x)])
    err = float(np.max(np.abs(x_hat - x)))
    finite = bool(np.all(np.isfinite(x_hat)))
    check(finite and err < 0.1, f"Identifier.push over {u.size} samples, max error {err:.2e} µm")

    fit = boucwen.fit(u, x, dt)
    check(fit.success and fit.rms_um < 1e-3, f"fit: rms {fit.rms_um:.2e} µm, kv {fit.params.kv:.4f} µm/V (true 0.19)")

    boucwen_cmd = shutil.which("boucwen")
    if boucwen_cmd is None:
        raise SystemExit("wheel smoke test failed: no boucwen command on PATH")
    check(Path(sys.prefix).resolve() in Path(boucwen_cmd).resolve().parents, f"boucwen command at {boucwen_cmd}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        check("usage: boucwen" in run(boucwen_cmd, "--help", cwd=folder), "boucwen --help")
        record = folder / "small.csv"
        np.savetxt(record, np.column_stack([t, u, x]), delimiter=",", header="t_s,u_V,x_um", comments="")
        out = run(boucwen_cmd, "fit", "small.csv", "--model", "M.json", cwd=folder)
        check("kv" in out and (folder / "M.json").is_file(), "boucwen fit small.csv --model M.json")
        np.savetxt(folder / "U.csv", np.column_stack([t, u]), delimiter=",", header="t_s,u_V", comments="")
        run(boucwen_cmd, "simulate", "--model", "M.json", "U.csv", "--out", "X.csv", cwd=folder)
        x_cli = np.loadtxt(folder / "X.csv", delimiter=",", skiprows=1)[:, 2]
        err = float(np.max(np.abs(x_cli - x)))
        check(err < 1e-3, f"boucwen simulate --model M.json U.csv --out X.csv: max error {err:.1e} µm")
    print(f"wheel smoke test passed ({time.perf_counter() - started:.1f} s)")


if __name__ == "__main__":
    main()
