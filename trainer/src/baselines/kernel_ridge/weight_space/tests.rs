use super::super::fit::kernel_matrix;
use super::super::selection::{normalised_residual, profiled_lml};
use super::ResidualWeightSpace;
use crate::evidence::search::assert_gradient_matches_central_differences;
use crate::simulate::{add_noise, configurations, rr, Sampling};
use cbd_protocol::{JointKernel, JointKernelAxis};

/// Noisy RR rows (σ = 1e-4), residual normalised as the peer's search normalises it.
fn rr_rows(count: usize) -> (crate::data::Measurements, faer::Mat<f64>) {
    let mut data = rr::RealRr::default().measure(&configurations(Sampling::Uniform { count, seed: 11 }, 2));
    add_noise(&mut data.positions, 1e-4, 3);
    let scale = data.normalisation().task_scale;
    let residual = normalised_residual(&rr::nominal(), &data, scale);
    (data, residual)
}

/// (ln b_1, ln b_2, ln ν) near what the peer picks on such data.
fn centre() -> Vec<f64> {
    vec![0.5f64.ln(), 2.0f64.ln(), 1e-4f64.ln()]
}

/// The kernel form's profiled negative log likelihood and γ̂ at `p` (unit-γ kernel matrix plus ν I).
fn kernel_form(data: &crate::data::Measurements, residual: &faer::Mat<f64>, p: &[f64]) -> (f64, f64) {
    let axes = p[..2].iter().map(|lb| JointKernelAxis::Periodic { b: lb.exp() });
    let kernel = JointKernel { gamma: 1.0, axes: heapless::Vec::from_iter(axes) };
    let c = kernel_matrix(&kernel, &data.joints, &data.joints, 2);
    let (lml, gamma) = profiled_lml(&c, residual, p[2].exp()).unwrap();
    (-lml, gamma)
}

#[test]
fn weight_space_evidence_equals_the_kernel_form() {
    let (data, residual) = rr_rows(120);
    let p = centre();
    let ws = ResidualWeightSpace::new(&rr::nominal(), &data, &residual, &p, 4000).unwrap();
    // At the box's centre and inside it away from the centre (b up to 3 ×, wider, ν down to 1/9).
    let away = [vec![p[0] + 1.0, p[1] - 1.5, p[2] - 2.0], vec![p[0] - 2.0, p[1] + 1.0, p[2] + 3.0]];
    for q in std::iter::once(&p).chain(&away) {
        let w = ws.profiled(q).unwrap();
        let (nlml, gamma) = kernel_form(&data, &residual, q);
        errln!("at {q:?}: weight space {} − kernel form {nlml} = {:.2e} ({} functions)", w.nlml, w.nlml - nlml, ws.weights());
        assert!((w.nlml - nlml).abs() <= 0.01, "at {q:?}: weight space {} vs kernel form {nlml} ({} functions)", w.nlml, ws.weights());
        // γ̂ enters the value as (N m/2) ln γ̂: within the same 0.01 nats.
        assert!((w.gamma / gamma).ln().abs() <= 0.02 / (120.0 * 2.0), "γ̂ {} vs {gamma}", w.gamma);
    }
}

#[test]
fn weight_space_gradient_matches_finite_differences() {
    let (data, residual) = rr_rows(80);
    let p = centre();
    let ws = ResidualWeightSpace::new(&rr::nominal(), &data, &residual, &p, 4000).unwrap();
    // Away from the box's centre.
    assert_gradient_matches_central_differences(&ws, &[p[0] + 0.4, p[1] - 0.3, p[2] + 0.5], 1e-5);
}

#[test]
fn prismatic_joints_and_long_bases_are_declined() {
    let (data, residual) = rr_rows(20);
    let err = ResidualWeightSpace::new(&rr::nominal(), &data, &residual, &centre(), 10).err().unwrap().to_string();
    assert!(err.contains("limit 10"), "{err}");
    // A second joint that slides: its Gaussian kernel's functions would depend on its width.
    let text = r#"
length_unit = "m"
angle_unit = "rad"
[chain]
convention = "standard"
joints = [ { a = 1, alpha = 0, d = 0 }, { a = 0.5, alpha = 0, d = 0, kind = "prismatic" } ]
"#;
    let prismatic = crate::data::model_file::parse_model_file(text, std::path::Path::new("p.toml")).unwrap().nominal;
    let err = ResidualWeightSpace::new(&prismatic, &data, &residual, &centre(), 4000).err().unwrap().to_string();
    assert!(err.contains("joint 2 is prismatic"), "{err}");
}

/// Probe (diagnosis, not a check): the peer's refinement on every row of the noisy RR grid
/// (`PROBE_GRID`², default 64², the bench's noise seed) restarted from its choice with the widths
/// scaled by each of `PROBE_FACTORS` (default 0.1,0.3,3,10): does it come back to the same optimum?
/// Measured at 64²: from × 0.3, 3, 10 to 64588.387 (the choice's), from × 0.1 it stops at 57643.52.
#[test]
#[ignore]
fn probe_krr_basins() {
    use super::super::selection::{choose_kernel_ridge_hyperparameters, SearchOptions};
    let per_axis: usize = std::env::var("PROBE_GRID").ok().map_or(64, |s| s.parse().unwrap());
    let factors: Vec<f64> =
        std::env::var("PROBE_FACTORS").ok().map_or(vec![0.1, 0.3, 3.0, 10.0], |s| s.split(',').map(|v| v.parse().unwrap()).collect());
    let mut data = rr::RealRr::default().measure(&configurations(Sampling::Grid { per_axis }, 2));
    add_noise(&mut data.positions, 1e-4, 1u64.wrapping_add(0x5eed));
    let nominal = rr::nominal();
    let options = SearchOptions::default();
    let h = choose_kernel_ridge_hyperparameters(&nominal, &data, &options).unwrap();
    println!("choice: {}", super::super::correction::describe(&h));
    let residual = normalised_residual(&nominal, &data, h.task_scale);
    let b: Vec<f64> = h.kernel.axes.iter().map(|a| if let JointKernelAxis::Periodic { b } = a { *b } else { f64::NAN }).collect();
    let log_ratio = (h.ridge() / h.kernel.gamma).ln();
    let (lower, upper) = (
        vec![options.b_range.0.ln(), options.b_range.0.ln(), options.noise_ratio_range.0.ln()],
        vec![options.b_range.1.ln(), options.b_range.1.ln(), options.noise_ratio_range.1.ln()],
    );
    let test = rr::RealRr::default().measure(&configurations(Sampling::Uniform { count: 3000, seed: 7 }, 2));
    let test_mean = |kernel: JointKernel, ridge: f64| {
        let krr = super::super::KernelRidge::fit(&nominal, &data, kernel, ridge).unwrap();
        crate::report::stats::ErrorStats::of_positions(&krr.predict(&nominal, &test.joints), &test.positions, 2).mean
    };
    println!("  test mean {:.4e}", test_mean(h.kernel.clone(), h.ridge()));
    for f in factors {
        let start = vec![(b[0] * f).ln(), (b[1] * f).ln(), log_ratio];
        match super::refine(&nominal, &data, &residual, &start, &lower, &upper, 6000, (0, f64::NAN)) {
            Ok(r) => {
                let axes = r.param[..2].iter().map(|lb| JointKernelAxis::Periodic { b: lb.exp() });
                let kernel = JointKernel { gamma: r.gamma, axes: heapless::Vec::from_iter(axes) };
                println!(
                    "b×{f}: lml {:.3} b [{:.4e} {:.4e}] γ {:.4e} ν {:.4e}, {} functions, {} rounds, {} evaluations; test mean {:.4e}",
                    -r.nlml,
                    r.param[0].exp(),
                    r.param[1].exp(),
                    r.gamma,
                    r.param[2].exp(),
                    r.report.weights,
                    r.report.rounds,
                    r.report.evaluations,
                    test_mean(kernel, r.param[2].exp() * r.gamma)
                )
            }
            Err(why) => println!("b×{f}: {why}"),
        }
    }
}
