"""What a model's residual x − x̂ shows: the record's noise level, whether the residual
is consistent with that noise, what it follows (signals, spectral lines, time spans),
checkable statistics per effect, and the tests that tell look-alike effects apart.

Everything here *describes* a residual; nothing here decides which effects a model
holds (that is :mod:`boucwen.diagnosis`'s judge). Modules:
:mod:`~boucwen.residual.noise` (the white-noise level of a record, from x alone),
:mod:`~boucwen.residual.unexplained` (the verdict against the noise, with
:mod:`~boucwen.residual.lines` and :mod:`~boucwen.residual.spans`),
:mod:`~boucwen.residual.evidence` (statistics per effect),
:mod:`~boucwen.residual.lookalike` (what the residual follows; the shape of the phase).
"""

from .evidence import fit_evidence, residual_evidence, residual_evidence_record
from .lookalike import lookalike_tests
from .noise import NoiseLevel, noise_level
from .unexplained import ALPHA, TOLERANCE, Unexplained, unexplained

__all__ = [
    "ALPHA",
    "TOLERANCE",
    "NoiseLevel",
    "Unexplained",
    "fit_evidence",
    "lookalike_tests",
    "noise_level",
    "residual_evidence",
    "residual_evidence_record",
    "unexplained",
]
