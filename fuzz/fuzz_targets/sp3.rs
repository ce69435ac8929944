//! The SP3 precise-orbit reader on arbitrary text.
//! The body is `fuzz/entries.rs`, which the corpus replay test runs too.
#![no_main]
include!("../entries.rs");

libfuzzer_sys::fuzz_target!(|data: &[u8]| sp3(data));
