//! A few channels at once: the number type of the integrator's branch-free path
//! (`advance_h_lanes` in [`super::integrator`]), `f64` for one channel and [`F64s`] for
//! [`WIDTH`] channels side by side.
//!
//! Every operation of [`F64s`] is the `f64` operation lane by lane (the same IEEE
//! results, bit for bit); a selection replaces each branch. On x86-64 the lanes are
//! SSE2 registers (part of every x86-64 processor, so no run-time detection); elsewhere
//! fixed arrays, lane by lane.

use core::ops::{Add, BitAnd, BitOr, Div, Mul, Sub};

#[cfg(target_arch = "x86_64")]
use core::arch::x86_64::*;

/// Channels per [`F64s`].
pub const WIDTH: usize = 4;

/// Numbers for the branch-free path: `f64`, or [`F64s`] lane by lane.
pub trait Lanes: Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> {
    /// A truth value per lane.
    type Mask: Copy + BitAnd<Output = Self::Mask> + BitOr<Output = Self::Mask>;
    /// `v` in every lane.
    fn splat(v: f64) -> Self;
    /// |self|.
    fn abs(self) -> Self;
    /// self ≤ other (false where either is NaN).
    fn le(self, other: Self) -> Self::Mask;
    /// self > other (false where either is NaN).
    fn gt(self, other: Self) -> Self::Mask;
    /// self < other (false where either is NaN).
    fn lt(self, other: Self) -> Self::Mask;
    /// self == other.
    fn eq(self, other: Self) -> Self::Mask;
    /// `yes` where `mask`, else `no`.
    fn select(mask: Self::Mask, yes: Self, no: Self) -> Self;
}

impl Lanes for f64 {
    type Mask = bool;
    #[inline(always)]
    fn splat(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f64::abs(self)
    }
    #[inline(always)]
    fn le(self, other: Self) -> bool {
        self <= other
    }
    #[inline(always)]
    fn gt(self, other: Self) -> bool {
        self > other
    }
    #[inline(always)]
    fn lt(self, other: Self) -> bool {
        self < other
    }
    #[inline(always)]
    fn eq(self, other: Self) -> bool {
        self == other
    }
    #[inline(always)]
    fn select(mask: bool, yes: Self, no: Self) -> Self {
        if mask {
            yes
        } else {
            no
        }
    }
}

/// [`WIDTH`] `f64` lanes.
#[derive(Debug, Clone, Copy)]
pub struct F64s(Repr);

/// A truth value per lane of [`F64s`] (all bits set or none, as SIMD comparisons give).
#[derive(Debug, Clone, Copy)]
pub struct Masks(Repr);

#[cfg(not(target_arch = "x86_64"))]
use portable as repr;
use repr::Repr;
#[cfg(target_arch = "x86_64")]
use sse2 as repr;

#[cfg(target_arch = "x86_64")]
// SAFETY (every `unsafe` block below): the intrinsics are SSE2's, which every x86-64
// processor has (the target's baseline); none of them touches memory.
mod sse2 {
    use super::*;

    pub(super) type Repr = [__m128d; 2];

    #[inline(always)]
    pub(super) fn from_array(v: [f64; WIDTH]) -> Repr {
        unsafe { [_mm_set_pd(v[1], v[0]), _mm_set_pd(v[3], v[2])] }
    }
    #[inline(always)]
    pub(super) fn to_array(r: Repr) -> [f64; WIDTH] {
        let half = |x: __m128d| unsafe { [_mm_cvtsd_f64(x), _mm_cvtsd_f64(_mm_unpackhi_pd(x, x))] };
        let ([a, b], [c, d]) = (half(r[0]), half(r[1]));
        [a, b, c, d]
    }
    #[inline(always)]
    pub(super) fn each(a: Repr, b: Repr, f: impl Fn(__m128d, __m128d) -> __m128d) -> Repr {
        [f(a[0], b[0]), f(a[1], b[1])]
    }
    #[inline(always)]
    pub(super) fn splat(v: f64) -> Repr {
        unsafe { [_mm_set1_pd(v); 2] }
    }
    #[inline(always)]
    pub(super) fn abs(a: Repr) -> Repr {
        unsafe {
            let sign = _mm_set1_pd(-0.0);
            [_mm_andnot_pd(sign, a[0]), _mm_andnot_pd(sign, a[1])]
        }
    }
    #[inline(always)]
    pub(super) fn select(m: Repr, yes: Repr, no: Repr) -> Repr {
        let pick = |m: __m128d, y: __m128d, n: __m128d| unsafe { _mm_or_pd(_mm_and_pd(m, y), _mm_andnot_pd(m, n)) };
        [pick(m[0], yes[0], no[0]), pick(m[1], yes[1], no[1])]
    }
    pub(super) const ADD: fn(__m128d, __m128d) -> __m128d = |a, b| unsafe { _mm_add_pd(a, b) };
    pub(super) const SUB: fn(__m128d, __m128d) -> __m128d = |a, b| unsafe { _mm_sub_pd(a, b) };
    pub(super) const MUL: fn(__m128d, __m128d) -> __m128d = |a, b| unsafe { _mm_mul_pd(a, b) };
    pub(super) const DIV: fn(__m128d, __m128d) -> __m128d = |a, b| unsafe { _mm_div_pd(a, b) };
    pub(super) const AND: fn(__m128d, __m128d) -> __m128d = |a, b| unsafe { _mm_and_pd(a, b) };
    pub(super) const OR: fn(__m128d, __m128d) -> __m128d = |a, b| unsafe { _mm_or_pd(a, b) };
    pub(super) const LE: fn(__m128d, __m128d) -> __m128d = |a, b| unsafe { _mm_cmple_pd(a, b) };
    pub(super) const GT: fn(__m128d, __m128d) -> __m128d = |a, b| unsafe { _mm_cmpgt_pd(a, b) };
    pub(super) const LT: fn(__m128d, __m128d) -> __m128d = |a, b| unsafe { _mm_cmplt_pd(a, b) };
    pub(super) const EQ: fn(__m128d, __m128d) -> __m128d = |a, b| unsafe { _mm_cmpeq_pd(a, b) };
}

/// Lane by lane on arrays (compiled on x86-64 too, for the test against SSE2).
#[cfg(any(test, not(target_arch = "x86_64")))]
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
mod portable {
    use super::*;

    pub(super) type Repr = [f64; WIDTH];

    type Lane = fn(f64, f64) -> f64;
    #[inline(always)]
    pub(super) fn from_array(v: [f64; WIDTH]) -> Repr {
        v
    }
    #[inline(always)]
    pub(super) fn to_array(r: Repr) -> [f64; WIDTH] {
        r
    }
    #[inline(always)]
    pub(super) fn each(a: Repr, b: Repr, f: impl Fn(f64, f64) -> f64) -> Repr {
        core::array::from_fn(|i| f(a[i], b[i]))
    }
    #[inline(always)]
    pub(super) fn splat(v: f64) -> Repr {
        [v; WIDTH]
    }
    #[inline(always)]
    pub(super) fn abs(a: Repr) -> Repr {
        a.map(f64::abs)
    }
    #[inline(always)]
    pub(super) fn select(m: Repr, yes: Repr, no: Repr) -> Repr {
        core::array::from_fn(|i| {
            f64::from_bits((m[i].to_bits() & yes[i].to_bits()) | (!m[i].to_bits() & no[i].to_bits()))
        })
    }
    fn mask(t: bool) -> f64 {
        f64::from_bits(0u64.wrapping_sub(u64::from(t)))
    }
    pub(super) const ADD: Lane = |a, b| a + b;
    pub(super) const SUB: Lane = |a, b| a - b;
    pub(super) const MUL: Lane = |a, b| a * b;
    pub(super) const DIV: Lane = |a, b| a / b;
    pub(super) const AND: Lane = |a, b| f64::from_bits(a.to_bits() & b.to_bits());
    pub(super) const OR: Lane = |a, b| f64::from_bits(a.to_bits() | b.to_bits());
    pub(super) const LE: Lane = |a, b| mask(a <= b);
    pub(super) const GT: Lane = |a, b| mask(a > b);
    pub(super) const LT: Lane = |a, b| mask(a < b);
    pub(super) const EQ: Lane = |a, b| mask(a == b);
}

impl F64s {
    /// The lanes `v`.
    #[inline(always)]
    pub fn from_array(v: [f64; WIDTH]) -> F64s {
        F64s(repr::from_array(v))
    }

    /// The lanes as an array.
    #[inline(always)]
    pub fn to_array(self) -> [f64; WIDTH] {
        repr::to_array(self.0)
    }
}

#[cfg(test)]
impl Masks {
    /// The lanes' truth values.
    #[inline(always)]
    pub fn to_array(self) -> [bool; WIDTH] {
        repr::to_array(self.0).map(|v| v.to_bits() != 0)
    }
}

impl BitAnd for Masks {
    type Output = Masks;
    #[inline(always)]
    fn bitand(self, o: Masks) -> Masks {
        Masks(repr::each(self.0, o.0, repr::AND))
    }
}

impl BitOr for Masks {
    type Output = Masks;
    #[inline(always)]
    fn bitor(self, o: Masks) -> Masks {
        Masks(repr::each(self.0, o.0, repr::OR))
    }
}

macro_rules! lanewise {
    ($trait:ident, $method:ident, $op:ident) => {
        impl $trait for F64s {
            type Output = F64s;
            #[inline(always)]
            fn $method(self, o: F64s) -> F64s {
                F64s(repr::each(self.0, o.0, repr::$op))
            }
        }
    };
}
lanewise!(Add, add, ADD);
lanewise!(Sub, sub, SUB);
lanewise!(Mul, mul, MUL);
lanewise!(Div, div, DIV);

impl Lanes for F64s {
    type Mask = Masks;
    #[inline(always)]
    fn splat(v: f64) -> Self {
        F64s(repr::splat(v))
    }
    #[inline(always)]
    fn abs(self) -> Self {
        F64s(repr::abs(self.0))
    }
    #[inline(always)]
    fn le(self, o: Self) -> Masks {
        Masks(repr::each(self.0, o.0, repr::LE))
    }
    #[inline(always)]
    fn gt(self, o: Self) -> Masks {
        Masks(repr::each(self.0, o.0, repr::GT))
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Masks {
        Masks(repr::each(self.0, o.0, repr::LT))
    }
    #[inline(always)]
    fn eq(self, o: Self) -> Masks {
        Masks(repr::each(self.0, o.0, repr::EQ))
    }
    #[inline(always)]
    fn select(mask: Masks, yes: Self, no: Self) -> Self {
        F64s(repr::select(mask.0, yes.0, no.0))
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;

    /// The SSE2 lanes against the portable ones, operation by operation, bit for bit,
    /// on values with NaN, infinities, signed zeros and subnormals.
    #[test]
    fn sse2_lanes_equal_portable_lanes() {
        let values = [0.0, -0.0, 1.0, -2.5, 1e-310, -1e300, f64::INFINITY, f64::NEG_INFINITY, f64::NAN, 3.0, 0.1, -7.0];
        let bits = |v: [f64; WIDTH]| v.map(f64::to_bits);
        for i in 0..values.len() {
            let a: [f64; WIDTH] = core::array::from_fn(|l| values[(i + l) % values.len()]);
            for j in 0..values.len() {
                let b: [f64; WIDTH] = core::array::from_fn(|l| values[(j + 3 * l) % values.len()]);
                let (sa, sb) = (sse2::from_array(a), sse2::from_array(b));
                let ops = [
                    (sse2::ADD, portable::ADD),
                    (sse2::SUB, portable::SUB),
                    (sse2::MUL, portable::MUL),
                    (sse2::DIV, portable::DIV),
                    (sse2::LE, portable::LE),
                    (sse2::GT, portable::GT),
                    (sse2::LT, portable::LT),
                    (sse2::EQ, portable::EQ),
                ];
                for (k, (fast, slow)) in ops.into_iter().enumerate() {
                    let got = sse2::to_array(sse2::each(sa, sb, fast));
                    let want = portable::each(a, b, slow);
                    assert_eq!(bits(got), bits(want), "op {k} on {a:?}, {b:?}");
                }
                let picked = sse2::to_array(sse2::select(sse2::each(sa, sb, sse2::LE), sa, sb));
                assert_eq!(bits(picked), bits(portable::select(portable::each(a, b, portable::LE), a, b)));
                assert_eq!(bits(sse2::to_array(sse2::abs(sa))), bits(portable::abs(a)));
            }
        }
    }
}
