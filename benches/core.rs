//! criterion benches of the per-sample paths: one warmed `push` per method and
//! window length, `push_many` over a record, `simulate` on the paper's input, one
//! `Model::step`, one `Inverse::step` and one adaptive `Compensator::step` beside it. Run with `cargo bench --bench core`; every group reports its
//! throughput in samples per second (criterion's "elem/s").

use std::hint::black_box;

use boucwen::identify::{AnyIdentifier, OnlineIdentifier, PaperConfig, PaperIdentifier};
use boucwen::model::paper_input;
use boucwen::{simulate_into, Model, Params};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};

const DT: f64 = 1e-4;

fn record() -> (Vec<f64>, Vec<f64>) {
    let u = paper_input(DT, 0.05);
    let mut x = vec![0.0; u.len()];
    simulate_into(&Params::paper_1hz(), &u, DT, 0.0, None, &mut x).expect("valid input");
    (u, x)
}

/// The paper's steps alone: the output gate and the window fit off (their O(N) work is
/// measured by `push_defaults`).
fn steps_only(window: usize) -> PaperConfig {
    PaperConfig { output_gate: f64::INFINITY, fit_iterations: 0, ..PaperConfig::with_window(window) }
}

/// One warmed `push` per window, in the group `name`, with the config `config(window)`.
fn push_group(c: &mut Criterion, name: &str, windows: &[usize], config: impl Fn(usize) -> PaperConfig) {
    let (u, x) = record();
    let mut group = c.benchmark_group(name);
    group.throughput(Throughput::Elements(1));
    for &window in windows {
        let mut id = PaperIdentifier::new(DT, Params::paper_1hz(), 0.0, config(window)).expect("valid config");
        // Warm up past the first full window so every sub-fit runs.
        let mut k = 0usize;
        for _ in 0..(window + 1000).min(u.len()) {
            id.push(u[k], x[k]).expect("finite");
            k = (k + 1) % u.len();
        }
        group.bench_with_input(BenchmarkId::from_parameter(window), &window, |b, _| {
            b.iter(|| {
                let y = id.push(black_box(u[k]), black_box(x[k])).expect("finite");
                k = (k + 1) % u.len();
                y
            })
        });
    }
    group.finish();
}

/// The paper's steps per push: O(1) in N.
fn push(c: &mut Criterion) {
    push_group(c, "paper_push", &[100, 1_000, 10_000, 100_000], steps_only);
}

/// The defaults per push, averaged over many pushes: the output gate simulates the
/// window where a step proposes an update (O(N) per push), the window fit refits it once
/// per `fit_every`·N points (its cost per push averages to a constant).
fn push_defaults(c: &mut Criterion) {
    push_group(c, "paper_push_defaults", &[100, 1_000], PaperConfig::with_window);
}

/// `push_many` over the whole paper record (3.38 s at 10 kHz), windows 1 000 and 10 000,
/// the paper's steps alone, from a warmed identifier: the batch path a Python caller gets
/// with one call.
fn push_many(c: &mut Criterion) {
    let (u, x) = record();
    let mut out = vec![0.0; u.len()];
    let mut group = c.benchmark_group("paper_push_many");
    group.throughput(Throughput::Elements(u.len() as u64));
    group.sample_size(20);
    for window in [1_000usize, 10_000] {
        let mut id = AnyIdentifier::Paper(
            PaperIdentifier::new(DT, Params::paper_1hz(), 0.0, steps_only(window)).expect("valid config"),
        );
        id.push_many(&u, &x, &mut out).expect("finite");
        group.bench_with_input(BenchmarkId::from_parameter(window), &window, |b, _| {
            b.iter(|| id.push_many(black_box(&u), black_box(&x), &mut out).expect("finite"))
        });
    }
    group.finish();
}

fn simulate(c: &mut Criterion) {
    let (u, _) = record();
    let mut out = vec![0.0; u.len()];
    let mut group = c.benchmark_group("simulate");
    group.throughput(Throughput::Elements(u.len() as u64));
    group.bench_function("paper_input", |b| {
        b.iter(|| simulate_into(&Params::paper_1hz(), black_box(&u), DT, 0.0, None, &mut out).expect("finite"))
    });
    group.finish();
}

fn model_step(c: &mut Criterion) {
    let (u, _) = record();
    let mut model = Model::new(Params::paper_1hz(), DT, 0.0).expect("valid");
    let mut k = 0usize;
    let mut group = c.benchmark_group("model_step");
    group.throughput(Throughput::Elements(1));
    group.bench_function("paper_1hz", |b| {
        b.iter(|| {
            let y = model.step(black_box(u[k])).expect("finite");
            k = (k + 1) % u.len();
            y
        })
    });
    group.finish();
}

/// One warmed push of the output-error method ("rpem"), past the first 1 Hz period.
fn rpem_push(c: &mut Criterion) {
    use boucwen::identify::{RpemConfig, RpemIdentifier};
    let (u, x) = record();
    let mut id = RpemIdentifier::new(DT, Params::paper_1hz(), 0.0, RpemConfig::default()).expect("valid config");
    let mut k = 0usize;
    for _ in 0..12_000 {
        id.push(u[k], x[k]).expect("finite");
        k = (k + 1) % u.len();
    }
    let mut group = c.benchmark_group("rpem_push");
    group.throughput(Throughput::Elements(1));
    group.bench_function("paper_1hz", |b| {
        b.iter(|| {
            let y = id.push(black_box(u[k]), black_box(x[k])).expect("finite");
            k = (k + 1) % u.len();
            y
        })
    });
    group.finish();
}

/// One warmed `Inverse::step` on the paper record's displacement (the voltages that
/// produced it are found again), beside `Model::step`. Prints the integrator
/// evaluations per sample of that record once (the solver's Newton/secant iterations).
fn inverse_step(c: &mut Criterion) {
    use boucwen::compensate::{invert, Inverse, VoltageLimits, MAX_EVALUATIONS};
    let (_, x) = record();
    let p = Params::paper_1hz();
    let (_, summary) = invert(&p, &x, DT, 0.0, None, VoltageLimits::NONE).expect("finite");
    eprintln!(
        "inverse on the paper record: {:.2} integrator evaluations per sample on average, at most {} (bound {})",
        summary.mean_evaluations, summary.max_evaluations, MAX_EVALUATIONS
    );
    let mut inv =
        Inverse::new(p, DT, 0.0, VoltageLimits::new(Some(-30.0), Some(120.0)).expect("valid")).expect("valid");
    let mut k = 0usize;
    for _ in 0..12_000 {
        inv.step(x[k]).expect("finite");
        k = (k + 1) % x.len();
    }
    let mut group = c.benchmark_group("inverse_step");
    group.throughput(Throughput::Elements(1));
    group.bench_function("paper_1hz", |b| {
        b.iter(|| {
            let u = inv.step(black_box(x[k])).expect("finite");
            k = (k + 1) % x.len();
            u
        })
    });
    group.finish();
}

/// One warmed step of the adaptive compensator (rpem identifier + inverse + PI) in a
/// closed loop around a plant (the paper's model, one `Model::step` per iteration, which
/// the figure includes), tracking the paper record's displacement, past 12 000 samples.
fn compensator_step(c: &mut Criterion) {
    use boucwen::compensate::{Compensator, CompensatorConfig, PidGains, VoltageLimits};
    use boucwen::identify::{RpemConfig, RpemIdentifier};
    let (_, x) = record();
    let start = Params { kv: 0.2, a: -0.08, ..Params::paper_1hz() };
    let id = RpemIdentifier::new(DT, start, 0.0, RpemConfig::for_tracking()).expect("valid config");
    let config = CompensatorConfig { gains: PidGains::pi(0.0, 200.0), ..CompensatorConfig::default() };
    let limits = VoltageLimits::new(Some(-30.0), Some(120.0)).expect("valid");
    let mut comp = Compensator::new(id, DT, limits, config).expect("valid");
    let mut plant = Model::new(Params::paper_1hz(), DT, 0.0).expect("valid");
    let mut x_meas = None;
    let mut k = 0usize;
    for _ in 0..12_000 {
        x_meas = Some(plant.step(comp.step(x[k], x_meas).expect("finite")).expect("finite"));
        k = (k + 1) % x.len();
    }
    let mut group = c.benchmark_group("compensator_step");
    group.throughput(Throughput::Elements(1));
    group.bench_function("adaptive_pi_with_plant", |b| {
        b.iter(|| {
            let u = comp.step(black_box(x[k]), x_meas).expect("finite");
            x_meas = Some(plant.step(u).expect("finite"));
            k = (k + 1) % x.len();
            u
        })
    });
    group.finish();
}

criterion_group!(
    benches,
    push,
    push_defaults,
    push_many,
    simulate,
    model_step,
    rpem_push,
    inverse_step,
    compensator_step
);
criterion_main!(benches);
