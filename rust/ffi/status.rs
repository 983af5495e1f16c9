//! What every call returns ([`BwStatus`] and its message) and the checks at the
//! boundary: panics caught, null pointers refused, arrays and snapshots copied.

use core::ffi::c_char;
use std::panic::{catch_unwind, AssertUnwindSafe};

use crate::error::Error;

/// What a call did.
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BwStatus {
    /// Done.
    BW_OK = 0,
    /// A model parameter is out of its domain (non-finite, or n ≤ 0).
    BW_INVALID_PARAMETER = 1,
    /// A configuration value (dt, window, tuning, channel count or index) is invalid.
    BW_INVALID_CONFIG = 2,
    /// A sample is NaN or infinite: rejected, state kept.
    BW_NON_FINITE_SAMPLE = 3,
    /// A snapshot is truncated, foreign or corrupt.
    BW_CORRUPT_SNAPSHOT = 4,
    /// Lengths that must agree do not.
    BW_LENGTH_MISMATCH = 5,
    /// A required pointer is null.
    BW_NULL_POINTER = 6,
    /// The caller's buffer is too short (the needed length was written).
    BW_BUFFER_TOO_SMALL = 7,
    /// A Rust panic was caught (a bug): destroy the object.
    BW_PANIC = 8,
    /// The call belongs to another method than the identifier's (e.g. the horizon
    /// method's refine on an rpem identifier): nothing was done.
    BW_WRONG_METHOD = 9,
}

impl BwStatus {
    /// Every status, in code order.
    pub(super) const ALL: [BwStatus; 10] = [
        BwStatus::BW_OK,
        BwStatus::BW_INVALID_PARAMETER,
        BwStatus::BW_INVALID_CONFIG,
        BwStatus::BW_NON_FINITE_SAMPLE,
        BwStatus::BW_CORRUPT_SNAPSHOT,
        BwStatus::BW_LENGTH_MISMATCH,
        BwStatus::BW_NULL_POINTER,
        BwStatus::BW_BUFFER_TOO_SMALL,
        BwStatus::BW_PANIC,
        BwStatus::BW_WRONG_METHOD,
    ];

    /// The status of integer code `code`, if it is one.
    pub(super) fn from_code(code: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|s| *s as u32 == code)
    }
}

impl From<Error> for BwStatus {
    fn from(e: Error) -> Self {
        match e {
            Error::InvalidParameter { .. } => BwStatus::BW_INVALID_PARAMETER,
            Error::InvalidConfig { .. } => BwStatus::BW_INVALID_CONFIG,
            Error::NonFiniteSample { .. } => BwStatus::BW_NON_FINITE_SAMPLE,
            Error::CorruptSnapshot { .. } => BwStatus::BW_CORRUPT_SNAPSHOT,
            Error::LengthMismatch { .. } => BwStatus::BW_LENGTH_MISMATCH,
        }
    }
}

/// Runs `f`, turning a panic into `BW_PANIC` and an `Err` into its code.
pub(super) fn guard(f: impl FnOnce() -> Result<(), BwStatus>) -> BwStatus {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => BwStatus::BW_OK,
        Ok(Err(code)) => code,
        Err(_) => BwStatus::BW_PANIC,
    }
}

pub(super) unsafe fn get<'a, T>(ptr: *const T) -> Result<&'a T, BwStatus> {
    ptr.as_ref().ok_or(BwStatus::BW_NULL_POINTER)
}

pub(super) unsafe fn get_mut<'a, T>(ptr: *mut T) -> Result<&'a mut T, BwStatus> {
    ptr.as_mut().ok_or(BwStatus::BW_NULL_POINTER)
}

pub(super) unsafe fn put<T>(out: *mut T, value: T) -> Result<(), BwStatus> {
    if out.is_null() {
        return Err(BwStatus::BW_NULL_POINTER);
    }
    out.write(value);
    Ok(())
}

pub(super) unsafe fn slice<'a>(ptr: *const f64, len: usize) -> Result<&'a [f64], BwStatus> {
    if len == 0 {
        Ok(&[])
    } else if ptr.is_null() {
        Err(BwStatus::BW_NULL_POINTER)
    } else {
        Ok(core::slice::from_raw_parts(ptr, len))
    }
}

pub(super) unsafe fn slice_mut<'a>(ptr: *mut f64, len: usize) -> Result<&'a mut [f64], BwStatus> {
    if len == 0 {
        Ok(&mut [])
    } else if ptr.is_null() {
        Err(BwStatus::BW_NULL_POINTER)
    } else {
        Ok(core::slice::from_raw_parts_mut(ptr, len))
    }
}

pub(super) unsafe fn boxed<T>(out: *mut *mut T, value: T) -> Result<(), BwStatus> {
    if out.is_null() {
        return Err(BwStatus::BW_NULL_POINTER);
    }
    out.write(Box::into_raw(Box::new(value)));
    Ok(())
}

pub(super) unsafe fn release<T>(ptr: *mut T) {
    if !ptr.is_null() {
        let _ = catch_unwind(AssertUnwindSafe(|| drop(Box::from_raw(ptr))));
    }
}

/// Copies a snapshot into the caller's buffer (`BW_BUFFER_TOO_SMALL` with `*len` the
/// needed length if `capacity` is short).
pub(super) unsafe fn write_snapshot(
    bytes: &[u8],
    buf: *mut u8,
    capacity: usize,
    len: *mut usize,
) -> Result<(), BwStatus> {
    put(len, bytes.len())?;
    if capacity < bytes.len() {
        return Err(BwStatus::BW_BUFFER_TOO_SMALL);
    }
    if buf.is_null() {
        return Err(BwStatus::BW_NULL_POINTER);
    }
    core::ptr::copy_nonoverlapping(bytes.as_ptr(), buf, bytes.len());
    Ok(())
}

pub(super) unsafe fn bytes<'a>(ptr: *const u8, len: usize) -> Result<&'a [u8], BwStatus> {
    if len == 0 {
        Ok(&[])
    } else if ptr.is_null() {
        Err(BwStatus::BW_NULL_POINTER)
    } else {
        Ok(core::slice::from_raw_parts(ptr, len))
    }
}

/// A static, NUL-terminated description of a status code.
///
/// Takes the code as an integer (a `BwStatus`, or any other value: "unknown status
/// code"), so that no value a C caller passes is undefined behaviour.
#[no_mangle]
pub extern "C" fn bw_status_message(status: u32) -> *const c_char {
    let Some(status) = BwStatus::from_code(status) else {
        return c"unknown status code".as_ptr();
    };
    let text: &'static [u8] = match status {
        BwStatus::BW_OK => b"ok\0",
        BwStatus::BW_INVALID_PARAMETER => b"invalid model parameter (non-finite, or n <= 0)\0",
        BwStatus::BW_INVALID_CONFIG => b"invalid configuration value\0",
        BwStatus::BW_NON_FINITE_SAMPLE => b"non-finite sample: rejected, state kept\0",
        BwStatus::BW_CORRUPT_SNAPSHOT => b"truncated, foreign or corrupt snapshot\0",
        BwStatus::BW_LENGTH_MISMATCH => b"array lengths do not agree\0",
        BwStatus::BW_NULL_POINTER => b"null pointer\0",
        BwStatus::BW_BUFFER_TOO_SMALL => b"buffer too small (needed length written)\0",
        BwStatus::BW_PANIC => b"internal error (panic caught); destroy the object\0",
        BwStatus::BW_WRONG_METHOD => b"the call belongs to another method than the identifier's\0",
    };
    text.as_ptr().cast()
}
