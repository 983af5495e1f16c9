//! The C ABI (feature `ffi`): the per-sample [`Model`], the online identifier (one
//! handle, `BwIdentifier`, over [`AnyIdentifier`]: built by `bw_identifier_new_horizon`,
//! the recommended method, `_new_rpem` or `_new_paper`, then the same calls whatever the
//! method), the [`Inverse`] of the model, [`simulate`](crate::simulate) and the channel
//! [`Bank`], behind opaque handles. A call that belongs to one method (the horizon
//! method's `refine`) returns `BW_WRONG_METHOD` on an identifier of another. The header
//! `include/boucwen.h` is generated from this file by cbindgen (`cbindgen.toml`; the
//! test `rust/tests/ffi_header.rs` fails when it is stale).
//!
//! Conventions, for every function:
//! - the return value is a [`BwStatus`]: `BW_OK`, or the reason the call did nothing
//!   (the object is then exactly as before, as in Rust: a non-finite sample is
//!   rejected and the state kept);
//! - results are written through out-pointers, which must be valid (a null one gives
//!   `BW_NULL_POINTER`); arrays are `(pointer, length)` pairs of `double`, frames of a
//!   bank row-major (frame t, channel c at `t·C + c`);
//! - no Rust panic crosses the boundary: each call runs under `catch_unwind` and a
//!   panic (a bug; none is known) returns `BW_PANIC`, after which the object should
//!   be destroyed;
//! - `*_new*` and `*_restore` allocate the object, `*_free` releases it (null is
//!   ignored); `push`, `push_many`, `step` and the bank's frame calls allocate
//!   nothing; `*_snapshot` copies the bytes into the caller's buffer (with
//!   `BW_BUFFER_TOO_SMALL` and the needed length when it is too short, so a call with
//!   capacity 0 asks for the size).
//!
//! Units as in Rust: u \[V\], x and h \[µm\], dt \[s\].
//!
//! # Safety
//!
//! Every function takes raw pointers from C. A handle must come from the matching
//! `*_new*`/`*_restore` and not be used after `*_free`, nor from two threads at
//! once; an array pointer must point to at least as many `double`s as the length
//! given (it may be null when the length is 0).
#![allow(clippy::missing_safety_doc)]

use core::ffi::c_char;
use std::panic::{catch_unwind, AssertUnwindSafe};

use crate::bank::Bank;
use crate::compensate::{Clip, Inverse, InverseStatus, VoltageLimits};
use crate::effects::{EffectSet, InputLag};
use crate::error::Error;
use crate::format::Snapshot;
use crate::identify::{
    AnyIdentifier, AnyStatus, Decomposition, HorizonConfig, HorizonIdentifier, HorizonStatus, OnlineIdentifier,
    PaperConfig, PaperIdentifier, PaperStatus, Reason, RefineMode, RpemConfig, RpemIdentifier, RpemStatus, StepStatus,
    SubFit,
};
use crate::model::Model;
use crate::params::Params;

/// What a call did.
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BwStatus {
    /// Done.
    BW_OK = 0,
    /// A model parameter is out of its domain (non-finite, or n ≤ 0).
    BW_INVALID_PARAMETER = 1,
    /// A configuration value (dt, window, tuning, channel count or index) is invalid.
    BW_INVALID_CONFIG = 2,
    /// A sample is NaN or infinite: rejected, state kept.
    BW_NON_FINITE_SAMPLE = 3,
    /// A snapshot is truncated, foreign or corrupt.
    BW_CORRUPT_SNAPSHOT = 4,
    /// Lengths that must agree do not.
    BW_LENGTH_MISMATCH = 5,
    /// A required pointer is null.
    BW_NULL_POINTER = 6,
    /// The caller's buffer is too short (the needed length was written).
    BW_BUFFER_TOO_SMALL = 7,
    /// A Rust panic was caught (a bug): destroy the object.
    BW_PANIC = 8,
    /// The call belongs to another method than the identifier's (e.g. the horizon
    /// method's refine on an rpem identifier): nothing was done.
    BW_WRONG_METHOD = 9,
}

impl BwStatus {
    /// Every status, in code order.
    const ALL: [BwStatus; 10] = [
        BwStatus::BW_OK,
        BwStatus::BW_INVALID_PARAMETER,
        BwStatus::BW_INVALID_CONFIG,
        BwStatus::BW_NON_FINITE_SAMPLE,
        BwStatus::BW_CORRUPT_SNAPSHOT,
        BwStatus::BW_LENGTH_MISMATCH,
        BwStatus::BW_NULL_POINTER,
        BwStatus::BW_BUFFER_TOO_SMALL,
        BwStatus::BW_PANIC,
        BwStatus::BW_WRONG_METHOD,
    ];

    /// The status of integer code `code`, if it is one.
    fn from_code(code: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|s| *s as u32 == code)
    }
}

impl From<Error> for BwStatus {
    fn from(e: Error) -> Self {
        match e {
            Error::InvalidParameter { .. } => BwStatus::BW_INVALID_PARAMETER,
            Error::InvalidConfig { .. } => BwStatus::BW_INVALID_CONFIG,
            Error::NonFiniteSample { .. } => BwStatus::BW_NON_FINITE_SAMPLE,
            Error::CorruptSnapshot { .. } => BwStatus::BW_CORRUPT_SNAPSHOT,
            Error::LengthMismatch { .. } => BwStatus::BW_LENGTH_MISMATCH,
        }
    }
}

/// The seven parameters of eqs. (3) and (5): kv \[µm/V\], x0 \[µm\], A \[µm/V\], β and γ
/// [µm^(1−n)/V], n \[-\], δ \[µm/(V·s)\].
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BwParams {
    pub kv: f64,
    pub x0: f64,
    pub a: f64,
    pub beta: f64,
    pub gamma: f64,
    pub n: f64,
    pub delta: f64,
}

impl From<Params> for BwParams {
    fn from(p: Params) -> Self {
        BwParams { kv: p.kv, x0: p.x0, a: p.a, beta: p.beta, gamma: p.gamma, n: p.n, delta: p.delta }
    }
}

impl BwParams {
    fn to_params(self) -> Result<Params, BwStatus> {
        Params::new(self.kv, self.x0, self.a, self.beta, self.gamma, self.n, self.delta).map_err(BwStatus::from)
    }
}

/// Tuning of the rpem method (see `RpemConfig` in the Rust docs for each value's
/// meaning, units and default); fill it with `bw_rpem_config_default` first.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BwRpemConfig {
    pub forgetting: f64,
    pub memory_travel_v: f64,
    pub p0: f64,
    pub offset_walk_um: f64,
    pub p0_effects: f64,
    pub noise_um2: f64,
    pub max_trace: f64,
    pub max_step: f64,
    pub max_offset_step_um: f64,
    pub n_min: f64,
    pub n_max: f64,
    pub margin: f64,
    /// Scales of kv, x0, A, β, γ, n, δ (their units).
    pub scales: [f64; 7],
    pub creep_gain_scale_um_per_v: f64,
    pub creep_gain_max_um_per_v: f64,
    pub fc_min_hz: f64,
    pub fc_max_hz: f64,
}

impl From<RpemConfig> for BwRpemConfig {
    fn from(c: RpemConfig) -> Self {
        BwRpemConfig {
            forgetting: c.forgetting,
            memory_travel_v: c.memory_travel_v,
            p0: c.p0,
            offset_walk_um: c.offset_walk_um,
            p0_effects: c.p0_effects,
            noise_um2: c.noise_um2,
            max_trace: c.max_trace,
            max_step: c.max_step,
            max_offset_step_um: c.max_offset_step_um,
            n_min: c.n_bounds.0,
            n_max: c.n_bounds.1,
            margin: c.margin,
            scales: c.scales,
            creep_gain_scale_um_per_v: c.creep_gain_scale_um_per_v,
            creep_gain_max_um_per_v: c.creep_gain_max_um_per_v,
            fc_min_hz: c.fc_bounds_hz.0,
            fc_max_hz: c.fc_bounds_hz.1,
        }
    }
}

impl BwRpemConfig {
    // Options the tuning gains later keep their Rust defaults.
    #[allow(clippy::needless_update)]
    fn to_config(self) -> RpemConfig {
        RpemConfig {
            forgetting: self.forgetting,
            memory_travel_v: self.memory_travel_v,
            p0: self.p0,
            offset_walk_um: self.offset_walk_um,
            p0_effects: self.p0_effects,
            noise_um2: self.noise_um2,
            max_trace: self.max_trace,
            max_step: self.max_step,
            max_offset_step_um: self.max_offset_step_um,
            n_bounds: (self.n_min, self.n_max),
            margin: self.margin,
            scales: self.scales,
            creep_gain_scale_um_per_v: self.creep_gain_scale_um_per_v,
            creep_gain_max_um_per_v: self.creep_gain_max_um_per_v,
            fc_bounds_hz: (self.fc_min_hz, self.fc_max_hz),
            ..RpemConfig::default()
        }
    }
}

/// Tuning of the paper's method (see `PaperConfig` in the Rust docs); fill it with
/// `bw_paper_config_default` first. `decomposition`: 0 = model (default), 1 = line.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BwPaperConfig {
    pub window_len: usize,
    pub decomposition: u32,
    pub h_zero_frac: f64,
    pub rate_frac: f64,
    pub min_points: usize,
    pub rank_tol: f64,
    pub min_log_spread: f64,
    pub min_arg_frac: f64,
    pub noise_gate: f64,
    pub min_delta_t: f64,
    pub min_r2: f64,
    pub min_line_t: f64,
    pub min_u_std_v: f64,
    pub n_min: f64,
    pub n_max: f64,
    /// Phase span of the derivative stencil \[rad\].
    pub derivative_phase: f64,
    /// Largest derivative half-width \[samples\].
    pub max_half_width: usize,
}

impl From<PaperConfig> for BwPaperConfig {
    fn from(c: PaperConfig) -> Self {
        BwPaperConfig {
            window_len: c.window_len,
            decomposition: match c.decomposition {
                Decomposition::Model => 0,
                Decomposition::Line => 1,
            },
            h_zero_frac: c.h_zero_frac,
            rate_frac: c.rate_frac,
            min_points: c.min_points,
            rank_tol: c.rank_tol,
            min_log_spread: c.min_log_spread,
            min_arg_frac: c.min_arg_frac,
            noise_gate: c.noise_gate,
            min_delta_t: c.min_delta_t,
            min_r2: c.min_r2,
            min_line_t: c.min_line_t,
            min_u_std_v: c.min_u_std_v,
            n_min: c.n_bounds.0,
            n_max: c.n_bounds.1,
            derivative_phase: c.derivative_phase,
            max_half_width: c.max_half_width,
        }
    }
}

impl BwPaperConfig {
    #[allow(clippy::needless_update)]
    fn to_config(self) -> Result<PaperConfig, BwStatus> {
        let decomposition = match self.decomposition {
            0 => Decomposition::Model,
            1 => Decomposition::Line,
            _ => return Err(BwStatus::BW_INVALID_CONFIG),
        };
        Ok(PaperConfig {
            window_len: self.window_len,
            decomposition,
            h_zero_frac: self.h_zero_frac,
            rate_frac: self.rate_frac,
            min_points: self.min_points,
            rank_tol: self.rank_tol,
            min_log_spread: self.min_log_spread,
            min_arg_frac: self.min_arg_frac,
            noise_gate: self.noise_gate,
            min_delta_t: self.min_delta_t,
            min_r2: self.min_r2,
            min_line_t: self.min_line_t,
            min_u_std_v: self.min_u_std_v,
            n_bounds: (self.n_min, self.n_max),
            derivative_phase: self.derivative_phase,
            max_half_width: self.max_half_width,
            ..PaperConfig::with_window(self.window_len)
        })
    }
}

/// What the last push of an rpem identifier did (see `RpemStatus` in the Rust docs).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BwRpemStatus {
    pub samples: u64,
    pub updated: bool,
    pub step_limited: bool,
    pub projected: bool,
    pub trace_capped: bool,
    pub restarted: bool,
    /// x − x̂ of the sample \[µm\].
    pub innovation_um: f64,
    /// tr P (scaled units).
    pub trace: f64,
}

impl From<RpemStatus> for BwRpemStatus {
    fn from(s: RpemStatus) -> Self {
        BwRpemStatus {
            samples: s.samples,
            updated: s.updated,
            step_limited: s.step_limited,
            projected: s.projected,
            trace_capped: s.trace_capped,
            restarted: s.restarted,
            innovation_um: s.innovation_um,
            trace: s.trace,
        }
    }
}

/// Tuning of the horizon method (see `HorizonConfig` in the Rust docs for each value's
/// meaning, units and default); fill it with `bw_horizon_config_default` first.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BwHorizonConfig {
    pub memory_travel_v: f64,
    pub recent_factor: f64,
    pub max_window: usize,
    pub samples_per_push: usize,
    pub min_pass_fraction: f64,
    pub ridge: f64,
    pub damping: f64,
    pub max_step: f64,
    pub n_min: f64,
    pub n_max: f64,
    pub fc_min_hz: f64,
    pub fc_max_hz: f64,
    pub margin: f64,
    /// Scales of kv, x0, A, β, γ, n, δ (their units) and of the window's initial h \[µm\].
    pub scales: [f64; 8],
}

impl From<HorizonConfig> for BwHorizonConfig {
    fn from(c: HorizonConfig) -> Self {
        BwHorizonConfig {
            memory_travel_v: c.memory_travel_v,
            recent_factor: c.recent_factor,
            max_window: c.max_window,
            samples_per_push: c.samples_per_push,
            min_pass_fraction: c.min_pass_fraction,
            ridge: c.ridge,
            damping: c.damping,
            max_step: c.max_step,
            n_min: c.n_bounds.0,
            n_max: c.n_bounds.1,
            fc_min_hz: c.fc_bounds_hz.0,
            fc_max_hz: c.fc_bounds_hz.1,
            margin: c.margin,
            scales: c.scales,
        }
    }
}

impl BwHorizonConfig {
    fn to_config(self) -> HorizonConfig {
        HorizonConfig {
            memory_travel_v: self.memory_travel_v,
            recent_factor: self.recent_factor,
            max_window: self.max_window,
            samples_per_push: self.samples_per_push,
            min_pass_fraction: self.min_pass_fraction,
            ridge: self.ridge,
            damping: self.damping,
            max_step: self.max_step,
            n_bounds: (self.n_min, self.n_max),
            fc_bounds_hz: (self.fc_min_hz, self.fc_max_hz),
            margin: self.margin,
            scales: self.scales,
        }
    }
}

/// What the last push of a horizon identifier did (see `HorizonStatus` in the Rust docs).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BwHorizonStatus {
    pub samples: u64,
    pub updated: bool,
    pub updates: u64,
    pub window_samples: u64,
    /// Input travel over the window \[V\].
    pub window_travel_v: f64,
    /// RMS output error over the last pass \[µm\].
    pub rms_um: f64,
    pub damping: f64,
    pub step_limited: bool,
    pub projected: bool,
    /// The last update's step was held on the boundary of the well-posed region.
    pub held: bool,
    /// Samples pushed after the last one the estimates in use were fitted on.
    pub behind_samples: u64,
    /// The same in seconds \[s\].
    pub behind_s: f64,
}

impl From<HorizonStatus> for BwHorizonStatus {
    fn from(s: HorizonStatus) -> Self {
        BwHorizonStatus {
            samples: s.samples,
            updated: s.updated,
            updates: s.updates,
            window_samples: s.window_samples,
            window_travel_v: s.window_travel_v,
            rms_um: s.rms_um,
            damping: s.damping,
            step_limited: s.step_limited,
            projected: s.projected,
            held: s.held,
            behind_samples: s.behind_samples,
            behind_s: s.behind_s,
        }
    }
}

/// Where a horizon identifier's window pass runs (see `RefineMode` in the Rust docs).
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BwRefineMode {
    /// In every push (the default; the predictions of earlier releases bit for bit).
    BW_REFINE_SYNC = 0,
    /// In `bw_identifier_refine`, called when the loop has time; push only predicts and
    /// stores. Deterministic for a given schedule of calls.
    BW_REFINE_COOPERATIVE = 1,
}

/// What the last step of an inverse did: `clip` 0 = within the limits, 1 = on the
/// lower, 2 = on the upper limit.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BwInverseStatus {
    pub clip: u32,
    /// Integrator evaluations in the step (at most 40).
    pub evaluations: u32,
    /// Model displacement minus x_d after the step \[µm\].
    pub residual_um: f64,
    pub exact: bool,
    pub samples: u64,
    pub clipped_samples: u64,
}

impl From<InverseStatus> for BwInverseStatus {
    fn from(s: InverseStatus) -> Self {
        BwInverseStatus {
            clip: match s.clip {
                Clip::None => 0,
                Clip::Low => 1,
                Clip::High => 2,
            },
            evaluations: s.evaluations,
            residual_um: s.residual_um,
            exact: s.exact,
            samples: s.samples,
            clipped_samples: s.clipped_samples,
        }
    }
}

/// What one step of the paper's method did (see `StepStatus` in the Rust docs): `fit`
/// 0 = held, 1 = reduced, 2 = ran; `reason` 0 = none, 1 = window filling, 2 = no
/// excitation, 3 = too few points, 4 = no spread, 5 = noise, 6 = out of bounds, 7 =
/// upstream (step 5: steps 3 and 4 both held), 8 = worse output (the update would make
/// the window's output error worse than holding), 9 = misfit (the window fit: the model
/// does not explain the window to its noise); `points` the window points it had;
/// `noise` their residual scatter about its fit (in the step's units).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BwStepStatus {
    pub fit: u32,
    pub reason: u32,
    pub points: u32,
    pub noise: f64,
}

impl From<StepStatus> for BwStepStatus {
    fn from(s: StepStatus) -> Self {
        BwStepStatus {
            fit: match s.fit {
                SubFit::Held => 0,
                SubFit::Reduced => 1,
                SubFit::Ran => 2,
            },
            reason: Reason::ALL.iter().position(|&r| r == s.reason).unwrap_or(0) as u32,
            points: s.points,
            noise: s.noise,
        }
    }
}

/// What the last push of a paper identifier did (see `PaperStatus` in the Rust docs):
/// steps 1–5 in `line_fit`, `rate_fit`, `shape_fit`, `return_fit`, `split_fit`, and the
/// window fit's last run in `window_fit`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BwPaperStatus {
    pub samples: u64,
    pub window_full: bool,
    pub refreshed: bool,
    /// Half-width m of the derivative stencil \[samples\] (0: no point completed).
    pub half_width: u32,
    /// Noise of x over the window \[µm\].
    pub x_noise_um: f64,
    /// The noise it leaves on ẋ at half-width m \[µm/s\].
    pub xdot_noise_um_s: f64,
    pub line_fit: BwStepStatus,
    pub rate_fit: BwStepStatus,
    pub shape_fit: BwStepStatus,
    pub return_fit: BwStepStatus,
    pub split_fit: BwStepStatus,
    pub window_fit: BwStepStatus,
}

impl From<PaperStatus> for BwPaperStatus {
    fn from(s: PaperStatus) -> Self {
        BwPaperStatus {
            samples: s.samples,
            window_full: s.window_full,
            refreshed: s.refreshed,
            half_width: s.half_width,
            x_noise_um: s.x_noise_um,
            xdot_noise_um_s: s.xdot_noise_um_s,
            line_fit: s.line_fit.into(),
            rate_fit: s.rate_fit.into(),
            shape_fit: s.shape_fit.into(),
            return_fit: s.return_fit.into(),
            split_fit: s.split_fit.into(),
            window_fit: s.window_fit.into(),
        }
    }
}

/// The online method an identifier runs.
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BwMethod {
    /// The moving-horizon output-error method (the recommended one).
    BW_METHOD_HORIZON = 0,
    /// The recursive prediction-error method on the output error.
    BW_METHOD_RPEM = 1,
    /// The paper's limited-memory RLS with least-squares sub-fits.
    BW_METHOD_PAPER = 2,
}

impl BwMethod {
    fn of(id: &AnyIdentifier) -> Self {
        match id {
            AnyIdentifier::Horizon(_) => BwMethod::BW_METHOD_HORIZON,
            AnyIdentifier::Rpem(_) => BwMethod::BW_METHOD_RPEM,
            AnyIdentifier::Paper(_) => BwMethod::BW_METHOD_PAPER,
        }
    }
}

/// What the last push of an identifier did: `method` says which of `horizon`, `rpem`
/// and `paper` is filled (the other two are zero); `samples` is the samples pushed.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BwIdentifierStatus {
    pub method: BwMethod,
    pub samples: u64,
    pub horizon: BwHorizonStatus,
    pub rpem: BwRpemStatus,
    pub paper: BwPaperStatus,
}

impl From<AnyStatus> for BwIdentifierStatus {
    fn from(s: AnyStatus) -> Self {
        let zero = BwIdentifierStatus {
            method: BwMethod::BW_METHOD_HORIZON,
            samples: 0,
            horizon: BwHorizonStatus::default(),
            rpem: BwRpemStatus::default(),
            paper: BwPaperStatus::default(),
        };
        match s {
            AnyStatus::Horizon(h) => BwIdentifierStatus {
                method: BwMethod::BW_METHOD_HORIZON,
                samples: h.samples,
                horizon: h.into(),
                ..zero
            },
            AnyStatus::Rpem(r) => {
                BwIdentifierStatus { method: BwMethod::BW_METHOD_RPEM, samples: r.samples, rpem: r.into(), ..zero }
            }
            AnyStatus::Paper(p) => {
                BwIdentifierStatus { method: BwMethod::BW_METHOD_PAPER, samples: p.samples, paper: p.into(), ..zero }
            }
        }
    }
}

/// Opaque per-sample model.
pub struct BwModel(Model);
/// Opaque online identifier, of any method (horizon, rpem or paper).
pub struct BwIdentifier(AnyIdentifier);
/// Opaque inverse of the model (feedforward compensation).
pub struct BwInverse(Inverse);
/// Opaque bank of channels (identifier, model and inverse each).
pub struct BwBank(Bank<AnyIdentifier>);

/// Runs `f`, turning a panic into `BW_PANIC` and an `Err` into its code.
fn guard(f: impl FnOnce() -> Result<(), BwStatus>) -> BwStatus {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => BwStatus::BW_OK,
        Ok(Err(code)) => code,
        Err(_) => BwStatus::BW_PANIC,
    }
}

unsafe fn get<'a, T>(ptr: *const T) -> Result<&'a T, BwStatus> {
    ptr.as_ref().ok_or(BwStatus::BW_NULL_POINTER)
}

unsafe fn get_mut<'a, T>(ptr: *mut T) -> Result<&'a mut T, BwStatus> {
    ptr.as_mut().ok_or(BwStatus::BW_NULL_POINTER)
}

unsafe fn put<T>(out: *mut T, value: T) -> Result<(), BwStatus> {
    if out.is_null() {
        return Err(BwStatus::BW_NULL_POINTER);
    }
    out.write(value);
    Ok(())
}

unsafe fn slice<'a>(ptr: *const f64, len: usize) -> Result<&'a [f64], BwStatus> {
    if len == 0 {
        Ok(&[])
    } else if ptr.is_null() {
        Err(BwStatus::BW_NULL_POINTER)
    } else {
        Ok(core::slice::from_raw_parts(ptr, len))
    }
}

unsafe fn slice_mut<'a>(ptr: *mut f64, len: usize) -> Result<&'a mut [f64], BwStatus> {
    if len == 0 {
        Ok(&mut [])
    } else if ptr.is_null() {
        Err(BwStatus::BW_NULL_POINTER)
    } else {
        Ok(core::slice::from_raw_parts_mut(ptr, len))
    }
}

unsafe fn boxed<T>(out: *mut *mut T, value: T) -> Result<(), BwStatus> {
    if out.is_null() {
        return Err(BwStatus::BW_NULL_POINTER);
    }
    out.write(Box::into_raw(Box::new(value)));
    Ok(())
}

unsafe fn release<T>(ptr: *mut T) {
    if !ptr.is_null() {
        let _ = catch_unwind(AssertUnwindSafe(|| drop(Box::from_raw(ptr))));
    }
}

/// Copies a snapshot into the caller's buffer (`BW_BUFFER_TOO_SMALL` with `*len` the
/// needed length if `capacity` is short).
unsafe fn write_snapshot(bytes: &[u8], buf: *mut u8, capacity: usize, len: *mut usize) -> Result<(), BwStatus> {
    put(len, bytes.len())?;
    if capacity < bytes.len() {
        return Err(BwStatus::BW_BUFFER_TOO_SMALL);
    }
    if buf.is_null() {
        return Err(BwStatus::BW_NULL_POINTER);
    }
    core::ptr::copy_nonoverlapping(bytes.as_ptr(), buf, bytes.len());
    Ok(())
}

unsafe fn bytes<'a>(ptr: *const u8, len: usize) -> Result<&'a [u8], BwStatus> {
    if len == 0 {
        Ok(&[])
    } else if ptr.is_null() {
        Err(BwStatus::BW_NULL_POINTER)
    } else {
        Ok(core::slice::from_raw_parts(ptr, len))
    }
}

/// A static, NUL-terminated description of a status code.
///
/// Takes the code as an integer (a `BwStatus`, or any other value: "unknown status
/// code"), so that no value a C caller passes is undefined behaviour.
#[no_mangle]
pub extern "C" fn bw_status_message(status: u32) -> *const c_char {
    let Some(status) = BwStatus::from_code(status) else {
        return c"unknown status code".as_ptr();
    };
    let text: &'static [u8] = match status {
        BwStatus::BW_OK => b"ok\0",
        BwStatus::BW_INVALID_PARAMETER => b"invalid model parameter (non-finite, or n <= 0)\0",
        BwStatus::BW_INVALID_CONFIG => b"invalid configuration value\0",
        BwStatus::BW_NON_FINITE_SAMPLE => b"non-finite sample: rejected, state kept\0",
        BwStatus::BW_CORRUPT_SNAPSHOT => b"truncated, foreign or corrupt snapshot\0",
        BwStatus::BW_LENGTH_MISMATCH => b"array lengths do not agree\0",
        BwStatus::BW_NULL_POINTER => b"null pointer\0",
        BwStatus::BW_BUFFER_TOO_SMALL => b"buffer too small (needed length written)\0",
        BwStatus::BW_PANIC => b"internal error (panic caught); destroy the object\0",
        BwStatus::BW_WRONG_METHOD => b"the call belongs to another method than the identifier's\0",
    };
    text.as_ptr().cast()
}

/// The paper's Table 2 values at 1 Hz.
#[no_mangle]
pub unsafe extern "C" fn bw_params_paper_1hz(out: *mut BwParams) -> BwStatus {
    guard(|| put(out, Params::paper_1hz().into()))
}

// -- model ------------------------------------------------------------------------

/// A per-sample model (`dt` \[s\], initial h `h0` \[µm\]) into `*out`.
#[no_mangle]
pub unsafe extern "C" fn bw_model_new(params: *const BwParams, dt: f64, h0: f64, out: *mut *mut BwModel) -> BwStatus {
    guard(|| {
        let p = get(params)?.to_params()?;
        boxed(out, BwModel(Model::new(p, dt, h0)?))
    })
}

/// Releases a model (null is ignored).
#[no_mangle]
pub unsafe extern "C" fn bw_model_free(model: *mut BwModel) {
    release(model)
}

/// Takes the next voltage `u` \[V\]; writes the displacement \[µm\] to `*x`.
#[no_mangle]
pub unsafe extern "C" fn bw_model_step(model: *mut BwModel, u: f64, x: *mut f64) -> BwStatus {
    guard(|| {
        let m = get_mut(model)?;
        if x.is_null() {
            return Err(BwStatus::BW_NULL_POINTER);
        }
        put(x, m.0.step(u)?)
    })
}

/// The model's parameters.
#[no_mangle]
pub unsafe extern "C" fn bw_model_params(model: *const BwModel, out: *mut BwParams) -> BwStatus {
    guard(|| put(out, (*get(model)?.0.params()).into()))
}

/// Replaces the model's parameters (validated; the state is kept).
#[no_mangle]
pub unsafe extern "C" fn bw_model_set_params(model: *mut BwModel, params: *const BwParams) -> BwStatus {
    guard(|| {
        let p = get(params)?.to_params()?;
        Ok(get_mut(model)?.0.set_params(p)?)
    })
}

/// The hysteresis state h \[µm\].
#[no_mangle]
pub unsafe extern "C" fn bw_model_h(model: *const BwModel, h: *mut f64) -> BwStatus {
    guard(|| put(h, get(model)?.0.h()))
}

/// Forgets the past: h = `h0` \[µm\], no previous sample.
#[no_mangle]
pub unsafe extern "C" fn bw_model_reset(model: *mut BwModel, h0: f64) -> BwStatus {
    guard(|| Ok(get_mut(model)?.0.reset(h0)?))
}

/// The model's snapshot bytes into `buf` (capacity `capacity`), length to `*len`.
#[no_mangle]
pub unsafe extern "C" fn bw_model_snapshot(
    model: *const BwModel,
    buf: *mut u8,
    capacity: usize,
    len: *mut usize,
) -> BwStatus {
    guard(|| write_snapshot(&get(model)?.0.to_bytes(), buf, capacity, len))
}

/// A model rebuilt from snapshot bytes into `*out`.
#[no_mangle]
pub unsafe extern "C" fn bw_model_restore(buf: *const u8, len: usize, out: *mut *mut BwModel) -> BwStatus {
    guard(|| boxed(out, BwModel(Model::from_bytes(bytes(buf, len)?)?)))
}

/// Simulates `len` samples of `u` \[V\] into `x_out` \[µm\] from h = `h0`; the final h
/// \[µm\] to `*h_final` (may be null). The first sample keeps h = h0.
#[no_mangle]
pub unsafe extern "C" fn bw_simulate(
    params: *const BwParams,
    u: *const f64,
    len: usize,
    dt: f64,
    h0: f64,
    x_out: *mut f64,
    h_final: *mut f64,
) -> BwStatus {
    guard(|| {
        let p = get(params)?.to_params()?;
        let h = crate::model::simulate_into(&p, slice(u, len)?, dt, h0, None, slice_mut(x_out, len)?)?;
        if !h_final.is_null() {
            h_final.write(h);
        }
        Ok(())
    })
}

// -- identifier -------------------------------------------------------------------

/// The rpem method's defaults.
#[no_mangle]
pub unsafe extern "C" fn bw_rpem_config_default(out: *mut BwRpemConfig) -> BwStatus {
    guard(|| put(out, RpemConfig::default().into()))
}

/// The paper method's defaults for a window of `window_len` samples.
#[no_mangle]
pub unsafe extern "C" fn bw_paper_config_default(window_len: usize, out: *mut BwPaperConfig) -> BwStatus {
    guard(|| put(out, PaperConfig::with_window(window_len).into()))
}

/// The horizon method's defaults.
#[no_mangle]
pub unsafe extern "C" fn bw_horizon_config_default(out: *mut BwHorizonConfig) -> BwStatus {
    guard(|| put(out, HorizonConfig::default().into()))
}

/// A horizon identifier, the recommended method (`dt` \[s\], starting values `init`, h
/// `h0` \[µm\], tuning `config` or null for the defaults) into `*out`. `lag_fc_hz` > 0:
/// an input lag (amplifier bandwidth) is identified along, starting at that corner
/// frequency \[Hz\] (the recommended model starts at 0.3/dt, as `Identifier(dt, init)`
/// in Python); 0: the seven-parameter model alone. The window is allocated here, once.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_new_horizon(
    dt: f64,
    init: *const BwParams,
    h0: f64,
    lag_fc_hz: f64,
    config: *const BwHorizonConfig,
    out: *mut *mut BwIdentifier,
) -> BwStatus {
    guard(|| {
        let p = get(init)?.to_params()?;
        let cfg = if config.is_null() { HorizonConfig::default() } else { (*config).to_config() };
        let effects = if lag_fc_hz == 0.0 {
            EffectSet::none()
        } else {
            EffectSet { input_lag: Some(InputLag { fc_hz: lag_fc_hz }), ..EffectSet::none() }
        };
        let id = HorizonIdentifier::with_effects(dt, p, &effects, h0, cfg)?;
        boxed(out, BwIdentifier(AnyIdentifier::Horizon(id)))
    })
}

/// An rpem identifier (`dt` \[s\], starting values `init`, h `h0` \[µm\], tuning
/// `config` or null for the defaults) into `*out`.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_new_rpem(
    dt: f64,
    init: *const BwParams,
    h0: f64,
    config: *const BwRpemConfig,
    out: *mut *mut BwIdentifier,
) -> BwStatus {
    guard(|| {
        let p = get(init)?.to_params()?;
        let cfg = if config.is_null() { RpemConfig::default() } else { (*config).to_config() };
        boxed(out, BwIdentifier(AnyIdentifier::Rpem(RpemIdentifier::new(dt, p, h0, cfg)?)))
    })
}

/// A paper identifier (`dt` \[s\], `init`, `h0` \[µm\], tuning `config` with its
/// window, not null) into `*out`. The window is allocated here, once.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_new_paper(
    dt: f64,
    init: *const BwParams,
    h0: f64,
    config: *const BwPaperConfig,
    out: *mut *mut BwIdentifier,
) -> BwStatus {
    guard(|| {
        let p = get(init)?.to_params()?;
        let cfg = get(config)?.to_config()?;
        boxed(out, BwIdentifier(AnyIdentifier::Paper(PaperIdentifier::new(dt, p, h0, cfg)?)))
    })
}

/// An identifier rebuilt from snapshot bytes (`bw_identifier_snapshot`) into `*out`,
/// of the method the bytes record; it continues bit for bit.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_restore(buf: *const u8, len: usize, out: *mut *mut BwIdentifier) -> BwStatus {
    guard(|| boxed(out, BwIdentifier(AnyIdentifier::from_snapshot(bytes(buf, len)?)?)))
}

/// Releases an identifier (null is ignored).
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_free(id: *mut BwIdentifier) {
    release(id)
}

/// The identifier's method.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_method(id: *const BwIdentifier, out: *mut BwMethod) -> BwStatus {
    guard(|| put(out, BwMethod::of(&get(id)?.0)))
}

/// One sample (u \[V\], measured x \[µm\]); the prediction made before x is used \[µm\]
/// to `*x_hat`. No allocation.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_push(id: *mut BwIdentifier, u: f64, x: f64, x_hat: *mut f64) -> BwStatus {
    guard(|| {
        let id = get_mut(id)?;
        if x_hat.is_null() {
            return Err(BwStatus::BW_NULL_POINTER);
        }
        put(x_hat, id.0.push(u, x)?)
    })
}

/// `len` samples at once; predictions into `out`. Rejected whole (state kept) if any
/// value is non-finite.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_push_many(
    id: *mut BwIdentifier,
    u: *const f64,
    x: *const f64,
    len: usize,
    out: *mut f64,
) -> BwStatus {
    guard(|| Ok(get_mut(id)?.0.push_many(slice(u, len)?, slice(x, len)?, slice_mut(out, len)?)?))
}

/// The current estimates.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_params(id: *const BwIdentifier, out: *mut BwParams) -> BwStatus {
    guard(|| put(out, get(id)?.0.params().into()))
}

/// The identified input lag's corner frequency \[Hz\] (0 without a lag, and for paper).
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_lag_fc(id: *const BwIdentifier, fc_hz: *mut f64) -> BwStatus {
    guard(|| {
        let effects = match &get(id)?.0 {
            AnyIdentifier::Horizon(h) => h.effects(),
            AnyIdentifier::Rpem(r) => r.effects(),
            AnyIdentifier::Paper(_) => EffectSet::none(),
        };
        put(fc_hz, effects.input_lag.map_or(0.0, |l| l.fc_hz))
    })
}

/// What the last push did: `out->method` says which of `out->paper`, `out->rpem` and
/// `out->horizon` is filled (the others are zero).
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_status(id: *const BwIdentifier, out: *mut BwIdentifierStatus) -> BwStatus {
    guard(|| put(out, get(id)?.0.status().into()))
}

/// The model's h \[µm\] after the last sample.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_h(id: *const BwIdentifier, h: *mut f64) -> BwStatus {
    guard(|| put(h, get(id)?.0.h()))
}

/// The identified model (effects included) run open loop over the future voltages `u`
/// \[V\] from the last sample pushed, into `out` \[µm\]; the identifier does not change.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_forecast(
    id: *const BwIdentifier,
    u: *const f64,
    len: usize,
    out: *mut f64,
) -> BwStatus {
    guard(|| Ok(get(id)?.0.forecast_into(slice(u, len)?, slice_mut(out, len)?)?))
}

/// Back to the state right after construction.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_reset(id: *mut BwIdentifier) -> BwStatus {
    guard(|| {
        get_mut(id)?.0.reset();
        Ok(())
    })
}

/// The identifier's snapshot bytes (see `bw_model_snapshot`); `bw_identifier_restore`
/// rebuilds it.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_snapshot(
    id: *const BwIdentifier,
    buf: *mut u8,
    capacity: usize,
    len: *mut usize,
) -> BwStatus {
    guard(|| write_snapshot(&get(id)?.0.to_snapshot(), buf, capacity, len))
}

/// The horizon identifier behind `id`; `BW_WRONG_METHOD` for another method.
unsafe fn horizon<'a>(id: *mut BwIdentifier) -> Result<&'a mut HorizonIdentifier, BwStatus> {
    match &mut get_mut(id)?.0 {
        AnyIdentifier::Horizon(h) => Ok(h),
        _ => Err(BwStatus::BW_WRONG_METHOD),
    }
}

/// Horizon only (`BW_WRONG_METHOD` otherwise): switches where the window pass runs (at
/// any sample; see `HorizonIdentifier::set_mode` in the Rust docs). A new identifier
/// runs it in every push (`BW_REFINE_SYNC`). `mode` is a `BwRefineMode` value taken as
/// an integer: any other value is `BW_INVALID_CONFIG` (nothing changed), never
/// undefined behaviour.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_set_refine(id: *mut BwIdentifier, mode: u32) -> BwStatus {
    guard(|| {
        let mode = match mode {
            m if m == BwRefineMode::BW_REFINE_SYNC as u32 => RefineMode::Sync,
            m if m == BwRefineMode::BW_REFINE_COOPERATIVE as u32 => RefineMode::Cooperative,
            _ => return Err(BwStatus::BW_INVALID_CONFIG),
        };
        horizon(id)?.set_mode(mode);
        Ok(())
    })
}

/// Horizon only (`BW_WRONG_METHOD` otherwise), cooperative mode: runs the window pass
/// at most `max_intervals` integration intervals on the samples pushed so far and
/// writes the number run into `*ran` (0: nothing to do until more samples come; also
/// in sync mode). An update is adopted here; the next `bw_identifier_push` predicts
/// with it. Call it from the idle loop or a lower-priority task, never concurrently
/// with a push on the same handle. No allocation.
#[no_mangle]
pub unsafe extern "C" fn bw_identifier_refine(
    id: *mut BwIdentifier,
    max_intervals: usize,
    ran: *mut usize,
) -> BwStatus {
    guard(|| {
        let id = horizon(id)?;
        if ran.is_null() {
            return Err(BwStatus::BW_NULL_POINTER);
        }
        put(ran, id.refine(max_intervals))
    })
}

// -- inverse ----------------------------------------------------------------------

/// The inverse of the model with parameters `params`, `dt` \[s\], h `h0` \[µm\] and
/// voltage limits \[V\] (±INFINITY for none) into `*out`.
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_new(
    params: *const BwParams,
    dt: f64,
    h0: f64,
    u_min: f64,
    u_max: f64,
    out: *mut *mut BwInverse,
) -> BwStatus {
    guard(|| {
        let p = get(params)?.to_params()?;
        let limits = VoltageLimits::new(Some(u_min), Some(u_max))?;
        boxed(out, BwInverse(Inverse::new(p, dt, h0, limits)?))
    })
}

/// Releases an inverse (null is ignored).
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_free(inv: *mut BwInverse) {
    release(inv)
}

/// The voltage \[V\] to `*u` that makes the model reach the desired displacement `x_d`
/// \[µm\] at this sample. No allocation; at most 40 integrator evaluations.
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_step(inv: *mut BwInverse, x_d: f64, u: *mut f64) -> BwStatus {
    guard(|| {
        let inv = get_mut(inv)?;
        if u.is_null() {
            return Err(BwStatus::BW_NULL_POINTER);
        }
        put(u, inv.0.step(x_d)?)
    })
}

/// New parameters from now on (e.g. an identifier's current estimates); h is kept.
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_set_params(inv: *mut BwInverse, params: *const BwParams) -> BwStatus {
    guard(|| {
        let p = get(params)?.to_params()?;
        Ok(get_mut(inv)?.0.set_params(p)?)
    })
}

/// What the last step did.
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_status(inv: *const BwInverse, out: *mut BwInverseStatus) -> BwStatus {
    guard(|| put(out, get(inv)?.0.status().into()))
}

/// The model's h \[µm\] after the last step.
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_h(inv: *const BwInverse, h: *mut f64) -> BwStatus {
    guard(|| put(h, get(inv)?.0.h()))
}

/// Back to the state right after construction.
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_reset(inv: *mut BwInverse) -> BwStatus {
    guard(|| {
        get_mut(inv)?.0.reset();
        Ok(())
    })
}

// -- bank -------------------------------------------------------------------------

/// A bank of `channels` copies of the identifier `prototype` as it is now (usually
/// fresh from a `bw_identifier_new_*`; it stays the caller's), each channel then
/// learning on its own, with a model and an inverse starting from its parameters and
/// h; `dt` \[s\] the identifier's. Every method may be banked; a horizon channel holds
/// its own window (`max_window` samples of about 100 bytes).
#[no_mangle]
pub unsafe extern "C" fn bw_bank_new(
    channels: usize,
    dt: f64,
    prototype: *const BwIdentifier,
    out: *mut *mut BwBank,
) -> BwStatus {
    guard(|| {
        let id = get(prototype)?.0.clone();
        boxed(out, BwBank(Bank::new(channels, id, dt)?))
    })
}

/// Releases a bank (null is ignored).
#[no_mangle]
pub unsafe extern "C" fn bw_bank_free(bank: *mut BwBank) {
    release(bank)
}

/// The number of channels C.
#[no_mangle]
pub unsafe extern "C" fn bw_bank_channels(bank: *const BwBank, out: *mut usize) -> BwStatus {
    guard(|| put(out, get(bank)?.0.channels()))
}

/// One frame for the identifiers: `u` \[V\], `x` \[µm\] (C values each); predictions
/// \[µm\] into `out` (C values). No allocation.
#[no_mangle]
pub unsafe extern "C" fn bw_bank_push(bank: *mut BwBank, u: *const f64, x: *const f64, out: *mut f64) -> BwStatus {
    guard(|| {
        let b = &mut get_mut(bank)?.0;
        let c = b.channels();
        Ok(b.push(slice(u, c)?, slice(x, c)?, slice_mut(out, c)?)?)
    })
}

/// `frames` frames at once, row-major (frame t, channel c at `t·C + c`).
#[no_mangle]
pub unsafe extern "C" fn bw_bank_push_many(
    bank: *mut BwBank,
    u: *const f64,
    x: *const f64,
    frames: usize,
    out: *mut f64,
) -> BwStatus {
    guard(|| {
        let b = &mut get_mut(bank)?.0;
        let len = frames.checked_mul(b.channels()).ok_or(BwStatus::BW_LENGTH_MISMATCH)?;
        Ok(b.push_many(slice(u, len)?, slice(x, len)?, slice_mut(out, len)?)?)
    })
}

/// One frame for the models: voltages `u` \[V\] (C values), displacements \[µm\] into `x_out`.
#[no_mangle]
pub unsafe extern "C" fn bw_bank_step_models(bank: *mut BwBank, u: *const f64, x_out: *mut f64) -> BwStatus {
    guard(|| {
        let b = &mut get_mut(bank)?.0;
        let c = b.channels();
        Ok(b.step_models(slice(u, c)?, slice_mut(x_out, c)?)?)
    })
}

/// Every model takes its identifier's current estimates (states kept).
#[no_mangle]
pub unsafe extern "C" fn bw_bank_adopt_estimates(bank: *mut BwBank) -> BwStatus {
    guard(|| Ok(get_mut(bank)?.0.adopt_estimates()?))
}

/// One frame of feedforward: `x_d` (C desired displacements \[µm\]) in, the C voltages
/// \[V\] at which each channel's inverse model reaches them out. No allocation.
#[no_mangle]
pub unsafe extern "C" fn bw_bank_feedforward(bank: *mut BwBank, x_d: *const f64, u_out: *mut f64) -> BwStatus {
    guard(|| {
        let bank = &mut get_mut(bank)?.0;
        let c = bank.channels();
        Ok(bank.feedforward(slice(x_d, c)?, slice_mut(u_out, c)?)?)
    })
}

/// Voltage limits \[V\] of every channel's inverse (±INFINITY: none).
#[no_mangle]
pub unsafe extern "C" fn bw_bank_set_voltage_limits(bank: *mut BwBank, u_min: f64, u_max: f64) -> BwStatus {
    guard(|| Ok(get_mut(bank)?.0.set_voltage_limits(VoltageLimits::new(Some(u_min), Some(u_max))?)?))
}

/// The current estimates of channel `channel`'s identifier.
#[no_mangle]
pub unsafe extern "C" fn bw_bank_params(bank: *const BwBank, channel: usize, out: *mut BwParams) -> BwStatus {
    guard(|| {
        let id = get(bank)?.0.identifiers().get(channel).ok_or(BwStatus::BW_INVALID_CONFIG)?;
        put(out, id.params().into())
    })
}

/// Every identifier and model back to its state right after construction.
#[no_mangle]
pub unsafe extern "C" fn bw_bank_reset(bank: *mut BwBank) -> BwStatus {
    guard(|| {
        get_mut(bank)?.0.reset();
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_becomes_a_status() {
        let hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        let status = guard(|| panic!("deliberate"));
        std::panic::set_hook(hook);
        assert_eq!(status, BwStatus::BW_PANIC);
    }

    #[test]
    fn errors_leave_state_and_null_pointers_are_reported() {
        unsafe {
            let mut p = BwParams { kv: 0.0, x0: 0.0, a: 0.0, beta: 0.0, gamma: 0.0, n: 0.0, delta: 0.0 };
            assert_eq!(bw_params_paper_1hz(&mut p), BwStatus::BW_OK);
            let mut id: *mut BwIdentifier = core::ptr::null_mut();
            assert_eq!(bw_identifier_new_rpem(1e-4, &p, 0.0, core::ptr::null(), &mut id), BwStatus::BW_OK);
            let mut x_hat = 0.0;
            assert_eq!(bw_identifier_push(id, 1.0, 0.2, &mut x_hat), BwStatus::BW_OK);
            let before = (*id).0.clone();
            assert_eq!(bw_identifier_push(id, f64::NAN, 0.2, &mut x_hat), BwStatus::BW_NON_FINITE_SAMPLE);
            assert_eq!(bw_identifier_push(id, 1.0, 0.2, core::ptr::null_mut()), BwStatus::BW_NULL_POINTER);
            assert_eq!((*id).0, before);
            assert_eq!(bw_identifier_push(core::ptr::null_mut(), 1.0, 0.2, &mut x_hat), BwStatus::BW_NULL_POINTER);
            let mut len = 0usize;
            assert_eq!(bw_identifier_snapshot(id, core::ptr::null_mut(), 0, &mut len), BwStatus::BW_BUFFER_TOO_SMALL);
            let mut buf = vec![0u8; len];
            assert_eq!(bw_identifier_snapshot(id, buf.as_mut_ptr(), len, &mut len), BwStatus::BW_OK);
            let mut copy: *mut BwIdentifier = core::ptr::null_mut();
            assert_eq!(bw_identifier_restore(buf.as_ptr(), len, &mut copy), BwStatus::BW_OK);
            assert_eq!((*copy).0, (*id).0);
            assert_eq!(bw_identifier_restore(buf.as_ptr(), len - 1, &mut copy), BwStatus::BW_CORRUPT_SNAPSHOT);
            bw_identifier_free(copy);
            bw_identifier_free(id);
            bw_identifier_free(core::ptr::null_mut());
            let bad = BwParams { n: -1.0, ..p };
            let mut m: *mut BwModel = core::ptr::null_mut();
            assert_eq!(bw_model_new(&bad, 1e-4, 0.0, &mut m), BwStatus::BW_INVALID_PARAMETER);
            assert!(m.is_null());
            let mut rpem: *mut BwIdentifier = core::ptr::null_mut();
            assert_eq!(bw_identifier_new_rpem(1e-4, &p, 0.0, core::ptr::null(), &mut rpem), BwStatus::BW_OK);
            let mut bank: *mut BwBank = core::ptr::null_mut();
            assert_eq!(bw_bank_new(0, 1e-4, rpem, &mut bank), BwStatus::BW_INVALID_CONFIG);
            assert_eq!(bw_bank_new(2, 1e-4, core::ptr::null(), &mut bank), BwStatus::BW_NULL_POINTER);
            assert!(bank.is_null());
            bw_identifier_free(rpem);
            let msg = std::ffi::CStr::from_ptr(bw_status_message(BwStatus::BW_NON_FINITE_SAMPLE as u32));
            assert!(msg.to_str().unwrap().contains("non-finite"));
            let msg = std::ffi::CStr::from_ptr(bw_status_message(BwStatus::BW_WRONG_METHOD as u32));
            assert!(msg.to_str().unwrap().contains("another method"));
            // Any integer a C caller passes is answered, not undefined behaviour.
            let msg = std::ffi::CStr::from_ptr(bw_status_message(77));
            assert_eq!(msg.to_str().unwrap(), "unknown status code");
            for status in BwStatus::ALL {
                assert_eq!(BwStatus::from_code(status as u32), Some(status));
            }
        }
    }

    /// One identifier of each method, through the one handle.
    unsafe fn each_method(p: &BwParams) -> [*mut BwIdentifier; 3] {
        let mut ids = [core::ptr::null_mut(); 3];
        let mut cfg = core::mem::zeroed::<BwPaperConfig>();
        assert_eq!(bw_paper_config_default(200, &mut cfg), BwStatus::BW_OK);
        assert_eq!(bw_identifier_new_horizon(1e-4, p, 0.0, 3000.0, core::ptr::null(), &mut ids[0]), BwStatus::BW_OK);
        assert_eq!(bw_identifier_new_rpem(1e-4, p, 0.0, core::ptr::null(), &mut ids[1]), BwStatus::BW_OK);
        assert_eq!(bw_identifier_new_paper(1e-4, p, 0.0, &cfg, &mut ids[2]), BwStatus::BW_OK);
        ids
    }

    #[test]
    fn one_handle_serves_every_method_and_method_calls_refuse_the_others() {
        unsafe {
            let mut p = core::mem::zeroed::<BwParams>();
            assert_eq!(bw_params_paper_1hz(&mut p), BwStatus::BW_OK);
            let ids = each_method(&p);
            let methods = [BwMethod::BW_METHOD_HORIZON, BwMethod::BW_METHOD_RPEM, BwMethod::BW_METHOD_PAPER];
            let u: Vec<f64> = (0..600).map(|k| 40.0 * (1.0 - (k as f64 * 0.02).cos())).collect();
            let x: Vec<f64> = u.iter().map(|v| 0.2 * v).collect();
            for (&id, &method) in ids.iter().zip(&methods) {
                let mut got = BwMethod::BW_METHOD_PAPER;
                assert_eq!(bw_identifier_method(id, &mut got), BwStatus::BW_OK);
                assert_eq!(got, method);
                let mut out = vec![0.0; u.len()];
                assert_eq!(
                    bw_identifier_push_many(id, u.as_ptr(), x.as_ptr(), u.len(), out.as_mut_ptr()),
                    BwStatus::BW_OK
                );
                let mut status = core::mem::zeroed::<BwIdentifierStatus>();
                assert_eq!(bw_identifier_status(id, &mut status), BwStatus::BW_OK);
                assert_eq!((status.method, status.samples), (method, 600));
                let filled = [status.horizon.samples, status.rpem.samples, status.paper.samples];
                assert_eq!(filled.iter().filter(|&&n| n == 600).count(), 1);
                // A forecast does not change the identifier.
                let before = (*id).0.clone();
                let mut ahead = [0.0; 5];
                assert_eq!(bw_identifier_forecast(id, u.as_ptr(), 5, ahead.as_mut_ptr()), BwStatus::BW_OK);
                assert!(ahead.iter().all(|v| v.is_finite()));
                assert_eq!((*id).0, before);
                let mut fc = -1.0;
                assert_eq!(bw_identifier_lag_fc(id, &mut fc), BwStatus::BW_OK);
                assert_eq!(fc > 0.0, method == BwMethod::BW_METHOD_HORIZON);
                // A snapshot comes back as the same method, equal.
                let mut len = 0usize;
                assert_eq!(
                    bw_identifier_snapshot(id, core::ptr::null_mut(), 0, &mut len),
                    BwStatus::BW_BUFFER_TOO_SMALL
                );
                let mut buf = vec![0u8; len];
                assert_eq!(bw_identifier_snapshot(id, buf.as_mut_ptr(), len, &mut len), BwStatus::BW_OK);
                let mut copy: *mut BwIdentifier = core::ptr::null_mut();
                assert_eq!(bw_identifier_restore(buf.as_ptr(), len, &mut copy), BwStatus::BW_OK);
                assert_eq!((*copy).0.to_snapshot(), buf);
                let mut next = [0.0; 2];
                let mut twin = (*id).0.clone();
                assert_eq!(bw_identifier_push(copy, u[3], x[3], &mut next[0]), BwStatus::BW_OK);
                next[1] = twin.push(u[3], x[3]).expect("finite");
                assert_eq!(next[0].to_bits(), next[1].to_bits());
                bw_identifier_free(copy);
                // The horizon method's own calls.
                let mut ran = 7usize;
                let refine = bw_identifier_refine(id, 16, &mut ran);
                if method == BwMethod::BW_METHOD_HORIZON {
                    // A value outside BwRefineMode is refused, the mode kept.
                    assert_eq!(bw_identifier_set_refine(id, 2), BwStatus::BW_INVALID_CONFIG);
                }
                let set = bw_identifier_set_refine(id, BwRefineMode::BW_REFINE_COOPERATIVE as u32);
                if method == BwMethod::BW_METHOD_HORIZON {
                    assert_eq!((refine, set, ran), (BwStatus::BW_OK, BwStatus::BW_OK, 0));
                    let mut y = 0.0;
                    assert_eq!(bw_identifier_push(id, u[10], x[10], &mut y), BwStatus::BW_OK);
                    assert_eq!(bw_identifier_refine(id, 16, &mut ran), BwStatus::BW_OK);
                    assert!(ran > 0);
                } else {
                    assert_eq!((refine, set, ran), (BwStatus::BW_WRONG_METHOD, BwStatus::BW_WRONG_METHOD, 7));
                    assert_eq!((*id).0, before);
                }
                assert_eq!(bw_identifier_reset(id), BwStatus::BW_OK);
                assert_eq!(bw_identifier_status(id, &mut status), BwStatus::BW_OK);
                assert_eq!(status.samples, 0);
                bw_identifier_free(id);
            }
        }
    }

    #[test]
    fn a_bank_of_any_method_equals_its_single_identifier() {
        unsafe {
            let mut p = core::mem::zeroed::<BwParams>();
            assert_eq!(bw_params_paper_1hz(&mut p), BwStatus::BW_OK);
            for id in each_method(&p) {
                let mut bank: *mut BwBank = core::ptr::null_mut();
                assert_eq!(bw_bank_new(2, 1e-4, id, &mut bank), BwStatus::BW_OK);
                for k in 0..300 {
                    let u = 30.0 * (1.0 - (k as f64 * 0.03).cos());
                    let (mut single, mut frame) = (0.0, [0.0; 2]);
                    assert_eq!(bw_identifier_push(id, u, 0.2 * u, &mut single), BwStatus::BW_OK);
                    let (uf, xf) = ([u, u], [0.2 * u, 0.2 * u]);
                    assert_eq!(bw_bank_push(bank, uf.as_ptr(), xf.as_ptr(), frame.as_mut_ptr()), BwStatus::BW_OK);
                    assert_eq!(frame.map(f64::to_bits), [single.to_bits(); 2]);
                }
                let (mut a, mut b) = (core::mem::zeroed::<BwParams>(), core::mem::zeroed::<BwParams>());
                assert_eq!(bw_bank_params(bank, 1, &mut a), BwStatus::BW_OK);
                assert_eq!(bw_identifier_params(id, &mut b), BwStatus::BW_OK);
                assert_eq!(a, b);
                bw_bank_free(bank);
                bw_identifier_free(id);
            }
        }
    }
}
