//! The GPU: one more structure beside [`crate::raster`] and [`crate::bvh`], whose gather runs in
//! WGSL compute shaders through wgpu (Vulkan, Metal, DX12): the design is in `docs/gpu.md`.
//!
//! The planes are sampled and prepared on the CPU as for every structure
//! ([`crate::gather::GatherContext`]); what crosses is defined once, beside the CPU's prepared
//! plane: [`crate::gather::PlaneRecord`] per plane, the [`crate::occlusion::Occluder`]s as they
//! are, and per plane its screen polygon
//! ([`ScreenReach`]). On the GPU, `reach.wgsl` finds the tiles and pixels each polygon comes
//! near (the specification: [`tile_reach`]), `bin.wgsl` bins the planes to blocks of
//! [`BLOCK_TILES`] x [`BLOCK_TILES`] tiles and from each block's list to its 16 x 16 tiles
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
pub use reach::{GROUP_ROWS, GROUPS, SLACK, ScreenReach, TileReach, screen_reach, test_polygons, tile_reach};

#[cfg(feature = "gpu")]
mod adapter;
#[cfg(feature = "gpu")]
mod batches;
#[cfg(feature = "gpu")]
mod clock;
#[cfg(feature = "gpu")]
mod device;
#[cfg(feature = "gpu")]
mod passes;
#[cfg(feature = "gpu")]
mod plane_buffers;
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
pub use adapter::{adapter, adapter_at, adapters, default_adapter};
#[cfg(feature = "gpu")]
pub use device::Gpu;
#[cfg(feature = "gpu")]
pub use passes::Recorded;
#[cfg(feature = "gpu")]
pub use planes::GpuPlanes;
#[cfg(feature = "gpu")]
pub use polygons::reach_on_gpu;
#[cfg(feature = "gpu")]
pub use rays::GpuRays;
#[cfg(feature = "gpu")]
pub use sums::{GpuSums, sums_of_bits};

#[cfg(not(feature = "gpu"))]
mod absent;
#[cfg(not(feature = "gpu"))]
pub use absent::{
    Gpu, GpuPlanes, GpuRays, GpuSums, Recorded, adapter, adapter_at, adapters, default_adapter, sums_of_bits,
};

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
    /// Whether `--device gpu` takes it: the one [`GPU_VARIABLE`] names where it is set (none
    /// where that names no adapter), else the first real GPU, else the first adapter.
    pub default: bool,
}

/// The variable a launcher sets per process to give each its own adapter (as dask-cuda sets
/// `CUDA_VISIBLE_DEVICES` per worker): `--device gpu` (Python's `device="gpu"`) then takes
/// adapter `FOGPLANES_GPU` of [`adapters`].
pub const GPU_VARIABLE: &str = "FOGPLANES_GPU";

/// An adapter's index as `gpu:N` and [`GPU_VARIABLE`] write it: decimal digits alone (no sign,
/// no space), within a `usize`.
pub fn adapter_index(s: &str) -> Option<usize> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

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
            Some(n) => adapter_index(n).map(|i| Device::Gpu(Some(i))).ok_or_else(|| {
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

/// Tiles on a block's side: the binning's first tier lists a batch's planes per block of 4 x 4
/// tiles (64 x 64 pixels), and each tile takes its candidates from its block's list
/// (`bin.wgsl`). Counted on the benchmark's planes at 640x360 (16,384 planes), the two tiers
/// test 3.5 times the (tile, plane) pairs with blocks of 4 x 4 tiles, 5.8 with 2 x 2 and 4.8
/// with 8 x 8, where one tier (every plane at every tile) tests 16.8 times; at 1280x720, 3.2
/// times against 21.
pub const BLOCK_TILES: u32 = 4;

/// The blocks of a `width x height` image.
pub fn blocks(width: u32, height: u32) -> u64 {
    (width.div_ceil(TILE).div_ceil(BLOCK_TILES) * height.div_ceil(TILE).div_ceil(BLOCK_TILES)) as u64
}

/// The most planes binned and gathered in one batch: the binning's loops then run at most 64
/// times per invocation.
pub const BATCH_PLANES: usize = 16_384;

/// The most segments of a batch (`bin.wgsl`'s `Params::segments`, its `segs` two a row): a
/// join's pieces along their ray sets, each binned with the batch and cut into work items of
/// its own (gpu/batches.rs).
pub const BATCH_SEGMENTS: usize = 32;

/// The work items a round's item size aims at ([`item_planes`]): several waves of the gather's
/// workgroups on a large GPU (an H100 holds about a thousand at once). A render's piece of
/// planes (a chunk's share of a ray set: about 2,300 planes on the benchmark) lists a mean of
/// about 140 planes a tile and the longest tiles about 7 times that: in items of 512 planes, a
/// piece is one wave of about as many items as tiles, as long as its longest item, with most
/// of the GPU idle before it ends.
pub const ITEMS_AIMED: u64 = 8192;

/// The most bytes of ray sets that work not yet submitted holds: past it, the work is submitted
/// at once (a large image's ray sets are then let go as their gatherings end), and a gathering
/// makes its sets side by side up to it at a time.
pub const PENDING_RAY_BYTES: u64 = 256 << 20;

/// The most planes of one work item of a round of at most `pairs` (tile, plane) pairs: a power
/// of two near `pairs / ITEMS_AIMED`, from 32 planes to 512 on a GPU (the prototype's best on
/// an H100 with 40,960 planes in one batch, a mean of about 2,400 planes a tile) and to 256 on
/// a CPU adapter, whose llvmpipe silently ends an invocation's loops after about 65,000
/// iterations (a work item with 64 orientations and 63 panels' occluders per hit stays at
/// 256 x 127: tested by the hit counts against the CPU's); `fixed` instead where given
/// ([`ITEM_VARIABLE`]), within the same most. A round's items are then at most its batches' tiles and
/// `2 ITEMS_AIMED` more, or its pairs over 512 where they are many.
pub fn item_planes(cpu_adapter: bool, pairs: u64, fixed: Option<u32>) -> u32 {
    let most = if cpu_adapter { 256 } else { 512 };
    match fixed {
        Some(n) => n.clamp(1, most),
        None => (pairs / ITEMS_AIMED).clamp(32, most as u64).next_power_of_two() as u32,
    }
}

/// The timestamps of a round of a gathering, where the adapter has them: its first pass's
/// start, its gather's start, its last pass's end (`clock.rs`; with the trace on, every pass's
/// start and end instead, the rounds' among them).
pub const TIMESTAMPS: u32 = 3;

/// The variable that fixes the planes of a work item, for measuring the item size on a device
/// (`scripts/gpu_check.sh`): a number from 1 to 512 (at most 256 on a CPU adapter).
pub const ITEM_VARIABLE: &str = "FOGPLANES_GPU_ITEM_PLANES";
/// The variable that gives the gather the GPU's own `exp`, `log`, `atan` and `atan2`
/// (`native`) instead of the CPU's polynomials (`polynomials`, the default), for measuring them.
pub const MATH_VARIABLE: &str = "FOGPLANES_GPU_MATH";
/// The variable that turns wgpu's shader runtime checks off (`off`; `on`, the default), for
/// measuring them.
pub const CHECKS_VARIABLE: &str = "FOGPLANES_GPU_CHECKS";
/// The variable that has each plane's K orientations made once a gathering (`table`) rather
/// than at every hit (`per-hit`, the default), for measuring it.
pub const ORIENTATIONS_VARIABLE: &str = "FOGPLANES_GPU_ORIENTATIONS";

/// The variable that has a render's pieces of a chunk gathered one by one (`apart`), not joined
/// into one structure whose work items are gathered in one dispatch (`joined`, the default),
/// for measuring the join.
pub const PIECES_VARIABLE: &str = "FOGPLANES_GPU_PIECES";

/// The variable that has every plane of a batch tested at every tile (`flat`), not the tiles'
/// candidates taken from their blocks' lists (`blocks`, the default), for measuring the first
/// tier of the binning.
pub const BINNING_VARIABLE: &str = "FOGPLANES_GPU_BINNING";

/// The variable that makes K of K orientations a constant of the gather's pipeline
/// (`constant`), not a parameter read at each hit (`uniform`, the default), for measuring it.
pub const K_VARIABLE: &str = "FOGPLANES_GPU_K";

/// The variable that has a workgroup's invocations take a tile's pixels in row order (`rows`, a
/// warp of 32 two rows of 16), not in blocks of 8 x 4 (`blocks`, the default), for measuring it.
pub const LANES_VARIABLE: &str = "FOGPLANES_GPU_LANES";

/// The choices that only a device can decide (issue 45: the work items' size, the GPU's own
/// transcendental functions, wgpu's runtime checks in the shaders, where K orientations are
/// made, whether a chunk's pieces are gathered in one dispatch, the binning's tiers, K a
/// pipeline constant, the pixels a warp takes), fixed by variables so that `scripts/gpu_check.sh` can time each against the
/// defaults in one process per setting. Read once where an adapter is resolved
/// ([`adapter_at`]), which every front end's settings do once; a device is made with them and
/// kept for the process. Any setting but the defaults is named after the adapter in the
/// summary and in every record of the render ([`Tuning::label`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Tuning {
    /// The planes of every work item ([`ITEM_VARIABLE`]), else sized by the round
    /// ([`item_planes`]).
    pub item_planes: Option<u32>,
    /// `exp`, `log`, `atan` and `atan2` of the GPU's driver ([`MATH_VARIABLE`]` = native`) in
    /// `gather.wgsl`, not the CPU's polynomials: the image is then not within the CPU's f32
    /// rounding but within the driver's accuracy for them. WGSL allows `exp` 3 + 2|x| ULP,
    /// `atan` and `atan2` 4096 ULP, and `log` 3 ULP but only an absolute 2^-21 on [0.5, 2],
    /// where the closed form of cmis-exact takes ln(1 + x) of small x (docs/mathematics.md
    /// section 3): a device's log2 may lose the small logarithms that the polynomial keeps.
    pub native_math: bool,
    /// wgpu's runtime checks off ([`CHECKS_VARIABLE`]` = off`, `ShaderRuntimeChecks::unchecked`):
    /// no clamps added to the shaders' indexing, no bound forced on their loops, no guard on
    /// their integer divisions. (Where the driver has robust buffer access, as NVIDIA's and
    /// lavapipe's do, wgpu adds no checks to storage buffers' indexing either way: what goes is
    /// the clamps on workgroup, local and vector indices, the loops' bounds and the guards.)
    /// Every index of the shaders is in range, every loop counts to a bound and every divisor
    /// is at least 1 (device.rs says why), so the image is the same bits (tested on lavapipe);
    /// what it saves is for a device to say.
    pub unchecked: bool,
    /// With K orientations (smis-cosine and smis-exact, K != 2), each plane's K - 1 further
    /// orientations (the rotated chord direction and its two reciprocals) made once a
    /// gathering into a table (`gather.wgsl`'s `orient`, [`ORIENTATIONS_VARIABLE`]` = table`),
    /// as the CPU makes them once a plane, instead of at every hit: four multiplies, two adds
    /// and a flip an orientation and hit (and for smis-exact two divisions) become a load of 16
    /// bytes that every thread of a workgroup reads alike. The same operations, so the same bits
    /// on lavapipe (tested; a driver that fuses multiply-adds may fuse the two shaders' alike or
    /// not: `scripts/gpu_check.sh` compares the images on a device); on lavapipe it took about
    /// as long (K = 8, 160x90, 4,096 planes: 0.97 and 1.05 s of GPU time against 0.95 and
    /// 0.93), so what it saves is for a device to say.
    pub orientation_table: bool,
    /// A render's pieces gathered one by one ([`PIECES_VARIABLE`]` = apart`), as before the
    /// join: each piece's batches binned and gathered in dispatches of their own, along its own
    /// ray set's buffer, rather than the pieces of a chunk along one gathering's sets joined
    /// into one structure ([`GpuPlanes::join`]) whose work items a dispatch a round gathers.
    /// The same bits where the work items' size is fixed ([`ITEM_VARIABLE`]; tested on
    /// lavapipe), else within f32 rounding: a joined round's items are sized by all its pairs.
    pub pieces_apart: bool,
    /// The binning in one tier ([`BINNING_VARIABLE`]` = flat`), as before the blocks: each
    /// tile's workgroup tests every plane of its batch, rather than the planes its block of
    /// [`BLOCK_TILES`] x [`BLOCK_TILES`] tiles lists (`bin.wgsl`). The tiles' lists are the same,
    /// so the image is the same bits (tested on lavapipe); the first tier costs three more
    /// passes a batch, each much shorter (on lavapipe, the binning of the benchmark's batches
    /// a fifth to a quarter of the flat one's time; a GPU's passes are not bound by their work
    /// alone: for a device to say).
    pub flat_binning: bool,
    /// K of smis-cosine and smis-exact with K orientations a constant of the gather's pipeline
    /// ([`K_VARIABLE`]` = constant`, `gather.wgsl`'s `ORIENTATIONS`), one pipeline a K, rather
    /// than read from the parameters: a driver can unroll the loop over the orientations. The
    /// same operations, so the same bits (tested on lavapipe); on lavapipe the gather took a
    /// little longer with it (smis-exact, K = 8, 160x90, 8,192 planes, three runs each
    /// alternated: 1.80, 1.79 and 1.86 s against 1.73, 1.74 and 1.72), so what it does on a GPU
    /// is for a device to say.
    pub k_constant: bool,
    /// A tile's pixels taken by the gather's invocations in row order ([`LANES_VARIABLE`]` =
    /// rows`), invocation i the tile's pixel i, as before the blocks: a warp of 32 lanes is two
    /// rows of 16 pixels. By default a warp is a block of 8 columns by 4 rows (`gather.wgsl`'s
    /// `pixel_of`), within one group of rows of a plane's column ranges and one half of the
    /// tile, so that fewer of the lanes that wait for a hit's arithmetic are out of the plane's
    /// columns: of the lanes of the warps that test a plane, 79% are in its columns by rows
    /// and 89% by blocks (the benchmark's 40,960 planes, `gpu::tile_reach`'s ranges). A wave of
    /// 64 is four rows of 16 either way, and lavapipe's lanes 8 of a row. The same pixels, each
    /// summed in the same order: the same bits (tested on lavapipe); what the blocks save is
    /// for a device to say.
    pub row_lanes: bool,
}

impl Tuning {
    /// The settings the variables give, or the one line that says which variable holds what.
    pub fn from_env() -> std::result::Result<Self, String> {
        // Unset is the default; a value that is set, even empty, must name a choice.
        let read = |name: &str| std::env::var(name).ok();
        let item_planes = match read(ITEM_VARIABLE) {
            None => None,
            Some(v) => match v.trim().parse::<u32>() {
                Ok(n) if (1..=512).contains(&n) => Some(n),
                _ => {
                    return Err(format!(
                        "{ITEM_VARIABLE}={v:?}: expected the planes of a GPU work item, a number from 1 to 512"
                    ));
                }
            },
        };
        let choice = |name: &str, default: &str, other: &str| match read(name) {
            None => Ok(false),
            Some(v) if v.trim() == default => Ok(false),
            Some(v) if v.trim() == other => Ok(true),
            Some(v) => Err(format!("{name}={v:?}: expected {default} (the default) or {other}")),
        };
        let native_math = choice(MATH_VARIABLE, "polynomials", "native")?;
        let unchecked = choice(CHECKS_VARIABLE, "on", "off")?;
        let orientation_table = choice(ORIENTATIONS_VARIABLE, "per-hit", "table")?;
        let pieces_apart = choice(PIECES_VARIABLE, "joined", "apart")?;
        let flat_binning = choice(BINNING_VARIABLE, "blocks", "flat")?;
        let k_constant = choice(K_VARIABLE, "uniform", "constant")?;
        let row_lanes = choice(LANES_VARIABLE, "blocks", "rows")?;
        Ok(Tuning {
            item_planes,
            native_math,
            unchecked,
            orientation_table,
            pieces_apart,
            flat_binning,
            k_constant,
            row_lanes,
        })
    }

    /// What a device made with these settings adds to its adapter's name, `None` for the
    /// defaults: a render's summary and records say how the image was made.
    pub fn label(&self) -> Option<String> {
        let mut parts = Vec::new();
        if let Some(n) = self.item_planes {
            parts.push(format!("work items of {n} planes"));
        }
        if self.native_math {
            parts.push("the driver's exp, log and atan".to_string());
        }
        if self.unchecked {
            parts.push("no shader runtime checks".to_string());
        }
        if self.orientation_table {
            parts.push("orientations made once a gathering".to_string());
        }
        if self.pieces_apart {
            parts.push("pieces gathered apart".to_string());
        }
        if self.flat_binning {
            parts.push("flat binning".to_string());
        }
        if self.k_constant {
            parts.push("K a pipeline constant".to_string());
        }
        if self.row_lanes {
            parts.push("lanes by rows".to_string());
        }
        (!parts.is_empty()).then(|| parts.join(", "))
    }
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

    /// A work item's planes grow with the batch's pairs, as powers of two within their bounds,
    /// so that a batch's items stay near the aim; a fixed size is kept within the most.
    #[test]
    fn work_items_are_sized_by_the_batch() {
        let items = |pairs: u64, cpu: bool| pairs / item_planes(cpu, pairs, None) as u64;
        assert_eq!(item_planes(false, 0, None), 32);
        assert_eq!(item_planes(false, 300_000, None), 64, "a piece of the benchmark: its bound");
        assert_eq!(item_planes(false, 2_120_000, None), 512, "a batch of 16,384 planes at 640x360: its bound");
        assert_eq!(item_planes(true, 2_120_000, None), 256);
        for pairs in [40_000u64, 300_000, 1 << 20, 4 << 20] {
            assert!(item_planes(false, pairs, None).is_power_of_two());
            assert!(items(pairs, false) <= 2 * ITEMS_AIMED, "{pairs} pairs: {} items", items(pairs, false));
        }
        assert_eq!(item_planes(false, 0, Some(48)), 48);
        assert_eq!(item_planes(true, 0, Some(512)), 256);
    }

    /// The defaults add nothing to an adapter's name; any other setting is named, in words a
    /// device's name may hold (no "; ", which joins the devices of a merge).
    #[test]
    fn a_tuning_is_named_unless_it_is_the_defaults() {
        assert_eq!(Tuning::default().label(), None);
        let all = Tuning {
            item_planes: Some(64),
            native_math: true,
            unchecked: true,
            orientation_table: true,
            pieces_apart: true,
            flat_binning: true,
            k_constant: true,
            row_lanes: true,
        };
        let label = all.label().unwrap();
        assert_eq!(
            label,
            "work items of 64 planes, the driver's exp, log and atan, no shader runtime checks, orientations made once a gathering, pieces gathered apart, flat binning, K a pipeline constant, lanes by rows"
        );
        let name = format!("gpu: {} (Vulkan, discrete GPU, tuned: {label})", "x".repeat(100));
        assert!(crate::options::Devices::from_names(vec![name]).is_ok());
    }

    #[test]
    fn every_estimator_has_a_shader_id_and_device_names_round_trip() {
        let ids: Vec<u32> = Weighting::all(&[4]).into_iter().map(estimator_id).collect();
        assert_eq!(ids, vec![0, 1, 2, 3, 4, 5, 6]);
        for d in Device::ALL.into_iter().chain([Device::Gpu(Some(0)), Device::Gpu(Some(12))]) {
            assert_eq!(d.to_string().parse::<Device>().unwrap(), d);
        }
        for bad in ["gpu:", "gpu:x", "gpu:-1", "gpu:+0", "gpu: 1", "gpu:1 ", "gpu:99999999999999999999999", "tpu"] {
            assert!(bad.parse::<Device>().is_err(), "{bad}");
        }
    }
}
