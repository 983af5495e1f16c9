"""Type stubs for ``boucwen._core``, the compiled Rust core (re-exported by ``boucwen``).

The model (Zhu, Bian & Rui, Precision Engineering 38 (2014) 921–927)::

    x     = kv·u + x0 + h                                           (3)
    dh/dt = A·u̇ − β·|u̇|·|h|^(n−1)·h − γ·u̇·|h|^n + δ·u·sgn(u̇)        (5)

u: voltage [V]; x, h: displacement [µm]; t: time [s].

Every invalid argument or non-finite sample raises a ``ValueError`` with a
one-line message naming the offending value, of a named subclass where the core
knows the kind (``InvalidParams``, ``InvalidConfig``, ``InvalidRecord``,
``CorruptSnapshot``, ``LengthMismatch``: one per variant of the Rust ``Error``);
an argument of the wrong kind (a string or ``None`` for an array) raises
``TypeError``.

Layout of this file, one section per part of the extension, so that a new
part is one new section (and one line in ``__all__``):

- module constants
- exceptions: ``InvalidParams``, ``InvalidConfig``, ``InvalidRecord``,
  ``CorruptSnapshot``, ``LengthMismatch``
- parameters: ``Params``
- simulation: ``simulate``, ``paper_input``, ``Model``
- online identification: ``_IdentifierMethod`` (type-only, absent at run time), ``Identifier``
  (its ``status`` a frozen ``PaperStatus``, ``RpemStatus`` or ``HorizonStatus`` of
  :mod:`boucwen.status`)
- effects: ``_CreepParams`` … ``_EffectParams`` (type-only: the dicts ``EffectSet``
  takes and gives), ``EffectSet``, ``ExtendedState``, ``simulate_extended``,
  ``simulate_extended_with_jacobian``
- channels: ``Bank``
- compensation: ``_Clip``, ``_InverseStatus``, ``_CompensatorStatus``,
  ``_CompensatorGains`` (type-only), ``Inverse``, ``invert``, ``Compensator``
- the hysteretic oscillator (a second model class): ``OSCILLATOR_UNKNOWNS``,
  ``oscillator_simulate``, ``oscillator_simulate_with_jacobian``
"""

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, ClassVar, Literal, TypedDict, final, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:  # type-only: the compiled core does not import the config module
    from .config import HorizonConfig, PaperConfig, RpemConfig
    from .status import HorizonStatus, PaperStatus, RpemStatus

__all__ = [
    "INVERSE_TOLERANCE_UM",
    "OSCILLATOR_UNKNOWNS",
    "RESONANCE_SUBSTEPS",
    "Bank",
    "Compensator",
    "CorruptSnapshot",
    "EffectSet",
    "ExtendedState",
    "Identifier",
    "InvalidConfig",
    "InvalidParams",
    "InvalidRecord",
    "Inverse",
    "LengthMismatch",
    "Model",
    "Params",
    "__version__",
    "_config_defaults",
    "_substep_plan",
    "_validate_config",
    "invert",
    "oscillator_simulate",
    "oscillator_simulate_with_jacobian",
    "paper_input",
    "simulate",
    "simulate_extended",
    "simulate_extended_with_jacobian",
    "simulate_many",
]

# ---------------------------------------------------------------- module constants

__version__: str
"""Version of the compiled core (the crate version)."""

INVERSE_TOLERANCE_UM: float
"""The inverse's tolerance on |model x − x_d| [µm] per µm of max(1 µm, |x_d|): 1e-7, a
tenth of a picometre, a thousand times below the best capacitive sensors' resolution."""

RESONANCE_SUBSTEPS: int
"""Sub-intervals per sample interval on which :func:`simulate_extended` runs the whole
chain when a resonance (or a second one) is present: such a pass costs about that many
times one without."""

# ---------------------------------------------------------------- exceptions

class InvalidParams(ValueError):
    """A model or effect parameter is out of its domain (non-finite, n <= 0, an unknown
    or missing name, a wrong count); raised before anything is built or changed."""

class InvalidConfig(ValueError):
    """A configuration value is invalid: the sampling interval dt [s], a window length, a
    tuning option of HorizonConfig/RpemConfig/PaperConfig, a channel count, an option of
    fit or diagnose."""

class InvalidRecord(ValueError):
    """A record or signal cannot be used: a NaN or infinite sample (rejected; an
    identifier's state is kept), an array not 1-D or empty, u and x of different
    lengths, a CSV file or column that cannot be read."""

class CorruptSnapshot(ValueError):
    """Snapshot bytes (a pickled Model, Identifier, Inverse...) are truncated, foreign or
    corrupt; nothing is built from them."""

class LengthMismatch(ValueError):
    """Two arrays handed to the core that must have the same length do not (creep gains
    and time constants, a bank frame and the channel count, u and x of push_many)."""

# ---------------------------------------------------------------- parameters

@final
class Params:
    """Parameters of the asymmetric Bouc–Wen model (eqs. 3 and 5).

    kv [µm/V], x0 [µm], A [µm/V], beta and gamma [µm^(1−n)/V], n [-] (> 0),
    delta [µm/(V·s)]. Immutable and hashable; ``repr`` round-trips; pickles.
    Building one with a non-finite value or n ≤ 0 raises ``InvalidParams``
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
    def check_admissible(self) -> None:
        """Raises ``InvalidParams`` (one line naming the combination and its value) unless
        the parameters are in the admissible region, where h stays bounded: β + γ ≥ 0
        and β − γ ≥ 0, both > 0 where δ ≠ 0 (docs/design.md, "The admissible region")."""
    def to_array(self) -> NDArray[np.float64]:
        """``[kv, x0, A, beta, gamma, n, delta]`` as a new float64 array."""
    @staticmethod
    def from_array(values: ArrayLike) -> Params:
        """Inverse of :meth:`to_array` (7 values); ``InvalidParams`` naming an invalid parameter."""
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
    u_prev=u[k-1])`` continues a record split at k as one call would (as
    ``scipy.signal.lfilter(..., zi)``), to the last bits: |h|^n, carried from
    sample to sample, is computed afresh at the cut (:class:`Model` continues bit
    for bit). A non-finite sample raises
    ``ValueError`` before anything is computed. Releases the GIL.
    """

def simulate_many(params: Sequence[Params], u: ArrayLike, dt: float, h0: float = 0.0) -> NDArray[np.float64]:
    """The model of each parameter set simulated over the same voltage ``u`` [V] from
    h[0] = ``h0`` [µm]: an array of shape ``(len(params), len(u))`` whose row i is
    ``simulate(params[i], u, dt, h0)[0]`` [µm] to the last bit. The sets are shared
    among the machine's cores with the GIL released (scoring many candidate models on
    one record). A non-finite sample raises :class:`InvalidRecord` before anything
    runs.
    """

def paper_input(
    dt: float, tail_s: float = 0.05, *, segments: list[tuple[float, float]] | None = None
) -> NDArray[np.float64]:
    """The paper's input u = 50 + 50·sin(2πft − π/2) [V] sampled every ``dt`` [s].

    f = 1 Hz for t < 3 s, 10 Hz to 3.3 s, 100 Hz to 3.33 s, then 200 Hz for
    ``tail_s`` [s]; each switch falls on a minimum (u = 0). ``segments``:
    (frequency [Hz], duration [s]) pairs in place of the paper's four (``tail_s`` is
    then not used), each a whole number of periods (``ValueError`` otherwise). The
    record has round(T/dt) samples, T the total duration, at t = k·dt from 0.
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

_IdentifierMethod = Literal["horizon", "rpem", "paper"]
_RefineMode = Literal["sync", "cooperative", "background"]
"""The online methods: ``Identifier.horizon`` (the default), ``Identifier.rpem`` and ``Identifier.paper``."""

def _config_defaults(method: _IdentifierMethod) -> dict[str, Any]:
    """Default options of a method's config (``boucwen.config`` takes them from here)."""

def _substep_plan(params: ArrayLike, h: ArrayLike, u: ArrayLike, dt: float) -> NDArray[np.int64]:
    """The integrator's plan of each interval u[k] → u[k+1] [V] from h[k] [µm] with the
    parameters of row k of ``params`` (kv, x0, A, β, γ, n, δ per interval, flattened):
    the RK4 sub-steps, 0 where u holds, −1 where the implicit path is taken."""

def _validate_config(method: _IdentifierMethod, config: object) -> None:
    """``InvalidConfig`` naming the offending option of a method's config object."""

@final
class Identifier:
    """Online identifier of the asymmetric Bouc–Wen model, one sample at a time.

    ``push(u, x)`` takes a voltage u [V] and a measured displacement x [µm] and
    returns the model's displacement [µm] for that sample, predicted with the
    estimates from *before* the sample and with the model's own simulated h;
    then it updates the estimates. A non-finite sample raises ``InvalidRecord``
    and leaves the identifier exactly as it was.

    One constructor per method, each with its own frozen config class:

    - ``Identifier(dt, init, h0=0.0, *, config=None, effects=None)``: the recommended
      model, horizon with an input lag identified along (the amplifier's bandwidth,
      starting at fc = 0.3/dt; ``effects`` overrides it, ``EffectSet()`` for the base
      model alone);
    - ``Identifier.horizon(dt, init, h0=0.0, *, config=None, effects=None)``: moving-horizon
      output-error least squares over a window measured in input travel, one
      Levenberg–Marquardt step per pass, the work spread evenly over the samples;
      ``config`` a :class:`boucwen.HorizonConfig`; ``effects`` an :class:`EffectSet`
      with an ``input_lag`` whose fc is identified too (default none);
    - ``Identifier.rpem(dt, init, h0=0.0, *, config=None, effects=None)``: recursive
      prediction-error method on the model's output error, sensitivities ∂h/∂θ
      propagated through the integrator; ``config`` a :class:`boucwen.RpemConfig`;
      ``effects`` an :class:`EffectSet` (e.g. from ``boucwen.diagnose``) whose
      ``input_lag`` fc and ``creep`` gains are identified too (creep time constants
      fixed, at most 4 elements, other effects rejected; with creep the default
      config has ``offset_walk_um = 0``);
    - ``Identifier.paper(dt, window, init, h0=0.0, *, config=None)``: the paper's
      limited-memory RLS and least-squares sub-fits over the newest ``window`` samples
      (16 to 10 000 000); ``config`` a :class:`boucwen.PaperConfig`.

    ``dt`` sampling interval [s]; ``init`` starting parameters (e.g. an offline fit,
    used as given); ``h0`` initial h [µm].

    ``refine`` (horizon only) says where the window pass runs: ``"sync"`` (the
    default: a share of it in every push; deterministic, the predictions of earlier
    releases bit for bit), ``"cooperative"`` (``push`` only predicts and stores; the
    pass runs in :meth:`refine`, called when the loop has time; deterministic for a
    given schedule of calls) or ``"background"`` (a worker thread owned by the
    identifier runs it and ``push`` never waits on it; not deterministic).
    """

    def __new__(
        cls,
        dt: float,
        init: Params,
        h0: float = 0.0,
        *,
        config: HorizonConfig | None = None,
        effects: EffectSet | None = None,
        refine: _RefineMode = "sync",
    ) -> Identifier: ...
    @staticmethod
    def horizon(
        dt: float,
        init: Params,
        h0: float = 0.0,
        *,
        config: HorizonConfig | None = None,
        effects: EffectSet | None = None,
        refine: _RefineMode = "sync",
    ) -> Identifier:
        """The moving-horizon output-error method ("horizon")."""
    @staticmethod
    def rpem(
        dt: float,
        init: Params,
        h0: float = 0.0,
        *,
        config: RpemConfig | None = None,
        effects: EffectSet | None = None,
    ) -> Identifier:
        """The output-error method ("rpem")."""
    @staticmethod
    def paper(
        dt: float,
        window: int,
        init: Params,
        h0: float = 0.0,
        *,
        config: PaperConfig | None = None,
    ) -> Identifier:
        """The paper's method over a window of ``window`` samples."""
    @property
    def effects(self) -> EffectSet | None:
        """Current effect estimates (fc [Hz], creep gains [µm/V]) of rpem and horizon (an
        empty EffectSet without effects); None for the paper's method."""
    def forecast(self, u: ArrayLike) -> NDArray[np.float64]:
        """Open-loop x̂ [µm] for the future voltages ``u`` [V]: the current estimates and
        state (effects included) simulated on from the last sample pushed. The
        identifier does not change; ``InvalidRecord`` on a non-finite ``u``."""
    def push(self, u: float, x: float) -> float:
        """Takes one sample, u [V] and measured x [µm]; returns the predicted x [µm]."""
    def refine(self, max_intervals: int) -> int:
        """Cooperative mode: runs the window pass at most ``max_intervals`` integration
        intervals on the samples pushed so far (GIL released); an update is adopted
        here and the next push predicts with it. Returns the intervals run (0: nothing
        to do until more samples come, and always in the other modes and methods)."""
    @property
    def refine_mode(self) -> _RefineMode | None:
        """Where the horizon method's window pass runs; None for the other methods."""
    def push_many(self, u: ArrayLike, x: ArrayLike) -> NDArray[np.float64]:
        """``push`` over arrays with the GIL released; predictions [µm] identical to a
        loop of ``push``. A non-finite value anywhere raises ``InvalidRecord`` before any
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
    def config(self) -> HorizonConfig | RpemConfig | PaperConfig:
        """The configuration in use, as the method's frozen config object (equal to the one
        given; the method's defaults when none was; the paper's window is ``window``)."""
    @property
    def window(self) -> int | None:
        """The paper method's window N [samples]; None for the other methods."""
    @property
    def status(self) -> PaperStatus | RpemStatus | HorizonStatus:
        """What the last push did, the method's own report: a frozen ``PaperStatus``,
        ``RpemStatus`` or ``HorizonStatus`` of :mod:`boucwen.status` (a new one at each read)."""
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

class _GainDriftParams(TypedDict):
    """``gain_drift``: kv(t) = kv·(1 + r·t), relative rate r [1/s]."""

    rate_per_s: float

class _ElectrostrictionParams(TypedDict):
    """``electrostriction``: s = kv·u_a + h becomes s + ε·s², ε [1/µm]."""

    epsilon_per_um: float

class _PickupParams(TypedDict):
    """``pickup``: line frequency [Hz], sine and cosine amplitudes of harmonics 1 … K [µm]."""

    line_hz: float
    sin_um: list[float]
    cos_um: list[float]

class _SaturationParams(TypedDict):
    """``saturation``: the sensor's range [µm]."""

    min_um: float
    max_um: float

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
    gain_drift: _GainDriftParams
    electrostriction: _ElectrostrictionParams
    resonance: _ResonanceParams
    resonance2: _ResonanceParams
    drift: _DriftParams
    delay: _DelayParams
    pickup: _PickupParams
    saturation: _SaturationParams

@final
class Bank:
    """C independent channels, each an online identifier, a model and an inverse of the
    model, stepped with one call per frame (adaptive optics, multi-axis stages).

    - ``Bank(channels, dt, init, h0=0.0, *, config=None)``: rpem channels (as ``Bank.rpem``);
    - ``Bank.paper(channels, dt, window, init, h0=0.0, *, config=None)``.

    Every channel starts from ``init`` and ``h0`` [µm] and learns on its own; its
    results are bit for bit those of a single :class:`Identifier` (and :class:`Model`)
    fed the same samples. A frame or call with a non-finite value raises
    ``ValueError`` before any channel changes.
    """

    def __new__(
        cls, channels: int, dt: float, init: Params, h0: float = 0.0, *, config: RpemConfig | None = None
    ) -> Bank: ...
    @staticmethod
    def rpem(channels: int, dt: float, init: Params, h0: float = 0.0, *, config: RpemConfig | None = None) -> Bank:
        """A bank of rpem channels."""
    @staticmethod
    def paper(
        channels: int,
        dt: float,
        window: int,
        init: Params,
        h0: float = 0.0,
        *,
        config: PaperConfig | None = None,
    ) -> Bank:
        """A bank of channels of the paper's method over ``window`` samples."""
    @property
    def channels(self) -> int:
        """The number of channels C."""
    @property
    def method(self) -> _IdentifierMethod:
        """The online method of every channel."""
    def push(self, u: ArrayLike, x: ArrayLike) -> NDArray[np.float64]:
        """One frame: C voltages [V] and C measurements [µm]; returns C predictions [µm]."""
    def push_many(self, u: ArrayLike, x: ArrayLike) -> NDArray[np.float64]:
        """T frames, u and x of shape (T, C); returns (T, C) predictions [µm] (GIL released)."""
    def step_models(self, u: ArrayLike) -> NDArray[np.float64]:
        """One frame for the models: C voltages [V] in, C displacements [µm] out."""
    def step_models_many(self, u: ArrayLike) -> NDArray[np.float64]:
        """T frames for the models: u of shape (T, C) [V]; returns (T, C) displacements [µm]."""
    def adopt_estimates(self) -> None:
        """Every model takes its identifier's current estimates, and every inverse too where
        they keep x(u) rising (states kept)."""
    def feedforward(self, x_d: ArrayLike) -> NDArray[np.float64]:
        """One frame of feedforward: C desired displacements [µm] in, the C voltages [V] at
        which each channel's inverse model reaches them out."""
    def set_voltage_limits(self, u_min: float | None = None, u_max: float | None = None) -> None:
        """Voltage limits [V] of every channel's inverse (None: no limit on that side)."""
    def inverse_params(self, channel: int) -> Params:
        """The parameters of channel ``channel``'s inverse."""
    def params(self, channel: int) -> Params:
        """The current estimates of channel ``channel``'s identifier."""
    def model_params(self, channel: int) -> Params:
        """The parameters of channel ``channel``'s model."""
    def reset(self) -> None:
        """Every identifier and model back to its state right after construction."""

@final
class EffectSet:
    """Which effects surround the base model, with their parameters (see boucwen.effects).

    creep={"tau_s": [s…], "gain_um_per_v": [µm/V…]}, input_lag={"fc_hz": Hz},
    gain_drift={"rate_per_s": 1/s}, electrostriction={"epsilon_per_um": 1/µm},
    resonance={"fn_hz": Hz, "zeta": -}, resonance2={"fn_hz": Hz, "zeta": -},
    drift={"rate_um_per_s": µm/s}, delay={"samples": int ≥ 0},
    pickup={"line_hz": Hz, "sin_um": [µm…], "cos_um": [µm…]},
    saturation={"min_um": µm, "max_um": µm}; None = absent. Invalid values raise ValueError.
    Typed: boucwen.effect_set(InputLag(650.0), …) and boucwen.effects_of(s)."""

    vocabulary: ClassVar[list[str]]
    def __new__(
        cls,
        *,
        creep: _CreepParams | None = None,
        input_lag: _InputLagParams | None = None,
        gain_drift: _GainDriftParams | None = None,
        electrostriction: _ElectrostrictionParams | None = None,
        resonance: _ResonanceParams | None = None,
        resonance2: _ResonanceParams | None = None,
        drift: _DriftParams | None = None,
        delay: _DelayParams | None = None,
        pickup: _PickupParams | None = None,
        saturation: _SaturationParams | None = None,
    ) -> EffectSet: ...
    @property
    def names(self) -> list[str]:
        """Names of the effects present, in vocabulary order."""
    def to_dict(self) -> _EffectParams: ...
    @staticmethod
    def from_dict(d: _EffectParams) -> EffectSet: ...
    def __len__(self) -> int: ...
    def __contains__(self, key: object, /) -> bool: ...

@final
class ExtendedState:
    """The state of the extended chain between two samples: what
    ``simulate_extended(..., state=s)`` continues from and returns.

    ``ExtendedState(h0=0.0)`` is the state before any sample, h = ``h0`` [µm]; the state
    after a piece of record comes from :func:`simulate_extended`. Immutable, comparable,
    picklable. It holds one value per creep element and the delay line, so it fits the
    effects that made it (others raise ``ValueError``).
    """

    def __new__(cls, h0: float = 0.0) -> ExtendedState: ...
    @property
    def samples(self) -> int:
        """Samples taken so far; the next one is at t = samples·dt [s]."""
    @property
    def u_prev(self) -> float | None:
        """Commanded voltage of the last sample [V] (None: no sample yet)."""
    @property
    def ua(self) -> float:
        """Voltage on the stack after the last sample [V] (the input lag's output)."""
    @property
    def h(self) -> float:
        """Hysteresis state h [µm]."""
    @property
    def creep(self) -> list[float]:
        """The creep elements c_i [µm], in the order of the creep's time constants."""
    @property
    def y(self) -> float:
        """The stack's displacement at the last sample [µm]."""
    @property
    def resonance(self) -> tuple[float, float]:
        """The first mode's (z [µm], ż [µm/s])."""
    @property
    def resonance2(self) -> tuple[float, float]:
        """The second mode's (z [µm], ż [µm/s])."""
    @property
    def delay(self) -> list[float]:
        """The delay line's d + 1 values [µm], oldest first (empty before the first sample)."""
    def __eq__(self, value: object, /) -> bool: ...
    def __ne__(self, value: object, /) -> bool: ...
    def __reduce__(
        self,
    ) -> tuple[
        object,
        tuple[
            int,
            float | None,
            float,
            float,
            tuple[float, float] | None,
            list[float],
            float,
            tuple[float, float],
            tuple[float, float],
            list[float],
        ],
    ]: ...
    @classmethod
    def _restore(
        cls,
        samples: int,
        u_prev: float | None,
        ua: float,
        h: float,
        h_pow_n: tuple[float, float] | None,
        creep: list[float],
        y: float,
        resonance: tuple[float, float],
        resonance2: tuple[float, float],
        delay: list[float],
    ) -> ExtendedState:
        """Rebuilds a state from the values written by ``__reduce__`` (``ValueError`` if invalid)."""

@overload
def simulate_extended(
    params: Params, effects: EffectSet | None, u: ArrayLike, dt: float, h0: float = 0.0, *, state: None = None
) -> NDArray[np.float64]: ...
@overload
def simulate_extended(
    params: Params, effects: EffectSet | None, u: ArrayLike, dt: float, h0: float = 0.0, *, state: ExtendedState
) -> tuple[NDArray[np.float64], ExtendedState]:
    """x [µm] of the base model with effects: u → input_lag → (Bouc–Wen with gain_drift
    and electrostriction, + creep) → resonance → resonance2 → + drift → delay → + pickup
    → saturation; u [V] piecewise linear between samples ``dt`` [s] apart, h0 [µm].

    With ``state`` (an :class:`ExtendedState`; ``ExtendedState(h0)`` starts a record)
    the chain continues from it (``h0`` must then be left at 0: the state holds h) and
    the call returns ``(x, final_state)``, as ``scipy.signal.lfilter`` does with
    ``zi``: a record simulated in pieces, each from the state the previous one
    returned, is the record simulated in one call, bit for bit. GIL released."""

def simulate_extended_with_jacobian(
    params: Params, effects: EffectSet | None, u: ArrayLike, dt: float, h0: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`simulate_extended` with the Jacobian, in one pass; returns ``(x, jac)``: x
    [µm] as :func:`simulate_extended` gives it and ``jac[k, j]`` = ∂x[k]/∂θ_j, one column
    per unknown: kv, x0, A, β, γ, n, δ, h0, then for each effect present in signal-chain
    order the creep gains, the input lag's ln fc, the gain_drift rate, the
    electrostriction ε, the resonance's ln fn and ln ζ, the second resonance's ln fn and
    ln ζ, the drift rate, the pickup's sine then cosine amplitudes, the saturation's min
    and max (the creep time constants and the delay are fixed). GIL released."""

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
    """|residual| ≤ INVERSE_TOLERANCE_UM·max(1, |x_d|) µm."""
    samples: int
    """Samples since construction or reset."""
    clipped_samples: int
    """Samples clipped since construction or reset."""

@final
class Inverse:
    """The inverse of the asymmetric Bouc–Wen model, one sample at a time: ``step(x_d) -> u``.

    Solves kv·u + x0 + Φ(h, u_prev → u) = x_d [µm] for u [V] with the model's own
    integrator Φ, so ``simulate`` on the voltages returns x_d (to
    ``INVERSE_TOLERANCE_UM``·max(1, |x_d|) µm) wherever the root lies within
    [``u_min``, ``u_max``] [V]; where a limit binds the sample is clipped,
    ``status["clip"]`` says which, and h [µm] follows the clipped u. Where x_d turns
    by less than |δ·u|·dt in a sample, no voltage reaches it exactly and the residual
    (at most that step) is reported. Newton with a secant slope, then Illinois inside
    a bracket: at most 40 evaluations of Φ per sample.

    ``effects``: an :class:`EffectSet` whose ``input_lag`` (exact one-sample lead),
    ``creep``, ``gain_drift`` (kv(t)), ``electrostriction`` (the quadratic stroke),
    ``drift`` and ``delay`` (the reference is then read ``delay`` samples ahead:
    ``step`` takes x_d of sample k + d) are inverted too; ``pickup`` and
    ``saturation`` (in the reading only) are ignored; a ``resonance`` or
    ``resonance2`` raises ``ValueError``. Pickles and copies with its state.
    """

    def __new__(
        cls,
        params: Params,
        dt: float,
        h0: float = 0.0,
        u_min: float | None = None,
        u_max: float | None = None,
        *,
        effects: EffectSet | None = None,
    ) -> Inverse: ...
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
    def effects(self) -> EffectSet | None:
        """The effects inverted along with the base model (None: none)."""
    @property
    def h(self) -> float:
        """Hysteresis state h [µm] after the last sample."""
    @property
    def dt(self) -> float:
        """Sampling interval [s]."""
    @property
    def u_min(self) -> float | None:
        """Lower voltage limit [V] (None: none)."""
    @property
    def u_max(self) -> float | None:
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
    ) -> tuple[
        object,
        tuple[
            Params,
            float,
            float,
            float | None,
            float | None,
            EffectSet | None,
            tuple[int, float | None, float, float, list[float]],
            tuple[str, int, float, bool, int],
        ],
    ]: ...
    @classmethod
    def _restore(
        cls,
        params: Params,
        dt: float,
        h0: float,
        u_min: float | None,
        u_max: float | None,
        effects: EffectSet | None,
        state: tuple[int, float | None, float, float, list[float]],
        status: tuple[str, int, float, bool, int],
    ) -> Inverse:
        """Rebuilds an inverse from the values written by ``__reduce__``."""
    def __copy__(self) -> Inverse: ...
    def __deepcopy__(self, _memo: dict[int, object], /) -> Inverse: ...

def invert(
    params: Params,
    x_d: ArrayLike,
    dt: float,
    h0: float = 0.0,
    u_prev: float | None = None,
    *,
    u_min: float | None = None,
    u_max: float | None = None,
    effects: EffectSet | None = None,
) -> tuple[NDArray[np.float64], float]:
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
    integral_limit_um: float | None
    """Largest |integral term| [µm] (None: none)."""
    feedforward: bool
    """x_d is fed forward through the inverse."""

@final
class Compensator:
    """Adaptive hysteresis compensator for a control loop: ``u = step(x_d, x_meas)``.

    Each call takes the desired displacement x_d [µm] of this sample and the
    measurement x_meas [µm] of the previous output (None on the first call, or when
    none arrived) and returns the voltage u [V] to apply now. With a measurement, the
    online identifier (``identifier``, started from ``params`` and ``h0``) takes
    (u_prev, x_meas) and the inverse takes its estimates and h (``adapt=True``); the
    feedback v = kp·e + ki·∫e dt + kd·ė [µm] acts on e = x_d,prev − x_meas (kp [-],
    ki [1/s], kd [s]; the derivative through a first-order filter at
    ``derivative_filter_hz`` [Hz]; |∫| ≤ ``integral_limit_um`` [µm]; no
    integration toward a limit that bound). Then u = inverse(x_d + v), within
    [``u_min``, ``u_max``] [V]; ``feedforward=False`` gives u = inverse(v).
    Estimates under which x(u) would not rise on both branches are not used (see
    ``status``). A non-finite value raises ``ValueError`` and changes nothing.

    ``identifier``: "rpem" (default, tuned for tracking) or "horizon" (the recommended
    identifier, ``Identifier(dt, params, h0)``: its input lag is identified too and the
    inverse runs through it). ``refine`` (horizon only): where its window pass runs,
    "sync", "cooperative" (call ``refine(max_intervals)`` when the loop has time) or
    "background" (a worker thread), as for :class:`Identifier`.
    """

    def __new__(
        cls,
        params: Params,
        dt: float,
        *,
        h0: float = 0.0,
        u_min: float | None = None,
        u_max: float | None = None,
        adapt: bool = True,
        kp: float = 0.0,
        ki: float = 0.0,
        kd: float = 0.0,
        derivative_filter_hz: float = 1000.0,
        integral_limit_um: float | None = None,
        feedforward: bool = True,
        identifier: Literal["rpem", "horizon"] = "rpem",
        refine: _RefineMode = "sync",
    ) -> Compensator: ...
    def step(self, x_d: float, x_meas: float | None = None) -> float:
        """Takes x_d [µm] and the previous output's measurement [µm] (or None); returns u [V]."""
    def refine(self, max_intervals: int) -> int:
        """Cooperative mode: runs the identifier's window pass at most ``max_intervals``
        integration intervals; returns the intervals run (0 in other modes and for rpem)."""
    @property
    def identifier(self) -> Literal["rpem", "horizon"]:
        """The online identifier."""
    @property
    def refine_mode(self) -> _RefineMode | None:
        """Where the horizon identifier's window pass runs; None for rpem."""
    @property
    def effects(self) -> EffectSet | None:
        """The effects the inverse runs through (the identified input lag); None for the base inverse."""
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
    def __copy__(self) -> Compensator: ...
    def __deepcopy__(self, _memo: dict[int, object], /) -> Compensator: ...

# ---------------------------------------------------------------- hysteretic oscillator
#
# m·ÿ + c·ẏ + k·y + z = F,  ż = α·ẏ − β·(γ·|ẏ|·|z|^(ν−1)·z + δ·ẏ·|z|^ν)
# F [N], y [m], z [N]; params in the order m [kg], c [N·s/m], k [N/m], alpha [N/m],
# beta [N^(1−ν)/m], gamma [-], delta [-], nu [-] (boucwen.oscillator.OscillatorParams).

OSCILLATOR_UNKNOWNS: list[str]
"""The columns of :func:`oscillator_simulate_with_jacobian`'s Jacobian: m, c, k, alpha,
gamma, delta, nu, y0, v0, z0 (β has none: it enters only as β·γ and β·δ)."""

def oscillator_simulate(
    params: Sequence[float],
    force: ArrayLike,
    dt: float,
    y0: float = 0.0,
    v0: float = 0.0,
    z0: float = 0.0,
) -> NDArray[np.float64]:
    """The displacement y [m] of the hysteretic oscillator driven by ``force`` [N] (linear
    between samples ``dt`` [s] apart) from the state (y0 [m], v0 [m/s], z0 [N]) at sample 0.

    Raises:
        InvalidParams: not 8 parameters, or one out of its domain (named).
        InvalidRecord: a non-finite force sample or initial state.
        InvalidConfig: dt not finite and > 0.
    """

def oscillator_simulate_with_jacobian(
    params: Sequence[float],
    force: ArrayLike,
    dt: float,
    y0: float = 0.0,
    v0: float = 0.0,
    z0: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(y, jac)``: :func:`oscillator_simulate` and ∂y/∂θ of shape (samples, 10), θ =
    :data:`OSCILLATOR_UNKNOWNS`, from one forward-mode pass with the same sub-steps."""
