//! `cbd check --update` (issue 50 item 4): the named change written into the blob's chain, the
//! fields kept. The named groups' parameters are refitted on the fresh poses by Gauss–Newton on
//! the blob itself — each step evaluates the changed blob at the fresh rows and solves the check's
//! own generalised least squares (C, and the registered frame's tangent as a nuisance) for the
//! groups' columns at the changed chain (`name::candidate_columns`), written into the chain along
//! `name::directions` (`diagnose::library::apply`). The new blob records its parent's SHA-256
//! (format 9, `cbd_protocol::Provenance::parent`).
//!
//! Its error is reported on fresh rows held out of the update: the poses cut into contiguous
//! blocks (in measurement order, so no held-out pose leans on a neighbour in time), each block
//! predicted by the update fitted on the others; the blob written is fitted on every pose.

use super::covariance::spd_inverse;
use super::name::{candidate_columns, directions, gls, stack, tangent_columns, Candidate};
use crate::data::Measurements;
use crate::diagnose::library::{apply, Param};
use cbd_protocol::{Model, NominalModel};
use faer::Mat;
use sha2::{Digest, Sha256};

/// Gauss–Newton steps: the change is small and the model nearly linear in it (the second step
/// moves the parameters by a few per cent of the first, the third by less than rounding).
const STEPS: usize = 3;
/// Held-out blocks at most (fewer with fewer poses: one pose per block).
const BLOCKS: usize = 10;

/// What `--update` wrote and measured.
#[derive(Debug, Clone)]
pub struct Updated {
    /// The new blob (its parent's hash recorded).
    pub blob: Vec<u8>,
    /// SHA-256 of the parent blob, hex.
    pub parent: String,
    /// Each group refitted and its parameters' change (the sum of the steps; a shift's three).
    pub changes: Vec<(Candidate, Vec<f64>)>,
    /// Mean error per row (the data's length unit) at the fresh rows, the registered frame
    /// refitted where there is one: the parent blob, and each block by the update fitted without it.
    pub before: f64,
    pub held_out: f64,
    /// The written blob's mean error on every fresh row (in sample).
    pub in_sample: f64,
    /// How many held-out blocks.
    pub blocks: usize,
}

/// Why no update was written.
#[derive(Debug, Clone, PartialEq)]
pub enum UpdateError {
    /// No change was named: nothing to refit (recalibrate instead).
    NothingNamed,
    /// The library's changes are a DH chain's.
    NotDhChain,
    /// The fit of the groups is not defined on the fresh rows (C, or FᵀC⁻¹F, singular).
    NotDefined,
    /// The changed blob did not load or evaluate (a change too large for the model).
    Evaluation(String),
}

impl std::fmt::Display for UpdateError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            UpdateError::NothingNamed => write!(f, "no change was named, so there is nothing to update: calibrate again"),
            UpdateError::NotDhChain => write!(f, "the update changes a DH chain measured in 3-D"),
            UpdateError::NotDefined => write!(f, "the named change cannot be refitted on these rows (its fit is singular)"),
            UpdateError::Evaluation(e) => write!(f, "the updated blob does not evaluate: {e}"),
        }
    }
}

/// Refits `groups` (the named change) on the fresh rows `fresh` with `measured` positions (the
/// data's length unit, in the blob's frame when registered), the check's covariance `c` and the
/// registered frame's `tangent`; `parent` is the blob's bytes (its hash is recorded). `frame`: the
/// import the fresh rows were read through (the check's model file's), which the new blob records —
/// not its parent's record, which a blob older than format 9 does not have.
#[allow(clippy::too_many_arguments)]
pub fn update(
    model: &Model<'_>,
    parent: &[u8],
    frame: Option<cbd_protocol::ImportFrame>,
    fresh: &Measurements,
    measured: &[f64],
    c: &Mat<f64>,
    tangent: Option<&Mat<f64>>,
    groups: &[Candidate],
) -> Result<Updated, UpdateError> {
    if groups.is_empty() {
        return Err(UpdateError::NothingNamed);
    }
    if !matches!(model.nominal, NominalModel::DhChain(_)) || fresh.task_dim != 3 {
        return Err(UpdateError::NotDhChain);
    }
    let rows = FreshRows { model, fresh, measured, c, tangent };
    let poses = fresh.len() / fresh.points_per_pose.max(1);
    let everything: Vec<usize> = (0..poses).collect();
    let mean = |e: Vec<f64>| e.iter().sum::<f64>() / e.len().max(1) as f64;
    let all = rows.refit(groups, &everything)?;
    let before = mean(rows.pose_errors(&model.nominal, &everything, &everything)?);
    // Held out: contiguous blocks of poses, each predicted by the update fitted on the others.
    let blocks = poses.min(BLOCKS);
    let mut errors = vec![0.0; poses];
    for b in 0..blocks {
        let held: Vec<usize> = (b * poses / blocks..(b + 1) * poses / blocks).collect();
        let kept: Vec<usize> = (0..poses).filter(|p| !held.contains(p)).collect();
        let fold = rows.refit(groups, &kept)?;
        for (p, e) in held.iter().zip(rows.pose_errors(&fold.nominal, &kept, &held)?) {
            errors[*p] = e;
        }
    }
    let held_out = mean(errors);
    let in_sample = mean(rows.pose_errors(&all.nominal, &everything, &everything)?);
    let parent_hash: [u8; 32] = Sha256::digest(parent).into();
    let mut updated = model.clone();
    updated.nominal = all.nominal;
    updated.provenance = Some(cbd_protocol::Provenance { import_frame: frame, parent: Some(parent_hash) });
    let blob = cbd_protocol::encode_to_vec(&updated).map_err(|e| UpdateError::Evaluation(e.to_string()))?;
    let parent = parent_hash.iter().map(|b| format!("{b:02x}")).collect();
    Ok(Updated { blob, parent, changes: all.changes, before, held_out, in_sample, blocks })
}

/// The groups refitted on some poses.
struct Refit {
    nominal: NominalModel,
    changes: Vec<(Candidate, Vec<f64>)>,
}

/// The fresh rows and what the check found at them: every fit and error below reads these.
struct FreshRows<'a, 'b> {
    model: &'a Model<'b>,
    fresh: &'a Measurements,
    measured: &'a [f64],
    c: &'a Mat<f64>,
    tangent: Option<&'a Mat<f64>>,
}

impl FreshRows<'_, '_> {
    /// `groups` refitted on `poses` by Gauss–Newton on the blob (the frame's tangent a nuisance).
    fn refit(&self, groups: &[Candidate], poses: &[usize]) -> Result<Refit, UpdateError> {
        let mut nominal = self.model.nominal.clone();
        let mut changes: Vec<(Candidate, Vec<f64>)> = groups.iter().map(|g| (*g, Vec::new())).collect();
        let fixed = self.tangent.map_or(0, |t| t.ncols());
        for _ in 0..STEPS {
            let at = with_nominal(self.model, &nominal);
            let r = residual(&at, self.fresh, self.measured)?;
            let columns: Vec<Vec<f64>> = candidate_columns(&at, self.fresh, groups).into_iter().flatten().collect();
            let beta = self.gls_on(poses, &r, &stack(&tangent_columns(self.tangent), columns.iter()))?;
            let NominalModel::DhChain(chain) = &nominal else { return Err(UpdateError::NotDhChain) };
            let (mut params, mut values): (Vec<Param>, Vec<f64>) = (Vec::new(), Vec::new());
            let mut k = fixed;
            for (group, total) in changes.iter_mut() {
                let dirs = directions(chain, *group);
                total.resize(dirs.len(), 0.0);
                for (column, terms) in dirs.iter().enumerate() {
                    total[column] += beta[k];
                    for (p, coefficient) in terms {
                        params.push(*p);
                        values.push(coefficient * beta[k]);
                    }
                    k += 1;
                }
            }
            nominal = apply(&nominal, &params, &values).map_err(|e| UpdateError::Evaluation(e.to_string()))?;
        }
        Ok(Refit { nominal, changes })
    }

    /// Each of the `judged` poses' mean error per row (the data's length unit) of the blob with
    /// `nominal`, after the frame's tangent fitted by GLS on the `fitted` poses.
    fn pose_errors(&self, nominal: &NominalModel, fitted: &[usize], judged: &[usize]) -> Result<Vec<f64>, UpdateError> {
        let at = with_nominal(self.model, nominal);
        let mut r = residual(&at, self.fresh, self.measured)?;
        if self.tangent.is_some() {
            let f = tangent_columns(self.tangent);
            let beta = self.gls_on(fitted, &r, &f)?;
            for (i, v) in r.iter_mut().enumerate() {
                *v -= f.iter().zip(&beta).map(|(col, b)| col[i] * b).sum::<f64>();
            }
        }
        let (m, per_pose) = (self.fresh.task_dim, self.fresh.points_per_pose.max(1));
        let norm = &self.model.normalisation;
        let pose = |p: usize| {
            let rows = p * per_pose..(p + 1) * per_pose;
            rows.map(|row| norm.length_to_user((0..m).map(|a| r[row * m + a].powi(2)).sum::<f64>().sqrt())).sum::<f64>() / per_pose as f64
        };
        Ok(judged.iter().map(|&p| pose(p)).collect())
    }

    /// The GLS estimate on the coordinates of `poses` (C restricted to them) of r against `f`.
    fn gls_on(&self, poses: &[usize], r: &[f64], f: &[Vec<f64>]) -> Result<Vec<f64>, UpdateError> {
        let block = self.fresh.points_per_pose.max(1) * self.fresh.task_dim;
        let rows: Vec<usize> = poses.iter().flat_map(|p| p * block..(p + 1) * block).collect();
        let c = Mat::from_fn(rows.len(), rows.len(), |i, j| self.c[(rows[i], rows[j])]);
        let cinv = spd_inverse(&c).ok_or(UpdateError::NotDefined)?;
        let f_rows: Vec<Vec<f64>> = f.iter().map(|col| rows.iter().map(|&i| col[i]).collect()).collect();
        let r_rows: Vec<f64> = rows.iter().map(|&i| r[i]).collect();
        gls(&cinv, &r_rows, &f_rows).map(|(beta, _)| beta).ok_or(UpdateError::NotDefined)
    }
}

/// The model with its chain replaced.
fn with_nominal<'a>(model: &Model<'a>, nominal: &NominalModel) -> Model<'a> {
    let mut at = model.clone();
    at.nominal = nominal.clone();
    at
}

/// measured − the blob's prediction at every fresh row, internal units (the check's residual).
fn residual(model: &Model<'_>, fresh: &Measurements, measured: &[f64]) -> Result<Vec<f64>, UpdateError> {
    let mut storage = vec![0.0; cbd_runtime::storage_len_for(model)];
    let mut cal = cbd_runtime::Calibrator::from_model(model.clone(), &mut storage).map_err(|e| UpdateError::Evaluation(e.to_string()))?;
    let (m, per_pose) = (fresh.task_dim, fresh.points_per_pose.max(1));
    let norm = &model.normalisation;
    let mut r = Vec::with_capacity(fresh.len() * m);
    for i in 0..fresh.len() {
        let e = cal.evaluate_point(fresh.joints(i), i % per_pose).map_err(|e| UpdateError::Evaluation(e.to_string()))?;
        for (a, p) in e.position().iter().enumerate() {
            r.push(norm.length_to_internal(measured[i * m + a] - p));
        }
    }
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A joint zero planted on the UR5 chain (the blob's fields zero: it evaluates as its chain):
    /// the update refits it within 4 standard errors of the truth, the held-out error drops from
    /// the change's size to the noise's, and the new blob names its parent.
    #[test]
    fn a_named_joint_zero_is_refitted_into_the_chain_and_the_blob_names_its_parent() {
        let chain = crate::simulate::six_joint::ur5_nominal();
        let nominal = NominalModel::DhChain(chain.clone());
        let q: Vec<f64> = (0..6 * 20).map(|i| ((i as f64) * 0.537).sin() * 2.8).collect();
        let mut model = crate::evidence::model_for_tests(nominal.clone(), &q[..6 * 5]);
        model.normalisation = cbd_protocol::Normalisation { task_offset: [0.0; 3], task_scale: 500.0 };
        let parent = cbd_protocol::encode_to_vec(&model).unwrap();
        let mut fresh = Measurements::new(6, 3);
        fresh.joints = q.clone();
        let mut changed = chain.clone();
        let truth = 2e-4;
        changed.joints[1].theta_offset += truth;
        let sigma = 0.02;
        let noise = |i: usize| sigma * (((i as f64) * 12.9898).sin() * 43758.5453).fract() * 1.7;
        let measured: Vec<f64> =
            crate::nominal::positions(&NominalModel::DhChain(changed), &q, 3).iter().enumerate().map(|(i, p)| p + noise(i)).collect();
        fresh.positions = measured.clone();
        let s = sigma / 500.0;
        let c = Mat::from_fn(measured.len(), measured.len(), |i, j| if i == j { s * s } else { 0.0 });
        let frame = cbd_protocol::ImportFrame { joints: Some(42), positions: None };
        let u = update(&model, &parent, Some(frame), &fresh, &measured, &c, None, &[Candidate::JointZero(1)]).unwrap();
        let new = cbd_protocol::decode(&u.blob).unwrap();
        let NominalModel::DhChain(fitted) = &new.nominal else { panic!("a DH chain") };
        // se of one joint zero from 60 coordinates at 0.02 mm on a ~0.5 m lever: ~1e-5 rad.
        let moved = fitted.joints[1].theta_offset - chain.joints[1].theta_offset;
        assert!((moved - truth).abs() < 4e-5, "refitted {moved}, planted {truth}");
        assert_eq!(u.changes.len(), 1);
        assert!((u.changes[0].1[0] - moved).abs() < 1e-12, "{:?} vs {moved}", u.changes);
        // Only that parameter moved.
        for (j, (a, b)) in fitted.joints.iter().zip(&chain.joints).enumerate() {
            assert_eq!((a.a, a.alpha, a.d), (b.a, b.alpha, b.d), "joint {j}");
        }
        assert!(u.before > 0.05, "the change is seen: {}", u.before);
        assert!(u.held_out < 0.05 && u.in_sample <= u.held_out, "{} → {} (in sample {})", u.before, u.held_out, u.in_sample);
        let expected: [u8; 32] = Sha256::digest(&parent).into();
        // The parent and the import the fresh rows were read through are recorded.
        assert_eq!(new.provenance, Some(cbd_protocol::Provenance { import_frame: Some(frame), parent: Some(expected) }));
        assert_eq!(u.parent.len(), 64);
        // Nothing named: nothing to update.
        assert_eq!(update(&model, &parent, None, &fresh, &measured, &c, None, &[]).unwrap_err(), UpdateError::NothingNamed);
    }
}
