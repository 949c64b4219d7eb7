//! An image's sums on the GPU ([`GpuSums`]): what every gathering into it adds to, the work
//! not submitted yet, and their one reading back.

use super::clock::Timestamps;
use super::device::Gpu;
use crate::error::{Error, Result};
use crate::gather::GatherStats;
use glam::Vec3;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// An image's f32 sums on the GPU: per pixel the bits of (r, g, b) (`gather.wgsl`'s `image`,
/// 12 bytes), then per tile of 16 x 16 pixels its hits and its tests (two u64, each two u32
/// words, low first: a total is all the render reports of them, and a pixel's count took a
/// quarter of the bytes read back), zero when made (wgpu zeroes a new buffer). Every
/// gathering into it ([`super::GpuPlanes::gather_into`]) adds there, in order, and it crosses
/// back once ([`GpuSums::read_into`]): a chunk's pieces cost one image read back, not one each.
pub struct GpuSums {
    gpu: Arc<Gpu>,
    pub(super) image: wgpu::Buffer,
    pub(super) pixels: usize,
    /// The bytes of `image`: the pixels' sums and the tiles' hits ([`sums_bytes`]).
    bytes: u64,
    /// The gatherings' timestamps, resolved on the GPU, to read with the sums.
    pub(super) timestamps: Vec<Timestamps>,
    /// When the first gathering into these sums was submitted (the GPU's time where the adapter
    /// has no timestamps).
    first_submission: Option<Instant>,
    /// A gathering into them without timestamps: they are timed by the wall time.
    pub(super) untimed: bool,
    /// The gatherings' command buffers (and their rays' passes) not submitted yet: submitted
    /// together when the sums are read ([`GpuSums::read_into`]), so that a chunk's pieces are one
    /// submission, not one each.
    pub(super) pending: Vec<wgpu::CommandBuffer>,
    /// Set once the pending work is submitted: whether a structure's reach has been found
    /// ([`super::GpuPlanes`] records the pass into the first gatherings until then).
    pub(super) on_submit: Vec<Arc<AtomicBool>>,
    /// Bytes of the ray sets the pending work holds on the GPU ([`super::PENDING_RAY_BYTES`]),
    /// each buffer counted where the work along it begins (consecutive gatherings along one
    /// buffer of several sets count it once), and that buffer.
    pub(super) pending_rays: u64,
    last_rays: Option<wgpu::Buffer>,
    /// Bytes that crossed to the GPU for these sums' gatherings, and the submissions, since
    /// the last read.
    pub(super) bytes_up: u64,
    submissions: u64,
    /// The reading back asked for ([`GpuSums::submit_pending`]), not yet done.
    reading: Option<Reading>,
    /// Copies of the pixels' sums after gatherings ([`GpuSums::snapshot`]), not read yet, and
    /// the bytes read back of them since the last read.
    snapshots: Vec<wgpu::Buffer>,
    bytes_down: u64,
}

/// A reading back under way: the buffer the sums are copied to, and the gatherings'
/// timestamps, both asked to be mapped.
struct Reading {
    readback: wgpu::Buffer,
    timestamps: Vec<Timestamps>,
    /// The submission that copies the sums: the reading waits for it alone, so that the GPU
    /// goes on with a window's later chunks while the CPU reads one back.
    index: Option<wgpu::SubmissionIndex>,
}

/// A pixel's sums as the GPU holds them (f32 bits, r g b): how a reading back and a snapshot
/// (`render`'s error image) both add them, the same bits.
pub fn sums_of_bits(v: &[u32; 3]) -> Vec3 {
    Vec3::new(f32::from_bits(v[0]), f32::from_bits(v[1]), f32::from_bits(v[2]))
}

/// Bytes of a `width x height` image's sums on the GPU: 12 a pixel, 16 a tile ([`GpuSums`]).
pub(super) fn sums_bytes(width: u32, height: u32) -> u64 {
    let tiles = width.div_ceil(super::TILE) as u64 * height.div_ceil(super::TILE) as u64;
    width as u64 * height as u64 * 12 + tiles * 16
}

impl GpuSums {
    /// Zero sums for a `width x height` image on `gpu`.
    pub fn new(gpu: Arc<Gpu>, width: u32, height: u32) -> Result<Self> {
        let pixels = width as usize * height as usize;
        let bytes = sums_bytes(width, height);
        if bytes > gpu.max_binding() {
            return Err(Error::Device(format!(
                "the sums of a {width}x{height} image take {bytes} bytes, more than the GPU binds at once ({} bytes): render a smaller image on it, or on the CPU",
                gpu.max_binding()
            )));
        }
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let image = gpu.checked(|| gpu.scratch("image", bytes, usage))?;
        Ok(GpuSums {
            gpu,
            image,
            pixels,
            bytes,
            timestamps: Vec::new(),
            first_submission: None,
            untimed: false,
            pending: Vec::new(),
            on_submit: Vec::new(),
            pending_rays: 0,
            last_rays: None,
            bytes_up: 0,
            submissions: 0,
            reading: None,
            snapshots: Vec::new(),
            bytes_down: 0,
        })
    }

    /// A copy of the pixels' sums as the work recorded so far leaves them, taken on the GPU in
    /// order with that work (no submission of its own) and read back with the other copies
    /// ([`GpuSums::read_snapshots`]): the error image's pieces told apart without a round trip
    /// each.
    pub fn snapshot(&mut self) -> Result<()> {
        assert!(self.reading.is_none(), "a snapshot of sums whose reading is under way");
        let gpu = self.gpu.clone();
        let bytes = self.pixels as u64 * 12;
        let copy = gpu.checked(|| {
            let copy = gpu.scratch("sums snapshot", bytes, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&self.image, 0, &copy, 0, bytes);
            self.pending.push(encoder.finish());
            copy
        })?;
        self.snapshots.push(copy);
        self.bytes_down += bytes;
        Ok(())
    }

    /// The bytes of the snapshots not read yet.
    pub fn snapshot_bytes(&self) -> u64 {
        self.snapshots.len() as u64 * self.pixels as u64 * 12
    }

    /// Submits the work not submitted yet and gives `each` the snapshots taken since the last
    /// ones were read, in order: each pixel's sums as the GPU held them (f32 bits, r g b).
    pub fn read_snapshots(&mut self, each: &mut dyn FnMut(&[[u32; 3]])) -> Result<()> {
        let copies = std::mem::take(&mut self.snapshots);
        if copies.is_empty() {
            return Ok(());
        }
        let index = self.submit();
        for copy in &copies {
            copy.slice(..).map_async(wgpu::MapMode::Read, |_| ());
        }
        let polled = self.gpu.device.poll(wgpu::PollType::Wait { submission_index: index, timeout: None });
        self.gpu.work_errors()?;
        polled.map_err(|e| Error::Device(format!("waiting for the GPU: {e}")))?;
        for copy in &copies {
            let view = copy
                .slice(..)
                .get_mapped_range()
                .map_err(|e| Error::Device(format!("reading the GPU's results back: {e}")))?;
            each(bytemuck::cast_slice(&view[..self.pixels * 12]));
        }
        Ok(())
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
        self.last_rays = None;
        let index = self.gpu.queue.submit(work);
        for found in self.on_submit.drain(..) {
            found.store(true, Ordering::Release);
        }
        Some(index)
    }

    /// Submits the work not submitted yet.
    pub(super) fn submit(&mut self) -> Option<wgpu::SubmissionIndex> {
        self.submit_with(None)
    }

    /// Adds a gathering recorded along `rays` ([`super::GpuPlanes::record`]) to the work on
    /// these sums, after the pass that makes the rays if it is not added yet: submitted when
    /// the sums are read, or now where the rays were made on the CPU (so that the CPU makes the
    /// next set while the GPU gathers). Where the work held passes [`super::PENDING_RAY_BYTES`]
    /// of ray sets ([`GpuSums::holds_too_many_rays`]), the caller submits every sums' work in
    /// order ([`GpuSums::submit_held`]): a buffer of sets is made by the work of the first sums
    /// that gathers along it, which must go first. Returns what the recording found (the
    /// planes' upload).
    pub fn add(&mut self, recorded: super::Recorded, rays: &super::GpuRays) -> GatherStats {
        assert!(self.reading.is_none(), "a gathering added to sums whose reading is under way");
        let Some(commands) = recorded.commands else {
            return recorded.stats;
        };
        let (made, made_timestamps) = rays.take_pending();
        self.pending.extend(made);
        self.timestamps.extend(made_timestamps);
        self.pending.push(commands);
        self.on_submit.extend(recorded.reach);
        if self.last_rays.as_ref() != Some(&rays.buffer) {
            self.pending_rays += rays.bytes();
            self.last_rays = Some(rays.buffer.clone());
        }
        self.bytes_up += recorded.bytes_up;
        if !rays.made_on_gpu {
            *rays.last_use.lock().unwrap_or_else(|p| p.into_inner()) = self.submit();
        }
        match recorded.timestamps {
            Some(t) => self.timestamps.push(t),
            None => self.untimed = true,
        }
        recorded.stats
    }

    /// Whether the work not submitted yet holds more than [`super::PENDING_RAY_BYTES`] of ray
    /// sets: the caller then submits every sums' work, in order ([`GpuSums::add`]).
    pub fn holds_too_many_rays(&self) -> bool {
        self.pending_rays > super::PENDING_RAY_BYTES
    }

    /// Submits the work not submitted yet (a large image's ray sets are then let go as their
    /// gatherings end).
    pub fn submit_held(&mut self) {
        self.submit();
    }

    /// Submits the gatherings not submitted yet with the copy of the sums for reading back
    /// ([`GpuSums::read_into`] then waits for them), so that the GPU runs them while the CPU
    /// reads other sums back: a window of several chunks submits each chunk's work before the
    /// first reading, not after the reading before it, still one submission a chunk.
    pub fn submit_pending(&mut self) -> Result<()> {
        if self.reading.is_none() {
            self.reading = Some(self.start_reading()?);
        }
        Ok(())
    }

    /// Submits the work not submitted yet and the sums' copy to a buffer the CPU maps, which is
    /// asked for (with the gatherings' timestamps).
    fn start_reading(&mut self) -> Result<Reading> {
        let _s = crate::trace::span("work submitted");
        let gpu = self.gpu.clone();
        let timestamps = std::mem::take(&mut self.timestamps);
        let bytes = self.bytes;
        gpu.checked(|| {
            let readback =
                gpu.scratch("image read back", bytes, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&self.image, 0, &readback, 0, bytes);
            let index = self.submit_with(Some(encoder.finish()));
            for b in timestamps.iter().map(|t| &t.readback).chain([&readback]) {
                b.slice(..).map_async(wgpu::MapMode::Read, |_| ());
            }
            Reading { readback, timestamps, index }
        })
    }

    /// Waits for the gatherings into these sums, adds the sums to `sums` (one per pixel) and
    /// returns the tests and hits they counted (in all) and the GPU's time of the gatherings
    /// since the last read.
    pub fn read_into(&mut self, sums: &mut [Vec3]) -> Result<GatherStats> {
        assert_eq!(sums.len(), self.pixels, "one sum per pixel");
        let held = self.gpu.clone();
        let gpu = &*held;
        let bytes = self.bytes;
        let Reading { readback, timestamps, index } = match self.reading.take() {
            Some(r) => r,
            None => self.start_reading()?,
        };
        let waiting = crate::trace::span("waited for the GPU");
        let t = Instant::now();
        let polled = gpu.device.poll(wgpu::PollType::Wait { submission_index: index, timeout: None });
        let wait_ns = t.elapsed().as_nanos() as u64;
        let waited = self.first_submission.take().map_or(0, |t| t.elapsed().as_nanos() as u64);
        let untimed = std::mem::take(&mut self.untimed);
        gpu.work_errors()?;
        polled.map_err(|e| Error::Device(format!("waiting for the GPU: {e}")))?;
        let mapped = |b: &wgpu::Buffer| {
            b.slice(..).get_mapped_range().map_err(|e| Error::Device(format!("reading the GPU's results back: {e}")))
        };
        let timestamp_bytes: u64 = timestamps.iter().map(|t| t.readback.size()).sum();
        let mut stats = GatherStats {
            device_ns: waited,
            wait_ns,
            bytes_crossed: std::mem::take(&mut self.bytes_up)
                + std::mem::take(&mut self.bytes_down)
                + bytes
                + timestamp_bytes,
            submissions: std::mem::take(&mut self.submissions),
            ..GatherStats::default()
        };
        if !untimed && !timestamps.is_empty() {
            let period = gpu.queue.get_timestamp_period() as f64;
            stats.device_ns = 0;
            for t in &timestamps {
                let view = mapped(&t.readback)?;
                let (all, gather) = t.read(bytemuck::cast_slice(&view), period);
                stats.device_ns += all;
                stats.device_gather_ns += gather;
            }
        }
        drop(waiting);
        let _s = crate::trace::span("sums read back");
        let view = mapped(&readback)?;
        let (back, counts) = view[..bytes as usize].split_at(self.pixels * 12);
        let back: &[[u32; 3]] = bytemuck::cast_slice(back);
        // Added pixel by pixel in parallel (the same bits: each pixel's one addition).
        use rayon::prelude::*;
        sums.par_iter_mut().zip(back).with_min_len(4096).for_each(|(sum, v)| {
            *sum += sums_of_bits(v);
        });
        let counts: &[[u32; 4]] = bytemuck::cast_slice(counts);
        let word = |lo: u32, hi: u32| lo as u64 | (hi as u64) << 32;
        stats.hits = counts.iter().map(|c| word(c[0], c[1])).sum();
        stats.tests = counts.iter().map(|c| word(c[2], c[3])).sum();
        Ok(stats)
    }
}
