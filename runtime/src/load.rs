//! Loading a blob into caller-provided storage: the loaded model ([`Calibrator`]'s state: the blob's
//! arrays, the control points' trajectory or the expansion's weights, working space) and how much
//! storage it needs. The operations on it are the modules above (`evaluate`, `flow_maps`, `pose`,
//! `compensate`, `compensate_pose`); [`Calibrator`]'s methods (calibrator.rs) wrap them.

use crate::error::Error;
use crate::flow::configuration_field::configuration_row_len;
use crate::flow::control_points::{initial_state, integrate_control_points_with_features};
use crate::flow::{Dims, FlowParams};
use crate::integrate::scratch_len;
use crate::kernel::{features_len, joint_features, FEATURES_PER_JOINT};
use crate::real::Real;
use cbd_protocol::{decode, Integrator, Model, MAX_JOINTS, MAX_TASK_DIM};

/// [`Real`] values of storage a model with these sizes needs: the configurations' kernel features
/// (`N × n × 2`, see [`crate::kernel::joint_features`]), the control points' trajectory
/// (`stages × N × (2m + n)`), and working space for loading and queries.
pub const fn storage_len(n_points: usize, n_joints: usize, task_dim: usize, integrator: Integrator) -> usize {
    let dims = Dims { n: n_joints, m: task_dim };
    let trajectory = integrator.stage_count() * n_points * dims.sample_len();
    let load = (1 + scratch_len(1)) * n_points * dims.state_len();
    let query = n_points * crate::flow::query_derivatives::kernel_row_len(n_joints) + crate::flow::query_derivatives::query_work_len(dims);
    features_len(n_points, n_joints) + trajectory + if load > query { load } else { query }
}

/// [`Real`] values of storage `model` needs: for the kernel form [`storage_len`] (with the
/// configuration term, format 8, docs/DESIGN.md §16, plus the query's configuration rows
/// `N × (1 + n)`); for a model with an
/// expansion (format 5, docs/DESIGN.md §11) the configurations' kernel features (`N × n × 2`, for
/// [`crate::Evaluation::support`]), the stage weights rounded once to [`Real`]
/// (`stages × (r_V n + r_W m)`), the query's joint-basis rows (`r_V × (1 + n + n²)`) and the query's
/// state with tangents and the integrator's scratch. No trajectory: nothing is integrated at load.
pub fn storage_len_for(model: &Model<'_>) -> usize {
    let (n_points, n, m) = (model.n_points as usize, model.n_joints(), model.task_dim());
    match &model.expansion {
        // With the configuration term (§16), the query's c_j and ∇c_j beside its kernel rows.
        None => {
            let configuration = model.configuration_kernel.as_ref().map_or(0, |_| n_points * configuration_row_len(n));
            storage_len(n_points, n, m, model.integrator) + configuration
        }
        Some(e) => {
            let dims = Dims { n, m };
            let weights = model.integrator.stage_count() * e.stage_len(n, m);
            let rows = e.n_joint_features as usize * crate::expansion::joint_row_len(n);
            features_len(n_points, n) + weights + rows + crate::flow::query_derivatives::query_work_len(dims)
        }
    }
}

/// A loaded model: the blob's arrays (borrowed, read in place) and the control points'
/// trajectories, integrated once at load time.
pub struct Calibrator<'a> {
    pub(crate) model: Model<'a>,
    pub(crate) dims: Dims,
    /// The configurations' kernel features ([`crate::kernel::write_features`]), N × n × 2.
    pub(crate) features: &'a [Real],
    pub(crate) trajectory: &'a mut [Real],
    /// With an expansion: its stage weights rounded once to [`Real`] (empty for the kernel form,
    /// whose `trajectory` is then empty instead).
    pub(crate) weights: &'a [Real],
    pub(crate) work: &'a mut [Real],
    /// [`crate::precision::evaluation_precision`] of the model, user units (computed at load).
    pub(crate) precision: f64,
    /// With an expansion: the highest order of each joint axis and of each task coordinate
    /// ([`crate::expansion::joint_orders`], [`crate::expansion::task_orders`], computed at load;
    /// zeros for the kernel form).
    pub(crate) orders: ExpansionOrders,
}

/// The highest orders an expansion's basis uses, per joint axis and per task coordinate: what
/// sizes the basis' factor tables, computed once per model instead of once per query.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct ExpansionOrders {
    pub joint: [u8; MAX_JOINTS],
    pub task: [u8; MAX_TASK_DIM],
}

/// Decodes and validates `blob`, then integrates the control points' trajectories into `storage`
/// (with an expansion: copies its weights), which must hold at least [`storage_len_for`] values.
pub(crate) fn load<'a>(blob: &'a [u8], storage: &'a mut [Real]) -> Result<Calibrator<'a>, Error> {
    let model = decode(blob).map_err(Error::Blob)?;
    from_model(model, storage)
}

/// As [`load`], for a model already decoded.
pub(crate) fn from_model<'a>(model: Model<'a>, storage: &'a mut [Real]) -> Result<Calibrator<'a>, Error> {
    model.validate().map_err(|e| Error::Blob(cbd_protocol::DecodeError::Invalid(e)))?;
    let dims = Dims { n: model.n_joints(), m: model.task_dim() };
    let n_points = model.n_points as usize;
    let needed = storage_len_for(&model);
    if storage.len() < needed {
        return Err(Error::StorageTooSmall { needed, got: storage.len() });
    }
    if model.expansion.is_some() {
        return with_expansion(model, dims, storage.get_mut(..needed).ok_or(Error::Internal)?);
    }
    let traj_len = model.integrator.stage_count() * n_points * dims.sample_len();
    let (features, rest) =
        storage.get_mut(..needed).ok_or(Error::Internal)?.split_at_mut_checked(features_len(n_points, dims.n)).ok_or(Error::Internal)?;
    let (trajectory, work) = rest.split_at_mut_checked(traj_len).ok_or(Error::Internal)?;
    let features: &'a [Real] = integrate_at_load(&model, dims, features, trajectory, work)?;
    let precision = crate::precision::evaluation_precision(&model);
    Ok(Calibrator { model, dims, features, trajectory, weights: &[], work, precision, orders: ExpansionOrders::default() })
}

/// A model with an expansion: the configurations' kernel features (for the support) and the
/// weights rounded once to [`Real`]; the rest of `storage` is the queries' working space.
fn with_expansion<'a>(model: Model<'a>, dims: Dims, storage: &'a mut [Real]) -> Result<Calibrator<'a>, Error> {
    let e = model.expansion.as_ref().ok_or(Error::Internal)?;
    let n_points = model.n_points as usize;
    let (features, rest) = storage.split_at_mut_checked(features_len(n_points, dims.n)).ok_or(Error::Internal)?;
    let (weights, work) = rest.split_at_mut_checked(e.weights.len()).ok_or(Error::Internal)?;
    write_features(&model, dims, features)?;
    for (dst, src) in weights.iter_mut().zip(e.weights.iter()) {
        *dst = src as Real;
    }
    let precision = crate::precision::evaluation_precision(&model);
    let orders = ExpansionOrders {
        joint: crate::expansion::joint_orders(e.joint_codes, dims.n),
        task: crate::expansion::task_orders(e.task_exponents, dims.m),
    };
    Ok(Calibrator { model, dims, features, trajectory: &mut [], weights, work, precision, orders })
}

/// K_V's features of every configuration, from the blob's f64 values (unaligned bytes).
fn write_features(model: &Model<'_>, dims: Dims, features: &mut [Real]) -> Result<(), Error> {
    let n = dims.n;
    let mut points = model.points.iter();
    let (mut x, mut f) = ([0.0; MAX_JOINTS], [[0.0; FEATURES_PER_JOINT]; MAX_JOINTS]);
    for out in features.chunks_exact_mut((n * FEATURES_PER_JOINT).max(1)) {
        for xd in x.iter_mut().take(n) {
            *xd = points.next().ok_or(Error::Internal)?;
        }
        joint_features(&model.joint_kernel, x.get(..n).ok_or(Error::Internal)?, &mut f);
        for (dst, src) in out.iter_mut().zip(f.iter().flatten()) {
            *dst = *src;
        }
    }
    Ok(())
}

/// Writes the kernel features of the configurations and the control points' trajectory;
/// `work` is scratch.
fn integrate_at_load<'f>(
    model: &Model<'_>,
    dims: Dims,
    features: &'f mut [Real],
    trajectory: &mut [Real],
    work: &mut [Real],
) -> Result<&'f [Real], Error> {
    let n_points = model.n_points as usize;
    write_features(model, dims, features)?;
    let state_len = n_points * dims.state_len();
    let (state, rest) = work.split_at_mut_checked(state_len).ok_or(Error::Internal)?;
    initial_state(model, state)?;
    let flow_kernel = model.joint_kernel.for_flow(model.momentum_law);
    let params = FlowParams { dims, joint_kernel: &flow_kernel, task_kernel: &model.task_kernel, law: model.momentum_law };
    let scratch = rest.get_mut(..scratch_len(state_len)).ok_or(Error::Internal)?;
    let features: &'f [Real] = features;
    integrate_control_points_with_features(&params, model.integrator, features, state, scratch, trajectory, |_, _| {})?;
    Ok(features)
}
