//! Photon planes (docs/mathematics.md section 2): sampling, and the plane's polygon inside the medium box.
//!
//! One plane is: a light chosen by power, an orientation alpha uniform in [0, pi), a point y
//! uniform on the light, a direction wl cosine-distributed about the light's normal. The chord is
//! the segment of the line through y along d(alpha) = cos(alpha) u + sin(alpha) v inside the
//! rectangle; the plane is that chord swept along wl, clipped where it leaves the box. Taking the
//! chord through a uniform point is sampling its offset with density width / A, the paper's
//! p(v | alpha) = |s| / A.

use crate::light::{ChordDirection, chord_extent};
use crate::limits::DEFAULT_LOBES;
use crate::medium::{Medium, PHASE};
use crate::sampling::{Discrete, Sampler, cosine_hemisphere};
use crate::scene::Scene;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use std::f64::consts::PI;

/// One sampled photon plane.
#[derive(Clone, Debug)]
pub struct PhotonPlane {
    /// Index of the light it was swept from.
    pub light: usize,
    /// Orientation alpha in [0, pi), and its sine and cosine (`alpha.sin_cos()`, computed once:
    /// the plane's view and frame take them too).
    pub alpha: f64,
    pub sin_alpha: f64,
    pub cos_alpha: f64,
    /// The uniformly sampled point y (kept for tests and diagnostics).
    pub point: DVec3,
    /// Start y0 of the chord (chord parameter a = 0), its unit direction d(alpha) and width.
    pub origin: DVec3,
    pub chord: DVec3,
    pub width: f64,
    /// Local coordinates (p, q) of y0 on the light.
    pub p0: f64,
    pub q0: f64,
    /// The sweep direction wl, unit, in the light's front hemisphere.
    pub direction: DVec3,
    /// `(cos theta / pi) / p(wl)`: the cosine density over the density wl was drawn with
    /// ([`Lobe`]), 1 where it was drawn by the cosine alone (an isotropic medium, a light
    /// facing away from the eye). A factor of the plane's contribution, at most `1 / (1 - share)`.
    pub direction_weight: f64,
    /// The factor of one plane's contribution that does not depend on the hit (RGB):
    /// sigma_s rho pi Le A / P_l, the same for every plane of a light. A hit adds
    /// `power * Tr / D / N` (docs/mathematics.md section 2: eta / (N P_l D)); the gathering sums
    /// a light's `Tr / D` and multiplies by `power` once ([`crate::gather`]).
    pub power: DVec3,
}

/// What sampling a plane needs of the scene, made once for a set: the lights' distribution by
/// power and each light's [`Lobe`], if it has one.
#[derive(Clone, Debug)]
pub struct PlaneSources {
    pub lights: Discrete,
    pub lobes: Vec<Option<Lobe>>,
}

impl PlaneSources {
    /// The sources of `scene`'s planes, `lobes` of each light's drawn from its lobe (the
    /// [`PlaneSet`]'s share).
    pub fn new(scene: &Scene, lobes: f64) -> Self {
        PlaneSources {
            lights: scene.light_distribution(),
            lobes: (0..scene.lights.len()).map(|i| Lobe::of(scene, i, lobes)).collect(),
        }
    }
}

/// Samples one plane from five uniform numbers in [0, 1) (docs/mathematics.md section 2.1):
/// `u[0]` chooses the light by inverting the CDF of the light powers, and where it fell within
/// that light's share, rescaled, is the orientation `alpha / pi` (uniform and independent of the
/// choice, and stratified within each light when `u[0]` is); `u[1], u[2]` give the direction
/// (section 2.5: by the cosine, or from the light's lobe) and `u[3], u[4]` the point.
pub fn sample_plane(scene: &Scene, sources: &PlaneSources, u: [f64; 5]) -> PhotonPlane {
    let lights = &sources.lights;
    let index = lights.sample(u[0]);
    let light = &scene.lights[index];
    let alpha = PI * lights.remainder(u[0], index);
    let (direction, direction_weight) = match &sources.lobes[index] {
        None => (cosine_hemisphere(u[1], u[2], light.u, light.v, light.n), 1.0),
        Some(lobe) => lobe.sample(light, u[1], u[2]),
    };
    let (p, q) = (u[3] * light.width, u[4] * light.height);
    let point = light.point(p, q);
    let (sin_a, cos_a) = alpha.sin_cos();
    let (back, forward) =
        chord_extent(light.width, light.height, p, q, &ChordDirection::<f64>::from_cos_sin(cos_a, sin_a));
    let chord = cos_a * light.u + sin_a * light.v;
    let power = scene.medium.sigma_s * PHASE * PI * light.radiance * light.area() / lights.probability(index);
    PhotonPlane {
        light: index,
        alpha,
        sin_alpha: sin_a,
        cos_alpha: cos_a,
        point,
        origin: point - back * chord,
        chord,
        width: back + forward,
        p0: p - back * cos_a,
        q0: q - back * sin_a,
        direction,
        direction_weight,
        power,
    }
}

/// The largest f64 below 1, so that a rescaled uniform stays in [0, 1).
const BELOW_ONE: f64 = 1.0 - f64::EPSILON / 2.0;

/// A second way for a light to draw its planes' sweep directions, in a medium that scatters
/// forward or back (docs/mathematics.md section 2.5): a share of its planes (the `lobes` setting,
/// [`DEFAULT_LOBES`] by default) sweep along
/// Henyey-Greenstein's lobe of the medium's |g| about the direction from the light's centre to
/// the eye (times the sign of g), where the phase function peaks for the rays that look toward
/// the light; the rest by the cosine, as in an isotropic medium. A direction's density is then
/// the mixture of the two, which the plane's [`PhotonPlane::direction_weight`] carries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lobe {
    /// Unit, in the light's front hemisphere.
    pub axis: DVec3,
    /// The lobe's |g|, in (0, 0.99].
    pub h: f64,
    /// The share of the light's planes drawn from the lobe, in (0, 1].
    pub share: f64,
}

impl Lobe {
    /// The lobe of light `index`, if it has one: none in an isotropic medium, nor for a light
    /// whose front faces away from the lobe's axis (forward fog seen from behind a light, or
    /// back-scattering fog seen from in front of it), where its directions would all be
    /// mirrored ones; none where `share`, the share of the light's planes drawn from it, is 0.
    pub fn of(scene: &Scene, index: usize, share: f64) -> Option<Lobe> {
        debug_assert!((0.0..=1.0).contains(&share), "a share of {share} (every door checks it)");
        let g = scene.medium.g;
        if g == 0.0 || share <= 0.0 {
            return None;
        }
        let light = &scene.lights[index];
        let center = light.point(0.5 * light.width, 0.5 * light.height);
        let axis = g.signum() * (scene.camera.position - center).normalize_or_zero();
        (axis.dot(light.n) > 1e-6).then_some(Lobe { axis, h: g.abs(), share: share.min(1.0) })
    }

    /// Henyey-Greenstein's density over directions (per steradian) at `cos` from the axis.
    fn density(&self, cos: f64) -> f64 {
        let h = self.h;
        let b = (1.0 + h * h - 2.0 * h * cos).max((1.0 - h) * (1.0 - h));
        PHASE * (1.0 - h * h) / (b * b.sqrt())
    }

    /// A direction from two uniforms and its [`PhotonPlane::direction_weight`]: the first
    /// uniform chooses the way (below `1 - share`: the cosine) and, rescaled, is the first
    /// number of that way's warp. A lobe's direction behind the light is mirrored into its
    /// front, so that the lobe's density there is the sum of its density at `wl` and at the
    /// mirror image.
    pub fn sample(&self, light: &crate::light::RectLight, u1: f64, u2: f64) -> (DVec3, f64) {
        let n = light.n;
        let c = 1.0 - self.share;
        let w = if u1 < c {
            cosine_hemisphere((u1 / c).min(BELOW_ONE), u2, light.u, light.v, n)
        } else {
            let v = ((u1 - c) / self.share).min(BELOW_ONE);
            let cos = hg_cosine(self.h, v);
            let sin = (1.0 - cos * cos).max(0.0).sqrt();
            let (t, b) = self.axis.any_orthonormal_pair();
            let (sp, cp) = (2.0 * PI * u2).sin_cos();
            let w = (sin * cp * t + sin * sp * b + cos * self.axis).normalize();
            let behind = w.dot(n);
            if behind < 0.0 { w - 2.0 * behind * n } else { w }
        };
        // A direction in the light's own plane (measure zero: the disk's rim, or the lobe's
        // directions along it) is taken as its normal, so that its weight is not 0.
        let w = if w.dot(n) > 1e-12 { w } else { n };
        let cos = w.dot(n);
        let mirrored = w - 2.0 * cos * n;
        let lobe = self.density(w.dot(self.axis)) + self.density(mirrored.dot(self.axis));
        let cosine = cos / PI;
        (w, cosine / (c * cosine + self.share * lobe))
    }
}

/// The cosine of the angle to the axis of a direction drawn from Henyey-Greenstein's lobe of
/// `h` by the uniform `v`: the inverse of its distribution,
///
/// ```text
/// cos = (1 + h^2 - ((1 - h^2) / D)^2) / (2 h),   D = 1 + h e,   e = 2 v - 1
///     = (2 e + h (e^2 + 3) + 2 h^2 e + h^3 (e^2 - 1)) / (2 D^2)
/// ```
///
/// (pbrt-v4's `SampleHenyeyGreenstein` takes the first form). The second, the same after the
/// division by h, has none to make: at a small h the first subtracts numbers near 1 to leave
/// one near 2 h e, and below h = 1e-16 leaves 0, every direction on the circle at a right angle
/// to the axis, where the second gives `e`, the uniform sphere's cosine.
fn hg_cosine(h: f64, v: f64) -> f64 {
    let e = 2.0 * v - 1.0;
    let d = h.mul_add(e, 1.0);
    let numerator = 2.0 * e + h * (e * e + 3.0) + 2.0 * h * h * e + h * h * h * (e * e - 1.0);
    (numerator / (2.0 * d * d)).clamp(-1.0, 1.0)
}

/// Which set of planes: the sampler and the seed that make it, and the share of each light's
/// planes swept along its lobe in fog that scatters forward or back ([`Lobe`]; no matter in
/// isotropic fog). A render's planes are its set's first N points; any range of them is sampled
/// alike wherever it is ([`sample_plane_range`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneSet {
    pub sampler: Sampler,
    pub seed: u64,
    /// In [0, 1] ([`DEFAULT_LOBES`] by default).
    pub lobes: f64,
}

impl PlaneSet {
    /// The set of `sampler` and `seed` with the default share of lobes.
    pub fn new(sampler: Sampler, seed: u64) -> Self {
        PlaneSet { sampler, seed, lobes: DEFAULT_LOBES }
    }
}

/// Samples `n` planes of [`PlaneSet::new`]`(sampler, seed)`, plane `i` from point `i` of the
/// sampler: the set depends on the seed only.
pub fn sample_planes(scene: &Scene, sampler: Sampler, n: usize, seed: u64) -> Vec<PhotonPlane> {
    sample_plane_range(scene, PlaneSet::new(sampler, seed), 0..n)
}

/// Planes `range` of `set` (so a large set can be made and consumed in pieces).
pub fn sample_plane_range(scene: &Scene, set: PlaneSet, range: std::ops::Range<usize>) -> Vec<PhotonPlane> {
    let (sources, numbers) = (PlaneSources::new(scene, set.lobes), set.sampler.numbers(set.seed));
    (range.start as u64..range.end as u64)
        .into_par_iter()
        .map(|i| sample_plane(scene, &sources, numbers.plane(i)))
        .collect()
}

/// A convex polygon of at most [`Polygon::CAPACITY`] vertices.
#[derive(Clone, Copy, Debug)]
pub struct Polygon<T: Copy + Default> {
    pub vertices: [T; Polygon::<DVec3>::CAPACITY],
    pub len: usize,
}

impl<T: Copy + Default> Polygon<T> {
    pub const CAPACITY: usize = 16;

    pub fn from_slice(points: &[T]) -> Self {
        let mut vertices = [T::default(); Polygon::<DVec3>::CAPACITY];
        vertices[..points.len()].copy_from_slice(points);
        Polygon { vertices, len: points.len() }
    }

    pub fn points(&self) -> &[T] {
        &self.vertices[..self.len]
    }

    /// No vertices.
    pub fn empty() -> Self {
        Polygon { vertices: [T::default(); Polygon::<DVec3>::CAPACITY], len: 0 }
    }

    /// Sutherland-Hodgman: keeps the part where `inside(v) >= 0`, with `inside` affine.
    pub fn clip(&self, inside: impl Fn(T) -> f64, lerp: impl Fn(T, T, f64) -> T) -> Self {
        let mut out = Self::empty();
        self.clip_sides_into(&self.sides(inside), &mut out, lerp);
        out
    }

    /// [`Polygon::clip`] in place, `scratch` its workspace: a chain of clips (11 per plane) fills
    /// no fresh polygon per clip, and a clip that keeps every vertex (most of a plane's clips by
    /// the box's faces and the screen's edges) leaves the polygon as it is, one that keeps none
    /// empties it, without copying either (the same vertices as [`Polygon::clip`] in every
    /// case).
    pub fn clip_in_place(&mut self, scratch: &mut Self, inside: impl Fn(T) -> f64, lerp: impl Fn(T, T, f64) -> T) {
        // The sides written where they are read, and counted as they are made: returned by
        // value, the array was copied in wide loads from narrow stores, a stall per clip (the
        // box polygon's hottest instructions).
        let mut side = [0.0f64; Polygon::<DVec3>::CAPACITY];
        let mut kept = 0;
        for (d, &v) in side.iter_mut().zip(self.points()) {
            *d = inside(v);
            kept += (*d >= 0.0) as usize;
        }
        if kept == self.len {
            return;
        }
        // None kept (a NaN side is not kept, and Sutherland-Hodgman keeps nothing of it either).
        if kept == 0 {
            self.len = 0;
            return;
        }
        self.clip_sides_into(&side, scratch, lerp);
        self.vertices[..scratch.len].copy_from_slice(scratch.points());
        self.len = scratch.len;
    }

    /// Each vertex's side of a clip (an edge's two ends share their vertices with its
    /// neighbours).
    fn sides(&self, inside: impl Fn(T) -> f64) -> [f64; Polygon::<DVec3>::CAPACITY] {
        let mut side = [0.0f64; Polygon::<DVec3>::CAPACITY];
        for (d, &v) in side.iter_mut().zip(self.points()) {
            *d = inside(v);
        }
        side
    }

    /// Sutherland-Hodgman with each vertex's side given.
    fn clip_sides_into(&self, side: &[f64; Polygon::<DVec3>::CAPACITY], out: &mut Self, lerp: impl Fn(T, T, f64) -> T) {
        out.len = 0;
        let pts = self.points();
        // Each edge cur -> next, the last closing the polygon (no index modulo the length: an
        // integer division per vertex).
        for i in 0..pts.len() {
            let next = if i + 1 == pts.len() { 0 } else { i + 1 };
            let (dc, dn) = (side[i], side[next]);
            if dc >= 0.0 && out.len < Self::CAPACITY {
                out.vertices[out.len] = pts[i];
                out.len += 1;
            }
            if (dc >= 0.0) != (dn >= 0.0) && out.len < Self::CAPACITY {
                out.vertices[out.len] = lerp(pts[i], pts[next], dc / (dc - dn));
                out.len += 1;
            }
        }
    }
}

/// The part of the segment `p`-`q` inside the box `[lo, hi]` (Liang and Barsky), if any.
pub fn clip_segment(p: DVec2, q: DVec2, lo: DVec2, hi: DVec2) -> Option<(DVec2, DVec2)> {
    let d = q - p;
    let (mut s0, mut s1) = (0.0f64, 1.0f64);
    for axis in 0..2 {
        for (num, den) in [(p[axis] - lo[axis], -d[axis]), (hi[axis] - p[axis], d[axis])] {
            if den == 0.0 {
                if num < 0.0 {
                    return None;
                }
            } else {
                let s = num / den;
                if den < 0.0 {
                    s0 = s0.max(s);
                } else {
                    s1 = s1.min(s);
                }
            }
        }
    }
    (s0 <= s1).then(|| (p + d * s0, p + d * s1))
}

impl PhotonPlane {
    /// The plane's polygon inside the medium box grown by `margin` on every side: the chord
    /// swept along wl as far as the box diagonal, clipped by the six faces.
    pub fn polygon_in_box(&self, medium: &Medium, margin: f64) -> Polygon<DVec3> {
        let reach = medium.diagonal() + 2.0 * margin;
        let (a, b) = (self.origin, self.origin + self.width * self.chord);
        let mut poly = Polygon::from_slice(&[a, b, b + reach * self.direction, a + reach * self.direction]);
        let mut scratch = Polygon::empty();
        let lerp = |p: DVec3, q: DVec3, s: f64| p + (q - p) * s;
        for axis in 0..3 {
            let (lo, hi) = (medium.min[axis] - margin, medium.max[axis] + margin);
            poly.clip_in_place(&mut scratch, |v| v[axis] - lo, lerp);
            poly.clip_in_place(&mut scratch, |v| hi - v[axis], lerp);
        }
        poly
    }

    /// The plane's normal d(alpha) x wl (not unit).
    pub fn normal(&self) -> DVec3 {
        self.chord.cross(self.direction)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_clipping_keeps_the_inside() {
        let (lo, hi) = (DVec2::ZERO, DVec2::new(2.0, 1.0));
        let (a, b) = clip_segment(DVec2::new(-1.0, 0.5), DVec2::new(3.0, 0.5), lo, hi).unwrap();
        assert_eq!((a, b), (DVec2::new(0.0, 0.5), DVec2::new(2.0, 0.5)));
        assert!(clip_segment(DVec2::new(-1.0, 2.0), DVec2::new(3.0, 2.0), lo, hi).is_none());
    }

    fn scene() -> Scene {
        let text = include_str!("../../../media_scenes/six_lights.toml");
        Scene::parse(text, "six_lights.toml", "six_lights").unwrap()
    }

    #[test]
    fn chord_contains_the_sampled_point_and_stays_on_the_light() {
        let s = scene();
        for p in sample_planes(&s, Sampler::default(), 2000, 3) {
            let l = &s.lights[p.light];
            let (pp, qq) = l.local(p.point);
            assert!(p.width >= 0.0 && p.width <= (l.width.hypot(l.height)) * (1.0 + 1e-12));
            // y lies on the chord.
            let a = (p.point - p.origin).dot(p.chord);
            assert!(a >= -1e-9 && a <= p.width + 1e-9);
            assert!((p.origin + a * p.chord - p.point).length() < 1e-9);
            // Both ends on the rectangle's boundary.
            for end in [p.origin, p.origin + p.width * p.chord] {
                let (x, y) = l.local(end);
                let on_edge = [x, l.width - x, y, l.height - y].iter().any(|d| d.abs() < 1e-9);
                assert!(on_edge, "end ({x}, {y}) of the chord through ({pp}, {qq})");
            }
            assert!(p.direction.dot(l.n) >= 0.0 && (p.direction.length() - 1.0).abs() < 1e-12);
            // The sine and cosine it carries are alpha's, bit for bit.
            assert_eq!((p.sin_alpha, p.cos_alpha), p.alpha.sin_cos());
        }
    }

    #[test]
    fn same_seed_same_planes() {
        let s = scene();
        let (a, b) = (sample_planes(&s, Sampler::default(), 100, 9), sample_planes(&s, Sampler::default(), 100, 9));
        assert!(a.iter().zip(&b).all(|(x, y)| x.origin == y.origin && x.direction == y.direction));
        let c = sample_planes(&s, Sampler::default(), 100, 10);
        assert!(a.iter().zip(&c).any(|(x, y)| x.origin != y.origin));
    }

    #[test]
    fn polygon_lies_in_the_box_and_on_the_plane() {
        let s = scene();
        for p in sample_planes(&s, Sampler::default(), 500, 4) {
            let poly = p.polygon_in_box(&s.medium, 0.0);
            assert!(poly.len >= 3 || p.width == 0.0);
            let n = p.normal();
            for &v in poly.points() {
                assert!(s.medium.contains(v, 1e-9));
                assert!((v - p.origin).dot(n).abs() < 1e-9);
            }
        }
    }

    /// A lobe about an axis 0.2 above the light's plane (most of its directions mirrored into
    /// the front), one about the normal, and one of a g of 1e-300 (a scene may give any), at
    /// the default share; and at the ends of the `lobes` setting's range, a share of 0.05 about
    /// the normal and every plane from the grazing lobe (share 1, no cosine to fall back on).
    fn lobes() -> Vec<(Lobe, crate::light::RectLight)> {
        let light = s_light();
        let grazing = (0.2 * light.n + (1.0f64 - 0.04).sqrt() * light.u).normalize();
        let s = DEFAULT_LOBES;
        [(grazing, 0.9, s), (light.n, 0.9, s), (grazing, 1e-300, s), (light.n, 0.9, 0.05), (grazing, 0.9, 1.0)]
            .into_iter()
            .map(|(axis, h, share)| (Lobe { axis, h, share }, light.clone()))
            .collect()
    }

    /// The lobe's cosine: the ends of [-1, 1] at v = 0 and 1, Henyey-Greenstein's mean cosine
    /// h (over 100,000 midpoints of v), and the uniform sphere's `2 v - 1` for h near 0, where
    /// pbrt-v4's form gave 0 below h = 1e-16.
    #[test]
    fn the_lobes_cosine_inverts_henyey_greenstein() {
        for h in [1e-300, 1e-12, 0.3, 0.9, 0.99] {
            assert!((hg_cosine(h, 0.0) + 1.0).abs() < 1e-12 && (hg_cosine(h, 1.0) - 1.0).abs() < 1e-12, "{h:e}");
            let n = 100_000;
            let mean = (0..n).map(|i| hg_cosine(h, (i as f64 + 0.5) / n as f64)).sum::<f64>() / n as f64;
            assert!((mean - h).abs() < 1e-3, "h {h:e}: mean cosine {mean}");
        }
        assert!((hg_cosine(1e-300, 0.3) + 0.4).abs() < 1e-15);
    }

    fn s_light() -> crate::light::RectLight {
        scene().lights[0].clone()
    }

    /// Under the mixture a direction's weight m = (cos / pi) / p(wl) has mean 1, and m f(wl)
    /// the cosine's mean of f, for f peaked on the axis (the phase function about it): within 4
    /// standard errors over 400,000 directions, where the cosine's own mean comes from as many
    /// cosine directions. Without the mirror image's density the grazing lobe's mean weight is
    /// 1.044 +- 0.0014 (tried).
    #[test]
    fn a_lobes_direction_weight_keeps_the_cosines_expectation() {
        use rand::{Rng, SeedableRng};
        for (lobe, light) in lobes() {
            let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(11);
            let peaked = |w: DVec3| crate::medium::henyey_greenstein(0.9, w.dot(lobe.axis));
            let n = 400_000;
            let (mut m, mut mf, mut cf) = ([0.0f64; 2], [0.0f64; 2], [0.0f64; 2]);
            for _ in 0..n {
                let (w, weight) = lobe.sample(&light, rng.random(), rng.random());
                m = [m[0] + weight, m[1] + weight * weight];
                let v = weight * peaked(w);
                mf = [mf[0] + v, mf[1] + v * v];
                let c = peaked(cosine_hemisphere(rng.random(), rng.random(), light.u, light.v, light.n));
                cf = [cf[0] + c, cf[1] + c * c];
            }
            let stats = |s: [f64; 2]| {
                let mean = s[0] / n as f64;
                (mean, ((s[1] / n as f64 - mean * mean) / n as f64).sqrt())
            };
            let ((m, m_se), (mf, mf_se), (cf, cf_se)) = (stats(m), stats(mf), stats(cf));
            assert!((m - 1.0).abs() < 4.0 * m_se, "axis {}: mean weight {m} +- {m_se}", lobe.axis);
            let z = (mf - cf) / mf_se.hypot(cf_se);
            assert!(z.abs() < 4.0, "axis {}: {mf} +- {mf_se} against the cosine's {cf} +- {cf_se}", lobe.axis);
            // The lobe finds the peak: its estimate is the tighter one.
            assert!(mf_se < cf_se, "axis {}: {mf_se} against {cf_se}", lobe.axis);
        }
    }

    /// Every direction is in the light's front and its weight positive, finite and at most
    /// 1 / (1 - share), and at most 2 (1 + h)^2 / (1 - h) (docs/mathematics.md section 2.5:
    /// `q(w) + q(R w) >= (1 - h) / (2 pi (1 + h)^2)`, the bound that holds where there is no
    /// cosine to fall back on, at share 1), for uniforms at their ends too, and at each side
    /// of the choice of way (`u1` at `1 - share`).
    #[test]
    fn a_lobes_directions_are_in_front_with_bounded_weights() {
        let ends = [0.0, 1e-300, 0.25, 0.5 - 1e-16, 0.5, 0.5 + 1e-16, 0.75, BELOW_ONE];
        for (lobe, light) in lobes() {
            let way = 1.0 - lobe.share;
            let u1s = ends
                .iter()
                .copied()
                .chain([way - 1e-15, way, way + 1e-15].into_iter().filter(|u| (0.0..1.0).contains(u)));
            let bound = (1.0 / (1.0 - lobe.share)).min(2.0 * (1.0 + lobe.h).powi(2) / (1.0 - lobe.h));
            for u1 in u1s {
                for &u2 in &ends {
                    let (w, m) = lobe.sample(&light, u1, u2);
                    assert!(w.dot(light.n) > 0.0 && (w.length() - 1.0).abs() < 1e-12, "{u1} {u2}: {w}");
                    assert!(
                        m.is_finite() && m > 0.0 && m <= bound * (1.0 + 1e-12),
                        "{u1} {u2}: weight {m} over {bound}"
                    );
                }
            }
        }
    }

    /// Only a medium that is not isotropic has lobes, and only lights whose front faces the
    /// axis: toward the eye in forward fog, away from it in fog that scatters back, so that of
    /// the benchmark's six lights those facing the camera have one at g = 0.85 and the others
    /// at g = -0.85.
    #[test]
    fn lobes_only_where_the_phase_function_has_one_in_the_lights_front() {
        let mut s = scene();
        assert!(PlaneSources::new(&s, DEFAULT_LOBES).lobes.iter().all(Option::is_none));
        assert!(sample_planes(&s, Sampler::default(), 200, 1).iter().all(|p| p.direction_weight == 1.0));
        let mut facing = Vec::new();
        for g in [0.85, -0.85] {
            s.medium.g = g;
            let lobes = PlaneSources::new(&s, DEFAULT_LOBES).lobes;
            for (light, lobe) in s.lights.iter().zip(&lobes) {
                let center = light.point(0.5 * light.width, 0.5 * light.height);
                let axis = g.signum() * (s.camera.position - center).normalize();
                assert_eq!(lobe.is_some(), axis.dot(light.n) > 1e-6, "{} at g = {g}", light.name);
                if let Some(lobe) = lobe {
                    assert!((lobe.axis - axis).length() < 1e-12);
                    assert_eq!((lobe.h, lobe.share), (0.85, DEFAULT_LOBES));
                }
            }
            facing.push(lobes.iter().map(Option::is_some).collect::<Vec<_>>());
        }
        assert!(facing[0].iter().filter(|&&f| f).count() >= 3, "{facing:?}");
        assert!(facing[0].iter().zip(&facing[1]).all(|(a, b)| a != b), "{facing:?}");
        // Sampled, the planes of the lights with a lobe carry weights other than 1.
        s.medium.g = 0.85;
        let planes = sample_planes(&s, Sampler::default(), 2000, 1);
        assert!(planes.iter().all(|p| facing[0][p.light] || p.direction_weight == 1.0));
        assert!(planes.iter().any(|p| p.direction_weight != 1.0));
        // A set of no lobes (the `lobes` setting at 0) sweeps every plane by the cosine, as in
        // isotropic fog: the same directions as the cosine's planes, bit for bit.
        assert!(PlaneSources::new(&s, 0.0).lobes.iter().all(Option::is_none));
        let none = sample_plane_range(&s, PlaneSet { lobes: 0.0, ..PlaneSet::new(Sampler::default(), 1) }, 0..2000);
        s.medium.g = 0.0;
        let cosine = sample_planes(&s, Sampler::default(), 2000, 1);
        assert!(none.iter().zip(&cosine).all(|(a, b)| a.direction == b.direction && a.direction_weight == 1.0));
        // A share given is the lobe's.
        s.medium.g = 0.85;
        let lobes = PlaneSources::new(&s, 0.25).lobes;
        assert!(lobes.iter().flatten().all(|l| l.share == 0.25) && lobes.iter().flatten().count() >= 3);
    }
}
