//! The controller's joint values (a CSV's joint columns, in their units) and the model's joints,
//! both ways: the import's mapping ([`JointColumns::to_model`]: the joint map in the columns'
//! units, each joint's unit, a planar frame's offsets) and its inverse for the commands `cbd`
//! writes. A written command is re-read through the same [`JointColumns::to_model`] the import
//! uses, so what is checked is what the controller — or `cbd` itself — reads back.

use super::column_spec::ColumnSpec;
use cbd_protocol::JointKind;

/// How one spec's joint columns map to the model's joints.
pub struct JointColumns<'a> {
    spec: &'a ColumnSpec,
    /// Column unit → model unit per joint (radians, or the model's length unit).
    factor: Vec<f64>,
}

impl<'a> JointColumns<'a> {
    pub fn new(spec: &'a ColumnSpec) -> Self {
        let factor = spec
            .joint_kinds
            .iter()
            .map(|k| match k {
                JointKind::Revolute => spec.angle_unit.radians(),
                JointKind::Prismatic => spec.length_unit.factor_to(spec.model_length_unit),
            })
            .collect();
        JointColumns { spec, factor }
    }

    /// Column unit → model unit per joint.
    pub fn factors(&self) -> &[f64] {
        &self.factor
    }

    /// Controller values `c` (the columns' units) → model joints, as the import reads a row.
    pub fn to_model(&self, c: &[f64]) -> Vec<f64> {
        let mut q = vec![0.0; c.len()];
        self.mapped(c, &mut q);
        if let Some(frame) = &self.spec.planar_frame {
            frame.move_row(&mut q, &mut []);
        }
        q
    }

    /// [`Self::to_model`] of controller values already in model units (`c × factor`, where the
    /// limits apply, as `cbd plan` samples them); without a joint map the values themselves.
    pub fn to_model_from_model_units(&self, c: &[f64]) -> Vec<f64> {
        let mut q = match &self.spec.joint_map {
            Some(_) => {
                let columns: Vec<f64> = c.iter().zip(&self.factor).map(|(v, f)| v / f).collect();
                let mut q = vec![0.0; c.len()];
                self.mapped(&columns, &mut q);
                q
            }
            None => c.to_vec(),
        };
        if let Some(frame) = &self.spec.planar_frame {
            frame.move_row(&mut q, &mut []);
        }
        q
    }

    /// `c` → the model's joints before a planar frame's offsets: the joint map in the columns'
    /// units, then each joint's unit factor (the import's order; zero terms skipped by the map).
    pub fn mapped(&self, c: &[f64], q: &mut [f64]) {
        match &self.spec.joint_map {
            Some(map) => {
                map.to_model(c, q);
                q.iter_mut().zip(&self.factor).for_each(|(q, f)| *q *= f);
            }
            None => q.iter_mut().zip(c.iter().zip(&self.factor)).for_each(|(q, (c, f))| *q = c * f),
        }
    }

    /// Model joints `q` → the controller's values in the columns' units (the inverse of
    /// [`Self::to_model`] up to rounding).
    pub fn to_columns(&self, q: &[f64]) -> Vec<f64> {
        let mut joints = q.to_vec();
        if let Some(frame) = &self.spec.planar_frame {
            joints.iter_mut().zip(&frame.offsets).for_each(|(q, o)| *q -= o);
        }
        let mut columns: Vec<f64> = joints.iter().zip(&self.factor).map(|(v, f)| v / f).collect();
        if let Some(map) = &self.spec.joint_map {
            let model = columns.clone();
            map.to_columns(&model, &mut columns);
        }
        columns
    }

    /// How far controller values `c` are outside the joint limits (summed over the joints, in
    /// model units, where the import checks them: c × factor); ∞ for a value that is not finite.
    pub fn limit_excess(&self, c: &[f64]) -> f64 {
        c.iter()
            .zip(&self.factor)
            .zip(&self.spec.joint_limits)
            .map(|((c, f), [lo, hi])| {
                let v = c * f;
                if v.is_finite() {
                    (lo - v).max(v - hi).max(0.0)
                } else {
                    f64::INFINITY
                }
            })
            .sum()
    }

    /// The command for model joints `q` as the controller's values, inside the joint limits where
    /// whole turns of the `periodic` joints (on which the calibrated model does not change) bring
    /// it there: a command of 276° against limits of ±180° is −84°. Greedy over the joints (a
    /// coupled map moves several columns per turn), at most two passes; `q` itself when inside.
    pub fn within_limits(&self, q: &[f64], periodic: &[bool]) -> Vec<f64> {
        let turn = 2.0 * std::f64::consts::PI;
        let mut best = q.to_vec();
        let mut excess = self.limit_excess(&self.to_columns(&best));
        for _ in 0..2 {
            if excess == 0.0 || !excess.is_finite() {
                break;
            }
            for d in (0..q.len()).filter(|&d| periodic.get(d).copied().unwrap_or(false)) {
                for turns in [-2.0, -1.0, 1.0, 2.0] {
                    let mut moved = best.clone();
                    moved[d] += turns * turn;
                    let e = self.limit_excess(&self.to_columns(&moved));
                    if e < excess {
                        (best, excess) = (moved, e);
                    }
                }
            }
        }
        self.to_columns(&best)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::model_file::parse_model_file;
    use std::path::Path;

    const DEG: &str = "length_unit = \"mm\"\nangle_unit = \"deg\"\n[planar]\nlengths = [1000.0, 500.0]\n\
                       [measurements]\njoints = [\"q1\", \"q2\"]\npositions = [\"x\", \"y\"]\njoint_limits = [[-180, 180], [-90, 270]]\n";

    #[test]
    fn commands_are_turned_into_the_limits_and_read_back() {
        let spec = parse_model_file(DEG, Path::new("d.toml")).unwrap().column_spec().unwrap();
        let columns = JointColumns::new(&spec);
        let q = [276f64.to_radians(), -100f64.to_radians()];
        assert!(columns.limit_excess(&columns.to_columns(&q)) > 0.0);
        let c = columns.within_limits(&q, &[true, true]);
        assert!((c[0] - -84.0).abs() < 1e-12 && (c[1] - 260.0).abs() < 1e-12, "{c:?}");
        assert_eq!(columns.limit_excess(&c), 0.0);
        // Not periodic (an encoder scale on the joint): left outside, and said so.
        let c = columns.within_limits(&q, &[false, true]);
        assert!((c[0] - 276.0).abs() < 1e-12 && columns.limit_excess(&c) > 0.0);
        assert_eq!(columns.limit_excess(&[f64::NAN, 0.0]), f64::INFINITY);
        // A joint map and a planar frame: to_model is the import's reading, to_columns its inverse.
        let mapped = DEG.replace("[planar]\n", "[planar]\noffsets = [10.0, -5.0]\n")
            + "[measurements.joint_map]\nsign = { q2 = -1 }\ncoupling = [[1, 0], [1, 1]]\n";
        let file = parse_model_file(&mapped, Path::new("m.toml")).unwrap();
        let spec = file.column_spec().unwrap();
        let columns = JointColumns::new(&spec);
        let read = crate::data::csv_import::read_measurements_from("q1,q2,x,y\n30,40,1,2\n".as_bytes(), Path::new("r.csv"), &spec)
            .unwrap()
            .measurements;
        assert_eq!(columns.to_model(&[30.0, 40.0]), read.joints);
        let back = columns.to_columns(&read.joints);
        assert!((back[0] - 30.0).abs() < 1e-12 && (back[1] - 40.0).abs() < 1e-12, "{back:?}");
    }
}
