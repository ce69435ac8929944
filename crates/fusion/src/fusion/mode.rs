//! Integration-mode selection: seed 000's fuzzy inference system and seed 003's seamless
//! scheme by satellite count.
//!
//! # Seed 000's fuzzy inference system (Cong et al., Sensors 2018, §3.2)
//!
//! Inputs: x₁ = GDOP of GPS (fuzzy sets S, L), x₂ = GDOP of GPS + DTMB (S, M, L) and
//! x₃ = the number of FM reference points inside the constraint circle (S, L). Output: the
//! integration mode A = GPS only, B = GPS + DTMB, C = GPS + DTMB + FM. A Mamdani system:
//!
//! ```text
//! fuzzify:   μ_X(x) with triangular membership functions
//! rule i:    w_i = min(μ_{X1^a}(x₁), μ_{X2^b}(x₂), μ_{X3^c}(x₃))   (absent inputs: 1)
//! implicate: μ_i(y) = min(w_i, μ_{Y^d}(y))
//! aggregate: μ(y) = max_i μ_i(y)
//! defuzzify: y* = ∫ y μ(y) dy / ∫ μ(y) dy                          (centroid)
//! ```
//!
//! and the mode is the output set whose peak is nearest y*. The paper's rule table is
//! damaged in the text; its narrative gives the default rule base: x₁ S → A;
//! x₁ L ∧ x₂ S → B; x₁ L ∧ x₂ M ∧ x₃ S → B; x₁ L ∧ x₂ M ∧ x₃ L → C; x₁ L ∧ x₂ L → C. The
//! paper's membership functions are drawn in its Fig. 4 without numbers; the defaults
//! here are assumptions (written next to each), and every set and rule can be replaced
//! in the world file.
//!
//! # Seed 003's seamless scheme (Table 1)
//!
//! More than 4 GPS satellites → GPS + BDS; 1 to 4 → GPS + BDS + DTMB; none → DTMB only.

use serde::Deserialize;

/// A triangular membership function `[a, b, c]`: 0 at a and c, 1 at b, linear between.
/// `a == b` makes a left shoulder (μ = 1 for every x ≤ b) and `b == c` a right shoulder
/// (μ = 1 for every x ≥ b), so the outer sets of an input cover its whole range.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(from = "[f64; 3]", into = "[f64; 3]")]
pub struct Triangle {
    pub a: f64,
    pub b: f64,
    pub c: f64,
}

impl From<[f64; 3]> for Triangle {
    fn from(v: [f64; 3]) -> Self {
        Self {
            a: v[0],
            b: v[1],
            c: v[2],
        }
    }
}

impl From<Triangle> for [f64; 3] {
    fn from(t: Triangle) -> Self {
        [t.a, t.b, t.c]
    }
}

impl Triangle {
    /// The membership of `x`.
    pub fn mu(&self, x: f64) -> f64 {
        if x.is_nan() {
            return 0.0;
        }
        if x <= self.b {
            if self.a == self.b {
                1.0
            } else if x <= self.a {
                0.0
            } else {
                (x - self.a) / (self.b - self.a)
            }
        } else if self.b == self.c {
            1.0
        } else if x >= self.c {
            0.0
        } else {
            (self.c - x) / (self.c - self.b)
        }
    }

    fn valid(&self) -> bool {
        self.a.is_finite()
            && self.b.is_finite()
            && self.c.is_finite()
            && self.a <= self.b
            && self.b <= self.c
            && self.a < self.c
    }
}

/// An integration mode of seed 000.
#[derive(
    Clone,
    Copy,
    Debug,
    Deserialize,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    serde::Serialize,
    schemars::JsonSchema,
)]
pub enum Mode {
    /// GPS only.
    A,
    /// GPS + DTMB.
    B,
    /// GPS + DTMB + FM.
    C,
}

impl Mode {
    /// The mode's index on the output axis (A = 0, B = 1, C = 2).
    pub fn index(self) -> usize {
        match self {
            Mode::A => 0,
            Mode::B => 1,
            Mode::C => 2,
        }
    }
}

/// A linguistic value of an input.
#[derive(
    Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Level {
    Small,
    Medium,
    Large,
}

/// The antecedent of a rule: a level per input; an absent input does not constrain.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct Antecedent {
    #[serde(default)]
    pub gdop_gps: Option<Level>,
    #[serde(default)]
    pub gdop_gps_dtmb: Option<Level>,
    #[serde(default)]
    pub rp_count: Option<Level>,
}

/// One rule: `if` the antecedent `then` the mode.
#[derive(
    Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct Rule {
    #[serde(rename = "if")]
    pub when: Antecedent,
    pub then: Mode,
}

/// The fuzzy system's configuration (`[estimator.fuzzy]` in a world file).
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct FuzzyConfig {
    /// GDOP of GPS: small (assumed left shoulder to 8) and large (rising from 3 to 8).
    pub gdop_gps_small: Triangle,
    pub gdop_gps_large: Triangle,
    /// GDOP of GPS + DTMB: small (to 4), medium (2–5–8), large (from 5, full at 10).
    pub gdop_gps_dtmb_small: Triangle,
    pub gdop_gps_dtmb_medium: Triangle,
    pub gdop_gps_dtmb_large: Triangle,
    /// Reference points in the circle: small (to 10), large (from 3, full at 15).
    pub rp_count_small: Triangle,
    pub rp_count_large: Triangle,
    /// Output sets on the mode axis (A at 0, B at 1, C at 2).
    pub output: [Triangle; 3],
    /// The rule base; default: the paper's narrative.
    pub rules: Vec<Rule>,
    /// Samples of the output axis for the centroid; default 601.
    pub resolution: usize,
}

impl Default for FuzzyConfig {
    fn default() -> Self {
        use Level::{Large, Medium, Small};
        let rule = |g: Option<Level>, gd: Option<Level>, rp: Option<Level>, then| Rule {
            when: Antecedent {
                gdop_gps: g,
                gdop_gps_dtmb: gd,
                rp_count: rp,
            },
            then,
        };
        Self {
            gdop_gps_small: [0.0, 0.0, 8.0].into(),
            gdop_gps_large: [3.0, 8.0, 8.0].into(),
            gdop_gps_dtmb_small: [0.0, 0.0, 4.0].into(),
            gdop_gps_dtmb_medium: [2.0, 5.0, 8.0].into(),
            gdop_gps_dtmb_large: [5.0, 10.0, 10.0].into(),
            rp_count_small: [0.0, 0.0, 10.0].into(),
            rp_count_large: [3.0, 15.0, 15.0].into(),
            output: [
                [-1.0, 0.0, 1.0].into(),
                [0.0, 1.0, 2.0].into(),
                [1.0, 2.0, 3.0].into(),
            ],
            rules: vec![
                rule(Some(Small), None, None, Mode::A),
                rule(Some(Large), Some(Small), None, Mode::B),
                rule(Some(Large), Some(Medium), Some(Small), Mode::B),
                rule(Some(Large), Some(Medium), Some(Large), Mode::C),
                rule(Some(Large), Some(Large), None, Mode::C),
            ],
            resolution: 601,
        }
    }
}

/// The inputs of one epoch. A GDOP that cannot be computed (too few emitters) is
/// `f64::INFINITY`: as large as it gets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FuzzyInputs {
    pub gdop_gps: f64,
    pub gdop_gps_dtmb: f64,
    pub rp_count: f64,
}

/// The decision of one epoch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FuzzyDecision {
    pub mode: Mode,
    /// The defuzzified output y* (None when no rule fired).
    pub centroid: Option<f64>,
    /// The firing strength of each rule, in rule order (up to the first 16).
    pub strengths: [f64; 16],
}

impl FuzzyConfig {
    /// Checks the sets and the rule base.
    ///
    /// # Errors
    /// `(key, message)` for a set that is not a triangle `a ≤ b ≤ c, a < c`, an empty rule
    /// base, a rule naming a level its input lacks (gdop_gps and rp_count have no medium),
    /// or a resolution outside 11–100 001.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let sets = [
            ("gdop_gps_small", self.gdop_gps_small),
            ("gdop_gps_large", self.gdop_gps_large),
            ("gdop_gps_dtmb_small", self.gdop_gps_dtmb_small),
            ("gdop_gps_dtmb_medium", self.gdop_gps_dtmb_medium),
            ("gdop_gps_dtmb_large", self.gdop_gps_dtmb_large),
            ("rp_count_small", self.rp_count_small),
            ("rp_count_large", self.rp_count_large),
            ("output[0]", self.output[0]),
            ("output[1]", self.output[1]),
            ("output[2]", self.output[2]),
        ];
        for (k, t) in sets {
            if !t.valid() {
                return Err((
                    k.to_string(),
                    format!("expected a triangle [a, b, c] with a ≤ b ≤ c and a < c, got {t:?}"),
                ));
            }
        }
        if self.rules.is_empty() || self.rules.len() > 16 {
            return Err(("rules".into(), "expected 1 to 16 rules".into()));
        }
        for (i, r) in self.rules.iter().enumerate() {
            for (name, l) in [("gdop_gps", r.when.gdop_gps), ("rp_count", r.when.rp_count)] {
                if l == Some(Level::Medium) {
                    return Err((
                        format!("rules[{i}].if.{name}"),
                        format!("{name} has only the levels small and large"),
                    ));
                }
            }
        }
        if !(11..=100_001).contains(&self.resolution) {
            return Err((
                "resolution".into(),
                format!("expected 11 to 100001 samples, got {}", self.resolution),
            ));
        }
        Ok(())
    }

    fn mu(&self, x: &FuzzyInputs, a: &Antecedent) -> f64 {
        let g =
            |l: Option<Level>, v: f64, s: &Triangle, m: Option<&Triangle>, lg: &Triangle| match l {
                None => 1.0,
                Some(Level::Small) => s.mu(v),
                Some(Level::Medium) => m.map_or(0.0, |t| t.mu(v)),
                Some(Level::Large) => lg.mu(v),
            };
        g(
            a.gdop_gps,
            x.gdop_gps,
            &self.gdop_gps_small,
            None,
            &self.gdop_gps_large,
        )
        .min(g(
            a.gdop_gps_dtmb,
            x.gdop_gps_dtmb,
            &self.gdop_gps_dtmb_small,
            Some(&self.gdop_gps_dtmb_medium),
            &self.gdop_gps_dtmb_large,
        ))
        .min(g(
            a.rp_count,
            x.rp_count,
            &self.rp_count_small,
            None,
            &self.rp_count_large,
        ))
    }

    /// Runs the inference for one epoch. When no rule fires (every strength 0) the mode
    /// is A, the paper's default with GPS alone.
    pub fn decide(&self, x: &FuzzyInputs) -> FuzzyDecision {
        let (strengths, clip) = self.fire(x);
        let (lo, hi, n) = self.axis();
        let (mut num, mut den) = (0.0, 0.0);
        for k in 0..n {
            let y = lo + (hi - lo) * k as f64 / (n - 1) as f64;
            let mut mu: f64 = 0.0;
            for (j, c) in clip.iter().enumerate() {
                if *c > 0.0 {
                    mu = mu.max(c.min(self.output[j].mu(y)));
                }
            }
            // Trapezoidal weights: the end samples count half.
            let wt = if k == 0 || k == n - 1 { 0.5 } else { 1.0 };
            num += wt * y * mu;
            den += wt * mu;
        }
        self.conclude(num, den, strengths)
    }

    /// The firing strength of each rule and, per output set, the largest strength of the
    /// rules that conclude it. Mamdani max–min aggregation folds per output set: since min
    /// is monotone, max over the rules r → j of min(w_r, μ_j(y)) = min(max_r w_r, μ_j(y)),
    /// so each sample of the output axis needs one term per output set, not one per rule.
    fn fire(&self, x: &FuzzyInputs) -> ([f64; 16], [f64; 3]) {
        let mut strengths = [0.0; 16];
        for (w, r) in strengths.iter_mut().zip(&self.rules) {
            *w = self.mu(x, &r.when);
        }
        let mut clip = [0.0f64; 3];
        for (w, r) in strengths.iter().zip(&self.rules) {
            let j = r.then.index();
            clip[j] = clip[j].max(*w);
        }
        (strengths, clip)
    }

    /// The output axis `[lo, hi]`, spanning every output set's support, and its number of
    /// samples.
    fn axis(&self) -> (f64, f64, usize) {
        let lo = self
            .output
            .iter()
            .map(|t| t.a)
            .fold(f64::INFINITY, f64::min);
        let hi = self
            .output
            .iter()
            .map(|t| t.c)
            .fold(f64::NEG_INFINITY, f64::max);
        (lo, hi, self.resolution.max(11))
    }

    /// The decision from the centroid's sums ∫yμ and ∫μ: the output set whose peak is
    /// nearest y*, or A when no rule fired.
    fn conclude(&self, num: f64, den: f64, strengths: [f64; 16]) -> FuzzyDecision {
        let centroid = (den > 0.0).then(|| num / den);
        let mode = centroid.map_or(Mode::A, |c| {
            [Mode::A, Mode::B, Mode::C]
                .into_iter()
                .min_by(|p, q| {
                    (self.output[p.index()].b - c)
                        .abs()
                        .total_cmp(&(self.output[q.index()].b - c).abs())
                })
                .unwrap_or(Mode::A)
        });
        FuzzyDecision {
            mode,
            centroid,
            strengths,
        }
    }
}

/// One sample y_k of the output axis: its trapezoidal weight w_k, w_k·y_k, and each output
/// set's membership μ_j(y_k).
#[derive(Clone, Copy, Debug)]
struct AxisSample {
    wy: f64,
    wt: f64,
    mu: [f64; 3],
}

/// A [`FuzzyConfig`] prepared for inference at every epoch: the output axis's samples, their
/// weights and the output sets' memberships at them are tabulated once, and each decision
/// visits only the samples where an output set that fired is positive. Elsewhere the
/// aggregated μ is 0 and a sample adds exactly ±0 to both centroid sums, so
/// [`FuzzySystem::decide`] returns [`FuzzyConfig::decide`]'s decision bit for bit (tested)
/// at a tenth of the cost.
#[derive(Clone, Debug)]
pub struct FuzzySystem {
    cfg: FuzzyConfig,
    samples: Vec<AxisSample>,
    /// Per output set, the samples `[first, end)` outside which its membership is 0.
    support: [(usize, usize); 3],
}

impl FuzzySystem {
    /// Tabulates `cfg` (which should be valid: [`FuzzyConfig::validate`]).
    pub fn new(cfg: &FuzzyConfig) -> Self {
        let (lo, hi, n) = cfg.axis();
        let samples: Vec<AxisSample> = (0..n)
            .map(|k| {
                // The same sample points and weights as FuzzyConfig::decide, computed the
                // same way.
                let y = lo + (hi - lo) * k as f64 / (n - 1) as f64;
                let wt = if k == 0 || k == n - 1 { 0.5 } else { 1.0 };
                AxisSample {
                    wy: wt * y,
                    wt,
                    mu: [0, 1, 2].map(|j| cfg.output[j].mu(y)),
                }
            })
            .collect();
        let support = [0, 1, 2].map(|j| {
            let first = samples.iter().position(|s| s.mu[j] > 0.0);
            let last = samples.iter().rposition(|s| s.mu[j] > 0.0);
            match (first, last) {
                (Some(a), Some(b)) => (a, b + 1),
                _ => (0, 0),
            }
        });
        Self {
            cfg: cfg.clone(),
            samples,
            support,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &FuzzyConfig {
        &self.cfg
    }

    /// The inference of [`FuzzyConfig::decide`], from the tables.
    pub fn decide(&self, x: &FuzzyInputs) -> FuzzyDecision {
        let (strengths, clip) = self.cfg.fire(x);
        let (mut from, mut to) = (usize::MAX, 0);
        for (c, (a, b)) in clip.iter().zip(self.support) {
            if *c > 0.0 && a < b {
                from = from.min(a);
                to = to.max(b);
            }
        }
        let (mut num, mut den) = (0.0, 0.0);
        if from < to {
            let samples = &self.samples[from..to];
            // The sets that fired, with their clip levels; the loop is written out for one,
            // two and three of them so that each sample costs a few instructions.
            let mut fired = [(0usize, 0.0f64); 3];
            let mut n = 0;
            for (j, c) in clip.iter().enumerate() {
                if *c > 0.0 {
                    fired[n] = (j, *c);
                    n += 1;
                }
            }
            match fired[..n] {
                [(a, ca)] => {
                    for s in samples {
                        let mu = min(ca, s.mu[a]);
                        num += s.wy * mu;
                        den += s.wt * mu;
                    }
                }
                [(a, ca), (b, cb)] => {
                    for s in samples {
                        let mu = max(min(ca, s.mu[a]), min(cb, s.mu[b]));
                        num += s.wy * mu;
                        den += s.wt * mu;
                    }
                }
                _ => {
                    for s in samples {
                        let mu = max(
                            max(min(clip[0], s.mu[0]), min(clip[1], s.mu[1])),
                            min(clip[2], s.mu[2]),
                        );
                        num += s.wy * mu;
                        den += s.wt * mu;
                    }
                }
            }
        }
        self.cfg.conclude(num, den, strengths)
    }
}

/// `f64::min` for the operands of the inference, which are never NaN and never −0 (clip
/// levels are positive, memberships are +0 or positive), so a plain comparison gives the
/// same value with one instruction.
#[inline(always)]
fn min(a: f64, b: f64) -> f64 {
    if a < b {
        a
    } else {
        b
    }
}

/// `f64::max` likewise.
#[inline(always)]
fn max(a: f64, b: f64) -> f64 {
    if a > b {
        a
    } else {
        b
    }
}

/// Seed 003's systems to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeamlessMode {
    GpsBds,
    GpsBdsDtmb,
    DtmbOnly,
}

/// Seed 003 Table 1: the combination by the number of GPS satellites tracked.
pub fn seamless_mode(gps_satellites: usize) -> SeamlessMode {
    match gps_satellites {
        0 => SeamlessMode::DtmbOnly,
        1..=4 => SeamlessMode::GpsBdsDtmb,
        _ => SeamlessMode::GpsBds,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangles_and_shoulders() {
        let t = Triangle::from([2.0, 5.0, 8.0]);
        assert_eq!(t.mu(2.0), 0.0);
        assert!((t.mu(3.5) - 0.5).abs() < 1e-12);
        assert_eq!(t.mu(5.0), 1.0);
        assert!((t.mu(7.0) - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(t.mu(9.0), 0.0);
        let left = Triangle::from([0.0, 0.0, 8.0]);
        assert_eq!(left.mu(-3.0), 1.0);
        assert!((left.mu(2.0) - 0.75).abs() < 1e-12);
        let right = Triangle::from([3.0, 8.0, 8.0]);
        assert_eq!(right.mu(f64::INFINITY), 1.0);
        assert_eq!(right.mu(f64::NAN), 0.0);
    }

    /// Inputs where one rule fires alone: its output set, clipped, is symmetric about its
    /// peak, so the centroid is the peak exactly (to the sampling) and the mode is the rule's.
    #[test]
    fn single_rule_cases_give_the_rule_mode() {
        let f = FuzzyConfig::default();
        f.validate().unwrap();
        // GDOP_GPS = 2: small 0.75, large 0 → only rule 1 (A) fires, at 0.75.
        let d = f.decide(&FuzzyInputs {
            gdop_gps: 2.0,
            gdop_gps_dtmb: 1.5,
            rp_count: 20.0,
        });
        assert_eq!(d.mode, Mode::A);
        assert!((d.strengths[0] - 0.75).abs() < 1e-12);
        assert!(d.strengths[1..5].iter().all(|w| *w == 0.0));
        assert!(d.centroid.unwrap().abs() < 1e-9);
        // GDOP_GPS = ∞ (too few satellites), GDOP_GPS+DTMB = 1.5: rule 2 (B) at
        // μ_S(1.5) = 1 − 1.5/4 = 0.625.
        let d = f.decide(&FuzzyInputs {
            gdop_gps: f64::INFINITY,
            gdop_gps_dtmb: 1.5,
            rp_count: 20.0,
        });
        assert_eq!(d.mode, Mode::B);
        assert!((d.strengths[1] - 0.625).abs() < 1e-12);
        assert!((d.centroid.unwrap() - 1.0).abs() < 1e-9);
        // GDOP_GPS+DTMB = 12: only rule 5 (C) fires, fully.
        let d = f.decide(&FuzzyInputs {
            gdop_gps: 20.0,
            gdop_gps_dtmb: 12.0,
            rp_count: 0.0,
        });
        assert_eq!(d.mode, Mode::C);
        assert!((d.centroid.unwrap() - 2.0).abs() < 1e-9);
    }

    /// Two rules at once: GDOP_GPS large (1), GDOP_GPS+DTMB = 3 (small 0.25, medium 1/3),
    /// 20 reference points (large 1). Rule 2 fires B at 0.25 and rule 4 fires C at 1/3.
    /// The aggregated output is max(min(0.25, B), min(1/3, C)); its centroid, integrated
    /// here in closed form piece by piece, is 1.5733, nearer C's peak (2) than B's (1), so
    /// the mode is C.
    #[test]
    fn two_rule_case_matches_the_closed_form_centroid() {
        let f = FuzzyConfig::default();
        let d = f.decide(&FuzzyInputs {
            gdop_gps: 10.0,
            gdop_gps_dtmb: 3.0,
            rp_count: 20.0,
        });
        assert!((d.strengths[1] - 0.25).abs() < 1e-12);
        assert!((d.strengths[3] - 1.0 / 3.0).abs() < 1e-12);
        // μ(y): B part on [0, 2]: min(0.25, 1 − |y − 1|); C part on [1, 3]: min(1/3, 1 − |y − 2|).
        // Pieces (y, μ linear between breakpoints):
        // [0, 0.25] rising y; [0.25, 1.25] 0.25 (B plateau; C is below 0.25 until y = 1.25);
        // [1.25, 1.3333] rising y − 1; [1.3333, 2.6667] 1/3; [2.6667, 3] falling 3 − y.
        let pieces: [(f64, f64, f64, f64); 5] = [
            (0.0, 0.25, 0.0, 0.25),
            (0.25, 1.25, 0.25, 0.25),
            (1.25, 4.0 / 3.0, 0.25, 1.0 / 3.0),
            (4.0 / 3.0, 8.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0),
            (8.0 / 3.0, 3.0, 1.0 / 3.0, 0.0),
        ];
        // For a linear μ from (y0, m0) to (y1, m1): ∫μ = (m0 + m1)/2 Δ and
        // ∫yμ = Δ (y0 (2 m0 + m1) + y1 (m0 + 2 m1)) / 6.
        let (mut area, mut moment) = (0.0, 0.0);
        for (y0, y1, m0, m1) in pieces {
            let dy = y1 - y0;
            area += 0.5 * (m0 + m1) * dy;
            moment += dy * (y0 * (2.0 * m0 + m1) + y1 * (m0 + 2.0 * m1)) / 6.0;
        }
        let expected = moment / area;
        let got = d.centroid.unwrap();
        assert!((got - expected).abs() < 1e-4, "{got} vs {expected}");
        assert!((expected - 1.5733).abs() < 1e-4);
        assert_eq!(d.mode, Mode::C);
    }

    /// The tabulated system decides exactly as the configuration's own inference (mode,
    /// centroid and strengths bit for bit) over a grid of inputs that fires every rule
    /// alone and in combination, with infinite and NaN inputs, for the default sets and
    /// for sets of another shape (narrow, overlapping, an axis of 11 samples).
    #[test]
    fn the_tabulated_system_decides_bit_for_bit_as_the_configuration() {
        let mut custom = FuzzyConfig {
            output: [
                [-0.3, 0.0, 0.2].into(),
                [0.4, 1.0, 1.1].into(),
                [0.5, 2.0, 2.0].into(),
            ],
            gdop_gps_small: [0.0, 0.0, 3.0].into(),
            ..FuzzyConfig::default()
        };
        custom.rules.push(Rule {
            when: Antecedent {
                gdop_gps: None,
                gdop_gps_dtmb: Some(Level::Medium),
                rp_count: None,
            },
            then: Mode::A,
        });
        let coarse = FuzzyConfig {
            resolution: 11,
            ..custom.clone()
        };
        let values = [
            0.0,
            0.5,
            1.5,
            2.0,
            2.999,
            3.0,
            4.5,
            5.0,
            7.9,
            8.0,
            9.5,
            12.0,
            20.0,
            f64::INFINITY,
            f64::NAN,
        ];
        let mut decided = [0usize; 3];
        for cfg in [FuzzyConfig::default(), custom, coarse] {
            cfg.validate().unwrap();
            let sys = FuzzySystem::new(&cfg);
            for &g in &values {
                for &gd in &values {
                    for rp in [0.0, 3.0, 6.5, 10.0, 15.0, f64::NAN] {
                        let x = FuzzyInputs {
                            gdop_gps: g,
                            gdop_gps_dtmb: gd,
                            rp_count: rp,
                        };
                        let (a, b) = (cfg.decide(&x), sys.decide(&x));
                        assert_eq!(a.mode, b.mode, "{x:?}");
                        assert_eq!(
                            a.centroid.map(f64::to_bits),
                            b.centroid.map(f64::to_bits),
                            "{x:?}"
                        );
                        assert_eq!(a.strengths.map(f64::to_bits), b.strengths.map(f64::to_bits));
                        decided[a.mode.index()] += 1;
                    }
                }
            }
        }
        // Every mode is reached, so every output set's table was exercised.
        assert!(decided.iter().all(|&n| n > 50), "{decided:?}");
    }

    #[test]
    fn seamless_scheme_follows_table_1() {
        assert_eq!(seamless_mode(0), SeamlessMode::DtmbOnly);
        assert_eq!(seamless_mode(1), SeamlessMode::GpsBdsDtmb);
        assert_eq!(seamless_mode(4), SeamlessMode::GpsBdsDtmb);
        assert_eq!(seamless_mode(5), SeamlessMode::GpsBds);
    }

    #[test]
    fn bad_configurations_are_named() {
        let mut f = FuzzyConfig {
            gdop_gps_small: [5.0, 2.0, 8.0].into(),
            ..FuzzyConfig::default()
        };
        assert_eq!(f.validate().unwrap_err().0, "gdop_gps_small");
        f = FuzzyConfig::default();
        f.rules[0].when.gdop_gps = Some(Level::Medium);
        assert_eq!(f.validate().unwrap_err().0, "rules[0].if.gdop_gps");
        f = FuzzyConfig {
            rules: vec![],
            ..FuzzyConfig::default()
        };
        assert_eq!(f.validate().unwrap_err().0, "rules");
    }
}
