//! The denominators D of docs/mathematics.md section 2, one type per estimator, and what they
//! read of a plane ([`PlaneFrame`]) and of its hits ([`HitLanes`]).

// Lane loops (`for l in 0..L`) index several arrays in step, as the vector code they become.
#![allow(clippy::needless_range_loop)]

use super::closed_form::cmis_exact_mean_lanes;
use crate::light::ChordDirection;
use crate::simd::Lanes;
use std::f64::consts::PI;

/// What the weights need to know about a plane, in its light's local frame (f32, gathered often).
#[derive(Clone, Copy, Debug)]
pub struct PlaneFrame {
    /// width(alpha, y'): the plane's own chord, the same for every hit on it.
    pub width: f32,
    /// (cos alpha, sin alpha), sin >= 0.
    pub cos_a: f32,
    pub sin_a: f32,
    /// Local coordinates (p, q) of the chord's start; y' = start + a (cos alpha, sin alpha).
    pub p0: f32,
    pub q0: f32,
    /// The light's side lengths W and H.
    pub light_w: f32,
    pub light_h: f32,
    /// The perpendicular direction alpha_perp = (alpha + pi/2) mod pi, ready for chords.
    pub perp: ChordDirection<f32>,
}

impl PlaneFrame {
    pub fn new(width: f64, alpha: f64, p0: f64, q0: f64, light_w: f64, light_h: f64) -> Self {
        let (sin_a, cos_a) = alpha.sin_cos();
        Self::from_cos_sin(width, cos_a, sin_a, p0, q0, light_w, light_h)
    }

    /// [`PlaneFrame::new`] with `alpha.sin_cos()` given (a plane computes it once).
    pub fn from_cos_sin(width: f64, cos_a: f64, sin_a: f64, p0: f64, q0: f64, light_w: f64, light_h: f64) -> Self {
        // (-sin, cos) has a negative sine when cos < 0; the same line is (sin, -cos).
        let (pc, ps) = if cos_a >= 0.0 { (-sin_a, cos_a) } else { (sin_a, -cos_a) };
        PlaneFrame {
            width: width as f32,
            cos_a: cos_a as f32,
            sin_a: sin_a.max(0.0) as f32,
            p0: p0 as f32,
            q0: q0 as f32,
            light_w: light_w as f32,
            light_h: light_h as f32,
            perp: ChordDirection::<f32>::from_cos_sin(pc as f32, ps as f32),
        }
    }

    /// [`PlaneFrame::vertex`] for a block of hits, lane by lane.
    #[inline(always)]
    pub fn vertex_lanes<const L: usize, V: Lanes<L>>(&self, a: V) -> (V, V) {
        let s = V::splat;
        let p = a.mul_add(s(self.cos_a), s(self.p0)).max(s(0.0)).min(s(self.light_w));
        let q = a.mul_add(s(self.sin_a), s(self.q0)).max(s(0.0)).min(s(self.light_h));
        (p, q)
    }

    /// Light-local coordinates of the light vertex y' at chord parameter `a`, kept inside.
    #[inline(always)]
    pub fn vertex(&self, a: f32) -> (f32, f32) {
        self.vertex_lanes::<1, f32>(a)
    }
}

/// What the weights need to know about one hit.
#[derive(Clone, Copy, Debug)]
pub struct HitLocal {
    /// det(alpha) = (d(alpha) x wl) . we and det(alpha_perp).
    pub det: f32,
    pub det_perp: f32,
    /// Chord parameter of the light vertex y'.
    pub a: f32,
}

/// L hits on one plane, lane by lane (L = 1 on the per-hit path, [`crate::kernel::LANES`] in the
/// vector kernels).
#[derive(Clone, Copy, Debug)]
pub struct HitLanes<const L: usize> {
    pub det: [f32; L],
    pub det_perp: [f32; L],
    pub a: [f32; L],
}

/// (a_u, a_v), undoing the rotation det(alpha) = cos a_u + sin a_v,
/// det(alpha_perp) = -sin a_u + cos a_v.
#[inline(always)]
fn a_uv<const L: usize, V: Lanes<L>>(f: &PlaneFrame, det: V, det_perp: V) -> (V, V) {
    let s = V::splat;
    (det.mul_add(s(f.cos_a), (s(f.sin_a) * det_perp).neg()), det.mul_add(s(f.sin_a), s(f.cos_a) * det_perp))
}

/// A denominator D, specialised per estimator so that the gathering loop is monomorphised.
///
/// D is computed for L hits of one plane at a time, each lane with the same operations in the
/// same order whatever L, so that the per-hit path (L = 1) and the vector kernels
/// (L = [`crate::kernel::LANES`]) give bit-identical values: one implementation for every width,
/// written as loops over lanes that the compiler turns into vector instructions.
pub trait Denominator: Sync + Send {
    /// What D needs of a plane beyond its [`PlaneFrame`], made once per plane before its hits
    /// are gathered (for K orientations: the K - 1 rotated chord directions).
    type Plane: Clone + Send + Sync;

    fn prepare(&self, f: &PlaneFrame) -> Self::Plane;

    /// D of each of `L` hits on the plane `p` was prepared for, as arrays: loops over the
    /// lanes, which the compiler vectorises as it can.
    fn denominators<const L: usize>(&self, p: &Self::Plane, h: &HitLanes<L>, out: &mut [f32; L]);

    /// D of a block of hits as a vector of lanes: what the kernels call. By default through
    /// [`Denominator::denominators`] and arrays; the estimators whose D is a few operations
    /// write it for [`Lanes`] directly (and their `denominators` as it with one lane).
    #[inline(always)]
    fn denominators_of<const L: usize, V: Lanes<L>>(&self, p: &Self::Plane, det: V, det_perp: V, a: V) -> V {
        let mut out = [0.0; L];
        let h = HitLanes { det: det.to_array(), det_perp: det_perp.to_array(), a: a.to_array() };
        self.denominators::<L>(p, &h, &mut out);
        V::from_array(out)
    }

    /// D of one hit (preparing the plane for it): for tests and benchmarks.
    fn denominator(&self, f: &PlaneFrame, h: &HitLocal) -> f32 {
        let mut out = [0.0];
        self.denominators(&self.prepare(f), &HitLanes { det: [h.det], det_perp: [h.det_perp], a: [h.a] }, &mut out);
        out[0]
    }
}

/// A `denominators` that runs `denominators_of` lane by lane with one lane: for the estimators
/// written for [`Lanes`], so that the arithmetic is written once.
macro_rules! lane_by_lane {
    () => {
        lane_by_lane!(PlaneFrame);
    };
    ($plane:ty) => {
        #[inline(always)]
        fn denominators<const L: usize>(&self, f: &$plane, h: &HitLanes<L>, out: &mut [f32; L]) {
            for l in 0..L {
                out[l] = self.denominators_of::<1, f32>(f, h.det[l], h.det_perp[l], h.a[l]);
            }
        }
    };
}

/// `unweighted`: D = g(alpha), paper eq. (22).
pub struct Unweighted;
impl Denominator for Unweighted {
    type Plane = PlaneFrame;
    fn prepare(&self, f: &PlaneFrame) -> PlaneFrame {
        *f
    }
    lane_by_lane!();
    #[inline(always)]
    fn denominators_of<const L: usize, V: Lanes<L>>(&self, f: &PlaneFrame, det: V, _: V, _: V) -> V {
        V::splat(f.width) * det.abs()
    }
}

/// `cmis-cosine`: D = width(alpha) (2/pi) sqrt(a_u^2 + a_v^2), paper eq. (26).
/// a_u^2 + a_v^2 = det(alpha)^2 + det(alpha_perp)^2, a rotation of the same pair.
pub struct CmisCosine;
impl Denominator for CmisCosine {
    type Plane = PlaneFrame;
    fn prepare(&self, f: &PlaneFrame) -> PlaneFrame {
        *f
    }
    lane_by_lane!();
    #[inline(always)]
    fn denominators_of<const L: usize, V: Lanes<L>>(&self, f: &PlaneFrame, det: V, det_perp: V, _: V) -> V {
        let s = V::splat;
        s(f.width) * s(std::f32::consts::FRAC_2_PI) * det.mul_add(det, det_perp * det_perp).sqrt()
    }
}

/// `smis-cosine` with the paper's perpendicular pair: D = width(alpha) (|det(alpha)| +
/// |det(alpha_perp)|) / 2.
pub struct SmisCosinePair;
impl Denominator for SmisCosinePair {
    type Plane = PlaneFrame;
    fn prepare(&self, f: &PlaneFrame) -> PlaneFrame {
        *f
    }
    lane_by_lane!();
    #[inline(always)]
    fn denominators_of<const L: usize, V: Lanes<L>>(&self, f: &PlaneFrame, det: V, det_perp: V, _: V) -> V {
        let s = V::splat;
        s(f.width) * s(0.5) * (det.abs() + det_perp.abs())
    }
}

/// `smis-exact` with the paper's perpendicular pair: D = (g(alpha) + g(alpha_perp)) / 2, the
/// perpendicular chord measured through the hit's light vertex y'.
pub struct SmisExactPair;
impl Denominator for SmisExactPair {
    type Plane = PlaneFrame;
    fn prepare(&self, f: &PlaneFrame) -> PlaneFrame {
        *f
    }
    lane_by_lane!();
    #[inline(always)]
    fn denominators_of<const L: usize, V: Lanes<L>>(&self, f: &PlaneFrame, det: V, det_perp: V, a: V) -> V {
        let s = V::splat;
        let (p, q) = f.vertex_lanes::<L, V>(a);
        let width_perp = chord_width_lanes::<L, V>(f.light_w, f.light_h, p, q, &f.perp);
        s(0.5) * width_perp.mul_add(det_perp.abs(), s(f.width) * det.abs())
    }
}

/// [`chord_width`](crate::light::chord_width) for a block of points, lane by lane: the same operations as its f32 form
/// (whose minimum is a compare-and-select, as [`Lanes::min`]).
#[inline(always)]
fn chord_width_lanes<const L: usize, V: Lanes<L>>(w: f32, h: f32, p: V, q: V, dir: &ChordDirection<f32>) -> V {
    let s = V::splat;
    let (fx, bx) = if dir.cos_positive { (s(w) - p, p) } else { (p, s(w) - p) };
    let forward = (fx * s(dir.inv_abs_cos)).min((s(h) - q) * s(dir.inv_sin));
    let backward = (bx * s(dir.inv_abs_cos)).min(q * s(dir.inv_sin));
    // Rounding can put a point a hair outside; a chord length is never negative.
    backward.max(s(0.0)) + forward.max(s(0.0))
}

/// `smis-cosine` and `smis-exact` with K stratified orientations alpha + k pi / K.
pub struct StratifiedK {
    exact: bool,
    /// (cos, sin) of k pi / K for k = 1..K.
    rotations: Vec<(f32, f32)>,
}

impl StratifiedK {
    pub fn new(exact: bool, k: u32) -> Self {
        let rotations = (1..k).map(|i| i as f64 * PI / k as f64).map(|b| (b.cos() as f32, b.sin() as f32)).collect();
        StratifiedK { exact, rotations }
    }
}

/// One of the K - 1 further orientations beta_k = alpha + k pi / K of a plane, reduced to
/// [0, pi): its (cos, sin) and its chord direction.
#[derive(Clone, Copy, Debug)]
pub struct Orientation {
    pub cos: f32,
    pub sin: f32,
    pub chord: ChordDirection<f32>,
}

/// A plane prepared for K orientations: the rotations and their reciprocals (two divisions
/// each) are made once per plane, so that an orientation costs a hit a few multiplies.
#[derive(Clone, Debug)]
pub struct PlaneOrientations {
    pub frame: PlaneFrame,
    pub others: Vec<Orientation>,
}

impl Denominator for StratifiedK {
    type Plane = PlaneOrientations;

    fn prepare(&self, f: &PlaneFrame) -> PlaneOrientations {
        let others = self
            .rotations
            .iter()
            .map(|&(ck, sk)| {
                // beta = alpha + k pi / K, reduced to [0, pi) so that sin(beta) >= 0.
                let (mut c, mut s) = (f.cos_a * ck - f.sin_a * sk, f.sin_a * ck + f.cos_a * sk);
                if s < 0.0 {
                    (c, s) = (-c, -s);
                }
                Orientation { cos: c, sin: s, chord: ChordDirection::<f32>::from_cos_sin(c, s) }
            })
            .collect();
        PlaneOrientations { frame: *f, others }
    }

    lane_by_lane!(PlaneOrientations);

    /// Each lane sums its orientations in the order k = 0, 1, .., K - 1.
    #[inline(always)]
    fn denominators_of<const L: usize, V: Lanes<L>>(&self, plane: &PlaneOrientations, det: V, det_perp: V, a: V) -> V {
        let (f, s) = (&plane.frame, V::splat);
        let (a_u, a_v) = a_uv::<L, V>(f, det, det_perp);
        let (p, q) = f.vertex_lanes::<L, V>(a);
        let mut sum = if self.exact { s(f.width) * det.abs() } else { det.abs() };
        for o in &plane.others {
            let det = a_u.mul_add(s(o.cos), s(o.sin) * a_v).abs();
            sum = if self.exact {
                chord_width_lanes::<L, V>(f.light_w, f.light_h, p, q, &o.chord).mul_add(det, sum)
            } else {
                sum + det
            };
        }
        let mean = sum * s(1.0 / (plane.others.len() + 1) as f32);
        if self.exact { mean } else { s(f.width) * mean }
    }
}

/// `cmis-exact`: D = (1/pi) int_0^pi g(beta) d beta, the closed form of section 3 in f32
/// ([`cmis_exact_mean_f32`](super::cmis_exact_mean_f32), vectorised over the lanes). The f64 form
/// [`cmis_exact_mean`](super::cmis_exact_mean) is its reference in the tests.
pub struct CmisExact;

/// A plane prepared for `cmis-exact`: the light's sides in units of W + H, so that the
/// logarithms of lengths stay near zero (D is proportional to the lengths: D = (W + H) D(unit)).
#[derive(Clone, Copy, Debug)]
pub struct CmisPlane {
    pub frame: PlaneFrame,
    pub unit: f32,
    pub inv_unit: f32,
}

impl Denominator for CmisExact {
    type Plane = CmisPlane;
    fn prepare(&self, f: &PlaneFrame) -> CmisPlane {
        let unit = f.light_w + f.light_h;
        CmisPlane { frame: *f, unit, inv_unit: 1.0 / unit }
    }
    /// Through arrays (the default `denominators_of`): the compiler's vectorisation of these
    /// lane loops is 5% faster than the closed form on the kernels' lane types, whose four
    /// sectors' fields spill from the registers either way.
    #[inline(always)]
    fn denominators<const L: usize>(&self, c: &CmisPlane, h: &HitLanes<L>, out: &mut [f32; L]) {
        for l in 0..L {
            out[l] = self.one(c, h.det[l], h.det_perp[l], h.a[l]);
        }
    }
}

impl CmisExact {
    /// D of one hit: the closed form on the light in units of W + H.
    #[inline(always)]
    fn one(&self, c: &CmisPlane, det: f32, det_perp: f32, a: f32) -> f32 {
        let f = &c.frame;
        let (w, hh) = (f.light_w * c.inv_unit, f.light_h * c.inv_unit);
        let (a_u, a_v) = a_uv::<1, f32>(f, det, det_perp);
        let (p, q) = f.vertex_lanes::<1, f32>(a);
        cmis_exact_mean_lanes::<1, f32>(w, hh, p * c.inv_unit, q * c.inv_unit, a_u, a_v) * c.unit
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn frame_and_hit(rng: &mut impl Rng) -> (PlaneFrame, HitLocal) {
        let (w, h) = (rng.random_range(0.1..3.0), rng.random_range(0.1..3.0));
        let alpha = rng.random::<f64>() * PI;
        let (p, q) = (rng.random::<f64>() * w, rng.random::<f64>() * h);
        let dir = ChordDirection::from_angle(alpha);
        let (back, fwd) = crate::light::chord_extent(w, h, p, q, &dir);
        let (p0, q0) = (p - back * alpha.cos(), q - back * alpha.sin());
        let f = PlaneFrame::new(back + fwd, alpha, p0, q0, w, h);
        let hit = HitLocal { det: rng.random_range(-1.0..1.0), det_perp: rng.random_range(-1.0..1.0), a: back as f32 };
        (f, hit)
    }

    #[test]
    fn stratified_k2_reproduces_the_pair_hit_by_hit() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(5);
        let (exact_k, cosine_k) = (StratifiedK::new(true, 2), StratifiedK::new(false, 2));
        for _ in 0..10_000 {
            let (f, hit) = frame_and_hit(&mut rng);
            let (a, b) = (SmisExactPair.denominator(&f, &hit), exact_k.denominator(&f, &hit));
            assert!((a - b).abs() <= 1e-5 * a.max(1e-6), "{a} vs {b}");
            let (a, b) = (SmisCosinePair.denominator(&f, &hit), cosine_k.denominator(&f, &hit));
            assert!((a - b).abs() <= 1e-5 * a.max(1e-6), "{a} vs {b}");
        }
    }

    #[test]
    fn many_orientations_approach_the_continuous_weights() {
        // The stratified averages are Riemann sums of the CMIS integrals.
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(6);
        let (exact_k, cosine_k) = (StratifiedK::new(true, 64), StratifiedK::new(false, 64));
        for _ in 0..1000 {
            let (f, hit) = frame_and_hit(&mut rng);
            let (c, e) = (CmisCosine.denominator(&f, &hit), cosine_k.denominator(&f, &hit));
            assert!((c - e).abs() <= 0.01 * c, "cosine {c} vs {e}");
            let (c, e) = (CmisExact.denominator(&f, &hit), exact_k.denominator(&f, &hit));
            assert!((c - e).abs() <= 0.05 * c, "exact {c} vs {e}");
        }
    }
}
