//! The import a calibration's rows were read through, beyond units, as a blob records it (format 9,
//! `cbd_protocol::ImportFrame`), and the check that a model file reads rows into the same frame.
//! A blob fitted through a joint map or a planar arm's base, yaw and offsets, and then evaluated
//! through a model file without them, evaluates every row in another frame: it must be refused,
//! not reported as 94 of 100 rows `ok` (issue 51).
//!
//! The joints' import is fingerprinted by what it does, not by how it is written: its affine map
//! in model units (radians, the model's length unit), probed at zero and at each unit vector, so a
//! map written in degrees or in radians, or with an explicit `sign = +1`, gives the same print.

use super::column_spec::ColumnSpec;
use super::joint_columns::JointColumns;
use cbd_protocol::{ImportFrame, Provenance};
use sha2::{Digest, Sha256};

/// Significant digits a value is rounded to before it is fingerprinted: the same map written two
/// ways (degrees and radians, a coupling and its hand-converted columns) rounds alike.
const DIGITS: usize = 9;

/// The import frame `spec` reads rows into; `None` when it is the identity (units only).
pub fn import_frame(spec: &ColumnSpec) -> Option<ImportFrame> {
    let frame = ImportFrame { joints: joints_fingerprint(spec), positions: positions_fingerprint(spec) };
    (frame.joints.is_some() || frame.positions.is_some()).then_some(frame)
}

/// Why a blob with `provenance` (format 9; `None`: an older format, which records nothing, so
/// nothing is checked) does not fit a model file whose import is `spec`'s, or `Ok`. A format-9 blob
/// without an import frame was fitted through units alone. The caller names both files.
pub fn check_import_frame(provenance: Option<&Provenance>, spec: &ColumnSpec) -> Result<(), String> {
    let Some(provenance) = provenance else { return Ok(()) };
    let (fitted, ours) = (provenance.import_frame, import_frame(spec));
    let parts: [(Part, &str, &str); 2] = [
        (|f| f.joints, "joints", "joint import ([measurements.joint_map], [planar] offsets)"),
        (|f| f.positions, "positions", "[planar] frame (base, yaw)"),
    ];
    for (get, rows, what) in parts {
        let why = match (fitted.as_ref().and_then(get), ours.as_ref().and_then(get)) {
            (a, b) if a == b => continue,
            (Some(_), None) => format!("the blob was fitted to {rows} read through a {what} the model file does not have"),
            (None, Some(_)) => format!("the model file reads {rows} through a {what} the blob was not fitted with"),
            _ => format!("the blob was fitted to {rows} read through another {what} than the model file's"),
        };
        return Err(format!("{why}: its rows would be read in another frame than the blob's"));
    }
    Ok(())
}

/// One part of an [`ImportFrame`], read off it.
type Part = fn(&ImportFrame) -> Option<u64>;

/// q = M c + b in model units (c the columns converted to model units): b at zero, M's columns at
/// the unit vectors; `None` for the identity.
fn joints_fingerprint(spec: &ColumnSpec) -> Option<u64> {
    if spec.joint_map.is_none() && spec.planar_frame.is_none() {
        return None;
    }
    let columns = JointColumns::new(spec);
    let n = spec.joint_kinds.len();
    let b = columns.to_model_from_model_units(&vec![0.0; n]);
    let mut values = b.clone();
    let mut identity = b.iter().all(|&v| v == 0.0);
    for j in 0..n {
        let mut e = vec![0.0; n];
        e[j] = 1.0;
        let q = columns.to_model_from_model_units(&e);
        for (i, (q, b)) in q.iter().zip(&b).enumerate() {
            let m = q - b;
            identity &= (m - f64::from(u8::from(i == j))).abs() <= 1e-12;
            values.push(m);
        }
    }
    (!identity).then(|| fingerprint(n, &values))
}

/// A planar frame's base and yaw; `None` without one, or where both are zero.
fn positions_fingerprint(spec: &ColumnSpec) -> Option<u64> {
    let frame = spec.planar_frame.as_ref()?;
    let values = [frame.base[0], frame.base[1], frame.yaw];
    values.iter().any(|&v| v != 0.0).then(|| fingerprint(2, &values))
}

/// 64 bits of the SHA-256 of `values` rounded to [`DIGITS`] significant digits (as text: a sum's
/// last bit does not change the print), after their dimension `n`.
fn fingerprint(n: usize, values: &[f64]) -> u64 {
    let mut hash = Sha256::new();
    hash.update((n as u64).to_le_bytes());
    for v in values {
        // −0 and 0 print alike; a value below the rounding's reach prints as 0.
        let v = if v.abs() < 1e-12 { 0.0 } else { *v };
        hash.update(format!("{v:.prec$e};", prec = DIGITS - 1).as_bytes());
    }
    let digest = hash.finalize();
    let mut first = [0u8; 8];
    first.copy_from_slice(&digest[..8]);
    u64::from_le_bytes(first)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::model_file::parse_model_file;
    use std::path::Path;

    /// A format-9 record of `frame` (a blob updated from a parent: the record exists either way).
    fn recorded(frame: Option<ImportFrame>) -> Option<Provenance> {
        Some(Provenance { import_frame: frame, parent: Some([1; 32]) })
    }

    fn spec(text: &str) -> ColumnSpec {
        parse_model_file(text, Path::new("m.toml")).unwrap().column_spec().unwrap()
    }

    const PLANAR: &str = "length_unit = \"mm\"\nangle_unit = \"deg\"\n[planar]\nlengths = [1000.0, 500.0]\n";
    const MEASURED: &str = "[measurements]\njoints = [\"q1\", \"q2\"]\npositions = [\"x\", \"y\"]\n";

    #[test]
    fn units_alone_are_the_identity_and_a_frame_is_printed_by_what_it_does() {
        assert_eq!(import_frame(&spec(&format!("{PLANAR}{MEASURED}"))), None);
        // Radian columns: still units only.
        assert_eq!(import_frame(&spec(&format!("{PLANAR}{MEASURED}angle_unit = \"rad\"\n"))), None);
        let offset_deg = spec(&format!("{PLANAR}{MEASURED}[measurements.joint_map]\noffset = {{ q2 = 90.0 }}\n"));
        let offset_rad = spec(&format!(
            "{PLANAR}{MEASURED}angle_unit = \"rad\"\n[measurements.joint_map]\noffset = {{ q2 = {} }}\n",
            std::f64::consts::FRAC_PI_2
        ));
        let a = import_frame(&offset_deg).unwrap();
        assert!(a.joints.is_some() && a.positions.is_none());
        // The same offset written in degrees and in radians: the same print.
        assert_eq!(import_frame(&offset_rad), Some(a));
        // A [planar] joint offset of 90° does the same to the joints as the map's.
        let planar = spec(&format!("{}offsets = [0.0, 90.0]\n{MEASURED}", PLANAR));
        assert_eq!(import_frame(&planar), Some(a));
        // An explicit +1 sign is the identity.
        assert_eq!(import_frame(&spec(&format!("{PLANAR}{MEASURED}[measurements.joint_map]\nsign = {{ q1 = 1 }}\n"))), None);
        let flipped = import_frame(&spec(&format!("{PLANAR}{MEASURED}[measurements.joint_map]\nsign = {{ q1 = -1 }}\n"))).unwrap();
        assert_ne!(flipped.joints, a.joints);
        let moved = import_frame(&spec(&format!("{}base = [30.0, -20.0]\nyaw = 0.5\n{MEASURED}", PLANAR))).unwrap();
        assert!(moved.positions.is_some() && moved.joints.is_none());
    }

    #[test]
    fn a_blob_is_checked_against_the_frame_it_was_fitted_in() {
        let plain = spec(&format!("{PLANAR}{MEASURED}"));
        let framed = spec(&format!("{}base = [30.0, -20.0]\nyaw = 0.5\noffsets = [1.0, -2.0]\n{MEASURED}", PLANAR));
        let fitted = import_frame(&framed);
        assert_eq!(check_import_frame(recorded(fitted).as_ref(), &framed), Ok(()));
        let e = check_import_frame(recorded(fitted).as_ref(), &plain).unwrap_err();
        assert!(e.starts_with("the blob was fitted to joints read through a joint import ([measurements.joint_map], [planar] offsets) the model file does not have"), "{e}");
        // Fitted without a frame (a format-9 blob records none), read with one.
        let e = check_import_frame(recorded(None).as_ref(), &framed).unwrap_err();
        assert!(e.starts_with("the model file reads joints through a joint import"), "{e}");
        // Only the positions differ.
        let yawed = spec(&format!("{}base = [30.0, -20.0]\nyaw = 0.6\noffsets = [1.0, -2.0]\n{MEASURED}", PLANAR));
        let e = check_import_frame(recorded(fitted).as_ref(), &yawed).unwrap_err();
        assert!(
            e.starts_with("the blob was fitted to positions read through another [planar] frame (base, yaw) than the model file's"),
            "{e}"
        );
        // An older blob records nothing: nothing to check.
        assert_eq!(check_import_frame(None, &framed), Ok(()));
    }
}
