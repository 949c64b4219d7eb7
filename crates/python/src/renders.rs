//! The whole-image functions: `render`, `reference`, `compare`, `load_image`, `save_image`, `load_scene`.

use crate::args::*;
use crate::arrays::*;
use crate::errors::*;
use crate::given::*;
use crate::interrupt::*;
use crate::progress::Progress;
use crate::scene::*;
use crate::*;
use fogplanes::control::Control;
use fogplanes::film::Film;
use fogplanes::metrics::compare as compare_films;
use fogplanes::reference::render_reference;
use fogplanes::render::{Until, progress_units, render_until};
use fogplanes::settings::{self, Setting};
use fogplanes::weights::Estimator;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use std::time::Duration;

/// Reads and validates a scene file (TOML) at `path` (str, bytes or os.PathLike).
///
/// Raises FileNotFoundError (an OSError) if the file cannot be opened, ValueError naming the
/// file, line and field if its content is invalid, TypeError naming `path` for anything but a
/// path.
#[pyfunction]
pub(crate) fn load_scene(path: &Bound<'_, PyAny>) -> PyResult<PyScene> {
    load(&path_arg(path, "path")?).map(|inner| PyScene { inner })
}

/// Renders a scene with photon planes: the image, shape (height, width, 3), float32.
///
/// The arguments are those of `fogplanes render`, and None takes the scene's [render]
/// default exactly as the command line does (both resolve them in the core): `estimator` (the
/// scene's, else smis-exact), `planes`, `seed`, `spp`, `sampler` ("sobol" or "independent";
/// the scene's, else sobol), `lobes` (in fog that scatters forward or back, the share of each
/// light's planes swept along the phase function's lobe, 0 to 1: 0 for the paper's planes; the
/// scene's, else 0.5), and `orientations` (the scene's K applies only when the scene's
/// estimator is the one rendered). `resolution` is (width, height). Pixels are whole: the mean
/// over each pixel's square (box filter), with `spp` camera samples per pixel (the scene's, else
/// 16) sharing the planes; `pixel_center=True` takes the centres. `time_budget` renders for
/// that many seconds instead of a plane count: planes in passes, each extending the set (the
/// stats give "planes" and "plane_passes"); `target_error` renders passes until the estimated
/// relative RMS error of the image falls below it (with `time_budget`, whichever comes first;
/// the stats' "stopped_by" says which), or stops as soon as it is shown out of reach: below the
/// stats' "error_floor" (the direct emission's error, which planes do not lower), or a black
/// image. `threads` runs the render in a pool of that many
/// threads (None: all cores); the image depends on the seed alone. The image is bit-identical
/// to the EXR that `fogplanes render` writes for the same arguments. With
/// `return_stderr=True`, also the estimated standard error of each pixel (as `render
/// --stderr-image`); with `return_stats=True`, also the stats: (image[, stderr][, stats]).
/// `device="gpu"` gathers on the GPU through wgpu (ValueError without an adapter), `"auto"` on
/// a GPU when one is found (not an emulated adapter such as lavapipe, which `devices()` lists
/// too; else the CPU); the image agrees with the CPU's within f32 rounding (docs/gpu.md).
/// `progress=True` shows a progress bar on standard error (a line per tenth when it is not a
/// terminal, as in a notebook or a log).
///
/// Raises ValueError for bad input (the command line's message, the setting named as given
/// here: `planes=0: ...`), OSError for a scene file that cannot be opened, KeyboardInterrupt
/// on Ctrl-C. The GIL is released while rendering.
#[pyfunction]
#[pyo3(signature = (scene, estimator = None, **kwargs))]
#[pyo3(text_signature = "(scene, estimator=None, *, planes=None, seed=None, spp=None, pixel_center=False, \
    resolution=None, orientations=None, threads=None, accelerator='raster', kernel='auto', device='cpu', \
    return_stats=False, sampler=None, lobes=None, time_budget=None, target_error=None, return_stderr=False, progress=False)")]
pub(crate) fn render<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    estimator: Option<&Bound<'py, PyAny>>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let scene = scene_arg(scene)?;
    let mut given = Given::default();
    let (mut overrides, returns) = render_overrides(kwargs, &mut given, Front::Render)?;
    let estimator = estimator.filter(|e| !e.is_none());
    overrides.estimator = given.named::<Estimator>(Setting::Estimator, estimator)?.or(overrides.estimator);
    let r = settings::resolve_render(&scene, &overrides).map_err(|e| given.error(e))?;
    let (scene, opts) = (&r.scene, &r.options);
    let label = opts.weighting().label();
    let pool = pool(r.threads)?;
    // The units of the pool that renders (the raster's bands are sized for its workers).
    let units = || progress_units(scene, opts, 0..opts.planes());
    let progress = if !returns.progress {
        Progress::hidden()
    } else if r.in_passes() {
        Progress::passes(&label)
    } else {
        Progress::planes(&label, pool.as_ref().map_or_else(units, |p| p.install(units)), opts.planes() as u64)
    };
    let tick = || progress.tick();
    let (film, stats) = run_showing(
        py,
        pool,
        |cancel| {
            let control = Control::new(&tick, cancel);
            if r.in_passes() {
                let until = Until { budget: r.time_budget.map(Duration::from_secs_f64), target_error: r.target_error };
                render_until(scene, opts, until, control)
            } else {
                fogplanes::render::render(scene, opts, control)
            }
        },
        &progress,
    )?
    .map_err(|e| given.error(e))?;
    let mut out = vec![film_to_array(py, &film).into_any()];
    if let Some(se) = stats.stderr.as_ref().filter(|_| returns.stderr) {
        out.push(film_to_array(py, se).into_any());
    }
    if returns.stats {
        out.push(stats_dict(py, &stats)?.into_any());
    }
    if out.len() == 1 { Ok(out.pop().expect("the image")) } else { Ok(PyTuple::new(py, out)?.into_any()) }
}

/// Renders the independent reference: (image, per-pixel standard error), both float32.
///
/// As `fogplanes reference` with its -o and --stderr-image files: `spp` samples per pixel on
/// average, spread by need unless `uniform`; whole pixels (box filter, as `render`), or
/// `pixel_center` to compare with `render(..., pixel_center=True)`. Ctrl-C stops it with
/// KeyboardInterrupt.
#[pyfunction]
#[pyo3(signature = (scene, spp = None, **kwargs))]
#[pyo3(
    text_signature = "(scene, spp=1024, *, pixel_center=False, resolution=None, seed=1, uniform=False, threads=None)"
)]
pub(crate) fn reference<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    spp: Option<&Bound<'py, PyAny>>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Image<'py>, Image<'py>)> {
    let (r, given) = resolve_reference_args(scene, spp, kwargs, &REFERENCE_KEYWORDS)?;
    let image = run_interruptible(py, pool(r.threads)?, |cancel| {
        render_reference(&r.scene, &r.options, Control::with_cancel(cancel))
    })?
    .map_err(|e| given.error(e))?;
    Ok((film_to_array(py, &image.mean), film_to_array(py, &image.stderr)))
}

/// Error metrics of an image against a reference, as `fogplanes compare` prints them.
///
/// Both are arrays of shape (height, width, 3) (any real dtype, converted to float32 as the
/// EXR files hold them). Returns a dict: smape, mse, rel_mse (also under "relmse"), max_abs.
#[pyfunction]
pub(crate) fn compare<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    reference: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyDict>> {
    let image = image_arg(image, "image")?;
    let reference = image_arg(reference, "reference")?;
    let m = compare_films(&image, &reference).map_err(py_error)?;
    let d = PyDict::new(py);
    d.set_item("smape", m.smape)?;
    d.set_item("mse", m.mse)?;
    d.set_item("rel_mse", m.rel_mse)?;
    d.set_item("relmse", m.rel_mse)?;
    d.set_item("max_abs", m.max_abs_error)?;
    Ok(d)
}

/// Reads the first RGB(A) layer of an EXR file (`path`: str, bytes or os.PathLike) as an
/// array (height, width, 3), float32.
#[pyfunction]
pub(crate) fn load_image<'py>(py: Python<'py>, path: &Bound<'py, PyAny>) -> PyResult<Image<'py>> {
    let path = path_arg(path, "path")?;
    let film = Film::load_exr(&path).map_err(|e| file_error(&path, e.to_string()))?;
    // As every image read is checked: a NaN or an infinity is named, not handed on.
    film.check_finite("image").map_err(|e| PyValueError::new_err(format!("{}: {e}", path.display())))?;
    Ok(film_to_array(py, &film))
}

/// Writes an array (height, width, 3) as .exr (linear float32) or .png (tone-mapped sRGB by
/// `exposure` stops), whole or not at all, as the command line writes its images; an exposure
/// with an .exr path is refused, as on the command line.
#[pyfunction]
#[pyo3(signature = (path, image, exposure = None))]
#[pyo3(text_signature = "(path, image, exposure=None)")]
pub(crate) fn save_image(
    py: Python<'_>,
    path: &Bound<'_, PyAny>,
    image: &Bound<'_, PyAny>,
    exposure: Option<&Bound<'_, PyAny>>,
) -> PyResult<()> {
    let path = path_arg(path, "path")?;
    let mut given = Given::default();
    let stops = given.float(Setting::Exposure, exposure)?.map(|e| e as f32);
    let exposure = settings::exposure(stops).map_err(|e| given.error(e))?;
    let film = image_arg(image, "image")?;
    film.check_finite("image").map_err(py_error)?;
    fogplanes::outputs::check_outputs(&[fogplanes::outputs::Output::Image(&path)], &[])
        .map_err(|e| output_error(&path, e))?;
    settings::check_exposure_applies(stops, &[&path]).map_err(|e| given.error(e))?;
    py.detach(|| film.save(&path, exposure)).map_err(py_error)
}
