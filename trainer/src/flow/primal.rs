//! The control points' flow, integrated by the runtime's functions, keeping every stage's state
//! for the tangent.

use cbd_protocol::{Integrator, JointKernel, MomentumLaw, NominalModel, Normalisation, TaskKernel};
use cbd_runtime::internals::flow::{Dims, FlowParams};

/// The fixed part of a flow: configurations, their nominal kinematics, kernels and scheme.
#[derive(Debug, Clone)]
pub struct ControlPoints {
    pub dims: Dims,
    /// N × n configurations.
    pub points: Vec<f64>,
    /// N × state_len initial state with P = 0: k0(x_i), Dk0(x_i) in internal units.
    pub initial: Vec<f64>,
    /// The configurations' joint-kernel features (`cbd_runtime::internals::kernel::write_features`), as the
    /// runtime keeps them.
    pub features: Vec<f64>,
    /// The joint kernel as the flow integrates it: γ carries the law's field sign
    /// ([`JointKernel::for_flow`]).
    pub joint_kernel: JointKernel,
    pub task_kernel: TaskKernel,
    pub law: MomentumLaw,
    pub integrator: Integrator,
}

/// One integration of the control points from given momenta.
#[derive(Debug, Clone)]
pub struct PrimalFlow {
    /// Input state of every stage, `stages × (N × state_len)`.
    pub stage_states: Vec<f64>,
    /// Final state (t = 1), N × state_len.
    pub last: Vec<f64>,
}

impl ControlPoints {
    pub fn new(
        nominal: &NominalModel,
        normalisation: &Normalisation,
        points: Vec<f64>,
        joint_kernel: JointKernel,
        task_kernel: TaskKernel,
        law: MomentumLaw,
        integrator: Integrator,
    ) -> Self {
        let dims = Dims { n: nominal.n_joints(), m: nominal.task_dim() };
        let (m, n) = (dims.m, dims.n);
        let mut initial = vec![0.0; points.len() / n * dims.state_len()];
        // Control point c is tool point c mod m_p (the blob's convention, the runtime's initial state).
        for (c, (x, s)) in points.chunks_exact(n).zip(initial.chunks_exact_mut(dims.state_len())).enumerate() {
            let k0 = crate::nominal::row_kinematics(nominal, x, c).normalised(normalisation);
            s[..m].copy_from_slice(&k0.position[..m]);
            for a in 0..m {
                s[m + a * n..m + (a + 1) * n].copy_from_slice(&k0.jacobian[a][..n]);
            }
        }
        let mut features = vec![0.0; cbd_runtime::internals::kernel::features_len(points.len() / n, n)];
        cbd_runtime::internals::kernel::write_features(&joint_kernel, n, &points, &mut features);
        let joint_kernel = joint_kernel.for_flow(law);
        ControlPoints { dims, points, initial, features, joint_kernel, task_kernel, law, integrator }
    }

    pub fn len(&self) -> usize {
        self.points.len() / self.dims.n
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    pub fn params(&self) -> FlowParams<'_> {
        FlowParams { dims: self.dims, joint_kernel: &self.joint_kernel, task_kernel: &self.task_kernel, law: self.law }
    }

    /// k0(x_i) in internal units, N × m.
    pub fn nominal_positions(&self) -> Vec<f64> {
        let (m, len) = (self.dims.m, self.dims.state_len());
        self.initial.chunks_exact(len).flat_map(|s| s[..m].to_vec()).collect()
    }

    /// Dk0(x_i) in internal units, N × m × n (row-major per point).
    pub fn nominal_jacobians(&self) -> Vec<f64> {
        let (m, n, len) = (self.dims.m, self.dims.n, self.dims.state_len());
        self.initial.chunks_exact(len).flat_map(|s| s[m..m + m * n].to_vec()).collect()
    }

    /// (k0, Dk0)(x_i) in internal units, N × (m + m n): the initial state without the momenta.
    pub fn nominal_kinematics(&self) -> Vec<f64> {
        let (m, n, len) = (self.dims.m, self.dims.n, self.dims.state_len());
        self.initial.chunks_exact(len).flat_map(|s| s[..m + m * n].to_vec()).collect()
    }

    /// Integrates from initial momenta `p0` (N × m) with the runtime's scheme: the runtime's
    /// integration loop and rates (from the kernel-feature table, as a loaded model does), each
    /// stage's rows split across the current rayon pool (bit-identical to the runtime's one pass).
    pub fn integrate(&self, p0: &[f64]) -> Result<PrimalFlow, cbd_runtime::Error> {
        use rayon::prelude::*;
        let (m, n, len) = (self.dims.m, self.dims.n, self.dims.state_len());
        let count = self.len();
        let mut state = self.initial.clone();
        for (s, p) in state.chunks_exact_mut(len).zip(p0.chunks_exact(m)) {
            s[m + m * n..].copy_from_slice(p);
        }
        let stages = self.integrator.stage_count();
        let mut stage_states = vec![0.0; stages * state.len()];
        let mut scratch = vec![0.0; cbd_runtime::internals::integrate::scratch_len(state.len())];
        let mut trajectory = vec![0.0; stages * count * self.dims.sample_len()];
        let block = state.len();
        let params = self.params();
        let rows_per_task = count.div_ceil(16).max(1);
        cbd_runtime::internals::flow::control_points::integrate_points(
            self.dims,
            self.integrator,
            count,
            &mut state,
            &mut scratch,
            &mut trajectory,
            |stage, y| stage_states[stage * block..(stage + 1) * block].copy_from_slice(y),
            |y, samples, out| {
                out.par_chunks_mut(rows_per_task * len).enumerate().for_each(|(task, out)| {
                    let start = task * rows_per_task;
                    let rows = start..start + out.len() / len;
                    cbd_runtime::internals::flow::control_point_rates_with_features(&params, &self.features, y, samples, rows, out);
                });
            },
        )?;
        Ok(PrimalFlow { stage_states, last: state })
    }
}

impl PrimalFlow {
    /// k1(x_i) = k_i(1), N × m, internal units.
    pub fn positions(&self, dims: Dims) -> Vec<f64> {
        self.last.chunks_exact(dims.state_len()).flat_map(|s| s[..dims.m].to_vec()).collect()
    }
}
