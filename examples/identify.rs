//! Identify the asymmetric Bouc–Wen model online in a 10 kHz loop, then run the
//! identified model open loop over the next period and compare.
//!
//! Run: `cargo run --release --example identify`

use boucwen::identify::{HorizonConfig, HorizonIdentifier, OnlineIdentifier};
use boucwen::{simulate, Model, Params};

fn main() -> Result<(), boucwen::Error> {
    let dt = 1e-4; // s
                   // A "measured" record: the paper's 1 Hz model driven at 10 Hz, 0–100 V.
    let truth = Params::paper_1hz();
    let u: Vec<f64> =
        (0..20_000).map(|k| 50.0 - 50.0 * (2.0 * std::f64::consts::PI * 10.0 * k as f64 * dt).cos()).collect();
    let (x, _) = simulate(&truth, &u, dt, 0.0, None)?;
    // Start 15 % off in A, β and γ (inside the admissible region: β ± γ ≥ 0).
    let start = Params { a: truth.a * 1.15, beta: truth.beta * 1.15, gamma: truth.gamma * 0.85, ..truth };
    let mut id = HorizonIdentifier::new(dt, start, 0.0, HorizonConfig::default())?;
    let mut worst_late = 0.0f64;
    for (k, (&uk, &xk)) in u.iter().zip(&x).enumerate() {
        let x_hat = id.push(uk, xk)?; // the model's prediction, before xk is used
        if k >= 19_000 {
            worst_late = worst_late.max((x_hat - xk).abs());
        }
    }
    // The identified model, frozen, run open loop over the next period.
    let mut model = Model::new(id.params(), dt, id.h())?;
    model.set_state(boucwen::ModelState { h: id.h(), u_prev: Some(u[u.len() - 1]) })?;
    // The true actuator, brought to the same point of the record.
    let mut truth_model = Model::new(truth, dt, 0.0)?;
    for &uk in &u {
        truth_model.step(uk)?;
    }
    let mut open_loop_err = 0.0f64;
    for (k, &uk) in u.iter().take(1000).enumerate() {
        let predicted = model.step(uk)?;
        let actual = truth_model.step(uk)?;
        if k > 0 {
            open_loop_err = open_loop_err.max((predicted - actual).abs());
        }
    }
    let s = id.status();
    println!("updates {}, window {} samples ({:.0} V of travel)", s.updates, s.window_samples, s.window_travel_v);
    println!("identified {:?}", id.params());
    println!("max |x - x_hat| over the last 0.1 s, one step ahead: {worst_late:.2e} µm");
    println!("max |x - x_hat| over the next period, open loop:     {open_loop_err:.2e} µm");
    Ok(())
}
