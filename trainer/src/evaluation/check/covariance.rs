//! C, the covariance of the fresh rows' residual under "nothing changed" (docs/DESIGN.md "cbd
//! check"): the posterior predictive covariance of the blob's linearised model at the fresh rows
//! given its measurement points, K** − K*ᵀ(K + σ²I)⁻¹K* (Rasmussen & Williams eq. 2.24), plus the
//! fresh rows' own noise σ²I and the drift in measurement order the calibration recorded,
//! sd² exp(−|i − j| / length) I between poses i and j (the row-order process of
//! `diagnose::drift`). Internal (normalised) units.

use crate::data::Measurements;
use cbd_protocol::{Model, RowDrift};
use faer::Mat;

/// C at the fresh rows `fresh` (pose-major, the blob's tool points per pose), internal units;
/// `geometry`: the blob's chain is DH-calibrated, its parameters' uncertainty is part of C
/// (`evidence::blob_covariance`). `None` when the blob records no σ or its covariance is not
/// positive definite.
pub fn fresh_covariance(model: &Model, fresh: &Measurements, geometry: bool) -> Option<Mat<f64>> {
    let (n, m) = (model.n_joints(), model.task_dim());
    let trained = model.n_points as usize;
    // The blob's measurement points, then the fresh rows: one covariance over both (positions are
    // not used — the covariance depends on the configurations only).
    let mut rows = Measurements::with_points(n, m, model.nominal.tool_point_count());
    rows.joints = model.points.iter().chain(fresh.joints.iter().copied()).collect();
    rows.positions = vec![0.0; (trained + fresh.len()) * m];
    // K_lin + σ² I over both: its training block is K + σ²I, its fresh block K** + σ²I (the fresh
    // rows' own noise), the off-diagonal block K*.
    let k = crate::evidence::blob_covariance(model, &rows, geometry)?;
    let (t, f) = (trained * m, fresh.len() * m);
    let l = cholesky(k.as_ref().submatrix(0, 0, t, t).to_owned())?;
    let mut v = k.as_ref().submatrix(0, t, t, f).to_owned();
    // V = L⁻¹ K*: K*ᵀ (K + σ²I)⁻¹ K* = Vᵀ V.
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(l.as_ref(), v.as_mut(), crate::numeric::FIXED_SPLIT);
    let mut c = k.as_ref().submatrix(t, t, f, f).to_owned();
    faer::linalg::matmul::matmul(c.as_mut(), faer::Accum::Add, v.transpose(), v.as_ref(), -1.0, crate::numeric::FIXED_SPLIT);
    if let Some(drift) = &model.drift {
        add_drift(&mut c, drift, fresh.points_per_pose.max(1), m, model.normalisation.length_to_internal(drift.sd));
    }
    // Symmetrise the rounding of the product.
    let c = Mat::from_fn(f, f, |i, j| 0.5 * (c[(i, j)] + c[(j, i)]));
    let finite = (0..f).all(|j| (0..f).all(|i| c[(i, j)].is_finite()));
    finite.then_some(c)
}

/// The lower Cholesky factor L of a symmetric positive-definite `a` (its lower triangle read; the
/// upper one zeroed), on faer's fixed work split (the result never depends on the thread count);
/// `None` when `a` is not positive definite.
pub fn cholesky(mut a: Mat<f64>) -> Option<Mat<f64>> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
    let (n, par) = (a.nrows(), crate::numeric::FIXED_SPLIT);
    let mut mem = MemBuffer::new(cholesky_in_place_scratch::<f64>(n, par, Default::default()));
    cholesky_in_place(a.as_mut(), Default::default(), par, MemStack::new(&mut mem), Default::default()).ok()?;
    for j in 1..n {
        for i in 0..j {
            a[(i, j)] = 0.0;
        }
    }
    Some(a)
}

/// C⁻¹ of a symmetric positive-definite C (faer's LLᵀ); `None` when C is not positive definite.
/// What the change's naming and `plan --check` weight the effect columns by.
pub fn spd_inverse(c: &Mat<f64>) -> Option<Mat<f64>> {
    let llt = c.llt(faer::Side::Lower).ok()?;
    Some(faer::linalg::solvers::DenseSolveCore::inverse(&llt))
}

/// Bytes the check's covariance takes for `points` blob points and `fresh` rows of `m`
/// coordinates: the joint covariance, its training block's copy and factor (3 (N m)² f64), and the
/// evidence table's per-pair J Jᵀ and distances ((N² / 2)(m² + 1) f64).
pub fn covariance_bytes(points: usize, fresh: usize, m: usize) -> f64 {
    let (all, points) = (((points + fresh) * m) as f64, points as f64 + fresh as f64);
    8.0 * (3.0 * all * all + 0.5 * points * points * (m * m + 1) as f64)
}

/// + sd² exp(−|pose_i − pose_j| / length) on coordinate pairs (a, a): the recorded drift over the
/// fresh rows in their order (`sd` in internal units).
fn add_drift(c: &mut Mat<f64>, drift: &RowDrift, points_per_pose: usize, m: usize, sd: f64) {
    let rows = c.nrows() / m;
    for i in 0..rows {
        for j in 0..rows {
            let lag = (i / points_per_pose).abs_diff(j / points_per_pose) as f64;
            let k = sd * sd * (-lag / drift.length).exp();
            for a in 0..m {
                c[(i * m + a, j * m + a)] += k;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The law the check relies on, by simulation of the model itself: draw the blob's rows and the
    /// fresh rows jointly from the linearised model's own Gaussian N(0, K_lin + σ²I) (K from the
    /// evidence's table, drawn through its Cholesky factor), predict the fresh rows by the posterior
    /// mean K*ᵀ(K + σ²I)⁻¹ r_train, and the statistic of the fresh residual against C is χ²(dof):
    /// its mean over 400 draws is dof (± 4 standard errors) and about 1 % of them exceed χ²'s 1 %
    /// point (a binomial band). `geometry`: with the geometric group's G Gᵀ in K.
    fn own_draws_are_chi_square(model: &Model, q: &[f64], trained: usize, geometry: bool) {
        let (n, m) = (model.n_joints(), model.task_dim());
        let rows = q.len() / n;
        let (t, f) = (trained * m, (rows - trained) * m);
        let mut fresh = Measurements::new(n, m);
        fresh.joints = q[n * trained..].to_vec();
        fresh.positions = vec![0.0; f];
        let c = fresh_covariance(model, &fresh, geometry).unwrap();
        let mut all = Measurements::new(n, m);
        all.joints = q.to_vec();
        all.positions = vec![0.0; t + f];
        let k = crate::evidence::blob_covariance(model, &all, geometry).unwrap();
        let l = k.llt(faer::Side::Lower).unwrap();
        let ktt_llt = k.as_ref().submatrix(0, 0, t, t).to_owned().llt(faer::Side::Lower).unwrap();
        let kft = k.as_ref().submatrix(t, 0, f, t).to_owned();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let draws = 400;
        let (mut sum, mut over) = (0.0, 0);
        for _ in 0..draws {
            // Box–Muller: √(−2 ln u) cos(2π v) is N(0, 1).
            let z = Mat::from_fn(t + f, 1, |_, _| {
                let (u, v): (f64, f64) = (1.0 - rng.gen::<f64>(), rng.gen());
                (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
            });
            let y = l.L() * &z;
            let mean = &kft * faer::linalg::solvers::Solve::solve(&ktt_llt, &y.as_ref().submatrix(0, 0, t, 1).to_owned());
            let r: Vec<f64> = (0..f).map(|i| y[(t + i, 0)] - mean[(i, 0)]).collect();
            let s = super::super::statistic::mahalanobis(&c, &r, None).unwrap();
            assert_eq!(s.dof, f);
            sum += s.statistic;
            over += usize::from(s.p_value < 0.01);
        }
        let mean = sum / draws as f64;
        // sd of χ²(f) is √(2f); of the mean of 400, √(2f)/20.
        assert!((mean - f as f64).abs() < 4.0 * (2.0 * f as f64).sqrt() / (draws as f64).sqrt(), "mean statistic {mean}, dof {f}");
        assert!(over <= 12, "{over} of {draws} beyond the 1 % point");
    }

    #[test]
    fn the_statistic_of_the_models_own_draws_is_chi_square() {
        let nominal = cbd_protocol::NominalModel::planar(&[1.0, 0.5]).unwrap();
        let q: Vec<f64> = (0..2 * 40).map(|i| ((i as f64) * 0.731).sin() * 2.5).collect();
        let mut model = crate::evidence::model_for_tests(nominal, &q[..2 * 30]);
        model.joint_kernel.gamma = 4.0;
        model.task_kernel.width = 0.6;
        model.sigma = 0.5; // σ / √γ_W with γ_W = 4e-4: σ = 0.01
        model.noise_sigma = Some(0.01);
        own_draws_are_chi_square(&model, &q, 30, false);
    }

    /// The same with a DH chain's geometric group in K (`geometry`): C conditions the group's
    /// parameters on the blob's points too. UR5 chain, metres-sized normalisation (scale 500 mm).
    #[test]
    fn the_statistic_with_the_geometry_term_is_chi_square() {
        let nominal = cbd_protocol::NominalModel::DhChain(crate::simulate::six_joint::ur5_nominal());
        let q: Vec<f64> = (0..6 * 48).map(|i| ((i as f64) * 0.537).sin() * 2.8).collect();
        let mut model = crate::evidence::model_for_tests(nominal, &q[..6 * 40]);
        model.normalisation = cbd_protocol::Normalisation { task_offset: [0.0; 3], task_scale: 500.0 };
        model.joint_kernel.gamma = 0.05;
        model.task_kernel.width = 0.3;
        model.sigma = 0.5; // γ_W = (0.02 / 0.5)² mm²
        model.noise_sigma = Some(0.02);
        let mut fresh = Measurements::new(6, 3);
        fresh.joints = q[6 * 40..].to_vec();
        fresh.positions = vec![0.0; 24];
        // The term is there: the geometry's uncertainty adds to C.
        let (with, without) = (fresh_covariance(&model, &fresh, true).unwrap(), fresh_covariance(&model, &fresh, false).unwrap());
        let trace = |c: &Mat<f64>| (0..24).map(|i| c[(i, i)]).sum::<f64>();
        assert!(trace(&with) > 1.01 * trace(&without), "{} vs {}", trace(&with), trace(&without));
        own_draws_are_chi_square(&model, &q, 40, true);
    }
    /// The drift term: sd² on the diagonal, sd² e^(−1/length) between consecutive poses, none
    /// across coordinates; the tool points of one pose share its time.
    #[test]
    fn the_drift_follows_the_pose_order() {
        let mut c = Mat::<f64>::zeros(8, 8);
        add_drift(&mut c, &RowDrift { sd: 2.0, length: 3.0 }, 2, 2, 2.0);
        assert_eq!(c[(0, 0)], 4.0);
        assert_eq!(c[(0, 2)], 4.0, "two points of pose 0");
        assert!((c[(0, 4)] - 4.0 * (-1.0f64 / 3.0).exp()).abs() < 1e-15);
        assert_eq!(c[(0, 1)], 0.0);
    }
}
