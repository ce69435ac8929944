//! Empirical semivariogram, variogram model fitting and ordinary kriging.
//!
//! # Semivariogram
//!
//! For data z(x_i), the binned empirical semivariogram (Matheron's estimator, Cressie,
//! *Statistics for Spatial Data*, 1993, §2.4) is
//!
//! ```text
//! γ̂(h_k) = 1 / (2 N_k) Σ_{(i,j) ∈ bin k} (z_i − z_j)²
//! ```
//!
//! over the N_k pairs whose distance falls in bin k; `h_k` is their mean distance.
//!
//! # Models (the parameterisation of PyKrige 1.7, so that parameters are interchangeable)
//!
//! ```text
//! γ(0) = 0
//! spherical:    γ(h) = c0 + c1 (3h/(2a) − h³/(2a³))   for 0 < h ≤ a,   c0 + c1 for h > a
//! exponential:  γ(h) = c0 + c1 (1 − exp(−3h/a))        for h > 0
//! ```
//!
//! with nugget c0, partial sill c1 and range a. For the exponential model `a` is the
//! *practical* range (95 % of the sill), as PyKrige's `range_/3` makes it. γ(0) = 0 and
//! γ(h > 0) ≥ c0: the nugget is a discontinuity at the origin, so the kriging predictor
//! is an exact interpolator even with a nugget (PyKrige's `exact_values=True`).
//!
//! # Fitting
//!
//! Weighted least squares over the bins with weights N_k: for a fixed range the model is
//! linear in (c0, c1), which is solved in closed form under c0, c1 ≥ 0; the range is
//! found by a log-spaced scan refined by golden-section search. The fit reports the
//! weighted residual sum of squares and the RMS residual (dB²).
//!
//! # Ordinary kriging
//!
//! The predictor ẑ(x0) = Σ λ_i z_i with Σ λ_i = 1 solves (Cressie 1993, §3.2)
//!
//! ```text
//! ⎡ Γ  1 ⎤ ⎡ λ ⎤   ⎡ γ0 ⎤        Γ_ij = γ(|x_i − x_j|),  γ0_i = γ(|x_i − x0|)
//! ⎣ 1ᵀ 0 ⎦ ⎣ μ ⎦ = ⎣ 1  ⎦        σ²_OK(x0) = λᵀ γ0 + μ
//! ```
//!
//! Writing A for the (n+1)×(n+1) matrix and b(x0) for the right-hand side,
//! ẑ = [z; 0]ᵀ A⁻¹ b(x0) = wᵀ b(x0) with w = A⁻¹ [z; 0] (A is symmetric). So A is
//! factorised once (LU, nalgebra), w is solved once, and each prediction costs n variogram
//! evaluations and a dot product: that is what makes 282 → 16 640 points cheap. The
//! kriging variance needs a solve per point ([`OrdinaryKriging::predict_with_variance`]).

use super::FmError;
use nalgebra::{DMatrix, DVector};

/// Distances at or below this (m) count as zero (PyKrige's `eps = 1e-10`).
pub const ZERO_DISTANCE_M: f64 = 1e-10;

/// The variogram family.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VariogramKind {
    Spherical,
    Exponential,
}

/// A variogram model with its parameters (PyKrige's `[psill, range, nugget]`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VariogramModel {
    pub kind: VariogramKind,
    /// Nugget c0 (dB²), ≥ 0.
    pub nugget: f64,
    /// Partial sill c1 (dB²), > 0.
    pub psill: f64,
    /// Range a (m), > 0; the practical range for the exponential model.
    pub range_m: f64,
}

impl VariogramModel {
    /// γ(h) for h > 0 without the zero-distance rule: the continuous part plus the nugget.
    #[inline]
    fn gamma_positive(&self, h: f64) -> f64 {
        match self.kind {
            VariogramKind::Spherical => {
                if h <= self.range_m {
                    let r = h / self.range_m;
                    self.nugget + self.psill * (1.5 * r - 0.5 * r * r * r)
                } else {
                    self.nugget + self.psill
                }
            }
            VariogramKind::Exponential => {
                self.nugget + self.psill * (1.0 - (-3.0 * h / self.range_m).exp())
            }
        }
    }

    /// γ(h): 0 at h ≤ [`ZERO_DISTANCE_M`], the model otherwise.
    #[inline]
    pub fn gamma(&self, h_m: f64) -> f64 {
        if h_m <= ZERO_DISTANCE_M {
            0.0
        } else {
            self.gamma_positive(h_m)
        }
    }

    /// The sill c0 + c1.
    pub fn sill(&self) -> f64 {
        self.nugget + self.psill
    }

    /// Checks the parameters.
    pub fn validate(&self) -> Result<(), FmError> {
        let ok = self.nugget.is_finite()
            && self.nugget >= 0.0
            && self.psill.is_finite()
            && self.psill > 0.0
            && self.range_m.is_finite()
            && self.range_m > 0.0;
        if ok {
            Ok(())
        } else {
            Err(FmError::Data(format!(
                "expected a variogram with nugget ≥ 0, partial sill > 0 and range > 0, got {self:?}"
            )))
        }
    }
}

/// One bin of the empirical semivariogram.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VariogramBin {
    /// Mean pair distance in the bin (m).
    pub lag_m: f64,
    /// γ̂ (dB²).
    pub gamma: f64,
    /// Number of pairs.
    pub pairs: usize,
}

/// The binned empirical semivariogram of the finite values of `z` at `xy`: `n_bins`
/// equal bins over (0, `max_lag_m`]; empty bins are left out.
pub fn empirical_variogram(
    xy: &[[f64; 2]],
    z: &[f64],
    n_bins: usize,
    max_lag_m: f64,
) -> Vec<VariogramBin> {
    let mut sum = vec![0.0; n_bins];
    let mut lag = vec![0.0; n_bins];
    let mut count = vec![0usize; n_bins];
    let width = max_lag_m / n_bins as f64;
    for i in 0..xy.len() {
        if !z[i].is_finite() {
            continue;
        }
        for j in i + 1..xy.len() {
            if !z[j].is_finite() {
                continue;
            }
            let h = ((xy[i][0] - xy[j][0]).powi(2) + (xy[i][1] - xy[j][1]).powi(2)).sqrt();
            if h <= ZERO_DISTANCE_M || h > max_lag_m {
                continue;
            }
            let k = ((h / width) as usize).min(n_bins - 1);
            sum[k] += (z[i] - z[j]).powi(2);
            lag[k] += h;
            count[k] += 1;
        }
    }
    (0..n_bins)
        .filter(|&k| count[k] > 0)
        .map(|k| VariogramBin {
            lag_m: lag[k] / count[k] as f64,
            gamma: sum[k] / (2.0 * count[k] as f64),
            pairs: count[k],
        })
        .collect()
}

/// A fitted model and how well it fits.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VariogramFit {
    pub model: VariogramModel,
    /// Σ N_k (γ̂_k − γ(h_k))² / Σ N_k (dB⁴): the weighted mean squared residual.
    pub weighted_mse: f64,
    /// Unweighted RMS residual over the bins (dB²).
    pub rms_residual: f64,
}

fn shape(kind: VariogramKind, h: f64, range_m: f64) -> f64 {
    VariogramModel {
        kind,
        nugget: 0.0,
        psill: 1.0,
        range_m,
    }
    .gamma_positive(h)
}

/// Best (c0, c1) ≥ 0 for a fixed range, and the weighted residual sum of squares.
fn linear_fit(bins: &[VariogramBin], kind: VariogramKind, range_m: f64) -> (f64, f64, f64) {
    let (mut sw, mut sf, mut sff, mut sg, mut sfg) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for b in bins {
        let w = b.pairs as f64;
        let f = shape(kind, b.lag_m, range_m);
        sw += w;
        sf += w * f;
        sff += w * f * f;
        sg += w * b.gamma;
        sfg += w * f * b.gamma;
    }
    let det = sw * sff - sf * sf;
    let (mut c0, mut c1) = if det.abs() > 1e-12 * sw * sff {
        ((sff * sg - sf * sfg) / det, (sw * sfg - sf * sg) / det)
    } else {
        (-1.0, -1.0)
    };
    if c0 < 0.0 || c1 < 0.0 || !c0.is_finite() || !c1.is_finite() {
        // One of the bounds is active: try each edge and keep the better.
        let edge_a = (0.0, if sff > 0.0 { (sfg / sff).max(0.0) } else { 0.0 });
        let edge_b = ((sg / sw).max(0.0), 0.0);
        let rss = |c0: f64, c1: f64| wrss(bins, kind, range_m, c0, c1);
        (c0, c1) = if rss(edge_a.0, edge_a.1) <= rss(edge_b.0, edge_b.1) {
            edge_a
        } else {
            edge_b
        };
    }
    (c0, c1, wrss(bins, kind, range_m, c0, c1))
}

fn wrss(bins: &[VariogramBin], kind: VariogramKind, range_m: f64, c0: f64, c1: f64) -> f64 {
    bins.iter()
        .map(|b| b.pairs as f64 * (b.gamma - c0 - c1 * shape(kind, b.lag_m, range_m)).powi(2))
        .sum()
}

/// Fits `kind` to the bins by weighted least squares (weights N_k), with the range
/// searched over [`min_range_m`, `max_range_m`].
pub fn fit_variogram(
    bins: &[VariogramBin],
    kind: VariogramKind,
    min_range_m: f64,
    max_range_m: f64,
) -> Result<VariogramFit, FmError> {
    if bins.len() < 3 {
        return Err(FmError::Data(format!(
            "expected at least 3 non-empty variogram bins to fit a model, got {}",
            bins.len()
        )));
    }
    if !(min_range_m > 0.0 && max_range_m > min_range_m && max_range_m.is_finite()) {
        return Err(FmError::Data(format!(
            "expected a range search interval 0 < min < max, got [{min_range_m}, {max_range_m}] m"
        )));
    }
    // A log-spaced scan finds the basin; golden-section search refines it in log range.
    let n = 60;
    let (la, lb) = (min_range_m.ln(), max_range_m.ln());
    let at = |i: usize| la + (lb - la) * i as f64 / n as f64;
    let best_i = (0..=n)
        .min_by(|&i, &j| {
            let a = linear_fit(bins, kind, at(i).exp()).2;
            let b = linear_fit(bins, kind, at(j).exp()).2;
            a.total_cmp(&b)
        })
        .unwrap_or(0);
    let (mut lo, mut hi) = (at(best_i.saturating_sub(1)), at((best_i + 1).min(n)));
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let cost = |l: f64| linear_fit(bins, kind, l.exp()).2;
    let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut f1, mut f2) = (cost(x1), cost(x2));
    for _ in 0..60 {
        if f1 <= f2 {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - g * (hi - lo);
            f1 = cost(x1);
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + g * (hi - lo);
            f2 = cost(x2);
        }
    }
    let range_m = (0.5 * (lo + hi)).exp();
    let (c0, c1, rss) = linear_fit(bins, kind, range_m);
    let sw: f64 = bins.iter().map(|b| b.pairs as f64).sum();
    let model = VariogramModel {
        kind,
        nugget: c0,
        psill: c1,
        range_m,
    };
    let rms = (bins
        .iter()
        .map(|b| (b.gamma - model.gamma(b.lag_m)).powi(2))
        .sum::<f64>()
        / bins.len() as f64)
        .sqrt();
    if c1 <= 0.0 {
        return Err(FmError::Data(
            "the variogram is flat (pure nugget): the data carry no spatial correlation to krige"
                .into(),
        ));
    }
    Ok(VariogramFit {
        model,
        weighted_mse: rss / sw,
        rms_residual: rms,
    })
}

/// How [`fit_best`] and [`krige_channels`] fit variograms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitOptions {
    /// Number of lag bins, default 15.
    pub n_bins: usize,
    /// Largest lag (m); `None`: half the largest pair distance.
    pub max_lag_m: Option<f64>,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            n_bins: 15,
            max_lag_m: None,
        }
    }
}

/// Fits both spherical and exponential models to the data and returns the better fit
/// (smaller weighted mean squared residual) and the bins.
pub fn fit_best(
    xy: &[[f64; 2]],
    z: &[f64],
    opts: &FitOptions,
) -> Result<(VariogramFit, Vec<VariogramBin>), FmError> {
    let max_pair = max_pair_distance(xy, z);
    let max_lag = opts.max_lag_m.unwrap_or(0.5 * max_pair);
    if max_lag.is_nan() || max_lag <= 0.0 || opts.n_bins < 3 {
        return Err(FmError::Data(format!(
            "expected at least 3 bins and distinct data points, got {} bins, largest lag {max_lag} m",
            opts.n_bins
        )));
    }
    let bins = empirical_variogram(xy, z, opts.n_bins, max_lag);
    let min_lag = bins.first().map_or(1.0, |b| b.lag_m);
    let lo = 0.25 * min_lag.max(1e-3);
    let hi = 4.0 * max_pair.max(lo * 2.0);
    let s = fit_variogram(&bins, VariogramKind::Spherical, lo, hi);
    let e = fit_variogram(&bins, VariogramKind::Exponential, lo, hi);
    let best = match (s, e) {
        (Ok(s), Ok(e)) => {
            if s.weighted_mse <= e.weighted_mse {
                s
            } else {
                e
            }
        }
        (Ok(s), Err(_)) => s,
        (Err(_), Ok(e)) => e,
        (Err(err), Err(_)) => return Err(err),
    };
    Ok((best, bins))
}

fn max_pair_distance(xy: &[[f64; 2]], z: &[f64]) -> f64 {
    // The diagonal of the bounding box bounds every pair distance and is within a factor
    // √2 of the largest; it avoids a second O(n²) pass.
    let pts = xy
        .iter()
        .zip(z)
        .filter(|(_, v)| v.is_finite())
        .map(|(p, _)| p);
    let (mut x0, mut y0, mut x1, mut y1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    for p in pts {
        x0 = x0.min(p[0]);
        y0 = y0.min(p[1]);
        x1 = x1.max(p[0]);
        y1 = y1.max(p[1]);
    }
    if x1 < x0 {
        return 0.0;
    }
    ((x1 - x0).powi(2) + (y1 - y0).powi(2)).sqrt()
}

/// The checks of [`OrdinaryKriging::new`] before it factorises: a valid model, at least two
/// points, one value per point, every number finite.
fn check_data(xy: &[[f64; 2]], z: &[f64], model: &VariogramModel) -> Result<(), FmError> {
    model.validate()?;
    let n = xy.len();
    if n < 2 || z.len() != n {
        return Err(FmError::Data(format!(
            "expected at least 2 data points and one value per point, got {n} points and {} values",
            z.len()
        )));
    }
    if !xy.iter().flatten().chain(z).all(|v| v.is_finite()) {
        return Err(FmError::Data(
            "expected finite data positions and values for kriging".into(),
        ));
    }
    Ok(())
}

/// The error of a kriging system whose data points coincide (within [`ZERO_DISTANCE_M`]),
/// found without factorising: points sorted by east, each compared with the next ones
/// less than the tolerance further east.
fn check_distinct(xy: &[[f64; 2]]) -> Result<(), FmError> {
    let mut order: Vec<usize> = (0..xy.len()).collect();
    order.sort_by(|&a, &b| xy[a][0].total_cmp(&xy[b][0]));
    for (k, &i) in order.iter().enumerate() {
        for &j in &order[k + 1..] {
            if xy[j][0] - xy[i][0] > ZERO_DISTANCE_M {
                break;
            }
            let h = ((xy[i][0] - xy[j][0]).powi(2) + (xy[i][1] - xy[j][1]).powi(2)).sqrt();
            if h <= ZERO_DISTANCE_M {
                return Err(FmError::Data("the kriging system is singular: two data points coincide (merge or remove duplicates)".into()));
            }
        }
    }
    Ok(())
}

/// For each point of `grid`, the index of the datum of `xy` at exactly the same
/// coordinates, if any.
fn data_at(xy: &[[f64; 2]], grid: &[[f64; 2]]) -> Vec<Option<usize>> {
    let key = |p: &[f64; 2]| (p[0].to_bits(), p[1].to_bits());
    let index: std::collections::HashMap<(u64, u64), usize> =
        xy.iter().enumerate().map(|(i, p)| (key(p), i)).collect();
    grid.iter().map(|p| index.get(&key(p)).copied()).collect()
}

/// An ordinary kriging predictor: the system factorised once for a data set and model.
pub struct OrdinaryKriging {
    xs: Vec<f64>,
    ys: Vec<f64>,
    model: VariogramModel,
    lu: nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>,
    /// w = A⁻¹ [z; 0].
    w: Vec<f64>,
}

impl OrdinaryKriging {
    /// Factorises the kriging system of the data `z` at `xy` under `model`. Errors for
    /// fewer than 2 points, non-finite values, or a singular system (repeated points).
    pub fn new(xy: &[[f64; 2]], z: &[f64], model: VariogramModel) -> Result<Self, FmError> {
        check_data(xy, z, &model)?;
        let n = xy.len();
        let mut a = DMatrix::<f64>::zeros(n + 1, n + 1);
        for i in 0..n {
            for j in i + 1..n {
                let h = ((xy[i][0] - xy[j][0]).powi(2) + (xy[i][1] - xy[j][1]).powi(2)).sqrt();
                let g = model.gamma(h);
                a[(i, j)] = g;
                a[(j, i)] = g;
            }
            a[(i, n)] = 1.0;
            a[(n, i)] = 1.0;
        }
        let lu = a.lu();
        let mut rhs = DVector::<f64>::zeros(n + 1);
        rhs.rows_mut(0, n).copy_from_slice(z);
        let w = lu.solve(&rhs).filter(|w| w.iter().all(|v| v.is_finite())).ok_or_else(|| {
            FmError::Data("the kriging system is singular: two data points coincide (merge or remove duplicates)".into())
        })?;
        Ok(Self {
            xs: xy.iter().map(|p| p[0]).collect(),
            ys: xy.iter().map(|p| p[1]).collect(),
            model,
            lu,
            w: w.as_slice().to_vec(),
        })
    }

    /// The model.
    pub fn model(&self) -> &VariogramModel {
        &self.model
    }

    /// The prediction at `p` (one dot product with the precomputed weights).
    #[inline]
    pub fn predict(&self, p: [f64; 2]) -> f64 {
        let n = self.xs.len();
        let mut acc = self.w[n];
        for i in 0..n {
            let h = ((self.xs[i] - p[0]).powi(2) + (self.ys[i] - p[1]).powi(2)).sqrt();
            acc += self.w[i] * self.model.gamma(h);
        }
        acc
    }

    /// Predictions at every point of `pts` into `out`.
    pub fn predict_many(&self, pts: &[[f64; 2]], out: &mut [f64]) {
        for (o, p) in out.iter_mut().zip(pts) {
            *o = self.predict(*p);
        }
    }

    /// The prediction and the kriging variance σ²_OK = λᵀγ0 + μ at `p` (one solve).
    pub fn predict_with_variance(&self, p: [f64; 2]) -> (f64, f64) {
        let n = self.xs.len();
        let mut b = DVector::<f64>::zeros(n + 1);
        for i in 0..n {
            let h = ((self.xs[i] - p[0]).powi(2) + (self.ys[i] - p[1]).powi(2)).sqrt();
            b[i] = self.model.gamma(h);
        }
        b[n] = 1.0;
        let z = self.predict(p);
        match self.lu.solve(&b) {
            Some(x) => (z, x.dot(&b).max(0.0)),
            None => (z, f64::NAN),
        }
    }
}

/// The per-channel result of [`krige_channels`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChannelKriging {
    /// The fitted variogram, or `None` when the channel had too few data (its grid
    /// column is then missing).
    pub fit: Option<VariogramFit>,
    /// Number of RPs with a value on this channel.
    pub data_points: usize,
}

/// Kriges every channel of a survey (`rssi_dbm`, row-major: RP × channel, NaN for a
/// missing reading) onto `grid`, each channel with its own fitted model over the RPs
/// that have a value on it. Channels with fewer than `min_points` values are left
/// missing (NaN) on the grid. Returns the grid values (grid point × channel) and the
/// fits.
///
/// Ordinary kriging is an exact interpolator (γ(0) = 0, see the module documentation):
/// at a data point the predictor is the datum itself, λ = e_i. So a grid point that is a
/// surveyed RP (same coordinates) takes the datum directly, and a channel whose grid
/// points are all data points (seed 000's "without interpolation": the grid is the RPs)
/// is not factorised at all. The factorised predictor gives the same value up to the
/// rounding of the (n+1)² solve (about 1e-12 dB, tested); the variogram is fitted either
/// way, for the report.
pub fn krige_channels(
    rp_xy: &[[f64; 2]],
    rssi_dbm: &[f64],
    channels: usize,
    grid: &[[f64; 2]],
    opts: &FitOptions,
    min_points: usize,
) -> Result<(Vec<f64>, Vec<ChannelKriging>), FmError> {
    if channels == 0 || rssi_dbm.len() != rp_xy.len() * channels {
        return Err(FmError::Data(format!(
            "expected {} × {channels} survey values, got {}",
            rp_xy.len(),
            rssi_dbm.len()
        )));
    }
    let mut out = vec![f64::NAN; grid.len() * channels];
    let mut col = vec![0.0; grid.len()];
    let mut report = Vec::with_capacity(channels);
    for c in 0..channels {
        let (xy, z): (Vec<[f64; 2]>, Vec<f64>) = rp_xy
            .iter()
            .enumerate()
            .map(|(i, p)| (*p, rssi_dbm[i * channels + c]))
            .filter(|(_, v)| v.is_finite())
            .unzip();
        if xy.len() < min_points.max(4) {
            report.push(ChannelKriging {
                fit: None,
                data_points: xy.len(),
            });
            continue;
        }
        let (fit, _) = fit_best(&xy, &z, opts)?;
        let at = data_at(&xy, grid);
        if at.iter().all(Option::is_some) {
            // Every grid point is a datum: the checks of the factorisation, without it.
            check_data(&xy, &z, &fit.model)?;
            check_distinct(&xy)?;
        } else {
            let ok = OrdinaryKriging::new(&xy, &z, fit.model)?;
            for ((v, p), a) in col.iter_mut().zip(grid).zip(&at) {
                if a.is_none() {
                    *v = ok.predict(*p);
                }
            }
        }
        for (g, v) in col.iter().enumerate() {
            out[g * channels + c] = at[g].map_or(*v, |i| z[i]);
        }
        report.push(ChannelKriging {
            fit: Some(fit),
            data_points: xy.len(),
        });
    }
    Ok((out, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;
    use rand::Rng;

    fn data(n: usize) -> (Vec<[f64; 2]>, Vec<f64>) {
        let mut rng = TrialRng::new(5, 0).stream("test/kriging");
        let xy: Vec<[f64; 2]> = (0..n)
            .map(|_| [rng.random::<f64>() * 300.0, rng.random::<f64>() * 300.0])
            .collect();
        let z = xy
            .iter()
            .map(|p| -60.0 + 5.0 * (p[0] / 40.0).sin() + 0.02 * p[1] + rng.random::<f64>())
            .collect();
        (xy, z)
    }

    #[test]
    fn kriging_reproduces_the_data_at_the_data_points() {
        let (xy, z) = data(120);
        for kind in [VariogramKind::Spherical, VariogramKind::Exponential] {
            // A nugget does not break exactness: γ(0) = 0 by definition.
            let m = VariogramModel {
                kind,
                nugget: 1.5,
                psill: 10.0,
                range_m: 90.0,
            };
            let ok = OrdinaryKriging::new(&xy, &z, m).unwrap();
            for (p, v) in xy.iter().zip(&z) {
                let (zp, var) = ok.predict_with_variance(*p);
                assert!((zp - v).abs() < 1e-9 * v.abs(), "{kind:?}: {zp} vs {v}");
                assert!(var.abs() < 1e-8, "variance at a datum {var}");
            }
            // Away from the data, the kriging variance is positive and below the
            // nugget + sill + μ bound.
            let (_, var) = ok.predict_with_variance([151.3, 77.7]);
            assert!(var > 0.0 && var < 2.0 * m.sill(), "{var}");
        }
    }

    #[test]
    fn weights_sum_to_one_so_a_constant_is_reproduced() {
        let (xy, _) = data(50);
        let z = vec![-72.5; xy.len()];
        let m = VariogramModel {
            kind: VariogramKind::Exponential,
            nugget: 0.0,
            psill: 4.0,
            range_m: 60.0,
        };
        let ok = OrdinaryKriging::new(&xy, &z, m).unwrap();
        for p in [[10.0, 10.0], [500.0, -300.0], [150.0, 150.0]] {
            assert!((ok.predict(p) + 72.5).abs() < 1e-9);
        }
    }

    /// Kriging onto the surveyed points themselves: a complete channel is the survey, bit
    /// for bit, and equals the factorised predictor to the rounding of the solve; a channel
    /// with missing readings keeps its data and gets the factorised prediction (bit for
    /// bit) at the RPs it lacks; a grid with one point between the RPs is predicted there.
    #[test]
    fn kriging_onto_the_data_points_returns_the_data() {
        let (xy, z) = data(150);
        let channels = 2;
        let mut rssi = vec![0.0; xy.len() * channels];
        for (i, v) in z.iter().enumerate() {
            rssi[i * channels] = *v;
            // Channel 1: the same field 3 dB weaker, missing at every seventh RP.
            rssi[i * channels + 1] = if i % 7 == 3 { f64::NAN } else { v - 3.0 };
        }
        let opts = FitOptions::default();
        let (grid_vals, report) = krige_channels(&xy, &rssi, channels, &xy, &opts, 10).unwrap();
        // Channel 0: the data exactly, and the factorised predictor within 1e-9 dB.
        let fit0 = report[0].fit.unwrap();
        let ok0 = OrdinaryKriging::new(&xy, &z, fit0.model).unwrap();
        let mut worst = 0.0f64;
        for (i, p) in xy.iter().enumerate() {
            assert_eq!(grid_vals[i * channels].to_bits(), z[i].to_bits());
            worst = worst.max((ok0.predict(*p) - z[i]).abs());
        }
        assert!(
            worst < 1e-9,
            "factorised predictor at the data: {worst} dB off"
        );
        // Channel 1: data where surveyed, the factorised prediction where not.
        let (xy1, z1): (Vec<[f64; 2]>, Vec<f64>) = xy
            .iter()
            .enumerate()
            .filter(|(i, _)| i % 7 != 3)
            .map(|(i, p)| (*p, z[i] - 3.0))
            .unzip();
        let ok1 = OrdinaryKriging::new(&xy1, &z1, report[1].fit.unwrap().model).unwrap();
        for (i, p) in xy.iter().enumerate() {
            let got = grid_vals[i * channels + 1];
            let want = if i % 7 == 3 {
                ok1.predict(*p)
            } else {
                z[i] - 3.0
            };
            assert_eq!(got.to_bits(), want.to_bits(), "RP {i}");
        }
        // A grid point between the RPs is predicted, the others are the data.
        let mut grid = xy[..5].to_vec();
        grid.push([151.3, 77.7]);
        let (vals, _) = krige_channels(&xy, &rssi, channels, &grid, &opts, 10).unwrap();
        assert_eq!(
            vals[5 * channels].to_bits(),
            ok0.predict([151.3, 77.7]).to_bits()
        );
        assert_eq!(vals[2 * channels].to_bits(), z[2].to_bits());
        // Coinciding RPs stay an error without a factorisation too.
        let mut dup = xy.clone();
        dup[9] = dup[4];
        let e = krige_channels(&dup, &rssi, channels, &dup, &opts, 10).unwrap_err();
        assert!(e.to_string().contains("coincide"), "{e}");
    }

    #[test]
    fn duplicate_points_are_a_clear_error() {
        let xy = vec![[0.0, 0.0], [10.0, 0.0], [10.0, 0.0], [0.0, 10.0]];
        let z = vec![1.0, 2.0, 3.0, 4.0];
        let m = VariogramModel {
            kind: VariogramKind::Spherical,
            nugget: 0.0,
            psill: 1.0,
            range_m: 50.0,
        };
        let e = OrdinaryKriging::new(&xy, &z, m).err().unwrap();
        assert!(e.to_string().contains("coincide"), "{e}");
    }

    #[test]
    fn fit_recovers_a_model_from_its_own_values() {
        // Bins that lie exactly on a model must give that model back.
        for kind in [VariogramKind::Spherical, VariogramKind::Exponential] {
            let m = VariogramModel {
                kind,
                nugget: 2.0,
                psill: 9.0,
                range_m: 80.0,
            };
            let bins: Vec<VariogramBin> = (1..=20)
                .map(|k| VariogramBin {
                    lag_m: 8.0 * k as f64,
                    gamma: m.gamma(8.0 * k as f64),
                    pairs: 100 + k,
                })
                .collect();
            let f = fit_variogram(&bins, kind, 5.0, 1000.0).unwrap();
            assert!((f.model.range_m - 80.0).abs() < 0.01, "{f:?}");
            assert!(
                (f.model.nugget - 2.0).abs() < 1e-3 && (f.model.psill - 9.0).abs() < 1e-3,
                "{f:?}"
            );
            assert!(f.rms_residual < 1e-3);
        }
    }
}
