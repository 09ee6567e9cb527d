//! Writing a model file: the inverse of [`super::parse_model_file`].

use super::ModelFile;
use crate::data::effects_section;
use cbd_protocol::{DhConvention, JointKind, NominalModel};

/// A TOML basic string.
fn quoted(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out += "\\\"",
            '\\' => out += "\\\\",
            c if (c as u32) < 0x20 || c == '\u{7f}' => out += &format!("\\u{:04X}", c as u32),
            c => out.push(c),
        }
    }
    out + "\""
}

/// The model file for `m` (the inverse of [`parse_model_file`]): its chain (a URDF-based model is
/// written as the DH table it was converted to), measurement columns, gravity model and effects.
/// Every number is written so that it reads back to the same value in the file's units; angles
/// go through the file's angle unit (degrees: equal to within an ulp or two).
pub fn write_model_file(m: &ModelFile, header: &str) -> String {
    use std::fmt::Write as _;
    let f = |v: f64| format!("{v:?}");
    let per_unit = m.angle_unit.radians();
    let mut out = String::new();
    for line in header.lines() {
        let _ = writeln!(out, "# {line}");
    }
    if let Some(name) = &m.name {
        let _ = writeln!(out, "name = {}", quoted(name));
    }
    let _ = writeln!(out, "length_unit = \"{}\"\nangle_unit = \"{}\"", m.length_unit.name(), m.angle_unit.name());
    match &m.nominal {
        NominalModel::DhChain(c) => {
            let convention = match c.convention {
                DhConvention::Standard => "standard",
                DhConvention::Modified => "modified",
            };
            let _ = writeln!(out, "\n[chain]\nconvention = \"{convention}\"\njoints = [");
            for j in &c.joints {
                let kind = match j.kind {
                    JointKind::Revolute => "revolute",
                    JointKind::Prismatic => "prismatic",
                };
                let _ = writeln!(
                    out,
                    "  {{ a = {}, alpha = {}, d = {}, theta_offset = {}, kind = \"{kind}\" }},",
                    f(j.a),
                    f(j.alpha / per_unit),
                    f(j.d),
                    f(j.theta_offset / per_unit)
                );
            }
            out += "]\n";
            for (name, t) in [("base", &c.base), ("tool", &c.tool)] {
                if name == "base" && m.register_base {
                    out += "base = { register = true }\n";
                    continue;
                }
                let r = &t.rotation;
                let rows: Vec<String> = (0..3).map(|i| effects_section::list(&r[3 * i..3 * i + 3])).collect();
                let points = if name == "tool" && !c.tool_points.is_empty() {
                    let points: Vec<String> = c.tool_points.iter().map(|p| effects_section::list(p)).collect();
                    format!(", points = [{}]", points.join(", "))
                } else {
                    String::new()
                };
                let _ = writeln!(
                    out,
                    "{name} = {{ translation = {}, rotation = [{}]{points} }}",
                    effects_section::list(&t.translation),
                    rows.join(", ")
                );
            }
        }
        NominalModel::PlanarChain { lengths, .. } => {
            let _ = writeln!(out, "\n[planar]\nlengths = {}", effects_section::list(lengths));
            if let Some(frame) = &m.planar_frame {
                let offsets: Vec<f64> = frame.offsets.iter().map(|o| o / per_unit).collect();
                let _ = writeln!(out, "base = {}", effects_section::list(&frame.base));
                let _ = writeln!(out, "yaw = {}", f(frame.yaw / per_unit));
                let _ = writeln!(out, "offsets = {}", effects_section::list(&offsets));
            }
        }
    }
    if let Some(s) = &m.measurements {
        let names = |v: &[String]| v.iter().map(|n| quoted(n)).collect::<Vec<_>>().join(", ");
        let _ = writeln!(out, "\n[measurements]\njoints = [{}]", names(&s.joints));
        match &s.pose {
            None => {
                let _ = writeln!(out, "positions = [{}]", names(&s.positions));
            }
            Some(pose) => {
                let orientation = match (&pose.quaternion, &pose.rotation) {
                    (Some(q), _) => format!("quaternion = [{}]", names(q)),
                    (None, Some(r)) => format!("rotation = [{}]", names(r)),
                    (None, None) => String::new(),
                };
                let _ = writeln!(out, "pose = {{ position = [{}], {orientation} }}", names(&pose.position));
            }
        }
        if let Some(u) = s.angle_unit {
            let _ = writeln!(out, "angle_unit = \"{}\"", u.name());
        }
        if let Some(u) = s.length_unit {
            let _ = writeln!(out, "length_unit = \"{}\"", u.name());
        }
        if let Some(r) = s.min_rows {
            let _ = writeln!(out, "min_rows = {r}");
        }
        if let Some(limits) = &s.joint_limits {
            let pairs: Vec<String> = limits.iter().map(|p| effects_section::list(p)).collect();
            let _ = writeln!(out, "joint_limits = [{}]", pairs.join(", "));
        }
        if let Some(t) = s.repeat_tolerance {
            let _ = writeln!(out, "repeat_tolerance = {}", f(t));
        }
        if let Some(order) = s.order {
            let _ = writeln!(out, "order = \"{}\"", order.name());
        }
        if let Some(map) = &s.joint_map {
            out += "\n[measurements.joint_map]\n";
            for (key, table) in [("sign", &map.sign), ("scale", &map.scale), ("offset", &map.offset)] {
                let Some(table) = table else { continue };
                // The file is written as a DH table, whose joints are q1 … qn: a URDF's joint names
                // become their positions' names (the map read back names the same joints).
                let written_name = |name: &str| match m.joint_names.iter().position(|j| j == name) {
                    Some(i) if matches!(m.nominal, NominalModel::DhChain(_)) => format!("q{}", i + 1),
                    _ => name.to_string(),
                };
                let entries: Vec<String> = table.iter().map(|(name, v)| format!("{} = {}", quoted(&written_name(name)), f(*v))).collect();
                let _ = writeln!(out, "{key} = {{ {} }}", entries.join(", "));
            }
            if let Some(rows) = &map.coupling {
                let rows: Vec<String> = rows.iter().map(|r| effects_section::list(r)).collect();
                let _ = writeln!(out, "coupling = [{}]", rows.join(", "));
            }
        }
    }
    out += &effects_section::write(&m.nominal, per_unit);
    out
}
