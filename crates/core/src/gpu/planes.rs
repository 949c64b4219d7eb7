//! A structure's planes on the GPU ([`GpuPlanes`]): cut into batches on the CPU, uploaded by
//! their first gathering, and each gathering's passes (the planes' reach until it has been
//! submitted; per batch, the binning's three, per round of batches the gather and its
//! reduction: gpu/batches.rs) encoded into one
//! command buffer kept with the sums.

use super::batches::{Batch, Bounds, Round, batches, merged, rounds};
use super::device::{GatherPipelines, Gpu, Patch, entry, grid};
use super::polygons::{PolygonBuffers, Polygons};
use super::rays::GpuRays;
use super::records::{BinParams, GatherParams};
use super::scratch::{Need, ScratchBuffers};
use super::sums::GpuSums;
use super::{BATCH_SEGMENTS, ScreenReach, TILE, TIMESTAMPS, estimator_id};
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

/// A structure's planes for the GPU, for gathering camera rays of one image size: made on the
/// CPU, uploaded by their first gathering ([`GpuPlanes::buffers`]).
pub struct GpuPlanes {
    gpu: Arc<Gpu>,
    width: u32,
    height: u32,
    /// What crosses, until it has (a join's parts keep theirs: it crosses as it is joined).
    host: Mutex<Option<PlaneData>>,
    /// Boxed: a structure is held in an enum beside the CPU's, and these are many handles.
    buffers: OnceLock<Box<PlaneBuffers>>,
    /// A join's upload (nanoseconds, bytes), made as it was joined, until a gathering tells it.
    joined_upload: Mutex<Option<(u64, u64)>>,
    /// Whether a submission has run the pass that finds the planes' reach (`reach.wgsl`); until
    /// one has, each gathering records it before its binning (set by [`GpuSums`] as it submits).
    reach_found: Arc<AtomicBool>,
    /// Its planes' count.
    planes: u32,
    /// The render's pieces it holds: 1, or a join's parts (a unit of progress each).
    pieces: u32,
    batches: Vec<Batch>,
    rounds: Vec<Round>,
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

impl PlaneBuffers {
    /// `parts` uploaded one after another for a `width x height` image, each part's indices
    /// made the whole's as they cross (its planes' occluders; its polygons' rows and vertices,
    /// [`PolygonBuffers::upload`]), the parts themselves untouched.
    fn upload(gpu: &Gpu, parts: &[&PlaneData], width: u32, height: u32) -> Result<Self> {
        let usage = wgpu::BufferUsages::STORAGE;
        // Where each part's occluders begin in the whole's.
        let bases: Vec<u32> = parts
            .iter()
            .scan(0u32, |at, d| {
                let base = *at;
                *at += d.occluders.len() as u32;
                Some(base)
            })
            .collect();
        let shift = |i: usize, r: &mut PlaneRecord| {
            (r.occluders_start, r.occluders_end) = (r.occluders_start + bases[i], r.occluders_end + bases[i]);
        };
        let shifted = bases.iter().any(|&b| b > 0);
        let planes = parts.iter().map(|d| d.planes.as_slice());
        Ok(PlaneBuffers {
            planes: gpu.upload_parts("planes", planes, shifted.then_some(&shift as Patch<PlaneRecord>), usage)?,
            occluders: gpu.upload_parts("occluders", parts.iter().map(|d| d.occluders.as_slice()), None, usage)?,
            polygons: PolygonBuffers::upload(gpu, parts.iter().map(|d| &d.polygons), width, height)?,
        })
    }

    /// The bytes that crossed for them.
    fn bytes_up(&self) -> u64 {
        self.planes.size() + self.occluders.size() + self.polygons.bytes_up()
    }
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
        let bounds = bounds(&gpu, width, height);
        let batches = batches(reach.iter().map(|r| r.pairs), &bounds);
        let rounds = rounds(&batches, &bounds)
            .map_err(|why| Error::Device(format!("{why} at {width}x{height}: render smaller images on it")))?;
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
            joined_upload: Mutex::new(None),
            reach_found: Arc::new(AtomicBool::new(false)),
            planes: reach.len() as u32,
            pieces: 1,
            batches,
            rounds,
            sigma_t: ctx.extinction.sigma_t,
            grey: ctx.extinction.grey,
            phase: ctx.phase,
        })
    }

    /// Several structures' planes as one, uploaded here: `parts`' planes in order, each
    /// gathered along its ray set, which begins at the floats given in the rays the whole is
    /// gathered along ([`super::GpuRays::sets_on_gpu`]). Their batches are kept (each a part's,
    /// carrying its set) and cut into rounds afresh, so that the parts' work items are gathered
    /// in one dispatch a round; a batch's sums are added to each pixel as they would be alone.
    /// The parts keep their planes (a prepared render gathers its pieces once a weighting, each
    /// time joined afresh). `Ok(None)` where the whole does not fit the GPU's bindings, or a
    /// part was uploaded alone: the parts are then gathered one by one.
    pub fn join(parts: &[(&GpuPlanes, u32)]) -> Result<Option<GpuPlanes>> {
        let Some((first, _)) = parts.first() else {
            return Ok(None);
        };
        let _s = crate::trace::span("pieces joined");
        let gpu = &first.gpu;
        let (width, height) = (first.width, first.height);
        let hosts: Vec<_> = parts.iter().map(|(p, _)| p.host.lock().unwrap_or_else(|e| e.into_inner())).collect();
        let Some(data) = hosts.iter().map(|h| h.as_ref()).collect::<Option<Vec<&PlaneData>>>() else {
            return Ok(None);
        };
        let planes: usize = data.iter().map(|d| d.planes.len()).sum();
        let occluders: usize = data.iter().map(|d| d.occluders.len()).sum();
        let rows: u64 = data.iter().map(|d| d.polygons.rows).sum();
        let fits = [
            planes * std::mem::size_of::<PlaneRecord>(),
            occluders * std::mem::size_of::<crate::occlusion::Occluder>(),
            rows as usize * std::mem::size_of::<[u32; super::GROUPS]>(),
        ]
        .iter()
        .all(|&b| b as u64 <= gpu.max_binding());
        let mut batches = Vec::new();
        let mut at = 0u32;
        for (p, rays_at) in parts {
            assert!(Arc::ptr_eq(&p.gpu, gpu) && (p.width, p.height) == (width, height), "parts of one image");
            batches.extend(p.batches.iter().map(|b| Batch {
                first: b.first + at,
                segments: b.segments.iter().map(|&(first, rays)| (first, rays + *rays_at)).collect(),
                ..b.clone()
            }));
            at += p.planes;
        }
        // The parts' batches binned together where they fit one (a chunk's pieces: one batch).
        let bounds = bounds(gpu, width, height);
        let batches = merged(batches, &bounds);
        let Some(rounds) = rounds(&batches, &bounds).ok().filter(|_| fits && planes <= u32::MAX as usize) else {
            return Ok(None);
        };
        let t = Instant::now();
        let made = gpu.checked(|| PlaneBuffers::upload(gpu, &data, width, height))??;
        let upload = (t.elapsed().as_nanos() as u64, made.bytes_up());
        Ok(Some(GpuPlanes {
            gpu: gpu.clone(),
            width,
            height,
            host: Mutex::new(None),
            buffers: OnceLock::from(Box::new(made)),
            joined_upload: Mutex::new(Some(upload)),
            reach_found: Arc::new(AtomicBool::new(false)),
            planes: planes as u32,
            pieces: parts.iter().map(|(p, _)| p.pieces).sum(),
            batches,
            rounds,
            sigma_t: first.sigma_t,
            grey: first.grey,
            phase: first.phase,
        }))
    }

    /// The planes on the GPU, uploaded by the first call, with the nanoseconds this call spent
    /// uploading and the bytes it uploaded (a join's, made as it was joined, told by its first
    /// call).
    fn buffers(&self) -> Result<(&PlaneBuffers, u64, u64)> {
        if let Some(b) = self.buffers.get() {
            let (ns, bytes) = self.joined_upload.lock().unwrap_or_else(|p| p.into_inner()).take().unwrap_or((0, 0));
            return Ok((b, ns, bytes));
        }
        let t = Instant::now();
        let host =
            self.host.lock().unwrap_or_else(|p| p.into_inner()).take().expect("uploaded once, on the gather side");
        let made = self.gpu.checked(|| PlaneBuffers::upload(&self.gpu, &[&host], self.width, self.height))??;
        let bytes = made.bytes_up();
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

    /// Ray sets `sets` (each with its panels) made on the GPU into one buffer
    /// ([`GpuRays::sets_on_gpu`]), for this structure's image.
    pub fn rays_on_gpu(&self, sets: &[(&RaySetRecord, &[PanelRecord])]) -> Result<GpuRays> {
        assert!(sets.iter().all(|(s, _)| (s.width, s.height) == (self.width, self.height)), "a ray per pixel");
        GpuRays::sets_on_gpu(&self.gpu, sets)
    }

    /// Whether its GPU joins a render's pieces ([`Gpu::joins_pieces`]).
    pub fn joins_pieces(&self) -> bool {
        self.gpu.joins_pieces()
    }

    /// How many ray sets of this structure's image one buffer holds ([`GpuRays::sets_fitting`]).
    pub fn ray_sets_fitting(&self) -> usize {
        GpuRays::sets_fitting(&self.gpu, self.width as usize * self.height as usize)
    }

    /// Gathers `rays` (one per pixel, row-major) with `weighting`, adding each pixel's sum to
    /// `sums`: [`GpuPlanes::gather_into`] fresh sums on the GPU, read back once. Checks
    /// `control` before each round; reports a unit of progress a piece it holds.
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
    /// the planes in batches, each binned, and rounds of them gathered in turn, the work kept with `into` and
    /// submitted when it is read ([`GpuSums::read_into`]: a chunk's pieces in one submission),
    /// or sooner where the work held passes [`super::PENDING_RAY_BYTES`] of ray sets. Checks `control`
    /// before each round (a cancel drops the work not submitted); reports a unit of progress a
    /// piece it holds.
    /// The result holds the planes' upload; the tests, the hits and the GPU's time are counted
    /// on the GPU, and when `into` is read back. [`GpuPlanes::record`] then [`GpuSums::add`].
    pub fn gather_into(
        &self,
        weighting: Weighting,
        rays: &GpuRays,
        into: &mut GpuSums,
        control: Control,
    ) -> Result<GatherStats> {
        let recorded = self.record(weighting, rays, 0, into, control)?;
        Ok(into.add(recorded, rays))
    }

    /// [`GpuPlanes::gather_into`]'s work recorded (the planes uploaded by their first
    /// gathering, every round in one command buffer), not yet added to `into`'s: the pieces of
    /// a gathering record side by side, and [`GpuSums::add`] adds each in order. The planes'
    /// ray set begins `rays_at` floats into `rays` (one set of several,
    /// [`GpuRays::floats_at`]); a join's parts' sets where each part's begins after that.
    pub fn record(
        &self,
        weighting: Weighting,
        rays: &GpuRays,
        rays_at: u32,
        into: &GpuSums,
        control: Control,
    ) -> Result<Recorded> {
        let (gpu, w, h) = (&*self.gpu, self.width, self.height);
        let pixels = w as usize * h as usize;
        assert!(rays.len == pixels && into.pixels == pixels, "one ray and one sum per pixel");
        control.check()?;
        let _s = crate::trace::span("piece recorded");
        let progress = || (0..self.pieces).for_each(|_| control.progress());
        if self.rounds.is_empty() {
            progress();
            return Ok(Recorded::default());
        }
        // Compiled on first use, before the scratch buffers are held.
        let pipelines = gpu.checked(|| gpu.gather_pipelines(estimator_id(weighting)))?;
        let (planes, upload_ns, bytes_crossed) = {
            let _s = crate::trace::span("planes uploaded");
            self.buffers()?
        };
        let mut recorded =
            gpu.checked(|| self.encode(weighting, &pipelines, planes, (rays, rays_at), into, control))??;
        let dispatches = self.rounds.len() as u64;
        recorded.stats = GatherStats { upload_ns, bytes_crossed, dispatches, ..GatherStats::default() };
        progress();
        Ok(recorded)
    }

    /// [`GpuPlanes::record`]'s work: its rounds one after another in one command buffer.
    fn encode(
        &self,
        weighting: Weighting,
        pipelines: &GatherPipelines,
        planes: &PlaneBuffers,
        (rays, rays_at): (&GpuRays, u32),
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
            regions: 0,
        };
        let storage = wgpu::BufferUsages::STORAGE;
        let uniform = wgpu::BufferUsages::UNIFORM;
        let rotations_buf = gpu.upload("rotations", bytemuck::cast_slice(&rotations), storage);
        let max_pairs = self.rounds.iter().map(|r| r.pairs).max().unwrap_or(0);
        let max_items = self.rounds.iter().map(|r| r.items).max().unwrap_or(0);
        let max_regions = self.rounds.iter().map(|r| r.batches.len() as u64).max().unwrap_or(0);
        let max_segments = self.batches.iter().map(|b| b.segments.len() as u64).max().unwrap_or(0);
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
        // A batch's blocks' lists hold at most its (tile, plane) pairs (a plane that reaches a
        // block reaches one of its tiles), after an offset per block and segment.
        let blocked = !gpu.bins_flat();
        let block_words = if blocked { super::blocks(w, h) * max_segments + 1 + max_pairs } else { 0 };
        let s = self.gpu.scratch.lock().unwrap_or_else(|p| p.into_inner()).at_least(
            &gpu.device,
            Need {
                regions: (max_regions * (tiles as u64 + 1)).max(max_segments * tiles as u64),
                pairs: max_pairs,
                items: max_items,
                orients,
                blocks: block_words,
            },
        );
        // A round's gather parameters (its batches' regions) and bindings each.
        let groups: Vec<(wgpu::BindGroup, u64)> = self
            .rounds
            .iter()
            .map(|r| {
                let round_params = GatherParams { regions: r.batches.len() as u32, ..gather_params };
                let params = gpu.upload("gather params", bytemuck::bytes_of(&round_params), uniform);
                let group = gather_group(gpu, &params, planes, rays, &rotations_buf, &s, &into.image);
                (group, std::mem::size_of::<GatherParams>() as u64)
            })
            .collect();
        let rounds = self.rounds.len();
        let queries = timestamp_queries(gpu, rounds);
        let tile_grid = grid(tiles as u64);
        let block_grid = grid(super::blocks(w, h));
        // Every round in one command buffer (the passes run in order, the scratch buffers
        // reused from round to round).
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        // The planes' reach, until a submission has found it (once for `into`'s work), timed
        // with the first round.
        let reach_first = !self.reach_found.load(Ordering::Acquire)
            && !into.on_submit.iter().any(|f| Arc::ptr_eq(f, &self.reach_found));
        // The first pass's start is the first round's (`starts` below).
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
        // The planes' orientations, timed with the first round too.
        if let Some(orient) = pipelines.orient.as_ref().filter(|_| orients > 0) {
            let timestamp_writes = first_pass(!reach_first);
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes });
            pass.set_pipeline(orient);
            pass.set_bind_group(0, &groups[0].0, &[]);
            let (x, y) = grid(orients.div_ceil(256));
            pass.dispatch_workgroups(x, y, 1);
        }
        let timed_before = reach_first || orients > 0;
        let mut bytes_up = std::mem::size_of_val(rotations.as_slice()) as u64;
        for (r, (round, (gather_group, params_bytes))) in self.rounds.iter().zip(&groups).enumerate() {
            control.check()?;
            bytes_up += params_bytes;
            // Each batch binned into its region, then the round's items gathered at once.
            let mut steps: Vec<Step> = Vec::new();
            for (region, batch) in self.batches[round.batches.clone()].iter().enumerate() {
                let mut segs = [[0u32; 4]; BATCH_SEGMENTS / 2];
                for (k, &(first, rays)) in batch.segments.iter().enumerate() {
                    segs[k / 2][2 * (k % 2)..2 * (k % 2) + 2].copy_from_slice(&[first, rays_at + rays]);
                }
                let bin_params = BinParams {
                    width: w,
                    height: h,
                    tiles_x,
                    tiles,
                    count: batch.count,
                    first: batch.first,
                    item_planes: round.item,
                    region: region as u32,
                    segments: batch.segments.len() as u32,
                    blocked: blocked as u32,
                    pad: [0; 2],
                    segs,
                };
                let bin_params = gpu.upload("bin params", bytemuck::bytes_of(&bin_params), uniform);
                bytes_up += std::mem::size_of::<BinParams>() as u64;
                let bin_group = bin_group(gpu, &bin_params, planes, &s);
                // The blocks' lists first (count, scan, scatter), then the tiles' from them.
                let tiers = [(&gpu.bin[..3], block_grid), (&gpu.bin[3..], tile_grid)];
                for (passes, size) in tiers.into_iter().skip(!blocked as usize) {
                    for (pass, size) in passes.iter().zip([size, (1, 1), size]) {
                        steps.push((pass, bin_group.clone(), Some(size)));
                    }
                }
            }
            // The gather's work items as many as the last `scan` counts (`bin.wgsl` writes the grid).
            let gather_at = steps.len();
            steps.push((&pipelines.gather, gather_group.clone(), None));
            steps.push((&pipelines.reduce, gather_group.clone(), Some((tiles_x, tiles_y))));
            let last = steps.len() - 1;
            for (k, (pipeline, group, size)) in steps.into_iter().enumerate() {
                // Round r's passes timed from its first (round 0's from the reach before it, if
                // any) to its last, and its gather from its start: where the GPU's time goes,
                // the reach and the binning or the gather and its reduction.
                let starts = k == 0 && !(r == 0 && timed_before);
                let at = TIMESTAMPS * r as u32;
                let begins = if k == gather_at { Some(at + 1) } else { starts.then_some(at) };
                let ends = (k == last).then_some(at + 2);
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
                pass.set_bind_group(0, &group, &[]);
                match size {
                    Some((x, y)) => pass.dispatch_workgroups(x, y, 1),
                    None => pass.dispatch_workgroups_indirect(&s.item_offsets, 0),
                }
            }
            if let Some((set, resolve, readback)) = queries.as_ref().filter(|_| r + 1 == rounds) {
                let queries = TIMESTAMPS * rounds as u32;
                encoder.resolve_query_set(set, 0..queries, resolve, 0);
                encoder.copy_buffer_to_buffer(resolve, 0, readback, 0, 8 * queries as u64);
            }
        }
        Ok(Recorded {
            commands: Some(encoder.finish()),
            timestamps: queries.map(|(_, _, readback)| readback),
            reach: reach_first.then(|| self.reach_found.clone()),
            bytes_up,
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

/// A pass of a round: its pipeline, its bindings, and its grid of workgroups (`None`: the
/// gather's, as `bin.wgsl`'s `scan` counted the round's work items).
type Step<'a> = (&'a wgpu::ComputePipeline, wgpu::BindGroup, Option<(u32, u32)>);

/// The bounds of a gathering's batches and rounds on `gpu` for a `width x height` image.
fn bounds(gpu: &Gpu, width: u32, height: u32) -> Bounds {
    Bounds {
        tiles: (width.div_ceil(TILE) * height.div_ceil(TILE)) as u64,
        cpu: gpu.is_cpu_adapter(),
        fixed: gpu.fixed_item_planes(),
        max_binding: gpu.max_binding(),
    }
}

/// The gather's bindings (`gather.wgsl`) for one round's parameters.
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
            entry(10, &s.blocks),
        ],
    })
}

/// [`TIMESTAMPS`] a round, where the adapter has them, read when the sums are; else (or for a
/// gathering of more rounds than a query set of wgpu's 4,096 queries takes) the sums are timed
/// by the wall time from their first submission to their reading back.
fn timestamp_queries(gpu: &Gpu, rounds: usize) -> Option<(wgpu::QuerySet, wgpu::Buffer, wgpu::Buffer)> {
    let count = TIMESTAMPS as usize * rounds;
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
