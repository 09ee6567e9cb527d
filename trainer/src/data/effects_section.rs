//! The model file's `[gravity]` and `[[effects]]` sections: the physical effects on top of the
//! rigid chain (what `cbd diagnose --write-model` finds), read into and written from the
//! protocol's [`Effects`].
//!
//! ```toml
//! [gravity]                        # optional: the mass model of the gravity-driven effects
//! direction = [0, 0, -1]           # unit vector along gravity, base frame (default −z; planar arms −y)
//! link_masses = [1, 1, 1, 1, 1, 1] # point mass at the distal end of each link (default 1 each),
//!                                  # the mass model of the "gravity_compliance" entries
//!
//! [[gravity.link_moments]]         # one link's mass moments as one compliant joint feels them
//! joint = 2                        # δ_j += ∂/∂q_j g·(mass·o_k(q) + R_k(q)·first_moment), k = link ≥ j
//! link = 3                         # o_k, R_k: origin and rotation of link k's frame (at its end)
//! mass = 0.8                       # c_j·m_k, mass unit (gauge c_j = 1 angle_unit per mass·length_unit)
//! first_moment = [0.1, 0.0, -0.02] # c_j·m_k·r_k, mass × length_unit, r_k the centre of mass in
//!                                  # link k's frame (planar arms: 2 entries, x along the link)
//!```
//!
//! Why per compliant joint, and why a gauge: the gravity torque is linear in the links' masses
//! and first moments (τ = Y(q)·(m, s), the gravity regressor), so a compliant joint's deflection
//! c_j τ_j is linear in the products c_j·m_k, c_j·s_k for k ≥ j. Kinematic data see only those
//! products (c_j and m_k never separately: the gauge c_j = 1 fixes the scale), and only their
//! identifiable combinations: `cbd diagnose` keeps the columns of the regressor that column-pivoted
//! QR finds independent and writes the others as zero, so the written set reproduces
//! exactly the fitted deflection. Each compliant joint has its own set: one set shared by several
//! joints would make the products of different joints proportional, a nonlinear constraint the
//! linear fit does not impose. Without `link_moments` a joint's gravity compliance is the point-mass
//! model (`link_masses` at the link ends, s = 0), which is what older files and blobs mean.
//!
//! ```toml
//! [[effects]]                      # joints and links are 1-based
//! type = "transmission"            # δ_j = cos·cos(h q_j) + sin·sin(h q_j)
//! joint = 2
//! harmonic = 2
//! cos = 0.1146                     # angle_unit
//! sin = -0.0573
//!
//! [[effects]]
//! type = "encoder_scale"           # δ_j = scale·q_j
//! joint = 1
//! scale = 1e-4
//!
//! [[effects]]
//! type = "gravity_compliance"      # δ_j = compliance·τ_j(q), τ_j the gravity torque (force, for a
//! joint = 3                        # prismatic joint) of the mass model
//! compliance = 2.3e-5              # angle_unit (prismatic: length_unit) per (mass·length_unit)
//!
//! [[effects]]
//! type = "link_bending"            # tool moved by compliance·(g − (g·u)u), u along link `link`
//! link = 2
//! compliance = 0.05                # length_unit
//! ```

use crate::effects::{check_values, FileUnits, Instance};
use cbd_protocol::{Effect, GravityModel, NominalModel, MAX_EFFECTS};
use serde::Deserialize;
use std::fmt::Write as _;

pub use crate::effects::{FieldError, RawEffect};

/// `[gravity]` as written in the file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawGravity {
    direction: Option<Vec<f64>>,
    link_masses: Option<Vec<f64>>,
    link_moments: Option<Vec<RawLinkMoment>>,
}

/// One `[[gravity.link_moments]]` entry (1-based joint and link, the file's units).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawLinkMoment {
    joint: usize,
    link: usize,
    mass: f64,
    first_moment: Vec<f64>,
}

/// The `[[gravity.link_moments]]` entries as effects (joint units per `rad_per_unit`).
fn link_moments(raw: &[RawLinkMoment], n: usize, planar: bool, revolute: &[bool], rad_per_unit: f64) -> Result<Vec<Effect>, FieldError> {
    let mut out = Vec::new();
    for (k, m) in raw.iter().enumerate() {
        let entry = k + 1;
        let at = format!("[[gravity.link_moments]] entry {entry}");
        let named = |what: &str, value: usize| {
            if value == 0 || value > n {
                Err(FieldError::new(&at, format!("{what} = {value}, the model has {n} (1 to {n})")))
            } else {
                Ok(value - 1)
            }
        };
        let (joint, link) = (named("joint", m.joint)?, named("link", m.link)?);
        if link < joint {
            return Err(FieldError::new(&at, format!("link = {} is before joint = {}; only links after a joint load it", m.link, m.joint)));
        }
        let want = if planar { 2 } else { 3 };
        if m.first_moment.len() != want {
            return Err(FieldError::new(&at, format!("first_moment has {} entries; this model needs {want}", m.first_moment.len())));
        }
        let mut values = vec![("mass", m.mass)];
        values.extend(m.first_moment.iter().map(|v| ("first_moment", *v)));
        check_values(&at, &values)?;
        // A revolute joint deflects by an angle (the gauge c_j = 1 angle unit per mass·length).
        let unit = if revolute[joint] { rad_per_unit } else { 1.0 };
        let mut first_moment = [0.0; 3];
        for (s, v) in first_moment.iter_mut().zip(&m.first_moment) {
            *s = v * unit;
        }
        out.push(Effect::GravityMoment { joint: joint as u8, link: link as u8, mass: m.mass * unit, first_moment });
    }
    Ok(out)
}

/// Puts the file's `[gravity]` and `[[effects]]` into `nominal` (lengths already in the model's
/// unit, which is the file's; `rad_per_unit` converts the file's angles). Errors name the entry
/// and the field.
pub fn apply(gravity: Option<&RawGravity>, effects: &[RawEffect], rad_per_unit: f64, nominal: &mut NominalModel) -> Result<(), FieldError> {
    let n = nominal.n_joints();
    let planar = matches!(nominal, NominalModel::PlanarChain { .. });
    let revolute: Vec<bool> = (0..n).map(|d| nominal.is_revolute(d)).collect();
    let target = nominal.effects_mut();
    if let Some(g) = gravity {
        if let Some(d) = &g.direction {
            let want = if planar { 2 } else { 3 };
            if d.len() != want {
                return Err(FieldError::new("[gravity] direction", format!("{} entries; this model needs {want}", d.len())));
            }
            let norm = d.iter().map(|v| v * v).sum::<f64>().sqrt();
            if !(norm.is_finite() && norm > 0.0) {
                return Err(FieldError::new("[gravity] direction", format!("{d:?} has no direction")));
            }
            // A direction already of unit length to rounding (as `--write-model` writes one) is
            // kept as written: dividing by a norm of 1 ± a few ulp would move its last bits, so a
            // written file would not read back to the model it came from.
            let scale = if (norm - 1.0).abs() <= 4.0 * f64::EPSILON { 1.0 } else { norm };
            let mut unit = [0.0; 3];
            for (u, v) in unit.iter_mut().zip(d) {
                *u = v / scale;
            }
            target.gravity.direction = unit;
        }
        if let Some(masses) = &g.link_masses {
            if masses.len() != n {
                return Err(FieldError::new("[gravity] link_masses", format!("{} entries; the model has {n} links", masses.len())));
            }
            if let Some((k, m)) = masses.iter().enumerate().find(|(_, m)| !(m.is_finite() && **m >= 0.0)) {
                return Err(FieldError::new(
                    format!("[gravity] link_masses[{}]", k + 1),
                    format!("{} is not a finite mass ≥ 0", crate::error::number(*m)),
                ));
            }
            target.gravity.link_masses =
                heapless::Vec::from_slice(masses).map_err(|_| FieldError::new("[gravity] link_masses", "too many"))?;
        }
    }
    let moments = match gravity.and_then(|g| g.link_moments.as_deref()) {
        Some(raw) => link_moments(raw, n, planar, &revolute, rad_per_unit)?,
        None => Vec::new(),
    };
    if moments.len() + effects.len() > MAX_EFFECTS {
        return Err(FieldError::new(
            "[[effects]]",
            format!(
                "{} entries and {} [[gravity.link_moments]] entries; at most {MAX_EFFECTS} in all are supported",
                effects.len(),
                moments.len()
            ),
        ));
    }
    if effects.len() > MAX_EFFECTS {
        return Err(FieldError::new("[[effects]]", format!("{} entries; at most {MAX_EFFECTS} are supported", effects.len())));
    }
    let units = FileUnits { rad_per_unit, revolute: &revolute };
    for (k, raw) in effects.iter().enumerate() {
        let at = format!("[[effects]] entry {}", k + 1);
        let effect = raw.read(k + 1, &units)?.to_blob().ok_or_else(|| FieldError::new(&at, "this effect has no blob form"))?;
        target.list.push(effect).map_err(|_| FieldError::new(&at, "too many effects"))?;
    }
    for effect in moments {
        target.list.push(effect).map_err(|_| FieldError::new("[[gravity.link_moments]]", "too many effects"))?;
    }
    Ok(())
}

/// One `[[effects]]` entry of `effect` (empty for a kind written elsewhere).
pub fn write_entry(effect: &Instance, units: &FileUnits) -> String {
    if effect.kind.file_fields().is_empty() {
        return String::new();
    }
    format!("\n[[effects]]\ntype = \"{}\"\n{}", effect.kind.name(), effect.kind.write(effect, units))
}

/// The `[gravity]` (when not the default) and `[[effects]]` sections of `nominal`, angles in the
/// unit with `rad_per_unit` radians.
pub fn write(nominal: &NominalModel, rad_per_unit: f64) -> String {
    let (effects, planar) = (nominal.effects(), matches!(nominal, NominalModel::PlanarChain { .. }));
    let mut out = String::new();
    let default = if planar { GravityModel::PLANAR } else { GravityModel::DEFAULT };
    let has_moments = effects.list.iter().any(|e| matches!(e, Effect::GravityMoment { .. }));
    let dims = if planar { 2 } else { 3 };
    if effects.gravity != default || has_moments {
        out += "\n[gravity]\n";
        let _ = writeln!(out, "direction = {}", list(&effects.gravity.direction[..dims]));
        if !effects.gravity.link_masses.is_empty() {
            let _ = writeln!(out, "link_masses = {}", list(&effects.gravity.link_masses));
        }
    }
    for e in &effects.list {
        if let Effect::GravityMoment { joint, link, mass, first_moment } = *e {
            let unit = if nominal.is_revolute(joint as usize) { rad_per_unit } else { 1.0 };
            let s: Vec<f64> = first_moment[..dims].iter().map(|v| v / unit).collect();
            let _ = writeln!(
                out,
                "\n[[gravity.link_moments]]\njoint = {}\nlink = {}\nmass = {:?}\nfirst_moment = {}",
                joint + 1,
                link + 1,
                mass / unit,
                list(&s)
            );
        }
    }
    let revolute: Vec<bool> = (0..nominal.n_joints()).map(|d| nominal.is_revolute(d)).collect();
    let units = FileUnits { rad_per_unit, revolute: &revolute };
    for e in &effects.list {
        out += &write_entry(&Instance::of(e), &units);
    }
    out
}

/// A TOML array of floats, each written so that it reads back to the same f64.
pub fn list(values: &[f64]) -> String {
    let items: Vec<String> = values.iter().map(|v| format!("{v:?}")).collect();
    format!("[{}]", items.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;
    use cbd_protocol::NominalModel;

    /// The sections of a model file, as `model_file` reads them.
    #[derive(Debug, Deserialize)]
    struct Sections {
        gravity: Option<RawGravity>,
        #[serde(default)]
        effects: Vec<RawEffect>,
    }

    fn six() -> NominalModel {
        NominalModel::DhChain(crate::simulate::six_joint::ur5_nominal())
    }

    /// The sections of `text` applied to `nominal` (a TOML error or the sections' own).
    fn read(text: &str, nominal: &NominalModel, rad_per_unit: f64) -> Result<NominalModel, Box<dyn std::error::Error>> {
        let sections: Sections = toml::from_str(text)?;
        let mut out = nominal.clone();
        apply(sections.gravity.as_ref(), &sections.effects, rad_per_unit, &mut out)?;
        Ok(out)
    }

    /// A written direction of unit length to rounding reads back bit for bit (a `[planar]` file
    /// written by `diagnose --write-model` once read back 1 ulp off and wrote different text); any
    /// other length is normalised.
    // The literals are the directions as written in files, 1 ulp apart on purpose.
    #[allow(clippy::approx_constant)]
    #[test]
    fn a_unit_gravity_direction_reads_back_as_written() {
        let planar = NominalModel::planar(&[1.0, 0.5]).unwrap();
        for g in [[-0.02199072373954877, -0.9997581747949905], [0.6, -0.8], [-0.7071067811865476, -0.7071067811865475]] {
            let text = format!("[gravity]\ndirection = [{:?}, {:?}]\n", g[0], g[1]);
            let read_back = read(&text, &planar, 1.0).unwrap().effects().gravity.direction;
            assert_eq!(read_back, [g[0], g[1], 0.0], "{text}");
        }
        let read_back = read("[gravity]\ndirection = [0, 0, -2]\n", &six(), 1.0).unwrap().effects().gravity.direction;
        assert_eq!(read_back, [0.0, 0.0, -1.0]);
    }

    #[test]
    fn link_moments_round_trip_in_the_files_units() {
        let deg = std::f64::consts::PI / 180.0;
        let mut model = six();
        model.effects_mut().list = heapless::Vec::from_slice(&[
            Effect::Transmission { joint: 3, harmonic: 1, cos: 1e-3, sin: -2e-3 },
            Effect::GravityMoment { joint: 1, link: 2, mass: 3e-7, first_moment: [4.5e-5, 0.0, -1.2e-5] },
            Effect::GravityMoment { joint: 1, link: 5, mass: -1e-8, first_moment: [0.0, 2e-6, 0.0] },
        ])
        .unwrap();
        for rad_per_unit in [1.0, deg] {
            let text = write(&model, rad_per_unit);
            assert!(text.contains("[[gravity.link_moments]]\njoint = 2\nlink = 3\n"), "{text}");
            let back = read(&text, &six(), rad_per_unit).unwrap();
            // Same effects (moments listed after [[effects]] on reading), values to rounding.
            let (a, b) = (&model.effects().list, &back.effects().list);
            assert_eq!(a.len(), b.len(), "{text}");
            for e in a.iter() {
                let found = b.iter().any(|f| match (e, f) {
                    (
                        Effect::GravityMoment { joint, link, mass, first_moment },
                        Effect::GravityMoment { joint: j, link: l, mass: m, first_moment: s },
                    ) => {
                        joint == j
                            && link == l
                            && (mass - m).abs() <= 1e-15 * mass.abs()
                            && first_moment.iter().zip(s).all(|(x, y)| (x - y).abs() <= 1e-15 * x.abs())
                    }
                    (Effect::Transmission { cos, sin, .. }, Effect::Transmission { cos: c, sin: s, .. }) => {
                        (cos - c).abs() <= 1e-15 * cos.abs() && (sin - s).abs() <= 1e-15 * sin.abs()
                    }
                    _ => false,
                });
                assert!(found, "{e:?} not read back from\n{text}");
            }
            // In degrees the file holds c·m with c = 1 degree per mass·mm: 180/π times the radian value.
            if rad_per_unit != 1.0 {
                assert!(text.contains(&format!("mass = {:?}", 3e-7 / deg)), "{text}");
            }
        }
    }

    #[test]
    fn bad_link_moments_are_errors_naming_the_entry_and_field() {
        let entry = |body: &str| format!("[gravity]\ndirection = [0, 0, -1]\n\n[[gravity.link_moments]]\n{body}\n");
        let cases = [
            ("joint = 0\nlink = 2\nmass = 1\nfirst_moment = [0, 0, 0]", "entry 1: joint = 0, the model has 6"),
            ("joint = 2\nlink = 7\nmass = 1\nfirst_moment = [0, 0, 0]", "entry 1: link = 7, the model has 6"),
            ("joint = 3\nlink = 2\nmass = 1\nfirst_moment = [0, 0, 0]", "entry 1: link = 2 is before joint = 3"),
            ("joint = 2\nlink = 3\nmass = 1\nfirst_moment = [0, 0]", "entry 1: first_moment has 2 entries; this model needs 3"),
            ("joint = 2\nlink = 3\nmass = nan\nfirst_moment = [0, 0, 0]", "[[gravity.link_moments]] entry 1: mass = NaN is not finite"),
            ("joint = 2\nlink = 3\nmass = 1\nfirst_moment = [0, inf, 0]", "entry 1: first_moment = inf is not finite"),
            ("joint = 2\nlink = 3\nmasses = 1\nfirst_moment = [0, 0, 0]", "unknown field `masses`"),
        ];
        for (body, needle) in cases {
            let err = read(&entry(body), &six(), 1.0).unwrap_err().to_string();
            assert!(err.contains(needle), "{body}: {err}");
        }
        assert!(read(&entry("joint = 2\nlink = 3\nmass = 1\nfirst_moment = [0, 0, 0]"), &six(), 1.0).is_ok());
    }
}
