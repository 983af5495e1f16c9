"""The result of a diagnosis and the files it is written to (JSON report, CSV predictions)."""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._core import EffectSet, Params
from ..boundedness import Boundedness
from ..checks import FloatArray
from ..effects import Effect
from ..io import jsonable, write_csv
from ..residual import Unexplained
from .fits import AtBound
from .judge import Decision
from .unseen import Unseen

if TYPE_CHECKING:
    from ..oscillator import OscillatorFit
    from .experiment import Experiment, Explained

__all__ = [
    "AtBound",
    "Diagnosis",
    "ModelFit",
    "NamedEffect",
    "NamedStructure",
    "jsonable",
    "write_predictions",
    "write_report",
]


@dataclass(frozen=True)
class ModelFit:
    """A model the diagnosis fitted: the base parameters and the initial hysteresis state.

    Attributes:
        params: the base :class:`boucwen.Params`.
        h0_um: initial hysteresis state h(0) [µm].
    """

    params: Params
    h0_um: float

    def to_dict(self) -> dict[str, Any]:
        """``{"base": {kv, x0, A, beta, gamma, n, delta}, "h0_um": …}`` (JSON-ready)."""
        return {"base": self.params.to_dict(), "h0_um": self.h0_um}


@dataclass(frozen=True)
class NamedEffect:
    """An effect the diagnosis named, with its fitted parameters and how sure it is.

    Attributes:
        effect: the typed effect (:mod:`boucwen.effects`), with its fitted parameters.
        level: ``"confident"`` or ``"tentative"``: confident only where no other
            candidate lay within the judge's margin of it (its rivals) and the model
            explains what the record holds beyond its noise.
        why: the reason for the level.
        rivals: the effects the record did not tell it from, in the vocabulary's order.
    """

    effect: Effect
    level: str
    why: str
    rivals: tuple[str, ...] = ()

    @property
    def competing(self) -> str | None:
        """The rivals in words (``"creep or drift"``), or None."""
        return " or ".join(self.rivals) if self.rivals else None

    @property
    def name(self) -> str:
        """The effect's name in the vocabulary."""
        return self.effect.name

    def to_dict(self) -> dict[str, Any]:
        """``{"effect": name, "params": {…}, "level", "why", "rivals", "competing"}`` (JSON-ready)."""
        return {
            "effect": self.name,
            "params": self.effect.to_dict(),
            "level": self.level,
            "why": self.why,
            "rivals": list(self.rivals),
            "competing": self.competing,
        }


@dataclass(frozen=True, eq=False)
class NamedStructure:
    """The model class returned where it is not the input-driven Bouc–Wen model: the
    hysteretic oscillator (:mod:`boucwen.oscillator`), whose hysteresis is driven by the
    output's motion, the input taken as the force [N] and the displacement in m.

    Attributes:
        name: ``"oscillator"``.
        level: ``"confident"`` or ``"tentative"`` (as for an effect).
        why: the reason for the level.
        fit: the oscillator fitted to the whole record
            (:class:`boucwen.oscillator.OscillatorFit`; its ``y`` in m).
        held_out_rms_um: its held-out RMS error [µm].
    """

    name: str
    level: str
    why: str
    fit: OscillatorFit
    held_out_rms_um: float

    def to_dict(self) -> dict[str, Any]:
        """``{"name", "level", "why", "fit", "held_out_rms_um"}`` (JSON-ready)."""
        return {
            "name": self.name,
            "level": self.level,
            "why": self.why,
            "fit": self.fit.to_dict(),
            "held_out_rms_um": self.held_out_rms_um,
        }


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of :func:`boucwen.diagnose`.

    Attributes:
        effects: names of the effects added, in the order added ([] when none).
        rms_before_um, max_before_um: RMS and maximum absolute error [µm] of the base
            model fitted on the whole record.
        rms_after_um, max_after_um: the same for the returned model (equal to *before*
            when no effect was added).
        params: the returned model's base :class:`boucwen.Params`.
        h0_um: the returned model's initial hysteresis state [µm].
        effect_set: the returned model's effects, a :class:`boucwen.EffectSet` with
            their fitted parameters (empty when none was added).
        base_only: the base model alone, fitted on the whole record
            (:class:`ModelFit`).
        evidence: what the residual showed and the search's rounds (JSON-ready; the
            decisions themselves, typed, are :attr:`decisions`).
        x_base, x_extended: displacement [µm] of the base and returned models over the
            record.
        unexplained: what the returned model leaves unexplained: its residual against the
            noise estimated from the record, the signals, spectral lines and time spans
            it follows, and whether it is consistent with noise
            (:class:`~boucwen.diagnosis.unexplained.Unexplained`; None if not computed).
        named_effects: the effects of the returned model, typed, each with its
            confidence and rivals (:class:`NamedEffect`), in the order added.
        decisions: every move the search judged, in order
            (:class:`~boucwen.diagnosis.judge.Decision`), then those on the validation
            record.
        taken: the moves the search took, in order.
        at_bounds: the returned model's unknowns that ended on a bound of the fit
            (:class:`AtBound`).
        base_loop: the base model's loop-shape unknowns (n, β + γ, β − γ) that ended on
            a bound of its fit (:func:`boucwen.diagnosis.fits.loop_on_bounds`): where any
            did, the base loop does not fit this device, and the effects named beside it
            may be taking up what the loop lacks.
        unseen: errors on data the fits did not see [µm]: forward validation of the
            base and returned models and, with validation records, both carried to each
            (:class:`~boucwen.diagnosis.unseen.Unseen`; None if not computed).
        explained: the record, the returned model and its rivals, for
            :meth:`next_experiment` (None where the diagnosis was not run here).
        structure: where the returned model is the hysteretic oscillator rather than the
            input-driven model (:class:`NamedStructure`); None otherwise. Then
            ``x_extended``, ``rms_after_um``, ``max_after_um``, ``unexplained`` and
            ``unseen`` are the oscillator's, while ``params``, ``h0_um``, ``effect_set``
            and ``named_effects`` stay the best input-driven model's (its rival).
        boundedness: the returned model driven over the record's range by full-range
            sines, steps and triangles (:func:`boucwen.boundedness.check`): whether its
            output stays within the stated multiple of the record's range (None if not
            computed).
    """

    effects: list[str]
    rms_before_um: float
    max_before_um: float
    rms_after_um: float
    max_after_um: float
    params: Params
    h0_um: float
    base_only: ModelFit
    evidence: dict[str, Any]
    x_base: FloatArray
    x_extended: FloatArray
    effect_set: EffectSet = field(default_factory=EffectSet)
    unexplained: Unexplained | None = None
    named_effects: tuple[NamedEffect, ...] = ()
    decisions: tuple[Decision, ...] = ()
    taken: tuple[Decision, ...] = ()
    at_bounds: list[AtBound] = field(default_factory=list)
    base_loop: list[AtBound] = field(default_factory=list)
    unseen: Unseen | None = None
    explained: Explained | None = field(default=None, repr=False)
    structure: NamedStructure | None = None
    boundedness: Boundedness | None = None

    def next_experiment(
        self,
        duration_s: float = 60.0,
        u_min: float | None = None,
        u_max: float | None = None,
        max_slew_v_per_s: float | None = None,
        dt: float | None = None,
        *,
        seed: int = 0,
    ) -> Experiment:
        """The input to record next so that the explanations this record could not tell
        apart (each tentative name and its rivals) can be told apart
        (:mod:`boucwen.diagnosis.experiment`).

        Args:
            duration_s: the experiment's length [s].
            u_min, u_max: its voltage range [V] (default: the record's).
            max_slew_v_per_s: its fastest slew [V/s] (default: the record's fastest).
            dt: its sampling interval [s] (default: the record's).
            seed: seed of the design's global search.

        Returns:
            An :class:`~boucwen.diagnosis.experiment.Experiment`: the input ``u`` [V] and
            ``dt`` [s], the explanations it separates, the predicted separation of each
            pair in units of the record's noise beside a generic input's, what in the
            input does the separating, and the record's own segments that separate them
            best. Where no name has a rival, it says so (``ambiguous`` False, no input).

        Raises:
            ValueError: a bad limit (precise message), or a diagnosis that holds no
                record (one read back from a report).
        """
        from .experiment import Limits, design

        if self.explained is None:
            raise ValueError("this diagnosis holds no record: run boucwen.diagnose to design an experiment")
        ctx = self.explained
        limits = Limits.of(ctx.record, duration_s, u_min, u_max, max_slew_v_per_s, dt)
        return design(ctx.record, ctx.members(), ctx.noise_um, limits, seed=seed)

    @property
    def model(self) -> ModelFit:
        """The returned model's base parameters and h0 (its effects: :attr:`effect_set`)."""
        return ModelFit(self.params, self.h0_um)

    @property
    def confidence(self) -> dict[str, dict[str, Any]]:
        """Per effect named, ``{"level", "why", "competing", "rivals"}`` (JSON-ready)."""
        return {
            e.name: {"level": e.level, "why": e.why, "competing": e.competing, "rivals": list(e.rivals)}
            for e in self.named_effects
        }

    def to_dict(self) -> dict[str, Any]:
        """The JSON report (without the arrays); every figure finite, or null with its
        reason under ``"non_finite"`` (:func:`finite_document`)."""
        doc = {
            "effects": list(self.effects),
            "rms_before_um": self.rms_before_um,
            "max_before_um": self.max_before_um,
            "rms_after_um": self.rms_after_um,
            "max_after_um": self.max_after_um,
            "params": {**self.model.to_dict(), **self.effect_set.to_dict(), "base_only": self.base_only.to_dict()},
            "evidence": self.evidence,
            "unexplained": None if self.unexplained is None else jsonable(self.unexplained.to_dict()),
            "confidence": self.confidence,
            "decisions": [d.to_dict() for d in self.decisions],
            "unseen": {} if self.unseen is None else self.unseen.to_dict(),
            "at_bounds": [b.to_dict() for b in self.at_bounds],
            "base_loop_on_bounds": [b.to_dict() for b in self.base_loop],
            "structure": None if self.structure is None else self.structure.to_dict(),
            "boundedness": None if self.boundedness is None else self.boundedness.to_dict(),
        }
        out: dict[str, Any] = finite_document(doc)
        return out

    def summary(self) -> str:
        """One line: effects and errors."""
        named = (
            ", ".join(f"{k} ({self.confidence[k]['level']})" if k in self.confidence else k for k in self.effects)
            if self.effects
            else "none"
        )
        unseen = self.unseen
        cv = (
            f"; unseen ({unseen.folds} forward folds) RMS {unseen.cv_rms_before_um:.4g} → "
            f"{unseen.cv_rms_after_um:.4g} µm"
            if unseen is not None
            else ""
        )
        for val in unseen.validation if unseen is not None else ():
            if val.before is not None and val.after is not None:
                cv += f"; {val.name or 'validation record'} RMS {val.before.rms_um:.4g} → {val.after.rms_um:.4g} µm"
        bounds = "".join(f"; {b.parameter} = {b.value:.4g} on its {b.side} bound" for b in self.at_bounds)
        if self.boundedness is not None and not self.boundedness.passed:
            bounds += f"; {self.boundedness.summary()}"
        if self.base_loop:
            bounds += f"; {self.base_loop_summary()}"
        if self.structure is not None:
            s = self.structure
            return (
                f"model: hysteretic oscillator ({s.level}; against the input-driven model with {named}); "
                f"RMS {self.rms_before_um:.4g} → {self.rms_after_um:.4g} µm, "
                f"max {self.max_before_um:.4g} → {self.max_after_um:.4g} µm{cv}"
            )
        return (
            f"effects: {named}; RMS {self.rms_before_um:.4g} → {self.rms_after_um:.4g} µm, "
            f"max {self.max_before_um:.4g} → {self.max_after_um:.4g} µm{cv}{bounds}"
        )

    def base_loop_summary(self) -> str:
        """What the base model's fit says of the base loop where its shape ended on a
        bound (:attr:`base_loop`); empty where it did not."""
        if not self.base_loop:
            return ""
        on = ", ".join(f"{b.parameter} = {b.value:.3g} on its {b.side} bound {b.bound:.3g}" for b in self.base_loop)
        return f"the base loop does not fit this device ({on}): the named effects may take up what it lacks"

    def __repr__(self) -> str:
        return f"Diagnosis({self.summary()})"


#: Why a figure of the report is not a number, by its name (the last key of its path).
_WHY_NOT_FINITE = {
    "gain_um2": "no fold's refit converged for both models: the gain cannot be computed",
    "se_um2": "no fold's refit converged for both models: the gain cannot be computed",
    "t": "no fold's refit converged for both models, or both predict alike: no statistic",
    "fold_gain_um2": "this fold's refit did not converge for both models",
    "reference_mse_um2": "no fold's refit converged for both models",
    "threshold_t": "the move was not judged (no statistic)",
    "needed_um2": "the move was not judged (no statistic)",
    "rms_um": "no fold's refit converged: no held-out error",
    "fold_rms_um": "this fold predicts no sample, or its refit did not converge",
    "cv_rms_before_um": "no fold's refit converged for both models",
    "cv_rms_after_um": "no fold's refit converged for both models",
}


def finite_document(doc: Any) -> Any:
    """``doc`` with every float that is not finite replaced by None, and a list
    ``"non_finite"`` beside it (at the top of a dict document) naming each one's path,
    its value and why it is not a number (:data:`_WHY_NOT_FINITE`, by its name; else
    "not computable on this record"): a report that JSON can carry, that loses nothing."""
    found: list[dict[str, str]] = []

    def walk(obj: Any, path: str, name: str) -> Any:
        if hasattr(obj, "to_dict") and callable(obj.to_dict):
            obj = obj.to_dict()
        if isinstance(obj, dict):
            return {str(k): walk(v, f"{path}.{k}" if path else str(k), str(k)) for k, v in obj.items()}
        if isinstance(obj, (list, tuple)):
            return [walk(v, f"{path}[{i}]", name) for i, v in enumerate(obj)]
        if isinstance(obj, (bool, np.bool_)):
            return bool(obj)
        if isinstance(obj, (float, np.floating)):
            v = float(obj)
            if math.isfinite(v):
                return v
            why = _WHY_NOT_FINITE.get(name, "not computable on this record")
            found.append({"path": path, "value": str(v), "why": why})
            return None
        if isinstance(obj, np.integer):
            return int(obj)
        return obj

    out = walk(doc, "", "")
    if isinstance(out, dict):
        out["non_finite"] = [*out.get("non_finite", []), *found] if isinstance(out.get("non_finite"), list) else found
    return out


def write_report(result: Diagnosis, path: str | os.PathLike[str], data: dict[str, Any] | None = None) -> None:
    """Writes the JSON report (:meth:`Diagnosis.to_dict`, plus ``data`` if given)."""
    doc = result.to_dict()
    if data is not None:
        doc["data"] = data
        doc = finite_document(doc)
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=2, allow_nan=False)


def write_predictions(result: Diagnosis, t: ArrayLike, x: ArrayLike, path: str | os.PathLike[str]) -> None:
    """Writes ``t,x,x_base,x_extended`` (s, µm) with a header line, one row per sample."""
    write_csv(path, {"t": t, "x": x, "x_base": result.x_base, "x_extended": result.x_extended})
