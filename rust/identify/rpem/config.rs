//! Tuning of the rpem identifier and its status.

use super::*;

/// Tuning of [`RpemIdentifier`], with documented defaults ([`Default`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RpemConfig {
    /// Forgetting factor per sample λ ∈ (0, 1]: a memory of about 1/(1 − λ)
    /// samples whatever the input does. Default 1.0 (none; see `memory_travel_v`).
    pub forgetting: f64,
    /// Memory measured in input travel \[V\]: a sample's weight falls by
    /// exp(−|Δu|/`memory_travel_v`) for every later interval in which u moves by
    /// |Δu|. One period of the paper's 0–100 V sine is 200 V of travel at any
    /// frequency, so the memory spans the same number of periods at 1 Hz and at
    /// 200 Hz, and nothing is forgotten while u holds (no wind-up). Default 400 V
    /// (two periods: long enough to average sensor noise and floor vibration, short
    /// enough to follow a change of frequency; on the simulated bench the model is
    /// best period-ahead there); `f64::INFINITY` turns it off.
    pub memory_travel_v: f64,
    /// Initial covariance P₀ = `p0`·I of the scaled parameters θᵢ/scaleᵢ: the prior
    /// standard deviation of θᵢ is √p0·scaleᵢ. Default 1e-3 (3 % of the scale; larger
    /// values overshoot in the first period, the model being far from linear in θ).
    pub p0: f64,
    /// Random walk of the offset x0 [µm per sample, standard deviation]: x0 may
    /// wander by this much from one sample to the next (creep, drift, thermal), so
    /// its variance grows by `offset_walk_um`² each sample, whatever the input does
    /// (P\[x0,x0\] stays bounded because x0 is always observed). Default 0: x0 is a
    /// parameter like the others. A walking offset follows whatever the model cannot
    /// explain within a few samples: it makes the one-step prediction sharp but the
    /// *model* worse (frozen at any instant, x0 carries that instant's vibration).
    pub offset_walk_um: f64,
    /// Initial covariance of the effects' coordinates: ln fc of the input lag and
    /// the logistic coordinate η = ln(g/(gmax − g)) of each creep gain, which near
    /// the usual gains (g ≪ gmax) is ln g. Both are relative: √p0_effects is the
    /// prior relative standard deviation of fc and of each gain. Default 0.05
    /// (about 22 %): the effects are meant to start from an offline extended fit
    /// (`fit_extended`, `diagnose`) or a guess within some 30 %.
    pub p0_effects: f64,
    /// R: the least variance the prediction error is expected to have \[µm²\] (sensor
    /// noise and the modelling floor). Default 1e-4 µm² (0.01 µm). R is learnt from the
    /// data above it (see `noise_memory_samples`).
    pub noise_um2: f64,
    /// Memory \[samples\] of the running mean of the squared prediction errors that R
    /// follows (R = max(that mean, `noise_um2`)): on a record with vibration or an
    /// unmodelled effect the gain falls by itself, instead of chasing them. Default
    /// 2000; `f64::INFINITY` keeps R = `noise_um2`.
    pub noise_memory_samples: f64,
    /// Bound on tr P (scaled units). Default 1.0.
    pub max_trace: f64,
    /// Largest change of any parameter in one sample, as a fraction of its scale
    /// (trust region). Default 0.01.
    pub max_step: f64,
    /// Largest change of the offset x0 in one sample \[µm\]. Default 0.5 µm.
    pub max_offset_step_um: f64,
    /// n is held within these bounds. Default (1.0, 4.0).
    pub n_bounds: (f64, f64),
    /// β + γ and β − γ are held at or above this [µm^(1−n)/V] (> 0: inside the
    /// admissible region, where the δ term is dissipated on both branches of the loop).
    /// Default 1e-6.
    pub margin: f64,
    /// Scale of each parameter (kv, x0, A, β, γ, n, δ, in their units): the
    /// identifier works on θᵢ/scaleᵢ. Default (0.2, 0.1, 0.07, 0.02, 0.02, 1.5, 0.007):
    /// the paper's Table 2 magnitudes, with 0.1 µm for the offset. The lag's
    /// ln fc has scale 1 (a step of `max_step` = 1 % of fc).
    pub scales: [f64; NUM_BASE],
    /// Scale of the creep gains \[µm/V\]. Default 0.002 µm/V.
    pub creep_gain_scale_um_per_v: f64,
    /// Each creep gain is held within [0, this] \[µm/V\] (creep follows the voltage;
    /// the slow elements are nearly collinear with x0 over short records and would
    /// otherwise drift against it). Default 0.02 µm/V.
    pub creep_gain_max_um_per_v: f64,
    /// The lag's corner frequency is held within these bounds \[Hz\]. Default (10, 1e5) Hz.
    pub fc_bounds_hz: (f64, f64),
}

impl Default for RpemConfig {
    fn default() -> Self {
        RpemConfig {
            forgetting: 1.0,
            memory_travel_v: 400.0,
            offset_walk_um: 0.0,
            p0: 1e-3,
            p0_effects: 0.05,
            noise_um2: 1e-4,
            noise_memory_samples: 2000.0,
            max_trace: 1.0,
            max_step: 0.01,
            max_offset_step_um: 0.5,
            n_bounds: (0.25, 4.0),
            margin: 1e-6,
            scales: [0.2, 0.1, 0.07, 0.02, 0.02, 1.5, 0.007],
            creep_gain_scale_um_per_v: 0.002,
            creep_gain_max_um_per_v: 0.02,
            fc_bounds_hz: (10.0, 1e5),
        }
    }
}

impl RpemConfig {
    /// The defaults for a model extended by `effects`: as [`Default`], but with
    /// `creep` among them the offset x0 is a constant (`offset_walk_um` = 0): the
    /// creep elements describe what the random walk absorbs otherwise, and a walking
    /// offset would take every slow error before the creep gains could see it.
    pub fn for_effects(effects: &EffectSet) -> Self {
        let mut cfg = Self::default();
        if effects.creep.is_some() {
            cfg.offset_walk_um = 0.0;
        }
        cfg
    }

    /// The tuning for a compensator in closed loop (`crate::compensate::Compensator`):
    /// there the prediction one sample ahead is what the inverse acts on, so the offset
    /// x0 walks (0.05 µm per sample) to take up within a few samples what the model
    /// cannot explain, the memory is ten periods of travel (2000 V) and R stays at
    /// `noise_um2`. As a *model* this tuning is worse (see the default's docs).
    pub fn for_tracking() -> Self {
        RpemConfig {
            offset_walk_um: 0.05,
            memory_travel_v: 2000.0,
            noise_memory_samples: f64::INFINITY,
            ..Self::default()
        }
    }

    /// Checks every value; the error names the offending option.
    pub fn validate(&self) -> Result<()> {
        let bad = |name, value: f64, reason| Err(Error::InvalidConfig { name, value, reason });
        if !(self.forgetting > 0.0 && self.forgetting <= 1.0) {
            return bad("forgetting", self.forgetting, "the forgetting factor must be in (0, 1]");
        }
        for (name, v) in [
            ("p0", self.p0),
            ("noise_um2", self.noise_um2),
            ("max_trace", self.max_trace),
            ("max_step", self.max_step),
            ("max_offset_step_um", self.max_offset_step_um),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(name, v, "must be finite and > 0");
            }
        }
        if !(self.p0_effects.is_finite() && self.p0_effects > 0.0) {
            return bad("p0_effects", self.p0_effects, "must be finite and > 0");
        }
        if self.p0 * NUM_BASE as f64 > self.max_trace {
            return bad("p0", self.p0, "the initial covariance trace (7·p0) must not exceed max_trace");
        }
        let (lo, hi) = self.n_bounds;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
            return bad("n_bounds", lo, "need 0 < n_min <= n_max, both finite");
        }
        if self.noise_memory_samples.is_nan() || self.noise_memory_samples < 1.0 {
            return bad("noise_memory_samples", self.noise_memory_samples, "must be >= 1 sample (inf keeps R fixed)");
        }
        if !(self.offset_walk_um.is_finite() && self.offset_walk_um >= 0.0) {
            return bad("offset_walk_um", self.offset_walk_um, "must be finite and >= 0 µm");
        }
        if self.memory_travel_v.is_nan() || self.memory_travel_v <= 0.0 {
            return bad("memory_travel_v", self.memory_travel_v, "must be > 0 V (inf turns travel forgetting off)");
        }
        // > 0: the δ the method estimates is dissipated only where β + γ and β − γ are
        // both > 0 (the admissible region, docs/design.md).
        if !(self.margin.is_finite() && self.margin > 0.0) {
            return bad("margin", self.margin, "must be finite and > 0");
        }
        if !(self.creep_gain_scale_um_per_v.is_finite() && self.creep_gain_scale_um_per_v > 0.0) {
            return bad("creep_gain_scale_um_per_v", self.creep_gain_scale_um_per_v, "must be finite and > 0");
        }
        if !(self.creep_gain_max_um_per_v.is_finite() && self.creep_gain_max_um_per_v > 0.0) {
            return bad("creep_gain_max_um_per_v", self.creep_gain_max_um_per_v, "must be finite and > 0");
        }
        let (lo, hi) = self.fc_bounds_hz;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
            return bad("fc_bounds_hz", lo, "need 0 < fc_min <= fc_max, both finite");
        }
        for v in self.scales {
            if !(v.is_finite() && v > 0.0) {
                return bad("scales", v, "every parameter scale must be finite and > 0");
            }
        }
        Ok(())
    }
}

/// What the last push of an [`RpemIdentifier`] did. `Copy`, no allocation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RpemStatus {
    /// Samples pushed since construction or reset.
    pub samples: u64,
    /// The parameters were updated (false on the first sample and after a dropped step).
    pub updated: bool,
    /// The trust region scaled the step down.
    pub step_limited: bool,
    /// The projection moved n, β or γ.
    pub projected: bool,
    /// The trace bound scaled P down.
    pub trace_capped: bool,
    /// A non-finite step, covariance or sensitivity was dropped (P restarted).
    pub restarted: bool,
    /// Prediction error e = x − x̂ of the sample \[µm\].
    pub innovation_um: f64,
    /// tr P after the push (scaled units).
    pub trace: f64,
    /// R in use after the push: the learnt variance of the prediction error \[µm²\].
    pub noise_um2: f64,
}
