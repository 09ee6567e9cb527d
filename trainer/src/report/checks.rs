//! The history of a calibration on its controller (`cbd report --checks`, issue 50 item 6): the
//! lines `cbd check --log` appends, read back, drawn as a trend (mean error and p against time,
//! the noise floor as a band, α as a line) and listed as a table, in one self-contained page.

use super::html::{escape, strip_xml_declaration, STYLE};
use serde_json::Value;
use std::fmt::Write as _;
use std::path::Path;

/// One check as `cbd check --log` wrote it. Lines written before the floor and the named change
/// were logged carry only time, p, mean error and verdict: the rest is then `None` / empty.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckEntry {
    /// As written (ISO 8601 UTC, `2026-12-06T19:44:23Z`).
    pub time: String,
    /// Seconds since the Unix epoch.
    pub seconds: i64,
    pub verdict: String,
    pub p_value: f64,
    pub mean_error: f64,
    pub alpha: Option<f64>,
    pub statistic: Option<f64>,
    pub dof: Option<u64>,
    pub rows: Option<u64>,
    pub unit: Option<String>,
    /// A perfect model's mean error on these rows, and the largest mean error still at it.
    pub floor: Option<(f64, f64)>,
    /// The named changes' `describe`-like spellings: "joint_zero:joint=2 1.03e-4 ± 7.9e-6 rad".
    pub changes: Vec<String>,
    pub blob: Option<String>,
    pub data: Option<String>,
}

/// Days since 1970-01-01 of a civil date (Hinnant's `days_from_civil`).
fn days_from_civil(year: i64, month: i64, day: i64) -> i64 {
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (month + 9) % 12;
    let doy = (153 * mp + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// Seconds since the Unix epoch as ISO 8601 UTC (`2026-12-06T19:44:23Z`): days to a civil date by
/// Hinnant's `civil_from_days`.
pub fn utc_text(secs: i64) -> String {
    let (days, rest) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z", rest / 3600, rest % 3600 / 60, rest % 60)
}

/// `YYYY-MM-DDTHH:MM:SSZ` (a fraction of a second allowed and dropped) as seconds since the Unix
/// epoch; `None` for anything else.
pub fn parse_utc(text: &str) -> Option<i64> {
    let b = text.as_bytes();
    if b.len() < 20 || b[4] != b'-' || b[7] != b'-' || b[10] != b'T' || b[13] != b':' || b[16] != b':' || !text.ends_with('Z') {
        return None;
    }
    let fraction = &text[19..text.len() - 1];
    if !(fraction.is_empty() || (fraction.starts_with('.') && fraction.len() > 1 && fraction[1..].bytes().all(|c| c.is_ascii_digit()))) {
        return None;
    }
    let n = |r: std::ops::Range<usize>| -> Option<i64> {
        let s = &text[r];
        s.bytes().all(|c| c.is_ascii_digit()).then(|| s.parse().ok()).flatten()
    };
    let (year, month, day, hour, minute, second) = (n(0..4)?, n(5..7)?, n(8..10)?, n(11..13)?, n(14..16)?, n(17..19)?);
    let leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
    let month_days = [31, if leap { 29 } else { 28 }, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31];
    if !(1..=12).contains(&month) || day < 1 || day > month_days[month as usize - 1] || hour > 23 || minute > 59 || second > 60 {
        return None;
    }
    Some(days_from_civil(year, month, day) * 86_400 + hour * 3600 + minute * 60 + second)
}

/// One named change of a logged check, as a table cell shows it.
fn change_text(c: &Value) -> String {
    let effect = c.get("effect").and_then(Value::as_str).unwrap_or("?");
    let unit = c.get("unit").and_then(Value::as_str).filter(|u| !u.is_empty()).map(|u| format!(" {u}")).unwrap_or_default();
    match (c.get("size").and_then(Value::as_f64), c.get("se").and_then(Value::as_f64)) {
        (Some(size), Some(se)) => format!("{effect} {size:.3e} ± {se:.1e}{unit}"),
        (Some(size), None) => format!("{effect} {size:.3e}{unit}"),
        _ => effect.to_string(),
    }
}

/// One log line (`line` its 1-based number, for the error).
fn parse_line(path: &Path, line: usize, text: &str) -> crate::Result<CheckEntry> {
    let bad = |reason: String| crate::Error::InvalidInput(format!("{}:{line}: {reason}", path.display()));
    let v: Value = serde_json::from_str(text).map_err(|e| bad(format!("not a JSON object as `cbd check --log` writes: {e}")))?;
    if !v.is_object() {
        return Err(bad("not a JSON object as `cbd check --log` writes".into()));
    }
    let time = v.get("time").and_then(Value::as_str).ok_or_else(|| bad("no \"time\"".into()))?.to_string();
    let seconds = parse_utc(&time).ok_or_else(|| bad(format!("\"time\" {time:?} is not YYYY-MM-DDTHH:MM:SSZ")))?;
    let number = |key: &str| -> crate::Result<f64> {
        v.get(key).and_then(Value::as_f64).filter(|x| x.is_finite()).ok_or_else(|| bad(format!("no finite number \"{key}\"")))
    };
    let p_value = number("p_value")?;
    if !(0.0..=1.0).contains(&p_value) {
        return Err(bad(format!("\"p_value\" {p_value} is not between 0 and 1")));
    }
    let mean_error = number("mean_error")?;
    let verdict = match v.get("verdict").and_then(Value::as_str) {
        Some(s @ ("holds" | "changed")) => s.to_string(),
        _ => return Err(bad("\"verdict\" is not \"holds\" or \"changed\"".into())),
    };
    let opt = |key: &str| v.get(key).and_then(Value::as_f64).filter(|x| x.is_finite());
    let text_of = |key: &str| v.get(key).and_then(Value::as_str).map(str::to_string);
    let floor = match (opt("floor"), opt("floor_limit")) {
        (Some(f), Some(l)) => Some((f, l)),
        (Some(f), None) => Some((f, f)),
        _ => None,
    };
    let changes = v.get("changes").and_then(Value::as_array).map(|a| a.iter().map(change_text).collect()).unwrap_or_default();
    Ok(CheckEntry {
        time,
        seconds,
        verdict,
        p_value,
        mean_error,
        alpha: opt("alpha"),
        statistic: opt("statistic"),
        dof: v.get("dof").and_then(Value::as_u64),
        rows: v.get("rows").and_then(Value::as_u64),
        unit: text_of("unit"),
        floor,
        changes,
        blob: text_of("blob"),
        data: text_of("data"),
    })
}

/// The checks of a `cbd check --log` file, in the file's order (blank lines skipped). A line that
/// is not a check is an error naming the file and the line.
pub fn read_log(path: &Path) -> crate::Result<Vec<CheckEntry>> {
    crate::io::note_input("--checks", path);
    let text = std::fs::read_to_string(path).map_err(|e| crate::Error::io(path, e))?;
    let entries = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| parse_line(path, i + 1, l))
        .collect::<crate::Result<Vec<_>>>()?;
    if entries.is_empty() {
        return Err(crate::Error::InvalidInput(format!("{}: no checks (write them with `cbd check --log`)", path.display())));
    }
    Ok(entries)
}

fn sci(v: f64) -> String {
    format!("{v:.3e}")
}

/// A p-value as `cbd check` prints it: two decimals, or one significant digit below 0.01.
pub fn p_text(p: f64) -> String {
    if p >= 0.01 {
        format!("{p:.2}")
    } else {
        format!("{p:.0e}")
    }
}

/// The page: headline (the last check), the trend figure (inline SVG), the table of checks.
pub fn render_checks_report(entries: &[CheckEntry], source: &str, unit: &str) -> crate::Result<String> {
    let unit = entries.iter().rev().find_map(|e| e.unit.clone()).unwrap_or_else(|| unit.to_string());
    let mut out = String::new();
    let _ = writeln!(
        out,
        "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8><meta name=viewport content=\"width=device-width,initial-scale=1\">\
         <title>cbd report — {}</title><style>{STYLE}</style></head><body>",
        escape(source)
    );
    let _ = writeln!(
        out,
        "<h1>Calibration by Diffeomorphisms — check history</h1><p class=note>From <code>{}</code> ({} checks, written by <code>cbd check --log</code>).</p>",
        escape(source),
        entries.len()
    );
    let changed = entries.iter().filter(|e| e.verdict == "changed").count();
    if let Some(last) = entries.last() {
        let _ = writeln!(
            out,
            "<p class=headline>Last check {}: <b>{}</b> (p = {}), mean error {} {}{}. {} of {} checks changed.</p>",
            escape(&last.time),
            escape(&last.verdict),
            p_text(last.p_value),
            sci(last.mean_error),
            escape(&unit),
            last.floor.map(|(f, _)| format!(" ({:.2} × the noise floor)", last.mean_error / f)).unwrap_or_default(),
            changed,
            entries.len()
        );
    }
    out.push_str("<h2>Trend</h2>\n");
    let svg = crate::report::plots::check_history_svg(entries, &unit)?;
    let _ = writeln!(
        out,
        "<figure>{}<figcaption>check_history: mean error (left, log axis; band: the noise floor, from a perfect model's mean error to the largest still at it over the check's rows) and p (right, log axis; line: α) of every check against time; red: changed, blue: holds.</figcaption></figure>",
        strip_xml_declaration(&svg)
    );
    out.push_str("<h2>Checks</h2>\n<table><tr><th>#</th><th>time (UTC)</th><th>verdict</th><th>p</th><th>α</th><th>statistic / dof</th>");
    let _ = write!(out, "<th>rows</th><th>mean error ({})</th><th>/ floor</th><th>named change</th><th>data</th></tr>\n", escape(&unit));
    for (i, e) in entries.iter().enumerate() {
        let _ = write!(
            out,
            "<tr><td class=num>{}</td><td>{}</td><td>{}</td><td class=num>{}</td><td class=num>{}</td><td class=num>{}</td><td class=num>{}</td><td class=num>{}</td><td class=num>{}</td><td>{}</td><td>{}</td></tr>\n",
            i + 1,
            escape(&e.time),
            escape(&e.verdict),
            p_text(e.p_value),
            e.alpha.map(|a| format!("{a}")).unwrap_or_default(),
            match (e.statistic, e.dof) {
                (Some(s), Some(d)) => format!("{s:.2} / {d}"),
                _ => String::new(),
            },
            e.rows.map(|r| r.to_string()).unwrap_or_default(),
            sci(e.mean_error),
            e.floor.map(|(f, _)| format!("{:.2}", e.mean_error / f)).unwrap_or_default(),
            escape(&e.changes.join("; ")),
            escape(e.data.as_deref().unwrap_or("")),
        );
    }
    out.push_str("</table>\n</body></html>\n");
    Ok(out)
}

/// `cbd report --checks`: reads the log at `log`, writes the page to `out`. Returns the number of
/// checks drawn.
pub fn write_checks_report(log: &Path, out: &Path, unit: &str) -> crate::Result<usize> {
    let entries = read_log(log)?;
    let page = render_checks_report(&entries, &log.display().to_string(), unit)?;
    crate::io::write_atomically(out, page.as_bytes())?;
    Ok(entries.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(time: &str, verdict: &str, p: f64, mean: f64, changes: &str) -> String {
        format!(
            r#"{{"time":"{time}","blob":"arm.blob","data":"fresh.csv","p_value":{p},"mean_error":{mean},"verdict":"{verdict}","statistic":61.2,"dof":60,"alpha":0.01,"rows":20,"unit":"mm","floor":0.0319,"floor_limit":0.0391,"changes":[{changes}]}}"#
        )
    }

    #[test]
    fn times_round_trip_and_bad_ones_are_refused() {
        for secs in [0, 1_796_000_663, 951_782_400 /* 2000-02-29 */, 4_102_444_799] {
            assert_eq!(parse_utc(&utc_text(secs)), Some(secs), "{}", utc_text(secs));
        }
        assert_eq!(utc_text(1_796_585_063), "2026-12-06T19:24:23Z");
        assert_eq!(parse_utc("2026-12-06T19:24:23.25Z"), Some(1_796_585_063));
        for bad in [
            "2026-12-06 19:24:23Z",
            "2026-13-06T19:24:23Z",
            "2026-02-29T00:00:00Z",
            "2026-12-06T19:24:23",
            "yesterday",
            "2026-12-06T19:24:23.Z",
        ] {
            assert_eq!(parse_utc(bad), None, "{bad}");
        }
    }

    /// A log of three checks (an old line without the floor among them) is read in order, drawn
    /// (PNG and SVG written) and listed; a malformed line is an error naming the file and line.
    #[test]
    fn a_log_is_read_drawn_and_listed_and_a_bad_line_is_named() {
        let dir = std::env::temp_dir().join(format!("cbd-checks-report-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let log = dir.join("checks.jsonl");
        let old = r#"{"time":"2026-11-01T08:00:00Z","p_value":0.52,"mean_error":0.0683,"verdict":"holds"}"#;
        let text = [
            old.to_string(),
            String::new(),
            line("2026-11-20T08:00:00Z", "holds", 0.31, 0.033, ""),
            line(
                "2026-12-06T19:24:23Z",
                "changed",
                1e-22,
                0.21,
                r#"{"effect":"joint_zero:joint=2","size":1.03e-4,"se":7.9e-6,"unit":"rad","plant":"joint_zero:joint=2,offset=1.03e-4"}"#,
            ),
        ]
        .join("\n");
        std::fs::write(&log, text + "\n").unwrap();
        let entries = read_log(&log).unwrap();
        assert_eq!(entries.len(), 3);
        assert_eq!(entries[0].floor, None);
        assert_eq!(entries[2].verdict, "changed");
        assert_eq!(entries[2].floor, Some((0.0319, 0.0391)));
        assert_eq!(entries[2].changes, ["joint_zero:joint=2 1.030e-4 ± 7.9e-6 rad"]);
        assert!(entries[1].seconds > entries[0].seconds);

        let written = crate::report::plots::check_history(&dir.join("plots"), &entries, "mm").unwrap();
        assert_eq!(written.len(), 2);
        let png = std::fs::read(&written[0]).unwrap();
        assert!(png.starts_with(b"\x89PNG\r\n\x1a\n") && png.len() > 5000, "{} bytes", png.len());
        assert!(std::fs::read_to_string(&written[1]).unwrap().contains("<svg"));
        // For looking at it: CBD_HISTORY_PNG=path keeps a copy.
        if let Some(keep) = std::env::var_os("CBD_HISTORY_PNG") {
            std::fs::copy(&written[0], keep).unwrap();
        }

        let out = dir.join("report.html");
        assert_eq!(write_checks_report(&log, &out, "length units").unwrap(), 3);
        let page = std::fs::read_to_string(&out).unwrap();
        for needle in [
            "check history",
            "<svg",
            "2026-12-06T19:24:23Z",
            "joint_zero:joint=2 1.030e-4",
            "1 of 3 checks changed",
            "mean error (mm)",
            "6.58",
        ] {
            assert!(page.contains(needle), "page lacks {needle:?}");
        }
        assert_eq!(page.matches("<tr><td class=num>").count(), 3);

        // Malformed lines: the file and the line named.
        for (bad, needle) in [
            ("{\"time\": ", "not a JSON object"),
            ("[1, 2]", "not a JSON object"),
            (r#"{"time":"then","p_value":0.5,"mean_error":0.1,"verdict":"holds"}"#, "\"time\""),
            (r#"{"time":"2026-11-01T08:00:00Z","p_value":0.5,"verdict":"holds"}"#, "mean_error"),
            (r#"{"time":"2026-11-01T08:00:00Z","p_value":2,"mean_error":0.1,"verdict":"holds"}"#, "p_value"),
            (r#"{"time":"2026-11-01T08:00:00Z","p_value":0.5,"mean_error":0.1,"verdict":"fine"}"#, "verdict"),
        ] {
            std::fs::write(&log, format!("{old}\n{bad}\n")).unwrap();
            let e = read_log(&log).unwrap_err().to_string();
            assert!(e.contains(&format!("{}:2: ", log.display())) && e.contains(needle), "{e}");
        }
        std::fs::write(&log, "\n").unwrap();
        assert!(read_log(&log).unwrap_err().to_string().contains("no checks"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
