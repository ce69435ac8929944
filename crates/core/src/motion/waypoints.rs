//! A car or a pedestrian following waypoints.
//!
//! # Geometry
//!
//! The path is the polyline through `points_enu_m` (closed and repeated `laps` times when
//! `laps` is given). When `lateral_accel_mps2` = a_lat is given and the platform does not
//! stop at a waypoint, the corner there is replaced by the circular arc tangent to both legs,
//! of radius
//!
//! ```text
//! R = min(v²/a_lat, R_fit),   R_fit = min(L_in, L_out) / (2 tan(θ/2)),
//! ```
//!
//! where v is `speed_mps`, θ the turn angle between the legs and L_in, L_out their lengths
//! (each corner may use at most half of each adjacent leg). The arc starts R·tan(θ/2) before
//! the waypoint and ends as far after it; the platform therefore passes within
//! R(1/cos(θ/2) − 1) of the waypoint rather than through it. On an arc of radius R the
//! centripetal acceleration is v²/R; when `accel_mps2` is given the speed on the arc is
//! limited to √(a_lat R), so the lateral acceleration never exceeds a_lat, and the platform
//! brakes before the arc. Without `accel_mps2` the speed stays v and a short-legged corner
//! (R_fit < v²/a_lat) is taken at more than a_lat. Near-reversals (θ within 1 µrad of π)
//! cannot be rounded: the platform stops there when `accel_mps2` is given.
//!
//! Without `lateral_accel_mps2` the direction changes instantly at each waypoint: position is
//! continuous but velocity jumps, and the reported acceleration ignores the (infinite)
//! turning impulse.
//!
//! # Speed profile
//!
//! With `accel_mps2` = a the speed along the path follows the fastest profile that starts
//! and ends at rest, never exceeds v or an arc's √(a_lat R), and accelerates or brakes at
//! exactly a otherwise (a trapezoid, or a triangle when a leg is too short to reach v).
//! Junction speeds come from the usual forward/backward pass,
//! `u_j ≤ min(v_max,j−1, v_max,j, √(u_{j−1}² + 2aL_{j−1}), √(u_{j+1}² + 2aL_j))`. Without
//! `accel_mps2` the platform moves at v from t = 0 to the end. A 200 m path at 10 m/s
//! takes 20 s without ramps and 20 + v/a s with them (two ramps of v/a s each, which cover
//! v²/a m at half speed).
//!
//! With `dwell_s` the platform stops at every waypoint after the first and before the last
//! (braking to rest when `accel_mps2` is given, instantly otherwise) and waits `dwell_s`.
//!
//! Traffic: `leg_speeds_mps` caps each leg at its own speed (the `v_max` of its pieces in
//! the pass above, so the platform brakes before a slower leg and enters it at that leg's
//! speed; a corner arc takes the lower of its two legs' caps, its radius is sized for the
//! higher), and `stops` halts the platform at single waypoints (a traffic light): the run
//! of pieces ends there at rest, waits `dwell_s`, and a new run starts from rest. Without
//! `accel_mps2` the speed changes instantly from leg to leg, and stops are refused (a stop
//! needs braking). Both are deterministic, so a world's trials share one truth.
//!
//! Velocity is speed times the unit tangent; acceleration is the tangential acceleration
//! along the tangent plus v²/R towards the centre on arcs, so acceleration is the time
//! derivative of velocity everywhere except at the instants where the tangential
//! acceleration switches. Heading is the direction of the tangent, which is defined even at
//! rest (so a stopped car keeps pointing along its leg); a vertical leg keeps the heading of
//! the leg before it.

use super::{clamp_time, heading_of, Trajectory, TrajectoryConfig, TruthState, MAX_DURATION_S};
use crate::core::config::check_range;
use crate::core::ConfigIssue;
use nalgebra::Vector3;

/// Largest speed a waypoint platform may have (m/s).
const MAX_SPEED_MPS: f64 = 1000.0;
/// Largest number of path vertices (points × laps).
const MAX_VERTICES: usize = 1_000_000;
/// Turn angles below this (rad) are straight-through.
const STRAIGHT_RAD: f64 = 1e-9;
/// Turn angles within this of π (rad) are reversals.
const REVERSAL_RAD: f64 = 1e-6;
/// Pieces shorter than this (m) are dropped.
const MIN_PIECE_M: f64 = 1e-9;

#[derive(Clone, Debug, PartialEq)]
enum Geom {
    Line {
        start: Vector3<f64>,
        dir: Vector3<f64>,
    },
    /// Starts at `center − radius·n1` heading along `d1`, turning towards `n1`.
    Arc {
        center: Vector3<f64>,
        d1: Vector3<f64>,
        n1: Vector3<f64>,
        radius: f64,
    },
}

#[derive(Clone, Debug, PartialEq)]
struct Piece {
    geom: Geom,
    length_m: f64,
    vmax_mps: f64,
    /// Heading used where the tangent is vertical.
    heading_fallback_rad: f64,
}

impl Piece {
    /// Position, unit tangent and curvature vector (inward normal / R) at arc length `s`.
    fn frame(&self, s: f64) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
        match &self.geom {
            Geom::Line { start, dir } => (start + dir * s, *dir, Vector3::zeros()),
            Geom::Arc {
                center,
                d1,
                n1,
                radius,
            } => {
                let (sn, cs) = (s / radius).sin_cos();
                let pos = center + (d1 * sn - n1 * cs) * *radius;
                let tangent = d1 * cs + n1 * sn;
                let inward = n1 * cs - d1 * sn;
                (pos, tangent, inward / *radius)
            }
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
enum PhaseKind {
    /// Motion along `piece` from arc length `s0` at speed `v0` with tangential acceleration `a`.
    Move {
        piece: usize,
        s0: f64,
        v0: f64,
        a: f64,
    },
    /// At rest at `pos`, pointing along `tangent`.
    Hold { pos: Vector3<f64>, heading_rad: f64 },
}

#[derive(Clone, Debug, PartialEq)]
struct Phase {
    t0: f64,
    dur: f64,
    kind: PhaseKind,
}

/// A planned waypoint trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct WaypointPlan {
    pieces: Vec<Piece>,
    phases: Vec<Phase>,
    duration_s: f64,
    length_m: f64,
}

enum Corner {
    /// Straight through, or an instantaneous turn at speed.
    Pass,
    /// Rounded by an arc of this radius whose tangent points lie `trim` from the waypoint.
    Arc { radius: f64, trim: f64 },
    /// The platform stops here (and waits `dwell`).
    Stop { dwell: f64 },
}

struct Limits {
    accel: Option<f64>,
    lateral: Option<f64>,
    dwell: f64,
}

fn points_issue(msg: impl Into<String>) -> ConfigIssue {
    ConfigIssue::new("points_enu_m", msg)
}

impl WaypointPlan {
    /// Validates a [`TrajectoryConfig::Waypoints`] and plans it.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the field at fault.
    pub fn from_config(cfg: &TrajectoryConfig) -> Result<Self, ConfigIssue> {
        let TrajectoryConfig::Waypoints {
            points_enu_m,
            speed_mps,
            accel_mps2,
            lateral_accel_mps2,
            dwell_s,
            leg_speeds_mps,
            stops,
            laps,
            height_m,
        } = cfg
        else {
            return Err(ConfigIssue::new("kind", "expected kind = \"waypoints\""));
        };
        check_range(
            "speed_mps",
            *speed_mps,
            0.0,
            MAX_SPEED_MPS,
            true,
            "a positive speed in m/s",
        )?;
        if let Some(a) = accel_mps2 {
            check_range(
                "accel_mps2",
                *a,
                0.0,
                100.0,
                true,
                "a positive acceleration in m/s²",
            )?;
        }
        if let Some(a) = lateral_accel_mps2 {
            check_range(
                "lateral_accel_mps2",
                *a,
                0.0,
                100.0,
                true,
                "a positive lateral acceleration in m/s²",
            )?;
        }
        if let Some(d) = dwell_s {
            check_range(
                "dwell_s",
                *d,
                0.0,
                86_400.0,
                false,
                "a dwell time in seconds",
            )?;
        }
        if let Some(h) = height_m {
            check_range("height_m", *h, -1.0e4, 1.0e5, false, "a height in m")?;
        }
        if *laps == Some(0) {
            return Err(ConfigIssue::new(
                "laps",
                "expected at least 1 lap, got 0 (omit laps to drive the polyline once)",
            ));
        }

        // Points: two or three finite coordinates each.
        if points_enu_m.len() < 2 {
            return Err(points_issue(format!(
                "expected at least two waypoints, got {}",
                points_enu_m.len()
            )));
        }
        let up = height_m.unwrap_or(0.0);
        let mut pts: Vec<Vector3<f64>> = Vec::with_capacity(points_enu_m.len());
        let mut dropped_repeat = false;
        for (i, p) in points_enu_m.iter().enumerate() {
            let v = match p.as_slice() {
                [e, n] => Vector3::new(*e, *n, up),
                [e, n, u] => Vector3::new(*e, *n, *u),
                _ => {
                    return Err(points_issue(format!(
                        "waypoint {i} has {} coordinates; expected [e, n] or [e, n, u] in metres",
                        p.len()
                    )))
                }
            };
            if !(v.iter().all(|c| c.is_finite() && c.abs() <= 1.0e8)) {
                return Err(points_issue(format!(
                    "waypoint {i} is {p:?}; expected finite coordinates within ±1e8 m"
                )));
            }
            if pts
                .last()
                .is_none_or(|q: &Vector3<f64>| (v - q).norm() > MIN_PIECE_M)
            {
                pts.push(v);
            } else {
                dropped_repeat = true;
            }
        }
        if height_m.is_some() && points_enu_m.iter().all(|p| p.len() == 3) {
            return Err(ConfigIssue::new(
                "height_m",
                "height_m sets the up coordinate of [e, n] points, but every point has three coordinates; remove height_m",
            ));
        }
        let mut closed_explicitly = false;
        if laps.is_some() && pts.len() > 2 && (pts[0] - pts[pts.len() - 1]).norm() <= MIN_PIECE_M {
            pts.pop();
            closed_explicitly = true;
        }
        if pts.len() < 2 {
            return Err(points_issue(
                "all waypoints are the same point: the path has zero length",
            ));
        }

        // The vertex sequence actually driven.
        let vertices: Vec<Vector3<f64>> = match laps {
            None => pts.clone(),
            Some(n) => {
                let n = *n as usize;
                if pts.len().saturating_mul(n) > MAX_VERTICES {
                    return Err(ConfigIssue::new(
                        "laps",
                        format!(
                            "{n} laps of {} waypoints is more than {MAX_VERTICES} path vertices",
                            pts.len()
                        ),
                    ));
                }
                let mut v = Vec::with_capacity(pts.len() * n + 1);
                for _ in 0..n {
                    v.extend_from_slice(&pts);
                }
                v.push(pts[0]);
                v
            }
        };
        // Per-leg speed caps and per-waypoint stops, mapped onto the driven vertices: with
        // laps, vertex j is point j mod n and segment j is leg j mod n.
        let n_legs = if laps.is_some() {
            pts.len()
        } else {
            pts.len() - 1
        };
        let per_leg = |what: &str| {
            if dropped_repeat || closed_explicitly {
                Err(ConfigIssue::new(
                    what,
                    "cannot be matched to the legs: points_enu_m repeats a point (consecutively, or the first as the last with laps); remove the repeat",
                ))
            } else {
                Ok(())
            }
        };
        let leg_speeds: Vec<f64> = match leg_speeds_mps {
            None => vec![*speed_mps; n_legs],
            Some(v) => {
                per_leg("leg_speeds_mps")?;
                if v.len() != n_legs {
                    return Err(ConfigIssue::new(
                        "leg_speeds_mps",
                        format!(
                            "expected {n_legs} leg speeds (one per leg of the {} waypoints{}), got {}",
                            pts.len(),
                            if laps.is_some() { ", the closing leg last" } else { "" },
                            v.len()
                        ),
                    ));
                }
                for (i, &v) in v.iter().enumerate() {
                    check_range(
                        "leg_speeds_mps",
                        v,
                        0.0,
                        MAX_SPEED_MPS,
                        true,
                        &format!("a positive speed in m/s for leg {i}"),
                    )?;
                }
                v.clone()
            }
        };
        let mut point_dwell: Vec<Option<f64>> = vec![None; pts.len()];
        for stop in stops.iter().flatten() {
            per_leg("stops")?;
            let last = if laps.is_some() {
                pts.len()
            } else {
                pts.len() - 1
            };
            if stop.at == 0 && laps.is_none() || stop.at >= last {
                return Err(ConfigIssue::new(
                    "stops",
                    format!(
                        "a stop at waypoint {}: expected an index in {}..{last} (not the path's ends)",
                        stop.at,
                        if laps.is_some() { 0 } else { 1 },
                    ),
                ));
            }
            check_range(
                "stops",
                stop.dwell_s,
                0.0,
                86_400.0,
                false,
                "a dwell time in seconds",
            )?;
            point_dwell[stop.at] = Some(stop.dwell_s);
        }
        if point_dwell.iter().any(Option::is_some) && accel_mps2.is_none() {
            return Err(ConfigIssue::new(
                "stops",
                "a stop needs accel_mps2 (the platform brakes to rest and starts again)",
            ));
        }
        let seg_speed: Vec<f64> = (0..vertices.len() - 1)
            .map(|j| leg_speeds[j % n_legs])
            .collect();
        let vertex_dwell: Vec<Option<f64>> = (0..vertices.len())
            .map(|j| point_dwell[j % pts.len()])
            .collect();

        let lower_bound_s = vertices
            .windows(2)
            .zip(&seg_speed)
            .map(|(w, v)| (w[1] - w[0]).norm() / v)
            .sum::<f64>()
            + dwell_s.unwrap_or(0.0) * (vertices.len() as f64 - 2.0)
            + vertex_dwell.iter().flatten().sum::<f64>();
        if lower_bound_s > MAX_DURATION_S {
            let key = if laps.is_some_and(|n| n > 1) {
                "laps"
            } else {
                "speed_mps"
            };
            return Err(ConfigIssue::new(
                key,
                format!("the path takes at least {lower_bound_s:.0} s; expected at most {MAX_DURATION_S} s (ten days)"),
            ));
        }

        let lim = Limits {
            accel: *accel_mps2,
            lateral: *lateral_accel_mps2,
            dwell: dwell_s.unwrap_or(0.0),
        };
        let plan = Self::plan(
            &vertices,
            &seg_speed,
            &vertex_dwell,
            &lim,
            dwell_s.is_some_and(|d| d > 0.0),
        );
        if !(plan.duration_s.is_finite() && plan.duration_s <= MAX_DURATION_S) {
            return Err(ConfigIssue::new(
                "speed_mps",
                format!(
                    "the path takes {} s; expected at most {MAX_DURATION_S} s (ten days)",
                    plan.duration_s
                ),
            ));
        }
        Ok(plan)
    }

    /// The length of the driven path (m), corners cut by arcs not included.
    pub fn polyline_length_m(&self) -> f64 {
        self.length_m
    }

    /// The length actually travelled (m), arcs included.
    pub fn travelled_length_m(&self) -> f64 {
        self.pieces.iter().map(|p| p.length_m).sum()
    }

    #[allow(clippy::too_many_arguments)]
    fn corner(
        lim: &Limits,
        stop_at_waypoints: bool,
        stop_dwell: Option<f64>,
        speed_mps: f64,
        l_in: f64,
        l_out: f64,
        d_in: &Vector3<f64>,
        d_out: &Vector3<f64>,
    ) -> Corner {
        if stop_at_waypoints {
            return Corner::Stop { dwell: lim.dwell };
        }
        if let Some(dwell) = stop_dwell {
            return Corner::Stop { dwell };
        }
        let theta = d_in.dot(d_out).clamp(-1.0, 1.0).acos();
        if theta < STRAIGHT_RAD {
            return Corner::Pass;
        }
        let Some(a_lat) = lim.lateral else {
            return Corner::Pass;
        };
        let stop_or_pass = if lim.accel.is_some() {
            Corner::Stop { dwell: 0.0 }
        } else {
            Corner::Pass
        };
        if theta > std::f64::consts::PI - REVERSAL_RAD {
            return stop_or_pass;
        }
        let tan_half = (0.5 * theta).tan();
        let radius = (speed_mps * speed_mps / a_lat).min(0.5 * l_in.min(l_out) / tan_half);
        if radius < 1e-6 {
            return stop_or_pass;
        }
        Corner::Arc {
            radius,
            trim: radius * tan_half,
        }
    }

    /// Plans the path through `vertices`; `seg_speed[j]` caps segment j and
    /// `vertex_dwell[j]` stops the platform at vertex j.
    fn plan(
        vertices: &[Vector3<f64>],
        seg_speed: &[f64],
        vertex_dwell: &[Option<f64>],
        lim: &Limits,
        stop_at_waypoints: bool,
    ) -> Self {
        let n_seg = vertices.len() - 1;
        let lens: Vec<f64> = vertices.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
        let dirs: Vec<Vector3<f64>> = vertices
            .windows(2)
            .zip(&lens)
            .map(|(w, l)| (w[1] - w[0]) / *l)
            .collect();
        // corners[j] is the corner at vertex j (1..n_seg); the ends are free.
        let corners: Vec<Corner> = (0..=n_seg)
            .map(|j| {
                if j == 0 || j == n_seg {
                    Corner::Pass
                } else {
                    Self::corner(
                        lim,
                        stop_at_waypoints,
                        vertex_dwell[j],
                        seg_speed[j - 1].max(seg_speed[j]),
                        lens[j - 1],
                        lens[j],
                        &dirs[j - 1],
                        &dirs[j],
                    )
                }
            })
            .collect();
        let trim = |c: &Corner| {
            if let Corner::Arc { trim, .. } = c {
                *trim
            } else {
                0.0
            }
        };

        // Pieces grouped in runs that start and end at rest (when ramps are on).
        let mut pieces: Vec<Piece> = Vec::new();
        let mut runs: Vec<(Vec<usize>, f64)> = vec![(Vec::new(), 0.0)];
        let mut last_heading = heading_of(&dirs[0]).unwrap_or(0.0);
        let mut push = |pieces: &mut Vec<Piece>,
                        runs: &mut Vec<(Vec<usize>, f64)>,
                        geom: Geom,
                        length_m: f64,
                        vmax_mps: f64| {
            if length_m < MIN_PIECE_M {
                return;
            }
            let tangent = match &geom {
                Geom::Line { dir, .. } => *dir,
                Geom::Arc { d1, .. } => *d1,
            };
            last_heading = heading_of(&tangent).unwrap_or(last_heading);
            pieces.push(Piece {
                geom,
                length_m,
                vmax_mps,
                heading_fallback_rad: last_heading,
            });
            if let Some(run) = runs.last_mut() {
                run.0.push(pieces.len() - 1);
            }
        };
        for i in 0..n_seg {
            let t0 = trim(&corners[i]);
            let t1 = trim(&corners[i + 1]);
            let start = vertices[i] + dirs[i] * t0;
            push(
                &mut pieces,
                &mut runs,
                Geom::Line {
                    start,
                    dir: dirs[i],
                },
                lens[i] - t0 - t1,
                seg_speed[i],
            );
            if i + 1 < n_seg {
                match corners[i + 1] {
                    Corner::Pass => {}
                    Corner::Arc { radius, trim } => {
                        let d1 = dirs[i];
                        let d2 = dirs[i + 1];
                        let n1 = (d2 - d1 * d1.dot(&d2)).normalize();
                        let theta = d1.dot(&d2).clamp(-1.0, 1.0).acos();
                        let a_start = vertices[i + 1] - d1 * trim;
                        let leg_cap = seg_speed[i].min(seg_speed[i + 1]);
                        let vmax = match (lim.accel, lim.lateral) {
                            (Some(_), Some(a_lat)) => leg_cap.min((a_lat * radius).sqrt()),
                            _ => leg_cap,
                        };
                        push(
                            &mut pieces,
                            &mut runs,
                            Geom::Arc {
                                center: a_start + n1 * radius,
                                d1,
                                n1,
                                radius,
                            },
                            radius * theta,
                            vmax,
                        );
                    }
                    Corner::Stop { dwell } => {
                        if let Some(run) = runs.last_mut() {
                            run.1 = dwell;
                        }
                        runs.push((Vec::new(), 0.0));
                    }
                }
            }
        }

        // Speed profile, run by run.
        let mut phases: Vec<Phase> = Vec::new();
        let mut t = 0.0;
        let n_runs = runs.len();
        for (r, (run, dwell)) in runs.iter().enumerate() {
            if run.is_empty() {
                continue;
            }
            match lim.accel {
                None => {
                    for &p in run {
                        let v = pieces[p].vmax_mps;
                        let dur = pieces[p].length_m / v;
                        phases.push(Phase {
                            t0: t,
                            dur,
                            kind: PhaseKind::Move {
                                piece: p,
                                s0: 0.0,
                                v0: v,
                                a: 0.0,
                            },
                        });
                        t += dur;
                    }
                }
                Some(a) => {
                    let u = junction_speeds(
                        run.iter()
                            .map(|&p| (pieces[p].length_m, pieces[p].vmax_mps)),
                        a,
                    );
                    for (k, &p) in run.iter().enumerate() {
                        t = trapezoid(
                            &mut phases,
                            t,
                            p,
                            pieces[p].length_m,
                            pieces[p].vmax_mps,
                            u[k],
                            u[k + 1],
                            a,
                        );
                    }
                }
            }
            if r + 1 < n_runs && *dwell > 0.0 {
                let last = &pieces[*run.last().unwrap_or(&0)];
                let (pos, tangent, _) = last.frame(last.length_m);
                let heading_rad = heading_of(&tangent).unwrap_or(last.heading_fallback_rad);
                phases.push(Phase {
                    t0: t,
                    dur: *dwell,
                    kind: PhaseKind::Hold { pos, heading_rad },
                });
                t += dwell;
            }
        }
        let length_m = lens.iter().sum();
        Self {
            pieces,
            phases,
            duration_s: t,
            length_m,
        }
    }
}

/// Junction speeds u_0..u_n of a run of pieces (length, speed cap) that starts and ends at
/// rest, by the forward/backward pass.
fn junction_speeds(pieces: impl Iterator<Item = (f64, f64)>, a: f64) -> Vec<f64> {
    let p: Vec<(f64, f64)> = pieces.collect();
    let n = p.len();
    let mut u = vec![0.0; n + 1];
    for j in 1..n {
        u[j] = p[j - 1].1.min(p[j].1);
    }
    for j in 1..=n {
        u[j] = u[j].min((u[j - 1] * u[j - 1] + 2.0 * a * p[j - 1].0).sqrt());
    }
    for j in (0..n).rev() {
        u[j] = u[j].min((u[j + 1] * u[j + 1] + 2.0 * a * p[j].0).sqrt());
    }
    u
}

/// Appends the accelerate / cruise / brake phases of one piece and returns the end time.
#[allow(clippy::too_many_arguments)]
fn trapezoid(
    phases: &mut Vec<Phase>,
    t0: f64,
    piece: usize,
    len: f64,
    vcap: f64,
    u0: f64,
    u1: f64,
    a: f64,
) -> f64 {
    let peak = ((u0 * u0 + u1 * u1) / 2.0 + a * len)
        .sqrt()
        .min(vcap)
        .max(u0.max(u1));
    let d_acc = ((peak * peak - u0 * u0) / (2.0 * a)).max(0.0);
    let d_dec = ((peak * peak - u1 * u1) / (2.0 * a)).max(0.0);
    let d_cruise = (len - d_acc - d_dec).max(0.0);
    let mut t = t0;
    let mut s = 0.0;
    let mut add = |dur: f64, v0: f64, acc: f64, dist: f64| {
        if dur > 1e-12 {
            phases.push(Phase {
                t0: t,
                dur,
                kind: PhaseKind::Move {
                    piece,
                    s0: s,
                    v0,
                    a: acc,
                },
            });
            t += dur;
            s += dist;
        }
    };
    add((peak - u0) / a, u0, a, d_acc);
    add(d_cruise / peak.max(f64::MIN_POSITIVE), peak, 0.0, d_cruise);
    add((peak - u1) / a, peak, -a, d_dec);
    t
}

impl Trajectory for WaypointPlan {
    fn state_at(&self, t_s: f64) -> TruthState {
        let t = clamp_time(t_s, self.duration_s);
        let idx = self.phases.partition_point(|p| p.t0 <= t).saturating_sub(1);
        let Some(ph) = self.phases.get(idx) else {
            return TruthState {
                t_s: t,
                pos_enu_m: Vector3::zeros(),
                vel_enu_mps: Vector3::zeros(),
                acc_enu_mps2: Vector3::zeros(),
                heading_rad: 0.0,
            };
        };
        let tau = (t - ph.t0).clamp(0.0, ph.dur);
        match &ph.kind {
            PhaseKind::Hold { pos, heading_rad } => TruthState {
                t_s: t,
                pos_enu_m: *pos,
                vel_enu_mps: Vector3::zeros(),
                acc_enu_mps2: Vector3::zeros(),
                heading_rad: *heading_rad,
            },
            PhaseKind::Move { piece, s0, v0, a } => {
                let pc = &self.pieces[*piece];
                let s = (s0 + v0 * tau + 0.5 * a * tau * tau).clamp(0.0, pc.length_m);
                let speed = (v0 + a * tau).max(0.0);
                let (pos, tangent, curv) = pc.frame(s);
                TruthState {
                    t_s: t,
                    pos_enu_m: pos,
                    vel_enu_mps: tangent * speed,
                    acc_enu_mps2: tangent * *a + curv * (speed * speed),
                    heading_rad: heading_of(&tangent).unwrap_or(pc.heading_fallback_rad),
                }
            }
        }
    }

    fn duration_s(&self) -> f64 {
        self.duration_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::WaypointStop;
    use std::f64::consts::FRAC_PI_2;

    fn cfg(
        points: &[&[f64]],
        speed: f64,
        accel: Option<f64>,
        lateral: Option<f64>,
        dwell: Option<f64>,
        laps: Option<u32>,
    ) -> TrajectoryConfig {
        TrajectoryConfig::Waypoints {
            points_enu_m: points.iter().map(|p| p.to_vec()).collect(),
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

    fn plan(c: &TrajectoryConfig) -> WaypointPlan {
        WaypointPlan::from_config(c).unwrap()
    }

    const L: &[&[f64]] = &[&[0.0, 0.0], &[100.0, 0.0], &[100.0, 100.0]];

    #[test]
    fn two_legs_without_ramps_take_twenty_seconds() {
        let p = plan(&cfg(L, 10.0, None, None, None, None));
        assert!((p.duration_s() - 20.0).abs() < 1e-12);
        assert!((p.polyline_length_m() - 200.0).abs() < 1e-12);
        let s = p.state_at(5.0);
        assert!((s.pos_enu_m - Vector3::new(50.0, 0.0, 0.0)).norm() < 1e-12);
        assert!(
            (s.heading_rad - FRAC_PI_2).abs() < 1e-12,
            "east leg heads 90°"
        );
        let s = p.state_at(15.0);
        assert!((s.pos_enu_m - Vector3::new(100.0, 50.0, 0.0)).norm() < 1e-12);
        assert!(s.heading_rad.abs() < 1e-12, "north leg heads 0°");
        assert_eq!(p.state_at(25.0).pos_enu_m, Vector3::new(100.0, 100.0, 0.0));
    }

    #[test]
    fn ramps_add_v_over_a() {
        // One trapezoid over 200 m: 5 s up (25 m), 15 s cruise (150 m), 5 s down (25 m).
        let p = plan(&cfg(L, 10.0, Some(2.0), None, None, None));
        assert!((p.duration_s() - 25.0).abs() < 1e-9, "{}", p.duration_s());
        let s = p.state_at(2.5);
        assert!((s.vel_enu_mps.norm() - 5.0).abs() < 1e-12);
        assert!((s.acc_enu_mps2 - Vector3::new(2.0, 0.0, 0.0)).norm() < 1e-12);
        assert!((s.pos_enu_m.x - 6.25).abs() < 1e-12);
        assert!(p.state_at(0.0).vel_enu_mps.norm() < 1e-12);
        assert!(p.state_at(25.0).vel_enu_mps.norm() < 1e-12);
        assert!((p.state_at(25.0).pos_enu_m - Vector3::new(100.0, 100.0, 0.0)).norm() < 1e-9);
        // Short path: a triangle that peaks below the cruise speed.
        let p = plan(&cfg(
            &[&[0.0, 0.0], &[16.0, 0.0]],
            10.0,
            Some(2.0),
            None,
            None,
            None,
        ));
        assert!((p.duration_s() - 2.0 * (16.0f64 / 2.0).sqrt()).abs() < 1e-9);
    }

    #[test]
    fn dwell_stops_at_each_waypoint() {
        // Each 100 m leg: 5 s up, 5 s cruise, 5 s down; plus a 3 s dwell at the corner.
        let p = plan(&cfg(L, 10.0, Some(2.0), None, Some(3.0), None));
        assert!((p.duration_s() - 33.0).abs() < 1e-9, "{}", p.duration_s());
        let s = p.state_at(16.5);
        assert_eq!(s.vel_enu_mps, Vector3::zeros());
        assert!((s.pos_enu_m - Vector3::new(100.0, 0.0, 0.0)).norm() < 1e-9);
        assert!((s.heading_rad - FRAC_PI_2).abs() < 1e-12);
    }

    /// A straight 200 m street in two legs of 100 m with the given leg speeds and stops.
    fn street(
        accel: Option<f64>,
        leg_speeds: Option<Vec<f64>>,
        stops: Option<Vec<WaypointStop>>,
    ) -> TrajectoryConfig {
        let mut c = cfg(
            &[&[0.0, 0.0], &[100.0, 0.0], &[200.0, 0.0]],
            10.0,
            accel,
            None,
            None,
            None,
        );
        if let TrajectoryConfig::Waypoints {
            leg_speeds_mps,
            stops: s,
            ..
        } = &mut c
        {
            *leg_speeds_mps = leg_speeds;
            *s = stops;
        }
        c
    }

    #[test]
    fn leg_speeds_slow_one_leg() {
        // Without ramps: 100 m at 10 m/s, then 100 m at 5 m/s.
        let p = plan(&street(None, Some(vec![10.0, 5.0]), None));
        assert!((p.duration_s() - 30.0).abs() < 1e-12, "{}", p.duration_s());
        let s = p.state_at(15.0);
        assert!((s.pos_enu_m.x - 125.0).abs() < 1e-9);
        assert!((s.vel_enu_mps.x - 5.0).abs() < 1e-12);
        // With a = 2 m/s²: 0→10 in 5 s (25 m), brake 10→5 in 2.5 s over 18.75 m so that the
        // slow leg is entered at 5 m/s, cruise 56.25 m (5.625 s); then 93.75 m at 5 m/s
        // (18.75 s) and 5→0 in 2.5 s (6.25 m): 34.375 s in all.
        let p = plan(&street(Some(2.0), Some(vec![10.0, 5.0]), None));
        assert!((p.duration_s() - 34.375).abs() < 1e-9, "{}", p.duration_s());
        let at_junction = p.state_at(5.0 + 5.625 + 2.5);
        assert!((at_junction.pos_enu_m.x - 100.0).abs() < 1e-9);
        assert!((at_junction.vel_enu_mps.x - 5.0).abs() < 1e-9);
        // The default (no leg speeds) equals every leg at speed_mps.
        assert_eq!(
            plan(&street(Some(2.0), None, None)),
            plan(&street(Some(2.0), Some(vec![10.0, 10.0]), None))
        );
    }

    #[test]
    fn a_stop_waits_at_its_waypoint() {
        // Two trapezoids of 15 s (5 s up, 5 s cruise, 5 s down) and a 10 s stop between.
        let stop = WaypointStop {
            at: 1,
            dwell_s: 10.0,
        };
        let p = plan(&street(Some(2.0), None, Some(vec![stop])));
        assert!((p.duration_s() - 40.0).abs() < 1e-9, "{}", p.duration_s());
        for t in [15.0, 20.0, 25.0] {
            let s = p.state_at(t);
            assert!((s.pos_enu_m.x - 100.0).abs() < 1e-9, "t = {t}");
            assert!(s.vel_enu_mps.norm() < 1e-9, "t = {t}");
        }
        assert!(p.state_at(30.0).vel_enu_mps.x > 9.99);
    }

    #[test]
    fn bad_leg_speeds_and_stops_name_their_key() {
        let key = |c: TrajectoryConfig| WaypointPlan::from_config(&c).unwrap_err();
        let e = key(street(None, Some(vec![10.0]), None));
        assert_eq!(e.key, "leg_speeds_mps");
        assert!(e.message.contains("expected 2 leg speeds"), "{}", e.message);
        assert_eq!(
            key(street(None, Some(vec![10.0, f64::NAN]), None)).key,
            "leg_speeds_mps"
        );
        assert_eq!(
            key(street(None, Some(vec![10.0, 0.0]), None)).key,
            "leg_speeds_mps"
        );
        let stop = |at: usize, dwell_s: f64| Some(vec![WaypointStop { at, dwell_s }]);
        for (at, dwell) in [(0, 5.0), (2, 5.0), (7, 5.0), (1, -1.0)] {
            assert_eq!(key(street(Some(2.0), None, stop(at, dwell))).key, "stops");
        }
        let e = key(street(None, None, stop(1, 5.0)));
        assert!(e.message.contains("accel_mps2"), "{}", e.message);
        // A repeated point cannot be matched to the legs.
        let mut c = cfg(
            &[&[0.0, 0.0], &[100.0, 0.0], &[100.0, 0.0], &[200.0, 0.0]],
            10.0,
            None,
            None,
            None,
            None,
        );
        if let TrajectoryConfig::Waypoints { leg_speeds_mps, .. } = &mut c {
            *leg_speeds_mps = Some(vec![1.0, 1.0, 1.0]);
        }
        assert!(key(c).message.contains("repeats a point"));
    }

    #[test]
    fn corner_arcs_respect_the_lateral_limit() {
        // v = 10, a_lat = 2: R = 50 m, the right-angle arc starts 50 m before the corner.
        let p = plan(&cfg(L, 10.0, None, Some(2.0), None, None));
        let travelled = 200.0 - 100.0 + 50.0 * FRAC_PI_2;
        assert!((p.travelled_length_m() - travelled).abs() < 1e-9);
        assert!((p.duration_s() - travelled / 10.0).abs() < 1e-9);
        let mid = p.state_at((50.0 + 25.0 * FRAC_PI_2) / 10.0);
        assert!((mid.acc_enu_mps2.norm() - 2.0).abs() < 1e-9);
        // At mid-arc the heading is 45°, half-way between the legs.
        assert!((mid.heading_rad - FRAC_PI_2 / 2.0).abs() < 1e-9);
        // Tight corner with ramps: legs of 10 m cap R at 5 m, so the speed there is √10.
        let p = plan(&cfg(
            &[&[0.0, 0.0], &[10.0, 0.0], &[10.0, 10.0]],
            10.0,
            Some(2.0),
            Some(2.0),
            None,
            None,
        ));
        let mut on_arc = 0;
        for i in 0..=1000 {
            let s = p.state_at(p.duration_s() * i as f64 / 1000.0);
            let v = s.vel_enu_mps.norm();
            assert!(v <= 10.0 + 1e-9);
            if v > 1e-9 {
                let along = s.acc_enu_mps2.dot(&s.vel_enu_mps) / v;
                let lateral = (s.acc_enu_mps2.norm_squared() - along * along)
                    .max(0.0)
                    .sqrt();
                assert!(lateral <= 2.0 + 1e-9, "lateral {lateral}");
                if lateral > 1e-9 {
                    on_arc += 1;
                    assert!((v - 10.0f64.sqrt()).abs() < 1e-9, "arc speed {v}");
                }
            }
        }
        assert!(on_arc > 50);
    }

    #[test]
    fn laps_close_the_loop() {
        let sq: &[&[f64]] = &[&[0.0, 0.0], &[100.0, 0.0], &[100.0, 100.0], &[0.0, 100.0]];
        let p = plan(&cfg(sq, 10.0, None, None, None, Some(2)));
        assert!((p.polyline_length_m() - 800.0).abs() < 1e-9);
        assert!((p.duration_s() - 80.0).abs() < 1e-9);
        assert!(p.state_at(40.0).pos_enu_m.norm() < 1e-9);
        // A closed list (last = first) is the same loop.
        let sq5: &[&[f64]] = &[
            &[0.0, 0.0],
            &[100.0, 0.0],
            &[100.0, 100.0],
            &[0.0, 100.0],
            &[0.0, 0.0],
        ];
        assert!(
            (plan(&cfg(sq5, 10.0, None, None, None, Some(1))).duration_s() - 40.0).abs() < 1e-9
        );
        // A two-point "loop" is a shuttle that stops at each end when ramps are on.
        let p = plan(&cfg(
            &[&[0.0, 0.0], &[50.0, 0.0]],
            5.0,
            Some(1.0),
            Some(1.0),
            None,
            Some(1),
        ));
        assert!(
            (p.duration_s() - 2.0 * (10.0 + 5.0)).abs() < 1e-9,
            "{}",
            p.duration_s()
        );
        assert!(p.state_at(15.0).vel_enu_mps.norm() < 1e-9);
    }

    #[test]
    fn validation_names_keys() {
        let key = |c: TrajectoryConfig| WaypointPlan::from_config(&c).unwrap_err().key;
        assert_eq!(key(cfg(L, 0.0, None, None, None, None)), "speed_mps");
        assert_eq!(key(cfg(L, f64::NAN, None, None, None, None)), "speed_mps");
        assert_eq!(
            key(cfg(L, 10.0, Some(-1.0), None, None, None)),
            "accel_mps2"
        );
        assert_eq!(
            key(cfg(L, 10.0, None, Some(0.0), None, None)),
            "lateral_accel_mps2"
        );
        assert_eq!(key(cfg(L, 10.0, None, None, Some(-1.0), None)), "dwell_s");
        assert_eq!(key(cfg(L, 10.0, None, None, None, Some(0))), "laps");
        assert_eq!(
            key(cfg(&[&[0.0, 0.0]], 10.0, None, None, None, None)),
            "points_enu_m"
        );
        assert_eq!(
            key(cfg(
                &[&[1.0, 1.0], &[1.0, 1.0]],
                10.0,
                None,
                None,
                None,
                None
            )),
            "points_enu_m"
        );
        assert_eq!(
            key(cfg(&[&[1.0], &[2.0, 1.0]], 10.0, None, None, None, None)),
            "points_enu_m"
        );
        assert_eq!(
            key(cfg(
                &[&[1.0, f64::INFINITY], &[2.0, 1.0]],
                10.0,
                None,
                None,
                None,
                None
            )),
            "points_enu_m"
        );
        assert_eq!(
            key(cfg(
                &[&[0.0, 0.0], &[1.0e6, 0.0]],
                0.001,
                None,
                None,
                None,
                None
            )),
            "speed_mps"
        );
        assert_eq!(key(cfg(L, 10.0, None, None, None, Some(u32::MAX))), "laps");
        let mut c = cfg(
            &[&[0.0, 0.0, 1.0], &[5.0, 0.0, 1.0]],
            1.0,
            None,
            None,
            None,
            None,
        );
        if let TrajectoryConfig::Waypoints { height_m, .. } = &mut c {
            *height_m = Some(3.0);
        }
        assert_eq!(key(c), "height_m");
    }

    #[test]
    fn vertical_leg_keeps_the_previous_heading() {
        let p = plan(&cfg(
            &[&[0.0, 0.0, 0.0], &[10.0, 0.0, 0.0], &[10.0, 0.0, 10.0]],
            1.0,
            None,
            None,
            None,
            None,
        ));
        assert!((p.state_at(15.0).heading_rad - FRAC_PI_2).abs() < 1e-12);
        assert!((p.state_at(15.0).pos_enu_m.z - 5.0).abs() < 1e-12);
    }
}
