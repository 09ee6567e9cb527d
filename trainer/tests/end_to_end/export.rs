//! `cbd export` (issue 40): the exported URDF read back by cbd's own URDF import, and the UR
//! kinematics file composed as ur_description composes it, give the calibrated chain's forward
//! kinematics to 1e-9 of the reach on 1000 random poses; a URDF model's own file keeps every byte
//! but the calibrated origins; a blob without calibrated geometry is refused.

use crate::cli_support;
#[allow(dead_code)] // the diagnose files use the rest
use crate::common;

use cbd_protocol::{DhChain, DhConvention, JointKind, NominalModel};
use cbd_runtime::internals::kinematics::rigid::dh_walk;
use cbd_trainer::nominal::export::{ur_kinematics, urdf_patch, urdf_write, LinkFrames};
use cbd_trainer::nominal::urdf::{chain_from_urdf, parse, urdf_tip_pose};
use cbd_trainer::nominal::{rotation_about, rpy, Frame};
use cli_support::*;
use rand::{Rng, SeedableRng};

const POSES: usize = 1000;

fn ur_description() -> String {
    std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/ur5_description.urdf")).unwrap()
}

/// 1000 random configurations, revolute joints in [−π, π], prismatic ones in [−50, 50] (model units).
fn poses(kinds: &[JointKind], seed: u64) -> Vec<Vec<f64>> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let pi = std::f64::consts::PI;
    (0..POSES)
        .map(|_| {
            kinds.iter().map(|k| if *k == JointKind::Revolute { rng.gen_range(-pi..pi) } else { rng.gen_range(-50.0..50.0) }).collect()
        })
        .collect()
}

/// The chain's tool frame at `q` (model units).
fn tool_frame(chain: &DhChain, q: &[f64]) -> Frame {
    let w = dh_walk(chain, q);
    Frame::new(w.tool_rotation, w.tool)
}

/// Largest distance of the tool from the base over `poses`: the reach the tolerance is relative to.
fn reach(chain: &DhChain, poses: &[Vec<f64>]) -> f64 {
    let base = Frame::from_transform(&chain.base).translation();
    poses
        .iter()
        .map(|q| {
            cbd_runtime::internals::kinematics::spatial::norm(cbd_runtime::internals::kinematics::spatial::sub(
                tool_frame(chain, q).translation(),
                base,
            ))
        })
        .fold(0.0, f64::max)
}

/// Largest position gap (model units) and rotation-entry gap between two frames over `poses`.
#[track_caller]
fn assert_same_frames(what: &str, poses: &[Vec<f64>], reach: f64, want: impl Fn(&[f64]) -> Frame, got: impl Fn(&[f64]) -> Frame) {
    let (mut dp, mut dr) = (0.0f64, 0.0f64);
    for q in poses {
        let (a, b) = (want(q), got(q));
        for i in 0..3 {
            dp = dp.max((a.translation()[i] - b.translation()[i]).abs());
            for j in 0..3 {
                dr = dr.max((a.rotation()[i][j] - b.rotation()[i][j]).abs());
            }
        }
    }
    eprintln!("{what}: largest position gap {:.2e} of the reach {reach:.1}, rotation {dr:.2e}", dp / reach);
    assert!(dp <= 1e-9 * reach && dr <= 1e-9, "{what}: position {dp:e} (reach {reach}), rotation {dr:e}");
}

/// The URDF `robot`'s chain `base` → `tip`, composed joint by joint and read by cbd's own URDF import
/// (URDF → DH), gives `calibrated`'s tool frame on 1000 random poses.
#[track_caller]
fn assert_urdf_is(what: &str, robot: &urdf_rs::Robot, base: &str, tip: &str, calibrated: &DhChain, seed: u64) {
    let kinds: Vec<JointKind> = calibrated.joints.iter().map(|j| j.kind).collect();
    let poses = poses(&kinds, seed);
    let r = reach(calibrated, &poses);
    let composed = |q: &[f64]| urdf_tip_pose(robot, base, tip, q, 1000.0).unwrap();
    assert_same_frames(&format!("{what}, composed"), &poses, r, |q| tool_frame(calibrated, q), composed);
    let read = chain_from_urdf(robot, base, tip, 1000.0).unwrap().chain;
    assert_same_frames(&format!("{what}, URDF → DH import"), &poses, r, |q| tool_frame(calibrated, q), |q| tool_frame(&read, q));
}

/// A realistic calibrated UR5 (mm): ±0.5 mm and ±0.1° on every DH parameter, the base and the
/// tool, the tool turned (the simulated arm's real chain).
fn calibrated_ur5(seed: u64) -> DhChain {
    cbd_trainer::simulate::six_joint::SixJointRobot::ur5_like(seed).real
}

fn naming<'a>(joints: &'a [String], limits: &'a [[f64; 2]]) -> urdf_write::UrdfNaming<'a> {
    urdf_write::UrdfNaming { robot: "test \"arm\" & co", joints, to_metres: 1e-3, limits, comment: &[] }
}

#[test]
fn urdf_of_a_dh_model_reads_back_to_the_calibrated_chain() {
    // The UR5 (standard), and a modified-convention chain with a prismatic joint.
    let mut modified = calibrated_ur5(3);
    modified.convention = DhConvention::Modified;
    modified.joints[2].kind = JointKind::Prismatic;
    for (k, calibrated) in [calibrated_ur5(1), modified].into_iter().enumerate() {
        let mut nominal = cbd_protocol::ur5::chain();
        nominal.convention = calibrated.convention;
        nominal.joints[2].kind = calibrated.joints[2].kind;
        let frames = LinkFrames::of_dh_chain(&calibrated).slid_toward(&LinkFrames::of_dh_chain(&nominal));
        let names: Vec<String> = (1..=6).map(|i| format!("q{i}")).collect();
        let limits = vec![[-100.0, 100.0]; 6];
        let text = urdf_write::write_urdf(&frames, &Frame::from_transform(&calibrated.base), &naming(&names, &limits));
        assert!(!text.contains("calibration") && text.contains("name=\"test &quot;arm&quot; &amp; co\""), "{text}");
        let robot = parse(&text).unwrap_or_else(|e| panic!("{e}\n{text}"));
        assert_eq!(chain_from_urdf(&robot, "base_link", "tool0", 1000.0).unwrap().joint_names, names);
        assert_urdf_is("URDF of a DH model", &robot, "base_link", "tool0", &calibrated, 10 + k as u64);
    }
}

/// Where `xyz="…"` and `rpy="…"` values lie in `text`: (start, end) byte ranges, in order.
fn attribute_values(text: &str) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for key in ["xyz=\"", "rpy=\""] {
        let mut at = 0;
        while let Some(k) = text[at..].find(key) {
            let start = at + k + key.len();
            let end = start + text[start..].find('"').unwrap();
            out.push((start, end));
            at = end;
        }
    }
    out.sort();
    out
}

/// The joint (`<joint name="…">`) a byte of `text` lies in, if any.
fn enclosing_joint(text: &str, at: usize) -> Option<&str> {
    let open = text[..at].rfind("<joint ")?;
    if text[..at].rfind("</joint>").is_some_and(|close| close > open) {
        return None;
    }
    let name = &text[open..][text[open..].find("name=\"").unwrap() + 6..];
    Some(&name[..name.find('"').unwrap()])
}

#[test]
fn urdf_of_a_urdf_model_changes_only_the_calibrated_origins() {
    let text = ur_description();
    let robot = parse(&text).unwrap();
    let nominal = chain_from_urdf(&robot, "world", "tool0", 1000.0).unwrap().chain;
    let errors = common::six_joint_geometric_errors(5);
    let calibrated = cbd_trainer::nominal::dh_parameters::apply_parameters(&nominal, &errors);
    let patched = urdf_patch::patch_urdf(&text, "world", "tool0", 1000.0, &calibrated).unwrap();
    let changed =
        ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint", "wrist_3-flange"];
    assert_eq!(patched.joints, changed);
    // Byte for byte outside the changed joints' origins: the same attributes, the same text between
    // them, and every value that differs is an origin's of a changed joint.
    let (before, after) = (attribute_values(&text), attribute_values(&patched.text));
    assert_eq!(before.len(), after.len());
    let mut differing = std::collections::BTreeSet::new();
    let mut last = (0, 0);
    for (&(s0, e0), &(s1, e1)) in before.iter().zip(&after) {
        assert_eq!(&text[last.0..s0], &patched.text[last.1..s1], "text between attribute values changed");
        if text[s0..e0] != patched.text[s1..e1] {
            let tag = &patched.text[patched.text[..s1].rfind('<').unwrap()..];
            assert!(tag.starts_with("<origin"), "a value outside an <origin> changed: {}", &tag[..40]);
            let joint = enclosing_joint(&patched.text, s1).expect("a changed origin inside a joint");
            differing.insert(joint.to_string());
        }
        last = (e0, e1);
    }
    assert_eq!(&text[last.0..], &patched.text[last.1..]);
    assert_eq!(differing, changed.iter().map(|s| s.to_string()).collect());
    // The transmission's <joint name="shoulder_pan_joint"> has no origin and got none.
    assert_eq!(patched.text.matches("<origin").count(), text.matches("<origin").count());

    let back = parse(&patched.text).unwrap();
    assert_urdf_is("patched URDF", &back, "world", "tool0", &calibrated, 7);
    // Each link stays where its meshes are: its origin moved by about the calibration's change
    // (millimetres), not along its axis by the DH parameters' redistribution.
    let (old, _) = urdf_patch::link_frames(&robot, "world", "tool0", 1000.0).unwrap();
    let (new, _) = urdf_patch::link_frames(&back, "world", "tool0", 1000.0).unwrap();
    for (a, b) in old.links.iter().zip(&new.links) {
        let moved = cbd_runtime::internals::kinematics::spatial::norm(cbd_runtime::internals::kinematics::spatial::sub(
            a.translation(),
            b.translation(),
        ));
        assert!(moved < 5.0, "a link moved {moved} mm");
    }
}

#[test]
fn urdf_patch_adds_a_missing_origin_or_attribute_and_refuses_a_chain_without_a_tool_joint() {
    let text = ur_description()
        .replace("    <origin xyz=\"-0.425 0 0\" rpy=\"0 0 0\"/>\n", "")
        .replace("<origin xyz=\"-0.39225 0 0.10915\" rpy=\"0 0 0\"/>", "<origin xyz=\"-0.39225 0 0.10915\"/>");
    let robot = parse(&text).unwrap();
    let nominal = chain_from_urdf(&robot, "base_link", "tool0", 1000.0).unwrap().chain;
    let mut p = vec![0.0; 33];
    p[1] = 0.001; // α1
    p[10] = 0.3; // d3
    let calibrated = cbd_trainer::nominal::dh_parameters::apply_parameters(&nominal, &p);
    let patched = urdf_patch::patch_urdf(&text, "base_link", "tool0", 1000.0, &calibrated).unwrap();
    let back = parse(&patched.text).unwrap();
    assert_urdf_is("origins added", &back, "base_link", "tool0", &calibrated, 8);
    let joint_text = |name: &str| {
        let at = patched.text.find(&format!("<joint name=\"{name}\"")).unwrap();
        &patched.text[at..at + patched.text[at..].find("</joint>").unwrap()]
    };
    assert!(joint_text("elbow_joint").contains("\n    <origin xyz=\""), "{}", joint_text("elbow_joint"));
    let wrist_1 = joint_text("wrist_1_joint");
    assert!(wrist_1[wrist_1.find("<origin").unwrap()..].lines().next().unwrap().contains(" rpy=\""), "{wrist_1}");
    // The tip is the last joint's own link: no fixed joint to carry the tool.
    let e = urdf_patch::patch_urdf(&text, "base_link", "wrist_3_link", 1000.0, &calibrated).unwrap_err().to_string();
    assert!(e.contains("'wrist_3_link' is the last joint's own link") && e.contains("add a link fixed"), "{e}");
}

/// ur_description's composition: base_link → base_link_inertia (rpy 0 0 π) → per joint its
/// origin from the file, then its turn about z → flange (0 −π/2 −π/2) → tool0 (π/2 0 π/2), read
/// from the file by a YAML parser that is not ours.
fn ur_description_tool0(yaml: &str, q: &[f64]) -> Frame {
    let docs = yaml_rust2::YamlLoader::load_from_str(yaml).unwrap();
    let k = &docs[0]["kinematics"];
    let pi = std::f64::consts::PI;
    let mut t = rpy(0.0, 0.0, pi);
    for (i, name) in ur_kinematics::SEGMENTS.iter().enumerate() {
        let v = |key: &str| {
            let y = &k[*name][key];
            y.as_f64().or_else(|| y.as_i64().map(|i| i as f64)).unwrap_or_else(|| panic!("{name}.{key}: {y:?}"))
        };
        let origin = rpy(v("roll"), v("pitch"), v("yaw")).with_translation([v("x"), v("y"), v("z")]);
        t = t.compose(&origin).compose(&rotation_about([0.0, 0.0, 1.0], q[i]));
    }
    t.compose(&rpy(0.0, -pi / 2.0, -pi / 2.0)).compose(&rpy(pi / 2.0, 0.0, pi / 2.0))
}

/// `frame` (model units, mm) in metres.
fn metres(frame: Frame) -> Frame {
    frame.with_translation(frame.translation().map(|v| v * 1e-3))
}

#[test]
fn ur_kinematics_file_composes_as_ur_description_to_the_calibrated_chain() {
    // The nominal UR5: UR's own default kinematics (ur_description's config/ur5/default_kinematics.yaml
    // values) and the 31 mm reflector as the TCP.
    let nominal = cbd_protocol::ur5::chain();
    let k = ur_kinematics::ur_kinematics(&LinkFrames::of_dh_chain(&nominal), &Frame::IDENTITY, 1e-3, &[]).unwrap();
    let half = std::f64::consts::FRAC_PI_2;
    let defaults = [
        [0.0, 0.0, 0.089159, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, half, 0.0, 0.0],
        [-0.425, 0.0, 0.0, 0.0, 0.0, 0.0],
        [-0.39225, 0.0, 0.10915, 0.0, 0.0, 0.0],
        [0.0, -0.09465, 0.0, half, 0.0, 0.0],
        [0.0, 0.0823, 0.0, -half, 0.0, 0.0],
    ];
    for (segment, want) in k.segments.iter().zip(defaults) {
        let got = rpy(want[3], want[4], want[5]).with_translation([want[0], want[1], want[2]]);
        for i in 0..3 {
            assert!((segment.translation()[i] - got.translation()[i]).abs() < 1e-12, "{segment:?}");
            for j in 0..3 {
                assert!((segment.rotation()[i][j] - got.rotation()[i][j]).abs() < 1e-12, "{segment:?}");
            }
        }
    }
    assert!((k.tcp.translation()[2] - 0.031).abs() < 1e-12 && k.tcp.translation()[..2].iter().all(|v| v.abs() < 1e-12), "{:?}", k.tcp);
    assert!(k.text.contains("kinematics:\n  shoulder:\n    x: 0\n") && k.text.contains("\n  hash: cbd_"), "{}", k.text);

    // Calibrated: every pose through the file as ur_description composes it, then the TCP.
    let calibrated = calibrated_ur5(2);
    let frames = LinkFrames::of_dh_chain(&calibrated).slid_toward(&LinkFrames::of_dh_chain(&nominal));
    let k = ur_kinematics::ur_kinematics(&frames, &Frame::IDENTITY, 1e-3, &["a comment".into()]).unwrap();
    assert!(k.text.starts_with("# a comment\nkinematics:\n"));
    let poses = poses(&[JointKind::Revolute; 6], 9);
    let r = reach(&calibrated, &poses) * 1e-3;
    let base_link = rpy(0.0, 0.0, std::f64::consts::PI);
    assert_same_frames(
        "UR kinematics (DH model)",
        &poses,
        r,
        |q| base_link.compose(&metres(tool_frame(&calibrated, q))),
        |q| ur_description_tool0(&k.text, q).compose(&k.tcp),
    );
    // The same written twice: the same bytes and hash.
    assert_eq!(ur_kinematics::ur_kinematics(&frames, &Frame::IDENTITY, 1e-3, &["a comment".into()]).unwrap(), k);
}

#[test]
fn ur_kinematics_of_a_urdf_model_composes_as_ur_description() {
    let text = ur_description();
    let robot = parse(&text).unwrap();
    let nominal = chain_from_urdf(&robot, "base_link", "tool0", 1000.0).unwrap().chain;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let p: Vec<f64> =
        (0..33).map(|k| if k < 24 && k % 4 % 2 == 1 { rng.gen_range(-0.002..0.002) } else { rng.gen_range(-0.5..0.5) }).collect();
    let calibrated = cbd_trainer::nominal::dh_parameters::apply_parameters(&nominal, &p);
    let patched = urdf_patch::patch_urdf(&text, "base_link", "tool0", 1000.0, &calibrated).unwrap();
    let (frames, root) = urdf_patch::link_frames(&parse(&patched.text).unwrap(), "base_link", "tool0", 1000.0).unwrap();
    let k = ur_kinematics::ur_kinematics(&frames, &root, 1e-3, &[]).unwrap();
    let poses = poses(&[JointKind::Revolute; 6], 12);
    let r = reach(&calibrated, &poses) * 1e-3;
    assert_same_frames(
        "UR kinematics (URDF model)",
        &poses,
        r,
        |q| metres(tool_frame(&calibrated, q)),
        |q| ur_description_tool0(&k.text, q).compose(&k.tcp),
    );
    // A joint about another axis than z, or a prismatic one, has no place in the file.
    let mut tilted = frames.clone();
    tilted.axes[3] = [0.0, 1.0, 0.0];
    let e = ur_kinematics::ur_kinematics(&tilted, &root, 1e-3, &[]).unwrap_err().to_string();
    assert!(e.contains("joint 4 turns about") && e.contains("axis 0 0 1"), "{e}");
}

// ---- the command

/// The UR5 example fitted on 300 rows with its geometry calibrated.
fn fitted_ur5(dir: &std::path::Path, name: &str) -> String {
    let (data, model) = (ur5_head(dir, "train300.csv", 300), ur5_model());
    succeeds(&cbd(dir, &["fit", "--quiet", "--dh-first", "--model", &model, "--data", &data, "--out", name]));
    name.to_string()
}

#[test]
fn cbd_export_writes_both_files_and_states_what_they_leave_out() {
    let dir = scratch("export");
    let blob = fitted_ur5(&dir, "ur5.blob");
    let test = ur5_dir().join("test.csv");
    let out = cbd(
        &dir,
        &[
            "export",
            "--model",
            &ur5_model(),
            "--blob",
            &blob,
            "--urdf",
            "ur5.urdf",
            "--ur-kinematics",
            "ur5.yaml",
            "--data",
            test.to_str().unwrap(),
        ],
    );
    succeeds(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("{stdout}");
    assert!(stdout.contains("URDF written to ur5.urdf") && stdout.contains("UR kinematics written to ur5.yaml (hash cbd_"), "{stdout}");
    let line = stdout.lines().find(|l| l.contains("URDF alone")).expect("the geometry-alone line");
    assert!(line.contains("(20 rows), mean error: URDF alone ") && line.contains(" mm; with the runtime's correction "), "{line}");
    let urdf = std::fs::read_to_string(dir.join("ur5.urdf")).unwrap();
    assert!(parse(&urdf).is_ok() && !urdf.contains("<calibration"));
    // The blob's chain, read back from the URDF.
    let bytes = std::fs::read(dir.join(&blob)).unwrap();
    let NominalModel::DhChain(chain) = cbd_protocol::decode(&bytes).unwrap().nominal else { panic!() };
    let read = chain_from_urdf(&parse(&urdf).unwrap(), "base_link", "tool0", 1000.0).unwrap().chain;
    let poses = poses(&[JointKind::Revolute; 6], 13);
    assert_same_frames("cbd export --urdf", &poses, reach(&chain, &poses), |q| tool_frame(&chain, q), |q| tool_frame(&read, q));

    // A blob of the nominal chain (what a fit that keeps the nominal geometry writes): refused,
    // saying why and what to do.
    let mut model = cbd_protocol::decode(&bytes).unwrap();
    model.nominal = NominalModel::DhChain(cbd_protocol::ur5::chain());
    let nominal = write(&dir, "nominal.blob", cbd_protocol::encode_to_vec(&model).unwrap());
    fails_with(
        &cbd(&dir, &["export", "--model", &ur5_model(), "--blob", &nominal, "--urdf", "n.urdf"]),
        &["nominal.blob: no calibrated geometry in it", "--geometry calibrated", "cbd compensate"],
    );
    assert!(!dir.join("n.urdf").exists());
    fails_with(&cbd(&dir, &["export", "--model", &ur5_model(), "--blob", &blob]), &["nothing to export: give --urdf"]);
    write(&dir, "rr.toml", PLANAR_RR_MODEL);
    fails_with(
        &cbd(&dir, &["export", "--model", "rr.toml", "--blob", &blob, "--urdf", "x.urdf"]),
        &["rr.toml: a planar arm ([planar]) has no URDF"],
    );
}

/// Names as a user may write them (issue 51 class 1): XML entities, quotes, dashes, non-ASCII,
/// white space an attribute would fold.
const NASTY_NAMES: [&str; 6] = ["a&amp;b", "x \"q\" 'y'", "--->", "ünïcødé ✓", "tab\there", "<joint name=\"z\"/>"];

/// Issue 51 class 1: a URDF whose joints are named with entities (`&amp;`), quotes and non-ASCII
/// gets every calibrated origin, read back by name — not the nominal one under a "calibrated" line.
#[test]
fn urdf_patch_finds_joints_named_with_entities() {
    let plain = ur_description();
    let names = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"];
    let mut text = plain.clone();
    let mut renamed = Vec::new();
    for (k, name) in names.iter().enumerate() {
        let new = format!("{name}{}", NASTY_NAMES[k]);
        let escaped = quick_xml::escape::escape(new.as_str()).replace('\t', "&#9;");
        text = text.replace(&format!("\"{name}\""), &format!("\"{escaped}\""));
        renamed.push(new);
    }
    let robot = parse(&text).unwrap();
    let nominal = chain_from_urdf(&robot, "world", "tool0", 1000.0).unwrap().chain;
    let calibrated = cbd_trainer::nominal::dh_parameters::apply_parameters(&nominal, &common::six_joint_geometric_errors(5));
    let patched = urdf_patch::patch_urdf(&text, "world", "tool0", 1000.0, &calibrated).unwrap();
    assert_eq!(patched.joints[..6], renamed[..]);
    // Read back by an independent parser (xml-rs) and by cbd's import: the calibrated chain.
    let mut origins = 0;
    for event in xml::reader::EventReader::from_str(&patched.text) {
        if let xml::reader::XmlEvent::StartElement { name, .. } = event.expect("well-formed XML") {
            origins += usize::from(name.local_name == "origin");
        }
    }
    assert_eq!(origins, text.matches("<origin").count());
    assert_urdf_is("patched URDF, entity names", &parse(&patched.text).unwrap(), "world", "tool0", &calibrated, 7);
}

/// Issue 51 class 1: whatever the names in the comment (file names with `---`, newlines, quotes) and
/// the robot's name, the written URDF and UR kinematics file parse back (xml-rs, urdf-rs,
/// yaml-rust2) with the names as given and the comment lines comments only.
#[test]
fn written_urdf_and_yaml_parse_back_whatever_the_names() {
    let chain = calibrated_ur5(3);
    let joints: Vec<String> = (1..=6).map(|k| format!("q{k}")).collect();
    let frames = LinkFrames::of_dh_chain(&chain);
    let mut names: Vec<String> = NASTY_NAMES.iter().map(|s| s.to_string()).collect();
    names.extend(
        ["line\nbreak.blob", "cr\rlf\u{2028}sep\u{85}.toml", "-", "ends with -", "a---b--", "kinematics: {x: 1}"].map(String::from),
    );
    for name in &names {
        let comment = vec![format!("Written from {name} (model {name})."), name.clone()];
        let naming = urdf_write::UrdfNaming { robot: name, joints: &joints, to_metres: 1e-3, limits: &[], comment: &comment };
        let text = urdf_write::write_urdf(&frames, &Frame::from_transform(&chain.base), &naming);
        let mut comments = 0;
        for event in xml::reader::ParserConfig::new().ignore_comments(false).create_reader(text.as_bytes()) {
            match event.unwrap_or_else(|e| panic!("{name:?}: {e}\n{text}")) {
                xml::reader::XmlEvent::Comment(_) => comments += 1,
                xml::reader::XmlEvent::StartElement { name: element, attributes, .. } if element.local_name == "robot" => {
                    assert_eq!(attributes[0].value, *name, "robot name read back");
                }
                _ => {}
            }
        }
        assert_eq!(comments, 2, "{name:?}: {text}");
        let robot = urdf_rs::read_from_string(&text).unwrap_or_else(|e| panic!("{name:?}: {e}"));
        assert_eq!(robot.name, *name);
        assert_urdf_is("written URDF, named", &robot, "base_link", "tool0", &chain, 5);

        let k = ur_kinematics::ur_kinematics(&frames, &Frame::IDENTITY, 1e-3, &comment).unwrap();
        let docs = yaml_rust2::YamlLoader::load_from_str(&k.text).unwrap_or_else(|e| panic!("{name:?}: {e}\n{}", k.text));
        assert_eq!(docs.len(), 1, "{name:?}: one document\n{}", k.text);
        let top = docs[0].as_hash().expect("a mapping");
        assert_eq!(top.len(), 1, "{name:?}: only `kinematics` at the top\n{}", k.text);
        assert_eq!(docs[0]["kinematics"]["hash"].as_str(), Some(k.hash.as_str()));
        assert!(docs[0]["kinematics"]["wrist_3"]["yaw"].as_f64().is_some() || docs[0]["kinematics"]["wrist_3"]["yaw"].as_i64().is_some());
    }
    // A name XML cannot hold at all is refused, naming the field.
    let e = urdf_write::check_name("arm.toml: name", "bell\u{7}").unwrap_err().to_string();
    assert!(e.contains("arm.toml: name") && e.contains("U+0007"), "{e}");
}
