//! `boucwen._core.InputPath`: a sampled input rebuilt between its samples
//! ([`crate::reconstruction`]), built once and handed to the simulators.

use numpy::PyArray1;
use pyo3::prelude::*;

use super::{samples, value_error, InvalidConfig};
use crate::reconstruction::{sinc, InputPath, Reconstruction};

/// The reconstruction called `name`, or `InvalidConfig` naming the choices.
pub(crate) fn reconstruction(name: &str) -> PyResult<Reconstruction> {
    Reconstruction::from_name(name).ok_or_else(|| {
        InvalidConfig::new_err(format!(
            "input = {name:?}: what the input does between samples is one of {:?}",
            Reconstruction::NAMES
        ))
    })
}

/// A sampled input as a function of time over its record: ``input`` is ``"hold"``
/// (zero-order hold, a DAC), ``"linear"`` (a straight line between samples) or
/// ``"bandlimited"`` (the band-limited signal through the samples: the exact Fourier
/// interpolation where ``periodic`` says the record holds a whole number of periods of
/// its input, else a Kaiser-windowed sinc of 32 samples on either side). Built once per
/// record (the band-limited one takes its DFT), then passed to the simulators in place
/// of the samples.
#[pyclass(name = "InputPath", module = "boucwen", frozen)]
pub struct PyInputPath {
    pub inner: InputPath,
    periodic: bool,
}

#[pymethods]
impl PyInputPath {
    #[new]
    #[pyo3(signature = (samples, input = "linear", periodic = false))]
    fn new(py: Python<'_>, samples: &Bound<'_, PyAny>, input: &str, periodic: bool) -> PyResult<Self> {
        let kind = reconstruction(input)?;
        let values = super::samples(samples, "samples")?;
        finite(&values, "samples")?;
        let inner = py.detach(move || InputPath::new(&values, kind, periodic)).map_err(value_error)?;
        Ok(PyInputPath { inner, periodic })
    }

    /// What the input does between samples: ``"hold"``, ``"linear"`` or ``"bandlimited"``.
    #[getter]
    fn input(&self) -> &'static str {
        self.inner.kind().name()
    }

    /// Whether the record was taken as a whole number of periods.
    #[getter]
    fn periodic(&self) -> bool {
        self.periodic
    }

    /// The band-limited path's content reaches this frequency, as a fraction of the
    /// sample rate (0 for hold and linear).
    #[getter]
    fn band(&self) -> f64 {
        self.inner.band()
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// The input at ``per_interval`` equally spaced points of every interval (the first
    /// sample, then for each interval the points after its start up to its end):
    /// (len − 1)·per_interval + 1 values [the samples' unit].
    #[pyo3(signature = (per_interval = 8))]
    fn values<'py>(&self, py: Python<'py>, per_interval: usize) -> PyResult<Bound<'py, PyArray1<f64>>> {
        if per_interval == 0 {
            return Err(InvalidConfig::new_err("per_interval must be >= 1"));
        }
        let n = self.inner.len();
        let mut out = Vec::with_capacity(n.saturating_sub(1) * per_interval + 1);
        out.extend(self.inner.samples().first().copied());
        for k in 1..n {
            for j in 1..=per_interval {
                out.push(self.inner.at(k, j as f64 / per_interval as f64));
            }
        }
        Ok(PyArray1::from_vec(py, out))
    }

    fn __repr__(&self) -> String {
        format!("InputPath({} samples, input={:?}, periodic={})", self.inner.len(), self.input(), self.periodic)
    }
}

/// The largest error of the band-limited reconstruction of a record that is not periodic
/// (the Kaiser-windowed sinc), as a fraction of the line amplitudes, for content up to
/// ``band`` × the Nyquist frequency (0 < band < 1), at least 32 samples from either end.
#[pyfunction]
pub fn bandlimited_error_bound(band: f64) -> PyResult<f64> {
    if !(band > 0.0 && band < 1.0) {
        return Err(InvalidConfig::new_err(format!("band = {band}: a fraction of the Nyquist frequency in (0, 1)")));
    }
    Ok(sinc::error_bound(band))
}

/// Every value finite, or the error naming the first that is not as `name`.
fn finite(values: &[f64], name: &'static str) -> PyResult<()> {
    values.iter().try_for_each(|&v| crate::error::finite_sample(name, v).map(|_| ())).map_err(value_error)
}

/// The record's ``force`` argument: an ``InputPath`` as given (then ``input`` and
/// ``periodic`` must be left unset), or samples rebuilt by ``input`` (default linear).
pub(crate) fn path_of(force: &Bound<'_, PyAny>, input: Option<&str>, periodic: Option<bool>) -> PyResult<InputPath> {
    if let Ok(path) = force.cast::<PyInputPath>() {
        if input.is_some() || periodic.is_some() {
            return Err(InvalidConfig::new_err(
                "an InputPath already says what the input does between samples: leave input and periodic unset",
            ));
        }
        return Ok(path.get().inner.clone());
    }
    let kind = reconstruction(input.unwrap_or("linear"))?;
    let values = samples(force, "force")?;
    finite(&values, "F")?;
    InputPath::new(&values, kind, periodic.unwrap_or(false)).map_err(value_error)
}
