//! A render's options resolved: every value checked against the scene and this CPU, nothing
//! left to default, and what a render measured.
//!
//! [`RenderOptions`] is built by [`crate::settings`] alone (its fields are private to the
//! library), from the caller's overrides, the scene's `[render]` table and the defaults of
//! [`crate::limits`]; the renderers below trust it and check nothing again (ripgrep's `HiArgs`).

use crate::accel::Accelerator;
use crate::error::{Error, Result, Setting};
use crate::film::{Film, ImageInfo};
use crate::gather::GatherStats;
use crate::gpu::Device;
use crate::kernel::Kernel;
use crate::photon_plane::PlaneSet;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spread::{relative_rms_error, stderr_film};
use crate::weights::Weighting;
use glam::DVec3;

/// Settings of one render, resolved ([`crate::settings::resolve_render`]).
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    pub(crate) planes: usize,
    pub(crate) weighting: Weighting,
    pub(crate) seed: u64,
    /// Where the planes' random numbers come from.
    pub(crate) sampler: Sampler,
    /// The share of each light's planes swept along the phase function's lobe in fog that
    /// scatters forward or back, in [0, 1] (docs/mathematics.md section 2.5). Resolved
    /// ([`crate::settings`]) to one value per image: +0 for -0, and the default where g = 0,
    /// where no light has a lobe, so that parts and checkpoints of one image hold one setting.
    pub(crate) lobes: f64,
    /// Camera samples per pixel: ray sets, each gathering its own share of the planes
    /// (docs/mathematics.md section 8.1), so that more cost about as much as one.
    pub(crate) spp: u32,
    pub(crate) pixel_center: bool,
    pub(crate) accelerator: Accelerator,
    /// The kernel that runs (`auto` resolved on this CPU).
    pub(crate) kernel: Kernel,
    /// The processor that gathers: [`Device::Cpu`] or [`Device::Gpu`] (`auto` resolved, the GPU
    /// found). Not in the render's fingerprint: the devices agree within f32 rounding
    /// (docs/gpu.md), and their parts may be merged (the merge says so).
    pub(crate) device: Device,
    /// On the GPU, whether the ray sets are made on the CPU and uploaded (the CPU's rays bit
    /// for bit) rather than made where they are gathered (`gpu/rays.wgsl`, the default: within
    /// f32 rounding of the CPU's, docs/gpu.md). Not in the fingerprint, as the device.
    pub(crate) rays_on_cpu: bool,
    /// Whether the render estimates its error image ([`crate::spread`]); never with fewer than
    /// two ray sets.
    pub(crate) stderr: bool,
}

impl RenderOptions {
    /// Planes N of the render (unused by a render on a time budget, which chooses its own).
    pub fn planes(&self) -> usize {
        self.planes
    }
    pub fn weighting(&self) -> Weighting {
        self.weighting
    }
    pub fn seed(&self) -> u64 {
        self.seed
    }
    pub fn sampler(&self) -> Sampler {
        self.sampler
    }
    /// The share of each light's planes swept along its lobe ([`crate::photon_plane::Lobe`]).
    pub fn lobes(&self) -> f64 {
        self.lobes
    }
    /// Camera samples per pixel as asked (see [`RenderOptions::ray_sets`]).
    pub fn spp(&self) -> u32 {
        self.spp
    }
    pub fn pixel_center(&self) -> bool {
        self.pixel_center
    }
    pub fn accelerator(&self) -> Accelerator {
        self.accelerator
    }
    /// The kernel that runs: resolved, never [`Kernel::Auto`].
    pub fn kernel(&self) -> Kernel {
        self.kernel
    }
    /// The processor that gathers: resolved, never [`Device::Auto`].
    pub fn device(&self) -> Device {
        self.device
    }
    /// On the GPU, whether its ray sets are made on the CPU and uploaded (see the field).
    pub fn rays_on_cpu(&self) -> bool {
        self.rays_on_cpu
    }
    /// The structure the planes are gathered through: the GPU's on [`Device::Gpu`], else the
    /// accelerator's.
    pub fn structure(&self) -> Accelerator {
        match self.device {
            Device::Gpu(index) => Accelerator::Gpu(index.unwrap_or_default()),
            _ => self.accelerator,
        }
    }
    /// The device as parts and images record it: `cpu`, or `gpu` with the adapter's name
    /// ([`Devices::record_name`]: any driver's name makes one that a record can hold).
    pub fn device_label(&self) -> String {
        match self.device {
            Device::Gpu(index) => match crate::gpu::adapter_at(index) {
                Ok((_, g)) => Devices::record_name(&format!("gpu: {}", g.name())),
                Err(_) => "gpu".into(),
            },
            d => d.name().into(),
        }
    }
    /// Whether the render estimates its error image (in [`RenderStats::stderr`]).
    pub fn stderr(&self) -> bool {
        self.stderr
    }

    /// Ray sets per pixel: `spp`, or one at pixel centres (where every set would be the same
    /// rays).
    pub fn ray_sets(&self) -> u32 {
        if self.pixel_center { 1 } else { self.spp.max(1) }
    }

    /// The set the planes come from.
    pub fn plane_set(&self) -> PlaneSet {
        PlaneSet { sampler: self.sampler, seed: self.seed, lobes: self.lobes }
    }

    /// What an image of this render of `scene` records of how it was made ([`ImageInfo`]);
    /// `planes` is the count it gathered (a render on a time budget chooses its own), on
    /// `devices` (a render's [`RenderStats::devices`], a merge's partial's).
    pub fn image_info(&self, scene: &Scene, planes: usize, devices: &Devices) -> ImageInfo {
        let (cam, w) = (&scene.camera, &self.weighting);
        let info =
            ImageInfo::new("render", &scene.name, scene.fingerprint(), (cam.width, cam.height), self.pixel_center)
                .with_medium_g(scene.medium.g)
                .with("estimator", w.estimator.name());
        let info = if w.estimator.has_orientations() { info.with("orientations", w.orientations) } else { info };
        let info = info.with("planes", planes).with("seed", self.seed).with("sampler", self.sampler.name());
        // The lobes change the planes only where the fog is not isotropic.
        let info = if scene.medium.g != 0.0 { info.with("lobes", crate::error::Number(self.lobes)) } else { info };
        info.with("spp", self.spp)
            .with("ray_sets", self.ray_sets())
            .with("accelerator", self.accelerator.name())
            .with("devices", devices)
    }
}

/// The devices whose gathering a result holds, each once, in order: `cpu`, or `gpu: ` and the
/// adapter ([`RenderOptions::device_label`]). One for a render; several for a merge of parts
/// gathered on different devices, or a render resumed from a checkpoint on another device than
/// the one that began it (the image agrees with each device's render within f32 rounding,
/// docs/gpu.md, and is the bits of neither). Not in a render's fingerprint: such parts merge.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Devices(Vec<String>);

impl Devices {
    /// The most devices a record may name (a merge of parts from many machines).
    pub const MOST: usize = 256;
    /// The most bytes of one device's name.
    pub const MOST_BYTES: usize = 512;

    /// One device.
    pub fn one(label: impl Into<String>) -> Self {
        Devices(vec![label.into()])
    }

    /// The devices a record names (a part file, a pickle), trusted no more than an argument:
    /// one at least, at most [`Devices::MOST`], each a line of text of at most
    /// [`Devices::MOST_BYTES`] bytes without control characters (`fogplanes info` prints
    /// them, an EXR header holds them); repeats kept once.
    pub fn from_names(names: Vec<String>) -> std::result::Result<Self, String> {
        let mut d = Devices::default();
        for n in names {
            d.add(&Devices(vec![n]));
        }
        d.check()?;
        Ok(d)
    }

    /// Checks the names as [`Devices::from_names`] does.
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.0.is_empty() || self.0.len() > Self::MOST {
            return Err(format!("{} devices named, not 1 to {}", self.0.len(), Self::MOST));
        }
        for n in &self.0 {
            // What `RenderOptions::device_label` makes: cpu, gpu, or gpu: and the adapter.
            let a_device = n == "cpu" || n == "gpu" || n.strip_prefix("gpu: ").is_some_and(|a| !a.is_empty());
            if !a_device || n.len() > Self::MOST_BYTES || n.chars().any(char::is_control) || n.contains("; ") {
                return Err(format!(
                    "{n:?} is not a device's name (cpu, gpu, or gpu: and the adapter's name, at most {} bytes of text on one line, without \"; \")",
                    Self::MOST_BYTES
                ));
            }
        }
        Ok(())
    }

    /// `name` as a record can hold it ([`Devices::check`]): its "; " and control characters
    /// replaced, and, past [`Devices::MOST_BYTES`], the middle cut (`...`), so that the
    /// adapter's name and its back end, kind and tuning at the end stay (a driver's name
    /// has no bound; a record of it must still be read back).
    pub fn record_name(name: &str) -> String {
        let clean: String = name.replace("; ", ", ").chars().map(|c| if c.is_control() { ' ' } else { c }).collect();
        if clean.len() <= Self::MOST_BYTES {
            return clean;
        }
        let (head, tail) = (Self::MOST_BYTES / 2 - 2, Self::MOST_BYTES / 2 - 2);
        let mut a = head;
        while !clean.is_char_boundary(a) {
            a -= 1;
        }
        let mut b = clean.len() - tail;
        while !clean.is_char_boundary(b) {
            b += 1;
        }
        format!("{}...{}", &clean[..a], &clean[b..])
    }

    /// Adds the devices of `other` not already here.
    pub fn add(&mut self, other: &Devices) {
        for n in &other.0 {
            if !self.0.contains(n) {
                self.0.push(n.clone());
            }
        }
        self.0.sort();
    }

    /// The devices' names, in order.
    pub fn names(&self) -> &[String] {
        &self.0
    }

    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

impl std::fmt::Display for Devices {
    /// The names joined by `; ` (a name holds commas: `gpu: llvmpipe (LLVM 15.0.6, 256 bits)
    /// (Vulkan, CPU emulation)`).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0.join("; "))
    }
}

/// What a render measured (wall-clock seconds; CPU time and memory are the caller's to read).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct RenderStats {
    pub estimator: String,
    /// The kernel that ran (`auto` resolved).
    pub kernel: String,
    pub planes: usize,
    /// Plane passes: 1, or more for a render on a time budget ([`crate::render::render_for`]).
    pub plane_passes: u32,
    /// The camera rays of the ray sets gathered along, each set once (the same on every
    /// device: a GPU render may make a set more than once, [`crate::pixel::RaySets`]).
    pub rays: u64,
    pub hits: u64,
    pub tests: u64,
    pub seconds_sampling: f64,
    pub seconds_build: f64,
    pub seconds_rays: f64,
    pub seconds_gather: f64,
    /// The device that gathered (`cpu`, or `gpu: ` and the adapter).
    pub device: String,
    /// The devices whose gathering the result holds: this render's device, and those of the
    /// planes it resumed from (a checkpoint begun on another device).
    pub devices: Devices,
    /// Seconds the GPU spent in its gather (the reach and the binning included), by its timestamps where it has
    /// them, else the wall time from each chunk's first submission to its sums read back (an
    /// upper bound); 0 on the CPU.
    pub seconds_device: f64,
    /// Of `seconds_device`, the gather's and its reduction's (the rest: the planes' reach and
    /// their binning), where the GPU has timestamps; else 0.
    pub seconds_device_gather: f64,
    /// Seconds of wall time spent uploading to the GPU (the planes, and each ray set's rays, or
    /// its record where the GPU makes them), their rays' writing aside; 0 on the CPU.
    pub seconds_upload: f64,
    /// Seconds of wall time the CPU waited for the GPU's work to end (each chunk's sums read
    /// back, a ray set's gatherings before another is made); 0 on the CPU.
    pub seconds_waited: f64,
    /// Bytes that crossed between the CPU and the GPU (planes up, sums back), and the GPU's
    /// queue submissions; 0 on the CPU.
    pub bytes_crossed: u64,
    pub submissions: u64,
    /// The GPU's gather dispatches (each a round of batches of planes, whose work items it
    /// gathers at once); 0 on the CPU.
    pub dispatches: u64,
    pub seconds_total: f64,
    /// The estimated standard error of each pixel, when the options asked for it
    /// (docs/mathematics.md section 10).
    #[serde(skip)]
    pub stderr: Option<Film>,
    /// The estimated relative RMS error of the image, with the error image (section 10.2);
    /// `None` without one, and for a black image (0/0: [`RenderStats::black`] says which).
    pub relative_error: Option<f64>,
    /// The part of `relative_error` that planes do not lower: the direct emission's (section
    /// 10.3). A target error below it is out of reach.
    pub error_floor: Option<f64>,
    /// Why a render in passes stopped: "time budget", "target error", "plane limit", "error
    /// floor" (the target lies below [`RenderStats::error_floor`]) or "black image" (the
    /// relative error is undefined).
    pub stopped_by: Option<&'static str>,
}

impl RenderStats {
    /// The statistics of a render with `opts`, before any work.
    pub fn new(opts: &RenderOptions) -> Self {
        RenderStats {
            estimator: opts.weighting.label(),
            kernel: opts.kernel.to_string(),
            device: opts.device_label(),
            devices: Devices::one(opts.device_label()),
            planes: opts.planes,
            plane_passes: 1,
            ..Default::default()
        }
    }

    /// Records the error image of `image` from its pixels' `variance` (`None`: too few plane
    /// groups to measure a spread), of which `emission_variance` is the direct emission's.
    pub fn add_error_image(
        &mut self,
        image: &Film,
        variance: Option<Vec<DVec3>>,
        emission_variance: &[DVec3],
    ) -> Result<()> {
        let variance = variance.ok_or_else(|| {
            Error::option(Setting::Planes, "an error image needs planes in at least two groups: give more planes")
        })?;
        let error = relative_rms_error(image, &variance, emission_variance);
        self.relative_error = error.map(|e| e.total);
        self.error_floor = error.map(|e| e.floor);
        self.stderr = Some(stderr_film(image.width, image.height, &variance)?);
        Ok(())
    }

    /// Counts one gathering that found `s` in `seconds`.
    pub fn add_gather(&mut self, s: GatherStats, seconds: f64) {
        self.seconds_gather += seconds;
        self.seconds_device += s.device_ns as f64 * 1e-9;
        self.seconds_device_gather += s.device_gather_ns as f64 * 1e-9;
        self.seconds_upload += s.upload_ns as f64 * 1e-9;
        self.seconds_waited += s.wait_ns as f64 * 1e-9;
        self.bytes_crossed += s.bytes_crossed;
        self.submissions += s.submissions;
        self.dispatches += s.dispatches;
        self.hits += s.hits;
        self.tests += s.tests;
    }

    /// Whether the render made an error image of a black image, whose relative error is
    /// undefined (0/0).
    pub fn black(&self) -> bool {
        self.stderr.is_some() && self.relative_error.is_none()
    }

    /// The estimated relative error as a report says it: the figure and its floor, or why
    /// there is none; `None` without an error image. Never `inf` or `NaN`.
    pub fn relative_error_text(&self) -> Option<String> {
        self.stderr.as_ref()?;
        Some(match (self.relative_error, self.error_floor) {
            (Some(e), Some(floor)) => {
                format!("{e:.2e} (its floor, the direct emission's error, which planes do not lower: {floor:.2e})")
            }
            (Some(e), None) => format!("{e:.2e}"),
            (None, _) => "undefined (the image is black)".to_string(),
        })
    }

    pub fn hits_per_ray(&self) -> f64 {
        self.hits as f64 / self.rays.max(1) as f64
    }
    pub fn tests_per_hit(&self) -> f64 {
        self.tests as f64 / self.hits.max(1) as f64
    }
    /// Nanoseconds of wall time in gathering alone per hit.
    pub fn gather_ns_per_hit(&self) -> f64 {
        1e9 * self.seconds_gather / self.hits.max(1) as f64
    }
    /// Hits per second of the GPU's own gather time (0 on the CPU).
    pub fn device_hits_per_second(&self) -> f64 {
        if self.seconds_device > 0.0 { self.hits as f64 / self.seconds_device } else { 0.0 }
    }
    /// What the summary says of the devices where the result holds the gathering of another
    /// device than this render's (a resumed checkpoint's, a merge's parts'); `None` otherwise.
    pub fn devices_note(&self) -> Option<String> {
        if self.devices.is_empty() || self.devices.names() == [self.device.as_str()] {
            return None;
        }
        Some(if self.devices.len() > 1 {
            format!(
                "its planes were gathered on several devices ({}): the image agrees with each one's render within f32 rounding, and is the bits of neither",
                self.devices
            )
        } else {
            format!("its planes were gathered on {}", self.devices)
        })
    }

    pub fn summary(&self) -> String {
        // On the GPU, also the CPU's share of the work (partly beside the GPU's): where an
        // end-to-end time goes.
        let gathered_by = if self.seconds_device > 0.0 {
            // The GPU's time split where its timestamps split it.
            let split = if self.seconds_device_gather > 0.0 {
                format!(
                    " (the reach and the binning {:.4} s, the gather {:.4} s)",
                    self.seconds_device - self.seconds_device_gather,
                    self.seconds_device_gather
                )
            } else {
                String::new()
            };
            format!(
                "{}; GPU time {:.4} s{split}, {:.4} G hits/s, {:.1} MB crossed in {} submissions, {} gather dispatches; the CPU's work: planes sampled {:.4} s, prepared {:.4} s, rays (into the upload buffers, or their records where the GPU makes them) and the emission {:.4} s, the uploads' own {:.4} s; it waited for the GPU {:.4} s",
                self.device,
                self.seconds_device,
                self.device_hits_per_second() * 1e-9,
                self.bytes_crossed as f64 * 1e-6,
                self.submissions,
                self.dispatches,
                self.seconds_sampling,
                self.seconds_build,
                self.seconds_rays,
                self.seconds_upload,
                self.seconds_waited
            )
        } else {
            format!("{} kernel", self.kernel)
        };
        // Figures per hit only where there are hits (a black scene's were its times over 1).
        let (per_hit, gather_per_hit) = if self.hits > 0 {
            (
                format!(" ({:.0} per ray, {:.2} tests per hit)", self.hits_per_ray(), self.tests_per_hit()),
                format!("{:.2} ns/hit of gathering, ", self.gather_ns_per_hit()),
            )
        } else {
            (String::new(), String::new())
        };
        format!(
            "{}: {} planes, {} rays, {} hits{per_hit}, gather {:.3} s ({gather_per_hit}wall, {}), total {:.3} s",
            self.estimator, self.planes, self.rays, self.hits, self.seconds_gather, gathered_by, self.seconds_total
        )
    }
}

#[cfg(test)]
mod tests {
    use super::Devices;

    /// Any driver's name makes a device's name that a record holds and reads back: its "; " and
    /// control characters replaced, its middle cut past the bound, its end (the back end, the
    /// kind, the tuning) kept.
    #[test]
    fn every_adapter_name_makes_a_record_name() {
        let end = " (Vulkan, discrete GPU, tuned: work items of 512 planes, the driver's exp, log and atan, no shader runtime checks)";
        for driver in ["NVIDIA H100 80GB HBM3", "a; b\u{7}c", &"é".repeat(200), &"x".repeat(300)] {
            let name = Devices::record_name(&format!("gpu: {driver}{end}"));
            assert!(name.starts_with("gpu: ") && name.ends_with(&end[end.len() - 100..]), "{name}");
            assert!(Devices::from_names(vec![name.clone()]).is_ok(), "{name}");
        }
        let plain = "gpu: NVIDIA H100 80GB HBM3 (Vulkan, discrete GPU)";
        assert_eq!(Devices::record_name(plain), plain);
    }
}
