//! The native part of the Python package `fogplanes`: scenes, the photon-plane renderer, the
//! reference and the metrics of the core library, with images as numpy arrays of shape
//! (height, width, 3) and float32.
//!
//! Everything a call can fail with is a Python exception: `ValueError` for bad input, with the
//! command line's one-line message, a setting named as the caller gave it (`planes=0: ...`
//! where the command line says `--planes: ...`); `OSError` (or its subclass
//! `FileNotFoundError`, ...) for a file that cannot be read. The settings are resolved by the
//! core (`fogplanes::settings`), as for the command line: the same defaults, the same checks. Renders run on a worker
//! thread with the GIL released, while the calling thread watches for signals: Ctrl-C sets the
//! core's cancel flag and raises `KeyboardInterrupt` once the work under way has stopped.

use fogplanes::Error;
use fogplanes::control::Control;
use fogplanes::film::Film;
use fogplanes::kernel::Kernel;
use fogplanes::metrics::compare as compare_films;
use fogplanes::partial::{self, Partial, stable_hash};
use fogplanes::reference::{self as refs, render_reference};
use fogplanes::render::{Accelerator, RenderStats, render_for};
use fogplanes::sampling::Sampler;
use fogplanes::scene::Scene;
use fogplanes::settings::{self, Overrides, ReferenceOverrides, Setting};
use fogplanes::weights::Estimator;
use numpy::ndarray::Array3;
use numpy::{AllowTypeChange, PyArray2, PyArray3, PyArrayLike2, PyArrayLike3};
use pyo3::exceptions::{
    PyFileNotFoundError, PyIsADirectoryError, PyOSError, PyOverflowError, PyPermissionError, PyRuntimeError,
    PyTypeError, PyValueError,
};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};
use std::io::ErrorKind;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

type Vec3 = (f64, f64, f64);

/// What a pickled scene is rebuilt from: text, name, file, (width, height).
type SceneParts = (String, String, String, (u32, u32));

/// An image for Python: shape (height, width, 3), float32.
type Image<'py> = Bound<'py, PyArray3<f32>>;

fn triple(v: glam::DVec3) -> Vec3 {
    (v.x, v.y, v.z)
}

// ---------------------------------------------------------------------------------------------
// Errors

/// The exception for a library error, a setting named by `name`: `ValueError` for the
/// caller's input, `OSError` for a write that failed, `RuntimeError` for cancelled work.
fn py_error_named(e: Error, name: impl Fn(Setting) -> String) -> PyErr {
    match e {
        Error::Write { .. } => PyOSError::new_err(e.to_string()),
        Error::Cancelled => PyRuntimeError::new_err("the work was cancelled"),
        e => PyValueError::new_err(e.worded(name)),
    }
}

/// [`py_error_named`] with settings named by their keyword alone.
fn py_error(e: Error) -> PyErr {
    py_error_named(e, |s| s.keyword().to_string())
}

/// The `OSError` subclass Python raises for an I/O error of this kind.
fn os_error(kind: ErrorKind, message: String) -> PyErr {
    match kind {
        ErrorKind::NotFound => PyFileNotFoundError::new_err(message),
        ErrorKind::PermissionDenied => PyPermissionError::new_err(message),
        ErrorKind::IsADirectory => PyIsADirectoryError::new_err(message),
        _ => PyOSError::new_err(message),
    }
}

/// The exception for a file that `read` failed on with `message`: an `OSError` if the file
/// itself cannot be opened (missing, a directory, unreadable), else `ValueError` (its content).
fn file_error(path: &Path, message: String) -> PyErr {
    match std::fs::metadata(path) {
        Err(e) => os_error(e.kind(), message),
        Ok(m) if m.is_dir() => PyIsADirectoryError::new_err(message),
        Ok(_) => match std::fs::File::open(path) {
            Err(e) => os_error(e.kind(), message),
            Ok(_) => PyValueError::new_err(message),
        },
    }
}

// ---------------------------------------------------------------------------------------------
// Arguments

/// The settings a caller gave, as Python shows them, so that an error names a setting the way
/// the caller wrote it (`planes=0: ...`), and never a command-line flag.
#[derive(Default)]
struct Given {
    reprs: Vec<(Setting, String)>,
}

impl Given {
    /// `keyword=value` of a setting given, the keyword alone of one not given.
    fn name(&self, setting: Setting) -> String {
        match self.reprs.iter().rev().find(|(s, _)| *s == setting) {
            Some((_, repr)) => format!("{}={repr}", setting.keyword()),
            None => setting.keyword().to_string(),
        }
    }

    fn error(&self, e: Error) -> PyErr {
        py_error_named(e, |s| self.name(s))
    }

    fn invalid(&self, setting: Setting, message: impl std::fmt::Display) -> PyErr {
        PyValueError::new_err(format!("{}: {message}", self.name(setting)))
    }

    fn note(&mut self, setting: Setting, value: &Bound<'_, PyAny>) -> PyResult<()> {
        self.reprs.push((setting, value.repr()?.to_string()));
        Ok(())
    }

    /// A non-negative integer: a Python int out of range is a `ValueError` naming the setting,
    /// anything but an int a `TypeError`.
    fn uint(&mut self, setting: Setting, value: Option<&Bound<'_, PyAny>>) -> PyResult<Option<u64>> {
        let Some(v) = value else { return Ok(None) };
        self.note(setting, v)?;
        match v.extract::<u64>() {
            Ok(n) => Ok(Some(n)),
            Err(e) if e.is_instance_of::<PyOverflowError>(v.py()) => {
                Err(self.invalid(setting, "out of range (a non-negative integer below 2**64)"))
            }
            Err(e) => Err(PyTypeError::new_err(format!("{}: expected an integer ({e})", setting.keyword()))),
        }
    }

    /// A `u32` (out of range as in [`Given::uint`]).
    fn uint32(&mut self, setting: Setting, value: Option<&Bound<'_, PyAny>>) -> PyResult<Option<u32>> {
        self.uint(setting, value)?
            .map(|n| u32::try_from(n).map_err(|_| self.invalid(setting, "out of range (an integer below 2**32)")))
            .transpose()
    }

    /// A number of seconds or stops (a float, or an int).
    fn float(&mut self, setting: Setting, value: Option<&Bound<'_, PyAny>>) -> PyResult<Option<f64>> {
        let Some(v) = value else { return Ok(None) };
        self.note(setting, v)?;
        v.extract::<f64>()
            .map(Some)
            .map_err(|e| PyTypeError::new_err(format!("{}: expected a number ({e})", setting.keyword())))
    }

    /// A name from a closed list (estimator, sampler, ...).
    fn named<T: std::str::FromStr<Err = String>>(
        &mut self,
        setting: Setting,
        value: Option<&str>,
    ) -> PyResult<Option<T>> {
        let Some(v) = value else { return Ok(None) };
        self.reprs.push((setting, py_str(v)));
        v.parse().map(Some).map_err(|m| self.invalid(setting, m))
    }

    /// `(width, height)`.
    fn resolution(&mut self, value: Option<&Bound<'_, PyAny>>) -> PyResult<Option<(u32, u32)>> {
        let Some(v) = value else { return Ok(None) };
        let (w, h): (Bound<PyAny>, Bound<PyAny>) =
            v.extract().map_err(|_| PyTypeError::new_err(format!("resolution: expected (width, height), got {v}")))?;
        let (w, h) = (self.uint32(Setting::Resolution, Some(&w))?, self.uint32(Setting::Resolution, Some(&h))?);
        self.note(Setting::Resolution, v)?;
        Ok(w.zip(h))
    }

    /// A thread count (its range is the core's to check).
    fn threads(&mut self, value: Option<&Bound<'_, PyAny>>) -> PyResult<Option<usize>> {
        self.uint(Setting::Threads, value)?
            .map(|t| usize::try_from(t).map_err(|_| self.invalid(Setting::Threads, "out of range")))
            .transpose()
    }
}

fn load(path: &Path) -> PyResult<Scene> {
    Scene::load(path).map_err(|e| file_error(path, e.to_string()))
}

/// The scene of a `scene` argument: a `Scene`, or the path of a scene file (str or
/// os.PathLike).
fn scene_arg(scene: &Bound<'_, PyAny>) -> PyResult<Scene> {
    if let Ok(s) = scene.cast::<PyScene>() {
        Ok(s.get().inner.clone())
    } else if let Ok(path) = scene.extract::<PathBuf>() {
        load(&path)
    } else {
        Err(PyTypeError::new_err(format!(
            "scene: expected a fogplanes.Scene or the path of a scene file, got {}",
            scene.get_type().name()?
        )))
    }
}

/// The worker pool of `threads` resolved (None: rayon's global pool).
fn pool(threads: Option<usize>) -> PyResult<Option<rayon::ThreadPool>> {
    let Some(t) = threads else { return Ok(None) };
    rayon::ThreadPoolBuilder::new()
        .num_threads(t)
        .thread_name(|i| format!("fogplanes-{i}"))
        .build()
        .map(Some)
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start the worker threads: {e}")))
}

// ---------------------------------------------------------------------------------------------
// Running work interruptibly

/// Runs `work` on a worker thread (inside `pool` if given) with the GIL released, checking for
/// signals on this thread every 50 ms. A signal's exception (KeyboardInterrupt for Ctrl-C) sets
/// the cancel flag, waits for the worker to stop and is raised. A panic becomes RuntimeError.
/// The work's own error is the library's, for the caller to word.
fn run_interruptible<T: Send>(
    py: Python<'_>,
    pool: Option<rayon::ThreadPool>,
    work: impl FnOnce(&AtomicBool) -> fogplanes::Result<T> + Send,
) -> PyResult<fogplanes::Result<T>> {
    let cancel = AtomicBool::new(false);
    let (tx, rx) = mpsc::channel();
    std::thread::scope(|s| {
        let cancel = &cancel;
        std::thread::Builder::new()
            .name("fogplanes-render".into())
            .spawn_scoped(s, move || {
                let run = || work(cancel);
                let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match &pool {
                    Some(p) => p.install(run),
                    None => run(),
                }));
                let _ = tx.send(result);
            })
            .map_err(|e| PyRuntimeError::new_err(format!("cannot start the render thread: {e}")))?;
        let mut rx = rx;
        loop {
            // The receiver is not Sync: it moves into the closure that runs without the GIL.
            let (received, back) = py.detach(move || (rx.recv_timeout(Duration::from_millis(50)), rx));
            rx = back;
            match received {
                Ok(Ok(result)) => return Ok(result),
                Ok(Err(panic)) => {
                    let what = panic
                        .downcast_ref::<&str>()
                        .map(|s| s.to_string())
                        .or_else(|| panic.downcast_ref::<String>().cloned())
                        .unwrap_or_else(|| "unknown".into());
                    return Err(PyRuntimeError::new_err(format!("fogplanes: internal error: {what}")));
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    if let Err(signal) = py.check_signals() {
                        cancel.store(true, Ordering::Relaxed);
                        py.detach(move || {
                            let _ = rx.recv();
                        });
                        return Err(signal);
                    }
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    return Err(PyRuntimeError::new_err("fogplanes: the render thread ended without a result"));
                }
            }
        }
    })
}

// ---------------------------------------------------------------------------------------------
// Images

fn film_to_array<'py>(py: Python<'py>, film: &Film) -> Image<'py> {
    let (w, h) = (film.width as usize, film.height as usize);
    let flat: Vec<f32> = film.pixels.iter().flat_map(|p| p.to_array()).collect();
    let array = Array3::from_shape_vec((h, w, 3), flat).unwrap_or_else(|_| Array3::zeros((h, w, 3)));
    PyArray3::from_owned_array(py, array)
}

/// The shape of an array as Python writes it: `(2, 3)`, `(5,)`.
fn shape_text(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!("({})", shape.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", ")),
    }
}

/// The image of an array-like argument (any real dtype), its shape checked against the
/// renderer's limits before anything is converted: a broadcast or float64 array that claims a
/// huge shape costs nothing until converted to float32.
fn image_arg(image: &Bound<'_, PyAny>, what: &str) -> PyResult<Film> {
    let py = image.py();
    // Arrays keep their own shape (no copy); nested lists become one to have one.
    let array = match image.getattr("shape") {
        Ok(_) => image.clone(),
        Err(_) => py.import("numpy")?.call_method1("asarray", (image,))?,
    };
    let Ok(shape) = array.getattr("shape")?.extract::<Vec<usize>>() else {
        return Err(PyTypeError::new_err(format!("{what}: expected an array, got {}", image.get_type().name()?)));
    };
    let [h, w, 3] = shape[..] else {
        return Err(PyValueError::new_err(format!(
            "{what}: expected an array of shape (height, width, 3), got {}",
            shape_text(&shape)
        )));
    };
    let side = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
    fogplanes::limits::check_resolution(side(w), side(h)).map_err(|m| PyValueError::new_err(format!("{what}: {m}")))?;
    let array: PyArrayLike3<'_, f32, AllowTypeChange> = array.extract()?;
    let view = array.as_array();
    let mut film = Film::new(w as u32, h as u32);
    for ((y, x), p) in (0..h).flat_map(|y| (0..w).map(move |x| (y, x))).zip(film.pixels.iter_mut()) {
        *p = glam::Vec3::new(view[[y, x, 0]], view[[y, x, 1]], view[[y, x, 2]]);
    }
    Ok(film)
}

fn stats_dict<'py>(py: Python<'py>, s: &RenderStats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("estimator", &s.estimator)?;
    d.set_item("kernel", &s.kernel)?;
    d.set_item("planes", s.planes)?;
    d.set_item("plane_passes", s.plane_passes)?;
    d.set_item("rays", s.rays)?;
    d.set_item("hits", s.hits)?;
    d.set_item("tests", s.tests)?;
    d.set_item("seconds_sampling", s.seconds_sampling)?;
    d.set_item("seconds_build", s.seconds_build)?;
    d.set_item("seconds_rays", s.seconds_rays)?;
    d.set_item("seconds_gather", s.seconds_gather)?;
    d.set_item("seconds_total", s.seconds_total)?;
    d.set_item("hits_per_ray", s.hits_per_ray())?;
    d.set_item("gather_ns_per_hit", s.gather_ns_per_hit())?;
    d.set_item("summary", s.summary())?;
    Ok(d)
}

// ---------------------------------------------------------------------------------------------
// Scenes

/// A validated scene: camera, fog box, rectangular lights and render defaults. Read-only.
///
/// Made by `fogplanes.load_scene(path)` or `Scene.from_toml(text)`.
#[pyclass(frozen, module = "fogplanes", name = "Scene")]
struct PyScene {
    inner: Scene,
}

/// The pinhole camera of a scene.
#[pyclass(frozen, get_all, module = "fogplanes", name = "Camera")]
struct PyCamera {
    /// Position of the pinhole.
    position: Vec3,
    /// Unit view direction.
    forward: Vec3,
    /// Unit right vector of the image plane.
    right: Vec3,
    /// Unit up vector of the image plane (orthogonal to forward).
    up: Vec3,
    /// Vertical field of view in degrees.
    vfov_deg: f64,
    /// (width, height) in pixels.
    resolution: (u32, u32),
}

/// The homogeneous fog: an axis-aligned box, vacuum outside.
#[pyclass(frozen, get_all, module = "fogplanes", name = "Medium")]
struct PyMedium {
    /// Lower corner of the box.
    min: Vec3,
    /// Upper corner of the box.
    max: Vec3,
    /// Scattering coefficient, RGB, per unit length.
    sigma_s: Vec3,
    /// Absorption coefficient, RGB, per unit length.
    sigma_a: Vec3,
    /// Extinction sigma_s + sigma_a.
    sigma_t: Vec3,
}

/// A one-sided rectangular light: corner + p edge_u/|edge_u| + q edge_v/|edge_v|.
#[pyclass(frozen, get_all, module = "fogplanes", name = "Light")]
struct PyLight {
    /// The light's name (`light<i>` when the file gives none).
    name: String,
    corner: Vec3,
    /// First edge (|edge_u| times its unit direction, as stored after validation).
    edge_u: Vec3,
    /// Second edge, orthogonal to the first.
    edge_v: Vec3,
    /// Unit normal normalize(edge_u x edge_v): the side it emits to.
    normal: Vec3,
    /// Emitted radiance, RGB.
    radiance: Vec3,
    /// Area |edge_u| |edge_v|.
    area: f64,
}

/// The scene file's `[render]` defaults (after defaults were filled in).
#[pyclass(frozen, get_all, module = "fogplanes", name = "RenderDefaults")]
struct PyRenderDefaults {
    planes: u64,
    estimator: String,
    orientations: u32,
    seed: u64,
    spp: u32,
}

/// A string as Python's repr writes it (for names without quotes or escapes, which is all of them
/// in practice; others are shown Rust's way).
fn py_str(s: &str) -> String {
    if s.chars().all(|c| c != '\'' && c != '\\' && !c.is_control()) { format!("'{s}'") } else { format!("{s:?}") }
}

fn fmt3(v: Vec3) -> String {
    format!("({}, {}, {})", v.0, v.1, v.2)
}

#[pymethods]
impl PyCamera {
    fn __repr__(&self) -> String {
        format!(
            "Camera(position={}, vfov_deg={}, resolution={:?})",
            fmt3(self.position),
            self.vfov_deg,
            self.resolution
        )
    }
}

#[pymethods]
impl PyMedium {
    fn __repr__(&self) -> String {
        format!(
            "Medium(min={}, max={}, sigma_s={}, sigma_a={})",
            fmt3(self.min),
            fmt3(self.max),
            fmt3(self.sigma_s),
            fmt3(self.sigma_a)
        )
    }
}

#[pymethods]
impl PyLight {
    fn __repr__(&self) -> String {
        format!(
            "Light(name={}, corner={}, edge_u={}, edge_v={}, radiance={})",
            py_str(&self.name),
            fmt3(self.corner),
            fmt3(self.edge_u),
            fmt3(self.edge_v),
            fmt3(self.radiance)
        )
    }
}

#[pymethods]
impl PyRenderDefaults {
    fn __repr__(&self) -> String {
        format!(
            "RenderDefaults(planes={}, estimator={}, orientations={}, seed={}, spp={})",
            self.planes,
            py_str(&self.estimator),
            self.orientations,
            self.seed,
            self.spp
        )
    }
}

#[pymethods]
impl PyScene {
    /// Parses and validates scene text (TOML, the schema of media_scenes/*.toml).
    ///
    /// `name` is the scene's name; `file` names the text in error messages. Raises ValueError
    /// with the file, line, field and problem for anything invalid.
    #[staticmethod]
    #[pyo3(signature = (text, name = "scene", file = "<string>"))]
    fn from_toml(text: &str, name: &str, file: &str) -> PyResult<Self> {
        Scene::parse(text, file, name).map(|inner| PyScene { inner }).map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// The scene made from its text, name, file and resolution: what a pickled scene is
    /// rebuilt with (`__reduce__`).
    #[staticmethod]
    fn _from_parts(text: &str, name: &str, file: &str, resolution: (u32, u32)) -> PyResult<Self> {
        let scene = Scene::parse(text, file, name).map_err(|e| PyValueError::new_err(e.to_string()))?;
        scene.with_resolution(resolution.0, resolution.1).map(|inner| PyScene { inner }).map_err(py_error)
    }

    /// Pickles as its text, name, file and resolution (not a pointer): a scene travels to
    /// another process (a Dask worker) and is rebuilt there, identical.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, SceneParts)> {
        let s = &slf.get().inner;
        let source = s.source().ok_or_else(|| PyValueError::new_err("this scene has no text to pickle"))?;
        let make = slf.get_type().getattr("_from_parts")?;
        Ok((make, (source.text.clone(), s.name.clone(), source.file.clone(), (s.camera.width, s.camera.height))))
    }

    /// A stable token (32 hex digits, the same in every process and run): a hash of the
    /// scene's text, name, file and resolution, for Dask's task keys.
    fn __dask_tokenize__(&self) -> String {
        let s = &self.inner;
        let (text, file) = s.source().map_or(("", ""), |src| (src.text.as_str(), src.file.as_str()));
        let resolution = format!("{}x{}", s.camera.width, s.camera.height);
        stable_hash(&[text.as_bytes(), s.name.as_bytes(), file.as_bytes(), resolution.as_bytes()])
    }

    /// The TOML text the scene was made from.
    #[getter]
    fn source(&self) -> String {
        self.inner.source().map(|s| s.text.clone()).unwrap_or_default()
    }

    /// The file name the scene's errors cite (`<string>` for from_toml's default).
    #[getter]
    fn file(&self) -> String {
        self.inner.source().map(|s| s.file.clone()).unwrap_or_default()
    }

    /// The same scene at another resolution.
    fn with_resolution(&self, width: &Bound<'_, PyAny>, height: &Bound<'_, PyAny>) -> PyResult<Self> {
        let mut given = Given::default();
        let w = given.uint32(Setting::Resolution, Some(width))?.unwrap_or_default();
        let h = given.uint32(Setting::Resolution, Some(height))?.unwrap_or_default();
        given.reprs.push((Setting::Resolution, format!("({w}, {h})")));
        self.inner.with_resolution(w, h).map(|inner| PyScene { inner }).map_err(|e| given.error(e))
    }

    /// The file stem (or the name given to from_toml).
    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }

    /// (width, height) in pixels.
    #[getter]
    fn resolution(&self) -> (u32, u32) {
        (self.inner.camera.width, self.inner.camera.height)
    }

    #[getter]
    fn camera(&self) -> PyCamera {
        let c = &self.inner.camera;
        PyCamera {
            position: triple(c.position),
            forward: triple(c.forward),
            right: triple(c.right),
            up: triple(c.up),
            vfov_deg: (2.0 * c.tan_half_fov.atan()).to_degrees(),
            resolution: (c.width, c.height),
        }
    }

    #[getter]
    fn medium(&self) -> PyMedium {
        let m = &self.inner.medium;
        PyMedium {
            min: triple(m.min),
            max: triple(m.max),
            sigma_s: triple(m.sigma_s),
            sigma_a: triple(m.sigma_a),
            sigma_t: triple(m.sigma_t()),
        }
    }

    /// The lights, in file order.
    #[getter]
    fn lights(&self) -> Vec<PyLight> {
        self.inner
            .lights
            .iter()
            .map(|l| PyLight {
                name: l.name.clone(),
                corner: triple(l.corner),
                edge_u: triple(l.u * l.width),
                edge_v: triple(l.v * l.height),
                normal: triple(l.n),
                radiance: triple(l.radiance),
                area: l.area(),
            })
            .collect()
    }

    /// The `[render]` defaults: planes, estimator, orientations, seed, spp.
    #[getter]
    fn render(&self) -> PyRenderDefaults {
        let r = &self.inner.render;
        PyRenderDefaults {
            planes: r.planes,
            estimator: r.weighting.estimator.name().to_string(),
            orientations: r.weighting.orientations,
            seed: r.seed,
            spp: r.spp,
        }
    }

    fn __repr__(&self) -> String {
        let s = &self.inner;
        format!(
            "Scene(name={}, resolution={}x{}, lights={})",
            py_str(&s.name),
            s.camera.width,
            s.camera.height,
            s.lights.len()
        )
    }
}

// ---------------------------------------------------------------------------------------------
// Functions

/// Reads and validates a scene file (TOML).
///
/// Raises FileNotFoundError (an OSError) if the file cannot be opened, ValueError naming the
/// file, line and field if its content is invalid.
#[pyfunction]
fn load_scene(path: PathBuf) -> PyResult<PyScene> {
    load(&path).map(|inner| PyScene { inner })
}

/// Renders a scene with photon planes: the image, shape (height, width, 3), float32.
///
/// The arguments are those of `fogplanes render`, and None takes the scene's [render]
/// default exactly as the command line does (both resolve them in the core): `estimator` (the
/// scene's, else smis-exact), `planes`, `seed`, `spp`, `sampler` ("sobol" or "independent";
/// the scene's, else sobol), and `orientations` (the scene's K applies only when the scene's
/// estimator is the one rendered). `resolution` is (width, height). Pixels are whole: the mean
/// over each pixel's square (box filter), with `spp` camera samples per pixel (the scene's, else
/// 16) sharing the planes; `pixel_center=True` takes the centres. `time_budget` renders for
/// that many seconds instead of a plane count: planes in passes, each extending the set (the
/// stats give "planes" and "plane_passes"). `threads` runs the render in a pool of that many
/// threads (None: all cores); the image depends on the seed alone. The image is bit-identical
/// to the EXR that `fogplanes render` writes for the same
/// arguments. With `return_stats=True`, returns (image, stats).
///
/// Raises ValueError for bad input (the command line's message, the setting named as given
/// here: `planes=0: ...`), OSError for a scene file that cannot be opened, KeyboardInterrupt
/// on Ctrl-C. The GIL is released while rendering.
#[pyfunction]
#[pyo3(signature = (scene, estimator = None, **kwargs))]
#[pyo3(text_signature = "(scene, estimator=None, planes=None, seed=None, spp=None, pixel_center=False, \
    resolution=None, orientations=None, threads=None, accelerator='raster', kernel='auto', return_stats=False, \
    sampler=None, time_budget=None)")]
fn render<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    estimator: Option<&str>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let scene = scene_arg(scene)?;
    let mut given = Given::default();
    let (mut overrides, return_stats) = render_overrides(kwargs, &mut given, Front::Render)?;
    overrides.estimator = given.named::<Estimator>(Setting::Estimator, estimator)?.or(overrides.estimator);
    let r = settings::resolve_render(&scene, &overrides).map_err(|e| given.error(e))?;
    let (film, stats) = run_interruptible(py, pool(r.threads)?, |cancel| match r.time_budget {
        None => fogplanes::render::render(&r.scene, &r.options, Control::with_cancel(cancel)),
        Some(seconds) => {
            render_for(&r.scene, &r.options, Duration::from_secs_f64(seconds), Control::with_cancel(cancel))
        }
    })?
    .map_err(|e| given.error(e))?;
    let image = film_to_array(py, &film).into_any();
    if return_stats { Ok(PyTuple::new(py, [image, stats_dict(py, &stats)?.into_any()])?.into_any()) } else { Ok(image) }
}

/// Renders the independent reference: (image, per-pixel standard error), both float32.
///
/// As `fogplanes reference` with its -o and --stderr-image files: `spp` samples per pixel on
/// average, spread by need unless `uniform`; whole pixels (box filter, as `render`), or
/// `pixel_center` to compare with `render(..., pixel_center=True)`. Ctrl-C stops it with
/// KeyboardInterrupt.
#[pyfunction]
#[pyo3(signature = (scene, spp = None, **kwargs))]
#[pyo3(text_signature = "(scene, spp=1024, pixel_center=False, resolution=None, seed=1, uniform=False, threads=None)")]
fn reference<'py>(
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
fn compare<'py>(
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

/// Reads the first RGB(A) layer of an EXR file as an array (height, width, 3), float32.
#[pyfunction]
fn load_image<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Image<'py>> {
    let film = Film::load_exr(&path).map_err(|e| file_error(&path, e.to_string()))?;
    Ok(film_to_array(py, &film))
}

/// Writes an array (height, width, 3) as .exr (linear float32) or .png (tone-mapped sRGB by
/// `exposure` stops), whole or not at all, as the command line writes its images.
#[pyfunction]
#[pyo3(signature = (path, image, exposure = None))]
#[pyo3(text_signature = "(path, image, exposure=0.0)")]
fn save_image(
    py: Python<'_>,
    path: PathBuf,
    image: &Bound<'_, PyAny>,
    exposure: Option<&Bound<'_, PyAny>>,
) -> PyResult<()> {
    let mut given = Given::default();
    let exposure = given.float(Setting::Exposure, exposure)?;
    let exposure = settings::exposure(exposure.map(|e| e as f32)).map_err(|e| given.error(e))?;
    let film = image_arg(image, "image")?;
    fogplanes::outputs::check_outputs(&[fogplanes::outputs::Output::Image(&path)]).map_err(py_error)?;
    py.detach(|| film.save(&path, exposure)).map_err(py_error)
}

// ---------------------------------------------------------------------------------------------
// Renders in chunks, references in row bands (the cluster layer, fogplanes.distributed)

/// Which function's keyword arguments [`render_overrides`] parses.
#[derive(Clone, Copy, PartialEq)]
enum Front {
    /// `render`: also `time_budget` and `return_stats`.
    Render,
    /// The chunked functions (`plan_render`, `render_chunk`, `finish_render`): a plane count.
    Chunks,
}

/// A keyword argument that is a flag (None: false).
fn flag(value: &Option<Bound<'_, PyAny>>) -> PyResult<bool> {
    Ok(value.as_ref().map(|v| v.extract()).transpose()?.unwrap_or(false))
}

/// The render settings of `**kwargs`: the keyword arguments of `render`, by the same names,
/// parsed in one place for every function that takes them; and `return_stats` (`render` only).
fn render_overrides(
    kwargs: Option<&Bound<'_, PyDict>>,
    given: &mut Given,
    front: Front,
) -> PyResult<(Overrides, bool)> {
    let (mut o, mut return_stats) = (Overrides::default(), false);
    let Some(kwargs) = kwargs else { return Ok((o, return_stats)) };
    for (key, value) in kwargs.iter() {
        let key: String = key.extract()?;
        let value = (!value.is_none()).then_some(value);
        let text =
            |v: &Option<Bound<'_, PyAny>>| -> PyResult<Option<String>> { v.as_ref().map(|v| v.extract()).transpose() };
        match key.as_str() {
            "estimator" => o.estimator = given.named(Setting::Estimator, text(&value)?.as_deref())?,
            "orientations" => o.orientations = given.uint32(Setting::Orientations, value.as_ref())?,
            "planes" => o.planes = given.uint(Setting::Planes, value.as_ref())?,
            "seed" => o.seed = given.uint(Setting::Seed, value.as_ref())?,
            "sampler" => o.sampler = given.named(Setting::Sampler, text(&value)?.as_deref())?,
            "spp" => o.spp = given.uint32(Setting::Spp, value.as_ref())?,
            "pixel_center" => o.pixel_center = flag(&value)?,
            "accelerator" => o.accelerator = given.named(Setting::Accelerator, text(&value)?.as_deref())?,
            "kernel" => o.kernel = given.named(Setting::Kernel, text(&value)?.as_deref())?,
            "resolution" => o.resolution = given.resolution(value.as_ref())?,
            "threads" => o.threads = given.threads(value.as_ref())?,
            "time_budget" if front == Front::Render => {
                o.time_budget = given.float(Setting::TimeBudget, value.as_ref())?;
            }
            "return_stats" if front == Front::Render => return_stats = flag(&value)?,
            "time_budget" if value.is_some() => {
                return Err(PyValueError::new_err(
                    "time_budget: a render in chunks has a plane count; give planes= instead",
                ));
            }
            "time_budget" => {}
            other => return Err(PyTypeError::new_err(format!("unexpected keyword argument '{other}'"))),
        }
    }
    Ok((o, return_stats))
}

/// The render `scene` and `**kwargs` describe, resolved as `render` resolves it.
fn resolve_chunked(
    scene: &Bound<'_, PyAny>,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<(settings::ResolvedRender, Given)> {
    let scene = scene_arg(scene)?;
    let mut given = Given::default();
    let (overrides, _) = render_overrides(kwargs, &mut given, Front::Chunks)?;
    let r = settings::resolve_render(&scene, &overrides).map_err(|e| given.error(e))?;
    Ok((r, given))
}

/// The plan of a render in chunks: its resolved settings (the keyword arguments of `render`),
/// `planes` N, `chunk_planes` (a fixed power of two), `chunks` (the (start, end) plane ranges,
/// in order, covering 0..N), `fingerprint` (the scene and every setting that changes the
/// image) and `shape` (height, width, 3). Raises ValueError as `render` does.
#[pyfunction]
#[pyo3(signature = (scene, **kwargs))]
fn plan_render<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let (r, given) = resolve_chunked(scene, kwargs)?;
    let (scene, o) = (&r.scene, &r.options);
    o.validate(scene).map_err(|e| given.error(e))?;
    let d = PyDict::new(py);
    d.set_item("planes", o.planes)?;
    d.set_item("chunk_planes", partial::CHUNK_PLANES)?;
    let chunks: Vec<(usize, usize)> = partial::chunks(o.planes).into_iter().map(|c| (c.start, c.end)).collect();
    d.set_item("chunks", chunks)?;
    d.set_item("fingerprint", partial::fingerprint(scene, o))?;
    d.set_item("shape", (scene.camera.height, scene.camera.width, 3))?;
    d.set_item("estimator", o.weighting.estimator.name())?;
    d.set_item("orientations", o.weighting.orientations)?;
    d.set_item("seed", o.seed)?;
    d.set_item("sampler", o.sampler.name())?;
    d.set_item("spp", o.spp)?;
    d.set_item("pixel_center", o.pixel_center)?;
    d.set_item("accelerator", o.accelerator.name())?;
    d.set_item("kernel", o.kernel.name())?;
    d.set_item("resolution", (scene.camera.width, scene.camera.height))?;
    d.set_item("threads", r.threads)?;
    Ok(d)
}

/// A partial render: the unnormalised sums of planes `start` to `end` (excluded) of a render of
/// `planes_total`, float64 (height, width, 3). Picklable; `a + b` adds adjacent partials of one
/// render (`combine`); `merge_partials` adds many in the canonical order.
#[pyclass(frozen, module = "fogplanes", name = "Partial")]
struct PyPartial {
    inner: Partial,
}

#[pymethods]
impl PyPartial {
    /// The sums, float64 (height, width, 3) (a copy).
    #[getter]
    fn sums<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        let p = &self.inner;
        let flat: Vec<f64> = p.sums.iter().flat_map(|s| s.to_array()).collect();
        let array = Array3::from_shape_vec((p.height as usize, p.width as usize, 3), flat)
            .unwrap_or_else(|_| Array3::zeros((p.height as usize, p.width as usize, 3)));
        PyArray3::from_owned_array(py, array)
    }
    #[getter]
    fn start(&self) -> usize {
        self.inner.start
    }
    #[getter]
    fn end(&self) -> usize {
        self.inner.end
    }
    #[getter]
    fn planes_total(&self) -> usize {
        self.inner.planes_total
    }
    #[getter]
    fn fingerprint(&self) -> &str {
        &self.inner.fingerprint
    }
    #[getter]
    fn hits(&self) -> u64 {
        self.inner.hits
    }
    /// Seconds spent rendering it (added up over merged partials).
    #[getter]
    fn seconds(&self) -> f64 {
        self.inner.seconds
    }
    /// (height, width, 3).
    #[getter]
    fn shape(&self) -> (u32, u32, u32) {
        (self.inner.height, self.inner.width, 3)
    }

    fn __add__(&self, other: &Bound<'_, PyAny>) -> PyResult<PyPartial> {
        let other =
            other.cast::<PyPartial>().map_err(|_| PyTypeError::new_err("can only add a Partial to a Partial"))?;
        partial::combine(&self.inner, &other.get().inner).map(|inner| PyPartial { inner }).map_err(py_error)
    }

    /// Rebuilds a pickled partial from its state, the tuple `__reduce__` gives: (width, height,
    /// sums as little-endian f64 bytes, start, end, planes_total, fingerprint, hits, seconds).
    #[staticmethod]
    fn _from_state(state: &Bound<'_, PyTuple>) -> PyResult<Self> {
        let not_a_state = || PyValueError::new_err("not the state of a fogplanes.Partial");
        if state.len() != 9 {
            return Err(not_a_state());
        }
        let item = |k: usize| state.get_item(k);
        let (width, height): (u32, u32) = (item(0)?.extract()?, item(1)?.extract()?);
        let sums = item(2)?;
        let sums = sums.cast::<PyBytes>().map_err(|_| not_a_state())?.as_bytes();
        let (start, end, planes_total): (usize, usize, usize) =
            (item(3)?.extract()?, item(4)?.extract()?, item(5)?.extract()?);
        let (fingerprint, hits, seconds): (String, u64, f64) =
            (item(6)?.extract()?, item(7)?.extract()?, item(8)?.extract()?);
        let pixels = width as usize * height as usize;
        if sums.len() != pixels * 24 || start >= end || end > planes_total {
            return Err(not_a_state());
        }
        let values: Vec<f64> =
            sums.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes"))).collect();
        let sums = values.chunks_exact(3).map(|c| glam::DVec3::new(c[0], c[1], c[2])).collect();
        Ok(PyPartial { inner: Partial { width, height, sums, start, end, planes_total, fingerprint, hits, seconds } })
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let py = slf.py();
        let p = &slf.get().inner;
        let bytes: Vec<u8> = p.sums.iter().flat_map(|s| s.to_array()).flat_map(f64::to_le_bytes).collect();
        let args = (
            p.width,
            p.height,
            PyBytes::new(py, &bytes),
            p.start,
            p.end,
            p.planes_total,
            p.fingerprint.clone(),
            p.hits,
            p.seconds,
        )
            .into_pyobject(py)?;
        Ok((slf.get_type().getattr("_from_state")?, PyTuple::new(py, [args])?))
    }

    fn __repr__(&self) -> String {
        let p = &self.inner;
        format!(
            "Partial(planes {}:{} of {}, {}x{}, {} hits)",
            p.start, p.end, p.planes_total, p.width, p.height, p.hits
        )
    }
}

/// Renders planes `chunk` = (start, end) of the render `**kwargs` describe (the keyword
/// arguments of `render`): one of `plan_render`'s chunks or a union of consecutive ones. Each
/// plane meets exactly what it meets in a whole render. The GIL is released; Ctrl-C cancels.
#[pyfunction]
#[pyo3(signature = (scene, chunk, **kwargs))]
fn render_chunk(
    py: Python<'_>,
    scene: &Bound<'_, PyAny>,
    chunk: &Bound<'_, PyAny>,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyPartial> {
    let chunk = index_pair(chunk, "chunk", "plane indices")?;
    let (r, given) = resolve_chunked(scene, kwargs)?;
    let (p, _) = run_interruptible(py, pool(r.threads)?, |cancel| {
        partial::render_chunk(&r.scene, &r.options, chunk.0..chunk.1, Control::with_cancel(cancel))
    })?
    .map_err(|e| given.error(e))?;
    Ok(PyPartial { inner: p })
}

/// A `(start, end)` pair of argument `name`, as Python ints checked before any conversion: a
/// `TypeError` for anything but a pair of integers, a `ValueError` for a negative one or one of
/// 2**64 or more, both naming the argument (`what` the integers are).
fn index_pair(value: &Bound<'_, PyAny>, name: &str, what: &str) -> PyResult<(usize, usize)> {
    let repr = value.repr()?;
    let not_a_pair = || PyTypeError::new_err(format!("{name}={repr}: expected a (start, end) pair of {what}"));
    let (start, end): (Bound<'_, PyAny>, Bound<'_, PyAny>) = value.extract().map_err(|_| not_a_pair())?;
    let index = |v: &Bound<'_, PyAny>| match v.extract::<i128>() {
        Ok(n) => usize::try_from(n).map_err(|_| {
            PyValueError::new_err(format!("{name}={repr}: {what} must be non-negative integers below 2**64"))
        }),
        Err(e) if e.is_instance_of::<PyOverflowError>(v.py()) => {
            Err(PyValueError::new_err(format!("{name}={repr}: {what} must be non-negative integers below 2**64")))
        }
        Err(_) => Err(not_a_pair()),
    };
    Ok((index(&start)?, index(&end)?))
}

/// The plan of a render of `chunks` canonical chunks (`len(plan_render(...)["chunks"])`) spread
/// over tasks of at most `block` chunks (a power of two): the core's steps in post-order, each a
/// tuple `(start, end, left, right)` over chunks `start..end`: `left` and `right` are None for a
/// task that renders those chunks (`render_chunk` of their planes), else the indices of the two
/// earlier steps whose partials it adds (`combine(left, right)`). The last step is the whole
/// render; following the plan gives the bits of `render`. ValueError for no chunks, more than a
/// render has, or a block that is not a power of two.
#[pyfunction]
fn merge_plan(chunks: &Bound<'_, PyAny>, block: &Bound<'_, PyAny>) -> PyResult<Vec<PlanTuple>> {
    let count = |v: &Bound<'_, PyAny>, name: &str| -> PyResult<usize> {
        let type_error = || -> PyResult<PyErr> {
            Ok(PyTypeError::new_err(format!("{name}: expected an integer, got {}", v.get_type().name()?)))
        };
        let n = match v.extract::<i128>() {
            _ if v.is_instance_of::<pyo3::types::PyBool>() => return Err(type_error()?),
            Ok(n) => n,
            Err(e) if e.is_instance_of::<PyOverflowError>(v.py()) => i128::MAX,
            Err(_) => return Err(type_error()?),
        };
        let repr = v.repr()?;
        usize::try_from(n).map_err(|_| PyValueError::new_err(format!("{name}: out of range, got {repr}")))
    };
    let (n, b) = (count(chunks, "chunks")?, count(block, "block")?);
    let plan = partial::merge_plan(n, b).map_err(py_error)?;
    Ok(plan.into_iter().map(|s| (s.chunks.start, s.chunks.end, s.parts.map(|p| p.0), s.parts.map(|p| p.1))).collect())
}

/// A step of [`merge_plan`] for Python: (start, end, left, right).
type PlanTuple = (usize, usize, Option<usize>, Option<usize>);

/// Adds two adjacent partials of one render (`a.end == b.start`): `a.sums + b.sums` in
/// float64. ValueError for partials of different renders, overlapping or not adjacent.
#[pyfunction]
fn combine(a: &Bound<'_, PyPartial>, b: &Bound<'_, PyPartial>) -> PyResult<PyPartial> {
    partial::combine(&a.get().inner, &b.get().inner).map(|inner| PyPartial { inner }).map_err(py_error)
}

/// Merges partials (any order) into one covering their union, added in the canonical order that
/// `render` uses: with the plan's chunks, the bits of `render`. ValueError for partials of
/// different renders, overlaps and gaps.
#[pyfunction]
fn merge_partials(py: Python<'_>, parts: &Bound<'_, PyAny>) -> PyResult<PyPartial> {
    let mut all = Vec::new();
    for p in parts.try_iter()? {
        let p = p?;
        let p = p.cast::<PyPartial>().map_err(|_| PyTypeError::new_err("parts: expected Partial objects"))?;
        all.push(p.get().inner.clone());
    }
    py.detach(|| partial::merge_in_canonical_order(all)).map(|inner| PyPartial { inner }).map_err(py_error)
}

/// The image (float32, (height, width, 3)) of a render from the partial of all its planes:
/// divided by N, plus the direct emission (computed here). `**kwargs` are the render's, as
/// given to `plan_render`. ValueError if the partial is of another render or does not cover
/// 0..N. With `return_stats=True`: (image, stats).
#[pyfunction]
#[pyo3(signature = (scene, partial, return_stats = false, **kwargs))]
fn finish_render<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    partial: &Bound<'py, PyPartial>,
    return_stats: bool,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let (r, given) = resolve_chunked(scene, kwargs)?;
    let p = &partial.get().inner;
    let film = run_interruptible(py, pool(r.threads)?, |_| partial::finish(&r.scene, &r.options, p))?
        .map_err(|e| given.error(e))?;
    let image = film_to_array(py, &film).into_any();
    if !return_stats {
        return Ok(image);
    }
    let o = &r.options;
    let stats = RenderStats {
        estimator: o.weighting.label(),
        kernel: o.kernel.resolve().map(|k| k.to_string()).unwrap_or_default(),
        planes: o.planes,
        plane_passes: 1,
        rays: film.pixels.len() as u64 * o.ray_sets() as u64,
        hits: p.hits,
        seconds_total: p.seconds,
        ..Default::default()
    };
    Ok(PyTuple::new(py, [image, stats_dict(py, &stats)?.into_any()])?.into_any())
}

/// The keyword arguments of `reference` (and of `reference_rows`, with `counts`).
const REFERENCE_KEYWORDS: [&str; 5] = ["pixel_center", "resolution", "seed", "uniform", "threads"];

/// The reference resolved from `spp` and the keyword arguments of `reference`, by the same
/// names, parsed in one place for every function that takes them; `accepted` are the keywords
/// the caller takes (besides `spp`).
fn resolve_reference_args(
    scene: &Bound<'_, PyAny>,
    spp: Option<&Bound<'_, PyAny>>,
    kwargs: Option<&Bound<'_, PyDict>>,
    accepted: &[&str],
) -> PyResult<(settings::ResolvedReference, Given)> {
    let scene = scene_arg(scene)?;
    let mut given = Given::default();
    let mut o = ReferenceOverrides { spp: given.uint32(Setting::Spp, spp)?, ..ReferenceOverrides::default() };
    for (key, value) in kwargs.into_iter().flat_map(|k| k.iter()) {
        let key: String = key.extract()?;
        if !accepted.contains(&key.as_str()) {
            return Err(PyTypeError::new_err(format!("unexpected keyword argument '{key}'")));
        }
        let value = (!value.is_none()).then_some(value);
        match key.as_str() {
            "pixel_center" => o.pixel_center = flag(&value)?,
            "uniform" => o.uniform = flag(&value)?,
            "resolution" => o.resolution = given.resolution(value.as_ref())?,
            "seed" => o.seed = given.uint(Setting::Seed, value.as_ref())?,
            _ => o.threads = given.threads(value.as_ref())?,
        }
    }
    let r = settings::resolve_reference(&scene, &o).map_err(|e| given.error(e))?;
    Ok((r, given))
}

/// Rows `rows` = (j0, j1) of the reference: (mean, stderr), float32 (j1 - j0, width, 3),
/// bit-identical to those rows of `reference(...)` with the same arguments. The adaptive
/// reference (`uniform=False`) needs `counts`, the per-pixel sample counts from
/// `reference_counts` (uint32 (height, width)).
#[pyfunction]
#[pyo3(signature = (scene, rows, spp = None, counts = None, **kwargs))]
#[pyo3(text_signature = "(scene, rows, spp=None, seed=None, pixel_center=False, uniform=False, counts=None, \
    resolution=None, threads=None)")]
fn reference_rows<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    rows: (u32, u32),
    spp: Option<&Bound<'py, PyAny>>,
    counts: Option<&Bound<'py, PyAny>>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Image<'py>, Image<'py>)> {
    let (r, given) = resolve_reference_args(scene, spp, kwargs, &REFERENCE_KEYWORDS)?;
    let uniform = r.options.uniform;
    let (w, h) = (r.scene.camera.width as usize, r.scene.camera.height as usize);
    let counts: Option<Vec<u32>> = match (counts, uniform) {
        (None, false) => {
            return Err(PyValueError::new_err(
                "counts: the adaptive reference in rows needs the per-pixel counts (reference_counts), or uniform=True",
            ));
        }
        (Some(_), true) => return Err(PyValueError::new_err("counts: a uniform reference takes no counts")),
        (None, true) => None,
        (Some(c), false) => {
            let c: PyArrayLike2<'_, u32, AllowTypeChange> = c.extract()?;
            let view = c.as_array();
            if view.shape() != [h, w] {
                return Err(PyValueError::new_err(format!(
                    "counts: expected shape ({h}, {w}), got {}",
                    shape_text(view.shape())
                )));
            }
            Some(view.iter().copied().collect())
        }
    };
    let (mean, stderr) = run_interruptible(py, pool(r.threads)?, |cancel| {
        refs::reference_rows(&r.scene, &r.options, rows.0..rows.1, counts.as_deref(), Control::with_cancel(cancel))
    })?
    .map_err(|e| given.error(e))?;
    Ok((film_to_array(py, &mean), film_to_array(py, &stderr)))
}

/// Rows `rows` = (j0, j1) of the adaptive reference's pilot pass: each pixel's standard error,
/// float32 (j1 - j0, width, 3). The whole pilot (the rows stacked) goes to `reference_counts`.
#[pyfunction]
#[pyo3(signature = (scene, rows, spp = None, **kwargs))]
#[pyo3(text_signature = "(scene, rows, spp=None, seed=None, pixel_center=False, resolution=None, threads=None)")]
fn reference_pilot_rows<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    rows: (u32, u32),
    spp: Option<&Bound<'py, PyAny>>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<Image<'py>> {
    let (r, given) = resolve_reference_args(scene, spp, kwargs, &["seed", "pixel_center", "resolution", "threads"])?;
    let pilot = run_interruptible(py, pool(r.threads)?, |cancel| {
        refs::reference_pilot_rows(&r.scene, &r.options, rows.0..rows.1, Control::with_cancel(cancel))
    })?
    .map_err(|e| given.error(e))?;
    Ok(film_to_array(py, &pilot))
}

/// The adaptive reference's per-pixel sample counts, uint32 (height, width), from its whole
/// pilot (float32 (height, width, 3): `reference_pilot_rows` of every row, stacked), by the
/// core code `reference` uses.
#[pyfunction]
#[pyo3(signature = (scene, pilot, spp = None, **kwargs))]
#[pyo3(text_signature = "(scene, pilot, spp=None, seed=None, pixel_center=False, resolution=None)")]
fn reference_counts<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    pilot: &Bound<'py, PyAny>,
    spp: Option<&Bound<'py, PyAny>>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyArray2<u32>>> {
    let (r, _) = resolve_reference_args(scene, spp, kwargs, &["seed", "pixel_center", "resolution"])?;
    let pilot = image_arg(pilot, "pilot")?;
    let (w, h) = (r.scene.camera.width, r.scene.camera.height);
    if (pilot.width, pilot.height) != (w, h) {
        return Err(PyValueError::new_err(format!(
            "pilot: expected shape ({h}, {w}, 3), the whole image, got ({}, {}, 3)",
            pilot.height, pilot.width
        )));
    }
    let counts = refs::reference_counts(&r.options, &pilot.pixels);
    let array = numpy::ndarray::Array2::from_shape_vec((h as usize, w as usize), counts)
        .unwrap_or_else(|_| numpy::ndarray::Array2::zeros((h as usize, w as usize)));
    Ok(PyArray2::from_owned_array(py, array))
}

#[pymodule]
fn _fogplanes(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScene>()?;
    m.add_class::<PyCamera>()?;
    m.add_class::<PyMedium>()?;
    m.add_class::<PyLight>()?;
    m.add_class::<PyRenderDefaults>()?;
    m.add_function(wrap_pyfunction!(load_scene, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(reference, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(load_image, m)?)?;
    m.add_function(wrap_pyfunction!(save_image, m)?)?;
    m.add_class::<PyPartial>()?;
    m.add_function(wrap_pyfunction!(plan_render, m)?)?;
    m.add_function(wrap_pyfunction!(render_chunk, m)?)?;
    m.add_function(wrap_pyfunction!(merge_plan, m)?)?;
    m.add_function(wrap_pyfunction!(combine, m)?)?;
    m.add_function(wrap_pyfunction!(merge_partials, m)?)?;
    m.add_function(wrap_pyfunction!(finish_render, m)?)?;
    m.add_function(wrap_pyfunction!(reference_rows, m)?)?;
    m.add_function(wrap_pyfunction!(reference_pilot_rows, m)?)?;
    m.add_function(wrap_pyfunction!(reference_counts, m)?)?;
    m.add("ESTIMATORS", PyTuple::new(m.py(), Estimator::names())?)?;
    m.add("KERNELS", PyTuple::new(m.py(), Kernel::ALL.iter().map(|k| k.name()))?)?;
    m.add("SAMPLERS", PyTuple::new(m.py(), Sampler::ALL.iter().map(|s| s.name()))?)?;
    m.add("ACCELERATORS", PyTuple::new(m.py(), Accelerator::ALL.iter().map(|a| a.name()))?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
