//! Percentiles of measured samples, the one definition every bench uses.

/// The `q`-quantile (0 ≤ `q` ≤ 1) by nearest rank: the sorted value at index
/// `round((n − 1)·q)`, halves rounded away from zero, so the median of an even count is the
/// upper of the two middle values; NaN when there are no values. Sorts a copy with
/// `f64::total_cmp` (a NaN sample sorts last).
pub fn percentile(values: &[f64], q: f64) -> f64 {
    percentile_of_sorted(&sorted(values), q).unwrap_or(f64::NAN)
}

/// [`percentile`] at 0.5.
pub fn median(values: &[f64]) -> f64 {
    percentile(values, 0.5)
}

/// [`percentile`] of values already sorted ascending; `None` when there are none.
pub fn percentile_of_sorted(sorted: &[f64], q: f64) -> Option<f64> {
    let last = sorted.len().checked_sub(1)?;
    // `as usize` saturates: a negative q gives index 0.
    let i = (last as f64 * q).round() as usize;
    sorted.get(i.min(last)).copied()
}

/// Smallest, median, 95th percentile and largest of some samples (nearest rank, as
/// [`percentile`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Summary {
    /// The smallest value.
    pub min: f64,
    /// The 0.5 quantile.
    pub median: f64,
    /// The 0.95 quantile.
    pub p95: f64,
    /// The largest value.
    pub max: f64,
}

impl Summary {
    /// The summary of `values`; `None` when there are none.
    pub fn of(values: &[f64]) -> Option<Summary> {
        let v = sorted(values);
        Some(Summary {
            min: *v.first()?,
            median: percentile_of_sorted(&v, 0.5)?,
            p95: percentile_of_sorted(&v, 0.95)?,
            max: *v.last()?,
        })
    }
}

fn sorted(values: &[f64]) -> Vec<f64> {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_with_halves_rounded_up() {
        let v = [4.0, 1.0, 3.0, 2.0];
        // (n − 1)·0.5 = 1.5 → index 2: the upper middle value, as `v[n / 2]`.
        assert_eq!(median(&v), 3.0);
        assert_eq!(percentile(&v, 0.0), 1.0);
        assert_eq!(percentile(&v, 1.0), 4.0);
        // 3 · 0.25 = 0.75 → index 1
        assert_eq!(percentile(&v, 0.25), 2.0);
        assert_eq!(median(&[5.0, 1.0, 3.0]), 3.0);
        for n in 1..40 {
            let v: Vec<f64> = (0..n).map(f64::from).collect();
            assert_eq!(median(&v), v[v.len() / 2], "n {n}");
        }
    }

    #[test]
    fn out_of_range_quantiles_are_clamped() {
        let v = [1.0, 2.0];
        assert_eq!(percentile(&v, 2.0), 2.0);
        assert_eq!(percentile(&v, -1.0), 1.0);
    }

    #[test]
    fn no_values() {
        assert!(percentile(&[], 0.5).is_nan());
        assert!(median(&[]).is_nan());
        assert_eq!(percentile_of_sorted(&[], 0.5), None);
        assert_eq!(Summary::of(&[]), None);
    }

    #[test]
    fn summary_matches_percentiles_and_sorts_nan_last() {
        let v: Vec<f64> = (0..100).rev().map(f64::from).collect();
        let s = Summary::of(&v).unwrap_or_default();
        assert_eq!((s.min, s.median, s.p95, s.max), (0.0, 50.0, 94.0, 99.0));
        let s = Summary::of(&[2.0, f64::NAN, 1.0]).unwrap_or_default();
        assert_eq!((s.min, s.median), (1.0, 2.0));
        assert!(s.max.is_nan());
    }
}
