//! Preprocessing before a filter sees a batch: the estimators' shared front end
//! ([`FrontEnd`]: systems, fix sources, mode selection) and seed 000's DTMB clock correction.
//!
//! A DTMB tower's pseudorange carries the tower's own clock offset relative to GPS time
//! and the receiver's DTMB inter-system delay, neither of which is broadcast. Seed 000
//! (Cong et al. 2018, §3.1) removes them with a GPS fix: while the GPS geometry is good
//! (GDOP_GPS small) the receiver knows its position `r̂` and GPS clock `b̂` well, and
//!
//! ```text
//! β_t = ρ_t − ‖r_t − r̂‖ − b̂                  (one sample per tower t and epoch)
//! β̂_t ← mean of the first n samples, then β̂_t ← β̂_t + (β_t − β̂_t)/n_max
//! ρ_t' = ρ_t − β̂_t                            (what the filter uses)
//! ```
//!
//! so the corrected DTMB range shares the GPS clock, which is what lets seed 000's filter
//! carry a single clock state. The smoothing (a running mean that becomes an exponential
//! average after `window` samples) follows the tower clock's slow drift. A tower never
//! calibrated has an unknown bias of up to microseconds, so its ranges are withheld (and
//! counted as rejected) until its first calibration. The calibration runs in every instant
//! with a good GPS fix, before the mode selection decides what the filter may use (the
//! paper's Fig. 2), so a tower left out in the open is ready when the sky closes.

use crate::core::{EmitterId, GpsTime, System};
use crate::fusion::selection::{Admission, ModeSelection, ModeSelector};
use crate::fusion::wls::{self, WlsOptions};
use crate::measurement::{
    EpochOutcome, Measurement, MeasurementBatch, PositionFix, RangeMeasurement, SourceKind,
};
use nalgebra::Vector3;
use serde::Deserialize;

/// `dtmb_clock_correction = { … }` in an `[[estimator]]` table.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct ClockCorrectionConfig {
    /// Calibrate only while the GPS-only GDOP is at most this. Default 4 (the paper says
    /// "small" without a number; 4 is a common threshold of a good GPS geometry).
    pub gdop_max: f64,
    /// Samples averaged before the estimate becomes an exponential average of this length.
    /// Default 10.
    pub window: u32,
}

impl Default for ClockCorrectionConfig {
    fn default() -> Self {
        Self {
            gdop_max: 4.0,
            window: 10,
        }
    }
}

impl ClockCorrectionConfig {
    /// # Errors
    /// `(key, message)` for a GDOP bound that is not positive or a zero window.
    pub fn validate(&self) -> Result<(), (String, String)> {
        if !(self.gdop_max.is_finite() && self.gdop_max > 0.0) {
            return Err((
                "gdop_max".into(),
                format!("{}: expected > 0", self.gdop_max),
            ));
        }
        if self.window == 0 {
            return Err(("window".into(), "0: expected at least 1 sample".into()));
        }
        Ok(())
    }
}

/// The calibration of one tower.
#[derive(Clone, Copy, Debug)]
struct TowerBias {
    id: EmitterId,
    bias_m: f64,
    samples: u32,
}

/// The running DTMB clock correction of one estimator.
#[derive(Clone, Debug)]
pub struct DtmbClockCorrector {
    cfg: ClockCorrectionConfig,
    /// The last good GPS fix: time, position (ECEF) and GPS clock (m).
    reference: Option<(GpsTime, Vector3<f64>, f64)>,
    towers: Vec<TowerBias>,
    gps: Vec<RangeMeasurement>,
}

impl DtmbClockCorrector {
    /// A corrector with no calibration yet.
    pub fn new(cfg: ClockCorrectionConfig) -> Self {
        Self {
            cfg,
            reference: None,
            towers: Vec::with_capacity(4),
            gps: Vec::with_capacity(32),
        }
    }

    /// Takes note of a GNSS batch: a GPS-only fix with GDOP ≤ `gdop_max` becomes the
    /// calibration reference for DTMB batches of the same instant.
    pub fn observe(&mut self, batch: &MeasurementBatch) {
        if batch.source != SourceKind::Gnss {
            return;
        }
        self.gps.clear();
        self.gps.extend(
            batch
                .ranges()
                .filter(|m| m.system() == System::Gps)
                .copied(),
        );
        self.reference = wls::solve(self.gps.iter(), &WlsOptions::default())
            .ok()
            .filter(|f| f.dop.gdop <= self.cfg.gdop_max)
            .and_then(|f| Some((batch.t, f.pos_ecef_m, f.clock_m(System::Gps)?)));
    }

    /// The calibrated bias of tower `id` (m), if it has one.
    pub fn bias_m(&self, id: EmitterId) -> Option<f64> {
        self.towers.iter().find(|t| t.id == id).map(|t| t.bias_m)
    }

    /// Calibrates from the DTMB ranges among `ranges` when a reference of the same
    /// instant `t` exists (the other ranges are passed over).
    pub fn calibrate<'a>(
        &mut self,
        t: GpsTime,
        ranges: impl Iterator<Item = &'a RangeMeasurement>,
    ) {
        let reference = self
            .reference
            .filter(|(t_ref, _, _)| t.seconds_since(*t_ref).abs() < 1e-3);
        if let Some((_, pos, clock_m)) = reference {
            for m in ranges.filter(|m| m.system() == System::Dtmb) {
                let sample = m.pseudorange_m - (m.emitter_pos_ecef_m - pos).norm() - clock_m;
                if !sample.is_finite() {
                    continue;
                }
                match self.towers.iter_mut().find(|t| t.id == m.emitter) {
                    Some(tb) => {
                        tb.samples = tb.samples.saturating_add(1);
                        let n = tb.samples.min(self.cfg.window);
                        tb.bias_m += (sample - tb.bias_m) / f64::from(n);
                    }
                    None => self.towers.push(TowerBias {
                        id: m.emitter,
                        bias_m: sample,
                        samples: 1,
                    }),
                }
            }
        }
    }

    /// Corrects the DTMB ranges in `ranges` in place by their towers' calibrated biases
    /// and removes those of towers without a calibration. Returns how many were removed.
    pub fn apply(&self, ranges: &mut Vec<RangeMeasurement>) -> u32 {
        let before = ranges.len();
        let towers = &self.towers;
        ranges.retain_mut(|m| {
            if m.system() != System::Dtmb {
                return true;
            }
            match towers.iter().find(|t| t.id == m.emitter) {
                Some(tb) => {
                    m.pseudorange_m -= tb.bias_m;
                    true
                }
                None => false,
            }
        });
        (before - ranges.len()) as u32
    }
}

/// What a Kalman-type estimator does to a batch before its filter sees it: keep the ranges
/// of its systems that the mode selection admits, correct the DTMB clocks, and decide
/// whether the batch's position fixes are used. Shared by `ekf11` and the filter family.
pub struct FrontEnd {
    systems: Vec<System>,
    fixes: Vec<SourceKind>,
    selector: Option<ModeSelector>,
    corrector: Option<DtmbClockCorrector>,
    /// This batch's admitted (and corrected) ranges, after [`FrontEnd::admit`].
    pub ranges: Vec<RangeMeasurement>,
    fixes_admitted: bool,
}

/// A filter's first fix: least squares on one epoch's ranges.
pub struct FirstFix {
    pub pos_ecef_m: Vector3<f64>,
    /// The clock (m) of the first of the estimator's systems that has one.
    pub clock_m: f64,
    /// `√tr(P_pos)`, at least 1 m.
    pub pos_sigma_m: f64,
    pub n_measurements: u32,
    pub gdop: f64,
}

impl FrontEnd {
    /// A front end for the ranges of `systems` and the fixes of the sources `fixes`.
    ///
    /// # Errors
    /// When the selection's configuration is invalid.
    pub fn new(
        systems: &[System],
        fixes: &[SourceKind],
        selection: Option<&ModeSelection>,
        correction: Option<ClockCorrectionConfig>,
    ) -> Result<Self, String> {
        Ok(Self {
            systems: systems.to_vec(),
            fixes: fixes.to_vec(),
            selector: selection.map(ModeSelector::new).transpose()?,
            corrector: correction.map(DtmbClockCorrector::new),
            ranges: Vec::with_capacity(64),
            fixes_admitted: false,
        })
    }

    /// The systems whose ranges the estimator uses.
    pub fn systems(&self) -> &[System] {
        &self.systems
    }

    /// GNSS batches, the abstract emitters of seeds 001 and 003 (whose batches mix
    /// systems; the ranges are filtered by system in [`FrontEnd::admit`]), DTMB or
    /// TC-OFDM batches when the estimator uses those systems, and the batches of its fix
    /// sources.
    pub fn consumes(&self, source: SourceKind) -> bool {
        match source {
            SourceKind::Gnss | SourceKind::Emitters => true,
            SourceKind::Dtmb => self.systems.contains(&System::Dtmb),
            SourceKind::Tcofdm => self.systems.contains(&System::Tcofdm),
            other => self.fixes.contains(&other),
        }
    }

    /// Prepares `batch`: fills [`FrontEnd::ranges`], records the mode in `out` and counts
    /// the ranges the correction withheld as rejected. `rx` is the estimator's position
    /// (ECEF), for the selection's GDOPs.
    pub fn admit(
        &mut self,
        batch: &MeasurementBatch,
        rx: Option<&Vector3<f64>>,
        out: &mut EpochOutcome,
    ) {
        let admitted = match self.selector.as_mut() {
            Some(s) => {
                let d = s.decide(batch, rx);
                out.mode = Some(d.label);
                d
            }
            None => Admission::all(),
        };
        let systems = &self.systems;
        // Seed 000's preprocessing (§3.1, Fig. 2) corrects the DTMB clock whenever the GPS
        // geometry allows it, before and apart from the mode selection, whose GDOP_GPS+DTMB
        // input it prepares: a tower is calibrated from its ranges in every instant with a
        // good GPS fix, also when the selected mode leaves DTMB out of the filter.
        if let Some(c) = self.corrector.as_mut() {
            c.observe(batch);
            c.calibrate(
                batch.t,
                batch.ranges().filter(|m| systems.contains(&m.system())),
            );
        }
        self.ranges.clear();
        self.ranges.extend(
            batch
                .ranges()
                .filter(|m| systems.contains(&m.system()) && admitted.admits(m.system()))
                .copied(),
        );
        if let Some(c) = self.corrector.as_ref() {
            out.rejected += c.apply(&mut self.ranges);
        }
        self.fixes_admitted = admitted.fixes && self.fixes.contains(&batch.source);
    }

    /// The position fixes of `batch` the estimator may use (none unless admitted).
    pub fn position_fixes<'a>(
        &self,
        batch: &'a MeasurementBatch,
    ) -> impl Iterator<Item = &'a PositionFix> + 'a {
        let admitted = self.fixes_admitted;
        batch.items.iter().filter_map(move |m| match m {
            Measurement::Position(p) if admitted => Some(p),
            _ => None,
        })
    }

    /// A first fix from this batch's ranges, if least squares gives one.
    pub fn first_fix(&self) -> Option<FirstFix> {
        let fix = wls::solve(self.ranges.iter(), &WlsOptions::default()).ok()?;
        Some(FirstFix {
            pos_ecef_m: fix.pos_ecef_m,
            clock_m: self
                .systems
                .iter()
                .find_map(|s| fix.clock_m(*s))
                .unwrap_or(0.0),
            pos_sigma_m: fix.cov_pos_ecef_m2.trace().max(0.0).sqrt().max(1.0),
            n_measurements: fix.n_measurements as u32,
            gdop: fix.dop.gdop,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measurement::Measurement;

    fn range(id: EmitterId, e: Vector3<f64>, rx: &Vector3<f64>, bias_m: f64) -> RangeMeasurement {
        RangeMeasurement {
            emitter: id,
            emitter_pos_ecef_m: e,
            emitter_vel_ecef_mps: Vector3::zeros(),
            pseudorange_m: (e - rx).norm() + bias_m,
            sigma_m: 3.0,
            range_rate_mps: None,
            sigma_rate_mps: 0.0,
            cn0_dbhz: 45.0,
            elevation_rad: 0.5,
        }
    }

    /// A receiver near Beijing, six GPS satellites of a good geometry around it, and a
    /// DTMB tower 12 km north on a 300 m mast.
    struct Sky {
        rx: Vector3<f64>,
        sats: Vec<Vector3<f64>>,
        tower_pos: Vector3<f64>,
    }

    fn sky() -> Sky {
        let rx = Vector3::new(-2_178_000.0, 4_388_000.0, 4_069_000.0);
        let up = rx.normalize();
        let east = Vector3::new(-rx.y, rx.x, 0.0).normalize();
        let north = up.cross(&east);
        let sats = [
            (0.0, 80.0),
            (0.0, 30.0),
            (90.0, 35.0),
            (180.0, 40.0),
            (270.0, 25.0),
            (45.0, 60.0),
        ]
        .iter()
        .map(|(az, el): &(f64, f64)| {
            let (a, e) = (az.to_radians(), el.to_radians());
            rx + (north * a.cos() * e.cos() + east * a.sin() * e.cos() + up * e.sin()) * 2.2e7
        })
        .collect();
        Sky {
            rx,
            sats,
            tower_pos: rx + north * 12_000.0 + up * 300.0,
        }
    }

    /// A batch at `tow_s` of noise-free ranges from `emitters` of `system`, every one
    /// offset by `bias_m`.
    fn batch(
        source: SourceKind,
        system: System,
        tow_s: f64,
        emitters: &[Vector3<f64>],
        rx: &Vector3<f64>,
        bias_m: f64,
    ) -> MeasurementBatch {
        MeasurementBatch {
            t: GpsTime::from_week_tow(2000, tow_s),
            source,
            items: emitters
                .iter()
                .enumerate()
                .map(|(i, e)| {
                    Measurement::Range(range(EmitterId::new(system, i as u16 + 1), *e, rx, bias_m))
                })
                .collect(),
            unscored: false,
            raw: None,
        }
    }

    /// Noise-free ranges: the calibration recovers the tower's bias exactly (relative to
    /// the GPS clock), withholds the tower before its first calibration, and corrects its
    /// range to the GPS clock afterwards.
    #[test]
    fn a_good_gps_fix_calibrates_the_tower_bias() {
        let Sky {
            rx,
            sats,
            tower_pos,
        } = sky();
        let clock_m = 1234.5;
        let gnss = batch(SourceKind::Gnss, System::Gps, 100.0, &sats, &rx, clock_m);
        let tower = EmitterId::new(System::Dtmb, 1);
        let tower_bias_m = 45.0 + 17.0;
        let mut c = DtmbClockCorrector::new(ClockCorrectionConfig::default());
        // Before any GPS fix the tower is unknown: its range is withheld.
        let mut r = vec![range(tower, tower_pos, &rx, clock_m + tower_bias_m)];
        c.calibrate(gnss.t, r.iter());
        assert_eq!(c.apply(&mut r), 1);
        assert!(r.is_empty());
        c.observe(&gnss);
        let mut r = vec![range(tower, tower_pos, &rx, clock_m + tower_bias_m)];
        c.calibrate(gnss.t, r.iter());
        assert_eq!(c.apply(&mut r), 0);
        assert!((c.bias_m(tower).unwrap() - tower_bias_m).abs() < 1e-4);
        let corrected = r[0].pseudorange_m - (tower_pos - rx).norm();
        assert!((corrected - clock_m).abs() < 1e-4, "{corrected}");
        // A fix with a poor geometry does not calibrate.
        let mut strict = DtmbClockCorrector::new(ClockCorrectionConfig {
            gdop_max: 0.5,
            window: 10,
        });
        strict.observe(&gnss);
        let mut r = vec![range(tower, tower_pos, &rx, clock_m + tower_bias_m)];
        strict.calibrate(gnss.t, r.iter());
        assert_eq!(strict.apply(&mut r), 1);
    }

    /// Seed 000's preprocessing calibrates the tower whenever the GPS geometry is good,
    /// whatever mode the selection then picks (§3.1, Fig. 2). In the open the fuzzy
    /// selection keeps DTMB out (mode A); when the sky closes to three satellites it
    /// admits the tower, which must arrive corrected to the GPS clock rather than be
    /// withheld as never calibrated.
    #[test]
    fn the_tower_is_calibrated_while_the_mode_leaves_it_out() {
        let Sky {
            rx,
            sats,
            tower_pos,
        } = sky();
        let clock_m = 1234.5;
        let tower_bias_m = 62.0;
        let mut fe = FrontEnd::new(
            &[System::Gps, System::Dtmb],
            &[],
            Some(&ModeSelection::Fuzzy(Box::default())),
            Some(ClockCorrectionConfig::default()),
        )
        .unwrap();
        let tower = [tower_pos];
        let dtmb = |tow_s| {
            batch(
                SourceKind::Dtmb,
                System::Dtmb,
                tow_s,
                &tower,
                &rx,
                clock_m + tower_bias_m,
            )
        };
        // Open sky: mode A, the tower's range stays out of the filter.
        for tow_s in [100.0, 101.0] {
            let mut out = EpochOutcome::default();
            fe.admit(
                &batch(SourceKind::Gnss, System::Gps, tow_s, &sats, &rx, clock_m),
                Some(&rx),
                &mut out,
            );
            let mut out = EpochOutcome::default();
            fe.admit(&dtmb(tow_s), Some(&rx), &mut out);
            assert_eq!(out.mode, Some("A"));
            assert!(fe.ranges.is_empty());
            assert_eq!(out.rejected, 0);
        }
        // Three satellites: the selection admits the tower.
        let mut out = EpochOutcome::default();
        fe.admit(
            &batch(
                SourceKind::Gnss,
                System::Gps,
                102.0,
                &sats[..3],
                &rx,
                clock_m,
            ),
            Some(&rx),
            &mut out,
        );
        let mut out = EpochOutcome::default();
        fe.admit(&dtmb(102.0), Some(&rx), &mut out);
        assert_ne!(out.mode, Some("A"));
        assert_eq!(
            out.rejected, 0,
            "the tower was withheld as never calibrated"
        );
        assert_eq!(fe.ranges.len(), 1);
        let corrected = fe.ranges[0].pseudorange_m - (tower_pos - rx).norm();
        assert!((corrected - clock_m).abs() < 1e-4, "{corrected}");
    }
}
