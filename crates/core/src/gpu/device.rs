//! The GPU through wgpu: the adapter, found once per process, its pipelines, and the planes of
//! a structure on it ([`GpuPlanes`]).

use super::{BATCH_PLANES, TILE, TileReach, estimator_id, item_planes};
use crate::camera::{CameraRay, RayRowFn};
use crate::control::Control;
use crate::error::{Error, Result};
use crate::gather::{GatherContext, GatherStats, Phase, PlaneRecord};
use crate::pixel::{PanelRecord, RaySetRecord};
use crate::weights::Weighting;
use glam::Vec3;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;
use wgpu::util::DeviceExt;

const GATHER_WGSL: &str = include_str!("gather.wgsl");
const BIN_WGSL: &str = include_str!("bin.wgsl");
const RAYS_WGSL: &str = include_str!("rays.wgsl");

/// Bytes of one work item's partial sums: 256 pixels of (r, g, b, hits) in f32.
const ITEM_BYTES: u64 = (TILE * TILE) as u64 * 16;

/// `gather.wgsl`'s `Params`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GatherParams {
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles: u32,
    sigma_t: [f32; 3],
    grey: u32,
    orientations: u32,
    inv_orientations: f32,
    /// gather.rs `Phase`: `abs(g)`, `(1 - abs(g))^2`, `1 / (1 - g^2)`, and whether g != 0.
    phase_h: f32,
    phase_floor: f32,
    phase_inv_numerator: f32,
    phase_hg: u32,
    pad: [u32; 2],
}

/// `bin.wgsl`'s `Params`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct BinParams {
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles: u32,
    count: u32,
    first: u32,
    item_planes: u32,
    pad: u32,
}

/// The adapter and device, with the pipelines made so far.
pub struct Gpu {
    device: wgpu::Device,
    queue: wgpu::Queue,
    /// The adapter's name, back end and kind, as `--device auto` reports it.
    name: String,
    /// A CPU adapter (lavapipe): smaller work items ([`item_planes`]).
    cpu_adapter: bool,
    timestamps: bool,
    max_binding: u64,
    bin_layout: wgpu::BindGroupLayout,
    gather_layout: wgpu::BindGroupLayout,
    bin: [wgpu::ComputePipeline; 3],
    rays_layout: wgpu::BindGroupLayout,
    rays: wgpu::ComputePipeline,
    gather_module: wgpu::ShaderModule,
    gather_pipeline_layout: wgpu::PipelineLayout,
    /// Per estimator (`gather.wgsl`'s ESTIMATOR): its gather and reduce pipelines.
    gather: Mutex<HashMap<u32, Arc<[wgpu::ComputePipeline; 2]>>>,
    /// Errors the device reported outside every error scope ([`Gpu::checked`]: each call's own
    /// errors are caught on its thread), taken after each wait.
    errors: Arc<Mutex<Vec<String>>>,
    /// The gatherings' scratch buffers, held by a gathering for its submissions. No lock is
    /// held by an upload: the render prepares the next chunk's planes while it gathers one, and
    /// a lock held across a submission (which a CPU adapter runs before it returns) kept the
    /// preparation waiting for the other side's whole gathering.
    scratch: Mutex<Scratch>,
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
    pub(super) fn new(adapter: wgpu::Adapter) -> std::result::Result<Self, String> {
        let info = adapter.get_info();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let limits = adapter.limits();
        let (device, queue) = block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("fogplanes"),
            required_features: if timestamps { wgpu::Features::TIMESTAMP_QUERY } else { wgpu::Features::empty() },
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| format!("the GPU adapter {} gave no device: {e}", info.name))?;
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            sink.lock().unwrap_or_else(|p| p.into_inner()).push(crate::error::one_line(&e.to_string()))
        }));
        let bin_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("bin"),
            entries: &[
                uniform_entry(),
                storage_entry(1, true),
                storage_entry(2, false),
                storage_entry(3, false),
                storage_entry(4, false),
                storage_entry(5, false),
                storage_entry(6, false),
                storage_entry(7, true),
                storage_entry(8, false),
            ],
        });
        let mut gather_entries = vec![uniform_entry()];
        gather_entries.extend((1..=7).map(|b| storage_entry(b, true)));
        gather_entries.extend((8..=9).map(|b| storage_entry(b, false)));
        gather_entries.push(storage_entry(10, true));
        let gather_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("gather"),
            entries: &gather_entries,
        });
        let pipeline_layout = |layout: &wgpu::BindGroupLayout| {
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: None,
                bind_group_layouts: &[Some(layout)],
                immediate_size: 0,
            })
        };
        let bin_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("bin.wgsl"),
            source: wgpu::ShaderSource::Wgsl(BIN_WGSL.into()),
        });
        let bin_pipeline_layout = pipeline_layout(&bin_layout);
        let bin = ["count", "scan", "scatter"].map(|entry| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&bin_pipeline_layout),
                module: &bin_module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        });
        let rays_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("rays"),
            entries: &[uniform_entry(), storage_entry(1, true), storage_entry(2, false)],
        });
        let rays_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("rays.wgsl"),
            source: wgpu::ShaderSource::Wgsl(RAYS_WGSL.into()),
        });
        let rays = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("rays"),
            layout: Some(&pipeline_layout(&rays_layout)),
            module: &rays_module,
            entry_point: Some("rays_main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let gather_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("gather.wgsl"),
            source: wgpu::ShaderSource::Wgsl(GATHER_WGSL.into()),
        });
        let kind = kind_name(info.device_type);
        let gpu = Gpu {
            name: format!("{} ({:?}, {kind})", info.name, info.backend),
            cpu_adapter: info.device_type == wgpu::DeviceType::Cpu,
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
    fn work_errors(&self) -> Result<()> {
        self.take_errors().map_err(Error::Device)
    }

    /// `f()` with the device's errors that it causes caught and returned in one line: wgpu's
    /// error scopes are the calling thread's own, so that work on another thread (the render's
    /// other side) neither sees these errors nor waits for this work.
    fn checked<T>(&self, f: impl FnOnce() -> T) -> Result<T> {
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

    /// The gather and reduce pipelines of estimator `id`, made on first use.
    fn gather_pipelines(&self, id: u32) -> Arc<[wgpu::ComputePipeline; 2]> {
        let mut cache = self.gather.lock().unwrap_or_else(|p| p.into_inner());
        cache
            .entry(id)
            .or_insert_with(|| {
                let constants = [("ESTIMATOR", id as f64)];
                Arc::new(["gather", "reduce"].map(|entry| {
                    self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some(entry),
                        layout: Some(&self.gather_pipeline_layout),
                        module: &self.gather_module,
                        entry_point: Some(entry),
                        compilation_options: wgpu::PipelineCompilationOptions {
                            constants: &constants,
                            zero_initialize_workgroup_memory: false,
                        },
                        cache: None,
                    })
                }))
            })
            .clone()
    }

    fn upload(&self, label: &str, bytes: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
        // A binding may not be empty.
        let pad = [0u8; 32];
        let contents = if bytes.is_empty() { &pad[..] } else { bytes };
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
    }

    fn scratch(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.max(32).next_multiple_of(4),
            usage,
            mapped_at_creation: false,
        })
    }
}

/// One batch of planes: binned and gathered together.
struct Batch {
    first: u32,
    count: u32,
    /// (tile, plane) pairs: the tiles' lists' total length.
    pairs: u64,
    /// A bound on its work items.
    items: u64,
}

/// A structure's planes for the GPU, for gathering camera rays of one image size: made on the
/// CPU, uploaded by their first gathering ([`GpuPlanes::buffers`]).
pub struct GpuPlanes {
    gpu: Arc<Gpu>,
    width: u32,
    height: u32,
    /// What crosses, until it has.
    host: Mutex<Option<PlaneData>>,
    buffers: OnceLock<PlaneBuffers>,
    batches: Vec<Batch>,
    /// The pixels a gathering tests the planes at ([`TileReach::tests`]).
    tests: u64,
    sigma_t: Vec3,
    grey: bool,
    phase: Phase,
}

/// A structure's planes as they cross: [`PlaneRecord`]s, the occluders, and per plane its
/// reach (first row of tiles, rows, first span, 0) and the spans (`bin.wgsl`'s `reach` and
/// `spans`).
struct PlaneData {
    planes: Vec<PlaneRecord>,
    occluders: Vec<crate::occlusion::Occluder>,
    reach: Vec<[u32; 4]>,
    /// Per row of tiles: its span of tiles and its box of pixels ([`TileReach`]).
    spans: Vec<[u32; 4]>,
}

/// [`PlaneData`] on the GPU.
struct PlaneBuffers {
    planes: wgpu::Buffer,
    occluders: wgpu::Buffer,
    reach: wgpu::Buffer,
    spans: wgpu::Buffer,
}

impl GpuPlanes {
    /// The planes of `ctx` for `gpu`, with the tiles each reaches (`reach`, from
    /// [`super::tile_reach`]) in a `width x height` image.
    pub fn new(gpu: Arc<Gpu>, ctx: &GatherContext, reach: &[TileReach], width: u32, height: u32) -> Result<Self> {
        assert_eq!(ctx.views.len(), reach.len(), "a reach per plane");
        let mut records = Vec::with_capacity(reach.len());
        let mut spans: Vec<[u32; 4]> = Vec::new();
        for r in reach {
            records.push([r.first_row, r.spans.len() as u32, spans.len() as u32, 0]);
            spans.extend(r.spans.iter().zip(&r.pixels).map(|(&[a, b], &[x, y])| [a, b, x, y]));
        }
        // Every whole buffer within one binding: the image's rays (the largest per pixel), the
        // planes and their occluders; refused here in one line, not by the driver's validation.
        let pixels = width as u64 * height as u64;
        let whole = [
            ("the rays of a", pixels * std::mem::size_of::<CameraRay>() as u64),
            ("the planes of a chunk for a", (ctx.views.len() * std::mem::size_of::<PlaneRecord>()) as u64),
            ("the occluders of a chunk's planes for a", std::mem::size_of_val(ctx.occluders.as_slice()) as u64),
            ("the rows of tiles a chunk's planes reach in a", std::mem::size_of_val(spans.as_slice()) as u64),
        ];
        if let Some((what, bytes)) = whole.into_iter().find(|&(_, bytes)| bytes > gpu.max_binding) {
            return Err(Error::Device(format!(
                "{what} {width}x{height} image take {bytes} bytes, more than the GPU binds at once ({} bytes): render a smaller image on it, or on the CPU",
                gpu.max_binding
            )));
        }
        let tiles = (width.div_ceil(TILE) * height.div_ceil(TILE)) as u64;
        let item = item_planes(gpu.cpu_adapter) as u64;
        // Batches of consecutive planes whose work items' partial sums fit one binding.
        let max_items = gpu.max_binding / ITEM_BYTES;
        let mut batches: Vec<Batch> = Vec::new();
        for (i, r) in reach.iter().enumerate() {
            let pairs = r.tiles();
            let fits = |batch: &Batch| {
                let p = batch.pairs + pairs;
                (batch.count as usize) < BATCH_PLANES
                    && p.min(tiles) + p / item <= max_items
                    && p * 4 <= gpu.max_binding
            };
            match batches.last_mut() {
                Some(batch) if fits(batch) => {
                    batch.count += 1;
                    batch.pairs += pairs;
                }
                _ => batches.push(Batch { first: i as u32, count: 1, pairs, items: 0 }),
            }
        }
        for b in &mut batches {
            b.items = b.pairs.min(tiles) + b.pairs / item;
            if b.items > max_items || b.pairs * 4 > gpu.max_binding {
                return Err(Error::Device(format!(
                    "a plane covers more of this {width}x{height} image than the GPU's buffers hold ({} bytes a binding): render smaller images on it",
                    gpu.max_binding
                )));
            }
        }
        let planes: Vec<PlaneRecord> = {
            use rayon::prelude::*;
            ctx.views.par_iter().map(PlaneRecord::from).collect()
        };
        // Not uploaded here: the render prepares planes beside its gathering, and an upload
        // waits for the device while a submission is under way (on a CPU adapter, which runs a
        // submission before it returns, for the other side's whole gathering).
        let host = PlaneData { planes, occluders: ctx.occluders.clone(), reach: records, spans };
        Ok(GpuPlanes {
            gpu,
            width,
            height,
            host: Mutex::new(Some(host)),
            buffers: OnceLock::new(),
            batches,
            tests: reach.iter().map(TileReach::tests).sum(),
            sigma_t: ctx.extinction.sigma_t,
            grey: ctx.extinction.grey,
            phase: ctx.phase,
        })
    }

    /// The planes on the GPU, uploaded by the first call, with the nanoseconds this call spent
    /// uploading and the bytes it uploaded.
    fn buffers(&self) -> Result<(&PlaneBuffers, u64, u64)> {
        if let Some(b) = self.buffers.get() {
            return Ok((b, 0, 0));
        }
        let t = Instant::now();
        let host =
            self.host.lock().unwrap_or_else(|p| p.into_inner()).take().expect("uploaded once, on the gather side");
        let (gpu, usage) = (&self.gpu, wgpu::BufferUsages::STORAGE);
        let made = gpu.checked(|| PlaneBuffers {
            planes: gpu.upload("planes", bytemuck::cast_slice(&host.planes), usage),
            occluders: gpu.upload("occluders", bytemuck::cast_slice(&host.occluders), usage),
            reach: gpu.upload("reach", bytemuck::cast_slice(&host.reach), usage),
            spans: gpu.upload("spans", bytemuck::cast_slice(&host.spans), usage),
        })?;
        let bytes = [made.planes.size(), made.occluders.size(), made.reach.size(), made.spans.size()].iter().sum();
        Ok((self.buffers.get_or_init(|| made), t.elapsed().as_nanos() as u64, bytes))
    }

    /// Zero sums on the GPU for this structure's image ([`GpuPlanes::gather_into`]).
    pub fn new_sums(&self) -> Result<GpuSums> {
        GpuSums::new(self.gpu.clone(), self.width, self.height)
    }

    /// `rays` (one per pixel of this structure's image, row-major) uploaded to its GPU.
    pub fn upload_rays(&self, rays: &[CameraRay]) -> Result<GpuRays> {
        assert_eq!(rays.len(), self.width as usize * self.height as usize, "one ray per pixel");
        GpuRays::new(&self.gpu, rays)
    }

    /// Rays for this structure's image, each row made by `row` straight into the GPU's upload
    /// buffer ([`GpuRays::made`]).
    pub fn make_rays(&self, row: RayRowFn) -> Result<GpuRays> {
        GpuRays::made(&self.gpu, self.width as usize, self.height as usize, row)
    }

    /// Ray set `set` (with its panels) made on the GPU ([`GpuRays::on_gpu`]), for this
    /// structure's image.
    pub fn rays_on_gpu(&self, set: &RaySetRecord, panels: &[PanelRecord]) -> Result<GpuRays> {
        assert_eq!((set.width, set.height), (self.width, self.height), "a ray per pixel");
        GpuRays::on_gpu(&self.gpu, set, panels)
    }

    /// Gathers `rays` (one per pixel, row-major) with `weighting`, adding each pixel's sum to
    /// `sums`: [`GpuPlanes::gather_into`] fresh sums on the GPU, read back once. Checks
    /// `control` before each batch; reports one unit of progress.
    pub fn gather(
        &self,
        weighting: Weighting,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        control: Control,
    ) -> Result<GatherStats> {
        let pixels = self.width as usize * self.height as usize;
        assert!(rays.len() == pixels && sums.len() == pixels, "one ray and one sum per pixel");
        control.check()?;
        let mut on_gpu = self.new_sums()?;
        let rays = self.upload_rays(rays)?;
        let mut stats = self.gather_into(weighting, &rays, &mut on_gpu, control)?;
        stats += on_gpu.read_into(sums)?;
        Ok(stats)
    }

    /// Gathers `rays` with `weighting`, adding each pixel's sum and hits to `into` on the GPU:
    /// the planes in batches, each binned and gathered in turn, the work kept with `into` and
    /// submitted when it is read ([`GpuSums::read_into`]: a chunk's pieces in one submission),
    /// or sooner where the work held passes [`PENDING_RAY_BYTES`] of ray sets. Checks `control`
    /// before each batch (a cancel drops the work not submitted); reports one unit of progress.
    /// The result holds the tests and the planes' upload; the hits and the GPU's time are
    /// counted when `into` is read back.
    pub fn gather_into(
        &self,
        weighting: Weighting,
        rays: &GpuRays,
        into: &mut GpuSums,
        control: Control,
    ) -> Result<GatherStats> {
        let (gpu, w, h) = (&*self.gpu, self.width, self.height);
        let pixels = w as usize * h as usize;
        assert!(rays.len == pixels && into.pixels == pixels, "one ray and one sum per pixel");
        control.check()?;
        if self.batches.is_empty() {
            control.progress();
            return Ok(GatherStats::default());
        }
        // Compiled on first use, before the scratch buffers are held.
        let pipelines = gpu.checked(|| gpu.gather_pipelines(estimator_id(weighting)))?;
        let (planes, upload_ns, bytes_crossed) = self.buffers()?;
        gpu.checked(|| self.encode(weighting, &pipelines, planes, rays, into, control))??;
        control.progress();
        Ok(GatherStats { tests: self.tests, upload_ns, bytes_crossed, ..GatherStats::default() })
    }

    /// [`GpuPlanes::gather_into`]'s work, its batches one after another in one command buffer,
    /// kept with `into` (submitted with its reading, or sooner where it holds many ray sets).
    fn encode(
        &self,
        weighting: Weighting,
        pipelines: &[wgpu::ComputePipeline; 2],
        planes: &PlaneBuffers,
        rays: &GpuRays,
        into: &mut GpuSums,
        control: Control,
    ) -> Result<()> {
        let mut scratch = self.gpu.scratch.lock().unwrap_or_else(|p| p.into_inner());
        let (gpu, w, h) = (&*self.gpu, self.width, self.height);
        let (tiles_x, tiles_y) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let tiles = tiles_x * tiles_y;
        let item = item_planes(gpu.cpu_adapter);
        let k = weighting.orientations.max(1);
        let rotations: Vec<[f32; 2]> = (1..k)
            .map(|i| i as f64 * std::f64::consts::PI / k as f64)
            .map(|b| [b.cos() as f32, b.sin() as f32])
            .collect();
        let gather_params = GatherParams {
            width: w,
            height: h,
            tiles_x,
            tiles,
            sigma_t: self.sigma_t.to_array(),
            grey: self.grey as u32,
            orientations: k,
            inv_orientations: 1.0 / k as f32,
            phase_h: self.phase.h,
            phase_floor: self.phase.floor,
            phase_inv_numerator: self.phase.inv_numerator,
            phase_hg: !self.phase.is_isotropic() as u32,
            pad: [0; 2],
        };
        let (storage, copy_src) = (wgpu::BufferUsages::STORAGE, wgpu::BufferUsages::COPY_SRC);
        let uniform = wgpu::BufferUsages::UNIFORM;
        let params = gpu.upload("gather params", bytemuck::bytes_of(&gather_params), uniform);
        let rotations_buf = gpu.upload("rotations", bytemuck::cast_slice(&rotations), storage);
        let max_pairs = self.batches.iter().map(|b| b.pairs).max().unwrap_or(0);
        let max_items = self.batches.iter().map(|b| b.items).max().unwrap_or(0);
        let s = scratch.at_least(gpu, tiles as u64, max_pairs, max_items);
        let gather_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("gather"),
            layout: &gpu.gather_layout,
            entries: &[
                entry(0, &params),
                entry(1, &planes.planes),
                entry(2, &planes.occluders),
                entry(3, &rays.buffer),
                entry(4, &rotations_buf),
                entry(5, &s.list),
                entry(6, &s.item_offsets),
                entry(7, &s.items),
                entry(8, &s.partial),
                entry(9, &into.image),
                entry(10, &s.boxes),
            ],
        });
        // A timestamp pair per batch (its first pass's start, its last pass's end), where the
        // adapter has them, read when the sums are; else (or for a gathering of more batches
        // than a query set takes here) the sums are timed by the wall time from their first
        // submission to their reading back.
        let batches = self.batches.len();
        let queries = (gpu.timestamps && batches <= 2048).then(|| {
            let set = gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("gather time"),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * batches as u32,
            });
            let resolve = gpu.scratch("timestamps", 16 * batches as u64, wgpu::BufferUsages::QUERY_RESOLVE | copy_src);
            let readback = gpu.scratch(
                "timestamps read back",
                16 * batches as u64,
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            );
            (set, resolve, readback)
        });
        let tile_grid = grid(tiles as u64);
        // Every batch in one command buffer (the passes run in order, the scratch buffers
        // reused from batch to batch), kept with the sums to submit with their reading.
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        for (b, batch) in self.batches.iter().enumerate() {
            control.check()?;
            let bin_params = BinParams {
                width: w,
                height: h,
                tiles_x,
                tiles,
                count: batch.count,
                first: batch.first,
                item_planes: item,
                pad: 0,
            };
            let bin_params = gpu.upload("bin params", bytemuck::bytes_of(&bin_params), uniform);
            let bin_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("bin"),
                layout: &gpu.bin_layout,
                entries: &[
                    entry(0, &bin_params),
                    entry(1, &planes.reach),
                    entry(2, &s.tile_counts),
                    entry(3, &s.offsets),
                    entry(4, &s.item_offsets),
                    entry(5, &s.list),
                    entry(6, &s.items),
                    entry(7, &planes.spans),
                    entry(8, &s.boxes),
                ],
            });
            let steps: [(&wgpu::ComputePipeline, &wgpu::BindGroup, (u32, u32)); 5] = [
                (&gpu.bin[0], &bin_group, tile_grid),
                (&gpu.bin[1], &bin_group, (1, 1)),
                (&gpu.bin[2], &bin_group, tile_grid),
                (&pipelines[0], &gather_group, grid(batch.items.max(1))),
                (&pipelines[1], &gather_group, (tiles_x, tiles_y)),
            ];
            for (k, (pipeline, group, (x, y))) in steps.into_iter().enumerate() {
                let timestamp_writes =
                    queries.as_ref().filter(|_| k == 0 || k == 4).map(|(set, _, _)| wgpu::ComputePassTimestampWrites {
                        query_set: set,
                        beginning_of_pass_write_index: (k == 0).then_some(2 * b as u32),
                        end_of_pass_write_index: (k == 4).then_some(2 * b as u32 + 1),
                    });
                let mut pass =
                    encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes });
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, group, &[]);
                pass.dispatch_workgroups(x, y, 1);
            }
            if let Some((set, resolve, readback)) = queries.as_ref().filter(|_| b + 1 == batches) {
                encoder.resolve_query_set(set, 0..2 * batches as u32, resolve, 0);
                encoder.copy_buffer_to_buffer(resolve, 0, readback, 0, 16 * batches as u64);
            }
        }
        into.pending.extend(rays.take_pending());
        into.pending.push(encoder.finish());
        into.pending_rays += (rays.len * std::mem::size_of::<CameraRay>()) as u64;
        into.bytes_up += (std::mem::size_of_val(&gather_params) + std::mem::size_of_val(rotations.as_slice())) as u64
            + (self.batches.len() * std::mem::size_of::<BinParams>()) as u64;
        if !rays.made_on_gpu || into.pending_rays > PENDING_RAY_BYTES {
            *rays.last_use.lock().unwrap_or_else(|p| p.into_inner()) = into.submit();
        }
        match queries {
            Some((_, _, readback)) => into.timestamps.push(readback),
            None => into.untimed = true,
        }
        Ok(())
    }
}

/// The scratch buffers of the binning and the work items, kept from gathering to gathering
/// (grown when one needs more): made a few times a process, not once a piece.
#[derive(Default)]
struct Scratch {
    buffers: Option<ScratchBuffers>,
}

struct ScratchBuffers {
    /// Tiles, (tile, plane) pairs and work items they hold.
    capacity: (u64, u64, u64),
    tile_counts: wgpu::Buffer,
    offsets: wgpu::Buffer,
    item_offsets: wgpu::Buffer,
    list: wgpu::Buffer,
    /// Per list entry, the plane's box of pixels in the tile (`bin.wgsl`'s `boxes`).
    boxes: wgpu::Buffer,
    items: wgpu::Buffer,
    partial: wgpu::Buffer,
}

impl Scratch {
    /// Buffers for `tiles` tiles, `pairs` pairs and `items` work items: those held if they are
    /// large enough, else new ones of the larger of each.
    fn at_least(&mut self, gpu: &Gpu, tiles: u64, pairs: u64, items: u64) -> &ScratchBuffers {
        let held = self.buffers.as_ref().map_or((0, 0, 0), |b| b.capacity);
        if held.0 < tiles || held.1 < pairs || held.2 < items {
            let (tiles, pairs, items) = (held.0.max(tiles), held.1.max(pairs), held.2.max(items));
            let storage = wgpu::BufferUsages::STORAGE;
            let tile_words = (tiles + 1) * 4;
            // The old buffers are let go first (wgpu frees them once the work using them is done).
            self.buffers = None;
            self.buffers = Some(ScratchBuffers {
                capacity: (tiles, pairs, items),
                tile_counts: gpu.scratch("tile counts", tile_words, storage),
                offsets: gpu.scratch("offsets", tile_words, storage),
                item_offsets: gpu.scratch("item offsets", tile_words, storage),
                list: gpu.scratch("list", pairs * 4, storage),
                boxes: gpu.scratch("boxes", pairs * 4, storage),
                items: gpu.scratch("items", items * 16, storage),
                partial: gpu.scratch("partial", items * ITEM_BYTES, storage),
            });
        }
        self.buffers.as_ref().expect("made above")
    }
}

/// Camera rays on the GPU, one per pixel, row-major: [`CameraRay`]s (20 bytes, `gather.wgsl`'s
/// `RAY_FLOATS`), made there by `rays.wgsl` ([`GpuRays::on_gpu`]) or uploaded
/// ([`GpuRays::new`]), for every piece gathered along them.
pub struct GpuRays {
    buffer: wgpu::Buffer,
    len: usize,
    gpu: Arc<Gpu>,
    /// The pass that makes them, submitted with the first gathering along them (or when they
    /// are read back).
    pending: Mutex<Option<wgpu::CommandBuffer>>,
    upload_ns: u64,
    /// Bytes that crossed to the GPU to make them.
    bytes_up: u64,
    /// Made by the GPU: the work along them is kept to be submitted with the sums' reading
    /// (rays made on the CPU are gathered along at once, so that the CPU makes the next set
    /// while the GPU gathers).
    made_on_gpu: bool,
    /// The last submission that gathers along them.
    last_use: Mutex<Option<wgpu::SubmissionIndex>>,
}

impl GpuRays {
    /// Refused in one line where the rays of `len` pixels exceed one binding.
    fn check(gpu: &Gpu, len: usize) -> Result<u64> {
        let bytes = (len * std::mem::size_of::<CameraRay>()) as u64;
        // The shaders index their floats with u32.
        let most = gpu.max_binding.min(4 * u32::MAX as u64);
        if bytes > most {
            return Err(Error::Device(format!(
                "the rays of an image of {len} pixels take {bytes} bytes, more than the GPU binds at once ({most} bytes): render a smaller image on it, or on the CPU",
            )));
        }
        Ok(bytes)
    }

    /// `rays` uploaded to `gpu`; refused in one line where they exceed one binding.
    pub fn new(gpu: &Arc<Gpu>, rays: &[CameraRay]) -> Result<Self> {
        let bytes = Self::check(gpu, rays.len())?;
        let t = Instant::now();
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let buffer = gpu.checked(|| gpu.upload("rays", bytemuck::cast_slice(rays), usage))?;
        Ok(GpuRays {
            buffer,
            len: rays.len(),
            gpu: gpu.clone(),
            pending: Mutex::new(None),
            upload_ns: t.elapsed().as_nanos() as u64,
            bytes_up: bytes,
            made_on_gpu: false,
            last_use: Mutex::new(None),
        })
    }

    /// The ray set `set` (with its light panels `panels`) made on `gpu` by `rays.wgsl`, a
    /// thread a pixel: only the record and the panels cross. The pass is submitted with the
    /// first gathering along the rays. Refused in one line where they exceed one binding.
    pub fn on_gpu(gpu: &Arc<Gpu>, set: &RaySetRecord, panels: &[PanelRecord]) -> Result<Self> {
        let (w, h) = (set.width, set.height);
        let bytes = Self::check(gpu, w as usize * h as usize)?;
        let groups = (w.div_ceil(super::TILE), h.div_ceil(super::TILE));
        if groups.0 > 65_535 || groups.1 > 65_535 {
            return Err(Error::Device(format!(
                "a {w}x{h} image has more than 65,535 x 16 pixels on a side, more than the GPU makes rays for: render a smaller image on it, or on the CPU"
            )));
        }
        let t = Instant::now();
        let (buffer, commands) = gpu.checked(|| {
            let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
            let buffer = gpu.scratch("rays", bytes, usage);
            let record = gpu.upload("ray set", bytemuck::bytes_of(set), wgpu::BufferUsages::UNIFORM);
            let panels = gpu.upload("panels", bytemuck::cast_slice(panels), wgpu::BufferUsages::STORAGE);
            let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("rays"),
                layout: &gpu.rays_layout,
                entries: &[entry(0, &record), entry(1, &panels), entry(2, &buffer)],
            });
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&gpu.rays);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(groups.0, groups.1, 1);
            }
            (buffer, encoder.finish())
        })?;
        Ok(GpuRays {
            buffer,
            len: w as usize * h as usize,
            gpu: gpu.clone(),
            pending: Mutex::new(Some(commands)),
            upload_ns: t.elapsed().as_nanos() as u64,
            bytes_up: (std::mem::size_of_val(set) + std::mem::size_of_val(panels)) as u64,
            made_on_gpu: true,
            last_use: Mutex::new(None),
        })
    }

    /// `height` rows of `width` rays on `gpu`, row `j` made by `row(j, out)` and written
    /// straight into the buffer that uploads them (mapped at its creation), the rows in
    /// parallel: no copy of the set on the CPU. Refused in one line where they exceed one
    /// binding.
    pub fn made(gpu: &Arc<Gpu>, width: usize, height: usize, row: RayRowFn) -> Result<Self> {
        use rayon::prelude::*;
        let len = width * height;
        let bytes = Self::check(gpu, len)?;
        let t = Instant::now();
        let buffer = gpu.checked(|| {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("rays"),
                // A binding may not be empty; 20 bytes a ray keep the size a multiple of 4.
                size: bytes.max(32),
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: true,
            })
        })?;
        let filling = Instant::now();
        {
            let mut view = buffer
                .slice(..)
                .get_mapped_range_mut()
                .map_err(|e| Error::Device(format!("writing rays to the GPU: {e}")))?;
            // Mapped memory may be write-combining, only to be written: each row is made in a
            // buffer of the thread's and copied in whole.
            let mut rest = view.slice(..bytes as usize);
            let mut rows = Vec::with_capacity(height);
            for _ in 0..height {
                let (first, tail) = rest.split_at(width * std::mem::size_of::<CameraRay>());
                rows.push(RowBytes(first));
                rest = tail;
            }
            rows.into_par_iter().enumerate().for_each_init(
                || vec![CameraRay::default(); width],
                |made, (j, out)| {
                    row(j, made);
                    let RowBytes(mut out) = out;
                    out.copy_from_slice(bytemuck::cast_slice(made));
                },
            );
        }
        let filled = filling.elapsed();
        gpu.checked(|| buffer.unmap())?;
        let upload_ns = t.elapsed().saturating_sub(filled).as_nanos() as u64;
        Ok(GpuRays {
            buffer,
            len,
            gpu: gpu.clone(),
            pending: Mutex::new(None),
            upload_ns,
            bytes_up: bytes,
            made_on_gpu: false,
            last_use: Mutex::new(None),
        })
    }

    /// Waits until the GPU has done the work submitted along these rays (so that the caller
    /// bounds the ray sets in flight: the CPU may otherwise run a chunk's pieces ahead).
    pub fn wait(&self) -> Result<()> {
        let last = self.last_use.lock().unwrap_or_else(|p| p.into_inner()).take();
        if let Some(index) = last {
            let polled = self.gpu.device.poll(wgpu::PollType::Wait { submission_index: Some(index), timeout: None });
            self.gpu.work_errors()?;
            polled.map_err(|e| Error::Device(format!("waiting for the GPU: {e}")))?;
        }
        Ok(())
    }

    /// The pass that makes them, if it is not submitted yet: to submit before the work that
    /// reads them.
    fn take_pending(&self) -> Option<wgpu::CommandBuffer> {
        self.pending.lock().unwrap_or_else(|p| p.into_inner()).take()
    }

    /// Nanoseconds spent making their buffer and handing it to the GPU.
    pub fn upload_ns(&self) -> u64 {
        self.upload_ns
    }

    /// Bytes that crossed to the GPU for them: the rays themselves where they were uploaded, a
    /// record and the panels where the GPU made them.
    pub fn bytes_up(&self) -> u64 {
        self.bytes_up
    }

    /// The rays, read back from the GPU (for holding the GPU's rays to the CPU's).
    pub fn read(&self) -> Result<Vec<CameraRay>> {
        let gpu = &*self.gpu;
        let bytes = (self.len * std::mem::size_of::<CameraRay>()) as u64;
        let readback = gpu.checked(|| {
            let readback =
                gpu.scratch("rays read back", bytes, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&self.buffer, 0, &readback, 0, bytes);
            gpu.queue.submit(self.take_pending().into_iter().chain([encoder.finish()]));
            readback.slice(..).map_async(wgpu::MapMode::Read, |_| ());
            readback
        })?;
        let polled = gpu.device.poll(wgpu::PollType::wait_indefinitely());
        gpu.work_errors()?;
        polled.map_err(|e| Error::Device(format!("waiting for the GPU: {e}")))?;
        let view = readback
            .slice(..)
            .get_mapped_range()
            .map_err(|e| Error::Device(format!("reading the GPU's rays back: {e}")))?;
        Ok(bytemuck::cast_slice(&view[..bytes as usize]).to_vec())
    }
}

/// A row's bytes of a mapped buffer, written by one thread.
struct RowBytes<'a>(wgpu::WriteOnly<'a, [u8]>);

// SAFETY: a `WriteOnly<[u8]>` is an exclusive, write-only reference to bytes, as `&mut [u8]` is,
// which may be sent to another thread; wgpu-types implements `Send` for `WriteOnly<T>` with
// `T: Send` (implicitly sized), which leaves slices out, not for a reason of theirs. Each row is
// a disjoint part of the mapping (`split_at`), which outlives the parallel loop that writes it.
unsafe impl Send for RowBytes<'_> {}

/// An image's f32 sums on the GPU: per pixel the bits of (r, g, b) and its hit count
/// (`gather.wgsl`'s `image`, 16 bytes), zero when made (wgpu zeroes a new buffer). Every
/// gathering into it ([`GpuPlanes::gather_into`]) adds there, in order, and it crosses back once
/// ([`GpuSums::read_into`]): a chunk's pieces cost one image read back, not one each.
pub struct GpuSums {
    gpu: Arc<Gpu>,
    image: wgpu::Buffer,
    pixels: usize,
    /// The gatherings' timestamps, resolved on the GPU, to read with the sums.
    timestamps: Vec<wgpu::Buffer>,
    /// When the first gathering into these sums was submitted (the GPU's time where the adapter
    /// has no timestamps).
    first_submission: Option<Instant>,
    /// A gathering into them without timestamps: they are timed by the wall time.
    untimed: bool,
    /// The gatherings' command buffers (and their rays' passes) not submitted yet: submitted
    /// together when the sums are read ([`GpuSums::read_into`]), so that a chunk's pieces are one
    /// submission, not one each.
    pending: Vec<wgpu::CommandBuffer>,
    /// Bytes of the ray sets the pending work holds on the GPU ([`PENDING_RAY_BYTES`]).
    pending_rays: u64,
    /// Bytes that crossed to the GPU for these sums' gatherings, and the submissions, since
    /// the last read.
    bytes_up: u64,
    submissions: u64,
}

/// The most bytes of ray sets that work not yet submitted holds: past it, the work is submitted
/// at once (a large image's ray sets are then let go as their gatherings end).
const PENDING_RAY_BYTES: u64 = 256 << 20;

impl GpuSums {
    /// Zero sums for a `width x height` image on `gpu`.
    pub fn new(gpu: Arc<Gpu>, width: u32, height: u32) -> Result<Self> {
        let pixels = width as usize * height as usize;
        let bytes = pixels as u64 * 16;
        if bytes > gpu.max_binding {
            return Err(Error::Device(format!(
                "the sums of a {width}x{height} image take {bytes} bytes, more than the GPU binds at once ({} bytes): render a smaller image on it, or on the CPU",
                gpu.max_binding
            )));
        }
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let image = gpu.checked(|| gpu.scratch("image", bytes, usage))?;
        Ok(GpuSums {
            gpu,
            image,
            pixels,
            timestamps: Vec::new(),
            first_submission: None,
            untimed: false,
            pending: Vec::new(),
            pending_rays: 0,
            bytes_up: 0,
            submissions: 0,
        })
    }

    /// Submits the work not submitted yet, with `then` after it, in one submission.
    fn submit_with(&mut self, then: Option<wgpu::CommandBuffer>) -> Option<wgpu::SubmissionIndex> {
        let work: Vec<wgpu::CommandBuffer> = self.pending.drain(..).chain(then).collect();
        if work.is_empty() {
            return None;
        }
        self.first_submission.get_or_insert_with(Instant::now);
        self.submissions += 1;
        self.pending_rays = 0;
        Some(self.gpu.queue.submit(work))
    }

    /// Submits the work not submitted yet.
    fn submit(&mut self) -> Option<wgpu::SubmissionIndex> {
        self.submit_with(None)
    }

    /// Waits for the gatherings into these sums, adds the sums to `sums` (one per pixel) and
    /// returns the hits they counted and the GPU's time of the gatherings since the last read.
    pub fn read_into(&mut self, sums: &mut [Vec3]) -> Result<GatherStats> {
        assert_eq!(sums.len(), self.pixels, "one sum per pixel");
        let held = self.gpu.clone();
        let gpu = &*held;
        let bytes = self.pixels as u64 * 16;
        let timestamps = std::mem::take(&mut self.timestamps);
        let readback = gpu.checked(|| {
            let readback =
                gpu.scratch("image read back", bytes, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&self.image, 0, &readback, 0, bytes);
            let _ = self.submit_with(Some(encoder.finish()));
            for b in timestamps.iter().chain([&readback]) {
                b.slice(..).map_async(wgpu::MapMode::Read, |_| ());
            }
            readback
        })?;
        let polled = gpu.device.poll(wgpu::PollType::wait_indefinitely());
        let waited = self.first_submission.take().map_or(0, |t| t.elapsed().as_nanos() as u64);
        let untimed = std::mem::take(&mut self.untimed);
        gpu.work_errors()?;
        polled.map_err(|e| Error::Device(format!("waiting for the GPU: {e}")))?;
        let mapped = |b: &wgpu::Buffer| {
            b.slice(..).get_mapped_range().map_err(|e| Error::Device(format!("reading the GPU's results back: {e}")))
        };
        let timestamp_bytes: u64 = timestamps.iter().map(|b| b.size()).sum();
        let mut stats = GatherStats {
            device_ns: waited,
            bytes_crossed: std::mem::take(&mut self.bytes_up) + bytes + timestamp_bytes,
            submissions: std::mem::take(&mut self.submissions),
            ..GatherStats::default()
        };
        if !untimed && !timestamps.is_empty() {
            let period = gpu.queue.get_timestamp_period() as f64;
            stats.device_ns = 0;
            for b in &timestamps {
                let view = mapped(b)?;
                let ts: &[u64] = bytemuck::cast_slice(&view);
                // A driver's timestamps out of order count 0, not 2^64 ticks.
                stats.device_ns +=
                    ts.chunks(2).map(|p| (p[1].saturating_sub(p[0]) as f64 * period) as u64).sum::<u64>();
            }
        }
        let view = mapped(&readback)?;
        let back: &[[u32; 4]] = bytemuck::cast_slice(&view[..bytes as usize]);
        // Added pixel by pixel in parallel (the same bits: each pixel's one addition).
        use rayon::prelude::*;
        stats.hits = sums
            .par_iter_mut()
            .zip(back)
            .with_min_len(4096)
            .map(|(sum, v)| {
                *sum += Vec3::new(f32::from_bits(v[0]), f32::from_bits(v[1]), f32::from_bits(v[2]));
                v[3] as u64
            })
            .sum();
        Ok(stats)
    }
}

fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource: buffer.as_entire_binding() }
}

/// `n` workgroups as a grid within the 65,535 a dimension allows (the shaders number them
/// `y * x_count + x` and skip those past `n`).
fn grid(n: u64) -> (u32, u32) {
    let x = n.clamp(1, 65_535);
    (x as u32, n.div_ceil(x).max(1) as u32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::occlusion::Occluder;
    use std::mem::{offset_of, size_of};
    use wgpu::naga;

    /// The size and members (name, byte offset) of WGSL struct `name` in `source`, laid out by
    /// the WGSL front end that wgpu compiles the shaders with.
    fn wgsl_layout(source: &str, name: &str) -> (usize, Vec<(String, usize)>) {
        let module = naga::front::wgsl::parse_str(source).expect("the shader parses");
        for (_, ty) in module.types.iter() {
            if let (Some(n), naga::TypeInner::Struct { members, span }) = (&ty.name, &ty.inner)
                && n == name
            {
                let members = members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize));
                return (*span as usize, members.collect());
            }
        }
        panic!("no struct {name} in the shader")
    }

    /// Every record that crosses to the GPU is laid out as its WGSL twin: the same size, and
    /// each Rust field at the offset of the WGSL member of its name (padding named `pad...` on
    /// both sides). The two definitions are one by this test: a field added, moved or retyped
    /// on one side only fails here, not as wrong pixels.
    #[test]
    fn records_are_laid_out_as_the_shaders_read_them() {
        macro_rules! fields {
            ($t:ty: $($f:ident),*) => {
                (stringify!($t), size_of::<$t>(), vec![$((stringify!($f), offset_of!($t, $f))),*])
            };
        }
        let pairs = [
            (
                GATHER_WGSL,
                "Plane",
                fields!(PlaneRecord: normal, t_det, a_axis, width, r_axis, occluders_start, normal_perp,
                    occluders_end, scale, scale_max, cos_a, sin_a, p0, q0, light_w, light_h, perp_inv_abs_cos,
                    perp_inv_sin, perp_cos_positive, unit, inv_unit, light, toward, pad),
            ),
            (GATHER_WGSL, "Occluder", fields!(Occluder: t0, t_a, p0, p_a, q0, q_a, width, height)),
            (
                GATHER_WGSL,
                "Params",
                fields!(GatherParams: width, height, tiles_x, tiles, sigma_t, grey, orientations, inv_orientations,
                    phase_h, phase_floor, phase_inv_numerator, phase_hg, pad),
            ),
            (BIN_WGSL, "Params", fields!(BinParams: width, height, tiles_x, tiles, count, first, item_planes, pad)),
            (
                RAYS_WGSL,
                "RaySet",
                fields!(RaySetRecord: forward, tan_x, right, tan_y, up, width, lo, height, hi, outside, scramble,
                    sobol, pixel_center, panels, pad),
            ),
            (RAYS_WGSL, "Panel", fields!(PanelRecord: corner, to_plane, n, width, u, height, v, pad, footprint)),
        ];
        // A camera ray is `RAY_FLOATS` f32 where it is made and where it is read, its fields in
        // the shaders' order.
        for source in [GATHER_WGSL, RAYS_WGSL] {
            let module = naga::front::wgsl::parse_str(source).expect("the shader parses");
            let ray_floats = module
                .constants
                .iter()
                .find(|(_, c)| c.name.as_deref() == Some("RAY_FLOATS"))
                .map(|(_, c)| &module.global_expressions[c.init]);
            let Some(naga::Expression::Literal(naga::Literal::U32(ray_floats))) = ray_floats else {
                panic!("the shader's RAY_FLOATS is a u32 literal")
            };
            assert_eq!(size_of::<CameraRay>(), 4 * *ray_floats as usize, "a ray is RAY_FLOATS f32");
        }
        let at = [offset_of!(CameraRay, dir), offset_of!(CameraRay, t0), offset_of!(CameraRay, t1)];
        assert_eq!(at, [0, 12, 16], "a ray's floats: x, y, z, t0, t1");
        for (source, name, (rust, size, fields)) in pairs {
            let (span, members) = wgsl_layout(source, name);
            assert_eq!(span, size, "{rust} is {size} bytes, the shader's {name} {span}");
            for (field, offset) in fields {
                let member = members.iter().find(|(_, o)| *o == offset).map(|(m, _)| m.as_str());
                let same = member == Some(field) || (field == "pad" && member.is_some_and(|m| m.starts_with("pad")));
                assert!(same, "{rust}.{field} at byte {offset}: the shader's {name} has {member:?} there");
            }
        }
    }
}
