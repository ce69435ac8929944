//! The content of the navigation messages beyond the ephemeris (subframes 4 and 5), checked
//! against an independent receiver: GNSS-SDR (Debian `gnss-sdr` 0.0.17) decodes hybridnav's
//! recordings and writes what it decoded as XML (`bds_dnav_utc_model.xml`), which is
//! compared field by field with what the world's navigation header makes the encoder send.

use crate::common::{hybridnav, repo, skip, stderr, tmp_dir};
use crate::gnss_iq::{bds_conf, xml_value, ESBC_NAV, ONE_RECEIVER, WORLD};
use hybridnav::core::GpsTime;
use std::path::{Path, PathBuf};
use std::process::Command;

/// `TIME SYSTEM CORR` lines added to the ESBC00DNK file's header, which has GPUT and GAUT
/// but neither BDUT nor GLUT: the a0/a1 of an IGS merged header of 2021 (as the `rinex`
/// crate's tests quote it), referred to the world's day, so that every offset of D1
/// subframe 5 page 9 is non-zero. They are the test's input, not a truth: the truth is
/// what the encoder derives from them (d1d2.rs, `BdsTimeParams`).
const TIME_LINES: &str = "\
BDUT  1.8626451492E-09-4.085620730E-14 345600  755          TIME SYSTEM CORR
GLUT -1.8626451492E-09 0.000000000E+00      0    0          TIME SYSTEM CORR
";
/// The file's LEAP SECONDS line and the full RINEX 3 form that replaces it, with the last
/// leap second (2016-12-31: GPS week 1929, day 7).
const LEAP_LINE: &str = "    18                                                      LEAP SECONDS";
const LEAP_FULL: &str = "    18    18  1929     7GPS                                 LEAP SECONDS";

/// The open-sky world with its navigation file's header extended by `extra` (inserted
/// before the LEAP SECONDS line, which becomes [`LEAP_FULL`]); returns the world's path.
fn world_with_header(dir: &Path, extra: &str) -> PathBuf {
    let nav_text = std::fs::read_to_string(repo().join(ESBC_NAV)).expect("navigation file");
    assert!(nav_text.contains(LEAP_LINE), "the file's LEAP SECONDS line");
    let nav_text = nav_text.replace(LEAP_LINE, &format!("{extra}{LEAP_FULL}"));
    let nav_path = dir.join("esbc-time.rnx");
    std::fs::write(&nav_path, nav_text).expect("write nav");
    let world = std::fs::read_to_string(repo().join(WORLD)).expect("world");
    let world = world.replace(
        &format!("\"../{ESBC_NAV}\""),
        &format!("{:?}", nav_path.to_str().expect("utf-8")),
    );
    assert!(world.contains("esbc-time.rnx"), "ephemeris line replaced");
    let path = dir.join("open-sky-time.toml");
    std::fs::write(&path, world).expect("write world");
    path
}

/// Records `world` on B1I from `from_s` for `duration_s` (ci8 at 4.2 Msps), runs GNSS-SDR
/// on it with [`bds_conf`] and returns its output directory and console log; `None` (after
/// the skip is reported) without GNSS-SDR.
fn bds_through_gnss_sdr(
    tag: &str,
    world: &Path,
    from_s: u32,
    duration_s: u32,
) -> Option<(PathBuf, String)> {
    if Command::new("gnss-sdr").arg("--version").output().is_err() {
        skip("gnss-sdr not installed (Debian package gnss-sdr; .ci/install-gnss-sdr)");
        return None;
    }
    let d = tmp_dir(tag);
    let base = d.join(tag);
    let rate = 4.2e6;
    let o = hybridnav(&[
        "gnss",
        "iq",
        world.to_str().expect("utf-8"),
        "--signal",
        "bds-b1i",
        "--from-s",
        &from_s.to_string(),
        "--duration-s",
        &duration_s.to_string(),
        "--rate-sps",
        &format!("{rate}"),
        "--format",
        "ci8",
        "--out",
        base.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "gnss iq failed: {}", stderr(&o));
    let file = |ext: &str| d.join(format!("{tag}.{ext}"));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(file("sigmf-meta")).expect("meta"))
            .expect("meta is JSON");
    let prns: Vec<u64> = meta["annotations"]
        .as_array()
        .expect("annotations")
        .iter()
        .map(|a| a["hybridnav:prn"].as_u64().expect("prn"))
        .collect();
    let _turn = ONE_RECEIVER.lock().unwrap_or_else(|e| e.into_inner());
    let conf = file("conf");
    std::fs::write(
        &conf,
        bds_conf(
            file("sigmf-data").to_str().expect("utf-8"),
            rate,
            d.to_str().expect("utf-8"),
            &prns,
        ),
    )
    .expect("write conf");
    let t0 = std::time::Instant::now();
    let run = Command::new("gnss-sdr")
        .arg(format!("--config_file={}", conf.display()))
        .arg(format!("--log_dir={}", d.display()))
        .current_dir(&d)
        .output()
        .expect("run gnss-sdr");
    eprintln!("{tag}: gnss-sdr took {:.1} s", t0.elapsed().as_secs_f64());
    // The samples are not needed any more (630 MB).
    let _ = std::fs::remove_file(file("sigmf-data"));
    Some((d, String::from_utf8_lossy(&run.stdout).into_owned()))
}

/// The world starts at 2020-06-25 02:00:18 GPST = 02:00:04 BDT, BDT week 755 second
/// 352 804 = 720·490 + 4: the D1 page rotation (`d1d2::d1_page`) starts page 1 there, so
/// page 9's subframe 5 is sent 260–266 s into the world and page 10's 290–296 s. A
/// recording from 225 s to 300 s carries both after ~35 s for acquisition and frame sync.
const FROM_S: u32 = 225;
const DURATION_S: u32 = 75;
const BDT_WEEK: i64 = 755;
const PAGE9_SF5_SOW: f64 = 353_064.0;
const PAGE10_SF5_SOW: f64 = 353_094.0;

/// D1 subframe 5 pages 9 and 10 through GNSS-SDR: it assembles its UTC model from a D1
/// satellite's two pages (`have_new_utc_model` needs both) and writes it to
/// `bds_dnav_utc_model.xml`; each field equals, to half its LSB, the value derived here from
/// the header lines with RINEX 3.05's `CORR = a0 + a1·(t − t_ref)` at the page's time.
/// GNSS-SDR 0.0.17 reads A0UTC wrongly (its `d1_subframe_decoder` sets A0UTC to
/// A0GPS·10⁻¹⁰ instead of scaling the A0UTC field) and never reads DN: those two are
/// printed, not compared (the unit test `d1_subframe_5_pages_9_and_10_carry_the_time_
/// parameters` decodes them with GNSSTk's bit positions).
#[test]
fn gnss_nav_bds_d1_time_pages_are_decoded_by_gnss_sdr() {
    let w = tmp_dir("nav-time-world");
    let world = world_with_header(&w, TIME_LINES);
    let Some((dir, log)) = bds_through_gnss_sdr("nav-time", &world, FROM_S, DURATION_S) else {
        return;
    };
    assert!(
        log.contains("utc model message received"),
        "no D1 page 9 + 10 pair decoded:\n{log}"
    );
    let xml = std::fs::read_to_string(dir.join("bds_dnav_utc_model.xml"))
        .unwrap_or_else(|e| panic!("bds_dnav_utc_model.xml: {e}\n{log}"));
    let got = |tag: &str| xml_value(&xml, tag).unwrap_or_else(|| panic!("{tag} in\n{xml}"));
    let bdt = |sow: f64| GpsTime::from_bdt_week_sow(BDT_WEEK, sow);
    // The header's corrections (the file's GPUT, GAUT and the added lines).
    let corr_gp = |t: GpsTime| {
        9.3132257462E-10
            + 2.664535259E-15 * t.seconds_since(GpsTime::from_week_tow(2111, 589_824.0))
    };
    let corr_ga = -9.3132257462E-10;
    let corr_bd = |t: GpsTime| 1.8626451492E-09 - 4.085620730E-14 * t.seconds_since(bdt(345_600.0));
    let corr_gl = -1.8626451492E-09;
    let t9 = bdt(PAGE9_SF5_SOW);
    let within = |name: &str, want: f64, lsb: f64| {
        let g = got(name);
        eprintln!("nav-time: {name}: sent {want:e}, GNSS-SDR {g:e}");
        assert!(
            (g - want).abs() <= 0.5 * lsb * (1.0 + 1e-6),
            "{name}: sent {want:e}, GNSS-SDR decoded {g:e}\n{xml}"
        );
    };
    within("A0_GPS", corr_bd(t9) - corr_gp(t9), 1e-10);
    within("A0_GAL", corr_bd(t9) - corr_ga, 1e-10);
    within("A0_GLO", corr_bd(t9) - corr_gl, 1e-10);
    // The drifts (~1e-14 s/s) are far below the fields' 0.1 ns/s LSB.
    for a1 in ["A1_GPS", "A1_GAL", "A1_GLO"] {
        within(a1, 0.0, 1e-10);
    }
    within("A1_UTC", -4.085620730E-14, 2f64.powi(-50));
    // ΔtLS = 18 − 14 (BDT − UTC); the announced leap: ΔtLSF = 18 − 14, WN_LSF = GPS week
    // 1929 − 1356 = 573, sent mod 256 (61, which GNSS-SDR reads as a signed byte).
    within("DeltaT_LS", 4.0, 1.0);
    within("DeltaT_LSF", 4.0, 1.0);
    within("WN_LSF", f64::from(573 % 256), 1.0);
    eprintln!(
        "nav-time: A0UTC sent {:e} (A0UTC + A1UTC·SOW = BDT − UTC − ΔtLS at page 10), \
         GNSS-SDR 0.0.17 reports A0_UTC {:e} (its A0GPS·1e-10) and DN {:?}",
        corr_bd(bdt(PAGE10_SF5_SOW)) + 4.085620730E-14 * PAGE10_SF5_SOW,
        got("A0_UTC"),
        xml_value(&xml, "DN")
    );
}
