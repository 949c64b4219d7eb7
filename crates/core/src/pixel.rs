//! The pixel: its area, the ray sets that sample it and the plane groups they gather
//! (docs/mathematics.md section 8).
//!
//! A pixel's value is the mean of the radiance over its square (a box filter). With `J` ray
//! sets (`--spp J`), ray set `k` crosses every pixel once, at point `k` of a per-pixel
//! Owen-scrambled 2D Sobol sequence, and the `N` planes are split into `J` groups of consecutive
//! indices: plane `i` is gathered only with ray set `floor(i J / N)`. Every plane is used once
//! and still weighs `1/N`, so the pixel gets `J` stratified positions for the cost of one pass
//! ([`ray_set_of_plane`], [`plane_group`], [`ray_set_position`]). The direct emission is
//! integrated over the pixel separately ([`crate::emission`]).

use crate::camera::{CameraRay, RayRowFn};
use crate::control::Control;
use crate::light::Rectangle;
use crate::numeric::dot;
use crate::sampling::sobol::{nested_uniform_scramble, sobol_u32};
use crate::sampling::splitmix64;
use crate::scene::Scene;
use glam::DVec3;
use rayon::prelude::*;
use std::ops::Range;
use std::sync::Arc;
use std::time::Instant;

/// The random stream of the ray sets' positions in their pixels.
const RAY_SET_STREAM: u64 = 0x91A5_E75D;

/// The ray set that plane `i` of a set of `planes` is gathered with when pixels have
/// `ray_sets` ray sets: `floor(i J / N)` (section 8.1). It depends on (i, N, J) alone, so a
/// plane meets the same rays in a render of the whole set and in a render of any range of it.
pub fn ray_set_of_plane(i: usize, planes: usize, ray_sets: u32) -> u32 {
    (i as u128 * ray_sets as u128 / planes.max(1) as u128) as u32
}

/// The planes gathered with ray set `k`: the indices `i` with `floor(i J / N) = k`, that is
/// `ceil(k N / J) .. ceil((k + 1) N / J)`: consecutive blocks, empty when `N < J` leaves a ray
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

    /// Each panel's box: first and last column, first and last row (inclusive).
    pub fn boxes(&self) -> &[[i64; 4]] {
        &self.boxes
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

/// One camera ray of ray set `k` through pixel `(i, j)` (pixel index `p`), the panels that can
/// cover the pixel tested: the reference form of [`ray_set_rays`], which gives the same bits.
fn ray_set_ray(
    scene: &Scene,
    footprints: &PanelFootprints,
    seed: u64,
    k: u32,
    pixel_center: bool,
    p: usize,
) -> CameraRay {
    let cam = &scene.camera;
    let w = cam.width as usize;
    let (i, j) = ((p % w) as u32, (p / w) as u32);
    let (sx, sy) = if pixel_center { (0.5, 0.5) } else { ray_set_position(seed, p as u64, k) };
    let we = cam.direction(i as f64 + sx, j as f64 + sy).normalize();
    let first = scene.first_light_among(cam.position, we, f64::INFINITY, footprints.over(i, j));
    camera_ray(we, scene.segment_before(cam.position, we, first.map_or(f64::INFINITY, |(t, _)| t)))
}

/// The camera rays of ray set `k` (docs/mathematics.md section 8.1): one per pixel, at the set's
/// position in the pixel ([`ray_set_position`]) or through its centre, each with its segment in
/// the medium before the first light panel (only the panels that can cover the pixel are
/// tested: the same answer, sooner). The emission seen directly comes from [`crate::emission`].
///
/// Rows in parallel, each in blocks of [`RAY_LANES`] pixels by [`RayRow::block`]: the same f64
/// operations in the same order as [`ray_set_ray`] (bit-identical rays, tested), with what is the
/// same for every pixel of the set made once and no branch, so that a block runs in vector
/// registers, the panel test included. It was 50 ns of CPU a ray (a fifth of the benchmark's
/// time), most of it in scalar f64 divisions and the per-pixel hash; the panel test, pixel by
/// pixel where a panel's box lay, was then 2-3% more in a profile.
pub fn ray_set_rays(scene: &Scene, seed: u64, k: u32, pixel_center: bool) -> Vec<CameraRay> {
    let mut rays = Vec::new();
    ray_set_rays_into(scene, seed, k, pixel_center, &mut rays);
    rays
}

/// [`ray_set_rays`] into `rays`, whose buffer is reused when it has the image's size: every ray
/// is written, and a fresh buffer of a few megabytes costs its page faults again (3% of the
/// benchmark's CPU time when each set had its own).
pub fn ray_set_rays_into(scene: &Scene, seed: u64, k: u32, pixel_center: bool, rays: &mut Vec<CameraRay>) {
    ray_set_rays_in(scene, seed, k, pixel_center, rays, Control::none())
}

/// [`ray_set_rays_into`] with its rows, units of work, recorded on `control`'s strand
/// ([`crate::schedule`]).
fn ray_set_rays_in(scene: &Scene, seed: u64, k: u32, pixel_center: bool, rays: &mut Vec<CameraRay>, control: Control) {
    let cam = &scene.camera;
    let (w, n) = (cam.width as usize, cam.width as usize * cam.height as usize);
    if rays.len() != n {
        // A fresh buffer written in parallel, then every ray written: `vec![...; n]` wrote it
        // on one thread, 4 ms at 640x360 (4.6 MB and its page faults) before each new set's
        // rows could start, twice a render of the benchmark (the schedule's records).
        *rays = control.map_units("ray buffer", n, w, |_| CameraRay::default());
    }
    ray_set_rays_to(scene, seed, k, pixel_center, rays, control)
}

/// [`ray_set_rays_in`] into `rays`, one per pixel (every one written), row by row in parallel.
fn ray_set_rays_to(scene: &Scene, seed: u64, k: u32, pixel_center: bool, rays: &mut [CameraRay], control: Control) {
    let w = scene.camera.width as usize;
    assert_eq!(rays.len(), w * scene.camera.height as usize, "a ray per pixel");
    with_ray_rows(scene, seed, k, pixel_center, control, |row| {
        rays.par_chunks_mut(w).enumerate().for_each(|(j, out)| row(j, out));
    });
}

/// Calls `with` with the function that writes row `j` of ray set `k` (its units of work
/// recorded on `control`'s strand): for [`ray_set_rays_in`], and for memory that is not a
/// slice of rays, such as the GPU's upload buffer, written row by row
/// ([`crate::gpu::GpuRays::made`]). The same rays either way.
pub fn with_ray_rows<R>(
    scene: &Scene,
    seed: u64,
    k: u32,
    pixel_center: bool,
    control: Control,
    with: impl FnOnce(RayRowFn) -> R,
) -> R {
    let w = scene.camera.width as usize;
    let footprints = PanelFootprints::new(scene);
    let maker = RayRow::new(scene, &footprints, seed, k, pixel_center);
    let section = control.section("rays");
    let row = |j: usize, row: &mut [CameraRay]| {
        assert_eq!(row.len(), w, "a row of rays");
        section.unit(|| {
            let blocks = w / RAY_LANES * RAY_LANES;
            for i in (0..blocks).step_by(RAY_LANES) {
                maker.run_block(j, i, (&mut row[i..i + RAY_LANES]).try_into().unwrap());
            }
            for (i, ray) in row.iter_mut().enumerate().skip(blocks) {
                *ray = ray_set_ray(scene, &footprints, seed, k, pixel_center, j * w + i);
            }
        })
    };
    let out = with(&row);
    section.close();
    out
}

/// Pixels per block of [`ray_set_rays`]: one AVX-512 vector of f64, two AVX2 ones.
pub const RAY_LANES: usize = 8;

/// What every ray of a set shares: the camera's frame and scale, the box, the light panels, and
/// the set's Sobol point before its per-pixel scramble.
struct RayRow {
    forward: [f64; 3],
    right: [f64; 3],
    up: [f64; 3],
    tan_half_fov: f64,
    aspect: f64,
    width: f64,
    height: f64,
    /// `lo - o` and `hi - o` per axis, and whether the camera lies outside the slab of an axis
    /// (which matters only for a direction parallel to it).
    lo: [f64; 3],
    hi: [f64; 3],
    outside: [bool; 3],
    origin: [f64; 3],
    panels: Vec<PanelTest>,
    pixel_center: bool,
    scramble_base: u64,
    sobol: [u32; 2],
    image_width: usize,
}

/// A light panel as [`RayRow::block`] tests it: [`crate::light::RectLight::intersect`]'s
/// rectangle, its `(corner - o) . n` (the same for every camera ray) and the pixels it can cover.
struct PanelTest {
    rect: Rectangle<f64>,
    to_plane: f64,
    footprint: [i64; 4],
}

impl RayRow {
    fn new(scene: &Scene, footprints: &PanelFootprints, seed: u64, k: u32, pixel_center: bool) -> Self {
        let cam = &scene.camera;
        let (o, m) = (cam.position.to_array(), &scene.medium);
        let (min, max) = (m.min.to_array(), m.max.to_array());
        RayRow {
            forward: cam.forward.to_array(),
            right: cam.right.to_array(),
            up: cam.up.to_array(),
            tan_half_fov: cam.tan_half_fov,
            aspect: cam.aspect(),
            width: cam.width as f64,
            height: cam.height as f64,
            lo: std::array::from_fn(|a| min[a] - o[a]),
            hi: std::array::from_fn(|a| max[a] - o[a]),
            outside: std::array::from_fn(|a| o[a] < min[a] || o[a] > max[a]),
            origin: o,
            panels: scene
                .lights
                .iter()
                .zip(footprints.boxes())
                .map(|(light, &footprint)| {
                    let rect = light.rectangle();
                    let c = rect.corner;
                    PanelTest { rect, to_plane: dot([c[0] - o[0], c[1] - o[1], c[2] - o[2]], rect.n), footprint }
                })
                .collect(),
            pixel_center,
            scramble_base: splitmix64(seed ^ RAY_SET_STREAM),
            sobol: [sobol_u32(k, 0), sobol_u32(k, 1)],
            image_width: cam.width as usize,
        }
    }

    /// The block compiled for the widest vectors this CPU has (the same bits on every path).
    fn run_block(&self, j: usize, i: usize, out: &mut [CameraRay; RAY_LANES]) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") && std::arch::is_x86_feature_detected!("avx512dq") {
                // SAFETY: the CPU has the features just checked.
                return unsafe { self.block_avx512(j, i, out) };
            }
            if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
                // SAFETY: as above.
                return unsafe { self.block_avx2(j, i, out) };
            }
        }
        self.block(j, i, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma")]
    fn block_avx512(&self, j: usize, i: usize, out: &mut [CameraRay; RAY_LANES]) {
        self.block(j, i, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn block_avx2(&self, j: usize, i: usize, out: &mut [CameraRay; RAY_LANES]) {
        self.block(j, i, out)
    }

    /// Pixels `i..i + RAY_LANES` of row `j`: [`ray_set_position`],
    /// [`crate::camera::Camera::direction`], `normalize`, [`crate::medium::Medium::clip_ray`],
    /// [`Scene::first_light_among`] the panels whose box holds the pixel, and
    /// [`Scene::segment_before`], operation for operation, as loops over lanes.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // lane loops index several arrays in step, as the vector code they become
    fn block(&self, j: usize, i: usize, out: &mut [CameraRay; RAY_LANES]) {
        const L: usize = RAY_LANES;
        let (mut sx, mut sy) = ([0.5f64; L], [0.5f64; L]);
        if !self.pixel_center {
            let row = (j * self.image_width + i) as u64;
            for l in 0..L {
                let scramble = splitmix64(self.scramble_base ^ (row + l as u64));
                let coordinate =
                    |x: u32, seed: u32| (nested_uniform_scramble(x, seed) as f64 + 0.5) * (1.0 / 4_294_967_296.0);
                sx[l] = coordinate(self.sobol[0], scramble as u32);
                sy[l] = coordinate(self.sobol[1], (scramble >> 32) as u32);
            }
        }
        let mut d = [[0.0f64; L]; 3];
        for l in 0..L {
            let (x, y) = ((i + l) as f64 + sx[l], j as f64 + sy[l]);
            let px = (2.0 * x / self.width - 1.0) * self.tan_half_fov * self.aspect;
            let py = (1.0 - 2.0 * y / self.height) * self.tan_half_fov;
            let v: [f64; 3] = std::array::from_fn(|a| (self.forward[a] + px * self.right[a]) + py * self.up[a]);
            let recip = 1.0 / ((v[0] * v[0]) + (v[1] * v[1]) + (v[2] * v[2])).sqrt();
            for (d, v) in d.iter_mut().zip(v) {
                d[l] = v * recip;
            }
        }
        let (mut t0, mut t1, mut inside) = ([0.0f64; L], [f64::INFINITY; L], [true; L]);
        for l in 0..L {
            for a in 0..3 {
                let da = d[a][l];
                let (near, far) = (self.lo[a] / da, self.hi[a] / da);
                let parallel = da == 0.0;
                let (c0, c1) = (t0[l].max(near.min(far)), t1[l].min(near.max(far)));
                t0[l] = if parallel { t0[l] } else { c0 };
                t1[l] = if parallel { t1[l] } else { c1 };
                inside[l] &= !(parallel & self.outside[a]);
            }
        }
        // The nearest panel crossed (Rectangle::crossing in (0, surface)), in index order as
        // first_light_among takes them, each only in the lanes its box holds.
        let mut surface = [f64::INFINITY; L];
        let (row, first, last) = (j as i64, i as i64, (i + L - 1) as i64);
        let o = self.origin;
        for panel in &self.panels {
            let (b, r) = (panel.footprint, &panel.rect);
            if row < b[2] || row > b[3] || last < b[0] || first > b[1] {
                continue;
            }
            for l in 0..L {
                let dl = [d[0][l], d[1][l], d[2][l]];
                let denom = dot(dl, r.n);
                let t = panel.to_plane / denom;
                let c = r.corner;
                let rel = [(o[0] + t * dl[0]) - c[0], (o[1] + t * dl[1]) - c[1], (o[2] + t * dl[2]) - c[2]];
                let (p, q) = (dot(rel, r.u), dot(rel, r.v));
                let column = first + l as i64;
                let hit = (denom != 0.0)
                    & (t > 0.0)
                    & (t < surface[l])
                    & (p >= 0.0)
                    & (p <= r.width)
                    & (q >= 0.0)
                    & (q <= r.height)
                    & (b[0] <= column)
                    & (column <= b[1]);
                surface[l] = if hit { t } else { surface[l] };
            }
        }
        for l in 0..L {
            // clip_ray's t0 <= t1, then segment_before's t0 < min(surface, t1).
            let end = surface[l].min(t1[l]);
            let inside = inside[l] & (t0[l] <= t1[l]) & (t0[l] < end);
            out[l] = CameraRay {
                dir: glam::Vec3::new(d[0][l] as f32, d[1][l] as f32, d[2][l] as f32),
                t0: if inside { t0[l] as f32 } else { 1.0 },
                t1: if inside { end as f32 } else { 0.0 },
            };
        }
    }
}

/// A ray set as the GPU makes it (`gpu/rays.wgsl`'s `RaySet`, a ray a thread): what
/// [`RayRow`] shares across the set, relative to the camera and rounded to f32 once, with the
/// per-pixel hash's seed and the set's Sobol point as they are (so that the jitter is the same
/// bits). Plain data, defined once: it crosses as it is.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RaySetRecord {
    pub forward: [f32; 3],
    /// tan(vfov / 2) times the aspect ratio: X's scale along `right`.
    pub tan_x: f32,
    pub right: [f32; 3],
    /// tan(vfov / 2): Y's scale along `up`.
    pub tan_y: f32,
    pub up: [f32; 3],
    pub width: u32,
    /// The medium's corners less the camera's position.
    pub lo: [f32; 3],
    pub height: u32,
    pub hi: [f32; 3],
    /// Bit `a`: the camera lies outside the box's slab along axis `a`.
    pub outside: u32,
    /// `splitmix64(seed ^ RAY_SET_STREAM)` as (low, high) words.
    pub scramble: [u32; 2],
    pub sobol: [u32; 2],
    pub pixel_center: u32,
    /// Its light panels ([`PanelRecord`]): how many, and where the first is among the panels
    /// of the sets made together (`gpu/rays.rs` sets it; 0 for a set alone).
    pub panels: u32,
    pub first_panel: u32,
    /// Where its rays begin in the buffer of the sets made together, in floats (`gpu/rays.rs`
    /// sets it; 0 for a set alone).
    pub first_float: u32,
}

/// A light panel as `gpu/rays.wgsl` tests it ([`PanelTest`] relative to the camera, in f32).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PanelRecord {
    /// The rectangle's corner less the camera's position.
    pub corner: [f32; 3],
    /// `(corner - o) . n`, made in f64.
    pub to_plane: f32,
    pub n: [f32; 3],
    pub width: f32,
    pub u: [f32; 3],
    pub height: f32,
    pub v: [f32; 3],
    pub pad: u32,
    /// First and last column, first and last row of the pixels it can cover.
    pub footprint: [i32; 4],
}

/// Ray set `k` of a render (seed `seed`) as the GPU makes it: its record and its panels, from
/// the values the CPU's rows share ([`RayRow`]).
pub fn ray_set_record(scene: &Scene, seed: u64, k: u32, pixel_center: bool) -> (RaySetRecord, Vec<PanelRecord>) {
    let footprints = PanelFootprints::new(scene);
    let r = RayRow::new(scene, &footprints, seed, k, pixel_center);
    let f = |v: [f64; 3]| v.map(|x| x as f32);
    let panels: Vec<PanelRecord> = r
        .panels
        .iter()
        .map(|p| PanelRecord {
            corner: f(std::array::from_fn(|a| p.rect.corner[a] - r.origin[a])),
            to_plane: p.to_plane as f32,
            n: f(p.rect.n),
            width: p.rect.width as f32,
            u: f(p.rect.u),
            height: p.rect.height as f32,
            v: f(p.rect.v),
            pad: 0,
            // Clamped to [-2, side + 1] ([`PanelFootprints::new`]): an i32.
            footprint: p.footprint.map(|b| b as i32),
        })
        .collect();
    let record = RaySetRecord {
        forward: f(r.forward),
        tan_x: (r.tan_half_fov * r.aspect) as f32,
        right: f(r.right),
        tan_y: r.tan_half_fov as f32,
        up: f(r.up),
        width: r.width as u32,
        lo: f(r.lo),
        height: r.height as u32,
        hi: f(r.hi),
        outside: (0..3).map(|a| (r.outside[a] as u32) << a).sum(),
        scramble: [r.scramble_base as u32, (r.scramble_base >> 32) as u32],
        sobol: r.sobol,
        pixel_center: pixel_center as u32,
        panels: panels.len() as u32,
        first_panel: 0,
        first_float: 0,
    };
    (record, panels)
}

/// Which ray sets a [`RaySets`] keeps once made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Keep {
    /// The last two sets made: a chunked render takes its pieces in plane order and a ray set
    /// serves one group of consecutive planes, so a set is needed again only by the next piece,
    /// and each set is made once in the memory of two (the chunk being gathered's and the next
    /// chunk's, prepared meanwhile).
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
    /// The sets kept, by index, oldest first.
    sets: Vec<(u32, Arc<Vec<CameraRay>>)>,
    /// Sets no longer kept, whose buffers serve the next sets once nothing holds them.
    retired: Vec<Arc<Vec<CameraRay>>>,
    /// Which sets have been asked for (made at least once), by index.
    asked: Vec<bool>,
    /// The camera rays of the sets asked for, each set once however often it was made (a GPU
    /// render makes a set again for each gathering along it): the render's rays, the same on
    /// every device; and the seconds spent making sets, every making counted.
    pub camera_rays: u64,
    pub seconds: f64,
}

impl RaySets {
    /// `ray_sets` sets of rays under `seed` (one at pixel centres), none made yet.
    pub fn new(seed: u64, ray_sets: u32, pixel_center: bool, keep: Keep) -> Self {
        let count = if pixel_center { 1 } else { ray_sets.max(1) };
        let asked = vec![false; count as usize];
        RaySets {
            seed,
            pixel_center,
            count,
            keep,
            sets: Vec::new(),
            retired: Vec::new(),
            asked,
            camera_rays: 0,
            seconds: 0.0,
        }
    }

    /// Counts set `k`'s rays the first time it is asked for (`k` already taken modulo the set
    /// count).
    fn count(&mut self, scene: &Scene, k: u32) {
        if !std::mem::replace(&mut self.asked[k as usize], true) {
            self.camera_rays += scene.camera.width as u64 * scene.camera.height as u64;
        }
    }

    /// The rays of ray set `k` (taken modulo the set count), made if need be (their rows
    /// recorded on `control`'s strand, [`crate::schedule`]).
    pub fn rays(&mut self, scene: &Scene, k: u32, control: Control) -> Arc<Vec<CameraRay>> {
        let k = k % self.count;
        if let Some((_, rays)) = self.sets.iter().find(|(set, _)| *set == k) {
            return rays.clone();
        }
        let t = Instant::now();
        // Keeping the last two sets, the older one retires, and the buffer of a retired set
        // that no gathering holds any more is the next one's.
        let mut rays = Vec::new();
        if self.keep == Keep::Last {
            if self.sets.len() >= 2 {
                self.retired.push(self.sets.remove(0).1);
            }
            if let Some(i) = self.retired.iter().position(|r| Arc::strong_count(r) == 1) {
                rays = Arc::try_unwrap(self.retired.swap_remove(i)).unwrap_or_default();
            }
        }
        ray_set_rays_in(scene, self.seed, k, self.pixel_center, &mut rays, control);
        self.seconds += t.elapsed().as_secs_f64();
        self.count(scene, k);
        let rays = Arc::new(rays);
        self.sets.push((k, rays.clone()));
        rays
    }

    /// The rays of ray set `k` (modulo the set count), not kept: `with` is given the function
    /// that writes a row of them ([`with_ray_rows`]), for the GPU's upload buffer, written
    /// once, in place ([`crate::accel::OnGpu`]). Counted ([`RaySets::camera_rays`]) and timed.
    pub fn make_rows<R>(&mut self, scene: &Scene, k: u32, control: Control, with: impl FnOnce(RayRowFn) -> R) -> R {
        let (t, k) = (Instant::now(), k % self.count);
        let out = with_ray_rows(scene, self.seed, k, self.pixel_center, control, with);
        self.seconds += t.elapsed().as_secs_f64();
        self.count(scene, k);
        out
    }

    /// Ray set `k` (modulo the set count) as the GPU makes it ([`ray_set_record`]): the rays are
    /// made where they are gathered ([`crate::accel::OnGpu`]), counted here ([`RaySets::camera_rays`]),
    /// and timed (their record's making).
    pub fn gpu_record(&mut self, scene: &Scene, k: u32) -> (RaySetRecord, Vec<PanelRecord>) {
        let (t, k) = (Instant::now(), k % self.count);
        let out = ray_set_record(scene, self.seed, k, self.pixel_center);
        self.seconds += t.elapsed().as_secs_f64();
        self.count(scene, k);
        out
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

    /// The blocked, branch-free rays are the reference form's bit for bit, jittered and at pixel
    /// centres, in scenes with panels in view, behind the camera and around it, many of them cut
    /// short by a panel; the block compiled for this CPU's widest vectors and for the baseline.
    #[test]
    fn ray_sets_are_the_reference_rays_bit_for_bit() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../media_scenes");
        let mut files: Vec<_> = std::fs::read_dir(dir.join("hard")).unwrap().map(|e| e.unwrap().path()).collect();
        files.sort();
        files.push(dir.join("six_lights.toml"));
        let (w, h) = (203, 41);
        let (mut panels, mut cut) = (0, 0);
        for file in &files {
            let file = file.display();
            let scene = Scene::load(std::path::Path::new(&file.to_string())).unwrap().with_resolution(w, h).unwrap();
            let footprints = PanelFootprints::new(&scene);
            // The same scene without its panels, to count the rays a panel cuts short.
            let mut bare = scene.clone();
            bare.lights.clear();
            let bare_footprints = PanelFootprints::new(&bare);
            for (seed, k, centre) in [(1, 0, false), (7, 5, false), (1, 0, true)] {
                let rays = ray_set_rays(&scene, seed, k, centre);
                let bits = |r: &CameraRay| (r.dir.to_array().map(f32::to_bits), r.t0.to_bits(), r.t1.to_bits());
                for (p, ray) in rays.iter().enumerate() {
                    let want = ray_set_ray(&scene, &footprints, seed, k, centre, p);
                    assert_eq!(bits(ray), bits(&want), "{file} seed {seed} set {k} pixel {p}");
                    panels += footprints.any_over(p as u32 % w, p as u32 / w) as usize;
                    cut += (bits(&want) != bits(&ray_set_ray(&bare, &bare_footprints, seed, k, centre, p))) as usize;
                }
                // The block compiled for the baseline too, not only for this CPU's widest vectors.
                let maker = RayRow::new(&scene, &footprints, seed, k, centre);
                let mut out = [CameraRay::default(); RAY_LANES];
                for (j, row) in rays.chunks(w as usize).enumerate() {
                    for i in (0..w as usize / RAY_LANES * RAY_LANES).step_by(RAY_LANES) {
                        maker.block(j, i, &mut out);
                        for (l, ray) in out.iter().enumerate() {
                            assert_eq!(
                                bits(ray),
                                bits(&row[i + l]),
                                "{file} seed {seed} set {k} pixel ({}, {j})",
                                i + l
                            );
                        }
                    }
                }
            }
        }
        assert!(panels > 1000, "{panels} pixels under panels");
        assert!(cut > 10_000, "{cut} rays cut short by a panel");
        println!("{panels} rays under a panel's box, {cut} cut short by a panel");
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
