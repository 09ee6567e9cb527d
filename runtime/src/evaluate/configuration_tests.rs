//! The configuration-dependent task field (format 8, docs/DESIGN.md §16) through every evaluating
//! entry, against independent checks: the position's change is Σ_j c_j K_X P_j by a direct formula
//! (libm), the exact Jacobian against central differences of the position (flat and Gaussian K_X,
//! periodic and Gaussian axes), a vanishing γ_C gives the plain model, compensation converges, and
//! a blob with the term loads and evaluates as the model it encodes.

#![allow(clippy::needless_range_loop)]

extern crate std;
use crate::evaluate::Evaluation;
use crate::load::Calibrator;
use crate::load::{from_model, storage_len_for};
use crate::real::Real;
use cbd_protocol::*;
use heapless::Vec as HVec;
use std::vec;
use std::vec::Vec;

/// Pseudo-random values in [−1, 1).
fn sequence(count: usize, seed: u32) -> Vec<f64> {
    let mut s = seed;
    (0..count)
        .map(|_| {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            2.0 * ((s >> 8) as f64 / 16_777_216.0) - 1.0
        })
        .collect()
}

fn le_bytes(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// A six-joint DH chain with a prismatic third joint (as tests/tests/cross_crate/exact_jacobian.rs).
fn six_joint() -> NominalModel {
    let j = |kind, a: f64, alpha: f64, d: f64| DhJoint { kind, a, alpha, d, theta_offset: 0.1 };
    let mut tool = Transform::IDENTITY;
    tool.translation = [10.0, 20.0, 31.0];
    NominalModel::DhChain(DhChain {
        convention: DhConvention::Standard,
        joints: HVec::from_slice(&[
            j(JointKind::Revolute, 0.0, core::f64::consts::FRAC_PI_2, 89.0),
            j(JointKind::Revolute, -425.0, 0.0, 0.0),
            j(JointKind::Prismatic, -392.0, 0.2, 0.0),
            j(JointKind::Revolute, 0.0, core::f64::consts::FRAC_PI_2, 109.0),
            j(JointKind::Revolute, 0.0, -core::f64::consts::FRAC_PI_2, 94.0),
            j(JointKind::Revolute, 0.0, 0.0, 82.0),
        ])
        .unwrap(),
        base: Transform::IDENTITY,
        tool,
        effects: Effects::NONE,
        tool_points: HVec::new(),
    })
}

/// The data of one test model: points and momenta (bytes), and its kernels.
struct Case {
    nominal: NominalModel,
    normalisation: Normalisation,
    joint_axes: Vec<JointKernelAxis>,
    configuration_axes: Vec<JointKernelAxis>,
    points: Vec<u8>,
    momenta: Vec<u8>,
    n_points: usize,
}

/// `count` configurations (the prismatic joint within ±100 of 0), momenta of size `p_scale`.
fn case(six: bool, count: usize, p_scale: f64) -> Case {
    let (nominal, normalisation, n) = if six {
        (six_joint(), Normalisation { task_offset: [0.0, 0.0, 300.0], task_scale: 500.0 }, 6)
    } else {
        (NominalModel::planar(&cbd_protocol::paper_rr::LENGTHS).unwrap(), Normalisation::IDENTITY, 2)
    };
    let mut x = sequence(count * n, 0x00c0_ffee + n as u32);
    for (i, v) in x.iter_mut().enumerate() {
        *v *= if six && i % n == 2 { 100.0 } else { core::f64::consts::PI };
    }
    let m = if six { 3 } else { 2 };
    let p: Vec<f64> = sequence(count * m, 0x0bad_5eed).iter().map(|v| p_scale * v).collect();
    let axes = |b: f64, width: f64| -> Vec<JointKernelAxis> {
        (0..n)
            .map(|d| if six && d == 2 { JointKernelAxis::Gaussian { width } } else { JointKernelAxis::Periodic { b: b + 0.1 * d as f64 } })
            .collect()
    };
    Case {
        nominal,
        normalisation,
        joint_axes: axes(0.6, 80.0),
        configuration_axes: axes(1.4, 45.0),
        points: le_bytes(&x),
        momenta: le_bytes(&p),
        n_points: count,
    }
}

impl Case {
    /// The model, Euler × 1, with the configuration kernel `kernel` (γ_C, task width) or without.
    fn model(&self, kernel: Option<(f64, Option<f64>)>) -> Model<'_> {
        Model {
            nominal: self.nominal.clone(),
            normalisation: self.normalisation.clone(),
            joint_kernel: JointKernel { gamma: 0.7, axes: HVec::from_slice(&self.joint_axes).unwrap() },
            task_kernel: TaskKernel { width: 0.9 },
            integrator: Integrator { method: IntegratorMethod::Euler, steps: 1 },
            momentum_law: MomentumLaw::Hamiltonian,
            sigma: 1.0,
            n_points: self.n_points as u32,
            points: F64Slice::from_le_bytes(&self.points),
            momenta: F64Slice::from_le_bytes(&self.momenta),
            expansion: None,
            noise_sigma: Some(0.01),
            configuration_kernel: kernel.map(|(gamma, task_width)| ConfigurationKernel {
                gamma,
                axes: HVec::from_slice(&self.configuration_axes).unwrap(),
                task_width,
            }),
            drift: None,
            provenance: None,
        }
    }

    /// Query configurations near the data's range.
    fn queries(&self, count: usize) -> Vec<Vec<f64>> {
        let n = self.joint_axes.len();
        let v = sequence(count * n, 0x0001_0203 + n as u32);
        v.chunks(n).map(|q| q.iter().enumerate().map(|(d, x)| if n == 6 && d == 2 { 90.0 * x } else { 2.5 * x }).collect()).collect()
    }
}

/// Evaluates `model` at every query (exact Jacobian).
fn evaluations(model: Model<'_>, queries: &[Vec<f64>]) -> Vec<Evaluation> {
    let mut storage = vec![0.0 as Real; storage_len_for(&model)];
    let mut cal = from_model(model, &mut storage).unwrap();
    queries.iter().map(|q| crate::evaluate::evaluate(&mut cal, q).unwrap()).collect()
}

/// The direct formula of the term at ξ, internal units: Σ_j c_j(ξ) K_X(k0(ξ), k_j) P_j with
/// c_j = γ_C exp(Σ_d f_d(ξ_d − q_jd)) (f_d = b (cos Δ − 1) or −Δ²/(2ℓ²)) and K_X Gaussian or 1;
/// returns the term and Σ_j |c_j K_X P_j| (its rounding scale).
fn direct_term(case: &Case, model: &Model<'_>, q: &[f64]) -> ([f64; 3], f64) {
    let c = model.configuration_kernel.as_ref().unwrap();
    let (n, m) = (model.n_joints(), model.task_dim());
    let k0 = |x: &[f64]| crate::kinematics::forward_kinematics(&case.nominal, x).normalised(&case.normalisation).position;
    let kq = k0(q);
    let (mut sum, mut scale) = ([0.0; 3], 0.0);
    for j in 0..case.n_points {
        let x: Vec<f64> = (0..n).map(|d| model.points.get(j * n + d).unwrap()).collect();
        let mut exponent = 0.0;
        for (d, axis) in c.axes.iter().enumerate() {
            let delta = q[d] - x[d];
            exponent += match *axis {
                JointKernelAxis::Periodic { b } => b * (libm::cos(delta) - 1.0),
                JointKernelAxis::Gaussian { width } => -delta * delta / (2.0 * width * width),
            };
        }
        let cj = c.gamma * libm::exp(exponent);
        let kj = k0(&x);
        let r2: f64 = (0..m).map(|a| (kq[a] - kj[a]) * (kq[a] - kj[a])).sum();
        let kx = c.task_width.map_or(1.0, |a| libm::exp(-r2 / (2.0 * a * a)));
        for (a, s) in sum.iter_mut().enumerate().take(m) {
            let term = cj * kx * model.momenta.get(j * m + a).unwrap();
            *s += term;
            scale += libm::fabs(term);
        }
    }
    (sum, scale)
}

/// Relative accuracy of the build's arithmetic (f64, or the `f32` feature).
// A cast from f64 to f64 in the default build, from f32 with the feature `f32`.
#[allow(clippy::unnecessary_cast)]
fn tolerance() -> f64 {
    1e3 * Real::EPSILON as f64
}

#[test]
fn the_position_moves_by_the_direct_formula_of_the_term() {
    for six in [false, true] {
        let case = case(six, 24, 0.05);
        let queries = case.queries(12);
        let plain = evaluations(case.model(None), &queries);
        for width in [None, Some(0.7)] {
            let model = case.model(Some((0.8, width)));
            let with = evaluations(case.model(Some((0.8, width))), &queries);
            let s = case.normalisation.task_scale;
            let mut largest: f64 = 0.0;
            for ((q, a), b) in queries.iter().zip(&with).zip(&plain) {
                let (term, scale) = direct_term(&case, &model, q);
                // Rounding: of the term's sum, and of the positions themselves (radius ~ 1 internal).
                let allowed = tolerance() * s * (scale + 2.0);
                for r in 0..model.task_dim() {
                    let diff = a.position()[r] - b.position()[r];
                    assert!((diff - s * term[r]).abs() <= allowed, "six {six} width {width:?} axis {r}: {diff} vs {}", s * term[r]);
                    largest = largest.max(libm::fabs(diff));
                }
            }
            // The term is visible (not lost below the check's tolerance).
            assert!(largest > 1e-4 * s, "six {six} width {width:?}: the term moved the position by {largest} only");
        }
    }
}

#[cfg(not(feature = "f32"))]
#[test]
fn the_exact_jacobian_matches_central_differences_with_the_term() {
    for six in [false, true] {
        let case = case(six, 24, 0.05);
        let queries = case.queries(6);
        for width in [None, Some(0.7)] {
            let model = case.model(Some((0.8, width)));
            let mut storage = vec![0.0 as Real; storage_len_for(&model)];
            let mut cal = from_model(model, &mut storage).unwrap();
            let (mut worst, mut explicit): (f64, f64) = (0.0, 0.0);
            for q in &queries {
                let e = cal.evaluate(q).unwrap();
                let transported = cal.evaluate_transported(q).unwrap();
                // The position is the same computation with and without tangents.
                assert_eq!(
                    e.position().iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    transported.position().iter().map(|v| v.to_bits()).collect::<Vec<_>>()
                );
                let scale = e.jacobian().iter().fold(0.0f64, |s, v| s.max(v.abs()));
                for d in 0..q.len() {
                    // Steps relative to the axis (the prismatic joint is in mm).
                    let h = if six && d == 2 { 1e-4 } else { 1e-6 };
                    let (mut qa, mut qb) = (q.clone(), q.clone());
                    qa[d] += h;
                    qb[d] -= h;
                    let (ya, yb) = (cal.evaluate(&qa).unwrap(), cal.evaluate(&qb).unwrap());
                    for r in 0..ya.position().len() {
                        let fd = (ya.position()[r] - yb.position()[r]) / (2.0 * h);
                        worst = worst.max((fd - e.jacobian()[(r, d)]).abs() / scale);
                        explicit = explicit.max((fd - e.transported_jacobian()[(r, d)]).abs() / scale);
                    }
                }
            }
            assert!(worst < 1e-7, "six {six} width {width:?}: exact Jacobian off by {worst:e}");
            // The check can see the term: the transported J (no explicit ∂_ξ w) is far off.
            assert!(explicit > 1e-3, "six {six} width {width:?}: transported J within {explicit:e}");
        }
    }
}

#[cfg(not(feature = "f32"))]
#[test]
fn a_vanishing_configuration_kernel_gives_the_plain_model() {
    let case = case(true, 24, 0.05);
    let queries = case.queries(8);
    let plain = evaluations(case.model(None), &queries);
    let gap = |gamma: f64, width: Option<f64>| -> f64 {
        let with = evaluations(case.model(Some((gamma, width))), &queries);
        let mut worst: f64 = 0.0;
        for (a, b) in with.iter().zip(&plain) {
            for (x, y) in a.position().iter().chain(a.jacobian().iter()).zip(b.position().iter().chain(b.jacobian().iter())) {
                worst = worst.max((x - y).abs());
            }
        }
        worst
    };
    for width in [None, Some(0.7)] {
        // Linear in γ_C, down to rounding.
        let (g2, g4) = (gap(1e-2, width), gap(1e-4, width));
        assert!(g2 > 0.0 && (g2 / g4 - 100.0).abs() < 1.0, "width {width:?}: gaps {g2:e} {g4:e}");
        assert!(gap(1e-30, width) < 1e-9, "width {width:?}: γ_C = 1e-30 off by {:e}", gap(1e-30, width));
    }
}

#[test]
fn compensation_converges_with_the_term() {
    for width in [None, Some(0.7)] {
        let case = case(true, 24, 0.05);
        let model = case.model(Some((0.8, width)));
        let mut storage = vec![0.0 as Real; storage_len_for(&model)];
        let mut cal = from_model(model, &mut storage).unwrap();
        for q in case.queries(8) {
            let target: Vec<f64> = cal.evaluate(&q).unwrap().position().iter().copied().collect();
            let seed: Vec<f64> = q.iter().enumerate().map(|(d, v)| v + if d == 2 { 2.0 } else { 0.02 }).collect();
            let mut out = [0.0; 6];
            let c = cal.compensate(&target, &seed, &mut out).unwrap();
            let reached: Vec<f64> = cal.evaluate(&out).unwrap().position().iter().copied().collect();
            let miss = reached.iter().zip(&target).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(c.reached, "width {width:?} q {q:?}: residual {} (miss {miss})", c.residual);
            assert!(miss <= 2.0 * cal.precision().max(1e-9 * 500.0), "width {width:?}: miss {miss}");
        }
    }
}

#[test]
fn a_blob_with_the_term_loads_and_evaluates_as_its_model() {
    let case = case(false, 16, 0.05);
    let model = case.model(Some((0.8, Some(0.7))));
    let mut blob = [0u8; 4096];
    let len = encode(&model, &mut blob).unwrap();
    let needed = storage_len_for(&model);
    // The configuration rows are sized in: N × (1 + n) beyond the plain model's storage.
    assert_eq!(needed, storage_len_for(&case.model(None)) + 16 * 3);
    let mut storage = vec![0.0 as Real; needed];
    let mut cal = Calibrator::load(&blob[..len], &mut storage).unwrap();
    let queries = case.queries(4);
    let direct = evaluations(case.model(Some((0.8, Some(0.7)))), &queries);
    for (q, e) in queries.iter().zip(&direct) {
        assert_eq!(cal.evaluate(q).unwrap(), *e);
    }
    // One value short is refused, not overrun.
    let mut short = vec![0.0 as Real; needed - 1];
    assert!(matches!(Calibrator::load(&blob[..len], &mut short), Err(crate::error::Error::StorageTooSmall { .. })));
}
