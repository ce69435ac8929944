//! Trajectory errors: the absolute trajectory error (ATE) and the relative pose error
//! (RPE) of the TUM RGB-D benchmark (Sturm, Engelhard, Endres, Burgard & Cremers, "A
//! Benchmark for the Evaluation of RGB-D SLAM Systems", IROS 2012, §VI), restricted to
//! positions, and the TUM trajectory file format.
//!
//! The estimators of this project estimate positions only, so every pose is taken with the
//! identity rotation. The TUM definitions then reduce to:
//!
//! * ATE at epoch i: `F_i = Q_i⁻¹ S P_i`, whose translation is `e_i = R p_i + t − q_i`,
//!   where `q_i` is the true and `p_i` the estimated position and `S = (R, t)` is either
//!   the identity ([`Alignment::None`]) or the rigid transformation that minimises
//!   `Σ‖R p_i + t − q_i‖²` ([`Alignment::Rigid`], Horn 1987; Umeyama 1991, without scale).
//! * RPE over an interval Δ: `E_i = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)` for the epoch `j` with
//!   `t_j = t_i + Δ`, whose translation is `e_i = R (p_j − p_i) − (q_j − q_i)`.
//!
//! Both are summarised by the norms `‖e_i‖` ([`TrajectoryStats`]). All statistics are
//! those of the benchmark's scripts and of `evo`: the standard deviation is the population
//! one (divisor n), unlike [`super::ErrorStats`], which keeps seed 000's sample one.
//!
//! Positions are ECEF metres (about 6.4e6 m), so the alignment works on coordinates
//! centred on their centroids, and residuals are formed from the centred coordinates: a
//! rotation applied to raw ECEF coordinates would lose about 1e-9 m to rounding for no
//! benefit.

use std::fmt::Write as _;
use std::io;
use std::path::Path;

use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::Serialize;

/// Absolute tolerance (seconds) within which `t_j − t_i` must equal the RPE interval Δ.
pub const RPE_TIME_TOLERANCE_S: f64 = 1e-6;

/// How the estimate is aligned to the truth before the errors are taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Alignment {
    /// The errors are taken in the common frame as they are (seed 000's choice: both
    /// trajectories are ECEF, so any offset or rotation is a real error).
    #[default]
    None,
    /// The estimate is first moved by the least-squares rotation and translation (no
    /// scale) onto the truth, as `evo_ape --align` does; see [`rigid_alignment`].
    Rigid,
}

/// Summary of trajectory errors (metres), with the statistics of the TUM benchmark and
/// `evo`. `std` is the population standard deviation, `median` the middle order statistic
/// (the mean of the two middle ones for an even count).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Default)]
pub struct TrajectoryStats {
    pub mean: f64,
    pub rmse: f64,
    pub median: f64,
    pub std: f64,
    pub max: f64,
    /// Number of errors (epochs for ATE, pairs for RPE).
    pub count: usize,
}

impl TrajectoryStats {
    /// Statistics of `errors` (sorted in place). `None` when empty or when an error is
    /// not finite, because a diverged estimate must be reported, not averaged.
    pub fn from_errors(errors: &mut [f64]) -> Option<Self> {
        if errors.iter().any(|e| !e.is_finite()) {
            return None;
        }
        errors.sort_by(f64::total_cmp);
        let mut sorted: &[f64] = errors;
        Self::from_sorted(&mut sorted).ok().flatten()
    }

    /// Statistics of finite values already in ascending order (`None` when there are
    /// none), summed in that order as [`TrajectoryStats::from_errors`] does.
    ///
    /// # Errors
    /// When values kept on disk cannot be read back.
    pub fn from_sorted(v: &mut dyn super::SortedValues) -> std::io::Result<Option<Self>> {
        let n = v.count();
        if n == 0 {
            return Ok(None);
        }
        let (lo, hi, w) = super::quantile_ranks(n, 0.5);
        let m = super::sorted_moments(v, &[lo, hi, n - 1])?;
        let nf = n as f64;
        Ok(Some(Self {
            mean: m.mean,
            rmse: (m.sq / nf).sqrt(),
            median: m.at[0] + w * (m.at[1] - m.at[0]),
            std: (m.sq_dev / nf).sqrt(),
            max: m.at[2],
            count: n,
        }))
    }
}

/// Centroid of `v`, computed as the first point plus the mean offset from it, so that
/// ECEF-sized coordinates do not lose their millimetres in one large running sum.
fn centroid(v: &[Vector3<f64>]) -> Vector3<f64> {
    let origin = v[0];
    let sum = v.iter().fold(Vector3::zeros(), |acc, p| acc + (p - origin));
    origin + sum / v.len() as f64
}

/// The least-squares rotation together with the two centroids it was computed about.
struct RigidFit {
    rotation: Matrix3<f64>,
    truth_centroid: Vector3<f64>,
    est_centroid: Vector3<f64>,
}

impl RigidFit {
    /// Horn's closed form via the SVD of the cross-covariance (Umeyama 1991, Lemma): with
    /// `Σ = (1/n) Σ_i (q_i − q̄)(p_i − p̄)ᵀ = U D Vᵀ`, the rotation is `R = U S Vᵀ` with
    /// `S = diag(1, 1, det(U)·det(V))`, the sign that rules out a reflection.
    fn new(truth: &[Vector3<f64>], est: &[Vector3<f64>]) -> Option<Self> {
        if !valid_pair(truth, est) {
            return None;
        }
        let truth_centroid = centroid(truth);
        let est_centroid = centroid(est);
        let mut cov = Matrix3::zeros();
        for (q, p) in truth.iter().zip(est) {
            cov += (q - truth_centroid) * (p - est_centroid).transpose();
        }
        cov /= truth.len() as f64;
        let svd = cov.svd(true, true);
        let (u, v_t) = (svd.u?, svd.v_t?);
        let mut s = Matrix3::identity();
        if u.determinant() * v_t.determinant() < 0.0 {
            s[(2, 2)] = -1.0;
        }
        Some(Self {
            rotation: u * s * v_t,
            truth_centroid,
            est_centroid,
        })
    }

    /// The translation `t = q̄ − R p̄`.
    fn translation(&self) -> Vector3<f64> {
        self.truth_centroid - self.rotation * self.est_centroid
    }
}

/// True when both slices are non-empty, of equal length and entirely finite.
fn valid_pair(truth: &[Vector3<f64>], est: &[Vector3<f64>]) -> bool {
    !truth.is_empty()
        && truth.len() == est.len()
        && truth
            .iter()
            .chain(est)
            .all(|p| p.iter().all(|c| c.is_finite()))
}

/// The rigid transformation `(R, t)` minimising `Σ_i ‖R est_i + t − truth_i‖²` (Horn,
/// "Closed-form solution of absolute orientation using unit quaternions", JOSA A 1987;
/// Umeyama, "Least-squares estimation of transformation parameters between two point
/// patterns", IEEE TPAMI 1991, without the scale). Epochs are paired by index.
///
/// `None` when the slices are empty, of different lengths or not finite. When the points
/// are collinear (or fewer than three) the rotation about their line is not determined by
/// the data; a valid least-squares rotation is still returned.
pub fn rigid_alignment(
    truth: &[Vector3<f64>],
    est: &[Vector3<f64>],
) -> Option<(Rotation3<f64>, Vector3<f64>)> {
    let fit = RigidFit::new(truth, est)?;
    Some((
        Rotation3::from_matrix_unchecked(fit.rotation),
        fit.translation(),
    ))
}

/// The per-epoch ATE norms `‖R p_i + t − q_i‖` (see the module documentation), paired by
/// index. `None` when the slices are empty, of different lengths or not finite.
pub fn ate_errors(
    truth: &[Vector3<f64>],
    est: &[Vector3<f64>],
    align: Alignment,
) -> Option<Vec<f64>> {
    if !valid_pair(truth, est) {
        return None;
    }
    Some(match align {
        Alignment::None => truth.iter().zip(est).map(|(q, p)| (p - q).norm()).collect(),
        Alignment::Rigid => {
            // R p + t − q = R (p − p̄) − (q − q̄), formed from centred coordinates.
            let fit = RigidFit::new(truth, est)?;
            truth
                .iter()
                .zip(est)
                .map(|(q, p)| {
                    (fit.rotation * (p - fit.est_centroid) - (q - fit.truth_centroid)).norm()
                })
                .collect()
        }
    })
}

/// Absolute trajectory error (TUM benchmark): statistics of `‖R p_i + t − q_i‖` over the
/// epochs, `(R, t)` the identity or the rigid alignment. `truth[i]` and `est[i]` must be
/// the same epoch. `None` when empty, of different lengths or not finite.
pub fn ate(
    truth: &[Vector3<f64>],
    est: &[Vector3<f64>],
    align: Alignment,
) -> Option<TrajectoryStats> {
    TrajectoryStats::from_errors(&mut ate_errors(truth, est, align)?)
}

/// The per-pair RPE norms `‖R (p_j − p_i) − (q_j − q_i)‖` for every pair of epochs with
/// `t_j − t_i = Δ` (within [`RPE_TIME_TOLERANCE_S`]), in the order of `i`.
///
/// Pairs are found by time, as the benchmark's `evaluate_rpe.py` does, not by index:
/// epochs without an estimate are simply absent from the input, and a pair never spans
/// such a gap with the wrong interval. (`evo_rpe` with `--delta 1 --delta_unit f` pairs
/// consecutive *lines* of the file and therefore also pairs the two epochs either side of
/// a gap; the integration test `tests/it/metrics.rs` shows both.)
///
/// With [`Alignment::Rigid`] the estimate is first aligned to the truth over all epochs
/// ([`rigid_alignment`]), which rotates its displacements by `R` (the translation
/// cancels). This is what `evo_rpe --align` computes for full poses whose orientations
/// were estimated in the same frame as the positions; with position-only trajectories
/// stored with identity orientations, `evo` moves the orientations too and its relative
/// poses are unchanged by the alignment, so there `--align` has no effect.
///
/// `None` when the inputs are empty, of different lengths, not finite, when `t_s` is not
/// strictly increasing or when `delta_s` is not positive.
pub fn rpe_errors(
    t_s: &[f64],
    truth: &[Vector3<f64>],
    est: &[Vector3<f64>],
    delta_s: f64,
    align: Alignment,
) -> Option<Vec<f64>> {
    if !valid_pair(truth, est)
        || t_s.len() != truth.len()
        || !(delta_s.is_finite() && delta_s > 0.0)
        || t_s.iter().any(|t| !t.is_finite())
        || t_s.windows(2).any(|w| w[1] <= w[0])
    {
        return None;
    }
    let rotation = match align {
        Alignment::None => Matrix3::identity(),
        Alignment::Rigid => RigidFit::new(truth, est)?.rotation,
    };
    let mut errors = Vec::new();
    // Two pointers: the partner index only moves forward because the times increase.
    let mut j = 0;
    for i in 0..t_s.len() {
        let target = t_s[i] + delta_s;
        while j < t_s.len() && t_s[j] < target - RPE_TIME_TOLERANCE_S {
            j += 1;
        }
        if j == t_s.len() {
            break;
        }
        if (t_s[j] - target).abs() <= RPE_TIME_TOLERANCE_S {
            let e = rotation * (est[j] - est[i]) - (truth[j] - truth[i]);
            errors.push(e.norm());
        }
    }
    Some(errors)
}

/// Relative pose error (TUM benchmark) over the interval `delta_s`: statistics of
/// [`rpe_errors`]. `None` when the inputs are invalid or no pair of epochs is `delta_s`
/// apart.
pub fn rpe(
    t_s: &[f64],
    truth: &[Vector3<f64>],
    est: &[Vector3<f64>],
    delta_s: f64,
    align: Alignment,
) -> Option<TrajectoryStats> {
    TrajectoryStats::from_errors(&mut rpe_errors(t_s, truth, est, delta_s, align)?)
}

/// Writes a trajectory in the TUM format, one line `timestamp tx ty tz qx qy qz qw` per
/// epoch with the identity quaternion `0 0 0 1` (positions only). Numbers are written in
/// Rust's shortest representation that reads back to the same `f64`, so nothing is lost
/// to rounding. The file is written atomically ([`crate::io::atomic::write_atomic`]).
///
/// # Errors
/// `InvalidInput` when the lengths differ or a value is not finite (the format has no
/// spelling for them that `evo` or the benchmark tools accept); any I/O error otherwise.
pub fn write_tum(path: &Path, t_s: &[f64], pos: &[Vector3<f64>]) -> io::Result<()> {
    if t_s.len() != pos.len() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "{}: {} timestamps for {} positions",
                path.display(),
                t_s.len(),
                pos.len()
            ),
        ));
    }
    let mut text = String::with_capacity(t_s.len() * 80);
    text.push_str("# timestamp tx ty tz qx qy qz qw\n");
    for (t, p) in t_s.iter().zip(pos) {
        if !(t.is_finite() && p.iter().all(|c| c.is_finite())) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("{}: non-finite value at t = {t}", path.display()),
            ));
        }
        // Writing to a String cannot fail.
        let _ = writeln!(text, "{t} {} {} {} 0 0 0 1", p.x, p.y, p.z);
    }
    crate::io::atomic::write_atomic(path, text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;
    use rand::Rng;
    use rand_distr::StandardNormal;

    /// A curved, non-planar 1 Hz trajectory near Beijing in ECEF, n epochs.
    fn ecef_track(n: usize) -> (Vec<f64>, Vec<Vector3<f64>>) {
        let origin = Vector3::new(-2_178_000.0, 4_388_000.0, 4_069_000.0);
        let t: Vec<f64> = (0..n).map(|i| 1000.0 + i as f64).collect();
        let p = t
            .iter()
            .map(|&t| {
                let a = 0.02 * t;
                origin + Vector3::new(300.0 * a.cos(), 200.0 * (2.0 * a).sin(), 15.0 * a.sin())
            })
            .collect();
        (t, p)
    }

    fn noisy(p: &[Vector3<f64>], sigma: f64, seed: u64) -> Vec<Vector3<f64>> {
        let mut rng = TrialRng::new(seed, 0).stream("test/metrics/noise");
        p.iter()
            .map(|q| {
                q + sigma
                    * Vector3::new(
                        rng.sample::<f64, _>(StandardNormal),
                        rng.sample::<f64, _>(StandardNormal),
                        rng.sample::<f64, _>(StandardNormal),
                    )
            })
            .collect()
    }

    #[test]
    fn constant_offset_is_the_ate_without_alignment_and_vanishes_with_it() {
        let (t, truth) = ecef_track(200);
        let d = Vector3::new(3.0, -4.0, 12.0); // ‖d‖ = 13
        let est: Vec<_> = truth.iter().map(|q| q + d).collect();
        let s = ate(&truth, &est, Alignment::None).unwrap();
        assert!((s.mean - 13.0).abs() < 1e-8 && (s.rmse - 13.0).abs() < 1e-8);
        assert!((s.median - 13.0).abs() < 1e-8 && (s.max - 13.0).abs() < 1e-8);
        assert!(s.std < 1e-8 && s.count == 200);
        let s = ate(&truth, &est, Alignment::Rigid).unwrap();
        assert!(s.max < 1e-8, "{s:?}");
        // A constant offset does not change any displacement.
        let r = rpe(&t, &truth, &est, 1.0, Alignment::None).unwrap();
        assert!(r.max < 1e-8 && r.count == 199, "{r:?}");
    }

    #[test]
    fn rigid_alignment_recovers_a_rotation_about_the_earth_centre() {
        let (t, truth) = ecef_track(300);
        // The estimate is the truth seen from a frame rotated by 1 mrad (about 6 km at the
        // surface) and shifted, so truth = R_true est + t_true.
        let r_true = Rotation3::from_scaled_axis(Vector3::new(0.3, -0.5, 0.8).normalize() * 1e-3);
        let t_true = Vector3::new(120.0, -40.0, 75.0);
        let est: Vec<_> = truth
            .iter()
            .map(|q| r_true.inverse() * (q - t_true))
            .collect();
        let (r, tr) = rigid_alignment(&truth, &est).unwrap();
        let dr = (r.matrix() - r_true.matrix()).abs().max();
        assert!(dr < 1e-9, "rotation off by {dr:e}");
        assert!((tr - t_true).norm() < 1e-6, "{tr:?}");
        assert!(ate(&truth, &est, Alignment::None).unwrap().mean > 1000.0);
        let s = ate(&truth, &est, Alignment::Rigid).unwrap();
        assert!(s.max < 1e-6, "{s:?}");
        // RPE: the rotation shows without alignment and is removed with it.
        assert!(rpe(&t, &truth, &est, 1.0, Alignment::None).unwrap().mean > 1e-3);
        assert!(rpe(&t, &truth, &est, 1.0, Alignment::Rigid).unwrap().max < 1e-8);
    }

    #[test]
    fn alignment_never_increases_the_ate_and_is_not_a_reflection() {
        let (_, truth) = ecef_track(250);
        let est = noisy(&truth, 2.0, 5);
        let plain = ate(&truth, &est, Alignment::None).unwrap();
        let rigid = ate(&truth, &est, Alignment::Rigid).unwrap();
        assert!(rigid.rmse <= plain.rmse + 1e-12);
        let (r, _) = rigid_alignment(&truth, &est).unwrap();
        assert!((r.matrix().determinant() - 1.0).abs() < 1e-12);
        // A mirrored estimate would fit better with a reflection, which is ruled out.
        let mirrored: Vec<_> = truth.iter().map(|q| Vector3::new(q.x, q.y, -q.z)).collect();
        let (r, _) = rigid_alignment(&truth, &mirrored).unwrap();
        assert!((r.matrix().determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn statistics_follow_numpy() {
        // numpy: mean 2.5, rmse √7.5, median 2.5, std (ddof 0) √1.25, max 4.
        let mut e = [4.0, 1.0, 3.0, 2.0];
        let s = TrajectoryStats::from_errors(&mut e).unwrap();
        assert_eq!((s.mean, s.median, s.max, s.count), (2.5, 2.5, 4.0, 4));
        assert!((s.rmse - 7.5f64.sqrt()).abs() < 1e-15);
        assert!((s.std - 1.25f64.sqrt()).abs() < 1e-15);
    }

    #[test]
    fn rpe_pairs_by_time_across_a_gap() {
        // Epochs 0, 1, 2, 5, 6: only (0,1), (1,2), (5,6) are 1 s apart; a pair (2,5) by
        // index would mix a 3 s displacement into the 1 s statistics.
        let t = [0.0, 1.0, 2.0, 5.0, 6.0];
        let truth: Vec<_> = t.iter().map(|&t| Vector3::new(t, 0.0, 0.0)).collect();
        let mut est = truth.clone();
        // Displacement errors: 1 → 2 gets +0.5 m in y, 5 → 6 gets −0.2 m in z.
        est[2].y += 0.5;
        est[4].z -= 0.2;
        let e = rpe_errors(&t, &truth, &est, 1.0, Alignment::None).unwrap();
        assert_eq!(e.len(), 3);
        assert!((e[0]).abs() < 1e-15 && (e[1] - 0.5).abs() < 1e-15);
        assert!((e[2] - 0.2).abs() < 1e-15);
        // Δ = 3 s finds (2, 5) and Δ = 4 s finds (1, 5) and (2, 6).
        let e3 = rpe_errors(&t, &truth, &est, 3.0, Alignment::None).unwrap();
        assert_eq!(e3.len(), 1);
        assert!((e3[0] - 0.5).abs() < 1e-15);
        assert_eq!(
            rpe_errors(&t, &truth, &est, 4.0, Alignment::None)
                .unwrap()
                .len(),
            2
        );
        // No pair at all is `None`, not zero statistics.
        assert!(rpe(&t, &truth, &est, 10.0, Alignment::None).is_none());
        // Times within the tolerance pair up; beyond it they do not.
        let t2 = [0.0, 1.0 + 5e-7, 2.0 + 5e-6];
        let p2 = &truth[..3];
        assert_eq!(
            rpe_errors(&t2, p2, p2, 1.0, Alignment::None).unwrap().len(),
            1
        );
    }

    #[test]
    fn bad_input_is_refused() {
        let (t, truth) = ecef_track(10);
        assert!(ate(&[], &[], Alignment::None).is_none());
        assert!(ate(&truth, &truth[..9], Alignment::Rigid).is_none());
        let mut bad = truth.clone();
        bad[3].x = f64::NAN;
        assert!(ate(&truth, &bad, Alignment::None).is_none());
        assert!(rigid_alignment(&truth, &bad).is_none());
        assert!(rpe(&t, &truth, &bad, 1.0, Alignment::None).is_none());
        assert!(rpe(&t[..9], &truth, &truth, 1.0, Alignment::None).is_none());
        assert!(rpe(&t, &truth, &truth, 0.0, Alignment::None).is_none());
        let mut back = t.clone();
        back.swap(2, 3);
        assert!(rpe(&back, &truth, &truth, 1.0, Alignment::None).is_none());
    }

    #[test]
    fn tum_file_reads_back_exactly() {
        let (t, truth) = ecef_track(5);
        let est = noisy(&truth, 1.0, 9);
        let t: Vec<f64> = t.iter().map(|t| t + 0.123_456_789_012).collect();
        let dir = std::env::temp_dir().join(format!("hybridnav-tum-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("est.txt");
        write_tum(&path, &t, &est).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let rows: Vec<Vec<f64>> = text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| l.split(' ').map(|x| x.parse().unwrap()).collect())
            .collect();
        assert_eq!(rows.len(), 5);
        for (i, r) in rows.iter().enumerate() {
            assert_eq!(r.len(), 8);
            assert_eq!(r[0], t[i]);
            assert_eq!(&r[1..4], est[i].as_slice());
            assert_eq!(&r[4..], &[0.0, 0.0, 0.0, 1.0]);
        }
        assert!(write_tum(&path, &t[..4], &est).is_err());
        let mut bad = est.clone();
        bad[1].y = f64::INFINITY;
        assert!(write_tum(&path, &t, &bad).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
