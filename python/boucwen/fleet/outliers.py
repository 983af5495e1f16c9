"""Outliers of a fleet: robust z-scores of the parameters and errors.

For a column v over the records that produced values (status ``ok`` or
``not_converged``)::

    z = (v − median(v)) / (1.4826 · MAD(v)),    MAD = median |v − median(v)|

1.4826·MAD estimates the standard deviation of normally spread values, and neither the
median nor the MAD moves much when a few records are wild (their breakdown point is
50 %), so the defective records do not hide themselves by inflating the spread, as they
would with the mean and the standard deviation. When more than half of the values are
equal (MAD = 0) the mean absolute deviation times 1.2533 (its ratio to the standard
deviation of normal values) is used instead; when all are equal, z = 0.

Errors are positive and spread multiplicatively (a record twice as bad as another), so
their z-scores are taken of log10 of the error. A record is an **outlier** when any
|z| exceeds :data:`THRESHOLD`; ``outlier_reason`` lists the columns and their z. Error
rows are not scored (they have no values); they are listed apart.

**What is scored** (:data:`SCORED_COLUMNS`): kv, A, β, γ and the RMS and maximum error
after the fit. x0, n and δ stay in the table but are not scored: within one record they
trade off with h0, with the size of β and γ, and with creep, so their spread says more
about the fit than about the actuator. On the generated 32 × 32 mirror
(:mod:`boucwen.fleet.generate`) the fitted kv, A, β, γ follow the true values (correlation
0.999, 0.89, 0.98, 0.89 over the sound actuators) while n does poorly (0.33, with a second
cluster near 1.65 from fits that end in another optimum) and x0 and δ not at all (≈ 0);
scoring n flags 20 sound actuators at |z| > 5.

**Threshold.** 3.5 is Iglewicz & Hoaglin's cut for one value; a fleet tests 6 columns of
N records at once, and at 3.5 even normally spread values would flag 6·N·4.7e-4 ≈ 3 sound
records of 1 024 by chance — the generated mirror, whose fitted values have heavier tails
than normal, gets 15. At |z| > 5 the chance count is 0.004 per 1 024 records and the
generated mirror has none, while its five defects score |z| ≥ 11.7.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["LOG_COLUMNS", "SCORED_COLUMNS", "THRESHOLD", "attention_list", "flag_outliers", "robust_z"]

#: Columns scored: the parameters a record pins down and the errors of the final model [µm].
SCORED_COLUMNS: tuple[str, ...] = ("kv", "A", "beta", "gamma", "rms_after_um", "max_after_um")
#: Columns scored in log10 (positive, multiplicative spread).
LOG_COLUMNS: tuple[str, ...] = ("rms_after_um", "max_after_um")
#: |z| above which a value is an outlier.
THRESHOLD = 5.0
#: Statuses whose rows carry values.
SCORED_STATUSES = ("ok", "not_converged")

_MAD_TO_SIGMA = 1.4826
_MEAN_AD_TO_SIGMA = 1.2533


def robust_z(values: np.ndarray) -> np.ndarray:
    """Robust z-scores of ``values`` (module docs); NaN stays NaN and is not used."""
    v = np.asarray(values, dtype=np.float64)
    z = np.full(v.shape, np.nan)
    ok = np.isfinite(v)
    if not np.any(ok):
        return z
    centre = float(np.median(v[ok]))
    dev = np.abs(v[ok] - centre)
    scale = _MAD_TO_SIGMA * float(np.median(dev))
    if scale <= 0.0:
        scale = _MEAN_AD_TO_SIGMA * float(np.mean(dev))
    z[ok] = (v[ok] - centre) / scale if scale > 0.0 else 0.0
    return z


def flag_outliers(
    table: pd.DataFrame, columns: tuple[str, ...] = SCORED_COLUMNS, threshold: float = THRESHOLD
) -> pd.DataFrame:
    """The table with ``z_<column>`` per scored column, ``outlier`` and ``outlier_reason``.

    Args:
        table: rows as built by :class:`boucwen.fleet.store.ResultStore.table`.
        columns: columns to score (those missing from the table are skipped).
        threshold: |z| above which a value is an outlier (> 0).

    Returns:
        A copy of ``table`` with the new columns; rows that are not scored have NaN
        z-scores, ``outlier = False`` and an empty reason.
    """
    if not threshold > 0:
        raise ValueError(f"threshold must be > 0, got {threshold!r}")
    out = table.copy()
    scored = out["status"].isin(SCORED_STATUSES).to_numpy()
    flagged = np.zeros(len(out), dtype=bool)
    reasons: list[list[str]] = [[] for _ in range(len(out))]
    for column in columns:
        if column not in out.columns:
            continue
        v = pd.to_numeric(out[column], errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
        v = np.where(scored, v, np.nan)
        if column in LOG_COLUMNS:
            with np.errstate(divide="ignore", invalid="ignore"):
                v = np.where(v > 0, np.log10(v), np.nan)
        z = robust_z(v)
        out[f"z_{column}"] = z
        hit = np.abs(np.nan_to_num(z)) > threshold
        flagged |= hit
        for k in np.flatnonzero(hit):
            reasons[k].append(f"{column} z={z[k]:+.1f}")
    out["outlier"] = flagged
    out["outlier_reason"] = ["; ".join(r) for r in reasons]
    return out


def attention_list(table: pd.DataFrame) -> pd.DataFrame:
    """The records to look at: outliers, then error and failed rows.

    Returns:
        Columns ``channel, row, col, status, flag, reason``: ``flag`` is ``"outlier"``
        (``reason`` = the columns and their z) or the row's status (``reason`` = its
        error message).
    """
    scored = table["status"].isin(SCORED_STATUSES)
    outlier = table["outlier"].astype(bool) if "outlier" in table else pd.Series(False, index=table.index)
    flagged = table[outlier & scored]
    broken = table[~scored]
    columns = ["channel", "row", "col", "status", "flag", "reason"]
    parts = [
        pd.DataFrame(
            {
                "channel": frame["channel"],
                "row": frame["row"],
                "col": frame["col"],
                "status": frame["status"],
                "flag": flag,
                "reason": reason,
            },
            columns=columns,
        )
        for frame, flag, reason in (
            (flagged, "outlier", flagged.get("outlier_reason", pd.Series("", index=flagged.index))),
            (broken, broken["status"], broken["error"]),
        )
    ]
    parts = [part for part in parts if len(part)]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=columns)
