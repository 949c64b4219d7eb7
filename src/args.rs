//! The command line's arguments: every command and flag, each documented once here (clap shows
//! these comments as `--help`), and what each command's arguments ask of the library (its
//! overrides, `From<&...Args>`), which `fogplanes::settings` resolves.

use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::{Args, Parser, Subcommand, ValueEnum};
use fogplanes::accel::Accelerator;
use fogplanes::gpu::Device;
use fogplanes::kernel::Kernel;
use fogplanes::sampling::Sampler;
use fogplanes::settings::{self, Overrides, ReferenceOverrides, ScalingOverrides, TableOverrides};
use fogplanes::weights::Estimator;
use std::path::PathBuf;
use std::sync::LazyLock;

// The lists' defaults as they are typed, comma separated: clap shows a list of defaults with
// spaces, which no value of a comma-separated list can be.
static SCALING_PLANES: LazyLock<String> = LazyLock::new(|| joined(settings::SCALING_PLANES));
static TABLE_SWEEP: LazyLock<String> = LazyLock::new(|| joined(settings::TABLE_SWEEP));
static TABLE_SAMPLERS: LazyLock<String> = LazyLock::new(|| joined(settings::TABLE_SAMPLERS.map(|s| s.name())));

fn joined<T: std::fmt::Display>(list: impl IntoIterator<Item = T>) -> String {
    list.into_iter().map(|v| v.to_string()).collect::<Vec<_>>().join(",")
}

/// Renders single scattering in fog lit by rectangular lights, with photon planes weighted by
/// continuous and stochastic multiple importance sampling (West et al. 2020, Section 6), and
/// measures the estimators against an independent reference.
#[derive(Parser)]
#[command(name = "fogplanes", version, about, long_about = None, max_term_width = 100)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Subcommand)]
pub(crate) enum Command {
    /// Render a scene with photon planes.
    ///
    /// Samples the planes from the lights, intersects every camera ray with them and weights
    /// each hit with the chosen estimator. Prints a summary line (estimator, planes, hits,
    /// seconds), then a `wrote` line for each file written.
    #[command(after_long_help = chunk_note())]
    Render(RenderArgs),
    /// Render the independent reference (light point + equiangular distance sampling).
    ///
    /// Shares nothing with the photon planes but the scene. Prints its own relative standard
    /// error and the MSE its noise adds to any comparison.
    Reference(ReferenceArgs),
    /// Compare an image against a reference: SMAPE, MSE, relMSE, largest absolute error.
    Compare(CompareArgs),
    /// Merge partial files into one image: the plane ranges of a render (`render --plane-range
    /// A:B --partial part.npz`) or the row bands of a reference (`reference --rows J0:J1
    /// --partial part.npz`), written by the jobs of a job array.
    ///
    /// The parts may come in any order; they must be parts of one image (same scene and
    /// settings), without overlap or gap. A render's parts are added in the same fixed order as
    /// `render` adds its chunks, so the image is bit-identical to `render`'s when each part is
    /// a canonical chunk of planes (or an aligned power-of-two run of them). Pilot parts of an
    /// adaptive reference (`reference --rows J0:J1 --pilot-pass`) merge into the .npz that
    /// `reference --pilot` reads.
    #[command(after_long_help = chunk_note())]
    Merge(MergeArgs),
    /// Render every estimator from the same planes and rays, and write the table, panel and plot.
    ///
    /// Writes table.md, table.json, panel.png, error_vs_time.png (and .svg) and index.html (an
    /// offline comparison page: the images, their per-pixel errors, the table and the plot) to --out.
    Table(TableArgs),
    /// Measure how render time grows with the number of ray-plane hits.
    ///
    /// Renders over a grid of plane counts and resolutions and writes scaling.md, scaling.json
    /// and seconds_vs_hits.png (and .svg) to --out.
    // Its sizes are --resolutions: the shared --resolution, refused there, is not offered.
    #[command(mut_arg("resolution", |a| a.hide(true)))]
    Scaling(ScalingArgs),
    /// Print what an image records of how it was made (fogplanes writes it into the header of
    /// every EXR of a render or reference: estimator, planes, seed, sampler, ray sets, pixel
    /// filter, resolution, scene fingerprint, version).
    ///
    /// An image made elsewhere (Mitsuba's) records nothing: then only its size is printed.
    Info(InfoArgs),
    /// Write the scene for another renderer, to check fogplanes against it.
    ///
    /// mitsuba: a Mitsuba 3 XML file rendering direct emission plus single scattering (volpath,
    /// max_depth 2, no Russian roulette); resolution, samples and seed are its parameters resx,
    /// resy, spp and seed. tests/mitsuba/check_export.py compares it with `reference`.
    Export(ExportArgs),
    /// List the GPU adapters wgpu finds (Vulkan, Metal, DX12): index, name, back end, kind
    /// (discrete, integrated, virtual GPU, CPU emulation) and largest buffer binding.
    ///
    /// `--device gpu:N` gathers on adapter N; `--device gpu` on the one marked default (a real
    /// GPU first, else an emulated one such as lavapipe). Without any adapter: one line saying
    /// why, exit 2.
    Devices,
}

#[derive(Args)]
pub(crate) struct InfoArgs {
    /// The image (EXR).
    pub(crate) image: PathBuf,
}

#[derive(Args)]
pub(crate) struct MergeArgs {
    /// The partial files (.npz).
    #[arg(required = true)]
    pub(crate) parts: Vec<PathBuf>,
    /// Output: an image (.exr or .png) for render and reference parts, a .npz for pilot parts.
    #[arg(long, short, value_name = "OUT")]
    pub(crate) output: PathBuf,
    /// Reference parts: also write the per-pixel standard error as an image.
    #[arg(long, value_name = "PATH")]
    pub(crate) stderr_image: Option<PathBuf>,
    /// Exposure in stops for PNG output [default: 0].
    #[arg(long, value_name = "EV", allow_negative_numbers = true)]
    pub(crate) exposure: Option<f32>,
    /// No summary line.
    #[arg(long, short)]
    pub(crate) quiet: bool,
}

/// The formats `export` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum ExportFormat {
    /// Mitsuba 3 scene XML (scalar_rgb variant).
    Mitsuba,
}

#[derive(Args)]
pub(crate) struct ExportArgs {
    /// The scene file (TOML).
    pub(crate) scene: PathBuf,
    /// The format to write.
    #[arg(long, short, value_enum)]
    pub(crate) format: ExportFormat,
    /// Output file. Default: <scene name>.xml here.
    #[arg(long, short, value_name = "OUT")]
    pub(crate) output: Option<PathBuf>,
    /// Image size WIDTHxHEIGHT written as the file's default, overriding the scene's camera.
    #[arg(long, value_name = "WxH", value_parser = parse_resolution)]
    pub(crate) resolution: Option<(u32, u32)>,
}

#[derive(Args)]
pub(crate) struct ScalingArgs {
    /// The scene file (TOML).
    pub(crate) scene: PathBuf,
    /// The weighting to time.
    #[arg(long, short, default_value = Estimator::DEFAULT.name(), value_parser = estimator_parser())]
    pub(crate) estimator: Estimator,
    /// Plane counts, comma separated.
    #[arg(long, value_delimiter = ',', default_value = SCALING_PLANES.as_str())]
    pub(crate) planes: Vec<u64>,
    /// Resolutions WxH, comma separated [default: 160x90,320x180,640x360,1280x720].
    #[arg(long, value_delimiter = ',', value_parser = parse_resolution)]
    pub(crate) resolutions: Option<Vec<(u32, u32)>>,
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR", default_value = "scaling")]
    pub(crate) out: PathBuf,
    /// Where the planes' random numbers come from.
    #[arg(long, default_value = "sobol", value_parser = sampler_parser())]
    pub(crate) sampler: Sampler,
    /// In fog that scatters forward or back, the share of each light's planes swept along the
    /// phase function's lobe (it changes the hits; 0: the paper's planes) [default: 0.5].
    #[arg(long, value_name = "SHARE", allow_negative_numbers = true)]
    pub(crate) lobes: Option<f64>,
    #[command(flatten)]
    pub(crate) common: CommonArgs,
    #[command(flatten)]
    pub(crate) device: DeviceArgs,
}

/// Which processor gathers: `render`, `table` and `scaling` (the reference stays on the CPU, so
/// that it shares nothing with the gather).
#[derive(Args)]
pub(crate) struct DeviceArgs {
    /// The processor that gathers: cpu, gpu (through Vulkan, Metal or DX12: a real GPU first,
    /// else an emulated one; refused where no adapter is found), gpu:N (adapter N of
    /// `fogplanes devices`) or auto (a real GPU when one is found, which the summary names)
    /// [default: cpu].
    #[arg(long, value_name = "DEVICE", value_parser = device_parser())]
    pub(crate) device: Option<Device>,
}

#[derive(Args)]
pub(crate) struct CommonArgs {
    /// Image size WIDTHxHEIGHT, overriding the scene's camera resolution.
    #[arg(long, value_name = "WxH", value_parser = parse_resolution)]
    pub(crate) resolution: Option<(u32, u32)>,
    /// Worker threads (default: all cores).
    #[arg(long, value_name = "T")]
    pub(crate) threads: Option<usize>,
    /// No progress bar.
    #[arg(long, short)]
    pub(crate) quiet: bool,
}

/// Watching a long job: `render` and `reference`.
#[derive(Args)]
pub(crate) struct WatchArgs {
    /// Show the image in the tev viewer as it is made: tev listening on HOST:PORT (its default
    /// is 127.0.0.1:14158), the image created once and updated after each finished chunk of
    /// planes (a render: the image of the planes so far) or band of rows (a reference: its mean
    /// and, as the layer `stderr`, its standard error). A viewer that is absent or lost costs
    /// one warning; the job goes on.
    #[arg(long, value_name = "HOST:PORT", value_parser = parse_display_server, conflicts_with = "partial")]
    pub(crate) display_server: Option<String>,
    /// Save each finished chunk of planes (or band of rows) into the directory CK (made if
    /// missing) as it completes; after an interruption (Ctrl-C, a kill), the same command
    /// resumes from it, with the bits of an uninterrupted run. Refused if CK holds another
    /// scene's or other settings' work. A finished job leaves its parts there
    /// (`fogplanes merge CK/*.npz -o OUT.exr` reads them; an adaptive reference's, CK/rows_*.npz
    /// without its pilot pass): remove CK when done.
    #[arg(long, value_name = "CK", conflicts_with = "partial")]
    pub(crate) checkpoint: Option<PathBuf>,
}

#[derive(Args)]
pub(crate) struct RenderArgs {
    /// The scene file (TOML), e.g. media_scenes/six_lights.toml.
    pub(crate) scene: PathBuf,
    /// Weighting (default: the scene's, else smis-exact).
    #[arg(long, short, value_parser = estimator_parser())]
    pub(crate) estimator: Option<Estimator>,
    /// Stratified orientations K for smis-cosine and smis-exact (2 is the paper's pair).
    #[arg(long, value_name = "K")]
    pub(crate) orientations: Option<u32>,
    /// Number of photon planes N.
    #[arg(long, short, value_name = "N")]
    pub(crate) planes: Option<u64>,
    /// Random seed: the image depends on it alone, not on the thread count.
    #[arg(long, short, value_name = "S")]
    pub(crate) seed: Option<u64>,
    /// Where the planes' random numbers come from: sobol (randomised quasi-Monte Carlo, the
    /// default) or independent (the paper's planes). Default: the scene's, else sobol.
    #[arg(long, value_parser = sampler_parser())]
    pub(crate) sampler: Option<Sampler>,
    /// In fog that scatters forward or back (g != 0), the share of each light's planes swept
    /// along the phase function's lobe toward the eye, 0 to 1: 0 sweeps every plane by the
    /// cosine, as the paper does (docs/mathematics.md section 2.5). No matter in isotropic fog.
    /// Default: the scene's, else 0.5.
    #[arg(long, value_name = "SHARE", allow_negative_numbers = true)]
    pub(crate) lobes: Option<f64>,
    /// Camera samples per pixel (ray sets), stratified over the pixel; each gathers its own
    /// share of the N planes, so J of them cost about what one does (default: the scene's, else
    /// 16).
    #[arg(long, value_name = "J")]
    pub(crate) spp: Option<u32>,
    /// Render for this many seconds of wall time (the whole command) instead of a fixed plane
    /// count: planes in passes, each extending the set, until the budget is spent.
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    pub(crate) time_budget: Option<f64>,
    /// Render in passes until the estimated relative RMS error of the image (the RMS of the
    /// error image over the image's mean) falls below R, e.g. 0.01; with --time-budget, stop
    /// at whichever comes first. The report says which.
    #[arg(long, value_name = "R", allow_negative_numbers = true)]
    pub(crate) target_error: Option<f64>,
    /// Also write the estimated standard error of each pixel, from the spread of the render's
    /// plane groups (.exr or .png; docs/mathematics.md section 10).
    #[arg(long, value_name = "SE.exr", conflicts_with = "partial")]
    pub(crate) stderr_image: Option<PathBuf>,
    /// Pixel centres instead of whole pixels (the box filter, by default): compare with
    /// `reference --pixel-center`.
    #[arg(long)]
    pub(crate) pixel_center: bool,
    /// How rays find planes [default: raster].
    #[arg(long, value_parser = accelerator_parser())]
    pub(crate) accelerator: Option<Accelerator>,
    /// The gathering kernel: the widest vector kernel the CPU has (auto), one of them by name,
    /// or one hit at a time (per-hit); all give bit-identical images [default: auto].
    #[arg(long, value_parser = kernel_parser())]
    pub(crate) kernel: Option<Kernel>,
    /// Output: .exr (linear float) or .png (tone-mapped sRGB). Default: <scene name>.exr here.
    #[arg(long, short, value_name = "OUT", conflicts_with = "partial")]
    pub(crate) output: Option<PathBuf>,
    /// Exposure in stops for PNG output [default: 0].
    #[arg(long, value_name = "EV", allow_negative_numbers = true)]
    pub(crate) exposure: Option<f32>,
    /// Render only planes A to B (excluded) of the N, for a job array: A and B multiples of
    /// the canonical chunk size or N. Needs --partial; `fogplanes merge` adds the parts.
    #[arg(long, value_name = "A:B", value_parser = parse_range, requires = "partial", conflicts_with_all = ["time_budget", "target_error"])]
    pub(crate) plane_range: Option<(u64, u64)>,
    /// Write the unnormalised sums of the planes rendered (all, or --plane-range) to this .npz
    /// file instead of an image (numpy loads it: `sums` and a JSON `meta`).
    #[arg(long, value_name = "PART.npz", conflicts_with_all = ["time_budget", "target_error"])]
    pub(crate) partial: Option<PathBuf>,
    /// Record the render's units of work (each one's CPU seconds, and what it waits for) into
    /// this JSON file, for the schedule model that predicts the speed on more cores
    /// (`scripts/scaling_model.py`; `fogplanes::schedule`).
    #[arg(long, value_name = "FILE.json", conflicts_with_all = ["partial", "time_budget", "target_error"])]
    pub(crate) schedule_record: Option<PathBuf>,
    /// With --schedule-record: cut the work (the raster's tiles) as for this many workers,
    /// whatever --threads, so that a record made on few cores holds a larger machine's units,
    /// each measured without more threads than cores. The image is the same bits.
    #[arg(long, value_name = "N", requires = "schedule_record", value_parser = parse_schedule_workers)]
    pub(crate) schedule_workers: Option<usize>,
    #[command(flatten)]
    pub(crate) watch: WatchArgs,
    #[command(flatten)]
    pub(crate) common: CommonArgs,
    #[command(flatten)]
    pub(crate) device: DeviceArgs,
    /// With --device gpu: make the ray sets on the CPU and upload them, the CPU's rays bit for
    /// bit, so that the image agrees with the CPU's at every pixel within f32 rounding (by
    /// default the GPU makes them where it gathers them: within f32 rounding of the CPU's, which
    /// can move a hit that grazes a plane's edge, and nothing but a record crosses).
    #[arg(long, requires = "device")]
    pub(crate) rays_on_cpu: bool,
}

#[derive(Args)]
pub(crate) struct ReferenceArgs {
    /// The scene file (TOML).
    pub(crate) scene: PathBuf,
    /// Samples per pixel, on average (see --uniform).
    #[arg(long, value_name = "N", default_value_t = settings::REFERENCE_SPP)]
    pub(crate) spp: u32,
    /// Random seed.
    #[arg(long, short, value_name = "S", default_value_t = settings::REFERENCE_SEED)]
    pub(crate) seed: u64,
    /// Sample pixel centres instead of whole pixels (to compare with `render --pixel-center`
    /// and `table --pixel-center`).
    #[arg(long)]
    pub(crate) pixel_center: bool,
    /// The same number of samples in every pixel (by default a pilot pass spreads them by need).
    #[arg(long)]
    pub(crate) uniform: bool,
    /// Output image (.exr or .png). Default: <scene name>_reference.exr here.
    #[arg(long, short, value_name = "OUT")]
    pub(crate) output: Option<PathBuf>,
    /// Also write the per-pixel standard error as an image.
    #[arg(long, value_name = "PATH")]
    pub(crate) stderr_image: Option<PathBuf>,
    /// Exposure in stops for PNG output [default: 0].
    #[arg(long, value_name = "EV", allow_negative_numbers = true)]
    pub(crate) exposure: Option<f32>,
    /// Render only rows J0 to J1 (excluded), for a job array; needs --partial, and `fogplanes
    /// merge` assembles the bands. Without --uniform, the bands share one pilot pass: render its
    /// bands with --pilot-pass, merge them into pilot.npz, then render each band with --pilot
    /// pilot.npz.
    #[arg(long, value_name = "J0:J1", value_parser = parse_range, requires = "partial")]
    pub(crate) rows: Option<(u64, u64)>,
    /// Write the rows' mean and standard error (or pilot) to this .npz instead of images.
    #[arg(long, value_name = "PART.npz", conflicts_with_all = ["output", "stderr_image"])]
    pub(crate) partial: Option<PathBuf>,
    /// Render the rows of the adaptive reference's pilot pass (its per-pixel standard errors).
    #[arg(long, requires = "partial", conflicts_with_all = ["uniform", "pilot"])]
    pub(crate) pilot_pass: bool,
    /// The adaptive reference's whole pilot pass (a .npz merged from --pilot-pass parts): the
    /// sample counts come from it instead of a pilot pass of this run's own.
    #[arg(long, value_name = "PILOT.npz", conflicts_with = "uniform")]
    pub(crate) pilot: Option<PathBuf>,
    /// Record the reference's units of work into this JSON file, as `render --schedule-record`
    /// does (`scripts/scaling_model.py --reference`).
    #[arg(long, value_name = "FILE.json", conflicts_with = "partial")]
    pub(crate) schedule_record: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) watch: WatchArgs,
    #[command(flatten)]
    pub(crate) common: CommonArgs,
}

#[derive(Args)]
pub(crate) struct CompareArgs {
    /// The image to measure (EXR).
    pub(crate) image: PathBuf,
    /// The reference (EXR).
    pub(crate) reference: PathBuf,
    /// The reference's standard error per pixel (EXR: `reference --stderr-image`, or another
    /// renderer's): subtract its noise from the MSE, and give z-scores and the regions the noise
    /// does not explain.
    #[arg(long, value_name = "REF_SE.exr")]
    pub(crate) ref_stderr: Option<PathBuf>,
    /// The image's own standard error per pixel (`render --stderr-image`): its noise counts in
    /// the z-scores, and the excess over both noises is reported. Needs --ref-stderr.
    #[arg(long, value_name = "SE.exr", requires = "ref_stderr")]
    pub(crate) stderr: Option<PathBuf>,
    /// Write the z-score of each pixel and channel, (image - reference) / noise, to this EXR.
    /// Needs --ref-stderr.
    #[arg(long, value_name = "Z.exr", requires = "ref_stderr")]
    pub(crate) z_image: Option<PathBuf>,
    /// How many regions to list, those whose excess over the noise is largest.
    #[arg(long, value_name = "N", default_value_t = 5, requires = "ref_stderr")]
    pub(crate) regions: usize,
    /// Print JSON instead of text.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Args)]
pub(crate) struct TableArgs {
    /// The scene file (TOML).
    pub(crate) scene: PathBuf,
    /// Reference image (EXR) at the same resolution and with the same pixel filter: whole
    /// pixels (`reference` as it is), or pixel centres (`reference --pixel-center`) with
    /// --pixel-center.
    #[arg(long, value_name = "REF")]
    pub(crate) reference: PathBuf,
    /// Number of photon planes of the table (default: the scene's).
    #[arg(long, short, value_name = "N")]
    pub(crate) planes: Option<u64>,
    /// Random seed of the table's planes (the sweep uses seed + 1000 onwards).
    #[arg(long, short, value_name = "S")]
    pub(crate) seed: Option<u64>,
    /// Pixel centres instead of whole pixels (box filter); the reference must match.
    #[arg(long)]
    pub(crate) pixel_center: bool,
    /// Plane counts of the error-versus-time sweep, comma separated.
    #[arg(long, value_delimiter = ',', default_value = TABLE_SWEEP.as_str(), conflicts_with = "no_sweep")]
    pub(crate) sweep: Vec<u64>,
    /// Skip the error-versus-time sweep (no plot).
    #[arg(long)]
    pub(crate) no_sweep: bool,
    /// Seeds per plane count in the sweep.
    #[arg(long, default_value_t = settings::TABLE_SWEEP_SEEDS, conflicts_with = "no_sweep")]
    pub(crate) sweep_seeds: u32,
    /// Also render every estimator for this many seconds each and compare at equal time.
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    pub(crate) equal_time: Option<f64>,
    /// Plane samplers to measure, comma separated: every estimator gathers each one's planes.
    #[arg(long, value_delimiter = ',', default_value = TABLE_SAMPLERS.as_str(), value_parser = sampler_parser())]
    pub(crate) samplers: Vec<Sampler>,
    /// In fog that scatters forward or back, the share of each light's planes swept along the
    /// phase function's lobe, for every render of the table (0: the paper's planes). Default:
    /// the scene's, else 0.5.
    #[arg(long, value_name = "SHARE", allow_negative_numbers = true)]
    pub(crate) lobes: Option<f64>,
    /// Extra estimators for the table: smis-exact and smis-cosine with these K besides 2.
    #[arg(long, value_delimiter = ',', value_name = "K")]
    pub(crate) orientations: Vec<u32>,
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR", default_value = "report")]
    pub(crate) out: PathBuf,
    /// Exposure in stops for the panel [default: 0].
    #[arg(long, value_name = "EV", allow_negative_numbers = true)]
    pub(crate) exposure: Option<f32>,
    #[command(flatten)]
    pub(crate) common: CommonArgs,
    #[command(flatten)]
    pub(crate) device: DeviceArgs,
}

/// Parses a value from the closed list of names `names` (shown in `--help` and in errors).
pub(crate) fn named<T: std::str::FromStr + Clone + Send + Sync + 'static>(
    names: Vec<&'static str>,
) -> impl TypedValueParser<Value = T> {
    PossibleValuesParser::new(names).map(|s| s.parse::<T>().ok().expect("a listed name parses"))
}

pub(crate) fn estimator_parser() -> impl TypedValueParser<Value = Estimator> {
    named(Estimator::names())
}

pub(crate) fn accelerator_parser() -> impl TypedValueParser<Value = Accelerator> {
    named(Accelerator::ALL.iter().map(|a| a.name()).collect())
}

/// `cpu`, `gpu`, `auto` or `gpu:N`.
pub(crate) fn device_parser() -> impl Fn(&str) -> Result<Device, String> + Clone + Send + Sync + 'static {
    |s: &str| s.parse::<Device>()
}

pub(crate) fn sampler_parser() -> impl TypedValueParser<Value = Sampler> {
    named(Sampler::ALL.iter().map(|s| s.name()).collect())
}

pub(crate) fn kernel_parser() -> impl TypedValueParser<Value = Kernel> {
    named(Kernel::ALL.iter().map(|k| k.name()).collect())
}

/// The canonical chunk size, as the help states it (from the library, never written out).
pub(crate) fn chunk_note() -> String {
    format!("A canonical chunk is {} planes.", fogplanes::limits::CHUNK_PLANES)
}

/// `WxH`. A value of it, or of [`parse_range`], that starts with `-` and a digit reaches it
/// (`main.rs`'s `negative_pairs`), so that `--resolution -5x3` is refused here as a value, where
/// clap took it for an unknown flag and advised `-- -5x3`.
pub(crate) fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("expected WIDTHxHEIGHT, got {s:?}"))?;
    Ok((whole(w, s)?, whole(h, s)?))
}

/// One whole number of a pair `s`, said as the counts are (`main.rs`'s `plainer`), not in
/// Rust's words ("invalid digit found in string").
fn whole<T: std::str::FromStr<Err = std::num::ParseIntError>>(v: &str, s: &str) -> Result<T, String> {
    v.trim().parse::<T>().map_err(|e| match e.kind() {
        std::num::IntErrorKind::PosOverflow => format!("{v:?} in {s:?}: too large"),
        _ => format!("{v:?} in {s:?}: expected a whole number, 0 or more"),
    })
}

/// A display server's `HOST:PORT` (checked by the library, not resolved).
pub(crate) fn parse_display_server(s: &str) -> Result<String, String> {
    fogplanes::display::check_address(s).map(|()| s.to_string())
}

/// `--schedule-workers`: 1 to 4096 simulated workers (a larger count would overflow the tiling's
/// arithmetic, and no machine has it).
pub(crate) fn parse_schedule_workers(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n @ 1..=4096) => Ok(n),
        _ => Err(format!("expected a number of workers from 1 to 4096, got {s:?}")),
    }
}

/// `A:B` with A < B.
pub(crate) fn parse_range(s: &str) -> Result<(u64, u64), String> {
    let (a, b) = s.split_once(':').ok_or_else(|| format!("expected START:END, got {s:?}"))?;
    let (a, b) = (whole::<u64>(a, s)?, whole::<u64>(b, s)?);
    if a >= b {
        return Err(format!("{s:?}: the start must be below the end"));
    }
    Ok((a, b))
}

// ---------------------------------------------------------------------------------------------
// Every option is used or refused. clap's `requires` is skipped when an option that conflicts
// with the required one is given (`render --plane-range 0:16384 -o x.exr` rendered the whole
// image): each command
// that has such options says here which one a command line would not use (`--exposure` without a
// PNG is the library's check, `settings::check_exposure_applies`, shared with Python).

impl RenderArgs {
    /// The first option given that the command would not use.
    pub(crate) fn unused(&self) -> Option<String> {
        if self.plane_range.is_some() && self.partial.is_none() {
            return Some("--plane-range: renders planes A:B into a partial file: give --partial PART.npz".into());
        }
        None
    }
}

impl ReferenceArgs {
    /// The first option given that the command would not use.
    pub(crate) fn unused(&self) -> Option<String> {
        if self.partial.is_none() {
            if self.rows.is_some() {
                return Some("--rows: renders rows J0:J1 into a partial file: give --partial PART.npz".into());
            }
            if self.pilot_pass || self.pilot.is_some() {
                return Some("--pilot and --pilot-pass make partial files: give --partial PART.npz".into());
            }
        }
        None
    }
}

// ---------------------------------------------------------------------------------------------
// What each command's arguments ask of the library: its overrides, resolved by
// `fogplanes::settings` (the one place that applies defaults and checks).

impl From<&RenderArgs> for Overrides {
    fn from(a: &RenderArgs) -> Self {
        Overrides {
            estimator: a.estimator,
            orientations: a.orientations,
            planes: a.planes,
            seed: a.seed,
            sampler: a.sampler,
            lobes: a.lobes,
            spp: a.spp,
            pixel_center: a.pixel_center,
            accelerator: a.accelerator,
            kernel: a.kernel,
            device: a.device.device,
            rays_on_cpu: a.rays_on_cpu,
            time_budget: a.time_budget,
            target_error: a.target_error,
            stderr: a.stderr_image.is_some(),
            resolution: a.common.resolution,
            threads: a.common.threads,
            exposure: a.exposure,
        }
    }
}

impl From<&ReferenceArgs> for ReferenceOverrides {
    fn from(a: &ReferenceArgs) -> Self {
        ReferenceOverrides {
            spp: Some(a.spp),
            seed: Some(a.seed),
            pixel_center: a.pixel_center,
            uniform: a.uniform,
            resolution: a.common.resolution,
            threads: a.common.threads,
            exposure: a.exposure,
        }
    }
}

impl From<&TableArgs> for TableOverrides {
    fn from(a: &TableArgs) -> Self {
        TableOverrides {
            planes: a.planes,
            seed: a.seed,
            pixel_center: a.pixel_center,
            sweep: Some(if a.no_sweep { Vec::new() } else { a.sweep.clone() }),
            sweep_seeds: Some(a.sweep_seeds),
            equal_time: a.equal_time,
            samplers: Some(a.samplers.clone()),
            lobes: a.lobes,
            orientations: a.orientations.clone(),
            resolution: a.common.resolution,
            threads: a.common.threads,
            exposure: a.exposure,
            device: a.device.device,
        }
    }
}

impl From<&ScalingArgs> for ScalingOverrides {
    fn from(a: &ScalingArgs) -> Self {
        ScalingOverrides {
            estimator: Some(a.estimator),
            sampler: Some(a.sampler),
            lobes: a.lobes,
            planes: Some(a.planes.clone()),
            resolutions: a.resolutions.clone(),
            threads: a.common.threads,
            device: a.device.device,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    /// The lists' defaults, shown as they are typed, are parsed into the settings' lists.
    #[test]
    fn list_defaults_are_the_settings_lists() {
        let Command::Table(t) =
            Cli::try_parse_from(["fogplanes", "table", "s.toml", "--reference", "r.exr"]).unwrap().command
        else {
            panic!("table")
        };
        assert_eq!(t.sweep, settings::TABLE_SWEEP);
        assert_eq!(t.samplers, settings::TABLE_SAMPLERS);
        let Command::Scaling(s) = Cli::try_parse_from(["fogplanes", "scaling", "s.toml"]).unwrap().command else {
            panic!("scaling")
        };
        assert_eq!(s.planes, settings::SCALING_PLANES);
        // As `--help` shows them: one value, comma separated.
        let cli = <Cli as clap::CommandFactory>::command();
        let shown = |command: &str, arg: &str| -> Vec<String> {
            let c = cli.find_subcommand(command).unwrap();
            let a = c.get_arguments().find(|a| a.get_id() == arg).unwrap();
            a.get_default_values().iter().map(|v| v.to_string_lossy().into_owned()).collect()
        };
        assert_eq!(shown("table", "sweep"), ["5120,10240,20480,40960,81920,163840"]);
        assert_eq!(shown("table", "samplers"), ["sobol,independent"]);
        assert_eq!(shown("scaling", "planes"), ["10000,40000,160000,640000"]);
    }
}
