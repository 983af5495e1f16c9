"""The next experiment: the input that tells apart the explanations a record could not.

Where the judge cannot tell an effect from its rivals on a record (the ambiguity sets of
:mod:`~boucwen.diagnosis.search`), no rule applied to that record settles it: the
models predict that record equally well. They do not predict every input equally, and
the input on which they differ most is the experiment to run next.

**The explanations** are the returned model and, for each effect of it with rivals, the
same model with that effect swapped for each rival, every one fitted to convergence on
the record (:func:`explanations`; the swaps the search's last round fitted are reused).

**The separation** of two explanations on an input u is the RMS difference of the
displacements they predict there, in units of the record's noise σ̂, after a least-squares
offset and linear trend are removed from the difference: what a record of a new
experiment re-estimates for every model alike (the offset, the trend: a different
zero, a different day's drift, :func:`~boucwen.diagnosis.unseen.carried`) cannot tell
them apart. Effects of the record (a drift, a pickup: :attr:`boucwen.effects.Effect.of_record`)
are left out of every prediction for the same reason.

**The design** (:func:`design`) chooses u by maximin: it maximises the smallest pairwise
separation over the set, within the limits (voltage range, slew rate, sampling interval,
duration). The input is a sequence of segments of equal length; each segment moves to a
level at the largest slew allowed (a step), may play a sine burst of whole cycles about
that level (amplitude within the range and the slew), then holds the level. Each
segment's level, burst amplitude, burst frequency and burst length are the unknowns;
differential evolution searches them (the cost is not smooth: a minimum over pairs), its
first population holding a staircase with holds. What does the separating is read off
the closest pair's squared difference, part by part (:class:`Feature`).

**The baseline** is the better of two generic inputs of the same duration and limits, a
staircase with holds (the levels spread over the range, shuffled) and a random-phase
multisine over the design's band; the designed input must beat it.

**The record's own evidence** (:class:`Segment`): the windows of the record where the
explanations' predictions differ most, with each one's error against the measurement
there.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import differential_evolution

from ..checks import FloatArray, check_finite
from ..effects import VOCABULARY, ExtendedFit, effect_class, simulate_chain
from ..io import write_csv
from ..metrics import rms
from ..record import Record
from . import fits
from .fits import Convergence, Scored
from .policy import DiagnosisPolicy
from .search import rival_order
from .unseen import device_part

__all__ = [
    "Experiment",
    "Explained",
    "Explanation",
    "Feature",
    "Limits",
    "Segment",
    "Separation",
    "design",
    "explanations",
    "separation",
]

#: Segments of a designed input: each a step, a burst and a hold, so the input can
#: hold as many steps and bursts as a creep, a lag or a mode needs to show, while the
#: unknowns (four per segment) stay few enough for a global search.
SEGMENTS = 6
#: Candidate inputs the global search evaluates per generation, and its generations:
#: about 1 600 simulations of each explanation.
POPULATION = 40
GENERATIONS = 40
#: Windows the record is cut into for its own evidence, and how many are reported.
WINDOWS = 16
REPORTED_SEGMENTS = 3
#: Highest burst frequency as a fraction of the sampling rate (four samples a cycle
#: and more keep a sine a sine).
MAX_FREQUENCY_FRACTION = 0.1
#: A part of the input is reported as doing the separating where it holds at least this
#: share of the closest pair's squared difference.
FEATURE_SHARE = 0.1


@dataclass(frozen=True, eq=False)
class Explanation:
    """One model the record could not tell from the others.

    Attributes:
        label: its effects joined by ``+`` (``"base model"`` for none).
        effects: its effects, in the vocabulary's order.
        fit: the model fitted on the record.
        x_record: its displacement over the record [µm].
        held_out_rms_um: its held-out RMS error on the record [µm] (forward
            validation).
        replaces: for a swap, ``(effect of the returned model, rival in its place)``;
            None for the returned model.
    """

    label: str
    effects: tuple[str, ...]
    fit: ExtendedFit
    x_record: FloatArray
    held_out_rms_um: float
    replaces: tuple[str, str] | None = None
    scored: Scored | None = field(default=None, repr=False)

    def predict(self, u: FloatArray, dt: float) -> FloatArray | None:
        """The displacement [µm] it predicts for the voltage ``u`` [V] at interval ``dt``
        [s], from rest (h0 = 0) and without the record's own effects; None where it
        cannot be simulated."""
        return simulate_chain(self.fit.params, device_part(self.fit.effects), u, dt, 0.0)

    def to_dict(self) -> dict[str, Any]:
        """``{"label", "effects", "held_out_rms_um", "replaces"}`` (JSON-ready)."""
        return {
            "label": self.label,
            "effects": list(self.effects),
            "held_out_rms_um": self.held_out_rms_um,
            "replaces": None if self.replaces is None else list(self.replaces),
        }


def _label(names: Sequence[str]) -> str:
    return "+".join(names) if names else "base model"


def _explanation(scored: Scored, replaces: tuple[str, str] | None = None) -> Explanation:
    return Explanation(_label(scored.names), scored.names, scored.fit, scored.x, scored.cv.rms_um, replaces, scored)


def explanations(
    record: Record,
    final: Scored,
    rivals: Mapping[str, set[str]],
    swaps: Mapping[frozenset[str], Scored],
    conv: Convergence,
    policy: DiagnosisPolicy,
) -> tuple[Explanation, ...]:
    """The returned model ``final`` and, for each of its effects with rivals, the model
    with that effect swapped for each rival, fitted to convergence on ``record`` (those in
    ``swaps`` are reused). The returned model comes first."""
    members = [_explanation(final)]
    names = final.names
    held = {frozenset(names)}
    for k in names:
        for r in sorted(rivals.get(k, ()), key=rival_order):
            rest = set(names) - {k}
            if r not in VOCABULARY:  # another structure (the oscillator): not an effect to swap in
                continue
            # An effect tied to a partner (a second mode after a first) comes with it.
            partner = effect_class(r).partner
            adds = (r,) if partner is None or partner in rest else (partner, r)
            key = frozenset(rest | set(adds))
            if r in names or key in held:
                continue
            held.add(key)
            got = swaps.get(key)
            if got is None:
                out = fits.swap(record, final, k, adds, conv, final.cv.folds, policy.max_delay_samples)
                if isinstance(out, str):
                    continue
                got = out
            members.append(_explanation(got, (k, r)))
    return tuple(members)


def _real(name: str, value: Any) -> float:
    """:func:`boucwen.checks.check_finite`, a value that is no number a ValueError too."""
    try:
        return check_finite(name, value)
    except TypeError as exc:
        raise ValueError(str(exc)) from None


def _positive(name: str, value: Any) -> float:
    out = _real(name, value)
    if not out > 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return out


@dataclass(eq=False)
class Explained:
    """What a diagnosis holds for its next experiment: the record, the returned model and
    its rivals (:meth:`boucwen.diagnosis.Diagnosis.next_experiment`). The explanations
    are fitted once, when first asked for."""

    record: Record
    final: Scored
    rivals: dict[str, set[str]]
    swaps: dict[frozenset[str], Scored]
    conv: Convergence
    policy: DiagnosisPolicy
    noise_um: float
    _members: tuple[Explanation, ...] | None = field(default=None, repr=False)

    def members(self) -> tuple[Explanation, ...]:
        """:func:`explanations` of the returned model (computed once)."""
        if self._members is None:
            self._members = explanations(self.record, self.final, self.rivals, self.swaps, self.conv, self.policy)
        return self._members


@dataclass(frozen=True)
class Limits:
    """What the experiment's input must respect.

    Attributes:
        u_min_v, u_max_v: the voltage range [V].
        max_slew_v_per_s: the fastest slew [V/s].
        dt_s: the sampling interval [s].
        duration_s: the experiment's length [s].
    """

    u_min_v: float
    u_max_v: float
    max_slew_v_per_s: float
    dt_s: float
    duration_s: float

    @classmethod
    def of(
        cls,
        record: Record,
        duration_s: float,
        u_min: float | None,
        u_max: float | None,
        max_slew_v_per_s: float | None,
        dt: float | None,
    ) -> Limits:
        """The limits given, the others from ``record`` (its voltage range, its fastest
        slew, its sampling interval); ValueError naming a bad one."""
        duration = _positive("duration_s", duration_s)
        lo = float(np.min(record.u)) if u_min is None else _real("u_min", u_min)
        hi = float(np.max(record.u)) if u_max is None else _real("u_max", u_max)
        if not hi > lo:
            raise ValueError(f"u_max must exceed u_min, got u_min = {lo:g} V, u_max = {hi:g} V")
        fastest = float(np.max(np.abs(np.diff(record.u)))) / record.dt
        slew = fastest if max_slew_v_per_s is None else _positive("max_slew_v_per_s", max_slew_v_per_s)
        interval = record.dt if dt is None else _positive("dt", dt)
        samples = duration / interval
        if samples < 100:
            raise ValueError(f"the experiment must hold at least 100 samples, got {samples:.0f} (duration_s / dt)")
        if samples > 20_000_000:
            raise ValueError(f"the experiment must hold at most 20 000 000 samples, got {samples:.0f}")
        return cls(lo, hi, slew, interval, duration)

    @property
    def samples(self) -> int:
        return round(self.duration_s / self.dt_s)

    def to_dict(self) -> dict[str, float]:
        return {
            "u_min_v": self.u_min_v,
            "u_max_v": self.u_max_v,
            "max_slew_v_per_s": self.max_slew_v_per_s,
            "dt_s": self.dt_s,
            "duration_s": self.duration_s,
        }


@dataclass(frozen=True)
class Separation:
    """The predicted separation of two explanations [noise units: σ̂ of the record].

    Attributes:
        a, b: their labels.
        designed: on the designed input.
        generic: on the generic input (the better of a staircase and a multisine).
    """

    a: str
    b: str
    designed: float
    generic: float

    def to_dict(self) -> dict[str, Any]:
        return {"a": self.a, "b": self.b, "designed": self.designed, "generic": self.generic}


@dataclass(frozen=True)
class Feature:
    """A part of the designed input and what it does for the separation.

    Attributes:
        kind: ``"step"``, ``"burst"`` or ``"hold"``.
        start_s, stop_s: where it lies [s from the start of the experiment].
        detail: the part in words (levels [V], frequency [Hz], length [s]).
        share: its share of the closest pair's squared difference [-].
    """

    kind: str
    start_s: float
    stop_s: float
    detail: str
    share: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "start_s": self.start_s,
            "stop_s": self.stop_s,
            "detail": self.detail,
            "share": self.share,
        }


@dataclass(frozen=True)
class Segment:
    """A window of the record where the explanations differ.

    Attributes:
        start_s, stop_s: where it lies [s from the record's start].
        kind: what the input does there (``"hold"``, ``"step"``, ``"oscillation"``).
        detail: the input there in words.
        separation: the closest pair's RMS difference there [noise units].
        errors_um: each explanation's RMS error against the measurement there [µm].
    """

    start_s: float
    stop_s: float
    kind: str
    detail: str
    separation: float
    errors_um: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {
            "start_s": self.start_s,
            "stop_s": self.stop_s,
            "kind": self.kind,
            "detail": self.detail,
            "separation": self.separation,
            "errors_um": dict(self.errors_um),
        }


@dataclass(frozen=True, eq=False)
class Experiment:
    """The input to record next, and what it is predicted to settle
    (:meth:`boucwen.diagnosis.Diagnosis.next_experiment`).

    Attributes:
        u: the voltage to play [V] (empty where the answer holds no ambiguity).
        dt: its sampling interval [s].
        explanations: the explanations it separates (the returned model first).
        separations: per pair, the predicted separation on the designed and the
            generic input [noise units].
        features: what in the input does the separating (the closest pair's).
        generic_u: the generic input of the same duration and limits [V].
        generic_kind: ``"staircase"`` or ``"multisine"``.
        segments: the record's own windows that separate the set best.
        limits: the limits the inputs respect.
        noise_um: the record's noise σ̂ [µm] (the unit of the separations).
        note: the answer in words.
    """

    u: FloatArray
    dt: float
    explanations: tuple[Explanation, ...]
    separations: tuple[Separation, ...]
    features: tuple[Feature, ...]
    generic_u: FloatArray
    generic_kind: str
    segments: tuple[Segment, ...]
    limits: Limits | None
    noise_um: float
    note: str

    @property
    def ambiguous(self) -> bool:
        """The record left two explanations or more."""
        return len(self.explanations) >= 2

    @property
    def t(self) -> FloatArray:
        """Time of each sample of :attr:`u` [s]."""
        return np.arange(self.u.size, dtype=np.float64) * self.dt

    @property
    def min_separation(self) -> float:
        """The smallest pairwise separation on the designed input [noise units] (nan
        without a pair)."""
        return min((s.designed for s in self.separations), default=math.nan)

    @property
    def generic_min_separation(self) -> float:
        """The same on the generic input [noise units]."""
        return min((s.generic for s in self.separations), default=math.nan)

    def predictions(self, generic: bool = False) -> dict[str, FloatArray]:
        """Each explanation's displacement [µm] on the designed input (the generic one
        with ``generic``), offset and trend removed as in the separation."""
        u = self.generic_u if generic else self.u
        out = _predictions(self.explanations, u, self.dt)
        if out is None:  # pragma: no cover - checked when designed
            raise ValueError("an explanation cannot be simulated on the input")
        return {e.label: _detrended(x) for e, x in zip(self.explanations, out)}

    def write_csv(self, path: Any) -> None:
        """Writes the input as ``t_s,u_V`` (one row per sample) to play on the bench;
        ValueError where the answer holds no ambiguity (nothing to record)."""
        if not self.ambiguous:
            raise ValueError(f"no experiment to write: {self.note}")
        write_csv(path, {"t_s": self.t, "u_V": self.u})

    def plot(self, path: Any) -> None:
        """A figure: the designed and the generic input, and each explanation's
        prediction on both (offset and trend removed), in noise units against the
        returned model's."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(2, 2, figsize=(11, 6), sharex="col", constrained_layout=True)
        for col, (generic, title) in enumerate(
            ((False, "designed input"), (True, f"generic input ({self.generic_kind})"))
        ):
            u = self.generic_u if generic else self.u
            t = np.arange(u.size) * self.dt
            axes[0, col].plot(t, u, lw=0.8, color="k")
            axes[0, col].set_title(title)
            axes[0, col].set_ylabel("u [V]")
            preds = self.predictions(generic)
            ref = preds[self.explanations[0].label]
            for label, x in preds.items():
                axes[1, col].plot(t, (x - ref) / self.noise_um, lw=0.8, label=label)
            axes[1, col].set_ylabel("prediction − returned model [σ̂]")
            axes[1, col].set_xlabel("t [s]")
            sep = self.min_separation if not generic else self.generic_min_separation
            axes[1, col].text(0.01, 0.95, f"closest pair: {sep:.3g} σ̂", transform=axes[1, col].transAxes, va="top")
        axes[1, 0].legend(fontsize=8, loc="lower right")
        fig.savefig(path, dpi=120)
        plt.close(fig)

    def summary(self) -> str:
        """The answer in a few lines."""
        if not self.ambiguous:
            return self.note
        lines = [self.note]
        lines += [f"  {s.a} vs {s.b}: {s.designed:.3g} σ̂ designed, {s.generic:.3g} σ̂ generic" for s in self.separations]
        lines += [f"  separating: {f.detail} ({f.share:.0%})" for f in self.features]
        lines += [
            f"  in the record: {s.start_s:.4g}–{s.stop_s:.4g} s, {s.detail}: {s.separation:.3g} σ̂ apart; errors "
            + ", ".join(f"{k} {v:.4g} µm" for k, v in s.errors_um.items())
            for s in self.segments
        ]
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """The experiment without its arrays (JSON-ready)."""
        return {
            "ambiguous": self.ambiguous,
            "note": self.note,
            "dt": self.dt,
            "samples": int(self.u.size),
            "explanations": [e.to_dict() for e in self.explanations],
            "separations": [s.to_dict() for s in self.separations],
            "min_separation": self.min_separation,
            "generic_kind": self.generic_kind,
            "generic_min_separation": self.generic_min_separation,
            "features": [f.to_dict() for f in self.features],
            "segments": [s.to_dict() for s in self.segments],
            "limits": None if self.limits is None else self.limits.to_dict(),
            "noise_um": self.noise_um,
        }


# ----------------------------------------------------------------------------- separation


def _detrended(x: FloatArray) -> FloatArray:
    """``x`` less its least-squares offset and linear trend."""
    n = x.size
    s = np.linspace(-1.0, 1.0, n)
    return np.asarray(x - np.mean(x) - s * (np.dot(s, x) / np.dot(s, s)), dtype=np.float64)


def separation(xa: FloatArray, xb: FloatArray, noise_um: float) -> float:
    """The separation of two predicted displacements [µm] (module docs) [noise units]."""
    return rms(_detrended(xa - xb)) / noise_um


def _predictions(members: Sequence[Explanation], u: FloatArray, dt: float) -> list[FloatArray] | None:
    out = []
    for e in members:
        x = e.predict(u, dt)
        if x is None:
            return None
        out.append(x)
    return out


def _pairs(k: int) -> list[tuple[int, int]]:
    return [(i, j) for i in range(k) for j in range(i + 1, k)]


def _all_separations(xs: Sequence[FloatArray], noise_um: float) -> list[float]:
    return [separation(xs[i], xs[j], noise_um) for i, j in _pairs(len(xs))]


# ----------------------------------------------------------------------------- the inputs


@dataclass(frozen=True)
class _Part:
    kind: str
    start: int
    stop: int
    detail: str


def _band(lim: Limits, segments: int) -> tuple[float, float]:
    """The bursts' frequency band [Hz]: two cycles in a segment at least, four samples a
    cycle at most."""
    seg_s = lim.duration_s / segments
    return 2.0 / seg_s, MAX_FREQUENCY_FRACTION / lim.dt_s


def _input(theta: FloatArray, lim: Limits, segments: int) -> tuple[FloatArray, list[_Part]]:
    """The input of the unknowns ``theta`` (per segment: level, burst amplitude, log
    burst frequency, burst length, each scaled to [0, 1]) and its parts."""
    n = lim.samples
    dt = lim.dt_s
    lo, hi = lim.u_min_v, lim.u_max_v
    f_lo, f_hi = _band(lim, segments)
    u = np.empty(n)
    parts: list[_Part] = []
    edges = np.linspace(0, n, segments + 1).astype(int)
    prev = lo
    max_du = lim.max_slew_v_per_s * dt
    for k in range(segments):
        a, b = int(edges[k]), int(edges[k + 1])
        level, amp, logf, frac = (float(v) for v in theta[4 * k : 4 * k + 4])
        target = lo + level * (hi - lo)
        ramp = math.ceil(abs(target - prev) / max_du) if target != prev else 0
        if ramp > b - a:
            ramp = b - a
            target = prev + math.copysign(max_du * ramp, target - prev)
        if ramp:
            u[a : a + ramp] = prev + (target - prev) * np.arange(1, ramp + 1) / ramp
            parts.append(_Part("step", a, a + ramp, f"step {prev:.4g} → {target:.4g} V"))
        start = a + ramp
        room = b - start
        burst = 0
        if f_hi > f_lo and room > 1:
            f = math.exp(math.log(f_lo) + logf * (math.log(f_hi) - math.log(f_lo)))
            cycles = math.floor(frac * (room - 1) * dt * f)
            burst = round(cycles / (f * dt))
            if cycles >= 1 and burst >= 4:
                f = cycles / (burst * dt)  # whole cycles in whole samples: the burst ends on its level
            size = amp * min(target - lo, hi - target, lim.max_slew_v_per_s / (2 * math.pi * f))
            if cycles < 1 or burst < 4 or burst > room - 1 or size <= 0:
                burst = 0
            else:
                s = np.arange(burst) * dt
                u[start : start + burst] = target + size * np.sin(2 * math.pi * f * s)
                parts.append(
                    _Part(
                        "burst",
                        start,
                        start + burst,
                        f"{cycles} cycle{'s' if cycles > 1 else ''} of ±{size:.3g} V at {f:.4g} Hz",
                    )
                )
        u[start + burst : b] = target
        if b > start + burst:
            parts.append(
                _Part("hold", start + burst, b, f"hold at {target:.4g} V for {(b - start - burst) * dt:.3g} s")
            )
        prev = target
    return np.clip(u, lo, hi), parts


def _staircase_theta(segments: int, seed: int) -> FloatArray:
    """The unknowns of a staircase with holds: levels spread over the range, shuffled."""
    levels = np.random.default_rng(seed).permutation(np.linspace(0.1, 0.9, segments))
    theta = np.zeros(4 * segments)
    theta[0::4] = levels
    return theta


def _multisine(lim: Limits, segments: int, seed: int) -> FloatArray:
    """A random-phase multisine over the design's band, log-spaced lines, scaled into
    the range and the slew."""
    n = lim.samples
    t = np.arange(n) * lim.dt_s
    f_lo, f_hi = _band(lim, segments)
    f_lo = max(1.0 / lim.duration_s, min(f_lo, f_hi))
    freqs = np.geomspace(f_lo, max(f_hi, f_lo), 12)
    phases = np.random.default_rng(seed).uniform(0, 2 * math.pi, freqs.size)
    wave = np.sum(np.sin(2 * math.pi * freqs[:, None] * t[None, :] + phases[:, None]), axis=0)
    wave -= np.mean(wave)
    peak = float(np.max(np.abs(wave)))
    slope = float(np.max(np.abs(np.diff(wave)))) / lim.dt_s
    half = 0.5 * (lim.u_max_v - lim.u_min_v)
    scale = min(half / peak if peak > 0 else 0.0, lim.max_slew_v_per_s / slope if slope > 0 else math.inf)
    u = 0.5 * (lim.u_max_v + lim.u_min_v) + scale * wave
    return np.asarray(np.clip(u, lim.u_min_v, lim.u_max_v), dtype=np.float64)


# ----------------------------------------------------------------------------- the design


def _closest(members: Sequence[Explanation], u: FloatArray, dt: float, noise_um: float) -> float:
    xs = _predictions(members, u, dt)
    return min(_all_separations(xs, noise_um)) if xs is not None else 0.0


def _features(xs: Sequence[FloatArray], parts: Sequence[_Part], noise_um: float, dt: float) -> tuple[Feature, ...]:
    seps = _all_separations(xs, noise_um)
    i, j = _pairs(len(xs))[int(np.argmin(seps))]
    d2 = _detrended(xs[i] - xs[j]) ** 2
    total = float(np.sum(d2))
    if not total > 0:
        return ()
    found = [
        Feature(p.kind, p.start * dt, p.stop * dt, p.detail, float(np.sum(d2[p.start : p.stop])) / total) for p in parts
    ]
    return tuple(sorted((f for f in found if f.share >= FEATURE_SHARE), key=lambda f: -f.share)[:5])


def _describe(u: FloatArray, dt: float, span: float) -> tuple[str, str]:
    """What the input does in a window: a hold, a step, or an oscillation (its dominant
    frequency)."""
    ptp = float(np.ptp(u))
    if ptp < 0.05 * span:
        return "hold", f"hold at {np.mean(u):.4g} V"
    jump = float(np.max(np.abs(np.diff(u)))) if u.size > 1 else 0.0
    if jump >= 0.5 * ptp and ptp >= 0.2 * span:
        k = int(np.argmax(np.abs(np.diff(u))))
        return "step", f"step {u[k]:.4g} → {u[k + 1]:.4g} V"
    spectrum = np.abs(np.fft.rfft(u - np.mean(u)))
    freqs = np.fft.rfftfreq(u.size, dt)
    f = float(freqs[int(np.argmax(spectrum[1:])) + 1]) if u.size > 2 else 0.0
    return "oscillation", f"oscillation of {ptp:.3g} V peak to peak near {f:.3g} Hz"


def _record_segments(record: Record, members: Sequence[Explanation], noise_um: float) -> tuple[Segment, ...]:
    n = len(record)
    edges = np.linspace(0, n, WINDOWS + 1).astype(int)
    span = max(float(np.ptp(record.u)), 1e-12)
    found = []
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a < 2:
            continue
        sl = slice(int(a), int(b))
        seps = [rms(members[i].x_record[sl] - members[j].x_record[sl]) / noise_um for i, j in _pairs(len(members))]
        kind, detail = _describe(record.u[sl], record.dt, span)
        errors = {m.label: rms(record.x[sl] - m.x_record[sl]) for m in members}
        found.append(Segment(float(record.t[a]), float(record.t[b - 1]), kind, detail, min(seps), errors))
    return tuple(sorted(found, key=lambda s: -s.separation)[:REPORTED_SEGMENTS])


def design(
    record: Record,
    members: Sequence[Explanation],
    noise_um: float,
    limits: Limits,
    *,
    seed: int = 0,
) -> Experiment:
    """The experiment that separates ``members`` best within ``limits`` (module docs);
    ``noise_um`` the record's noise σ̂ [µm], ``seed`` the global search's."""
    members = tuple(members)
    noise = max(noise_um, 1e-12)
    if len(members) < 2:
        return Experiment(
            np.empty(0),
            limits.dt_s,
            members,
            (),
            (),
            np.empty(0),
            "",
            (),
            limits,
            noise,
            "no effect named has a rival: the record already tells the returned model from every "
            "candidate it was judged against, so no experiment is needed to separate explanations",
        )
    segments = SEGMENTS
    dims = 4 * segments
    stair = _staircase_theta(segments, seed)
    rng = np.random.default_rng(seed)
    init = rng.uniform(size=(POPULATION, dims))
    init[0] = stair

    def cost(theta: FloatArray) -> float:
        return -_closest(members, _input(theta, limits, segments)[0], limits.dt_s, noise)

    found = differential_evolution(
        cost,
        [(0.0, 1.0)] * dims,
        init=init,
        maxiter=GENERATIONS,
        seed=seed,
        polish=False,
        tol=0.0,
        mutation=(0.5, 1.0),
        recombination=0.7,
    )
    u, parts = _input(np.asarray(found.x), limits, segments)
    staircase = _input(stair, limits, segments)[0]
    multisine = _multisine(limits, segments, seed)
    xs = _predictions(members, u, limits.dt_s)
    generics = [
        (kind, g, _predictions(members, g, limits.dt_s))
        for kind, g in (("staircase", staircase), ("multisine", multisine))
    ]
    generic_kind, generic_u, xg = max(
        generics, key=lambda g: min(_all_separations(g[2], noise)) if g[2] is not None else 0.0
    )
    if xs is None or xg is None:
        raise ValueError("an explanation cannot be simulated on the designed input")
    seps = tuple(
        Separation(members[i].label, members[j].label, d, g)
        for (i, j), d, g in zip(_pairs(len(members)), _all_separations(xs, noise), _all_separations(xg, noise))
    )
    closest = min(s.designed for s in seps)
    generic = min(s.generic for s in seps)
    note = (
        f"{len(members)} explanations the record could not tell apart ({', '.join(m.label for m in members)}); "
        f"the designed input separates the closest pair by {closest:.3g} σ̂ "
        f"(σ̂ = {noise * 1e3:.3g} nm), the generic {generic_kind} by {generic:.3g} σ̂"
    )
    return Experiment(
        u,
        limits.dt_s,
        members,
        seps,
        _features(xs, parts, noise, limits.dt_s),
        generic_u,
        generic_kind,
        _record_segments(record, members, noise),
        limits,
        noise,
        note,
    )
