//! Inertial sensing and navigation: truth attitude, IMU error models, Allan deviation,
//! strapdown mechanisation, the 15-state loosely coupled error-state Kalman filter of
//! seed 004 and pedestrian dead reckoning (PDR) as in seed 002.
//!
//! # Frames and the Earth model
//!
//! Everything works in the world's local **East-North-Up tangent plane** (the `EnuFrame`
//! of the world origin), treated as an Earth-fixed Cartesian frame (Groves 2013, §2.1.4
//! "local tangent-plane frame"). Because the frame is fixed to the Earth, the mechanisation
//! is the Earth-frame mechanisation of Groves §5.3 written in rotated axes: the frame turns
//! with the Earth rate ω_ie, and there is **no transport rate** (ω_en = 0):
//!
//! ```text
//! Ċ_b^n = C_b^n [ω_ib^b ×] − [ω_ie^n ×] C_b^n
//! v̇^n   = C_b^n f^b + g^n(h) − 2 ω_ie^n × v^n
//! ṙ^n   = v^n
//! ```
//!
//! with ω_ie^n = Ω (0, cos L₀, sin L₀) at the origin latitude L₀ and Ω = 7.292115e-5 rad/s.
//! Gravity g^n = (0, 0, −γ(L₀, h)) is the WGS-84 normal gravity (Somigliana) with the
//! Groves eq. 2.134 height correction; its direction is the origin's vertical everywhere.
//! This "flat Earth with the true Earth rate and true height dependence of gravity" is exact
//! for the simulator because the truth IMU ([`attitude::ideal_imu`]) is generated with the
//! same model, so a perfect IMU integrates back to the truth. Its limits are those of any
//! tangent-plane navigator: over a few kilometres the real plumb line turns by d/R (0.16 mrad
//! per km), and the Schuler feedback of a curved Earth is absent, so error growth over
//! outages longer than ~10 minutes is pessimistic (Groves §5.7).
//!
//! Body axes are **forward-left-up** (FLU). Attitude is the unit quaternion `q_nb` that
//! rotates body vectors into ENU, C_b^n = R_z(π/2 − ψ) R_y(−θ) R_x(φ) with heading ψ from
//! north clockwise, pitch θ nose up and roll φ right side down.
//!
//! # Modules
//!
//! * [`attitude`]: truth with attitude for a car, a pedestrian and a handheld phone (gait
//!   overlay with countable steps) and the ideal specific force and angular rate.
//! * [`imu`]: the IMU error model and its configuration (`low`, `mid`, `high` grades of
//!   facts §4, or custom values).
//! * [`allan`]: overlapping Allan deviation (IEEE Std 952-1997, Annex C).
//! * [`strapdown`]: the mechanisation above.
//! * [`ins_ekf`]: the psi-angle 15-state error-state Kalman filter (seed 004, eqs. 1–8,
//!   14–19), closed loop.
//! * [`ins_bound`]: the posterior Cramér–Rao bound of the INS rows (the error model along
//!   the true trajectory, with the ranges' information).
//! * [`ins_family`]: the same error model as a process and measurement model of the
//!   generic Kalman family, so that seed 004's EKF, CKF, STF and RE-KF run on it.
//! * [`magnetometer`]: a constant Earth field and a noisy three-axis magnetometer.
//! * [`pdr`]: step detection, Weinberg step length and an AHRS heading.
//! * [`source`]: the IMU (`"imu"`) and the PDR unit (`"pdr"`) as event-engine sources.
//! * [`ins_estimator`], [`pdr_estimator`]: the loosely coupled INS and PDR dead reckoning as
//!   engine estimators, taking their fixes through [`fixes`].

pub mod allan;
pub mod attitude;
pub mod fixes;
pub mod imu;
pub mod ins_bound;
pub mod ins_ekf;
pub mod ins_estimator;
pub mod ins_family;
pub mod ins_tight;
pub mod magnetometer;
pub mod pdr;
pub mod pdr_estimator;
pub mod source;
pub mod strapdown;

use nalgebra::Vector3;

/// The Earth's rotation rate Ω (rad/s), WGS-84.
pub const OMEGA_IE_RAD_PER_S: f64 = 7.292_115e-5;
/// WGS-84 equatorial radius (m).
const WGS84_A_M: f64 = 6_378_137.0;
/// WGS-84 flattening.
const WGS84_F: f64 = 1.0 / 298.257_223_563;
/// WGS-84 first eccentricity squared.
const WGS84_E2: f64 = WGS84_F * (2.0 - WGS84_F);
/// WGS-84 polar radius (m).
const WGS84_B_M: f64 = WGS84_A_M * (1.0 - WGS84_F);
/// WGS-84 Earth gravitational constant μ (m³/s²).
const WGS84_MU_M3PS2: f64 = 3.986_004_418e14;
/// Standard gravity, used only to express accelerations in g in messages.
pub const STANDARD_GRAVITY_MPS2: f64 = 9.806_65;

/// The Earth as seen from a local tangent plane at latitude L₀: the Earth rate in ENU and
/// normal gravity as a function of height.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalEarth {
    /// Geodetic latitude of the tangent point (rad).
    pub lat_rad: f64,
    /// Ellipsoidal height of the tangent point, the ENU origin (m).
    pub origin_h_m: f64,
    /// ω_ie^n = Ω (0, cos L₀, sin L₀) (rad/s).
    pub omega_ie_enu_rps: Vector3<f64>,
    /// Surface normal gravity γ₀(L₀) (m/s²).
    gamma0_mps2: f64,
}

impl LocalEarth {
    /// The Earth at a tangent point of latitude `lat_rad` and height `origin_h_m`.
    pub fn new(lat_rad: f64, origin_h_m: f64) -> Self {
        let s2 = lat_rad.sin().powi(2);
        // Somigliana's closed form for WGS-84 normal gravity on the ellipsoid (Groves eq. 2.133).
        let gamma0_mps2 =
            9.780_325_335_9 * (1.0 + 0.001_931_852_652_41 * s2) / (1.0 - WGS84_E2 * s2).sqrt();
        Self {
            lat_rad,
            origin_h_m,
            omega_ie_enu_rps: Vector3::new(0.0, lat_rad.cos(), lat_rad.sin()) * OMEGA_IE_RAD_PER_S,
            gamma0_mps2,
        }
    }

    /// Normal gravity magnitude γ at ENU up coordinate `up_m` (m/s²), Groves eq. 2.134:
    /// γ(h) = γ₀ [1 − (2/a)(1 + f + ω²a²b/μ) h + 3h²/a²], h = origin height + up.
    pub fn gravity_mps2(&self, up_m: f64) -> f64 {
        let h = self.origin_h_m + up_m;
        let m = OMEGA_IE_RAD_PER_S.powi(2) * WGS84_A_M.powi(2) * WGS84_B_M / WGS84_MU_M3PS2;
        self.gamma0_mps2
            * (1.0 - 2.0 / WGS84_A_M * (1.0 + WGS84_F + m) * h + 3.0 * h * h / WGS84_A_M.powi(2))
    }

    /// The gravity vector g^n = (0, 0, −γ) at up coordinate `up_m` (m/s²).
    pub fn gravity_enu_mps2(&self, up_m: f64) -> Vector3<f64> {
        Vector3::new(0.0, 0.0, -self.gravity_mps2(up_m))
    }

    /// ∂γ/∂h (1/s², negative): the vertical gravity gradient that makes the INS vertical
    /// channel unstable.
    pub fn gravity_gradient_per_s2(&self, up_m: f64) -> f64 {
        let h = self.origin_h_m + up_m;
        let m = OMEGA_IE_RAD_PER_S.powi(2) * WGS84_A_M.powi(2) * WGS84_B_M / WGS84_MU_M3PS2;
        self.gamma0_mps2 * (-2.0 / WGS84_A_M * (1.0 + WGS84_F + m) + 6.0 * h / WGS84_A_M.powi(2))
    }
}

/// The skew-symmetric matrix [v×] with [v×] u = v × u.
pub(crate) fn skew(v: &Vector3<f64>) -> nalgebra::Matrix3<f64> {
    nalgebra::Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The ENU variances `[σ_h², σ_h², σ_v²]` (m²/s²) of velocity noise given as
/// `[σ_h, σ_v]` (m/s): what a velocity measurement does not describe of the IMU's motion
/// (a walker's gait, `fix_velocity_noise_mps` of [`ins_estimator::InsFilterConfig`]).
pub fn velocity_noise_var_enu(sigma_mps: [f64; 2]) -> Vector3<f64> {
    let [h, v] = sigma_mps;
    Vector3::new(h * h, h * h, v * v)
}

/// Heading from north, clockwise, in [0, 2π), of the body forward axis of `q_nb`.
pub fn heading_of_attitude(q_nb: &nalgebra::UnitQuaternion<f64>) -> f64 {
    let x = q_nb * Vector3::x();
    x.x.atan2(x.y).rem_euclid(std::f64::consts::TAU)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_gravity_matches_published_values() {
        // WGS-84 normal gravity: 9.7803253359 at the equator, 9.8321849379 at the poles (NIMA
        // TR8350.2 table 3.4); 45° latitude gives 9.806199 m/s².
        assert!((LocalEarth::new(0.0, 0.0).gravity_mps2(0.0) - 9.780_325_335_9).abs() < 1e-9);
        let pole = LocalEarth::new(std::f64::consts::FRAC_PI_2, 0.0).gravity_mps2(0.0);
        assert!((pole - 9.832_184_937_9).abs() < 1e-7, "{pole}");
        // The free-air gradient is about −3.086e-6 s⁻².
        let e = LocalEarth::new(0.7, 0.0);
        assert!((e.gravity_gradient_per_s2(0.0) + 3.086e-6).abs() < 0.01e-6);
        let dg = e.gravity_mps2(100.0) - e.gravity_mps2(0.0);
        assert!((dg - 100.0 * e.gravity_gradient_per_s2(50.0)).abs() < 1e-9);
    }
}
