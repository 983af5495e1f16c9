//! The output gate (`PaperConfig::output_gate`): an update is taken only where it does
//! not make the window's own output error worse than the estimates it would replace.

use alloc::vec::Vec;

use super::window::Ring;
use super::Point;
use crate::model::simulate_into;
use crate::params::Params;

/// Work buffers of the output gate (the window's inputs and the simulated outputs). A
/// pure cache: not saved in snapshots, never compared (two identifiers in the same
/// state are equal whatever their buffers hold).
#[derive(Debug, Clone, Default)]
pub(super) struct Scratch {
    pub(super) u: Vec<f64>,
    pub(super) x: Vec<f64>,
}

impl PartialEq for Scratch {
    fn eq(&self, _other: &Self) -> bool {
        true
    }
}

/// The window's own output error of the estimates `p` (the output gate,
/// [`PaperConfig::output_gate`]): Σ (x − x̂)² over the window's points, x̂ the model `p`
/// simulated over the window's inputs (`scratch.u`, filled by the caller) from h at
/// the oldest point as `p` reads it there, x − kv·u − x0. Infinite where the model
/// cannot be simulated or leaves the finite numbers.
fn window_sse(window: &Ring<Point>, scratch: &mut Scratch, dt: f64, p: &Params) -> f64 {
    let Some(first) = window.iter().next() else {
        return 0.0;
    };
    let h0 = first.x - p.kv * first.u - p.x0;
    scratch.x.resize(scratch.u.len(), 0.0);
    if simulate_into(p, &scratch.u, dt, h0, None, &mut scratch.x).is_err() {
        return f64::INFINITY;
    }
    let sse = window.iter().zip(&scratch.x).fold(0.0, |acc, (q, xs)| {
        let e = q.x - xs;
        acc + e * e
    });
    if sse.is_finite() {
        sse
    } else {
        f64::INFINITY
    }
}

/// The output gate's state within one refit: the window's output error of the
/// estimates taken so far (computed when first needed) and the tolerance per unknown.
pub(super) struct Gate {
    pub(super) on: bool,
    /// `scratch.u` holds this refit's window inputs.
    pub(super) filled: bool,
    pub(super) held_sse: Option<f64>,
    /// `output_gate`·σ̂² \[µm²\]: the rise of the sum allowed per unknown changed.
    pub(super) per_unknown: f64,
}

impl Gate {
    /// Whether `candidate` (changing `k` unknowns of `held`) is taken; on yes, its error
    /// becomes the one to beat.
    pub(super) fn accepts(
        &mut self,
        window: &Ring<Point>,
        scratch: &mut Scratch,
        dt: f64,
        held: &Params,
        candidate: &Params,
        k: f64,
    ) -> bool {
        if !self.on || candidate == held {
            return true;
        }
        if !self.filled {
            scratch.u.clear();
            scratch.u.extend(window.iter().map(|q| q.u));
            self.filled = true;
        }
        let before = *self.held_sse.get_or_insert_with(|| window_sse(window, scratch, dt, held));
        let after = window_sse(window, scratch, dt, candidate);
        let taken = after.is_finite() && (before == f64::INFINITY || after <= before + k * self.per_unknown);
        if taken {
            self.held_sse = Some(after);
        }
        taken
    }
}
