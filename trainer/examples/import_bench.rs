//! Import throughput of the measurement reader (issue 17 item 1: it was quadratic in rows).
//!
//!     cargo run --release -p cbd-trainer --example import_bench -- [ROWS ...]
//!
//! Writes a UR5-like CSV (six joints in degrees, positions in mm, 9 columns) of each size to a
//! temporary file, imports it with the UR5 example's column spec, and prints one Markdown table
//! row per size (rows, file MB, wall and CPU seconds of the import, rows per wall second, the
//! 1-minute load average: on shared cores the wall time stretches, the CPU time does not).
//! Default sizes: 10⁴, 10⁵, 10⁶.

use cbd_protocol::JointKind;
use cbd_trainer::data::csv_import::{default_joint_limits, read_measurements, ColumnSpec};
use cbd_trainer::data::model_file::{AngleUnit, LengthUnit};
use std::io::Write;
use std::time::Instant;

fn ur5_spec() -> ColumnSpec {
    let kinds = vec![JointKind::Revolute; 6];
    ColumnSpec {
        joint_columns: (1..=6).map(|i| format!("q{i}_deg")).collect(),
        position_columns: ["x_mm", "y_mm", "z_mm"].iter().map(|s| s.to_string()).collect(),
        joint_limits: default_joint_limits(&kinds),
        joint_kinds: kinds,
        angle_unit: AngleUnit::Deg,
        length_unit: LengthUnit::Mm,
        model_length_unit: LengthUnit::Mm,
        min_rows: 10,
        repeat_tolerance: None,
        joint_map: None,
        planar_frame: None,
        tool_points: Vec::new(),
        orientation_columns: None,
        order: cbd_trainer::data::RowOrder::Measured,
        range_hint: cbd_trainer::data::csv_import::RANGE_FROM_MODEL_FILE,
    }
}

/// A CSV of `rows` distinct configurations with full-precision values, as a tracker writes them.
fn write_csv(path: &std::path::Path, rows: usize) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(out, "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm")?;
    for i in 0..rows {
        let t = i as f64;
        let q: Vec<String> = (0..6).map(|d| format!("{:?}", 170.0 * (0.618_033_988_7 * t * (d + 1) as f64).sin())).collect();
        let y: Vec<String> = (0..3).map(|c| format!("{:?}", 800.0 * (0.414_213_562_3 * t + c as f64).cos())).collect();
        writeln!(out, "{},{}", q.join(","), y.join(","))?;
    }
    out.flush()
}

/// User + system CPU seconds of this process so far.
fn cpu_seconds() -> f64 {
    // SAFETY: getrusage fills the struct we own.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) } != 0 {
        return f64::NAN;
    }
    let t = |tv: libc::timeval| tv.tv_sec as f64 + tv.tv_usec as f64 * 1e-6;
    t(usage.ru_utime) + t(usage.ru_stime)
}

/// The 1-minute load average (Linux), or "?".
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|t| t.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "?".into())
}

fn main() {
    let sizes: Vec<usize> = std::env::args().skip(1).map(|a| a.parse().expect("ROWS must be a whole number")).collect();
    let sizes = if sizes.is_empty() { vec![10_000, 100_000, 1_000_000] } else { sizes };
    let path = std::env::temp_dir().join(format!("cbd-import-bench-{}.csv", std::process::id()));
    let spec = ur5_spec();
    println!("| rows | file MB | import wall s | import CPU s | rows/s (wall) | load average |");
    println!("|---:|---:|---:|---:|---:|---:|");
    for rows in sizes {
        write_csv(&path, rows).expect("write the CSV");
        let mb = std::fs::metadata(&path).map(|m| m.len() as f64 / 1e6).unwrap_or(f64::NAN);
        let (start, cpu_start) = (Instant::now(), cpu_seconds());
        let imported = read_measurements(&path, &spec).unwrap_or_else(|e| panic!("{e}"));
        let (seconds, cpu) = (start.elapsed().as_secs_f64(), cpu_seconds() - cpu_start);
        assert_eq!(imported.measurements.len(), rows);
        println!("| {rows} | {mb:.1} | {seconds:.2} | {cpu:.2} | {:.0} | {} |", rows as f64 / seconds, load_average());
    }
    let _ = std::fs::remove_file(&path);
}
