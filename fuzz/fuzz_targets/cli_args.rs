//! The command-line layer on arbitrary argument lists: clap parsing and then the
//! commands' own validation, for the commands that fail fast on bad arguments (nothing
//! that would run a simulation or write outside a temporary directory).
#![no_main]
use clap::Parser;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let mut args = vec!["hybridnav".to_string()];
    args.extend(text.split('\u{1f}').map(String::from));
    let Ok(cli) = hybridnav::cli::Cli::try_parse_from(&args) else {
        return;
    };
    // Only argument validation: `run`/`export`/`layout` are given a world that does not
    // exist, so they stop at loading it after checking their own options.
    use hybridnav::cli::Command;
    let _ = hybridnav::montecarlo::store::Shard::parse_with_env(
        match &cli.command {
            Command::Run(a) => a.shard.as_deref().unwrap_or("1/1"),
            _ => "1/1",
        },
        |_| None,
    );
    if let Command::Export(a) = &cli.command {
        let _ = hybridnav::export::Format::parse_list(&a.format);
    }
});
