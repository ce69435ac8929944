//! Weighted least-squares snapshot fix from pseudoranges, and dilution of precision.
//!
//! The unknowns are the receiver position and one clock offset per positioning system
//! present (GPS, BDS, DTMB, TC-OFDM: up to 3 + 4 = 7), or a single clock shared by all
//! systems when [`WlsOptions::shared_clock`] is set (seed 000's assumption for GPS and
//! DTMB, §5.1), or with DTMB ranges on the GPS clock and every other system on its own
//! when [`WlsOptions::dtmb_on_gps_clock`] is set (seed 000's shared clock for GPS and DTMB
//! next to a BeiDou clock that absorbs BeiDou's inter-system bias). With `u_i` the unit line of sight from the receiver to emitter `i` and
//! `b_{s(i)}` the clock of its system, the model and its Jacobian row are (seed 000 eqs.
//! 9–13, here solved as a snapshot rather than inside the filter):
//!
//! ```text
//! ρ_i = ‖r_i − r‖ + b_{s(i)} + ε_i,    ε_i ~ N(0, σ_i²)
//! h_i = [−u_iᵀ, e_{s(i)}ᵀ]             (e_s: unit vector selecting the clock of system s)
//! ```
//! Gauss–Newton iterates `Δ = (Hᵀ W H)⁻¹ Hᵀ W (ρ − ρ̂)`, `W = diag(1/σ_i²)`, until the step
//! is below a tolerance. The normal equations are accumulated in fixed 7×7 matrices (the
//! unused clock rows are padded with an identity so that one Cholesky factorisation fits
//! every system mix), so no iteration touches the heap.
//!
//! The formal covariance of the position is the position block of `(Hᵀ W H)⁻¹`. The
//! dilutions of precision use the *unweighted* `G = (Hᵀ H)⁻¹`, the textbook definition,
//! with the position block rotated into local East-North-Up axes at the solution:
//! `HDOP = √(G_EE + G_NN)`, `VDOP = √G_UU`, `PDOP = √(tr G_pos)`, `TDOP = √(Σ G_clock)`,
//! `GDOP = √(tr G)`.
//!
//! Geometry is judged degenerate when a Cholesky pivot of the normal matrix falls below
//! 1e-12 of its diagonal entry, i.e. when one unknown's column is (to that precision) a
//! combination of the others — emitters all in one plane through the receiver, or all on
//! one cone around it (every satellite at one elevation), make the vertical position and
//! the clock inseparable.

use crate::core::geodesy::ecef_to_enu_rotation;
use crate::core::{Geodetic, System};
use crate::measurement::RangeMeasurement;
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Position and at most one clock unknown per [`System`] (in [`System::ALL`] order).
const MAX_UNKNOWNS: usize = 3 + System::COUNT;
type NormalMatrix = SMatrix<f64, MAX_UNKNOWNS, MAX_UNKNOWNS>;
type UnknownVector = SVector<f64, MAX_UNKNOWNS>;

/// Smallest accepted ratio of a squared Cholesky pivot to its diagonal entry.
const MIN_PIVOT_RATIO: f64 = 1e-12;

/// Options of [`solve`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WlsOptions {
    /// One clock for every system instead of one per system.
    pub shared_clock: bool,
    /// DTMB ranges take the GPS clock when GPS ranges are present (a tower locked to GPS
    /// time, as a single-frequency network's transmitters are); the other systems keep
    /// one clock each. Without GPS ranges DTMB has its own clock. Ignored when
    /// `shared_clock` is set.
    pub dtmb_on_gps_clock: bool,
    /// Starting position; by default the point of the WGS-84 ellipsoid below the mean of
    /// the emitter positions, which lies near the receiver for satellites spread across
    /// the sky and for towers around it alike.
    pub initial_pos_ecef_m: Option<Vector3<f64>>,
    /// Gauss–Newton iterations allowed before [`WlsError::NotConverged`].
    pub max_iterations: usize,
    /// Convergence threshold on the norm of the step (m).
    pub tolerance_m: f64,
}

impl Default for WlsOptions {
    fn default() -> Self {
        Self {
            shared_clock: false,
            dtmb_on_gps_clock: false,
            initial_pos_ecef_m: None,
            max_iterations: 20,
            tolerance_m: 1e-6,
        }
    }
}

/// Dilutions of precision (dimensionless).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dop {
    pub gdop: f64,
    pub pdop: f64,
    pub hdop: f64,
    pub vdop: f64,
    /// Root of the summed clock variances (all clock unknowns).
    pub tdop: f64,
}

/// A snapshot fix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WlsFix {
    /// Receiver position (ECEF, m).
    pub pos_ecef_m: Vector3<f64>,
    /// Clock offset (m) of each system in [`System::ALL`] order; `None` for a system with no
    /// measurement. With a shared clock every present system reports the same value.
    pub clocks_m: [Option<f64>; System::COUNT],
    /// Formal covariance of the position (ECEF, m²), from the stated measurement sigmas.
    pub cov_pos_ecef_m2: Matrix3<f64>,
    /// Dilutions of precision of the geometry at the solution.
    pub dop: Dop,
    /// Gauss–Newton iterations used.
    pub iterations: usize,
    /// RMS of the post-fit residuals (m).
    pub residual_rms_m: f64,
    /// Number of measurements used.
    pub n_measurements: usize,
    /// Number of clock unknowns solved for.
    pub n_clocks: usize,
}

impl WlsFix {
    /// The clock offset of a system (m), if it had measurements.
    pub fn clock_m(&self, s: System) -> Option<f64> {
        self.clocks_m[s.index()]
    }
}

/// Why no fix could be computed.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum WlsError {
    /// Fewer measurements than unknowns.
    #[error("too few measurements for a fix: have {have}, need at least {need} (3 position + 1 clock per system)")]
    TooFewMeasurements { have: usize, need: usize },
    /// The geometry does not determine every unknown.
    #[error("singular geometry: the emitters do not determine position and clock(s) (coplanar, conical or coincident)")]
    SingularGeometry,
    /// Gauss–Newton did not settle.
    #[error(
        "least squares did not converge in {iterations} iterations (last step {last_step_m} m)"
    )]
    NotConverged { iterations: usize, last_step_m: f64 },
    /// A measurement holds a non-finite value or a non-positive sigma.
    #[error("measurement {index} is invalid: non-finite value or sigma ≤ 0")]
    InvalidMeasurement { index: usize },
}

/// Computes a weighted least-squares fix from pseudoranges (range rates are ignored).
///
/// Takes anything that iterates over `&RangeMeasurement` and can be iterated again (a
/// slice, `batch.ranges()`), because the measurements are read once per iteration and
/// never copied.
///
/// # Errors
/// [`WlsError::InvalidMeasurement`], [`WlsError::TooFewMeasurements`],
/// [`WlsError::SingularGeometry`], [`WlsError::NotConverged`]. It never panics on input.
pub fn solve<'a, I>(measurements: I, opts: &WlsOptions) -> Result<WlsFix, WlsError>
where
    I: IntoIterator<Item = &'a RangeMeasurement>,
    I::IntoIter: Clone,
{
    let iter = measurements.into_iter();
    // First pass: validate, find the systems present and the default starting point.
    let mut present = [false; System::COUNT];
    let mut n = 0usize;
    let mut mean = Vector3::zeros();
    for (i, m) in iter.clone().enumerate() {
        let finite =
            m.pseudorange_m.is_finite() && m.emitter_pos_ecef_m.iter().all(|v| v.is_finite());
        if !finite || !m.sigma_m.is_finite() || m.sigma_m <= 0.0 {
            return Err(WlsError::InvalidMeasurement { index: i });
        }
        present[m.system().index()] = true;
        mean += m.emitter_pos_ecef_m;
        n += 1;
    }
    // Columns: 0..3 position, then one clock per present system (or one shared clock).
    let mut clock_col = [None; System::COUNT];
    let mut n_clocks = 0;
    let gps = System::Gps.index();
    for (s, &here) in present.iter().enumerate() {
        if here {
            if opts.dtmb_on_gps_clock
                && !opts.shared_clock
                && s == System::Dtmb.index()
                && clock_col[gps].is_some()
            {
                // GPS comes first in System::ALL, so its column already exists.
                clock_col[s] = clock_col[gps];
                continue;
            }
            clock_col[s] = Some(3 + if opts.shared_clock { 0 } else { n_clocks });
            if !opts.shared_clock || n_clocks == 0 {
                n_clocks += 1;
            }
        }
    }
    let n_unknowns = 3 + n_clocks;
    if n < n_unknowns {
        return Err(WlsError::TooFewMeasurements {
            have: n,
            need: n_unknowns.max(4),
        });
    }
    let mut est = UnknownVector::zeros();
    let start = match opts.initial_pos_ecef_m {
        Some(p) if p.iter().all(|v| v.is_finite()) => p,
        _ => {
            // The point of the ellipsoid below the emitters' centroid.
            let mut g = Geodetic::from_ecef(&(mean / n as f64));
            g.h_m = 0.0;
            g.to_ecef()
        }
    };
    est.fixed_rows_mut::<3>(0).copy_from(&start);

    let mut last_step_m = f64::INFINITY;
    for iteration in 1..=opts.max_iterations {
        let acc = accumulate(iter.clone(), &est, &clock_col, n_unknowns, false)
            .ok_or(WlsError::SingularGeometry)?;
        let chol = factor(&acc.normal, n_unknowns).ok_or(WlsError::SingularGeometry)?;
        let step = chol.solve(&acc.rhs);
        if !step.iter().all(|v| v.is_finite()) {
            return Err(WlsError::SingularGeometry);
        }
        est += step;
        last_step_m = step.norm();
        if last_step_m < opts.tolerance_m {
            return finish(iter, &est, &clock_col, n_unknowns, n_clocks, n, iteration);
        }
    }
    Err(WlsError::NotConverged {
        iterations: opts.max_iterations,
        last_step_m,
    })
}

/// Normal equations and residual sums at one linearisation point.
struct Accumulation {
    /// `Hᵀ W H`, identity-padded beyond the active unknowns.
    normal: NormalMatrix,
    /// `Hᵀ W (ρ − ρ̂)`.
    rhs: UnknownVector,
    /// `Hᵀ H`, identity-padded (for the dilutions of precision); only filled on request,
    /// at the solution.
    geometry: NormalMatrix,
    /// `Σ (ρ − ρ̂)²`.
    sum_sq_residual_m2: f64,
}

fn accumulate<'a>(
    iter: impl Iterator<Item = &'a RangeMeasurement>,
    est: &UnknownVector,
    clock_col: &[Option<usize>; System::COUNT],
    n_unknowns: usize,
    with_geometry: bool,
) -> Option<Accumulation> {
    let pos = Vector3::new(est[0], est[1], est[2]);
    let mut acc = Accumulation {
        normal: NormalMatrix::zeros(),
        rhs: UnknownVector::zeros(),
        geometry: NormalMatrix::zeros(),
        sum_sq_residual_m2: 0.0,
    };
    for m in iter {
        let los = m.emitter_pos_ecef_m - pos;
        let d = los.norm();
        if d.is_nan() || d <= 1e-3 {
            return None;
        }
        let col = clock_col[m.system().index()]?;
        let u = -los / d;
        let residual = m.pseudorange_m - (d + est[col]);
        let w = 1.0 / (m.sigma_m * m.sigma_m);
        // Rank-one updates of the 7×7 sums, h hᵀ w and h w r, over the four non-zero
        // entries of h = [−uᵀ, e_col]: the other products are exact zeros, which leave a
        // sum unchanged (a sum started at +0 is never −0), so this is the full update bit
        // for bit (tested against it) without the 45 zero terms.
        let (idx, hv) = ([0, 1, 2, col], [u.x, u.y, u.z, 1.0]);
        for a in 0..4 {
            for b in 0..4 {
                let o = hv[a] * hv[b];
                acc.normal[(idx[a], idx[b])] += o * w;
                if with_geometry {
                    acc.geometry[(idx[a], idx[b])] += o;
                }
            }
            acc.rhs[idx[a]] += hv[a] * (w * residual);
        }
        acc.sum_sq_residual_m2 += residual * residual;
    }
    for k in n_unknowns..MAX_UNKNOWNS {
        acc.normal[(k, k)] = 1.0;
        acc.geometry[(k, k)] = 1.0;
    }
    Some(acc)
}

/// Cholesky factor of an identity-padded normal matrix, or `None` when it is not
/// positive definite or a pivot reveals a (nearly) dependent column.
fn factor(
    n: &NormalMatrix,
    n_unknowns: usize,
) -> Option<nalgebra::Cholesky<f64, nalgebra::Const<MAX_UNKNOWNS>>> {
    if !n.iter().all(|v| v.is_finite()) {
        return None;
    }
    let chol = n.cholesky()?;
    let l = chol.l_dirty();
    for k in 0..n_unknowns {
        let pivot2 = l[(k, k)] * l[(k, k)];
        if pivot2.is_nan() || pivot2 <= MIN_PIVOT_RATIO * n[(k, k)] {
            return None;
        }
    }
    Some(chol)
}

/// Dilutions of precision from an identity-padded `Hᵀ H` at the receiver position.
fn dop_of_geometry(
    geometry: &NormalMatrix,
    n_unknowns: usize,
    receiver: &Vector3<f64>,
) -> Option<Dop> {
    let g = factor(geometry, n_unknowns)?.inverse();
    let g_pos = g.fixed_view::<3, 3>(0, 0).into_owned();
    let geo = Geodetic::from_ecef(receiver);
    let rot = ecef_to_enu_rotation(geo.lat_rad, geo.lon_rad);
    let g_enu = rot * g_pos * rot.transpose();
    let clock_var: f64 = (3..n_unknowns).map(|k| g[(k, k)]).sum();
    let pos_var = g_enu.trace();
    let dop = Dop {
        gdop: (pos_var + clock_var).sqrt(),
        pdop: pos_var.sqrt(),
        hdop: (g_enu[(0, 0)] + g_enu[(1, 1)]).sqrt(),
        vdop: g_enu[(2, 2)].sqrt(),
        tdop: clock_var.sqrt(),
    };
    [dop.gdop, dop.pdop, dop.hdop, dop.vdop, dop.tdop]
        .iter()
        .all(|v| v.is_finite())
        .then_some(dop)
}

fn finish<'a>(
    iter: impl Iterator<Item = &'a RangeMeasurement>,
    est: &UnknownVector,
    clock_col: &[Option<usize>; System::COUNT],
    n_unknowns: usize,
    n_clocks: usize,
    n: usize,
    iterations: usize,
) -> Result<WlsFix, WlsError> {
    let acc =
        accumulate(iter, est, clock_col, n_unknowns, true).ok_or(WlsError::SingularGeometry)?;
    let cov = factor(&acc.normal, n_unknowns)
        .ok_or(WlsError::SingularGeometry)?
        .inverse();
    let pos = Vector3::new(est[0], est[1], est[2]);
    let dop = dop_of_geometry(&acc.geometry, n_unknowns, &pos).ok_or(WlsError::SingularGeometry)?;
    let mut clocks_m = [None; System::COUNT];
    for (slot, col) in clocks_m.iter_mut().zip(clock_col) {
        *slot = col.map(|c| est[c]);
    }
    Ok(WlsFix {
        pos_ecef_m: pos,
        clocks_m,
        cov_pos_ecef_m2: cov.fixed_view::<3, 3>(0, 0).into_owned(),
        dop,
        iterations,
        residual_rms_m: (acc.sum_sq_residual_m2 / n as f64).sqrt(),
        n_measurements: n,
        n_clocks,
    })
}

/// Dilutions of precision of a set of emitters seen from `receiver_ecef_m`, each tagged
/// with the index (`0..n_clocks`) of the clock its ranges carry.
///
/// `None` when there are fewer emitters than unknowns, an index is out of range, an
/// emitter coincides with the receiver, or the geometry is singular.
pub fn dop(
    receiver_ecef_m: &Vector3<f64>,
    emitters: &[(Vector3<f64>, usize)],
    n_clocks: usize,
) -> Option<Dop> {
    if n_clocks == 0 || n_clocks > System::COUNT || emitters.len() < 3 + n_clocks {
        return None;
    }
    let mut geometry = NormalMatrix::zeros();
    for (emitter, clock) in emitters {
        if *clock >= n_clocks {
            return None;
        }
        let los = emitter - receiver_ecef_m;
        let d = los.norm();
        if !(d > 1e-3 && d.is_finite()) {
            return None;
        }
        add_outer(&mut geometry, &(-los / d), 3 + clock);
    }
    for k in (3 + n_clocks)..MAX_UNKNOWNS {
        geometry[(k, k)] = 1.0;
    }
    dop_of_geometry(&geometry, 3 + n_clocks, receiver_ecef_m)
}

/// `geometry += h hᵀ` for `h = [uᵀ, e_col]`, over the non-zero entries of h only (as in
/// [`accumulate`]: the same sums bit for bit).
fn add_outer(geometry: &mut NormalMatrix, u: &Vector3<f64>, col: usize) {
    let (idx, hv) = ([0, 1, 2, col], [u.x, u.y, u.z, 1.0]);
    for a in 0..4 {
        for b in 0..4 {
            geometry[(idx[a], idx[b])] += hv[a] * hv[b];
        }
    }
}

/// GDOP of emitters whose ranges all carry one clock — the GPS-only and GPS + DTMB
/// figures of seed 000's mode selection (§4, Fig. 8), where DTMB shares the GPS clock.
pub fn gdop(receiver_ecef_m: &Vector3<f64>, emitters: &[Vector3<f64>]) -> Option<f64> {
    if emitters.len() < 4 {
        return None;
    }
    let mut geometry = NormalMatrix::zeros();
    for emitter in emitters {
        let los = emitter - receiver_ecef_m;
        let d = los.norm();
        if !(d > 1e-3 && d.is_finite()) {
            return None;
        }
        add_outer(&mut geometry, &(-los / d), 3);
    }
    for k in 4..MAX_UNKNOWNS {
        geometry[(k, k)] = 1.0;
    }
    dop_of_geometry(&geometry, 4, receiver_ecef_m).map(|d| d.gdop)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::{EmitterId, EnuFrame};
    use approx::assert_relative_eq;

    fn meas(sys: System, pos: Vector3<f64>, pr: f64) -> RangeMeasurement {
        RangeMeasurement {
            emitter: EmitterId::new(sys, 1),
            emitter_pos_ecef_m: pos,
            emitter_vel_ecef_mps: Vector3::zeros(),
            pseudorange_m: pr,
            sigma_m: 2.0,
            range_rate_mps: None,
            sigma_rate_mps: 0.1,
            cn0_dbhz: 45.0,
            elevation_rad: 0.5,
        }
    }

    /// Emitters at the given (azimuth, elevation) in degrees, 20 000 km away.
    fn sky(frame: &EnuFrame, az_el_deg: &[(f64, f64)]) -> Vec<Vector3<f64>> {
        az_el_deg
            .iter()
            .map(|&(az, el)| {
                let (az, el) = (az.to_radians(), el.to_radians());
                let u = Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin());
                frame.ecef_of_enu(&(u * 20_000e3))
            })
            .collect()
    }

    /// The full 7×7 updates of the textbook form (h hᵀ w, h hᵀ, h w r with nalgebra's
    /// products), as `accumulate` was first written: the reference of the sparse loop.
    fn reference_accumulate(
        ms: &[RangeMeasurement],
        est: &UnknownVector,
        clock_col: &[Option<usize>; System::COUNT],
        n_unknowns: usize,
    ) -> Accumulation {
        let pos = Vector3::new(est[0], est[1], est[2]);
        let mut acc = Accumulation {
            normal: NormalMatrix::zeros(),
            rhs: UnknownVector::zeros(),
            geometry: NormalMatrix::zeros(),
            sum_sq_residual_m2: 0.0,
        };
        for m in ms {
            let los = m.emitter_pos_ecef_m - pos;
            let d = los.norm();
            let col = clock_col[m.system().index()].unwrap();
            let mut h = UnknownVector::zeros();
            h.fixed_rows_mut::<3>(0).copy_from(&(-los / d));
            h[col] = 1.0;
            let residual = m.pseudorange_m - (d + est[col]);
            let w = 1.0 / (m.sigma_m * m.sigma_m);
            let outer = h * h.transpose();
            acc.normal += outer * w;
            acc.geometry += outer;
            acc.rhs += h * (w * residual);
            acc.sum_sq_residual_m2 += residual * residual;
        }
        for k in n_unknowns..MAX_UNKNOWNS {
            acc.normal[(k, k)] = 1.0;
            acc.geometry[(k, k)] = 1.0;
        }
        acc
    }

    /// The rank-one updates over the non-zero entries of h (`accumulate`, and `dop`
    /// through `add_outer`) equal the full products bit for bit, over random geometries,
    /// sigmas, system mixes and receiver positions, emitters on the receiver's axes (exact
    /// and negative zeros in h) included.
    #[test]
    fn sparse_rank_one_updates_equal_the_full_products() {
        use rand::Rng;
        let mut rng = crate::core::TrialRng::new(11, 0).stream("test/wls/outer");
        let frame = EnuFrame::new(Geodetic::from_deg(39.9, 116.4, 60.0));
        let systems = [System::Gps, System::Bds, System::Dtmb, System::Tcofdm];
        for trial in 0..500 {
            let rx = frame.origin_ecef()
                + Vector3::new(
                    rng.random::<f64>() * 100.0,
                    rng.random::<f64>() * 100.0,
                    0.0,
                );
            let ms: Vec<RangeMeasurement> = (0..(4 + trial % 12))
                .map(|k| {
                    let mut e = rx
                        + Vector3::new(
                            rng.random::<f64>() - 0.5,
                            rng.random::<f64>() - 0.5,
                            rng.random::<f64>(),
                        ) * 2e7;
                    if k % 5 == 1 {
                        e.x = rx.x; // u.x = −0.0
                    }
                    let sys = systems[rng.random_range(0..4)];
                    let mut m = meas(sys, e, (e - rx).norm() + 100.0 * rng.random::<f64>());
                    m.sigma_m = 0.5 + 10.0 * rng.random::<f64>();
                    m
                })
                .collect();
            let mut present = [false; System::COUNT];
            for m in &ms {
                present[m.system().index()] = true;
            }
            let mut clock_col = [None; System::COUNT];
            let mut n_clocks = 0;
            for (c, here) in clock_col.iter_mut().zip(present) {
                if here {
                    *c = Some(3 + n_clocks);
                    n_clocks += 1;
                }
            }
            let mut est = UnknownVector::zeros();
            est.fixed_rows_mut::<3>(0)
                .copy_from(&(rx + Vector3::repeat(30.0)));
            est[3] = 55.0;
            let a = accumulate(ms.iter(), &est, &clock_col, 3 + n_clocks, true).unwrap();
            let b = reference_accumulate(&ms, &est, &clock_col, 3 + n_clocks);
            let bits = |m: &NormalMatrix| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a.normal), bits(&b.normal), "trial {trial}");
            assert_eq!(bits(&a.geometry), bits(&b.geometry), "trial {trial}");
            let vb = |v: &UnknownVector| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(vb(&a.rhs), vb(&b.rhs), "trial {trial}");
            assert_eq!(
                a.sum_sq_residual_m2.to_bits(),
                b.sum_sq_residual_m2.to_bits()
            );
            // dop() with one shared clock against the reference geometry.
            let tagged: Vec<_> = ms.iter().map(|m| (m.emitter_pos_ecef_m, 0)).collect();
            let shared = [Some(3); System::COUNT];
            let got = dop(&rx, &tagged, 1);
            let want = dop_of_geometry(
                &reference_accumulate(
                    &ms,
                    &{
                        let mut e = est;
                        e.fixed_rows_mut::<3>(0).copy_from(&rx);
                        e
                    },
                    &shared,
                    4,
                )
                .geometry,
                4,
                &rx,
            );
            assert_eq!(got, want, "trial {trial}");
            assert_eq!(
                gdop(
                    &rx,
                    &ms.iter().map(|m| m.emitter_pos_ecef_m).collect::<Vec<_>>()
                ),
                want.map(|d| d.gdop)
            );
        }
    }

    #[test]
    fn hand_checked_dop() {
        // Zenith plus three on the horizon 120° apart: HᵀH in ENU is block diagonal with
        // E, N entries 3/2 and an (U, clock) block [[1, 1], [1, 4]], so
        // HDOP² = 2/3 + 2/3, VDOP² = 4/3, TDOP² = 1/3, GDOP = √3, PDOP = √(8/3).
        let frame = EnuFrame::new(Geodetic::from_deg(40.0, 116.0, 0.0));
        let sats = sky(
            &frame,
            &[(0.0, 90.0), (0.0, 0.0), (120.0, 0.0), (240.0, 0.0)],
        );
        let r = frame.origin_ecef();
        assert_relative_eq!(gdop(&r, &sats).unwrap(), 3f64.sqrt(), max_relative = 1e-9);
        let tagged: Vec<_> = sats.iter().map(|&s| (s, 0)).collect();
        let d = dop(&r, &tagged, 1).unwrap();
        assert_relative_eq!(d.pdop, (8.0f64 / 3.0).sqrt(), max_relative = 1e-9);
        assert_relative_eq!(d.hdop, (4.0f64 / 3.0).sqrt(), max_relative = 1e-9);
        assert_relative_eq!(d.vdop, (4.0f64 / 3.0).sqrt(), max_relative = 1e-9);
        assert_relative_eq!(d.tdop, (1.0f64 / 3.0).sqrt(), max_relative = 1e-9);
        assert!(
            dop(&r, &tagged, 2).is_none(),
            "clock 1 has no emitter and only 4 rows for 5 unknowns"
        );
    }

    #[test]
    fn noise_free_fix_recovers_truth() {
        let frame = EnuFrame::new(Geodetic::from_deg(39.9, 116.4, 60.0));
        let truth = frame.origin_ecef();
        let sats = sky(
            &frame,
            &[
                (10.0, 70.0),
                (80.0, 30.0),
                (150.0, 45.0),
                (200.0, 15.0),
                (300.0, 50.0),
                (250.0, 25.0),
            ],
        );
        let ms: Vec<_> = sats
            .iter()
            .map(|&s| meas(System::Gps, s, (s - truth).norm() + 1234.5))
            .collect();
        let fix = solve(&ms, &WlsOptions::default()).unwrap();
        assert!(
            (fix.pos_ecef_m - truth).norm() < 1e-3,
            "{}",
            (fix.pos_ecef_m - truth).norm()
        );
        assert!((fix.clock_m(System::Gps).unwrap() - 1234.5).abs() < 1e-3);
        assert_eq!(fix.clock_m(System::Bds), None);
        assert!(fix.residual_rms_m < 1e-6);
        assert!(fix.dop.gdop > fix.dop.pdop && fix.dop.pdop > fix.dop.hdop);
    }

    #[test]
    fn too_few_and_invalid_measurements_are_errors() {
        let frame = EnuFrame::new(Geodetic::from_deg(39.9, 116.4, 60.0));
        let truth = frame.origin_ecef();
        let sats = sky(&frame, &[(10.0, 70.0), (80.0, 30.0), (150.0, 45.0)]);
        let ms: Vec<_> = sats
            .iter()
            .map(|&s| meas(System::Gps, s, (s - truth).norm()))
            .collect();
        assert_eq!(
            solve(&ms, &WlsOptions::default()),
            Err(WlsError::TooFewMeasurements { have: 3, need: 4 })
        );
        assert_eq!(
            solve(&[], &WlsOptions::default()),
            Err(WlsError::TooFewMeasurements { have: 0, need: 4 })
        );
        let mut bad = ms.clone();
        bad[1].pseudorange_m = f64::NAN;
        assert_eq!(
            solve(&bad, &WlsOptions::default()),
            Err(WlsError::InvalidMeasurement { index: 1 })
        );
    }

    /// A DTMB tower on the GPS clock: with noiseless ranges the fix is exact and DTMB
    /// reports the GPS clock; the tower's range adds information (smaller position
    /// covariance), while on a clock of its own it adds none (the covariance equals the
    /// fix without it, since a free clock absorbs the one range that observes it).
    #[test]
    fn dtmb_on_the_gps_clock_adds_information() {
        let frame = EnuFrame::new(Geodetic::from_deg(40.0, 116.4, 45.0));
        let rx = frame.ecef_of_enu(&Vector3::new(12.0, -7.0, 1.5));
        let (b_gps, b_bds) = (30.0, 45.0);
        let gps = sky(
            &frame,
            &[(20.0, 60.0), (140.0, 35.0), (260.0, 40.0), (330.0, 15.0)],
        );
        let bds = sky(&frame, &[(90.0, 50.0), (200.0, 25.0)]);
        let tower = frame.ecef_of_enu(&Vector3::new(-8250.0, -9345.0, 273.0));
        let mut ms: Vec<RangeMeasurement> = gps
            .iter()
            .map(|e| meas(System::Gps, *e, (e - rx).norm() + b_gps))
            .chain(
                bds.iter()
                    .map(|e| meas(System::Bds, *e, (e - rx).norm() + b_bds)),
            )
            .collect();
        let without = solve(&ms, &WlsOptions::default()).unwrap();
        ms.push(meas(System::Dtmb, tower, (tower - rx).norm() + b_gps));
        let own = solve(&ms, &WlsOptions::default()).unwrap();
        let on_gps = WlsOptions {
            dtmb_on_gps_clock: true,
            ..WlsOptions::default()
        };
        let joint = solve(&ms, &on_gps).unwrap();
        assert!((joint.pos_ecef_m - rx).norm() < 1e-4);
        assert_eq!(joint.n_clocks, 2);
        assert_relative_eq!(joint.clock_m(System::Dtmb).unwrap(), b_gps, epsilon = 1e-4);
        assert_relative_eq!(joint.clock_m(System::Bds).unwrap(), b_bds, epsilon = 1e-4);
        assert_eq!(own.n_clocks, 3);
        assert_relative_eq!(
            own.cov_pos_ecef_m2,
            without.cov_pos_ecef_m2,
            max_relative = 1e-9
        );
        assert!(joint.cov_pos_ecef_m2.trace() < 0.99 * without.cov_pos_ecef_m2.trace());
        // Without GPS ranges the tower keeps a clock of its own.
        let no_gps: Vec<RangeMeasurement> = ms
            .iter()
            .filter(|m| m.system() != System::Gps)
            .copied()
            .collect();
        assert!(matches!(
            solve(&no_gps, &on_gps),
            Err(WlsError::TooFewMeasurements { .. })
        ));
    }
}
