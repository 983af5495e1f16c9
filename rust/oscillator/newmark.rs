//! Newmark's average-acceleration scheme for the oscillator (a = 0.5, b = 0.25), the
//! integrator of the Bouc–Wen benchmark's own simulator (Noël & Schoukens 2016, at 20×
//! the sampling rate): for replicating its records, not for fitting (second order, no
//! sensitivities).
//!
//! The mass: y₊ = y + h·ẏ + h²·(¼·ÿ + ¼·ÿ₊), ẏ₊ = ẏ + h·(½·ÿ + ½·ÿ₊), with
//! m·ÿ₊ + c·ẏ₊ + k·y₊ + z₊ = F₊ at the step's end. The benchmark's simulator is
//! distributed as p-code, which does not say how it steps z; here z takes the
//! trapezoidal rule, the scheme's own rule for a first-order state (its velocity update
//! is the trapezoidal rule too): z₊ = z + h/2·(ż + ż₊). The two unknowns ÿ₊ and z₊ are
//! solved by Newton's method at every step until the update is below 1e-14 of them (at
//! most [`NEWTON_ITERATIONS`]).

use alloc::vec::Vec;

use super::{check, OscillatorParams, OscillatorState};
use crate::error::Result;
use crate::math;
use crate::model::integrator::sgn;

/// Newton iterations per step, at most.
pub const NEWTON_ITERATIONS: usize = 50;

/// ż and its slopes ∂ż/∂ẏ, ∂ż/∂z at (ẏ, z).
fn hysteresis(p: &OscillatorParams, v: f64, z: f64) -> (f64, f64, f64) {
    let za = z.abs();
    let zn = if za == 0.0 { 0.0 } else { math::powf(za, p.nu) };
    let (sv, sz) = (sgn(v), sgn(z));
    let rate = p.alpha * v - p.beta * (p.gamma * v.abs() * sz * zn + p.delta * v * zn);
    let dv = p.alpha - p.beta * (p.gamma * sv * sz * zn + p.delta * zn);
    let slope = if za == 0.0 { 0.0 } else { p.nu * zn / za };
    let dz = -p.beta * (p.gamma * v.abs() + p.delta * v * sz) * slope;
    (rate, dv, dz)
}

/// y \[m\] at every sample of `force` \[N\], `h` \[s\] apart, from the state `start` at
/// sample 0 (at rest in its acceleration: ÿ₀ from the equation of motion there).
pub fn newmark(p: &OscillatorParams, force: &[f64], h: f64, start: OscillatorState) -> Result<Vec<f64>> {
    check(p, force, h, &start)?;
    let mut out = Vec::with_capacity(force.len());
    let Some(&f0) = force.first() else {
        return Ok(out);
    };
    let (mut y, mut v, mut z) = (start.y, start.v, start.z);
    let mut a = (f0 - p.c * v - p.k * y - z) / p.m;
    out.push(y);
    let d_ra = p.m + p.c * 0.5 * h + p.k * 0.25 * h * h;
    for &f in &force[1..] {
        let (zd, _, _) = hysteresis(p, v, z);
        // Predictor: the acceleration and z held.
        let (mut a1, mut z1) = (a, z);
        for _ in 0..NEWTON_ITERATIONS {
            let v1 = v + 0.5 * h * (a + a1);
            let y1 = y + h * v + 0.25 * h * h * (a + a1);
            let (zd1, dv, dz) = hysteresis(p, v1, z1);
            let r1 = p.m * a1 + p.c * v1 + p.k * y1 + z1 - f;
            let r2 = z1 - z - 0.5 * h * (zd + zd1);
            // [[d_ra, 1], [−h/2·dv·h/2, 1 − h/2·dz]]·(Δa, Δz) = −(r1, r2)
            let (j21, j22) = (-0.25 * h * h * dv, 1.0 - 0.5 * h * dz);
            let det = d_ra * j22 - j21;
            let da = (-r1 * j22 + r2) / det;
            let dzz = (-r2 * d_ra + j21 * r1) / det;
            a1 += da;
            z1 += dzz;
            if !(a1.is_finite() && z1.is_finite()) {
                break;
            }
            if da.abs() <= 1e-14 * a1.abs().max(1e-300) && dzz.abs() <= 1e-14 * z1.abs().max(1e-300) {
                break;
            }
        }
        let v1 = v + 0.5 * h * (a + a1);
        y += h * v + 0.25 * h * h * (a + a1);
        (v, z, a) = (v1, z1, a1);
        out.push(y);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oscillator::{multisine, simulate, OscillatorState};

    /// At 20× the benchmark's rate the scheme is second order: halving its step divides its
    /// distance to the RK6 simulator by about four.
    #[test]
    fn is_second_order_and_close_to_the_simulator() {
        let dt = 1.0 / 750.0;
        let force = multisine(256, 2, dt, (5.0, 150.0), 50.0, 5);
        let p = OscillatorParams::benchmark();
        let (y, _) = simulate(&p, &force, dt, OscillatorState::default()).unwrap();
        let error = |r: usize| {
            // The force a straight line between samples, as the simulator takes it.
            let fine: Vec<f64> = (0..(force.len() - 1) * r + 1)
                .map(|i| {
                    let (k, s) = (i / r, (i % r) as f64 / r as f64);
                    if k + 1 < force.len() {
                        force[k] + (force[k + 1] - force[k]) * s
                    } else {
                        force[k]
                    }
                })
                .collect();
            let yn = newmark(&p, &fine, dt / r as f64, OscillatorState::default()).unwrap();
            (0..force.len()).map(|k| (yn[k * r] - y[k]).abs()).fold(0.0, f64::max)
        };
        let (e20, e40, e80) = (error(20), error(40), error(80));
        let range = y.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
        // 3.6e-7, 6.9e-8, 2.0e-8 m here (a range of 3e-3 m): second order, the ratios
        // about 4 (5.2 and 3.4).
        assert!(e20 < 1e-3 * range, "{e20:e}");
        assert!(e40 < e20 / 3.0 && e80 < e40 / 3.0, "{e20:e}, {e40:e}, {e80:e}");
    }
}
