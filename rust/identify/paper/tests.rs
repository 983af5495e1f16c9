//! Tests of the paper's identifier.

use super::*;
use crate::model::{paper_input, simulate};

fn run(decomposition: Decomposition) -> (Vec<f64>, Vec<f64>, PaperIdentifier) {
    let dt = 1e-4;
    let u = paper_input(dt, 0.05);
    let truth = Params::paper_1hz();
    let (x, _) = simulate(&truth, &u, dt, 0.0, None).unwrap();
    let cfg = PaperConfig { decomposition, ..PaperConfig::with_window(10_000) };
    let mut id = PaperIdentifier::new(dt, truth, 0.0, cfg).unwrap();
    let pred: Vec<f64> = u.iter().zip(&x).map(|(&u, &x)| id.push(u, x).unwrap()).collect();
    (x, pred, id)
}

#[test]
fn started_from_the_truth_it_stays_close() {
    let (x, pred, id) = run(Decomposition::Model);
    let worst = x.iter().zip(&pred).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(worst < 0.5, "max prediction error {worst} µm");
    assert!(id.params().validate().is_ok());
}

#[test]
fn rls_recursion_agrees_with_the_exact_window_fit() {
    let (_, _, id) = run(Decomposition::Line);
    let (rls, exact) = id.line_fit_check().expect("step 1 active");
    // The recursion re-synchronises every N samples; in between, rank-one
    // updates on a 2×2 system with |u| ≤ 100 lose at most a few ulps per step.
    for i in 0..2 {
        assert!((rls[i] - exact[i]).abs() <= 1e-8 * (1.0 + exact[i].abs()), "{rls:?} vs {exact:?}");
    }
}

#[test]
fn rejected_samples_leave_no_trace() {
    let cfg = PaperConfig::with_window(64);
    let mut id = PaperIdentifier::new(1e-3, Params::paper_1hz(), 0.0, cfg).unwrap();
    for k in 0..200 {
        let u = 50.0 + 50.0 * (k as f64 * 0.05).sin();
        id.push(u, 0.18 * u).unwrap();
    }
    let before = id.clone();
    assert!(id.push(f64::NAN, 1.0).is_err());
    assert!(id.push(1.0, f64::INFINITY).is_err());
    assert_eq!(id, before);
}

#[test]
fn constant_input_holds_the_estimates() {
    let cfg = PaperConfig::with_window(64);
    let mut id = PaperIdentifier::new(1e-3, Params::paper_1hz(), 0.0, cfg).unwrap();
    for _ in 0..10_000 {
        let x = id.push(20.0, 3.8).unwrap();
        assert!(x.is_finite());
    }
    assert!(id.params().to_array().iter().all(|v| v.is_finite()));
    assert_eq!(id.status().line_fit, SubFit::Held);
}
