//! `boucwen.Inverse`, `boucwen.invert` and `boucwen.Compensator`: conversions and
//! error mapping only; the numerics are in `crate::compensate`.

use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyType};

use super::effects::PyEffectSet;
use super::identifier::{max_intervals_arg, refine_arg, Refine};
use super::params::PyParams;
use super::{samples, value_error, CorruptSnapshot};
use crate::compensate::{
    AnyInverse, Clip, Compensator, CompensatorConfig, ExtendedInverseState, InverseStatus, PidGains, VoltageLimits,
};
use crate::identify::{BackgroundHorizon, HorizonConfig, HorizonIdentifier, RefineMode, RpemConfig, RpemIdentifier};
use pyo3::exceptions::PyValueError;

fn limits(u_min: Option<f64>, u_max: Option<f64>) -> PyResult<VoltageLimits> {
    VoltageLimits::new(u_min, u_max).map_err(value_error)
}

fn bound(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn clip_from_name(name: &str) -> PyResult<Clip> {
    match name {
        "none" => Ok(Clip::None),
        "low" => Ok(Clip::Low),
        "high" => Ok(Clip::High),
        other => Err(CorruptSnapshot::new_err(format!("invalid clip {other:?} in the pickled state"))),
    }
}

fn inverse_status_dict<'py>(py: Python<'py>, s: &InverseStatus) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("clip", s.clip.name())?;
    d.set_item("evaluations", s.evaluations)?;
    d.set_item("residual_um", s.residual_um)?;
    d.set_item("exact", s.exact)?;
    d.set_item("samples", s.samples)?;
    d.set_item("clipped_samples", s.clipped_samples)?;
    Ok(d)
}

/// The pickled state of an `Inverse`: (samples, u_prev, ua_prev, h, creep states)
/// and the status (clip, evaluations, residual, exact, clipped samples).
type StateTuple = (u64, Option<f64>, f64, f64, Vec<f64>);
type StatusTuple = (String, u32, f64, bool, u64);
type InverseArgs = (PyParams, f64, f64, Option<f64>, Option<f64>, Option<PyEffectSet>, StateTuple, StatusTuple);

/// The inverse of the asymmetric Bouc–Wen model, one sample at a time:
/// `step(x_d) -> u`.
///
/// Solves kv·u + x0 + Φ(h, u_prev → u) = x_d \[µm\] for u \[V\] with the model's own
/// integrator Φ (Newton with a secant slope, then Illinois inside a bracket; at most
/// 40 evaluations of Φ per sample), within [u_min, u_max] \[V\]; h \[µm\] then follows
/// the u returned (the clipped one where a limit binds). `status` reports the limit,
/// the residual \[µm\] and the evaluations of the last sample. `effects`: an
/// `EffectSet` whose input_lag, creep, gain_drift, electrostriction, drift and delay are
/// inverted too (no resonance; pickup and saturation, in the reading only, are ignored);
/// with a delay of d samples, `step` takes the reference d samples ahead.
#[pyclass(name = "Inverse", module = "boucwen")]
#[derive(Clone)]
pub struct PyInverse {
    inner: AnyInverse,
}

#[pymethods]
impl PyInverse {
    #[new]
    #[pyo3(signature = (params, dt, h0 = 0.0, u_min = None, u_max = None, *, effects = None))]
    fn new(
        params: &PyParams,
        dt: f64,
        h0: f64,
        u_min: Option<f64>,
        u_max: Option<f64>,
        effects: Option<PyRef<'_, PyEffectSet>>,
    ) -> PyResult<Self> {
        let effects = effects.map(|e| e.inner.clone());
        let inner = AnyInverse::new(params.inner, effects, dt, h0, limits(u_min, u_max)?).map_err(value_error)?;
        Ok(PyInverse { inner })
    }

    /// Takes the desired displacement x_d \[µm\]; returns the voltage u \[V\].
    fn step(&mut self, x_d: f64) -> PyResult<f64> {
        self.inner.step(x_d).map_err(value_error)
    }

    /// `step` over an array, with the GIL released; identical to a loop of `step`.
    fn step_many<'py>(&mut self, py: Python<'py>, x_d: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let x_d = samples(x_d, "x_d")?;
        let inner = &mut self.inner;
        let out = py
            .detach(move || {
                let mut out = vec![0.0; x_d.len()];
                inner.step_many(&x_d, &mut out).map(|_| out)
            })
            .map_err(value_error)?;
        Ok(PyArray1::from_vec(py, out))
    }

    /// Replaces the parameters; h and the previous voltage are kept.
    fn set_params(&mut self, params: &PyParams) -> PyResult<()> {
        self.inner.set_params(params.inner).map_err(value_error)
    }

    /// The model's parameters.
    #[getter]
    fn params(&self) -> PyParams {
        PyParams { inner: *self.inner.params() }
    }

    /// The effects inverted along with the base model (None: the base model alone).
    #[getter]
    fn effects(&self) -> Option<PyEffectSet> {
        self.inner.effects().map(|e| PyEffectSet { inner: e.clone() })
    }

    /// Hysteresis state h \[µm\] after the last sample.
    #[getter]
    fn h(&self) -> f64 {
        self.inner.h()
    }

    /// Sampling interval \[s\].
    #[getter]
    fn dt(&self) -> f64 {
        self.inner.dt()
    }

    /// Lower voltage limit \[V\] (None: no limit).
    #[getter]
    fn u_min(&self) -> Option<f64> {
        bound(self.inner.limits().min_v)
    }

    /// Upper voltage limit \[V\] (None: no limit).
    #[getter]
    fn u_max(&self) -> Option<f64> {
        bound(self.inner.limits().max_v)
    }

    /// How many samples ahead `step` reads the reference (the inverted delay; 0 without).
    #[getter]
    fn preview_samples(&self) -> usize {
        self.inner.preview_samples()
    }

    /// What the last step did: "clip" ("none", "low", "high"), "evaluations" of the
    /// integrator, "residual_um" (model x − x_d \[µm\]), "exact" (within the tolerance),
    /// "samples", "clipped_samples".
    #[getter]
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        inverse_status_dict(py, &self.inner.status())
    }

    /// Forgets the past: h = h0, no previous sample, counters zero.
    fn reset(&mut self) {
        self.inner.reset()
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, InverseArgs)> {
        let this = slf.borrow();
        let inv = &this.inner;
        let s = inv.state();
        let st = inv.status();
        let limits = inv.limits();
        let args = (
            PyParams { inner: *inv.params() },
            inv.dt(),
            inv.h0(),
            bound(limits.min_v),
            bound(limits.max_v),
            inv.effects().map(|e| PyEffectSet { inner: e.clone() }),
            (s.samples, s.u_prev, s.ua_prev, s.h, s.creep),
            (st.clip.name().to_string(), st.evaluations, st.residual_um, st.exact, st.clipped_samples),
        );
        Ok((slf.get_type().getattr("_restore")?, args))
    }

    /// Rebuilds an inverse from the values written by `__reduce__` (ValueError if invalid).
    #[classmethod]
    #[allow(clippy::too_many_arguments)]
    fn _restore(
        _cls: &Bound<'_, PyType>,
        params: &PyParams,
        dt: f64,
        h0: f64,
        u_min: Option<f64>,
        u_max: Option<f64>,
        effects: Option<PyRef<'_, PyEffectSet>>,
        state: StateTuple,
        status: StatusTuple,
    ) -> PyResult<Self> {
        let mut me = Self::new(params, dt, h0, u_min, u_max, effects)?;
        let (samples, u_prev, ua_prev, h, creep) = state;
        let (clip, evaluations, residual_um, exact, clipped_samples) = status;
        let status =
            InverseStatus { clip: clip_from_name(&clip)?, evaluations, residual_um, exact, samples, clipped_samples };
        me.inner.restore(ExtendedInverseState { samples, u_prev, ua_prev, h, creep }, status).map_err(value_error)?;
        Ok(me)
    }

    fn __copy__(&self) -> Self {
        self.clone()
    }

    fn __deepcopy__(&self, _memo: &Bound<'_, PyAny>) -> Self {
        self.clone()
    }

    fn __repr__(&self) -> String {
        let l = self.inner.limits();
        let py_float = |v: f64| bound(v).map_or_else(|| "None".to_string(), |v| format!("{v:?}"));
        let effects = self.inner.effects().map_or_else(|| "None".to_string(), |e| format!("{:?}", e.names()));
        format!(
            "Inverse(samples={}, h={:?}, u_min={}, u_max={}, effects={effects})",
            self.inner.status().samples,
            self.inner.h(),
            py_float(l.min_v),
            py_float(l.max_v),
        )
    }
}

/// Inverts a record: the voltages u \[V\] that make the model produce x_d \[µm\].
///
/// Returns `(u, h_final)`. Sample k solves kv·u + x0 + Φ(h, u[k−1] → u) = x_d[k]
/// with the simulator's integrator, so `simulate(params, u, dt)` returns x_d
/// wherever the root lies within [u_min, u_max] (to 1e-12·max(1, |x_d|) µm). With
/// `u_prev=v` the first interval starts at v (stream a record in chunks, as
/// `simulate`). With `effects` (input_lag, creep, gain_drift, electrostriction, drift,
/// delay; pickup and saturation ignored), the extended model is inverted; a delay of d samples is met by reading x_d d samples ahead.
/// The GIL is released while it runs.
#[pyfunction]
#[pyo3(signature = (params, x_d, dt, h0 = 0.0, u_prev = None, *, u_min = None, u_max = None, effects = None))]
#[allow(clippy::too_many_arguments)]
pub fn invert<'py>(
    py: Python<'py>,
    params: &PyParams,
    x_d: &Bound<'py, PyAny>,
    dt: f64,
    h0: f64,
    u_prev: Option<f64>,
    u_min: Option<f64>,
    u_max: Option<f64>,
    effects: Option<PyRef<'py, PyEffectSet>>,
) -> PyResult<(Bound<'py, PyArray1<f64>>, f64)> {
    let x_d = samples(x_d, "x_d")?;
    let p = params.inner;
    let lim = limits(u_min, u_max)?;
    let effects = effects.map(|e| e.inner.clone()).filter(|e| !e.names().is_empty());
    let (u, h) = match effects {
        None => py
            .detach(move || crate::compensate::invert(&p, &x_d, dt, h0, u_prev, lim).map(|(u, s)| (u, s.h_final)))
            .map_err(value_error)?,
        Some(effects) => {
            if u_prev.is_some() {
                return Err(pyo3::exceptions::PyValueError::new_err(
                    "u_prev is not supported with effects (their state is more than h and u); \
                     use boucwen.Inverse(..., effects=...) to stream a record",
                ));
            }
            py.detach(move || crate::compensate::invert_extended(&p, &effects, &x_d, dt, h0, lim))
                .map_err(value_error)?
        }
    };
    Ok((PyArray1::from_vec(py, u), h))
}

/// The compensator around the identifier chosen (`identifier`, `refine`).
#[allow(clippy::large_enum_variant)]
enum Comp {
    Rpem(Compensator<RpemIdentifier>),
    Horizon(Compensator<HorizonIdentifier>),
    Background(Compensator<BackgroundHorizon>),
}

/// Runs `$body` with `$c` bound to the compensator, whichever identifier it holds.
macro_rules! with_comp {
    ($inner:expr, $c:ident => $body:expr) => {
        match $inner {
            Comp::Rpem($c) => $body,
            Comp::Horizon($c) => $body,
            Comp::Background($c) => $body,
        }
    };
}

impl Comp {
    fn try_clone(&self) -> PyResult<Self> {
        Ok(match self {
            Comp::Background(c) => Comp::Background(c.try_clone().map_err(value_error)?),
            Comp::Rpem(c) => Comp::Rpem(c.clone()),
            Comp::Horizon(c) => Comp::Horizon(c.clone()),
        })
    }
}

/// Adaptive hysteresis compensator for a control loop: `u = step(x_d, x_meas)`.
///
/// Each call takes the desired displacement x_d \[µm\] of this sample and the
/// measurement x_meas \[µm\] of the previous output (None on the first call or when
/// none arrived) and returns the voltage u \[V\] to apply:
///
/// 1. with a measurement, the online identifier takes (u_prev, x_meas) and the inverse
///    takes its new estimates and h (`adapt=True`); the feedback takes the error
///    e = x_d,prev − x_meas \[µm\];
/// 2. u = inverse(x_d + v) with v = kp·e + ki·∫e dt + kd·ė \[µm\] (kp \[-\], ki \[1/s\],
///    kd \[s\], the derivative through a first-order filter at `derivative_filter_hz`
///    \[Hz\], |∫| ≤ `integral_limit_um` \[µm\], no integration toward a limit that bound);
///    `feedforward=False` gives u = inverse(v): feedback alone.
///
/// `identifier`: "rpem" (the default: the output-error method tuned for tracking) or
/// "horizon" (the recommended identifier, `Identifier(dt, params, h0)`: its input lag
/// is identified too and the inverse runs through it, the extended inverse). `refine`
/// (horizon only) says where its window pass runs, as for `Identifier`: "sync" (in
/// every step), "cooperative" (`step` costs a model step and an inversion; call
/// `refine(max_intervals)` when the loop has time) or "background" (a worker thread).
///
/// `params`, `h0`: the start of the estimates and of h; `u_min`, `u_max`: voltage
/// limits \[V\]. A non-finite value raises ValueError and changes nothing.
#[pyclass(name = "Compensator", module = "boucwen")]
pub struct PyCompensator {
    inner: Comp,
}

#[pymethods]
impl PyCompensator {
    #[new]
    #[pyo3(signature = (params, dt, *, h0 = 0.0, u_min = None, u_max = None, adapt = true, kp = 0.0, ki = 0.0,
        kd = 0.0, derivative_filter_hz = 1000.0, integral_limit_um = None, feedforward = true,
        identifier = "rpem", refine = "sync"))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        params: &PyParams,
        dt: f64,
        h0: f64,
        u_min: Option<f64>,
        u_max: Option<f64>,
        adapt: bool,
        kp: f64,
        ki: f64,
        kd: f64,
        derivative_filter_hz: f64,
        integral_limit_um: Option<f64>,
        feedforward: bool,
        identifier: &str,
        refine: &str,
    ) -> PyResult<Self> {
        let gains = PidGains {
            kp,
            ki,
            kd,
            derivative_filter_hz,
            integral_limit_um: integral_limit_um.unwrap_or(f64::INFINITY),
        };
        let config = CompensatorConfig { adapt, feedforward, gains };
        let lim = limits(u_min, u_max)?;
        let refine = refine_arg(refine)?;
        let inner = match identifier {
            "rpem" => {
                if !matches!(refine, Refine::Mode(RefineMode::Sync)) {
                    return Err(PyValueError::new_err(
                        "invalid refine for identifier=\"rpem\": only \"sync\" (the split is the horizon method's)",
                    ));
                }
                let id = RpemIdentifier::new(dt, params.inner, h0, RpemConfig::for_tracking()).map_err(value_error)?;
                Comp::Rpem(Compensator::new(id, dt, lim, config).map_err(value_error)?)
            }
            "horizon" => {
                let id = HorizonIdentifier::recommended(dt, params.inner, h0, HorizonConfig::default())
                    .map_err(value_error)?;
                match refine {
                    Refine::Mode(mode) => {
                        Comp::Horizon(Compensator::new(id.with_mode(mode), dt, lim, config).map_err(value_error)?)
                    }
                    Refine::Background => {
                        let id = BackgroundHorizon::spawn(id).map_err(value_error)?;
                        Comp::Background(Compensator::new(id, dt, lim, config).map_err(value_error)?)
                    }
                }
            }
            other => {
                return Err(PyValueError::new_err(format!(
                    "invalid identifier = {other:?}: expected \"rpem\" or \"horizon\""
                )))
            }
        };
        Ok(PyCompensator { inner })
    }

    /// Takes x_d \[µm\] and the previous output's measurement x_meas \[µm\] (or None);
    /// returns the voltage u \[V\] to apply now.
    #[pyo3(signature = (x_d, x_meas = None))]
    fn step(&mut self, x_d: f64, x_meas: Option<f64>) -> PyResult<f64> {
        with_comp!(&mut self.inner, c => c.step(x_d, x_meas)).map_err(value_error)
    }

    /// Cooperative mode: runs the identifier's window pass at most `max_intervals`
    /// integration intervals, with the GIL released; the next step inverts the update
    /// it adopts. Returns the intervals run (0 in the other modes and for "rpem").
    fn refine(&mut self, py: Python<'_>, max_intervals: &Bound<'_, PyAny>) -> PyResult<usize> {
        let n = max_intervals_arg(max_intervals)?;
        match &mut self.inner {
            Comp::Horizon(c) => Ok(py.detach(move || c.refine(n))),
            _ => Ok(0),
        }
    }

    /// The online identifier: "rpem" or "horizon".
    #[getter]
    fn identifier(&self) -> &'static str {
        match self.inner {
            Comp::Rpem(_) => "rpem",
            Comp::Horizon(_) | Comp::Background(_) => "horizon",
        }
    }

    /// Where the horizon identifier's window pass runs ("sync", "cooperative",
    /// "background"); None for "rpem".
    #[getter]
    fn refine_mode(&self) -> Option<&'static str> {
        match &self.inner {
            Comp::Rpem(_) => None,
            Comp::Horizon(c) => Some(c.identifier().mode().name()),
            Comp::Background(_) => Some("background"),
        }
    }

    /// The effects the inverse runs through (the identified input lag at its current
    /// estimate, fc \[Hz\]); None for the base inverse.
    #[getter]
    fn effects(&self) -> Option<PyEffectSet> {
        with_comp!(&self.inner, c => c.inverse().effects().map(|e| PyEffectSet { inner: e.clone() }))
    }

    /// The parameters the inverse uses now (the current estimates when adapting).
    #[getter]
    fn params(&self) -> PyParams {
        PyParams { inner: with_comp!(&self.inner, c => c.params()) }
    }

    /// The inverse model's h \[µm\] after the last sample.
    #[getter]
    fn h(&self) -> f64 {
        with_comp!(&self.inner, c => c.h())
    }

    /// Sampling interval \[s\].
    #[getter]
    fn dt(&self) -> f64 {
        with_comp!(&self.inner, c => c.inverse().dt())
    }

    /// Whether the estimates are updated online.
    #[getter]
    fn adapt(&self) -> bool {
        with_comp!(&self.inner, c => c.config().adapt)
    }

    /// The feedback gains: {"kp": \[-\], "ki": \[1/s\], "kd": \[s\], "derivative_filter_hz":
    /// \[Hz\], "integral_limit_um": \[µm\] or None, "feedforward": bool}.
    #[getter]
    fn gains<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = *with_comp!(&self.inner, c => c.config());
        let d = PyDict::new(py);
        d.set_item("kp", c.gains.kp)?;
        d.set_item("ki", c.gains.ki)?;
        d.set_item("kd", c.gains.kd)?;
        d.set_item("derivative_filter_hz", c.gains.derivative_filter_hz)?;
        d.set_item("integral_limit_um", bound(c.gains.integral_limit_um))?;
        d.set_item("feedforward", c.feedforward)?;
        Ok(d)
    }

    /// What the last step did: the inverse's "clip", "evaluations", "residual_um",
    /// "exact", "clipped_samples"; "prediction_um" (the identifier's prediction of
    /// the measured sample, NaN if none), "error_um" (x_d − x_meas of the previous
    /// sample, NaN if none), "feedback_um" (v), "command_um" (what the inverse was
    /// asked for), "samples", "in_step" (no measurement missing so far),
    /// "estimates_held" (this sample's estimates were not admissible: the inverse kept
    /// the last ones whose x(u) rises on both branches with at least 0.1·kv),
    /// "held_samples".
    #[getter]
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = with_comp!(&self.inner, c => c.status());
        let d = inverse_status_dict(py, &s.inverse)?;
        d.set_item("samples", s.samples)?;
        d.set_item("prediction_um", s.prediction_um)?;
        d.set_item("error_um", s.error_um)?;
        d.set_item("feedback_um", s.feedback_um)?;
        d.set_item("command_um", s.command_um)?;
        d.set_item("in_step", s.in_step)?;
        d.set_item("estimates_held", s.estimates_held)?;
        d.set_item("held_samples", s.held_samples)?;
        Ok(d)
    }

    /// A copy (a background identifier's copy gets its own worker).
    fn __copy__(&self) -> PyResult<Self> {
        Ok(PyCompensator { inner: self.inner.try_clone()? })
    }

    fn __deepcopy__(&self, _memo: &Bound<'_, PyAny>) -> PyResult<Self> {
        self.__copy__()
    }

    fn __repr__(&self) -> String {
        let c = *with_comp!(&self.inner, c => c.config());
        let samples = with_comp!(&self.inner, c => c.status().samples);
        format!(
            "Compensator(identifier={:?}, adapt={}, kp={:?}, ki={:?}, kd={:?}, samples={})",
            self.identifier(),
            if c.adapt { "True" } else { "False" },
            c.gains.kp,
            c.gains.ki,
            c.gains.kd,
            samples
        )
    }
}
