//! # boucwen
//!
//! The asymmetric Bouc–Wen model of piezoelectric-actuator hysteresis and its
//! online (sample-by-sample) identification, after Zhu, Bian & Rui, *Online
//! parameter identification of the asymmetrical Bouc–Wen model for piezoelectric
//! actuators*, Precision Engineering 38 (2014) 921–927.
//!
//! ```text
//! x(t)  = kv·u(t) + x0 + h(t)                                   (3)
//! dh/dt = A·u̇ − β·|u̇|·|h|^(n−1)·h − γ·u̇·|h|^n + δ·u·sgn(u̇)    (5)
//! ```
//!
//! u: voltage \[V\]; x: displacement \[µm\]; h: hysteresis state \[µm\]; t: time \[s\].
//!
//! - [`Params`]: the seven parameters and their units.
//! - [`reconstruction`]: what the input does between samples (hold, linear, band-limited),
//!   read by the integrators of both model classes.
//! - [`oscillator`]: a second model class, the hysteretic oscillator of the Noël & Schoukens
//!   benchmark (a mass, spring and damper with a Bouc–Wen spring driven by its motion).
//! - [`model`]: the operator, its integrator, the per-sample [`Model`] and [`simulate`].
//! - [`identify`]: online identifiers behind one trait, [`identify::OnlineIdentifier`].
//! - [`Error`]: every fallible call returns it; nothing here panics on user input.
//! - [`bank`]: C channels (identifier + model each) stepped with one call per frame.
//! - [`Snapshot`]: save a [`Model`] or an identifier to bytes and restore it bit for bit.
//! - [`compensate`]: the inverse model ([`Inverse`]), PI/PID feedback and the adaptive
//!   compensator ([`Compensator`]) that cancel the hysteresis in a control loop.
//!
//! The Python bindings live in `python/` behind the `python` feature; this crate's
//! numerics never depend on them.

#![cfg_attr(not(feature = "std"), no_std)]

extern crate alloc;

pub mod bank;
pub mod compensate;
pub mod effects;
pub mod error;
pub mod format;
pub mod identify;
pub mod math;
pub mod model;
pub mod oscillator;
pub mod params;
pub mod reconstruction;

#[cfg(feature = "ffi")]
pub mod ffi;
#[cfg(feature = "python")]
mod python;

pub use bank::{Bank, ModelBank};
pub use compensate::{invert, Compensator, ExtendedInverse, Inverse, VoltageLimits};
pub use effects::{simulate_extended, simulate_extended_from, EffectSet, ExtendedModel, ExtendedState};
pub use error::{Error, Result};
pub use format::Snapshot;
pub use model::{simulate, simulate_into, Model, ModelState};
pub use params::Params;
