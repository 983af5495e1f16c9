"""Type stubs for ``boucwen._core``, the compiled Rust core (re-exported by ``boucwen``).

The model (Zhu, Bian & Rui, Precision Engineering 38 (2014) 921–927)::

    x     = kv·u + x0 + h                                           (3)
    dh/dt = A·u̇ − β·|u̇|·|h|^(n−1)·h − γ·u̇·|h|^n + δ·u·sgn(u̇)        (5)

u: voltage [V]; x, h: displacement [µm]; t: time [s].

Every invalid argument or non-finite sample raises ``ValueError`` with a
one-line message naming the offending value; an argument of the wrong kind
(a string or ``None`` for an array) raises ``TypeError``.

Layout of this file, one section per part of the extension, so that a new
part is one new section (and one line in ``__all__``):

- module constants
- parameters: ``Params``
- simulation: ``simulate``, ``paper_input``, ``Model``
- online identification: ``_IdentifierMethod``, ``_SubFitOutcome`` and
  ``_IdentifierStatus`` (type-only names, absent at run time), ``Identifier``
- effects: ``_CreepParams`` … ``_EffectParams`` (type-only: the dicts ``EffectSet``
  takes and gives), ``EffectSet``, ``simulate_extended``
"""

from typing import ClassVar, Literal, TypedDict, final

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "EffectSet",
    "Identifier",
    "Model",
    "Params",
    "__version__",
    "paper_input",
    "simulate",
    "simulate_extended",
]

# ---------------------------------------------------------------- module constants

__version__: str
"""Version of the compiled core (the crate version)."""

# ---------------------------------------------------------------- parameters

@final
class Params:
    """Parameters of the asymmetric Bouc–Wen model (eqs. 3 and 5).

    kv [µm/V], x0 [µm], A [µm/V], beta and gamma [µm^(1−n)/V], n [-] (> 0),
    delta [µm/(V·s)]. Immutable and hashable; ``repr`` round-trips; pickles.
    Building one with a non-finite value or n ≤ 0 raises ``ValueError``
    naming the parameter.
    """

    names: ClassVar[list[str]]
    """Parameter names in array order: ``["kv", "x0", "A", "beta", "gamma", "n", "delta"]``."""

    def __new__(cls, kv: float, x0: float, A: float, beta: float, gamma: float, n: float, delta: float) -> Params: ...
    @staticmethod
    def paper_1hz() -> Params:
        """The paper's Table 2 values identified at 1 Hz on a P-885.51 stack."""
    @property
    def kv(self) -> float:
        """Linear gain kv [µm/V]."""
    @property
    def x0(self) -> float:
        """Offset x0 [µm]."""
    @property
    def A(self) -> float:
        """Hysteresis gain A [µm/V]."""
    @property
    def beta(self) -> float:
        """β [µm^(1−n)/V], weight of the |u̇|·|h|^(n−1)·h term."""
    @property
    def gamma(self) -> float:
        """γ [µm^(1−n)/V], weight of the u̇·|h|^n term."""
    @property
    def n(self) -> float:
        """Shape exponent n [-], > 0."""
    @property
    def delta(self) -> float:
        """Asymmetry δ [µm/(V·s)], weight of the u·sgn(u̇) term."""
    def to_array(self) -> NDArray[np.float64]:
        """``[kv, x0, A, beta, gamma, n, delta]`` as a new float64 array."""
    @staticmethod
    def from_array(values: ArrayLike) -> Params:
        """Inverse of :meth:`to_array` (7 values); ``ValueError`` naming an invalid parameter."""
    def to_dict(self) -> dict[str, float]:
        """``{"kv": …, "x0": …, "A": …, "beta": …, "gamma": …, "n": …, "delta": …}``."""
    @staticmethod
    def from_dict(d: dict[str, float]) -> Params:
        """Inverse of :meth:`to_dict`: every key required (``KeyError``), no other key allowed (``ValueError``)."""
    def replace(self, **changes: float) -> Params:
        """A copy with some values replaced, e.g. ``p.replace(n=1.6)``; validated."""
    def __eq__(self, value: object, /) -> bool: ...
    def __ne__(self, value: object, /) -> bool: ...
    def __hash__(self) -> int: ...
    def __reduce__(self) -> tuple[type, tuple[float, float, float, float, float, float, float]]: ...

# ---------------------------------------------------------------- simulation

def simulate(
    params: Params,
    u: ArrayLike,
    dt: float,
    h0: float = 0.0,
    u_prev: float | None = None,
) -> tuple[NDArray[np.float64], float]:
    """Simulates the model over a record; returns ``(x, h_final)``.

    ``u`` [V] is piecewise linear between samples ``dt`` [s] apart. ``x[k] =
    kv·u[k] + x0 + h[k]`` [µm]; ``h_final`` is h after the last sample [µm].
    With ``u_prev=None``, h[0] = ``h0`` [µm]; with ``u_prev=v`` [V] the first
    interval runs from v to u[0], so ``simulate(p, u[k:], dt, h0=h_final,
    u_prev=u[k-1])`` continues a record split at k exactly as one call would
    (as ``scipy.signal.lfilter(..., zi)``). A non-finite sample raises
    ``ValueError`` before anything is computed. Releases the GIL.
    """

def paper_input(dt: float, tail_s: float = 0.05) -> NDArray[np.float64]:
    """The paper's input u = 50 + 50·sin(2πft − π/2) [V] sampled every ``dt`` [s].

    f = 1 Hz for t < 3 s, 10 Hz to 3.3 s, 100 Hz to 3.33 s, then 200 Hz for
    ``tail_s`` [s]; each switch falls on a minimum (u = 0).
    """

@final
class Model:
    """A per-sample model for control loops: ``step(u) -> x``.

    ``params``: the model; ``dt``: sampling interval [s]; ``h0``: initial h [µm].
    The first sample keeps h = h0; each later one integrates eq. (5) from the
    previous voltage. A non-finite ``u`` raises ``ValueError`` and changes
    nothing. Pickles with its state.
    """

    def __new__(cls, params: Params, dt: float, h0: float = 0.0) -> Model: ...
    def step(self, u: float) -> float:
        """Takes the next voltage u [V]; returns the displacement x [µm]."""
    @property
    def h(self) -> float:
        """Current hysteresis state h [µm]."""
    @property
    def params(self) -> Params:
        """The model's parameters."""
    @property
    def dt(self) -> float:
        """Sampling interval [s]."""
    def reset(self, h0: float = 0.0) -> None:
        """Forgets the past: h = ``h0`` [µm], no previous sample."""
    def __getstate__(self) -> tuple[Params, float, float, float | None]: ...
    def __setstate__(self, state: tuple[Params, float, float, float | None]) -> None: ...
    def __getnewargs__(self) -> tuple[Params, float]: ...

# ---------------------------------------------------------------- online identification

_IdentifierMethod = Literal["paper", "rpem"]
"""Names accepted by ``Identifier(method=...)``."""

_SubFitOutcome = Literal["ran", "reduced", "held"]
"""What a sub-fit did in the last push: ran in full, ran on fewer unknowns
(rank-deficient data; the rest kept), or held the previous estimate."""

class _IdentifierStatus(TypedDict):
    """``Identifier.status``: what the last push did."""

    samples: int
    """Samples pushed since construction or reset."""
    window_full: bool
    """The window holds its full N samples."""
    refreshed: bool
    """The window's running sums were recomputed exactly in this push."""
    line_fit: _SubFitOutcome
    """Step 1, kv and x0 (limited-memory RLS)."""
    rate_fit: _SubFitOutcome
    """Step 2, A and δ."""
    shape_fit: _SubFitOutcome
    """Step 3, n and β + γ."""
    return_fit: _SubFitOutcome
    """Step 4, γ − β."""

@final
class Identifier:
    """Online identifier of the asymmetric Bouc–Wen model, one sample at a time.

    ``push(u, x)`` takes a voltage u [V] and a measured displacement x [µm] and
    returns the model's displacement [µm] for that sample, predicted with the
    estimates from *before* the sample and with the model's own simulated h;
    then it updates the estimates. A non-finite sample raises ``ValueError``
    and leaves the identifier exactly as it was.

    Arguments: ``dt`` sampling interval [s]; ``window`` limited memory N
    [samples] (16 to 10 000 000); ``init`` starting parameters (e.g. an offline fit);
    ``h0`` initial h [µm]; ``method`` the online method: "rpem" (default, the
    output-error method) or "paper" (the paper's method; ``window`` is its N).

    Options of ``method="paper"`` (default in brackets; ``None`` keeps it):
    ``decomposition`` "model" (line through x − h_model) or "line" (the
    paper, literal: line through the loop) ["model"]; ``h_zero_frac``: |h|
    below this fraction of the window's std(x) counts as h ≈ 0 [0.005];
    ``rate_frac``: points with |u̇| below this fraction of rms(u̇) are left out
    [0.2]; ``min_points``: fewest points for a sub-fit [8]; ``rank_tol``: step 2
    fits δ only when 1 − corr²(u̇, u) exceeds it [1e-3]; ``min_log_spread``:
    fewest std(ln h) for fitting n [0.05]; ``min_r2``: least squared correlation
    of the log–log points [0.9]; ``min_arg_frac``: steps 3–4 use a point only when
    |A − r| ≥ this fraction of |A| [0.05]; ``min_line_t``: kv, x0 are updated only
    when |kv| is at least this many standard errors [10]; ``noise_gate``: steps 3–4
    use a point only when |A − r| exceeds this many noise standard deviations [3.0];
    ``min_delta_t``: δ is updated only when
    resolved to this many standard errors [3.0]; ``min_u_std_v``: step 1 runs only
    while std(u) over the window exceeds this [1e-6 V]; ``n_bounds``: accepted
    range of n [(0.5, 4.0)].

    Options of ``method="rpem"`` (recursive prediction-error method on the
    model's output error, sensitivities ∂h/∂θ propagated through the
    integrator; ``window`` is not used): ``forgetting`` λ per sample [1.0];
    ``memory_travel_v`` memory in input travel [2000 V = ten periods of a
    0–100 V sine]; ``p0`` initial covariance of θᵢ/scaleᵢ [1e-3];
    ``noise_um2`` expected prediction-error variance R [1e-4 µm²];
    ``max_trace`` bound on tr P [1.0]; ``max_step`` largest change per sample
    as a fraction of each parameter's scale [0.01]; ``max_offset_step_um``
    largest change of x0 per sample [0.5 µm]; ``offset_walk_um`` random walk
    of x0 per sample [0.05 µm]; ``n_bounds`` [(1.0, 4.0)]; ``margin`` least
    β + γ and β − γ [1e-6]; ``effects`` an :class:`EffectSet` (e.g. from
    ``boucwen.effects.fit_extended`` or ``boucwen.diagnose``) whose ``input_lag`` fc
    and ``creep`` gains are identified too, from the values given (creep time
    constants fixed, at most 4 elements, other effects rejected) [None];
    ``p0_effects`` initial covariance of ln fc and of the gains' logistic
    coordinates, a relative standard deviation of about √p0_effects [0.05]. With
    ``creep`` among the effects ``offset_walk_um`` defaults to 0. Options of one
    method given to the other raise ``ValueError``.
    """

    def __new__(
        cls,
        dt: float,
        window: int,
        init: Params,
        h0: float = 0.0,
        method: _IdentifierMethod = "rpem",
        *,
        decomposition: Literal["model", "line"] = "model",
        h_zero_frac: float | None = None,
        rate_frac: float | None = None,
        min_points: int | None = None,
        rank_tol: float | None = None,
        min_log_spread: float | None = None,
        min_r2: float | None = None,
        min_arg_frac: float | None = None,
        min_line_t: float | None = None,
        noise_gate: float | None = None,
        min_delta_t: float | None = None,
        min_u_std_v: float | None = None,
        n_bounds: tuple[float, float] | None = None,
        forgetting: float | None = None,
        memory_travel_v: float | None = None,
        p0: float | None = None,
        noise_um2: float | None = None,
        max_trace: float | None = None,
        max_step: float | None = None,
        margin: float | None = None,
        offset_walk_um: float | None = None,
        max_offset_step_um: float | None = None,
        effects: EffectSet | None = None,
        p0_effects: float | None = None,
    ) -> Identifier: ...
    @property
    def effects(self) -> EffectSet | None:
        """Current effect estimates (fc [Hz], creep gains [µm/V]) of ``method="rpem"``
        (an empty EffectSet without effects); None for ``method="paper"``."""
    def push(self, u: float, x: float) -> float:
        """Takes one sample, u [V] and measured x [µm]; returns the predicted x [µm]."""
    def push_many(self, u: ArrayLike, x: ArrayLike) -> NDArray[np.float64]:
        """``push`` over arrays with the GIL released; predictions [µm] identical to a
        loop of ``push``. A non-finite value anywhere raises ``ValueError`` before any
        sample is used (the state is unchanged)."""
    @property
    def params(self) -> Params:
        """The current parameter estimates."""
    @property
    def h(self) -> float:
        """The model's hysteresis state h [µm] after the last sample."""
    @property
    def method(self) -> _IdentifierMethod:
        """The online method in use."""
    @property
    def status(self) -> _IdentifierStatus:
        """What the last push did (a new dict at each read)."""
    def __copy__(self) -> Identifier:
        """An independent copy that continues exactly like this one."""
    def __deepcopy__(self, _memo: dict[int, object], /) -> Identifier:
        """As ``__copy__``."""
    def reset(self) -> None:
        """Back to the state right after construction."""

class _CreepParams(TypedDict):
    """``creep``: first-order elements, time constants [s] and static gains [µm/V]."""

    tau_s: list[float]
    gain_um_per_v: list[float]

class _InputLagParams(TypedDict):
    """``input_lag``: first-order lag of the voltage, corner frequency [Hz]."""

    fc_hz: float

class _ResonanceParams(TypedDict):
    """``resonance``: second-order element, natural frequency [Hz] and damping ratio [-]."""

    fn_hz: float
    zeta: float

class _DriftParams(TypedDict):
    """``drift``: a trend of the output [µm/s]."""

    rate_um_per_s: float

class _DelayParams(TypedDict):
    """``delay``: a whole number of samples [-]."""

    samples: int

class _EffectParams(TypedDict, total=False):
    """``EffectSet.to_dict()``: the effects present, each with its parameters."""

    creep: _CreepParams
    input_lag: _InputLagParams
    resonance: _ResonanceParams
    drift: _DriftParams
    delay: _DelayParams

@final
class EffectSet:
    """Which effects surround the base model, with their parameters (see boucwen.effects).

    creep={"tau_s": [s…], "gain_um_per_v": [µm/V…]}, input_lag={"fc_hz": Hz},
    resonance={"fn_hz": Hz, "zeta": -}, drift={"rate_um_per_s": µm/s},
    delay={"samples": int ≥ 0}; None = absent. Invalid values raise ValueError."""

    vocabulary: ClassVar[list[str]]
    def __new__(
        cls,
        *,
        creep: _CreepParams | None = None,
        input_lag: _InputLagParams | None = None,
        resonance: _ResonanceParams | None = None,
        drift: _DriftParams | None = None,
        delay: _DelayParams | None = None,
    ) -> EffectSet: ...
    @property
    def names(self) -> list[str]:
        """Names of the effects present, in vocabulary order."""
    def to_dict(self) -> _EffectParams: ...
    @staticmethod
    def from_dict(d: _EffectParams) -> EffectSet: ...
    def __len__(self) -> int: ...
    def __contains__(self, key: object, /) -> bool: ...

def simulate_extended(
    params: Params, effects: EffectSet | None, u: ArrayLike, dt: float, h0: float = 0.0
) -> NDArray[np.float64]:
    """x [µm] of the base model with effects: u → input_lag → (Bouc–Wen + creep) →
    resonance → + drift → delay. GIL released."""
