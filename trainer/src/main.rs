use clap::Parser;

fn main() {
    // A usage error (unknown flag, missing or mistyped value): clap prints the usage, exit code 2.
    let cli = cbd_trainer::cli::Cli::parse();
    cbd_trainer::cli::configure_allocator();
    if let Err(e) = cbd_trainer::cli::run(cli) {
        cbd_trainer::errln!("error: {}", cbd_trainer::error::one_line(&e.to_string()));
        std::process::exit(1);
    }
    // A command that succeeded may still answer with its code (`cbd check`: 3 when changed).
    let code = cbd_trainer::cli::exit_code();
    if code != 0 {
        std::process::exit(code);
    }
}
