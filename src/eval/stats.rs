//! Summary statistics for the evaluation: angular errors and per-frame times.

/// Mean, maximum and variance of a set of values (population variance, as the paper's Table I).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Summary {
    pub count: usize,
    pub mean: f64,
    pub max: f64,
    pub variance: f64,
}

impl Summary {
    pub fn of(values: &[f64]) -> Self {
        let n = values.len();
        if n == 0 {
            return Summary::default();
        }
        let mean = values.iter().sum::<f64>() / n as f64;
        let variance = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
        let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Summary {
            count: n,
            mean,
            max,
            variance,
        }
    }
}

/// The q-th quantile (0..=1) by nearest rank of a sample; NaN when empty.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = (q.clamp(0.0, 1.0) * v.len() as f64).ceil().max(1.0) as usize;
    v[rank - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_and_quantiles() {
        let s = Summary::of(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(s.count, 4);
        assert_eq!(s.mean, 2.5);
        assert_eq!(s.max, 4.0);
        assert_eq!(s.variance, 1.25);
        assert_eq!(quantile(&[5.0, 1.0, 3.0], 0.5), 3.0);
        assert_eq!(
            quantile(&(1..=100).map(f64::from).collect::<Vec<_>>(), 0.99),
            99.0
        );
        assert!(quantile(&[], 0.5).is_nan());
        assert_eq!(Summary::of(&[]).count, 0);
    }
}
