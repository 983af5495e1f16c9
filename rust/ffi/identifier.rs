//! The online identifier: one handle, `BwIdentifier`, over every method (horizon, rpem,
//! paper), each method's tuning and what its last push did.

use super::model::BwParams;
use super::status::{boxed, bytes, get, get_mut, guard, put, release, slice, slice_mut, write_snapshot, BwStatus};
use crate::effects::{EffectSet, InputLag};
use crate::identify::{
    AnyIdentifier, AnyStatus, Decomposition, HorizonConfig, HorizonIdentifier, HorizonStatus, OnlineIdentifier,
    PaperConfig, PaperIdentifier, PaperStatus, Reason, RefineMode, RpemConfig, RpemIdentifier, RpemStatus, StepStatus,
    SubFit,
};

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

/// Opaque online identifier, of any method (horizon, rpem or paper).
pub struct BwIdentifier(pub(super) AnyIdentifier);

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
