//! The offline survey: reference-point layouts and the surveyor's measurements.
//!
//! A surveyor stands at each reference point (RP) and records `scans_per_point` scans
//! of every channel with their own instrument (noise σ `noise_sigma_db`, the field's
//! quantisation and sensitivity). The RP's fingerprint is the mean in dB of the scans
//! that detected the channel; a channel detected in fewer than half the scans is missing
//! (NaN), because a mean of the few strong outliers above the floor would be biased high.
//! Averaging N scans divides the noise variance by N (before quantisation), which is why
//! a survey is more accurate than one online scan.
//!
//! The survey is also done at another time than the test, and usually with another
//! receiver: the field the surveyor measures is not the one the user later sees. What
//! averaging cannot remove is modelled as one more, independent, spatially correlated
//! log-normal draw per station, `Δ_s(x)` of σ `time_variation_sigma_db` and decorrelation
//! distance `time_variation_decorrelation_m` (a [`ShadowingField`] drawn from the
//! surveyor's own stream before the first scan), added to the mean the surveyor measures:
//!
//! ```text
//! fingerprint_s(x) = mean_k Q( P̄_s(x) + Δ_s(x) + n_k ),   n_k ~ N(0, σ_survey²)
//! ```
//!
//! so that the database error at an RP has variance σ_Δ² + σ_survey²/N (before
//! quantisation). With σ_Δ = 0 (the default) the survey sees exactly the user's field.

use super::field::FmField;
use super::FmError;
use crate::core::config::check;
use crate::core::rng::StreamRng;
use crate::core::ConfigIssue;
use crate::propagation::{ShadowingConfig, ShadowingField};
use nalgebra::Vector3;
use serde::Deserialize;

fn default_scans() -> u32 {
    10
}
fn default_noise() -> f64 {
    2.0
}
fn default_time_decorrelation() -> f64 {
    ShadowingConfig::default().decorrelation_m
}

/// How the surveyor measures.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SurveyConfig {
    /// Scans averaged per RP (1–1000), default 10.
    #[serde(default = "default_scans")]
    pub scans_per_point: u32,
    /// The surveyor's per-scan noise σ (dB), default 2.
    #[serde(default = "default_noise")]
    pub noise_sigma_db: f64,
    /// σ (dB) of the field's change between the survey and the test (another time,
    /// another receiver), an independent log-normal draw per station; default 0.
    #[serde(default)]
    pub time_variation_sigma_db: f64,
    /// Decorrelation distance (m) of that change, default 37 (the default shadowing's).
    #[serde(default = "default_time_decorrelation")]
    pub time_variation_decorrelation_m: f64,
}

impl Default for SurveyConfig {
    fn default() -> Self {
        Self {
            scans_per_point: default_scans(),
            noise_sigma_db: default_noise(),
            time_variation_sigma_db: 0.0,
            time_variation_decorrelation_m: default_time_decorrelation(),
        }
    }
}

impl SurveyConfig {
    /// Checks every value; the key is the field name.
    pub fn validate(&self) -> Result<(), ConfigIssue> {
        check(
            "scans_per_point",
            (1..=1000).contains(&self.scans_per_point),
            || {
                format!(
                    "expected 1 to 1000 scans per point, got {}",
                    self.scans_per_point
                )
            },
        )?;
        check(
            "noise_sigma_db",
            self.noise_sigma_db.is_finite() && (0.0..=30.0).contains(&self.noise_sigma_db),
            || {
                format!(
                    "expected a surveyor noise σ in [0, 30] dB, got {}",
                    self.noise_sigma_db
                )
            },
        )?;
        self.time_variation()
            .validate()
            .map_err(|c| ConfigIssue::new(format!("time_variation_{}", c.key), c.message))
    }

    /// The survey-to-test change as a shadowing configuration.
    fn time_variation(&self) -> ShadowingConfig {
        ShadowingConfig {
            sigma_db: self.time_variation_sigma_db,
            decorrelation_m: self.time_variation_decorrelation_m,
            ..ShadowingConfig::default()
        }
    }
}

/// Grid points from (`east0`, `north0`) to (`east1`, `north1`) inclusive, every
/// `spacing_m`, row by row (north outer, east inner).
pub fn grid_points(
    min_en_m: [f64; 2],
    max_en_m: [f64; 2],
    spacing_m: f64,
) -> Result<Vec<[f64; 2]>, FmError> {
    grid_points_en(min_en_m, max_en_m, [spacing_m, spacing_m])
}

/// [`grid_points`] with its own spacing along each axis, `[east, north]` (m): a survey
/// driven along parallel lanes has RPs every few metres along a lane and one row per
/// lane.
pub fn grid_points_en(
    min_en_m: [f64; 2],
    max_en_m: [f64; 2],
    spacing_en_m: [f64; 2],
) -> Result<Vec<[f64; 2]>, FmError> {
    let ok = spacing_en_m.iter().all(|s| s.is_finite() && *s > 0.0)
        && min_en_m.iter().chain(&max_en_m).all(|v| v.is_finite())
        && max_en_m[0] >= min_en_m[0]
        && max_en_m[1] >= min_en_m[1];
    if !ok {
        return Err(FmError::Data(format!(
            "expected a grid with min ≤ max corners and positive spacings, got {min_en_m:?}–{max_en_m:?} every {spacing_en_m:?} m"
        )));
    }
    let [se, sn] = spacing_en_m;
    let ne = ((max_en_m[0] - min_en_m[0]) / se + 1e-9).floor() as usize + 1;
    let nn = ((max_en_m[1] - min_en_m[1]) / sn + 1e-9).floor() as usize + 1;
    if ne.saturating_mul(nn) > 10_000_000 {
        return Err(FmError::Data(format!(
            "expected at most 10 million grid points, got {ne} × {nn}"
        )));
    }
    let mut out = Vec::with_capacity(ne * nn);
    for j in 0..nn {
        for i in 0..ne {
            out.push([min_en_m[0] + i as f64 * se, min_en_m[1] + j as f64 * sn]);
        }
    }
    Ok(out)
}

/// Points along the polyline `vertices` every `spacing_m` of arc length, starting at the
/// first vertex (the last vertex is included only when it falls on the spacing).
pub fn polyline_points(vertices: &[[f64; 2]], spacing_m: f64) -> Result<Vec<[f64; 2]>, FmError> {
    if vertices.len() < 2
        || !(spacing_m.is_finite() && spacing_m > 0.0)
        || !vertices.iter().flatten().all(|v| v.is_finite())
    {
        return Err(FmError::Data(format!(
            "expected a polyline of at least 2 finite vertices and a positive spacing, got {} vertices every {spacing_m} m",
            vertices.len()
        )));
    }
    let mut out = vec![vertices[0]];
    // `carry` is the arc length since the last point.
    let mut carry = 0.0;
    for w in vertices.windows(2) {
        let (a, b) = (w[0], w[1]);
        let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        let mut s = spacing_m - carry;
        while s <= len + 1e-9 {
            let t = s / len;
            out.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
            s += spacing_m;
        }
        carry = len - (s - spacing_m);
        if out.len() > 10_000_000 {
            return Err(FmError::Data(
                "expected at most 10 million polyline points".into(),
            ));
        }
    }
    Ok(out)
}

/// Surveys `points` (horizontal ENU, at ENU height `up_m`) with `field`: returns the
/// fingerprints row-major (point × station, dBm, NaN where missing). `rng` is the
/// surveyor's named stream (e.g. `fm/survey`); when `time_variation_sigma_db` > 0 the
/// survey-to-test change of every station is drawn from it first, in station order.
pub fn survey(
    field: &mut FmField,
    points: &[[f64; 2]],
    up_m: f64,
    cfg: &SurveyConfig,
    rng: &mut StreamRng,
) -> Result<Vec<f64>, ConfigIssue> {
    cfg.validate()?;
    let c = field.stations().len();
    let mut out = vec![f64::NAN; points.len() * c];
    let mut mean = vec![0.0; c];
    let mut sum = vec![0.0; c];
    let mut hits = vec![0u32; c];
    let field_cfg = field.config().clone();
    let change: Vec<ShadowingField> = if cfg.time_variation_sigma_db > 0.0 {
        (0..c)
            .map(|_| ShadowingField::new(&cfg.time_variation(), rng))
            .collect::<Result<_, _>>()?
    } else {
        Vec::new()
    };
    for (i, p) in points.iter().enumerate() {
        field.mean_rssi_dbm(&Vector3::new(p[0], p[1], up_m), &mut mean);
        for (m, d) in mean.iter_mut().zip(&change) {
            *m += d.value_db(p[0], p[1]);
        }
        sum.iter_mut().for_each(|s| *s = 0.0);
        hits.iter_mut().for_each(|h| *h = 0);
        for _ in 0..cfg.scans_per_point {
            for k in 0..c {
                let v = field_cfg.read(mean[k], cfg.noise_sigma_db, rng);
                if v.is_finite() {
                    sum[k] += v;
                    hits[k] += 1;
                }
            }
        }
        for k in 0..c {
            if 2 * hits[k] >= cfg.scans_per_point && hits[k] > 0 {
                out[i * c + k] = sum[k] / f64::from(hits[k]);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One station 3 km away without shadowing or quantisation: the field's mean is then
    /// what the surveyor's errors are measured against.
    fn one_station_field() -> FmField {
        use crate::fm::field::{FmFieldConfig, FmStation};
        let fcfg = FmFieldConfig {
            quantisation_db: 0.0,
            shadowing: ShadowingConfig {
                sigma_db: 0.0,
                ..Default::default()
            },
            ..Default::default()
        };
        let st = FmStation::new("F01", Vector3::new(3_000.0, 0.0, 100.0), 98e6, 40.0, 0.0);
        FmField::new(fcfg, vec![st], None, 1).unwrap()
    }

    #[test]
    fn averaging_n_scans_divides_the_noise_by_root_n() {
        use crate::core::TrialRng;
        let mut field = one_station_field();
        let pts = grid_points([0.0, 0.0], [190.0, 190.0], 10.0).unwrap();
        let cfg = SurveyConfig {
            scans_per_point: 16,
            noise_sigma_db: 2.0,
            ..Default::default()
        };
        let mut rng = TrialRng::new(1, 0).stream("test/fm/survey");
        let v = survey(&mut field, &pts, 1.5, &cfg, &mut rng).unwrap();
        let mut mean = [0.0];
        let mut sq = 0.0;
        for (p, x) in pts.iter().zip(&v) {
            field.mean_rssi_dbm(&Vector3::new(p[0], p[1], 1.5), &mut mean);
            sq += (x - mean[0]).powi(2);
        }
        let rms = (sq / pts.len() as f64).sqrt();
        // 2 dB / √16 = 0.5 dB; 400 points give the RMS to about ±4 % (1σ).
        assert!((rms - 0.5).abs() < 0.06, "{rms}");
    }

    /// With a survey-to-test change of σ_Δ = 3 dB decorrelating over 1 m, RPs 10 m apart
    /// see independent changes: the database error over 400 RPs has the standard deviation
    /// √(σ_Δ² + σ_survey²/N) = √(9 + 4/16) = 3.041 dB, to within 3 standard errors
    /// (σ/√(2n) = 0.11 dB). The same seed gives the same bits; without the change the
    /// error is the averaged scan noise alone.
    #[test]
    fn the_survey_to_test_change_has_its_stated_sigma() {
        use crate::core::TrialRng;
        let mut field = one_station_field();
        let pts = grid_points([0.0, 0.0], [190.0, 190.0], 10.0).unwrap();
        let cfg = SurveyConfig {
            scans_per_point: 16,
            noise_sigma_db: 2.0,
            time_variation_sigma_db: 3.0,
            time_variation_decorrelation_m: 1.0,
        };
        let run = |field: &mut FmField| {
            let mut rng = TrialRng::new(7, 0).stream("test/fm/survey");
            survey(field, &pts, 1.5, &cfg, &mut rng).unwrap()
        };
        let v = run(&mut field);
        assert_eq!(
            v.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            run(&mut field)
                .iter()
                .map(|x| x.to_bits())
                .collect::<Vec<_>>()
        );
        let mut mean = [0.0];
        let e: Vec<f64> = pts
            .iter()
            .zip(&v)
            .map(|(p, x)| {
                field.mean_rssi_dbm(&Vector3::new(p[0], p[1], 1.5), &mut mean);
                x - mean[0]
            })
            .collect();
        let n = e.len() as f64;
        let m = e.iter().sum::<f64>() / n;
        let sd = (e.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let want = (9.0f64 + 4.0 / 16.0).sqrt();
        assert!(
            (sd - want).abs() < 3.0 * want / (2.0 * n).sqrt(),
            "{sd} vs {want}"
        );
        let bad = SurveyConfig {
            time_variation_decorrelation_m: 0.0,
            ..cfg
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .key
            .starts_with("time_variation_"));
    }

    #[test]
    fn grid_and_polyline_layouts() {
        let g = grid_points([0.0, 0.0], [9.0, 6.0], 3.0).unwrap();
        assert_eq!(g.len(), 4 * 3);
        assert_eq!(g[5], [3.0, 3.0]);
        // A 100 m × 50 m rectangle (300 m) every 10 m: 30 points plus the closing vertex.
        let p = polyline_points(
            &[
                [0.0, 0.0],
                [100.0, 0.0],
                [100.0, 50.0],
                [0.0, 50.0],
                [0.0, 0.0],
            ],
            10.0,
        )
        .unwrap();
        assert_eq!(p.len(), 31);
        for w in p.windows(2) {
            let d = ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt();
            assert!((d - 10.0).abs() < 1e-9, "{d}");
        }
        // A spacing that does not divide the legs still keeps 7 m of arc between points.
        let p = polyline_points(&[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]], 7.0).unwrap();
        assert_eq!(p, vec![[0.0, 0.0], [7.0, 0.0], [10.0, 4.0]]);
        assert!(grid_points([0.0, 0.0], [1.0, 1.0], 0.0).is_err());
        // Two lanes 8 m apart, every 4 m along them: 3 × 2 points, north outer.
        let g = grid_points_en([0.0, 0.0], [8.0, 8.0], [4.0, 8.0]).unwrap();
        assert_eq!(
            g,
            vec![
                [0.0, 0.0],
                [4.0, 0.0],
                [8.0, 0.0],
                [0.0, 8.0],
                [4.0, 8.0],
                [8.0, 8.0]
            ]
        );
        assert!(grid_points_en([0.0, 0.0], [1.0, 1.0], [1.0, f64::NAN]).is_err());
        assert!(polyline_points(&[[0.0, 0.0]], 1.0).is_err());
    }
}
