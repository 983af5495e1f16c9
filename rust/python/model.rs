//! `boucwen.Model` (per-sample) and `boucwen.simulate` (batch, chunkable).

use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
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

/// The model of each parameter set of `params` simulated over the same voltage `u`
/// \[V\] from h\[0\] = `h0` \[µm\]: row i is `simulate(params[i], u, dt, h0)[0]` to
/// the last bit. The sets are shared among the machine's cores, the GIL released
/// (scoring many candidate models on one record). A non-finite sample raises
/// before anything runs.
#[pyfunction]
#[pyo3(signature = (params, u, dt, h0 = 0.0))]
pub fn simulate_many<'py>(
    py: Python<'py>,
    params: Vec<PyRef<'py, PyParams>>,
    u: &Bound<'py, PyAny>,
    dt: f64,
    h0: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let u = samples(u, "u")?;
    positive_dt(dt).map_err(value_error)?;
    finite(h0, "h0")?;
    let sets: Vec<crate::Params> = params.iter().map(|p| p.inner).collect();
    let (rows, n) = (sets.len(), u.len());
    let values = py.detach(move || -> PyResult<Vec<f64>> {
        let mut out = vec![0.0; rows * n];
        if rows == 0 || n == 0 {
            return Ok(out);
        }
        let threads = std::thread::available_parallelism().map_or(1, |t| t.get()).min(rows);
        let per = rows.div_ceil(threads);
        std::thread::scope(|scope| {
            let workers: Vec<_> = out
                .chunks_mut(per * n)
                .zip(sets.chunks(per))
                .map(|(block, sets)| {
                    let u = &u;
                    scope.spawn(move || -> crate::Result<()> {
                        for (row, p) in block.chunks_mut(n).zip(sets) {
                            crate::simulate_into(p, u, dt, h0, None, row)?;
                        }
                        Ok(())
                    })
                })
                .collect();
            workers.into_iter().try_for_each(|w| match w.join() {
                Ok(done) => done.map_err(value_error),
                Err(_) => Err(PyRuntimeError::new_err("a simulation worker stopped unexpectedly")),
            })
        })?;
        Ok(out)
    })?;
    PyArray1::from_vec(py, values).reshape([rows, n])
}

/// The integrator's plan of each interval u\[k\] → u\[k+1\] \[V\] from h\[k\] \[µm\] with
/// the parameters of row k of `params` (kv, x0, A, β, γ, n, δ: 7 values per interval,
/// row after row): the RK4 sub-steps, 0 where u holds, −1 where the implicit path is
/// taken ([`crate::model::interval_plan`]).
#[pyfunction]
pub fn _substep_plan<'py>(
    py: Python<'py>,
    params: &Bound<'py, PyAny>,
    h: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    dt: f64,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let (params, h, u) = (samples(params, "params")?, samples(h, "h")?, samples(u, "u")?);
    positive_dt(dt).map_err(value_error)?;
    let intervals = u.len().saturating_sub(1);
    if params.len() != 7 * intervals || h.len() != intervals {
        return Err(PyValueError::new_err(format!(
            "params and h need one row per interval: {intervals} × 7 and {intervals} values, got {} and {}",
            params.len(),
            h.len()
        )));
    }
    let plan = params
        .chunks_exact(7)
        .zip(&h)
        .zip(u.windows(2))
        .map(|((row, &h), w)| {
            let p = crate::Params {
                kv: row[0],
                x0: row[1],
                a: row[2],
                beta: row[3],
                gamma: row[4],
                n: row[5],
                delta: row[6],
            };
            crate::model::interval_plan(&p, h, w[0], w[1], dt).map_or(-1, i64::from)
        })
        .collect();
    Ok(PyArray1::from_vec(py, plan))
}

/// The paper's input u = 50 + 50·sin(2πft − π/2) \[V\], sampled every `dt` \[s\]:
/// 1 Hz for 3 s, 10 Hz to 3.3 s, 100 Hz to 3.33 s, then 200 Hz for `tail_s` \[s\].
///
/// ``segments``: (frequency \[Hz\], duration \[s\]) pairs in place of the paper's
/// four (``tail_s`` is then not used), each a whole number of periods so that every
/// switch falls on a minimum (u = 0). The record has round(T/dt) samples, T the total
/// duration, t = k·dt from 0.
#[pyfunction]
#[pyo3(signature = (dt, tail_s = 0.05, *, segments = None))]
pub fn paper_input<'py>(
    py: Python<'py>,
    dt: f64,
    tail_s: f64,
    segments: Option<Vec<(f64, f64)>>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    positive_dt(dt).map_err(value_error)?;
    let segments = match segments {
        None => {
            let tail_s = finite(tail_s, "tail_s")?;
            if tail_s < 0.0 {
                return Err(PyValueError::new_err(format!("tail_s = {tail_s} must be >= 0 s")));
            }
            crate::model::paper_segments(tail_s).to_vec()
        }
        Some(segments) => whole_periods(segments)?,
    };
    let total: f64 = segments.iter().map(|&(_, d)| d).sum();
    if total / dt > 1e9 {
        return Err(PyValueError::new_err(format!("{total} s at dt = {dt} s is more than 1e9 samples")));
    }
    Ok(PyArray1::from_vec(py, crate::model::sine_segments(dt, &segments)))
}

/// Checks that there is at least one segment and that each lasts a whole number (≥ 1)
/// of periods of its finite, positive frequency.
fn whole_periods(segments: Vec<(f64, f64)>) -> PyResult<Vec<(f64, f64)>> {
    if segments.is_empty() {
        return Err(PyValueError::new_err("segments must hold at least one (frequency, duration) pair"));
    }
    for &(f, d) in &segments {
        if !(f.is_finite() && f > 0.0 && d.is_finite() && d > 0.0) {
            return Err(PyValueError::new_err(format!(
                "segment ({f}, {d}): frequency [Hz] and duration [s] must be finite and > 0"
            )));
        }
        let periods = f * d;
        if (periods - periods.round()).abs() > 1e-6 * periods.max(1.0) || periods.round() < 1.0 {
            return Err(PyValueError::new_err(format!(
                "segment ({f}, {d}): {periods} periods, not a whole number; the switch would not fall on a minimum"
            )));
        }
    }
    Ok(segments)
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
