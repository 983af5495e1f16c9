//! `delay`: the measurement lags the command by a whole number of samples.
//!
//! ```text
//! x_measured[k] = x[k − d]     (x\[0\] for k < d)
//! ```

use alloc::vec;
use alloc::vec::Vec;

use super::Effect;
use crate::error::{Error, Result};
use crate::model::scalar::Scalar;

/// Largest delay accepted \[samples\].
pub const MAX_DELAY_SAMPLES: usize = 1_000_000;

/// A pure delay of whole samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Delay {
    /// Delay d \[samples\] (0 … [`MAX_DELAY_SAMPLES`]).
    pub samples: usize,
}

impl Effect for Delay {
    const NAME: &'static str = "delay";

    fn validate(&self) -> Result<()> {
        if self.samples > MAX_DELAY_SAMPLES {
            return Err(Error::InvalidParameter {
                name: "delay.samples",
                value: self.samples as f64,
                reason: "must be at most 1000000 samples",
            });
        }
        Ok(())
    }
}

/// A ring of the last d+1 values: `push(v)` returns the value d samples ago
/// (the first value pushed while fewer than d+1 have arrived).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DelayLine<S = f64> {
    ring: Vec<S>,
    next: usize,
    filled: bool,
}

impl<S: Scalar> DelayLine<S> {
    pub(crate) fn new(samples: usize) -> Self {
        DelayLine { ring: vec![S::cst(0.0); samples + 1], next: 0, filled: false }
    }

    #[inline]
    pub(crate) fn push(&mut self, value: S) -> S {
        if !self.filled {
            self.ring.iter_mut().for_each(|v| *v = value);
            self.filled = true;
        }
        self.ring[self.next] = value;
        self.next = (self.next + 1) % self.ring.len();
        self.ring[self.next]
    }

    pub(crate) fn reset(&mut self) {
        self.filled = false;
        self.next = 0;
    }

    /// The delay in samples d.
    pub(crate) fn samples(&self) -> usize {
        self.ring.len() - 1
    }

    /// The d + 1 values held, oldest first (the next push returns the second); empty
    /// before the first push.
    pub(crate) fn values(&self) -> Vec<S> {
        if !self.filled {
            return Vec::new();
        }
        self.ring[self.next..].iter().chain(&self.ring[..self.next]).copied().collect()
    }

    /// Holds `values` (d + 1 of them, oldest first), as [`DelayLine::values`] gave them.
    pub(crate) fn set_values(&mut self, values: &[S]) {
        self.ring.copy_from_slice(values);
        self.next = 0;
        self.filled = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delays_by_whole_samples_and_holds_the_first_value() {
        let mut line = DelayLine::new(2);
        let out: Vec<f64> = [1.0, 2.0, 3.0, 4.0].iter().map(|&v| line.push(v)).collect();
        assert_eq!(out, vec![1.0, 1.0, 1.0, 2.0]);
        let mut line = DelayLine::new(0);
        assert_eq!(line.push(5.0), 5.0);
    }
}
