//! Running one trial of a world: build its parts from the trial's random streams, then hand
//! them to the engine's event loop.

use super::World;
use crate::core::TrialRng;
use crate::engine::trial::{simulate, TrialResult};

/// Runs trial `trial` of `world` under `seed`.
///
/// The trial depends only on `(world, seed, trial)`: every random draw comes from a
/// stream of [`TrialRng::new(seed, trial)`].
///
/// # Errors
/// When the world cannot build this trial's parts.
pub fn run_trial(world: &World, seed: u64, trial: u64) -> Result<TrialResult, String> {
    let rng = TrialRng::new(seed, trial);
    let mut setup = world.build_trial(&rng)?;
    let estimators = simulate(&world.frame, world.start, &mut setup);
    let warnings = setup.sources.iter().flat_map(|s| s.warnings()).collect();
    Ok(TrialResult {
        trial,
        estimators,
        warnings,
    })
}
