//! Many channels stepped with one call per frame: an online identifier, a model and
//! an inverse of the model per channel (adaptive optics: hundreds of actuators;
//! multi-axis stages).
//!
//! A frame is one sample of every channel: `u[c]` \[V\] and `x[c]` \[µm\] for channel
//! `c < C`. Every channel is independent and its results are bit for bit those of a
//! single-channel object given the same samples ([`Model`] for the models, the
//! identifier type for the identifiers): each channel runs the same code on the
//! same numbers.
//!
//! Layout:
//! - [`ModelBank`]: structure of arrays. Each quantity of the C channels (the seven
//!   parameters, h, the last voltage) is one contiguous `Vec<f64>`, so a frame reads
//!   and writes C consecutive values of each; the input check and the output
//!   equation x = kv·u + x0 + h run as straight loops the compiler vectorises. The
//!   usual interval (one RK4 step, |h|^n from the interval's series: most intervals of
//!   the paper's input) runs four channels at a time in SIMD lanes without branches;
//!   the channels it does not cover (h near zero or crossing it, stiff or fast
//!   intervals) then take the general integrator one by one, and the |h|^n the series
//!   did not give are computed in a pass of their own.
//! - [`Bank`]: the identifiers (one contiguous `Vec` of them, each with its own
//!   fixed-size state), a [`ModelBank`] and one [`Inverse`] per channel
//!   ([`Bank::feedforward`]: the voltages for the desired displacements of a frame).
//!
//! A frame with a non-finite value is rejected whole before any channel changes
//! (the NaN policy of a single channel, applied to the frame). Stepping a frame
//! allocates nothing.

use alloc::vec;
use alloc::vec::Vec;

use crate::compensate::{admissible, Inverse, VoltageLimits};
use crate::error::{finite_sample, positive_dt, Error, Result};
use crate::identify::OnlineIdentifier;
use crate::model::integrator::{abs_pow, advance_h_carrying, advance_h_lanes, LaneCoefficients};
use crate::model::lanes::{F64s, Lanes, WIDTH};
use crate::model::Model;
use crate::params::Params;

/// C per-sample models in structure-of-arrays layout; channel c behaves as a
/// [`Model`] with parameters `params(c)` (bit for bit).
#[derive(Debug, Clone, PartialEq)]
pub struct ModelBank {
    dt: f64,
    /// The parameters, one array per parameter (SoA), in the order of [`Params::to_array`].
    kv: Vec<f64>,
    x0: Vec<f64>,
    a: Vec<f64>,
    beta: Vec<f64>,
    gamma: Vec<f64>,
    n: Vec<f64>,
    delta: Vec<f64>,
    /// Hysteresis state h \[µm\] per channel.
    h: Vec<f64>,
    /// |h|^n per channel, carried as by the [`Model`].
    hn: Vec<f64>,
    /// Last voltage \[V\] per channel (meaningful once `started`).
    u_prev: Vec<f64>,
    /// A frame was stepped since construction or reset (all channels start together).
    started: bool,
    h0: f64,
}

/// Checks that every value of a frame is finite and the frame has `channels` values.
fn check_frame(what: &'static str, values: &[f64], channels: usize) -> Result<()> {
    if values.len() != channels {
        return Err(Error::LengthMismatch { what, expected: channels, found: values.len() });
    }
    for &v in values {
        finite_sample(what, v)?;
    }
    Ok(())
}

impl ModelBank {
    /// `channels` (≥ 1) models with the same parameters `params`, sampling interval
    /// `dt` \[s\] and initial h `h0` \[µm\].
    pub fn new(channels: usize, params: Params, dt: f64, h0: f64) -> Result<Self> {
        params.validate()?;
        positive_dt(dt)?;
        finite_sample("h0", h0)?;
        if channels == 0 {
            return Err(Error::InvalidConfig {
                name: "channels",
                value: 0.0,
                reason: "a bank has at least one channel",
            });
        }
        let fill = |v: f64| vec![v; channels];
        Ok(ModelBank {
            dt,
            kv: fill(params.kv),
            x0: fill(params.x0),
            a: fill(params.a),
            beta: fill(params.beta),
            gamma: fill(params.gamma),
            n: fill(params.n),
            delta: fill(params.delta),
            h: fill(h0),
            hn: fill(abs_pow(h0, params.n)),
            u_prev: fill(0.0),
            started: false,
            h0,
        })
    }

    /// Number of channels C.
    pub fn channels(&self) -> usize {
        self.h.len()
    }

    /// Sampling interval \[s\].
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Parameters of channel `c` (panics if `c` ≥ C, as slice indexing).
    #[inline(always)]
    pub fn params(&self, c: usize) -> Params {
        Params {
            kv: self.kv[c],
            x0: self.x0[c],
            a: self.a[c],
            beta: self.beta[c],
            gamma: self.gamma[c],
            n: self.n[c],
            delta: self.delta[c],
        }
    }

    /// Replaces the parameters of channel `c` (validated; the state is kept).
    pub fn set_params(&mut self, c: usize, p: Params) -> Result<()> {
        p.validate()?;
        if c >= self.channels() {
            return Err(Error::InvalidConfig { name: "channel", value: c as f64, reason: "no such channel" });
        }
        self.kv[c] = p.kv;
        self.x0[c] = p.x0;
        self.a[c] = p.a;
        self.beta[c] = p.beta;
        self.gamma[c] = p.gamma;
        if p.n != self.n[c] {
            self.hn[c] = abs_pow(self.h[c], p.n);
        }
        self.n[c] = p.n;
        self.delta[c] = p.delta;
        Ok(())
    }

    /// Hysteresis states h \[µm\], one per channel.
    pub fn h(&self) -> &[f64] {
        &self.h
    }

    /// Takes one frame of voltages `u` \[V\] (length C) and writes the displacements
    /// x \[µm\] into `x_out` (length C). A frame with a non-finite value, or of the
    /// wrong length, is rejected before any channel changes. Allocation-free.
    pub fn step(&mut self, u: &[f64], x_out: &mut [f64]) -> Result<()> {
        let channels = self.channels();
        check_frame("u", u, channels)?;
        if x_out.len() != channels {
            return Err(Error::LengthMismatch { what: "bank output", expected: channels, found: x_out.len() });
        }
        if self.started {
            // The usual interval of every channel in SIMD lanes (branch-free, WIDTH
            // channels at a time; a last, partial group repeats its last channel in
            // the spare lanes); `x_out` holds 1 where it applied, 0 where the channel
            // takes the general path below.
            for c in (0..channels).step_by(WIDTH) {
                let width = WIDTH.min(channels - c);
                let lanes = |v: &[f64]| F64s::from_array(core::array::from_fn(|l| v[c + l.min(width - 1)]));
                let coefficients = LaneCoefficients {
                    a: lanes(&self.a),
                    beta: lanes(&self.beta),
                    gamma: lanes(&self.gamma),
                    n: lanes(&self.n),
                    delta: lanes(&self.delta),
                };
                let (h, hn) = (lanes(&self.h), lanes(&self.hn));
                let (next, next_hn, ok) = advance_h_lanes(&coefficients, h, hn, lanes(&self.u_prev), lanes(u), self.dt);
                let r = c..c + width;
                self.h[r.clone()].copy_from_slice(&F64s::select(ok, next, h).to_array()[..width]);
                self.hn[r.clone()].copy_from_slice(&F64s::select(ok, next_hn, hn).to_array()[..width]);
                x_out[r].copy_from_slice(&F64s::select(ok, F64s::splat(1.0), F64s::splat(0.0)).to_array()[..width]);
            }
            // Indexed: each channel reads its parameters from seven arrays.
            #[allow(clippy::needless_range_loop)]
            for c in 0..channels {
                if x_out[c] == 0.0 {
                    let (h, carried) =
                        advance_h_carrying(&self.params(c), self.h[c], self.hn[c], self.u_prev[c], u[c], self.dt);
                    self.h[c] = h;
                    self.hn[c] = carried.unwrap_or(f64::NAN);
                }
            }
            // The powers the series did not give, in a pass of their own.
            for ((hn, &h), &n) in self.hn.iter_mut().zip(&self.h).zip(&self.n) {
                if hn.is_nan() {
                    *hn = abs_pow(h, n);
                }
            }
        }
        self.started = true;
        self.u_prev.copy_from_slice(u);
        for (((x, &v), (&kv, &x0)), &h) in x_out.iter_mut().zip(u).zip(self.kv.iter().zip(&self.x0)).zip(&self.h) {
            *x = kv * v + x0 + h;
        }
        Ok(())
    }

    /// Forgets the past: h = h0 on every channel, no previous frame.
    pub fn reset(&mut self) {
        self.h.iter_mut().for_each(|h| *h = self.h0);
        for (hn, &n) in self.hn.iter_mut().zip(&self.n) {
            *hn = abs_pow(self.h0, n);
        }
        self.started = false;
    }

    /// Channel `c` as a single [`Model`] in the same state (for checks and hand-over).
    pub fn channel_model(&self, c: usize) -> Result<Model> {
        let mut m = Model::new(self.params(c), self.dt, self.h[c])?;
        m.set_state(crate::model::ModelState { h: self.h[c], u_prev: self.started.then(|| self.u_prev[c]) })?;
        m.set_carried_power(self.hn[c]);
        Ok(m)
    }
}

/// C channels, each an online identifier of type `I` and a model, stepped one
/// frame per call. Channel c's identifier is exactly `identifiers()[c]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Bank<I> {
    identifiers: Vec<I>,
    models: ModelBank,
    inverses: Vec<Inverse>,
}

impl<I: OnlineIdentifier + Clone> Bank<I> {
    /// `channels` copies of `identifier` (each channel then learns on its own) and
    /// as many models, all starting from the identifier's parameters and h, with
    /// sampling interval `dt` \[s\] (the identifier's).
    pub fn new(channels: usize, identifier: I, dt: f64) -> Result<Self> {
        let models = ModelBank::new(channels, identifier.params(), dt, identifier.h())?;
        let inverse = Inverse::new(identifier.params(), dt, identifier.h(), VoltageLimits::NONE)?;
        Ok(Bank { identifiers: vec![identifier; channels], models, inverses: vec![inverse; channels] })
    }

    /// The inverses, channel by channel.
    pub fn inverses(&self) -> &[Inverse] {
        &self.inverses
    }

    /// Voltage limits \[V\] of every channel's inverse (the amplifier's range).
    pub fn set_voltage_limits(&mut self, limits: VoltageLimits) -> Result<()> {
        limits.validate()?;
        for inv in &mut self.inverses {
            inv.set_limits(limits)?;
        }
        Ok(())
    }

    /// One frame of feedforward: for each channel the voltage `u_out[c]` \[V\] at which
    /// its inverse's model reaches the desired displacement `x_d[c]` \[µm\] (see
    /// [`Inverse::step`]; channel c is bit for bit a single [`Inverse`] given the same
    /// parameters and targets). A frame with a non-finite value, or of the wrong
    /// length, is rejected before any channel changes. Allocation-free.
    pub fn feedforward(&mut self, x_d: &[f64], u_out: &mut [f64]) -> Result<()> {
        let channels = self.channels();
        check_frame("x_d", x_d, channels)?;
        if u_out.len() != channels {
            return Err(Error::LengthMismatch { what: "bank output", expected: channels, found: u_out.len() });
        }
        for ((inv, out), &target) in self.inverses.iter_mut().zip(u_out.iter_mut()).zip(x_d) {
            *out = inv.step(target)?;
        }
        Ok(())
    }

    /// Number of channels C.
    pub fn channels(&self) -> usize {
        self.identifiers.len()
    }

    /// The identifiers, channel by channel.
    pub fn identifiers(&self) -> &[I] {
        &self.identifiers
    }

    /// Channel `c`'s identifier (for per-channel configuration or hand-over).
    pub fn identifier_mut(&mut self, c: usize) -> Option<&mut I> {
        self.identifiers.get_mut(c)
    }

    /// The models.
    pub fn models(&self) -> &ModelBank {
        &self.models
    }

    /// The models, mutably (parameters, reset).
    pub fn models_mut(&mut self) -> &mut ModelBank {
        &mut self.models
    }

    /// One frame for the identifiers: `u` \[V\] and measured `x` \[µm\] (length C
    /// each); writes each channel's prediction (its identifier's `push`) into
    /// `predictions` \[µm\]. A frame with a non-finite value, or of the wrong length,
    /// is rejected before any channel changes. Allocation-free.
    pub fn push(&mut self, u: &[f64], x: &[f64], predictions: &mut [f64]) -> Result<()> {
        let channels = self.channels();
        check_frame("u", u, channels)?;
        check_frame("x", x, channels)?;
        if predictions.len() != channels {
            return Err(Error::LengthMismatch { what: "bank output", expected: channels, found: predictions.len() });
        }
        for (((id, out), &uc), &xc) in self.identifiers.iter_mut().zip(predictions.iter_mut()).zip(u).zip(x) {
            *out = id.push(uc, xc)?;
        }
        Ok(())
    }

    /// `frames` frames at once, row-major (T, C): `u[t·C + c]`, `x[t·C + c]`;
    /// predictions into `out` likewise. The whole call is rejected before any
    /// channel changes if a value is non-finite or a length is not T·C.
    pub fn push_many(&mut self, u: &[f64], x: &[f64], out: &mut [f64]) -> Result<()> {
        let channels = self.channels();
        if u.len() % channels != 0 {
            return Err(Error::LengthMismatch {
                what: "u (frames × channels)",
                expected: u.len() / channels * channels,
                found: u.len(),
            });
        }
        check_frame("u", u, u.len())?;
        check_frame("x", x, u.len())?;
        if out.len() != u.len() {
            return Err(Error::LengthMismatch { what: "bank output", expected: u.len(), found: out.len() });
        }
        for ((uf, xf), of) in u.chunks_exact(channels).zip(x.chunks_exact(channels)).zip(out.chunks_exact_mut(channels))
        {
            self.push(uf, xf, of)?;
        }
        Ok(())
    }

    /// One frame for the models: voltages `u` \[V\] in, displacements \[µm\] out
    /// (see [`ModelBank::step`]).
    pub fn step_models(&mut self, u: &[f64], x_out: &mut [f64]) -> Result<()> {
        self.models.step(u, x_out)
    }

    /// Every model takes its identifier's current estimates, and every inverse too
    /// where they keep x(u) rising (both branch slopes ≥ a fraction of kv up to the
    /// larger |h| of the identifier and the inverse, see
    /// [`crate::compensate::admissible`]; otherwise the inverse keeps its parameters).
    /// States are kept. Call it when the models and the feedforward should follow what
    /// the identifiers learnt.
    pub fn adopt_estimates(&mut self) -> Result<()> {
        for (c, id) in self.identifiers.iter().enumerate() {
            let p = id.params();
            self.models.set_params(c, p)?;
            let inv = &mut self.inverses[c];
            if admissible(&p, id.h().abs().max(inv.h().abs())) {
                inv.set_params(p)?;
            }
        }
        Ok(())
    }

    /// Every identifier, model and inverse back to its state right after construction
    /// (the inverses keep their current parameters and limits).
    pub fn reset(&mut self) {
        self.identifiers.iter_mut().for_each(|id| id.reset());
        self.models.reset();
        self.inverses.iter_mut().for_each(|inv| inv.reset());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compensate::VoltageLimits;
    use crate::identify::{AnyIdentifier, PaperConfig, PaperIdentifier, RpemConfig, RpemIdentifier};
    use crate::model::paper_input;

    const DT: f64 = 1e-4;

    /// C channels of different records: the paper input, shifted and scaled per
    /// channel, measured through a model with channel-dependent parameters plus
    /// deterministic noise.
    fn frames(channels: usize, len: usize) -> (Vec<f64>, Vec<f64>) {
        let base = paper_input(DT, 0.05);
        let mut u = vec![0.0; len * channels];
        let mut x = vec![0.0; len * channels];
        for c in 0..channels {
            let p = Params { kv: 0.19 + 0.01 * c as f64, beta: 0.02 + 0.002 * c as f64, ..Params::paper_1hz() };
            let mut m = Model::new(p, DT, 0.0).unwrap();
            for t in 0..len {
                let v = base[(t * (c + 1) * 7) % base.len()] * (1.0 - 0.03 * c as f64);
                u[t * channels + c] = v;
                let noise = 1e-3 * ((t * 31 + c * 17) % 13) as f64 / 13.0;
                x[t * channels + c] = m.step(v).unwrap() + noise;
            }
        }
        (u, x)
    }

    fn channel(v: &[f64], channels: usize, c: usize) -> Vec<f64> {
        v.iter().skip(c).step_by(channels).copied().collect()
    }

    #[test]
    fn each_channel_equals_a_single_channel_object_bit_for_bit() {
        let channels = 5;
        let len = 6000;
        let (u, x) = frames(channels, len);
        let rpem = RpemIdentifier::new(DT, Params::paper_1hz(), 0.0, RpemConfig::default()).unwrap();
        let paper = PaperIdentifier::new(DT, Params::paper_1hz(), 0.0, PaperConfig::with_window(200)).unwrap();
        for proto in [AnyIdentifier::Rpem(rpem), AnyIdentifier::Paper(paper)] {
            let mut bank = Bank::new(channels, proto.clone(), DT).unwrap();
            let mut pred = vec![0.0; u.len()];
            bank.push_many(&u, &x, &mut pred).unwrap();
            let mut modelled = vec![0.0; u.len()];
            for (uf, of) in u.chunks_exact(channels).zip(modelled.chunks_exact_mut(channels)) {
                bank.step_models(uf, of).unwrap();
            }
            for c in 0..channels {
                let (uc, xc) = (channel(&u, channels, c), channel(&x, channels, c));
                let mut single = proto.clone();
                let mut want = vec![0.0; len];
                single.push_many(&uc, &xc, &mut want).unwrap();
                let got = channel(&pred, channels, c);
                assert!(
                    got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{} channel {c}",
                    proto.method()
                );
                assert_eq!(bank.identifiers()[c], single);
                let mut model = Model::new(Params::paper_1hz(), DT, 0.0).unwrap();
                let want: Vec<f64> = uc.iter().map(|&v| model.step(v).unwrap()).collect();
                let got = channel(&modelled, channels, c);
                assert!(got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "model channel {c}");
                assert_eq!(bank.models().channel_model(c).unwrap(), model);
            }
        }
    }

    /// Channels of different parameters (slow, n < 1, stiff, steep; a partial group of
    /// lanes at the end) over the paper input at several speeds: each is a single
    /// [`Model`] bit for bit, whether its intervals take the lanes or the general path.
    #[test]
    fn models_of_different_parameters_equal_single_models_bit_for_bit() {
        let kinds = [
            Params::paper_1hz(),
            Params { n: 0.64, ..Params::paper_1hz() },
            Params { beta: 0.4, gamma: 0.1, n: 2.5, ..Params::paper_1hz() },
            Params { a: 0.3, beta: 0.02, gamma: 0.01, n: 1.1, delta: -0.01, ..Params::paper_1hz() },
        ];
        let channels = 7;
        let base = paper_input(DT, 0.05);
        let len = base.len();
        let u_of = |c: usize, t: usize| base[(t * (1 + c % 3) + 311 * c) % len];
        let mut bank = ModelBank::new(channels, Params::paper_1hz(), DT, 0.0).unwrap();
        let mut singles: Vec<Model> = (0..channels)
            .map(|c| {
                bank.set_params(c, kinds[c % kinds.len()]).unwrap();
                Model::new(kinds[c % kinds.len()], DT, 0.0).unwrap()
            })
            .collect();
        let mut out = vec![0.0; channels];
        for t in 0..len {
            let frame: Vec<f64> = (0..channels).map(|c| u_of(c, t)).collect();
            bank.step(&frame, &mut out).unwrap();
            for (c, single) in singles.iter_mut().enumerate() {
                assert_eq!(out[c].to_bits(), single.step(frame[c]).unwrap().to_bits(), "sample {t}, channel {c}");
            }
        }
        for (c, single) in singles.iter().enumerate() {
            assert_eq!(&bank.channel_model(c).unwrap(), single);
        }
    }

    #[test]
    fn models_follow_the_identifiers_when_asked() {
        let channels = 3;
        let (u, x) = frames(channels, 3000);
        let id = RpemIdentifier::new(DT, Params::paper_1hz(), 0.0, RpemConfig::default()).unwrap();
        let mut bank = Bank::new(channels, id, DT).unwrap();
        let mut pred = vec![0.0; u.len()];
        bank.push_many(&u, &x, &mut pred).unwrap();
        bank.adopt_estimates().unwrap();
        for c in 0..channels {
            assert_eq!(bank.models().params(c), bank.identifiers()[c].params());
        }
        assert_ne!(bank.models().params(0), bank.models().params(2));
    }

    #[test]
    fn each_channel_feeds_forward_as_a_single_inverse() {
        let channels = 3;
        let (u, x) = frames(channels, 3000);
        let id = RpemIdentifier::new(DT, Params::paper_1hz(), 0.0, RpemConfig::default()).unwrap();
        let mut bank = Bank::new(channels, id, DT).unwrap();
        bank.set_voltage_limits(VoltageLimits::new(Some(0.0), Some(100.0)).unwrap()).unwrap();
        let mut singles: Vec<Inverse> = bank.inverses().to_vec();
        let (mut pred, mut u_ff) = (vec![0.0; channels], vec![0.0; channels]);
        for (t, (uf, xf)) in u.chunks_exact(channels).zip(x.chunks_exact(channels)).enumerate() {
            bank.push(uf, xf, &mut pred).unwrap();
            if t % 500 == 499 {
                bank.adopt_estimates().unwrap();
                for (single, inv) in singles.iter_mut().zip(bank.inverses()) {
                    single.set_params(*inv.params()).unwrap();
                }
            }
            bank.feedforward(xf, &mut u_ff).unwrap();
            for c in 0..channels {
                assert_eq!(u_ff[c].to_bits(), singles[c].step(xf[c]).unwrap().to_bits(), "frame {t}, channel {c}");
            }
        }
        assert_ne!(bank.inverses()[0].params(), &Params::paper_1hz(), "the inverses took the estimates");
        let before = bank.clone();
        assert!(bank.feedforward(&[1.0, f64::NAN, 1.0], &mut u_ff).is_err());
        assert!(bank.feedforward(&[1.0, 1.0], &mut u_ff[..2]).is_err());
        assert_eq!(bank, before);
    }

    #[test]
    fn a_bad_frame_is_rejected_whole_and_changes_nothing() {
        let channels = 4;
        let (u, x) = frames(channels, 50);
        let id = RpemIdentifier::new(DT, Params::paper_1hz(), 0.0, RpemConfig::default()).unwrap();
        let mut bank = Bank::new(channels, id, DT).unwrap();
        let mut pred = vec![0.0; u.len()];
        bank.push_many(&u, &x, &mut pred).unwrap();
        let mut out = vec![0.0; channels];
        bank.step_models(&u[..channels], &mut out).unwrap();
        let before = bank.clone();
        let mut bad = u[..channels].to_vec();
        bad[2] = f64::NAN;
        assert!(matches!(bank.push(&bad, &x[..channels], &mut out), Err(Error::NonFiniteSample { .. })));
        assert!(bank.step_models(&bad, &mut out).is_err());
        assert!(matches!(bank.push(&u[..3], &x[..3], &mut out[..3]), Err(Error::LengthMismatch { .. })));
        let mut many = vec![0.0; 2 * channels];
        let mut bad_many = u[..2 * channels].to_vec();
        bad_many[channels + 1] = f64::INFINITY;
        assert!(bank.push_many(&bad_many, &x[..2 * channels], &mut many).is_err());
        assert!(bank.push_many(&u[..channels + 1], &x[..channels + 1], &mut many[..channels + 1]).is_err());
        assert_eq!(bank, before);
        assert!(ModelBank::new(0, Params::paper_1hz(), DT, 0.0).is_err());
        assert!(bank.models_mut().set_params(channels, Params::paper_1hz()).is_err());
    }
}
