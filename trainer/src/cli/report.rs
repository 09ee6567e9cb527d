//! `cbd report`: one self-contained HTML page for a calibration run, from the JSON written by
//! `cbd demo --json` (or `cbd compare --json`) and, optionally, the figures of `--plots DIR`.

use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// The run's JSON, as written by `cbd demo --json` or `cbd compare --json`.
    #[arg(long)]
    pub json: PathBuf,
    /// Directory of figures written by `--plots`; its PNGs are embedded in the page.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// Where to write the page (HTML).
    #[arg(long, default_value = "report.html")]
    pub out: PathBuf,
    /// Length unit of the errors, when the JSON does not name one (`unit` or `length_unit`).
    #[arg(long, default_value = "length units")]
    pub unit: String,
}

pub fn run(args: ReportArgs) -> crate::Result<()> {
    crate::io::check_paths(&[("--json", Some(&args.json))], &[("--out", Some(&args.out))])?;
    let labels = crate::cli::peers::labels(crate::cli::peers::PEERS);
    let figures = crate::report::html::write_report(&args.json, args.plots.as_deref(), &args.out, &args.unit, &labels)?;
    outln!("report written to {} ({figures} figures embedded)", args.out.display());
    Ok(())
}
