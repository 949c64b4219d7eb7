//! What a user may set, resolved once: the scene's `[render]` defaults, the library's defaults
//! ([`crate::limits`]) and the caller's overrides become checked options. The resolved render
//! options ([`RenderOptions`]) are built here alone; the renderers trust them.
//!
//! Each command has its overrides (plain data: `None` takes the default) and its resolution
//! ([`resolve_render`], [`resolve_reference`], [`resolve_table`], [`resolve_scaling`]), which
//! applies the defaults, the rule that the scene's K belongs to the scene's estimator, and every
//! range check of [`crate::limits`]. The command line, the Python module and any other front
//! end fill in the overrides from their arguments, call the resolution and word its errors
//! ([`Error::worded`]): a setting is a closed [`Setting`], named `--planes` on the command line
//! and `planes=` in Python, and a value the scene gave is named as the scene file names it.

use crate::accel::Accelerator;
use crate::error::{Error, Result};
pub use crate::error::{Origin, Setting};
use crate::film::ImageFormat;
use crate::gpu::Device;
use crate::kernel::Kernel;
use crate::limits::{
    MAX_EQUAL_TIME_SECONDS, MAX_TIME_BUDGET_SECONDS, check_exposure, check_lobes, check_memory, check_planes,
    check_render_memory_with, check_resolution, check_seconds, check_spp, check_sweep_seeds, check_threads,
};
use crate::options::RenderOptions;
use crate::reference::ReferenceOptions;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spread::GroupSpread;
use crate::weights::{Estimator, Weighting};
use std::path::Path;

fn origin<T>(given: &Option<T>) -> Origin {
    if given.is_some() { Origin::Given } else { Origin::Scene }
}

fn invalid(setting: Setting, origin: Origin) -> impl FnOnce(String) -> Error {
    move |message| Error::InvalidSetting { setting, origin, message }
}

fn from_caller(setting: Setting) -> impl FnOnce(String) -> Error {
    invalid(setting, Origin::Given)
}

// ---------------------------------------------------------------------------------------------
// Shared by every command

/// The scene at the resolution asked for (its own when `None`): each side in range. The memory
/// a render needs at that size is checked by the command's resolution, which knows its planes.
fn scene_at(scene: &Scene, resolution: Option<(u32, u32)>) -> Result<Scene> {
    match resolution {
        Some((w, h)) => scene.with_resolution(w, h),
        None => Ok(scene.clone()),
    }
}

/// `planes` planes held at once at the scene's resolution fit the memory budget; an excess is
/// blamed on the resolution if the caller gave it, else on the plane count's `setting` and
/// origin.
fn check_fits(scene: &Scene, planes: u64, resolution: Origin, planes_from: (Setting, Origin)) -> Result<()> {
    let (setting, origin) = if resolution == Origin::Given { (Setting::Resolution, resolution) } else { planes_from };
    check_memory(scene.camera.width, scene.camera.height, planes).map_err(invalid(setting, origin))
}

fn threads(threads: Option<usize>) -> Result<Option<usize>> {
    if let Some(t) = threads {
        check_threads(t).map_err(from_caller(Setting::Threads))?;
    }
    Ok(threads)
}

/// The exposure in stops (0 if not given): finite, since a NaN turns every pixel black.
pub fn exposure(stops: Option<f32>) -> Result<f32> {
    let stops = stops.unwrap_or(0.0);
    check_exposure(stops).map_err(from_caller(Setting::Exposure))?;
    Ok(stops)
}

/// An exposure given when none of the images written is a PNG is refused: an EXR (or a part
/// file) holds linear radiance, so the exposure would be ignored without a word.
pub fn check_exposure_applies(stops: Option<f32>, images: &[&Path]) -> Result<()> {
    let png = images.iter().any(|p| matches!(ImageFormat::from_path(p), Ok(ImageFormat::Png)));
    if stops.is_some() && !png {
        return Err(Error::option(
            Setting::Exposure,
            "tone-maps PNG images only, and nothing written here is one (an EXR holds linear radiance): \
             write a .png, or leave the exposure out",
        ));
    }
    Ok(())
}

/// `estimator` with `orientations` K: the caller's K, else the scene's when the scene's
/// estimator is the one rendered (a K belongs to its estimator), else the default.
fn weighting(scene: &Scene, estimator: Option<Estimator>, orientations: Option<u32>) -> Result<Weighting> {
    let defaults = scene.render.weighting;
    let estimator = estimator.unwrap_or(defaults.estimator);
    let scene_k = (estimator == defaults.estimator && estimator.has_orientations()).then_some(defaults.orientations);
    if let Some(k) = orientations {
        check_orientations(estimator, k)?;
    }
    Weighting::new(estimator, orientations.or(scene_k)).map_err(invalid(Setting::Orientations, origin(&orientations)))
}

/// A K the caller gave applies to `estimator` (K = 2 is every estimator's default, so it
/// always does) and lies in range.
fn check_orientations(estimator: Estimator, k: u32) -> Result<()> {
    Weighting::new(estimator, Some(k)).map(|_| ()).map_err(from_caller(Setting::Orientations))
}

/// The device asked for, with what the arguments alone decide of it, no adapter touched: `gpu`
/// with the CPU's accelerator or kernel (`cpu_options`: the caller gave one) is refused, since
/// they do not apply to the GPU; `auto` with them is the CPU.
fn wanted_device(given: Option<Device>, cpu_options: bool) -> Result<Device> {
    match given.unwrap_or_default() {
        d @ Device::Gpu(_) if cpu_options => Err(Error::option(
            Setting::Device,
            format!("{d}: the accelerator and the kernel choose how the CPU gathers, and apply to the CPU alone"),
        )),
        // `auto` wants speed, and the caller chose how the CPU gathers.
        Device::Auto if cpu_options => Ok(Device::Cpu),
        d => Ok(d),
    }
}

/// The device that gathers, found for `wanted` ([`wanted_device`]): the CPU without touching
/// any adapter; `auto` the GPU when a GPU adapter is found (not a CPU adapter such as
/// lavapipe, slower than the CPU's own kernels), else the CPU; `gpu` without an adapter is
/// refused in one line saying why.
fn find_device(wanted: Device) -> Result<Device> {
    match wanted {
        Device::Cpu => Ok(Device::Cpu),
        Device::Auto => match crate::gpu::adapter_at(None) {
            Ok((i, g)) if !g.is_cpu_adapter() => Ok(Device::Gpu(Some(i))),
            // A variable the caller set (FOGPLANES_GPU naming no adapter, a tuning variable's
            // value) is refused as under `gpu`, not passed over for the CPU: no adapter at all,
            // or an emulated one, is what `auto` falls back from.
            Err(why) if why.starts_with(crate::gpu::GPU_VARIABLE) => Err(Error::option(Setting::Device, why)),
            _ => Ok(Device::Cpu),
        },
        Device::Gpu(index) => match crate::gpu::adapter_at(index) {
            Ok((i, _)) => Ok(Device::Gpu(Some(i))),
            // An index out of range names itself (or FOGPLANES_GPU) and the count; a setting that
            // a variable of gpu::Tuning cannot give (FOGPLANES_GPU_ITEM_PLANES, _MATH, _CHECKS)
            // names the variable.
            Err(why) if why.starts_with("gpu:") || why.starts_with(crate::gpu::GPU_VARIABLE) => {
                Err(Error::option(Setting::Device, why))
            }
            Err(why) => Err(Error::option(Setting::Device, format!("{wanted}: {why}"))),
        },
    }
}

/// Settings whose device is set last ([`Pending::find_device`]).
pub trait OnDevice {
    #[doc(hidden)]
    fn set_device(&mut self, device: Device);
}

/// Settings checked but for their device: every refusal that the arguments alone decide is
/// made, and no GPU adapter has been touched (a driver's start-up takes a fraction of a second,
/// and a driver may print). A caller makes its own such refusals (its outputs, its files)
/// before [`Pending::find_device`], so that they too come before any driver.
pub struct Pending<T> {
    settings: T,
    wanted: Device,
}

impl<T: OnDevice> Pending<T> {
    fn new(mut settings: T, wanted: Device) -> Self {
        settings.set_device(Device::Cpu);
        Pending { settings, wanted }
    }

    /// The settings before their device is found: their device is the CPU until then.
    pub fn settings(&self) -> &T {
        &self.settings
    }

    /// The settings whole: the device found (`auto` resolved, the GPU's adapter found or
    /// refused in one line).
    pub fn find_device(mut self) -> Result<T> {
        self.settings.set_device(find_device(self.wanted)?);
        Ok(self.settings)
    }
}

// ---------------------------------------------------------------------------------------------
// render

/// What a caller may set for a photon-plane render (`fogplanes render`, Python `render`). `None`
/// takes the scene's `[render]` default (which the scene took from [`crate::limits`] where its
/// file says nothing), and the library's for the rest.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Overrides {
    pub estimator: Option<Estimator>,
    /// Stratified orientations K of smis-cosine and smis-exact.
    pub orientations: Option<u32>,
    pub planes: Option<u64>,
    pub seed: Option<u64>,
    pub sampler: Option<Sampler>,
    /// The share of each light's planes swept along the phase function's lobe, in [0, 1].
    pub lobes: Option<f64>,
    pub spp: Option<u32>,
    pub pixel_center: bool,
    pub accelerator: Option<Accelerator>,
    pub kernel: Option<Kernel>,
    /// The processor that gathers (`None`: the CPU).
    pub device: Option<Device>,
    /// On the GPU, make the ray sets on the CPU and upload them (the CPU's rays bit for bit)
    /// instead of on the GPU; nothing to do on the CPU.
    pub rays_on_cpu: bool,
    /// Render in plane passes for this many seconds instead of a plane count.
    pub time_budget: Option<f64>,
    /// Render in plane passes until the estimated relative RMS error of the image falls below
    /// this (docs/mathematics.md section 10.2), or the time budget runs out.
    pub target_error: Option<f64>,
    /// Estimate the render's error image ([`crate::spread`]).
    pub stderr: bool,
    /// (width, height), overriding the scene's camera.
    pub resolution: Option<(u32, u32)>,
    /// Worker threads (`None`: every core).
    pub threads: Option<usize>,
    /// Stops of exposure for a PNG.
    pub exposure: Option<f32>,
}

/// A render resolved: every value checked, nothing left to default.
#[derive(Clone, Debug)]
pub struct ResolvedRender {
    /// The scene at the resolution to render.
    pub scene: Scene,
    /// The options; `options.planes` is the scene's or the caller's, unused on a time budget.
    pub options: RenderOptions,
    /// Seconds of a render in plane passes ([`crate::render::render_for`]), if one was asked.
    pub time_budget: Option<f64>,
    /// The relative RMS error a render in passes stops at ([`crate::render::render_until`]),
    /// if one was asked (then `options.stderr` is on).
    pub target_error: Option<f64>,
    pub exposure: f32,
    pub threads: Option<usize>,
}

impl ResolvedRender {
    /// Whether the render goes in plane passes (on a time budget or to a target error) rather
    /// than over `options.planes`.
    pub fn in_passes(&self) -> bool {
        self.time_budget.is_some() || self.target_error.is_some()
    }
}

/// Resolves a photon-plane render: the scene's `[render]` defaults where `given` has none,
/// its K only for its own estimator, and every check a render would make (ranges, memory at
/// the resolution, the kernel on this CPU); the device last ([`check_render`], then
/// [`Pending::find_device`]).
pub fn resolve_render(scene: &Scene, given: &Overrides) -> Result<ResolvedRender> {
    check_render(scene, given)?.find_device()
}

impl OnDevice for ResolvedRender {
    fn set_device(&mut self, device: Device) {
        self.options.device = device;
    }
}

/// [`resolve_render`] but for the device: every refusal the arguments decide, no adapter
/// touched.
pub fn check_render(scene: &Scene, given: &Overrides) -> Result<Pending<ResolvedRender>> {
    let scene = scene_at(scene, given.resolution)?;
    let defaults = &scene.render;
    let weighting = weighting(&scene, given.estimator, given.orientations)?;
    let planes = given.planes.unwrap_or(defaults.planes);
    check_planes(planes).map_err(invalid(Setting::Planes, origin(&given.planes)))?;
    let spp = given.spp.unwrap_or(defaults.spp);
    check_spp(spp).map_err(invalid(Setting::Spp, origin(&given.spp)))?;
    let lobes = given.lobes.unwrap_or(defaults.lobes);
    check_lobes(lobes).map_err(invalid(Setting::Lobes, origin(&given.lobes)))?;
    let lobes = image_lobes(&scene, lobes);
    if let Some(seconds) = given.time_budget {
        check_seconds(seconds, MAX_TIME_BUDGET_SECONDS).map_err(from_caller(Setting::TimeBudget))?;
        if given.planes.is_some() {
            return Err(Error::option(
                Setting::Planes,
                "a render on a time budget chooses its own plane count: give one or the other",
            ));
        }
    }
    if let Some(r) = given.target_error {
        if !(r > 0.0 && r < 1.0) {
            return Err(Error::option(
                Setting::TargetError,
                format!("must be a relative error between 0 and 1 (0.01 for 1%), got {}", crate::error::Number(r)),
            ));
        }
        if given.planes.is_some() {
            return Err(Error::option(
                Setting::Planes,
                "a render to a target error chooses its own plane count: give one or the other",
            ));
        }
    }
    let stderr = given.stderr || given.target_error.is_some();
    let ray_sets = if given.pixel_center { 1 } else { spp };
    if stderr && ray_sets < 2 {
        // The error is the spread of the ray sets' plane groups (section 10).
        let why = "an error image (and a target error) needs two ray sets or more, whose plane groups it compares: 2 samples a pixel or more, over whole pixels (not their centres)";
        return Err(Error::option(Setting::Spp, why));
    }
    // A render holds one chunk's planes at a time, so what can exceed the memory is the image:
    // the resolution is at fault, the caller's or the scene's. A render on a time budget sizes
    // its passes to fit (each checks its own memory).
    let in_passes = given.time_budget.is_some() || given.target_error.is_some();
    let held = if in_passes { 1 } else { planes };
    // An error image keeps its plane groups' sums and a copy of the image ([`GroupSpread`]).
    let extra = if stderr { GroupSpread::BYTES_PER_PIXEL + 12 } else { 0 };
    check_render_memory_with(scene.camera.width, scene.camera.height, held, extra)
        .map_err(invalid(Setting::Resolution, origin(&given.resolution)))?;
    let kernel = given.kernel.unwrap_or_default().resolve()?;
    if given.rays_on_cpu && given.device == Some(Device::Cpu) {
        // Not left unused without a word: it moves a GPU render's ray sets.
        return Err(Error::option(
            Setting::Device,
            "cpu with --rays-on-cpu: that makes a GPU render's ray sets on the CPU, where a CPU render makes its own (give --device gpu, or leave it out)",
        ));
    }
    let wanted = wanted_device(given.device, given.accelerator.is_some() || given.kernel.is_some())?;
    let options = RenderOptions {
        planes: planes as usize,
        weighting,
        seed: given.seed.unwrap_or(defaults.seed),
        sampler: given.sampler.unwrap_or(defaults.sampler),
        lobes,
        spp,
        pixel_center: given.pixel_center,
        accelerator: given.accelerator.unwrap_or_default(),
        kernel,
        device: Device::Cpu,
        rays_on_cpu: given.rays_on_cpu,
        stderr,
    };
    let render = ResolvedRender {
        scene,
        options,
        time_budget: given.time_budget,
        target_error: given.target_error,
        exposure: exposure(given.exposure)?,
        threads: threads(given.threads)?,
    };
    Ok(Pending::new(render, wanted))
}

impl Overrides {
    /// [`resolve_render`] of these overrides.
    pub fn resolve(&self, scene: &Scene) -> Result<ResolvedRender> {
        resolve_render(scene, self)
    }
}

// ---------------------------------------------------------------------------------------------
// reference

/// The reference's samples per pixel when the caller gives none.
pub const REFERENCE_SPP: u32 = 1024;
/// The reference's seed when the caller gives none.
pub const REFERENCE_SEED: u64 = 1;

/// What a caller may set for the independent reference (`fogplanes reference`, Python
/// `reference`). `None` takes [`REFERENCE_SPP`], [`REFERENCE_SEED`], the scene's resolution.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReferenceOverrides {
    /// Samples per pixel, on average.
    pub spp: Option<u32>,
    pub seed: Option<u64>,
    pub pixel_center: bool,
    /// The same number of samples in every pixel.
    pub uniform: bool,
    pub resolution: Option<(u32, u32)>,
    pub threads: Option<usize>,
    pub exposure: Option<f32>,
}

/// A reference render resolved.
#[derive(Clone, Debug)]
pub struct ResolvedReference {
    pub scene: Scene,
    pub options: ReferenceOptions,
    pub exposure: f32,
    pub threads: Option<usize>,
}

pub fn resolve_reference(scene: &Scene, given: &ReferenceOverrides) -> Result<ResolvedReference> {
    let scene = scene_at(scene, given.resolution)?;
    let spp = given.spp.unwrap_or(REFERENCE_SPP);
    check_spp(spp).map_err(from_caller(Setting::Spp))?;
    if spp < 2 {
        // One sample is one replicate, whose spread is no standard error (it read 0, and a
        // comparison against it found every difference infinitely significant).
        let why = "a reference's standard error is the spread of its samples' replicates (up to 16 a pixel): 2 samples a pixel or more";
        return Err(Error::option(Setting::Spp, why));
    }
    // The reference holds no planes, only its pixels.
    check_fits(&scene, 0, origin(&given.resolution), (Setting::Resolution, Origin::Scene))?;
    Ok(ResolvedReference {
        scene,
        options: ReferenceOptions {
            spp,
            uniform: given.uniform,
            seed: given.seed.unwrap_or(REFERENCE_SEED),
            pixel_center: given.pixel_center,
        },
        exposure: exposure(given.exposure)?,
        threads: threads(given.threads)?,
    })
}

// ---------------------------------------------------------------------------------------------
// table

/// The table's error-versus-time sweep when the caller gives none: plane counts.
pub const TABLE_SWEEP: [u64; 6] = [5120, 10240, 20480, 40960, 81920, 163_840];
/// Seeds per plane count of the sweep when the caller gives none.
pub const TABLE_SWEEP_SEEDS: u32 = 3;
/// The samplers the table measures when the caller gives none.
pub const TABLE_SAMPLERS: [Sampler; 2] = [Sampler::Sobol, Sampler::Independent];

/// What a caller may set for the estimator table (`fogplanes table`). `None` takes the scene's
/// planes and seed and the defaults above.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TableOverrides {
    pub planes: Option<u64>,
    pub seed: Option<u64>,
    /// Pixel centres instead of whole pixels (the box filter); the reference must match.
    pub pixel_center: bool,
    /// Plane counts of the sweep (`Some(vec![])`: no sweep).
    pub sweep: Option<Vec<u64>>,
    pub sweep_seeds: Option<u32>,
    /// Seconds of each render at equal time (none: no equal-time comparison).
    pub equal_time: Option<f64>,
    pub samplers: Option<Vec<Sampler>>,
    /// The share of each light's planes swept along the phase function's lobe (`None`: the
    /// scene's).
    pub lobes: Option<f64>,
    /// Extra K of smis-cosine and smis-exact besides 2.
    pub orientations: Vec<u32>,
    pub resolution: Option<(u32, u32)>,
    pub threads: Option<usize>,
    pub exposure: Option<f32>,
    /// The processor that gathers (`None`: the CPU).
    pub device: Option<Device>,
}

/// The table resolved.
#[derive(Clone, Debug)]
pub struct ResolvedTable {
    pub scene: Scene,
    pub planes: usize,
    pub seed: u64,
    /// Camera samples per pixel: the scene's (the table renders as `render` does).
    pub spp: u32,
    pub pixel_center: bool,
    /// Plane counts of the sweep (empty: no sweep).
    pub sweep: Vec<usize>,
    pub sweep_seeds: u32,
    /// Every weighting of the table, the baseline among them.
    pub weightings: Vec<Weighting>,
    pub samplers: Vec<Sampler>,
    /// The share of each light's planes swept along its lobe, for every render of the table.
    pub lobes: f64,
    pub equal_time: Option<f64>,
    pub exposure: f32,
    pub threads: Option<usize>,
    /// The processor that gathers, resolved.
    pub device: Device,
}

/// The lobes' share as the image knows it: shares that give the same planes are one setting, so
/// that parts, checkpoints and the fingerprint agree on them (parts of an isotropic render at
/// two shares, the same image, were refused as different images, and -0 was another share
/// than 0 in a part, an EXR's header and the fingerprint).
fn image_lobes(scene: &Scene, lobes: f64) -> f64 {
    if scene.medium.g == 0.0 { crate::limits::DEFAULT_LOBES } else { lobes + 0.0 }
}

/// The first value of `list` that an earlier one repeats. Each of the table's and the scaling
/// run's lists names a value once: a repeated K was dropped without a word, a repeated plane
/// count measured twice.
fn repeated<T: PartialEq>(list: &[T]) -> Option<&T> {
    list.iter().enumerate().find(|(i, v)| list[..*i].contains(v)).map(|(_, v)| v)
}

pub fn resolve_table(scene: &Scene, given: &TableOverrides) -> Result<ResolvedTable> {
    check_table(scene, given)?.find_device()
}

impl OnDevice for ResolvedTable {
    fn set_device(&mut self, device: Device) {
        self.device = device;
    }
}

/// [`resolve_table`] but for the device: every refusal the arguments decide, no adapter
/// touched.
pub fn check_table(scene: &Scene, given: &TableOverrides) -> Result<Pending<ResolvedTable>> {
    let wanted = wanted_device(given.device, false)?;
    let scene = scene_at(scene, given.resolution)?;
    let resolution = origin(&given.resolution);
    let planes = given.planes.unwrap_or(scene.render.planes);
    check_planes(planes).map_err(invalid(Setting::Planes, origin(&given.planes)))?;
    check_fits(&scene, planes, resolution, (Setting::Planes, origin(&given.planes)))?;
    let sweep = given.sweep.clone().unwrap_or_else(|| TABLE_SWEEP.to_vec());
    for &n in &sweep {
        check_planes(n).map_err(from_caller(Setting::Sweep))?;
        check_fits(&scene, n, resolution, (Setting::Sweep, origin(&given.sweep)))?;
    }
    if let Some(n) = repeated(&sweep) {
        return Err(Error::option(Setting::Sweep, format!("{n} is named twice")));
    }
    let sweep_seeds = given.sweep_seeds.unwrap_or(TABLE_SWEEP_SEEDS);
    check_sweep_seeds(sweep_seeds).map_err(from_caller(Setting::SweepSeeds))?;
    if let Some(seconds) = given.equal_time {
        check_seconds(seconds, MAX_EQUAL_TIME_SECONDS).map_err(from_caller(Setting::EqualTime))?;
    }
    let samplers = given.samplers.clone().unwrap_or_else(|| TABLE_SAMPLERS.to_vec());
    if samplers.is_empty() {
        return Err(Error::option(Setting::Samplers, "the table needs at least one sampler"));
    }
    if let Some(s) = repeated(&samplers) {
        return Err(Error::option(Setting::Samplers, format!("{s} is named twice")));
    }
    for &k in &given.orientations {
        check_orientations(Estimator::SmisExact, k)?;
    }
    if let Some(k) = repeated(&given.orientations) {
        return Err(Error::option(Setting::Orientations, format!("{k} is named twice")));
    }
    let lobes = given.lobes.unwrap_or(scene.render.lobes);
    check_lobes(lobes).map_err(invalid(Setting::Lobes, origin(&given.lobes)))?;
    let lobes = image_lobes(&scene, lobes);
    let table = ResolvedTable {
        planes: planes as usize,
        seed: given.seed.unwrap_or(scene.render.seed),
        spp: scene.render.spp,
        pixel_center: given.pixel_center,
        sweep: sweep.iter().map(|&n| n as usize).collect(),
        sweep_seeds,
        weightings: Weighting::all(&given.orientations),
        samplers,
        lobes,
        equal_time: given.equal_time,
        exposure: exposure(given.exposure)?,
        threads: threads(given.threads)?,
        device: Device::Cpu,
        scene,
    };
    Ok(Pending::new(table, wanted))
}

impl ResolvedTable {
    /// The options of one of the table's renders: `weighting` with `sampler` over `planes`
    /// planes (the table's count or one of its sweep, all checked) made with `seed`; the rest
    /// as `render` with nothing given would take them (the table's pixel filter).
    pub fn render_options(&self, weighting: Weighting, sampler: Sampler, planes: usize, seed: u64) -> RenderOptions {
        RenderOptions {
            planes,
            weighting,
            seed,
            sampler,
            lobes: self.lobes,
            spp: self.spp,
            pixel_center: self.pixel_center,
            accelerator: Accelerator::default(),
            kernel: Kernel::widest(),
            device: self.device,
            rays_on_cpu: false,
            stderr: false,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// scaling

/// The plane counts a scaling run measures when the caller gives none.
pub const SCALING_PLANES: [u64; 4] = [10_000, 40_000, 160_000, 640_000];
/// The image sizes a scaling run measures when the caller gives none.
pub const SCALING_RESOLUTIONS: [(u32, u32); 4] = [(160, 90), (320, 180), (640, 360), (1280, 720)];

/// What a caller may set for a scaling run (`fogplanes scaling`). `None` takes the library's
/// default estimator and sampler (not the scene's) and the grids above.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScalingOverrides {
    pub estimator: Option<Estimator>,
    pub sampler: Option<Sampler>,
    /// The lobes' share (`None`: the library's default, not the scene's).
    pub lobes: Option<f64>,
    pub planes: Option<Vec<u64>>,
    pub resolutions: Option<Vec<(u32, u32)>>,
    pub threads: Option<usize>,
    /// The processor that gathers (`None`: the CPU).
    pub device: Option<Device>,
}

/// A scaling run resolved.
#[derive(Clone, Debug)]
pub struct ResolvedScaling {
    pub weighting: Weighting,
    pub sampler: Sampler,
    pub lobes: f64,
    pub planes: Vec<usize>,
    pub resolutions: Vec<(u32, u32)>,
    pub threads: Option<usize>,
    /// The processor that gathers, resolved.
    pub device: Device,
}

impl ResolvedScaling {
    /// The options of the study's render of `planes` planes (one of its counts): the rest as
    /// `render` with nothing given would take them, but the study's estimator and sampler.
    pub fn render_options(&self, planes: usize) -> RenderOptions {
        RenderOptions {
            planes,
            weighting: self.weighting,
            seed: crate::limits::DEFAULT_SEED,
            sampler: self.sampler,
            lobes: self.lobes,
            spp: crate::limits::DEFAULT_RAY_SETS,
            pixel_center: false,
            accelerator: Accelerator::default(),
            kernel: Kernel::widest(),
            device: self.device,
            rays_on_cpu: false,
            stderr: false,
        }
    }
}

pub fn resolve_scaling(given: &ScalingOverrides) -> Result<ResolvedScaling> {
    check_scaling(given)?.find_device()
}

impl OnDevice for ResolvedScaling {
    fn set_device(&mut self, device: Device) {
        self.device = device;
    }
}

/// [`resolve_scaling`] but for the device: every refusal the arguments decide, no adapter
/// touched.
pub fn check_scaling(given: &ScalingOverrides) -> Result<Pending<ResolvedScaling>> {
    let wanted = wanted_device(given.device, false)?;
    let planes = given.planes.clone().unwrap_or_else(|| SCALING_PLANES.to_vec());
    for &n in &planes {
        check_planes(n).map_err(from_caller(Setting::Planes))?;
    }
    // A count or size named twice was measured twice: two points of the study where one was meant.
    if let Some(n) = repeated(&planes) {
        return Err(Error::option(Setting::Planes, format!("{n} is named twice")));
    }
    let resolutions = given.resolutions.clone().unwrap_or_else(|| SCALING_RESOLUTIONS.to_vec());
    for &(w, h) in &resolutions {
        check_resolution(w, h).map_err(from_caller(Setting::Resolutions))?;
        for &n in &planes {
            check_memory(w, h, n).map_err(from_caller(Setting::Resolutions))?;
        }
    }
    if let Some((w, h)) = repeated(&resolutions) {
        return Err(Error::option(Setting::Resolutions, format!("{w}x{h} is named twice")));
    }
    // +0 for -0, as image_lobes gives a render (a scaling run writes no image nor part, and its
    // heading names the share only where the fog is not isotropic).
    let lobes = given.lobes.unwrap_or(crate::limits::DEFAULT_LOBES);
    check_lobes(lobes).map_err(from_caller(Setting::Lobes))?;
    let lobes = lobes + 0.0;
    let scaling = ResolvedScaling {
        weighting: Weighting::new(given.estimator.unwrap_or(Estimator::DEFAULT), None)
            .map_err(from_caller(Setting::Estimator))?,
        sampler: given.sampler.unwrap_or_default(),
        lobes,
        planes: planes.iter().map(|&n| n as usize).collect(),
        resolutions,
        threads: threads(given.threads)?,
        device: Device::Cpu,
    };
    Ok(Pending::new(scaling, wanted))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::limits::DEFAULT_LOBES;
    use crate::limits::{MAX_PLANES, MAX_RESOLUTION_SIDE};
    use crate::scene::tests::MINIMAL;

    fn scene(render: &str) -> Scene {
        Scene::parse(&format!("{MINIMAL}\n[render]\n{render}"), "test.toml", "test").unwrap()
    }

    /// [`scene`] in fog that scatters forward, where the lobes' share is a setting of the image.
    fn forward(render: &str) -> Scene {
        let text = format!("{MINIMAL}\n[render]\n{render}").replace("sigma_a = 0.05", "sigma_a = 0.05\ng = 0.5");
        Scene::parse(&text, "test.toml", "test").unwrap()
    }

    /// Shares that give the same planes resolve to one: in isotropic fog every share is the
    /// default (no light has a lobe), and -0 is 0, so that parts and checkpoints of one image
    /// agree (isotropic parts at two shares were refused as different images).
    #[test]
    fn shares_of_the_lobes_that_give_the_same_planes_are_one_setting() {
        let share = |s: &Scene, lobes: f64| {
            let render = resolve_render(s, &Overrides { lobes: Some(lobes), ..Default::default() }).unwrap();
            let table = resolve_table(s, &TableOverrides { lobes: Some(lobes), ..Default::default() }).unwrap();
            let from_table = table.render_options(Weighting::default(), Sampler::Sobol, 10, 1).lobes;
            assert_eq!(render.options.lobes.to_bits(), from_table.to_bits());
            render.options.lobes
        };
        let (iso, fwd) = (scene(""), forward(""));
        for lobes in [0.0, -0.0, 0.3, 1.0] {
            assert_eq!(share(&iso, lobes).to_bits(), DEFAULT_LOBES.to_bits(), "{lobes}");
        }
        assert_eq!(share(&fwd, -0.0).to_bits(), 0.0f64.to_bits());
        assert_eq!((share(&fwd, 0.3), share(&fwd, 1.0)), (0.3, 1.0));
        assert_eq!(
            resolve_render(&scene("lobes = 0.3\n"), &Overrides::default()).unwrap().options.lobes,
            DEFAULT_LOBES
        );
    }

    /// The setting, origin and message of an error that must be an invalid setting.
    fn refused(e: Error) -> (Setting, Origin, String) {
        match e {
            Error::InvalidSetting { setting, origin, message } => (setting, origin, message),
            e => panic!("not an invalid setting: {e}"),
        }
    }

    #[test]
    fn nothing_given_takes_the_scenes_render_table_and_the_librarys_defaults() {
        let s = forward(
            "estimator = \"smis-cosine\"\norientations = 4\nplanes = 1500\nseed = 3\nspp = 2\nsampler = \"independent\"\nlobes = 0.25\n",
        );
        let r = resolve_render(&s, &Overrides::default()).unwrap();
        let expected = RenderOptions {
            planes: 1500,
            weighting: Weighting { estimator: Estimator::SmisCosine, orientations: 4 },
            seed: 3,
            sampler: Sampler::Independent,
            lobes: 0.25,
            spp: 2,
            pixel_center: false,
            accelerator: Accelerator::Raster,
            kernel: Kernel::Auto.resolve().unwrap(),
            device: Device::Cpu,
            rays_on_cpu: false,
            stderr: false,
        };
        assert_eq!(r.options, expected);
        assert_eq!((r.time_budget, r.exposure, r.threads), (None, 0.0, None));
        assert_eq!((r.scene.camera.width, r.scene.camera.height), (32, 16));
        // Everything given replaces the scene's.
        let given = Overrides {
            estimator: Some(Estimator::CmisExact),
            orientations: None,
            planes: Some(7),
            seed: Some(9),
            sampler: Some(Sampler::Sobol),
            lobes: Some(0.0),
            spp: Some(5),
            pixel_center: true,
            accelerator: Some(Accelerator::Bvh),
            kernel: Some(Kernel::PerHit),
            device: None,
            rays_on_cpu: true,
            time_budget: None,
            target_error: None,
            stderr: false,
            resolution: Some((8, 4)),
            threads: Some(3),
            exposure: Some(-1.5),
        };
        let r = resolve_render(&s, &given).unwrap();
        let expected = RenderOptions {
            planes: 7,
            weighting: Weighting { estimator: Estimator::CmisExact, orientations: 2 },
            seed: 9,
            sampler: Sampler::Sobol,
            lobes: 0.0,
            spp: 5,
            pixel_center: true,
            accelerator: Accelerator::Bvh,
            kernel: Kernel::PerHit,
            device: Device::Cpu,
            rays_on_cpu: true,
            stderr: false,
        };
        assert_eq!(r.options, expected);
        assert_eq!((r.exposure, r.threads), (-1.5, Some(3)));
        assert_eq!((r.scene.camera.width, r.scene.camera.height), (8, 4));
    }

    /// An error image needs two ray sets; a target error is a fraction in (0, 1) and, like a
    /// time budget, chooses its own plane count; it turns the error image on.
    #[test]
    fn error_images_and_target_errors_are_checked() {
        let s = scene("");
        for given in [
            Overrides { stderr: true, pixel_center: true, ..Default::default() },
            Overrides { stderr: true, spp: Some(1), ..Default::default() },
            Overrides { target_error: Some(0.01), pixel_center: true, ..Default::default() },
        ] {
            let (setting, _, message) = refused(resolve_render(&s, &given).unwrap_err());
            assert_eq!(setting, Setting::Spp, "{given:?}");
            assert!(message.contains("two ray sets"), "{message}");
        }
        for r in [0.0, 1.0, -0.1, f64::NAN, f64::INFINITY] {
            let given = Overrides { target_error: Some(r), ..Default::default() };
            assert_eq!(refused(resolve_render(&s, &given).unwrap_err()).0, Setting::TargetError, "{r}");
        }
        let given = Overrides { target_error: Some(0.01), planes: Some(100), ..Default::default() };
        assert_eq!(refused(resolve_render(&s, &given).unwrap_err()).0, Setting::Planes);
        let r = resolve_render(&s, &Overrides { target_error: Some(0.01), ..Default::default() }).unwrap();
        assert!(r.options.stderr && r.in_passes());
    }

    /// The scene's K belongs to the scene's estimator: over every estimator of the scene and of
    /// the caller, with and without a K given.
    #[test]
    fn the_scenes_k_applies_to_its_own_estimator_only() {
        for scene_estimator in Estimator::ALL {
            let k = if scene_estimator.has_orientations() { 5 } else { 2 };
            let s = scene(&format!("estimator = \"{scene_estimator}\"\norientations = {k}\n"));
            for estimator in [None].into_iter().chain(Estimator::ALL.map(Some)) {
                for orientations in [None, Some(2), Some(3)] {
                    let given = Overrides { estimator, orientations, ..Overrides::default() };
                    let rendered = estimator.unwrap_or(scene_estimator);
                    let expected = match orientations {
                        Some(3) if !rendered.has_orientations() => None,
                        Some(k) => Some(k),
                        None if rendered == scene_estimator => Some(k),
                        None => Some(2),
                    };
                    let got = resolve_render(&s, &given).map(|r| r.options.weighting);
                    match expected {
                        Some(k) => assert_eq!(got.unwrap(), Weighting { estimator: rendered, orientations: k }),
                        None => {
                            let (setting, origin, message) = refused(got.unwrap_err());
                            assert_eq!((setting, origin), (Setting::Orientations, Origin::Given));
                            assert!(message.contains("applies to smis-cosine and smis-exact only"), "{message}");
                            assert!(!message.contains("--"), "{message}");
                        }
                    }
                }
            }
        }
    }

    /// An exposure once went into EXR files without a word, which hold linear radiance.
    #[test]
    fn an_exposure_needs_a_png_to_apply_to() {
        let (exr, png, part) = (Path::new("a.exr"), Path::new("b.PNG"), Path::new("c.npz"));
        for images in [&[][..], &[exr], &[exr, part]] {
            let (setting, origin, message) = refused(check_exposure_applies(Some(1.0), images).unwrap_err());
            assert_eq!((setting, origin), (Setting::Exposure, Origin::Given));
            assert!(message.starts_with("tone-maps PNG images only"), "{message}");
            assert!(check_exposure_applies(None, images).is_ok());
        }
        assert!(check_exposure_applies(Some(-2.0), &[exr, png]).is_ok());
    }

    #[test]
    fn every_value_out_of_range_names_its_setting() {
        let s = scene("");
        let cases: Vec<(Overrides, Setting)> = vec![
            (Overrides { planes: Some(0), ..Default::default() }, Setting::Planes),
            (Overrides { planes: Some(MAX_PLANES + 1), ..Default::default() }, Setting::Planes),
            (Overrides { spp: Some(0), ..Default::default() }, Setting::Spp),
            (Overrides { orientations: Some(0), ..Default::default() }, Setting::Orientations),
            (Overrides { orientations: Some(65), ..Default::default() }, Setting::Orientations),
            (Overrides { resolution: Some((0, 10)), ..Default::default() }, Setting::Resolution),
            (Overrides { resolution: Some((MAX_RESOLUTION_SIDE + 1, 1)), ..Default::default() }, Setting::Resolution),
            // The memory budget at the size given, with the scene's planes.
            (Overrides { resolution: Some((30_000, 30_000)), ..Default::default() }, Setting::Resolution),
            (Overrides { threads: Some(0), ..Default::default() }, Setting::Threads),
            (Overrides { exposure: Some(f32::NAN), ..Default::default() }, Setting::Exposure),
            (Overrides { exposure: Some(f32::NEG_INFINITY), ..Default::default() }, Setting::Exposure),
            (Overrides { time_budget: Some(-1.0), ..Default::default() }, Setting::TimeBudget),
            (Overrides { time_budget: Some(0.0), ..Default::default() }, Setting::TimeBudget),
            (Overrides { time_budget: Some(f64::NAN), ..Default::default() }, Setting::TimeBudget),
            (Overrides { time_budget: Some(2e6), ..Default::default() }, Setting::TimeBudget),
            (Overrides { time_budget: Some(1.0), planes: Some(100), ..Default::default() }, Setting::Planes),
            (Overrides { lobes: Some(-0.1), ..Default::default() }, Setting::Lobes),
            (Overrides { lobes: Some(1.5), ..Default::default() }, Setting::Lobes),
            (Overrides { lobes: Some(f64::NAN), ..Default::default() }, Setting::Lobes),
        ];
        for (given, setting) in cases {
            let e = resolve_render(&s, &given).unwrap_err();
            assert!(e.is_input(), "{given:?}");
            let worded = e.worded(|s| s.flag());
            let (got, origin, message) = refused(e);
            assert_eq!((got, origin), (setting, Origin::Given), "{given:?}: {message}");
            assert_eq!(worded, format!("{}: {message}", setting.flag()));
            assert!(!message.contains("--"), "{message}");
        }
    }

    /// A value the scene gave is blamed on the scene, whoever asked: no flag the user never
    /// typed (a scene's spp once read "--spp: ..." in an error about a time budget).
    #[test]
    fn a_value_from_the_scene_is_named_as_the_scene_names_it() {
        // The table holds all its planes; a render holds one chunk of them at a time.
        let s = scene(&format!("planes = {MAX_PLANES}\n"));
        assert_eq!(resolve_render(&s, &Overrides::default()).unwrap().options.planes, MAX_PLANES as usize);
        let e = resolve_table(&s, &TableOverrides::default()).unwrap_err();
        let line = e.worded(|s| s.flag());
        let says = format!("32x16 pixels with {MAX_PLANES} planes would need about 64.0 GiB; the limit is 16 GiB");
        assert_eq!(line, format!("the scene's render.planes: {says}"));
        assert_eq!(e.worded(|s| format!("{}=", s.keyword())), line);
        assert_eq!(e.to_string(), line);
        // Given, the same value is the caller's.
        let e = resolve_table(&s, &TableOverrides { planes: Some(MAX_PLANES), ..Default::default() }).unwrap_err();
        assert_eq!(e.worded(|s| s.flag()), format!("--planes: {says}"));
        assert_eq!(e.to_string(), format!("planes: {says}"));
    }

    #[test]
    fn names_are_spelled_for_each_front_end() {
        for setting in Setting::ALL {
            let (flag, keyword) = (setting.flag(), setting.keyword());
            assert!(flag.starts_with("--") && !flag.contains('_') && !keyword.contains('-'), "{flag} {keyword}");
            assert_eq!(flag[2..].replace('-', "_"), keyword);
        }
        assert_eq!(Setting::TimeBudget.flag(), "--time-budget");
        assert_eq!(Setting::TimeBudget.keyword(), "time_budget");
    }

    #[test]
    fn the_reference_table_and_scaling_resolve_their_own_defaults_and_ranges() {
        let s = scene("planes = 1234\nseed = 7\n");
        let r = resolve_reference(&s, &ReferenceOverrides::default()).unwrap();
        assert_eq!((r.options.spp, r.options.seed, r.options.uniform, r.options.pixel_center), (1024, 1, false, false));
        for (given, setting) in [
            (ReferenceOverrides { spp: Some(0), ..Default::default() }, Setting::Spp),
            (ReferenceOverrides { spp: Some(1), ..Default::default() }, Setting::Spp),
            (ReferenceOverrides { exposure: Some(f32::NAN), ..Default::default() }, Setting::Exposure),
            (ReferenceOverrides { resolution: Some((32_000, 32_000)), ..Default::default() }, Setting::Resolution),
        ] {
            assert_eq!(refused(resolve_reference(&s, &given).unwrap_err()).0, setting, "{given:?}");
        }

        let t = resolve_table(&s, &TableOverrides::default()).unwrap();
        assert_eq!((t.planes, t.seed, t.pixel_center, t.sweep_seeds), (1234, 7, false, 3));
        assert_eq!(t.sweep, TABLE_SWEEP.map(|n| n as usize));
        // Every render of the table takes the scene's share of lobes, or the one given.
        assert_eq!(t.render_options(Weighting::default(), Sampler::Sobol, 10, 1).lobes, DEFAULT_LOBES);
        let t = resolve_table(&forward("lobes = 0.3\n"), &TableOverrides::default()).unwrap();
        assert_eq!(t.render_options(Weighting::default(), Sampler::Sobol, 10, 1).lobes, 0.3);
        let t = resolve_table(&forward(""), &TableOverrides { lobes: Some(0.0), ..Default::default() }).unwrap();
        assert_eq!(t.render_options(Weighting::default(), Sampler::Sobol, 10, 1).plane_set().lobes, 0.0);
        let t = resolve_table(&s, &TableOverrides::default()).unwrap();
        assert_eq!((t.samplers, t.weightings), (TABLE_SAMPLERS.to_vec(), Weighting::all(&[])));
        for (given, setting) in [
            (TableOverrides { planes: Some(0), ..Default::default() }, Setting::Planes),
            (TableOverrides { sweep: Some(vec![100, 0]), ..Default::default() }, Setting::Sweep),
            (TableOverrides { sweep_seeds: Some(0), ..Default::default() }, Setting::SweepSeeds),
            (TableOverrides { equal_time: Some(-1.0), ..Default::default() }, Setting::EqualTime),
            (TableOverrides { equal_time: Some(f64::INFINITY), ..Default::default() }, Setting::EqualTime),
            (TableOverrides { samplers: Some(vec![]), ..Default::default() }, Setting::Samplers),
            (
                TableOverrides { samplers: Some(vec![Sampler::Sobol, Sampler::Sobol]), ..Default::default() },
                Setting::Samplers,
            ),
            (TableOverrides { orientations: vec![3, 0], ..Default::default() }, Setting::Orientations),
            (TableOverrides { sweep: Some(vec![100, 200, 100]), ..Default::default() }, Setting::Sweep),
            (TableOverrides { exposure: Some(f32::NAN), ..Default::default() }, Setting::Exposure),
            (TableOverrides { lobes: Some(2.0), ..Default::default() }, Setting::Lobes),
        ] {
            assert_eq!(refused(resolve_table(&s, &given).unwrap_err()).0, setting, "{given:?}");
        }
        // A value named twice in a list is refused, naming it: a K was dropped without a word.
        // K = 2 (the table's own) names what the table measures anyway, once.
        for ks in [vec![2, 2], vec![4, 3, 4]] {
            let given = TableOverrides { orientations: ks.clone(), ..Default::default() };
            let (setting, _, message) = refused(resolve_table(&s, &given).unwrap_err());
            assert_eq!((setting, message), (Setting::Orientations, format!("{} is named twice", ks[0])), "{ks:?}");
        }
        let t = resolve_table(&s, &TableOverrides { orientations: vec![2, 4], ..Default::default() }).unwrap();
        assert_eq!(t.weightings, Weighting::all(&[4]));
        // No sweep at all is a choice, not an error.
        let t = resolve_table(&s, &TableOverrides { sweep: Some(vec![]), ..Default::default() }).unwrap();
        assert!(t.sweep.is_empty());

        let c = resolve_scaling(&ScalingOverrides::default()).unwrap();
        assert_eq!((c.weighting, c.sampler), (Weighting::default(), Sampler::Sobol));
        assert_eq!((c.lobes, c.render_options(100).lobes), (DEFAULT_LOBES, DEFAULT_LOBES));
        let c = resolve_scaling(&ScalingOverrides { lobes: Some(0.85), ..Default::default() }).unwrap();
        assert_eq!(c.render_options(100).lobes, 0.85);
        assert_eq!((c.planes.len(), c.resolutions), (SCALING_PLANES.len(), SCALING_RESOLUTIONS.to_vec()));
        for (given, setting) in [
            (ScalingOverrides { planes: Some(vec![0]), ..Default::default() }, Setting::Planes),
            (ScalingOverrides { resolutions: Some(vec![(0, 1)]), ..Default::default() }, Setting::Resolutions),
            (
                ScalingOverrides { resolutions: Some(vec![(30_000, 30_000)]), ..Default::default() },
                Setting::Resolutions,
            ),
            (ScalingOverrides { threads: Some(0), ..Default::default() }, Setting::Threads),
            (ScalingOverrides { lobes: Some(1.5), ..Default::default() }, Setting::Lobes),
            (ScalingOverrides { planes: Some(vec![1000, 2000, 1000]), ..Default::default() }, Setting::Planes),
            (
                ScalingOverrides { resolutions: Some(vec![(16, 9), (32, 18), (16, 9)]), ..Default::default() },
                Setting::Resolutions,
            ),
        ] {
            assert_eq!(refused(resolve_scaling(&given).unwrap_err()).0, setting, "{given:?}");
        }
    }
}
