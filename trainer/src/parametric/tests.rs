//! Tests of the parametric fit: a perturbed chain recovered, both DH conventions, planar arms.

use super::*;
use crate::data::Measurements;
use crate::nominal::dh_parameters::{apply_parameters, parameter_count, parameter_names};
use cbd_protocol::{DhChain, DhConvention};
use cbd_runtime::internals::kinematics::forward_kinematics;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub(crate) fn ur5_like(convention: DhConvention) -> DhChain {
    DhChain { convention, ..crate::simulate::six_joint::ur5_nominal() }
}

pub(crate) fn sample(model: &NominalModel, count: usize, seed: u64) -> Measurements {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut m = Measurements::new(6, 3);
    for _ in 0..count {
        let q: Vec<f64> = (0..6).map(|_| rng.gen_range(-3.0..3.0)).collect();
        m.push(&q, &forward_kinematics(model, &q).position);
    }
    m
}

#[test]
fn recovers_positions_of_a_perturbed_chain_without_noise() {
    let nominal = ur5_like(DhConvention::Standard);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let p_true: Vec<f64> = parameter_names(6)
        .iter()
        .map(|s| {
            if s.starts_with("alpha") || s.starts_with("theta") || s.starts_with("base_r") {
                rng.gen_range(-0.01..0.01)
            } else {
                rng.gen_range(-2.0..2.0)
            }
        })
        .collect();
    let truth = NominalModel::DhChain(apply_parameters(&nominal, &p_true));
    let train = sample(&truth, 150, 1);
    let test = sample(&truth, 300, 2);
    let fit = calibrate_dh(&NominalModel::DhChain(nominal), &train, &DhCalibrationOptions::default()).unwrap();
    assert!(fit.stats.initial_rms > 1.0, "{:?}", fit.stats);
    assert!(fit.stats.rank < fit.stats.n_parameters && !fit.stats.unidentifiable.is_empty(), "{:?}", fit.stats);
    let mut worst: f64 = 0.0;
    for i in 0..test.len() {
        let k = forward_kinematics(&fit.model, test.joints(i));
        for c in 0..3 {
            worst = worst.max((k.position[c] - test.position(i)[c]).abs());
        }
    }
    assert!(worst < 1e-6, "worst test error {worst} mm; stats {:?}", fit.stats);
}

#[test]
fn modified_convention_also_recovers() {
    let nominal = ur5_like(DhConvention::Modified);
    let mut p_true = vec![0.0; parameter_count(6)];
    p_true[0] = 0.8; // a1
    p_true[5] = 0.004; // alpha2
    p_true[10] = -1.5; // d3
    p_true[24] = 3.0; // base_tx
    p_true[28] = 0.01; // base_ry
    p_true[32] = 2.0; // tool_tz
    let truth = NominalModel::DhChain(apply_parameters(&nominal, &p_true));
    let train = sample(&truth, 120, 3);
    let fit = calibrate_dh(&NominalModel::DhChain(nominal), &train, &DhCalibrationOptions::default()).unwrap();
    // This chain read as modified DH has many redundant parameters; LM ends in a flat valley
    // of the parameter space about 1e-5 mm (rms) from an exact fit (a local minimum: the
    // straight line to the true parameters rises to 1e-2 mm). Far below any real noise.
    assert!(fit.stats.final_rms < 1e-4, "{:?}", fit.stats);
    assert!(fit.stats.final_rms < 1e-5 * fit.stats.initial_rms, "{:?}", fit.stats);
}

#[test]
fn planar_chain_is_rejected() {
    let planar = NominalModel::planar(&[1.0]).unwrap();
    let e = calibrate_dh(&planar, &Measurements::new(1, 2), &DhCalibrationOptions::default()).unwrap_err();
    assert_eq!(e, DhCalibrationError::NotADhChain);
}

#[test]
fn a_planar_arm_is_calibrated_as_its_dh_form_in_its_plane() {
    use crate::simulate::rr::planar_arm;
    let nominal = NominalModel::planar(&[1.0, 0.5, 0.3]).unwrap();
    let truth = planar_arm(&[1.03, 0.48, 0.31], [0.04, -0.03], 0.02, &[0.01, -0.015, 0.02]);
    let measure = |seed: u64| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut m = Measurements::new(3, 2);
        for _ in 0..60 {
            let q: Vec<f64> = (0..3).map(|_| rng.gen_range(-3.0..3.0)).collect();
            m.push(&q, &forward_kinematics(&truth, &q).position[..2]);
        }
        m
    };
    let (train, test) = (measure(1), measure(2));
    // Refused unless asked for (the result is a 3-D chain read in two coordinates).
    assert_eq!(calibrate_dh(&nominal, &train, &DhCalibrationOptions::default()).unwrap_err(), DhCalibrationError::NotADhChain);
    let fit = calibrate_dh(&nominal, &train, &DhCalibrationOptions { planar_as_dh: true, ..Default::default() }).unwrap();
    // In-plane parameters: 3 lengths, 3 offsets, base x, y, yaw; yaw and the first offset are one.
    assert_eq!((fit.stats.n_parameters, fit.stats.rank), (9, 8), "{:?}", fit.stats);
    assert!(fit.stats.initial_rms > 0.01 && fit.stats.final_rms < 1e-10, "{:?}", fit.stats);
    let predicted = crate::nominal::positions(&fit.model, &test.joints, 2);
    let worst = predicted.iter().zip(&test.positions).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(worst < 1e-9, "{worst}");
    // Out of the plane nothing moved: the result is exactly a planar chain in a moved frame.
    assert!(crate::nominal::planar::as_planar_in_frame(&fit.model).is_some(), "{:?}", fit.model);
}

/// Three tool points 100 mm apart measured on a chain whose tool frame is turned (and moved):
/// the fit's tool rotation (three columns, only for tool points off the origin) recovers every
/// point exactly, and the rotation it found is needed (the fitted chain with the nominal tool
/// rotation put back misses by the lever × the turn).
#[test]
fn tool_points_off_the_origin_identify_the_tool_rotation() {
    use crate::nominal::dh_parameters::{has_tool_rotation, parameter_count_for, parameter_names_for};
    use crate::nominal::row_kinematics;
    let mut nominal = ur5_like(DhConvention::Standard);
    nominal.tool_points = heapless::Vec::from_slice(&[[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]]).unwrap();
    assert!(has_tool_rotation(&nominal));
    assert_eq!(parameter_count_for(&nominal), parameter_count(6) + 3);
    assert_eq!(parameter_names_for(&nominal)[parameter_count(6)..], ["tool_rx", "tool_ry", "tool_rz"]);
    let mut p_true = vec![0.0; parameter_count_for(&nominal)];
    p_true[2] = 0.7; // d1
    p_true[13] = -0.002; // alpha4
    p_true[32] = 1.5; // tool_tz
    p_true[33] = 0.002; // tool_rx
    p_true[34] = 0.0035; // tool_ry (0.2°)
    p_true[35] = -0.001; // tool_rz
    let truth = NominalModel::DhChain(apply_parameters(&nominal, &p_true));
    let measure = |seed: u64, count: usize| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut m = Measurements::with_points(6, 3, 3);
        for _ in 0..count {
            let q: Vec<f64> = (0..6).map(|_| rng.gen_range(-3.0..3.0)).collect();
            for j in 0..3 {
                m.push(&q, &row_kinematics(&truth, &q, j).position[..3]);
            }
        }
        m
    };
    let (train, test) = (measure(5, 80), measure(6, 200));
    let fit = calibrate_dh(&NominalModel::DhChain(nominal.clone()), &train, &DhCalibrationOptions::default()).unwrap();
    assert_eq!(fit.stats.parameter_changes.len(), parameter_count(6) + 3);
    let worst = |model: &NominalModel| {
        let test = &test;
        (0..test.len())
            .flat_map(|i| {
                let k = row_kinematics(model, test.joints(i), i);
                (0..3).map(move |c| (k.position[c] - test.position(i)[c]).abs()).collect::<Vec<_>>()
            })
            .fold(0.0f64, f64::max)
    };
    let calibrated = worst(&fit.model);
    assert!(calibrated < 1e-6, "worst test error {calibrated} mm; stats {:?}", fit.stats);
    let NominalModel::DhChain(fitted) = &fit.model else { unreachable!() };
    let mut turned_back = fitted.clone();
    turned_back.tool.rotation = nominal.tool.rotation;
    assert!(worst(&NominalModel::DhChain(turned_back)) > 0.05, "the tool rotation matters here");
}

/// The tool rotation's central-difference columns against the analytic derivative at r = 0: a turn
/// δ about the tool frame's axis k moves point j by (R_tool e_k) × (y_j − o_tool) δ.
#[test]
fn tool_rotation_columns_match_the_analytic_derivative() {
    use super::jacobian::jacobian_at;
    use crate::nominal::dh_parameters::parameter_count_for;
    use crate::nominal::row_kinematics;
    use cbd_runtime::internals::kinematics::rigid::dh_walk;
    let mut chain = ur5_like(DhConvention::Modified);
    chain.tool_points = heapless::Vec::from_slice(&[[30.0, -20.0, 50.0], [-80.0, 10.0, 5.0]]).unwrap();
    chain.tool.rotation = crate::nominal::rpy(0.3, -0.2, 1.1).to_transform().rotation;
    let model = NominalModel::DhChain(chain.clone());
    let mut data = Measurements::with_points(6, 3, 2);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for _ in 0..4 {
        let q: Vec<f64> = (0..6).map(|_| rng.gen_range(-3.0..3.0)).collect();
        for j in 0..2 {
            data.push(&q, &row_kinematics(&model, &q, j).position[..3]);
        }
    }
    let np = parameter_count_for(&chain);
    let mut jac = faer::Mat::<f64>::zeros(3 * data.len(), np);
    let (mut rp, mut rm) = (vec![0.0; 3 * data.len()], vec![0.0; 3 * data.len()]);
    jacobian_at(&chain, &vec![0.0; np], &data, &mut jac, (&mut rp, &mut rm));
    for row in 0..data.len() {
        let walk = dh_walk(&chain, data.joints(row));
        let y = data.position(row);
        for k in 0..3 {
            let axis: [f64; 3] = std::array::from_fn(|a| walk.tool_rotation[a][k]);
            let expected = crate::nominal::cross(axis, crate::nominal::sub([y[0], y[1], y[2]], walk.tool));
            for c in 0..3 {
                let got = jac[(3 * row + c, parameter_count(6) + k)];
                assert!(
                    (got - expected[c]).abs() < 1e-6 * (1.0 + expected[c].abs()),
                    "row {row} axis {k} coordinate {c}: {got} vs {}",
                    expected[c]
                );
            }
        }
    }
}
