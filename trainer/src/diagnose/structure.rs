//! Tests for structure left in residuals r_i = y_i − k(q_i): nested F-tests of an
//! intercept-per-coordinate model against regressors of three families —
//!   joint harmonics:  cos/sin(h q_j), h = 1..H, per task coordinate and through the joint's
//!                     Jacobian (J_j cos(h q_j), J_j sin(h q_j));
//!   gravity torque:   τ_j(q) per coordinate and J_j τ_j(q) (compliance of joint j);
//!   joint shape:      J_j · 1[q_j in bin b], b = 1..B over the data's range of q_j: any deflection
//!                     of joint j that is a function of q_j alone (a dead zone, a step), whether
//!                     the library has its shape or not;
//!   task position:    a quadratic polynomial of the (normalised) predicted position per coordinate.
//! A test is significant when its p-value is below α / (number of tests) (Bonferroni) and its
//! regressors explain at least `min_share` of the residual sum of squares.

use super::f_test::{nested_f_test, FTest};
use super::kinematics;
use crate::data::Measurements;
use cbd_protocol::NominalModel;
use faer::Mat;

/// Settings of the tests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StructureOptions {
    pub harmonics: u8,
    /// Family-wise significance level.
    pub alpha: f64,
    /// Smallest share of the residual sum of squares worth reporting.
    pub min_share: f64,
    /// Bins of the joint-shape test.
    pub shape_bins: usize,
}

impl Default for StructureOptions {
    fn default() -> Self {
        StructureOptions { harmonics: 3, alpha: 0.01, min_share: 0.01, shape_bins: 16 }
    }
}

/// One test's outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct StructureTest {
    /// e.g. `joint harmonics q2`, `gravity torque q3`, `task position`.
    pub name: String,
    pub family: &'static str,
    pub joint: Option<usize>,
    pub test: FTest,
    pub significant: bool,
}

/// Runs every test on residual `r` (rows × m, row-major) of `model` on `data`.
pub fn structure_tests(model: &NominalModel, data: &Measurements, r: &[f64], options: &StructureOptions) -> Vec<StructureTest> {
    let (n, m, rows) = (model.n_joints(), data.task_dim, data.len());
    let obs = rows * m;
    let null = Mat::from_fn(obs, m, |i, c| if i % m == c { 1.0 } else { 0.0 });
    let rigid = kinematics::rigid(model);
    let jac: Vec<Vec<f64>> = (0..rows)
        .map(|i| kinematics::deflected_rigid_jacobian(model, &rigid, data.joints(i), kinematics::point_of_row(model, i)))
        .collect();
    let tau: Vec<Vec<f64>> = (0..rows).map(|i| kinematics::gravity_torques(model, data.joints(i))).collect();
    // Regressor f(i) per coordinate (m columns) plus f(i)·J_j(q_i) (one column).
    let per_joint = |j: usize, f: &dyn Fn(usize) -> f64, cols: &mut Vec<Vec<f64>>| {
        for c in 0..m {
            cols.push((0..obs).map(|o| if o % m == c { f(o / m) } else { 0.0 }).collect());
        }
        cols.push((0..obs).map(|o| f(o / m) * jac[o / m][(o % m) * n + j]).collect());
    };
    let to_mat = |cols: &[Vec<f64>]| Mat::from_fn(obs, cols.len(), |i, k| cols[k][i]);
    let mut out = Vec::new();
    for j in 0..n {
        if model.is_revolute(j) {
            let mut cols = Vec::new();
            for h in 1..=options.harmonics as usize {
                let hf = h as f64;
                per_joint(j, &|i| (hf * data.joints(i)[j]).cos(), &mut cols);
                per_joint(j, &|i| (hf * data.joints(i)[j]).sin(), &mut cols);
            }
            out.push(("joint harmonics", Some(j), nested_f_test(&null, &to_mat(&cols), r)));
        }
        let mut cols = Vec::new();
        per_joint(j, &|i| tau[i][j], &mut cols);
        out.push(("gravity torque", Some(j), nested_f_test(&null, &to_mat(&cols), r)));
        // Through the joint only: a deflection of joint j, piecewise constant in q_j.
        let bins = options.shape_bins.max(2);
        let (lo, hi) = (0..rows).map(|i| data.joints(i)[j]).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
        let bin = |i: usize| (((data.joints(i)[j] - lo) / (hi - lo).max(f64::MIN_POSITIVE) * bins as f64) as usize).min(bins - 1);
        let mut cols: Vec<Vec<f64>> = Vec::new();
        for b in 0..bins {
            cols.push((0..obs).map(|o| if bin(o / m) == b { jac[o / m][(o % m) * n + j] } else { 0.0 }).collect());
        }
        out.push(("joint shape", Some(j), nested_f_test(&null, &to_mat(&cols), r)));
    }
    // Task position, normalised: (k − mean) / rms.
    let predicted: Vec<f64> =
        (0..rows).flat_map(|i| kinematics::position(model, data.joints(i), m, kinematics::point_of_row(model, i))).collect();
    let norm = Measurements {
        n_joints: n,
        task_dim: m,
        points_per_pose: data.points_per_pose,
        joints: data.joints.clone(),
        positions: predicted.clone(),
        order: data.order,
    }
    .normalisation();
    let x = |i: usize, d: usize| norm.position_to_internal(d, predicted[m * i + d]);
    let mut monomials: Vec<Box<dyn Fn(usize) -> f64>> = Vec::new();
    for d in 0..m {
        monomials.push(Box::new(move |i| x(i, d)));
        for e in d..m {
            monomials.push(Box::new(move |i| x(i, d) * x(i, e)));
        }
    }
    let mut cols = Vec::new();
    for f in &monomials {
        for c in 0..m {
            cols.push((0..obs).map(|o| if o % m == c { f(o / m) } else { 0.0 }).collect::<Vec<f64>>());
        }
    }
    out.push(("task position", None, nested_f_test(&null, &to_mat(&cols), r)));
    let count = out.len() as f64;
    out.into_iter()
        .map(|(family, joint, test)| StructureTest {
            name: match joint {
                Some(j) => format!("{family} q{}", j + 1),
                None => family.to_string(),
            },
            family,
            joint,
            significant: test.p_value < options.alpha / count && test.explained >= options.min_share,
            test,
        })
        .collect()
}

/// The significant tests, strongest first.
pub fn significant(tests: &[StructureTest]) -> Vec<&StructureTest> {
    let mut s: Vec<&StructureTest> = tests.iter().filter(|t| t.significant).collect();
    s.sort_by(|a, b| b.test.explained.total_cmp(&a.test.explained));
    s
}
