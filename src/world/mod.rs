//! World files: the TOML description of one scenario, validated into a [`World`].
//!
//! Every error names the file, the line and column, and what was expected: syntax and type
//! errors through the spans serde reports, value checks made after deserialisation through
//! [`locate`], which maps a key path back to the text.

pub mod locate;
pub mod schema;

use crate::core::{EmitterId, EnuFrame, Geodetic, GpsTime, SimTime, System, TrialRng};
use crate::gnss::measurement::{GnssSource, Shielding, ShieldingRule};
use crate::gnss::receiver_clock::ReceiverClock;
use crate::gnss::rinex_nav::{parse_nav, read_nav_file, NavData};
use crate::motion::Trajectory;
use locate::{locate, path_to_string, PathSeg};
use schema::{EstimatorSpec, FilterKind, WorldFile};
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The navigation file embedded in the binary: the nominal GPS + BeiDou constellation that
/// `hybridnav ephemeris synth` writes, used when a world names no ephemeris.
pub const BUILTIN_EPHEMERIS: &str = include_str!("../../ephemeris/nominal-gps-bds.rnx");
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
    /// Scenario length.
    pub duration_s: f64,
    /// Shielding windows with their satellites parsed.
    pub shielding: Vec<Shielding>,
}

/// Everything a trial needs, freshly built from the world and the trial's random streams.
pub struct TrialSetup {
    pub trajectory: Box<dyn Trajectory>,
    pub sources: Vec<Box<dyn crate::engine::Source>>,
    pub estimators: Vec<Box<dyn crate::fusion::estimator::Estimator>>,
    pub end: SimTime,
}

struct Ctx<'a> {
    path: &'a Path,
    text: &'a str,
}

impl Ctx<'_> {
    fn err(&self, path: &[PathSeg], message: impl Into<String>) -> WorldError {
        let (line, column) = locate(self.text, path);
        WorldError {
            file: self.path.to_path_buf(),
            line,
            column,
            key: path_to_string(path),
            message: message.into(),
        }
    }
}

fn key(k: &str) -> PathSeg {
    PathSeg::Key(k.to_string())
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
    let text = std::fs::read_to_string(path).map_err(|e| WorldError {
        file: path.to_path_buf(),
        line: 0,
        column: 0,
        key: String::new(),
        message: format!("cannot read the world file: {e}"),
    })?;
    parse_world(&text, path)
}

/// Validates world text as if read from `path` (relative paths inside it are resolved
/// against `path`'s directory).
pub fn parse_world(text: &str, path: &Path) -> Result<World, WorldError> {
    let ctx = Ctx { path, text };
    let file: WorldFile = toml::from_str(text).map_err(|e| {
        let (line, column) = e.span().map_or((1, 1), |s| locate::line_col(text, s.start));
        WorldError {
            file: path.to_path_buf(),
            line,
            column,
            key: String::new(),
            message: e.message().trim().to_string(),
        }
    })?;

    let w = &file.world;
    let origin_path = [key("world"), key("origin")];
    let o = &w.origin;
    if !(o.lat_deg.is_finite() && (-90.0..=90.0).contains(&o.lat_deg)) {
        return Err(ctx.err(
            &[key("world"), key("origin"), key("lat_deg")],
            format!(
                "expected a latitude in degrees within −90..90, got {}",
                o.lat_deg
            ),
        ));
    }
    if !(o.lon_deg.is_finite() && (-180.0..=360.0).contains(&o.lon_deg)) {
        return Err(ctx.err(
            &[key("world"), key("origin"), key("lon_deg")],
            format!(
                "expected a longitude in degrees within −180..360, got {}",
                o.lon_deg
            ),
        ));
    }
    if !(o.h_m.is_finite() && (-500.0..=10_000.0).contains(&o.h_m)) {
        return Err(ctx.err(
            &origin_path,
            format!(
                "expected an ellipsoidal height within −500..10000 m, got {}",
                o.h_m
            ),
        ));
    }
    let start =
        GpsTime::parse_iso(&w.start).map_err(|m| ctx.err(&[key("world"), key("start")], m))?;

    let traj_path = [key("platform"), key("trajectory")];
    file.platform.trajectory.validate().map_err(|issue| {
        let mut p = traj_path.to_vec();
        p.push(key(&issue.key));
        ctx.err(&p, issue.message)
    })?;

    if let Some(d) = w.duration_s {
        if !(d.is_finite() && d > 0.0 && d <= 10.0 * 86_400.0) {
            return Err(ctx.err(
                &[key("world"), key("duration_s")],
                format!("expected a duration in seconds within (0, 864000], got {d}"),
            ));
        }
    }

    // Navigation data: a file relative to the world file, or the embedded default.
    let (nav, nav_source) = match w.ephemeris.as_deref() {
        None | Some(BUILTIN_EPHEMERIS_NAME) => {
            let nav = parse_nav(BUILTIN_EPHEMERIS, BUILTIN_EPHEMERIS_NAME).map_err(|e| {
                ctx.err(
                    &[key("world"), key("ephemeris")],
                    format!("the embedded ephemeris does not parse: {e}"),
                )
            })?;
            (nav, BUILTIN_EPHEMERIS_NAME.to_string())
        }
        Some(rel) => {
            let base = path.parent().unwrap_or(Path::new("."));
            let p = base.join(rel);
            if !p.exists() {
                return Err(ctx.err(&[key("world"), key("ephemeris")], format!("navigation file {} does not exist (paths are relative to the world file; use \"{BUILTIN_EPHEMERIS_NAME}\" for the embedded one)", p.display())));
            }
            let nav = read_nav_file(&p).map_err(|e| {
                ctx.err(
                    &[key("world"), key("ephemeris")],
                    format!("cannot use navigation file: {e}"),
                )
            })?;
            (nav, p.display().to_string())
        }
    };

    // GNSS sensor checks.
    if let Some(g) = &file.sensors.gnss {
        let gp = [key("sensors"), key("gnss")];
        if !(g.rate_hz.is_finite() && g.rate_hz > 0.0 && g.rate_hz <= 100.0) {
            let mut p = gp.to_vec();
            p.push(key("rate_hz"));
            return Err(ctx.err(
                &p,
                format!("expected a rate in Hz within (0, 100], got {}", g.rate_hz),
            ));
        }
        if !(g.elevation_mask_deg.is_finite() && (-5.0..90.0).contains(&g.elevation_mask_deg)) {
            let mut p = gp.to_vec();
            p.push(key("elevation_mask_deg"));
            return Err(ctx.err(
                &p,
                format!(
                    "expected an elevation mask in degrees within −5..90, got {}",
                    g.elevation_mask_deg
                ),
            ));
        }
        if g.systems.is_empty() || g.systems.iter().any(|s| !s.is_gnss()) {
            let mut p = gp.to_vec();
            p.push(key("systems"));
            return Err(ctx.err(
                &p,
                "expected a non-empty list of satellite systems from \"gps\", \"bds\"",
            ));
        }
        for (i, s) in g.systems.iter().enumerate() {
            if !nav.ephemerides.iter().any(|e| e.sat.system == *s) {
                let mut p = gp.to_vec();
                p.push(key("systems"));
                p.push(PathSeg::Index(i));
                return Err(ctx.err(
                    &p,
                    format!(
                        "the navigation data ({nav_source}) has no {} ephemerides",
                        s.name()
                    ),
                ));
            }
        }
        g.tracking.validate().map_err(|issue| {
            let mut p = gp.to_vec();
            p.push(key("tracking"));
            p.push(key(&issue.key));
            ctx.err(&p, issue.message)
        })?;
        let e = &g.errors;
        for (name, v) in [
            ("ure_gps_m", e.ure_gps_m),
            ("ure_bds_m", e.ure_bds_m),
            ("iono_residual", e.iono_residual),
            ("iono_residual_per_sat", e.iono_residual_per_sat),
            ("tropo_residual", e.tropo_residual),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ctx.err(
                    &[key("sensors"), key("gnss"), key("errors"), key(name)],
                    format!("expected a non-negative number, got {v}"),
                ));
            }
        }
        if !(e.ure_tau_s.is_finite() && e.ure_tau_s > 0.0) {
            return Err(ctx.err(
                &[key("sensors"), key("gnss"), key("errors"), key("ure_tau_s")],
                format!(
                    "expected a positive correlation time in s, got {}",
                    e.ure_tau_s
                ),
            ));
        }
        if !(e.humidity.is_finite() && (0.0..=1.0).contains(&e.humidity)) {
            return Err(ctx.err(
                &[key("sensors"), key("gnss"), key("errors"), key("humidity")],
                format!(
                    "expected a relative humidity within 0..1, got {}",
                    e.humidity
                ),
            ));
        }
    }
    // An empty sky: no satellite of the tracked systems has an ephemeris valid at the start.
    if let Some(g) = &file.sensors.gnss {
        let usable = nav
            .satellites()
            .into_iter()
            .filter(|s| g.systems.contains(&s.system))
            .any(|s| nav.select(s, start).is_some());
        if !usable {
            let span = match (
                nav.ephemerides.iter().map(|e| e.toe).min(),
                nav.ephemerides.iter().map(|e| e.toe).max(),
            ) {
                (Some(a), Some(b)) => {
                    format!("its ephemerides have reference times from {a} to {b}")
                }
                _ => "it holds no GPS or BeiDou ephemeris".to_string(),
            };
            return Err(ctx.err(
                &[key("world"), key("start")],
                format!("empty sky: no satellite in {nav_source} has an ephemeris valid at the start {start}; {span}"),
            ));
        }
    }
    file.receiver.clock.validate().map_err(|issue| {
        ctx.err(
            &[key("receiver"), key("clock"), key(&issue.key)],
            issue.message,
        )
    })?;

    // Shielding windows.
    let mut shielding = Vec::with_capacity(file.shielding.len());
    for (i, s) in file.shielding.iter().enumerate() {
        let sp = |k: &str| vec![key("shielding"), PathSeg::Index(i), key(k)];
        if !(s.from_s.is_finite() && s.to_s.is_finite() && s.from_s >= 0.0 && s.to_s > s.from_s) {
            return Err(ctx.err(
                &sp("to_s"),
                format!(
                    "expected 0 ≤ from_s < to_s, got from_s = {}, to_s = {}",
                    s.from_s, s.to_s
                ),
            ));
        }
        let rules = usize::from(s.keep_highest.is_some())
            + usize::from(s.keep.is_some())
            + usize::from(s.block.is_some());
        if rules != 1 {
            return Err(ctx.err(&[key("shielding"), PathSeg::Index(i)], "expected exactly one of keep_highest = N, keep = [\"G05\", …] or block = [\"G05\", …]"));
        }
        let parse_list = |k: &str, list: &[String]| -> Result<Vec<EmitterId>, WorldError> {
            list.iter()
                .enumerate()
                .map(|(j, s)| {
                    let mut p = sp(k);
                    p.push(PathSeg::Index(j));
                    let id: EmitterId = s.parse().map_err(|m: String| ctx.err(&p, m))?;
                    if !nav.ephemerides.iter().any(|e| e.sat == id) {
                        return Err(ctx.err(
                            &p,
                            format!("satellite {id} is not in the navigation data ({nav_source})"),
                        ));
                    }
                    Ok(id)
                })
                .collect()
        };
        let rule = if let Some(n) = s.keep_highest {
            ShieldingRule::KeepHighest(n)
        } else if let Some(l) = &s.keep {
            ShieldingRule::Keep(parse_list("keep", l)?)
        } else {
            ShieldingRule::Block(parse_list("block", s.block.as_deref().unwrap_or(&[]))?)
        };
        shielding.push(Shielding {
            from_s: s.from_s,
            to_s: s.to_s,
            rule,
        });
    }

    // Estimators.
    if file.estimators.is_empty() {
        return Err(ctx.err(&[], "expected at least one [[estimator]] table"));
    }
    let gnss_systems: Vec<System> = file
        .sensors
        .gnss
        .as_ref()
        .map(|g| g.systems.clone())
        .unwrap_or_default();
    for (i, e) in file.estimators.iter().enumerate() {
        check_estimator(&ctx, i, e, &gnss_systems)?;
        if file.estimators[..i].iter().any(|o| o.name == e.name) {
            return Err(ctx.err(
                &[key("estimator"), PathSeg::Index(i), key("name")],
                format!(
                    "estimator name '{}' is used twice; names must be unique",
                    e.name
                ),
            ));
        }
    }

    let mc = &file.montecarlo;
    if mc.trials == 0 {
        return Err(ctx.err(
            &[key("montecarlo"), key("trials")],
            "expected at least 1 trial",
        ));
    }

    // The scenario length: the world's, or the trajectory's.
    let probe = file
        .platform
        .trajectory
        .build(&mut TrialRng::new(0, 0).stream("motion/probe"))
        .map_err(|issue| {
            let mut p = traj_path.to_vec();
            p.push(key(&issue.key));
            ctx.err(&p, issue.message)
        })?;
    let duration_s = w.duration_s.unwrap_or_else(|| probe.duration_s());

    Ok(World {
        path: path.to_path_buf(),
        hash: fnv_hex(text.as_bytes()),
        start,
        frame: EnuFrame::new(Geodetic::from_deg(o.lat_deg, o.lon_deg, o.h_m)),
        nav: Arc::new(nav),
        nav_source,
        duration_s,
        shielding,
        file,
    })
}

fn check_estimator(
    ctx: &Ctx<'_>,
    i: usize,
    e: &EstimatorSpec,
    gnss_systems: &[System],
) -> Result<(), WorldError> {
    let ep = |k: &str| vec![key("estimator"), PathSeg::Index(i), key(k)];
    if e.name.trim().is_empty() {
        return Err(ctx.err(&ep("name"), "expected a non-empty name"));
    }
    if e.sources.is_empty() {
        return Err(ctx.err(
            &ep("sources"),
            "expected a non-empty list of systems, e.g. [\"gps\"]",
        ));
    }
    for (j, s) in e.sources.iter().enumerate() {
        if !gnss_systems.contains(s) {
            let mut p = ep("sources");
            p.push(PathSeg::Index(j));
            return Err(ctx.err(&p, format!("the estimator uses '{}', which this world does not simulate (add it to [sensors.gnss] systems)", s.name())));
        }
    }
    if let (FilterKind::Ekf11, Some(cfg)) = (e.filter, &e.ekf) {
        cfg.validate()
            .map_err(|m| ctx.err(&ep("ekf"), m.to_string()))?;
    }
    if let Err(m) = e.build() {
        return Err(ctx.err(&ep("filter"), m));
    }
    Ok(())
}

impl World {
    /// Builds the trajectory, sources and estimators of one trial.
    ///
    /// # Errors
    /// When a part cannot be built (validation builds each once, so this is rare: a
    /// stochastic trajectory that fails for this trial's draws).
    pub fn build_trial(&self, rng: &TrialRng) -> Result<TrialSetup, String> {
        let end = SimTime::from_seconds(self.duration_s);
        let trajectory = self
            .file
            .platform
            .trajectory
            .build(&mut rng.stream("motion/trajectory"))
            .map_err(|issue| format!("platform.trajectory.{}: {}", issue.key, issue.message))?;
        let mut sources: Vec<Box<dyn crate::engine::Source>> = Vec::new();
        if let Some(g) = &self.file.sensors.gnss {
            let clock = ReceiverClock::new(
                &self.file.receiver.clock,
                &mut rng.stream("receiver/clock/init"),
            );
            sources.push(Box::new(GnssSource::new(
                g.clone(),
                Arc::clone(&self.nav),
                self.shielding.clone(),
                clock,
                rng,
                end,
            )));
        }
        let estimators = self
            .file
            .estimators
            .iter()
            .map(|e| e.build())
            .collect::<Result<Vec<_>, _>>()?;
        Ok(TrialSetup {
            trajectory,
            sources,
            estimators,
            end,
        })
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
        for w in &self.shielding {
            let _ = writeln!(
                s,
                "shielding  {:.0}–{:.0} s: {:?}",
                w.from_s, w.to_s, w.rule
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
