//! The diagnosis as text (stdout) and JSON (`--json`), and the residual figure (`--plots`).

use super::library::{is_angle, GroupKind, Param};
use super::{Diagnosis, DropReason, FoundEffect};
use crate::data::model_file::AngleUnit;
use crate::report::plots::EffectCurve;
use cbd_protocol::NominalModel;
use serde_json::{json, Value};

/// The units the report speaks: the model file's (the data's, without a model file).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Units<'a> {
    pub length: &'a str,
    pub angle: AngleUnit,
}

/// Unit of a parameter, as printed: angles in the file's angle unit, lengths in its length unit.
fn unit_of(model: &NominalModel, p: &Param, units: &Units) -> String {
    match *p {
        Param::Geometric(_) if is_angle(model, p) => units.angle.name().into(),
        Param::Geometric(_) => units.length.into(),
        Param::Effect { kind, site, component } => kind.unit(model, site, component, units.length, units.angle.name()).0,
    }
}

/// A value (or standard error) in the file's units: what is an angle, or an angle per torque
/// (a revolute joint's compliance), converted from radians.
fn shown(model: &NominalModel, p: &Param, v: f64, units: &Units) -> f64 {
    let per_angle = match *p {
        Param::Geometric(_) => is_angle(model, p),
        Param::Effect { kind, site, component } => kind.unit(model, site, component, units.length, units.angle.name()).1,
    };
    if per_angle {
        v / units.angle.radians()
    } else {
        v
    }
}

/// A share as a percentage with three significant figures (a small true share is not 0.00 %).
fn percent(share: f64) -> String {
    let p = 100.0 * share;
    if p >= 10.0 || p == 0.0 {
        format!("{p:.1} %")
    } else {
        let decimals = (2 - p.log10().floor() as i32).clamp(1, 9) as usize;
        format!("{p:.decimals$} %")
    }
}

/// The stdout report.
pub fn text(d: &Diagnosis, model: &NominalModel, units: &Units) -> String {
    let unit = units.length;
    let mut out = format!(
        "diagnosis on {} training rows; held-out rows: {} ({})\n\nstructure in the residual of the current model (significant, strongest first):\n",
        d.train_rows, d.test_rows, d.held_out
    );
    let list = |tests: &[super::structure::StructureTest]| -> String {
        let s = super::structure::significant(tests);
        if s.is_empty() {
            return "  none\n".into();
        }
        s.iter()
            .map(|t| {
                format!("  {:<24} explains {:>9}  F = {:.3e}  p = {:.1e}\n", t.name, percent(t.test.explained), t.test.f, t.test.p_value)
            })
            .collect()
    };
    out += &list(&d.structure_before);
    out +=
        &format!("\nselection ({} candidate groups, cross-validated RMS {:.4e} {unit} before):\n", d.candidates, d.selection.cv_rms_before);
    if d.found.is_empty() {
        out += "  no effect lowers the cross-validated error by the required margin: none found\n";
    }
    if !d.found.is_empty() {
        out += "  (explains: the drop in residual variance when the effect is added last, on the training rows)\n";
    }
    for f in &d.found {
        out += &format!("  {:<32} explains {:>9}; CV RMS after {:.4e}\n", f.name, percent(f.partial_share), f.cv_rms);
        if f.kind == GroupKind::Geometric && f.parameters.len() > 8 {
            out += &format!("      {} identifiable DH/base/tool parameters (see --json); largest changes:\n", f.parameters.len());
        }
        let mut ps: Vec<_> = f.parameters.iter().collect();
        if f.kind == GroupKind::Geometric {
            ps.sort_by(|a, b| (b.value / b.std_error.max(1e-300)).abs().total_cmp(&(a.value / a.std_error.max(1e-300)).abs()));
            ps.truncate(8);
        }
        for p in ps {
            out += &format!(
                "      {:<22} {:>+12.5e} ± {:.1e} {}\n",
                p.name,
                shown(model, &p.param, p.value, units),
                shown(model, &p.param, p.std_error, units),
                unit_of(model, &p.param, units)
            );
        }
    }
    if let Some((g, cv)) = d.selection.best_refused {
        let before = d.selection.cv_rms_after();
        out += &format!(
            "  (best refused: {}, CV RMS {cv:.4e}, {:.1} % lower: below the {:.0} % margin)\n",
            d.group_names[g],
            100.0 * (1.0 - cv / before),
            100.0 * d.margin
        );
    }
    if !d.dropped.is_empty() {
        let list: Vec<String> = d.dropped.iter().map(dropped_text).collect();
        out += &format!("  dropped after refinement: {}\n", list.join("; "));
    }
    out += "\nstructure left after the effects:\n";
    out += &list(&d.structure_after);
    if d.unexplained_structure {
        out += "  => unexplained structure: no library effect accounts for it; CbD absorbs it (table below)\n";
    }
    out += &format!("\nheld-out error ({unit}), {} rows:\n", d.test_rows);
    let floor_header = if d.noise_floor.is_some() { "   / floor" } else { "" };
    out += &format!("  {:<26} {:>11} {:>11} {:>11} {:>11}{floor_header}\n", "model", "mean", "median", "p99", "max");
    for r in &d.table {
        let floor = d.noise_floor.as_ref().map_or(String::new(), |f| format!(" {:>9}", f.verdict(r.stats.mean, r.errors.len()).cell()));
        let cell = |v: f64| if v.is_finite() { format!("{v:>11.4e}") } else { format!("{:>11}", "failed") };
        out += &format!(
            "  {:<26} {} {} {} {}{floor}\n",
            r.name,
            cell(r.stats.mean),
            cell(r.stats.median),
            cell(r.stats.p99),
            cell(r.stats.max)
        );
    }
    if let Some(f) = &d.noise_floor {
        out += &format!("  {}; `=` at it (more data or effects will not help), `>` above it (structure left)\n", f.describe(unit));
    }
    out += &pose_table(d, unit);
    out += &drift_text(d, unit);
    if let Some(rec) = &d.recommendation {
        let cv: Vec<String> = rec.cross_validation.iter().map(|(name, rms)| format!("{name} {rms:.4e}")).collect();
        out += &format!(
            "\nrecommended pipeline ({}-fold cross-validation on the training rows, RMS {unit}: {}): {}\n",
            rec.folds,
            cv.join(", "),
            rec.best
        );
        if rec.effects_hurt {
            out += "  => naming the effects makes the calibrated model worse out of sample: fit CbD on the nominal model (cbd fit without the written model)\n";
        }
    }
    out
}

/// The drift test's lines: found or not, its size, length and share of the floor, and advice.
fn drift_text(d: &Diagnosis, unit: &str) -> String {
    let Some(x) = &d.drift else {
        return "\ndrift in measurement order: not tested (too few poses)\n".into();
    };
    let test = format!(
        "log-likelihood ratio {:.1} nats, threshold {:.0}; first {} poses in file order, {} blocks",
        x.log_likelihood_ratio, x.threshold, x.poses, x.blocks
    );
    if x.detected {
        format!(
            "\ndrift in measurement order: found ({test})\n  sd {:.4e} {unit} per coordinate over {} (correlation exp(−lag/length)); \
             white noise {:.4e} {unit}; drift is {} of the noise floor's variance\n  => {}\n",
            x.sd,
            x.length_text(),
            x.noise_sd,
            percent(x.share_of_floor),
            x.advice()
        )
    } else {
        format!("\ndrift in measurement order: none ({test})\n")
    }
}

/// With several tool points per pose: each held-out row's mean error per tool point, of the tool
/// frame's origin and of its orientation; empty otherwise.
fn pose_table(d: &Diagnosis, unit: &str) -> String {
    use crate::evaluation::pose_errors::{pose_table, PoseTableLayout};
    let rows: Vec<_> = d.table.iter().map(|r| (r.name.as_str(), r.pose.as_ref())).collect();
    let heading = format!("held-out mean error per tool point and of the tool frame ({unit}; orientation in degrees)");
    pose_table(&heading, "model", &PoseTableLayout { indent: "  ", name_width: 26, number_width: 11 }, &rows)
}

/// `name (not significant: p = …)` or `name (lowers the CV RMS by only …)`.
fn dropped_text(d: &super::DroppedEffect) -> String {
    match d.reason {
        DropReason::NotSignificant => {
            format!("{} (within 3 standard errors of zero: p = {:.2e} > {})", d.name, d.p_value, super::SIGNIFICANCE)
        }
        DropReason::NoCrossValidatedGain => {
            format!("{} (added last it lowers the cross-validated RMS by {:.1} %)", d.name, 100.0 * d.cv_gain)
        }
        DropReason::ShapeOutsideLibrary => {
            format!("{} (its joint's deflection keeps a shape the library does not have: joint shape test p = {:.1e})", d.name, d.p_value)
        }
    }
}

fn effect_json(model: &NominalModel, f: &FoundEffect, units: &Units) -> Value {
    json!({
        "name": f.name,
        "type": f.kind.type_name(),
        "joint": f.joint.map(|j| j + 1),
        "harmonic": f.kind.harmonic(),
        "explains": f.partial_share,
        "share_in_selection_order": f.share,
        "cv_rms_after": f.cv_rms,
        "parameters": f.parameters.iter().map(|p| json!({
            "name": p.name, "value": shown(model, &p.param, p.value, units), "std_error": shown(model, &p.param, p.std_error, units),
            "unit": unit_of(model, &p.param, units),
        })).collect::<Vec<_>>(),
    })
}

/// The `--json` shape: `{found: [...], structure_before/after: [...], unexplained_structure,
/// selection: {...}, held_out: {name: {mean, median, p99, max}}, ...}`.
pub fn to_json(d: &Diagnosis, model: &NominalModel, units: &Units) -> Value {
    let tests = |t: &[super::structure::StructureTest]| -> Vec<Value> {
        t.iter()
            .map(|t| {
                json!({"name": t.name, "family": t.family, "joint": t.joint.map(|j| j + 1), "f": t.test.f, "df1": t.test.df1,
                       "df2": t.test.df2, "p_value": t.test.p_value, "explained": t.test.explained, "significant": t.significant})
            })
            .collect()
    };
    let mut held = serde_json::Map::new();
    for r in &d.table {
        let mut row = json!({"mean": r.stats.mean, "median": r.stats.median, "p99": r.stats.p99, "max": r.stats.max});
        if let Some(f) = &d.noise_floor {
            f.verdict(r.stats.mean, r.errors.len()).write_json(&mut row);
        }
        if !r.stats.mean.is_finite() {
            row["failed"] = json!(true);
        }
        if let Some(pose) = &r.pose {
            row["pose"] = pose.to_json();
        }
        held.insert(r.name.clone(), row);
    }
    json!({
        "unit": units.length,
        "angle_unit": units.angle.name(),
        "train_rows": d.train_rows,
        "test_rows": d.test_rows,
        "held_out_source": d.held_out,
        "found": d.found.iter().map(|f| effect_json(model, f, units)).collect::<Vec<_>>(),
        "physical_effects": d.physical_effects().len(),
        "dropped": d.dropped.iter().map(|x| json!({
            "name": x.name,
            "reason": match x.reason {
                DropReason::NotSignificant => "not significant",
                DropReason::NoCrossValidatedGain => "no cross-validated gain",
                DropReason::ShapeOutsideLibrary => "shape outside the library",
            },
            "p_value": x.p_value, "cv_gain": x.cv_gain,
        })).collect::<Vec<_>>(),
        "unexplained_structure": d.unexplained_structure,
        "structure_before": tests(&d.structure_before),
        "structure_after": tests(&d.structure_after),
        "selection": {"candidates": d.candidates, "margin": d.margin,
                      "best_refused": d.selection.best_refused.map(|(g, cv)| json!({"group": d.group_names[g], "cv_rms": cv})), "cv_rms_before": d.selection.cv_rms_before, "cv_rms_after": d.selection.cv_rms_after()},
        "held_out": held,
        "noise_floor": d.noise_floor,
        "drift": match &d.drift {
            Some(x) => {
                let mut v = serde_json::to_value(x).unwrap_or(Value::Null);
                v["tested"] = json!(true);
                v["advice"] = json!(x.advice());
                v
            }
            None => json!({"detected": false, "sd": null, "length": null, "tested": false}),
        },
        "recommendation": d.recommendation.as_ref().map(|r| json!({
            "best": r.best, "effects_hurt": r.effects_hurt, "folds": r.folds,
            "cross_validation": r.cross_validation.iter().map(|(n, e)| json!({"pipeline": n, "rms": e})).collect::<Vec<_>>(),
        })),
    })
}

/// `residual_vs_joint` figure: the norm of the training residual the geometric corrections leave
/// (the same model as the held-out "nominal + geometric" row) against each joint, in the file's
/// units (`joint_scale[j]` converts joint j from the model's radians or length unit), and over it
/// each joint effect's curve: the part of the residual that effect explains, i.e. its
/// displacement less what the geometric corrections absorb of it, as a norm averaged in bins of q_j.
pub fn plots(
    dir: &std::path::Path,
    d: &Diagnosis,
    model_start: &NominalModel,
    joint_names: &[String],
    joint_scale: &[f64],
    unit: &str,
) -> crate::Result<Vec<std::path::PathBuf>> {
    use super::library::{apply, jacobian};
    use crate::nominal::positions;
    use crate::numeric::least_squares::TruncatedSvd;
    let n = model_start.n_joints();
    let m = d.train.task_dim;
    let gp: Vec<Param> =
        d.found.iter().filter(|f| f.kind == GroupKind::Geometric).flat_map(|f| f.parameters.iter().map(|p| p.param)).collect();
    // The geometric corrections alone, as in the held-out "nominal + geometric" row.
    let geometric = d.model_geometric.clone();
    let before = positions(&geometric, &d.train.joints, m);
    let residual: Vec<f64> = before
        .chunks_exact(m)
        .zip(d.train.positions.chunks_exact(m))
        .map(|(k, y)| k.iter().zip(y).map(|(a, b)| (b - a).powi(2)).sum::<f64>().sqrt())
        .collect();
    // What the geometric parameters can absorb: their Jacobian at the geometric model.
    let absorb = if gp.is_empty() {
        None
    } else {
        let jac = jacobian(&geometric, &d.train, &gp);
        let svd = TruncatedSvd::unit_columns(jac.as_ref())?;
        Some((jac, svd))
    };
    let scale_of = |j: usize| joint_scale.get(j).copied().unwrap_or(1.0);
    let joints: Vec<f64> = d.train.joints.chunks_exact(n).flat_map(|q| q.iter().enumerate().map(|(j, v)| v * scale_of(j))).collect();
    let mut curves: Vec<EffectCurve> = Vec::new();
    for f in d.physical_effects() {
        let Some(j) = f.joint.filter(|&j| j < n) else { continue };
        // This effect's displacement at each row, less its least-squares fit by the geometric columns.
        let (p, v): (Vec<Param>, Vec<f64>) = f.parameters.iter().map(|p| (p.param, p.value)).unzip();
        let with = positions(&apply(&geometric, &p, &v)?, &d.train.joints, m);
        let mut shift: Vec<f64> = with.iter().zip(&before).map(|(a, b)| a - b).collect();
        if let Some((jac, svd)) = &absorb {
            let c = svd.solve(&shift, 1e-12);
            for (i, s) in shift.iter_mut().enumerate() {
                *s -= (0..c.len()).map(|k| jac[(i, k)] * c[k]).sum::<f64>();
            }
        }
        let bins = 48;
        let qs: Vec<f64> = joints.chunks_exact(n).map(|q| q[j]).collect();
        let (lo, hi) = qs.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
        let mut sum = vec![(0.0, 0usize); bins];
        for (i, q) in qs.iter().enumerate() {
            let b = (((q - lo) / (hi - lo).max(1e-12)) * bins as f64).min(bins as f64 - 1.0) as usize;
            sum[b].0 += shift[m * i..m * (i + 1)].iter().map(|s| s * s).sum::<f64>().sqrt();
            sum[b].1 += 1;
        }
        let curve = sum
            .iter()
            .enumerate()
            .filter(|(_, s)| s.1 > 0)
            .map(|(b, s)| (lo + (b as f64 + 0.5) * (hi - lo) / bins as f64, s.0 / s.1 as f64))
            .collect();
        curves.push((f.name.clone(), j, curve));
    }
    crate::report::plots::residual_vs_joint(
        dir,
        joint_names,
        &joints,
        &residual,
        &format!("residual norm after the geometric corrections ({unit})"),
        &curves,
    )
}
