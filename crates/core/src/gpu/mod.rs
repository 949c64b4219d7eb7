//! The GPU: one more structure beside [`crate::raster`] and [`crate::bvh`], whose gather runs in
//! WGSL compute shaders through wgpu (Vulkan, Metal, DX12): the design is in `docs/gpu.md`.
//!
//! The planes are sampled and prepared on the CPU as for every structure ([`GatherContext`]);
//! what crosses is defined once, beside the CPU's prepared plane: [`PlaneRecord`] per plane,
//! the [`crate::occlusion::Occluder`]s as they are, and per plane the box of pixels its screen
//! polygon can touch ([`screen_bounds`]). On the GPU, `bin.wgsl` bins the planes to 16 x 16
//! tiles (count, prefix sum, scatter, in plane order) and cuts each tile's list into work items
//! of at most [`item_planes`] planes; `gather.wgsl` gathers a work item per workgroup, each
//! pixel's sum in registers, and adds a tile's items in order. The f32 sums come back and are
//! added to the caller's sums, which the render adds into its canonical f64 chunk sums as the
//! CPU's (so partials, merges, checkpoints and the live view are unchanged).
//!
//! Without the `gpu` feature this module still names the devices; asking for the GPU is then
//! refused in one line.

use crate::photon_plane::Polygon;
use crate::weights::{Estimator, Weighting};
use glam::DVec2;

#[cfg(feature = "gpu")]
mod adapter;
#[cfg(feature = "gpu")]
mod device;
#[cfg(feature = "gpu")]
mod planes;
#[cfg(feature = "gpu")]
mod rays;
#[cfg(feature = "gpu")]
mod records;
#[cfg(feature = "gpu")]
mod scratch;
#[cfg(feature = "gpu")]
mod sums;
#[cfg(feature = "gpu")]
pub use adapter::{adapter, adapter_at, adapters};
#[cfg(feature = "gpu")]
pub use device::Gpu;
#[cfg(feature = "gpu")]
pub use planes::GpuPlanes;
#[cfg(feature = "gpu")]
pub use rays::GpuRays;
#[cfg(feature = "gpu")]
pub use sums::GpuSums;

#[cfg(not(feature = "gpu"))]
mod absent;
#[cfg(not(feature = "gpu"))]
pub use absent::{Gpu, GpuPlanes, GpuRays, GpuSums, adapter, adapter_at, adapters};

/// An adapter as `fogplanes devices` lists it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct AdapterInfo {
    /// Its index in the list: `--device gpu:N`.
    pub index: usize,
    pub name: String,
    /// `Vulkan`, `Metal` or `Dx12`.
    pub backend: String,
    /// `discrete GPU`, `integrated GPU`, `virtual GPU`, `CPU emulation` or `other`.
    pub kind: &'static str,
    /// The most bytes one storage buffer binding holds (the rays of an image must fit one).
    pub max_binding: u64,
    /// Whether `--device gpu` takes it (the first real GPU, else the first adapter).
    pub default: bool,
}

/// The variable a launcher sets per process to give each its own adapter (as dask-cuda sets
/// `CUDA_VISIBLE_DEVICES` per worker): `--device gpu` (Python's `device="gpu"`) then takes
/// adapter `FOGPLANES_GPU` of [`adapters`].
pub const GPU_VARIABLE: &str = "FOGPLANES_GPU";

/// Which processor gathers (`--device`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Device {
    /// The CPU's structures and kernels.
    #[default]
    Cpu,
    /// The GPU ([`GpuPlanes`]): adapter N of [`adapters`] (`gpu:N`), or `None` (`gpu`) the one
    /// [`adapter`] takes, a real GPU before an emulated one; refused where there is none.
    /// Resolved settings always hold the index.
    Gpu(Option<usize>),
    /// The GPU when an adapter is found, else the CPU (resolved once, by the settings).
    Auto,
}

impl Device {
    /// `gpu`: the adapter [`adapter`] takes.
    pub const GPU: Device = Device::Gpu(None);
    pub const ALL: [Device; 3] = [Device::Cpu, Device::GPU, Device::Auto];

    /// The processor's name (`gpu` for every adapter).
    pub fn name(self) -> &'static str {
        match self {
            Device::Cpu => "cpu",
            Device::Gpu(_) => "gpu",
            Device::Auto => "auto",
        }
    }

    pub fn is_gpu(self) -> bool {
        matches!(self, Device::Gpu(_))
    }
}

impl std::fmt::Display for Device {
    /// `cpu`, `gpu`, `gpu:N`, `auto`: what parses back to it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Device::Gpu(Some(i)) => write!(f, "gpu:{i}"),
            d => f.write_str(d.name()),
        }
    }
}

impl std::str::FromStr for Device {
    type Err = String;
    /// A name of [`Device::ALL`], or `gpu:N` with N an adapter's index.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.strip_prefix("gpu:") {
            Some(n) => n.parse::<usize>().map(|i| Device::Gpu(Some(i))).map_err(|_| {
                format!(
                    "unknown device {s:?}; gpu:N takes an adapter's index N (0, 1, ...: `fogplanes devices` lists them)"
                )
            }),
            None => crate::parse_name("device", s, &Device::ALL, Device::name)
                .map_err(|e| format!("{e}, or gpu:N for adapter N")),
        }
    }
}

/// Pixels on a tile's side: a tile is a workgroup of 16 x 16 threads, a pixel each.
pub const TILE: u32 = 16;

/// The most planes binned and gathered in one batch: the binning's loops then run at most 64
/// times per invocation.
pub const BATCH_PLANES: usize = 16_384;

/// The most planes of one work item: 512 on a GPU (the prototype's best on an H100); 256 on a
/// CPU adapter, whose llvmpipe silently ends an invocation's loops after about 65,000
/// iterations: a work item with 64 orientations and 63 panels' occluders per hit stays at
/// 256 x 127 (tested by the hit counts against the CPU's).
pub fn item_planes(cpu_adapter: bool) -> u32 {
    if cpu_adapter { 256 } else { 512 }
}

/// The estimator as `gather.wgsl`'s `ESTIMATOR` names it.
pub fn estimator_id(w: Weighting) -> u32 {
    match (w.estimator, w.orientations) {
        (Estimator::Unweighted, _) => 0,
        (Estimator::CmisCosine, _) => 1,
        (Estimator::SmisCosine, 2) => 2,
        (Estimator::SmisExact, 2) => 3,
        (Estimator::CmisExact, _) => 4,
        (Estimator::SmisCosine, _) => 5,
        (Estimator::SmisExact, _) => 6,
    }
}

/// The tiles a plane's screen polygon ([`crate::raster::screen_polygon`]) can touch, row of
/// tiles by row: from row `first_row`, for each row the first and last column of tiles
/// (inclusive; `[1, 0]` where none) whose pixels' squares come within a pixel of the polygon
/// (far above its rounding). What `bin.wgsl`'s `covers` tests: binning to these spans, not to
/// the polygon's box, keeps a thin diagonal plane out of the tiles its box crosses but it does
/// not (the benchmark's tests per hit: 4.2 with boxes). Per row of tiles, too, the box of
/// pixels within it that come within a pixel of the polygon (`pixels`): the gather tests only
/// a tile's pixels in it (tighter tiles: a tile's 256 pixels tested per plane were 1.79 tests
/// per hit on the benchmark).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TileReach {
    pub first_row: u32,
    pub spans: Vec<[u32; 2]>,
    /// Per row of tiles: its first and last pixel column, packed `first | last << 16`, and its
    /// first and last pixel row, packed alike (`[1, 0]` where the row is empty).
    pub pixels: Vec<[u32; 2]>,
}

impl TileReach {
    /// The (tile, plane) pairs: how many tiles the plane is binned to.
    pub fn tiles(&self) -> u64 {
        self.spans.iter().map(|&[a, b]| (b + 1).saturating_sub(a) as u64).sum()
    }

    /// The pixels the gather tests the plane at: each row of tiles' box of pixels.
    pub fn tests(&self) -> u64 {
        let len = |v: u32| ((v >> 16) + 1).saturating_sub(v & 0xffff) as u64;
        self.spans.iter().zip(&self.pixels).filter(|(s, _)| s[0] <= s[1]).map(|(_, &[x, y])| len(x) * len(y)).sum()
    }
}

/// The plane's [`TileReach`] in a `width x height` image; no rows for a polygon that shows
/// nothing. A row of tiles `r` holds pixel rows `16 r .. 16 r + 15`, whose squares span
/// `y in [16 r, 16 r + 16]`: its span is the polygon's x-range within the strip
/// `[16 r - 1, 16 r + 17]`, grown by a pixel, kept in the image, in tiles.
pub fn tile_reach(poly: &Polygon<DVec2>, width: u32, height: u32) -> TileReach {
    const M: f64 = 1.0;
    let t = TILE as f64;
    let none = TileReach::default();
    if poly.len < 3 || poly.points().iter().any(|v| !(v.x.is_finite() && v.y.is_finite())) {
        return none;
    }
    let (mut ylo, mut yhi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in poly.points() {
        (ylo, yhi) = (ylo.min(v.y), yhi.max(v.y));
    }
    // Pixel row py's square [py, py + 1] comes within a pixel of [ylo, yhi] where
    // ylo - 2 <= py <= yhi + 1; its row of tiles is py / 16.
    let first = ((ylo - 2.0 * M).ceil().max(0.0) / t).floor();
    let last = ((yhi + M).floor().min(height as f64 - 1.0) / t).floor();
    if !(first <= last) {
        return none;
    }
    let (first, last) = (first as u32, last as u32);
    let n = (last - first + 1) as usize;
    let mut lo = vec![f64::INFINITY; n];
    let mut hi = vec![f64::NEG_INFINITY; n];
    let points = poly.points();
    for (&p, &q) in points.iter().zip(points.iter().cycle().skip(1)) {
        let (ymin, ymax) = (p.y.min(q.y), p.y.max(q.y));
        let (xlo, xhi) = (p.x.min(q.x), p.x.max(q.x));
        // The strips the edge can meet (each checked below).
        let j0 = (((ymin - t - M) / t).ceil() - first as f64).clamp(0.0, n as f64) as usize;
        let j1 = (((ymax + M) / t).floor() - first as f64 + 1.0).clamp(0.0, n as f64) as usize;
        for j in j0..j1 {
            let top = (first as usize + j) as f64 * t - M;
            let bottom = top + t + 2.0 * M;
            if ymax < top || ymin > bottom {
                continue;
            }
            // The edge's x at the ends of its part inside the strip, kept on the edge; a
            // horizontal edge's two ends.
            let (xa, xb) = if q.y == p.y {
                (xlo, xhi)
            } else {
                let at = |y: f64| (p.x + (y - p.y) * (q.x - p.x) / (q.y - p.y)).clamp(xlo, xhi);
                (at(ymin.max(top)), at(ymax.min(bottom)))
            };
            lo[j] = lo[j].min(xa.min(xb));
            hi[j] = hi[j].max(xa.max(xb));
        }
    }
    // The polygon's pixel rows, as above: ylo - 2 <= py <= yhi + 1.
    let (row_lo, row_hi) = ((ylo - 2.0 * M).ceil().max(0.0) as u32, (yhi + M).floor().min(height as f64 - 1.0) as u32);
    let (mut spans, mut pixels) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for (j, (&lo, &hi)) in lo.iter().zip(&hi).enumerate() {
        // Pixel px's square [px, px + 1] comes within a pixel of [lo, hi] where
        // lo - 2 <= px <= hi + 1; its tile is px / 16.
        let a = (lo - 2.0 * M).ceil().max(0.0);
        let b = (hi + M).floor().min(width as f64 - 1.0);
        if !(a <= b) {
            spans.push([1, 0]);
            pixels.push([1, 0]);
            continue;
        }
        let (a, b) = (a as u32, b as u32);
        let row = (first as usize + j) as u32 * TILE;
        let (r0, r1) = (row_lo.max(row), row_hi.min(row + TILE - 1));
        spans.push([a / TILE, b / TILE]);
        pixels.push([a | b << 16, r0 | r1 << 16]);
    }
    TileReach { first_row: first, spans, pixels }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pixel whose square comes within a pixel of a polygon is in a tile of its reach
    /// (points of the polygon, its vertices and edges among them, checked against the tiles);
    /// a thin diagonal polygon reaches far fewer tiles than its box; one outside the image or
    /// degenerate reaches none.
    #[test]
    fn a_reach_holds_every_tile_the_polygon_comes_near() {
        let (w, h) = (200u32, 120u32);
        let mut seed = 7u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for case in 0..300 {
            // A convex polygon: points on an ellipse, some thin and tilted, some past the edges.
            let (cx, cy) = (next() * 260.0 - 30.0, next() * 180.0 - 30.0);
            let (a, b) = (next() * 150.0 + 0.5, if case % 3 == 0 { next() * 2.0 + 0.01 } else { next() * 60.0 + 0.5 });
            let (tilt, k) = (next() * std::f64::consts::PI, 3 + case % 6);
            let points: Vec<DVec2> = (0..k)
                .map(|i| {
                    let u = i as f64 / k as f64 * std::f64::consts::TAU;
                    let (x, y) = (a * u.cos(), b * u.sin());
                    DVec2::new(cx + x * tilt.cos() - y * tilt.sin(), cy + x * tilt.sin() + y * tilt.cos())
                })
                .collect();
            let poly = Polygon::from_slice(&points);
            let reach = tile_reach(&poly, w, h);
            let covered = |px: i64, py: i64| {
                let (tx, ty) = ((px / TILE as i64) as u32, (py / TILE as i64) as u32);
                let (px, py) = (px as u32, py as u32);
                let row = (ty >= reach.first_row).then(|| (ty - reach.first_row) as usize);
                let inside = |v: u32, packed: u32| packed & 0xffff <= v && v <= packed >> 16;
                row.is_some_and(|r| {
                    reach.spans.get(r).is_some_and(|&[f, l]| f <= tx && tx <= l)
                        && inside(px, reach.pixels[r][0])
                        && inside(py, reach.pixels[r][1])
                })
            };
            // Points of the polygon and each pixel square within a pixel of them.
            for i in 0..k {
                let (p, q) = (points[i], points[(i + 1) % k]);
                for s in 0..=40 {
                    let on = p + (q - p) * (s as f64 / 40.0);
                    let inner = on + (points[(i + 2) % k] - on) * next();
                    for v in [on, inner] {
                        for dy in -1..=1 {
                            for dx in -1..=1 {
                                let (px, py) = ((v.x + dx as f64).floor() as i64, (v.y + dy as f64).floor() as i64);
                                if (0..w as i64).contains(&px) && (0..h as i64).contains(&py) {
                                    assert!(covered(px, py), "case {case}: pixel ({px}, {py}) near {v} not reached");
                                }
                            }
                        }
                    }
                }
            }
        }
        // Thin and diagonal: from corner to corner of a 200 x 120 image.
        let thin = Polygon::from_slice(&[DVec2::new(0.0, 0.0), DVec2::new(200.0, 119.0), DVec2::new(200.0, 120.0)]);
        let reach = tile_reach(&thin, w, h);
        assert!(reach.tiles() * 3 <= 13 * 8, "{} of the box's 104 tiles", reach.tiles());
        let outside = Polygon::from_slice(&[DVec2::new(-9.0, -9.0), DVec2::new(-3.0, -9.0), DVec2::new(-9.0, -3.0)]);
        assert_eq!(tile_reach(&outside, w, h).tiles(), 0);
        let right = Polygon::from_slice(&[DVec2::new(202.0, 5.0), DVec2::new(209.0, 5.0), DVec2::new(202.0, 9.0)]);
        assert_eq!(tile_reach(&right, w, h).tiles(), 0);
        assert_eq!(tile_reach(&Polygon::from_slice(&[DVec2::ZERO, DVec2::ONE]), w, h).tiles(), 0);
        let nan = Polygon::from_slice(&[DVec2::ZERO, DVec2::new(f64::NAN, 1.0), DVec2::ONE]);
        assert_eq!(tile_reach(&nan, w, h), TileReach::default());
    }

    #[test]
    fn every_estimator_has_a_shader_id_and_device_names_round_trip() {
        let ids: Vec<u32> = Weighting::all(&[4]).into_iter().map(estimator_id).collect();
        assert_eq!(ids, vec![0, 1, 2, 3, 4, 5, 6]);
        for d in Device::ALL.into_iter().chain([Device::Gpu(Some(0)), Device::Gpu(Some(12))]) {
            assert_eq!(d.to_string().parse::<Device>().unwrap(), d);
        }
        for bad in ["gpu:", "gpu:x", "gpu:-1", "tpu"] {
            assert!(bad.parse::<Device>().is_err(), "{bad}");
        }
    }
}
