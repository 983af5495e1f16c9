//! `boucwen.Params`: frozen, comparable, picklable, round-tripping `repr`.

use numpy::PyArray1;
use pyo3::exceptions::PyKeyError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use super::{samples, value_error, InvalidParams};
use crate::Params;

/// Parameters of the asymmetric Bouc–Wen model (Zhu, Bian & Rui 2014, eqs. 3 and 5):
///
///     x = kv·u + x0 + h
///     dh/dt = A·u̇ − β·|u̇|·|h|^(n−1)·h − γ·u̇·|h|^n + δ·u·sgn(u̇)
///
/// kv \[µm/V\], x0 \[µm\], A \[µm/V\], beta and gamma [µm^(1−n)/V], n \[-\] (> 0),
/// delta \[µm/(V·s)\]. Immutable; all values finite.
#[pyclass(name = "Params", module = "boucwen", frozen, eq)]
#[derive(Clone, Copy, PartialEq)]
pub struct PyParams {
    pub inner: Params,
}

// PyO3 methods take `&self`, even on a `Copy` class.
#[allow(clippy::wrong_self_convention)]
#[pymethods]
impl PyParams {
    #[new]
    #[pyo3(signature = (kv, x0, A, beta, gamma, n, delta))]
    #[allow(non_snake_case)]
    fn new(kv: f64, x0: f64, A: f64, beta: f64, gamma: f64, n: f64, delta: f64) -> PyResult<Self> {
        Params::new(kv, x0, A, beta, gamma, n, delta).map(|inner| PyParams { inner }).map_err(value_error)
    }

    /// The paper's Table 2 values identified at 1 Hz.
    #[staticmethod]
    fn paper_1hz() -> Self {
        PyParams { inner: Params::paper_1hz() }
    }

    /// Parameter names in array order.
    #[classattr]
    fn names() -> Vec<&'static str> {
        Params::NAMES.to_vec()
    }

    /// Linear gain kv \[µm/V\].
    #[getter]
    fn kv(&self) -> f64 {
        self.inner.kv
    }
    /// Offset x0 \[µm\].
    #[getter]
    fn x0(&self) -> f64 {
        self.inner.x0
    }
    /// Hysteresis gain A \[µm/V\].
    #[getter(A)]
    fn a(&self) -> f64 {
        self.inner.a
    }
    /// β [µm^(1−n)/V].
    #[getter]
    fn beta(&self) -> f64 {
        self.inner.beta
    }
    /// γ [µm^(1−n)/V].
    #[getter]
    fn gamma(&self) -> f64 {
        self.inner.gamma
    }
    /// Shape exponent n \[-\].
    #[getter]
    fn n(&self) -> f64 {
        self.inner.n
    }
    /// Asymmetry δ \[µm/(V·s)\].
    #[getter]
    fn delta(&self) -> f64 {
        self.inner.delta
    }

    /// Raises `InvalidParams` (one line naming the combination) unless the parameters
    /// are in the admissible region, where h stays bounded: β + γ ≥ 0 and β − γ ≥ 0,
    /// both > 0 where δ ≠ 0 (docs/design.md, "The admissible region").
    fn check_admissible(&self) -> PyResult<()> {
        self.inner.check_admissible().map_err(value_error)
    }

    /// `[kv, x0, A, beta, gamma, n, delta]` as a float64 array.
    fn to_array<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.to_array())
    }

    /// Inverse of `to_array`; ValueError naming the parameter if one is invalid.
    #[staticmethod]
    fn from_array(values: &Bound<'_, PyAny>) -> PyResult<Self> {
        let v = samples(values, "values")?;
        let arr: [f64; 7] = v.try_into().map_err(|v: Vec<f64>| {
            InvalidParams::new_err(format!("expected 7 values {:?}, got {}", Params::NAMES, v.len()))
        })?;
        Params::from_array(arr).map(|inner| PyParams { inner }).map_err(value_error)
    }

    /// `{"kv": …, "x0": …, "A": …, "beta": …, "gamma": …, "n": …, "delta": …}`.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in Params::NAMES.iter().zip(self.inner.to_array()) {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// Inverse of `to_dict`; every key required, no other key allowed.
    #[staticmethod]
    fn from_dict(d: &Bound<'_, PyDict>) -> PyResult<Self> {
        let mut v = [0.0; 7];
        for (slot, name) in v.iter_mut().zip(Params::NAMES) {
            let item = d.get_item(name)?.ok_or_else(|| PyKeyError::new_err(format!("missing parameter {name}")))?;
            *slot = item
                .extract::<f64>()
                .map_err(|_| InvalidParams::new_err(format!("parameter {name} must be a number")))?;
        }
        for key in d.keys() {
            let key: String = key.str()?.to_string();
            if !Params::NAMES.contains(&key.as_str()) {
                return Err(InvalidParams::new_err(format!("unknown parameter {key}; expected {:?}", Params::NAMES)));
            }
        }
        Params::from_array(v).map(|inner| PyParams { inner }).map_err(value_error)
    }

    /// A copy with some values replaced, e.g. `p.replace(n=1.6)`.
    #[pyo3(signature = (**changes))]
    fn replace(&self, py: Python<'_>, changes: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let d = self.to_dict(py)?;
        if let Some(c) = changes {
            d.update(c.as_mapping())?;
        }
        Self::from_dict(&d)
    }

    fn __repr__(&self) -> String {
        let p = &self.inner;
        format!(
            "Params(kv={:?}, x0={:?}, A={:?}, beta={:?}, gamma={:?}, n={:?}, delta={:?})",
            p.kv, p.x0, p.a, p.beta, p.gamma, p.n, p.delta
        )
    }

    fn __hash__(&self) -> u64 {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        for v in self.inner.to_array() {
            (if v == 0.0 { 0.0f64 } else { v }).to_bits().hash(&mut h);
        }
        h.finish()
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let p = slf.get().inner;
        let args = PyTuple::new(slf.py(), p.to_array())?;
        Ok((slf.get_type().into_any(), args))
    }
}
