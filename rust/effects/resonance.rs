//! `resonance`: second-order mechanical dynamics between the stack and the sensor.
//!
//! ```text
//! z̈ + 2ζω·ż + ω²·z = ω²·y,     ω = 2π·fn
//! ```
//!
//! y: the stack's displacement (base model + creep) \[µm\]; z: what the sensor sees \[µm\];
//! fn: natural frequency \[Hz\]; ζ: damping ratio \[-\]. The static gain is 1.
//!
//! y is a straight line between samples. The step is exact for such an input: the
//! matrix exponential of the augmented system `[z, ż, y, Δy]` over one interval,
//! computed once per sampling interval, so it is stable for every fn and ζ > 0.
//! fn must stay below the Nyquist frequency 1/(2·dt) (checked where dt is known).

use nalgebra::{Const, DimMin, Matrix4, SMatrix, SVector};

use super::Effect;
use crate::error::{Error, Result};
use crate::model::scalar::{Dual, Scalar};

/// A second-order low-pass of unit static gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resonance {
    /// Natural frequency fn \[Hz\] (> 0, below the Nyquist frequency).
    pub fn_hz: f64,
    /// Damping ratio ζ \[-\] (> 0).
    pub zeta: f64,
}

impl Effect for Resonance {
    const NAME: &'static str = "resonance";

    fn validate(&self) -> Result<()> {
        validate_mode(self.fn_hz, self.zeta, NAMES)
    }
}

/// The parameter names of a mode, for the errors: (fn, ζ).
pub(crate) type ModeNames = (&'static str, &'static str);

pub(crate) const NAMES: ModeNames = ("resonance.fn_hz", "resonance.zeta");

/// Checks a mode's natural frequency `fn_hz` \[Hz\] and damping ratio `zeta` \[-\].
pub(crate) fn validate_mode(fn_hz: f64, zeta: f64, names: ModeNames) -> Result<()> {
    if !(fn_hz.is_finite() && fn_hz > 0.0) {
        return Err(Error::InvalidParameter {
            name: names.0,
            value: fn_hz,
            reason: "the natural frequency must be finite and > 0 Hz",
        });
    }
    if !(zeta.is_finite() && zeta > 0.0) {
        return Err(Error::InvalidParameter {
            name: names.1,
            value: zeta,
            reason: "the damping ratio must be finite and > 0",
        });
    }
    Ok(())
}

/// The exact one-interval map of a mode for sampling interval `dt` \[s\].
pub(crate) fn mode_stage(fn_hz: f64, zeta: f64, dt: f64, names: ModeNames) -> Result<ResonanceStage> {
    validate_mode(fn_hz, zeta, names)?;
    if fn_hz >= 0.5 / dt {
        return Err(Error::InvalidParameter {
            name: names.0,
            value: fn_hz,
            reason: "the natural frequency must be below the Nyquist frequency 1/(2·dt)",
        });
    }
    let e = matrix_exp(augmented(fn_hz, zeta, dt));
    Ok(ResonanceStage::from_exp(&e, |_, v| v))
}

/// [`mode_stage`] with every coefficient carrying its derivatives over ln fn and ln ζ
/// at derivative slots `slots` (the mode's unknowns in a fit).
///
/// The derivatives are those of the matrix exponential itself, by Van Loan's block
/// form: exp([[m, ∂m], [0, m]]) holds ∂e^m in its upper-right block.
pub(crate) fn mode_stage_seeded<const M: usize>(
    fn_hz: f64,
    zeta: f64,
    dt: f64,
    names: ModeNames,
    slots: (usize, usize),
) -> Result<ResonanceStage<Dual<M>>> {
    let plain = mode_stage(fn_hz, zeta, dt, names)?;
    let m = augmented(fn_hz, zeta, dt);
    let w = 2.0 * core::f64::consts::PI * fn_hz;
    // ∂m/∂ln fn (= ∂m/∂ln ω) and ∂m/∂ln ζ: only the row of z̈ depends on them.
    let mut by_fn = Matrix4::zeros();
    by_fn[(1, 0)] = -2.0 * w * w * dt;
    by_fn[(1, 1)] = -2.0 * zeta * w * dt;
    by_fn[(1, 2)] = 2.0 * w * w * dt;
    let mut by_zeta = Matrix4::zeros();
    by_zeta[(1, 1)] = -2.0 * zeta * w * dt;
    let (d_fn, d_zeta) = (exp_derivative(&m, &by_fn), exp_derivative(&m, &by_zeta));
    let seeded = ResonanceStage::from_exp(&d_fn, |(i, j), slope_fn| {
        let mut du = SVector::<f64, M>::zeros();
        du[slots.0] = slope_fn;
        du[slots.1] = d_zeta[(i, j)];
        Dual::new(0.0, du)
    });
    Ok(ResonanceStage {
        phi: [0, 1].map(|i| [0, 1].map(|j| seeded.phi[i][j].with_re(plain.phi[i][j]))),
        from_y: [0, 1].map(|i| seeded.from_y[i].with_re(plain.from_y[i])),
        from_dy: [0, 1].map(|i| seeded.from_dy[i].with_re(plain.from_dy[i])),
    })
}

/// ∂e^m in the direction `dm` (Van Loan: the upper-right block of the exponential of
/// the block matrix [[m, dm], [0, m]]).
fn exp_derivative(m: &Matrix4<f64>, dm: &Matrix4<f64>) -> Matrix4<f64> {
    let mut block = SMatrix::<f64, 8, 8>::zeros();
    block.fixed_view_mut::<4, 4>(0, 0).copy_from(m);
    block.fixed_view_mut::<4, 4>(4, 4).copy_from(m);
    block.fixed_view_mut::<4, 4>(0, 4).copy_from(dm);
    matrix_exp(block).fixed_view::<4, 4>(0, 4).into_owned()
}

/// The augmented system's matrix times `dt`: d/dt \[z, ż, y, Δy\] with ẏ = Δy/dt over
/// the interval.
fn augmented(fn_hz: f64, zeta: f64, dt: f64) -> Matrix4<f64> {
    let w = 2.0 * core::f64::consts::PI * fn_hz;
    #[rustfmt::skip]
    let m = Matrix4::new(
        0.0,    1.0,               0.0,   0.0,
        -w * w, -2.0 * zeta * w,   w * w, 0.0,
        0.0,    0.0,               0.0,   1.0 / dt,
        0.0,    0.0,               0.0,   0.0,
    );
    m * dt
}

/// e^m: nalgebra's `exp` with `std`; without it (nalgebra's `exp` needs `std`),
/// [`taylor_exp`].
#[inline]
fn matrix_exp<const D: usize>(m: SMatrix<f64, D, D>) -> SMatrix<f64, D, D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    #[cfg(feature = "std")]
    {
        m.exp()
    }
    #[cfg(not(feature = "std"))]
    {
        taylor_exp(m)
    }
}

/// e^m by scaling and squaring: m/2^s with ‖m/2^s‖₁ ≤ 1/2, its Taylor series to
/// degree 18 (the first dropped term is below 2^−19/19! ≈ 1.6e-23 relative), then s
/// squarings. Used without `std`; agrees with nalgebra's Padé form to about 1e-12 of the
/// largest entry (test below).
#[cfg_attr(feature = "std", allow(dead_code))]
fn taylor_exp<const D: usize>(m: SMatrix<f64, D, D>) -> SMatrix<f64, D, D> {
    let mut norm = 0.0f64;
    for j in 0..D {
        norm = norm.max((0..D).map(|i| m[(i, j)].abs()).sum::<f64>());
    }
    let mut scaled = m;
    let mut squarings = 0u32;
    while norm > 0.5 && squarings < 1100 {
        scaled *= 0.5;
        norm *= 0.5;
        squarings += 1;
    }
    let mut term = SMatrix::<f64, D, D>::identity();
    let mut sum = SMatrix::<f64, D, D>::identity();
    for k in 1..=18 {
        term = term * scaled / k as f64;
        sum += term;
    }
    for _ in 0..squarings {
        sum = sum * sum;
    }
    sum
}

/// `s[k+1] = Φ·s[k] + g_y·y[k] + g_Δ·(y[k+1] − y[k])`, s = [z, ż], in the number type
/// of the run (`f64`, or duals carrying ∂/∂ln fn and ∂/∂ln ζ: [`mode_stage_seeded`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ResonanceStage<S = f64> {
    phi: [[S; 2]; 2],
    from_y: [S; 2],
    from_dy: [S; 2],
}

impl<S: Scalar> ResonanceStage<S> {
    /// The coefficients from the entries of e^m (or of its derivative), each made an
    /// `S` by `entry((row, column), value)`.
    fn from_exp(e: &Matrix4<f64>, entry: impl Fn((usize, usize), f64) -> S) -> Self {
        let at = |i: usize, j: usize| entry((i, j), e[(i, j)]);
        ResonanceStage {
            phi: [[at(0, 0), at(0, 1)], [at(1, 0), at(1, 1)]],
            from_y: [at(0, 2), at(1, 2)],
            from_dy: [at(0, 3), at(1, 3)],
        }
    }

    #[inline]
    pub(crate) fn advance(&self, s: [S; 2], y0: S, y1: S) -> [S; 2] {
        let dy = y1 - y0;
        [0, 1].map(|i| (self.phi[i][0] * s[0] + self.phi[i][1] * s[1]) + self.from_y[i] * y0 + self.from_dy[i] * dy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_no_std_exponential_matches_nalgebras() {
        for (fn_hz, zeta, dt) in [(1500.0, 0.05, 1e-4), (40.0, 1.0, 1e-3), (4000.0, 3.0, 2.5e-5)] {
            let m = augmented(fn_hz, zeta, dt);
            let (a, b) = (taylor_exp(m), m.exp());
            // The matrix is badly scaled (ω²·dt ≈ 9e3 against 1), and both forms round
            // through several squarings: 1e-11 of the largest entry is rounding.
            let scale = b.abs().max();
            eprintln!("fn {fn_hz}: {:.1e} of the largest entry", (a - b).abs().max() / scale);
            assert!((a - b).abs().max() <= 1e-11 * scale, "fn {fn_hz}, ζ {zeta}: {}", (a - b).abs().max());
        }
    }

    fn fine_rk4(r: &Resonance, y0: f64, y1: f64, dt: f64, s: [f64; 2]) -> [f64; 2] {
        let w = 2.0 * std::f64::consts::PI * r.fn_hz;
        let f = |t: f64, s: [f64; 2]| {
            let y = y0 + (y1 - y0) * t / dt;
            [s[1], w * w * (y - s[0]) - 2.0 * r.zeta * w * s[1]]
        };
        let m = 20_000;
        let h = dt / m as f64;
        let mut s = s;
        for i in 0..m {
            let t = i as f64 * h;
            let k1 = f(t, s);
            let k2 = f(t + h / 2.0, [s[0] + h / 2.0 * k1[0], s[1] + h / 2.0 * k1[1]]);
            let k3 = f(t + h / 2.0, [s[0] + h / 2.0 * k2[0], s[1] + h / 2.0 * k2[1]]);
            let k4 = f(t + h, [s[0] + h * k3[0], s[1] + h * k3[1]]);
            for j in 0..2 {
                s[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
            }
        }
        s
    }

    #[test]
    fn matches_a_fine_rk4_solution_on_a_ramp() {
        let r = Resonance { fn_hz: 300.0, zeta: 0.05 };
        let dt = 1e-3;
        let stage = mode_stage(r.fn_hz, r.zeta, dt, NAMES).unwrap();
        let got = stage.advance([0.2, -50.0], 0.0, 1.0);
        let want = fine_rk4(&r, 0.0, 1.0, dt, [0.2, -50.0]);
        assert!((got[0] - want[0]).abs() < 1e-9 && (got[1] - want[1]).abs() < 1e-6, "{got:?} {want:?}");
    }

    #[test]
    fn settles_at_the_input_and_rejects_bad_values() {
        let stage = mode_stage(400.0, 0.01, 1e-3, NAMES).unwrap();
        let mut s = [0.0, 0.0];
        for _ in 0..200_000 {
            s = stage.advance(s, 1.0, 1.0);
        }
        assert!((s[0] - 1.0).abs() < 1e-9);
        assert!(mode_stage(500.0, 0.1, 1e-3, NAMES).is_err());
        assert!(Resonance { fn_hz: 50.0, zeta: 0.0 }.validate().is_err());
    }
}
