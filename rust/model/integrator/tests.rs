//! The integrator against finite differences, `powf`, its generic path and its lanes.

use super::*;

#[test]
fn series_power_matches_powf_where_it_is_used() {
    for n in [0.3, 1.0, 1.52, 2.7, 4.9] {
        for h_ref in [-3.0, -0.01, 1e-3, 0.7, 12.0] {
            let near = NearPower::new(n, h_ref, abs_pow(h_ref, n), None, true);
            let mut used = 0;
            for k in -25..=25 {
                let h = h_ref * (1.0 + 0.001 * k as f64);
                if let Some(e) = near.valid((h - h_ref) / h_ref) {
                    let exact = abs_pow(h, n);
                    let v = near.power(e);
                    // The dropped ε⁵ term: at most 0.02⁵·|c₅| relative, |c₅| < 1.
                    assert!(((v - exact) / exact).abs() < 3.3e-9, "n={n} h={h}: {v} vs {exact}");
                    assert!((near.ln(e) - h.abs().ln()).abs() < 1e-10);
                    used += 1;
                }
            }
            // |ε| ≤ 0.02: k = −19 … 19, and ±20 where ε rounds to 0.02 or below.
            assert!((39..=41).contains(&used), "n={n} h_ref={h_ref}: {used} states on the series");
            assert!(near.valid((-h_ref - h_ref) / h_ref).is_none());
        }
    }
}

/// h after `u` (from h = 0) and its gradient over (A, β, γ, n, δ).
fn run(p: &Params, u: &[f64], dt: f64) -> (f64, [f64; 5]) {
    let c = Coefficients::<Dual<5>>::seeded(p, 0);
    let mut h = Dual::cst(0.0);
    for w in u.windows(2) {
        let next = advance(p, &c, h, Dual::cst(w[0]), Dual::cst(w[1]), dt);
        assert_eq!(next.re, advance_h(p, h.re, w[0], w[1], dt), "the dual value is the model's h");
        h = next;
    }
    (h.re, h.du.into())
}

#[test]
fn sensitivities_match_finite_differences_on_steps_holds_reversals_and_stiff_intervals() {
    let dt = 1e-4;
    let ramp = |a: f64, b: f64, k: usize| (0..k).map(move |i| a + (b - a) * i as f64 / (k - 1) as f64);
    let cases: Vec<(&str, Params, Vec<f64>)> = vec![
        // 0 -> 95 V in one sample: the end-point stiffness check sends it to more sub-steps.
        ("step", Params::paper_1hz(), vec![0.0, 95.0, 95.0]),
        ("hold", Params::paper_1hz(), ramp(0.0, 40.0, 50).chain(std::iter::repeat_n(40.0, 50)).collect()),
        ("reversal", Params::paper_1hz(), ramp(0.0, 60.0, 80).chain(ramp(60.0, 10.0, 80)).collect()),
        ("n < 1", Params { n: 0.64, ..Params::paper_1hz() }, ramp(0.0, 50.0, 60).chain(ramp(50.0, 5.0, 60)).collect()),
        (
            "stiff",
            Params { beta: 0.4, gamma: 0.1, n: 2.5, ..Params::paper_1hz() },
            ramp(0.0, 100.0, 20).chain(ramp(100.0, 0.0, 20)).collect(),
        ),
    ];
    for (name, p, u) in cases {
        let (_, grad) = run(&p, &u, dt);
        let largest = grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        for (i, g) in grad.iter().enumerate() {
            let eps = 1e-6 * [p.a, p.beta, p.gamma, p.n, p.delta][i].abs().max(1e-3);
            let shifted = |d: f64| {
                let mut q = p;
                match i {
                    0 => q.a += d,
                    1 => q.beta += d,
                    2 => q.gamma += d,
                    3 => q.n += d,
                    _ => q.delta += d,
                }
                run(&q, &u, dt).0
            };
            let fd = (shifted(eps) - shifted(-eps)) / (2.0 * eps);
            assert!(
                (fd - g).abs() <= 1e-4 * largest + 1e-9,
                "{name}, coefficient {i}: dual {g}, finite difference {fd}"
            );
        }
    }
}

/// An interval that would take 24 RK4 sub-steps, with the estimates the paper
/// method reaches on noisy data (β ≈ −γ, n = 4, δ = 22 µm/(V·s), h = 23 µm): the two
/// backward-Euler half steps agree with the whole step and are kept; they are within
/// the tolerance of the 24 RK4 sub-steps, and the sensitivities are those of the two
/// steps (finite differences).
#[test]
fn a_stiff_interval_on_its_slow_manifold_takes_two_backward_euler_steps() {
    let dt = 1e-4;
    let p = Params { a: -0.0525, beta: 0.00256, gamma: -0.00256, n: 4.0, delta: 22.18, ..Params::paper_1hz() };
    let (h, u0, u1) = (23.077820009515385, 15.772644703565568, 15.795552683113677);
    let (hn, udot) = (abs_pow(h, p.n), (u1 - u0) / dt);
    let k1 = hysteresis_rate(&p, h, u0, udot);
    assert_eq!(substeps(&p, h, k1, hn, udot, dt), Some(24));
    let trial = ImplicitTrial::new(&p, h, u0, udot, dt);
    assert!(trial.agrees());
    let kept = advance_h(&p, h, u0, u1, dt);
    assert_eq!(kept, trial.end);
    let rk4 = advance_forced(&p, &Coefficients::of(&p), h, u0, u1, dt, Some(24));
    assert!(kept != rk4 && (kept - rk4).abs() <= IMPLICIT_TOLERANCE_UM, "{kept} vs {rk4}");
    let c = Coefficients::<Dual<5>>::seeded(&p, 0);
    let dual = advance(&p, &c, Dual::cst(h), Dual::cst(u0), Dual::cst(u1), dt);
    assert_eq!(dual.re, kept);
    for i in 0..5 {
        let shifted = |d: f64| {
            let mut q = p;
            *[&mut q.a, &mut q.beta, &mut q.gamma, &mut q.n, &mut q.delta][i] += d;
            advance_h(&q, h, u0, u1, dt)
        };
        let eps = 1e-7 * [p.a, p.beta, p.gamma, p.n, p.delta][i].abs();
        let fd = (shifted(eps) - shifted(-eps)) / (2.0 * eps);
        assert!((fd - dual.du[i]).abs() <= 1e-6 * (1.0 + fd.abs()), "coefficient {i}: {} vs {fd}", dual.du[i]);
    }
}

/// [`Seeded`] against the seeded [`Coefficients`] it stands in for: every value and
/// every derivative equal (`==`: up to the sign of a zero), along records that take
/// one, several and implicit sub-steps, with and without a voltage derivative.
#[test]
fn seeded_law_equals_the_generic_one() {
    let dt = 1e-4;
    let u: Vec<f64> = (0..3000).map(|k| 50.0 - 50.0 * (k as f64 * 2e-3 * (1.0 + k as f64 * 1e-3)).cos()).collect();
    let cases = [
        Params::paper_1hz(),
        Params { n: 0.64, ..Params::paper_1hz() },
        Params { beta: 0.4, gamma: 0.1, n: 2.5, ..Params::paper_1hz() },
        Params { beta: 3.0, gamma: 2.0, n: 3.5, ..Params::paper_1hz() },
    ];
    for p in cases {
        for lag in [false, true] {
            let law = Coefficients::<Dual<7>>::seeded(&p, 0);
            let (mut a, mut b) = (Dual::<7>::var(0.0, 5), Dual::<7>::var(0.0, 5));
            let mut u_prev = Dual::<7>::cst(u[0]);
            for (k, &v) in u.iter().enumerate().skip(1) {
                let mut u1 = Dual::<7>::cst(v);
                if lag {
                    u1.du[6] = 0.3 * (k as f64 * 0.01).sin();
                }
                let seeded = Seeded::<7, 0, 6>::new(&p, &u_prev.du, &u1.du, Drive::Moving).unwrap();
                a = advance_forced(&p, &law, a, u_prev, u1, dt, None);
                b = advance_forced(&p, &seeded, b, u_prev, u1, dt, None);
                assert_eq!(a.re.to_bits(), b.re.to_bits());
                assert!(a.du.iter().zip(b.du.iter()).all(|(x, y)| x == y), "sample {k}: {a:?} vs {b:?}");
                u_prev = u1;
            }
        }
    }
    let (zero, mut two) = (SVector::<f64, 7>::zeros(), SVector::<f64, 7>::zeros());
    two[1] = 1.0;
    assert!(Seeded::<7, 0, 6>::new(&Params::paper_1hz(), &zero, &two, Drive::Moving).is_none());
}

#[test]
fn h_is_exactly_zero_at_rest_for_small_n() {
    let p = Params { n: 0.3, ..Params::paper_1hz() };
    assert_eq!(hysteresis_rate(&p, 0.0, 0.0, 0.0), 0.0);
    assert_eq!(hysteresis_rate(&p, 0.0, 10.0, 5.0), p.a * 5.0 + p.delta * 10.0);
}

/// The branch-free path ([`advance_h_lanes`], on `f64` and on four lanes) against
/// [`advance_h_carrying`]: the same bits wherever it reports that it applies, and it
/// applies on most intervals of the paper's input.
#[test]
fn the_lane_path_equals_the_general_one_where_it_applies() {
    use crate::model::lanes::{F64s, WIDTH};
    let dt = 1e-4;
    let u = crate::model::paper_input(dt, 0.05);
    let cases = [
        Params::paper_1hz(),
        Params { n: 0.64, ..Params::paper_1hz() },
        Params { beta: 0.4, gamma: 0.1, n: 2.5, ..Params::paper_1hz() },
        Params { a: 0.3, beta: 0.02, gamma: 0.01, n: 1.1, delta: -0.01, ..Params::paper_1hz() },
    ];
    for p in cases {
        let coef = |v: f64| v;
        let one = LaneCoefficients { a: coef(p.a), beta: p.beta, gamma: p.gamma, n: p.n, delta: p.delta };
        let wide = LaneCoefficients {
            a: F64s::splat(p.a),
            beta: F64s::splat(p.beta),
            gamma: F64s::splat(p.gamma),
            n: F64s::splat(p.n),
            delta: F64s::splat(p.delta),
        };
        // Lane l runs the record from offset 997·l.
        let mut h = [0.0; WIDTH];
        let mut hn = [0.0; WIDTH];
        let (mut applied, mut total) = (0usize, 0usize);
        for k in 1..u.len() {
            let at = |l: usize, d: usize| u[(k - d + 997 * l) % u.len()];
            let (u0, u1): ([f64; WIDTH], [f64; WIDTH]) =
                (core::array::from_fn(|l| at(l, 1)), core::array::from_fn(|l| at(l, 0)));
            let w = F64s::from_array;
            let (wh, whn, wok) = advance_h_lanes(&wide, w(h), w(hn), w(u0), w(u1), dt);
            let (wh, whn, wok) = (wh.to_array(), whn.to_array(), wok.to_array());
            for l in 0..WIDTH {
                let (sh, shn, sok) = advance_h_lanes(&one, h[l], hn[l], u0[l], u1[l], dt);
                assert_eq!(sok, wok[l]);
                let (want, carried) = advance_h_carrying(&p, h[l], hn[l], u0[l], u1[l], dt);
                if sok {
                    applied += 1;
                    assert_eq!((sh.to_bits(), wh[l].to_bits()), (want.to_bits(), want.to_bits()), "{p:?} k={k}");
                    let c = carried.unwrap_or(f64::NAN);
                    assert!(shn.to_bits() == c.to_bits() && whn[l].to_bits() == c.to_bits(), "{p:?} k={k}");
                }
                total += 1;
                (h[l], hn[l]) = (want, carried.unwrap_or_else(|| abs_pow(want, p.n)));
            }
        }
        assert!(applied * 10 >= total * 7, "{p:?}: the lane path applied on {applied} of {total} intervals");
    }
}
