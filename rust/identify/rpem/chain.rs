//! The model the identifier runs: h through the one integrator on dual numbers (value
//! and ∂h/∂θ in one pass), and the effect chain u → u_a → (h, creep) → x with its
//! sensitivities.

use nalgebra::SVector;

use super::*;
use crate::effects::{first_order_coefficient, first_order_step, InputLag};
use crate::model::integrator::{advance_seeded, Drive};
use crate::model::output;
use crate::model::scalar::Dual;

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
    advance_with_substeps(p, h, dh, u0, u1, dt, None, Drive::of(u0.0, u1.0))
}

/// [`advance_h_with_gradient`] with the number of RK4 sub-steps optionally forced.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn advance_with_substeps<const M: usize>(
    p: &Params,
    h: f64,
    dh: &SVector<f64, M>,
    (u0, du0): (f64, &SVector<f64, M>),
    (u1, du1): (f64, &SVector<f64, M>),
    dt: f64,
    forced: Option<u32>,
    drive: Drive,
) -> (f64, SVector<f64, M>) {
    // A, β, γ, n, δ are consecutive in θ.
    const _: () = assert!(I_BETA == I_A + 1 && I_GAMMA == I_A + 2 && I_N == I_A + 3 && I_DELTA == I_A + 4);
    let (h, u0, u1) = (Dual::new(h, *dh), Dual::new(u0, *du0), Dual::new(u1, *du1));
    // The voltages' derivatives are in the lag's slot (beyond M = 7 without effects).
    let r = advance_seeded::<M, I_A, I_LN_FC>(p, h, u0, u1, dt, forced, drive);
    (r.re, r.du)
}

/// Current estimates: the base parameters and those of the effects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Estimates {
    pub(super) params: Params,
    /// Corner frequency of the input lag \[Hz\] (unused without the lag).
    pub(super) fc_hz: f64,
    /// Creep gains g_i \[µm/V\] (the first `n_creep` are used).
    pub(super) creep_gain: [f64; MAX_CREEP],
}

#[cfg(test)]
impl Estimates {
    pub(super) fn to_theta(self) -> ParamVector {
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

    pub(super) fn from_theta(t: &ParamVector, lag: bool, before: &Estimates) -> Result<Self> {
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
pub(super) struct Shape {
    pub(super) lag: bool,
    pub(super) n_creep: usize,
    pub(super) creep_tau: [f64; MAX_CREEP],
    pub(super) creep_decay: [f64; MAX_CREEP],
}

/// The model's state and its sensitivities ∂/∂θ (unscaled).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Chain {
    pub(super) h: f64,
    pub(super) dh: ParamVector,
    /// Voltage on the stack u_a \[V\] (= u without the lag).
    pub(super) ua: f64,
    pub(super) dua: ParamVector,
    /// Unit-gain creep elements sᵢ (τᵢ·ṡᵢ = u_a − sᵢ); cᵢ = gᵢ·sᵢ, so that a new
    /// gain acts on the whole history at once.
    pub(super) creep: [f64; MAX_CREEP],
    /// ∂sᵢ/∂θ.
    pub(super) dcreep: [ParamVector; MAX_CREEP],
}

impl Chain {
    pub(super) fn new(h0: f64) -> Self {
        Chain {
            h: h0,
            dh: ParamVector::zeros(),
            ua: 0.0,
            dua: ParamVector::zeros(),
            creep: [0.0; MAX_CREEP],
            dcreep: [ParamVector::zeros(); MAX_CREEP],
        }
    }

    pub(super) fn is_finite(&self) -> bool {
        self.dh.as_slice().iter().chain(self.dua.as_slice()).all(|v| v.is_finite())
            && self.dcreep.iter().all(|d| d.as_slice().iter().all(|v| v.is_finite()))
    }

    /// [`Chain::step`] without effects (u_a = u, no creep), with ∂x̂/∂θ over the
    /// base parameters only: the same values, without the work on the effect slots.
    #[inline]
    pub(super) fn step_base(
        &mut self,
        p: &Params,
        u_prev: Option<f64>,
        u: f64,
        dt: f64,
    ) -> (f64, SVector<f64, NUM_BASE>) {
        match u_prev {
            None => {
                self.ua = u;
                self.dua = ParamVector::zeros();
            }
            Some(_) => {
                let ua0 = self.ua;
                self.ua = u;
                let zero = SVector::<f64, NUM_BASE>::zeros();
                let dh = SVector::<f64, NUM_BASE>::from_fn(|i, _| self.dh[i]);
                let (h, dh) = advance_h_with_gradient(p, self.h, &dh, (ua0, &zero), (u, &zero), dt);
                self.h = h;
                self.dh.as_mut_slice()[..NUM_BASE].copy_from_slice(dh.as_slice());
            }
        }
        let mut psi = SVector::<f64, NUM_BASE>::from_fn(|i, _| self.dh[i]);
        psi[I_KV] += self.ua;
        psi[I_X0] += 1.0;
        (output(p, self.ua, self.h), psi)
    }

    /// Advances the chain to the sample `u` (the first sample when `u_prev` is None),
    /// in the order of [`crate::effects::ExtendedModel::step`]: lag, h, creep. Returns
    /// x̂ = kv·u_a + x0 + h + Σcᵢ \[µm\] and ψ = ∂x̂/∂θ.
    #[inline]
    pub(super) fn step(
        &mut self,
        est: &Estimates,
        shape: &Shape,
        u_prev: Option<f64>,
        u: f64,
        dt: f64,
    ) -> (f64, ParamVector) {
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
                // The δ term follows the command ([`Drive`]), not the lagged voltage.
                (self.h, self.dh) = advance_with_substeps(
                    p,
                    self.h,
                    &self.dh,
                    (ua0, &dua0),
                    (self.ua, &self.dua),
                    dt,
                    None,
                    Drive::of(u0, u),
                );
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
