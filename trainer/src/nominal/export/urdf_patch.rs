//! The user's own URDF with the calibrated geometry: only the `<origin>` of each movable joint on
//! the chain, and of the first fixed joint after the last one (it carries the calibrated tool), are
//! rewritten; every other byte — links, inertias, meshes, limits, comments, the other branches — is
//! kept. Each link keeps its orientation about its axis ([`LinkFrames::carried_over`]), so meshes
//! stay on their links and the `<axis>` elements stay as written.

use super::{rpy_of, triple, LinkFrames};
use crate::error::{Error, Result};
use crate::nominal::urdf::{chain_from_urdf, joint_path, origin_pose, unit};
use crate::nominal::Frame;
use cbd_protocol::{DhChain, JointKind};
use std::collections::HashMap;

/// The rewritten URDF and the joints whose origins changed, in chain order.
#[derive(Debug, Clone, PartialEq)]
pub struct PatchedUrdf {
    pub text: String,
    pub joints: Vec<String>,
}

/// `text` (a URDF) with the chain `base_link` → `tip_link` moved to `calibrated`, the DH form of
/// that chain after calibration (lengths in the model's unit: `length_scale` per metre, as
/// [`chain_from_urdf`] read it).
pub fn patch_urdf(text: &str, base_link: &str, tip_link: &str, length_scale: f64, calibrated: &DhChain) -> Result<PatchedUrdf> {
    patch_urdf_in_frame(text, base_link, tip_link, length_scale, calibrated, false)
}

/// [`patch_urdf`], `base_registered` when `calibrated`'s base is a frame registered on the data
/// (`base = { register = true }`: a tracker's, metres from the URDF's base): each link is then
/// slid toward the nominal link moved into that frame, not toward the URDF's own (which would slide
/// the links metres along their axes).
pub fn patch_urdf_in_frame(
    text: &str,
    base_link: &str,
    tip_link: &str,
    length_scale: f64,
    calibrated: &DhChain,
    base_registered: bool,
) -> Result<PatchedUrdf> {
    let robot = crate::nominal::urdf::parse(text)?;
    let nominal_dh = chain_from_urdf(&robot, base_link, tip_link, length_scale)?.chain;
    let ChainWalk { path, frames: nominal, movable, .. } = walk(&robot, base_link, tip_link, length_scale)?;
    if calibrated.joints.len() != movable.len() || calibrated.joints.iter().zip(&nominal.kinds).any(|(j, k)| j.kind != *k) {
        return Err(Error::InvalidInput(format!(
            "the calibrated chain has {} joints; the URDF's chain from '{base_link}' to '{tip_link}' has {} movable joints of other kinds or number",
            calibrated.joints.len(),
            movable.len()
        )));
    }
    let last = *movable.last().unwrap_or(&0);
    if last + 1 >= path.len() {
        return Err(Error::InvalidInput(format!(
            "the URDF's tip link '{tip_link}' is the last joint's own link ('{}'): the calibrated tool needs a fixed joint after it to go in — add a link fixed to '{tip_link}' (e.g. tool0) and name it as tip_link",
            path[last].name
        )));
    }
    let reference = if base_registered {
        let moved = Frame::from_transform(&calibrated.base).compose(&Frame::from_transform(&nominal_dh.base).inverse());
        LinkFrames { links: nominal.links.iter().map(|l| moved.compose(l)).collect(), ..nominal.clone() }
    } else {
        nominal.clone()
    };
    let frames = LinkFrames::carried_over(&nominal, &nominal_dh, calibrated).slid_toward(&reference);
    let mut origins: Vec<(String, Frame)> = Vec::new();
    let mut pose = Frame::IDENTITY;
    let mut next = 0;
    for (k, joint) in path.iter().enumerate() {
        let origin = if movable.get(next) == Some(&k) {
            next += 1;
            pose.inverse().compose(&frames.links[next - 1])
        } else if k == last + 1 {
            // The fixed joints after this one keep their origins: this one takes the tool's change.
            let rest = path[k + 1..].iter().fold(Frame::IDENTITY, |f, j| f.compose(&origin_pose(&j.origin, length_scale)));
            pose.inverse().compose(&frames.tip).compose(&rest.inverse())
        } else {
            pose = pose.compose(&origin_pose(&joint.origin, length_scale));
            continue;
        };
        pose = pose.compose(&origin);
        origins.push((joint.name.clone(), origin));
    }
    let written: HashMap<&str, [String; 2]> = origins
        .iter()
        .map(|(name, f)| (name.as_str(), [triple(f.translation(), 1.0 / length_scale), triple(rpy_of(&f.rotation()), 1.0)]))
        .collect();
    let text = rewrite_origins(text, &written)?;
    // Every joint reported calibrated had its origin rewritten (read back by name).
    let reread = crate::nominal::urdf::parse(&text)?;
    for (name, values) in &written {
        let joint = reread.joints.iter().find(|j| j.name == *name);
        let got = joint.map(|j| [triple(j.origin.xyz.0, 1.0), triple(j.origin.rpy.0, 1.0)]);
        if got.as_ref() != Some(values) {
            return Err(Error::Internal(format!("URDF rewrite: joint '{name}' kept its origin")));
        }
    }
    Ok(PatchedUrdf { text, joints: origins.into_iter().map(|(name, _)| name).collect() })
}

/// The chain `base_link` → `tip_link` of a URDF at zero joint values: its link frames and root.
struct ChainWalk<'a> {
    path: Vec<&'a urdf_rs::Joint>,
    frames: LinkFrames,
    /// The first movable joint's parent link (the fixed joints before it composed).
    root: Frame,
    /// Index in `path` of each movable joint.
    movable: Vec<usize>,
}

fn walk<'a>(robot: &'a urdf_rs::Robot, base_link: &str, tip_link: &str, length_scale: f64) -> Result<ChainWalk<'a>> {
    let path = joint_path(robot, base_link, tip_link)?;
    let mut pose = Frame::IDENTITY;
    let mut root = None;
    let mut frames = LinkFrames { links: Vec::new(), axes: Vec::new(), kinds: Vec::new(), tip: Frame::IDENTITY };
    let mut movable = Vec::new();
    for (k, joint) in path.iter().enumerate() {
        let parent = pose;
        pose = pose.compose(&origin_pose(&joint.origin, length_scale));
        let kind = match joint.joint_type {
            urdf_rs::JointType::Fixed => continue,
            urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => JointKind::Revolute,
            urdf_rs::JointType::Prismatic => JointKind::Prismatic,
            ref other => return Err(Error::Urdf(format!("URDF joint '{}' has unsupported type {other:?}", joint.name))),
        };
        root.get_or_insert(parent);
        frames.links.push(pose);
        frames.axes.push(unit(joint.axis.xyz.0).ok_or_else(|| Error::Urdf(format!("URDF joint '{}' has a zero axis", joint.name)))?);
        frames.kinds.push(kind);
        movable.push(k);
    }
    frames.tip = pose;
    Ok(ChainWalk { path, frames, root: root.unwrap_or(Frame::IDENTITY), movable })
}

/// The chain `base_link` → `tip_link` of `robot` at zero joint values, lengths × `length_scale`,
/// and the frame of the first movable joint's parent link (the root its origin hangs from).
pub fn link_frames(robot: &urdf_rs::Robot, base_link: &str, tip_link: &str, length_scale: f64) -> Result<(LinkFrames, Frame)> {
    let ChainWalk { frames, root, .. } = walk(robot, base_link, tip_link, length_scale)?;
    Ok((frames, root))
}

/// `text` with the `<origin>` of each named top-level `<joint>` given `xyz` and `rpy` (in place of
/// the attributes' values, added where missing, or a new `<origin/>` element where the joint has
/// none); nothing else changes.
fn rewrite_origins(text: &str, origins: &HashMap<&str, [String; 2]>) -> Result<String> {
    use quick_xml::events::Event;
    let xml_error = |reader: &quick_xml::Reader<&[u8]>, e: quick_xml::Error| {
        let at = reader.error_position() as usize;
        let line = 1 + text.as_bytes()[..at.min(text.len())].iter().filter(|&&b| b == b'\n').count();
        Error::Urdf(format!("line {line}: {e}"))
    };
    let mut reader = quick_xml::Reader::from_str(text);
    // (byte range replaced, new text), in file order.
    let mut edits: Vec<(std::ops::Range<usize>, String)> = Vec::new();
    let mut depth = 0usize;
    // The joint being rewritten: its values, its depth, where its start tag ends, whether it has an origin.
    let mut open: Option<(&[String; 2], usize, usize, bool)> = None;
    loop {
        let event = reader.read_event().map_err(|e| xml_error(&reader, e))?;
        let end = reader.buffer_position() as usize;
        match &event {
            Event::Start(e) | Event::Empty(e) => {
                let element_depth = depth + 1;
                if matches!(event, Event::Start(_)) {
                    depth += 1;
                }
                let name = e.name();
                if name.as_ref() == b"joint" && element_depth == 2 && matches!(event, Event::Start(_)) {
                    // The name as the URDF means it: `a&amp;b` is the joint `a&b`.
                    let raw = attribute(e, b"name", text)?.map(|r| &text[r]);
                    let joint = raw
                        .map(|r| quick_xml::escape::unescape(r).map_err(|e| Error::Urdf(format!("joint name {r:?}: {e}"))))
                        .transpose()?;
                    if let Some(values) = joint.and_then(|j| origins.get(j.as_ref())) {
                        open = Some((values, element_depth, end, false));
                    }
                } else if name.as_ref() == b"origin" {
                    if let Some((values, joint_depth, _, found)) = open.as_mut() {
                        if element_depth == *joint_depth + 1 && !*found {
                            *found = true;
                            // Before `/>` or `>`: where a missing attribute goes.
                            let tag_end = if matches!(event, Event::Empty(_)) { end - 2 } else { end - 1 };
                            for (key, value) in [(b"xyz".as_slice(), &values[0]), (b"rpy".as_slice(), &values[1])] {
                                match attribute(e, key, text)? {
                                    Some(range) => edits.push((range, value.clone())),
                                    None => edits.push((tag_end..tag_end, format!(" {}=\"{value}\"", String::from_utf8_lossy(key)))),
                                }
                            }
                        }
                    }
                }
            }
            Event::End(_) => {
                if let Some((values, joint_depth, tag_end, found)) = open {
                    if joint_depth == depth {
                        if !found {
                            edits.push((tag_end..tag_end, format!("\n    <origin xyz=\"{}\" rpy=\"{}\"/>", values[0], values[1])));
                        }
                        open = None;
                    }
                }
                depth = depth.saturating_sub(1);
            }
            Event::Eof => break,
            _ => {}
        }
    }
    edits.sort_by_key(|(range, _)| (range.start, range.end));
    let mut out = String::with_capacity(text.len() + 64 * edits.len());
    let mut at = 0;
    for (range, value) in edits {
        out.push_str(&text[at..range.start]);
        out.push_str(&value);
        at = range.end;
    }
    out.push_str(&text[at..]);
    Ok(out)
}

/// Where in `text` the value of attribute `key` of tag `e` lies, `None` when the tag has none (the
/// reader lends the tag's raw bytes out of `text` itself, so the value's place is its offset there).
fn attribute(e: &quick_xml::events::BytesStart<'_>, key: &[u8], text: &str) -> Result<Option<std::ops::Range<usize>>> {
    let Some(attr) = e.attributes().flatten().find(|a| a.key.as_ref() == key) else { return Ok(None) };
    let lost = || Error::Internal(format!("URDF rewrite: attribute {} not found in the text", String::from_utf8_lossy(key)));
    let std::borrow::Cow::Borrowed(value) = attr.value else { return Err(lost()) };
    let offset = (value.as_ptr() as usize).checked_sub(text.as_ptr() as usize).ok_or_else(lost)?;
    let range = offset..offset + value.len();
    match text.as_bytes().get(range.clone()) {
        Some(bytes) if bytes == value => Ok(Some(range)),
        _ => Err(lost()),
    }
}
