"""The fleet figure: parameter distributions, errors per channel and, on a grid, maps.

Drawn on matplotlib's Agg canvas without pyplot (like :mod:`boucwen.plots`), from the
table with outlier columns (:func:`boucwen.fleet.outliers.flag_outliers`). Outliers are
red throughout; error rows are black crosses.
"""

from __future__ import annotations

import os

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from ..plots import _figure
from .outliers import SCORED_COLUMNS
from .tasks import PARAM_COLUMNS

__all__ = ["UNITS", "plot_fleet"]

#: Axis labels of the plotted columns.
UNITS = {
    "kv": "kv [µm/V]",
    "x0": "x0 [µm]",
    "A": "A [µm/V]",
    "beta": "β [µm^(1−n)/V]",
    "gamma": "γ [µm^(1−n)/V]",
    "n": "n [-]",
    "delta": "δ [µm/(V·s)]",
    "rms_after_um": "RMS error after [µm]",
}
_OUTLIER = "tab:red"


def _values(table: pd.DataFrame, column: str) -> np.ndarray:
    return np.asarray(pd.to_numeric(table[column], errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan))


def _histogram(ax: Axes, table: pd.DataFrame, column: str, scored: np.ndarray, outlier: np.ndarray) -> None:
    v = _values(table, column)
    inliers = v[scored & ~outlier & np.isfinite(v)]
    wild = v[scored & outlier & np.isfinite(v)]
    if inliers.size == 0 and wild.size == 0:
        ax.set_visible(False)
        return
    base = inliers if inliers.size else wild
    lo, hi = float(np.min(base)), float(np.max(base))
    pad = 0.1 * (hi - lo) if hi > lo else 0.1 * max(abs(lo), 1e-12)
    lo, hi = lo - pad, hi + pad
    if inliers.size:
        ax.hist(inliers, bins=min(40, max(5, inliers.size // 4)), range=(lo, hi), color="tab:blue", alpha=0.8)
    for value in wild[(wild >= lo) & (wild <= hi)]:
        ax.axvline(value, color=_OUTLIER, linewidth=1.2)
    below, above = int(np.sum(wild < lo)), int(np.sum(wild > hi))
    if below:
        ax.annotate(f"◀ {below}", (0.02, 0.9), xycoords="axes fraction", color=_OUTLIER, fontsize=9)
    if above:
        ax.annotate(f"{above} ▶", (0.98, 0.9), xycoords="axes fraction", color=_OUTLIER, fontsize=9, ha="right")
    ax.set_xlim(lo, hi)
    ax.xaxis.set_major_locator(MaxNLocator(4))
    ax.set_xlabel(UNITS.get(column, column), fontsize=8)
    ax.tick_params(labelsize=7)
    name = column if column in SCORED_COLUMNS else f"{column} (not scored)"
    title = f"{name}: {wild.size} outlier record{'s' if wild.size != 1 else ''}" if wild.size else f"{name}: no outlier"
    if below or above:
        title += " (◀ ▶ off scale)"
    ax.set_title(title, fontsize=8)


def _errors(ax: Axes, table: pd.DataFrame, scored: np.ndarray, outlier: np.ndarray, errors: np.ndarray) -> None:
    index = np.arange(len(table))
    before, after = _values(table, "rms_before_um"), _values(table, "rms_after_um")
    ax.semilogy(index[scored], before[scored], ".", color="lightgrey", markersize=3, label="before")
    ax.semilogy(index[scored & ~outlier], after[scored & ~outlier], ".", color="tab:blue", markersize=3, label="after")
    ax.semilogy(index[scored & outlier], after[scored & outlier], "o", color=_OUTLIER, markersize=5, label="outlier")
    if np.any(errors):
        low = np.nanmin(after[scored]) if np.any(scored & np.isfinite(after)) else 1.0
        ax.semilogy(index[errors], np.full(int(errors.sum()), low), "x", color="black", label="error row")
    ax.set_xlabel("record (table order)")
    ax.set_ylabel("RMS output error [µm]")
    ax.set_title("errors per record: before → after")
    ax.legend(loc="upper right", fontsize=7)
    ax.grid(True, alpha=0.3, which="both")


def _grid_map(
    fig: Figure, ax: Axes, table: pd.DataFrame, column: str, log: bool, outlier: np.ndarray, errors: np.ndarray
) -> None:
    rows = _values(table, "row")
    cols = _values(table, "col")
    placed = np.isfinite(rows) & np.isfinite(cols)
    shape = (int(np.nanmax(rows[placed])) + 1, int(np.nanmax(cols[placed])) + 1)
    grid = np.full(shape, np.nan)
    v = _values(table, column)
    if log:
        with np.errstate(divide="ignore", invalid="ignore"):
            v = np.where(v > 0, np.log10(v), np.nan)
    r, c = rows[placed].astype(int), cols[placed].astype(int)
    grid[r, c] = np.where(errors[placed], np.nan, v[placed])
    finite = grid[np.isfinite(grid)]
    inl = np.where(outlier[placed] | errors[placed], np.nan, v[placed])
    inl = inl[np.isfinite(inl)]
    lo, hi = (np.percentile(inl, [1, 99]) if inl.size else (np.min(finite), np.max(finite))) if finite.size else (0, 1)
    from matplotlib import colormaps

    cmap = colormaps["viridis"].with_extremes(bad="lightgrey")
    image = ax.imshow(np.ma.masked_invalid(grid), cmap=cmap, vmin=lo, vmax=hi, origin="upper", interpolation="nearest")
    fig.colorbar(image, ax=ax, shrink=0.8, label=("log10 " if log else "") + UNITS.get(column, column))
    sel = placed & outlier
    ax.plot(
        cols[sel], rows[sel], "o", markerfacecolor="none", markeredgecolor=_OUTLIER, markersize=8, markeredgewidth=1.5
    )
    sel = placed & errors
    ax.plot(cols[sel], rows[sel], "x", color="black", markersize=7)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("column")
    ax.set_ylabel("row")
    ax.set_title(f"mirror map of {column}", fontsize=9)


def plot_fleet(table: pd.DataFrame, path: str | os.PathLike[str], title: str = "") -> None:
    """Writes the fleet figure (PNG) of a table with outlier columns.

    Panels: a histogram per parameter and of the RMS error after, outliers as red lines;
    the RMS error before and after per record; with grid positions (``row``, ``col``),
    maps of the RMS error after (log10) and of kv.
    """
    status = table["status"].astype(str).to_numpy()
    scored = np.isin(status, ("ok", "not_converged"))
    errors = ~scored
    outlier = table["outlier"].to_numpy(dtype=bool) if "outlier" in table else np.zeros(len(table), dtype=bool)
    has_grid = bool(np.any(np.isfinite(_values(table, "row")) & np.isfinite(_values(table, "col"))))
    fig = _figure(16.0, 11.0 if has_grid else 8.0)
    spec = fig.add_gridspec(3, 4, height_ratios=(1.0, 1.0, 1.6 if has_grid else 1.2))
    for k, column in enumerate((*PARAM_COLUMNS, "rms_after_um")):
        _histogram(fig.add_subplot(spec[k // 4, k % 4]), table, column, scored, outlier)
    if has_grid:
        _errors(fig.add_subplot(spec[2, :2]), table, scored, outlier, errors)
        _grid_map(fig, fig.add_subplot(spec[2, 2]), table, "rms_after_um", True, outlier, errors)
        _grid_map(fig, fig.add_subplot(spec[2, 3]), table, "kv", False, outlier, errors)
    else:
        _errors(fig.add_subplot(spec[2, :]), table, scored, outlier, errors)
    n_out, n_err = int(np.sum(outlier)), int(np.sum(errors))
    fig.suptitle(
        f"{title + ': ' if title else ''}{len(table)} records, {n_out} outlier{'s' if n_out != 1 else ''} (red), "
        f"{n_err} error row{'s' if n_err != 1 else ''} (×)"
        + ("; grey cells: no record or no value" if has_grid else "")
    )
    fig.savefig(path, dpi=90)
