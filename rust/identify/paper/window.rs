//! Fixed-capacity window of the newest samples, with running sums that stay exact.
//!
//! Running sums updated by `+= new; -= oldest` pick up rounding error at every
//! step and drift over long runs. [`WindowSums`] keeps a second, *shadow* sum that
//! starts from zero and takes only additions; after exactly `capacity` additions the
//! window holds precisely the samples the shadow has seen, so the shadow is a fresh
//! sum of the window and replaces the running one. Each sample costs O(1) (one add
//! to each sum), there is no O(N) spike, and the error never grows past that of one
//! window's worth of additions.
//!
//! [`SlidingRange`] keeps the least and greatest of the values in the same kind of
//! window (monotone deques: amortised O(1) per sample, no allocation after
//! construction).

use alloc::vec;
use alloc::vec::Vec;

/// A ring buffer of `Copy` items with a capacity fixed at construction (no
/// allocation after [`Ring::with_capacity`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Ring<T: Copy> {
    items: Vec<T>,
    head: usize,
    len: usize,
    capacity: usize,
}

impl<T: Copy + Default> Ring<T> {
    /// An empty ring that holds at most `capacity` (≥ 1) items.
    pub fn with_capacity(capacity: usize) -> Self {
        let capacity = capacity.max(1);
        Ring { items: vec![T::default(); capacity], head: 0, len: 0, capacity }
    }

    /// Appends `item`; returns the oldest item when the ring was full.
    #[inline]
    pub fn push(&mut self, item: T) -> Option<T> {
        let slot = (self.head + self.len) % self.capacity;
        if self.len == self.capacity {
            let old = self.items[self.head];
            self.items[self.head] = item;
            self.head = (self.head + 1) % self.capacity;
            Some(old)
        } else {
            self.items[slot] = item;
            self.len += 1;
            None
        }
    }

    /// Number of items held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// No item held.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Holds `capacity` items.
    pub fn is_full(&self) -> bool {
        self.len == self.capacity
    }

    /// The capacity given at construction.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// The `i`-th item from the oldest (`None` past the newest).
    #[inline]
    pub fn get(&self, i: usize) -> Option<&T> {
        (i < self.len).then(|| &self.items[(self.head + i) % self.capacity])
    }

    /// The `i`-th item from the oldest, to change in place (`None` past the newest).
    #[inline]
    pub fn get_mut(&mut self, i: usize) -> Option<&mut T> {
        (i < self.len).then(|| &mut self.items[(self.head + i) % self.capacity])
    }

    /// The newest item.
    #[inline]
    pub fn last(&self) -> Option<&T> {
        self.len.checked_sub(1).and_then(|i| self.get(i))
    }

    /// The oldest item.
    #[inline]
    pub fn first(&self) -> Option<&T> {
        self.get(0)
    }

    /// Removes and returns the oldest item.
    #[inline]
    pub fn pop_front(&mut self) -> Option<T> {
        let item = *self.first()?;
        self.head = (self.head + 1) % self.capacity;
        self.len -= 1;
        Some(item)
    }

    /// Removes and returns the newest item.
    #[inline]
    pub fn pop_back(&mut self) -> Option<T> {
        let item = *self.last()?;
        self.len -= 1;
        Some(item)
    }

    /// Items from the oldest to the newest.
    pub fn iter(&self) -> impl Iterator<Item = &T> + '_ {
        (0..self.len).map(move |i| &self.items[(self.head + i) % self.capacity])
    }

    /// Empties the ring (capacity kept).
    pub fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
    }
}

/// `K` running sums over a window of `capacity` samples, refreshed exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowSums<const K: usize> {
    sums: [f64; K],
    shadow: [f64; K],
    shadow_count: usize,
    capacity: usize,
}

impl<const K: usize> WindowSums<K> {
    /// Zero sums over a window of `capacity` samples.
    pub fn new(capacity: usize) -> Self {
        WindowSums { sums: [0.0; K], shadow: [0.0; K], shadow_count: 0, capacity: capacity.max(1) }
    }

    /// Adds the contribution of a sample entering and, if any, removes that of the
    /// sample leaving. Returns `true` when this call refreshed the sums exactly.
    #[inline]
    pub fn slide(&mut self, entering: &[f64; K], leaving: Option<&[f64; K]>) -> bool {
        for ((sum, shadow), &v) in self.sums.iter_mut().zip(&mut self.shadow).zip(entering) {
            *sum += v;
            *shadow += v;
        }
        if let Some(old) = leaving {
            for (sum, &v) in self.sums.iter_mut().zip(old) {
                *sum -= v;
            }
        }
        self.shadow_count += 1;
        if self.shadow_count == self.capacity {
            self.sums = self.shadow;
            self.shadow = [0.0; K];
            self.shadow_count = 0;
            true
        } else {
            false
        }
    }

    /// The current sums.
    #[inline]
    pub fn get(&self) -> &[f64; K] {
        &self.sums
    }

    /// Sets every sum to zero.
    pub fn clear(&mut self) {
        *self = Self::new(self.capacity);
    }
}

/// The least and greatest value among the samples of a sliding window of the newest
/// `window` sample numbers, where a sample may carry no value (it still slides the
/// window). Two monotone deques of (sample number, value): the lows increase and the
/// highs decrease from the oldest to the newest, so the front of each is the window's
/// extreme. A value that enters removes from the back every one it makes redundant
/// (an older value that is no lower, resp. no higher, leaves the window first and can
/// never be the extreme again); a value leaves the front when its sample leaves the
/// window. Each value enters and leaves each deque once: amortised O(1) per sample.
///
/// The deques are a function of the window's values alone (not of the order of the
/// slides that brought them), so sliding in a window's values again, oldest first,
/// rebuilds them exactly (a restore).
#[derive(Debug, Clone, PartialEq)]
pub struct SlidingRange {
    lows: Ring<(u64, f64)>,
    highs: Ring<(u64, f64)>,
    window: u64,
}

impl SlidingRange {
    /// An empty range over windows of `window` samples (0: holds nothing, no buffers).
    pub fn new(window: usize) -> Self {
        SlidingRange { lows: Ring::with_capacity(window), highs: Ring::with_capacity(window), window: window as u64 }
    }

    /// Slides the window to end at sample `seq` (sample numbers strictly increase from
    /// one call to the next) and enters `value` where the sample carries one. NaN
    /// values are ignored, as `f64::min` and `f64::max` ignore them.
    #[inline]
    pub fn slide(&mut self, seq: u64, value: Option<f64>) {
        if self.window == 0 {
            return;
        }
        // Sample `s` is in the window ending at `seq` while s + window > seq.
        for deque in [&mut self.lows, &mut self.highs] {
            while deque.first().is_some_and(|&(s, _)| s + self.window <= seq) {
                deque.pop_front();
            }
        }
        let Some(v) = value.filter(|v| !v.is_nan()) else {
            return;
        };
        while self.lows.last().is_some_and(|&(_, w)| w >= v) {
            self.lows.pop_back();
        }
        while self.highs.last().is_some_and(|&(_, w)| w <= v) {
            self.highs.pop_back();
        }
        // At most window − 1 values remain after the expiry: neither ring evicts.
        self.lows.push((seq, v));
        self.highs.push((seq, v));
    }

    /// The least and greatest value in the window; (∞, −∞) when it holds none.
    #[inline]
    pub fn range(&self) -> (f64, f64) {
        (
            self.lows.first().map_or(f64::INFINITY, |&(_, v)| v),
            self.highs.first().map_or(f64::NEG_INFINITY, |&(_, v)| v),
        )
    }

    /// Empties the window (buffers kept).
    pub fn clear(&mut self) {
        self.lows.clear();
        self.highs.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_evicts_the_oldest() {
        let mut r = Ring::with_capacity(3);
        assert_eq!(r.push(1), None);
        r.push(2);
        r.push(3);
        assert_eq!(r.push(4), Some(1));
        assert_eq!(r.iter().copied().collect::<Vec<_>>(), vec![2, 3, 4]);
    }

    /// After many slides with large offsets the running sum equals a fresh sum of
    /// the window to within the rounding of one window's additions (≤ 1e-12 relative
    /// here; a plain running sum drifts by orders of magnitude more).
    #[test]
    fn sums_stay_exact_over_long_runs() {
        let capacity = 97;
        let mut ring = Ring::with_capacity(capacity);
        let mut sums = WindowSums::<2>::new(capacity);
        let mut naive = [0.0f64; 2];
        for k in 0..1_000_000u64 {
            let v = 1.0e6 + ((k * 7919) % 1000) as f64 * 0.123_456_789;
            let item = [v, v * v];
            let old = ring.push(item);
            sums.slide(&item, old.as_ref());
            naive[0] += item[0];
            naive[1] += item[1];
            if let Some(o) = old {
                naive[0] -= o[0];
                naive[1] -= o[1];
            }
        }
        let exact: [f64; 2] = ring.iter().fold([0.0; 2], |acc, it| [acc[0] + it[0], acc[1] + it[1]]);
        for (i, (&got, &want)) in sums.get().iter().zip(&exact).enumerate() {
            let rel = ((got - want) / want).abs();
            assert!(rel <= 1e-12, "sum {i}: relative error {rel}");
        }
    }

    /// The sliding range equals a scan of the window after every sample: random values
    /// (quantised, so that equal values occur) on two branches that change at random
    /// lengths, with samples that carry no value, for several window lengths.
    #[test]
    fn sliding_range_matches_a_scan() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for window in [1usize, 2, 3, 16, 97] {
            let mut ranges = [SlidingRange::new(window), SlidingRange::new(window)];
            let mut history: Vec<(Option<usize>, f64)> = Vec::new();
            let mut branch = 0usize;
            let mut left = 0u64;
            for seq in 0..5_000u64 {
                if left == 0 {
                    branch ^= 1;
                    left = 1 + next() % (2 * window as u64 + 3);
                }
                left -= 1;
                let value = (next() % 41) as f64 * 0.25 - 5.0;
                let on = (next() % 11 != 0).then_some(branch);
                history.push((on, value));
                for (b, r) in ranges.iter_mut().enumerate() {
                    r.slide(seq, (on == Some(b)).then_some(value));
                }
                let from = history.len().saturating_sub(window);
                for (b, r) in ranges.iter().enumerate() {
                    let scan = history[from..]
                        .iter()
                        .filter(|(on, _)| *on == Some(b))
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &(_, v)| (lo.min(v), hi.max(v)));
                    assert_eq!(r.range(), scan, "window {window}, sample {seq}, branch {b}");
                }
            }
        }
    }
}
