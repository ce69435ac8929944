//! Platform truth models through their public API: waypoint kinematics (property tests),
//! the statistics of seed 001's Singer model, seed 003's plane-turning model against an
//! independent integration, and configuration errors that name their key.

use hybridnav::core::TrialRng;
use hybridnav::motion::{Trajectory, TrajectoryConfig};
use nalgebra::Vector3;
use proptest::prelude::*;

fn parse(text: &str) -> Result<TrajectoryConfig, String> {
    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Doc {
        trajectory: TrajectoryConfig,
    }
    toml::from_str::<Doc>(text)
        .map(|d| d.trajectory)
        .map_err(|e| e.to_string())
}

fn build(cfg: &TrajectoryConfig, trial: u64) -> Box<dyn Trajectory> {
    cfg.build(&mut TrialRng::new(2024, trial).stream("motion/trajectory"))
        .expect("valid configuration")
}

fn waypoints(
    points: Vec<Vec<f64>>,
    speed: f64,
    accel: Option<f64>,
    lateral: Option<f64>,
    dwell: Option<f64>,
    laps: Option<u32>,
) -> TrajectoryConfig {
    TrajectoryConfig::Waypoints {
        points_enu_m: points,
        speed_mps: speed,
        accel_mps2: accel,
        lateral_accel_mps2: lateral,
        dwell_s: dwell,
        leg_speeds_mps: None,
        stops: None,
        laps,
        height_m: None,
    }
}

/// Distance from `p` to the polyline through `pts`.
fn distance_to_polyline(p: &Vector3<f64>, pts: &[Vector3<f64>]) -> f64 {
    pts.windows(2)
        .map(|w| {
            let d = w[1] - w[0];
            let u = ((p - w[0]).dot(&d) / d.norm_squared()).clamp(0.0, 1.0);
            (p - (w[0] + d * u)).norm()
        })
        .fold(f64::INFINITY, f64::min)
}

fn point_strategy() -> impl Strategy<Value = Vec<Vec<f64>>> {
    prop::collection::vec((-500.0f64..500.0, -500.0f64..500.0, -5.0f64..5.0), 2..7)
        .prop_map(|v| v.into_iter().map(|(e, n, u)| vec![e, n, u]).collect())
        .prop_filter("distinct consecutive points", |v: &Vec<Vec<f64>>| {
            v.windows(2)
                .all(|w| (w[0][0] - w[1][0]).hypot(w[0][1] - w[1][1]) > 1.0)
        })
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 64,
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// With ramps and rounded corners the motion is smooth: velocity is the derivative of
    /// position, acceleration the derivative of velocity (up to its switching instants),
    /// speeds and lateral accelerations respect their limits and heading follows velocity.
    #[test]
    fn waypoint_kinematics_are_consistent(
        points in point_strategy(),
        speed in 0.5f64..30.0,
        accel in 0.3f64..5.0,
        lateral in 0.5f64..5.0,
        dwell in prop::option::of(0.0f64..5.0),
        laps in prop::option::of(1u32..3),
        fractions in prop::collection::vec(0.0f64..1.0, 40),
    ) {
        let cfg = waypoints(points.clone(), speed, Some(accel), Some(lateral), dwell, laps);
        let tr = build(&cfg, 0);
        let dur = tr.duration_s();
        prop_assert!(dur.is_finite() && dur > 0.0);
        // Start at the first point at rest; end at rest at the last (or, for loops, the first).
        let first = Vector3::new(points[0][0], points[0][1], points[0][2]);
        let last_pt = if laps.is_some() { &points[0] } else { &points[points.len() - 1] };
        let last = Vector3::new(last_pt[0], last_pt[1], last_pt[2]);
        prop_assert!((tr.state_at(0.0).pos_enu_m - first).norm() < 1e-6);
        prop_assert!((tr.state_at(dur).pos_enu_m - last).norm() < 1e-6);
        prop_assert!(tr.state_at(0.0).vel_enu_mps.norm() < 1e-9 && tr.state_at(dur).vel_enu_mps.norm() < 1e-9);

        let h = 1e-4;
        for f in fractions {
            let t = h + f * (dur - 2.0 * h);
            let s = tr.state_at(t);
            let v = s.vel_enu_mps.norm();
            prop_assert!(v <= speed * (1.0 + 1e-12) + 1e-12, "speed {} > {}", v, speed);
            let num_v = (tr.state_at(t + h).pos_enu_m - tr.state_at(t - h).pos_enu_m) / (2.0 * h);
            prop_assert!((num_v - s.vel_enu_mps).norm() < 1e-3 * (1.0 + accel + lateral), "t {}: d/dt p = {:?}, v = {:?}", t, num_v, s.vel_enu_mps);
            // The forward difference of velocity lies between the accelerations at both ends
            // (the acceleration switches at most once within h).
            let s2 = tr.state_at(t + h);
            let num_a = (s2.vel_enu_mps - s.vel_enu_mps) / h;
            for i in 0..3 {
                let lo = s.acc_enu_mps2[i].min(s2.acc_enu_mps2[i]);
                let hi = s.acc_enu_mps2[i].max(s2.acc_enu_mps2[i]);
                prop_assert!(num_a[i] > lo - 1e-3 && num_a[i] < hi + 1e-3, "t {}: d/dt v = {:?}, a = {:?}..{:?}", t, num_a, s.acc_enu_mps2, s2.acc_enu_mps2);
            }
            if v > 1e-6 {
                let along = s.acc_enu_mps2.dot(&s.vel_enu_mps) / v;
                let lat = (s.acc_enu_mps2.norm_squared() - along * along).max(0.0).sqrt();
                prop_assert!(lat <= lateral * (1.0 + 1e-9) + 1e-9, "lateral {} > {}", lat, lateral);
                prop_assert!(along.abs() <= accel * (1.0 + 1e-9) + 1e-9);
                let hv = s.vel_enu_mps.x.hypot(s.vel_enu_mps.y);
                if hv > 1e-6 {
                    let mut want = s.vel_enu_mps.x.atan2(s.vel_enu_mps.y);
                    if want < 0.0 {
                        want += std::f64::consts::TAU;
                    }
                    let diff = (s.heading_rad - want).abs();
                    prop_assert!(diff.min(std::f64::consts::TAU - diff) < 1e-9, "heading {} vs {}", s.heading_rad, want);
                }
            }
        }
    }

    /// Without ramps or arcs the platform runs the exact polyline at constant speed.
    #[test]
    fn plain_waypoints_run_the_polyline(points in point_strategy(), speed in 0.5f64..30.0, fractions in prop::collection::vec(0.0f64..1.0, 20)) {
        let tr = build(&waypoints(points.clone(), speed, None, None, None, None), 0);
        let pts: Vec<Vector3<f64>> = points.iter().map(|p| Vector3::new(p[0], p[1], p[2])).collect();
        let length: f64 = pts.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        prop_assert!((tr.duration_s() - length / speed).abs() < 1e-9 * (1.0 + length / speed));
        for f in fractions {
            let s = tr.state_at(f * tr.duration_s());
            prop_assert!(distance_to_polyline(&s.pos_enu_m, &pts) < 1e-6);
            prop_assert!((s.vel_enu_mps.norm() - speed).abs() < 1e-9 * speed);
        }
    }
}

#[test]
fn hundred_metre_legs_take_twenty_seconds_plus_ramps() {
    let pts = vec![vec![0.0, 0.0], vec![100.0, 0.0], vec![100.0, 100.0]];
    assert!(
        (build(&waypoints(pts.clone(), 10.0, None, None, None, None), 0).duration_s() - 20.0).abs()
            < 1e-12
    );
    // Ramps of v/a = 5 s at each end, each covering 25 m at half speed: 20 + 5 s.
    assert!(
        (build(
            &waypoints(pts.clone(), 10.0, Some(2.0), None, None, None),
            0
        )
        .duration_s()
            - 25.0)
            .abs()
            < 1e-9
    );
    // Stopping 3 s at the corner: two 15 s legs plus the dwell.
    assert!(
        (build(&waypoints(pts, 10.0, Some(2.0), None, Some(3.0), None), 0).duration_s() - 33.0)
            .abs()
            < 1e-9
    );
}

/// ÿ samples at whole seconds from `t0` to the end, for `runs` independent trials of seed
/// 001's model lengthened to `duration` s.
fn singer_accels(runs: u64, duration: f64, t0: usize) -> Vec<Vec<f64>> {
    let cfg = parse(&format!(
        "trajectory = {{ kind = \"singer\", duration_s = {duration} }}"
    ))
    .unwrap();
    (0..runs)
        .map(|r| {
            let tr = build(&cfg, r);
            (t0..=duration as usize)
                .map(|k| tr.state_at(k as f64).acc_enu_mps2.y)
                .collect()
        })
        .collect()
}

#[test]
fn singer_acceleration_has_the_papers_variance_and_correlation() {
    // Seed 001: σ_m² = 3.5 (m/s²)², α = 0.1 /s. Starting from ÿ = 0 the variance reaches
    // σ_m²(1 − e^{−2αt}); after 50 s that is σ_m² to 5e-5, so samples from 50 s on are
    // stationary.
    let runs = singer_accels(2000, 300.0, 50);
    let n: usize = runs.iter().map(Vec::len).sum();
    let mean = runs.iter().flatten().sum::<f64>() / n as f64;
    let var = runs
        .iter()
        .flatten()
        .map(|a| (a - mean).powi(2))
        .sum::<f64>()
        / n as f64;
    eprintln!("Singer ÿ: mean {mean:.4} m/s², variance {var:.4} (m/s²)² vs σ_m² = 3.5");
    assert!(mean.abs() < 0.1, "mean {mean}");
    assert!((var / 3.5 - 1.0).abs() < 0.10, "variance {var}");
    for lag in [1usize, 5, 10, 20] {
        let (mut sum, mut count) = (0.0, 0usize);
        for r in &runs {
            for i in 0..r.len() - lag {
                sum += (r[i] - mean) * (r[i + lag] - mean);
                count += 1;
            }
        }
        let rho = sum / count as f64 / var;
        let want = (-0.1 * lag as f64).exp();
        eprintln!("Singer ÿ autocorrelation at {lag:2} s: {rho:.4} vs e^(−ατ) = {want:.4}");
        assert!((rho - want).abs() < 0.05, "lag {lag}: {rho} vs {want}");
    }
}

#[test]
fn singer_x_is_uniform_and_runs_are_reproducible() {
    let cfg = parse("trajectory = { kind = \"singer\" }").unwrap();
    let a = build(&cfg, 7);
    let b = build(&cfg, 7);
    let c = build(&cfg, 8);
    assert_eq!(a.duration_s(), 100.0);
    for k in 0..=100 {
        let t = k as f64;
        let s = a.state_at(t);
        assert_eq!(s, b.state_at(t));
        assert!((s.pos_enu_m.x - (4000.0 + 14.0 * t)).abs() < 1e-9);
        assert_eq!(s.vel_enu_mps.x, 14.0);
    }
    assert_ne!(a.state_at(50.0).pos_enu_m.y, c.state_at(50.0).pos_enu_m.y);
    let s0 = a.state_at(0.0);
    assert_eq!(
        (s0.pos_enu_m.y, s0.vel_enu_mps.y, s0.acc_enu_mps2.y),
        (0.0, 11.0, 0.0)
    );
}

/// Independent reference: RK4 integration of ṗ = v, v̇ = a, ȧ = M a.
fn rk4_turning(alpha: f64, omega: f64, x: [f64; 9], t_end: f64, dt: f64) -> [f64; 9] {
    let f = |s: &[f64; 9]| -> [f64; 9] {
        [
            s[3],
            s[4],
            s[5],
            s[6],
            s[7],
            s[8],
            -alpha * s[6] - omega * s[7],
            omega * s[6] - alpha * s[7],
            -alpha * s[8],
        ]
    };
    let mut s = x;
    let steps = (t_end / dt).round() as usize;
    for _ in 0..steps {
        let k1 = f(&s);
        let add = |a: &[f64; 9], k: &[f64; 9], c: f64| -> [f64; 9] {
            std::array::from_fn(|i| a[i] + c * k[i])
        };
        let k2 = f(&add(&s, &k1, dt / 2.0));
        let k3 = f(&add(&s, &k2, dt / 2.0));
        let k4 = f(&add(&s, &k3, dt));
        s = std::array::from_fn(|i| s[i] + dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
    }
    s
}

#[test]
fn plane_turning_without_noise_matches_an_independent_integration() {
    let tr = build(
        &parse("trajectory = { kind = \"plane_turning\", noise_var_m2ps4 = 0 }").unwrap(),
        0,
    );
    let x0 = [0.0, 0.0, 0.0, 4.0, -4.0, 4.0, 0.5, -0.5, -0.5];
    for t in [1.0, 2.0, 3.0, 10.0, 57.5, 100.0] {
        let want = rk4_turning(0.03, 0.1, x0, t, 1e-3);
        let s = tr.state_at(t);
        let got = [
            s.pos_enu_m.x,
            s.pos_enu_m.y,
            s.pos_enu_m.z,
            s.vel_enu_mps.x,
            s.vel_enu_mps.y,
            s.vel_enu_mps.z,
            s.acc_enu_mps2.x,
            s.acc_enu_mps2.y,
            s.acc_enu_mps2.z,
        ];
        for i in 0..9 {
            assert!(
                (got[i] - want[i]).abs() < 1e-8 * (1.0 + want[i].abs()),
                "t = {t}, component {i}: {} vs {}",
                got[i],
                want[i]
            );
        }
    }
    // The horizontal acceleration turns counter-clockwise at ω and decays at α:
    // after π/ω = 31.4 s it points the other way, e^{−0.03·31.4} as long.
    let t = std::f64::consts::PI / 0.1;
    let a = tr.state_at(t).acc_enu_mps2;
    let k = -(-0.03 * t).exp();
    assert!((a.x - 0.5 * k).abs() < 1e-9 && (a.y + 0.5 * k).abs() < 1e-9);
}

#[test]
fn plane_turning_paper_run_is_reproducible() {
    let cfg = parse("trajectory = { kind = \"plane_turning\" }").unwrap();
    let a = build(&cfg, 3);
    assert_eq!(a.duration_s(), 100.0);
    assert_eq!(a.state_at(37.3), build(&cfg, 3).state_at(37.3));
    assert_ne!(a.state_at(37.3), build(&cfg, 4).state_at(37.3));
    let s = a.state_at(0.0);
    assert_eq!(s.pos_enu_m, Vector3::zeros());
    assert_eq!(s.vel_enu_mps, Vector3::new(4.0, -4.0, 4.0));
    assert_eq!(s.acc_enu_mps2, Vector3::new(0.5, -0.5, -0.5));
}

#[test]
fn configuration_errors_name_their_key() {
    let key = |text: &str| parse(text).unwrap().validate().unwrap_err().key;
    assert_eq!(key("trajectory = { kind = \"waypoints\", points_enu_m = [[0, 0], [5, 0]], speed_mps = -3 }"), "speed_mps");
    assert_eq!(
        key("trajectory = { kind = \"waypoints\", points_enu_m = [[0, 0]], speed_mps = 3 }"),
        "points_enu_m"
    );
    assert_eq!(
        key(
            "trajectory = { kind = \"waypoints\", points_enu_m = [[2, 2], [2, 2]], speed_mps = 3 }"
        ),
        "points_enu_m"
    );
    assert_eq!(key("trajectory = { kind = \"waypoints\", points_enu_m = [[0, 0], [5, 0]], speed_mps = 3, accel_mps2 = 0 }"), "accel_mps2");
    assert_eq!(key("trajectory = { kind = \"waypoints\", points_enu_m = [[0, 0], [5, 0]], speed_mps = 3, laps = 0 }"), "laps");
    assert_eq!(
        key("trajectory = { kind = \"singer\", alpha_per_s = -0.1 }"),
        "alpha_per_s"
    );
    assert_eq!(
        key("trajectory = { kind = \"singer\", duration_s = 1e7 }"),
        "duration_s"
    );
    assert_eq!(
        key("trajectory = { kind = \"singer\", step_s = 0 }"),
        "step_s"
    );
    assert_eq!(
        key("trajectory = { kind = \"singer\", step_s = 1e-5, duration_s = 864000 }"),
        "step_s"
    );
    assert_eq!(
        key("trajectory = { kind = \"plane_turning\", noise_var_m2ps4 = -1 }"),
        "noise_var_m2ps4"
    );
    assert_eq!(
        key("trajectory = { kind = \"static\", position_enu_m = [0, 0, 0], duration_s = -1 }"),
        "duration_s"
    );
    let issue = parse(
        "trajectory = { kind = \"waypoints\", points_enu_m = [[0, 0], [5, 0]], speed_mps = -3 }",
    )
    .unwrap()
    .validate()
    .unwrap_err();
    assert!(
        issue.message.contains("expected") && issue.message.contains("-3"),
        "{}",
        issue.message
    );
    // Misspelt keys are serde errors that name the key.
    let e =
        parse("trajectory = { kind = \"waypoints\", points = [[0, 0], [5, 0]], speed_mps = 3 }")
            .unwrap_err();
    assert!(e.contains("points"), "{e}");
}
