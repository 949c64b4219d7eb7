//! A gathering's passes, encoded into one command buffer that is kept with the sums
//! ([`Gathering::encode`]): the planes' reach until a submission has found it, the
//! orientations' table where it is asked for, per batch the binning's two tiers (`bin.wgsl`),
//! and per round of batches (gpu/batches.rs) the gather and its reduction (`gather.wgsl`),
//! timed by the GPU's timestamps where it has them.

use super::batches::{Batch, Round, block_words};
use super::clock::{Clock, Mark, Timestamps};
use super::device::{GatherPipelines, Gpu, entry, grid};
use super::plane_buffers::PlaneBuffers;
use super::rays::GpuRays;
use super::records::{BinParams, GatherParams};
use super::scratch::{Need, ScratchBuffers};
use super::sums::GpuSums;
use super::{BATCH_SEGMENTS, TILE};
use crate::control::Control;
use crate::error::{Error, Result};
use crate::gather::{GatherStats, Phase};
use crate::weights::Weighting;
use glam::Vec3;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// What a gathering's passes are encoded from: a structure's planes on the GPU, how they are
/// cut into batches and rounds, and the medium they are gathered in.
pub(super) struct Gathering<'a> {
    pub(super) gpu: &'a Gpu,
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) planes: &'a PlaneBuffers,
    /// The planes' count.
    pub(super) count: u32,
    pub(super) batches: &'a [Batch],
    pub(super) rounds: &'a [Round],
    pub(super) sigma_t: Vec3,
    pub(super) grey: bool,
    pub(super) phase: Phase,
    /// Set once a submission has found the planes' reach ([`GpuSums`] sets it as it submits).
    pub(super) reach_found: &'a Arc<AtomicBool>,
}

/// A piece's gathering recorded ([`super::GpuPlanes::record`]), to add to its sums' work in
/// order ([`GpuSums::add`]): nothing where the piece has no planes.
#[derive(Default)]
pub struct Recorded {
    pub(super) commands: Option<wgpu::CommandBuffer>,
    /// Its timestamps, where the adapter has them.
    pub(super) timestamps: Option<Timestamps>,
    /// The flag its reach pass sets once submitted, where it records one.
    pub(super) reach: Option<Arc<AtomicBool>>,
    /// Bytes of its parameters, uploaded.
    pub(super) bytes_up: u64,
    /// Its planes' upload (time and bytes).
    pub(super) stats: GatherStats,
}

/// A pass of a round: its name (the trace's), its pipeline, its bindings, and its grid of
/// workgroups (`None`: the gather's, as `bin.wgsl`'s `scan` counted the round's work items).
type Step<'a> = (&'static str, &'a wgpu::ComputePipeline, wgpu::BindGroup, Option<(u32, u32)>);

/// The names of `bin.wgsl`'s passes, in [`Gpu`]'s order: the blocks' tier, then the tiles'.
const BIN_PASSES: [&str; 6] =
    ["bin: block_count", "bin: block_scan", "bin: block_scatter", "bin: count", "bin: scan", "bin: scatter"];

impl Gathering<'_> {
    /// The gathering along the ray set that begins `rays_at` floats into `rays` (a join's
    /// parts' sets where each part's begins after that) with `weighting`, into `into`: its
    /// rounds one after another in one command buffer, `control` checked before each.
    pub(super) fn encode(
        &self,
        weighting: Weighting,
        pipelines: &GatherPipelines,
        (rays, rays_at): (&GpuRays, u32),
        into: &GpuSums,
        control: Control,
    ) -> Result<Recorded> {
        let _s = crate::trace::span("batches encoded");
        let gpu = self.gpu;
        let k = weighting.orientations.max(1);
        // beta_k - alpha for k = 1 .. K - 1 (`gather.wgsl`'s `rotations`).
        let rotations: Vec<[f32; 2]> = (1..k)
            .map(|i| i as f64 * std::f64::consts::PI / k as f64)
            .map(|b| [b.cos() as f32, b.sin() as f32])
            .collect();
        let rotations_buf = gpu.upload("rotations", bytemuck::cast_slice(&rotations), wgpu::BufferUsages::STORAGE);
        // With K orientations and the table asked for (`Tuning::orientation_table`), each plane's
        // K - 1 further ones, made once here (`orient`) rather than at each hit.
        let orients = if pipelines.orient.is_some() { self.count as u64 * (k as u64 - 1) } else { 0 };
        let block_words = self.block_words();
        let s = self.scratch(k, orients, block_words.unwrap_or(0))?;
        // A round's gather parameters (its batches' regions) and bindings each.
        let gather_params = self.gather_params(k);
        let groups: Vec<wgpu::BindGroup> = self
            .rounds
            .iter()
            .map(|r| {
                let round_params = GatherParams { regions: r.batches.len() as u32, ..gather_params };
                let params =
                    gpu.upload("gather params", bytemuck::bytes_of(&round_params), wgpu::BufferUsages::UNIFORM);
                gather_group(gpu, &params, self.planes, rays, &rotations_buf, &s, &into.image)
            })
            .collect();
        // The planes' reach, until a submission has found it (once for `into`'s work), timed
        // with the first round.
        let reach_first = !self.reach_found.load(Ordering::Acquire)
            && !into.on_submit.iter().any(|f| Arc::ptr_eq(f, self.reach_found));
        let orient = pipelines.orient.as_ref().filter(|_| orients > 0);
        let blocked = block_words.is_some();
        // Every pass, for the clock: the reach, the orientations, and each round's.
        let bin_passes = if blocked { 6 } else { 3 };
        let passes = reach_first as usize
            + orient.is_some() as usize
            + self.rounds.iter().map(|r| r.batches.len() * bin_passes + 2).sum::<usize>();
        let mut clock = Clock::new(gpu, self.rounds.len(), passes);
        // Every round in one command buffer (the passes run in order, the scratch buffers
        // reused from round to round).
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        // The first pass's start is the first round's (`timed_from_first` in `encode_round`).
        let first_pass = Mark { starts: Some(0), ..Mark::default() };
        if reach_first {
            let timestamp_writes = clock.as_mut().and_then(|c| c.pass("reach", first_pass));
            self.planes.polygons.encode(gpu, &mut encoder, timestamp_writes);
        }
        // The planes' orientations, timed with the first round too.
        if let Some(orient) = orient {
            let mark = if reach_first { Mark::default() } else { first_pass };
            let timestamp_writes = clock.as_mut().and_then(|c| c.pass("orient", mark));
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes });
            pass.set_pipeline(orient);
            pass.set_bind_group(0, &groups[0], &[]);
            let (x, y) = grid(orients.div_ceil(256));
            pass.dispatch_workgroups(x, y, 1);
        }
        let timed_before = reach_first || orients > 0;
        let mut bytes_up = std::mem::size_of_val(rotations.as_slice()) as u64;
        for (r, (round, gather_group)) in self.rounds.iter().zip(&groups).enumerate() {
            control.check()?;
            bytes_up += std::mem::size_of::<GatherParams>() as u64;
            let steps = self.round_steps(round, (pipelines, gather_group), &s, (rays_at, blocked), &mut bytes_up);
            let timed_from_first = !(r == 0 && timed_before);
            encode_round(&mut encoder, steps, clock.as_mut(), r as u32, timed_from_first, &s);
        }
        let timestamps = clock.map(|c| c.finish(&mut encoder));
        Ok(Recorded {
            commands: Some(encoder.finish()),
            timestamps,
            reach: reach_first.then(|| self.reach_found.clone()),
            bytes_up,
            stats: GatherStats::default(),
        })
    }

    /// Tiles across and down the image.
    fn tiles(&self) -> (u32, u32) {
        (self.width.div_ceil(TILE), self.height.div_ceil(TILE))
    }

    /// `gather.wgsl`'s parameters with K orientations, for a round of one batch.
    fn gather_params(&self, k: u32) -> GatherParams {
        let (tiles_x, tiles_y) = self.tiles();
        GatherParams {
            width: self.width,
            height: self.height,
            tiles_x,
            tiles: tiles_x * tiles_y,
            sigma_t: self.sigma_t.to_array(),
            grey: self.grey as u32,
            orientations: k,
            inv_orientations: 1.0 / k as f32,
            phase_h: self.phase.h,
            phase_floor: self.phase.floor,
            pad0: 0,
            phase_hg: !self.phase.is_isotropic() as u32,
            planes: self.count,
            regions: 0,
        }
    }

    /// The words of the blocks' offsets and lists (`bin.wgsl`'s `blocks`) for this gathering's
    /// batches, one batch's at a time; `None` where it is binned in one tier: by the setting
    /// ([`super::Tuning::flat_binning`]), or where they would pass one binding (a batch cut
    /// near the binding's bound by its pairs, with an offset per block and segment more). The
    /// tiles' lists are the same either way.
    fn block_words(&self) -> Option<u64> {
        let blocks = super::blocks(self.width, self.height);
        let words = block_words(self.batches, blocks, self.gpu.max_binding());
        words.filter(|_| !self.gpu.bins_flat())
    }

    /// The scratch buffers this gathering needs, with `orients` (plane, orientation) rows of the
    /// table of K orientations and `blocks` words of the blocks' lists: held only while they are found (grown if need be), so that the
    /// pieces of a gathering record side by side (each piece's passes run after the piece's
    /// before it on the queue, whichever buffers each one holds). A table larger than one
    /// binding is refused in one line.
    fn scratch(&self, k: u32, orients: u64, blocks: u64) -> Result<ScratchBuffers> {
        let gpu = self.gpu;
        // 16 bytes a row, within one binding (a piece is at most a chunk, 16,384 planes: 16.5
        // MB at K = 64).
        if orients * 16 > gpu.max_binding() {
            return Err(Error::Device(format!(
                "the table of {} planes' {} orientations takes {} bytes, more than the GPU binds at once ({} bytes): gather them with {}=per-hit",
                self.count,
                k,
                orients * 16,
                gpu.max_binding(),
                super::ORIENTATIONS_VARIABLE
            )));
        }
        let tiles = {
            let (x, y) = self.tiles();
            x as u64 * y as u64
        };
        let max_pairs = self.rounds.iter().map(|r| r.pairs).max().unwrap_or(0);
        let max_items = self.rounds.iter().map(|r| r.items).max().unwrap_or(0);
        let max_regions = self.rounds.iter().map(|r| r.batches.len() as u64).max().unwrap_or(0);
        let max_segments = self.batches.iter().map(|b| b.segments.len() as u64).max().unwrap_or(0);
        let need = Need {
            regions: (max_regions * (tiles + 1)).max(max_segments * tiles),
            pairs: max_pairs,
            items: max_items,
            orients,
            blocks,
        };
        Ok(gpu.scratch.lock().unwrap_or_else(|p| p.into_inner()).at_least(&gpu.device, need))
    }

    /// A round's passes: each of its batches binned into its region (the blocks' tier first
    /// where `blocked`), then the round's work items gathered at once (`pipelines` with the
    /// round's bindings) and added to the image by the reduction, along the ray set that begins
    /// `rays_at` floats in. The bytes of the batches' parameters are added to `bytes_up`.
    fn round_steps<'p>(
        &self,
        round: &Round,
        (pipelines, gather_group): (&'p GatherPipelines, &wgpu::BindGroup),
        s: &ScratchBuffers,
        (rays_at, blocked): (u32, bool),
        bytes_up: &mut u64,
    ) -> Vec<Step<'p>>
    where
        Self: 'p,
    {
        let gpu = self.gpu;
        let (tiles_x, tiles_y) = self.tiles();
        let (tile_grid, block_grid) =
            (grid(tiles_x as u64 * tiles_y as u64), grid(super::blocks(self.width, self.height)));
        let mut steps: Vec<Step> = Vec::new();
        for (region, batch) in self.batches[round.batches.clone()].iter().enumerate() {
            let mut segs = [[0u32; 4]; BATCH_SEGMENTS / 2];
            for (k, &(first, rays)) in batch.segments.iter().enumerate() {
                segs[k / 2][2 * (k % 2)..2 * (k % 2) + 2].copy_from_slice(&[first, rays_at + rays]);
            }
            let bin_params = BinParams {
                width: self.width,
                height: self.height,
                tiles_x,
                tiles: tiles_x * tiles_y,
                count: batch.count,
                first: batch.first,
                item_planes: round.item,
                region: region as u32,
                segments: batch.segments.len() as u32,
                blocked: blocked as u32,
                pad: [0; 2],
                segs,
            };
            let bin_params = gpu.upload("bin params", bytemuck::bytes_of(&bin_params), wgpu::BufferUsages::UNIFORM);
            *bytes_up += std::mem::size_of::<BinParams>() as u64;
            let bin_group = bin_group(gpu, &bin_params, self.planes, s);
            // The blocks' lists first (count, scan, scatter), then the tiles' from them.
            let tiers = [(0..3, block_grid), (3..6, tile_grid)];
            for (passes, size) in tiers.into_iter().skip(!blocked as usize) {
                for (k, size) in passes.zip([size, (1, 1), size]) {
                    steps.push((BIN_PASSES[k], &gpu.bin[k], bin_group.clone(), Some(size)));
                }
            }
        }
        // The gather's work items as many as the last `scan` counts (`bin.wgsl` writes the grid).
        steps.push(("gather", &pipelines.gather, gather_group.clone(), None));
        steps.push(("reduce", &pipelines.reduce, gather_group.clone(), Some((tiles_x, tiles_y))));
        steps
    }
}

/// Round `r`'s passes encoded: timed from its first (unless `timed_from_first` is false: round
/// 0's from the reach or the orientations before it) to its last, and its gather from its
/// start, so that the summary splits the GPU's time into the reach and the binning, and the
/// gather and its reduction; with the trace on, each pass by its own timestamps.
fn encode_round(
    encoder: &mut wgpu::CommandEncoder,
    steps: Vec<Step>,
    mut clock: Option<&mut Clock>,
    r: u32,
    timed_from_first: bool,
    s: &ScratchBuffers,
) {
    let last = steps.len() - 1;
    let gather_at = steps.len() - 2;
    for (k, (name, pipeline, group, size)) in steps.into_iter().enumerate() {
        let mark = Mark {
            starts: (k == 0 && timed_from_first).then_some(r),
            gather: (k == gather_at).then_some(r),
            ends: (k == last).then_some(r),
        };
        let timestamp_writes = clock.as_deref_mut().and_then(|c| c.pass(name, mark));
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &group, &[]);
        match size {
            Some((x, y)) => pass.dispatch_workgroups(x, y, 1),
            None => pass.dispatch_workgroups_indirect(&s.item_offsets, 0),
        }
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
