//! The noise floor of an error table: the mean distance between a perfect model's predictions and
//! measurements carrying isotropic Gaussian noise of σ per coordinate — what no model, however much
//! data or how many effects it names, can go below on those rows — and whether a method is at it.

use serde::Serialize;

/// Above the floor by at most this fraction, plus two standard errors of the rows' mean, a method
/// is "at the floor": a model fitted on N rows with p effective parameters predicts new rows with
/// error variance about σ² (1 + p/N), 5–10 % above the floor's mean error for p/N ≈ 0.1–0.2.
pub const AT_FLOOR_MARGIN: f64 = 0.1;

/// The floor for noise σ per coordinate in `m` coordinates.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NoiseFloor {
    /// σ per coordinate (data length unit).
    pub sigma: f64,
    /// Coordinates per point.
    pub dimension: usize,
    /// E|ε| of ε ~ N(0, σ² I_m): 1-D σ √(2/π), 2-D σ √(π/2), 3-D 2σ √(2/π).
    pub mean_error: f64,
    /// Where σ comes from ("CbD's evidence on the training rows", …).
    pub source: String,
}

/// A method's mean error against the floor.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FloorVerdict {
    /// Mean error / the floor's mean error.
    pub ratio: f64,
    pub at_floor: bool,
}

impl NoiseFloor {
    /// The floor of σ per coordinate in `dimension` coordinates (1 to 3).
    pub fn new(sigma: f64, dimension: usize, source: impl Into<String>) -> Self {
        use std::f64::consts::PI;
        let factor = match dimension {
            1 => (2.0 / PI).sqrt(),
            2 => (PI / 2.0).sqrt(),
            // Three (or more, not used) coordinates: the chi distribution's mean with 3 degrees.
            _ => 2.0 * (2.0 / PI).sqrt(),
        };
        NoiseFloor { sigma, dimension, mean_error: factor * sigma, source: source.into() }
    }

    /// Standard deviation of one point's error distance |ε| over the floor's mean: √(m − E|ε|²/σ²) / (E|ε|/σ).
    fn relative_spread(&self) -> f64 {
        let mean = self.mean_error / self.sigma;
        ((self.dimension as f64 - mean * mean).max(0.0)).sqrt() / mean
    }

    /// Whether a mean error over `rows` rows is at the floor: at most [`AT_FLOOR_MARGIN`] above it
    /// plus two standard errors of a mean of `rows` distances.
    pub fn verdict(&self, mean: f64, rows: usize) -> FloorVerdict {
        let ratio = mean / self.mean_error;
        let spread = 2.0 * self.relative_spread() / (rows.max(1) as f64).sqrt();
        FloorVerdict { ratio, at_floor: ratio <= 1.0 + AT_FLOOR_MARGIN + spread }
    }

    /// The largest mean error over `rows` rows that [`NoiseFloor::verdict`] still calls at the
    /// floor: the top of the floor's band (`cbd report --checks`).
    pub fn at_floor_limit(&self, rows: usize) -> f64 {
        let spread = 2.0 * self.relative_spread() / (rows.max(1) as f64).sqrt();
        self.mean_error * (1.0 + AT_FLOOR_MARGIN + spread)
    }

    /// Whether a root-mean-square distance over `rows` rows (a cross-validation's held-out RMS) is at
    /// the floor's, √m σ: the same margin, plus two standard errors of an RMS of `rows` Gaussian
    /// distances (1/√(2 m rows) relative).
    pub fn verdict_rms(&self, rms: f64, rows: usize) -> FloorVerdict {
        let ratio = rms / ((self.dimension as f64).sqrt() * self.sigma);
        let spread = 2.0 / (2.0 * (self.dimension * rows.max(1)) as f64).sqrt();
        FloorVerdict { ratio, at_floor: ratio <= 1.0 + AT_FLOOR_MARGIN + spread }
    }

    /// One line: σ, where it comes from and the floor's mean error.
    pub fn describe(&self, unit: &str) -> String {
        format!(
            "noise floor: σ = {:.4e} {unit} per coordinate ({}) → a perfect model's mean error {:.4e} {unit} on these rows",
            self.sigma, self.source, self.mean_error
        )
    }
}

impl FloorVerdict {
    /// "at the floor" or "× r above it", with what to do about it.
    pub fn describe(&self) -> String {
        if !self.ratio.is_finite() {
            format!("no ratio to the floor ({}): no verdict", self.ratio)
        } else if self.at_floor {
            format!("{} × floor: at the noise floor (more data or effects will not help)", ratio_text(self.ratio))
        } else {
            format!("{} × floor: structure left (try `cbd diagnose`)", ratio_text(self.ratio))
        }
    }

    /// Writes the verdict into a JSON row: `floor_ratio` and `at_floor`, or — for a figure that is
    /// not a number (a failed method) — both `null` and `"failed": true`: no verdict on it.
    pub fn write_json(&self, row: &mut serde_json::Value) {
        if self.ratio.is_finite() {
            row["floor_ratio"] = serde_json::json!(self.ratio);
            row["at_floor"] = serde_json::json!(self.at_floor);
        } else {
            row["floor_ratio"] = serde_json::Value::Null;
            row["at_floor"] = serde_json::Value::Null;
            row["failed"] = serde_json::json!(true);
        }
    }

    /// A short table cell: "1.04 =" (at the floor) / "12.10 >" (above it); "failed" for a figure
    /// that is not a number (a method that failed): no verdict on it.
    pub fn cell(&self) -> String {
        if !self.ratio.is_finite() {
            return "failed".into();
        }
        format!("{}{}", ratio_text(self.ratio), if self.at_floor { " =" } else { " >" })
    }
}

/// A ratio to the floor as lines and cells print it: two decimals from 0.01 to 10⁶, three
/// significant digits beyond (`2.67e26`, `1.25e-30`, not 27 digits or `0.00`).
fn ratio_text(ratio: f64) -> String {
    if ratio == 0.0 || (0.01..1e6).contains(&ratio.abs()) {
        format!("{ratio:.2}")
    } else {
        format!("{ratio:.2e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The floor's mean error against the sample mean of simulated noise distances, in 1, 2 and 3
    /// coordinates (200 000 draws: within 0.5 %).
    #[test]
    fn the_floor_is_the_mean_distance_of_gaussian_noise() {
        for m in 1..=3 {
            let floor = NoiseFloor::new(0.02, m, "test");
            let n = 200_000;
            // The simulators' own noise.
            let mut noise = vec![0.0; n * m];
            crate::simulate::add_noise(&mut noise, 0.02, 3 + m as u64);
            let mean = noise.chunks_exact(m).map(|e| e.iter().map(|v| v * v).sum::<f64>().sqrt()).sum::<f64>() / n as f64;
            assert!((mean / floor.mean_error - 1.0).abs() < 5e-3, "m = {m}: sample {mean} vs floor {}", floor.mean_error);
            // Pure noise over 1000 rows is at the floor; 1.3 × it is not.
            assert!(floor.verdict(mean, 1000).at_floor);
            assert!(!floor.verdict(1.3 * floor.mean_error, 1000).at_floor);
            let rms = (noise.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
            let v = floor.verdict_rms(rms, n);
            assert!(v.at_floor && (v.ratio - 1.0).abs() < 5e-3, "m = {m}: RMS ratio {}", v.ratio);
        }
    }

    /// Issue 51 classes 3 and 4: a ratio far from 1 prints in three significant digits (not 27
    /// digits, not `0.00`); a ratio that is not a number (a failed method) gets no verdict.
    #[test]
    fn ratios_print_readably_and_a_failed_figure_gets_no_verdict() {
        let floor = NoiseFloor::new(1e-30, 3, "test");
        let v = floor.verdict(1e-3, 100);
        assert!(v.describe().starts_with("6.27e26 × floor: structure left"), "{}", v.describe());
        assert_eq!(NoiseFloor::new(1e30, 3, "test").verdict(1e-3, 100).cell(), "6.27e-34 =");
        assert_eq!(NoiseFloor::new(1.0, 3, "test").verdict(1.5957691216057308, 100).cell(), "1.00 =");
        let failed = floor.verdict(f64::NAN, 100);
        assert_eq!(failed.cell(), "failed");
        let mut row = serde_json::json!({"mean": f64::NAN});
        failed.write_json(&mut row);
        assert_eq!(row, serde_json::json!({"mean": null, "floor_ratio": null, "at_floor": null, "failed": true}));
        assert!(failed.describe().contains("no verdict") && !failed.describe().contains('>'), "{}", failed.describe());
    }
}
