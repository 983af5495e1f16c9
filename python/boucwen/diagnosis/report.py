"""The result of a diagnosis and the files it is written to (JSON report, CSV predictions)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any

from numpy.typing import ArrayLike

from .._core import EffectSet, Params
from ..checks import FloatArray
from ..effects import Effect, effects_of
from ..io import jsonable, write_csv
from .margins import ANSWER, CloseCall
from .scoring import AtBound
from .unexplained import Unexplained
from .unseen import Unseen

__all__ = ["Diagnosis", "ModelFit", "NamedEffect", "jsonable", "write_predictions", "write_report"]


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
        level: ``"confident"`` or ``"tentative"`` (:mod:`~boucwen.diagnosis.confidence`).
        why: the reason for the level.
        competing: the competing explanation named, or None.
    """

    effect: Effect
    level: str
    why: str
    competing: str | None = None

    @property
    def name(self) -> str:
        """The effect's name in the vocabulary."""
        return self.effect.name

    def to_dict(self) -> dict[str, Any]:
        """``{"effect": name, "params": {…}, "level", "why", "competing"}`` (JSON-ready)."""
        return {
            "effect": self.name,
            "params": self.effect.to_dict(),
            "level": self.level,
            "why": self.why,
            "competing": self.competing,
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
        evidence: what the decision rests on (see :mod:`boucwen.diagnosis`).
        x_base, x_extended: displacement [µm] of the base and returned models over the
            record.
        unexplained: what the returned model leaves unexplained: its residual against the
            noise estimated from the record, the signals, spectral lines and time spans
            it follows, and whether it is consistent with noise
            (:class:`~boucwen.diagnosis.unexplained.Unexplained`; None if not computed).
        confidence: per effect named, ``{"level": "confident" | "tentative", "why",
            "competing"}`` (:mod:`~boucwen.diagnosis.confidence`; typed:
            :attr:`named_effects`).
        at_bounds: the returned model's unknowns that ended on a bound of the fit
            (:class:`~boucwen.diagnosis.scoring.AtBound`).
        unseen: errors on data the fits did not see [µm]: blocked cross-validation of the
            base and returned models and, with a validation record, both carried to it
            (:class:`~boucwen.diagnosis.unseen.Unseen`; None if not computed).
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
    confidence: dict[str, dict[str, Any]] = field(default_factory=dict)
    at_bounds: list[AtBound] = field(default_factory=list)
    unseen: Unseen | None = None

    @property
    def model(self) -> ModelFit:
        """The returned model's base parameters and h0 (its effects: :attr:`effect_set`)."""
        return ModelFit(self.params, self.h0_um)

    @property
    def named_effects(self) -> tuple[NamedEffect, ...]:
        """The effects of the returned model, typed (:func:`boucwen.effects_of`), in the
        order added, each with its confidence."""
        typed = {e.name: e for e in effects_of(self.effect_set)}
        levels = self.confidence
        return tuple(
            NamedEffect(typed[k], levels[k]["level"], levels[k]["why"], levels[k]["competing"]) for k in self.effects
        )

    @property
    def close_calls(self) -> list[CloseCall]:
        """The choices closer than the margin of :mod:`~boucwen.diagnosis.margins`,
        decided by its stated rule (``kind``: ``"answer"`` for what the answer holds,
        ``"path"`` for a trial's way there; the summary counts the first)."""
        return [CloseCall(**c) for c in self.evidence.get("close_calls", [])]

    def to_dict(self) -> dict[str, Any]:
        """The JSON report (without the arrays)."""
        return {
            "effects": list(self.effects),
            "rms_before_um": self.rms_before_um,
            "max_before_um": self.max_before_um,
            "rms_after_um": self.rms_after_um,
            "max_after_um": self.max_after_um,
            "params": {**self.model.to_dict(), **self.effect_set.to_dict(), "base_only": self.base_only.to_dict()},
            "evidence": self.evidence,
            "unexplained": None if self.unexplained is None else jsonable(self.unexplained.to_dict()),
            "confidence": self.confidence,
            "close_calls": [c.to_dict() for c in self.close_calls],
            "unseen": {} if self.unseen is None else self.unseen.to_dict(),
            "at_bounds": [b.to_dict() for b in self.at_bounds],
        }

    def summary(self) -> str:
        """One line: effects and errors."""
        named = (
            ", ".join(f"{k} ({self.confidence[k]['level']})" if k in self.confidence else k for k in self.effects)
            if self.effects
            else "none"
        )
        on_answer = [c for c in self.close_calls if c.kind == ANSWER]
        close = f"; {len(on_answer)} close call(s)" if on_answer else ""
        unseen = self.unseen
        cv = (
            f"; unseen ({unseen.folds}-fold CV) RMS {unseen.cv_rms_before_um:.4g} → {unseen.cv_rms_after_um:.4g} µm"
            if unseen is not None
            else ""
        )
        val = unseen.validation if unseen is not None else None
        if val is not None and val.before is not None and val.after is not None:
            cv += f"; validation record RMS {val.before.rms_um:.4g} → {val.after.rms_um:.4g} µm"
        bounds = "".join(f"; {b.parameter} = {b.value:.4g} on its {b.side} bound" for b in self.at_bounds)
        return (
            f"effects: {named}; RMS {self.rms_before_um:.4g} → {self.rms_after_um:.4g} µm, "
            f"max {self.max_before_um:.4g} → {self.max_after_um:.4g} µm{cv}{bounds}{close}"
        )

    def __repr__(self) -> str:
        return f"Diagnosis({self.summary()})"


def write_report(result: Diagnosis, path: str | os.PathLike[str], data: dict[str, Any] | None = None) -> None:
    """Writes the JSON report (:meth:`Diagnosis.to_dict`, plus ``data`` if given)."""
    doc = result.to_dict()
    if data is not None:
        doc["data"] = data
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=2, allow_nan=False)


def write_predictions(result: Diagnosis, t: ArrayLike, x: ArrayLike, path: str | os.PathLike[str]) -> None:
    """Writes ``t,x,x_base,x_extended`` (s, µm) with a header line, one row per sample."""
    write_csv(path, {"t": t, "x": x, "x_base": result.x_base, "x_extended": result.x_extended})
