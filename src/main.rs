//! The `hybridnav` binary: parse, run, map errors to exit codes.

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = hybridnav::cli::Cli::parse();
    match hybridnav::cli::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::from(2)
        }
    }
}
