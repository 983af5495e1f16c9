//! Save and restore of the moving-horizon identifier (format: `crate::format`): every
//! field it carries between samples, the stored window included. The struct patterns
//! are exhaustive on purpose: a field added stops the build here until it is saved.

use super::*;
use crate::error::Error;
use crate::format::{corrupt, Reader, Snapshot, Writer, KIND_HORIZON};

fn write_params(w: &mut Writer, p: &Params) {
    w.params(p);
}

impl Snapshot for HorizonIdentifier {
    fn to_bytes(&self) -> Vec<u8> {
        let HorizonIdentifier {
            config,
            dt,
            init,
            h0,
            params,
            ln_fc,
            ln_fc0,
            lag: _, // follows from ln_fc
            h,
            ua,
            u_prev,
            buffer,
            travels,
            next,
            start,
            mid,
            pass,
            finish_due,
            last_mse,
            damping,
            status,
            mode,
            pass_end,
            pending,
            fitted,
        } = self;
        let HorizonConfig {
            memory_travel_v,
            recent_factor,
            max_window,
            samples_per_push,
            min_pass_fraction,
            ridge,
            damping: damping0,
            max_step,
            n_bounds,
            fc_bounds_hz,
            margin,
            scales,
        } = config;
        let mut w = Writer::new(KIND_HORIZON);
        w.f64s(&[*memory_travel_v, *min_pass_fraction, *ridge, *damping0, *max_step, n_bounds.0, n_bounds.1, *margin]);
        w.f64s(scales);
        w.f64s(&[fc_bounds_hz.0, fc_bounds_hz.1, *recent_factor]);
        w.u64(*max_window as u64);
        w.u64(*samples_per_push as u64);
        w.f64(*dt);
        write_params(&mut w, init);
        w.f64(*h0);
        write_params(&mut w, params);
        w.f64(*h);
        w.opt_f64(*u_prev);
        w.opt_f64(*ln_fc0);
        w.opt_f64(*ln_fc);
        w.f64(*ua);
        w.u64(*next);
        w.u64(*start);
        w.u64(*mid);
        let first = next.saturating_sub(buffer.len() as u64);
        for k in first..*next {
            let slot = (k % buffer.len() as u64) as usize;
            let Entry { u, x, h, dh, ua, dua } = &buffer[slot];
            w.f64s(&[*u, *x, travels[slot], *h, *ua, *dua]);
            w.f64s(dh);
        }
        let Pass {
            start: p_start,
            cursor,
            params: p_params,
            h_start,
            h: p_h,
            power,
            ua: p_ua,
            lag: _,
            jtj,
            jtr,
            sse,
            count,
        } = pass;
        w.u64(*p_start);
        w.u64(*cursor);
        write_params(&mut w, p_params);
        w.f64(*h_start);
        w.f64(p_h.re);
        w.f64s(p_h.du.as_slice());
        w.opt_f64(power.map(|(hn, _)| hn));
        w.opt_f64(power.map(|(_, ln)| ln));
        w.f64(p_ua.re);
        w.f64s(p_ua.du.as_slice());
        w.f64s(jtj.as_slice());
        w.f64s(jtr.as_slice());
        w.f64(*sse);
        w.u64(*count);
        w.u8(*finish_due as u8);
        w.f64(*last_mse);
        w.f64(*damping);
        let HorizonStatus {
            samples,
            updated,
            updates,
            window_samples,
            window_travel_v,
            rms_um,
            damping: s_damping,
            step_limited,
            projected,
            held,
            behind_samples,
            behind_s,
        } = status;
        w.u64(*samples);
        w.u8(*updated as u8);
        w.u64(*updates);
        w.u64(*window_samples);
        w.f64s(&[*window_travel_v, *rms_um, *s_damping]);
        w.u8(*step_limited as u8);
        // Both flags of the region in one byte (bit 0 projected, bit 1 held).
        w.u8(*projected as u8 | (*held as u8) << 1);
        w.u64(*behind_samples);
        w.f64(*behind_s);
        w.u8(match mode {
            RefineMode::Sync => 0,
            RefineMode::Cooperative => 1,
        });
        w.u64(*pass_end);
        w.u64(*fitted);
        match pending {
            None => w.u8(0),
            Some(Pending { at, params, ln_fc, h, ua, fitted }) => {
                w.u8(1);
                w.u64(*at);
                write_params(&mut w, params);
                w.opt_f64(*ln_fc);
                w.f64s(&[*h, *ua]);
                w.u64(*fitted);
            }
        }
        w.finish()
    }

    fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let mut r = Reader::new(bytes, KIND_HORIZON)?;
        let at = r.offset();
        let [memory_travel_v, min_pass_fraction, ridge, damping0, max_step, n_lo, n_hi, margin] = r.f64s::<8>()?;
        let scales = r.f64s::<8>()?;
        let [fc_lo, fc_hi, recent_factor] = r.f64s::<3>()?;
        let max_window = r.u64()?;
        let samples_per_push = r.u64()?;
        if max_window > HorizonConfig::MAX_WINDOW as u64 || samples_per_push > 64 {
            return Err(corrupt(at, "snapshot holds an invalid horizon configuration"));
        }
        let config = HorizonConfig {
            memory_travel_v,
            recent_factor,
            max_window: max_window as usize,
            samples_per_push: samples_per_push as usize,
            min_pass_fraction,
            ridge,
            damping: damping0,
            max_step,
            n_bounds: (n_lo, n_hi),
            fc_bounds_hz: (fc_lo, fc_hi),
            margin,
            scales,
        };
        let dt = r.f64()?;
        let init = r.params()?;
        let h0 = r.finite()?;
        let mut id = HorizonIdentifier::new(dt, init, h0, config).map_err(|e| match e {
            Error::CorruptSnapshot { .. } => e,
            _ => corrupt(at, "snapshot holds an invalid horizon configuration"),
        })?;
        id.params = r.params()?;
        id.h = r.finite()?;
        id.u_prev = r.opt_f64()?;
        let at = r.offset();
        let (ln_fc0, ln_fc) = (r.opt_f64()?, r.opt_f64()?);
        if ln_fc0.is_some() != ln_fc.is_some() || ln_fc.is_some_and(|l| !l.is_finite()) {
            return Err(corrupt(at, "snapshot holds an invalid input lag"));
        }
        id.ln_fc0 = ln_fc0;
        id.ln_fc = ln_fc;
        id.lag = lag_of(ln_fc.map_or(id.config.fc_bounds_hz.1, math::exp), dt);
        id.ua = r.f64()?;
        let at = r.offset();
        id.next = r.u64()?;
        id.start = r.u64()?;
        id.mid = r.u64()?;
        let cap = id.buffer.len() as u64;
        if id.start > id.next || id.next - id.start > cap || id.mid < id.start || id.mid > id.next {
            return Err(corrupt(at, "snapshot holds an invalid window"));
        }
        let first = id.next.saturating_sub(cap);
        for k in first..id.next {
            let [u, x, travel, h, ua, dua] = r.f64s::<6>()?;
            let dh = r.f64s::<ND>()?;
            let slot = (k % cap) as usize;
            id.buffer[slot] = Entry { u, x, h, dh, ua, dua };
            id.travels[slot] = travel;
        }
        let at = r.offset();
        let p_start = r.u64()?;
        let cursor = r.u64()?;
        if p_start > cursor || cursor > id.next || p_start < first && cursor < id.next {
            return Err(corrupt(at, "snapshot holds an invalid pass"));
        }
        let p_params = r.params()?;
        let h_start = r.f64()?;
        let re = r.f64()?;
        let du = r.f64s::<ND>()?;
        let at = r.offset();
        let power = match (r.opt_f64()?, r.opt_f64()?) {
            (Some(hn), Some(ln)) => Some((hn, ln)),
            (None, None) => None,
            _ => return Err(corrupt(at, "snapshot holds an invalid pass")),
        };
        let ua_re = r.f64()?;
        let ua_du = r.f64s::<ND>()?;
        let jtj = r.f64s::<{ NZ * NZ }>()?;
        let jtr = r.f64s::<NZ>()?;
        let sse = r.f64()?;
        let count = r.u64()?;
        id.pass = Pass {
            start: p_start,
            cursor,
            params: p_params,
            h_start,
            h: Dual::new(re, SVector::from(du)),
            power,
            ua: Dual::new(ua_re, SVector::from(ua_du)),
            lag: id.lag,
            jtj: Normal::from_column_slice(&jtj),
            jtr: Vector::from(jtr),
            sse,
            count,
        };
        id.finish_due = r.u8()? != 0;
        id.last_mse = r.f64()?;
        id.damping = r.f64()?;
        id.status.samples = r.u64()?;
        id.status.updated = r.bool()?;
        id.status.updates = r.u64()?;
        id.status.window_samples = r.u64()?;
        let [travel, rms, damping] = r.f64s::<3>()?;
        id.status.window_travel_v = travel;
        id.status.rms_um = rms;
        id.status.damping = damping;
        id.status.step_limited = r.bool()?;
        let at = r.offset();
        let region = r.u8()?;
        if region > 3 {
            return Err(corrupt(at, "snapshot holds unknown region flags"));
        }
        id.status.projected = region & 1 == 1;
        id.status.held = region & 2 == 2;
        id.status.behind_samples = r.u64()?;
        id.status.behind_s = r.f64()?;
        let at = r.offset();
        id.mode = match r.u8()? {
            0 => RefineMode::Sync,
            1 => RefineMode::Cooperative,
            _ => return Err(corrupt(at, "snapshot holds an unknown refine mode")),
        };
        let at = r.offset();
        id.pass_end = r.u64()?;
        id.fitted = r.u64()?;
        if id.pass_end > id.next || id.fitted > id.next {
            return Err(corrupt(at, "snapshot holds an invalid pass"));
        }
        let at = r.offset();
        id.pending = match r.u8()? {
            0 => None,
            1 => {
                let p_at = r.u64()?;
                let params = r.params()?;
                let ln_fc = r.opt_f64()?;
                let [h, ua] = [r.finite()?, r.finite()?];
                let fitted = r.u64()?;
                if p_at >= id.next || fitted > id.next || ln_fc.is_some() != id.ln_fc.is_some() {
                    return Err(corrupt(at, "snapshot holds an invalid pending update"));
                }
                if ln_fc.is_some_and(|l| !l.is_finite()) {
                    return Err(corrupt(at, "snapshot holds an invalid input lag"));
                }
                Some(Pending { at: p_at, params, ln_fc, h, ua, fitted })
            }
            _ => return Err(corrupt(at, "snapshot holds an invalid pending update")),
        };
        r.end()?;
        Ok(id)
    }
}
