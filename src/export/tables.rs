//! Measurement tables (CSV, Parquet) and TUM trajectories of a recorded trial.

use super::Recording;
use crate::world::World;
use std::path::{Path, PathBuf};

pub fn write_tum(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let _ = (world, rec, dir);
    Err("not yet written".into())
}

pub fn write_csv(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let _ = (world, rec, dir);
    Err("not yet written".into())
}

pub fn write_parquet(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let _ = (world, rec, dir);
    Err("not yet written".into())
}
