//! Numerics shared by the f64 sampling path and the f32 gathering path: the scalar arithmetic
//! that generic routines need ([`Real`]), three-vectors as arrays for them, and a branch-free
//! exponential for the gathering kernels.

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
/// (truncation below 6e-9 relative, evaluated by Estrin's scheme), and 2^k written into the exponent bits. Below -87 (where
/// 2^k would leave the normal range) the result is 0. Within 2e-7 relative of exp (tested).
#[inline(always)]
#[allow(clippy::manual_clamp)] // clamp has a panic path, which would stop vectorisation
pub fn exp_f32(x: f32) -> f32 {
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    // Adding and subtracting 1.5 * 2^23 rounds to the nearest integer without a call.
    const ROUND: f32 = 12_582_912.0;
    let xc = x.max(-87.0).min(0.0);
    // xc log2(e) + 1.5 * 2^23 holds k in its low mantissa bits: the integer is read from there
    // (no float-to-int conversion, which would not vectorise).
    let shifted = xc * std::f32::consts::LOG2_E + ROUND;
    let k = shifted - ROUND;
    let r = (xc - k * LN2_HI) - k * LN2_LO;
    // The degree-7 Taylor polynomial by Estrin's scheme: the same terms as Horner's rule in
    // a dependency chain of 6 operations instead of 14, so vector lanes wait less.
    let (r2, r4) = (r * r, (r * r) * (r * r));
    let low = (1.0 + r) + r2 * (0.5 + r * (1.0 / 6.0));
    let high = (1.0 / 24.0 + r * (1.0 / 120.0)) + r2 * (1.0 / 720.0 + r * (1.0 / 5040.0));
    let p = low + r4 * high;
    let scale = f32::from_bits(shifted.to_bits().wrapping_sub(0x4B40_0000 - 127) << 23);
    if x < -87.0 { 0.0 } else { p * scale }
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
        assert_eq!(exp_f32(-100.0), 0.0);
        assert_eq!(exp_f32(f32::NEG_INFINITY), 0.0);
    }

    #[test]
    fn dot_sums_like_glam() {
        let (a, b) = (glam::Vec3::new(0.1, -2.5, 3.7), glam::Vec3::new(1e-3, 7.0, -0.3));
        assert_eq!(dot(a.to_array(), b.to_array()), a.dot(b));
        let (a, b) = (glam::DVec3::new(0.1, -2.5, 3.7), glam::DVec3::new(1e-3, 7.0, -0.3));
        assert_eq!(dot(a.to_array(), b.to_array()), a.dot(b));
    }
}
