//! The hysteretic oscillator's simulator against a converged reference.
//!
//! The reference is written here on its own (no code of the library's integrator): RK4
//! at [`REFERENCE_STEPS`] steps a sample interval (≥ 100× the rate) on the exact force
//! — the multisine's own cosines for the band-limited input, the straight line or the
//! held sample for the others — with every kink of |ẏ| and |z| located: a step whose
//! ends differ in the sign of ẏ or z is cut at the zero crossing, found by regula falsi
//! (Illinois) on the RK4 step's length to 1e-15 of the step, and integration goes on from
//! there, so that no RK4 step spans a kink and the scheme keeps its fourth order. That
//! it has converged is checked, not assumed: at twice the steps it moves by less than a
//! hundredth of the tolerance.
//!
//! The tolerance is 1e-6 of the displacement range, on the benchmark's kind of input (a
//! 5–150 Hz multisine of 50 N RMS at 750 Hz) with its parameters, for each of hold,
//! linear and band-limited.

use boucwen::oscillator::{simulate_path, OscillatorParams, OscillatorState};
use boucwen::reconstruction::{InputPath, Reconstruction};

const DT: f64 = 1.0 / 750.0;
/// RK4 steps of the reference per sample interval.
const REFERENCE_STEPS: usize = 128;
/// Samples per period of the test multisine (1.46 Hz between its lines).
const PERIOD: usize = 512;
/// Periods simulated (the last ones are steady: the mode's decay time 2m/c is 0.4 s).
const PERIODS: usize = 3;
/// The criterion: largest |y − y_ref| as a fraction of the range of y_ref.
const TOLERANCE: f64 = 1e-6;

/// The benchmark's kind of excitation as a function of time: cosines at every line of
/// the period from 5 to 150 Hz, Schroeder phases, 50 N RMS.
struct Multisine {
    omega: Vec<f64>,
    phase: Vec<f64>,
    amplitude: f64,
}

impl Multisine {
    fn new() -> Self {
        let span = PERIOD as f64 * DT;
        let (lo, hi) = ((5.0 * span).ceil() as usize, (150.0 * span).floor() as usize);
        let count = hi - lo + 1;
        let omega = (lo..=hi).map(|j| 2.0 * std::f64::consts::PI * j as f64 / span).collect();
        let phase = (0..count).map(|j| -std::f64::consts::PI * (j * (j + 1)) as f64 / count as f64).collect();
        Multisine { omega, phase, amplitude: 50.0 * (2.0 / count as f64).sqrt() }
    }

    fn at(&self, t: f64) -> f64 {
        self.omega.iter().zip(&self.phase).map(|(w, p)| (w * t + p).cos()).sum::<f64>() * self.amplitude
    }
}

/// The right-hand side (y, ẏ, z) → (ẏ, ÿ, ż) at force `f` \[N\].
fn rhs(p: &OscillatorParams, s: [f64; 3], f: f64) -> [f64; 3] {
    let [y, v, z] = s;
    let zn = z.abs().powf(p.nu);
    let zdot = p.alpha * v - p.beta * (p.gamma * v.abs() * zn * z.signum() * f64::from(z != 0.0) + p.delta * v * zn);
    [v, (f - p.c * v - p.k * y - z) / p.m, zdot]
}

fn rk4(p: &OscillatorParams, s: [f64; 3], t: f64, h: f64, force: &dyn Fn(f64) -> f64) -> [f64; 3] {
    let add = |a: [f64; 3], k: [f64; 3], c: f64| [a[0] + c * k[0], a[1] + c * k[1], a[2] + c * k[2]];
    let k1 = rhs(p, s, force(t));
    let k2 = rhs(p, add(s, k1, 0.5 * h), force(t + 0.5 * h));
    let k3 = rhs(p, add(s, k2, 0.5 * h), force(t + 0.5 * h));
    let k4 = rhs(p, add(s, k3, h), force(t + h));
    core::array::from_fn(|i| s[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

/// The index (1: ẏ, 2: z) of the first variable whose sign differs between `a` and `b`.
fn kink(a: &[f64; 3], b: &[f64; 3]) -> Option<usize> {
    [1, 2].into_iter().find(|&i| a[i] * b[i] < 0.0)
}

/// The length τ ∈ (0, h) of the RK4 step from `s` at `t` at whose end variable `i` is 0
/// (Illinois regula falsi; `h` ends on its other side).
fn locate(p: &OscillatorParams, s: [f64; 3], t: f64, h: f64, i: usize, force: &dyn Fn(f64) -> f64) -> f64 {
    let (mut a, mut fa) = (0.0, s[i]);
    let (mut b, mut fb) = (h, rk4(p, s, t, h, force)[i]);
    let mut side = 0;
    for _ in 0..200 {
        let c = (a * fb - b * fa) / (fb - fa);
        let fc = rk4(p, s, t, c, force)[i];
        if (b - a).abs() <= 1e-15 * h || fc == 0.0 {
            return c;
        }
        if fc * fb < 0.0 {
            (a, fa) = (b, fb);
            side = 0;
        } else {
            fa = if side == 1 { 0.5 * fa } else { fa };
            side = 1;
        }
        (b, fb) = (c, fc);
    }
    b
}

/// The force over interval k (from sample k − 1 to k) at the time t ∈ \[0, dt\] within it.
type Force<'a> = Box<dyn Fn(usize, f64) -> f64 + 'a>;

/// y at every sample from rest, `steps` RK4 steps a sample interval, kinks located.
fn reference(p: &OscillatorParams, samples: usize, steps: usize, force: &Force<'_>) -> Vec<f64> {
    let h = DT / steps as f64;
    let mut s = [0.0; 3];
    let mut y = vec![0.0];
    for k in 1..samples {
        let force = |t: f64| force(k, t);
        let force: &dyn Fn(f64) -> f64 = &force;
        for i in 0..steps {
            let (mut t, end) = (i as f64 * h, (i + 1) as f64 * h);
            loop {
                let left = end - t;
                let trial = rk4(p, s, t, left, force);
                match kink(&s, &trial) {
                    None => {
                        s = trial;
                        break;
                    }
                    Some(j) => {
                        let tau = locate(p, s, t, left, j, force);
                        s = rk4(p, s, t, tau, force);
                        s[j] = 0.0; // the kink itself: the next step starts on it
                        t += tau;
                    }
                }
            }
        }
        y.push(s[0]);
    }
    y
}

fn range(y: &[f64]) -> f64 {
    y.iter().fold(f64::MIN, |a, &b| a.max(b)) - y.iter().fold(f64::MAX, |a, &b| a.min(b))
}

fn largest_difference(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

/// The force of `kind` from the samples of `ms` (the band-limited one is the multisine
/// itself).
fn exact_force<'a>(kind: Reconstruction, ms: &'a Multisine, samples: &'a [f64]) -> Force<'a> {
    match kind {
        Reconstruction::Hold => Box::new(move |k, _| samples[k - 1]),
        Reconstruction::Linear => Box::new(move |k, t| samples[k - 1] + (samples[k] - samples[k - 1]) * (t / DT)),
        Reconstruction::Bandlimited => Box::new(move |k, t| ms.at((k - 1) as f64 * DT + t)),
    }
}

#[test]
fn the_simulator_agrees_with_a_converged_reference_to_a_millionth_of_the_range() {
    let p = OscillatorParams::benchmark();
    let p = if std::env::var("LINEAR_OSC").is_ok() { OscillatorParams { gamma: 0.0, delta: 0.0, ..p } } else { p };
    let ms = Multisine::new();
    let n = PERIOD * PERIODS;
    let samples: Vec<f64> = (0..n).map(|k| ms.at(k as f64 * DT)).collect();
    for kind in [Reconstruction::Bandlimited, Reconstruction::Linear, Reconstruction::Hold] {
        let force = exact_force(kind, &ms, &samples);
        let fine = reference(&p, n, REFERENCE_STEPS, &force);
        let finer = reference(&p, n, 2 * REFERENCE_STEPS, &force);
        let span = range(&fine);
        let converged = largest_difference(&fine, &finer) / span;
        let path = InputPath::new(&samples, kind, true).unwrap();
        let (y, _) = simulate_path(&p, &path, DT, OscillatorState::default()).unwrap();
        let error = largest_difference(&y, &fine) / span;
        eprintln!(
            "{}: range {span:.4e} m; the simulator {error:.3e} of it from the reference \
             ({:.3e} m), the reference {converged:.1e} from itself at twice the steps",
            kind.name(),
            error * span
        );
        assert!(converged <= TOLERANCE / 100.0, "{}: the reference moved by {converged:e}", kind.name());
        assert!(error <= TOLERANCE, "{}: {error:e} of the range", kind.name());
    }
}
