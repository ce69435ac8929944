//! A plan view of a world as SVG: surfaces, forests, buildings, indoor zones, the
//! trajectory and the transmitters, on axes in metres east and north of the world's
//! origin, with a legend, a scale bar and a north arrow. Labels are placed by
//! [`Labels`]: transmitters on one mast (Beihang's DTMB and FM towers) stack their labels
//! instead of overprinting them.
//!
//! Written by hand rather than with a plotting crate: the drawing is a handful of polygons
//! and labels, and plain SVG keeps the output small, diffable and viewable anywhere.
//! Transmitters farther than the drawing's extent (a TV tower kilometres away) are drawn as
//! an arrow on the border pointing towards them, labelled with their distance.

use super::svg::{escape, fmt_tick, legend_sample, marker, text_width_px, ticks, Labels, Style};
use crate::world::scene::TransmitterKind;
use crate::world::World;
use std::fmt::Write;

const WIDTH_PX: f64 = 900.0;
/// Margins around the frame (px): the left one holds the north axis, the bottom one the
/// east axis and the scale bar.
const LEFT_PX: f64 = 70.0;
const RIGHT_PX: f64 = 40.0;
const TOP_PX: f64 = 50.0;
const BOTTOM_PX: f64 = 75.0;

struct View {
    min_e: f64,
    max_e: f64,
    min_n: f64,
    max_n: f64,
    scale: f64,
    height_px: f64,
}

impl View {
    fn px(&self, e: f64, n: f64) -> (f64, f64) {
        (
            LEFT_PX + (e - self.min_e) * self.scale,
            TOP_PX + (self.max_n - n) * self.scale,
        )
    }
}

impl View {
    /// The view of `pts` with a 5 % margin (at least 1 m) on every side, `WIDTH_PX` wide,
    /// and at least `min_height_px` tall (the legend's box must fit in the frame): a
    /// flatter extent gets the extra height as equal margins above and below.
    fn fit(pts: &[[f64; 2]], min_height_px: f64) -> Self {
        let (mut min_e, mut max_e, mut min_n, mut max_n) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in pts {
            min_e = min_e.min(p[0]);
            max_e = max_e.max(p[0]);
            min_n = min_n.min(p[1]);
            max_n = max_n.max(p[1]);
        }
        let pad = 0.05 * (max_e - min_e).max(max_n - min_n).max(20.0);
        let (min_e, max_e, min_n, max_n) = (min_e - pad, max_e + pad, min_n - pad, max_n + pad);
        let scale = (WIDTH_PX - LEFT_PX - RIGHT_PX) / (max_e - min_e);
        let mut height_px = (max_n - min_n) * scale + TOP_PX + BOTTOM_PX;
        let (mut min_n, mut max_n) = (min_n, max_n);
        if height_px < min_height_px {
            let extra_m = (min_height_px - height_px) / scale;
            min_n -= 0.5 * extra_m;
            max_n += 0.5 * extra_m;
            height_px = min_height_px;
        }
        View {
            min_e,
            max_e,
            min_n,
            max_n,
            scale,
            height_px,
        }
    }
}

fn polygon(svg: &mut String, v: &View, pts: &[[f64; 2]], style: &str) {
    let mut d = String::new();
    for p in pts {
        let (x, y) = v.px(p[0], p[1]);
        let _ = write!(d, "{x:.1},{y:.1} ");
    }
    let _ = writeln!(svg, r#"<polygon points="{}" {style}/>"#, d.trim_end());
}

/// A line drawn over the map (an estimator's track in a run's report).
pub struct Overlay<'a> {
    pub label: &'a str,
    pub style: Style,
    /// ENU positions (m); `None` breaks the line (an epoch without an estimate).
    pub points_enu_m: Vec<Option<[f64; 2]>>,
}

/// The SVG text of the world's map.
///
/// # Errors
/// When the trajectory cannot be built.
pub fn svg(world: &World) -> Result<String, String> {
    svg_with(world, &[])
}

/// The world's map with `overlays` drawn over the scene (clipped to the drawing, which
/// spans the scene and the true trajectory: a diverged estimate leaves the frame rather
/// than shrinking the city to a dot), with a legend.
///
/// # Errors
/// When the trajectory cannot be built.
pub fn svg_with(world: &World, overlays: &[Overlay<'_>]) -> Result<String, String> {
    let track = world.track_enu_m(20_001)?;
    let cfg = world
        .file
        .scene
        .as_ref()
        .map(|s| s.resolve(&world.frame))
        .transpose()
        .map_err(|(k, m)| format!("scene.{k}: {m}"))?
        .map(|r| r.config)
        .unwrap_or_default();

    // The extent: the trajectory and the scene, not far transmitters.
    let mut pts: Vec<[f64; 2]> = track.clone();
    pts.extend(
        cfg.buildings
            .iter()
            .flat_map(|b| b.footprint_enu_m.iter().copied()),
    );
    pts.extend(
        cfg.forests
            .iter()
            .flat_map(|f| f.polygon_enu_m.iter().copied()),
    );
    pts.extend(
        cfg.indoor_zones
            .iter()
            .flat_map(|z| z.polygon_enu_m.iter().copied()),
    );
    pts.extend(
        cfg.surfaces
            .iter()
            .flat_map(|s| s.polygon_enu_m.iter().copied()),
    );
    // Over a report's coloured estimates the truth is drawn in black, so that no
    // estimator's colour can be mistaken for it.
    let truth_colour = if overlays.is_empty() {
        "#c0392b"
    } else {
        "#111"
    };
    let legend = legend_rows(world, &cfg, overlays, truth_colour);
    // The legend box sits inside the frame, a margin from its top and bottom edges.
    let v = View::fit(
        &pts,
        TOP_PX + 2.0 * LEGEND_MARGIN_PX + legend_height_px(legend.len()) + BOTTOM_PX,
    );
    let height_px = v.height_px;

    let mut svg = String::new();
    let title = &world.file.world.name;
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH_PX}" height="{height_px:.0}" viewBox="0 0 {WIDTH_PX} {height_px:.0}" font-family="sans-serif" font-size="11" role="img"><title>{}</title>"#,
        escape(title)
    );
    let _ = writeln!(
        svg,
        r##"<rect width="100%" height="100%" fill="#f7f5ef"/><text x="{LEFT_PX}" y="22" font-size="15">{}</text>"##,
        escape(title)
    );
    let mut labels = Labels::new(WIDTH_PX, height_px);
    labels.reserve_text(title, 15.0, LEFT_PX, 22.0);
    draw_scene(&mut svg, &v, &cfg);
    draw_axes(&mut svg, &v, &mut labels);
    let mut d = String::new();
    for (i, p) in track.iter().enumerate() {
        let (x, y) = v.px(p[0], p[1]);
        let _ = write!(d, "{}{x:.1},{y:.1} ", if i == 0 { "M" } else { "L" });
    }
    let _ = writeln!(
        svg,
        r##"<path d="{}" fill="none" stroke="{truth_colour}" stroke-width="2"/>"##,
        d.trim_end()
    );
    if !overlays.is_empty() {
        let (x0, y0) = v.px(v.min_e, v.max_n);
        let (x1, y1) = v.px(v.max_e, v.min_n);
        let _ = writeln!(
            svg,
            r#"<clipPath id="map-clip"><rect x="{x0:.1}" y="{y0:.1}" width="{:.1}" height="{:.1}"/></clipPath><g clip-path="url(#map-clip)">"#,
            x1 - x0,
            y1 - y0
        );
        // Each line carries its legend's marker every 150 px of its length, each line
        // starting at its own offset, so that a track stays identifiable in greyscale.
        const MARKER_EVERY_PX: f64 = 150.0;
        for (k, o) in overlays.iter().enumerate() {
            let mut d = String::new();
            let mut marks = String::new();
            let mut since_mark = MARKER_EVERY_PX - 20.0 - 23.0 * (k % 6) as f64;
            let mut last: Option<(f64, f64)> = None;
            for p in &o.points_enu_m {
                match p {
                    Some(p) => {
                        let (x, y) = v.px(p[0], p[1]);
                        let _ = write!(
                            d,
                            "{}{x:.1},{y:.1} ",
                            if last.is_none() { "M" } else { "L" }
                        );
                        if let Some((lx, ly)) = last {
                            since_mark += (x - lx).hypot(y - ly);
                        }
                        if since_mark >= MARKER_EVERY_PX {
                            marks.push_str(&marker(o.style.marker, x, y, o.style.colour));
                            since_mark = 0.0;
                        }
                        last = Some((x, y));
                    }
                    None => last = None,
                }
            }
            let _ = writeln!(
                svg,
                r#"<path d="{}" fill="none" stroke="{}" stroke-width="1.3" stroke-opacity="0.85"{}/>{marks}"#,
                d.trim_end(),
                o.style.colour,
                o.style.dash_attr()
            );
        }
        svg.push_str("</g>\n");
    }
    draw_legend(&mut svg, &legend, &mut labels);
    draw_scale_and_north(&mut svg, &v, &mut labels);
    let (sx, sy) = v.px(track[0][0], track[0][1]);
    labels.reserve(sx - 4.0, sy - 4.0, sx + 4.0, sy + 4.0);
    let _ = writeln!(
        svg,
        r##"<circle cx="{sx:.1}" cy="{sy:.1}" r="4" fill="{truth_colour}"/>"##
    );
    let (tx, ty) = labels.place(
        "start",
        11.0,
        &[
            (sx + 6.0, sy - 6.0),
            (sx + 6.0, sy + 14.0),
            (sx - 34.0, sy - 6.0),
            (sx - 34.0, sy + 14.0),
        ],
    );
    let _ = writeln!(svg, r#"<text x="{tx:.1}" y="{ty:.1}">start</text>"#);
    draw_transmitters(&mut svg, &v, world, &mut labels);
    svg.push_str("</svg>\n");
    Ok(svg)
}

/// The frame of the drawing with ticks in metres east (below) and north (left) of the
/// world's origin, labelled, and the axes' titles.
fn draw_axes(svg: &mut String, v: &View, labels: &mut Labels) {
    let (x0, y0) = v.px(v.min_e, v.max_n);
    let (x1, y1) = v.px(v.max_e, v.min_n);
    let _ = writeln!(
        svg,
        r##"<rect x="{x0:.1}" y="{y0:.1}" width="{:.1}" height="{:.1}" fill="none" stroke="#444"/>"##,
        x1 - x0,
        y1 - y0
    );
    for e in ticks(v.min_e, v.max_e, 8) {
        let (x, _) = v.px(e, v.min_n);
        let text = fmt_tick(e);
        let w = text_width_px(&text, 11.0);
        labels.reserve(x - 0.5 * w, y1 + 4.0, x + 0.5 * w, y1 + 20.0);
        let _ = writeln!(
            svg,
            r##"<line x1="{x:.1}" y1="{y1:.1}" x2="{x:.1}" y2="{:.1}" stroke="#444"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{text}</text>"##,
            y1 + 5.0,
            y1 + 17.0
        );
    }
    for n in ticks(v.min_n, v.max_n, 6) {
        let (_, y) = v.px(v.min_e, n);
        let text = fmt_tick(n);
        let w = text_width_px(&text, 11.0);
        labels.reserve(x0 - 8.0 - w, y - 8.0, x0, y + 5.0);
        let _ = writeln!(
            svg,
            r##"<line x1="{:.1}" y1="{y:.1}" x2="{x0:.1}" y2="{y:.1}" stroke="#444"/><text x="{:.1}" y="{:.1}" text-anchor="end">{text}</text>"##,
            x0 - 5.0,
            x0 - 7.0,
            y + 4.0
        );
    }
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let east = "east of the origin (m)";
    let w = text_width_px(east, 11.0);
    labels.reserve(cx - 0.5 * w, y1 + 22.0, cx + 0.5 * w, y1 + 36.0);
    labels.reserve(4.0, cy - 60.0, 20.0, cy + 60.0);
    let _ = writeln!(
        svg,
        r#"<text x="{cx:.1}" y="{:.1}" text-anchor="middle">{east}</text><text transform="translate(16 {cy:.1}) rotate(-90)" text-anchor="middle">north (m)</text>"#,
        y1 + 33.0
    );
}

/// A legend entry's key: a line's style, a transmitter's triangle, an indoor zone's dash.
enum LegendKey<'a> {
    Line(Style),
    Triangle(&'a str),
    Dashed,
}

/// The legend box's distance from the frame's top edge (px).
const LEGEND_MARGIN_PX: f64 = 6.0;
/// Vertical distance between legend entries (px).
const LEGEND_ROW_PX: f64 = 16.0;

/// The height (px) of a legend box of `rows` entries.
fn legend_height_px(rows: usize) -> f64 {
    LEGEND_ROW_PX * rows as f64 + 8.0
}

/// The legend's entries: the true path, each estimator's line, each kind of transmitter
/// and, when the scene has them, indoor zones.
fn legend_rows<'a>(
    world: &World,
    cfg: &crate::propagation::SceneConfig,
    overlays: &[Overlay<'_>],
    truth_colour: &'static str,
) -> Vec<(LegendKey<'a>, String)> {
    let mut rows: Vec<(LegendKey<'_>, String)> = Vec::new();
    let truth = Style {
        colour: truth_colour,
        dash: "",
        marker: super::svg::Marker::Circle,
    };
    rows.push((
        LegendKey::Line(truth),
        if overlays.is_empty() {
            "trajectory".into()
        } else {
            "truth".into()
        },
    ));
    for o in overlays {
        rows.push((LegendKey::Line(o.style), o.label.to_string()));
    }
    for kind in [
        TransmitterKind::Dtmb,
        TransmitterKind::Tcofdm,
        TransmitterKind::Fm,
    ] {
        if world.transmitters.iter().any(|t| t.kind == kind) {
            rows.push((
                LegendKey::Triangle(kind_colour(kind)),
                format!("{} transmitter", kind.label()),
            ));
        }
    }
    if !cfg.indoor_zones.is_empty() {
        rows.push((LegendKey::Dashed, "indoor zone".into()));
    }
    rows
}

/// The legend, in a box at the frame's top right.
fn draw_legend(svg: &mut String, rows: &[(LegendKey<'_>, String)], labels: &mut Labels) {
    let row_px = LEGEND_ROW_PX;
    let text_w = rows
        .iter()
        .map(|(_, t)| text_width_px(t, 11.0))
        .fold(0.0f64, f64::max);
    let w = 26.0 + 8.0 + text_w + 12.0;
    let h = legend_height_px(rows.len());
    let (x, y) = (WIDTH_PX - RIGHT_PX - w - 6.0, TOP_PX + LEGEND_MARGIN_PX);
    labels.reserve(x, y, x + w, y + h);
    let _ = writeln!(
        svg,
        r##"<rect x="{x:.1}" y="{y:.1}" width="{w:.1}" height="{h:.1}" fill="#fff" fill-opacity="0.9" stroke="#999"/>"##
    );
    for (k, (key, text)) in rows.iter().enumerate() {
        let ry = y + 12.0 + row_px * k as f64;
        let sample = match key {
            LegendKey::Line(s) => {
                // The true path is drawn without markers, and so is its legend entry.
                if k > 0 {
                    legend_sample(s, x + 6.0, ry)
                } else {
                    format!(
                        r#"<line x1="{:.1}" y1="{ry:.1}" x2="{:.1}" y2="{ry:.1}" stroke="{}" stroke-width="2.5"/>"#,
                        x + 6.0,
                        x + 32.0,
                        s.colour
                    )
                }
            }
            LegendKey::Triangle(c) => format!(
                r#"<path d="M{:.1},{:.1} L{:.1},{:.1} L{:.1},{:.1} Z" fill="{c}"/>"#,
                x + 19.0,
                ry - 6.0,
                x + 13.0,
                ry + 5.0,
                x + 25.0,
                ry + 5.0
            ),
            LegendKey::Dashed => format!(
                r##"<rect x="{:.1}" y="{:.1}" width="26" height="9" fill="none" stroke="#d95f02" stroke-width="1.5" stroke-dasharray="5,3"/>"##,
                x + 6.0,
                ry - 5.0
            ),
        };
        let _ = writeln!(
            svg,
            r#"{sample}<text x="{:.1}" y="{:.1}">{}</text>"#,
            x + 40.0,
            ry + 4.0,
            escape(text)
        );
    }
}

fn kind_colour(kind: TransmitterKind) -> &'static str {
    match kind {
        TransmitterKind::Dtmb => "#1f78b4",
        TransmitterKind::Tcofdm => "#6a3d9a",
        TransmitterKind::Fm => "#b15928",
    }
}

/// The scene under everything: surfaces, forests (denser is darker), buildings (taller
/// is darker) and indoor zones (dashed).
fn draw_scene(svg: &mut String, v: &View, cfg: &crate::propagation::SceneConfig) {
    for s in &cfg.surfaces {
        let fill = match s.material {
            crate::propagation::GroundMaterial::FreshWater
            | crate::propagation::GroundMaterial::SeaWater => "#a6cee3",
            crate::propagation::GroundMaterial::Paved => "#d9d9d9",
            _ => "#e5dcc3",
        };
        polygon(
            svg,
            v,
            &s.polygon_enu_m,
            &format!(r#"fill="{fill}" stroke="none""#),
        );
    }
    for f in &cfg.forests {
        let opacity = 0.35 + 0.5 * f.foliage_density;
        polygon(
            svg,
            v,
            &f.polygon_enu_m,
            &format!(r##"fill="#4d9a4d" fill-opacity="{opacity:.2}" stroke="none""##),
        );
    }
    for b in &cfg.buildings {
        // Darker for taller: the eye reads a canyon's depth from it.
        let shade = (200.0 - (b.height_m.min(100.0) * 1.4)) as u8;
        polygon(
            svg,
            v,
            &b.footprint_enu_m,
            &format!(r##"fill="rgb({shade},{shade},{shade})" stroke="#333" stroke-width="0.8""##),
        );
    }
    for z in &cfg.indoor_zones {
        polygon(
            svg,
            v,
            &z.polygon_enu_m,
            r##"fill="none" stroke="#d95f02" stroke-width="1.5" stroke-dasharray="5,3""##,
        );
    }
}

/// Each transmitter as a labelled triangle, or, beyond the drawing (a TV tower
/// kilometres away), as an arrow on the border pointing at it with its distance. Labels
/// go where [`Labels`] finds room: beside the mark if free, else stacked under it.
fn draw_transmitters(svg: &mut String, v: &View, world: &World, labels: &mut Labels) {
    let mut texts = Vec::new();
    for t in &world.transmitters {
        let colour = kind_colour(t.kind);
        let name = format!(
            "{} {}{}",
            t.kind.label(),
            t.id,
            t.name
                .as_deref()
                .map(|n| format!(" ({n})"))
                .unwrap_or_default()
        );
        let (e, n) = (t.pos_enu_m.x, t.pos_enu_m.y);
        if (v.min_e..=v.max_e).contains(&e) && (v.min_n..=v.max_n).contains(&n) {
            let (x, y) = v.px(e, n);
            labels.reserve(x - 6.0, y - 7.0, x + 6.0, y + 5.0);
            let _ = writeln!(
                svg,
                r#"<polygon points="{:.1},{:.1} {:.1},{:.1} {:.1},{:.1}" fill="{colour}"/>"#,
                x,
                y - 7.0,
                x - 6.0,
                y + 5.0,
                x + 6.0,
                y + 5.0,
            );
            let w = text_width_px(&name, 11.0);
            texts.push((
                name,
                colour,
                vec![
                    (x + 8.0, y + 4.0),
                    (x - 8.0 - w, y + 4.0),
                    (x - 0.5 * w, y - 10.0),
                    (x - 0.5 * w, y + 18.0),
                ],
            ));
        } else {
            // An arrow on the border, from the drawing's centre towards the transmitter.
            let (ce, cn) = (0.5 * (v.min_e + v.max_e), 0.5 * (v.min_n + v.max_n));
            let (de, dn) = (e - ce, n - cn);
            let k = ((0.5 * (v.max_e - v.min_e)) / de.abs().max(1e-9))
                .min((0.5 * (v.max_n - v.min_n)) / dn.abs().max(1e-9));
            let (be, bn) = (ce + de * k * 0.97, cn + dn * k * 0.97);
            let (x1, y1) = v.px(be, bn);
            let norm = de.hypot(dn).max(1e-9);
            let (ux, uy) = (de / norm, -dn / norm);
            let (x0, y0) = (x1 - 30.0 * ux, y1 - 30.0 * uy);
            let dist_km = (t.pos_enu_m - nalgebra::Vector3::new(ce, cn, 0.0)).norm() / 1e3;
            let _ = writeln!(
                svg,
                r#"<line x1="{x0:.1}" y1="{y0:.1}" x2="{x1:.1}" y2="{y1:.1}" stroke="{colour}" stroke-width="2.5"/><circle cx="{x1:.1}" cy="{y1:.1}" r="4" fill="{colour}"/>"#,
            );
            let text = format!("{name} → {dist_km:.1} km");
            let w = text_width_px(&text, 11.0);
            // Beyond the arrow's tail, then stacked a line at a time further into the
            // drawing (away from the border the arrow points at): transmitters on one
            // mast share the arrow and list their labels one under another.
            let (lx, ly) = (x0 - 10.0 * ux, y0 - 10.0 * uy + 4.0);
            let inward = if uy > 0.0 { -1.0 } else { 1.0 };
            let candidates = (0..40)
                .map(|k| (lx - 0.5 * w, ly + inward * 14.0 * k as f64))
                .collect();
            texts.push((text, colour, candidates));
        }
    }
    // Labels after every mark, so that no label is placed over a mark drawn later.
    for (text, colour, candidates) in texts {
        let (x, y) = labels.place(&text, 11.0, &candidates);
        // A white halo keeps the label legible over the tracks and buildings under it.
        let _ = writeln!(
            svg,
            r##"<text x="{x:.1}" y="{y:.1}" fill="{colour}" stroke="#fff" stroke-width="3" stroke-opacity="0.85" paint-order="stroke">{}</text>"##,
            escape(&text)
        );
    }
}

/// A scale bar of the largest 1-2-5 length under a quarter of the width, under the east
/// axis, and a north arrow in the right margin.
fn draw_scale_and_north(svg: &mut String, v: &View, labels: &mut Labels) {
    let target_m = 0.25 * (v.max_e - v.min_e);
    let mut bar_m = 1.0;
    for mag in [1.0, 10.0, 100.0, 1000.0, 10_000.0] {
        for m in [1.0, 2.0, 5.0] {
            if m * mag <= target_m {
                bar_m = m * mag;
            }
        }
    }
    let y = v.height_px - 14.0;
    let x1 = LEFT_PX + bar_m * v.scale;
    let text = format!("{bar_m} m");
    labels.reserve(LEFT_PX, y - 4.0, x1, y + 4.0);
    labels.reserve_text(&text, 11.0, x1 + 6.0, y + 4.0);
    let _ = writeln!(
        svg,
        r##"<line x1="{LEFT_PX}" y1="{y:.1}" x2="{x1:.1}" y2="{y:.1}" stroke="#000" stroke-width="3"/><text x="{:.1}" y="{:.1}">{text}</text>"##,
        x1 + 6.0,
        y + 4.0
    );
    let nx = WIDTH_PX - 0.5 * RIGHT_PX;
    labels.reserve(nx - 7.0, TOP_PX - 14.0, nx + 7.0, TOP_PX + 16.0);
    let _ = writeln!(
        svg,
        r##"<polygon points="{nx:.1},{:.1} {:.1},{:.1} {:.1},{:.1}" fill="#000"/><text x="{nx:.1}" y="{:.1}" text-anchor="middle">N</text>"##,
        TOP_PX,
        nx - 6.0,
        TOP_PX + 16.0,
        nx + 6.0,
        TOP_PX + 16.0,
        TOP_PX - 4.0
    );
}
