//! One camera ray against one photon plane: the hit test and the weighted contribution
//! `C = K / (N P_l D)` of docs/mathematics.md section 2. Everything here is f32 and relative to
//! the ray origin, prepared once per plane so that a hit costs a few dot products and one
//! exponential.
//!
//! The per-hit arithmetic is written once, here, branch-free: [`PlaneView::crossing`] (where
//! the ray meets the plane and whether that is a hit) and [`PlaneView::contribution`] (D, the
//! transmittance and the finite check). Every path that gathers calls these two and nothing
//! else: the vector kernels of [`crate::kernel`], the per-hit path [`GatherContext::gather_one`]
//! (which adds only the visibility test of planes another panel can shadow), the BVH and the
//! brute-force loop. So images are bit-identical whichever path found a hit.

use crate::light::Rectangle;
use crate::numeric::exp_f32;
use crate::photon_plane::PhotonPlane;
use crate::scene::Scene;
use crate::weights::{Denominator, HitLocal, PlaneFrame};
use glam::{DVec3, Vec3};

/// A camera ray: unit direction (f32, origin at the camera) and its segment `[t0, t1]` inside
/// the medium before the first light panel (empty, `t0 > t1`, when there is none).
#[derive(Clone, Copy, Debug, Default)]
pub struct CameraRay {
    pub dir: Vec3,
    pub t0: f32,
    pub t1: f32,
}

/// A plane prepared for rays from one origin `o`.
///
/// With b = y0 - o and the plane normal n_P = d x wl, the hit `o + t we = y0 + a d + r wl` solves
/// by Cramer's rule with the common determinant det = we . n_P (det(alpha) of section 2):
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
    /// Index into [`GatherContext::shadowed`], or [`PlaneView::UNSHADOWED`].
    pub shadow: u32,
}

/// Where a ray meets a plane, computed whether or not it hits (the values are then harmless
/// and unused): camera distance t, chord parameter a, plane distance r (section 2) and
/// det(alpha).
#[derive(Clone, Copy, Debug)]
pub struct Crossing {
    pub hit: bool,
    pub det: f32,
    pub t: f32,
    pub a: f32,
    pub r: f32,
}

impl PlaneView {
    /// No other light panel can shadow the plane.
    pub const UNSHADOWED: u32 = u32::MAX;

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

    /// Where the ray with unit direction `dir` meets the plane, and whether that is a hit: inside
    /// `[t0, t1]`, on the chord (`0 <= a <= width`) and strictly in front of the light (r > 0).
    ///
    /// A hit at r = 0 lies on the light itself: only a camera ray lying in the light's own plane
    /// meets planes there, and along such a ray cos(theta_y) = 0, so the integrand of section 1
    /// vanishes; counting the hit would add light that is not there.
    #[inline(always)]
    pub fn crossing(&self, dir: [f32; 3], t0: f32, t1: f32) -> Crossing {
        let [x, y, z] = dir;
        let det = x * self.normal.x + y * self.normal.y + z * self.normal.z;
        let inv = 1.0 / det;
        let t = self.t_det * inv;
        let a = (x * self.a_axis.x + y * self.a_axis.y + z * self.a_axis.z) * inv;
        let r = (x * self.r_axis.x + y * self.r_axis.y + z * self.r_axis.z) * inv;
        let hit = (det != 0.0) & (t >= t0) & (t <= t1) & (a >= 0.0) & (a <= self.frame.width) & (r > 0.0);
        Crossing { hit, det, t, a, r }
    }

    /// The contribution C of a crossing (section 2): `power Tr_cam(t) Tr(x, y') / (N D)` with
    /// `Tr_cam(t) Tr(x, y') = exp(-sigma_t ((t - t0) + r))` (both segments lie inside the box).
    /// Zero unless the crossing is a hit with D > 0 and a finite value: D vanishes, or underflows
    /// to a denormal, only on a set of probability ~0, and such a hit adds nothing rather than
    /// an infinity. Visibility is the caller's (only planes another panel can shadow need it).
    /// `GREY`: one exponential serves the three channels.
    #[inline(always)]
    pub fn contribution<D: Denominator, const GREY: bool>(
        &self,
        weights: &D,
        sigma_t: Vec3,
        dir: [f32; 3],
        t0: f32,
        c: &Crossing,
    ) -> [f32; 3] {
        let [x, y, z] = dir;
        let perp = self.normal_perp;
        let det_perp = x * perp.x + y * perp.y + z * perp.z;
        let d = weights.denominator(&self.frame, &HitLocal { det: c.det, det_perp, a: c.a });
        let length = (c.t - t0) + c.r;
        let scale = self.scale;
        let (cr, cg, cb) = if GREY {
            let q = exp_f32(-sigma_t.x * length) / d;
            (scale.x * q, scale.y * q, scale.z * q)
        } else {
            (
                scale.x * (exp_f32(-sigma_t.x * length) / d),
                scale.y * (exp_f32(-sigma_t.y * length) / d),
                scale.z * (exp_f32(-sigma_t.z * length) / d),
            )
        };
        let keep = c.hit & (d > 0.0) & cr.is_finite() & cg.is_finite() & cb.is_finite();
        [if keep { cr } else { 0.0 }, if keep { cg } else { 0.0 }, if keep { cb } else { 0.0 }]
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
}

/// Counters from one gathering pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GatherStats {
    /// Ray-plane tests made and hits found.
    pub tests: u64,
    pub hits: u64,
}

impl std::ops::AddAssign for GatherStats {
    fn add_assign(&mut self, o: Self) {
        self.tests += o.tests;
        self.hits += o.hits;
    }
}

/// All planes prepared for rays from one origin.
pub struct GatherContext {
    pub origin: DVec3,
    pub views: Vec<PlaneView>,
    pub shadowed: Vec<ShadowedPlane>,
    /// Every light panel as an occluder, relative to the origin.
    pub occluders: Vec<Rectangle<f32>>,
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
            .map(|l| Rectangle {
                corner: (l.corner - origin).as_vec3().to_array(),
                u: l.u.as_vec3().to_array(),
                v: l.v.as_vec3().to_array(),
                n: l.n.as_vec3().to_array(),
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
                shadow_index.push(PlaneView::UNSHADOWED);
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

    /// The per-hit path: one ray against one plane. `None` if it misses; otherwise its
    /// contribution, zero when another panel blocks the light path. The same arithmetic as the
    /// vector kernels, plus the visibility test.
    #[inline]
    pub fn gather_one<D: Denominator>(&self, weights: &D, view: &PlaneView, ray: &CameraRay) -> Option<Vec3> {
        let dir = ray.dir.to_array();
        let c = view.crossing(dir, ray.t0, ray.t1);
        if !c.hit {
            return None;
        }
        if view.shadow != PlaneView::UNSHADOWED && self.is_shadowed(&self.shadowed[view.shadow as usize], &c) {
            return Some(Vec3::ZERO);
        }
        let sigma_t = self.extinction.sigma_t;
        let value = if self.extinction.grey {
            view.contribution::<D, true>(weights, sigma_t, dir, ray.t0, &c)
        } else {
            view.contribution::<D, false>(weights, sigma_t, dir, ray.t0, &c)
        };
        Some(Vec3::from_array(value))
    }

    /// Whether another panel blocks the segment from the light vertex y' to the hit point.
    fn is_shadowed(&self, s: &ShadowedPlane, c: &Crossing) -> bool {
        let y = (s.origin + c.a * s.chord).to_array();
        let wl = s.direction.to_array();
        let mut mask = s.occluders;
        while mask != 0 {
            let k = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            if self.occluders[k].crossing(y, wl, 1e-6 * c.r, c.r * (1.0 - 1e-6)).is_some() {
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
            if let Some(c) = self.gather_one(weights, view, ray) {
                hits += 1;
                sum += c;
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
    use crate::sampling::Sampler;

    /// Culling occluders per plane never drops one that blocks: the same images as testing
    /// every other light at every hit.
    #[test]
    fn occluder_culling_keeps_every_blocking_light() {
        for file in ["media_scenes/six_lights.toml", "media_scenes/hard/facing_lights_close.toml"] {
            let scene =
                Scene::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(file)).unwrap();
            let planes = sample_planes(&scene, Sampler::Independent, 4000, 8);
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
        let text = include_str!("../../../media_scenes/six_lights.toml");
        let scene = Scene::parse(text, "six_lights.toml", "s").unwrap();
        let planes = sample_planes(&scene, Sampler::default(), 300, 2);
        let o = scene.camera.position;
        let ctx = GatherContext::new(&scene, &planes, o);
        let mut found = 0;
        for (p, v) in planes.iter().zip(&ctx.views) {
            for k in 0..50 {
                let we = scene.camera.direction(12.8 * k as f64, 7.2 * k as f64).normalize();
                let ray = CameraRay { dir: we.as_vec3(), t0: 0.0, t1: 1e9 };
                let h = v.crossing(ray.dir.to_array(), ray.t0, ray.t1);
                if h.hit {
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
