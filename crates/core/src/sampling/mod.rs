//! Where the random numbers come from: the plane samplers ([`Sampler`]), the one hash every
//! random stream is made from, the warps from uniform numbers to the densities the planes and
//! the reference need, the Owen-scrambled Sobol sequence ([`sobol`]), the reference's
//! low-discrepancy sequence ([`Kronecker`]), and the chi-square test the sampling tests share.
//!
//! Every random decision is a pure function of (seed, index), so that images do not depend on
//! the number of threads: plane `i` takes point `i` of its [`Sampler`], pixel sample
//! `(pass, pixel)` draws from a hash.

pub mod chi_square;
mod hash;
mod kronecker;
pub mod sobol;
mod warp;

pub use hash::{rng_for, splitmix64, stable_hash, unit_f64};
pub use kronecker::Kronecker;
pub use warp::{Discrete, concentric_disk, cosine_hemisphere};

use rand::RngCore;
use sobol::SobolSampler;

/// The random stream that planes draw from (see [`rng_for`]).
const PLANE_STREAM: u64 = 0x9_1A4E;

/// Where the five uniform numbers of a photon plane come from (docs/mathematics.md section 2.1:
/// light and orientation, the direction's two, the point's p and q).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Sampler {
    /// Randomised quasi-Monte Carlo: plane i is point i of a 5D Owen-scrambled Sobol sequence,
    /// an independent scrambling per seed ([`sobol`]). Unbiased for every seed, and the
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
    /// number, see there), the direction's two, the point's p and q. (For many planes of one
    /// set, [`Sampler::numbers`] derives what depends on the seed once.)
    pub fn plane_numbers(self, seed: u64, index: u64) -> [f64; 5] {
        self.numbers(seed).plane(index)
    }

    /// The numbers of the set made with `seed`, plane by plane ([`PlaneNumbers::plane`]).
    pub fn numbers(self, seed: u64) -> PlaneNumbers {
        let stream = splitmix64(seed ^ PLANE_STREAM);
        PlaneNumbers { sampler: self, seed, stream, sobol: SobolSampler::new(stream) }
    }
}

/// The numbers of one set of planes ([`Sampler::numbers`]), with what depends on its seed alone
/// derived once: the Sobol sequence's scrambling seeds.
#[derive(Clone, Copy, Debug)]
pub struct PlaneNumbers {
    sampler: Sampler,
    seed: u64,
    stream: u64,
    sobol: SobolSampler,
}

impl PlaneNumbers {
    /// [`Sampler::plane_numbers`] of this set's plane `index`.
    #[inline]
    pub fn plane(&self, index: u64) -> [f64; 5] {
        match self.sampler {
            Sampler::Independent => {
                let mut rng = rng_for(self.seed, PLANE_STREAM, index);
                std::array::from_fn(|_| unit_f64(rng.next_u64()))
            }
            Sampler::Sobol => {
                // Plane counts stay far below 2^32 (limits::MAX_PLANES).
                debug_assert!(index <= u32::MAX as u64, "plane index {index} beyond the Sobol sequence");
                let point: [f64; 5] = self.sobol.point(index as u32);
                // The digits below the sequence's 32 bits, uniform and independent, as an Owen
                // scrambling of unlimited depth would make them: the light's share of dimension
                // 0 is stretched into the orientation, and must not come out on a grid.
                let low = splitmix64(self.stream ^ splitmix64(index));
                std::array::from_fn(|d| {
                    let fine = unit_f64(splitmix64(low ^ d as u64)) * (1.0 / 4_294_967_296.0);
                    (point[d] + fine).min(ONE_BELOW)
                })
            }
        }
    }
}

/// The largest f64 below 1.
const ONE_BELOW: f64 = 1.0 - f64::EPSILON / 2.0;

crate::named_choice!(Sampler, "sampler");

#[cfg(test)]
mod tests {
    use super::*;

    /// The Sobol sampler's numbers, bit for bit, as they were before its hash and the sequence
    /// moved here: the planes (and so the images) of a seed stay what they were.
    #[test]
    fn sobol_plane_numbers_are_unchanged() {
        let want: [((u64, u64), [u64; 5]); 4] = [
            (
                (0x1, 0),
                [0x3fe627a7eb0c5998, 0x3fd76485af70769e, 0x3fde476d9d17bd55, 0x3fd4ad8e49392647, 0x3fee28f00babc07b],
            ),
            (
                (0x1, 1),
                [0x3fd05e0482279ff4, 0x3fe45a6df62519ee, 0x3fe452a116556238, 0x3fe566799cec51d3, 0x3fccd039268907a6],
            ),
            (
                (0x7, 12345),
                [0x3fbdffbbbfa214b0, 0x3fa5550ae2830502, 0x3faf51bf0da62adc, 0x3fd6b11abf1225f1, 0x3fe21d3d84b0ad17],
            ),
            (
                (0xdeadbeef, 4000000),
                [0x3fca337e18fdebfc, 0x3fc8390648cbc46f, 0x3fe43dcd6ed966bd, 0x3fe8e0fadcda5ee8, 0x3fcb13b8c0dd8556],
            ),
        ];
        for ((seed, index), bits) in want {
            assert_eq!(Sampler::Sobol.plane_numbers(seed, index).map(f64::to_bits), bits, "seed {seed} plane {index}");
        }
    }
}
