//! `resonance2`: a second mechanical mode, in series after `resonance`.
//!
//! ```text
//! z̈₂ + 2ζ₂ω₂·ż₂ + ω₂²·z₂ = ω₂²·z,     ω₂ = 2π·fn₂
//! ```
//!
//! z: the output of the first mode (the stack's displacement y where `resonance` is
//! absent) \[µm\]; z₂: what the sensor sees \[µm\]; fn₂ \[Hz\], ζ₂ \[-\] as for
//! [`super::Resonance`], static gain 1. A stack on a flexure, or a sensor target on
//! a bracket, has more than one mode below the Nyquist frequency; two modes in series
//! give two peaks. The step is that of `resonance`, exact for a straight line between
//! the chain's sub-steps ([`super::RESONANCE_SUBSTEPS`] per sample), which z is to
//! within the sub-step's curvature.

use super::resonance::{validate_mode, ModeNames};
use super::Effect;
use crate::error::Result;

pub(crate) const NAMES: ModeNames = ("resonance2.fn_hz", "resonance2.zeta");

/// A second second-order low-pass of unit static gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resonance2 {
    /// Natural frequency fn₂ \[Hz\] (> 0, below the Nyquist frequency).
    pub fn_hz: f64,
    /// Damping ratio ζ₂ \[-\] (> 0).
    pub zeta: f64,
}

impl Effect for Resonance2 {
    const NAME: &'static str = "resonance2";

    fn validate(&self) -> Result<()> {
        validate_mode(self.fn_hz, self.zeta, NAMES)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::resonance::mode_stage;

    #[test]
    fn names_its_own_parameters() {
        let err = Resonance2 { fn_hz: -1.0, zeta: 0.1 }.validate().unwrap_err();
        assert!(err.to_string().contains("resonance2.fn_hz"));
        let err = Resonance2 { fn_hz: 100.0, zeta: 0.0 }.validate().unwrap_err();
        assert!(err.to_string().contains("resonance2.zeta"));
        assert!(mode_stage(600.0, 0.1, 1e-3, NAMES).is_err());
    }
}
