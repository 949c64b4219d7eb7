//! A structure's planes on the GPU ([`GpuPlanes`]): cut into batches and rounds on the CPU
//! (gpu/batches.rs), joined with other pieces' where they are gathered together, uploaded by
//! their first gathering (gpu/plane_buffers.rs), and each gathering's passes recorded
//! (gpu/passes.rs) to be kept with the sums.

use super::batches::{Batch, Bounds, Round, batches, merged, rounds};
use super::device::Gpu;
use super::passes::{Gathering, Recorded};
use super::plane_buffers::{PlaneBuffers, PlaneData};
use super::polygons::Polygons;
use super::rays::GpuRays;
use super::sums::GpuSums;
use super::{ScreenReach, TILE};
use crate::camera::{CameraRay, RayRowFn};
use crate::control::Control;
use crate::error::{Error, Result};
use crate::gather::{GatherContext, GatherStats, Phase, PlaneRecord};
use crate::pixel::{PanelRecord, RaySetRecord};
use crate::weights::Weighting;
use glam::Vec3;
use std::sync::atomic::AtomicBool;
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
        let pipelines = gpu.checked(|| gpu.gather_pipelines(weighting))?;
        let (planes, upload_ns, bytes_crossed) = {
            let _s = crate::trace::span("planes uploaded");
            self.buffers()?
        };
        let gathering = Gathering {
            gpu,
            width: w,
            height: h,
            planes,
            count: self.planes,
            batches: &self.batches,
            rounds: &self.rounds,
            sigma_t: self.sigma_t,
            grey: self.grey,
            phase: self.phase,
            reach_found: &self.reach_found,
        };
        let mut recorded =
            gpu.checked(|| gathering.encode(weighting, &pipelines, (rays, rays_at), into, control))??;
        let dispatches = self.rounds.len() as u64;
        recorded.stats = GatherStats { upload_ns, bytes_crossed, dispatches, ..GatherStats::default() };
        progress();
        Ok(recorded)
    }
}

/// The bounds of a gathering's batches and rounds on `gpu` for a `width x height` image.
fn bounds(gpu: &Gpu, width: u32, height: u32) -> Bounds {
    Bounds {
        tiles: (width.div_ceil(TILE) * height.div_ceil(TILE)) as u64,
        cpu: gpu.is_cpu_adapter(),
        fixed: gpu.fixed_item_planes(),
        max_binding: gpu.max_binding(),
    }
}
