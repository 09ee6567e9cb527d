//! The kernel-ridge peer as a correction for the evaluation harnesses (`cbd compare`, the commanded
//! table): [`fit_kernel_ridge_peer`] on the base model given, its prediction, and what it chose.

use super::peer::fit_kernel_ridge_peer;
use super::selection::{Hyperparameters, SearchOptions};
use crate::data::Measurements;
use crate::evaluation::correction::FittedCorrection;
use cbd_protocol::NominalModel;

/// The kernel-ridge correction with hyperparameters by `search` (`crate::evaluation::correction::CorrectionFitter`).
pub fn kernel_ridge_correction(search: &SearchOptions) -> impl Fn(&NominalModel, &Measurements) -> crate::Result<FittedCorrection> + '_ {
    move |model: &NominalModel, data: &Measurements| -> crate::Result<FittedCorrection> {
        let peer = fit_kernel_ridge_peer(model, data, search)?;
        let (note, hyperparameters) = (describe(&peer.hyperparameters), Some(to_json(&peer.hyperparameters)));
        let (krr, model) = (peer.regression, model.clone());
        Ok(FittedCorrection {
            predict: Box::new(move |joints: &[f64]| krr.predict(&model, joints)),
            note,
            hyperparameters,
            noise_sigma: None,
        })
    }
}

/// One line: widths, γ, σ (normalised and in data units), the likelihood, the rows it is on and the
/// search's cost.
pub fn describe(h: &Hyperparameters) -> String {
    let widths: Vec<String> = h
        .kernel
        .axes
        .iter()
        .map(|a| {
            let (form, p) = crate::axis_forms::form_and_parameter(a);
            format!("{}={p:.3}", form.label())
        })
        .collect();
    let rows = match (&h.weight_space, &h.weight_space_declined) {
        (Some(w), _) => format!(
            "on {} rows (weight space, {} functions, {} evaluations, {:.2} s; from the kernel form's {} evaluations on {} rows, lml={:.2} there)",
            h.rows_used, w.weights, w.evaluations, w.seconds, h.evaluations, w.kernel_rows, w.kernel_log_marginal_likelihood
        ),
        (None, Some(why)) => format!("after {} evaluations on {} rows (every row declined: {why})", h.evaluations, h.rows_used),
        (None, None) => format!("after {} evaluations on {} rows", h.evaluations, h.rows_used),
    };
    format!(
        "{} gamma={:.3e} sigma={:.3e} (normalised, scale {:.4}; sigma {:.4e} in data units) lml={:.2} {rows}",
        widths.join(" "),
        h.kernel.gamma,
        h.noise_sigma,
        h.task_scale,
        h.noise_sigma_data_units(),
        h.log_marginal_likelihood,
    )
}

/// The `cbd compare --json` shape of the choice: `{"joint_axes": [{"periodic_b" | "gaussian_width"}],
/// "gamma", "noise_sigma", "noise_sigma_data_units", "task_scale", "log_marginal_likelihood", "rows_used",
/// "weight_space" (null, or the refinement on every row), "weight_space_declined", …}`.
pub fn to_json(h: &Hyperparameters) -> serde_json::Value {
    use serde_json::json;
    let widths: Vec<serde_json::Value> = h.kernel.axes.iter().map(crate::axis_forms::axis_json).collect();
    json!({
        "joint_axes": widths, "gamma": h.kernel.gamma, "noise_sigma": h.noise_sigma,
        "noise_sigma_data_units": h.noise_sigma_data_units(), "task_scale": h.task_scale,
        "log_marginal_likelihood": h.log_marginal_likelihood, "evaluations": h.evaluations, "rows_used": h.rows_used,
        "weight_space": h.weight_space, "weight_space_declined": h.weight_space_declined,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluation::compare::compare_peers;
    use crate::face::peers::{CBD, KRR};
    use crate::simulate::six_joint::{random_configurations, SixJointRobot};

    #[test]
    fn peers_on_the_simulated_six_joint_arm() {
        let robot = SixJointRobot::ur5_like(21);
        let train = robot.measure(&random_configurations(250, 22), 23);
        let test = robot.measure(&random_configurations(100, 24), 25);
        let search = SearchOptions { max_evaluations: 100, ..SearchOptions::default() };
        // A stand-in correction for the CbD hook: kernel ridge again, to check the plumbing.
        let krr = kernel_ridge_correction(&search);
        let c = compare_peers(&robot.nominal, &train, &test, &[KRR.with(&krr), CBD.with(&krr)]);
        let names: Vec<&str> = c.rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["nominal", "dh", "krr", "dh+krr", "cbd", "dh+cbd"]);
        let get = |n: &str| c.rows.iter().find(|r| r.name == n).unwrap().stats.mean;
        assert!(get("dh") < 0.2 * get("nominal"), "{:?}", c.rows);
        assert!(get("dh+krr") <= get("dh") * 1.05, "{:?}", c.rows);
        assert_eq!(get("dh+krr"), get("dh+cbd"));
        for r in &c.rows {
            errln!(
                "{:8} mean {:.4} median {:.4} p99 {:.4} max {:.4} fit {:.2}s  {}",
                r.name,
                r.stats.mean,
                r.stats.median,
                r.stats.p99,
                r.stats.max,
                r.fit_seconds,
                r.note
            );
        }
        let json = c.to_json();
        for name in ["nominal", "dh", "krr", "cbd", "dh+krr", "dh+cbd"] {
            for key in ["mean", "median", "p99", "max", "fit_seconds"] {
                assert!(json["methods"][name][key].is_number(), "{name}.{key}");
            }
        }
        for name in ["krr", "dh+krr"] {
            assert!(json["hyperparameters"][name]["joint_axes"][5]["periodic_b"].is_number(), "{name}");
        }
        assert!(c.table("mm").lines().count() == 7);
    }

    /// Issue 14: a planar model gets DH calibration (base, joint offsets, lengths) and the hybrids.
    #[test]
    fn peers_on_a_planar_arm_with_base_and_joint_offsets() {
        use crate::simulate::effects::EffectArm;
        use crate::simulate::{configurations, rr::planar_arm, Sampling};
        let arm = EffectArm::new(planar_arm(&[1.03, 0.48], [0.03, -0.02], 0.01, &[0.01, -0.02]));
        let train = arm.measure_planar(&configurations(Sampling::Uniform { count: 120, seed: 1 }, 2), 1e-4, 2);
        let test = arm.measure_planar(&configurations(Sampling::Uniform { count: 100, seed: 3 }, 2), 1e-4, 4);
        let search = SearchOptions { max_evaluations: 60, ..SearchOptions::default() };
        let krr = kernel_ridge_correction(&search);
        let nominal = NominalModel::planar(&[1.0, 0.5]).unwrap();
        let c = compare_peers(&nominal, &train, &test, &[KRR.with(&krr), CBD.with(&krr)]);
        let names: Vec<&str> = c.rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["nominal", "dh", "krr", "dh+krr", "cbd", "dh+cbd"]);
        let get = |n: &str| c.rows.iter().find(|r| r.name == n).unwrap().stats.mean;
        // Geometry is all there is: DH calibration reaches the noise (E|ε| = 1.25e-4).
        assert!(get("dh") < 2e-4 && get("nominal") > 100.0 * get("dh"), "{:?}", c.rows);
        for name in ["dh+krr", "dh+cbd"] {
            assert!(get(name) < 1.2 * get("dh"), "{name}: {:?}", c.rows);
        }
    }
}
