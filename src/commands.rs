//! The commands: each loads its scene, resolves its arguments through `fogplanes::settings`,
//! checks every output before any work, runs, and reports. Errors carry their exit code
//! ([`Failure`]: 2 for bad input, 1 for the rest).

use crate::args::*;
use crate::experiments::{self, TableOptions, run_table};
use crate::watch::{ReferenceWatch, RenderWatch};
use crate::{page, system};
use anyhow::{Context, Result, anyhow};
use fogplanes::control::Control;
use fogplanes::error::Fixed;
use fogplanes::film::{Film, ImageInfo, read_image_info, write_file_atomically};
use fogplanes::merge::{Merged, merge_parts};
use fogplanes::metrics::{compare, compare_noisy};
use fogplanes::options::RenderOptions;
use fogplanes::outputs::{Output, check_outputs};
use fogplanes::partial::parts::{read_pilot, save_pilot_part, save_reference_part, save_render_part};
use fogplanes::reference::{
    band_of_rows, reference_counts, reference_pilot_rows, reference_rows, render_reference_from,
};
use fogplanes::render::{Until, progress_units, render_chunk, render_from, render_until};
use fogplanes::scene::Scene;
use fogplanes::settings::{self, Overrides, ReferenceOverrides, ScalingOverrides, TableOverrides};
use indicatif::{ProgressBar, ProgressStyle};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Prints a line to standard output; a closed pipe (`fogplanes ... | head`) is not an error.
/// Each line as [`fogplanes::error::one_line`] writes it: what it quotes of a name or a file
/// (an escape sequence, a text-direction override) acts on no terminal.
macro_rules! say {
    ($($arg:tt)*) => {{
        let text = format!($($arg)*);
        let lines: Vec<String> = text.split('\n').map(fogplanes::error::one_line).collect();
        let _ = writeln!(std::io::stdout().lock(), "{}", lines.join("\n"));
    }};
}

/// A path as the lines of [`say!`] quote it, a newline in it too written as an escape
/// ([`fogplanes::error::one_line`]): an output is named after its scene's file by default,
/// whose name may hold anything.
fn shown(path: &Path) -> String {
    fogplanes::error::one_line(&path.display().to_string())
}

/// An error with the exit code it deserves: 2 for bad input, 1 for everything else.
pub(crate) struct Failure {
    pub(crate) code: u8,
    pub(crate) error: anyhow::Error,
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

/// When the command started (for `--time-budget`, which covers the whole command).
pub(crate) static STARTED: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();

fn film_pixels(scene: &Scene) -> f64 {
    scene.camera.width as f64 * scene.camera.height as f64
}

/// Refuses an option the command would not use ([`RenderArgs::unused`] and the others), before
/// any work.
fn refuse_unused(unused: Option<String>) -> Result<(), Failure> {
    unused.map_or(Ok(()), |m| Err(input(anyhow!(m))))
}

/// A partial file's name ends in .npz (numpy loads it by that name), and it is none of the
/// command's `inputs`.
fn check_partial_output(path: &std::path::Path, inputs: &[&Path]) -> Result<(), Failure> {
    if path.extension().and_then(|e| e.to_str()) != Some("npz") {
        return Err(input(anyhow!("{}: a partial file is a .npz", path.display())));
    }
    check_outputs(&[Output::File(path)], inputs)?;
    Ok(())
}

/// Starts the worker threads the settings ask for (none: rayon's default, every core).
fn start_threads(threads: Option<usize>) -> Result<(), Failure> {
    if let Some(t) = threads {
        rayon::ThreadPoolBuilder::new().num_threads(t).build_global().context("cannot start the worker threads")?;
    }
    Ok(())
}

/// What a progress bar counts, as it is shown.
enum Unit {
    /// The planes of a render (its units of work, shown as the planes they stand for).
    Planes(u64),
    /// Rows of a reference (of each of its passes).
    Rows,
    /// A render in passes, whose end is not known: elapsed time and passes.
    Passes,
}

/// The command's progress bar on standard error (hidden off a terminal, or with --quiet):
/// `total` units of work, shown in `unit`, with the time left.
fn progress_bar(quiet: bool, total: u64, what: &str, unit: Unit) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(total.max(1));
    let style = match unit {
        Unit::Planes(planes) => {
            ProgressStyle::with_template("{msg} [{elapsed_precise}] {wide_bar} {planes} planes (eta {eta})")
                .expect("a valid template")
                .with_key("planes", move |s: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                    let done = (s.fraction() as f64 * planes as f64).round() as u64;
                    let _ = write!(w, "{done}/{planes}");
                })
        }
        Unit::Rows => ProgressStyle::with_template("{msg} [{elapsed_precise}] {wide_bar} {pos}/{len} rows (eta {eta})")
            .expect("a valid template"),
        Unit::Passes => ProgressStyle::with_template(
            "{msg} [{elapsed_precise}] {spinner} plane passes until the budget or the target error",
        )
        .expect("a valid template"),
    };
    bar.set_style(style.progress_chars("=> "));
    bar.set_message(what.to_string());
    bar
}

fn default_output(scene: &Scene, suffix: &str) -> PathBuf {
    PathBuf::from(format!("{}{suffix}.exr", scene.name))
}

pub(crate) fn cmd_render(a: RenderArgs) -> Result<(), Failure> {
    refuse_unused(a.unused())?;
    let scene = Scene::load(&a.scene).map_err(input)?;
    // Every refusal the arguments decide, the command's own among them, before the device is
    // found: a GPU's driver starts only for a render that goes on.
    let pending = settings::check_render(&scene, &Overrides::from(&a))?;
    if let Some(part) = &a.partial {
        settings::check_exposure_applies(a.exposure, &[])?;
        check_partial_output(part, &[&a.scene])?;
        if let Some((start, end)) = a.plane_range {
            fogplanes::partial::chunk_indices(pending.settings().options.planes(), &(start as usize..end as usize))?;
        }
        let r = pending.find_device()?;
        return render_part(&a, &r.scene, &r.options, part, r.threads);
    }
    let output = a.output.clone().unwrap_or_else(|| default_output(&pending.settings().scene, ""));
    let mut outputs = vec![Output::Image(&output)];
    outputs.extend(a.stderr_image.as_deref().map(Output::Image));
    outputs.extend(a.schedule_record.as_deref().map(Output::File));
    let files = outputs.len();
    outputs.extend(a.watch.checkpoint.as_deref().map(Output::Directory));
    check_outputs(&outputs, &[&a.scene])?;
    if pending.settings().in_passes() && (a.watch.checkpoint.is_some() || a.watch.display_server.is_some()) {
        let flag = if a.watch.checkpoint.is_some() { "--checkpoint" } else { "--display-server" };
        return Err(input(anyhow!(
            "{flag}: a render in passes (on a time budget or to a target error) has no chunks to follow: give --planes"
        )));
    }
    let images: Vec<&Path> = outputs[..files].iter().map(|o| o.path()).collect();
    settings::check_exposure_applies(a.exposure, &images)?;
    let r = pending.find_device()?;
    let (scene, opts) = (&r.scene, &r.options);
    start_threads(r.threads)?;
    // Before the progress bar: its units are the tiles cut for these workers.
    fogplanes::schedule::cut_for(a.schedule_workers.filter(|&n| n > 0));

    let unit = if r.in_passes() { Unit::Passes } else { Unit::Planes(opts.planes() as u64) };
    let bar =
        progress_bar(a.common.quiet, progress_units(scene, opts, 0..opts.planes()), &opts.weighting().label(), unit);
    let mut watch = RenderWatch::start(&a.watch, scene, opts, &bar)?;
    if let (Some(ck), resumed @ 1..) = (&a.watch.checkpoint, watch.resumed_planes()) {
        bar.set_position(progress_units(scene, opts, 0..resumed));
        // On another device than the checkpoint's, the render goes on, and says so here and
        // in its summary; the image records every device (docs/gpu.md).
        let devices = watch.resumed_devices();
        let on =
            if devices.names() == [opts.device_label()] { String::new() } else { format!(" (gathered on {devices})") };
        say!("resuming from {}: {resumed} of {} planes are done{on}", shown(ck), opts.planes());
    }
    let cpu = system::cpu_seconds();
    let (film, stats) = if !r.in_passes() {
        let held = watch.take_resumed();
        let strand = a.schedule_record.is_some().then(fogplanes::schedule::start);
        let progress = || bar.inc(1);
        let mut control = Control::with_progress(&progress);
        if let Some(strand) = &strand {
            control = control.with_strand(strand);
        }
        let done = render_from(scene, opts, control, held, &mut |h, spread| watch.chunk_done(h, spread))?;
        if let Some(path) = &a.schedule_record {
            let record = serde_json::json!({
                "threads": rayon::current_num_threads(),
                "cut_for": fogplanes::schedule::workers(),
                "planes": opts.planes(),
                "width": scene.camera.width,
                "height": scene.camera.height,
                "estimator": opts.weighting().label(),
                "sections": fogplanes::schedule::finish(),
            });
            fogplanes::film::write_file_atomically(path, record.to_string().as_bytes())?;
        }
        done
    } else {
        // What the command spent before rendering, and what writing the file will take.
        let reserve = 0.02 + 5e-8 * film_pixels(scene);
        let budget = r.time_budget.map(|seconds| {
            let left = seconds - STARTED.get().map_or(0.0, |t| t.elapsed().as_secs_f64()) - reserve;
            std::time::Duration::from_secs_f64(left.max(0.0))
        });
        let until = Until { budget, target_error: r.target_error };
        render_until(scene, opts, until, Control::with_progress(&|| bar.inc(1)))?
    };
    let cpu = cpu.zip(system::cpu_seconds()).map(|(a, b)| b - a);
    bar.finish_and_clear();
    // The image's planes: a render in passes chose its count; a render of a count holds all
    // of them, those a checkpoint held included (the statistics count this process's).
    let planes = if r.in_passes() { stats.planes } else { opts.planes() };
    let info = opts.image_info(scene, planes, &stats.devices);
    // The image and its error image moved into place together: an interruption finds both or
    // neither.
    fogplanes::film::written_together(|| {
        film.save_with_info(&output, r.exposure, Some(&info))?;
        if let (Some(path), Some(se)) = (&a.stderr_image, &stats.stderr) {
            se.save_with_info(path, r.exposure, Some(&info.clone().with(ImageInfo::IMAGE, "render standard error")))?;
        }
        Ok(())
    })?;
    watch.finish(&film, stats.stderr.as_ref());
    let mut summary = stats.summary();
    if r.in_passes() {
        summary += &format!(", {} plane passes", stats.plane_passes);
    }
    if let Some(stop) = stats.stopped_by {
        summary += &format!(", stopped by the {stop}");
    }
    if let Some(e) = stats.relative_error_text() {
        summary += &format!(", estimated relative RMS error {e}");
    }
    if let Some(c) = cpu.filter(|_| stats.hits > 0) {
        summary += &format!(", {:.2} ns/hit CPU all included", 1e9 * c / stats.hits.max(1) as f64);
    }
    if let Some(b) = system::peak_memory_bytes() {
        summary += &format!(", peak memory {:.0} MB", b as f64 / 1e6);
    }
    // A render resumed from a checkpoint begun on another device goes on, and says so.
    if let Some(note) = stats.devices_note() {
        summary += &format!("; {note}");
    }
    say!("{summary}");
    if let Some(why) = out_of_reach(&stats, r.target_error) {
        let _ = writeln!(std::io::stderr(), "warning: {why}");
    }
    say!(
        "wrote {} ({}x{}, mean {:.6}, max {:.4})",
        shown(&output),
        film.width,
        film.height,
        Fixed(film.mean()),
        Fixed(film.max() as f64)
    );
    if let (Some(path), Some(se)) = (&a.stderr_image, &stats.stderr) {
        say!("wrote {} (standard error: mean {:.3e}, max {:.3e})", shown(path), se.mean(), se.max());
    }
    Ok(())
}

/// Why a render to a target error stopped short of it, in one line: the target below the
/// error's floor, or a black image.
fn out_of_reach(stats: &fogplanes::options::RenderStats, target: Option<f64>) -> Option<String> {
    let target = target?;
    match stats.stopped_by? {
        "error floor" => Some(format!(
            "--target-error {target:.2e} is out of reach: the direct emission's error, {:.2e} of the image's mean, \
             does not fall with more planes (docs/mathematics.md section 10.3); stopped after {} planes",
            stats.error_floor.unwrap_or_default(),
            stats.planes
        )),
        "black image" => Some(format!(
            "--target-error {target:.2e} cannot be met: the image is black after {} planes, so its relative error \
             is undefined (0/0); stopped",
            stats.planes
        )),
        _ => None,
    }
}

/// `render --partial`: planes `--plane-range` (all by default, a union of the render's chunks)
/// into a partial file (a .npz that is none of the inputs).
fn render_part(
    a: &RenderArgs,
    scene: &Scene,
    opts: &RenderOptions,
    part: &std::path::Path,
    threads: Option<usize>,
) -> Result<(), Failure> {
    // Its output and its plane range were checked before the device was found.
    let (start, end) = a.plane_range.unwrap_or((0, opts.planes() as u64));
    let range = start as usize..end as usize;
    start_threads(threads)?;
    let units = progress_units(scene, opts, range.clone());
    let planes = (range.end - range.start) as u64;
    let bar = progress_bar(a.common.quiet, units, &opts.weighting().label(), Unit::Planes(planes));
    let (partial, stats) = render_chunk(scene, opts, range, Control::with_progress(&|| bar.inc(1)))?;
    bar.finish_and_clear();
    save_render_part(part, scene, opts, &partial)?;
    say!("{}", stats.summary());
    say!("wrote {} (planes {}:{} of {})", shown(part), partial.start, partial.end, partial.planes_total);
    Ok(())
}

pub(crate) fn cmd_merge(a: MergeArgs) -> Result<(), Failure> {
    // Before any part is read: an exposure needs a PNG among the outputs.
    let images: Vec<&std::path::Path> = std::iter::once(a.output.as_path()).chain(a.stderr_image.as_deref()).collect();
    settings::check_exposure_applies(a.exposure, &images)?;
    // Before any part is read: no output is one of the parts (of whatever kind they turn out).
    let parts: Vec<&Path> = a.parts.iter().map(PathBuf::as_path).collect();
    let files: Vec<Output> = images.iter().map(|p| Output::File(p)).collect();
    check_outputs(&files, &parts)?;
    let merged = merge_parts(&a.parts)?;
    let exposure = settings::exposure(a.exposure)?;
    match merged {
        Merged::Render { scene, options, partial, image } => {
            if a.stderr_image.is_some() {
                return Err(input(anyhow!("--stderr-image: render parts have no standard error")));
            }
            check_outputs(&[Output::Image(&a.output)], &parts)?;
            settings::check_exposure_applies(a.exposure, &[&a.output])?;
            let info = options.image_info(&scene, partial.planes_total, &partial.devices);
            image.save_with_info(&a.output, exposure, Some(&info))?;
            if !a.quiet {
                say!(
                    "merged {} parts: {} planes, {} hits, {:.3} s of rendering",
                    a.parts.len(),
                    partial.planes_total,
                    partial.hits,
                    partial.seconds
                );
                if partial.devices.len() > 1 {
                    say!(
                        "note: the parts were gathered on different devices ({}): the image agrees with each one's render within f32 rounding, and is the bits of neither",
                        partial.devices
                    );
                }
                say!(
                    "wrote {} ({}x{}, mean {:.6}, max {:.4})",
                    shown(&a.output),
                    image.width,
                    image.height,
                    Fixed(image.mean()),
                    Fixed(image.max() as f64)
                );
            }
        }
        Merged::Reference { scene, options, mean, stderr, seconds } => {
            let mut outputs = vec![Output::Image(&a.output)];
            outputs.extend(a.stderr_image.as_deref().map(Output::Image));
            check_outputs(&outputs, &parts)?;
            let images: Vec<&std::path::Path> = outputs.iter().map(|o| o.path()).collect();
            settings::check_exposure_applies(a.exposure, &images)?;
            fogplanes::film::written_together(|| {
                mean.save_with_info(&a.output, exposure, Some(&options.image_info(&scene, false)))?;
                if let Some(p) = &a.stderr_image {
                    stderr.save_with_info(p, exposure, Some(&options.image_info(&scene, true)))?;
                }
                Ok(())
            })?;
            if !a.quiet {
                say!("merged {} reference bands ({:.3} s of rendering)", a.parts.len(), seconds);
                say!("wrote {}", shown(&a.output));
            }
        }
        Merged::Pilot { scene, options, pilot, seconds } => {
            if a.stderr_image.is_some() {
                return Err(input(anyhow!("--stderr-image: pilot parts merge into one .npz")));
            }
            check_partial_output(&a.output, &parts)?;
            settings::check_exposure_applies(a.exposure, &[])?;
            let rows = 0..scene.camera.height;
            save_pilot_part(&a.output, &scene, &options, rows, &pilot, seconds)?;
            if !a.quiet {
                say!("merged {} pilot bands; wrote {} (for reference --pilot)", a.parts.len(), shown(&a.output));
            }
        }
    }
    Ok(())
}

/// `reference --partial`: rows `--rows` (all by default) into a partial file: the pilot's with
/// `--pilot-pass`, else the reference's (counts from `--pilot` unless uniform).
fn reference_part(a: &ReferenceArgs, r: &settings::ResolvedReference, part: &std::path::Path) -> Result<(), Failure> {
    check_partial_output(part, &reference_inputs(a))?;
    let (scene, opts) = (&r.scene, &r.options);
    let rows = band_of_rows(scene, a.rows.unwrap_or((0, scene.camera.height as u64)))?;
    start_threads(r.threads)?;
    let bar = progress_bar(a.common.quiet, rows.len() as u64, "reference", Unit::Rows);
    let tick = || bar.inc(1);
    let control = Control::with_progress(&tick);
    let start = std::time::Instant::now();
    if a.pilot_pass {
        let pilot = reference_pilot_rows(scene, opts, rows.clone(), control)?;
        bar.finish_and_clear();
        save_pilot_part(part, scene, opts, rows.clone(), &pilot, start.elapsed().as_secs_f64())?;
        say!("wrote {} (pilot rows {}:{} of {})", shown(part), rows.start, rows.end, scene.camera.height);
        return Ok(());
    }
    let counts = match (&a.pilot, opts.uniform) {
        (_, true) => None,
        (Some(p), false) => Some(reference_counts(opts, &read_pilot(p, scene, opts)?.pixels, scene.camera.width)?),
        (None, false) if rows.len() as u32 == scene.camera.height => {
            let pilot = reference_pilot_rows(scene, opts, 0..scene.camera.height, control)?;
            Some(reference_counts(opts, &pilot.pixels, scene.camera.width)?)
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
    say!("wrote {} (rows {}:{} of {})", shown(part), rows.start, rows.end, scene.camera.height);
    Ok(())
}

/// The files `reference` reads: its scene and, if given, its pilot.
fn reference_inputs(a: &ReferenceArgs) -> Vec<&Path> {
    std::iter::once(a.scene.as_path()).chain(a.pilot.as_deref()).collect()
}

pub(crate) fn cmd_reference(a: ReferenceArgs) -> Result<(), Failure> {
    refuse_unused(a.unused())?;
    let scene = Scene::load(&a.scene).map_err(input)?;
    let r = settings::resolve_reference(&scene, &ReferenceOverrides::from(&a))?;
    if let Some(part) = &a.partial {
        settings::check_exposure_applies(a.exposure, &[])?;
        return reference_part(&a, &r, part);
    }
    let scene = &r.scene;
    let output = a.output.clone().unwrap_or_else(|| default_output(scene, "_reference"));
    let mut outputs = vec![Output::Image(&output)];
    outputs.extend(a.stderr_image.as_deref().map(Output::Image));
    outputs.extend(a.schedule_record.as_deref().map(Output::File));
    let files = outputs.len();
    outputs.extend(a.watch.checkpoint.as_deref().map(Output::Directory));
    check_outputs(&outputs, &reference_inputs(&a))?;
    let images: Vec<&std::path::Path> = outputs[..files].iter().map(|o| o.path()).collect();
    settings::check_exposure_applies(a.exposure, &images)?;
    start_threads(r.threads)?;
    let passes = if r.options.uniform { 1 } else { 2 };
    let bar = progress_bar(a.common.quiet, passes * scene.camera.height as u64, "reference", Unit::Rows);
    let mut watch = ReferenceWatch::start(&a.watch, scene, &r.options, &bar)?;
    if let (Some(ck), 1..) = (&a.watch.checkpoint, watch.units_done()) {
        bar.set_position(watch.units_done());
        say!("resuming from {}: {} are done", shown(ck), watch.done());
    }
    let done = watch.take_done();
    let tick = || bar.inc(1);
    let strand = a.schedule_record.is_some().then(fogplanes::schedule::start);
    let mut control = Control::with_progress(&tick);
    if let Some(strand) = &strand {
        control = control.with_strand(strand);
    }
    let reference = render_reference_from(scene, &r.options, control, done, &mut |step| watch.step(step))?;
    if let Some(path) = &a.schedule_record {
        let record = serde_json::json!({
            "threads": rayon::current_num_threads(),
            "cut_for": rayon::current_num_threads(),
            "planes": 0,
            "width": scene.camera.width,
            "height": scene.camera.height,
            "estimator": "reference",
            "sections": fogplanes::schedule::finish(),
        });
        fogplanes::film::write_file_atomically(path, record.to_string().as_bytes())?;
    }
    bar.finish_and_clear();
    fogplanes::film::written_together(|| {
        reference.mean.save_with_info(&output, r.exposure, Some(&r.options.image_info(scene, false)))?;
        if let Some(p) = &a.stderr_image {
            reference.stderr.save_with_info(p, r.exposure, Some(&r.options.image_info(scene, true)))?;
        }
        Ok(())
    })?;
    watch.finish(&reference);
    say!(
        "reference: {} spp asked, {:.1} taken on average{}, {:.3} s, relative standard error {:.3e} (RMS over pixels / mean), noise MSE {:.3e} (x10^4: {:.3e})",
        r.options.spp,
        reference.samples,
        if r.options.uniform { "" } else { " (the pilot pass's included)" },
        reference.seconds,
        reference.relative_stderr(),
        reference.noise_mse(),
        reference.noise_mse() * 1e4
    );
    say!("wrote {}", shown(&output));
    Ok(())
}

/// Refuses a reference whose record says it was made for another pixel filter or resolution
/// than the image's ([`ImageInfo::check_reference`]), naming its file; warns on stderr when
/// they record different scenes. Images that record nothing (made elsewhere) pass.
fn check_reference(image: Option<&ImageInfo>, reference: Option<&ImageInfo>, path: &Path) -> Result<(), Failure> {
    let warning =
        ImageInfo::check_reference(image, reference).map_err(|e| input(anyhow!("{}: {e}", path.display())))?;
    if let Some(w) = warning {
        let _ = writeln!(std::io::stderr(), "warning: {}: {w}", shown(path));
    }
    Ok(())
}

pub(crate) fn cmd_compare(a: CompareArgs) -> Result<(), Failure> {
    // Before any file is read: the z-image is none of the images compared.
    if let Some(z) = &a.z_image {
        let inputs: Vec<&Path> =
            [Some(a.image.as_path()), Some(a.reference.as_path()), a.ref_stderr.as_deref(), a.stderr.as_deref()]
                .into_iter()
                .flatten()
                .collect();
        check_outputs(&[Output::Image(z)], &inputs)?;
    }
    let (image, image_info) = Film::load_exr_with_info(&a.image).map_err(input)?;
    let (reference, reference_info) = Film::load_exr_with_info(&a.reference).map_err(input)?;
    ImageInfo::check_is_image(image_info.as_ref(), "--stderr")
        .map_err(|e| input(anyhow!("{}: {e}", a.image.display())))?;
    check_reference(image_info.as_ref(), reference_info.as_ref(), &a.reference)?;
    // Each image's fault named with its file (compare's errors name the role alone).
    fn named(path: &Path) -> impl Fn(fogplanes::Error) -> Failure + '_ {
        move |e| input(anyhow!("{}: {e}", path.display()))
    }
    image.check_finite("image").map_err(named(&a.image))?;
    reference.check_finite("reference").map_err(named(&a.reference))?;
    let m = compare(&image, &reference).map_err(named(&a.reference))?;
    let Some(ref_se_path) = &a.ref_stderr else {
        if a.json {
            say!("{}", serde_json::to_string_pretty(&m).context("cannot format JSON")?);
        } else {
            print_metrics(&m);
        }
        return Ok(());
    };
    // Each standard error is checked against what its image records.
    let load_se = |path: &Path, of: Option<&ImageInfo>, what: &str| -> Result<Film, Failure> {
        let bad = |e: fogplanes::Error| input(anyhow!("{}: {e}", path.display()));
        let (film, info) = Film::load_exr_with_info(path).map_err(bad)?;
        ImageInfo::check_stderr(info.as_ref(), of).map_err(bad)?;
        fogplanes::metrics::check_stderr(&film, &image, what).map_err(bad)?;
        Ok(film)
    };
    let ref_se = load_se(ref_se_path, reference_info.as_ref(), "reference's standard error")?;
    let image_se =
        a.stderr.as_deref().map(|p| load_se(p, image_info.as_ref(), "image's standard error")).transpose()?;
    let (noisy, z) = compare_noisy(&image, &reference, &ref_se, image_se.as_ref(), a.regions).map_err(input)?;
    if let Some(path) = &a.z_image {
        let compared = format!("{} against {}", a.image.display(), a.reference.display());
        let info = ImageInfo::z_image(image_info.as_ref(), (z.width, z.height), &compared);
        z.save_with_info(path, 0.0, Some(&info))?;
    }
    if a.json {
        let both = serde_json::json!({ "metrics": m, "noise": noisy });
        say!("{}", serde_json::to_string_pretty(&both).context("cannot format JSON")?);
        return Ok(());
    }
    print_metrics(&m);
    say!("reference noise, mean s_r^2         {:.6e}", noisy.reference_noise);
    say!(
        "MSE - reference noise               {:.6e}  (the image's MSE against the truth, estimated)",
        noisy.mse_minus_reference_noise
    );
    if let (Some(noise), Some(excess)) = (noisy.image_noise, noisy.excess) {
        say!("image noise, mean s_e^2             {noise:.6e}");
        say!(
            "excess over both noises             {excess:.6e}  ({:+.1}% of the image's noise)",
            Fixed(100.0 * excess / noise.max(f64::MIN_POSITIVE))
        );
    }
    say!("mean z^2                            {:.4}  (1 when the noise explains the difference)", Fixed(noisy.mean_z2));
    say!("|z| > 3                             {:.3}%  (0.27% for normal noise)", 100.0 * noisy.beyond_3);
    if !noisy.regions.is_empty() {
        say!("regions the noise does not explain (|z| > 2, connected), largest excess first:");
        say!("  {:>17}  {:>6}  {:>11}  {:>11}  {:>7}", "pixels x, y", "count", "excess", "noise", "mean z");
        for r in &noisy.regions {
            let area = format!("{}-{}, {}-{}", r.x0, r.x1, r.y0, r.y1);
            say!("  {area:>17}  {:>6}  {:>11.4e}  {:>11.4e}  {:>+7.2}", r.pixels, r.excess, r.noise, Fixed(r.mean_z));
        }
    }
    if let Some(path) = &a.z_image {
        say!("wrote {} (z per pixel and channel)", shown(path));
    }
    Ok(())
}

fn print_metrics(m: &fogplanes::metrics::ErrorMetrics) {
    say!("SMAPE        {:.6}  (x10^2: {:.4})", Fixed(m.smape), Fixed(m.smape_e2()));
    say!("MSE          {:.6e}  (x10^4: {:.4})", m.mse, Fixed(m.mse_e4()));
    say!("relMSE       {:.6e}", m.rel_mse);
    say!("max |error|  {:.6e}", m.max_abs_error);
}

/// The files `table` writes into its directory; the plot's only with a sweep.
const TABLE_FILES: [&str; 3] = ["table.md", "table.json", "index.html"];
const TABLE_PLOTS: [&str; 2] = ["error_vs_time.png", "error_vs_time.svg"];

pub(crate) fn cmd_table(a: TableArgs) -> Result<(), Failure> {
    let scene = Scene::load(&a.scene).map_err(input)?;
    // The device is found after every refusal the arguments and files decide.
    let pending = settings::check_table(&scene, &TableOverrides::from(&a))?;
    let r = pending.settings();
    let scene = &r.scene;
    let (reference, reference_info) = Film::load_exr_with_info(&a.reference).map_err(input)?;
    reference.check_finite("reference").map_err(|e| input(anyhow!("{}: {e}", a.reference.display())))?;
    // The table's images record what `render` with its settings would.
    let cam = &scene.camera;
    let made = ImageInfo::new("render", &scene.name, scene.fingerprint(), (cam.width, cam.height), r.pixel_center)
        .with_medium_g(scene.medium.g);
    check_reference(Some(&made), reference_info.as_ref(), &a.reference)?;
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
    check_outputs(&outputs, &[&a.scene, &a.reference])?;
    let r = pending.find_device()?;
    start_threads(r.threads)?;
    let opts =
        TableOptions { settings: &r, out: a.out.clone(), quiet: a.common.quiet, reference_path: a.reference.clone() };
    let table = run_table(&reference, &opts)?;
    say!("{}", table);
    Ok(())
}

/// The files `scaling` writes into its directory besides its plot's PNG.
const SCALING_FILES: [&str; 3] = ["scaling.md", "scaling.json", "seconds_vs_hits.svg"];

pub(crate) fn cmd_scaling(a: ScalingArgs) -> Result<(), Failure> {
    let scene = Scene::load(&a.scene).map_err(input)?;
    if a.common.resolution.is_some() {
        return Err(input(anyhow!("--resolution: scaling measures the sizes of --resolutions")));
    }
    let pending = settings::check_scaling(&ScalingOverrides::from(&a))?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("{}: cannot create the output directory", a.out.display()))
        .map_err(input)?;
    let (plot, files) = (a.out.join("seconds_vs_hits.png"), SCALING_FILES.map(|f| a.out.join(f)));
    check_outputs(&[&[Output::Image(&plot)][..], &files.each_ref().map(|p| Output::File(p))].concat(), &[&a.scene])?;
    let r = pending.find_device()?;
    start_threads(r.threads)?;
    let md = experiments::run_scaling(&scene, &r, &a.out, a.common.quiet)?;
    say!("{md}");
    Ok(())
}

pub(crate) fn cmd_info(a: InfoArgs) -> Result<(), Failure> {
    let (info, (w, h)) = read_image_info(&a.image).map_err(input)?;
    match info {
        Some(info) => say!("{}", info.to_string().trim_end()),
        None => say!("{}: {w}x{h}, no record of how it was made (not written by fogplanes)", shown(&a.image)),
    }
    Ok(())
}

pub(crate) fn cmd_devices() -> Result<(), Failure> {
    let all = fogplanes::gpu::adapters().map_err(|e| input(anyhow!("{e}")))?;
    for a in &all {
        say!(
            "gpu:{}  {} ({}, {}), largest binding {} MiB{}",
            a.index,
            a.name,
            a.backend,
            a.kind,
            a.max_binding >> 20,
            if a.default { "  [default: --device gpu]" } else { "" }
        );
    }
    // FOGPLANES_GPU naming no adapter: the list stands, and `--device gpu` would refuse.
    if let Err(why) = fogplanes::gpu::default_adapter() {
        let _ = writeln!(std::io::stderr(), "warning: {why}: --device gpu refuses it");
    }
    Ok(())
}

pub(crate) fn cmd_export(a: ExportArgs) -> Result<(), Failure> {
    let mut scene = Scene::load(&a.scene).map_err(input)?;
    if let Some((w, h)) = a.resolution {
        scene = scene.with_resolution(w, h)?;
    }
    let output = a.output.clone().unwrap_or_else(|| PathBuf::from(format!("{}.xml", scene.name)));
    check_outputs(&[Output::File(&output)], &[&a.scene])?;
    let text = match a.format {
        ExportFormat::Mitsuba => fogplanes::export::mitsuba_xml(&scene),
    };
    write_file_atomically(&output, text.as_bytes())?;
    say!("wrote {} ({} lights, {}x{})", shown(&output), scene.lights.len(), scene.camera.width, scene.camera.height);
    Ok(())
}
