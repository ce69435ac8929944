//! The command-line layer on arbitrary argument lists (split at U+001F).
//! The body is `fuzz/entries.rs`, which the corpus replay test runs too.
#![no_main]
include!("../entries.rs");

libfuzzer_sys::fuzz_target!(|data: &[u8]| cli_args(data));
