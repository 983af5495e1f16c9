"""The effects kept, refitted from a fresh base model (:func:`rebased`): the search's way
out of a base model that bent its hysteresis to imitate an effect."""

from __future__ import annotations

from .._core import EffectSet
from ..effects import DIAGNOSIS_METHOD, ExtendedFit, fit_extended_record, simulate_chain
from ..fit import fit_record
from ..record import Record, validate_record
from .policy import DiagnosisPolicy

__all__ = ["fits_better", "rebased"]


def rebased(
    record: Record, kept: ExtendedFit, *, seed: int, workers: int | None, q: int, policy: DiagnosisPolicy
) -> ExtendedFit | None:
    """``kept`` refitted from a fresh base model: the base model fitted from scratch
    (global stage and all) on the record less what the kept effects add to the kept
    base model, then everything refitted from there (``rebase_nfev``). A base model
    fitted without the effect may have found a basin where its hysteresis imitates the
    effect (the rate term δ·u·sgn(u̇) integrating into a drift, kv and A cancelling);
    the trial that adds the effect starts in that basin and a few iterations do not
    leave it. None when the fresh start cannot be simulated or fitted."""
    u, dt = record.u, record.dt
    with_effects = simulate_chain(kept.params, kept.effects, u, dt, kept.h0)
    plain_x = simulate_chain(kept.params, EffectSet(), u, dt, kept.h0)
    if with_effects is None or plain_x is None:
        return None
    try:
        plain = validate_record(u, record.x - (with_effects - plain_x), dt)
        base = fit_record(plain, seed=seed, workers=workers, decimate=q if q > 1 else None, method=DIAGNOSIS_METHOD)
        return fit_extended_record(
            record, base.params, kept.effects, base.h0, max_nfev=policy.rebase_nfev, tol=policy.trial_tol
        )
    except ValueError:
        return None


def fits_better(fresh: ExtendedFit, kept: ExtendedFit, policy: DiagnosisPolicy) -> bool:
    """The search goes on from the ``fresh`` refit (:func:`rebased`) only where its RMS
    error is below the ``kept`` model's by more than ``close_rel`` of it (a tie keeps the
    model the search had)."""
    return fresh.rms_um < (1.0 - policy.close_rel) * kept.rms_um
