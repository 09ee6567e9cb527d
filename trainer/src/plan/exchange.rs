//! Exchange (Fedorov) passes after the greedy batch: the greedy choice is myopic, so each planned
//! pose in turn is taken out and the candidate that most reduces the workspace's mean posterior
//! variance given all the others put back — the pose itself unless another candidate lowers the
//! criterion by more than a set fraction (docs/DESIGN.md §13). Measured poses are never exchanged.

use super::posterior::Posterior;

/// A swap must lower the criterion by more than this fraction of it (else the pass keeps the pose):
/// rounding in the rank-m up- and downdates is far below it, so passes cannot cycle on noise.
pub const MIN_IMPROVEMENT: f64 = 1e-4;

/// One pass over `batch` (candidate indices of `gp`, whose posterior is conditioned on them and
/// on the measured poses): pose by pose, the best candidate given the others, Δ = gain'(c) −
/// gain'(b) ≥ 0 in the posterior without b, replaces b when Δ > `MIN_IMPROVEMENT` × the criterion.
/// `chosen` marks the batch's candidates. Returns the swaps made; the criterion never increases.
pub fn pass(gp: &mut Posterior, batch: &mut [usize], chosen: &mut [bool]) -> usize {
    let mut swaps = 0;
    for slot in 0..batch.len() {
        let b = batch[slot];
        let Some(gains) = gp.gains_without(b) else { continue };
        let best = (0..gains.len()).filter(|&c| c == b || !chosen[c]).max_by(|&x, &y| gains[x].total_cmp(&gains[y]));
        let Some(c) = best else { continue };
        if c == b || gains[c] - gains[b] <= MIN_IMPROVEMENT * gp.criterion() {
            continue;
        }
        // Both are rank-m updates of the same posterior: a failed factorisation (σ = 0) leaves it.
        if !gp.remove(b) {
            continue;
        }
        if !gp.add(c) {
            gp.add(b);
            continue;
        }
        chosen[b] = false;
        chosen[c] = true;
        batch[slot] = c;
        swaps += 1;
    }
    swaps
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evidence::CbdHyperparameters;
    use crate::plan::posterior::Prior;

    /// An exchange pass on a poor batch (the first candidates, not the greedy choice) swaps, every
    /// swap lowers the criterion, and the result is the posterior of the final batch built afresh.
    #[test]
    fn a_pass_never_increases_the_criterion() {
        let rr = crate::simulate::rr::nominal();
        let h = CbdHyperparameters {
            joint_axes: vec![cbd_protocol::JointKernelAxis::Periodic { b: 1.0 }; 2],
            joint_gamma: 1e-3,
            task_width: 1.0,
            task_gamma: 1e-4,
            sigma: 1e-3,
            configuration: None,
        };
        let (count_c, count_w) = (60, 24);
        let q = crate::plan::candidates::uniform_within(&[[-3.1, 3.1], [0.2, 3.0]], count_c + count_w, 4);
        let process = |batch: &[usize]| {
            let prior = Prior::new(&h, 2);
            let points = q.chunks_exact(2).map(|x| prior.point(&rr, x, vec![x[0].cos(), x[1].sin(), 0.2, 0.1 * x[1]])).collect();
            let mut gp = Posterior::new(prior, points, count_c, count_w);
            batch.iter().for_each(|&c| assert!(gp.add(c)));
            gp
        };
        let mut batch = vec![0, 1, 2, 3, 4, 5];
        let mut chosen = vec![false; count_c];
        batch.iter().for_each(|&c| chosen[c] = true);
        let mut gp = process(&batch);
        let mut criterion = vec![gp.criterion()];
        let mut swaps = 0;
        for _ in 0..5 {
            let made = pass(&mut gp, &mut batch, &mut chosen);
            swaps += made;
            criterion.push(gp.criterion());
            if made == 0 {
                break;
            }
        }
        assert!(swaps > 0, "the first six candidates are not a local optimum");
        for w in criterion.windows(2) {
            assert!(w[1] <= w[0] * (1.0 + 1e-12), "criterion rose: {criterion:?}");
        }
        assert!(criterion.last().unwrap() < &(criterion[0] * (1.0 - MIN_IMPROVEMENT)), "{criterion:?}");
        let fresh = process(&batch).criterion();
        assert!((fresh - gp.criterion()).abs() <= 1e-9 * fresh, "updated {} vs fresh {fresh}", gp.criterion());
        assert_eq!(chosen.iter().filter(|c| **c).count(), batch.len());
        assert!(batch.iter().all(|&c| chosen[c]));
    }
}
