//! `boucwen.Identifier`: streaming online identification.

use numpy::PyArray1;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::params::PyParams;
use super::{samples, value_error};
use crate::identify::{AnyIdentifier, Decomposition, OnlineIdentifier, PaperConfig, PaperIdentifier};

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
/// `method` "paper" (the paper's limited-memory RLS and sub-fits). Options of the
/// paper method (defaults in brackets): `decomposition` "model" or "line" ["model"],
/// `h_zero_frac` [0.005], `rate_frac` [0.2], `min_points` [8], `rank_tol` [1e-3],
/// `min_log_spread` [0.05], `min_r2` [0.9], `n_bounds` [(0.5, 4.0)].
#[pyclass(name = "Identifier", module = "boucwen")]
#[derive(Clone)]
pub struct PyIdentifier {
    inner: AnyIdentifier,
}

#[pymethods]
impl PyIdentifier {
    #[new]
    #[pyo3(signature = (dt, window, init, h0 = 0.0, method = "paper", *, decomposition = "model",
        h_zero_frac = None, rate_frac = None, min_points = None, rank_tol = None,
        min_log_spread = None, min_r2 = None, n_bounds = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        dt: f64,
        window: i64,
        init: &PyParams,
        h0: f64,
        method: &str,
        decomposition: &str,
        h_zero_frac: Option<f64>,
        rate_frac: Option<f64>,
        min_points: Option<i64>,
        rank_tol: Option<f64>,
        min_log_spread: Option<f64>,
        min_r2: Option<f64>,
        n_bounds: Option<(f64, f64)>,
    ) -> PyResult<Self> {
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
        if let Some(v) = n_bounds {
            cfg.n_bounds = v;
        }
        let inner = match method {
            "paper" => AnyIdentifier::Paper(PaperIdentifier::new(dt, init.inner, h0, cfg).map_err(value_error)?),
            other => {
                return Err(PyValueError::new_err(format!("invalid method = {other:?}: expected \"paper\"")))
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

    fn __repr__(&self) -> String {
        format!("Identifier(method={:?}, samples={})", self.inner.method(), self.inner.status().samples)
    }
}
