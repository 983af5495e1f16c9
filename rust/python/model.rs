//! `boucwen.Model` (per-sample) and `boucwen.simulate` (batch, chunkable).

use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use super::params::PyParams;
use super::{finite, samples, value_error};
use crate::error::positive_dt;
use crate::format::Snapshot;
use crate::Model;

/// Simulates the asymmetric Bouc–Wen model over a record.
///
/// u \[V\] is taken as piecewise linear between samples `dt` \[s\] apart. Returns
/// `(x, h_final)`: x[k] = kv·u[k] + x0 + h[k] \[µm\] and h after the last sample \[µm\].
/// With `u_prev=None`, h\[0\] = h0; with `u_prev=v`, the first interval runs from v
/// to u\[0\], so `simulate(p, u[k:], dt, h0=h_final, u_prev=u[k-1])` continues a
/// record split at k as one call would, to the last bits (|h|^n, carried from sample to
/// sample, is computed afresh at the cut; `Model` continues bit for bit). The GIL is
/// released while it runs.
#[pyfunction]
#[pyo3(signature = (params, u, dt, h0 = 0.0, u_prev = None))]
pub fn simulate<'py>(
    py: Python<'py>,
    params: &PyParams,
    u: &Bound<'py, PyAny>,
    dt: f64,
    h0: f64,
    u_prev: Option<f64>,
) -> PyResult<(Bound<'py, PyArray1<f64>>, f64)> {
    let u = samples(u, "u")?;
    let p = params.inner;
    let (x, h) = py.detach(move || crate::simulate(&p, &u, dt, h0, u_prev)).map_err(value_error)?;
    Ok((PyArray1::from_vec(py, x), h))
}

/// The paper's input u = 50 + 50·sin(2πft − π/2) \[V\], sampled every `dt` \[s\]:
/// 1 Hz for 3 s, 10 Hz to 3.3 s, 100 Hz to 3.33 s, then 200 Hz for `tail_s` \[s\].
#[pyfunction]
#[pyo3(signature = (dt, tail_s = 0.05))]
pub fn paper_input<'py>(py: Python<'py>, dt: f64, tail_s: f64) -> PyResult<Bound<'py, PyArray1<f64>>> {
    positive_dt(dt).map_err(value_error)?;
    let tail_s = finite(tail_s, "tail_s")?;
    if tail_s < 0.0 || (3.33 + tail_s) / dt > 1e9 {
        return Err(pyo3::exceptions::PyValueError::new_err("tail_s must be >= 0 and the record at most 1e9 samples"));
    }
    Ok(PyArray1::from_vec(py, crate::model::paper_input(dt, tail_s)))
}

/// A per-sample asymmetric Bouc–Wen model for control loops: `step(u) -> x`.
///
/// `params`: the model; `dt`: sampling interval \[s\]; `h0`: initial h \[µm\]. The
/// first sample keeps h = h0; each later one integrates eq. (5) from the
/// previous voltage. A non-finite u raises ValueError and changes nothing.
#[pyclass(name = "Model", module = "boucwen")]
#[derive(Clone)]
pub struct PyModel {
    inner: Model,
}

#[pymethods]
impl PyModel {
    #[new]
    #[pyo3(signature = (params, dt, h0 = 0.0))]
    fn new(params: &PyParams, dt: f64, h0: f64) -> PyResult<Self> {
        Model::new(params.inner, dt, h0).map(|inner| PyModel { inner }).map_err(value_error)
    }

    /// Takes the next voltage u \[V\]; returns the displacement x \[µm\].
    fn step(&mut self, u: f64) -> PyResult<f64> {
        self.inner.step(u).map_err(value_error)
    }

    /// Current hysteresis state h \[µm\].
    #[getter]
    fn h(&self) -> f64 {
        self.inner.h()
    }

    /// The model's parameters.
    #[getter]
    fn params(&self) -> PyParams {
        PyParams { inner: *self.inner.params() }
    }

    /// Sampling interval \[s\].
    #[getter]
    fn dt(&self) -> f64 {
        self.inner.dt()
    }

    /// Forgets the past: h = h0 \[µm\], no previous sample.
    #[pyo3(signature = (h0 = 0.0))]
    fn reset(&mut self, h0: f64) -> PyResult<()> {
        self.inner.reset(h0).map_err(value_error)
    }

    fn __getstate__<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.inner.to_bytes())
    }

    fn __setstate__(&mut self, state: &[u8]) -> PyResult<()> {
        self.inner = Model::from_bytes(state).map_err(value_error)?;
        Ok(())
    }

    fn __getnewargs__(&self) -> (PyParams, f64) {
        (PyParams { inner: *self.inner.params() }, self.inner.dt())
    }
}
