//! The per-sample model: its parameters ([`BwParams`]), the `BwModel` handle and
//! `bw_simulate`.

use super::status::{boxed, bytes, get, get_mut, guard, put, release, slice, slice_mut, write_snapshot, BwStatus};
use crate::format::Snapshot;
use crate::model::Model;
use crate::params::Params;

/// The seven parameters of eqs. (3) and (5): kv \[µm/V\], x0 \[µm\], A \[µm/V\], β and γ
/// [µm^(1−n)/V], n \[-\], δ \[µm/(V·s)\].
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BwParams {
    pub kv: f64,
    pub x0: f64,
    pub a: f64,
    pub beta: f64,
    pub gamma: f64,
    pub n: f64,
    pub delta: f64,
}

impl From<Params> for BwParams {
    fn from(p: Params) -> Self {
        BwParams { kv: p.kv, x0: p.x0, a: p.a, beta: p.beta, gamma: p.gamma, n: p.n, delta: p.delta }
    }
}

impl BwParams {
    pub(super) fn to_params(self) -> Result<Params, BwStatus> {
        Params::new(self.kv, self.x0, self.a, self.beta, self.gamma, self.n, self.delta).map_err(BwStatus::from)
    }
}

/// Opaque per-sample model.
pub struct BwModel(Model);

/// The paper's Table 2 values at 1 Hz.
#[no_mangle]
pub unsafe extern "C" fn bw_params_paper_1hz(out: *mut BwParams) -> BwStatus {
    guard(|| put(out, Params::paper_1hz().into()))
}

/// A per-sample model (`dt` \[s\], initial h `h0` \[µm\]) into `*out`.
#[no_mangle]
pub unsafe extern "C" fn bw_model_new(params: *const BwParams, dt: f64, h0: f64, out: *mut *mut BwModel) -> BwStatus {
    guard(|| {
        let p = get(params)?.to_params()?;
        boxed(out, BwModel(Model::new(p, dt, h0)?))
    })
}

/// Releases a model (null is ignored).
#[no_mangle]
pub unsafe extern "C" fn bw_model_free(model: *mut BwModel) {
    release(model)
}

/// Takes the next voltage `u` \[V\]; writes the displacement \[µm\] to `*x`.
#[no_mangle]
pub unsafe extern "C" fn bw_model_step(model: *mut BwModel, u: f64, x: *mut f64) -> BwStatus {
    guard(|| {
        let m = get_mut(model)?;
        if x.is_null() {
            return Err(BwStatus::BW_NULL_POINTER);
        }
        put(x, m.0.step(u)?)
    })
}

/// The model's parameters.
#[no_mangle]
pub unsafe extern "C" fn bw_model_params(model: *const BwModel, out: *mut BwParams) -> BwStatus {
    guard(|| put(out, (*get(model)?.0.params()).into()))
}

/// Replaces the model's parameters (validated; the state is kept).
#[no_mangle]
pub unsafe extern "C" fn bw_model_set_params(model: *mut BwModel, params: *const BwParams) -> BwStatus {
    guard(|| {
        let p = get(params)?.to_params()?;
        Ok(get_mut(model)?.0.set_params(p)?)
    })
}

/// The hysteresis state h \[µm\].
#[no_mangle]
pub unsafe extern "C" fn bw_model_h(model: *const BwModel, h: *mut f64) -> BwStatus {
    guard(|| put(h, get(model)?.0.h()))
}

/// Forgets the past: h = `h0` \[µm\], no previous sample.
#[no_mangle]
pub unsafe extern "C" fn bw_model_reset(model: *mut BwModel, h0: f64) -> BwStatus {
    guard(|| Ok(get_mut(model)?.0.reset(h0)?))
}

/// The model's snapshot bytes into `buf` (capacity `capacity`), length to `*len`.
#[no_mangle]
pub unsafe extern "C" fn bw_model_snapshot(
    model: *const BwModel,
    buf: *mut u8,
    capacity: usize,
    len: *mut usize,
) -> BwStatus {
    guard(|| write_snapshot(&get(model)?.0.to_bytes(), buf, capacity, len))
}

/// A model rebuilt from snapshot bytes into `*out`.
#[no_mangle]
pub unsafe extern "C" fn bw_model_restore(buf: *const u8, len: usize, out: *mut *mut BwModel) -> BwStatus {
    guard(|| boxed(out, BwModel(Model::from_bytes(bytes(buf, len)?)?)))
}

/// Simulates `len` samples of `u` \[V\] into `x_out` \[µm\] from h = `h0`; the final h
/// \[µm\] to `*h_final` (may be null). The first sample keeps h = h0.
#[no_mangle]
pub unsafe extern "C" fn bw_simulate(
    params: *const BwParams,
    u: *const f64,
    len: usize,
    dt: f64,
    h0: f64,
    x_out: *mut f64,
    h_final: *mut f64,
) -> BwStatus {
    guard(|| {
        let p = get(params)?.to_params()?;
        let h = crate::model::simulate_into(&p, slice(u, len)?, dt, h0, None, slice_mut(x_out, len)?)?;
        if !h_final.is_null() {
            h_final.write(h);
        }
        Ok(())
    })
}
