//! `report.html`: one self-contained page per run, readable in any browser offline.
//!
//! It holds the papers' kind of table (σ-levels, ATE/RPE, NEES, availability, modes), the
//! empirical CDF of every estimator's error, trial 0's trajectories over the scene map,
//! its error against time with the spans of poor satellite coverage shaded, the mode
//! timeline, the GDOP and a sky plot of the satellites. Every chart is inline SVG
//! ([`svg`]); there is no script, no external style sheet and no font to fetch. Every
//! chart is also a standalone SVG document ([`Report::figures`]), which the run writes
//! under `report/figures/` for papers.

pub mod map;
pub mod svg;

use crate::core::{SimTime, TrialRng};
use crate::engine::trial::{truth_at, EpochRecord, TrialResult};
use crate::metrics::summary::Summary;
use crate::world::World;
use map::Overlay;
use std::fmt::Write;
use svg::{colour, escape, style, Chart, ModeRow, Scale, Series, SkyTrack};

const STYLE: &str = "body{font-family:sans-serif;max-width:1100px;margin:1.5em auto;padding:0 1em;color:#222}
h1{font-size:1.5em}h2{font-size:1.15em;margin-top:1.8em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;font-size:0.85em;max-width:100%}th,td{padding:3px 6px;border-bottom:1px solid #e3e3e3;text-align:right;vertical-align:top}
th{font-weight:600;overflow-wrap:break-word}td{white-space:nowrap}td.wrap{white-space:normal}
th:first-child,td:first-child{text-align:left}td:first-child{white-space:normal}th{background:#f3f3f3}.meta{color:#555;font-size:0.9em}
.flag{color:#b2182b;font-weight:bold}.band{color:#666;font-size:0.9em}
@media (max-width:900px){th,td{padding:2px 3px}table{font-size:0.8em}}
figure{margin:0.8em 0}figcaption{color:#555;font-size:0.85em;max-width:860px}svg{max-width:100%;height:auto}";

/// A rendered report: the page, and each of its charts as a standalone SVG document.
pub struct Report {
    pub html: String,
    /// `(file name, SVG document)` in page order, e.g. `("error-cdf.svg", …)`.
    pub figures: Vec<(String, String)>,
}

/// The page being written and the figures drawn on it so far.
struct Page {
    h: String,
    figures: Vec<(String, String)>,
}

/// A curve of `(x, y)` points.
pub type Curve = Vec<(f64, f64)>;

/// What the report draws across trials, per estimator in the world's order.
#[derive(Clone, Debug, Default)]
pub struct Curves {
    /// The empirical CDF of the 3-D error, `(error_m, share)`, thinned to [`crate::montecarlo::reduce::CDF_POINTS`]
    /// (empty without an estimate).
    pub cdfs: Vec<Curve>,
    /// `(t_s, rmse_m)`: at each scored instant, the RMSE of the 3-D error across the trials
    /// that had an estimate then, `√(Σ e² / n)` (empty without an estimate).
    pub rmse_vs_time: Vec<Curve>,
    /// The PCRLB on that RMSE at each epoch ([`crate::world::bound::PositionBound`]), for
    /// the estimators whose model it covers.
    pub pcrlb_vs_time: Vec<Option<Curve>>,
}

impl Page {
    /// A section holding one chart: a heading, the inline SVG and its caption; the chart
    /// is also kept as `name.svg`.
    fn figure(&mut self, name: &str, heading: &str, svg: String, caption: &str) {
        let caption = if caption.is_empty() {
            String::new()
        } else {
            format!("<figcaption>{caption}</figcaption>")
        };
        let _ = writeln!(self.h, "<h2>{heading}</h2><figure>{svg}{caption}</figure>");
        self.figures.push((format!("{name}.svg"), svg));
    }
}

/// Renders the report of a run from its summary, its first trial (whose trajectories are
/// drawn) and the curves taken across every trial
/// ([`Curves`]: error CDFs, RMSE against time, the PCRLB).
///
/// # Errors
/// When the world's trajectory or map cannot be built.
pub fn html(
    world: &World,
    summary: &Summary,
    first: Option<&TrialResult>,
    curves: &Curves,
) -> Result<String, String> {
    render(world, summary, first, curves).map(|r| r.html)
}

/// [`html`] and each of the page's charts as its own SVG document.
///
/// # Errors
/// When the world's trajectory or map cannot be built.
pub fn render(
    world: &World,
    summary: &Summary,
    first: Option<&TrialResult>,
    curves: &Curves,
) -> Result<Report, String> {
    let mut page = Page {
        h: String::new(),
        figures: Vec::new(),
    };
    let h = &mut page.h;
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
    table(h, summary);
    cdf(&mut page, summary, &curves.cdfs);
    rmse_vs_time(&mut page, summary, curves);
    if let Some(t0) = first {
        trajectories(&mut page, world, t0)?;
        error_vs_time(&mut page, t0);
        modes(&mut page, t0);
        gdop(&mut page, t0);
    }
    sky(&mut page, world)?;
    let h = &mut page.h;
    if !summary.warnings.is_empty() {
        h.push_str("<h2>Warnings</h2><ul>\n");
        for w in &summary.warnings {
            let _ = writeln!(h, "<li>{}</li>", escape(w));
        }
        h.push_str("</ul>\n");
    }
    h.push_str("</body></html>\n");
    Ok(Report {
        html: page.h,
        figures: page.figures,
    })
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.filter(|x| x.is_finite())
        .map_or_else(|| "–".into(), |x| format!("{x:.digits$}"))
}

/// Whether an estimator's filter is over-confident: its mean position NEES lies above
/// the upper end of its 95 % band (its covariance claims more accuracy than it has).
fn over_confident(e: &crate::metrics::summary::EstimatorSummary) -> bool {
    e.nees.as_ref().is_some_and(|n| n.mean > n.band_hi)
}

/// The estimator's name with its flags: † when it reset (numerical failures), ‡ when it
/// is over-confident.
fn name_cell(e: &crate::metrics::summary::EstimatorSummary) -> String {
    let mut flags = String::new();
    if e.numerical_failures > 0 {
        flags.push('†');
    }
    if over_confident(e) {
        flags.push('‡');
    }
    if flags.is_empty() {
        format!("<td>{}</td>", escape(&e.name))
    } else {
        format!(
            "<td>{} <span class=\"flag\">{flags}</span></td>",
            escape(&e.name)
        )
    }
}

/// The papers' table, in two parts that each fit the page: the σ-levels and moments of
/// the 3-D and horizontal error, then the trajectory and consistency statistics of
/// `summary.json`; with resets and over-confident filters flagged.
fn table(h: &mut String, s: &Summary) {
    h.push_str("<h2>Position error</h2>\n<table><tr><th>estimator</th><th>1σ</th><th>2σ</th><th>3σ</th><th>mean</th><th>RMSE</th><th>max</th><th>horiz. 1σ</th><th>horiz. 2σ</th><th>horiz. 3σ</th><th>avail&shy;ability</th><th>coast&shy;ing</th></tr>\n");
    for e in &s.estimators {
        let a = e.error_3d_m.as_ref();
        let b = e.error_h_m.as_ref();
        let _ = writeln!(
            h,
            "<tr>{}<td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.1} %</td><td>{:.1} %</td></tr>",
            name_cell(e),
            opt(a.map(|x| x.sigma1), 2),
            opt(a.map(|x| x.sigma2), 2),
            opt(a.map(|x| x.sigma3), 2),
            opt(a.map(|x| x.mean), 2),
            opt(a.map(|x| x.rmse), 2),
            opt(a.map(|x| x.max), 2),
            opt(b.map(|x| x.sigma1), 2),
            opt(b.map(|x| x.sigma2), 2),
            opt(b.map(|x| x.sigma3), 2),
            100.0 * e.availability,
            100.0 * e.coasting_epochs as f64 / e.epochs.max(1) as f64,
        );
    }
    h.push_str("</table>\n<p class=\"meta\">Metres. σ-levels are the 68.27/95.45/99.73 % percentiles of the 3-D error over every epoch of every trial (seed 000's convention); horiz., of the horizontal error. Every estimator is scored at the same instants (the world's scoring epochs: the GNSS epochs unless <code>[scoring]</code> says otherwise), with the estimate after every batch of the instant. Availability counts the epochs whose estimate used a measurement within the coast limit; coasting, those among them at which the estimator used none.</p>\n");
    h.push_str("<h3>Trajectory and consistency</h3>\n<table><tr><th>estimator</th><th>mean ATE</th><th>RMSE ATE</th><th>mean RPE</th><th>RMSE RPE</th><th>RMSE ATE aligned</th><th>mean NEES [95 % band]</th><th>mean NIS / dof</th><th>PCRLB on RMSE</th><th>RMSE / PCRLB</th><th>resets</th><th>modes</th></tr>\n");
    for e in &s.estimators {
        // The mean over its band, on two lines: the column stays narrow.
        let nees = e.nees.as_ref().map_or_else(
            || "–".to_string(),
            |n| {
                let mean = if n.mean > n.band_hi {
                    format!("<span class=\"flag\">{} ‡</span>", opt(Some(n.mean), 2))
                } else {
                    opt(Some(n.mean), 2)
                };
                format!(
                    "{mean}<br><span class=\"band\">[{:.2}, {:.2}]</span>",
                    n.band_lo, n.band_hi
                )
            },
        );
        let nis = e.nis.as_ref().map_or_else(
            || "–".to_string(),
            |n| format!("{:.2} / {:.2}", n.mean, n.dof),
        );
        let resets = if e.numerical_failures > 0 {
            format!("<span class=\"flag\">{} †</span>", e.numerical_failures)
        } else {
            "0".to_string()
        };
        let modes: Vec<String> = e
            .modes
            .iter()
            .map(|(m, f)| format!("{} {:.0}&nbsp;%", escape(m), 100.0 * f))
            .collect();
        let _ = writeln!(
            h,
            "<tr>{}<td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td class=\"wrap\">{}</td></tr>",
            name_cell(e),
            opt(e.ate_m.as_ref().map(|x| x.mean), 2),
            opt(e.ate_m.as_ref().map(|x| x.rmse), 2),
            opt(e.rpe_m.as_ref().map(|x| x.mean), 2),
            opt(e.rpe_m.as_ref().map(|x| x.rmse), 2),
            opt(e.ate_aligned_m.as_ref().map(|x| x.rmse), 2),
            nees,
            nis,
            opt(e.pcrlb_pos_rmse_m, 2),
            opt(e.efficiency, 2),
            resets,
            modes.join("<br>")
        );
    }
    let _ = write!(
        h,
        "</table>\n<p class=\"meta\">Metres. ATE and RPE follow the TUM benchmark in ECEF without alignment, RPE over Δ = {} s (the TUM benchmark and seed 000 use 1 s); the aligned ATE first fits each trial's trajectory to the truth by a rigid (Horn) transform. NEES is of the position (3 degrees of freedom, 3 for a consistent filter) with the two-sided 95 % χ² band of its mean; NIS is summed over each epoch's updates, against the summed dimensions (its expectation for a consistent filter; particle filters have none). The PCRLB is the posterior Cramér–Rao bound on the position RMSE (Tichavský, Muravchik &amp; Nehorai 1998) for the estimators whose process model it covers: no unbiased estimator of that model does better, so RMSE / PCRLB is 1 for an efficient one.</p>\n",
        s.rpe_delta_s
    );
    flags(h, s);
    segments(
        h,
        s,
        "By segment",
        |e| &e.segments,
        "The 3-D error of the epochs inside each <code>[[shielding]]</code> window of the world and of those outside every window: where each source helps.",
    );
    segments(
        h,
        s,
        "Outdoors and indoors",
        |e| &e.environments,
        "The 3-D error of the epochs whose truth was outside every building and indoor zone of the world's <code>[scene]</code>, and of those whose truth was inside one.",
    );
    across(h, s);
}

/// The 3-D error in each segment `of` gives an estimator (the shielding windows and the
/// rest, or outdoors and indoors), under `title`, with `about` below the table.
fn segments(
    h: &mut String,
    s: &Summary,
    title: &str,
    of: impl Fn(
        &crate::metrics::summary::EstimatorSummary,
    ) -> &Vec<crate::metrics::summary::SegmentStats>,
    about: &str,
) {
    let Some(first) = s.estimators.iter().map(&of).find(|g| !g.is_empty()) else {
        return;
    };
    let _ = write!(h, "<h3>{title}</h3>\n<table><tr><th>estimator</th>");
    for g in first {
        let _ = write!(h, "<th>{} RMSE</th><th>2σ</th>", escape(&g.label));
    }
    h.push_str("</tr>\n");
    for e in &s.estimators {
        h.push_str("<tr>");
        h.push_str(&name_cell(e));
        for g in of(e) {
            let x = g.error_3d_m.as_ref();
            let _ = write!(
                h,
                "<td>{}</td><td>{}</td>",
                opt(x.map(|x| x.rmse), 2),
                opt(x.map(|x| x.sigma2), 2)
            );
        }
        h.push_str("</tr>\n");
    }
    let _ = writeln!(h, "</table>\n<p class=\"meta\">Metres. {about}</p>");
}

/// The footnotes of the flags, naming each flagged estimator and what happened.
fn flags(h: &mut String, s: &Summary) {
    let reset: Vec<String> = s
        .estimators
        .iter()
        .filter(|e| e.numerical_failures > 0)
        .map(|e| {
            let first = e
                .first_failures
                .first()
                .map(|f| format!(", first in trial {} at t = {:.1} s", f.trial, f.t_s))
                .unwrap_or_default();
            format!(
                "{} ({} reset(s){first})",
                escape(&e.name),
                e.numerical_failures
            )
        })
        .collect();
    let over: Vec<String> = s
        .estimators
        .iter()
        .filter(|e| over_confident(e))
        .filter_map(|e| {
            e.nees.as_ref().map(|n| {
                format!(
                    "{} (mean NEES {:.2} against {:.2} – {:.2})",
                    escape(&e.name),
                    n.mean,
                    n.band_lo,
                    n.band_hi
                )
            })
        })
        .collect();
    if reset.is_empty() && over.is_empty() {
        return;
    }
    h.push_str("<ul class=\"meta\">\n");
    if !reset.is_empty() {
        let _ = writeln!(
            h,
            "<li><span class=\"flag\">†</span> Reset: the estimator hit a numerical failure (a covariance no longer positive definite, every particle weight zero) and re-initialised, so its figures include the re-convergence: {}.</li>",
            reset.join("; ")
        );
    }
    if !over.is_empty() {
        let _ = writeln!(
            h,
            "<li><span class=\"flag\">‡</span> Over-confident: the mean NEES lies above its 95 % band, so the filter's covariance claims more accuracy than its estimates have (its σ are too small for gating or fusion downstream): {}.</li>",
            over.join("; ")
        );
    }
    h.push_str("</ul>\n");
}

/// The spread of the per-trial statistics.
fn across(h: &mut String, s: &Summary) {
    if s.trials < 2 {
        return;
    }
    let iv = |v: Option<[f64; 2]>| {
        v.map_or_else(
            || "–".to_string(),
            // On a narrow page an interval breaks after its dash, nowhere else.
            |[a, b]| format!("{}&nbsp;– {}", sig3(a), sig3(b)),
        )
    };
    h.push_str("<h3>Across trials</h3>\n<table><tr><th>estimator</th><th>trials</th><th>1σ</th><th>2σ</th><th>3σ</th><th>mean</th><th>RMSE</th><th>RMSE ATE</th><th>RMSE RPE</th></tr>\n");
    for e in &s.estimators {
        let a = &e.across_trials;
        let _ = writeln!(
            h,
            "<tr>{}<td>{}</td><td class=\"wrap\">{}</td><td class=\"wrap\">{}</td><td class=\"wrap\">{}</td><td class=\"wrap\">{}</td><td class=\"wrap\">{}</td><td class=\"wrap\">{}</td><td class=\"wrap\">{}</td></tr>",
            name_cell(e),
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
    h.push_str("</table>\n<p class=\"meta\">Metres. 95 % confidence interval of the mean over trials of each trial's own statistic: how much the figures above would move with another set of trials. Every statistic here is positive, so the interval is taken on the log scale (a Student t interval of the log of the mean, by the delta method): x̄ · exp(∓ t·s/(√n·x̄)), which never goes below zero and is asymmetric where the spread is large against the mean. <code>summary.json</code> holds the same intervals (availability's on the logit scale).</p>\n");
}

/// Three significant digits (at least two decimals below 10), for interval ends spanning
/// orders of magnitude.
fn sig3(v: f64) -> String {
    if !v.is_finite() {
        "–".into()
    } else if v.abs() >= 100.0 {
        format!("{v:.0}")
    } else if v.abs() >= 10.0 {
        format!("{v:.1}")
    } else if v.abs() >= 0.01 || v == 0.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.1e}")
    }
}

/// The style of the PCRLB curves: black, a dash pattern of its own, no estimator's.
const BOUND_STYLE: svg::Style = svg::Style {
    colour: "#000000",
    dash: "3,4",
    marker: svg::Marker::Cross,
};

/// The RMSE across trials at each instant for every estimator, and under it the PCRLB of
/// the estimators whose model it covers: one curve per distinct bound, naming the
/// estimators that share it. Drawn when there are at least two trials (with one, the
/// RMSE is the error of the chart below).
fn rmse_vs_time(page: &mut Page, s: &Summary, curves: &Curves) {
    if s.trials < 2 {
        return;
    }
    let mut series = estimator_series(s, &curves.rmse_vs_time);
    // Estimators of one model and one source set share one bound; draw it once.
    let mut bounds: Vec<(&Curve, Vec<&str>)> = Vec::new();
    for (e, b) in s.estimators.iter().zip(&curves.pcrlb_vs_time) {
        let Some(b) = b else { continue };
        match bounds.iter_mut().find(|(c, _)| *c == b) {
            Some((_, names)) => names.push(&e.name),
            None => bounds.push((b, vec![&e.name])),
        }
    }
    if series.is_empty() {
        return;
    }
    // A legend entry names one estimator at most, so that it fits beside the chart; the
    // caption lists every estimator under each bound.
    let labels: Vec<String> = if bounds.len() == 1 {
        vec!["PCRLB".to_string()]
    } else {
        bounds
            .iter()
            .map(|(_, names)| format!("PCRLB · {}", names[0]))
            .collect()
    };
    let under: Vec<String> = bounds
        .iter()
        .zip(&labels)
        .map(|((_, names), label)| format!("{label}: {}", escape(&names.join(", "))))
        .collect();
    for ((points, _), label) in bounds.iter().zip(&labels) {
        series.push(Series {
            label,
            style: BOUND_STYLE,
            points: (*points).clone(),
        });
    }
    let svg = svg::line_chart(
        &Chart {
            title: "RMSE of the 3-D position across trials against time",
            x_label: "time since start (s)",
            y_label: "RMSE across trials (m), log scale",
            x_scale: Scale::Linear,
            y_scale: Scale::Log,
            spans: &[],
            span_label: "",
        },
        &series,
    );
    let caption = if labels.is_empty() {
        format!(
            "At each instant, the root mean square of the 3-D error over the {} trials that had an estimate then.",
            s.trials
        )
    } else {
        format!(
            "At each instant, the root mean square of the 3-D error over the {} trials that had an estimate then. Black dashes: the posterior Cramér–Rao bound on that RMSE (Tichavský, Muravchik &amp; Nehorai 1998) from the world's process model and emitters along the trials' truth, below which no unbiased estimator of that model goes ({}).",
            s.trials,
            under.join("; ")
        )
    };
    page.figure("rmse-vs-time", "RMSE against time", svg, &caption);
}

/// One series per estimator with a non-empty curve, in the world's styles.
fn estimator_series<'a>(s: &'a Summary, curves: &[Curve]) -> Vec<Series<'a>> {
    s.estimators
        .iter()
        .zip(curves)
        .enumerate()
        .filter(|(_, (_, points))| !points.is_empty())
        .map(|(k, (e, points))| Series {
            label: &e.name,
            style: style(k),
            points: points.clone(),
        })
        .collect()
}

fn cdf(page: &mut Page, s: &Summary, cdfs: &[Curve]) {
    let series = estimator_series(s, cdfs);
    // A CDF of errors spanning decades reads best with the error on a log axis, its
    // ticks labelled in metres.
    let svg = svg::line_chart(
        &Chart {
            title: "Empirical CDF of the 3-D position error",
            x_label: "3-D position error (m), log scale",
            y_label: "share of epochs",
            x_scale: Scale::Log,
            y_scale: Scale::Linear,
            spans: &[],
            span_label: "",
        },
        &series,
    );
    page.figure(
        "error-cdf",
        "Error distribution",
        svg,
        "Share of all epochs of all trials with a 3-D error at most x (x on a logarithmic axis in metres).",
    );
}

fn trajectories(page: &mut Page, world: &World, t0: &TrialResult) -> Result<(), String> {
    let overlays: Vec<Overlay<'_>> = t0
        .estimators
        .iter()
        .enumerate()
        .map(|(k, e)| Overlay {
            label: &e.name,
            style: style(k),
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
    page.figure(
        "trajectories",
        &format!("Trajectories (trial {})", t0.trial),
        map,
        "The true path in black; each estimator's estimates as a line (broken where it had none), over the scene. The frame spans the scene and the true path: estimates outside it are clipped. Axes in metres east and north of the world's origin.",
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
            style: style(k),
            points: e
                .epochs
                .iter()
                .map(|ep| (ep.t_s, value(ep).unwrap_or(f64::NAN)))
                .collect(),
        })
        .collect()
}

fn error_vs_time(page: &mut Page, t0: &TrialResult) {
    let spans = poor_coverage_spans(t0);
    let series = time_series(t0, |ep| ep.err_3d_m);
    let svg = svg::line_chart(
        &Chart {
            title: "3-D position error against time",
            x_label: "time since start (s)",
            y_label: "3-D error (m), log scale",
            x_scale: Scale::Linear,
            y_scale: Scale::Log,
            spans: &spans,
            span_label: "< 4 GPS satellites",
        },
        &series,
    );
    page.figure(
        "error-vs-time",
        &format!("Error against time (trial {})", t0.trial),
        svg,
        "Shaded: epochs where fewer than four GPS satellites were tracked (blocked by buildings, foliage or a shielding window): a GPS-only receiver has no fix of its own there.",
    );
}

fn modes(page: &mut Page, t0: &TrialResult) {
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
    page.figure(
        "modes",
        &format!("Modes (trial {})", t0.trial),
        svg,
        "The mode each mode-selecting estimator chose (seed 000: A = GPS, B = GPS+DTMB, C = GPS+DTMB+FM; seed 003: by satellite count).",
    );
}

fn gdop(page: &mut Page, t0: &TrialResult) {
    let series = time_series(t0, |ep| ep.gdop);
    if series.is_empty() {
        return;
    }
    let svg = svg::line_chart(
        &Chart {
            title: "GDOP of the ranges each estimator used",
            x_label: "time since start (s)",
            y_label: "GDOP, log scale",
            x_scale: Scale::Linear,
            y_scale: Scale::Log,
            spans: &[],
            span_label: "",
        },
        &series,
    );
    page.figure("gdop", &format!("Geometry (trial {})", t0.trial), svg, "");
}

/// The sky over the trajectory's start during the run: every satellite of the world's
/// systems above the elevation mask, sampled every 30 s.
fn sky(page: &mut Page, world: &World) -> Result<(), String> {
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
                colour: system_colour(sat.system),
                az_el_rad: az_el,
            });
        }
    }
    if tracks.is_empty() {
        return Ok(());
    }
    let mut legend: Vec<(&str, &str)> = Vec::new();
    for (system, name) in [
        (crate::core::System::Gps, "GPS"),
        (crate::core::System::Bds, "BeiDou"),
    ] {
        if g.systems.contains(&system) {
            legend.push((name, system_colour(system)));
        }
    }
    let svg = svg::sky_plot("Satellites above the mask", &tracks, &legend);
    page.figure(
        "sky",
        "Sky",
        svg,
        &format!(
            "Satellites above the {:.0}° mask at the start point during the run; the dot marks the end of each track. Buildings are not drawn: see the error plot's shading for what they blocked.",
            g.elevation_mask_deg
        ),
    );
    Ok(())
}

/// The sky plot's colour of a satellite system.
fn system_colour(system: crate::core::System) -> &'static str {
    match system {
        crate::core::System::Gps => colour(0),
        crate::core::System::Bds => colour(1),
        _ => colour(2),
    }
}
