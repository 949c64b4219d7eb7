//! The one hash behind every random stream: SplitMix64 (Steele, Lea and Flood 2014), and the
//! streams and uniform numbers made from it, each a pure function of its inputs; and the one
//! hash that names contents (scenes, settings, images), FNV-1a.

use rand::SeedableRng;

/// SplitMix64's increment: 2^64 / phi, odd.
pub(super) const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's output function (Stafford's "Mix13"): a bijective 64-bit hash with good
/// avalanche, applied to the generator's state.
#[inline]
pub(super) const fn splitmix64_finalizer(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The number a SplitMix64 generator in state `z` returns: one step (the increment
/// `GOLDEN`), then its output function. A bijective 64-bit hash.
#[inline]
pub const fn splitmix64(z: u64) -> u64 {
    splitmix64_finalizer(z.wrapping_add(GOLDEN))
}

/// An independent generator for item `index` of stream `stream` under `seed`.
pub fn rng_for(seed: u64, stream: u64, index: u64) -> rand_pcg::Pcg64Mcg {
    rand_pcg::Pcg64Mcg::seed_from_u64(splitmix64(splitmix64(seed ^ splitmix64(stream)) ^ index))
}

/// A uniform number in [0, 1) from 64 random bits (53-bit precision).
pub fn unit_f64(bits: u64) -> f64 {
    (bits >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// A stable 128-bit hash of `bytes` (FNV-1a): the same in every process, run and machine, as
/// 32 hex digits. It names contents (scenes, settings), it does not guard against forgery.
pub fn stable_hash(parts: &[&[u8]]) -> String {
    const OFFSET: u128 = 0x6c62_272e_07bb_0142_62b8_2175_6295_c58d;
    const PRIME: u128 = 0x0000_0000_0100_0000_0000_0000_0000_013b;
    let mut h = OFFSET;
    for part in parts {
        // Each part's length first, so that ("ab", "c") and ("a", "bc") differ.
        for &b in (part.len() as u64).to_le_bytes().iter().chain(part.iter()) {
            h ^= b as u128;
            h = h.wrapping_mul(PRIME);
        }
    }
    format!("{h:032x}")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first outputs of SplitMix64 from state 0, as its reference implementation (Vigna's
    /// splitmix64.c) gives them: the hash is the standard one, and planes drawn with a seed stay
    /// what they were.
    #[test]
    fn splitmix64_is_the_reference_generator() {
        let mut state = 0u64;
        let mut next = || {
            let out = splitmix64(state);
            state = state.wrapping_add(GOLDEN);
            out
        };
        assert_eq!([next(), next(), next()], [0xE220_A839_7B1D_CDAF, 0x6E78_9E6A_A1B9_65F4, 0x06C4_5D18_8009_454F]);
    }

    #[test]
    fn the_stable_hash_is_fnv_1a() {
        // FNV-1a 128 of the empty string is its offset basis; lengths are hashed first here.
        assert_eq!(stable_hash(&[]), "6c62272e07bb014262b821756295c58d");
        assert_ne!(stable_hash(&[b"ab", b"c"]), stable_hash(&[b"a", b"bc"]));
        assert_eq!(stable_hash(&[b"x"]), stable_hash(&[b"x"]));
    }
}
