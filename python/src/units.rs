//! One unit convention for every array in and out of a `cbd.Model` (issue 51 class 7): a model that
//! came with a model file — `cbd.fit(model_file, …)`, `Model.load(path, model_file)` — takes and
//! returns arrays in that file's columns' units, as `cbd fit`'s CSV holds them (joints in the
//! `[measurements]` angle unit, e.g. degrees for the UR5 example, through its joint map and a planar
//! frame's offsets; positions in its length unit and, for a planar frame, in the arm's base frame).
//! A model without one (a blob alone, or the built-in RR arm's) is in the blob's units: radians and
//! the model's length unit.

use cbd_trainer::face::{ColumnSpec, JointColumns};

/// The columns of the model file a model came with.
#[derive(Debug, Clone)]
pub struct Columns {
    pub spec: ColumnSpec,
}

impl Columns {
    /// Column length unit → model length unit.
    fn length_factor(&self) -> f64 {
        self.spec.length_unit.factor_to(self.spec.model_length_unit)
    }

    /// A row of joint columns → the model's joints, as the CSV import reads it.
    pub fn joints_in(&self, c: &[f64]) -> Vec<f64> {
        JointColumns::new(&self.spec).to_model(c)
    }

    /// The model's joints → the controller's values in the columns' units, turned by whole turns
    /// of revolute joints into the joint limits where that brings them there (as `cbd compensate`
    /// writes its commands).
    pub fn joints_out(&self, q: &[f64], periodic: &[bool]) -> Vec<f64> {
        JointColumns::new(&self.spec).within_limits(q, periodic)
    }

    /// A position in the columns' units and frame → the model's (the import's order: the unit,
    /// then a planar frame's base and yaw).
    pub fn position_in(&self, y: &[f64]) -> Vec<f64> {
        let f = self.length_factor();
        let mut p: Vec<f64> = y.iter().map(|v| v * f).collect();
        if let Some(frame) = &self.spec.planar_frame {
            frame.move_row(&mut [], &mut p);
        }
        p
    }

    /// A model position → the columns' units and frame (the inverse of [`Self::position_in`]).
    pub fn position_out(&self, p: &[f64]) -> Vec<f64> {
        let f = self.length_factor();
        let mut y = p.to_vec();
        if let Some(frame) = &self.spec.planar_frame {
            if p.len() == 2 && (frame.yaw != 0.0 || frame.base != [0.0; 2]) {
                y = frame.from_chain(p).to_vec();
            }
        }
        y.iter().map(|v| v / f).collect()
    }

    /// ∂q/∂c (n × n, row-major): the import's map from columns to joints.
    pub fn joint_derivative(&self, n: usize) -> Vec<f64> {
        affine_derivative(n, |c| self.joints_in(c))
    }

    /// ∂y/∂p (m × m, row-major): a model position's derivative into the columns' units and frame.
    pub fn position_derivative(&self, m: usize) -> Vec<f64> {
        affine_derivative(m, |p| self.position_out(p))
    }

    /// What the arrays hold, for docstrings' `units` and messages.
    pub fn describe(&self) -> String {
        format!(
            "joints in the model file's columns {} ({}; prismatic: {}), positions in {} ({})",
            self.spec.joint_columns.join(", "),
            self.spec.angle_unit.name(),
            self.spec.length_unit.name(),
            self.spec.length_unit.name(),
            match self.spec.planar_frame {
                Some(_) => "the arm's base frame, as the CSV holds them",
                None => "as the CSV holds them",
            }
        )
    }
}

/// The linear part of an affine map `f` of `dim` values (dim × dim, row-major): its columns are the
/// images of the unit vectors less the image of zero (exact for the import's maps, which are affine).
fn affine_derivative(dim: usize, f: impl Fn(&[f64]) -> Vec<f64>) -> Vec<f64> {
    let zero = f(&vec![0.0; dim]);
    let mut d = vec![0.0; dim * dim];
    for k in 0..dim {
        let mut e = vec![0.0; dim];
        e[k] = 1.0;
        let image = f(&e);
        for row in 0..dim {
            d[row * dim + k] = image[row] - zero[row];
        }
    }
    d
}

/// `left` (a × b) · `right` (b × c), row-major.
pub fn times(left: &[f64], right: &[f64], a: usize, b: usize, c: usize) -> Vec<f64> {
    let mut out = vec![0.0; a * c];
    for i in 0..a {
        for k in 0..b {
            let l = left[i * b + k];
            if l != 0.0 {
                for j in 0..c {
                    out[i * c + j] += l * right[k * c + j];
                }
            }
        }
    }
    out
}
