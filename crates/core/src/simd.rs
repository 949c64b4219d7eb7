//! Vectors of f32 lanes: the one type the per-hit arithmetic is written against, for every
//! width (as Mitsuba 3's Dr.Jit arrays). [`Lanes`] is implemented by `f32` (one lane: the
//! per-hit paths and the tests), by `Avx512`, `Ymm` and `Avx2` (16 lanes in one AVX-512
//! register, 8 in one AVX2 register, 16 in two: [`Pair`]; the intrinsics written out, and the
//! types private to the crate, since their methods run instructions only the kernels compiled
//! for them may) and by [`Portable`] (N lanes as an array, whatever the compiler makes of the
//! loops for the baseline target).
//!
//! Every operation is exactly rounded IEEE arithmetic or a compare-and-select with the same
//! NaN rule in every implementation (`min(a, b)` is `if a < b { a } else { b }`), and nothing
//! is fused, so a lane gives the same bits whichever type carries it.
//!
//! Why intrinsics: the lane loops of [`Portable`], vectorised by the compiler, were 20% slower
//! than the same operations written out for AVX-512 on `unweighted` (the vectoriser's choices of
//! registers and spills moved by 10% either way with edits that did not change the arithmetic).
//! The intrinsics run only inside the kernels compiled for their features
//! ([`crate::kernel`]): every method is `#[inline(always)]`, so it is inlined there first and
//! its intrinsics then with it.

#![allow(clippy::needless_range_loop)]

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Sub};

/// The result of comparing two [`Lanes`], lane by lane.
pub trait Mask: Copy + BitAnd<Output = Self> + BitOr<Output = Self> {
    /// Whether any lane is set.
    fn any(self) -> bool;
    /// How many lanes are set.
    fn count(self) -> u32;
    /// The lanes set in `self` and not in `other`.
    fn and_not(self, other: Self) -> Self;
}

/// `L` f32 lanes and the operations the per-hit arithmetic needs.
pub trait Lanes<const L: usize>:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
    type Mask: Mask;
    fn splat(v: f32) -> Self;
    fn load(a: &[f32; L]) -> Self;
    fn store(self, a: &mut [f32; L]);
    fn from_array(a: [f32; L]) -> Self {
        Self::load(&a)
    }
    fn to_array(self) -> [f32; L] {
        let mut a = [0.0; L];
        self.store(&mut a);
        a
    }
    fn lt(self, o: Self) -> Self::Mask;
    fn le(self, o: Self) -> Self::Mask;
    fn gt(self, o: Self) -> Self::Mask;
    fn ge(self, o: Self) -> Self::Mask;
    /// `a` where `m` is set, else `b`.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    /// `if self < o { self } else { o }`, lane by lane.
    fn min(self, o: Self) -> Self;
    /// `if self > o { self } else { o }`, lane by lane.
    fn max(self, o: Self) -> Self;
    fn abs(self) -> Self;
    fn sqrt(self) -> Self;
    /// `from_bits((to_bits(self) - (0x4B40_0000 - 127)) << 23)`, wrapping: 2^k for a value that
    /// holds the integer k in its low mantissa bits (see [`crate::numeric::exp_f32`]).
    fn exponent_scale(self) -> Self;
    /// `x = m 2^e` of a positive normal x, as `(m, e)`: m in [1, 2) from the mantissa bits, the
    /// exponent's biased bits less 127 (the raw fields, whatever x is: see
    /// [`crate::numeric::ln_f32`]).
    fn split_exponent(self) -> (Self, Self);
    /// `-self` (the sign flipped: -0 for 0).
    fn neg(self) -> Self;
    /// `self * b + c` rounded once (a fused multiply-add): exactly specified, so every width
    /// gives the bits of one lane, `f32::mul_add` (a library call where the target lacks FMA).
    fn mul_add(self, b: Self, c: Self) -> Self;
    /// Whether each lane is finite (not infinite, not NaN).
    #[inline(always)]
    fn is_finite(self) -> Self::Mask {
        self.abs().lt(Self::splat(f32::INFINITY))
    }
}

impl Mask for bool {
    #[inline(always)]
    fn any(self) -> bool {
        self
    }
    #[inline(always)]
    fn count(self) -> u32 {
        self as u32
    }
    #[inline(always)]
    fn and_not(self, other: bool) -> bool {
        self & !other
    }
}

/// One lane: the per-hit paths.
impl Lanes<1> for f32 {
    type Mask = bool;
    #[inline(always)]
    fn splat(v: f32) -> f32 {
        v
    }
    #[inline(always)]
    fn load(a: &[f32; 1]) -> f32 {
        a[0]
    }
    #[inline(always)]
    fn store(self, a: &mut [f32; 1]) {
        a[0] = self;
    }
    #[inline(always)]
    fn lt(self, o: f32) -> bool {
        self < o
    }
    #[inline(always)]
    fn le(self, o: f32) -> bool {
        self <= o
    }
    #[inline(always)]
    fn gt(self, o: f32) -> bool {
        self > o
    }
    #[inline(always)]
    fn ge(self, o: f32) -> bool {
        self >= o
    }
    #[inline(always)]
    fn select(m: bool, a: f32, b: f32) -> f32 {
        if m { a } else { b }
    }
    #[inline(always)]
    fn min(self, o: f32) -> f32 {
        if self < o { self } else { o }
    }
    #[inline(always)]
    fn max(self, o: f32) -> f32 {
        if self > o { self } else { o }
    }
    #[inline(always)]
    fn abs(self) -> f32 {
        f32::abs(self)
    }
    #[inline(always)]
    fn sqrt(self) -> f32 {
        f32::sqrt(self)
    }
    #[inline(always)]
    fn exponent_scale(self) -> f32 {
        f32::from_bits(self.to_bits().wrapping_sub(0x4B40_0000 - 127) << 23)
    }
    #[inline(always)]
    fn split_exponent(self) -> (f32, f32) {
        let bits = self.to_bits();
        (f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000), (((bits >> 23) & 0xff) as i32 - 127) as f32)
    }
    #[inline(always)]
    fn neg(self) -> f32 {
        -self
    }
    #[inline(always)]
    fn mul_add(self, b: f32, c: f32) -> f32 {
        f32::mul_add(self, b, c)
    }
}

/// N lanes as an array: loops the compiler vectorises as it can (the portable kernel).
#[derive(Clone, Copy, Debug)]
pub struct Portable<const N: usize>(pub [f32; N]);

/// The mask of [`Portable`]: 0 or 1 per lane as u32 (a vector of bools is a vector of bytes,
/// which the loops would pack and unpack).
#[derive(Clone, Copy, Debug)]
pub struct PortableMask<const N: usize>(pub [u32; N]);

macro_rules! portable_binary {
    ($trait:ident, $method:ident, $op:tt) => {
        impl<const N: usize> $trait for Portable<N> {
            type Output = Portable<N>;
            #[inline(always)]
            fn $method(self, o: Portable<N>) -> Portable<N> {
                Portable(std::array::from_fn(|l| self.0[l] $op o.0[l]))
            }
        }
    };
}
portable_binary!(Add, add, +);
portable_binary!(Sub, sub, -);
portable_binary!(Mul, mul, *);
portable_binary!(Div, div, /);

impl<const N: usize> BitAnd for PortableMask<N> {
    type Output = PortableMask<N>;
    #[inline(always)]
    fn bitand(self, o: PortableMask<N>) -> PortableMask<N> {
        PortableMask(std::array::from_fn(|l| self.0[l] & o.0[l]))
    }
}
impl<const N: usize> BitOr for PortableMask<N> {
    type Output = PortableMask<N>;
    #[inline(always)]
    fn bitor(self, o: PortableMask<N>) -> PortableMask<N> {
        PortableMask(std::array::from_fn(|l| self.0[l] | o.0[l]))
    }
}
impl<const N: usize> Mask for PortableMask<N> {
    #[inline(always)]
    fn any(self) -> bool {
        self.0.iter().fold(0, |any, &m| any | m) != 0
    }
    #[inline(always)]
    fn count(self) -> u32 {
        self.0.iter().sum()
    }
    #[inline(always)]
    fn and_not(self, o: PortableMask<N>) -> PortableMask<N> {
        PortableMask(std::array::from_fn(|l| self.0[l] & (o.0[l] ^ 1)))
    }
}

impl<const N: usize> Portable<N> {
    #[inline(always)]
    fn compare(self, o: Portable<N>, f: impl Fn(f32, f32) -> bool) -> PortableMask<N> {
        PortableMask(std::array::from_fn(|l| f(self.0[l], o.0[l]) as u32))
    }
    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> Portable<N> {
        Portable(std::array::from_fn(|l| f(self.0[l])))
    }
}

impl<const N: usize> Lanes<N> for Portable<N> {
    type Mask = PortableMask<N>;
    #[inline(always)]
    fn splat(v: f32) -> Portable<N> {
        Portable([v; N])
    }
    #[inline(always)]
    fn load(a: &[f32; N]) -> Portable<N> {
        Portable(*a)
    }
    #[inline(always)]
    fn store(self, a: &mut [f32; N]) {
        *a = self.0;
    }
    #[inline(always)]
    fn lt(self, o: Portable<N>) -> PortableMask<N> {
        self.compare(o, |a, b| a < b)
    }
    #[inline(always)]
    fn le(self, o: Portable<N>) -> PortableMask<N> {
        self.compare(o, |a, b| a <= b)
    }
    #[inline(always)]
    fn gt(self, o: Portable<N>) -> PortableMask<N> {
        self.compare(o, |a, b| a > b)
    }
    #[inline(always)]
    fn ge(self, o: Portable<N>) -> PortableMask<N> {
        self.compare(o, |a, b| a >= b)
    }
    #[inline(always)]
    fn select(m: PortableMask<N>, a: Portable<N>, b: Portable<N>) -> Portable<N> {
        Portable(std::array::from_fn(|l| if m.0[l] != 0 { a.0[l] } else { b.0[l] }))
    }
    #[inline(always)]
    fn min(self, o: Portable<N>) -> Portable<N> {
        Portable(std::array::from_fn(|l| <f32 as Lanes<1>>::min(self.0[l], o.0[l])))
    }
    #[inline(always)]
    fn max(self, o: Portable<N>) -> Portable<N> {
        Portable(std::array::from_fn(|l| <f32 as Lanes<1>>::max(self.0[l], o.0[l])))
    }
    #[inline(always)]
    fn abs(self) -> Portable<N> {
        self.map(f32::abs)
    }
    #[inline(always)]
    fn sqrt(self) -> Portable<N> {
        self.map(f32::sqrt)
    }
    #[inline(always)]
    fn exponent_scale(self) -> Portable<N> {
        self.map(<f32 as Lanes<1>>::exponent_scale)
    }
    #[inline(always)]
    fn split_exponent(self) -> (Portable<N>, Portable<N>) {
        (self.map(|x| <f32 as Lanes<1>>::split_exponent(x).0), self.map(|x| <f32 as Lanes<1>>::split_exponent(x).1))
    }
    #[inline(always)]
    fn neg(self) -> Portable<N> {
        self.map(|x| -x)
    }
    #[inline(always)]
    fn mul_add(self, b: Portable<N>, c: Portable<N>) -> Portable<N> {
        Portable(std::array::from_fn(|l| self.0[l].mul_add(b.0[l], c.0[l])))
    }
}

/// 16 lanes as two halves of 8: every operation on both (AVX2's 16 lanes are two `Ymm`).
#[derive(Clone, Copy, Debug)]
pub struct Pair<V>(pub [V; 2]);

/// The mask of a [`Pair`].
#[derive(Clone, Copy, Debug)]
pub struct PairMask<M>(pub [M; 2]);

macro_rules! pair_binary {
    ($trait:ident, $method:ident) => {
        impl<V: Lanes<8>> $trait for Pair<V> {
            type Output = Pair<V>;
            #[inline(always)]
            fn $method(self, o: Pair<V>) -> Pair<V> {
                Pair([self.0[0].$method(o.0[0]), self.0[1].$method(o.0[1])])
            }
        }
    };
}
pair_binary!(Add, add);
pair_binary!(Sub, sub);
pair_binary!(Mul, mul);
pair_binary!(Div, div);

impl<M: Mask> BitAnd for PairMask<M> {
    type Output = PairMask<M>;
    #[inline(always)]
    fn bitand(self, o: PairMask<M>) -> PairMask<M> {
        PairMask([self.0[0] & o.0[0], self.0[1] & o.0[1]])
    }
}
impl<M: Mask> BitOr for PairMask<M> {
    type Output = PairMask<M>;
    #[inline(always)]
    fn bitor(self, o: PairMask<M>) -> PairMask<M> {
        PairMask([self.0[0] | o.0[0], self.0[1] | o.0[1]])
    }
}
impl<M: Mask> Mask for PairMask<M> {
    #[inline(always)]
    fn any(self) -> bool {
        (self.0[0] | self.0[1]).any()
    }
    #[inline(always)]
    fn count(self) -> u32 {
        self.0[0].count() + self.0[1].count()
    }
    #[inline(always)]
    fn and_not(self, o: PairMask<M>) -> PairMask<M> {
        PairMask([self.0[0].and_not(o.0[0]), self.0[1].and_not(o.0[1])])
    }
}

impl<V: Lanes<8>> Lanes<16> for Pair<V> {
    type Mask = PairMask<V::Mask>;
    #[inline(always)]
    fn splat(v: f32) -> Pair<V> {
        Pair([V::splat(v); 2])
    }
    #[inline(always)]
    fn load(a: &[f32; 16]) -> Pair<V> {
        let (lo, hi) = a.split_at(8);
        Pair([V::load(lo.try_into().unwrap()), V::load(hi.try_into().unwrap())])
    }
    #[inline(always)]
    fn store(self, a: &mut [f32; 16]) {
        let (lo, hi) = a.split_at_mut(8);
        self.0[0].store(lo.try_into().unwrap());
        self.0[1].store(hi.try_into().unwrap());
    }
    #[inline(always)]
    fn lt(self, o: Pair<V>) -> Self::Mask {
        PairMask([self.0[0].lt(o.0[0]), self.0[1].lt(o.0[1])])
    }
    #[inline(always)]
    fn le(self, o: Pair<V>) -> Self::Mask {
        PairMask([self.0[0].le(o.0[0]), self.0[1].le(o.0[1])])
    }
    #[inline(always)]
    fn gt(self, o: Pair<V>) -> Self::Mask {
        PairMask([self.0[0].gt(o.0[0]), self.0[1].gt(o.0[1])])
    }
    #[inline(always)]
    fn ge(self, o: Pair<V>) -> Self::Mask {
        PairMask([self.0[0].ge(o.0[0]), self.0[1].ge(o.0[1])])
    }
    #[inline(always)]
    fn select(m: Self::Mask, a: Pair<V>, b: Pair<V>) -> Pair<V> {
        Pair([V::select(m.0[0], a.0[0], b.0[0]), V::select(m.0[1], a.0[1], b.0[1])])
    }
    #[inline(always)]
    fn min(self, o: Pair<V>) -> Pair<V> {
        Pair([self.0[0].min(o.0[0]), self.0[1].min(o.0[1])])
    }
    #[inline(always)]
    fn max(self, o: Pair<V>) -> Pair<V> {
        Pair([self.0[0].max(o.0[0]), self.0[1].max(o.0[1])])
    }
    #[inline(always)]
    fn abs(self) -> Pair<V> {
        Pair([self.0[0].abs(), self.0[1].abs()])
    }
    #[inline(always)]
    fn sqrt(self) -> Pair<V> {
        Pair([self.0[0].sqrt(), self.0[1].sqrt()])
    }
    #[inline(always)]
    fn exponent_scale(self) -> Pair<V> {
        Pair([self.0[0].exponent_scale(), self.0[1].exponent_scale()])
    }
    #[inline(always)]
    fn split_exponent(self) -> (Pair<V>, Pair<V>) {
        let ((m0, e0), (m1, e1)) = (self.0[0].split_exponent(), self.0[1].split_exponent());
        (Pair([m0, m1]), Pair([e0, e1]))
    }
    #[inline(always)]
    fn neg(self) -> Pair<V> {
        Pair([self.0[0].neg(), self.0[1].neg()])
    }
    #[inline(always)]
    fn mul_add(self, b: Pair<V>, c: Pair<V>) -> Pair<V> {
        Pair([self.0[0].mul_add(b.0[0], c.0[0]), self.0[1].mul_add(b.0[1], c.0[1])])
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) use x86::{Avx2, Avx512, Ymm};

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::{Lanes, Mask};
    use std::arch::x86_64::*;
    use std::ops::{Add, BitAnd, BitOr, Div, Mul, Sub};

    /// 16 lanes in one AVX-512 register. Only for code compiled with AVX-512 F, VL, DQ and BW.
    #[derive(Clone, Copy, Debug)]
    pub(crate) struct Avx512(__m512);

    /// The mask of [`Avx512`]: a mask register.
    #[derive(Clone, Copy, Debug)]
    pub(crate) struct Mask16(__mmask16);

    /// 8 lanes in one AVX2 register. Only for code compiled with AVX2 and FMA (the AVX2 and
    /// AVX-512 kernels).
    #[derive(Clone, Copy, Debug)]
    pub(crate) struct Ymm(__m256);

    /// The mask of [`Ymm`]: all ones or zero per lane, as compares give.
    #[derive(Clone, Copy, Debug)]
    pub(crate) struct YmmMask(__m256);

    /// 16 lanes in two AVX2 registers.
    pub(crate) type Avx2 = super::Pair<Ymm>;

    // SAFETY (every `unsafe` below): these types are private to the crate, which makes them
    // only inside the kernels compiled for their features (`crate::kernel`), after
    // `Kernel::resolve` checked the CPU (and in tests, after checking it themselves): their
    // safe methods would run instructions the CPU may lack if called anywhere else. The loads
    // and stores take whole arrays of lanes.

    macro_rules! binary {
        ($trait:ident, $method:ident, $f512:ident, $f256:ident) => {
            impl $trait for Avx512 {
                type Output = Avx512;
                #[inline(always)]
                fn $method(self, o: Avx512) -> Avx512 {
                    unsafe { Avx512($f512(self.0, o.0)) }
                }
            }
            impl $trait for Ymm {
                type Output = Ymm;
                #[inline(always)]
                fn $method(self, o: Ymm) -> Ymm {
                    unsafe { Ymm($f256(self.0, o.0)) }
                }
            }
        };
    }
    binary!(Add, add, _mm512_add_ps, _mm256_add_ps);
    binary!(Sub, sub, _mm512_sub_ps, _mm256_sub_ps);
    binary!(Mul, mul, _mm512_mul_ps, _mm256_mul_ps);
    binary!(Div, div, _mm512_div_ps, _mm256_div_ps);

    impl BitAnd for Mask16 {
        type Output = Mask16;
        #[inline(always)]
        fn bitand(self, o: Mask16) -> Mask16 {
            Mask16(self.0 & o.0)
        }
    }
    impl BitOr for Mask16 {
        type Output = Mask16;
        #[inline(always)]
        fn bitor(self, o: Mask16) -> Mask16 {
            Mask16(self.0 | o.0)
        }
    }
    impl Mask for Mask16 {
        #[inline(always)]
        fn any(self) -> bool {
            self.0 != 0
        }
        #[inline(always)]
        fn count(self) -> u32 {
            self.0.count_ones()
        }
        #[inline(always)]
        fn and_not(self, o: Mask16) -> Mask16 {
            Mask16(self.0 & !o.0)
        }
    }

    impl BitAnd for YmmMask {
        type Output = YmmMask;
        #[inline(always)]
        fn bitand(self, o: YmmMask) -> YmmMask {
            unsafe { YmmMask(_mm256_and_ps(self.0, o.0)) }
        }
    }
    impl BitOr for YmmMask {
        type Output = YmmMask;
        #[inline(always)]
        fn bitor(self, o: YmmMask) -> YmmMask {
            unsafe { YmmMask(_mm256_or_ps(self.0, o.0)) }
        }
    }
    impl Mask for YmmMask {
        #[inline(always)]
        fn any(self) -> bool {
            unsafe { _mm256_movemask_ps(self.0) != 0 }
        }
        #[inline(always)]
        fn count(self) -> u32 {
            unsafe { (_mm256_movemask_ps(self.0) as u32).count_ones() }
        }
        #[inline(always)]
        fn and_not(self, o: YmmMask) -> YmmMask {
            unsafe { YmmMask(_mm256_andnot_ps(o.0, self.0)) }
        }
    }

    const SIGN: i32 = 0x7fff_ffff;
    const NEG: i32 = i32::MIN;
    const MANTISSA: i32 = 0x007f_ffff;
    const ONE: i32 = 0x3f80_0000;
    const EXPONENT_BIAS: i32 = 0x4B40_0000 - 127;

    impl Lanes<16> for Avx512 {
        type Mask = Mask16;
        #[inline(always)]
        fn splat(v: f32) -> Avx512 {
            unsafe { Avx512(_mm512_set1_ps(v)) }
        }
        #[inline(always)]
        fn load(a: &[f32; 16]) -> Avx512 {
            unsafe { Avx512(_mm512_loadu_ps(a.as_ptr())) }
        }
        #[inline(always)]
        fn store(self, a: &mut [f32; 16]) {
            unsafe { _mm512_storeu_ps(a.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        fn lt(self, o: Avx512) -> Mask16 {
            unsafe { Mask16(_mm512_cmp_ps_mask::<_CMP_LT_OQ>(self.0, o.0)) }
        }
        #[inline(always)]
        fn le(self, o: Avx512) -> Mask16 {
            unsafe { Mask16(_mm512_cmp_ps_mask::<_CMP_LE_OQ>(self.0, o.0)) }
        }
        #[inline(always)]
        fn gt(self, o: Avx512) -> Mask16 {
            unsafe { Mask16(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(self.0, o.0)) }
        }
        #[inline(always)]
        fn ge(self, o: Avx512) -> Mask16 {
            unsafe { Mask16(_mm512_cmp_ps_mask::<_CMP_GE_OQ>(self.0, o.0)) }
        }
        #[inline(always)]
        fn select(m: Mask16, a: Avx512, b: Avx512) -> Avx512 {
            unsafe { Avx512(_mm512_mask_blend_ps(m.0, b.0, a.0)) }
        }
        #[inline(always)]
        fn min(self, o: Avx512) -> Avx512 {
            // minps(a, b) is `a < b ? a : b`.
            unsafe { Avx512(_mm512_min_ps(self.0, o.0)) }
        }
        #[inline(always)]
        fn max(self, o: Avx512) -> Avx512 {
            unsafe { Avx512(_mm512_max_ps(self.0, o.0)) }
        }
        #[inline(always)]
        fn abs(self) -> Avx512 {
            unsafe {
                Avx512(_mm512_castsi512_ps(_mm512_and_si512(_mm512_castps_si512(self.0), _mm512_set1_epi32(SIGN))))
            }
        }
        #[inline(always)]
        fn sqrt(self) -> Avx512 {
            unsafe { Avx512(_mm512_sqrt_ps(self.0)) }
        }
        #[inline(always)]
        fn exponent_scale(self) -> Avx512 {
            unsafe {
                let bits = _mm512_sub_epi32(_mm512_castps_si512(self.0), _mm512_set1_epi32(EXPONENT_BIAS));
                Avx512(_mm512_castsi512_ps(_mm512_slli_epi32::<23>(bits)))
            }
        }
        #[inline(always)]
        fn split_exponent(self) -> (Avx512, Avx512) {
            unsafe {
                let bits = _mm512_castps_si512(self.0);
                let m = _mm512_or_si512(_mm512_and_si512(bits, _mm512_set1_epi32(MANTISSA)), _mm512_set1_epi32(ONE));
                let e = _mm512_sub_epi32(
                    _mm512_and_si512(_mm512_srli_epi32::<23>(bits), _mm512_set1_epi32(0xff)),
                    _mm512_set1_epi32(127),
                );
                (Avx512(_mm512_castsi512_ps(m)), Avx512(_mm512_cvtepi32_ps(e)))
            }
        }
        #[inline(always)]
        fn neg(self) -> Avx512 {
            unsafe {
                Avx512(_mm512_castsi512_ps(_mm512_xor_si512(_mm512_castps_si512(self.0), _mm512_set1_epi32(NEG))))
            }
        }
        #[inline(always)]
        fn mul_add(self, b: Avx512, c: Avx512) -> Avx512 {
            unsafe { Avx512(_mm512_fmadd_ps(self.0, b.0, c.0)) }
        }
    }

    impl Ymm {
        #[inline(always)]
        fn compare<const P: i32>(self, o: Ymm) -> YmmMask {
            unsafe { YmmMask(_mm256_cmp_ps::<P>(self.0, o.0)) }
        }
    }

    impl Lanes<8> for Ymm {
        type Mask = YmmMask;
        #[inline(always)]
        fn splat(v: f32) -> Ymm {
            unsafe { Ymm(_mm256_set1_ps(v)) }
        }
        #[inline(always)]
        fn load(a: &[f32; 8]) -> Ymm {
            unsafe { Ymm(_mm256_loadu_ps(a.as_ptr())) }
        }
        #[inline(always)]
        fn store(self, a: &mut [f32; 8]) {
            unsafe { _mm256_storeu_ps(a.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        fn lt(self, o: Ymm) -> YmmMask {
            self.compare::<_CMP_LT_OQ>(o)
        }
        #[inline(always)]
        fn le(self, o: Ymm) -> YmmMask {
            self.compare::<_CMP_LE_OQ>(o)
        }
        #[inline(always)]
        fn gt(self, o: Ymm) -> YmmMask {
            self.compare::<_CMP_GT_OQ>(o)
        }
        #[inline(always)]
        fn ge(self, o: Ymm) -> YmmMask {
            self.compare::<_CMP_GE_OQ>(o)
        }
        #[inline(always)]
        fn select(m: YmmMask, a: Ymm, b: Ymm) -> Ymm {
            unsafe { Ymm(_mm256_blendv_ps(b.0, a.0, m.0)) }
        }
        #[inline(always)]
        fn min(self, o: Ymm) -> Ymm {
            // minps(a, b) is `a < b ? a : b`.
            unsafe { Ymm(_mm256_min_ps(self.0, o.0)) }
        }
        #[inline(always)]
        fn max(self, o: Ymm) -> Ymm {
            unsafe { Ymm(_mm256_max_ps(self.0, o.0)) }
        }
        #[inline(always)]
        fn abs(self) -> Ymm {
            unsafe { Ymm(_mm256_and_ps(self.0, _mm256_castsi256_ps(_mm256_set1_epi32(SIGN)))) }
        }
        #[inline(always)]
        fn sqrt(self) -> Ymm {
            unsafe { Ymm(_mm256_sqrt_ps(self.0)) }
        }
        #[inline(always)]
        fn exponent_scale(self) -> Ymm {
            unsafe {
                let bits = _mm256_sub_epi32(_mm256_castps_si256(self.0), _mm256_set1_epi32(EXPONENT_BIAS));
                Ymm(_mm256_castsi256_ps(_mm256_slli_epi32::<23>(bits)))
            }
        }
        #[inline(always)]
        fn split_exponent(self) -> (Ymm, Ymm) {
            unsafe {
                let bits = _mm256_castps_si256(self.0);
                let m = _mm256_or_si256(_mm256_and_si256(bits, _mm256_set1_epi32(MANTISSA)), _mm256_set1_epi32(ONE));
                let e = _mm256_sub_epi32(
                    _mm256_and_si256(_mm256_srli_epi32::<23>(bits), _mm256_set1_epi32(0xff)),
                    _mm256_set1_epi32(127),
                );
                (Ymm(_mm256_castsi256_ps(m)), Ymm(_mm256_cvtepi32_ps(e)))
            }
        }
        #[inline(always)]
        fn neg(self) -> Ymm {
            unsafe { Ymm(_mm256_xor_ps(self.0, _mm256_castsi256_ps(_mm256_set1_epi32(NEG)))) }
        }
        #[inline(always)]
        fn mul_add(self, b: Ymm, c: Ymm) -> Ymm {
            unsafe { Ymm(_mm256_fmadd_ps(self.0, b.0, c.0)) }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every implementation gives the bits of the one-lane form, NaN, infinities and signed
    /// zeros included.
    #[test]
    fn every_width_gives_the_bits_of_one_lane() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(27);
        let special = [0.0, -0.0, 1.0, -1.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 1e-40, -87.5, 3e38];
        let draw = |rng: &mut rand_pcg::Pcg64Mcg| -> [f32; 16] {
            std::array::from_fn(|_| {
                if rng.random::<f32>() < 0.3 {
                    special[rng.random_range(0..special.len())]
                } else {
                    rng.random_range(-10.0f32..10.0) * 10f32.powi(rng.random_range(-5..5))
                }
            })
        };
        fn all<const L: usize, V: Lanes<L>>(a: [f32; L], b: [f32; L]) -> Vec<[f32; L]> {
            let (x, y) = (V::from_array(a), V::from_array(b));
            let m = x.lt(y);
            vec![
                (x + y).to_array(),
                (x - y).to_array(),
                (x * y).to_array(),
                (x / y).to_array(),
                x.min(y).to_array(),
                x.max(y).to_array(),
                x.abs().to_array(),
                x.sqrt().to_array(),
                x.exponent_scale().to_array(),
                x.split_exponent().0.to_array(),
                x.split_exponent().1.to_array(),
                x.neg().to_array(),
                x.mul_add(y, x).to_array(),
                y.mul_add(y, x.neg()).to_array(),
                V::select(m, x, y).to_array(),
                V::select(x.le(y) & y.ge(x), x, y).to_array(),
                V::select(x.gt(y) | x.is_finite(), x, y).to_array(),
                V::select(x.ge(y).and_not(x.gt(y)), x, y).to_array(),
            ]
        }
        fn one_lane(a: [f32; 16], b: [f32; 16]) -> Vec<[f32; 16]> {
            let per: Vec<Vec<[f32; 1]>> = (0..16).map(|l| all::<1, f32>([a[l]], [b[l]])).collect();
            (0..per[0].len()).map(|k| std::array::from_fn(|l| per[l][k][0])).collect()
        }
        // Any NaN is one NaN: its payload is the hardware's choice, not the arithmetic's.
        let bits = |v: Vec<[f32; 16]>| {
            v.iter().map(|a| a.map(|x| if x.is_nan() { u32::MAX } else { x.to_bits() })).collect::<Vec<_>>()
        };
        for _ in 0..2000 {
            let (a, b) = (draw(&mut rng), draw(&mut rng));
            let want = bits(one_lane(a, b));
            assert_eq!(bits(all::<16, Portable<16>>(a, b)), want);
            // Eight lanes: each half of the sixteen.
            let halves = |f: &dyn Fn([f32; 8], [f32; 8]) -> Vec<[f32; 8]>| -> Vec<[f32; 16]> {
                let (lo, hi) = (
                    f(a[..8].try_into().unwrap(), b[..8].try_into().unwrap()),
                    f(a[8..].try_into().unwrap(), b[8..].try_into().unwrap()),
                );
                lo.iter().zip(&hi).map(|(l, h)| std::array::from_fn(|k| if k < 8 { l[k] } else { h[k - 8] })).collect()
            };
            assert_eq!(bits(halves(&|a, b| all::<8, Portable<8>>(a, b))), want);
            #[cfg(target_arch = "x86_64")]
            {
                let has = |f: &str| match f {
                    "avx512" => {
                        std::arch::is_x86_feature_detected!("avx512f")
                            && std::arch::is_x86_feature_detected!("avx512vl")
                            && std::arch::is_x86_feature_detected!("avx512dq")
                            && std::arch::is_x86_feature_detected!("avx512bw")
                    }
                    _ => std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma"),
                };
                if has("avx512") {
                    // SAFETY: the CPU has the features.
                    assert_eq!(bits(unsafe { avx512(a, b) }), want);
                }
                if has("avx2") {
                    assert_eq!(bits(unsafe { avx2(a, b) }), want);
                    assert_eq!(bits(halves(&|a, b| unsafe { ymm(a, b) })), want);
                }
            }
        }
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma")]
        unsafe fn avx512(a: [f32; 16], b: [f32; 16]) -> Vec<[f32; 16]> {
            all::<16, Avx512>(a, b)
        }
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn avx2(a: [f32; 16], b: [f32; 16]) -> Vec<[f32; 16]> {
            all::<16, Avx2>(a, b)
        }
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn ymm(a: [f32; 8], b: [f32; 8]) -> Vec<[f32; 8]> {
            all::<8, Ymm>(a, b)
        }
        // Masks count and test alike.
        let m = PortableMask::<16>(std::array::from_fn(|l| (l % 3 == 0) as u32));
        assert_eq!((m.count(), m.any(), m.and_not(m).any()), (6, true, false));
    }
}
