//! A URDF serial chain as an equivalent standard Denavit–Hartenberg chain.
//!
//! The runtime evaluates DH chains only. The conversion is exact for every serial chain of
//! revolute, continuous, prismatic and fixed joints: at the zero configuration the movable joints'
//! axes are lines in space, and the standard DH frames are built along the common normals of
//! consecutive axes (for parallel axes, the normal through the previous frame's origin, d = 0).
//! General origins (any xyz/rpy) and axes (any direction) are absorbed into the DH rows plus the
//! base and tool transforms; fixed joints are folded into the neighbouring rows. Joint values keep
//! the URDF's zero and sign (θ = q + θ_offset with the DH z axis along the URDF axis).
//! Not supported: floating, planar and spherical joints, mimic joints (treated as independent),
//! and joint limits (ignored).

use super::{add, cross, dot, norm, rotation_about, rpy, scale, sub, Frame};
use crate::error::{Error, Result};
use cbd_protocol::{DhChain, DhConvention, DhJoint, JointKind, MAX_JOINTS};

/// Deepest element nesting a URDF may have. A robot description nests about six deep (robot >
/// link > visual > geometry > mesh); the reader urdf-rs uses recurses once per level, so 30 000
/// nested elements overflowed the stack and aborted the process.
pub const MAX_URDF_DEPTH: usize = 64;

/// Parses a URDF document. Nesting deeper than [`MAX_URDF_DEPTH`] is refused first, with the line
/// and column where it goes too deep, by a streaming (non-recursive) pass over the XML events.
pub fn parse(text: &str) -> Result<urdf_rs::Robot> {
    check_nesting(text)?;
    urdf_rs::read_from_string(text).map_err(|e| Error::Urdf(e.to_string()))
}

/// The nesting check of [`parse`]. Malformed XML is left to urdf-rs, whose message names the fault.
fn check_nesting(text: &str) -> Result<()> {
    use xml::reader::{EventReader, XmlEvent};
    let mut reader = EventReader::from_str(text);
    let mut depth = 0usize;
    loop {
        match reader.next() {
            Ok(XmlEvent::StartElement { .. }) => {
                depth += 1;
                if depth > MAX_URDF_DEPTH {
                    let at = xml::common::Position::position(&reader);
                    return Err(Error::Urdf(format!(
                        "line {}, column {}: elements nested more than {MAX_URDF_DEPTH} deep (a robot description nests about 6)",
                        at.row + 1,
                        at.column + 1
                    )));
                }
            }
            Ok(XmlEvent::EndElement { .. }) => depth = depth.saturating_sub(1),
            Ok(XmlEvent::EndDocument) | Err(_) => return Ok(()),
            Ok(_) => {}
        }
    }
}

/// A URDF chain converted to DH: the chain (lengths multiplied by `length_scale`) and the URDF
/// names of its movable joints, in the order of the joint values.
#[derive(Debug, Clone, PartialEq)]
pub struct UrdfChain {
    pub chain: DhChain,
    pub joint_names: Vec<String>,
}

/// One movable URDF joint at the zero configuration: kind, a point on its axis, unit direction.
#[derive(Debug, Clone)]
struct AxisLine {
    kind: JointKind,
    point: [f64; 3],
    dir: [f64; 3],
}

/// The joints from `base_link` to `tip_link`, base first.
pub(crate) fn joint_path<'a>(robot: &'a urdf_rs::Robot, base_link: &str, tip_link: &str) -> Result<Vec<&'a urdf_rs::Joint>> {
    if !robot.links.iter().any(|l| l.name == base_link) {
        return Err(Error::Urdf(format!("URDF robot '{}' has no link named '{base_link}' (base_link)", robot.name)));
    }
    if !robot.links.iter().any(|l| l.name == tip_link) {
        return Err(Error::Urdf(format!("URDF robot '{}' has no link named '{tip_link}' (tip_link)", robot.name)));
    }
    // Each link's parent joint, looked up in O(1): the walk stays linear in the chain's length
    // (a search per link made a 200k-link chain quadratic).
    // (The first joint naming a child wins, as the linear search did.)
    let mut parent_joint: std::collections::HashMap<&str, &urdf_rs::Joint> = std::collections::HashMap::new();
    for j in &robot.joints {
        parent_joint.entry(j.child.link.as_str()).or_insert(j);
    }
    let mut path = Vec::new();
    let mut link = tip_link;
    while link != base_link {
        let joint = parent_joint.get(link).copied().ok_or_else(|| {
            Error::Urdf(format!("URDF: link '{tip_link}' is not a descendant of '{base_link}' (no joint has child '{link}')"))
        })?;
        path.push(joint);
        link = joint.parent.link.as_str();
        if path.len() > robot.joints.len() {
            return Err(Error::Urdf("URDF: the joint tree has a cycle".into()));
        }
    }
    path.reverse();
    Ok(path)
}

/// Pose of a URDF joint origin, lengths scaled.
pub(crate) fn origin_pose(origin: &urdf_rs::Pose, length_scale: f64) -> Frame {
    let [r, p, y] = origin.rpy.0;
    rpy(r, p, y).with_translation(scale(origin.xyz.0, length_scale))
}

/// Pose of `tip_link` in `base_link`'s frame at joint values `q` (URDF order; prismatic values
/// in the scaled unit), computed directly from the URDF (the reference the DH conversion is
/// tested against). Lengths are multiplied by `length_scale`.
pub fn urdf_tip_pose(robot: &urdf_rs::Robot, base_link: &str, tip_link: &str, q: &[f64], length_scale: f64) -> Result<Frame> {
    let mut pose = Frame::IDENTITY;
    let mut k = 0;
    for joint in joint_path(robot, base_link, tip_link)? {
        pose = pose.compose(&origin_pose(&joint.origin, length_scale));
        let axis = unit(joint.axis.xyz.0).ok_or_else(|| Error::Urdf(format!("URDF joint '{}' has a zero axis", joint.name)))?;
        match joint.joint_type {
            urdf_rs::JointType::Fixed => continue,
            urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => pose = pose.compose(&rotation_about(axis, q[k])),
            urdf_rs::JointType::Prismatic => pose = pose.compose(&Frame::IDENTITY.with_translation(scale(axis, q[k]))),
            ref other => return Err(Error::Urdf(format!("URDF joint '{}' has unsupported type {other:?}", joint.name))),
        }
        k += 1;
    }
    Ok(pose)
}

/// A joint's origin and axis as the model uses them: finite and within ±1e100 after the length unit's
/// conversion (`xyz="1e307 0 0"` in millimetres is 1e310: infinite, and the NaN it made in the
/// kinematics was blamed on the first data line).
fn check_origin(joint: &urdf_rs::Joint, length_scale: f64) -> Result<()> {
    let limit = crate::limits::MAX_MAGNITUDE;
    let values =
        [("origin xyz", scale(joint.origin.xyz.0, length_scale)), ("origin rpy", joint.origin.rpy.0), ("axis xyz", joint.axis.xyz.0)];
    for (what, v) in values {
        if let Some(x) = v.iter().find(|x| !x.is_finite() || x.abs() > limit) {
            let unit = if what == "origin xyz" && length_scale != 1.0 { " after the length unit's conversion" } else { "" };
            return Err(Error::Urdf(format!("URDF joint '{}': {what} has {x:e}{unit}, beyond ±{limit:e}", joint.name)));
        }
    }
    Ok(())
}

pub(crate) fn unit(v: [f64; 3]) -> Option<[f64; 3]> {
    let n = norm(v);
    (n > 1e-12).then(|| scale(v, 1.0 / n))
}

/// Converts the chain `base_link` → `tip_link` of `robot` into a standard DH chain whose task
/// position is the origin of `tip_link`, in `base_link`'s frame. Lengths are multiplied by
/// `length_scale` (URDF is in metres: 1000 gives millimetres).
pub fn chain_from_urdf(robot: &urdf_rs::Robot, base_link: &str, tip_link: &str, length_scale: f64) -> Result<UrdfChain> {
    let mut pose = Frame::IDENTITY;
    let mut lines = Vec::new();
    let mut names = Vec::new();
    for joint in joint_path(robot, base_link, tip_link)? {
        check_origin(joint, length_scale)?;
        pose = pose.compose(&origin_pose(&joint.origin, length_scale));
        let kind = match joint.joint_type {
            urdf_rs::JointType::Fixed => continue,
            urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => JointKind::Revolute,
            urdf_rs::JointType::Prismatic => JointKind::Prismatic,
            ref other => {
                return Err(Error::Urdf(format!(
                    "URDF joint '{}' has unsupported type {other:?} (only revolute, continuous, prismatic and fixed)",
                    joint.name
                )))
            }
        };
        let axis = unit(joint.axis.xyz.0).ok_or_else(|| Error::Urdf(format!("URDF joint '{}' has a zero axis", joint.name)))?;
        lines.push(AxisLine { kind, point: pose.translation(), dir: pose.rotate(axis) });
        names.push(joint.name.clone());
    }
    if lines.is_empty() {
        return Err(Error::Urdf(format!("URDF: no movable joint between '{base_link}' and '{tip_link}'")));
    }
    if lines.len() > MAX_JOINTS {
        return Err(Error::Urdf(format!(
            "URDF: {} movable joints between '{base_link}' and '{tip_link}'; at most {MAX_JOINTS} are supported",
            lines.len()
        )));
    }
    let tip = pose;
    let chain = dh_from_axis_lines(&lines, &tip);
    Ok(UrdfChain { chain, joint_names: names })
}

/// Standard DH frames along the axis lines (see the module comment).
fn dh_from_axis_lines(lines: &[AxisLine], tip: &Frame) -> DhChain {
    let n = lines.len();
    // Frame 0: on axis 1, z along it; x any perpendicular (the best-conditioned world axis).
    let z0 = lines[0].dir;
    let helper = if z0[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let x0 = unit(sub(helper, scale(z0, dot(helper, z0)))).expect("non-degenerate helper");
    let mut frames = vec![(lines[0].point, x0, z0)]; // (origin, x, z) of frames 0..n-1
    let mut joints = heapless::Vec::<DhJoint, MAX_JOINTS>::new();
    for i in 1..n {
        let (o, x_prev, z) = frames[i - 1];
        let (p2, z2) = (lines[i].point, lines[i].dir);
        let c = cross(z, z2);
        let (x, a, d, origin) = if norm(c) > 1e-9 {
            let x = scale(c, 1.0 / norm(c));
            // Closest points of the lines o + t1 z and p2 + t2 z2: t1 = (w × z2)·c / |c|²,
            // t2 = (w × z)·c / |c|² with w = p2 − o. Written with c = z × z2 itself, not 1 − (z·z2)²,
            // which cancels for nearly parallel axes (a calibrated UR5's joints 2–4): that lost
            // 1e-9 of the reach in the DH form of an exported URDF.
            let w = sub(p2, o);
            let cc = dot(c, c);
            let t1 = dot(cross(w, z2), c) / cc;
            let t2 = dot(cross(w, z), c) / cc;
            let c1 = add(o, scale(z, t1));
            let c2 = add(p2, scale(z2, t2));
            (x, dot(sub(c2, c1), x), t1, c2)
        } else {
            let w = sub(p2, o);
            let perp = sub(w, scale(z, dot(w, z)));
            match unit(perp) {
                Some(x) => (x, norm(perp), 0.0, add(o, perp)),
                None => (x_prev, 0.0, 0.0, o),
            }
        };
        let theta = dot(cross(x_prev, x), z).atan2(dot(x_prev, x));
        let alpha = dot(cross(z, z2), x).atan2(dot(z, z2));
        let _ = joints.push(DhJoint { kind: lines[i - 1].kind, a, alpha, d, theta_offset: theta });
        frames.push((origin, x, z2));
    }
    // Last joint: a pure rotation (or translation) about its own axis.
    let _ = joints.push(DhJoint { kind: lines[n - 1].kind, a: 0.0, alpha: 0.0, d: 0.0, theta_offset: 0.0 });
    let pose_of = |(o, x, z): ([f64; 3], [f64; 3], [f64; 3])| {
        let y = cross(z, x);
        Frame::new([[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]], o)
    };
    let base = pose_of(frames[0]);
    let last = pose_of(frames[n - 1]);
    let tool = last.inverse().compose(tip);
    DhChain {
        convention: DhConvention::Standard,
        joints,
        base: base.to_transform(),
        tool: tool.to_transform(),
        effects: cbd_protocol::Effects::NONE,
        tool_points: heapless::Vec::new(),
    }
}

#[cfg(test)]
pub(crate) mod tests_support {
    /// A 6-joint arm with skewed origins, tilted axes, a prismatic joint and fixed joints.
    pub(crate) const TEST_URDF: &str = r#"<?xml version="1.0"?>
<robot name="skewed">
  <link name="world"/>
  <link name="base_link"/>
  <link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/><link name="l5"/><link name="l6"/>
  <link name="flange"/><link name="tool0"/>
  <joint name="mount" type="fixed"><parent link="world"/><child link="base_link"/>
    <origin xyz="0.1 -0.05 0.02" rpy="0 0 0.3"/></joint>
  <joint name="j1" type="revolute"><parent link="base_link"/><child link="l1"/>
    <origin xyz="0 0 0.089" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0.135 0" rpy="0 1.5708 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0 -0.12 0.425" rpy="0.01 -0.02 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="slide" type="prismatic"><parent link="l3"/><child link="l4"/>
    <origin xyz="0.01 0 0.39" rpy="0 0 0"/><axis xyz="0.6 0 0.8"/>
    <limit lower="-0.1" upper="0.1" effort="1" velocity="1"/></joint>
  <joint name="j5" type="continuous"><parent link="l4"/><child link="l5"/>
    <origin xyz="0 0.093 0" rpy="0 0 0"/><axis xyz="0 0 -1"/></joint>
  <joint name="j6" type="revolute"><parent link="l5"/><child link="l6"/>
    <origin xyz="0 0 0.09465" rpy="0.2 0 0"/><axis xyz="1 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="to_flange" type="fixed"><parent link="l6"/><child link="flange"/>
    <origin xyz="0 0.0823 0" rpy="0 0 1.5708"/></joint>
  <joint name="to_tool" type="fixed"><parent link="flange"/><child link="tool0"/>
    <origin xyz="0.01 0.02 0.031" rpy="0 0 0"/></joint>
</robot>"#;
}

#[cfg(test)]
mod tests {
    use super::tests_support::TEST_URDF;
    use super::*;
    use cbd_protocol::NominalModel;
    use cbd_runtime::internals::kinematics::forward_kinematics;

    /// Issue 27 item 4: 30 000 nested elements (210 KB) overflowed the stack inside urdf-rs's
    /// recursive reader (abort). The nesting is now checked first, without recursion.
    #[test]
    fn deeply_nested_urdf_is_refused_with_its_line_and_column() {
        let n = 30_000;
        let deep = format!("<robot name=\"r\">\n{}{}</robot>", "<a>".repeat(n), "</a>".repeat(n));
        let e = parse(&deep).unwrap_err().to_string();
        assert!(e.contains("line 2, column 190") && e.contains("nested more than 64 deep"), "{e}");
        assert!(parse(TEST_URDF).is_ok());
        // Malformed XML is urdf-rs's to name.
        assert!(parse("<robot name=\"r\"><link name=\"a\"></robot>").is_err());
    }

    /// Issue 17 item 8: a 200k-deep URDF did not finish in 120 s (a search through all joints
    /// for every link on the path). The walk is now linear.
    #[test]
    fn deep_urdf_chain_is_walked_in_linear_time() {
        let template = urdf_rs::read_from_string(TEST_URDF).unwrap();
        let (link, joint) = (template.links[0].clone(), template.joints.iter().find(|j| j.name == "to_tool").unwrap().clone());
        let depth = 200_000;
        let mut robot = template.clone();
        robot.links = (0..=depth).map(|k| urdf_rs::Link { name: format!("l{k}"), ..link.clone() }).collect();
        robot.joints = (0..depth)
            .map(|k| {
                let mut j = joint.clone();
                j.name = format!("j{k}");
                j.parent.link = format!("l{k}");
                j.child.link = format!("l{}", k + 1);
                j
            })
            .collect();
        let start = std::time::Instant::now();
        let path = joint_path(&robot, "l0", &format!("l{depth}")).unwrap();
        assert_eq!(path.len(), depth);
        assert_eq!(path[0].name, "j0");
        assert!(start.elapsed().as_secs_f64() < 5.0, "{:?}", start.elapsed());
    }

    #[test]
    fn urdf_chain_converts_to_an_exact_dh_chain() {
        let robot = urdf_rs::read_from_string(TEST_URDF).unwrap();
        let conv = chain_from_urdf(&robot, "world", "tool0", 1000.0).unwrap();
        assert_eq!(conv.joint_names, ["j1", "j2", "j3", "slide", "j5", "j6"]);
        assert_eq!(conv.chain.joints[3].kind, JointKind::Prismatic);
        let model = NominalModel::DhChain(conv.chain.clone());
        for k in 0..20 {
            let q: Vec<f64> = (0..6).map(|d| ((k * 7 + d * 3) as f64 * 0.77).sin() * 2.5).collect();
            let mut q_m = q.clone();
            q_m[3] *= 0.04; // prismatic: metres in the URDF…
            let mut q_mm = q_m.clone();
            q_mm[3] *= 1000.0; // …millimetres in the converted chain
            let reference = urdf_tip_pose(&robot, "world", "tool0", &q_mm, 1000.0).unwrap();
            let fk = forward_kinematics(&model, &q_mm);
            for c in 0..3 {
                assert!(
                    (fk.position[c] - reference.translation()[c]).abs() < 1e-9,
                    "config {k}: {:?} vs {:?}",
                    fk.position,
                    reference.translation()
                );
            }
            // The whole tip frame, not only its position.
            let tip = cbd_runtime::internals::kinematics::rigid::dh_walk(&conv.chain, &q_mm).tool_rotation;
            for i in 0..3 {
                for j in 0..3 {
                    assert!((tip[i][j] - reference.rotation()[i][j]).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn urdf_errors_name_the_problem() {
        let robot = urdf_rs::read_from_string(TEST_URDF).unwrap();
        let e = chain_from_urdf(&robot, "world", "nowhere", 1.0).unwrap_err().to_string();
        assert!(e.contains("nowhere"), "{e}");
        let e = chain_from_urdf(&robot, "l3", "l1", 1.0).unwrap_err().to_string();
        assert!(e.contains("not a descendant"), "{e}");
        let e = chain_from_urdf(&robot, "flange", "tool0", 1.0).unwrap_err().to_string();
        assert!(e.contains("no movable joint"), "{e}");
    }

    /// Issue 27 (messages): an origin made infinite by the unit conversion gave a NaN that was
    /// blamed on a data line; it is now refused naming the joint.
    #[test]
    fn a_urdf_origin_beyond_range_after_unit_conversion_names_the_joint() {
        let robot = urdf_rs::read_from_string(&TEST_URDF.replacen("xyz=\"0 0 0.089\"", "xyz=\"1e98 0 0.089\"", 1)).unwrap();
        assert!(chain_from_urdf(&robot, "world", "tool0", 1.0).is_ok());
        let e = chain_from_urdf(&robot, "world", "tool0", 1000.0).unwrap_err().to_string();
        assert!(
            e.contains("URDF joint 'j1'")
                && e.contains("origin xyz has 1")
                && e.contains("e101 after the length unit's conversion, beyond ±1e100"),
            "{e}"
        );
    }
}
