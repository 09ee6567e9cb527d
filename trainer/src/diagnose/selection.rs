//! Forward selection of effect groups judged out of sample: K-fold cross-validated RMS of the
//! linearised least-squares problem r ≈ A θ (A: library Jacobian columns at the current model).
//! A group is kept only if it lowers the cross-validated RMS by a clear margin and lowers BIC,
//! so that an absent effect is not reported.
//!
//! Cheap CV without the normal equations: per fold the training rows are QR-factored once,
//! A_train = Q R, so a candidate set S is fitted on R's columns S and Qᵀr (P rows, not the
//! training rows: the same least-squares problem); the held-out SSE is summed on the held rows.

use crate::numeric::least_squares::{column_norm, QrLeastSquares, TruncatedSvd};
use faer::{Mat, Par};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::data::RowOrder;

/// Settings of the selection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelectionOptions {
    pub folds: usize,
    /// A group must lower the CV RMS by at least this fraction (0.05 = 5 %). Measured: genuine
    /// effects in the tests lower it by 80–90 %; library effects fitted to a localized bump
    /// outside the library, by 1–4 % each (and they raise the held-out mean error).
    pub margin: f64,
    pub seed: u64,
}

impl Default for SelectionOptions {
    fn default() -> Self {
        SelectionOptions { folds: 5, margin: 0.05, seed: 1 }
    }
}

/// A least-squares problem min |A_S θ − r| compressed by QR to P rows: R (A = Q R) and Qᵀr.
struct Compressed {
    r_factor: Mat<f64>,
    qt_r: Vec<f64>,
}

/// Truncation of the selection's solves: directions with σ² below 1e-12 σ_max² are dropped.
const TOLERANCE: f64 = 1e-12;

/// The stacked linear problem and its per-fold QR factors (columns scaled to unit norm).
pub struct LinearProblem {
    /// Column norms (θ = θ_scaled / scale).
    pub scale: Vec<f64>,
    /// Measurement rows and scalar observations (rows × task_dim).
    pub rows: usize,
    pub observations: usize,
    /// A with unit-norm columns (observations × P).
    a: Mat<f64>,
    r: Vec<f64>,
    /// Per fold: its held-out observations and its training rows, compressed.
    folds: Vec<(Vec<usize>, Compressed)>,
    total: Compressed,
}

fn compress(a: &Mat<f64>, r: &[f64], obs: &[usize]) -> Compressed {
    let sub = Mat::from_fn(obs.len(), a.ncols(), |i, k| a[(obs[i], k)]);
    let rs: Vec<f64> = obs.iter().map(|&i| r[i]).collect();
    let qr = QrLeastSquares::factor(sub, Par::Seq);
    Compressed { r_factor: qr.r_factor(), qt_r: qr.project(&rs) }
}

/// Least-squares solution restricted to `cols` (scaled parameters): truncated SVD of R's columns.
fn solve(c: &Compressed, cols: &[usize]) -> Vec<f64> {
    let p = cols.len();
    if p == 0 {
        return Vec::new();
    }
    let sub = Mat::from_fn(c.r_factor.nrows(), p, |i, j| c.r_factor[(i, cols[j])]);
    match TruncatedSvd::with_scales(sub.as_ref(), vec![1.0; p]) {
        Ok(svd) => svd.solve(&c.qt_r, TOLERANCE),
        Err(_) => vec![0.0; p],
    }
}

impl LinearProblem {
    /// Residual sum of squares of θ (scaled, on `cols`) over the observations `obs`.
    fn sse(&self, obs: impl Iterator<Item = usize>, cols: &[usize], theta: &[f64]) -> f64 {
        obs.map(|i| {
            let fitted: f64 = cols.iter().zip(theta).map(|(&c, t)| self.a[(i, c)] * t).sum();
            (self.r[i] - fitted).powi(2)
        })
        .sum()
    }

    /// `a`: (rows·m) × P Jacobian, `r`: residual y − k (rows·m), pose-major rows of
    /// `points_per_pose` tool points each; whole poses assigned to `folds` folds (a pose's points are
    /// never split between fitting and judging): unordered rows by a permutation drawn from `seed`,
    /// measured rows ([`RowOrder`]) as contiguous blocks, the poses within the gap of a held-out
    /// block left out of its training rows ([`crate::data::blocked_fold`]).
    pub fn new(
        a: &Mat<f64>,
        r: &[f64],
        task_dim: usize,
        points_per_pose: usize,
        order: RowOrder,
        folds: usize,
        seed: u64,
    ) -> LinearProblem {
        let rows = r.len() / task_dim;
        let per_pose = points_per_pose.max(1);
        let poses = rows.div_ceil(per_pose);
        let scale: Vec<f64> = (0..a.ncols()).map(|k| column_norm(a.as_ref(), k).max(f64::MIN_POSITIVE)).collect();
        let scaled = Mat::from_fn(a.nrows(), a.ncols(), |i, k| a[(i, k)] / scale[k]);
        let folds = folds.clamp(2, poses.max(2));
        // Per fold: which poses are held out, which train.
        let (held_of, train_of): (Vec<Vec<bool>>, Vec<Vec<bool>>) = match order {
            RowOrder::Unordered => {
                let mut permutation: Vec<usize> = (0..poses).collect();
                permutation.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
                let mut fold_of = vec![0; poses];
                for (pos, &k) in permutation.iter().enumerate() {
                    fold_of[k] = pos % folds;
                }
                (0..folds).map(|f| (fold_of.iter().map(|&g| g == f).collect(), fold_of.iter().map(|&g| g != f).collect())).unzip()
            }
            RowOrder::Measured => (0..folds)
                .map(|f| {
                    let (held, out) = crate::data::blocked_fold(poses, folds, f);
                    ((0..poses).map(|k| held.contains(&k)).collect(), (0..poses).map(|k| !out.contains(&k)).collect())
                })
                .unzip(),
        };
        let pose_of = |o: usize| o / task_dim / per_pose;
        let fold_problems = (0..folds)
            .map(|f| {
                let held: Vec<usize> = (0..r.len()).filter(|&o| held_of[f][pose_of(o)]).collect();
                let train: Vec<usize> = (0..r.len()).filter(|&o| train_of[f][pose_of(o)]).collect();
                (held, compress(&scaled, r, &train))
            })
            .collect();
        let all: Vec<usize> = (0..r.len()).collect();
        let total = compress(&scaled, r, &all);
        LinearProblem { scale, rows, observations: r.len(), a: scaled, r: r.to_vec(), folds: fold_problems, total }
    }

    /// Cross-validated RMS position error (per measurement row) of the columns `cols`.
    pub fn cv_rms(&self, cols: &[usize]) -> f64 {
        let total: f64 = self.folds.iter().map(|(held, train)| self.sse(held.iter().copied(), cols, &solve(train, cols))).sum();
        (total / self.rows as f64).sqrt()
    }

    /// Fit on all rows: parameter values (unscaled) and the residual sum of squares.
    pub fn fit(&self, cols: &[usize]) -> (Vec<f64>, f64) {
        let theta = solve(&self.total, cols);
        let s = self.sse(0..self.observations, cols, &theta);
        (theta.iter().zip(cols).map(|(t, &c)| t / self.scale[c]).collect(), s)
    }

    /// Bayesian information criterion of the fit with `cols` (Gaussian errors).
    pub fn bic(&self, cols: &[usize]) -> f64 {
        let n = self.observations as f64;
        let (_, s) = self.fit(cols);
        n * (s.max(f64::MIN_POSITIVE) / n).ln() + cols.len() as f64 * n.ln()
    }

    /// Residual sum of squares before any column.
    pub fn base_sse(&self) -> f64 {
        self.r.iter().map(|v| v * v).sum()
    }
}

/// One accepted step of the forward selection.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    pub group: usize,
    pub cv_rms: f64,
    pub bic: f64,
}

/// What the forward selection did.
#[derive(Debug, Clone, PartialEq)]
pub struct Selection {
    /// Group indices in the order they were accepted.
    pub selected: Vec<usize>,
    pub cv_rms_before: f64,
    pub steps: Vec<Step>,
    /// The best candidate that was refused at the end (group, CV RMS it would have given).
    pub best_refused: Option<(usize, f64)>,
}

impl Selection {
    pub fn cv_rms_after(&self) -> f64 {
        self.steps.last().map(|s| s.cv_rms).unwrap_or(self.cv_rms_before)
    }
}

/// Greedy forward selection over groups (`group_cols[g]`: the problem's columns of group g;
/// empty groups are never chosen).
pub fn forward_select(problem: &LinearProblem, group_cols: &[Vec<usize>], options: &SelectionOptions) -> Selection {
    let mut selected: Vec<usize> = Vec::new();
    let mut cols: Vec<usize> = Vec::new();
    let cv_before = problem.cv_rms(&[]);
    let (mut cv, mut bic) = (cv_before, problem.bic(&[]));
    let mut steps = Vec::new();
    let mut best_refused = None;
    loop {
        let best = (0..group_cols.len())
            .filter(|g| !selected.contains(g) && !group_cols[*g].is_empty())
            .map(|g| {
                let trial: Vec<usize> = cols.iter().chain(&group_cols[g]).copied().collect();
                (g, problem.cv_rms(&trial), trial)
            })
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let Some((g, trial_cv, trial)) = best else { break };
        let trial_bic = problem.bic(&trial);
        if trial_cv < cv * (1.0 - options.margin) && trial_bic < bic {
            selected.push(g);
            cols = trial;
            cv = trial_cv;
            bic = trial_bic;
            steps.push(Step { group: g, cv_rms: cv, bic });
        } else {
            best_refused = Some((g, trial_cv));
            break;
        }
    }
    Selection { selected, cv_rms_before: cv_before, steps, best_refused }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn selects_the_column_that_generated_the_data_and_not_the_noise_ones() {
        let rows = 400;
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        use rand::Rng;
        let a = Mat::from_fn(rows, 4, |_, _| rng.gen_range(-1.0..1.0));
        let r: Vec<f64> = (0..rows).map(|i| 0.7 * a[(i, 2)] + 0.01 * rng.gen_range(-1.0..1.0)).collect();
        let problem = LinearProblem::new(&a, &r, 1, 1, RowOrder::Unordered, 5, 1);
        let groups = vec![vec![0], vec![1], vec![2], vec![3]];
        let s = forward_select(&problem, &groups, &SelectionOptions::default());
        assert_eq!(s.selected, vec![2]);
        let (theta, _) = problem.fit(&[2]);
        assert!((theta[0] - 0.7).abs() < 2e-3, "{theta:?}");
    }

    #[test]
    fn folds_hold_out_whole_poses() {
        // 30 poses of 3 points, 3 coordinates each: every fold holds all 9 observations of a
        // pose or none of them.
        let (poses, points, m) = (30, 3, 3);
        let obs = poses * points * m;
        let a = Mat::from_fn(obs, 2, |i, k| ((i * 7 + k * 3) % 11) as f64 - 5.0);
        let r: Vec<f64> = (0..obs).map(|i| (i % 5) as f64).collect();
        for order in [RowOrder::Unordered, RowOrder::Measured] {
            let problem = LinearProblem::new(&a, &r, m, points, order, 4, 9);
            let mut seen = vec![0usize; poses];
            for (held, _) in &problem.folds {
                let mut count = vec![0usize; poses];
                for &o in held {
                    count[o / (points * m)] += 1;
                }
                for (k, c) in count.iter().enumerate() {
                    assert!(*c == 0 || *c == points * m, "pose {k} split: {c} of {} observations held", points * m);
                    seen[k] += c;
                }
            }
            assert!(seen.iter().all(|&c| c == points * m), "every pose held out exactly once: {seen:?}");
        }
    }

    #[test]
    fn measured_rows_are_held_out_in_blocks_without_their_neighbours_in_training() {
        // 40 poses, 4 folds: fold 1 holds poses 10..20 out; 2 poses each side (a quarter of the
        // block) train in no fold that holds it out. A column whose training rows would include
        // a held-out pose's neighbours shows it in the compressed system's row count.
        let obs = 40;
        let a = Mat::from_fn(obs, 1, |i, _| 1.0 + i as f64);
        let r: Vec<f64> = (0..obs).map(|i| i as f64).collect();
        let problem = LinearProblem::new(&a, &r, 1, 1, RowOrder::Measured, 4, 9);
        assert_eq!(problem.folds[1].0, (10..20).collect::<Vec<_>>());
        let (blocked, gap) = crate::data::blocked_fold(40, 4, 1);
        assert_eq!((blocked, gap), (10..20, 8..22));
    }
}
