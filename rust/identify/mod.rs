//! Online identifiers: one sample in, one prediction out, estimates updated.
//!
//! Every method implements [`OnlineIdentifier`]. `push(u, x)` first predicts the
//! displacement of this sample with the estimates from *before* it (the model's own
//! hysteresis state h is carried by simulation, never reset from the measurement),
//! then uses the measurement to update the estimates. A rejected sample (NaN or
//! infinite) returns an error and leaves the identifier exactly as it was.
//!
//! Each method lives in its own folder with its configuration, its status and its
//! snapshot code:
//! - [`paper`]: the paper's limited-memory RLS plus least-squares sub-fits
//!   (section 3 of the paper), [`PaperIdentifier`];
//! - [`rpem`]: recursive prediction-error method on the model's output (simulation)
//!   error, sensitivities of h propagated through the integrator, bounded covariance
//!   and projected steps, [`RpemIdentifier`];
//! - [`horizon`]: moving-horizon output-error least squares over a window measured in
//!   input travel, one Levenberg–Marquardt step per pass, the work spread over the
//!   samples, [`HorizonIdentifier`].
//!
//! [`AnyIdentifier`] holds either, for callers that choose the method at run time.
//!
//! Adding a method: a folder `identify/<name>/` with the identifier, its `Config`
//! and `Status` types and its `Snapshot` impl; an arm in [`AnyIdentifier`] and
//! [`AnyStatus`]; the Python constructor in `python/identifier.rs`; the method in the
//! generic conformance suite (`rust/tests/conformance.rs`).

pub mod horizon;
pub mod paper;
pub mod rpem;

use alloc::vec::Vec;

use crate::effects::InputLag;
use crate::error::{finite_sample, Error, Result};
use crate::format::{corrupt, Snapshot, KIND_HORIZON, KIND_PAPER, KIND_RPEM};
use crate::params::Params;

#[cfg(feature = "std")]
pub use horizon::BackgroundHorizon;
pub use horizon::{HorizonConfig, HorizonIdentifier, HorizonStatus, RefineMode};
pub use paper::{Decomposition, PaperConfig, PaperIdentifier, PaperStatus, Reason, StepStatus, SubFit};
pub use rpem::{RpemConfig, RpemIdentifier, RpemStatus};

/// Projects `p` onto the region where the model is well posed, the one both
/// output-error methods keep their estimates in: n within `n_bounds`, and β + γ ≥
/// `margin`, β − γ ≥ `margin` (h stays bounded for every input), each half-plane by the
/// orthogonal projection in (β, γ).
#[inline]
pub(crate) fn project_well_posed(mut p: Params, n_bounds: (f64, f64), margin: f64) -> Params {
    p.n = p.n.clamp(n_bounds.0, n_bounds.1);
    let sum = p.beta + p.gamma;
    if sum < margin {
        let shift = 0.5 * (margin - sum);
        p.beta += shift;
        p.gamma += shift;
    }
    let diff = p.beta - p.gamma;
    if diff < margin {
        let shift = 0.5 * (margin - diff);
        p.beta += shift;
        p.gamma -= shift;
    }
    p
}

/// The interface shared by every online method.
pub trait OnlineIdentifier {
    /// What a push did: each method reports its own state (`Copy`, no allocation).
    type Status: Copy + core::fmt::Debug;

    /// Takes one sample, voltage `u` \[V\] and measured displacement `x` \[µm\], and
    /// returns the model's displacement \[µm\] for it, predicted before the
    /// measurement is used. Errors leave the state unchanged. No heap allocation.
    fn push(&mut self, u: f64, x: f64) -> Result<f64>;
    /// The current parameter estimates.
    fn params(&self) -> Params;
    /// The model's hysteresis state h \[µm\] after the last sample.
    fn h(&self) -> f64;
    /// What the last push did.
    fn status(&self) -> Self::Status;
    /// Back to the state right after construction.
    fn reset(&mut self);
    /// The model's open-loop displacement \[µm\] for the future voltages `u` \[V\],
    /// written into `out`: the current estimates and model state, simulated on from
    /// the last sample pushed (the interval from it to `u[0]` included), effects
    /// identified with the parameters included. The state does not change. A
    /// non-finite `u` or a length mismatch is rejected before anything is written.
    fn forecast_into(&self, u: &[f64], out: &mut [f64]) -> Result<()>;

    /// The input lag identified with the parameters (at its current estimate) and the
    /// model's voltage on the stack u_a \[V\] after the last sample; `None` where the
    /// model has no lag (u_a = u). The adaptive compensator inverts through it.
    fn input_lag(&self) -> Option<(InputLag, f64)> {
        None
    }

    /// Pushes every sample of `u`, `x`, writing the predictions (as `push`) into
    /// `out`. If any sample is non-finite, or the lengths differ, the whole call is
    /// rejected before the state changes.
    fn push_many(&mut self, u: &[f64], x: &[f64], out: &mut [f64]) -> Result<()> {
        if x.len() != u.len() {
            return Err(Error::LengthMismatch { what: "x (same length as u)", expected: u.len(), found: x.len() });
        }
        if out.len() != u.len() {
            return Err(Error::LengthMismatch { what: "output", expected: u.len(), found: out.len() });
        }
        for (&a, &b) in u.iter().zip(x) {
            finite_sample("u", a)?;
            finite_sample("x", b)?;
        }
        for ((o, &a), &b) in out.iter_mut().zip(u).zip(x) {
            *o = self.push(a, b)?;
        }
        Ok(())
    }
}

/// Any of the crate's online methods, for callers that choose at run time.
///
/// Held inline, not boxed: the run-time dispatch of `push` costs one match, no
/// indirection, and construction allocates nothing more than the method does.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum AnyIdentifier {
    /// The paper's method.
    Paper(PaperIdentifier),
    /// The output-error recursive prediction-error method ("rpem").
    Rpem(RpemIdentifier),
    /// The moving-horizon output-error method ("horizon").
    Horizon(HorizonIdentifier),
}

/// The status of an [`AnyIdentifier`]: that of its method.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AnyStatus {
    /// Status of the paper's method.
    Paper(PaperStatus),
    /// Status of the rpem method.
    Rpem(RpemStatus),
    /// Status of the moving-horizon method.
    Horizon(HorizonStatus),
}

impl AnyIdentifier {
    /// Short name of the method.
    pub fn method(&self) -> &'static str {
        match self {
            AnyIdentifier::Paper(_) => "paper",
            AnyIdentifier::Rpem(_) => "rpem",
            AnyIdentifier::Horizon(_) => "horizon",
        }
    }

    /// The identifier's byte snapshot (see [`Snapshot`]).
    pub fn to_snapshot(&self) -> Vec<u8> {
        match self {
            AnyIdentifier::Paper(id) => id.to_bytes(),
            AnyIdentifier::Rpem(id) => id.to_bytes(),
            AnyIdentifier::Horizon(id) => id.to_bytes(),
        }
    }

    /// Rebuilds an identifier from [`AnyIdentifier::to_snapshot`]; the method is
    /// read from the snapshot's kind byte.
    pub fn from_snapshot(bytes: &[u8]) -> Result<Self> {
        match bytes.get(5) {
            Some(&KIND_PAPER) => Ok(AnyIdentifier::Paper(PaperIdentifier::from_bytes(bytes)?)),
            Some(&KIND_RPEM) => Ok(AnyIdentifier::Rpem(RpemIdentifier::from_bytes(bytes)?)),
            Some(&KIND_HORIZON) => Ok(AnyIdentifier::Horizon(HorizonIdentifier::from_bytes(bytes)?)),
            _ => Err(corrupt(5, "not a snapshot of an online identifier")),
        }
    }
}

impl OnlineIdentifier for AnyIdentifier {
    type Status = AnyStatus;

    #[inline]
    fn push(&mut self, u: f64, x: f64) -> Result<f64> {
        match self {
            AnyIdentifier::Paper(id) => id.push(u, x),
            AnyIdentifier::Rpem(id) => id.push(u, x),
            AnyIdentifier::Horizon(id) => id.push(u, x),
        }
    }
    fn params(&self) -> Params {
        match self {
            AnyIdentifier::Paper(id) => id.params(),
            AnyIdentifier::Rpem(id) => id.params(),
            AnyIdentifier::Horizon(id) => id.params(),
        }
    }
    fn h(&self) -> f64 {
        match self {
            AnyIdentifier::Paper(id) => id.h(),
            AnyIdentifier::Rpem(id) => id.h(),
            AnyIdentifier::Horizon(id) => id.h(),
        }
    }
    fn status(&self) -> AnyStatus {
        match self {
            AnyIdentifier::Paper(id) => AnyStatus::Paper(id.status()),
            AnyIdentifier::Rpem(id) => AnyStatus::Rpem(id.status()),
            AnyIdentifier::Horizon(id) => AnyStatus::Horizon(id.status()),
        }
    }
    fn input_lag(&self) -> Option<(InputLag, f64)> {
        match self {
            AnyIdentifier::Paper(id) => id.input_lag(),
            AnyIdentifier::Rpem(id) => id.input_lag(),
            AnyIdentifier::Horizon(id) => id.input_lag(),
        }
    }
    fn reset(&mut self) {
        match self {
            AnyIdentifier::Paper(id) => id.reset(),
            AnyIdentifier::Rpem(id) => id.reset(),
            AnyIdentifier::Horizon(id) => id.reset(),
        }
    }
    fn forecast_into(&self, u: &[f64], out: &mut [f64]) -> Result<()> {
        match self {
            AnyIdentifier::Paper(id) => id.forecast_into(u, out),
            AnyIdentifier::Rpem(id) => id.forecast_into(u, out),
            AnyIdentifier::Horizon(id) => id.forecast_into(u, out),
        }
    }
}

/// Checks the arguments of [`OnlineIdentifier::forecast_into`].
pub(crate) fn check_forecast(u: &[f64], out: &[f64]) -> Result<()> {
    if out.len() != u.len() {
        return Err(Error::LengthMismatch { what: "forecast output", expected: u.len(), found: out.len() });
    }
    for &v in u {
        finite_sample("u", v)?;
    }
    Ok(())
}
