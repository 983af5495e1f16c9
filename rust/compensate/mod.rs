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
//! Units: u [V], x, h [µm], t [s]. Nothing here allocates per sample or panics on
//! user input; every error leaves the state as it was.

pub mod adaptive;
pub mod extended;
pub mod feedback;
pub mod inverse;

pub use adaptive::{Compensator, CompensatorConfig, CompensatorStatus};
pub use extended::{invert_extended, ExtendedInverse, ExtendedInverseState};
pub use feedback::{Pid, PidGains, PidState};
pub use inverse::{invert, invert_into, Clip, Inverse, InverseStatus, InvertSummary, VoltageLimits, MAX_EVALUATIONS};
