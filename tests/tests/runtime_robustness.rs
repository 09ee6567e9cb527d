//! The runtime never panics: any query, any damaged blob gives a value or a typed error.

use cbd_protocol::*;
use cbd_runtime::{Calibrator, Error};
use proptest::prelude::*;

fn reference_blob() -> Vec<u8> {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/data/rr_flow_reference.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let flat = |key: &str| -> Vec<f64> {
        v[key].as_array().unwrap().iter().flat_map(|r| r.as_array().unwrap().iter().map(|x| x.as_f64().unwrap())).collect()
    };
    let (x, p) = (f64_le_bytes(&flat("X")), f64_le_bytes(&flat("P0")));
    let model = Model {
        nominal: NominalModel::PlanarChain { lengths: heapless::Vec::from_slice(&[1.0, 0.5]).unwrap() },
        normalisation: Normalisation::IDENTITY,
        joint_kernel: JointKernel { gamma: 8.0, axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: 1.0186 }; 2]).unwrap() },
        task_kernel: TaskKernel { width: 1.027 },
        integrator: Integrator { method: IntegratorMethod::Heun, steps: 5 },
        momentum_law: MomentumLaw::WithDivergence,
        sigma: 1e-4,
        n_points: 256,
        points: F64Slice::from_le_bytes(&x),
        momenta: F64Slice::from_le_bytes(&p),
    };
    encode_to_vec(&model).unwrap()
}

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
