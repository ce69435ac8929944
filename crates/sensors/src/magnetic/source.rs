//! Magnetic landmarks as a measurement source (`"magnetic"`): position fixes when the
//! walker passes a landmark the matcher recognises (seed 002 §2 and §4.1).
//!
//! Built per trial:
//!
//! 1. **Survey** (once per master seed, the same for every trial): the world's trajectory
//!    walked with a survey magnetometer (stream `magnetic/survey` of trial 0's streams,
//!    which no trial source uses); its windows whose centre lies within
//!    `label_tolerance_m` of a landmark become that landmark's templates (DTW library) or
//!    training images (spiking network).
//! 2. **Trial walk**: the trial's trajectory with the phone's magnetometer (noise, hard and
//!    soft iron; stream `magnetic/mag`) at `rate_hz`; windows, features, candidates.
//! 3. **Selection**: with `dtmb_check`, the best candidate whose landmark is consistent
//!    with a DTMB range to the world's first DTMB tower, `| ‖P_i − P_base‖ − r_dtmb | <
//!    δr` (§4.1); the range is the true range plus N(0, σ²) (stream `magnetic/dtmb`), the
//!    error of seed 002's TPS ranging, since the ranging itself is a separate source.
//! 4. Each accepted detection is a `Measurement::Position` at the landmark's position,
//!    with `R = diag(σ_fix², σ_fix², σ_up²)` in ENU, delivered at the time of the window's
//!    centre (when the walker passed the landmark; the half-window latency of an online
//!    detector is not modelled).
//!
//! The whole walk is processed when the source is built (the detector looks at complete
//! windows), so the source only replays the detections at their times.

use super::anomaly::{MagneticAnomalyConfig, MagneticScene, MagneticWalk};
use super::earth::EarthField;
use super::landmark::{
    augmented_features, extract_windows, select_by_dtmb, Candidate, DtwLibrary, DtwScratch,
    LandmarkDetectorConfig, LandmarkFeature, LandmarkWindow,
};
use super::snn::{SnnClassifier, SnnConfig, SnnScratch};
use crate::core::config::check;
use crate::core::{ConfigIssue, EnuFrame, GpsTime, SimTime, TrialRng};
use crate::inertial::attitude::{PlatformConfig, PlatformTruth};
use crate::inertial::magnetometer::{Magnetometer, MagnetometerConfig};
use crate::measurement::{
    Measurement, MeasurementBatch, PositionFix, SampleContext, Source, SourceKind,
};
use crate::motion::Trajectory;
use nalgebra::{Matrix3, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;
use serde::Deserialize;

/// Which matcher names the landmark.
#[derive(
    Clone, Copy, Debug, Deserialize, PartialEq, Eq, Default, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Matcher {
    /// Dynamic time warping against the survey's templates (the paper's baseline).
    #[default]
    Dtw,
    /// The spiking neural network (Tempotron neurons, one per landmark).
    Snn,
}

/// `dtmb_check = { enabled, sigma_m, delta_r_m }`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct DtmbCheck {
    /// Apply the check; default true (`dtmb_check = { enabled = false }` takes the best
    /// candidate as it is).
    pub enabled: bool,
    /// σ of the DTMB range (m); default 2.65 (seed 002's median error 1.79 m = 0.674 σ).
    pub sigma_m: f64,
    /// δr (m); default 8 (three σ).
    pub delta_r_m: f64,
}

impl Default for DtmbCheck {
    fn default() -> Self {
        Self {
            enabled: true,
            sigma_m: 2.65,
            delta_r_m: 8.0,
        }
    }
}

/// `[sensors.magnetic]`.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct MagneticSensorConfig {
    /// Magnetometer rate (Hz); default 50.
    pub rate_hz: f64,
    /// The phone's magnetometer (noise, hard and soft iron).
    pub magnetometer: MagnetometerConfig,
    /// The survey's magnetometer; default: the same model with no iron and 0.3 µT noise.
    pub survey_magnetometer: Option<MagnetometerConfig>,
    /// Window detection and imaging.
    pub detector: LandmarkDetectorConfig,
    /// `dtw` (default) or `snn`.
    pub matcher: Matcher,
    /// DTW: Sakoe–Chiba band (cells) and acceptance threshold (mean µT); default 4, 0.8.
    pub dtw_band: usize,
    /// DTW: the acceptance threshold (mean µT per cell); default 0.8.
    pub dtw_threshold_ut: f64,
    /// The spiking network's settings (`matcher = "snn"`).
    pub snn: SnnConfig,
    /// Survey windows within this horizontal distance of a landmark label it (m); default 3.
    pub label_tolerance_m: f64,
    /// Seed 002 §4.1's DTMB consistency check; default on.
    pub dtmb_check: DtmbCheck,
    /// σ of a landmark fix, horizontal and vertical (m); default 1.5 and 5.
    pub fix_sigma_m: f64,
    /// Vertical σ of a landmark fix (m); default 5.
    pub fix_sigma_up_m: f64,
}

impl Default for MagneticSensorConfig {
    fn default() -> Self {
        Self {
            rate_hz: 50.0,
            magnetometer: MagnetometerConfig::default(),
            survey_magnetometer: None,
            detector: LandmarkDetectorConfig::default(),
            matcher: Matcher::Dtw,
            dtw_band: 4,
            dtw_threshold_ut: 0.8,
            snn: SnnConfig::default(),
            label_tolerance_m: 3.0,
            dtmb_check: DtmbCheck::default(),
            fix_sigma_m: 1.5,
            fix_sigma_up_m: 5.0,
        }
    }
}

impl MagneticSensorConfig {
    /// Checks every value; the key is the field's path.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        check(
            "rate_hz",
            self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 1000.0,
            || format!("expected a rate in (0, 1000] Hz, got {}", self.rate_hz),
        )?;
        let sub = |t: &str, c: ConfigIssue| ConfigIssue::new(format!("{t}.{}", c.key), c.message);
        self.magnetometer
            .validate()
            .map_err(|c| sub("magnetometer", c))?;
        if let Some(m) = &self.survey_magnetometer {
            m.validate().map_err(|c| sub("survey_magnetometer", c))?;
        }
        self.detector.validate().map_err(|c| sub("detector", c))?;
        self.snn.validate().map_err(|c| sub("snn", c))?;
        check("dtw_band", self.dtw_band >= 1, || {
            "expected at least 1 cell".into()
        })?;
        for (k, v) in [
            ("dtw_threshold_ut", self.dtw_threshold_ut),
            ("label_tolerance_m", self.label_tolerance_m),
            ("fix_sigma_m", self.fix_sigma_m),
            ("fix_sigma_up_m", self.fix_sigma_up_m),
        ] {
            check(k, v.is_finite() && v > 0.0, || {
                format!("expected a finite value > 0, got {v}")
            })?;
        }
        let d = &self.dtmb_check;
        if d.enabled {
            check(
                "dtmb_check.sigma_m",
                d.sigma_m.is_finite() && d.sigma_m >= 0.0,
                || format!("expected a σ ≥ 0, got {}", d.sigma_m),
            )?;
            check(
                "dtmb_check.delta_r_m",
                d.delta_r_m.is_finite() && d.delta_r_m > 0.0,
                || format!("expected δr > 0, got {}", d.delta_r_m),
            )?;
        }
        Ok(())
    }
}

/// The decimal year of `t` (for the IGRF coefficients; a day's error is irrelevant).
pub fn decimal_year(t: GpsTime) -> f64 {
    let (y, mo, d, h, mi, s, _) = t.to_gpst_calendar();
    let start = GpsTime::from_gpst_calendar(y, 1, 1, 0, 0, 0, 0);
    let next = GpsTime::from_gpst_calendar(y + 1, 1, 1, 0, 0, 0, 0);
    let now = GpsTime::from_gpst_calendar(y, mo, d, h, mi, s, 0);
    f64::from(y) + now.seconds_since(start) / next.seconds_since(start)
}

/// What the trained matcher is.
enum Trained {
    Dtw(DtwLibrary),
    Snn(Box<SnnClassifier>),
}

/// One accepted detection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Detection {
    /// When the walker passed the landmark (s since the world start).
    pub t_s: f64,
    /// Index of the landmark in the world's anomaly list.
    pub label: usize,
    /// Where the walker truly was (ENU), for scoring only.
    pub true_pos_enu_m: Vector3<f64>,
}

/// The magnetic-landmark source.
pub struct MagneticSource {
    frame: EnuFrame,
    landmarks_enu_m: Vec<Vector3<f64>>,
    detections: Vec<Detection>,
    next: usize,
    cov_ecef_m2: Matrix3<f64>,
    survey_windows: usize,
    survey_labelled: usize,
    end: SimTime,
    /// The trial's magnetometer walk (times, body-frame readings, true positions), kept
    /// for a dataset export that asks for the raw samples.
    walk: MagneticWalk,
    /// The first walk sample not yet logged.
    walk_next: usize,
}

fn walk(
    scene: &MagneticScene,
    trajectory: Box<dyn Trajectory>,
    platform: &PlatformConfig,
    mag: &MagnetometerConfig,
    rate_hz: f64,
    rng: &TrialRng,
    prefix: &str,
) -> Result<MagneticWalk, ConfigIssue> {
    let truth = PlatformTruth::new(
        trajectory,
        platform,
        &mut rng.stream(&format!("{prefix}/gait")),
    )?;
    let mut m = Magnetometer::new(mag, rng.stream(&format!("{prefix}/mag")))?;
    scene
        .sample_walk(&truth, &mut m, rate_hz)
        .map_err(|e| ConfigIssue::new("rate_hz", e.to_string()))
}

fn windows_of(
    w: &MagneticWalk,
    cfg: &LandmarkDetectorConfig,
) -> Result<(Vec<f64>, Vec<LandmarkWindow>), ConfigIssue> {
    let (mut smoothed, mut windows) = (Vec::new(), Vec::new());
    extract_windows(&w.magnitude_ut, w.rate_hz, cfg, &mut smoothed, &mut windows)
        .map_err(|e| ConfigIssue::new("detector", e.to_string()))?;
    Ok((smoothed, windows))
}

impl MagneticSource {
    /// Builds the source: surveys with `survey_trajectory` (trial 0's path), walks
    /// `trajectory` (this trial's), detects and selects. `tower_enu_m` is the DTMB tower of
    /// the consistency check (required when `cfg.dtmb_check` is enabled).
    ///
    /// # Errors
    /// An invalid configuration or anomaly (the key names it), no anomaly, or a DTMB check
    /// without a tower.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        cfg: &MagneticSensorConfig,
        anomalies: &[MagneticAnomalyConfig],
        platform: &PlatformConfig,
        survey_trajectory: Box<dyn Trajectory>,
        trajectory: Box<dyn Trajectory>,
        frame: &EnuFrame,
        start: GpsTime,
        tower_enu_m: Option<Vector3<f64>>,
        rng: &TrialRng,
        end: SimTime,
    ) -> Result<Self, ConfigIssue> {
        cfg.validate()?;
        if anomalies.is_empty() {
            return Err(ConfigIssue::new(
                "magnetic_anomaly",
                "expected at least one [[scene.magnetic_anomaly]] to detect",
            ));
        }
        let earth = EarthField::igrf14(&frame.origin(), decimal_year(start))
            .map_err(|e| ConfigIssue::new("world.start", e.to_string()))?;
        let scene = MagneticScene::new(earth, anomalies)
            .map_err(|e| ConfigIssue::new("magnetic_anomaly", e.to_string()))?;
        let landmarks: Vec<Vector3<f64>> = anomalies
            .iter()
            .map(|a| Vector3::from(a.position_enu_m))
            .collect();
        let check = cfg.dtmb_check;
        let check_tower = match (check.enabled, tower_enu_m) {
            (true, Some(t)) => Some((check, t)),
            (true, None) => return Err(ConfigIssue::new(
                "dtmb_check",
                "needs a DTMB [[transmitter]] to range to (or `dtmb_check = { enabled = false }`)",
            )),
            (false, _) => None,
        };
        // The survey: one walk of the path, labelled by the landmarks nearby.
        let survey_rng = TrialRng::new(rng.master_seed(), 0);
        let survey_mag = cfg
            .survey_magnetometer
            .clone()
            .unwrap_or(MagnetometerConfig {
                noise_ut: 0.3,
                hard_iron_ut: [0.0; 3],
                ..cfg.magnetometer.clone()
            });
        let survey = walk(
            &scene,
            survey_trajectory,
            platform,
            &survey_mag,
            cfg.rate_hz,
            &survey_rng,
            "magnetic/survey",
        )?;
        let (smoothed, windows) = windows_of(&survey, &cfg.detector)?;
        let horizontal = |a: &Vector3<f64>, b: &Vector3<f64>| (a.x - b.x).hypot(a.y - b.y);
        let label_at = |p: &Vector3<f64>| {
            landmarks
                .iter()
                .enumerate()
                .filter(|(_, l)| horizontal(p, l) <= cfg.label_tolerance_m)
                .min_by(|a, b| horizontal(p, a.1).total_cmp(&horizontal(p, b.1)))
                .map(|(i, _)| i)
        };
        let bad = |k: &str, e: super::MagneticError| ConfigIssue::new(k, e.to_string());
        let mut dtw = DtwLibrary::new(landmarks.len(), cfg.dtw_band, cfg.dtw_threshold_ut)
            .map_err(|e| bad("dtw_band", e))?;
        let mut samples = Vec::new();
        let mut labelled = 0;
        let survey_windows = windows.len();
        // Where the surveyor was when passing each landmark: the position the database
        // gives a recognised landmark (the mean over its labelled windows).
        let mut sum = vec![(Vector3::<f64>::zeros(), 0usize); landmarks.len()];
        for w in &windows {
            let label = label_at(&survey.pos_enu_m[w.centre()]);
            labelled += usize::from(label.is_some());
            if let Some(l) = label {
                sum[l].0 += survey.pos_enu_m[w.centre()];
                sum[l].1 += 1;
            }
            for f in augmented_features(&smoothed, w, 0.1).map_err(|e| bad("detector", e))? {
                if let Some(l) = label {
                    dtw.add(l, &f).map_err(|e| bad("detector", e))?;
                }
                samples.push((label, f.image(cfg.detector.image_full_scale_ut)));
            }
        }
        let survey_height_m = survey.pos_enu_m.iter().map(|p| p.z).sum::<f64>()
            / survey.pos_enu_m.len().max(1) as f64;
        let positions: Vec<Vector3<f64>> = sum
            .iter()
            .zip(&landmarks)
            .map(|((p, n), l)| {
                if *n > 0 {
                    p / *n as f64
                } else {
                    Vector3::new(l.x, l.y, survey_height_m)
                }
            })
            .collect();
        let trained = match cfg.matcher {
            Matcher::Dtw => Trained::Dtw(dtw),
            Matcher::Snn => Trained::Snn(Box::new(
                SnnClassifier::train(
                    &samples,
                    landmarks.len(),
                    &cfg.snn,
                    &mut survey_rng.stream("magnetic/snn/train"),
                )
                .map_err(|e| bad("snn", e))?,
            )),
        };
        // The trial's walk and its detections.
        let trial = walk(
            &scene,
            trajectory,
            platform,
            &cfg.magnetometer,
            cfg.rate_hz,
            rng,
            "magnetic",
        )?;
        let (smoothed, windows) = windows_of(&trial, &cfg.detector)?;
        let mut range_rng = rng.stream("magnetic/dtmb");
        let (mut ds, mut ss) = (DtwScratch::default(), SnnScratch::default());
        let mut cands = Vec::<Candidate>::new();
        let mut detections = Vec::new();
        for w in &windows {
            let c = w.centre();
            let f = LandmarkFeature::from_window(&smoothed, w).map_err(|e| bad("detector", e))?;
            match &trained {
                Trained::Dtw(lib) => lib.candidates(&f, &mut ds, &mut cands),
                Trained::Snn(net) => net.candidates(
                    &f.image(cfg.detector.image_full_scale_ut),
                    &mut ss,
                    &mut cands,
                ),
            }
            let chosen = match check_tower {
                Some((chk, tower)) => {
                    let e: f64 = range_rng.sample(StandardNormal);
                    let r = (trial.pos_enu_m[c] - tower).norm() + chk.sigma_m * e;
                    select_by_dtmb(&cands, &positions, &tower, r.max(0.0), chk.delta_r_m)
                        .map_err(|e| bad("dtmb_check", e))?
                }
                None => cands.first().copied(),
            };
            if let Some(sel) = chosen {
                detections.push(Detection {
                    t_s: trial.t_s[c],
                    label: sel.label,
                    true_pos_enu_m: trial.pos_enu_m[c],
                });
            }
        }
        let r = frame.rotation();
        let cov_enu = Matrix3::from_diagonal(&Vector3::new(
            cfg.fix_sigma_m.powi(2),
            cfg.fix_sigma_m.powi(2),
            cfg.fix_sigma_up_m.powi(2),
        ));
        Ok(Self {
            frame: frame.clone(),
            landmarks_enu_m: positions,
            detections,
            next: 0,
            cov_ecef_m2: r.transpose() * cov_enu * r,
            survey_windows,
            survey_labelled: labelled,
            end,
            walk: trial,
            walk_next: 0,
        })
    }

    /// The detections this trial delivers, in time order.
    pub fn detections(&self) -> &[Detection] {
        &self.detections
    }

    /// The landmark positions the survey gives (ENU: where the surveyor passed each
    /// landmark), in the world's anomaly order.
    pub fn landmarks_enu_m(&self) -> &[Vector3<f64>] {
        &self.landmarks_enu_m
    }

    /// Windows of the survey walk, and how many of them a landmark labelled.
    pub fn window_counts(&self) -> (usize, usize) {
        (self.survey_windows, self.survey_labelled)
    }
}

impl Source for MagneticSource {
    fn kind(&self) -> SourceKind {
        SourceKind::Magnetic
    }

    fn first_sample(&self) -> SimTime {
        self.detections
            .first()
            .map_or(self.end, |d| SimTime::from_seconds(d.t_s))
    }

    fn sample(&mut self, ctx: &SampleContext<'_>, out: &mut MeasurementBatch) -> Option<SimTime> {
        out.t = ctx.truth.t;
        out.source = SourceKind::Magnetic;
        // Compared as the engine's integer times, so a detection is never missed by a
        // rounding of its time.
        while let Some(d) = self.detections.get(self.next) {
            if SimTime::from_seconds(d.t_s) > ctx.truth.sim {
                break;
            }
            let p = self.landmarks_enu_m[d.label];
            out.items.push(Measurement::Position(PositionFix {
                pos_ecef_m: self.frame.ecef_of_enu(&p),
                cov_m2: self.cov_ecef_m2,
                support: 1,
            }));
            self.next += 1;
        }
        let next = self
            .detections
            .get(self.next)
            .map(|d| SimTime::from_seconds(d.t_s))
            .filter(|t| *t < self.end);
        if let Some(raw) = out.raw.as_mut() {
            // The samples up to now; after the last detection, the rest of the walk, so
            // that a dataset holds the whole magnetometer record.
            let w = &self.walk;
            while self.walk_next < w.t_s.len()
                && (next.is_none() || SimTime::from_seconds(w.t_s[self.walk_next]) <= ctx.truth.sim)
            {
                let k = self.walk_next;
                raw.mag.push(crate::measurement::MagSample {
                    t_s: w.t_s[k],
                    b_body_ut: w.b_body_ut[k].into(),
                    true_pos_enu_m: w.pos_enu_m[k].into(),
                });
                self.walk_next += 1;
            }
        }
        next
    }
}
