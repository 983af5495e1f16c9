"""Figures of the experiment, drawn with matplotlib's Agg canvas (no display needed).

The functions build their own :class:`matplotlib.figure.Figure` and never touch
pyplot's global state, so they are safe to call from scripts, tests and threads.
Displacements and errors in µm, voltage in V, time in s.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .checks import FloatArray

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from .diagnosis.report import Diagnosis
    from .replay import Replay

__all__ = ["plot_diagnosis", "plot_identify", "plot_loops", "plot_switch", "plot_tracking"]

_MEASURED_STYLE: dict[str, Any] = {"color": "black", "linewidth": 1.4, "label": "measured"}


def _figure(width: float, height: float) -> Figure:
    """A figure of ``width`` × ``height`` inches on its own Agg canvas."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def plot_switch(
    path: str | os.PathLike[str],
    t: FloatArray,
    x: FloatArray,
    predictions: Mapping[str, FloatArray],
    t_switch: float,
    span: tuple[float, float],
    title: str,
) -> None:
    """Displacement and modelling error around a frequency switch (like the paper's Figs. 6–8).

    Args:
        path: PNG file to write.
        t: sample times [s].
        x: measured displacement [µm].
        predictions: ``{label: predicted displacement [µm]}``, each the length of ``x``.
        t_switch: time of the switch [s], drawn as a dotted line.
        span: ``(t_start, t_stop)`` [s] of the plotted interval.
        title: figure title.
    """
    lo, hi = np.searchsorted(t, span[0]), np.searchsorted(t, span[1], side="right")
    sel = slice(lo, hi)
    fig = _figure(9.0, 6.0)
    ax_x, ax_e = fig.subplots(2, 1, sharex=True)
    ax_x.plot(t[sel], x[sel], **_MEASURED_STYLE)
    for label, pred in predictions.items():
        ax_x.plot(t[sel], pred[sel], linewidth=1.0, label=label)
        ax_e.plot(t[sel], (x - pred)[sel], linewidth=1.0, label=label)
    for ax in (ax_x, ax_e):
        ax.axvline(t_switch, color="grey", linestyle=":", linewidth=1.0)
        ax.grid(True, alpha=0.3)
    ax_x.set_ylabel("displacement x [µm]")
    ax_x.set_title(f"(a) {title}")
    ax_x.legend(loc="upper left", fontsize=8)
    ax_e.set_ylabel("error x − x̂ [µm]")
    ax_e.set_xlabel("time t [s]")
    ax_e.set_title("(b) modelling error")
    ax_e.legend(loc="upper left", fontsize=8)
    fig.savefig(path, dpi=110)


def plot_loops(
    path: str | os.PathLike[str],
    u: FloatArray,
    x: FloatArray,
    predictions: Mapping[str, FloatArray],
    windows: Sequence[tuple[str, slice]],
) -> None:
    """Hysteresis loops x(u), one panel per window (like the paper's Fig. 9).

    Args:
        path: PNG file to write.
        u: voltage [V].
        x: measured displacement [µm].
        predictions: ``{label: predicted displacement [µm]}``.
        windows: ``(panel title, sample slice)`` per panel, e.g. the steady-state
            period of each frequency.
    """
    cols = 2 if len(windows) > 1 else 1
    rows = (len(windows) + cols - 1) // cols
    fig = _figure(5.0 * cols, 4.2 * rows)
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for ax, (title, sel) in zip(axes, windows):
        ax.plot(u[sel], x[sel], **_MEASURED_STYLE)
        # Keep the measured loop readable when a prediction is far off.
        lo, hi = float(np.min(x[sel])), float(np.max(x[sel]))
        pad = 0.3 * max(hi - lo, 1e-9)
        ax.set_ylim(lo - pad, hi + pad)
        for label, pred in predictions.items():
            ax.plot(u[sel], pred[sel], linewidth=1.0, linestyle="--", label=label)
        ax.set_title(title)
        ax.set_xlabel("voltage u [V]")
        ax.set_ylabel("displacement x [µm]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", fontsize=7)
    for ax in axes[len(windows) :]:
        ax.set_visible(False)
    fig.savefig(path, dpi=110)


def plot_diagnosis(
    result: Diagnosis,
    t: ArrayLike,
    u: ArrayLike,
    x: ArrayLike,
    path: str | os.PathLike[str],
    title: str = "",
) -> None:
    """The figure of a diagnosis (:func:`boucwen.diagnose`), as PNG.

    Panels: (a) the residual x − x̂ [µm] of the base model and of the model with the
    effects against time t [s], (b) the loops x(u) measured and of both models
    (u [V], x [µm]), (c) the amplitude spectrum [µm] of both residuals, with the
    spectral lines left unexplained (dashed); the verdict on what is left
    (:attr:`Diagnosis.unexplained`) is the figure's title.
    """
    t_arr, u_arr, x_arr = (np.asarray(v, dtype=np.float64) for v in (t, u, x))
    fig = _figure(11.0, 7.5)
    grid = fig.add_gridspec(2, 2)
    ax_r = fig.add_subplot(grid[0, :])
    ax_l = fig.add_subplot(grid[1, 0])
    ax_s = fig.add_subplot(grid[1, 1])
    # The extended model's label: what was added, or that nothing was.
    named = f"with {', '.join(result.effects)}" if result.effects else "base model only"
    ax_r.plot(
        t_arr,
        x_arr - result.x_base,
        linewidth=0.7,
        color="tab:red",
        label=f"base model (RMS {result.rms_before_um:.3g} µm, max {result.max_before_um:.3g} µm)",
    )
    ax_r.plot(
        t_arr,
        x_arr - result.x_extended,
        linewidth=0.7,
        color="tab:blue",
        label=f"{named} (RMS {result.rms_after_um:.3g} µm, max {result.max_after_um:.3g} µm)",
    )
    ax_r.axhline(0.0, color="grey", linewidth=0.5)
    ax_r.set_xlabel("time t [s]")
    ax_r.set_ylabel("error x − x̂ [µm]")
    ax_r.set_title(f"(a) residual before and after{': ' + title if title else ''}")
    ax_r.legend(loc="upper right", fontsize=8)
    ax_r.grid(True, alpha=0.3)
    ax_l.plot(u_arr, x_arr, color="black", linewidth=1.2, label="measured")
    ax_l.plot(u_arr, result.x_base, color="tab:red", linewidth=0.7, linestyle="--", label="base model")
    ax_l.plot(u_arr, result.x_extended, color="tab:blue", linewidth=0.7, linestyle=":", label=named)
    ax_l.set_xlabel("voltage u [V]")
    ax_l.set_ylabel("displacement x [µm]")
    ax_l.set_title("(b) loops")
    ax_l.legend(loc="upper left", fontsize=8)
    ax_l.grid(True, alpha=0.3)
    dt = float(t_arr[1] - t_arr[0]) if t_arr.size > 1 else 1.0
    freqs = np.fft.rfftfreq(t_arr.size, dt)[1:]
    for err, color, label in (
        (x_arr - result.x_base, "tab:red", "base model"),
        (x_arr - result.x_extended, "tab:blue", named),
    ):
        amp = np.abs(np.fft.rfft(err - err.mean()))[1:] * 2.0 / t_arr.size
        ax_s.loglog(freqs, np.maximum(amp, 1e-12), color=color, linewidth=0.6, label=label)
    ax_s.set_xlabel("frequency [Hz]")
    ax_s.set_ylabel("residual amplitude [µm]")
    ax_s.set_title("(c) residual spectrum")
    ax_s.legend(loc="lower left", fontsize=8)
    ax_s.grid(True, alpha=0.3, which="both")
    left = result.unexplained
    if left is not None:
        for line in left.unexplained_lines:
            ax_s.axvline(line["freq_hz"], color="tab:green", linewidth=0.6, linestyle="--")
        fig.suptitle(left.summary(), fontsize=8)
    fig.savefig(path, dpi=110)


def plot_identify(
    result: Replay,
    t: ArrayLike,
    x: ArrayLike,
    path: str | os.PathLike[str],
    title: str = "",
) -> None:
    """The figure of a replay through an online identifier (:func:`boucwen.replay.replay`), as PNG.

    One panel per parameter estimate (kv, x0, A, β, γ, n, δ, then the effects' values)
    against time t [s], and below them (a) the error x − x̂ [µm] of the one-step
    prediction, of the block-ahead run and of the fixed model, and (b) the block-ahead
    error of each block, identified beside fixed.
    """
    from ._core import Params

    t_arr, x_arr = np.asarray(t, dtype=np.float64), np.asarray(x, dtype=np.float64)
    traces = {name: result.params[:, i] for i, name in enumerate(Params.names)} | result.effects
    cols = 3
    rows = -(-len(traces) // cols)
    fig = _figure(11.0, 2.0 * rows + 5.0)
    grid = fig.add_gridspec(rows + 2, cols, height_ratios=[1.0] * rows + [1.4, 1.4])
    for i, (name, values) in enumerate(traces.items()):
        ax = fig.add_subplot(grid[i // cols, i % cols])
        ax.plot(t_arr, values, linewidth=0.9, color="tab:blue")
        ax.set_title(name, fontsize=9)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
    ax_e = fig.add_subplot(grid[rows, :])
    ax_e.plot(t_arr, x_arr - result.one_step, linewidth=0.6, color="tab:grey", label="one-step prediction")
    ax_e.plot(t_arr, x_arr - result.fixed, linewidth=0.7, color="tab:red", label="fixed model, open loop")
    ax_e.plot(t_arr, x_arr - result.block_ahead, linewidth=0.7, color="tab:blue", label="identified, block-ahead")
    ax_e.set_ylabel("error x − x̂ [µm]")
    ax_e.set_title(f"(a) error over time{': ' + title if title else ''}")
    ax_e.legend(loc="upper right", fontsize=8)
    ax_e.grid(True, alpha=0.3)
    ax_b = fig.add_subplot(grid[rows + 1, :], sharex=ax_e)
    t_blocks = t_arr[result.block_starts()]
    ax_b.step(t_blocks, result.fixed_block_errors, where="post", color="tab:red", linewidth=0.8, label="fixed model")
    ax_b.step(t_blocks, result.block_errors, where="post", color="tab:blue", linewidth=0.8, label="identified")
    ax_b.set_xlabel("time t [s]")
    ax_b.set_ylabel("max |x − x̂| [µm]")
    ax_b.set_title(f"(b) block-ahead error, blocks of {result.block} samples")
    ax_b.legend(loc="upper right", fontsize=8)
    ax_b.grid(True, alpha=0.3)
    fig.savefig(path, dpi=110)


def plot_tracking(
    path: str | os.PathLike[str],
    t: np.ndarray,
    x_d: np.ndarray,
    runs: Mapping[str, np.ndarray],
    adaptation: int,
    title: str,
) -> None:
    """Closed-loop tracking of one reference: (a) x_d and x over time, (b) the error
    x − x_d, (c) x against x_d.

    Args:
        path: PNG file to write.
        t: sample times [s].
        x_d: desired displacement [µm].
        runs: ``{method label: measured displacement x [µm]}``, each the length of ``x_d``.
        adaptation: samples of the adaptation period (shaded; the metrics leave them out).
        title: figure title.

    Records longer than 16 000 samples are drawn decimated (every k-th sample); the
    extremes of the error between drawn samples may then be missing from panel (b).
    """
    # Long records: every k-th sample is enough for the eye (at most about 8000 per line).
    k = max(1, t.size // 8000)
    t, x_d, adaptation = t[::k], x_d[::k], adaptation // k
    runs = {label: x[::k] for label, x in runs.items()}
    fig = _figure(12.0, 7.5)
    grid = fig.add_gridspec(2, 2, width_ratios=(2.2, 1.0))
    ax_x = fig.add_subplot(grid[0, 0])
    ax_e = fig.add_subplot(grid[1, 0], sharex=ax_x)
    ax_l = fig.add_subplot(grid[:, 1])
    ax_x.plot(t, x_d, color="black", linewidth=1.6, label="desired x_d")
    ax_l.plot(x_d, x_d, color="black", linewidth=1.0, linestyle=":", label="x = x_d")
    for label, x in runs.items():
        ax_x.plot(t, x, linewidth=0.9, label=label)
        ax_e.plot(t, x - x_d, linewidth=0.9, label=label)
        ax_l.plot(x_d[adaptation:], x[adaptation:], linewidth=0.9, label=label)
    for ax in (ax_x, ax_e):
        ax.axvspan(t[0], t[min(adaptation, t.size - 1)], color="grey", alpha=0.12, linewidth=0)
        ax.grid(True, alpha=0.3)
    ax_x.set_ylabel("displacement [µm]")
    ax_x.set_title(f"(a) {title}")
    ax_x.legend(loc="upper right", fontsize=7)
    ax_e.set_ylabel("error x − x_d [µm]")
    ax_e.set_xlabel("time t [s] (shaded: adaptation)")
    ax_e.set_title("(b) tracking error")
    settled = np.concatenate([np.abs(x - x_d)[adaptation:] for x in runs.values()]) if runs else np.zeros(1)
    limit = float(np.max(settled)) if settled.size else 1.0
    ax_e.set_ylim(-1.1 * limit - 1e-9, 1.1 * limit + 1e-9)
    ax_l.set_xlabel("desired x_d [µm]")
    ax_l.set_ylabel("measured x [µm]")
    ax_l.set_title("(c) x against x_d, after adaptation")
    ax_l.grid(True, alpha=0.3)
    fig.savefig(path, dpi=100)
