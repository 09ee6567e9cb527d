//! The figures: written as PNG and SVG of the stated sizes, errors for bad inputs.

use super::chart::{bare_name, finite_range, linear_label, log_err, pow10_label, ERROR_FLOOR};
use super::heatmaps::bin_log_errors;
use super::*;
use crate::report::stats::median;
use plotters::style::RGBColor;
use std::path::{Path, PathBuf};

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("cbd-plots-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Width and height from a PNG's IHDR chunk, after checking the signature.
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap();
    assert!(bytes.len() > 33, "{}: too short", path.display());
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}: PNG signature", path.display());
    assert_eq!(&bytes[12..16], b"IHDR");
    let be = |i: usize| u32::from_be_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    assert_eq!(&bytes[bytes.len() - 8..bytes.len() - 4], b"IEND", "{}: IEND chunk", path.display());
    (be(16), be(20))
}

fn check_svg(path: &Path, must_contain: &[&str]) {
    let text = std::fs::read_to_string(path).unwrap();
    let t = text.trim();
    assert!(t.starts_with("<svg") || t.starts_with("<?xml"), "{}: starts with {:?}", path.display(), &t[..t.len().min(40)]);
    assert!(t.ends_with("</svg>"), "{}: does not close </svg>", path.display());
    assert_eq!(t.matches("<svg").count(), 1);
    for s in must_contain {
        assert!(text.contains(s), "{}: lacks {s:?}", path.display());
    }
}

fn check_pair(files: &[PathBuf], stem: &str, size: (u32, u32), svg_text: &[&str]) {
    assert_eq!(files.len(), 2, "{files:?}");
    assert!(files[0].ends_with(format!("{stem}.png")) && files[1].ends_with(format!("{stem}.svg")), "{files:?}");
    assert_eq!(png_size(&files[0]), size);
    check_svg(&files[1], svg_text);
}

/// Synthetic RR-like errors: about 0.1 before, about 1e-6 after, varying over the grid.
fn rr_like(grid: &[(f64, f64)]) -> (Vec<f64>, Vec<f64>) {
    let before = grid.iter().map(|&(a, b)| 0.1 + 0.05 * (a + 0.5 * b).sin()).collect();
    let after = grid.iter().map(|&(a, b)| 1e-6 * (1.5 + (3.0 * a).cos() * b.sin())).collect();
    (before, after)
}

#[test]
fn heatmaps_of_a_grid_are_written_as_png_and_svg() {
    let dir = tmp("heat");
    let grid = joint_grid(12, 0.0, 2.0 * std::f64::consts::PI);
    assert_eq!(grid.len(), 144);
    let (before, after) = rr_like(&grid);
    let files = error_heatmaps(&dir, "q1 (rad)", "q2 (rad)", &grid, &before, &after, 12, "length units").unwrap();
    check_pair(
        &files,
        "error_heatmaps",
        HEATMAP_SIZE,
        &["q1 (rad)", "Before calibration", "After calibration", "log10 position error (length units)"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn heatmap_bins_put_one_grid_point_per_cell_and_share_one_scale() {
    let grid = joint_grid(5, 0.0, 5.0);
    let errors: Vec<f64> = (0..25).map(|k| 10f64.powi(-(k as i32 % 5))).collect();
    let range = finite_range(grid.iter().map(|p| &p.0)).unwrap();
    assert_eq!(range, (0.0, 4.0));
    let bins = bin_log_errors(&grid, &errors, 5, range, range);
    for (k, b) in bins.iter().enumerate() {
        assert!((b - (-((k % 5) as f64))).abs() < 1e-12, "bin {k}: {b}");
    }
    // Scattered points: averaged in log space; empty cells NaN.
    let bins = bin_log_errors(&[(0.0, 0.0), (0.1, 0.0), (4.0, 4.0)], &[1e-2, 1e-4, 1.0], 5, range, range);
    assert!((bins[0] + 3.0).abs() < 1e-12 && bins[24].abs() < 1e-12 && bins[1].is_nan());
    // Exact zeros do not poison the scale.
    assert_eq!(log_err(0.0), ERROR_FLOOR.log10());
}

#[test]
fn heatmaps_reject_mismatched_inputs() {
    let dir = tmp("heat-bad");
    let grid = joint_grid(3, 0.0, 1.0);
    assert!(error_heatmaps(&dir, "a", "b", &grid, &[0.1; 9], &[0.1; 8], 3, "m").is_err());
    assert!(error_heatmaps(&dir, "a", "b", &[], &[], &[], 3, "m").is_err());
    assert!(workspace_grid(&dir, &[[0.0; 2]; 4], &[[0.0; 2]; 4], &[[0.0; 2]; 3], 2, false, "m").is_err());
    assert!(residual_vs_joint(&dir, &["q1".into()], &[0.0, 1.0], &[0.5], "r", &[]).is_err());
    assert!(method_comparison(&dir, &[], "m").is_err());
}

#[test]
fn workspace_histogram_comparison_residual_and_convergence_figures() {
    let dir = tmp("all");
    let n = 8;
    let grid = joint_grid(n, 0.0, 2.0 * std::f64::consts::PI);
    let fk = |l1: f64, l2: f64, dx: f64| -> Vec<[f64; 2]> {
        grid.iter().map(|&(a, b)| [dx + l1 * a.cos() + l2 * (a + b).cos(), l1 * a.sin() + l2 * (a + b).sin()]).collect()
    };
    let (nominal, real) = (fk(1.0, 0.5, 0.0), fk(1.1, 0.45, 0.02));
    let calibrated: Vec<[f64; 2]> = real.iter().map(|p| [p[0] + 1e-6, p[1]]).collect();
    let files = workspace_grid(&dir, &nominal, &real, &calibrated, n, true, "length units").unwrap();
    check_pair(&files, "workspace_grid", WORKSPACE_SIZE, &["nominal model", "calibrated model", "x (length units)"]);

    let before: Vec<f64> = nominal.iter().zip(&real).map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()).collect();
    let after: Vec<f64> = (0..before.len()).map(|i| 1e-6 * (1.0 + (i % 5) as f64)).collect();
    let files = error_histograms(&dir, &before, &after, "length units").unwrap();
    check_pair(&files, "error_histogram", HISTOGRAM_SIZE, &["before calibration", "after calibration", "log scale"]);

    let methods = vec![
        ("nominal".to_string(), before.clone()),
        ("krr".to_string(), after.iter().map(|e| e * 100.0).collect()),
        ("cbd".to_string(), after.clone()),
    ];
    let files = method_comparison(&dir, &methods, "mm").unwrap();
    check_pair(&files, "method_comparison", (COMPARISON_WIDTH, 150 + 70 * 3), &["nominal", "krr", "cbd", "median"]);

    let names = vec!["q1 (rad)".to_string(), "q2 (rad)".to_string(), "q3 (rad)".to_string()];
    let joints: Vec<f64> = (0..60).map(|i| (i as f64 * 0.7).sin() * 3.0).collect();
    let residuals: Vec<f64> = joints.chunks(3).map(|q| 0.2 * q[1].sin()).collect();
    let curve: Vec<(f64, f64)> = (0..50).map(|i| (-3.0 + 0.12 * i as f64, 0.2 * (-3.0 + 0.12 * i as f64).sin())).collect();
    let files = residual_vs_joint(&dir, &names, &joints, &residuals, "residual norm (mm)", &[("elbow gravity".into(), 1, curve)]).unwrap();
    check_pair(&files, "residual_vs_joint", (RESIDUAL_WIDTH, 40 + 420 * 2), &["elbow gravity", "residual norm (mm)"]);

    let log: Vec<(usize, f64, f64)> = (0..6).map(|i| (i, 10f64.powi(-(i as i32)), 0.1 * 10f64.powi(-(i as i32)))).collect();
    let files = convergence(&dir, &log, "length units").unwrap();
    check_pair(&files, "convergence", CONVERGENCE_SIZE, &["iteration", "RMS training error"]);
    let svg = convergence_svg(&log, "length units").unwrap();
    assert!(svg.contains("<svg") && svg.trim_end().ends_with("</svg>"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn demo_figures_from_planar_maps() {
    let dir = tmp("demo");
    let fk = |l1: f64, l2: f64| {
        move |q: &[f64]| -> crate::Result<Vec<f64>> {
            Ok(q.chunks_exact(2)
                .flat_map(|x| [l1 * x[0].cos() + l2 * (x[0] + x[1]).cos(), l1 * x[0].sin() + l2 * (x[0] + x[1]).sin()])
                .collect())
        }
    };
    let (nominal, real) = (fk(1.0, 0.5), fk(1.1, 0.45));
    let calibrated = |q: &[f64]| -> crate::Result<Vec<f64>> { Ok(fk(1.1, 0.45)(q)?.into_iter().map(|v| v + 1e-6).collect()) };
    let before = vec![0.1, 0.12, 0.08];
    let after = vec![1e-6, 2e-6, 3e-6];
    let inputs = DemoPlotInputs {
        nominal: &nominal,
        real: &real,
        calibrated: &calibrated,
        joint_labels: ["q1 (rad)", "q2 (rad)"],
        test_before: &before,
        test_after: &after,
        fit_log: &[(0, 1.0, 0.1), (1, 1e-3, 1e-4)],
        unit: "length units",
        heatmap_per_axis: 16,
        workspace_per_axis: 6,
    };
    let files = demo_figures(&dir, &inputs).unwrap();
    let names: Vec<String> = files.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    for stem in ["error_heatmaps", "workspace_grid", "error_histogram", "convergence"] {
        assert!(names.contains(&format!("{stem}.png")) && names.contains(&format!("{stem}.svg")), "{names:?}");
    }
    assert!(files.iter().all(|p| p.exists()));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn helpers() {
    assert_eq!(viridis(0.0), RGBColor(68, 1, 84));
    assert_eq!(viridis(1.0), RGBColor(253, 231, 37));
    assert_eq!(viridis(f64::NAN), viridis(0.0));
    assert_eq!(bare_name("q1 (rad)"), "q1");
    assert_eq!(linear_label(-5.55e-17, 0.6), "0");
    assert_eq!(linear_label(0.25, 0.6), "0.250");
    assert_eq!(pow10_label(&-3.0), "1e-3");
    assert_eq!(median(&[3.0, f64::NAN, 1.0, 2.0]), 2.0);
}

/// The real RR demo pipeline (simulate, fit, load the blob, evaluate) drawn to
/// `$CBD_PLOTS_DIR` (default: the temp dir's `cbd-rr-plots`), for looking at the figures:
/// `cargo test -p cbd-trainer --lib report::plots::tests::rr_demo_figures -- --ignored`.
#[test]
#[ignore = "fits the RR demo (seconds to minutes); run by hand to look at the figures"]
fn rr_demo_figures() {
    use crate::simulate::{configurations, rr, Sampling};
    let dir = std::env::var_os("CBD_PLOTS_DIR").map(PathBuf::from).unwrap_or_else(|| std::env::temp_dir().join("cbd-rr-plots"));
    let nominal_model = rr::nominal();
    let real_arm = rr::RealRr::default();
    let train = real_arm.measure(&configurations(Sampling::Grid { per_axis: 16 }, 2));
    let test = real_arm.measure(&configurations(Sampling::Uniform { count: 3000, seed: 2026 }, 2));
    let fit = crate::solver::fit_cbd(&nominal_model, &train, &crate::solver::CbdOptions::paper_rr()).unwrap();
    let nominal = |q: &[f64]| -> crate::Result<Vec<f64>> { Ok(crate::nominal::positions(&nominal_model, q, 2)) };
    let real = |q: &[f64]| -> crate::Result<Vec<f64>> { Ok(q.chunks_exact(2).flat_map(|x| real_arm.position(x)).collect()) };
    let calibrated = |q: &[f64]| crate::predict::evaluate_blob(&fit.blob, q);
    let test_before = position_errors(&nominal(&test.joints).unwrap(), &test.positions, 2);
    let test_after = position_errors(&calibrated(&test.joints).unwrap(), &test.positions, 2);
    let log: Vec<(usize, f64, f64)> = fit.report.log.iter().map(|r| (r.iteration, r.energy, r.train_rms)).collect();
    let inputs = DemoPlotInputs {
        nominal: &nominal,
        real: &real,
        calibrated: &calibrated,
        joint_labels: ["q1 (rad)", "q2 (rad)"],
        test_before: &test_before,
        test_after: &test_after,
        fit_log: &log,
        unit: "length units",
        heatmap_per_axis: 64,
        workspace_per_axis: 16,
    };
    let files = demo_figures(&dir, &inputs).unwrap();
    errln!("{} LM iterations; wrote {files:?}", fit.report.iterations);
}
