//! `report.html`: one self-contained page per run, readable in any browser offline.
//!
//! It holds the papers' kind of table (σ-levels, ATE/RPE, NEES, availability, modes), the
//! empirical CDF of every estimator's error, trial 0's trajectories over the scene map,
//! its error against time with the spans of poor satellite coverage shaded, the mode
//! timeline, the GDOP and a sky plot of the satellites. Every chart is inline SVG
//! ([`svg`]); there is no script, no external style sheet and no font to fetch.

pub mod map;
pub mod svg;

use crate::core::{SimTime, TrialRng};
use crate::engine::trial::{truth_at, EpochRecord, TrialResult};
use crate::metrics::summary::Summary;
use crate::world::World;
use map::Overlay;
use std::fmt::Write;
use svg::{colour, escape, Chart, ModeRow, Scale, Series, SkyTrack};

const STYLE: &str = "body{font-family:sans-serif;max-width:1100px;margin:1.5em auto;padding:0 1em;color:#222}
h1{font-size:1.5em}h2{font-size:1.15em;margin-top:1.8em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;font-size:0.9em}th,td{padding:3px 8px;border-bottom:1px solid #e3e3e3;text-align:right}
th:first-child,td:first-child{text-align:left}th{background:#f3f3f3}.meta{color:#555;font-size:0.9em}
figure{margin:0.8em 0}.wide{overflow-x:auto}figcaption{color:#555;font-size:0.85em;max-width:860px}svg{max-width:100%;height:auto}";

/// Renders the report of a run from its summary, its first trial (whose trajectories are
/// drawn) and each estimator's thinned error CDF
/// ([`crate::montecarlo::reduce::Reduced::cdfs`]).
///
/// # Errors
/// When the world's trajectory or map cannot be built.
pub fn html(
    world: &World,
    summary: &Summary,
    first: Option<&TrialResult>,
    cdfs: &[Vec<(f64, f64)>],
) -> Result<String, String> {
    let mut h = String::new();
    let title = format!("{} — hybridnav report", summary.world);
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title><style>{STYLE}</style></head><body>\n",
        escape(&title)
    );
    let _ = writeln!(h, "<h1>{}</h1>", escape(&summary.world));
    let _ = writeln!(
        h,
        "<p class=\"meta\">World file <code>{}</code> (hash <code>{}</code>) · seed {} · {} trial(s){} · {:.1} s each · hybridnav {}</p>",
        escape(&summary.world_file),
        escape(&summary.world_hash[..summary.world_hash.len().min(16)]),
        summary.seed,
        summary.trials,
        summary
            .shard
            .as_deref()
            .map(|s| format!(" (shard {s} only)"))
            .unwrap_or_default(),
        summary.duration_s,
        escape(&summary.hybridnav_version)
    );
    table(&mut h, summary);
    cdf(&mut h, summary, cdfs);
    if let Some(t0) = first {
        trajectories(&mut h, world, t0)?;
        error_vs_time(&mut h, t0);
        modes(&mut h, t0);
        gdop(&mut h, t0);
    }
    sky(&mut h, world)?;
    if !summary.warnings.is_empty() {
        h.push_str("<h2>Warnings</h2><ul>\n");
        for w in &summary.warnings {
            let _ = writeln!(h, "<li>{}</li>", escape(w));
        }
        h.push_str("</ul>\n");
    }
    h.push_str("</body></html>\n");
    Ok(h)
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.filter(|x| x.is_finite())
        .map_or_else(|| "–".into(), |x| format!("{x:.digits$}"))
}

/// The papers' table: σ-levels of the 3-D and horizontal error, their spread, and the
/// other statistics of `summary.json`.
fn table(h: &mut String, s: &Summary) {
    h.push_str("<h2>Position error</h2>\n<div class=\"wide\"><table><tr><th>estimator</th><th>1σ</th><th>2σ</th><th>3σ</th><th>mean</th><th>RMSE</th><th>max</th><th>mean ATE</th><th>RMSE ATE</th><th>mean RPE</th><th>RMSE RPE</th><th>RMSE ATE aligned</th><th>horiz. 1σ / 2σ / 3σ</th><th>mean NEES [95 % band]</th><th>mean NIS / dof</th><th>PCRLB on RMSE</th><th>RMSE / PCRLB</th><th>availability</th><th>coasting</th><th>modes</th></tr>\n");
    for e in &s.estimators {
        let a = e.error_3d_m.as_ref();
        let b = e.error_h_m.as_ref();
        let nees = e.nees.as_ref().map_or_else(
            || "–".to_string(),
            |n| format!("{:.2} [{:.2}, {:.2}]", n.mean, n.band_lo, n.band_hi),
        );
        let nis = e.nis.as_ref().map_or_else(
            || "–".to_string(),
            |n| format!("{:.2} / {:.2}", n.mean, n.dof),
        );
        let modes: Vec<String> = e
            .modes
            .iter()
            .map(|(m, f)| format!("{} {:.0} %", escape(m), 100.0 * f))
            .collect();
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{} / {} / {}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.1} %</td><td>{:.1} %</td><td>{}</td></tr>",
            escape(&e.name),
            opt(a.map(|x| x.sigma1), 2),
            opt(a.map(|x| x.sigma2), 2),
            opt(a.map(|x| x.sigma3), 2),
            opt(a.map(|x| x.mean), 2),
            opt(a.map(|x| x.rmse), 2),
            opt(a.map(|x| x.max), 2),
            opt(e.ate_m.as_ref().map(|x| x.mean), 2),
            opt(e.ate_m.as_ref().map(|x| x.rmse), 2),
            opt(e.rpe_m.as_ref().map(|x| x.mean), 2),
            opt(e.rpe_m.as_ref().map(|x| x.rmse), 2),
            opt(e.ate_aligned_m.as_ref().map(|x| x.rmse), 2),
            opt(b.map(|x| x.sigma1), 2),
            opt(b.map(|x| x.sigma2), 2),
            opt(b.map(|x| x.sigma3), 2),
            nees,
            nis,
            opt(e.pcrlb_pos_rmse_m, 2),
            opt(e.efficiency, 2),
            100.0 * e.availability,
            100.0 * e.coasting_epochs as f64 / e.epochs.max(1) as f64,
            modes.join(", ")
        );
    }
    h.push_str("</table></div>\n<p class=\"meta\">Metres. σ-levels are the 68.27/95.45/99.73 % percentiles of the 3-D error over every epoch of every trial (seed 000's convention). ATE and RPE follow the TUM benchmark in ECEF without alignment, RPE over Δ = 1 s, as seed 000 computes them; the aligned ATE first fits each trial's trajectory to the truth by a rigid (Horn) transform. NEES is of the position (3 degrees of freedom, 3 for a consistent filter) with the two-sided 95 % χ² band of its mean; NIS is summed over each epoch's updates, against the summed dimensions (its expectation for a consistent filter; particle filters have none). The PCRLB is the posterior Cramér–Rao bound on the position RMSE (Tichavský, Muravchik &amp; Nehorai 1998) for the estimators whose process model it covers: no unbiased estimator of that model does better, so RMSE / PCRLB is 1 for an efficient one. Every estimator is scored at the same instants (the world's scoring epochs: the GNSS epochs unless <code>[scoring]</code> says otherwise), with the estimate after every batch of the instant. Availability counts the epochs whose estimate used a measurement within the coast limit; coasting, those among them at which the estimator used none.</p>\n");
    across(h, s);
}

/// The spread of the per-trial statistics.
fn across(h: &mut String, s: &Summary) {
    if s.trials < 2 {
        return;
    }
    let iv = |v: Option<[f64; 2]>| {
        v.map_or_else(|| "–".to_string(), |[a, b]| format!("{a:.2} – {b:.2}"))
    };
    h.push_str("<h3>Across trials</h3>\n<table><tr><th>estimator</th><th>trials</th><th>1σ</th><th>2σ</th><th>3σ</th><th>mean</th><th>RMSE</th><th>RMSE ATE</th><th>RMSE RPE</th></tr>\n");
    for e in &s.estimators {
        let a = &e.across_trials;
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&e.name),
            a.trials,
            iv(a.sigma1_ci95_m),
            iv(a.sigma2_ci95_m),
            iv(a.sigma3_ci95_m),
            iv(a.mean_ci95_m),
            iv(a.rmse_ci95_m),
            iv(a.ate_rmse_ci95_m),
            iv(a.rpe_rmse_ci95_m),
        );
    }
    h.push_str("</table>\n<p class=\"meta\">95 % confidence interval (Student t) of the mean over trials of each trial's own statistic: how much the figures above would move with another set of trials. The interval is symmetric: with few trials and a skewed statistic its lower end can fall below zero.</p>\n");
}

fn cdf(h: &mut String, s: &Summary, cdfs: &[Vec<(f64, f64)>]) {
    let mut series = Vec::new();
    for (k, (e, points)) in s.estimators.iter().zip(cdfs).enumerate() {
        if points.is_empty() {
            continue;
        }
        series.push(Series {
            label: &e.name,
            colour: colour(k),
            points: points.clone(),
        });
    }
    let x_scale_note = "error axis logarithmic";
    let chart = Chart {
        title: "Empirical CDF of the 3-D position error",
        x_label: "3-D position error (m)",
        y_label: "share of epochs",
        y_scale: Scale::Linear,
        spans: &[],
        span_label: "",
    };
    // A CDF reads best with the error on a log axis: plot log10(error) on x and label it.
    let log_series: Vec<Series<'_>> = series
        .iter()
        .map(|s| Series {
            label: s.label,
            colour: s.colour,
            points: s
                .points
                .iter()
                .map(|&(x, p)| (if x > 0.0 { x.log10() } else { f64::NAN }, p))
                .collect(),
        })
        .collect();
    let svg = svg::line_chart(
        &Chart {
            x_label: "log10 of the 3-D position error (m): 0 = 1 m, 1 = 10 m, 2 = 100 m",
            ..chart
        },
        &log_series,
    );
    let _ = writeln!(
        h,
        "<h2>Error distribution</h2><figure>{svg}<figcaption>Share of all epochs of all trials with a 3-D error at most x ({x_scale_note}).</figcaption></figure>"
    );
}

fn trajectories(h: &mut String, world: &World, t0: &TrialResult) -> Result<(), String> {
    let overlays: Vec<Overlay<'_>> = t0
        .estimators
        .iter()
        .enumerate()
        .map(|(k, e)| Overlay {
            label: &e.name,
            colour: colour(k),
            points_enu_m: e
                .epochs
                .iter()
                .map(|ep| {
                    ep.est_ecef_m.map(|p| {
                        let enu = world.frame.enu_of_ecef(&nalgebra::Vector3::from(p));
                        [enu.x, enu.y]
                    })
                })
                .collect(),
        })
        .collect();
    let map = map::svg_with(world, &overlays)?;
    let _ = writeln!(
        h,
        "<h2>Trajectories (trial {})</h2><figure>{map}<figcaption>The true path in black; each estimator's estimates as a line (broken where it had none), over the scene. The frame spans the scene and the true path: estimates outside it are clipped.</figcaption></figure>",
        t0.trial
    );
    Ok(())
}

/// Spans of trial `t0` where fewer than four GPS satellites were tracked (a GPS-only
/// receiver cannot fix there).
fn poor_coverage_spans(t0: &TrialResult) -> Vec<(f64, f64)> {
    let mut by_t: std::collections::BTreeMap<u64, (f64, u32)> = Default::default();
    for e in &t0.estimators {
        for ep in &e.epochs {
            let key = ep.t_s.to_bits();
            let slot = by_t.entry(key).or_insert((ep.t_s, 0));
            slot.1 = slot.1.max(ep.n_gps);
        }
    }
    let mut pts: Vec<(f64, u32)> = by_t.into_values().collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    if pts.iter().all(|p| p.1 == 0) {
        return Vec::new();
    }
    let mut spans: Vec<(f64, f64)> = Vec::new();
    for w in pts.windows(2) {
        if w[0].1 < 4 {
            match spans.last_mut() {
                Some(last) if (last.1 - w[0].0).abs() < 1e-9 => last.1 = w[1].0,
                _ => spans.push((w[0].0, w[1].0)),
            }
        }
    }
    spans
}

/// One series per estimator of trial `t0` that has `value` at some epoch, in the world's
/// colours; epochs without a value break the line.
fn time_series<'a>(
    t0: &'a TrialResult,
    value: impl Fn(&EpochRecord) -> Option<f64>,
) -> Vec<Series<'a>> {
    t0.estimators
        .iter()
        .enumerate()
        .filter(|(_, e)| e.epochs.iter().any(|ep| value(ep).is_some()))
        .map(|(k, e)| Series {
            label: &e.name,
            colour: colour(k),
            points: e
                .epochs
                .iter()
                .map(|ep| (ep.t_s, value(ep).unwrap_or(f64::NAN)))
                .collect(),
        })
        .collect()
}

fn error_vs_time(h: &mut String, t0: &TrialResult) {
    let spans = poor_coverage_spans(t0);
    let series = time_series(t0, |ep| ep.err_3d_m);
    let svg = svg::line_chart(
        &Chart {
            title: "3-D position error against time",
            x_label: "time since start (s)",
            y_label: "3-D error (m), log scale",
            y_scale: Scale::Log,
            spans: &spans,
            span_label: "< 4 GPS satellites",
        },
        &series,
    );
    let _ = writeln!(
        h,
        "<h2>Error against time (trial {})</h2><figure>{svg}<figcaption>Shaded: epochs where fewer than four GPS satellites were tracked (blocked by buildings, foliage or a shielding window): a GPS-only receiver has no fix of its own there.</figcaption></figure>",
        t0.trial
    );
}

fn modes(h: &mut String, t0: &TrialResult) {
    let rows: Vec<ModeRow<'_>> = t0
        .estimators
        .iter()
        .filter(|e| e.epochs.iter().any(|ep| ep.mode.is_some()))
        .map(|e| ModeRow {
            label: &e.name,
            epochs: e
                .epochs
                .iter()
                .map(|ep| (ep.t_s, ep.mode.as_deref()))
                .collect(),
        })
        .collect();
    if rows.is_empty() {
        return;
    }
    let svg = svg::mode_timeline("Integration mode chosen at each epoch", &rows);
    let _ = writeln!(
        h,
        "<h2>Modes (trial {})</h2><figure>{svg}<figcaption>The mode each mode-selecting estimator chose (seed 000: A = GPS, B = GPS+DTMB, C = GPS+DTMB+FM; seed 003: by satellite count).</figcaption></figure>",
        t0.trial
    );
}

fn gdop(h: &mut String, t0: &TrialResult) {
    let series = time_series(t0, |ep| ep.gdop);
    if series.is_empty() {
        return;
    }
    let svg = svg::line_chart(
        &Chart {
            title: "GDOP of the ranges each estimator used",
            x_label: "time since start (s)",
            y_label: "GDOP, log scale",
            y_scale: Scale::Log,
            spans: &[],
            span_label: "",
        },
        &series,
    );
    let _ = writeln!(
        h,
        "<h2>Geometry (trial {})</h2><figure>{svg}</figure>",
        t0.trial
    );
}

/// The sky over the trajectory's start during the run: every satellite of the world's
/// systems above the elevation mask, sampled every 30 s.
fn sky(h: &mut String, world: &World) -> Result<(), String> {
    let Some(g) = world.file.sensors.gnss.as_ref() else {
        return Ok(());
    };
    let trajectory = world.build_trajectory(&TrialRng::new(world.file.montecarlo.seed, 0))?;
    let truth = truth_at(
        &world.frame,
        world.start,
        trajectory.as_ref(),
        SimTime::from_seconds(0.0),
    );
    let geo = crate::core::Geodetic::from_ecef(&truth.pos_ecef_m);
    let rot = crate::core::geodesy::ecef_to_enu_rotation(geo.lat_rad, geo.lon_rad);
    let mask = g.elevation_mask_deg.to_radians();
    let steps = ((world.duration_s / 30.0).ceil() as usize).max(1);
    let mut tracks = Vec::new();
    for sat in world.nav.satellites() {
        if !g.systems.contains(&sat.system) {
            continue;
        }
        let az_el: Vec<(f64, f64)> = (0..=steps)
            .filter_map(|k| {
                let t = truth
                    .t
                    .add_seconds(world.duration_s * k as f64 / steps as f64);
                crate::gnss::measurement::satellite_in_view(
                    &world.nav,
                    sat,
                    t,
                    &truth.pos_ecef_m,
                    &rot,
                    mask,
                )
                .map(|(_, _, az, el)| (az, el))
            })
            .collect();
        if !az_el.is_empty() {
            tracks.push(SkyTrack {
                label: sat.to_string(),
                colour: match sat.system {
                    crate::core::System::Gps => colour(0),
                    crate::core::System::Bds => colour(2),
                    _ => colour(4),
                },
                az_el_rad: az_el,
            });
        }
    }
    if tracks.is_empty() {
        return Ok(());
    }
    let svg = svg::sky_plot("Satellites above the mask", &tracks);
    let _ = writeln!(
        h,
        "<h2>Sky</h2><figure>{svg}<figcaption>Satellites above the {:.0}° mask at the start point during the run (GPS blue, BeiDou red); the dot marks the end of each track. Buildings are not drawn: see the error plot's shading for what they blocked.</figcaption></figure>",
        g.elevation_mask_deg
    );
    Ok(())
}
