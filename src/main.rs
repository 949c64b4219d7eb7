//! The `fogplanes` command line: a thin layer over the core library (`crates/core`). It parses
//! and checks arguments, shows progress, measures CPU time and memory, and runs the experiments
//! of [`experiments`], which draw with [`pictures`].

mod experiments;
mod page;
mod pictures;
mod report;
mod system;

use anyhow::{Context, Result, anyhow};
use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::{Args, Parser, Subcommand, ValueEnum};
use experiments::{TableOptions, run_table};
use fogplanes::accel::Accelerator;
use fogplanes::control::Control;
use fogplanes::film::{Film, check_writable, write_file_atomically};
use fogplanes::kernel::Kernel;
use fogplanes::merge::{Merged, merge_parts};
use fogplanes::metrics::compare;
use fogplanes::options::RenderOptions;
use fogplanes::outputs::{Output, check_outputs};
use fogplanes::partial::parts::{read_pilot, save_pilot_part, save_reference_part, save_render_part};
use fogplanes::reference::{reference_counts, reference_pilot_rows, reference_rows, render_reference};
use fogplanes::render::{progress_units, render, render_chunk, render_for};
use fogplanes::sampling::Sampler;
use fogplanes::scene::Scene;
use fogplanes::settings::{self, Overrides, ReferenceOverrides, ScalingOverrides, TableOverrides};
use fogplanes::weights::Estimator;
use indicatif::{ProgressBar, ProgressStyle};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Renders single scattering in fog lit by rectangular lights, with photon planes weighted by
/// continuous and stochastic multiple importance sampling (West et al. 2020, Section 6), and
/// measures the estimators against an independent reference.
#[derive(Parser)]
#[command(name = "fogplanes", version, about, long_about = None, max_term_width = 100)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene with photon planes.
    ///
    /// Samples the planes from the lights, intersects every camera ray with them and weights
    /// each hit with the chosen estimator. Prints a one-line summary: estimator, planes, hits,
    /// seconds.
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
    /// a chunk of 16384 planes (or an aligned power-of-two run of them). Pilot parts of an
    /// adaptive reference (`reference --rows J0:J1 --pilot-pass`) merge into the .npz that
    /// `reference --pilot` reads.
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
    Scaling(ScalingArgs),
    /// Write the scene for another renderer, to check fogplanes against it.
    ///
    /// mitsuba: a Mitsuba 3 XML file rendering direct emission plus single scattering (volpath,
    /// max_depth 2, no Russian roulette); resolution, samples and seed are its parameters resx,
    /// resy, spp and seed. tests/mitsuba/check_export.py compares it with `reference`.
    Export(ExportArgs),
}

#[derive(Args)]
struct MergeArgs {
    /// The partial files (.npz).
    #[arg(required = true)]
    parts: Vec<PathBuf>,
    /// Output: an image (.exr or .png) for render and reference parts, a .npz for pilot parts.
    #[arg(long, short, value_name = "OUT")]
    output: PathBuf,
    /// Reference parts: also write the per-pixel standard error as an image.
    #[arg(long, value_name = "PATH")]
    stderr_image: Option<PathBuf>,
    /// Exposure in stops for PNG output [default: 0].
    #[arg(long, value_name = "EV", allow_negative_numbers = true)]
    exposure: Option<f32>,
    /// No summary line.
    #[arg(long, short)]
    quiet: bool,
}

/// The formats `export` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum ExportFormat {
    /// Mitsuba 3 scene XML (scalar_rgb variant).
    Mitsuba,
}

#[derive(Args)]
struct ExportArgs {
    /// The scene file (TOML).
    scene: PathBuf,
    /// The format to write.
    #[arg(long, short, value_enum)]
    format: ExportFormat,
    /// Output file. Default: <scene name>.xml here.
    #[arg(long, short, value_name = "OUT")]
    output: Option<PathBuf>,
    /// Image size WIDTHxHEIGHT written as the file's default, overriding the scene's camera.
    #[arg(long, value_name = "WxH", value_parser = parse_resolution)]
    resolution: Option<(u32, u32)>,
}

#[derive(Args)]
struct ScalingArgs {
    /// The scene file (TOML).
    scene: PathBuf,
    /// The weighting to time.
    #[arg(long, short, default_value = Estimator::DEFAULT.name(), value_parser = estimator_parser())]
    estimator: Estimator,
    /// Plane counts, comma separated.
    #[arg(long, value_delimiter = ',', default_values_t = settings::SCALING_PLANES)]
    planes: Vec<u64>,
    /// Resolutions WxH, comma separated [default: 160x90,320x180,640x360,1280x720].
    #[arg(long, value_delimiter = ',', value_parser = parse_resolution)]
    resolutions: Option<Vec<(u32, u32)>>,
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR", default_value = "scaling")]
    out: PathBuf,
    /// Where the planes' random numbers come from.
    #[arg(long, default_value = "sobol", value_parser = sampler_parser())]
    sampler: Sampler,
    #[command(flatten)]
    common: CommonArgs,
}

#[derive(Args)]
struct CommonArgs {
    /// Image size WIDTHxHEIGHT, overriding the scene's camera resolution.
    #[arg(long, value_name = "WxH", value_parser = parse_resolution)]
    resolution: Option<(u32, u32)>,
    /// Worker threads (default: all cores).
    #[arg(long, value_name = "T")]
    threads: Option<usize>,
    /// No progress bar.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Args)]
struct RenderArgs {
    /// The scene file (TOML), e.g. media_scenes/six_lights.toml.
    scene: PathBuf,
    /// Weighting (default: the scene's, else smis-exact).
    #[arg(long, short, value_parser = estimator_parser())]
    estimator: Option<Estimator>,
    /// Stratified orientations K for smis-cosine and smis-exact (2 is the paper's pair).
    #[arg(long, value_name = "K")]
    orientations: Option<u32>,
    /// Number of photon planes N.
    #[arg(long, short, value_name = "N")]
    planes: Option<u64>,
    /// Random seed: the image depends on it alone, not on the thread count.
    #[arg(long, short, value_name = "S")]
    seed: Option<u64>,
    /// Where the planes' random numbers come from: sobol (randomised quasi-Monte Carlo, the
    /// default) or independent (the paper's planes). Default: the scene's, else sobol.
    #[arg(long, value_parser = sampler_parser())]
    sampler: Option<Sampler>,
    /// Camera samples per pixel (ray sets), stratified over the pixel; each gathers its own
    /// share of the N planes, so K of them cost about what one does (default: the scene's, else
    /// 16).
    #[arg(long, value_name = "K")]
    spp: Option<u32>,
    /// Render for this many seconds of wall time (the whole command) instead of a fixed plane
    /// count: planes in passes, each extending the set, until the budget is spent.
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    time_budget: Option<f64>,
    /// Pixel centres instead of whole pixels (the box filter, by default): compare with
    /// `reference --pixel-center`.
    #[arg(long)]
    pixel_center: bool,
    /// How rays find planes [default: raster].
    #[arg(long, value_parser = accelerator_parser())]
    accelerator: Option<Accelerator>,
    /// The gathering kernel: the widest vector kernel the CPU has (auto), one of them by name,
    /// or one hit at a time (per-hit); all give bit-identical images [default: auto].
    #[arg(long, value_parser = kernel_parser())]
    kernel: Option<Kernel>,
    /// Output: .exr (linear float) or .png (tone-mapped sRGB). Default: <scene name>.exr here.
    #[arg(long, short, value_name = "OUT", conflicts_with = "partial")]
    output: Option<PathBuf>,
    /// Exposure in stops for PNG output [default: 0].
    #[arg(long, value_name = "EV", allow_negative_numbers = true)]
    exposure: Option<f32>,
    /// Render only planes A to B (excluded) of the N, for a job array: A and B multiples of
    /// 16384 (the render's chunks) or N. Needs --partial; `fogplanes merge` adds the parts.
    #[arg(long, value_name = "A:B", value_parser = parse_range, requires = "partial", conflicts_with = "time_budget")]
    plane_range: Option<(u64, u64)>,
    /// Write the unnormalised sums of the planes rendered (all, or --plane-range) to this .npz
    /// file instead of an image (numpy loads it: `sums` and a JSON `meta`).
    #[arg(long, value_name = "PART.npz", conflicts_with = "time_budget")]
    partial: Option<PathBuf>,
    #[command(flatten)]
    common: CommonArgs,
}

#[derive(Args)]
struct ReferenceArgs {
    /// The scene file (TOML).
    scene: PathBuf,
    /// Samples per pixel, on average (see --uniform).
    #[arg(long, value_name = "N", default_value_t = settings::REFERENCE_SPP)]
    spp: u32,
    /// Random seed.
    #[arg(long, short, value_name = "S", default_value_t = settings::REFERENCE_SEED)]
    seed: u64,
    /// Sample pixel centres instead of whole pixels (to compare with `render --pixel-center`
    /// and `table --pixel-center`).
    #[arg(long)]
    pixel_center: bool,
    /// The same number of samples in every pixel (by default a pilot pass spreads them by need).
    #[arg(long)]
    uniform: bool,
    /// Output image (.exr or .png). Default: <scene name>_reference.exr here.
    #[arg(long, short, value_name = "OUT")]
    output: Option<PathBuf>,
    /// Also write the per-pixel standard error as an image.
    #[arg(long, value_name = "PATH")]
    stderr_image: Option<PathBuf>,
    /// Exposure in stops for PNG output [default: 0].
    #[arg(long, value_name = "EV", allow_negative_numbers = true)]
    exposure: Option<f32>,
    /// Render only rows J0 to J1 (excluded), for a job array; needs --partial, and `fogplanes
    /// merge` assembles the bands. Without --uniform, the bands share one pilot pass: render its
    /// bands with --pilot-pass, merge them into pilot.npz, then render each band with --pilot
    /// pilot.npz.
    #[arg(long, value_name = "J0:J1", value_parser = parse_range, requires = "partial")]
    rows: Option<(u64, u64)>,
    /// Write the rows' mean and standard error (or pilot) to this .npz instead of images.
    #[arg(long, value_name = "PART.npz", conflicts_with_all = ["output", "stderr_image"])]
    partial: Option<PathBuf>,
    /// Render the rows of the adaptive reference's pilot pass (its per-pixel standard errors).
    #[arg(long, requires = "partial", conflicts_with_all = ["uniform", "pilot"])]
    pilot_pass: bool,
    /// The adaptive reference's whole pilot pass (a .npz merged from --pilot-pass parts): the
    /// sample counts come from it instead of a pilot pass of this run's own.
    #[arg(long, value_name = "PILOT.npz", conflicts_with = "uniform")]
    pilot: Option<PathBuf>,
    #[command(flatten)]
    common: CommonArgs,
}

#[derive(Args)]
struct CompareArgs {
    /// The image to measure (EXR).
    image: PathBuf,
    /// The reference (EXR).
    reference: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct TableArgs {
    /// The scene file (TOML).
    scene: PathBuf,
    /// Reference image (EXR) at the same resolution and with the same pixel filter: whole
    /// pixels (`reference` as it is), or pixel centres (`reference --pixel-center`) with
    /// --pixel-center.
    #[arg(long, value_name = "REF")]
    reference: PathBuf,
    /// Number of photon planes of the table (default: the scene's).
    #[arg(long, short, value_name = "N")]
    planes: Option<u64>,
    /// Random seed of the table's planes (the sweep uses seed + 1000 onwards).
    #[arg(long, short, value_name = "S")]
    seed: Option<u64>,
    /// Pixel centres instead of whole pixels (box filter); the reference must match.
    #[arg(long)]
    pixel_center: bool,
    /// Plane counts of the error-versus-time sweep, comma separated.
    #[arg(long, value_delimiter = ',', default_values_t = settings::TABLE_SWEEP)]
    sweep: Vec<u64>,
    /// Skip the error-versus-time sweep (no plot).
    #[arg(long)]
    no_sweep: bool,
    /// Seeds per plane count in the sweep.
    #[arg(long, default_value_t = settings::TABLE_SWEEP_SEEDS)]
    sweep_seeds: u32,
    /// Also render every estimator for this many seconds each and compare at equal time.
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    equal_time: Option<f64>,
    /// Plane samplers to measure, comma separated: every estimator gathers each one's planes.
    #[arg(long, value_delimiter = ',', default_values = settings::TABLE_SAMPLERS.map(|s| s.name()), value_parser = sampler_parser())]
    samplers: Vec<Sampler>,
    /// Extra estimators for the table: smis-exact and smis-cosine with these K besides 2.
    #[arg(long, value_delimiter = ',', value_name = "K")]
    orientations: Vec<u32>,
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR", default_value = "report")]
    out: PathBuf,
    /// Exposure in stops for the panel [default: 0].
    #[arg(long, value_name = "EV", allow_negative_numbers = true)]
    exposure: Option<f32>,
    #[command(flatten)]
    common: CommonArgs,
}

/// Prints a line to standard output; a closed pipe (`fogplanes ... | head`) is not an error.
macro_rules! say {
    ($($arg:tt)*) => {{
        let _ = writeln!(std::io::stdout().lock(), $($arg)*);
    }};
}

/// An error with the exit code it deserves: 2 for bad input, 1 for everything else.
struct Failure {
    code: u8,
    error: anyhow::Error,
}

fn input<E: Into<anyhow::Error>>(e: E) -> Failure {
    Failure { code: 2, error: e.into() }
}

impl From<fogplanes::Error> for Failure {
    fn from(e: fogplanes::Error) -> Self {
        // A setting is named as the command line spells it: `--planes`.
        Failure { code: if e.is_input() { 2 } else { 1 }, error: anyhow!(e.worded(|s| s.flag())) }
    }
}

impl From<anyhow::Error> for Failure {
    fn from(e: anyhow::Error) -> Self {
        // The library's errors keep their exit code through the experiments' anyhow chains.
        let code = match e.downcast_ref::<fogplanes::Error>() {
            Some(inner) if inner.is_input() => 2,
            _ => 1,
        };
        Failure { code, error: e }
    }
}

/// Parses a value from the closed list of names `names` (shown in `--help` and in errors).
fn named<T: std::str::FromStr + Clone + Send + Sync + 'static>(
    names: Vec<&'static str>,
) -> impl TypedValueParser<Value = T> {
    PossibleValuesParser::new(names).map(|s| s.parse::<T>().ok().expect("a listed name parses"))
}

fn estimator_parser() -> impl TypedValueParser<Value = Estimator> {
    named(Estimator::names())
}

fn accelerator_parser() -> impl TypedValueParser<Value = Accelerator> {
    named(Accelerator::ALL.iter().map(|a| a.name()).collect())
}

fn sampler_parser() -> impl TypedValueParser<Value = Sampler> {
    named(Sampler::ALL.iter().map(|s| s.name()).collect())
}

fn kernel_parser() -> impl TypedValueParser<Value = Kernel> {
    named(Kernel::ALL.iter().map(|k| k.name()).collect())
}

/// When the command started (for `--time-budget`, which covers the whole command).
static STARTED: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();

fn film_pixels(scene: &Scene) -> f64 {
    scene.camera.width as f64 * scene.camera.height as f64
}

fn main() -> ExitCode {
    STARTED.get_or_init(std::time::Instant::now);
    let cli = Cli::parse();
    // Ctrl-C, SIGTERM or SIGHUP: remove any half-written output before leaving, so no truncated
    // file remains.
    let _ = ctrlc::set_handler(|| {
        fogplanes::film::remove_unfinished_files();
        let _ = writeln!(std::io::stderr(), "\ninterrupted: nothing was written");
        std::process::exit(130);
    });
    let result = match cli.command {
        Command::Render(a) => cmd_render(a),
        Command::Reference(a) => cmd_reference(a),
        Command::Compare(a) => cmd_compare(a),
        Command::Merge(a) => cmd_merge(a),
        Command::Table(a) => cmd_table(a),
        Command::Scaling(a) => cmd_scaling(a),
        Command::Export(a) => cmd_export(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            let _ = writeln!(std::io::stderr(), "error: {:#}", f.error);
            ExitCode::from(f.code)
        }
    }
}

fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("expected WIDTHxHEIGHT, got {s:?}"))?;
    let parse = |v: &str| v.trim().parse::<u32>().map_err(|e| format!("{v:?} in {s:?}: {e}"));
    Ok((parse(w)?, parse(h)?))
}

/// `A:B` with A < B.
fn parse_range(s: &str) -> Result<(u64, u64), String> {
    let (a, b) = s.split_once(':').ok_or_else(|| format!("expected START:END, got {s:?}"))?;
    let parse = |v: &str| v.trim().parse::<u64>().map_err(|e| format!("{v:?} in {s:?}: {e}"));
    let (a, b) = (parse(a)?, parse(b)?);
    if a >= b {
        return Err(format!("{s:?}: the start must be below the end"));
    }
    Ok((a, b))
}

/// A partial file's name ends in .npz (numpy loads it by that name).
fn check_partial_output(path: &std::path::Path) -> Result<(), Failure> {
    if path.extension().and_then(|e| e.to_str()) != Some("npz") {
        return Err(input(anyhow!("{}: a partial file is a .npz", path.display())));
    }
    check_outputs(&[Output::File(path)])?;
    Ok(())
}

/// Starts the worker threads the settings ask for (none: rayon's default, every core).
fn start_threads(threads: Option<usize>) -> Result<(), Failure> {
    if let Some(t) = threads {
        rayon::ThreadPoolBuilder::new().num_threads(t).build_global().context("cannot start the worker threads")?;
    }
    Ok(())
}

fn progress_bar(quiet: bool, total: u64, what: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{elapsed_precise}] {wide_bar} {pos}/{len} (eta {eta})")
            .expect("a valid template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}

fn default_output(scene: &Scene, suffix: &str) -> PathBuf {
    PathBuf::from(format!("{}{suffix}.exr", scene.name))
}

fn cmd_render(a: RenderArgs) -> Result<(), Failure> {
    let scene = Scene::load(&a.scene).map_err(input)?;
    let r = settings::resolve_render(
        &scene,
        &Overrides {
            estimator: a.estimator,
            orientations: a.orientations,
            planes: a.planes,
            seed: a.seed,
            sampler: a.sampler,
            spp: a.spp,
            pixel_center: a.pixel_center,
            accelerator: a.accelerator,
            kernel: a.kernel,
            time_budget: a.time_budget,
            resolution: a.common.resolution,
            threads: a.common.threads,
            exposure: a.exposure,
        },
    )?;
    let (scene, opts) = (&r.scene, &r.options);
    if let Some(part) = &a.partial {
        return render_part(&a, scene, opts, part, r.threads);
    }
    let output = a.output.clone().unwrap_or_else(|| default_output(scene, ""));
    check_outputs(&[Output::Image(&output)])?;
    start_threads(r.threads)?;

    let bar =
        progress_bar(a.common.quiet, progress_units(scene, opts, 0..opts.planes()), opts.weighting().label().as_str());
    let cpu = system::cpu_seconds();
    let (film, stats) = match r.time_budget {
        None => render(scene, opts, Control::with_progress(&|| bar.inc(1)))?,
        Some(seconds) => {
            bar.set_length(u64::MAX);
            // What the command spent before rendering, and what writing the file will take.
            let reserve = 0.02 + 5e-8 * film_pixels(scene);
            let left = seconds - STARTED.get().map_or(0.0, |t| t.elapsed().as_secs_f64()) - reserve;
            let budget = std::time::Duration::from_secs_f64(left.max(0.0));
            render_for(scene, opts, budget, Control::with_progress(&|| bar.inc(1)))?
        }
    };
    let cpu = cpu.zip(system::cpu_seconds()).map(|(a, b)| b - a);
    bar.finish_and_clear();
    film.save(&output, r.exposure)?;
    let mut summary = stats.summary();
    if r.time_budget.is_some() {
        summary += &format!(", {} plane passes", stats.plane_passes);
    }
    if let Some(c) = cpu {
        summary += &format!(", {:.2} ns/hit CPU all included", 1e9 * c / stats.hits.max(1) as f64);
    }
    if let Some(b) = system::peak_memory_bytes() {
        summary += &format!(", peak memory {:.0} MB", b as f64 / 1e6);
    }
    say!("{summary}");
    say!("wrote {} ({}x{}, mean {:.6}, max {:.4})", output.display(), film.width, film.height, film.mean(), film.max());
    Ok(())
}

/// `render --partial`: planes `--plane-range` (all by default) into a partial file.
fn render_part(
    a: &RenderArgs,
    scene: &Scene,
    opts: &RenderOptions,
    part: &std::path::Path,
    threads: Option<usize>,
) -> Result<(), Failure> {
    check_partial_output(part)?;
    let (start, end) = a.plane_range.unwrap_or((0, opts.planes() as u64));
    let range = start as usize..end as usize;
    fogplanes::partial::chunk_indices(opts.planes(), &range)?;
    start_threads(threads)?;
    let units = progress_units(scene, opts, range.clone());
    let bar = progress_bar(a.common.quiet, units, opts.weighting().label().as_str());
    let (partial, stats) = render_chunk(scene, opts, range, Control::with_progress(&|| bar.inc(1)))?;
    bar.finish_and_clear();
    save_render_part(part, scene, opts, &partial)?;
    say!("{}", stats.summary());
    say!("wrote {} (planes {}:{} of {})", part.display(), partial.start, partial.end, partial.planes_total);
    Ok(())
}

fn cmd_merge(a: MergeArgs) -> Result<(), Failure> {
    let merged = merge_parts(&a.parts)?;
    let exposure = settings::exposure(a.exposure)?;
    match merged {
        Merged::Render { partial, image, .. } => {
            if a.stderr_image.is_some() {
                return Err(input(anyhow!("--stderr-image: render parts have no standard error")));
            }
            check_outputs(&[Output::Image(&a.output)])?;
            image.save(&a.output, exposure)?;
            if !a.quiet {
                say!(
                    "merged {} parts: {} planes, {} hits, {:.3} s of rendering",
                    a.parts.len(),
                    partial.planes_total,
                    partial.hits,
                    partial.seconds
                );
                say!(
                    "wrote {} ({}x{}, mean {:.6}, max {:.4})",
                    a.output.display(),
                    image.width,
                    image.height,
                    image.mean(),
                    image.max()
                );
            }
        }
        Merged::Reference { mean, stderr, seconds, .. } => {
            let mut outputs = vec![Output::Image(&a.output)];
            outputs.extend(a.stderr_image.as_deref().map(Output::Image));
            check_outputs(&outputs)?;
            mean.save(&a.output, exposure)?;
            if let Some(p) = &a.stderr_image {
                stderr.save(p, exposure)?;
            }
            if !a.quiet {
                say!("merged {} reference bands ({:.3} s of rendering)", a.parts.len(), seconds);
                say!("wrote {}", a.output.display());
            }
        }
        Merged::Pilot { scene, options, pilot, seconds } => {
            if a.stderr_image.is_some() {
                return Err(input(anyhow!("--stderr-image: pilot parts merge into one .npz")));
            }
            check_partial_output(&a.output)?;
            let rows = 0..scene.camera.height;
            save_pilot_part(&a.output, &scene, &options, rows, &pilot, seconds)?;
            if !a.quiet {
                say!("merged {} pilot bands; wrote {} (for reference --pilot)", a.parts.len(), a.output.display());
            }
        }
    }
    Ok(())
}

/// `reference --partial`: rows `--rows` (all by default) into a partial file: the pilot's with
/// `--pilot-pass`, else the reference's (counts from `--pilot` unless uniform).
fn reference_part(a: &ReferenceArgs, r: &settings::ResolvedReference, part: &std::path::Path) -> Result<(), Failure> {
    check_partial_output(part)?;
    let (scene, opts) = (&r.scene, &r.options);
    let (j0, j1) = a.rows.unwrap_or((0, scene.camera.height as u64));
    let rows = u32::try_from(j0).unwrap_or(u32::MAX)..u32::try_from(j1).unwrap_or(u32::MAX);
    start_threads(r.threads)?;
    let bar = progress_bar(a.common.quiet, rows.len() as u64, "reference");
    let tick = || bar.inc(1);
    let control = Control::with_progress(&tick);
    let start = std::time::Instant::now();
    if a.pilot_pass {
        let pilot = reference_pilot_rows(scene, opts, rows.clone(), control)?;
        bar.finish_and_clear();
        save_pilot_part(part, scene, opts, rows.clone(), &pilot, start.elapsed().as_secs_f64())?;
        say!("wrote {} (pilot rows {}:{} of {})", part.display(), rows.start, rows.end, scene.camera.height);
        return Ok(());
    }
    let counts = match (&a.pilot, opts.uniform) {
        (_, true) => None,
        (Some(p), false) => Some(reference_counts(opts, &read_pilot(p, scene, opts)?.pixels)),
        (None, false) if rows.len() as u32 == scene.camera.height => {
            let pilot = reference_pilot_rows(scene, opts, 0..scene.camera.height, control)?;
            Some(reference_counts(opts, &pilot.pixels))
        }
        (None, false) => {
            return Err(input(anyhow!(
                "--rows: the bands of an adaptive reference share one pilot pass: give --pilot PILOT.npz \
                 (made by `reference --rows J0:J1 --pilot-pass` for each band and `merge`), or --uniform"
            )));
        }
    };
    let (mean, stderr) = reference_rows(scene, opts, rows.clone(), counts.as_deref(), control)?;
    bar.finish_and_clear();
    save_reference_part(part, scene, opts, rows.clone(), (&mean, &stderr), start.elapsed().as_secs_f64())?;
    say!("wrote {} (rows {}:{} of {})", part.display(), rows.start, rows.end, scene.camera.height);
    Ok(())
}

fn cmd_reference(a: ReferenceArgs) -> Result<(), Failure> {
    let scene = Scene::load(&a.scene).map_err(input)?;
    let r = settings::resolve_reference(
        &scene,
        &ReferenceOverrides {
            spp: Some(a.spp),
            seed: Some(a.seed),
            pixel_center: a.pixel_center,
            uniform: a.uniform,
            resolution: a.common.resolution,
            threads: a.common.threads,
            exposure: a.exposure,
        },
    )?;
    if let Some(part) = &a.partial {
        return reference_part(&a, &r, part);
    }
    if a.pilot_pass || a.pilot.is_some() {
        return Err(input(anyhow!("--pilot and --pilot-pass make partial files: give --partial PART.npz")));
    }
    let scene = &r.scene;
    let output = a.output.clone().unwrap_or_else(|| default_output(scene, "_reference"));
    let mut outputs = vec![Output::Image(&output)];
    outputs.extend(a.stderr_image.as_deref().map(Output::Image));
    check_outputs(&outputs)?;
    start_threads(r.threads)?;
    let passes = if r.options.uniform { 1 } else { 2 };
    let bar = progress_bar(a.common.quiet, passes * scene.camera.height as u64, "reference");
    let reference = render_reference(scene, &r.options, Control::with_progress(&|| bar.inc(1)))?;
    bar.finish_and_clear();
    reference.mean.save(&output, r.exposure)?;
    if let Some(p) = &a.stderr_image {
        reference.stderr.save(p, r.exposure)?;
    }
    say!(
        "reference: {} spp on average, {:.3} s, relative standard error {:.3e} (RMS over pixels / mean), noise MSE {:.3e} (x10^4: {:.3e})",
        r.options.spp,
        reference.seconds,
        reference.relative_stderr(),
        reference.noise_mse(),
        reference.noise_mse() * 1e4
    );
    say!("wrote {}", output.display());
    Ok(())
}

fn cmd_compare(a: CompareArgs) -> Result<(), Failure> {
    let image = Film::load_exr(&a.image).map_err(input)?;
    let reference = Film::load_exr(&a.reference).map_err(input)?;
    let m = compare(&image, &reference)?;
    if a.json {
        say!("{}", serde_json::to_string_pretty(&m).context("cannot format JSON")?);
    } else {
        say!("SMAPE        {:.6}  (x10^2: {:.4})", m.smape, m.smape_e2());
        say!("MSE          {:.6e}  (x10^4: {:.4})", m.mse, m.mse_e4());
        say!("relMSE       {:.6e}", m.rel_mse);
        say!("max |error|  {:.6e}", m.max_abs_error);
    }
    Ok(())
}

/// The files `table` writes into its directory; the plot's only with a sweep.
const TABLE_FILES: [&str; 3] = ["table.md", "table.json", "index.html"];
const TABLE_PLOTS: [&str; 2] = ["error_vs_time.png", "error_vs_time.svg"];

fn cmd_table(a: TableArgs) -> Result<(), Failure> {
    let scene = Scene::load(&a.scene).map_err(input)?;
    let r = settings::resolve_table(
        &scene,
        &TableOverrides {
            planes: a.planes,
            seed: a.seed,
            pixel_center: a.pixel_center,
            sweep: Some(if a.no_sweep { Vec::new() } else { a.sweep.clone() }),
            sweep_seeds: Some(a.sweep_seeds),
            equal_time: a.equal_time,
            samplers: Some(a.samplers.clone()),
            orientations: a.orientations.clone(),
            resolution: a.common.resolution,
            threads: a.common.threads,
            exposure: a.exposure,
        },
    )?;
    let scene = &r.scene;
    let reference = Film::load_exr(&a.reference).map_err(input)?;
    reference.check_finite("reference").map_err(|e| input(anyhow!("{}: {e}", a.reference.display())))?;
    if (reference.width, reference.height) != (scene.camera.width, scene.camera.height) {
        return Err(input(anyhow!(
            "{}: the reference is {}x{} but the scene renders at {}x{} (use --resolution)",
            a.reference.display(),
            reference.width,
            reference.height,
            scene.camera.width,
            scene.camera.height
        )));
    }
    // The comparison page is written last: refuse what it cannot show before any work.
    if scene.camera.width.max(scene.camera.height) > page::MAX_SIDE {
        return Err(input(anyhow!(
            "--resolution: the table's comparison page shows images up to {} pixels on a side, not {}x{}",
            page::MAX_SIDE,
            scene.camera.width,
            scene.camera.height
        )));
    }
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("{}: cannot create the output directory", a.out.display()))
        .map_err(input)?;
    // Every file the table writes, checked now: a failure after the renders would lose them.
    let panel = a.out.join("panel.png");
    let plots = if r.sweep.is_empty() { &[][..] } else { &TABLE_PLOTS[..] };
    let files: Vec<PathBuf> = TABLE_FILES.iter().chain(plots).map(|f| a.out.join(f)).collect();
    let outputs: Vec<Output> =
        std::iter::once(Output::Image(&panel)).chain(files.iter().map(|p| Output::File(p))).collect();
    check_outputs(&outputs)?;
    start_threads(r.threads)?;
    let opts =
        TableOptions { settings: &r, out: a.out.clone(), quiet: a.common.quiet, reference_path: a.reference.clone() };
    let table = run_table(&reference, &opts)?;
    say!("{}", table);
    Ok(())
}

/// The files `scaling` writes into its directory besides its plot's PNG.
const SCALING_FILES: [&str; 3] = ["scaling.md", "scaling.json", "seconds_vs_hits.svg"];

fn cmd_scaling(a: ScalingArgs) -> Result<(), Failure> {
    let scene = Scene::load(&a.scene).map_err(input)?;
    if a.common.resolution.is_some() {
        return Err(input(anyhow!("--resolution: scaling measures the sizes of --resolutions")));
    }
    let r = settings::resolve_scaling(&ScalingOverrides {
        estimator: Some(a.estimator),
        sampler: Some(a.sampler),
        planes: Some(a.planes.clone()),
        resolutions: a.resolutions.clone(),
        threads: a.common.threads,
    })?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("{}: cannot create the output directory", a.out.display()))
        .map_err(input)?;
    let (plot, files) = (a.out.join("seconds_vs_hits.png"), SCALING_FILES.map(|f| a.out.join(f)));
    check_outputs(&[&[Output::Image(&plot)][..], &files.each_ref().map(|p| Output::File(p))].concat())?;
    start_threads(r.threads)?;
    let md = experiments::run_scaling(&scene, &r, &a.out, a.common.quiet)?;
    say!("{md}");
    Ok(())
}

fn cmd_export(a: ExportArgs) -> Result<(), Failure> {
    let mut scene = Scene::load(&a.scene).map_err(input)?;
    if let Some((w, h)) = a.resolution {
        scene = scene.with_resolution(w, h)?;
    }
    let output = a.output.clone().unwrap_or_else(|| PathBuf::from(format!("{}.xml", scene.name)));
    check_writable(&output)?;
    let text = match a.format {
        ExportFormat::Mitsuba => fogplanes::export::mitsuba_xml(&scene),
    };
    write_file_atomically(&output, text.as_bytes())?;
    say!("wrote {} ({} lights, {}x{})", output.display(), scene.lights.len(), scene.camera.width, scene.camera.height);
    Ok(())
}
