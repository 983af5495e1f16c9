//! `boucwen.ExtendedState`: the state `simulate_extended` continues from.

use pyo3::prelude::*;
use pyo3::types::PyType;

use super::value_error;
use crate::effects::ExtendedState;

/// The values `ExtendedState.__reduce__` writes, in the order of `_restore`'s arguments.
type StateArgs = (u64, Option<f64>, f64, f64, Option<(f64, f64)>, Vec<f64>, f64, (f64, f64), (f64, f64), Vec<f64>);

/// The state of the extended chain between two samples: what
/// ``simulate_extended(..., state=s)`` continues from and returns.
///
/// ``ExtendedState(h0=0.0)`` is the state before any sample, h = ``h0`` \[µm\]; the
/// state after a piece of record comes from ``simulate_extended``. Immutable,
/// comparable, picklable. A state holds one value per creep element and the delay
/// line, so it fits the effects that made it (others raise ``ValueError``).
#[pyclass(name = "ExtendedState", module = "boucwen", frozen, eq)]
#[derive(Clone, PartialEq)]
pub struct PyExtendedState {
    pub(crate) inner: ExtendedState,
}

#[pymethods]
impl PyExtendedState {
    #[new]
    #[pyo3(signature = (h0 = 0.0))]
    fn new(h0: f64) -> PyResult<Self> {
        let h0 = super::finite(h0, "h0")?;
        Ok(PyExtendedState { inner: ExtendedState::initial(h0) })
    }

    /// Samples taken so far; the next one is at t = samples·dt.
    #[getter]
    fn samples(&self) -> u64 {
        self.inner.samples
    }

    /// Commanded voltage of the last sample \[V\] (None: no sample yet).
    #[getter]
    fn u_prev(&self) -> Option<f64> {
        self.inner.u_prev
    }

    /// Voltage on the stack after the last sample \[V\] (the input lag's output).
    #[getter]
    fn ua(&self) -> f64 {
        self.inner.ua
    }

    /// Hysteresis state h \[µm\].
    #[getter]
    fn h(&self) -> f64 {
        self.inner.h
    }

    /// The creep elements c_i \[µm\], in the order of the creep's time constants.
    #[getter]
    fn creep(&self) -> Vec<f64> {
        self.inner.creep.clone()
    }

    /// The stack's displacement at the last sample \[µm\].
    #[getter]
    fn y(&self) -> f64 {
        self.inner.y
    }

    /// The first mode's (z \[µm\], ż \[µm/s\]).
    #[getter]
    fn resonance(&self) -> (f64, f64) {
        (self.inner.resonance[0], self.inner.resonance[1])
    }

    /// The second mode's (z \[µm\], ż \[µm/s\]).
    #[getter]
    fn resonance2(&self) -> (f64, f64) {
        (self.inner.resonance2[0], self.inner.resonance2[1])
    }

    /// The delay line's d + 1 values \[µm\], oldest first (empty before the first sample).
    #[getter]
    fn delay(&self) -> Vec<f64> {
        self.inner.delay.clone()
    }

    fn __repr__(&self) -> String {
        let s = &self.inner;
        format!("ExtendedState(samples={}, u_prev={:?}, h={:?})", s.samples, s.u_prev, s.h)
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, StateArgs)> {
        let s = &slf.get().inner;
        let args = (
            s.samples,
            s.u_prev,
            s.ua,
            s.h,
            s.h_pow_n,
            s.creep.clone(),
            s.y,
            (s.resonance[0], s.resonance[1]),
            (s.resonance2[0], s.resonance2[1]),
            s.delay.clone(),
        );
        Ok((slf.get_type().getattr("_restore")?, args))
    }

    /// Rebuilds a state from the values written by `__reduce__` (ValueError if invalid).
    #[classmethod]
    #[allow(clippy::too_many_arguments)]
    fn _restore(
        _cls: &Bound<'_, PyType>,
        samples: u64,
        u_prev: Option<f64>,
        ua: f64,
        h: f64,
        h_pow_n: Option<(f64, f64)>,
        creep: Vec<f64>,
        y: f64,
        resonance: (f64, f64),
        resonance2: (f64, f64),
        delay: Vec<f64>,
    ) -> PyResult<Self> {
        let inner = ExtendedState {
            samples,
            u_prev,
            ua,
            h,
            h_pow_n,
            creep,
            y,
            resonance: [resonance.0, resonance.1],
            resonance2: [resonance2.0, resonance2.1],
            delay,
        };
        let delay_samples = inner.delay.len().max(1) - 1;
        inner.check(inner.creep.len(), delay_samples).map_err(value_error)?;
        Ok(PyExtendedState { inner })
    }
}
