//! A plan view of a world as SVG: surfaces, forests, buildings, indoor zones, the
//! trajectory and the transmitters, with a scale bar and a north arrow.
//!
//! Written by hand rather than with a plotting crate: the drawing is a handful of polygons
//! and labels, and plain SVG keeps the output small, diffable and viewable anywhere.
//! Transmitters farther than the drawing's extent (a TV tower kilometres away) are drawn as
//! an arrow on the border pointing towards them, labelled with their distance.

use super::svg::escape;
use crate::world::scene::TransmitterKind;
use crate::world::World;
use std::fmt::Write;

const WIDTH_PX: f64 = 900.0;
const MARGIN_PX: f64 = 50.0;

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
            MARGIN_PX + (e - self.min_e) * self.scale,
            MARGIN_PX + (self.max_n - n) * self.scale,
        )
    }
}

impl View {
    /// The view of `pts` with a 5 % margin (at least 1 m) on every side, `WIDTH_PX` wide.
    fn fit(pts: &[[f64; 2]]) -> Self {
        let (mut min_e, mut max_e, mut min_n, mut max_n) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in pts {
            min_e = min_e.min(p[0]);
            max_e = max_e.max(p[0]);
            min_n = min_n.min(p[1]);
            max_n = max_n.max(p[1]);
        }
        let pad = 0.05 * (max_e - min_e).max(max_n - min_n).max(20.0);
        let (min_e, max_e, min_n, max_n) = (min_e - pad, max_e + pad, min_n - pad, max_n + pad);
        let scale = (WIDTH_PX - 2.0 * MARGIN_PX) / (max_e - min_e);
        let height_px = (max_n - min_n) * scale + 2.0 * MARGIN_PX + 30.0;
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
    pub colour: &'a str,
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
    let v = View::fit(&pts);
    let height_px = v.height_px;

    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH_PX}" height="{height_px:.0}" viewBox="0 0 {WIDTH_PX} {height_px:.0}" font-family="sans-serif" font-size="11">"#
    );
    let _ = writeln!(
        svg,
        r##"<rect width="100%" height="100%" fill="#f7f5ef"/><text x="{MARGIN_PX}" y="22" font-size="15">{}</text>"##,
        escape(&world.file.world.name)
    );
    draw_scene(&mut svg, &v, &cfg);
    // Over a report's coloured estimates the truth is drawn in black, so that no
    // estimator's colour can be mistaken for it.
    let truth_colour = if overlays.is_empty() {
        "#c0392b"
    } else {
        "#111"
    };
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
        for o in overlays {
            let mut d = String::new();
            let mut pen_up = true;
            for p in &o.points_enu_m {
                match p {
                    Some(p) => {
                        let (x, y) = v.px(p[0], p[1]);
                        let _ = write!(d, "{}{x:.1},{y:.1} ", if pen_up { "M" } else { "L" });
                        pen_up = false;
                    }
                    None => pen_up = true,
                }
            }
            let _ = writeln!(
                svg,
                r#"<path d="{}" fill="none" stroke="{}" stroke-width="1.3" stroke-opacity="0.85"/>"#,
                d.trim_end(),
                o.colour
            );
        }
        svg.push_str("</g>\n");
        let truth = Overlay {
            label: "truth",
            colour: truth_colour,
            points_enu_m: Vec::new(),
        };
        for (k, o) in std::iter::once(&truth).chain(overlays).enumerate() {
            let y = MARGIN_PX + 14.0 * k as f64;
            let _ = writeln!(
                svg,
                r#"<line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{}" stroke-width="3"/><text x="{:.1}" y="{:.1}">{}</text>"#,
                WIDTH_PX - 230.0,
                WIDTH_PX - 210.0,
                o.colour,
                WIDTH_PX - 205.0,
                y + 4.0,
                escape(o.label)
            );
        }
    }
    let (sx, sy) = v.px(track[0][0], track[0][1]);
    let _ = writeln!(
        svg,
        r##"<circle cx="{sx:.1}" cy="{sy:.1}" r="4" fill="{truth_colour}"/><text x="{:.1}" y="{:.1}">start</text>"##,
        sx + 6.0,
        sy - 6.0
    );

    draw_transmitters(&mut svg, &v, world);

    draw_scale_and_north(&mut svg, &v);
    svg.push_str("</svg>\n");
    Ok(svg)
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
/// kilometres away), as an arrow on the border pointing at it with its distance.
fn draw_transmitters(svg: &mut String, v: &View, world: &World) {
    for t in &world.transmitters {
        let colour = match t.kind {
            TransmitterKind::Dtmb => "#1f78b4",
            TransmitterKind::Tcofdm => "#6a3d9a",
            TransmitterKind::Fm => "#b15928",
        };
        let label = format!(
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
            let _ = writeln!(
                svg,
                r#"<polygon points="{:.1},{:.1} {:.1},{:.1} {:.1},{:.1}" fill="{colour}"/><text x="{:.1}" y="{:.1}" fill="{colour}">{}</text>"#,
                x,
                y - 7.0,
                x - 6.0,
                y + 5.0,
                x + 6.0,
                y + 5.0,
                x + 8.0,
                y + 4.0,
                escape(&label)
            );
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
                r#"<line x1="{x0:.1}" y1="{y0:.1}" x2="{x1:.1}" y2="{y1:.1}" stroke="{colour}" stroke-width="2.5"/><circle cx="{x1:.1}" cy="{y1:.1}" r="4" fill="{colour}"/><text x="{:.1}" y="{:.1}" fill="{colour}" text-anchor="middle">{} → {dist_km:.1} km</text>"#,
                x0 - 10.0 * ux,
                y0 - 10.0 * uy,
                escape(&label)
            );
        }
    }
}

/// A scale bar of the largest 1-2-5 length under a quarter of the width, and a north
/// arrow.
fn draw_scale_and_north(svg: &mut String, v: &View) {
    // Scale bar: the largest 1-2-5 length under a quarter of the width.
    let target_m = 0.25 * (v.max_e - v.min_e);
    let mut bar_m = 1.0;
    for mag in [1.0, 10.0, 100.0, 1000.0, 10_000.0] {
        for m in [1.0, 2.0, 5.0] {
            if m * mag <= target_m {
                bar_m = m * mag;
            }
        }
    }
    let y = v.height_px - 20.0;
    let _ = writeln!(
        svg,
        r##"<line x1="{MARGIN_PX}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#000" stroke-width="3"/><text x="{MARGIN_PX}" y="{:.1}">{bar_m} m</text>"##,
        MARGIN_PX + bar_m * v.scale,
        y - 6.0
    );
    let nx = WIDTH_PX - MARGIN_PX + 20.0;
    let _ = writeln!(
        svg,
        r##"<polygon points="{nx:.1},{:.1} {:.1},{:.1} {:.1},{:.1}" fill="#000"/><text x="{nx:.1}" y="{:.1}" text-anchor="middle">N</text>"##,
        MARGIN_PX,
        nx - 6.0,
        MARGIN_PX + 16.0,
        nx + 6.0,
        MARGIN_PX + 16.0,
        MARGIN_PX - 4.0
    );
}
