//! The world's per-run epoch cache: the GNSS geometry and FM field along the trajectory,
//! computed once per master seed and shared by every trial (the generic table is
//! [`crate::engine::cache::EpochTable`]).

use super::World;
use crate::core::{SimTime, TrialRng};
use crate::engine::cache::MAX_TABLE_BYTES;
use crate::engine::trial::truth_at;
use crate::fm::source::FmEpochTable;
use crate::gnss::measurement::{GnssEpochTable, GnssGeometry};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// The deterministic epochs of one `(world, master seed)`, for each source that has them.
#[derive(Debug, Default)]
pub struct EpochCache {
    /// The GNSS receiver's links.
    pub gnss: Option<Arc<GnssEpochTable>>,
    /// The FM receiver's mean RSSI of every station.
    pub fm: Option<Arc<FmEpochTable>>,
}

impl EpochCache {
    /// Computes the cache of `world` for `master_seed`, each table bounded by
    /// `max_table_bytes`: the GNSS links and the FM means at every epoch of the trajectory
    /// the trials of this seed drive. Only valid for a world whose truth does not depend
    /// on the trial (the sources check it epoch by epoch anyway, see
    /// [`crate::engine::cache::EpochTable::epoch`]).
    ///
    /// # Errors
    /// When the trajectory or the FM field cannot be built (the first trial would fail
    /// the same way).
    pub fn build(world: &World, master_seed: u64, max_table_bytes: usize) -> Result<Self, String> {
        let trajectory = world.build_trajectory(&TrialRng::new(master_seed, 0))?;
        let end = SimTime::from_seconds(world.duration_s);
        let mut truth_of = |t: SimTime| truth_at(&world.frame, world.start, trajectory.as_ref(), t);
        let sensors = &world.file.sensors;
        let gnss = sensors.gnss.as_ref().map(|g| {
            let mut geometry = GnssGeometry::new(
                g,
                Arc::clone(&world.nav),
                world.shielding.clone(),
                world.gnss_scene_view(),
            );
            Arc::new(geometry.table(end, max_table_bytes, &mut truth_of))
        });
        let fm = match &sensors.fm {
            None => None,
            Some(cfg) => Some(Arc::new(
                FmEpochTable::build(
                    cfg,
                    &crate::world::fm::stations(world),
                    world.scene.clone(),
                    master_seed,
                    end,
                    max_table_bytes,
                    &mut truth_of,
                )
                .map_err(|i| format!("sensors.fm.{}: {}", i.key, i.message))?,
            )),
        };
        Ok(Self { gnss, fm })
    }

    /// Approximate heap bytes held.
    pub fn bytes(&self) -> usize {
        self.gnss.as_ref().map_or(0, |t| t.bytes()) + self.fm.as_ref().map_or(0, |t| t.bytes())
    }
}

/// A world's cache of the last master seed asked for, built on first use. Trials running
/// in parallel wait for the first one's build (one trial's worth of geometry).
#[derive(Debug, Default)]
pub struct CacheSlot {
    disabled: AtomicBool,
    /// The bound of each table; 0 for [`MAX_TABLE_BYTES`].
    max_table_bytes: AtomicUsize,
    slot: Mutex<Option<(u64, Arc<EpochCache>)>>,
}

impl CacheSlot {
    /// Turns the cache on (the default) or off; off, every trial computes every epoch.
    pub fn set_enabled(&self, enabled: bool) {
        self.disabled.store(!enabled, Ordering::SeqCst);
        self.clear();
    }

    /// Sets the bound of each table (bytes; 0 for [`MAX_TABLE_BYTES`]).
    pub fn set_max_table_bytes(&self, bytes: usize) {
        self.max_table_bytes.store(bytes, Ordering::SeqCst);
        self.clear();
    }

    fn clear(&self) {
        *self.slot.lock().unwrap_or_else(|p| p.into_inner()) = None;
    }

    /// The cache for `master_seed`, built by `build` (given the table bound) when the slot
    /// holds another seed's or none; `None` when the cache is off.
    ///
    /// # Errors
    /// What `build` returns.
    pub fn get_or_build(
        &self,
        master_seed: u64,
        build: impl FnOnce(usize) -> Result<EpochCache, String>,
    ) -> Result<Option<Arc<EpochCache>>, String> {
        if self.disabled.load(Ordering::SeqCst) {
            return Ok(None);
        }
        let mut guard = self.slot.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((seed, cache)) = guard.as_ref() {
            if *seed == master_seed {
                return Ok(Some(Arc::clone(cache)));
            }
        }
        let bound = match self.max_table_bytes.load(Ordering::SeqCst) {
            0 => MAX_TABLE_BYTES,
            b => b,
        };
        let cache = Arc::new(build(bound)?);
        *guard = Some((master_seed, Arc::clone(&cache)));
        Ok(Some(cache))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::measurement::{GnssConfig, GnssSource};
    use crate::measurement::{MeasurementBatch, SampleContext, Source, Truth};

    /// The default world (Kehui Road's street, GNSS through its scene).
    fn world() -> World {
        crate::world::load_world(
            &std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
                .join("worlds/default.toml"),
        )
        .unwrap()
    }

    fn source(w: &World, rng: &TrialRng) -> GnssSource {
        let cfg = w.file.sensors.gnss.clone().unwrap();
        let clock = Arc::new(w.receiver_clock(rng));
        GnssSource::new(
            cfg,
            Arc::clone(&w.nav),
            w.shielding.clone(),
            w.gnss_scene_view(),
            clock,
            rng,
            SimTime::from_seconds(w.duration_s),
        )
    }

    /// The run's table holds, at every epoch, the links the geometry computes at that
    /// epoch's truth; a source serves an epoch from the table when the truth matches it
    /// bit for bit, and computes it itself otherwise. The table used here is built with a
    /// 40° mask instead of the receiver's 10°, so which one answered shows in the
    /// elevations of the measurements.
    #[test]
    fn a_source_uses_the_table_exactly_at_the_truths_it_was_built_at() {
        let w = world();
        let traj = w.build_trajectory(&TrialRng::new(1, 0)).unwrap();
        let mut truth_of = |t: SimTime| truth_at(&w.frame, w.start, traj.as_ref(), t);
        let end = SimTime::from_seconds(w.duration_s);
        let cfg = w.file.sensors.gnss.clone().unwrap();
        let mut geometry = GnssGeometry::new(
            &cfg,
            Arc::clone(&w.nav),
            w.shielding.clone(),
            w.gnss_scene_view(),
        );
        let table = geometry.table(end, usize::MAX, &mut truth_of);
        assert_eq!(table.len(), w.duration_s.floor() as usize + 1);
        let mut links = Vec::new();
        for k in [0, 1, 17, table.len() - 1] {
            let truth = truth_of(SimTime(k as i64 * 1_000_000_000));
            links.clear();
            geometry.epoch(&truth, &mut links);
            let (cached, ()) = table.epoch(&truth).unwrap();
            assert!(!links.is_empty());
            assert_eq!(cached, &links[..], "epoch {k}");
        }

        let high = GnssConfig {
            elevation_mask_deg: 40.0,
            ..cfg.clone()
        };
        let mut high_geometry = GnssGeometry::new(
            &high,
            Arc::clone(&w.nav),
            w.shielding.clone(),
            w.gnss_scene_view(),
        );
        let high_table = Arc::new(high_geometry.table(end, usize::MAX, &mut truth_of));
        let rng = TrialRng::new(1, 0);
        let mut src = source(&w, &rng).with_table(Some(high_table));
        let lowest = |src: &mut GnssSource, truth: &Truth| {
            let mut batch = MeasurementBatch::default();
            src.sample(
                &SampleContext {
                    truth,
                    estimates: &[],
                },
                &mut batch,
            );
            batch
                .ranges()
                .map(|r| r.elevation_rad.to_degrees())
                .fold(90.0, f64::min)
        };
        let truth = truth_of(SimTime(0));
        assert!(lowest(&mut src, &truth) >= 40.0, "served from the table");
        let mut moved = truth_of(SimTime(1_000_000_000));
        moved.pos_ecef_m.x += 1e-9;
        assert!(
            lowest(&mut src, &moved) < 40.0,
            "computed at a truth the table lacks"
        );
    }
}
