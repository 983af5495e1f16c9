//! The background mode of the moving-horizon identifier (`std`): a worker thread owned
//! by the identifier runs the window pass; `push` predicts, stores and never waits.
//!
//! Two single-writer exchanges, both written with std atomics, no lock on the loop's side:
//! - **samples**, loop → worker: a ring of `max_window` slots, each (u, x) behind its
//!   own sequence number (a seqlock per slot). The worker reads the slots it has not
//!   read yet; a slot overwritten while it was reading fails its check and is skipped,
//!   as are the samples the loop wrote more than `max_window` ago: they lie before any
//!   window ending at the newest sample (the window holds at most `max_window`), so
//!   nothing the usual window rule keeps is lost.
//! - **estimates**, worker → loop: a seqlock over the worker's model state after its
//!   last update (parameters, ln fc, h and u_a at a sample index, with the status of
//!   the update). `push` reads it with one atomic load when nothing changed; a read
//!   that overlaps a write is discarded, not waited for. The loop adopts an update
//!   only where the worker's state is at the loop's own newest sample, so that
//!   parameters, lag, h and u_a switch together (no tear); the worker republishes at
//!   every sample it reads until the loop has adopted.
//!
//! The worker runs a [`HorizonIdentifier`] in [`RefineMode::Cooperative`] (the engine),
//! fed with the samples in the order pushed, refining in chunks of at most
//! [`BackgroundHorizon::CHUNK`] intervals; it sleeps briefly when it has nothing to do.
//!
//! **Cadence.** The worker runs at most [`BackgroundHorizon::INTERVALS_PER_SAMPLE`]
//! intervals per sample it reads, as the cooperative schedule `refine(32)` after every
//! push would (a budget not used while the pass waits for samples is not kept). A free
//! running worker would end a pass, and take a Levenberg–Marquardt step, as often as
//! the CPU allows: at 10 kHz on the simulated bench some ten times as many updates as
//! in sync mode, and the estimates then follow the window's noise (period-ahead error
//! at 10 Hz 0.49 → 0.67–0.71 µm, `boucwen reproduce --refine`). With the cadence the
//! worker does what the cooperative schedule does, later by the threads' timing.
//! When it cannot keep up, its passes end over the samples they started with and the
//! estimates still improve ([`HorizonStatus::behind_samples`] grows).
//!
//! Not deterministic: when an update is adopted depends on the threads' timing. For
//! reproducible runs use [`RefineMode::Sync`] or [`RefineMode::Cooperative`].

use std::sync::atomic::{fence, AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use super::*;
use crate::format::Snapshot;

/// One sample slot of the ring: u and x as bit patterns, behind a sequence number
/// (0 while written, else the absolute index of the sample + 1).
#[derive(Default)]
struct Slot {
    tag: AtomicU64,
    u: AtomicU64,
    x: AtomicU64,
}

/// Positions in the published estimates.
mod est {
    /// Absolute index of the next sample after the worker's state (the loop adopts
    /// when this equals its own sample count).
    pub const INDEX: usize = 0;
    pub const UPDATES: usize = 1;
    pub const FITTED: usize = 2;
    pub const PARAMS: usize = 3; // 7 values
    pub const LN_FC: usize = 10;
    pub const H: usize = 11;
    pub const UA: usize = 12;
    pub const RMS: usize = 13;
    pub const DAMPING: usize = 14;
    pub const FLAGS: usize = 15;
    pub const WINDOW_SAMPLES: usize = 16;
    pub const WINDOW_TRAVEL: usize = 17;
    pub const LEN: usize = 18;
}

/// What the worker publishes (see [`est`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Estimate {
    index: u64,
    updates: u64,
    fitted: u64,
    params: Params,
    ln_fc: Option<f64>,
    h: f64,
    ua: f64,
    rms_um: f64,
    damping: f64,
    step_limited: bool,
    projected: bool,
    held: bool,
    window_samples: u64,
    window_travel_v: f64,
}

struct Shared {
    ring: Box<[Slot]>,
    /// Samples written by the loop.
    head: AtomicU64,
    /// Updates the loop has adopted (the worker stops republishing once it has).
    adopted: AtomicU64,
    stop: AtomicBool,
    /// Intervals the worker may still run before it reads more samples (see the
    /// module docs, *Cadence*).
    credit: AtomicU64,
    /// The worker holds off (a starved worker, for tests and for callers that want the
    /// core back for a while).
    hold: AtomicBool,
    seq: AtomicU64,
    est: [AtomicU64; est::LEN],
    /// The worker's identifier and the absolute index of the next sample it reads.
    engine: Mutex<(HorizonIdentifier, u64)>,
}

impl Shared {
    fn engine(&self) -> MutexGuard<'_, (HorizonIdentifier, u64)> {
        // A panic in the worker (a bug) leaves the engine as it was at its last call.
        self.engine.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Writes the estimates (worker only: single writer).
    fn publish(&self, e: &Estimate) {
        let s = self.seq.load(Ordering::Relaxed);
        self.seq.store(s + 1, Ordering::Relaxed);
        fence(Ordering::Release);
        let p = e.params.to_array();
        let w = |i: usize, v: u64| self.est[i].store(v, Ordering::Relaxed);
        w(est::INDEX, e.index);
        w(est::UPDATES, e.updates);
        w(est::FITTED, e.fitted);
        for (i, v) in p.iter().enumerate() {
            w(est::PARAMS + i, v.to_bits());
        }
        w(est::LN_FC, e.ln_fc.unwrap_or(f64::NAN).to_bits());
        w(est::H, e.h.to_bits());
        w(est::UA, e.ua.to_bits());
        w(est::RMS, e.rms_um.to_bits());
        w(est::DAMPING, e.damping.to_bits());
        w(est::FLAGS, u64::from(e.step_limited) | u64::from(e.projected) << 1 | u64::from(e.held) << 2);
        w(est::WINDOW_SAMPLES, e.window_samples);
        w(est::WINDOW_TRAVEL, e.window_travel_v.to_bits());
        self.seq.store(s + 2, Ordering::Release);
    }

    /// Reads the estimates if they were not being written (never waits).
    fn read(&self, seq: u64) -> Option<Estimate> {
        if seq & 1 == 1 {
            return None;
        }
        let r = |i: usize| self.est[i].load(Ordering::Relaxed);
        let f = |i: usize| f64::from_bits(r(i));
        let mut p = [0.0; 7];
        for (i, v) in p.iter_mut().enumerate() {
            *v = f(est::PARAMS + i);
        }
        let ln_fc = f(est::LN_FC);
        let flags = r(est::FLAGS);
        let (window_samples, window_travel_v) = (r(est::WINDOW_SAMPLES), f(est::WINDOW_TRAVEL));
        let (index, updates, fitted, h, ua, rms_um, damping) =
            (r(est::INDEX), r(est::UPDATES), r(est::FITTED), f(est::H), f(est::UA), f(est::RMS), f(est::DAMPING));
        fence(Ordering::Acquire);
        if self.seq.load(Ordering::Relaxed) != seq {
            return None;
        }
        let params = Params::from_array(p).ok()?;
        Some(Estimate {
            index,
            updates,
            fitted,
            params,
            ln_fc: if ln_fc.is_nan() { None } else { Some(ln_fc) },
            h,
            ua,
            rms_um,
            damping,
            step_limited: flags & 1 == 1,
            projected: flags & 2 == 2,
            held: flags & 4 == 4,
            window_samples,
            window_travel_v,
        })
    }

    /// Reads sample `k` from the ring if it is still there, whole.
    fn sample(&self, k: u64) -> Option<(f64, f64)> {
        let slot = &self.ring[(k % self.ring.len() as u64) as usize];
        let tag = slot.tag.load(Ordering::Acquire);
        if tag != k + 1 {
            return None;
        }
        let (u, x) = (slot.u.load(Ordering::Relaxed), slot.x.load(Ordering::Relaxed));
        fence(Ordering::Acquire);
        if slot.tag.load(Ordering::Relaxed) != tag {
            return None;
        }
        Some((f64::from_bits(u), f64::from_bits(x)))
    }

    /// Feeds the engine every sample written since it last read (worker, or the loop's
    /// thread for a snapshot); returns how many it took.
    fn drain(&self, engine: &mut (HorizonIdentifier, u64)) -> u64 {
        let head = self.head.load(Ordering::Acquire);
        let cap = self.ring.len() as u64;
        let mut taken = 0;
        let mut k = engine.1.max(head.saturating_sub(cap));
        while k < head {
            if let Some((u, x)) = self.sample(k) {
                // Finite: the loop checked them before writing.
                if engine.0.push(u, x).is_ok() {
                    taken += 1;
                }
            }
            k += 1;
        }
        engine.1 = head;
        taken
    }
}

fn estimate_of(id: &HorizonIdentifier, index: u64) -> Estimate {
    let s = id.status;
    Estimate {
        index,
        updates: s.updates,
        fitted: index.saturating_sub(id.next.saturating_sub(id.fitted)),
        params: id.params,
        ln_fc: id.ln_fc,
        h: id.h,
        ua: id.ua,
        rms_um: s.rms_um,
        damping: s.damping,
        step_limited: s.step_limited,
        projected: s.projected,
        held: s.held,
        window_samples: s.window_samples,
        window_travel_v: s.window_travel_v,
    }
}

/// The worker's loop: read the new samples, refine a chunk, publish, until stopped.
fn work(shared: Arc<Shared>) {
    let mut published = 0u64;
    while !shared.stop.load(Ordering::Acquire) {
        if shared.hold.load(Ordering::Acquire) {
            std::thread::sleep(Duration::from_micros(200));
            continue;
        }
        let (taken, ran, waiting) = {
            let mut guard = shared.engine();
            let taken = shared.drain(&mut guard);
            let per_sample = BackgroundHorizon::INTERVALS_PER_SAMPLE as u64;
            let credit = shared.credit.load(Ordering::Relaxed).saturating_add(taken.saturating_mul(per_sample));
            let budget = credit.min(BackgroundHorizon::CHUNK as u64) as usize;
            let ran = if budget > 0 { guard.0.refine(budget) } else { 0 };
            // A budget the pass could not use (it waits for samples) is not kept.
            let left = if ran < budget { 0 } else { credit - ran as u64 };
            shared.credit.store(left, Ordering::Relaxed);
            let updates = guard.0.status.updates;
            let waiting = updates > shared.adopted.load(Ordering::Acquire);
            if waiting && (taken > 0 || updates > published) {
                shared.publish(&estimate_of(&guard.0, guard.1));
                published = updates;
            }
            (taken, ran, waiting)
        };
        if ran == 0 && taken == 0 {
            if waiting {
                // An update waits for the loop's next sample: stay close.
                std::thread::yield_now();
            } else {
                std::thread::sleep(Duration::from_micros(50));
            }
        }
    }
}

/// The moving-horizon identifier with its window pass on a worker thread it owns (see
/// the module docs of [`super`] and of this file): `push` predicts with the current
/// estimates, advances the model, hands the sample to the worker and adopts the
/// worker's newest update when it is at the same sample; it never waits, never
/// allocates. Not deterministic (the adoption depends on timing).
///
/// Dropping it stops and joins the worker. A snapshot ([`BackgroundHorizon::to_bytes`])
/// is that of a cooperative identifier with the samples the worker had not read yet
/// and an update not adopted yet included; [`BackgroundHorizon::from_bytes`] restores
/// any horizon snapshot with a new worker.
pub struct BackgroundHorizon {
    shared: Arc<Shared>,
    worker: Option<JoinHandle<()>>,
    // The loop's model.
    dt: f64,
    init: (Params, Option<f64>, f64),
    params: Params,
    ln_fc: Option<f64>,
    lag: LagStage,
    h: f64,
    ua: f64,
    u_prev: Option<f64>,
    next: u64,
    /// Samples the estimates in use were fitted on (as the worker counts them).
    fitted: u64,
    /// Sequence of the estimates last looked at.
    seen: u64,
    status: HorizonStatus,
    config: HorizonConfig,
}

impl core::fmt::Debug for BackgroundHorizon {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("BackgroundHorizon")
            .field("params", &self.params)
            .field("h", &self.h)
            .field("status", &self.status)
            .finish_non_exhaustive()
    }
}

impl BackgroundHorizon {
    /// Intervals the worker refines between two looks at the new samples (at most).
    pub const CHUNK: usize = 256;
    /// Intervals the worker runs per sample it reads, at most (see the module docs,
    /// *Cadence*): twice sync's `samples_per_push` default, the pass and the carrying
    /// of each update to the newest sample.
    pub const INTERVALS_PER_SAMPLE: usize = 32;

    /// Moves `id` (any mode; its state, window and pass included) into a worker thread
    /// and returns the loop's side. Errors if the thread cannot be started.
    pub fn spawn(mut id: HorizonIdentifier) -> Result<Self> {
        let cap = id.buffer.len();
        let mut ring = Vec::with_capacity(cap);
        ring.resize_with(cap, Slot::default);
        let (dt, init, config, status) = (id.dt, (id.init, id.ln_fc0, id.h0), id.config, id.status);
        let (params, ln_fc, lag, h, ua, u_prev, next) = (id.params, id.ln_fc, id.lag, id.h, id.ua, id.u_prev, id.next);
        // An update the identifier had not adopted yet is the engine's to carry on.
        id.set_mode(RefineMode::Cooperative);
        let fitted = id.fitted;
        let shared = Arc::new(Shared {
            ring: ring.into_boxed_slice(),
            head: AtomicU64::new(next),
            adopted: AtomicU64::new(status.updates),
            stop: AtomicBool::new(false),
            credit: AtomicU64::new(0),
            hold: AtomicBool::new(false),
            seq: AtomicU64::new(0),
            est: Default::default(),
            engine: Mutex::new((id, next)),
        });
        let for_worker = Arc::clone(&shared);
        let worker =
            std::thread::Builder::new().name("boucwen-horizon".into()).spawn(move || work(for_worker)).map_err(
                |_| Error::InvalidConfig { name: "refine", value: 0.0, reason: "the worker thread could not start" },
            )?;
        Ok(BackgroundHorizon {
            shared,
            worker: Some(worker),
            dt,
            init,
            params,
            ln_fc,
            lag,
            h,
            ua,
            u_prev,
            next,
            fitted,
            seen: 0,
            status,
            config,
        })
    }

    /// The recommended identifier ([`HorizonIdentifier::recommended`]) in background mode.
    pub fn recommended(dt: f64, init: Params, h0: f64, config: HorizonConfig) -> Result<Self> {
        Self::spawn(HorizonIdentifier::recommended(dt, init, h0, config)?)
    }

    /// The tuning in use.
    pub fn config(&self) -> &HorizonConfig {
        &self.config
    }

    /// The effects identified with the parameters, at their current estimates.
    pub fn effects(&self) -> EffectSet {
        EffectSet { input_lag: self.ln_fc.map(|l| InputLag { fc_hz: math::exp(l) }), ..EffectSet::none() }
    }

    /// Holds the worker off (`true`) or lets it run again (`false`): while held it
    /// reads no samples and runs no pass, as a worker starved of the CPU would; `push`
    /// goes on alike. The samples it has not read stay in the ring (those older than
    /// `max_window` samples are skipped when it runs again: they are out of the window).
    pub fn hold_worker(&self, hold: bool) {
        self.shared.hold.store(hold, Ordering::Release);
    }

    /// Waits (at most `timeout`) until the worker has read every sample pushed and has
    /// no pass work left that the samples and its cadence allow; true if it got there.
    /// For tests and shutdown paths, never for the loop.
    pub fn wait_idle(&self, timeout: Duration) -> bool {
        let t0 = std::time::Instant::now();
        loop {
            {
                let guard = self.shared.engine();
                let head = self.shared.head.load(Ordering::Acquire);
                let spent = self.shared.credit.load(Ordering::Relaxed) == 0;
                if guard.1 == head && (spent || guard.0.clone().refine(1) == 0) {
                    return true;
                }
            }
            if t0.elapsed() >= timeout {
                return false;
            }
            std::thread::sleep(Duration::from_micros(200));
        }
    }

    /// Adopts the worker's update if it is at this sample count (see the module docs).
    #[inline]
    fn adopt(&mut self) {
        let seq = self.shared.seq.load(Ordering::Acquire);
        if seq == self.seen {
            return;
        }
        let Some(e) = self.shared.read(seq) else {
            return;
        };
        if e.updates <= self.status.updates {
            self.seen = seq;
            return;
        }
        if e.index != self.next || e.ln_fc.is_some() != self.ln_fc.is_some() {
            return; // the worker republishes at the next sample it reads
        }
        self.seen = seq;
        self.params = e.params;
        if e.ln_fc != self.ln_fc {
            self.ln_fc = e.ln_fc;
            self.lag = lag_of(e.ln_fc.map_or(self.config.fc_bounds_hz.1, math::exp), self.dt);
        }
        self.h = e.h;
        self.ua = e.ua;
        self.fitted = e.fitted;
        self.status.updated = true;
        self.status.updates = e.updates;
        self.status.rms_um = e.rms_um;
        self.status.damping = e.damping;
        self.status.step_limited = e.step_limited;
        self.status.projected = e.projected;
        self.status.held = e.held;
        self.status.window_samples = e.window_samples;
        self.status.window_travel_v = e.window_travel_v;
        self.shared.adopted.store(e.updates, Ordering::Release);
    }

    /// A snapshot of the identifier as a cooperative one: the worker's identifier with
    /// the samples it has not read yet, the loop's model (estimates in use, h, u_a) and
    /// the worker's update the loop has not adopted yet as the pending update. Briefly
    /// waits for the worker's current chunk.
    pub fn to_bytes(&self) -> Vec<u8> {
        self.cooperative().to_bytes()
    }

    /// The state as a cooperative identifier (see [`BackgroundHorizon::to_bytes`]).
    pub fn cooperative(&self) -> HorizonIdentifier {
        let mut copy = {
            let guard = self.shared.engine();
            guard.clone()
        };
        self.shared.drain(&mut copy);
        let mut id = copy.0;
        if id.status.updates > self.status.updates && id.next > 0 {
            id.pending = Some(Pending {
                at: id.next - 1,
                params: id.params,
                ln_fc: id.ln_fc,
                h: id.h,
                ua: id.ua,
                fitted: id.fitted,
            });
        } else {
            id.pending = None;
        }
        let gap = self.next.saturating_sub(id.next);
        id.params = self.params;
        id.ln_fc = self.ln_fc;
        id.lag = self.lag;
        id.h = self.h;
        id.ua = self.ua;
        id.fitted = self.fitted.saturating_sub(gap).min(id.next);
        id.status.updates = self.status.updates;
        id.mode = RefineMode::Cooperative;
        id
    }

    /// Rebuilds from a horizon snapshot (any mode) and starts a worker.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        Self::spawn(HorizonIdentifier::from_bytes(bytes)?)
    }
}

impl Drop for BackgroundHorizon {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        if let Some(worker) = self.worker.take() {
            let _ = worker.join();
        }
    }
}

impl OnlineIdentifier for BackgroundHorizon {
    type Status = HorizonStatus;

    fn push(&mut self, u: f64, x: f64) -> Result<f64> {
        finite_sample("u", u)?;
        finite_sample("x", x)?;
        self.status.updated = false;
        self.adopt();
        // Predict with the current estimates, as `HorizonIdentifier::push` does.
        let lag = self.ln_fc.map(|_| &self.lag);
        (self.h, self.ua) = loop_interval(&self.params, lag, self.dt, (self.h, self.ua), self.u_prev, u);
        let prediction = output(&self.params, self.ua, self.h);
        self.u_prev = Some(u);
        // Hand the sample to the worker.
        let k = self.next;
        let slot = &self.shared.ring[(k % self.shared.ring.len() as u64) as usize];
        slot.tag.store(0, Ordering::Relaxed);
        fence(Ordering::Release);
        slot.u.store(u.to_bits(), Ordering::Relaxed);
        slot.x.store(x.to_bits(), Ordering::Relaxed);
        slot.tag.store(k + 1, Ordering::Release);
        self.next += 1;
        self.shared.head.store(self.next, Ordering::Release);
        self.status.samples = self.next;
        let behind = self.next.saturating_sub(self.fitted);
        self.status.behind_samples = behind;
        self.status.behind_s = behind as f64 * self.dt;
        Ok(prediction)
    }

    fn params(&self) -> Params {
        self.params
    }

    fn h(&self) -> f64 {
        self.h
    }

    fn input_lag(&self) -> Option<(InputLag, f64)> {
        self.ln_fc.map(|l| (InputLag { fc_hz: math::exp(l) }, self.ua))
    }

    /// The loop's status: the window fields are those of the worker's last update.
    fn status(&self) -> HorizonStatus {
        self.status
    }

    /// Back to the state right after construction (waits for the worker's chunk).
    fn reset(&mut self) {
        let mut guard = self.shared.engine();
        guard.0.reset();
        guard.1 = 0;
        for slot in self.shared.ring.iter() {
            slot.tag.store(0, Ordering::Relaxed);
        }
        self.shared.head.store(0, Ordering::Release);
        self.shared.adopted.store(0, Ordering::Release);
        self.shared.credit.store(0, Ordering::Relaxed);
        let (init, ln_fc0, h0) = self.init;
        self.params = init;
        self.ln_fc = ln_fc0;
        self.lag = lag_of(ln_fc0.map_or(self.config.fc_bounds_hz.1, math::exp), self.dt);
        self.h = h0;
        self.ua = 0.0;
        self.u_prev = None;
        self.next = 0;
        self.fitted = 0;
        self.seen = self.shared.seq.load(Ordering::Acquire);
        self.status = guard.0.status;
    }

    fn forecast_into(&self, u: &[f64], out: &mut [f64]) -> Result<()> {
        super::super::check_forecast(u, out)?;
        let lag = self.ln_fc.map(|_| &self.lag);
        forecast_from(&self.params, lag, self.dt, (self.h, self.ua), self.u_prev, u, out);
        Ok(())
    }
}
