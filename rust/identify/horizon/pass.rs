//! The window pass: the window simulated with the current estimates and its
//! sensitivities, the normal equations it accumulates, and the Levenberg–Marquardt step
//! (within the bounds of the well-posed region) that ends it.

use nalgebra::{SMatrix, SVector};

use super::{
    lag_of, lag_step_dual, HorizonConfig, HorizonIdentifier, HorizonStatus, Pending, I_LN_FC, LN_FC_SCALE, ND, NZ,
};
use super::{Normal, Vector};
use crate::effects::input_lag::LagStage;
use crate::math;
use crate::model::integrator::{advance_seeded_carrying, Drive, Power};
use crate::model::scalar::{Dual, Scalar};
use crate::model::{output, H_LIMIT_UM};
use crate::params::Params;

/// A simulation of the window in progress.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Pass {
    /// Absolute index of the pass's first sample.
    pub(super) start: u64,
    /// Absolute index of the next sample to simulate.
    pub(super) cursor: u64,
    /// Parameters the pass runs.
    pub(super) params: Params,
    /// h at the pass's start \[µm\].
    pub(super) h_start: f64,
    /// h and its derivatives at the last simulated sample.
    pub(super) h: Dual<ND>,
    /// |h|^n and ln|h| there, where the last interval's series carried them.
    pub(super) power: Option<Power>,
    /// u_a and its derivative over ln fc at the last simulated sample \[V\].
    pub(super) ua: Dual<ND>,
    /// The lag the pass runs (unused without the lag).
    pub(super) lag: LagStage,
    pub(super) jtj: Normal,
    pub(super) jtr: Vector,
    pub(super) sse: f64,
    pub(super) count: u64,
}

impl Pass {
    pub(super) fn new(start: u64, params: Params, h_start: f64, ua: f64, dua: f64, lag: LagStage) -> Self {
        let mut ua_dual = Dual::cst(ua);
        ua_dual.du[I_LN_FC - 2] = dua;
        Pass {
            start,
            cursor: start,
            params,
            h_start,
            h: Dual::var(h_start, 5),
            power: None,
            ua: ua_dual,
            lag,
            jtj: Normal::zeros(),
            jtr: Vector::zeros(),
            sse: 0.0,
            count: 0,
        }
    }
}

/// Scale of unknown `i` in the update.
fn scale(cfg: &HorizonConfig, i: usize) -> f64 {
    if i == I_LN_FC {
        LN_FC_SCALE
    } else {
        cfg.scales[i]
    }
}

/// Rows of the constraints the step may have to meet: n at a bound, β + γ and β − γ at
/// the margin.
const NC: usize = 3;

/// The Gauss–Newton step (in scaled coordinates) of the normal equations `ch`, `g`,
/// subject to the bounds of the well-posed region: constraints the free step would
/// break are made active (held on their boundary) and the step is solved again on
/// the rest, up to [`NC`] times. Clamping a coordinate after the solve would instead
/// keep the moves of the others that assumed it had moved (and stall against a bound).
/// Returns the step and whether a constraint was made active (the step held).
fn constrained_step(
    ch: &nalgebra::Cholesky<f64, nalgebra::Const<NZ>>,
    g: &Vector,
    p: &Params,
    cfg: &HorizonConfig,
) -> (Vector, bool) {
    let s = &cfg.scales;
    let free = ch.solve(g);
    let mut active = [false; NC];
    let mut step = free;
    for _ in 0..NC {
        let n_new = p.n + s[5] * step[5];
        let (b, c) = (p.beta + s[3] * step[3], p.gamma + s[4] * step[4]);
        let broken = [n_new < cfg.n_bounds.0 || n_new > cfg.n_bounds.1, b + c < cfg.margin, b - c < cfg.margin];
        let mut added = false;
        for i in 0..NC {
            if broken[i] && !active[i] {
                active[i] = true;
                added = true;
            }
        }
        if !added {
            break;
        }
        // Rows C z = d of the active constraints (inactive rows are zero).
        let mut cm = SMatrix::<f64, NC, NZ>::zeros();
        let mut d = SVector::<f64, NC>::zeros();
        if active[0] {
            let bound = if p.n + s[5] * free[5] < cfg.n_bounds.0 { cfg.n_bounds.0 } else { cfg.n_bounds.1 };
            cm[(0, 5)] = 1.0;
            d[0] = (bound - p.n) / s[5];
        }
        if active[1] {
            cm[(1, 3)] = s[3];
            cm[(1, 4)] = s[4];
            d[1] = cfg.margin - p.beta - p.gamma;
        }
        if active[2] {
            cm[(2, 3)] = s[3];
            cm[(2, 4)] = -s[4];
            d[2] = cfg.margin - p.beta + p.gamma;
        }
        // z = free − A⁻¹Cᵀλ with (C A⁻¹ Cᵀ) λ = C·free − d; inactive rows get λ = 0.
        let ainv_ct = ch.solve(&cm.transpose());
        let mut schur = cm * ainv_ct;
        let mut rhs = cm * free - d;
        for i in 0..NC {
            if !active[i] {
                schur[(i, i)] = 1.0;
                rhs[i] = 0.0;
            }
        }
        match schur.lu().solve(&rhs) {
            Some(lambda) => step = free - ainv_ct * lambda,
            None => break,
        }
    }
    (step, active.iter().any(|&a| a))
}

impl HorizonIdentifier {
    /// Simulates the pass one sample further and accumulates the normal equations;
    /// `slot` is the slot of the pass's cursor and `before` that of the sample before it.
    #[inline]
    fn pass_step(&mut self, slot: usize, before: usize) {
        let k = self.pass.cursor;
        let e = self.buffer[slot];
        let p = self.pass.params;
        if k > self.pass.start {
            let u0 = self.buffer[before].u;
            let ua0 = self.pass.ua;
            let ua1 = if self.ln_fc.is_some() {
                lag_step_dual(&self.pass.lag, ua0, u0, e.u, self.dt)
            } else {
                Dual::cst(e.u)
            };
            (self.pass.h, self.pass.power) = advance_seeded_carrying::<ND, 0, { I_LN_FC - 2 }>(
                &p,
                self.pass.h,
                self.pass.power,
                ua0,
                ua1,
                self.dt,
                None,
                Drive::of(u0, e.u),
            );
            self.pass.ua = ua1;
        }
        let h = self.pass.h;
        let ua = self.pass.ua;
        let residual = e.x - output(&p, ua.re, h.re);
        let s = &self.config.scales;
        let mut psi = Vector::zeros();
        psi[0] = ua.re * s[0];
        psi[1] = s[1];
        for i in 0..ND - 1 {
            psi[2 + i] = h.du[i] * s[2 + i];
        }
        psi[I_LN_FC] = (h.du[I_LN_FC - 2] + p.kv * ua.du[I_LN_FC - 2]) * LN_FC_SCALE;
        if residual.is_finite() && psi.as_slice().iter().all(|v| v.is_finite()) {
            self.pass.jtj.syger(1.0, &psi, &psi, 1.0);
            self.pass.jtr.axpy(residual, &psi, 1.0);
            self.pass.sse += residual * residual;
            self.pass.count += 1;
        }
        let entry = &mut self.buffer[slot];
        entry.h = h.re;
        entry.dh = h.du.into();
        entry.ua = ua.re;
        entry.dua = ua.du[I_LN_FC - 2];
        self.pass.cursor += 1;
    }

    /// Runs the pass at most `samples` samples on, not beyond the newest.
    pub(super) fn run_pass(&mut self, samples: usize) {
        self.run_pass_to(self.next, samples);
    }

    /// Runs the pass at most `samples` samples on, not beyond absolute index `end`
    /// (exclusive, at most the newest sample's index + 1).
    pub(super) fn run_pass_to(&mut self, end: u64, samples: usize) {
        if self.pass.cursor >= end {
            return;
        }
        let mut slot = self.slot(self.pass.cursor);
        let mut before = if slot == 0 { self.buffer.len() - 1 } else { slot - 1 };
        for _ in 0..samples {
            if self.pass.cursor >= end {
                break;
            }
            self.pass_step(slot, before);
            before = slot;
            slot = self.following(slot);
        }
    }

    /// Ends the pass: one Levenberg–Marquardt step, then a new pass from the window's
    /// start. The pass ends at its cursor: the newest sample in sync mode, where the
    /// update is adopted at once; in cooperative mode an update of a pass that ended
    /// before the newest sample is kept pending (see [`Pending`]).
    pub(super) fn finish_pass(&mut self) {
        let cfg = self.config;
        let pass = self.pass;
        let end = pass.cursor;
        let before = (self.params, self.ln_fc, self.lag, self.h, self.ua);
        let mse = pass.sse / pass.count.max(1) as f64;
        self.damping =
            if mse > 1.1 * self.last_mse { (self.damping * 4.0).min(1e6) } else { (self.damping * 0.5).max(1e-9) };
        self.last_mse = mse;
        let mut a = pass.jtj;
        let mean_diag = a.trace() / NZ as f64;
        for i in 0..NZ {
            a[(i, i)] += self.damping * a[(i, i)] + cfg.ridge * mean_diag + f64::MIN_POSITIVE;
        }
        // Lower triangle only was accumulated by `syger`; mirror it.
        a.fill_upper_triangle_with_lower_triangle();
        let step = a.cholesky().map(|ch| constrained_step(&ch, &pass.jtr, &self.params, &cfg));
        let mut status = HorizonStatus {
            rms_um: math::sqrt(mse),
            damping: self.damping,
            updates: self.status.updates,
            ..self.status
        };
        status.step_limited = false;
        status.projected = false;
        status.held = false;
        let mut delta = Vector::zeros();
        if let Some((mut step, held)) = step.filter(|(s, _)| s.iter().all(|v| v.is_finite())) {
            status.held = held;
            // Trust region: no parameter moves by more than `max_step` times its own
            // size (its scale where it is smaller), so that large parameters can travel
            // geometrically fast while small ones stay careful.
            let mut theta = self.params.to_array();
            let mut largest = 0.0_f64;
            for i in 0..NZ {
                let size = if i < 7 { theta[i].abs().max(cfg.scales[i]) } else { scale(&cfg, i) };
                largest = largest.max(step[i].abs() * scale(&cfg, i) / size);
            }
            if largest > cfg.max_step {
                step *= cfg.max_step / largest;
                status.step_limited = true;
            }
            for (i, t) in theta.iter_mut().enumerate() {
                *t += step[i] * cfg.scales[i];
            }
            if let Ok(raw) = Params::from_array(theta) {
                let projected = crate::identify::project_well_posed(raw, cfg.n_bounds, cfg.margin);
                status.projected = projected != raw;
                let after = projected.to_array();
                for i in 0..7 {
                    delta[i] = after[i] - self.params.to_array()[i];
                }
                delta[7] = step[7] * cfg.scales[7];
                if let Some(ln_fc) = self.ln_fc {
                    let (lo, hi) = cfg.fc_bounds_hz;
                    let moved = (ln_fc + step[I_LN_FC] * LN_FC_SCALE).clamp(math::ln(lo), math::ln(hi));
                    delta[I_LN_FC] = moved - ln_fc;
                    self.ln_fc = Some(moved);
                    self.lag = lag_of(math::exp(moved), self.dt);
                }
                self.params = projected;
                status.updated = true;
                status.updates += 1;
            }
        }
        // The model's h now, and the window's new start, moved to first order.
        let moved = |h: f64, dh: &[f64; ND]| -> f64 {
            let mut v = h;
            for i in 0..ND {
                v += dh[i] * delta[2 + i];
            }
            if v.is_finite() {
                v.clamp(-H_LIMIT_UM, H_LIMIT_UM)
            } else {
                h
            }
        };
        let last = *self.entry(end - 1);
        self.h = moved(last.h, &last.dh);
        let first = *self.entry(self.start);
        let h_start = moved(first.h, &first.dh);
        let (ua_start, dua_start) = if self.ln_fc.is_some() {
            self.ua = last.ua + last.dua * delta[I_LN_FC];
            (first.ua + first.dua * delta[I_LN_FC], first.dua)
        } else {
            (first.u, 0.0)
        };
        self.pass = Pass::new(self.start, self.params, h_start, ua_start, dua_start, self.lag);
        self.pass_end = self.next;
        if end < self.next {
            // Newer samples were pushed with the estimates from before: the update is
            // carried to the newest sample first, then adopted (see `carry_pending`).
            let ua = if self.ln_fc.is_some() { self.ua } else { last.u };
            let (params, ln_fc, h) = (self.params, self.ln_fc, self.h);
            self.pending = Some(Pending { at: end - 1, params, ln_fc, h, ua, fitted: end });
            (self.params, self.ln_fc, self.lag, self.h, self.ua) = before;
            status.updates = self.status.updates;
            status.updated = false;
        } else {
            self.fitted = end;
        }
        self.status = status;
    }
}
