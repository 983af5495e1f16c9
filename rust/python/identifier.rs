//! `boucwen.Identifier`: streaming online identification.

use numpy::PyArray1;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyType};

use super::effects::PyEffectSet;
use super::params::PyParams;
use super::{samples, value_error};
use crate::identify::{
    AnyIdentifier, Decomposition, OnlineIdentifier, OutputErrorConfig, OutputErrorIdentifier, PaperConfig,
    PaperIdentifier,
};

/// Online identifier of the asymmetric Bouc–Wen model, one sample at a time.
///
/// `push(u, x)` takes a voltage u [V] and a measured displacement x [µm] and
/// returns the model's displacement [µm] for that sample, predicted with the
/// estimates from *before* the sample and with the model's own simulated h; then
/// it updates the estimates. A non-finite sample raises ValueError and leaves
/// the identifier exactly as it was.
///
/// Arguments: `dt` sampling interval [s]; `window` limited memory N [samples];
/// `init` starting parameters (e.g. an offline fit); `h0` initial h [µm];
/// `method` "rpem" (default: the output-error method below) or "paper" (the
/// paper's limited-memory RLS and sub-fits; `window` is its N). Options of the
/// paper method (defaults in brackets): `decomposition` "model" or "line" ["model"],
/// `h_zero_frac` [0.005], `rate_frac` [0.2], `min_points` [8], `rank_tol` [1e-3],
/// `min_log_spread` [0.05], `min_r2` [0.9], `min_arg_frac` [0.05], `min_line_t` [10], `noise_gate` [3.0], `min_delta_t` [3.0],
/// `min_u_std_v` [1e-6 V], `n_bounds` [(0.5, 4.0)] (see `PaperConfig` in the Rust docs).
///
/// `method="rpem"`: recursive prediction-error method on the model's output
/// (simulation) error, sensitivities ∂h/∂θ propagated through the integrator;
/// `window` is not used. Options (defaults in brackets): `forgetting` λ per
/// sample [1.0]; `memory_travel_v` memory in input travel [2000 V = ten periods
/// of a 0–100 V sine]; `p0` initial covariance of θᵢ/scaleᵢ [1e-3];
/// `noise_um2` expected prediction-error variance R [1e-4 µm²]; `max_trace`
/// bound on tr P [1.0]; `max_step` largest change per sample as a fraction of
/// each parameter's scale [0.01]; `n_bounds` [(1.0, 4.0)]; `margin` least
/// β + γ and β − γ [1e-6]; `offset_walk_um` random walk of x0 per sample
/// (creep, drift) [0.05 µm]; `max_offset_step_um` largest change of x0 per
/// sample [0.5 µm]; `effects` an `EffectSet` (e.g. from `boucwen.effects.fit_extended`
/// or `boucwen.diagnose`) whose `input_lag` fc and `creep` gains are identified
/// too, starting from the values given (creep time constants fixed, at most 4
/// elements; other effects are rejected) [None]; `p0_effects` initial covariance
/// of ln fc and of the gains' logistic coordinates, i.e. a relative standard
/// deviation of about √p0_effects [0.05, about 22 %]. With `creep` among the
/// effects, `offset_walk_um` defaults to 0 (the creep elements take the slow part
/// the walk would absorb). The current effect estimates are in `effects`.
/// Largest window [samples] accepted (the window is held in memory).
const MAX_WINDOW: usize = PaperConfig::MAX_WINDOW;

/// An integer argument; a too-large int is a ValueError (not OverflowError), a non-int a TypeError.
fn count_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<i64> {
    obj.extract::<i64>().map_err(|err| {
        if err.is_instance_of::<pyo3::exceptions::PyOverflowError>(obj.py()) {
            PyValueError::new_err(format!("invalid {name} = {obj}: too large"))
        } else {
            pyo3::exceptions::PyTypeError::new_err(format!(
                "{name} must be an integer, got {}",
                obj.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into())
            ))
        }
    })
}

#[pyclass(name = "Identifier", module = "boucwen")]
#[derive(Clone)]
pub struct PyIdentifier {
    inner: AnyIdentifier,
}

#[pymethods]
impl PyIdentifier {
    #[new]
    #[pyo3(signature = (dt, window, init, h0 = 0.0, method = "rpem", *, decomposition = "model",
        h_zero_frac = None, rate_frac = None, min_points = None, rank_tol = None,
        min_log_spread = None, min_r2 = None, min_arg_frac = None, min_line_t = None, noise_gate = None, min_delta_t = None, min_u_std_v = None, n_bounds = None, forgetting = None, memory_travel_v = None,
        p0 = None, noise_um2 = None, max_trace = None, max_step = None, margin = None, offset_walk_um = None, max_offset_step_um = None,
        effects = None, p0_effects = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        dt: f64,
        window: &Bound<'_, PyAny>,
        init: &PyParams,
        h0: f64,
        method: &str,
        decomposition: &str,
        h_zero_frac: Option<f64>,
        rate_frac: Option<f64>,
        min_points: Option<&Bound<'_, PyAny>>,
        rank_tol: Option<f64>,
        min_log_spread: Option<f64>,
        min_r2: Option<f64>,
        min_arg_frac: Option<f64>,
        min_line_t: Option<f64>,
        noise_gate: Option<f64>,
        min_delta_t: Option<f64>,
        min_u_std_v: Option<f64>,
        n_bounds: Option<(f64, f64)>,
        forgetting: Option<f64>,
        memory_travel_v: Option<f64>,
        p0: Option<f64>,
        noise_um2: Option<f64>,
        max_trace: Option<f64>,
        max_step: Option<f64>,
        margin: Option<f64>,
        offset_walk_um: Option<f64>,
        max_offset_step_um: Option<f64>,
        effects: Option<PyRef<'_, PyEffectSet>>,
        p0_effects: Option<f64>,
    ) -> PyResult<Self> {
        if method == "rpem" {
            let paper_only = [
                h_zero_frac,
                rate_frac,
                rank_tol,
                min_log_spread,
                min_r2,
                min_arg_frac,
                min_line_t,
                min_delta_t,
                min_u_std_v,
            ];
            if decomposition != "model" || min_points.is_some() || paper_only.iter().any(Option::is_some) {
                return Err(PyValueError::new_err(
                    "decomposition, h_zero_frac, rate_frac, min_points, rank_tol, min_log_spread, min_r2, \
                     min_arg_frac, min_line_t, min_delta_t and min_u_std_v are \
                     options of method=\"paper\", not of method=\"rpem\"",
                ));
            }
            let effects = effects.map(|e| e.inner.clone()).unwrap_or_default();
            let mut cfg = OutputErrorConfig::for_effects(&effects);
            let options = [
                (&mut cfg.forgetting, forgetting),
                (&mut cfg.memory_travel_v, memory_travel_v),
                (&mut cfg.p0, p0),
                (&mut cfg.noise_um2, noise_um2),
                (&mut cfg.max_trace, max_trace),
                (&mut cfg.max_step, max_step),
                (&mut cfg.margin, margin),
                (&mut cfg.offset_walk_um, offset_walk_um),
                (&mut cfg.max_offset_step_um, max_offset_step_um),
            ];
            for (slot, value) in options {
                if let Some(v) = value {
                    *slot = v;
                }
            }
            if let Some(v) = n_bounds {
                cfg.n_bounds = v;
            }
            if let Some(v) = p0_effects {
                cfg.p0_effects = v;
            }
            let id = OutputErrorIdentifier::with_effects(dt, init.inner, &effects, h0, cfg).map_err(value_error)?;
            return Ok(PyIdentifier { inner: AnyIdentifier::OutputError(id) });
        }
        let window = count_arg(window, "window")?;
        if window > MAX_WINDOW as i64 {
            return Err(PyValueError::new_err(format!(
                "invalid window = {window}: at most {MAX_WINDOW} samples (the window is held in memory)"
            )));
        }
        let rpem_only = [
            forgetting,
            memory_travel_v,
            p0,
            noise_um2,
            max_trace,
            max_step,
            margin,
            offset_walk_um,
            max_offset_step_um,
            p0_effects,
        ];
        if method == "paper" && (rpem_only.iter().any(Option::is_some) || effects.is_some()) {
            return Err(PyValueError::new_err(
                "forgetting, memory_travel_v, p0, noise_um2, max_trace, max_step, margin, offset_walk_um, \
                 max_offset_step_um, effects and p0_effects are options of method=\"rpem\", not of method=\"paper\"",
            ));
        }
        if window < PaperConfig::MIN_WINDOW as i64 {
            return Err(PyValueError::new_err(format!(
                "invalid window = {window}: the window must hold at least {} samples",
                PaperConfig::MIN_WINDOW
            )));
        }
        let mut cfg = PaperConfig::with_window(window as usize);
        cfg.decomposition = match decomposition {
            "model" => Decomposition::Model,
            "line" => Decomposition::Line,
            other => {
                return Err(PyValueError::new_err(format!(
                    "invalid decomposition = {other:?}: expected \"model\" or \"line\""
                )))
            }
        };
        if let Some(v) = h_zero_frac {
            cfg.h_zero_frac = v;
        }
        if let Some(v) = rate_frac {
            cfg.rate_frac = v;
        }
        if let Some(v) = min_points {
            let v = count_arg(v, "min_points")?;
            if v < 2 {
                return Err(PyValueError::new_err(format!("invalid min_points = {v}: must be >= 2")));
            }
            cfg.min_points = v as usize;
        }
        if let Some(v) = rank_tol {
            cfg.rank_tol = v;
        }
        if let Some(v) = min_log_spread {
            cfg.min_log_spread = v;
        }
        if let Some(v) = min_r2 {
            cfg.min_r2 = v;
        }
        if let Some(v) = min_arg_frac {
            cfg.min_arg_frac = v;
        }
        if let Some(v) = min_line_t {
            cfg.min_line_t = v;
        }
        if let Some(v) = noise_gate {
            cfg.noise_gate = v;
        }
        if let Some(v) = min_delta_t {
            cfg.min_delta_t = v;
        }
        if let Some(v) = min_u_std_v {
            cfg.min_u_std_v = v;
        }
        if let Some(v) = n_bounds {
            cfg.n_bounds = v;
        }
        let inner = match method {
            "paper" => AnyIdentifier::Paper(PaperIdentifier::new(dt, init.inner, h0, cfg).map_err(value_error)?),
            other => {
                return Err(PyValueError::new_err(format!(
                    "invalid method = {other:?}: expected \"paper\" or \"rpem\""
                )))
            }
        };
        Ok(PyIdentifier { inner })
    }

    /// Takes one sample (u [V], x [µm]); returns the predicted x [µm] (see the class docs).
    fn push(&mut self, u: f64, x: f64) -> PyResult<f64> {
        self.inner.push(u, x).map_err(value_error)
    }

    /// `push` over arrays, with the GIL released; returns the predictions [µm],
    /// identical to a loop of `push`. If any value is NaN or infinite the whole call
    /// raises ValueError before any sample is used (the state is unchanged).
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
                inner.push_many(&u, &x, &mut out).map(|_| out)
            })
            .map_err(value_error)?;
        Ok(PyArray1::from_vec(py, out))
    }

    /// The current parameter estimates.
    #[getter]
    fn params(&self) -> PyParams {
        PyParams { inner: self.inner.params() }
    }

    /// The model's hysteresis state h [µm] after the last sample.
    #[getter]
    fn h(&self) -> f64 {
        self.inner.h()
    }

    /// The effects identified along with the parameters, with their current
    /// estimates (input_lag fc [Hz], creep gains [µm/V]; the creep time constants
    /// stay as given): an `EffectSet`, empty for method="rpem" without effects, and
    /// None for method="paper", which identifies no effects.
    #[getter]
    fn effects(&self) -> Option<PyEffectSet> {
        match &self.inner {
            AnyIdentifier::OutputError(id) => Some(PyEffectSet { inner: id.effects() }),
            _ => None,
        }
    }

    /// The online method in use.
    #[getter]
    fn method(&self) -> &'static str {
        self.inner.method()
    }

    /// What the last push did: samples seen, window full, and for each sub-fit
    /// ("line_fit", "rate_fit", "shape_fit", "return_fit") "ran", "reduced" or "held".
    #[getter]
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.inner.status();
        let d = PyDict::new(py);
        d.set_item("samples", s.samples)?;
        d.set_item("window_full", s.window_full)?;
        d.set_item("refreshed", s.refreshed)?;
        d.set_item("line_fit", s.line_fit.name())?;
        d.set_item("rate_fit", s.rate_fit.name())?;
        d.set_item("shape_fit", s.shape_fit.name())?;
        d.set_item("return_fit", s.return_fit.name())?;
        Ok(d)
    }

    /// Back to the state right after construction.
    fn reset(&mut self) {
        self.inner.reset()
    }

    /// Pickle support: the identifier is saved as its byte snapshot (every value it
    /// carries between samples), so an unpickled copy continues bit for bit.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyBytes>,))> {
        let bytes = slf.borrow().inner.to_snapshot().map_err(value_error)?;
        let restore = slf.get_type().getattr("_from_snapshot")?;
        Ok((restore, (PyBytes::new(slf.py(), &bytes),)))
    }

    /// Rebuilds an identifier from the bytes written by `__reduce__` (ValueError if corrupt).
    #[classmethod]
    fn _from_snapshot(_cls: &Bound<'_, PyType>, data: &[u8]) -> PyResult<Self> {
        AnyIdentifier::from_snapshot(data).map(|inner| PyIdentifier { inner }).map_err(value_error)
    }

    fn __copy__(&self) -> Self {
        self.clone()
    }

    fn __deepcopy__(&self, _memo: &Bound<'_, PyAny>) -> Self {
        self.clone()
    }

    fn __repr__(&self) -> String {
        format!("Identifier(method={:?}, samples={})", self.inner.method(), self.inner.status().samples)
    }
}
