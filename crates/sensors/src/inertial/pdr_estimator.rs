//! Pedestrian dead reckoning as an estimator the engine drives ([`PdrEstimator`], seed 002
//! §4.2, the PDR-only row): step events move the position, position fixes reset it through
//! a Kalman update, and seed 002's DTMB range differences can be fused with their error as
//! states ([`RangeDifferenceModel`]).
//!
//! It works in the world's ENU frame and reports ECEF estimates. It never panics on its
//! input: a measurement it cannot use is counted as rejected, and a state that stops
//! being finite is reported as `numerical_failure`; the PDR keeps its last finite
//! position.

use crate::core::config::check_range;
use crate::core::{ConfigIssue, EnuFrame, GpsTime, System};
use crate::fusion::models::MeasurementModel;
use crate::measurement::{
    EpochOutcome, Estimate, Estimator, Measurement, MeasurementBatch, RangeDifference,
    RangeMeasurement, SourceKind, StepEvent,
};
use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, Vector2, Vector3};

/// The filter's covariance: `[x, y, e, ė, β, κ]`.
type Matrix6 = SMatrix<f64, 6, 6>;
use serde::{Deserialize, Serialize};

use super::fixes::{ecef_cov, fixes_of_batch, Fix};

fn d_start_sigma() -> f64 {
    0.5
}
fn d_ocxo_h0() -> f64 {
    2e-25
}
fn d_ocxo_hm2() -> f64 {
    6e-25
}
fn d_calibration_s() -> f64 {
    5.0
}
fn d_rd_floor() -> f64 {
    0.05
}
fn d_rd_multipath() -> f64 {
    0.01
}

/// `[estimator.pdr]`: where dead reckoning starts and which fixes (if any) reset it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PdrFilterConfig {
    /// Start position (ENU m, up optional as 0); default the world's known start point (the
    /// constructor's `known_start_enu_m`), else the first fix.
    #[serde(default)]
    pub start_enu_m: Option<Vec<f64>>,
    /// 1-σ of the start position per axis (m); default 0.5.
    #[serde(default = "d_start_sigma")]
    pub start_sigma_m: f64,
    /// Sources whose fixes update the position (`"gnss"` by least squares, others by their
    /// position items); default none (PDR only, seed 002's "PDR" row).
    #[serde(default)]
    pub fix_sources: Vec<SourceKind>,
    /// Reject fixes whose NIS exceeds this (χ², 2 degrees of freedom); default none.
    #[serde(default)]
    pub nis_gate: Option<f64>,
    /// Sources whose TPS-CFO range differences (seed 002 §3.2) update the filter, e.g.
    /// `["dtmb"]`; default none. Only the first tower seen is used.
    #[serde(default)]
    pub range_difference_sources: Vec<SourceKind>,
    /// The power-law coefficients h₀ (s) and h₋₂ (1/s) of the DTMB receiver's oscillator,
    /// whose phase wander the range differences integrate; default Brown & Hwang's OCXO
    /// (2e-25, 6e-25), the `ocxo` preset of `[receiver.clock]` (a TCXO is 2e-19, 2e-20).
    #[serde(default = "d_ocxo_h0")]
    pub range_difference_h0_s: f64,
    /// The oscillator's random-walk FM coefficient h₋₂ (Hz) for the range differences;
    /// default the `ocxo` preset's.
    #[serde(default = "d_ocxo_hm2")]
    pub range_difference_h_minus2_hz: f64,
    /// Duration of the static CFO calibration at the start (s); default 5, as
    /// `dtmb::tps::STATIC_CALIBRATION_S`.
    #[serde(default = "d_calibration_s")]
    pub range_difference_calibration_s: f64,
    /// Random-walk intensity of the range-difference error that the oscillator does not
    /// explain, the integrated multipath Doppler error (m/√s); default 0.01 (the
    /// multipath part of `worlds/seed002-lianhua.toml`'s range differences stays within
    /// 2 cm over its 188 s walk; the default leaves 0.14 m for sites with more).
    #[serde(default = "d_rd_multipath")]
    pub range_difference_multipath_m_per_sqrt_s: f64,
    /// Added in quadrature to the range difference's own σ (m); default 0.05: between steps
    /// the walker's position is extrapolated with the last step's velocity, and the gait's
    /// surge (±0.13 m/s for the default gait) moves it by centimetres about that.
    #[serde(default = "d_rd_floor")]
    pub range_difference_sigma_floor_m: f64,
    /// 1-σ (°) of the AHRS heading offset β at the start, the slowly varying part of the
    /// step headings' error (gyro bias held by the magnetometer loop, magnetometer
    /// calibration residual); default none: the heading error is white from step to step
    /// and the filter has no β state (the older model). When set, β is a filter state that
    /// the fixes and range differences observe (see [`PdrEstimator`]).
    #[serde(default)]
    pub heading_offset_sigma_deg: Option<f64>,
    /// Correlation time τ (s) of the heading offset β, a first-order Gauss–Markov process
    /// of σ `heading_offset_sigma_deg`; default 150 s, the slow pole k_m/k_i of the
    /// default AHRS (mag gain 0.3 /s, bias gain 0.002 /s²), with which the AHRS's integral
    /// term learns the gyro bias and the offset it causes fades.
    #[serde(default = "d_heading_offset_tau")]
    pub heading_offset_time_constant_s: f64,
    /// Relative 1-σ of the step-length scale error κ (the walker's Weinberg K calibration
    /// error: every step length is L_true (1 + κ)); default none: step-length errors are
    /// white and κ is no state. When set, κ is a constant state the fixes and range
    /// differences observe.
    #[serde(default)]
    pub step_scale_sigma: Option<f64>,
}

fn d_heading_offset_tau() -> f64 {
    150.0
}

impl Default for PdrFilterConfig {
    fn default() -> Self {
        Self {
            start_enu_m: None,
            start_sigma_m: d_start_sigma(),
            fix_sources: Vec::new(),
            nis_gate: None,
            range_difference_sources: Vec::new(),
            range_difference_h0_s: d_ocxo_h0(),
            range_difference_h_minus2_hz: d_ocxo_hm2(),
            range_difference_calibration_s: d_calibration_s(),
            range_difference_sigma_floor_m: d_rd_floor(),
            range_difference_multipath_m_per_sqrt_s: d_rd_multipath(),
            heading_offset_sigma_deg: None,
            heading_offset_time_constant_s: d_heading_offset_tau(),
            step_scale_sigma: None,
        }
    }
}

impl PdrFilterConfig {
    /// Checks every value.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the first bad field.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        if let Some(s) = &self.start_enu_m {
            if !(s.len() == 2 || s.len() == 3) || s.iter().any(|v| !v.is_finite()) {
                return Err(ConfigIssue::new(
                    "start_enu_m",
                    format!("expected [east, north] or [east, north, up] in m, got {s:?}"),
                ));
            }
        }
        check_range(
            "start_sigma_m",
            self.start_sigma_m,
            0.0,
            1.0e4,
            true,
            "a start σ in m",
        )?;
        if self.fix_sources.contains(&SourceKind::Pdr) {
            return Err(ConfigIssue::new(
                "fix_sources",
                format!(
                    "expected names of fix sources such as \"gnss\" (not \"pdr\"), got {:?}",
                    self.fix_sources
                ),
            ));
        }
        if let Some(g) = self.nis_gate {
            check_range("nis_gate", g, 0.0, 1.0e6, true, "a χ² gate")?;
        }
        if self.range_difference_sources.contains(&SourceKind::Pdr) {
            return Err(ConfigIssue::new(
                "range_difference_sources",
                format!(
                    "expected names of range-difference sources such as \"dtmb\", got {:?}",
                    self.range_difference_sources
                ),
            ));
        }
        for (key, v) in [
            ("range_difference_h0_s", self.range_difference_h0_s),
            (
                "range_difference_h_minus2_hz",
                self.range_difference_h_minus2_hz,
            ),
        ] {
            if !(v.is_finite() && (0.0..1e-12).contains(&v)) {
                return Err(ConfigIssue::new(
                    key,
                    format!("expected an oscillator coefficient within [0, 1e-12), got {v}"),
                ));
            }
        }
        let f = self.range_difference_sigma_floor_m;
        if !(f.is_finite() && (0.0..=100.0).contains(&f)) {
            return Err(ConfigIssue::new(
                "range_difference_sigma_floor_m",
                format!("expected a σ in m within [0, 100], got {f}"),
            ));
        }
        check_range(
            "range_difference_calibration_s",
            self.range_difference_calibration_s,
            0.0,
            3600.0,
            true,
            "a calibration time in s",
        )?;
        if let Some(sig) = self.heading_offset_sigma_deg {
            check_range(
                "heading_offset_sigma_deg",
                sig,
                0.0,
                180.0,
                true,
                "a heading-offset σ in degrees",
            )?;
        }
        if let Some(sig) = self.step_scale_sigma {
            check_range(
                "step_scale_sigma",
                sig,
                0.0,
                0.5,
                true,
                "a relative step-length σ",
            )?;
        }
        check_range(
            "heading_offset_time_constant_s",
            self.heading_offset_time_constant_s,
            1e-3,
            1e7,
            true,
            "a correlation time in s",
        )?;
        let q = self.range_difference_multipath_m_per_sqrt_s;
        if !(q.is_finite() && (0.0..=100.0).contains(&q)) {
            return Err(ConfigIssue::new(
                "range_difference_multipath_m_per_sqrt_s",
                format!("expected a random-walk intensity in m/√s within [0, 100], got {q}"),
            ));
        }
        Ok(())
    }
}

/// The range difference to one tower as a measurement of the [`PdrEstimator`]'s state
/// `[x, y, e, ė]` (east, north m; the accumulated range-difference error e (m) and its
/// rate (m/s)), seed 002 §3.2 and §4.2:
///
/// ```text
/// Δr = ‖p + d − p_b‖ − r₀ + e + w,   p = (x, y, up),   w ~ N(0, σ²)
/// H  = [u_x, u_y, 1, 0],              u = (p + d − p_b)/‖p + d − p_b‖
/// ```
///
/// with `r₀` the range at the reference epoch as the filter anchored it and `d` the
/// walker's displacement since the last step (the PDR state is the position at the last
/// step; `d` = the last step's velocity × the time since it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeDifferenceModel {
    /// Tower position (ENU m).
    pub tower_enu_m: Vector3<f64>,
    /// The walker's up coordinate (m), held fixed by the PDR.
    pub up_m: f64,
    /// The anchored reference range r₀ (m).
    pub r0_m: f64,
    /// The displacement d since the last step (east, north m).
    pub offset_en_m: Vector2<f64>,
    /// σ of the white part w (m).
    pub sigma_m: f64,
}

impl MeasurementModel<4, 1> for RangeDifferenceModel {
    fn h(&self, x: &SVector<f64, 4>) -> SVector<f64, 1> {
        let d = Vector3::new(
            x[0] + self.offset_en_m.x,
            x[1] + self.offset_en_m.y,
            self.up_m,
        ) - self.tower_enu_m;
        SVector::<f64, 1>::new(d.norm() - self.r0_m + x[2])
    }
    fn jacobian(&self, x: &SVector<f64, 4>) -> SMatrix<f64, 1, 4> {
        let d = Vector3::new(
            x[0] + self.offset_en_m.x,
            x[1] + self.offset_en_m.y,
            self.up_m,
        ) - self.tower_enu_m;
        let n = d.norm().max(1e-9);
        SMatrix::<f64, 1, 4>::new(d.x / n, d.y / n, 1.0, 0.0)
    }
    fn r(&self) -> SMatrix<f64, 1, 1> {
        SMatrix::<f64, 1, 1>::new(self.sigma_m * self.sigma_m)
    }
}

/// The anchored tower of a [`PdrEstimator`] that fuses range differences.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Anchor {
    emitter: crate::core::EmitterId,
    tower_enu_m: Vector3<f64>,
    r0_m: f64,
}

/// Dead reckoning from [`StepEvent`]s (seed 002 §4.2's PDR), a filter on the horizontal
/// position [x_east, y_north] with covariance P:
///
/// ```text
/// x ← x + L sin ψ,   y ← y + L cos ψ                        (ψ from north, clockwise)
/// P ← P + J diag(σ_L², σ_ψ²) Jᵀ,   J = [[sin ψ,  L cos ψ], [cos ψ, −L sin ψ]]
/// ```
///
/// (seed 002's x_t = x_{t−1} + v Δt cos θ with θ = π/2 − ψ and v Δt = L), and, when fixes
/// come, the Kalman update with H = I₂ and the horizontal block of the fix covariance. The
/// up coordinate stays at the start's.
///
/// # Heading offset and step scale (`heading_offset_sigma_deg`, `step_scale_sigma`)
///
/// Seed 002 §4.2's EKF (state [x, y, θ̇, θ, v]) observes the AHRS heading as θ + δ₄ with
/// white δ₄, as the plain step covariance above does. A phone's heading error is not
/// white but a slowly varying offset (the gyro bias the AHRS's magnetometer loop holds,
/// the hard-iron compass deviation), and the Weinberg K error is one scale for the walk.
/// When configured, both are states (augmentation for coloured measurement noise): the
/// state is `[x, y, e, ė, β, κ]`, a step moves the position along ψ − β̂ by L/(1 + κ̂),
///
/// ```text
/// Φ[x,β] = −L' cos ψ',  Φ[y,β] = L' sin ψ',  Φ[x,κ] = −L' sin ψ'/(1+κ̂),  Φ[y,κ] = −L' cos ψ'/(1+κ̂)
/// β ← e^{−Δt/τ} β,  Q_β = σ_β² (1 − e^{−2Δt/τ}),   κ constant
/// ```
///
/// (ψ' = ψ − β̂, L' = L/(1 + κ̂), Δt the time between steps), and the fixes and range
/// differences observe β and κ through the position. Unset, β and κ have zero variance
/// and stay 0: the filter is the plain one.
///
/// # Range differences (`range_difference_sources`)
///
/// Seed 002 observes `Δr_t = r_t − r_{t−1} + δ₃`, the increment against the previous
/// estimate. The error of a TPS-CFO range difference is not white from epoch to epoch but
/// the receiver oscillator's phase wander plus the integrated multipath Doppler
/// (`dtmb::tps`), so the filter carries it: the state is `[x, y, e, ė]`, the
/// cumulative Δr is the measurement ([`RangeDifferenceModel`]) and between batches
///
/// ```text
/// e ← e + ė Δt,   Q_e = c² Q_clock(h₀, h₋₂, Δt) + diag(q_mp² Δt, 0)
/// ```
///
/// (Brown & Hwang's two-state clock noise of the configured h₀, h₋₂; `q_mp` is
/// `range_difference_multipath_m_per_sqrt_s`). The first range difference anchors
/// `r₀ = ‖p̂ − p_b‖ − Δr`, and e starts at 0 with the position's uncertainty along the line
/// of sight, `var e = uᵀ P u`, `cov(p, e) = −P u`, and ė with the static calibration's
/// (`c² (h₀/(2T) + 2π² h₋₂ T/3)`, T = `range_difference_calibration_s`). Without range differences e and ė stay
/// uncorrelated with the position and the filter is the 2-state one.
pub struct PdrEstimator {
    name: String,
    cfg: PdrFilterConfig,
    frame: EnuFrame,
    systems: Vec<System>,
    start_sigma_m: f64,
    pos_en_m: Option<Vector2<f64>>,
    up_m: f64,
    /// `[e, ė]` of the range differences.
    rd: Vector2<f64>,
    /// The heading offset β (rad) the step headings carry, when it is a state.
    beta_rad: f64,
    /// Its σ at the start (rad); `None` when β is not a state.
    beta_sigma_rad: Option<f64>,
    /// The step-length scale error κ, when it is a state.
    kappa: f64,
    /// Its σ at the start; `None` when κ is not a state.
    kappa_sigma: Option<f64>,
    /// Covariance of `[x, y, e, ė, β]`.
    p: Matrix6,
    anchor: Option<Anchor>,
    last_t: Option<GpsTime>,
    /// Time of the last step and the walking velocity of that step (east, north m/s).
    last_step: Option<(GpsTime, Vector2<f64>)>,
    scratch: Vec<RangeMeasurement>,
    fixes: Vec<Fix>,
    latest: Option<Estimate>,
}

impl PdrEstimator {
    /// Dead reckoning in the world frame from `cfg.start_enu_m`, else `known_start_enu_m`
    /// (the world's surveyed start, e.g. its trajectory's first point), else the first fix.
    /// From GNSS batches it uses the `systems` (all when empty).
    ///
    /// # Errors
    /// A [`ConfigIssue`] for a bad setting.
    pub fn new(
        name: &str,
        cfg: &PdrFilterConfig,
        systems: &[System],
        frame: &EnuFrame,
        known_start_enu_m: Option<Vector3<f64>>,
    ) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        let start = cfg
            .start_enu_m
            .as_ref()
            .map(|s| Vector3::new(s[0], s[1], s.get(2).copied().unwrap_or(0.0)))
            .or(known_start_enu_m.filter(|s| s.iter().all(|v| v.is_finite())));
        let start_sigma_m = cfg.start_sigma_m;
        let beta_sigma_rad = cfg.heading_offset_sigma_deg.map(f64::to_radians);
        let mut p = Matrix6::zeros();
        p.fixed_view_mut::<2, 2>(0, 0)
            .copy_from(&(Matrix2::identity() * start_sigma_m * start_sigma_m));
        p[(4, 4)] = beta_sigma_rad.map_or(0.0, |s| s * s);
        p[(5, 5)] = cfg.step_scale_sigma.map_or(0.0, |s| s * s);
        Ok(Self {
            name: name.to_string(),
            cfg: cfg.clone(),
            frame: frame.clone(),
            systems: systems.to_vec(),
            start_sigma_m,
            pos_en_m: start.map(|s| s.xy()),
            up_m: start.map_or(0.0, |s| s.z),
            rd: Vector2::zeros(),
            beta_rad: 0.0,
            beta_sigma_rad,
            kappa: 0.0,
            kappa_sigma: cfg.step_scale_sigma,
            p,
            anchor: None,
            last_t: None,
            last_step: None,
            scratch: Vec::with_capacity(64),
            fixes: Vec::with_capacity(4),
            latest: None,
        })
    }

    /// The dead-reckoned position (east, north m), once started.
    pub fn position_en_m(&self) -> Option<Vector2<f64>> {
        self.pos_en_m
    }

    /// The horizontal covariance (m²).
    pub fn covariance_m2(&self) -> Matrix2<f64> {
        self.p.fixed_view::<2, 2>(0, 0).into_owned()
    }

    /// The estimated heading offset β and its σ (rad), when β is a state: the step
    /// headings are taken as ψ − β.
    pub fn heading_offset_rad(&self) -> Option<(f64, f64)> {
        self.beta_sigma_rad
            .map(|_| (self.beta_rad, self.p[(4, 4)].max(0.0).sqrt()))
    }

    /// The estimated step-length scale error κ and its σ, when κ is a state: the step
    /// lengths are taken as L/(1 + κ).
    pub fn step_scale(&self) -> Option<(f64, f64)> {
        self.kappa_sigma
            .map(|_| (self.kappa, self.p[(5, 5)].max(0.0).sqrt()))
    }

    /// The range-difference error states `[e, ė]` (m, m/s), once anchored.
    pub fn range_difference_error(&self) -> Option<Vector2<f64>> {
        self.anchor.map(|_| self.rd)
    }

    fn estimate(&self, t: GpsTime) -> Option<Estimate> {
        let pos = self.pos_en_m?;
        let mut cov = Matrix3::zeros();
        cov.fixed_view_mut::<2, 2>(0, 0)
            .copy_from(&self.covariance_m2());
        cov[(2, 2)] = self.start_sigma_m * self.start_sigma_m;
        Some(Estimate {
            t,
            pos_ecef_m: self
                .frame
                .ecef_of_enu(&Vector3::new(pos.x, pos.y, self.up_m)),
            vel_ecef_mps: None,
            cov_pos_m2: ecef_cov(&self.frame, &cov),
        })
    }

    /// Moves `[e, ė]` to time `t` (only once anchored: before, they are not in use).
    fn propagate_rd(&mut self, t: GpsTime) {
        let last = self.last_t.replace(t);
        let (Some(last), Some(_)) = (last, self.anchor) else {
            return;
        };
        let dt = t.seconds_since(last);
        if dt.is_nan() || dt <= 0.0 {
            return;
        }
        // Brown & Hwang's two-state clock noise, S_b = h₀/2, S_d = 2π² h₋₂, in metres.
        let c2 = crate::core::C_MPS * crate::core::C_MPS;
        let sb = self.cfg.range_difference_h0_s / 2.0 * c2;
        let sd = 2.0 * std::f64::consts::PI.powi(2) * self.cfg.range_difference_h_minus2_hz * c2;
        let qc = Matrix2::new(
            sb * dt + sd * dt.powi(3) / 3.0,
            sd * dt * dt / 2.0,
            sd * dt * dt / 2.0,
            sd * dt,
        );
        let mut phi = Matrix6::identity();
        phi[(2, 3)] = dt;
        let mut p = phi * self.p * phi.transpose();
        let block = p.fixed_view::<2, 2>(2, 2) + qc;
        p.fixed_view_mut::<2, 2>(2, 2).copy_from(&block);
        p[(2, 2)] += self.cfg.range_difference_multipath_m_per_sqrt_s.powi(2) * dt;
        self.rd.x += self.rd.y * dt;
        self.p = 0.5 * (p + p.transpose());
    }

    /// One step at `t`; false when it cannot be used (non-finite, negative length, no
    /// start yet).
    fn step(&mut self, s: &StepEvent, t: GpsTime) -> bool {
        let Some(pos) = self.pos_en_m else {
            return false;
        };
        let ok = [
            s.length_m,
            s.sigma_length_m,
            s.heading_rad,
            s.sigma_heading_rad,
        ]
        .iter()
        .all(|v| v.is_finite())
            && s.length_m >= 0.0
            && s.length_m < 10.0;
        if !ok {
            return false;
        }
        let (sn, cs) = (s.heading_rad - self.beta_rad).sin_cos();
        // The length corrected for the scale error, L/(1 + κ̂) (κ̂ stays 0 when κ is no
        // state; it is kept above −0.9 so the division cannot blow up).
        let l = s.length_m / (1.0 + self.kappa.max(-0.9));
        let new_pos = pos + Vector2::new(sn, cs) * l;
        let j = Matrix2::new(sn, l * cs, cs, -l * sn);
        let q = Matrix2::new(
            s.sigma_length_m * s.sigma_length_m,
            0.0,
            0.0,
            s.sigma_heading_rad * s.sigma_heading_rad,
        );
        let mut new_p = self.p;
        if self.beta_sigma_rad.is_some() || self.kappa_sigma.is_some() {
            // The position moves along ψ − β: ∂(x, y)/∂β = −L (cos, −sin); β is a
            // Gauss–Markov process of correlation time τ between steps.
            let dt = self
                .last_step
                .map_or(0.0, |(tp, _)| t.seconds_since(tp).clamp(0.0, 60.0));
            let phi_b = (-dt / self.cfg.heading_offset_time_constant_s).exp();
            let mut phi = Matrix6::identity();
            phi[(0, 4)] = -l * cs;
            phi[(1, 4)] = l * sn;
            phi[(4, 4)] = phi_b;
            // ∂(x, y)/∂κ = −L/(1 + κ̂) (sin, cos).
            let dl = -l / (1.0 + self.kappa.max(-0.9));
            phi[(0, 5)] = dl * sn;
            phi[(1, 5)] = dl * cs;
            new_p = phi * self.p * phi.transpose();
            let s0 = self.beta_sigma_rad.unwrap_or(0.0);
            new_p[(4, 4)] += s0 * s0 * (1.0 - phi_b * phi_b);
        }
        let new_pp = new_p.fixed_view::<2, 2>(0, 0) + j * q * j.transpose();
        new_p.fixed_view_mut::<2, 2>(0, 0).copy_from(&new_pp);
        if new_pos.iter().chain(new_p.iter()).all(|v| v.is_finite()) {
            self.pos_en_m = Some(new_pos);
            self.p = 0.5 * (new_p + new_p.transpose());
            // The walking velocity of this step, for range differences between steps.
            let vel = match self.last_step {
                Some((t_prev, _)) => {
                    let dt = t.seconds_since(t_prev);
                    if dt > 0.1 && dt < 2.0 {
                        Vector2::new(sn, cs) * (l / dt)
                    } else {
                        Vector2::zeros()
                    }
                }
                None => Vector2::zeros(),
            };
            self.last_step = Some((t, vel));
            true
        } else {
            false
        }
    }

    /// A horizontal position fix: initialises, or updates with H = [I₂ 0]. Returns (used,
    /// numerical failure).
    fn fix(&mut self, f: &Fix) -> PdrUpdate {
        let z = f.pos_enu_m.xy();
        let r: Matrix2<f64> = f.pos_cov_m2.fixed_view::<2, 2>(0, 0).into_owned();
        let Some(pos) = self.pos_en_m else {
            if r.cholesky().is_none() {
                return PdrUpdate::Refused;
            }
            self.pos_en_m = Some(z);
            self.up_m = f.pos_enu_m.z;
            let (var_beta, var_kappa) = (self.p[(4, 4)], self.p[(5, 5)]);
            self.p = Matrix6::zeros();
            self.p.fixed_view_mut::<2, 2>(0, 0).copy_from(&r);
            self.p[(4, 4)] = var_beta;
            self.p[(5, 5)] = var_kappa;
            self.anchor = None;
            self.rd = Vector2::zeros();
            return PdrUpdate::Anchored;
        };
        let s = self.p.fixed_view::<2, 2>(0, 0) + r;
        let Some(chol) = s.cholesky() else {
            return PdrUpdate::Refused;
        };
        let innov = z - pos;
        let nis = innov.dot(&chol.solve(&innov));
        if self.cfg.nis_gate.is_some_and(|g| nis > g) {
            return PdrUpdate::Gated {
                state_led: self.p[(0, 0)] + self.p[(1, 1)] >= r.trace(),
            };
        }
        // K = P Hᵀ S⁻¹ = (S⁻¹ H P)ᵀ, Joseph form.
        let hp: SMatrix<f64, 2, 6> = self.p.fixed_rows::<2>(0).into_owned();
        let k = chol.solve(&hp).transpose();
        let mut h = SMatrix::<f64, 2, 6>::zeros();
        h.fixed_view_mut::<2, 2>(0, 0)
            .copy_from(&Matrix2::identity());
        let ikh = Matrix6::identity() - k * h;
        let new_p = ikh * self.p * ikh.transpose() + k * r * k.transpose();
        let dx = k * innov;
        let new_pos = pos + dx.fixed_rows::<2>(0);
        if new_pos.iter().chain(new_p.iter()).all(|v| v.is_finite()) {
            self.pos_en_m = Some(new_pos);
            self.rd += dx.fixed_rows::<2>(2);
            self.beta_rad += dx[4];
            self.kappa += dx[5];
            self.p = 0.5 * (new_p + new_p.transpose());
            PdrUpdate::Used { nis, dof: 2 }
        } else {
            PdrUpdate::Failed
        }
    }

    /// A range difference: anchors on the first, then a scalar Joseph update. Returns
    /// (used, numerical failure).
    fn range_difference(&mut self, m: &RangeDifference, t: GpsTime) -> PdrUpdate {
        let Some(pos) = self.pos_en_m else {
            return PdrUpdate::Refused;
        };
        let offset = match self.last_step {
            Some((ts, v)) => {
                let dt = t.seconds_since(ts);
                if (0.0..2.0).contains(&dt) {
                    v * dt
                } else {
                    Vector2::zeros()
                }
            }
            None => Vector2::zeros(),
        };
        let pos_now = pos + offset;
        let sigma = m.sigma_m.hypot(self.cfg.range_difference_sigma_floor_m);
        if !(m.delta_range_m.is_finite() && m.sigma_m.is_finite() && m.sigma_m > 0.0)
            || m.emitter_pos_ecef_m.iter().any(|v| !v.is_finite())
        {
            return PdrUpdate::Refused;
        }
        let tower = self.frame.enu_of_ecef(&m.emitter_pos_ecef_m);
        let anchor = match self.anchor {
            Some(a) if a.emitter == m.emitter => a,
            Some(_) => return PdrUpdate::Refused,
            None => {
                let d = Vector3::new(pos_now.x, pos_now.y, self.up_m) - tower;
                let n = d.norm();
                if n.is_nan() || n <= 1.0 {
                    return PdrUpdate::Refused;
                }
                let u = Vector2::new(d.x / n, d.y / n);
                let pp: Matrix2<f64> = self.p.fixed_view::<2, 2>(0, 0).into_owned();
                let pu = pp * u;
                let (h0, hm2) = (
                    self.cfg.range_difference_h0_s,
                    self.cfg.range_difference_h_minus2_hz,
                );
                let t_cal = self.cfg.range_difference_calibration_s;
                let var_rate = crate::core::C_MPS.powi(2)
                    * (h0 / (2.0 * t_cal) + 2.0 * std::f64::consts::PI.powi(2) * hm2 * t_cal / 3.0);
                self.rd = Vector2::zeros();
                // e = −uᵀ δp at the anchor, so it correlates with β as the position does.
                let mut p = Matrix6::zeros();
                p.fixed_view_mut::<2, 2>(0, 0).copy_from(&pp);
                for j in 4..6 {
                    let pb = Vector2::new(self.p[(0, j)], self.p[(1, j)]);
                    p[(0, j)] = pb.x;
                    p[(1, j)] = pb.y;
                    p[(j, 0)] = pb.x;
                    p[(j, 1)] = pb.y;
                    p[(2, j)] = -u.dot(&pb);
                    p[(j, 2)] = -u.dot(&pb);
                }
                p.fixed_view_mut::<2, 2>(4, 4)
                    .copy_from(&self.p.fixed_view::<2, 2>(4, 4));
                p[(0, 2)] = -pu.x;
                p[(1, 2)] = -pu.y;
                p[(2, 0)] = -pu.x;
                p[(2, 1)] = -pu.y;
                p[(2, 2)] = u.dot(&pu) + sigma * sigma;
                p[(3, 3)] = var_rate;
                self.p = p;
                let a = Anchor {
                    emitter: m.emitter,
                    tower_enu_m: tower,
                    r0_m: n - m.delta_range_m,
                };
                self.anchor = Some(a);
                return PdrUpdate::Anchored;
            }
        };
        let model = RangeDifferenceModel {
            tower_enu_m: anchor.tower_enu_m,
            up_m: self.up_m,
            r0_m: anchor.r0_m,
            offset_en_m: offset,
            sigma_m: sigma,
        };
        let x = SVector::<f64, 4>::new(pos.x, pos.y, self.rd.x, self.rd.y);
        let mut h = SMatrix::<f64, 1, 6>::zeros();
        h.fixed_view_mut::<1, 4>(0, 0)
            .copy_from(&model.jacobian(&x));
        let nu = m.delta_range_m - model.h(&x)[0];
        let ph = self.p * h.transpose();
        let s = (h * ph)[(0, 0)] + sigma * sigma;
        if !(s.is_finite() && s > 0.0) {
            return PdrUpdate::Failed;
        }
        let k = ph / s;
        let ikh = Matrix6::identity() - k * h;
        let new_p = ikh * self.p * ikh.transpose() + k * k.transpose() * (sigma * sigma);
        let dx = k * nu;
        if dx.iter().chain(new_p.iter()).all(|v| v.is_finite()) {
            self.pos_en_m = Some(pos + dx.fixed_rows::<2>(0));
            self.rd += dx.fixed_rows::<2>(2);
            self.beta_rad += dx[4];
            self.kappa += dx[5];
            self.p = 0.5 * (new_p + new_p.transpose());
            PdrUpdate::Used {
                nis: nu * nu / s,
                dof: 1,
            }
        } else {
            PdrUpdate::Failed
        }
    }
}

/// What the PDR filter did with one fix or range difference.
#[derive(Clone, Copy, Debug, PartialEq)]
enum PdrUpdate {
    /// A Kalman update with its normalised innovation squared and dimension.
    Used { nis: f64, dof: u32 },
    /// The measurement started the filter (the first fix) or its range-difference anchor.
    Anchored,
    /// The innovation gate refused it as an outlier; `state_led` when the filter's own
    /// position variance was at least the fix's (by trace).
    Gated { state_led: bool },
    /// Invalid input, or no filter state to update yet.
    Refused,
    /// The update produced a non-finite state or covariance, which was not kept.
    Failed,
}

impl PdrUpdate {
    /// Tallies `n` measurements (a fix counts the ranges it came from) into `out`.
    fn tally(self, n: u32, out: &mut EpochOutcome) {
        match self {
            PdrUpdate::Used { nis, dof } => {
                out.used += n;
                out.record_nis(nis, dof);
            }
            PdrUpdate::Anchored => out.used += n,
            PdrUpdate::Gated { state_led } => {
                out.rejected += n;
                out.rejected_gate += n;
                if state_led {
                    out.rejected_gate_state_led += n;
                }
            }
            PdrUpdate::Refused => out.rejected += n,
            PdrUpdate::Failed => {
                out.rejected += n;
                out.numerical_failure = true;
            }
        }
    }
}

impl Estimator for PdrEstimator {
    fn name(&self) -> &str {
        &self.name
    }

    fn consumes(&self, source: SourceKind) -> bool {
        source == SourceKind::Pdr
            || self.cfg.fix_sources.contains(&source)
            || self.cfg.range_difference_sources.contains(&source)
    }

    fn process(&mut self, batch: &MeasurementBatch) -> EpochOutcome {
        let mut out = EpochOutcome::default();
        if !self.cfg.range_difference_sources.is_empty() {
            self.propagate_rd(batch.t);
        }
        if batch.source == SourceKind::Pdr {
            for m in &batch.items {
                if let Measurement::Step(s) = m {
                    if self.step(s, batch.t) {
                        out.used += 1;
                    } else {
                        out.rejected += 1;
                    }
                }
            }
        } else if self.cfg.range_difference_sources.contains(&batch.source) {
            for m in &batch.items {
                if let Measurement::RangeDifference(rd) = m {
                    self.range_difference(rd, batch.t).tally(1, &mut out);
                }
            }
        }
        if self.cfg.fix_sources.contains(&batch.source) {
            let near = self.latest.map(|e| e.pos_ecef_m);
            let mut fixes = std::mem::take(&mut self.fixes);
            fixes_of_batch(
                batch,
                0.0,
                &self.frame,
                &self.systems,
                false,
                near,
                &mut self.scratch,
                &mut fixes,
                &mut out.rejected,
                &mut out.gdop,
            );
            for f in &fixes {
                self.fix(f).tally(f.n, &mut out);
            }
            self.fixes = fixes;
        }
        self.latest = self.estimate(batch.t);
        out.estimate = self.latest;
        out
    }

    fn latest(&self) -> Option<Estimate> {
        self.latest
    }

    /// Dead reckoning restarts from the next fix, with the start's uncertainty.
    fn reset(&mut self) {
        self.pos_en_m = None;
        self.p = Matrix6::zeros();
        self.p
            .fixed_view_mut::<2, 2>(0, 0)
            .copy_from(&(Matrix2::identity() * self.start_sigma_m * self.start_sigma_m));
        self.p[(4, 4)] = self.beta_sigma_rad.map_or(0.0, |s| s * s);
        self.beta_rad = 0.0;
        self.p[(5, 5)] = self.kappa_sigma.map_or(0.0, |s| s * s);
        self.kappa = 0.0;
        self.anchor = None;
        self.rd = Vector2::zeros();
        self.last_step = None;
        self.latest = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::Geodetic;
    use crate::measurement::PositionFix;

    fn frame() -> EnuFrame {
        EnuFrame::new(Geodetic::from_deg(30.55, 114.27, 25.0))
    }

    #[test]
    fn pdr_steps_a_square_and_a_fix_pulls_it() {
        let f = frame();
        let cfg = PdrFilterConfig {
            fix_sources: vec![SourceKind::Fm],
            ..Default::default()
        };
        let mut est =
            PdrEstimator::new("PDR", &cfg, &[], &f, Some(Vector3::new(1.0, 2.0, 0.0))).unwrap();
        let mut batch = MeasurementBatch {
            unscored: false,
            raw: None,
            source: SourceKind::Pdr,
            ..Default::default()
        };
        // Four sides of 10 steps of 0.5 m: back to the start.
        for side in 0..4 {
            for _ in 0..10 {
                batch.items = vec![Measurement::Step(StepEvent {
                    length_m: 0.5,
                    sigma_length_m: 0.05,
                    heading_rad: side as f64 * std::f64::consts::FRAC_PI_2,
                    sigma_heading_rad: 0.05,
                })];
                let o = est.process(&batch);
                assert_eq!(o.used, 1);
            }
        }
        let p = est.position_en_m().unwrap();
        assert!((p - Vector2::new(1.0, 2.0)).norm() < 1e-9, "{p}");
        // Covariance: start 0.25 m² per axis + Σ over steps of σ_L² along and (L σ_ψ)²
        // across the step: each axis gets 20 along-track and 20 cross-track terms.
        let expect = 0.25 + 20.0 * 0.05f64.powi(2) + 20.0 * (0.5f64 * 0.05).powi(2);
        assert!((est.covariance_m2()[(0, 0)] - expect).abs() < 1e-12);
        // A fix 4 m east with σ² equal to P: the estimate moves halfway.
        let fix_enu = Vector3::new(5.0, 2.0, 0.0);
        let pe = est.covariance_m2()[(0, 0)];
        let mut cov = Matrix3::identity() * pe;
        cov[(2, 2)] = 1.0;
        let b = MeasurementBatch {
            unscored: false,
            raw: None,
            source: SourceKind::Fm,
            items: vec![Measurement::Position(PositionFix {
                pos_ecef_m: f.ecef_of_enu(&fix_enu),
                cov_m2: ecef_cov(&f, &cov),
                support: 0,
            })],
            ..Default::default()
        };
        let o = est.process(&b);
        assert_eq!((o.used, o.rejected), (1, 0));
        let p = est.position_en_m().unwrap();
        assert!((p - Vector2::new(3.0, 2.0)).norm() < 1e-6, "{p}");
        // Bad steps are rejected, never NaN.
        batch.items = vec![Measurement::Step(StepEvent {
            length_m: f64::NAN,
            sigma_length_m: 0.05,
            heading_rad: 0.0,
            sigma_heading_rad: 0.05,
        })];
        let o = est.process(&batch);
        assert_eq!(o.rejected, 1);
        assert!(o.estimate.unwrap().pos_ecef_m.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn range_difference_jacobian_matches_finite_differences() {
        let m = RangeDifferenceModel {
            tower_enu_m: Vector3::new(600.0, -160.0, 240.0),
            up_m: 1.2,
            r0_m: 688.2,
            offset_en_m: Vector2::new(0.3, -0.1),
            sigma_m: 0.05,
        };
        for x in [
            SVector::<f64, 4>::new(0.0, 0.0, 0.0, 0.0),
            SVector::<f64, 4>::new(36.0, 22.0, 1.3, -0.01),
            SVector::<f64, 4>::new(-10.0, 40.0, -2.0, 0.02),
        ] {
            let j = m.jacobian(&x);
            for i in 0..4 {
                let h = 1e-4;
                let mut a = x;
                let mut b = x;
                a[i] += h;
                b[i] -= h;
                let fd = (m.h(&a)[0] - m.h(&b)[0]) / (2.0 * h);
                assert!(
                    (fd - j[(0, i)]).abs() < 1e-8,
                    "∂h/∂x{i}: {fd} vs {}",
                    j[(0, i)]
                );
            }
        }
    }

    #[test]
    fn fusing_range_differences_reduces_the_error_against_the_truth() {
        // A walker heads north at 1 m/s (steps of 0.5 m every 0.5 s) for 120 s with a
        // heading error of 0.2 rad per step (the σ the filter is told), so the PDR drifts
        // across the track, east, along the line to a tower 600 m east. The range
        // differences carry the error of an OCXO-referenced receiver (the clock's phase
        // wander about its frequency at the start, Brown & Hwang's OCXO, the filter's
        // default model) plus 2 mm of white noise. Over 20 seeded walks the RMS horizontal
        // error against the truth must fall when they are fused.
        use crate::core::receiver_clock::{ClockConfig, ClockTrack, Oscillator, ReceiverClock};
        use rand_distr::{Distribution, Normal};
        let f = frame();
        let tower = Vector3::new(600.0, 0.0, 200.0);
        let start = GpsTime::from_week_tow(2300, 0.0);
        let p0 = Vector3::new(0.0, 0.0, 1.2);
        let (mut sum_without, mut sum_with, mut n) = (0.0, 0.0, 0usize);
        for seed in 0..20u64 {
            let rng = crate::core::TrialRng::new(seed, 0);
            let clock_cfg = ClockConfig {
                oscillator: Oscillator::Ocxo,
                ..ClockConfig::default()
            };
            let clock = ClockTrack::record(
                ReceiverClock::new(&clock_cfg, &mut rng.stream("clock")),
                130.0,
                0.1,
                &mut rng.stream("clock/track"),
            );
            let mut heading = rng.stream("heading");
            let mut white = rng.stream("white");
            let heading_err: Vec<f64> = (0..240)
                .map(|_| Normal::new(0.0, 0.2).unwrap().sample(&mut heading))
                .collect();
            for fuse in [false, true] {
                let cfg = PdrFilterConfig {
                    range_difference_sources: if fuse { vec![SourceKind::Dtmb] } else { vec![] },
                    ..Default::default()
                };
                let mut est = PdrEstimator::new("PDR", &cfg, &[], &f, Some(p0)).unwrap();
                let mut sq = 0.0;
                for k in 1..=240usize {
                    let t = k as f64 * 0.5;
                    let step = MeasurementBatch {
                        t: start.add_seconds(t),
                        source: SourceKind::Pdr,
                        items: vec![Measurement::Step(StepEvent {
                            length_m: 0.5,
                            sigma_length_m: 0.05,
                            heading_rad: heading_err[k - 1],
                            sigma_heading_rad: 0.2,
                        })],
                        ..Default::default()
                    };
                    est.process(&step);
                    if k % 2 != 0 {
                        continue;
                    }
                    let truth = Vector3::new(0.0, t, 1.2);
                    let r = (truth - tower).norm() - (p0 - tower).norm();
                    let osc = crate::core::C_MPS
                        * (clock.bias_s(t) - clock.bias_s(0.0) - clock.drift_s_per_s(0.0) * t);
                    let w: f64 = 0.002 * Normal::new(0.0, 1.0).unwrap().sample(&mut white);
                    let b = MeasurementBatch {
                        t: start.add_seconds(t),
                        source: SourceKind::Dtmb,
                        items: vec![Measurement::RangeDifference(RangeDifference {
                            emitter: crate::core::EmitterId {
                                system: System::Dtmb,
                                number: 1,
                            },
                            emitter_pos_ecef_m: f.ecef_of_enu(&tower),
                            t0: start,
                            delta_range_m: r + osc + w,
                            sigma_m: 0.002,
                        })],
                        ..Default::default()
                    };
                    let o = est.process(&b);
                    assert_eq!(o.used, u32::from(fuse));
                    let e = est.position_en_m().unwrap() - truth.xy();
                    sq += e.norm_squared();
                    if fuse {
                        n += 1;
                    }
                }
                if fuse {
                    sum_with += sq;
                } else {
                    sum_without += sq;
                }
            }
        }
        let (without, with) = (
            (sum_without / n as f64).sqrt(),
            (sum_with / n as f64).sqrt(),
        );
        println!("RMS horizontal error over 20 walks: PDR {without:.2} m, PDR + Δr {with:.2} m");
        assert!(without > 0.5, "{without}");
        assert!(with < 0.7 * without, "{with} vs {without}");
    }

    /// One synthetic walk of a square loop (10 m sides, 0.5 m steps every 0.5 s) whose step
    /// headings carry a heading offset β (a Gauss–Markov process of σ `beta_sigma`, τ
    /// `tau_s`, or constant when `tau_s` is infinite) plus white noise, and whose lengths
    /// carry a scale error (1 + κ) plus white noise; a position fix of σ 0.5 m every
    /// `fix_every` steps. Returns the filter and the per-epoch 2-D NEES of its position
    /// after each step.
    #[allow(clippy::too_many_arguments)]
    fn synthetic_walk(
        seed: u64,
        cfg: &PdrFilterConfig,
        beta0_rad: f64,
        beta_sigma_rad: f64,
        tau_s: f64,
        kappa: f64,
        steps: usize,
        fix_every: usize,
    ) -> (PdrEstimator, Vec<f64>) {
        use rand_distr::{Distribution, StandardNormal};
        let f = frame();
        let rng = crate::core::TrialRng::new(seed, 0);
        let mut noise = rng.stream("walk");
        let mut g = move || -> f64 { StandardNormal.sample(&mut noise) };
        let start = GpsTime::from_week_tow(2300, 0.0);
        let mut est = PdrEstimator::new("PDR", cfg, &[], &f, Some(Vector3::zeros())).unwrap();
        let (sig_l, sig_psi, sig_fix) = (0.02, 0.02, 0.5);
        let mut truth = Vector2::zeros();
        let mut beta = beta0_rad;
        let phi = (-0.5 / tau_s).exp();
        let mut nees = Vec::with_capacity(steps);
        for k in 0..steps {
            let t = start.add_seconds(0.5 * (k + 1) as f64);
            // Counter-clockwise square: east, north, west, south, 20 steps a side.
            let psi =
                ((k / 20) % 4) as f64 * -std::f64::consts::FRAC_PI_2 + std::f64::consts::FRAC_PI_2;
            truth += Vector2::new(psi.sin(), psi.cos()) * 0.5;
            beta = phi * beta + (1.0 - phi * phi).sqrt() * beta_sigma_rad * g();
            let step = MeasurementBatch {
                t,
                source: SourceKind::Pdr,
                items: vec![Measurement::Step(StepEvent {
                    length_m: 0.5 * (1.0 + kappa) + sig_l * g(),
                    sigma_length_m: sig_l,
                    heading_rad: psi + beta + sig_psi * g(),
                    sigma_heading_rad: sig_psi,
                })],
                ..Default::default()
            };
            est.process(&step);
            if (k + 1) % fix_every == 0 {
                let z = Vector3::new(truth.x + sig_fix * g(), truth.y + sig_fix * g(), 0.0);
                let cov = Matrix3::from_diagonal(&Vector3::new(
                    sig_fix * sig_fix,
                    sig_fix * sig_fix,
                    1.0,
                ));
                let b = MeasurementBatch {
                    t,
                    source: SourceKind::Fm,
                    items: vec![Measurement::Position(PositionFix {
                        pos_ecef_m: f.ecef_of_enu(&z),
                        cov_m2: ecef_cov(&f, &cov),
                        support: 0,
                    })],
                    ..Default::default()
                };
                est.process(&b);
            }
            let e = est.position_en_m().unwrap() - truth;
            let pinv = est.covariance_m2().try_inverse().unwrap();
            nees.push(e.dot(&(pinv * e)));
        }
        (est, nees)
    }

    #[test]
    fn a_constant_heading_offset_and_step_scale_are_learnt_from_fixes() {
        // Truth: β = 6° and κ = +6 % for the whole walk (τ infinite); the filter is told
        // σ_β = 10°, σ_κ = 8 %. After two laps with a fix every 10 steps its estimates
        // must hold the truth within 3σ, and σ must have shrunk to under half the prior.
        let cfg = PdrFilterConfig {
            fix_sources: vec![SourceKind::Fm],
            heading_offset_sigma_deg: Some(10.0),
            heading_offset_time_constant_s: 1.0e7,
            step_scale_sigma: Some(0.08),
            ..Default::default()
        };
        let (beta, kappa) = (6f64.to_radians(), 0.06);
        for seed in 0..10 {
            let (est, _) = synthetic_walk(seed, &cfg, beta, 0.0, f64::INFINITY, kappa, 160, 10);
            let (b, sb) = est.heading_offset_rad().unwrap();
            let (kk, sk) = est.step_scale().unwrap();
            assert!(sb < 1.5f64.to_radians(), "σ_β {}°", sb.to_degrees());
            assert!(sk < 0.04, "σ_κ {sk}");
            assert!(
                (b - beta).abs() < 3.0 * sb,
                "seed {seed}: β̂ {:.2}° ± {:.2}° vs 6°",
                b.to_degrees(),
                sb.to_degrees()
            );
            assert!(
                (kk - kappa).abs() < 3.0 * sk,
                "seed {seed}: κ̂ {kk} ± {sk} vs 0.06"
            );
        }
        // Without the states the same walk's last error is far outside the filter's σ.
        let old = PdrFilterConfig {
            fix_sources: vec![SourceKind::Fm],
            ..Default::default()
        };
        let (_, nees_old) = synthetic_walk(0, &old, beta, 0.0, f64::INFINITY, kappa, 160, 10);
        let mean_old = nees_old.iter().sum::<f64>() / nees_old.len() as f64;
        assert!(mean_old > 10.0, "mean NEES without states {mean_old}");
    }

    #[test]
    fn the_filter_nees_over_many_walks_is_within_its_chi_square_band() {
        // The truth follows the filter's own model: β a Gauss–Markov process of σ 5°,
        // τ 60 s, drawn at the start from its prior; κ ~ N(0, 0.08²); fixes every 40 steps.
        // The 2-D position NEES after the last step (independent across walks) must
        // average 2: over 200 walks the mean of χ²(2) has σ 2/√200 = 0.14, so the 99 %
        // band is 2 ± 0.37.
        let cfg = PdrFilterConfig {
            fix_sources: vec![SourceKind::Fm],
            heading_offset_sigma_deg: Some(5.0),
            heading_offset_time_constant_s: 60.0,
            step_scale_sigma: Some(0.08),
            ..Default::default()
        };
        use rand_distr::{Distribution, StandardNormal};
        let (n, mut last, mut mid) = (200u64, 0.0, 0.0);
        for seed in 0..n {
            let mut prior = crate::core::TrialRng::new(seed, 1).stream("prior");
            let b0: f64 = StandardNormal.sample(&mut prior);
            let k0: f64 = StandardNormal.sample(&mut prior);
            let (_, nees) = synthetic_walk(
                seed,
                &cfg,
                5f64.to_radians() * b0,
                5f64.to_radians(),
                60.0,
                0.08 * k0,
                235,
                40,
            );
            last += nees[234];
            mid += nees[99];
        }
        let (last, mid) = (last / n as f64, mid / n as f64);
        println!("mean NEES over {n} walks: step 100 {mid:.3}, step 235 {last:.3}");
        assert!((last - 2.0).abs() < 0.37, "{last}");
        assert!((mid - 2.0).abs() < 0.37, "{mid}");
    }
}
