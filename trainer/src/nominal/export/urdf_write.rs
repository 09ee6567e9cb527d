//! A URDF written from a DH chain's link frames: the base and the tool as fixed joints, each DH
//! joint a joint about its own z axis whose origin is the fixed motion between it and the previous
//! one ([`LinkFrames::origin`]), the θ offsets and the calibrated a, α, d folded into those origins.

use super::{decimal, rpy_of, triple, xml_comment, LinkFrames};
use crate::error::{Error, Result};
use crate::nominal::Frame;
use cbd_protocol::JointKind;
use std::fmt::Write as _;

/// Names and units of a written URDF.
#[derive(Debug, Clone)]
pub struct UrdfNaming<'a> {
    /// The `<robot name>`.
    pub robot: &'a str,
    /// One per joint, in chain order.
    pub joints: &'a [String],
    /// Model length unit → metres (URDF lengths are metres).
    pub to_metres: f64,
    /// Each prismatic joint's travel [lo, hi], model length unit (URDF requires a limit there).
    pub limits: &'a [[f64; 2]],
    /// Comment lines for the file's head (what it was written from).
    pub comment: &'a [String],
}

/// Prismatic travel written when the model file declares none (metres): URDF needs a limit.
const UNDECLARED_TRAVEL_M: f64 = 1000.0;

/// The URDF text of `frames` (a chain about each link's z axis) hung from `base`: links `base_link`
/// (the model's base frame: the measurements'), `link_0` (`base`), `link_1` … `link_n`, `tool0`
/// (the tip); joints `base_joint` and `tool_joint` fixed, revolute joints `continuous`, prismatic
/// ones `prismatic`.
pub fn write_urdf(frames: &LinkFrames, base: &Frame, naming: &UrdfNaming<'_>) -> String {
    let n = frames.links.len();
    let mut out = String::from("<?xml version=\"1.0\"?>\n");
    for line in naming.comment {
        let _ = writeln!(out, "{}", xml_comment(line));
    }
    let _ = writeln!(out, "<robot name=\"{}\">", attribute(naming.robot));
    out.push_str("  <link name=\"base_link\"/>\n");
    for i in 0..=n {
        let _ = writeln!(out, "  <link name=\"link_{i}\"/>");
    }
    out.push_str("  <link name=\"tool0\"/>\n");
    joint(&mut out, "base_joint", "fixed", "base_link", "link_0", base, naming.to_metres, None);
    for i in 0..n {
        let origin = frames.origin(i, base);
        let (parent, child) = (format!("link_{i}"), format!("link_{}", i + 1));
        let name = attribute(&naming.joints[i]);
        match frames.kinds[i] {
            JointKind::Revolute => joint(&mut out, &name, "continuous", &parent, &child, &origin, naming.to_metres, Some(None)),
            JointKind::Prismatic => {
                let [lo, hi] = naming.limits.get(i).copied().unwrap_or([f64::NEG_INFINITY, f64::INFINITY]);
                let travel = |v: f64, fallback: f64| if v.is_finite() { v * naming.to_metres } else { fallback };
                let limit = [travel(lo, -UNDECLARED_TRAVEL_M), travel(hi, UNDECLARED_TRAVEL_M)];
                joint(&mut out, &name, "prismatic", &parent, &child, &origin, naming.to_metres, Some(Some(limit)))
            }
        }
    }
    joint(&mut out, "tool_joint", "fixed", &format!("link_{n}"), "tool0", &frames.tip_in_last_link(), naming.to_metres, None);
    out.push_str("</robot>\n");
    out
}

/// `value` as an XML attribute's text: `&`, `<`, `>`, quotes and the white space an attribute would
/// otherwise turn into spaces (tab, line feed, carriage return) as references, so it reads back as
/// written. Characters XML cannot hold at all are refused first ([`check_name`]).
fn attribute(value: &str) -> String {
    let mut out = String::with_capacity(value.len());
    for c in value.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            '\t' | '\n' | '\r' => out.push_str(&format!("&#{};", c as u32)),
            c => out.push(c),
        }
    }
    out
}

/// A name a URDF can hold (the robot's, a joint's): not empty, and no character XML 1.0 cannot
/// hold even as a reference (control characters other than tab, line feed and carriage return;
/// U+FFFE, U+FFFF). `what` names it in the error (`[chain] joint 2's name`).
pub fn check_name(what: &str, name: &str) -> Result<()> {
    if name.is_empty() {
        return Err(Error::InvalidInput(format!("{what} is empty; a URDF needs a name there")));
    }
    if let Some(c) = name.chars().find(|&c| (c.is_control() && !matches!(c, '\t' | '\n' | '\r')) || matches!(c, '\u{fffe}' | '\u{ffff}')) {
        return Err(Error::InvalidInput(format!(
            "{what} {name:?} holds the character U+{:04X}, which an XML file (a URDF) cannot hold; rename it",
            c as u32
        )));
    }
    Ok(())
}

/// One `<joint>`; `axis`: `None` for a fixed joint, `Some(limit)` for a movable one about or along
/// z (`limit` in metres, prismatic joints; effort and velocity are not cbd's to know: 0).
#[allow(clippy::too_many_arguments)]
fn joint(
    out: &mut String,
    name: &str,
    kind: &str,
    parent: &str,
    child: &str,
    origin: &Frame,
    to_metres: f64,
    axis: Option<Option<[f64; 2]>>,
) {
    let _ = writeln!(out, "  <joint name=\"{name}\" type=\"{kind}\">");
    let _ = writeln!(out, "    <parent link=\"{parent}\"/>\n    <child link=\"{child}\"/>");
    let _ = writeln!(
        out,
        "    <origin xyz=\"{}\" rpy=\"{}\"/>",
        triple(origin.translation(), to_metres),
        triple(rpy_of(&origin.rotation()), 1.0)
    );
    if let Some(limit) = axis {
        out.push_str("    <axis xyz=\"0 0 1\"/>\n");
        if let Some([lo, hi]) = limit {
            let _ = writeln!(out, "    <limit lower=\"{}\" upper=\"{}\" effort=\"0\" velocity=\"0\"/>", decimal(lo), decimal(hi));
        }
    }
    out.push_str("  </joint>\n");
}
