//! Pearson's chi-square test of counts against the probabilities they should follow: how the
//! sampling tests (the Sobol sequence's, the photon planes') check a sampler's distribution,
//! written once here so that every such test uses the same statistic and the same threshold.

/// Pearson's statistic sum_i (c_i - n p_i)^2 / (n p_i) of `counts` (n their sum) against the
/// expected `probabilities`, one per bin.
pub fn statistic(counts: &[u64], probabilities: &[f64]) -> f64 {
    assert_eq!(counts.len(), probabilities.len(), "one probability per bin");
    let n: u64 = counts.iter().sum();
    counts.iter().zip(probabilities).map(|(&c, &p)| (c as f64 - n as f64 * p).powi(2) / (n as f64 * p)).sum()
}

/// The statistic against equal probabilities.
pub fn uniform_statistic(counts: &[u64]) -> f64 {
    statistic(counts, &vec![1.0 / counts.len() as f64; counts.len()])
}

/// The value the statistic of a correct sampler exceeds with probability 1e-4 at `dof` degrees
/// of freedom (bins - 1), by the Wilson-Hilferty approximation: a little above the exact
/// quantile (2.2% at 5 degrees of freedom, 0.7% at 15, 0.13% at 63).
pub fn critical(dof: usize) -> f64 {
    let k = dof as f64;
    let z = 3.719; // standard normal upper 1e-4 quantile
    k * (1.0 - 2.0 / (9.0 * k) + z * (2.0 / (9.0 * k)).sqrt()).powi(3)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against the exact upper 1e-4 quantiles of chi-square (by the regularised incomplete
    /// gamma function), and a statistic that is zero for exact counts and sums the deviations.
    #[test]
    fn critical_values_and_statistic() {
        for (dof, exact) in [(63, 113.505), (15, 44.263), (5, 25.745)] {
            let c = critical(dof);
            assert!(c > exact && c < 1.025 * exact, "{dof} dof: {c} vs {exact}");
        }
        assert_eq!(uniform_statistic(&[1024; 64]), 0.0);
        assert_eq!(statistic(&[10, 30], &[0.25, 0.75]), 0.0);
        assert!((statistic(&[20, 20], &[0.25, 0.75]) - (100.0 / 10.0 + 100.0 / 30.0)).abs() < 1e-12);
    }
}
