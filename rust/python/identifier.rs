//! `boucwen.Identifier`: streaming online identification, one constructor per method.

use numpy::PyArray1;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple, PyType};

use super::config::{config_object, horizon_config, horizon_slots, paper_config, paper_slots, rpem_config, rpem_slots};
use super::effects::PyEffectSet;
use super::params::PyParams;
use super::{samples, value_error, InvalidConfig};
use crate::effects::EffectSet;
use crate::identify::{
    AnyIdentifier, AnyStatus, BackgroundHorizon, HorizonIdentifier, OnlineIdentifier, PaperIdentifier, RefineMode,
    RpemConfig, RpemIdentifier, StepStatus,
};

/// Online identifier of the asymmetric Bouc–Wen model, one sample at a time.
///
/// `push(u, x)` takes a voltage u \[V\] and a measured displacement x \[µm\] and
/// returns the model's displacement \[µm\] for that sample, predicted with the
/// estimates from *before* the sample and with the model's own simulated h; then
/// it updates the estimates. A non-finite sample raises InvalidRecord and leaves
/// the identifier exactly as it was.
///
/// Constructors, one per method:
///
/// - `Identifier(dt, init, h0=0.0, *, config=None, effects=None)`: the recommended
///   model, "horizon" with an input lag identified along (the amplifier's bandwidth,
///   starting at fc = 0.3/dt; `effects` overrides it, `EffectSet()` for the base model
///   alone). The lag is read from `effects`; `forecast` simulates with it.
/// - `Identifier.horizon(dt, init, h0=0.0, *, config=None, effects=None)`: moving-horizon
///   output-error least squares over a window measured in input travel, one
///   Levenberg–Marquardt step per pass, the work spread evenly over the samples;
///   `config` a `HorizonConfig`; `effects` an `EffectSet` with an `input_lag` whose fc
///   is identified too (default: none).
/// - `Identifier.rpem(dt, init, h0=0.0, *, config=None, effects=None)`: recursive
///   prediction-error method on the model's output (simulation) error, sensitivities
///   ∂h/∂θ propagated through the integrator. `config` an `RpemConfig`; `effects` an
///   `EffectSet` (e.g. from `boucwen.diagnose`) whose `input_lag` fc and `creep` gains
///   are identified too (with creep, the default config has `offset_walk_um = 0`).
/// - `Identifier.paper(dt, window, init, h0=0.0, *, config=None)`: the paper's
///   limited-memory RLS with least-squares sub-fits over the newest `window` samples;
///   `config` a `PaperConfig`.
///
/// `dt` sampling interval \[s\]; `init` starting parameters (e.g. an offline fit, used
/// as given); `h0` initial h \[µm\].
///
/// `refine` (horizon only) says where the window pass runs: "sync" (the default: a
/// share of it in every push, deterministic, the predictions of earlier releases bit
/// for bit), "cooperative" (`push` only predicts and stores; the pass runs in
/// `ident.refine(max_intervals)`, called when the loop has time; deterministic for a
/// given schedule of calls) or "background" (a worker thread owned by the identifier
/// runs it; `push` never waits on it; not deterministic).
#[pyclass(name = "Identifier", module = "boucwen")]
pub struct PyIdentifier {
    inner: Inner,
}

/// An online identifier, or the horizon method with its pass on a worker thread (held
/// inline as `AnyIdentifier` holds its methods: no indirection in `push`).
#[allow(clippy::large_enum_variant)]
enum Inner {
    Any(AnyIdentifier),
    Background(BackgroundHorizon),
}

/// What `__reduce__` returns: the restoring class method and its arguments (the
/// snapshot, and "background" for an identifier whose worker is to restart).
type Reduced<'py> = (Bound<'py, PyAny>, Bound<'py, PyTuple>);

/// Runs `$body` with `$id` bound to the identifier, whichever it is.
macro_rules! with_id {
    ($inner:expr, $id:ident => $body:expr) => {
        match $inner {
            Inner::Any($id) => $body,
            Inner::Background($id) => $body,
        }
    };
}

impl Inner {
    fn status(&self) -> AnyStatus {
        match self {
            Inner::Any(id) => id.status(),
            Inner::Background(id) => AnyStatus::Horizon(id.status()),
        }
    }
    fn method(&self) -> &'static str {
        match self {
            Inner::Any(id) => id.method(),
            Inner::Background(_) => "horizon",
        }
    }
    fn refine_mode(&self) -> Option<&'static str> {
        match self {
            Inner::Any(AnyIdentifier::Horizon(id)) => Some(id.mode().name()),
            Inner::Any(_) => None,
            Inner::Background(_) => Some("background"),
        }
    }
    fn to_snapshot(&self) -> Vec<u8> {
        match self {
            Inner::Any(id) => id.to_snapshot(),
            Inner::Background(id) => id.to_bytes(),
        }
    }
    fn try_clone(&self) -> PyResult<Self> {
        match self {
            Inner::Any(id) => Ok(Inner::Any(id.clone())),
            Inner::Background(id) => {
                Ok(Inner::Background(BackgroundHorizon::spawn(id.cooperative()).map_err(value_error)?))
            }
        }
    }
}

/// Where the horizon method's window pass runs, from its Python name.
pub(super) enum Refine {
    Mode(RefineMode),
    Background,
}

pub(super) fn refine_arg(refine: &str) -> PyResult<Refine> {
    match refine {
        "sync" => Ok(Refine::Mode(RefineMode::Sync)),
        "cooperative" => Ok(Refine::Mode(RefineMode::Cooperative)),
        "background" => Ok(Refine::Background),
        other => Err(InvalidConfig::new_err(format!(
            "invalid refine = {other:?}: expected \"sync\", \"cooperative\" or \"background\""
        ))),
    }
}

/// The horizon identifier `id` with its pass run as `refine` says.
fn horizon_inner(id: HorizonIdentifier, refine: &str) -> PyResult<Inner> {
    Ok(match refine_arg(refine)? {
        Refine::Mode(mode) => Inner::Any(AnyIdentifier::Horizon(id.with_mode(mode))),
        Refine::Background => Inner::Background(BackgroundHorizon::spawn(id).map_err(value_error)?),
    })
}

/// An integer argument; a too-large int is a ValueError (not OverflowError), a non-int a TypeError.
fn count_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<i64> {
    obj.extract::<i64>().map_err(|err| {
        if err.is_instance_of::<pyo3::exceptions::PyOverflowError>(obj.py()) {
            PyValueError::new_err(format!("invalid {name} = {obj}: too large"))
        } else {
            PyTypeError::new_err(format!(
                "{name} must be an integer, got {}",
                obj.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into())
            ))
        }
    })
}

/// The `max_intervals` argument of `refine`: an integer >= 0 (ValueError below 0).
pub(super) fn max_intervals_arg(obj: &Bound<'_, PyAny>) -> PyResult<usize> {
    let n = count_arg(obj, "max_intervals")?;
    if n < 0 {
        return Err(PyValueError::new_err(format!("invalid max_intervals = {n}: must be >= 0")));
    }
    Ok(usize::try_from(n).unwrap_or(usize::MAX))
}

/// A config object must be of the method's class (or duck-type it).
fn check_config_class(config: Option<&Bound<'_, PyAny>>, expected: &str) -> PyResult<()> {
    if let Some(c) = config {
        let name = c.get_type().name()?.to_string();
        let known = ["RpemConfig", "PaperConfig", "HorizonConfig"];
        if name != expected && known.contains(&name.as_str()) {
            return Err(PyTypeError::new_err(format!("config must be a {expected}, got a {name}")));
        }
    }
    Ok(())
}

impl PyIdentifier {
    fn build_rpem(
        dt: f64,
        init: &PyParams,
        h0: f64,
        config: Option<&Bound<'_, PyAny>>,
        effects: Option<PyRef<'_, PyEffectSet>>,
    ) -> PyResult<Self> {
        check_config_class(config, "RpemConfig")?;
        let effects = effects.map(|e| e.inner.clone()).unwrap_or_default();
        let cfg = rpem_config(config, RpemConfig::for_effects(&effects))?;
        let id = RpemIdentifier::with_effects(dt, init.inner, &effects, h0, cfg).map_err(value_error)?;
        Ok(PyIdentifier { inner: Inner::Any(AnyIdentifier::Rpem(id)) })
    }

    /// The horizon method with `effects`, or the recommended model (input lag from
    /// fc = 0.3/dt) when None.
    fn build_horizon(
        dt: f64,
        init: &PyParams,
        h0: f64,
        config: Option<&Bound<'_, PyAny>>,
        effects: Option<EffectSet>,
        refine: &str,
    ) -> PyResult<Self> {
        check_config_class(config, "HorizonConfig")?;
        refine_arg(refine)?;
        let cfg = horizon_config(config)?;
        let id = match effects {
            Some(e) => HorizonIdentifier::with_effects(dt, init.inner, &e, h0, cfg),
            None => HorizonIdentifier::recommended(dt, init.inner, h0, cfg),
        };
        Ok(PyIdentifier { inner: horizon_inner(id.map_err(value_error)?, refine)? })
    }
}

#[pymethods]
impl PyIdentifier {
    #[new]
    #[pyo3(signature = (dt, init, h0 = 0.0, *, config = None, effects = None, refine = "sync"))]
    fn new(
        dt: f64,
        init: &PyParams,
        h0: f64,
        config: Option<&Bound<'_, PyAny>>,
        effects: Option<PyRef<'_, PyEffectSet>>,
        refine: &str,
    ) -> PyResult<Self> {
        Self::build_horizon(dt, init, h0, config, effects.map(|e| e.inner.clone()), refine)
    }

    /// The output-error method ("rpem"); see the class docs.
    #[staticmethod]
    #[pyo3(signature = (dt, init, h0 = 0.0, *, config = None, effects = None))]
    fn rpem(
        dt: f64,
        init: &PyParams,
        h0: f64,
        config: Option<&Bound<'_, PyAny>>,
        effects: Option<PyRef<'_, PyEffectSet>>,
    ) -> PyResult<Self> {
        Self::build_rpem(dt, init, h0, config, effects)
    }

    /// The moving-horizon output-error method ("horizon"); see the class docs.
    #[staticmethod]
    #[pyo3(signature = (dt, init, h0 = 0.0, *, config = None, effects = None, refine = "sync"))]
    fn horizon(
        dt: f64,
        init: &PyParams,
        h0: f64,
        config: Option<&Bound<'_, PyAny>>,
        effects: Option<PyRef<'_, PyEffectSet>>,
        refine: &str,
    ) -> PyResult<Self> {
        Self::build_horizon(dt, init, h0, config, Some(effects.map(|e| e.inner.clone()).unwrap_or_default()), refine)
    }

    /// The paper's method over a window of `window` samples; see the class docs.
    #[staticmethod]
    #[pyo3(signature = (dt, window, init, h0 = 0.0, *, config = None))]
    fn paper(
        dt: f64,
        window: &Bound<'_, PyAny>,
        init: &PyParams,
        h0: f64,
        config: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        check_config_class(config, "PaperConfig")?;
        let window = count_arg(window, "window")?;
        let cfg = paper_config(config, window)?;
        let id = PaperIdentifier::new(dt, init.inner, h0, cfg).map_err(value_error)?;
        Ok(PyIdentifier { inner: Inner::Any(AnyIdentifier::Paper(id)) })
    }

    /// Takes one sample (u \[V\], x \[µm\]); returns the predicted x \[µm\] (see the class docs).
    fn push(&mut self, u: f64, x: f64) -> PyResult<f64> {
        with_id!(&mut self.inner, id => id.push(u, x)).map_err(value_error)
    }

    /// Cooperative mode: runs the window pass at most `max_intervals` integration
    /// intervals on the samples pushed so far, with the GIL released; an update is
    /// adopted here, so the next push predicts with it. Returns the intervals run (0:
    /// nothing to do until more samples come). In the other modes and methods the
    /// pass runs elsewhere (in push, or on the worker) and this returns 0.
    fn refine(&mut self, py: Python<'_>, max_intervals: &Bound<'_, PyAny>) -> PyResult<usize> {
        let n = max_intervals_arg(max_intervals)?;
        match &mut self.inner {
            Inner::Any(AnyIdentifier::Horizon(id)) => Ok(py.detach(move || id.refine(n))),
            _ => Ok(0),
        }
    }

    /// Where the horizon method's window pass runs: "sync", "cooperative" or
    /// "background"; None for the other methods.
    #[getter]
    fn refine_mode(&self) -> Option<&'static str> {
        self.inner.refine_mode()
    }

    /// `push` over arrays, with the GIL released; returns the predictions \[µm\],
    /// identical to a loop of `push`. If any value is NaN or infinite the whole call
    /// raises InvalidRecord before any sample is used (the state is unchanged).
    fn push_many<'py>(
        &mut self,
        py: Python<'py>,
        u: &Bound<'py, PyAny>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let u = samples(u, "u")?;
        let x = samples(x, "x")?;
        let inner = &mut self.inner;
        let out = py
            .detach(move || {
                let mut out = vec![0.0; u.len()];
                with_id!(inner, id => id.push_many(&u, &x, &mut out)).map(|_| out)
            })
            .map_err(value_error)?;
        Ok(PyArray1::from_vec(py, out))
    }

    /// The current parameter estimates.
    #[getter]
    fn params(&self) -> PyParams {
        PyParams { inner: with_id!(&self.inner, id => id.params()) }
    }

    /// The model's hysteresis state h \[µm\] after the last sample.
    #[getter]
    fn h(&self) -> f64 {
        with_id!(&self.inner, id => id.h())
    }

    /// The effects identified along with the parameters, with their current
    /// estimates (input_lag fc \[Hz\], creep gains \[µm/V\]; the creep time constants
    /// stay as given): an `EffectSet`, empty for "rpem" and "horizon" without effects,
    /// and None for "paper", which identifies no effects.
    #[getter]
    fn effects(&self) -> Option<PyEffectSet> {
        match &self.inner {
            Inner::Any(AnyIdentifier::Rpem(id)) => Some(PyEffectSet { inner: id.effects() }),
            Inner::Any(AnyIdentifier::Horizon(id)) => Some(PyEffectSet { inner: id.effects() }),
            Inner::Background(id) => Some(PyEffectSet { inner: id.effects() }),
            Inner::Any(AnyIdentifier::Paper(_)) => None,
        }
    }

    /// The model's open-loop displacement x̂ \[µm\] for the future voltages `u` \[V\]:
    /// the current estimates and model state (with the effects identified along)
    /// simulated on from the last sample pushed, the interval from it to `u[0]`
    /// included. Nothing changes in the identifier. InvalidRecord on a non-finite `u`.
    fn forecast<'py>(&self, py: Python<'py>, u: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let u = samples(u, "u")?;
        let mut out = vec![0.0; u.len()];
        with_id!(&self.inner, id => id.forecast_into(&u, &mut out)).map_err(value_error)?;
        Ok(PyArray1::from_vec(py, out))
    }

    /// The online method in use: "horizon", "rpem" or "paper".
    #[getter]
    fn method(&self) -> &'static str {
        self.inner.method()
    }

    /// The configuration in use, as the method's frozen config object: a
    /// `HorizonConfig`, `RpemConfig` or `PaperConfig` equal to the one given (the
    /// method's defaults when none was; the paper's window is `window`).
    #[getter]
    fn config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        match &self.inner {
            Inner::Any(AnyIdentifier::Rpem(id)) => {
                config_object(py, "RpemConfig", rpem_slots(&mut id.config().clone()))
            }
            Inner::Any(AnyIdentifier::Paper(id)) => {
                config_object(py, "PaperConfig", paper_slots(&mut id.config().clone()))
            }
            Inner::Any(AnyIdentifier::Horizon(id)) => {
                config_object(py, "HorizonConfig", horizon_slots(&mut id.config().clone()))
            }
            Inner::Background(id) => config_object(py, "HorizonConfig", horizon_slots(&mut id.config().clone())),
        }
    }

    /// The window N of the paper's method \[samples\]; None for "rpem".
    #[getter]
    fn window(&self) -> Option<usize> {
        match &self.inner {
            Inner::Any(AnyIdentifier::Paper(id)) => Some(id.config().window_len),
            _ => None,
        }
    }

    /// What the last push did, the method's own report: a frozen `PaperStatus`,
    /// `RpemStatus` or `HorizonStatus` of `boucwen.status` (a new one at each read).
    #[getter]
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        status_object(py, self.inner.status())
    }

    /// Back to the state right after construction.
    fn reset(&mut self) {
        with_id!(&mut self.inner, id => id.reset())
    }

    /// Pickle support: the identifier is saved as its byte snapshot (every value it
    /// carries between samples), so an unpickled copy continues bit for bit (sync and
    /// cooperative; a background one is saved as a cooperative one with the samples
    /// its worker had not read yet, and restored with a new worker).
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Reduced<'py>> {
        let me = slf.borrow();
        let bytes = PyBytes::new(slf.py(), &me.inner.to_snapshot());
        let restore = slf.get_type().getattr("_from_snapshot")?;
        let args = if matches!(me.inner, Inner::Background(_)) {
            PyTuple::new(slf.py(), [bytes.into_any(), "background".into_pyobject(slf.py())?.into_any()])?
        } else {
            PyTuple::new(slf.py(), [bytes])?
        };
        Ok((restore, args))
    }

    /// Rebuilds an identifier from the bytes written by `__reduce__` (CorruptSnapshot if
    /// corrupt); `refine="background"` restarts a horizon identifier's worker.
    #[classmethod]
    #[pyo3(signature = (data, refine = None))]
    fn _from_snapshot(_cls: &Bound<'_, PyType>, data: &[u8], refine: Option<&str>) -> PyResult<Self> {
        let any = AnyIdentifier::from_snapshot(data).map_err(value_error)?;
        let inner = match (any, refine) {
            (AnyIdentifier::Horizon(id), Some("background")) => {
                Inner::Background(BackgroundHorizon::spawn(id).map_err(value_error)?)
            }
            (any, _) => Inner::Any(any),
        };
        Ok(PyIdentifier { inner })
    }

    fn __copy__(&self) -> PyResult<Self> {
        Ok(PyIdentifier { inner: self.inner.try_clone()? })
    }

    fn __deepcopy__(&self, _memo: &Bound<'_, PyAny>) -> PyResult<Self> {
        self.__copy__()
    }

    fn __repr__(&self) -> String {
        let samples = match self.inner.status() {
            AnyStatus::Paper(s) => s.samples,
            AnyStatus::Rpem(s) => s.samples,
            AnyStatus::Horizon(s) => s.samples,
        };
        format!("Identifier(method={:?}, samples={samples})", self.inner.method())
    }
}

/// `boucwen.status.<class>(**fields)`.
fn status_class<'py>(py: Python<'py>, class: &str, d: &Bound<'py, PyDict>) -> PyResult<Bound<'py, PyAny>> {
    py.import("boucwen.status")?.getattr(class)?.call((), Some(d))
}

/// A step of the paper's method as a `boucwen.status.StepStatus`.
fn step_object<'py>(py: Python<'py>, s: StepStatus) -> PyResult<Bound<'py, PyAny>> {
    let d = PyDict::new(py);
    d.set_item("outcome", s.fit.name())?;
    d.set_item("reason", s.reason.name())?;
    d.set_item("points", s.points)?;
    d.set_item("noise", s.noise)?;
    status_class(py, "StepStatus", &d)
}

/// A method's status as its frozen `boucwen.status` object.
pub(super) fn status_object<'py>(py: Python<'py>, status: AnyStatus) -> PyResult<Bound<'py, PyAny>> {
    let d = PyDict::new(py);
    match status {
        AnyStatus::Paper(s) => {
            d.set_item("samples", s.samples)?;
            d.set_item("window_full", s.window_full)?;
            d.set_item("refreshed", s.refreshed)?;
            d.set_item("half_width", s.half_width)?;
            d.set_item("x_noise_um", s.x_noise_um)?;
            d.set_item("xdot_noise_um_s", s.xdot_noise_um_s)?;
            d.set_item("line_fit", step_object(py, s.line_fit)?)?;
            d.set_item("rate_fit", step_object(py, s.rate_fit)?)?;
            d.set_item("shape_fit", step_object(py, s.shape_fit)?)?;
            d.set_item("return_fit", step_object(py, s.return_fit)?)?;
            d.set_item("split_fit", step_object(py, s.split_fit)?)?;
            d.set_item("window_fit", step_object(py, s.window_fit)?)?;
            status_class(py, "PaperStatus", &d)
        }
        AnyStatus::Rpem(s) => {
            d.set_item("samples", s.samples)?;
            d.set_item("updated", s.updated)?;
            d.set_item("step_limited", s.step_limited)?;
            d.set_item("projected", s.projected)?;
            d.set_item("trace_capped", s.trace_capped)?;
            d.set_item("restarted", s.restarted)?;
            d.set_item("innovation_um", s.innovation_um)?;
            d.set_item("trace", s.trace)?;
            d.set_item("noise_um2", s.noise_um2)?;
            status_class(py, "RpemStatus", &d)
        }
        AnyStatus::Horizon(s) => {
            d.set_item("samples", s.samples)?;
            d.set_item("updated", s.updated)?;
            d.set_item("updates", s.updates)?;
            d.set_item("window_samples", s.window_samples)?;
            d.set_item("window_travel_v", s.window_travel_v)?;
            d.set_item("rms_um", s.rms_um)?;
            d.set_item("damping", s.damping)?;
            d.set_item("step_limited", s.step_limited)?;
            d.set_item("projected", s.projected)?;
            d.set_item("held", s.held)?;
            d.set_item("behind_samples", s.behind_samples)?;
            d.set_item("behind_s", s.behind_s)?;
            status_class(py, "HorizonStatus", &d)
        }
    }
}
