//! `between_samples`: what the commanded voltage does between its samples, the
//! measurement chain's input end ([`crate::reconstruction`]).
//!
//! - `hold`: a DAC's zero-order hold: u\[k−1\] on \[t_{k−1}, t_k), u\[k\] from t_k on. The
//!   input lag and creep see the held voltage over the interval; where the stack takes the
//!   command directly (no lag), h follows the step at t_k along the loop (A, β, γ: a jump
//!   of the voltage moves h by the same amount however fast), and δ·u·sgn(u̇), a rate
//!   term, adds nothing over a step of no duration. The output at t_k sees u\[k\].
//! - `linear`: a straight line between samples (the chain without this effect).
//! - `bandlimited`: the band-limited signal through the samples (the Kaiser-windowed
//!   sinc of [`crate::reconstruction::sinc`]), taken at [`PIECES`] equally spaced points
//!   of each interval with straight lines between them (the chain then runs on [`PIECES`]
//!   sub-intervals: a line over an eighth of a sample interval departs from the signal by
//!   at most (ω·dt/8)²/8 of a component at ω). It depends on later samples: a whole
//!   record only, not sample by sample.

use super::Effect;
use crate::error::Result;
use crate::reconstruction::Reconstruction;
pub use crate::reconstruction::PIECES;

/// What the commanded voltage does between samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BetweenSamples {
    /// Hold, linear or band-limited.
    pub input: Reconstruction,
}

impl Effect for BetweenSamples {
    const NAME: &'static str = "between_samples";

    /// Every choice is valid.
    fn validate(&self) -> Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::{simulate_extended, EffectSet, ExtendedModel, InputLag};
    use crate::model::paper_input;
    use crate::params::Params;

    fn with(input: Reconstruction, effects: EffectSet) -> EffectSet {
        EffectSet { between_samples: Some(BetweenSamples { input }), ..effects }
    }

    /// Without a lag, h follows each step along the loop and the δ term, a rate, adds
    /// nothing: the held input is the straight line with δ = 0, to the bit.
    #[test]
    fn a_held_input_into_the_stack_is_the_line_without_the_rate_term() {
        let (p, dt) = (Params::paper_1hz(), 1e-4);
        let u = paper_input(dt, 0.02);
        let held = simulate_extended(&p, &with(Reconstruction::Hold, EffectSet::none()), &u, dt, 0.1).unwrap();
        let line = simulate_extended(&Params { delta: 0.0, ..p }, &EffectSet::none(), &u, dt, 0.1).unwrap();
        assert_eq!(held, line);
        assert_ne!(held, simulate_extended(&p, &EffectSet::none(), &u, dt, 0.1).unwrap());
    }

    /// Behind a lag the held input is the zero-order-hold discretisation of the lag:
    /// u_a\[k\] = e^(−dt/τ)·u_a\[k−1\] + (1 − e^(−dt/τ))·u\[k−1\] (a model with no hysteresis
    /// shows u_a: x = kv·u_a + x0).
    #[test]
    fn a_held_input_behind_a_lag_is_its_zero_order_hold_discretisation() {
        let p = Params { kv: 2.0, x0: 1.0, a: 0.0, beta: 0.0, gamma: 0.0, n: 1.5, delta: 0.0 };
        let (dt, lag) = (1e-3, InputLag { fc_hz: 30.0 });
        let u: Vec<f64> = (0..400).map(|k| (k as f64 * 0.05).sin() * 10.0 + (k / 37) as f64).collect();
        let x = simulate_extended(
            &p,
            &with(Reconstruction::Hold, EffectSet { input_lag: Some(lag), ..EffectSet::none() }),
            &u,
            dt,
            0.0,
        )
        .unwrap();
        let decay = (-dt / lag.tau_s()).exp();
        let mut ua = u[0];
        for k in 1..u.len() {
            ua = decay * ua + (1.0 - decay) * u[k - 1];
            assert!((x[k] - (p.kv * ua + p.x0)).abs() < 1e-12, "sample {k}");
        }
    }

    /// A band-limited input needs the record: sample by sample it is refused; on a slow
    /// record it is the straight line to within the line's curvature error.
    #[test]
    fn a_band_limited_input_needs_the_record_and_bends_the_line_between_samples() {
        let (p, dt) = (Params::paper_1hz(), 1e-4);
        let effects = with(
            Reconstruction::Bandlimited,
            EffectSet { input_lag: Some(InputLag { fc_hz: 300.0 }), ..EffectSet::none() },
        );
        let mut model = ExtendedModel::new(p, effects.clone(), dt, 0.0).unwrap();
        assert!(model.step(1.0).unwrap_err().to_string().contains("whole record"));
        let u = paper_input(dt, 0.0);
        let u = &u[..20_000];
        let smooth = simulate_extended(&p, &effects, u, dt, 0.0).unwrap();
        let line = simulate_extended(&p, &EffectSet { between_samples: None, ..effects }, u, dt, 0.0).unwrap();
        let worst = smooth.iter().zip(&line).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        // 1 Hz at 10 kHz: the line's departure, (2π·1e-4)²/8 of 50 V, is 2e-7 V.
        assert!(worst > 0.0 && worst < 1e-4, "{worst}");
    }
}
