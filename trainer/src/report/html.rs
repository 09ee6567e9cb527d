//! One self-contained HTML page per calibration run (`cbd report`): the run's inputs, chosen
//! hyperparameters, convergence, before/after error tables and the figures, from the JSON that
//! `cbd demo --json` or `cbd compare --json` wrote. Figures are embedded as base64 PNG (and the
//! convergence chart as inline SVG), so the page is one file with no links.

use serde_json::{Map, Value};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A PNG figure to embed: file stem (e.g. "error_heatmaps") and its bytes.
pub struct Figure {
    pub name: String,
    pub png: Vec<u8>,
}

/// Standard base64 (RFC 4648, with padding).
pub fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        out.push(ALPHABET[(n >> 18) as usize & 63] as char);
        out.push(ALPHABET[(n >> 12) as usize & 63] as char);
        out.push(if chunk.len() > 1 { ALPHABET[(n >> 6) as usize & 63] as char } else { '=' });
        out.push(if chunk.len() > 2 { ALPHABET[n as usize & 63] as char } else { '=' });
    }
    out
}

/// Escapes text for HTML element content and attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A number as a reader wants it: integers plainly, others with 4 significant digits.
fn num(v: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    if v == v.trunc() && v.abs() < 1e9 {
        return format!("{}", v as i64);
    }
    if v.abs() >= 1e-3 && v.abs() < 1e5 {
        let digits = (3 - v.abs().log10().floor() as i32).clamp(0, 6) as usize;
        format!("{v:.digits$}")
    } else {
        format!("{v:.3e}")
    }
}

fn value_text(v: &Value) -> String {
    match v {
        Value::Null => "—".into(),
        Value::Bool(b) => if *b { "yes" } else { "no" }.into(),
        Value::Number(n) => n.as_f64().map(num).unwrap_or_else(|| n.to_string()),
        Value::String(s) => s.clone(),
        Value::Array(a) => a.iter().map(value_text).collect::<Vec<_>>().join(", "),
        Value::Object(o) => o.iter().map(|(k, v)| format!("{k}: {}", value_text(v))).collect::<Vec<_>>().join("; "),
    }
}

fn field(v: &Value, key: &str) -> Option<f64> {
    v.get(key).and_then(Value::as_f64)
}

/// Whether `v` is an error-statistics object {mean, median, p99, max}.
fn is_stats(v: &Value) -> bool {
    ["mean", "median", "p99", "max"].iter().all(|k| field(v, k).is_some())
}

/// Reader-facing names of the peers' rows by key (`face::peers::labels`: `krr`, `dh+krr`, …).
pub type MethodLabels<'a> = &'a [(String, &'a str)];

/// Reader-facing names of the statistics keys: the bases' and the demo's here, the peers' from `labels`.
fn method_label(key: &str, labels: MethodLabels<'_>) -> String {
    let base = key.trim_end_matches("_grid");
    match base {
        "nominal" => "nominal model".into(),
        "calibrated" => "calibrated (CbD)".into(),
        "dh" => "DH parameter calibration".into(),
        other => labels.iter().find(|(k, _)| k == other).map_or_else(|| other.replace('_', " "), |(_, label)| label.to_string()),
    }
}

/// Orders rows: nominal first, then the rest in the given order.
fn nominal_first(mut keys: Vec<String>) -> Vec<String> {
    keys.sort_by_key(|k| k.trim_end_matches("_grid") != "nominal");
    keys
}

fn stats_table(out: &mut String, rows: &[(String, &Value)], unit: &str, extra: &[(&str, &str)], labels: MethodLabels<'_>) {
    let reference = rows.iter().find(|(k, _)| k.trim_end_matches("_grid") == "nominal").and_then(|(_, v)| field(v, "mean"));
    let _ = write!(out, "<table><tr><th>model</th><th>mean</th><th>median</th><th>p99</th><th>max</th>");
    if reference.is_some() {
        out.push_str("<th>orders of magnitude (mean)</th>");
    }
    for (_, title) in extra {
        let _ = write!(out, "<th>{}</th>", escape(title));
    }
    let _ = writeln!(out, "</tr>");
    for (key, v) in rows {
        let _ = write!(out, "<tr><td>{}</td>", escape(&method_label(key, labels)));
        for k in ["mean", "median", "p99", "max"] {
            let _ = write!(out, "<td class=num>{}</td>", field(v, k).map(num).unwrap_or_default());
        }
        if let Some(r) = reference {
            let gain = field(v, "mean").map(|m| (r / m).log10()).filter(|g| g.is_finite());
            let _ = write!(out, "<td class=num>{}</td>", gain.map(|g| format!("{g:.2}")).unwrap_or_default());
        }
        for (k, _) in extra {
            let _ = write!(out, "<td>{}</td>", v.get(*k).map(value_text).map(|s| escape(&s)).unwrap_or_default());
        }
        let _ = writeln!(out, "</tr>");
    }
    let _ = writeln!(out, "</table><p class=note>Position errors in {}.</p>", escape(unit));
}

fn key_value_table(out: &mut String, rows: &[(String, String)]) {
    if rows.is_empty() {
        return;
    }
    out.push_str("<table>");
    for (k, v) in rows {
        let _ = write!(out, "<tr><th>{}</th><td>{}</td></tr>", escape(k), escape(v));
    }
    out.push_str("</table>\n");
}

/// Captions of the figures `report::plots` writes.
fn figure_caption(name: &str) -> &str {
    match name {
        "error_heatmaps" => {
            "log10 position error over a grid of two joints, before (left) and after (right) calibration, on one colour scale."
        }
        "workspace_grid" => "Images of a joint grid in the workspace: nominal vs real arm (left), calibrated vs real arm (right).",
        "error_histogram" => "Distribution of the position error before and after calibration (log axis); vertical lines mark the medians.",
        "method_comparison" => "Error distribution of every method: box = quartiles, whiskers = 1st–99th percentile, cross = maximum.",
        "residual_vs_joint" => "Residual against each joint angle, with the curves of the effects found.",
        "convergence" => "Levenberg–Marquardt convergence: energy and RMS training error per iteration.",
        _ => "",
    }
}

pub(crate) const STYLE: &str =
    "body{font-family:system-ui,-apple-system,'DejaVu Sans',sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222}\
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2em}\
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left}\
th{background:#f3f3f3}td.num{text-align:right;font-variant-numeric:tabular-nums}\
.note{color:#666;font-size:.9em}figure{margin:1em 0}figure img,figure svg{max-width:100%;height:auto;border:1px solid #ddd}\
.headline{font-size:1.15em;background:#eef5ff;border-left:4px solid #1e64dc;padding:.6em 1em}\
details{margin:.5em 0}";

/// The page for a run: `json` as written by `cbd demo --json` or `cbd compare --json`, `source`
/// names it, `figures` are embedded in order, `unit` names the length unit of the errors, `labels`
/// the peers' rows.
pub fn render_report(json: &Value, source: &str, figures: &[Figure], unit: &str, labels: MethodLabels<'_>) -> crate::Result<String> {
    let top = json
        .as_object()
        .ok_or_else(|| crate::Error::Path { path: source.into(), reason: "expected a JSON object at the top level".into() })?;
    // Every field but a list is shown (in a table or section of its own): none, no page.
    if !top.iter().any(|(k, v)| !v.is_array() || k == "joint_widths") {
        return Err(crate::Error::Path {
            path: source.into(),
            reason:
                "nothing to report: the JSON object has no field a report shows (expected the --json of cbd demo, compare, eval or fit)"
                    .into(),
        });
    }
    let mut out = String::new();
    let kind = if top.contains_key("methods") { "method comparison" } else { "calibration run" };
    let _ = writeln!(
        out,
        "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8><meta name=viewport content=\"width=device-width,initial-scale=1\">\
         <title>cbd report — {}</title><style>{STYLE}</style></head><body>",
        escape(source)
    );
    let _ = writeln!(out, "<h1>Calibration by Diffeomorphisms — {kind} report</h1><p class=note>From <code>{}</code>.</p>", escape(source));

    // Headline: how far the error fell.
    if let (Some(n), Some(c)) = (top.get("nominal").filter(|v| is_stats(v)), top.get("calibrated").filter(|v| is_stats(v))) {
        let (nm, cm) = (field(n, "mean").unwrap_or(f64::NAN), field(c, "mean").unwrap_or(f64::NAN));
        let _ = writeln!(
            out,
            "<p class=headline>Mean position error on the test set: {} → {} {} ({:.2} orders of magnitude).</p>",
            num(nm),
            num(cm),
            escape(unit),
            (nm / cm).log10()
        );
    }

    // Inputs and hyperparameters: the scalar fields, then nested settings objects.
    let stats_keys: Vec<String> = top.iter().filter(|(_, v)| is_stats(v)).map(|(k, _)| k.clone()).collect();
    const HYPER: [&str; 8] = ["integrator", "steps", "sigma", "gamma", "task_width", "joint_b", "joint_widths", "noise"];
    let mut inputs = Vec::new();
    let mut hyper = Vec::new();
    for (k, v) in top {
        if stats_keys.contains(k) || matches!(v, Value::Object(_)) || (matches!(v, Value::Array(_)) && k != "joint_widths") {
            continue;
        }
        let row = (k.replace('_', " "), value_text(v));
        if HYPER.contains(&k.as_str()) {
            hyper.push(row);
        } else {
            inputs.push(row);
        }
    }
    for key in ["hyperparameters", "options", "solver", "kernel"] {
        if let Some(Value::Object(o)) = top.get(key) {
            for (k, v) in o {
                hyper.push((format!("{key}: {k}"), value_text(v)));
            }
        }
    }
    out.push_str("<h2>Run</h2>\n");
    key_value_table(&mut out, &inputs);
    if !hyper.is_empty() {
        out.push_str("<h2>Hyperparameters</h2>\n");
        key_value_table(&mut out, &hyper);
    }

    // Before/after tables.
    if !stats_keys.is_empty() {
        out.push_str("<h2>Position error before and after calibration</h2>\n");
        let test: Vec<String> = nominal_first(stats_keys.iter().filter(|k| !k.ends_with("_grid")).cloned().collect());
        let grid: Vec<String> = nominal_first(stats_keys.iter().filter(|k| k.ends_with("_grid")).cloned().collect());
        for (title, keys) in [("Test set", test), ("Training configurations", grid)] {
            if keys.is_empty() {
                continue;
            }
            let rows: Vec<(String, &Value)> = keys.iter().map(|k| (k.clone(), &top[k])).collect();
            let _ = writeln!(out, "<h3>{title}</h3>");
            stats_table(&mut out, &rows, unit, &[], labels);
        }
    }
    if let Some(Value::Object(methods)) = top.get("methods") {
        out.push_str("<h2>Methods compared on the test set</h2>\n");
        let keys = nominal_first(methods.keys().cloned().collect());
        let rows: Vec<(String, &Value)> = keys.iter().map(|k| (k.clone(), &methods[k])).collect();
        stats_table(&mut out, &rows, unit, &[("train_mean", "train mean"), ("fit_seconds", "fit [s]"), ("note", "note")], labels);
    }
    for (key, v) in top {
        if let Value::Object(o) = v {
            if ["fit", "methods", "hyperparameters", "options", "solver", "kernel"].contains(&key.as_str()) || is_stats(v) {
                continue;
            }
            let _ = writeln!(out, "<h2>{}</h2>", escape(&key.replace('_', " ")));
            let rows: Vec<(String, String)> = o.iter().map(|(k, v)| (k.replace('_', " "), value_text(v))).collect();
            key_value_table(&mut out, &rows);
        }
    }

    // Convergence.
    if let Some(fit) = top.get("fit").and_then(Value::as_object) {
        out.push_str("<h2>Convergence</h2>\n");
        convergence_section(&mut out, fit, unit)?;
    }

    // Figures.
    let figures: Vec<&Figure> = figures.iter().filter(|f| !(f.name == "convergence" && top.contains_key("fit"))).collect();
    if !figures.is_empty() {
        out.push_str("<h2>Figures</h2>\n");
        for f in figures {
            let caption = figure_caption(&f.name);
            let _ = writeln!(
                out,
                "<figure><img alt=\"{name}\" src=\"data:image/png;base64,{data}\"><figcaption>{name}{sep}{caption}</figcaption></figure>",
                name = escape(&f.name),
                data = base64(&f.png),
                sep = if caption.is_empty() { "" } else { ": " },
                caption = escape(caption),
            );
        }
    }
    out.push_str("</body></html>\n");
    Ok(out)
}

fn convergence_section(out: &mut String, fit: &Map<String, Value>, unit: &str) -> crate::Result<()> {
    let summary: Vec<(String, String)> = fit
        .iter()
        .filter(|(k, v)| *k != "log" && !matches!(v, Value::Array(_) | Value::Object(_)))
        .map(|(k, v)| (k.replace('_', " "), value_text(v)))
        .collect();
    key_value_table(out, &summary);
    let log: Vec<&Value> = fit.get("log").and_then(Value::as_array).map(|a| a.iter().collect()).unwrap_or_default();
    if log.is_empty() {
        return Ok(());
    }
    let points: Vec<(usize, f64, f64)> = log
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let it = r.get("iteration").and_then(Value::as_u64).map(|v| v as usize).unwrap_or(i);
            (it, field(r, "energy").unwrap_or(f64::NAN), field(r, "train_rms").unwrap_or(f64::NAN))
        })
        .collect();
    let svg = crate::report::plots::convergence_svg(&points, unit)?;
    let _ =
        writeln!(out, "<figure>{}<figcaption>{}</figcaption></figure>", strip_xml_declaration(&svg), escape(figure_caption("convergence")));
    let columns: Vec<String> = match log[0].as_object() {
        Some(o) => o.keys().cloned().collect(),
        None => return Ok(()),
    };
    let ordered: Vec<&String> = ["iteration", "energy", "train_rms"]
        .iter()
        .filter_map(|k| columns.iter().find(|c| c.as_str() == *k))
        .chain(columns.iter().filter(|c| !["iteration", "energy", "train_rms"].contains(&c.as_str())))
        .collect();
    let _ = write!(out, "<details open><summary>Per-iteration log ({} rows)</summary><table><tr>", log.len());
    for c in &ordered {
        let title = if c.as_str() == "train_rms" { format!("train RMS ({unit})") } else { c.replace('_', " ") };
        let _ = write!(out, "<th>{}</th>", escape(&title));
    }
    out.push_str("</tr>\n");
    for r in &log {
        out.push_str("<tr>");
        for c in &ordered {
            let v = r.get(c.as_str()).map(value_text).unwrap_or_default();
            let _ = write!(out, "<td class=num>{}</td>", escape(&v));
        }
        out.push_str("</tr>\n");
    }
    out.push_str("</table></details>\n");
    Ok(())
}

pub(crate) fn strip_xml_declaration(svg: &str) -> &str {
    let s = svg.trim_start();
    if s.starts_with("<?xml") {
        s.find("?>").map(|i| &s[i + 2..]).unwrap_or(s)
    } else {
        s
    }
}

/// Figure stems in the order the page shows them; other PNGs follow alphabetically.
const ORDER: [&str; 6] = ["error_heatmaps", "workspace_grid", "error_histogram", "method_comparison", "residual_vs_joint", "convergence"];

/// The PNGs in `dir`, in page order.
pub fn collect_figures(dir: &Path) -> crate::Result<Vec<Figure>> {
    let entries = std::fs::read_dir(dir).map_err(|e| crate::Error::io(dir, e))?;
    let mut paths: Vec<PathBuf> =
        entries.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png"))).collect();
    let rank = |p: &PathBuf| {
        let stem = p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        (ORDER.iter().position(|o| *o == stem).unwrap_or(ORDER.len()), stem)
    };
    paths.sort_by_key(rank);
    paths
        .into_iter()
        .map(|p| {
            crate::io::note_input("a figure of --plots", &p);
            let png = std::fs::read(&p).map_err(|e| crate::Error::io(&p, e))?;
            if !png.starts_with(b"\x89PNG\r\n\x1a\n") {
                return Err(crate::Error::Path { path: p, reason: "not a PNG file".into() });
            }
            Ok(Figure { name: p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(), png })
        })
        .collect()
}

/// `cbd report`: reads the run's JSON at `json`, embeds the PNGs of `plots`, writes the page to
/// `out`. The length unit is the JSON's `unit` / `length_unit` when present, else `unit`.
/// `labels` name the peers' rows. Returns the number of figures embedded.
pub fn write_report(json_path: &Path, plots: Option<&Path>, out: &Path, unit: &str, labels: MethodLabels<'_>) -> crate::Result<usize> {
    crate::io::note_input("--json", json_path);
    let text = std::fs::read_to_string(json_path).map_err(|e| crate::Error::io(json_path, e))?;
    let json: Value = serde_json::from_str(&text).map_err(|e| crate::Error::Json {
        path: json_path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        error: e,
    })?;
    let unit = ["unit", "length_unit"].iter().find_map(|k| json.get(*k).and_then(|v| v.as_str())).unwrap_or(unit).to_string();
    let figures = match plots {
        Some(dir) => collect_figures(dir)?,
        None => Vec::new(),
    };
    let page = render_report(&json, &json_path.display().to_string(), &figures, &unit, labels)?;
    crate::io::write_atomically(out, page.as_bytes())?;
    Ok(figures.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn labels() -> Vec<(String, &'static str)> {
        crate::face::peers::labels(crate::face::peers::PEERS)
    }

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (plain, coded) in
            [("", ""), ("f", "Zg=="), ("fo", "Zm8="), ("foo", "Zm9v"), ("foob", "Zm9vYg=="), ("fooba", "Zm9vYmE="), ("foobar", "Zm9vYmFy")]
        {
            assert_eq!(base64(plain.as_bytes()), coded);
        }
    }

    /// Issue 27 item 12: `report --json` on `{}` wrote an empty page with exit 0.
    #[test]
    fn an_object_with_nothing_to_show_is_refused() {
        for empty in [serde_json::json!({}), serde_json::json!({"log": [1, 2]})] {
            let e = render_report(&empty, "d.json", &[], "m", &labels()).unwrap_err().to_string();
            assert!(e.starts_with("d.json: nothing to report"), "{e}");
        }
        assert!(render_report(&serde_json::json!({"rows": 3}), "d.json", &[], "m", &labels()).is_ok());
    }

    #[test]
    fn escapes_markup() {
        assert_eq!(escape("<a href=\"x\">&'"), "&lt;a href=&quot;x&quot;&gt;&amp;&#39;");
    }

    #[test]
    fn numbers_read_well() {
        assert_eq!(num(256.0), "256");
        assert_eq!(num(0.1234567), "0.1235");
        assert_eq!(num(1.5e-6), "1.500e-6");
    }

    fn demo_json() -> serde_json::Value {
        let stats = |m: f64| serde_json::json!({"mean": m, "median": m * 0.9, "p99": m * 2.0, "max": m * 3.0});
        serde_json::json!({
            "nominal": stats(0.1), "calibrated": stats(1e-5), "krr": stats(1e-3),
            "nominal_grid": stats(0.1), "calibrated_grid": stats(1e-7), "krr_grid": stats(1e-9),
            "fit_seconds": 12.5, "krr_fit_seconds": 0.01, "iterations": 3, "blob_bytes": 9000,
            "max_runtime_trainer_diff": 1e-13, "n_train": 256, "n_test": 3000,
            "integrator": "heun", "steps": 5, "sigma": 1e-4,
            "fit": {"iterations": 3, "converged": true, "stop_reason": "gradient small", "seconds": 12.5,
                    "seconds_flow": 1.0, "seconds_tangent": 10.0, "seconds_solve": 1.5, "max_runtime_trainer_diff": 1e-13,
                    "log": [
                        {"iteration": 0, "energy": 1.0, "regulariser": 0.0, "train_rms": 0.1, "damping": 1e-3, "seconds": 0.1},
                        {"iteration": 1, "energy": 1e-3, "regulariser": 1e-4, "train_rms": 1e-3, "damping": 1e-4, "seconds": 4.0},
                        {"iteration": 2, "energy": 1e-6, "regulariser": 1e-4, "train_rms": 1e-5, "damping": 1e-5, "seconds": 8.0},
                        {"iteration": 3, "energy": 1e-9, "regulariser": 1e-4, "train_rms": 1e-7, "damping": 1e-6, "seconds": 12.0}]}
        })
    }

    #[test]
    fn report_of_a_demo_run_embeds_tables_log_and_figures() {
        let dir = std::env::temp_dir().join(format!("cbd-report-test-{}", std::process::id()));
        let plots = dir.join("plots");
        let before: Vec<f64> = (0..200).map(|i| 0.05 + 0.001 * i as f64).collect();
        let after: Vec<f64> = (0..200).map(|i| 1e-6 * (1.0 + (i % 7) as f64)).collect();
        crate::report::plots::error_histograms(&plots, &before, &after, "length units").unwrap();
        let json_path = dir.join("demo.json");
        std::fs::write(&json_path, serde_json::to_string_pretty(&demo_json()).unwrap()).unwrap();
        let out = dir.join("report.html");
        write_report(&json_path, Some(&plots), &out, "length units", &labels()).unwrap();
        let page = std::fs::read_to_string(&out).unwrap();
        assert!(page.starts_with("<!DOCTYPE html>") && page.trim_end().ends_with("</html>"));
        for needle in [
            "4.00 orders of magnitude",
            "calibrated (CbD)",
            "kernel ridge regression",
            "Training configurations",
            "heun",
            "gradient small",
            "Per-iteration log (4 rows)",
            "<svg",
            "data:image/png;base64,iVBORw0KGgo",
            "error_histogram",
        ] {
            assert!(page.contains(needle), "page lacks {needle:?}");
        }
        // Self-contained: no links to other files.
        assert!(!page.contains("src=\"file") && !page.contains("href="));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn report_of_a_comparison_lists_every_method() {
        let json = serde_json::json!({"methods": {
            "nominal": {"mean": 0.1, "median": 0.1, "p99": 0.2, "max": 0.3, "fit_seconds": 0.0, "train_mean": 0.1, "note": ""},
            "cbd": {"mean": 1e-4, "median": 1e-4, "p99": 2e-4, "max": 3e-4, "fit_seconds": 9.0, "train_mean": 1e-6, "note": "σ = 1e-4"},
            "dh": {"mean": 1e-2, "median": 1e-2, "p99": 2e-2, "max": 3e-2, "fit_seconds": 0.1, "train_mean": 1e-2, "note": "rank 20 <of 24>"}},
            "dh": {"iterations": 5, "rank": 20}, "hyperparameters": {"krr": null, "dh+krr": null}});
        let page = render_report(&json, "compare.json", &[], "mm", &labels()).unwrap();
        let nominal = page.find("nominal model").unwrap();
        assert!(page.find("calibrated (CbD)").unwrap() > nominal && page.contains("DH parameter calibration"));
        assert!(page.contains("rank 20 &lt;of 24&gt;"), "notes are escaped");
        assert!(page.contains("Position errors in mm"));
    }

    #[test]
    fn errors_name_the_file() {
        let dir = std::env::temp_dir().join(format!("cbd-report-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let bad = dir.join("bad.json");
        std::fs::write(&bad, "{\n  \"nominal\": ,\n}").unwrap();
        let err = write_report(&bad, None, &dir.join("r.html"), "m", &labels()).unwrap_err().to_string();
        assert!(err.contains("bad.json") && err.contains("line 2"), "{err}");
        let err = write_report(&dir.join("missing.json"), None, &dir.join("r.html"), "m", &labels()).unwrap_err().to_string();
        assert!(err.contains("missing.json"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Writes the page for `$CBD_REPORT_JSON` with the figures of `$CBD_PLOTS_DIR` to
    /// `$CBD_REPORT_OUT` (default: the temp dir's `cbd-report.html`), for looking at it.
    #[test]
    #[ignore = "reads a run's JSON named by the environment; run by hand"]
    fn report_of_a_named_run() {
        let Some(json) = std::env::var_os("CBD_REPORT_JSON") else { return };
        let plots = std::env::var_os("CBD_PLOTS_DIR").map(PathBuf::from);
        let out = std::env::var_os("CBD_REPORT_OUT").map(PathBuf::from).unwrap_or_else(|| std::env::temp_dir().join("cbd-report.html"));
        let n = write_report(Path::new(&json), plots.as_deref(), &out, "length units", &labels()).unwrap();
        errln!("wrote {} with {n} figures", out.display());
    }
}
