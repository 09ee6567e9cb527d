//! `cbd simulate`: measurements of a simulated "real" robot (`crate::face::simulate`), as CSV.

use crate::error::Result;
use crate::face::SimulateSettings;
use std::path::PathBuf;

// The files' flags keep their places in `--help` among the settings' (after --noise and --effect).
#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    #[command(flatten)]
    pub settings: SimulateSettings,
    /// Output CSV (columns q1, q2 in radians, x, y in length units).
    #[arg(long, display_order = 6)]
    pub out: PathBuf,
    /// Measure at these poses instead of sampling (`cbd plan --out`): a CSV with the robot's joint
    /// columns (rr: q1, q2 in radians; six: q1_deg … q6_deg), one pose per row; --sampling, --grid and
    /// --count are then ignored.
    #[arg(long, display_order = 7)]
    pub poses: Option<PathBuf>,
}

pub fn run(args: SimulateArgs) -> Result<()> {
    crate::io::check_paths(&[("--poses", args.poses.as_deref())], &[("--out", Some(&args.out))])?;
    let settings = &args.settings;
    // The flags are checked before the poses are read: a wrong flag is named first.
    settings.check(args.poses.is_some())?;
    let poses = match &args.poses {
        Some(path) => Some(crate::face::Dataset::read(path, &crate::face::poses_spec(&settings.robot))?.imported.measurements.joints),
        None => None,
    };
    let simulated = crate::face::simulate(settings, poses)?;
    crate::cli::write_atomically(&args.out, csv(&simulated).as_bytes())?;
    errln!("wrote {} to {}", simulated.what, args.out.display());
    Ok(())
}

/// The CSV text: every value in shortest round-trip form (read back, the same numbers).
fn csv(simulated: &crate::face::Simulated) -> String {
    let width = simulated.header.len().max(1);
    let mut text = simulated.header.join(",") + "\n";
    for row in simulated.values.chunks(width) {
        let fields: Vec<String> = row.iter().map(|v| format!("{v:?}")).collect();
        text.push_str(&(fields.join(",") + "\n"));
    }
    text
}
