//! The pixel: its area, the ray sets that sample it and the plane groups they gather
//! (docs/mathematics.md section 8).
//!
//! A pixel's value is the mean of the radiance over its square (a box filter). With `K` ray
//! sets (`--spp K`), ray set `k` crosses every pixel once, at point `k` of a per-pixel
//! Owen-scrambled 2D Sobol sequence, and the `N` planes are split into `K` groups of consecutive
//! indices: plane `i` is gathered only with ray set `floor(i K / N)`. Every plane is used once
//! and still weighs `1/N`, so the pixel gets `K` stratified positions for the cost of one pass
//! ([`ray_set_of_plane`], [`plane_group`], [`ray_set_position`]). The direct emission is
//! integrated over the pixel separately ([`crate::emission`]).

use crate::camera::CameraRay;
use crate::sampling::sobol::{nested_uniform_scramble, sobol_u32};
use crate::sampling::splitmix64;
use crate::scene::Scene;
use glam::DVec3;
use rayon::prelude::*;
use std::ops::Range;
use std::time::Instant;

/// The random stream of the ray sets' positions in their pixels.
const RAY_SET_STREAM: u64 = 0x91A5_E75D;

/// The ray set that plane `i` of a set of `planes` is gathered with when pixels have
/// `ray_sets` ray sets: `floor(i K / N)` (section 8.1). It depends on (i, N, K) alone, so a
/// plane meets the same rays in a render of the whole set and in a render of any range of it.
pub fn ray_set_of_plane(i: usize, planes: usize, ray_sets: u32) -> u32 {
    (i as u128 * ray_sets as u128 / planes.max(1) as u128) as u32
}

/// The planes gathered with ray set `k`: the indices `i` with `floor(i K / N) = k`, that is
/// `ceil(k N / K) .. ceil((k + 1) N / K)`: consecutive blocks, empty when `N < K` leaves a ray
/// set without planes.
pub fn plane_group(k: u32, planes: usize, ray_sets: u32) -> Range<usize> {
    let start = |k: u32| (k as u128 * planes as u128).div_ceil(ray_sets.max(1) as u128) as usize;
    start(k)..start(k + 1)
}

/// Where ray set `k` crosses pixel `pixel` under `seed`, in `[0, 1)^2` of the pixel: point `k`
/// of a 2D Sobol (0,2)-sequence under nested uniform (Owen) scrambling of its own per pixel
/// (hash-based, as the planes', [`crate::sampling::sobol`]), at the centre of the 2^-32 cell the 32-bit
/// point names. Every point is uniform over the pixel (whatever `k`), and the first `2^m` points
/// of a pixel form a (0,m,2)-net: one in each elementary box of area `2^-m` (section 8.1).
#[inline]
pub fn ray_set_position(seed: u64, pixel: u64, k: u32) -> (f64, f64) {
    let scramble = splitmix64(splitmix64(seed ^ RAY_SET_STREAM) ^ pixel);
    let coordinate = |dim: usize, seed: u32| {
        (nested_uniform_scramble(sobol_u32(k, dim), seed) as f64 + 0.5) * (1.0 / 4_294_967_296.0)
    };
    (coordinate(0, scramble as u32), coordinate(1, (scramble >> 32) as u32))
}

/// The pixels each light panel can cover: a box of pixels around its projection, so that a
/// ray through a pixel is tested only against the panels it can cross.
///
/// A panel wholly in front of the camera projects to the convex quadrilateral of its projected
/// corners; its box is that of the corners grown by a pixel (far above the rounding of the
/// projection). A panel reaching behind the camera may cover any pixel.
#[derive(Clone, Debug)]
pub struct PanelFootprints {
    /// Per panel: first and last column, first and last row (inclusive).
    boxes: Vec<[i64; 4]>,
}

impl PanelFootprints {
    pub fn new(scene: &Scene) -> Self {
        let cam = &scene.camera;
        let near = 1e-6 * scene.medium.diagonal();
        let everywhere = [0, cam.width as i64 - 1, 0, cam.height as i64 - 1];
        let boxes = scene
            .lights
            .iter()
            .map(|l| {
                let corners = l.corners().map(|c| cam.to_camera(c));
                if corners.iter().any(|c| !(c.z > near)) {
                    return everywhere;
                }
                let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
                for c in corners {
                    let (x, y) = cam.project(c);
                    (lo[0], lo[1], hi[0], hi[1]) = (lo[0].min(x), lo[1].min(y), hi[0].max(x), hi[1].max(y));
                }
                // Clamped before the conversion, so that a huge projection stays an i64.
                let cell = |v: f64, side: u32| (v.floor().clamp(-2.0, side as f64 + 1.0)) as i64;
                [
                    cell(lo[0] - 1.0, cam.width),
                    cell(hi[0] + 1.0, cam.width),
                    cell(lo[1] - 1.0, cam.height),
                    cell(hi[1] + 1.0, cam.height),
                ]
            })
            .collect();
        PanelFootprints { boxes }
    }

    /// The panels (ascending indices) whose box holds pixel `(i, j)`.
    pub fn over(&self, i: u32, j: u32) -> impl Iterator<Item = usize> + Clone + '_ {
        let (i, j) = (i as i64, j as i64);
        self.boxes
            .iter()
            .enumerate()
            .filter(move |(_, b)| b[0] <= i && i <= b[1] && b[2] <= j && j <= b[3])
            .map(|(k, _)| k)
    }

    /// Whether some panel's box holds pixel `(i, j)`.
    pub fn any_over(&self, i: u32, j: u32) -> bool {
        self.over(i, j).next().is_some()
    }
}

/// The camera ray along unit `we` with its segment in the medium (an empty one, `t0 > t1`,
/// when there is none).
fn camera_ray(we: DVec3, segment: Option<(f64, f64)>) -> CameraRay {
    match segment {
        Some((t0, t1)) => CameraRay { dir: we.as_vec3(), t0: t0 as f32, t1: t1 as f32 },
        None => CameraRay { dir: we.as_vec3(), t0: 1.0, t1: 0.0 },
    }
}

/// The camera rays of ray set `k` (docs/mathematics.md section 8.1): one per pixel, at the set's
/// position in the pixel ([`ray_set_position`]) or through its centre, each with its segment in
/// the medium before the first light panel (only the panels that can cover the pixel are
/// tested: the same answer, sooner). The emission seen directly comes from [`crate::emission`].
pub fn ray_set_rays(scene: &Scene, seed: u64, k: u32, pixel_center: bool) -> Vec<CameraRay> {
    let cam = &scene.camera;
    let w = cam.width as usize;
    let footprints = PanelFootprints::new(scene);
    (0..w * cam.height as usize)
        .into_par_iter()
        .map(|p| {
            let (i, j) = ((p % w) as u32, (p / w) as u32);
            let (sx, sy) = if pixel_center { (0.5, 0.5) } else { ray_set_position(seed, p as u64, k) };
            let we = cam.direction(i as f64 + sx, j as f64 + sy).normalize();
            let first = scene.first_light_among(cam.position, we, f64::INFINITY, footprints.over(i, j));
            camera_ray(we, scene.segment_before(cam.position, we, first.map_or(f64::INFINITY, |(t, _)| t)))
        })
        .collect()
}

/// Which ray sets a [`RaySets`] keeps once made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Keep {
    /// The last set made: a chunked render takes its pieces in plane order and a ray set
    /// serves one group of consecutive planes, so a set is needed again only by the next piece,
    /// and each set is made once in the memory of one.
    Last,
    /// Every set made: passes that come back to the same sets (a render on a time budget), or
    /// several weightings gathered along the same rays (the table).
    All,
}

/// The camera rays of a render's ray sets (one set at pixel centres, which every set shares),
/// made when first asked for: the one cache of ray sets.
pub struct RaySets {
    seed: u64,
    pixel_center: bool,
    count: u32,
    keep: Keep,
    /// The sets kept, by index.
    sets: Vec<(u32, Vec<CameraRay>)>,
    /// Rays made so far (a set made twice counts twice) and the seconds spent making them.
    pub made: u64,
    pub seconds: f64,
}

impl RaySets {
    /// `ray_sets` sets of rays under `seed` (one at pixel centres), none made yet.
    pub fn new(seed: u64, ray_sets: u32, pixel_center: bool, keep: Keep) -> Self {
        let count = if pixel_center { 1 } else { ray_sets.max(1) };
        RaySets { seed, pixel_center, count, keep, sets: Vec::new(), made: 0, seconds: 0.0 }
    }

    /// The rays of ray set `k` (taken modulo the set count), made if need be.
    pub fn rays(&mut self, scene: &Scene, k: u32) -> &[CameraRay] {
        let k = k % self.count;
        let index = match self.sets.iter().position(|(set, _)| *set == k) {
            Some(i) => i,
            None => {
                let t = Instant::now();
                let rays = ray_set_rays(scene, self.seed, k, self.pixel_center);
                self.seconds += t.elapsed().as_secs_f64();
                self.made += rays.len() as u64;
                if self.keep == Keep::Last {
                    self.sets.clear();
                }
                self.sets.push((k, rays));
                self.sets.len() - 1
            }
        };
        &self.sets[index].1
    }

    /// Bytes the rays of `ray_sets` sets take at a resolution (for the memory check).
    pub fn bytes(width: u32, height: u32, ray_sets: u32) -> u64 {
        (width as u64 * height as u64).saturating_mul(ray_sets as u64 * std::mem::size_of::<CameraRay>() as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_are_the_planes_of_their_ray_set() {
        for (planes, ray_sets) in [(40_960usize, 16u32), (1000, 16), (7, 16), (16, 16), (5, 1), (100_003, 7)] {
            let mut next = 0;
            for k in 0..ray_sets {
                let g = plane_group(k, planes, ray_sets);
                assert_eq!(g.start, next, "{planes} {ray_sets} {k}");
                for i in g.clone() {
                    assert_eq!(ray_set_of_plane(i, planes, ray_sets), k);
                }
                // Sizes differ by at most one.
                assert!(g.len() == planes / ray_sets as usize || g.len() == planes.div_ceil(ray_sets as usize));
                next = g.end;
            }
            assert_eq!(next, planes);
        }
        assert_eq!(plane_group(3, 40_960, 16), 7680..10_240);
    }

    #[test]
    fn the_first_ray_sets_of_a_pixel_are_a_net() {
        for pixel in 0..50u64 {
            for m in 0..=6u32 {
                let n = 1u32 << m;
                let points: Vec<(f64, f64)> = (0..n).map(|k| ray_set_position(9, pixel, k)).collect();
                // Every elementary box 2^-a x 2^-(m-a) holds one point.
                for a in 0..=m {
                    let mut seen = vec![false; n as usize];
                    for &(x, y) in &points {
                        assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
                        let cell =
                            ((x * (1u64 << a) as f64) as usize) << (m - a) | (y * (1u64 << (m - a)) as f64) as usize;
                        assert!(!seen[cell], "pixel {pixel}: two of {n} points in one box ({a})");
                        seen[cell] = true;
                    }
                }
            }
        }
        assert_ne!(ray_set_position(1, 5, 0), ray_set_position(1, 6, 0));
        assert_ne!(ray_set_position(1, 5, 0), ray_set_position(2, 5, 0));
    }
}
