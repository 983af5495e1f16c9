//! `boucwen.Bank`: C channels (identifier + model each) stepped one frame per call.

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyIndexError, PyTypeError};
use pyo3::prelude::*;

use super::config::{paper_config, rpem_config};
use super::errors::LengthMismatch;
use super::params::PyParams;
use super::{samples, value_error, InvalidConfig, InvalidRecord};
use crate::bank::Bank;
use crate::identify::{AnyIdentifier, OnlineIdentifier, PaperIdentifier, RpemConfig, RpemIdentifier};

/// C independent channels, each an online identifier and a model, stepped with one
/// call per frame (adaptive optics, multi-axis stages).
///
/// - `Bank(channels, dt, init, h0=0.0, *, config=None)`: rpem channels (as `Bank.rpem`);
/// - `Bank.rpem(channels, dt, init, h0=0.0, *, config=None)`;
/// - `Bank.paper(channels, dt, window, init, h0=0.0, *, config=None)`.
///
/// Every channel starts from `init` (parameters) and `h0` \[µm\] and then learns on its
/// own; its results are bit for bit those of a single `Identifier` (and `Model`) fed
/// the same samples. `push(u, x)` takes one frame (C voltages \[V\], C measurements
/// \[µm\]) and returns the C predictions \[µm\]; `push_many(u, x)` takes (T, C) arrays
/// and returns (T, C) predictions, with the GIL released. `step_models(u)` /
/// `step_models_many(u)` run the channels' models (parameters from `init` until
/// `adopt_estimates()` hands them the identifiers' current estimates). A frame or a
/// call with a non-finite value raises ValueError before any channel changes.
#[pyclass(name = "Bank", module = "boucwen")]
#[derive(Clone)]
pub struct PyBank {
    inner: Bank<AnyIdentifier>,
}

fn channel_count(channels: i64) -> PyResult<usize> {
    if !(1..=1 << 20).contains(&channels) {
        return Err(InvalidConfig::new_err(format!("invalid channels = {channels}: a bank has 1 to 1048576 channels")));
    }
    Ok(channels as usize)
}

/// A (T, C) array-like as a contiguous row-major float64 copy; returns (values, T).
fn frames(obj: &Bound<'_, PyAny>, name: &str, channels: usize) -> PyResult<(Vec<f64>, usize)> {
    let py = obj.py();
    let numpy = py.import("numpy")?;
    let array = numpy
        .call_method1("asarray", (obj,))
        .map_err(|_| PyTypeError::new_err(format!("{name} must be a (T, C) array of numbers")))?;
    let kind: String = array.getattr("dtype")?.getattr("kind")?.extract()?;
    if !matches!(kind.as_str(), "f" | "i" | "u" | "b") {
        return Err(PyTypeError::new_err(format!("{name} must hold real numbers")));
    }
    let array = numpy.call_method1("ascontiguousarray", (array, "float64"))?;
    let shape = array.getattr("shape")?.to_string();
    let array: Bound<'_, PyArray2<f64>> = array
        .cast_into::<PyArray2<f64>>()
        .map_err(|_| InvalidRecord::new_err(format!("{name} must be 2-D (T, C), got shape {shape}")))?;
    let view: PyReadonlyArray2<'_, f64> = array.readonly();
    let [rows, cols] = [view.shape()[0], view.shape()[1]];
    if cols != channels {
        return Err(LengthMismatch::new_err(format!("{name} must have shape (T, {channels}), got {shape}")));
    }
    Ok((view.as_slice().map_err(|e| InvalidRecord::new_err(format!("{name}: {e}")))?.to_vec(), rows))
}

#[pymethods]
impl PyBank {
    #[new]
    #[pyo3(signature = (channels, dt, init, h0 = 0.0, *, config = None))]
    fn new(channels: i64, dt: f64, init: &PyParams, h0: f64, config: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        Self::rpem(channels, dt, init, h0, config)
    }

    /// A bank of rpem channels; see the class docs.
    #[staticmethod]
    #[pyo3(signature = (channels, dt, init, h0 = 0.0, *, config = None))]
    fn rpem(channels: i64, dt: f64, init: &PyParams, h0: f64, config: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let channels = channel_count(channels)?;
        let cfg = rpem_config(config, RpemConfig::default())?;
        let id = RpemIdentifier::new(dt, init.inner, h0, cfg).map_err(value_error)?;
        let inner = Bank::new(channels, AnyIdentifier::Rpem(id), dt).map_err(value_error)?;
        Ok(PyBank { inner })
    }

    /// A bank of channels of the paper's method over `window` samples; see the class docs.
    #[staticmethod]
    #[pyo3(signature = (channels, dt, window, init, h0 = 0.0, *, config = None))]
    fn paper(
        channels: i64,
        dt: f64,
        window: i64,
        init: &PyParams,
        h0: f64,
        config: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let channels = channel_count(channels)?;
        let cfg = paper_config(config, window)?;
        let id = PaperIdentifier::new(dt, init.inner, h0, cfg).map_err(value_error)?;
        let inner = Bank::new(channels, AnyIdentifier::Paper(id), dt).map_err(value_error)?;
        Ok(PyBank { inner })
    }

    /// The number of channels C.
    #[getter]
    fn channels(&self) -> usize {
        self.inner.channels()
    }

    /// The online method of every channel: "rpem" or "paper".
    #[getter]
    fn method(&self) -> &'static str {
        self.inner.identifiers()[0].method()
    }

    /// One frame: u \[V\] and x \[µm\], C values each; returns the C predictions \[µm\].
    fn push<'py>(
        &mut self,
        py: Python<'py>,
        u: &Bound<'py, PyAny>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (u, x) = (samples(u, "u")?, samples(x, "x")?);
        let mut out = vec![0.0; self.inner.channels()];
        self.inner.push(&u, &x, &mut out).map_err(value_error)?;
        Ok(PyArray1::from_vec(py, out))
    }

    /// T frames: u \[V\] and x \[µm\] of shape (T, C); returns (T, C) predictions \[µm\],
    /// identical to T calls of `push`. The GIL is released while it runs.
    fn push_many<'py>(
        &mut self,
        py: Python<'py>,
        u: &Bound<'py, PyAny>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let channels = self.inner.channels();
        let (u, rows) = frames(u, "u", channels)?;
        let (x, x_rows) = frames(x, "x", channels)?;
        if x_rows != rows {
            return Err(LengthMismatch::new_err(format!("x has {x_rows} frames, u has {rows}")));
        }
        let inner = &mut self.inner;
        let out = py
            .detach(move || {
                let mut out = vec![0.0; u.len()];
                inner.push_many(&u, &x, &mut out).map(|_| out)
            })
            .map_err(value_error)?;
        PyArray1::from_vec(py, out).reshape([rows, channels])
    }

    /// One frame for the models: C voltages \[V\] in, C displacements \[µm\] out.
    fn step_models<'py>(&mut self, py: Python<'py>, u: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let u = samples(u, "u")?;
        let mut out = vec![0.0; self.inner.channels()];
        self.inner.step_models(&u, &mut out).map_err(value_error)?;
        Ok(PyArray1::from_vec(py, out))
    }

    /// T frames for the models: u of shape (T, C) \[V\]; returns (T, C) displacements
    /// \[µm\]. The GIL is released while it runs.
    fn step_models_many<'py>(&mut self, py: Python<'py>, u: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let channels = self.inner.channels();
        let (u, rows) = frames(u, "u", channels)?;
        let inner = &mut self.inner;
        let out = py
            .detach(move || {
                if let Some(bad) = u.iter().find(|v| !v.is_finite()) {
                    return Err(crate::Error::NonFiniteSample { name: "u", value: *bad });
                }
                let mut out = vec![0.0; u.len()];
                for (uf, of) in u.chunks_exact(channels).zip(out.chunks_exact_mut(channels)) {
                    inner.step_models(uf, of)?;
                }
                Ok(out)
            })
            .map_err(value_error)?;
        PyArray1::from_vec(py, out).reshape([rows, channels])
    }

    /// Every model takes its identifier's current estimates, and every inverse too
    /// where they keep x(u) rising (states kept).
    fn adopt_estimates(&mut self) -> PyResult<()> {
        self.inner.adopt_estimates().map_err(value_error)
    }

    /// One frame of feedforward: C desired displacements x_d \[µm\] in, the C voltages
    /// \[V\] at which each channel's inverse model reaches them out (each channel as a
    /// single `Inverse` with the channel's adopted parameters).
    fn feedforward<'py>(&mut self, py: Python<'py>, x_d: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let x_d = samples(x_d, "x_d")?;
        let mut out = vec![0.0; self.inner.channels()];
        self.inner.feedforward(&x_d, &mut out).map_err(value_error)?;
        Ok(PyArray1::from_vec(py, out))
    }

    /// Voltage limits \[V\] of every channel's inverse (None: no limit on that side).
    #[pyo3(signature = (u_min = None, u_max = None))]
    fn set_voltage_limits(&mut self, u_min: Option<f64>, u_max: Option<f64>) -> PyResult<()> {
        let limits = crate::compensate::VoltageLimits::new(u_min, u_max).map_err(value_error)?;
        self.inner.set_voltage_limits(limits).map_err(value_error)
    }

    /// The parameters of channel `channel`'s inverse.
    fn inverse_params(&self, channel: usize) -> PyResult<PyParams> {
        self.inner
            .inverses()
            .get(channel)
            .map(|inv| PyParams { inner: *inv.params() })
            .ok_or_else(|| PyIndexError::new_err(format!("channel {channel} out of range")))
    }

    /// The current estimates of channel `channel`'s identifier.
    fn params(&self, channel: usize) -> PyResult<PyParams> {
        self.inner
            .identifiers()
            .get(channel)
            .map(|id| PyParams { inner: id.params() })
            .ok_or_else(|| PyIndexError::new_err(format!("channel {channel} out of range")))
    }

    /// The parameters of channel `channel`'s model.
    fn model_params(&self, channel: usize) -> PyResult<PyParams> {
        if channel >= self.inner.channels() {
            return Err(PyIndexError::new_err(format!("channel {channel} out of range")));
        }
        Ok(PyParams { inner: self.inner.models().params(channel) })
    }

    /// Every identifier, model and inverse back to its state right after construction.
    fn reset(&mut self) {
        self.inner.reset()
    }

    fn __repr__(&self) -> String {
        format!("Bank(method={:?}, channels={})", self.method(), self.inner.channels())
    }
}
