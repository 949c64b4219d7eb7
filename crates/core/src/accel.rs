//! The planes of a render prepared for gathering, behind one interface whatever the
//! intersection structure (the raster, the BVH, the brute force or the GPU): a set's planes are sampled in pieces,
//! each plane's constants prepared for rays from the camera ([`GatherContext`]), and the
//! structure chosen by [`Accelerator`] built over them; [`PreparedPlanes::gather`] then runs one
//! weighting through the structure's [`Aggregate::gather`].

use crate::bvh::PlaneBvh;
use crate::camera::CameraRay;
use crate::control::Control;
use crate::error::{Error, Result};
use crate::gather::{GatherContext, GatherStats};
use crate::gpu::{self, GpuPlanes, GpuRays, GpuSums};
use crate::kernel::{Aggregate, Gathering, Kernel, RAY_CHUNK, gather_per_ray};
use crate::limits::PLANE_UNIT;
use crate::occlusion::occluders_of_polygon;
use crate::photon_plane::{PhotonPlane, PlaneSet, PlaneSources, sample_plane};
use crate::pixel::{PanelRecord, RaySetRecord};
use crate::raster::{RasterPiece, ScreenRaster, Tiling, box_polygon, screen_polygon_of};
use crate::scene::Scene;
use crate::weights::{Denominator, Weighting, WithDenominator};
use glam::{DVec3, Vec3};
use std::ops::Range;
use std::sync::Arc;
use std::time::Instant;

/// How camera rays find the planes they hit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Accelerator {
    /// Planes rasterised in screen space (the fast path).
    #[default]
    Raster,
    /// A bounding volume hierarchy over the planes, traversed per ray.
    Bvh,
    /// Every ray tests every plane (for checking the others).
    BruteForce,
    /// The GPU ([`crate::gpu`]), adapter N of [`gpu::adapters`]: chosen by the device
    /// (`--device gpu`, `gpu:N`), never by name, so it is not among [`Accelerator::ALL`], the
    /// CPU's structures.
    Gpu(usize),
}

impl Accelerator {
    /// The CPU's structures (`--accelerator`).
    pub const ALL: [Accelerator; 3] = [Accelerator::Raster, Accelerator::Bvh, Accelerator::BruteForce];

    pub fn name(self) -> &'static str {
        match self {
            Accelerator::Raster => "raster",
            Accelerator::Bvh => "bvh",
            Accelerator::BruteForce => "brute-force",
            Accelerator::Gpu(_) => "gpu",
        }
    }

    /// Makes ready now what a gathering with `weighting` compiles on first use: the GPU's
    /// pipelines ([`gpu::Gpu::compile_gather`]), so that a render compiles them beside its
    /// first planes' preparation; nothing on the CPU.
    pub fn compile(self, weighting: Weighting) -> Result<()> {
        match self {
            Accelerator::Gpu(index) => gpu::adapter_at(Some(index)).map_err(Error::Device)?.1.compile_gather(weighting),
            _ => Ok(()),
        }
    }

    /// Progress units of one gathering over the image (for sizing a progress bar): a tile on
    /// the raster (sized for the current thread pool: call it in the pool that renders), a
    /// chunk of rays on the per-ray structures, the whole image on the GPU.
    pub fn units_per_gathering(self, width: u32, height: u32) -> u64 {
        match self {
            Accelerator::Raster => Tiling::new(width, height, crate::schedule::workers()).count() as u64,
            Accelerator::Gpu(_) => 1,
            _ => (width as u64 * height as u64).div_ceil(RAY_CHUNK as u64),
        }
    }
}

crate::named_choice!(Accelerator, "accelerator");

/// Every ray tests every plane: the slowest structure, and the simplest check of the others.
pub struct BruteForce;

impl Aggregate for BruteForce {
    fn gather<D: Denominator>(
        &self,
        with: Gathering<D>,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        control: Control,
    ) -> GatherStats {
        let tests = with.ctx.views.len() as u64;
        gather_per_ray(rays, sums, control, |ray| {
            let (value, hits) = with.ctx.gather_brute_force(with.weights, ray);
            (value, GatherStats { tests, hits, ..Default::default() })
        })
    }
}

/// The structure built over a set's planes: one of the CPU's, gathered through [`Aggregate`]
/// with the weighting's denominator as a type, or the GPU's, which takes the weighting as a
/// value (its shaders are specialised per estimator instead).
enum Structure {
    Cpu(CpuStructure),
    Gpu(GpuPlanes),
}

/// The CPU's structures.
enum CpuStructure {
    Raster(ScreenRaster),
    Bvh(PlaneBvh),
    BruteForce(BruteForce),
}

impl Aggregate for CpuStructure {
    fn gather<D: Denominator>(
        &self,
        with: Gathering<D>,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        control: Control,
    ) -> GatherStats {
        match self {
            CpuStructure::Raster(s) => s.gather(with, rays, sums, control),
            CpuStructure::Bvh(s) => s.gather(with, rays, sums, control),
            CpuStructure::BruteForce(s) => s.gather(with, rays, sums, control),
        }
    }
}

/// Planes sampled in pieces of this many, so that the sampled planes never all exist at once:
/// only their prepared views and screen polygons are kept.
const SAMPLING_PIECE: usize = 16_384;

/// What the CPU prepares of a piece of planes before its structure is made
/// ([`PreparedPlanes::from_cpu_side`]): the planes' constants, and the raster's binning, the
/// GPU's reach records or the planes themselves (for the BVH), as the accelerator needs. Public
/// so that `benches/examples/prepare_planes.rs` times the render's own preparation.
pub struct CpuSide {
    /// The structure it was prepared for.
    pub accelerator: Accelerator,
    pub context: GatherContext,
    pub raster: Option<ScreenRaster>,
    /// What crosses for the GPU's reach, a plane's each (empty but on the GPU).
    pub reach: Vec<gpu::ScreenReach>,
    /// The planes, kept for the BVH only.
    pub all: Vec<PhotonPlane>,
    pub seconds_sampling: f64,
    pub seconds_build: f64,
}

impl CpuSide {
    /// Planes `range` of `set` sampled and prepared for `accelerator` in pieces of
    /// [`SAMPLING_PIECE`]; [`crate::Error::Cancelled`] once `control` is cancelled (checked
    /// before each piece).
    pub fn prepare(
        scene: &Scene,
        set: PlaneSet,
        range: Range<usize>,
        accelerator: Accelerator,
        tiling: Tiling,
        control: Control,
    ) -> Result<Self> {
        let (mut seconds_sampling, mut seconds_build) = (0.0, 0.0);
        let origin = scene.camera.position;
        let mut context = GatherContext::empty(scene, origin);
        // On the GPU, the views and the reach records reserved whole (a piece of 40,960 planes
        // grown piece by piece cost 1.4 times the CPU of its preparation:
        // benches/examples/prepare_planes.rs). Not for the raster: with glibc's own allocator
        // settings (the Python module's; the command line sets its own,
        // `limits::keep_freed_memory`) its reserved views were fresh pages at every piece (a
        // render of 655,360 planes at 32x18: 71,700 page faults against 10,400, 0.25 s of
        // system time), where grown ones reuse the heap's; the BVH and the brute force are
        // left as they were.
        let on_gpu = matches!(accelerator, Accelerator::Gpu(_));
        if on_gpu {
            context.reserve(range.len());
        }
        let mut raster = (accelerator == Accelerator::Raster).then(|| ScreenRaster::empty_in(&scene.camera, tiling));
        // What crosses for each plane's reach on the GPU (`gpu::screen_reach`), made from its
        // screen polygon.
        let mut reach = Vec::with_capacity(if on_gpu { range.len() } else { 0 });
        // The BVH is built over the whole set at once; it keeps the planes while it does.
        let mut all = Vec::new();
        let (sources, numbers) = (PlaneSources::new(scene, set.lobes), set.sampler.numbers(set.seed));
        for start in range.clone().step_by(SAMPLING_PIECE) {
            control.check()?;
            let t = Instant::now();
            let piece = start..(start + SAMPLING_PIECE).min(range.end);
            let _s = crate::trace::span("planes sampled");
            let piece = control.map_units("sample", piece.len(), PLANE_UNIT, |j| {
                sample_plane(scene, &sources, numbers.plane((piece.start + j) as u64))
            });
            seconds_sampling += t.elapsed().as_secs_f64();
            drop(_s);
            let _s = crate::trace::span("planes prepared");
            let t = Instant::now();
            if matches!(accelerator, Accelerator::Raster | Accelerator::Gpu(_)) {
                // Each plane's box polygon made once, for its occluders and its screen polygon,
                // and on the GPU what crosses for its reach made from that in the same loop.
                let (cam, medium) = (&scene.camera, &scene.medium);
                let footprint = |i: usize| {
                    let world = box_polygon(&piece[i], medium);
                    (occluders_of_polygon(scene, &piece[i], &world), screen_polygon_of(cam, &world, medium))
                };
                match &mut raster {
                    Some(r) => {
                        let footprints = control.map_units("footprints", piece.len(), PLANE_UNIT, footprint);
                        let masks: Vec<u64> = footprints.iter().map(|f| f.0).collect();
                        context.push_planes_with_occluders_in(scene, &piece, &masks, 1, control);
                        // After the views, as before the footprints' loop was split: binning
                        // first made the heap's reuse fail under glibc's own settings (fresh
                        // pages: 78,000 page faults against 10,400, as above).
                        r.push_projected_in(&piece, |i| &footprints[i].1, control);
                    }
                    None => {
                        let footprints = control.map_units("footprints", piece.len(), PLANE_UNIT, |i| {
                            let (mask, screen) = footprint(i);
                            (mask, gpu::screen_reach(&screen, cam.width, cam.height))
                        });
                        let masks: Vec<u64> = footprints.iter().map(|f| f.0).collect();
                        context.push_planes_with_occluders_in(scene, &piece, &masks, 1, control);
                        // Copied in parallel, in place (the vector has room for every piece): a
                        // serial move of the records (152 bytes a plane) cost a tenth of the
                        // piece's wall time on 2 threads, and would cost more on more.
                        control.extend_units("reach", &mut reach, piece.len(), PLANE_UNIT, |i| footprints[i].1);
                    }
                }
            } else {
                context.push_planes_in(scene, &piece, 1, control);
            }
            seconds_build += t.elapsed().as_secs_f64();
            if accelerator == Accelerator::Bvh {
                all.extend(piece);
            }
        }
        Ok(CpuSide { accelerator, context, raster, reach, all, seconds_sampling, seconds_build })
    }
}

/// Planes sampled and prepared for gathering from the camera, each weighted 1 (the division by
/// the set's N comes once, when the image is finished: [`crate::film::Film::finish`]).
pub struct PreparedPlanes {
    context: GatherContext,
    structure: Structure,
    /// Seconds spent sampling planes and building the structure.
    pub seconds_sampling: f64,
    pub seconds_build: f64,
}

impl PreparedPlanes {
    /// Planes `range` of `set`, with the structure `accelerator` over them
    /// ([`Accelerator::Gpu`]: on the GPU, which the settings have found).
    /// [`crate::Error::Cancelled`] once `control` is cancelled (checked before each piece of
    /// planes sampled and after the last); [`crate::Error::Device`] if the GPU fails.
    pub fn new(
        scene: &Scene,
        set: PlaneSet,
        range: Range<usize>,
        accelerator: Accelerator,
        control: Control,
    ) -> Result<Self> {
        let (w, h) = (scene.camera.width, scene.camera.height);
        let tiling = Tiling::new(w, h, crate::schedule::workers());
        Self::from_cpu_side(scene, CpuSide::prepare(scene, set, range, accelerator, tiling, control)?, control)
    }

    /// The structure made over what the CPU prepared (a render's pieces: [`CpuSide::prepare`]
    /// with the raster's tiles of its windows of chunks, [`Tiling::for_window`]).
    pub fn from_cpu_side(scene: &Scene, side: CpuSide, control: Control) -> Result<Self> {
        let CpuSide { accelerator, context, raster, reach, all, seconds_sampling, mut seconds_build } = side;
        control.check()?;
        let t = Instant::now();
        let origin = scene.camera.position;
        let structure = match (accelerator, raster) {
            (Accelerator::Raster, Some(r)) => Structure::Cpu(CpuStructure::Raster(r)),
            (Accelerator::Bvh, _) => {
                Structure::Cpu(CpuStructure::Bvh(PlaneBvh::build(&all, &scene.medium, origin, control)?))
            }
            (Accelerator::Gpu(index), _) => {
                let (_, gpu) = gpu::adapter_at(Some(index)).map_err(Error::Device)?;
                let (w, h) = (scene.camera.width, scene.camera.height);
                let _s = crate::trace::span("planes for the GPU");
                Structure::Gpu(GpuPlanes::new(gpu, &context, &reach, w, h)?)
            }
            _ => Structure::Cpu(CpuStructure::BruteForce(BruteForce)),
        };
        seconds_build += t.elapsed().as_secs_f64();
        Ok(PreparedPlanes { context, structure, seconds_sampling, seconds_build })
    }

    /// The planes' per-plane constants.
    pub fn context(&self) -> &GatherContext {
        &self.context
    }

    /// The GPU's structure: a render's pieces all have one structure, and this is called
    /// where it is the GPU's.
    fn gpu(&self) -> &GpuPlanes {
        match &self.structure {
            Structure::Gpu(g) => g,
            _ => unreachable!("a render's pieces all have one structure, here the GPU's"),
        }
    }

    /// The raster, if that is the structure (for measuring the traversal alone).
    pub fn raster(&self) -> Option<&ScreenRaster> {
        match &self.structure {
            Structure::Cpu(CpuStructure::Raster(r)) => Some(r),
            _ => None,
        }
    }

    /// Gathers the rays of one ray set with `weighting`, adding each ray's estimate to `sums`;
    /// the raster runs `kernel` (resolved, see [`Kernel::resolve`]), the GPU its own shaders. Reports each unit of work to
    /// `control`; once it is cancelled, the work stops before the next plane (or ray) and the
    /// result is [`crate::Error::Cancelled`], with `sums` incomplete.
    pub fn gather(
        &self,
        weighting: Weighting,
        kernel: Kernel,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        control: Control,
    ) -> Result<GatherStats> {
        if let Structure::Gpu(g) = &self.structure {
            return g.gather(weighting, rays, sums, control);
        }
        let piece = GatherPiece { planes: self, rays, target: 0, tap: None };
        Ok(gather_pieces(&[piece], weighting, kernel, &mut [sums], &mut [], control)?[0])
    }
}

/// A piece of planes for [`gather_pieces`]: its planes, the rays it is gathered along, the
/// sums (of several) it adds to and the tap (of several), if any, that its own sums also go to.
#[derive(Clone, Copy)]
pub struct GatherPiece<'a> {
    pub planes: &'a PreparedPlanes,
    pub rays: &'a [CameraRay],
    pub target: usize,
    pub tap: Option<usize>,
}

/// A piece of planes on the GPU for [`gather_pieces_on_gpu`]: its planes, the ray set it is
/// gathered along (made on the GPU when the set changes) and the sums it adds to.
#[derive(Clone, Copy)]
pub struct GpuPiece<'a> {
    pub planes: &'a PreparedPlanes,
    pub set: u32,
    pub target: usize,
}

/// Sums kept on the GPU across gatherings, a target's each, with the ray set made last there:
/// [`gather_pieces_on_gpu`] adds there, and the sums cross back once, when the caller asks
/// ([`OnGpu::read_into`]), not after each gathering: one image read back per chunk, not per
/// piece, the chunk's work submitted with it, and a ray set made once for the consecutive
/// pieces along it.
pub struct OnGpu {
    sums: Vec<Option<GpuSums>>,
    /// The set made last: its index, its buffer and where it begins there, in floats.
    rays: Option<(u32, Arc<GpuRays>, u32)>,
    /// The set before, whose work may still be under way.
    before: Option<Arc<GpuRays>>,
    /// Each target's hits and tests told by earlier reads.
    told: Vec<[u64; 2]>,
}

impl OnGpu {
    /// Nothing on the GPU yet, for `targets` sums.
    pub fn new(targets: usize) -> Self {
        OnGpu { sums: (0..targets).map(|_| None).collect(), rays: None, before: None, told: vec![[0; 2]; targets] }
    }

    /// Submits every target's gatherings not submitted yet (before a window's sums are read
    /// one after another: [`GpuSums::submit_pending`]).
    pub fn submit_all(&mut self) -> Result<()> {
        self.sums.iter_mut().flatten().try_for_each(GpuSums::submit_pending)
    }

    /// A copy of target `target`'s sums after the gatherings recorded so far (one of its pieces
    /// at least), read back with the others ([`OnGpu::read_snapshots`]).
    pub fn snapshot(&mut self, target: usize) -> Result<()> {
        self.sums[target].as_mut().expect("a target gathered into holds its sums").snapshot()
    }

    /// The bytes of every target's snapshots not read yet.
    pub fn snapshot_bytes(&self) -> u64 {
        self.sums.iter().flatten().map(GpuSums::snapshot_bytes).sum()
    }

    /// Target `target`'s snapshots since the last read, in order, each given to `each` as the
    /// pixels' sums on the GPU (f32 bits).
    pub fn read_snapshots(&mut self, target: usize, each: &mut dyn FnMut(&[[u32; 3]])) -> Result<()> {
        self.sums[target].as_mut().map_or(Ok(()), |s| s.read_snapshots(each))
    }

    /// Waits for target `target`'s gatherings, adds its sums on the GPU to `sums` (untouched
    /// where none of its pieces was gathered yet) and returns the hits and the GPU's time of
    /// its gatherings since the last read (so that the reads of a target add up).
    pub fn read_into(&mut self, target: usize, sums: &mut [Vec3]) -> Result<GatherStats> {
        let Some(held) = &mut self.sums[target] else {
            return Ok(GatherStats::default());
        };
        let mut stats = held.read_into(sums)?;
        let told = std::mem::replace(&mut self.told[target], [stats.hits, stats.tests]);
        stats.hits -= told[0];
        stats.tests -= told[1];
        Ok(stats)
    }
}

/// A ray set for the GPU: made on the CPU, written into the buffer that uploads it
/// ([`GpuPlanes::make_rays`]), or its record, for the GPU to make it from
/// ([`GpuPlanes::rays_on_gpu`], side by side with the other sets of a gathering).
pub enum RaySet {
    Made(GpuRays),
    Record(RaySetRecord, Vec<PanelRecord>),
}

/// Makes ray set `k` for the GPU structure given ([`RaySet`]).
pub type RaySetMaker<'m> = &'m mut dyn FnMut(u32, &GpuPlanes) -> Result<RaySet>;

/// A piece's rays: a set made (its buffer, and where it begins there, in floats), or the set
/// of a gathering's records to make.
#[derive(Clone)]
enum Along {
    Made(Arc<GpuRays>, u32),
    Record(usize),
}

/// A gathering's ray sets to make from their records (each with its set, its structure and the
/// target its upload counts to) and pieces to record, not yet done.
#[derive(Default)]
struct Waiting<'p> {
    sets: Vec<(u32, RaySetRecord, Vec<PanelRecord>, &'p GpuPlanes, usize)>,
    pieces: Vec<(&'p GpuPiece<'p>, Along)>,
}

/// [`gather_pieces`] of pieces on the GPU, into sums held there ([`OnGpu`]), a piece's ray set
/// made where it is not the set made last. Along rays made on the GPU, the gathering's sets are
/// made and its pieces recorded side by side (a set's or a piece's recording, buffers and
/// passes, takes a few tenths of a millisecond of the CPU, which the GPU waits for), then
/// added to their sums' work in order; nothing is submitted before the sums are read (a
/// target's gatherings go in one submission with its reading). Along rays made on the CPU,
/// piece after piece, each submitted at once. The hits and the GPU's time are counted when the
/// sums are read back.
pub fn gather_pieces_on_gpu<'p>(
    pieces: &'p [GpuPiece<'p>],
    weighting: Weighting,
    on_gpu: &mut OnGpu,
    make_rays: RaySetMaker,
    control: Control,
) -> Result<Vec<GatherStats>> {
    let mut found = vec![GatherStats::default(); on_gpu.sums.len()];
    let mut waiting = Waiting::default();
    let mut current = on_gpu.rays.as_ref().map(|(set, r, at)| (*set, Along::Made(r.clone(), *at)));
    for p in pieces {
        let g = p.planes.gpu();
        if current.as_ref().is_none_or(|(set, _)| *set != p.set) {
            match make_rays(p.set, g)? {
                RaySet::Record(record, panels) => {
                    // At most PENDING_RAY_BYTES of sets made at once (a large image's).
                    let sets = waiting.sets.len() as u64 + 1;
                    if sets > 1 && sets * g.ray_set_bytes() > gpu::PENDING_RAY_BYTES {
                        record_side_by_side(&mut waiting, weighting, on_gpu, &mut found, control)?;
                    }
                    waiting.sets.push((p.set, record, panels, g, p.target));
                    current = Some((p.set, Along::Record(waiting.sets.len() - 1)));
                }
                RaySet::Made(rays) => {
                    record_side_by_side(&mut waiting, weighting, on_gpu, &mut found, control)?;
                    // The submissions along rays made on the CPU are not waited for, so that the
                    // CPU makes the next set while the GPU gathers; but at most two sets' work is
                    // under way: the one before last is waited for and let go.
                    if let Some(done) = on_gpu.before.take() {
                        found[p.target].wait_ns += done.wait()?;
                    }
                    found[p.target].upload_ns += rays.upload_ns();
                    found[p.target].bytes_crossed += rays.bytes_up();
                    let rays = Arc::new(rays);
                    on_gpu.before = on_gpu.rays.replace((p.set, rays.clone(), 0)).map(|(_, r, _)| r);
                    current = Some((p.set, Along::Made(rays, 0)));
                }
            }
        }
        if on_gpu.sums[p.target].is_none() {
            on_gpu.sums[p.target] = Some(g.new_sums()?);
        }
        let along = current.as_ref().expect("made above").1.clone();
        match along {
            Along::Made(rays, _) if !rays.made_on_gpu() => {
                let sums = on_gpu.sums[p.target].as_mut().expect("made above");
                found[p.target] += g.gather_into(weighting, &rays, sums, control)?;
            }
            along => waiting.pieces.push((p, along)),
        }
    }
    record_side_by_side(&mut waiting, weighting, on_gpu, &mut found, control)?;
    Ok(found)
}

/// Pieces of a gathering recorded together: consecutive pieces of one target along sets of one
/// buffer, or one piece alone.
struct Run {
    target: usize,
    pieces: Vec<usize>,
}

/// The runs of `waiting`'s pieces, in order: consecutive pieces of one target along this
/// gathering's sets of one buffer (`group` of a set's index), or each piece alone where
/// `join` is false (the pieces apart); each piece along a set made before alone.
fn runs(waiting: &Waiting, join: bool, group: impl Fn(usize) -> usize) -> Vec<Run> {
    let mut runs: Vec<Run> = Vec::new();
    let mut last: Option<usize> = None;
    for (k, (p, along)) in waiting.pieces.iter().enumerate() {
        let buffer = match along {
            Along::Record(i) => Some(group(*i)),
            Along::Made(..) => None,
        };
        match runs.last_mut() {
            Some(r) if join && buffer.is_some() && buffer == last && r.target == p.target => r.pieces.push(k),
            _ => runs.push(Run { target: p.target, pieces: vec![k] }),
        }
        last = buffer;
    }
    runs
}

/// The ray sets and pieces `waiting` made and recorded side by side, then the pieces added to
/// their sums' work in their order (each after its rays' pass, the first time), what they
/// found added to `found`; the last set made is kept as the set made last. The gathering's sets
/// are made into as few buffers as hold them ([`GpuRays::sets_fitting`]: one, but for a very
/// large image), each set once; the pieces of a run ([`runs`]) are joined into one structure
/// ([`GpuPlanes::join`]) where the GPU allows it (`FOGPLANES_GPU_PIECES`), so that their work
/// items are gathered in one dispatch a round.
fn record_side_by_side(
    waiting: &mut Waiting,
    weighting: Weighting,
    on_gpu: &mut OnGpu,
    found: &mut [GatherStats],
    control: Control,
) -> Result<()> {
    let Some((first, _)) = waiting.pieces.first() else {
        return Ok(());
    };
    let first = first.planes.gpu();
    let join = first.joins_pieces();
    // Sets a buffer: one each for the pieces apart, as before the join.
    let per = if join { first.ray_sets_fitting().max(1) } else { 1 };
    let sets = &waiting.sets;
    let groups = sets.len().div_ceil(per);
    let made = control.map_units("ray sets", groups, 1, |g| {
        let _s = crate::trace::span("ray set recorded");
        let range = g * per..((g + 1) * per).min(sets.len());
        let records: Vec<(&RaySetRecord, &[PanelRecord])> =
            sets[range.clone()].iter().map(|s| (&s.1, s.2.as_slice())).collect();
        sets[range.start].3.rays_on_gpu(&records).map(Arc::new)
    });
    let made: Vec<Arc<GpuRays>> = made.into_iter().collect::<Result<_>>()?;
    for (g, rays) in made.iter().enumerate() {
        // Counted to the target of the first piece along its first set.
        let target = sets[g * per].4;
        found[target].upload_ns += rays.upload_ns();
        found[target].bytes_crossed += rays.bytes_up();
    }
    // Set i's buffer, and where it begins there.
    let set = |i: usize| -> (Arc<GpuRays>, u32) {
        let rays = made[i / per].clone();
        let at = rays.floats_at((i % per) as u32);
        (rays, at)
    };
    if let Some(last) = sets.len().checked_sub(1) {
        let (rays, at) = set(last);
        on_gpu.rays = Some((sets[last].0, rays, at));
    }
    let runs = runs(waiting, join, |i| i / per);
    let along = |k: usize| -> (Arc<GpuRays>, u32) {
        match &waiting.pieces[k].1 {
            Along::Made(rays, at) => (rays.clone(), *at),
            Along::Record(i) => set(*i),
        }
    };
    let sums = &on_gpu.sums;
    let recorded = control.map_units("record", runs.len(), 1, |r| {
        let run = &runs[r];
        let into = sums[run.target].as_ref().expect("made before the piece waits");
        let parts: Vec<(&GpuPlanes, (Arc<GpuRays>, u32))> =
            run.pieces.iter().map(|&k| (waiting.pieces[k].0.planes.gpu(), along(k))).collect();
        if parts.len() > 1 {
            let joined: Vec<(&GpuPlanes, u32)> = parts.iter().map(|(g, (_, at))| (*g, *at)).collect();
            if let Some(whole) = GpuPlanes::join(&joined)? {
                let rays = parts[0].1.0.clone();
                return Ok(vec![(whole.record(weighting, &rays, 0, into, control)?, rays)]);
            }
        }
        parts
            .into_iter()
            .map(|(g, (rays, at))| Ok((g.record(weighting, &rays, at, into, control)?, rays)))
            .collect::<Result<Vec<_>>>()
    });
    for (run, recorded) in runs.iter().zip(recorded) {
        for (recorded, rays) in recorded? {
            let into = on_gpu.sums[run.target].as_mut().expect("made before the piece waits");
            found[run.target] += into.add(recorded, &rays);
            // Too many ray sets held: every target's work submitted, in order, so that a buffer
            // of sets goes with (or after) the work that makes it, an earlier target's.
            if into.holds_too_many_rays() {
                on_gpu.sums.iter_mut().flatten().for_each(GpuSums::submit_held);
            }
        }
    }
    waiting.sets.clear();
    waiting.pieces.clear();
    Ok(())
}

/// Gathers several pieces of planes, each along its own ray set, adding each ray's estimate of
/// each to `sums[target]`, the pieces of a target in their order: [`PreparedPlanes::gather`] of
/// each piece in turn, the same bits; returns what each target's pieces found. On the raster,
/// one parallel loop over the tiles of every target, each tile taking its target's pieces in
/// turn ([`crate::raster::gather_pieces`]: no barrier between pieces, nor between targets); on
/// the other structures, piece after piece. A piece with a tap also adds what it added to
/// each pixel, `after - before` in f64, to `taps[tap]` (the error image's sums of a group's half,
/// [`crate::spread::GroupSpread::open_group`]), in piece order; a tap takes the pieces of one
/// target. Progress and cancelling as for [`PreparedPlanes::gather`].
pub fn gather_pieces(
    pieces: &[GatherPiece],
    weighting: Weighting,
    kernel: Kernel,
    sums: &mut [&mut [Vec3]],
    taps: &mut [&mut [DVec3]],
    control: Control,
) -> Result<Vec<GatherStats>> {
    // The GPU's pieces go one after another, each in its own submissions and read back (a
    // render keeps a chunk's sums on the GPU instead: [`gather_pieces_on_gpu`]).
    if pieces.iter().any(|p| matches!(p.planes.structure, Structure::Gpu(_))) {
        let mut found = vec![GatherStats::default(); sums.len()];
        for p in pieces {
            let before = p.tap.map(|_| sums[p.target].to_vec());
            found[p.target] += p.planes.gather(weighting, kernel, p.rays, sums[p.target], control)?;
            if let (Some(t), Some(before)) = (p.tap, before) {
                add_difference(taps[t], &before, sums[p.target]);
            }
        }
        return Ok(found);
    }
    struct Run<'a, 'p, 's, 't> {
        pieces: &'p [GatherPiece<'a>],
        kernel: Kernel,
        sums: &'p mut [&'s mut [Vec3]],
        taps: &'p mut [&'t mut [DVec3]],
        control: Control<'p>,
    }
    impl WithDenominator for Run<'_, '_, '_, '_> {
        type Output = Vec<GatherStats>;
        fn run<D: Denominator>(self, weights: &D) -> Vec<GatherStats> {
            let rasters: Option<Vec<RasterPiece>> = self
                .pieces
                .iter()
                .map(|p| {
                    p.planes.raster().map(|raster| RasterPiece {
                        raster,
                        ctx: &p.planes.context,
                        rays: p.rays,
                        target: p.target,
                        tap: p.tap,
                    })
                })
                .collect();
            if let Some(rasters) = rasters {
                return crate::raster::gather_pieces::<D, true>(
                    &rasters,
                    weights,
                    self.kernel,
                    self.sums,
                    self.taps,
                    self.control,
                );
            }
            let mut found = vec![GatherStats::default(); self.sums.len()];
            for p in self.pieces {
                if self.control.is_cancelled() {
                    break;
                }
                // Every piece is the CPU's here: the GPU's were gathered above.
                if let Structure::Cpu(cpu) = &p.planes.structure {
                    let with = Gathering { ctx: &p.planes.context, weights, kernel: self.kernel };
                    let before = p.tap.map(|_| self.sums[p.target].to_vec());
                    found[p.target] += cpu.gather(with, p.rays, self.sums[p.target], self.control);
                    if let (Some(t), Some(before)) = (p.tap, before) {
                        add_difference(self.taps[t], &before, self.sums[p.target]);
                    }
                }
            }
            found
        }
    }
    let found = weighting.dispatch(Run { pieces, kernel, sums, taps, control });
    control.check()?;
    Ok(found)
}

/// Adds `after - before` to `tap`, pixel by pixel, in f64 (as the raster's tiles add it).
fn add_difference(tap: &mut [DVec3], before: &[Vec3], after: &[Vec3]) {
    for ((t, b), a) in tap.iter_mut().zip(before).zip(after) {
        *t += a.as_dvec3() - b.as_dvec3();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::BAND_ROWS;
    use crate::sampling::Sampler;
    use crate::weights::{HitLanes, PlaneFrame, Unweighted};
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

    fn small_scene() -> Scene {
        Scene::parse(crate::scene::tests::MINIMAL, "test.toml", "test").unwrap().with_resolution(128, 96).unwrap()
    }

    /// The unweighted D, counting the blocks of hits it weighs (a block of up to 16 pixels on
    /// the raster, one hit on the per-ray paths) and setting `cancel` when the count reaches
    /// `after`: a flag set in the middle of a plane's work, where no progress is reported.
    struct CancelAfter<'a> {
        weighed: AtomicUsize,
        after: usize,
        cancel: &'a AtomicBool,
    }

    impl Denominator for CancelAfter<'_> {
        type Plane = PlaneFrame;
        fn prepare(&self, f: &PlaneFrame) -> PlaneFrame {
            *f
        }
        fn denominators<const L: usize>(&self, p: &PlaneFrame, h: &HitLanes<L>, out: &mut [f32; L]) {
            if self.weighed.fetch_add(1, Ordering::Relaxed) + 1 == self.after {
                self.cancel.store(true, Ordering::Relaxed);
            }
            Unweighted.denominators(p, h, out)
        }
    }

    /// A piece's tap holds what the piece added to each pixel, `after - before` of its target's
    /// sums as a gathering of the pieces one by one leaves them, and the taps change nothing of
    /// the sums: two pieces along two ray sets into one target, each with its tap, and a third
    /// into another target, on every CPU structure (the raster's tiles and the others' copies),
    /// on 64 workers (the raster's heavy tiles cut into parts, each with its rows of the taps).
    #[test]
    fn a_pieces_tap_holds_its_own_sums() {
        rayon::ThreadPoolBuilder::new().num_threads(64).build().unwrap().install(a_pieces_tap_holds_its_own_sums_here);
    }

    fn a_pieces_tap_holds_its_own_sums_here() {
        let scene = small_scene();
        let sets = [0, 1, 0].map(|k| crate::pixel::ray_set_rays(&scene, 2, k, false));
        let pixels = sets[0].len();
        for accelerator in Accelerator::ALL {
            let set = PlaneSet::new(Sampler::default(), 3);
            let prepared: Vec<PreparedPlanes> = [0..700, 700..1500, 1500..1900]
                .into_iter()
                .map(|r| PreparedPlanes::new(&scene, set, r, accelerator, Control::none()).unwrap())
                .collect();
            let (targets, taps_of) = ([0, 0, 1], [Some(0), Some(1), Some(2)]);
            // One by one, each piece's sums before and after.
            let mut alone = vec![vec![Vec3::ZERO; pixels]; 2];
            let mut expected = vec![vec![DVec3::ZERO; pixels]; 3];
            for (i, p) in prepared.iter().enumerate() {
                let before = alone[targets[i]].clone();
                p.gather(Weighting::default(), Kernel::Portable, &sets[i], &mut alone[targets[i]], Control::none())
                    .unwrap();
                add_difference(&mut expected[i], &before, &alone[targets[i]]);
            }
            let pieces: Vec<GatherPiece> = (0..3)
                .map(|i| GatherPiece { planes: &prepared[i], rays: &sets[i], target: targets[i], tap: taps_of[i] })
                .collect();
            let mut sums = vec![vec![Vec3::ZERO; pixels]; 2];
            let mut taps = vec![vec![DVec3::ZERO; pixels]; 3];
            {
                let mut sums: Vec<&mut [Vec3]> = sums.iter_mut().map(|s| s.as_mut_slice()).collect();
                let mut taps: Vec<&mut [DVec3]> = taps.iter_mut().map(|t| t.as_mut_slice()).collect();
                gather_pieces(&pieces, Weighting::default(), Kernel::Portable, &mut sums, &mut taps, Control::none())
                    .unwrap();
            }
            assert_eq!(sums, alone, "{accelerator}: the sums as without taps");
            assert_eq!(taps, expected, "{accelerator}: each tap its piece's sums");
            assert!(taps.iter().all(|t| t.iter().any(|v| v.max_element() > 0.0)), "{accelerator}: every piece adds");
        }
    }

    /// Cancelled in the middle of a plane, the raster stops before the next plane: each thread
    /// weighs at most the rest of the plane under way in its tile, with every kernel. The
    /// per-ray paths stop before the next ray: each thread finishes at most the hits of its ray
    /// under way. Counted in blocks weighed, out of the thousands a whole pass weighs.
    #[test]
    fn cancelling_stops_gathering_within_a_plane_or_a_ray() {
        let scene = small_scene();
        let rays = crate::pixel::ray_set_rays(&scene, 1, 0, false);
        let (planes, after, threads) = (3000, 20, 2);
        // The most blocks one plane has in one tile: every half block of every row.
        let band_blocks = (BAND_ROWS * scene.camera.width.div_ceil(crate::kernel::HALF_LANES as u32)) as usize;
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        for accelerator in Accelerator::ALL {
            let set = PlaneSet::new(Sampler::default(), 1);
            let prepared = PreparedPlanes::new(&scene, set, 0..planes, accelerator, Control::none()).unwrap();
            let kernels = if accelerator == Accelerator::Raster { Kernel::available() } else { vec![Kernel::Portable] };
            for kernel in kernels {
                let run = |after: usize| {
                    let cancel = AtomicBool::new(false);
                    let weights = CancelAfter { weighed: AtomicUsize::new(0), after, cancel: &cancel };
                    let mut sums = vec![Vec3::ZERO; rays.len()];
                    let with = Gathering { ctx: &prepared.context, weights: &weights, kernel };
                    let Structure::Cpu(structure) = &prepared.structure else { panic!("a CPU structure") };
                    let stats =
                        pool.install(|| structure.gather(with, &rays, &mut sums, Control::with_cancel(&cancel)));
                    (weights.weighed.into_inner(), stats, cancel.into_inner())
                };
                let (whole, whole_stats, set) = run(usize::MAX);
                assert!(!set && whole > 100 * after, "{accelerator} {kernel}: {whole} blocks weighed in a pass");
                let (done, stats, set) = run(after);
                assert!(set);
                let bound = match accelerator {
                    Accelerator::Raster => after + threads * band_blocks,
                    _ => after + threads * planes,
                };
                assert!(done <= bound, "{accelerator} {kernel}: {done} blocks weighed, at most {bound} expected");
                // On the raster the ray-plane tests follow the planes (the per-ray paths test
                // every plane of a ray whether it hits or not).
                if accelerator == Accelerator::Raster {
                    assert!(stats.tests < whole_stats.tests / 20, "{kernel}: {stats:?} of {whole_stats:?}");
                }
            }
        }
    }
}
