//! Save and restore of the paper's identifier (format: `crate::format`): every field the identifier carries
//! between samples. The shadow half of the window sums is not stored: it is the
//! sum, in arrival order, of the newest `(samples − 2) mod N` window points, and
//! is recomputed from them with the same additions; so are the stroke bound's spans of
//! u (the same slides).

use alloc::vec::Vec;

use super::*;
use crate::format::{corrupt, Reader, Snapshot, Writer, KIND_PAPER, MAX_WINDOW_LEN};

// The format's bound on a declared window is the largest window a configuration accepts.
const _: () = assert!(MAX_WINDOW_LEN == PaperConfig::MAX_WINDOW);

impl Snapshot for PaperIdentifier {
    fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer::new(KIND_PAPER);
        let c = &self.config;
        w.u64(c.window_len as u64);
        w.u8(match c.decomposition {
            Decomposition::Line => 0,
            Decomposition::Model => 1,
        });
        w.f64s(&[c.h_zero_frac, c.rate_frac]);
        w.u64(c.min_points as u64);
        w.f64s(&[
            c.rank_tol,
            c.min_log_spread,
            c.min_r2,
            c.min_arg_frac,
            c.min_line_t,
            c.noise_gate,
            c.derivative_phase,
            c.min_delta_t,
            c.min_u_std_v,
            c.n_bounds.0,
            c.n_bounds.1,
            c.max_hysteresis_gain,
            c.max_delta_ratio,
            c.output_gate,
            c.min_stroke_frac,
            c.fit_every,
            c.min_fit_t,
            c.max_misfit,
        ]);
        w.u64(c.max_half_width as u64);
        w.u64(c.fit_iterations as u64);
        w.f64(self.dt);
        w.params(&self.init);
        w.f64(self.h0);
        w.params(&self.params);
        w.f64(self.h_model);
        w.f64s(&[self.u_seen.0, self.u_seen.1]);
        w.u64(self.since_fit);
        w.f64(self.noise_floor2);
        w.u8(self.fit_carry.is_some() as u8);
        if let Some(p) = &self.fit_carry {
            w.params(p);
        }
        w.u64(self.raw.len() as u64);
        for r in self.raw.iter() {
            w.f64s(&[r.u, r.x, r.h_model]);
        }
        w.u64(self.next);
        w.u64(self.entered);
        w.u64(self.window.len() as u64);
        for p in self.window.iter() {
            w.f64s(&[p.u, p.x, p.y, p.udot, p.a, p.b, p.noise2]);
            w.u8(match p.class {
                Class::Unused => 0,
                Class::Crossing => 1,
                Class::Loading { positive: true } => 2,
                Class::Loading { positive: false } => 3,
                Class::Unloading { positive: true } => 4,
                Class::Unloading { positive: false } => 5,
            });
        }
        w.f64s(self.sums.get());
        w.f64s(self.rls.theta.as_slice());
        w.f64s(self.rls.p.as_slice());
        w.u8(self.rls.active as u8);
        let s = &self.status;
        w.u64(s.samples);
        w.u8(s.window_full as u8);
        w.u8(s.refreshed as u8);
        w.u64(s.half_width as u64);
        w.f64s(&[s.x_noise_um, s.xdot_noise_um_s]);
        for f in [s.line_fit, s.rate_fit, s.shape_fit, s.return_fit, s.split_fit, s.window_fit] {
            w.u8(match f.fit {
                SubFit::Held => 0,
                SubFit::Reduced => 1,
                SubFit::Ran => 2,
            });
            w.u8(Reason::ALL.iter().position(|&r| r == f.reason).unwrap_or(0) as u8);
            w.u64(f.points as u64);
            w.f64(f.noise);
        }
        w.finish()
    }

    fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let mut r = Reader::new(bytes, KIND_PAPER)?;
        let at = r.offset();
        let window_len = usize::try_from(r.u64()?)
            .ok()
            .filter(|&n| n <= MAX_WINDOW_LEN)
            .ok_or_else(|| corrupt(at, "window length out of range"))?;
        let decomposition = match r.u8()? {
            0 => Decomposition::Line,
            1 => Decomposition::Model,
            _ => return Err(corrupt(r.offset() - 1, "unknown decomposition tag")),
        };
        let [h_zero_frac, rate_frac] = r.f64s::<2>()?;
        let min_points = usize::try_from(r.u64()?).map_err(|_| corrupt(at, "min_points out of range"))?;
        let [rank_tol, min_log_spread, min_r2, min_arg_frac, min_line_t, noise_gate, derivative_phase, min_delta_t, min_u_std_v, n_lo, n_hi, max_hysteresis_gain, max_delta_ratio, output_gate, min_stroke_frac, fit_every, min_fit_t, max_misfit] =
            r.f64s::<18>()?;
        let at = r.offset();
        let max_half_width = usize::try_from(r.u64()?)
            .ok()
            .filter(|&m| m <= PaperConfig::MAX_HALF_WIDTH)
            .ok_or_else(|| corrupt(at, "derivative half-width out of range"))?;
        let at = r.offset();
        let fit_iterations = usize::try_from(r.u64()?)
            .ok()
            .filter(|&k| k <= PaperConfig::MAX_FIT_ITERATIONS)
            .ok_or_else(|| corrupt(at, "window-fit iterations out of range"))?;
        let config = PaperConfig {
            window_len,
            decomposition,
            h_zero_frac,
            rate_frac,
            min_points,
            rank_tol,
            min_log_spread,
            min_r2,
            min_arg_frac,
            min_line_t,
            noise_gate,
            derivative_phase,
            max_half_width,
            min_delta_t,
            min_u_std_v,
            n_bounds: (n_lo, n_hi),
            max_hysteresis_gain,
            max_delta_ratio,
            output_gate,
            min_stroke_frac,
            fit_every,
            fit_iterations,
            min_fit_t,
            max_misfit,
        };
        let dt = r.f64()?;
        let init = r.params()?;
        let h0 = r.finite()?;
        // Validates dt, init, h0 and the whole configuration.
        let mut id = PaperIdentifier::new(dt, init, h0, config)?;
        id.params = r.params()?;
        id.h_model = r.finite()?;
        let [u_lo, u_hi] = r.f64s::<2>()?;
        id.u_seen = (u_lo, u_hi);
        id.since_fit = r.u64()?;
        id.noise_floor2 = r.f64()?;
        id.fit_carry = if r.bool()? { Some(r.params()?) } else { None };
        let at = r.offset();
        let raws = r.u64()?;
        if raws > id.raw.capacity() as u64 {
            return Err(corrupt(at, "more raw samples than the stencil holds"));
        }
        for _ in 0..raws {
            id.raw.push(Raw { u: r.finite()?, x: r.finite()?, h_model: r.finite()? });
        }
        id.next = r.u64()?;
        id.entered = r.u64()?;
        let at = r.offset();
        let points = r.u64()?;
        if points > window_len as u64 {
            return Err(corrupt(at, "more window points than the window holds"));
        }
        for _ in 0..points {
            let [u, x, y, udot, a, b, noise2] = r.f64s::<7>()?;
            let class = match r.u8()? {
                0 => Class::Unused,
                1 => Class::Crossing,
                2 => Class::Loading { positive: true },
                3 => Class::Loading { positive: false },
                4 => Class::Unloading { positive: true },
                5 => Class::Unloading { positive: false },
                _ => return Err(corrupt(r.offset() - 1, "unknown window point class")),
            };
            id.window.push(Point { u, x, y, udot, a, b, noise2, class });
        }
        let sums = r.f64s::<NSUMS>()?;
        let theta = r.f64s::<2>()?;
        let p = r.f64s::<4>()?;
        id.rls =
            LineRls { theta: Vector2::from_column_slice(&theta), p: Matrix2::from_column_slice(&p), active: r.bool()? };
        let at = r.offset();
        let samples = r.u64()?;
        let window_full = r.bool()?;
        let refreshed = r.bool()?;
        let half_width = u32::try_from(r.u64()?).map_err(|_| corrupt(at, "half-width out of range"))?;
        let [x_noise_um, xdot_noise_um_s] = r.f64s::<2>()?;
        let mut fits = [StepStatus::default(); 6];
        for f in fits.iter_mut() {
            f.fit = match r.u8()? {
                0 => SubFit::Held,
                1 => SubFit::Reduced,
                2 => SubFit::Ran,
                _ => return Err(corrupt(r.offset() - 1, "unknown sub-fit status")),
            };
            f.reason =
                *Reason::ALL.get(r.u8()? as usize).ok_or_else(|| corrupt(r.offset() - 1, "unknown sub-fit reason"))?;
            f.points = u32::try_from(r.u64()?).map_err(|_| corrupt(r.offset() - 8, "point count out of range"))?;
            f.noise = r.f64()?;
        }
        r.end()?;
        let [line_fit, rate_fit, shape_fit, return_fit, split_fit, window_fit] = fits;
        id.status = PaperStatus {
            samples,
            window_full,
            refreshed,
            half_width,
            x_noise_um,
            xdot_noise_um_s,
            line_fit,
            rate_fit,
            shape_fit,
            return_fit,
            split_fit,
            window_fit,
        };

        // The shadow sum holds the newest `entered mod N` window points; every raw
        // sample up to the newest is held (as many as the stencil keeps), and the next
        // sample to complete is among them.
        let first = samples - raws;
        if points != id.entered.min(window_len as u64)
            || raws != samples.min(id.raw.capacity() as u64)
            || id.entered > id.next
            || id.next > samples
            || (id.next < first && samples > 0)
        {
            return Err(corrupt(at, "sample count does not match the stored window"));
        }
        let count = (id.entered % window_len as u64) as usize;
        let mut shadow = [0.0; NSUMS];
        for p in id.window.iter().skip(points as usize - count) {
            for (s, c) in shadow.iter_mut().zip(p.contribution()) {
                *s += c;
            }
        }
        id.sums = rebuild_window_sums(window_len, &sums, &shadow, count);
        // The stroke bound's spans are a function of the window's points alone.
        let first_seq = id.entered - points;
        for i in 0..points as usize {
            if let Some(q) = id.window.get(i).copied() {
                id.slide_spans(first_seq + i as u64, &q);
            }
        }
        Ok(id)
    }
}

/// Rebuilds window sums whose running sums are `sums` and whose shadow sum,
/// `count` additions into its current window (`count < capacity`), is `shadow`,
/// using only [`WindowSums::slide`], bit for bit:
///
/// 1. `capacity` slides (`start`, then zeros) end in a refresh that leaves the
///    running sums at exactly `start` and the shadow empty (adding 0.0 is exact);
/// 2. with `count > 0`, `start = −shadow`; one slide that enters `shadow` and
///    removes `−sums` gives running sums (−shadow + shadow) − (−sums) = 0 + sums
///    = sums and shadow 0 + shadow = shadow, both exact; `count − 1` slides of
///    zeros then advance the counter without changing either.
///
/// Only the sign of a zero sum could differ (−0.0 becomes +0.0); the sums never
/// hold −0.0, since they start at +0.0 and x − x = +0.0. Non-finite sums (a
/// window that overflowed) do not survive the subtraction and come back as NaN,
/// which the identifier treats like the original: every sub-fit holds.
fn rebuild_window_sums<const K: usize>(
    capacity: usize,
    sums: &[f64; K],
    shadow: &[f64; K],
    count: usize,
) -> WindowSums<K> {
    let capacity = capacity.max(1);
    let mut w = WindowSums::<K>::new(capacity);
    let zero = [0.0; K];
    let start = if count == 0 { *sums } else { shadow.map(|v| -v) };
    w.slide(&start, None);
    for _ in 1..capacity {
        w.slide(&zero, None);
    }
    if count > 0 {
        w.slide(shadow, Some(&sums.map(|v| -v)));
        for _ in 1..count {
            w.slide(&zero, Some(&zero));
        }
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rebuilt_sums_have_the_same_bits() {
        let capacity = 7;
        for count in 0..capacity {
            let sums = [1.0e6 + 0.1, -3.3e-7, 0.0];
            let shadow = [2.5, 0.1 + 0.2, -1e300];
            let w = rebuild_window_sums(capacity, &sums, &shadow, count);
            assert_eq!(w.get(), &sums, "count {count}");
            // Sliding `capacity - count` more zeros refreshes: the shadow comes out.
            let mut w2 = w.clone();
            for _ in count..capacity {
                w2.slide(&[0.0; 3], None);
            }
            let expected = if count == 0 { [0.0; 3] } else { shadow };
            assert_eq!(w2.get(), &expected, "count {count}");
        }
    }
}
