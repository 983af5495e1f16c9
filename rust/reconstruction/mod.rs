//! What the input does between samples: a sampled input rebuilt as a function of time,
//! the part of the measurement chain the integrators of both model classes read
//! ([`crate::oscillator`], and the piezo model's chain in [`crate::effects`]).
//!
//! A record holds the input at the sample instants only; what it did in between was set
//! by the rig, and a model integrated between the samples has to assume it:
//!
//! - [`Reconstruction::Hold`]: zero-order hold, a DAC: u(t) = u\[k−1\] on
//!   \[t_{k−1}, t_k), the value u\[k\] from t_k on (the output at t_k sees u\[k\] through
//!   any static path, as the ZOH-equivalent discretisation of a linear system does);
//! - [`Reconstruction::Linear`]: first-order hold, a straight line from u\[k−1\] to u\[k\];
//! - [`Reconstruction::Bandlimited`]: the band-limited signal through the samples, a
//!   smooth generator sampled by the logger. For a periodic record (a whole number of
//!   periods, [`InputPath::new`]'s `periodic`) exactly the Fourier interpolation
//!   (trigonometric polynomial of the record's DFT); for any other record the
//!   Kaiser-windowed sinc of [`sinc::HALF_WIDTH`] samples on either side, the record
//!   extended beyond its ends by point reflection, to within [`sinc::error_bound`]
//!   (3.1e-8 of the line amplitudes for content up to 0.8 of the Nyquist frequency).
//!
//! Within an interval a band-limited path is the polynomial of degree [`PIECES`]
//! through its values at [`KNOTS`] equally spaced points (both samples included). For
//! content up to 0.4 of the Nyquist frequency (the benchmark's 150 Hz at 750 Hz) the
//! polynomial is within 6.4e-10 of each line's amplitude of the reconstruction
//! (|f⁽⁹⁾|/9!·max|Π(s − j/8)|·dt⁹ with |f⁽⁹⁾| ≤ ω⁹·amplitude, ω·dt ≤ 0.4π).

mod fft;
pub mod sinc;

use alloc::vec::Vec;

use nalgebra::{Complex, SMatrix, SVector};

use crate::error::{finite_sample, Result};
use crate::math;

/// Equal pieces of a sample interval at whose ends a band-limited path is computed.
pub const PIECES: usize = 8;
/// Points per interval of a band-limited path, both samples included.
pub const KNOTS: usize = PIECES + 1;

/// What the input does between samples (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Reconstruction {
    /// Zero-order hold (a DAC).
    Hold,
    /// A straight line between samples (first-order hold).
    #[default]
    Linear,
    /// The band-limited signal through the samples.
    Bandlimited,
}

impl Reconstruction {
    /// The names, in the order hold, linear, bandlimited.
    pub const NAMES: [&'static str; 3] = ["hold", "linear", "bandlimited"];

    /// The name (`"hold"`, `"linear"`, `"bandlimited"`).
    pub fn name(self) -> &'static str {
        match self {
            Reconstruction::Hold => Self::NAMES[0],
            Reconstruction::Linear => Self::NAMES[1],
            Reconstruction::Bandlimited => Self::NAMES[2],
        }
    }

    /// The reconstruction of that name; `None` for any other.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "hold" => Some(Reconstruction::Hold),
            "linear" => Some(Reconstruction::Linear),
            "bandlimited" => Some(Reconstruction::Bandlimited),
            _ => None,
        }
    }

    /// Its code in snapshots and the C ABI: 0 hold, 1 linear, 2 bandlimited.
    pub fn code(self) -> u8 {
        match self {
            Reconstruction::Hold => 0,
            Reconstruction::Linear => 1,
            Reconstruction::Bandlimited => 2,
        }
    }

    /// Inverse of [`Reconstruction::code`].
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(Reconstruction::Hold),
            1 => Some(Reconstruction::Linear),
            2 => Some(Reconstruction::Bandlimited),
            _ => None,
        }
    }

    /// Whether the value within an interval depends on samples after its end (the
    /// band-limited path does: it cannot be built sample by sample).
    pub fn needs_the_record(self) -> bool {
        self == Reconstruction::Bandlimited
    }
}

/// A sampled input as a function of time over its record: one piece per sample
/// interval, interval k running from sample k − 1 to sample k (1 ≤ k < len).
#[derive(Debug, Clone, PartialEq)]
pub struct InputPath {
    kind: Reconstruction,
    samples: Vec<f64>,
    /// Band-limited: per interval, the coefficients of its polynomial in x = 2s − 1
    /// (s ∈ \[0, 1\] the fraction of the interval), lowest degree first.
    poly: Vec<[f64; KNOTS]>,
    /// Band-limited: per interval, the least and largest of its knots.
    range: Vec<(f64, f64)>,
    /// Band-limited: [`band`] of the samples.
    band: f64,
}

impl InputPath {
    /// The path of `samples` (finite) under `kind`; `periodic`: the record is a whole
    /// number of periods of its input, so that the band-limited path is the exact
    /// Fourier interpolation (ignored by hold and linear).
    pub fn new(samples: &[f64], kind: Reconstruction, periodic: bool) -> Result<Self> {
        for &v in samples {
            finite_sample("u", v)?;
        }
        let mut path = InputPath { kind, samples: samples.to_vec(), poly: Vec::new(), range: Vec::new(), band: 0.0 };
        if kind == Reconstruction::Bandlimited && samples.len() >= 2 {
            path.band = band(samples, periodic);
            let inner = if periodic { fourier_knots(samples) } else { sinc_knots(samples) };
            let to_poly = knots_to_polynomial();
            for k in 1..samples.len() {
                let mut v = [0.0; KNOTS];
                v[0] = samples[k - 1];
                v[PIECES] = samples[k];
                for j in 1..PIECES {
                    v[j] = inner[(j - 1) * samples.len() + (k - 1)];
                }
                let c = to_poly * SVector::<f64, KNOTS>::from(v);
                path.poly.push(c.into());
                let lo = v.iter().fold(f64::INFINITY, |a, &b| a.min(b));
                let hi = v.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b));
                path.range.push((lo, hi));
            }
        }
        Ok(path)
    }

    /// The reconstruction.
    pub fn kind(&self) -> Reconstruction {
        self.kind
    }

    /// The samples.
    pub fn samples(&self) -> &[f64] {
        &self.samples
    }

    /// Samples of the record.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// No samples.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The input at the fraction `s` ∈ \[0, 1\] of interval `k` (1 ≤ k < len); at s = 1
    /// the value the interval ends with (for a hold, the held value: the next sample
    /// takes effect at the start of the next interval).
    #[inline(always)]
    pub fn at(&self, k: usize, s: f64) -> f64 {
        match self.kind {
            Reconstruction::Hold => self.samples[k - 1],
            Reconstruction::Linear => {
                let (a, b) = (self.samples[k - 1], self.samples[k]);
                a + (b - a) * s
            }
            Reconstruction::Bandlimited => polynomial(&self.poly[k - 1], 2.0 * s - 1.0),
        }
    }

    /// The least and largest value of the input over interval k (for a band-limited
    /// path, over its knots).
    #[inline(always)]
    pub fn range(&self, k: usize) -> (f64, f64) {
        match self.kind {
            Reconstruction::Hold => (self.samples[k - 1], self.samples[k - 1]),
            Reconstruction::Linear => {
                let (a, b) = (self.samples[k - 1], self.samples[k]);
                (a.min(b), a.max(b))
            }
            Reconstruction::Bandlimited => self.range[k - 1],
        }
    }

    /// The band-limited path's content reaches this frequency, as a fraction of the
    /// sample rate ([`band`]); 0 for hold and linear.
    pub fn band(&self) -> f64 {
        self.band
    }

    /// The coefficients of interval k's polynomial in x = 2s − 1 (band-limited only).
    #[inline(always)]
    pub(crate) fn polynomial(&self, k: usize) -> &[f64; KNOTS] {
        &self.poly[k - 1]
    }

    /// The values at the [`KNOTS`] points s = j/[`PIECES`] of interval k.
    pub fn knots(&self, k: usize) -> [f64; KNOTS] {
        core::array::from_fn(|j| self.at(k, j as f64 / PIECES as f64))
    }
}

/// Σ cᵢ·xⁱ by Horner's rule.
#[inline(always)]
pub(crate) fn polynomial(c: &[f64; KNOTS], x: f64) -> f64 {
    let mut v = c[KNOTS - 1];
    for &ci in c[..KNOTS - 1].iter().rev() {
        v = v * x + ci;
    }
    v
}

/// d/dx of [`polynomial`].
#[inline(always)]
pub(crate) fn polynomial_slope(c: &[f64; KNOTS], x: f64) -> f64 {
    let mut v = c[KNOTS - 1] * (KNOTS - 1) as f64;
    for i in (1..KNOTS - 1).rev() {
        v = v * x + c[i] * i as f64;
    }
    v
}

/// The matrix that takes the values at x_j = −1 + 2j/[`PIECES`] to the coefficients of
/// the polynomial through them (the inverse of their Vandermonde matrix; its condition
/// number on these points is about 3e3).
fn knots_to_polynomial() -> SMatrix<f64, KNOTS, KNOTS> {
    let v = SMatrix::<f64, KNOTS, KNOTS>::from_fn(|j, i| math::powi(-1.0 + 2.0 * j as f64 / PIECES as f64, i as i32));
    // Equally spaced distinct points: the matrix is invertible.
    v.try_inverse().unwrap_or_else(SMatrix::identity)
}

/// The band-limited values at the inner points j/[`PIECES`] (j = 1 … PIECES − 1) of
/// every interval of a periodic record, `out[(j − 1)·n + (k − 1)]` for interval k: the
/// record's DFT shifted by the fraction and transformed back. For an even length the
/// Nyquist line is the cosine through its samples (its two halves at ±n/2).
fn fourier_knots(u: &[f64]) -> Vec<f64> {
    let n = u.len();
    let x: Vec<Complex<f64>> = u.iter().map(|&v| Complex::new(v, 0.0)).collect();
    let spectrum = fft::dft(&x, false);
    let mut out = Vec::with_capacity((PIECES - 1) * n);
    for j in 1..PIECES {
        let frac = j as f64 / PIECES as f64;
        let shifted: Vec<Complex<f64>> = spectrum
            .iter()
            .enumerate()
            .map(|(m, &c)| {
                if 2 * m == n {
                    return c * math::cos(core::f64::consts::PI * frac);
                }
                let signed = if 2 * m < n { m as f64 } else { m as f64 - n as f64 };
                let angle = 2.0 * core::f64::consts::PI * signed * frac / n as f64;
                c * Complex::new(math::cos(angle), math::sin(angle))
            })
            .collect();
        let back = fft::dft(&shifted, true);
        out.extend(back.iter().map(|v| v.re / n as f64));
    }
    out
}

/// The windowed-sinc values at the inner points of every interval of a record
/// ([`sinc`]), laid out as [`fourier_knots`]'s.
fn sinc_knots(u: &[f64]) -> Vec<f64> {
    let n = u.len();
    let mut out = Vec::with_capacity((PIECES - 1) * n);
    for j in 1..PIECES {
        let taps = sinc::taps(j as f64 / PIECES as f64);
        for k0 in 0..n {
            let first = k0 as isize - (sinc::HALF_WIDTH as isize - 1);
            let v = taps.iter().enumerate().fold(0.0, |acc, (i, &t)| acc + t * sinc::extended(u, first + i as isize));
            out.push(v);
        }
    }
    out
}

/// Share of a record's power that may lie above its [`band`]: 1e-12, an amplitude of a
/// millionth of the record's RMS, whose sub-steps need not be resolved.
pub const POWER_ABOVE_BAND: f64 = 1e-12;

/// The frequency, as a fraction of the sample rate (≤ 0.5), above which `u`'s power
/// spectrum (of the record, or of the record under a Hann window where it is not
/// periodic, so that its ends do not spread power over every line) holds less than
/// [`POWER_ABOVE_BAND`] of its power, the mean left out.
pub fn band(u: &[f64], periodic: bool) -> f64 {
    let n = u.len();
    if n < 2 {
        return 0.0;
    }
    let mean = u.iter().sum::<f64>() / n as f64;
    let x: Vec<Complex<f64>> = u
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let w =
                if periodic { 1.0 } else { 0.5 - 0.5 * math::cos(2.0 * core::f64::consts::PI * i as f64 / n as f64) };
            Complex::new((v - mean) * w, 0.0)
        })
        .collect();
    let spectrum = fft::dft(&x, false);
    let power: Vec<f64> = spectrum[..=n / 2].iter().map(|c| c.norm_sqr()).collect();
    let total: f64 = power.iter().sum();
    if total == 0.0 {
        return 0.0;
    }
    let mut above = 0.0;
    for (m, &p) in power.iter().enumerate().rev() {
        above += p;
        if above > POWER_ABOVE_BAND * total {
            return m as f64 / n as f64;
        }
    }
    0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Σ a·cos(2π·m·t/n + φ) over `spec` = (m, a, φ), t in samples: a periodic record of
    /// n samples with lines m.
    fn lines(spec: &[(usize, f64, f64)], n: usize, t: f64) -> f64 {
        spec.iter().fold(0.0, |acc, &(m, a, ph)| {
            acc + a * math::cos(2.0 * core::f64::consts::PI * m as f64 * t / n as f64 + ph)
        })
    }

    /// The largest difference between the band-limited path of the periodic record of
    /// `spec` and its lines, at 17 points of every interval.
    fn periodic_error(spec: &[(usize, f64, f64)], n: usize) -> f64 {
        let u: Vec<f64> = (0..n).map(|k| lines(spec, n, k as f64)).collect();
        let path = InputPath::new(&u, Reconstruction::Bandlimited, true).unwrap();
        (1..n)
            .flat_map(|k| (0..=16).map(move |g| (k, g as f64 / 16.0)))
            .map(|(k, s)| (path.at(k, s) - lines(spec, n, (k - 1) as f64 + s)).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn a_periodic_band_limited_record_is_rebuilt_exactly_between_its_samples() {
        // 640 = 2^7·5 and 641 (prime, Bluestein); lines up to 0.19 of Nyquist: the
        // polynomial's bound is far below rounding there, so this is the Fourier values'.
        for n in [640usize, 641] {
            let worst = periodic_error(&[(3, 1.0, 0.3), (17, 0.5, -1.0), (60, 0.2, 2.0)], n);
            assert!(worst < 1e-12, "n = {n}: {worst:e}");
        }
        // A line at 0.875 of Nyquist: the polynomial's own error, (0.875π)⁹·2.95e-5/9! of
        // the amplitude 0.2, 1.5e-7.
        let worst = periodic_error(&[(3, 1.0, 0.3), (280, 0.2, 2.0)], 640);
        assert!(worst < 3e-7, "{worst:e}");
    }

    #[test]
    fn the_windowed_sinc_keeps_its_bound_away_from_the_ends() {
        // Not periodic over the record: lines at non-whole frequencies, up to 0.4 Nyquist.
        let f = |t: f64| math::sin(0.31 * t + 0.2) + 0.4 * math::cos(1.2 * t - 1.0);
        let n = 400;
        let u: Vec<f64> = (0..n).map(|k| f(k as f64)).collect();
        let path = InputPath::new(&u, Reconstruction::Bandlimited, false).unwrap();
        let bound = sinc::error_bound(1.2 / core::f64::consts::PI) * 1.4;
        let mut worst = 0.0f64;
        for k in sinc::HALF_WIDTH + 1..n - sinc::HALF_WIDTH {
            for j in 0..=PIECES {
                let s = j as f64 / PIECES as f64;
                worst = worst.max((path.at(k, s) - f((k - 1) as f64 + s)).abs());
            }
        }
        assert!(worst <= bound + 1e-14, "{worst:e} > {bound:e}");
    }

    #[test]
    fn hold_and_linear_are_what_they_say() {
        let u = [1.0, 3.0, -2.0];
        let hold = InputPath::new(&u, Reconstruction::Hold, false).unwrap();
        let line = InputPath::new(&u, Reconstruction::Linear, false).unwrap();
        assert_eq!((hold.at(1, 0.0), hold.at(1, 0.7), hold.at(2, 1.0)), (1.0, 1.0, 3.0));
        assert_eq!((line.at(1, 0.5), line.at(2, 1.0)), (2.0, -2.0));
        assert_eq!(line.range(2), (-2.0, 3.0));
        assert!(InputPath::new(&[0.0, f64::NAN], Reconstruction::Linear, false).is_err());
        for name in Reconstruction::NAMES {
            let r = Reconstruction::from_name(name).unwrap();
            assert_eq!((r.name(), Reconstruction::from_code(r.code())), (name, Some(r)));
        }
        assert_eq!(Reconstruction::from_name("cubic"), None);
    }

    #[test]
    fn the_polynomial_goes_through_its_knots_and_its_slope_is_its_derivative() {
        let u: Vec<f64> = (0..50).map(|k| math::sin(k as f64 * 0.7)).collect();
        let path = InputPath::new(&u, Reconstruction::Bandlimited, false).unwrap();
        for k in 1..u.len() {
            assert!((path.at(k, 0.0) - u[k - 1]).abs() < 1e-12 && (path.at(k, 1.0) - u[k]).abs() < 1e-12);
            let c = path.polynomial(k);
            let (x, e) = (0.3, 1e-6);
            let fd = (polynomial(c, x + e) - polynomial(c, x - e)) / (2.0 * e);
            assert!((fd - polynomial_slope(c, x)).abs() < 1e-7);
        }
    }
}
