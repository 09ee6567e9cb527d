//! Consistency checks run on every encode and decode.

use crate::error::ModelError;
use crate::expansion::{code_is_sin, code_order, FieldExpansion};
use crate::limits::{MAX_EXPANSION_FEATURES, MAX_EXPANSION_ORDER, MAX_STEPS, MAX_TOOL_POINT_COORDINATE, ROTATION_TOLERANCE};
use crate::model::*;
use crate::physical_effects::{Effect, Effects, GRAVITY_UNIT_TOLERANCE, MAX_HARMONIC};

fn finite(field: &'static str, values: impl IntoIterator<Item = f64>) -> Result<(), ModelError> {
    for (index, v) in values.into_iter().enumerate() {
        if !v.is_finite() {
            return Err(ModelError::NonFinite { field, index });
        }
    }
    Ok(())
}

fn positive(field: &'static str, v: f64) -> Result<(), ModelError> {
    finite(field, [v])?;
    if v > 0.0 {
        Ok(())
    } else {
        Err(ModelError::OutOfRange { field })
    }
}

fn dimension(field: &'static str, expected: usize, found: usize) -> Result<(), ModelError> {
    if expected == found {
        Ok(())
    } else {
        Err(ModelError::Dimension { field, expected, found })
    }
}

/// R (row-major) must be a rotation: RRᵀ = I within [`ROTATION_TOLERANCE`] entry by entry and
/// det R > 0. A blob with a scaled, sheared or mirrored base or tool passes every finiteness check
/// yet evaluates to nonsense (1e24 mm) and misleads compensation.
fn rotation(field: &'static str, r: &[f64; 9]) -> Result<(), ModelError> {
    // Constant indices only: no bounds check, no panic path in the firmware.
    let rows = [[r[0], r[1], r[2]], [r[3], r[4], r[5]], [r[6], r[7], r[8]]];
    for (i, a) in rows.iter().enumerate() {
        for (j, b) in rows.iter().enumerate() {
            let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            let want = if i == j { 1.0 } else { 0.0 };
            // Finite entries (checked first): `>` refuses what `<=` would not accept.
            if (dot - want).abs() > ROTATION_TOLERANCE {
                return Err(ModelError::OutOfRange { field });
            }
        }
    }
    let det = r[0] * (r[4] * r[8] - r[5] * r[7]) - r[1] * (r[3] * r[8] - r[5] * r[6]) + r[2] * (r[3] * r[7] - r[4] * r[6]);
    if det > 0.0 {
        Ok(())
    } else {
        Err(ModelError::OutOfRange { field })
    }
}

/// Control points are pose-major, each pose's configuration repeated for its `per_pose` tool
/// points (docs/DESIGN.md §12): a blob whose tool-point count regroups the rows (2 or 4 points
/// over data of 3) breaks this and is refused; `index` is the first control point that differs.
fn poses_repeat_their_configuration(points: crate::f64_slice::F64Slice<'_>, n: usize, per_pose: usize) -> Result<(), ModelError> {
    if per_pose <= 1 || n == 0 {
        return Ok(());
    }
    let count = points.len() / n;
    for c in 0..count {
        if c % per_pose == 0 {
            continue;
        }
        for d in 0..n {
            if points.get(c * n + d).map(f64::to_bits) != points.get((c - 1) * n + d).map(f64::to_bits) {
                return Err(ModelError::OutOfRangeAt { field: "points (a pose's tool points at different configurations)", index: c });
            }
        }
    }
    Ok(())
}

/// `count × width` f64 values must fill `found` bytes. Checked products: on a 32-bit controller
/// `n_points × n × 8` wraps for a crafted `n_points`, and a wrapped size could match an empty array.
fn array_bytes(field: &'static str, count: usize, width: usize, found: usize) -> Result<(), ModelError> {
    match count.checked_mul(width).and_then(|values| values.checked_mul(8)) {
        Some(expected) => dimension(field, expected, found),
        None => Err(ModelError::OutOfRange { field }),
    }
}

impl Effects {
    /// Checks the effects of a chain of `n_joints` joints: every joint/link index below
    /// `n_joints`, harmonics 1..=[`MAX_HARMONIC`], every value finite, `link_masses` empty or one
    /// finite value ≥ 0 per joint, the gravity direction finite and of unit length (within
    /// [`GRAVITY_UNIT_TOLERANCE`]). `index` in the errors is the effect's position in `list`
    /// (the joint for `link_masses`, the component for `direction`).
    pub fn validate(&self, n_joints: usize) -> Result<(), ModelError> {
        let g = &self.gravity;
        finite("nominal.effects.gravity.direction", g.direction)?;
        let [x, y, z] = g.direction;
        let length2 = x * x + y * y + z * z;
        let (lo, hi) = (1.0 - GRAVITY_UNIT_TOLERANCE, 1.0 + GRAVITY_UNIT_TOLERANCE);
        if !(length2 >= lo * lo && length2 <= hi * hi) {
            return Err(ModelError::OutOfRange { field: "nominal.effects.gravity.direction (not unit length)" });
        }
        if !g.link_masses.is_empty() {
            dimension("nominal.effects.gravity.link_masses", n_joints, g.link_masses.len())?;
            finite("nominal.effects.gravity.link_masses", g.link_masses.iter().copied())?;
            if let Some(index) = g.link_masses.iter().position(|m| *m < 0.0) {
                return Err(ModelError::OutOfRangeAt { field: "nominal.effects.gravity.link_masses (negative)", index });
            }
        }
        for (index, effect) in self.list.iter().enumerate() {
            let in_range = |field: &'static str, i: u8| {
                if (i as usize) < n_joints {
                    Ok(())
                } else {
                    Err(ModelError::OutOfRangeAt { field, index })
                }
            };
            let value = |field: &'static str, v: f64| if v.is_finite() { Ok(()) } else { Err(ModelError::NonFinite { field, index }) };
            match *effect {
                Effect::EncoderScale { joint, scale } => {
                    in_range("nominal.effects.list.EncoderScale.joint", joint)?;
                    value("nominal.effects.list.EncoderScale.scale", scale)?;
                }
                Effect::Transmission { joint, harmonic, cos, sin } => {
                    in_range("nominal.effects.list.Transmission.joint", joint)?;
                    if !(1..=MAX_HARMONIC).contains(&harmonic) {
                        return Err(ModelError::OutOfRangeAt { field: "nominal.effects.list.Transmission.harmonic", index });
                    }
                    value("nominal.effects.list.Transmission.cos", cos)?;
                    value("nominal.effects.list.Transmission.sin", sin)?;
                }
                Effect::GravityCompliance { joint, compliance } => {
                    in_range("nominal.effects.list.GravityCompliance.joint", joint)?;
                    value("nominal.effects.list.GravityCompliance.compliance", compliance)?;
                }
                Effect::LinkBending { link, compliance } => {
                    in_range("nominal.effects.list.LinkBending.link", link)?;
                    value("nominal.effects.list.LinkBending.compliance", compliance)?;
                }
                Effect::GravityMoment { joint, link, mass, first_moment } => {
                    in_range("nominal.effects.list.GravityMoment.joint", joint)?;
                    in_range("nominal.effects.list.GravityMoment.link", link)?;
                    // A link before its joint adds no torque to it: an entry that means nothing.
                    if link < joint {
                        return Err(ModelError::OutOfRangeAt {
                            field: "nominal.effects.list.GravityMoment.link (before its joint)",
                            index,
                        });
                    }
                    value("nominal.effects.list.GravityMoment.mass", mass)?;
                    for v in first_moment {
                        value("nominal.effects.list.GravityMoment.first_moment", v)?;
                    }
                }
            }
        }
        Ok(())
    }
}

impl Model<'_> {
    /// Checks every dimension and value; a model that passes can be evaluated.
    pub fn validate(&self) -> Result<(), ModelError> {
        let n = self.n_joints();
        let m = self.task_dim();
        if n == 0 {
            return Err(ModelError::OutOfRange { field: "nominal.joints" });
        }
        match &self.nominal {
            NominalModel::PlanarChain { lengths, .. } => finite("nominal.lengths", lengths.iter().copied())?,
            NominalModel::DhChain(c) => {
                for j in &c.joints {
                    finite("nominal.joints", [j.a, j.alpha, j.d, j.theta_offset])?;
                }
                for (name, t) in [("nominal.base", &c.base), ("nominal.tool", &c.tool)] {
                    finite(name, t.rotation.iter().chain(t.translation.iter()).copied())?;
                }
                rotation("nominal.base.rotation (not a rotation within ROTATION_TOLERANCE)", &c.base.rotation)?;
                rotation("nominal.tool.rotation (not a rotation within ROTATION_TOLERANCE)", &c.tool.rotation)?;
                finite("nominal.tool_points", c.tool_points.iter().flatten().copied())?;
                if let Some(index) = c.tool_points.iter().flatten().position(|v| v.abs() > MAX_TOOL_POINT_COORDINATE) {
                    return Err(ModelError::OutOfRangeAt { field: "nominal.tool_points (beyond MAX_TOOL_POINT_COORDINATE)", index });
                }
            }
        }
        self.nominal.effects().validate(n)?;
        finite("normalisation.task_offset", self.normalisation.task_offset)?;
        positive("normalisation.task_scale", self.normalisation.task_scale)?;
        positive("joint_kernel.gamma", self.joint_kernel.gamma)?;
        dimension("joint_kernel.axes", n, self.joint_kernel.axes.len())?;
        for (d, axis) in self.joint_kernel.axes.iter().enumerate() {
            match *axis {
                JointKernelAxis::Periodic { b } => {
                    positive("joint_kernel.axes.b", b)?;
                    if !self.nominal.is_revolute(d) {
                        return Err(ModelError::OutOfRange { field: "joint_kernel.axes (periodic on a prismatic joint)" });
                    }
                }
                JointKernelAxis::Gaussian { width } => positive("joint_kernel.axes.width", width)?,
            }
        }
        positive("task_kernel.width", self.task_kernel.width)?;
        if self.integrator.steps == 0 || self.integrator.steps > MAX_STEPS {
            return Err(ModelError::OutOfRange { field: "integrator.steps" });
        }
        positive("sigma", self.sigma)?;
        if let Some(sigma) = self.noise_sigma {
            positive("noise_sigma", sigma)?;
        }
        if self.n_points == 0 {
            return Err(ModelError::OutOfRange { field: "n_points" });
        }
        let n_points = self.n_points as usize;
        if !n_points.is_multiple_of(self.nominal.tool_point_count()) {
            return Err(ModelError::OutOfRange { field: "n_points (not a multiple of the tool points)" });
        }
        array_bytes("points", n_points, n, self.points.byte_len())?;
        array_bytes("momenta", n_points, m, self.momenta.byte_len())?;
        finite("points", self.points.iter())?;
        poses_repeat_their_configuration(self.points, n, self.nominal.tool_point_count())?;
        finite("momenta", self.momenta.iter())?;
        if let Some(e) = &self.expansion {
            e.validate(self)?;
        }
        if let Some(c) = &self.configuration_kernel {
            c.validate(self)?;
        }
        if let Some(d) = &self.drift {
            finite("drift.sd", [d.sd])?;
            if d.sd < 0.0 {
                return Err(ModelError::OutOfRange { field: "drift.sd" });
            }
            positive("drift.length", d.length)?;
            if self.noise_sigma.is_none() {
                return Err(ModelError::OutOfRange { field: "drift (without noise_sigma)" });
            }
        }
        if let Some(p) = &self.provenance {
            if p.is_empty() {
                return Err(ModelError::OutOfRange { field: "provenance (empty: write None)" });
            }
            if p.import_frame.is_some_and(|f| f.joints.is_none() && f.positions.is_none()) {
                return Err(ModelError::OutOfRange { field: "provenance.import_frame (empty: write None)" });
            }
        }
        Ok(())
    }
}

impl ConfigurationKernel {
    /// Checks the kernel against its model (whose other fields are valid): γ_C and the widths
    /// positive and finite, one axis per joint of the joint kernel's kind; and what the runtime
    /// evaluates it with: the kernel form (no expansion) and the linear scheme, Euler × 1 (where the
    /// control points do not move, so the field needs no pair table of the control points), with
    /// the noise σ its format's layout holds.
    pub fn validate(&self, model: &Model<'_>) -> Result<(), ModelError> {
        positive("configuration_kernel.gamma", self.gamma)?;
        dimension("configuration_kernel.axes", model.n_joints(), self.axes.len())?;
        for (d, axis) in self.axes.iter().enumerate() {
            match *axis {
                JointKernelAxis::Periodic { b } => {
                    positive("configuration_kernel.axes.b", b)?;
                    if !model.nominal.is_revolute(d) {
                        return Err(ModelError::OutOfRangeAt {
                            field: "configuration_kernel.axes (periodic on a prismatic joint)",
                            index: d,
                        });
                    }
                }
                JointKernelAxis::Gaussian { width } => positive("configuration_kernel.axes.width", width)?,
            }
            // The same form as the joint kernel's axis: both read one table of the control points'
            // kernel features ((cos, sin) or (x, 0) per joint, independent of the widths).
            let same_form = matches!(
                (axis, model.joint_kernel.axes.get(d)),
                (JointKernelAxis::Periodic { .. }, Some(JointKernelAxis::Periodic { .. }))
                    | (JointKernelAxis::Gaussian { .. }, Some(JointKernelAxis::Gaussian { .. }))
            );
            if !same_form {
                return Err(ModelError::OutOfRangeAt { field: "configuration_kernel.axes (not the joint kernel's form)", index: d });
            }
        }
        if let Some(width) = self.task_width {
            positive("configuration_kernel.task_width", width)?;
        }
        if model.integrator.method != IntegratorMethod::Euler || model.integrator.steps != 1 {
            return Err(ModelError::OutOfRange { field: "configuration_kernel (needs the integrator Euler × 1)" });
        }
        if model.expansion.is_some() {
            return Err(ModelError::OutOfRange { field: "configuration_kernel (with an expansion)" });
        }
        if model.noise_sigma.is_none() {
            return Err(ModelError::OutOfRange { field: "configuration_kernel (without noise_sigma)" });
        }
        Ok(())
    }
}

impl FieldExpansion<'_> {
    /// Checks the expansion against its model (whose other fields are valid): tolerance in (0, 1),
    /// task radius > 0, at most [`MAX_EXPANSION_FEATURES`] functions per basis, r_V × n codes valid
    /// for their axes (orders ≤ [`MAX_EXPANSION_ORDER`]; Gaussian axes: no sine bit; periodic axes:
    /// no sin(0·x), a function that is identically zero), r_W × m exponents ≤ [`MAX_EXPANSION_ORDER`],
    /// `stage_count × (r_V n + r_W m)` finite weights.
    pub fn validate(&self, model: &Model<'_>) -> Result<(), ModelError> {
        let (n, m) = (model.n_joints(), model.task_dim());
        finite("expansion.tolerance", [self.tolerance])?;
        if !(self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(ModelError::OutOfRange { field: "expansion.tolerance" });
        }
        positive("expansion.task_radius", self.task_radius)?;
        if self.n_joint_features > MAX_EXPANSION_FEATURES {
            return Err(ModelError::OutOfRange { field: "expansion.n_joint_features" });
        }
        if self.n_task_features > MAX_EXPANSION_FEATURES {
            return Err(ModelError::OutOfRange { field: "expansion.n_task_features" });
        }
        let (r_v, r_w) = (self.n_joint_features as usize, self.n_task_features as usize);
        dimension("expansion.joint_codes", r_v * n, self.joint_codes.len())?;
        dimension("expansion.task_exponents", r_w * m, self.task_exponents.len())?;
        dimension("expansion.weights", 8 * model.integrator.stage_count() * self.stage_len(n, m), self.weights.byte_len())?;
        for (index, &code) in self.joint_codes.iter().enumerate() {
            if code_order(code) > MAX_EXPANSION_ORDER {
                return Err(ModelError::OutOfRangeAt { field: "expansion.joint_codes (order)", index });
            }
            let axis = model.joint_kernel.axes.get(index % n.max(1));
            match axis {
                Some(JointKernelAxis::Gaussian { .. }) if code_is_sin(code) => {
                    return Err(ModelError::OutOfRangeAt { field: "expansion.joint_codes (sine on a Gaussian axis)", index });
                }
                Some(JointKernelAxis::Periodic { .. }) if code == 1 => {
                    return Err(ModelError::OutOfRangeAt { field: "expansion.joint_codes (sin 0x)", index });
                }
                _ => {}
            }
        }
        if let Some(index) = self.task_exponents.iter().position(|&a| a > MAX_EXPANSION_ORDER) {
            return Err(ModelError::OutOfRangeAt { field: "expansion.task_exponents", index });
        }
        finite("expansion.weights", self.weights.iter())
    }
}

#[cfg(test)]
mod array_bytes_tests {
    use super::*;

    #[test]
    fn a_size_that_wraps_the_address_space_is_refused_not_matched_with_an_empty_array() {
        // 2^(bits − 3) values × 8 bytes = 2^bits: wrapping arithmetic gives 0, the length of an empty array.
        let count = 1usize << (usize::BITS - 3);
        assert_eq!(count.wrapping_mul(8), 0);
        assert_eq!(array_bytes("points", count, 1, 0), Err(ModelError::OutOfRange { field: "points" }));
        assert_eq!(array_bytes("points", 3, 2, 48), Ok(()));
        assert_eq!(array_bytes("momenta", 3, 2, 40), Err(ModelError::Dimension { field: "momenta", expected: 48, found: 40 }));
    }
}
