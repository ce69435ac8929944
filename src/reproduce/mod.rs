//! `hybridnav reproduce`: runs the paper worlds and prints each paper's table with the
//! simulated figure beside the published one, their ratio, and whether each ordering the
//! paper claims holds.
//!
//! A figure counts as reproduced when the ratio simulated / published lies within
//! [½, 2] (the factor the project holds its reproductions to). The tables that
//! `docs/reproductions.md` quotes are this command's `--markdown` output for the default
//! trials and seed, generated and never edited by hand; a test regenerates them and fails
//! when the committed file is stale.

pub mod paired;
pub mod papers;
pub mod seeds;

use crate::montecarlo::store::Shard;
use crate::montecarlo::{run_trials, summarise, EstimatorSummary, RunOptions, Summary};
use crate::world::load_world;
use papers::{
    Figure, GainSplit, Metric, Ordering, Paper, Stated, Variant, GAIN_SPLITS, PAPERS, STATED,
    VARIANTS,
};
use std::fmt::Write as _;
use std::path::Path;

/// Trials per world when none are given: the count docs/reproductions.md quotes.
pub const DEFAULT_TRIALS: u64 = 20;
/// The seed when none is given.
pub const DEFAULT_SEED: u64 = 1;

/// The ratio band within which a simulated figure counts as reproducing a published one.
pub const WITHIN: f64 = 2.0;

/// A published figure below the posterior Cramér–Rao bound cannot be reached by any
/// estimator of the world's model; such a figure counts as reproduced when the
/// estimator's RMSE is within this factor of the bound (the fair-reproductions issue's
/// rule for the particle-filter rows of seeds 001 and 003).
pub const WITHIN_BOUND: f64 = 1.25;

/// Two figures closer than this fraction of the larger are a tie, not an ordering: 0.1 %,
/// a tenth of the smallest difference the tables' two decimals show on a metre-level
/// figure.
pub const TIE_RELATIVE: f64 = 1e-3;

/// One figure, simulated beside published.
#[derive(Clone, Debug)]
pub struct FigureResult {
    pub row: &'static str,
    pub metric: Metric,
    pub paper_m: f64,
    /// `None` when the estimator has no such statistic (no estimate in any epoch).
    pub simulated_m: Option<f64>,
    /// The estimator's 3-D RMSE, beside the bound.
    pub rmse_m: Option<f64>,
    /// The posterior Cramér–Rao bound on the estimator's position RMSE, where the world
    /// has one for it (`summary.json`'s `pcrlb_pos_rmse_m`).
    pub pcrlb_m: Option<f64>,
    /// Whether the row's estimator departs from the world's comparison protocol (marked
    /// † in the tables, with the paper's citation below them).
    pub deviates: bool,
}

impl FigureResult {
    /// simulated / published.
    pub fn ratio(&self) -> Option<f64> {
        self.simulated_m.map(|s| s / self.paper_m)
    }

    /// Whether the simulated figure is within a factor [`WITHIN`] of the paper's, or
    /// [`Self::at_bound`].
    pub fn within(&self) -> bool {
        self.in_band() || self.at_bound()
    }

    /// Whether simulated / published lies within [1/[`WITHIN`], [`WITHIN`]].
    fn in_band(&self) -> bool {
        self.ratio().is_some_and(|r| within_factor(r, WITHIN))
    }

    /// Whether the published figure lies below the bound (no estimator of the model can
    /// reach it) while the estimator's RMSE is within [`WITHIN_BOUND`] of the bound.
    pub fn at_bound(&self) -> bool {
        match (self.pcrlb_m, self.rmse_m) {
            (Some(b), Some(rmse)) => self.paper_m < b && rmse <= WITHIN_BOUND * b,
            _ => false,
        }
    }

    /// The row's cells as both tables print them: row, figure, paper, hybridnav, ratio,
    /// PCRLB and the mark.
    fn cells(&self) -> [String; 7] {
        [
            if self.deviates {
                format!("{} †", self.row)
            } else {
                self.row.to_string()
            },
            self.metric.label().to_string(),
            format!("{:.2}", self.paper_m),
            fmt_opt(self.simulated_m, 2),
            fmt_opt(self.ratio(), 2),
            fmt_opt(self.pcrlb_m, 2),
            self.mark().to_string(),
        ]
    }

    /// The mark of the "within" column: ✓, ✓ at the bound, or ✗.
    fn mark(&self) -> &'static str {
        if self.in_band() {
            "✓"
        } else if self.at_bound() {
            "✓ (bound)"
        } else {
            "✗"
        }
    }
}

/// One claimed ordering and whether it holds.
#[derive(Clone, Debug)]
pub struct OrderingResult {
    pub metric: Metric,
    /// `(estimator, simulated value)` in the claimed ascending order.
    pub values: Vec<(&'static str, Option<f64>)>,
    /// For each adjacent pair of `values`, the split of the run's trials
    /// ([`paired::PairedSign`]); empty when the trials were not at hand (a summary read
    /// back), `None` for a pair without per-trial values.
    pub paired: Vec<Option<paired::PairedSign>>,
}

impl OrderingResult {
    /// Whether every value is present and ascending by more than [`TIE_RELATIVE`] of the
    /// larger: filters that agree to the printed digits have not beaten each other (seed
    /// 004's loosely coupled RE-KF, CKF and EKF are one linear update and differ by
    /// rounding, 10⁻⁹ m).
    pub fn holds(&self) -> bool {
        self.values.windows(2).all(|w| match (w[0].1, w[1].1) {
            (Some(a), Some(b)) => b - a > TIE_RELATIVE * b.abs(),
            _ => false,
        })
    }
}

/// A [`GainSplit`] on a run's figures.
#[derive(Clone, Debug)]
pub struct SplitResult {
    pub split: &'static GainSplit,
    /// The metric of `method`, `without` and `baseline` (m).
    pub method_m: Option<f64>,
    pub without_m: Option<f64>,
    pub baseline_m: Option<f64>,
}

impl SplitResult {
    /// `baseline − method`: the method's gain (m).
    pub fn gain_m(&self) -> Option<f64> {
        Some(self.baseline_m? - self.method_m?)
    }

    /// `without − method`: the term's part of the gain (m).
    pub fn term_part_m(&self) -> Option<f64> {
        Some(self.without_m? - self.method_m?)
    }

    /// The term's share of the gain, when there is a gain larger than a tie
    /// ([`TIE_RELATIVE`] of the baseline) to split.
    pub fn share(&self) -> Option<f64> {
        let gain = self.gain_m()?;
        (gain > TIE_RELATIVE * self.baseline_m?.abs())
            .then(|| self.term_part_m().map(|p| p / gain))?
    }

    fn line(&self) -> String {
        let sp = self.split;
        let head = format!(
            "Share of {} in {}'s {} gain over {}: {} {}, {} {}, {} {} m",
            sp.term,
            sp.method,
            sp.metric.label(),
            sp.baseline,
            sp.method,
            fmt_opt(self.method_m, 3),
            sp.without,
            fmt_opt(self.without_m, 3),
            sp.baseline,
            fmt_opt(self.baseline_m, 3),
        );
        match (self.share(), self.gain_m(), self.term_part_m()) {
            (Some(share), Some(g), Some(p)) => format!(
                "{head}; gain {} m, of which the term {} m: share {:.0} %.",
                mm(g),
                mm(p),
                100.0 * share
            ),
            (None, Some(g), Some(p)) => format!(
                "{head}; no gain to split (gain {} m); the term itself moves {} by {} m.",
                mm(g),
                sp.method,
                mm(-p)
            ),
            _ => format!("{head}; a row has no value."),
        }
    }
}

/// A [`Stated`] figure on a run: the estimator's horizontal RMS error at the epochs of
/// the stated place.
#[derive(Clone, Debug)]
pub struct StatedResult {
    pub stated: &'static Stated,
    /// `None` when the run has no such epoch with an estimate (or no indoor epoch at all).
    pub simulated_m: Option<f64>,
}

impl StatedResult {
    /// Whether the run meets the paper's words: at most the bound, or within
    /// [`WITHIN`] of the value.
    pub fn met(&self) -> bool {
        let st = self.stated;
        self.simulated_m.is_some_and(|x| {
            if st.at_most {
                x <= st.paper_m
            } else {
                within_factor(x / st.paper_m, WITHIN)
            }
        })
    }

    /// What the paper says, what the run gives, and whether it meets it.
    fn line(&self) -> String {
        let st = self.stated;
        let head = format!(
            "Stated in the text, not counted: {} horizontal RMS {} {} m, against {}",
            st.estimator,
            st.place.adverb(),
            fmt_opt(self.simulated_m, 2),
            st.quote
        );
        let judged = if st.at_most {
            format!("at most {} m", st.paper_m)
        } else {
            match self.simulated_m {
                Some(x) => format!("{:.2}×", x / st.paper_m),
                None => "no value".to_string(),
            }
        };
        format!("{head}: {judged} {}", tick(self.met()))
    }
}

/// One paper's reproduction.
#[derive(Clone, Debug)]
pub struct PaperResult {
    pub paper: &'static Paper,
    pub trials: u64,
    pub seed: u64,
    pub figures: Vec<FigureResult>,
    pub orderings: Vec<OrderingResult>,
    /// What the world's compared estimators share, and each departure with its citation
    /// (empty for a world without `[comparison]`).
    pub protocol: Vec<String>,
    /// `(estimator, resets, share of its epochs)` of every estimator of the world that was
    /// reset at least once.
    pub resets: Vec<(String, usize, f64)>,
    /// The paper's [`Variant`] rows, scored the same way and printed apart; they count in
    /// no total.
    pub variants: Vec<VariantResult>,
    /// The paper's [`GainSplit`]s on this run.
    pub splits: Vec<SplitResult>,
    /// The figures the paper states in its text ([`STATED`]) on this run.
    pub stated: Vec<StatedResult>,
    /// `(estimator, PCRLB on its RMSE m, RMSE / PCRLB)` of every estimator of the world
    /// the run bounded, in the world's order.
    pub bounds: Vec<(String, f64, f64)>,
    /// `(estimator, mean position NEES, its degrees of freedom)` of every estimator of the
    /// world that reports a covariance, in the world's order.
    pub consistency: Vec<(String, f64, f64)>,
}

/// One variant's rows and orderings.
#[derive(Clone, Debug)]
pub struct VariantResult {
    pub variant: &'static Variant,
    pub figures: Vec<FigureResult>,
    pub orderings: Vec<OrderingResult>,
}

impl PaperResult {
    /// The largest share of epochs at which an estimator of the world was reset.
    pub fn worst_reset_share(&self) -> f64 {
        self.resets.iter().map(|r| r.2).fold(0.0, f64::max)
    }
}

/// The value of `metric` on one estimator's summary line.
pub fn metric_of(e: &EstimatorSummary, metric: Metric) -> Option<f64> {
    let e3 = e.error_3d_m.as_ref();
    let eh = e.error_h_m.as_ref();
    match metric {
        Metric::Sigma1 => e3.map(|x| x.sigma1),
        Metric::Sigma2 => e3.map(|x| x.sigma2),
        Metric::Sigma3 => e3.map(|x| x.sigma3),
        Metric::Mean => e3.map(|x| x.mean),
        Metric::Std => e3.map(|x| x.std),
        Metric::Rmse => e3.map(|x| x.rmse),
        Metric::AteMean => e.ate_m.as_ref().map(|x| x.mean),
        Metric::AteRmse => e.ate_m.as_ref().map(|x| x.rmse),
        Metric::RpeMean => e.rpe_m.as_ref().map(|x| x.mean),
        Metric::RpeRmse => e.rpe_m.as_ref().map(|x| x.rmse),
        Metric::Horizontal1 => eh.map(|x| x.sigma1),
        Metric::Horizontal2 => eh.map(|x| x.sigma2),
    }
}

/// Scores one paper against a run's summary.
///
/// # Errors
/// When the world has no estimator of a name the paper's table needs.
pub fn score(paper: &'static Paper, s: &Summary) -> Result<PaperResult, String> {
    let (figures, orderings) = score_rows(paper.world, paper.figures, paper.orderings, s)?;
    let variants = VARIANTS
        .iter()
        .filter(|v| v.paper == paper.id)
        .map(|v| {
            let (figures, orderings) = score_rows(paper.world, v.figures, v.orderings, s)?;
            Ok(VariantResult {
                variant: v,
                figures,
                orderings,
            })
        })
        .collect::<Result<Vec<_>, String>>()?;
    let (protocol, resets) = protocol_and_resets(s);
    let value = |name: &str, metric: Metric| {
        s.estimators
            .iter()
            .find(|e| e.name == name)
            .map(|e| metric_of(e, metric))
            .ok_or_else(|| format!("{} has no estimator named {name:?}", paper.world))
    };
    let splits = GAIN_SPLITS
        .iter()
        .filter(|g| g.paper == paper.id)
        .map(|g| {
            Ok(SplitResult {
                split: g,
                method_m: value(g.method, g.metric)?,
                without_m: value(g.without, g.metric)?,
                baseline_m: value(g.baseline, g.metric)?,
            })
        })
        .collect::<Result<Vec<_>, String>>()?;
    let stated = STATED
        .iter()
        .filter(|st| st.paper == paper.id)
        .map(|st| {
            let e = s
                .estimators
                .iter()
                .find(|e| e.name == st.estimator)
                .ok_or_else(|| {
                    format!("{} has no estimator named {:?}", paper.world, st.estimator)
                })?;
            Ok(StatedResult {
                stated: st,
                simulated_m: e
                    .environments
                    .iter()
                    .find(|g| g.label == st.place.label())
                    .and_then(|g| g.rmse_h_m),
            })
        })
        .collect::<Result<Vec<_>, String>>()?;
    let bounds = s
        .estimators
        .iter()
        .filter_map(|e| Some((e.name.clone(), e.pcrlb_pos_rmse_m?, e.efficiency?)))
        .collect();
    let consistency = s
        .estimators
        .iter()
        .filter_map(|e| e.nees.as_ref().map(|n| (e.name.clone(), n.mean, n.dof)))
        .collect();
    Ok(PaperResult {
        paper,
        trials: s.trials,
        seed: s.seed,
        consistency,
        figures,
        orderings,
        protocol,
        resets,
        variants,
        splits,
        stated,
        bounds,
    })
}

/// The lines saying what a world's compared estimators share and where a row departs
/// from it, and every estimator's resets.
fn protocol_and_resets(s: &Summary) -> (Vec<String>, Vec<(String, usize, f64)>) {
    let compared: Vec<&EstimatorSummary> = s
        .estimators
        .iter()
        .filter(|e| e.protocol.compared)
        .collect();
    let mut protocol = Vec::new();
    if let Some(p) = compared
        .iter()
        .find(|e| e.protocol.deviations.is_empty())
        .map(|e| &e.protocol)
    {
        let names: Vec<&str> = compared.iter().map(|e| e.name.as_str()).collect();
        protocol.push(format!(
            "Protocol shared by {}: data-layer gate {}; divergence after {} instants out of bounds at {:e} each; on divergence: {}.",
            names.join(", "),
            p.residual_gate_c
                .map_or_else(|| "none".to_string(), |c| format!("C = {c}")),
            p.divergence_window_epochs,
            p.divergence_false_alarm,
            p.reset
        ));
    }
    for e in &compared {
        for d in &e.protocol.deviations {
            protocol.push(format!("† {} keeps its own {}: {}", e.name, d.key, d.cite));
        }
    }
    // Every row's RPE shares the world's interval; say so where it is not the usual 1 s.
    if s.rpe_delta_s != crate::engine::trial::Scoring::DEFAULT_RPE_DELTA_S {
        protocol.push(format!(
            "RPE over Δ = {} s for every row (the world's `[scoring] rpe_delta_s`).",
            s.rpe_delta_s
        ));
    }
    let resets = s
        .estimators
        .iter()
        .filter(|e| e.numerical_failures > 0)
        .map(|e| (e.name.clone(), e.numerical_failures, e.reset_share))
        .collect();
    (protocol, resets)
}

/// Scores a list of figures and orderings against a run's summary.
fn score_rows(
    world: &str,
    figures: &[Figure],
    orderings: &[Ordering],
    s: &Summary,
) -> Result<(Vec<FigureResult>, Vec<OrderingResult>), String> {
    let find = |name: &str| {
        s.estimators
            .iter()
            .find(|e| e.name == name)
            .ok_or_else(|| format!("{world} has no estimator named {name:?}"))
    };
    let figures = figures
        .iter()
        .map(|f| {
            let e = find(f.estimator)?;
            Ok(FigureResult {
                row: f.row,
                metric: f.metric,
                paper_m: f.paper_m,
                simulated_m: metric_of(e, f.metric),
                rmse_m: metric_of(e, Metric::Rmse),
                pcrlb_m: e.pcrlb_pos_rmse_m,
                deviates: !e.protocol.deviations.is_empty(),
            })
        })
        .collect::<Result<Vec<_>, String>>()?;
    let orderings = orderings
        .iter()
        .map(|o| {
            Ok(OrderingResult {
                paired: Vec::new(),
                metric: o.metric,
                values: o
                    .ascending
                    .iter()
                    .map(|n| Ok((*n, metric_of(find(n)?, o.metric))))
                    .collect::<Result<Vec<_>, String>>()?,
            })
        })
        .collect::<Result<Vec<_>, String>>()?;
    Ok((figures, orderings))
}

/// The papers named by `ids` (a world's stem, or any unambiguous prefix such as
/// `seed003`), every paper when `ids` is empty.
///
/// # Errors
/// An unknown or ambiguous name, with the list of names.
pub fn select(ids: &[String]) -> Result<Vec<&'static Paper>, String> {
    if ids.is_empty() {
        return Ok(PAPERS.iter().collect());
    }
    let names = || PAPERS.iter().map(|p| p.id).collect::<Vec<_>>().join(", ");
    ids.iter()
        .map(|id| {
            let hits: Vec<&Paper> = PAPERS
                .iter()
                .filter(|p| p.id == id || p.id.starts_with(id.as_str()))
                .collect();
            match hits.as_slice() {
                [one] => Ok(*one),
                [] => Err(format!("unknown paper {id:?}; expected one of {}", names())),
                _ => Err(format!(
                    "{id:?} names several papers ({}); expected one of {}",
                    hits.iter().map(|p| p.id).collect::<Vec<_>>().join(", "),
                    names()
                )),
            }
        })
        .collect()
}

/// Runs one paper's world (`root` is the repository, where the world files live) and
/// scores it.
///
/// # Errors
/// A world that does not load or run, or lacks an estimator the table needs.
pub fn run_paper(
    root: &Path,
    paper: &'static Paper,
    trials: u64,
    seed: u64,
    threads: usize,
) -> Result<PaperResult, String> {
    let world = load_world(&root.join(paper.world)).map_err(|e| e.to_string())?;
    let opts = RunOptions {
        trials,
        seed,
        threads,
        progress: false,
        shard: Shard::WHOLE,
    };
    let results = run_trials(&world, &opts)?;
    let summary = summarise(&world, &opts, &results)?;
    let mut scored = score(paper, &summary)?;
    let names: Vec<String> = summary.estimators.iter().map(|e| e.name.clone()).collect();
    paired::pair(&mut scored.orderings, &results, &names);
    for v in &mut scored.variants {
        paired::pair(&mut v.orderings, &results, &names);
    }
    Ok(scored)
}

/// Metres to the millimetre; a difference that rounds to zero prints as 0.000, not −0.000.
fn mm(x: f64) -> String {
    format!("{:.3}", (x * 1e3).round() / 1e3 + 0.0)
}

fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".to_string(), |x| format!("{x:.digits$}"))
}

fn tick(ok: bool) -> &'static str {
    if ok {
        "✓"
    } else {
        "✗"
    }
}

fn ordering_text(o: &OrderingResult) -> String {
    let names: Vec<&str> = o.values.iter().map(|v| v.0).collect();
    let vals: Vec<String> = o.values.iter().map(|v| fmt_opt(v.1, 2)).collect();
    let mut text = format!(
        "{}: {} ({})",
        o.metric.label(),
        names.join(" < "),
        vals.join(" < ")
    );
    if let Some(pairs) = paired_text(o) {
        let _ = write!(text, "; trial by trial: {pairs}");
    }
    text
}

/// Each adjacent pair of an ordering with its split of the trials, "A < B in k of n
/// trials, reversed in r[, t tied] (sign test p = …)", joined by "; "; `None` without
/// one.
fn paired_text(o: &OrderingResult) -> Option<String> {
    let pairs: Vec<String> = o
        .values
        .windows(2)
        .zip(&o.paired)
        .filter_map(|(w, p)| {
            let p = p.as_ref()?;
            let n = p.holds + p.reversed + p.ties;
            let ties = if p.ties > 0 {
                format!(", {} tied", p.ties)
            } else {
                String::new()
            };
            Some(format!(
                "{} < {} in {} of {n} trials, reversed in {}{ties} (sign test p = {})",
                w[0].0,
                w[1].0,
                p.holds,
                p.reversed,
                p_value(p.p)
            ))
        })
        .collect();
    (!pairs.is_empty()).then(|| pairs.join("; "))
}

/// A p-value to two significant digits, in scientific notation below 0.01.
fn p_value(p: f64) -> String {
    if p < 1e-2 {
        format!("{p:.1e}")
    } else if p < 0.1 {
        format!("{p:.3}")
    } else {
        format!("{p:.2}")
    }
}

/// The plain-text tables printed by `hybridnav reproduce`.
pub fn text(results: &[PaperResult]) -> String {
    let mut s = String::new();
    for r in results {
        let _ = writeln!(
            s,
            "{}\n{} — {} trial(s), seed {}",
            r.paper.title, r.paper.world, r.trials, r.seed
        );
        if !r.figures.is_empty() {
            let _ = writeln!(
                s,
                "  {:<20} {:<12} {:>10} {:>10} {:>7} {:>12}",
                "row", "figure", "paper", "hybridnav", "ratio", "PCRLB rmse"
            );
            for f in &r.figures {
                let [row, fig, paper, sim, ratio, bound, mark] = f.cells();
                let _ = writeln!(
                    s,
                    "  {row:<20} {fig:<12} {paper:>10} {sim:>10} {ratio:>7} {bound:>12} {mark}"
                );
            }
            let n = r.figures.iter().filter(|f| f.within()).count();
            let _ = writeln!(s, "  within 2×: {n} of {}", r.figures.len());
        }
        for o in &r.orderings {
            let _ = writeln!(s, "  {} {}", tick(o.holds()), ordering_text(o));
        }
        for g in &r.splits {
            let _ = writeln!(s, "  {}", g.line());
        }
        for st in &r.stated {
            let _ = writeln!(s, "  {}", st.line());
        }
        for v in &r.variants {
            let _ = writeln!(
                s,
                "  extra rows, not counted: {}\n  {:<20} {:<12} {:>10} {:>10} {:>7} {:>12}",
                v.variant.about, "row", "figure", "paper", "hybridnav", "ratio", "PCRLB rmse"
            );
            for f in &v.figures {
                let [row, fig, paper, sim, ratio, bound, mark] = f.cells();
                let _ = writeln!(
                    s,
                    "  {row:<20} {fig:<12} {paper:>10} {sim:>10} {ratio:>7} {bound:>12} {mark}"
                );
            }
            let n = v.figures.iter().filter(|f| f.within()).count();
            let _ = writeln!(s, "  within 2× (not counted): {n} of {}", v.figures.len());
            for o in &v.orderings {
                let _ = writeln!(s, "  {} {}", tick(o.holds()), ordering_text(o));
            }
        }
        for line in r
            .protocol
            .iter()
            .chain(&resets_lines(r))
            .chain(&bounds_line(r))
            .chain(&consistency_line(r))
        {
            let _ = writeln!(s, "  {line}");
        }
        s.push('\n');
    }
    let _ = writeln!(s, "{}", totals(results));
    s
}

/// One line per estimator that was reset, or one saying none was.
fn resets_lines(r: &PaperResult) -> Vec<String> {
    if r.resets.is_empty() {
        return vec!["Resets: none.".to_string()];
    }
    r.resets
        .iter()
        .map(|(name, n, share)| {
            format!(
                "Resets: {name} {n} times, {:.2} % of its epochs.",
                100.0 * share
            )
        })
        .collect()
}

/// One line with every bounded estimator's PCRLB and its RMSE over it (none without a
/// bounded estimator).
fn bounds_line(r: &PaperResult) -> Vec<String> {
    if r.bounds.is_empty() {
        return Vec::new();
    }
    let parts: Vec<String> = r
        .bounds
        .iter()
        .map(|(name, b, eff)| format!("{name} {b:.2} m ({eff:.2}×)"))
        .collect();
    vec![format!(
        "PCRLB on the RMSE (RMSE / PCRLB): {}.",
        parts.join(", ")
    )]
}

/// A filter is taken as consistent when its mean position NEES lies within this factor of
/// its degrees of freedom (the particle-filter issue's goal, "every PF's mean NEES within
/// 2× of its dof").
pub const NEES_WITHIN: f64 = 2.0;

/// Whether a mean NEES is within [`NEES_WITHIN`] of its degrees of freedom, either way.
pub fn nees_consistent(mean: f64, dof: f64) -> bool {
    let r = mean / dof;
    within_factor(r, NEES_WITHIN)
}

/// Whether a ratio lies within `factor` of 1 either way, `[1/factor, factor]`.
fn within_factor(ratio: f64, factor: f64) -> bool {
    (1.0 / factor..=factor).contains(&ratio)
}

/// A positive figure to three significant digits, in scientific notation from 10⁴ (a
/// diverged filter's NEES runs to 10⁸).
fn sig3(x: f64) -> String {
    if !x.is_finite() || x >= 1e4 {
        format!("{x:.2e}")
    } else if x >= 100.0 {
        format!("{x:.0}")
    } else if x >= 10.0 {
        format!("{x:.1}")
    } else {
        format!("{x:.2}")
    }
}

/// One line with every estimator's mean position NEES over its degrees of freedom, marked
/// ✗ outside [`NEES_WITHIN`] (none without an estimator that reports a covariance).
fn consistency_line(r: &PaperResult) -> Vec<String> {
    if r.consistency.is_empty() {
        return Vec::new();
    }
    let parts: Vec<String> = r
        .consistency
        .iter()
        .map(|(name, mean, dof)| {
            let mark = if nees_consistent(*mean, *dof) {
                ""
            } else {
                " ✗"
            };
            format!("{name} {}{mark}", sig3(mean / dof))
        })
        .collect();
    let inside = r
        .consistency
        .iter()
        .filter(|(_, m, d)| nees_consistent(*m, *d))
        .count();
    vec![format!(
        "Mean position NEES over its degrees of freedom (1 for a consistent filter; ✗ outside ½–2, {inside} of {} inside): {}.",
        r.consistency.len(),
        parts.join(", ")
    )]
}

fn totals(results: &[PaperResult]) -> String {
    let figs: Vec<&FigureResult> = results.iter().flat_map(|r| &r.figures).collect();
    let ords: Vec<&OrderingResult> = results.iter().flat_map(|r| &r.orderings).collect();
    format!(
        "{} of {} figures within 2× of the papers; {} of {} claimed orderings hold",
        figs.iter().filter(|f| f.within()).count(),
        figs.len(),
        ords.iter().filter(|o| o.holds()).count(),
        ords.len()
    )
}

/// The same tables in Markdown, for docs/reproductions-tables.md.
pub fn markdown(results: &[PaperResult]) -> String {
    let mut s = String::from(
        "<!-- Generated by `hybridnav reproduce --markdown docs/reproductions-tables.md`; do not edit by hand. -->\n\n# Reproduced tables\n\n",
    );
    if let Some(r) = results.first() {
        let _ = writeln!(
            s,
            "Every paper world at {} trials, seed {}. A figure is ✓ when hybridnav's value is within a factor of 2 of the paper's, and ✓ (bound) when the paper's figure lies below the posterior Cramér–Rao bound on the estimator's RMSE (no estimator of the world's model reaches it) and the estimator's RMSE is within 1.25× of that bound; an ordering is ✓ when it holds. Explanations of the figures outside 2× are in `docs/reproductions.md`.\n",
            r.trials, r.seed
        );
    }
    for r in results {
        let _ = writeln!(s, "## {}\n\n`{}`\n", r.paper.title, r.paper.world);
        if !r.figures.is_empty() {
            s.push_str("| row | figure | paper (m) | hybridnav (m) | ratio | PCRLB on RMSE (m) | within 2× |\n|---|---|---:|---:|---:|---:|:-:|\n");
            for f in &r.figures {
                let _ = writeln!(s, "| {} |", f.cells().join(" | "));
            }
            s.push('\n');
        }
        for o in &r.orderings {
            let _ = writeln!(s, "- {} {}", tick(o.holds()), ordering_text(o));
        }
        for g in &r.splits {
            let _ = writeln!(s, "- {}", g.line());
        }
        for st in &r.stated {
            let _ = writeln!(s, "- {}", st.line());
        }
        for v in &r.variants {
            let _ = writeln!(
                s,
                "\nExtra rows, not counted in the totals: {}.\n",
                v.variant.about
            );
            s.push_str("| row | figure | paper (m) | hybridnav (m) | ratio | PCRLB on RMSE (m) | within 2× |\n|---|---|---:|---:|---:|---:|:-:|\n");
            for f in &v.figures {
                let _ = writeln!(s, "| {} |", f.cells().join(" | "));
            }
            s.push('\n');
            for o in &v.orderings {
                let _ = writeln!(s, "- {} {}", tick(o.holds()), ordering_text(o));
            }
        }
        for line in r
            .protocol
            .iter()
            .chain(&resets_lines(r))
            .chain(&bounds_line(r))
            .chain(&consistency_line(r))
        {
            let _ = writeln!(s, "- {line}");
        }
        s.push('\n');
    }
    let _ = writeln!(s, "**{}.**", totals(results));
    s
}

/// A figure of 10 m published and `sim` simulated (its RMSE too), for the tests.
#[cfg(test)]
pub(crate) fn test_figure(sim: f64) -> FigureResult {
    FigureResult {
        row: "r",
        metric: Metric::Mean,
        paper_m: 10.0,
        simulated_m: Some(sim),
        rmse_m: Some(sim),
        pcrlb_m: None,
        deviates: false,
    }
}

/// An empty result of `paper`, for the tests to fill.
#[cfg(test)]
pub(crate) fn test_result(paper: &'static Paper) -> PaperResult {
    PaperResult {
        paper,
        trials: 1,
        seed: 1,
        figures: vec![],
        orderings: vec![],
        protocol: vec![],
        resets: vec![],
        variants: vec![],
        splits: vec![],
        stated: vec![],
        bounds: vec![],
        consistency: vec![],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The split's arithmetic by hand: EKF 3.0, CKF 2.5, RE-KF 2.0 m → gain 1.0 m, the
    /// term's part 0.5 m, share ½; no gain (RE-KF = EKF) → no share, whatever the term does.
    #[test]
    fn a_gain_split_is_the_terms_part_over_the_gain() {
        let split = &GAIN_SPLITS[0];
        let r = SplitResult {
            split,
            method_m: Some(2.0),
            without_m: Some(2.5),
            baseline_m: Some(3.0),
        };
        assert_eq!(r.gain_m(), Some(1.0));
        assert_eq!(r.term_part_m(), Some(0.5));
        assert_eq!(r.share(), Some(0.5));
        assert!(r.line().ends_with("share 50 %."), "{}", r.line());
        let tie = SplitResult {
            split,
            method_m: Some(2.584225),
            without_m: Some(2.584225),
            baseline_m: Some(2.584225),
        };
        assert_eq!(tie.share(), None);
        assert!(tie.line().contains("no gain to split"), "{}", tie.line());
        let missing = SplitResult {
            without_m: None,
            ..tie
        };
        assert_eq!(missing.share(), None);
        // Every split names rows of its paper's world (checked when the world runs) and
        // belongs to a paper `reproduce` knows.
        for g in GAIN_SPLITS {
            assert!(PAPERS.iter().any(|p| p.id == g.paper), "{}", g.paper);
        }
    }

    #[test]
    fn the_tables_hold_the_papers_56_figures() {
        let n: usize = PAPERS.iter().map(|p| p.figures.len()).sum();
        assert_eq!(n, 21 + 21 + 4 + 4 + 6);
        assert!(PAPERS
            .iter()
            .all(|p| p.figures.iter().all(|f| f.paper_m > 0.0)));
        // Every variant extends a paper that exists, with figures the paper also has.
        for v in VARIANTS {
            let p = PAPERS.iter().find(|p| p.id == v.paper).expect(v.paper);
            for f in v.figures {
                assert!(p
                    .figures
                    .iter()
                    .any(|g| g.metric == f.metric && g.paper_m == f.paper_m));
            }
        }
    }

    /// The consistency line by hand: NEES 3.3 for 3 dof is inside, 7 (2.33×) and 1.4
    /// (0.47×) are not, and a diverged filter's 1.4e7 prints in scientific notation.
    #[test]
    fn the_consistency_line_marks_the_filters_outside_half_to_twice() {
        assert!(
            nees_consistent(3.3, 3.0) && nees_consistent(6.0, 3.0) && nees_consistent(1.5, 3.0)
        );
        assert!(!nees_consistent(7.0, 3.0) && !nees_consistent(1.4, 3.0));
        let mut r = test_result(&PAPERS[0]);
        r.consistency = vec![
            ("EKF".into(), 3.3, 3.0),
            ("PF-100".into(), 1.4e7, 3.0),
            ("PF-2d".into(), 2.8, 2.0),
        ];
        assert_eq!(
            consistency_line(&r),
            vec!["Mean position NEES over its degrees of freedom (1 for a consistent filter; ✗ outside ½–2, 2 of 3 inside): EKF 1.10, PF-100 4.67e6 ✗, PF-2d 1.40.".to_string()]
        );
        r.consistency.clear();
        assert!(consistency_line(&r).is_empty());
    }

    #[test]
    fn selection_by_stem_and_prefix() {
        assert_eq!(
            select(&["seed003".into()]).unwrap()[0].id,
            "seed003-seamless"
        );
        assert!(select(&["seed000".into()]).unwrap_err().contains("several"));
        assert!(select(&["nope".into()])
            .unwrap_err()
            .contains("expected one of"));
        assert_eq!(select(&[]).unwrap().len(), PAPERS.len());
    }

    /// A stated value is met within 2×, a stated bound by anything up to it; a run with
    /// no epoch there meets neither. (That seed 004's statements are read from the
    /// summary's `environments` is tested on the world, `tests/it/reproductions.rs`.)
    #[test]
    fn stated_figures_are_met_as_the_papers_words_say() {
        let value = &STATED[0];
        let bound = &STATED[1];
        assert!(!value.at_most && value.paper_m == 0.5 && value.place == papers::Place::Outdoor);
        assert!(bound.at_most && bound.paper_m == 1.0 && bound.place == papers::Place::Indoor);
        let r = |stated, x: Option<f64>| StatedResult {
            stated,
            simulated_m: x,
        };
        assert!(r(value, Some(0.25)).met() && r(value, Some(1.0)).met());
        assert!(!r(value, Some(1.01)).met() && !r(value, Some(0.24)).met());
        assert!(r(bound, Some(0.01)).met() && r(bound, Some(1.0)).met());
        assert!(!r(bound, Some(1.001)).met() && !r(bound, None).met());
        let line = r(value, Some(1.2)).line();
        assert!(
            line.contains("RE-KF horizontal RMS outdoors 1.20 m")
                && line.contains("2.40× ✗")
                && line.contains("0.5 m"),
            "{line}"
        );
        assert!(r(bound, Some(0.8)).line().ends_with("at most 1 m ✓"));
    }

    #[test]
    fn within_two_and_orderings() {
        let f = test_figure;
        assert!(f(5.0).within() && f(20.0).within() && f(12.0).within());
        assert!(!f(4.99).within() && !f(20.01).within());
        // A published 10 m below a 30 m bound: 37.5 m RMSE (1.25× the bound) counts, 37.6
        // does not; a bound below the published figure changes nothing.
        let b = |rmse: f64, bound: f64| FigureResult {
            pcrlb_m: Some(bound),
            ..f(rmse)
        };
        assert!(b(37.5, 30.0).within() && b(37.5, 30.0).at_bound());
        assert!(!b(37.6, 30.0).within());
        assert!(!b(25.0, 8.0).within() && !b(25.0, 8.0).at_bound());
        let o = |a: f64, b: f64| OrderingResult {
            paired: vec![],
            metric: Metric::Mean,
            values: vec![("a", Some(a)), ("b", Some(b))],
        };
        assert!(o(1.0, 2.0).holds() && !o(2.0, 1.0).holds() && !o(1.0, 1.0).holds());
        // Agreeing to six digits is a tie.
        assert!(!o(2.584225, 2.5842251).holds() && o(2.0, 2.01).holds());
    }
}
