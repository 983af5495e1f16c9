//! `electrostriction`: the stack's stroke grows with the square of its displacement.
//!
//! ```text
//! s = kv·u_a + h,     y = x0 + s + ε·s² + c
//! ```
//!
//! s: the Bouc–Wen displacement without its offset \[µm\]; ε: electrostrictive
//! coefficient \[1/µm\]; c: the creep \[µm\]. The strain of a poled ceramic is Q·P²
//! (Q the electrostrictive coefficient, P the polarisation), so with P = P_r + ΔP the
//! stroke is linear in the hysteretic ΔP plus a term in ΔP²: the local gain
//! 1 + 2ε·s grows along the stroke. This is the stroke map of the simulated bench
//! (`boucwen.plant`, `stroke_quadratic_per_um`). Algebraic: exact at every instant.

use super::Effect;
use crate::error::{Error, Result};
use crate::model::scalar::Scalar;

/// A quadratic stroke map s ↦ s + ε·s².
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Electrostriction {
    /// Electrostrictive coefficient ε \[1/µm\] (finite).
    pub epsilon_per_um: f64,
}

impl Effect for Electrostriction {
    const NAME: &'static str = "electrostriction";

    fn validate(&self) -> Result<()> {
        if !self.epsilon_per_um.is_finite() {
            return Err(Error::InvalidParameter {
                name: "electrostriction.epsilon_per_um",
                value: self.epsilon_per_um,
                reason: "must be finite",
            });
        }
        Ok(())
    }
}

impl Electrostriction {
    /// s + ε·s² \[µm\] for the Bouc–Wen displacement `s` \[µm\].
    #[inline]
    pub fn apply(&self, s: f64) -> f64 {
        bend(self.epsilon_per_um, s)
    }

    /// The s \[µm\] with s + ε·s² = `q` on the branch where the map rises (1 + 2ε·s ≥ 0);
    /// where no s reaches `q`, the s of the map's extreme, −1/(2ε).
    #[inline]
    pub fn invert(&self, q: f64) -> f64 {
        quadratic_root(self.epsilon_per_um, 1.0, -q)
    }
}

/// The root of a·s² + b·s + c = 0 that tends to −c/b as a → 0 (b > 0), in the form
/// without cancellation; the vertex −b/(2a) where there is no real root.
#[inline]
pub(crate) fn quadratic_root(a: f64, b: f64, c: f64) -> f64 {
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return -b / (2.0 * a);
    }
    -2.0 * c / (b + crate::math::sqrt(disc))
}

/// s + ε·s² \[µm\] with ε = `epsilon` \[1/µm\], in any number type.
#[inline]
pub(crate) fn bend<S: Scalar>(epsilon: S, s: S) -> S {
    s + epsilon * s * s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverts_its_map_and_rejects_nan() {
        let e = Electrostriction { epsilon_per_um: 0.004 };
        for s in [-3.0, 0.0, 0.5, 17.6] {
            let back = e.invert(e.apply(s));
            assert!((back - s).abs() < 1e-12, "{s} {back}");
        }
        assert_eq!(Electrostriction { epsilon_per_um: 0.0 }.invert(2.5), 2.5);
        // Below the map's minimum −1/(4ε): the extreme.
        assert_eq!(e.invert(-100.0), -125.0);
        let err = Electrostriction { epsilon_per_um: f64::NAN }.validate().unwrap_err();
        assert!(err.to_string().contains("electrostriction.epsilon_per_um"));
    }
}
