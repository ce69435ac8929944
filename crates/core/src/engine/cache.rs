//! The per-run epoch cache: what every trial of a run computes identically, computed once.
//!
//! In a world whose platform truth is deterministic (waypoints, static), the geometry of
//! every measurement epoch is the same in every trial of a run: which satellites are in
//! view, their transmit-time positions, what the scene does to each link (class, C/N0,
//! multipath code and rate error), the broadcast ionosphere and troposphere models, and
//! each FM station's mean RSSI at the receiver (its shadowing is keyed by the master seed,
//! not the trial). Only the noise, the receiver clock and the estimators differ between
//! trials. The world's `EpochCache` (`world::cache`) holds that deterministic part for
//! one `(world, master seed)` in [`EpochTable`]s, built once by the first trial that asks
//! and shared by every trial through an `Arc`.
//!
//! # Invariant: a cached epoch is the uncached computation
//!
//! A table is filled by the very functions the sources call without it
//! (`gnss::measurement::GnssGeometry::epoch`, `fm::FmField::mean_rssi_dbm`), at the very truth the engine hands the
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

use crate::core::SimTime;
use crate::measurement::Truth;

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
