//! The runtime's Jacobians against central differences of its own positions: the one check the
//! subjects exact_jacobian, expansion and effects each apply to their blobs.

use cbd_runtime::Calibrator;

/// Largest |central difference (step `h`) − Jacobian| / max |Dk1| over `queries` and the joints:
/// (the exact Jacobian's, the transported J(1)'s). The transported evaluation's position must be the
/// exact one's bit for bit (the same computation), and is asserted so.
pub fn worst_jacobian_errors(cal: &mut Calibrator<'_>, queries: &[Vec<f64>], h: f64) -> (f64, f64) {
    let (mut worst_exact, mut worst_transported): (f64, f64) = (0.0, 0.0);
    for q in queries {
        let plain = cal.evaluate_transported(q).unwrap();
        let e = cal.evaluate(q).unwrap();
        assert_eq!(
            plain.position().iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            e.position().iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        let scale = e.jacobian().iter().fold(0.0f64, |s, v| s.max(v.abs()));
        for d in 0..q.len() {
            let (mut qa, mut qb) = (q.clone(), q.clone());
            qa[d] += h;
            qb[d] -= h;
            let ya: Vec<f64> = cal.evaluate(&qa).unwrap().position().iter().copied().collect();
            let yb: Vec<f64> = cal.evaluate(&qb).unwrap().position().iter().copied().collect();
            for r in 0..ya.len() {
                let fd = (ya[r] - yb[r]) / (2.0 * h);
                worst_exact = worst_exact.max((fd - e.jacobian()[(r, d)]).abs() / scale);
                worst_transported = worst_transported.max((fd - e.transported_jacobian()[(r, d)]).abs() / scale);
            }
        }
    }
    (worst_exact, worst_transported)
}
