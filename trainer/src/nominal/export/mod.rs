//! A calibrated chain written where ROS users read kinematics (`cbd export`): a URDF whose joint
//! origins carry the calibrated geometry ([`urdf_write`] from a DH table, [`urdf_patch`] into the
//! user's own URDF) and the UR description's kinematics file ([`ur_kinematics`]).
//!
//! All three start from [`LinkFrames`]: the chain at zero joint values as URDF composes it,
//! T(q) = L₁ R₁(q₁) L₁⁻¹ L₂ R₂(q₂) … — each movable joint's child-link frame L_i and its axis in
//! that frame — so a joint's origin is L_{i−1}⁻¹ L_i. Joint zero offsets are in the frames, never
//! in `<calibration>` tags (which robot_state_publisher and the drivers ignore).

pub mod ur_kinematics;
pub mod urdf_patch;
pub mod urdf_write;

use super::{add, dot, rotation_about, scale, sub, Frame};
use cbd_protocol::{DhChain, DhConvention, JointKind};

/// A serial chain at zero joint values, in its base frame (model length unit).
#[derive(Debug, Clone, PartialEq)]
pub struct LinkFrames {
    /// The child-link frame of each movable joint: the joint turns (or slides) about `axes[i]`
    /// through its origin.
    pub links: Vec<Frame>,
    /// Each joint's unit axis in its child link's frame.
    pub axes: Vec<[f64; 3]>,
    pub kinds: Vec<JointKind>,
    /// The tool (tip) frame.
    pub tip: Frame,
}

impl LinkFrames {
    /// A DH chain's frames: link i is the frame joint i turns about, D_i = (frames before) ·
    /// Rz(θ_offset) Tz(d) (standard) or · Tx(a) Rx(α) Rz(θ_offset) Tz(d) (modified), axis z. The
    /// joint's own turn Rz(q) commutes with Rz(θ_offset) Tz(d), so D_i Rz(q_i) is the walk's frame.
    pub fn of_dh_chain(chain: &DhChain) -> LinkFrames {
        let mut frame = Frame::from_transform(&chain.base);
        let mut links = Vec::with_capacity(chain.joints.len());
        for joint in &chain.joints {
            let turn = rotation_about([0.0, 0.0, 1.0], joint.theta_offset).with_translation([0.0, 0.0, joint.d]);
            let link_x = Frame::IDENTITY.with_translation([joint.a, 0.0, 0.0]).compose(&rotation_about([1.0, 0.0, 0.0], joint.alpha));
            match chain.convention {
                DhConvention::Standard => {
                    let link = frame.compose(&turn);
                    links.push(link);
                    frame = link.compose(&link_x);
                }
                DhConvention::Modified => {
                    let link = frame.compose(&link_x).compose(&turn);
                    links.push(link);
                    frame = link;
                }
            }
        }
        LinkFrames {
            axes: vec![[0.0, 0.0, 1.0]; links.len()],
            kinds: chain.joints.iter().map(|j| j.kind).collect(),
            links,
            tip: frame.compose(&Frame::from_transform(&chain.tool)),
        }
    }

    /// The calibrated chain's frames with each link's own orientation about its axis kept: the
    /// nominal link frame sits at C_i = D_i⁻¹ L_i from its DH frame D_i (a turn about and a shift
    /// along the axis, which commute with the joint's motion), and the calibrated link at D'_i C_i.
    /// `nominal_dh` is `nominal`'s DH form, `calibrated` that chain after calibration.
    pub fn carried_over(nominal: &LinkFrames, nominal_dh: &DhChain, calibrated: &DhChain) -> LinkFrames {
        let (before, after) = (LinkFrames::of_dh_chain(nominal_dh), LinkFrames::of_dh_chain(calibrated));
        let links = before
            .links
            .iter()
            .zip(&after.links)
            .zip(&nominal.links)
            .map(|((d, d_cal), link)| d_cal.compose(&d.inverse().compose(link)))
            .collect();
        LinkFrames { links, axes: nominal.axes.clone(), kinds: nominal.kinds.clone(), tip: after.tip }
    }

    /// These frames with each revolute link slid along its own axis to the point nearest the
    /// `nominal` link's origin. Where a frame sits on its axis is a free choice (a turn about the axis
    /// commutes with a shift along it, so the chain's motion is unchanged), but DH calibration spends
    /// it freely: on the UR5's three parallel axes the calibrated d's run to metres and cancel. Slid
    /// back, each link stays where its meshes and the nominal put it, and the origins read as the
    /// nominal's plus the calibration's small changes. Prismatic links stay: there the origin is the
    /// joint's zero.
    pub fn slid_toward(&self, nominal: &LinkFrames) -> LinkFrames {
        let mut out = self.clone();
        for ((link, kind), (axis, target)) in out.links.iter_mut().zip(&self.kinds).zip(self.axes.iter().zip(&nominal.links)) {
            if *kind == JointKind::Revolute {
                let (o, z) = (link.translation(), link.rotate(*axis));
                let t = dot(sub(target.translation(), o), z);
                *link = link.with_translation(add(o, scale(z, t)));
            }
        }
        out
    }

    /// Joint i's origin in its parent link: L_{i−1}⁻¹ L_i, the first relative to `root`.
    pub fn origin(&self, i: usize, root: &Frame) -> Frame {
        let parent = if i == 0 { *root } else { self.links[i - 1] };
        parent.inverse().compose(&self.links[i])
    }

    /// The tip in the last link's frame.
    pub fn tip_in_last_link(&self) -> Frame {
        self.links.last().map_or(self.tip, |last| last.inverse().compose(&self.tip))
    }
}

/// Roll, pitch and yaw (radians) of rotation `r` as URDF reads them, R = Rz(yaw) Ry(pitch) Rx(roll).
/// Yaw from the first column, then roll and pitch from what is left, Rz(−yaw) R = Ry(pitch) Rx(roll),
/// so the angles give R back to rounding even at pitch = ±90° (where yaw and roll are one turn).
pub fn rpy_of(r: &[[f64; 3]; 3]) -> [f64; 3] {
    let yaw = r[1][0].atan2(r[0][0]);
    let rest = rotation_about([0.0, 0.0, 1.0], -yaw).compose(&Frame::new(*r, [0.0; 3])).rotation();
    // rest = [[cp, sp sr, sp cr], [0, cr, −sr], [−sp, cp sr, cp cr]].
    let roll = (-rest[1][2]).atan2(rest[1][1]);
    let pitch = (-rest[2][0]).atan2(rest[0][0]);
    [roll, pitch, yaw].map(|v| v + 0.0)
}

/// A number as URDF and YAML files get it: the shortest text that reads back to the same f64, in
/// plain decimal (YAML 1.1, which xacro's loader speaks, reads `1e-11` as a string), `0` for ±0.
pub fn decimal(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else {
        format!("{v}")
    }
}

/// `text` as one comment line can hold it whatever it is (a file name with a newline, `--`, a
/// quote, an invisible character): every control character, line or paragraph separator and
/// byte-order mark is written as its escape (`\n`, `\u{2028}`), so the line never ends early.
fn one_line(text: &str) -> String {
    text.chars()
        .map(|c| match c {
            c if c.is_control() || matches!(c, '\u{2028}' | '\u{2029}' | '\u{feff}') => c.escape_default().to_string(),
            c => c.to_string(),
        })
        .collect()
}

/// `<!-- text -->`, whatever `text` holds: one line ([`one_line`]); no `--` inside an XML comment
/// and no `-` just before its end (each `-` that follows a `-` gets a space before it).
pub fn xml_comment(text: &str) -> String {
    let mut body = String::new();
    for c in one_line(text).chars() {
        if c == '-' && body.ends_with('-') {
            body.push(' ');
        }
        body.push(c);
    }
    if body.ends_with('-') {
        body.push(' ');
    }
    format!("<!-- {body} -->")
}

/// `# text`, one YAML comment line whatever `text` holds ([`one_line`]).
pub fn yaml_comment(text: &str) -> String {
    format!("# {}", one_line(text))
}

/// Magnitude (metres or radians) below which an exported origin's entry is written as 0: what is
/// left of a zero after composing frames (1e-16 of their lengths), far below anything physical.
pub const ROUNDING_ZERO: f64 = 1e-14;

/// `[x, y, z]` as `"x y z"` ([`decimal`]), `factor` applied (model length unit → metres), entries
/// below [`ROUNDING_ZERO`] as 0.
pub fn triple(v: [f64; 3], factor: f64) -> String {
    v.map(|x| x * factor).map(|x| decimal(if x.abs() < ROUNDING_ZERO { 0.0 } else { x })).join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nominal::rpy;

    #[test]
    fn rpy_of_reads_back_every_rotation_even_at_gimbal_lock() {
        let half = std::f64::consts::FRAC_PI_2;
        for (k, [r, p, y]) in [[0.3, -0.7, 1.9], [0.0, half, 0.4], [1.0, -half, -2.0], [3.0, 0.0, 3.1], [-3.1, 1.2, 0.0], [0.0, 0.0, 0.0]]
            .into_iter()
            .enumerate()
        {
            let want = rpy(r, p, y).rotation();
            let [r2, p2, y2] = rpy_of(&want);
            let got = rpy(r2, p2, y2).rotation();
            for i in 0..3 {
                for j in 0..3 {
                    assert!((got[i][j] - want[i][j]).abs() < 1e-15, "case {k}: {got:?} vs {want:?}");
                }
            }
        }
    }

    // The literals are values as a file writes them.
    #[allow(clippy::approx_constant)]
    #[test]
    fn decimals_read_back_exactly_without_exponents() {
        for v in [0.089159, -1.941303950897609e-11, 1.5707963267948966, 1e21, -0.0, 3.0] {
            let text = decimal(v);
            assert!(!text.contains('e') && !text.contains('E'), "{text}");
            assert_eq!(text.parse::<f64>().unwrap(), v + 0.0, "{text}");
        }
        assert_eq!(decimal(-0.0), "0");
    }

    /// Composing the frames' origins with each joint's motion gives the DH walk's tool frame.
    #[test]
    fn dh_link_frames_compose_to_the_walk() {
        for convention in [DhConvention::Standard, DhConvention::Modified] {
            let mut chain = cbd_protocol::ur5::chain();
            chain.convention = convention;
            chain.joints[2].kind = JointKind::Prismatic;
            chain.base = rotation_about([0.6, 0.0, 0.8], 0.4).with_translation([10.0, -20.0, 5.0]).to_transform();
            chain.tool = rotation_about([0.0, 1.0, 0.0], 0.2).with_translation([1.0, 2.0, 30.0]).to_transform();
            let frames = LinkFrames::of_dh_chain(&chain);
            let q = [0.3, -1.1, 25.0, 2.0, -0.4, 1.3];
            let mut t = Frame::IDENTITY;
            for i in 0..6 {
                let motion = match frames.kinds[i] {
                    JointKind::Revolute => rotation_about(frames.axes[i], q[i]),
                    JointKind::Prismatic => Frame::IDENTITY.with_translation(frames.axes[i].map(|a| a * q[i])),
                };
                t = t.compose(&frames.origin(i, &Frame::IDENTITY)).compose(&motion);
            }
            t = t.compose(&frames.tip_in_last_link());
            let walk = cbd_runtime::internals::kinematics::rigid::dh_walk(&chain, &q);
            for c in 0..3 {
                assert!((t.translation()[c] - walk.tool[c]).abs() < 1e-10, "{convention:?}");
                for j in 0..3 {
                    assert!((t.rotation()[c][j] - walk.tool_rotation[c][j]).abs() < 1e-14);
                }
            }
        }
    }
}
