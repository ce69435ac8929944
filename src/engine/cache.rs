//! The per-run epoch cache: what every trial of a run computes identically, computed once.
//!
//! In a world whose platform truth is deterministic (waypoints, static), the geometry of
//! every measurement epoch is the same in every trial of a run: which satellites are in
//! view, their transmit-time positions, what the scene does to each link (class, C/N0,
//! multipath code and rate error), the broadcast ionosphere and troposphere models, and
//! each FM station's mean RSSI at the receiver (its shadowing is keyed by the master seed,
//! not the trial). Only the noise, the receiver clock and the estimators differ between
//! trials. An [`EpochCache`] holds that deterministic part for one `(world, master seed)`,
//! built once by the first trial that asks ([`crate::world::World::epoch_cache`]) and
//! shared by every trial through an `Arc`.
//!
//! # Invariant: a cached epoch is the uncached computation
//!
//! A table is filled by the very functions the sources call without it
//! ([`crate::gnss::measurement::GnssGeometry::epoch`],
//! [`crate::fm::FmField::mean_rssi_dbm`]), at the very truth the engine hands the
//! source (the same [`super::trial::truth_at`] at the same integer [`SimTime`]), and a
//! source uses a cached epoch only when the truth it is given equals, bit for bit, the
//! truth the epoch was computed at ([`EpochTable::epoch`]); otherwise it computes the
//! epoch itself. The random draws are taken by the trial, in the same order as without
//! the cache, so every output is byte-identical with the cache on or off (tested in
//! `tests/it/reliability.rs`).
//!
//! # Memory
//!
//! Each table stops at [`MAX_TABLE_BYTES`]; the epochs after the last one it holds are
//! computed on the fly by each trial, as without a cache. The Kehui Road world (361
//! epochs of about 20 satellite links and 21 FM stations) needs about 1 MB.

use super::trial::truth_at;
use crate::core::{SimTime, TrialRng};
use crate::fm::source::FmEpochTable;
use crate::gnss::measurement::{GnssEpochTable, GnssGeometry};
use crate::measurement::Truth;
use crate::world::World;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// The most bytes one table holds (the GNSS links of about 3 h at 1 Hz; the FM means of
/// about 30 h). Later epochs are computed by each trial.
pub const MAX_TABLE_BYTES: usize = 32 << 20;

/// Whether two truths are the same bit for bit (so a function of one is a function of the
/// other: `-0.0` and `0.0`, or two NaNs, are told apart or matched exactly as their bits).
pub fn same_truth(a: &Truth, b: &Truth) -> bool {
    let v = |x: &nalgebra::Vector3<f64>, y: &nalgebra::Vector3<f64>| {
        x.iter()
            .zip(y.iter())
            .all(|(p, q)| p.to_bits() == q.to_bits())
    };
    a.sim == b.sim
        && a.t == b.t
        && v(&a.pos_ecef_m, &b.pos_ecef_m)
        && v(&a.vel_ecef_mps, &b.vel_ecef_mps)
        && a.enu.t_s.to_bits() == b.enu.t_s.to_bits()
        && v(&a.enu.pos_enu_m, &b.enu.pos_enu_m)
        && v(&a.enu.vel_enu_mps, &b.enu.vel_enu_mps)
        && v(&a.enu.acc_enu_mps2, &b.enu.acc_enu_mps2)
        && a.enu.heading_rad.to_bits() == b.enu.heading_rad.to_bits()
}

/// The deterministic part of a source's epochs `k·step` (k = 0, 1, …), each epoch a slice
/// of items `T` and one value `E` (a source's state after that epoch, e.g. the warnings
/// it had logged by then).
#[derive(Debug)]
pub struct EpochTable<T, E = ()> {
    step_ns: i64,
    truths: Vec<Truth>,
    extra: Vec<E>,
    /// Epoch k's items are `items[offsets[k]..offsets[k + 1]]`.
    offsets: Vec<u32>,
    items: Vec<T>,
    /// Whether the table stopped at its byte bound before the source's last epoch.
    truncated: bool,
}

impl<T, E> EpochTable<T, E> {
    /// Fills the table for a source sampled at `0, step_ns, 2·step_ns, …` up to and
    /// including `end` (the schedule of the GNSS, FM and DTMB receivers): `truth_of` gives
    /// the engine's truth at an epoch, `epoch` computes that epoch's items (appended to
    /// the vector it is given) and its value. Stops before the epoch that would take the
    /// table beyond `max_bytes`.
    pub fn build(
        step_ns: i64,
        end: SimTime,
        max_bytes: usize,
        truth_of: &mut dyn FnMut(SimTime) -> Truth,
        mut epoch: impl FnMut(&Truth, &mut Vec<T>) -> E,
    ) -> Self {
        let step_ns = step_ns.max(1);
        let mut table = Self {
            step_ns,
            truths: Vec::new(),
            extra: Vec::new(),
            offsets: vec![0],
            items: Vec::new(),
            truncated: false,
        };
        let per_epoch =
            std::mem::size_of::<Truth>() + std::mem::size_of::<E>() + std::mem::size_of::<u32>();
        let mut t = SimTime(0);
        while t <= end {
            let before = table.items.len();
            let truth = truth_of(t);
            let e = epoch(&truth, &mut table.items);
            let bytes = table.truths.len().saturating_add(1) * per_epoch
                + table.items.len() * std::mem::size_of::<T>();
            if bytes > max_bytes || table.items.len() > u32::MAX as usize {
                table.items.truncate(before);
                table.truncated = true;
                break;
            }
            table.truths.push(truth);
            table.extra.push(e);
            table.offsets.push(table.items.len() as u32);
            t = SimTime(t.0 + step_ns);
        }
        table.items.shrink_to_fit();
        table
    }

    /// The cached epoch at `truth`: its items and value, when the table holds the epoch
    /// `truth.sim` and computed it at this very truth; `None` otherwise (the caller then
    /// computes the epoch itself).
    pub fn epoch(&self, truth: &Truth) -> Option<(&[T], &E)> {
        let k = self.index(truth.sim)?;
        if !same_truth(&self.truths[k], truth) {
            return None;
        }
        let (a, b) = (self.offsets[k] as usize, self.offsets[k + 1] as usize);
        Some((&self.items[a..b], &self.extra[k]))
    }

    /// The index of the epoch at `t`, when the table holds it.
    pub fn index(&self, t: SimTime) -> Option<usize> {
        if t.0 < 0 || t.0 % self.step_ns != 0 {
            return None;
        }
        let k = usize::try_from(t.0 / self.step_ns).ok()?;
        (k < self.truths.len()).then_some(k)
    }

    /// The value of epoch `k` (which the table holds).
    pub fn extra(&self, k: usize) -> &E {
        &self.extra[k]
    }

    /// Epochs held.
    pub fn len(&self) -> usize {
        self.truths.len()
    }

    /// Whether the table holds no epoch.
    pub fn is_empty(&self) -> bool {
        self.truths.is_empty()
    }

    /// Whether the byte bound stopped the table before the source's last epoch.
    pub fn truncated(&self) -> bool {
        self.truncated
    }

    /// Approximate heap bytes held.
    pub fn bytes(&self) -> usize {
        self.truths.len() * std::mem::size_of::<Truth>()
            + self.extra.len() * std::mem::size_of::<E>()
            + self.offsets.len() * std::mem::size_of::<u32>()
            + self.items.len() * std::mem::size_of::<T>()
    }
}

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
    /// [`EpochTable::epoch`]).
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
    use crate::core::{EnuFrame, Geodetic, GpsTime};
    use crate::motion::TruthState;
    use nalgebra::Vector3;

    fn truth(sim: SimTime) -> Truth {
        let frame = EnuFrame::new(Geodetic::from_deg(40.0, 116.0, 50.0));
        let e = sim.seconds();
        let pos = Vector3::new(3.0 * e, -e, 1.5);
        Truth {
            sim,
            t: sim.to_gps(GpsTime::from_week_tow(2000, 0.0)),
            enu: TruthState {
                t_s: e,
                pos_enu_m: pos,
                vel_enu_mps: Vector3::new(3.0, -1.0, 0.0),
                acc_enu_mps2: Vector3::zeros(),
                heading_rad: 1.0,
            },
            pos_ecef_m: frame.ecef_of_enu(&pos),
            vel_ecef_mps: frame.ecef_vector_of_enu(&Vector3::new(3.0, -1.0, 0.0)),
        }
    }

    /// The table holds epochs 0, 1, …, end at the step, answers only at an epoch time with
    /// the truth it was built at, and stops at its byte bound.
    #[test]
    fn epochs_are_served_only_at_their_time_and_truth() {
        let step = 500_000_000;
        let end = SimTime::from_seconds(10.0);
        let mut calls = 0;
        let t: EpochTable<f64, u32> =
            EpochTable::build(step, end, usize::MAX, &mut truth, |tr, out| {
                calls += 1;
                // A variable number of items per epoch: k + 1 copies of the time.
                let k = (tr.sim.0 / step) as usize;
                out.extend(std::iter::repeat_n(tr.enu.t_s, k + 1));
                k as u32 * 10
            });
        assert_eq!((t.len(), calls, t.truncated()), (21, 21, false));
        let (items, e) = t.epoch(&truth(SimTime(3 * step))).unwrap();
        assert_eq!((items, *e), (&[1.5, 1.5, 1.5, 1.5][..], 30));
        // Not an epoch time, beyond the end, or another truth at the time: no answer.
        assert!(t.epoch(&truth(SimTime(3 * step + 1))).is_none());
        assert!(t.epoch(&truth(SimTime(21 * step))).is_none());
        let mut moved = truth(SimTime(3 * step));
        moved.enu.pos_enu_m.x += 1e-12;
        assert!(t.epoch(&moved).is_none());
        let mut signed = truth(SimTime(0));
        signed.enu.acc_enu_mps2.x = -0.0;
        assert!(t.epoch(&signed).is_none());

        // A bound of about five epochs' bytes keeps the first epochs only.
        let per_epoch = std::mem::size_of::<Truth>() + 4 + 4;
        let small: EpochTable<f64, u32> =
            EpochTable::build(step, end, 5 * per_epoch + 15 * 8, &mut truth, |tr, out| {
                let k = (tr.sim.0 / step) as usize;
                out.extend(std::iter::repeat_n(tr.enu.t_s, k + 1));
                0
            });
        assert_eq!((small.len(), small.truncated()), (5, true));
        assert!(small.epoch(&truth(SimTime(4 * step))).is_some());
        assert!(small.epoch(&truth(SimTime(5 * step))).is_none());
        assert!(small.bytes() <= 5 * per_epoch + 15 * 8 + 4);
    }
}
