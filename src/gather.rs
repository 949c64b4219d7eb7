//! One camera ray against one photon plane: the hit test and the weighted contribution
//! C = K / (N P_l D) of SPEC section 2. Everything here is f32 and relative to the ray origin,
//! prepared once per plane so that a hit costs a few dot products and one exponential.
//!
//! Every intersection structure ([`crate::raster`], [`crate::bvh`], the brute-force loop
//! [`GatherContext::gather_brute_force`]) finds candidate planes and calls [`PlaneView::hit`] and
//! [`GatherContext::contribution`]; they differ only in which planes they try.

use crate::photon_plane::PhotonPlane;
use crate::scene::Scene;
use crate::weights::{Denominator, HitLocal, PlaneFrame};
use glam::{DVec3, Vec3};

/// A camera ray: unit direction (f32, origin at the camera) and its segment `[t0, t1]` inside
/// the medium before the first light panel.
#[derive(Clone, Copy, Debug, Default)]
pub struct CameraRay {
    pub dir: Vec3,
    pub t0: f32,
    pub t1: f32,
}

/// A plane prepared for rays from one origin `o`.
///
/// With b = y0 - o and the plane normal n_P = d x wl, the hit `o + t we = y0 + a d + r wl` solves
/// by Cramer's rule with the common determinant det = we . n_P (SPEC's det(alpha)):
/// t det = b . n_P, a det = we . (wl x b), r det = we . (b x d).
#[derive(Clone, Copy, Debug)]
pub struct PlaneView {
    pub normal: Vec3,
    /// (d(alpha_perp) x wl) with d(alpha_perp) = -sin(alpha) u + cos(alpha) v: det(alpha_perp).
    pub normal_perp: Vec3,
    pub a_axis: Vec3,
    pub r_axis: Vec3,
    pub t_det: f32,
    pub frame: PlaneFrame,
    /// power / N: the hit-independent factor of C.
    pub scale: Vec3,
    /// Index into [`GatherContext::shadowed`], or `u32::MAX` when no other light can shadow it.
    pub shadow: u32,
}

/// A hit of a ray on a plane.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Camera distance, chord parameter, plane distance (SPEC section 2), and det(alpha).
    pub t: f32,
    pub a: f32,
    pub r: f32,
    pub det: f32,
}

impl PlaneView {
    pub fn new(plane: &PhotonPlane, scene: &Scene, origin: DVec3, planes_total: usize, shadow: u32) -> Self {
        let light = &scene.lights[plane.light];
        let b = plane.origin - origin;
        let normal = plane.chord.cross(plane.direction);
        let (sin_a, cos_a) = plane.alpha.sin_cos();
        let chord_perp = -sin_a * light.u + cos_a * light.v;
        PlaneView {
            normal: normal.as_vec3(),
            normal_perp: chord_perp.cross(plane.direction).as_vec3(),
            a_axis: plane.direction.cross(b).as_vec3(),
            r_axis: b.cross(plane.chord).as_vec3(),
            t_det: b.dot(normal) as f32,
            frame: PlaneFrame::new(plane.width, plane.alpha, plane.p0, plane.q0, light.width, light.height),
            scale: (plane.power / planes_total as f64).as_vec3(),
            shadow,
        }
    }

    /// Where the ray with unit direction `we` meets the plane within `[t0, t1]`, if it does.
    #[inline(always)]
    pub fn hit(&self, ray: &CameraRay) -> Option<Hit> {
        let det = ray.dir.dot(self.normal);
        if det == 0.0 {
            return None;
        }
        let inv = 1.0 / det;
        let t = self.t_det * inv;
        let a = ray.dir.dot(self.a_axis) * inv;
        let r = ray.dir.dot(self.r_axis) * inv;
        let inside = t >= ray.t0 && t <= ray.t1 && a >= 0.0 && a <= self.frame.width && r >= 0.0;
        inside.then_some(Hit { t, a, r, det })
    }
}

/// The geometry needed to test whether a plane's light path is blocked by another panel.
#[derive(Clone, Copy, Debug)]
pub struct ShadowedPlane {
    /// Chord start y0 relative to the origin, chord direction, sweep direction wl.
    pub origin: Vec3,
    pub chord: Vec3,
    pub direction: Vec3,
    /// Bit k set: light k may block.
    pub occluders: u64,
}

/// A light panel as an occluder, relative to the origin.
#[derive(Clone, Copy, Debug)]
pub struct Occluder {
    pub corner: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    pub n: Vec3,
    pub width: f32,
    pub height: f32,
}

impl Occluder {
    /// Whether the segment `y + s wl`, `s` in `(0, r)`, crosses the panel.
    #[inline]
    pub fn blocks(&self, y: Vec3, wl: Vec3, r: f32) -> bool {
        let denom = wl.dot(self.n);
        if denom == 0.0 {
            return false;
        }
        let s = (self.corner - y).dot(self.n) / denom;
        if !(s > 1e-6 * r && s < r * (1.0 - 1e-6)) {
            return false;
        }
        let rel = y + s * wl - self.corner;
        let (p, q) = (rel.dot(self.u), rel.dot(self.v));
        p >= 0.0 && p <= self.width && q >= 0.0 && q <= self.height
    }
}

/// Extinction, with the common grey case (one exponential per hit) recognised.
#[derive(Clone, Copy, Debug)]
pub struct Extinction {
    pub sigma_t: Vec3,
    pub grey: bool,
}

impl Extinction {
    pub fn new(sigma_t: DVec3) -> Self {
        Extinction { sigma_t: sigma_t.as_vec3(), grey: sigma_t.x == sigma_t.y && sigma_t.y == sigma_t.z }
    }

    /// exp(-sigma_t length) / d: the attenuation of a hit over its denominator, one exponential
    /// and one division when the medium is grey.
    #[inline(always)]
    pub fn transmittance_over(&self, length: f32, d: f32) -> Vec3 {
        if self.grey {
            Vec3::splat(exp_f32(-self.sigma_t.x * length) / d)
        } else {
            Vec3::new(
                exp_f32(-self.sigma_t.x * length) / d,
                exp_f32(-self.sigma_t.y * length) / d,
                exp_f32(-self.sigma_t.z * length) / d,
            )
        }
    }
}

/// exp(x) for x <= 0 in f32, branch-free so that loops over pixels vectorise: x = k ln 2 + r
/// with k = round(x / ln 2) (Cody-Waite, |r| <= ln 2 / 2), exp(r) by its Taylor series to r^7
/// (truncation below 6e-9 relative), and 2^k written into the exponent bits. Below -87 (where
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
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r * (1.0 / 5040.0)))))));
    let scale = f32::from_bits(shifted.to_bits().wrapping_sub(0x4B40_0000 - 127) << 23);
    if x < -87.0 { 0.0 } else { p * scale }
}

/// All planes prepared for rays from one origin.
pub struct GatherContext {
    pub origin: DVec3,
    pub views: Vec<PlaneView>,
    pub shadowed: Vec<ShadowedPlane>,
    pub occluders: Vec<Occluder>,
    pub extinction: Extinction,
}

impl GatherContext {
    /// Prepares `planes` (a set of N = planes.len()) for rays from `origin`.
    pub fn new(scene: &Scene, planes: &[PhotonPlane], origin: DVec3) -> Self {
        let mut ctx = GatherContext::empty(scene, origin);
        ctx.push_planes(scene, planes, planes.len());
        ctx
    }

    /// A context with no planes yet, for [`GatherContext::push_planes`].
    pub fn empty(scene: &Scene, origin: DVec3) -> Self {
        let occluders = scene
            .lights
            .iter()
            .map(|l| Occluder {
                corner: (l.corner - origin).as_vec3(),
                u: l.u.as_vec3(),
                v: l.v.as_vec3(),
                n: l.n.as_vec3(),
                width: l.width as f32,
                height: l.height as f32,
            })
            .collect();
        let extinction = Extinction::new(scene.medium.sigma_t());
        GatherContext { origin, views: Vec::new(), shadowed: Vec::new(), occluders, extinction }
    }

    /// Prepares and appends the next planes of a set of `planes_total` planes.
    pub fn push_planes(&mut self, scene: &Scene, planes: &[PhotonPlane], planes_total: usize) {
        use rayon::prelude::*;
        let masks: Vec<u64> = planes.par_iter().map(|p| possible_occluders(scene, p)).collect();
        let mut shadow_index = Vec::with_capacity(planes.len());
        for (p, &mask) in planes.iter().zip(&masks) {
            if mask == 0 {
                shadow_index.push(u32::MAX);
            } else {
                shadow_index.push(self.shadowed.len() as u32);
                self.shadowed.push(ShadowedPlane {
                    origin: (p.origin - self.origin).as_vec3(),
                    chord: p.chord.as_vec3(),
                    direction: p.direction.as_vec3(),
                    occluders: mask,
                });
            }
        }
        let origin = self.origin;
        self.views.par_extend(
            planes
                .par_iter()
                .zip(shadow_index.par_iter())
                .map(|(p, &s)| PlaneView::new(p, scene, origin, planes_total, s)),
        );
    }

    /// The contribution C of a hit (SPEC section 2): power Tr_cam(t) Tr(x, y') V(x, y') / (N D),
    /// zero when D is zero or the light path is blocked. Never NaN or infinite.
    #[inline(always)]
    pub fn contribution<D: Denominator>(&self, weights: &D, view: &PlaneView, ray: &CameraRay, hit: &Hit) -> Vec3 {
        let local = HitLocal { det: hit.det, det_perp: ray.dir.dot(view.normal_perp), a: hit.a };
        let d = weights.denominator(&view.frame, &local);
        if !(d > 0.0) {
            return Vec3::ZERO;
        }
        if view.shadow != u32::MAX && self.is_shadowed(&self.shadowed[view.shadow as usize], hit) {
            return Vec3::ZERO;
        }
        // Tr_cam(t) Tr(x, y') = exp(-sigma_t ((t - t0) + r)): both segments lie inside the box.
        let c = view.scale * self.extinction.transmittance_over((hit.t - ray.t0) + hit.r, d);
        // D can underflow to a denormal only on a set of probability ~0; drop such a hit rather
        // than let an infinity through.
        if c.x.is_finite() & c.y.is_finite() & c.z.is_finite() { c } else { Vec3::ZERO }
    }

    fn is_shadowed(&self, s: &ShadowedPlane, hit: &Hit) -> bool {
        let y = s.origin + hit.a * s.chord;
        let mut mask = s.occluders;
        while mask != 0 {
            let k = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            if self.occluders[k].blocks(y, s.direction, hit.r) {
                return true;
            }
        }
        false
    }

    /// The estimate for one ray by testing every plane (the reference path for tests), with the
    /// number of hits.
    pub fn gather_brute_force<D: Denominator>(&self, weights: &D, ray: &CameraRay) -> (Vec3, u64) {
        let (mut sum, mut hits) = (Vec3::ZERO, 0);
        for view in &self.views {
            if let Some(hit) = view.hit(ray) {
                hits += 1;
                sum += self.contribution(weights, view, ray, &hit);
            }
        }
        (sum, hits)
    }
}

/// The other lights whose panel crosses the plane's polygon (a bit per light), so that the
/// per-hit visibility test runs only where it can matter. The polygon meets the light's plane
/// in a segment (if it straddles it at all); the light can block only if that segment crosses
/// the rectangle, which is tested by clipping it to the rectangle grown by a small margin.
pub fn possible_occluders(scene: &Scene, plane: &PhotonPlane) -> u64 {
    let poly = plane.polygon_in_box(&scene.medium, 0.0);
    if poly.len < 3 {
        return 0;
    }
    let eps = 1e-9 * scene.medium.diagonal();
    let margin = 1e-6 * scene.medium.diagonal();
    let mut mask = 0u64;
    for (k, light) in scene.lights.iter().enumerate() {
        if k == plane.light {
            continue;
        }
        let pts = poly.points();
        let dist: Vec<f64> = pts.iter().map(|&v| (v - light.corner).dot(light.n)).collect();
        if dist.iter().all(|&d| d > eps) || dist.iter().all(|&d| d < -eps) {
            continue;
        }
        if dist.iter().all(|d| d.abs() <= eps) {
            mask |= 1 << k; // in the light's own plane: leave it to the per-hit test
            continue;
        }
        // Where the polygon's boundary meets the light's plane, in the light's local frame.
        let mut crossing = Vec::with_capacity(4);
        for a in 0..pts.len() {
            let b = (a + 1) % pts.len();
            let (da, db) = (dist[a], dist[b]);
            if da.abs() <= eps {
                crossing.push(light.local(pts[a]));
            } else if (da < 0.0) != (db < 0.0) && db.abs() > eps {
                crossing.push(light.local(pts[a] + (pts[b] - pts[a]) * (da / (da - db))));
            }
        }
        if segment_meets_rectangle(&crossing, light.width, light.height, margin) {
            mask |= 1 << k;
        }
    }
    mask
}

/// Whether the segment spanned by collinear points meets [-m, w + m] x [-m, h + m]
/// (Liang-Barsky clipping of the segment between its two extreme points).
fn segment_meets_rectangle(points: &[(f64, f64)], w: f64, h: f64, m: f64) -> bool {
    let Some(&first) = points.first() else {
        return false;
    };
    // The extreme points along the line through the crossing points.
    let far = points.iter().copied().max_by(|a, b| {
        let da = (a.0 - first.0).hypot(a.1 - first.1);
        da.total_cmp(&(b.0 - first.0).hypot(b.1 - first.1))
    });
    let a = far.unwrap_or(first);
    let b = points
        .iter()
        .copied()
        .max_by(|p, q| (p.0 - a.0).hypot(p.1 - a.1).total_cmp(&(q.0 - a.0).hypot(q.1 - a.1)))
        .unwrap_or(a);
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [(-dx, a.0 + m), (dx, w + m - a.0), (-dy, a.1 + m), (dy, h + m - a.1)] {
        if p == 0.0 {
            if q < 0.0 {
                return false;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    t0 <= t1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photon_plane::sample_planes;

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

    /// Culling occluders per plane never drops one that blocks: the same images as testing
    /// every other light at every hit.
    #[test]
    fn occluder_culling_keeps_every_blocking_light() {
        for file in ["media_scenes/six_lights.toml", "media_scenes/hard/facing_lights_close.toml"] {
            let scene = Scene::load(std::path::Path::new(file)).unwrap();
            let planes = sample_planes(&scene, 4000, 8);
            let o = scene.camera.position;
            let culled = GatherContext::new(&scene, &planes, o);
            let mut all = GatherContext::new(&scene, &planes, o);
            all.shadowed.clear();
            for (p, v) in planes.iter().zip(all.views.iter_mut()) {
                v.shadow = all.shadowed.len() as u32;
                let every_other = ((1u64 << scene.lights.len()) - 1) & !(1 << p.light);
                all.shadowed.push(ShadowedPlane {
                    origin: (p.origin - o).as_vec3(),
                    chord: p.chord.as_vec3(),
                    direction: p.direction.as_vec3(),
                    occluders: every_other,
                });
            }
            if file.contains("six_lights") {
                assert!(culled.shadowed.len() < planes.len() / 4, "{file}: culling should drop most planes");
            }
            let w = crate::weights::Unweighted;
            for j in 0..40 {
                for i in 0..40 {
                    let (x, y) = (
                        scene.camera.width as f64 * (i as f64 + 0.5) / 40.0,
                        scene.camera.height as f64 * (j as f64 + 0.5) / 40.0,
                    );
                    let we = scene.camera.direction(x, y).normalize();
                    let Some((t0, t1)) = scene.camera_segment(o, we).0 else { continue };
                    let ray = CameraRay { dir: we.as_vec3(), t0: t0 as f32, t1: t1 as f32 };
                    assert_eq!(
                        culled.gather_brute_force(&w, &ray),
                        all.gather_brute_force(&w, &ray),
                        "{file} pixel ({x}, {y})"
                    );
                }
            }
        }
    }

    #[test]
    fn hit_solves_the_plane_equation() {
        let text = include_str!("../media_scenes/six_lights.toml");
        let scene = Scene::parse(text, "six_lights.toml", "s").unwrap();
        let planes = sample_planes(&scene, 300, 2);
        let o = scene.camera.position;
        let ctx = GatherContext::new(&scene, &planes, o);
        let mut found = 0;
        for (p, v) in planes.iter().zip(&ctx.views) {
            for k in 0..50 {
                let we = scene.camera.direction(12.8 * k as f64, 7.2 * k as f64).normalize();
                let ray = CameraRay { dir: we.as_vec3(), t0: 0.0, t1: 1e9 };
                if let Some(h) = v.hit(&ray) {
                    found += 1;
                    let x = o + h.t as f64 * we;
                    let on_plane = p.origin + h.a as f64 * p.chord + h.r as f64 * p.direction;
                    assert!((x - on_plane).length() < 1e-3 * (1.0 + h.t as f64), "{x} vs {on_plane}");
                }
            }
        }
        assert!(found > 100);
    }
}
