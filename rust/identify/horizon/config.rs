//! Tuning of the moving-horizon identifier and its status.

use crate::error::{Error, Result};

/// Tuning of [`super::HorizonIdentifier`], with documented defaults ([`Default`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HorizonConfig {
    /// Length of the horizon measured in input travel \[V\]: the window holds the newest
    /// samples over which u has moved by this much in all. One period of a 0–100 V
    /// sine is 200 V of travel at any frequency, so the default 300 V is the newest
    /// one and a half periods at 1 Hz and at 200 Hz alike (longer windows follow a
    /// change of frequency more slowly; on the simulated bench 250–300 V scored best
    /// period-ahead); while u holds the window keeps its samples (nothing is
    /// forgotten, no wind-up).
    pub memory_travel_v: f64,
    /// The window also holds at most this × the samples over which u travelled the
    /// newest half of `memory_travel_v`: when the input speeds up (a switch from 10 Hz
    /// to 100 Hz), the slow samples, many per volt, leave the window within a period of
    /// the new input instead of outweighing it for a whole memory. On a steady periodic
    /// input the window is then about 0.75 × `memory_travel_v` long. Default 1.5
    /// (∞: no such limit); at least 1.
    pub recent_factor: f64,
    /// Most samples the window holds (the buffer is allocated once, at construction,
    /// 120 bytes a sample, and 24 more for the background mode's sample ring). Default
    /// 40 000 (two periods of 1 Hz at 20 kHz).
    pub max_window: usize,
    /// Samples of the window's simulation run per push: a pass over a window of W
    /// samples ends after about W / (this − 1) pushes. Default 16: about 15 updates
    /// per window, enough to follow the paper's switches within a period or two.
    pub samples_per_push: usize,
    /// A pass leads to an update only when it spans at least this fraction of
    /// `memory_travel_v` (or half of `max_window` samples). Default 0.5.
    pub min_pass_fraction: f64,
    /// Relative weight of a proximal term that keeps each update near the current
    /// estimates in the directions the window does not determine well (and the normal
    /// equations well posed): ρ·mean(diag JᵀJ) is added to the diagonal. Default 1e-3:
    /// started from an offline fit on a record that does not change, the model stays
    /// within a few % of the fit period-ahead instead of chasing the window's noise.
    pub ridge: f64,
    /// Initial Levenberg–Marquardt damping μ (relative to diag JᵀJ). Default 1e-3.
    pub damping: f64,
    /// Largest change of any parameter in one update, as a fraction of its scale
    /// (trust region). Default 0.5.
    pub max_step: f64,
    /// n is held within these bounds. Default (0.25, 4.0).
    pub n_bounds: (f64, f64),
    /// With an identified input lag, its corner frequency is held within these
    /// bounds \[Hz\]. Default (10, 1e5).
    pub fc_bounds_hz: (f64, f64),
    /// β + γ and β − γ are held at or above this [µm^(1−n)/V] (> 0: inside the
    /// admissible region, where the δ term is dissipated on both branches of the loop).
    /// Default 1e-6.
    pub margin: f64,
    /// Scale of each parameter (kv, x0, A, β, γ, n, δ) and of the window's initial h
    /// \[µm\]: the update works on θᵢ/scaleᵢ. Default (0.2, 0.1, 0.07, 0.02, 0.02, 1.5,
    /// 0.007, 0.1).
    pub scales: [f64; 8],
}

impl Default for HorizonConfig {
    fn default() -> Self {
        HorizonConfig {
            memory_travel_v: 300.0,
            recent_factor: 1.5,
            max_window: 40_000,
            samples_per_push: 16,
            min_pass_fraction: 0.5,
            ridge: 1e-3,
            damping: 1e-3,
            max_step: 0.5,
            n_bounds: (0.25, 4.0),
            fc_bounds_hz: (10.0, 1e5),
            margin: 1e-6,
            scales: [0.2, 0.1, 0.07, 0.02, 0.02, 1.5, 0.007, 0.1],
        }
    }
}

impl HorizonConfig {
    /// Largest accepted `max_window` \[samples\].
    pub const MAX_WINDOW: usize = 10_000_000;
    /// Fewest samples the window keeps (and the least `max_window`).
    pub const MIN_WINDOW: usize = 16;

    /// Checks every value; the error names the offending option.
    pub fn validate(&self) -> Result<()> {
        let bad = |name, value: f64, reason| Err(Error::InvalidConfig { name, value, reason });
        if !(self.memory_travel_v.is_finite() && self.memory_travel_v > 0.0) {
            return bad("memory_travel_v", self.memory_travel_v, "must be finite and > 0 V");
        }
        if self.recent_factor.is_nan() || self.recent_factor < 1.0 {
            return bad("recent_factor", self.recent_factor, "must be >= 1 (inf: no limit)");
        }
        if !(Self::MIN_WINDOW..=Self::MAX_WINDOW).contains(&self.max_window) {
            return bad("max_window", self.max_window as f64, "must be between 16 and 10 000 000 samples");
        }
        if !(2..=64).contains(&self.samples_per_push) {
            return bad("samples_per_push", self.samples_per_push as f64, "must be between 2 and 64");
        }
        if !(self.min_pass_fraction.is_finite() && self.min_pass_fraction > 0.0 && self.min_pass_fraction <= 1.0) {
            return bad("min_pass_fraction", self.min_pass_fraction, "must be in (0, 1]");
        }
        for (name, v) in [("ridge", self.ridge), ("damping", self.damping), ("max_step", self.max_step)] {
            if !(v.is_finite() && v > 0.0) {
                return bad(name, v, "must be finite and > 0");
            }
        }
        let (lo, hi) = self.n_bounds;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
            return bad("n_bounds", lo, "need 0 < n_min <= n_max, both finite");
        }
        let (lo, hi) = self.fc_bounds_hz;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
            return bad("fc_bounds_hz", lo, "need 0 < fc_min <= fc_max, both finite");
        }
        // > 0: the δ the method estimates is dissipated only where β + γ and β − γ are
        // both > 0 (the admissible region, docs/design.md).
        if !(self.margin.is_finite() && self.margin > 0.0) {
            return bad("margin", self.margin, "must be finite and > 0");
        }
        for v in self.scales {
            if !(v.is_finite() && v > 0.0) {
                return bad("scales", v, "every parameter scale must be finite and > 0");
            }
        }
        Ok(())
    }
}

/// Where the window pass of a [`super::HorizonIdentifier`] runs (see the module docs
/// of [`super`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RefineMode {
    /// In `push`, a share of the pass in every push: the predictions of every earlier
    /// release, bit for bit. The default.
    #[default]
    Sync,
    /// In [`super::HorizonIdentifier::refine`], called when the loop has time; `push`
    /// only predicts and stores. No thread (`no_std`, the C ABI).
    Cooperative,
}

impl RefineMode {
    /// Short name: "sync" or "cooperative".
    pub fn name(self) -> &'static str {
        match self {
            RefineMode::Sync => "sync",
            RefineMode::Cooperative => "cooperative",
        }
    }
}

/// What the last push of a [`super::HorizonIdentifier`] did. `Copy`, no allocation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HorizonStatus {
    /// Samples pushed since construction or reset.
    pub samples: u64,
    /// The estimates were updated in this push (sync mode: the push after a pass over
    /// the window caught up with the newest sample) or, in cooperative mode, in the
    /// `refine` calls since it (cleared by the next push).
    pub updated: bool,
    /// Updates since construction or reset.
    pub updates: u64,
    /// Samples in the window.
    pub window_samples: u64,
    /// Input travel over the window \[V\].
    pub window_travel_v: f64,
    /// RMS output error over the window's last pass, with the estimates it ran \[µm\].
    pub rms_um: f64,
    /// Levenberg–Marquardt damping μ after the last update.
    pub damping: f64,
    /// The trust region scaled the last update down.
    pub step_limited: bool,
    /// The projection onto the well-posed region moved n, β or γ in the last update
    /// (after the step was held on it: what rounding and the trust region left outside).
    pub projected: bool,
    /// The last update's step would have left the well-posed region (n outside
    /// `n_bounds`, β + γ or β − γ below `margin`) and was held on its boundary: those
    /// constraints made active and the step solved again on the rest.
    pub held: bool,
    /// How far the estimates in use lag the newest sample \[samples\]: samples pushed
    /// after the last one the pass of the last update ran over (all samples before the
    /// first update). In sync mode at most about one pass (the window / 15); where the
    /// pass cannot keep up (cooperative `refine` or the background worker starved) it
    /// grows.
    pub behind_samples: u64,
    /// The same in seconds (`behind_samples` × dt) \[s\].
    pub behind_s: f64,
}
