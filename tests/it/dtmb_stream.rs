//! `dtmb iq` streams its recordings frame by frame (issue 27 item 4): the files are
//! byte-identical to the ones the in-memory writer of main made (commit 081ed8a, SHA-256
//! recorded with that binary before the writer changed), their lengths follow from the
//! arguments alone, and the library's in-memory path (`generate_iq_with` + `write_sigmf`)
//! writes the same bytes as the streamed command.

use crate::common::{hybridnav, repo, skip, tmp_dir};
use std::path::Path;
use std::process::Command;

/// SHA-256 of a file by coreutils' `sha256sum` (an independent implementation).
fn sha256(path: &Path) -> Option<String> {
    let o = Command::new("sha256sum").arg(path).output().ok()?;
    o.status
        .success()
        .then(|| String::from_utf8_lossy(&o.stdout)[..64].to_string())
}

fn run(args: &[&str]) {
    let o = hybridnav(args);
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Recordings made by the streaming writer have the SHA-256 of the in-memory writer's
/// files for the same arguments: plain cf32 and ci8 (the ci8 scale needs the peak of the
/// whole recording: a first pass), SRRC-shaped at 2 and 3 samples per symbol (the filter
/// tail flushed after the last frame), and a world's tower (`--world`).
#[test]
fn dtmb_stream_recordings_equal_the_in_memory_writers() {
    if sha256(Path::new("Cargo.toml")).is_none() {
        skip("sha256sum (coreutils) is not available");
        return;
    }
    let dir = tmp_dir("dtmb-stream-sha");
    let kehui = repo().join("worlds/seed000-kehui.toml");
    let kehui = kehui.to_str().unwrap();
    // (base, arguments, SHA-256 of .sigmf-data, of .sigmf-meta) from main's binary.
    let cases: [(&str, Vec<&str>, &str, &str); 5] = [
        (
            "plain_cf32",
            vec!["--mode", "pn945", "--frames", "40", "--snr-db", "20"],
            "b29b0b3d5f7e04019b61ad068c5a587fe760375ec24c08f27daba37aee3ce3cc",
            "5ea55429ff2bb39ccc4db82d654d8c64210ef63cd2d362595a7fe1692b87c71e",
        ),
        (
            "plain_ci8",
            vec![
                "--mode", "pn420", "--frames", "40", "--snr-db", "15", "--format", "ci8", "--seed",
                "3",
            ],
            "9e5a38c8ebb01601b340999d52c16e5753913d15ae19f38e4034b3a436cef652",
            "338bd87fde53ed7f91212c63fa5220c7f5f8503fc052ebe3e1c4c9f3dd1e2e91",
        ),
        (
            "os3_ci8",
            vec![
                "--mode",
                "pn595",
                "--frames",
                "12",
                "--snr-db",
                "15",
                "--oversampling",
                "3",
                "--format",
                "ci8",
            ],
            "a731646b6bfb86560c067856172ffabcba6a7c856feb6c6339949af04b3a2f27",
            "b5d3be2cbac3f3b5195a8425caef577486ecb5666174ad51e6beb96fe595dfc8",
        ),
        (
            "os2_cf32",
            vec![
                "--mode",
                "pn945",
                "--frames",
                "30",
                "--snr-db",
                "25",
                "--oversampling",
                "2",
            ],
            "310d1401d6a7e260c3f8097fba57b362f78c7016207e164cbed4ae9f95b136e5",
            "23b2d3906fadf1c9b558caa5ca6e580cd9fbc9eeba61be56d1583b8a23349eb5",
        ),
        (
            "world_cf32",
            vec!["--world", kehui, "--from-s", "5", "--frames", "60"],
            // Compared with the in-memory recording below (its pin from main's binary
            // changed with ERP → EIRP, which moves every tower's SNR), and the meta names
            // the world file's path, so neither hash is pinned.
            "",
            "",
        ),
    ];
    for (name, args, data_sha, meta_sha) in cases {
        let base = dir.join(name);
        let mut a = vec!["dtmb", "iq"];
        a.extend(args.iter().copied());
        a.extend(["--out", base.to_str().unwrap()]);
        run(&a);
        let data = base.with_extension("sigmf-data");
        if data_sha.is_empty() {
            // The in-memory writer of a world's tower: every sample as cf32 little-endian.
            let w = hybridnav::world::load_world(Path::new(kehui)).unwrap();
            let req = hybridnav::world::dtmb_iq::WorldIqRequest {
                tower: None,
                from_s: 5.0,
                frames: 60,
                seed: w.file.montecarlo.seed,
                trial: 0,
                data_layer: Default::default(),
            };
            let rec = hybridnav::world::dtmb_iq::world_iq(&w, &req).unwrap();
            let bytes: Vec<u8> = rec
                .samples
                .iter()
                .flat_map(|c| [c.re.to_le_bytes(), c.im.to_le_bytes()])
                .flatten()
                .collect();
            assert!(std::fs::read(&data).unwrap() == bytes, "{name} data");
            continue;
        }
        assert_eq!(sha256(&data).unwrap(), data_sha, "{name} data");
        if !meta_sha.is_empty() {
            let meta = base.with_extension("sigmf-meta");
            assert_eq!(sha256(&meta).unwrap(), meta_sha, "{name} meta");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A recording with a payload through the whole transmitter (64QAM 0.6 M240): its data
/// file holds exactly `frames · N · L · bytes` bytes and one annotation per frame, and
/// the library's in-memory path writes the same two files byte for byte.
#[test]
fn dtmb_stream_length_follows_the_arguments_and_matches_the_library() {
    use hybridnav::dtmb::data_layer::data_layer_from_options;
    use hybridnav::dtmb::pn::PnMode;
    use hybridnav::dtmb::sigmf::{generate_iq_with, iq_sample_rate_hz, write_sigmf};
    use hybridnav::dtmb::SampleFormat;
    let dir = tmp_dir("dtmb-stream-len");
    let payload = dir.join("p.ts");
    let mut ts = Vec::new();
    for i in 0..500u32 {
        ts.extend_from_slice(&[0x47, 0x01, 0x00, 0x10 | (i % 16) as u8]);
        ts.extend((0..184u32).map(|j| (i.wrapping_mul(31) ^ j.wrapping_mul(7)) as u8));
    }
    std::fs::write(&payload, &ts).unwrap();
    let p = payload.to_str().unwrap();
    for (format, bytes, l) in [("cf32", 8u64, 1usize), ("ci8", 2, 2)] {
        let base = dir.join(format!("cli-{format}"));
        let frames = 180usize;
        run(&[
            "dtmb",
            "iq",
            "--mode",
            "pn420",
            "--frames",
            &frames.to_string(),
            "--snr-db",
            "22",
            "--payload",
            p,
            "--qam",
            "64qam",
            "--fec",
            "0.6",
            "--interleaver",
            "240",
            "--format",
            format,
            "--oversampling",
            &l.to_string(),
            "--seed",
            "9",
            "--out",
            base.to_str().unwrap(),
        ]);
        let len = std::fs::metadata(base.with_extension("sigmf-data"))
            .unwrap()
            .len();
        assert_eq!(len, frames as u64 * 4200 * l as u64 * bytes, "{format}");
        let meta: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(base.with_extension("sigmf-meta")).unwrap(),
        )
        .unwrap();
        assert_eq!(meta["annotations"].as_array().unwrap().len(), frames);
        // The in-memory path of the library.
        let layer = data_layer_from_options(
            Some(payload.as_path()),
            Some("64qam"),
            Some("0.6"),
            Some(240),
            None,
        )
        .unwrap();
        let (s, a) = generate_iq_with(PnMode::Pn420, frames, 22.0, l, 9, layer).unwrap();
        let mem = dir.join(format!("mem-{format}"));
        let fmt = if format == "ci8" {
            SampleFormat::Ci8
        } else {
            SampleFormat::Cf32
        };
        write_sigmf(&mem, &s, fmt, iq_sample_rate_hz(l), 482e6, &a).unwrap();
        for ext in ["sigmf-data", "sigmf-meta"] {
            assert!(
                std::fs::read(base.with_extension(ext)).unwrap()
                    == std::fs::read(mem.with_extension(ext)).unwrap(),
                "{format} {ext} differs between the streamed and the in-memory writer"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
