//! criterion bench of the hysteretic oscillator (`boucwen::oscillator`): `simulate_into`
//! and `simulate_with_jacobian` over the benchmark's kind of record (a 5–150 Hz
//! random-phase multisine of 50 N RMS at 750 Hz, 5 periods of 8192 samples) with the
//! benchmark's parameters. Run with `cargo bench --bench oscillator`; throughput in
//! samples per second (criterion's "elem/s").

use std::hint::black_box;

use boucwen::oscillator::{multisine, simulate_into, simulate_with_jacobian, OscillatorParams, OscillatorState};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

const DT: f64 = 1.0 / 750.0;

fn oscillator(c: &mut Criterion) {
    let force = multisine(8192, 5, DT, (5.0, 150.0), 50.0, 1);
    let p = OscillatorParams::benchmark();
    let mut y = vec![0.0; force.len()];
    let mut group = c.benchmark_group("oscillator");
    group.throughput(Throughput::Elements(force.len() as u64));
    group.sample_size(20);
    group.bench_function("simulate", |b| {
        b.iter(|| simulate_into(&p, black_box(&force), DT, OscillatorState::default(), &mut y).expect("valid"))
    });
    group.sample_size(10);
    group.bench_function("simulate_with_jacobian", |b| {
        b.iter(|| simulate_with_jacobian(&p, black_box(&force), DT, OscillatorState::default()).expect("valid"))
    });
    group.finish();
}

criterion_group!(benches, oscillator);
criterion_main!(benches);
