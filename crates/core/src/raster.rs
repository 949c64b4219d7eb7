//! The intersection structure for the pinhole camera: planes rasterised in screen space.
//!
//! Every camera ray starts at the camera, so the rays that can hit a plane are exactly those
//! whose image point lies in the projection of the plane's polygon (clipped to the box). Each
//! polygon is projected once, clipped to the image, and binned into horizontal bands of rows.
//! A band walks its planes light by light, each light's in index order; for every row it
//! covers, the conservative span of pixels whose squares meet the polygon is tested exactly
//! with [`crate::gather::PlaneJob::gather_block`]. The exact test decides; the span only has
//! to contain every pixel that can hit, whatever the jitter.
//!
//! Each pixel's sum runs over planes in that order whatever the thread count ([the sums light by
//! light](crate::gather#sums-light-by-light)), so images are bit-identical for a seed.

use crate::camera::Camera;
use crate::camera::CameraRay;
use crate::control::Control;
use crate::gather::{GatherContext, GatherStats, RayBlock};
use crate::kernel::{self, Aggregate, Band, Gathering, HALF_LANES, Kernel, LANES, Span};
use crate::medium::Medium;
use crate::photon_plane::{PhotonPlane, Polygon};
use crate::weights::{Denominator, Unweighted};
use glam::{DVec2, DVec3, Vec2, Vec3};
use rayon::prelude::*;
use std::ops::Range;

/// Rows per band: a band's rays and sums stay in cache while its planes stream by, its spans
/// computed with its rows as lanes. At most this many: see [`band_rows`].
pub const BAND_ROWS: u32 = 16;

/// The rows of a band for an image `height` rows high gathered by `threads` workers: 16, halved
/// (to 8, 4, 2, 1) while that leaves fewer than two bands per worker, so that many cores are all
/// busy and the bands' unequal work evens out (23 bands of 16 rows make a 640x360 image: 12
/// workers or more get bands of 8 rows, 23 or more of 4). The image is the same bits whatever
/// the band: a pixel adds its planes light by light, each light's in index order, within its
/// band either way (and the lights' sums in light order). A smaller band makes more plane-band
/// pairs, each with its span walk and its plane's set-up, which costs CPU time: on the
/// benchmark, bands of 16 rows took 0.97x the CPU time of bands of 8 (7 alternating runs; a
/// band's rays, sums and totals, 460 KB, still sit in a 1 MB L2), an older build 0.66 CPU s
/// with 8 rows, 0.73 with 4, 0.86 with 2 (12 and 24 workers on 2 cores, so an upper bound),
/// paid only where there are the workers to spare.
pub fn band_rows(height: u32, threads: usize) -> u32 {
    let mut rows = BAND_ROWS;
    while rows > 1 && (height.div_ceil(rows) as usize) < 2 * threads {
        rows /= 2;
    }
    rows
}
/// Slack in pixels around a projected polygon, far above the rounding of the projection.
const SPAN_MARGIN: f32 = 1e-2;

/// The raster's unit of work is a band of rows: one progress report each.
impl Aggregate for ScreenRaster {
    fn gather<D: Denominator>(
        &self,
        with: Gathering<D>,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        control: Control,
    ) -> GatherStats {
        self.gather_all::<D, true>(with, rays, sums, control)
    }
}

/// Projected, image-clipped polygons of all planes, binned into bands of rows.
pub struct ScreenRaster {
    /// Rows per band ([`band_rows`]).
    band_rows: u32,
    pub width: u32,
    pub height: u32,
    /// Vertices of polygon `i` are `vertices[offsets[i]..offsets[i + 1]]`, in pixel units.
    vertices: Vec<Vec2>,
    offsets: Vec<u32>,
    /// Plane indices per band, by light, each light's ascending.
    bands: Vec<Vec<u32>>,
    /// The light of each plane.
    lights: Vec<u32>,
}

/// The plane's polygon as seen from the camera, clipped to the image grown by one pixel, in
/// pixel coordinates; empty if the camera cannot see it.
pub fn screen_polygon(camera: &Camera, plane: &PhotonPlane, medium: &Medium) -> Polygon<DVec2> {
    let margin = 1e-6 * medium.diagonal();
    let world = plane.polygon_in_box(medium, margin);
    let mut cam = Polygon::<DVec3>::empty();
    for &v in world.points() {
        cam.vertices[cam.len] = camera.to_camera(v);
        cam.len += 1;
    }
    // Only points in front of the camera can be hit; a tiny positive depth keeps the
    // projection finite (points closer than this lie within it of the camera).
    let near = 1e-9 * medium.diagonal().max(1e-30);
    let cam = cam.clip(|v| v.z - near, |p, q, s| p + (q - p) * s);
    let (mut screen, mut other) = (Polygon::<DVec2>::empty(), Polygon::<DVec2>::empty());
    for &v in cam.points() {
        let (x, y) = camera.project(v);
        screen.vertices[screen.len] = DVec2::new(x, y);
        screen.len += 1;
    }
    let (w, h) = (camera.width as f64, camera.height as f64);
    let lerp = |p: DVec2, q: DVec2, s: f64| p + (q - p) * s;
    screen.clip_into(&mut other, |v| v.x + 1.0, lerp);
    other.clip_into(&mut screen, |v| w + 1.0 - v.x, lerp);
    screen.clip_into(&mut other, |v| v.y + 1.0, lerp);
    other.clip_into(&mut screen, |v| h + 1.0 - v.y, lerp);
    screen
}

impl ScreenRaster {
    pub fn build(camera: &Camera, planes: &[PhotonPlane], medium: &Medium) -> Self {
        let mut raster = ScreenRaster::empty(camera);
        raster.push_planes(camera, planes, medium);
        raster
    }

    /// A raster with no planes yet, for [`ScreenRaster::push_planes`], in bands sized for the
    /// workers of the current thread pool ([`band_rows`]).
    pub fn empty(camera: &Camera) -> Self {
        let band_rows = band_rows(camera.height, rayon::current_num_threads());
        let band_count = camera.height.div_ceil(band_rows) as usize;
        ScreenRaster {
            band_rows,
            width: camera.width,
            height: camera.height,
            vertices: Vec::new(),
            offsets: vec![0],
            bands: vec![Vec::new(); band_count],
            lights: Vec::new(),
        }
    }

    /// Projects, clips and bins the next planes of the set (their indices continue the count).
    pub fn push_planes(&mut self, camera: &Camera, planes: &[PhotonPlane], medium: &Medium) {
        let polygons: Vec<Polygon<DVec2>> = planes.par_iter().map(|p| screen_polygon(camera, p, medium)).collect();
        let band_count = self.bands.len() as u32;
        for poly in &polygons {
            let index = (self.offsets.len() - 1) as u32;
            if poly.len >= 3 {
                let (lo, hi) = poly
                    .points()
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v.y), hi.max(v.y)));
                let rows = self.band_rows;
                let first = ((lo - SPAN_MARGIN as f64).floor().max(0.0) as u32 / rows) as usize;
                let last = ((hi + SPAN_MARGIN as f64).floor().max(0.0) as u32 / rows).min(band_count - 1) as usize;
                for band in self.bands.iter_mut().take(last + 1).skip(first) {
                    band.push(index);
                }
                self.vertices.extend(poly.points().iter().map(|v| v.as_vec2()));
            }
            self.offsets.push(self.vertices.len() as u32);
        }
        self.lights.extend(planes.iter().map(|p| p.light as u32));
        // Light by light (stable: each light's planes stay in index order).
        let lights = &self.lights;
        self.bands.par_iter_mut().for_each(|band| band.sort_by_key(|&i| lights[i as usize]));
    }

    /// For each row of `first_row..first_row + rows` (at most [`BAND_ROWS`]), the columns
    /// `[first, last]` whose pixel squares may meet polygon `i`, if any: the polygon's x-range
    /// within the row's strip `[row - m, row + 1 + m]`, grown by m = [`SPAN_MARGIN`]. One walk
    /// over the edges serves the whole band, its rows as lanes (two AVX registers): the scalar
    /// walk, row by row, took a tenth of the gathering's instructions.
    fn spans(&self, i: usize, first_row: u32, rows: u32) -> [Option<(u32, u32)>; BAND_ROWS as usize] {
        #[cfg(target_arch = "x86_64")]
        if Kernel::Avx2.is_available() {
            // SAFETY: the CPU has the features of `spans_avx2`, just checked.
            return unsafe { self.spans_avx2(i, first_row, rows) };
        }
        self.spans_in_lanes(i, first_row, rows)
    }

    /// [`ScreenRaster::spans`] with the band's sixteen rows in two AVX registers (the same
    /// operations: the same bits); with SSE's four lanes it took 7% of the benchmark's CPU time.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn spans_avx2(&self, i: usize, first_row: u32, rows: u32) -> [Option<(u32, u32)>; BAND_ROWS as usize] {
        self.spans_in_lanes(i, first_row, rows)
    }

    #[inline(always)]
    fn spans_in_lanes(&self, i: usize, first_row: u32, rows: u32) -> [Option<(u32, u32)>; BAND_ROWS as usize] {
        const R: usize = BAND_ROWS as usize;
        let poly = &self.vertices[self.offsets[i] as usize..self.offsets[i + 1] as usize];
        let mut lo = [f32::INFINITY; R];
        let mut hi = [f32::NEG_INFINITY; R];
        // Each row's strip.
        let top: [f32; R] = std::array::from_fn(|j| (first_row as usize + j) as f32 - SPAN_MARGIN);
        let bottom: [f32; R] = std::array::from_fn(|j| (first_row as usize + j) as f32 + 1.0 + SPAN_MARGIN);
        let (band_top, band_bottom) = (top[0], (first_row + rows) as f32 + SPAN_MARGIN);
        // Each edge p -> q, the last closing the polygon (a rotated iterator: an index modulo
        // the length was an integer division per edge).
        for (&p, &q) in poly.iter().zip(poly.iter().cycle().skip(1)) {
            let (ymin, ymax) = (min(p.y, q.y), max(p.y, q.y));
            if ymax < band_top || ymin > band_bottom {
                continue;
            }
            let dy = q.y - p.y;
            let flat = dy == 0.0;
            let slope = (q.x - p.x) / dy;
            let (xlo, xhi) = (min(p.x, q.x), max(p.x, q.x));
            for j in 0..R {
                // The edge's x at the ends of its part inside the strip, kept on the edge; a
                // horizontal edge's two ends.
                let (ya, yb) = (max(ymin, top[j]), min(ymax, bottom[j]));
                let xa = if flat { xlo } else { min(max(p.x + (ya - p.y) * slope, xlo), xhi) };
                let xb = if flat { xhi } else { min(max(p.x + (yb - p.y) * slope, xlo), xhi) };
                let meets = (bottom[j] >= ymin) & (top[j] <= ymax);
                lo[j] = if meets { min(lo[j], min(xa, xb)) } else { lo[j] };
                hi[j] = if meets { max(hi[j], max(xa, xb)) } else { hi[j] };
            }
        }
        let mut out = [None; R];
        for j in 0..rows as usize {
            if lo[j] > hi[j] || hi[j] + SPAN_MARGIN < 0.0 {
                continue;
            }
            // Truncation is floor for the non-negative values it is given.
            let first = max(lo[j] - SPAN_MARGIN, 0.0) as u32;
            let last = ((hi[j] + SPAN_MARGIN) as u32).min(self.width - 1);
            out[j] = (first <= last).then_some((first, last));
        }
        out
    }

    /// Finds every hit without weighting it (the traversal and intersection work alone, for
    /// measuring its share of the gathering time).
    pub fn count_hits(&self, ctx: &GatherContext, kernel: Kernel, rays: &[CameraRay]) -> GatherStats {
        let mut out = vec![Vec3::ZERO; rays.len()];
        let with = Gathering { ctx, weights: &Unweighted, kernel };
        self.gather_all::<Unweighted, false>(with, rays, &mut out, Control::none())
    }

    fn gather_all<D: Denominator, const CONTRIBUTE: bool>(
        &self,
        with: Gathering<D>,
        rays: &[CameraRay],
        out: &mut [Vec3],
        control: Control,
    ) -> GatherStats {
        // The kernels' target features are the CPU's: checked once here, for every plane and
        // fold of the gathering (a `Gathering` can be made with any kernel).
        assert!(with.kernel.is_available(), "the {} kernel is not available on this CPU", with.kernel);
        let w = self.width as usize;
        let band_pixels = self.band_rows as usize * w;
        // What the weights need of each plane, once (a plane crosses many bands); stopped, like
        // the gathering, by a cancel.
        let prepared: Vec<D::Plane> = with
            .ctx
            .views
            .par_iter()
            .map(|v| (!control.is_cancelled()).then(|| with.weights.prepare(&v.frame)))
            .while_some()
            .collect();
        if control.is_cancelled() {
            return GatherStats::default();
        }
        // The bands with the most planes first: the last a worker takes are then small ones, and
        // the workers finish together (with 23 bands for 2 workers, in image order one of them
        // idled for 5% of the gathering's wall time).
        let mut bands: Vec<_> = out.chunks_mut(band_pixels).zip(rays.chunks(band_pixels)).enumerate().collect();
        bands.sort_by_key(|(band, _)| std::cmp::Reverse(self.bands[*band].len()));
        bands
            .into_par_iter()
            .with_max_len(1)
            .map(|(band, (sums, rays))| {
                let stats = self.gather_band::<D, CONTRIBUTE>(with, &prepared, band, rays, sums, control);
                if !control.is_cancelled() {
                    control.progress();
                }
                stats
            })
            .reduce(GatherStats::default, |mut a, b| {
                a += b;
                a
            })
    }

    /// One band of rows: its planes light by light, each against its spans, each light's sums
    /// folded into the band's totals when its planes end ([`kernel::fold`]). The cancel flag is
    /// read before each plane (a relaxed load, nothing beside a plane's work), so that even a
    /// band of millions of planes stops within milliseconds.
    fn gather_band<D: Denominator, const CONTRIBUTE: bool>(
        &self,
        with: Gathering<D>,
        prepared: &[D::Plane],
        band: usize,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        control: Control,
    ) -> GatherStats {
        let Gathering { ctx, weights, kernel } = with;
        let w = self.width as usize;
        let first_row = band as u32 * self.band_rows;
        let rows = (rays.len() / w) as u32;
        let soa = PaddedRays::new(rays, w);
        let stride = soa.stride;
        let mut acc = PaddedSums::new(soa.x.len());
        let mut folded = PaddedSums::new(soa.x.len());
        let mut totals = kernel::BandTotals { r: &mut folded.r, g: &mut folded.g, b: &mut folded.b };
        let mut stats = GatherStats::default();
        let mut kernel_band = Band {
            rays: kernel::BandRays { x: &soa.x, y: &soa.y, z: &soa.z, t0: &soa.t0, t1: &soa.t1 },
            sums: kernel::BandSums { r: &mut acc.r, g: &mut acc.g, b: &mut acc.b },
        };
        let mut spans = Vec::with_capacity(BAND_ROWS as usize);
        let mut light: Option<LightSum> = None;
        // The per-hit kernel's sums are folded by the portable one (a fold has no per-hit form;
        // its lanes do the same operations).
        let fold_kernel = if kernel == Kernel::PerHit { Kernel::Portable } else { kernel };
        let grey = ctx.extinction.grey;
        let fold = |sums: &mut kernel::BandSums, totals: &mut kernel::BandTotals, done: LightSum| {
            // Counting hits alone writes no sums.
            if CONTRIBUTE {
                kernel::fold(fold_kernel, done.scale, grey, sums, totals, blocks(done.touched));
            }
        };
        for &plane in &self.bands[band] {
            if control.is_cancelled() {
                return stats;
            }
            let view = &ctx.views[plane as usize];
            spans.clear();
            for (row, span) in (first_row..).zip(self.spans(plane as usize, first_row, rows)) {
                let Some((first, last)) = span else {
                    continue;
                };
                // Whole half blocks: the span grown to a multiple of HALF_LANES, into the row's
                // padding if need be (padding rays never hit). Every kernel tests the same pixels.
                let len = (last - first + 1).next_multiple_of(HALF_LANES as u32);
                spans.push(Span { start: (row - first_row) * stride as u32 + first, len });
                stats.tests += len as u64;
            }
            if spans.is_empty() {
                continue;
            }
            let (first, end) = spans
                .iter()
                .fold((usize::MAX, 0), |(lo, hi), s| (lo.min(s.start as usize), hi.max((s.start + s.len) as usize)));
            match &mut light {
                Some(current) if current.light == view.light => {
                    debug_assert_eq!(current.scale, view.scale, "one scale per light");
                    current.touched = current.touched.start.min(first)..current.touched.end.max(end);
                }
                _ => {
                    if let Some(done) = light.take() {
                        fold(&mut kernel_band.sums, &mut totals, done);
                    }
                    light = Some(LightSum { light: view.light, scale: view.scale, touched: first..end });
                }
            }
            let job = ctx.job(weights, view, &prepared[plane as usize]);
            if kernel == Kernel::PerHit {
                let (rays, sums) = (&kernel_band.rays, &mut kernel_band.sums);
                for k in spans.iter().flat_map(|s| s.start as usize..(s.start + s.len) as usize) {
                    let one = RayBlock { x: rays.x[k], y: rays.y[k], z: rays.z[k], t0: rays.t0[k], t1: rays.t1[k] };
                    let sums = [
                        std::array::from_mut(&mut sums.r[k]),
                        std::array::from_mut(&mut sums.g[k]),
                        std::array::from_mut(&mut sums.b[k]),
                    ];
                    stats.hits += job.gather_block_in::<1, f32, CONTRIBUTE>(&one, sums) as u64;
                }
            } else {
                stats.hits += kernel::gather_plane::<D, CONTRIBUTE>(kernel, &job, &spans, &mut kernel_band);
            }
        }
        if let Some(done) = light {
            fold(&mut kernel_band.sums, &mut totals, done);
        }
        for (row, sums) in sums.chunks_mut(w).enumerate() {
            let i = row * stride;
            for (k, s) in sums.iter_mut().enumerate() {
                *s += Vec3::new(totals.r[i + k], totals.g[i + k], totals.b[i + k]);
            }
        }
        stats
    }
}

/// The light whose planes a band is summing: its index, its scale and the pixels its planes
/// touched.
struct LightSum {
    light: u32,
    scale: Vec3,
    touched: Range<usize>,
}

/// `range` grown to whole blocks of [`LANES`] (a band's rows are padded to whole blocks).
fn blocks(range: Range<usize>) -> Range<usize> {
    range.start / LANES * LANES..range.end.next_multiple_of(LANES)
}

/// Compare-and-select: one instruction each (f32::min and max spend several on NaN, which only
/// the unused slope of a horizontal edge is). Functions, not closures: a closure is compiled
/// without the caller's target features.
#[inline(always)]
fn min(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

#[inline(always)]
fn max(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// The camera rays of one band as a structure of arrays, so that a span vectorises. Each row is
/// followed by at least LANES - 1 padding rays that never hit anything (zero direction, empty
/// segment), so that a span grown to whole blocks stays in its row.
struct PaddedRays {
    stride: usize,
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    t0: Vec<f32>,
    t1: Vec<f32>,
}

impl PaddedRays {
    fn new(rays: &[CameraRay], width: usize) -> Self {
        let stride = (width + LANES - 1).next_multiple_of(LANES);
        let n = rays.len() / width * stride;
        let field = |get: fn(&CameraRay) -> f32, pad: f32| -> Vec<f32> {
            // Each row and its padding written once (not the whole band filled first).
            let mut v = Vec::with_capacity(n);
            for row in rays.chunks(width) {
                v.extend(row.iter().map(get));
                v.resize(v.len() + stride - row.len(), pad);
            }
            v
        };
        PaddedRays {
            stride,
            x: field(|r| r.dir.x, 0.0),
            y: field(|r| r.dir.y, 0.0),
            z: field(|r| r.dir.z, 0.0),
            t0: field(|r| r.t0, 1.0),
            t1: field(|r| r.t1, 0.0),
        }
    }
}

/// Per-pixel sums of one band (rows padded like [`PaddedRays`]), a structure of arrays.
struct PaddedSums {
    r: Vec<f32>,
    g: Vec<f32>,
    b: Vec<f32>,
}

impl PaddedSums {
    fn new(n: usize) -> Self {
        PaddedSums { r: vec![0.0; n], g: vec![0.0; n], b: vec![0.0; n] }
    }
}
