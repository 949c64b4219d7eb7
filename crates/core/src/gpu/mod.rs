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
mod device;
#[cfg(feature = "gpu")]
pub use device::{Gpu, GpuPlanes, GpuRays, GpuSums, adapter};

#[cfg(not(feature = "gpu"))]
mod absent;
#[cfg(not(feature = "gpu"))]
pub use absent::{Gpu, GpuPlanes, GpuRays, GpuSums, adapter};

/// Which processor gathers (`--device`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Device {
    /// The CPU's structures and kernels.
    #[default]
    Cpu,
    /// The GPU ([`GpuPlanes`]); refused where there is no adapter.
    Gpu,
    /// The GPU when an adapter is found, else the CPU (resolved once, by the settings).
    Auto,
}

impl Device {
    pub const ALL: [Device; 3] = [Device::Cpu, Device::Gpu, Device::Auto];

    pub fn name(self) -> &'static str {
        match self {
            Device::Cpu => "cpu",
            Device::Gpu => "gpu",
            Device::Auto => "auto",
        }
    }
}

crate::named_choice!(Device, "device");

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

/// The box of pixels a plane's screen polygon ([`crate::raster::screen_polygon`]) can touch:
/// first and last column, first and last row, inclusive, grown by a pixel beyond the polygon
/// (far above its rounding) and kept in the image; `[0, -1, 0, -1]` (empty) for a polygon that
/// shows nothing.
pub fn screen_bounds(poly: &Polygon<DVec2>, width: u32, height: u32) -> [i32; 4] {
    const EMPTY: [i32; 4] = [0, -1, 0, -1];
    if poly.len < 3 {
        return EMPTY;
    }
    let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    for &v in poly.points() {
        (lo, hi) = (lo.min(v), hi.max(v));
    }
    if !(lo.x.is_finite() && lo.y.is_finite() && hi.x.is_finite() && hi.y.is_finite()) {
        return EMPTY;
    }
    let (w, h) = (width as f64, height as f64);
    let x0 = (lo.x - 1.0).floor().max(0.0);
    let x1 = (hi.x + 1.0).floor().min(w - 1.0);
    let y0 = (lo.y - 1.0).floor().max(0.0);
    let y1 = (hi.y + 1.0).floor().min(h - 1.0);
    if x0 > x1 || y0 > y1 {
        return EMPTY;
    }
    [x0 as i32, x1 as i32, y0 as i32, y1 as i32]
}

/// The tiles a box of [`screen_bounds`] meets: what `bin.wgsl`'s `covers` counts.
pub fn tiles_of(b: [i32; 4]) -> u64 {
    if b[0] > b[1] || b[2] > b[3] {
        return 0;
    }
    let t = TILE as i32;
    ((b[1] / t - b[0] / t + 1) as u64) * ((b[3] / t - b[2] / t + 1) as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_grow_by_a_pixel_and_stay_in_the_image() {
        let poly = Polygon::from_slice(&[DVec2::new(3.2, 4.5), DVec2::new(20.7, 4.5), DVec2::new(10.0, 17.9)]);
        assert_eq!(screen_bounds(&poly, 64, 32), [2, 21, 3, 18]);
        assert_eq!(tiles_of([2, 21, 3, 18]), 4);
        let outside = Polygon::from_slice(&[DVec2::new(-1.0, -1.0), DVec2::new(-0.5, -1.0), DVec2::new(-1.0, -0.5)]);
        assert_eq!(screen_bounds(&outside, 64, 32), [0, 0, 0, 0]);
        let edge = Polygon::from_slice(&[DVec2::new(70.0, 1.0), DVec2::new(71.0, 1.0), DVec2::new(70.0, 2.0)]);
        assert_eq!(tiles_of(screen_bounds(&edge, 64, 32)), 0);
        assert_eq!(tiles_of(screen_bounds(&Polygon::from_slice(&[DVec2::ZERO, DVec2::ONE]), 64, 32)), 0);
    }

    #[test]
    fn every_estimator_has_a_shader_id_and_device_names_round_trip() {
        let ids: Vec<u32> = Weighting::all(&[4]).into_iter().map(estimator_id).collect();
        assert_eq!(ids, vec![0, 1, 2, 3, 4, 5, 6]);
        for d in Device::ALL {
            assert_eq!(d.name().parse::<Device>().unwrap(), d);
        }
    }
}
