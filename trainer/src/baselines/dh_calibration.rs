//! Parametric calibration: Levenberg–Marquardt over every Denavit–Hartenberg parameter
//! (a, α, d, θ_offset of each joint), the base transform (3 translations + 3 small rotations,
//! applied on the left of the nominal base) and the tool translation (the tool's rotation does
//! not move a measured position, so it is not a parameter).
//!
//! Residual: k(p; x_i) − y_i for every measured coordinate. The Jacobian is by central differences
//! (each length parameter enters the position affinely, so for them it is exact to rounding).
//! Columns are scaled to unit norm; the damped steps come from the SVD of the scaled Jacobian
//! (`solver::least_squares::TruncatedSvd`, never JᵀJ itself), and directions whose eigenvalue of
//! the scaled JᵀJ (σ²) is below `rank_tolerance × λ_max` are dropped: unidentifiable combinations (e.g. d₂ + d₃ + d₄ for
//! parallel axes, base yaw vs θ₁ offset) stay at their nominal values (the minimum-norm change
//! in scaled parameters) and are reported by name.

use crate::data::Measurements;
use crate::nominal::dh_parameters::{apply_parameters, parameter_count, parameter_names};
use crate::solver::least_squares::TruncatedSvd;
use cbd_protocol::{DhChain, NominalModel};
use cbd_runtime::kinematics::forward_kinematics;
use faer::Mat;

/// Settings of the fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DhCalibrationOptions {
    pub max_iterations: usize,
    /// Eigenvalues of the scaled JᵀJ below this fraction of the largest are unidentifiable.
    pub rank_tolerance: f64,
    /// Stop when an accepted step lowers the cost by less than this fraction.
    pub cost_tolerance: f64,
    /// Parameters whose (unit-scaled) Jacobian column lies within this distance of the span of
    /// the others at the nominal model are redundant and kept at their nominal values
    /// (greedy column-pivoted Gram–Schmidt). 0 disables.
    pub redundancy_tolerance: f64,
    /// Fit a planar arm as its DH form (the result is then a 3-D DH chain read in its first two
    /// coordinates, which only callers that read it so — compare, diagnose — can use); when
    /// false a planar arm is refused as before.
    pub planar_as_dh: bool,
}

impl Default for DhCalibrationOptions {
    fn default() -> Self {
        DhCalibrationOptions {
            max_iterations: 200,
            rank_tolerance: 1e-14,
            cost_tolerance: 1e-15,
            redundancy_tolerance: 1e-9,
            planar_as_dh: false,
        }
    }
}

/// What the fit did.
#[derive(Debug, Clone, PartialEq)]
pub struct DhFitStats {
    pub iterations: usize,
    /// Root-mean-square position error (Euclidean, per measurement) before and after.
    pub initial_rms: f64,
    pub final_rms: f64,
    pub n_parameters: usize,
    /// Identifiable directions (numerical rank of the scaled Jacobian at the solution).
    pub rank: usize,
    /// For each unidentifiable direction, the parameters that dominate it (weight > 0.3).
    pub unidentifiable: Vec<String>,
    /// Change of every parameter from the nominal (names in `parameter_names`).
    pub parameter_changes: Vec<f64>,
    pub parameter_names: Vec<String>,
    pub converged: bool,
    /// Parameters redundant at the nominal model (first stage kept them fixed).
    pub redundant_at_nominal: Vec<String>,
}

#[derive(Debug, Clone)]
pub struct DhCalibration {
    pub model: NominalModel,
    pub stats: DhFitStats,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DhCalibrationError {
    /// Only DH chains have DH parameters.
    #[error("DH calibration needs a DH chain as nominal model")]
    NotADhChain,
    /// Fewer measured coordinates than parameters would be meaningless.
    #[error("DH calibration: {rows} measurements are too few")]
    TooFewMeasurements { rows: usize },
    /// The SVD of the Jacobian failed (non-finite data?).
    #[error("DH calibration: {0}")]
    Numerical(#[from] crate::solver::least_squares::LeastSquaresError),
}

impl From<DhCalibrationError> for crate::Error {
    fn from(e: DhCalibrationError) -> crate::Error {
        crate::Error::stage("DH calibration", e)
    }
}

/// k − y over the data's `m = data.task_dim` coordinates (2 for a planar arm's DH form).
fn residuals(chain: &DhChain, data: &Measurements, out: &mut [f64]) {
    let model = NominalModel::DhChain(chain.clone());
    let m = data.task_dim;
    for i in 0..data.len() {
        let k = forward_kinematics(&model, data.joints(i));
        for c in 0..m {
            out[m * i + c] = k.position[c] - data.position(i)[c];
        }
    }
}

/// Column-pivoted Gram–Schmidt on the unit-scaled Jacobian: repeatedly keep the column with the
/// largest component orthogonal to those kept; columns left with less than `tol` are redundant.
fn redundant_parameters(jac: &Mat<f64>, colnorm: &[f64], tol: f64) -> Vec<usize> {
    let (rows, np) = (jac.nrows(), jac.ncols());
    let mut cols: Vec<Vec<f64>> = (0..np).map(|k| (0..rows).map(|i| jac[(i, k)] / colnorm[k]).collect()).collect();
    let mut remaining: Vec<usize> = (0..np).collect();
    loop {
        let norms: Vec<f64> = remaining.iter().map(|&k| cols[k].iter().map(|v| v * v).sum::<f64>().sqrt()).collect();
        let Some((pos, &best)) = norms.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) else { break };
        if best <= tol {
            break;
        }
        let pivot = remaining.remove(pos);
        let q: Vec<f64> = cols[pivot].iter().map(|v| v / best).collect();
        for &k in &remaining {
            let d: f64 = q.iter().zip(&cols[k]).map(|(a, b)| a * b).sum();
            for (c, qi) in cols[k].iter_mut().zip(&q) {
                *c -= d * qi;
            }
        }
    }
    remaining.sort_unstable();
    remaining
}

/// ∂k/∂(DH rows, base translation, tool translation) at the chain's current parameters, into
/// `jac` (`data.task_dim` rows per measurement); the base-rotation columns are left for the caller.
fn analytic_jacobian(chain: &DhChain, data: &Measurements, jac: &mut Mat<f64>) {
    use crate::nominal::{cross, sub};
    use cbd_protocol::DhConvention;
    use cbd_runtime::kinematics::rigid::dh_walk;
    let (n, m) = (chain.joints.len(), data.task_dim);
    let column = |r: &[[f64; 3]; 3], c: usize| [r[0][c], r[1][c], r[2][c]];
    for row in 0..data.len() {
        let walk = dh_walk(chain, data.joints(row));
        let p = walk.tool;
        // Frame i (0 = base, i = after joint i): its rotation's column c and its origin.
        let axis = |i: usize, c: usize| if i == 0 { column(&walk.start_rotation, c) } else { column(&walk.end_rotations[i - 1], c) };
        let origin = |i: usize| if i == 0 { walk.start } else { walk.ends[i - 1] };
        let mut put = |col: usize, v: [f64; 3]| {
            for c in 0..m {
                jac[(m * row + c, col)] = v[c];
            }
        };
        for i in 1..=n {
            let base_col = 4 * (i - 1);
            match chain.convention {
                // Rz(θ) Tz(d) about/along z_{i−1}; Tx(a) Rx(α) along/about x_i through o_i.
                DhConvention::Standard => {
                    put(base_col, axis(i, 0));
                    put(base_col + 1, cross(axis(i, 0), sub(p, origin(i))));
                    put(base_col + 2, axis(i - 1, 2));
                    put(base_col + 3, cross(axis(i - 1, 2), sub(p, origin(i - 1))));
                }
                // Rx(α) Tx(a) about/along x_{i−1} through o_{i−1}; Rz(θ) Tz(d) about/along z_i.
                DhConvention::Modified => {
                    put(base_col, axis(i - 1, 0));
                    put(base_col + 1, cross(axis(i - 1, 0), sub(p, origin(i - 1))));
                    put(base_col + 2, axis(i, 2));
                    put(base_col + 3, cross(axis(i, 2), sub(p, origin(i))));
                }
            }
        }
        let o = 4 * n;
        for k in 0..3 {
            let mut e = [0.0; 3];
            e[k] = 1.0;
            put(o + k, e);
            // Tool translation is expressed in the last joint frame.
            put(o + 6 + k, axis(n, k));
        }
    }
}

fn rms(r: &[f64], m: usize) -> f64 {
    let n = r.len() / m;
    (r.iter().map(|v| v * v).sum::<f64>() / n.max(1) as f64).sqrt()
}

/// The Jacobian of the residuals at parameter changes `p` from `chain0`: analytic columns for the
/// DH rows, base translation and tool; central differences for the base rotation (its axis-angle
/// parametrisation), with `scratch` for the two residual vectors.
fn jacobian_at(chain0: &DhChain, p: &[f64], data: &Measurements, jac: &mut Mat<f64>, scratch: (&mut [f64], &mut [f64])) {
    let (rp, rm) = scratch;
    let n = chain0.joints.len();
    analytic_jacobian(&apply_parameters(chain0, p), data, jac);
    for k in 4 * n + 3..4 * n + 6 {
        let h = 1e-6;
        let mut q = p.to_vec();
        q[k] = p[k] + h;
        residuals(&apply_parameters(chain0, &q), data, rp);
        q[k] = p[k] - h;
        residuals(&apply_parameters(chain0, &q), data, rm);
        for i in 0..jac.nrows() {
            jac[(i, k)] = (rp[i] - rm[i]) / (2.0 * h);
        }
    }
}

/// The parameters a planar arm's data (m < 3 coordinates) cannot see, which never change
/// (first-order blind in the plane's coordinates); none for 3-D data.
fn out_of_plane_parameters(n: usize, m: usize) -> Vec<usize> {
    if m >= 3 {
        return Vec::new();
    }
    let inside = crate::nominal::planar::in_plane_parameters(n);
    (0..parameter_count(n)).filter(|k| !inside.contains(k)).collect()
}

/// The parameters redundant at this Jacobian (none when `tolerance` is 0), less those out of the plane.
fn redundant_in_plane(jac: &Mat<f64>, colnorm: &[f64], tolerance: f64, out_of_plane: &[usize]) -> Vec<usize> {
    if !(tolerance > 0.0) {
        return Vec::new();
    }
    let mut f = redundant_parameters(jac, colnorm, tolerance);
    f.retain(|k| !out_of_plane.contains(k));
    f
}

/// The unidentifiable directions worth reporting: directions of the out-of-plane parameters alone
/// are not news, only those that move an in-plane parameter are.
fn reported_null_directions(factored: &TruncatedSvd, rank_tolerance: f64, out_of_plane: &[usize]) -> Vec<Vec<f64>> {
    (0..factored.scales().len())
        .filter(|&k| !factored.keeps(k, rank_tolerance))
        .map(|k| factored.direction(k))
        .filter(|v| v.iter().enumerate().any(|(i, w)| w.abs() > 0.3 && !out_of_plane.contains(&i)))
        .collect()
}

/// Sets the Jacobian columns of parameters that do not move (out of the plane, frozen) to zero.
fn zero_columns(jac: &mut Mat<f64>, columns: &[usize]) {
    for &k in columns {
        for i in 0..jac.nrows() {
            jac[(i, k)] = 0.0;
        }
    }
}

/// The column norms of `jac`, floored: a parameter with almost no effect must not take huge steps
/// (a null direction drifting to 1e10 rad would ruin the arithmetic).
fn column_scales(jac: &Mat<f64>, colnorm: &mut [f64]) {
    for (k, c) in colnorm.iter_mut().enumerate() {
        *c = (0..jac.nrows()).map(|i| jac[(i, k)] * jac[(i, k)]).sum::<f64>().sqrt();
    }
    let floor = 1e-6 * colnorm.iter().cloned().fold(0.0, f64::max);
    for c in colnorm.iter_mut() {
        *c = c.max(floor).max(f64::MIN_POSITIVE);
    }
}

/// An unidentifiable direction as its large components, largest first: `+0.71·d1 -0.71·d2`.
fn describe_direction(v: &[f64], names: &[String]) -> String {
    let mut parts: Vec<(f64, &str)> = v.iter().zip(names).filter(|(w, _)| w.abs() > 0.3).map(|(w, s)| (*w, s.as_str())).collect();
    parts.sort_by(|a, b| b.0.abs().total_cmp(&a.0.abs()));
    parts.iter().map(|(w, s)| format!("{w:+.2}·{s}")).collect::<Vec<_>>().join(" ")
}

/// The same chain with its θ offsets and α in (−π, π].
fn with_wrapped_angles(mut chain: DhChain) -> DhChain {
    for j in chain.joints.iter_mut() {
        j.theta_offset = j.theta_offset.sin().atan2(j.theta_offset.cos());
        j.alpha = j.alpha.sin().atan2(j.alpha.cos());
    }
    chain
}

/// What the Levenberg–Marquardt iterations of [`calibrate_dh`] end with.
struct Minimum {
    /// Parameter changes from the nominal, and the residuals there.
    p: Vec<f64>,
    r: Vec<f64>,
    iterations: usize,
    converged: bool,
    /// Rank of the last scaled Jacobian and its reported unidentifiable directions.
    rank: usize,
    null_dirs: Vec<Vec<f64>>,
    /// The parameters held fixed in stage 1.
    redundant_at_nominal: Vec<usize>,
}

/// Levenberg–Marquardt on the scaled Jacobian's SVD from the nominal `chain0` (residuals `r`
/// there), the `out_of_plane` parameters fixed.
fn minimise(
    chain0: &DhChain,
    data: &Measurements,
    out_of_plane: &[usize],
    options: &DhCalibrationOptions,
    mut r: Vec<f64>,
) -> Result<Minimum, DhCalibrationError> {
    let (rows, np) = (r.len(), parameter_count(chain0.joints.len()));
    let mut p = vec![0.0; np];
    let mut cost = 0.5 * r.iter().map(|v| v * v).sum::<f64>();
    let mut mu = -1.0;
    let mut nu = 2.0;
    let mut converged = false;
    let mut iterations = 0;
    let (mut rp, mut rm) = (vec![0.0; rows], vec![0.0; rows]);
    let mut rank = np;
    let mut null_dirs: Vec<Vec<f64>> = Vec::new();
    let mut jac = Mat::<f64>::zeros(rows, np);
    let mut recompute = true;
    let mut frozen: Option<Vec<usize>> = None;
    // Stage 1 keeps the parameters redundant at the nominal fixed (well conditioned, fast);
    // stage 2 ("polish") frees them all, since away from the nominal some become identifiable.
    let mut redundant_at_nominal: Vec<usize> = Vec::new();
    let polish = |frozen: &mut Option<Vec<usize>>, recompute: &mut bool, mu: &mut f64| -> bool {
        match frozen {
            Some(f) if !f.is_empty() => {
                f.clear();
                *recompute = true;
                *mu = -1.0;
                true
            }
            _ => false,
        }
    };
    let mut colnorm = vec![1.0; np];
    let mut svd: Option<TruncatedSvd> = None;
    while iterations < options.max_iterations {
        if recompute {
            jacobian_at(chain0, &p, data, &mut jac, (&mut rp, &mut rm));
            zero_columns(&mut jac, out_of_plane);
            column_scales(&jac, &mut colnorm);
            if frozen.is_none() {
                redundant_at_nominal = redundant_in_plane(&jac, &colnorm, options.redundancy_tolerance, out_of_plane);
                frozen = Some(redundant_at_nominal.clone());
            }
            let still = frozen.as_deref().unwrap_or(&[]);
            zero_columns(&mut jac, still);
            for &k in still {
                colnorm[k] = 1.0;
            }
            // The scaled Jacobian J D⁻¹ = U Σ Vᵀ: λ_k = σ_k² are the eigenvalues of D⁻¹ JᵀJ D⁻¹.
            let factored = TruncatedSvd::with_scales(jac.as_ref(), colnorm.clone())?;
            rank = (0..np).filter(|&k| factored.keeps(k, options.rank_tolerance)).count();
            null_dirs = reported_null_directions(&factored, options.rank_tolerance, out_of_plane);
            if mu < 0.0 {
                mu = 1e-3 * factored.eigenvalues().first().copied().unwrap_or(0.0);
            }
            svd = Some(factored);
            recompute = false;
        }
        let factored = svd.as_ref().expect("computed");
        let lmax = factored.eigenvalues().first().copied().unwrap_or(0.0);
        // Step in scaled parameters over the identifiable directions, and the decrease the linear model predicts.
        let (mut step_s, predicted) = factored.damped_step(&r, mu, options.rank_tolerance);
        // Rounding in the singular vectors must not move what stays out of the plane.
        for &k in out_of_plane {
            step_s[k] = 0.0;
        }
        iterations += 1;
        let step_norm = step_s.iter().map(|v| v * v).sum::<f64>().sqrt();
        let p_norm = p.iter().zip(&colnorm).map(|(v, c)| (v * c).powi(2)).sum::<f64>().sqrt();
        if step_norm <= 1e-14 * (p_norm + 1e-9) || predicted <= 0.0 {
            if polish(&mut frozen, &mut recompute, &mut mu) {
                continue;
            }
            converged = true;
            break;
        }
        let trial: Vec<f64> = p.iter().zip(&step_s).zip(&colnorm).map(|((v, s), c)| v + s / c).collect();
        let mut rt = vec![0.0; rows];
        residuals(&apply_parameters(chain0, &trial), data, &mut rt);
        let new_cost = 0.5 * rt.iter().map(|v| v * v).sum::<f64>();
        let rho = (cost - new_cost) / predicted;
        if new_cost.is_finite() && rho > 0.0 {
            let decrease = cost - new_cost;
            p = trial;
            r = rt;
            cost = new_cost;
            mu *= (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3));
            nu = 2.0;
            recompute = true;
            if decrease <= options.cost_tolerance * cost.max(f64::MIN_POSITIVE) || cost == 0.0 {
                if cost > 0.0 && polish(&mut frozen, &mut recompute, &mut mu) {
                    continue;
                }
                converged = true;
                break;
            }
        } else {
            mu *= nu;
            nu *= 2.0;
            if mu > 1e20 * lmax.max(1e-300) {
                if polish(&mut frozen, &mut recompute, &mut mu) {
                    continue;
                }
                converged = true;
                break;
            }
        }
    }
    Ok(Minimum { p, r, iterations, converged, rank, null_dirs, redundant_at_nominal })
}

/// Fits all DH parameters plus base and tool to `data` (positions in the model's length unit).
/// A planar arm is fitted as its DH form (`nominal::planar::as_dh`) on its two task coordinates,
/// over the parameters that move the tool in the plane (link lengths, joint offsets, base x, y
/// and yaw) when `options.planar_as_dh`; the returned model is then that DH form, read in its
/// first two coordinates.
pub fn calibrate_dh(
    nominal: &NominalModel,
    data: &Measurements,
    options: &DhCalibrationOptions,
) -> Result<DhCalibration, DhCalibrationError> {
    if !options.planar_as_dh && !matches!(nominal, NominalModel::DhChain(_)) {
        return Err(DhCalibrationError::NotADhChain);
    }
    let dh_form = crate::nominal::planar::as_dh(nominal);
    let NominalModel::DhChain(chain0) = &dh_form else { return Err(DhCalibrationError::NotADhChain) };
    let n = chain0.joints.len();
    let np = parameter_count(n);
    let m = nominal.task_dim();
    let rows = m * data.len();
    if data.len() < 2 || data.task_dim != m {
        return Err(DhCalibrationError::TooFewMeasurements { rows: data.len() });
    }
    let out_of_plane = out_of_plane_parameters(n, m);
    let names = parameter_names(n);
    let mut r = vec![0.0; rows];
    residuals(chain0, data, &mut r);
    let initial_rms = rms(&r, m);
    let Minimum { p, r, iterations, converged, rank, null_dirs, redundant_at_nominal } = minimise(chain0, data, &out_of_plane, options, r)?;
    let unidentifiable = null_dirs.iter().map(|v| describe_direction(v, &names)).collect();
    let redundant_at_nominal = redundant_at_nominal.iter().map(|&k| names[k].clone()).collect();
    Ok(DhCalibration {
        model: NominalModel::DhChain(with_wrapped_angles(apply_parameters(chain0, &p))),
        stats: DhFitStats {
            iterations,
            initial_rms,
            final_rms: rms(&r, m),
            n_parameters: np - out_of_plane.len(),
            rank,
            unidentifiable,
            parameter_changes: p,
            parameter_names: names,
            converged,
            redundant_at_nominal,
        },
    })
}

/// The geometric group's identification Jacobian at the nominal parameters, ∂k/∂p (the DH fit's own
/// Jacobian: `task_dim` rows per configuration of `joints`, row-major, `n` per row), and the
/// parameters it can identify: those that move the task coordinates (not out of the plane) and are
/// not redundant on these configurations (the fit's column-pivoted test and tolerance). `None` for a
/// model without a DH form.
pub(crate) fn identification_jacobian(nominal: &NominalModel, joints: &[f64]) -> Option<(Mat<f64>, Vec<usize>)> {
    let dh_form = crate::nominal::planar::as_dh(nominal);
    let NominalModel::DhChain(chain0) = &dh_form else { return None };
    let (n, m) = (chain0.joints.len(), nominal.task_dim());
    let count = joints.len() / n.max(1);
    let data = Measurements { n_joints: n, task_dim: m, joints: joints[..count * n].to_vec(), positions: vec![0.0; count * m] };
    let np = parameter_count(n);
    let mut jac = Mat::zeros(m * count, np);
    let (mut rp, mut rm) = (vec![0.0; m * count], vec![0.0; m * count]);
    jacobian_at(chain0, &vec![0.0; np], &data, &mut jac, (&mut rp, &mut rm));
    let out_of_plane = out_of_plane_parameters(n, m);
    zero_columns(&mut jac, &out_of_plane);
    let mut colnorm = vec![0.0; np];
    column_scales(&jac, &mut colnorm);
    let mut dropped = redundant_parameters(&jac, &colnorm, DhCalibrationOptions::default().redundancy_tolerance);
    dropped.extend(out_of_plane);
    let identifiable = (0..np).filter(|k| !dropped.contains(k)).collect();
    Some((jac, identifiable))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use cbd_protocol::DhConvention;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    pub(crate) fn ur5_like(convention: DhConvention) -> DhChain {
        DhChain { convention, ..crate::simulate::six_joint::ur5_nominal() }
    }

    pub(crate) fn sample(model: &NominalModel, count: usize, seed: u64) -> Measurements {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut m = Measurements::new(6, 3);
        for _ in 0..count {
            let q: Vec<f64> = (0..6).map(|_| rng.gen_range(-3.0..3.0)).collect();
            m.push(&q, &forward_kinematics(model, &q).position);
        }
        m
    }

    #[test]
    fn recovers_positions_of_a_perturbed_chain_without_noise() {
        let nominal = ur5_like(DhConvention::Standard);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let p_true: Vec<f64> = parameter_names(6)
            .iter()
            .map(|s| {
                if s.starts_with("alpha") || s.starts_with("theta") || s.starts_with("base_r") {
                    rng.gen_range(-0.01..0.01)
                } else {
                    rng.gen_range(-2.0..2.0)
                }
            })
            .collect();
        let truth = NominalModel::DhChain(apply_parameters(&nominal, &p_true));
        let train = sample(&truth, 150, 1);
        let test = sample(&truth, 300, 2);
        let fit = calibrate_dh(&NominalModel::DhChain(nominal), &train, &DhCalibrationOptions::default()).unwrap();
        assert!(fit.stats.initial_rms > 1.0, "{:?}", fit.stats);
        assert!(fit.stats.rank < fit.stats.n_parameters && !fit.stats.unidentifiable.is_empty(), "{:?}", fit.stats);
        let mut worst: f64 = 0.0;
        for i in 0..test.len() {
            let k = forward_kinematics(&fit.model, test.joints(i));
            for c in 0..3 {
                worst = worst.max((k.position[c] - test.position(i)[c]).abs());
            }
        }
        assert!(worst < 1e-6, "worst test error {worst} mm; stats {:?}", fit.stats);
    }

    #[test]
    fn modified_convention_also_recovers() {
        let nominal = ur5_like(DhConvention::Modified);
        let mut p_true = vec![0.0; parameter_count(6)];
        p_true[0] = 0.8; // a1
        p_true[5] = 0.004; // alpha2
        p_true[10] = -1.5; // d3
        p_true[24] = 3.0; // base_tx
        p_true[28] = 0.01; // base_ry
        p_true[32] = 2.0; // tool_tz
        let truth = NominalModel::DhChain(apply_parameters(&nominal, &p_true));
        let train = sample(&truth, 120, 3);
        let fit = calibrate_dh(&NominalModel::DhChain(nominal), &train, &DhCalibrationOptions::default()).unwrap();
        // This chain read as modified DH has many redundant parameters; LM ends in a flat valley
        // of the parameter space about 1e-5 mm (rms) from an exact fit (a local minimum: the
        // straight line to the true parameters rises to 1e-2 mm). Far below any real noise.
        assert!(fit.stats.final_rms < 1e-4, "{:?}", fit.stats);
        assert!(fit.stats.final_rms < 1e-5 * fit.stats.initial_rms, "{:?}", fit.stats);
    }

    #[test]
    fn planar_chain_is_rejected() {
        let planar = NominalModel::planar(&[1.0]).unwrap();
        let e = calibrate_dh(&planar, &Measurements::new(1, 2), &DhCalibrationOptions::default()).unwrap_err();
        assert_eq!(e, DhCalibrationError::NotADhChain);
    }
}

#[cfg(test)]
mod jacobian_tests {
    use super::tests::{sample, ur5_like};
    use super::*;
    use cbd_protocol::DhConvention;

    #[test]
    fn analytic_jacobian_matches_finite_differences() {
        for conv in [DhConvention::Standard, DhConvention::Modified] {
            let mut p: Vec<f64> = (0..parameter_count(6)).map(|k| 0.01 * ((k * 37 % 11) as f64 - 5.0)).collect();
            p[27] = 0.02; // base rotation too
            let chain = apply_parameters(&ur5_like(conv), &p);
            let data = sample(&NominalModel::DhChain(chain.clone()), 5, 9);
            let np = parameter_count(6);
            let mut jac = Mat::<f64>::zeros(15, np);
            analytic_jacobian(&chain, &data, &mut jac);
            let (mut rp, mut rm) = (vec![0.0; 15], vec![0.0; 15]);
            for k in (0..np).filter(|k| !(27..30).contains(k)) {
                let h = 1e-5;
                let mut q = p.clone();
                q[k] += h;
                residuals(&apply_parameters(&ur5_like(conv), &q), &data, &mut rp);
                q[k] -= 2.0 * h;
                residuals(&apply_parameters(&ur5_like(conv), &q), &data, &mut rm);
                for i in 0..15 {
                    let fd = (rp[i] - rm[i]) / (2.0 * h);
                    assert!(
                        (fd - jac[(i, k)]).abs() < 1e-5 * (1.0 + fd.abs()),
                        "{conv:?} {} row {i}: fd {fd} analytic {}",
                        parameter_names(6)[k],
                        jac[(i, k)]
                    );
                }
            }
        }
    }

    #[test]
    fn a_planar_arm_is_calibrated_as_its_dh_form_in_its_plane() {
        use crate::simulate::rr::planar_arm;
        use rand::{Rng, SeedableRng};
        use rand_chacha::ChaCha8Rng;
        let nominal = NominalModel::planar(&[1.0, 0.5, 0.3]).unwrap();
        let truth = planar_arm(&[1.03, 0.48, 0.31], [0.04, -0.03], 0.02, &[0.01, -0.015, 0.02]);
        let measure = |seed: u64| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut m = Measurements::new(3, 2);
            for _ in 0..60 {
                let q: Vec<f64> = (0..3).map(|_| rng.gen_range(-3.0..3.0)).collect();
                m.push(&q, &forward_kinematics(&truth, &q).position[..2]);
            }
            m
        };
        let (train, test) = (measure(1), measure(2));
        // Refused unless asked for (the result is a 3-D chain read in two coordinates).
        assert_eq!(calibrate_dh(&nominal, &train, &DhCalibrationOptions::default()).unwrap_err(), DhCalibrationError::NotADhChain);
        let fit = calibrate_dh(&nominal, &train, &DhCalibrationOptions { planar_as_dh: true, ..Default::default() }).unwrap();
        // In-plane parameters: 3 lengths, 3 offsets, base x, y, yaw; yaw and the first offset are one.
        assert_eq!((fit.stats.n_parameters, fit.stats.rank), (9, 8), "{:?}", fit.stats);
        assert!(fit.stats.initial_rms > 0.01 && fit.stats.final_rms < 1e-10, "{:?}", fit.stats);
        let predicted = crate::nominal::planar::positions(&fit.model, &test.joints, 2);
        let worst = predicted.iter().zip(&test.positions).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-9, "{worst}");
        // Out of the plane nothing moved: the result is exactly a planar chain in a moved frame.
        assert!(crate::nominal::planar::as_planar_in_frame(&fit.model).is_some(), "{:?}", fit.model);
    }
}
