// The entry points of the fuzz targets, one function per target, shared by
// `fuzz/fuzz_targets/*.rs` (libFuzzer, nightly) and by the corpus replay test
// (`tests/it/reliability.rs`, stable Rust, every CI run), which `include!` this file: a
// corpus input or a saved crash runs through exactly the code the fuzzer ran. Each
// function must return (an error is fine) — never panic, hang or allocate without bound.
// (Plain comments: an included file cannot carry inner doc comments.)

/// The world-file loader on arbitrary UTF-8.
pub fn world_file(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = hybridnav::world::parse_world(text, std::path::Path::new("fuzz.toml"));
    }
}

/// The RINEX 2/3 navigation reader on arbitrary text.
pub fn rinex_nav(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let _ = hybridnav::gnss::rinex_nav::parse_nav(&text, "fuzz.rnx");
}

/// The SP3 reader on arbitrary text.
pub fn sp3(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let _ = hybridnav::gnss::sp3::parse_sp3(&text, "fuzz.sp3");
}

/// The layout candidates reader (CSV, streamed) on arbitrary bytes.
pub fn layout_candidates(data: &[u8]) {
    let region = hybridnav::layout::grid::Region {
        west_m: -1000.0,
        south_m: -1000.0,
        east_m: 1000.0,
        north_m: 1000.0,
    };
    let _ = hybridnav::layout::place::parse_candidates_from(data, "fuzz.csv", &region);
}

/// The SigMF reader or the FM fingerprint-database reader, chosen by the first byte; the
/// rest is split at the first NUL into the metadata and the data file (SigMF) or taken
/// whole (the database JSON). Files go to a directory of this process under the system's
/// temporary directory.
pub fn sigmf_fmdb(data: &[u8]) {
    let Some((&which, rest)) = data.split_first() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("hybridnav-fuzz-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let write = |name: &str, bytes: &[u8]| {
        std::fs::write(dir.join(name), bytes).expect("temp write");
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
}

/// The command-line layer on argument lists split at U+001F: clap parsing, then the
/// validation of `--shard`, `--format` and `--outputs` (nothing that runs a simulation or
/// writes a file).
pub fn cli_args(data: &[u8]) {
    use clap::Parser;
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let mut args = vec!["hybridnav".to_string()];
    args.extend(text.split('\u{1f}').map(String::from));
    let Ok(cli) = hybridnav::cli::Cli::try_parse_from(&args) else {
        return;
    };
    use hybridnav::cli::Command;
    if let Command::Run(a) = &cli.command {
        let _ = hybridnav::montecarlo::store::Shard::parse_with_env(
            a.shard.as_deref().unwrap_or("1/1"),
            |_| None,
        );
        let _ = hybridnav::montecarlo::OutputSet::parse(&a.outputs);
    }
    if let Command::Export(a) = &cli.command {
        let _ = hybridnav::export::Format::parse_list(&a.format);
    }
}

/// The transport-stream payload reader (`dtmb iq --payload`): the file check, then every
/// packet read until the stream turns to null packets. The file goes to a directory of
/// this process under the system's temporary directory.
pub fn ts_payload(data: &[u8]) {
    let dir = std::env::temp_dir().join(format!("hybridnav-fuzz-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let path = dir.join("payload.ts");
    std::fs::write(&path, data).expect("temp write");
    let Ok(mut source) = hybridnav::dtmb::ts::PacketSource::from_file(&path) else {
        return;
    };
    let mut packet = [0u8; 188];
    // A checked file holds at most data.len() / 188 packets: one more read must give the
    // first null packet.
    for _ in 0..=data.len() / 188 {
        if source.next_packet(&mut packet).is_err() || source.null_packets() > 0 {
            break;
        }
    }
    assert!(
        source.payload_packets() as usize <= data.len() / 188,
        "more packets than the file holds"
    );
}

/// The RINEX 2/3 observation reader on arbitrary bytes: the header, then every epoch,
/// checking that each satellite holds exactly the values its system's types announce.
pub fn rinex_obs(data: &[u8]) {
    let _ = hybridnav::gnss::rinex_obs::read_all(data, "fuzz.obs", |header, epoch| {
        for (k, (sat, values)) in epoch.iter().enumerate() {
            let n_types = header.obs_types(sat.system).map_or(0, <[String]>::len);
            assert_eq!(values.len(), n_types, "satellite {k} ({sat})");
        }
    });
}
