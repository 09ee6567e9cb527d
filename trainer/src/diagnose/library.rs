//! The library of candidate effects: named scalar parameters, grouped (a group is selected or
//! not as a whole), how a parameter vector changes the model, and each parameter's Jacobian
//! column ∂k/∂θ over the data.
//!
//! Geometric parameters are those of `parametric` (a, α, d, θ_offset per joint,
//! base, tool; planar chains: the link lengths) and are written into the chain itself; their
//! columns are `parametric`'s analytic identification Jacobian at the deflected joints. Joint
//! effects: ∂k/∂θ = Dk_rigid(q + δ) · response; task effects (link bending): ∂k/∂θ = response.

use super::kinematics::{self, Response};
use crate::data::Measurements;
use crate::nominal::dh_parameters::{apply_parameters, parameter_count_for, parameter_names_for};
use crate::nominal::positions;
use cbd_protocol::{Effect, NominalModel};
use cbd_runtime::kinematics::augmented::{effect_terms, Order};
use faer::Mat;

/// One scalar parameter of the library.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Param {
    /// Index into the DH parameter vector (`nominal::dh_parameters::parameter_names_for`) or, for a planar
    /// chain, the link index.
    Geometric(usize),
    EncoderScale {
        joint: usize,
    },
    TransmissionCos {
        joint: usize,
        harmonic: u8,
    },
    TransmissionSin {
        joint: usize,
        harmonic: u8,
    },
    GravityCompliance {
        joint: usize,
    },
    /// c_j·m_k (`component` 0) or c_j·s_k along x, y, z of link k's frame (1, 2, 3): one column of
    /// compliant joint j's gravity regressor, ∂/∂q_j g·o_k or ∂/∂q_j g·R_k e_i (gauge c_j = 1).
    GravityMoment {
        joint: usize,
        link: usize,
        component: u8,
    },
    LinkBending {
        link: usize,
    },
}

/// What kind of effect a group is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum GroupKind {
    Geometric,
    EncoderScale,
    Transmission { harmonic: u8 },
    GravityCompliance,
    LinkBending,
}

impl GroupKind {
    pub fn type_name(&self) -> &'static str {
        match self {
            GroupKind::Geometric => "geometric",
            GroupKind::EncoderScale => "encoder_scale",
            GroupKind::Transmission { .. } => "transmission",
            GroupKind::GravityCompliance => "gravity_compliance",
            GroupKind::LinkBending => "link_bending",
        }
    }
}

/// Parameters selected or rejected together.
#[derive(Debug, Clone, PartialEq)]
pub struct Group {
    pub name: String,
    pub kind: GroupKind,
    /// 0-based joint (or link, for bending); `None` for the geometric group.
    pub joint: Option<usize>,
    pub params: Vec<Param>,
}

/// Settings of the library.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LibraryOptions {
    /// Transmission harmonics 1..=H per revolute joint.
    pub harmonics: u8,
}

impl Default for LibraryOptions {
    fn default() -> Self {
        LibraryOptions { harmonics: 3 }
    }
}

/// Names of the parameters (1-based joints), e.g. `a2`, `transmission q3 h2 cos`.
pub fn param_name(model: &NominalModel, p: &Param) -> String {
    match *p {
        Param::Geometric(k) => match model {
            NominalModel::DhChain(c) => parameter_names_for(c)[k].clone(),
            NominalModel::PlanarChain { .. } => format!("l{}", k + 1),
        },
        Param::EncoderScale { joint } => format!("scale q{}", joint + 1),
        Param::TransmissionCos { joint, harmonic } => format!("q{} h{harmonic} cos", joint + 1),
        Param::TransmissionSin { joint, harmonic } => format!("q{} h{harmonic} sin", joint + 1),
        Param::GravityCompliance { joint } => format!("compliance q{}", joint + 1),
        Param::GravityMoment { joint, link, component: 0 } => format!("q{} link {} mass", joint + 1, link + 1),
        Param::GravityMoment { joint, link, component } => {
            format!("q{} link {} first moment {}", joint + 1, link + 1, ["x", "y", "z"][(component as usize - 1).min(2)])
        }
        Param::LinkBending { link } => format!("bending link {}", link + 1),
    }
}

/// Whether a geometric parameter is an angle (radians) rather than a length.
pub fn is_angle(model: &NominalModel, p: &Param) -> bool {
    match (model, p) {
        (NominalModel::DhChain(c), Param::Geometric(k)) => {
            let name = &parameter_names_for(c)[*k];
            name.starts_with("alpha") || name.starts_with("theta") || name.starts_with("base_r") || name.starts_with("tool_r")
        }
        (_, Param::TransmissionCos { .. } | Param::TransmissionSin { .. }) => true,
        _ => false,
    }
}

fn geometric_count(model: &NominalModel) -> usize {
    match model {
        NominalModel::DhChain(c) => parameter_count_for(c),
        NominalModel::PlanarChain { lengths, .. } => lengths.len(),
    }
}

/// Every candidate group for `model` whose data has `m` task coordinates (geometric parameters
/// not yet pruned to an identifiable set). A DH chain read in two coordinates (a planar arm's DH
/// form) has the in-plane geometric parameters only.
pub fn candidate_groups(model: &NominalModel, options: &LibraryOptions, m: usize) -> Vec<Group> {
    let n = model.n_joints();
    let geometric = match model {
        NominalModel::DhChain(_) if m < model.task_dim() => crate::nominal::planar::in_plane_parameters(n),
        _ => (0..geometric_count(model)).collect(),
    };
    let mut groups = vec![Group {
        name: "geometric".into(),
        kind: GroupKind::Geometric,
        joint: None,
        params: geometric.into_iter().map(Param::Geometric).collect(),
    }];
    for j in 0..n {
        let revolute = model.is_revolute(j);
        groups.push(Group {
            name: format!("encoder scale q{}", j + 1),
            kind: GroupKind::EncoderScale,
            joint: Some(j),
            params: vec![Param::EncoderScale { joint: j }],
        });
        if revolute {
            for h in 1..=options.harmonics {
                groups.push(Group {
                    name: format!("transmission q{} harmonic {h}", j + 1),
                    kind: GroupKind::Transmission { harmonic: h },
                    joint: Some(j),
                    params: vec![Param::TransmissionCos { joint: j, harmonic: h }, Param::TransmissionSin { joint: j, harmonic: h }],
                });
            }
        }
        groups.push(Group {
            name: format!("gravity compliance q{}", j + 1),
            kind: GroupKind::GravityCompliance,
            joint: Some(j),
            params: gravity_regressor(n, j, m),
        });
        groups.push(Group {
            name: format!("link bending {}", j + 1),
            kind: GroupKind::LinkBending,
            joint: Some(j),
            params: vec![Param::LinkBending { link: j }],
        });
    }
    groups
}

/// Compliant joint j's gravity regressor as parameters: c_j·m_k and c_j·s_k for every link
/// k ≥ j (in-plane data: the first moment's z component does nothing and is left out). Which
/// combinations the data identify is decided on the Jacobian (`diagnose::usable_columns`).
fn gravity_regressor(n: usize, j: usize, m: usize) -> Vec<Param> {
    let components = if m < 3 { 3 } else { 4 };
    (j..n).flat_map(|link| (0..components).map(move |component| Param::GravityMoment { joint: j, link, component })).collect()
}

/// The effect a non-geometric parameter stands for, with value `v`.
fn effect_of(p: &Param, v: f64) -> Option<Effect> {
    Some(match *p {
        Param::Geometric(_) => return None,
        Param::EncoderScale { joint } => Effect::EncoderScale { joint: joint as u8, scale: v },
        Param::TransmissionCos { joint, harmonic } => Effect::Transmission { joint: joint as u8, harmonic, cos: v, sin: 0.0 },
        Param::TransmissionSin { joint, harmonic } => Effect::Transmission { joint: joint as u8, harmonic, cos: 0.0, sin: v },
        Param::GravityCompliance { joint } => Effect::GravityCompliance { joint: joint as u8, compliance: v },
        Param::GravityMoment { joint, link, component } => {
            let (mass, mut first_moment) = if component == 0 { (v, [0.0; 3]) } else { (0.0, [0.0; 3]) };
            if let Some(s) = first_moment.get_mut((component as usize).wrapping_sub(1)) {
                *s = v;
            }
            Effect::GravityMoment { joint: joint as u8, link: link as u8, mass, first_moment }
        }
        Param::LinkBending { link } => Effect::LinkBending { link: link as u8, compliance: v },
    })
}

/// Adds `e` to `list`, merging it into an entry of the same type and joint (parameters add).
fn merge_effect(list: &mut heapless::Vec<Effect, { cbd_protocol::MAX_EFFECTS }>, e: Effect) -> Result<(), super::DiagnoseError> {
    for old in list.iter_mut() {
        match (old, e) {
            (Effect::EncoderScale { joint: a, scale }, Effect::EncoderScale { joint: b, scale: s }) if *a == b => {
                *scale += s;
                return Ok(());
            }
            (Effect::Transmission { joint: a, harmonic: h, cos, sin }, Effect::Transmission { joint: b, harmonic: g, cos: c, sin: s })
                if *a == b && *h == g =>
            {
                *cos += c;
                *sin += s;
                return Ok(());
            }
            (Effect::GravityCompliance { joint: a, compliance }, Effect::GravityCompliance { joint: b, compliance: c }) if *a == b => {
                *compliance += c;
                return Ok(());
            }
            (Effect::LinkBending { link: a, compliance }, Effect::LinkBending { link: b, compliance: c }) if *a == b => {
                *compliance += c;
                return Ok(());
            }
            (
                Effect::GravityMoment { joint: a, link: k, mass, first_moment },
                Effect::GravityMoment { joint: b, link: l, mass: m, first_moment: s },
            ) if *a == b && *k == l => {
                *mass += m;
                for (o, v) in first_moment.iter_mut().zip(s) {
                    *o += v;
                }
                return Ok(());
            }
            _ => {}
        }
    }
    list.push(e).map_err(|_| super::DiagnoseError::TooManyEffects)
}

/// `model` changed by `values` of `params`: geometric changes written into the chain, effects
/// merged into its effect list.
pub fn apply(model: &NominalModel, params: &[Param], values: &[f64]) -> Result<NominalModel, super::DiagnoseError> {
    let mut out = match model {
        NominalModel::DhChain(chain) => {
            let mut p = vec![0.0; parameter_count_for(chain)];
            for (param, v) in params.iter().zip(values) {
                if let Param::Geometric(k) = param {
                    p[*k] += v;
                }
            }
            if p.iter().any(|v| *v != 0.0) {
                NominalModel::DhChain(apply_parameters(chain, &p))
            } else {
                model.clone()
            }
        }
        NominalModel::PlanarChain { lengths, effects } => {
            let mut lengths = lengths.clone();
            for (param, v) in params.iter().zip(values) {
                if let Param::Geometric(k) = param {
                    lengths[*k] += v;
                }
            }
            NominalModel::PlanarChain { lengths, effects: effects.clone() }
        }
    };
    for (param, v) in params.iter().zip(values) {
        if let Some(e) = effect_of(param, *v) {
            merge_effect(&mut out.effects_mut().list, e)?;
        }
    }
    Ok(out)
}

/// Step of the central difference for geometric parameter `p`: 1e-6 rad, or 1e-6 of the
/// workspace's size for lengths.
fn fd_step(model: &NominalModel, p: &Param, length_scale: f64) -> f64 {
    if is_angle(model, p) {
        1e-6
    } else {
        1e-6 * length_scale
    }
}

/// The index of geometric parameter `k` in the DH form's parameter vector (a planar chain's link
/// length k is a_k of its DH form).
fn dh_index(model: &NominalModel, k: usize) -> usize {
    match model {
        NominalModel::DhChain(_) => k,
        NominalModel::PlanarChain { .. } => 4 * k,
    }
}

/// The geometric columns of `jac` (`geometric`: (column, parameter)), ∂k_aug/∂p for k_aug(q) =
/// k_rigid(p; q + δ(p; q)) + b(p; q): the rigid chain's analytic identification Jacobian at the
/// deflected joints (`parametric::geometric_jacobian`), plus, for a model with effects, how they
/// move with the geometry (gravity torques, link frames), Dk_rigid(q + δ) ∂δ/∂p + ∂b/∂p, by
/// central differences of δ and b alone (zero for effects that do not depend on the geometry).
fn geometric_columns(model: &NominalModel, data: &Measurements, geometric: &[(usize, Param)], jac: &mut Mat<f64>) {
    let (n, m, rows) = (model.n_joints(), data.task_dim, data.len());
    let rigid = kinematics::rigid(model);
    let NominalModel::DhChain(chain) = crate::nominal::planar::as_dh(&rigid) else { unreachable!("as_dh gives a DH chain") };
    let effects = &model.effects().list;
    let deflected: Vec<f64> = if effects.is_empty() {
        data.joints.clone()
    } else {
        data.joints
            .chunks_exact(n)
            .flat_map(|q| {
                let delta = effect_terms(model, effects, q, Order::Value).delta;
                q.iter().zip(delta).map(|(a, d)| a + d).collect::<Vec<f64>>()
            })
            .collect()
    };
    let analytic = crate::parametric::geometric_jacobian(&chain, &deflected, m);
    for &(col, p) in geometric {
        let Param::Geometric(k) = p else { continue };
        let k = dh_index(model, k);
        for i in 0..m * rows {
            jac[(i, col)] = analytic[(i, k)];
        }
    }
    if effects.is_empty() {
        return;
    }
    // Size of the workspace (for the difference step of lengths): the model's own positions.
    let length_scale = positions(model, &data.joints, m).iter().chain(&data.positions).fold(0.0f64, |a, v| a.max(v.abs())).max(1e-9);
    for &(col, p) in geometric {
        let h = fd_step(model, &p, length_scale);
        let plus = apply(model, &[p], &[h]).expect("geometric change adds no effect");
        let minus = apply(model, &[p], &[-h]).expect("geometric change adds no effect");
        for i in 0..rows {
            let q = data.joints(i);
            let (a, b) =
                (effect_terms(&plus, &plus.effects().list, q, Order::Value), effect_terms(&minus, &minus.effects().list, q, Order::Value));
            let d_delta: Vec<f64> = (0..n).map(|d| (a.delta[d] - b.delta[d]) / (2.0 * h)).collect();
            if d_delta.iter().all(|v| *v == 0.0) && (0..m).all(|c| a.b[c] == b.b[c]) {
                continue;
            }
            let dk = kinematics::deflected_rigid_jacobian(model, &rigid, q, kinematics::point_of_row(model, i));
            for c in 0..m {
                jac[(m * i + c, col)] += (0..n).map(|d| dk[c * n + d] * d_delta[d]).sum::<f64>() + (a.b[c] - b.b[c]) / (2.0 * h);
            }
        }
    }
}

/// The Jacobian ∂k(q_i)/∂θ of every `params` at `model` over `data`: (N·m) × params.len(),
/// rows ordered (row i, coordinate c) → m·i + c.
pub fn jacobian(model: &NominalModel, data: &Measurements, params: &[Param]) -> Mat<f64> {
    let (n, m, rows) = (model.n_joints(), data.task_dim, data.len());
    let mut jac = Mat::<f64>::zeros(m * rows, params.len());
    let geometric: Vec<(usize, Param)> =
        params.iter().enumerate().filter(|(_, p)| matches!(p, Param::Geometric(_))).map(|(col, p)| (col, *p)).collect();
    if !geometric.is_empty() {
        geometric_columns(model, data, &geometric, &mut jac);
    }
    // Effect columns: responses of unit-valued effects.
    let rigid = kinematics::rigid(model);
    let effects: Vec<(usize, Effect)> = params.iter().enumerate().filter_map(|(col, p)| effect_of(p, 1.0).map(|e| (col, e))).collect();
    if effects.is_empty() {
        return jac;
    }
    for i in 0..rows {
        let q = data.joints(i);
        let dk = kinematics::deflected_rigid_jacobian(model, &rigid, q, kinematics::point_of_row(model, i));
        for (col, e) in &effects {
            match kinematics::response(model, e, q) {
                Response::Joint(delta) => {
                    for c in 0..m {
                        jac[(m * i + c, *col)] = (0..n).map(|d| dk[c * n + d] * delta[d]).sum();
                    }
                }
                Response::Task(b) => {
                    for c in 0..m {
                        jac[(m * i + c, *col)] = b[c];
                    }
                }
            }
        }
    }
    jac
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every column of `jac` (the library's `jacobian` of `params`) against central differences of
    /// the positions of `model` changed by ±1e-6 in that parameter, relative tolerance `tolerance`.
    #[track_caller]
    fn assert_columns_are_central_differences(model: &NominalModel, data: &Measurements, params: &[Param], jac: &Mat<f64>, tolerance: f64) {
        let m = data.task_dim;
        for (col, p) in params.iter().enumerate() {
            let h = 1e-6;
            let (plus, minus) = (apply(model, &[*p], &[h]).unwrap(), apply(model, &[*p], &[-h]).unwrap());
            let (a, b) = (positions(&plus, &data.joints, m), positions(&minus, &data.joints, m));
            for r in 0..a.len() {
                let fd = (a[r] - b[r]) / (2.0 * h);
                assert!(
                    (fd - jac[(r, col)]).abs() < tolerance * (1.0 + fd.abs()),
                    "{} row {r}: fd {fd} vs {}",
                    param_name(model, p),
                    jac[(r, col)]
                );
            }
        }
    }

    #[test]
    fn geometric_and_effect_columns_match_finite_differences() {
        let model = crate::simulate::rr::nominal();
        let groups = candidate_groups(&model, &LibraryOptions { harmonics: 2 }, 2);
        let params: Vec<Param> = groups.iter().flat_map(|g| g.params.clone()).collect();
        let mut data = Measurements::new(2, 2);
        for q in [[0.3, 1.2], [-2.0, 0.4], [2.5, -1.1]] {
            data.push(&q, &[0.0, 0.0]);
        }
        let jac = jacobian(&model, &data, &params);
        assert_columns_are_central_differences(&model, &data, &params, &jac, 1e-7);
    }

    #[test]
    fn columns_of_a_model_with_tool_points_match_central_differences_at_every_point() {
        // Three tool points per pose (rows pose-major): every column — geometric, joint effects,
        // bending — at each row's own point, the effects deflecting the chain the points ride on.
        let mut chain = crate::simulate::six_joint::ur5_nominal();
        chain.tool_points = heapless::Vec::from_slice(&[[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [50.0, 86.6, 20.0]]).unwrap();
        let mut model = NominalModel::DhChain(chain);
        for e in
            [Effect::GravityCompliance { joint: 2, compliance: 4e-7 }, Effect::Transmission { joint: 1, harmonic: 2, cos: 1e-3, sin: 0.0 }]
        {
            model.effects_mut().list.push(e).unwrap();
        }
        let groups = candidate_groups(&model, &LibraryOptions { harmonics: 2 }, 3);
        let params: Vec<Param> = groups.iter().flat_map(|g| g.params.clone()).collect();
        let mut data = Measurements::with_points(6, 3, 3);
        for q in [[0.3, -1.2, 0.8, 0.1, 1.5, -0.4], [-2.0, -0.4, 1.9, -1.0, 0.2, 2.2]] {
            for _ in 0..3 {
                data.push(&q, &[0.0; 3]);
            }
        }
        let jac = jacobian(&model, &data, &params);
        // The points differ: a rotation's column (θ offset 1, the q2 transmission) read at the tool
        // origin for every row would not match.
        let transmission = params.iter().position(|p| matches!(p, Param::TransmissionCos { joint: 1, harmonic: 1 })).unwrap();
        for col in [3, transmission] {
            assert!((0..3).any(|c| (jac[(c, col)] - jac[(3 + c, col)]).abs() > 1e-3), "rows 0 and 1 share column {col}");
        }
        assert_columns_are_central_differences(&model, &data, &params, &jac, 1e-5);
    }

    #[test]
    fn geometric_columns_of_a_model_with_effects_match_central_differences() {
        // Gravity compliance and bending move with the geometry (torques, link frames): the analytic
        // rigid columns at the deflected joints plus that coupling are the whole derivative.
        let mut model = NominalModel::DhChain(crate::simulate::six_joint::ur5_nominal());
        for e in [
            Effect::GravityCompliance { joint: 1, compliance: 2e-3 },
            Effect::LinkBending { link: 2, compliance: 1e-3 },
            Effect::Transmission { joint: 0, harmonic: 2, cos: 1e-3, sin: -2e-3 },
        ] {
            model.effects_mut().list.push(e).unwrap();
        }
        let params: Vec<Param> = (0..crate::nominal::dh_parameters::parameter_count(6)).map(Param::Geometric).collect();
        let mut data = Measurements::new(6, 3);
        for q in [[0.3, -1.2, 0.8, 0.1, 1.5, -0.4], [-2.0, -0.4, 1.9, -1.0, 0.2, 2.2]] {
            data.push(&q, &[0.0; 3]);
        }
        let jac = jacobian(&model, &data, &params);
        assert_columns_are_central_differences(&model, &data, &params, &jac, 1e-5);
    }
}
