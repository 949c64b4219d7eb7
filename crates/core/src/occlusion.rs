//! The visibility test of a hit: which other light panels may shadow a photon plane's light
//! paths, found once per plane, and the branch-free per-hit test against them
//! (docs/mathematics.md section 2.3).

use crate::light::RectLight;
use crate::photon_plane::{PhotonPlane, Polygon, clip_segment};
use crate::scene::Scene;
use crate::simd::Lanes;
use glam::{DVec2, DVec3};

/// A light panel that may block the light paths of one plane, as a function of the chord
/// parameter a of the light vertex y' = y0 + a d: the segment from y' along wl meets the
/// panel's plane at distance t(a) = t0 + a t_a, at the panel-local point
/// (p(a), q(a)) = (p0 + a p_a, q0 + a q_a) (all linear in a, made once per plane in f64).
/// A hit at plane distance r is in shadow when 0 < t < r (with a relative margin of 1e-6 at
/// both ends, so that neither the light itself nor the hit's own panel counts) and the point
/// lies on the panel, edges included (docs/mathematics.md section 2.3).
///
/// Plain data (`repr(C)`): it crosses to the GPU as it is (`gpu/gather.wgsl`'s `Occluder`).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Occluder {
    pub t0: f32,
    pub t_a: f32,
    pub p0: f32,
    pub p_a: f32,
    pub q0: f32,
    pub q_a: f32,
    pub width: f32,
    pub height: f32,
}

impl Occluder {
    /// The panel `light` against the plane's light paths; `None` if the sweep direction is
    /// parallel to the panel (its paths can never cross it).
    pub fn new(plane: &PhotonPlane, light: &RectLight) -> Option<Self> {
        let denom = plane.direction.dot(light.n);
        if denom == 0.0 {
            return None;
        }
        let rel = plane.origin - light.corner;
        let (t0, t_a) = (-rel.dot(light.n) / denom, -plane.chord.dot(light.n) / denom);
        let along = |axis: DVec3| {
            let w = plane.direction.dot(axis);
            ((rel.dot(axis) + t0 * w) as f32, (plane.chord.dot(axis) + t_a * w) as f32)
        };
        let ((p0, p_a), (q0, q_a)) = (along(light.u), along(light.v));
        Some(Occluder {
            t0: t0 as f32,
            t_a: t_a as f32,
            p0,
            p_a,
            q0,
            q_a,
            width: light.width as f32,
            height: light.height as f32,
        })
    }

    /// Whether the panel blocks the path from the light vertex at chord parameter `a` to the
    /// hit at plane distance `r`.
    #[inline(always)]
    pub fn blocks(&self, a: f32, r: f32) -> bool {
        self.blocks_lanes::<1, f32>(a, r)
    }

    /// [`Occluder::blocks`] for a block of hits, lane by lane.
    #[inline(always)]
    pub fn blocks_lanes<const L: usize, V: Lanes<L>>(&self, a: V, r: V) -> V::Mask {
        let s = V::splat;
        let t = s(self.t0) + a * s(self.t_a);
        let (p, q) = (s(self.p0) + a * s(self.p_a), s(self.q0) + a * s(self.q_a));
        t.gt(s(1e-6) * r)
            & t.lt(r * s(1.0 - 1e-6))
            & p.ge(s(0.0))
            & p.le(s(self.width))
            & q.ge(s(0.0))
            & q.le(s(self.height))
    }
}

/// The other lights whose panel crosses the plane's polygon (a bit per light), so that the
/// per-hit visibility test runs only where it can matter. The polygon meets the light's plane
/// in a segment (if it straddles it at all); the light can block only if that segment crosses
/// the rectangle, which is tested by clipping it to the rectangle grown by a small margin.
pub fn possible_occluders(scene: &Scene, plane: &PhotonPlane) -> u64 {
    occluders_of_polygon(scene, plane, &plane.polygon_in_box(&scene.medium, 0.0))
}

/// [`possible_occluders`] of the plane's polygon `poly` in the medium box (a polygon of the
/// plane's own plane); the raster and the
/// GPU give the box polygon they project ([`crate::raster::box_polygon`], the box grown by a
/// millionth of its diagonal), made once for both. The grown polygon holds the exact one, so
/// its mask holds every light the exact polygon's names (tested), and perhaps one whose plane
/// passes within the margin: a light tested per hit for nothing, never one left out (on every
/// scene of media_scenes, 200,000 planes each, no mask differed at all).
pub fn occluders_of_polygon(scene: &Scene, plane: &PhotonPlane, poly: &Polygon<DVec3>) -> u64 {
    occluders_with(scene, plane, poly, Some(CLEAR_MARGINS))
}

/// How far, in margins, a light's corners must all lie to one side of the photon plane for
/// [`occluders_of_polygon`] to leave it out before finding its crossings. A light the crossings
/// name has a point of its grown rectangle on a line of the plane: local coordinates within a
/// margin of the rectangle's, along edges whose cosine may reach 1e-6 (the scene's check), so
/// each coordinate of the point along the edges within two margins of the rectangle (the skew
/// adds at most 1e-6 of an edge, a margin), and the point within 2 sqrt(2) margins of it, plus
/// eps where a polygon's vertex is taken as on the light's plane. Four leaves a margin of room
/// (a light built at that bound, skewed, is named: tested; at two margins it would be lost).
const CLEAR_MARGINS: f64 = 4.0;

/// [`occluders_of_polygon`], a light left out first where its corners all lie more than
/// `clear_margins` margins to one side of the plane (`None`: no light left out so; the tests
/// compare the two).
fn occluders_with(scene: &Scene, plane: &PhotonPlane, poly: &Polygon<DVec3>, clear_margins: Option<f64>) -> u64 {
    if poly.len < 3 {
        return 0;
    }
    let eps = 1e-9 * scene.medium.diagonal();
    let margin = 1e-6 * scene.medium.diagonal();
    let mut mask = 0u64;
    let pts = poly.points();
    // On the stack, not in vectors: this runs for every other light of every plane.
    let mut dist = [0.0f64; Polygon::<DVec3>::CAPACITY];
    let mut crossing = [(0.0f64, 0.0f64); Polygon::<DVec3>::CAPACITY];
    // A light whose rectangle stays clear of the photon plane's infinite plane cannot cross its
    // polygon: three dot products instead of one a vertex and the crossings. The mask is the
    // same but where the polygon lies within eps of the light's own plane and the light far
    // from it (named below, for nothing: its per-hit test finds no crossing).
    let normal = plane.normal();
    let clear = clear_margins.map(|c| c * margin * normal.length());
    for (k, light) in scene.lights.iter().enumerate() {
        if k == plane.light {
            continue;
        }
        if let Some(clear) = clear {
            let (d0, du, dv) = (
                (light.corner - plane.origin).dot(normal),
                light.width * light.u.dot(normal),
                light.height * light.v.dot(normal),
            );
            if d0 + du.min(0.0) + dv.min(0.0) > clear || d0 + du.max(0.0) + dv.max(0.0) < -clear {
                continue;
            }
        }
        let dist = &mut dist[..pts.len()];
        for (d, &v) in dist.iter_mut().zip(pts) {
            *d = (v - light.corner).dot(light.n);
        }
        if dist.iter().all(|&d| d > eps) || dist.iter().all(|&d| d < -eps) {
            continue;
        }
        if dist.iter().all(|d| d.abs() <= eps) {
            mask |= 1 << k; // in the light's own plane: leave it to the per-hit test
            continue;
        }
        // Where the polygon's boundary meets the light's plane, in the light's local frame
        // (at most one point per edge).
        let mut crossings = 0;
        for a in 0..pts.len() {
            let b = if a + 1 == pts.len() { 0 } else { a + 1 };
            let (da, db) = (dist[a], dist[b]);
            if da.abs() <= eps {
                crossing[crossings] = light.local(pts[a]);
                crossings += 1;
            } else if (da < 0.0) != (db < 0.0) && db.abs() > eps {
                crossing[crossings] = light.local(pts[a] + (pts[b] - pts[a]) * (da / (da - db)));
                crossings += 1;
            }
        }
        if segment_meets_rectangle(&crossing[..crossings], light.width, light.height, margin) {
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
    // The extreme points along the line through the crossing points (by squared distance:
    // the same order as the distance, without a square root).
    let farthest = |from: (f64, f64)| {
        let far = |p: &(f64, f64)| (p.0 - from.0).powi(2) + (p.1 - from.1).powi(2);
        points.iter().copied().max_by(|p, q| far(p).total_cmp(&far(q))).unwrap_or(from)
    };
    let a = farthest(first);
    let b = farthest(a);
    let (a, b) = (DVec2::new(a.0, a.1), DVec2::new(b.0, b.1));
    clip_segment(a, b, DVec2::splat(-m), DVec2::new(w + m, h + m)).is_some()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photon_plane::sample_planes;
    use crate::raster::box_polygon;
    use rand::{Rng, SeedableRng};

    /// Whether the segment from `y` to `x` crosses the light's rectangle (edges included)
    /// strictly between its ends: the ground truth of a shadow, written apart from
    /// [`Occluder`]'s linear form.
    fn segment_crosses(light: &RectLight, y: DVec3, x: DVec3) -> bool {
        let (dy, dx) = ((y - light.corner).dot(light.n), (x - light.corner).dot(light.n));
        if !((dy > 0.0 && dx < 0.0) || (dy < 0.0 && dx > 0.0)) {
            return false;
        }
        let (p, q) = light.local(y + (x - y) * (dy / (dy - dx)));
        (0.0..=light.width).contains(&p) && (0.0..=light.height).contains(&q)
    }

    /// Every light that blocks a light path of a plane is in the plane's mask, from the exact
    /// polygon in the box ([`possible_occluders`]) and from the grown one the renderer projects
    /// ([`box_polygon`]): light paths sampled over each plane (a point of the chord, a distance
    /// along wl whose end lies in the medium box), each tested against every other light by
    /// [`segment_crosses`]. Scenes where lights block each other, face each other closely, lie
    /// on the box's faces or are seen edge-on, and the benchmark.
    #[test]
    fn every_light_that_blocks_a_path_is_in_the_mask() {
        let scenes = [
            ("six_lights", include_str!("../../../media_scenes/six_lights.toml")),
            ("two_lights_one_blocker", include_str!("../../../media_scenes/two_lights_one_blocker.toml")),
            ("facing_lights_close", include_str!("../../../media_scenes/hard/facing_lights_close.toml")),
            ("edge_on_light", include_str!("../../../media_scenes/hard/edge_on_light.toml")),
        ];
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        for (name, text) in scenes {
            let scene = crate::scene::Scene::parse(text, name, name).unwrap();
            let medium = &scene.medium;
            let (mut blocked, mut left_out) = (0usize, 0usize);
            for plane in sample_planes(&scene, Default::default(), 4_000, 5) {
                let masks = [
                    possible_occluders(&scene, &plane),
                    occluders_of_polygon(&scene, &plane, &box_polygon(&plane, medium)),
                ];
                for _ in 0..64 {
                    let y = plane.origin + rng.random::<f64>() * plane.width * plane.chord;
                    let x = y + rng.random::<f64>() * medium.diagonal() * plane.direction;
                    if (x.cmplt(medium.min) | x.cmpgt(medium.max)).any() {
                        continue;
                    }
                    for (k, light) in scene.lights.iter().enumerate() {
                        if k != plane.light && segment_crosses(light, y, x) {
                            blocked += 1;
                            left_out += masks.iter().filter(|&&m| m & (1 << k) == 0).count();
                        }
                    }
                }
            }
            println!("{name}: {blocked} paths blocked, {left_out} by a light left out of a mask");
            assert_eq!(left_out, 0, "{name}: a light that blocks a path is left out");
            assert!(blocked > 0, "{name}: no path to test");
        }
    }

    /// Leaving out the lights clear of the plane changes no mask: on every scene of
    /// media_scenes, 20,000 planes each, exact and grown polygons, the masks with it are those
    /// without it. The comparison can tell: with no margin at all some masks differ.
    #[test]
    fn leaving_out_the_lights_clear_of_the_plane_changes_no_mask() {
        let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../../media_scenes");
        let mut files: Vec<_> = std::fs::read_dir(root).unwrap().map(|e| e.unwrap().path()).collect();
        files.extend(std::fs::read_dir(format!("{root}/hard")).unwrap().map(|e| e.unwrap().path()));
        files.retain(|p| p.extension().is_some_and(|e| e == "toml"));
        assert!(files.len() >= 10, "the scenes of media_scenes: {files:?}");
        let (mut differ, mut differ_at_no_margin) = (0, 0);
        for file in files {
            let scene = crate::scene::Scene::load(&file).unwrap();
            for plane in sample_planes(&scene, Default::default(), 20_000, 3) {
                for poly in [plane.polygon_in_box(&scene.medium, 0.0), box_polygon(&plane, &scene.medium)] {
                    let all = occluders_with(&scene, &plane, &poly, None);
                    differ += (occluders_of_polygon(&scene, &plane, &poly) != all) as usize;
                    differ_at_no_margin += (occluders_with(&scene, &plane, &poly, Some(0.0)) != all) as usize;
                }
            }
        }
        println!("{differ} masks differ; {differ_at_no_margin} at no margin");
        assert_eq!(differ, 0, "a mask changed");
        assert!(differ_at_no_margin > 0, "the comparison cannot tell a margin from none");
    }

    /// A light at the bound of [`CLEAR_MARGINS`]: large, its edges skewed as far as a scene may
    /// have them (cosine 1e-6), and placed so that the far corner of its grown rectangle just
    /// meets each plane's polygon, the step from its corner along the plane's normal. The
    /// crossings name it on nearly every plane, and so does the mask; two margins would lose
    /// it (the construction reaches beyond them).
    #[test]
    fn a_skewed_light_at_the_margin_stays_in_the_mask() {
        let text = include_str!("../../../media_scenes/six_lights.toml");
        let base = crate::scene::Scene::parse(text, "six_lights", "six_lights").unwrap();
        let diag = base.medium.diagonal();
        let margin = 1e-6 * diag;
        for size in [0.5, 0.7] {
            let (mut named, mut kept, mut kept_at_two) = (0, 0, 0);
            let planes = sample_planes(&base, Default::default(), 200, 9);
            for plane in &planes {
                let poly = box_polygon(plane, &base.medium);
                if poly.len < 3 {
                    continue;
                }
                let centre = poly.points().iter().copied().sum::<DVec3>() / poly.len as f64;
                let (e1, e2) = (plane.normal().normalize(), plane.chord);
                let u = (e1 + e2).normalize();
                let v = ((e1 - e2).normalize() - 1e-6 * u).normalize();
                let cos = u.dot(v);
                let (w, h) = (size * diag, size * diag);
                // The point at local coordinates (w + m, h + m), just inside the grown
                // rectangle, at the polygon's centre.
                let (p, q) = (w + 0.999 * margin, h + 0.999 * margin);
                let (a, b) = ((p - cos * q) / (1.0 - cos * cos), (q - cos * p) / (1.0 - cos * cos));
                let light = RectLight {
                    name: "at the margin".into(),
                    corner: centre - a * u - b * v,
                    u,
                    v,
                    n: u.cross(v).normalize(),
                    width: w,
                    height: h,
                    radiance: DVec3::ONE,
                };
                let mut scene = base.clone();
                scene.lights.push(light);
                let k = scene.lights.len() - 1;
                let bit = |mask: u64| mask >> k & 1 == 1;
                if bit(occluders_with(&scene, plane, &poly, None)) {
                    named += 1;
                    kept += bit(occluders_of_polygon(&scene, plane, &poly)) as usize;
                    kept_at_two += bit(occluders_with(&scene, plane, &poly, Some(2.0))) as usize;
                }
            }
            println!(
                "size {size}: named on {named} of {} planes, kept {kept}, at two margins {kept_at_two}",
                planes.len()
            );
            assert!(named >= planes.len() / 2, "size {size}: the construction misses the polygons");
            assert_eq!(kept, named, "size {size}: a light at the margin left out");
            assert!(kept_at_two < named, "size {size}: the construction stays within two margins");
        }
    }
}
