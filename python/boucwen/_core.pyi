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
- effects: ``EffectSet``, ``simulate_extended``
- compensation: ``_Clip``, ``_InverseStatus``, ``_CompensatorStatus``,
  ``_CompensatorGains`` (type-only), ``Inverse``, ``invert``, ``Compensator``
"""

from typing import ClassVar, Dict, List, Literal, Optional, Tuple, TypedDict, final

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "__version__",
    "Params",
    "simulate",
    "paper_input",
    "Model",
    "Identifier",
    "EffectSet",
    "simulate_extended",
    "Inverse",
    "invert",
    "Compensator",
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

    names: ClassVar[List[str]]
    """Parameter names in array order: ``["kv", "x0", "A", "beta", "gamma", "n", "delta"]``."""

    def __new__(cls, kv: float, x0: float, A: float, beta: float, gamma: float, n: float, delta: float) -> "Params": ...
    @staticmethod
    def paper_1hz() -> "Params":
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
    def from_array(values: ArrayLike) -> "Params":
        """Inverse of :meth:`to_array` (7 values); ``ValueError`` naming an invalid parameter."""
    def to_dict(self) -> Dict[str, float]:
        """``{"kv": …, "x0": …, "A": …, "beta": …, "gamma": …, "n": …, "delta": …}``."""
    @staticmethod
    def from_dict(d: Dict[str, float]) -> "Params":
        """Inverse of :meth:`to_dict`: every key required (``KeyError``), no other key allowed (``ValueError``)."""
    def replace(self, **changes: float) -> "Params":
        """A copy with some values replaced, e.g. ``p.replace(n=1.6)``; validated."""
    def __eq__(self, value: object, /) -> bool: ...
    def __ne__(self, value: object, /) -> bool: ...
    def __hash__(self) -> int: ...
    def __reduce__(self) -> Tuple[type, Tuple[float, float, float, float, float, float, float]]: ...

# ---------------------------------------------------------------- simulation

def simulate(
    params: Params,
    u: ArrayLike,
    dt: float,
    h0: float = 0.0,
    u_prev: Optional[float] = None,
) -> Tuple[NDArray[np.float64], float]:
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

    def __new__(cls, params: Params, dt: float, h0: float = 0.0) -> "Model": ...
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
    def __getstate__(self) -> Tuple[Params, float, float, Optional[float]]: ...
    def __setstate__(self, state: Tuple[Params, float, float, Optional[float]]) -> None: ...
    def __getnewargs__(self) -> Tuple[Params, float]: ...

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
        h_zero_frac: Optional[float] = None,
        rate_frac: Optional[float] = None,
        min_points: Optional[int] = None,
        rank_tol: Optional[float] = None,
        min_log_spread: Optional[float] = None,
        min_r2: Optional[float] = None,
        min_arg_frac: Optional[float] = None,
        min_line_t: Optional[float] = None,
        noise_gate: Optional[float] = None,
        min_delta_t: Optional[float] = None,
        min_u_std_v: Optional[float] = None,
        n_bounds: Optional[Tuple[float, float]] = None,
        forgetting: Optional[float] = None,
        memory_travel_v: Optional[float] = None,
        p0: Optional[float] = None,
        noise_um2: Optional[float] = None,
        max_trace: Optional[float] = None,
        max_step: Optional[float] = None,
        margin: Optional[float] = None,
        offset_walk_um: Optional[float] = None,
        max_offset_step_um: Optional[float] = None,
        effects: Optional[EffectSet] = None,
        p0_effects: Optional[float] = None,
    ) -> "Identifier": ...
    @property
    def effects(self) -> Optional[EffectSet]:
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
    def __copy__(self) -> "Identifier":
        """An independent copy that continues exactly like this one."""
    def __deepcopy__(self, _memo: Dict[int, object], /) -> "Identifier":
        """As ``__copy__``."""
    def reset(self) -> None:
        """Back to the state right after construction."""

@final
class EffectSet:
    """Which effects surround the base model, with their parameters (see boucwen.effects).

    creep={"tau_s": [s…], "gain_um_per_v": [µm/V…]}, input_lag={"fc_hz": Hz},
    resonance={"fn_hz": Hz, "zeta": -}, drift={"rate_um_per_s": µm/s},
    delay={"samples": int ≥ 0}; None = absent. Invalid values raise ValueError."""

    vocabulary: ClassVar[List[str]]
    def __new__(
        cls,
        *,
        creep: Optional[Dict[str, object]] = None,
        input_lag: Optional[Dict[str, float]] = None,
        resonance: Optional[Dict[str, float]] = None,
        drift: Optional[Dict[str, float]] = None,
        delay: Optional[Dict[str, int]] = None,
    ) -> "EffectSet": ...
    @property
    def names(self) -> List[str]:
        """Names of the effects present, in vocabulary order."""
    def to_dict(self) -> Dict[str, Dict[str, object]]: ...
    @staticmethod
    def from_dict(d: Dict[str, Dict[str, object]]) -> EffectSet: ...
    def __len__(self) -> int: ...
    def __contains__(self, key: object, /) -> bool: ...

def simulate_extended(
    params: Params, effects: Optional[EffectSet], u: ArrayLike, dt: float, h0: float = 0.0
) -> NDArray[np.float64]:
    """x [µm] of the base model with effects: u → input_lag → (Bouc–Wen + creep) →
    resonance → + drift → delay. GIL released."""

# ---------------------------------------------------------------- compensation

_Clip = Literal["none", "low", "high"]
"""Which voltage limit bound on a sample: none, ``u_min`` or ``u_max``."""

class _InverseStatus(TypedDict):
    """``Inverse.status``: what the last step did."""

    clip: _Clip
    """The limit that bound (the root lies beyond it; u sits on it)."""
    evaluations: int
    """Evaluations of the integrator in the step (at most 40; 0 for a hold)."""
    residual_um: float
    """Model displacement minus x_d after the step [µm]."""
    exact: bool
    """|residual| ≤ 1e-12·max(1, |x_d|) µm."""
    samples: int
    """Samples since construction or reset."""
    clipped_samples: int
    """Samples clipped since construction or reset."""

@final
class Inverse:
    """The inverse of the asymmetric Bouc–Wen model, one sample at a time: ``step(x_d) -> u``.

    Solves kv·u + x0 + Φ(h, u_prev → u) = x_d [µm] for u [V] with the model's own
    integrator Φ, so ``simulate`` on the voltages returns x_d (to 1e-12·max(1, |x_d|)
    µm) wherever the root lies within [``u_min``, ``u_max``] [V]; where a limit binds
    the sample is clipped, ``status["clip"]`` says which, and h [µm] follows the
    clipped u. Where x_d turns by less than |δ·u|·dt in a sample, no voltage reaches
    it exactly and the residual (at most that step) is reported. Newton with a secant
    slope, then Illinois inside a bracket: at most 40 evaluations of Φ per sample.

    ``effects``: an :class:`EffectSet` whose ``input_lag`` (exact one-sample lead),
    ``creep``, ``drift`` and ``delay`` (the reference is then read ``delay`` samples
    ahead: ``step`` takes x_d of sample k + d) are inverted too; a ``resonance``
    raises ``ValueError``. Pickles and copies with its state.
    """

    def __new__(
        cls,
        params: Params,
        dt: float,
        h0: float = 0.0,
        u_min: Optional[float] = None,
        u_max: Optional[float] = None,
        *,
        effects: Optional[EffectSet] = None,
    ) -> "Inverse": ...
    def step(self, x_d: float) -> float:
        """Takes the desired displacement x_d [µm]; returns the voltage u [V]."""
    def step_many(self, x_d: ArrayLike) -> NDArray[np.float64]:
        """``step`` over an array with the GIL released; identical to a loop of ``step``.
        A non-finite value anywhere raises ``ValueError`` before any sample is used."""
    def set_params(self, params: Params) -> None:
        """Replaces the parameters; h and the previous voltage are kept."""
    @property
    def params(self) -> Params:
        """The model's parameters."""
    @property
    def effects(self) -> Optional[EffectSet]:
        """The effects inverted along with the base model (None: none)."""
    @property
    def h(self) -> float:
        """Hysteresis state h [µm] after the last sample."""
    @property
    def dt(self) -> float:
        """Sampling interval [s]."""
    @property
    def u_min(self) -> Optional[float]:
        """Lower voltage limit [V] (None: none)."""
    @property
    def u_max(self) -> Optional[float]:
        """Upper voltage limit [V] (None: none)."""
    @property
    def preview_samples(self) -> int:
        """How many samples ahead ``step`` reads the reference (the inverted delay; 0 without)."""
    @property
    def status(self) -> _InverseStatus:
        """What the last step did (a new dict at each read)."""
    def reset(self) -> None:
        """Forgets the past: h = h0, no previous sample, counters zero."""
    def __reduce__(
        self,
    ) -> Tuple[
        object,
        Tuple[
            Params,
            float,
            float,
            Optional[float],
            Optional[float],
            Optional[EffectSet],
            Tuple[int, Optional[float], float, float, List[float]],
            Tuple[str, int, float, bool, int],
        ],
    ]: ...
    @classmethod
    def _restore(
        cls,
        params: Params,
        dt: float,
        h0: float,
        u_min: Optional[float],
        u_max: Optional[float],
        effects: Optional[EffectSet],
        state: Tuple[int, Optional[float], float, float, List[float]],
        status: Tuple[str, int, float, bool, int],
    ) -> "Inverse":
        """Rebuilds an inverse from the values written by ``__reduce__``."""
    def __copy__(self) -> "Inverse": ...
    def __deepcopy__(self, _memo: Dict[int, object], /) -> "Inverse": ...

def invert(
    params: Params,
    x_d: ArrayLike,
    dt: float,
    h0: float = 0.0,
    u_prev: Optional[float] = None,
    *,
    u_min: Optional[float] = None,
    u_max: Optional[float] = None,
    effects: Optional[EffectSet] = None,
) -> Tuple[NDArray[np.float64], float]:
    """The voltages u [V] that make the model produce x_d [µm]; returns ``(u, h_final)``.

    ``simulate(params, u, dt, h0)`` returns x_d wherever the root lies within the
    limits [V]. ``u_prev=v`` [V] starts the first interval at v, so a record can be
    inverted in chunks (as ``simulate``). With ``effects`` the extended model is
    inverted (a delay of d samples by reading x_d d samples ahead; ``u_prev`` is then
    not accepted). Releases the GIL.
    """

class _CompensatorStatus(TypedDict):
    """``Compensator.status``: what the last step did."""

    clip: _Clip
    evaluations: int
    residual_um: float
    exact: bool
    clipped_samples: int
    samples: int
    """Calls since construction."""
    prediction_um: float
    """The identifier's prediction of the measured sample [µm] (NaN: none)."""
    error_um: float
    """x_d − x_meas of the previous sample [µm] (NaN: no measurement)."""
    feedback_um: float
    """Feedback correction v [µm]."""
    command_um: float
    """What the inverse was asked for, x_d + v (v alone without feedforward) [µm]."""
    in_step: bool
    """The identifier has seen every voltage (no measurement missing so far)."""
    estimates_held: bool
    """This sample's estimates were not admissible (x(u) not rising by at least
    0.1·kv on both branches): the inverse kept the last admissible ones, with its
    offset following the identifier's output."""
    held_samples: int
    """Samples whose estimates were held."""

class _CompensatorGains(TypedDict):
    """``Compensator.gains``."""

    kp: float
    """Proportional gain [-]."""
    ki: float
    """Integral gain [1/s]."""
    kd: float
    """Derivative gain [s]."""
    derivative_filter_hz: float
    """Corner of the derivative's first-order filter [Hz]."""
    integral_limit_um: Optional[float]
    """Largest |integral term| [µm] (None: none)."""
    feedforward: bool
    """x_d is fed forward through the inverse."""

@final
class Compensator:
    """Adaptive hysteresis compensator for a control loop: ``u = step(x_d, x_meas)``.

    Each call takes the desired displacement x_d [µm] of this sample and the
    measurement x_meas [µm] of the previous output (None on the first call, or when
    none arrived) and returns the voltage u [V] to apply now. With a measurement, the
    online identifier ("rpem", default configuration, started from ``params`` and
    ``h0``) takes (u_prev, x_meas) and the inverse takes its estimates and h
    (``adapt=True``); the feedback v = kp·e + ki·∫e dt + kd·ė [µm] acts on e = x_d,prev
    − x_meas (kp [-], ki [1/s], kd [s]; the derivative through a first-order filter
    at ``derivative_filter_hz`` [Hz]; |∫| ≤ ``integral_limit_um`` [µm]; no
    integration toward a limit that bound). Then u = inverse(x_d + v), within
    [``u_min``, ``u_max``] [V]; ``feedforward=False`` gives u = inverse(v).
    Estimates under which x(u) would not rise on both branches are not used (see
    ``status``). A non-finite value raises ``ValueError`` and changes nothing.
    """

    def __new__(
        cls,
        params: Params,
        dt: float,
        *,
        h0: float = 0.0,
        u_min: Optional[float] = None,
        u_max: Optional[float] = None,
        adapt: bool = True,
        kp: float = 0.0,
        ki: float = 0.0,
        kd: float = 0.0,
        derivative_filter_hz: float = 1000.0,
        integral_limit_um: Optional[float] = None,
        feedforward: bool = True,
    ) -> "Compensator": ...
    def step(self, x_d: float, x_meas: Optional[float] = None) -> float:
        """Takes x_d [µm] and the previous output's measurement [µm] (or None); returns u [V]."""
    @property
    def params(self) -> Params:
        """The parameters the inverse uses now (the current estimates when adapting)."""
    @property
    def h(self) -> float:
        """The inverse model's h [µm] after the last sample."""
    @property
    def dt(self) -> float:
        """Sampling interval [s]."""
    @property
    def adapt(self) -> bool:
        """Whether the estimates are updated online."""
    @property
    def gains(self) -> _CompensatorGains:
        """The feedback configuration (a new dict at each read)."""
    @property
    def status(self) -> _CompensatorStatus:
        """What the last step did (a new dict at each read)."""
    def __copy__(self) -> "Compensator": ...
    def __deepcopy__(self, _memo: Dict[int, object], /) -> "Compensator": ...
