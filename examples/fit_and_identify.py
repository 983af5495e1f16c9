"""Fit a record offline, identify online sample by sample, and score the model open loop.

Run: ``python examples/fit_and_identify.py`` (after ``bash scripts/main.sh`` or
``pip install .``). Uses the simulated bench of ``boucwen.plant`` as the "measurement".
"""

from __future__ import annotations

import numpy as np

import boucwen
from boucwen import evaluation, plant


def main() -> None:
    dt = plant.DEFAULT_DT  # s
    _, u_cmd, segments = plant.paper_input(dt, ((1.0, 2.0), (10.0, 0.3), (100.0, 0.03)))
    rec = plant.measure(u_cmd, dt, seed=1)  # u [V], x [µm]
    f1, lo, hi = segments[0]
    fit = boucwen.fit(rec.u[lo:hi], rec.x[lo:hi], dt)  # offline, on the 1 Hz part
    print(f"offline fit on {f1:g} Hz: {fit.params}, rms {fit.rms_um:.3f} µm")
    ident = boucwen.Identifier(dt, fit.params, fit.h0)  # online, from the fit
    score, _, one_step = evaluation.period_ahead(ident, rec.u, rec.x, dt, segments)
    fixed = evaluation.fixed_model(fit.params, fit.h0, rec.u, rec.x, dt, segments)
    baseline = evaluation.one_step_baselines(rec.x, segments, dt)["two_tap"]
    print(f"{'f [Hz]':>8}{'offline':>10}{'online':>10}{'1-step':>10}{'two-tap':>10}   [µm, max over the last period]")
    for f, _, _ in segments:
        k = evaluation.key(f)
        one = evaluation.one_step_scores(rec.x, one_step, segments, dt)[k]
        print(f"{k:>8}{fixed[k]:>10.3f}{score[k]:>10.3f}{one:>10.3f}{baseline[k]:>10.3f}")
    print("status:", ident.status)
    assert np.all(np.isfinite(one_step))


if __name__ == "__main__":
    main()
