//! The C ABI driven as C drives it: status codes, null pointers, every method through
//! the one handle, and the bank.

use super::status::guard;
use super::*;
use crate::identify::OnlineIdentifier;

#[test]
fn a_panic_becomes_a_status() {
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let status = guard(|| panic!("deliberate"));
    std::panic::set_hook(hook);
    assert_eq!(status, BwStatus::BW_PANIC);
}

#[test]
fn errors_leave_state_and_null_pointers_are_reported() {
    unsafe {
        let mut p = BwParams { kv: 0.0, x0: 0.0, a: 0.0, beta: 0.0, gamma: 0.0, n: 0.0, delta: 0.0 };
        assert_eq!(bw_params_paper_1hz(&mut p), BwStatus::BW_OK);
        let mut id: *mut BwIdentifier = core::ptr::null_mut();
        assert_eq!(bw_identifier_new_rpem(1e-4, &p, 0.0, core::ptr::null(), &mut id), BwStatus::BW_OK);
        let mut x_hat = 0.0;
        assert_eq!(bw_identifier_push(id, 1.0, 0.2, &mut x_hat), BwStatus::BW_OK);
        let before = (*id).0.clone();
        assert_eq!(bw_identifier_push(id, f64::NAN, 0.2, &mut x_hat), BwStatus::BW_NON_FINITE_SAMPLE);
        assert_eq!(bw_identifier_push(id, 1.0, 0.2, core::ptr::null_mut()), BwStatus::BW_NULL_POINTER);
        assert_eq!((*id).0, before);
        assert_eq!(bw_identifier_push(core::ptr::null_mut(), 1.0, 0.2, &mut x_hat), BwStatus::BW_NULL_POINTER);
        let mut len = 0usize;
        assert_eq!(bw_identifier_snapshot(id, core::ptr::null_mut(), 0, &mut len), BwStatus::BW_BUFFER_TOO_SMALL);
        let mut buf = vec![0u8; len];
        assert_eq!(bw_identifier_snapshot(id, buf.as_mut_ptr(), len, &mut len), BwStatus::BW_OK);
        let mut copy: *mut BwIdentifier = core::ptr::null_mut();
        assert_eq!(bw_identifier_restore(buf.as_ptr(), len, &mut copy), BwStatus::BW_OK);
        assert_eq!((*copy).0, (*id).0);
        assert_eq!(bw_identifier_restore(buf.as_ptr(), len - 1, &mut copy), BwStatus::BW_CORRUPT_SNAPSHOT);
        bw_identifier_free(copy);
        bw_identifier_free(id);
        bw_identifier_free(core::ptr::null_mut());
        let bad = BwParams { n: -1.0, ..p };
        let mut m: *mut BwModel = core::ptr::null_mut();
        assert_eq!(bw_model_new(&bad, 1e-4, 0.0, &mut m), BwStatus::BW_INVALID_PARAMETER);
        assert!(m.is_null());
        let mut rpem: *mut BwIdentifier = core::ptr::null_mut();
        assert_eq!(bw_identifier_new_rpem(1e-4, &p, 0.0, core::ptr::null(), &mut rpem), BwStatus::BW_OK);
        let mut bank: *mut BwBank = core::ptr::null_mut();
        assert_eq!(bw_bank_new(0, 1e-4, rpem, &mut bank), BwStatus::BW_INVALID_CONFIG);
        assert_eq!(bw_bank_new(2, 1e-4, core::ptr::null(), &mut bank), BwStatus::BW_NULL_POINTER);
        assert!(bank.is_null());
        bw_identifier_free(rpem);
        let msg = std::ffi::CStr::from_ptr(bw_status_message(BwStatus::BW_NON_FINITE_SAMPLE as u32));
        assert!(msg.to_str().unwrap().contains("non-finite"));
        let msg = std::ffi::CStr::from_ptr(bw_status_message(BwStatus::BW_WRONG_METHOD as u32));
        assert!(msg.to_str().unwrap().contains("another method"));
        // Any integer a C caller passes is answered, not undefined behaviour.
        let msg = std::ffi::CStr::from_ptr(bw_status_message(77));
        assert_eq!(msg.to_str().unwrap(), "unknown status code");
        for status in BwStatus::ALL {
            assert_eq!(BwStatus::from_code(status as u32), Some(status));
        }
    }
}

/// One identifier of each method, through the one handle.
unsafe fn each_method(p: &BwParams) -> [*mut BwIdentifier; 3] {
    let mut ids = [core::ptr::null_mut(); 3];
    let mut cfg = core::mem::zeroed::<BwPaperConfig>();
    assert_eq!(bw_paper_config_default(200, &mut cfg), BwStatus::BW_OK);
    assert_eq!(bw_identifier_new_horizon(1e-4, p, 0.0, 3000.0, core::ptr::null(), &mut ids[0]), BwStatus::BW_OK);
    assert_eq!(bw_identifier_new_rpem(1e-4, p, 0.0, core::ptr::null(), &mut ids[1]), BwStatus::BW_OK);
    assert_eq!(bw_identifier_new_paper(1e-4, p, 0.0, &cfg, &mut ids[2]), BwStatus::BW_OK);
    ids
}

#[test]
fn one_handle_serves_every_method_and_method_calls_refuse_the_others() {
    unsafe {
        let mut p = core::mem::zeroed::<BwParams>();
        assert_eq!(bw_params_paper_1hz(&mut p), BwStatus::BW_OK);
        let ids = each_method(&p);
        let methods = [BwMethod::BW_METHOD_HORIZON, BwMethod::BW_METHOD_RPEM, BwMethod::BW_METHOD_PAPER];
        let u: Vec<f64> = (0..600).map(|k| 40.0 * (1.0 - (k as f64 * 0.02).cos())).collect();
        let x: Vec<f64> = u.iter().map(|v| 0.2 * v).collect();
        for (&id, &method) in ids.iter().zip(&methods) {
            let mut got = BwMethod::BW_METHOD_PAPER;
            assert_eq!(bw_identifier_method(id, &mut got), BwStatus::BW_OK);
            assert_eq!(got, method);
            let mut out = vec![0.0; u.len()];
            assert_eq!(bw_identifier_push_many(id, u.as_ptr(), x.as_ptr(), u.len(), out.as_mut_ptr()), BwStatus::BW_OK);
            let mut status = core::mem::zeroed::<BwIdentifierStatus>();
            assert_eq!(bw_identifier_status(id, &mut status), BwStatus::BW_OK);
            assert_eq!((status.method, status.samples), (method, 600));
            let filled = [status.horizon.samples, status.rpem.samples, status.paper.samples];
            assert_eq!(filled.iter().filter(|&&n| n == 600).count(), 1);
            // A forecast does not change the identifier.
            let before = (*id).0.clone();
            let mut ahead = [0.0; 5];
            assert_eq!(bw_identifier_forecast(id, u.as_ptr(), 5, ahead.as_mut_ptr()), BwStatus::BW_OK);
            assert!(ahead.iter().all(|v| v.is_finite()));
            assert_eq!((*id).0, before);
            let mut fc = -1.0;
            assert_eq!(bw_identifier_lag_fc(id, &mut fc), BwStatus::BW_OK);
            assert_eq!(fc > 0.0, method == BwMethod::BW_METHOD_HORIZON);
            // A snapshot comes back as the same method, equal.
            let mut len = 0usize;
            assert_eq!(bw_identifier_snapshot(id, core::ptr::null_mut(), 0, &mut len), BwStatus::BW_BUFFER_TOO_SMALL);
            let mut buf = vec![0u8; len];
            assert_eq!(bw_identifier_snapshot(id, buf.as_mut_ptr(), len, &mut len), BwStatus::BW_OK);
            let mut copy: *mut BwIdentifier = core::ptr::null_mut();
            assert_eq!(bw_identifier_restore(buf.as_ptr(), len, &mut copy), BwStatus::BW_OK);
            assert_eq!((*copy).0.to_snapshot(), buf);
            let mut next = [0.0; 2];
            let mut twin = (*id).0.clone();
            assert_eq!(bw_identifier_push(copy, u[3], x[3], &mut next[0]), BwStatus::BW_OK);
            next[1] = twin.push(u[3], x[3]).expect("finite");
            assert_eq!(next[0].to_bits(), next[1].to_bits());
            bw_identifier_free(copy);
            // The horizon method's own calls.
            let mut ran = 7usize;
            let refine = bw_identifier_refine(id, 16, &mut ran);
            if method == BwMethod::BW_METHOD_HORIZON {
                // A value outside BwRefineMode is refused, the mode kept.
                assert_eq!(bw_identifier_set_refine(id, 2), BwStatus::BW_INVALID_CONFIG);
            }
            let set = bw_identifier_set_refine(id, BwRefineMode::BW_REFINE_COOPERATIVE as u32);
            if method == BwMethod::BW_METHOD_HORIZON {
                assert_eq!((refine, set, ran), (BwStatus::BW_OK, BwStatus::BW_OK, 0));
                let mut y = 0.0;
                assert_eq!(bw_identifier_push(id, u[10], x[10], &mut y), BwStatus::BW_OK);
                assert_eq!(bw_identifier_refine(id, 16, &mut ran), BwStatus::BW_OK);
                assert!(ran > 0);
            } else {
                assert_eq!((refine, set, ran), (BwStatus::BW_WRONG_METHOD, BwStatus::BW_WRONG_METHOD, 7));
                assert_eq!((*id).0, before);
            }
            assert_eq!(bw_identifier_reset(id), BwStatus::BW_OK);
            assert_eq!(bw_identifier_status(id, &mut status), BwStatus::BW_OK);
            assert_eq!(status.samples, 0);
            bw_identifier_free(id);
        }
    }
}

#[test]
fn a_bank_of_any_method_equals_its_single_identifier() {
    unsafe {
        let mut p = core::mem::zeroed::<BwParams>();
        assert_eq!(bw_params_paper_1hz(&mut p), BwStatus::BW_OK);
        for id in each_method(&p) {
            let mut bank: *mut BwBank = core::ptr::null_mut();
            assert_eq!(bw_bank_new(2, 1e-4, id, &mut bank), BwStatus::BW_OK);
            for k in 0..300 {
                let u = 30.0 * (1.0 - (k as f64 * 0.03).cos());
                let (mut single, mut frame) = (0.0, [0.0; 2]);
                assert_eq!(bw_identifier_push(id, u, 0.2 * u, &mut single), BwStatus::BW_OK);
                let (uf, xf) = ([u, u], [0.2 * u, 0.2 * u]);
                assert_eq!(bw_bank_push(bank, uf.as_ptr(), xf.as_ptr(), frame.as_mut_ptr()), BwStatus::BW_OK);
                assert_eq!(frame.map(f64::to_bits), [single.to_bits(); 2]);
            }
            let (mut a, mut b) = (core::mem::zeroed::<BwParams>(), core::mem::zeroed::<BwParams>());
            assert_eq!(bw_bank_params(bank, 1, &mut a), BwStatus::BW_OK);
            assert_eq!(bw_identifier_params(id, &mut b), BwStatus::BW_OK);
            assert_eq!(a, b);
            bw_bank_free(bank);
            bw_identifier_free(id);
        }
    }
}
