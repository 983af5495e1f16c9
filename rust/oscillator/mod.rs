//! The hysteretic oscillator: a mass on a linear spring and damper and a Bouc–Wen
//! spring driven by the mass's own motion (the Noël & Schoukens hysteretic benchmark).
//!
//! ```text
//! m·ÿ + c·ẏ + k·y + z = F
//! ż = α·ẏ − β·(γ·|ẏ|·|z|^(ν−1)·z + δ·ẏ·|z|^ν)
//! ```
//!
//! F: applied force \[N\]; y: displacement \[m\]; z: hysteretic force \[N\]; t: time \[s\].
//! A second model class beside [`crate::model`] (whose hysteresis is driven by the
//! input): its own parameters ([`OscillatorParams`]), the same habits — one integrator
//! generic over the number type ([`integrator`]), the input between samples as the
//! record's [`crate::reconstruction`] says, a sub-step rule on values only, states held finite for any valid
//! parameters, and the exact Jacobian of the simulated output from the same pass on
//! [`Dual`] numbers ([`simulate_with_jacobian`]).
//!
//! **Input.** [`simulate`] and [`simulate_with_jacobian`] take F as a straight line
//! between samples; [`simulate_path`] and [`simulate_path_with_jacobian`] take an
//! [`InputPath`]: held, a straight line, or band-limited (the benchmark's input is a
//! multisine generated at 20× the rate: between the samples of its record it is the
//! band-limited signal, exactly the Fourier interpolation of its periodic record).
//!
//! **β.** β appears only in the products β·γ and β·δ: the Jacobian has no column for
//! it (a fit fixes β and identifies γ and δ).

pub mod integrator;
pub mod newmark;

use alloc::vec;
use alloc::vec::Vec;

use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::model::scalar::{Dual, Scalar};
use crate::reconstruction::{InputPath, Reconstruction};
use integrator::{advance, values, Coefficients, Force, Held, Ramp, Rule, Smooth, State};

/// The parameters of the hysteretic oscillator.
///
/// Units: m \[kg\], c \[N·s/m\], k \[N/m\], α \[N/m\], β \[N^(1−ν)/m\] (1/m for ν = 1),
/// γ and δ \[-\], ν \[-\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OscillatorParams {
    /// Mass m \[kg\], > 0.
    pub m: f64,
    /// Viscous damping c \[N·s/m\], ≥ 0.
    pub c: f64,
    /// Linear stiffness k \[N/m\], ≥ 0.
    pub k: f64,
    /// Initial stiffness of the Bouc–Wen spring α \[N/m\], > 0.
    pub alpha: f64,
    /// β \[N^(1−ν)/m\], > 0: the scale of γ and δ.
    pub beta: f64,
    /// γ \[-\], finite.
    pub gamma: f64,
    /// δ \[-\], finite.
    pub delta: f64,
    /// ν \[-\], in \[1, 10\].
    pub nu: f64,
}

/// Smallest exponent ν: below 1 the slope ∂ż/∂z = −β·ν·(…)·|z|^(ν−1) is unbounded at
/// z = 0 (an infinitely stiff relaxation at every zero crossing of z).
pub const NU_MIN: f64 = 1.0;
/// Largest exponent ν (the loops are square long before it).
pub const NU_MAX: f64 = 10.0;

impl OscillatorParams {
    /// Names in the order of [`OscillatorParams::to_array`].
    pub const NAMES: [&'static str; 8] = ["m", "c", "k", "alpha", "beta", "gamma", "delta", "nu"];

    /// The values of the benchmark's simulator (Noël & Schoukens 2016): m = 2 kg,
    /// c = 10 N·s/m, k = 5e4 N/m, α = 5e4 N/m, β = 1e3 1/m, γ = 0.8, δ = −1.1, ν = 1.
    pub fn benchmark() -> Self {
        OscillatorParams { m: 2.0, c: 10.0, k: 5e4, alpha: 5e4, beta: 1e3, gamma: 0.8, delta: -1.1, nu: 1.0 }
    }

    /// Every value finite; m > 0, c ≥ 0, k ≥ 0, α > 0, β > 0, ν in \[[`NU_MIN`], [`NU_MAX`]\].
    ///
    /// m > 0: a massless oscillator is a different (first-order) system. c, k ≥ 0: a
    /// negative damper or spring feeds energy in. α, β > 0: the Bouc–Wen spring's
    /// initial stiffness and the scale of its loop (its sign is γ's and δ's). ν ≥ 1:
    /// [`NU_MIN`].
    pub fn validate(&self) -> Result<()> {
        for (name, value) in Self::NAMES.iter().zip(self.to_array()) {
            if !value.is_finite() {
                return Err(Error::InvalidParameter { name, value, reason: "must be finite" });
            }
        }
        let checks: [(&'static str, f64, bool, &'static str); 6] = [
            ("m", self.m, self.m > 0.0, "the mass must be > 0 kg"),
            ("c", self.c, self.c >= 0.0, "the damping must be >= 0 N·s/m"),
            ("k", self.k, self.k >= 0.0, "the stiffness must be >= 0 N/m"),
            ("alpha", self.alpha, self.alpha > 0.0, "the Bouc-Wen spring's stiffness must be > 0 N/m"),
            ("beta", self.beta, self.beta > 0.0, "must be > 0 (the sign of the loop is gamma's and delta's)"),
            ("nu", self.nu, (NU_MIN..=NU_MAX).contains(&self.nu), "must be in [1, 10]"),
        ];
        for (name, value, ok, reason) in checks {
            if !ok {
                return Err(Error::InvalidParameter { name, value, reason });
            }
        }
        Ok(())
    }

    /// `[m, c, k, alpha, beta, gamma, delta, nu]`.
    pub fn to_array(&self) -> [f64; 8] {
        [self.m, self.c, self.k, self.alpha, self.beta, self.gamma, self.delta, self.nu]
    }

    /// Inverse of [`OscillatorParams::to_array`], validated.
    pub fn from_array(v: [f64; 8]) -> Result<Self> {
        let p =
            OscillatorParams { m: v[0], c: v[1], k: v[2], alpha: v[3], beta: v[4], gamma: v[5], delta: v[6], nu: v[7] };
        p.validate()?;
        Ok(p)
    }
}

/// The oscillator's state: y \[m\], ẏ \[m/s\], z \[N\].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OscillatorState {
    /// Displacement y \[m\].
    pub y: f64,
    /// Velocity ẏ \[m/s\].
    pub v: f64,
    /// Hysteretic force z \[N\].
    pub z: f64,
}

impl OscillatorState {
    fn validate(&self) -> Result<()> {
        finite_sample("y0", self.y)?;
        finite_sample("v0", self.v)?;
        finite_sample("z0", self.z)?;
        Ok(())
    }
}

/// The unknowns of [`simulate_with_jacobian`], in the order of its columns.
pub const UNKNOWNS: [&str; 10] = ["m", "c", "k", "alpha", "gamma", "delta", "nu", "y0", "v0", "z0"];

/// Checks the arguments of a simulation.
fn check(p: &OscillatorParams, force: &[f64], dt: f64, start: &OscillatorState) -> Result<()> {
    p.validate()?;
    positive_dt(dt)?;
    start.validate()?;
    for &f in force {
        finite_sample("F", f)?;
    }
    Ok(())
}

/// The force of every sample interval: interval k (1 ≤ k < len) runs from sample k − 1
/// to sample k.
trait Pieces {
    /// The force within an interval.
    type F: Force;
    /// Samples of the record.
    fn len(&self) -> usize;
    /// The force of interval k, with its least and largest value (for the sub-step rule).
    fn piece(&self, k: usize) -> (Self::F, f64, f64);
    /// The highest angular frequency of the force's content \[rad/s\] that the sub-steps
    /// must resolve (0 for a force that is a polynomial of degree ≤ 1 within an interval,
    /// which RK6 integrates exactly).
    fn force_omega(&self, _dt: f64) -> f64 {
        0.0
    }
}

/// A straight line between samples (first-order hold).
struct Lines<'a> {
    force: &'a [f64],
    dt: f64,
}

impl Pieces for Lines<'_> {
    type F = Ramp;
    fn len(&self) -> usize {
        self.force.len()
    }
    #[inline(always)]
    fn piece(&self, k: usize) -> (Ramp, f64, f64) {
        let (f0, f1) = (self.force[k - 1], self.force[k]);
        (Ramp::between(f0, f1, self.dt), f0, f1)
    }
}

/// The earlier sample held over the interval (zero-order hold).
struct Holds<'a>(&'a [f64]);

impl Pieces for Holds<'_> {
    type F = Held;
    fn len(&self) -> usize {
        self.0.len()
    }
    #[inline(always)]
    fn piece(&self, k: usize) -> (Held, f64, f64) {
        let f = self.0[k - 1];
        (Held(f), f, f)
    }
}

/// The band-limited polynomials of an [`InputPath`].
struct Smooths<'a> {
    path: &'a InputPath,
    /// 2/dt \[1/s\].
    scale: f64,
}

impl<'a> Pieces for Smooths<'a> {
    type F = Smooth<'a>;
    fn len(&self) -> usize {
        self.path.len()
    }
    #[inline(always)]
    fn piece(&self, k: usize) -> (Smooth<'a>, f64, f64) {
        let (lo, hi) = self.path.range(k);
        (Smooth { coefficients: self.path.polynomial(k), scale: self.scale }, lo, hi)
    }
    fn force_omega(&self, dt: f64) -> f64 {
        2.0 * core::f64::consts::PI * self.path.band() / dt
    }
}

/// Runs the integrator over the intervals of `pieces` from `s`, handing the state at
/// every sample (sample 0 included) to `emit`; returns the last state. The one loop of
/// every simulation and its Jacobian, dispatched once on ν = 1
/// ([`integrator::abs_pow`]).
#[inline(always)]
fn run<S: Scalar, P: Pieces>(
    c: &Coefficients<S>,
    p: &OscillatorParams,
    s: State<S>,
    pieces: &P,
    dt: f64,
    emit: impl FnMut(&State<S>),
) -> State<S> {
    #[inline(always)]
    fn steps<S: Scalar, P: Pieces, const UNIT: bool>(
        c: &Coefficients<S>,
        rule: &Rule,
        mut s: State<S>,
        pieces: &P,
        dt: f64,
        mut emit: impl FnMut(&State<S>),
    ) -> State<S> {
        if pieces.len() == 0 {
            return s;
        }
        emit(&s);
        for k in 1..pieces.len() {
            let (force, lo, hi) = pieces.piece(k);
            let plan = rule.substeps::<UNIT>(&values(&s), lo, hi);
            s = advance::<S, UNIT, P::F>(c, s, &force, dt, plan);
            emit(&s);
        }
        s
    }
    let rule = Rule::new(p, dt, pieces.force_omega(dt));
    if p.nu == 1.0 {
        steps::<S, P, true>(c, &rule, s, pieces, dt, emit)
    } else {
        steps::<S, P, false>(c, &rule, s, pieces, dt, emit)
    }
}

/// [`run`] over the intervals of `path` under its reconstruction.
#[inline(always)]
fn run_path<S: Scalar>(
    c: &Coefficients<S>,
    p: &OscillatorParams,
    s: State<S>,
    path: &InputPath,
    dt: f64,
    emit: impl FnMut(&State<S>),
) -> State<S> {
    match path.kind() {
        Reconstruction::Hold => run(c, p, s, &Holds(path.samples()), dt, emit),
        Reconstruction::Linear => run(c, p, s, &Lines { force: path.samples(), dt }, dt, emit),
        Reconstruction::Bandlimited => run(c, p, s, &Smooths { path, scale: 2.0 / dt }, dt, emit),
    }
}

/// Simulates the oscillator over a record of force samples `force` \[N\], `dt` \[s\]
/// apart, the force a straight line between samples, from the state `start` at sample
/// 0, into `y_out` (y\[0\] = start.y) \[m\]; returns the state at the last sample. Input
/// with a non-finite value is rejected before anything is computed. Allocation-free.
pub fn simulate_into(
    p: &OscillatorParams,
    force: &[f64],
    dt: f64,
    start: OscillatorState,
    y_out: &mut [f64],
) -> Result<OscillatorState> {
    check(p, force, dt, &start)?;
    into(y_out, force.len(), start, |s, emit| run(&Coefficients::of(p), p, s, &Lines { force, dt }, dt, emit))
}

/// [`simulate_into`] with the force between samples given by `path`
/// ([`crate::reconstruction`]). Allocation-free.
pub fn simulate_path_into(
    p: &OscillatorParams,
    path: &InputPath,
    dt: f64,
    start: OscillatorState,
    y_out: &mut [f64],
) -> Result<OscillatorState> {
    check(p, &[], dt, &start)?;
    into(y_out, path.len(), start, |s, emit| run_path(&Coefficients::of(p), p, s, path, dt, emit))
}

/// The output of one `f64` pass into `y_out` (of length `n`).
fn into(
    y_out: &mut [f64],
    n: usize,
    start: OscillatorState,
    pass: impl FnOnce(State<f64>, &mut dyn FnMut(&State<f64>)) -> State<f64>,
) -> Result<OscillatorState> {
    if y_out.len() != n {
        return Err(Error::LengthMismatch { what: "oscillator output", expected: n, found: y_out.len() });
    }
    let mut out = y_out.iter_mut();
    let s = State { y: start.y, v: start.v, z: start.z };
    let end = pass(s, &mut |s: &State<f64>| {
        if let Some(y) = out.next() {
            *y = s.y;
        }
    });
    Ok(OscillatorState { y: end.y, v: end.v, z: end.z })
}

/// Allocating form of [`simulate_into`]: returns `(y, final state)`.
pub fn simulate(
    p: &OscillatorParams,
    force: &[f64],
    dt: f64,
    start: OscillatorState,
) -> Result<(Vec<f64>, OscillatorState)> {
    let mut y = vec![0.0; force.len()];
    let end = simulate_into(p, force, dt, start, &mut y)?;
    Ok((y, end))
}

/// Allocating form of [`simulate_path_into`]: returns `(y, final state)`.
pub fn simulate_path(
    p: &OscillatorParams,
    path: &InputPath,
    dt: f64,
    start: OscillatorState,
) -> Result<(Vec<f64>, OscillatorState)> {
    let mut y = vec![0.0; path.len()];
    let end = simulate_path_into(p, path, dt, start, &mut y)?;
    Ok((y, end))
}

/// [`simulate`] with the exact Jacobian of y over all samples: returns `(y, jac)` with
/// `jac[k·10 + j]` = ∂y\[k\]/∂θⱼ for θ = [`UNKNOWNS`] (m, c, k, α, γ, δ, ν and the
/// initial state y0, v0, z0), row-major. One pass on [`Dual`] numbers that takes the
/// sub-steps of the `f64` simulation (the value part is the same numbers), so the
/// Jacobian is that of the discrete map computed.
pub fn simulate_with_jacobian(
    p: &OscillatorParams,
    force: &[f64],
    dt: f64,
    start: OscillatorState,
) -> Result<(Vec<f64>, Vec<f64>)> {
    check(p, force, dt, &start)?;
    Ok(with_jacobian(force.len(), start, |c, s, emit| run(c, p, s, &Lines { force, dt }, dt, emit), p))
}

/// [`simulate_with_jacobian`] with the force between samples given by `path`.
pub fn simulate_path_with_jacobian(
    p: &OscillatorParams,
    path: &InputPath,
    dt: f64,
    start: OscillatorState,
) -> Result<(Vec<f64>, Vec<f64>)> {
    check(p, &[], dt, &start)?;
    Ok(with_jacobian(path.len(), start, |c, s, emit| run_path(c, p, s, path, dt, emit), p))
}

/// The value and the Jacobian rows of one [`Dual`] pass over `n` samples.
fn with_jacobian(
    n: usize,
    start: OscillatorState,
    pass: impl FnOnce(&Coefficients<Dual<10>>, State<Dual<10>>, &mut dyn FnMut(&State<Dual<10>>)) -> State<Dual<10>>,
    p: &OscillatorParams,
) -> (Vec<f64>, Vec<f64>) {
    const M: usize = UNKNOWNS.len();
    let s = State { y: Dual::var(start.y, 7), v: Dual::var(start.v, 8), z: Dual::var(start.z, 9) };
    let mut y = Vec::with_capacity(n);
    let mut jac = Vec::with_capacity(n * M);
    pass(&Coefficients::<Dual<M>>::seeded(p), s, &mut |s: &State<Dual<M>>| {
        y.push(s.y.re);
        jac.extend(s.y.du.iter());
    });
    (y, jac)
}

/// A random-phase multisine \[N\]: `lines` cosines of equal amplitude at the
/// frequencies j/(period·dt) for j from round(f_lo·period·dt) to round(f_hi·period·dt),
/// with phases from a small linear congruential generator seeded by `seed`, scaled to
/// `rms` \[N\] and repeated `periods` times (`period` samples each). For tests and
/// benches: the benchmark's kind of excitation without its data.
pub fn multisine(period: usize, periods: usize, dt: f64, band_hz: (f64, f64), rms: f64, seed: u64) -> Vec<f64> {
    let span = period as f64 * dt;
    let lo = crate::math::round(band_hz.0 * span).max(1.0) as usize;
    let hi = (crate::math::round(band_hz.1 * span) as usize).min(period / 2 - 1).max(lo);
    let mut state = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    let phases: Vec<f64> = (lo..=hi)
        .map(|_| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 * core::f64::consts::PI
        })
        .collect();
    let amplitude = rms * crate::math::sqrt(2.0 / phases.len() as f64);
    let one: Vec<f64> = (0..period)
        .map(|k| {
            let t = k as f64 / period as f64;
            phases
                .iter()
                .enumerate()
                .map(|(i, &ph)| crate::math::cos(2.0 * core::f64::consts::PI * (lo + i) as f64 * t + ph))
                .sum::<f64>()
                * amplitude
        })
        .collect();
    (0..periods).flat_map(|_| one.iter().copied()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use integrator::rate;

    const DT: f64 = 1.0 / 750.0;
    const EPS: f64 = 1e-7;

    /// y over the intervals of `pieces` with the sub-step counts `plan` (the rule's, for
    /// the base run), on `f64`: finite differences across the rule's jumps would spoil
    /// the quotient.
    fn planned<P: Pieces>(p: &OscillatorParams, pieces: &P, start: OscillatorState, plan: &[Option<u32>]) -> Vec<f64> {
        let c = Coefficients::of(p);
        let mut s = State { y: start.y, v: start.v, z: start.z };
        let mut out = vec![s.y];
        for (k, &m) in (1..pieces.len()).zip(plan) {
            s = advance::<f64, false, P::F>(&c, s, &pieces.piece(k).0, DT, m);
            out.push(s.y);
        }
        out
    }

    /// The rule's plan for the intervals of `pieces` from `start`.
    fn plan_of<P: Pieces>(p: &OscillatorParams, pieces: &P, start: OscillatorState) -> Vec<Option<u32>> {
        let (c, rule) = (Coefficients::of(p), Rule::new(p, DT, pieces.force_omega(DT)));
        let (mut s, mut plan) = (State { y: start.y, v: start.v, z: start.z }, vec![]);
        for k in 1..pieces.len() {
            let (force, lo, hi) = pieces.piece(k);
            plan.push(rule.substeps::<false>(&s, lo, hi));
            s = advance::<f64, false, P::F>(&c, s, &force, DT, *plan.last().unwrap());
        }
        plan
    }

    /// Central differences of y over `pieces` in each unknown, the plan held, against the
    /// Jacobian's columns.
    fn check_columns<P: Pieces>(p: &OscillatorParams, pieces: &P, start: OscillatorState, jac: &[f64]) {
        let plan = plan_of(p, pieces, start);
        let n = pieces.len();
        for j in 0..UNKNOWNS.len() {
            let shifted = |d: f64| {
                let (mut q, mut s) = (*p, start);
                let v = [
                    &mut q.m,
                    &mut q.c,
                    &mut q.k,
                    &mut q.alpha,
                    &mut q.gamma,
                    &mut q.delta,
                    &mut q.nu,
                    &mut s.y,
                    &mut s.v,
                    &mut s.z,
                ];
                let eps = EPS * v[j].abs().max(1e-3);
                *v[j] += d * eps;
                (planned(&q, pieces, s, &plan), eps)
            };
            let ((up, eps), (down, _)) = (shifted(1.0), shifted(-1.0));
            let column: Vec<f64> = (0..n).map(|k| jac[k * UNKNOWNS.len() + j]).collect();
            let scale = column.iter().fold(0.0f64, |a, b| a.max(b.abs())).max(1e-300);
            let worst = (0..n).map(|k| ((up[k] - down[k]) / (2.0 * eps) - column[k]).abs()).fold(0.0, f64::max);
            assert!(worst <= 1e-6 * scale, "{}: worst {:e} of the column's largest", UNKNOWNS[j], worst / scale);
        }
    }

    #[test]
    fn the_jacobian_matches_finite_differences_and_its_values_are_the_simulation() {
        let force = multisine(1024, 1, DT, (5.0, 150.0), 50.0, 3);
        let sloped = OscillatorParams { nu: 1.7, beta: 30.0, ..OscillatorParams::benchmark() };
        let start = OscillatorState { y: 1e-4, v: -0.01, z: 2.0 };
        for p in [OscillatorParams::benchmark(), sloped] {
            let (y, jac) = simulate_with_jacobian(&p, &force, DT, start).unwrap();
            let (plain, _) = simulate(&p, &force, DT, start).unwrap();
            assert_eq!(y, plain, "the dual pass's values are the simulation's");
            let lines = Lines { force: &force, dt: DT };
            assert_eq!(planned(&p, &lines, start, &plan_of(&p, &lines, start)), plain);
            check_columns(&p, &lines, start, &jac);
        }
        // The held and the band-limited force, with the benchmark's parameters.
        let p = OscillatorParams::benchmark();
        for kind in [Reconstruction::Hold, Reconstruction::Bandlimited] {
            let path = InputPath::new(&force, kind, true).unwrap();
            let (y, jac) = simulate_path_with_jacobian(&p, &path, DT, start).unwrap();
            let (plain, _) = simulate_path(&p, &path, DT, start).unwrap();
            assert_eq!(y, plain, "{}: the dual pass's values are the simulation's", kind.name());
            match kind {
                Reconstruction::Hold => check_columns(&p, &Holds(&force), start, &jac),
                _ => check_columns(&p, &Smooths { path: &path, scale: 2.0 / DT }, start, &jac),
            }
        }
        // A linear path is the plain simulation.
        let path = InputPath::new(&force, Reconstruction::Linear, false).unwrap();
        assert_eq!(simulate_path(&p, &path, DT, start).unwrap(), simulate(&p, &force, DT, start).unwrap());
    }

    #[test]
    fn rejects_bad_parameters_by_name_and_non_finite_samples() {
        let good = OscillatorParams::benchmark();
        for (p, name) in [
            (OscillatorParams { m: 0.0, ..good }, "m"),
            (OscillatorParams { c: -1.0, ..good }, "c"),
            (OscillatorParams { k: -1.0, ..good }, "k"),
            (OscillatorParams { alpha: 0.0, ..good }, "alpha"),
            (OscillatorParams { beta: 0.0, ..good }, "beta"),
            (OscillatorParams { gamma: f64::NAN, ..good }, "gamma"),
            (OscillatorParams { nu: 0.5, ..good }, "nu"),
        ] {
            let err = simulate(&p, &[0.0, 1.0], DT, OscillatorState::default()).unwrap_err();
            assert!(matches!(err, Error::InvalidParameter { name: n, .. } if n == name), "{err}");
        }
        let err = simulate(&good, &[0.0, f64::NAN], DT, OscillatorState::default()).unwrap_err();
        assert!(matches!(err, Error::NonFiniteSample { name: "F", .. }));
        assert!(simulate(&good, &[0.0], 0.0, OscillatorState::default()).is_err());
        assert!(simulate(&good, &[0.0], DT, OscillatorState { z: f64::INFINITY, ..Default::default() }).is_err());
        assert_eq!(OscillatorParams::from_array(good.to_array()).unwrap(), good);
        assert_eq!(simulate(&good, &[], DT, OscillatorState::default()).unwrap().0.len(), 0);
    }

    #[test]
    fn at_rest_with_no_force_it_stays_at_rest() {
        let p = OscillatorParams::benchmark();
        let (y, end) = simulate(&p, &[0.0; 100], DT, OscillatorState::default()).unwrap();
        assert!(y.iter().all(|&v| v == 0.0) && end == OscillatorState::default());
        let s = State { y: 0.0, v: 0.0, z: 0.0 };
        assert_eq!(rate::<f64, true>(&Coefficients::of(&p), &s, 0.0), s);
    }
}
