//! The inverse against the model it inverts: round trips, limits, holds and bad input.

use super::*;
use crate::model::{paper_input, simulate};

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

#[test]
fn round_trip_on_the_paper_input() {
    let dt = 1e-4;
    let p = Params::paper_1hz();
    let u_true = paper_input(dt, 0.02);
    let (x_d, _) = simulate(&p, &u_true, dt, 0.0, None).unwrap();
    let (u, summary) = invert(&p, &x_d, dt, 0.0, None, VoltageLimits::NONE).unwrap();
    let (x, h) = simulate(&p, &u, dt, 0.0, None).unwrap();
    let err = max_diff(&x, &x_d);
    eprintln!("round trip {err:.2e} µm, {summary:?}");
    assert!(beyond_tolerance(&x, &x_d) <= 1e-12, "{err}");
    assert_eq!(h, summary.h_final);
    assert_eq!(summary.inexact_samples, 0);
    assert!(summary.max_evaluations <= MAX_EVALUATIONS);
    assert!(summary.mean_evaluations < 4.0, "{}", summary.mean_evaluations);
    // The voltages are the ones the record was made with, up to the tolerance
    // over the branch slope (≥ 0.1 µm/V here away from holds).
    assert!(max_diff(&u, &u_true) < 1e-4, "{}", max_diff(&u, &u_true));
}

#[test]
fn small_n_round_trip() {
    let dt = 1e-4;
    let p = Params { n: 0.6, beta: 0.05, gamma: 0.01, ..Params::paper_1hz() };
    let u_true: Vec<f64> =
        (0..8000).map(|k| 50.0 + 45.0 * (2.0 * std::f64::consts::PI * 7.0 * k as f64 * dt).sin()).collect();
    let (x_d, _) = simulate(&p, &u_true, dt, 0.3, None).unwrap();
    let (u, summary) = invert(&p, &x_d, dt, 0.3, None, VoltageLimits::NONE).unwrap();
    let (x, _) = simulate(&p, &u, dt, 0.3, None).unwrap();
    assert!(beyond_tolerance(&x, &x_d) <= 1e-12, "{} {summary:?}", max_diff(&x, &x_d));
}

#[test]
fn limits_clip_and_h_follows_the_clipped_voltage() {
    let dt = 1e-4;
    let p = Params::paper_1hz();
    let u_true = paper_input(dt, 0.0);
    let u_true = &u_true[..10_000];
    let (x_d, _) = simulate(&p, u_true, dt, 0.0, None).unwrap();
    let limits = VoltageLimits::new(Some(10.0), Some(80.0)).unwrap();
    let mut inv = Inverse::new(p, dt, 0.0, limits).unwrap();
    let mut u = Vec::new();
    let mut clipped = Vec::new();
    for &target in &x_d {
        u.push(inv.step(target).unwrap());
        clipped.push(inv.status().clip != Clip::None);
    }
    let (x, h) = simulate(&p, &u, dt, 0.0, None).unwrap();
    assert_eq!(h, inv.h());
    assert!(u.iter().all(|&v| (10.0..=80.0).contains(&v)));
    let n_clipped = clipped.iter().filter(|&&c| c).count();
    assert!(n_clipped > 1000, "{n_clipped}");
    assert_eq!(inv.status().clipped_samples, n_clipped as u64);
    for k in 0..x.len() {
        if clipped[k] {
            assert!(u[k] == 10.0 || u[k] == 80.0);
            let tol = tolerance(x_d[k]);
            let wrong_way = if u[k] == 10.0 { x[k] < x_d[k] - tol } else { x[k] > x_d[k] + tol };
            assert!(!wrong_way, "sample {k}: clipped on the wrong side");
        } else {
            assert!((x[k] - x_d[k]).abs() <= tolerance(x_d[k]) + 1e-12, "sample {k}: {} vs {}", x[k], x_d[k]);
        }
    }
}

#[test]
fn holds_are_exact_and_take_no_evaluation() {
    let dt = 1e-4;
    let p = Params::paper_1hz();
    let mut inv = Inverse::new(p, dt, 0.0, VoltageLimits::NONE).unwrap();
    inv.step(1.0).unwrap();
    let u = inv.step(5.0).unwrap();
    for _ in 0..10 {
        assert_eq!(inv.step(5.0).unwrap(), u);
        assert_eq!(inv.status().evaluations, 0);
    }
}

#[test]
fn reversal_inside_the_step_at_the_kink_is_bounded_by_it() {
    // A slow sine: near its turns the wanted move is below |δ·u|·Δt.
    let dt = 1e-4;
    let p = Params::paper_1hz();
    let x_d: Vec<f64> = (0..20_000).map(|k| 9.0 - 8.0 * (2.0 * std::f64::consts::PI * k as f64 * dt).cos()).collect();
    let (u, summary) = invert(&p, &x_d, dt, 0.0, None, VoltageLimits::NONE).unwrap();
    let (x, _) = simulate(&p, &u, dt, 0.0, None).unwrap();
    let bound = p.delta * u.iter().fold(0.0f64, |m, v| m.max(v.abs())) * dt;
    eprintln!(
        "inexact {} samples, max residual {:.2e} µm (bound {bound:.2e})",
        summary.inexact_samples, summary.max_residual_um
    );
    assert!(summary.inexact_samples > 0 && summary.inexact_samples < 200);
    assert!(max_diff(&x, &x_d) <= bound + 1e-9);
    assert!((summary.max_residual_um - max_diff(&x, &x_d)).abs() < 1e-12);
}

#[test]
fn rejects_bad_input_and_keeps_state() {
    let p = Params::paper_1hz();
    assert!(Inverse::new(p, 0.0, 0.0, VoltageLimits::NONE).is_err());
    assert!(VoltageLimits::new(Some(5.0), Some(1.0)).is_err());
    assert!(VoltageLimits::new(Some(f64::NAN), None).is_err());
    let mut inv = Inverse::new(p, 1e-4, 0.0, VoltageLimits::NONE).unwrap();
    inv.step(2.0).unwrap();
    let before = inv.clone();
    assert!(inv.step(f64::NAN).is_err());
    assert_eq!(inv, before);
    assert!(inv.set_params(Params { n: -1.0, ..p }).is_err());
    assert_eq!(inv, before);
    let mut empty = [0.0; 0];
    assert!(invert_into(&p, &[1.0], 1e-4, 0.0, None, VoltageLimits::NONE, &mut empty).is_err());
    assert!(invert(&p, &[1.0, f64::INFINITY], 1e-4, 0.0, None, VoltageLimits::NONE).is_err());
}

#[test]
fn chunks_give_the_same_result_as_one_call() {
    let dt = 1e-4;
    let p = Params::paper_1hz();
    let (x_d, _) = simulate(&p, &paper_input(dt, 0.01), dt, 0.0, None).unwrap();
    let (whole, s) = invert(&p, &x_d, dt, 0.0, None, VoltageLimits::NONE).unwrap();
    let (a, sa) = invert(&p, &x_d[..777], dt, 0.0, None, VoltageLimits::NONE).unwrap();
    let (b, sb) = invert(&p, &x_d[777..], dt, sa.h_final, Some(a[776]), VoltageLimits::NONE).unwrap();
    // |h|^n is computed afresh at the cut: the same to the last bits.
    let worst = [a, b].concat().iter().zip(&whole).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    assert!(worst <= 1e-9 && (sb.h_final - s.h_final).abs() <= 1e-12, "{worst}");
}

#[test]
fn odd_parameters_never_panic_and_stay_finite() {
    let dt = 1e-4;
    let targets: Vec<f64> = (0..2000).map(|k| 20.0 * ((k as f64) * 0.01).sin()).collect();
    // A model whose h runs away (β + γ < 0) is refused, not inverted.
    let runaway = Params { beta: -0.5, gamma: -0.5, n: 3.0, ..Params::paper_1hz() };
    assert!(matches!(
        invert(&runaway, &targets, dt, 0.0, None, VoltageLimits::NONE),
        Err(Error::InvalidParameter { name: "beta + gamma", .. })
    ));
    for p in [
        Params { kv: 0.0, a: 0.0, ..Params::paper_1hz() },
        Params { kv: -0.3, ..Params::paper_1hz() },
        Params { n: 0.2, beta: 2.0, gamma: 1.0, ..Params::paper_1hz() },
        Params { delta: -5.0, ..Params::paper_1hz() },
    ] {
        for limits in [VoltageLimits::NONE, VoltageLimits::new(Some(-10.0), Some(100.0)).unwrap()] {
            let (u, summary) = invert(&p, &targets, dt, 0.0, None, limits).unwrap();
            assert!(u.iter().all(|v| v.is_finite() && limits.contains(*v)), "{p:?}");
            assert!(summary.max_evaluations <= MAX_EVALUATIONS);
            let (x, _) = simulate(&p, &u, dt, 0.0, None).unwrap();
            assert!(x.iter().all(|v| v.is_finite()));
        }
    }
}
