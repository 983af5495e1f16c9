//! PI/PID feedback on the tracking error, in the displacement domain.
//!
//! The compensator adds the feedback term to the desired displacement *before* the
//! inverse model, x_cmd = x_d + v, so the controller sees a plant that the inverse
//! has made close to unity gain (x ≈ x_cmd) and its gains do not depend on the
//! actuator's µm/V:
//!
//! ```text
//! e_k = x_d,k − x_k                                        \[µm\]
//! I_k = I_k−1 + ki·e_k·Δt        (held within ±integral_limit_um; not integrated
//!                                 toward a voltage limit that bound on the last sample)
//! D_k = a·D_k−1 + (1 − a)·(e_k − e_k−1)/Δt,   a = exp(−2π·derivative_filter_hz·Δt)
//! v_k = kp·e_k + I_k + kd·D_k                              \[µm\]
//! ```
//!
//! Units: kp \[-\], ki \[1/s\], kd \[s\]. The integral is backward Euler (it includes the
//! current error); the derivative is a backward difference through a first-order
//! low-pass, and is zero on the first error. The anti-windup rule assumes a plant
//! whose displacement grows with the voltage (kv + A > 0, as every piezo stack).

use super::inverse::Clip;
use crate::error::{finite_sample, positive_dt, Error, Result};

/// Gains and filters of [`Pid`], with documented units. `Default` is all gains zero
/// (no feedback), a 1 kHz derivative filter and no integral limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidGains {
    /// Proportional gain kp \[-\] (µm of correction per µm of error).
    pub kp: f64,
    /// Integral gain ki \[1/s\].
    pub ki: f64,
    /// Derivative gain kd \[s\].
    pub kd: f64,
    /// Corner of the first-order low-pass on the derivative \[Hz\] (> 0; ∞ = none).
    pub derivative_filter_hz: f64,
    /// Largest |I| \[µm\] (> 0; ∞ = none).
    pub integral_limit_um: f64,
}

impl Default for PidGains {
    fn default() -> Self {
        PidGains { kp: 0.0, ki: 0.0, kd: 0.0, derivative_filter_hz: 1000.0, integral_limit_um: f64::INFINITY }
    }
}

impl PidGains {
    /// A PI controller: kp \[-\], ki \[1/s\], the other values default.
    pub fn pi(kp: f64, ki: f64) -> Self {
        PidGains { kp, ki, ..Self::default() }
    }

    /// Gains finite, filter corner and integral limit > 0.
    pub fn validate(&self) -> Result<()> {
        for (name, value) in [("kp", self.kp), ("ki", self.ki), ("kd", self.kd)] {
            if !value.is_finite() {
                return Err(Error::InvalidConfig { name, value, reason: "the feedback gain must be finite" });
            }
        }
        if self.derivative_filter_hz.is_nan() || self.derivative_filter_hz <= 0.0 {
            return Err(Error::InvalidConfig {
                name: "derivative_filter_hz",
                value: self.derivative_filter_hz,
                reason: "the derivative filter corner must be > 0 Hz (inf = no filter)",
            });
        }
        if self.integral_limit_um.is_nan() || self.integral_limit_um <= 0.0 {
            return Err(Error::InvalidConfig {
                name: "integral_limit_um",
                value: self.integral_limit_um,
                reason: "the integral limit must be > 0 um (inf = none)",
            });
        }
        Ok(())
    }
}

/// The state [`Pid`] carries between samples.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PidState {
    /// Integral term I \[µm\].
    pub integral_um: f64,
    /// Filtered derivative of the error D \[µm/s\].
    pub derivative_um_per_s: f64,
    /// The last error \[µm\]; `None` before the first.
    pub e_prev: Option<f64>,
}

/// Discrete PI/PID on the tracking error (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Pid {
    gains: PidGains,
    dt: f64,
    decay: f64,
    state: PidState,
}

impl Pid {
    /// A controller with `gains` for samples `dt` \[s\] apart.
    pub fn new(gains: PidGains, dt: f64) -> Result<Self> {
        gains.validate()?;
        positive_dt(dt)?;
        let decay = crate::math::exp(-2.0 * core::f64::consts::PI * gains.derivative_filter_hz * dt);
        Ok(Pid { gains, dt, decay, state: PidState::default() })
    }

    /// Takes the error `e` \[µm\] and the limit that bound on the last voltage; returns
    /// the correction v \[µm\]. A non-finite `e` is rejected and the state kept.
    #[inline]
    pub fn update(&mut self, e: f64, saturated: Clip) -> Result<f64> {
        finite_sample("e", e)?;
        let g = &self.gains;
        let s = &mut self.state;
        let winds_up = matches!((saturated, e > 0.0, e < 0.0), (Clip::High, true, _) | (Clip::Low, _, true));
        if !winds_up {
            s.integral_um = (s.integral_um + g.ki * e * self.dt).clamp(-g.integral_limit_um, g.integral_limit_um);
        }
        if let Some(prev) = s.e_prev {
            let raw = (e - prev) / self.dt;
            s.derivative_um_per_s = self.decay * s.derivative_um_per_s + (1.0 - self.decay) * raw;
        }
        s.e_prev = Some(e);
        Ok(g.kp * e + s.integral_um + g.kd * s.derivative_um_per_s)
    }

    /// The correction for the current state without a new error \[µm\]: the integral
    /// alone (used while no measurement arrives).
    pub fn hold(&self) -> f64 {
        self.state.integral_um
    }

    /// The gains.
    pub fn gains(&self) -> &PidGains {
        &self.gains
    }

    /// The state carried between samples.
    pub fn state(&self) -> PidState {
        self.state
    }

    /// Restores a state taken with [`Pid::state`] (values finite).
    pub fn set_state(&mut self, state: PidState) -> Result<()> {
        finite_sample("integral_um", state.integral_um)?;
        finite_sample("derivative_um_per_s", state.derivative_um_per_s)?;
        if let Some(e) = state.e_prev {
            finite_sample("e_prev", e)?;
        }
        self.state = state;
        Ok(())
    }

    /// Back to rest: no integral, no previous error.
    pub fn reset(&mut self) {
        self.state = PidState::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pi_integrates_and_proportional_acts_at_once() {
        let mut pid = Pid::new(PidGains::pi(0.5, 100.0), 1e-3).unwrap();
        let v1 = pid.update(2.0, Clip::None).unwrap();
        assert!((v1 - (1.0 + 0.2)).abs() < 1e-15);
        let v2 = pid.update(2.0, Clip::None).unwrap();
        assert!((v2 - (1.0 + 0.4)).abs() < 1e-15);
    }

    #[test]
    fn does_not_wind_up_against_a_bound_limit() {
        let mut pid = Pid::new(PidGains::pi(0.0, 100.0), 1e-3).unwrap();
        pid.update(1.0, Clip::None).unwrap();
        let held = pid.update(1.0, Clip::High).unwrap();
        assert_eq!(held, 0.1);
        // Integrating away from the limit is allowed.
        assert!(pid.update(-1.0, Clip::High).unwrap() < held);
    }

    #[test]
    fn derivative_of_a_ramp_settles_at_its_slope() {
        let gains = PidGains { kd: 1.0, derivative_filter_hz: 50.0, ..PidGains::default() };
        let mut pid = Pid::new(gains, 1e-3).unwrap();
        let mut v = 0.0;
        for k in 0..2000 {
            v = pid.update(0.003 * k as f64, Clip::None).unwrap();
        }
        assert!((v - 3.0).abs() < 1e-9, "{v}");
    }

    #[test]
    fn integral_limit_and_bad_values() {
        let gains = PidGains { ki: 1e4, integral_limit_um: 2.0, ..PidGains::default() };
        let mut pid = Pid::new(gains, 1e-3).unwrap();
        for _ in 0..100 {
            pid.update(5.0, Clip::None).unwrap();
        }
        assert_eq!(pid.hold(), 2.0);
        let before = pid.clone();
        assert!(pid.update(f64::NAN, Clip::None).is_err());
        assert_eq!(pid, before);
        assert!(Pid::new(PidGains { kp: f64::NAN, ..PidGains::default() }, 1e-3).is_err());
        assert!(Pid::new(PidGains { derivative_filter_hz: 0.0, ..PidGains::default() }, 1e-3).is_err());
        assert!(Pid::new(PidGains::default(), -1.0).is_err());
    }
}
