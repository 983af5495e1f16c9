//! The discrete Fourier transform of any length, for the periodic band-limited
//! reconstruction ([`super::InputPath`]): mixed-radix Cooley–Tukey over the prime
//! factors of the length, each small prime by its direct sum, a large prime factor by
//! Bluestein's chirp convolution on a power of two. O(n·Σp) for lengths whose prime
//! factors p are small (the records of periodic excitations, e.g. 8192·5), O(n log n)
//! for any other. Run once per record, never per simulation.

use alloc::vec;
use alloc::vec::Vec;

use nalgebra::Complex;

use crate::math;

/// Prime factors above this are taken by Bluestein's algorithm instead of their direct
/// sum (p² operations per group).
const DIRECT_PRIME_MAX: usize = 64;

type C = Complex<f64>;

/// exp(i·angle).
#[inline]
fn cis(angle: f64) -> C {
    C::new(math::cos(angle), math::sin(angle))
}

/// X_k = Σ_j x_j·exp(∓2πi·jk/n): the forward transform (`inverse` false, minus sign) or
/// the unnormalised inverse (plus sign).
pub(crate) fn dft(x: &[C], inverse: bool) -> Vec<C> {
    let n = x.len();
    if n <= 1 {
        return x.to_vec();
    }
    let sign = if inverse { 1.0 } else { -1.0 };
    let table: Vec<C> = (0..n).map(|j| cis(sign * 2.0 * core::f64::consts::PI * j as f64 / n as f64)).collect();
    let input: Vec<C> = x.to_vec();
    transform(&input, 0, 1, n, &table, sign)
}

/// The transform of the `n` values `x[offset + i·stride]`, the twiddles read from
/// `table` (exp(sign·2πi·j/N) for the top length N = `table.len()`).
fn transform(x: &[C], offset: usize, stride: usize, n: usize, table: &[C], sign: f64) -> Vec<C> {
    if n == 1 {
        return vec![x[offset]];
    }
    let top = table.len();
    let p = smallest_factor(n);
    if p == n {
        let values: Vec<C> = (0..n).map(|i| x[offset + i * stride]).collect();
        return if n <= DIRECT_PRIME_MAX { direct(&values, table, top / n) } else { bluestein(&values, sign) };
    }
    let m = n / p;
    let parts: Vec<Vec<C>> = (0..p).map(|r| transform(x, offset + r * stride, stride * p, m, table, sign)).collect();
    let scale = top / n;
    let mut out = vec![C::new(0.0, 0.0); n];
    for (k, slot) in out.iter_mut().enumerate() {
        let km = k % m;
        let mut sum = parts[0][km];
        for (r, part) in parts.iter().enumerate().skip(1) {
            sum += part[km] * table[(r * k % n) * scale];
        }
        *slot = sum;
    }
    out
}

/// The direct sum for a small prime length, twiddles `table[(j·k mod n)·scale]`.
fn direct(x: &[C], table: &[C], scale: usize) -> Vec<C> {
    let n = x.len();
    (0..n)
        .map(|k| x.iter().enumerate().fold(C::new(0.0, 0.0), |acc, (j, &v)| acc + v * table[(j * k % n) * scale]))
        .collect()
}

/// Bluestein: jk = (j² + k² − (k − j)²)/2 turns the transform into a convolution with
/// the chirp exp(−sign·iπ·m²/n), taken by power-of-two transforms (the phases from m²
/// mod 2n, so that they stay exact for long records).
fn bluestein(x: &[C], sign: f64) -> Vec<C> {
    let n = x.len();
    let size = (2 * n - 1).next_power_of_two();
    let chirp = |m: usize| -> C {
        let sq = ((m as u128 * m as u128) % (2 * n as u128)) as f64;
        cis(sign * core::f64::consts::PI * sq / n as f64)
    };
    let w: Vec<C> = (0..n).map(chirp).collect();
    let mut a = vec![C::new(0.0, 0.0); size];
    for (j, (&v, c)) in x.iter().zip(&w).enumerate() {
        a[j] = v * c;
    }
    let mut b = vec![C::new(0.0, 0.0); size];
    b[0] = w[0].conj();
    for m in 1..n {
        b[m] = w[m].conj();
        b[size - m] = w[m].conj();
    }
    let (fa, fb) = (dft(&a, false), dft(&b, false));
    let product: Vec<C> = fa.iter().zip(&fb).map(|(u, v)| u * v).collect();
    let conv = dft(&product, true);
    (0..n).map(|k| conv[k] / size as f64 * w[k]).collect()
}

/// The smallest prime factor of `n` ≥ 2.
fn smallest_factor(n: usize) -> usize {
    if n % 2 == 0 {
        return 2;
    }
    let mut p = 3;
    while p * p <= n {
        if n % p == 0 {
            return p;
        }
        p += 2;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive(x: &[C], sign: f64) -> Vec<C> {
        let n = x.len();
        (0..n)
            .map(|k| {
                x.iter().enumerate().fold(C::new(0.0, 0.0), |acc, (j, &v)| {
                    acc + v * cis(sign * 2.0 * core::f64::consts::PI * ((j * k) % n) as f64 / n as f64)
                })
            })
            .collect()
    }

    #[test]
    fn matches_the_direct_sum_for_composite_prime_and_power_of_two_lengths() {
        for n in [1usize, 2, 3, 5, 12, 64, 97, 127, 240, 257, 1000, 1031] {
            let x: Vec<C> = (0..n).map(|j| C::new((j as f64 * 0.37).sin(), (j as f64 * 1.3).cos() - 0.2)).collect();
            for inverse in [false, true] {
                let fast = dft(&x, inverse);
                let slow = naive(&x, if inverse { 1.0 } else { -1.0 });
                let scale = slow.iter().fold(1.0f64, |a, v| a.max(v.norm()));
                let worst = fast.iter().zip(&slow).fold(0.0f64, |a, (u, v)| a.max((u - v).norm()));
                assert!(worst <= 1e-12 * scale, "n = {n}: {worst:e}");
            }
            let back: Vec<C> = dft(&dft(&x, false), true).iter().map(|v| v / n as f64).collect();
            let worst = back.iter().zip(&x).fold(0.0f64, |a, (u, v)| a.max((u - v).norm()));
            assert!(worst <= 1e-12, "n = {n}: round trip {worst:e}");
        }
    }
}
