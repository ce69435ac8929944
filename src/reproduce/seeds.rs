//! `hybridnav reproduce --seeds A-B`: the paper tables over several master seeds.
//!
//! The fair-reproductions goals are stated over seeds 1–5 ("≥ 45 of the 56 figures within
//! 2×, each paper's ordering holding … with 20 trials and seeds 1–5"), because one seed's
//! 20 trials can put a heavy-tailed figure (a 3σ level, an RMSE) on either side of the 2×
//! line. This module lays the runs of several seeds side by side: for every figure its
//! smallest, median and largest simulated value and the seeds on which it is within 2×;
//! for every ordering the seeds on which it holds; for every paper its worst reset share;
//! and the totals per seed, on every seed and on at least one. Each seed's run is scored
//! exactly as a one-seed `hybridnav reproduce --seed S` scores it ([`super::score`]), so
//! the per-seed totals equal those runs' totals (tested).

use super::paired::PairedSign;
use super::{fmt_opt, FigureResult, OrderingResult, PaperResult};
use std::fmt::Write as _;

/// The most seeds one sweep takes (each is a full run of every selected paper).
pub const MAX_SEEDS: usize = 64;

/// Parses a seed list: `A-B` (inclusive), `A,B,C` or one seed; the seeds must be distinct.
///
/// # Errors
/// An empty or malformed list, a reversed range, a repeated seed, or more than
/// [`MAX_SEEDS`] seeds, with the text that was given.
pub fn parse_seeds(text: &str) -> Result<Vec<u64>, String> {
    let bad = |why: &str| {
        Err(format!(
            "--seeds {text:?}: {why}; expected a range A-B, a list A,B,C or one seed"
        ))
    };
    let num = |s: &str| s.trim().parse::<u64>().ok();
    let seeds: Vec<u64> = if let Some((a, b)) = text.split_once('-') {
        let (Some(a), Some(b)) = (num(a), num(b)) else {
            return bad("a bound is not a non-negative integer");
        };
        if b < a {
            return bad("the range runs backwards");
        }
        if b - a >= MAX_SEEDS as u64 {
            return bad(&format!("more than {MAX_SEEDS} seeds"));
        }
        (a..=b).collect()
    } else {
        let parts: Vec<Option<u64>> = text.split(',').map(num).collect();
        if parts.iter().any(Option::is_none) {
            return bad("an entry is not a non-negative integer");
        }
        parts.into_iter().flatten().collect()
    };
    if seeds.len() > MAX_SEEDS {
        return bad(&format!("more than {MAX_SEEDS} seeds"));
    }
    let mut sorted = seeds.clone();
    sorted.sort_unstable();
    sorted.dedup();
    if sorted.len() != seeds.len() {
        return bad("a seed is repeated");
    }
    Ok(seeds)
}

/// One figure over the seeds.
#[derive(Clone, Debug)]
pub struct FigureAcross {
    pub row: &'static str,
    pub label: &'static str,
    pub paper_m: f64,
    /// The simulated value of each seed, in the sweep's order.
    pub simulated_m: Vec<Option<f64>>,
    /// Whether it counts as reproduced on each seed ([`FigureResult::within`]).
    pub within: Vec<bool>,
}

impl FigureAcross {
    /// Smallest, median (the mean of the middle two for an even count) and largest
    /// simulated value over the seeds that have one.
    pub fn spread(&self) -> Option<(f64, f64, f64)> {
        let mut v: Vec<f64> = self.simulated_m.iter().flatten().copied().collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let median = if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        };
        Some((v[0], median, v[n - 1]))
    }

    /// The spread as both reports print it: smallest, median and largest to the
    /// centimetre, `-` where no seed has a value.
    fn spread_cells(&self) -> [String; 3] {
        match self.spread() {
            Some((lo, med, hi)) => [lo, med, hi].map(|x| fmt_opt(Some(x), 2)),
            None => [(); 3].map(|()| fmt_opt(None, 2)),
        }
    }

    /// On how many seeds the figure is within.
    pub fn within_count(&self) -> usize {
        self.within.iter().filter(|w| **w).count()
    }
}

/// One paper over the seeds.
#[derive(Clone, Debug)]
pub struct PaperAcross {
    pub title: &'static str,
    pub world: &'static str,
    pub figures: Vec<FigureAcross>,
    /// Each claimed ordering's text on the first seed and on how many seeds it holds.
    pub orderings: Vec<(String, usize)>,
    /// Each claimed ordering's pairs trial by trial, the seeds' splits taken together
    /// ([`super::paired::PairedSign::pooled`]); `None` where a seed has no split.
    pub orderings_paired: Vec<Option<String>>,
    /// The largest reset share of any of the world's estimators on each seed, with its
    /// estimator (`None`: no reset on that seed).
    pub worst_resets: Vec<Option<(String, f64)>>,
    /// Each estimator that reports a covariance (by the first seed's list) and on how many
    /// seeds its mean position NEES is within 2× of its degrees of freedom
    /// ([`super::nees_consistent`]).
    pub consistent: Vec<(String, usize)>,
    /// The figures the paper states in its text ([`super::StatedResult`]) over the seeds,
    /// `within` being whether each seed meets the paper's words; counted in no total.
    pub stated: Vec<FigureAcross>,
}

/// The sweep: `runs[k]` is seed `seeds[k]`'s results, every run over the same papers in
/// the same order.
#[derive(Clone, Debug)]
pub struct Sweep {
    pub seeds: Vec<u64>,
    pub trials: u64,
    pub papers: Vec<PaperAcross>,
    /// Per seed: (figures within, figures, orderings holding, orderings).
    pub totals: Vec<(usize, usize, usize, usize)>,
}

impl Sweep {
    /// Lays the runs side by side.
    ///
    /// # Errors
    /// When the runs do not hold the same papers with the same figures and orderings (a
    /// caller's mistake, never a user's).
    pub fn new(seeds: Vec<u64>, runs: &[Vec<PaperResult>]) -> Result<Self, String> {
        if runs.len() != seeds.len() || runs.is_empty() {
            return Err(format!("{} runs for {} seeds", runs.len(), seeds.len()));
        }
        let first = &runs[0];
        let same = runs.iter().all(|r| {
            r.len() == first.len()
                && r.iter().zip(first).all(|(a, b)| {
                    a.paper.id == b.paper.id
                        && a.figures.len() == b.figures.len()
                        && a.orderings.len() == b.orderings.len()
                        && a.stated.len() == b.stated.len()
                })
        });
        if !same {
            return Err("the seeds' runs do not hold the same papers".into());
        }
        let papers = first
            .iter()
            .enumerate()
            .map(|(pi, p0)| {
                let figures = p0
                    .figures
                    .iter()
                    .enumerate()
                    .map(|(fi, f0)| {
                        let per: Vec<&FigureResult> =
                            runs.iter().map(|r| &r[pi].figures[fi]).collect();
                        FigureAcross {
                            row: f0.row,
                            label: f0.metric.label(),
                            paper_m: f0.paper_m,
                            simulated_m: per.iter().map(|f| f.simulated_m).collect(),
                            within: per.iter().map(|f| f.within()).collect(),
                        }
                    })
                    .collect();
                let orderings = p0
                    .orderings
                    .iter()
                    .enumerate()
                    .map(|(oi, o0)| {
                        let held = runs.iter().filter(|r| r[pi].orderings[oi].holds()).count();
                        (claim_text(o0), held)
                    })
                    .collect();
                let orderings_paired = p0
                    .orderings
                    .iter()
                    .enumerate()
                    .map(|(oi, o0)| {
                        let pooled = (0..o0.paired.len())
                            .map(|j| {
                                let parts: Option<Vec<&PairedSign>> = runs
                                    .iter()
                                    .map(|r| r[pi].orderings[oi].paired.get(j)?.as_ref())
                                    .collect();
                                parts.map(PairedSign::pooled)
                            })
                            .collect();
                        super::paired_text(&OrderingResult {
                            paired: pooled,
                            ..o0.clone()
                        })
                    })
                    .collect();
                let worst_resets = runs
                    .iter()
                    .map(|r| {
                        r[pi]
                            .resets
                            .iter()
                            .max_by(|a, b| a.2.total_cmp(&b.2))
                            .map(|(n, _, s)| (n.clone(), *s))
                    })
                    .collect();
                let consistent = p0
                    .consistency
                    .iter()
                    .map(|(name, _, _)| {
                        let seeds =
                            runs.iter()
                                .filter(|r| {
                                    r[pi].consistency.iter().any(|(n, m, d)| {
                                        n == name && super::nees_consistent(*m, *d)
                                    })
                                })
                                .count();
                        (name.clone(), seeds)
                    })
                    .collect();
                let stated = p0
                    .stated
                    .iter()
                    .enumerate()
                    .map(|(si, s0)| {
                        let per: Vec<&super::StatedResult> =
                            runs.iter().map(|r| &r[pi].stated[si]).collect();
                        FigureAcross {
                            row: s0.stated.estimator,
                            label: s0.stated.place.adverb(),
                            paper_m: s0.stated.paper_m,
                            simulated_m: per.iter().map(|x| x.simulated_m).collect(),
                            within: per.iter().map(|x| x.met()).collect(),
                        }
                    })
                    .collect();
                PaperAcross {
                    consistent,
                    stated,
                    title: p0.paper.title,
                    world: p0.paper.world,
                    figures,
                    orderings,
                    orderings_paired,
                    worst_resets,
                }
            })
            .collect();
        let totals = runs
            .iter()
            .map(|r| {
                let figs: Vec<&FigureResult> = r.iter().flat_map(|p| &p.figures).collect();
                let ords: Vec<&OrderingResult> = r.iter().flat_map(|p| &p.orderings).collect();
                (
                    figs.iter().filter(|f| f.within()).count(),
                    figs.len(),
                    ords.iter().filter(|o| o.holds()).count(),
                    ords.len(),
                )
            })
            .collect();
        Ok(Self {
            seeds,
            trials: first.first().map_or(0, |p| p.trials),
            papers,
            totals,
        })
    }

    fn figures(&self) -> impl Iterator<Item = &FigureAcross> {
        self.papers.iter().flat_map(|p| &p.figures)
    }

    /// Figures within on every seed, and on at least one.
    pub fn figures_within(&self) -> (usize, usize) {
        let n = self.seeds.len();
        (
            self.figures().filter(|f| f.within_count() == n).count(),
            self.figures().filter(|f| f.within_count() > 0).count(),
        )
    }

    /// Orderings that hold on every seed.
    pub fn orderings_holding(&self) -> usize {
        let n = self.seeds.len();
        self.papers
            .iter()
            .flat_map(|p| &p.orderings)
            .filter(|o| o.1 == n)
            .count()
    }

    fn seed_list(&self) -> String {
        let s: Vec<String> = self.seeds.iter().map(u64::to_string).collect();
        s.join(", ")
    }

    fn totals_lines(&self) -> Vec<String> {
        let n = self.seeds.len();
        let nfig = self.figures().count();
        let nord: usize = self.papers.iter().map(|p| p.orderings.len()).sum();
        let per: Vec<String> = self
            .seeds
            .iter()
            .zip(&self.totals)
            .map(|(s, t)| {
                format!(
                    "seed {s}: {} of {} figures, {} of {} orderings",
                    t.0, t.1, t.2, t.3
                )
            })
            .collect();
        let (every, any) = self.figures_within();
        vec![
            format!("Per seed: {}.", per.join("; ")),
            format!(
                "Within 2× on all {n} seeds: {every} of {nfig} figures; on at least one: {any}. \
                 Orderings holding on all {n} seeds: {} of {nord}.",
                self.orderings_holding()
            ),
        ]
    }

    /// The estimators whose mean NEES is within 2× of its dof on every seed, on some and
    /// on none (nothing without an estimator that reports a covariance).
    fn consistency_line(p: &PaperAcross, n: usize) -> Option<String> {
        if p.consistent.is_empty() {
            return None;
        }
        let pick = |keep: &dyn Fn(usize) -> bool, with_count: bool| -> String {
            let v: Vec<String> = p
                .consistent
                .iter()
                .filter(|(_, k)| keep(*k))
                .map(|(name, k)| {
                    if with_count {
                        format!("{name} ({k}/{n})")
                    } else {
                        name.clone()
                    }
                })
                .collect();
            if v.is_empty() {
                "none".to_string()
            } else {
                v.join(", ")
            }
        };
        Some(format!(
            "Mean NEES within 2× of its dof on all {n} seeds: {}; on some: {}; on none: {}.",
            pick(&|k| k == n, false),
            pick(&|k| k > 0 && k < n, true),
            pick(&|k| k == 0, false)
        ))
    }

    fn resets_line(p: &PaperAcross, seeds: &[u64]) -> String {
        let parts: Vec<String> = seeds
            .iter()
            .zip(&p.worst_resets)
            .map(|(s, w)| match w {
                Some((name, share)) => format!("seed {s} {name} {:.2} %", 100.0 * share),
                None => format!("seed {s} none"),
            })
            .collect();
        format!("Largest reset share: {}.", parts.join(", "))
    }

    /// The lines under a paper's table in both reports: each ordering's seeds (with its
    /// pairs over all the seeds' trials), the figures stated in the paper's text, who is
    /// consistent on which seeds, and the largest reset share per seed.
    fn paper_lines(&self, p: &PaperAcross) -> Vec<String> {
        let n = self.seeds.len();
        let mut lines: Vec<String> = p
            .orderings
            .iter()
            .zip(&p.orderings_paired)
            .map(|((text, held), paired)| match paired {
                Some(pairs) => format!(
                    "holds on {held}/{n}: {text}; trial by trial over the {n} seeds: {pairs}"
                ),
                None => format!("holds on {held}/{n}: {text}"),
            })
            .collect();
        lines.extend(p.stated.iter().map(|f| {
            let [lo, med, hi] = f.spread_cells();
            format!(
                "Stated in the text, not counted: {} horizontal RMS {} {lo} / {med} / {hi} m \
                 (smallest / median / largest) against the paper's {} m; meets the paper's \
                 words on {}/{n}.",
                f.row,
                f.label,
                f.paper_m,
                f.within_count()
            )
        }));
        lines.extend(Self::consistency_line(p, n));
        lines.push(Self::resets_line(p, &self.seeds));
        lines
    }

    /// The plain-text report.
    pub fn text(&self) -> String {
        let n = self.seeds.len();
        let mut s = String::new();
        let _ = writeln!(
            s,
            "Across master seeds {} ({} trial(s) each)\n",
            self.seed_list(),
            self.trials
        );
        for p in &self.papers {
            let _ = writeln!(s, "{}\n{}", p.title, p.world);
            if !p.figures.is_empty() {
                let _ = writeln!(
                    s,
                    "  {:<20} {:<12} {:>10} {:>10} {:>10} {:>10} {:>8}",
                    "row", "figure", "paper", "min", "median", "max", "within"
                );
                for f in &p.figures {
                    let [lo, med, hi] = f.spread_cells();
                    let _ = writeln!(
                        s,
                        "  {:<20} {:<12} {:>10.2} {lo:>10} {med:>10} {hi:>10} {:>8}",
                        f.row,
                        f.label,
                        f.paper_m,
                        format!("{}/{n}", f.within_count())
                    );
                }
            }
            for line in self.paper_lines(p) {
                let _ = writeln!(s, "  {line}");
            }
            s.push('\n');
        }
        for line in self.totals_lines() {
            let _ = writeln!(s, "{line}");
        }
        s
    }

    /// The same report in Markdown.
    pub fn markdown(&self) -> String {
        let n = self.seeds.len();
        let mut s = format!(
            "<!-- Generated by `hybridnav reproduce --seeds … --markdown FILE`; do not edit by hand. -->\n\n\
             # Reproduced tables across master seeds\n\n\
             Every paper world at {} trials on each of the master seeds {}. For each published figure: the smallest, median and largest of hybridnav's values over the seeds, and on how many seeds it is within 2× of the paper's (or at the bound, as in `reproductions-tables.md`); for each claimed ordering, on how many seeds it holds.\n\n",
            self.trials,
            self.seed_list()
        );
        for p in &self.papers {
            let _ = writeln!(s, "## {}\n\n`{}`\n", p.title, p.world);
            if !p.figures.is_empty() {
                s.push_str("| row | figure | paper (m) | min (m) | median (m) | max (m) | within 2× |\n|---|---|---:|---:|---:|---:|:-:|\n");
                for f in &p.figures {
                    let [lo, med, hi] = f.spread_cells();
                    let _ = writeln!(
                        s,
                        "| {} | {} | {:.2} | {lo} | {med} | {hi} | {}/{n} |",
                        f.row,
                        f.label,
                        f.paper_m,
                        f.within_count()
                    );
                }
                s.push('\n');
            }
            for line in self.paper_lines(p) {
                let _ = writeln!(s, "- {line}");
            }
            s.push('\n');
        }
        for line in self.totals_lines() {
            let _ = writeln!(s, "**{line}**\n");
        }
        s
    }
}

/// An ordering's claim without the values, which differ from seed to seed.
fn claim_text(o: &OrderingResult) -> String {
    let names: Vec<&str> = o.values.iter().map(|v| v.0).collect();
    format!("{}: {}", o.metric.label(), names.join(" < "))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reproduce::papers::{Metric, PAPERS};

    #[test]
    fn seed_lists() {
        assert_eq!(parse_seeds("1-5").unwrap(), vec![1, 2, 3, 4, 5]);
        assert_eq!(parse_seeds("7").unwrap(), vec![7]);
        assert_eq!(parse_seeds("3, 1,9").unwrap(), vec![3, 1, 9]);
        for bad in ["", "5-1", "1,1", "a-3", "1,,2", "-3", "0-64"] {
            let e = parse_seeds(bad).unwrap_err();
            assert!(e.contains("expected a range"), "{bad}: {e}");
        }
        assert_eq!(parse_seeds("0-63").unwrap().len(), MAX_SEEDS);
    }

    /// The sweep's arithmetic by hand: three seeds of one made-up paper result whose one
    /// figure (paper 10 m) is 4, 12 and 30 m, so within on one seed only, median 12; an
    /// ordering that holds on two; resets on one seed.
    #[test]
    fn spreads_counts_and_totals_by_hand() {
        let paper = &PAPERS[3];
        let run = |sim: f64, a: f64, reset: Option<f64>| {
            let mut r = crate::reproduce::test_result(paper);
            r.trials = 2;
            r.figures = vec![crate::reproduce::test_figure(sim)];
            r.orderings = vec![OrderingResult {
                paired: vec![Some(super::super::paired::PairedSign::of([
                    (Some(1.0), Some(2.0)),
                    (Some(a), Some(2.0)),
                ]))],
                metric: Metric::Mean,
                values: vec![("a (tight)", Some(a)), ("b", Some(2.0))],
            }];
            r.resets = reset.map_or_else(Vec::new, |s| vec![("PF".to_string(), 3, s)]);
            r.consistency = vec![
                ("PF".to_string(), 3.0 * a, 3.0),
                ("EKF".to_string(), 3.3, 3.0),
            ];
            // A stated figure (0.5 m outdoors) at 1.5 × the seed's figure: met (≤ 1 m)
            // on the first seed only.
            r.stated = vec![crate::reproduce::StatedResult {
                stated: &crate::reproduce::papers::STATED[0],
                simulated_m: Some(sim / 6.0),
            }];
            vec![r]
        };
        let runs = vec![
            run(4.0, 1.0, None),
            run(12.0, 1.5, Some(0.02)),
            run(30.0, 3.0, None),
        ];
        let sw = Sweep::new(vec![1, 2, 3], &runs).unwrap();
        let f = &sw.papers[0].figures[0];
        assert_eq!(f.spread(), Some((4.0, 12.0, 30.0)));
        assert_eq!(f.within_count(), 1);
        assert_eq!(
            sw.papers[0].orderings[0],
            ("mean: a (tight) < b".to_string(), 2)
        );
        assert_eq!(sw.figures_within(), (0, 1));
        assert_eq!(sw.orderings_holding(), 0);
        assert_eq!(sw.totals, vec![(0, 1, 1, 1), (1, 1, 1, 1), (0, 1, 0, 1)]);
        let text = sw.text();
        assert!(text.contains("seed 2 PF 2.00 %") && text.contains("seed 1 none"));
        // Each seed's two trials: the first holds, the second holds for a = 1 and 1.5 and
        // is reversed for a = 3; over the seeds 5 hold and 1 is reversed.
        assert!(
            text.contains(
                "holds on 2/3: mean: a (tight) < b; trial by trial over the 3 seeds: a (tight) \
                 < b in 5 of 6 trials, reversed in 1 (sign test p = 0.22)"
            ),
            "{text}"
        );
        // The PF's NEES is 3a for 3 dof: a = 1 and 1.5 are within 2×, a = 3 is not.
        assert_eq!(
            sw.papers[0].consistent,
            vec![("PF".to_string(), 2), ("EKF".to_string(), 3)]
        );
        assert!(text.contains("on all 3 seeds: EKF; on some: PF (2/3); on none: none."));
        assert!(
            text.contains(
                "RE-KF horizontal RMS outdoors 0.67 / 2.00 / 5.00 m (smallest / median / \
                 largest) against the paper's 0.5 m; meets the paper's words on 1/3."
            ),
            "{text}"
        );
        // An even count's median is the mean of the middle two.
        let sw2 = Sweep::new(vec![1, 2], &runs[..2]).unwrap();
        assert_eq!(sw2.papers[0].figures[0].spread(), Some((4.0, 8.0, 12.0)));
        assert!(Sweep::new(vec![1], &runs).is_err());
    }
}
