//! The photon-plane renderer: camera rays, direct emission, planes, gathering.
//!
//! A render is three steps that the table command reuses separately: sample the planes and
//! build the intersection structure once ([`PreparedPlanes`]), make the camera rays of a pass
//! ([`camera_rays`]), and gather them with one weighting ([`PreparedPlanes::gather`]).

use crate::bvh::PlaneBvh;
use crate::film::Film;
use crate::gather::{CameraRay, GatherContext};
use crate::photon_plane::sample_plane_range;
use crate::raster::{GatherStats, ScreenRaster};
use crate::sampling::pixel_jitter;
use crate::scene::Scene;
use crate::weights::{
    CmisCosine, CmisExact, Denominator, Estimator, SmisCosinePair, SmisExactPair, StratifiedK, Unweighted, Weighting,
};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// Memory refused up front: a render that would need more than this is an input error.
pub const MEMORY_BUDGET_BYTES: u64 = 16 << 30;
/// Bytes per plane held while rendering (sampled plane, prepared view, screen polygon, bins).
pub const BYTES_PER_PLANE: u64 = 512;
/// Bytes per pixel held while rendering (rays, sums, emission, film).
pub const BYTES_PER_PIXEL: u64 = 96;

/// Refuses, with the figure, a render that would exhaust memory.
pub fn check_memory(width: u32, height: u32, planes: u64) -> Result<(), String> {
    let bytes = planes
        .saturating_mul(BYTES_PER_PLANE)
        .saturating_add((width as u64 * height as u64).saturating_mul(BYTES_PER_PIXEL));
    if bytes > MEMORY_BUDGET_BYTES {
        return Err(format!(
            "{width}x{height} pixels with {planes} planes would need about {:.1} GiB; the limit is {} GiB",
            bytes as f64 / (1u64 << 30) as f64,
            MEMORY_BUDGET_BYTES >> 30
        ));
    }
    Ok(())
}

/// How camera rays find the planes they hit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Accelerator {
    /// Planes rasterised in screen space (the fast path).
    #[default]
    Raster,
    /// A bounding volume hierarchy over the planes, traversed per ray.
    Bvh,
    /// Every ray tests every plane (for checking the others).
    BruteForce,
}

/// Camera rays of one pass with the emission seen directly along them.
pub struct PassRays {
    pub rays: Vec<CameraRay>,
    pub emission: Vec<Vec3>,
}

/// The rays of pass `pass`: one per pixel, jittered over the pixel from (seed, pass, pixel), or
/// through pixel centres. Along each, the segment inside the medium before the first light
/// panel, and the attenuated emission of that panel when its front faces the camera.
pub fn camera_rays(scene: &Scene, seed: u64, pass: u32, pixel_center: bool) -> PassRays {
    let cam = &scene.camera;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let (rays, emission): (Vec<CameraRay>, Vec<Vec3>) = (0..w * h)
        .into_par_iter()
        .map(|k| {
            let (i, j) = ((k % w) as f64, (k / w) as f64);
            let (sx, sy) = if pixel_center { (0.5, 0.5) } else { pixel_jitter(seed, pass, k as u64) };
            let we = cam.direction(i + sx, j + sy).normalize();
            let (segment, emitted) = scene.camera_segment(cam.position, we);
            let ray = match segment {
                Some((t0, t1)) => CameraRay { dir: we.as_vec3(), t0: t0 as f32, t1: t1 as f32 },
                None => CameraRay { dir: we.as_vec3(), t0: 1.0, t1: 0.0 },
            };
            (ray, emitted.as_vec3())
        })
        .unzip();
    PassRays { rays, emission }
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
    pub fn new(scene: &Scene, planes: usize, seed: u64, accelerator: Accelerator) -> Self {
        let (mut seconds_sampling, mut seconds_build) = (0.0, 0.0);
        let origin = scene.camera.position;
        let mut context = GatherContext::empty(scene, origin);
        let mut raster = (accelerator == Accelerator::Raster).then(|| ScreenRaster::empty(&scene.camera));
        // The BVH is built over the whole set at once; it keeps the planes while it does.
        let mut all = Vec::new();
        for start in (0..planes).step_by(PLANE_CHUNK) {
            let t = Instant::now();
            let chunk = sample_plane_range(scene, seed, start..(start + PLANE_CHUNK).min(planes));
            seconds_sampling += t.elapsed().as_secs_f64();
            let t = Instant::now();
            context.push_planes(scene, &chunk, planes);
            if let Some(r) = &mut raster {
                r.push_planes(&scene.camera, &chunk, &scene.medium);
            }
            seconds_build += t.elapsed().as_secs_f64();
            if accelerator == Accelerator::Bvh {
                all.extend(chunk);
            }
        }
        let t = Instant::now();
        let bvh = (accelerator == Accelerator::Bvh).then(|| PlaneBvh::build(&all, &scene.medium, origin));
        seconds_build += t.elapsed().as_secs_f64();
        PreparedPlanes { context, raster, bvh, accelerator, seconds_sampling, seconds_build }
    }

    /// Gathers the rays of one pass with `weighting`, adding each ray's estimate to `sums`.
    pub fn gather(
        &self,
        weighting: Weighting,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        on_band: &(dyn Fn() + Sync),
    ) -> GatherStats {
        let k = weighting.orientations;
        match (weighting.estimator, k) {
            (Estimator::Unweighted, _) => self.gather_with(&Unweighted, rays, sums, on_band),
            (Estimator::CmisCosine, _) => self.gather_with(&CmisCosine, rays, sums, on_band),
            (Estimator::CmisExact, _) => self.gather_with(&CmisExact, rays, sums, on_band),
            (Estimator::SmisCosine, 2) => self.gather_with(&SmisCosinePair, rays, sums, on_band),
            (Estimator::SmisExact, 2) => self.gather_with(&SmisExactPair, rays, sums, on_band),
            (Estimator::SmisCosine, k) => self.gather_with(&StratifiedK::new(false, k), rays, sums, on_band),
            (Estimator::SmisExact, k) => self.gather_with(&StratifiedK::new(true, k), rays, sums, on_band),
        }
    }

    fn gather_with<D: Denominator>(
        &self,
        weights: &D,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        on_band: &(dyn Fn() + Sync),
    ) -> GatherStats {
        let ctx = &self.context;
        if let Some(raster) = &self.raster {
            return raster.gather(ctx, weights, rays, sums, on_band);
        }
        // Per-ray structures: chunks of rays in parallel, one progress unit per chunk.
        sums.par_chunks_mut(RAY_CHUNK)
            .zip(rays.par_chunks(RAY_CHUNK))
            .map(|(sums, rays)| {
                let mut stats = GatherStats::default();
                for (sum, ray) in sums.iter_mut().zip(rays) {
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
                on_band();
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

/// Settings of one render.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub planes: usize,
    pub weighting: Weighting,
    pub seed: u64,
    pub spp: u32,
    pub pixel_center: bool,
    pub accelerator: Accelerator,
}

/// What a render measured.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct RenderStats {
    pub estimator: String,
    pub planes: usize,
    pub rays: u64,
    pub hits: u64,
    pub tests: u64,
    pub seconds_sampling: f64,
    pub seconds_build: f64,
    pub seconds_rays: f64,
    pub seconds_gather: f64,
    pub seconds_total: f64,
    /// CPU seconds (all threads) of the whole render and of gathering, where the OS tells.
    pub cpu_seconds_total: Option<f64>,
    pub cpu_seconds_gather: Option<f64>,
    /// Peak resident memory of the process so far, where the OS tells.
    pub peak_memory_bytes: Option<u64>,
}

impl RenderStats {
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
    /// Nanoseconds of CPU time (all threads) per hit, for the whole render.
    pub fn cpu_ns_per_hit(&self) -> Option<f64> {
        self.cpu_seconds_total.map(|c| 1e9 * c / self.hits.max(1) as f64)
    }
    pub fn summary(&self) -> String {
        let mut s = format!(
            "{}: {} planes, {} rays, {} hits ({:.0} per ray, {:.2} tests per hit), gather {:.3} s ({:.2} ns/hit wall), total {:.3} s",
            self.estimator,
            self.planes,
            self.rays,
            self.hits,
            self.hits_per_ray(),
            self.tests_per_hit(),
            self.seconds_gather,
            self.gather_ns_per_hit(),
            self.seconds_total
        );
        if let Some(ns) = self.cpu_ns_per_hit() {
            s += &format!(", {ns:.2} ns/hit CPU all included");
        }
        if let Some(b) = self.peak_memory_bytes {
            s += &format!(", peak memory {:.0} MB", b as f64 / 1e6);
        }
        s
    }
}

/// A progress callback: called once per finished unit of work (band or row).
pub type Progress<'a> = &'a (dyn Fn() + Sync);

/// Number of progress units in one pass (for sizing a progress bar).
pub fn progress_units_per_pass(scene: &Scene, accelerator: Accelerator) -> u64 {
    let pixels = scene.camera.width as u64 * scene.camera.height as u64;
    match accelerator {
        Accelerator::Raster => scene.camera.height.div_ceil(crate::raster::BAND_ROWS) as u64,
        _ => pixels.div_ceil(RAY_CHUNK as u64),
    }
}

/// Renders the scene: direct emission plus the photon-plane estimate of single scattering,
/// averaged over `spp` passes.
pub fn render(scene: &Scene, opts: &RenderOptions, progress: Progress) -> (Film, RenderStats) {
    let (start, cpu_start) = (Instant::now(), cpu_seconds());
    let prepared = PreparedPlanes::new(scene, opts.planes, opts.seed, opts.accelerator);
    let mut film = Film::new(scene.camera.width, scene.camera.height);
    let mut stats = RenderStats {
        estimator: opts.weighting.label(),
        planes: opts.planes,
        seconds_sampling: prepared.seconds_sampling,
        seconds_build: prepared.seconds_build,
        ..Default::default()
    };
    for pass in 0..opts.spp {
        let t = Instant::now();
        let pass_rays = camera_rays(scene, opts.seed, pass, opts.pixel_center);
        stats.seconds_rays += t.elapsed().as_secs_f64();
        let (t, cpu) = (Instant::now(), cpu_seconds());
        // Scattering first, emission after: every accelerator then sums in the same order.
        let mut sums = vec![Vec3::ZERO; pass_rays.rays.len()];
        let s = prepared.gather(opts.weighting, &pass_rays.rays, &mut sums, progress);
        stats.seconds_gather += t.elapsed().as_secs_f64();
        if let (Some(a), Some(b)) = (cpu, cpu_seconds()) {
            *stats.cpu_seconds_gather.get_or_insert(0.0) += b - a;
        }
        stats.hits += s.hits;
        stats.tests += s.tests;
        stats.rays += pass_rays.rays.len() as u64;
        for ((f, s), e) in film.pixels.iter_mut().zip(&sums).zip(&pass_rays.emission) {
            *f += *s + *e;
        }
    }
    let inv = 1.0 / opts.spp as f32;
    film.pixels.iter_mut().for_each(|p| *p *= inv);
    stats.seconds_total = start.elapsed().as_secs_f64();
    stats.cpu_seconds_total = cpu_start.zip(cpu_seconds()).map(|(a, b)| b - a);
    stats.peak_memory_bytes = peak_memory_bytes();
    (film, stats)
}

/// CPU seconds used by this process so far (user + system, all threads), from /proc on Linux.
pub fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are the 12th and 13th.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0) // USER_HZ is 100 on Linux
}

/// Peak resident memory of this process (VmHWM), from /proc on Linux.
pub fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}
