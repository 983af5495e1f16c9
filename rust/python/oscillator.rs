//! `boucwen._core.oscillator_simulate` and `oscillator_simulate_with_jacobian`: the
//! hysteretic oscillator ([`crate::oscillator`]) on NumPy arrays.

use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;

use super::effects::OutputAndJacobian;
use super::{samples, value_error, InvalidParams};
use crate::oscillator::{OscillatorParams, OscillatorState};

/// The parameters (8 values in the order of [`OscillatorParams::NAMES`], validated), the
/// force samples and the initial state of a call.
fn arguments(
    params: Vec<f64>,
    force: &Bound<'_, PyAny>,
    y0: f64,
    v0: f64,
    z0: f64,
) -> PyResult<(OscillatorParams, Vec<f64>, OscillatorState)> {
    let array: [f64; 8] = params.try_into().map_err(|v: Vec<f64>| {
        InvalidParams::new_err(format!(
            "the oscillator takes 8 parameters (m, c, k, alpha, beta, gamma, delta, nu), got {}",
            v.len()
        ))
    })?;
    let p = OscillatorParams::from_array(array).map_err(value_error)?;
    Ok((p, samples(force, "force")?, OscillatorState { y: y0, v: v0, z: z0 }))
}

/// Simulates the hysteretic oscillator m·ÿ + c·ẏ + k·y + z = F,
/// ż = α·ẏ − β·(γ·|ẏ|·|z|^(ν−1)·z + δ·ẏ·|z|^ν) over a record.
///
/// `params`: m \[kg\], c \[N·s/m\], k \[N/m\], α \[N/m\], β \[N^(1−ν)/m\], γ, δ, ν \[-\];
/// `force` F \[N\] every `dt` \[s\], linear between samples; the state at sample 0 is
/// (`y0` \[m\], `v0` \[m/s\], `z0` \[N\]). Returns y \[m\] at every sample. The GIL is
/// released while it runs.
#[pyfunction]
#[pyo3(signature = (params, force, dt, y0 = 0.0, v0 = 0.0, z0 = 0.0))]
pub fn oscillator_simulate<'py>(
    py: Python<'py>,
    params: Vec<f64>,
    force: &Bound<'py, PyAny>,
    dt: f64,
    y0: f64,
    v0: f64,
    z0: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (p, force, start) = arguments(params, force, y0, v0, z0)?;
    let (y, _) = py.detach(move || crate::oscillator::simulate(&p, &force, dt, start)).map_err(value_error)?;
    Ok(PyArray1::from_vec(py, y))
}

/// [`oscillator_simulate`] with the exact Jacobian of y: returns `(y, jac)`, `jac` of shape
/// (samples, 10) with the columns ∂y/∂(m, c, k, α, γ, δ, ν, y0, v0, z0) (β has none: it
/// enters only as β·γ and β·δ).
#[pyfunction]
#[pyo3(signature = (params, force, dt, y0 = 0.0, v0 = 0.0, z0 = 0.0))]
pub fn oscillator_simulate_with_jacobian<'py>(
    py: Python<'py>,
    params: Vec<f64>,
    force: &Bound<'py, PyAny>,
    dt: f64,
    y0: f64,
    v0: f64,
    z0: f64,
) -> PyResult<OutputAndJacobian<'py>> {
    let (p, force, start) = arguments(params, force, y0, v0, z0)?;
    let n = force.len();
    let (y, jac) =
        py.detach(move || crate::oscillator::simulate_with_jacobian(&p, &force, dt, start)).map_err(value_error)?;
    let jac = PyArray1::from_vec(py, jac).reshape([n, crate::oscillator::UNKNOWNS.len()])?;
    Ok((PyArray1::from_vec(py, y), jac))
}
