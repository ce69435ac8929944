//! RINEX 3.04 observation files of a recorded trial.

use super::Recording;
use crate::world::World;
use std::path::{Path, PathBuf};

/// Writes the observation file and the navigation file of the trial.
pub fn write(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let _ = (world, rec, dir);
    Err("not yet written".into())
}
