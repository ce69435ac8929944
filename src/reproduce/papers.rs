//! The five papers' published tables, as data: each figure with the world-file estimator
//! that reproduces it, and each ordering the paper claims.
//!
//! The values are the papers' own (`../shared/seeds/`, summarised in
//! `../shared/reference/seeds.md`); nothing here is a simulated number.

/// A statistic of one estimator's `summary.json` line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Metric {
    /// 68.27 / 95.45 / 99.73 % percentiles of the 3-D error (seed 000's σ-levels).
    Sigma1,
    Sigma2,
    Sigma3,
    /// Mean and RMSE of the absolute trajectory error (TUM, ECEF, no alignment).
    AteMean,
    AteRmse,
    /// Mean and RMSE of the relative pose error over Δ = 1 s.
    RpeMean,
    RpeRmse,
    /// Mean and standard deviation of the error over every epoch of every trial
    /// (seeds 001 and 003 report these).
    Mean,
    Std,
    /// RMSE of the 3-D error.
    Rmse,
    /// The 68.27 / 95.45 % percentiles of the horizontal error (seed 002 reports 68 % and
    /// 95 % of the horizontal error).
    Horizontal1,
    Horizontal2,
}

impl Metric {
    /// The column label.
    pub fn label(self) -> &'static str {
        match self {
            Metric::Sigma1 => "1σ",
            Metric::Sigma2 => "2σ",
            Metric::Sigma3 => "3σ",
            Metric::AteMean => "mean ATE",
            Metric::AteRmse => "RMSE ATE",
            Metric::RpeMean => "mean RPE",
            Metric::RpeRmse => "RMSE RPE",
            Metric::Mean => "mean",
            Metric::Std => "std",
            Metric::Rmse => "RMSE",
            Metric::Horizontal1 => "68 % horiz.",
            Metric::Horizontal2 => "95 % horiz.",
        }
    }
}

/// One published figure.
#[derive(Clone, Copy, Debug)]
pub struct Figure {
    /// The paper's row name.
    pub row: &'static str,
    /// The estimator of the world file that runs the paper's system of that row.
    pub estimator: &'static str,
    pub metric: Metric,
    /// The paper's value (m).
    pub paper_m: f64,
}

/// An ordering a paper claims: `ascending[0] < ascending[1] < …` in `metric`.
#[derive(Clone, Copy, Debug)]
pub struct Ordering {
    pub metric: Metric,
    pub ascending: &'static [&'static str],
}

/// One paper table and the world that reproduces it.
#[derive(Clone, Copy, Debug)]
pub struct Paper {
    /// The name `hybridnav reproduce` takes (the world file's stem).
    pub id: &'static str,
    pub title: &'static str,
    /// The world file, relative to the repository.
    pub world: &'static str,
    pub figures: &'static [Figure],
    pub orderings: &'static [Ordering],
}

const fn fig(row: &'static str, estimator: &'static str, metric: Metric, paper_m: f64) -> Figure {
    Figure {
        row,
        estimator,
        metric,
        paper_m,
    }
}

use Metric::*;

/// Seed 000's published rows (Tables 5 and 6): 1σ, 2σ, 3σ, ATE mean and RMSE, RPE mean
/// and RMSE (m), each written once for the paper's rows and their eq.-17 variants.
const BEIHANG_GPS: [f64; 7] = [29.49, 74.51, 87.46, 24.52, 32.45, 16.61, 21.72];
const BEIHANG_GPS_DTMB: [f64; 7] = [14.46, 28.50, 35.31, 13.53, 15.57, 13.38, 15.80];
const BEIHANG_PROPOSED: [f64; 7] = [10.56, 22.57, 27.80, 9.90, 11.23, 10.92, 12.29];
const KEHUI_GPS: [f64; 7] = [6.47, 96.89, 416.60, 21.60, 53.42, 5.57, 25.93];
const KEHUI_GPS_DTMB: [f64; 7] = [6.45, 71.31, 262.80, 11.78, 27.32, 5.68, 25.76];
const KEHUI_PROPOSED: [f64; 7] = [6.42, 28.23, 60.23, 7.88, 11.87, 2.79, 4.84];

/// Seed 000's table for one site: three rows × (1σ, 2σ, 3σ, mean ATE, RMSE ATE, mean RPE,
/// RMSE RPE).
macro_rules! seed000_rows {
    ($( $row:literal => $est:literal : $v:expr ),* $(,)?) => {
        &[ $(
            fig($row, $est, Sigma1, $v[0]),
            fig($row, $est, Sigma2, $v[1]),
            fig($row, $est, Sigma3, $v[2]),
            fig($row, $est, AteMean, $v[3]),
            fig($row, $est, AteRmse, $v[4]),
            fig($row, $est, RpeMean, $v[5]),
            fig($row, $est, RpeRmse, $v[6]),
        )* ]
    };
}

/// Extra rows a paper world runs beside the paper's own: another form of a paper's system
/// (e.g. seed 000's filter with the range-rate Jacobian exactly as eq. 17 prints it),
/// scored against the same published figures and printed by `hybridnav reproduce`, but
/// not counted among the papers' figures or claimed orderings.
#[derive(Clone, Copy, Debug)]
pub struct Variant {
    /// The [`Paper::id`] whose table the rows extend.
    pub paper: &'static str,
    /// What the variant is, in one line.
    pub about: &'static str,
    pub figures: &'static [Figure],
    pub orderings: &'static [Ordering],
}

/// Seed 000's rows with eq. 17's Jacobian (presets `seed000-*-eq17`): the paper's table
/// rows map to the default presets, whose range-rate Jacobian is exact.
const SEED000_EQ17: &str =
    "the paper's filter with the range-rate Jacobian as eq. 17 prints it (presets seed000-*-eq17)";

/// Every variant, by paper.
pub const VARIANTS: &[Variant] = &[
    Variant {
        paper: "seed000-beihang",
        about: SEED000_EQ17,
        figures: seed000_rows![
            "GPS (eq. 17)" => "GPS (eq. 17)": BEIHANG_GPS,
            "GPS + DTMB (eq. 17)" => "GPS+DTMB (eq. 17)": BEIHANG_GPS_DTMB,
            "Proposed (eq. 17)" => "Proposed (eq. 17)": BEIHANG_PROPOSED,
        ],
        orderings: &[
            Ordering {
                metric: Sigma3,
                ascending: &["Proposed (eq. 17)", "GPS+DTMB (eq. 17)", "GPS (eq. 17)"],
            },
            Ordering {
                metric: AteMean,
                ascending: &["Proposed (eq. 17)", "GPS+DTMB (eq. 17)", "GPS (eq. 17)"],
            },
        ],
    },
    Variant {
        paper: "seed000-kehui",
        about: SEED000_EQ17,
        figures: seed000_rows![
            "GPS (eq. 17)" => "GPS (eq. 17)": KEHUI_GPS,
            "GPS + DTMB (eq. 17)" => "GPS+DTMB (eq. 17)": KEHUI_GPS_DTMB,
            "Proposed (eq. 17)" => "Proposed (eq. 17)": KEHUI_PROPOSED,
        ],
        orderings: &[
            Ordering {
                metric: Sigma2,
                ascending: &["Proposed (eq. 17)", "GPS+DTMB (eq. 17)", "GPS (eq. 17)"],
            },
            Ordering {
                metric: Sigma3,
                ascending: &["Proposed (eq. 17)", "GPS+DTMB (eq. 17)", "GPS (eq. 17)"],
            },
            Ordering {
                metric: AteMean,
                ascending: &["Proposed (eq. 17)", "GPS+DTMB (eq. 17)", "GPS (eq. 17)"],
            },
        ],
    },
];

/// Every paper table hybridnav reproduces, in the papers' order.
pub const PAPERS: &[Paper] = &[
    Paper {
        id: "seed000-beihang",
        title: "Seed 000 site 1 — Beihang campus (Cong et al., Sensors 2018, Table 5)",
        world: "worlds/seed000-beihang.toml",
        figures: seed000_rows![
            "GPS" => "GPS": BEIHANG_GPS,
            "GPS + DTMB" => "GPS+DTMB": BEIHANG_GPS_DTMB,
            "Proposed" => "Proposed": BEIHANG_PROPOSED,
        ],
        orderings: &[
            Ordering {
                metric: Sigma3,
                ascending: &["Proposed", "GPS+DTMB", "GPS"],
            },
            Ordering {
                metric: AteMean,
                ascending: &["Proposed", "GPS+DTMB", "GPS"],
            },
        ],
    },
    Paper {
        id: "seed000-kehui",
        title: "Seed 000 site 2 — Kehui Road (Cong et al., Sensors 2018, Table 6)",
        world: "worlds/seed000-kehui.toml",
        figures: seed000_rows![
            "GPS" => "GPS": KEHUI_GPS,
            "GPS + DTMB" => "GPS+DTMB": KEHUI_GPS_DTMB,
            "Proposed" => "Proposed": KEHUI_PROPOSED,
        ],
        orderings: &[
            Ordering {
                metric: Sigma2,
                ascending: &["Proposed", "GPS+DTMB", "GPS"],
            },
            Ordering {
                metric: Sigma3,
                ascending: &["Proposed", "GPS+DTMB", "GPS"],
            },
            Ordering {
                metric: AteMean,
                ascending: &["Proposed", "GPS+DTMB", "GPS"],
            },
        ],
    },
    Paper {
        id: "seed001-pf2d",
        title: "Seed 001 — GPS + DTMB particle filter (2-D simulation)",
        world: "worlds/seed001-pf2d.toml",
        figures: &[
            fig("10 particles", "PF-10", Mean, 138.66),
            fig("10 particles", "PF-10", Std, 126.30),
            fig("20 particles", "PF-20", Mean, 97.36),
            fig("20 particles", "PF-20", Std, 70.66),
        ],
        orderings: &[Ordering {
            metric: Mean,
            ascending: &["PF-20", "PF-10"],
        }],
    },
    Paper {
        id: "seed002-lianhua",
        title: "Seed 002 — PDR with magnetic landmarks and DTMB, Lianhua Lake (Remote Sensing 2023)",
        world: "worlds/seed002-lianhua.toml",
        figures: &[
            fig("PDR", "PDR", Horizontal1, 8.77),
            fig("PDR", "PDR", Horizontal2, 12.84),
            fig("Proposed", "Proposed", Horizontal1, 2.84),
            fig("Proposed", "Proposed", Horizontal2, 3.98),
        ],
        orderings: &[
            Ordering {
                metric: Horizontal1,
                ascending: &["Proposed", "PDR"],
            },
            Ordering {
                metric: Horizontal2,
                ascending: &["Proposed", "PDR"],
            },
        ],
    },
    Paper {
        id: "seed003-seamless",
        title: "Seed 003 — GPS/BeiDou/DTMB seamless positioning, EKF vs PF (Sensors and Materials 2018, Table 2)",
        world: "worlds/seed003-seamless.toml",
        figures: &[
            fig("EKF", "EKF", Mean, 11.2065),
            fig("EKF", "EKF", Std, 5.4361),
            fig("PF, 100 particles", "PF-100", Mean, 5.3601),
            fig("PF, 100 particles", "PF-100", Std, 3.1325),
            fig("PF, 500 particles", "PF-500", Mean, 2.8736),
            fig("PF, 500 particles", "PF-500", Std, 1.7603),
        ],
        orderings: &[Ordering {
            metric: Mean,
            ascending: &["PF-500", "PF-100", "EKF"],
        }],
    },
    Paper {
        id: "seed004-bupt",
        title: "Seed 004 — relative-entropy KF for INS/TC-OFDM/GNSS, BUPT campus (2018)",
        world: "worlds/seed004-bupt.toml",
        // The paper gives its comparison as figures of error against time, not as a
        // table: only its orderings are checked.
        figures: &[],
        // The paper's four rows are loosely coupled (its §2.3) and share the eq. 24 gate;
        // the tightly coupled rows are the same filters on the pseudoranges, where the
        // ranges are nonlinear in the error state (not in the paper).
        orderings: &[
            Ordering {
                metric: Rmse,
                ascending: &["RE-KF", "CKF", "EKF"],
            },
            Ordering {
                metric: Rmse,
                ascending: &["RE-KF", "STF"],
            },
            Ordering {
                metric: Rmse,
                ascending: &["RE-KF (tight)", "CKF (tight)", "EKF (tight)"],
            },
            Ordering {
                metric: Rmse,
                ascending: &["RE-KF (tight)", "STF (tight)"],
            },
        ],
    },
];

/// Where a stated figure is taken: the epochs whose truth was outdoors or indoors
/// (`summary.json`'s `environments`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Place {
    Outdoor,
    Indoor,
}

impl Place {
    /// The label of the place in `summary.json`'s `environments`.
    pub fn label(self) -> &'static str {
        match self {
            Place::Outdoor => "outdoor",
            Place::Indoor => "indoor",
        }
    }

    /// "outdoors" or "indoors", as the reports print it.
    pub fn adverb(self) -> &'static str {
        match self {
            Place::Outdoor => "outdoors",
            Place::Indoor => "indoors",
        }
    }
}

/// A figure a paper states in its text rather than in a table: the horizontal RMS error
/// of one estimator at the epochs of one [`Place`]. `hybridnav reproduce` prints it
/// beside the run's value; it counts in no total.
#[derive(Clone, Copy, Debug)]
pub struct Stated {
    /// The [`Paper::id`] whose world runs the estimator.
    pub paper: &'static str,
    pub estimator: &'static str,
    pub place: Place,
    /// The paper's value (m).
    pub paper_m: f64,
    /// Whether the paper gives a bound ("better than 1 m"), met by any value up to it,
    /// rather than a value, met within 2×.
    pub at_most: bool,
    /// The paper's words and where they are.
    pub quote: &'static str,
}

/// Seed 004's accuracy, stated for its RE-KF in §4.3: "indoor
/// positioning accuracy is better than 1 m, outdoor positioning accuracy of 0.5 m". The
/// paper does not say which error it means; its static test reports east and north
/// errors, so the horizontal RMS is taken. The tightly coupled RE-KF is hybridnav's, not
/// the paper's, and is held to the same words.
const SEED004_OUTDOOR: &str = "\"outdoor positioning accuracy of 0.5 m\" (§4.3)";
const SEED004_INDOOR: &str = "\"indoor positioning accuracy is better than 1 m\" (§4.3)";

/// Every stated figure, by paper.
pub const STATED: &[Stated] = &[
    Stated {
        paper: "seed004-bupt",
        estimator: "RE-KF",
        place: Place::Outdoor,
        paper_m: 0.5,
        at_most: false,
        quote: SEED004_OUTDOOR,
    },
    Stated {
        paper: "seed004-bupt",
        estimator: "RE-KF",
        place: Place::Indoor,
        paper_m: 1.0,
        at_most: true,
        quote: SEED004_INDOOR,
    },
    Stated {
        paper: "seed004-bupt",
        estimator: "RE-KF (tight)",
        place: Place::Outdoor,
        paper_m: 0.5,
        at_most: false,
        quote: SEED004_OUTDOOR,
    },
    Stated {
        paper: "seed004-bupt",
        estimator: "RE-KF (tight)",
        place: Place::Indoor,
        paper_m: 1.0,
        at_most: true,
        quote: SEED004_INDOOR,
    },
];

/// A method's gain over a baseline, and the part of it that one of the method's terms
/// contributes. `method` is `without` plus that term, everything else shared (model,
/// gate, divergence watch, and the trials' measurements: every estimator of a world sees
/// the same random numbers), so on the run's own figures
///
/// ```text
/// gain = baseline − method,   term's part = without − method,   share = part / gain
/// ```
///
/// Seed 004's RE-KF is the cubature Kalman filter plus the relative-entropy selection of
/// its eq. 38 (`fusion::kalman::RelativeEntropyKf`), so RE-KF against CKF isolates the
/// relative-entropy term's part of the RE-KF's gain over the EKF.
#[derive(Clone, Copy, Debug)]
pub struct GainSplit {
    /// The [`Paper::id`] whose world runs the three rows.
    pub paper: &'static str,
    pub method: &'static str,
    pub without: &'static str,
    pub baseline: &'static str,
    /// The term `method` adds to `without`, in words.
    pub term: &'static str,
    pub metric: Metric,
}

const RE_TERM: &str = "the relative-entropy selection (eq. 38)";

/// Every gain split, by paper.
pub const GAIN_SPLITS: &[GainSplit] = &[
    GainSplit {
        paper: "seed004-bupt",
        method: "RE-KF",
        without: "CKF",
        baseline: "EKF",
        term: RE_TERM,
        metric: Rmse,
    },
    GainSplit {
        paper: "seed004-bupt",
        method: "RE-KF (tight)",
        without: "CKF (tight)",
        baseline: "EKF (tight)",
        term: RE_TERM,
        metric: Rmse,
    },
];
