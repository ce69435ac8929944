//! Choosing K new transmitter sites among candidates.
//!
//! **Objective.** With `S` the chosen sites, every outdoor cell `c` gets
//! `v_c(S) = max over epochs of GDOP_hybrid` (`gdop95`) or of `σ_3D` (`error95`) with the
//! rows of `S` added to the cell's hybrid geometry ([`super::metrics`]); cells where the
//! geometry stays singular count as [`GDOP_CAP`] or [`ERROR_CAP_M`]. The objective is the
//! 95th percentile (nearest rank) of `v_c(S)` over the cells, ties broken by their mean,
//! so that among placements with the same p95 the one that also helps the other cells
//! wins.
//!
//! **Search.** Greedy: add the site that lowers the objective most, K times. Then local
//! search by best improvement: among all swaps of a chosen site for an unchosen
//! candidate, apply the best one if it lowers the objective, until none does (a 2-swap
//! local optimum). Candidates are scanned in file order and only strict improvements are
//! taken, so the result is deterministic. Greedy is myopic — the best single site can be
//! a poor member of the best pair — and the swaps repair that. A baseline of R seeded
//! random K-subsets is reported beside it.

use super::metrics::{Normals, Row};
use rand::SeedableRng;
use std::cmp::Ordering;
use std::path::Path;

/// GDOP counted for a cell whose geometry is singular.
pub const GDOP_CAP: f64 = 100.0;
/// Predicted error (m) counted for a cell whose geometry is singular.
pub const ERROR_CAP_M: f64 = 1000.0;

/// What the placement minimises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Objective {
    /// 95th percentile of the hybrid GDOP over the region.
    Gdop95,
    /// 95th percentile of the predicted 3-D position error over the region.
    Error95,
}

impl Objective {
    /// The names the command line and the outputs use.
    pub const NAMES: [&'static str; 2] = ["gdop95", "error95"];
}

impl std::str::FromStr for Objective {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "gdop95" => Ok(Objective::Gdop95),
            "error95" => Ok(Objective::Error95),
            _ => Err(format!(
                "expected one of {}, got {s:?}",
                Self::NAMES.join(", ")
            )),
        }
    }
}

/// A value of the objective: the 95th percentile and the mean that breaks ties.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Score {
    pub p95: f64,
    pub mean: f64,
}

impl Score {
    /// Whether `self` is strictly better than `other` (lower p95, or equal p95 and lower
    /// mean), beyond rounding.
    pub fn better_than(&self, other: &Score) -> bool {
        let tol = |a: f64| 1e-12 * a.abs().max(1.0);
        if self.p95 < other.p95 - tol(other.p95) {
            return true;
        }
        (self.p95 - other.p95).abs() <= tol(other.p95) && self.mean < other.mean - tol(other.mean)
    }

    fn cmp(&self, other: &Score) -> Ordering {
        self.p95
            .total_cmp(&other.p95)
            .then(self.mean.total_cmp(&other.mean))
    }
}

/// A candidate site from the candidates file.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Candidate {
    pub id: String,
    pub east_m: f64,
    pub north_m: f64,
    pub height_m: f64,
    pub kind: String,
    pub erp_kw: f64,
    pub freq_mhz: f64,
    /// The line it was read from (1-based).
    pub line: usize,
}

/// Default ERP of a candidate DTMB site (kW): a small gap filler.
pub const DEFAULT_DTMB_ERP_KW: f64 = 1.0;
/// Default frequency of a candidate DTMB site (MHz): UHF channel 21.
pub const DEFAULT_DTMB_FREQ_MHZ: f64 = 474.0 + 8.0 * 8.0;
/// Default ERP of a candidate TC-OFDM site (kW).
pub const DEFAULT_TCOFDM_ERP_KW: f64 = 0.1;
/// Default frequency of a candidate TC-OFDM site (MHz).
pub const DEFAULT_TCOFDM_FREQ_MHZ: f64 = 1900.0;

/// Parses a candidates file: CSV lines `id,east_m,north_m,height_m[,kind[,erp_kw[,freq_mhz]]]`
/// in the world's ENU frame (height above the origin's ground level), `kind` `dtmb`
/// (default) or `tcofdm`; blank lines and lines starting with `#` are skipped, as is a
/// first line starting with `id`. Every site must lie inside `region`.
///
/// # Errors
/// `FILE:LINE: message` for an unreadable file, a malformed line, a non-finite
/// coordinate, a site outside the region, a duplicate id, an unknown kind, an ERP or
/// frequency out of range, or a file without candidates.
pub fn parse_candidates(
    path: &Path,
    region: &super::grid::Region,
) -> Result<Vec<Candidate>, String> {
    let cannot =
        |e: std::io::Error| format!("{}: cannot read the candidates file: {e}", path.display());
    let reader = crate::io::read::reader(path, crate::io::read::CANDIDATES).map_err(cannot)?;
    parse_candidates_from(reader, &path.display().to_string(), region)
}

/// [`parse_candidates`] on text, `name` naming it in messages.
///
/// # Errors
/// As [`parse_candidates`].
pub fn parse_candidates_text(
    text: &str,
    name: &str,
    region: &super::grid::Region,
) -> Result<Vec<Candidate>, String> {
    parse_candidates_from(text.as_bytes(), name, region)
}

/// [`parse_candidates`] on a stream, read one line at a time: time is linear in the
/// file's length (ids are checked for duplicates in a hash map) and the first bad line
/// is reported without reading further.
///
/// # Errors
/// As [`parse_candidates`].
pub fn parse_candidates_from(
    mut input: impl std::io::BufRead,
    name: &str,
    region: &super::grid::Region,
) -> Result<Vec<Candidate>, String> {
    let mut out: Vec<Candidate> = Vec::new();
    let mut first_line: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    let mut bytes: Vec<u8> = Vec::new();
    let mut line_no = 0;
    loop {
        bytes.clear();
        let n = input
            .read_until(b'\n', &mut bytes)
            .map_err(|e| format!("{name}: cannot read the candidates file: {e}"))?;
        if n == 0 {
            break;
        }
        line_no += 1;
        let err = |m: String| format!("{name}:{line_no}: {m}");
        let raw = std::str::from_utf8(&bytes).map_err(|e| {
            err(format!(
                "byte {} of the line: not UTF-8 text; save the file as UTF-8",
                e.valid_up_to() + 1
            ))
        })?;
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if out.is_empty() && line.to_ascii_lowercase().starts_with("id") {
            continue;
        }
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if !(4..=7).contains(&f.len()) {
            return Err(err(format!(
                "expected id,east_m,north_m,height_m[,kind[,erp_kw[,freq_mhz]]], got {} fields",
                f.len()
            )));
        }
        let id = f[0].to_string();
        if id.is_empty() {
            return Err(err("expected a non-empty id".into()));
        }
        let num = |i: usize, what: &str| -> Result<f64, String> {
            let v: f64 = f[i]
                .parse()
                .map_err(|_| err(format!("{what}: expected a number, got {:?}", f[i])))?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(err(format!("{what}: expected a finite number, got {v}")))
            }
        };
        let (east_m, north_m, height_m) =
            (num(1, "east_m")?, num(2, "north_m")?, num(3, "height_m")?);
        if !region.contains(east_m, north_m) {
            return Err(err(format!(
                "candidate {id} at ({east_m}, {north_m}) m is outside the region E {:.1}…{:.1} m, N {:.1}…{:.1} m",
                region.west_m, region.east_m, region.south_m, region.north_m
            )));
        }
        if !(0.0..=1000.0).contains(&height_m) {
            return Err(err(format!(
                "height_m: expected an antenna height in [0, 1000] m, got {height_m}"
            )));
        }
        let kind = f.get(4).map_or("dtmb", |s| s).to_ascii_lowercase();
        let (erp0, freq0, band) = match kind.as_str() {
            "dtmb" => (DEFAULT_DTMB_ERP_KW, DEFAULT_DTMB_FREQ_MHZ, 470.0..=862.0),
            "tcofdm" => (
                DEFAULT_TCOFDM_ERP_KW,
                DEFAULT_TCOFDM_FREQ_MHZ,
                100.0..=6000.0,
            ),
            other => return Err(err(format!("kind: expected dtmb or tcofdm, got {other:?}"))),
        };
        let erp_kw = if f.len() > 5 { num(5, "erp_kw")? } else { erp0 };
        if !(erp_kw > 0.0 && erp_kw <= 1e4) {
            return Err(err(format!(
                "erp_kw: expected an ERP in (0, 10000] kW, got {erp_kw}"
            )));
        }
        let freq_mhz = if f.len() > 6 {
            num(6, "freq_mhz")?
        } else {
            freq0
        };
        if !band.contains(&freq_mhz) {
            return Err(err(format!(
                "freq_mhz: expected {:?} MHz for a {kind} site, got {freq_mhz}",
                band
            )));
        }
        if let Some(prev) = first_line.get(&id) {
            return Err(err(format!(
                "duplicate candidate id {id:?} (first on line {prev})"
            )));
        }
        first_line.insert(id.clone(), line_no);
        out.push(Candidate {
            id,
            east_m,
            north_m,
            height_m,
            kind,
            erp_kw,
            freq_mhz,
            line: line_no,
        });
    }
    if out.is_empty() {
        return Err(format!("{name}: no candidate sites"));
    }
    Ok(out)
}

/// The data the objective reads: the hybrid normal matrices of every considered cell and
/// epoch, and the row of every candidate at every cell.
pub struct Problem<'a> {
    /// `cells × epochs`, cell-major.
    pub base: &'a [Normals],
    pub epochs: usize,
    /// `candidates × cells`, candidate-major.
    pub rows: &'a [Row],
    pub cells: usize,
    /// The cells the statistics run over (outdoor cells).
    pub considered: &'a [usize],
    pub objective: Objective,
}

impl Problem<'_> {
    /// The value at cell `c` with the sites `chosen` added.
    pub fn cell_value(&self, c: usize, chosen: &[usize]) -> f64 {
        let mut worst = 0.0f64;
        for e in 0..self.epochs {
            let mut n = self.base[c * self.epochs + e];
            for &s in chosen {
                n.add(&self.rows[s * self.cells + c]);
            }
            let (gdop, sigma) = n.solve();
            let v = match self.objective {
                Objective::Gdop95 => gdop.min(GDOP_CAP),
                Objective::Error95 => sigma.min(ERROR_CAP_M),
            };
            worst = worst.max(v);
        }
        worst
    }

    /// The objective with `chosen` added.
    pub fn score(&self, chosen: &[usize]) -> Score {
        use rayon::prelude::*;
        let mut v: Vec<f64> = self
            .considered
            .par_iter()
            .map(|&c| self.cell_value(c, chosen))
            .collect();
        score_of(&mut v)
    }
}

/// The 95th percentile (nearest rank) and mean of `values` (sorted in place).
pub fn score_of(values: &mut [f64]) -> Score {
    if values.is_empty() {
        return Score {
            p95: f64::NAN,
            mean: f64::NAN,
        };
    }
    values.sort_by(f64::total_cmp);
    Score {
        p95: percentile(values, 95.0),
        mean: values.iter().sum::<f64>() / values.len() as f64,
    }
}

/// The `p`-th percentile of sorted `values` by nearest rank: the smallest value with at
/// least `p` % of the values at or below it.
pub fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((p / 100.0) * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

/// One step of the search.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Step {
    /// `"greedy"` or `"swap"`.
    pub phase: &'static str,
    /// The chosen candidates (indices) after the step.
    pub chosen: Vec<usize>,
    pub score: Score,
}

/// The search's result.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Placement {
    pub greedy: Vec<usize>,
    pub greedy_score: Score,
    pub chosen: Vec<usize>,
    pub score: Score,
    pub steps: Vec<Step>,
    pub evaluations: usize,
}

/// Greedy then best-improvement swaps (module documentation) over `n` candidates,
/// choosing `k`, minimising `f`. `on_step` sees every step as it is taken.
pub fn optimise(
    n: usize,
    k: usize,
    f: &dyn Fn(&[usize]) -> Score,
    on_step: &mut dyn FnMut(&Step),
) -> Placement {
    let mut evaluations = 0;
    let mut eval = |s: &[usize]| {
        evaluations += 1;
        f(s)
    };
    let mut steps = Vec::new();
    let mut chosen: Vec<usize> = Vec::with_capacity(k);
    let mut score = eval(&chosen);
    for _ in 0..k.min(n) {
        let mut best: Option<(usize, Score)> = None;
        let mut trial = chosen.clone();
        trial.push(0);
        for c in (0..n).filter(|c| !chosen.contains(c)) {
            *trial.last_mut().unwrap_or(&mut 0) = c;
            let s = eval(&trial);
            if best
                .as_ref()
                .is_none_or(|(_, b)| s.cmp(b) == Ordering::Less)
            {
                best = Some((c, s));
            }
        }
        let Some((c, s)) = best else { break };
        chosen.push(c);
        score = s;
        let step = Step {
            phase: "greedy",
            chosen: chosen.clone(),
            score,
        };
        on_step(&step);
        steps.push(step);
    }
    let greedy = chosen.clone();
    let greedy_score = score;
    // Best-improvement swaps; the bound only guards against a cycle, which strict
    // improvement already rules out.
    for _ in 0..10_000 {
        let mut best: Option<(usize, usize, Score)> = None;
        let mut trial = chosen.clone();
        for pos in 0..chosen.len() {
            for c in (0..n).filter(|c| !chosen.contains(c)) {
                trial.copy_from_slice(&chosen);
                trial[pos] = c;
                let s = eval(&trial);
                let incumbent = best.as_ref().map_or(score, |b| b.2);
                if s.better_than(&incumbent) {
                    best = Some((pos, c, s));
                }
            }
        }
        let Some((pos, c, s)) = best else { break };
        chosen[pos] = c;
        score = s;
        let step = Step {
            phase: "swap",
            chosen: chosen.clone(),
            score,
        };
        on_step(&step);
        steps.push(step);
    }
    Placement {
        greedy,
        greedy_score,
        chosen,
        score,
        steps,
        evaluations,
    }
}

/// Scores of `trials` random K-subsets of `n` candidates drawn from `seed`.
pub fn random_baseline(
    n: usize,
    k: usize,
    trials: usize,
    seed: u64,
    f: &dyn Fn(&[usize]) -> Score,
) -> Vec<Score> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..trials)
        .map(|_| {
            let s = rand::seq::index::sample(&mut rng, n, k.min(n)).into_vec();
            f(&s)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::grid::Region;

    fn region() -> Region {
        Region {
            west_m: 0.0,
            south_m: 0.0,
            east_m: 100.0,
            north_m: 100.0,
        }
    }

    /// A set function where greedy is provably myopic: site 0 alone is best (1.0 against
    /// 2.0), but every pair with it (0.9) is worse than the pair {1, 2} (0.5).
    fn myopic(s: &[usize]) -> Score {
        let mut v = s.to_vec();
        v.sort_unstable();
        let p95 = match v[..] {
            [] => 3.0,
            [0] => 1.0,
            [_] => 2.0,
            [1, 2] => 0.5,
            [0, _] => 0.9,
            _ => 1.5,
        };
        Score { p95, mean: p95 }
    }

    #[test]
    fn local_search_repairs_a_myopic_greedy_choice() {
        let mut seen = Vec::new();
        let p = optimise(4, 2, &myopic, &mut |s| seen.push(s.score.p95));
        assert_eq!(p.greedy.len(), 2);
        assert!(p.greedy.contains(&0));
        assert_eq!(p.greedy_score.p95, 0.9);
        let mut c = p.chosen.clone();
        c.sort_unstable();
        assert_eq!(c, vec![1, 2]);
        assert_eq!(p.score.p95, 0.5);
        // Every step is reported, and the objective never rises.
        assert_eq!(seen.len(), p.steps.len());
        assert!(seen.windows(2).all(|w| w[1] <= w[0]));
    }

    #[test]
    fn percentile_is_nearest_rank() {
        let v: Vec<f64> = (1..=20).map(f64::from).collect();
        assert_eq!(percentile(&v, 95.0), 19.0);
        assert_eq!(percentile(&v, 50.0), 10.0);
        assert_eq!(percentile(&v, 100.0), 20.0);
        assert_eq!(percentile(&[7.0], 95.0), 7.0);
    }

    #[test]
    fn candidates_parse_and_errors_name_the_line() {
        let ok = "id,east_m,north_m,height_m,kind\n# a comment\nA,10,20,30\nB, 50, 50, 40, tcofdm, 0.5, 2100\n";
        let c = parse_candidates_text(ok, "c.csv", &region()).unwrap();
        assert_eq!(c.len(), 2);
        assert_eq!((c[0].kind.as_str(), c[0].line), ("dtmb", 3));
        assert_eq!((c[1].erp_kw, c[1].freq_mhz), (0.5, 2100.0));
        for (text, needle) in [
            (
                "A,10,20,30\nA,30,30,30\n",
                "c.csv:2: duplicate candidate id \"A\" (first on line 1)",
            ),
            (
                "A,500,20,30\n",
                "c.csv:1: candidate A at (500, 20) m is outside the region",
            ),
            ("A,NaN,20,30\n", "c.csv:1: east_m: expected a finite number"),
            ("A,1,2\n", "c.csv:1: expected id,east_m"),
            ("A,1,2,3,fm\n", "c.csv:1: kind: expected dtmb or tcofdm"),
            ("# nothing\n", "c.csv: no candidate sites"),
        ] {
            let e = parse_candidates_text(text, "c.csv", &region()).unwrap_err();
            assert!(e.contains(needle), "{e}");
        }
    }

    #[test]
    fn random_baseline_is_seeded() {
        let a = random_baseline(6, 2, 5, 7, &myopic);
        let b = random_baseline(6, 2, 5, 7, &myopic);
        assert_eq!(a, b);
        assert_eq!(a.len(), 5);
    }
}
