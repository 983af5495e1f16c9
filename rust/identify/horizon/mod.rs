//! Moving-horizon output-error identification ("horizon"): the paper's limited-memory
//! least squares, applied to the model's *output* (simulation) error and spread over
//! the samples so that every push costs about the same.
//!
//! The window holds the newest samples over which the input has travelled
//! `memory_travel_v` volts (one and a half periods of the paper's 0–100 V sine by
//! default, at any frequency). Its cost is the output error of the model simulated open loop over the
//! window from an initial state h_s, a free unknown like the seven parameters:
//!
//! ```text
//! J(θ, h_s) = Σ_{k in window} (x_k − kv·u_k − x0 − h_k(θ, h_s))²,   θ = (kv, x0, A, β, γ, n, δ)
//! ```
//!
//! Per sample:
//! 1. **Predict** x̂ₖ = kv·uₖ + x0 + hₖ with the current estimates, h advanced by the
//!    model's own integrator from the previous sample (this is the model the caller
//!    uses; it is never reset from the measurement).
//! 2. **Store** the sample; the window's start moves on as the travel grows.
//! 3. **Pass.** A simulation of the window with the current estimates runs
//!    `samples_per_push` samples further, on dual numbers ([`crate::model::advance`]),
//!    accumulating the Gauss–Newton normal equations JᵀJ, Jᵀr over the 8 unknowns.
//!    When it has caught up with the newest sample (and spans at least
//!    `min_pass_fraction` of the memory), one Levenberg–Marquardt step is taken in
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
//! Worst case per push: one integration interval for the prediction and
//! `samples_per_push` on 6-derivative duals (each bounded by the integrator's 32
//! sub-steps), plus, on the push that ends a pass, an 8 × 8 Cholesky solve. The
//! window buffer is the one allocation (at construction, `max_window` samples).
//! Starting values are used as given (n < 1 included; the sensitivities are
//! regularised at h = 0, see [`crate::model::scalar::SLOPE_FLOOR_UM`]).

mod config;
mod snapshot;

pub use config::{HorizonConfig, HorizonStatus};

use alloc::vec::Vec;

use nalgebra::{SMatrix, SVector};

use super::OnlineIdentifier;
use crate::error::{finite_sample, positive_dt, Result};
use crate::math;
use crate::model::scalar::{Dual, Scalar};
use crate::model::{advance, advance_h, output, Coefficients, H_LIMIT_UM};
use crate::params::Params;

/// Unknowns of the window fit: kv, x0, A, β, γ, n, δ and the window's initial h.
const NZ: usize = 8;
/// Derivatives carried through the integrator: A, β, γ, n, δ and the initial h.
const ND: usize = 6;

type Normal = SMatrix<f64, NZ, NZ>;
type Vector = SVector<f64, NZ>;

/// One stored sample: u \[V\], x \[µm\], the input travel up to it \[V\], and the h of the
/// last pass there with its derivatives over (A, β, γ, n, δ, h_s).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Entry {
    u: f64,
    x: f64,
    travel: f64,
    h: f64,
    dh: [f64; ND],
}

/// A simulation of the window in progress.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Pass {
    /// Absolute index of the pass's first sample.
    start: u64,
    /// Absolute index of the next sample to simulate.
    cursor: u64,
    /// Parameters the pass runs.
    params: Params,
    /// h at the pass's start \[µm\].
    h_start: f64,
    /// h and its derivatives at the last simulated sample.
    h: Dual<ND>,
    jtj: Normal,
    jtr: Vector,
    sse: f64,
    count: u64,
}

impl Pass {
    fn new(start: u64, params: Params, h_start: f64) -> Self {
        Pass {
            start,
            cursor: start,
            params,
            h_start,
            h: Dual::var(h_start, ND - 1),
            jtj: Normal::zeros(),
            jtr: Vector::zeros(),
            sse: 0.0,
            count: 0,
        }
    }
}

/// The moving-horizon identifier (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct HorizonIdentifier {
    config: HorizonConfig,
    dt: f64,
    init: Params,
    h0: f64,
    params: Params,
    /// The model's h at the last sample (the prediction's state).
    h: f64,
    u_prev: Option<f64>,
    /// Ring buffer of the newest samples, `max_window` slots.
    buffer: Vec<Entry>,
    /// Absolute index of the next sample (= samples pushed).
    next: u64,
    /// Absolute index of the window's first sample.
    start: u64,
    pass: Pass,
    /// Mean squared error of the last finished pass \[µm²\] (∞ before the first).
    last_mse: f64,
    damping: f64,
    status: HorizonStatus,
}

impl HorizonIdentifier {
    /// An identifier for samples every `dt` \[s\], starting from `init` (used as given)
    /// with model state `h0` \[µm\].
    pub fn new(dt: f64, init: Params, h0: f64, config: HorizonConfig) -> Result<Self> {
        positive_dt(dt)?;
        init.validate()?;
        config.validate()?;
        finite_sample("h0", h0)?;
        let mut buffer = Vec::new();
        buffer.resize(config.max_window, Entry::default());
        Ok(HorizonIdentifier {
            config,
            dt,
            init,
            h0,
            params: init,
            h: h0,
            u_prev: None,
            buffer,
            next: 0,
            start: 0,
            pass: Pass::new(0, init, h0),
            last_mse: f64::INFINITY,
            damping: config.damping,
            status: HorizonStatus { damping: config.damping, ..HorizonStatus::default() },
        })
    }

    /// The tuning in use.
    pub fn config(&self) -> &HorizonConfig {
        &self.config
    }

    fn slot(&self, k: u64) -> usize {
        (k % self.buffer.len() as u64) as usize
    }

    fn entry(&self, k: u64) -> &Entry {
        &self.buffer[self.slot(k)]
    }

    /// Simulates the pass one sample further and accumulates the normal equations.
    #[inline]
    fn pass_step(&mut self) {
        let k = self.pass.cursor;
        let e = *self.entry(k);
        let p = self.pass.params;
        if k > self.pass.start {
            let u0 = self.entry(k - 1).u;
            let c = Coefficients {
                a: Dual::var(p.a, 0),
                beta: Dual::var(p.beta, 1),
                gamma: Dual::var(p.gamma, 2),
                n: Dual::var(p.n, 3),
                delta: Dual::var(p.delta, 4),
            };
            self.pass.h = advance(&p, &c, self.pass.h, Dual::cst(u0), Dual::cst(e.u), self.dt);
        }
        let h = self.pass.h;
        let residual = e.x - output(&p, e.u, h.re);
        let s = &self.config.scales;
        let mut psi = Vector::zeros();
        psi[0] = e.u * s[0];
        psi[1] = s[1];
        for i in 0..ND {
            psi[2 + i] = h.du[i] * s[2 + i];
        }
        if residual.is_finite() && psi.iter().all(|v| v.is_finite()) {
            self.pass.jtj.syger(1.0, &psi, &psi, 1.0);
            self.pass.jtr.axpy(residual, &psi, 1.0);
            self.pass.sse += residual * residual;
            self.pass.count += 1;
        }
        let slot = self.slot(k);
        let entry = &mut self.buffer[slot];
        entry.h = h.re;
        entry.dh = h.du.into();
        self.pass.cursor += 1;
    }

    /// Ends the pass: one Levenberg–Marquardt step, then a new pass from the window's start.
    fn finish_pass(&mut self) {
        let cfg = self.config;
        let pass = self.pass;
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
        let step = a.cholesky().map(|ch| ch.solve(&pass.jtr));
        let mut status = HorizonStatus {
            rms_um: math::sqrt(mse),
            damping: self.damping,
            updates: self.status.updates,
            ..self.status
        };
        status.step_limited = false;
        status.projected = false;
        let mut delta = Vector::zeros();
        if let Some(mut step) = step.filter(|s| s.iter().all(|v| v.is_finite())) {
            let largest = step.amax();
            if largest > cfg.max_step {
                step *= cfg.max_step / largest;
                status.step_limited = true;
            }
            let mut theta = self.params.to_array();
            for (i, t) in theta.iter_mut().enumerate() {
                *t += step[i] * cfg.scales[i];
            }
            if let Ok(raw) = Params::from_array(theta) {
                let projected = super::project_well_posed(raw, cfg.n_bounds, cfg.margin);
                status.projected = projected != raw;
                let after = projected.to_array();
                for i in 0..7 {
                    delta[i] = after[i] - self.params.to_array()[i];
                }
                delta[7] = step[7] * cfg.scales[7];
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
        let last = *self.entry(self.next - 1);
        self.h = moved(last.h, &last.dh);
        let first = *self.entry(self.start);
        let h_start = moved(first.h, &first.dh);
        self.pass = Pass::new(self.start, self.params, h_start);
        self.status = status;
    }
}

impl OnlineIdentifier for HorizonIdentifier {
    type Status = HorizonStatus;

    fn push(&mut self, u: f64, x: f64) -> Result<f64> {
        finite_sample("u", u)?;
        finite_sample("x", x)?;
        // 1. Predict with the current estimates.
        if let Some(u0) = self.u_prev {
            self.h = advance_h(&self.params, self.h, u0, u, self.dt);
        }
        let prediction = output(&self.params, u, self.h);
        // 2. Store; move the window's start.
        let travel = match self.u_prev {
            Some(u0) if self.next > 0 => self.entry(self.next - 1).travel + (u - u0).abs(),
            _ => 0.0,
        };
        self.u_prev = Some(u);
        let k = self.next;
        let slot = self.slot(k);
        self.buffer[slot] = Entry { u, x, travel, h: self.h, dh: [0.0; ND] };
        self.next += 1;
        let cap = self.buffer.len() as u64;
        while self.next - self.start > cap
            || (self.next - self.start > 16
                && travel - self.entry(self.start + 1).travel >= self.config.memory_travel_v)
        {
            self.start += 1;
        }
        // 3. Run the pass on; end it when it has caught up and spans enough.
        self.status.updated = false;
        if self.pass.start < self.next.saturating_sub(cap) {
            // The pass's start has left the buffer (a long hold filled it): restart.
            let e = *self.entry(self.start);
            self.pass = Pass::new(self.start, self.params, e.h);
        }
        for _ in 0..self.config.samples_per_push {
            if self.pass.cursor >= self.next {
                break;
            }
            self.pass_step();
        }
        if self.pass.cursor >= self.next {
            let span_travel = travel - self.entry(self.pass.start).travel;
            let span = self.next - self.pass.start;
            if span_travel >= self.config.min_pass_fraction * self.config.memory_travel_v || span >= cap / 2 {
                self.finish_pass();
            }
        }
        self.status.samples = self.next;
        self.status.window_samples = self.next - self.start;
        self.status.window_travel_v = travel - self.entry(self.start).travel;
        Ok(prediction)
    }

    fn params(&self) -> Params {
        self.params
    }

    fn h(&self) -> f64 {
        self.h
    }

    fn status(&self) -> HorizonStatus {
        self.status
    }

    fn reset(&mut self) {
        let cfg = self.config;
        self.params = self.init;
        self.h = self.h0;
        self.u_prev = None;
        self.buffer.fill(Entry::default());
        self.next = 0;
        self.start = 0;
        self.pass = Pass::new(0, self.init, self.h0);
        self.last_mse = f64::INFINITY;
        self.damping = cfg.damping;
        self.status = HorizonStatus { damping: cfg.damping, ..HorizonStatus::default() };
    }
}
