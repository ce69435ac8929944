//! Mode selection inside an estimator: which measurements of a batch it may use.
//!
//! The sources deliver their batches separately (GNSS, DTMB, FM), so the decision is made
//! batch by batch from the latest of each: the GPS geometry of the last GNSS batch, the
//! DTMB towers of the last DTMB batch, the support (reference points in the constraint
//! circle) of the last FM fix. The decision is causal: a batch is judged with what had
//! arrived by its time, as a receiver's navigation processor would.
//!
//! * Seed 000's fuzzy system ([`crate::fusion::mode::FuzzyConfig`]): x₁ = GDOP of GPS,
//!   x₂ = GDOP of GPS + DTMB (one shared clock, as after the paper's DTMB clock
//!   correction, §3.1), x₃ = RPs in the circle; mode A admits the satellites only, B adds
//!   the DTMB ranges, C adds the position fixes too.
//! * Seed 003's seamless scheme ([`crate::fusion::mode::seamless_mode`]): more than four
//!   GPS satellites → GPS + BDS, one to four → GPS + BDS + DTMB, none → DTMB only. Position
//!   fixes are not part of the scheme and are always admitted.

use crate::core::System;
use crate::fusion::mode::{
    seamless_mode, FuzzyConfig, FuzzyInputs, FuzzySystem, Mode, SeamlessMode,
};
use crate::fusion::wls;
use crate::measurement::{Measurement, MeasurementBatch, SourceKind};
use nalgebra::Vector3;
use serde::Deserialize;

/// `selection = "…"` in an `[[estimator]]` table.
#[derive(
    Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum SelectionKind {
    /// Seed 000's fuzzy inference system (tuned by `[estimator.fuzzy]`).
    Fuzzy,
    /// Seed 003's seamless scheme by GPS satellite count.
    Seamless,
}

/// A configured selection scheme.
#[derive(Clone, Debug, PartialEq)]
pub enum ModeSelection {
    Fuzzy(Box<FuzzyConfig>),
    Seamless,
}

/// What a batch may contribute.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Admission {
    /// The mode's label, recorded per epoch (`"A"`, `"B"`, `"C"`, `"GPS+BDS"`, …).
    pub label: &'static str,
    /// Systems whose ranges are admitted, indexed like [`System::ALL`].
    pub systems: [bool; System::COUNT],
    /// Whether position fixes are admitted.
    pub fixes: bool,
}

impl Admission {
    /// Everything admitted (no selection scheme).
    pub fn all() -> Self {
        Self {
            label: "",
            systems: [true; System::COUNT],
            fixes: true,
        }
    }

    /// True when ranges of `s` are admitted.
    pub fn admits(&self, s: System) -> bool {
        self.systems[s.index()]
    }
}

/// GDOP with one shared clock of the emitters in `a` and `b` seen from `rx`; infinite when
/// it cannot be computed (fewer than four emitters, or no receiver position yet).
fn shared_clock_gdop(
    rx: Option<&Vector3<f64>>,
    a: &[Vector3<f64>],
    b: &[Vector3<f64>],
    geometry: &mut Vec<(Vector3<f64>, usize)>,
) -> f64 {
    let Some(rx) = rx else {
        return f64::INFINITY;
    };
    geometry.clear();
    geometry.extend(a.iter().chain(b).map(|p| (*p, 0)));
    wls::dop(rx, geometry, 1).map_or(f64::INFINITY, |d| d.gdop)
}

/// A selection scheme ready to run (the fuzzy system tabulated).
#[derive(Clone, Debug)]
enum Scheme {
    Fuzzy(Box<FuzzySystem>),
    Seamless,
}

/// The running state of a selection scheme.
#[derive(Clone, Debug)]
pub struct ModeSelector {
    scheme: Scheme,
    /// Emitter positions of the GPS ranges of the last GNSS batch.
    gps: Vec<Vector3<f64>>,
    /// Emitter positions of the last DTMB batch.
    dtmb: Vec<Vector3<f64>>,
    /// Support of the last position fix (FM: RPs in the circle).
    rp_count: u32,
    geometry: Vec<(Vector3<f64>, usize)>,
}

impl ModeSelector {
    /// A selector running `scheme`.
    ///
    /// # Errors
    /// When the fuzzy configuration is invalid (`fuzzy.<key>: message`).
    pub fn new(scheme: &ModeSelection) -> Result<Self, String> {
        if let ModeSelection::Fuzzy(f) = scheme {
            f.validate().map_err(|(k, m)| format!("fuzzy.{k}: {m}"))?;
        }
        Ok(Self {
            scheme: match scheme {
                ModeSelection::Fuzzy(f) => Scheme::Fuzzy(Box::new(FuzzySystem::new(f))),
                ModeSelection::Seamless => Scheme::Seamless,
            },
            gps: Vec::with_capacity(32),
            dtmb: Vec::with_capacity(8),
            rp_count: 0,
            geometry: Vec::with_capacity(48),
        })
    }

    /// Takes note of `batch` and decides what it may contribute. `rx` is the estimator's
    /// current position estimate (ECEF), needed for the GDOPs.
    pub fn decide(&mut self, batch: &MeasurementBatch, rx: Option<&Vector3<f64>>) -> Admission {
        match batch.source {
            SourceKind::Gnss => {
                self.gps.clear();
                self.gps.extend(
                    batch
                        .ranges()
                        .filter(|m| m.system() == System::Gps)
                        .map(|m| m.emitter_pos_ecef_m),
                );
            }
            SourceKind::Dtmb => {
                self.dtmb.clear();
                self.dtmb
                    .extend(batch.ranges().map(|m| m.emitter_pos_ecef_m));
            }
            // The abstract emitters (seeds 001 and 003) deliver every system in one batch:
            // it is at once the latest GPS and the latest DTMB batch.
            SourceKind::Emitters => {
                self.gps.clear();
                self.dtmb.clear();
                for m in batch.ranges() {
                    match m.system() {
                        System::Gps => self.gps.push(m.emitter_pos_ecef_m),
                        System::Dtmb => self.dtmb.push(m.emitter_pos_ecef_m),
                        _ => {}
                    }
                }
            }
            _ => {
                if let Some(support) = batch.items.iter().find_map(|m| match m {
                    Measurement::Position(p) => Some(p.support),
                    _ => None,
                }) {
                    self.rp_count = support;
                }
            }
        }
        let idx = |s: System| s.index();
        match &self.scheme {
            Scheme::Seamless => {
                let mut systems = [false; System::COUNT];
                let label = match seamless_mode(self.gps.len()) {
                    SeamlessMode::GpsBds => {
                        systems[idx(System::Gps)] = true;
                        systems[idx(System::Bds)] = true;
                        "GPS+BDS"
                    }
                    SeamlessMode::GpsBdsDtmb => {
                        systems[idx(System::Gps)] = true;
                        systems[idx(System::Bds)] = true;
                        systems[idx(System::Dtmb)] = true;
                        "GPS+BDS+DTMB"
                    }
                    SeamlessMode::DtmbOnly => {
                        systems[idx(System::Dtmb)] = true;
                        "DTMB"
                    }
                };
                systems[idx(System::Tcofdm)] = true;
                Admission {
                    label,
                    systems,
                    fixes: true,
                }
            }
            Scheme::Fuzzy(fuzzy) => {
                let inputs = FuzzyInputs {
                    gdop_gps: shared_clock_gdop(rx, &self.gps, &[], &mut self.geometry),
                    gdop_gps_dtmb: shared_clock_gdop(rx, &self.gps, &self.dtmb, &mut self.geometry),
                    rp_count: f64::from(self.rp_count),
                };
                let mode = fuzzy.decide(&inputs).mode;
                let mut systems = [true; System::COUNT];
                systems[idx(System::Dtmb)] = mode != Mode::A;
                Admission {
                    label: match mode {
                        Mode::A => "A",
                        Mode::B => "B",
                        Mode::C => "C",
                    },
                    systems,
                    fixes: mode == Mode::C,
                }
            }
        }
    }
}
