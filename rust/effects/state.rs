//! The state of the extended chain between two samples, so that a record simulated in
//! pieces is the record simulated in one call, bit for bit.

use alloc::vec::Vec;

use crate::error::{Error, Result};

/// Everything [`super::ExtendedModel`] carries from one sample to the next.
///
/// Units: voltages \[V\], displacements \[µm\], velocities \[µm/s\]. A state is tied to
/// the effect set that made it (the number of creep elements and the delay's length);
/// [`ExtendedState::initial`] fits every effect set.
#[derive(Debug, Clone, PartialEq)]
pub struct ExtendedState {
    /// Samples taken so far; the next one is at t = `samples`·dt.
    pub samples: u64,
    /// Commanded voltage of the last sample \[V\] (`None`: no sample yet; the next
    /// one starts the chain at rest in equilibrium with it).
    pub u_prev: Option<f64>,
    /// Voltage on the stack after the last sample \[V\] (the input lag's output).
    pub ua: f64,
    /// Hysteresis state h \[µm\].
    pub h: f64,
    /// `(n, |h|^n)` as carried by the integrator for the shape exponent n it was
    /// computed with (`None`: computed from h). With other parameters it is
    /// recomputed.
    pub h_pow_n: Option<(f64, f64)>,
    /// The creep elements c_i \[µm\], in the order of the creep's time constants.
    pub creep: Vec<f64>,
    /// The stack's displacement at the last sample \[µm\] (the resonance's input).
    pub y: f64,
    /// The first mode's (z \[µm\], ż \[µm/s\]).
    pub resonance: [f64; 2],
    /// The second mode's (z \[µm\], ż \[µm/s\]).
    pub resonance2: [f64; 2],
    /// The delay line's d + 1 values \[µm\], oldest first (empty before the first sample).
    pub delay: Vec<f64>,
}

impl ExtendedState {
    /// The state before any sample, with h = `h0` \[µm\].
    pub fn initial(h0: f64) -> Self {
        ExtendedState {
            samples: 0,
            u_prev: None,
            ua: 0.0,
            h: h0,
            h_pow_n: None,
            creep: Vec::new(),
            y: 0.0,
            resonance: [0.0; 2],
            resonance2: [0.0; 2],
            delay: Vec::new(),
        }
    }

    /// Checks the values: finite, a started state with `creep_elements` creep states
    /// and a delay line of `delay_samples` + 1 values, an initial one with samples 0.
    pub(crate) fn check(&self, creep_elements: usize, delay_samples: usize) -> Result<()> {
        let scalars = [
            ("state.ua", self.ua),
            ("state.h", self.h),
            ("state.y", self.y),
            ("state.resonance", self.resonance[0]),
            ("state.resonance", self.resonance[1]),
            ("state.resonance2", self.resonance2[0]),
            ("state.resonance2", self.resonance2[1]),
        ];
        let listed =
            self.creep.iter().map(|&c| ("state.creep", c)).chain(self.delay.iter().map(|&v| ("state.delay", v)));
        let optional =
            self.u_prev.map(|u| ("state.u_prev", u)).into_iter().chain(self.h_pow_n.map(|(n, _)| ("state.h_pow_n", n)));
        for (name, value) in scalars.into_iter().chain(listed).chain(optional) {
            if !value.is_finite() {
                return Err(invalid(name, value, "every value of a state must be finite"));
            }
        }
        if let Some((_, hn)) = self.h_pow_n {
            if !(hn.is_finite() && hn >= 0.0) {
                return Err(invalid("state.h_pow_n", hn, "|h|^n must be finite and >= 0"));
            }
        }
        match self.u_prev {
            None if self.samples != 0 || !self.creep.is_empty() || !self.delay.is_empty() => Err(invalid(
                "state.samples",
                self.samples as f64,
                "a state before the first sample has no samples, creep or delay values",
            )),
            Some(_) if self.creep.len() != creep_elements => Err(Error::LengthMismatch {
                what: "state.creep (one per creep element of the effects)",
                expected: creep_elements,
                found: self.creep.len(),
            }),
            Some(_) if self.delay.len() != delay_samples + 1 => Err(Error::LengthMismatch {
                what: "state.delay (the effects' delay + 1 values)",
                expected: delay_samples + 1,
                found: self.delay.len(),
            }),
            _ => Ok(()),
        }
    }
}

fn invalid(name: &'static str, value: f64, reason: &'static str) -> Error {
    Error::InvalidConfig { name, value, reason }
}
