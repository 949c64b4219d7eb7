//! Camera rays on the GPU ([`GpuRays`]): uploaded from the CPU, written by the CPU's threads
//! straight into a mapped buffer, or made on the GPU by `rays.wgsl`; kept there for every piece
//! gathered along them.

use super::clock::{Clock, Mark, Timestamps};
use super::device::{Gpu, entry};
use super::records::RaysDispatch;
use crate::camera::{CameraRay, RayRowFn};
use crate::error::{Error, Result};
use crate::pixel::{PanelRecord, RaySetRecord};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Camera rays on the GPU, one per pixel, row-major: [`CameraRay`]s (20 bytes, `gather.wgsl`'s
/// `RAY_FLOATS`), made there by `rays.wgsl` ([`GpuRays::on_gpu`]) or uploaded
/// ([`GpuRays::new`]), for every piece gathered along them. Made on the GPU, a buffer may hold
/// several ray sets ([`GpuRays::sets_on_gpu`]), each at a multiple of the binding offset's
/// alignment, so that the pieces along them are gathered in one dispatch.
pub struct GpuRays {
    pub(super) buffer: wgpu::Buffer,
    /// Rays in one set (a pixel's each).
    pub(super) len: usize,
    /// Its sets, and the bytes from one's start to the next's.
    sets: u32,
    stride: u64,
    gpu: Arc<Gpu>,
    /// The pass that makes them, submitted with the first gathering along them (or when they
    /// are read back), and with the trace on its timestamps.
    pending: Mutex<(Option<wgpu::CommandBuffer>, Option<Timestamps>)>,
    upload_ns: u64,
    /// Bytes that crossed to the GPU to make them.
    bytes_up: u64,
    /// Made by the GPU: the work along them is kept to be submitted with the sums' reading
    /// (rays made on the CPU are gathered along at once, so that the CPU makes the next set
    /// while the GPU gathers).
    pub(super) made_on_gpu: bool,
    /// The last submission that gathers along them.
    pub(super) last_use: Mutex<Option<wgpu::SubmissionIndex>>,
}

/// The most sets one dispatch makes: a workgroup's z, at most wgpu's default 65,535 a side.
const MAX_SETS_A_DISPATCH: u32 = 65_535;

impl GpuRays {
    /// Refused in one line where the rays of `len` pixels exceed one binding.
    fn check(gpu: &Gpu, len: usize) -> Result<u64> {
        let bytes = (len * std::mem::size_of::<CameraRay>()) as u64;
        // The shaders index their floats with u32.
        let most = gpu.max_binding().min(4 * u32::MAX as u64);
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
            sets: 1,
            stride: bytes,
            gpu: gpu.clone(),
            pending: Mutex::new((None, None)),
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
        Self::sets_on_gpu(gpu, &[(set, panels)])
    }

    /// The ray sets `sets` (each with its light panels) made on `gpu` into one buffer, set `k`
    /// at [`GpuRays::floats_at`]`(k)`: their records and panels in two uploads and one dispatch
    /// (a workgroup's z its set; 65,535 sets a dispatch), submitted with the first gathering
    /// along them. Refused in one line where a set exceeds one binding; `sets`
    /// must fit one binding together ([`GpuRays::sets_fitting`]).
    pub fn sets_on_gpu(gpu: &Arc<Gpu>, sets: &[(&RaySetRecord, &[PanelRecord])]) -> Result<Self> {
        let (w, h) = (sets[0].0.width, sets[0].0.height);
        assert!(sets.iter().all(|(s, _)| (s.width, s.height) == (w, h)), "the sets of one image");
        let bytes = Self::check(gpu, w as usize * h as usize)?;
        let stride = Self::stride(gpu, bytes);
        assert!(stride * (sets.len() as u64 - 1) + bytes <= gpu.max_binding(), "the sets fit one binding");
        let groups = (w.div_ceil(super::TILE), h.div_ceil(super::TILE));
        if groups.0 > 65_535 || groups.1 > 65_535 {
            return Err(Error::Device(format!(
                "a {w}x{h} image has more than 65,535 x 16 pixels on a side, more than the GPU makes rays for: render a smaller image on it, or on the CPU"
            )));
        }
        let t = Instant::now();
        // Every set's record, where its panels and its rays begin in the buffers of all of
        // them, and their panels one after another: two uploads, one dispatch.
        let mut records = Vec::with_capacity(sets.len());
        let mut all_panels = Vec::new();
        for (k, (set, panels)) in sets.iter().enumerate() {
            let first_float = u32::try_from(stride / 4 * k as u64).expect("the sets fit one binding, u32 floats");
            records.push(RaySetRecord { first_panel: all_panels.len() as u32, first_float, ..**set });
            all_panels.extend_from_slice(panels);
        }
        // A buffer is never empty: a scene without a panel binds one panel that no set reads.
        if all_panels.is_empty() {
            all_panels.push(PanelRecord::default());
        }
        let (buffer, commands, timestamps) = gpu.checked(|| {
            let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
            let buffer = gpu.scratch("rays", stride * (sets.len() as u64 - 1) + bytes, usage);
            let records = gpu.upload("ray sets", bytemuck::cast_slice(&records), wgpu::BufferUsages::STORAGE);
            let panels = gpu.upload("panels", bytemuck::cast_slice(&all_panels), wgpu::BufferUsages::STORAGE);
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            // No round (the rays are not in the gather's time): timed only with the trace on.
            let dispatches = sets.len().div_ceil(MAX_SETS_A_DISPATCH as usize);
            let mut clock = Clock::new(gpu, 0, dispatches);
            for first in (0..sets.len() as u32).step_by(MAX_SETS_A_DISPATCH as usize) {
                let count = (sets.len() as u32 - first).min(MAX_SETS_A_DISPATCH);
                let dispatch = RaysDispatch { first_set: first, pad: [0; 3] };
                let dispatch = gpu.upload("rays dispatch", bytemuck::bytes_of(&dispatch), wgpu::BufferUsages::UNIFORM);
                let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("rays"),
                    layout: &gpu.rays_layout,
                    entries: &[entry(0, &dispatch), entry(1, &records), entry(2, &panels), entry(3, &buffer)],
                });
                let timestamp_writes = clock.as_mut().and_then(|c| c.pass("rays", Mark::default()));
                let mut pass =
                    encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes });
                pass.set_pipeline(&gpu.rays);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(groups.0, groups.1, count);
            }
            let timestamps = clock.map(|c| c.finish(&mut encoder));
            (buffer, encoder.finish(), timestamps)
        })?;
        let crossed: usize = sets.iter().map(|(s, p)| std::mem::size_of_val(*s) + std::mem::size_of_val(*p)).sum();
        Ok(GpuRays {
            buffer,
            len: w as usize * h as usize,
            sets: sets.len() as u32,
            stride,
            gpu: gpu.clone(),
            pending: Mutex::new((Some(commands), timestamps)),
            upload_ns: t.elapsed().as_nanos() as u64,
            bytes_up: crossed as u64,
            made_on_gpu: true,
            last_use: Mutex::new(None),
        })
    }

    /// Bytes from one set's start to the next's in a buffer of several: a set's `bytes` rounded
    /// up to the alignment of a binding's offset.
    fn stride(gpu: &Gpu, bytes: u64) -> u64 {
        bytes.next_multiple_of(gpu.device.limits().min_storage_buffer_offset_alignment as u64)
    }

    /// How many ray sets of a `pixels`-pixel image one buffer of [`GpuRays::sets_on_gpu`] holds
    /// (at least 1).
    pub fn sets_fitting(gpu: &Gpu, pixels: usize) -> usize {
        let bytes = (pixels * std::mem::size_of::<CameraRay>()) as u64;
        let stride = Self::stride(gpu, bytes).max(1);
        // The shaders index the floats with u32.
        let most = gpu.max_binding().min(4 * u32::MAX as u64);
        (most.saturating_sub(bytes) / stride + 1) as usize
    }

    /// Bytes of the buffer (every set's).
    pub(super) fn bytes(&self) -> u64 {
        self.stride * (self.sets as u64 - 1) + (self.len * std::mem::size_of::<CameraRay>()) as u64
    }

    /// Where set `k` begins, in floats (what a gathering's work items carry).
    pub fn floats_at(&self, k: u32) -> u32 {
        assert!(k < self.sets, "set {k} of {}", self.sets);
        (self.stride / 4 * k as u64) as u32
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
            sets: 1,
            stride: bytes,
            gpu: gpu.clone(),
            pending: Mutex::new((None, None)),
            upload_ns,
            bytes_up: bytes,
            made_on_gpu: false,
            last_use: Mutex::new(None),
        })
    }

    /// Waits until the GPU has done the work submitted along these rays (so that the caller
    /// bounds the ray sets in flight: the CPU may otherwise run a chunk's pieces ahead);
    /// returns the nanoseconds it waited.
    pub fn wait(&self) -> Result<u64> {
        let last = self.last_use.lock().unwrap_or_else(|p| p.into_inner()).take();
        let t = Instant::now();
        if let Some(index) = last {
            let polled = self.gpu.device.poll(wgpu::PollType::Wait { submission_index: Some(index), timeout: None });
            self.gpu.work_errors()?;
            polled.map_err(|e| Error::Device(format!("waiting for the GPU: {e}")))?;
        }
        Ok(t.elapsed().as_nanos() as u64)
    }

    /// The pass that makes them, if it is not submitted yet: to submit before the work that
    /// reads them, and its timestamps (with the trace on) to read with that work's.
    pub(super) fn take_pending(&self) -> (Option<wgpu::CommandBuffer>, Option<Timestamps>) {
        std::mem::take(&mut *self.pending.lock().unwrap_or_else(|p| p.into_inner()))
    }

    /// Whether the GPU makes them (the work along them is then kept to be submitted with the
    /// sums' reading).
    pub fn made_on_gpu(&self) -> bool {
        self.made_on_gpu
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
        self.read_set(0)
    }

    /// The rays of set `k` of those made together, read back (for tests).
    pub fn read_set(&self, k: u32) -> Result<Vec<CameraRay>> {
        let gpu = &*self.gpu;
        let bytes = (self.len * std::mem::size_of::<CameraRay>()) as u64;
        let from = 4 * self.floats_at(k) as u64;
        let readback = gpu.checked(|| {
            let readback =
                gpu.scratch("rays read back", bytes, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&self.buffer, from, &readback, 0, bytes);
            gpu.queue.submit(self.take_pending().0.into_iter().chain([encoder.finish()]));
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
