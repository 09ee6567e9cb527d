use clap::Parser;

fn main() {
    let cli = cbd_trainer::cli::Cli::parse();
    if let Err(message) = cbd_trainer::cli::run(cli) {
        eprintln!("error: {}", cbd_trainer::error::one_line(&message));
        std::process::exit(1);
    }
}
