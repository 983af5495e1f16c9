//! Latency per call, not only a median: p50 / p99 / p99.9 / max of every single call
//! over 10⁶ samples, and the channel bank's cost per frame from C = 1 to 1024, in one
//! run:
//!
//! ```text
//! cargo bench --bench latency            # a few minutes
//! cargo bench --bench latency -- --quick # 10⁵ samples, a smoke test
//! ```
//!
//! Data: the paper's input (1 Hz for 3 s, 10, 100, 200 Hz) at 10 kHz, repeated to 10⁶
//! samples, measured through the paper's 1 Hz model plus white noise whose standard
//! deviation steps through 1, 2, 3, 4, 5 nm from one repetition to the next.
//!
//! Timer: the time-stamp counter (`rdtsc` between `lfence`s) on x86-64, converted to
//! ns against `Instant` over 200 ms; `Instant` elsewhere. The cost of an empty
//! timed region (its median) is subtracted from every sample. On Linux the process is
//! pinned to one core (the last one) and, where permitted, runs under `SCHED_FIFO`
//! as a real-time loop would (`--no-rt` turns that off), so that other processes
//! on that core do not preempt it; the kernel's real-time throttling still takes
//! 50 ms of every second, which shows in the max column. Release build (`cargo bench`).
//!
//! Every row is replayed three times on fresh objects (the calls are deterministic):
//! the columns p50 … mean are the first replay's calls as a loop meets them; the
//! `work` columns are each call's minimum over the replays, its own cost without the
//! interrupts and preemptions the machine adds (which hit one call of one replay, not
//! the same call of all three). Two control rows of fixed work show what the machine
//! adds to a call of constant cost.
//!
//! Rows: `Model::step`; `Inverse::step` (the voltage for the model's own noise-free
//! displacement, beside `Model::step`: the ratio of their p50 is printed); `horizon` push without the input lag (`HorizonIdentifier::new`)
//! and with it (`HorizonIdentifier::recommended`, the default online method), the
//! latter in its three refine modes: sync (the pass in push), cooperative (push
//! timed, `refine(16)` called untimed after it) and background (the worker on
//! another core than the loop); `rpem`
//! push; the paper's method at N = 100 … 100 000; `simulate` throughput; and a hand-written floor: one RK4
//! step with one `powf` per sample (stage powers from its first-order expansion) and
//! a 7-parameter RLS update on fixed arrays, the least work any identifier of this
//! model can do per sample, timed the same way in the same run.
//!
//! After the table: the cost of the cooperative `refine` per window interval (the
//! Levenberg–Marquardt steps included) and the highest sample rate at which one core
//! runs both the loop's push and the window pass at the cadence of sync mode
//! (`samples_per_push` intervals per sample, as fresh estimates as sync).

use std::hint::black_box;
use std::time::Instant;

use boucwen::compensate::{Compensator, CompensatorConfig};
use boucwen::identify::{
    BackgroundHorizon, HorizonConfig, HorizonIdentifier, OnlineIdentifier, PaperConfig, PaperIdentifier, RefineMode,
    RpemConfig, RpemIdentifier,
};
use boucwen::model::paper_input;
use boucwen::{simulate_into, Bank, Inverse, Model, ModelBank, Params, VoltageLimits};

const DT: f64 = 1e-4;

// -- timer ---------------------------------------------------------------------------

#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn ticks() -> u64 {
    use core::arch::x86_64::{_mm_lfence, _rdtsc};
    // SAFETY: rdtsc and lfence exist on every x86-64 processor.
    unsafe {
        _mm_lfence();
        let t = _rdtsc();
        _mm_lfence();
        t
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn ticks() -> u64 {
    use std::sync::OnceLock;
    static START: OnceLock<Instant> = OnceLock::new();
    START.get_or_init(Instant::now).elapsed().as_nanos() as u64
}

struct Timer {
    ns_per_tick: f64,
    overhead: u64,
}

impl Timer {
    fn calibrate() -> Self {
        let (t0, i0) = (ticks(), Instant::now());
        while i0.elapsed().as_millis() < 200 {}
        let (t1, i1) = (ticks(), Instant::now());
        let ns_per_tick = (i1 - i0).as_nanos() as f64 / (t1 - t0) as f64;
        let mut empty: Vec<u64> = (0..100_000)
            .map(|_| {
                let a = ticks();
                let b = ticks();
                b - a
            })
            .collect();
        empty.sort_unstable();
        Timer { ns_per_tick, overhead: empty[empty.len() / 2] }
    }

    /// Times `f(k)` for k in 0..n, one call at a time; returns the ticks of each call.
    fn ticks_each(&self, n: usize, mut f: impl FnMut(usize)) -> Vec<u64> {
        let mut t = Vec::with_capacity(n);
        for k in 0..n {
            let a = ticks();
            f(k);
            let b = ticks();
            t.push((b - a).saturating_sub(self.overhead));
        }
        t
    }

    fn sorted_ns(&self, mut t: Vec<u64>) -> Vec<f64> {
        t.sort_unstable();
        t.into_iter().map(|v| v as f64 * self.ns_per_tick).collect()
    }

    /// Times `f(k)` for k in 0..n, one call at a time; returns the sorted ns.
    fn each(&self, n: usize, f: impl FnMut(usize)) -> Vec<f64> {
        self.sorted_ns(self.ticks_each(n, f))
    }

    /// As [`Timer::replayed`], with `between(object, k)` run untimed after each call.
    fn replayed_between<T>(
        &self,
        n: usize,
        make: impl Fn() -> T,
        mut call: impl FnMut(&mut T, usize),
        mut between: impl FnMut(&mut T, usize),
    ) -> (Vec<f64>, Vec<f64>) {
        let mut runs: Vec<Vec<u64>> = Vec::with_capacity(REPLAYS);
        for _ in 0..REPLAYS {
            let mut object = make();
            let mut t = Vec::with_capacity(n);
            for k in 0..n {
                let a = ticks();
                call(&mut object, k);
                let b = ticks();
                t.push((b - a).saturating_sub(self.overhead));
                between(&mut object, k);
            }
            runs.push(t);
        }
        let mut least = runs[0].clone();
        for run in &runs[1..] {
            for (m, &t) in least.iter_mut().zip(run) {
                *m = (*m).min(t);
            }
        }
        (self.sorted_ns(runs.swap_remove(0)), self.sorted_ns(least))
    }

    /// The same n calls on [`REPLAYS`] fresh objects from `make` (the calls are
    /// deterministic, so every replay does the same work at call k): the sorted ns of
    /// the first replay, as a loop meets them, and the sorted per-call minimum over
    /// the replays, the work of each call without what the machine adds (an interrupt
    /// or a preemption hits the same call of every replay with negligible probability).
    fn replayed<T>(&self, n: usize, make: impl Fn() -> T, mut call: impl FnMut(&mut T, usize)) -> (Vec<f64>, Vec<f64>) {
        let mut object = make();
        let first = self.ticks_each(n, |k| call(&mut object, k));
        let mut least = first.clone();
        for _ in 1..REPLAYS {
            let mut object = make();
            for (m, t) in least.iter_mut().zip(self.ticks_each(n, |k| call(&mut object, k))) {
                *m = (*m).min(t);
            }
        }
        (self.sorted_ns(first), self.sorted_ns(least))
    }
}

/// One call of the adaptive compensator for sample k: x_d = `desired[k]`, the
/// measurement of the previous sample `x[k − 1]`.
fn comp_step<I: OnlineIdentifier>(c: &mut Compensator<I>, desired: &[f64], x: &[f64], k: usize) {
    let x_meas = if k == 0 { None } else { Some(black_box(x[k - 1])) };
    black_box(c.step(black_box(desired[k]), x_meas).expect("finite"));
}

/// Replays of every identifier row (see [`Timer::replayed`]).
const REPLAYS: usize = 3;

#[cfg(target_os = "linux")]
fn pin_to_one_core() -> String {
    // SAFETY: plain libc calls on zeroed structs of this process.
    unsafe {
        let cores = libc::sysconf(libc::_SC_NPROCESSORS_ONLN).max(1) as usize;
        let core = cores - 1;
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(core, &mut set);
        let pinned = if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0 {
            format!("pinned to core {core} of {cores}")
        } else {
            "not pinned (sched_setaffinity failed)".into()
        };
        // As a real-time loop runs: SCHED_FIFO, so that ordinary processes on the same
        // core do not preempt the measurement (needs the privilege; else say so).
        let param = libc::sched_param { sched_priority: 10 };
        let policy = if std::env::args().any(|a| a == "--no-rt") {
            "normal scheduling (--no-rt)"
        } else if libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) == 0 {
            "SCHED_FIFO priority 10"
        } else {
            "normal scheduling (SCHED_FIFO not permitted)"
        };
        format!("{pinned}, {policy}")
    }
}

#[cfg(not(target_os = "linux"))]
fn pin_to_one_core() -> String {
    "not pinned".into()
}

/// Runs `make` with this thread's affinity set to the first core, so that a thread it
/// starts (the background worker) runs beside the loop's core, not on it; then pins
/// the thread back to the last core.
#[cfg(target_os = "linux")]
fn on_first_core<T>(make: impl FnOnce() -> T) -> T {
    // SAFETY: plain libc calls on zeroed structs of this process.
    unsafe {
        let cores = libc::sysconf(libc::_SC_NPROCESSORS_ONLN).max(1) as usize;
        let size = std::mem::size_of::<libc::cpu_set_t>();
        let mut first: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(0, &mut first);
        let mut last: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cores - 1, &mut last);
        libc::sched_setaffinity(0, size, &first);
        let out = make();
        libc::sched_setaffinity(0, size, &last);
        out
    }
}

#[cfg(not(target_os = "linux"))]
fn on_first_core<T>(make: impl FnOnce() -> T) -> T {
    make()
}

// -- data ----------------------------------------------------------------------------

/// xorshift64* and Box–Muller: deterministic N(0, 1) samples.
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
    }
}

/// The paper schedule repeated to `len` samples, and its measurement with 1–5 nm noise.
fn record(len: usize) -> (Vec<f64>, Vec<f64>) {
    let one = paper_input(DT, 0.05);
    let u: Vec<f64> = one.iter().copied().cycle().take(len).collect();
    let mut x = vec![0.0; len];
    simulate_into(&Params::paper_1hz(), &u, DT, 0.0, None, &mut x).expect("finite input");
    let mut noise = Noise(0x9e37_79b9_7f4a_7c15);
    for (k, v) in x.iter_mut().enumerate() {
        let sigma_um = 1e-3 * (1 + (k / one.len()) % 5) as f64;
        *v += sigma_um * noise.normal();
    }
    (u, x)
}

// -- the floor -------------------------------------------------------------------------

/// The least work per sample: one RK4 step with one `powf` (|h|^n at the stages from
/// its first-order expansion around the step's start) and a 7-parameter RLS update on
/// fixed arrays. Not an identifier anyone should use; a yardstick.
struct Floor {
    p: [f64; 7],
    h: f64,
    u_prev: f64,
    cov: [[f64; 7]; 7],
}

impl Floor {
    fn new(p: Params) -> Self {
        let mut cov = [[0.0; 7]; 7];
        for (i, row) in cov.iter_mut().enumerate() {
            row[i] = 1e-3;
        }
        Floor { p: p.to_array(), h: 0.0, u_prev: 0.0, cov }
    }

    #[inline(never)]
    fn push(&mut self, u: f64, x: f64) -> f64 {
        let [kv, x0, a, beta, gamma, n, delta] = self.p;
        let udot = (u - self.u_prev) / DT;
        let su = udot.signum();
        let h = self.h;
        let ah = h.abs();
        let hn = if ah > 0.0 { ah.powf(n) } else { 0.0 };
        let slope = if ah > 0.0 { n * hn / ah } else { 0.0 };
        let f = |hh: f64, uu: f64| {
            let p = hn + slope * (hh.abs() - ah);
            a * udot - (beta * udot.abs() * hh.signum() + gamma * udot) * p + delta * uu * su
        };
        let (u0, um) = (self.u_prev, 0.5 * (self.u_prev + u));
        let k1 = f(h, u0);
        let k2 = f(h + 0.5 * DT * k1, um);
        let k3 = f(h + 0.5 * DT * k2, um);
        let k4 = f(h + DT * k3, u);
        self.h = h + DT / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
        self.u_prev = u;
        let pred = kv * u + x0 + self.h;
        let phi = [u, 1.0, udot * DT, -udot.abs() * DT * hn, -udot * DT * hn, 0.0, u * su * DT];
        let mut pphi = [0.0; 7];
        for (out, row) in pphi.iter_mut().zip(&self.cov) {
            *out = row.iter().zip(&phi).map(|(c, f)| c * f).sum::<f64>();
        }
        let s = 1e-4 + (0..7).map(|i| phi[i] * pphi[i]).sum::<f64>();
        let e = x - pred;
        for ((p, row), &pp) in self.p.iter_mut().zip(self.cov.iter_mut()).zip(&pphi) {
            let k = pp / s;
            *p += k * e * 1e-3;
            for (c, &pj) in row.iter_mut().zip(&pphi) {
                *c -= k * pj;
            }
        }
        self.p[5] = n;
        pred
    }
}

// -- report --------------------------------------------------------------------------

struct Row {
    name: String,
    sorted_ns: Vec<f64>,
    /// Per-call minimum over the replays, sorted.
    work_ns: Vec<f64>,
    target: &'static str,
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * q).round() as usize;
    sorted[i]
}

fn print_rows(rows: &[Row], floor_p50: f64) {
    println!(
        "| call | samples | p50 ns | p99 ns | p99.9 ns | max ns | mean ns | work p99 ns | work p99.9 ns | work max ns \
         | p50 / floor | target |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    for r in rows {
        let (s, w) = (&r.sorted_ns, &r.work_ns);
        let mean = s.iter().sum::<f64>() / s.len() as f64;
        println!(
            "| {} | {} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.2} | {} |",
            r.name,
            s.len(),
            quantile(s, 0.5),
            quantile(s, 0.99),
            quantile(s, 0.999),
            s[s.len() - 1],
            mean,
            quantile(w, 0.99),
            quantile(w, 0.999),
            w[w.len() - 1],
            quantile(s, 0.5) / floor_p50,
            r.target
        );
    }
}

/// A fixed amount of work: `steps` dependent multiply-adds (a control row: what the
/// machine adds to a call of known, constant cost).
#[inline(never)]
fn fixed_work(seed: f64, steps: usize) -> f64 {
    let mut v = seed;
    for _ in 0..steps {
        v = black_box(v * 0.999_999 + 1e-9);
    }
    v
}

/// [`Timer::replayed`] of `push` over the record, on identifiers from `make`.
fn pushes<I: OnlineIdentifier>(timer: &Timer, u: &[f64], x: &[f64], make: impl Fn() -> I) -> (Vec<f64>, Vec<f64>) {
    timer.replayed(u.len(), make, |id, k| {
        black_box(id.push(black_box(u[k]), black_box(x[k])).expect("finite"));
    })
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let len = if quick { 100_000 } else { 1_000_000 };
    let pinned = pin_to_one_core();
    let timer = Timer::calibrate();
    println!(
        "latency per call over {len} samples (paper schedule repeated, 1–5 nm noise); {pinned}; \
         timer {:.3} ns/tick, overhead {} ticks subtracted; work = per-call minimum over {REPLAYS} replays",
        timer.ns_per_tick, timer.overhead
    );
    let (u, x) = record(len);
    let p = Params::paper_1hz();
    let mut rows = Vec::new();
    let mut row = |name: String, (sorted_ns, work_ns): (Vec<f64>, Vec<f64>), target| {
        rows.push(Row { name, sorted_ns, work_ns, target });
    };

    for steps in [60usize, 400] {
        let times = timer.replayed(
            len,
            || (),
            |_, k| {
                black_box(fixed_work(black_box(k as f64), steps));
            },
        );
        row(format!("control: fixed work, {steps} dependent multiply-adds"), times, "");
    }
    let times = timer.replayed(
        len,
        || Floor::new(p),
        |f, k| {
            black_box(f.push(black_box(u[k]), black_box(x[k])));
        },
    );
    let floor_p50 = quantile(&times.0, 0.5);
    row("floor: RK4 + one powf + 7-parameter RLS".into(), times, "");

    let times = timer.replayed(
        len,
        || Model::new(p, DT, 0.0).expect("valid"),
        |m, k| {
            black_box(m.step(black_box(u[k])).expect("finite"));
        },
    );
    let step_p50 = quantile(&times.0, 0.5);
    row("`Model::step`".into(), times, "p50 ≤ 60");

    // The inverse finds again the voltages of the model's own (noise-free) displacement.
    let mut desired = vec![0.0; len];
    simulate_into(&p, &u, DT, 0.0, None, &mut desired).expect("finite");
    let times = timer.replayed(
        len,
        || Inverse::new(p, DT, 0.0, VoltageLimits::NONE).expect("valid"),
        |inv, k| {
            black_box(inv.step(black_box(desired[k])).expect("finite"));
        },
    );
    let inverse_p50 = quantile(&times.0, 0.5);
    row("`Inverse::step`".into(), times, "p50 ≤ 2 × `Model::step`");

    let times = pushes(&timer, &u, &x, || HorizonIdentifier::new(DT, p, 0.0, HorizonConfig::default()).expect("valid"));
    row("`horizon` push, no lag".into(), times, "p99.9 ≤ 2000");
    let times =
        pushes(&timer, &u, &x, || HorizonIdentifier::recommended(DT, p, 0.0, HorizonConfig::default()).expect("valid"));
    row("`horizon` push, `recommended` (default method), sync".into(), times, "p99.9 ≤ 2000");
    let cooperative = || {
        HorizonIdentifier::recommended(DT, p, 0.0, HorizonConfig::default())
            .expect("valid")
            .with_mode(RefineMode::Cooperative)
    };
    let spp = HorizonConfig::default().samples_per_push;
    let times = timer.replayed_between(
        len,
        cooperative,
        |id, k| {
            black_box(id.push(black_box(u[k]), black_box(x[k])).expect("finite"));
        },
        |id, _| {
            black_box(id.refine(spp));
        },
    );
    let push_p50 = quantile(&times.0, 0.5);
    row(
        format!("`horizon` push, `recommended`, cooperative (`refine({spp})` untimed between)"),
        times,
        "p50 ≤ 150, p99.9 ≤ 500",
    );
    let times = pushes(&timer, &u, &x, || {
        on_first_core(|| BackgroundHorizon::recommended(DT, p, 0.0, HorizonConfig::default()).expect("valid"))
    });
    row("`horizon` push, `recommended`, background (worker on core 0)".into(), times, "p50 ≤ 150, p99.9 ≤ 500");
    let times = pushes(&timer, &u, &x, || RpemIdentifier::new(DT, p, 0.0, RpemConfig::default()).expect("valid"));
    row("`rpem` push".into(), times, "p50 ≤ 200, p99.9 ≤ 1000");
    // The adaptive compensator, one call per sample: x_d = the model's own displacement,
    // the measurement of the previous sample from the record (the cost of a push and an
    // inversion; not a closed loop).
    let limits = VoltageLimits::new(Some(-30.0), Some(120.0)).expect("valid");
    let times = timer.replayed(
        len,
        || {
            let id = RpemIdentifier::new(DT, p, 0.0, RpemConfig::for_tracking()).expect("valid");
            Compensator::new(id, DT, limits, CompensatorConfig::default()).expect("valid")
        },
        |c, k| comp_step(c, &desired, &x, k),
    );
    row("`Compensator::step`, rpem".into(), times, "");
    let times = timer.replayed_between(
        len,
        || Compensator::new(cooperative(), DT, limits, CompensatorConfig::default()).expect("valid"),
        |c, k| comp_step(c, &desired, &x, k),
        |c, _| {
            black_box(c.refine(2 * spp));
        },
    );
    row(
        format!("`Compensator::step`, recommended, lag inverted, cooperative (`refine({})` untimed)", 2 * spp),
        times,
        "",
    );
    for window in [100usize, 1_000, 10_000, 100_000] {
        let times = pushes(&timer, &u, &x, || {
            PaperIdentifier::new(DT, p, 0.0, PaperConfig::with_window(window)).expect("valid")
        });
        row(format!("`paper` push, N = {window}"), times, "p99.9 ≤ 1000");
    }
    print_rows(&rows, floor_p50);
    println!("\n`Inverse::step` / `Model::step` at p50: {:.2} (target ≤ 2)", inverse_p50 / step_p50);
    refine_cost(&timer, &u, &x, push_p50);

    let mut out = vec![0.0; len];
    let best = (0..5)
        .map(|_| {
            let t = Instant::now();
            simulate_into(&p, black_box(&u), DT, 0.0, None, &mut out).expect("finite");
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min);
    println!(
        "\n`simulate`: {:.1} ns/sample = {:.1} M samples/s (best of 5 over {len} samples; target ≥ 15 M/s)",
        best * 1e9 / len as f64,
        len as f64 / best / 1e6
    );

    bank_scaling(&timer, &u, &x, quick);
}

/// The cooperative `refine` per window interval: the record pushed with `refine(B)`
/// after every E-th push, each refine call timed (B = 16 every push, 256 every 16th:
/// the same 16 intervals a sample on average; the best of the replays), and the sample
/// rate one core sustains at sync's cadence.
fn refine_cost(timer: &Timer, u: &[f64], x: &[f64], push_p50: f64) {
    let p = Params::paper_1hz();
    let spp = HorizonConfig::default().samples_per_push;
    println!("\ncooperative `refine` (recommended identifier), cost per window interval:");
    let mut per_interval = f64::INFINITY;
    for (budget, every) in [(spp, 1), (256, 256 / spp)] {
        let mut best = f64::INFINITY;
        let mut updates = 0;
        for _ in 0..REPLAYS {
            let mut id = HorizonIdentifier::recommended(DT, p, 0.0, HorizonConfig::default())
                .expect("valid")
                .with_mode(RefineMode::Cooperative);
            let (mut ticks_sum, mut intervals) = (0u64, 0usize);
            for k in 0..u.len() {
                id.push(u[k], x[k]).expect("finite");
                if k % every != every - 1 {
                    continue;
                }
                let a = ticks();
                let ran = black_box(id.refine(budget));
                let b = ticks();
                ticks_sum += (b - a).saturating_sub(timer.overhead);
                intervals += ran;
            }
            best = best.min(ticks_sum as f64 * timer.ns_per_tick / intervals.max(1) as f64);
            updates = id.status().updates;
        }
        per_interval = per_interval.min(best);
        println!(
            "  refine({budget}) after every {every} push(es): {best:.1} ns per interval ({updates} updates over the record)"
        );
    }
    let per_sample = push_p50 + spp as f64 * per_interval;
    println!(
        "  one core, push (p50 {push_p50:.0} ns) + {spp} intervals per sample (sync's cadence): {per_sample:.0} ns per \
         sample, window pass up to date up to {:.0} kHz",
        1e6 / per_sample
    );
}

/// ns per frame of the bank, C = 1 … 1024: rpem push (identifier per channel) and the
/// models' step. Channel c reads the record from offset 977·c.
fn bank_scaling(timer: &Timer, u: &[f64], x: &[f64], quick: bool) {
    println!("\nbank: one call per frame, ns per frame (per channel)");
    println!("| C | rpem push p50 | rpem push p99 | models step p50 | models step p99 |");
    println!("|---:|---:|---:|---:|---:|");
    let p = Params::paper_1hz();
    for channels in [1usize, 4, 16, 64, 256, 1024] {
        let frames = if quick { 500 } else { (400_000 / channels).clamp(2_000, 100_000) };
        let mut uf = vec![0.0; frames * channels];
        let mut xf = vec![0.0; frames * channels];
        for c in 0..channels {
            for t in 0..frames {
                let k = (t + 977 * c) % u.len();
                uf[t * channels + c] = u[k];
                xf[t * channels + c] = x[k];
            }
        }
        let id = RpemIdentifier::new(DT, p, 0.0, RpemConfig::default()).expect("valid");
        let mut bank = Bank::new(channels, id, DT).expect("valid");
        let mut models = ModelBank::new(channels, p, DT, 0.0).expect("valid");
        let mut out = vec![0.0; channels];
        let push = timer.each(frames, |t| {
            let r = t * channels..(t + 1) * channels;
            bank.push(&uf[r.clone()], &xf[r], &mut out).expect("finite");
            black_box(&out);
        });
        let step = timer.each(frames, |t| {
            models.step(&uf[t * channels..(t + 1) * channels], &mut out).expect("finite");
            black_box(&out);
        });
        let cell = |s: &[f64], q: f64| {
            let v = quantile(s, q);
            format!("{:.0} ({:.0})", v, v / channels as f64)
        };
        println!(
            "| {channels} | {} | {} | {} | {} |",
            cell(&push, 0.5),
            cell(&push, 0.99),
            cell(&step, 0.5),
            cell(&step, 0.99)
        );
    }
    println!("targets: C = 256 rpem ≤ 100 000 ns per frame; C = 1024 models ≤ 50 000 ns per frame");
}
