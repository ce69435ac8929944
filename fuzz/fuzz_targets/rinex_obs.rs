//! The RINEX observation reader on arbitrary bytes.
//! The body is `fuzz/entries.rs`, which the corpus replay test runs too.
#![no_main]
include!("../entries.rs");

libfuzzer_sys::fuzz_target!(|data: &[u8]| rinex_obs(data));
