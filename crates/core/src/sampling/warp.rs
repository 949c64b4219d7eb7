//! Warps: from uniform numbers to the distributions the planes and the reference sample (an
//! index by weight, a cosine-distributed direction, a point on the disk).

use glam::DVec3;

/// Chooses an index with probability proportional to its weight (by inverting the CDF).
#[derive(Clone, Debug)]
pub struct Discrete {
    cdf: Vec<f64>,
    probabilities: Vec<f64>,
}

impl Discrete {
    /// The weights must be non-negative with a positive sum.
    pub fn new(weights: &[f64]) -> Self {
        let total: f64 = weights.iter().sum();
        let probabilities: Vec<f64> = weights.iter().map(|w| w / total).collect();
        let mut acc = 0.0;
        let cdf = probabilities
            .iter()
            .map(|p| {
                acc += p;
                acc
            })
            .collect();
        Discrete { cdf, probabilities }
    }

    pub fn probability(&self, i: usize) -> f64 {
        self.probabilities[i]
    }

    /// Where `u` lies within index `i`'s interval of the CDF, rescaled to [0, 1): given the
    /// choice of `i`, a uniform number again, and stratified wherever `u` was.
    pub fn remainder(&self, u: f64, i: usize) -> f64 {
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        ((u - lo) / self.probabilities[i]).clamp(0.0, super::ONE_BELOW)
    }

    /// The index for a uniform `u` in [0, 1); never one of probability zero.
    pub fn sample(&self, u: f64) -> usize {
        let i = self.cdf.partition_point(|&c| c <= u).min(self.cdf.len() - 1);
        // Rounding in the CDF could land on a zero-probability tail; step back from it.
        (0..=i).rev().find(|&k| self.probabilities[k] > 0.0).unwrap_or(i)
    }
}

/// A direction cosine-distributed about `n` (pdf cos(theta) / pi), from two uniforms, given an
/// orthonormal frame (t, b, n). Malley's method: a uniform point on the disk (by the concentric
/// map, which keeps strata of the square compact), lifted.
pub fn cosine_hemisphere(u1: f64, u2: f64, t: DVec3, b: DVec3, n: DVec3) -> DVec3 {
    let (x, y) = concentric_disk(u1, u2);
    let z = (1.0 - x * x - y * y).max(0.0).sqrt();
    (x * t + y * b + z * n).normalize()
}

/// Shirley and Chiu's concentric map from the unit square to the unit disk: area-preserving and
/// of low distortion, so strata of the square stay compact on the disk.
pub fn concentric_disk(u1: f64, u2: f64) -> (f64, f64) {
    let (a, b) = (2.0 * u1 - 1.0, 2.0 * u2 - 1.0);
    if a == 0.0 && b == 0.0 {
        return (0.0, 0.0);
    }
    let quarter = std::f64::consts::FRAC_PI_4;
    let (r, phi) = if a.abs() > b.abs() { (a, quarter * (b / a)) } else { (b, 2.0 * quarter - quarter * (a / b)) };
    let (s, c) = phi.sin_cos();
    (r * c, r * s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn discrete_follows_its_weights_and_skips_zero() {
        let d = Discrete::new(&[1.0, 0.0, 3.0]);
        assert_eq!(d.sample(0.0), 0);
        assert_eq!(d.sample(0.2499), 0);
        assert_eq!(d.sample(0.25), 2);
        assert_eq!(d.sample(0.999_999_999), 2);
        assert!((d.probability(2) - 0.75).abs() < 1e-15);
    }
}
