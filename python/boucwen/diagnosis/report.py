"""The result of a diagnosis and the files it is written to (JSON report, CSV predictions)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any

from numpy.typing import ArrayLike

from .._core import EffectSet
from ..checks import FloatArray
from ..io import jsonable, write_csv
from .unexplained import Unexplained

__all__ = ["Diagnosis", "jsonable", "write_predictions", "write_report"]


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of :func:`boucwen.diagnose`.

    Attributes:
        effects: names of the effects added, in the order added ([] when none).
        rms_before, max_before: RMS and maximum absolute error [µm] of the base model
            fitted on the whole record.
        rms_after, max_after: the same with the effects added (equal to *before* when
            none was added).
        params: ``{"base": {kv, x0, A, beta, gamma, n, delta}, "h0_um": …, <effect>:
            {…}, "base_only": {"base": {...}, "h0_um": …}}`` — the extended model's
            values and, under ``base_only``, the base model's.
        evidence: what the decision rests on (see :mod:`boucwen.diagnosis`).
        x_base, x_extended: displacement [µm] of the two models over the record.
        effect_set: the fitted :class:`boucwen.EffectSet`.
        unexplained: what the final model leaves unexplained: its residual against the
            noise estimated from the record, the signals, spectral lines and time spans
            it follows, and whether it is consistent with noise
            (:class:`~boucwen.diagnosis.unexplained.Unexplained`; None if not computed).
        confidence: per effect named, ``{"level": "confident" | "tentative", "why",
            "competing"}`` (:mod:`~boucwen.diagnosis.confidence`).
        at_bounds: the returned model's unknowns that ended on a bound of the fit:
            ``{"parameter", "value", "bound", "side"}`` each.
    """

    effects: list[str]
    rms_before: float
    max_before: float
    rms_after: float
    max_after: float
    params: dict[str, Any]
    evidence: dict[str, Any]
    x_base: FloatArray
    x_extended: FloatArray
    effect_set: EffectSet = field(default_factory=EffectSet)
    unexplained: Unexplained | None = None
    confidence: dict[str, dict[str, Any]] = field(default_factory=dict)
    at_bounds: list[dict[str, Any]] = field(default_factory=list)

    @property
    def close_calls(self) -> list[dict[str, Any]]:
        """The choices closer than the margin of :mod:`~boucwen.diagnosis.margins`,
        decided by its stated rule: ``{"decision", "value", "against", "chose", "kind"}``
        each (``kind``: ``"answer"`` for what the answer holds, ``"path"`` for a trial's
        way there; the summary counts the first)."""
        calls: list[dict[str, Any]] = self.evidence.get("close_calls", [])
        return calls

    @property
    def unseen(self) -> dict[str, Any]:
        """Errors on data the fits did not see [µm]: ``cv_rms_before_um`` and
        ``cv_rms_after_um`` (blocked cross-validation over ``folds`` contiguous folds,
        base model and returned model) and, with a validation record, ``validation``:
        ``{"samples", "before", "after"}`` (RMS, max and re-estimated offset of each)."""
        unseen: dict[str, Any] = self.evidence.get("unseen", {})
        return unseen

    def to_dict(self) -> dict[str, Any]:
        """The JSON report (without the arrays)."""
        return {
            "effects": list(self.effects),
            "rms_before": self.rms_before,
            "max_before": self.max_before,
            "rms_after": self.rms_after,
            "max_after": self.max_after,
            "params": self.params,
            "evidence": self.evidence,
            "unexplained": None if self.unexplained is None else jsonable(self.unexplained.to_dict()),
            "confidence": self.confidence,
            "close_calls": self.close_calls,
            "unseen": self.unseen,
            "at_bounds": self.at_bounds,
        }

    def summary(self) -> str:
        """One line: effects and errors."""
        named = (
            ", ".join(f"{k} ({self.confidence[k]['level']})" if k in self.confidence else k for k in self.effects)
            if self.effects
            else "none"
        )
        on_answer = [c for c in self.close_calls if c.get("kind") == "answer"]
        close = f"; {len(on_answer)} close call(s)" if on_answer else ""
        unseen = self.unseen
        cv = (
            f"; unseen ({unseen['folds']}-fold CV) RMS {unseen['cv_rms_before_um']:.4g} → "
            f"{unseen['cv_rms_after_um']:.4g} µm"
            if unseen.get("cv_rms_before_um") is not None and unseen.get("cv_rms_after_um") is not None
            else ""
        )
        val = unseen.get("validation")
        if val and val.get("before") and val.get("after"):
            cv += f"; validation record RMS {val['before']['rms_um']:.4g} → {val['after']['rms_um']:.4g} µm"
        bounds = "".join(f"; {b['parameter']} = {b['value']:.4g} on its {b['side']} bound" for b in self.at_bounds)
        return (
            f"effects: {named}; RMS {self.rms_before:.4g} → {self.rms_after:.4g} µm, "
            f"max {self.max_before:.4g} → {self.max_after:.4g} µm{cv}{bounds}{close}"
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
