//! The GPU through wgpu: the device and queue of the adapter a render gathers on, its pipelines
//! and bind group layouts, and the helpers every piece of work on it uses (error scopes,
//! buffers, bind group entries, grids). The work itself is in the files beside it: the planes
//! ([`super::planes`], their buffers in [`super::plane_buffers`]), a gathering's passes
//! ([`super::passes`]), the rays ([`super::rays`]), the sums ([`super::sums`]).

use super::records::{BIN_WGSL, GATHER_WGSL, RAYS_WGSL, REACH_WGSL};
use super::scratch::{self, Scratch};
use crate::error::{Error, Result};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use wgpu::util::DeviceExt;

/// The adapter and device, with the pipelines made so far.
pub struct Gpu {
    pub(super) device: wgpu::Device,
    pub(super) queue: wgpu::Queue,
    /// The adapter's name, back end and kind, as `--device auto` reports it.
    name: String,
    /// A CPU adapter (lavapipe): smaller work items ([`super::item_planes`]).
    cpu_adapter: bool,
    /// The choices fixed for measuring them ([`super::Tuning`], read by [`super::adapter_at`]
    /// before the device was made).
    tuning: super::Tuning,
    timestamps: bool,
    max_binding: u64,
    pub(super) bin_layout: wgpu::BindGroupLayout,
    pub(super) gather_layout: wgpu::BindGroupLayout,
    /// The binning's passes (`bin.wgsl`): the blocks' count, scan and scatter, then the tiles'.
    pub(super) bin: [wgpu::ComputePipeline; 6],
    pub(super) rays_layout: wgpu::BindGroupLayout,
    pub(super) rays: wgpu::ComputePipeline,
    pub(super) reach_layout: wgpu::BindGroupLayout,
    pub(super) reach: wgpu::ComputePipeline,
    gather_module: wgpu::ShaderModule,
    gather_pipeline_layout: wgpu::PipelineLayout,
    /// Per estimator and constant K, 0 where K is read from the parameters (`gather.wgsl`'s
    /// ESTIMATOR and ORIENTATIONS): its pipelines ([`GatherPipelines`]).
    gather: Mutex<HashMap<(u32, u32), Arc<GatherPipelines>>>,
    /// Errors the device reported outside every error scope ([`Gpu::checked`]: each call's own
    /// errors are caught on its thread), taken after each wait.
    errors: Arc<Mutex<Vec<String>>>,
    /// The gatherings' scratch buffers, held by a gathering for its submissions. No lock is
    /// held by an upload: the render prepares the next chunk's planes while it gathers one, and
    /// a lock held across a submission (which a CPU adapter runs before it returns) kept the
    /// preparation waiting for the other side's whole gathering.
    pub(super) scratch: Mutex<Scratch>,
}

/// The words for an adapter's kind (the summary's label here, `fogplanes devices` in
/// `adapter.rs`, which builds on this file: the adapters' list makes a [`Gpu`] of the one it picks).
pub(super) fn kind_name(kind: wgpu::DeviceType) -> &'static str {
    match kind {
        wgpu::DeviceType::DiscreteGpu => "discrete GPU",
        wgpu::DeviceType::IntegratedGpu => "integrated GPU",
        wgpu::DeviceType::VirtualGpu => "virtual GPU",
        wgpu::DeviceType::Cpu => "CPU emulation",
        wgpu::DeviceType::Other => "other",
    }
}

/// Runs a future of wgpu's to its end on this thread.
pub(super) fn block_on<F: std::future::Future>(f: F) -> F::Output {
    let mut f = std::pin::pin!(f);
    let mut cx = std::task::Context::from_waker(std::task::Waker::noop());
    loop {
        if let std::task::Poll::Ready(v) = f.as_mut().poll(&mut cx) {
            return v;
        }
        std::thread::yield_now();
    }
}

fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// The compute pipeline of `entry` in `module`.
fn compute_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    entry: &str,
    compilation_options: wgpu::PipelineCompilationOptions,
) -> wgpu::ComputePipeline {
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        layout: Some(layout),
        module,
        entry_point: Some(entry),
        compilation_options,
        cache: None,
    })
}

fn uniform_entry() -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding: 0,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

impl Gpu {
    /// The device on `adapter`, with its pipelines ([`super::adapter`] finds the adapter).
    pub(super) fn new(adapter: wgpu::Adapter, tuning: super::Tuning) -> std::result::Result<Self, String> {
        let info = adapter.get_info();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let limits = adapter.limits();
        let _s = crate::trace::span("device asked for");
        let (device, queue) = block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("fogplanes"),
            required_features: if timestamps { wgpu::Features::TIMESTAMP_QUERY } else { wgpu::Features::empty() },
            required_limits: limits.clone(),
            // Small blocks of memory (4 MB on the host, 8 MB on the device, growing), not
            // wgpu's default of 64 and 128 MB: a render's first read-back buffer then costs no
            // 64 MB block of pinned host memory (about 20 ms on an H200's driver, in the first
            // gathering of every process: docs/gpu_measurements.md, the timeline), and
            // fogplanes' buffers are few and large.
            memory_hints: wgpu::MemoryHints::MemoryUsage,
            ..Default::default()
        }))
        .map_err(|e| format!("the GPU adapter {} gave no device: {e}", info.name))?;
        drop(_s);
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            sink.lock().unwrap_or_else(|p| p.into_inner()).push(crate::error::one_line(&e.to_string()))
        }));
        // A bind group layout of a uniform at binding 0, then storage buffers, read-only or not.
        let layout = |label: &str, read_only: &[bool]| {
            let mut entries = vec![uniform_entry()];
            entries.extend(read_only.iter().enumerate().map(|(i, &r)| storage_entry(i as u32 + 1, r)));
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries })
        };
        let pipeline_layout = |layout: &wgpu::BindGroupLayout| {
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: None,
                bind_group_layouts: &[Some(layout)],
                immediate_size: 0,
            })
        };
        let shader = |label: &str, source: &str| {
            let desc =
                wgpu::ShaderModuleDescriptor { label: Some(label), source: wgpu::ShaderSource::Wgsl(source.into()) };
            if tuning.unchecked {
                // SAFETY: wgpu asks that no index of the shaders leave its buffer or array,
                // that every loop end and that no integer division be by zero. Each index is
                // clamped into its array (a pixel's ray, a work item), below a constant (a
                // tile's rows and columns, a batch's staged rows), or comes from the binning's
                // counts and offsets, which stay within the buffers sized from the CPU's bound
                // on each plane's (tile, plane) pairs (`ScreenReach::pairs`: the GPU's reach
                // takes a narrower margin than the CPU's, reach.wgsl); every loop counts up to
                // a bound read once (a batch's planes, a plane's occluders, the orientations)
                // or halves its range (a binary search); every divisor is a constant, the
                // tiles across (at least 1) or a work item's planes (1 to 512). Only for
                // measuring (scripts/gpu_check.sh), never by default.
                unsafe { device.create_shader_module_trusted(desc, wgpu::ShaderRuntimeChecks::unchecked()) }
            } else {
                device.create_shader_module(desc)
            }
        };
        let pipeline = |layout: &wgpu::PipelineLayout, module: &wgpu::ShaderModule, entry: &str| {
            compute_pipeline(&device, layout, module, entry, Default::default())
        };
        let (r, w) = (true, false);
        let bin_layout = layout("bin", &[r, w, w, w, w, w, r, w, r, w]);
        let gather_layout = layout("gather", &[r, r, r, r, r, r, r, w, w, r, w]);
        let rays_layout = layout("rays", &[r, r, w]);
        let reach_layout = layout("reach", &[r, r, w, w]);
        let (bin_module, bin_pipeline_layout) = (shader("bin.wgsl", BIN_WGSL), pipeline_layout(&bin_layout));
        let _s = crate::trace::span("pipelines made: bin, rays, reach");
        let bin = ["block_count", "block_scan", "block_scatter", "count", "scan", "scatter"]
            .map(|entry| pipeline(&bin_pipeline_layout, &bin_module, entry));
        let rays = pipeline(&pipeline_layout(&rays_layout), &shader("rays.wgsl", RAYS_WGSL), "rays_main");
        let reach = pipeline(&pipeline_layout(&reach_layout), &shader("reach.wgsl", REACH_WGSL), "reach_rows");
        let gather_module = shader("gather.wgsl", GATHER_WGSL);
        drop(_s);
        let kind = kind_name(info.device_type);
        let gpu = Gpu {
            name: {
                // The work items' size as the adapter takes it (at most 256 on a CPU adapter).
                let cpu = info.device_type == wgpu::DeviceType::Cpu;
                let items = tuning.item_planes.map(|n| super::item_planes(cpu, 0, Some(n)));
                let shown = super::Tuning { item_planes: items, ..tuning };
                match shown.label() {
                    None => format!("{} ({:?}, {kind})", info.name, info.backend),
                    Some(tuned) => format!("{} ({:?}, {kind}, tuned: {tuned})", info.name, info.backend),
                }
            },
            cpu_adapter: info.device_type == wgpu::DeviceType::Cpu,
            tuning,
            timestamps,
            max_binding: limits.max_storage_buffer_binding_size.min(limits.max_buffer_size),
            gather_pipeline_layout: pipeline_layout(&gather_layout),
            device,
            queue,
            bin_layout,
            gather_layout,
            bin,
            rays_layout,
            rays,
            reach_layout,
            reach,
            gather_module,
            gather: Mutex::new(HashMap::new()),
            errors,
            scratch: Mutex::new(Scratch::default()),
        };
        gpu.take_errors().map_err(|e| format!("the GPU's shaders: {e}"))?;
        Ok(gpu)
    }

    /// The adapter: its name, back end and kind.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Whether the adapter runs on the CPU (lavapipe).
    pub fn is_cpu_adapter(&self) -> bool {
        self.cpu_adapter
    }

    /// The work items' size fixed for measuring, if it is ([`super::ITEM_VARIABLE`]).
    pub fn fixed_item_planes(&self) -> Option<u32> {
        self.tuning.item_planes
    }

    /// Whether a render's pieces of a chunk are joined into one gathering
    /// ([`super::Tuning::pieces_apart`] not asked for).
    pub fn joins_pieces(&self) -> bool {
        !self.tuning.pieces_apart
    }

    /// Whether the binning tests every plane of a batch at every tile
    /// ([`super::Tuning::flat_binning`]).
    pub fn bins_flat(&self) -> bool {
        self.tuning.flat_binning
    }

    /// The most bytes one buffer binding holds on this device.
    pub fn max_binding(&self) -> u64 {
        self.max_binding
    }

    /// Whether the gather is timed by the GPU's timestamps (else by the wall time from a chunk's
    /// first submission to its sums read back: an upper bound, the CPU's work between its
    /// submissions included).
    pub fn has_timestamps(&self) -> bool {
        self.timestamps
    }

    fn take_errors(&self) -> std::result::Result<(), String> {
        let mut errors = self.errors.lock().unwrap_or_else(|p| p.into_inner());
        if errors.is_empty() {
            return Ok(());
        }
        let all = errors.join("; ");
        errors.clear();
        Err(all)
    }

    /// [`Gpu::take_errors`] as an [`Error::Device`] (after a wait).
    pub(super) fn work_errors(&self) -> Result<()> {
        self.take_errors().map_err(Error::Device)
    }

    /// `f()` with the device's errors that it causes caught and returned in one line: wgpu's
    /// error scopes are the calling thread's own, so that work on another thread (the render's
    /// other side) neither sees these errors nor waits for this work.
    pub(super) fn checked<T>(&self, f: impl FnOnce() -> T) -> Result<T> {
        let filters = [wgpu::ErrorFilter::Validation, wgpu::ErrorFilter::OutOfMemory, wgpu::ErrorFilter::Internal];
        let scopes = filters.map(|filter| self.device.push_error_scope(filter));
        let out = f();
        // Popped innermost first, as they were pushed.
        let errors: Vec<String> = scopes
            .into_iter()
            .rev()
            .filter_map(|scope| block_on(scope.pop()))
            .map(|e| crate::error::one_line(&e.to_string()))
            .collect();
        if errors.is_empty() { Ok(out) } else { Err(Error::Device(errors.join("; "))) }
    }

    /// Makes the gather's pipelines for `weighting` now if they are not made yet: a render
    /// does it beside the preparation of its first planes, which its first gathering waits
    /// for otherwise (the WGSL translated and the driver's cache looked up: about 3 ms on an
    /// H200, 100 to 200 ms where the driver's cache does not hold them yet).
    pub fn compile_gather(&self, weighting: crate::weights::Weighting) -> Result<()> {
        self.checked(|| {
            self.gather_pipelines(weighting);
        })
    }

    /// The gather's pipelines for `weighting`, made on first use: per estimator, and per K
    /// where K is a pipeline constant ([`super::Tuning::k_constant`]).
    pub(super) fn gather_pipelines(&self, weighting: crate::weights::Weighting) -> Arc<GatherPipelines> {
        let id = super::estimator_id(weighting);
        let k = if self.tuning.k_constant && matches!(id, 5 | 6) { weighting.orientations.max(1) } else { 0 };
        let mut cache = self.gather.lock().unwrap_or_else(|p| p.into_inner());
        cache
            .entry((id, k))
            .or_insert_with(|| {
                let flag = |on: bool| if on { 1.0 } else { 0.0 };
                let constants = [
                    ("ESTIMATOR", id as f64),
                    ("NATIVE_MATH", flag(self.tuning.native_math)),
                    ("ORIENTATION_TABLE", flag(self.tuning.orientation_table)),
                    ("ORIENTATIONS", k as f64),
                    ("LANE_BLOCKS", flag(!self.tuning.row_lanes)),
                ];
                let options =
                    wgpu::PipelineCompilationOptions { constants: &constants, zero_initialize_workgroup_memory: false };
                let make = |entry: &str| {
                    let _s = crate::trace::span("pipeline made: gather, reduce or orient");
                    compute_pipeline(
                        &self.device,
                        &self.gather_pipeline_layout,
                        &self.gather_module,
                        entry,
                        options.clone(),
                    )
                };
                // `orient` only where its table is read: a pipeline more is a translation and a
                // driver's compilation more in every process.
                let table = self.tuning.orientation_table && matches!(id, 5 | 6);
                Arc::new(GatherPipelines {
                    gather: make("gather"),
                    reduce: make("reduce"),
                    orient: table.then(|| make("orient")),
                })
            })
            .clone()
    }

    pub(super) fn upload(&self, label: &str, bytes: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
        // A binding may not be empty.
        let pad = [0u8; 32];
        let contents = if bytes.is_empty() { &pad[..] } else { bytes };
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
    }

    /// A buffer of `parts` one after another, written straight into its mapping (a join's
    /// parts cross without a copy of the whole made first), each element of part `i` changed by
    /// `patch(i, _)` on its way where given (through a copy of one part at a time, reused);
    /// never empty.
    pub(super) fn upload_parts<'a, T: bytemuck::Pod>(
        &self,
        label: &str,
        parts: impl Iterator<Item = &'a [T]> + Clone,
        patch: Option<Patch<'_, T>>,
        usage: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer> {
        let bytes: usize = parts.clone().map(std::mem::size_of_val).sum();
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (bytes as u64).max(32).next_multiple_of(4),
            usage,
            mapped_at_creation: true,
        });
        {
            let mut view = buffer
                .slice(..)
                .get_mapped_range_mut()
                .map_err(|e| crate::error::Error::Device(format!("writing {label} to the GPU: {e}")))?;
            let mut rest = view.slice(..bytes);
            let mut patched: Vec<T> = Vec::new();
            for (i, part) in parts.enumerate() {
                let (mut first, tail) = rest.split_at(std::mem::size_of_val(part));
                match patch {
                    Some(patch) => {
                        patched.clear();
                        patched.extend_from_slice(part);
                        patched.iter_mut().for_each(|t| patch(i, t));
                        first.copy_from_slice(bytemuck::cast_slice(&patched));
                    }
                    None => first.copy_from_slice(bytemuck::cast_slice(part)),
                }
                rest = tail;
            }
        }
        buffer.unmap();
        Ok(buffer)
    }

    /// A buffer the GPU fills ([`scratch::buffer`]).
    pub(super) fn scratch(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        scratch::buffer(&self.device, label, size, usage)
    }
}

/// The pipelines of `gather.wgsl` for one estimator: the gather, the reduction of a tile's
/// work items, and where K orientations are read from a table (`Tuning::orientation_table`),
/// the pass that makes it.
pub(super) struct GatherPipelines {
    pub(super) gather: wgpu::ComputePipeline,
    pub(super) reduce: wgpu::ComputePipeline,
    pub(super) orient: Option<wgpu::ComputePipeline>,
}

/// What [`Gpu::upload_parts`] does to each element of a part on its way (the part's index, the
/// element).
pub(super) type Patch<'p, T> = &'p dyn Fn(usize, &mut T);

pub(super) fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource: buffer.as_entire_binding() }
}

/// `n` workgroups as a grid within the 65,535 a dimension allows (the shaders number them
/// `y * x_count + x` and skip those past `n`).
pub(super) fn grid(n: u64) -> (u32, u32) {
    let x = n.clamp(1, 65_535);
    (x as u32, n.div_ceil(x).max(1) as u32)
}
