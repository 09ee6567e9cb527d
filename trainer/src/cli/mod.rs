//! The `cbd` command line: one file per command.

use clap::{Parser, Subcommand};

#[derive(Debug, Parser)]
#[command(name = "cbd", version, about = "Calibration by Diffeomorphisms: train, evaluate and compare calibrated robot models")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {}

/// Runs a parsed command; errors are printed by `main` with exit code 1.
pub fn run(cli: Cli) -> Result<(), String> {
    match cli.command {}
}
