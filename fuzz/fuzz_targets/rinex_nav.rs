//! The RINEX 2/3 navigation reader (and the SP3 reader) on arbitrary text.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let _ = hybridnav::gnss::rinex_nav::parse_nav(&text, "fuzz.rnx");
    let _ = hybridnav::gnss::sp3::parse_sp3(&text, "fuzz.sp3");
});
