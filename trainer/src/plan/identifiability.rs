//! The geometric group: the DH calibration's parameter Jacobian, unit-scaled, at every tracked
//! point — the basis functions the planner's Gaussian process carries besides CbD's kernel — the
//! information of the chosen poses and whether the group is identified yet (docs/DESIGN.md §13).

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};

/// Below this smallest/largest eigenvalue ratio of the unit-scaled information the group is rank
/// deficient (the DH fit's own rank tolerance, `DhCalibrationOptions::rank_tolerance`, is 1e-14 on
/// converged data; before the data are in, a looser test).
const RANK_RATIO: f64 = 1e-10;

/// The information M = Σ_s J_sᵀ J_s of the chosen poses on the identifiable parameters, each
/// column scaled to unit RMS over the candidates.
#[derive(Clone)]
pub struct Identifiability {
    m: usize,
    p: usize,
    /// The identifiable columns of the DH Jacobian and their scales.
    columns: Vec<usize>,
    scale: Vec<f64>,
    /// Per point: its m × p scaled Jacobian rows, row-major.
    rows: Vec<f64>,
    info: Mat<f64>,
}

impl Identifiability {
    /// `jac`: m rows per point, the candidates first (`0..candidates`, which set the column scales),
    /// all DH parameters; `identifiable`: the columns kept.
    pub fn new(jac: &Mat<f64>, m: usize, candidates: usize, identifiable: &[usize]) -> Self {
        let p = identifiable.len();
        let total = jac.nrows() / m;
        let scale: Vec<f64> = identifiable
            .iter()
            .map(|&k| {
                let s = ((0..m * candidates).map(|i| jac[(i, k)] * jac[(i, k)]).sum::<f64>() / candidates.max(1) as f64).sqrt();
                if s > 0.0 {
                    s
                } else {
                    1.0
                }
            })
            .collect();
        let mut rows = vec![0.0; total * m * p];
        for i in 0..total * m {
            for (a, &k) in identifiable.iter().enumerate() {
                rows[i * p + a] = jac[(i, k)] / scale[a];
            }
        }
        Identifiability { m, p, columns: identifiable.to_vec(), scale, rows, info: Mat::zeros(p, p) }
    }

    /// The m × p scaled rows of point `point` of another DH Jacobian `jac` (all parameters, m rows
    /// per point): the same columns and scales as the tracked points'.
    pub fn scaled_rows(&self, jac: &Mat<f64>, point: usize) -> Vec<f64> {
        let (m, p) = (self.m, self.p);
        (0..m * p).map(|k| jac[(point * m + k / p, self.columns[k % p])] / self.scale[k % p]).collect()
    }

    /// Number of identifiable parameters.
    pub fn parameters(&self) -> usize {
        self.p
    }

    /// The m × p scaled Jacobian rows of `point` (row-major).
    pub fn block(&self, point: usize) -> &[f64] {
        &self.rows[point * self.m * self.p..(point + 1) * self.m * self.p]
    }

    /// Adds `point` to the chosen poses: M += JᵀJ.
    pub fn add(&mut self, point: usize) {
        let (m, p) = (self.m, self.p);
        let j = Mat::from_fn(m, p, |r, a| self.rows[(point * m + r) * p + a]);
        self.info += j.transpose() * &j;
    }

    /// Whether the information has full rank on the identifiable parameters.
    pub fn full_rank(&self) -> bool {
        full_rank(&self.info)
    }

    /// The factor L (p × p, row-major, LLᵀ = Σ) of the parameters' prior covariance
    /// Σ = (I/s² + M_extra/σ²)⁻¹: broad (s) before any pose, narrowed by the information `extra`
    /// of poses the Gaussian process is not conditioned on (their rows, as [`Self::block`] indexes
    /// them). The least-squares fit dh+cbd runs is the limit s → ∞.
    pub fn prior_factor(&self, s2: f64, sigma2: f64, extra: &[usize]) -> Vec<f64> {
        let p = self.p;
        let mut a = Mat::from_fn(p, p, |i, j| if i == j { 1.0 / s2 } else { 0.0 });
        for &point in extra {
            let j = Mat::from_fn(self.m, p, |r, c| self.rows[(point * self.m + r) * p + c] / sigma2.sqrt());
            a += j.transpose() * &j;
        }
        let cov = match a.llt(Side::Lower) {
            Ok(l) => l.solve(Mat::<f64>::identity(p, p)),
            Err(_) => Mat::from_fn(p, p, |i, j| if i == j { s2 } else { 0.0 }),
        };
        let cov = Mat::from_fn(p, p, |i, j| 0.5 * (cov[(i, j)] + cov[(j, i)]));
        match cov.llt(Side::Lower) {
            Ok(l) => (0..p * p).map(|k| if k % p <= k / p { l.L()[(k / p, k % p)] } else { 0.0 }).collect(),
            Err(_) => (0..p * p).map(|k| if k / p == k % p { s2.sqrt() } else { 0.0 }).collect(),
        }
    }
}

/// Whether measured poses (`measured`, model joints, row-major) identify the geometric group with
/// coordinates to spare: the group's identifiable parameters as a generic set of poses (`generic`,
/// e.g. uniform within the limits) shows them, the measured poses' information of full rank on
/// them, and at least twice as many measured coordinates as parameters — so that what a DH fit
/// leaves is a residual to estimate CbD's hyperparameters (σ above all) on, not an interpolation
/// (5 poses of the six-joint arm left 1e-9 mm, and the plan predicted it). `Err` gives the
/// group's size and the poses it needs at least.
pub fn measured_identify_group(nominal: &cbd_protocol::NominalModel, generic: &[f64], measured: &[f64]) -> Result<(), GroupNotIdentified> {
    let (n, m) = (nominal.n_joints().max(1), nominal.task_dim());
    let mut all = generic.to_vec();
    all.extend_from_slice(measured);
    let Some((jac, identifiable)) = crate::parametric::identification_jacobian(nominal, &all) else { return Ok(()) };
    let count = generic.len() / n;
    let mut group = Identifiability::new(&jac, m, count, &identifiable);
    let poses = measured.len() / n;
    for i in 0..poses {
        group.add(count + i);
    }
    let p = group.parameters();
    let needed = (2 * p).div_ceil(m.max(1));
    let identified = group.full_rank();
    if identified && poses >= needed {
        Ok(())
    } else {
        Err(GroupNotIdentified { poses, parameters: p, needed, identified, identifying: p.div_ceil(m.max(1)) })
    }
}

/// Measured poses that do not identify the geometric group ([`measured_identify_group`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GroupNotIdentified {
    pub poses: usize,
    pub parameters: usize,
    /// Poses in general position needed at least (twice the parameters in coordinates).
    pub needed: usize,
    /// Whether the poses identify the group (their information of full rank: the criterion the
    /// plan's "before the geometric group is identified" counts by), only without coordinates to spare.
    pub identified: bool,
    /// Poses in general position that can identify the group at the least (its parameters in coordinates).
    pub identifying: usize,
}

impl GroupNotIdentified {
    /// Why `data_name`'s poses give CbD's evidence nothing to stand on, in the plan's own terms of
    /// "identified" (the information's rank, as the planned poses are counted), e.g. "12 poses
    /// identify the geometric group (23 parameters) but leave no coordinates to spare: …".
    pub fn describe(&self) -> String {
        let why = match self.identified {
            true => format!(
                "{} poses identify the geometric group ({} parameters) but leave too few coordinates beyond it for CbD's evidence (at least {} poses, twice the parameters in coordinates)",
                self.poses, self.parameters, self.needed
            ),
            false => format!(
                "{} poses do not identify the geometric group ({} parameters; at least {} poses in general position, and {} for CbD's evidence: twice the parameters in coordinates)",
                self.poses, self.parameters, self.identifying, self.needed
            ),
        };
        format!("{why}: the predictions rest on the stated prior (--noise, --prior-error), not on CbD's evidence on these poses")
    }
}

fn full_rank(info: &Mat<f64>) -> bool {
    if info.nrows() == 0 {
        return true;
    }
    match info.self_adjoint_eigenvalues(Side::Lower) {
        Ok(ev) => {
            let max = ev.iter().cloned().fold(0.0, f64::max);
            let min = ev.iter().cloned().fold(f64::INFINITY, f64::min);
            max > 0.0 && min > RANK_RATIO * max
        }
        Err(_) => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn poses(count: usize, seed: f64) -> Vec<f64> {
        (0..count * 6).map(|k| ((k as f64 + seed) * 0.731).sin() * 2.5).collect()
    }

    /// One meaning of "identified" (the information's rank, as the plan counts its poses): poses
    /// that identify the group but leave no coordinates to spare are said to identify it.
    #[test]
    fn measured_poses_are_identified_by_the_plans_own_criterion() {
        let nominal = cbd_protocol::NominalModel::DhChain(cbd_protocol::ur5::chain());
        let generic = poses(200, 0.5);
        let few = measured_identify_group(&nominal, &generic, &poses(3, 7.0)).unwrap_err();
        assert!(!few.identified && few.identifying == few.parameters.div_ceil(3), "{few:?}");
        assert!(few.describe().starts_with("3 poses do not identify the geometric group"), "{}", few.describe());
        let some = measured_identify_group(&nominal, &generic, &poses(12, 7.0)).unwrap_err();
        assert!(some.identified && some.poses < some.needed, "{some:?}");
        let text = some.describe();
        assert!(text.starts_with("12 poses identify the geometric group") && !text.contains("do not identify"), "{text}");
        assert!(measured_identify_group(&nominal, &generic, &poses(40, 7.0)).is_ok());
    }
}
