//! Output-error online identification: a recursive prediction-error method (RPEM).
//!
//! Names follow the paper (A, β, γ, n, δ are the model's, eqs. 3 and 5). The
//! method minimises the *output* (simulation) error of the model, not an
//! equation error built from finite differences of measured signals:
//!
//! ```text
//! x̂ₖ = kv·uₖ + x0 + hₖ,   hₖ = Φ(hₖ₋₁, uₖ₋₁ → uₖ; θ)      (model.rs's integrator)
//! ψₖ = ∂x̂ₖ/∂θ = [uₖ, 1, 0, 0, 0, 0, 0] + ∂hₖ/∂θ            (sensitivities)
//! ```
//!
//! Per sample k:
//! 1. **Predict.** h is advanced by the model itself ([`crate::model::advance_h`]),
//!    so the prediction is exactly the model's. Its sensitivities ∂h/∂θ to all
//!    seven parameters are carried alongside through the same scheme, RK4 on
//!    sub-steps (the sub-step rule of model.rs: more sub-steps where h may cross
//!    zero or the interval is stiff, backward Euler on the stiffest (see [`TRIAL_ABOVE_SUBSTEPS`](crate::model::TRIAL_ABOVE_SUBSTEPS)), h held
//!    within ±[`H_LIMIT_UM`](crate::model::H_LIMIT_UM)), differentiated stage by stage (forward mode), each
//!    interval starting from the model's h. x̂ₖ uses the estimates from before the
//!    sample.
//! 2. **Gauss–Newton / Kalman step** in scaled coordinates φ = θ / `scales` (so
//!    that kv ≈ 0.2, δ ≈ 0.007 and n ≈ 1.5 all count alike):
//!    ```text
//!    e = xₖ − x̂ₖ,  ψ̃ = ψ ∘ scales,  s = R + ψ̃ᵀPψ̃,  K = Pψ̃ / s,  Δφ = K·e
//!    trust region: |Δφᵢ| ≤ max_step for all i but x0 (Δφ scaled down as a whole),
//!                  |Δx0| ≤ max_offset_step_um
//!    P ← (P − K ψ̃ᵀP) / λₖ,   λₖ = forgetting · exp(−|uₖ − uₖ₋₁| / memory_travel_v)
//!    P\[x0,x0\] += (offset_walk_um / scale_x0)²                 (x0 is a random walk)
//!    P ← P · min(1, max_trace / tr P)                         (bounded covariance)
//!    ```
//!    R = `noise_um2` \[µm²\] is the variance the prediction error is expected to
//!    have; P is the covariance of φ (dimensionless: P = 0.01 means a standard
//!    deviation of 10 % of the parameter's scale). Forgetting is counted in
//!    volts of input travel, not in samples: the memory spans the same number of
//!    periods at 1 Hz and at 200 Hz, and nothing is forgotten while u holds.
//!    The offset x0 is modelled as a random walk: it absorbs slow disturbances the
//!    model does not describe (creep, drift) within a few samples.
//! 3. **Projection** onto the region where the model is well posed: n within
//!    `n_bounds` (n ≥ 1: ∂ḣ/∂h is singular at h = 0 for n < 1), β + γ ≥ `margin`
//!    and β − γ ≥ `margin` (h stays bounded for every input, as with the paper's
//!    Table 2); the projection onto each half-plane is the orthogonal one in (β, γ).
//!    The starting values are projected too.
//!
//! Robustness by construction:
//! - *No wind-up*: under constant input λₖ = `forgetting` (1 by default), so P
//!   does not grow, except the x0 entry, which stays bounded because x0 is always
//!   observed; and whatever the tuning, tr P ≤ `max_trace`.
//! - *No divergence*: per-sample steps are capped, the projection keeps the
//!   hysteresis operator dissipative (∂ḣ/∂h ≤ 0, so h and the sensitivities stay
//!   bounded), h is held within ±[`H_LIMIT_UM`](crate::model::H_LIMIT_UM).
//! - *No NaN*: a non-finite sample is rejected before anything changes; a step,
//!   covariance or sensitivity that comes out non-finite is dropped (estimates held,
//!   P and the sensitivities restarted).
//! - O(1) and allocation-free per sample: only fixed-size nalgebra types
//!   ([`Covariance`] is a 12 × 12 `SMatrix`, of which the base model uses 7 × 7).
//!
//! Effects ([`RpemIdentifier::with_effects`]): θ is extended by ln fc of an
//! `input_lag` and the gains of up to [`MAX_CREEP`] `creep` elements, the chain
//! u → u_a → (h, creep) → x of [`crate::effects`] is propagated with its
//! sensitivities (∂u_a/∂ln fc through the exact first-order step, ∂h/∂θ through
//! u_a at both ends of each interval, creep kept at unit gain so that cᵢ = gᵢ·sᵢ).
//! The step is taken in ln fc and in each gain's logistic coordinate
//! η = ln(g/(gmax − g)), so the gains stay within (0, gmax) without clipping
//! against the covariance; the effects start from the values given (an offline
//! extended fit) with the relative prior `p0_effects`, and with creep the offset
//! does not walk ([`RpemConfig::for_effects`]).
//!
//! Cost: without effects the update runs on the 7 base slots only (7 × 7
//! covariance, sensitivities over 7 parameters), with the same results as the
//! full 12-slot computation; the effect slots are used only when declared.

mod chain;
mod config;
mod snapshot;
#[cfg(test)]
mod tests;

pub use chain::advance_h_with_gradient;
use chain::{Chain, Estimates, Shape};
pub use config::{RpemConfig, RpemStatus};

use nalgebra::{SMatrix, SVector};

use super::OnlineIdentifier;
use crate::effects::{first_order_coefficient, Creep, EffectSet, InputLag};
use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::math;
use crate::params::Params;

/// Number of base parameters (kv, x0, A, β, γ, n, δ).
pub const NUM_BASE: usize = 7;
/// Most creep elements identified online.
pub const MAX_CREEP: usize = 4;
/// Length of θ = (kv, x0, A, β, γ, n, δ, ln fc, g₁ … g₄): the base parameters in
/// the order of [`Params::to_array`], the input lag's corner frequency (as ln fc,
/// fc in Hz) and the creep gains \[µm/V\]. The slots of absent effects stay unused.
pub const NUM_PARAMS: usize = NUM_BASE + 1 + MAX_CREEP;

/// Parameter vector θ (see [`NUM_PARAMS`]).
pub type ParamVector = SVector<f64, NUM_PARAMS>;
/// Covariance of the scaled parameters.
pub type Covariance = SMatrix<f64, NUM_PARAMS, NUM_PARAMS>;

// Positions of the Bouc–Wen parameters in θ.
const I_KV: usize = 0;
const I_X0: usize = 1;
const I_A: usize = 2;
const I_BETA: usize = 3;
const I_GAMMA: usize = 4;
const I_N: usize = 5;
const I_DELTA: usize = 6;
const I_LN_FC: usize = 7;
const I_CREEP: usize = 8;

/// The output-error online identifier (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct RpemIdentifier {
    config: RpemConfig,
    dt: f64,
    init: Estimates,
    h0: f64,
    est: Estimates,
    shape: Shape,
    scales: ParamVector,
    /// 1 for identified parameters, 0 for the slots of absent effects.
    active: ParamVector,
    chain: Chain,
    u_prev: Option<f64>,
    /// Covariance of the scaled parameters θ/scales (dimensionless).
    p: Covariance,
    status: RpemStatus,
}

impl RpemIdentifier {
    /// An identifier of the base model for samples every `dt` \[s\], starting from
    /// `init` with model state `h0` \[µm\]. `init` must lie in the admissible region
    /// ([`Params::check_admissible`]; refused otherwise) and is projected onto the
    /// region the updates keep to (n within `n_bounds`, β ± γ ≥ `margin`).
    pub fn new(dt: f64, init: Params, h0: f64, config: RpemConfig) -> Result<Self> {
        Self::with_effects(dt, init, &EffectSet::none(), h0, config)
    }

    /// As [`RpemIdentifier::new`], with the base model extended by `effects`,
    /// whose parameters are identified too: `input_lag` (fc, starting from the value
    /// given) and `creep` (the gains gᵢ, starting from the values given; the time
    /// constants τᵢ stay fixed; at most [`MAX_CREEP`] elements). Other effects are
    /// not identified online and are rejected.
    ///
    /// The lag is identified as ln fc and each creep gain through its logistic
    /// coordinate (see `update`), with the relative prior `p0_effects`. Use
    /// [`RpemConfig::for_effects`] for the configuration: with creep the
    /// offset must not walk, or it takes the slow errors the gains should explain.
    /// A creep gain given below 5 % of `creep_gain_scale_um_per_v` starts there.
    pub fn with_effects(dt: f64, init: Params, effects: &EffectSet, h0: f64, config: RpemConfig) -> Result<Self> {
        positive_dt(dt)?;
        init.check_admissible()?;
        config.validate()?;
        effects.validate()?;
        finite_sample("h0", h0)?;
        if !effects.unsupported(&["input_lag", "creep"]).is_empty() {
            return Err(Error::InvalidConfig {
                name: "effects",
                value: f64::NAN,
                reason: "the rpem method identifies input_lag and creep only (the other effects are not supported)",
            });
        }
        let mut shape = Shape { lag: false, n_creep: 0, creep_tau: [1.0; MAX_CREEP], creep_decay: [0.0; MAX_CREEP] };
        let mut est = Estimates { params: project_params(init, &config), fc_hz: 1.0, creep_gain: [0.0; MAX_CREEP] };
        let mut active = ParamVector::from_element(0.0);
        let mut scales = ParamVector::from_element(1.0);
        for i in 0..NUM_BASE {
            active[i] = 1.0;
            scales[i] = config.scales[i];
        }
        if let Some(lag) = effects.input_lag {
            shape.lag = true;
            est.fc_hz = lag.fc_hz.clamp(config.fc_bounds_hz.0, config.fc_bounds_hz.1);
            active[I_LN_FC] = 1.0;
        }
        if let Some(creep) = &effects.creep {
            if creep.tau_s.len() > MAX_CREEP {
                return Err(Error::InvalidConfig {
                    name: "creep.tau_s",
                    value: creep.tau_s.len() as f64,
                    reason: "the rpem method identifies at most 4 creep elements",
                });
            }
            shape.n_creep = creep.tau_s.len();
            for (i, (&tau, &g)) in creep.tau_s.iter().zip(&creep.gain_um_per_v).enumerate() {
                shape.creep_tau[i] = tau;
                shape.creep_decay[i] = first_order_coefficient(tau, dt);
                // The logistic coordinate cannot reach 0 or gmax: a gain given below
                // `START_GAIN_FRACTION`·scale starts there, one near gmax just below it.
                let lowest =
                    (START_GAIN_FRACTION * config.creep_gain_scale_um_per_v).min(0.5 * config.creep_gain_max_um_per_v);
                est.creep_gain[i] = g.clamp(lowest, (1.0 - START_GAIN_FRACTION) * config.creep_gain_max_um_per_v);
                active[I_CREEP + i] = 1.0;
                scales[I_CREEP + i] = config.creep_gain_scale_um_per_v;
            }
        }
        Ok(RpemIdentifier {
            config,
            dt,
            init: est,
            h0,
            est,
            shape,
            scales,
            active,
            chain: Chain::new(h0),
            u_prev: None,
            p: initial_covariance(&active, &config),
            status: RpemStatus::default(),
        })
    }

    /// The tuning in use.
    pub fn config(&self) -> &RpemConfig {
        &self.config
    }

    /// Covariance P of the scaled parameters θᵢ/scaleᵢ (dimensionless), θ =
    /// (kv, x0, A, β, γ, n, δ, ln fc, g₁ … g₄); the rows of absent effects are zero.
    pub fn covariance(&self) -> &Covariance {
        &self.p
    }

    /// ∂h/∂θ after the last sample [µm per unit of each parameter], θ as in
    /// [`RpemIdentifier::covariance`].
    pub fn sensitivities(&self) -> [f64; NUM_PARAMS] {
        self.chain.dh.into()
    }

    /// The effects in the model with their current estimates (allocates; not for
    /// the per-sample path).
    pub fn effects(&self) -> EffectSet {
        let mut e = EffectSet::none();
        if self.shape.lag {
            e.input_lag = Some(InputLag { fc_hz: self.est.fc_hz });
        }
        if self.shape.n_creep > 0 {
            let n = self.shape.n_creep;
            e.creep = Some(Creep {
                tau_s: self.shape.creep_tau[..n].to_vec(),
                gain_um_per_v: self.est.creep_gain[..n].to_vec(),
            });
        }
        e
    }
}

/// Creep gains start from at least this fraction of `creep_gain_scale_um_per_v`.
const START_GAIN_FRACTION: f64 = 0.05;

/// P₀: `p0` on the base parameters, `p0_effects` on the effects' (zero where absent).
fn initial_covariance(active: &ParamVector, cfg: &RpemConfig) -> Covariance {
    let mut d = *active * cfg.p0;
    for i in NUM_BASE..NUM_PARAMS {
        d[i] = active[i] * cfg.p0_effects;
    }
    Covariance::from_diagonal(&d)
}

/// Projects `p` into the admissible region (n within `n_bounds`, β ± γ ≥ `margin`).
#[inline]
fn project_params(p: Params, cfg: &RpemConfig) -> Params {
    super::project_well_posed(p, cfg.n_bounds, cfg.margin)
}

/// Creep gain from its logistic coordinate: g = gmax·σ(η) ∈ [0, gmax] \[µm/V\].
#[inline]
fn gain_from_logit(eta: f64, gmax: f64) -> f64 {
    gmax / (1.0 + math::exp(-eta))
}

/// Logistic coordinate of a creep gain: η = ln(g / (gmax − g)).
#[inline]
fn logit_of_gain(g: f64, gmax: f64) -> f64 {
    math::ln(g / (gmax - g))
}

/// aᵀb summed in the order nalgebra uses for a [`NUM_PARAMS`]-vector whose slots
/// M.. are zero, so that the base path (M = [`NUM_BASE`]) gives the bits of the
/// full-width computation it replaces.
#[inline(always)]
fn dot_as_full<const M: usize>(a: &SVector<f64, M>, b: &SVector<f64, M>) -> f64 {
    if M == NUM_PARAMS {
        return a.dot(b);
    }
    let mut acc = [0.0f64; 8];
    for (i, slot) in acc.iter_mut().enumerate().take(M.min(8)) {
        *slot = a[i] * b[i];
    }
    let mut res = 0.0;
    res += acc[0] + acc[4];
    res += acc[1] + acc[5];
    res += acc[2] + acc[6];
    res += acc[3] + acc[7];
    for k in 8..M {
        res += a[k] * b[k];
    }
    res
}

impl RpemIdentifier {
    /// Steps 2 and 3 of the module docs on the first M slots of θ: M = [`NUM_BASE`]
    /// without effects (the effect slots are then zero and are skipped: a 7 × 7
    /// covariance update instead of 12 × 12, same results), [`NUM_PARAMS`] with them.
    ///
    /// Coordinates of the step: θᵢ/scaleᵢ for the base parameters, ln fc for the
    /// lag, and for each creep gain its logistic coordinate η = ln(g/(gmax − g)),
    /// gmax = `creep_gain_max_um_per_v`: the gains stay within (0, gmax) without
    /// clipping, so no bound works against the covariance (near a bound the
    /// sensitivity ∂x̂/∂η = ∂x̂/∂g·g(1 − g/gmax) fades instead). Should fc reach
    /// `fc_bounds_hz`, it is held there and its covariance is decoupled from the
    /// other parameters (the off-diagonal terms of ln fc are zeroed), so that the
    /// others no longer move to make up for it.
    #[inline(always)]
    fn update<const M: usize>(&mut self, prediction: f64, u: f64, x: f64, psi: SVector<f64, M>) -> RpemStatus {
        let cfg = self.config;
        let mut status = RpemStatus { samples: self.status.samples + 1, ..Default::default() };
        let e = x - prediction;
        status.innovation_um = e;
        let travel = self.u_prev.map_or(0.0, |u0| (u - u0).abs());
        let first = self.u_prev.is_none();
        self.u_prev = Some(u);
        // Without creep, nothing is learnt while u holds: a hold carries no information
        // on the hysteresis, and repeating one regressor would let every parameter
        // drift to absorb a constant error (the learnt R is kept as it was). With creep,
        // holds are where its gains show, so they are used.
        if first || (travel == 0.0 && self.shape.n_creep == 0 && cfg.offset_walk_um == 0.0) {
            status.noise_um2 = self.status.noise_um2.max(cfg.noise_um2);
            return status;
        }
        let gmax = cfg.creep_gain_max_um_per_v;
        let n_creep = if M == NUM_PARAMS { self.shape.n_creep } else { 0 };
        // ∂θ/∂(step coordinates): the scales, and g(1 − g/gmax) for the gains.
        // The fixed-size work below is written as index loops (nalgebra's iterators and
        // views over part of a matrix cost more than the arithmetic); each element
        // gets the operations, in the order, of the matrix expression in its comment.
        let mut jac = SVector::<f64, M>::from_fn(|i, _| self.scales[i]);
        for i in 0..n_creep {
            let g = self.est.creep_gain[i];
            jac[I_CREEP + i] = g * (1.0 - g / gmax);
        }
        // psi ∘ jac ∘ active.
        let psi = SVector::<f64, M>::from_fn(|i, _| psi[i] * jac[i] * self.active[i]);
        // p · psi on the first M rows and columns of the covariance (column-major,
        // NUM_PARAMS rows), column by column as a matrix–vector product accumulates.
        let mut p_psi = SVector::<f64, M>::zeros();
        for (j, col) in self.p.as_slice().chunks_exact(NUM_PARAMS).take(M).enumerate() {
            let w = psi[j];
            for i in 0..M {
                p_psi[i] += col[i] * w;
            }
        }
        let noise = if self.status.samples == 0 { cfg.noise_um2 } else { self.status.noise_um2 };
        status.noise_um2 = if cfg.noise_memory_samples.is_finite() {
            let a = 1.0 / cfg.noise_memory_samples;
            (noise + a * (e * e - noise)).max(cfg.noise_um2)
        } else {
            noise
        };
        let s = noise + dot_as_full(&psi, &p_psi);
        let gain = p_psi * (1.0 / s);
        let mut step = gain * e;
        // Trust region: every parameter but the offset moves by at most
        // max_step of its scale (the step scaled down as a whole); the offset x0,
        // which tracks slow disturbances, by at most max_offset_step_um.
        let offset_step = step[I_X0] * self.scales[I_X0];
        step[I_X0] = 0.0;
        let largest = step.amax();
        if largest > cfg.max_step {
            step *= cfg.max_step / largest;
            status.step_limited = true;
        }
        let offset_capped = offset_step.clamp(-cfg.max_offset_step_um, cfg.max_offset_step_um);
        status.step_limited |= offset_capped != offset_step;
        step[I_X0] = offset_capped / self.scales[I_X0];
        let lambda = cfg.forgetting * math::exp(-travel / cfg.memory_travel_v);
        // P ← (P − gain·p_psiᵀ) / λ, symmetrised (each entry of the lower triangle the
        // mean of the two it stands for, mirrored), in place on the first M rows and
        // columns: a step that fails below resets P anyway.
        let half_over_lambda = 0.5 / lambda;
        let p = self.p.as_mut_slice();
        let at = |i: usize, j: usize| j * NUM_PARAMS + i;
        let mut finite = true;
        for j in 0..M {
            for i in j..M {
                let v = ((p[at(i, j)] - gain[i] * p_psi[j]) + (p[at(j, i)] - gain[j] * p_psi[i])) * half_over_lambda;
                finite &= v.is_finite();
                p[at(i, j)] = v;
                p[at(j, i)] = v;
            }
        }
        p[at(I_X0, I_X0)] += math::powi(cfg.offset_walk_um / self.scales[I_X0], 2);
        let mut trace = 0.0;
        for i in 0..M {
            trace += p[at(i, i)];
            finite &= p[at(i, i)] >= 0.0;
        }
        if trace > cfg.max_trace {
            let shrink = cfg.max_trace / trace;
            for j in 0..M {
                for v in &mut p[at(0, j)..at(M, j)] {
                    *v *= shrink;
                }
            }
            status.trace_capped = true;
        }
        let mut theta = self.est.params.to_array();
        for (i, t) in theta.iter_mut().enumerate() {
            *t += step[i] * self.scales[i];
        }
        let finite = finite && step.as_slice().iter().all(|v| v.is_finite());
        match Params::from_array(theta) {
            Ok(params) if finite => {
                let mut raw = Estimates { params, ..self.est };
                let mut candidate = raw;
                candidate.params = project_params(raw.params, &cfg);
                if M == NUM_PARAMS && self.shape.lag {
                    raw.fc_hz = math::exp(math::ln(self.est.fc_hz) + step[I_LN_FC] * self.scales[I_LN_FC]);
                    candidate.fc_hz = raw.fc_hz.clamp(cfg.fc_bounds_hz.0, cfg.fc_bounds_hz.1);
                    if candidate.fc_hz != raw.fc_hz {
                        for j in 0..M {
                            if j != I_LN_FC {
                                self.p[(I_LN_FC, j)] = 0.0;
                                self.p[(j, I_LN_FC)] = 0.0;
                            }
                        }
                    }
                }
                for i in 0..n_creep {
                    let eta = logit_of_gain(self.est.creep_gain[i], gmax) + step[I_CREEP + i];
                    let g = gain_from_logit(eta, gmax);
                    raw.creep_gain[i] = g;
                    // Kept off the end points, where η would be infinite.
                    candidate.creep_gain[i] = g.clamp(GAIN_FLOOR * gmax, (1.0 - GAIN_FLOOR) * gmax);
                }
                // Without effects only the base parameters can have moved.
                status.projected = if M == NUM_PARAMS { candidate != raw } else { candidate.params != raw.params };
                self.est = candidate;
                status.updated = true;
            }
            _ => {
                self.p = initial_covariance(&self.active, &cfg);
                status.restarted = true;
            }
        }
        status
    }
}

/// Creep gains are held within [`GAIN_FLOOR`·gmax, (1 − `GAIN_FLOOR`)·gmax].
const GAIN_FLOOR: f64 = 1e-9;

impl OnlineIdentifier for RpemIdentifier {
    type Status = RpemStatus;

    fn push(&mut self, u: f64, x: f64) -> Result<f64> {
        finite_sample("u", u)?;
        finite_sample("x", x)?;

        // 1. Predict with the estimates from before the sample: h by the model
        // itself, the sensitivities alongside. 2–3. Update (see `update`).
        let (prediction, mut status, finite) = if self.shape.lag || self.shape.n_creep > 0 {
            let (prediction, psi) = self.chain.step(&self.est, &self.shape, self.u_prev, u, self.dt);
            let status = self.update::<NUM_PARAMS>(prediction, u, x, psi);
            (prediction, status, self.chain.is_finite())
        } else {
            let (prediction, psi) = self.chain.step_base(&self.est.params, self.u_prev, u, self.dt);
            let status = self.update::<NUM_BASE>(prediction, u, x, psi);
            // Without effects only ∂h/∂θ moves (∂u_a/∂θ and the creep rows stay zero).
            (prediction, status, self.chain.dh.as_slice().iter().all(|v| v.is_finite()))
        };
        if !finite {
            let h = self.chain.h;
            let ua = self.chain.ua;
            let creep = self.chain.creep;
            self.chain = Chain { h, ua, creep, ..Chain::new(h) };
            status.restarted = true;
        }
        status.trace = self.p.trace();
        self.status = status;
        Ok(prediction)
    }

    fn params(&self) -> Params {
        self.est.params
    }

    fn h(&self) -> f64 {
        self.chain.h
    }

    fn input_lag(&self) -> Option<(InputLag, f64)> {
        self.shape.lag.then_some((InputLag { fc_hz: self.est.fc_hz }, self.chain.ua))
    }

    fn forecast_into(&self, u: &[f64], out: &mut [f64]) -> Result<()> {
        super::check_forecast(u, out)?;
        // The chain with its effects, stepped on a copy (the derivatives it carries
        // along are not used).
        let mut chain = self.chain;
        let mut u_prev = self.u_prev;
        for (o, &v) in out.iter_mut().zip(u) {
            *o = chain.step(&self.est, &self.shape, u_prev, v, self.dt).0;
            u_prev = Some(v);
        }
        Ok(())
    }

    fn status(&self) -> RpemStatus {
        self.status
    }

    fn reset(&mut self) {
        self.est = self.init;
        self.chain = Chain::new(self.h0);
        self.u_prev = None;
        self.p = initial_covariance(&self.active, &self.config);
        self.status = RpemStatus::default();
    }
}
