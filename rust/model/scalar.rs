//! The number type the integrator runs on: `f64` for the model, [`Dual`] for its
//! sensitivities.
//!
//! [`Dual<M>`] carries a value and its derivatives with respect to M quantities
//! (forward-mode automatic differentiation). The integrator in
//! [`super::integrator`] is written once, generic over [`Scalar`], so that the
//! simulator, the per-sample model, the identifiers' predictions and their
//! sensitivities ∂h/∂θ all take the same sub-steps and the same stages. The value
//! part of a `Dual` is computed by exactly the operations the `f64` instance
//! performs, so its bits equal the model's.

use core::ops::{Add, Div, Mul, Neg, Sub};

use nalgebra::SVector;

/// For n < 1, below this |h| \[µm\] the slope n·|h|^(n−1) of |h|^n is taken at |h| = this
/// value when differentiating (it is unbounded at h = 0). Values are never
/// changed, only derivatives; 1 nm is below every sensor's noise.
pub const SLOPE_FLOOR_UM: f64 = 1e-3;

/// A real number for the integrator: `f64`, or a [`Dual`] that carries derivatives.
pub trait Scalar:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
    + Neg<Output = Self>
{
    /// Whether the type carries derivatives (then [`Scalar::abs_pow`] needs ln|h|, for
    /// the derivative with respect to n, and the implicit step needs ∂f/∂θ).
    const DERIVATIVES: bool;
    /// The value.
    fn re(self) -> f64;
    /// A constant (zero derivatives).
    fn cst(v: f64) -> Self;
    /// |self|^n given `hn` = |re|^n and, when [`Scalar::DERIVATIVES`], `ln_abs` = ln|re|.
    fn abs_pow(self, n: Self, hn: f64, ln_abs: f64) -> Self;
    /// The same derivatives with another value.
    fn with_re(self, v: f64) -> Self;
    /// The value `v` with zero derivatives (a clamped state no longer depends on θ).
    fn pinned(v: f64) -> Self {
        Self::cst(v)
    }
    /// The backward-Euler solution h* of h = h₀ + step·f(h, θ), value `h_star`, with
    /// derivatives by the implicit function theorem: (∂h₀ + step·∂f/∂θ) / (1 − step·∂f/∂h),
    /// `f_at` being f evaluated at h* held constant and `slope` = ∂f/∂h there.
    fn implicit(h_star: f64, h0: Self, f_at: Self, slope: f64, step: f64) -> Self;
    /// Value and every derivative finite.
    fn all_finite(self) -> bool;
}

impl Scalar for f64 {
    const DERIVATIVES: bool = false;
    #[inline(always)]
    fn re(self) -> f64 {
        self
    }
    #[inline(always)]
    fn cst(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn abs_pow(self, _n: Self, hn: f64, _ln_abs: f64) -> Self {
        hn
    }
    #[inline(always)]
    fn with_re(self, v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn implicit(h_star: f64, _h0: Self, _f_at: Self, _slope: f64, _step: f64) -> Self {
        h_star
    }
    #[inline(always)]
    fn all_finite(self) -> bool {
        self.is_finite()
    }
}

/// A value with its derivatives with respect to M quantities.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dual<const M: usize> {
    /// The value.
    pub re: f64,
    /// ∂value/∂θᵢ, i < M.
    pub du: SVector<f64, M>,
}

impl<const M: usize> Dual<M> {
    /// The i-th independent variable with value `v` (∂/∂θᵢ = 1).
    #[inline(always)]
    pub fn var(v: f64, i: usize) -> Self {
        let mut du = SVector::zeros();
        du[i] = 1.0;
        Dual { re: v, du }
    }

    /// The value `v` with ∂/∂θ_`slot` = `slope` and the other derivatives 0 (a quantity
    /// that depends on one independent variable, seeded by the chain rule).
    #[inline(always)]
    pub fn slope(v: f64, slot: usize, slope: f64) -> Self {
        let mut du = SVector::zeros();
        du[slot] = slope;
        Dual { re: v, du }
    }

    /// A value with the given derivatives.
    #[inline(always)]
    pub fn new(re: f64, du: SVector<f64, M>) -> Self {
        Dual { re, du }
    }
}

/// `f` of the derivatives slot by slot, in place (one pass, no temporaries).
#[inline(always)]
fn map<const M: usize>(mut a: SVector<f64, M>, f: impl Fn(f64) -> f64) -> SVector<f64, M> {
    for v in a.iter_mut() {
        *v = f(*v);
    }
    a
}

/// `f` of two sets of derivatives slot by slot, into the first.
#[inline(always)]
fn zip<const M: usize>(mut a: SVector<f64, M>, b: &SVector<f64, M>, f: impl Fn(f64, f64) -> f64) -> SVector<f64, M> {
    for (v, &w) in a.iter_mut().zip(b.iter()) {
        *v = f(*v, w);
    }
    a
}

impl<const M: usize> Add for Dual<M> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Dual { re: self.re + o.re, du: zip(self.du, &o.du, |a, b| a + b) }
    }
}

impl<const M: usize> Sub for Dual<M> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Dual { re: self.re - o.re, du: zip(self.du, &o.du, |a, b| a - b) }
    }
}

impl<const M: usize> Mul for Dual<M> {
    type Output = Self;
    // The product rule: the sum is meant.
    #[allow(clippy::suspicious_arithmetic_impl)]
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        Dual { re: self.re * o.re, du: zip(self.du, &o.du, |a, b| a * o.re + b * self.re) }
    }
}

impl<const M: usize> Mul<f64> for Dual<M> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, k: f64) -> Self {
        Dual { re: self.re * k, du: map(self.du, |a| a * k) }
    }
}

impl<const M: usize> Div<f64> for Dual<M> {
    type Output = Self;
    #[inline(always)]
    fn div(self, k: f64) -> Self {
        Dual { re: self.re / k, du: map(self.du, |a| a / k) }
    }
}

impl<const M: usize> Neg for Dual<M> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Dual { re: -self.re, du: map(self.du, |a| -a) }
    }
}

/// ∂|h|^n/∂h = sgn(h)·n·|h|^(n−1) given `hn` = |h|^n, with |h| taken at
/// [`SLOPE_FLOOR_UM`] below it for n < 1; `None` at h = 0 (where both derivatives of
/// |h|^n are taken as 0).
#[inline(always)]
pub(crate) fn abs_pow_slope(h: f64, n: f64, hn: f64) -> Option<f64> {
    let a = h.abs();
    if a == 0.0 {
        return None;
    }
    let slope =
        if a >= SLOPE_FLOOR_UM || n >= 1.0 { n * hn / a } else { n * crate::math::powf(SLOPE_FLOOR_UM, n - 1.0) };
    Some(if h > 0.0 { slope } else { -slope })
}

impl<const M: usize> Scalar for Dual<M> {
    const DERIVATIVES: bool = true;
    #[inline(always)]
    fn re(self) -> f64 {
        self.re
    }
    #[inline(always)]
    fn cst(v: f64) -> Self {
        Dual { re: v, du: SVector::zeros() }
    }
    /// d|h|^n = |h|^n·(n·sgn(h)/|h|·dh + ln|h|·dn), with |h| floored at
    /// [`SLOPE_FLOOR_UM`] in the first term for n < 1 only; both terms are 0 at h = 0.
    #[inline(always)]
    fn abs_pow(self, n: Self, hn: f64, ln_abs: f64) -> Self {
        let Some(signed) = abs_pow_slope(self.re, n.re, hn) else {
            return Dual::cst(0.0);
        };
        let dn = hn * ln_abs;
        Dual { re: hn, du: zip(self.du, &n.du, |a, b| a * signed + b * dn) }
    }
    #[inline(always)]
    fn with_re(self, v: f64) -> Self {
        Dual { re: v, du: self.du }
    }
    #[inline(always)]
    fn implicit(h_star: f64, h0: Self, f_at: Self, slope: f64, step: f64) -> Self {
        let den = (1.0 - step * slope).max(1.0);
        Dual { re: h_star, du: zip(h0.du, &f_at.du, |a, b| (a + b * step) / den) }
    }
    #[inline(always)]
    fn all_finite(self) -> bool {
        self.re.is_finite() && self.du.iter().all(|v| v.is_finite())
    }
}
