//! Heat maps of one metric over the grid as SVG, drawn under the scene's building
//! outlines and the transmitters, with a colour bar ticked at 1-2-5 values. Cells whose
//! centre lies inside a building are hatched as indoor (the layout leaves them out of its
//! statistics; no receiver stands there), whatever their value. Plain SVG, as the world
//! map (`report::map`): one `<rect>` per cell, small and viewable anywhere.

use super::grid::Grid;
use crate::report::svg::{escape, fmt_tick, text_width_px, ticks, Labels};
use std::fmt::Write;

const WIDTH_PX: f64 = 900.0;
const MARGIN_PX: f64 = 50.0;
const BAR_PX: f64 = 70.0;

/// How values map to colours.
pub enum Scale {
    /// Continuous from `lo` to `hi` (values beyond are clamped); lower is better when
    /// `low_is_good`, and the palette runs from good (green) to bad (red).
    Continuous { lo: f64, hi: f64, low_is_good: bool },
    /// One colour per category, with its label.
    Categories(&'static [(&'static str, &'static str)]),
}

/// A point drawn on the map: a transmitter or a chosen site.
pub struct Marker<'a> {
    pub label: &'a str,
    pub east_m: f64,
    pub north_m: f64,
    pub colour: &'a str,
}

/// The fill of indoor cells: grey with dark diagonal hatching, unlike any colour of the
/// ramps or the categories.
const INDOOR_PATTERN: &str = r##"<defs><pattern id="indoor" width="6" height="6" patternUnits="userSpaceOnUse" patternTransform="rotate(45)"><rect width="6" height="6" fill="#d9d9d9"/><line x1="0" y1="0" x2="0" y2="6" stroke="#666" stroke-width="2"/></pattern></defs>"##;

/// Whether `(e, n)` lies inside the polygon `ring` (even–odd rule: a ray towards +east
/// crosses its edges an odd number of times).
fn inside(ring: &[[f64; 2]], e: f64, n: f64) -> bool {
    let mut odd = false;
    for (k, a) in ring.iter().enumerate() {
        let b = ring[(k + 1) % ring.len()];
        if (a[1] > n) != (b[1] > n) {
            let cross_e = a[0] + (n - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if e < cross_e {
                odd = !odd;
            }
        }
    }
    odd
}

/// A five-stop green–yellow–red ramp, linear in between.
fn ramp(t: f64) -> String {
    const STOPS: [(f64, [f64; 3]); 5] = [
        (0.0, [26.0, 150.0, 65.0]),
        (0.25, [166.0, 217.0, 106.0]),
        (0.5, [255.0, 255.0, 191.0]),
        (0.75, [253.0, 174.0, 97.0]),
        (1.0, [215.0, 25.0, 28.0]),
    ];
    let t = t.clamp(0.0, 1.0);
    let k = STOPS
        .windows(2)
        .position(|w| t <= w[1].0)
        .unwrap_or(STOPS.len() - 2);
    let (a, b) = (STOPS[k], STOPS[k + 1]);
    let w = (t - a.0) / (b.0 - a.0);
    let c: Vec<u8> = (0..3)
        .map(|i| (a.1[i] + w * (b.1[i] - a.1[i])).round() as u8)
        .collect();
    format!("rgb({},{},{})", c[0], c[1], c[2])
}

fn colour_of(v: f64, scale: &Scale) -> String {
    match scale {
        Scale::Continuous {
            lo,
            hi,
            low_is_good,
        } => {
            if v.is_nan() {
                return "#bbbbbb".into();
            }
            let t = if hi > lo { (v - lo) / (hi - lo) } else { 0.0 };
            ramp(if *low_is_good { t } else { 1.0 - t })
        }
        Scale::Categories(cats) => cats
            .get(v as usize)
            .map_or("#bbbbbb".into(), |c| c.1.to_string()),
    }
}

/// The SVG of `values` (one per cell, row-major from the south-west; NaN drawn grey)
/// with the building `outlines` and `markers` over it; cells whose centre is inside an
/// outline are hatched as indoor.
pub fn heat_map(
    title: &str,
    grid: &Grid,
    values: &[f64],
    scale: &Scale,
    outlines: &[Vec<[f64; 2]>],
    markers: &[Marker<'_>],
) -> String {
    let r = &grid.region;
    let span_e = grid.nx as f64 * grid.spacing_m;
    let span_n = grid.ny as f64 * grid.spacing_m;
    let px_per_m = (WIDTH_PX - 2.0 * MARGIN_PX) / span_e;
    let height_px = span_n * px_per_m + 2.0 * MARGIN_PX + BAR_PX;
    let px = |e: f64, n: f64| {
        (
            MARGIN_PX + (e - r.west_m) * px_per_m,
            MARGIN_PX + (r.south_m + span_n - n) * px_per_m,
        )
    };
    let mut s = String::with_capacity(values.len() * 90 + 4096);
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH_PX}" height="{height_px:.0}" viewBox="0 0 {WIDTH_PX} {height_px:.0}" font-family="sans-serif" font-size="11">"#
    );
    let _ = writeln!(
        s,
        r##"<title>{0}</title>{INDOOR_PATTERN}<rect width="100%" height="100%" fill="#f7f5ef"/><text x="{MARGIN_PX}" y="22" font-size="15">{0}</text>"##,
        escape(title)
    );
    let mut labels = Labels::new(WIDTH_PX, height_px);
    labels.reserve_text(title, 15.0, MARGIN_PX, 22.0);
    let mut any_indoor = false;
    // Cells overlap their neighbours by a hair so that no background shows between them.
    let side = grid.spacing_m * px_per_m;
    let _ = writeln!(s, r#"<g shape-rendering="crispEdges">"#);
    for j in 0..grid.ny {
        for i in 0..grid.nx {
            let v = values[j * grid.nx + i];
            let (sw, ne) = grid.corners(i, j);
            let (x, y) = px(sw[0], ne[1]);
            let (ce, cn) = grid.centre(i, j);
            let fill = if outlines.iter().any(|o| inside(o, ce, cn)) {
                any_indoor = true;
                "url(#indoor)".to_string()
            } else {
                colour_of(v, scale)
            };
            let _ = writeln!(
                s,
                r#"<rect x="{x:.2}" y="{y:.2}" width="{:.2}" height="{:.2}" fill="{fill}"/>"#,
                side + 0.05,
                side + 0.05,
            );
        }
    }
    let _ = writeln!(s, "</g>");
    for o in outlines {
        let mut d = String::new();
        for p in o {
            let (x, y) = px(p[0], p[1]);
            let _ = write!(d, "{x:.1},{y:.1} ");
        }
        let _ = writeln!(
            s,
            r##"<polygon points="{}" fill="none" stroke="#222" stroke-width="1"/>"##,
            d.trim_end()
        );
    }
    // Markers first, then their labels where they find room (two sites in one cell, or
    // transmitters pinned to one border point, list their labels one under another).
    let mut texts = Vec::new();
    for m in markers {
        // A transmitter outside the drawing is pinned to its border, where it points from.
        let (x, y) = px(m.east_m, m.north_m);
        let x = x.clamp(MARGIN_PX, WIDTH_PX - MARGIN_PX);
        let y = y.clamp(MARGIN_PX, MARGIN_PX + span_n * px_per_m);
        labels.reserve(x - 6.0, y - 7.0, x + 6.0, y + 5.0);
        let _ = writeln!(
            s,
            r##"<path d="M{x:.1},{:.1} L{:.1},{:.1} L{:.1},{:.1} Z" fill="{}" stroke="#000"/>"##,
            y - 7.0,
            x - 6.0,
            y + 5.0,
            x + 6.0,
            y + 5.0,
            m.colour,
        );
        let w = text_width_px(m.label, 11.0);
        texts.push((
            m.label,
            [
                (x + 8.0, y + 4.0),
                (x - 8.0 - w, y + 4.0),
                (x - 0.5 * w, y - 10.0),
            ],
        ));
    }
    let y0 = MARGIN_PX + span_n * px_per_m + 25.0;
    // The colour bar's area is set aside before the labels are placed.
    labels.reserve(0.0, y0 - 8.0, WIDTH_PX, height_px);
    for (text, candidates) in texts {
        let (x, y) = labels.place(text, 11.0, &candidates);
        let _ = writeln!(
            s,
            r##"<text x="{x:.1}" y="{y:.1}" stroke="#fff" stroke-width="3" stroke-opacity="0.85" paint-order="stroke">{}</text>"##,
            escape(text)
        );
    }
    // The colour bar or the category legend.
    match scale {
        Scale::Continuous {
            lo,
            hi,
            low_is_good,
        } => {
            let w = WIDTH_PX - 2.0 * MARGIN_PX;
            for k in 0..100 {
                let t = k as f64 / 99.0;
                let _ = writeln!(
                    s,
                    r#"<rect x="{:.1}" y="{y0:.1}" width="{:.2}" height="12" fill="{}"/>"#,
                    MARGIN_PX + t * (w - w / 100.0),
                    w / 100.0 + 0.5,
                    ramp(if *low_is_good { t } else { 1.0 - t })
                );
            }
            // Ticks at 1-2-5 values along the bar; beyond `hi` values are clamped to it,
            // which its label says.
            let bar_x = |v: f64| MARGIN_PX + (v - lo) / (hi - lo).max(1e-12) * w;
            let mut values = ticks(*lo, *hi, 8);
            // The low end is labelled too when it is not a tick and there is room for it.
            if values
                .first()
                .is_some_and(|t| bar_x(*t) - bar_x(*lo) >= 40.0)
            {
                values.insert(0, *lo);
            }
            for (k, v) in values.iter().enumerate() {
                let x = bar_x(*v);
                let text = if k + 1 == values.len() && (v - hi).abs() < 1e-9 * hi.abs().max(1.0) {
                    format!("≥ {}", fmt_tick(*v))
                } else {
                    fmt_tick(*v)
                };
                let _ = writeln!(
                    s,
                    r##"<line x1="{x:.1}" y1="{y0:.1}" x2="{x:.1}" y2="{:.1}" stroke="#222"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{text}</text>"##,
                    y0 + 17.0,
                    y0 + 29.0
                );
            }
            let mut key = "grey: no fix".to_string();
            if any_indoor {
                key.push_str(" · hatched: indoor (not evaluated)");
            }
            let _ = writeln!(
                s,
                r#"<text x="{MARGIN_PX}" y="{:.1}">{key}</text>"#,
                y0 + 46.0
            );
        }
        Scale::Categories(cats) => {
            let mut x = MARGIN_PX;
            for (label, colour) in cats.iter() {
                let _ = writeln!(
                    s,
                    r#"<rect x="{x:.1}" y="{y0:.1}" width="14" height="12" fill="{colour}"/><text x="{:.1}" y="{:.1}">{}</text>"#,
                    x + 20.0,
                    y0 + 10.0,
                    escape(label)
                );
                x += 20.0 + text_width_px(label, 11.0) + 24.0;
            }
            if any_indoor {
                let _ = writeln!(
                    s,
                    r##"<rect x="{x:.1}" y="{y0:.1}" width="14" height="12" fill="url(#indoor)" stroke="#666"/><text x="{:.1}" y="{:.1}">indoor (not evaluated)</text>"##,
                    x + 20.0,
                    y0 + 10.0,
                );
            }
        }
    }
    let _ = writeln!(
        s,
        r#"<text x="{MARGIN_PX}" y="{:.1}">grid {} m, {} × {} cells; E {:.0}…{:.0} m, N {:.0}…{:.0} m</text>"#,
        height_px - 8.0,
        grid.spacing_m,
        grid.nx,
        grid.ny,
        r.west_m,
        r.west_m + span_e,
        r.south_m,
        r.south_m + span_n
    );
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::grid::Region;

    #[test]
    fn one_rect_per_cell_and_a_closed_document() {
        let g = Grid::new(
            Region {
                west_m: 0.0,
                south_m: 0.0,
                east_m: 30.0,
                north_m: 20.0,
            },
            10.0,
            1,
            0,
        )
        .unwrap();
        let v = vec![1.0, 2.0, f64::NAN, 4.0, 5.0, 6.0];
        let s = heat_map(
            "t & <x>",
            &g,
            &v,
            &Scale::Continuous {
                lo: 1.0,
                hi: 6.0,
                low_is_good: true,
            },
            &[vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]],
            &[],
        );
        assert!(s.ends_with("</svg>\n"));
        assert!(s.contains("t &amp; &lt;x&gt;"));
        assert_eq!(s.matches("#bbbbbb").count(), 1);
        // The colour bar is ticked at 1-2-5 values between its ends, not only at them.
        for tick in [
            ">1</text>",
            ">2</text>",
            ">3</text>",
            ">4</text>",
            ">5</text>",
            ">≥ 6</text>",
        ] {
            assert!(s.contains(tick), "no tick {tick}");
        }
        // The cell whose centre (5, 5) lies in the triangle is hatched as indoor; the
        // one whose centre (15, 5) does not is coloured by its value.
        assert_eq!(s.matches(r#"fill="url(#indoor)"/>"#).count(), 1);
        assert!(s.contains("hatched: indoor"));
        assert_eq!(ramp(0.0), "rgb(26,150,65)");
        assert_eq!(ramp(1.0), "rgb(215,25,28)");
    }
}
