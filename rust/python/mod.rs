//! Python bindings: conversions and error mapping only; the numerics live in the
//! crate's other modules. Compiled with the `python` feature into `boucwen._core`.

mod bank;
mod compensate;
mod config;
mod effects;
mod errors;
mod extended_state;
mod identifier;
mod model;
mod oscillator;
mod params;
mod reconstruction;

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyUntypedArrayMethods};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;

pub(crate) use errors::{value_error, CorruptSnapshot, InvalidConfig, InvalidParams, InvalidRecord};

/// Converts any array-like to a contiguous 1-D float64 copy, with a precise error.
pub(crate) fn samples(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<f64>> {
    let py = obj.py();
    if obj.is_none() {
        return Err(PyTypeError::new_err(format!("{name} must be a 1-D array of numbers, got None")));
    }
    if obj.is_instance_of::<pyo3::types::PyString>() || obj.is_instance_of::<pyo3::types::PyBytes>() {
        return Err(PyTypeError::new_err(format!("{name} must be a 1-D array of numbers, got a string")));
    }
    let numpy = py.import("numpy")?;
    let array = numpy
        .call_method1("asarray", (obj,))
        .map_err(|_| PyTypeError::new_err(format!("{name} must be a 1-D array of numbers")))?;
    let kind: String = array.getattr("dtype")?.getattr("kind")?.extract()?;
    if !matches!(kind.as_str(), "f" | "i" | "u" | "b") {
        return Err(PyTypeError::new_err(format!(
            "{name} must hold real numbers, got an array of dtype {}",
            array.getattr("dtype")?.str()?
        )));
    }
    let array = numpy.call_method1("ascontiguousarray", (array, "float64"))?;
    let array: Bound<'_, PyArray1<f64>> = array.cast_into::<PyArray1<f64>>().map_err(|_| {
        let shape = obj.getattr("shape").map(|s| s.to_string()).unwrap_or_else(|_| "?".into());
        InvalidRecord::new_err(format!("{name} must be 1-D, got shape {shape}"))
    })?;
    let view: PyReadonlyArray1<'_, f64> = array.readonly();
    let _ = view.len();
    Ok(view.as_slice().map_err(|e| InvalidRecord::new_err(format!("{name}: {e}")))?.to_vec())
}

/// Checks that a float option is finite (`InvalidConfig` if not).
pub(crate) fn finite(value: f64, name: &str) -> PyResult<f64> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(InvalidConfig::new_err(format!("{name} = {value} must be finite")))
    }
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add_class::<params::PyParams>()?;
    m.add_class::<model::PyModel>()?;
    m.add_class::<identifier::PyIdentifier>()?;
    m.add_class::<bank::PyBank>()?;
    m.add_function(wrap_pyfunction!(config::_config_defaults, m)?)?;
    m.add_function(wrap_pyfunction!(config::_validate_config, m)?)?;
    m.add_function(wrap_pyfunction!(model::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(model::simulate_many, m)?)?;
    m.add_function(wrap_pyfunction!(model::_substep_plan, m)?)?;
    m.add_class::<effects::PyEffectSet>()?;
    m.add_class::<extended_state::PyExtendedState>()?;
    m.add_function(wrap_pyfunction!(effects::simulate_extended, m)?)?;
    m.add_function(wrap_pyfunction!(effects::simulate_extended_with_jacobian, m)?)?;
    m.add_function(wrap_pyfunction!(model::paper_input, m)?)?;
    m.add_class::<compensate::PyInverse>()?;
    m.add_function(wrap_pyfunction!(compensate::invert, m)?)?;
    m.add_function(wrap_pyfunction!(oscillator::oscillator_simulate, m)?)?;
    m.add_function(wrap_pyfunction!(oscillator::oscillator_simulate_with_jacobian, m)?)?;
    m.add_function(wrap_pyfunction!(oscillator::oscillator_newmark, m)?)?;
    m.add("OSCILLATOR_UNKNOWNS", crate::oscillator::UNKNOWNS.to_vec())?;
    m.add_class::<reconstruction::PyInputPath>()?;
    m.add_function(wrap_pyfunction!(reconstruction::bandlimited_error_bound, m)?)?;
    m.add("INPUT_CHOICES", crate::reconstruction::Reconstruction::NAMES.to_vec())?;
    m.add_class::<compensate::PyCompensator>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("INVERSE_TOLERANCE_UM", crate::compensate::inverse::TOLERANCE_UM)?;
    m.add("RESONANCE_SUBSTEPS", crate::effects::RESONANCE_SUBSTEPS)?;
    Ok(())
}
