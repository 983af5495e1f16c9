//! The adaptive compensator: the inverse of the current estimates, updated online.
//!
//! One call per sample of the control loop, `u_k = step(x_d,k, x_k−1)`:
//!
//! ```text
//! 1. measurement of the previous output x_k−1 \[µm\] (None: none arrived)
//!      identifier.push(u_k−1, x_k−1)            estimates θ and h updated
//!      inverse ← θ, h                            (the identifier's h is the model's h
//!                                               after u_k−1 with the estimates of
//!                                               that moment, as the inverse's own)
//!      e_k−1 = x_d,k−1 − x_k−1,  v = PID(e_k−1)  \[µm\]
//! 2. x_cmd = x_d,k + v        (v alone without feedforward)
//! 3. u_k = inverse.step(x_cmd)                   within the voltage limits
//! ```
//!
//! The loop sees the measurement one sample late, as a sampled controller does: the
//! output x_k is measured after u_k is applied and enters at the next call. The
//! compensator is generic over the crate's online identifiers and uses only
//! `push`, `params`, `h` and `input_lag` of [`OnlineIdentifier`]. With `adapt` off, the
//! identifier is not used: a fixed inverse plus feedback.
//!
//! **Input lag.** When the identifier identifies an input lag (the recommended
//! [`crate::identify::HorizonIdentifier`]), the inverse is the
//! [`super::ExtendedInverse`] through that lag: it takes the lag's estimate with the
//! parameters, and the identifier's voltage on the stack u_a with its h.
//!
//! **Split identifier.** The recommended identifier's `push` costs a model step when
//! its window pass runs elsewhere ([`crate::identify::RefineMode::Cooperative`]: call
//! [`Compensator::refine`] when the loop has time; or
//! [`crate::identify::BackgroundHorizon`], a worker thread): the compensator's step
//! then costs a push and an inversion, and the estimates arrive when the pass has run.
//!
//! **Admissible estimates.** The inverse is well posed only while x(u) rises along
//! both branches, kv + A − (±β + γ)·|h|^n > 0. In closed loop an online estimate can
//! wander to where that fails (kv and x0 trade off against each other, A against kv).
//! The inverse therefore takes new estimates only if both branch slopes stay at
//! least [`MIN_SLOPE_FRACTION`]·kv for every |h| up to the largest |h| seen so far;
//! otherwise it keeps the last admissible ones (and its own h) and the status says
//! so, but moves their offset x0 so that at the last sample its model gives what the
//! identifier's updated model gives: the offset keeps following the measurement as
//! with admissible estimates. The identifier itself keeps running.
//!
//! Missing measurements (`None` after the first sample) leave the estimates and the
//! feedback integral as they are; the identifier then no longer sees every voltage,
//! so from that sample on the inverse keeps its own h and takes only the estimates.
//!
//! Errors (a non-finite x_d or x_meas) are detected before anything changes: the
//! compensator stays exactly as it was.

use super::feedback::{Pid, PidGains};
use super::inverse::{Clip, InverseStatus, VoltageLimits};
use super::AnyInverse;
use crate::effects::EffectSet;
use crate::error::{finite_sample, Result};
use crate::identify::{HorizonIdentifier, OnlineIdentifier};
use crate::model::output;
use crate::params::Params;

/// Least slope of x(u) on either branch, as a fraction of kv, for estimates the
/// inverse takes (see the module docs).
pub const MIN_SLOPE_FRACTION: f64 = 0.1;

/// Both branch slopes kv + A − (±β + γ)·|h|^n \[µm/V\] are at least
/// [`MIN_SLOPE_FRACTION`]·kv for every |h| ≤ `h_bound` \[µm\] (the extremes are at
/// |h| = 0 and |h| = `h_bound`).
pub fn admissible(p: &Params, h_bound: f64) -> bool {
    let floor = MIN_SLOPE_FRACTION * p.kv;
    let base = p.kv + p.a;
    let hn = if h_bound > 0.0 { crate::math::powf(h_bound, p.n) } else { 0.0 };
    p.kv > 0.0 && base >= floor && base - (p.beta + p.gamma) * hn >= floor && base - (p.gamma - p.beta) * hn >= floor
}

/// How the compensator combines its parts. `Default`: adaptive, feedforward on, no
/// feedback.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensatorConfig {
    /// Update the estimates from each measurement and invert the current ones.
    pub adapt: bool,
    /// Feed the desired displacement forward through the inverse (off: the
    /// reference enters through the feedback alone, x_cmd = v).
    pub feedforward: bool,
    /// Feedback gains (all zero: no feedback).
    pub gains: PidGains,
}

impl Default for CompensatorConfig {
    fn default() -> Self {
        CompensatorConfig { adapt: true, feedforward: true, gains: PidGains::default() }
    }
}

/// What the last [`Compensator::step`] did. Small and `Copy`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CompensatorStatus {
    /// The inverse's step.
    pub inverse: InverseStatus,
    /// The identifier's prediction of the measured sample \[µm\] (NaN: not pushed).
    pub prediction_um: f64,
    /// Tracking error of the previous sample, x_d − x \[µm\] (NaN: no measurement).
    pub error_um: f64,
    /// Feedback correction added to x_d \[µm\].
    pub feedback_um: f64,
    /// The displacement the inverse was asked for \[µm\].
    pub command_um: f64,
    /// Calls since construction.
    pub samples: u64,
    /// The identifier has seen every voltage (no missing measurement so far).
    pub in_step: bool,
    /// The identifier's estimates were not admissible this sample (the inverse kept
    /// the last admissible ones, see [`admissible`]).
    pub estimates_held: bool,
    /// Samples whose estimates were held since construction.
    pub held_samples: u64,
}

/// The last applied sample.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Applied {
    u: f64,
    x_d: f64,
    clip: Clip,
}

/// Inverse + online identifier + PID (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Compensator<I: OnlineIdentifier> {
    identifier: I,
    inverse: AnyInverse,
    feedback: Pid,
    config: CompensatorConfig,
    last: Option<Applied>,
    in_step: bool,
    /// Largest |h| of the inverse and the identifier so far \[µm\].
    h_peak: f64,
    status: CompensatorStatus,
}

impl<I: OnlineIdentifier> Compensator<I> {
    /// A compensator around `identifier` (its current estimates, input lag and h are
    /// the inverse's start) for samples `dt` \[s\] apart, voltages within `limits`.
    pub fn new(identifier: I, dt: f64, limits: VoltageLimits, config: CompensatorConfig) -> Result<Self> {
        let effects = identifier.input_lag().map(|(lag, _)| EffectSet { input_lag: Some(lag), ..EffectSet::none() });
        let inverse = AnyInverse::new(identifier.params(), effects, dt, identifier.h(), limits)?;
        let feedback = Pid::new(config.gains, dt)?;
        Ok(Compensator {
            h_peak: identifier.h().abs(),
            identifier,
            inverse,
            feedback,
            config,
            last: None,
            in_step: true,
            status: CompensatorStatus { in_step: true, ..Default::default() },
        })
    }

    /// Takes the desired displacement `x_d` \[µm\] of this sample and the measurement
    /// `x_meas` \[µm\] of the previous output (`None` on the first call, or when none
    /// arrived); returns the voltage u \[V\] to apply. Allocation-free.
    pub fn step(&mut self, x_d: f64, x_meas: Option<f64>) -> Result<f64> {
        finite_sample("x_d", x_d)?;
        if let Some(x) = x_meas {
            finite_sample("x_meas", x)?;
        }
        let mut status = CompensatorStatus {
            prediction_um: f64::NAN,
            error_um: f64::NAN,
            samples: self.status.samples + 1,
            held_samples: self.status.held_samples,
            ..Default::default()
        };
        let mut v = self.feedback.hold();
        match (self.last, x_meas) {
            (Some(last), Some(x)) => {
                let e = finite_sample("x_d - x_meas", last.x_d - x)?;
                if self.config.adapt {
                    status.prediction_um = self.identifier.push(last.u, x)?;
                    let (estimates, h) = (self.identifier.params(), self.identifier.h());
                    let lag = self.identifier.input_lag();
                    let ua = lag.map_or(last.u, |(_, ua)| ua);
                    self.h_peak = self.h_peak.max(h.abs());
                    if admissible(&estimates, self.h_peak) {
                        self.inverse.set_params(estimates)?;
                        if let Some((lag, _)) = lag {
                            if self.inverse.effects().and_then(|e| e.input_lag) != Some(lag) {
                                self.inverse.set_input_lag(lag)?;
                            }
                        }
                        if self.in_step {
                            self.inverse.follow(h, last.u, ua)?;
                        }
                    } else {
                        let held = *self.inverse.params();
                        let gap =
                            output(&estimates, ua, h) - output(&held, self.inverse.stack_voltage(), self.inverse.h());
                        self.inverse.set_params(Params { x0: held.x0 + gap, ..held })?;
                        status.estimates_held = true;
                        status.held_samples += 1;
                    }
                }
                status.error_um = e;
                v = self.feedback.update(e, last.clip)?;
            }
            (Some(_), None) => self.in_step = false,
            (None, _) => {}
        }
        let command = if self.config.feedforward { x_d + v } else { v };
        let u = self.inverse.step(command)?;
        self.h_peak = self.h_peak.max(self.inverse.h().abs());
        let inverse_status = self.inverse.status();
        self.last = Some(Applied { u, x_d, clip: inverse_status.clip });
        status.inverse = inverse_status;
        status.feedback_um = v;
        status.command_um = command;
        status.in_step = self.in_step;
        self.status = status;
        Ok(u)
    }

    /// The parameters the inverse uses now (the current estimates when adapting).
    pub fn params(&self) -> Params {
        *self.inverse.params()
    }

    /// The inverse model's h \[µm\] after the last sample.
    pub fn h(&self) -> f64 {
        self.inverse.h()
    }

    /// The identifier.
    pub fn identifier(&self) -> &I {
        &self.identifier
    }

    /// The inverse model (through the identifier's input lag where it has one).
    pub fn inverse(&self) -> &AnyInverse {
        &self.inverse
    }

    /// The feedback controller.
    pub fn feedback(&self) -> &Pid {
        &self.feedback
    }

    /// The configuration.
    pub fn config(&self) -> &CompensatorConfig {
        &self.config
    }

    /// What the last step did.
    pub fn status(&self) -> CompensatorStatus {
        self.status
    }
}

impl Compensator<HorizonIdentifier> {
    /// Cooperative mode: runs the identifier's window pass at most `max_intervals`
    /// integration intervals ([`HorizonIdentifier::refine`]); the next step inverts the
    /// update it adopts. Returns the intervals run (0 in sync mode). Call it when the
    /// loop has time, between two steps. Never allocates.
    pub fn refine(&mut self, max_intervals: usize) -> usize {
        self.identifier.refine(max_intervals)
    }
}

#[cfg(feature = "std")]
impl Compensator<crate::identify::BackgroundHorizon> {
    /// A copy with a worker of its own: the identifier is restarted from its state
    /// ([`crate::identify::BackgroundHorizon::cooperative`], the samples its worker had
    /// not read and an update not adopted yet included). Errors if the thread cannot start.
    pub fn try_clone(&self) -> Result<Self> {
        Ok(Compensator {
            identifier: crate::identify::BackgroundHorizon::spawn(self.identifier.cooperative())?,
            inverse: self.inverse.clone(),
            feedback: self.feedback.clone(),
            config: self.config,
            last: self.last,
            in_step: self.in_step,
            h_peak: self.h_peak,
            status: self.status,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::{RpemConfig, RpemIdentifier};
    use crate::model::Model;

    fn sine(k: usize, dt: f64, f: f64) -> f64 {
        10.0 - 8.0 * (2.0 * std::f64::consts::PI * f * k as f64 * dt).cos()
    }

    /// The plant: the paper's model with other parameters than the compensator's start.
    fn run(config: CompensatorConfig, samples: usize, f: f64) -> (f64, f64) {
        let dt = 1e-4;
        let truth = Params { kv: 0.17, a: -0.06, beta: 0.024, ..Params::paper_1hz() };
        let mut plant = Model::new(truth, dt, 0.0).unwrap();
        let id = RpemIdentifier::new(dt, Params::paper_1hz(), 0.0, RpemConfig::for_tracking()).unwrap();
        let limits = VoltageLimits::new(Some(0.0), Some(120.0)).unwrap();
        let mut comp = Compensator::new(id, dt, limits, config).unwrap();
        let mut x_meas = None;
        let (mut first, mut last) = (0.0f64, 0.0f64);
        let period = (1.0 / (f * dt)) as usize;
        assert!(samples >= 2 * period);
        for k in 0..samples {
            let x_d = sine(k, dt, f);
            let u = comp.step(x_d, x_meas).unwrap();
            let x = plant.step(u).unwrap();
            let err = (x - x_d).abs();
            if k < period {
                first = first.max(err);
            } else if k >= samples - period {
                last = last.max(err);
            }
            x_meas = Some(x);
        }
        (first, last)
    }

    #[test]
    fn adaptation_removes_the_model_error() {
        let (fixed_first, fixed_last) = run(CompensatorConfig { adapt: false, ..Default::default() }, 3000, 10.0);
        let (_, adaptive_last) = run(CompensatorConfig::default(), 3000, 10.0);
        eprintln!("fixed {fixed_first:.3}/{fixed_last:.3} µm, adaptive {adaptive_last:.4} µm");
        assert!(fixed_last > 0.3);
        assert!(adaptive_last < 0.1 * fixed_last, "{adaptive_last} vs {fixed_last}");
    }

    #[test]
    fn integral_feedback_alone_removes_a_static_error() {
        let config = CompensatorConfig { adapt: false, gains: PidGains::pi(0.2, 200.0), ..Default::default() };
        let (_, with_pi) = run(config, 6000, 5.0);
        let (_, without) = run(CompensatorConfig { adapt: false, ..Default::default() }, 6000, 5.0);
        assert!(with_pi < 0.2 * without, "{with_pi} vs {without}");
    }

    #[test]
    fn rejects_bad_measurements_and_keeps_state() {
        let dt = 1e-4;
        let id = RpemIdentifier::new(dt, Params::paper_1hz(), 0.0, RpemConfig::for_tracking()).unwrap();
        let mut comp = Compensator::new(id, dt, VoltageLimits::NONE, CompensatorConfig::default()).unwrap();
        comp.step(1.0, None).unwrap();
        comp.step(2.0, Some(0.9)).unwrap();
        let before = comp.clone();
        assert!(comp.step(3.0, Some(f64::NAN)).is_err());
        assert!(comp.step(f64::INFINITY, Some(1.0)).is_err());
        assert_eq!(comp, before);
    }

    #[test]
    fn admissibility_follows_the_branch_slopes() {
        let p = Params::paper_1hz();
        assert!(admissible(&p, 0.0) && admissible(&p, 5.0));
        // kv + A nearly zero: the loop is flat.
        assert!(!admissible(&Params { a: -0.185, ..p }, 0.0));
        // The loading slope turns negative at large |h|.
        let soft = Params { beta: 0.05, gamma: 0.04, n: 1.0, ..p };
        assert!(admissible(&soft, 0.5) && !admissible(&soft, 2.0));
        assert!(!admissible(&Params { kv: -0.19, ..p }, 0.0));
    }

    /// The recommended identifier in cooperative mode behind the compensator, on a plant
    /// with a 650 Hz amplifier lag tracking a 100 Hz sine from the paper's 1 Hz values:
    /// `refine(budget)` after every step. Returns the last period's max error \[µm\],
    /// the inverse's lag corner \[Hz\] and the compensator.
    fn run_horizon(budget: usize) -> (f64, f64, Compensator<HorizonIdentifier>) {
        use crate::effects::{EffectSet, ExtendedModel, InputLag};
        use crate::identify::{HorizonConfig, RefineMode};
        let (dt, f) = (1e-4, 100.0);
        let truth = Params { kv: 0.17, a: -0.06, beta: 0.024, ..Params::paper_1hz() };
        let lag = EffectSet { input_lag: Some(InputLag { fc_hz: 650.0 }), ..EffectSet::none() };
        let mut plant = ExtendedModel::new(truth, lag, dt, 0.0).unwrap();
        let id = HorizonIdentifier::recommended(dt, Params::paper_1hz(), 0.0, HorizonConfig::default())
            .unwrap()
            .with_mode(RefineMode::Cooperative);
        let limits = VoltageLimits::new(Some(-30.0), Some(120.0)).unwrap();
        let mut comp = Compensator::new(id, dt, limits, CompensatorConfig::default()).unwrap();
        let period = (1.0 / (f * dt)) as usize;
        let samples = 30 * period;
        let (mut x_meas, mut last) = (None, 0.0f64);
        for k in 0..samples {
            let x_d = sine(k, dt, f);
            let u = comp.step(x_d, x_meas).unwrap();
            let x = plant.step(u).unwrap();
            if k >= samples - period {
                last = last.max((x - x_d).abs());
            }
            x_meas = Some(x);
            comp.refine(budget);
        }
        let fc = comp.inverse().effects().and_then(|e| e.input_lag).map(|l| l.fc_hz).unwrap();
        (last, fc, comp)
    }

    #[test]
    fn the_recommended_identifier_compensates_through_its_lag_on_the_split() {
        // No refine: the starting model (fc = 0.3/dt = 3 kHz, the 1 Hz parameters).
        let (starved, fc0, _) = run_horizon(0);
        assert!((fc0 - 3000.0).abs() < 1e-9, "fc = {fc0} Hz");
        // Refined between steps: the lag and the parameters are found and inverted.
        let (refined, fc, comp) = run_horizon(64);
        eprintln!("horizon, cooperative: {starved:.4} µm without refine, {refined:.4} µm with (fc {fc:.0} Hz)");
        assert!(comp.identifier().status().updates > 10, "{:?}", comp.identifier().status());
        assert!((fc / 650.0 - 1.0).abs() < 0.2, "fc = {fc} Hz");
        assert!(refined < 0.2 * starved, "{refined} vs {starved} µm");
        assert!(refined < 0.1, "{refined} µm");
        // The inverse follows the identifier's model: same h, same voltage on the stack.
        assert_eq!(comp.h().to_bits(), comp.inverse().h().to_bits());
    }

    #[test]
    fn missing_measurements_hold_the_estimates() {
        let dt = 1e-4;
        let id = RpemIdentifier::new(dt, Params::paper_1hz(), 0.0, RpemConfig::for_tracking()).unwrap();
        let mut comp = Compensator::new(id, dt, VoltageLimits::NONE, CompensatorConfig::default()).unwrap();
        comp.step(1.0, None).unwrap();
        comp.step(2.0, Some(1.3)).unwrap();
        let params = comp.params();
        comp.step(3.0, None).unwrap();
        assert_eq!(comp.params(), params);
        assert!(!comp.status().in_step);
        comp.step(4.0, Some(3.2)).unwrap();
        assert!(comp.params() != params);
    }
}
