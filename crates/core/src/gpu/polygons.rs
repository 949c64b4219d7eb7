//! The planes' screen polygons on the GPU: as they cross ([`Polygons`], from each plane's
//! [`ScreenReach`]), the rows of tiles the GPU fills from them, and the pass that does
//! (`reach.wgsl`), recorded before a chunk's first binning. [`reach_on_gpu`] reads what it finds
//! back, for holding it to the specification ([`super::tile_reach`]) in tests/gpu.rs.

use super::device::{Gpu, Patch, entry, grid};
use super::records::ReachParams;
use super::{GROUPS, ScreenReach, TileReach};
use crate::error::{Error, Result};
use std::sync::Arc;

/// The polygons of a chunk's planes as they cross: per plane, and one more after the last, its
/// first row of tiles, its rows, its first row's index among all the planes' rows and its first
/// vertex (`reach.wgsl`'s and `bin.wgsl`'s `reach`); the vertices in pixels.
pub(super) struct Polygons {
    pub(super) reach: Vec<[u32; 4]>,
    pub(super) vertices: Vec<[f32; 2]>,
    /// The planes' rows of tiles in all: the GPU fills a span and a group's columns for each.
    pub(super) rows: u64,
}

impl Polygons {
    pub(super) fn new(planes: &[ScreenReach]) -> Self {
        let mut reach = Vec::with_capacity(planes.len() + 1);
        let mut vertices = Vec::with_capacity(planes.len() * 5);
        let mut rows = 0u64;
        for p in planes {
            // A plane without rows crosses no vertex (and none is read for it).
            let shown = if p.rows > 0 { p.polygon.points() } else { &[] };
            reach.push([p.first_row, p.rows, rows as u32, vertices.len() as u32]);
            vertices.extend(shown.iter().map(|v| v.to_array()));
            rows += p.rows as u64;
        }
        reach.push([0, 0, rows as u32, vertices.len() as u32]);
        Polygons { reach, vertices, rows }
    }

    /// The bytes of the rows the GPU fills (`groups`, the larger of the two), which must fit one
    /// binding.
    pub(super) fn row_bytes(&self) -> u64 {
        self.rows * std::mem::size_of::<[u32; GROUPS]>() as u64
    }
}

/// [`Polygons`] on the GPU, with the rows filled from them: per row of tiles its span of tiles
/// (`spans`) and its groups' pixel columns (`groups`), as [`TileReach`] packs them.
pub(super) struct PolygonBuffers {
    pub(super) reach: wgpu::Buffer,
    vertices: wgpu::Buffer,
    pub(super) spans: wgpu::Buffer,
    pub(super) groups: wgpu::Buffer,
    params: wgpu::Buffer,
    rows: u64,
}

impl PolygonBuffers {
    /// `parts` uploaded one after another for a `width x height` image (a join's,
    /// [`super::GpuPlanes::join`]), each part's rows and vertices made the whole's as its reach
    /// crosses, and the buffers of their rows made (filled by [`PolygonBuffers::encode`]'s
    /// pass).
    pub(super) fn upload<'a>(
        gpu: &Gpu,
        parts: impl Iterator<Item = &'a Polygons> + Clone,
        width: u32,
        height: u32,
    ) -> Result<Self> {
        let storage = wgpu::BufferUsages::STORAGE;
        let filled = storage | wgpu::BufferUsages::COPY_SRC;
        let planes = parts.clone().map(|p| p.reach.len() as u32 - 1).sum();
        let rows: u64 = parts.clone().map(|p| p.rows).sum();
        let vertices = parts.clone().map(|p| p.vertices.len() as u32).sum();
        // Each part's reach but its sentinel, its row and vertex indices moved by the parts'
        // before it, then the whole's sentinel.
        let bases: Vec<(u32, u32)> = parts
            .clone()
            .scan((0u32, 0u32), |at, p| {
                let base = *at;
                *at = (at.0 + p.rows as u32, at.1 + p.vertices.len() as u32);
                Some(base)
            })
            .chain([(0, 0)])
            .collect();
        let shift = |i: usize, r: &mut [u32; 4]| (r[2], r[3]) = (r[2] + bases[i].0, r[3] + bases[i].1);
        let shifted = bases.iter().any(|&b| b != (0, 0));
        let last = [[0, 0, rows as u32, vertices]];
        let reach = parts.clone().map(|p| &p.reach[..p.reach.len() - 1]).chain([&last[..]]);
        let params = ReachParams { width, height, planes, rows: rows as u32 };
        Ok(PolygonBuffers {
            reach: gpu.upload_parts("reach", reach, shifted.then_some(&shift as Patch<[u32; 4]>), storage)?,
            vertices: gpu.upload_parts("vertices", parts.map(|p| p.vertices.as_slice()), None, storage)?,
            spans: gpu.scratch("spans", rows * 4, filled),
            groups: gpu.scratch("groups", rows * std::mem::size_of::<[u32; GROUPS]>() as u64, filled),
            params: gpu.upload("reach params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM),
            rows,
        })
    }

    /// The bytes that crossed for them.
    pub(super) fn bytes_up(&self) -> u64 {
        [&self.reach, &self.vertices, &self.params].map(|b| b.size()).iter().sum()
    }

    /// Records the pass that fills the rows: a thread per row of tiles (with `timestamp_writes`).
    pub(super) fn encode(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        timestamp_writes: Option<wgpu::ComputePassTimestampWrites>,
    ) {
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("reach"),
            layout: &gpu.reach_layout,
            entries: &[
                entry(0, &self.params),
                entry(1, &self.reach),
                entry(2, &self.vertices),
                entry(3, &self.spans),
                entry(4, &self.groups),
            ],
        });
        let (x, y) = grid(self.rows.div_ceil(256));
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes });
        pass.set_pipeline(&gpu.reach);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(x, y, 1);
    }
}

/// The reach the GPU finds for each of `planes` in a `width x height` image (what the binning
/// reads), read back: for holding it to [`super::tile_reach`]'s.
pub fn reach_on_gpu(gpu: &Arc<Gpu>, planes: &[ScreenReach], width: u32, height: u32) -> Result<Vec<TileReach>> {
    let host = Polygons::new(planes);
    let readback = |label, size| gpu.scratch(label, size, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
    let (buffers, spans, groups) = gpu.checked(|| -> Result<_> {
        let buffers = PolygonBuffers::upload(gpu, [&host].into_iter(), width, height)?;
        let (spans, groups) =
            (readback("spans read back", buffers.spans.size()), readback("groups read back", buffers.groups.size()));
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        buffers.encode(gpu, &mut encoder, None);
        encoder.copy_buffer_to_buffer(&buffers.spans, 0, &spans, 0, spans.size());
        encoder.copy_buffer_to_buffer(&buffers.groups, 0, &groups, 0, groups.size());
        gpu.queue.submit([encoder.finish()]);
        for b in [&spans, &groups] {
            b.slice(..).map_async(wgpu::MapMode::Read, |_| ());
        }
        Ok((buffers, spans, groups))
    })??;
    gpu.device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| Error::Device(format!("waiting for the GPU: {e}")))?;
    gpu.work_errors()?;
    drop(buffers);
    let mapped = |b: &wgpu::Buffer| {
        b.slice(..).get_mapped_range().map_err(|e| Error::Device(format!("reading the GPU's reach back: {e}")))
    };
    let (spans, groups) = (mapped(&spans)?, mapped(&groups)?);
    let (spans, groups): (&[u32], &[[u32; GROUPS]]) = (bytemuck::cast_slice(&spans), bytemuck::cast_slice(&groups));
    Ok(planes
        .iter()
        .zip(&host.reach)
        .map(|(p, r)| {
            let rows = r[2] as usize..(r[2] + p.rows) as usize;
            TileReach {
                first_row: p.first_row,
                spans: spans[rows.clone()].iter().map(|&s| [s & 0xffff, s >> 16]).collect(),
                groups: groups[rows].to_vec(),
            }
        })
        .collect())
}
