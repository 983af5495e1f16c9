//! Save and restore: a compact byte snapshot of a [`Model`] or an online identifier.
//!
//! A control loop that is restarted can take up where it left off: `to_bytes()`
//! writes everything the object carries between samples, `from_bytes()` rebuilds
//! it, and the restored object continues bit for bit like the original (the same
//! predictions, estimates and state for every later sample).
//!
//! Format (no serde, no external schema): the 4-byte magic `BWSN`, a format
//! version byte, a kind byte, then the fields as little-endian IEEE-754 `f64`
//! bit patterns, `u64` counters and one-byte tags. Restoring validates every
//! value (parameters, configuration, lengths) and fails with
//! [`Error::InvalidConfig`] naming `snapshot` on a truncated, foreign or corrupt
//! byte string; it never panics.
//!
//! The window's running sums are restored through [`WindowSums`]' public
//! operations so that the running and the shadow sums come back with exactly
//! the bits they had (see [`rebuild_window_sums`]).

use crate::error::{Error, Result};
use crate::identify::window::WindowSums;
use crate::identify::AnyIdentifier;
use crate::model::{Model, ModelState};
use crate::params::Params;

/// First bytes of every snapshot.
pub const MAGIC: [u8; 4] = *b"BWSN";
/// Version of the layout written by this build.
pub const VERSION: u8 = 1;

/// Largest window [samples] a snapshot may declare (and the Python binding
/// accepts): 10⁷ samples, about 0.6 GB of window points. A corrupt length must
/// not turn into an allocation the process cannot survive.
pub const MAX_WINDOW_LEN: usize = crate::identify::PaperConfig::MAX_WINDOW;

/// Kind byte of a [`Model`] snapshot.
pub(crate) const KIND_MODEL: u8 = 1;
/// Kind byte of a [`crate::identify::PaperIdentifier`] snapshot.
pub(crate) const KIND_PAPER: u8 = 2;
/// Kind byte of a [`crate::identify::OutputErrorIdentifier`] ("rpem") snapshot.
pub(crate) const KIND_RPEM: u8 = 3;

/// Objects that can be saved to bytes and restored bit for bit.
pub trait Snapshot: Sized {
    /// Everything the object carries between samples, as bytes.
    fn to_bytes(&self) -> Vec<u8>;
    /// Rebuilds an object written by [`Snapshot::to_bytes`]; validated.
    fn from_bytes(bytes: &[u8]) -> Result<Self>;
}

/// The error of every malformed snapshot; `at` is the byte offset where reading stopped.
pub(crate) fn corrupt(at: usize, reason: &'static str) -> Error {
    Error::InvalidConfig { name: "snapshot", value: at as f64, reason }
}

/// Appends fields to a snapshot.
pub(crate) struct Writer(Vec<u8>);

impl Writer {
    /// A snapshot of kind `kind`, header written.
    pub(crate) fn new(kind: u8) -> Self {
        let mut bytes = Vec::with_capacity(256);
        bytes.extend_from_slice(&MAGIC);
        bytes.push(VERSION);
        bytes.push(kind);
        Writer(bytes)
    }
    pub(crate) fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_bits().to_le_bytes());
    }
    pub(crate) fn f64s(&mut self, vs: &[f64]) {
        for &v in vs {
            self.f64(v);
        }
    }
    pub(crate) fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    pub(crate) fn opt_f64(&mut self, v: Option<f64>) {
        match v {
            Some(v) => {
                self.u8(1);
                self.f64(v);
            }
            None => self.u8(0),
        }
    }
    pub(crate) fn params(&mut self, p: &Params) {
        self.f64s(&p.to_array());
    }
    pub(crate) fn finish(self) -> Vec<u8> {
        self.0
    }
}

/// Reads fields back; every read checks the length.
pub(crate) struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    /// Checks the header and the kind.
    pub(crate) fn new(bytes: &'a [u8], kind: u8) -> Result<Self> {
        if bytes.len() < 6 || bytes[..4] != MAGIC {
            return Err(corrupt(0, "not a boucwen snapshot (bad magic bytes)"));
        }
        if bytes[4] != VERSION {
            return Err(corrupt(4, "snapshot written by an unsupported format version"));
        }
        if bytes[5] != kind {
            return Err(corrupt(5, "snapshot of another kind of object"));
        }
        Ok(Reader { bytes, at: 6 })
    }
    fn take<const L: usize>(&mut self) -> Result<[u8; L]> {
        let end = self.at.checked_add(L).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(corrupt(self.at, "snapshot is truncated"));
        };
        let mut out = [0u8; L];
        out.copy_from_slice(&self.bytes[self.at..end]);
        self.at = end;
        Ok(out)
    }
    pub(crate) fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_bits(u64::from_le_bytes(self.take::<8>()?)))
    }
    pub(crate) fn f64s<const L: usize>(&mut self) -> Result<[f64; L]> {
        let mut out = [0.0; L];
        for v in out.iter_mut() {
            *v = self.f64()?;
        }
        Ok(out)
    }
    /// A finite f64 (every state value but the window sums).
    pub(crate) fn finite(&mut self) -> Result<f64> {
        let at = self.at;
        let v = self.f64()?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(corrupt(at, "snapshot holds a non-finite state value"))
        }
    }
    pub(crate) fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.take::<8>()?))
    }
    pub(crate) fn u8(&mut self) -> Result<u8> {
        Ok(self.take::<1>()?[0])
    }
    pub(crate) fn bool(&mut self) -> Result<bool> {
        match self.u8()? {
            0 => Ok(false),
            1 => Ok(true),
            _ => Err(corrupt(self.at - 1, "snapshot holds an invalid flag byte")),
        }
    }
    pub(crate) fn opt_f64(&mut self) -> Result<Option<f64>> {
        Ok(if self.bool()? { Some(self.finite()?) } else { None })
    }
    pub(crate) fn params(&mut self) -> Result<Params> {
        let at = self.at;
        Params::from_array(self.f64s::<7>()?).map_err(|_| corrupt(at, "snapshot holds invalid parameters"))
    }
    /// Current offset (for error messages).
    pub(crate) fn offset(&self) -> usize {
        self.at
    }
    /// Fails unless every byte was read.
    pub(crate) fn end(self) -> Result<()> {
        if self.at == self.bytes.len() {
            Ok(())
        } else {
            Err(corrupt(self.at, "snapshot has trailing bytes"))
        }
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
pub(crate) fn rebuild_window_sums<const K: usize>(
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

impl Snapshot for Model {
    fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer::new(KIND_MODEL);
        w.params(self.params());
        w.f64(self.dt());
        let s = self.state();
        w.f64(s.h);
        w.opt_f64(s.u_prev);
        w.finish()
    }

    fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let mut r = Reader::new(bytes, KIND_MODEL)?;
        let params = r.params()?;
        let at = r.offset();
        let dt = r.f64()?;
        let h = r.finite()?;
        let u_prev = r.opt_f64()?;
        r.end()?;
        let mut m = Model::new(params, dt, h).map_err(|_| corrupt(at, "snapshot holds an invalid time step"))?;
        m.set_state(ModelState { h, u_prev })?;
        Ok(m)
    }
}

impl AnyIdentifier {
    /// The identifier's byte snapshot (see [`Snapshot`]); an error for a method that
    /// has no snapshot layout yet.
    pub fn to_snapshot(&self) -> Result<Vec<u8>> {
        #[allow(unreachable_patterns)]
        match self {
            AnyIdentifier::Paper(id) => Ok(id.to_bytes()),
            AnyIdentifier::OutputError(id) => Ok(id.to_bytes()),
            _ => Err(Error::InvalidConfig {
                name: "method",
                value: f64::NAN,
                reason: "saving this online method is not supported yet",
            }),
        }
    }

    /// Rebuilds an identifier from [`AnyIdentifier::to_snapshot`]; the method is
    /// read from the snapshot's kind byte.
    pub fn from_snapshot(bytes: &[u8]) -> Result<Self> {
        match bytes.get(5) {
            Some(&KIND_PAPER) => Ok(AnyIdentifier::Paper(crate::identify::PaperIdentifier::from_bytes(bytes)?)),
            Some(&KIND_RPEM) => {
                Ok(AnyIdentifier::OutputError(crate::identify::OutputErrorIdentifier::from_bytes(bytes)?))
            }
            _ => Err(corrupt(5, "not a snapshot of an online identifier")),
        }
    }
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

    #[test]
    fn model_round_trips_and_rejects_garbage() {
        let mut m = Model::new(Params::paper_1hz(), 1e-4, 0.0).unwrap();
        for k in 0..100 {
            m.step((k as f64 * 0.1).sin() * 40.0).unwrap();
        }
        let bytes = m.to_bytes();
        let r = Model::from_bytes(&bytes).unwrap();
        assert_eq!(r, m);
        for cut in 0..bytes.len() {
            assert!(Model::from_bytes(&bytes[..cut]).is_err());
        }
        let mut bad = bytes.clone();
        bad[6 + 5 * 8..6 + 6 * 8].copy_from_slice(&(-1.0f64).to_bits().to_le_bytes()); // n = -1
        assert!(Model::from_bytes(&bad).is_err());
        assert!(AnyIdentifier::from_snapshot(&bytes).is_err());
    }
}
