//! `cbd simulate`: measurements of a simulated "real" robot, as CSV.

use crate::simulate::{add_noise, configurations, rr, Sampling};
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// Which robot: `rr` (the paper's planar arm).
    #[arg(long, default_value = "rr")]
    pub robot: String,
    /// `grid` (per-axis points given by --grid) or `uniform` (--count random configurations).
    #[arg(long, default_value = "grid")]
    pub sampling: String,
    #[arg(long, default_value_t = 16)]
    pub grid: usize,
    #[arg(long, default_value_t = 3000)]
    pub count: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Standard deviation of Gaussian noise added to the measured positions.
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    /// Output CSV (columns q1, q2 in radians, x, y in length units).
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: SimulateArgs) -> Result<(), String> {
    if args.robot != "rr" {
        return Err(format!("unknown robot `{}` (expected rr)", args.robot));
    }
    if !(args.noise >= 0.0 && args.noise.is_finite()) {
        return Err(format!("--noise must be a finite non-negative number, got {}", args.noise));
    }
    let sampling = match args.sampling.as_str() {
        "grid" => Sampling::Grid { per_axis: args.grid },
        "uniform" => Sampling::Uniform { count: args.count, seed: args.seed },
        other => return Err(format!("unknown sampling `{other}` (expected grid or uniform)")),
    };
    let mut data = rr::RealRr::default().measure(&configurations(sampling, 2));
    add_noise(&mut data.positions, args.noise, args.seed.wrapping_add(0x5eed));
    let mut text = String::from("q1,q2,x,y\n");
    for i in 0..data.len() {
        let (q, y) = (data.joints(i), data.position(i));
        text.push_str(&format!("{:?},{:?},{:?},{:?}\n", q[0], q[1], y[0], y[1]));
    }
    crate::cli::write_atomically(&args.out, text.as_bytes())?;
    eprintln!("wrote {} measurements to {}", data.len(), args.out.display());
    Ok(())
}
