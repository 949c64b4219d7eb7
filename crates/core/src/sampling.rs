//! Random numbers and elementary sampling routines.
//!
//! Every random decision is a pure function of (seed, index), so that images do not depend on
//! the number of threads: plane `i` draws from its own generator, pixel sample `(pass, pixel)`
//! from a hash.

use glam::DVec3;
use rand::SeedableRng;

/// SplitMix64's finaliser: a bijective 64-bit hash with good avalanche.
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// An independent generator for item `index` of stream `stream` under `seed`.
pub fn rng_for(seed: u64, stream: u64, index: u64) -> rand_pcg::Pcg64Mcg {
    rand_pcg::Pcg64Mcg::seed_from_u64(mix64(mix64(seed ^ mix64(stream)) ^ index))
}

/// A uniform number in [0, 1) from 64 random bits (53-bit precision).
pub fn unit_f64(bits: u64) -> f64 {
    (bits >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// The jitter (sx, sy) in [0, 1)^2 of pixel sample `pixel` in pass `pass`.
pub fn pixel_jitter(seed: u64, pass: u32, pixel: u64) -> (f64, f64) {
    let h = mix64(mix64(seed ^ 0x5EED_F0C5) ^ mix64(((pass as u64) << 40) ^ pixel));
    (unit_f64(h), unit_f64(mix64(h)))
}

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

    /// The index for a uniform `u` in [0, 1); never one of probability zero.
    pub fn sample(&self, u: f64) -> usize {
        let i = self.cdf.partition_point(|&c| c <= u).min(self.cdf.len() - 1);
        // Rounding in the CDF could land on a zero-probability tail; step back from it.
        (0..=i).rev().find(|&k| self.probabilities[k] > 0.0).unwrap_or(i)
    }
}

/// Light choice by power, P_l proportional to A_l luminance(Le_l) (docs/mathematics.md
/// section 2, step 1): shared by the photon planes and the reference.
pub fn light_distribution(scene: &crate::scene::Scene) -> Discrete {
    Discrete::new(&scene.lights.iter().map(crate::light::RectLight::power).collect::<Vec<_>>())
}

/// A direction cosine-distributed about `n` (pdf cos(theta) / pi), from two uniforms, given an
/// orthonormal frame (t, b, n). Malley's method: a uniform point on the disk, lifted.
pub fn cosine_hemisphere(u1: f64, u2: f64, t: DVec3, b: DVec3, n: DVec3) -> DVec3 {
    let r = u1.sqrt();
    let phi = 2.0 * std::f64::consts::PI * u2;
    let (s, c) = phi.sin_cos();
    let z = (1.0 - u1).max(0.0).sqrt();
    (r * c * t + r * s * b + z * n).normalize()
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

    #[test]
    fn jitter_is_a_pure_function_of_its_inputs() {
        assert_eq!(pixel_jitter(1, 0, 5), pixel_jitter(1, 0, 5));
        assert_ne!(pixel_jitter(1, 0, 5), pixel_jitter(1, 1, 5));
        let (x, y) = pixel_jitter(9, 3, 77);
        assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
    }
}
