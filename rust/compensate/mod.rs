//! Hysteresis compensation: the inverse model, feedback and the adaptive compensator.
//!
//! ```text
//! x_d ─► [+ PID(x_d − x)] ─► x_cmd ─► inverse of the model ─► u ─► actuator ─► x
//!                                          ▲                            │
//!                                          └── online identifier ◄──────┘
//! ```
//!
//! - [`inverse`]: [`Inverse`], per sample `step(x_d) -> u`, solving kv·u + x0 +
//!   Φ(hₖ₋₁, uₖ₋₁ → u) = x_d through the model's own integrator Φ
//!   ([`crate::model::advance_h`]), within voltage limits; [`invert`] for a record.
//! - [`extended`]: [`ExtendedInverse`], the same through the effects that have an
//!   inverse (input lag, creep, drift; a delay by preview of the reference).
//! - [`feedback`]: [`Pid`], PI/PID on the tracking error, in µm.
//! - [`adaptive`]: [`Compensator`], the inverse of an online identifier's current
//!   estimates plus optional feedback, one call per sample.
//!
//! Units: u \[V\], x, h \[µm\], t \[s\]. Nothing here allocates per sample or panics on
//! user input; every error leaves the state as it was.

pub mod adaptive;
pub mod extended;
pub mod feedback;
pub mod inverse;

pub use adaptive::{admissible, Compensator, CompensatorConfig, CompensatorStatus, MIN_SLOPE_FRACTION};
pub use extended::{invert_extended, ExtendedInverse, ExtendedInverseState};
pub use feedback::{Pid, PidGains, PidState};
pub use inverse::{invert, invert_into, Clip, Inverse, InverseStatus, InvertSummary, VoltageLimits, MAX_EVALUATIONS};

use crate::effects::{EffectSet, InputLag};
use crate::error::Result;
use crate::model::ModelState;
use crate::params::Params;
use alloc::boxed::Box;
use alloc::vec::Vec;

/// The base or the extended inverse, for callers that choose at run time.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyInverse {
    /// The base model's inverse.
    Base(Inverse),
    /// The inverse through the effects (boxed: it carries the effects and their states).
    Extended(Box<ExtendedInverse>),
}

impl AnyInverse {
    /// [`Inverse`] without effects, [`ExtendedInverse`] with them (an empty set counts as none).
    pub fn new(params: Params, effects: Option<EffectSet>, dt: f64, h0: f64, limits: VoltageLimits) -> Result<Self> {
        match effects {
            Some(e) if !e.names().is_empty() => {
                ExtendedInverse::new(params, e, dt, h0, limits).map(|inv| Self::Extended(Box::new(inv)))
            }
            _ => Inverse::new(params, dt, h0, limits).map(Self::Base),
        }
    }

    /// The voltage u \[V\] for the desired displacement `x_d` \[µm\] (d samples ahead
    /// with a delay of d samples, see [`ExtendedInverse::step`]).
    #[inline]
    pub fn step(&mut self, x_d: f64) -> Result<f64> {
        match self {
            Self::Base(inv) => inv.step(x_d),
            Self::Extended(inv) => inv.step(x_d),
        }
    }

    /// [`AnyInverse::step`] over a record into `u_out`; a non-finite value anywhere
    /// rejects the whole call before the state changes.
    pub fn step_many(&mut self, x_d: &[f64], u_out: &mut [f64]) -> Result<()> {
        if u_out.len() != x_d.len() {
            return Err(crate::Error::LengthMismatch { what: "output", expected: x_d.len(), found: u_out.len() });
        }
        for &v in x_d {
            crate::error::finite_sample("x_d", v)?;
        }
        for (u, &v) in u_out.iter_mut().zip(x_d) {
            *u = self.step(v)?;
        }
        Ok(())
    }

    /// Base parameters.
    pub fn params(&self) -> &Params {
        match self {
            Self::Base(inv) => inv.params(),
            Self::Extended(inv) => inv.params(),
        }
    }

    /// Replaces the base parameters; the state is kept.
    pub fn set_params(&mut self, params: Params) -> Result<()> {
        match self {
            Self::Base(inv) => inv.set_params(params),
            Self::Extended(inv) => inv.set_params(params),
        }
    }

    /// Replaces the input lag's corner frequency ([`ExtendedInverse::set_input_lag`]);
    /// the base inverse has none (`InvalidConfig`).
    pub fn set_input_lag(&mut self, lag: InputLag) -> Result<()> {
        match self {
            Self::Base(_) => Err(crate::Error::InvalidConfig {
                name: "input_lag",
                value: lag.fc_hz,
                reason: "this inverse was built without an input lag",
            }),
            Self::Extended(inv) => inv.set_input_lag(lag),
        }
    }

    /// Moves the model's state to h \[µm\] after a sample at command `u` \[V\], the
    /// voltage on the stack at `ua` \[V\] (ignored by the base inverse, where it is u);
    /// see [`ExtendedInverse::follow`]. No allocation.
    pub fn follow(&mut self, h: f64, u: f64, ua: f64) -> Result<()> {
        match self {
            Self::Base(inv) => inv.set_state(ModelState { h, u_prev: Some(u) }),
            Self::Extended(inv) => inv.follow(h, u, ua),
        }
    }

    /// The voltage on the stack after the last sample \[V\] (the last command for the
    /// base inverse; 0 before the first sample).
    pub fn stack_voltage(&self) -> f64 {
        match self {
            Self::Base(inv) => inv.state().u_prev.unwrap_or(0.0),
            Self::Extended(inv) => inv.stack_voltage(),
        }
    }

    /// The effects inverted (`None` for the base inverse).
    pub fn effects(&self) -> Option<&EffectSet> {
        match self {
            Self::Base(_) => None,
            Self::Extended(inv) => Some(inv.effects()),
        }
    }

    /// Hysteresis state h \[µm\].
    pub fn h(&self) -> f64 {
        match self {
            Self::Base(inv) => inv.h(),
            Self::Extended(inv) => inv.h(),
        }
    }

    /// Initial h \[µm\].
    pub fn h0(&self) -> f64 {
        match self {
            Self::Base(inv) => inv.h0(),
            Self::Extended(inv) => inv.h0(),
        }
    }

    /// Sampling interval \[s\].
    pub fn dt(&self) -> f64 {
        match self {
            Self::Base(inv) => inv.dt(),
            Self::Extended(inv) => inv.dt(),
        }
    }

    /// Voltage limits.
    pub fn limits(&self) -> VoltageLimits {
        match self {
            Self::Base(inv) => inv.limits(),
            Self::Extended(inv) => inv.limits(),
        }
    }

    /// The reference preview the inverse needs \[samples\] (the delay; 0 without).
    pub fn preview_samples(&self) -> usize {
        match self {
            Self::Base(_) => 0,
            Self::Extended(inv) => inv.preview_samples(),
        }
    }

    /// What the last step did.
    pub fn status(&self) -> InverseStatus {
        match self {
            Self::Base(inv) => inv.status(),
            Self::Extended(inv) => inv.status(),
        }
    }

    /// The state in the extended form (the base inverse has u_a = u and no creep).
    pub fn state(&self) -> ExtendedInverseState {
        match self {
            Self::Base(inv) => {
                let s = inv.state();
                ExtendedInverseState {
                    samples: inv.status().samples,
                    u_prev: s.u_prev,
                    ua_prev: s.u_prev.unwrap_or(0.0),
                    h: s.h,
                    creep: Vec::new(),
                }
            }
            Self::Extended(inv) => inv.state(),
        }
    }

    /// Restores a state and status taken with [`AnyInverse::state`] and [`AnyInverse::status`].
    pub fn restore(&mut self, state: ExtendedInverseState, status: InverseStatus) -> Result<()> {
        match self {
            Self::Base(inv) => {
                if !state.creep.is_empty() {
                    return Err(crate::Error::LengthMismatch {
                        what: "creep states (the base inverse has none)",
                        expected: 0,
                        found: state.creep.len(),
                    });
                }
                inv.set_state(ModelState { h: state.h, u_prev: state.u_prev })?;
                inv.set_status(status);
            }
            Self::Extended(inv) => {
                inv.set_state(state)?;
                inv.set_status(status);
            }
        }
        Ok(())
    }

    /// Forgets the past (h = h0, no previous sample, counters zero).
    pub fn reset(&mut self) {
        match self {
            Self::Base(inv) => inv.reset(),
            Self::Extended(inv) => inv.reset(),
        }
    }
}
