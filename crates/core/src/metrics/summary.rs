//! The content of `summary.json`: one line per estimator of the statistics the metrics
//! compute, with the run's identity. Monte Carlo fills it; the report and the CLI read it.

use super::{ConsistencySummary, ErrorStats, TrajectoryStats};
use serde::Serialize;
use std::collections::BTreeMap;

/// One estimator's line of the summary.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct EstimatorSummary {
    pub name: String,
    /// Statistics of the 3-D position error over every epoch of every trial.
    pub error_3d_m: Option<ErrorStats>,
    /// Statistics of the horizontal position error.
    pub error_h_m: Option<ErrorStats>,
    /// Share of scoring epochs with an *available* estimate: one whose estimator used a
    /// measurement within the world's coast limit (`[scoring] coast_limit_s`).
    pub availability: f64,
    /// Scoring epochs over all trials (the same instants for every estimator of a world).
    pub epochs: usize,
    /// Epochs without an estimate.
    pub epochs_without_fix: usize,
    /// Epochs with an estimate, within the coast limit, at which the estimator used no
    /// measurement (it coasted on its prediction or held its last fix); they count as
    /// available.
    pub coasting_epochs: usize,
    /// Epochs with an estimate older than the coast limit: not available, although their
    /// errors are in the statistics above.
    pub stale_epochs: usize,
    /// Mean position NEES (3 degrees of freedom; 3 for a consistent filter).
    pub mean_nees_pos: Option<f64>,
    /// Epochs where the estimator reported a numerical failure (a non-finite state or a
    /// divergence it detected), after which it re-initialised.
    pub numerical_failures: usize,
    /// `numerical_failures / epochs`: the share of scoring epochs at which the estimator
    /// was reset.
    pub reset_share: f64,
    /// Measurements its gates refused (innovation and data-layer gates), over all trials.
    pub gated_measurements: u64,
    /// The comparison protocol it ran under: its gates, divergence watch and reset policy,
    /// and where it departs from the world's `[comparison]`, with the paper's citation.
    pub protocol: EstimatorProtocol,
    /// The first of them (at most `montecarlo::reduce::FAILURES_LISTED`), in trial and time order.
    pub first_failures: Vec<FailureEpoch>,
    /// Absolute trajectory error as seed 000 computes it (TUM definition, ECEF, no
    /// alignment), over every epoch with an estimate of every trial.
    pub ate_m: Option<TrajectoryStats>,
    /// The ATE after a rigid (Horn) alignment of each trial's trajectory to the truth.
    pub ate_aligned_m: Option<TrajectoryStats>,
    /// Relative pose error of the translation over the summary's `rpe_delta_s` (1 s unless
    /// the world's `[scoring]` says otherwise), no alignment (seed 000).
    pub rpe_m: Option<TrajectoryStats>,
    /// The RPE after each trial's rigid alignment.
    pub rpe_aligned_m: Option<TrajectoryStats>,
    /// Position NEES (3 degrees of freedom) against its χ² bands over the trials.
    pub nees: Option<ConsistencySummary>,
    /// NIS (summed over each epoch's updates, with their summed dimensions as degrees of
    /// freedom) against its χ² bands. Particle filters have no innovation covariance and
    /// report none.
    pub nis: Option<ConsistencySummary>,
    /// Share of scored epochs in each integration mode (mode-selecting estimators only).
    pub modes: BTreeMap<String, f64>,
    /// How much each statistic varies from trial to trial: the 95 % confidence interval
    /// (Student t) of the mean over trials of each trial's own value.
    pub across_trials: AcrossTrials,
    /// The posterior Cramér–Rao bound on the position RMSE (m) of the estimator's model
    /// in this world (`fusion::pcrlb`, `world::bound`: the paper models, and seed 000's
    /// model where every epoch's pseudoranges fix the position): no estimator can do
    /// better.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pcrlb_pos_rmse_m: Option<f64>,
    /// `rmse / pcrlb_pos_rmse_m`: 1 for an efficient estimator.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub efficiency: Option<f64>,
    /// The errors inside each of the world's `[[shielding]]` windows and outside all of
    /// them (the last entry), so a table shows where each source helps; empty for a world
    /// without shielding windows.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub segments: Vec<SegmentStats>,
    /// The errors at the epochs whose truth was outdoors and at those whose truth was
    /// indoors (inside a building or an indoor zone of the world's `[scene]`), labelled
    /// `"outdoor"` and `"indoor"`; empty for a world whose truth never goes indoors.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub environments: Vec<SegmentStats>,
}

impl EstimatorSummary {
    /// The estimator's name, marked † when it departs from the comparison protocol.
    pub fn row_name(&self) -> String {
        if self.protocol.deviations.is_empty() {
            self.name.clone()
        } else {
            format!("{} †", self.name)
        }
    }
}

/// The protocol one estimator ran under (`[comparison]` of the world file;
/// `world::comparison`).
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct EstimatorProtocol {
    /// Whether the estimator is a row of the world's `[comparison]`.
    pub compared: bool,
    /// The data-layer residual gate `C` it applies (seed 004 eq. 24); `null`: none.
    pub residual_gate_c: Option<f64>,
    /// Its innovation gate on each scalar range or rate (a χ²(1) quantile); `null`: none,
    /// or a filter without one.
    pub gate_chi2: Option<f64>,
    /// The divergence watch: consecutive scoring instants out of bounds that declare a
    /// divergence, and the per-instant tail probability of the bound (`engine::health`).
    pub divergence_window_epochs: u32,
    pub divergence_false_alarm: f64,
    /// What the engine does on a divergence.
    pub reset: String,
    /// Where it departs from the shared protocol, each with where its paper says so.
    pub deviations: Vec<ProtocolDeviation>,
}

/// One departure from the comparison protocol.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ProtocolDeviation {
    /// The protocol key (`"residual_gate_c"`, `"divergence"`).
    pub key: String,
    /// Where the estimator's paper says so.
    pub cite: String,
}

/// An estimator's errors over the epochs of one segment of the run's time line.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct SegmentStats {
    /// What the segment is: `"40–80 s (3 per system)"`, or `"outside shielding"`.
    pub label: String,
    /// The window `[from_s, to_s)` (s since the world start); absent for the epochs
    /// outside every window.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub window_s: Option<[f64; 2]>,
    /// Epochs of every trial in the segment with an estimate.
    pub epochs: usize,
    /// Statistics of the 3-D error over them (as for the whole run); absent without an
    /// estimate.
    pub error_3d_m: Option<ErrorStats>,
    /// RMS of the horizontal error over them (m).
    pub rmse_h_m: Option<f64>,
}

/// An epoch at which an estimator reported a numerical failure.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct FailureEpoch {
    pub trial: u64,
    pub t_s: f64,
}

/// 95 % confidence intervals, across trials, of the mean of per-trial statistics (`[lo,
/// hi]`; absent with fewer than two trials with an estimate). Each respects its
/// statistic's support: the errors' Student t interval is taken on the log scale
/// ([`crate::metrics::positive_ci95`]), availability's on the logit scale
/// ([`crate::metrics::unit_ci95`]).
#[derive(Clone, Debug, Serialize, PartialEq, Default)]
pub struct AcrossTrials {
    /// Trials that contributed (those with at least one estimate).
    pub trials: usize,
    pub sigma1_ci95_m: Option<[f64; 2]>,
    pub sigma2_ci95_m: Option<[f64; 2]>,
    pub sigma3_ci95_m: Option<[f64; 2]>,
    pub mean_ci95_m: Option<[f64; 2]>,
    pub rmse_ci95_m: Option<[f64; 2]>,
    pub ate_rmse_ci95_m: Option<[f64; 2]>,
    pub rpe_rmse_ci95_m: Option<[f64; 2]>,
    pub availability_ci95: Option<[f64; 2]>,
}

/// The content of `summary.json`.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Summary {
    pub hybridnav_version: String,
    pub world: String,
    pub world_file: String,
    pub world_hash: String,
    pub seed: u64,
    pub trials: u64,
    /// `"K/N"` for the summary of one shard's trials; absent for a whole run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shard: Option<String>,
    pub duration_s: f64,
    /// The interval Δ (s) of every estimator's RPE (`[scoring] rpe_delta_s`).
    pub rpe_delta_s: f64,
    pub estimators: Vec<EstimatorSummary>,
    /// Distinct warnings of every trial's sources, sorted (a model used outside its
    /// validity range, …).
    pub warnings: Vec<String>,
}

impl Summary {
    /// The table printed after a run, in the papers' layout.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{} — {} trial(s), seed {}",
            self.world, self.trials, self.seed
        );
        // The efficiency column appears only when some estimator has a bound.
        let bounded = self.estimators.iter().any(|e| e.efficiency.is_some());
        // The name column fits the longest (marked) name, so the columns stay aligned.
        let w = self
            .estimators
            .iter()
            .map(|e| e.row_name().chars().count())
            .max()
            .unwrap_or(0)
            .max(16);
        let _ = write!(
            s,
            "{:<w$} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>7} {:>7}",
            "estimator",
            "1σ",
            "2σ",
            "3σ",
            "rmse",
            "ATE",
            "ATE rms",
            "RPE",
            "RPE rms",
            "avail",
            "coast"
        );
        let _ = if bounded {
            writeln!(s, " {:>8} {:>10}", "PCRLB", "rmse/PCRLB")
        } else {
            writeln!(s)
        };
        let f = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |x| format!("{x:.2}"));
        for e in &self.estimators {
            let x = e.error_3d_m.as_ref();
            let _ = write!(
                s,
                "{:<w$} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>6.1}% {:>6.1}%",
                e.row_name(),
                f(x.map(|x| x.sigma1)),
                f(x.map(|x| x.sigma2)),
                f(x.map(|x| x.sigma3)),
                f(x.map(|x| x.rmse)),
                f(e.ate_m.as_ref().map(|a| a.mean)),
                f(e.ate_m.as_ref().map(|a| a.rmse)),
                f(e.rpe_m.as_ref().map(|a| a.mean)),
                f(e.rpe_m.as_ref().map(|a| a.rmse)),
                100.0 * e.availability,
                100.0 * e.coasting_epochs as f64 / e.epochs.max(1) as f64
            );
            let _ = if bounded {
                writeln!(s, " {:>8} {:>10}", f(e.pcrlb_pos_rmse_m), f(e.efficiency))
            } else {
                writeln!(s)
            };
        }
        let _ = writeln!(
            s,
            "(metres; σ-levels: 3-D error percentiles 68.27/95.45/99.73 % over all epochs of all trials;\n ATE/RPE: mean and RMSE, TUM definitions in ECEF, no alignment, RPE over {} s;\n avail: epochs with an estimate that used a measurement within the coast limit; coast: of all epochs, those\n available without a measurement at that instant; every estimator is scored at the same instants)",
            self.rpe_delta_s
        );
        if bounded {
            let _ = writeln!(
                s,
                "(PCRLB: the posterior Cramér–Rao bound on the position RMSE of the estimator's model)"
            );
        }
        self.protocol_notes(&mut s);
        self.segment_table(
            &mut s,
            w,
            "3-D error by segment (m; rmse and 2σ, the 95.45 % percentile, of the epochs inside):",
            |e| &e.segments,
        );
        self.segment_table(
            &mut s,
            w,
            "3-D error by where the truth was (m; rmse and 2σ of the epochs outdoors and indoors):",
            |e| &e.environments,
        );
        s
    }

    /// The comparison protocol under the table: what the compared rows share, the rows
    /// that depart from it (marked †) with their papers' citations, and every reset.
    fn protocol_notes(&self, s: &mut String) {
        use std::fmt::Write;
        let compared: Vec<&EstimatorSummary> = self
            .estimators
            .iter()
            .filter(|e| e.protocol.compared)
            .collect();
        if let Some(first) = compared.iter().find(|e| e.protocol.deviations.is_empty()) {
            let p = &first.protocol;
            let gate = p
                .residual_gate_c
                .map_or_else(|| "none".to_string(), |c| format!("C = {c}"));
            let names: Vec<&str> = compared.iter().map(|e| e.name.as_str()).collect();
            let _ = writeln!(
                s,
                "(comparison protocol of {}: data-layer gate {gate}; divergence after {} instants out of bounds at {:e}; reset: {})",
                names.join(", "),
                p.divergence_window_epochs,
                p.divergence_false_alarm,
                p.reset
            );
        }
        for e in &compared {
            for d in &e.protocol.deviations {
                let _ = writeln!(s, "(† {} keeps its own {}: {})", e.name, d.key, d.cite);
            }
        }
        for e in self.estimators.iter().filter(|e| e.numerical_failures > 0) {
            let _ = writeln!(
                s,
                "(resets: {} {} times, {:.2} % of its epochs)",
                e.name,
                e.numerical_failures,
                100.0 * e.reset_share
            );
        }
    }

    /// The RMS 3-D error of each estimator in each segment `of` gives it (the shielding
    /// windows and the rest, or outdoors and indoors; nothing for a world without them).
    fn segment_table(
        &self,
        s: &mut String,
        w: usize,
        heading: &str,
        of: impl Fn(&EstimatorSummary) -> &Vec<SegmentStats>,
    ) {
        use std::fmt::Write;
        let Some(first) = self.estimators.iter().map(&of).find(|g| !g.is_empty()) else {
            return;
        };
        // Each segment is two columns, rmse and 2σ, under its label.
        let widths: Vec<usize> = first
            .iter()
            .map(|g| g.label.chars().count().max(15))
            .collect();
        let _ = writeln!(s, "\n{heading}");
        let _ = write!(s, "{:<w$}", "");
        for (g, cw) in first.iter().zip(&widths) {
            let _ = write!(s, "  {:>cw$}", g.label);
        }
        let _ = writeln!(s);
        let _ = write!(s, "{:<w$}", "estimator");
        for cw in &widths {
            let _ = write!(s, "  {:>cw$}", format!("{:>7} {:>7}", "rmse", "2σ"));
        }
        let _ = writeln!(s);
        let f = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |x| format!("{x:.2}"));
        for e in &self.estimators {
            let _ = write!(s, "{:<w$}", e.name);
            for (g, cw) in of(e).iter().zip(&widths) {
                let x = g.error_3d_m.as_ref();
                let cell = format!("{:>7} {:>7}", f(x.map(|x| x.rmse)), f(x.map(|x| x.sigma2)));
                let _ = write!(s, "  {cell:>cw$}");
            }
            let _ = writeln!(s);
        }
    }
}
