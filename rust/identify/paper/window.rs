//! Fixed-capacity window of the newest samples, with running sums that stay exact.
//!
//! Running sums updated by `+= new; -= oldest` pick up rounding error at every
//! step and drift over long runs. [`WindowSums`] keeps a second, *shadow* sum that
//! starts from zero and takes only additions; after exactly `capacity` additions the
//! window holds precisely the samples the shadow has seen, so the shadow is a fresh
//! sum of the window and replaces the running one. Each sample costs O(1) (one add
//! to each sum), there is no O(N) spike, and the error never grows past that of one
//! window's worth of additions.

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
}
