//! Naming the change (issue 50 item 3): when a check says "changed", which physical change of the
//! arm explains the fresh residual? The candidates are small changes of the blob's own chain —
//! each joint's zero, each link's length and twist, each encoder's scale (the effects library's
//! `encoder_scale`), the base and tool translations, a uniform length scale — linearised at the
//! blob's chain (`diagnose::library::jacobian`; the blob's flows are close to the identity, so the
//! prediction moves as the chain does). Each is named by its `cbd simulate --effect` spelling
//! (`joint_zero:joint=2`).
//!
//! The fit is the check's own generalised least squares: the residual r ~ N(F β, C) with C the
//! check's covariance (`covariance::fresh_covariance`) and F the chosen candidates' columns (and
//! the registered frame's tangent, always). Candidates are chosen forward, one group at a time, by
//! out-of-sample evidence: the leave-one-pose-out log predictive density of r, in closed form for
//! a Gaussian process with a linear mean re-estimated without the pose (Dubrule 1983, "Cross
//! validation of kriging in a unique neighborhood", Math. Geology 15: with P = C⁻¹ −
//! C⁻¹F(FᵀC⁻¹F)⁻¹FᵀC⁻¹, pose i's prediction error is P_ii⁻¹ (P r)_i with covariance P_ii⁻¹). A
//! group is kept when it raises that density by more than [`MARGIN`] nats; what is left is the
//! check's statistic on the part of r the named change does not explain (`statistic::mahalanobis`
//! with F as the tangent), on dof − rank F.

use super::covariance::spd_inverse as inverse;
use super::statistic::{mahalanobis, Statistic};
use crate::data::Measurements;
use crate::diagnose::library::{jacobian, Param};
use crate::effects::Site;
use cbd_protocol::{Model, NominalModel};
use faer::Mat;

/// The gain of the leave-one-pose-out log predictive density (nats) a group must bring. One
/// parameter fitting noise alone gains about (z² − 1)/2, so 4 nats is z² ≈ 9 (p ≈ 0.003 each; of
/// the ~30 candidates one is named on noise in a few % of checks); a change the check detects
/// brings tens of nats.
pub const MARGIN: f64 = 4.0;
/// At most this many groups are named.
pub const MAX_GROUPS: usize = 3;

/// One candidate change of the blob's chain.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Candidate {
    /// θ_offset of joint J (0-based): `joint_zero:joint=J+1`.
    JointZero(usize),
    /// DH a of link L: `link_length:link=L+1`.
    LinkLength(usize),
    /// DH α of link L: `link_twist:link=L+1`.
    LinkTwist(usize),
    /// δ = scale · q_J: `encoder_scale:joint=J+1`.
    EncoderScale(usize),
    /// The base translation: `base_shift`.
    BaseShift,
    /// The tool translation in the flange frame: `tool_shift`.
    ToolShift,
    /// Every length × (1 + s): `length_scale`.
    LengthScale,
}

impl Candidate {
    /// The `--effect` spelling without its size: `joint_zero:joint=2`, `base_shift`.
    pub fn spelling(&self) -> String {
        match *self {
            Candidate::JointZero(j) => format!("joint_zero:joint={}", j + 1),
            Candidate::LinkLength(l) => format!("link_length:link={}", l + 1),
            Candidate::LinkTwist(l) => format!("link_twist:link={}", l + 1),
            Candidate::EncoderScale(j) => format!("encoder_scale:joint={}", j + 1),
            Candidate::BaseShift => "base_shift".into(),
            Candidate::ToolShift => "tool_shift".into(),
            Candidate::LengthScale => "length_scale".into(),
        }
    }

    /// How many parameters (columns) it has.
    fn width(&self) -> usize {
        match self {
            Candidate::BaseShift | Candidate::ToolShift => 3,
            _ => 1,
        }
    }
}

/// Every candidate of an n-joint chain; without `base_shift` when the frame is registered (the
/// frame's translation is the base's).
pub fn candidates(n: usize, register: bool) -> Vec<Candidate> {
    let mut out: Vec<Candidate> = (0..n).map(Candidate::JointZero).collect();
    out.extend((0..n).map(Candidate::LinkLength));
    out.extend((0..n).map(Candidate::LinkTwist));
    out.extend((0..n).map(Candidate::EncoderScale));
    if !register {
        out.push(Candidate::BaseShift);
    }
    out.push(Candidate::ToolShift);
    out.push(Candidate::LengthScale);
    out
}

/// One named change: its spelling, size (the parameter; for a shift the length of the vector) and
/// standard error, its unit and (shifts) its components with theirs.
#[derive(Debug, Clone, PartialEq)]
pub struct Change {
    pub candidate: Candidate,
    pub size: f64,
    pub se: f64,
    /// `mm` (the data's length unit), `rad`, or `` (a ratio).
    pub unit: String,
    /// (name, value, se): `dx`, `dy`, `dz` of a shift; empty otherwise.
    pub components: Vec<(&'static str, f64, f64)>,
}

impl Change {
    /// The `--effect` spec that plants this change in `cbd simulate`: `joint_zero:joint=2,offset=1.02e-4`.
    pub fn plant(&self) -> String {
        let s = self.candidate.spelling();
        match self.candidate {
            Candidate::JointZero(_) => format!("{s},offset={:.4e}", self.size),
            Candidate::LinkLength(_) | Candidate::LinkTwist(_) => format!("{s},delta={:.4e}", self.size),
            Candidate::EncoderScale(_) => format!("{s},scale={:.4e}", self.size),
            Candidate::BaseShift | Candidate::ToolShift => {
                let c = &self.components;
                format!("{s}:dx={:.4e},dy={:.4e},dz={:.4e}", c[0].1, c[1].1, c[2].1)
            }
            Candidate::LengthScale => format!("{s}:scale={:.9}", 1.0 + self.size),
        }
    }

    /// One line with units: `joint_zero:joint=2  offset 1.020e-4 ± 4.1e-6 rad (0.00584°)`.
    pub fn describe(&self) -> String {
        let s = self.candidate.spelling();
        let u = if self.unit.is_empty() { String::new() } else { format!(" {}", self.unit) };
        match self.candidate {
            Candidate::JointZero(_) | Candidate::LinkTwist(_) => {
                let what = if matches!(self.candidate, Candidate::JointZero(_)) { "offset" } else { "delta" };
                format!("{s}  {what} {:.4e} ± {:.2e} rad ({:.5}°)", self.size, self.se, self.size.to_degrees())
            }
            Candidate::LinkLength(_) => format!("{s}  delta {:.4e} ± {:.2e}{u}", self.size, self.se),
            Candidate::EncoderScale(_) => format!("{s}  scale {:.4e} ± {:.2e} (ratio)", self.size, self.se),
            Candidate::BaseShift | Candidate::ToolShift => {
                let c = &self.components;
                format!(
                    "{s}  {:.4e} ± {:.2e}{u} (dx {:.4e}, dy {:.4e}, dz {:.4e}{u}{})",
                    self.size,
                    self.se,
                    c[0].1,
                    c[1].1,
                    c[2].1,
                    if matches!(self.candidate, Candidate::ToolShift) { ", flange frame" } else { "" }
                )
            }
            Candidate::LengthScale => {
                format!("{s}  scale − 1 = {:.4e} ± {:.2e} (every length × {:.7})", self.size, self.se, 1.0 + self.size)
            }
        }
    }

    pub fn to_json(&self) -> serde_json::Value {
        let mut v = serde_json::json!({
            "effect": self.candidate.spelling(),
            "size": self.size,
            "se": self.se,
            "unit": self.unit,
            "plant": self.plant(),
        });
        if !self.components.is_empty() {
            v["components"] = self.components.iter().map(|(k, x, _)| (k.to_string(), serde_json::json!(x))).collect();
            v["components_se"] = self.components.iter().map(|(k, _, e)| (k.to_string(), serde_json::json!(e))).collect();
        }
        v
    }
}

/// What naming found.
#[derive(Debug, Clone, PartialEq)]
pub struct Named {
    /// The smallest set the evidence keeps, in the order chosen (empty: no candidate explains the
    /// residual out of sample).
    pub changes: Vec<Change>,
    /// The check's statistic on what the named change leaves (the frame projected out as before).
    pub after: Statistic,
    /// Leave-one-pose-out log predictive density before and after (nats).
    pub evidence_before: f64,
    pub evidence_after: f64,
    /// Candidates not offered and why (`base_shift`: the registered frame holds it).
    pub excluded: Vec<(String, &'static str)>,
}

/// Why no change could be named.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NameError {
    /// The library's changes are a DH chain's, read in 3-D.
    NotDhChain,
    /// C is not positive definite.
    NotPositiveDefinite,
}

/// Names the change behind the residual `r` (internal units, the check's) with covariance `c` at
/// the fresh rows `fresh`; `tangent`: the registered frame's columns (internal units), always in
/// the fit.
/// `unit`: the data's length unit's name.
pub fn name_change(
    model: &Model,
    fresh: &Measurements,
    r: &[f64],
    c: &Mat<f64>,
    tangent: Option<&Mat<f64>>,
    unit: &str,
) -> Result<Named, NameError> {
    let NominalModel::DhChain(chain) = &model.nominal else { return Err(NameError::NotDhChain) };
    if fresh.task_dim != 3 {
        return Err(NameError::NotDhChain);
    }
    let n = chain.joints.len();
    let dim = r.len();
    let register = tangent.is_some();
    let cands = candidates(n, register);
    let columns = candidate_columns(model, fresh, &cands);
    let cinv = inverse(c).ok_or(NameError::NotPositiveDefinite)?;
    let block = fresh.points_per_pose.max(1) * fresh.task_dim;
    let fixed = tangent_columns(tangent);
    let score = |chosen: &[usize]| -> Option<f64> {
        let f = stack(&fixed, chosen.iter().flat_map(|&g| columns[g].iter()));
        loo_log_density(&cinv, r, &f, block)
    };
    let before = score(&[]).ok_or(NameError::NotPositiveDefinite)?;
    let (mut chosen, mut best) = (Vec::<usize>::new(), before);
    while chosen.len() < MAX_GROUPS {
        let mut step: Option<(usize, f64)> = None;
        for g in 0..cands.len() {
            if chosen.contains(&g) {
                continue;
            }
            let mut trial = chosen.clone();
            trial.push(g);
            let f = stack(&fixed, trial.iter().flat_map(|&k| columns[k].iter()));
            if !identifiable(&cinv, &f) {
                continue;
            }
            if let Some(s) = score(&trial) {
                if step.is_none_or(|(_, b)| s > b) {
                    step = Some((g, s));
                }
            }
        }
        match step {
            Some((g, s)) if s > best + MARGIN => {
                chosen.push(g);
                best = s;
            }
            _ => break,
        }
    }
    let f = stack(&fixed, chosen.iter().flat_map(|&g| columns[g].iter()));
    let after = if f.is_empty() { mahalanobis(c, r, None) } else { mahalanobis(c, r, Some(&Mat::from_fn(dim, f.len(), |i, k| f[k][i]))) }
        .ok_or(NameError::NotPositiveDefinite)?;
    // The GLS estimate and its covariance (FᵀC⁻¹F)⁻¹, the frame's columns first.
    let (beta, cov) = gls(&cinv, r, &f).ok_or(NameError::NotPositiveDefinite)?;
    let unit = unit.to_string();
    let mut k = fixed.len();
    let mut changes = Vec::new();
    for &g in &chosen {
        let cand = cands[g];
        let w = cand.width();
        let (vals, ses): (Vec<f64>, Vec<f64>) = (k..k + w).map(|i| (beta[i], cov[(i, i)].max(0.0).sqrt())).unzip();
        let change = if w == 3 {
            let size = vals.iter().map(|v| v * v).sum::<f64>().sqrt();
            // δ-method: se(|d|) = √(dᵀ Σ d) / |d|.
            let quad: f64 = (0..3).flat_map(|a| (0..3).map(move |b| (a, b))).map(|(a, b)| vals[a] * cov[(k + a, k + b)] * vals[b]).sum();
            let se = if size > 0.0 { quad.max(0.0).sqrt() / size } else { ses.iter().map(|s| s * s).sum::<f64>().sqrt() };
            let components = ["dx", "dy", "dz"].into_iter().zip(vals.iter().zip(&ses)).map(|(n, (v, s))| (n, *v, *s)).collect();
            Change { candidate: cand, size, se, unit: unit.clone(), components }
        } else {
            let unit = match cand {
                Candidate::JointZero(_) | Candidate::LinkTwist(_) => "rad".to_string(),
                Candidate::LinkLength(_) => unit.clone(),
                _ => String::new(),
            };
            Change { candidate: cand, size: vals[0], se: ses[0], unit, components: Vec::new() }
        };
        changes.push(change);
        k += w;
    }
    let excluded = if register { vec![("base_shift".to_string(), "the registered frame holds the base's transform")] } else { Vec::new() };
    Ok(Named { changes, after, evidence_before: before, evidence_after: best, excluded })
}

/// Each candidate's columns as changes of the diagnose library's parameters (`Param`): one list of
/// (parameter, coefficient) per column, at `chain`. What the columns differentiate along and what
/// `--update` writes into the chain (`update`), so both read the same mapping.
pub fn directions(chain: &cbd_protocol::DhChain, cand: Candidate) -> Vec<Vec<(Param, f64)>> {
    let n = chain.joints.len();
    let o = 4 * n;
    let one = |k: usize| vec![(Param::Geometric(k), 1.0)];
    match cand {
        Candidate::JointZero(j) => vec![one(4 * j + 3)],
        Candidate::LinkLength(l) => vec![one(4 * l)],
        Candidate::LinkTwist(l) => vec![one(4 * l + 1)],
        Candidate::EncoderScale(j) => {
            vec![vec![(Param::Effect { kind: crate::effects::encoder_scale::KIND, site: Site::at(j), component: 0 }, 1.0)]]
        }
        Candidate::BaseShift => (0..3).map(|a| one(o + a)).collect(),
        Candidate::ToolShift => (0..3).map(|a| one(o + 6 + a)).collect(),
        Candidate::LengthScale => {
            // d/ds of every length × s at s = 1: Σ length_k ∂/∂length_k.
            let mut lengths: Vec<(Param, f64)> = Vec::new();
            for (j, joint) in chain.joints.iter().enumerate() {
                lengths.push((Param::Geometric(4 * j), joint.a));
                lengths.push((Param::Geometric(4 * j + 2), joint.d));
            }
            lengths.extend((0..3).map(|a| (Param::Geometric(o + a), chain.base.translation[a])));
            lengths.extend((0..3).map(|a| (Param::Geometric(o + 6 + a), chain.tool.translation[a])));
            vec![lengths]
        }
    }
}

/// Each candidate's columns ∂prediction/∂parameter at the fresh rows, internal units per the
/// parameter's own (lengths in the data's unit, angles in radians).
pub fn candidate_columns(model: &Model, fresh: &Measurements, cands: &[Candidate]) -> Vec<Vec<Vec<f64>>> {
    let NominalModel::DhChain(chain) = &model.nominal else { unreachable!("checked by the caller") };
    let n = chain.joints.len();
    let geometric = crate::nominal::dh_parameters::parameter_count_for(chain);
    let mut params: Vec<Param> = (0..geometric).map(Param::Geometric).collect();
    params.extend((0..n).map(|j| Param::Effect { kind: crate::effects::encoder_scale::KIND, site: Site::at(j), component: 0 }));
    let jac = jacobian(&model.nominal, fresh, &params);
    let norm = &model.normalisation;
    let index = |p: &Param| match *p {
        Param::Geometric(k) => k,
        Param::Effect { site, .. } => geometric + site.index,
    };
    let column = |terms: &[(Param, f64)]| -> Vec<f64> {
        match terms {
            [(p, c)] if *c == 1.0 => (0..jac.nrows()).map(|i| norm.length_to_internal(jac[(i, index(p))])).collect(),
            _ => {
                let mut v = vec![0.0; jac.nrows()];
                for (p, c) in terms {
                    for (i, x) in v.iter_mut().enumerate() {
                        *x += c * norm.length_to_internal(jac[(i, index(p))]);
                    }
                }
                v
            }
        }
    };
    cands.iter().map(|c| directions(chain, *c).iter().map(|terms| column(terms)).collect()).collect()
}

pub(super) fn stack<'a>(fixed: &[Vec<f64>], more: impl Iterator<Item = &'a Vec<f64>>) -> Vec<Vec<f64>> {
    fixed.iter().cloned().chain(more.cloned()).collect()
}

/// P = C⁻¹ − C⁻¹F(FᵀC⁻¹F)⁻¹FᵀC⁻¹: the precision of the part of r the columns F do not explain
/// (C⁻¹ itself without columns); `None` when FᵀC⁻¹F is not positive definite. What the
/// leave-one-out density scores with, and `plan --check` sizes a registered check with (F the
/// frame's tangent).
pub fn projected_precision(cinv: &Mat<f64>, f: &[Vec<f64>]) -> Option<Mat<f64>> {
    if f.is_empty() {
        return Some(cinv.clone());
    }
    let (cf, a) = weighted(cinv, f);
    let ainv = inverse(&a)?;
    Some(cinv - &cf * &ainv * cf.transpose())
}

/// A registered frame's tangent (dim × k) as its k columns, the form the fits here take.
pub fn tangent_columns(tangent: Option<&Mat<f64>>) -> Vec<Vec<f64>> {
    tangent.map_or_else(Vec::new, |t| (0..t.ncols()).map(|k| (0..t.nrows()).map(|i| t[(i, k)]).collect()).collect())
}

/// C⁻¹F (dim × k) and A = FᵀC⁻¹F.
fn weighted(cinv: &Mat<f64>, f: &[Vec<f64>]) -> (Mat<f64>, Mat<f64>) {
    let dim = cinv.nrows();
    let fm = Mat::from_fn(dim, f.len(), |i, k| f[k][i]);
    let cf = cinv * &fm;
    let a = fm.transpose() * &cf;
    (cf, a)
}

/// Whether F's columns are independent in C's metric: the correlation form of FᵀC⁻¹F has every
/// Cholesky pivot² above 1e-6 (a column less than 0.1 % off the others' span is not told apart).
fn identifiable(cinv: &Mat<f64>, f: &[Vec<f64>]) -> bool {
    let (_, a) = weighted(cinv, f);
    let k = a.nrows();
    if (0..k).any(|i| !(a[(i, i)] > 0.0) || !a[(i, i)].is_finite()) {
        return false;
    }
    let d: Vec<f64> = (0..k).map(|i| 1.0 / a[(i, i)].sqrt()).collect();
    let corr = Mat::from_fn(k, k, |i, j| a[(i, j)] * d[i] * d[j]);
    match super::covariance::cholesky(corr) {
        Some(l) => (0..k).all(|i| l[(i, i)] * l[(i, i)] > 1e-6),
        None => false,
    }
}

/// The GLS estimate β = (FᵀC⁻¹F)⁻¹FᵀC⁻¹r and its covariance (FᵀC⁻¹F)⁻¹.
pub(super) fn gls(cinv: &Mat<f64>, r: &[f64], f: &[Vec<f64>]) -> Option<(Vec<f64>, Mat<f64>)> {
    if f.is_empty() {
        return Some((Vec::new(), Mat::zeros(0, 0)));
    }
    let (cf, a) = weighted(cinv, f);
    let cov = inverse(&a)?;
    let b: Vec<f64> = (0..f.len()).map(|k| (0..r.len()).map(|i| cf[(i, k)] * r[i]).sum()).collect();
    let beta = (0..f.len()).map(|i| (0..f.len()).map(|j| cov[(i, j)] * b[j]).sum()).collect();
    Some((beta, cov))
}

/// The leave-one-pose-out log predictive density of r ~ N(Fβ, C), β re-estimated without the
/// pose, poses `block` consecutive entries (Dubrule 1983): with P = C⁻¹ − C⁻¹F(FᵀC⁻¹F)⁻¹FᵀC⁻¹,
/// Σ_i −½ (Pr)_iᵀ P_ii⁻¹ (Pr)_i + ½ log det P_ii − (block/2) log 2π.
pub fn loo_log_density(cinv: &Mat<f64>, r: &[f64], f: &[Vec<f64>], block: usize) -> Option<f64> {
    let dim = r.len();
    let p = projected_precision(cinv, f)?;
    let rm = Mat::from_fn(dim, 1, |i, _| r[i]);
    let pr = &p * &rm;
    let mut total = 0.0;
    for start in (0..dim).step_by(block) {
        let b = block.min(dim - start);
        let pii = p.as_ref().submatrix(start, start, b, b).to_owned();
        let l = super::covariance::cholesky(pii)?;
        let mut v = pr.as_ref().submatrix(start, 0, b, 1).to_owned();
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(l.as_ref(), v.as_mut(), crate::numeric::FIXED_SPLIT);
        let quad: f64 = (0..b).map(|i| v[(i, 0)] * v[(i, 0)]).sum();
        let logdet: f64 = (0..b).map(|i| 2.0 * l[(i, i)].ln()).sum();
        total += -0.5 * quad + 0.5 * logdet - 0.5 * b as f64 * (std::f64::consts::TAU).ln();
    }
    total.is_finite().then_some(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dubrule's closed form against leaving each pose out by hand: refit β by GLS on the other
    /// rows, predict the pose by the conditional Gaussian (kriging with the refitted mean), and
    /// score its error by the conditional covariance plus the refitted mean's uncertainty.
    #[test]
    fn the_closed_form_leave_one_out_matches_refitting_without_the_pose() {
        let dim = 12;
        let block = 3;
        let c = Mat::from_fn(dim, dim, |i, j| {
            let d = (i as f64 - j as f64).abs();
            if i == j {
                1.5 + 0.1 * i as f64
            } else {
                0.4 * (-d / 3.0).exp()
            }
        });
        let r: Vec<f64> = (0..dim).map(|i| ((i as f64) * 1.37).sin() + 0.2).collect();
        let f = vec![(0..dim).map(|i| 1.0 + 0.1 * i as f64).collect::<Vec<f64>>(), (0..dim).map(|i| ((i as f64) * 0.7).cos()).collect()];
        let cinv = inverse(&c).unwrap();
        let closed = loo_log_density(&cinv, &r, &f, block).unwrap();
        let mut by_hand = 0.0;
        for start in (0..dim).step_by(block) {
            let keep: Vec<usize> = (0..dim).filter(|i| *i < start || *i >= start + block).collect();
            let out: Vec<usize> = (start..start + block).collect();
            let sub = |rows: &[usize], cols: &[usize]| Mat::from_fn(rows.len(), cols.len(), |a, b| c[(rows[a], cols[b])]);
            let ckk = sub(&keep, &keep);
            let ckk_inv = inverse(&ckk).unwrap();
            let fk = Mat::from_fn(keep.len(), 2, |a, k| f[k][keep[a]]);
            let fo = Mat::from_fn(block, 2, |a, k| f[k][out[a]]);
            let rk = Mat::from_fn(keep.len(), 1, |a, _| r[keep[a]]);
            let ro = Mat::from_fn(block, 1, |a, _| r[out[a]]);
            let a = fk.transpose() * &ckk_inv * &fk;
            let ainv = inverse(&a).unwrap();
            let beta = &ainv * fk.transpose() * &ckk_inv * &rk;
            let cok = sub(&out, &keep);
            let pred = &fo * &beta + &cok * &ckk_inv * (&rk - &fk * &beta);
            // The error's covariance: the conditional one plus the mean's, through the kriging weights.
            let cond = sub(&out, &out) - &cok * &ckk_inv * cok.transpose();
            let g = &fo - &cok * &ckk_inv * &fk;
            let cov = cond + &g * &ainv * g.transpose();
            let e = &ro - &pred;
            let cov_inv = inverse(&cov).unwrap();
            let quad = (e.transpose() * &cov_inv * &e)[(0, 0)];
            let logdet = cov.llt(faer::Side::Lower).unwrap().L().diagonal().column_vector().iter().map(|v| 2.0 * v.ln()).sum::<f64>();
            by_hand += -0.5 * quad - 0.5 * logdet - 0.5 * block as f64 * std::f64::consts::TAU.ln();
        }
        assert!((closed - by_hand).abs() < 1e-9 * by_hand.abs().max(1.0), "{closed} vs {by_hand}");
    }

    /// A planted joint zero on the UR5 chain, seen through the check's residual with white noise:
    /// the named change is that joint's zero, its size within 4 standard errors of the truth, and
    /// what is left is the noise; pure noise names nothing.
    #[test]
    fn a_planted_joint_zero_is_named_and_noise_names_nothing() {
        let chain = crate::simulate::six_joint::ur5_nominal();
        let nominal = NominalModel::DhChain(chain.clone());
        let q: Vec<f64> = (0..6 * 20).map(|i| ((i as f64) * 0.537).sin() * 2.8).collect();
        let mut model = crate::evidence::model_for_tests(nominal.clone(), &q[..6 * 5]);
        model.normalisation = cbd_protocol::Normalisation { task_offset: [0.0; 3], task_scale: 500.0 };
        let mut fresh = Measurements::new(6, 3);
        fresh.joints = q.clone();
        let mut changed = chain.clone();
        let truth = 2e-4;
        changed.joints[1].theta_offset += truth;
        let p0 = crate::nominal::positions(&nominal, &q, 3);
        let p1 = crate::nominal::positions(&NominalModel::DhChain(changed), &q, 3);
        fresh.positions = p1.clone();
        let sigma = 0.02 / 500.0;
        let noise: Vec<f64> = (0..p0.len()).map(|i| sigma * ((i as f64) * 12.9898).sin().mul_add(43758.5453, 0.0).fract() * 1.7).collect();
        let c = Mat::from_fn(p0.len(), p0.len(), |i, j| if i == j { sigma * sigma } else { 0.0 });
        let r: Vec<f64> = p1.iter().zip(&p0).zip(&noise).map(|((a, b), e)| (a - b) / 500.0 + e).collect();
        let named = name_change(&model, &fresh, &r, &c, None, "mm").unwrap();
        assert_eq!(named.changes.len(), 1, "{:?}", named.changes);
        let ch = &named.changes[0];
        assert_eq!(ch.candidate.spelling(), "joint_zero:joint=2");
        assert!((ch.size - truth).abs() < 4.0 * ch.se, "{} ± {} vs {truth}", ch.size, ch.se);
        assert!(named.after.p_value > 1e-3, "{:?}", named.after);
        let only_noise: Vec<f64> = noise.clone();
        let named = name_change(&model, &fresh, &only_noise, &c, None, "mm").unwrap();
        assert!(named.changes.is_empty(), "{:?}", named.changes);
    }
}
