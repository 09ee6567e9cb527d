//! The header is current; every error path returns its status; results are the runtime's bits.

use super::*;

#[path = "../../examples/fw-host/src/blobs.rs"]
#[allow(dead_code)]
mod blobs;

/// Regenerates include/cbd.h and compares it with the checked-in file
/// (`CBD_FFI_WRITE_HEADER=1 cargo test -p cbd-ffi header` rewrites it).
#[test]
fn header_is_current() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).expect("cbindgen.toml");
    let bindings = cbindgen::Builder::new().with_config(config).with_src(dir.join("src/lib.rs")).generate().expect("cbindgen");
    let mut generated = Vec::new();
    bindings.write(&mut generated);
    let generated = std::string::String::from_utf8(generated).expect("utf-8");
    let path = dir.join("include/cbd.h");
    if std::env::var_os("CBD_FFI_WRITE_HEADER").is_some() {
        std::fs::write(&path, &generated).expect("write include/cbd.h");
        return;
    }
    let current = std::fs::read_to_string(&path).unwrap_or_default();
    if current != generated {
        let line = current
            .lines()
            .zip(generated.lines())
            .position(|(a, b)| a != b)
            .unwrap_or(current.lines().count().min(generated.lines().count()));
        panic!(
            "ffi/include/cbd.h is out of date (first difference at line {}); regenerate it with\n    CBD_FFI_WRITE_HEADER=1 cargo test -p cbd-ffi header\nand commit it",
            line + 1
        );
    }
}

/// Storage for a blob: `u64`s, so 8-byte aligned; returns (buffer, bytes needed).
fn storage_for(blob: &[u8]) -> (Vec<u64>, usize) {
    let mut bytes = 0;
    assert_eq!(unsafe { cbd_storage_size(blob.as_ptr(), blob.len(), &mut bytes) }, CBD_OK);
    (vec![0u64; bytes.div_ceil(8) + 1], bytes)
}

fn load(blob: &[u8], storage: &mut [u64], bytes: usize) -> (CbdStatus, *mut CbdCalibrator) {
    let mut h = core::ptr::dangling_mut();
    let s = unsafe { cbd_load(blob.as_ptr(), blob.len(), storage.as_mut_ptr().cast(), bytes, &mut h) };
    (s, h)
}

#[test]
fn results_are_the_runtimes_bits() {
    for blob in [blobs::rr_reference_blob(), blobs::six_effects_blob(), blobs::rr_ws_blob(), blobs::six_ws_blob()] {
        let (mut storage, bytes) = storage_for(&blob);
        let (s, h) = load(&blob, &mut storage, bytes);
        assert_eq!(s, CBD_OK);
        let (n, m) = unsafe { (cbd_n_joints(h), cbd_task_dim(h)) };
        let model = decode(&blob).unwrap();
        assert_eq!((n, m), (model.n_joints(), model.task_dim()));
        let mut reals = vec![0.0 as Real; storage_len_for(&model)];
        let mut cal = Calibrator::load(&blob, &mut reals).unwrap();
        let mut q = vec![0.0; n];
        for i in 0..shared::COUNT {
            shared::config(i, &mut q);
            let (mut pos, mut jac, mut support) = ([0.0; CBD_MAX_TASK_DIM], [0.0; CBD_MAX_TASK_DIM * CBD_MAX_JOINTS], 0.0);
            let s = unsafe { cbd_evaluate(h, q.as_ptr(), n, pos.as_mut_ptr(), m, jac.as_mut_ptr(), m * n, &mut support) };
            assert_eq!(s, CBD_OK);
            let e = cal.evaluate(&q).unwrap();
            for a in 0..m {
                assert_eq!(pos[a].to_bits(), e.position()[a].to_bits());
                for d in 0..n {
                    assert_eq!(jac[a * n + d].to_bits(), e.jacobian()[(a, d)].to_bits());
                }
            }
            assert_eq!(support.to_bits(), e.support().to_bits());
            // Support is optional.
            let s = unsafe { cbd_evaluate(h, q.as_ptr(), n, pos.as_mut_ptr(), m, jac.as_mut_ptr(), m * n, core::ptr::null_mut()) };
            assert_eq!(s, CBD_OK);
        }
    }
}

#[test]
fn error_paths_return_status_codes() {
    let null: *mut f64 = core::ptr::null_mut();
    let blob = blobs::rr_reference_blob();
    let (mut storage, bytes) = storage_for(&blob);
    let mut size = 0;
    unsafe {
        // Null pointers.
        assert_eq!(cbd_storage_size(core::ptr::null(), blob.len(), &mut size), CBD_ERR_NULL_POINTER);
        assert_eq!(cbd_storage_size(blob.as_ptr(), blob.len(), core::ptr::null_mut()), CBD_ERR_NULL_POINTER);
        let mut h = core::ptr::dangling_mut();
        assert_eq!(cbd_load(core::ptr::null(), blob.len(), storage.as_mut_ptr().cast(), bytes, &mut h), CBD_ERR_NULL_POINTER);
        assert!(h.is_null());
        assert_eq!(cbd_load(blob.as_ptr(), blob.len(), core::ptr::null_mut(), bytes, &mut h), CBD_ERR_NULL_POINTER);
        assert_eq!(cbd_load(blob.as_ptr(), blob.len(), storage.as_mut_ptr().cast(), bytes, core::ptr::null_mut()), CBD_ERR_NULL_POINTER);
        // Short and misaligned storage.
        for short in [0, 1, HEAD, bytes - 1] {
            assert_eq!(load(&blob, &mut storage, short).0, CBD_ERR_STORAGE_TOO_SMALL, "{short} bytes");
        }
        let misaligned = storage.as_mut_ptr().cast::<u8>().add(4).cast();
        assert_eq!(cbd_load(blob.as_ptr(), blob.len(), misaligned, bytes, &mut h), CBD_ERR_MISALIGNED);
        // Corrupt blobs.
        let mut corrupt = blob.clone();
        corrupt[40] ^= 1;
        assert_eq!(load(&corrupt, &mut storage, bytes).0, CBD_ERR_CHECKSUM);
        assert_eq!(cbd_storage_size(corrupt.as_ptr(), corrupt.len(), &mut size), CBD_ERR_CHECKSUM);
        assert_eq!(load(&blob[..blob.len() - 1], &mut storage, bytes).0, CBD_ERR_TRUNCATED);
        assert_eq!(load(&blob[..3], &mut storage, bytes).0, CBD_ERR_TRUNCATED);
        assert_eq!(cbd_load(blob.as_ptr(), 0, storage.as_mut_ptr().cast(), bytes, &mut h), CBD_ERR_TRUNCATED);
        let mut longer = blob.clone();
        longer.push(0);
        assert_eq!(load(&longer, &mut storage, bytes).0, CBD_ERR_TRAILING_BYTES);
        let mut magic = blob.clone();
        magic[0] = b'X';
        assert_eq!(load(&magic, &mut storage, bytes).0, CBD_ERR_BAD_MAGIC);
        let mut version = blob.clone();
        version[4] = 99;
        assert_eq!(load(&version, &mut storage, bytes).0, CBD_ERR_UNSUPPORTED_VERSION);
        // A failed load invalidates a handle into the same storage; never-loaded storage is no handle.
        let (s, h) = load(&blob, &mut storage, bytes);
        assert_eq!(s, CBD_OK);
        assert_eq!(cbd_n_joints(h), 2);
        assert_eq!(load(&corrupt, &mut storage, bytes).0, CBD_ERR_CHECKSUM);
        assert_eq!(cbd_n_joints(h), 0);
        let (mut pos, mut jac) = ([0.0; 3], [0.0; 21]);
        let q = [0.1, 0.2];
        assert_eq!(cbd_evaluate(h, q.as_ptr(), 2, pos.as_mut_ptr(), 3, jac.as_mut_ptr(), 21, null), CBD_ERR_BAD_HANDLE);
        assert_eq!(
            cbd_evaluate(core::ptr::null_mut(), q.as_ptr(), 2, pos.as_mut_ptr(), 3, jac.as_mut_ptr(), 21, null),
            CBD_ERR_NULL_POINTER
        );
        assert_eq!(cbd_task_dim(core::ptr::null()), 0);
        // Evaluation errors.
        let (s, h) = load(&blob, &mut storage, bytes);
        assert_eq!(s, CBD_OK);
        assert_eq!(cbd_evaluate(h, core::ptr::null(), 2, pos.as_mut_ptr(), 3, jac.as_mut_ptr(), 21, null), CBD_ERR_NULL_POINTER);
        assert_eq!(cbd_evaluate(h, q.as_ptr(), 2, null, 3, jac.as_mut_ptr(), 21, null), CBD_ERR_NULL_POINTER);
        assert_eq!(cbd_evaluate(h, q.as_ptr(), 2, pos.as_mut_ptr(), 3, null, 21, null), CBD_ERR_NULL_POINTER);
        assert_eq!(cbd_evaluate(h, q.as_ptr(), 3, pos.as_mut_ptr(), 3, jac.as_mut_ptr(), 21, null), CBD_ERR_QUERY_DIMENSION);
        assert_eq!(cbd_evaluate(h, q.as_ptr(), 2, pos.as_mut_ptr(), 1, jac.as_mut_ptr(), 21, null), CBD_ERR_BUFFER_TOO_SMALL);
        assert_eq!(cbd_evaluate(h, q.as_ptr(), 2, pos.as_mut_ptr(), 2, jac.as_mut_ptr(), 3, null), CBD_ERR_BUFFER_TOO_SMALL);
        let bad = [f64::NAN, 0.0];
        assert_eq!(cbd_evaluate(h, bad.as_ptr(), 2, pos.as_mut_ptr(), 2, jac.as_mut_ptr(), 4, null), CBD_ERR_NON_FINITE_QUERY);
        assert_eq!((pos, jac), ([0.0; 3], [0.0; 21]), "nothing written on an error");
        assert_eq!(cbd_evaluate(h, q.as_ptr(), 2, pos.as_mut_ptr(), 2, jac.as_mut_ptr(), 4, null), CBD_OK);
    }
}

#[test]
fn versions_and_names() {
    let version = unsafe { core::ffi::CStr::from_ptr(cbd_version()) };
    assert_eq!(version.to_str().unwrap(), env!("CARGO_PKG_VERSION"));
    assert_eq!(cbd_format_version(), FORMAT_VERSION);
    assert_eq!(cbd_oldest_format_version(), OLDEST_FORMAT_VERSION);
    for (status, name) in [
        (CBD_OK, "CBD_OK"),
        (CBD_ERR_CHECKSUM, "CBD_ERR_CHECKSUM"),
        (CBD_ERR_INTERNAL, "CBD_ERR_INTERNAL"),
        (CBD_ERR_TOOL_POINT, "CBD_ERR_TOOL_POINT"),
        (CBD_ERR_ORIENTATION_UNDETERMINED, "CBD_ERR_ORIENTATION_UNDETERMINED"),
        (CBD_ERR_TOO_FEW_JOINTS, "CBD_ERR_TOO_FEW_JOINTS"),
        (CBD_ERR_INVALID_ROTATION, "CBD_ERR_INVALID_ROTATION"),
    ] {
        assert_eq!(unsafe { core::ffi::CStr::from_ptr(cbd_status_name(status as i32)) }.to_str().unwrap(), name);
    }
    assert_eq!(unsafe { core::ffi::CStr::from_ptr(cbd_status_name(-1)) }.to_str().unwrap(), "CBD_UNKNOWN_STATUS");
}

#[test]
fn compensate_gives_the_runtimes_bits_and_its_errors() {
    let blob = blobs::rr_reference_blob();
    let (mut storage, bytes) = storage_for(&blob);
    let (s, h) = load(&blob, &mut storage, bytes);
    assert_eq!(s, CBD_OK);
    let model = decode(&blob).unwrap();
    let mut reals = vec![0.0 as Real; storage_len_for(&model)];
    let mut cal = Calibrator::load(&blob, &mut reals).unwrap();
    let (target, seed) = ([0.9, 0.6], [0.3, 1.0]);
    let (mut command, mut residual, mut flags) = ([0.0; 2], 0.0, 0u32);
    let s = unsafe { cbd_compensate(h, target.as_ptr(), 2, seed.as_ptr(), command.as_mut_ptr(), 2, &mut residual, &mut flags) };
    assert_eq!(s, CBD_OK);
    let mut expected = [0.0; 2];
    let c = cal.compensate(&target, &seed, &mut expected).unwrap();
    assert_eq!(command.map(f64::to_bits), expected.map(f64::to_bits));
    assert_eq!(residual.to_bits(), c.residual.to_bits());
    assert_eq!(flags & CBD_COMPENSATE_REACHED != 0, c.reached);
    assert!(c.reached);
    let nan = [f64::NAN, 0.0];
    let s =
        unsafe { cbd_compensate(h, nan.as_ptr(), 2, seed.as_ptr(), command.as_mut_ptr(), 2, core::ptr::null_mut(), core::ptr::null_mut()) };
    assert_eq!(s, CBD_ERR_NON_FINITE_QUERY);
    let s = unsafe {
        cbd_compensate(h, target.as_ptr(), 3, seed.as_ptr(), command.as_mut_ptr(), 2, core::ptr::null_mut(), core::ptr::null_mut())
    };
    assert_eq!(s, CBD_ERR_QUERY_DIMENSION);
    let s = unsafe {
        cbd_compensate(h, core::ptr::null(), 2, seed.as_ptr(), command.as_mut_ptr(), 2, core::ptr::null_mut(), core::ptr::null_mut())
    };
    assert_eq!(s, CBD_ERR_NULL_POINTER);
}

#[test]
fn tool_points_and_the_pose_give_the_runtimes_bits() {
    let blob = blobs::six_tool_points_blob();
    let (mut storage, bytes) = storage_for(&blob);
    let (s, h) = load(&blob, &mut storage, bytes);
    assert_eq!(s, CBD_OK);
    let model = decode(&blob).unwrap();
    let mut reals = vec![0.0 as Real; storage_len_for(&model)];
    let mut cal = Calibrator::load(&blob, &mut reals).unwrap();
    assert_eq!(unsafe { cbd_tool_point_count(h) }, 3);
    assert_eq!(unsafe { cbd_tool_point_count(core::ptr::null()) }, 0);
    let null: *mut f64 = core::ptr::null_mut();
    let q = [0.3, -1.1, 1.4, 0.2, -0.7, 2.1];
    let (mut pos, mut jac, mut support) = ([0.0; 3], [0.0; 18], 0.0);
    for j in 0..3 {
        let s = unsafe { cbd_evaluate_point(h, q.as_ptr(), 6, j, pos.as_mut_ptr(), 3, jac.as_mut_ptr(), 18, &mut support) };
        assert_eq!(s, CBD_OK);
        let e = cal.evaluate_point(&q, j).unwrap();
        for a in 0..3 {
            assert_eq!(pos[a].to_bits(), e.position()[a].to_bits());
            for d in 0..6 {
                assert_eq!(jac[a * 6 + d].to_bits(), e.jacobian()[(a, d)].to_bits());
            }
        }
    }
    let s = unsafe { cbd_evaluate_point(h, q.as_ptr(), 6, 3, pos.as_mut_ptr(), 3, jac.as_mut_ptr(), 18, null) };
    assert_eq!(s, CBD_ERR_TOOL_POINT);
    let (mut rotation, mut origin, mut pose_jac, mut points, mut residual) = ([0.0; 9], [0.0; 3], [0.0; 36], [0.0; 9], 0.0);
    let s = unsafe {
        cbd_evaluate_pose(
            h,
            q.as_ptr(),
            6,
            rotation.as_mut_ptr(),
            origin.as_mut_ptr(),
            pose_jac.as_mut_ptr(),
            36,
            points.as_mut_ptr(),
            9,
            &mut residual,
        )
    };
    assert_eq!(s, CBD_OK);
    let pose = cal.evaluate_pose(&q).unwrap();
    assert_eq!(rotation.map(f64::to_bits).to_vec(), pose.rotation().iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>());
    assert_eq!(origin.map(f64::to_bits), pose.origin().map(f64::to_bits));
    for a in 0..6 {
        for d in 0..6 {
            assert_eq!(pose_jac[a * 6 + d].to_bits(), pose.jacobian()[(a, d)].to_bits());
        }
    }
    for j in 0..3 {
        for a in 0..3 {
            assert_eq!(points[3 * j + a].to_bits(), pose.point(j).unwrap().position()[a].to_bits());
        }
    }
    assert_eq!(residual.to_bits(), pose.fit_residual().to_bits());
    let s = unsafe {
        cbd_evaluate_pose(h, q.as_ptr(), 6, rotation.as_mut_ptr(), origin.as_mut_ptr(), pose_jac.as_mut_ptr(), 35, null, 0, null)
    };
    assert_eq!(s, CBD_ERR_BUFFER_TOO_SMALL);
    let s = unsafe {
        cbd_evaluate_pose(
            h,
            q.as_ptr(),
            6,
            rotation.as_mut_ptr(),
            origin.as_mut_ptr(),
            pose_jac.as_mut_ptr(),
            36,
            points.as_mut_ptr(),
            8,
            null,
        )
    };
    assert_eq!(s, CBD_ERR_BUFFER_TOO_SMALL);
    // Pose compensation to the pose just evaluated, from a nearby seed.
    let seed = [0.35, -1.0, 1.3, 0.25, -0.6, 2.0];
    let (mut command, mut pr, mut ar, mut flags) = ([0.0; 6], 0.0, 0.0, 0u32);
    let s = unsafe {
        cbd_compensate_pose(h, origin.as_ptr(), rotation.as_ptr(), seed.as_ptr(), command.as_mut_ptr(), 6, &mut pr, &mut ar, &mut flags)
    };
    assert_eq!(s, CBD_OK);
    let rows = [[rotation[0], rotation[1], rotation[2]], [rotation[3], rotation[4], rotation[5]], [rotation[6], rotation[7], rotation[8]]];
    let mut expected = [0.0; 6];
    let c = cal.compensate_pose(&origin, &rows, &seed, &mut expected).unwrap();
    assert_eq!(command.map(f64::to_bits), expected.map(f64::to_bits));
    assert_eq!((pr.to_bits(), ar.to_bits()), (c.position_residual.to_bits(), c.angle_residual.to_bits()));
    assert!(c.reached && flags & CBD_COMPENSATE_REACHED != 0, "{c:?}");
    let mirror = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0];
    let s = unsafe {
        cbd_compensate_pose(h, origin.as_ptr(), mirror.as_ptr(), seed.as_ptr(), command.as_mut_ptr(), 6, null, null, core::ptr::null_mut())
    };
    assert_eq!(s, CBD_ERR_INVALID_ROTATION);
    // A model with one tool point: no orientation.
    let blob = blobs::six_joint_blob();
    let (mut storage, bytes) = storage_for(&blob);
    let (_, h) = load(&blob, &mut storage, bytes);
    let s = unsafe {
        cbd_evaluate_pose(h, q.as_ptr(), 6, rotation.as_mut_ptr(), origin.as_mut_ptr(), pose_jac.as_mut_ptr(), 36, null, 0, null)
    };
    assert_eq!(s, CBD_ERR_ORIENTATION_UNDETERMINED);
    // A planar arm: too few joints for a pose.
    let blob = blobs::rr_reference_blob();
    let (mut storage, bytes) = storage_for(&blob);
    let (_, h) = load(&blob, &mut storage, bytes);
    let s = unsafe {
        cbd_compensate_pose(h, origin.as_ptr(), mirror.as_ptr(), seed.as_ptr(), command.as_mut_ptr(), 2, null, null, core::ptr::null_mut())
    };
    assert_eq!(s, CBD_ERR_TOO_FEW_JOINTS);
}
