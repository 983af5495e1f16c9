//! The one error type of the crate.
//!
//! Every fallible entry returns [`Error`]. Building an error never allocates
//! (names and reasons are `&'static str`), so the per-sample paths can reject a
//! sample without touching the heap.

use core::fmt;

/// What went wrong, precisely enough to be shown to a user as one line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Error {
    /// A model parameter is out of its domain (`name` follows [`crate::Params::NAMES`]).
    InvalidParameter { name: &'static str, value: f64, reason: &'static str },
    /// A configuration value (time step, window length, tolerance…) is invalid.
    InvalidConfig { name: &'static str, value: f64, reason: &'static str },
    /// A sample is NaN or infinite; the state is left as it was.
    NonFiniteSample { name: &'static str, value: f64 },
    /// A snapshot is truncated, foreign or corrupt: reading stopped at byte `at`.
    CorruptSnapshot { at: usize, reason: &'static str },
    /// Two arrays that must have the same length do not.
    LengthMismatch { what: &'static str, expected: usize, found: usize },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Error::InvalidParameter { name, value, reason } => {
                write!(f, "invalid parameter {name} = {value}: {reason}")
            }
            Error::InvalidConfig { name, value, reason } => {
                write!(f, "invalid {name} = {value}: {reason}")
            }
            Error::NonFiniteSample { name, value } => {
                write!(f, "sample {name} = {value} is not finite; the sample was rejected and the state kept")
            }
            Error::CorruptSnapshot { at, reason } => write!(f, "corrupt snapshot at byte {at}: {reason}"),
            Error::LengthMismatch { what, expected, found } => {
                write!(f, "{what}: expected length {expected}, found {found}")
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for Error {}

/// Result alias of the crate.
pub type Result<T> = core::result::Result<T, Error>;

/// Checks that a sample is finite.
#[inline]
pub(crate) fn finite_sample(name: &'static str, value: f64) -> Result<f64> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(Error::NonFiniteSample { name, value })
    }
}

/// Checks that a time step is finite and positive.
pub(crate) fn positive_dt(dt: f64) -> Result<f64> {
    if dt.is_finite() && dt > 0.0 {
        Ok(dt)
    } else {
        Err(Error::InvalidConfig {
            name: "dt",
            value: dt,
            reason: "the sampling interval must be finite and > 0 (seconds)",
        })
    }
}
