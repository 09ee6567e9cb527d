//! `cbd report`: one self-contained HTML page for a calibration run, from the JSON written by
//! `cbd demo --json` (or `cbd compare --json`) and, optionally, the figures of `--plots DIR`; or,
//! with `--checks`, the history of a calibration's checks from the lines `cbd check --log` wrote.

use std::path::PathBuf;

#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("input").required(true).args(["json", "checks"])))]
pub struct ReportArgs {
    /// The run's JSON, as written by `cbd demo --json` or `cbd compare --json`.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// A check log, as `cbd check --log` appends it: the page draws its trend (mean error with the
    /// noise floor as a band, p with α, against time) and lists the checks.
    #[arg(long, conflicts_with = "plots")]
    pub checks: Option<PathBuf>,
    /// Directory of figures written by `--plots`; its PNGs are embedded in the page.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// Where to write the page (HTML).
    #[arg(long, default_value = "report.html")]
    pub out: PathBuf,
    /// Length unit of the errors, when the JSON (or the check log) does not name one.
    #[arg(long, default_value = "length units")]
    pub unit: String,
}

pub fn run(args: ReportArgs) -> crate::Result<()> {
    if let Some(log) = &args.checks {
        crate::io::check_paths(&[("--checks", Some(log))], &[("--out", Some(&args.out))])?;
        let n = crate::report::checks::write_checks_report(log, &args.out, &args.unit)?;
        outln!("report written to {} ({n} checks drawn)", args.out.display());
        return Ok(());
    }
    let json = args.json.as_ref().expect("clap requires --json or --checks");
    crate::io::check_paths(&[("--json", Some(json))], &[("--out", Some(&args.out))])?;
    let labels = crate::face::peers::labels(crate::face::peers::PEERS);
    let figures = crate::report::html::write_report(json, args.plots.as_deref(), &args.out, &args.unit, &labels)?;
    outln!("report written to {} ({figures} figures embedded)", args.out.display());
    Ok(())
}
