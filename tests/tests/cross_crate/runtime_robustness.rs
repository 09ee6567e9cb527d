//! The runtime never panics: any query, any damaged blob gives a value or a typed error.

use cbd_protocol::*;
use cbd_runtime::{Calibrator, Error};
use proptest::prelude::*;

use cbd_tests::reference_blob;

fn storage() -> Vec<f64> {
    vec![0.0; cbd_runtime::storage_len(256, 2, 2, Integrator { method: IntegratorMethod::Heun, steps: 5 })]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]
    #[test]
    fn any_query_gives_a_value_or_an_error(a in prop::num::f64::ANY, b in prop::num::f64::ANY, len in 0usize..4) {
        // Loaded once per thread: the blob and storage live for the whole test run.
        thread_local! {
            static CAL: std::cell::RefCell<Calibrator<'static>> = std::cell::RefCell::new(
                Calibrator::load(Vec::leak(reference_blob()), Vec::leak(storage())).unwrap());
        }
        CAL.with(|cal| {
            let mut cal = cal.borrow_mut();
            let q = [a, b, 0.5];
            let q = &q[..len.min(3)];
            match cal.evaluate(q) {
                Ok(e) => {
                    prop_assert!(q.len() == 2 && a.is_finite() && b.is_finite());
                    prop_assert!(e.position().iter().all(|v| v.is_finite()));
                }
                Err(Error::QueryDimension { .. }) => prop_assert!(q.len() != 2),
                Err(Error::NonFiniteQuery { .. }) => prop_assert!(!(a.is_finite() && b.is_finite())),
                Err(e) => prop_assert!(false, "unexpected error {e:?}"),
            }
            Ok(())
        })?;
    }
}

#[test]
fn damaged_blobs_are_rejected_by_the_runtime() {
    let blob = reference_blob();
    let mut s = storage();
    let mut bad = blob.clone();
    bad[HEADER_LEN + 40] ^= 0x10;
    assert!(matches!(Calibrator::load(&bad, &mut s), Err(Error::Blob(DecodeError::ChecksumMismatch { .. }))));
    assert!(matches!(Calibrator::load(&blob[..blob.len() - 1], &mut s), Err(Error::Blob(DecodeError::Truncated { .. }))));
    let mut old = blob.clone();
    old[4] = 0;
    assert!(matches!(Calibrator::load(&old, &mut s), Err(Error::Blob(DecodeError::UnsupportedVersion { .. }))));
    let mut tiny = vec![0.0; 100];
    assert!(matches!(Calibrator::load(&blob, &mut tiny), Err(Error::StorageTooSmall { .. })));
}
