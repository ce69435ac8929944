//! The world-file loader on arbitrary text: it must return a world or an error naming a
//! line, never panic, hang or allocate without bound.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = hybridnav::world::parse_world(text, Path::new("fuzz.toml"));
    }
});
