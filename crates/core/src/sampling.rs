//! Random numbers and elementary sampling routines.
//!
//! Every random decision is a pure function of (seed, index), so that images do not depend on
//! the number of threads: plane `i` takes point `i` of its [`Sampler`], pixel sample
//! `(pass, pixel)` draws from a hash.

use crate::sobol::SobolSampler;
use glam::DVec3;
use rand::{RngCore, SeedableRng};
use std::fmt;
use std::str::FromStr;

/// The random stream that planes draw from (see [`rng_for`]).
const PLANE_STREAM: u64 = 0x9_1A4E;

/// Where the five uniform numbers of a photon plane come from (docs/mathematics.md section 2.1:
/// light and orientation, the direction's two, the point's p and q).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Sampler {
    /// Randomised quasi-Monte Carlo: plane i is point i of a 5D Owen-scrambled Sobol sequence,
    /// an independent scrambling per seed ([`crate::sobol`]). Unbiased for every seed, and the
    /// planes cover the five dimensions far more evenly than independent ones.
    #[default]
    Sobol,
    /// Five independent uniform numbers per plane, as in the paper.
    Independent,
}

impl Sampler {
    pub const ALL: [Sampler; 2] = [Sampler::Sobol, Sampler::Independent];

    pub fn name(self) -> &'static str {
        match self {
            Sampler::Sobol => "sobol",
            Sampler::Independent => "independent",
        }
    }

    /// The five uniform numbers in [0, 1) of plane `index` of the set made with `seed`, in the
    /// order [`crate::photon_plane::sample_plane`] reads them: light and orientation (one
    /// number, see there), the direction's two, the point's p and q.
    #[inline]
    pub fn plane_numbers(self, seed: u64, index: u64) -> [f64; 5] {
        match self {
            Sampler::Independent => {
                let mut rng = rng_for(seed, PLANE_STREAM, index);
                std::array::from_fn(|_| unit_f64(rng.next_u64()))
            }
            Sampler::Sobol => {
                // Plane counts stay far below 2^32 (limits::MAX_PLANES).
                debug_assert!(index <= u32::MAX as u64, "plane index {index} beyond the Sobol sequence");
                let stream = mix64(seed ^ PLANE_STREAM);
                let point: [f64; 5] = SobolSampler::new(stream).point(index as u32);
                // The digits below the sequence's 32 bits, uniform and independent, as an Owen
                // scrambling of unlimited depth would make them: the light's share of dimension
                // 0 is stretched into the orientation, and must not come out on a grid.
                let low = mix64(stream ^ mix64(index));
                std::array::from_fn(|d| {
                    let fine = unit_f64(mix64(low ^ d as u64)) * (1.0 / 4_294_967_296.0);
                    (point[d] + fine).min(ONE_BELOW)
                })
            }
        }
    }
}

/// The largest f64 below 1.
const ONE_BELOW: f64 = 1.0 - f64::EPSILON / 2.0;

impl fmt::Display for Sampler {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Sampler {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        crate::parse_name("sampler", s, &Sampler::ALL, Sampler::name)
    }
}

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

    /// Where `u` lies within index `i`'s interval of the CDF, rescaled to [0, 1): given the
    /// choice of `i`, a uniform number again, and stratified wherever `u` was.
    pub fn remainder(&self, u: f64, i: usize) -> f64 {
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        ((u - lo) / self.probabilities[i]).clamp(0.0, ONE_BELOW)
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

    #[test]
    fn jitter_is_a_pure_function_of_its_inputs() {
        assert_eq!(pixel_jitter(1, 0, 5), pixel_jitter(1, 0, 5));
        assert_ne!(pixel_jitter(1, 0, 5), pixel_jitter(1, 1, 5));
        let (x, y) = pixel_jitter(9, 3, 77);
        assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
    }
}
