//! The region a layout study covers and the regular grid laid over it.
//!
//! The region is an east–north rectangle in the world's ENU frame. Unless the user gives
//! one (`--region W,S,E,N`), it is the bounding box of the scene's outlines (buildings,
//! forests, tree rows, indoor zones, surfaces) together with the trajectory, so that the
//! route is always covered; a world without a scene uses the trajectory's box widened by
//! [`NO_SCENE_MARGIN_M`] on every side (a straight road would otherwise give a region of
//! zero width). Cells are squares of the grid spacing; the last column and row may stick
//! out of the region by less than one spacing, so that the region is covered whole.

use crate::world::World;

/// Margin around the trajectory's box when the world has no scene (m).
pub const NO_SCENE_MARGIN_M: f64 = 100.0;
/// The most cells a grid may have, whatever the memory estimate says.
pub const MAX_CELLS: u64 = 20_000_000;
/// The most memory (bytes) a layout run may estimate for itself before it refuses.
pub const MAX_BYTES: u64 = 2 << 30;
/// Memory per cell independent of the epochs and candidates: the metrics (about 70 bytes)
/// and the text of the outputs, measured on the default world at about 100 bytes per cell
/// for the CSV, 465 for the GeoJSON and 87 for each of up to seven SVG maps; counted as if
/// all were held at once, which overestimates (they are written one after the other).
pub const BYTES_PER_CELL: u64 = 1_300;
/// Memory per cell and epoch when sites are placed: the two 7 × 7 normal matrices of the
/// base geometry (2 · 49 · 8 bytes).
pub const BYTES_PER_CELL_EPOCH: u64 = 784;
/// Memory per cell and candidate site: its geometry row.
pub const BYTES_PER_CELL_CANDIDATE: u64 = 40;

/// An east–north rectangle in the world's ENU frame (m).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Region {
    pub west_m: f64,
    pub south_m: f64,
    pub east_m: f64,
    pub north_m: f64,
}

impl Region {
    /// Whether the point `(e, n)` lies inside, borders included.
    pub fn contains(&self, e: f64, n: f64) -> bool {
        (self.west_m..=self.east_m).contains(&e) && (self.south_m..=self.north_m).contains(&n)
    }

    /// Parses `W,S,E,N` in metres.
    ///
    /// # Errors
    /// A message naming what was expected.
    pub fn parse(text: &str) -> Result<Self, String> {
        let v: Vec<f64> = text
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("--region: expected W,S,E,N in metres, got {text:?}"))?;
        let [w, s, e, n] = v[..] else {
            return Err(format!(
                "--region: expected four numbers W,S,E,N, got {}",
                v.len()
            ));
        };
        if !(v.iter().all(|x| x.is_finite()) && e > w && n > s) {
            return Err(format!(
                "--region: expected finite W < E and S < N, got {text:?}"
            ));
        }
        Ok(Self {
            west_m: w,
            south_m: s,
            east_m: e,
            north_m: n,
        })
    }

    /// The world's region (module documentation).
    ///
    /// # Errors
    /// When the trajectory or the scene cannot be built.
    pub fn of_world(world: &World) -> Result<Self, String> {
        let mut pts = world.track_enu_m(200_001)?;
        let has_scene = world.file.scene.is_some();
        if let Some(section) = &world.file.scene {
            let cfg = section
                .resolve(&world.frame)
                .map_err(|(k, m)| format!("scene.{k}: {m}"))?
                .config;
            pts.extend(cfg.buildings.iter().flat_map(|b| b.footprint_enu_m.clone()));
            pts.extend(cfg.forests.iter().flat_map(|f| f.polygon_enu_m.clone()));
            pts.extend(
                cfg.indoor_zones
                    .iter()
                    .flat_map(|z| z.polygon_enu_m.clone()),
            );
            pts.extend(cfg.surfaces.iter().flat_map(|s| s.polygon_enu_m.clone()));
        }
        let mut r = Self {
            west_m: f64::INFINITY,
            south_m: f64::INFINITY,
            east_m: f64::NEG_INFINITY,
            north_m: f64::NEG_INFINITY,
        };
        for p in &pts {
            r.west_m = r.west_m.min(p[0]);
            r.east_m = r.east_m.max(p[0]);
            r.south_m = r.south_m.min(p[1]);
            r.north_m = r.north_m.max(p[1]);
        }
        if !has_scene {
            r.west_m -= NO_SCENE_MARGIN_M;
            r.south_m -= NO_SCENE_MARGIN_M;
            r.east_m += NO_SCENE_MARGIN_M;
            r.north_m += NO_SCENE_MARGIN_M;
        }
        // A scene of one point (or a stationary platform) still gets a region one metre
        // across, so that the grid has a cell.
        if r.east_m - r.west_m < 1.0 {
            r.east_m = r.west_m + 1.0;
        }
        if r.north_m - r.south_m < 1.0 {
            r.north_m = r.south_m + 1.0;
        }
        Ok(r)
    }
}

/// A regular grid over a region: `nx` columns eastward, `ny` rows northward, cells of
/// `spacing_m`, numbered row-major from the south-west corner.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Grid {
    pub region: Region,
    pub spacing_m: f64,
    pub nx: usize,
    pub ny: usize,
}

/// What a grid of a given spacing would cost, computed before anything is allocated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridCost {
    pub nx: f64,
    pub ny: f64,
    pub cells: f64,
    pub bytes: f64,
}

impl Grid {
    /// The cost of a grid of `spacing_m` over `region` with `epochs` GNSS epochs and
    /// `candidates` candidate sites (0 without placement), in floating point so that an
    /// absurd spacing cannot overflow the count.
    pub fn cost(region: &Region, spacing_m: f64, epochs: usize, candidates: usize) -> GridCost {
        let nx = ((region.east_m - region.west_m) / spacing_m)
            .ceil()
            .max(1.0);
        let ny = ((region.north_m - region.south_m) / spacing_m)
            .ceil()
            .max(1.0);
        let cells = nx * ny;
        let per_cell = BYTES_PER_CELL as f64
            + if candidates > 0 {
                epochs as f64 * BYTES_PER_CELL_EPOCH as f64
                    + candidates as f64 * BYTES_PER_CELL_CANDIDATE as f64
            } else {
                0.0
            };
        GridCost {
            nx,
            ny,
            cells,
            bytes: cells * per_cell,
        }
    }

    /// The grid of `spacing_m` over `region`, after the memory guard.
    ///
    /// # Errors
    /// A non-positive or non-finite spacing, or a grid over [`MAX_CELLS`] cells or
    /// [`MAX_BYTES`] of estimated memory, with the size, the estimate and a spacing that
    /// would fit.
    pub fn new(
        region: Region,
        spacing_m: f64,
        epochs: usize,
        candidates: usize,
    ) -> Result<Self, String> {
        if !(spacing_m.is_finite() && spacing_m > 0.0) {
            return Err(format!("--grid: expected a spacing > 0 m, got {spacing_m}"));
        }
        let c = Self::cost(&region, spacing_m, epochs, candidates);
        if c.cells > MAX_CELLS as f64 || c.bytes > MAX_BYTES as f64 {
            // The spacing that brings both under their limits: cells scale as 1/spacing².
            let factor = (c.cells / MAX_CELLS as f64)
                .max(c.bytes / MAX_BYTES as f64)
                .sqrt();
            let suggested = (spacing_m * factor * 1.05).max(spacing_m * 1.05);
            return Err(format!(
                "--grid {spacing_m} m is too fine for this region ({:.0} m × {:.0} m): {:.0} × {:.0} = {:.3e} cells, an estimated {:.1} GiB (limits: {} cells, {} GiB); nothing was allocated; use a coarser grid, e.g. --grid {:.3}",
                region.east_m - region.west_m,
                region.north_m - region.south_m,
                c.nx,
                c.ny,
                c.cells,
                c.bytes / f64::from(1u32 << 30),
                MAX_CELLS,
                MAX_BYTES >> 30,
                suggested
            ));
        }
        Ok(Self {
            region,
            spacing_m,
            nx: c.nx as usize,
            ny: c.ny as usize,
        })
    }

    /// The number of cells.
    pub fn cells(&self) -> usize {
        self.nx * self.ny
    }

    /// The centre (east, north) of cell `(i, j)`, column `i` and row `j`.
    pub fn centre(&self, i: usize, j: usize) -> (f64, f64) {
        (
            self.region.west_m + (i as f64 + 0.5) * self.spacing_m,
            self.region.south_m + (j as f64 + 0.5) * self.spacing_m,
        )
    }

    /// The south-west and north-east corners of cell `(i, j)`.
    pub fn corners(&self, i: usize, j: usize) -> ([f64; 2], [f64; 2]) {
        let w = self.region.west_m + i as f64 * self.spacing_m;
        let s = self.region.south_m + j as f64 * self.spacing_m;
        ([w, s], [w + self.spacing_m, s + self.spacing_m])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(side: f64) -> Region {
        Region {
            west_m: 0.0,
            south_m: 0.0,
            east_m: side,
            north_m: side,
        }
    }

    #[test]
    fn grid_covers_the_region() {
        let g = Grid::new(square(95.0), 10.0, 1, 0).unwrap();
        assert_eq!((g.nx, g.ny), (10, 10));
        assert_eq!(g.centre(0, 0), (5.0, 5.0));
        assert_eq!(g.corners(9, 9).1, [100.0, 100.0]);
    }

    #[test]
    fn absurd_grids_are_refused_before_allocating() {
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(Grid::new(square(100.0), bad, 1, 0).is_err(), "{bad}");
        }
        let e = Grid::new(square(10_000.0), 1e-3, 1, 0).unwrap_err();
        assert!(e.contains("too fine") && e.contains("coarser"), "{e}");
        // The suggested spacing is accepted.
        let s: f64 = e.rsplit("--grid ").next().unwrap().trim().parse().unwrap();
        assert!(Grid::new(square(10_000.0), s, 1, 0).is_ok(), "{s}");
    }

    #[test]
    fn region_parses_and_checks() {
        assert_eq!(Region::parse("-10,-20,30,40").unwrap().north_m, 40.0);
        assert!(Region::parse("1,2,3").is_err());
        assert!(Region::parse("5,0,1,1").is_err());
        assert!(Region::parse("a,b,c,d").is_err());
    }
}
