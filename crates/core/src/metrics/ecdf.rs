//! The empirical cumulative distribution function of a sample, thinned for plotting.

/// The empirical CDF of `sorted` (ascending, finite) as points `(x_(i), (i + 1)/n)`, the
/// value of the step function just after each order statistic, thinned to at most
/// `max_points` points.
///
/// The kept order statistics are evenly spaced in rank, `i_k = round(k (n − 1)/(m − 1))`
/// for `k = 0 … m − 1`, so a long tail is drawn with the same density of points as the
/// bulk and the first point and the last one (probability 1) are always kept. With
/// `max_points == 1` only the last point is returned; with 0 or an empty sample, none.
pub fn ecdf(sorted: &[f64], max_points: usize) -> Vec<(f64, f64)> {
    debug_assert!(
        sorted.windows(2).all(|w| w[0] <= w[1]),
        "ecdf needs ascending data"
    );
    let n = sorted.len();
    ecdf_ranks(n, max_points)
        .into_iter()
        .map(|i| (sorted[i], (i + 1) as f64 / n as f64))
        .collect()
}

/// The ranks [`ecdf`] keeps of `n` sorted values.
fn ecdf_ranks(n: usize, max_points: usize) -> Vec<usize> {
    if n == 0 || max_points == 0 {
        return Vec::new();
    }
    if max_points == 1 {
        return vec![n - 1];
    }
    let m = max_points.min(n);
    // Rounding k (n − 1)/(m − 1) gives strictly increasing ranks because m ≤ n.
    (0..m)
        .map(|k| ((k * (n - 1)) as f64 / (m - 1) as f64).round() as usize)
        .collect()
}

/// [`ecdf`] of values that may not fit in memory, read in one sorted pass.
///
/// # Errors
/// When values kept on disk cannot be read back.
pub fn ecdf_of(
    v: &mut dyn super::SortedValues,
    max_points: usize,
) -> std::io::Result<Vec<(f64, f64)>> {
    let n = v.count();
    let ranks = ecdf_ranks(n, max_points);
    let mut out = Vec::with_capacity(ranks.len());
    let mut next = ranks.iter().peekable();
    v.pass(&mut |i, x| {
        if next.peek() == Some(&&i) {
            next.next();
            out.push((x, (i + 1) as f64 / n as f64));
        }
    })?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_samples_are_kept_whole() {
        let p = ecdf(&[1.0, 2.0, 2.0, 5.0], 10);
        assert_eq!(p, vec![(1.0, 0.25), (2.0, 0.5), (2.0, 0.75), (5.0, 1.0)]);
        assert!(ecdf(&[], 5).is_empty() && ecdf(&[1.0], 0).is_empty());
        assert_eq!(ecdf(&[1.0, 3.0], 1), vec![(3.0, 1.0)]);
    }

    #[test]
    fn thinning_is_even_and_keeps_both_ends() {
        let v: Vec<f64> = (0..10_001).map(f64::from).collect();
        let p = ecdf(&v, 101);
        assert_eq!(p.len(), 101);
        assert_eq!(p[0], (0.0, 1.0 / 10_001.0));
        assert_eq!(*p.last().unwrap(), (10_000.0, 1.0));
        // Every 100th order statistic.
        assert!(p
            .iter()
            .enumerate()
            .all(|(k, &(x, _))| x == 100.0 * k as f64));
        // Ranks strictly increase for awkward ratios too.
        let q = ecdf(&v[..997], 300);
        assert_eq!(q.len(), 300);
        assert!(q.windows(2).all(|w| w[0].1 < w[1].1));
        assert_eq!(q.last().unwrap().1, 1.0);
    }
}
