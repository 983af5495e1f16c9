//! `boucwen._core.oscillator_simulate` and `oscillator_simulate_with_jacobian`: the
//! hysteretic oscillator ([`crate::oscillator`]) on NumPy arrays.

use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;

use super::effects::OutputAndJacobian;
use super::reconstruction::path_of;
use super::{samples, value_error, InvalidParams};
use crate::oscillator::{OscillatorParams, OscillatorState};
use crate::reconstruction::InputPath;

/// The parameters of a call: 8 values in the order of [`OscillatorParams::NAMES`],
/// validated.
fn parameters(params: Vec<f64>) -> PyResult<OscillatorParams> {
    let array: [f64; 8] = params.try_into().map_err(|v: Vec<f64>| {
        InvalidParams::new_err(format!(
            "the oscillator takes 8 parameters (m, c, k, alpha, beta, gamma, delta, nu), got {}",
            v.len()
        ))
    })?;
    OscillatorParams::from_array(array).map_err(value_error)
}

/// The parameters, the force between samples and the initial state of a call.
fn arguments(
    params: Vec<f64>,
    force: &Bound<'_, PyAny>,
    input: Option<&str>,
    periodic: Option<bool>,
    start: (f64, f64, f64),
) -> PyResult<(OscillatorParams, InputPath, OscillatorState)> {
    let (y, v, z) = start;
    Ok((parameters(params)?, path_of(force, input, periodic)?, OscillatorState { y, v, z }))
}

/// Simulates the hysteretic oscillator m·ÿ + c·ẏ + k·y + z = F,
/// ż = α·ẏ − β·(γ·|ẏ|·|z|^(ν−1)·z + δ·ẏ·|z|^ν) over a record.
///
/// `params`: m \[kg\], c \[N·s/m\], k \[N/m\], α \[N/m\], β \[N^(1−ν)/m\], γ, δ, ν \[-\];
/// `force` F \[N\] every `dt` \[s\], between samples as `input` says (`"hold"`,
/// `"linear"` (default), `"bandlimited"`; `periodic`: the record is a whole number of
/// periods), or an `InputPath`; the state at sample 0 is (`y0` \[m\], `v0` \[m/s\],
/// `z0` \[N\]). Returns y \[m\] at every sample. The GIL is released while it runs.
#[pyfunction]
#[pyo3(signature = (params, force, dt, y0 = 0.0, v0 = 0.0, z0 = 0.0, *, input = None, periodic = None))]
#[allow(clippy::too_many_arguments)]
pub fn oscillator_simulate<'py>(
    py: Python<'py>,
    params: Vec<f64>,
    force: &Bound<'py, PyAny>,
    dt: f64,
    y0: f64,
    v0: f64,
    z0: f64,
    input: Option<&str>,
    periodic: Option<bool>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (p, path, start) = arguments(params, force, input, periodic, (y0, v0, z0))?;
    let (y, _) = py.detach(move || crate::oscillator::simulate_path(&p, &path, dt, start)).map_err(value_error)?;
    Ok(PyArray1::from_vec(py, y))
}

/// [`oscillator_simulate`] with the exact Jacobian of y: returns `(y, jac)`, `jac` of shape
/// (samples, 10) with the columns ∂y/∂(m, c, k, α, γ, δ, ν, y0, v0, z0) (β has none: it
/// enters only as β·γ and β·δ).
#[pyfunction]
#[pyo3(signature = (params, force, dt, y0 = 0.0, v0 = 0.0, z0 = 0.0, *, input = None, periodic = None))]
#[allow(clippy::too_many_arguments)]
pub fn oscillator_simulate_with_jacobian<'py>(
    py: Python<'py>,
    params: Vec<f64>,
    force: &Bound<'py, PyAny>,
    dt: f64,
    y0: f64,
    v0: f64,
    z0: f64,
    input: Option<&str>,
    periodic: Option<bool>,
) -> PyResult<OutputAndJacobian<'py>> {
    let (p, path, start) = arguments(params, force, input, periodic, (y0, v0, z0))?;
    let n = path.len();
    let (y, jac) =
        py.detach(move || crate::oscillator::simulate_path_with_jacobian(&p, &path, dt, start)).map_err(value_error)?;
    let jac = PyArray1::from_vec(py, jac).reshape([n, crate::oscillator::UNKNOWNS.len()])?;
    Ok((PyArray1::from_vec(py, y), jac))
}

/// The benchmark's own integration of the oscillator: Newmark's average-acceleration
/// scheme (a = 0.5, b = 0.25) with z by the trapezoidal rule, each step solved by
/// Newton's method ([`crate::oscillator::newmark`]). `force` F \[N\] every `h` \[s\] (the
/// integration's own step: the benchmark's 15 kHz); returns y \[m\] at every step. For
/// replicating the benchmark's records; second order, no Jacobian.
#[pyfunction]
#[pyo3(signature = (params, force, h, y0 = 0.0, v0 = 0.0, z0 = 0.0))]
pub fn oscillator_newmark<'py>(
    py: Python<'py>,
    params: Vec<f64>,
    force: &Bound<'py, PyAny>,
    h: f64,
    y0: f64,
    v0: f64,
    z0: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let p = parameters(params)?;
    let force = samples(force, "force")?;
    let start = OscillatorState { y: y0, v: v0, z: z0 };
    let y = py.detach(move || crate::oscillator::newmark::newmark(&p, &force, h, start)).map_err(value_error)?;
    Ok(PyArray1::from_vec(py, y))
}
