//! The crate's elementary functions, one place for every transcendental call.
//!
//! With the `std` feature (the default) each function is the standard library's
//! `f64` method, which calls the platform's C maths library (glibc on Linux), the
//! same one NumPy uses: the results are those of every earlier build and of the
//! NumPy reference, bit for bit. Without `std` (`#![no_std]`, e.g.
//! `thumbv7em-none-eabihf`) they come from the [`libm`] crate, a port of musl's
//! maths library. Both are faithfully rounded (error below one unit in the last
//! place); they can differ in the last bit for some arguments, so a `no_std` build
//! reproduces a `std` build's results to rounding, not always bit for bit (the test
//! `libm_and_std_agree_to_one_ulp` below measures how often on the model's own
//! arguments).
//!
//! Everything that needs no maths library (`abs`, `min`, `max`, `clamp`,
//! `is_finite`) stays a method call: those are in `core`.

/// xʸ.
#[inline(always)]
pub fn powf(x: f64, y: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.powf(y)
    }
    #[cfg(not(feature = "std"))]
    {
        libm::pow(x, y)
    }
}

/// xⁿ for an integer n (repeated multiplication, as the standard library's `powi`).
#[inline(always)]
pub fn powi(x: f64, n: i32) -> f64 {
    #[cfg(feature = "std")]
    {
        x.powi(n)
    }
    #[cfg(not(feature = "std"))]
    {
        // Square and multiply, as compiler-rt's __powidf2 (what `powi` lowers to).
        let negative = n < 0;
        let mut e = n.unsigned_abs();
        let mut base = x;
        let mut r = 1.0;
        loop {
            if e & 1 == 1 {
                r *= base;
            }
            e >>= 1;
            if e == 0 {
                break;
            }
            base *= base;
        }
        if negative {
            1.0 / r
        } else {
            r
        }
    }
}

/// eˣ.
#[inline(always)]
pub fn exp(x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.exp()
    }
    #[cfg(not(feature = "std"))]
    {
        libm::exp(x)
    }
}

/// Natural logarithm.
#[inline(always)]
pub fn ln(x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.ln()
    }
    #[cfg(not(feature = "std"))]
    {
        libm::log(x)
    }
}

/// Square root (correctly rounded in both: IEEE 754 requires it).
#[inline(always)]
pub fn sqrt(x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.sqrt()
    }
    #[cfg(not(feature = "std"))]
    {
        libm::sqrt(x)
    }
}

/// Smallest integer ≥ x.
#[inline(always)]
pub fn ceil(x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.ceil()
    }
    #[cfg(not(feature = "std"))]
    {
        libm::ceil(x)
    }
}

/// Nearest integer, halves away from zero.
#[inline(always)]
pub fn round(x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.round()
    }
    #[cfg(not(feature = "std"))]
    {
        libm::round(x)
    }
}

/// Sine (x in radians).
#[inline(always)]
pub fn sin(x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.sin()
    }
    #[cfg(not(feature = "std"))]
    {
        libm::sin(x)
    }
}

/// Cosine (x in radians).
#[inline(always)]
pub fn cos(x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.cos()
    }
    #[cfg(not(feature = "std"))]
    {
        libm::cos(x)
    }
}

/// The largest integer not above x.
#[inline(always)]
pub fn floor(x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.floor()
    }
    #[cfg(not(feature = "std"))]
    {
        libm::floor(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ulps(a: f64, b: f64) -> u64 {
        (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs()
    }

    /// The no_std functions (libm) against the std ones on the arguments the model
    /// meets: |h|^n over the range of h \[µm\] and n the integrator sees, and exp and
    /// ln over the identifiers' ranges. They agree within one unit in the last place;
    /// the share of last-bit differences is printed (`--nocapture`).
    #[test]
    fn libm_and_std_agree_to_one_ulp() {
        let mut differ = 0usize;
        let mut total = 0usize;
        for i in 0..2000 {
            let h = 1e-4 * (1.0 + i as f64 * 0.137).powi(3);
            for n in [1.0, 1.2, 1.52, 2.0, 2.5, 3.7] {
                let (a, b) = (libm::pow(h, n), powf(h, n));
                assert!(ulps(a, b) <= 1, "pow({h}, {n}): {a} vs {b}");
                differ += (a != b) as usize;
                total += 1;
            }
            let x = -30.0 + i as f64 * 0.0301;
            assert!(ulps(libm::exp(x), exp(x)) <= 1);
            assert!(ulps(libm::log(h), ln(h)) <= 1);
        }
        eprintln!("pow: libm and std differ in the last bit in {differ} of {total} calls");
        assert_eq!(libm::sqrt(2.0), sqrt(2.0));
        for (x, n) in [(1.7, 2), (-0.3, 3), (2.5, -2), (0.9, 0)] {
            assert_eq!(powi(x, n), x.powi(n));
        }
    }
}
