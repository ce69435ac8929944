//! The report's charts as plain SVG: line charts with shaded spans, a mode timeline and a
//! sky plot.
//!
//! Hand-written rather than drawn with `plotters`: the report embeds every chart inline in
//! one HTML file, and the SVG `plotters` emits carries fixed pixel fonts and no `viewBox`
//! scaling; a few hundred lines of our own give charts that scale with the page, stay small
//! and diff cleanly.

use std::fmt::Write;

/// Categorical colours (Tableau 10), one per estimator in world order.
pub const PALETTE: [&str; 10] = [
    "#4e79a7", "#f28e2b", "#e15759", "#76b7b2", "#59a14f", "#edc948", "#b07aa1", "#ff9da7",
    "#9c755f", "#bab0ac",
];

/// The colour of series `k`.
pub fn colour(k: usize) -> &'static str {
    PALETTE[k % PALETTE.len()]
}

/// Escapes text for SVG and HTML.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// One line of a chart: `(x, y)` points; a non-finite `y` breaks the line.
pub struct Series<'a> {
    pub label: &'a str,
    pub colour: &'a str,
    pub points: Vec<(f64, f64)>,
}

/// Axis scaling.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    Linear,
    /// Base-10 logarithmic (values ≤ 0 are left out).
    Log,
}

/// A line chart's frame and labels.
pub struct Chart<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub y_scale: Scale,
    /// Shaded x-intervals (e.g. spans with fewer than four satellites in view), with
    /// their legend text.
    pub spans: &'a [(f64, f64)],
    pub span_label: &'a str,
}

const W: f64 = 860.0;
const H: f64 = 330.0;
const L: f64 = 70.0;
const R: f64 = 170.0;
const T: f64 = 34.0;
const B: f64 = 46.0;

/// "Nice" tick positions (1-2-5 steps) covering `[lo, hi]`.
pub fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return vec![lo];
    }
    let raw = (hi - lo) / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        // A relative tolerance, so that a range of 0.6 in three steps is 0.2 each, not 0.5.
        .find(|s| *s >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0 * mag);
    let start = (lo / step).ceil() as i64;
    let end = (hi / step).floor() as i64;
    // Multiples of the integer mantissa, scaled by an exact power of ten, so that tick
    // values print as 0.6 rather than 0.6000000000000001.
    let mantissa = (step / mag).round();
    (start..=end)
        .map(|k| {
            let v = k as f64 * mantissa;
            if mag < 1.0 {
                v / (1.0 / mag).round()
            } else {
                v * mag
            }
        })
        .collect()
}

fn fmt_tick(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        format!("{v:.0e}")
    } else if a >= 10.0 || (v - v.round()).abs() < 1e-9 {
        format!("{v:.0}")
    } else if a >= 1.0 {
        format!("{v:.1}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').to_string()
    }
}

/// A line chart of `series` as an inline SVG element.
pub fn line_chart(c: &Chart<'_>, series: &[Series<'_>]) -> String {
    let tr = |y: f64| match c.y_scale {
        Scale::Linear => y,
        Scale::Log => {
            if y > 0.0 {
                y.log10()
            } else {
                f64::NAN
            }
        }
    };
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for s in series {
        for &(x, y) in &s.points {
            let y = tr(y);
            if x.is_finite() && y.is_finite() {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
    }
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {W} {H}" width="{W}" height="{H}" font-family="sans-serif" font-size="11" role="img"><title>{}</title>"#,
        escape(c.title)
    );
    let _ = writeln!(
        svg,
        r##"<text x="{L}" y="20" font-size="14" font-weight="bold">{}</text>"##,
        escape(c.title)
    );
    if x0 > x1 {
        let _ = writeln!(
            svg,
            r##"<text x="{}" y="{}" fill="#777">no data</text></svg>"##,
            W / 2.0,
            H / 2.0
        );
        return svg;
    }
    if c.y_scale == Scale::Linear {
        y0 = y0.min(0.0);
    }
    if (x1 - x0).abs() < 1e-12 {
        x1 = x0 + 1.0;
    }
    if (y1 - y0).abs() < 1e-12 {
        y1 = y0 + 1.0;
    }
    let pad = 0.04 * (y1 - y0);
    let (y0, y1) = (
        if c.y_scale == Scale::Linear && y0 == 0.0 {
            0.0
        } else {
            y0 - pad
        },
        y1 + pad,
    );
    let px = |x: f64| L + (x - x0) / (x1 - x0) * (W - L - R);
    let py = |y: f64| H - B - (y - y0) / (y1 - y0) * (H - T - B);
    for &(a, b) in c.spans {
        let (a, b) = (a.max(x0), b.min(x1));
        if b > a {
            let _ = writeln!(
                svg,
                r##"<rect x="{:.1}" y="{T}" width="{:.1}" height="{:.1}" fill="#999" fill-opacity="0.18"/>"##,
                px(a),
                (px(b) - px(a)).max(0.8),
                H - T - B
            );
        }
    }
    // Axes, grid and ticks.
    let _ = writeln!(
        svg,
        r##"<rect x="{L}" y="{T}" width="{:.1}" height="{:.1}" fill="none" stroke="#444"/>"##,
        W - L - R,
        H - T - B
    );
    for t in ticks(x0, x1, 8) {
        let x = px(t);
        let _ = writeln!(
            svg,
            r##"<line x1="{x:.1}" y1="{T}" x2="{x:.1}" y2="{:.1}" stroke="#ddd"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
            H - B,
            H - B + 14.0,
            fmt_tick(t)
        );
    }
    let yt = match c.y_scale {
        Scale::Linear => ticks(y0, y1, 6),
        Scale::Log => {
            let decades: Vec<f64> = (y0.floor() as i64..=y1.ceil() as i64)
                .map(|k| k as f64)
                .collect();
            // Over less than two decades the powers of ten alone leave the axis bare:
            // add the 2s and 5s.
            let mults: &[f64] = if y1 - y0 < 2.0 {
                &[1.0, 2.0, 5.0]
            } else {
                &[1.0]
            };
            let t: Vec<f64> = decades
                .iter()
                .flat_map(|d| mults.iter().map(move |m| d + m.log10()))
                .filter(|t| (y0..=y1).contains(t))
                .collect();
            if t.len() >= 2 {
                t
            } else {
                // Less than a 1-2-5 step wide (a GDOP between 3 and 4.5): ticks of the
                // values themselves.
                ticks(10f64.powf(y0), 10f64.powf(y1), 4)
                    .into_iter()
                    .filter(|v| *v > 0.0)
                    .map(f64::log10)
                    .collect()
            }
        }
    };
    for t in yt {
        let y = py(t);
        let label = match c.y_scale {
            Scale::Linear => fmt_tick(t),
            Scale::Log => fmt_tick(10f64.powf(t)),
        };
        let _ = writeln!(
            svg,
            r##"<line x1="{L}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{label}</text>"##,
            W - R,
            L - 5.0,
            y + 4.0
        );
    }
    let _ = writeln!(
        svg,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text><text transform="translate(16 {:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
        L + 0.5 * (W - L - R),
        H - 10.0,
        escape(c.x_label),
        T + 0.5 * (H - T - B),
        escape(c.y_label)
    );
    let _ = writeln!(
        svg,
        r#"<clipPath id="clip-{0}"><rect x="{L}" y="{T}" width="{1:.1}" height="{2:.1}"/></clipPath><g clip-path="url(#clip-{0})">"#,
        clip_id(c.title),
        W - L - R,
        H - T - B
    );
    for s in series {
        let mut d = String::new();
        let mut pen_up = true;
        for &(x, y) in &s.points {
            let y = tr(y);
            if x.is_finite() && y.is_finite() {
                let _ = write!(
                    d,
                    "{}{:.1},{:.1} ",
                    if pen_up { "M" } else { "L" },
                    px(x),
                    py(y)
                );
                pen_up = false;
            } else {
                pen_up = true;
            }
        }
        let _ = writeln!(
            svg,
            r#"<path d="{}" fill="none" stroke="{}" stroke-width="1.5"/>"#,
            d.trim_end(),
            s.colour
        );
    }
    svg.push_str("</g>\n");
    let lx = W - R + 12.0;
    for (k, s) in series.iter().enumerate() {
        let y = T + 8.0 + 16.0 * k as f64;
        let _ = writeln!(
            svg,
            r#"<line x1="{lx:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{}" stroke-width="3"/><text x="{:.1}" y="{:.1}">{}</text>"#,
            lx + 18.0,
            s.colour,
            lx + 23.0,
            y + 4.0,
            escape(s.label)
        );
    }
    if !c.spans.is_empty() {
        let y = T + 8.0 + 16.0 * series.len() as f64;
        let _ = writeln!(
            svg,
            r##"<rect x="{lx:.1}" y="{:.1}" width="18" height="10" fill="#999" fill-opacity="0.35"/><text x="{:.1}" y="{:.1}">{}</text>"##,
            y - 5.0,
            lx + 23.0,
            y + 4.0,
            escape(c.span_label)
        );
    }
    svg.push_str("</svg>\n");
    svg
}

/// An id for a chart's clip path, unique per title within a report.
fn clip_id(title: &str) -> String {
    title
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect()
}

/// One timeline row: an estimator's mode at each epoch time.
pub struct ModeRow<'a> {
    pub label: &'a str,
    pub epochs: Vec<(f64, Option<&'a str>)>,
}

/// Each estimator's mode over time as coloured bands, one row per estimator.
pub fn mode_timeline(title: &str, rows: &[ModeRow<'_>]) -> String {
    let mut modes: Vec<&str> = rows
        .iter()
        .flat_map(|r| r.epochs.iter().filter_map(|e| e.1))
        .collect();
    modes.sort_unstable();
    modes.dedup();
    let (t0, t1) = rows
        .iter()
        .flat_map(|r| r.epochs.iter().map(|e| e.0))
        .fold((f64::MAX, f64::MIN), |(a, b), t| (a.min(t), b.max(t)));
    let row_h = 26.0;
    let h = T + B + row_h * rows.len() as f64;
    let left = 150.0;
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {W} {h}" width="{W}" height="{h}" font-family="sans-serif" font-size="11" role="img"><title>{0}</title><text x="{left}" y="20" font-size="14" font-weight="bold">{0}</text>"#,
        escape(title)
    );
    if t1 <= t0 {
        svg.push_str("</svg>\n");
        return svg;
    }
    let px = |t: f64| left + (t - t0) / (t1 - t0) * (W - left - R);
    for (k, r) in rows.iter().enumerate() {
        let y = T + row_h * k as f64;
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"#,
            left - 6.0,
            y + 16.0,
            escape(r.label)
        );
        // One band per run of epochs in the same mode (not one per epoch: adjacent
        // rectangles leave hairline seams in most renderers).
        let mut k = 0;
        while k + 1 < r.epochs.len() {
            let mode = r.epochs[k].1;
            let mut j = k + 1;
            while j + 1 < r.epochs.len() && r.epochs[j].1 == mode {
                j += 1;
            }
            if let Some(m) = mode {
                let idx = modes.iter().position(|x| *x == m).unwrap_or(0);
                let _ = writeln!(
                    svg,
                    r#"<rect x="{:.2}" y="{:.1}" width="{:.2}" height="{:.1}" fill="{}"/>"#,
                    px(r.epochs[k].0),
                    y + 4.0,
                    (px(r.epochs[j].0) - px(r.epochs[k].0)).max(0.5),
                    row_h - 8.0,
                    colour(idx + 4)
                );
            }
            k = j;
        }
    }
    let ya = T + row_h * rows.len() as f64;
    for t in ticks(t0, t1, 8) {
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            px(t),
            ya + 14.0,
            fmt_tick(t)
        );
    }
    let _ = writeln!(
        svg,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">time since start (s)</text>"#,
        left + 0.5 * (W - left - R),
        ya + 32.0
    );
    for (k, m) in modes.iter().enumerate() {
        let y = T + 8.0 + 16.0 * k as f64;
        let lx = W - R + 12.0;
        let _ = writeln!(
            svg,
            r#"<rect x="{lx:.1}" y="{:.1}" width="18" height="10" fill="{}"/><text x="{:.1}" y="{:.1}">mode {}</text>"#,
            y - 5.0,
            colour(k + 4),
            lx + 23.0,
            y + 4.0,
            escape(m)
        );
    }
    svg.push_str("</svg>\n");
    svg
}

/// A satellite's track across the sky: `(azimuth, elevation)` in radians.
pub struct SkyTrack {
    pub label: String,
    pub colour: &'static str,
    pub az_el_rad: Vec<(f64, f64)>,
}

/// A polar sky plot: north up, east right, zenith at the centre, the horizon at the rim.
pub fn sky_plot(title: &str, tracks: &[SkyTrack]) -> String {
    let size = 420.0;
    let (cx, cy, r) = (size / 2.0, size / 2.0 + 10.0, size / 2.0 - 30.0);
    let at = |az: f64, el: f64| {
        let rho = r * (1.0 - el / std::f64::consts::FRAC_PI_2);
        (cx + rho * az.sin(), cy - rho * az.cos())
    };
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {size} {0}" width="{size}" height="{0}" font-family="sans-serif" font-size="10" role="img"><title>{1}</title><text x="8" y="16" font-size="14" font-weight="bold">{1}</text>"#,
        size + 20.0,
        escape(title)
    );
    for el in [0.0f64, 30.0, 60.0] {
        let rho = r * (1.0 - el / 90.0);
        let _ = writeln!(
            svg,
            r##"<circle cx="{cx}" cy="{cy}" r="{rho:.1}" fill="none" stroke="#bbb"/><text x="{:.1}" y="{:.1}" fill="#777">{el:.0}°</text>"##,
            cx + 3.0,
            cy - rho + 11.0
        );
    }
    for (label, az) in [("N", 0.0f64), ("E", 90.0), ("S", 180.0), ("W", 270.0)] {
        let (x, y) = at(az.to_radians(), -0.12);
        let _ = writeln!(
            svg,
            r#"<text x="{x:.1}" y="{:.1}" text-anchor="middle" font-weight="bold">{label}</text>"#,
            y + 4.0
        );
    }
    for t in tracks {
        let mut d = String::new();
        for (k, &(az, el)) in t.az_el_rad.iter().enumerate() {
            let (x, y) = at(az, el);
            let _ = write!(d, "{}{x:.1},{y:.1} ", if k == 0 { "M" } else { "L" });
        }
        if let Some(&(az, el)) = t.az_el_rad.last() {
            let (x, y) = at(az, el);
            let _ = writeln!(
                svg,
                r#"<path d="{d}" fill="none" stroke="{c}" stroke-width="1.5"/><circle cx="{x:.1}" cy="{y:.1}" r="3" fill="{c}"/><text x="{tx:.1}" y="{ty:.1}">{label}</text>"#,
                d = d.trim_end(),
                c = t.colour,
                tx = x + 4.0,
                ty = y - 3.0,
                label = escape(&t.label),
            );
        }
    }
    svg.push_str("</svg>\n");
    svg
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_one_two_five_steps_inside_the_range() {
        assert_eq!(ticks(0.0, 10.0, 5), [0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        assert_eq!(ticks(0.3, 0.9, 3), [0.4, 0.6, 0.8]);
        let t = ticks(-37.0, 412.0, 6);
        assert!(t.iter().all(|v| (-37.0..=412.0).contains(v)));
        assert_eq!(t[1] - t[0], 100.0);
    }

    #[test]
    fn a_chart_is_well_formed_and_breaks_lines_at_gaps() {
        let s = line_chart(
            &Chart {
                title: "e",
                x_label: "t",
                y_label: "m",
                y_scale: Scale::Linear,
                spans: &[(1.0, 2.0)],
                span_label: "few satellites",
            },
            &[Series {
                label: "a<b",
                colour: colour(0),
                points: vec![(0.0, 1.0), (1.0, 2.0), (2.0, f64::NAN), (3.0, 1.0)],
            }],
        );
        assert!(s.starts_with("<svg") && s.trim_end().ends_with("</svg>"));
        // Two pen-down moves: the NaN split the line.
        assert_eq!(s.matches(" M").count() + s.matches("\"M").count(), 2, "{s}");
        assert!(s.contains("a&lt;b"));
        assert!(s.contains("few satellites"));
    }
}
