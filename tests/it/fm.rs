//! FM fingerprinting (seed 000 §3.2, §4.1): kriging against PyKrige and against a known
//! covariance, WKNN accuracy against RP density and the GPS constraint on a Beihang-like
//! setup, the fingerprint database file, bad inputs, and the `"fm"` source.

use hybridnav::core::{EnuFrame, Geodetic, GpsTime, SimTime, TrialRng};
use hybridnav::fm::database::{build_kriged, ChannelInfo};
use hybridnav::fm::field::synthesize_stations;
use hybridnav::fm::kriging::{empirical_variogram, fit_variogram, FitOptions};
use hybridnav::fm::wknn::locate;
use hybridnav::fm::*;
use hybridnav::measurement::{
    Estimate, Measurement, MeasurementBatch, SampleContext, Source, Truth,
};
use hybridnav::motion::TruthState;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;
use std::sync::Arc;

// ---------------------------------------------------------------------------------------
// Kriging vs PyKrige

fn pykrige_script() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/pykrige_crosscheck.py")
}

/// Runs PyKrige; `None` (with the reason printed) when python3 or PyKrige is missing.
fn pykrige(
    xy: &[[f64; 2]],
    z: &[f64],
    pts: &[[f64; 2]],
    m: &VariogramModel,
) -> Option<(Vec<f64>, Vec<f64>)> {
    let problem = serde_json::json!({
        "x": xy.iter().map(|p| p[0]).collect::<Vec<_>>(),
        "y": xy.iter().map(|p| p[1]).collect::<Vec<_>>(),
        "z": z,
        "xp": pts.iter().map(|p| p[0]).collect::<Vec<_>>(),
        "yp": pts.iter().map(|p| p[1]).collect::<Vec<_>>(),
        "model": match m.kind { VariogramKind::Spherical => "spherical", VariogramKind::Exponential => "exponential" },
        "psill": m.psill, "range": m.range_m, "nugget": m.nugget,
    });
    let dir = std::env::temp_dir().join(format!(
        "hybridnav_pykrige_{}_{:?}",
        std::process::id(),
        m.kind
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let (inp, out) = (dir.join("in.json"), dir.join("out.json"));
    std::fs::write(&inp, problem.to_string()).unwrap();
    match std::process::Command::new("python3")
        .arg(pykrige_script())
        .arg(&inp)
        .arg(&out)
        .status()
    {
        Ok(s) if s.success() => {}
        Ok(s) if s.code() == Some(3) => {
            println!(
                "SKIP: PyKrige is not installed (pip install pykrige) — kriging not cross-checked"
            );
            return None;
        }
        Ok(s) => panic!("the PyKrige script failed: {s}"),
        Err(_) => {
            println!("SKIP: python3 not found — kriging not cross-checked against PyKrige");
            return None;
        }
    }
    let res: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let col = |k: &str| {
        res[k]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect::<Vec<_>>()
    };
    Some((col("z"), col("ss")))
}

#[test]
fn ordinary_kriging_matches_pykrige() {
    let mut rng = TrialRng::new(21, 0).stream("test/fm/pykrige");
    let xy: Vec<[f64; 2]> = (0..150)
        .map(|_| [rng.random::<f64>() * 380.0, rng.random::<f64>() * 380.0])
        .collect();
    let z: Vec<f64> = xy
        .iter()
        .map(|p| {
            -65.0
                + 6.0 * (p[0] / 55.0).sin() * (p[1] / 80.0).cos()
                + 2.0 * rng.sample::<f64, _>(StandardNormal)
        })
        .collect();
    // Prediction points: random points, points outside the data hull, and 10 data points
    // (exactness, where PyKrige's zero-distance rule applies).
    let mut pts: Vec<[f64; 2]> = (0..300)
        .map(|_| {
            [
                rng.random::<f64>() * 450.0 - 35.0,
                rng.random::<f64>() * 450.0 - 35.0,
            ]
        })
        .collect();
    pts.extend_from_slice(&xy[..10]);
    for m in [
        VariogramModel {
            kind: VariogramKind::Spherical,
            nugget: 1.3,
            psill: 17.0,
            range_m: 120.0,
        },
        VariogramModel {
            kind: VariogramKind::Exponential,
            nugget: 0.7,
            psill: 20.0,
            range_m: 150.0,
        },
    ] {
        let Some((zp, ssp)) = pykrige(&xy, &z, &pts, &m) else {
            return;
        };
        let ok = OrdinaryKriging::new(&xy, &z, m).unwrap();
        let (mut dz, mut dss) = (0.0f64, 0.0f64);
        for (i, p) in pts.iter().enumerate() {
            let (zr, ssr) = ok.predict_with_variance(*p);
            dz = dz.max((zr - zp[i]).abs() / zp[i].abs());
            // Variances are compared relative to the sill (they are 0 at the data points).
            dss = dss.max((ssr - ssp[i]).abs() / m.sill());
        }
        println!("PyKrige {:?}: largest relative difference {dz:.2e} (prediction), {dss:.2e} (variance / sill) over {} points", m.kind, pts.len());
        assert!(dz < 1e-6 && dss < 1e-6, "{:?}: {dz} {dss}", m.kind);
    }
}

// ---------------------------------------------------------------------------------------
// Variogram fit vs a known covariance

/// One realisation of a Gaussian field with variogram `m` at `xy` (Cholesky of the
/// covariance C(h) = sill − γ(h), nugget as white noise).
fn simulate(xy: &[[f64; 2]], m: &VariogramModel, rng: &mut hybridnav::core::StreamRng) -> Vec<f64> {
    let n = xy.len();
    let cont = VariogramModel { nugget: 0.0, ..*m };
    let c = DMatrix::from_fn(n, n, |i, j| {
        let h = ((xy[i][0] - xy[j][0]).powi(2) + (xy[i][1] - xy[j][1]).powi(2)).sqrt();
        m.psill - cont.gamma(h) + if i == j { 1e-9 } else { 0.0 }
    });
    let l = c.cholesky().expect("covariance is positive definite").l();
    let e = DVector::from_fn(n, |_, _| rng.sample::<f64, _>(StandardNormal));
    let f = l * e;
    (0..n)
        .map(|i| f[i] + m.nugget.sqrt() * rng.sample::<f64, _>(StandardNormal))
        .collect()
}

#[test]
fn variogram_fit_recovers_simulated_parameters() {
    for truth in [
        VariogramModel {
            kind: VariogramKind::Exponential,
            nugget: 2.0,
            psill: 16.0,
            range_m: 150.0,
        },
        VariogramModel {
            kind: VariogramKind::Spherical,
            nugget: 1.0,
            psill: 12.0,
            range_m: 120.0,
        },
    ] {
        let mut rng = TrialRng::new(33, 0).stream(&format!("test/fm/variogram/{:?}", truth.kind));
        let (mut ranges, mut sills, mut nuggets) = (vec![], vec![], vec![]);
        for _ in 0..7 {
            let xy: Vec<[f64; 2]> = (0..700)
                .map(|_| [rng.random::<f64>() * 700.0, rng.random::<f64>() * 700.0])
                .collect();
            let z = simulate(&xy, &truth, &mut rng);
            let bins = empirical_variogram(&xy, &z, 28, 280.0);
            let f = fit_variogram(&bins, truth.kind, 5.0, 2000.0).unwrap();
            ranges.push(f.model.range_m);
            sills.push(f.model.sill());
            nuggets.push(f.model.nugget);
        }
        let med = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let (r, s, n) = (med(&mut ranges), med(&mut sills), med(&mut nuggets));
        println!(
            "{:?} truth range {} m, sill {}, nugget {}: median fit over 7 fields range {r:.1} m, sill {s:.2}, nugget {n:.2} (ranges {ranges:.0?})",
            truth.kind, truth.range_m, truth.sill(), truth.nugget
        );
        assert!((r / truth.range_m - 1.0).abs() < 0.3, "range {r}");
        assert!((s / truth.sill() - 1.0).abs() < 0.2, "sill {s}");
        assert!((n - truth.nugget).abs() < 1.5, "nugget {n}");
    }
}

// ---------------------------------------------------------------------------------------
// A Beihang-like setup (worlds/seed000-beihang.toml): the 3 declared stations on the
// Central Radio and TV Tower, completed to seed 000's 21 channels with synthetic ones.

const MASTER_SEED: u64 = 2018;
const UP_M: f64 = 1.2;

fn frame() -> EnuFrame {
    EnuFrame::new(Geodetic::from_deg(39.98070, 116.34680, 45.0))
}

fn stations(frame: &EnuFrame) -> Vec<FmStation> {
    let tower = frame.enu_of_ecef(&Geodetic::from_deg(39.9205, 116.3004, 300.0).to_ecef());
    let declared = [("F01", 97.4e6), ("F02", 103.9e6), ("F03", 106.1e6)]
        .map(|(id, f)| FmStation::new(id, tower, f, 40.0, 0.0))
        .to_vec();
    synthesize_stations(&declared, 21, MASTER_SEED)
}

fn field() -> FmField {
    FmField::new(
        FmFieldConfig::default(),
        stations(&frame()),
        None,
        MASTER_SEED,
    )
    .unwrap()
}

fn tag() -> WorldTag {
    WorldTag::new("Seed 000 site 1 — Beihang campus, Beijing", &frame(), None)
}

fn db_from_survey(points: &[[f64; 2]], stream: &str) -> FingerprintDb {
    let mut f = field();
    let mut rng = TrialRng::new(MASTER_SEED, 0).stream(stream);
    let fp =
        hybridnav::fm::survey::survey(&mut f, points, UP_M, &SurveyConfig::default(), &mut rng)
            .unwrap();
    let channels = f
        .stations()
        .iter()
        .map(|s| ChannelInfo {
            id: s.id.clone(),
            freq_hz: s.freq_hz,
        })
        .collect();
    FingerprintDb::new(
        tag(),
        &frame(),
        channels,
        points.iter().map(|p| [p[0], p[1], UP_M]).collect(),
        fp,
    )
    .unwrap()
}

/// The test points: the 828.66 m loop of the world file every 4 m.
fn test_points() -> Vec<[f64; 2]> {
    polyline_points(
        &[
            [-117.0, -90.0],
            [117.33, -90.0],
            [117.33, 90.0],
            [-117.0, 90.0],
            [-117.0, -90.0],
        ],
        4.0,
    )
    .unwrap()
}

/// Online scans at the test points (one scan each, stream `test/fm/online`).
fn scans(tps: &[[f64; 2]]) -> Vec<Vec<f64>> {
    let mut f = field();
    let mut rng = TrialRng::new(MASTER_SEED, 1).stream("test/fm/online");
    tps.iter()
        .map(|p| {
            let mut out = vec![0.0; f.stations().len()];
            f.scan(&Vector3::new(p[0], p[1], UP_M), &mut rng, &mut out);
            out
        })
        .collect()
}

/// Horizontal errors of WKNN at the test points, with an optional constraint per point.
fn errors(
    db: &FingerprintDb,
    tps: &[[f64; 2]],
    scans: &[Vec<f64>],
    constraints: Option<&[Constraint]>,
) -> Vec<f64> {
    let cfg = WknnConfig::default();
    let mut scratch = WknnScratch::new(cfg.k);
    tps.iter()
        .enumerate()
        .map(|(i, p)| {
            let c = constraints.map(|c| &c[i]);
            let fix = locate(
                db,
                &scans[i],
                &cfg,
                c,
                NoRpPolicy::Unconstrained,
                &mut scratch,
            )
            .unwrap();
            ((fix.pos_enu_m.x - p[0]).powi(2) + (fix.pos_enu_m.y - p[1]).powi(2)).sqrt()
        })
        .collect()
}

fn stats(e: &[f64]) -> (f64, f64, f64) {
    let mut s = e.to_vec();
    s.sort_by(f64::total_cmp);
    let mean = s.iter().sum::<f64>() / s.len() as f64;
    (
        mean,
        s[(0.95 * (s.len() - 1) as f64).round() as usize],
        s[s.len() - 1],
    )
}

const AREA: ([f64; 2], [f64; 2]) = ([-192.0, -195.0], [189.0, 192.0]);

#[test]
fn wknn_error_falls_as_reference_points_get_denser() {
    let tps = test_points();
    let sc = scans(&tps);
    let mut means = vec![];
    for spacing in [24.0, 12.0, 6.0] {
        let db = db_from_survey(
            &grid_points(AREA.0, AREA.1, spacing).unwrap(),
            &format!("test/fm/survey/{spacing}"),
        );
        let (mean, p95, max) = stats(&errors(&db, &tps, &sc, None));
        println!("RP grid {spacing} m ({} RPs, 21 channels): WKNN error mean {mean:.1} m, p95 {p95:.1} m, max {max:.1} m over {} test points", db.len(), tps.len());
        means.push(mean);
    }
    assert!(
        means[0] > 1.1 * means[1] && means[1] > 1.05 * means[2],
        "{means:?}"
    );
}

/// 282 surveyed RPs: a jittered 17 × 17 grid over the area, the first 282.
fn survey_282() -> Vec<[f64; 2]> {
    let mut rng = TrialRng::new(MASTER_SEED, 0).stream("test/fm/rp282");
    let step = (AREA.1[0] - AREA.0[0]) / 16.0;
    (0..289)
        .map(|i| {
            let (a, b) = ((i % 17) as f64, (i / 17) as f64);
            [
                (AREA.0[0] + a * step + (rng.random::<f64>() - 0.5) * 0.6 * step)
                    .clamp(AREA.0[0], AREA.1[0]),
                (AREA.0[1] + b * step + (rng.random::<f64>() - 0.5) * 0.6 * step)
                    .clamp(AREA.0[1], AREA.1[1]),
            ]
        })
        .take(282)
        .collect()
}

#[test]
fn kriging_282_rps_to_16640_and_the_gps_constraint() {
    let tps = test_points();
    let sc = scans(&tps);
    let rps = survey_282();
    let grid = grid_points(AREA.0, AREA.1, 3.0).unwrap();
    assert_eq!(grid.len(), 16_640);
    let mut f = field();
    let mut rng = TrialRng::new(MASTER_SEED, 0).stream("test/fm/survey/282");
    let t0 = std::time::Instant::now();
    let (kriged, report) = build_kriged(
        tag(),
        &frame(),
        &mut f,
        &rps,
        UP_M,
        &SurveyConfig::default(),
        &grid,
        &FitOptions::default(),
        &mut rng,
    )
    .unwrap();
    let dt = t0.elapsed().as_secs_f64();
    let fits: Vec<String> = report
        .iter()
        .take(3)
        .map(|r| {
            let m = r.fit.unwrap().model;
            format!(
                "{:?} nugget {:.1}, psill {:.1}, range {:.0} m",
                m.kind, m.nugget, m.psill, m.range_m
            )
        })
        .collect();
    println!(
        "kriged 282 → {} RPs × 21 channels in {dt:.2} s; first fits: {fits:?}",
        kriged.len()
    );
    assert!(report
        .iter()
        .all(|r| r.fit.is_some() && r.data_points == 282));

    // Kriging's error at the grid against the noise-free mean field (an independent truth).
    let mut mean = vec![0.0; 21];
    let mut sq = 0.0;
    for (i, p) in grid.iter().enumerate().step_by(37) {
        f.mean_rssi_dbm(&Vector3::new(p[0], p[1], UP_M), &mut mean);
        sq += kriged
            .fingerprint(i)
            .iter()
            .zip(&mean)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / 21.0;
    }
    let rms_db = (sq / grid.iter().step_by(37).count() as f64).sqrt();
    println!("kriged field vs the true mean field: RMS {rms_db:.2} dB (shadowing σ 4 dB)");
    assert!(rms_db < 4.0, "{rms_db}");

    let raw = db_from_survey(&rps, "test/fm/survey/282");
    let (m_raw, p_raw, x_raw) = stats(&errors(&raw, &tps, &sc, None));
    let (m_kr, p_kr, x_kr) = stats(&errors(&kriged, &tps, &sc, None));
    println!("282 surveyed RPs: mean {m_raw:.1} m, p95 {p_raw:.1} m, max {x_raw:.1} m; kriged 16 640: mean {m_kr:.1} m, p95 {p_kr:.1} m, max {x_kr:.1} m");
    assert!(m_kr < m_raw, "kriging should help: {m_kr} vs {m_raw}");

    // The constraint: centred on a GPS-like estimate (truth + N(0, 8 m) per axis), radius
    // r0 = 30 m, and after 30 s and 60 s without a reliable fix (r = 90 m, 150 m).
    let mut grng = TrialRng::new(MASTER_SEED, 1).stream("test/fm/gps");
    let centres: Vec<[f64; 2]> = tps
        .iter()
        .map(|p| {
            [
                p[0] + 8.0 * grng.sample::<f64, _>(StandardNormal),
                p[1] + 8.0 * grng.sample::<f64, _>(StandardNormal),
            ]
        })
        .collect();
    let cc = ConstraintConfig::default();
    let mut maxes = vec![];
    for since_s in [0.0, 30.0, 60.0] {
        let r = cc.radius_m(since_s);
        let cons: Vec<Constraint> = centres
            .iter()
            .map(|c| Constraint {
                centre_en_m: *c,
                radius_m: r,
            })
            .collect();
        let (m, p, x) = stats(&errors(&kriged, &tps, &sc, Some(&cons)));
        println!("constrained, r = {r:.0} m: mean {m:.1} m, p95 {p:.1} m, max {x:.1} m");
        maxes.push(x);
    }
    println!("unconstrained: max {x_kr:.1} m");
    assert!(
        maxes[0] < 0.6 * x_kr,
        "the constraint should cut the worst case: {} vs {x_kr}",
        maxes[0]
    );
    assert!(maxes[0] <= maxes[2] + 1e-9);
}

// ---------------------------------------------------------------------------------------
// The database file and bad inputs

fn small_db(world: WorldTag, frame: &EnuFrame) -> FingerprintDb {
    let channels = ["A", "B", "C", "D"]
        .iter()
        .enumerate()
        .map(|(i, id)| ChannelInfo {
            id: id.to_string(),
            freq_hz: 90e6 + 2e6 * i as f64,
        })
        .collect();
    let rps = vec![
        [0.0, 0.0, 1.0],
        [10.0, 0.0, 1.0],
        [0.0, 10.0, 1.0],
        [10.0, 10.0, 1.0],
        [100.0, 100.0, 1.0],
    ];
    #[rustfmt::skip]
    let rssi = vec![
        -50.0, -60.0, -70.0, f64::NAN,
        -52.0, -58.0, f64::NAN, -80.0,
        -54.0, -62.0, -66.0, -82.0,
        -56.0, f64::NAN, -64.0, -84.0,
        -80.0, -80.0, -80.0, -80.0,
    ];
    FingerprintDb::new(world, frame, channels, rps, rssi).unwrap()
}

#[test]
fn database_round_trip_and_world_mismatch() {
    let dir = std::env::temp_dir().join(format!("hybridnav-fm-db-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("fp.json");
    let db = small_db(tag(), &frame());
    db.save(&path).unwrap();
    let back = FingerprintDb::load(&path, &tag()).unwrap();
    // NaN ≠ NaN, so compare the missing pattern and the values separately.
    assert_eq!(back.rp_enu_m(), db.rp_enu_m());
    assert_eq!(back.channels(), db.channels());
    for (a, b) in back.rssi_dbm().iter().zip(db.rssi_dbm()) {
        assert!(a == b || (a.is_nan() && b.is_nan()));
    }
    let g = back.rp_lat_lon_deg()[0];
    assert!(
        (g[0] - 39.98070).abs() < 1e-6 && (g[1] - 116.34680).abs() < 1e-6,
        "{g:?}"
    );

    // Another world: other origin, or same origin but another name.
    let other_frame = EnuFrame::new(Geodetic::from_deg(30.5, 114.3, 20.0));
    let other = WorldTag::new("Seed 002 — Lianhua Lake Park, Wuhan", &other_frame, None);
    let e = FingerprintDb::load(&path, &other).unwrap_err();
    let msg = e.to_string();
    println!("{msg}");
    assert!(matches!(e, FmError::WorldMismatch { .. }));
    assert!(
        msg.contains("Lianhua") && msg.contains("Beihang") && msg.contains("rebuild"),
        "{msg}"
    );
    let renamed = WorldTag {
        name: "another".into(),
        ..tag()
    };
    assert!(matches!(
        FingerprintDb::load(&path, &renamed),
        Err(FmError::WorldMismatch { .. })
    ));
    let hashed = WorldTag {
        content_hash: Some("abc".into()),
        ..tag()
    };
    assert!(
        FingerprintDb::load(&path, &hashed).is_ok(),
        "a tag without a hash matches any hash"
    );

    // A damaged file names what was expected.
    std::fs::write(&path, "{\"format\": \"something else\"}").unwrap();
    let msg = FingerprintDb::load(&path, &tag()).unwrap_err().to_string();
    assert!(msg.contains("hybridnav-fm-fingerprints"), "{msg}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_channels_are_compared_on_the_common_ones() {
    let db = small_db(tag(), &frame());
    let mut scratch = WknnScratch::new(1);
    let cfg = WknnConfig {
        k: 1,
        min_common_channels: 3,
        ..Default::default()
    };
    // The measurement equals RP 1 on its three channels and misses channel C: RP 1 (which
    // lacks C too) must win, compared on A, B, D.
    let fix = locate(
        &db,
        &[-52.0, -58.0, f64::NAN, -80.0],
        &cfg,
        None,
        NoRpPolicy::Unconstrained,
        &mut scratch,
    )
    .unwrap();
    assert_eq!((fix.pos_enu_m.x, fix.pos_enu_m.y), (10.0, 0.0));
    assert_eq!(fix.best_distance_db, 0.0);
    // Only two channels measured: no RP shares three, a clear error.
    let e = locate(
        &db,
        &[-52.0, -58.0, f64::NAN, f64::NAN],
        &cfg,
        None,
        NoRpPolicy::Unconstrained,
        &mut scratch,
    )
    .unwrap_err();
    assert!(
        matches!(
            e,
            FmError::NoComparableRp {
                min_common: 3,
                measured: 2
            }
        ),
        "{e}"
    );
    // With a 2-channel minimum it works again.
    let cfg2 = WknnConfig {
        min_common_channels: 2,
        ..cfg
    };
    assert!(locate(
        &db,
        &[-52.0, -58.0, f64::NAN, f64::NAN],
        &cfg2,
        None,
        NoRpPolicy::Unconstrained,
        &mut scratch
    )
    .is_ok());
    // The wrong number of readings is an error, not a panic.
    assert!(locate(
        &db,
        &[-52.0],
        &cfg,
        None,
        NoRpPolicy::Unconstrained,
        &mut scratch
    )
    .is_err());
}

#[test]
fn no_rp_inside_the_circle_falls_back_or_errors() {
    let db = small_db(tag(), &frame());
    let cfg = WknnConfig {
        k: 2,
        ..Default::default()
    };
    let mut scratch = WknnScratch::new(cfg.k);
    let m = [-54.0, -62.0, -66.0, -82.0];
    let far = Constraint {
        centre_en_m: [500.0, 500.0],
        radius_m: 30.0,
    };
    let fix = locate(
        &db,
        &m,
        &cfg,
        Some(&far),
        NoRpPolicy::Unconstrained,
        &mut scratch,
    )
    .unwrap();
    assert!(!fix.constrained && fix.support == 0);
    let e = locate(&db, &m, &cfg, Some(&far), NoRpPolicy::Error, &mut scratch).unwrap_err();
    assert!(
        matches!(e, FmError::NoRpInCircle { .. }) && e.to_string().contains("radius 30.0 m"),
        "{e}"
    );
    // A circle holding only the far RP forces the fix there, whatever the signal says.
    let only_far = Constraint {
        centre_en_m: [100.0, 100.0],
        radius_m: 5.0,
    };
    let fix = locate(
        &db,
        &m,
        &cfg,
        Some(&only_far),
        NoRpPolicy::Error,
        &mut scratch,
    )
    .unwrap();
    assert!(fix.constrained && fix.support == 1 && fix.pos_enu_m.x == 100.0);
    // A circle around the four near RPs: support 4, the fix among them.
    let near = Constraint {
        centre_en_m: [5.0, 5.0],
        radius_m: 10.0,
    };
    let fix = locate(&db, &m, &cfg, Some(&near), NoRpPolicy::Error, &mut scratch).unwrap();
    assert_eq!(fix.support, 4);
    assert!(
        fix.pos_enu_m.x <= 10.0 + 1e-9 && fix.pos_enu_m.y <= 10.0 + 1e-9,
        "{:?}",
        fix.pos_enu_m
    );
    // R_f has at least the floor.
    assert!(
        fix.cov_enu_m2[(0, 0)] >= cfg.sigma_floor_m.powi(2)
            && fix.cov_enu_m2[(2, 2)] >= cfg.sigma_up_m.powi(2)
    );
}

#[test]
fn bad_config_values_name_their_key() {
    let parse = |s: &str| toml::from_str::<FmSensorConfig>(s);
    let ok = parse("rate_hz = 1.0\n[wknn]\nk = 5\nweighting = \"uniform\"\n[constraint]\nr0_m = 20.0\nno_rp = \"error\"\n").unwrap();
    ok.validate().unwrap();
    assert_eq!(ok.wknn.weighting, Weighting::Uniform);
    assert!(parse("rate_hz = 1.0\nradius = 3\n")
        .unwrap_err()
        .to_string()
        .contains("radius"));
    assert!(parse("[wknn]\nweighting = \"gaussian\"\n").is_err());
    for (text, key) in [
        ("[wknn]\nk = 0\n", "wknn.k"),
        ("[wknn]\nepsilon_db = 0.0\n", "wknn.epsilon_db"),
        (
            "[constraint]\nr0_m = 50.0\nr_max_m = 20.0\n",
            "constraint.r_max_m",
        ),
        ("[constraint]\ngrowth_mps = -1.0\n", "constraint.growth_mps"),
        ("[field]\nquantisation_db = -1.0\n", "field.quantisation_db"),
        (
            "[field.shadowing]\ndecorrelation_m = 0.0\n",
            "field.shadowing.decorrelation_m",
        ),
        ("rate_hz = 0.0\n", "rate_hz"),
    ] {
        let e = parse(text).unwrap().validate().unwrap_err();
        assert_eq!(e.key, key, "{text}: {e:?}");
        assert!(e.message.starts_with("expected"), "{e:?}");
    }
}

// ---------------------------------------------------------------------------------------
// The source

fn truth_at(frame: &EnuFrame, t_s: f64, e: f64, n: f64) -> Truth {
    let enu = Vector3::new(e, n, UP_M);
    Truth {
        sim: SimTime::from_seconds(t_s),
        t: GpsTime::from_ns(0).add_seconds(t_s),
        enu: TruthState {
            t_s,
            pos_enu_m: enu,
            vel_enu_mps: Vector3::zeros(),
            acc_enu_mps2: Vector3::zeros(),
            heading_rad: 0.0,
        },
        pos_ecef_m: frame.ecef_of_enu(&enu),
        vel_ecef_mps: Vector3::zeros(),
    }
}

/// The source tests' database: a survey of a 120 m square on a 3 m grid.
fn source_db() -> Arc<FingerprintDb> {
    let grid = grid_points([-60.0, -60.0], [60.0, 60.0], 3.0).unwrap();
    Arc::new(db_from_survey(&grid, "test/fm/survey/source"))
}

/// A source aided by estimator 0 (its estimates centre the constraint circle), for 100 s.
fn aided_source(fr: &EnuFrame, db: Arc<FingerprintDb>, cfg: &FmSensorConfig) -> FmSource {
    FmSource::new(
        cfg.clone(),
        stations(fr),
        None,
        fr.clone(),
        db,
        &TrialRng::new(MASTER_SEED, 3),
        Some(0),
        SimTime::from_seconds(100.0),
    )
    .unwrap()
}

#[test]
fn fm_source_emits_constrained_fixes_in_ecef() {
    let fr = frame();
    let db = source_db();
    let cfg = FmSensorConfig::default();
    let mut src = aided_source(&fr, db.clone(), &cfg);
    assert_eq!(src.kind(), hybridnav::measurement::SourceKind::Fm);
    let estimate = |t_s: f64, sigma_m: f64| Estimate {
        t: GpsTime::from_ns(0).add_seconds(t_s),
        pos_ecef_m: fr.ecef_of_enu(&Vector3::new(2.0, -3.0, UP_M)),
        vel_ecef_mps: None,
        cov_pos_m2: Matrix3::identity() * sigma_m * sigma_m,
    };
    let mut out = MeasurementBatch::default();
    let mut supports = vec![];
    // t = 0: a reliable estimate (σ 5 m) → r = r0; then unreliable (σ 50 m) for 20 s: the
    // circle grows by growth_mps per second.
    for (t_s, sigma) in [(0.0, 5.0), (10.0, 50.0), (20.0, 50.0)] {
        let truth = truth_at(&fr, t_s, 0.0, 0.0);
        let est = [Some(estimate(t_s, sigma))];
        out.items.clear();
        let next = src.sample(
            &SampleContext {
                truth: &truth,
                estimates: &est,
            },
            &mut out,
        );
        assert_eq!(next, Some(SimTime::from_seconds(t_s + 1.0)));
        let Some(Measurement::Position(fix)) = out.items.first() else {
            panic!("no fix at {t_s} s: {:?}", src.warnings())
        };
        let enu = fr.enu_of_ecef(&fix.pos_ecef_m);
        assert!(enu.xy().norm() < 40.0, "fix {enu:?}");
        // R_f is rotated, not invented: its trace is the ENU trace.
        assert!(
            fix.cov_m2.trace()
                >= 2.0 * cfg.wknn.sigma_floor_m.powi(2) + cfg.wknn.sigma_up_m.powi(2) - 1e-6
        );
        supports.push(fix.support);
    }
    // RPs in a circle of radius r on a 3 m grid ≈ π r² / 9.
    let expect = |r: f64| std::f64::consts::PI * r * r / 9.0;
    println!("support at r = 30, 50, 70 m: {supports:?}");
    for (s, r) in supports.iter().zip([30.0, 50.0, 70.0]) {
        let rr: f64 = r;
        // The 120 m grid clips the 70 m circle: compare with the clipped area bound.
        assert!(
            (*s as f64) <= expect(rr) * 1.1 && (*s as f64) >= expect(rr.min(60.0)) * 0.7,
            "{s} for r = {r}"
        );
    }
    assert!(supports[0] < supports[1] && supports[1] < supports[2]);
    // Without an aiding estimator every RP is searched and the support is 0.
    let mut free = FmSource::new(
        cfg,
        stations(&fr),
        None,
        fr.clone(),
        db,
        &TrialRng::new(MASTER_SEED, 3),
        None,
        SimTime::from_seconds(0.0),
    )
    .unwrap();
    out.items.clear();
    let truth = truth_at(&fr, 0.0, 0.0, 0.0);
    assert_eq!(
        free.sample(
            &SampleContext {
                truth: &truth,
                estimates: &[]
            },
            &mut out
        ),
        None
    );
    assert!(matches!(out.items[0], Measurement::Position(p) if p.support == 0));
}

/// Seed 000 §3.2: while the aiding estimate is unreliable, the circle is centred on the
/// position of the last reliable one and only its radius grows. An unreliable estimate
/// that has drifted 250 m away (outside the surveyed area) must not drag the search with
/// it: the fix stays inside the grown circle around the last reliable position, with the
/// support of that circle. (Centred on the drifted estimate, the circle would hold no RP.)
#[test]
fn fm_source_holds_the_circle_at_the_last_reliable_position() {
    let fr = frame();
    let mut src = aided_source(&fr, source_db(), &FmSensorConfig::default());
    let reliable_en = [2.0, -3.0];
    let mut out = MeasurementBatch::default();
    let mut fixes = vec![];
    for (t_s, at_en, sigma_m) in [
        (0.0, reliable_en, 5.0),
        (10.0, [180.0, 175.0], 60.0),
        (20.0, [250.0, 0.0], 90.0),
    ] {
        let est = [Some(Estimate {
            t: GpsTime::from_ns(0).add_seconds(t_s),
            pos_ecef_m: fr.ecef_of_enu(&Vector3::new(at_en[0], at_en[1], UP_M)),
            vel_ecef_mps: None,
            cov_pos_m2: Matrix3::identity() * sigma_m * sigma_m,
        })];
        let truth = truth_at(&fr, t_s, 0.0, 0.0);
        out.items.clear();
        src.sample(
            &SampleContext {
                truth: &truth,
                estimates: &est,
            },
            &mut out,
        );
        let Some(Measurement::Position(fix)) = out.items.first() else {
            panic!("no fix at {t_s} s: {:?}", src.warnings())
        };
        fixes.push((fr.enu_of_ecef(&fix.pos_ecef_m), fix.support));
    }
    println!("fixes (ENU, support): {fixes:?}");
    for ((enu, support), (t_s, r_m)) in fixes.iter().zip([(0.0, 30.0), (10.0, 50.0), (20.0, 70.0)])
    {
        let d = ((enu.x - reliable_en[0]).powi(2) + (enu.y - reliable_en[1]).powi(2)).sqrt();
        assert!(
            d <= r_m,
            "t = {t_s} s: fix {d:.1} m from the last reliable position, r = {r_m}"
        );
        assert!(*support > 0, "t = {t_s} s: the circle must hold RPs");
    }
    assert!(
        fixes[0].1 < fixes[1].1 && fixes[1].1 < fixes[2].1,
        "{fixes:?}"
    );
}

#[test]
fn fm_source_is_deterministic_per_trial() {
    let fr = frame();
    let grid = grid_points([-30.0, -30.0], [30.0, 30.0], 3.0).unwrap();
    let db = Arc::new(db_from_survey(&grid, "test/fm/survey/determinism"));
    // `declared_only`: the world's 3 stations, completed to 21 by the source itself.
    let run = |trial: u64, declared_only: bool| {
        let (cfg, st) = if declared_only {
            let cfg = FmSensorConfig {
                synthetic_stations_total: 21,
                ..Default::default()
            };
            (cfg, stations(&fr)[..3].to_vec())
        } else {
            (FmSensorConfig::default(), stations(&fr))
        };
        let mut src = FmSource::new(
            cfg,
            st,
            None,
            fr.clone(),
            db.clone(),
            &TrialRng::new(MASTER_SEED, trial),
            None,
            SimTime::from_seconds(10.0),
        )
        .unwrap();
        let mut fixes = vec![];
        for k in 0..5 {
            let truth = truth_at(&fr, k as f64, 3.0 * k as f64, 0.0);
            let mut out = MeasurementBatch::default();
            src.sample(
                &SampleContext {
                    truth: &truth,
                    estimates: &[],
                },
                &mut out,
            );
            fixes.push(out.items);
        }
        fixes
    };
    assert_eq!(run(4, false), run(4, false));
    assert_ne!(
        run(4, false),
        run(5, false),
        "another trial draws other scan noise"
    );
    assert_eq!(
        run(4, true),
        run(4, false),
        "the source completes the stations as the survey did"
    );
}

#[test]
fn fm_source_refuses_a_database_without_its_stations() {
    let fr = frame();
    let db = Arc::new(small_db(tag(), &fr));
    let e = FmSource::new(
        FmSensorConfig::default(),
        stations(&fr),
        None,
        fr.clone(),
        db,
        &TrialRng::new(1, 0),
        None,
        SimTime::from_seconds(1.0),
    )
    .err()
    .unwrap();
    assert_eq!(e.key, "database");
    assert!(e.message.contains("at least 3 channels"), "{e:?}");
}
