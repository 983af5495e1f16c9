//! Save and restore of the rpem identifier (format: `crate::format`): every field the identifier carries
//! between samples, written as it is held. The constants derived from the
//! configuration and the effects (parameter scales, active slots, the creep
//! elements' decay factors) are rebuilt by the constructor from the same values,
//! with the same bits. The struct patterns below are exhaustive on purpose: a
//! field added to any of these types stops the build here until it is saved.

use alloc::vec::Vec;

use super::*;
use crate::format::{corrupt, Reader, Snapshot, Writer, KIND_RPEM};

fn write_estimates(w: &mut Writer, e: &Estimates) {
    let Estimates { params, fc_hz, creep_gain } = e;
    w.params(params);
    w.f64(*fc_hz);
    w.f64s(creep_gain);
}

fn read_estimates(r: &mut Reader<'_>) -> Result<Estimates> {
    let params = r.params()?;
    let at = r.offset();
    let fc_hz = r.finite()?;
    if fc_hz <= 0.0 {
        return Err(corrupt(at, "snapshot holds a corner frequency <= 0 Hz"));
    }
    let mut creep_gain = [0.0; MAX_CREEP];
    for g in creep_gain.iter_mut() {
        *g = r.finite()?;
    }
    Ok(Estimates { params, fc_hz, creep_gain })
}

fn read_vector(r: &mut Reader<'_>) -> Result<ParamVector> {
    let mut v = ParamVector::zeros();
    for x in v.iter_mut() {
        *x = r.finite()?;
    }
    Ok(v)
}

impl Snapshot for RpemIdentifier {
    fn to_bytes(&self) -> Vec<u8> {
        let RpemIdentifier { config, dt, init, h0, est, shape, scales: _, active: _, chain, u_prev, p, status } = self;
        let mut w = Writer::new(KIND_RPEM);
        let RpemConfig {
            forgetting,
            memory_travel_v,
            p0,
            offset_walk_um,
            p0_effects,
            noise_um2,
            noise_memory_samples,
            max_trace,
            max_step,
            max_offset_step_um,
            n_bounds,
            margin,
            scales,
            creep_gain_scale_um_per_v,
            creep_gain_max_um_per_v,
            fc_bounds_hz,
        } = *config;
        w.f64s(&[
            forgetting,
            memory_travel_v,
            p0,
            offset_walk_um,
            p0_effects,
            noise_um2,
            max_trace,
            max_step,
            max_offset_step_um,
            n_bounds.0,
            n_bounds.1,
            margin,
            creep_gain_scale_um_per_v,
            creep_gain_max_um_per_v,
            fc_bounds_hz.0,
            fc_bounds_hz.1,
            noise_memory_samples,
        ]);
        w.f64s(&scales);
        w.f64(*dt);
        w.f64(*h0);
        let Shape { lag, n_creep, creep_tau, creep_decay: _ } = *shape;
        w.u8(lag as u8);
        w.u64(n_creep as u64);
        w.f64s(&creep_tau[..n_creep.min(MAX_CREEP)]);
        write_estimates(&mut w, init);
        write_estimates(&mut w, est);
        let Chain { h, dh, ua, dua, creep, dcreep } = chain;
        w.f64(*h);
        w.f64s(dh.as_slice());
        w.f64(*ua);
        w.f64s(dua.as_slice());
        w.f64s(creep);
        for d in dcreep {
            w.f64s(d.as_slice());
        }
        w.opt_f64(*u_prev);
        w.f64s(p.as_slice());
        let RpemStatus {
            samples,
            updated,
            step_limited,
            projected,
            trace_capped,
            restarted,
            innovation_um,
            trace,
            noise_um2: learnt_noise,
        } = *status;
        w.u64(samples);
        for flag in [updated, step_limited, projected, trace_capped, restarted] {
            w.u8(flag as u8);
        }
        w.f64(innovation_um);
        w.f64(trace);
        w.f64(learnt_noise);
        w.finish()
    }

    fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let mut r = Reader::new(bytes, KIND_RPEM)?;
        let config_at = r.offset();
        let c = r.f64s::<17>()?;
        let scales = r.f64s::<NUM_BASE>()?;
        let config = RpemConfig {
            forgetting: c[0],
            memory_travel_v: c[1],
            p0: c[2],
            offset_walk_um: c[3],
            p0_effects: c[4],
            noise_um2: c[5],
            max_trace: c[6],
            max_step: c[7],
            max_offset_step_um: c[8],
            n_bounds: (c[9], c[10]),
            margin: c[11],
            creep_gain_scale_um_per_v: c[12],
            creep_gain_max_um_per_v: c[13],
            fc_bounds_hz: (c[14], c[15]),
            noise_memory_samples: c[16],
            scales,
        };
        let dt = r.f64()?;
        let h0 = r.finite()?;
        let lag = r.bool()?;
        let at = r.offset();
        let n_creep = r.u64()?;
        if n_creep > MAX_CREEP as u64 {
            return Err(corrupt(at, "snapshot declares more creep elements than the method identifies"));
        }
        let n_creep = n_creep as usize;
        let mut creep_tau = [1.0; MAX_CREEP];
        for tau in creep_tau.iter_mut().take(n_creep) {
            *tau = r.finite()?;
        }
        let init = read_estimates(&mut r)?;
        let est = read_estimates(&mut r)?;

        // The constructor validates dt, h0, the configuration and the effects,
        // and rebuilds the derived constants; its error is reported as a corrupt
        // snapshot (the values were valid when they were written).
        let effects = EffectSet {
            input_lag: lag.then_some(InputLag { fc_hz: init.fc_hz }),
            creep: (n_creep > 0).then(|| Creep {
                tau_s: creep_tau[..n_creep].to_vec(),
                gain_um_per_v: init.creep_gain[..n_creep].to_vec(),
            }),
            ..EffectSet::none()
        };
        let mut id = RpemIdentifier::with_effects(dt, init.params, &effects, h0, config)
            .map_err(|_| corrupt(config_at, "snapshot holds an invalid configuration, time step or effect"))?;
        // Stored as they were held (the constructor's projection of the starting
        // values is not repeated: projecting twice may move a rounding bit). The
        // effects' estimates must lie where the recursion keeps them: fc within
        // `fc_bounds_hz`, each creep gain strictly within (0, gmax) (its logistic
        // coordinate is finite there).
        let (fc_lo, fc_hi) = config.fc_bounds_hz;
        let gmax = config.creep_gain_max_um_per_v;
        for e in [&init, &est] {
            if lag && !(fc_lo..=fc_hi).contains(&e.fc_hz) {
                return Err(corrupt(config_at, "snapshot holds a corner frequency outside fc_bounds_hz"));
            }
            if e.creep_gain[..n_creep].iter().any(|&g| !(g > 0.0 && g < gmax)) {
                return Err(corrupt(config_at, "snapshot holds a creep gain outside (0, creep_gain_max_um_per_v)"));
            }
        }
        id.init = init;
        id.est = est;

        let h = r.finite()?;
        let dh = read_vector(&mut r)?;
        let ua = r.finite()?;
        let dua = read_vector(&mut r)?;
        let mut creep = [0.0; MAX_CREEP];
        for s in creep.iter_mut() {
            *s = r.finite()?;
        }
        let mut dcreep = [ParamVector::zeros(); MAX_CREEP];
        for d in dcreep.iter_mut() {
            *d = read_vector(&mut r)?;
        }
        id.chain = Chain { h, dh, ua, dua, creep, dcreep };
        id.u_prev = r.opt_f64()?;
        let p_at = r.offset();
        let mut p = Covariance::zeros();
        for v in p.iter_mut() {
            *v = r.finite()?;
        }
        if p.diagonal().iter().any(|&v| v < 0.0) {
            return Err(corrupt(p_at, "snapshot holds a covariance with a negative variance"));
        }
        id.p = p;
        let at = r.offset();
        let samples = r.u64()?;
        let mut flags = [false; 5];
        for f in flags.iter_mut() {
            *f = r.bool()?;
        }
        let innovation_um = r.f64()?;
        let trace = r.f64()?;
        let noise_um2 = r.f64()?;
        r.end()?;
        if (samples == 0) != id.u_prev.is_none() {
            return Err(corrupt(at, "sample count does not match the stored previous input"));
        }
        let [updated, step_limited, projected, trace_capped, restarted] = flags;
        id.status = RpemStatus {
            samples,
            updated,
            step_limited,
            projected,
            trace_capped,
            restarted,
            innovation_um,
            trace,
            noise_um2,
        };
        Ok(id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::AnyIdentifier;
    use crate::model::{paper_input, simulate};

    fn record() -> (Vec<f64>, Vec<f64>) {
        let dt = 1e-4;
        let u: Vec<f64> = paper_input(dt, 0.0)[..6_000].to_vec();
        let (mut x, _) = simulate(&Params::paper_1hz(), &u, dt, 0.0, None).unwrap();
        for (k, v) in x.iter_mut().enumerate() {
            *v += 1e-3 * ((k as f64 * 0.37).sin() + (k as f64 * 1.91).cos());
        }
        (u, x)
    }

    fn identifiers() -> Vec<RpemIdentifier> {
        let dt = 1e-4;
        let p = Params { n: 1.7, ..Params::paper_1hz() };
        let effects = EffectSet {
            input_lag: Some(InputLag { fc_hz: 800.0 }),
            creep: Some(Creep { tau_s: vec![0.01, 0.3], gain_um_per_v: vec![0.001, 0.0005] }),
            ..EffectSet::none()
        };
        let cfg = RpemConfig { memory_travel_v: 500.0, offset_walk_um: 0.02, ..Default::default() };
        vec![
            RpemIdentifier::new(dt, p, 0.05, RpemConfig::default()).unwrap(),
            RpemIdentifier::with_effects(dt, p, &effects, 0.0, cfg).unwrap(),
        ]
    }

    #[test]
    fn restored_identifier_continues_bit_for_bit() {
        let (u, x) = record();
        for fresh in identifiers() {
            for cut in [0, 1, 2, 3, 777, 4_000] {
                let mut original = fresh.clone();
                for k in 0..cut {
                    original.push(u[k], x[k]).unwrap();
                }
                let bytes = original.to_bytes();
                let mut restored = RpemIdentifier::from_bytes(&bytes).unwrap();
                assert_eq!(restored, original, "cut {cut}");
                assert_eq!(restored.to_bytes(), bytes, "cut {cut}");
                for k in cut..u.len() {
                    let a = original.push(u[k], x[k]).unwrap();
                    let b = restored.push(u[k], x[k]).unwrap();
                    assert_eq!(a.to_bits(), b.to_bits(), "cut {cut}, sample {k}");
                }
                assert_eq!(restored, original);
                // And through the run-time choice of method.
                let any = AnyIdentifier::Rpem(original.clone());
                let back = AnyIdentifier::from_snapshot(&any.to_snapshot()).unwrap();
                assert_eq!(back, any);
            }
        }
    }

    #[test]
    fn corrupt_snapshots_are_errors_naming_snapshot() {
        let (u, x) = record();
        for mut id in identifiers() {
            for k in 0..500 {
                id.push(u[k], x[k]).unwrap();
            }
            let bytes = id.to_bytes();
            let names_snapshot = |e: Error| matches!(e, Error::CorruptSnapshot { .. });
            for cut in 0..bytes.len() {
                let err = RpemIdentifier::from_bytes(&bytes[..cut]).unwrap_err();
                assert!(names_snapshot(err), "cut {cut}");
            }
            let mut longer = bytes.clone();
            longer.push(0);
            assert!(names_snapshot(RpemIdentifier::from_bytes(&longer).unwrap_err()));
            // A NaN in the covariance, a forgetting factor of 2, a paper snapshot.
            let mut bad = bytes.clone();
            let p_start = bytes.len() - (8 + 5 + 16) - NUM_PARAMS * NUM_PARAMS * 8;
            bad[p_start..p_start + 8].copy_from_slice(&f64::NAN.to_bits().to_le_bytes());
            assert!(names_snapshot(RpemIdentifier::from_bytes(&bad).unwrap_err()));
            let mut bad = bytes.clone();
            bad[6..14].copy_from_slice(&2.0f64.to_bits().to_le_bytes());
            assert!(names_snapshot(RpemIdentifier::from_bytes(&bad).unwrap_err()));
            let mut other_kind = bytes.clone();
            other_kind[5] = crate::format::KIND_PAPER;
            assert!(AnyIdentifier::from_snapshot(&other_kind).is_err());
            // Every single flipped bit: an error or a valid identifier, never a panic.
            for i in 0..bytes.len() {
                for bit in [0, 3, 6, 7] {
                    let mut flipped = bytes.clone();
                    flipped[i] ^= 1 << bit;
                    if let Ok(mut r) = RpemIdentifier::from_bytes(&flipped) {
                        for k in 500..520 {
                            let _ = r.push(u[k], x[k]);
                        }
                    }
                }
            }
        }
    }
}
