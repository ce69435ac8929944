//! The SigMF reader and the FM fingerprint-database reader on arbitrary files. The first
//! byte chooses the reader; the rest is split at the first NUL into the metadata and the
//! data file (SigMF) or taken whole (the database JSON).
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::io::Write;

fuzz_target!(|data: &[u8]| {
    let Some((&which, rest)) = data.split_first() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("hybridnav-fuzz-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let write = |name: &str, bytes: &[u8]| {
        let mut f = std::fs::File::create(dir.join(name)).expect("temp file");
        f.write_all(bytes).expect("temp write");
    };
    if which % 2 == 0 {
        let (meta, samples) = match rest.iter().position(|&b| b == 0) {
            Some(k) => (&rest[..k], &rest[k + 1..]),
            None => (rest, &[][..]),
        };
        write("r.sigmf-meta", meta);
        write("r.sigmf-data", samples);
        let _ = hybridnav::dtmb::sigmf::read_sigmf(&dir.join("r"));
    } else {
        write("db.json", rest);
        let frame =
            hybridnav::core::EnuFrame::new(hybridnav::core::Geodetic::from_deg(40.0, 116.0, 0.0));
        let tag = hybridnav::fm::database::WorldTag::new("fuzz", &frame, None);
        let _ = hybridnav::fm::database::FingerprintDb::load(&dir.join("db.json"), &tag);
    }
});
