//! The compensator: the inverse of the model (`BwInverse`) and what its last step did.

use super::model::BwParams;
use super::status::{boxed, get, get_mut, guard, put, release, BwStatus};
use crate::compensate::{Clip, Inverse, InverseStatus, VoltageLimits};

/// What the last step of an inverse did: `clip` 0 = within the limits, 1 = on the
/// lower, 2 = on the upper limit.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BwInverseStatus {
    pub clip: u32,
    /// Integrator evaluations in the step (at most 40).
    pub evaluations: u32,
    /// Model displacement minus x_d after the step \[µm\].
    pub residual_um: f64,
    pub exact: bool,
    pub samples: u64,
    pub clipped_samples: u64,
}

impl From<InverseStatus> for BwInverseStatus {
    fn from(s: InverseStatus) -> Self {
        BwInverseStatus {
            clip: match s.clip {
                Clip::None => 0,
                Clip::Low => 1,
                Clip::High => 2,
            },
            evaluations: s.evaluations,
            residual_um: s.residual_um,
            exact: s.exact,
            samples: s.samples,
            clipped_samples: s.clipped_samples,
        }
    }
}

/// Opaque inverse of the model (feedforward compensation).
pub struct BwInverse(Inverse);

/// The inverse of the model with parameters `params`, `dt` \[s\], h `h0` \[µm\] and
/// voltage limits \[V\] (±INFINITY for none) into `*out`.
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_new(
    params: *const BwParams,
    dt: f64,
    h0: f64,
    u_min: f64,
    u_max: f64,
    out: *mut *mut BwInverse,
) -> BwStatus {
    guard(|| {
        let p = get(params)?.to_params()?;
        let limits = VoltageLimits::new(Some(u_min), Some(u_max))?;
        boxed(out, BwInverse(Inverse::new(p, dt, h0, limits)?))
    })
}

/// Releases an inverse (null is ignored).
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_free(inv: *mut BwInverse) {
    release(inv)
}

/// The voltage \[V\] to `*u` that makes the model reach the desired displacement `x_d`
/// \[µm\] at this sample. No allocation; at most 40 integrator evaluations.
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_step(inv: *mut BwInverse, x_d: f64, u: *mut f64) -> BwStatus {
    guard(|| {
        let inv = get_mut(inv)?;
        if u.is_null() {
            return Err(BwStatus::BW_NULL_POINTER);
        }
        put(u, inv.0.step(x_d)?)
    })
}

/// New parameters from now on (e.g. an identifier's current estimates); h is kept.
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_set_params(inv: *mut BwInverse, params: *const BwParams) -> BwStatus {
    guard(|| {
        let p = get(params)?.to_params()?;
        Ok(get_mut(inv)?.0.set_params(p)?)
    })
}

/// What the last step did.
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_status(inv: *const BwInverse, out: *mut BwInverseStatus) -> BwStatus {
    guard(|| put(out, get(inv)?.0.status().into()))
}

/// The model's h \[µm\] after the last step.
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_h(inv: *const BwInverse, h: *mut f64) -> BwStatus {
    guard(|| put(h, get(inv)?.0.h()))
}

/// Back to the state right after construction.
#[no_mangle]
pub unsafe extern "C" fn bw_inverse_reset(inv: *mut BwInverse) -> BwStatus {
    guard(|| {
        get_mut(inv)?.0.reset();
        Ok(())
    })
}
