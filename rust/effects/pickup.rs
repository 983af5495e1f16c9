//! `pickup`: the sensor's signal picks up the power line and its harmonics.
//!
//! ```text
//! x ← x + Σ_k a_k·sin(2π·k·f_line·t) + b_k·cos(2π·k·f_line·t),   k = 1 … K
//! ```
//!
//! f_line: the line frequency \[Hz\] (50 or 60; a fixed parameter, not fitted);
//! a_k, b_k: the amplitudes of harmonic k \[µm\] (the fitted unknowns; the output is
//! linear in them); t \[s\] counts from the first sample. Electrical interference on
//! the sensor's cable or electronics: it is in the reading only, not in the stack's
//! motion, so the inverse does not compensate it. Evaluated exactly at each sample
//! (the phase is reduced to one period before the sine is taken). K·f_line must stay
//! below the Nyquist frequency 1/(2·dt) (checked where dt is known).

use alloc::vec::Vec;

use super::Effect;
use crate::error::{Error, Result};
use crate::model::scalar::Scalar;

/// Largest number of harmonics K.
pub const MAX_HARMONICS: usize = 8;

/// Line-frequency pickup: harmonics 1 … K with their sine and cosine amplitudes.
#[derive(Debug, Clone, PartialEq)]
pub struct Pickup {
    /// Line frequency f_line \[Hz\] (finite, > 0).
    pub line_hz: f64,
    /// a_k \[µm\], k = 1 … K (finite; 1 to [`MAX_HARMONICS`] of them).
    pub sin_um: Vec<f64>,
    /// b_k \[µm\], k = 1 … K (finite; as many as `sin_um`).
    pub cos_um: Vec<f64>,
}

impl Effect for Pickup {
    const NAME: &'static str = "pickup";

    fn validate(&self) -> Result<()> {
        if !(self.line_hz.is_finite() && self.line_hz > 0.0) {
            return Err(Error::InvalidParameter {
                name: "pickup.line_hz",
                value: self.line_hz,
                reason: "the line frequency must be finite and > 0 Hz",
            });
        }
        if self.sin_um.is_empty() || self.sin_um.len() > MAX_HARMONICS {
            return Err(Error::InvalidParameter {
                name: "pickup.sin_um",
                value: self.sin_um.len() as f64,
                reason: "pickup needs between 1 and 8 harmonics",
            });
        }
        if self.cos_um.len() != self.sin_um.len() {
            return Err(Error::LengthMismatch {
                what: "pickup.cos_um (one per harmonic of pickup.sin_um)",
                expected: self.sin_um.len(),
                found: self.cos_um.len(),
            });
        }
        for (name, values) in [("pickup.sin_um", &self.sin_um), ("pickup.cos_um", &self.cos_um)] {
            if let Some(&v) = values.iter().find(|v| !v.is_finite()) {
                return Err(Error::InvalidParameter { name, value: v, reason: "every amplitude must be finite" });
            }
        }
        Ok(())
    }
}

impl Pickup {
    /// Number of harmonics K.
    pub fn harmonics(&self) -> usize {
        self.sin_um.len()
    }

    /// Checks that the highest harmonic is below the Nyquist frequency of `dt` \[s\].
    pub(crate) fn check_sampling(&self, dt: f64) -> Result<()> {
        if self.harmonics() as f64 * self.line_hz >= 0.5 / dt {
            return Err(Error::InvalidParameter {
                name: "pickup.line_hz",
                value: self.line_hz,
                reason: "the highest harmonic K·line_hz must be below the Nyquist frequency 1/(2·dt)",
            });
        }
        Ok(())
    }

    /// The pickup \[µm\] at time `t_s` \[s\] after the first sample.
    pub fn at(&self, t_s: f64) -> f64 {
        line_pickup(self.line_hz, &self.sin_um, &self.cos_um, t_s)
    }
}

/// The pickup \[µm\] of the line at `line_hz` \[Hz\] with harmonic amplitudes `sin_um`
/// and `cos_um` \[µm\] at time `t_s` \[s\], in any number type.
pub(crate) fn line_pickup<S: Scalar>(line_hz: f64, sin_um: &[S], cos_um: &[S], t_s: f64) -> S {
    let mut total = S::cst(0.0);
    for (k, (&a, &b)) in sin_um.iter().zip(cos_um).enumerate() {
        let cycles = (k + 1) as f64 * line_hz * t_s;
        let angle = 2.0 * core::f64::consts::PI * (cycles - crate::math::floor(cycles));
        total = total + (a * crate::math::sin(angle) + b * crate::math::cos(angle));
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec;

    #[test]
    fn is_the_sum_of_its_harmonics_and_names_bad_values() {
        let p = Pickup { line_hz: 50.0, sin_um: vec![0.1, 0.0], cos_um: vec![0.0, 0.02] };
        for t in [0.0, 0.0013, 1234.5671] {
            let w = 2.0 * std::f64::consts::PI * 50.0 * t;
            let want = 0.1 * w.sin() + 0.02 * (2.0 * w).cos();
            assert!((p.at(t) - want).abs() < 1e-9, "{t}");
        }
        assert!(p.check_sampling(1e-3).is_ok());
        assert!(p.check_sampling(1e-2).is_err());
        let bad = Pickup { line_hz: 0.0, ..p.clone() };
        assert!(bad.validate().unwrap_err().to_string().contains("pickup.line_hz"));
        let bad = Pickup { cos_um: vec![0.0], ..p.clone() };
        assert!(bad.validate().unwrap_err().to_string().contains("pickup.cos_um"));
        let bad = Pickup { sin_um: vec![f64::NAN, 0.0], ..p };
        assert!(bad.validate().unwrap_err().to_string().contains("pickup.sin_um"));
    }
}
