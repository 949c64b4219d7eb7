//! The GPU: one more structure beside [`crate::raster`] and [`crate::bvh`], whose gather runs in
//! WGSL compute shaders through wgpu (Vulkan, Metal, DX12): the design is in `docs/gpu.md`.
//!
//! The planes are sampled and prepared on the CPU as for every structure ([`GatherContext`]);
//! what crosses is defined once, beside the CPU's prepared plane: [`PlaneRecord`] per plane,
//! the [`crate::occlusion::Occluder`]s as they are, and per plane its screen polygon
//! ([`ScreenReach`]). On the GPU, `reach.wgsl` finds the tiles and pixels each polygon comes
//! near (the specification: [`tile_reach`]), `bin.wgsl` bins the planes to 16 x 16 tiles
//! (count, prefix sum, scatter, in plane order) and cuts each tile's list into work items
//! of at most [`item_planes`] planes; `gather.wgsl` gathers a work item per workgroup, each
//! pixel's sum in registers, and adds a tile's items in order. The f32 sums come back and are
//! added to the caller's sums, which the render adds into its canonical f64 chunk sums as the
//! CPU's (so partials, merges, checkpoints and the live view are unchanged).
//!
//! Without the `gpu` feature this module still names the devices; asking for the GPU is then
//! refused in one line.

use crate::weights::{Estimator, Weighting};

mod reach;
pub use reach::{GROUP_ROWS, GROUPS, SLACK, ScreenReach, TileReach, screen_reach, tile_reach};

#[cfg(feature = "gpu")]
mod adapter;
#[cfg(feature = "gpu")]
mod device;
#[cfg(feature = "gpu")]
mod planes;
#[cfg(feature = "gpu")]
mod polygons;
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
pub use polygons::reach_on_gpu;
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

#[cfg(test)]
mod tests {
    use super::*;

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
