//! Fixes as the inertial estimators take them: the position (and velocity) fixes of a
//! batch in the world's ENU frame — weighted least squares on a GNSS batch's pseudoranges
//! and range rates, or a fix source's positions — with their covariances moved between
//! ECEF and ENU, and the NIS record of updates the divergence watch does not judge.

use crate::core::{EnuFrame, System};
use crate::fusion::wls::{self, WlsOptions};
use crate::measurement::{
    EpochOutcome, Measurement, MeasurementBatch, PositionFix, RangeMeasurement, SourceKind,
};
use nalgebra::{Matrix3, Matrix4, Vector3, Vector4};

/// A velocity from pseudorange rates at a known receiver position, by weighted least
/// squares on the model of seed 000 eq. 16, `ρ̇ᵢ = uᵢ · (v − vᵢ) + ḃ`, with
/// `uᵢ = (r − rᵢ)/‖r − rᵢ‖` and one clock drift ḃ shared by all systems (one oscillator).
/// Rows are `[uᵢᵀ 1]`, observations `ρ̇ᵢ + uᵢ · vᵢ`, weights `1/σᵢ²`.
///
/// Returns (velocity ECEF m/s, its covariance (m/s)², rates used), or `None` with fewer
/// than four usable rates or a singular geometry. Does not allocate.
pub fn velocity_from_rates(
    ranges: &[RangeMeasurement],
    rx_ecef_m: &Vector3<f64>,
) -> Option<(Vector3<f64>, Matrix3<f64>, usize)> {
    let mut n = Matrix4::<f64>::zeros();
    let mut rhs = Vector4::<f64>::zeros();
    let mut used = 0;
    for m in ranges {
        let Some(rate) = m.range_rate_mps else {
            continue;
        };
        let s = m.sigma_rate_mps;
        let los = rx_ecef_m - m.emitter_pos_ecef_m;
        let d = los.norm();
        if !(rate.is_finite() && s.is_finite() && s > 0.0 && d > 1e-3 && d.is_finite()) {
            continue;
        }
        let u = los / d;
        let h = Vector4::new(u.x, u.y, u.z, 1.0);
        let w = 1.0 / (s * s);
        n += h * h.transpose() * w;
        rhs += h * (w * (rate + u.dot(&m.emitter_vel_ecef_mps)));
        used += 1;
    }
    if used < 4 {
        return None;
    }
    let chol = n.cholesky()?;
    let x = chol.solve(&rhs);
    let cov = chol.inverse();
    let v = Vector3::new(x[0], x[1], x[2]);
    let c: Matrix3<f64> = cov.fixed_view::<3, 3>(0, 0).into_owned();
    (v.iter().chain(c.iter()).all(|e| e.is_finite()) && c[(0, 0)] > 0.0).then_some((v, c, used))
}

/// One fix in the world frame.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Fix {
    pub(crate) t_s: f64,
    pub(crate) pos_enu_m: Vector3<f64>,
    pub(crate) pos_cov_m2: Matrix3<f64>,
    pub(crate) vel: Option<(Vector3<f64>, Matrix3<f64>)>,
    /// Measurements behind the fix.
    pub(crate) n: u32,
}

/// ENU covariance of an ECEF covariance: C P Cᵀ with C the ECEF → ENU rotation.
pub(crate) fn enu_cov(frame: &EnuFrame, cov_ecef: &Matrix3<f64>) -> Matrix3<f64> {
    let c = frame.rotation();
    c * cov_ecef * c.transpose()
}

/// ECEF covariance of an ENU covariance.
pub(crate) fn ecef_cov(frame: &EnuFrame, cov_enu: &Matrix3<f64>) -> Matrix3<f64> {
    let c = frame.rotation();
    c.transpose() * cov_enu * c
}

/// Collects the batch's fixes: one from the pseudoranges of a `"gnss"` batch (the
/// estimator's systems), plus every [`Measurement::Position`] item. Ranges that give no
/// fix are counted in `rejected`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn fixes_of_batch(
    batch: &MeasurementBatch,
    t_s: f64,
    frame: &EnuFrame,
    systems: &[System],
    with_velocity: bool,
    near_ecef_m: Option<Vector3<f64>>,
    scratch: &mut Vec<RangeMeasurement>,
    fixes: &mut Vec<Fix>,
    rejected: &mut u32,
    gdop: &mut Option<f64>,
) {
    fixes.clear();
    if batch.source == SourceKind::Gnss {
        scratch.clear();
        scratch.extend(
            batch
                .ranges()
                .filter(|m| systems.is_empty() || systems.contains(&m.system()))
                .copied(),
        );
        if !scratch.is_empty() {
            let opts = WlsOptions {
                initial_pos_ecef_m: near_ecef_m,
                ..WlsOptions::default()
            };
            match wls::solve(scratch.iter(), &opts) {
                Ok(fix) => {
                    let vel = if with_velocity {
                        velocity_from_rates(scratch, &fix.pos_ecef_m)
                            .map(|(v, c, _)| (frame.enu_vector_of_ecef(&v), enu_cov(frame, &c)))
                    } else {
                        None
                    };
                    *gdop = Some(fix.dop.gdop);
                    fixes.push(Fix {
                        t_s,
                        pos_enu_m: frame.enu_of_ecef(&fix.pos_ecef_m),
                        pos_cov_m2: enu_cov(frame, &fix.cov_pos_ecef_m2),
                        vel,
                        n: fix.n_measurements as u32,
                    });
                }
                Err(_) => *rejected += scratch.len() as u32,
            }
        }
    }
    for m in &batch.items {
        if let Measurement::Position(p) = m {
            match fix_of_position(frame, t_s, p) {
                Some(f) => fixes.push(f),
                None => *rejected += 1,
            }
        }
    }
}

/// A fix source's position item at `t_s` as a fix in the world frame; `None` when a value
/// is not finite.
pub(crate) fn fix_of_position(frame: &EnuFrame, t_s: f64, p: &PositionFix) -> Option<Fix> {
    p.pos_ecef_m
        .iter()
        .chain(p.cov_m2.iter())
        .all(|v| v.is_finite())
        .then(|| Fix {
            t_s,
            pos_enu_m: frame.enu_of_ecef(&p.pos_ecef_m),
            pos_cov_m2: enu_cov(frame, &p.cov_m2),
            vel: None,
            n: 1,
        })
}

/// Adds one update's NIS of `dof` components to the epoch's record, outside the
/// divergence watch's χ² test (`EpochOutcome::nis_unwatched`).
pub(crate) fn tally_unwatched_nis(out: &mut EpochOutcome, nis: f64, dof: u32) {
    if dof > 0 && out.record_nis(nis, dof) {
        out.nis_unwatched = true;
    }
}
