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
use crate::effects::{Instance, Kind, Site, KINDS};
use crate::nominal::dh_parameters::{apply_parameters, parameter_count_for, parameter_names_for};
use crate::nominal::positions;
use cbd_protocol::{Effect, NominalModel};
use cbd_runtime::internals::kinematics::augmented::{effect_terms, Order};
use faer::Mat;

pub use crate::effects::LibraryOptions;

/// One scalar parameter of the library.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Param {
    /// Index into the DH parameter vector (`nominal::dh_parameters::parameter_names_for`) or, for a planar
    /// chain, the link index.
    Geometric(usize),
    /// Parameter `component` (of [`EffectKind::components`](crate::effects::EffectKind::components)) of an effect of `kind` at `site`.
    Effect { kind: Kind, site: Site, component: usize },
}

impl Param {
    /// The effect this parameter stands for with value `v` (`None`: geometric).
    pub fn effect(&self, v: f64) -> Option<Instance> {
        match *self {
            Param::Geometric(_) => None,
            Param::Effect { kind, site, component } => Some(Instance::single(kind, site, component, v)),
        }
    }

    /// The parameter's name among its kind's components (`cos`, `scale`; `geometric` for the chain's).
    pub fn component_name(&self) -> &'static str {
        match self {
            Param::Geometric(_) => "geometric",
            Param::Effect { kind, component, .. } => kind.components()[*component],
        }
    }
}

/// What kind of effect a group is: the chain's geometry, or an effect of the library with the
/// `type` it reports (and a transmission's harmonic).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum GroupKind {
    Geometric,
    Effect { type_name: &'static str, harmonic: Option<u8> },
}

impl GroupKind {
    /// An effect group's kind: `GroupKind::effect("transmission", Some(2))`.
    pub fn effect(type_name: &'static str, harmonic: Option<u8>) -> GroupKind {
        GroupKind::Effect { type_name, harmonic }
    }

    pub fn type_name(&self) -> &'static str {
        match self {
            GroupKind::Geometric => "geometric",
            GroupKind::Effect { type_name, .. } => type_name,
        }
    }

    /// A transmission group's harmonic.
    pub fn harmonic(&self) -> Option<u8> {
        match self {
            GroupKind::Geometric => None,
            GroupKind::Effect { harmonic, .. } => *harmonic,
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

impl Group {
    /// The effect kind of the group's parameters (`None`: geometric).
    pub fn effect_kind(&self) -> Option<Kind> {
        self.params.iter().find_map(|p| match p {
            Param::Effect { kind, .. } => Some(*kind),
            Param::Geometric(_) => None,
        })
    }
}

/// Names of the parameters (1-based joints), e.g. `a2`, `q3 h2 cos`.
pub fn param_name(model: &NominalModel, p: &Param) -> String {
    match *p {
        Param::Geometric(k) => match model {
            NominalModel::DhChain(c) => parameter_names_for(c)[k].clone(),
            NominalModel::PlanarChain { .. } => format!("l{}", k + 1),
        },
        Param::Effect { kind, site, component } => kind.param_name(site, component),
    }
}

/// Whether a geometric parameter is an angle (radians) rather than a length.
pub fn is_angle(model: &NominalModel, p: &Param) -> bool {
    match (model, p) {
        (NominalModel::DhChain(c), Param::Geometric(k)) => {
            let name = &parameter_names_for(c)[*k];
            name.starts_with("alpha") || name.starts_with("theta") || name.starts_with("base_r") || name.starts_with("tool_r")
        }
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
    candidate_groups_of(KINDS, model, options, m)
}

/// [`candidate_groups`] of the effect kinds `kinds`: the geometric group, then per joint each
/// kind's groups in the list's order.
pub fn candidate_groups_of(kinds: &[Kind], model: &NominalModel, options: &LibraryOptions, m: usize) -> Vec<Group> {
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
        for &kind in kinds {
            groups.extend(kind.groups(model, options, m, j).into_iter().map(|g| Group {
                name: g.name,
                kind: GroupKind::Effect { type_name: g.type_name, harmonic: g.harmonic },
                joint: Some(g.joint),
                params: g.params.into_iter().map(|(site, component)| Param::Effect { kind, site, component }).collect(),
            }));
        }
    }
    groups
}

/// Adds `e` to `list`, merging it into an entry of the same kind and site (parameters add).
fn merge_effect(list: &mut heapless::Vec<Effect, { cbd_protocol::MAX_EFFECTS }>, e: Instance) -> Result<(), super::DiagnoseError> {
    for old in list.iter_mut() {
        let mut merged = Instance::of(old);
        if merged.kind == e.kind && merged.site == e.site {
            for (o, v) in merged.values.iter_mut().zip(&e.values) {
                *o += v;
            }
            *old = merged.to_blob().expect("a blob effect's kind has a blob form");
            return Ok(());
        }
    }
    let blob = e.to_blob().ok_or(super::DiagnoseError::NotInBlob { kind: e.kind.name() })?;
    list.push(blob).map_err(|_| super::DiagnoseError::TooManyEffects)
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
        if let Some(e) = param.effect(*v) {
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
    let effects: Vec<(usize, Instance)> = params.iter().enumerate().filter_map(|(col, p)| p.effect(1.0).map(|e| (col, e))).collect();
    if effects.is_empty() {
        return jac;
    }
    for i in 0..rows {
        let q = data.joints(i);
        let dk = kinematics::deflected_rigid_jacobian(model, &rigid, q, kinematics::point_of_row(model, i));
        for (col, e) in &effects {
            match e.kind.response(model, e, q) {
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
        let cos = |p: &Param| p.component_name() == "cos" && matches!(p, Param::Effect { site: Site { index: 1, sub: 1 }, .. });
        let transmission = params.iter().position(cos).unwrap();
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
