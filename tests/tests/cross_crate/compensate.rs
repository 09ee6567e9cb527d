//! Compensation (`Calibrator::compensate`): k1(compensate(x)) = x for reachable targets, checked by
//! evaluating k1 at the returned command independently of the residual compensate reports; bad
//! input (NaN/inf, wrong lengths), unreachable targets and singular seeds flagged, never a panic.

use cbd_protocol::*;
use cbd_runtime::internals::inverse_kinematics::nominal_position;
use cbd_runtime::{Calibrator, Error};
use cbd_tests::{lcg, model_blob, reference_blob};

/// |k1(q) − target| by a fresh evaluation.
fn miss(cal: &mut Calibrator<'_>, q: &[f64], target: &[f64]) -> f64 {
    let e = cal.evaluate(q).unwrap();
    e.position().iter().zip(target).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt()
}

/// For `count` targets k1(q*) at random q*, the seed is the nominal IK of the target from q*
/// moved by up to `perturbation` rad per joint; returns the fraction within `1e-9 × reach`, the
/// worst independent miss among those compensate calls reached, and the fraction flagged reached.
fn round_trip(blob: &[u8], reach: f64, count: usize, perturbation: f64) -> (f64, f64, f64) {
    let mut storage = vec![0.0; 400_000];
    let mut cal = Calibrator::load(blob, &mut storage).unwrap();
    let nominal = cal.model().nominal.clone();
    let scale = cal.model().normalisation.task_scale;
    let (n, m) = (nominal.n_joints(), nominal.task_dim());
    let mut s = 99u64;
    let (mut within, mut flagged_reached, mut worst_reached) = (0usize, 0usize, 0.0f64);
    for _ in 0..count {
        let q_true: Vec<f64> = (0..n).map(|_| 3.0 * lcg(&mut s)).collect();
        let target: Vec<f64> = cal.evaluate(&q_true).unwrap().position().iter().copied().collect();
        assert_eq!(target.len(), m);
        let hint: Vec<f64> = q_true.iter().map(|q| q + perturbation * lcg(&mut s)).collect();
        let mut seed = vec![0.0; n];
        nominal_position(&nominal, &target, &hint, &mut seed, 8, scale).unwrap();
        let mut q = vec![0.0; n];
        let c = cal.compensate(&target, &seed, &mut q).unwrap();
        let independent = miss(&mut cal, &q, &target);
        // The residual compensate reports is the one of the command it returns.
        assert!((independent - c.residual).abs() <= 1e-12 * reach, "reported {} vs {}", c.residual, independent);
        if independent <= 1e-9 * reach {
            within += 1;
        }
        if c.reached {
            flagged_reached += 1;
            worst_reached = worst_reached.max(independent);
        }
    }
    (within as f64 / count as f64, worst_reached, flagged_reached as f64 / count as f64)
}

#[test]
fn rr_reference_model_reaches_reachable_targets() {
    let (fraction, worst, reached) = round_trip(&reference_blob(), 1.5, 3000, 0.1);
    eprintln!("RR: {:.4} within 1e-9 of reach, {reached:.4} flagged reached, worst reached {worst:e}", fraction);
    assert!(fraction >= 0.999, "only {fraction} of targets within 1e-9 of reach");
    assert!(worst <= 1e-9 * 1.5);
}

/// The UR5 nominal chain of the simulator.
fn six_joint() -> NominalModel {
    NominalModel::DhChain(cbd_trainer::simulate::six_joint::ur5_nominal())
}

#[test]
fn six_joint_model_reaches_reachable_targets() {
    for integrator in [Integrator { method: IntegratorMethod::Euler, steps: 1 }, Integrator { method: IntegratorMethod::Heun, steps: 2 }] {
        let blob = model_blob(six_joint(), 40, 0.02, integrator, 2.0);
        let (fraction, worst, reached) = round_trip(&blob, 1000.0, 1000, 0.05);
        eprintln!("six-joint {integrator:?}: {fraction:.4} within 1e-9 of reach, {reached:.4} flagged reached, worst reached {worst:e}");
        assert!(fraction >= 0.999, "only {fraction} of targets within 1e-9 of reach");
        assert!(worst <= 1e-9 * 1000.0);
    }
}

#[test]
fn bad_input_is_an_error_and_unreachable_or_singular_is_flagged() {
    let blob = reference_blob();
    let mut storage = vec![0.0; 100_000];
    let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
    let mut q = [0.0; 2];
    assert_eq!(cal.compensate(&[f64::NAN, 0.0], &[0.1, 0.2], &mut q), Err(Error::NonFiniteTarget { index: 0 }));
    assert_eq!(cal.compensate(&[0.5, f64::INFINITY], &[0.1, 0.2], &mut q), Err(Error::NonFiniteTarget { index: 1 }));
    assert_eq!(cal.compensate(&[0.5, 0.5], &[0.1, f64::NEG_INFINITY], &mut q), Err(Error::NonFiniteQuery { index: 1 }));
    assert_eq!(cal.compensate(&[0.5], &[0.1, 0.2], &mut q), Err(Error::TargetDimension { expected: 2, found: 1 }));
    assert_eq!(cal.compensate(&[0.5, 0.5], &[0.1], &mut q), Err(Error::QueryDimension { expected: 2, found: 1 }));
    assert_eq!(cal.compensate(&[0.5, 0.5], &[0.1, 0.2], &mut [0.0; 3]), Err(Error::QueryDimension { expected: 2, found: 3 }));
    // Far outside the workspace (reach about 1.5): not reached, best effort returned, finite.
    let c = cal.compensate(&[5.0, 1.0], &[0.1, 0.2], &mut q).unwrap();
    assert!(!c.reached && c.residual > 3.0 && q.iter().all(|v| v.is_finite()), "{c:?} {q:?}");
    // Huge but finite targets: still no panic, flagged.
    let c = cal.compensate(&[1e300, -1e300], &[0.1, 0.2], &mut q).unwrap();
    assert!(!c.reached && q.iter().all(|v| v.is_finite()), "{c:?}");
    // A seed at the stretched-out singularity (q2 = 0, Dk1 of rank 1 there) with a target
    // straight along the arm beyond reach: not reached, the best command near the singularity.
    let e = cal.evaluate(&[0.0, 0.0]).unwrap();
    let along: Vec<f64> = e.position().iter().map(|v| v * 1.2).collect();
    let c = cal.compensate(&along, &[0.0, 0.0], &mut q).unwrap();
    assert!(!c.reached && c.conditioning < 1e-2, "{c:?}");
    // The same singular seed with a reachable target: the damped step leaves the singularity.
    let target: Vec<f64> = cal.evaluate(&[0.4, 1.1]).unwrap().position().iter().copied().collect();
    let c = cal.compensate(&target, &[0.0, 0.0], &mut q).unwrap();
    assert!(c.is_ok(), "{c:?} {q:?}");
    // Exactly at a singular command with the target there (zero momenta: k1 = k0, stretched
    // out at q2 = 0): reached, flagged singular.
    let identity =
        model_blob(NominalModel::planar(&[1.0, 0.5]).unwrap(), 3, 0.0, Integrator { method: IntegratorMethod::Euler, steps: 1 }, 1.0);
    let mut storage2 = vec![0.0; 100_000];
    let mut flat = Calibrator::load(&identity, &mut storage2).unwrap();
    let c = flat.compensate(&[1.5, 0.0], &[0.0, 0.0], &mut q).unwrap();
    assert!(c.reached && c.singular && c.conditioning < 1e-12, "{c:?} {q:?}");
    // Far from every measured configuration is flagged as extrapolation: the reference model's
    // grid covers the torus, so no command is outside; checked on a model with three points
    // (periodic kernel b = 1: support ≥ e^-4 everywhere, so the threshold is raised to 0.5).
    let few =
        model_blob(NominalModel::planar(&[1.0, 0.5]).unwrap(), 3, 0.01, Integrator { method: IntegratorMethod::Euler, steps: 1 }, 1.0);
    let mut storage = vec![0.0; 100_000];
    let mut cal = Calibrator::load(&few, &mut storage).unwrap();
    let mut support_min = f64::INFINITY;
    let mut s = 5u64;
    let mut flagged = 0;
    for _ in 0..200 {
        let q_true = [3.0 * lcg(&mut s), 3.0 * lcg(&mut s)];
        let target: Vec<f64> = cal.evaluate(&q_true).unwrap().position().iter().copied().collect();
        let mut options = cbd_runtime::CompensateOptions::for_model(&cal);
        options.extrapolation_threshold = 0.5;
        let c = cal.compensate_with(&target, &q_true, &mut q, &options).unwrap();
        support_min = support_min.min(c.support);
        assert_eq!(c.extrapolating, c.support < 0.5);
        flagged += c.extrapolating as usize;
    }
    assert!(flagged > 0 && flagged < 200, "{flagged} of 200 commands flagged outside the calibrated region (least support {support_min})");
}

#[test]
fn the_cost_is_fixed_and_the_result_deterministic() {
    let blob = reference_blob();
    let mut storage = vec![0.0; 100_000];
    let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
    let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
    let ca = cal.compensate(&[0.9, 0.6], &[0.3, 1.0], &mut a).unwrap();
    let _ = cal.compensate(&[-0.2, 1.1], &[1.3, 0.4], &mut b).unwrap();
    let cb = cal.compensate(&[0.9, 0.6], &[0.3, 1.0], &mut b).unwrap();
    assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
    assert_eq!(ca.residual.to_bits(), cb.residual.to_bits());
}

mod never_panics {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        /// Any f64 bits as target and seed (NaN, ∞, huge, subnormal): a typed error or a finite command.
        #[test]
        fn compensate_with_arbitrary_values(t in proptest::array::uniform2(any::<u64>()), s in proptest::array::uniform2(any::<u64>())) {
            let blob = reference_blob();
            let mut storage = vec![0.0; 100_000];
            let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
            let (target, seed) = (t.map(f64::from_bits), s.map(f64::from_bits));
            let mut q = [0.0; 2];
            match cal.compensate(&target, &seed, &mut q) {
                Ok(c) => {
                    prop_assert!(target.iter().chain(&seed).all(|v| v.is_finite()));
                    prop_assert!(q.iter().all(|v| v.is_finite()) && !c.residual.is_nan());
                }
                Err(Error::NonFiniteTarget { .. }) => prop_assert!(target.iter().any(|v| !v.is_finite())),
                Err(Error::NonFiniteQuery { .. }) => prop_assert!(seed.iter().any(|v| !v.is_finite())),
                Err(Error::NonFiniteResult) => {}
                Err(e) => prop_assert!(false, "unexpected error {e:?}"),
            }
            let nominal = cal.model().nominal.clone();
            let mut start = [0.0; 2];
            let _ = nominal_position(&nominal, &target, &seed, &mut start, 8, 1.0);
        }
    }
}

/// Host wall time of compensate against one evaluate at N = 256 (printed, not asserted: the
/// machine's load decides wall time; the firmware's instruction count is the fixed figure).
/// `cargo test --release -p cbd-tests --test cross_crate compensate::cost -- --ignored --nocapture`
#[test]
#[ignore]
fn cost_relative_to_evaluate() {
    let six = model_blob(six_joint(), 256, 0.02, Integrator { method: IntegratorMethod::Euler, steps: 1 }, 2.0);
    for (name, blob) in [("RR reference (Heun x 5)", reference_blob()), ("six-joint (Euler x 1)", six)] {
        let mut storage = vec![0.0; 1_000_000];
        let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
        let n = cal.model().n_joints();
        let q: Vec<f64> = (0..n).map(|d| 0.3 + 0.1 * d as f64).collect();
        let target: Vec<f64> = cal.evaluate(&q).unwrap().position().iter().map(|v| v + 1e-3).collect();
        let reps = 2000;
        let t = std::time::Instant::now();
        for _ in 0..reps {
            std::hint::black_box(cal.evaluate(std::hint::black_box(&q)).unwrap());
        }
        let evaluate = t.elapsed().as_secs_f64() / reps as f64;
        let t = std::time::Instant::now();
        for _ in 0..reps {
            std::hint::black_box(cal.evaluate_transported(std::hint::black_box(&q)).unwrap());
        }
        let transported = t.elapsed().as_secs_f64() / reps as f64;
        let mut out = vec![0.0; n];
        let t = std::time::Instant::now();
        for _ in 0..reps {
            std::hint::black_box(cal.compensate(std::hint::black_box(&target), &q, &mut out).unwrap());
        }
        let compensate = t.elapsed().as_secs_f64() / reps as f64;
        eprintln!(
            "{name}: evaluate {:.1} us, evaluate_transported {:.1} us, compensate {:.1} us = {:.2} x evaluate",
            evaluate * 1e6,
            transported * 1e6,
            compensate * 1e6,
            compensate / evaluate
        );
    }
}

/// Residual distribution against the number of steps, with and without the inverse-flow start
/// (k1⁻¹ ≈ φ ∘ k0⁻¹ ∘ ψ⁻¹), over `count` reachable targets (the targets and seeds of
/// [`round_trip`]). Printed for BENCHMARKS.md:
/// `cargo test --release -p cbd-tests --test cross_crate compensate::steps_saved -- --ignored --nocapture`
#[test]
#[ignore]
fn steps_saved_by_the_inverse_flow_start() {
    let euler = Integrator { method: IntegratorMethod::Euler, steps: 1 };
    let heun = Integrator { method: IntegratorMethod::Heun, steps: 2 };
    let blobs: Vec<(&str, Vec<u8>, f64, f64)> = vec![
        ("RR reference (Heun x 5)", reference_blob(), 1.5, 0.1),
        ("six-joint N=40 (Euler x 1)", model_blob(six_joint(), 40, 0.02, euler, 2.0), 1000.0, 0.05),
        ("six-joint N=40 (Heun x 2)", model_blob(six_joint(), 40, 0.02, heun, 2.0), 1000.0, 0.05),
        ("six-joint N=256 (Euler x 1)", model_blob(six_joint(), 256, 0.02, euler, 2.0), 1000.0, 0.05),
    ];
    let count = 2000;
    let only = std::env::var("CBD_STEPS_BLOB").ok();
    for (name, blob, reach, perturbation) in blobs {
        if only.as_deref().is_some_and(|o| !name.starts_with(o)) {
            continue;
        }
        let mut storage = vec![0.0; 1_000_000];
        let mut cal = Calibrator::load(&blob, &mut storage).unwrap();
        let nominal = cal.model().nominal.clone();
        let scale = cal.model().normalisation.task_scale;
        let n = nominal.n_joints();
        let mut s = 99u64;
        let cases: Vec<(Vec<f64>, Vec<f64>)> = (0..count)
            .map(|_| {
                let q_true: Vec<f64> = (0..n).map(|_| 3.0 * lcg(&mut s)).collect();
                let target: Vec<f64> = cal.evaluate(&q_true).unwrap().position().iter().copied().collect();
                let hint: Vec<f64> = q_true.iter().map(|q| q + perturbation * lcg(&mut s)).collect();
                let mut seed = vec![0.0; n];
                nominal_position(&nominal, &target, &hint, &mut seed, 8, scale).unwrap();
                (target, seed)
            })
            .collect();
        eprintln!("{name}: {count} targets, residual / reach (median, p99, p99.9, max), fraction within 1e-9");
        let mut configs: Vec<(String, cbd_runtime::CompensateOptions)> = Vec::new();
        let config = |(start, guard): (bool, bool), fold: bool, corrections: usize, iterations: usize, chord: usize| {
            let mut o = cbd_runtime::CompensateOptions::for_model(&cal);
            (o.inverse_flow_start, o.start_guard, o.fold_steps) = (start, guard, fold);
            (o.iterations, o.chord_steps, o.start_corrections) = (iterations, chord, corrections);
            let from = match (start, corrections) {
                (false, _) => "seed ".to_string(),
                (true, 0) => "flows".to_string(),
                (true, c) => format!("flows x{}", c + 1),
            } + if guard { " guarded" } else { "" };
            let label = format!(
                "{from}{} + {iterations} full{}",
                if fold { " fold" } else { "" },
                if chord > 0 { format!(" + {chord} chord") } else { String::new() }
            );
            (label, o)
        };
        for fold in [false, true] {
            for start in [(false, false), (true, false), (true, true)] {
                for iterations in 0..=8 {
                    configs.push(config(start, fold, 0, iterations, 0));
                }
                for (iterations, chord) in [(1, 1), (2, 1), (2, 2), (3, 1), (5, 1), (5, 2), (6, 1)] {
                    configs.push(config(start, fold, 0, iterations, chord));
                }
                if start == (true, false) {
                    for (corrections, iterations, chord) in
                        [(1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 2, 0), (1, 2, 1), (1, 4, 0), (1, 5, 0), (1, 6, 0)]
                    {
                        configs.push(config(start, fold, corrections, iterations, chord));
                    }
                }
            }
        }
        // `CBD_STEPS_CONFIG='fold + 2|fold + 3'` (say): only the variants whose label contains one of them.
        let filter = std::env::var("CBD_STEPS_CONFIG").ok();
        configs.retain(|(label, _)| filter.as_deref().is_none_or(|f| f.split('|').any(|f| label.contains(f))));
        for (label, options) in configs {
            let mut q = vec![0.0; n];
            let mut r: Vec<f64> =
                cases.iter().map(|(target, seed)| cal.compensate_with(target, seed, &mut q, &options).unwrap().residual / reach).collect();
            r.sort_by(f64::total_cmp);
            let at = |p: f64| r[((p * count as f64) as usize).min(count - 1)];
            let within = r.iter().filter(|v| **v <= 1e-9).count() as f64 / count as f64;
            eprintln!("  {label:<36} {:9.2e} {:9.2e} {:9.2e} {:9.2e}  {:.4}", at(0.5), at(0.99), at(0.999), r[count - 1], within);
        }
    }
}
