//! The FM fingerprint database of a world: loaded from the file `[sensors.fm] database`
//! names, or surveyed and kriged by the world itself (`[sensors.fm.survey]`), once per
//! master seed, and shared by every trial.
//!
//! The survey uses the same field as the trials (the world's FM stations completed with
//! the same synthetic ones, the same shadowing keyed by the master seed), measured as a
//! surveyor would with their own noise (stream `fm/survey` of trial 0's streams, which no
//! trial source uses), so the database describes the city the receiver drives through, as
//! a real survey does. The survey was done at another time, with another receiver: with
//! `time_variation_sigma_db` > 0 the surveyor also sees an independent change of the field
//! per station (drawn from the same `fm/survey` stream), which no test trial sees.

use crate::core::TrialRng;
use crate::fm::database::build_kriged;
use crate::fm::kriging::{ChannelKriging, FitOptions};
use crate::fm::{grid_points_en, FingerprintDb, FmField, FmSensorConfig, FmStation, WorldTag};
use crate::world::scene::TransmitterKind;
use crate::world::World;
use std::sync::{Arc, Mutex};

/// Where a world's FM database comes from.
#[derive(Debug, Default)]
pub enum FmDatabase {
    /// The world has no `[sensors.fm]`.
    #[default]
    None,
    /// Loaded from a file at world load.
    Loaded(Arc<FingerprintDb>),
    /// Surveyed on first use, kept for the last master seed asked for.
    Surveyed(Mutex<Option<(u64, Arc<FingerprintDb>)>>),
}

/// The world's declared FM stations.
pub fn stations(world: &World) -> Vec<FmStation> {
    world
        .transmitters
        .iter()
        .filter(|t| t.kind == TransmitterKind::Fm)
        .map(|t| FmStation::new(&t.id, t.pos_enu_m, t.freq_hz, t.erp_dbw, 0.0))
        .collect()
}

/// The identity a database file must carry to be used with the world named `name` at
/// `frame`'s origin.
pub fn tag(name: &str, frame: &crate::core::EnuFrame) -> WorldTag {
    WorldTag::new(name, frame, None)
}

/// Surveys and kriges the world's FM field for `master_seed`; returns the database and
/// the kriging report of each channel.
///
/// # Errors
/// When the configuration, the trajectory or the kriging fails.
pub fn survey(
    world: &World,
    cfg: &FmSensorConfig,
    master_seed: u64,
) -> Result<(FingerprintDb, Vec<ChannelKriging>), String> {
    let rng = TrialRng::new(master_seed, 0);
    let (lo, hi) = match cfg.survey.area_enu_m {
        Some([lo, hi]) => (lo, hi),
        None => {
            let trajectory = world.build_trajectory(&rng)?;
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            let mut t = 0.0;
            while t <= world.duration_s {
                let p = trajectory.state_at(t).pos_enu_m;
                for a in 0..2 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
                t += 0.5;
            }
            let m = cfg.survey.margin_m;
            ([lo[0] - m, lo[1] - m], [hi[0] + m, hi[1] + m])
        }
    };
    let err = |e: crate::fm::FmError| format!("sensors.fm.survey: {e}");
    let rps = grid_points_en(lo, hi, cfg.survey.rp_spacing_en_m()).map_err(err)?;
    let grid = grid_points_en(lo, hi, cfg.survey.grid_spacing_en_m()).map_err(err)?;
    let stations = crate::fm::field::synthesize_stations(
        &stations(world),
        cfg.synthetic_stations_total,
        master_seed,
    );
    let mut field = FmField::new(
        cfg.field.clone(),
        stations,
        world.scene.clone(),
        master_seed,
    )
    .map_err(|i| format!("sensors.fm.field.{}: {}", i.key, i.message))?;
    build_kriged(
        tag(&world.file.world.name, &world.frame),
        &world.frame,
        &mut field,
        &rps,
        cfg.field.rx_antenna_height_m,
        &cfg.survey.scan(),
        &grid,
        &FitOptions::default(),
        &mut rng.stream("fm/survey"),
    )
    .map_err(err)
}

impl World {
    /// The FM database for trials of `master_seed` (`None` without `[sensors.fm]`).
    ///
    /// # Errors
    /// When the survey fails.
    pub fn fm_database(&self, master_seed: u64) -> Result<Option<Arc<FingerprintDb>>, String> {
        match &self.fm_db {
            FmDatabase::None => Ok(None),
            FmDatabase::Loaded(db) => Ok(Some(Arc::clone(db))),
            FmDatabase::Surveyed(cache) => {
                // Trials running in parallel wait here for the first one's survey.
                let mut guard = cache.lock().unwrap_or_else(|p| p.into_inner());
                if let Some((seed, db)) = guard.as_ref() {
                    if *seed == master_seed {
                        return Ok(Some(Arc::clone(db)));
                    }
                }
                let cfg = self
                    .file
                    .sensors
                    .fm
                    .as_ref()
                    .ok_or("the world has no [sensors.fm]")?;
                let db = Arc::new(survey(self, cfg, master_seed)?.0);
                *guard = Some((master_seed, Arc::clone(&db)));
                Ok(Some(db))
            }
        }
    }
}
