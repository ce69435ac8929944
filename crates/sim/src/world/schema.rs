//! The serde schema of world files. Every table denies unknown keys, so a typo is an
//! error that names the key and its line, never a silently ignored setting.

use crate::core::receiver_clock::ClockConfig;
use crate::core::System;
use crate::dtmb::DtmbSensorConfig;
use crate::fusion::ekf11::Ekf11Config;
use crate::fusion::estimator::{EkfEstimator, WlsEstimator};
use crate::fusion::family::{FamilyConfig, FamilyEstimator, FamilyKind};
use crate::fusion::mode::FuzzyConfig;
use crate::fusion::paper::{PaperContext, PaperFilter, ProcessSpec};
use crate::fusion::preprocess::ClockCorrectionConfig;
use crate::fusion::selection::{ModeSelection, SelectionKind};
use crate::gnss::measurement::GnssConfig;
use crate::inertial::attitude::{Platform, PlatformConfig};
use crate::inertial::imu::ImuConfig;
use crate::inertial::ins_estimator::{InsEstimator, InsFilterConfig};
use crate::inertial::pdr_estimator::{PdrEstimator, PdrFilterConfig};
use crate::inertial::source::PdrSensorConfig;
use crate::measurement::{Estimator, SourceKind};
use crate::motion::TrajectoryConfig;
use crate::tcofdm::TcofdmSensorConfig;
use crate::world::scene::{SceneSection, TransmitterSpec};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// The most trials one run takes (world file or `--trials`). Memory does not grow with
/// the count, as the outputs are streamed (a merge's plan keeps 4 bytes per trial); the
/// bound stops a typo of a few extra digits from starting a run of centuries.
pub const MAX_TRIALS: u64 = 100_000_000;

/// A whole world file.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WorldFile {
    pub world: WorldSection,
    pub platform: PlatformSection,
    #[serde(default)]
    pub receiver: ReceiverSection,
    #[serde(default)]
    pub sensors: SensorsSection,
    #[serde(default)]
    pub scene: Option<SceneSection>,
    #[serde(default, rename = "transmitter")]
    pub transmitters: Vec<TransmitterSpec>,
    #[serde(default)]
    pub shielding: Vec<ShieldingSpec>,
    #[serde(
        default,
        rename = "estimator",
        deserialize_with = "estimators_with_presets"
    )]
    #[schemars(with = "Vec<EstimatorTable>")]
    pub estimators: Vec<EstimatorSpec>,
    #[serde(default)]
    pub montecarlo: MonteCarloSection,
    #[serde(default)]
    pub scoring: ScoringSection,
    /// What the estimators of the world's comparison share (`world::comparison`).
    #[serde(default)]
    pub comparison: Option<crate::world::comparison::ComparisonSection>,
}

/// `[scoring]`: when every estimator of the world is scored (one record per estimator per
/// instant, the same instants for all; see `engine::trial::Scoring`).
#[derive(Clone, Debug, Default, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ScoringSection {
    /// A fixed scoring rate (Hz) from the start of the trial. Without it, the instants are
    /// the epochs of the `sources` below.
    #[serde(default)]
    #[schemars(range(min = 1e-3, max = 1e3))]
    pub rate_hz: Option<f64>,
    /// The sources whose epochs are the scoring instants; by default the GNSS receiver's
    /// (or seeds 001/003's emitters'), and every source's when the world has neither.
    #[serde(default)]
    pub sources: Option<Vec<crate::measurement::SourceKind>>,
    /// Seconds an estimate stays *available* after its estimator last used a measurement
    /// (default 10 s); older estimates are scored as coasting.
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 86_400.0))]
    pub coast_limit_s: Option<f64>,
    /// The interval Δ (s) of the relative pose error (default 1 s, as seed 000 and the
    /// TUM benchmark use): every pair of scoring instants Δ apart is one RPE sample, so Δ
    /// should be a multiple of the interval between scoring instants. A world whose
    /// paper scored static test points a walk apart sets the time between two of them.
    #[serde(default)]
    #[schemars(range(min = 1e-3, max = 86_400.0))]
    pub rpe_delta_s: Option<f64>,
}

/// `[world]`: name, place, time and navigation data.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WorldSection {
    /// The world's name, printed on tables and reports.
    pub name: String,
    /// What the world is, in a sentence or two (shown by `check` and in the report).
    #[serde(default)]
    pub description: Option<String>,
    /// Origin of the local ENU frame.
    pub origin: Origin,
    /// Start time, ISO-8601; GPST unless suffixed `Z`, `UTC` or `BDT`.
    pub start: String,
    /// Scenario length (s); defaults to the trajectory's length.
    #[serde(default)]
    #[schemars(range(min = 1e-3, max = 864_000.0))]
    pub duration_s: Option<f64>,
    /// RINEX navigation file relative to this world file, or `"builtin:nominal-gps-bds"`.
    #[serde(default)]
    pub ephemeris: Option<String>,
}

/// A geodetic point in degrees and metres (WGS-84 ellipsoidal height).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Origin {
    /// Geodetic latitude (degrees, north positive).
    #[schemars(range(min = -90.0, max = 90.0))]
    pub lat_deg: f64,
    /// Geodetic longitude (degrees, east positive; 180 to 360 accepted as west).
    #[schemars(range(min = -180.0, max = 360.0))]
    pub lon_deg: f64,
    /// Height above the WGS-84 ellipsoid (m).
    #[serde(default)]
    #[schemars(range(min = -500.0, max = 10_000.0))]
    pub h_m: f64,
}

/// What carries the receiver.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, Serialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum PlatformKind {
    Car,
    Pedestrian,
    /// An abstract point target (seeds 001 and 003).
    Target,
}

/// `[platform]`.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PlatformSection {
    pub kind: PlatformKind,
    pub trajectory: TrajectoryConfig,
    /// Attitude and gait for inertial sensors; default from `kind` (a car; a pedestrian
    /// holding a phone).
    #[serde(default)]
    pub attitude: Option<PlatformConfig>,
}

impl PlatformSection {
    /// The attitude model the inertial sensors use.
    pub fn attitude(&self) -> PlatformConfig {
        self.attitude.clone().unwrap_or_else(|| PlatformConfig {
            platform: match self.kind {
                PlatformKind::Pedestrian => Platform::Handheld,
                PlatformKind::Car | PlatformKind::Target => Platform::Car,
            },
            ..PlatformConfig::default()
        })
    }
}

/// `[receiver]`.
#[derive(Clone, Debug, Deserialize, Default, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ReceiverSection {
    #[serde(default)]
    pub clock: ClockConfig,
}

/// `[sensors]`.
#[derive(Clone, Debug, Deserialize, Default, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SensorsSection {
    #[serde(default)]
    pub gnss: Option<GnssConfig>,
    /// A DTMB receiver ranging on the world's DTMB transmitters.
    #[serde(default)]
    pub dtmb: Option<DtmbSensorConfig>,
    /// A TC-OFDM receiver ranging on the world's TC-OFDM base stations.
    #[serde(default)]
    pub tcofdm: Option<TcofdmSensorConfig>,
    /// An IMU (source `"imu"`).
    #[serde(default)]
    pub imu: Option<ImuConfig>,
    /// Pedestrian dead reckoning: step events (source `"pdr"`).
    #[serde(default)]
    pub pdr: Option<PdrSensorConfig>,
    /// FM fingerprinting: position fixes by WKNN (source `"fm"`).
    #[serde(default)]
    pub fm: Option<crate::fm::FmSensorConfig>,
    /// Magnetic landmarks: position fixes when a landmark is recognised (source
    /// `"magnetic"`).
    #[serde(default)]
    pub magnetic: Option<crate::magnetic::source::MagneticSensorConfig>,
    /// Abstract emitters at fixed positions (source `"emitters"`, seeds 001 and 003).
    #[serde(default)]
    pub emitters: Option<crate::beacons::EmittersConfig>,
}

/// One `[[shielding]]` window: exactly one of `keep_highest`, `keep`, `block`.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ShieldingSpec {
    /// Start of the window, seconds after the world start.
    pub from_s: f64,
    /// End of the window (exclusive).
    pub to_s: f64,
    /// Keep only the N highest satellites of each system.
    #[serde(default)]
    pub keep_highest: Option<usize>,
    /// Keep only these satellites (`"G05"`, `"C19"`, …).
    #[serde(default)]
    pub keep: Option<Vec<String>>,
    /// Remove these satellites.
    #[serde(default)]
    pub block: Option<Vec<String>>,
}

/// Reads the `[[estimator]]` tables, expanding each `preset = "…"` first
/// ([`crate::world::presets`]).
fn estimators_with_presets<'de, D>(d: D) -> Result<Vec<EstimatorSpec>, D::Error>
where
    D: serde::Deserializer<'de>,
{
    use serde::de::Error;
    let tables = Vec::<toml::Table>::deserialize(d)?;
    tables
        .into_iter()
        .enumerate()
        .map(|(i, t)| {
            let t = crate::world::presets::expand(t)
                .map_err(|m| D::Error::custom(format!("estimator[{i}].{m}")))?;
            serde_path_to_error::deserialize(toml::Value::Table(t)).map_err(|e| {
                let inner = e.path().to_string();
                let at = if inner.is_empty() || inner == "." || inner == "?" {
                    format!("estimator[{i}]")
                } else {
                    format!("estimator[{i}].{inner}")
                };
                D::Error::custom(format!("{at}: {}", e.into_inner().message()))
            })
        })
        .collect()
}

/// One `[[estimator]]` table as written, for the JSON Schema: the keys of
/// [`EstimatorSpec`] plus `preset`, which names a preset whose keys are laid under the
/// table's own. With a preset, `name`, `sources` and `filter` may come from it; without
/// one, the table must give them.
struct EstimatorTable;

impl JsonSchema for EstimatorTable {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "EstimatorTable".into()
    }

    fn json_schema(generator: &mut schemars::SchemaGenerator) -> schemars::Schema {
        let mut schema = EstimatorSpec::json_schema(generator);
        let required = schema.remove("required");
        let names: Vec<&str> = crate::world::presets::PRESETS
            .iter()
            .map(|p| p.name)
            .collect();
        if let Some(props) = schema
            .get_mut("properties")
            .and_then(serde_json::Value::as_object_mut)
        {
            props.insert(
                "preset".into(),
                serde_json::json!({
                    "description": "A named estimator preset (the papers' systems; `hybridnav presets` lists them) whose keys are laid under this table's own, key by key.",
                    "type": "string",
                    "enum": names,
                }),
            );
        }
        if let Some(required) = required {
            schema.insert(
                "anyOf".into(),
                serde_json::json!([{ "required": ["preset"] }, { "required": required }]),
            );
        }
        schema
    }
}

/// Splits an error of [`estimators_with_presets`] into its key path and message:
/// `estimator[1].filter: unknown variant` → (`estimator[1].filter`, `unknown variant`).
pub(crate) fn split_estimator_error(message: &str) -> Option<(&str, &str)> {
    let rest = message.strip_prefix("estimator[")?;
    let close = rest.find(']')?;
    rest[..close].parse::<usize>().ok()?;
    let (key, msg) = message.split_once(": ")?;
    (!key.contains(' ')).then_some((key, msg))
}

/// The filter an estimator runs.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, Serialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum FilterKind {
    /// Seed 000's 11-state EKF (position, velocity, acceleration, clock, drift).
    Ekf11,
    /// Epoch-by-epoch weighted least squares.
    Wls,
    /// Strapdown INS with seed 004's 15-state loosely coupled filter.
    Ins,
    /// Pedestrian dead reckoning from step events, optionally corrected by fixes.
    Pdr,
    /// The generic EKF (Joseph form) on seed 000's model ([`crate::fusion::family`]).
    Ekf,
    /// The unscented Kalman filter on the same model.
    Ukf,
    /// The cubature Kalman filter.
    Ckf,
    /// The strong tracking filter.
    Stf,
    /// Seed 004's relative-entropy Kalman filter.
    Rekf,
    /// The particle filter: regularised on the paper models, the family's on seed 000's.
    Pf,
    /// The plain SIR particle filter (the papers' own, seeds 001 and 003; paper models).
    Sir,
    /// The Rao-Blackwellised particle filter, clocks by a Kalman filter per particle
    /// (paper models).
    Rbpf,
    /// The marginalised particle filter: positions sampled, velocities, accelerations
    /// and clocks by a Kalman filter per particle (paper models).
    Mpf,
    /// The Gaussian particle filter (Kotecha & Djurić 2003): no resampling, the posterior
    /// carried as the Gaussian of the weighted cloud's moments (paper models).
    Gpf,
}

impl FilterKind {
    /// The member of the filter family, for the kinds [`FamilyEstimator`] runs.
    pub fn family(self) -> Option<FamilyKind> {
        Some(match self {
            FilterKind::Ekf => FamilyKind::Ekf,
            FilterKind::Ukf => FamilyKind::Ukf,
            FilterKind::Ckf => FamilyKind::Ckf,
            FilterKind::Stf => FamilyKind::Stf,
            FilterKind::Rekf => FamilyKind::Rekf,
            FilterKind::Pf => FamilyKind::Pf,
            FilterKind::Ekf11
            | FilterKind::Wls
            | FilterKind::Ins
            | FilterKind::Pdr
            | FilterKind::Sir
            | FilterKind::Rbpf
            | FilterKind::Mpf
            | FilterKind::Gpf => return None,
        })
    }
}

/// One `[[estimator]]`.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EstimatorSpec {
    /// Row name in the tables (the paper's own names, e.g. `"GPS"`, `"GPS+DTMB"`).
    pub name: String,
    /// Systems whose measurements it uses.
    pub sources: Vec<System>,
    pub filter: FilterKind,
    /// Seed 000's model tuning (PSDs, initial sigmas, χ² gates) for `ekf11` and for the
    /// filter family (`ekf`, `ukf`, `ckf`, `stf`, `rekf`, `pf`); `[estimator.model]` is
    /// accepted as another name.
    #[serde(default, alias = "model")]
    pub ekf: Option<Ekf11Config>,
    /// Tuning of the family's filters (`[estimator.options]`).
    #[serde(default)]
    pub options: Option<FamilyConfig>,
    /// Sources whose position fixes the estimator takes (`"fm"`).
    #[serde(default)]
    pub fixes: Vec<SourceKind>,
    /// Mode selection: `"fuzzy"` (seed 000) or `"seamless"` (seed 003).
    #[serde(default)]
    pub selection: Option<SelectionKind>,
    /// The fuzzy system's sets and rules (`selection = "fuzzy"`); default: seed 000's.
    #[serde(default)]
    pub fuzzy: Option<FuzzyConfig>,
    /// Seed 000's DTMB clock correction from good GPS fixes (`{}` for the defaults).
    #[serde(default)]
    pub dtmb_clock_correction: Option<ClockCorrectionConfig>,
    /// INS filter settings (filter = "ins").
    #[serde(default)]
    pub ins: Option<InsFilterConfig>,
    /// PDR filter settings (filter = "pdr").
    #[serde(default)]
    pub pdr: Option<PdrFilterConfig>,
    /// The process model (`[estimator.process]`, `model = "pva_clock"`, `"singer_2d"` or
    /// `"plane_turning"`); absent: seed 000's `pva_clock` for the filter family. The paper
    /// models run with every filter of the family, `filter = "ekf"`, `"ukf"`, `"ckf"`,
    /// `"stf"`, `"rekf"` or `"pf"` ([`crate::fusion::paper`]), tuned by
    /// `[estimator.options]` as on the 12-state model.
    #[serde(default)]
    pub process: Option<ProcessSpec>,
}

/// What an estimator needs from its world beyond its own table.
pub struct BuildContext<'a> {
    pub frame: &'a crate::core::EnuFrame,
    pub start: crate::core::GpsTime,
    pub imu: Option<&'a ImuConfig>,
    /// The platform's true start position (ENU), standing in for a surveyed start point.
    pub start_enu_m: nalgebra::Vector3<f64>,
    /// The trial's random streams (the particle filter draws from its own).
    pub rng: crate::core::TrialRng,
    /// The clock term (m) of each system's ranges declared by `[sensors.emitters]`,
    /// indexed like [`crate::core::System::ALL`]: what a paper estimator with
    /// `clocks = "known"` is assumed to know.
    pub emitter_clocks_m: Option<[f64; System::COUNT]>,
}

fn one() -> u64 {
    1
}

/// `[montecarlo]`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MonteCarloSection {
    /// Number of independent trials (`run --trials` overrides it).
    #[serde(default = "one")]
    #[schemars(range(min = 1, max = MAX_TRIALS))]
    pub trials: u64,
    /// Master seed: every trial's random streams derive from it and the trial index.
    #[serde(default = "one")]
    pub seed: u64,
}

impl Default for MonteCarloSection {
    fn default() -> Self {
        Self { trials: 1, seed: 1 }
    }
}

impl EstimatorSpec {
    /// Whether the estimator runs seed 000's 12-state model: `ekf11`, or a filter of the
    /// family without a paper `[estimator.process]` (absent or `model = "pva_clock"`), as
    /// [`EstimatorSpec::build`] decides.
    pub fn runs_pva_clock(&self) -> bool {
        let family_model = self
            .process
            .as_ref()
            .is_none_or(|p| *p == ProcessSpec::PvaClock {});
        family_model && (self.filter == FilterKind::Ekf11 || self.filter.family().is_some())
    }

    /// Builds a paper model's estimator ([`crate::fusion::paper`]).
    fn build_paper(
        &self,
        spec: &ProcessSpec,
        selection: Option<&ModeSelection>,
        ctx: &BuildContext<'_>,
    ) -> Result<Box<dyn Estimator>, String> {
        let cfg = self.options.unwrap_or_default();
        cfg.validate()
            .map_err(|(k, m)| format!("options.{k}: {m}"))?;
        let gate = cfg.residual_gate_c;
        let filter = match self.filter {
            FilterKind::Ekf => PaperFilter::Ekf {
                residual_gate_c: gate,
            },
            FilterKind::Ukf => PaperFilter::Ukf {
                alpha: cfg.ukf_alpha,
                beta: cfg.ukf_beta,
                kappa: cfg.ukf_kappa,
                residual_gate_c: gate,
            },
            FilterKind::Ckf => PaperFilter::Ckf {
                residual_gate_c: gate,
            },
            FilterKind::Stf => PaperFilter::Stf {
                forgetting: cfg.stf_forgetting,
                weakening: cfg.stf_weakening,
                max_fading: cfg.stf_max_fading,
                residual_gate_c: gate,
            },
            // As in the filter family, the RE-KF's data layer defaults to C = 3.
            FilterKind::Rekf => PaperFilter::Rekf {
                aleph_threshold: cfg.rekf_aleph_threshold,
                residual_gate_c: gate.or(Some(3.0)),
            },
            FilterKind::Pf
            | FilterKind::Sir
            | FilterKind::Rbpf
            | FilterKind::Mpf
            | FilterKind::Gpf => {
                use crate::fusion::particle::PfVariant;
                let variant = match self.filter {
                    FilterKind::Sir => PfVariant::Sir,
                    FilterKind::Rbpf => PfVariant::RaoBlackwellised,
                    FilterKind::Mpf => PfVariant::Marginalised,
                    FilterKind::Gpf => PfVariant::Gaussian,
                    _ => PfVariant::Regularised,
                };
                let proposal = cfg.pf_proposal_for(variant);
                let linearised = proposal == crate::fusion::family::ProposalKind::Linearised;
                PaperFilter::Pf {
                    particles: cfg.particles,
                    resampling: cfg.resampling.scheme(),
                    neff_threshold: cfg.neff_threshold_for(variant, proposal),
                    variant,
                    linearised,
                    kernel: cfg.pf_kernel.placement(),
                    covariance: cfg.gpf_covariance.estimate(),
                    // Progressive correction is the default wherever it applies; an
                    // explicit "progressive" elsewhere reaches the paper filter, which
                    // refuses it.
                    progressive: cfg.pf_correction.map_or_else(
                        || variant.takes_progressive_correction(linearised),
                        |kind| kind == crate::fusion::family::CorrectionKind::Progressive,
                    ),
                }
            }
            other @ (FilterKind::Ekf11 | FilterKind::Wls | FilterKind::Ins | FilterKind::Pdr) => {
                return Err(format!(
                    "process model '{}' runs with filter = \"ekf\", \"ukf\", \"ckf\", \"stf\", \"rekf\" or \"pf\", not '{}'",
                    spec.label(),
                    format!("{other:?}").to_lowercase()
                ))
            }
        };
        if !self.fixes.is_empty() || self.dtmb_clock_correction.is_some() {
            return Err(format!(
                "process model '{}' takes ranges only: remove 'fixes' and 'dtmb_clock_correction'",
                spec.label()
            ));
        }
        crate::fusion::paper::build(
            &self.name,
            spec,
            filter,
            &self.sources,
            selection,
            &PaperContext {
                frame: ctx.frame,
                start: ctx.start,
                start_enu_m: ctx.start_enu_m,
                emitter_clocks_m: ctx.emitter_clocks_m,
                rng: &ctx.rng,
            },
        )
    }

    /// Builds the estimator this table describes.
    ///
    /// # Errors
    /// When its configuration is unusable.
    pub fn build(&self, ctx: &BuildContext<'_>) -> Result<Box<dyn Estimator>, String> {
        let issue = |t: &str, i: crate::core::ConfigIssue| format!("{t}.{}: {}", i.key, i.message);
        let selection = self.selection.map(|k| match k {
            SelectionKind::Fuzzy => {
                ModeSelection::Fuzzy(Box::new(self.fuzzy.clone().unwrap_or_default()))
            }
            SelectionKind::Seamless => ModeSelection::Seamless,
        });
        if let Some(spec) = self
            .process
            .as_ref()
            .filter(|p| **p != ProcessSpec::PvaClock {})
        {
            return self.build_paper(spec, selection.as_ref(), ctx);
        }
        Ok(match self.filter {
            FilterKind::Ekf
            | FilterKind::Ukf
            | FilterKind::Ckf
            | FilterKind::Stf
            | FilterKind::Rekf
            | FilterKind::Pf => {
                let kind = self.filter.family().ok_or("not a filter-family kind")?;
                Box::new(FamilyEstimator::new(
                    &self.name,
                    kind,
                    &self.sources,
                    &self.fixes,
                    self.ekf,
                    self.options,
                    selection.as_ref(),
                    self.dtmb_clock_correction,
                    &ctx.rng,
                )?)
            }
            FilterKind::Ekf11 => Box::new(
                EkfEstimator::new(&self.name, &self.sources, self.ekf)?.with_preprocessing(
                    &self.fixes,
                    selection.as_ref(),
                    self.dtmb_clock_correction,
                )?,
            ),
            FilterKind::Wls => Box::new(WlsEstimator::new(&self.name, &self.sources)),
            FilterKind::Sir | FilterKind::Rbpf | FilterKind::Mpf | FilterKind::Gpf => {
                return Err(format!(
                    "filter \"{}\" runs on a paper process model ([estimator.process] model = \"singer_2d\" or \"plane_turning\"); on seed 000's model use filter = \"pf\"",
                    format!("{:?}", self.filter).to_lowercase()
                ))
            }
            FilterKind::Ins => {
                let imu = ctx
                    .imu
                    .ok_or("filter \"ins\" needs an IMU: add a [sensors.imu] table")?;
                Box::new(
                    InsEstimator::new(
                        &self.name,
                        &self.ins.clone().unwrap_or_default(),
                        imu,
                        &self.sources,
                        ctx.frame,
                        ctx.start,
                    )
                    .map_err(|i| issue("ins", i))?,
                )
            }
            FilterKind::Pdr => Box::new(
                PdrEstimator::new(
                    &self.name,
                    &self.pdr.clone().unwrap_or_default(),
                    &self.sources,
                    ctx.frame,
                    Some(ctx.start_enu_m),
                )
                .map_err(|i| issue("pdr", i))?,
            ),
        })
    }
}
