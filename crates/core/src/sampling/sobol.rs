//! Randomised quasi-Monte Carlo sampling: Owen-scrambled Sobol' points.
//!
//! Why: every photon plane is drawn from a handful of uniform numbers (light
//! choice, orientation, points on the light, a cosine-weighted direction).
//! Independent random numbers converge as O(n^-1/2); a Sobol' sequence fills
//! the unit cube evenly (its prefixes of 2^m points are (t,m,s)-nets), and
//! nested-uniform (Owen) scrambling keeps that structure while making every
//! point uniformly distributed, so estimates stay unbiased, independent runs
//! with different seeds give honest error bars, and smooth integrands converge
//! much faster (Owen: variance O(n^-3 log^(s-1) n) for smooth integrands).
//!
//! * Direction numbers: S. Joe and F. Y. Kuo, "Constructing Sobol sequences
//!   with better two-dimensional projections", SIAM J. Sci. Comput. 30 (2008)
//!   2635-2654; set `new-joe-kuo-6.21201`, first 16 dimensions.
//! * Scrambling and shuffling: B. Burley, "Practical Hash-based Owen
//!   Scrambling", JCGT 9(4), 2020, with the improved Laine-Karras-style hash
//!   constants of N. Vegdahl ("Building a Better LK Hash", 2021).
//!
//! Everything is 32-bit: indices are `u32`, points are `u32` fixed-point
//! fractions, converted by `to_unit_f64`. What the renderer uses is
//! [`SobolSampler::point`]; the rest are its parts.

use super::hash::{splitmix64, splitmix64_finalizer};

/// Number of Sobol' dimensions provided (dimension indices are `0..16`).
pub const MAX_DIMENSIONS: usize = 16;

/// Joe-Kuo `new-joe-kuo-6.21201` rows for the (1-based) dimensions 2..=16:
/// `(s, a, [m_1 .. m_s])` where `s` is the degree of the primitive
/// polynomial, `a` encodes its inner coefficients (a_1 is the most significant
/// of the `s-1` bits) and the `m_k` are the odd initial direction integers.
/// Unused trailing entries are zero. Dimension 1 (our dimension 0) is the van
/// der Corput sequence (all m_k = 1) and has no row.
const JOE_KUO: [(u32, u32, [u32; 6]); MAX_DIMENSIONS - 1] = [
    (1, 0, [1, 0, 0, 0, 0, 0]),
    (2, 1, [1, 3, 0, 0, 0, 0]),
    (3, 1, [1, 3, 1, 0, 0, 0]),
    (3, 2, [1, 1, 1, 0, 0, 0]),
    (4, 1, [1, 1, 3, 3, 0, 0]),
    (4, 4, [1, 3, 5, 13, 0, 0]),
    (5, 2, [1, 1, 5, 5, 17, 0]),
    (5, 4, [1, 1, 5, 5, 5, 0]),
    (5, 7, [1, 1, 7, 11, 19, 0]),
    (5, 11, [1, 1, 5, 1, 1, 0]),
    (5, 13, [1, 1, 1, 3, 11, 0]),
    (5, 14, [1, 3, 5, 5, 31, 0]),
    (6, 1, [1, 3, 3, 9, 7, 49]),
    (6, 13, [1, 1, 1, 15, 21, 21]),
    (6, 16, [1, 3, 1, 13, 27, 49]),
];

/// Builds the direction numbers: column `k` of dimension `d` is
/// `v_{k+1} = m_{k+1} / 2^{k+1}` as a 32-bit fraction, extended past the
/// initial values by the usual recurrence
/// `v_k = v_{k-s} ^ (v_{k-s} >> s) ^ XOR_{j<s} a_j v_{k-j}`.
const fn build_matrices() -> [[u32; 32]; MAX_DIMENSIONS] {
    let mut out = [[0u32; 32]; MAX_DIMENSIONS];
    let mut k = 0;
    while k < 32 {
        out[0][k] = 1u32 << (31 - k);
        k += 1;
    }
    let mut d = 1;
    while d < MAX_DIMENSIONS {
        let (s, a, m) = JOE_KUO[d - 1];
        let s = s as usize;
        let mut k = 0;
        while k < 32 {
            out[d][k] = if k < s {
                m[k] << (31 - k)
            } else {
                let mut v = out[d][k - s];
                v ^= v >> s;
                let mut j = 1;
                while j < s {
                    if (a >> (s - 1 - j)) & 1 == 1 {
                        v ^= out[d][k - j];
                    }
                    j += 1;
                }
                v
            };
            k += 1;
        }
        d += 1;
    }
    out
}

/// Sobol' generator matrices, one row of 32 direction numbers per dimension,
/// evaluated at compile time.
const SOBOL_MATRICES: [[u32; 32]; MAX_DIMENSIONS] = build_matrices();

/// The generator matrices a byte of the index at a time: entry `[d][k][b]` is the XOR of the
/// direction numbers of dimension `d` selected by the bits of byte value `b` in byte `k` of the
/// index (bits `8k .. 8k + 8`). Sobol' points are linear over GF(2) in the index's bits, so a
/// point is the XOR of its four bytes' entries: four loads instead of a loop over the index's
/// set bits (about 16 for a shuffled index). 64 KB, of which a plane's five dimensions touch 20.
const fn build_byte_tables() -> [[[u32; 256]; 4]; MAX_DIMENSIONS] {
    let mut out = [[[0u32; 256]; 4]; MAX_DIMENSIONS];
    let mut d = 0;
    while d < MAX_DIMENSIONS {
        let mut k = 0;
        while k < 4 {
            let mut b = 1usize;
            while b < 256 {
                // The entry of b is that of b without its lowest set bit, XOR that bit's column.
                let low = b & (b - 1);
                let bit = (b ^ low).trailing_zeros() as usize;
                out[d][k][b] = out[d][k][low] ^ SOBOL_MATRICES[d][8 * k + bit];
                b += 1;
            }
            k += 1;
        }
        d += 1;
    }
    out
}

static SOBOL_BYTES: [[[u32; 256]; 4]; MAX_DIMENSIONS] = build_byte_tables();

/// Unscrambled Sobol' point `index` in dimension `dim` as a 32-bit fraction
/// (the point is `result / 2^32`). Natural (not Gray-code) order, so the
/// first `2^m` points of each dimension form a (0,m,1)-net.
///
/// Panics if `dim >= MAX_DIMENSIONS`.
#[inline]
pub(crate) fn sobol_u32(index: u32, dim: usize) -> u32 {
    let t = &SOBOL_BYTES[dim];
    let b = index.to_le_bytes();
    t[0][b[0] as usize] ^ t[1][b[1] as usize] ^ t[2][b[2] as usize] ^ t[3][b[3] as usize]
}

/// [`sobol_u32`] as the definition gives it, a direction number per set bit of the index: the
/// reference the byte tables are tested against.
#[cfg(test)]
fn sobol_u32_by_bits(index: u32, dim: usize) -> u32 {
    let matrix = &SOBOL_MATRICES[dim];
    let mut bits = index;
    let mut result = 0u32;
    while bits != 0 {
        result ^= matrix[bits.trailing_zeros() as usize];
        bits &= bits - 1;
    }
    result
}

/// Laine-Karras-style hash on bit-reversed input with Vegdahl's constants.
/// Every step maps bit `i` to `bit_i ^ f(lower bits)` (multiplications by
/// even constants, an addition, an odd multiplication), so it is a
/// bijection that only propagates information upwards.
#[inline]
fn laine_karras_permutation(mut x: u32, seed: u32) -> u32 {
    x ^= x.wrapping_mul(0x3d20_adea);
    x = x.wrapping_add(seed);
    x = x.wrapping_mul((seed >> 16) | 1);
    x ^= x.wrapping_mul(0x0552_6c56);
    x ^= x.wrapping_mul(0x53a2_2864);
    x
}

/// Hash-based nested uniform (Owen) scramble of a 32-bit fraction (Burley
/// 2020): each digit is flipped by a pseudo-random function of the more
/// significant digits only. Hence it is a bijection, maps every elementary
/// interval onto one of the same shape, and preserves every (t,m,s)-net
/// property exactly, while making each single value (close to) uniform over
/// seeds. Applied to an *index* it permutes every aligned block of `2^m`
/// indices onto an aligned block of `2^m` indices (Burley's shuffling).
#[inline]
pub(crate) fn nested_uniform_scramble(x: u32, seed: u32) -> u32 {
    laine_karras_permutation(x.reverse_bits(), seed).reverse_bits()
}

/// Seed tag for the index shuffle; distinct from every dimension number.
const SHUFFLE_TAG: u32 = u32::MAX;

/// Derives a well-mixed 32-bit seed from `(seed, tag)`; injective before
/// truncation because [`splitmix64`] is a bijection.
#[inline]
const fn hash_seed(seed: u32, tag: u32) -> u32 {
    (splitmix64(((seed as u64) << 32) | tag as u64) >> 32) as u32
}

/// Owen-scrambled Sobol' point: dimension `dim` is scrambled with its own
/// seed hashed from `(seed, dim)`, so dimensions do not share a permutation.
///
/// Caveat: for a fixed `index`, the same dimension under two seeds is a
/// bijective function of the same raw value, so the *index-by-index*
/// sequences of two seeds are strongly correlated (|r| typically 0.5-0.9).
/// Each seed on its own is a valid randomisation; [`SobolSampler::point`]
/// shuffles the index first, which decorrelates seeds.
/// ([`SobolSampler::point`] computes it with the dimension's seed derived once.)
#[cfg(test)]
fn owen_sobol(index: u32, dim: usize, seed: u32) -> u32 {
    nested_uniform_scramble(sobol_u32(index, dim), hash_seed(seed, dim as u32))
}

/// The index nested-uniform-scrambled (Burley 2020, section 4): each prefix
/// of `2^m` indices maps to an aligned block of `2^m` indices.
/// ([`SobolSampler::point`] computes it with the shuffle's seed derived once.)
#[cfg(test)]
fn shuffle_index(index: u32, seed: u32) -> u32 {
    nested_uniform_scramble(index, hash_seed(seed, SHUFFLE_TAG))
}

/// Converts a 32-bit fraction to `x * 2^-32`, exact in `f64` and always in
/// `[0, 1)` (the largest value is `1 - 2^-32`). No jitter is added below the
/// 32-bit resolution; note that rounding the result to `f32` can give 1.0.
#[inline]
fn to_unit_f64(x: u32) -> f64 {
    x as f64 * (1.0 / 4_294_967_296.0)
}

/// The sampler: one 64-bit seed per independent randomisation (per plane
/// set), mixed into the 32-bit seed of its scrambling. What depends on the
/// seed alone (the scrambling's seed, the index shuffle's and each
/// dimension's) is derived once, when it is made, not per point.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SobolSampler {
    seed: u64,
    /// The scrambling's 32-bit seed, the index shuffle's seed hashed from it,
    /// and each dimension's.
    scramble: u32,
    shuffle: u32,
    dimensions: [u32; MAX_DIMENSIONS],
}

impl SobolSampler {
    pub const fn new(seed: u64) -> Self {
        let scramble = (splitmix64(splitmix64_finalizer(seed)) >> 32) as u32;
        let mut dimensions = [0u32; MAX_DIMENSIONS];
        let mut d = 0;
        while d < MAX_DIMENSIONS {
            dimensions[d] = hash_seed(scramble, d as u32);
            d += 1;
        }
        Self { seed, scramble, shuffle: hash_seed(scramble, SHUFFLE_TAG), dimensions }
    }

    /// The 32-bit seed of the scrambling and the index shuffle.
    #[cfg(test)]
    fn scramble_seed(&self) -> u32 {
        self.scramble
    }

    /// Point `index` of a `D`-dimensional shuffled Owen-scrambled Sobol'
    /// sequence (`D <= 16`, checked at compile time). The index shuffle
    /// depends on the seed only, not on the dimension, so the dimensions keep
    /// their joint net structure: the first `2^m` indices form a scrambled
    /// (t,m,D)-net, and different seeds give decorrelated sequences.
    /// (What the tests' `shuffle_index` and `owen_sobol` compute, their seeds
    /// derived once.)
    pub fn point<const D: usize>(&self, index: u32) -> [f64; D] {
        const { assert!(D <= MAX_DIMENSIONS, "SobolSampler::point supports at most 16 dimensions") };
        let shuffled = nested_uniform_scramble(index, self.shuffle);
        std::array::from_fn(|d| to_unit_f64(nested_uniform_scramble(sobol_u32(shuffled, d), self.dimensions[d])))
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::super::chi_square;
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// What [`SobolSampler::point`] computes in dimension `dim` for the
    /// scramble seed `seed`, as a 32-bit fraction: the Owen-scrambled point
    /// of the shuffled index.
    fn shuffled_owen_sobol(index: u32, dim: usize, seed: u32) -> u32 {
        owen_sobol(shuffle_index(index, seed), dim, seed)
    }

    /// The `bits` most significant bits of `x` (0 if `bits == 0`).
    fn top(x: u32, bits: u32) -> u32 {
        if bits == 0 { 0 } else { x >> (32 - bits) }
    }

    /// True if the `2^m` values hit each of the `2^m` intervals exactly once.
    fn is_0m1_net(vals: &[u32], m: u32) -> bool {
        assert_eq!(vals.len(), 1 << m);
        let mut seen = vec![false; 1 << m];
        for &v in vals {
            let c = top(v, m) as usize;
            if seen[c] {
                return false;
            }
            seen[c] = true;
        }
        true
    }

    /// True if the `2^m` points form a (t,m,2)-net: every elementary interval
    /// of area `2^(t-m)` (all shapes `2^-a x 2^-b`, `a+b = m-t`) holds `2^t`.
    fn is_tm2_net(pts: &[(u32, u32)], m: u32, t: u32) -> bool {
        assert_eq!(pts.len(), 1 << m);
        let k = m - t;
        let mut counts = vec![0u32; 1 << k];
        for a in 0..=k {
            let b = k - a;
            counts.fill(0);
            for &(x, y) in pts {
                counts[((top(x, a) << b) | top(y, b)) as usize] += 1;
            }
            if counts.iter().any(|&c| c != 1 << t) {
                return false;
            }
        }
        true
    }

    fn t_value(pts: &[(u32, u32)], m: u32) -> u32 {
        (0..=m).find(|&t| is_tm2_net(pts, m, t)).unwrap()
    }

    fn pearson(x: &[f64], y: &[f64]) -> f64 {
        let n = x.len() as f64;
        let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
        let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
        for (a, b) in x.iter().zip(y) {
            sxy += (a - mx) * (b - my);
            sxx += (a - mx) * (a - mx);
            syy += (b - my) * (b - my);
        }
        sxy / (sxx * syy).sqrt()
    }

    #[test]
    fn direction_numbers_match_reference_recurrence() {
        // Independent formulation: integer m_k recurrence of Bratley-Fox /
        // Joe-Kuo, m_k = 2a_1 m_{k-1} ^ ... ^ 2^{s-1}a_{s-1} m_{k-s+1}
        //                ^ 2^s m_{k-s} ^ m_{k-s},  v_k = m_k 2^{32-k}.
        for d in 0..MAX_DIMENSIONS {
            // Dimension 0 (van der Corput) has m_k = 1 for all k.
            let (s, a, init) = if d == 0 { (32, 0, [1; 6]) } else { JOE_KUO[d - 1] };
            let s = s as usize;
            let mut m = vec![0u64; 33]; // 1-based
            for k in 1..=32 {
                m[k] = if d == 0 {
                    1
                } else if k <= s {
                    init[k - 1] as u64
                } else {
                    let mut v = m[k - s] ^ (m[k - s] << s);
                    for j in 1..s {
                        if (a >> (s - 1 - j)) & 1 == 1 {
                            v ^= m[k - j] << j;
                        }
                    }
                    v
                };
                assert!(m[k] % 2 == 1 && m[k] < 1 << k, "dim {d} m_{k} = {}", m[k]);
                assert_eq!(SOBOL_MATRICES[d][k - 1] as u64, m[k] << (32 - k), "dim {d} k {k}");
            }
        }
        // Cross-check against an independently generated table (pbrt-v4's
        // SobolMatrices32, L. Gruenschloss, same Joe-Kuo file): column 31
        // depends on every polynomial coefficient and initial m value.
        const LAST_COLUMN: [u32; MAX_DIMENSIONS] = [
            0x0000_0001,
            0xffff_ffff,
            0xc500_5555,
            0x5005_0093,
            0xb00d_db9d,
            0x40bb_bbbb,
            0xc010_4477,
            0x8763_9641,
            0x8435_0611,
            0x82ff_78f1,
            0x81d0_0a2d,
            0x8723_9795,
            0x8247_06d7,
            0x2610_00a3,
            0xd91d_919d,
            0x72c4_d755,
        ];
        for d in 0..MAX_DIMENSIONS {
            assert_eq!(SOBOL_MATRICES[d][31], LAST_COLUMN[d], "dim {d} column 31");
        }
        // Spot values: dimension 1 (polynomial x+1) has m = 1, 3, 5, 15.
        assert_eq!(&SOBOL_MATRICES[1][..4], &[0x8000_0000, 0xc000_0000, 0xa000_0000, 0xf000_0000]);
        assert_eq!(SOBOL_MATRICES[0][31], 1);
    }

    #[test]
    fn first_points_match_known_values() {
        // Natural-order Sobol' points (Gray-code order in SciPy differs only by
        // a permutation of indices within blocks).
        let expect = [
            [0.0, 0.5, 0.25, 0.75, 0.125, 0.625, 0.375, 0.875],
            [0.0, 0.5, 0.75, 0.25, 0.625, 0.125, 0.375, 0.875],
            [0.0, 0.5, 0.75, 0.25, 0.375, 0.875, 0.625, 0.125],
        ];
        for (d, row) in expect.iter().enumerate() {
            for (i, &e) in row.iter().enumerate() {
                let got = to_unit_f64(sobol_u32(i as u32, d));
                assert_eq!(got, e, "dim {d} index {i}");
            }
        }
        // Dimension 0 is van der Corput: bit reversal of the index.
        let mut rng = Pcg64::seed_from_u64(7);
        for _ in 0..1000 {
            let i: u32 = rng.random();
            assert_eq!(sobol_u32(i, 0), i.reverse_bits());
        }
    }

    #[test]
    fn byte_tables_give_the_points_of_the_definition() {
        let mut rng = Pcg64::seed_from_u64(11);
        for d in 0..MAX_DIMENSIONS {
            let edges = [0u32, 1, 255, 256, 0xffff, 0x0100_0000, u32::MAX];
            for i in edges.into_iter().chain((0..2000).map(|_| rng.random())) {
                assert_eq!(sobol_u32(i, d), sobol_u32_by_bits(i, d), "dim {d} index {i:#x}");
            }
        }
    }

    #[test]
    fn every_dimension_is_a_0m1_sequence() {
        for d in 0..MAX_DIMENSIONS {
            for m in 1..=16u32 {
                let raw: Vec<u32> = (0..1u32 << m).map(|i| sobol_u32(i, d)).collect();
                assert!(is_0m1_net(&raw, m), "dim {d}, first 2^{m} points");
            }
            // Aligned later blocks too (the (0,1)-sequence property).
            for m in [3u32, 8, 12] {
                for block in [1u32, 5, 1000] {
                    let start = block << m;
                    let raw: Vec<u32> = (start..start + (1 << m)).map(|i| sobol_u32(i, d)).collect();
                    assert!(is_0m1_net(&raw, m), "dim {d}, block {block} of 2^{m}");
                }
            }
            // Scrambled and shuffled versions keep it.
            for seed in [1u32, 0xdead_beef] {
                for m in [4u32, 10, 16] {
                    let o: Vec<u32> = (0..1u32 << m).map(|i| owen_sobol(i, d, seed)).collect();
                    let s: Vec<u32> = (0..1u32 << m).map(|i| shuffled_owen_sobol(i, d, seed)).collect();
                    assert!(is_0m1_net(&o, m) && is_0m1_net(&s, m), "dim {d} seed {seed} m {m}");
                }
            }
        }
    }

    #[test]
    fn dims_0_1_are_0m2_nets_raw_scrambled_shuffled() {
        let max_m = 16;
        let n = 1u32 << max_m;
        let raw: Vec<(u32, u32)> = (0..n).map(|i| (sobol_u32(i, 0), sobol_u32(i, 1))).collect();
        for m in 0..=max_m {
            assert!(is_tm2_net(&raw[..1 << m], m, 0), "raw m={m}");
        }
        for seed in [0u32, 42, 0x9e37_79b9] {
            let owen: Vec<_> = (0..n).map(|i| (owen_sobol(i, 0, seed), owen_sobol(i, 1, seed))).collect();
            let shuf: Vec<_> =
                (0..n).map(|i| (shuffled_owen_sobol(i, 0, seed), shuffled_owen_sobol(i, 1, seed))).collect();
            for m in 0..=max_m {
                assert!(is_tm2_net(&owen[..1 << m], m, 0), "owen seed {seed} m={m}");
                assert!(is_tm2_net(&shuf[..1 << m], m, 0), "shuffled seed {seed} m={m}");
            }
            // Scrambling must actually move the points.
            assert!(owen.iter().zip(&raw).filter(|(a, b)| a == b).count() < 16);
        }
        // The sampler's points are (0,m,2)-nets in dimensions 0 and 1 as well.
        for seed in 0..3 {
            let s = SobolSampler::new(seed);
            let pts: Vec<(u32, u32)> = (0..1u32 << 12)
                .map(|i| {
                    let [x, y] = s.point::<2>(i);
                    ((x * 4_294_967_296.0) as u32, (y * 4_294_967_296.0) as u32)
                })
                .collect();
            assert!(is_tm2_net(&pts, 12, 0), "sampler seed {seed}");
        }
    }

    /// Observed t-values of the first 2^m points, m = 0..=16, for the 2D
    /// projections a 6D photon-plane point uses. (0,1) is a (0,2)-sequence;
    /// (2,3) has t <= 2 and (4,5) t <= 3 for m <= 16 (a square 2^(m/2) grid
    /// then holds at most 2 points per cell). Identical under Owen scrambling.
    const PAIRS: [((usize, usize), [u32; 17]); 3] = [
        ((0, 1), [0; 17]),
        ((2, 3), [0, 0, 1, 2, 0, 1, 1, 1, 1, 1, 1, 2, 2, 2, 2, 1, 2]),
        ((4, 5), [0, 0, 1, 2, 0, 1, 1, 2, 3, 2, 1, 2, 2, 2, 3, 2, 2]),
    ];

    #[test]
    fn pair_t_values_raw_and_scrambled() {
        let n = 1u32 << 16;
        for &((dx, dy), expected) in &PAIRS {
            let raw: Vec<_> = (0..n).map(|i| (sobol_u32(i, dx), sobol_u32(i, dy))).collect();
            let owen: Vec<_> = (0..n).map(|i| (owen_sobol(i, dx, 11), owen_sobol(i, dy, 11))).collect();
            let mut ts = [0u32; 17];
            let mut grid_max = Vec::new();
            for m in 0..=16u32 {
                let (r, o) = (&raw[..1 << m], &owen[..1 << m]);
                ts[m as usize] = t_value(r, m);
                assert_eq!(t_value(o, m), ts[m as usize], "pair ({dx},{dy}) m={m}: scrambling changed t");
                if m % 2 == 0 {
                    // 2^(m/2) x 2^(m/2) grid: max count per cell (1 = perfect).
                    let h = m / 2;
                    for pts in [r, o] {
                        let mut c = vec![0u32; 1 << m];
                        for &(x, y) in pts {
                            c[((top(x, h) << h) | top(y, h)) as usize] += 1;
                        }
                        let mx = *c.iter().max().unwrap();
                        assert!(mx <= 1 << ts[m as usize], "pair ({dx},{dy}) m={m} grid max {mx}");
                        if pts.as_ptr() == r.as_ptr() {
                            grid_max.push(mx);
                        }
                    }
                }
            }
            println!("pair ({dx},{dy}): t(m=0..16) = {ts:?}, square-grid max count (m even) = {grid_max:?}");
            assert_eq!(ts, expected, "pair ({dx},{dy}) t-values");
        }
    }

    #[test]
    fn nested_scramble_is_prefix_preserving_bijection() {
        let mut rng = Pcg64::seed_from_u64(99);
        for _ in 0..20 {
            let seed: u32 = rng.random();
            // Bijection: 2^16 distinct inputs (random high halves) stay distinct.
            let mut outs: Vec<u32> = (0..1u32 << 16)
                .map(|i| nested_uniform_scramble((i << 16) | (rng.random::<u32>() & 0xffff), seed))
                .collect();
            outs.sort_unstable();
            outs.dedup();
            assert_eq!(outs.len(), 1 << 16);
            // Nested: a shared k-bit prefix stays a shared k-bit prefix.
            for _ in 0..2000 {
                let x: u32 = rng.random();
                let k = rng.random_range(0..32u32);
                let mask = if k == 0 { 0 } else { !0u32 << (32 - k) };
                let y = (x & mask) | (rng.random::<u32>() & !mask);
                let (sx, sy) = (nested_uniform_scramble(x, seed), nested_uniform_scramble(y, seed));
                assert_eq!(sx & mask, sy & mask);
                if x != y {
                    assert_ne!(sx, sy);
                }
            }
        }
        assert_ne!(nested_uniform_scramble(0, 1), nested_uniform_scramble(0, 2));
    }

    #[test]
    fn scrambled_values_uniform_chi_square() {
        // (a) Per sequence: 2^16 points in 64 bins per dimension. A scrambled
        // (0,1)-sequence gives exactly 1024 per bin (chi2 = 0); 50000 points
        // (not a power of two) must also be far below the threshold.
        for d in 0..MAX_DIMENSIONS {
            for n in [1u32 << 16, 50_000] {
                let mut c = [0u64; 64];
                for i in 0..n {
                    c[top(owen_sobol(i, d, 1234), 6) as usize] += 1;
                }
                let chi2 = chi_square::uniform_statistic(&c);
                assert!(chi2 < chi_square::critical(63), "dim {d} n {n} chi2 {chi2}");
                if n == 1 << 16 {
                    assert_eq!(chi2, 0.0);
                }
            }
        }
        // (b) Randomisation: a fixed point scrambled with 2^16 seeds must be
        // uniform over seeds. This tests the hash (index 0 is the raw origin).
        let mut worst: f64 = 0.0;
        for d in [0usize, 1, 5, 15] {
            for index in [0u32, 1, 777, 1 << 20] {
                let mut c = [0u64; 64];
                for s in 0..1u32 << 16 {
                    c[top(owen_sobol(index, d, s), 6) as usize] += 1;
                }
                let chi2 = chi_square::uniform_statistic(&c);
                worst = worst.max(chi2);
                assert!(chi2 < chi_square::critical(63), "dim {d} index {index} chi2 over seeds {chi2}");
            }
        }
        println!("worst chi2 over seeds (63 dof): {worst:.1}");
    }

    #[test]
    fn seeds_give_uncorrelated_sequences() {
        let n = 4096u32;
        let bound = 4.0 / (n as f64).sqrt();
        let mut rng = Pcg64::seed_from_u64(2024);
        let mut worst: f64 = 0.0;
        for _ in 0..20 {
            let (a, b) = (SobolSampler::new(rng.random()), SobolSampler::new(rng.random()));
            let pa: Vec<[f64; 6]> = (0..n).map(|i| a.point::<6>(i)).collect();
            let pb: Vec<[f64; 6]> = (0..n).map(|i| b.point::<6>(i)).collect();
            for d in 0..6 {
                let xa: Vec<f64> = pa.iter().map(|p| p[d]).collect();
                let xb: Vec<f64> = pb.iter().map(|p| p[d]).collect();
                let r = pearson(&xa, &xb);
                worst = worst.max(r.abs());
                assert!(r.abs() < bound, "dim {d}: r = {r}");
                let same = xa.iter().zip(&xb).filter(|(x, y)| x == y).count();
                assert!(same < 4, "{same} identical values");
            }
        }
        println!("worst |r| * sqrt(n) = {:.2} (bound 4)", worst * (n as f64).sqrt());
    }

    #[test]
    fn unshuffled_owen_same_dim_is_correlated_across_seeds() {
        // Documents the caveat on `owen_sobol`: without the index shuffle two
        // seeds scramble the same raw value, so index-by-index values are
        // strongly (anti)correlated. This is why the sampler shuffles.
        let n = 4096u32;
        let mut rng = Pcg64::seed_from_u64(5);
        let mut min_abs: f64 = 1.0;
        for _ in 0..20 {
            let (sa, sb): (u32, u32) = (rng.random(), rng.random());
            let xa: Vec<f64> = (0..n).map(|i| to_unit_f64(owen_sobol(i, 2, sa))).collect();
            let xb: Vec<f64> = (0..n).map(|i| to_unit_f64(owen_sobol(i, 2, sb))).collect();
            min_abs = min_abs.min(pearson(&xa, &xb).abs());
        }
        println!("unshuffled: min |r| over 20 seed pairs = {min_abs:.3}");
        assert!(min_abs > 0.4);
    }

    #[test]
    fn large_indices() {
        let s = SobolSampler::new(77);
        for index in [1u32 << 27, (1 << 27) + 12345, 0x8000_0000, u32::MAX - 1, u32::MAX] {
            for d in 0..MAX_DIMENSIONS {
                for v in [sobol_u32(index, d), owen_sobol(index, d, 9), shuffled_owen_sobol(index, d, 9)] {
                    let u = to_unit_f64(v);
                    assert!((0.0..1.0).contains(&u));
                }
            }
            for u in s.point::<16>(index) {
                assert!((0.0..1.0).contains(&u), "{u}");
            }
        }
        assert!(to_unit_f64(u32::MAX) < 1.0);
        for d in 0..MAX_DIMENSIONS {
            assert_eq!(sobol_u32(1 << 27, d), SOBOL_MATRICES[d][27]);
            assert_ne!(sobol_u32(u32::MAX - 1, d), sobol_u32(u32::MAX, d));
        }
        // Aligned blocks at 2^27 and at the very top are still nets.
        for start in [1u32 << 27, u32::MAX - 4095] {
            let idx = || start..=start + 4095;
            for d in 0..MAX_DIMENSIONS {
                let v: Vec<u32> = idx().map(|i| owen_sobol(i, d, 3)).collect();
                assert!(is_0m1_net(&v, 12), "dim {d} block at {start}");
            }
            let p: Vec<_> = idx().map(|i| (sobol_u32(i, 0), sobol_u32(i, 1))).collect();
            assert!(is_tm2_net(&p, 12, 0));
        }
    }

    /// RMSE over 64 seeds of a 2^12-point estimate of `f` vs. `exact`.
    fn rmse(exact: f64, mut est: impl FnMut(u64) -> f64) -> f64 {
        let se: f64 = (0..64u64).map(|s| (est(s) - exact).powi(2)).sum();
        (se / 64.0).sqrt()
    }

    #[test]
    fn integration_beats_random_sampling() {
        let n = 1u32 << 12;
        // 2D: f = x e^{xy}, integral over the unit square = e - 2.
        let f2 = |p: &[f64; 2]| p[0] * (p[0] * p[1]).exp();
        let exact2 = std::f64::consts::E - 2.0;
        let qmc = rmse(exact2, |s| {
            let smp = SobolSampler::new(s);
            (0..n).map(|i| f2(&smp.point::<2>(i))).sum::<f64>() / n as f64
        });
        let mc = rmse(exact2, |s| {
            let mut rng = Pcg64::seed_from_u64(s);
            (0..n).map(|_| f2(&[rng.random(), rng.random()])).sum::<f64>() / n as f64
        });
        // 6D: f = exp(sum c_k x_k), integral = prod (e^{c_k} - 1) / c_k.
        let c = [0.9, -0.7, 0.5, 1.1, -0.3, 0.6];
        let f6 = move |p: &[f64; 6]| (0..6).map(|k| c[k] * p[k]).sum::<f64>().exp();
        let exact6: f64 = c.iter().map(|&ck: &f64| (ck.exp() - 1.0) / ck).product();
        let qmc6 = rmse(exact6, |s| {
            let smp = SobolSampler::new(s);
            (0..n).map(|i| f6(&smp.point::<6>(i))).sum::<f64>() / n as f64
        });
        let mc6 = rmse(exact6, |s| {
            let mut rng = Pcg64::seed_from_u64(s + 1000);
            (0..n).map(|_| f6(&std::array::from_fn(|_| rng.random()))).sum::<f64>() / n as f64
        });
        println!(
            "2D RMSE: owen-sobol {qmc:.3e}, random {mc:.3e} (x{:.0}); 6D: {qmc6:.3e} vs {mc6:.3e} (x{:.0})",
            mc / qmc,
            mc6 / qmc6
        );
        assert!(mc / qmc >= 10.0);
        assert!(mc6 / qmc6 >= 10.0);
    }

    #[test]
    fn sampler_is_consistent_and_deterministic() {
        let s = SobolSampler::new(0xfeed);
        let seed = s.scramble_seed();
        for i in [0u32, 1, 2, 1000, 123_456] {
            let p = s.point::<16>(i);
            for d in 0..16 {
                assert_eq!(p[d], to_unit_f64(shuffled_owen_sobol(i, d, seed)));
            }
            assert_eq!(p, SobolSampler::new(0xfeed).point::<16>(i));
            assert_eq!(&p[..6], &s.point::<6>(i)[..]);
        }
        assert_ne!(s.point::<2>(5), SobolSampler::new(0xfeee).point::<2>(5));
    }
}
