//! The simulated output and its Jacobian with respect to the unknowns of a fit, in one
//! pass: the chain of [`super::ExtendedModel`] run on [`Dual`] numbers (forward-mode
//! automatic differentiation through the same integrator and stages, so the Jacobian is
//! that of the discrete map the simulator computes, and the output is the simulator's
//! to the last bit).
//!
//! The unknowns (the Jacobian's columns), in this order: kv, x0, A, β, γ, n, δ, h0, then
//! for each effect present, in signal-chain order, the creep gains g_i, the input lag's
//! ln fc, the gain_drift rate, the electrostriction ε, the resonance's ln fn and ln ζ,
//! the second resonance's ln fn and ln ζ, the drift rate, the pickup's sine amplitudes
//! then its cosine amplitudes, the saturation's min and max. The creep time constants
//! and the delay are not unknowns. Frequencies and damping ratios enter by their
//! logarithms, as the fits take them.

use alloc::vec;
use alloc::vec::Vec;

use super::chain::{Chain, Slots, FIXED_SLOTS, SLOT_H0, SLOT_KV, SLOT_LN_FC, SLOT_X0};
use super::{record_path, EffectSet};
use crate::error::{finite_sample, positive_dt, Result};
use crate::model::scalar::Dual;
use crate::params::Params;
use crate::reconstruction::InputPath;

/// The output of a record and its Jacobian.
#[derive(Debug, Clone, PartialEq)]
pub struct Jacobian {
    /// The simulated displacement x \[µm\], one value per sample.
    pub x: Vec<f64>,
    /// Number of unknowns (columns).
    pub columns: usize,
    /// ∂x\[k\]/∂θ_j at `values[k * columns + j]` (row-major; units of x per unit of θ_j).
    pub values: Vec<f64>,
}

/// The derivative slot of each column, in column order.
fn column_slots(effects: &EffectSet, slots: &Slots) -> Vec<usize> {
    let mut cols = vec![SLOT_KV, SLOT_X0, 0, 1, 2, 3, 4, SLOT_H0];
    let creep = effects.creep.as_ref().map_or(0, |c| c.tau_s.len());
    cols.extend(slots.creep..slots.creep + creep);
    if effects.input_lag.is_some() {
        cols.push(SLOT_LN_FC);
    }
    cols.extend(slots.gain_drift..slots.total);
    cols
}

/// Number of unknowns of a fit of the base model with `effects`.
pub fn unknowns(effects: &EffectSet) -> usize {
    column_slots(effects, &Slots::of(effects)).len()
}

/// [`super::simulate_extended`] with the Jacobian of x with respect to the unknowns
/// (module docs). Input with a non-finite value, invalid parameters or effects are
/// rejected before anything is computed.
pub fn simulate_extended_with_jacobian(
    params: &Params,
    effects: &EffectSet,
    u: &[f64],
    dt: f64,
    h0: f64,
) -> Result<Jacobian> {
    params.validate()?;
    effects.validate()?;
    positive_dt(dt)?;
    finite_sample("h0", h0)?;
    let path = record_path(effects, u)?;
    let path = path.as_ref();
    let slots = Slots::of(effects);
    let cols = column_slots(effects, &slots);
    // The widths the chain is built for (each slot costs every operation of the pass);
    // 50 slots at most (16 creep elements, 8 pickup harmonics and every other effect).
    match slots.total {
        0..=10 => run::<10>(params, effects, (u, path), dt, h0, &slots, &cols),
        11..=13 => run::<13>(params, effects, (u, path), dt, h0, &slots, &cols),
        14..=16 => run::<16>(params, effects, (u, path), dt, h0, &slots, &cols),
        17..=20 => run::<20>(params, effects, (u, path), dt, h0, &slots, &cols),
        21..=26 => run::<26>(params, effects, (u, path), dt, h0, &slots, &cols),
        27..=34 => run::<34>(params, effects, (u, path), dt, h0, &slots, &cols),
        _ => run::<50>(params, effects, (u, path), dt, h0, &slots, &cols),
    }
}

/// [`crate::simulate`] from h\[0\] = `h0` with the Jacobian of x with respect to kv, x0,
/// A, β, γ, n, δ and h0 (in this order): the base model is the chain without effects.
pub fn simulate_with_jacobian(params: &Params, u: &[f64], dt: f64, h0: f64) -> Result<Jacobian> {
    simulate_extended_with_jacobian(params, &EffectSet::none(), u, dt, h0)
}

/// The pass on duals of width `M` (≥ `slots.total`) over the commands `u` and, where the
/// input is band-limited between samples, their path.
fn run<const M: usize>(
    params: &Params,
    effects: &EffectSet,
    (u, path): (&[f64], Option<&InputPath>),
    dt: f64,
    h0: f64,
    slots: &Slots,
    cols: &[usize],
) -> Result<Jacobian> {
    debug_assert!(slots.total <= M && FIXED_SLOTS <= M);
    let mut chain = Chain::<Dual<M>>::new(*params, effects, dt, h0, slots)?;
    let mut x = Vec::with_capacity(u.len());
    let mut values = Vec::with_capacity(u.len() * cols.len());
    for (k, &v) in u.iter().enumerate() {
        let out = chain.step_along(v, path, k);
        x.push(out.re);
        values.extend(cols.iter().map(|&s| out.du[s]));
    }
    Ok(Jacobian { x, columns: cols.len(), values })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::{
        simulate_extended, BetweenSamples, Creep, Delay, Drift, Electrostriction, GainDrift, InputLag, Pickup,
        Resonance, Resonance2, Saturation,
    };
    use crate::reconstruction::Reconstruction;

    /// A slow, smooth record (a 5 Hz sine with a 13 Hz ripple at 2 kHz): the integrator
    /// takes the same sub-steps at every shifted point of the finite differences.
    fn record() -> (Vec<f64>, f64) {
        let dt = 5e-4;
        let u = (0..1200)
            .map(|k| {
                let t = k as f64 * dt;
                50.0 + 40.0 * (2.0 * core::f64::consts::PI * 5.0 * t).sin()
                    + 6.0 * (2.0 * core::f64::consts::PI * 13.0 * t).cos()
            })
            .collect();
        (u, dt)
    }

    /// The unknowns of (params, effects, h0) in column order, and back.
    fn pack(p: &Params, e: &EffectSet, h0: f64) -> Vec<f64> {
        let mut v = vec![p.kv, p.x0, p.a, p.beta, p.gamma, p.n, p.delta, h0];
        if let Some(c) = &e.creep {
            v.extend(&c.gain_um_per_v);
        }
        if let Some(l) = &e.input_lag {
            v.push(l.fc_hz.ln());
        }
        v.extend(e.gain_drift.map(|g| g.rate_per_s));
        v.extend(e.electrostriction.map(|g| g.epsilon_per_um));
        for r in [e.resonance.map(|r| (r.fn_hz, r.zeta)), e.resonance2.map(|r| (r.fn_hz, r.zeta))].into_iter().flatten()
        {
            v.extend([r.0.ln(), r.1.ln()]);
        }
        v.extend(e.drift.map(|d| d.rate_um_per_s));
        if let Some(p) = &e.pickup {
            v.extend(&p.sin_um);
            v.extend(&p.cos_um);
        }
        if let Some(s) = &e.saturation {
            v.extend([s.min_um, s.max_um]);
        }
        v
    }

    fn unpack(v: &[f64], like: &EffectSet) -> (Params, EffectSet, f64) {
        let p = Params { kv: v[0], x0: v[1], a: v[2], beta: v[3], gamma: v[4], n: v[5], delta: v[6] };
        let mut e = like.clone();
        let mut i = 8;
        let mut next = |k: usize| {
            let s = v[i..i + k].to_vec();
            i += k;
            s
        };
        if let Some(c) = &mut e.creep {
            c.gain_um_per_v = next(c.tau_s.len());
        }
        if let Some(l) = &mut e.input_lag {
            l.fc_hz = next(1)[0].exp();
        }
        if let Some(g) = &mut e.gain_drift {
            g.rate_per_s = next(1)[0];
        }
        if let Some(g) = &mut e.electrostriction {
            g.epsilon_per_um = next(1)[0];
        }
        if let Some(r) = &mut e.resonance {
            let w = next(2);
            (r.fn_hz, r.zeta) = (w[0].exp(), w[1].exp());
        }
        if let Some(r) = &mut e.resonance2 {
            let w = next(2);
            (r.fn_hz, r.zeta) = (w[0].exp(), w[1].exp());
        }
        if let Some(d) = &mut e.drift {
            d.rate_um_per_s = next(1)[0];
        }
        if let Some(p) = &mut e.pickup {
            let k = p.harmonics();
            p.sin_um = next(k);
            p.cos_um = next(k);
        }
        if let Some(s) = &mut e.saturation {
            let w = next(2);
            (s.min_um, s.max_um) = (w[0], w[1]);
        }
        (p, e, v[7])
    }

    /// Every column against a central difference of the simulator.
    ///
    /// Tolerance: 1e-5 of the column's largest entry. The central difference's own
    /// truncation error is O(step²) ≈ 1e-12 relative at steps of 1e-6 relative, its
    /// rounding error about 1e-16·|x|/step ≈ 1e-9 µm per unit; the integrator's choice
    /// between the series and `powf` for |h|^n (3e-9 relative apart) may differ between
    /// the two shifted points at a few samples, which the difference turns into up to
    /// about 3e-9/2e-6 ≈ 1.5e-3 of |h|^n's share there, diluted to far below 1e-5 of the
    /// largest entry on this record (measured: below 1e-6). A wrong derivative is off by
    /// its own size.
    fn check(p: &Params, e: &EffectSet, h0: f64) {
        check_on(p, e, h0, record());
    }

    /// [`check`] on the record `(u, dt)`.
    fn check_on(p: &Params, e: &EffectSet, h0: f64, (u, dt): (Vec<f64>, f64)) {
        let jac = simulate_extended_with_jacobian(p, e, &u, dt, h0).unwrap();
        let v = pack(p, e, h0);
        assert_eq!(jac.columns, v.len());
        assert_eq!(unknowns(e), v.len());
        assert_eq!(jac.x, simulate_extended(p, e, &u, dt, h0).unwrap(), "the output is the simulator's");
        for j in 0..v.len() {
            let step = 1e-6 * v[j].abs().max(1e-2);
            let at = |d: f64| {
                let mut w = v.clone();
                w[j] += d;
                let (q, f, g) = unpack(&w, e);
                simulate_extended(&q, &f, &u, dt, g).unwrap()
            };
            let (plus, minus) = (at(step), at(-step));
            let col: Vec<f64> = (0..u.len()).map(|k| jac.values[k * jac.columns + j]).collect();
            let largest = col.iter().fold(0.0f64, |m, c| m.max(c.abs()));
            let worst =
                (0..u.len()).map(|k| ((plus[k] - minus[k]) / (2.0 * step) - col[k]).abs()).fold(0.0f64, f64::max);
            eprintln!("{:?} column {j}: largest {largest:.3e}, worst {worst:.3e}", e.names());
            if j == 6 && e.input() == Reconstruction::Hold {
                // δ·u·sgn(u̇) acts while the command moves, which a held one never does
                // within an interval: the model does not depend on δ.
                assert!(largest == 0.0 && worst == 0.0, "the δ column under a hold: {largest:e}, {worst:e}");
                continue;
            }
            assert!(largest > 0.0, "column {j} of {:?} is zero", e.names());
            assert!(worst <= 1e-5 * largest, "column {j} of {:?}: {worst:e} against {largest:e}", e.names());
        }
    }

    /// Through a hold behind the input lag the δ term is off while the stack settles
    /// (`Drive`): the δ column and every other stays that of the simulator's map.
    #[test]
    fn columns_match_central_differences_through_a_hold_behind_the_lag() {
        let (mut u, dt) = record();
        let held = u[500];
        u[500..800].iter_mut().for_each(|v| *v = held);
        let effects = EffectSet { input_lag: Some(InputLag { fc_hz: 40.0 }), ..EffectSet::none() };
        check_on(&Params::paper_1hz(), &effects, 0.3, (u, dt));
    }

    #[test]
    fn base_columns_match_central_differences() {
        check(&Params::paper_1hz(), &EffectSet::none(), 0.3);
        // (n ≥ 1: for n < 1 the slope of |h|^n is floored within 1 nm of h = 0 by design,
        // `SLOPE_FLOOR_UM`, so differences there do not measure the derivative.)
        check(&Params { n: 1.2, ..Params::paper_1hz() }, &EffectSet::none(), -0.2);
    }

    #[test]
    fn effect_columns_match_central_differences() {
        let p = Params::paper_1hz();
        let creep = Creep { tau_s: vec![0.01, 0.2], gain_um_per_v: vec![0.01, 0.02] };
        check(
            &p,
            &EffectSet {
                creep: Some(creep),
                input_lag: Some(InputLag { fc_hz: 40.0 }),
                gain_drift: Some(GainDrift { rate_per_s: 0.05 }),
                electrostriction: Some(Electrostriction { epsilon_per_um: 0.004 }),
                drift: Some(Drift { rate_um_per_s: 0.3 }),
                delay: Some(Delay { samples: 2 }),
                pickup: Some(Pickup { line_hz: 50.0, sin_um: vec![0.1, 0.02], cos_um: vec![-0.05, 0.01] }),
                ..EffectSet::none()
            },
            0.1,
        );
        check(
            &p,
            &EffectSet {
                resonance: Some(Resonance { fn_hz: 120.0, zeta: 0.2 }),
                resonance2: Some(Resonance2 { fn_hz: 300.0, zeta: 0.5 }),
                saturation: Some(Saturation { min_um: 4.0, max_um: 14.0 }),
                ..EffectSet::none()
            },
            // Not 0: at h = 0 the first interval takes more sub-steps than at h = ±step.
            0.05,
        );
    }

    #[test]
    fn columns_match_central_differences_with_the_input_held_or_band_limited() {
        let p = Params::paper_1hz();
        for input in [Reconstruction::Hold, Reconstruction::Bandlimited] {
            let between_samples = Some(BetweenSamples { input });
            let creep = Creep { tau_s: vec![0.01, 0.2], gain_um_per_v: vec![0.01, 0.02] };
            check(&p, &EffectSet { between_samples, ..EffectSet::none() }, 0.1);
            let lagged = EffectSet {
                creep: Some(creep),
                input_lag: Some(InputLag { fc_hz: 40.0 }),
                between_samples,
                ..EffectSet::none()
            };
            check(&p, &lagged, 0.1);
            check(
                &p,
                &EffectSet {
                    resonance: Some(Resonance { fn_hz: 120.0, zeta: 0.2 }),
                    between_samples,
                    ..EffectSet::none()
                },
                0.05,
            );
        }
    }

    #[test]
    fn the_base_model_has_eight_columns_and_the_simulators_output() {
        let (u, dt) = record();
        let p = Params::paper_1hz();
        let jac = simulate_with_jacobian(&p, &u, dt, 0.2).unwrap();
        assert_eq!(jac.columns, 8);
        assert_eq!(jac.x, crate::simulate(&p, &u, dt, 0.2, None).unwrap().0);
        // ∂x/∂kv = u, ∂x/∂x0 = 1.
        for (k, &v) in u.iter().enumerate() {
            assert_eq!([jac.values[8 * k], jac.values[8 * k + 1]], [v, 1.0]);
        }
        assert!(simulate_with_jacobian(&p, &[0.0, f64::NAN], dt, 0.0).is_err());
    }
}
