//! Transmitter-layout design: coverage, geometry and predicted accuracy over a grid, and
//! the choice of new transmitter sites.
//!
//! `hybridnav layout WORLD --grid 10 --out DIR` lays a grid over the world's region
//! ([`grid`]), evaluates every cell ([`eval`], models in [`metrics`]) and writes
//! `layout.json`, `grid.csv`, `layout.geojson` and one SVG heat map per metric. With
//! `--place K --candidates FILE` it also chooses K new sites ([`place`]) and writes
//! `placement.json` and the heat maps of the completed layout. `docs/layout.md` is the
//! user's guide.

pub mod eval;
pub mod grid;
pub mod metrics;
pub mod place;
pub mod svg;

use crate::core::{GpsTime, System};
use crate::io::atomic::write_atomic;
use crate::world::World;
use eval::Context;
use grid::{Grid, Region};
use metrics::{CellMetrics, ClockModel, Coverage, Normals};
use nalgebra::Vector3;
use place::{Candidate, Objective, Placement};
use serde_json::{json, Value};
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// What `hybridnav layout` is asked to do (the CLI's options, checked by [`run`]).
#[derive(Debug, Clone)]
pub struct LayoutRequest {
    /// The world file.
    pub world: PathBuf,
    /// Grid spacing (m).
    pub grid: f64,
    /// Output directory.
    pub out: PathBuf,
    /// Receiver antenna height above the ground (m).
    pub height: f64,
    /// GNSS epoch: `YYYY-MM-DDTHH:MM:SS GPST`, or `+SECONDS` after the world's start
    /// (default: the start). Repeat for several epochs; each cell reports its worst.
    pub times: Vec<String>,
    /// The region as `W,S,E,N` in the world's ENU metres (default: the scene and the
    /// trajectory; see docs/layout.md).
    pub region: Option<String>,
    /// How ranges share clock unknowns.
    pub clocks: ClockModel,
    /// Choose this many new sites from `--candidates`.
    pub place: Option<usize>,
    /// Candidate sites: CSV `id,east_m,north_m,height_m[,kind[,erp_kw[,freq_mhz]]]`.
    pub candidates: Option<PathBuf>,
    /// What the placement minimises over the region.
    pub objective: Objective,
    /// Seed of the random-placement baseline.
    pub seed: u64,
    /// Random placements in the baseline.
    pub random_trials: usize,
}

/// What stops `hybridnav layout`: the world file, or an option or input it cannot use
/// (the message names the option and what was expected).
#[derive(Debug, thiserror::Error)]
pub enum LayoutError {
    #[error(transparent)]
    World(#[from] crate::world::WorldError),
    #[error("{0}")]
    Invalid(String),
}

/// The epochs of `--time` (the world's start when none is given).
fn epochs(world: &World, times: &[String]) -> Result<Vec<GpsTime>, LayoutError> {
    if times.is_empty() {
        return Ok(vec![world.start]);
    }
    times
        .iter()
        .map(|t| {
            if let Some(rest) = t.strip_prefix('+') {
                let s: f64 = rest.trim().parse().map_err(|_| {
                    LayoutError::Invalid(format!(
                        "--time {t:?}: expected +SECONDS after the world's start"
                    ))
                })?;
                if !(s.is_finite() && s.abs() < 1e8) {
                    return Err(LayoutError::Invalid(format!(
                        "--time {t:?}: expected a finite offset in seconds"
                    )));
                }
                Ok(world.start.add_seconds(s))
            } else {
                GpsTime::parse_iso(t)
                    .map_err(|m| LayoutError::Invalid(format!("--time {t:?}: {m}")))
            }
        })
        .collect()
}

/// Runs `hybridnav layout`.
///
/// # Errors
/// Every user-facing failure, with what was expected.
pub fn run(args: &LayoutRequest) -> Result<(), LayoutError> {
    let started = std::time::Instant::now();
    if !(args.height.is_finite() && (0.0..=1000.0).contains(&args.height)) {
        return Err(LayoutError::Invalid(format!(
            "--height: expected a receiver height in [0, 1000] m, got {}",
            args.height
        )));
    }
    if !(args.grid.is_finite() && args.grid > 0.0) {
        return Err(LayoutError::Invalid(format!(
            "--grid: expected a spacing > 0 m, got {}",
            args.grid
        )));
    }
    let k = match (args.place, &args.candidates) {
        (None, None) => 0,
        (Some(0), _) => {
            return Err(LayoutError::Invalid(
                "--place: expected at least 1 site, got 0".to_string(),
            ))
        }
        (Some(k), Some(_)) => k,
        (Some(_), None) => {
            return Err(LayoutError::Invalid(
                "--place needs --candidates FILE".to_string(),
            ))
        }
        (None, Some(_)) => {
            return Err(LayoutError::Invalid(
                "--candidates needs --place K".to_string(),
            ))
        }
    };
    let world = crate::world::load_world(&args.world)?;
    // Every command that reads a world shows its warnings (the CLI's own loader does the
    // same); layout sits below the CLI and so prints them itself.
    for m in &world.warnings {
        eprintln!("warning: {m}");
    }
    let times = epochs(&world, &args.times)?;
    let region = match &args.region {
        Some(r) => Region::parse(r).map_err(LayoutError::Invalid)?,
        None => Region::of_world(&world).map_err(LayoutError::Invalid)?,
    };
    let candidates = match &args.candidates {
        Some(p) => place::parse_candidates(p, &region).map_err(LayoutError::Invalid)?,
        None => Vec::new(),
    };
    // A candidate mast must stand where the world would accept a transmitter: above the
    // ground and not inside a building (on a roof is fine).
    if let (Some(scene), Some(file)) = (world.scene.as_deref(), &args.candidates) {
        for c in &candidates {
            scene
                .check_transmitter(&Vector3::new(c.east_m, c.north_m, c.height_m))
                .map_err(|i| {
                    LayoutError::Invalid(format!(
                        "{}:{}: candidate {}: {}",
                        file.display(),
                        c.line,
                        c.id,
                        i.message
                    ))
                })?;
        }
    }
    if k > candidates.len() {
        return Err(LayoutError::Invalid(format!(
            "--place {k}: only {} candidate sites in {}",
            candidates.len(),
            args.candidates
                .as_deref()
                .unwrap_or(Path::new("?"))
                .display()
        )));
    }
    let grid = Grid::new(region, args.grid, times.len(), candidates.len())
        .map_err(LayoutError::Invalid)?;
    let centre = (
        0.5 * (region.west_m + region.east_m),
        0.5 * (region.south_m + region.north_m),
    );
    let ctx = Context::new(&world, &times, args.clocks, args.height, centre);
    if ctx.gnss.is_none() && ctx.sites.is_empty() && k == 0 {
        eprintln!(
            "note: {} has no [sensors.gnss] and no DTMB or TC-OFDM transmitter: no cell can have a fix (other emitters are not modelled by layout)",
            args.world.display()
        );
    }
    std::fs::create_dir_all(&args.out).map_err(|e| {
        LayoutError::Invalid(format!(
            "cannot create the output directory {}: {e}",
            args.out.display()
        ))
    })?;

    let t0 = std::time::Instant::now();
    let (cells, base) = ctx.evaluate(&grid, k > 0);
    let grid_s = t0.elapsed().as_secs_f64();
    let considered: Vec<usize> = (0..cells.len()).filter(|&c| !cells[c].indoor).collect();
    println!(
        "layout: {} × {} cells of {} m ({} outdoor) over E {:.0}…{:.0} m, N {:.0}…{:.0} m in {:.2} s ({:.0} cells/s)",
        grid.nx,
        grid.ny,
        grid.spacing_m,
        considered.len(),
        region.west_m,
        region.east_m,
        region.south_m,
        region.north_m,
        grid_s,
        cells.len() as f64 / grid_s.max(1e-9)
    );

    // The wall time is printed above, not stored: the same world and options must give
    // the same files.
    let mut summary = summary_json(&world, &ctx, &grid, &cells, &considered, args);
    let outlines = building_outlines(&world);
    let markers: Vec<(String, f64, f64, &str)> = ctx
        .sites
        .iter()
        .map(|s| (s.id.clone(), s.pos_enu_m.x, s.pos_enu_m.y, "#1f78b4"))
        .collect();

    let placed = if k > 0 {
        Some(place_sites(
            args,
            &ctx,
            &grid,
            &candidates,
            &cells,
            &base,
            &considered,
            times.len(),
            k,
            &mut summary,
        )?)
    } else {
        None
    };

    write_json(&args.out.join("layout.json"), &summary)?;
    write_file(
        &args.out.join("grid.csv"),
        &grid_csv(
            &world,
            &grid,
            &cells,
            placed.as_ref().map(|p| &p.1[..]),
            args.height,
        ),
    )?;
    write_file(
        &args.out.join("layout.geojson"),
        &geojson(&world, &grid, &cells),
    )?;
    let marker_refs: Vec<svg::Marker<'_>> = markers
        .iter()
        .map(|(id, e, n, c)| svg::Marker {
            label: id,
            east_m: *e,
            north_m: *n,
            colour: c,
        })
        .collect();
    write_maps(
        &args.out,
        "",
        &world,
        &grid,
        &cells,
        &outlines,
        &marker_refs,
    )?;
    if let Some((p, after)) = &placed {
        let mut m2 = marker_refs;
        for &i in &p.chosen {
            let c = &candidates[i];
            m2.push(svg::Marker {
                label: &c.id,
                east_m: c.east_m,
                north_m: c.north_m,
                colour: "#e31a1c",
            });
        }
        write_maps(&args.out, "placed_", &world, &grid, after, &outlines, &m2)?;
    }
    println!(
        "layout: wrote {} in {:.2} s",
        args.out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `--place K`: chooses `k` of the candidate sites (greedy, then local search, against a
/// random baseline), writes `placement.json`, notes the choice in the summary, and
/// returns the placement with the cells' metrics once the chosen sites are added.
#[allow(clippy::too_many_arguments)]
fn place_sites(
    args: &LayoutRequest,
    ctx: &Context<'_>,
    grid: &Grid,
    candidates: &[Candidate],
    cells: &[CellMetrics],
    base: &[Normals],
    considered: &[usize],
    epochs: usize,
    k: usize,
    summary: &mut Value,
) -> Result<(Placement, Vec<CellMetrics>), LayoutError> {
    let sites: Vec<_> = candidates.iter().map(|c| candidate_site(ctx, c)).collect();
    let rows = ctx.site_rows(grid, &sites);
    let problem = place::Problem {
        base,
        epochs,
        rows: &rows,
        cells: grid.cells(),
        considered,
        objective: args.objective,
    };
    let f = |s: &[usize]| problem.score(s);
    let unit = match args.objective {
        Objective::Gdop95 => "",
        Objective::Error95 => " m",
    };
    let start = problem.score(&[]);
    println!(
        "place: {k} of {} candidates minimising {:?}; without new sites p95 {:.3}{unit} (mean {:.3})",
        candidates.len(),
        args.objective,
        start.p95,
        start.mean
    );
    let names = |s: &[usize]| {
        s.iter()
            .map(|&i| candidates[i].id.as_str())
            .collect::<Vec<_>>()
            .join(",")
    };
    let p = place::optimise(candidates.len(), k, &f, &mut |step| {
        println!(
            "place: {:<6} [{}] p95 {:.4}{unit} (mean {:.4})",
            step.phase,
            names(&step.chosen),
            step.score.p95,
            step.score.mean
        );
    });
    // Each candidate alone: what the first greedy step compared, kept for the user (and
    // for checking the evaluation's symmetry).
    let single: Vec<Value> = (0..candidates.len())
        .map(|i| {
            let s = f(&[i]);
            json!({ "id": candidates[i].id, "p95": s.p95, "mean": s.mean })
        })
        .collect();
    let random = place::random_baseline(candidates.len(), k, args.random_trials, args.seed, &f);
    let rp: Vec<f64> = random.iter().map(|s| s.p95).collect();
    let r_mean = rp.iter().sum::<f64>() / rp.len().max(1) as f64;
    let r_min = rp.iter().copied().fold(f64::INFINITY, f64::min);
    let r_better = random.iter().filter(|s| s.better_than(&p.score)).count();
    println!(
        "place: greedy p95 {:.4}{unit}, after local search {:.4}{unit} [{}]; {} random placements (seed {}): mean p95 {:.4}{unit}, best {:.4}{unit}, {} better than the search",
        p.greedy_score.p95,
        p.score.p95,
        names(&p.chosen),
        random.len(),
        args.seed,
        r_mean,
        r_min,
        r_better
    );
    // The completed layout: the world's transmitters and the chosen sites.
    let mut after = cells.to_vec();
    for (c, m) in after.iter_mut().enumerate() {
        let mut worst = (0.0f64, 0.0f64);
        for e in 0..epochs {
            let mut n = base[c * epochs + e];
            for &s in &p.chosen {
                n.add(&rows[s * grid.cells() + c]);
            }
            let (g, s) = n.solve();
            worst = (worst.0.max(g), worst.1.max(s));
        }
        m.gdop_hybrid = worst.0;
        m.sigma_hybrid_m = worst.1;
    }
    let placement = json!({
        "objective": args.objective,
        "k": k,
        "candidates": candidates,
        "without_new_sites": start,
        "greedy": { "sites": ids(candidates, &p.greedy), "score": p.greedy_score },
        "chosen": { "sites": ids(candidates, &p.chosen), "score": p.score },
        "steps": p.steps.iter().map(|s| json!({
            "phase": s.phase,
            "sites": ids(candidates, &s.chosen),
            "p95": s.score.p95,
            "mean": s.score.mean,
        })).collect::<Vec<_>>(),
        "evaluations": p.evaluations,
        "single_site": single,
        "random": {
            "seed": args.seed,
            "trials": random.len(),
            "p95_mean": r_mean,
            "p95_min": r_min,
            "better_than_search": r_better,
            "p95": rp,
        },
        "after": stats_json(&after, considered),
    });
    write_json(&args.out.join("placement.json"), &placement)?;
    summary["placement"] = json!({
        "chosen": ids(candidates, &p.chosen),
        "score": p.score,
        "greedy_score": p.greedy_score,
    });
    Ok((p, after))
}

/// The site a candidate describes, with the world's receiver parameters.
pub fn candidate_site(ctx: &Context<'_>, c: &Candidate) -> metrics::Site {
    let system = if c.kind == "tcofdm" {
        System::Tcofdm
    } else {
        System::Dtmb
    };
    ctx.site(
        &c.id,
        system,
        Vector3::new(c.east_m, c.north_m, c.height_m),
        c.freq_mhz * 1e6,
        10.0 * (c.erp_kw * 1e3).log10(),
        crate::dtmb::PnMode::Pn945,
        crate::dtmb::service::DEFAULT_PROFILE,
    )
}

fn ids(c: &[Candidate], s: &[usize]) -> Vec<String> {
    s.iter().map(|&i| c[i].id.clone()).collect()
}

fn write_file(path: &Path, text: &str) -> Result<(), LayoutError> {
    write_atomic(path, text.as_bytes())
        .map_err(|e| LayoutError::Invalid(format!("cannot write {}: {e}", path.display())))
}

fn write_json(path: &Path, v: &Value) -> Result<(), LayoutError> {
    let mut text = serde_json::to_string_pretty(v)
        .map_err(|e| LayoutError::Invalid(format!("cannot encode {}: {e}", path.display())))?;
    text.push('\n');
    write_file(path, &text)
}

/// A number for JSON: `null` for ±∞ and NaN (no fix), which JSON cannot hold.
fn num(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// p50, p95 and max of one metric over the considered cells (nearest rank; an
/// infinite value, a cell without a fix, sorts last and shows as `null`), and the share
/// of cells with a finite value.
fn metric_stats(
    cells: &[CellMetrics],
    considered: &[usize],
    f: impl Fn(&CellMetrics) -> f64,
) -> Value {
    let mut v: Vec<f64> = considered.iter().map(|&c| f(&cells[c])).collect();
    v.sort_by(f64::total_cmp);
    let finite = v.iter().filter(|x| x.is_finite()).count();
    json!({
        "p50": num(place::percentile(&v, 50.0)),
        "p95": num(place::percentile(&v, 95.0)),
        "max": num(v.last().copied().unwrap_or(f64::NAN)),
        "finite_share": finite as f64 / v.len().max(1) as f64,
    })
}

fn stats_json(cells: &[CellMetrics], considered: &[usize]) -> Value {
    let share = |f: &dyn Fn(&CellMetrics) -> bool| {
        considered.iter().filter(|&&c| f(&cells[c])).count() as f64 / considered.len().max(1) as f64
    };
    json!({
        "gdop_gnss": metric_stats(cells, considered, |m| m.gdop_gnss),
        "gdop_hybrid": metric_stats(cells, considered, |m| m.gdop_hybrid),
        "sigma_gnss_m": metric_stats(cells, considered, |m| m.sigma_gnss_m),
        "sigma_hybrid_m": metric_stats(cells, considered, |m| m.sigma_hybrid_m),
        "n_gps": metric_stats(cells, considered, |m| f64::from(m.n_gps)),
        "n_bds": metric_stats(cells, considered, |m| f64::from(m.n_bds)),
        "n_dtmb": metric_stats(cells, considered, |m| f64::from(m.n_dtmb)),
        "n_tcofdm": metric_stats(cells, considered, |m| f64::from(m.n_tcofdm)),
        "coverage_share": {
            "any": share(&|m| m.coverage != Coverage::None),
            "los": share(&|m| m.coverage == Coverage::Los),
            "foliage": share(&|m| m.coverage == Coverage::Foliage),
            "nlos_only": share(&|m| m.coverage == Coverage::Nlos),
            "none": share(&|m| m.coverage == Coverage::None),
        },
        "dtmb_service_margin_db": metric_stats(cells, considered, |m| m.dtmb_service_margin_db),
        "dtmb_service_share": share(&|m| m.dtmb_service_margin_db >= 0.0),
        "hybrid_fix_share": share(&|m| m.gdop_hybrid.is_finite()),
        "gnss_fix_share": share(&|m| m.gdop_gnss.is_finite()),
    })
}

fn summary_json(
    world: &World,
    ctx: &Context<'_>,
    grid: &Grid,
    cells: &[CellMetrics],
    considered: &[usize],
    args: &LayoutRequest,
) -> Value {
    let frames = world
        .file
        .sensors
        .dtmb
        .as_ref()
        .map_or(1, |d| d.accumulation_frames.max(1) as usize);
    json!({
        "world": world.path.display().to_string(),
        "world_hash": world.hash,
        "grid": {
            "spacing_m": grid.spacing_m,
            "nx": grid.nx,
            "ny": grid.ny,
            "cells": grid.cells(),
            "outdoor_cells": considered.len(),
        },
        "region_enu_m": grid.region,
        "receiver_height_m": args.height,
        "clocks": args.clocks,
        "epochs": ctx.epochs.iter().map(|e| json!({
            "time": e.t.to_iso_gpst(),
            "satellites_in_view": e.sats.len(),
        })).collect::<Vec<_>>(),
        "transmitters": ctx.sites.iter().map(|s| json!({
            "id": s.id,
            "system": s.system.name(),
            "enu_m": [s.pos_enu_m.x, s.pos_enu_m.y, s.pos_enu_m.z],
        })).collect::<Vec<_>>(),
        "sync_threshold_snr_db_pn945": metrics::sync_threshold_snr_db(crate::dtmb::PnMode::Pn945, frames),
        "statistics": stats_json(cells, considered),
    })
}

/// The resolved building footprints, drawn over the heat maps.
fn building_outlines(world: &World) -> Vec<Vec<[f64; 2]>> {
    world
        .file
        .scene
        .as_ref()
        .and_then(|s| s.resolve(&world.frame).ok())
        .map(|r| {
            r.config
                .buildings
                .into_iter()
                .map(|b| b.footprint_enu_m)
                .collect()
        })
        .unwrap_or_default()
}

/// WGS-84 (lon, lat) in degrees of an ENU point on the origin's ground plane.
fn lon_lat(world: &World, e: f64, n: f64) -> (f64, f64) {
    let g = crate::core::Geodetic::from_ecef(&world.frame.ecef_of_enu(&Vector3::new(e, n, 0.0)));
    (g.lon_deg(), g.lat_deg())
}

fn fmt_num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        String::new()
    }
}

/// `grid.csv`: one row per cell (empty field: no fix).
fn grid_csv(
    world: &World,
    grid: &Grid,
    cells: &[CellMetrics],
    after: Option<&[CellMetrics]>,
    height_m: f64,
) -> String {
    let mut s = String::with_capacity(cells.len() * 180);
    s.push_str("i,j,east_m,north_m,lat_deg,lon_deg,height_m,indoor,n_gps,n_bds,n_dtmb,n_tcofdm,n_terr_los,n_terr_foliage,n_terr_nlos,coverage,best_terr_snr_db,gdop_gnss,gdop_hybrid,sigma_gnss_m,sigma_hybrid_m,dtmb_service_margin_db");
    if after.is_some() {
        s.push_str(",gdop_hybrid_placed,sigma_hybrid_placed_m");
    }
    s.push('\n');
    for j in 0..grid.ny {
        for i in 0..grid.nx {
            let c = j * grid.nx + i;
            let m = &cells[c];
            let (e, n) = grid.centre(i, j);
            let (lon, lat) = lon_lat(world, e, n);
            let _ = write!(
                s,
                "{i},{j},{e:.2},{n:.2},{lat:.8},{lon:.8},{height_m},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
                u8::from(m.indoor),
                m.n_gps,
                m.n_bds,
                m.n_dtmb,
                m.n_tcofdm,
                m.n_terr_los,
                m.n_terr_foliage,
                m.n_terr_nlos,
                m.coverage.label(),
                fmt_num(m.best_terr_snr_db),
                fmt_num(m.gdop_gnss),
                fmt_num(m.gdop_hybrid),
                fmt_num(m.sigma_gnss_m),
                fmt_num(m.sigma_hybrid_m),
                fmt_num(m.dtmb_service_margin_db)
            );
            if let Some(a) = after {
                let _ = write!(
                    s,
                    ",{},{}",
                    fmt_num(a[c].gdop_hybrid),
                    fmt_num(a[c].sigma_hybrid_m)
                );
            }
            s.push('\n');
        }
    }
    s
}

/// `layout.geojson` (RFC 7946): a FeatureCollection of one Polygon per cell in WGS-84
/// longitude, latitude; each exterior ring counter-clockwise (south-west, south-east,
/// north-east, north-west, south-west: the right-hand rule) and closed; no `crs` member.
fn geojson(world: &World, grid: &Grid, cells: &[CellMetrics]) -> String {
    let mut s = String::with_capacity(cells.len() * 520 + 64);
    s.push_str("{\"type\":\"FeatureCollection\",\"features\":[\n");
    for j in 0..grid.ny {
        for i in 0..grid.nx {
            let c = j * grid.nx + i;
            let m = &cells[c];
            let (sw, ne) = grid.corners(i, j);
            let ring = [
                (sw[0], sw[1]),
                (ne[0], sw[1]),
                (ne[0], ne[1]),
                (sw[0], ne[1]),
                (sw[0], sw[1]),
            ];
            let coords: Vec<String> = ring
                .iter()
                .map(|&(e, n)| {
                    let (lon, lat) = lon_lat(world, e, n);
                    format!("[{lon:.8},{lat:.8}]")
                })
                .collect();
            let props = json!({
                "i": i, "j": j,
                "indoor": m.indoor,
                "n_gps": m.n_gps, "n_bds": m.n_bds,
                "n_dtmb": m.n_dtmb, "n_tcofdm": m.n_tcofdm,
                "coverage": m.coverage.label(),
                "best_terr_snr_db": num(m.best_terr_snr_db),
                "gdop_gnss": num(m.gdop_gnss),
                "gdop_hybrid": num(m.gdop_hybrid),
                "sigma_gnss_m": num(m.sigma_gnss_m),
                "sigma_hybrid_m": num(m.sigma_hybrid_m),
                "dtmb_service_margin_db": num(m.dtmb_service_margin_db),
            });
            let _ = write!(
                s,
                "{}{{\"type\":\"Feature\",\"geometry\":{{\"type\":\"Polygon\",\"coordinates\":[[{}]]}},\"properties\":{}}}",
                if c == 0 { "" } else { ",\n" },
                coords.join(","),
                props
            );
        }
    }
    s.push_str("\n]}\n");
    s
}

/// The heat maps, file names prefixed by `prefix`.
fn write_maps(
    dir: &Path,
    prefix: &str,
    world: &World,
    grid: &Grid,
    cells: &[CellMetrics],
    outlines: &[Vec<[f64; 2]>],
    markers: &[svg::Marker<'_>],
) -> Result<(), LayoutError> {
    let has_dtmb = world
        .transmitters
        .iter()
        .any(|t| t.kind == crate::world::scene::TransmitterKind::Dtmb);
    const COVERAGE: &[(&str, &str)] = &[
        ("no usable DTMB/TC-OFDM", "#d7191c"),
        ("NLOS only", "#fdae61"),
        ("foliage", "#a6d96a"),
        ("line of sight", "#1a9641"),
    ];
    const SERVICE: &[(&str, &str)] = &[
        ("no DTMB programme decodable", "#d7191c"),
        (
            "DTMB programme decodable (SNR over its AWGN threshold)",
            "#1a9641",
        ),
    ];
    let name = &world.file.world.name;
    let finite_max = |f: &dyn Fn(&CellMetrics) -> f64, cap: f64| {
        cells
            .iter()
            .map(f)
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max)
            .min(cap)
    };
    let nan_inf = |v: f64| if v.is_finite() { v } else { f64::NAN };
    let maps: Vec<(&str, String, Vec<f64>, svg::Scale)> = vec![
        (
            "gdop_gnss",
            format!("{name}: GDOP, GNSS only"),
            cells.iter().map(|m| nan_inf(m.gdop_gnss)).collect(),
            svg::Scale::Continuous {
                lo: 1.0,
                hi: 10.0,
                low_is_good: true,
            },
        ),
        (
            "gdop_hybrid",
            format!("{name}: GDOP, GNSS + terrestrial"),
            cells.iter().map(|m| nan_inf(m.gdop_hybrid)).collect(),
            svg::Scale::Continuous {
                lo: 1.0,
                hi: 10.0,
                low_is_good: true,
            },
        ),
        (
            "error_hybrid",
            format!("{name}: predicted 3-D error σ (m), GNSS + terrestrial"),
            cells.iter().map(|m| nan_inf(m.sigma_hybrid_m)).collect(),
            svg::Scale::Continuous {
                lo: 0.0,
                hi: finite_max(&|m| m.sigma_hybrid_m, 50.0).max(1.0),
                low_is_good: true,
            },
        ),
        (
            "dtmb_count",
            format!("{name}: usable DTMB + TC-OFDM transmitters"),
            cells
                .iter()
                .map(|m| f64::from(m.n_dtmb + m.n_tcofdm))
                .collect(),
            svg::Scale::Continuous {
                lo: 0.0,
                hi: finite_max(&|m| f64::from(m.n_dtmb + m.n_tcofdm), 1e9).max(1.0),
                low_is_good: false,
            },
        ),
        (
            "coverage",
            format!("{name}: terrestrial coverage (best usable link)"),
            cells.iter().map(|m| m.coverage as u8 as f64).collect(),
            svg::Scale::Categories(COVERAGE),
        ),
        (
            "service",
            format!("{name}: DTMB service (best tower's SNR over its profile's threshold)"),
            cells
                .iter()
                .map(|m| f64::from(u8::from(m.dtmb_service_margin_db >= 0.0)))
                .collect(),
            svg::Scale::Categories(SERVICE),
        ),
    ];
    for (file, title, values, scale) in &maps {
        if !prefix.is_empty() && !matches!(*file, "gdop_hybrid" | "error_hybrid") {
            continue;
        }
        // A world without a DTMB tower has no programme to map.
        if *file == "service" && !has_dtmb {
            continue;
        }
        let title = if prefix.is_empty() {
            title.clone()
        } else {
            format!("{title}, with the chosen sites")
        };
        let text = svg::heat_map(&title, grid, values, scale, outlines, markers);
        write_file(&dir.join(format!("{prefix}{file}.svg")), &text)?;
    }
    Ok(())
}
