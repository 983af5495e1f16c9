"""Replaying a logged record through an online identifier, as ``boucwen identify`` does.

The record is pushed sample by sample (``Identifier.push``: the same predictions as
``push_many``), each sample's prediction, parameter estimates, effect estimates and
status recorded. The model is scored as the tables score it (:mod:`boucwen.evaluation`):
the record is cut into blocks of ``block`` samples; at the start of every block the
estimates and state are frozen and the model is run open loop over the block
(``Identifier.forecast``), and the block's score is the largest |x − x̂| there [µm]
(the *block-ahead error*; on the paper's schedule a block is a period of the input, on a
random input :data:`boucwen.experiments.long_run.RANDOM_BLOCK` samples). Beside it, the
*fixed model* (the starting model, never updated) run open loop over the whole record
with its effects, scored on the same blocks.

Units: u [V], x and errors [µm], t and dt [s].
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, replace
from typing import Any, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import evaluation
from ._core import EffectSet, Identifier, InvalidConfig, Params
from .checks import FloatArray
from .config import PaperConfig
from .effects.base import params_of, set_of
from .model_file import ModelSource, SavedModel
from .pacing import PacedFeed, RefineMode, feed_for
from .record import Record
from .status import StepReason

__all__ = [
    "BLOCK_S",
    "METHODS",
    "ONLINE_EFFECTS",
    "REASON_CODES",
    "SUBFIT_CODES",
    "Replay",
    "check_options",
    "make_identifier",
    "replay",
]

#: The online methods ``boucwen identify`` offers.
METHODS = ("horizon", "rpem", "paper")
#: Default block of the block-ahead error [s]: the tables' block on a random input
#: (1000 samples at 10 kHz).
BLOCK_S = 0.1
#: The effects each method identifies along (the others of a starting model are left out).
ONLINE_EFFECTS: dict[str, tuple[str, ...]] = {"horizon": ("input_lag",), "rpem": ("input_lag", "creep"), "paper": ()}
#: How the paper method's sub-fit outcomes are written in the status columns.
SUBFIT_CODES = {"ran": 0, "reduced": 1, "held": 2}
#: The number written for each reason a step of the paper's method gives
#: (:data:`boucwen.status.StepReason`, in its order).
REASON_CODES = {reason: k for k, reason in enumerate(get_args(StepReason))}


def make_identifier(
    method: str, init: SavedModel, dt: float, *, refine: RefineMode = "sync", window: int | None = None
) -> tuple[Identifier, list[str]]:
    """The identifier of ``method`` started from ``init`` (its parameters, h0 and the
    effects the method identifies along, :data:`ONLINE_EFFECTS`), and the names of the
    starting model's effects it leaves out.

    ``horizon`` is the recommended :class:`boucwen.Identifier` (an input lag identified
    along, from the model's lag if it has one); ``refine`` only applies to it.
    ``window``: the paper method's window [samples] (default: 1 s of samples, at least 16).

    Raises:
        InvalidConfig: an unknown method, ``refine`` for another method than horizon.
    """
    check_options(method, refine, window)
    present = params_of(init.effects)
    kept = {k: v for k, v in present.items() if k in ONLINE_EFFECTS[method]}
    dropped = [k for k in present if k not in kept]
    effects = set_of(kept) if kept else None
    p, h0 = init.params, init.h0_um
    if method == "paper":
        n = max(16, round(1.0 / dt)) if window is None else window
        return Identifier.paper(dt, n, p, h0, config=PaperConfig()), dropped
    if method == "rpem":
        return Identifier.rpem(dt, p, h0, effects=effects), dropped
    return Identifier(dt, p, h0, effects=effects, refine=refine), dropped


def check_options(method: str, refine: str, window: int | None) -> None:
    """:class:`boucwen.InvalidConfig` unless ``method`` is one of :data:`METHODS`, ``refine``
    is "sync" or the method horizon, and ``window`` is None or the method paper."""
    if method not in METHODS:
        raise InvalidConfig(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if refine != "sync" and method != "horizon":
        raise InvalidConfig(f"refine={refine!r} is for the horizon method, not {method!r}")
    if window is not None and method != "paper":
        raise InvalidConfig(f"window is for the paper method, not {method!r}")


@dataclass(frozen=True, eq=False)
class Replay:
    """What :func:`replay` recorded.

    Attributes:
        one_step: each sample's prediction, made before the sample was used [µm].
        block_ahead: the frozen model's open-loop run over each block [µm].
        fixed: the fixed model's open-loop run over the record [µm].
        params: the estimates after each sample, shape (N, 7), in the order of
            :attr:`boucwen.Params.names`.
        effects: the effect estimates after each sample, one column per value
            (``input_lag.fc_hz``, ``creep.gain_um_per_v.1``, …).
        status: the identifier's status after each sample, one column per field
            (booleans as 0/1, the paper's sub-fit outcomes as :data:`SUBFIT_CODES`).
        block: samples per block.
        block_errors, fixed_block_errors: the block-ahead errors of the identified and
            the fixed model, one per block [µm].
        final: the identified model at the end (parameters and effects; h0 the start's).
        late_samples: samples pushed more than one interval late (background mode,
            paced at the record's own rate; 0 otherwise).
    """

    one_step: FloatArray
    block_ahead: FloatArray
    fixed: FloatArray
    params: FloatArray
    effects: dict[str, FloatArray]
    status: dict[str, FloatArray]
    block: int
    block_errors: FloatArray
    fixed_block_errors: FloatArray
    final: SavedModel
    late_samples: int

    def block_starts(self) -> NDArray[np.intp]:
        """The first sample of every block."""
        return np.arange(self.block_errors.size) * self.block


def _flat(prefix: str, value: Any, out: dict[str, float]) -> None:
    """``value`` (a number, bool, text, list or dict) as named numbers in ``out``."""
    if isinstance(value, dict):
        for k, v in value.items():
            _flat(f"{prefix}.{k}" if prefix else str(k), v, out)
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _flat(f"{prefix}.{i + 1}", v, out)
    elif isinstance(value, str):
        out[prefix] = float(SUBFIT_CODES.get(value, REASON_CODES.get(value, -1)))
    else:
        out[prefix] = float("nan") if value is None else float(value)


class _RecordingFeed(PacedFeed):
    """A feed that pushes one sample at a time and records the estimates and status after each."""

    def __init__(self, base: PacedFeed | None, dt: float, n: int) -> None:
        if base is None:
            super().__init__(dt, paced=False)
        else:
            super().__init__(base.dt, paced=base.paced, refine_intervals=base.refine_intervals)
        self.params = np.empty((n, len(Params.names)))
        self.rows: list[dict[str, float]] = []
        self.status_rows: list[dict[str, float]] = []

    def push_many(self, ident: Identifier, u: ArrayLike, x: ArrayLike) -> NDArray[np.float64]:
        ua, xa = np.asarray(u, dtype=np.float64), np.asarray(x, dtype=np.float64)
        out = np.empty_like(ua)
        for i in range(ua.size):
            k = self.samples
            out[i] = super().push_many(ident, ua[i : i + 1], xa[i : i + 1])[0]
            self.params[k] = ident.params.to_array()
            effects: dict[str, float] = {}
            found = ident.effects
            if found is not None:
                _flat("", params_of(found), effects)
            self.rows.append(effects)
            status: dict[str, float] = {}
            _flat("", dataclasses.asdict(ident.status), status)
            self.status_rows.append(status)
        return out


def _columns(rows: list[dict[str, float]]) -> dict[str, FloatArray]:
    names: dict[str, None] = {}
    for row in rows:
        names.update(dict.fromkeys(row))
    return {name: np.array([row.get(name, np.nan) for row in rows]) for name in names}


def replay(
    rec: Record,
    init: SavedModel,
    *,
    method: str = "horizon",
    refine: RefineMode = "sync",
    window: int | None = None,
    block: int | None = None,
) -> tuple[Replay, list[str]]:
    """Pushes ``rec`` through the identifier of :func:`make_identifier` and scores it
    (module docs); also returns the starting model's effects the method left out.

    Args:
        rec: the record.
        init: the starting model, also the fixed model.
        method, refine, window: as :func:`make_identifier`.
        block: samples per block (default :data:`BLOCK_S` of samples, at least 2).

    Raises:
        InvalidConfig: bad options, a block longer than the record.
    """
    n = len(rec)
    b = max(2, round(BLOCK_S / rec.dt)) if block is None else int(block)
    if not 2 <= b <= n:
        raise InvalidConfig(f"block must be 2 … {n} samples (the record's length), got {block!r}")
    ident, dropped = make_identifier(method, init, rec.dt, refine=refine, window=window)
    feed = _RecordingFeed(feed_for(refine, rec.dt), rec.dt, n)
    trace = np.empty(n)
    # One segment whose "period" is the block: period_ahead freezes and forecasts at every block start.
    _, per_block, one_step = evaluation.period_ahead(
        ident, rec.u, rec.x, rec.dt, [(1.0 / (b * rec.dt), 0, n)], trace=trace, feed=feed
    )
    fixed = init.simulate(rec.u, rec.dt)
    starts = np.arange(0, n, b)
    fixed_blocks = np.maximum.reduceat(np.abs(rec.x - fixed), starts)
    found = ident.effects
    final = SavedModel(ident.params, init.h0_um, rec.dt, found if found is not None else EffectSet())
    final = replace(final, source=ModelSource.of_record(rec, "identify", final.simulate(rec.u)))
    result = Replay(
        one_step=one_step,
        block_ahead=trace,
        fixed=fixed,
        params=feed.params,
        effects=_columns(feed.rows),
        status=_columns(feed.status_rows),
        block=b,
        block_errors=np.asarray(next(iter(per_block.values()))),
        fixed_block_errors=fixed_blocks,
        final=final,
        late_samples=feed.late_samples,
    )
    return result, dropped
