//! The `hybridnav` binary: parse, run, map errors to exit codes.

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = hybridnav::cli::Cli::parse();
    match hybridnav::cli::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", message(&e));
            std::process::ExitCode::from(2)
        }
    }
}

/// The error and its causes as one line, `outer: cause: …`, each text once: an error
/// whose message already quotes its source (`FILE: cannot read: No such file (os error
/// 2)`, with that OS error as its source) would otherwise print the OS error twice.
fn message(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if text.is_empty() || out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}
