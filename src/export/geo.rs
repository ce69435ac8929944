//! GeoJSON and KML of the scene, transmitters and trajectories.

use super::Recording;
use crate::world::World;
use std::path::{Path, PathBuf};

pub fn write_geojson(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let _ = (world, rec, dir);
    Err("not yet written".into())
}

pub fn write_kml(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let _ = (world, rec, dir);
    Err("not yet written".into())
}
