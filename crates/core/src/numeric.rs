//! Numerics shared by the f64 sampling path and the f32 gathering path: the scalar arithmetic
//! that generic routines need ([`Real`]), three-vectors as arrays for them, and a branch-free
//! exponential for the gathering kernels.

use crate::simd::Lanes;

/// The arithmetic that the generic geometry routines (chords, ray-rectangle crossings) need, so
/// that one routine serves the f64 sampling path and the f32 gathering path.
pub trait Real:
    Copy
    + PartialOrd
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
{
    const ZERO: Self;
    /// IEEE minNum: a NaN argument is ignored (used on purpose, see
    /// [`crate::light::chord_extent`]).
    fn min_num(self, other: Self) -> Self;
}

/// The gathering path (f32) takes the cheaper compare-and-select, one vector instruction: it
/// returns `other` when either is NaN. The NaN case (0 * inf, a vertex exactly on an edge with
/// a chord exactly along an axis) has probability zero; [`crate::light::chord_extent`] then
/// clamps NaN to 0, so a width is never NaN.
impl Real for f32 {
    const ZERO: f32 = 0.0;
    #[inline(always)]
    fn min_num(self, other: f32) -> f32 {
        if self < other { self } else { other }
    }
}

impl Real for f64 {
    const ZERO: f64 = 0.0;
    #[inline(always)]
    fn min_num(self, other: f64) -> f64 {
        self.min(other)
    }
}

/// A three-vector as the generic routines see it.
pub type V3<T> = [T; 3];

/// `a . b`, summed x, y, z in that order (as glam does, so results are bit-identical to it).
#[inline(always)]
pub fn dot<T: Real>(a: V3<T>, b: V3<T>) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// exp(x) for x <= 0 in f32, branch-free so that loops over pixels vectorise: x = k ln 2 + r
/// with k = round(x / ln 2) (Cody-Waite, |r| <= ln 2 / 2), exp(r) by its Taylor series to r^7
/// (truncation below 6e-9 relative, evaluated by Estrin's scheme in fused multiply-adds), and
/// 2^k written into the exponent bits. Below -87 (where 2^k would leave the normal range) the
/// result is 0, as it is for -inf. Within 2e-7 relative of exp (tested). The argument is not
/// clamped (the gathering's exponents are <= 0 on every hit, and a lane that misses is
/// discarded): above 0 the result is exp(x) until 2^k overflows near 88, and NaN gives NaN.
#[inline(always)]
pub fn exp_f32(x: f32) -> f32 {
    exp_lanes::<1, f32>(x)
}

/// [`exp_f32`] lane by lane, for any width ([`Lanes`]): the same operations.
#[inline(always)]
pub fn exp_lanes<const L: usize, V: Lanes<L>>(x: V) -> V {
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    // Adding and subtracting 1.5 * 2^23 rounds to the nearest integer without a call.
    const ROUND: f32 = 12_582_912.0;
    let s = V::splat;
    // No clamp of x (two operations of a hit's ninety): below -87 the select at the end gives 0
    // whatever the lanes computed, and above 0 is outside the domain.
    let xc = x;
    // xc log2(e) + 1.5 * 2^23 holds k in its low mantissa bits: the integer is read from there
    // (no float-to-int conversion, which would not vectorise).
    let shifted = xc.mul_add(s(std::f32::consts::LOG2_E), s(ROUND));
    let k = shifted - s(ROUND);
    let r = k.mul_add(s(-LN2_LO), k.mul_add(s(-LN2_HI), xc));
    // The degree-7 Taylor polynomial by Estrin's scheme in fused multiply-adds: the same terms
    // as Horner's rule in a dependency chain of 4 operations instead of 14, so vector lanes wait
    // less.
    let (r2, r4) = (r * r, (r * r) * (r * r));
    let low = r2.mul_add(r.mul_add(s(1.0 / 6.0), s(0.5)), s(1.0) + r);
    let high = r2.mul_add(r.mul_add(s(1.0 / 5040.0), s(1.0 / 720.0)), r.mul_add(s(1.0 / 120.0), s(1.0 / 24.0)));
    let p = r4.mul_add(high, low);
    V::select(x.lt(s(-87.0)), s(0.0), p * shifted.exponent_scale())
}

/// atan2(y, x) in f32, branch-free so that loops over lanes vectorise: the octant reduction to
/// t = min(|x|, |y|) / max(|x|, |y|) in [0, 1], atan(t) = t P(t^2) with P a degree-8 minimax fit
/// (numpy, Lawson's iteration), then the octant restored. Within 4e-7 of the true angle (tested:
/// the fit, the f32 roundings of pi and pi/2 and of the result near pi);
/// atan2(0, 0) = 0, and a zero y of either sign gives 0 or pi.
#[inline(always)]
pub fn atan2_f32(y: f32, x: f32) -> f32 {
    atan2_lanes::<1, f32>(y, x)
}

/// [`atan2_f32`] lane by lane, for any width ([`Lanes`]): the same operations.
#[inline(always)]
pub fn atan2_lanes<const L: usize, V: Lanes<L>>(y: V, x: V) -> V {
    use std::f32::consts::{FRAC_PI_2, PI};
    let (s, zero) = (V::splat, V::splat(0.0));
    let (ax, ay) = (x.abs(), y.abs());
    let steep = ay.gt(ax);
    let (small, large) = (V::select(steep, ax, ay), V::select(steep, ay, ax));
    let t = V::select(large.gt(zero), small / large, zero);
    let a = atan_unit_lanes::<L, V>(t);
    let a = V::select(steep, s(FRAC_PI_2) - a, a);
    let a = V::select(x.lt(zero), s(PI) - a, a);
    V::select(y.lt(zero), a.neg(), a)
}

/// atan(t) for t in [0, 1], lane by lane: the polynomial of [`atan2_lanes`] (the same bits).
#[inline(always)]
pub fn atan_unit_lanes<const L: usize, V: Lanes<L>>(t: V) -> V {
    const C: [f32; 9] = [
        1.0,
        -0.333_330_93,
        0.199_930_55,
        -0.142_071_34,
        0.106_546_79,
        -0.075_336_78,
        0.043_039_385,
        -0.016_283_017,
        0.002_903_554,
    ];
    let s = V::splat;
    let t2 = t * t;
    let (t4, t8) = (t2 * t2, (t2 * t2) * (t2 * t2));
    // Estrin's scheme in fused multiply-adds, for a short dependency chain and few operations.
    let p01 = t2.mul_add(s(C[1]), s(C[0]));
    let p23 = t2.mul_add(s(C[3]), s(C[2]));
    let p45 = t2.mul_add(s(C[5]), s(C[4]));
    let p67 = t2.mul_add(s(C[7]), s(C[6]));
    let p = t8.mul_add(t8.mul_add(s(C[8]), t4.mul_add(p67, p45)), t4.mul_add(p23, p01));
    t * p
}

/// ln(x) in f32 for x >= 0, branch-free: x = m 2^e with m in [sqrt(1/2), sqrt(2)), f = m - 1
/// (exact), ln(1 + f) = f - f^2 / 2 + f^3 P(f) with P a degree-6 minimax fit, plus e ln 2.
/// Within 1.5e-7 relative (tested) for normal x; ln(0) (and a subnormal) gives about -88, and
/// infinity, NaN or a negative x some other finite value (tested), so that a factor of zero in
/// front of it still gives zero.
#[inline(always)]
pub fn ln_f32(x: f32) -> f32 {
    ln_lanes::<1, f32>(x)
}

/// [`ln_f32`] lane by lane, for any width ([`Lanes`]): the same operations.
#[inline(always)]
pub fn ln_lanes<const L: usize, V: Lanes<L>>(x: V) -> V {
    const C: [f32; 7] =
        [0.333_339_1, -0.250_013_38, 0.199_630_62, -0.165_775_8, 0.149_147_76, -0.142_675_19, 0.087_004_56];
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    let s = V::splat;
    let (m, e) = x.split_exponent();
    let big = m.gt(s(std::f32::consts::SQRT_2));
    let (m, e) = (V::select(big, m * s(0.5), m), V::select(big, e + s(1.0), e));
    let f = m - s(1.0);
    let (f2, f4) = (f * f, (f * f) * (f * f));
    // In fused multiply-adds: Estrin's scheme, then the terms in the same order.
    let low = f2.mul_add(f.mul_add(s(C[3]), s(C[2])), f.mul_add(s(C[1]), s(C[0])));
    let high = f2.mul_add(s(C[6]), f.mul_add(s(C[5]), s(C[4])));
    let p = f4.mul_add(high, low);
    let sum = (f2 * f).mul_add(p, f2.mul_add(s(-0.5), f));
    e.mul_add(s(LN2_HI), e.mul_add(s(LN2_LO), sum))
}

/// ln(1 + x) in f32 for x > -1, accurate also for tiny x: ln(u) of u = 1 + x plus the rounding
/// error of u, x - (u - 1) (exact), which is what ln(1 + x) - ln(u) is to first order. Within
/// 3e-7 relative (tested).
#[inline(always)]
pub fn ln_1p_f32(x: f32) -> f32 {
    let u = 1.0 + x;
    ln_f32(u) + (x - (u - 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_f32_is_accurate_and_vanishes_far_out() {
        let mut worst = 0.0f64;
        for i in 0..=200_000 {
            let x = -87.0 * i as f64 / 200_000.0;
            let (got, want) = (exp_f32(x as f32) as f64, (x as f32 as f64).exp());
            worst = worst.max((got - want).abs() / want);
        }
        assert!(worst < 2e-7, "largest relative error {worst:e}");
        assert_eq!(exp_f32(0.0), 1.0);
        // Unclamped, far below -87 the lanes compute garbage that the final select replaces.
        for x in [-87.001f32, -88.0, -100.0, -1e4, -1e30, f32::MIN, f32::NEG_INFINITY] {
            assert_eq!(exp_f32(x), 0.0, "exp({x})");
        }
        assert!(exp_f32(f32::NAN).is_nan());
    }

    #[test]
    fn atan2_ln_and_ln_1p_are_accurate() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(9);
        let (mut worst_atan, mut worst_ln, mut worst_ln_1p) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..1_000_000 {
            let scale = 10f32.powi(rng.random_range(-20..20));
            let (y, x) = (rng.random_range(-1.0f32..1.0) * scale, rng.random_range(-1.0f32..1.0) * scale);
            let want = (y as f64).atan2(x as f64);
            let got = atan2_f32(y, x) as f64;
            // A zero y gives 0 or pi whatever its sign: compare modulo 2 pi.
            let d = (got - want).abs();
            let diff = d.min((d - 2.0 * std::f64::consts::PI).abs());
            worst_atan = worst_atan.max(diff);
            let v = rng.random_range(0.0f32..1.0) * 10f32.powi(rng.random_range(-37..37));
            if v.is_normal() {
                let want = (v as f64).ln();
                worst_ln = worst_ln.max((ln_f32(v) as f64 - want).abs() / want.abs().max(1.0));
            }
            let t = rng.random_range(-1.0f32..1.0) * 10f32.powi(rng.random_range(-30..2));
            if t > -1.0 {
                let want = (t as f64).ln_1p();
                worst_ln_1p = worst_ln_1p.max((ln_1p_f32(t) as f64 - want).abs() / want.abs().max(f64::MIN_POSITIVE));
            }
        }
        assert!(worst_atan < 4e-7, "atan2: largest error {worst_atan:e}");
        assert!(worst_ln < 1.5e-7, "ln: largest relative error {worst_ln:e}");
        assert!(worst_ln_1p < 3e-7, "ln_1p: largest relative error {worst_ln_1p:e}");
        assert_eq!(atan2_f32(0.0, 0.0), 0.0);
        assert_eq!(atan2_f32(0.0, -1.0), std::f32::consts::PI);
        assert!(ln_f32(0.0).is_finite() && ln_f32(0.0) < -87.0);
        // Finite for any input (cmis-exact's zero of det relies on it where z = 0: a factor of
        // zero in front still gives zero).
        for x in [f32::INFINITY, f32::NAN, -1.0, f32::MAX, f32::MIN_POSITIVE / 8.0] {
            assert!(ln_f32(x).is_finite(), "ln_f32({x}) = {}", ln_f32(x));
        }
        println!("atan2 {worst_atan:e}, ln {worst_ln:e}, ln_1p {worst_ln_1p:e}");
    }

    #[test]
    fn dot_sums_like_glam() {
        let (a, b) = (glam::Vec3::new(0.1, -2.5, 3.7), glam::Vec3::new(1e-3, 7.0, -0.3));
        assert_eq!(dot(a.to_array(), b.to_array()), a.dot(b));
        let (a, b) = (glam::DVec3::new(0.1, -2.5, 3.7), glam::DVec3::new(1e-3, 7.0, -0.3));
        assert_eq!(dot(a.to_array(), b.to_array()), a.dot(b));
    }
}
