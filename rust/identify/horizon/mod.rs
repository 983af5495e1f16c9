//! Moving-horizon output-error identification ("horizon"): the paper's limited-memory
//! least squares, applied to the model's *output* (simulation) error and spread over
//! the samples so that every push costs about the same.
//!
//! The window holds the newest samples over which the input has travelled
//! `memory_travel_v` volts (one and a half periods of the paper's 0–100 V sine by
//! default, at any frequency), and at most `recent_factor` × the samples of the newest
//! half of that travel (so that after a switch to a faster input the slow samples, many
//! per volt, leave within a period). Its cost is the output error of the model simulated
//! open loop over the window from an initial state h_s, a free unknown like the seven
//! parameters:
//!
//! ```text
//! J(θ, h_s) = Σ_{k in window} (x_k − kv·u_a,k − x0 − h_k(θ, h_s))²,   θ = (kv, x0, A, β, γ, n, δ)
//! ```
//!
//! With an input lag ([`HorizonIdentifier::with_effects`], and by default in
//! [`HorizonIdentifier::recommended`]) u_a is the command u through the first-order lag
//! τ·u̇_a = u − u_a of [`crate::effects::input_lag`], and ln fc is a ninth unknown whose
//! sensitivity is carried through the same integrator; without it u_a = u.
//!
//! Per sample:
//! 1. **Predict** x̂ₖ = kv·uₖ + x0 + hₖ with the current estimates, h advanced by the
//!    model's own integrator from the previous sample (this is the model the caller
//!    uses; it is never reset from the measurement).
//! 2. **Store** the sample; the window's start moves on as the travel grows.
//! 3. **Pass.** A simulation of the window with the current estimates runs
//!    `samples_per_push` samples further, on dual numbers ([`crate::model::advance`],
//!    |h|^n and ln|h| carried from one sample to the next where h moved by at most
//!    0.1 % of itself, so that `powf` and `ln` run only where h moves fast or near 0),
//!    accumulating the Gauss–Newton normal equations JᵀJ, Jᵀr over the 8 unknowns (9
//!    with the input lag).
//!    When it has caught up with the newest sample (and spans at least
//!    `min_pass_fraction` of the memory), the next push runs it over the one new
//!    sample and takes, instead of a further share of the pass, one
//!    Levenberg–Marquardt step in
//!    scaled coordinates, bounded by a trust region and projected onto the region
//!    where the model is well posed (n within `n_bounds`, β ± γ ≥ `margin`); the
//!    model's h is moved to first order with the step (∂h/∂θ of the pass), and a new
//!    pass starts at the window's current start, from the h that the last pass
//!    computed there (moved likewise).
//!
//! The damping μ adapts: ×4 when a pass's mean squared error is more than 10 % above
//! the previous one's, ×½ otherwise. While the input holds the window's travel does not
//! grow, no pass reaches the span it needs, and nothing changes.
//!
//! Worst case per push, by construction: one integration interval for the prediction
//! and either `samples_per_push` intervals on 7-derivative duals or one interval and
//! the update (a 9 × 9 Cholesky solve and up to three re-solves for the active bounds),
//! each interval bounded by the integrator's 32 sub-steps; the window's start moves by
//! a galloping search over the stored travel (1 or 2 probes when it moves by a sample,
//! at most 48 at the largest `max_window`, however many samples leave at once). The
//! window buffer is the one allocation (at
//! construction, `max_window` samples).
//! Starting values are used as given (n < 1 included; the sensitivities are
//! regularised at h = 0, see [`crate::model::scalar::SLOPE_FLOOR_UM`]).
//!
//! # Two paths: `push` and the window pass
//!
//! Steps 1 and 2 are the loop's (the prediction, now); step 3 is the window pass (the
//! estimates, soon). [`RefineMode`] says where the pass runs:
//! - [`RefineMode::Sync`] (the default): in-line, a share of it in every push, as
//!   described above. Deterministic; the predictions are those of every earlier
//!   release, bit for bit.
//! - [`RefineMode::Cooperative`]: `push` does steps 1 and 2 only (one integration
//!   interval, the window's start moved by a galloping search: no O(window) work, no
//!   allocation); the pass runs in [`HorizonIdentifier::refine`]`(max_intervals)`,
//!   called when the loop has time (an idle loop, a lower-priority task). No thread:
//!   the mode for `no_std` and the C ABI. A pass runs over the samples stored when it
//!   started; its update is carried (one scalar interval per sample) from the pass's
//!   last sample to the newest one with the new estimates, and only then adopted:
//!   parameters, lag, h and u_a switch together, between two pushes. Where `refine`
//!   gets less time than the samples need, passes still end and the estimates still
//!   improve, over the window the usual rule keeps (older samples leave it as the
//!   input travels, whether a pass has seen them or not). Deterministic for a given
//!   sequence of pushes and `refine` calls (same calls, same budgets, same bits).
//! - Background (`std`): [`BackgroundHorizon`], a worker thread owned by the identifier
//!   runs the cooperative pass; see its docs. Not deterministic.
//!
//! [`HorizonStatus::behind_samples`] says how far the estimates in use lag the
//! newest sample.

#[cfg(feature = "std")]
mod background;
mod config;
mod pass;
mod snapshot;

#[cfg(feature = "std")]
pub use background::BackgroundHorizon;
pub use config::{HorizonConfig, HorizonStatus, RefineMode};

use alloc::vec::Vec;

use nalgebra::{SMatrix, SVector};

use super::OnlineIdentifier;
use crate::effects::input_lag::LagStage;
use crate::effects::{EffectSet, InputLag};
use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::math;
use crate::model::integrator::Drive;
use crate::model::scalar::Dual;
use crate::model::{advance_h, output};
use crate::params::Params;
use pass::Pass;

/// Unknowns of the window fit: kv, x0, A, β, γ, n, δ, the window's initial h and
/// ln fc of the input lag (a zero column without the lag).
const NZ: usize = 9;
/// Derivatives carried through the integrator: A, β, γ, n, δ, the initial h and ln fc.
const ND: usize = 7;
/// Position of ln fc among the unknowns.
const I_LN_FC: usize = 8;
/// Scale of ln fc in the update (a step of 0.5 changes fc by 65 %).
const LN_FC_SCALE: f64 = 0.5;

type Normal = SMatrix<f64, NZ, NZ>;
type Vector = SVector<f64, NZ>;

/// One stored sample: u \[V\], x \[µm\], the h of the last pass there with its
/// derivatives over (A, β, γ, n, δ, h_s, ln fc), and the voltage on the stack u_a \[V\]
/// with its derivative over ln fc. (The input travel up to it is kept apart, in
/// `HorizonIdentifier::travels`, so that the window's search reads 8 bytes a sample.)
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Entry {
    u: f64,
    x: f64,
    h: f64,
    dh: [f64; ND],
    ua: f64,
    dua: f64,
}

/// The input lag with corner `fc_hz` \[Hz\] for samples every `dt` \[s\].
fn lag_of(fc_hz: f64, dt: f64) -> LagStage {
    InputLag { fc_hz }.stage(dt)
}

/// [`LagStage::advance`] on duals: every derivative of `ua` passes through with the
/// decay, and the ln fc slot gains the step's own ∂u_a/∂ln fc.
#[inline]
fn lag_step_dual(lag: &LagStage, ua: Dual<ND>, u0: f64, u1: f64, dt: f64) -> Dual<ND> {
    let mut du = ua.du * lag.decay();
    du[I_LN_FC - 2] += lag.ln_fc_slope(ua.re, u0, u1, dt);
    Dual::new(lag.advance(ua.re, u0, u1, dt), du)
}

/// One interval of the loop's model from the voltage `u_prev` \[V\] of the last sample
/// to `u` \[V\]: u_a through the lag (`lag`, when one is identified), h by the model's
/// integrator. Takes and returns (h \[µm\], u_a \[V\]); on the first sample (`u_prev`
/// None) u_a is u and h stays.
#[inline(always)]
fn loop_interval(
    p: &Params,
    lag: Option<&LagStage>,
    dt: f64,
    (h, ua): (f64, f64),
    u_prev: Option<f64>,
    u: f64,
) -> (f64, f64) {
    let Some(u0) = u_prev else {
        return (h, u);
    };
    let ua_next = match lag {
        Some(lag) => lag.advance(ua, u0, u, dt),
        None => u,
    };
    (advance_h(&Drive::of(u0, u).params(p), h, ua, ua_next, dt), ua_next)
}

/// The loop's model run open loop over the voltages `u` \[V\] from state (h, u_a) after
/// a sample at voltage `u_prev`, the displacements \[µm\] into `out` (of `u`'s length).
fn forecast_from(
    p: &Params,
    lag: Option<&LagStage>,
    dt: f64,
    mut state: (f64, f64),
    mut u_prev: Option<f64>,
    u: &[f64],
    out: &mut [f64],
) {
    for (o, &v) in out.iter_mut().zip(u) {
        state = loop_interval(p, lag, dt, state, u_prev, v);
        u_prev = Some(v);
        *o = output(p, state.1, state.0);
    }
}

/// Cooperative mode: the estimates of a finished pass, carried with the model's own
/// integrator from the pass's last sample towards the newest one before they are
/// adopted (so that parameters, lag, h and u_a switch together).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Pending {
    /// Absolute index of the sample the carried state is at.
    at: u64,
    params: Params,
    /// ln fc of the input lag (`None` without the lag).
    ln_fc: Option<f64>,
    /// h there \[µm\].
    h: f64,
    /// u_a there \[V\].
    ua: f64,
    /// Samples the update was fitted on (its pass ended at sample `fitted − 1`).
    fitted: u64,
}

/// The moving-horizon identifier (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct HorizonIdentifier {
    config: HorizonConfig,
    dt: f64,
    init: Params,
    h0: f64,
    params: Params,
    /// ln fc of the identified input lag (fc \[Hz\]); `None` without the lag.
    ln_fc: Option<f64>,
    /// The lag's starting ln fc (for `reset`).
    ln_fc0: Option<f64>,
    /// The lag at the current estimate.
    lag: LagStage,
    /// The model's h at the last sample (the prediction's state).
    h: f64,
    /// The model's voltage on the stack at the last sample \[V\] (= u without the lag).
    ua: f64,
    u_prev: Option<f64>,
    /// Ring buffer of the newest samples, `max_window` slots.
    buffer: Vec<Entry>,
    /// The input travel up to each sample of `buffer` \[V\], slot for slot.
    travels: Vec<f64>,
    /// Absolute index of the next sample (= samples pushed).
    next: u64,
    /// Absolute index of the window's first sample.
    start: u64,
    /// Absolute index of the first sample of the newest half of the memory's travel.
    mid: u64,
    pass: Pass,
    /// The pass has caught up and spans enough: the next push ends it (one sample of
    /// the pass, then the update), so that no push does both a full share of the pass
    /// and the solve.
    finish_due: bool,
    /// Mean squared error of the last finished pass \[µm²\] (∞ before the first).
    last_mse: f64,
    damping: f64,
    status: HorizonStatus,
    /// Where the window pass runs.
    mode: RefineMode,
    /// Cooperative mode: the pass ends at this absolute index (exclusive), the newest
    /// sample when it started (or later, when it had to wait for enough travel).
    pass_end: u64,
    /// Cooperative mode: the update of a finished pass, not adopted yet.
    pending: Option<Pending>,
    /// Samples the estimates in use were fitted on: the pass of the last update ended
    /// at sample `fitted − 1` (0 before the first update).
    fitted: u64,
}

impl HorizonIdentifier {
    /// An identifier for samples every `dt` \[s\], starting from `init` (used as given;
    /// it must lie in the admissible region, [`Params::check_admissible`], and is refused
    /// otherwise) with model state `h0` \[µm\].
    pub fn new(dt: f64, init: Params, h0: f64, config: HorizonConfig) -> Result<Self> {
        Self::with_effects(dt, init, &EffectSet::none(), h0, config)
    }

    /// The recommended model: as [`HorizonIdentifier::new`] with an input lag identified
    /// along, starting at fc = [`Self::LAG_START_FRACTION`] / dt (held within the
    /// configured bounds). Every piezo amplifier has a finite bandwidth on its
    /// capacitive load; at a third of the sampling rate the starting lag is negligible
    /// for slow inputs, and the data move it where it shows (fast inputs).
    pub fn recommended(dt: f64, init: Params, h0: f64, config: HorizonConfig) -> Result<Self> {
        positive_dt(dt)?;
        let (lo, hi) = config.fc_bounds_hz;
        let fc_hz = (Self::LAG_START_FRACTION / dt).clamp(lo.min(hi), hi.max(lo));
        let effects = EffectSet { input_lag: Some(InputLag { fc_hz }), ..EffectSet::none() };
        Self::with_effects(dt, init, &effects, h0, config)
    }

    /// Starting corner frequency of the lag of [`Self::recommended`], as a fraction of
    /// the sampling rate 1/dt.
    pub const LAG_START_FRACTION: f64 = 0.3;

    /// As [`HorizonIdentifier::new`], with the base model behind an `input_lag` whose
    /// corner frequency is identified too (as ln fc, starting from the value given,
    /// held within [`HorizonConfig::fc_bounds_hz`]); the model is then the chain
    /// u → u_a → (kv·u_a + x0 + h) of [`crate::effects`]. Other effects are rejected.
    pub fn with_effects(dt: f64, init: Params, effects: &EffectSet, h0: f64, config: HorizonConfig) -> Result<Self> {
        positive_dt(dt)?;
        init.check_admissible()?;
        config.validate()?;
        finite_sample("h0", h0)?;
        effects.validate()?;
        if !effects.unsupported(&["input_lag"]).is_empty() {
            return Err(Error::InvalidConfig {
                name: "effects",
                value: effects.names().len() as f64,
                reason: "the horizon method identifies an input_lag only (the other effects are not supported)",
            });
        }
        let (lo, hi) = config.fc_bounds_hz;
        let ln_fc = effects.input_lag.map(|l| math::ln(l.fc_hz.clamp(lo, hi)));
        let lag = lag_of(ln_fc.map_or(hi, math::exp), dt);
        let mut buffer = Vec::new();
        buffer.resize(config.max_window, Entry::default());
        let mut travels = Vec::new();
        travels.resize(config.max_window, 0.0);
        Ok(HorizonIdentifier {
            config,
            dt,
            init,
            h0,
            params: init,
            ln_fc,
            ln_fc0: ln_fc,
            lag,
            h: h0,
            ua: 0.0,
            u_prev: None,
            buffer,
            travels,
            next: 0,
            start: 0,
            mid: 0,
            pass: Pass::new(0, init, h0, 0.0, 0.0, lag),
            finish_due: false,
            last_mse: f64::INFINITY,
            damping: config.damping,
            status: HorizonStatus { damping: config.damping, ..HorizonStatus::default() },
            mode: RefineMode::Sync,
            pass_end: 0,
            pending: None,
            fitted: 0,
        })
    }

    /// The same identifier with the window pass run as `mode` says (see the module
    /// docs); [`RefineMode::Sync`] is the default.
    pub fn with_mode(mut self, mode: RefineMode) -> Self {
        self.set_mode(mode);
        self
    }

    /// Switches where the window pass runs, at any sample: to cooperative, the pass in
    /// progress ends at the newest sample; to sync, an update not adopted yet is
    /// carried to the newest sample and adopted first.
    pub fn set_mode(&mut self, mode: RefineMode) {
        if mode == self.mode {
            return;
        }
        match mode {
            RefineMode::Cooperative => self.pass_end = self.next,
            RefineMode::Sync => {
                self.carry_pending(usize::MAX);
                self.finish_due = false;
            }
        }
        self.mode = mode;
    }

    /// Where the window pass runs.
    pub fn mode(&self) -> RefineMode {
        self.mode
    }

    /// The tuning in use.
    pub fn config(&self) -> &HorizonConfig {
        &self.config
    }

    /// The effects identified with the parameters, at their current estimates: the
    /// input lag when one was given, else none.
    pub fn effects(&self) -> EffectSet {
        EffectSet { input_lag: self.ln_fc.map(|l| InputLag { fc_hz: math::exp(l) }), ..EffectSet::none() }
    }

    /// The model's voltage on the stack u_a at the last sample \[V\] (the last u without
    /// the lag; 0 before the first sample).
    pub fn stack_voltage(&self) -> f64 {
        self.ua
    }

    fn slot(&self, k: u64) -> usize {
        (k % self.buffer.len() as u64) as usize
    }

    fn entry(&self, k: u64) -> &Entry {
        &self.buffer[self.slot(k)]
    }

    /// The input travel up to sample `k` \[V\].
    #[inline(always)]
    fn travel(&self, k: u64) -> f64 {
        self.travels[self.slot(k)]
    }

    /// The slot after `slot` in the ring buffer.
    #[inline(always)]
    fn following(&self, slot: usize) -> usize {
        if slot + 1 == self.buffer.len() {
            0
        } else {
            slot + 1
        }
    }

    /// The first index in `lo..hi` whose travel is above `limit` \[V\] (`hi` if none):
    /// the travel grows with the index, so a galloping search from `lo` (probes at lo,
    /// lo + 1, lo + 3, lo + 7, … until one is above, then a bisection between the last
    /// two): 1 or 2 probes, near samples already in cache, when the window's start moves
    /// by a sample or none, and at most 48 for the largest buffer when it jumps.
    ///
    /// Where `lo` lies before the oldest sample still stored (its slot holds a newer
    /// sample), the plain bisection of earlier releases runs, probe for probe, so that
    /// the predictions stay theirs bit for bit.
    fn first_travel_above(&self, mut lo: u64, mut hi: u64, limit: f64) -> u64 {
        let gallop = lo >= self.next.saturating_sub(self.buffer.len() as u64);
        let mut width = 1u64;
        while gallop && lo < hi {
            let probe = lo.saturating_add(width - 1).min(hi - 1);
            if self.travel(probe) > limit {
                hi = probe;
                break;
            }
            lo = probe + 1;
            width = width.saturating_mul(2);
        }
        while lo < hi {
            let m = lo + (hi - lo) / 2;
            if self.travel(m) > limit {
                hi = m;
            } else {
                lo = m + 1;
            }
        }
        lo
    }

    /// Moves the window's start (and the start of its newest half) after a sample with
    /// input travel `travel` \[V\] was stored: the start is the latest index that keeps
    /// at least `memory_travel_v` of travel after the one following it, the window at
    /// most `recent_factor` × the newest half's samples and at most the buffer. Found by
    /// a galloping search, so a push's cost grows with the logarithm of how far the
    /// start moves only (a switch to a faster input drops thousands of samples at once).
    fn move_window(&mut self, travel: f64) {
        let cfg = &self.config;
        let (next, cap) = (self.next, self.buffer.len() as u64);
        // mid: the largest index m (≥ start) with travel − travel(m) ≥ half, i.e. the
        // first index whose travel is above travel − half, less one.
        let half = 0.5 * cfg.memory_travel_v;
        let above = self.first_travel_above(self.mid.max(self.start), next, travel - half);
        self.mid = above.saturating_sub(1).max(self.mid).max(self.start);
        let least = HorizonConfig::MIN_WINDOW as u64;
        let mut start = self.start.max(next.saturating_sub(cap));
        if next - start > least {
            // Travel: the start s may move while travel − travel(s + 1) ≥ memory, i.e.
            // up to the first index whose travel is above travel − memory, less one.
            let by_travel = self.first_travel_above(start + 1, next, travel - cfg.memory_travel_v).saturating_sub(1);
            // Recent: next − s ≤ recent_factor × (next − mid).
            let recent = cfg.recent_factor * (next - self.mid) as f64;
            let by_recent = if recent.is_finite() { next.saturating_sub(math::floor(recent) as u64) } else { 0 };
            start = start.max(by_travel).max(by_recent).min(next - least);
        }
        self.start = start;
        self.mid = self.mid.max(self.start);
    }

    /// Cooperative mode: carries the pending update at most `intervals` samples
    /// towards the newest sample with the model's own integrator (as `push` predicts)
    /// and adopts it there (parameters, lag, h and u_a together). Returns the
    /// intervals run. When the samples it needs have left the buffer (no `refine`
    /// for longer than `max_window` samples), the parameters are adopted with the
    /// model's own h and u_a.
    fn carry_pending(&mut self, intervals: usize) -> usize {
        let Some(mut p) = self.pending else {
            return 0;
        };
        let cap = self.buffer.len() as u64;
        let newest = self.next - 1;
        let mut ran = 0;
        if p.at < self.next.saturating_sub(cap) {
            p.h = self.h;
            p.ua = self.ua;
            p.at = newest;
        }
        let lag = lag_of(p.ln_fc.map_or(self.config.fc_bounds_hz.1, math::exp), self.dt);
        while p.at < newest && ran < intervals {
            let (u0, u1) = (self.entry(p.at).u, self.entry(p.at + 1).u);
            let carried = p.ln_fc.map(|_| &lag);
            (p.h, p.ua) = loop_interval(&p.params, carried, self.dt, (p.h, p.ua), Some(u0), u1);
            p.at += 1;
            ran += 1;
        }
        if p.at < newest {
            self.pending = Some(p);
            return ran;
        }
        self.params = p.params;
        self.ln_fc = p.ln_fc;
        self.lag = lag;
        self.h = p.h;
        self.ua = p.ua;
        self.fitted = p.fitted;
        self.pending = None;
        self.status.updated = true;
        self.status.updates += 1;
        ran
    }

    /// Refreshes how far the estimates in use lag the newest sample.
    #[inline]
    fn update_lag_status(&mut self) {
        let behind = self.next.saturating_sub(self.fitted);
        self.status.behind_samples = behind;
        self.status.behind_s = behind as f64 * self.dt;
    }

    /// Cooperative mode: runs the window pass, at most `max_intervals` integration
    /// intervals (one sample of the pass on dual numbers, or one scalar interval of
    /// carrying an update to the newest sample), on the samples pushed so far. An
    /// update is adopted here, between two pushes: the next `push` predicts with it.
    /// Returns the intervals run (fewer than `max_intervals` when the pass has caught
    /// up: nothing left to do until more samples come). In sync mode the pass runs in
    /// `push` and this does nothing (returns 0).
    ///
    /// Cost: about the `samples_per_push`-th part of a sync push per interval
    /// (`cargo bench --bench latency` prints it), plus one Levenberg–Marquardt step
    /// (a 9 × 9 solve) per pass. Never allocates, never panics.
    pub fn refine(&mut self, max_intervals: usize) -> usize {
        if self.mode == RefineMode::Sync || self.next == 0 {
            return 0;
        }
        let mut left = max_intervals;
        loop {
            if self.pending.is_some() {
                left -= self.carry_pending(left);
                if self.pending.is_some() {
                    break;
                }
            }
            if left == 0 {
                break;
            }
            if self.pass_end <= self.start {
                // Every sample of the pass has left the window: start over on it.
                let e = *self.entry(self.start);
                self.pass = Pass::new(self.start, self.pass.params, e.h, e.ua, e.dua, self.pass.lag);
                self.pass_end = self.next;
            }
            if self.pass.cursor < self.pass_end {
                let from = self.pass.cursor;
                self.run_pass_to(self.pass_end, left);
                left -= (self.pass.cursor - from) as usize;
                if self.pass.cursor < self.pass_end {
                    break;
                }
            }
            // The pass has reached its end: it ends with an update when it spans enough
            // and holds a sample the last update did not see; else it waits for (and
            // runs on over) the newer samples.
            let end = self.pass_end;
            let cap = self.buffer.len() as u64;
            let spans = end > self.pass.start && {
                let span_travel = self.travel(end - 1) - self.travel(self.pass.start);
                span_travel >= self.config.min_pass_fraction * self.config.memory_travel_v
                    || end - self.pass.start >= cap / 2
            };
            if spans && end > self.fitted {
                self.finish_pass();
                left = left.saturating_sub(1);
            } else if end < self.next {
                self.pass_end = self.next;
            } else {
                break;
            }
        }
        self.update_lag_status();
        max_intervals - left
    }
}

impl OnlineIdentifier for HorizonIdentifier {
    type Status = HorizonStatus;

    fn push(&mut self, u: f64, x: f64) -> Result<f64> {
        finite_sample("u", u)?;
        finite_sample("x", x)?;
        // 1. Predict with the current estimates.
        let lag = self.ln_fc.map(|_| &self.lag);
        (self.h, self.ua) = loop_interval(&self.params, lag, self.dt, (self.h, self.ua), self.u_prev, u);
        let prediction = output(&self.params, self.ua, self.h);
        // 2. Store; move the window's start.
        let travel = match self.u_prev {
            Some(u0) if self.next > 0 => self.travel(self.next - 1) + (u - u0).abs(),
            _ => 0.0,
        };
        self.u_prev = Some(u);
        let k = self.next;
        let slot = self.slot(k);
        self.buffer[slot] = Entry { u, x, h: self.h, dh: [0.0; ND], ua: self.ua, dua: 0.0 };
        self.travels[slot] = travel;
        self.next += 1;
        self.move_window(travel);
        // 3. Run the pass on; end it on the push after it has caught up and spans enough.
        self.status.updated = false;
        let cap = self.buffer.len() as u64;
        if self.pass.start < self.next.saturating_sub(cap) {
            // The pass's start has left the buffer (a long hold filled it, or no
            // `refine` ran): restart.
            let e = *self.entry(self.start);
            self.pass = Pass::new(self.start, self.pass.params, e.h, e.ua, e.dua, self.pass.lag);
            self.finish_due = false;
            self.pass_end = self.next;
        }
        if self.mode != RefineMode::Sync {
            // The pass runs in `refine`.
        } else if self.finish_due {
            // The one sample stored since, then the update.
            self.run_pass(1);
            self.finish_due = false;
            self.finish_pass();
        } else {
            self.run_pass(self.config.samples_per_push);
            if self.pass.cursor >= self.next {
                let span_travel = travel - self.travel(self.pass.start);
                let span = self.next - self.pass.start;
                self.finish_due =
                    span_travel >= self.config.min_pass_fraction * self.config.memory_travel_v || span >= cap / 2;
            }
        }
        self.status.samples = self.next;
        self.status.window_samples = self.next - self.start;
        self.status.window_travel_v = travel - self.travel(self.start);
        self.update_lag_status();
        Ok(prediction)
    }

    fn params(&self) -> Params {
        self.params
    }

    fn forecast_into(&self, u: &[f64], out: &mut [f64]) -> Result<()> {
        super::check_forecast(u, out)?;
        let lag = self.ln_fc.map(|_| &self.lag);
        forecast_from(&self.params, lag, self.dt, (self.h, self.ua), self.u_prev, u, out);
        Ok(())
    }

    fn h(&self) -> f64 {
        self.h
    }

    fn input_lag(&self) -> Option<(InputLag, f64)> {
        self.ln_fc.map(|l| (InputLag { fc_hz: math::exp(l) }, self.ua))
    }

    fn status(&self) -> HorizonStatus {
        self.status
    }

    fn reset(&mut self) {
        let cfg = self.config;
        self.params = self.init;
        self.ln_fc = self.ln_fc0;
        self.lag = lag_of(self.ln_fc0.map_or(cfg.fc_bounds_hz.1, math::exp), self.dt);
        self.h = self.h0;
        self.ua = 0.0;
        self.u_prev = None;
        self.buffer.fill(Entry::default());
        self.travels.fill(0.0);
        self.next = 0;
        self.start = 0;
        self.mid = 0;
        self.pass = Pass::new(0, self.init, self.h0, 0.0, 0.0, self.lag);
        self.finish_due = false;
        self.last_mse = f64::INFINITY;
        self.damping = cfg.damping;
        self.status = HorizonStatus { damping: cfg.damping, ..HorizonStatus::default() };
        self.pass_end = 0;
        self.pending = None;
        self.fitted = 0;
    }
}

#[cfg(test)]
mod tests;
