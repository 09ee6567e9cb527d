//! Where the evidence search starts, and the box it stays in, from scales of the data: the
//! residual's variance, the mean |Dk0|² and the joints' spread.

use super::table::{PairTable, Theta};

/// Scales of the data that set the starts and the bounds (normalised units, logs where named so).
pub(super) struct DataScales {
    /// Residual variance per coordinate.
    var_r: f64,
    /// γ_V that gives the joint field half the residual's variance.
    gamma_v0: f64,
    /// Per axis, the log parameter (periodic b, Gaussian ℓ) at which typical pairs of rows have kernel ½.
    log_half: Vec<f64>,
    /// ln of the median distance from a row's nominal position to its nearest other row's.
    log_spacing: f64,
}

impl DataScales {
    pub fn of(table: &PairTable) -> Self {
        let m = table.m;
        let var_r = table.fields_variance;
        let count = table.count;
        let mean_jj =
            (0..count).map(|i| table.jj[(i * (i + 1) / 2 + i) * m * m..][..m * m].iter().step_by(m + 1).sum::<f64>()).sum::<f64>()
                / (count * m) as f64;
        // Typical pairs (the mean over every pair) at kernel ½.
        let log_half = table.joint.half_kernel_log_widths(0..table.dist2.len());
        let gamma_v0 = (0.5 * var_r / mean_jj.max(1e-30)).ln();
        DataScales { var_r, gamma_v0, log_half, log_spacing: median_spacing(table).ln() }
    }

    /// Per axis, the log parameter at which typical pairs of rows have kernel ½.
    pub fn log_half(&self) -> &[f64] {
        &self.log_half
    }

    /// Joint widths shifted by `shift` in log weight (log b; ℓ moves by half as much the other way).
    fn widths(&self, table: &PairTable, shift: f64) -> Vec<f64> {
        table.joint.forms.iter().zip(&self.log_half).map(|(f, l)| l + shift / f.log_weight_slope()).collect()
    }

    /// The four starts: balanced, smooth, nearly noise-free, rough.
    pub fn starts(&self, table: &PairTable) -> [Theta; 4] {
        let (var_r, gamma_v0) = (self.var_r, self.gamma_v0);
        [
            // Balanced: half the residual's variance to each field, noise a tenth.
            Theta {
                log_widths: self.widths(table, 0.0),
                log_gamma_v: gamma_v0,
                log_a: 0.0,
                log_gamma_w: (0.5 * var_r).ln(),
                log_sigma: 0.5 * (0.1 * var_r).ln(),
                config: None,
            },
            // Smooth: near-constant joint kernel (offsets and first harmonics) and a nearly affine task field.
            Theta {
                log_widths: self.widths(table, -4.0f64.ln() * 2.0),
                log_gamma_v: gamma_v0 + 100f64.ln(),
                log_a: 10f64.ln(),
                log_gamma_w: (100.0 * var_r).ln(),
                log_sigma: 0.5 * (1e-4 * var_r).ln(),
                config: None,
            },
            // Nearly noise-free: the balanced kernels, noise 1e-5 of the residual.
            Theta {
                log_widths: self.widths(table, 0.0),
                log_gamma_v: gamma_v0,
                log_a: 0.0,
                log_gamma_w: (0.5 * var_r).ln(),
                log_sigma: 0.5 * (1e-10 * var_r).ln(),
                config: None,
            },
            // Rough: narrow kernels, more noise.
            Theta {
                log_widths: self.widths(table, 4f64.ln()),
                log_gamma_v: gamma_v0,
                log_a: 0.3f64.ln(),
                log_gamma_w: (0.5 * var_r).ln(),
                log_sigma: 0.5 * (0.03 * var_r).ln(),
                config: None,
            },
        ]
    }

    /// The box θ stays in (lower, upper), packed like θ. The joint axes' each form's
    /// ([`crate::axis_forms::AxisForm::evidence_bounds`]: periodic b from 1e-5 to 1e3, Gaussian
    /// widths 1e±3 around the typical pair's), γ_V and γ_W from 1e-12 to 1e8 of the residual's
    /// scale, the task width from the rows' spacing (at least 1e-2) to 1e3, σ below.
    pub fn bounds(&self, table: &PairTable) -> (Vec<f64>, Vec<f64>) {
        let (n, var_r, gamma_v0) = (table.n, self.var_r, self.gamma_v0);
        let ln = |v: f64| v.ln();
        let mut lower = vec![0.0; n + 4];
        let mut upper = vec![0.0; n + 4];
        for d in 0..n {
            (lower[d], upper[d]) = table.joint.forms[d].evidence_bounds(self.log_half[d]);
        }
        (lower[n], upper[n]) = (gamma_v0 - ln(1e12), gamma_v0 + ln(1e8));
        // A task kernel narrower than the rows' spacing correlates almost no two measurements: the
        // evidence cannot tell it from noise, and a nearly equal basin where it stands in for σ (which
        // then drops to its floor) leaves no smooth task field — the six-joint arm with its geometry
        // marginalised: a = 8 mm, σ = 4e-7 mm, test error +12 %.
        (lower[n + 1], upper[n + 1]) = (ln(1e-2).max(self.log_spacing).min(ln(1e3)), ln(1e3));
        (lower[n + 2], upper[n + 2]) = (ln(var_r * 1e-12), ln(var_r * 1e8));
        // σ from 1e-8 of the residual's spread (and 1e-12 of the workspace) to three times it; a
        // residual below 1e-12 / √10 of the workspace (data a model fits exactly) leaves σ at the floor.
        let sigma_floor = (0.5 * ln(var_r * 1e-16)).max(ln(1e-12));
        (lower[n + 3], upper[n + 3]) = (sigma_floor, (0.5 * ln(var_r * 10.0)).max(sigma_floor));
        (lower, upper)
    }
}

/// The median over rows of the distance from a row's nominal position to the nearest other row's
/// (normalised units; 1e-2 for fewer than two rows or rows all at one point).
fn median_spacing(table: &PairTable) -> f64 {
    use crate::evidence::joint_pair_table::JointPairTable;
    let count = table.count;
    let mut nearest: Vec<f64> = (0..count)
        .map(|i| {
            (0..count)
                .filter(|&j| j != i)
                .map(|j| table.dist2[JointPairTable::pair_index(i.max(j), i.min(j))])
                .fold(f64::INFINITY, f64::min)
        })
        .filter(|d| d.is_finite() && *d > 0.0)
        .collect();
    if nearest.is_empty() {
        return 1e-2;
    }
    nearest.sort_by(f64::total_cmp);
    nearest[nearest.len() / 2].sqrt()
}
