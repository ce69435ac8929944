//! The GNSS estimators of seed 000's comparison: the 11-state EKF behind its front end,
//! and weighted least squares, each implementing [`Estimator`].

use crate::core::{GpsTime, System};
use crate::fusion::ekf11::{Ekf11, Ekf11Config, RejectReason, UpdateOutcome};
use crate::fusion::preprocess::{ClockCorrectionConfig, FrontEnd};
use crate::fusion::selection::ModeSelection;
use crate::fusion::wls::{self, WlsOptions};
use crate::measurement::{
    EpochOutcome, Estimate, Estimator, MeasurementBatch, RangeMeasurement, SourceKind,
};
use nalgebra::Vector3;

/// Seed 000's EKF driven epoch by epoch: initialised from a weighted-least-squares fix,
/// then predicted to each batch's time and updated with each range and range rate.
pub struct EkfEstimator {
    name: String,
    ekf: Ekf11,
    last_t: Option<GpsTime>,
    /// Systems, fix sources, mode selection and DTMB clock correction; holds the current
    /// batch's admitted ranges.
    front: FrontEnd,
    /// Emitter geometry of the current batch for the GDOP (reused buffer).
    geometry: Vec<(Vector3<f64>, usize)>,
}

impl EkfEstimator {
    /// An estimator using `systems`. When it mixes GPS and BeiDou and the configuration has
    /// no inter-system-bias state, one is switched on with its defaults: a receiver's BDS
    /// ranges carry a hardware and time-scale bias relative to GPS that a shared clock
    /// would turn into position error.
    ///
    /// # Errors
    /// When the configuration is invalid.
    pub fn new(name: &str, systems: &[System], cfg: Option<Ekf11Config>) -> Result<Self, String> {
        let cfg = cfg.unwrap_or_default().for_systems(systems);
        let ekf = Ekf11::new(cfg).map_err(|e| e.to_string())?;
        Ok(Self {
            name: name.to_string(),
            ekf,
            last_t: None,
            front: FrontEnd::new(systems, &[], None, None)?,
            geometry: Vec::with_capacity(64),
        })
    }

    /// The same estimator also taking the position fixes of the sources named in `fixes`,
    /// selecting what it uses by `selection` and correcting DTMB clocks by `correction`.
    ///
    /// # Errors
    /// When the selection's configuration is invalid.
    pub fn with_preprocessing(
        mut self,
        fixes: &[SourceKind],
        selection: Option<&ModeSelection>,
        correction: Option<ClockCorrectionConfig>,
    ) -> Result<Self, String> {
        self.front = FrontEnd::new(self.front.systems(), fixes, selection, correction)?;
        Ok(self)
    }

    fn estimate(&self, t: GpsTime) -> Option<Estimate> {
        self.ekf.is_initialised().then(|| Estimate {
            t,
            pos_ecef_m: self.ekf.position_ecef(),
            vel_ecef_mps: Some(self.ekf.velocity_ecef()),
            cov_pos_m2: self.ekf.position_covariance(),
        })
    }
}

/// Adds one update's outcome (of dimension `dim`) to the epoch's counts.
fn tally_outcome(out: &mut EpochOutcome, o: UpdateOutcome, dim: u32) {
    match o {
        UpdateOutcome::Accepted { nis } => {
            out.used += 1;
            out.record_nis(nis, dim);
        }
        UpdateOutcome::Rejected { reason, .. } => {
            out.rejected += 1;
            if let RejectReason::Gate { state_led } = reason {
                out.rejected_gate += 1;
                out.rejected_gate_state_led += u32::from(state_led);
            }
        }
    }
}

/// Fills `scratch` with the batch's ranges from `systems`.
fn select_ranges(
    batch: &MeasurementBatch,
    systems: &[System],
    scratch: &mut Vec<RangeMeasurement>,
) {
    scratch.clear();
    scratch.extend(
        batch
            .ranges()
            .filter(|m| systems.contains(&m.system()))
            .copied(),
    );
}

/// GDOP of the ranges in `ranges` seen from `rx`, one clock per system present.
pub(crate) fn gdop_of(
    rx: &Vector3<f64>,
    ranges: &[RangeMeasurement],
    geometry: &mut Vec<(Vector3<f64>, usize)>,
) -> Option<f64> {
    let mut present = [false; System::COUNT];
    for m in ranges {
        present[m.system().index()] = true;
    }
    let mut map = [0usize; System::COUNT];
    let mut n_clocks = 0;
    for (i, p) in present.iter().enumerate() {
        if *p {
            map[i] = n_clocks;
            n_clocks += 1;
        }
    }
    geometry.clear();
    geometry.extend(
        ranges
            .iter()
            .map(|m| (m.emitter_pos_ecef_m, map[m.system().index()])),
    );
    wls::dop(rx, geometry, n_clocks).map(|d| d.gdop)
}

impl Estimator for EkfEstimator {
    fn name(&self) -> &str {
        &self.name
    }

    /// GNSS batches, and DTMB or TC-OFDM batches when the estimator uses those systems:
    /// their ranges share the receiver clock (seed 000), so one filter takes them all.
    fn consumes(&self, source: SourceKind) -> bool {
        self.front.consumes(source)
    }

    fn process(&mut self, batch: &MeasurementBatch) -> EpochOutcome {
        let mut out = EpochOutcome::default();
        let rx = self.ekf.is_initialised().then(|| self.ekf.position_ecef());
        self.front.admit(batch, rx.as_ref(), &mut out);
        if !self.ekf.is_initialised() {
            // The first fix comes from least squares on this epoch alone; until one exists
            // the epoch counts as an epoch without a fix.
            let Some(fix) = self.front.first_fix() else {
                return out;
            };
            let s = fix.pos_sigma_m;
            if self
                .ekf
                .initialise(fix.pos_ecef_m, fix.clock_m, s, 10.0 * s)
                .is_err()
            {
                out.numerical_failure = true;
                return out;
            }
            self.last_t = Some(batch.t);
            out.used = fix.n_measurements;
            out.gdop = Some(fix.gdop);
            out.estimate = self.estimate(batch.t);
            return out;
        }
        let dt = self.last_t.map_or(0.0, |l| batch.t.seconds_since(l));
        self.last_t = Some(batch.t);
        if self.ekf.predict(dt.max(0.0)).is_err() {
            // A prediction that cannot be computed resets the filter; the next epoch
            // re-initialises it from least squares. The reset is reported, never hidden.
            out.numerical_failure = true;
            self.ekf = Ekf11::new(*self.ekf.config())
                .unwrap_or_else(|_| unreachable!("config validated at build"));
            return out;
        }
        for m in &self.front.ranges {
            let r = self.ekf.update_range(m);
            for o in std::iter::once(r.range).chain(r.rate) {
                tally_outcome(&mut out, o, 1);
            }
        }
        for p in self.front.position_fixes(batch) {
            let o = self.ekf.update_position(p);
            tally_outcome(&mut out, o, 3);
        }
        out.gdop = gdop_of(
            &self.ekf.position_ecef(),
            &self.front.ranges,
            &mut self.geometry,
        );
        out.estimate = self.estimate(batch.t);
        out
    }

    fn latest(&self) -> Option<Estimate> {
        self.last_t.and_then(|t| self.estimate(t))
    }

    /// The next epoch re-initialises from least squares, as the first one did.
    fn reset(&mut self) {
        self.ekf = Ekf11::new(*self.ekf.config())
            .unwrap_or_else(|_| unreachable!("config validated at build"));
        self.last_t = None;
    }
}

/// Epoch-by-epoch weighted least squares: no memory, no fix with too few satellites.
pub struct WlsEstimator {
    name: String,
    systems: Vec<System>,
    scratch: Vec<RangeMeasurement>,
    latest: Option<Estimate>,
}

impl WlsEstimator {
    /// An estimator using `systems`, one clock per system.
    pub fn new(name: &str, systems: &[System]) -> Self {
        Self {
            name: name.to_string(),
            systems: systems.to_vec(),
            scratch: Vec::with_capacity(64),
            latest: None,
        }
    }
}

impl Estimator for WlsEstimator {
    fn name(&self) -> &str {
        &self.name
    }

    fn consumes(&self, source: SourceKind) -> bool {
        source == SourceKind::Gnss
    }

    fn process(&mut self, batch: &MeasurementBatch) -> EpochOutcome {
        select_ranges(batch, &self.systems, &mut self.scratch);
        let opts = WlsOptions {
            initial_pos_ecef_m: self.latest.map(|e| e.pos_ecef_m),
            ..WlsOptions::default()
        };
        let mut out = EpochOutcome::default();
        match wls::solve(self.scratch.iter(), &opts) {
            Ok(fix) => {
                let e = Estimate {
                    t: batch.t,
                    pos_ecef_m: fix.pos_ecef_m,
                    vel_ecef_mps: None,
                    cov_pos_m2: fix.cov_pos_ecef_m2,
                };
                self.latest = Some(e);
                out.estimate = Some(e);
                out.used = fix.n_measurements as u32;
                out.gdop = Some(fix.dop.gdop);
            }
            Err(_) => {
                out.rejected = self.scratch.len() as u32;
            }
        }
        out
    }

    fn latest(&self) -> Option<Estimate> {
        self.latest
    }

    /// Least squares keeps no state between epochs but its last fix, forgotten here.
    fn reset(&mut self) {
        self.latest = None;
    }
}
