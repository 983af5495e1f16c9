"""The tests that tell look-alike effects apart, on the residual of a model.

Effects that leave residuals alike are told apart by two tests, each naming a
*signature* (an effect declares its own: :attr:`boucwen.effects.Effect.signature`).
They are evidence, reported beside the diagnosis's answer; they never accept or reject
an effect:

* **what the residual follows** (signatures ``lowpass_u``, ``t``, ``t_x``): creep follows
  the voltage (a slow relaxation towards it after each change), a drift follows time, a
  gain drift follows time × the displacement. The residual r = x − x̂ is regressed on
  each signal — u through a first-order low-pass of a tenth of the record's length,
  t, t·(x̂ − mean x̂) — each taken beyond an affine map of x̂ (which the base model
  absorbs); the share of r's variance each explains (R²) is reported and the
  largest names what r follows.
* **the shape of the phase** (signatures ``delay``, ``lag``, ``peak``): the transfer
  H(f) from the model's x̂ to the measured x (Welch cross-spectrum, where x̂ has power
  and the coherence is high) is compared with a pure delay (phase −2πfτ, gain 1: the
  group delay is flat), a first-order lag (phase −atan(f/fc), gain falling: the group
  delay falls with f) and a resonance (gain rising above 1 towards a peak). The RMS
  misfit [rad] of the best delay and of the best lag to the measured phase, and the
  largest gain, are reported; the shape named is ``peak`` where the gain exceeds
  1 by more than 5 % at bins of coherence above 0.99 where x̂ has power (neither a
  delay nor a lag amplifies), else the one of least phase misfit. Below its corner a
  lag turns the phase as a delay of 1/(2π·fc) does: where neither misfit undercuts the
  other by :data:`PHASE_MARGIN`, ``lag_or_delay_apart`` is False and the test does not
  choose between the two.

:func:`lookalike_tests` runs both tests and returns their outcomes (JSON-ready);
:func:`named` reads the signatures they name.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.signal import coherence, csd, lfilter, welch

from ..checks import FloatArray
from ..record import Record

__all__ = ["SHAPES", "SIGNALS", "TESTS", "lookalike_tests", "named", "phase_shape", "what_it_follows"]

#: The signals the first test regresses the residual on: u through a slow low-pass
#: (creep), time (a drift), time × the displacement (a gain drift).
SIGNALS = ("lowpass_u", "t", "t_x")
#: The shapes of the phase the second test tells apart: a pure delay, a first-order
#: lag, a gain peak (a mode).
SHAPES = ("delay", "lag", "peak")
#: Least coherence of a frequency bin used by the phase test.
MIN_COHERENCE = 0.9
#: The gain above 1 [-] at bins of at least this coherence that names a resonance.
RESONANCE_GAIN = 0.05
RESONANCE_COHERENCE = 0.99
#: ... and at least this share of the largest power of x̂ (the weak bins between the
#: input's lines hold what the hysteresis makes, not a transfer).
RESONANCE_POWER = 1e-3
#: Least share [-] by which one phase misfit must undercut the other to tell a delay
#: from a lag (within it the phase is as straight as both: a lag far above the band).
PHASE_MARGIN = 0.1
#: Least phase [rad] the shapes are told apart at (smaller: ``"none"``).
MIN_PHASE_RAD = 2e-3


def _beyond(v: FloatArray, basis: FloatArray) -> FloatArray:
    coef, *_ = np.linalg.lstsq(basis, v, rcond=None)
    out: FloatArray = v - basis @ coef
    return out


def what_it_follows(record: Record, x_model: FloatArray) -> dict[str, Any]:
    """The first test (module docs): ``{"r2": {signal: R²}, "follows": signal or "none"}``."""
    u, dt = record.u, record.dt
    n = u.size
    t = np.arange(n) * dt
    tau = max(0.1 * n * dt, 10 * dt)
    a = math.exp(-dt / tau)
    slow_u = lfilter([1 - a], [1, -a], u - u[0]) + u[0]
    basis = np.column_stack([x_model, np.ones(n)])
    r = _beyond(record.x - x_model, basis)
    var = float(r @ r)
    signals = dict(zip(SIGNALS, (slow_u, t, t * (x_model - np.mean(x_model)))))
    r2: dict[str, float] = {}
    for name, s in signals.items():
        v = _beyond(s, basis)
        vv = float(v @ v)
        r2[name] = float((r @ v) ** 2 / (vv * var)) if vv > 0 and var > 0 else 0.0
    best = max(r2, key=r2.__getitem__)
    return {"r2": r2, "follows": best if r2[best] > 0.05 else "none"}


def phase_shape(record: Record, x_model: FloatArray) -> dict[str, Any]:
    """The second test (module docs): the misfit [rad] of the best delay and lag to the
    phase of H, their parameters, the largest gain |H| and the shape named."""
    fs = 1.0 / record.dt
    n = record.u.size
    nper = int(min(n, max(256, 2 ** round(math.log2(n / 8)))))
    xm = x_model - np.mean(x_model)
    xd = record.x - np.mean(record.x)
    f, pxx = welch(xm, fs=fs, nperseg=nper)
    _, pxy = csd(xm, xd, fs=fs, nperseg=nper)
    _, coh = coherence(xm, xd, fs=fs, nperseg=nper)
    sel = (f > 0) & (pxx > 1e-6 * np.max(pxx)) & (coh > MIN_COHERENCE)
    out: dict[str, Any] = {"bins": int(np.sum(sel)), "shape": "none"}
    if np.sum(sel) < 3:
        return out
    fk = f[sel]
    h = pxy[sel] / pxx[sel]
    phase = np.angle(h)
    w = pxx[sel] / np.sum(pxx[sel])
    # Pure delay: least squares of phase = −2πfτ (weighted by the power of x̂).
    tau = float(-np.sum(w * phase * 2 * np.pi * fk) / np.sum(w * (2 * np.pi * fk) ** 2))
    delay_misfit = float(math.sqrt(np.sum(w * (phase + 2 * np.pi * fk * tau) ** 2)))
    # First-order lag: phase = −atan(f/fc), fc on a grid.
    grid = np.geomspace(fk[0] / 10.0, 100.0 * fs, 200)
    misfits = [float(math.sqrt(np.sum(w * (phase + np.arctan(fk / fc)) ** 2))) for fc in grid]
    k = int(np.argmin(misfits))
    gain = float(np.max(np.abs(h)))
    out.update(
        {
            "delay_s": tau,
            "delay_phase_misfit_rad": delay_misfit,
            "lag_fc_hz": float(grid[k]),
            "lag_phase_misfit_rad": misfits[k],
            "max_gain": gain,
        }
    )
    if float(np.max(np.abs(phase))) < MIN_PHASE_RAD:
        return out
    sure = (coh[sel] > RESONANCE_COHERENCE) & (pxx[sel] > RESONANCE_POWER * np.max(pxx))
    peak = float(np.max(np.abs(h[sure]))) if np.any(sure) else 0.0
    out["max_gain_coherent"] = peak
    if peak > 1.0 + RESONANCE_GAIN:
        out["shape"] = "peak"
    else:
        out["shape"] = "delay" if delay_misfit <= misfits[k] else "lag"
        out["lag_or_delay_apart"] = min(delay_misfit, misfits[k]) <= (1.0 - PHASE_MARGIN) * max(
            delay_misfit, misfits[k]
        )
    return out


def named(outcomes: dict[str, Any]) -> set[str]:
    """The signatures the tests' ``outcomes`` (:func:`lookalike_tests`) name: what the
    residual follows and the shape of its phase, the shape only where it is told apart
    (a delay and a lag are not, where ``lag_or_delay_apart`` is False)."""
    out = set()
    follows = outcomes.get("follows", {}).get("follows", "none")
    if follows != "none":
        out.add(follows)
    phase = outcomes.get("phase", {})
    shape = phase.get("shape", "none")
    if shape != "none" and phase.get("lag_or_delay_apart", True):
        out.add(shape)
    return out


#: The tests, by name.
TESTS: dict[str, Callable[[Record, FloatArray], dict[str, Any]]] = {
    "follows": what_it_follows,
    "phase": phase_shape,
}


def lookalike_tests(record: Record, x_model: FloatArray) -> dict[str, Any]:
    """Both tests on the residual of ``x_model`` [µm] (module docs)."""
    return {test: run(record, x_model) for test, run in TESTS.items()}
