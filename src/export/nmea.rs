//! NMEA 0183 sentences of a recorded trial.

use super::Recording;
use crate::world::World;
use std::path::{Path, PathBuf};

/// Writes one NMEA file for the truth and one per estimator.
pub fn write(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let _ = (world, rec, dir);
    Err("not yet written".into())
}
