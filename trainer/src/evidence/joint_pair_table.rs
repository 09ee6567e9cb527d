//! The joint kernel's exponent per pair of rows and axis, f_d = t_d(Δ_d) (each axis form's
//! [`AxisForm::pair_term`]: cos Δ_d − 1 periodic, −Δ_d²/2 Gaussian), so that the unit joint kernel
//! K̃_V = exp(Σ_d w_d f_d) (w_d the form's weight: b_d, or 1/ℓ_d²) costs one `exp` per pair at any
//! widths; and the widths at which typical pairs have kernel ½. Shared by CbD's evidence and the
//! kernel-ridge peer's search.

use crate::axis_forms::AxisForm;
use crate::data::Measurements;

/// Per pair of rows (lower triangle, i ≥ j, row-major) and per axis: f_d.
pub(crate) struct JointPairTable {
    pub n: usize,
    pub count: usize,
    /// Per axis: its form (periodic for a revolute joint, Gaussian for a prismatic one by default).
    pub forms: Vec<&'static dyn AxisForm>,
    /// Per pair, per axis: the form's term (cos Δ − 1 periodic, −Δ²/2 Gaussian).
    pub terms: Vec<f64>,
}

impl JointPairTable {
    pub fn new(forms: Vec<&'static dyn AxisForm>, data: &Measurements) -> Self {
        let (n, count) = (forms.len(), data.len());
        let mut terms = Vec::with_capacity(count * (count + 1) / 2 * n);
        for i in 0..count {
            let xi = data.joints(i);
            for j in 0..=i {
                let xj = data.joints(j);
                for d in 0..n {
                    let delta = xi[d] - xj[d];
                    terms.push(forms[d].pair_term(delta));
                }
            }
        }
        JointPairTable { n, count, forms, terms }
    }

    /// The index of pair (i, j) in the lower triangle, either order.
    pub fn pair_index(i: usize, j: usize) -> usize {
        let (hi, lo) = (i.max(j), i.min(j));
        hi * (hi + 1) / 2 + lo
    }

    /// f_d of pair `at`, every axis.
    pub fn terms_of(&self, at: usize) -> &[f64] {
        &self.terms[at * self.n..(at + 1) * self.n]
    }

    /// Exponent weight of axis d: b_d, or 1/ℓ_d² (the terms hold −Δ²/2).
    pub fn axis_weight(&self, d: usize, log_width: f64) -> f64 {
        self.forms[d].weight(log_width)
    }

    /// Every axis's weight at log widths (log b_d or log ℓ_d).
    pub fn axis_weights(&self, log_widths: &[f64]) -> Vec<f64> {
        (0..self.n).map(|d| self.axis_weight(d, log_widths[d])).collect()
    }

    /// K̃_V of pair `at` at axis weights `w`: exp(Σ_d w_d f_d).
    pub fn unit_kernel(&self, at: usize, w: &[f64]) -> f64 {
        self.terms_of(at).iter().zip(w).map(|(t, w)| t * w).sum::<f64>().exp()
    }

    /// Per axis, the log parameter (log b, log ℓ) at which typical pairs of rows have kernel ½ with
    /// that parameter on every axis: the mean of −f_d over `pairs` (pair indices) is the spread s_d,
    /// and b Σ_d s_d = ln 2 (periodic), Σ_d s_d / ℓ² = ln 2 (Gaussian).
    pub fn half_kernel_log_widths(&self, pairs: impl ExactSizeIterator<Item = usize>) -> Vec<f64> {
        let count = pairs.len() as f64;
        let mut spread = vec![0.0; self.n];
        for at in pairs {
            for (s, f) in spread.iter_mut().zip(self.terms_of(at)) {
                *s += -f / count;
            }
        }
        let total: f64 = spread.iter().sum::<f64>().max(1e-12);
        self.forms.iter().map(|f| f.half_kernel_log_parameter(total)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_half_kernel_widths_give_typical_pairs_kernel_one_half() {
        let configurations = crate::simulate::configurations(crate::simulate::Sampling::Uniform { count: 40, seed: 9 }, 2);
        let mut data = Measurements::new(2, 2);
        for q in configurations.chunks_exact(2) {
            data.push(q, &[0.0, 0.0]);
        }
        let (periodic, gaussian): (&'static dyn AxisForm, &'static dyn AxisForm) =
            (&crate::axis_forms::Periodic, &crate::axis_forms::Gaussian);
        for form in [periodic, gaussian] {
            let table = JointPairTable::new(vec![form; 2], &data);
            let pairs = table.terms.len() / 2;
            let log_width = table.half_kernel_log_widths(0..pairs)[0];
            let w = table.axis_weights(&[log_width, log_width]);
            // The mean exponent over the pairs is ln ½.
            let mean: f64 = (0..pairs).map(|at| table.unit_kernel(at, &w).ln()).sum::<f64>() / pairs as f64;
            assert!((mean - 0.5f64.ln()).abs() < 1e-12, "{}: {mean}", form.name());
            // Either order of a pair is the same pair.
            assert_eq!(JointPairTable::pair_index(7, 3), JointPairTable::pair_index(3, 7));
            let delta = data.joints(7)[1] - data.joints(3)[1];
            let expected = if form.periodic() { delta.cos() - 1.0 } else { -0.5 * delta * delta };
            assert_eq!(table.terms_of(JointPairTable::pair_index(3, 7))[1], expected);
        }
    }
}
