//! The joint mapping of a model file's `[measurements.joint_map]`: how the controller's joint
//! values (the CSV's joint columns, c) become the model's joints (q), in the columns' units:
//!
//! ```text
//! q_i = sign_i · scale_i · Σ_j coupling_ij c_j + offset_i      (coupling: identity when absent)
//! ```
//!
//! e.g. a FANUC arm, whose J3 is measured from the horizontal and J4–J6 turn the other way:
//!
//! ```toml
//! [measurements.joint_map]
//! sign = { q3 = -1, q4 = -1, q5 = -1, q6 = -1 }   # by model joint name (q1 … qn, or the URDF's)
//! coupling = [[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 1, 1, 0, 0, 0],
//!             [0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1]]   # q3 = −(J2 + J3)
//! # scale = { q2 = 1.0 }     offset = { q2 = -90 }   # offsets in the columns' unit
//! ```
//!
//! Applied at import (`csv_import`), so every command sees model joints; `cbd compensate` maps
//! its commands back with the inverse. Zero coefficients and zero offsets are skipped, so a
//! mapping reproduces bit for bit a column converted by hand in floating point.

use crate::error::number;
use serde::Deserialize;
use std::collections::BTreeMap;

/// `[measurements.joint_map]` as written (names not yet checked).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawJointMap {
    /// ±1 per model joint (by name); default +1.
    pub sign: Option<BTreeMap<String, f64>>,
    /// Finite, non-zero factor per model joint; default 1.
    pub scale: Option<BTreeMap<String, f64>>,
    /// Added last, in the column's unit; default 0.
    pub offset: Option<BTreeMap<String, f64>>,
    /// n × n: row i = model joint i, column j = the j-th joint column of `[measurements] joints`.
    pub coupling: Option<Vec<Vec<f64>>>,
}

/// A checked, invertible joint mapping.
#[derive(Debug, Clone, PartialEq)]
pub struct JointMap {
    /// sign_i · scale_i.
    factor: Vec<f64>,
    offset: Vec<f64>,
    /// coupling and its inverse, row-major rows; `None`: identity.
    coupling: Option<(Vec<Vec<f64>>, Vec<Vec<f64>>)>,
}

/// A bad entry: the field (`[measurements.joint_map] sign`) and what is wrong.
pub type FieldError = (String, String);

const SECTION: &str = "[measurements.joint_map]";

/// Largest condition number of a coupling accepted (beyond, the inverse of `cbd compensate`
/// loses more than a few of f64's digits).
const MAX_CONDITION: f64 = 1e12;

impl JointMap {
    /// Checks `raw` against the model's joint `names`: every name known, signs ±1, scales finite
    /// and non-zero, offsets finite, the coupling n × n, finite and not singular.
    pub fn new(raw: &RawJointMap, names: &[String]) -> Result<JointMap, FieldError> {
        let n = names.len();
        let per_joint = |key: &str, table: &Option<BTreeMap<String, f64>>, default: f64| -> Result<Vec<f64>, FieldError> {
            let field = format!("{SECTION} {key}");
            let mut out = vec![default; n];
            for (name, &v) in table.iter().flatten() {
                let Some(i) = names.iter().position(|x| x == name) else {
                    return Err((field, format!("no model joint named '{name}' (joints: {})", names.join(", "))));
                };
                let ok = match key {
                    "sign" => v == 1.0 || v == -1.0,
                    "scale" => v.is_finite() && v != 0.0 && v.abs() <= crate::limits::MAX_MAGNITUDE,
                    _ => v.is_finite() && v.abs() <= crate::limits::MAX_MAGNITUDE,
                };
                if !ok {
                    let need = match key {
                        "sign" => "+1 or -1",
                        "scale" => "a finite, non-zero factor within ±1e100",
                        _ => "a finite value within ±1e100",
                    };
                    return Err((field, format!("{name} = {}: needs {need}", crate::error::as_written(v))));
                }
                out[i] = v;
            }
            Ok(out)
        };
        let sign = per_joint("sign", &raw.sign, 1.0)?;
        let scale = per_joint("scale", &raw.scale, 1.0)?;
        let offset = per_joint("offset", &raw.offset, 0.0)?;
        let coupling = match &raw.coupling {
            None => None,
            Some(rows) => Some(coupling_and_inverse(rows, n)?),
        };
        Ok(JointMap { factor: sign.iter().zip(&scale).map(|(s, k)| s * k).collect(), offset, coupling })
    }

    /// Checks the whole map, sign · scale · coupling, on the controller's joint `limits` (the
    /// columns' units; ±∞ where a joint has none): its condition number at most [`MAX_CONDITION`],
    /// the model joints it gives within ±1e100, and its inverse — how `cbd compensate` writes a
    /// command back — taking the limits' range to within ±1e100 and at most [`MAX_CONDITION`] times
    /// the limits (a scale of 1e-300 is not singular by the coupling's test, yet maps a 30° command
    /// back to 3e301°). `columns` names the controller's joints in messages.
    pub fn check_range(&self, limits: &[[f64; 2]], columns: &[String]) -> Result<(), FieldError> {
        let n = self.factor.len();
        let field = || SECTION.to_string();
        let coupling = |i: usize, j: usize| match &self.coupling {
            Some((rows, _)) => rows[i][j],
            None => f64::from(u8::from(i == j)),
        };
        let inverse = |j: usize, i: usize| match &self.coupling {
            Some((_, inv)) => inv[j][i] / self.factor[i],
            None => f64::from(u8::from(i == j)) / self.factor[i],
        };
        let whole = faer::Mat::<f64>::from_fn(n, n, |i, j| self.factor[i] * coupling(i, j));
        let s = whole.singular_values().map_err(|e| (field(), format!("singular values failed: {e:?}")))?;
        let (largest, smallest) = (s[0], s[n - 1]);
        if !(smallest > 0.0 && largest / smallest <= MAX_CONDITION) {
            return Err((
                field(),
                format!(
                    "sign · scale · coupling has condition number {} (singular values {} … {}), beyond {MAX_CONDITION:e}: commands cannot be mapped back to the controller's values",
                    number(largest / smallest),
                    number(largest),
                    number(smallest)
                ),
            ));
        }
        let half = |[lo, hi]: [f64; 2]| lo.abs().max(hi.abs());
        // |coefficient| × (limit + |offset|); a zero coefficient adds nothing, even to a joint without limits.
        let term = |coefficient: f64, limit: Option<f64>, offset: f64| {
            if coefficient == 0.0 {
                Some(0.0)
            } else {
                limit.map(|l| coefficient.abs() * (l + offset.abs()))
            }
        };
        let finite: Vec<Option<f64>> = limits.iter().map(|l| Some(half(*l)).filter(|h| h.is_finite())).collect();
        for i in 0..n {
            // The model joint's reach over the limit box: Σ_j |M_ij| L_j + |offset_i|.
            let reach: Option<f64> = (0..n).map(|j| term(self.factor[i] * coupling(i, j), finite[j], 0.0)).sum();
            if let Some(r) = reach.map(|r| r + self.offset[i].abs()) {
                if !(r <= crate::limits::MAX_MAGNITUDE) {
                    return Err((
                        field(),
                        format!("maps the joint limits to model joint {} values of ±{}, beyond ±1e100", i + 1, number(r)),
                    ));
                }
            }
        }
        for j in 0..n {
            // The controller's value of a command anywhere in the limit box: Σ_i |M⁻¹_ji| (L_i + |offset_i|).
            let Some(own) = finite[j] else { continue };
            let Some(back) = (0..n).map(|i| term(inverse(j, i), finite[i], self.offset[i])).sum::<Option<f64>>() else {
                continue;
            };
            if !(back <= crate::limits::MAX_MAGNITUDE && back <= MAX_CONDITION * own.max(f64::MIN_POSITIVE)) {
                return Err((
                    field(),
                    format!(
                        "its inverse (sign · scale · coupling, then offset) takes commands within the joint limits to {} values of ±{} (limits ±{}): the map is too close to singular, or its offset too large, for commands to be written back",
                        crate::error::excerpt(columns.get(j).map_or("?", String::as_str)),
                        number(back),
                        number(own)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Controller values `c` → model joints `q` (the columns' units).
    pub fn to_model(&self, c: &[f64], q: &mut [f64]) {
        for (i, q) in q.iter_mut().enumerate() {
            let coupled = match &self.coupling {
                Some((rows, _)) => sparse_dot(&rows[i], c),
                None => c[i],
            };
            *q = plus(coupled * self.factor[i], self.offset[i]);
        }
    }

    /// Model joints `q` → controller values `c`: c = C⁻¹ ((q − offset) / (sign · scale)).
    pub fn to_columns(&self, q: &[f64], c: &mut [f64]) {
        let unscaled: Vec<f64> = q.iter().enumerate().map(|(i, q)| plus(*q, -self.offset[i]) / self.factor[i]).collect();
        for (j, c) in c.iter_mut().enumerate() {
            *c = match &self.coupling {
                Some((_, inverse)) => sparse_dot(&inverse[j], &unscaled),
                None => unscaled[j],
            };
        }
    }
}

/// a + b, skipping b = 0 (keeps a's bits, −0 included).
fn plus(a: f64, b: f64) -> f64 {
    if b == 0.0 {
        a
    } else {
        a + b
    }
}

/// Σ_j w_j x_j over the non-zero w_j in order, starting from the first term (no 0 + …): a
/// coupling row of ones adds exactly the columns it names.
fn sparse_dot(w: &[f64], x: &[f64]) -> f64 {
    let mut terms = w.iter().zip(x).filter(|(w, _)| **w != 0.0).map(|(w, x)| if *w == 1.0 { *x } else { w * x });
    let first = terms.next().unwrap_or(0.0);
    terms.fold(first, |s, t| s + t)
}

/// The coupling's rows checked (n × n, finite) with its inverse; singular or ill-conditioned
/// (condition number beyond [`MAX_CONDITION`]) is an error.
fn coupling_and_inverse(rows: &[Vec<f64>], n: usize) -> Result<(Vec<Vec<f64>>, Vec<Vec<f64>>), FieldError> {
    use faer::linalg::solvers::DenseSolveCore;
    let field = format!("{SECTION} coupling");
    if rows.len() != n || rows.iter().any(|r| r.len() != n) {
        let shape = rows.iter().map(|r| r.len().to_string()).collect::<Vec<_>>().join(", ");
        return Err((
            field,
            format!("needs {n} rows of {n} entries (one per model joint and joint column); has {} rows of [{shape}]", rows.len()),
        ));
    }
    if let Some((i, j)) = (0..n).flat_map(|i| (0..n).map(move |j| (i, j))).find(|&(i, j)| !rows[i][j].is_finite()) {
        return Err((field, format!("row {} entry {}: {} is not finite", i + 1, j + 1, number(rows[i][j]))));
    }
    let c = faer::Mat::<f64>::from_fn(n, n, |i, j| rows[i][j]);
    let s = c.singular_values().map_err(|e| (field.clone(), format!("singular values failed: {e:?}")))?;
    let (largest, smallest) = (s[0], s[n - 1]);
    if !(smallest > 0.0 && largest / smallest <= MAX_CONDITION) {
        return Err((
            field,
            format!("the matrix is singular (singular values {} … {}): the model joints do not determine the controller's, so commands cannot be mapped back", number(largest), number(smallest)),
        ));
    }
    let inverse = c.full_piv_lu().inverse();
    Ok((rows.to_vec(), (0..n).map(|i| (0..n).map(|j| inverse[(i, j)]).collect()).collect()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: usize) -> Vec<String> {
        (1..=n).map(|i| format!("q{i}")).collect()
    }

    fn raw(text: &str) -> RawJointMap {
        toml::from_str(text).unwrap()
    }

    const FANUC: &str = "sign = { q3 = -1, q4 = -1, q5 = -1, q6 = -1 }\n\
        coupling = [[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 1, 1, 0, 0, 0], [0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1]]";

    #[test]
    fn fanuc_coupling_maps_like_the_hand_formula_and_back() {
        let map = JointMap::new(&raw(FANUC), &names(6)).unwrap();
        let c = [10.5, -33.25, 71.125, 12.0, -0.1, 179.9];
        let mut q = [0.0; 6];
        map.to_model(&c, &mut q);
        // Bit for bit: q3 = −(J3 + J2), q4..q6 = −J.
        assert_eq!(q.map(f64::to_bits), [c[0], c[1], -(c[2] + c[1]), -c[3], -c[4], -c[5]].map(f64::to_bits));
        let mut back = [0.0; 6];
        map.to_columns(&q, &mut back);
        for (a, b) in back.iter().zip(&c) {
            assert!((a - b).abs() <= 1e-13 * b.abs().max(1.0), "{back:?}");
        }
        // Scale and offset: q = sign · scale · c + offset, and back.
        let map = JointMap::new(&raw("scale = { q2 = 2.0 }\noffset = { q2 = -90 }\nsign = { q1 = -1 }"), &names(2)).unwrap();
        let mut q = [0.0; 2];
        map.to_model(&[3.0, 50.0], &mut q);
        assert_eq!(q, [-3.0, 10.0]);
        let mut back = [0.0; 2];
        map.to_columns(&q, &mut back);
        assert_eq!(back, [3.0, 50.0]);
    }

    #[test]
    fn bad_entries_are_errors_naming_the_field() {
        let cases = [
            ("sign = { q7 = -1 }", "[measurements.joint_map] sign", "no model joint named 'q7'"),
            ("sign = { q1 = 2 }", "[measurements.joint_map] sign", "q1 = 2: needs +1 or -1"),
            ("scale = { q2 = 0 }", "[measurements.joint_map] scale", "q2 = 0: needs a finite, non-zero"),
            ("scale = { q2 = nan }", "[measurements.joint_map] scale", "q2 = NaN"),
            ("offset = { q1 = inf }", "[measurements.joint_map] offset", "q1 = inf: needs a finite value"),
            ("coupling = [[1, 0], [0, 1]]", "[measurements.joint_map] coupling", "needs 3 rows of 3 entries"),
            ("coupling = [[1, 0, 0], [0, 1], [0, 0, 1]]", "[measurements.joint_map] coupling", "[3, 2, 3]"),
            ("coupling = [[1, 0, 0], [0, 1, 1], [0, 2, 2]]", "[measurements.joint_map] coupling", "singular"),
            ("coupling = [[1, 0, 0], [0, nan, 1], [0, 0, 1]]", "[measurements.joint_map] coupling", "row 2 entry 2: NaN"),
        ];
        for (text, field, needle) in cases {
            let (f, message) = JointMap::new(&raw(text), &names(3)).unwrap_err();
            assert_eq!(f, field, "{text}");
            assert!(message.contains(needle), "{text}: {message}");
        }
    }

    /// Issue 39 case 1: `scale = { q1 = 1e-320 }` passed (only the coupling's condition was tested)
    /// and `cbd compensate` wrote −inf. The whole map is checked now, and its inverse on the limits.
    #[test]
    fn the_whole_map_and_its_inverse_on_the_limits_are_checked() {
        let degrees = vec![[-360.0, 360.0]; 3];
        let columns: Vec<String> = ["J1", "J2", "J3"].map(String::from).to_vec();
        let check = |text: &str, limits: &[[f64; 2]]| JointMap::new(&raw(text), &names(3)).unwrap().check_range(limits, &columns);
        for (text, needle) in [
            ("scale = { q1 = 1e-320 }", "condition number inf"),
            ("scale = { q1 = 1e-13 }", "condition number 1e13"),
            ("scale = { q1 = 1e-90, q2 = 1e-90, q3 = 1e-90 }", "takes commands within the joint limits to J1 values of ±3.6e92"),
            ("scale = { q1 = 1e99, q2 = 1e99, q3 = 1e99 }", "maps the joint limits to model joint 1 values of ±3.6e101"),
            ("scale = { q1 = 1e-7, q2 = 1e7 }\ncoupling = [[1, 0, 0], [0, 1, 0], [1, 0, 1]]", "condition number 1.4142e14"),
        ] {
            let (field, message) = check(text, &degrees).unwrap_err();
            assert_eq!(field, "[measurements.joint_map]", "{text}");
            assert!(message.contains(needle), "{text}: {message}");
        }
        // Real maps pass: FANUC's coupling, a gear ratio, a prismatic joint without limits.
        JointMap::new(&raw(FANUC), &names(6)).unwrap().check_range(&[[-180.0, 180.0]; 6], &names(6)).unwrap();
        check("scale = { q2 = 0.01 }\noffset = { q2 = -90 }", &degrees).unwrap();
        check("coupling = [[1, 0, 0], [0, 1, 0], [0, 1, 1]]", &[[-360.0, 360.0], [-360.0, 360.0], [f64::NEG_INFINITY, f64::INFINITY]])
            .unwrap();
    }
}
