//! The C ABI (feature `ffi`): the per-sample [`Model`], the online identifier (one
//! handle, `BwIdentifier`, over [`AnyIdentifier`]: built by `bw_identifier_new_horizon`,
//! the recommended method, `_new_rpem` or `_new_paper`, then the same calls whatever the
//! method), the [`Inverse`] of the model, [`simulate`](crate::simulate) and the channel
//! [`Bank`], behind opaque handles. A call that belongs to one method (the horizon
//! method's `refine`) returns `BW_WRONG_METHOD` on an identifier of another. The header
//! `include/boucwen.h` is generated from this folder by cbindgen (`cbindgen.toml`; the
//! test `rust/tests/ffi_header.rs` fails when it is stale).
//!
//! Conventions, for every function:
//! - the return value is a [`BwStatus`]: `BW_OK`, or the reason the call did nothing
//!   (the object is then exactly as before, as in Rust: a non-finite sample is
//!   rejected and the state kept);
//! - results are written through out-pointers, which must be valid (a null one gives
//!   `BW_NULL_POINTER`); arrays are `(pointer, length)` pairs of `double`, frames of a
//!   bank row-major (frame t, channel c at `t·C + c`);
//! - no Rust panic crosses the boundary: each call runs under `catch_unwind` and a
//!   panic (a bug; none is known) returns `BW_PANIC`, after which the object should
//!   be destroyed;
//! - `*_new*` and `*_restore` allocate the object, `*_free` releases it (null is
//!   ignored); `push`, `push_many`, `step` and the bank's frame calls allocate
//!   nothing; `*_snapshot` copies the bytes into the caller's buffer (with
//!   `BW_BUFFER_TOO_SMALL` and the needed length when it is too short, so a call with
//!   capacity 0 asks for the size).
//!
//! Units as in Rust: u \[V\], x and h \[µm\], dt \[s\].
//!
//! # Safety
//!
//! Every function takes raw pointers from C. A handle must come from the matching
//! `*_new*`/`*_restore` and not be used after `*_free`, nor from two threads at
//! once; an array pointer must point to at least as many `double`s as the length
//! given (it may be null when the length is 0).

#![allow(clippy::missing_safety_doc)]

// One file per thing exposed, declared in the header's order (cbindgen reads them so):
// what every call returns and the checks at the boundary,
mod status;
// the parameters, the per-sample model and `bw_simulate`,
mod model;
// the one identifier handle over every method, each method's tuning and status,
mod identifier;
// the compensator (the model's inverse),
mod inverse;
// the bank of channels.
mod bank;
#[cfg(test)]
mod tests;

pub use bank::*;
pub use identifier::*;
pub use inverse::*;
pub use model::*;
pub use status::*;
