//! World files: the TOML description of one scenario, validated into a [`World`].
//!
//! Every error names the file, the line and column, and what was expected: syntax and type
//! errors through the spans serde reports, value checks made after deserialisation through
//! [`mod@locate`], which maps a key path back to the text.

pub mod bound;
pub mod cache;
pub mod comparison;
pub mod dtmb_iq;
pub mod fm;
pub mod locate;
pub mod presets;
pub mod reference;
pub mod scene;
pub mod schema;
pub mod trial;
pub mod visibility;

use crate::core::receiver_clock::{ClockTrack, ReceiverClock};
use crate::core::{EmitterId, EnuFrame, Geodetic, GpsTime, SimTime, System, TrialRng};
use crate::dtmb::DtmbSource;
use crate::engine::trial::{Scoring, ScoringInstants, TrialSetup};
use crate::gnss::measurement::{GnssSource, SceneView, Shielding, ShieldingRule};
use crate::gnss::rinex_nav::{parse_nav, read_nav_file, NavData};
use crate::inertial::source::{ImuSource, PdrSource};
use crate::measurement::SourceKind;
use crate::motion::Trajectory;
use crate::propagation::{Indoor, Scene};
use crate::tcofdm::{BaseStationSpec, TcofdmSource};
use locate::{locate, path_to_string, PathSeg};
use scene::{Transmitter, TransmitterKind, TransmitterSpec};
use schema::{BuildContext, EstimatorSpec, FilterKind, PlatformKind, WorldFile};
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The navigation file embedded in the binary: the nominal GPS + BeiDou constellation that
/// `hybridnav ephemeris synth` writes, used when a world names no ephemeris.
pub const BUILTIN_EPHEMERIS: &str = include_str!("../../../../ephemeris/nominal-gps-bds.rnx");
/// The name a world file uses for the embedded navigation file.
pub const BUILTIN_EPHEMERIS_NAME: &str = "builtin:nominal-gps-bds";

/// An error in a world file, with where it is and what was expected.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldError {
    pub file: PathBuf,
    pub line: usize,
    pub column: usize,
    /// Key path, e.g. `estimator[1].filter` (empty for syntax errors).
    pub key: String,
    pub message: String,
}

impl fmt::Display for WorldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}: ", self.file.display(), self.line, self.column)?;
        if !self.key.is_empty() {
            write!(f, "{}: ", self.key)?;
        }
        f.write_str(&self.message)
    }
}

impl std::error::Error for WorldError {}

/// A validated world, ready to build trials from.
#[derive(Debug)]
pub struct World {
    /// Where it was read from.
    pub path: PathBuf,
    /// The parsed file.
    pub file: WorldFile,
    /// FNV-1a hash of the file's bytes, reported in every summary.
    pub hash: String,
    /// Start of the scenario.
    pub start: GpsTime,
    /// Local frame at the world origin.
    pub frame: EnuFrame,
    /// Broadcast navigation data (shared by every trial).
    pub nav: Arc<NavData>,
    /// Where the navigation data came from.
    pub nav_source: String,
    /// Things a user should know that do not stop the world from running (dropped
    /// navigation records, implausible values); `check` and `run` print them.
    pub warnings: Vec<String>,
    /// Scenario length.
    pub duration_s: f64,
    /// Shielding windows with their satellites parsed.
    pub shielding: Vec<Shielding>,
    /// The physical scene, when the world has one.
    pub scene: Option<Arc<Scene>>,
    /// The transmitters, positions resolved.
    pub transmitters: Vec<Transmitter>,
    /// The FM fingerprint database (see [`fm`]).
    pub fm_db: fm::FmDatabase,
    /// The deterministic epochs every trial shares (see [`crate::engine::cache`]).
    pub epoch_cache: cache::CacheSlot,
    /// The comparison protocol as applied: per estimator, its record for `summary.json`
    /// and its divergence watch.
    pub comparison: comparison::Applied,
}

struct Ctx<'a> {
    path: &'a Path,
    text: &'a str,
}

impl Ctx<'_> {
    /// An error at the key path `at`, written as a user reads it: `sensors.gnss.systems[1]`.
    fn err(&self, at: &str, message: impl Into<String>) -> WorldError {
        let segs = parse_path(at);
        let (line, column) = locate(self.text, &segs);
        WorldError {
            file: self.path.to_path_buf(),
            line,
            column,
            key: path_to_string(&segs),
            message: message.into(),
        }
    }

    /// Checks that `v` is finite and inside `range`, naming `what` it should be otherwise.
    fn in_range(
        &self,
        at: &str,
        v: f64,
        range: impl std::ops::RangeBounds<f64> + std::fmt::Debug,
        what: &str,
    ) -> Result<(), WorldError> {
        if v.is_finite() && range.contains(&v) {
            Ok(())
        } else {
            Err(self.err(at, format!("expected {what} within {range:?}, got {v}")))
        }
    }

    /// Prefixes a module's [`ConfigIssue`] key with the table that holds it.
    fn issue(&self, table: &str, issue: crate::core::ConfigIssue) -> WorldError {
        self.err(&format!("{table}.{}", issue.key), issue.message)
    }
}

/// Splits `a.b[2].c` into key-path segments.
fn parse_path(at: &str) -> Vec<PathSeg> {
    let mut segs = Vec::new();
    for part in at.split('.').filter(|p| !p.is_empty()) {
        let mut rest = part;
        if let Some(i) = rest.find('[') {
            segs.push(PathSeg::Key(rest[..i].to_string()));
            rest = &rest[i..];
            while let Some(close) = rest.find(']') {
                if let Ok(n) = rest[1..close].parse() {
                    segs.push(PathSeg::Index(n));
                }
                rest = &rest[close + 1..];
            }
        } else {
            segs.push(PathSeg::Key(rest.to_string()));
        }
    }
    segs
}

/// Deserialises a world file, returning on error the key path of the error (the table of
/// a missing key, the key of a wrong value; empty for syntax errors), the parser's byte
/// span when it has one, and the message without the path.
fn deserialize_world(
    text: &str,
) -> Result<WorldFile, (String, Option<std::ops::Range<usize>>, String)> {
    serde_path_to_error::deserialize(toml::Deserializer::new(text)).map_err(|e| {
        let tracked = e.path().to_string();
        let inner = e.into_inner();
        let span = inner.span();
        let message = inner.message().trim().to_string();
        // Errors inside `[[estimator]]` tables carry their own path (they are read table
        // by table after presets are expanded): `estimator[1].filter: unknown variant …`.
        if let Some((key, rest)) = schema::split_estimator_error(&message) {
            return (key.to_string(), span, rest.to_string());
        }
        // A path of only `?` segments (or nothing) means the error is about the syntax.
        let key = if tracked.split('.').all(|s| s == "?" || s.is_empty()) {
            String::new()
        } else {
            tracked
        };
        (key, span, message)
    })
}

fn fnv_hex(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// Reads and validates a world file.
///
/// # Errors
/// A [`WorldError`] for a missing or unreadable file, a syntax error, an unknown key, a
/// value of the wrong type or an impossible value.
pub fn load_world(path: &Path) -> Result<World, WorldError> {
    use crate::io::read::{read_text, TextError, WORLD};
    let text = read_text(path, WORLD).map_err(|e| {
        let (line, column, message) = match e {
            TextError::Io(e) => (0, 0, format!("cannot read the world file: {e}")),
            TextError::NotText(e) => (e.line, e.column, e.message),
        };
        WorldError {
            file: path.to_path_buf(),
            line,
            column,
            key: String::new(),
            message,
        }
    })?;
    parse_world(&text, path)
}

/// Validates world text as if read from `path` (relative paths inside it are resolved
/// against `path`'s directory).
///
/// # Errors
/// As [`load_world`].
pub fn parse_world(text: &str, path: &Path) -> Result<World, WorldError> {
    let ctx = Ctx { path, text };
    let mut file: WorldFile = deserialize_world(text).map_err(|(key, span, message)| {
        let segs = parse_path(&key);
        // The parser's span is exact for syntax errors and values; the key path is what
        // locates errors inside tables the parser only saw as a whole (`[[estimator]]`,
        // read through presets) and missing keys (at their table's header).
        let (line, column) = match span {
            Some(s) if !key.starts_with("estimator") => locate::line_col(text, s.start),
            _ if !segs.is_empty() => locate(text, &segs),
            Some(s) => locate::line_col(text, s.start),
            None => (1, 1),
        };
        WorldError {
            file: path.to_path_buf(),
            line,
            column,
            key: path_to_string(&segs),
            message,
        }
    })?;

    let w = &file.world;
    let o = &w.origin;
    ctx.in_range(
        "world.origin.lat_deg",
        o.lat_deg,
        -90.0..=90.0,
        "a latitude in degrees",
    )?;
    ctx.in_range(
        "world.origin.lon_deg",
        o.lon_deg,
        -180.0..=360.0,
        "a longitude in degrees",
    )?;
    ctx.in_range(
        "world.origin.h_m",
        o.h_m,
        -500.0..=10_000.0,
        "an ellipsoidal height in m",
    )?;
    let start = GpsTime::parse_iso(&w.start).map_err(|m| ctx.err("world.start", m))?;
    if let Some(d) = w.duration_s {
        ctx.in_range(
            "world.duration_s",
            d,
            1e-3..=864_000.0,
            "a duration in seconds",
        )?;
    }
    let trajectory = &file.platform.trajectory;
    trajectory
        .validate()
        .map_err(|i| ctx.issue("platform.trajectory", i))?;

    let (nav, nav_source) = load_nav(&ctx, w.ephemeris.as_deref())?;
    if let Some(g) = &file.sensors.gnss {
        check_gnss(&ctx, g, &nav, &nav_source, start)?;
    }
    let clock = &file.receiver.clock;
    clock
        .validate()
        .map_err(|i| ctx.issue("receiver.clock", i))?;
    let shielding = check_shielding(&ctx, &file.shielding, &nav, &nav_source)?;

    if !(1..=crate::world::schema::MAX_TRIALS).contains(&file.montecarlo.trials) {
        return Err(ctx.err(
            "montecarlo.trials",
            format!(
                "expected 1 to {} trials, got {}",
                crate::world::schema::MAX_TRIALS,
                file.montecarlo.trials
            ),
        ));
    }

    let sc = &file.scoring;
    if let Some(r) = sc.rate_hz {
        ctx.in_range("scoring.rate_hz", r, 1e-3..=1e3, "a scoring rate (Hz)")?;
    }
    if let Some(c) = sc.coast_limit_s {
        ctx.in_range(
            "scoring.coast_limit_s",
            c,
            0.0..=86_400.0,
            "a coast limit (s)",
        )?;
    }
    if let Some(d) = sc.rpe_delta_s {
        ctx.in_range(
            "scoring.rpe_delta_s",
            d,
            1e-3..=86_400.0,
            "an RPE interval (s)",
        )?;
        // With a fixed rate the instants are known here: an interval that is not a whole
        // number of scoring periods would pair no two instants and leave the RPE empty.
        if let Some(r) = sc.rate_hz {
            let periods = d * r;
            if periods.round() < 1.0 || (periods - periods.round()).abs() > 1e-6 {
                return Err(ctx.err(
                    "scoring.rpe_delta_s",
                    format!(
                        "expected a whole number of scoring periods (1/rate_hz = {} s), got {d} s",
                        1.0 / r
                    ),
                ));
            }
        }
    }
    if sc.rate_hz.is_some() && sc.sources.is_some() {
        return Err(ctx.err(
            "scoring.sources",
            "give either a scoring rate_hz or the sources whose epochs are scored, not both",
        ));
    }

    // The scenario length is the world's, or the trajectory's. Building the trajectory
    // once here also proves that every trial can build it.
    let probe = trajectory
        .build(&mut TrialRng::new(0, 0).stream("motion/probe"))
        .map_err(|i| ctx.issue("platform.trajectory", i))?;
    let duration_s = w.duration_s.unwrap_or_else(|| probe.duration_s());

    let frame = EnuFrame::new(Geodetic::from_deg(o.lat_deg, o.lon_deg, o.h_m));
    let scene = match &file.scene {
        None => None,
        Some(section) => {
            let resolved = section
                .resolve(&frame)
                .map_err(|(k, m)| ctx.err(&format!("scene.{k}"), m))?;
            let scene = Scene::new(&resolved.config)
                .map_err(|i| ctx.err(&format!("scene.{}", resolved.user_key(&i.key)), i.message))?;
            if let Some(sh) = &section.shadowing {
                sh.validate().map_err(|i| ctx.issue("scene.shadowing", i))?;
            }
            check_platform_in_scene(&ctx, &scene, file.platform.kind, probe.as_ref(), duration_s)?;
            Some(Arc::new(scene))
        }
    };
    let transmitters = check_transmitters(&ctx, &file.transmitters, &frame, scene.as_deref())?;
    let simulated = check_terrestrial_and_inertial(&ctx, &file, &transmitters)?;

    let fm_db = match &file.sensors.fm {
        None => fm::FmDatabase::None,
        Some(cfg) => {
            cfg.validate().map_err(|i| ctx.issue("sensors.fm", i))?;
            let declared = transmitters
                .iter()
                .filter(|t| t.kind == TransmitterKind::Fm)
                .count();
            if declared == 0 && cfg.synthetic_stations_total == 0 {
                return Err(ctx.err(
                    "sensors.fm",
                    "expected FM stations: add [[transmitter]] tables with kind = \"fm\" or set synthetic_stations_total",
                ));
            }
            match &cfg.database {
                Some(db) => {
                    let p = path.parent().unwrap_or(Path::new(".")).join(db);
                    let db = crate::fm::FingerprintDb::load(&p, &fm::tag(&file.world.name, &frame))
                        .map_err(|e| ctx.err("sensors.fm.database", e.to_string()))?;
                    fm::FmDatabase::Loaded(Arc::new(db))
                }
                None => fm::FmDatabase::Surveyed(std::sync::Mutex::new(None)),
            }
        }
    };
    let anomalies = file
        .scene
        .as_ref()
        .map_or(&[][..], |s| &s.magnetic_anomalies[..]);
    for (i, a) in anomalies.iter().enumerate() {
        a.validate()
            .map_err(|c| ctx.issue(&format!("scene.magnetic_anomaly[{i}]"), c))?;
    }
    if let Some(m) = &file.sensors.magnetic {
        m.validate().map_err(|i| ctx.issue("sensors.magnetic", i))?;
        if anomalies.is_empty() {
            return Err(ctx.err(
                "sensors.magnetic",
                "expected landmarks to detect: add [[scene.magnetic_anomaly]] tables",
            ));
        }
        if m.dtmb_check.enabled && !transmitters.iter().any(|t| t.kind == TransmitterKind::Dtmb) {
            return Err(ctx.err(
                "sensors.magnetic.dtmb_check",
                "the DTMB consistency check needs a DTMB [[transmitter]] to range to",
            ));
        }
    }
    if file.estimators.is_empty() {
        return Err(ctx.err("", "expected at least one [[estimator]] table"));
    }
    // The comparison protocol is applied before the estimators are checked, so what is
    // checked (and built) is what runs.
    let comparison = comparison::apply(file.comparison.as_ref(), &mut file.estimators)
        .map_err(|(key, message)| ctx.err(&key, message))?;
    let build_ctx = BuildContext {
        frame: &frame,
        start,
        imu: file.sensors.imu.as_ref(),
        start_enu_m: probe.state_at(0.0).pos_enu_m,
        rng: TrialRng::new(0, 0),
        emitter_clocks_m: file.sensors.emitters.as_ref().map(|e| e.clocks_m()),
    };
    for (i, e) in file.estimators.iter().enumerate() {
        check_estimator(&ctx, i, e, &simulated, &file, &build_ctx)?;
        if file.estimators[..i].iter().any(|o| o.name == e.name) {
            return Err(ctx.err(
                &format!("estimator[{i}].name"),
                format!(
                    "estimator name '{}' is used twice; names must be unique",
                    e.name
                ),
            ));
        }
    }

    let mut warnings: Vec<String> = nav.dropped.iter().map(ToString::to_string).collect();
    warnings.extend(plausibility_warnings(
        &ctx,
        &file,
        probe.as_ref(),
        &transmitters,
    ));

    Ok(World {
        path: path.to_path_buf(),
        hash: fnv_hex(text.as_bytes()),
        start,
        frame,
        warnings,
        nav: Arc::new(nav),
        nav_source,
        duration_s,
        shielding,
        scene,
        transmitters,
        fm_db,
        epoch_cache: Default::default(),
        comparison,
        file,
    })
}

/// Fastest plausible pedestrian (m/s): running pace. Preferred walking speed is about
/// 1.4 m/s (Bohannon 1997, Age and Ageing 26:15–19) and recreational running stays below
/// 6 m/s; faster usually means a speed in km/h.
const PEDESTRIAN_MAX_MPS: f64 = 6.0;
/// Fastest plausible road vehicle (m/s), 250 km/h; faster usually means km/h.
const CAR_MAX_MPS: f64 = 70.0;
/// Highest ERP (kW) of a UHF television transmitter: 1000 kW is the FCC's cap for UHF DTV
/// (47 CFR 73.622(f)(8)); more usually means a value in W.
const TV_MAX_ERP_KW: f64 = 1000.0;
/// Highest ERP (kW) of an FM broadcast station: 100 kW, the FCC's class C maximum
/// (47 CFR 73.211(b)).
const FM_MAX_ERP_KW: f64 = 100.0;
/// Lowest plausible antenna height (m above the world origin) of a broadcast or base
/// station transmitter: antennas sit on masts or roofs; less usually means km or a
/// height above the wrong datum.
const TRANSMITTER_MIN_HEIGHT_M: f64 = 3.0;

/// Values that are valid but probably not what the author meant, each with the unit slip
/// it suggests. They do not stop the world; `check` and `run` print them.
fn plausibility_warnings(
    ctx: &Ctx<'_>,
    file: &WorldFile,
    probe: &dyn Trajectory,
    transmitters: &[Transmitter],
) -> Vec<String> {
    let mut out = Vec::new();
    let mut warn = |at: &str, m: String| out.push(ctx.err(at, m).to_string());
    // Speed: the fastest moment of the trajectory, sampled every 0.5 s.
    let traj_s = probe.duration_s();
    let n = (traj_s / 0.5).ceil().min(2.0e6) as usize;
    let top_mps = (0..=n)
        .map(|k| probe.state_at(k as f64 * 0.5).vel_enu_mps.norm())
        .fold(0.0, f64::max);
    let limit = match file.platform.kind {
        PlatformKind::Pedestrian => Some(("a pedestrian", PEDESTRIAN_MAX_MPS)),
        PlatformKind::Car => Some(("a car", CAR_MAX_MPS)),
        PlatformKind::Target => None,
    };
    if let Some((what, max)) = limit {
        if top_mps > max {
            warn(
                "platform.trajectory",
                format!(
                    "the trajectory reaches {top_mps:.1} m/s ({:.0} km/h), fast for {what} \
                     (at most {max} m/s expected); was a speed in km/h given as m/s?",
                    top_mps * 3.6
                ),
            );
        }
    }
    if let Some(d) = file.world.duration_s {
        if d < traj_s - 1e-6 {
            warn(
                "world.duration_s",
                format!(
                    "duration_s = {d} s stops the scenario before the trajectory ends \
                     ({traj_s:.1} s); leave it out to run the whole trajectory"
                ),
            );
        }
    }
    if let Some(g) = &file.sensors.gnss {
        let m = g.elevation_mask_deg;
        if m > 0.0 && m < std::f64::consts::FRAC_PI_2 && m.fract() != 0.0 {
            warn(
                "sensors.gnss.elevation_mask_deg",
                format!(
                    "an elevation mask of {m}° is unusually low; if it is in radians, write \
                     {:.1} (degrees)",
                    m.to_degrees()
                ),
            );
        }
    }
    for (i, t) in transmitters.iter().enumerate() {
        let max_kw = if t.kind == TransmitterKind::Fm {
            FM_MAX_ERP_KW
        } else {
            TV_MAX_ERP_KW
        };
        if t.spec.erp_kw > max_kw {
            warn(
                &format!("transmitter[{i}].erp_kw"),
                format!(
                    "{} radiates {} kW ERP, more than the {max_kw} kW of the largest \
                     {} transmitters; was it given in W ({} kW)?",
                    t.id,
                    t.spec.erp_kw,
                    if t.kind == TransmitterKind::Fm {
                        "FM"
                    } else {
                        "UHF TV"
                    },
                    t.spec.erp_kw / 1e3
                ),
            );
        }
        if t.pos_enu_m.z < TRANSMITTER_MIN_HEIGHT_M {
            let key = if t.spec.position.is_some() {
                "position.h_m"
            } else {
                "position_enu_m"
            };
            warn(
                &format!("transmitter[{i}].{key}"),
                format!(
                    "{}'s antenna is {:.2} m above the world origin; masts and roofs put \
                     antennas at least {TRANSMITTER_MIN_HEIGHT_M} m up (a height in km? an \
                     ellipsoidal height h_m is above the ellipsoid, like the origin's)",
                    t.id, t.pos_enu_m.z
                ),
            );
        }
    }
    // Co-channel DTMB towers at signal level: their signals add at the receiver, and
    // unless they form a declared single-frequency network (same payload and schedule)
    // the receiver's acquisition locks onto either and ranging resets.
    let signal_level = file
        .sensors
        .dtmb
        .as_ref()
        .is_some_and(|d| d.level == crate::dtmb::source::DtmbLevel::Signal);
    if signal_level {
        for (i, t) in transmitters.iter().enumerate() {
            if t.kind != TransmitterKind::Dtmb {
                continue;
            }
            let twin = transmitters[..i].iter().find(|o| {
                o.kind == TransmitterKind::Dtmb
                    && o.freq_hz == t.freq_hz
                    && (o.spec.sfn.is_none() || o.spec.sfn != t.spec.sfn)
            });
            if let Some(o) = twin {
                warn(
                    &format!("transmitter[{i}].channel"),
                    format!(
                        "DTMB towers {} and {} share the carrier {} MHz at level = \"signal\" \
                         without a common sfn: their independent signals interfere and the \
                         receiver's ranging loses lock; put them on different channels or \
                         in one single-frequency network (sfn = \"…\")",
                        o.id,
                        t.id,
                        t.freq_hz * 1e-6
                    ),
                );
            }
        }
    }
    out
}

/// A car or a target cannot drive through a building; a pedestrian may walk into one (an
/// indoor section). The trajectory is checked every 0.5 s.
fn check_platform_in_scene(
    ctx: &Ctx<'_>,
    scene: &Scene,
    kind: PlatformKind,
    trajectory: &dyn Trajectory,
    duration_s: f64,
) -> Result<(), WorldError> {
    let n = (duration_s / 0.5).ceil() as usize;
    for k in 0..=n {
        let t_s = (k as f64 * 0.5).min(duration_s);
        let p = trajectory.state_at(t_s).pos_enu_m;
        let indoor = scene.check_receiver(&p).map_err(|i| {
            ctx.err(
                "platform.trajectory",
                format!("at t = {t_s} s: {}", i.message),
            )
        })?;
        if let (Some(Indoor::Building(b)), PlatformKind::Car | PlatformKind::Target) =
            (indoor, kind)
        {
            return Err(ctx.err(
                "platform.trajectory",
                format!(
                    "the {} enters building {b} (scene.buildings[{b}]) at t = {t_s} s, at \
                     [{:.1}, {:.1}, {:.1}] m ENU; only pedestrians may go indoors",
                    if kind == PlatformKind::Car {
                        "car"
                    } else {
                        "target"
                    },
                    p.x,
                    p.y,
                    p.z
                ),
            ));
        }
    }
    Ok(())
}

fn check_transmitters(
    ctx: &Ctx<'_>,
    specs: &[TransmitterSpec],
    frame: &EnuFrame,
    scene: Option<&Scene>,
) -> Result<Vec<Transmitter>, WorldError> {
    let mut out: Vec<Transmitter> = Vec::with_capacity(specs.len());
    for (i, s) in specs.iter().enumerate() {
        let at = |k: &str| format!("transmitter[{i}].{k}");
        let t = s.resolve(frame).map_err(|(k, m)| ctx.err(&at(&k), m))?;
        let system = match s.kind {
            TransmitterKind::Dtmb => Some(System::Dtmb),
            TransmitterKind::Tcofdm => Some(System::Tcofdm),
            TransmitterKind::Fm => None,
        };
        if let Some(sys) = system {
            let ok = s.id.parse::<EmitterId>().is_ok_and(|id| id.system == sys);
            if !ok {
                let prefix = if sys == System::Dtmb { "D" } else { "T" };
                return Err(ctx.err(
                    &at("id"),
                    format!(
                        "expected an id like \"{prefix}01\" for a {} transmitter, got \"{}\"",
                        s.kind.label(),
                        s.id
                    ),
                ));
            }
        }
        if out.iter().any(|o| o.id == s.id) {
            return Err(ctx.err(
                &at("id"),
                format!("transmitter id \"{}\" is used twice", s.id),
            ));
        }
        if let Some(scene) = scene {
            scene
                .check_transmitter(&t.pos_enu_m)
                .map_err(|i| ctx.err(&at("position"), i.message))?;
        }
        out.push(t);
    }
    scene::check_sfn_groups(&out)
        .map_err(|(i, k, m)| ctx.err(&format!("transmitter[{i}].{k}"), m))?;
    Ok(out)
}

/// The embedded navigation files, by the name worlds and commands use for them.
pub const BUILTIN_NAV: &[(&str, &str)] = &[(BUILTIN_EPHEMERIS_NAME, BUILTIN_EPHEMERIS)];

/// Reads a navigation source as worlds and commands name it: `builtin:NAME` for an
/// embedded file ([`BUILTIN_NAV`]), otherwise a RINEX navigation file path, relative to
/// `base_dir`. Returns the data and how to name its source in messages.
///
/// # Errors
/// An unknown `builtin:` name (the message lists the known ones), a missing file, or the
/// reader's [`crate::gnss::rinex_nav::RinexError`] text, each said once.
pub fn read_nav_source(spec: &str, base_dir: &Path) -> Result<(NavData, String), String> {
    if let Some(name) = spec.strip_prefix("builtin:") {
        let Some((full, text)) = BUILTIN_NAV
            .iter()
            .find(|(n, _)| n.strip_prefix("builtin:") == Some(name))
        else {
            let known: Vec<&str> = BUILTIN_NAV.iter().map(|(n, _)| *n).collect();
            return Err(format!(
                "unknown embedded navigation data \"{spec}\": expected one of {}",
                known.join(", ")
            ));
        };
        let nav = parse_nav(text, full)
            .map_err(|e| format!("the embedded ephemeris does not parse: {e}"))?;
        return Ok((nav, (*full).to_string()));
    }
    let p = base_dir.join(spec);
    if !p.exists() {
        return Err(format!(
            "navigation file {} does not exist (a relative path is read from {}; use \
             \"{BUILTIN_EPHEMERIS_NAME}\" for the embedded one)",
            p.display(),
            if base_dir.as_os_str().is_empty() {
                "the current directory".to_string()
            } else {
                base_dir.display().to_string()
            }
        ));
    }
    let nav = read_nav_file(&p).map_err(|e| e.to_string())?;
    Ok((nav, p.display().to_string()))
}

/// Navigation data: a file relative to the world file, or the embedded default.
fn load_nav(ctx: &Ctx<'_>, ephemeris: Option<&str>) -> Result<(NavData, String), WorldError> {
    let base = ctx.path.parent().unwrap_or(Path::new("."));
    read_nav_source(ephemeris.unwrap_or(BUILTIN_EPHEMERIS_NAME), base)
        .map_err(|m| ctx.err("world.ephemeris", m))
}

fn check_gnss(
    ctx: &Ctx<'_>,
    g: &crate::gnss::measurement::GnssConfig,
    nav: &NavData,
    nav_source: &str,
    start: GpsTime,
) -> Result<(), WorldError> {
    let at = |k: &str| format!("sensors.gnss.{k}");
    ctx.in_range(&at("rate_hz"), g.rate_hz, 1e-3..=100.0, "a rate in Hz")?;
    ctx.in_range(
        &at("elevation_mask_deg"),
        g.elevation_mask_deg,
        -5.0..90.0,
        "an elevation mask in degrees",
    )?;
    if g.systems.is_empty() || g.systems.iter().any(|s| !s.is_gnss()) {
        return Err(ctx.err(
            &at("systems"),
            "expected a non-empty list of satellite systems from \"gps\", \"bds\"",
        ));
    }
    for (i, s) in g.systems.iter().enumerate() {
        if !nav.ephemerides.iter().any(|e| e.sat.system == *s) {
            return Err(ctx.err(
                &at(&format!("systems[{i}]")),
                format!(
                    "the navigation data ({nav_source}) has no {} ephemerides",
                    s.name()
                ),
            ));
        }
    }
    g.tracking
        .validate()
        .map_err(|i| ctx.issue(&at("tracking"), i))?;
    let e = &g.errors;
    let err_at = |k: &str| at(&format!("errors.{k}"));
    for (name, v) in [
        ("ure_gps_m", e.ure_gps_m),
        ("ure_bds_m", e.ure_bds_m),
        ("iono_residual", e.iono_residual),
        ("iono_residual_per_sat", e.iono_residual_per_sat),
        ("tropo_residual", e.tropo_residual),
    ] {
        ctx.in_range(&err_at(name), v, 0.0..1e6, "a non-negative number")?;
    }
    ctx.in_range(
        &err_at("ure_tau_s"),
        e.ure_tau_s,
        1e-6..1e9,
        "a correlation time in s",
    )?;
    ctx.in_range(
        &err_at("humidity"),
        e.humidity,
        0.0..=1.0,
        "a relative humidity",
    )?;

    // An empty sky: no satellite of the tracked systems has an ephemeris valid at the start.
    let usable = nav
        .satellites()
        .into_iter()
        .filter(|s| g.systems.contains(&s.system))
        .any(|s| nav.select(s, start).is_some());
    if !usable {
        let toes = nav.ephemerides.iter().map(|e| e.toe);
        let span = match (toes.clone().min(), toes.max()) {
            (Some(a), Some(b)) => format!("its ephemerides have reference times from {a} to {b}"),
            _ => "it holds no GPS or BeiDou ephemeris".to_string(),
        };
        return Err(ctx.err(
            "world.start",
            format!(
                "empty sky: no satellite in {nav_source} has an ephemeris valid at the start \
                 {start}; {span}"
            ),
        ));
    }
    Ok(())
}

fn check_shielding(
    ctx: &Ctx<'_>,
    specs: &[schema::ShieldingSpec],
    nav: &NavData,
    nav_source: &str,
) -> Result<Vec<Shielding>, WorldError> {
    let mut shielding = Vec::with_capacity(specs.len());
    for (i, s) in specs.iter().enumerate() {
        let at = |k: &str| format!("shielding[{i}].{k}");
        if !(s.from_s.is_finite() && s.to_s.is_finite() && s.from_s >= 0.0 && s.to_s > s.from_s) {
            return Err(ctx.err(
                &at("to_s"),
                format!(
                    "expected 0 ≤ from_s < to_s, got from_s = {}, to_s = {}",
                    s.from_s, s.to_s
                ),
            ));
        }
        let parse_list = |k: &str, list: &[String]| -> Result<Vec<EmitterId>, WorldError> {
            list.iter()
                .enumerate()
                .map(|(j, text)| {
                    let here = at(&format!("{k}[{j}]"));
                    let id: EmitterId = text.parse().map_err(|m: String| ctx.err(&here, m))?;
                    if !nav.ephemerides.iter().any(|e| e.sat == id) {
                        return Err(ctx.err(
                            &here,
                            format!("satellite {id} is not in the navigation data ({nav_source})"),
                        ));
                    }
                    Ok(id)
                })
                .collect()
        };
        let rule = match (s.keep_highest, &s.keep, &s.block) {
            (Some(n), None, None) => ShieldingRule::KeepHighest(n),
            (None, Some(l), None) => ShieldingRule::Keep(parse_list("keep", l)?),
            (None, None, Some(l)) => ShieldingRule::Block(parse_list("block", l)?),
            _ => {
                return Err(ctx.err(
                    &format!("shielding[{i}]"),
                    "expected exactly one of keep_highest = N, keep = [\"G05\", …] or \
                     block = [\"G05\", …]",
                ))
            }
        };
        shielding.push(Shielding {
            from_s: s.from_s,
            to_s: s.to_s,
            rule,
        });
    }
    Ok(shielding)
}

/// Validates the DTMB, TC-OFDM, IMU and PDR sensor tables and returns the systems the
/// world simulates (its GNSS systems, plus DTMB and TC-OFDM when a receiver and at least
/// one transmitter of the kind exist).
fn check_terrestrial_and_inertial(
    ctx: &Ctx<'_>,
    file: &WorldFile,
    transmitters: &[Transmitter],
) -> Result<Vec<System>, WorldError> {
    let mut systems: Vec<System> = file
        .sensors
        .gnss
        .as_ref()
        .map(|g| g.systems.clone())
        .unwrap_or_default();
    let count = |k: TransmitterKind| transmitters.iter().filter(|t| t.kind == k).count();
    if let Some(d) = &file.sensors.dtmb {
        d.validate().map_err(|i| ctx.issue("sensors.dtmb", i))?;
        if count(TransmitterKind::Dtmb) == 0 {
            return Err(ctx.err(
                "sensors.dtmb",
                "a DTMB receiver needs at least one [[transmitter]] with kind = \"dtmb\"",
            ));
        }
        systems.push(System::Dtmb);
    }
    if let Some(t) = &file.sensors.tcofdm {
        t.validate().map_err(|i| ctx.issue("sensors.tcofdm", i))?;
        if count(TransmitterKind::Tcofdm) == 0 {
            return Err(ctx.err(
                "sensors.tcofdm",
                "a TC-OFDM receiver needs at least one [[transmitter]] with kind = \"tcofdm\"",
            ));
        }
        systems.push(System::Tcofdm);
    }
    if let Some(e) = &file.sensors.emitters {
        // Resolved once here so that every error names its key; the source resolves
        // again per trial (the positions are a pure function of the table).
        e.resolve(&EnuFrame::new(Geodetic::from_deg(
            file.world.origin.lat_deg,
            file.world.origin.lon_deg,
            file.world.origin.h_m,
        )))
        .map_err(|i| ctx.issue("sensors.emitters", i))?;
        for s in e.systems() {
            if !systems.contains(&s) {
                systems.push(s);
            }
        }
    }
    if let Some(imu) = &file.sensors.imu {
        imu.validate().map_err(|i| ctx.issue("sensors.imu", i))?;
    }
    if let Some(pdr) = &file.sensors.pdr {
        pdr.validate().map_err(|i| ctx.issue("sensors.pdr", i))?;
    }
    if file.sensors.imu.is_some() || file.sensors.pdr.is_some() {
        file.platform
            .attitude()
            .validate()
            .map_err(|i| ctx.issue("platform.attitude", i))?;
    }
    Ok(systems)
}

/// The sources of position fixes the world simulates.
fn fix_sources(file: &WorldFile) -> Vec<&'static str> {
    let mut v = Vec::new();
    if file.sensors.fm.is_some() {
        v.push(SourceKind::Fm.name());
    }
    if file.sensors.magnetic.is_some() {
        v.push(SourceKind::Magnetic.name());
    }
    v
}

fn check_estimator(
    ctx: &Ctx<'_>,
    i: usize,
    e: &EstimatorSpec,
    simulated: &[System],
    file: &WorldFile,
    build_ctx: &BuildContext<'_>,
) -> Result<(), WorldError> {
    let at = |k: &str| format!("estimator[{i}].{k}");
    if e.name.trim().is_empty() {
        return Err(ctx.err(&at("name"), "expected a non-empty name"));
    }
    if e.sources.is_empty() && e.filter != FilterKind::Pdr {
        return Err(ctx.err(
            &at("sources"),
            "expected a non-empty list of systems, e.g. [\"gps\"]",
        ));
    }
    for (j, s) in e.sources.iter().enumerate() {
        if !simulated.contains(s) {
            let fix = match s {
                System::Dtmb => "add [sensors.dtmb] and a DTMB [[transmitter]]",
                System::Tcofdm => "add [sensors.tcofdm] and a TC-OFDM [[transmitter]]",
                _ => "add it to [sensors.gnss] systems or a [[sensors.emitters.emitter]] of it",
            };
            return Err(ctx.err(
                &at(&format!("sources[{j}]")),
                format!(
                    "the estimator uses '{}', which this world does not simulate ({fix})",
                    s.name()
                ),
            ));
        }
    }
    let needs = |ok: bool, what: &str| {
        if ok {
            Ok(())
        } else {
            Err(ctx.err(&at("filter"), format!("this filter needs {what}")))
        }
    };
    match e.filter {
        FilterKind::Ins => needs(file.sensors.imu.is_some(), "an IMU: add [sensors.imu]")?,
        FilterKind::Pdr => needs(file.sensors.pdr.is_some(), "step events: add [sensors.pdr]")?,
        _ => {}
    }
    // The particle filters only the paper models run take the family's options too.
    let paper_pf = matches!(
        e.filter,
        FilterKind::Sir | FilterKind::Rbpf | FilterKind::Mpf | FilterKind::Gpf
    );
    let kalman = e.filter == FilterKind::Ekf11 || e.filter.family().is_some() || paper_pf;
    if !kalman {
        let extra = [
            ("options", e.options.is_some()),
            ("fixes", !e.fixes.is_empty()),
            ("selection", e.selection.is_some()),
            ("fuzzy", e.fuzzy.is_some()),
            ("dtmb_clock_correction", e.dtmb_clock_correction.is_some()),
        ];
        if let Some((k, _)) = extra.iter().find(|(_, set)| *set) {
            return Err(ctx.err(
                &at(k),
                format!(
                    "'{k}' applies to the filters ekf11, ekf, ukf, ckf, stf, rekf and pf, not to '{}'",
                    format!("{:?}", e.filter).to_lowercase()
                ),
            ));
        }
    }
    if e.options.is_some() && e.filter.family().is_none() && !paper_pf {
        return Err(ctx.err(
            &at("options"),
            "[estimator.options] tunes the filters ekf, ukf, ckf, stf, rekf and pf",
        ));
    }
    if e.fuzzy.is_some() && e.selection != Some(crate::fusion::selection::SelectionKind::Fuzzy) {
        return Err(ctx.err(
            &at("fuzzy"),
            "[estimator.fuzzy] needs selection = \"fuzzy\"",
        ));
    }
    if let Some(c) = &e.dtmb_clock_correction {
        c.validate()
            .map_err(|(k, m)| ctx.err(&at(&format!("dtmb_clock_correction.{k}")), m))?;
    }
    for (j, f) in e.fixes.iter().enumerate() {
        let simulated_fix = fix_sources(file);
        if !simulated_fix.contains(&f.name()) {
            return Err(ctx.err(
                &at(&format!("fixes[{j}]")),
                format!(
                    "'{f}' is not a position-fix source this world simulates (it has: {})",
                    if simulated_fix.is_empty() {
                        "none".to_string()
                    } else {
                        simulated_fix.join(", ")
                    }
                ),
            ));
        }
    }
    if let (FilterKind::Ekf11, Some(cfg)) = (e.filter, &e.ekf) {
        cfg.validate()
            .map_err(|m| ctx.err(&at("ekf"), m.to_string()))?;
    }
    // An option's own complaint ("options.particles: …", "ins.coupling: …") points at
    // that option.
    e.build(build_ctx)
        .map(|_| ())
        .map_err(|m| match m.split_once(": ") {
            Some((k, rest))
                if ["options.", "ins.", "pdr."]
                    .iter()
                    .any(|p| k.starts_with(p))
                    && !k.contains(' ') =>
            {
                ctx.err(&at(k), rest)
            }
            _ => ctx.err(&at("filter"), m),
        })
}

impl World {
    /// The platform trajectory of the trial whose streams `rng` gives (from the
    /// `motion/trajectory` stream, so every caller of one trial gets the same path).
    ///
    /// # Errors
    /// When a stochastic trajectory fails for this trial's draws.
    pub fn build_trajectory(&self, rng: &TrialRng) -> Result<Box<dyn Trajectory>, String> {
        self.file
            .platform
            .trajectory
            .build(&mut rng.stream("motion/trajectory"))
            .map_err(|i| format!("platform.trajectory.{}: {}", i.key, i.message))
    }

    /// The plan view of trial 0's path under the world's seed: ENU `[east, north]` every
    /// 0.5 s (fewer, evenly spaced, when that would exceed `max_points`), ends included —
    /// what maps draw and what regions are fitted around.
    ///
    /// # Errors
    /// When the trajectory cannot be built.
    pub fn track_enu_m(&self, max_points: usize) -> Result<Vec<[f64; 2]>, String> {
        let trajectory = self.build_trajectory(&TrialRng::new(self.file.montecarlo.seed, 0))?;
        let n = ((self.duration_s / 0.5).ceil() as usize).clamp(2, max_points.max(3) - 1);
        Ok((0..=n)
            .map(|k| {
                let t_s = self.duration_s * k as f64 / n as f64;
                let p = trajectory
                    .state_at(SimTime::from_seconds(t_s).seconds())
                    .pos_enu_m;
                [p.x, p.y]
            })
            .collect())
    }

    /// Whether the platform truth is the same in every trial: a waypoint plan or a static
    /// platform draws nothing from the `motion/trajectory` stream (the Singer and turning
    /// models do).
    pub fn truth_is_deterministic(&self) -> bool {
        use crate::motion::TrajectoryConfig as T;
        matches!(
            self.file.platform.trajectory,
            T::Waypoints { .. } | T::Static { .. }
        )
    }

    /// The deterministic epochs the trials of `master_seed` share, built on first use
    /// (see [`crate::engine::cache`]); `None` when the truth changes from trial to trial,
    /// or when the cache is off ([`World::set_epoch_cache`]).
    ///
    /// # Errors
    /// When the cache cannot be built (as the trial itself could not be).
    pub fn epoch_cache(&self, master_seed: u64) -> Result<Option<Arc<cache::EpochCache>>, String> {
        if !self.truth_is_deterministic() {
            return Ok(None);
        }
        self.epoch_cache.get_or_build(master_seed, |bound| {
            cache::EpochCache::build(self, master_seed, bound)
        })
    }

    /// Turns the per-run epoch cache on (the default) or off. Outputs are byte-identical
    /// either way; off, every trial computes every epoch's geometry itself.
    pub fn set_epoch_cache(&self, enabled: bool) {
        self.epoch_cache.set_enabled(enabled);
    }

    /// The receiver's view of the scene, when the world has one.
    pub fn gnss_scene_view(&self) -> Option<SceneView> {
        self.scene
            .as_ref()
            .map(|s| SceneView::new(Arc::clone(s), self.frame.clone()))
    }

    /// The trial's receiver clock: its initial state from the stream
    /// `receiver/clock/init`, its random walk recorded on a 0.1 s grid from
    /// `receiver/clock`. Every radio source of the trial shares it, and a world IQ
    /// recording of the same trial draws the very same clock here.
    pub fn receiver_clock(&self, rng: &TrialRng) -> ClockTrack {
        ClockTrack::record(
            ReceiverClock::new(
                &self.file.receiver.clock,
                &mut rng.stream("receiver/clock/init"),
            ),
            self.duration_s,
            0.1,
            &mut rng.stream("receiver/clock"),
        )
    }

    /// The trial's DTMB receiver (`[sensors.dtmb]`, the world's DTMB transmitters), aided
    /// by estimator `aid` when the receiver is configured `aided`; `None` without
    /// `[sensors.dtmb]`.
    ///
    /// # Errors
    /// When the receiver or a tower is invalid.
    pub fn dtmb_source(
        &self,
        clock: Arc<ClockTrack>,
        aid: Option<usize>,
        rng: &TrialRng,
        end: SimTime,
    ) -> Result<Option<DtmbSource>, String> {
        let Some(d) = &self.file.sensors.dtmb else {
            return Ok(None);
        };
        let towers = self
            .transmitters
            .iter()
            .filter(|t| t.kind == TransmitterKind::Dtmb)
            .map(|t| t.tower_spec(System::Dtmb))
            .collect();
        DtmbSource::new(
            d.clone(),
            towers,
            self.scene.clone(),
            self.frame.clone(),
            clock,
            aid.filter(|_| d.aided),
            rng,
            end,
        )
        .map(Some)
        .map_err(|i| format!("sensors.dtmb.{}: {}", i.key, i.message))
    }

    /// The trial's TC-OFDM receiver over the world's `kind = "tcofdm"` base stations
    /// (`None` without `[sensors.tcofdm]`), aided by estimator `aid` when the receiver is.
    ///
    /// # Errors
    /// An unusable `[sensors.tcofdm]`.
    pub fn tcofdm_source(
        &self,
        clock: Arc<ClockTrack>,
        aid: Option<usize>,
        rng: &TrialRng,
        end: SimTime,
    ) -> Result<Option<TcofdmSource>, String> {
        let Some(tc) = &self.file.sensors.tcofdm else {
            return Ok(None);
        };
        let stations = self
            .transmitters
            .iter()
            .filter(|t| t.kind == TransmitterKind::Tcofdm)
            .map(|t| BaseStationSpec::from(t.tower_spec(System::Tcofdm)))
            .collect();
        TcofdmSource::new(
            tc.clone(),
            stations,
            self.scene.clone(),
            self.frame.clone(),
            clock,
            aid.filter(|_| tc.aided),
            rng,
            end,
        )
        .map(Some)
        .map_err(|i| format!("sensors.tcofdm.{}: {}", i.key, i.message))
    }

    /// Builds the trajectory, sources and estimators of one trial.
    ///
    /// # Errors
    /// When a part cannot be built (validation builds each once, so this is rare: a
    /// stochastic trajectory that fails for this trial's draws).
    pub fn build_trial(&self, rng: &TrialRng) -> Result<TrialSetup, String> {
        let end = SimTime::from_seconds(self.duration_s);
        let trajectory = self.build_trajectory(rng)?;
        let sensors = &self.file.sensors;
        let mut sources: Vec<Box<dyn crate::measurement::Source>> = Vec::new();
        // One receiver clock for every radio source of the trial.
        let clock = Arc::new(self.receiver_clock(rng));
        let err = |t: &str, i: crate::core::ConfigIssue| format!("{t}.{}: {}", i.key, i.message);
        let cache = self.epoch_cache(rng.master_seed())?;
        if let Some(g) = &sensors.gnss {
            sources.push(Box::new(
                GnssSource::new(
                    g.clone(),
                    Arc::clone(&self.nav),
                    self.shielding.clone(),
                    self.gnss_scene_view(),
                    Arc::clone(&clock),
                    rng,
                    end,
                )
                .with_table(cache.as_ref().and_then(|c| c.gnss.clone())),
            ));
        }
        // A terrestrial receiver aided in closed loop centres its search on the first
        // estimator that uses its system.
        let aid = |sys: System| {
            self.file
                .estimators
                .iter()
                .position(|e| e.sources.contains(&sys))
        };
        if let Some(d) = self.dtmb_source(Arc::clone(&clock), aid(System::Dtmb), rng, end)? {
            sources.push(Box::new(d));
        }
        if let Some(tc) = self.tcofdm_source(Arc::clone(&clock), aid(System::Tcofdm), rng, end)? {
            sources.push(Box::new(tc));
        }
        if let Some(e) = &sensors.emitters {
            sources.push(Box::new(
                crate::beacons::EmittersSource::new(e, &self.frame, rng, end)
                    .map_err(|i| err("sensors.emitters", i))?,
            ));
        }
        if let Some(fm) = &sensors.fm {
            let db = self
                .fm_database(rng.master_seed())?
                .ok_or("sensors.fm: no fingerprint database")?;
            let aid = self
                .file
                .estimators
                .iter()
                .position(|e| e.fixes.contains(&SourceKind::Fm));
            sources.push(Box::new(
                crate::fm::FmSource::new(
                    fm.clone(),
                    fm::stations(self),
                    self.scene.clone(),
                    self.frame.clone(),
                    db,
                    rng,
                    aid,
                    end,
                )
                .map_err(|i| err("sensors.fm", i))?
                .with_table(cache.as_ref().and_then(|c| c.fm.clone())),
            ));
        }
        let attitude = self.file.platform.attitude();
        if let Some(m) = &sensors.magnetic {
            let anomalies = self
                .file
                .scene
                .as_ref()
                .map_or(&[][..], |s| &s.magnetic_anomalies[..]);
            let tower = self
                .transmitters
                .iter()
                .find(|t| t.kind == TransmitterKind::Dtmb)
                .map(|t| t.pos_enu_m);
            sources.push(Box::new(
                crate::magnetic::source::MagneticSource::new(
                    m,
                    anomalies,
                    &attitude,
                    self.build_trajectory(&TrialRng::new(rng.master_seed(), 0))?,
                    self.build_trajectory(rng)?,
                    &self.frame,
                    self.start,
                    tower,
                    rng,
                    end,
                )
                .map_err(|i| err("sensors.magnetic", i))?,
            ));
        }
        // The inertial sources own a copy of the same (deterministic) trajectory.
        let rebuild = || self.build_trajectory(rng);
        if let Some(imu) = &sensors.imu {
            sources.push(Box::new(
                ImuSource::new(imu, &attitude, rebuild()?, &self.frame, rng, end)
                    .map_err(|i| err("sensors.imu", i))?,
            ));
        }
        if let Some(pdr) = &sensors.pdr {
            // The phone's magnetometer reads the world's field: IGRF-14 at the origin and
            // start date plus the scene's anomalies, the field the landmark matcher sees.
            let anomalies = self
                .file
                .scene
                .as_ref()
                .map_or(&[][..], |s| &s.magnetic_anomalies[..]);
            let earth = crate::magnetic::EarthField::igrf14(
                &self.frame.origin(),
                crate::magnetic::source::decimal_year(self.start),
            )
            .map_err(|e| {
                err(
                    "sensors.pdr",
                    crate::core::ConfigIssue::new("world.start", e.to_string()),
                )
            })?;
            let scene = crate::magnetic::MagneticScene::new(earth, anomalies).map_err(|e| {
                err(
                    "sensors.pdr",
                    crate::core::ConfigIssue::new("magnetic_anomaly", e.to_string()),
                )
            })?;
            sources.push(Box::new(
                PdrSource::in_scene(
                    pdr,
                    &attitude,
                    rebuild()?,
                    &self.frame,
                    Some(Box::new(scene)),
                    rng,
                    end,
                )
                .map_err(|i| err("sensors.pdr", i))?,
            ));
        }
        let ctx = BuildContext {
            frame: &self.frame,
            start: self.start,
            imu: sensors.imu.as_ref(),
            start_enu_m: trajectory.state_at(0.0).pos_enu_m,
            rng: *rng,
            emitter_clocks_m: sensors.emitters.as_ref().map(|e| e.clocks_m()),
        };
        let estimators = self
            .file
            .estimators
            .iter()
            .map(|e| e.build(&ctx))
            .collect::<Result<Vec<_>, _>>()?;
        let scoring = self.scoring(sources.iter().map(|s| s.kind()));
        Ok(TrialSetup {
            trajectory,
            sources,
            estimators,
            end,
            scoring,
            health: self.comparison.health.clone(),
        })
    }

    /// When this world's estimators are scored, for a trial with sources of these kinds
    /// (the `[scoring]` table, or the default: the GNSS epochs).
    pub fn scoring(&self, kinds: impl IntoIterator<Item = SourceKind>) -> Scoring {
        let sc = &self.file.scoring;
        let mut s = match (&sc.sources, sc.rate_hz) {
            (_, Some(rate_hz)) => Scoring {
                instants: ScoringInstants::Periodic {
                    first: SimTime(0),
                    period: SimTime::from_seconds(1.0 / rate_hz),
                },
                coast_limit_s: Scoring::DEFAULT_COAST_LIMIT_S,
                rpe_delta_s: Scoring::DEFAULT_RPE_DELTA_S,
            },
            (Some(list), None) => Scoring {
                instants: ScoringInstants::Sources(list.clone()),
                coast_limit_s: Scoring::DEFAULT_COAST_LIMIT_S,
                rpe_delta_s: Scoring::DEFAULT_RPE_DELTA_S,
            },
            (None, None) => Scoring::default_for(kinds),
        };
        if let Some(c) = sc.coast_limit_s {
            s.coast_limit_s = c;
        }
        if let Some(d) = sc.rpe_delta_s {
            s.rpe_delta_s = d;
        }
        s
    }

    /// A human-readable summary for `hybridnav check`.
    pub fn summary(&self) -> String {
        use std::fmt::Write;
        let f = &self.file;
        let o = self.frame.origin();
        let mut s = String::new();
        let _ = writeln!(s, "world      {}", f.world.name);
        let _ = writeln!(s, "file       {} (hash {})", self.path.display(), self.hash);
        let _ = writeln!(
            s,
            "origin     {:.6}° N, {:.6}° E, {:.1} m",
            o.lat_deg(),
            o.lon_deg(),
            o.h_m
        );
        let _ = writeln!(
            s,
            "start      {} (GPS week {}, tow {:.3} s)",
            self.start,
            self.start.week(),
            self.start.tow_s()
        );
        let _ = writeln!(s, "duration   {:.1} s", self.duration_s);
        let per_sys = |sys: System| {
            let mut v: Vec<_> = self
                .nav
                .ephemerides
                .iter()
                .filter(|e| e.sat.system == sys)
                .map(|e| e.sat)
                .collect();
            v.sort();
            v.dedup();
            v.len()
        };
        let _ = writeln!(
            s,
            "ephemeris  {}: {} GPS and {} BeiDou satellites, {} records",
            self.nav_source,
            per_sys(System::Gps),
            per_sys(System::Bds),
            self.nav.ephemerides.len()
        );
        let _ = writeln!(s, "platform   {:?}", f.platform.kind);
        if let Some(g) = &f.sensors.gnss {
            let names: Vec<&str> = g.systems.iter().map(|s| s.name()).collect();
            let _ = writeln!(
                s,
                "gnss       {} at {} Hz, mask {}°",
                names.join("+"),
                g.rate_hz,
                g.elevation_mask_deg
            );
        }
        if let Some(e) = &f.sensors.emitters {
            let counts: Vec<String> = e
                .systems()
                .iter()
                .map(|sys| {
                    let n = e.emitters.iter().filter(|x| x.system == *sys).count();
                    format!("{n} {}", sys.name())
                })
                .collect();
            let _ = writeln!(
                s,
                "emitters   {} at fixed positions, {} Hz",
                counts.join(" + "),
                e.rate_hz
            );
        }
        for w in &self.shielding {
            let _ = writeln!(
                s,
                "shielding  {:.0}–{:.0} s: {:?}",
                w.from_s, w.to_s, w.rule
            );
        }
        if let (Some(sec), Some(scene)) = (&f.scene, &self.scene) {
            let _ = writeln!(
                s,
                "scene      {} buildings, {} forests, {} tree rows, {} indoor zones, {} surfaces",
                scene.building_count(),
                sec.forests.len(),
                sec.tree_rows.len(),
                sec.indoor_zones.len(),
                sec.surfaces.len()
            );
        }
        for t in &self.transmitters {
            let p = &t.pos_enu_m;
            let _ = writeln!(
                s,
                "transmitter {:<4} {:<7} {:>8.3} MHz {:>7.1} kW at [{:.0}, {:.0}, {:.0}] m ENU ({:.2} km){}",
                t.id,
                t.kind.label(),
                t.freq_hz * 1e-6,
                t.spec.erp_kw,
                p.x,
                p.y,
                p.z,
                p.xy().norm() / 1e3,
                t.name.as_deref().map(|n| format!(" {n}")).unwrap_or_default()
            );
        }
        for e in &f.estimators {
            let names: Vec<&str> = e.sources.iter().map(|s| s.name()).collect();
            let _ = writeln!(
                s,
                "estimator  {:<14} {:?} on {}",
                e.name,
                e.filter,
                names.join("+")
            );
        }
        let _ = writeln!(
            s,
            "montecarlo {} trials, seed {}",
            f.montecarlo.trials, f.montecarlo.seed
        );
        s
    }
}
