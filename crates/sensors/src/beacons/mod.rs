//! Abstract emitters at fixed positions: the measurement source of seeds 001 and 003.
//!
//! Both papers simulate their receivers without any signal, orbit or propagation model:
//! "3 GPS satellites and 3 DTMB stations" (seed 001, §5) and "three GPS satellite signals,
//! two Beidou satellites, and one DTMB signal" (seed 003, §3.1) at known coordinates, each
//! giving a pseudorange with Gaussian noise once a second. This module is that source
//! (`[sensors.emitters]`, source name `"emitters"`): a list of emitters, each with its
//! system and a fixed position in the world's ENU frame, and the clock terms of the
//! papers' pseudorange equations.
//!
//! # The measurement
//!
//! ```text
//! ρ_j = ‖r_j − r‖ + b_u + b_sys(j) + ε_j,    ε_j ~ N(0, σ_sys(j)²)
//! ```
//!
//! * Seed 001, eq. 1: `ρ_G = ‖r_i − r_u‖ + b_u` and `ρ_D = ‖r_D − r_u‖ + b_u + b_D`, with
//!   `b_u` the receiver clock offset and `b_D` the DTMB-to-GPS time offset (both in metres):
//!   `receiver_clock_m = b_u`, `clock_offset_m = { dtmb = b_D }`.
//! * Seed 003, eqs. 1–3: one clock deviation per system, `a₁` (GPS), `a₂` (BeiDou) and
//!   `a₃` (DTMB): `clock_offset_m = { gps = a₁, bds = a₂, dtmb = a₃ }` and
//!   `receiver_clock_m = 0`.
//!
//! The offsets are constants, as the papers write them. An emitter may be switched off in
//! time windows (`outages_s`), which is how a world exercises seed 003's seamless scheme
//! (Table 1 switches on the number of GPS satellites received).
//!
//! Each emitter's noise comes from its own random stream `emitters/<id>`, so adding an
//! emitter changes no other emitter's numbers. The measurements carry the emitter's
//! position (as a receiver would know a satellite's or a tower's) and the σ of the noise,
//! never the truth.

use crate::core::rng::StreamRng;
use crate::core::{ConfigIssue, EmitterId, EnuFrame, SimTime, System, TrialRng};
use crate::measurement::{
    Measurement, MeasurementBatch, RangeMeasurement, SampleContext, Source, SourceKind,
};
use nalgebra::Vector3;
use rand::Rng;
use rand_distr::StandardNormal;
use serde::Deserialize;

/// The source's name, which estimators select it by.
pub const SOURCE_NAME: &str = "emitters";

/// A value per system (`{ gps = …, bds = …, dtmb = …, tcofdm = … }`), every key optional.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct PerSystem {
    pub gps: Option<f64>,
    pub bds: Option<f64>,
    pub dtmb: Option<f64>,
    pub tcofdm: Option<f64>,
}

impl PerSystem {
    /// The value of `s`, if given.
    pub fn get(&self, s: System) -> Option<f64> {
        match s {
            System::Gps => self.gps,
            System::Bds => self.bds,
            System::Dtmb => self.dtmb,
            System::Tcofdm => self.tcofdm,
        }
    }

    fn entries(&self) -> [(&'static str, Option<f64>); 4] {
        [
            ("gps", self.gps),
            ("bds", self.bds),
            ("dtmb", self.dtmb),
            ("tcofdm", self.tcofdm),
        ]
    }
}

/// One `[[sensors.emitters.emitter]]`: exactly one of `position_enu_m` and the triple
/// `azimuth_deg`, `elevation_deg`, `range_m` (a satellite seen from the ENU origin).
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EmitterSpec {
    /// `gps`, `bds`, `dtmb` or `tcofdm`.
    pub system: System,
    /// Identifier (`G01`, `C02`, `D01`); default: the system's letter and the emitter's
    /// rank among the world's emitters of that system.
    #[serde(default)]
    pub id: Option<String>,
    /// Position in the world's ENU frame (m).
    #[serde(default)]
    pub position_enu_m: Option<[f64; 3]>,
    /// Azimuth from north, clockwise (degrees), seen from the ENU origin.
    #[serde(default)]
    pub azimuth_deg: Option<f64>,
    /// Elevation above the local horizontal plane (degrees).
    #[serde(default)]
    pub elevation_deg: Option<f64>,
    /// Distance from the ENU origin (m).
    #[serde(default)]
    pub range_m: Option<f64>,
    /// Range noise σ (m) of this emitter; default the system's in `sigma_m`.
    #[serde(default)]
    pub sigma_m: Option<f64>,
    /// Windows `[from_s, to_s)` (seconds after the start) in which the emitter is not
    /// received.
    #[serde(default)]
    pub outages_s: Vec<[f64; 2]>,
}

/// `[sensors.emitters]`.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EmittersConfig {
    /// Measurement rate (Hz); default 1 (both papers: "interval 1 s").
    #[serde(default = "one_hz")]
    pub rate_hz: f64,
    /// Range noise σ (m) per system.
    #[serde(default)]
    pub sigma_m: PerSystem,
    /// The receiver clock offset `b_u` (m) common to every range (seed 001 eq. 1).
    #[serde(default)]
    pub receiver_clock_m: f64,
    /// The clock offset (m) of each system's ranges on top of `receiver_clock_m`: seed 001's
    /// DTMB-to-GPS offset `b_D`, seed 003's `a₁`, `a₂`, `a₃`. Default 0.
    #[serde(default)]
    pub clock_offset_m: PerSystem,
    /// The emitters (at least one).
    #[serde(default, rename = "emitter")]
    pub emitters: Vec<EmitterSpec>,
}

fn one_hz() -> f64 {
    1.0
}

/// One emitter resolved: id, positions, noise.
#[derive(Clone, Debug, PartialEq)]
pub struct ResolvedEmitter {
    pub id: EmitterId,
    pub pos_enu_m: Vector3<f64>,
    pub pos_ecef_m: Vector3<f64>,
    pub sigma_m: f64,
    pub outages_s: Vec<[f64; 2]>,
}

impl ResolvedEmitter {
    /// Whether the emitter is in one of its outage windows at `t_s` (seconds after the
    /// start).
    pub fn in_outage(&self, t_s: f64) -> bool {
        self.outages_s.iter().any(|w| t_s >= w[0] && t_s < w[1])
    }

    /// The range measurement a receiver at `receiver_ecef_m` makes of this emitter with
    /// pseudorange `pseudorange_m` (the geometric range plus whatever clock and noise the
    /// caller adds) and the emitter's σ.
    pub fn range_measurement(
        &self,
        receiver_ecef_m: &Vector3<f64>,
        pseudorange_m: f64,
    ) -> RangeMeasurement {
        let d = self.pos_ecef_m - receiver_ecef_m;
        // The geocentric vertical: the elevation is informative only.
        let up = receiver_ecef_m.normalize();
        RangeMeasurement {
            emitter: self.id,
            emitter_pos_ecef_m: self.pos_ecef_m,
            emitter_vel_ecef_mps: Vector3::zeros(),
            pseudorange_m,
            sigma_m: self.sigma_m,
            range_rate_mps: None,
            sigma_rate_mps: 1.0,
            cn0_dbhz: 45.0,
            elevation_rad: (d.dot(&up) / d.norm()).clamp(-1.0, 1.0).asin(),
        }
    }
}

fn issue(key: impl Into<String>, message: impl Into<String>) -> ConfigIssue {
    ConfigIssue {
        key: key.into(),
        message: message.into(),
    }
}

impl EmittersConfig {
    /// The sampling period (ns) of `rate_hz`.
    pub fn period_ns(&self) -> i64 {
        ((1e9 / self.rate_hz).round() as i64).max(1)
    }

    /// The total clock term (m) of a system's ranges, `b_u + b_sys`.
    pub fn clock_m(&self, s: System) -> f64 {
        self.receiver_clock_m + self.clock_offset_m.get(s).unwrap_or(0.0)
    }

    /// The clock term of every system, indexed like [`System::ALL`].
    pub fn clocks_m(&self) -> [f64; System::COUNT] {
        System::ALL.map(|s| self.clock_m(s))
    }

    /// The systems the emitters belong to, in [`System::ALL`] order.
    pub fn systems(&self) -> Vec<System> {
        System::ALL
            .into_iter()
            .filter(|s| self.emitters.iter().any(|e| e.system == *s))
            .collect()
    }

    /// Checks every value and resolves the emitters' positions in `frame`.
    ///
    /// # Errors
    /// A [`ConfigIssue`] naming the key: no emitters, a σ that is missing, zero or negative,
    /// a position given twice or not at all, a duplicate id, a bad outage window.
    pub fn resolve(&self, frame: &EnuFrame) -> Result<Vec<ResolvedEmitter>, ConfigIssue> {
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 1000.0) {
            return Err(issue(
                "rate_hz",
                format!("expected a rate in (0, 1000] Hz, got {}", self.rate_hz),
            ));
        }
        for (k, v) in self.sigma_m.entries() {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0) {
                    return Err(issue(
                        format!("sigma_m.{k}"),
                        format!("expected a noise σ > 0 m, got {v}"),
                    ));
                }
            }
        }
        for (k, v) in self.clock_offset_m.entries() {
            if let Some(v) = v {
                if !(v.is_finite() && v.abs() <= 1e9) {
                    return Err(issue(
                        format!("clock_offset_m.{k}"),
                        format!("expected a finite offset in m (|b| ≤ 1e9), got {v}"),
                    ));
                }
            }
        }
        if !(self.receiver_clock_m.is_finite() && self.receiver_clock_m.abs() <= 1e9) {
            return Err(issue(
                "receiver_clock_m",
                format!(
                    "expected a finite offset in m (|b| ≤ 1e9), got {}",
                    self.receiver_clock_m
                ),
            ));
        }
        if self.emitters.is_empty() {
            return Err(issue(
                "emitter",
                "expected at least one [[sensors.emitters.emitter]] table",
            ));
        }
        let mut out: Vec<ResolvedEmitter> = Vec::with_capacity(self.emitters.len());
        let mut rank = [0u16; System::COUNT];
        for (i, e) in self.emitters.iter().enumerate() {
            let at = |k: &str| format!("emitter[{i}].{k}");
            let s = e.system.index();
            rank[s] += 1;
            let id = match &e.id {
                Some(text) => {
                    let id: EmitterId = text.parse().map_err(|m: String| issue(at("id"), m))?;
                    if id.system != e.system {
                        return Err(issue(
                            at("id"),
                            format!(
                                "id '{text}' names a {} emitter, but system = \"{}\"",
                                id.system.name(),
                                e.system.name()
                            ),
                        ));
                    }
                    id
                }
                None => EmitterId::new(e.system, rank[s]),
            };
            if out.iter().any(|o| o.id == id) {
                return Err(issue(at("id"), format!("emitter id {id} is used twice")));
            }
            let sigma_m = match e.sigma_m.or(self.sigma_m.get(e.system)) {
                Some(v) if v.is_finite() && v > 0.0 => v,
                Some(v) => {
                    return Err(issue(
                        at("sigma_m"),
                        format!("expected a noise σ > 0 m, got {v}"),
                    ))
                }
                None => {
                    return Err(issue(
                        at("sigma_m"),
                        format!(
                            "no range noise for this {} emitter: set sigma_m here or sigma_m.{} in [sensors.emitters]",
                            e.system.name(),
                            e.system.name()
                        ),
                    ))
                }
            };
            let angles = [e.azimuth_deg, e.elevation_deg, e.range_m];
            let pos_enu_m = match (e.position_enu_m, angles) {
                (Some(p), [None, None, None]) => {
                    if !p.iter().all(|v| v.is_finite() && v.abs() <= 1e9) {
                        return Err(issue(
                            at("position_enu_m"),
                            "expected finite coordinates in m (|x| ≤ 1e9)",
                        ));
                    }
                    Vector3::from(p)
                }
                (None, [Some(az), Some(el), Some(r)]) => {
                    if !(az.is_finite() && (-90.0..=90.0).contains(&el) && r > 0.0 && r <= 1e9) {
                        return Err(issue(
                            at("elevation_deg"),
                            format!(
                                "expected a finite azimuth, an elevation in [-90, 90]° and a range in (0, 1e9] m, got {az}°, {el}°, {r} m"
                            ),
                        ));
                    }
                    let (a, l) = (az.to_radians(), el.to_radians());
                    Vector3::new(a.sin() * l.cos(), a.cos() * l.cos(), l.sin()) * r
                }
                _ => {
                    return Err(issue(
                        at("position_enu_m"),
                        "expected either position_enu_m or all of azimuth_deg, elevation_deg and range_m",
                    ))
                }
            };
            for (k, w) in e.outages_s.iter().enumerate() {
                if !(w[0].is_finite() && w[1].is_finite() && w[0] < w[1]) {
                    return Err(issue(
                        format!("emitter[{i}].outages_s[{k}]"),
                        format!("expected [from_s, to_s] with from_s < to_s, got {w:?}"),
                    ));
                }
            }
            out.push(ResolvedEmitter {
                id,
                pos_enu_m,
                pos_ecef_m: frame.ecef_of_enu(&pos_enu_m),
                sigma_m,
                outages_s: e.outages_s.clone(),
            });
        }
        Ok(out)
    }
}

/// The source: every `1/rate_hz` seconds, one range to each emitter not in an outage.
pub struct EmittersSource {
    emitters: Vec<ResolvedEmitter>,
    clocks_m: [f64; System::COUNT],
    rngs: Vec<StreamRng>,
    period_ns: i64,
    end: SimTime,
}

impl EmittersSource {
    /// A source over `cfg`'s emitters in `frame`, drawing its noise from `rng`'s streams
    /// `emitters/<id>` and sampling until `end`.
    ///
    /// # Errors
    /// The configuration's first [`ConfigIssue`].
    pub fn new(
        cfg: &EmittersConfig,
        frame: &EnuFrame,
        rng: &TrialRng,
        end: SimTime,
    ) -> Result<Self, ConfigIssue> {
        let emitters = cfg.resolve(frame)?;
        let rngs = emitters
            .iter()
            .map(|e| rng.stream(&format!("emitters/{}", e.id)))
            .collect();
        Ok(Self {
            emitters,
            clocks_m: cfg.clocks_m(),
            rngs,
            period_ns: cfg.period_ns(),
            end,
        })
    }
}

impl Source for EmittersSource {
    fn kind(&self) -> SourceKind {
        SourceKind::Emitters
    }

    /// The first sample is one period after the start: the papers' filters start from the
    /// known X(0) and take their first measurement at k = 1.
    fn first_sample(&self) -> SimTime {
        SimTime(self.period_ns)
    }

    fn sample(&mut self, ctx: &SampleContext<'_>, out: &mut MeasurementBatch) -> Option<SimTime> {
        let truth = ctx.truth;
        out.t = truth.t;
        out.source = SourceKind::Emitters;
        let t_s = truth.sim.seconds();
        for (e, rng) in self.emitters.iter().zip(self.rngs.iter_mut()) {
            // The noise is drawn even in an outage, so an emitter's noise sequence does
            // not depend on when it is received.
            let n: f64 = rng.sample(StandardNormal);
            if e.in_outage(t_s) {
                continue;
            }
            let range_m = (e.pos_ecef_m - truth.pos_ecef_m).norm();
            let pseudorange_m = range_m + self.clocks_m[e.id.system.index()] + e.sigma_m * n;
            out.items.push(Measurement::Range(
                e.range_measurement(&truth.pos_ecef_m, pseudorange_m),
            ));
        }
        let next = SimTime(truth.sim.0 + self.period_ns);
        (next <= self.end).then_some(next)
    }

    /// An epoch with every emitter in an outage is still an epoch (the filters predict
    /// through it and the metrics count it).
    fn empty_batches_are_epochs(&self) -> bool {
        true
    }
}
