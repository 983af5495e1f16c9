//! Online identifiers: one sample in, one prediction out, estimates updated.
//!
//! Every method implements [`OnlineIdentifier`]. `push(u, x)` first predicts the
//! displacement of this sample with the estimates from *before* it (the model's own
//! hysteresis state h is carried by simulation, never reset from the measurement),
//! then uses the measurement to update the estimates. A rejected sample (NaN or
//! infinite) returns an error and leaves the identifier exactly as it was.
//!
//! Methods:
//! - [`paper::PaperIdentifier`]: the paper's limited-memory RLS plus least-squares
//!   sub-fits (section 3 of the paper).
//! - [`output_error::OutputErrorIdentifier`] ("rpem"): recursive prediction-error
//!   method on the model's output (simulation) error, sensitivities of h propagated
//!   through the integrator, bounded covariance and projected steps.

pub mod output_error;
pub mod paper;
pub mod window;

use crate::error::Result;
use crate::params::Params;

pub use output_error::{OutputErrorConfig, OutputErrorIdentifier, OutputErrorStatus};
pub use paper::{Decomposition, PaperConfig, PaperIdentifier};

/// Outcome of one sub-fit in a push.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SubFit {
    /// Not enough usable points, or ill-conditioned: the previous estimate was kept.
    #[default]
    Held,
    /// Ran on a reduced set of unknowns (rank-deficient data); the rest was kept.
    Reduced,
    /// Ran in full.
    Ran,
}

impl SubFit {
    /// Lower-case name, for logs and Python.
    pub fn name(self) -> &'static str {
        match self {
            SubFit::Held => "held",
            SubFit::Reduced => "reduced",
            SubFit::Ran => "ran",
        }
    }
}

/// What the last `push` did. Small and `Copy`: reading it never allocates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PushStatus {
    /// Samples pushed since construction or reset.
    pub samples: u64,
    /// The window holds its full N samples.
    pub window_full: bool,
    /// The window sums were refreshed exactly during this push.
    pub refreshed: bool,
    /// Step 1, kv and x0 (limited-memory RLS).
    pub line_fit: SubFit,
    /// Step 2, A and δ.
    pub rate_fit: SubFit,
    /// Step 3, n and β + γ.
    pub shape_fit: SubFit,
    /// Step 4, γ − β.
    pub return_fit: SubFit,
}

/// Any of the crate's online methods, for callers that choose at run time.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyIdentifier {
    /// The paper's method.
    Paper(PaperIdentifier),
    /// The output-error recursive prediction-error method ("rpem").
    OutputError(OutputErrorIdentifier),
}

impl AnyIdentifier {
    /// Short name of the method.
    pub fn method(&self) -> &'static str {
        match self {
            AnyIdentifier::Paper(_) => "paper",
            AnyIdentifier::OutputError(_) => "rpem",
        }
    }

    fn inner(&self) -> &dyn OnlineIdentifier {
        match self {
            AnyIdentifier::Paper(id) => id,
            AnyIdentifier::OutputError(id) => id,
        }
    }

    fn inner_mut(&mut self) -> &mut dyn OnlineIdentifier {
        match self {
            AnyIdentifier::Paper(id) => id,
            AnyIdentifier::OutputError(id) => id,
        }
    }

    /// Pushes every sample of `u`, `x` into `out` (predictions, as `push`). If any
    /// sample is non-finite the whole call is rejected before the state changes.
    pub fn push_many(&mut self, u: &[f64], x: &[f64], out: &mut [f64]) -> Result<()> {
        if x.len() != u.len() {
            return Err(crate::Error::LengthMismatch {
                what: "x (same length as u)",
                expected: u.len(),
                found: x.len(),
            });
        }
        if out.len() != u.len() {
            return Err(crate::Error::LengthMismatch { what: "output", expected: u.len(), found: out.len() });
        }
        for (&a, &b) in u.iter().zip(x) {
            crate::error::finite_sample("u", a)?;
            crate::error::finite_sample("x", b)?;
        }
        for ((o, &a), &b) in out.iter_mut().zip(u).zip(x) {
            *o = self.push(a, b)?;
        }
        Ok(())
    }
}

impl OnlineIdentifier for AnyIdentifier {
    #[inline]
    fn push(&mut self, u: f64, x: f64) -> Result<f64> {
        match self {
            AnyIdentifier::Paper(id) => id.push(u, x),
            AnyIdentifier::OutputError(id) => id.push(u, x),
        }
    }
    fn params(&self) -> Params {
        self.inner().params()
    }
    fn h(&self) -> f64 {
        self.inner().h()
    }
    fn status(&self) -> PushStatus {
        self.inner().status()
    }
    fn reset(&mut self) {
        self.inner_mut().reset()
    }
}

/// The interface shared by every online method.
pub trait OnlineIdentifier {
    /// Takes one sample, voltage `u` [V] and measured displacement `x` [µm], and
    /// returns the model's displacement [µm] for it, predicted before the
    /// measurement is used. Errors leave the state unchanged. No heap allocation.
    fn push(&mut self, u: f64, x: f64) -> Result<f64>;
    /// The current parameter estimates.
    fn params(&self) -> Params;
    /// The model's hysteresis state h [µm] after the last sample.
    fn h(&self) -> f64;
    /// What the last push did.
    fn status(&self) -> PushStatus;
    /// Back to the state right after construction.
    fn reset(&mut self);
}
