//! The bank: C channels (identifier, model and inverse each) stepped with one call per
//! frame.

use super::identifier::BwIdentifier;
use super::model::BwParams;
use super::status::{boxed, get, get_mut, guard, put, release, slice, slice_mut, BwStatus};
use crate::bank::Bank;
use crate::compensate::VoltageLimits;
use crate::identify::{AnyIdentifier, OnlineIdentifier};

/// Opaque bank of channels (identifier, model and inverse each).
pub struct BwBank(Bank<AnyIdentifier>);

/// A bank of `channels` copies of the identifier `prototype` as it is now (usually
/// fresh from a `bw_identifier_new_*`; it stays the caller's), each channel then
/// learning on its own, with a model and an inverse starting from its parameters and
/// h; `dt` \[s\] the identifier's. Every method may be banked; a horizon channel holds
/// its own window (`max_window` samples of about 100 bytes).
#[no_mangle]
pub unsafe extern "C" fn bw_bank_new(
    channels: usize,
    dt: f64,
    prototype: *const BwIdentifier,
    out: *mut *mut BwBank,
) -> BwStatus {
    guard(|| {
        let id = get(prototype)?.0.clone();
        boxed(out, BwBank(Bank::new(channels, id, dt)?))
    })
}

/// Releases a bank (null is ignored).
#[no_mangle]
pub unsafe extern "C" fn bw_bank_free(bank: *mut BwBank) {
    release(bank)
}

/// The number of channels C.
#[no_mangle]
pub unsafe extern "C" fn bw_bank_channels(bank: *const BwBank, out: *mut usize) -> BwStatus {
    guard(|| put(out, get(bank)?.0.channels()))
}

/// One frame for the identifiers: `u` \[V\], `x` \[µm\] (C values each); predictions
/// \[µm\] into `out` (C values). No allocation.
#[no_mangle]
pub unsafe extern "C" fn bw_bank_push(bank: *mut BwBank, u: *const f64, x: *const f64, out: *mut f64) -> BwStatus {
    guard(|| {
        let b = &mut get_mut(bank)?.0;
        let c = b.channels();
        Ok(b.push(slice(u, c)?, slice(x, c)?, slice_mut(out, c)?)?)
    })
}

/// `frames` frames at once, row-major (frame t, channel c at `t·C + c`).
#[no_mangle]
pub unsafe extern "C" fn bw_bank_push_many(
    bank: *mut BwBank,
    u: *const f64,
    x: *const f64,
    frames: usize,
    out: *mut f64,
) -> BwStatus {
    guard(|| {
        let b = &mut get_mut(bank)?.0;
        let len = frames.checked_mul(b.channels()).ok_or(BwStatus::BW_LENGTH_MISMATCH)?;
        Ok(b.push_many(slice(u, len)?, slice(x, len)?, slice_mut(out, len)?)?)
    })
}

/// One frame for the models: voltages `u` \[V\] (C values), displacements \[µm\] into `x_out`.
#[no_mangle]
pub unsafe extern "C" fn bw_bank_step_models(bank: *mut BwBank, u: *const f64, x_out: *mut f64) -> BwStatus {
    guard(|| {
        let b = &mut get_mut(bank)?.0;
        let c = b.channels();
        Ok(b.step_models(slice(u, c)?, slice_mut(x_out, c)?)?)
    })
}

/// Every model takes its identifier's current estimates (states kept).
#[no_mangle]
pub unsafe extern "C" fn bw_bank_adopt_estimates(bank: *mut BwBank) -> BwStatus {
    guard(|| Ok(get_mut(bank)?.0.adopt_estimates()?))
}

/// One frame of feedforward: `x_d` (C desired displacements \[µm\]) in, the C voltages
/// \[V\] at which each channel's inverse model reaches them out. No allocation.
#[no_mangle]
pub unsafe extern "C" fn bw_bank_feedforward(bank: *mut BwBank, x_d: *const f64, u_out: *mut f64) -> BwStatus {
    guard(|| {
        let bank = &mut get_mut(bank)?.0;
        let c = bank.channels();
        Ok(bank.feedforward(slice(x_d, c)?, slice_mut(u_out, c)?)?)
    })
}

/// Voltage limits \[V\] of every channel's inverse (±INFINITY: none).
#[no_mangle]
pub unsafe extern "C" fn bw_bank_set_voltage_limits(bank: *mut BwBank, u_min: f64, u_max: f64) -> BwStatus {
    guard(|| Ok(get_mut(bank)?.0.set_voltage_limits(VoltageLimits::new(Some(u_min), Some(u_max))?)?))
}

/// The current estimates of channel `channel`'s identifier.
#[no_mangle]
pub unsafe extern "C" fn bw_bank_params(bank: *const BwBank, channel: usize, out: *mut BwParams) -> BwStatus {
    guard(|| {
        let id = get(bank)?.0.identifiers().get(channel).ok_or(BwStatus::BW_INVALID_CONFIG)?;
        put(out, id.params().into())
    })
}

/// Every identifier and model back to its state right after construction.
#[no_mangle]
pub unsafe extern "C" fn bw_bank_reset(bank: *mut BwBank) -> BwStatus {
    guard(|| {
        get_mut(bank)?.0.reset();
        Ok(())
    })
}
