//! |h|^n and ln|h| near a reference state by their series: the integrator's stages take
//! their powers from it instead of `powf`.

use super::{abs_pow, Law};
use crate::math;
use crate::model::lanes::Lanes;
use crate::model::scalar::Scalar;

/// |h|^n (and ln|h|) near a reference state h_ref by their series in
/// ε = (h − h_ref)/h_ref (= |h|/|h_ref| − 1 for h of the sign of h_ref):
/// |h|^n = |h_ref|^n·(1 + ε)^n to ε⁴, ln|h| = ln|h_ref| + ln(1 + ε) to ε⁵.
///
/// The RK4 stages of one interval sit close to its starting h, so one |h|^n per
/// interval (carried from the interval before, see [`advance_h_carried`], or one
/// `powf`) serves all of them. The series is used only for |ε| ≤
/// [`NearPower::MAX_EPS`] (where h has the sign of h_ref), where the dropped ε⁵
/// term is below 3.2e-9·|c₅| relative (|c₅| < 1 for 0 < n < 5) and ln's ε⁶ term
/// below 1.1e-11; elsewhere (near h = 0 in particular) the caller falls back to
/// `powf` and `ln`.
///
/// Both are on the chain of dependent operations of every stage, so they are
/// written for a short chain: a stage's ε comes from its rate k as εₛ + k·(c/h_ref)
/// (the stage state is h + c·k, εₛ that of the sub-step's start h), without waiting
/// for the state itself, and the polynomial is evaluated in two halves,
/// |h_ref|^n + (ε·(a₁ + a₂ε) + ε³·(a₃ + a₄ε)) with aₖ = |h_ref|^n·cₖ (five dependent
/// operations instead of Horner's nine).
///
/// Generic over [`Lanes`]: one channel (`f64`) or several side by side.
#[derive(Clone, Copy)]
pub(super) struct NearPower<L = f64> {
    /// 1/h_ref (0 when h_ref = 0: the series never applies).
    pub(super) inv_ref: L,
    pub(super) hn_ref: L,
    pub(super) ln_ref: L,
    pub(super) a: [L; 4],
}

impl<L: Lanes> NearPower<L> {
    /// Largest |ε| at which a stage takes its |h|^n from the series.
    pub(super) const MAX_EPS: f64 = 0.02;
    /// Largest |ε| at which an interval's end takes its |h|^n from the series to carry
    /// it to the next interval: the dropped ε⁵ term is then below 1e-15·|c₅| relative,
    /// at the level of rounding, so carried values do not drift from |h|^n.
    pub(super) const CARRY_EPS: f64 = 1e-3;

    /// aₖ = `hn_ref`·cₖ, cₖ the coefficients of (1 + ε)^n.
    #[inline(always)]
    pub(super) fn coefficients(n: L, hn_ref: L) -> [L; 4] {
        let one = L::splat(1.0);
        // cₖ = cₖ₋₁·(n − k + 1)/k, the divisions as multiplications by 1/k.
        let c2 = n * (n - one) * L::splat(0.5);
        let c3 = c2 * (n - L::splat(2.0)) * L::splat(1.0 / 3.0);
        let c4 = c3 * (n - L::splat(3.0)) * L::splat(0.25);
        [hn_ref * n, hn_ref * c2, hn_ref * c3, hn_ref * c4]
    }

    #[inline(always)]
    pub(super) fn power(&self, e: L) -> L {
        let [a1, a2, a3, a4] = self.a;
        let e3 = (e * e) * e;
        self.hn_ref + (e * (a1 + a2 * e) + e3 * (a3 + a4 * e))
    }
}

impl NearPower {
    /// The series about `h_ref` with |h_ref|^n = `hn_ref`; ln|h_ref| is `ln_ref` when
    /// given, else computed where `with_ln` (0 otherwise).
    #[inline(always)]
    pub(super) fn new(n: f64, h_ref: f64, hn_ref: f64, ln_ref: Option<f64>, with_ln: bool) -> Self {
        let a = h_ref.abs();
        let ln_ref = match ln_ref {
            Some(ln) => ln,
            None if with_ln && a > 0.0 => math::ln(a),
            None => 0.0,
        };
        NearPower {
            inv_ref: if a > 0.0 { 1.0 / h_ref } else { 0.0 },
            hn_ref,
            ln_ref,
            a: NearPower::coefficients(n, hn_ref),
        }
    }

    /// `e` where the series applies (h_ref ≠ 0 and |e| ≤ [`Self::MAX_EPS`]), else `None`.
    #[inline(always)]
    pub(super) fn valid(&self, e: f64) -> Option<f64> {
        if self.inv_ref == 0.0 || e.abs() > Self::MAX_EPS {
            return None;
        }
        Some(e)
    }

    #[inline(always)]
    pub(super) fn ln(&self, e: f64) -> f64 {
        self.ln_ref + e * (1.0 - e * (0.5 - e * (1.0 / 3.0 - e * (0.25 - e * 0.2))))
    }

    /// |x|^n in the number type of `x` by `law`, n being `nv`, where `e` is the ε of x.
    #[inline(always)]
    pub(super) fn power_at<S: Scalar, L: Law<S>>(&self, law: &L, x: S, e: f64, nv: f64) -> S {
        let (hn, ln) = self.eval::<S>(x.re(), e, nv);
        law.power(x, hn, ln)
    }

    /// |h|^n and, when `S` carries derivatives, ln|h| (else 0), `e` being the ε of h.
    #[inline(always)]
    pub(super) fn eval<S: Scalar>(&self, h: f64, e: f64, n: f64) -> (f64, f64) {
        match self.valid(e) {
            Some(e) => (self.power(e), if S::DERIVATIVES { self.ln(e) } else { 0.0 }),
            None => {
                let a = h.abs();
                let ln = if S::DERIVATIVES && a > 0.0 { math::ln(a) } else { 0.0 };
                (abs_pow(h, n), ln)
            }
        }
    }
}
