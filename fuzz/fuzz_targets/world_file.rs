//! The world-file loader on arbitrary text: it must return a world or an error naming a
//! line, never panic, hang or allocate without bound.
//! The body is `fuzz/entries.rs`, which the corpus replay test runs too.
#![no_main]
include!("../entries.rs");

libfuzzer_sys::fuzz_target!(|data: &[u8]| world_file(data));
