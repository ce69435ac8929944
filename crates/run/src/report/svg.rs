//! The report's charts as plain SVG: line charts with shaded spans, a mode timeline and a
//! sky plot, with the line styles and the label placement they share.
//!
//! Hand-written rather than drawn with `plotters`: the report embeds every chart inline in
//! one HTML file, and the SVG `plotters` emits carries fixed pixel fonts and no `viewBox`
//! scaling; a few hundred lines of our own give charts that scale with the page, stay small
//! and diff cleanly.

use std::fmt::Write;

/// Categorical line colours from Paul Tol's qualitative schemes ("vibrant" and "muted",
/// <https://personal.sron.nl/~pault/>, colour-blind safe), chosen so that their CIE L*
/// lightness values (22.4, 63.0, 43.6, 53.9, 71.2, 31.9) differ by at least 8 between
/// any two: printed in greyscale, two lines of one dash pattern still differ in grey.
pub const PALETTE: [&str; 6] = [
    "#332288", "#ee7733", "#117733", "#ee3377", "#33bbee", "#882255",
];

/// Dash patterns (SVG `stroke-dasharray`; empty is solid). Five, prime to the six
/// colours, so that series `k` and `j < k` share both colour and dash only when
/// `k − j` is a multiple of 30.
pub const DASHES: [&str; 5] = ["", "7,3", "2,2.5", "10,3,2,3", "14,4"];

/// Marker shapes drawn along each line and in its legend entry, one per dash pattern, so
/// that a line keeps its identity where its dashes cannot be seen (a short segment).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Marker {
    Circle,
    Square,
    Triangle,
    Diamond,
    Cross,
}

const MARKERS: [Marker; 5] = [
    Marker::Circle,
    Marker::Square,
    Marker::Triangle,
    Marker::Diamond,
    Marker::Cross,
];

/// The look of one series: colour, dash pattern and marker.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Style {
    pub colour: &'static str,
    pub dash: &'static str,
    pub marker: Marker,
}

impl Style {
    /// The `stroke-dasharray` attribute (with a leading space), empty for a solid line.
    pub fn dash_attr(&self) -> String {
        if self.dash.is_empty() {
            String::new()
        } else {
            format!(r#" stroke-dasharray="{}""#, self.dash)
        }
    }
}

/// The style of series `k` (an estimator's index in world order): colour `k mod 6`, dash
/// and marker `k mod 5`; 30 distinct styles before one repeats.
pub fn style(k: usize) -> Style {
    Style {
        colour: PALETTE[k % PALETTE.len()],
        dash: DASHES[k % DASHES.len()],
        marker: MARKERS[k % MARKERS.len()],
    }
}

/// The colour of category `k` (satellite systems, modes).
pub fn colour(k: usize) -> &'static str {
    PALETTE[k % PALETTE.len()]
}

/// CIE 1976 L* lightness (0–100) of an `#rrggbb` colour: the grey it prints as.
///
/// sRGB is linearised (IEC 61966-2-1), Y = 0.2126 R + 0.7152 G + 0.0722 B (ITU-R BT.709
/// primaries), and L* = 116 (Y)^(1/3) − 16 above the CIE's (6/29)³ threshold, 903.3 Y
/// below it.
pub fn lightness(hex: &str) -> f64 {
    let c = |i: usize| {
        let v = f64::from(u8::from_str_radix(&hex[i..i + 2], 16).unwrap_or(0)) / 255.0;
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    };
    let y = 0.2126 * c(1) + 0.7152 * c(3) + 0.0722 * c(5);
    if y > 216.0 / 24389.0 {
        116.0 * y.cbrt() - 16.0
    } else {
        24389.0 / 27.0 * y
    }
}

/// An SVG marker of `shape` centred on `(x, y)`, about 7 px across.
pub fn marker(shape: Marker, x: f64, y: f64, colour: &str) -> String {
    let r = 3.5;
    match shape {
        Marker::Circle => format!(r#"<circle cx="{x:.1}" cy="{y:.1}" r="{r}" fill="{colour}"/>"#),
        Marker::Square => format!(
            r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="{colour}"/>"#,
            x - r * 0.9,
            y - r * 0.9,
            1.8 * r,
            1.8 * r
        ),
        Marker::Triangle => format!(
            r#"<path d="M{x:.1},{:.1} L{:.1},{:.1} L{:.1},{:.1} Z" fill="{colour}"/>"#,
            y - r * 1.1,
            x - r,
            y + r * 0.8,
            x + r,
            y + r * 0.8
        ),
        Marker::Diamond => format!(
            r#"<path d="M{x:.1},{:.1} L{:.1},{y:.1} L{x:.1},{:.1} L{:.1},{y:.1} Z" fill="{colour}"/>"#,
            y - r * 1.2,
            x + r,
            y + r * 1.2,
            x - r
        ),
        Marker::Cross => format!(
            r#"<path d="M{:.1},{:.1} L{:.1},{:.1} M{:.1},{:.1} L{:.1},{:.1}" stroke="{colour}" stroke-width="1.8"/>"#,
            x - r,
            y - r,
            x + r,
            y + r,
            x - r,
            y + r,
            x + r,
            y - r
        ),
    }
}

/// A legend entry's sample: a short stretch of the line with its marker in the middle.
pub fn legend_sample(s: &Style, x: f64, y: f64) -> String {
    format!(
        r#"<line x1="{x:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{}" stroke-width="2"{}/>{}"#,
        x + 26.0,
        s.colour,
        s.dash_attr(),
        marker(s.marker, x + 13.0, y, s.colour)
    )
}

/// The width (px) a label of `text` at `font_px` takes at most in a sans-serif face: DejaVu
/// Sans (the common fallback, and the widest of the usual faces) averages under 0.62 em a
/// character over mixed-case text and digits; capitals and wide symbols take up to 0.8.
pub fn text_width_px(text: &str, font_px: f64) -> f64 {
    text.chars()
        .map(|c| {
            if c.is_ascii_uppercase() || "MW@%—→".contains(c) {
                0.78
            } else if c.is_ascii_digit() || c.is_ascii_lowercase() {
                0.62
            } else if " .,:;'|il()[]".contains(c) {
                0.36
            } else {
                0.7
            }
        })
        .sum::<f64>()
        * font_px
}

/// Places labels so that none overlaps another or an area set aside (a legend, a title),
/// and none leaves the canvas: each label takes the first of its candidate positions that
/// is free, else is stacked below the first one, line by line, until free.
pub struct Labels {
    width: f64,
    height: f64,
    taken: Vec<[f64; 4]>,
}

impl Labels {
    /// An empty canvas of `width` × `height` px.
    pub fn new(width: f64, height: f64) -> Self {
        Self {
            width,
            height,
            taken: Vec::new(),
        }
    }

    /// Sets aside the box `x0, y0, x1, y1`.
    pub fn reserve(&mut self, x0: f64, y0: f64, x1: f64, y1: f64) {
        self.taken.push([x0, y0, x1, y1]);
    }

    /// Sets aside the box of a label already drawn, left-aligned with baseline at `(x, y)`.
    pub fn reserve_text(&mut self, text: &str, font_px: f64, x: f64, y: f64) {
        let b = Self::text_box(text, font_px, x, y);
        self.taken.push(b);
    }

    fn text_box(text: &str, font_px: f64, x: f64, y: f64) -> [f64; 4] {
        [
            x - 1.0,
            y - 0.95 * font_px,
            x + text_width_px(text, font_px) + 1.0,
            y + 0.3 * font_px,
        ]
    }

    fn free(&self, b: &[f64; 4]) -> bool {
        b[0] >= 0.0
            && b[1] >= 0.0
            && b[2] <= self.width
            && b[3] <= self.height
            && self
                .taken
                .iter()
                .all(|t| b[2] <= t[0] || t[2] <= b[0] || b[3] <= t[1] || t[3] <= b[1])
    }

    /// Where to draw `text` (left-aligned, baseline): the first free position of
    /// `candidates` (each the left end of the baseline), else the first candidate moved
    /// into the canvas and stacked down (then up) a line at a time until free.
    pub fn place(&mut self, text: &str, font_px: f64, candidates: &[(f64, f64)]) -> (f64, f64) {
        let w = text_width_px(text, font_px);
        let clamp = |(x, y): (f64, f64)| {
            (
                x.clamp(1.0, (self.width - w - 2.0).max(1.0)),
                y.clamp(font_px + 1.0, self.height - 0.3 * font_px - 1.0),
            )
        };
        let mut tries: Vec<(f64, f64)> = candidates.to_vec();
        if let Some(&first) = candidates.first() {
            let (x, y) = clamp(first);
            let line = 1.25 * font_px;
            for k in 0..200 {
                tries.push((x, y + line * k as f64));
            }
            for k in 1..200 {
                tries.push((x, y - line * k as f64));
            }
        }
        let at = tries
            .into_iter()
            .map(|p| {
                let b = Self::text_box(text, font_px, p.0, p.1);
                (p, b)
            })
            .find(|(_, b)| self.free(b))
            .map_or_else(
                || clamp(candidates.first().copied().unwrap_or((0.0, 0.0))),
                |(p, _)| p,
            );
        self.taken.push(Self::text_box(text, font_px, at.0, at.1));
        at
    }
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
    pub style: Style,
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
    pub x_scale: Scale,
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
/// Vertical distance between legend entries (px).
const LEGEND_ROW: f64 = 18.0;

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

/// The ticks of a base-10 log axis spanning `[lo, hi]` (in log10 units): the labelled
/// ones (the powers of ten, with the 2s and 5s over less than two decades) and the
/// unlabelled minor ones (the other integers times a power of ten), both in log10 units.
pub fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return (vec![lo], Vec::new());
    }
    let labelled_mults: &[f64] = if hi - lo < 2.0 {
        &[1.0, 2.0, 5.0]
    } else {
        &[1.0]
    };
    let (mut major, mut minor) = (Vec::new(), Vec::new());
    for d in lo.floor() as i64..=hi.ceil() as i64 {
        for m in 1..10 {
            let t = d as f64 + f64::from(m).log10();
            if !(lo..=hi).contains(&t) {
                continue;
            }
            if labelled_mults.contains(&f64::from(m)) {
                major.push(t);
            } else {
                minor.push(t);
            }
        }
    }
    if major.len() < 2 {
        // Less than a 1-2-5 step wide (a GDOP between 3 and 4.5): ticks of the values
        // themselves.
        major = ticks(10f64.powf(lo), 10f64.powf(hi), 4)
            .into_iter()
            .filter(|v| *v > 0.0)
            .map(f64::log10)
            .collect();
        minor.clear();
    }
    (major, minor)
}

/// A tick label: integers without decimals, small values with the digits they need
/// (0.1, 0.25, not 1e-1).
pub fn fmt_tick(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e6).contains(&a) {
        format!("{v:.0e}")
    } else if (v - v.round()).abs() < 1e-9 * a.max(1.0) {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').to_string()
    }
}

fn transform(scale: Scale, v: f64) -> f64 {
    match scale {
        Scale::Linear => v,
        Scale::Log => {
            if v > 0.0 {
                v.log10()
            } else {
                f64::NAN
            }
        }
    }
}

/// The labelled and minor ticks of an axis over `[lo, hi]` (transformed units).
fn axis_ticks(scale: Scale, lo: f64, hi: f64, target: usize) -> (Vec<f64>, Vec<f64>) {
    match scale {
        Scale::Linear => (ticks(lo, hi, target), Vec::new()),
        Scale::Log => log_ticks(lo, hi),
    }
}

fn tick_label(scale: Scale, t: f64) -> String {
    match scale {
        Scale::Linear => fmt_tick(t),
        // Rounded to 12 significant digits first: 10^log10(0.2) is 0.20000000000000004.
        Scale::Log => fmt_tick(
            format!("{:.11e}", 10f64.powf(t))
                .parse()
                .unwrap_or(f64::NAN),
        ),
    }
}

/// A line chart of `series` as a standalone SVG document (it also embeds inline in HTML).
pub fn line_chart(c: &Chart<'_>, series: &[Series<'_>]) -> String {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for s in series {
        for &(x, y) in &s.points {
            let (x, y) = (transform(c.x_scale, x), transform(c.y_scale, y));
            if x.is_finite() && y.is_finite() {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
    }
    // The legend sets the right margin (the longest label) and, with many series, the
    // height.
    let legend_rows = series.len() + usize::from(!c.spans.is_empty());
    let longest = series
        .iter()
        .map(|s| text_width_px(s.label, 11.0))
        .chain(std::iter::once(text_width_px(c.span_label, 11.0)))
        .fold(0.0f64, f64::max);
    let r_px = R.max(12.0 + 32.0 + longest + 8.0).min(0.45 * W);
    let h_px = H.max(T + 10.0 + LEGEND_ROW * legend_rows as f64 + B);
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {W} {h_px}" width="{W}" height="{h_px}" font-family="sans-serif" font-size="11" role="img"><title>{}</title>"#,
        escape(c.title)
    );
    let _ = writeln!(
        svg,
        r##"<rect width="100%" height="100%" fill="#fff"/><text x="{L}" y="20" font-size="14" font-weight="bold">{}</text>"##,
        escape(c.title)
    );
    if x0 > x1 {
        let _ = writeln!(
            svg,
            r##"<text x="{}" y="{}" fill="#777">no data</text></svg>"##,
            W / 2.0,
            h_px / 2.0
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
    let plot_w = W - L - r_px;
    let plot_h = h_px - T - B;
    let px = |x: f64| L + (x - x0) / (x1 - x0) * plot_w;
    let py = |y: f64| h_px - B - (y - y0) / (y1 - y0) * plot_h;
    for &(a, b) in c.spans {
        let (a, b) = (
            transform(c.x_scale, a).max(x0),
            transform(c.x_scale, b).min(x1),
        );
        if b > a {
            let _ = writeln!(
                svg,
                r##"<rect x="{:.1}" y="{T}" width="{:.1}" height="{plot_h:.1}" fill="#999" fill-opacity="0.18"/>"##,
                px(a),
                (px(b) - px(a)).max(0.8),
            );
        }
    }
    // Axes, grid and ticks: labelled ticks with a grid line, minor ticks as short marks
    // inside the frame.
    let _ = writeln!(
        svg,
        r##"<rect x="{L}" y="{T}" width="{plot_w:.1}" height="{plot_h:.1}" fill="none" stroke="#444"/>"##,
    );
    let (xt, xm) = axis_ticks(c.x_scale, x0, x1, 8);
    for t in xt {
        let x = px(t);
        let _ = writeln!(
            svg,
            r##"<line x1="{x:.1}" y1="{T}" x2="{x:.1}" y2="{:.1}" stroke="#ddd"/><line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#444"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
            h_px - B,
            h_px - B,
            h_px - B + 5.0,
            h_px - B + 16.0,
            tick_label(c.x_scale, t)
        );
    }
    for t in xm {
        let x = px(t);
        let _ = writeln!(
            svg,
            r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#444"/>"##,
            h_px - B,
            h_px - B - 4.0,
        );
    }
    let (yt, ym) = axis_ticks(c.y_scale, y0, y1, 6);
    for t in yt {
        let y = py(t);
        let _ = writeln!(
            svg,
            r##"<line x1="{L}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><line x1="{:.1}" y1="{y:.1}" x2="{L}" y2="{y:.1}" stroke="#444"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
            W - r_px,
            L - 5.0,
            L - 7.0,
            y + 4.0,
            tick_label(c.y_scale, t)
        );
    }
    for t in ym {
        let y = py(t);
        let _ = writeln!(
            svg,
            r##"<line x1="{L}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#444"/>"##,
            L + 4.0
        );
    }
    let _ = writeln!(
        svg,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text><text transform="translate(16 {:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
        L + 0.5 * plot_w,
        h_px - 10.0,
        escape(c.x_label),
        T + 0.5 * plot_h,
        escape(c.y_label)
    );
    let _ = writeln!(
        svg,
        r#"<clipPath id="clip-{0}"><rect x="{L}" y="{T}" width="{plot_w:.1}" height="{plot_h:.1}"/></clipPath><g clip-path="url(#clip-{0})">"#,
        clip_id(c.title),
    );
    // Markers every 90 px along each line, each series starting at its own offset so that
    // the markers of lines running together do not pile up.
    const MARKER_EVERY_PX: f64 = 90.0;
    for (k, s) in series.iter().enumerate() {
        let mut d = String::new();
        let mut marks = String::new();
        let mut pen_up = true;
        let mut since_mark = MARKER_EVERY_PX - 12.0 - 17.0 * (k % 5) as f64;
        let mut last: Option<(f64, f64)> = None;
        for &(x, y) in &s.points {
            let (x, y) = (transform(c.x_scale, x), transform(c.y_scale, y));
            if x.is_finite() && y.is_finite() {
                let (sx, sy) = (px(x), py(y));
                let _ = write!(d, "{}{sx:.1},{sy:.1} ", if pen_up { "M" } else { "L" });
                pen_up = false;
                if let Some((lx, ly)) = last {
                    since_mark += (sx - lx).hypot(sy - ly);
                }
                if since_mark >= MARKER_EVERY_PX {
                    marks.push_str(&marker(s.style.marker, sx, sy, s.style.colour));
                    since_mark = 0.0;
                }
                last = Some((sx, sy));
            } else {
                pen_up = true;
                last = None;
            }
        }
        let _ = writeln!(
            svg,
            r#"<path d="{}" fill="none" stroke="{}" stroke-width="1.5"{}/>{marks}"#,
            d.trim_end(),
            s.style.colour,
            s.style.dash_attr()
        );
    }
    svg.push_str("</g>\n");
    let lx = W - r_px + 12.0;
    for (k, s) in series.iter().enumerate() {
        let y = T + 8.0 + LEGEND_ROW * k as f64;
        let _ = writeln!(
            svg,
            r#"{}<text x="{:.1}" y="{:.1}">{}</text>"#,
            legend_sample(&s.style, lx, y),
            lx + 32.0,
            y + 4.0,
            escape(s.label)
        );
    }
    if !c.spans.is_empty() {
        let y = T + 8.0 + LEGEND_ROW * series.len() as f64;
        let _ = writeln!(
            svg,
            r##"<rect x="{lx:.1}" y="{:.1}" width="26" height="10" fill="#999" fill-opacity="0.35"/><text x="{:.1}" y="{:.1}">{}</text>"##,
            y - 5.0,
            lx + 32.0,
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
    // Tall enough for the rows and for the legend of modes beside them.
    let h = T + B + (row_h * rows.len() as f64).max(LEGEND_ROW * modes.len() as f64 + 4.0);
    // The row labels end 6 px before the bands: the margin takes the longest of them.
    let longest = rows
        .iter()
        .map(|r| text_width_px(r.label, 11.0))
        .fold(0.0f64, f64::max);
    let left = (longest + 14.0).clamp(150.0, 0.4 * W);
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r##"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {W} {h}" width="{W}" height="{h}" font-family="sans-serif" font-size="11" role="img"><title>{0}</title><rect width="100%" height="100%" fill="#fff"/><text x="{left}" y="20" font-size="14" font-weight="bold">{0}</text>"##,
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
        let y = T + 8.0 + LEGEND_ROW * k as f64;
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
/// Each track is labelled at its end, the labels placed by [`Labels`] so that two
/// satellites ending close together do not overprint each other.
///
/// `legend` names the colours (a satellite system's name and its colour).
pub fn sky_plot(title: &str, tracks: &[SkyTrack], legend: &[(&str, &str)]) -> String {
    let size = 420.0;
    let (cx, cy, r) = (size / 2.0, size / 2.0 + 10.0, size / 2.0 - 30.0);
    let at = |az: f64, el: f64| {
        let rho = r * (1.0 - el / std::f64::consts::FRAC_PI_2);
        (cx + rho * az.sin(), cy - rho * az.cos())
    };
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r##"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {size} {0}" width="{size}" height="{0}" font-family="sans-serif" font-size="10" role="img"><title>{1}</title><rect width="100%" height="100%" fill="#fff"/><text x="8" y="16" font-size="14" font-weight="bold">{1}</text>"##,
        size + 20.0,
        escape(title)
    );
    let mut labels = Labels::new(size, size + 20.0);
    labels.reserve_text(title, 14.0 * 1.1, 8.0, 16.0);
    for el in [0.0f64, 30.0, 60.0] {
        let rho = r * (1.0 - el / 90.0);
        let text = format!("{el:.0}°");
        let (x, y) = (cx + 3.0, cy - rho + 11.0);
        labels.reserve_text(&text, 10.0, x, y);
        let _ = writeln!(
            svg,
            r##"<circle cx="{cx}" cy="{cy}" r="{rho:.1}" fill="none" stroke="#bbb"/><text x="{x:.1}" y="{y:.1}" fill="#777">{text}</text>"##,
        );
    }
    for (label, az) in [("N", 0.0f64), ("E", 90.0), ("S", 180.0), ("W", 270.0)] {
        let (x, y) = at(az.to_radians(), -0.12);
        labels.reserve(x - 6.0, y - 7.0, x + 6.0, y + 7.0);
        let _ = writeln!(
            svg,
            r#"<text x="{x:.1}" y="{:.1}" text-anchor="middle" font-weight="bold">{label}</text>"#,
            y + 4.0
        );
    }
    for (k, (name, c)) in legend.iter().enumerate() {
        let (x, y) = (size - 90.0, 36.0 + LEGEND_ROW * k as f64);
        labels.reserve(x - 2.0, y - 12.0, size, y + 4.0);
        let _ = writeln!(
            svg,
            r#"<circle cx="{x:.1}" cy="{:.1}" r="4" fill="{c}"/><text x="{:.1}" y="{y:.1}">{}</text>"#,
            y - 4.0,
            x + 8.0,
            escape(name)
        );
    }
    // Tracks first, then their labels, so that no track is drawn over a label.
    let mut ends = Vec::new();
    for t in tracks {
        let mut d = String::new();
        for (k, &(az, el)) in t.az_el_rad.iter().enumerate() {
            let (x, y) = at(az, el);
            let _ = write!(d, "{}{x:.1},{y:.1} ", if k == 0 { "M" } else { "L" });
        }
        if let Some(&(az, el)) = t.az_el_rad.last() {
            let (x, y) = at(az, el);
            labels.reserve(x - 3.0, y - 3.0, x + 3.0, y + 3.0);
            ends.push((x, y, t));
            let _ = writeln!(
                svg,
                r#"<path d="{d}" fill="none" stroke="{c}" stroke-width="1.5"/><circle cx="{x:.1}" cy="{y:.1}" r="3" fill="{c}"/>"#,
                d = d.trim_end(),
                c = t.colour,
            );
        }
    }
    for (x, y, t) in ends {
        let w = text_width_px(&t.label, 10.0);
        let (tx, ty) = labels.place(
            &t.label,
            10.0,
            &[
                (x + 4.0, y - 3.0),
                (x + 4.0, y + 11.0),
                (x - 4.0 - w, y - 3.0),
                (x - 4.0 - w, y + 11.0),
                (x - 0.5 * w, y - 6.0),
                (x - 0.5 * w, y + 14.0),
            ],
        );
        let _ = writeln!(
            svg,
            r#"<text x="{tx:.1}" y="{ty:.1}" fill="{}">{}</text>"#,
            t.colour,
            escape(&t.label)
        );
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
                x_scale: Scale::Linear,
                y_scale: Scale::Linear,
                spans: &[(1.0, 2.0)],
                span_label: "few satellites",
            },
            &[Series {
                label: "a<b",
                style: style(0),
                points: vec![(0.0, 1.0), (1.0, 2.0), (2.0, f64::NAN), (3.0, 1.0)],
            }],
        );
        assert!(s.starts_with("<svg") && s.trim_end().ends_with("</svg>"));
        // Two pen-down moves: the NaN split the line.
        assert_eq!(s.matches(" M").count() + s.matches("\"M").count(), 2, "{s}");
        assert!(s.contains("a&lt;b"));
        assert!(s.contains("few satellites"));
    }

    #[test]
    fn twelve_series_keep_distinct_styles_in_colour_and_in_grey() {
        let styles: Vec<Style> = (0..12).map(style).collect();
        for (i, a) in styles.iter().enumerate() {
            for (j, b) in styles.iter().enumerate().skip(i + 1) {
                assert!(
                    (a.colour, a.dash) != (b.colour, b.dash),
                    "series {i} and {j} share colour and dash"
                );
                // Printed in grey, two lines of one dash pattern must still differ.
                if a.dash == b.dash {
                    let dl = (lightness(a.colour) - lightness(b.colour)).abs();
                    assert!(dl >= 8.0, "series {i} and {j}: ΔL* {dl:.1}");
                }
            }
        }
        // The L* formula against published values: white 100, black 0, sRGB mid-grey
        // #777777 at 50.0 (CIE L* of Y = 0.184).
        assert!((lightness("#ffffff") - 100.0).abs() < 1e-9);
        assert!(lightness("#000000").abs() < 1e-9);
        assert!(
            (lightness("#777777") - 50.0).abs() < 0.1,
            "{}",
            lightness("#777777")
        );
    }

    #[test]
    fn log_ticks_are_labelled_in_the_axis_units_with_minor_ticks_between() {
        // 0.3 m to 700 m: labelled 1, 10, 100 m; minor ticks at 0.3…0.9, 2…9, 20…90 and
        // 200…700 (the ends included).
        let (major, minor) = log_ticks(0.3f64.log10(), 700f64.log10());
        let labels: Vec<String> = major.iter().map(|t| tick_label(Scale::Log, *t)).collect();
        assert_eq!(labels, ["1", "10", "100"]);
        assert_eq!(minor.len(), 7 + 8 + 8 + 6);
        // Under two decades the 2s and 5s are labelled too.
        let (major, _) = log_ticks(0.1f64.log10(), 3f64.log10());
        let labels: Vec<String> = major.iter().map(|t| tick_label(Scale::Log, *t)).collect();
        assert_eq!(labels, ["0.1", "0.2", "0.5", "1", "2"]);
    }

    #[test]
    fn the_error_cdf_reads_in_metres_on_its_log_axis() {
        let s = line_chart(
            &Chart {
                title: "cdf",
                x_label: "3-D error (m)",
                y_label: "share",
                x_scale: Scale::Log,
                y_scale: Scale::Linear,
                spans: &[],
                span_label: "",
            },
            &[Series {
                label: "EKF",
                style: style(0),
                points: vec![(0.5, 0.0), (3.0, 0.5), (40.0, 1.0)],
            }],
        );
        for tick in [">1</text>", ">10</text>", ">0.5</text>"] {
            assert!(s.contains(tick), "no tick {tick}");
        }
        assert!(!s.contains("log10"));
    }

    #[test]
    fn placed_labels_never_overlap_and_stay_on_the_canvas() {
        let mut l = Labels::new(200.0, 100.0);
        l.reserve(0.0, 0.0, 200.0, 20.0);
        // Five labels at one point (transmitters on one mast) stack instead of
        // overprinting, and the one asked for beyond the right edge moves inside.
        let placed: Vec<(f64, f64)> = (0..5)
            .map(|_| l.place("DTMB D01", 11.0, &[(150.0, 50.0)]))
            .collect();
        let w = text_width_px("DTMB D01", 11.0);
        for (i, a) in placed.iter().enumerate() {
            assert!(a.0 >= 0.0 && a.0 + w <= 200.0, "{a:?}");
            assert!(a.1 - 11.0 >= 20.0 && a.1 <= 100.0, "{a:?}");
            for b in &placed[i + 1..] {
                assert!(
                    (a.1 - b.1).abs() >= 11.0 || (a.0 - b.0).abs() >= w,
                    "{a:?} {b:?}"
                );
            }
        }
    }
}
