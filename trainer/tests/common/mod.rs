//! Helpers shared by the diagnose test files.

use rand::{Rng, SeedableRng};

/// Geometric errors of a real six-joint arm drawn from `seed`, in the order of
/// `nominal::dh_parameters::parameter_names(6)`: ±0.05° for angles, ±0.5 mm for lengths.
pub fn six_joint_geometric_errors(seed: u64) -> Vec<f64> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let deg = std::f64::consts::PI / 180.0;
    cbd_trainer::nominal::dh_parameters::parameter_names(6)
        .iter()
        .map(|s| {
            if s.starts_with("alpha") || s.starts_with("theta") || s.starts_with("base_r") {
                rng.gen_range(-0.05..0.05) * deg
            } else {
                rng.gen_range(-0.5..0.5)
            }
        })
        .collect()
}
