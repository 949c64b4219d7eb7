//! A structure's planes on the GPU ([`GpuPlanes`]): cut into batches on the CPU, uploaded by
//! their first gathering, and each gathering's passes (the planes' reach until it has been
//! submitted; per batch, the binning's three, the gather and its reduction) encoded into one
//! command buffer kept with the sums.

use super::device::{GatherPipelines, Gpu, entry, grid};
use super::polygons::{PolygonBuffers, Polygons};
use super::rays::GpuRays;
use super::records::{BinParams, GatherParams, ITEM_BYTES};
use super::scratch::{ScratchBuffers, indirect_offset};
use super::sums::GpuSums;
use super::{BATCH_PLANES, ScreenReach, TILE, TIMESTAMPS, estimator_id, item_planes};
use crate::camera::{CameraRay, RayRowFn};
use crate::control::Control;
use crate::error::{Error, Result};
use crate::gather::{GatherContext, GatherStats, Phase, PlaneRecord};
use crate::pixel::{PanelRecord, RaySetRecord};
use crate::weights::Weighting;
use glam::Vec3;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;

/// One batch of planes: binned and gathered together.
struct Batch {
    first: u32,
    count: u32,
    /// A bound on its (tile, plane) pairs, the tiles' lists' total length ([`ScreenReach`]).
    pairs: u64,
    /// The most planes of one of its work items ([`item_planes`]).
    item: u32,
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
    /// Boxed: a structure is held in an enum beside the CPU's, and these are many handles.
    buffers: OnceLock<Box<PlaneBuffers>>,
    /// Whether a submission has run the pass that finds the planes' reach (`reach.wgsl`); until
    /// one has, each gathering records it before its binning (set by [`GpuSums`] as it submits).
    reach_found: Arc<AtomicBool>,
    /// Its planes' count.
    planes: u32,
    batches: Vec<Batch>,
    sigma_t: Vec3,
    grey: bool,
    phase: Phase,
}

/// A structure's planes as they cross: [`PlaneRecord`]s, the occluders, and their screen
/// polygons.
struct PlaneData {
    planes: Vec<PlaneRecord>,
    occluders: Vec<crate::occlusion::Occluder>,
    polygons: Polygons,
}

/// [`PlaneData`] on the GPU.
struct PlaneBuffers {
    planes: wgpu::Buffer,
    occluders: wgpu::Buffer,
    polygons: PolygonBuffers,
}

impl GpuPlanes {
    /// The planes of `ctx` for `gpu`, with their screen polygons (`reach`, from
    /// [`super::screen_reach`]) in a `width x height` image.
    pub fn new(gpu: Arc<Gpu>, ctx: &GatherContext, reach: &[ScreenReach], width: u32, height: u32) -> Result<Self> {
        assert_eq!(ctx.views.len(), reach.len(), "a reach per plane");
        let polygons = Polygons::new(reach);
        // Every whole buffer within one binding: the image's rays (the largest per pixel), the
        // planes and their occluders; refused here in one line, not by the driver's validation.
        let pixels = width as u64 * height as u64;
        let whole = [
            ("the rays of a", pixels * std::mem::size_of::<CameraRay>() as u64),
            ("the planes of a chunk for a", (ctx.views.len() * std::mem::size_of::<PlaneRecord>()) as u64),
            ("the occluders of a chunk's planes for a", std::mem::size_of_val(ctx.occluders.as_slice()) as u64),
            ("the rows of tiles a chunk's planes reach in a", polygons.row_bytes()),
        ];
        if let Some((what, bytes)) = whole.into_iter().find(|&(_, bytes)| bytes > gpu.max_binding()) {
            return Err(Error::Device(format!(
                "{what} {width}x{height} image take {bytes} bytes, more than the GPU binds at once ({} bytes): render a smaller image on it, or on the CPU",
                gpu.max_binding()
            )));
        }
        let tiles = (width.div_ceil(TILE) * height.div_ceil(TILE)) as u64;
        let fixed = gpu.fixed_item_planes();
        let cpu = gpu.is_cpu_adapter();
        // A bound on the work items of a batch of `pairs` pairs (at most, each tile's one more).
        let items = |pairs: u64| pairs.min(tiles) + pairs / item_planes(cpu, pairs, fixed) as u64;
        // Batches of consecutive planes whose work items' partial sums fit one binding.
        let max_items = gpu.max_binding() / ITEM_BYTES;
        let mut batches: Vec<Batch> = Vec::new();
        for (i, r) in reach.iter().enumerate() {
            let pairs = r.pairs;
            let fits = |batch: &Batch| {
                let p = batch.pairs + pairs;
                (batch.count as usize) < BATCH_PLANES && items(p) <= max_items && p * 4 <= gpu.max_binding()
            };
            match batches.last_mut() {
                Some(batch) if fits(batch) => {
                    batch.count += 1;
                    batch.pairs += pairs;
                }
                _ => batches.push(Batch { first: i as u32, count: 1, pairs, item: 0, items: 0 }),
            }
        }
        for b in &mut batches {
            (b.item, b.items) = (item_planes(cpu, b.pairs, fixed), items(b.pairs));
            if b.items > max_items || b.pairs * 4 > gpu.max_binding() {
                return Err(Error::Device(format!(
                    "a plane covers more of this {width}x{height} image than the GPU's buffers hold ({} bytes a binding): render smaller images on it",
                    gpu.max_binding()
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
        let host = PlaneData { planes, occluders: ctx.occluders.clone(), polygons };
        Ok(GpuPlanes {
            gpu,
            width,
            height,
            host: Mutex::new(Some(host)),
            buffers: OnceLock::new(),
            reach_found: Arc::new(AtomicBool::new(false)),
            planes: reach.len() as u32,
            batches,
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
            polygons: PolygonBuffers::upload(gpu, &host.polygons, self.width, self.height),
        })?;
        let bytes = made.planes.size() + made.occluders.size() + made.polygons.bytes_up();
        Ok((self.buffers.get_or_init(|| Box::new(made)), t.elapsed().as_nanos() as u64, bytes))
    }

    /// Bytes of a ray set of this structure's image on the GPU.
    pub fn ray_set_bytes(&self) -> u64 {
        self.width as u64 * self.height as u64 * std::mem::size_of::<CameraRay>() as u64
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
    /// or sooner where the work held passes [`super::PENDING_RAY_BYTES`] of ray sets. Checks `control`
    /// before each batch (a cancel drops the work not submitted); reports one unit of progress.
    /// The result holds the planes' upload; the tests, the hits and the GPU's time are counted
    /// on the GPU, and when `into` is read back. [`GpuPlanes::record`] then [`GpuSums::add`].
    pub fn gather_into(
        &self,
        weighting: Weighting,
        rays: &GpuRays,
        into: &mut GpuSums,
        control: Control,
    ) -> Result<GatherStats> {
        let recorded = self.record(weighting, rays, into, control)?;
        Ok(into.add(recorded, rays))
    }

    /// [`GpuPlanes::gather_into`]'s work recorded (the planes uploaded by their first
    /// gathering, every batch in one command buffer), not yet added to `into`'s: the pieces of
    /// a gathering record side by side, and [`GpuSums::add`] adds each in order.
    pub fn record(&self, weighting: Weighting, rays: &GpuRays, into: &GpuSums, control: Control) -> Result<Recorded> {
        let (gpu, w, h) = (&*self.gpu, self.width, self.height);
        let pixels = w as usize * h as usize;
        assert!(rays.len == pixels && into.pixels == pixels, "one ray and one sum per pixel");
        control.check()?;
        let _s = crate::trace::span("piece recorded");
        if self.batches.is_empty() {
            control.progress();
            return Ok(Recorded::default());
        }
        // Compiled on first use, before the scratch buffers are held.
        let pipelines = gpu.checked(|| gpu.gather_pipelines(estimator_id(weighting)))?;
        let (planes, upload_ns, bytes_crossed) = {
            let _s = crate::trace::span("planes uploaded");
            self.buffers()?
        };
        let mut recorded = gpu.checked(|| self.encode(weighting, &pipelines, planes, rays, into, control))??;
        recorded.stats = GatherStats { upload_ns, bytes_crossed, ..GatherStats::default() };
        control.progress();
        Ok(recorded)
    }

    /// [`GpuPlanes::record`]'s work: its batches one after another in one command buffer.
    fn encode(
        &self,
        weighting: Weighting,
        pipelines: &GatherPipelines,
        planes: &PlaneBuffers,
        rays: &GpuRays,
        into: &GpuSums,
        control: Control,
    ) -> Result<Recorded> {
        let _s = crate::trace::span("batches encoded");
        let (gpu, w, h) = (&*self.gpu, self.width, self.height);
        let (tiles_x, tiles_y) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let tiles = tiles_x * tiles_y;
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
            planes: self.planes,
            pad: 0,
        };
        let storage = wgpu::BufferUsages::STORAGE;
        let uniform = wgpu::BufferUsages::UNIFORM;
        let params = gpu.upload("gather params", bytemuck::bytes_of(&gather_params), uniform);
        let rotations_buf = gpu.upload("rotations", bytemuck::cast_slice(&rotations), storage);
        let max_pairs = self.batches.iter().map(|b| b.pairs).max().unwrap_or(0);
        let max_items = self.batches.iter().map(|b| b.items).max().unwrap_or(0);
        // With K orientations and the table asked for (`Tuning::orientation_table`), each plane's
        // K - 1 further ones, made once here (`orient`) rather than at each hit: 16 bytes each,
        // within one binding (a piece is at most a chunk, 16,384 planes: 16.5 MB at K = 64).
        let orients = if pipelines.orient.is_some() { self.planes as u64 * (k as u64 - 1) } else { 0 };
        if orients * 16 > gpu.max_binding() {
            return Err(Error::Device(format!(
                "the table of {} planes' {} orientations takes {} bytes, more than the GPU binds at once ({} bytes): gather them with {}=per-hit",
                self.planes,
                k,
                orients * 16,
                gpu.max_binding(),
                super::ORIENTATIONS_VARIABLE
            )));
        }
        // The scratch buffers held only while they are found (grown if need be), so that the
        // pieces of a gathering record side by side: each piece's passes run after the piece's
        // before it on the queue, whichever buffers each one holds.
        let s = self.gpu.scratch.lock().unwrap_or_else(|p| p.into_inner()).at_least(
            &gpu.device,
            tiles as u64,
            max_pairs,
            max_items,
            orients,
        );
        let gather_group = gather_group(gpu, &params, planes, rays, &rotations_buf, &s, &into.image);
        let batches = self.batches.len();
        let queries = timestamp_queries(gpu, batches);
        let tile_grid = grid(tiles as u64);
        // Every batch in one command buffer (the passes run in order, the scratch buffers
        // reused from batch to batch).
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        // The planes' reach, until a submission has found it (once for `into`'s work), timed
        // with the first batch.
        let reach_first = !self.reach_found.load(Ordering::Acquire)
            && !into.on_submit.iter().any(|f| Arc::ptr_eq(f, &self.reach_found));
        // The first pass's start is the first batch's (`starts` below).
        let first_pass = |first: bool| {
            queries.as_ref().filter(|_| first).map(|(set, _, _)| wgpu::ComputePassTimestampWrites {
                query_set: set,
                beginning_of_pass_write_index: Some(0),
                end_of_pass_write_index: None,
            })
        };
        if reach_first {
            planes.polygons.encode(gpu, &mut encoder, first_pass(true));
        }
        // The planes' orientations, timed with the first batch too.
        if let Some(orient) = pipelines.orient.as_ref().filter(|_| orients > 0) {
            let timestamp_writes = first_pass(!reach_first);
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes });
            pass.set_pipeline(orient);
            pass.set_bind_group(0, &gather_group, &[]);
            let (x, y) = grid(orients.div_ceil(256));
            pass.dispatch_workgroups(x, y, 1);
        }
        let timed_before = reach_first || orients > 0;
        for (b, batch) in self.batches.iter().enumerate() {
            control.check()?;
            let bin_params = BinParams {
                width: w,
                height: h,
                tiles_x,
                tiles,
                count: batch.count,
                first: batch.first,
                item_planes: batch.item,
                pad: 0,
            };
            let bin_params = gpu.upload("bin params", bytemuck::bytes_of(&bin_params), uniform);
            let bin_group = bin_group(gpu, &bin_params, planes, &s);
            // The gather's work items as many as `scan` counts (`bin.wgsl` writes the grid).
            let steps: [Step; 5] = [
                (&gpu.bin[0], &bin_group, Some(tile_grid)),
                (&gpu.bin[1], &bin_group, Some((1, 1))),
                (&gpu.bin[2], &bin_group, Some(tile_grid)),
                (&pipelines.gather, &gather_group, None),
                (&pipelines.reduce, &gather_group, Some((tiles_x, tiles_y))),
            ];
            for (k, (pipeline, group, size)) in steps.into_iter().enumerate() {
                // Batch b's passes timed from its first (batch 0's from the reach before it, if
                // any) to its last, and its gather from its start: where the GPU's time goes,
                // the reach and the binning or the gather and its reduction.
                let starts = k == 0 && !(b == 0 && timed_before);
                let begins = (starts || k == 3).then_some(TIMESTAMPS * b as u32 + if k == 3 { 1 } else { 0 });
                let ends = (k == 4).then_some(TIMESTAMPS * b as u32 + 2);
                let timestamp_writes =
                    queries.as_ref().filter(|_| begins.is_some() || ends.is_some()).map(|(set, _, _)| {
                        wgpu::ComputePassTimestampWrites {
                            query_set: set,
                            beginning_of_pass_write_index: begins,
                            end_of_pass_write_index: ends,
                        }
                    });
                let mut pass =
                    encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes });
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, group, &[]);
                match size {
                    Some((x, y)) => pass.dispatch_workgroups(x, y, 1),
                    None => pass.dispatch_workgroups_indirect(&s.item_offsets, indirect_offset(tiles)),
                }
            }
            if let Some((set, resolve, readback)) = queries.as_ref().filter(|_| b + 1 == batches) {
                let queries = TIMESTAMPS * batches as u32;
                encoder.resolve_query_set(set, 0..queries, resolve, 0);
                encoder.copy_buffer_to_buffer(resolve, 0, readback, 0, 8 * queries as u64);
            }
        }
        Ok(Recorded {
            commands: Some(encoder.finish()),
            timestamps: queries.map(|(_, _, readback)| readback),
            reach: reach_first.then(|| self.reach_found.clone()),
            bytes_up: (std::mem::size_of_val(&gather_params) + std::mem::size_of_val(rotations.as_slice())) as u64
                + (self.batches.len() * std::mem::size_of::<BinParams>()) as u64,
            stats: GatherStats::default(),
        })
    }
}

/// A piece's gathering recorded ([`GpuPlanes::record`]), to add to its sums' work in order
/// ([`GpuSums::add`]): nothing where the piece has no planes.
#[derive(Default)]
pub struct Recorded {
    pub(super) commands: Option<wgpu::CommandBuffer>,
    /// Its timestamps' read-back, where the adapter has them.
    pub(super) timestamps: Option<wgpu::Buffer>,
    /// The flag its reach pass sets once submitted, where it records one.
    pub(super) reach: Option<Arc<AtomicBool>>,
    /// Bytes of its parameters, uploaded.
    pub(super) bytes_up: u64,
    /// Its planes' upload (time and bytes).
    pub(super) stats: GatherStats,
}

/// A pass of a batch: its pipeline, its bindings, and its grid of workgroups (`None`: the
/// gather's, as `bin.wgsl`'s `scan` counted its work items).
type Step<'a> = (&'a wgpu::ComputePipeline, &'a wgpu::BindGroup, Option<(u32, u32)>);

/// The gather's bindings (`gather.wgsl`), the same for every batch of a gathering.
fn gather_group(
    gpu: &Gpu,
    params: &wgpu::Buffer,
    planes: &PlaneBuffers,
    rays: &GpuRays,
    rotations: &wgpu::Buffer,
    s: &ScratchBuffers,
    image: &wgpu::Buffer,
) -> wgpu::BindGroup {
    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("gather"),
        layout: &gpu.gather_layout,
        entries: &[
            entry(0, params),
            entry(1, &planes.planes),
            entry(2, &planes.occluders),
            entry(3, &rays.buffer),
            entry(4, rotations),
            entry(5, &s.list),
            entry(6, &s.item_offsets),
            entry(7, &s.items),
            entry(8, &s.partial),
            entry(9, image),
            entry(10, &s.ranges),
            entry(11, &s.orients),
        ],
    })
}

/// The binning's bindings (`bin.wgsl`) for one batch's parameters.
fn bin_group(gpu: &Gpu, params: &wgpu::Buffer, planes: &PlaneBuffers, s: &ScratchBuffers) -> wgpu::BindGroup {
    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("bin"),
        layout: &gpu.bin_layout,
        entries: &[
            entry(0, params),
            entry(1, &planes.polygons.reach),
            entry(2, &s.tile_counts),
            entry(3, &s.offsets),
            entry(4, &s.item_offsets),
            entry(5, &s.list),
            entry(6, &s.items),
            entry(7, &planes.polygons.spans),
            entry(8, &s.ranges),
            entry(9, &planes.polygons.groups),
        ],
    })
}

/// [`TIMESTAMPS`] a batch, where the adapter has them, read when the sums are; else (or for a
/// gathering of more batches than a query set of wgpu's 4,096 queries takes) the sums are timed
/// by the wall time from their first submission to their reading back.
fn timestamp_queries(gpu: &Gpu, batches: usize) -> Option<(wgpu::QuerySet, wgpu::Buffer, wgpu::Buffer)> {
    let count = TIMESTAMPS as usize * batches;
    (gpu.has_timestamps() && count <= 4096).then(|| {
        let set = gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("gather time"),
            ty: wgpu::QueryType::Timestamp,
            count: count as u32,
        });
        let bytes = 8 * count as u64;
        let copy_src = wgpu::BufferUsages::COPY_SRC;
        let resolve = gpu.scratch("timestamps", bytes, wgpu::BufferUsages::QUERY_RESOLVE | copy_src);
        let readback =
            gpu.scratch("timestamps read back", bytes, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
        (set, resolve, readback)
    })
}
