//! The byte format of snapshots: save and restore a model or an online identifier.
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
//! [`Error::CorruptSnapshot`] (the byte offset and what is wrong) on a truncated,
//! foreign or corrupt byte string; it never panics.
//!
//! Each type writes and reads itself with `Writer` and `Reader`, beside its own
//! code: `model/mod.rs`, `identify/paper/snapshot.rs`, `identify/rpem/snapshot.rs`,
//! `identify/horizon/snapshot.rs`.

use alloc::vec::Vec;

use crate::error::{Error, Result};
use crate::params::Params;

/// First bytes of every snapshot.
pub const MAGIC: [u8; 4] = *b"BWSN";
/// Version of the layout written by this build (7: the paper identifier's output gate;
/// 6: the paper identifier's derivative
/// stencil (raw ring, next sample, points entered) and its per-step status; 5: the horizon identifier's refine
/// mode, its pass's end, the update awaiting adoption and how far the estimates lag;
/// 4: the horizon pass's carried |h|^n and ln|h|; 3: the model's carried |h|^n; 2: the
/// horizon identifier's pending update). Snapshots of other versions are refused with a
/// clear error.
pub const VERSION: u8 = 7;

/// Largest window \[samples\] a snapshot may declare (and the Python binding
/// accepts): 10⁷ samples, about 0.6 GB of window points. A corrupt length must
/// not turn into an allocation the process cannot survive. The paper identifier's
/// largest window (`PaperConfig::MAX_WINDOW`) is this bound: its snapshot code checks
/// at compile time that the two agree.
pub const MAX_WINDOW_LEN: usize = 10_000_000;

/// Kind byte of a [`crate::Model`] snapshot.
pub(crate) const KIND_MODEL: u8 = 1;
/// Kind byte of a [`crate::identify::PaperIdentifier`] snapshot.
pub(crate) const KIND_PAPER: u8 = 2;
/// Kind byte of a [`crate::identify::RpemIdentifier`] ("rpem") snapshot.
pub(crate) const KIND_RPEM: u8 = 3;
/// Kind byte of a [`crate::identify::HorizonIdentifier`] snapshot.
pub(crate) const KIND_HORIZON: u8 = 4;

/// Objects that can be saved to bytes and restored bit for bit.
pub trait Snapshot: Sized {
    /// Everything the object carries between samples, as bytes.
    fn to_bytes(&self) -> Vec<u8>;
    /// Rebuilds an object written by [`Snapshot::to_bytes`]; validated.
    fn from_bytes(bytes: &[u8]) -> Result<Self>;
}

/// The error of every malformed snapshot; `at` is the byte offset where reading stopped.
pub(crate) fn corrupt(at: usize, reason: &'static str) -> Error {
    Error::CorruptSnapshot { at, reason }
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
