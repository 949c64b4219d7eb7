//! The photon-plane renderer: camera rays, direct emission, planes, gathering.
//!
//! A render is three steps: sample the planes and build the intersection structure
//! ([`PreparedPlanes`]), make the camera rays of a ray set ([`crate::pixel::ray_set_rays`]), and gather them
//! with one weighting ([`PreparedPlanes::gather`]); each group of planes goes with its own ray
//! set, and the direct emission is integrated over the pixel apart ([`crate::pixel`],
//! [`crate::emission`]). The table reuses the steps through [`crate::pixel::PreparedPixels`].

use crate::bvh::PlaneBvh;
use crate::control::Control;
use crate::error::Setting;
use crate::error::{Error, Result};
use crate::film::Film;
use crate::gather::GatherStats;
use crate::gather::{CameraRay, GatherContext};
use crate::kernel::Kernel;
use crate::limits::{check_memory, check_planes, check_spp};
use crate::photon_plane::sample_plane_range;
use crate::pixel::{RaySets, plane_group};
use crate::raster::{Gathering, ScreenRaster};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::weights::{Denominator, Weighting, WithDenominator};
use glam::Vec3;
use rayon::prelude::*;
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
}

impl Accelerator {
    pub const ALL: [Accelerator; 3] = [Accelerator::Raster, Accelerator::Bvh, Accelerator::BruteForce];

    pub fn name(self) -> &'static str {
        match self {
            Accelerator::Raster => "raster",
            Accelerator::Bvh => "bvh",
            Accelerator::BruteForce => "brute-force",
        }
    }
}

impl std::fmt::Display for Accelerator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Accelerator {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        crate::parse_name("accelerator", s, &Accelerator::ALL, Accelerator::name)
    }
}

/// Planes made in pieces of this many, so that the sampled planes never all exist at once:
/// only their prepared views and screen polygons are kept.
const PLANE_CHUNK: usize = 16_384;

/// Planes sampled and prepared for gathering from the camera.
pub struct PreparedPlanes {
    pub context: GatherContext,
    pub raster: Option<ScreenRaster>,
    pub bvh: Option<PlaneBvh>,
    pub accelerator: Accelerator,
    /// Seconds spent sampling planes and building the structure.
    pub seconds_sampling: f64,
    pub seconds_build: f64,
}

impl PreparedPlanes {
    /// The first `planes` planes of the set made with `seed` and `sampler`.
    pub fn new(
        scene: &Scene,
        planes: usize,
        seed: u64,
        sampler: Sampler,
        accelerator: Accelerator,
        control: Control,
    ) -> Result<Self> {
        PreparedPlanes::range(scene, 0..planes, planes, seed, sampler, accelerator, control)
    }

    /// Planes `range` of the set, each weighted as one of `planes_total` (1 leaves the
    /// division by N to the caller, as passes that extend a set do). [`Error::Cancelled`] once
    /// `control` is cancelled (checked after each piece of [`PLANE_CHUNK`] planes).
    pub fn range(
        scene: &Scene,
        range: std::ops::Range<usize>,
        planes_total: usize,
        seed: u64,
        sampler: Sampler,
        accelerator: Accelerator,
        control: Control,
    ) -> Result<Self> {
        let (mut seconds_sampling, mut seconds_build) = (0.0, 0.0);
        let origin = scene.camera.position;
        let mut context = GatherContext::empty(scene, origin);
        let mut raster = (accelerator == Accelerator::Raster).then(|| ScreenRaster::empty(&scene.camera));
        // The BVH is built over the whole set at once; it keeps the planes while it does.
        let mut all = Vec::new();
        for start in range.clone().step_by(PLANE_CHUNK) {
            control.check()?;
            let t = Instant::now();
            let chunk = sample_plane_range(scene, sampler, seed, start..(start + PLANE_CHUNK).min(range.end));
            seconds_sampling += t.elapsed().as_secs_f64();
            let t = Instant::now();
            context.push_planes(scene, &chunk, planes_total);
            if let Some(r) = &mut raster {
                r.push_planes(&scene.camera, &chunk, &scene.medium);
            }
            seconds_build += t.elapsed().as_secs_f64();
            if accelerator == Accelerator::Bvh {
                all.extend(chunk);
            }
        }
        control.check()?;
        let t = Instant::now();
        let bvh = match accelerator {
            Accelerator::Bvh => Some(PlaneBvh::build(&all, &scene.medium, origin, control)?),
            _ => None,
        };
        seconds_build += t.elapsed().as_secs_f64();
        Ok(PreparedPlanes { context, raster, bvh, accelerator, seconds_sampling, seconds_build })
    }

    /// Gathers the rays of one pass with `weighting`, adding each ray's estimate to `sums`;
    /// the raster runs `kernel` (resolved, see [`Kernel::resolve`]). Reports each band of rows
    /// (or chunk of rays) to `control`; once it is cancelled, the work stops before the next
    /// plane (or ray) and the result is [`Error::Cancelled`], with `sums` incomplete.
    pub fn gather(
        &self,
        weighting: Weighting,
        kernel: Kernel,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        control: Control,
    ) -> Result<GatherStats> {
        struct Gather<'a> {
            planes: &'a PreparedPlanes,
            kernel: Kernel,
            rays: &'a [CameraRay],
            sums: &'a mut [Vec3],
            control: Control<'a>,
        }
        impl WithDenominator for Gather<'_> {
            type Output = GatherStats;
            fn run<D: Denominator>(self, weights: &D) -> GatherStats {
                let with = Gathering { ctx: &self.planes.context, weights, kernel: self.kernel };
                self.planes.gather_with(with, self.rays, self.sums, self.control)
            }
        }
        let stats = weighting.dispatch(Gather { planes: self, kernel, rays, sums, control });
        control.check()?;
        Ok(stats)
    }

    /// [`PreparedPlanes::gather`] with the weights chosen (`with.kernel` serves the raster).
    fn gather_with<D: Denominator>(
        &self,
        with: Gathering<D>,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        control: Control,
    ) -> GatherStats {
        if let Some(raster) = &self.raster {
            return raster.gather(with, rays, sums, control);
        }
        let Gathering { ctx, weights, .. } = with;
        // Per-ray structures: chunks of rays in parallel, one progress unit per chunk, the
        // cancel flag read before each ray (against every plane, a brute-force ray is the
        // longest unit of work: milliseconds at a million planes).
        sums.par_chunks_mut(RAY_CHUNK)
            .zip(rays.par_chunks(RAY_CHUNK))
            .map(|(sums, rays)| {
                let mut stats = GatherStats::default();
                for (sum, ray) in sums.iter_mut().zip(rays) {
                    if control.is_cancelled() {
                        return stats;
                    }
                    let (value, s) = match &self.bvh {
                        Some(bvh) => bvh.gather(ctx, weights, ray),
                        None => {
                            let (v, hits) = ctx.gather_brute_force(weights, ray);
                            (v, GatherStats { tests: ctx.views.len() as u64, hits })
                        }
                    };
                    *sum += value;
                    stats += s;
                }
                control.progress();
                stats
            })
            .reduce(GatherStats::default, |mut a, b| {
                a += b;
                a
            })
    }
}

/// Rays per parallel work item for the per-ray accelerators.
const RAY_CHUNK: usize = 4096;

/// Settings of one render. `RenderOptions::default()` is the paper's setting (40,960 planes,
/// smis-exact with the perpendicular pair, one jittered sample per pixel);
/// [`RenderOptions::from_scene`] takes the scene file's `[render]` table.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    pub planes: usize,
    pub weighting: Weighting,
    pub seed: u64,
    /// Where the planes' random numbers come from.
    pub sampler: Sampler,
    /// Camera samples per pixel: ray sets, each gathering its own share of the planes
    /// (docs/mathematics.md section 8.1), so that more cost about as much as one.
    pub spp: u32,
    pub pixel_center: bool,
    pub accelerator: Accelerator,
    pub kernel: Kernel,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            planes: 40_960,
            weighting: Weighting::default(),
            seed: 1,
            sampler: Sampler::default(),
            spp: crate::pixel::DEFAULT_RAY_SETS,
            pixel_center: false,
            accelerator: Accelerator::Raster,
            kernel: Kernel::Auto,
        }
    }
}

impl RenderOptions {
    /// Ray sets per pixel: `spp`, or one at pixel centres (where every set would be the same
    /// rays).
    pub fn ray_sets(&self) -> u32 {
        if self.pixel_center { 1 } else { self.spp.max(1) }
    }

    /// The scene file's defaults.
    pub fn from_scene(scene: &Scene) -> Self {
        let d = &scene.render;
        RenderOptions {
            planes: d.planes as usize,
            weighting: d.weighting,
            seed: d.seed,
            sampler: d.sampler,
            spp: d.spp,
            ..RenderOptions::default()
        }
    }

    /// Checks every setting against the scene (the memory budget at its resolution) and the
    /// CPU (the kernel), naming the option at fault.
    pub fn validate(&self, scene: &Scene) -> Result<()> {
        check_planes(self.planes as u64).map_err(|m| Error::option(Setting::Planes, m))?;
        check_spp(self.spp).map_err(|m| Error::option(Setting::Spp, m))?;
        Weighting::new(self.weighting.estimator, Some(self.weighting.orientations))
            .map_err(|m| Error::option(Setting::Orientations, m))?;
        // One chunk of planes is held at a time ([`crate::partial`]).
        let held = self.planes.min(crate::partial::CHUNK_PLANES) as u64;
        check_memory(scene.camera.width, scene.camera.height, held)
            .map_err(|m| Error::option(Setting::Resolution, m))?;
        self.kernel.resolve()?;
        Ok(())
    }
}

/// What a render measured (wall-clock seconds; CPU time and memory are the caller's to read).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct RenderStats {
    pub estimator: String,
    /// The kernel that ran (`auto` resolved).
    pub kernel: String,
    pub planes: usize,
    /// Plane passes: 1, or more for a render on a time budget ([`render_for`]).
    pub plane_passes: u32,
    pub rays: u64,
    pub hits: u64,
    pub tests: u64,
    pub seconds_sampling: f64,
    pub seconds_build: f64,
    pub seconds_rays: f64,
    pub seconds_gather: f64,
    pub seconds_total: f64,
}

impl RenderStats {
    /// Counts one gathering of `planes` that found `s` in `seconds`.
    pub fn add_gather(&mut self, planes: &PreparedPlanes, s: GatherStats, seconds: f64) {
        self.seconds_gather += seconds;
        self.seconds_sampling += planes.seconds_sampling;
        self.seconds_build += planes.seconds_build;
        self.hits += s.hits;
        self.tests += s.tests;
    }

    pub fn hits_per_ray(&self) -> f64 {
        self.hits as f64 / self.rays.max(1) as f64
    }
    pub fn tests_per_hit(&self) -> f64 {
        self.tests as f64 / self.hits.max(1) as f64
    }
    /// Nanoseconds of wall time in gathering per hit.
    pub fn gather_ns_per_hit(&self) -> f64 {
        1e9 * self.seconds_gather / self.hits.max(1) as f64
    }
    pub fn summary(&self) -> String {
        format!(
            "{}: {} planes, {} rays, {} hits ({:.0} per ray, {:.2} tests per hit), gather {:.3} s ({:.2} ns/hit wall, {} kernel), total {:.3} s",
            self.estimator,
            self.planes,
            self.rays,
            self.hits,
            self.hits_per_ray(),
            self.tests_per_hit(),
            self.seconds_gather,
            self.gather_ns_per_hit(),
            self.kernel,
            self.seconds_total
        )
    }
}

/// Number of progress units in one pass (for sizing a progress bar).
pub fn progress_units_per_pass(scene: &Scene, accelerator: Accelerator) -> u64 {
    let pixels = scene.camera.width as u64 * scene.camera.height as u64;
    match accelerator {
        Accelerator::Raster => scene.camera.height.div_ceil(crate::raster::BAND_ROWS) as u64,
        _ => pixels.div_ceil(RAY_CHUNK as u64),
    }
}

/// Renders the scene: the mean over each pixel of the direct emission (integrated over the
/// pixel, [`crate::emission`]) plus the photon-plane estimate of single scattering, each plane
/// gathered with one of the `spp` ray sets (docs/mathematics.md section 8). Checks the options
/// first ([`RenderOptions::validate`]). Reports each band of rows (or chunk of rays) to
/// `control`; once another thread cancels it, the work stops within a plane (or a ray) and the
/// result is [`Error::Cancelled`].
///
/// The planes are rendered in the canonical chunks of [`crate::partial`] and added along its
/// canonical tree, so that the same chunks rendered anywhere and merged give this image bit for
/// bit; only one chunk's planes exist at a time.
pub fn render(scene: &Scene, opts: &RenderOptions, control: Control) -> Result<(Film, RenderStats)> {
    let start = Instant::now();
    let mut chunks = crate::partial::ChunkRenderer::new(scene, opts, control)?;
    let partial = chunks.render(0..opts.planes)?;
    let mut stats = chunks.stats;
    let t = Instant::now();
    let film = crate::partial::finish(scene, opts, &partial)?;
    stats.seconds_rays += t.elapsed().as_secs_f64();
    stats.seconds_total = start.elapsed().as_secs_f64();
    Ok((film, stats))
}

/// Progress units of a render of planes `range` (a union of chunks; `0..opts.planes` for a
/// whole [`render`]): [`progress_units_per_pass`] for every gathering over the image, one per
/// piece of every chunk ([`crate::partial::gatherings`]).
pub fn progress_units(scene: &Scene, opts: &RenderOptions, range: std::ops::Range<usize>) -> u64 {
    progress_units_per_pass(scene, opts.accelerator) * crate::partial::gatherings(opts.planes, opts.ray_sets(), range)
}

/// The first pass of a render on a time budget, small so that even the slowest estimator
/// measures its speed early; each further pass doubles the plane count (the passes before
/// the last keep the Sobol sampler's counts at powers of two) until the budget runs short, and
/// the last is sized from the measured time per plane.
const FIRST_PASS_PLANES: usize = 256;

/// Renders the scene within `budget` of wall time: planes in passes, each extending the plane
/// set by the next points of the sampler (for Sobol, further points of the same sequence), until
/// the next pass would not fit; the last pass is sized from the measured time per plane to use
/// what remains. The image is the estimate of the N planes gathered, N = the total over passes:
/// the same planes as a render of N planes; each pass splits its planes among the `opts.spp` ray
/// sets (fewer for small passes, taken in turn), so every plane is still gathered with a ray set
/// uniform over the pixel, and the estimate is unbiased (docs/mathematics.md section 8.1).
/// `opts.planes` is ignored. Returns as soon as
/// `budget` would be exceeded by more work; the caller's own time (loading, writing) is not in
/// it. `control` as for [`render`]: cancelled, it stops mid-pass.
pub fn render_for(
    scene: &Scene,
    opts: &RenderOptions,
    budget: std::time::Duration,
    control: Control,
) -> Result<(Film, RenderStats)> {
    let start = Instant::now();
    let deadline = budget.as_secs_f64();
    render_in_passes(scene, opts, control, &mut |done, seconds_per_plane| {
        if done == 0 {
            return FIRST_PASS_PLANES;
        }
        // A pass's cost is close to proportional to its planes; keep a tenth in hand.
        let remaining = deadline - start.elapsed().as_secs_f64();
        let affordable = (0.9 * remaining / seconds_per_plane.max(1e-12)).floor().max(0.0) as usize;
        let next = affordable.min(done).min(MAX_PASS_PLANES);
        if next < FIRST_PASS_PLANES / 4 { 0 } else { next }
    })
}

/// The fewest planes a pass of a render on a time budget gives each ray set it gathers with:
/// smaller passes use fewer ray sets.
const MIN_PASS_GROUP: usize = 1024;

/// The largest pass of a render on a time budget (a pass's planes are held at once; this keeps
/// them near 0.5 GB whatever the budget).
const MAX_PASS_PLANES: usize = 1 << 20;

/// Renders planes in passes, each extending the set by the next planes of the sampler:
/// `next_pass(planes so far, seconds per plane of the last pass)` sizes the next pass, 0 ends
/// the render. The image is the estimate of all the planes gathered, the same set as a render
/// of that many planes (with one pass of at least 1024 planes per ray set, the same image up to
/// f32 summation order). The ray sets are made when first needed and kept. `opts.planes` is
/// ignored. `control` as for [`render`]: cancelled, it stops mid-pass (while sampling or
/// gathering) and no further pass starts.
pub fn render_in_passes(
    scene: &Scene,
    opts: &RenderOptions,
    control: Control,
    next_pass: &mut dyn FnMut(usize, f64) -> usize,
) -> Result<(Film, RenderStats)> {
    RenderOptions { planes: FIRST_PASS_PLANES, ..opts.clone() }.validate(scene)?;
    let kernel = opts.kernel.resolve()?;
    let start = Instant::now();
    let (width, height) = (scene.camera.width, scene.camera.height);
    let ray_sets = opts.ray_sets();
    // The ray sets are kept for every pass: their memory counts as that many planes'.
    let rays_as_planes = RaySets::bytes(width, height, ray_sets) / crate::limits::BYTES_PER_PLANE;
    check_memory(width, height, rays_as_planes).map_err(|m| Error::option(Setting::Spp, m))?;
    let mut sets = RaySets::empty(opts.seed, ray_sets, opts.pixel_center);
    let pixels = width as usize * height as usize;
    let mut stats = RenderStats { estimator: opts.weighting.label(), kernel: kernel.to_string(), ..Default::default() };
    // Each pass sums its planes in f32 weighted 1 (not 1/N, which is known only at the end);
    // the passes add up in f64, so that the sums stay as far from f32 overflow as a single
    // pass's.
    let mut total = vec![glam::DVec3::ZERO; pixels];
    let (mut done, mut per_plane, mut next_set) = (0usize, 0.0, 0u32);
    loop {
        control.check()?;
        let next = next_pass(done, per_plane).min(crate::limits::MAX_PLANES as usize - done);
        if next == 0 {
            break;
        }
        check_memory(width, height, next as u64 + rays_as_planes).map_err(|m| Error::option(Setting::TimeBudget, m))?;
        let pass_start = Instant::now();
        // The pass's planes split into groups, each gathered along the next ray set in turn
        // (section 8.1): as many groups as ray sets once a pass has MIN_PASS_GROUP planes per
        // set, fewer before (a gather costs something per pixel). Weighted as one of 1, the
        // division by the final count comes at the end.
        let used = (next / MIN_PASS_GROUP).clamp(1, ray_sets as usize) as u32;
        let mut sums = vec![Vec3::ZERO; pixels];
        for g in 0..used {
            let group = plane_group(g, next, used);
            let range = done + group.start..done + group.end;
            let prepared = PreparedPlanes::range(scene, range, 1, opts.seed, opts.sampler, opts.accelerator, control)?;
            let rays = sets.rays(scene, (next_set + g) % ray_sets);
            let t = Instant::now();
            let s = prepared.gather(opts.weighting, kernel, rays, &mut sums, control)?;
            stats.add_gather(&prepared, s, t.elapsed().as_secs_f64());
        }
        next_set = (next_set + used) % ray_sets;
        for (t, s) in total.iter_mut().zip(&sums) {
            *t += s.as_dvec3();
        }
        stats.plane_passes += 1;
        done += next;
        per_plane = pass_start.elapsed().as_secs_f64() / next as f64;
    }
    if done == 0 {
        return Err(Error::option(Setting::TimeBudget, "no plane pass was made"));
    }
    (stats.rays, stats.seconds_rays) = (sets.count(), sets.seconds);
    let t = Instant::now();
    let emission = crate::emission::direct_emission(scene, opts.seed, opts.spp, opts.pixel_center);
    stats.seconds_rays += t.elapsed().as_secs_f64();
    let mut film = Film::new(width, height);
    let inv = 1.0 / done as f64;
    for ((f, s), e) in film.pixels.iter_mut().zip(&total).zip(&emission) {
        *f = (*s * inv).as_vec3() + *e;
    }
    stats.planes = done;
    stats.seconds_total = start.elapsed().as_secs_f64();
    Ok((film, stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::weights::{HitLanes, PlaneFrame, Unweighted};
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

    fn small_scene() -> Scene {
        Scene::parse(crate::scene::tests::MINIMAL, "test.toml", "test").unwrap().with_resolution(128, 96).unwrap()
    }

    #[test]
    fn cancelling_stops_a_render_after_the_work_under_way() {
        let scene = small_scene();
        let opts = RenderOptions { planes: 3000, spp: 3, ..RenderOptions::default() };
        // Never set: the same image as without a flag.
        let (a, _) = render(&scene, &opts, Control::none()).unwrap();
        let (b, _) = render(&scene, &opts, Control::with_cancel(&AtomicBool::new(false))).unwrap();
        assert_eq!(a, b);
        // Set before: nothing runs.
        let e = render(&scene, &opts, Control::with_cancel(&AtomicBool::new(true))).unwrap_err();
        assert!(matches!(e, Error::Cancelled) && !e.is_input(), "{e}");
        // Set when the first band (or chunk of rays) ends: the other thread's stops within a
        // plane (or a ray), and no further unit starts.
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        for accelerator in Accelerator::ALL {
            let opts = RenderOptions { accelerator, ..opts.clone() };
            let (cancel, units) = (AtomicBool::new(false), AtomicUsize::new(0));
            let progress = || {
                units.fetch_add(1, Ordering::Relaxed);
                cancel.store(true, Ordering::Relaxed);
            };
            let e = pool.install(|| render(&scene, &opts, Control::new(&progress, &cancel))).unwrap_err();
            assert!(matches!(e, Error::Cancelled));
            let per_pass = progress_units_per_pass(&scene, accelerator) as usize;
            assert!(per_pass >= 3, "{accelerator}: {per_pass} units a pass");
            assert!(
                units.load(Ordering::Relaxed) <= 2,
                "{accelerator}: {} of {per_pass} units ran",
                units.into_inner()
            );
        }
    }

    /// The unweighted D, counting the planes prepared (once per plane and band on the raster,
    /// once per hit on the per-ray paths) and setting `cancel` when the count reaches `after`:
    /// a flag set in the middle of a band, where no progress is reported.
    struct CancelAfter<'a> {
        prepared: AtomicUsize,
        after: usize,
        cancel: &'a AtomicBool,
    }

    impl Denominator for CancelAfter<'_> {
        type Plane = PlaneFrame;
        fn prepare(&self, f: &PlaneFrame) -> PlaneFrame {
            if self.prepared.fetch_add(1, Ordering::Relaxed) + 1 == self.after {
                self.cancel.store(true, Ordering::Relaxed);
            }
            *f
        }
        fn denominators<const L: usize>(&self, p: &PlaneFrame, h: &HitLanes<L>, out: &mut [f32; L]) {
            Unweighted.denominators(p, h, out)
        }
    }

    /// Cancelled in the middle of a band, the raster stops before the next plane: each thread
    /// prepares at most one plane after the flag is set, with every kernel. The per-ray paths
    /// stop before the next ray: each thread finishes at most the hits of its ray under way.
    /// Counted in planes prepared, out of the millions a whole pass prepares.
    #[test]
    fn cancelling_stops_gathering_within_a_plane_or_a_ray() {
        let scene = small_scene();
        let rays = crate::pixel::ray_set_rays(&scene, 1, 0, false);
        let (planes, after, threads) = (3000, 20, 2);
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        for accelerator in Accelerator::ALL {
            let prepared =
                PreparedPlanes::new(&scene, planes, 1, Sampler::default(), accelerator, Control::none()).unwrap();
            let kernels = if accelerator == Accelerator::Raster { Kernel::available() } else { vec![Kernel::Portable] };
            for kernel in kernels {
                let run = |after: usize| {
                    let cancel = AtomicBool::new(false);
                    let weights = CancelAfter { prepared: AtomicUsize::new(0), after, cancel: &cancel };
                    let mut sums = vec![Vec3::ZERO; rays.len()];
                    let with = Gathering { ctx: &prepared.context, weights: &weights, kernel };
                    let stats =
                        pool.install(|| prepared.gather_with(with, &rays, &mut sums, Control::with_cancel(&cancel)));
                    (weights.prepared.into_inner(), stats, cancel.into_inner())
                };
                let (whole, whole_stats, set) = run(usize::MAX);
                assert!(!set && whole > 100 * after, "{accelerator} {kernel}: {whole} planes prepared in a pass");
                let (done, stats, set) = run(after);
                assert!(set);
                let bound = match accelerator {
                    Accelerator::Raster => after + (threads - 1),
                    _ => after + threads * planes,
                };
                assert!(done <= bound, "{accelerator} {kernel}: {done} planes prepared, at most {bound} expected");
                // On the raster the ray-plane tests follow the planes (the per-ray paths test
                // every plane of a ray whether it hits or not).
                if accelerator == Accelerator::Raster {
                    assert!(stats.tests < whole_stats.tests / 20, "{kernel}: {stats:?} of {whole_stats:?}");
                }
            }
        }
    }

    /// A render in passes, and so a render on a time budget, stops in the middle of a pass.
    #[test]
    fn cancelling_stops_a_render_in_passes_mid_pass() {
        let scene = small_scene();
        let opts = RenderOptions::default();
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let (cancel, units) = (AtomicBool::new(false), AtomicUsize::new(0));
        let progress = || {
            units.fetch_add(1, Ordering::Relaxed);
            cancel.store(true, Ordering::Relaxed);
        };
        let control = Control::new(&progress, &cancel);
        // Passes of 4096 planes, each of 12 bands: set after the first band of the first pass.
        let mut passes = 0;
        let mut next = |_: usize, _: f64| {
            passes += 1;
            4096
        };
        let e = pool.install(|| render_in_passes(&scene, &opts, control, &mut next)).unwrap_err();
        assert!(matches!(e, Error::Cancelled), "{e}");
        assert_eq!((passes, units.load(Ordering::Relaxed)), (1, 1));
        // Set between passes: the next pass gathers nothing.
        let (cancel, units) = (AtomicBool::new(false), AtomicUsize::new(0));
        let count = || {
            units.fetch_add(1, Ordering::Relaxed);
        };
        let mut next = |done: usize, _: f64| {
            if done > 0 {
                cancel.store(true, Ordering::Relaxed);
            }
            256
        };
        let e = render_in_passes(&scene, &opts, Control::new(&count, &cancel), &mut next).unwrap_err();
        assert!(matches!(e, Error::Cancelled));
        assert_eq!(units.into_inner() as u64, progress_units_per_pass(&scene, Accelerator::Raster));
        // On a budget of an hour: the first band ends it.
        let (cancel, units) = (AtomicBool::new(false), AtomicUsize::new(0));
        let progress = || {
            units.fetch_add(1, Ordering::Relaxed);
            cancel.store(true, Ordering::Relaxed);
        };
        let control = Control::new(&progress, &cancel);
        let hour = std::time::Duration::from_secs(3600);
        let e = pool.install(|| render_for(&scene, &opts, hour, control)).unwrap_err();
        assert!(matches!(e, Error::Cancelled) && units.into_inner() == 1, "{e}");
    }
}
