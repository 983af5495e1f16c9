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
//!    zero or the interval is stiff, backward Euler beyond [`MAX_SUBSTEPS`], h held
//!    within ±[`H_LIMIT_UM`]), differentiated stage by stage (forward mode), each
//!    interval starting from the model's h. x̂ₖ uses the estimates from before the
//!    sample.
//! 2. **Gauss–Newton / Kalman step** in scaled coordinates φ = θ / `scales` (so
//!    that kv ≈ 0.2, δ ≈ 0.007 and n ≈ 1.5 all count alike):
//!    ```text
//!    e = xₖ − x̂ₖ,  ψ̃ = ψ ∘ scales,  s = R + ψ̃ᵀPψ̃,  K = Pψ̃ / s,  Δφ = K·e
//!    trust region: |Δφᵢ| ≤ max_step for all i but x0 (Δφ scaled down as a whole),
//!                  |Δx0| ≤ max_offset_step_um
//!    P ← (P − K ψ̃ᵀP) / λₖ,   λₖ = forgetting · exp(−|uₖ − uₖ₋₁| / memory_travel_v)
//!    P[x0,x0] += (offset_walk_um / scale_x0)²                 (x0 is a random walk)
//!    P ← P · min(1, max_trace / tr P)                         (bounded covariance)
//!    ```
//!    R = `noise_um2` [µm²] is the variance the prediction error is expected to
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
//!   bounded), h is held within ±[`H_LIMIT_UM`].
//! - *No NaN*: a non-finite sample is rejected before anything changes; a step,
//!   covariance or sensitivity that comes out non-finite is dropped (estimates held,
//!   P and the sensitivities restarted).
//! - O(1) and allocation-free per sample: only fixed-size nalgebra types
//!   ([`Covariance`] is a 12 × 12 `SMatrix`, of which the base model uses 7 × 7).
//!
//! Effects ([`OutputErrorIdentifier::with_effects`]): θ is extended by ln fc of an
//! `input_lag` and the gains of up to [`MAX_CREEP`] `creep` elements, the chain
//! u → u_a → (h, creep) → x of [`crate::effects`] is propagated with its
//! sensitivities (∂u_a/∂ln fc through the exact first-order step, ∂h/∂θ through
//! u_a at both ends of each interval, creep kept at unit gain so that cᵢ = gᵢ·sᵢ).
//! The step is taken in ln fc and in each gain's logistic coordinate
//! η = ln(g/(gmax − g)), so the gains stay within (0, gmax) without clipping
//! against the covariance; the effects start from the values given (an offline
//! extended fit) with the relative prior `p0_effects`, and with creep the offset
//! does not walk ([`OutputErrorConfig::for_effects`]).
//!
//! Cost: without effects the update runs on the 7 base slots only (7 × 7
//! covariance, sensitivities over 7 parameters), with the same results as the
//! full 12-slot computation; the effect slots are used only when declared.

use nalgebra::{SMatrix, SVector};

use super::{OnlineIdentifier, PushStatus, SubFit};
use crate::effects::{first_order_coefficient, first_order_step, Creep, EffectSet, InputLag};
use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::model::integrator::advance_forced;
use crate::model::output;
use crate::model::scalar::Dual;
use crate::model::Coefficients;
use crate::params::Params;

/// Number of base parameters (kv, x0, A, β, γ, n, δ).
pub const NUM_BASE: usize = 7;
/// Most creep elements identified online.
pub const MAX_CREEP: usize = 4;
/// Length of θ = (kv, x0, A, β, γ, n, δ, ln fc, g₁ … g₄): the base parameters in
/// the order of [`Params::to_array`], the input lag's corner frequency (as ln fc,
/// fc in Hz) and the creep gains [µm/V]. The slots of absent effects stay unused.
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

/// Tuning of [`OutputErrorIdentifier`], with documented defaults ([`Default`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputErrorConfig {
    /// Forgetting factor per sample λ ∈ (0, 1]: a memory of about 1/(1 − λ)
    /// samples whatever the input does. Default 1.0 (none; see `memory_travel_v`).
    pub forgetting: f64,
    /// Memory measured in input travel [V]: a sample's weight falls by
    /// exp(−|Δu|/`memory_travel_v`) for every later interval in which u moves by
    /// |Δu|. One period of the paper's 0–100 V sine is 200 V of travel at any
    /// frequency, so the memory spans the same number of periods at 1 Hz and at
    /// 200 Hz, and nothing is forgotten while u holds (no wind-up). Default 2000 V
    /// (ten periods; shorter memories let the parameters drift at 200 Hz on the
    /// simulated bench); `f64::INFINITY` turns it off.
    pub memory_travel_v: f64,
    /// Initial covariance P₀ = `p0`·I of the scaled parameters θᵢ/scaleᵢ: the prior
    /// standard deviation of θᵢ is √p0·scaleᵢ. Default 1e-3 (3 % of the scale; larger
    /// values overshoot in the first period, the model being far from linear in θ).
    pub p0: f64,
    /// Random walk of the offset x0 [µm per sample, standard deviation]: x0 may
    /// wander by this much from one sample to the next (creep, drift, thermal), so
    /// its variance grows by `offset_walk_um`² each sample, whatever the input does
    /// (P[x0,x0] stays bounded because x0 is always observed). Default 0.05 µm:
    /// the offset follows what the model cannot explain within a few samples,
    /// which makes the prediction one step ahead sharp; 0 makes x0 a constant.
    pub offset_walk_um: f64,
    /// Initial covariance of the effects' coordinates: ln fc of the input lag and
    /// the logistic coordinate η = ln(g/(gmax − g)) of each creep gain, which near
    /// the usual gains (g ≪ gmax) is ln g. Both are relative: √p0_effects is the
    /// prior relative standard deviation of fc and of each gain. Default 0.05
    /// (about 22 %): the effects are meant to start from an offline extended fit
    /// (`fit_extended`, `diagnose`) or a guess within some 30 %.
    pub p0_effects: f64,
    /// R: expected variance of the prediction error [µm²]. Default 1e-4 µm²
    /// (0.01 µm: sensor noise plus what the model cannot explain).
    pub noise_um2: f64,
    /// Bound on tr P (scaled units). Default 1.0.
    pub max_trace: f64,
    /// Largest change of any parameter in one sample, as a fraction of its scale
    /// (trust region). Default 0.01.
    pub max_step: f64,
    /// Largest change of the offset x0 in one sample [µm]. Default 0.5 µm.
    pub max_offset_step_um: f64,
    /// n is held within these bounds. Default (1.0, 4.0).
    pub n_bounds: (f64, f64),
    /// β + γ and β − γ are held at or above this [µm^(1−n)/V]. Default 1e-6.
    pub margin: f64,
    /// Scale of each parameter (kv, x0, A, β, γ, n, δ, in their units): the
    /// identifier works on θᵢ/scaleᵢ. Default (0.2, 0.1, 0.07, 0.02, 0.02, 1.5, 0.007):
    /// the paper's Table 2 magnitudes, with 0.1 µm for the offset. The lag's
    /// ln fc has scale 1 (a step of `max_step` = 1 % of fc).
    pub scales: [f64; NUM_BASE],
    /// Scale of the creep gains [µm/V]. Default 0.002 µm/V.
    pub creep_gain_scale_um_per_v: f64,
    /// Each creep gain is held within [0, this] [µm/V] (creep follows the voltage;
    /// the slow elements are nearly collinear with x0 over short records and would
    /// otherwise drift against it). Default 0.02 µm/V.
    pub creep_gain_max_um_per_v: f64,
    /// The lag's corner frequency is held within these bounds [Hz]. Default (10, 1e5) Hz.
    pub fc_bounds_hz: (f64, f64),
}

impl Default for OutputErrorConfig {
    fn default() -> Self {
        OutputErrorConfig {
            forgetting: 1.0,
            memory_travel_v: 2000.0,
            offset_walk_um: 0.05,
            p0: 1e-3,
            p0_effects: 0.05,
            noise_um2: 1e-4,
            max_trace: 1.0,
            max_step: 0.01,
            max_offset_step_um: 0.5,
            n_bounds: (1.0, 4.0),
            margin: 1e-6,
            scales: [0.2, 0.1, 0.07, 0.02, 0.02, 1.5, 0.007],
            creep_gain_scale_um_per_v: 0.002,
            creep_gain_max_um_per_v: 0.02,
            fc_bounds_hz: (10.0, 1e5),
        }
    }
}

impl OutputErrorConfig {
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
        if !(lo.is_finite() && hi.is_finite() && lo >= 1.0 && lo <= hi) {
            return bad("n_bounds", lo, "need 1 <= n_min <= n_max, both finite (∂ḣ/∂h is singular at h = 0 for n < 1)");
        }
        if !(self.offset_walk_um.is_finite() && self.offset_walk_um >= 0.0) {
            return bad("offset_walk_um", self.offset_walk_um, "must be finite and >= 0 µm");
        }
        if self.memory_travel_v.is_nan() || self.memory_travel_v <= 0.0 {
            return bad("memory_travel_v", self.memory_travel_v, "must be > 0 V (inf turns travel forgetting off)");
        }
        if !(self.margin.is_finite() && self.margin >= 0.0) {
            return bad("margin", self.margin, "must be finite and >= 0");
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

/// What the last push of an [`OutputErrorIdentifier`] did. `Copy`, no allocation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OutputErrorStatus {
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
    /// Prediction error e = x − x̂ of the sample [µm].
    pub innovation_um: f64,
    /// tr P after the push (scaled units).
    pub trace: f64,
}

/// The Bouc–Wen coefficients of `p` as the independent variables at their slots of θ.
#[inline(always)]
fn seeded<const M: usize>(p: &Params) -> Coefficients<Dual<M>> {
    Coefficients {
        a: Dual::var(p.a, I_A),
        beta: Dual::var(p.beta, I_BETA),
        gamma: Dual::var(p.gamma, I_GAMMA),
        n: Dual::var(p.n, I_N),
        delta: Dual::var(p.delta, I_DELTA),
    }
}

/// h over one sample interval (u linear from `u0` to `u1`) together with its gradient
/// over M parameters: the model's own integrator ([`crate::model::advance`]) run on
/// dual numbers, so the value is the model's h bit for bit and the gradient is that of
/// the discrete map it computes (the sub-step choice is piecewise constant in θ).
///
/// `dh` is ∂h/∂θ at the start; `du0`, `du1` are ∂u/∂θ at both ends (zero when u
/// is the measured voltage; non-zero when u passes through an identified effect
/// such as an input lag). The Bouc–Wen parameters sit at positions 2..=6 of θ.
#[inline]
pub fn advance_h_with_gradient<const M: usize>(
    p: &Params,
    h: f64,
    dh: &SVector<f64, M>,
    u0: (f64, &SVector<f64, M>),
    u1: (f64, &SVector<f64, M>),
    dt: f64,
) -> (f64, SVector<f64, M>) {
    advance_with_substeps(p, h, dh, u0, u1, dt, None)
}

/// [`advance_h_with_gradient`] with the number of RK4 sub-steps optionally forced.
#[inline(always)]
fn advance_with_substeps<const M: usize>(
    p: &Params,
    h: f64,
    dh: &SVector<f64, M>,
    (u0, du0): (f64, &SVector<f64, M>),
    (u1, du1): (f64, &SVector<f64, M>),
    dt: f64,
    forced: Option<u32>,
) -> (f64, SVector<f64, M>) {
    let r = advance_forced(p, &seeded::<M>(p), Dual::new(h, *dh), Dual::new(u0, *du0), Dual::new(u1, *du1), dt, forced);
    (r.re, r.du)
}

/// Current estimates: the base parameters and those of the effects.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Estimates {
    params: Params,
    /// Corner frequency of the input lag [Hz] (unused without the lag).
    fc_hz: f64,
    /// Creep gains g_i [µm/V] (the first `n_creep` are used).
    creep_gain: [f64; MAX_CREEP],
}

#[cfg(test)]
impl Estimates {
    fn to_theta(self) -> ParamVector {
        let mut t = ParamVector::zeros();
        for (i, v) in self.params.to_array().into_iter().enumerate() {
            t[i] = v;
        }
        t[I_LN_FC] = self.fc_hz.ln();
        for i in 0..MAX_CREEP {
            t[I_CREEP + i] = self.creep_gain[i];
        }
        t
    }

    fn from_theta(t: &ParamVector, lag: bool, before: &Estimates) -> Result<Self> {
        let params = Params::from_array([t[0], t[1], t[2], t[3], t[4], t[5], t[6]])?;
        let fc_hz = if lag { t[I_LN_FC].exp() } else { before.fc_hz };
        let mut creep_gain = [0.0; MAX_CREEP];
        for (i, g) in creep_gain.iter_mut().enumerate() {
            *g = t[I_CREEP + i];
        }
        Ok(Estimates { params, fc_hz, creep_gain })
    }
}

/// Which effects are in the chain, with their fixed constants.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Shape {
    lag: bool,
    n_creep: usize,
    creep_tau: [f64; MAX_CREEP],
    creep_decay: [f64; MAX_CREEP],
}

/// The model's state and its sensitivities ∂/∂θ (unscaled).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Chain {
    h: f64,
    dh: ParamVector,
    /// Voltage on the stack u_a [V] (= u without the lag).
    ua: f64,
    dua: ParamVector,
    /// Unit-gain creep elements sᵢ (τᵢ·ṡᵢ = u_a − sᵢ); cᵢ = gᵢ·sᵢ, so that a new
    /// gain acts on the whole history at once.
    creep: [f64; MAX_CREEP],
    /// ∂sᵢ/∂θ.
    dcreep: [ParamVector; MAX_CREEP],
}

impl Chain {
    fn new(h0: f64) -> Self {
        Chain {
            h: h0,
            dh: ParamVector::zeros(),
            ua: 0.0,
            dua: ParamVector::zeros(),
            creep: [0.0; MAX_CREEP],
            dcreep: [ParamVector::zeros(); MAX_CREEP],
        }
    }

    fn is_finite(&self) -> bool {
        self.dh.iter().chain(self.dua.iter()).all(|v| v.is_finite())
            && self.dcreep.iter().all(|d| d.iter().all(|v| v.is_finite()))
    }

    /// [`Chain::step`] without effects (u_a = u, no creep), with ∂x̂/∂θ over the
    /// base parameters only: the same values, without the work on the effect slots.
    #[inline]
    fn step_base(&mut self, p: &Params, u_prev: Option<f64>, u: f64, dt: f64) -> (f64, SVector<f64, NUM_BASE>) {
        match u_prev {
            None => {
                self.ua = u;
                self.dua = ParamVector::zeros();
            }
            Some(_) => {
                let ua0 = self.ua;
                self.ua = u;
                let zero = SVector::<f64, NUM_BASE>::zeros();
                let dh: SVector<f64, NUM_BASE> = self.dh.fixed_rows::<NUM_BASE>(0).into_owned();
                let (h, dh) = advance_h_with_gradient(p, self.h, &dh, (ua0, &zero), (u, &zero), dt);
                self.h = h;
                self.dh.fixed_rows_mut::<NUM_BASE>(0).copy_from(&dh);
            }
        }
        let mut psi: SVector<f64, NUM_BASE> = self.dh.fixed_rows::<NUM_BASE>(0).into_owned();
        psi[I_KV] += self.ua;
        psi[I_X0] += 1.0;
        (output(p, self.ua, self.h), psi)
    }

    /// Advances the chain to the sample `u` (the first sample when `u_prev` is None),
    /// in the order of [`crate::effects::ExtendedModel::step`]: lag, h, creep. Returns
    /// x̂ = kv·u_a + x0 + h + Σcᵢ [µm] and ψ = ∂x̂/∂θ.
    #[inline]
    fn step(&mut self, est: &Estimates, shape: &Shape, u_prev: Option<f64>, u: f64, dt: f64) -> (f64, ParamVector) {
        let p = &est.params;
        match u_prev {
            None => {
                self.ua = u;
                self.dua = ParamVector::zeros();
                for i in 0..shape.n_creep {
                    self.creep[i] = u;
                    self.dcreep[i] = ParamVector::zeros();
                }
            }
            Some(u0) => {
                let (ua0, dua0) = (self.ua, self.dua);
                if shape.lag {
                    let tau = InputLag { fc_hz: est.fc_hz }.tau_s();
                    let decay = first_order_coefficient(tau, dt);
                    self.ua = first_order_step(ua0, u0, u, tau, decay, dt);
                    // ∂/∂τ of the exact step, then τ = 1/(2π·fc) gives ∂τ/∂ln fc = −τ.
                    let slope = (u - u0) / dt;
                    let d_tau = -slope + slope * decay + (ua0 - u0 + tau * slope) * decay * dt / (tau * tau);
                    self.dua = dua0 * decay;
                    self.dua[I_LN_FC] += -tau * d_tau;
                } else {
                    self.ua = u;
                }
                (self.h, self.dh) =
                    advance_h_with_gradient(p, self.h, &self.dh, (ua0, &dua0), (self.ua, &self.dua), dt);
                for i in 0..shape.n_creep {
                    let (tau, decay) = (shape.creep_tau[i], shape.creep_decay[i]);
                    self.creep[i] = first_order_step(self.creep[i], ua0, self.ua, tau, decay, dt);
                    if shape.lag {
                        // The step is linear in (s, u_a0, u_a1).
                        let spread = tau / dt * (1.0 - decay);
                        let (w0, w1) = (spread - decay, 1.0 - spread);
                        self.dcreep[i] = self.dcreep[i] * decay + dua0 * w0 + self.dua * w1;
                    }
                }
            }
        }
        let mut x = output(p, self.ua, self.h);
        let mut psi = self.dh + self.dua * p.kv;
        psi[I_KV] += self.ua;
        psi[I_X0] += 1.0;
        if shape.n_creep > 0 {
            let mut c = 0.0;
            for i in 0..shape.n_creep {
                let g = est.creep_gain[i];
                c += g * self.creep[i];
                psi += self.dcreep[i] * g;
                psi[I_CREEP + i] += self.creep[i];
            }
            x += c;
        }
        (x, psi)
    }
}

/// The output-error online identifier (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct OutputErrorIdentifier {
    config: OutputErrorConfig,
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
    status: OutputErrorStatus,
}

impl OutputErrorIdentifier {
    /// An identifier of the base model for samples every `dt` [s], starting from
    /// `init` with model state `h0` [µm]. `init` is projected into the admissible
    /// region first (n within `n_bounds`, β ± γ ≥ `margin`).
    pub fn new(dt: f64, init: Params, h0: f64, config: OutputErrorConfig) -> Result<Self> {
        Self::with_effects(dt, init, &EffectSet::none(), h0, config)
    }

    /// As [`OutputErrorIdentifier::new`], with the base model extended by `effects`,
    /// whose parameters are identified too: `input_lag` (fc, starting from the value
    /// given) and `creep` (the gains gᵢ, starting from the values given; the time
    /// constants τᵢ stay fixed; at most [`MAX_CREEP`] elements). Other effects are
    /// not identified online and are rejected.
    ///
    /// The lag is identified as ln fc and each creep gain through its logistic
    /// coordinate (see `update`), with the relative prior `p0_effects`. Use
    /// [`OutputErrorConfig::for_effects`] for the configuration: with creep the
    /// offset must not walk, or it takes the slow errors the gains should explain.
    /// A creep gain given below 5 % of `creep_gain_scale_um_per_v` starts there.
    pub fn with_effects(
        dt: f64,
        init: Params,
        effects: &EffectSet,
        h0: f64,
        config: OutputErrorConfig,
    ) -> Result<Self> {
        positive_dt(dt)?;
        init.validate()?;
        config.validate()?;
        effects.validate()?;
        finite_sample("h0", h0)?;
        if effects.resonance.is_some() || effects.drift.is_some() || effects.delay.is_some() {
            return Err(Error::InvalidConfig {
                name: "effects",
                value: f64::NAN,
                reason:
                    "the rpem method identifies input_lag and creep only (resonance, drift and delay are not supported)",
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
        Ok(OutputErrorIdentifier {
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
            status: OutputErrorStatus::default(),
        })
    }

    /// The tuning in use.
    pub fn config(&self) -> &OutputErrorConfig {
        &self.config
    }

    /// What the last push did, in detail.
    pub fn detail(&self) -> OutputErrorStatus {
        self.status
    }

    /// Covariance P of the scaled parameters θᵢ/scaleᵢ (dimensionless), θ =
    /// (kv, x0, A, β, γ, n, δ, ln fc, g₁ … g₄); the rows of absent effects are zero.
    pub fn covariance(&self) -> &Covariance {
        &self.p
    }

    /// ∂h/∂θ after the last sample [µm per unit of each parameter], θ as in
    /// [`OutputErrorIdentifier::covariance`].
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
fn initial_covariance(active: &ParamVector, cfg: &OutputErrorConfig) -> Covariance {
    let mut d = *active * cfg.p0;
    for i in NUM_BASE..NUM_PARAMS {
        d[i] = active[i] * cfg.p0_effects;
    }
    Covariance::from_diagonal(&d)
}

/// Projects `p` into the admissible region.
fn project_params(mut p: Params, cfg: &OutputErrorConfig) -> Params {
    p.n = p.n.clamp(cfg.n_bounds.0, cfg.n_bounds.1);
    // β + γ ≥ margin and β − γ ≥ margin: two orthogonal half-planes in (β, γ).
    let sum = p.beta + p.gamma;
    if sum < cfg.margin {
        let shift = 0.5 * (cfg.margin - sum);
        p.beta += shift;
        p.gamma += shift;
    }
    let diff = p.beta - p.gamma;
    if diff < cfg.margin {
        let shift = 0.5 * (cfg.margin - diff);
        p.beta += shift;
        p.gamma -= shift;
    }
    p
}

/// Creep gain from its logistic coordinate: g = gmax·σ(η) ∈ [0, gmax] [µm/V].
#[inline]
fn gain_from_logit(eta: f64, gmax: f64) -> f64 {
    gmax / (1.0 + (-eta).exp())
}

/// Logistic coordinate of a creep gain: η = ln(g / (gmax − g)).
#[inline]
fn logit_of_gain(g: f64, gmax: f64) -> f64 {
    (g / (gmax - g)).ln()
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

impl OutputErrorIdentifier {
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
    fn update<const M: usize>(&mut self, prediction: f64, u: f64, x: f64, psi: SVector<f64, M>) -> OutputErrorStatus {
        let cfg = self.config;
        let mut status = OutputErrorStatus { samples: self.status.samples + 1, ..Default::default() };
        let e = x - prediction;
        status.innovation_um = e;
        let travel = self.u_prev.map_or(0.0, |u0| (u - u0).abs());
        let first = self.u_prev.is_none();
        self.u_prev = Some(u);
        if first {
            return status;
        }
        let gmax = cfg.creep_gain_max_um_per_v;
        let n_creep = if M == NUM_PARAMS { self.shape.n_creep } else { 0 };
        // ∂θ/∂(step coordinates): the scales, and g(1 − g/gmax) for the gains.
        let mut jac: SVector<f64, M> = self.scales.fixed_rows::<M>(0).into_owned();
        for i in 0..n_creep {
            let g = self.est.creep_gain[i];
            jac[I_CREEP + i] = g * (1.0 - g / gmax);
        }
        let active: SVector<f64, M> = self.active.fixed_rows::<M>(0).into_owned();
        let psi = psi.component_mul(&jac).component_mul(&active);
        let p: SMatrix<f64, M, M> = self.p.fixed_view::<M, M>(0, 0).into_owned();
        let p_psi = p * psi;
        let s = cfg.noise_um2 + dot_as_full(&psi, &p_psi);
        let gain = p_psi / s;
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
        let lambda = cfg.forgetting * (-travel / cfg.memory_travel_v).exp();
        let mut new_p = (p - gain * p_psi.transpose()) / lambda;
        new_p = (new_p + new_p.transpose()) * 0.5;
        new_p[(I_X0, I_X0)] += (cfg.offset_walk_um / self.scales[I_X0]).powi(2);
        let trace = new_p.trace();
        if trace > cfg.max_trace {
            new_p *= cfg.max_trace / trace;
            status.trace_capped = true;
        }
        let mut theta = self.est.params.to_array();
        for (i, t) in theta.iter_mut().enumerate() {
            *t += step[i] * self.scales[i];
        }
        let finite = step.iter().all(|v| v.is_finite())
            && new_p.iter().all(|v| v.is_finite())
            && new_p.diagonal().iter().all(|&v| v >= 0.0);
        match Params::from_array(theta) {
            Ok(params) if finite => {
                let mut raw = Estimates { params, ..self.est };
                let mut candidate = raw;
                candidate.params = project_params(raw.params, &cfg);
                if M == NUM_PARAMS && self.shape.lag {
                    raw.fc_hz = (self.est.fc_hz.ln() + step[I_LN_FC] * self.scales[I_LN_FC]).exp();
                    candidate.fc_hz = raw.fc_hz.clamp(cfg.fc_bounds_hz.0, cfg.fc_bounds_hz.1);
                    if candidate.fc_hz != raw.fc_hz {
                        for j in 0..M {
                            if j != I_LN_FC {
                                new_p[(I_LN_FC, j)] = 0.0;
                                new_p[(j, I_LN_FC)] = 0.0;
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
                status.projected = candidate != raw;
                self.est = candidate;
                self.p.fixed_view_mut::<M, M>(0, 0).copy_from(&new_p);
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

impl OnlineIdentifier for OutputErrorIdentifier {
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
            (prediction, status, self.chain.dh.iter().all(|v| v.is_finite()))
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

    /// `samples` as counted; `window_full` is always false (no window); every
    /// sub-fit reads "ran" when the parameters were updated and "held" otherwise.
    fn status(&self) -> PushStatus {
        let fit = if self.status.updated { SubFit::Ran } else { SubFit::Held };
        PushStatus {
            samples: self.status.samples,
            window_full: false,
            refreshed: false,
            line_fit: fit,
            rate_fit: fit,
            shape_fit: fit,
            return_fit: fit,
        }
    }

    fn reset(&mut self) {
        self.est = self.init;
        self.chain = Chain::new(self.h0);
        self.u_prev = None;
        self.p = initial_covariance(&self.active, &self.config);
        self.status = OutputErrorStatus::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{advance_h, paper_input, simulate};

    /// h and ∂h/∂θ over a whole record (`forced`: fixed number of RK4 sub-steps).
    fn run_gradient(p: &Params, u: &[f64], dt: f64, forced: Option<u32>) -> (Vec<f64>, Vec<ParamVector>) {
        let zero = ParamVector::zeros();
        let (mut h, mut g) = (0.0, zero);
        let mut hs = vec![h];
        let mut gs = vec![g];
        for w in u.windows(2) {
            (h, g) = advance_with_substeps(p, h, &g, (w[0], &zero), (w[1], &zero), dt, forced);
            hs.push(h);
            gs.push(g);
        }
        (hs, gs)
    }

    #[test]
    fn gradient_pass_integrates_h_like_model_advance_h() {
        // One integrator: the sensitivity pass runs the model's own scheme on dual
        // numbers, so its h is the model's bit for bit, stiff intervals included.
        let dt = 1e-4;
        let mut u = paper_input(dt, 0.02);
        u.extend([0.0, 95.0, 95.0, 3.0]);
        for p in
            [Params::paper_1hz(), Params { n: 1.0, ..Params::paper_1hz() }, Params { n: 0.64, ..Params::paper_1hz() }]
        {
            let (hs, _) = run_gradient(&p, &u, dt, None);
            let mut h = 0.0;
            for (k, w) in u.windows(2).enumerate() {
                h = advance_h(&p, h, w[0], w[1], dt);
                assert_eq!(hs[k + 1], h, "sample {k}");
            }
        }
    }

    #[test]
    fn sensitivities_match_central_finite_differences() {
        // 1 Hz then 10 Hz, with 3 RK4 sub-steps in every interval for the base and
        // the perturbed parameters alike: the sub-step rule is piecewise constant in
        // θ and its jumps would spoil a difference quotient; what is checked is the
        // derivative of the discrete map, which is what the identifier uses.
        let dt = 1e-4;
        let u: Vec<f64> = paper_input(dt, 0.0)[..31_000].to_vec();
        let p = Params::paper_1hz();
        let (_, gs) = run_gradient(&p, &u, dt, Some(3));
        let scales = OutputErrorConfig::default().scales;
        for i in I_A..=I_DELTA {
            // Central differences with ε = 1e-4 of the parameter's scale: truncation
            // error O(ε²·∂³h/∂θ³) ≈ 1e-8 relative; the stages take |h|^n from a series
            // exact to 1e-10 relative, whose hand-over to powf leaves steps of about
            // 1e-10 µm in h, i.e. ≈ 1e-6 µm per unit scale in the quotient. Both lie
            // below the tolerance of 1e-5 of the largest sensitivity, while a wrong term
            // in the derivative (a missed factor or sign) shows up at order 1.
            let eps = 1e-4 * scales[i];
            let mut plus = p.to_array();
            plus[i] += eps;
            let mut minus = p.to_array();
            minus[i] -= eps;
            let (hp, _) = run_gradient(&Params::from_array(plus).unwrap(), &u, dt, Some(3));
            let (hm, _) = run_gradient(&Params::from_array(minus).unwrap(), &u, dt, Some(3));
            let largest = gs.iter().map(|g| g[i].abs()).fold(0.0, f64::max);
            assert!(largest > 0.0);
            let mut worst = 0.0f64;
            for k in (0..u.len()).step_by(7) {
                let fd = (hp[k] - hm[k]) / (2.0 * eps);
                worst = worst.max((fd - gs[k][i]).abs());
            }
            assert!(worst <= 1e-5 * largest, "parameter {}: worst {worst}, largest {largest}", Params::NAMES[i]);
        }
    }

    #[test]
    fn sensitivities_through_the_input_match_finite_differences() {
        // ∂h/∂u at both interval ends, checked with a synthetic direction: u(θ) =
        // u + θ₀·v(t) for a fixed v; d h/dθ₀ at θ₀ = 0 against central differences.
        let dt = 1e-4;
        let u: Vec<f64> = paper_input(dt, 0.0)[29_000..31_000].to_vec();
        let v: Vec<f64> = (0..u.len()).map(|k| (k as f64 * 0.01).sin()).collect();
        let p = Params::paper_1hz();
        let zero = ParamVector::zeros();
        let sim = |theta0: f64| -> Vec<f64> {
            let mut h = 0.0;
            let mut hs = vec![h];
            for k in 1..u.len() {
                let (u0, u1) = (u[k - 1] + theta0 * v[k - 1], u[k] + theta0 * v[k]);
                h = advance_with_substeps(&p, h, &zero, (u0, &zero), (u1, &zero), dt, Some(3)).0;
                hs.push(h);
            }
            hs
        };
        let mut g = ParamVector::zeros();
        let mut h = 0.0;
        let mut worst = 0.0f64;
        let mut largest = 0.0f64;
        let eps = 1e-4;
        let (hp, hm) = (sim(eps), sim(-eps));
        for k in 1..u.len() {
            let (mut d0, mut d1) = (ParamVector::zeros(), ParamVector::zeros());
            d0[0] = v[k - 1];
            d1[0] = v[k];
            (h, g) = advance_with_substeps(&p, h, &g, (u[k - 1], &d0), (u[k], &d1), dt, Some(3));
            let fd = (hp[k] - hm[k]) / (2.0 * eps);
            worst = worst.max((fd - g[0]).abs());
            largest = largest.max(g[0].abs());
        }
        assert!(largest > 0.0);
        assert!(worst <= 1e-5 * largest, "worst {worst}, largest {largest}");
    }

    fn lag_and_creep() -> EffectSet {
        EffectSet {
            input_lag: Some(InputLag { fc_hz: 500.0 }),
            creep: Some(Creep { tau_s: vec![0.01, 0.1, 1.0], gain_um_per_v: vec![0.0015, 0.002, 0.0015] }),
            ..EffectSet::none()
        }
    }

    /// x̂ and ψ of the effect chain over a record, with estimates frozen.
    fn run_chain(id: &OutputErrorIdentifier, est: &Estimates, u: &[f64]) -> (Vec<f64>, Vec<ParamVector>) {
        let mut chain = Chain::new(id.h0);
        let mut prev = None;
        let mut xs = Vec::new();
        let mut psis = Vec::new();
        for &v in u {
            let (x, psi) = chain.step(est, &id.shape, prev, v, id.dt);
            prev = Some(v);
            xs.push(x);
            psis.push(psi);
        }
        (xs, psis)
    }

    #[test]
    fn effect_chain_reproduces_simulate_extended() {
        let dt = 1e-4;
        let u: Vec<f64> = paper_input(dt, 0.05);
        let p = Params::paper_1hz();
        let effects = lag_and_creep();
        let id = OutputErrorIdentifier::with_effects(dt, p, &effects, 0.0, OutputErrorConfig::default()).unwrap();
        let (xs, _) = run_chain(&id, &id.est, &u);
        let reference = crate::effects::simulate_extended(&p, &effects, &u, dt, 0.0).unwrap();
        // The creep elements are kept at unit gain and multiplied by gᵢ afterwards
        // (the step is linear, so this is the same up to rounding: a few ulps of the
        // ≈ 20 µm output).
        let worst = xs.iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst <= 1e-12, "{worst}");
    }

    #[test]
    fn effect_sensitivities_match_central_finite_differences() {
        // 1 Hz then 10 Hz. h is advanced by the model's own rule here, whose number
        // of sub-steps can change when fc moves u_a; such a jump is an RK4 local
        // error difference (< 1e-9 µm at these rates), so ε is taken large enough
        // (1e-3 of the scale) that jumps contribute < 1e-9/2e-3·… ≪ the tolerance,
        // and small enough that the O(ε²) truncation stays below 1e-5 relative.
        let dt = 1e-4;
        let u: Vec<f64> = paper_input(dt, 0.0)[..31_000].to_vec();
        let id = OutputErrorIdentifier::with_effects(
            dt,
            Params::paper_1hz(),
            &lag_and_creep(),
            0.0,
            OutputErrorConfig::default(),
        )
        .unwrap();
        let (_, psis) = run_chain(&id, &id.est, &u);
        for i in [I_KV, I_X0, I_A, I_DELTA, I_LN_FC, I_CREEP, I_CREEP + 1, I_CREEP + 2] {
            let eps = 1e-3 * id.scales[i];
            let shifted = |sign: f64| {
                let mut theta = id.est.to_theta();
                theta[i] += sign * eps;
                Estimates::from_theta(&theta, true, &id.est).unwrap()
            };
            let (xp, _) = run_chain(&id, &shifted(1.0), &u);
            let (xm, _) = run_chain(&id, &shifted(-1.0), &u);
            let largest = psis.iter().map(|g| g[i].abs()).fold(0.0, f64::max);
            assert!(largest > 0.0, "parameter {i}");
            let mut worst = 0.0f64;
            for k in (0..u.len()).step_by(7) {
                worst = worst.max(((xp[k] - xm[k]) / (2.0 * eps) - psis[k][i]).abs());
            }
            assert!(worst <= 1e-4 * largest, "parameter {i}: worst {worst}, largest {largest}");
        }
    }

    /// Sine bursts around changing means, each after a ramp and a 0.3 s hold [V]
    /// (as tests/test_rpem.py's `creep_input`).
    fn creep_input(dt: f64, seconds: f64) -> Vec<f64> {
        let plan = [(2.0, 40.0, 50.0), (8.0, 20.0, 30.0), (32.0, 15.0, 70.0), (4.0, 30.0, 40.0), (16.0, 25.0, 60.0)];
        let total = (seconds / dt) as usize;
        let (mut u, mut last, mut i) = (Vec::new(), 0.0f64, 0);
        while u.len() < total {
            let (f, amp, mean): (f64, f64, f64) = plan[i % plan.len()];
            let ramp = (0.02 / dt) as usize;
            u.extend((0..ramp).map(|k| last + (mean - amp - last) * k as f64 / (ramp - 1) as f64));
            u.extend(std::iter::repeat_n(mean - amp, (0.3 / dt) as usize));
            let periods = (f * 0.4).round().max(2.0);
            let n = (periods / f / dt).round() as usize;
            u.extend((0..n).map(|k| mean - amp * (2.0 * std::f64::consts::PI * f * k as f64 * dt).cos()));
            last = *u.last().unwrap();
            i += 1;
        }
        u.truncate(total);
        u
    }

    #[test]
    fn identifies_input_lag_and_creep_from_effects_started_off() {
        // Noise-free record of the model with a 500 Hz lag and three creep elements;
        // the identifier starts from fc 30 % high and gains 25–30 % off.
        let dt = 1e-4;
        let truth = Params::paper_1hz();
        let effects = lag_and_creep();
        let u = creep_input(dt, 8.0);
        let x = crate::effects::simulate_extended(&truth, &effects, &u, dt, 0.0).unwrap();
        let start = EffectSet {
            input_lag: Some(InputLag { fc_hz: 650.0 }),
            creep: Some(Creep { tau_s: vec![0.01, 0.1, 1.0], gain_um_per_v: vec![0.0011, 0.0026, 0.00105] }),
            ..EffectSet::none()
        };
        let cfg = OutputErrorConfig::for_effects(&start);
        assert_eq!(cfg.offset_walk_um, 0.0);
        let mut ext = OutputErrorIdentifier::with_effects(dt, truth, &start, 0.0, cfg).unwrap();
        let mut base = OutputErrorIdentifier::new(dt, truth, 0.0, OutputErrorConfig::default()).unwrap();
        let last = u.len() - u.len() / 4;
        let (mut err_ext, mut err_base) = (0.0f64, 0.0f64);
        for (k, (&u, &x)) in u.iter().zip(&x).enumerate() {
            let (pe, pb) = (ext.push(u, x).unwrap(), base.push(u, x).unwrap());
            assert!(pe.is_finite() && ext.covariance().iter().all(|v| v.is_finite()));
            assert!(ext.covariance().trace() <= cfg.max_trace * (1.0 + 1e-12));
            if k >= last {
                err_ext += (x - pe).powi(2);
                err_base += (x - pb).powi(2);
            }
        }
        assert!(err_ext < err_base, "{err_ext} vs {err_base}");
        let found = ext.effects();
        let fc = found.input_lag.unwrap().fc_hz;
        assert!((fc - 500.0).abs() < 0.05 * 500.0, "fc {fc}");
        let g = found.creep.unwrap().gain_um_per_v;
        let (want, began) = ([0.0015, 0.002, 0.0015], [0.0011, 0.0026, 0.00105]);
        for i in 1..3 {
            assert!((g[i] - want[i]).abs() < 0.5 * (began[i] - want[i]).abs(), "gain {i}: {g:?}");
        }
    }

    fn perturbed() -> Params {
        let t = Params::paper_1hz();
        Params {
            kv: t.kv * 1.1,
            x0: t.x0 + 0.05,
            a: t.a * 0.9,
            beta: t.beta * 1.1,
            gamma: t.gamma * 0.9,
            n: 1.6,
            delta: t.delta * 1.2,
        }
    }

    /// Sine bursts of several frequencies and amplitudes [V].
    pub(super) fn rich_input(dt: f64, seconds: f64) -> Vec<f64> {
        // Sine bursts of 1, 4 and 16 Hz and two amplitudes, each starting at a minimum.
        let plan = [(1.0, 50.0), (4.0, 30.0), (16.0, 50.0), (2.0, 20.0), (8.0, 45.0)];
        let mut u = Vec::new();
        let total = (seconds / dt) as usize;
        let mut i = 0;
        while u.len() < total {
            let (f, amp) = plan[i % plan.len()];
            let periods = (f * 0.5f64).ceil().max(1.0);
            let n = (periods / f / dt).round() as usize;
            for k in 0..n {
                let t = k as f64 * dt;
                u.push(50.0 - amp * (2.0 * std::f64::consts::PI * f * t).cos());
            }
            i += 1;
        }
        u.truncate(total);
        u
    }

    #[test]
    fn recovers_known_parameters_from_noise_free_data() {
        // Several frequencies: δ·u·sgn(u̇) acts per unit time, not per volt, so one
        // frequency alone cannot separate it from A (see the paper's Table 2).
        let dt = 1e-4;
        let truth = Params::paper_1hz();
        let u = rich_input(dt, 6.0);
        let (x, _) = simulate(&truth, &u, dt, 0.0, None).unwrap();
        let cfg = OutputErrorConfig { offset_walk_um: 0.0, ..Default::default() };
        let mut id = OutputErrorIdentifier::new(dt, perturbed(), 0.0, cfg).unwrap();
        let mut last_err = 0.0f64;
        let last_second = u.len() - 10_000;
        for (k, (&u, &x)) in u.iter().zip(&x).enumerate() {
            let pred = id.push(u, x).unwrap();
            if k >= last_second {
                last_err = last_err.max((pred - x).abs());
            }
        }
        let est = id.params().to_array();
        assert!(last_err < 0.005, "output error in the last second {last_err} µm");
        // Tolerances: the loop pins kv, A, β, γ, n tightly; δ and x0 less so.
        let tolerance = [0.01, 0.5, 0.02, 0.05, 0.05, 0.03, 0.1];
        for (i, tol) in tolerance.iter().enumerate() {
            let want = truth.to_array()[i];
            let rel = (est[i] - want).abs() / want.abs();
            assert!(rel < *tol, "{}: {} vs {want}", Params::NAMES[i], est[i]);
        }
    }

    #[test]
    fn constant_input_holds_estimates_and_bounds_the_covariance() {
        let dt = 1e-4;
        let truth = Params::paper_1hz();
        let u: Vec<f64> = paper_input(dt, 0.0)[..20_000].to_vec();
        let (x, _) = simulate(&truth, &u, dt, 0.0, None).unwrap();
        let cfg = OutputErrorConfig::default();
        let mut id = OutputErrorIdentifier::new(dt, truth, 0.0, cfg).unwrap();
        for (&u, &x) in u.iter().zip(&x) {
            id.push(u, x).unwrap();
        }
        let before = id.params();
        let (u_hold, x_hold) = (*u.last().unwrap(), *x.last().unwrap());
        for _ in 0..300_000 {
            let pred = id.push(u_hold, x_hold).unwrap();
            assert!(pred.is_finite());
        }
        let held = id.params().to_array();
        for (a, b) in held.iter().zip(before.to_array()) {
            assert!((a - b).abs() <= 1e-3 * b.abs().max(0.01), "{held:?} vs {before:?}");
        }
        assert!(id.covariance().trace() <= cfg.max_trace * (1.0 + 1e-12));
        assert!(id.covariance().iter().all(|v| v.is_finite()));
    }

    #[test]
    fn rejected_samples_leave_no_trace() {
        let mut id = OutputErrorIdentifier::new(1e-3, Params::paper_1hz(), 0.0, OutputErrorConfig::default()).unwrap();
        for k in 0..200 {
            let u = 50.0 + 50.0 * (k as f64 * 0.05).sin();
            id.push(u, 0.18 * u).unwrap();
        }
        let before = id.clone();
        assert!(id.push(f64::NAN, 1.0).is_err());
        assert!(id.push(1.0, f64::INFINITY).is_err());
        assert_eq!(id, before);
    }

    #[test]
    fn rejects_bad_config() {
        let bad = [
            OutputErrorConfig { forgetting: 0.0, ..Default::default() },
            OutputErrorConfig { forgetting: 1.5, ..Default::default() },
            OutputErrorConfig { noise_um2: -1.0, ..Default::default() },
            OutputErrorConfig { max_step: f64::NAN, ..Default::default() },
            OutputErrorConfig { n_bounds: (0.5, 3.0), ..Default::default() },
            OutputErrorConfig { scales: [0.0; NUM_BASE], ..Default::default() },
        ];
        for cfg in bad {
            assert!(OutputErrorIdentifier::new(1e-4, Params::paper_1hz(), 0.0, cfg).is_err(), "{cfg:?}");
        }
    }
}

// Save and restore (see `crate::snapshot`): every field the identifier carries
// between samples, written as it is held. The constants derived from the
// configuration and the effects (parameter scales, active slots, the creep
// elements' decay factors) are rebuilt by the constructor from the same values,
// with the same bits. The struct patterns below are exhaustive on purpose: a
// field added to any of these types stops the build here until it is saved.
mod snapshot_impl {
    use super::*;
    use crate::snapshot::{corrupt, Reader, Snapshot, Writer, KIND_RPEM};

    fn write_estimates(w: &mut Writer, e: &Estimates) {
        let Estimates { params, fc_hz, creep_gain } = e;
        w.params(params);
        w.f64(*fc_hz);
        w.f64s(creep_gain);
    }

    fn read_estimates(r: &mut Reader<'_>) -> Result<Estimates> {
        let params = r.params()?;
        let at = r.offset();
        let fc_hz = r.finite()?;
        if fc_hz <= 0.0 {
            return Err(corrupt(at, "snapshot holds a corner frequency <= 0 Hz"));
        }
        let mut creep_gain = [0.0; MAX_CREEP];
        for g in creep_gain.iter_mut() {
            *g = r.finite()?;
        }
        Ok(Estimates { params, fc_hz, creep_gain })
    }

    fn read_vector(r: &mut Reader<'_>) -> Result<ParamVector> {
        let mut v = ParamVector::zeros();
        for x in v.iter_mut() {
            *x = r.finite()?;
        }
        Ok(v)
    }

    impl Snapshot for OutputErrorIdentifier {
        fn to_bytes(&self) -> Vec<u8> {
            let OutputErrorIdentifier {
                config,
                dt,
                init,
                h0,
                est,
                shape,
                scales: _,
                active: _,
                chain,
                u_prev,
                p,
                status,
            } = self;
            let mut w = Writer::new(KIND_RPEM);
            let OutputErrorConfig {
                forgetting,
                memory_travel_v,
                p0,
                offset_walk_um,
                p0_effects,
                noise_um2,
                max_trace,
                max_step,
                max_offset_step_um,
                n_bounds,
                margin,
                scales,
                creep_gain_scale_um_per_v,
                creep_gain_max_um_per_v,
                fc_bounds_hz,
            } = *config;
            w.f64s(&[
                forgetting,
                memory_travel_v,
                p0,
                offset_walk_um,
                p0_effects,
                noise_um2,
                max_trace,
                max_step,
                max_offset_step_um,
                n_bounds.0,
                n_bounds.1,
                margin,
                creep_gain_scale_um_per_v,
                creep_gain_max_um_per_v,
                fc_bounds_hz.0,
                fc_bounds_hz.1,
            ]);
            w.f64s(&scales);
            w.f64(*dt);
            w.f64(*h0);
            let Shape { lag, n_creep, creep_tau, creep_decay: _ } = *shape;
            w.u8(lag as u8);
            w.u64(n_creep as u64);
            w.f64s(&creep_tau[..n_creep.min(MAX_CREEP)]);
            write_estimates(&mut w, init);
            write_estimates(&mut w, est);
            let Chain { h, dh, ua, dua, creep, dcreep } = chain;
            w.f64(*h);
            w.f64s(dh.as_slice());
            w.f64(*ua);
            w.f64s(dua.as_slice());
            w.f64s(creep);
            for d in dcreep {
                w.f64s(d.as_slice());
            }
            w.opt_f64(*u_prev);
            w.f64s(p.as_slice());
            let OutputErrorStatus {
                samples,
                updated,
                step_limited,
                projected,
                trace_capped,
                restarted,
                innovation_um,
                trace,
            } = *status;
            w.u64(samples);
            for flag in [updated, step_limited, projected, trace_capped, restarted] {
                w.u8(flag as u8);
            }
            w.f64(innovation_um);
            w.f64(trace);
            w.finish()
        }

        fn from_bytes(bytes: &[u8]) -> Result<Self> {
            let mut r = Reader::new(bytes, KIND_RPEM)?;
            let config_at = r.offset();
            let c = r.f64s::<16>()?;
            let scales = r.f64s::<NUM_BASE>()?;
            let config = OutputErrorConfig {
                forgetting: c[0],
                memory_travel_v: c[1],
                p0: c[2],
                offset_walk_um: c[3],
                p0_effects: c[4],
                noise_um2: c[5],
                max_trace: c[6],
                max_step: c[7],
                max_offset_step_um: c[8],
                n_bounds: (c[9], c[10]),
                margin: c[11],
                creep_gain_scale_um_per_v: c[12],
                creep_gain_max_um_per_v: c[13],
                fc_bounds_hz: (c[14], c[15]),
                scales,
            };
            let dt = r.f64()?;
            let h0 = r.finite()?;
            let lag = r.bool()?;
            let at = r.offset();
            let n_creep = r.u64()?;
            if n_creep > MAX_CREEP as u64 {
                return Err(corrupt(at, "snapshot declares more creep elements than the method identifies"));
            }
            let n_creep = n_creep as usize;
            let mut creep_tau = [1.0; MAX_CREEP];
            for tau in creep_tau.iter_mut().take(n_creep) {
                *tau = r.finite()?;
            }
            let init = read_estimates(&mut r)?;
            let est = read_estimates(&mut r)?;

            // The constructor validates dt, h0, the configuration and the effects,
            // and rebuilds the derived constants; its error is reported as a corrupt
            // snapshot (the values were valid when they were written).
            let effects = EffectSet {
                input_lag: lag.then_some(InputLag { fc_hz: init.fc_hz }),
                creep: (n_creep > 0).then(|| Creep {
                    tau_s: creep_tau[..n_creep].to_vec(),
                    gain_um_per_v: init.creep_gain[..n_creep].to_vec(),
                }),
                ..EffectSet::none()
            };
            let mut id = OutputErrorIdentifier::with_effects(dt, init.params, &effects, h0, config)
                .map_err(|_| corrupt(config_at, "snapshot holds an invalid configuration, time step or effect"))?;
            // Stored as they were held (the constructor's projection of the starting
            // values is not repeated: projecting twice may move a rounding bit). The
            // effects' estimates must lie where the recursion keeps them: fc within
            // `fc_bounds_hz`, each creep gain strictly within (0, gmax) (its logistic
            // coordinate is finite there).
            let (fc_lo, fc_hi) = config.fc_bounds_hz;
            let gmax = config.creep_gain_max_um_per_v;
            for e in [&init, &est] {
                if lag && !(fc_lo..=fc_hi).contains(&e.fc_hz) {
                    return Err(corrupt(config_at, "snapshot holds a corner frequency outside fc_bounds_hz"));
                }
                if e.creep_gain[..n_creep].iter().any(|&g| !(g > 0.0 && g < gmax)) {
                    return Err(corrupt(config_at, "snapshot holds a creep gain outside (0, creep_gain_max_um_per_v)"));
                }
            }
            id.init = init;
            id.est = est;

            let h = r.finite()?;
            let dh = read_vector(&mut r)?;
            let ua = r.finite()?;
            let dua = read_vector(&mut r)?;
            let mut creep = [0.0; MAX_CREEP];
            for s in creep.iter_mut() {
                *s = r.finite()?;
            }
            let mut dcreep = [ParamVector::zeros(); MAX_CREEP];
            for d in dcreep.iter_mut() {
                *d = read_vector(&mut r)?;
            }
            id.chain = Chain { h, dh, ua, dua, creep, dcreep };
            id.u_prev = r.opt_f64()?;
            let p_at = r.offset();
            let mut p = Covariance::zeros();
            for v in p.iter_mut() {
                *v = r.finite()?;
            }
            if p.diagonal().iter().any(|&v| v < 0.0) {
                return Err(corrupt(p_at, "snapshot holds a covariance with a negative variance"));
            }
            id.p = p;
            let at = r.offset();
            let samples = r.u64()?;
            let mut flags = [false; 5];
            for f in flags.iter_mut() {
                *f = r.bool()?;
            }
            let innovation_um = r.f64()?;
            let trace = r.f64()?;
            r.end()?;
            if (samples == 0) != id.u_prev.is_none() {
                return Err(corrupt(at, "sample count does not match the stored previous input"));
            }
            let [updated, step_limited, projected, trace_capped, restarted] = flags;
            id.status = OutputErrorStatus {
                samples,
                updated,
                step_limited,
                projected,
                trace_capped,
                restarted,
                innovation_um,
                trace,
            };
            Ok(id)
        }
    }

    #[cfg(test)]
    mod tests {
        use super::*;
        use crate::identify::AnyIdentifier;
        use crate::model::{paper_input, simulate};

        fn record() -> (Vec<f64>, Vec<f64>) {
            let dt = 1e-4;
            let u: Vec<f64> = paper_input(dt, 0.0)[..6_000].to_vec();
            let (mut x, _) = simulate(&Params::paper_1hz(), &u, dt, 0.0, None).unwrap();
            for (k, v) in x.iter_mut().enumerate() {
                *v += 1e-3 * ((k as f64 * 0.37).sin() + (k as f64 * 1.91).cos());
            }
            (u, x)
        }

        fn identifiers() -> Vec<OutputErrorIdentifier> {
            let dt = 1e-4;
            let p = Params { n: 1.7, ..Params::paper_1hz() };
            let effects = EffectSet {
                input_lag: Some(InputLag { fc_hz: 800.0 }),
                creep: Some(Creep { tau_s: vec![0.01, 0.3], gain_um_per_v: vec![0.001, 0.0005] }),
                ..EffectSet::none()
            };
            let cfg = OutputErrorConfig { memory_travel_v: 500.0, offset_walk_um: 0.02, ..Default::default() };
            vec![
                OutputErrorIdentifier::new(dt, p, 0.05, OutputErrorConfig::default()).unwrap(),
                OutputErrorIdentifier::with_effects(dt, p, &effects, 0.0, cfg).unwrap(),
            ]
        }

        #[test]
        fn restored_identifier_continues_bit_for_bit() {
            let (u, x) = record();
            for fresh in identifiers() {
                for cut in [0, 1, 2, 3, 777, 4_000] {
                    let mut original = fresh.clone();
                    for k in 0..cut {
                        original.push(u[k], x[k]).unwrap();
                    }
                    let bytes = original.to_bytes();
                    let mut restored = OutputErrorIdentifier::from_bytes(&bytes).unwrap();
                    assert_eq!(restored, original, "cut {cut}");
                    assert_eq!(restored.to_bytes(), bytes, "cut {cut}");
                    for k in cut..u.len() {
                        let a = original.push(u[k], x[k]).unwrap();
                        let b = restored.push(u[k], x[k]).unwrap();
                        assert_eq!(a.to_bits(), b.to_bits(), "cut {cut}, sample {k}");
                    }
                    assert_eq!(restored, original);
                    // And through the run-time choice of method.
                    let any = AnyIdentifier::OutputError(original.clone());
                    let back = AnyIdentifier::from_snapshot(&any.to_snapshot().unwrap()).unwrap();
                    assert_eq!(back, any);
                }
            }
        }

        #[test]
        fn corrupt_snapshots_are_errors_naming_snapshot() {
            let (u, x) = record();
            for mut id in identifiers() {
                for k in 0..500 {
                    id.push(u[k], x[k]).unwrap();
                }
                let bytes = id.to_bytes();
                let names_snapshot = |e: Error| matches!(e, Error::InvalidConfig { name: "snapshot", .. });
                for cut in 0..bytes.len() {
                    let err = OutputErrorIdentifier::from_bytes(&bytes[..cut]).unwrap_err();
                    assert!(names_snapshot(err), "cut {cut}");
                }
                let mut longer = bytes.clone();
                longer.push(0);
                assert!(names_snapshot(OutputErrorIdentifier::from_bytes(&longer).unwrap_err()));
                // A NaN in the covariance, a forgetting factor of 2, a paper snapshot.
                let mut bad = bytes.clone();
                let p_start = bytes.len() - (8 + 5 + 16) - NUM_PARAMS * NUM_PARAMS * 8;
                bad[p_start..p_start + 8].copy_from_slice(&f64::NAN.to_bits().to_le_bytes());
                assert!(names_snapshot(OutputErrorIdentifier::from_bytes(&bad).unwrap_err()));
                let mut bad = bytes.clone();
                bad[6..14].copy_from_slice(&2.0f64.to_bits().to_le_bytes());
                assert!(names_snapshot(OutputErrorIdentifier::from_bytes(&bad).unwrap_err()));
                let mut other_kind = bytes.clone();
                other_kind[5] = crate::snapshot::KIND_PAPER;
                assert!(AnyIdentifier::from_snapshot(&other_kind).is_err());
                // Every single flipped bit: an error or a valid identifier, never a panic.
                for i in 0..bytes.len() {
                    for bit in [0, 3, 6, 7] {
                        let mut flipped = bytes.clone();
                        flipped[i] ^= 1 << bit;
                        if let Ok(mut r) = OutputErrorIdentifier::from_bytes(&flipped) {
                            for k in 500..520 {
                                let _ = r.push(u[k], x[k]);
                            }
                        }
                    }
                }
            }
        }
    }
}
