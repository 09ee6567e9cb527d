use super::super::search::Criterion;
use super::super::table::{PairTable, Theta};
use super::WeightSpaceTable;
use crate::simulate::{configurations, rr, Sampling};

/// θ near what the evidence picks on noisy RR data (flat joint kernels, a wide task kernel).
fn theta() -> Theta {
    Theta { log_widths: vec![0.05f64.ln(), 0.02f64.ln()], log_gamma_v: -6.0, log_a: 2.0f64.ln(), log_gamma_w: -7.0, log_sigma: -8.0 }
}

fn rr_rows(count: usize) -> crate::data::Measurements {
    rr::RealRr::default().measure(&configurations(Sampling::Uniform { count, seed: 11 }, 2))
}

#[test]
fn weight_space_evidence_equals_the_kernel_form() {
    let data = rr_rows(60);
    let norm = crate::evidence::normalisation_of(&data);
    let p = theta().pack();
    let ws = WeightSpaceTable::new(&rr::nominal(), &data, &norm, &p, 4000).unwrap();
    let kernel = PairTable::new(&rr::nominal(), &data, &norm);
    let (a, _) = ws.nlml_and_gradient(&p).unwrap();
    let (b, _) = kernel.nlml_and_gradient(&p).unwrap();
    // The truncation drops ≤ 1e-2 σ² of prior variance per coordinate: far below a nat (measured: 6e-4 of 11811).
    assert!((a - b).abs() <= 0.01, "weight space {a} vs kernel form {b} ({} weights)", ws.weights());
    // And at a θ inside the box but away from its centre.
    let mut q = theta();
    q.log_widths[0] += 0.7;
    q.log_a -= 0.3;
    q.log_sigma += 0.5;
    let (a, _) = ws.nlml_and_gradient(&q.pack()).unwrap();
    let (b, _) = kernel.nlml_and_gradient(&q.pack()).unwrap();
    assert!((a - b).abs() <= 0.01, "off centre: weight space {a} vs kernel form {b}");
}

#[test]
fn weight_space_gradient_matches_finite_differences() {
    let data = rr_rows(40);
    let norm = crate::evidence::normalisation_of(&data);
    let p = theta().pack();
    let ws = WeightSpaceTable::new(&rr::nominal(), &data, &norm, &p, 4000).unwrap();
    let (_, grad) = ws.nlml_and_gradient(&p).unwrap();
    for k in 0..p.len() {
        let h = 1e-5;
        let (mut up, mut down) = (p.clone(), p.clone());
        up[k] += h;
        down[k] -= h;
        let fd = (ws.nlml_and_gradient(&up).unwrap().0 - ws.nlml_and_gradient(&down).unwrap().0) / (2.0 * h);
        assert!((fd - grad[k]).abs() <= 1e-5 * fd.abs().max(1.0), "θ[{k}]: analytic {} vs finite differences {fd}", grad[k]);
    }
}

#[test]
fn prismatic_joints_and_long_bases_are_declined() {
    let data = rr_rows(20);
    let norm = crate::evidence::normalisation_of(&data);
    // Narrow joint kernels need many functions: more than a small limit allows.
    let mut narrow = theta();
    narrow.log_widths = vec![20f64.ln(), 20f64.ln()];
    let err = WeightSpaceTable::new(&rr::nominal(), &data, &norm, &narrow.pack(), 50).err().unwrap().to_string();
    assert!(err.contains("limit 50"), "{err}");
}
