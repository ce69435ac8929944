//! The SigMF reader and the FM fingerprint-database reader on arbitrary files (the first
//! byte chooses the reader).
//! The body is `fuzz/entries.rs`, which the corpus replay test runs too.
#![no_main]
include!("../entries.rs");

libfuzzer_sys::fuzz_target!(|data: &[u8]| sigmf_fmdb(data));
