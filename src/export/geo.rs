//! GeoJSON (RFC 7946) and KML 2.2 (OGC 07-147r2) of a recorded trial: the scene's
//! buildings, forests and indoor zones, the transmitters, the true trajectory and each
//! estimator's, in WGS-84 longitude/latitude, for QGIS, geojson.io or Google Earth.
//!
//! RFC 7946 rules kept here: positions are `[lon, lat(, h)]`; rings are closed; exterior
//! rings are counter-clockwise (§3.1.6, the right-hand rule); no `crs` member; at most 8
//! decimals of a degree (about 1 mm).

use super::{write_text, Recording};
use crate::core::{EnuFrame, Geodetic};
use crate::world::World;
use nalgebra::Vector3;
use serde_json::{json, Value};
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// Everything drawn, in ENU metres, before conversion to a format.
struct Features {
    polygons: Vec<PolygonFeature>,
    points: Vec<PointFeature>,
    lines: Vec<LineFeature>,
}

struct PolygonFeature {
    kind: &'static str,
    name: String,
    ring_enu_m: Vec<[f64; 2]>,
    height_m: f64,
    props: Vec<(&'static str, Value)>,
}

struct PointFeature {
    name: String,
    kind: String,
    pos_ecef_m: Vector3<f64>,
    props: Vec<(&'static str, Value)>,
}

struct LineFeature {
    name: String,
    kind: &'static str,
    /// Positions (ECEF, m).
    points_ecef_m: Vec<Vector3<f64>>,
}

fn collect(world: &World, rec: &Recording) -> Result<Features, String> {
    let mut f = Features {
        polygons: Vec::new(),
        points: Vec::new(),
        lines: Vec::new(),
    };
    if let Some(scene) = &world.file.scene {
        let cfg = scene
            .resolve(&world.frame)
            .map_err(|(k, m)| format!("scene.{k}: {m}"))?
            .config;
        for (i, b) in cfg.buildings.iter().enumerate() {
            f.polygons.push(PolygonFeature {
                kind: "building",
                name: scene
                    .buildings
                    .get(i)
                    .and_then(|s| s.name.clone())
                    .unwrap_or_else(|| format!("building {}", i + 1)),
                ring_enu_m: b.footprint_enu_m.clone(),
                height_m: b.height_m,
                props: vec![
                    (
                        "material",
                        json!(format!("{:?}", b.material).to_lowercase()),
                    ),
                    ("class", json!(format!("{:?}", b.class).to_lowercase())),
                ],
            });
        }
        for (i, fo) in cfg.forests.iter().enumerate() {
            f.polygons.push(PolygonFeature {
                kind: "forest",
                name: format!("forest {}", i + 1),
                ring_enu_m: fo.polygon_enu_m.clone(),
                height_m: fo.height_m,
                props: vec![("foliage_density", json!(fo.foliage_density))],
            });
        }
        for (i, z) in cfg.indoor_zones.iter().enumerate() {
            f.polygons.push(PolygonFeature {
                kind: "indoor_zone",
                name: format!("indoor zone {}", i + 1),
                ring_enu_m: z.polygon_enu_m.clone(),
                height_m: 0.0,
                props: Vec::new(),
            });
        }
    }
    for t in &world.transmitters {
        f.points.push(PointFeature {
            name: t.id.clone(),
            kind: t.kind.label().to_string(),
            pos_ecef_m: t.pos_ecef_m,
            props: vec![
                ("freq_mhz", json!(t.freq_hz * 1e-6)),
                ("erp_dbw", json!(t.erp_dbw)),
            ],
        });
    }
    f.lines.push(LineFeature {
        name: "truth".into(),
        kind: "truth",
        points_ecef_m: rec.truth_track().iter().map(|t| t.pos_ecef_m).collect(),
    });
    for est in &rec.estimators {
        f.lines.push(LineFeature {
            name: est.name.clone(),
            kind: "estimate",
            points_ecef_m: est
                .epochs
                .iter()
                .filter_map(|e| e.est_ecef_m.map(Vector3::from))
                .collect(),
        });
    }
    Ok(f)
}

/// `[lon, lat]` of an ENU point on the ground plane, rounded to 1e-8°.
fn lon_lat(frame: &EnuFrame, e: f64, n: f64) -> [f64; 2] {
    let g = Geodetic::from_ecef(&frame.ecef_of_enu(&Vector3::new(e, n, 0.0)));
    [round8(g.lon_deg()), round8(g.lat_deg())]
}

fn round8(x: f64) -> f64 {
    (x * 1e8).round() / 1e8
}

/// A closed ring, counter-clockwise in (lon, lat) as RFC 7946 §3.1.6 asks of exterior
/// rings.
fn ring(frame: &EnuFrame, enu: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut r: Vec<[f64; 2]> = enu.iter().map(|p| lon_lat(frame, p[0], p[1])).collect();
    let area2: f64 = (0..r.len())
        .map(|i| {
            let (a, b) = (r[i], r[(i + 1) % r.len()]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum();
    if area2 < 0.0 {
        r.reverse();
    }
    if r.first() != r.last() {
        r.push(r[0]);
    }
    r
}

fn geodetic(p: &Vector3<f64>) -> [f64; 3] {
    let g = Geodetic::from_ecef(p);
    [
        round8(g.lon_deg()),
        round8(g.lat_deg()),
        (g.h_m * 1e3).round() / 1e3,
    ]
}

/// The GeoJSON FeatureCollection of a recording.
///
/// # Errors
/// When the world's scene cannot be resolved.
pub fn geojson(world: &World, rec: &Recording) -> Result<Value, String> {
    let f = collect(world, rec)?;
    let mut features = Vec::new();
    for p in &f.polygons {
        let mut props = serde_json::Map::new();
        props.insert("kind".into(), json!(p.kind));
        props.insert("name".into(), json!(p.name));
        props.insert("height_m".into(), json!(p.height_m));
        for (k, v) in &p.props {
            props.insert((*k).into(), v.clone());
        }
        features.push(json!({
            "type": "Feature",
            "geometry": {"type": "Polygon", "coordinates": [ring(&world.frame, &p.ring_enu_m)]},
            "properties": props,
        }));
    }
    for p in &f.points {
        let mut props = serde_json::Map::new();
        props.insert("kind".into(), json!("transmitter"));
        props.insert("system".into(), json!(p.kind));
        props.insert("name".into(), json!(p.name));
        for (k, v) in &p.props {
            props.insert((*k).into(), v.clone());
        }
        features.push(json!({
            "type": "Feature",
            "geometry": {"type": "Point", "coordinates": geodetic(&p.pos_ecef_m)},
            "properties": props,
        }));
    }
    for l in f.lines.iter().filter(|l| l.points_ecef_m.len() >= 2) {
        let coords: Vec<[f64; 3]> = l.points_ecef_m.iter().map(geodetic).collect();
        features.push(json!({
            "type": "Feature",
            "geometry": {"type": "LineString", "coordinates": coords},
            "properties": {"kind": l.kind, "name": l.name, "seed": rec.seed, "trial": rec.trial},
        }));
    }
    Ok(json!({"type": "FeatureCollection", "features": features}))
}

/// Writes `DIR/scene.geojson`.
pub fn write_geojson(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let v = geojson(world, rec)?;
    let text = serde_json::to_string_pretty(&v).map_err(|e| e.to_string())?;
    Ok(vec![write_text(dir, "scene.geojson", &text)?])
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Writes `DIR/scene.kml`: buildings and forests as extruded polygons at their heights,
/// transmitters as points at their antenna heights, trajectories as lines (absolute
/// altitudes: KML's are above mean sea level, here the ellipsoidal heights — within the
/// local geoid undulation, tens of metres, of what Google Earth draws).
pub fn write_kml(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let f = collect(world, rec)?;
    let mut k = String::from(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<kml xmlns=\"http://www.opengis.net/kml/2.2\">\n<Document>\n",
    );
    let _ = writeln!(k, "<name>{}</name>", xml_escape(&world.file.world.name));
    for (id, colour, width) in [
        ("building", "ff7f7f7f", 1),
        ("forest", "ff2e8b57", 1),
        ("indoor_zone", "ff0080ff", 1),
        ("truth", "ff0000ff", 3),
        ("estimate", "ffff7f00", 2),
    ] {
        let _ = writeln!(
            k,
            "<Style id=\"{id}\"><LineStyle><color>{colour}</color><width>{width}</width></LineStyle>\
             <PolyStyle><color>{}</color></PolyStyle></Style>",
            format_args!("99{}", &colour[2..])
        );
    }
    k.push_str("<Folder><name>Scene</name>\n");
    for p in &f.polygons {
        let coords: Vec<String> = ring(&world.frame, &p.ring_enu_m)
            .iter()
            .map(|c| format!("{},{},{}", c[0], c[1], p.height_m))
            .collect();
        let _ = writeln!(
            k,
            "<Placemark><name>{}</name><styleUrl>#{}</styleUrl><Polygon><extrude>1</extrude>\
             <altitudeMode>relativeToGround</altitudeMode><outerBoundaryIs><LinearRing>\
             <coordinates>{}</coordinates></LinearRing></outerBoundaryIs></Polygon></Placemark>",
            xml_escape(&p.name),
            p.kind,
            coords.join(" ")
        );
    }
    k.push_str("</Folder>\n<Folder><name>Transmitters</name>\n");
    for p in &f.points {
        let c = geodetic(&p.pos_ecef_m);
        let _ = writeln!(
            k,
            "<Placemark><name>{}</name><description>{}</description><Point>\
             <altitudeMode>absolute</altitudeMode><coordinates>{},{},{}</coordinates></Point></Placemark>",
            xml_escape(&p.name),
            xml_escape(&p.kind),
            c[0],
            c[1],
            c[2]
        );
    }
    k.push_str("</Folder>\n<Folder><name>Trajectories</name>\n");
    for l in f.lines.iter().filter(|l| l.points_ecef_m.len() >= 2) {
        let coords: Vec<String> = l
            .points_ecef_m
            .iter()
            .map(|p| {
                let c = geodetic(p);
                format!("{},{},{}", c[0], c[1], c[2])
            })
            .collect();
        let _ = writeln!(
            k,
            "<Placemark><name>{}</name><styleUrl>#{}</styleUrl><LineString>\
             <altitudeMode>absolute</altitudeMode><coordinates>{}</coordinates></LineString></Placemark>",
            xml_escape(&l.name),
            l.kind,
            coords.join(" ")
        );
    }
    k.push_str("</Folder>\n</Document>\n</kml>\n");
    Ok(vec![write_text(dir, "scene.kml", &k)?])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rings_are_closed_and_counter_clockwise() {
        let frame = EnuFrame::new(Geodetic::from_deg(40.0, 116.0, 0.0));
        // Clockwise in ENU (east, north): it must come out reversed.
        let cw = [[0.0, 0.0], [0.0, 10.0], [10.0, 10.0], [10.0, 0.0]];
        let r = ring(&frame, &cw);
        assert_eq!(r.len(), 5);
        assert_eq!(r[0], r[4]);
        let area2: f64 = r
            .windows(2)
            .map(|w| w[0][0] * w[1][1] - w[1][0] * w[0][1])
            .sum();
        assert!(area2 > 0.0);
        // 10 m east at 40° N is 10 / (cos 40° · 111 320 m/°) ≈ 1.17e-4 degrees.
        let span = r.iter().map(|c| c[0]).fold(f64::MIN, f64::max)
            - r.iter().map(|c| c[0]).fold(f64::MAX, f64::min);
        assert!((span - 10.0 / (40f64.to_radians().cos() * 111_320.0)).abs() < 2e-6);
    }
}
