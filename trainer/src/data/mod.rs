//! Measurement data: joint configurations and measured positions.

/// N measured pairs (x_i, y_i): joint configurations (`n` per row) and positions (`m` per row),
/// in the nominal model's units (radians / length unit of the model).
#[derive(Debug, Clone, PartialEq)]
pub struct Measurements {
    pub n_joints: usize,
    pub task_dim: usize,
    /// N × n, row-major.
    pub joints: Vec<f64>,
    /// N × m, row-major.
    pub positions: Vec<f64>,
}

impl Measurements {
    pub fn new(n_joints: usize, task_dim: usize) -> Self {
        Measurements { n_joints, task_dim, joints: Vec::new(), positions: Vec::new() }
    }
    pub fn len(&self) -> usize {
        self.joints.len() / self.n_joints.max(1)
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn push(&mut self, joints: &[f64], position: &[f64]) {
        self.joints.extend_from_slice(joints);
        self.positions.extend_from_slice(position);
    }
    pub fn joints(&self, i: usize) -> &[f64] {
        &self.joints[i * self.n_joints..(i + 1) * self.n_joints]
    }
    pub fn position(&self, i: usize) -> &[f64] {
        &self.positions[i * self.task_dim..(i + 1) * self.task_dim]
    }
    /// Fold `fold` of `folds` interleaved folds (row i is held out when i mod folds = fold):
    /// (the other rows, the held-out rows).
    pub fn fold(&self, folds: usize, fold: usize) -> (Measurements, Measurements) {
        let (rest, held): (Vec<usize>, Vec<usize>) = (0..self.len()).partition(|i| i % folds != fold);
        (self.subset(&rest), self.subset(&held))
    }
    /// The rows at `indices`, in that order.
    pub fn subset(&self, indices: &[usize]) -> Measurements {
        let mut out = Measurements::new(self.n_joints, self.task_dim);
        for &i in indices {
            out.push(self.joints(i), self.position(i));
        }
        out
    }
}

pub mod csv_import;
pub mod effects_section;
pub mod model_file;
