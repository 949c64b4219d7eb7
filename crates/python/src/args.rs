//! Argument parsing: the settings a caller gave, named as Python names them, and the keyword arguments of each function, parsed in one place for all.

use crate::errors::*;
use crate::given::*;
use crate::scene::*;
use fogplanes::scene::Scene;
use fogplanes::settings::{self, Overrides, ReferenceOverrides, Setting};
use pyo3::exceptions::{PyOverflowError, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyDict, PyString};
use std::path::{Path, PathBuf};

/// The scene file at `path`: a regular file (a pipe would block the interpreter, which holds
/// its lock while it reads, until a writer came; its text goes to `Scene.from_toml`).
pub(crate) fn load(path: &Path) -> PyResult<Scene> {
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir()) {
        return Err(PyValueError::new_err(format!(
            "{}: not a regular file (a pipe or a device): read its text and give it to Scene.from_toml",
            path.display()
        )));
    }
    Scene::load(path).map_err(|e| file_error(path, e.to_string()))
}

/// The path of argument `name`: a str, bytes or an os.PathLike, as `open()` takes them, bytes
/// decoded as `os.fsdecode` decodes them (on POSIX the file system's bytes, unchanged); `None`
/// for anything else (the caller words what it takes). A path holding a NUL byte is a
/// `ValueError` naming the argument, as Python's own `open()` refuses it.
pub(crate) fn path_or_none(value: &Bound<'_, PyAny>, name: &str) -> PyResult<Option<PathBuf>> {
    let py = value.py();
    let is_path = value.is_instance_of::<PyString>()
        || value.is_instance_of::<PyBytes>()
        || value.get_type().hasattr("__fspath__")?;
    if !is_path {
        return Ok(None);
    }
    // An os.PathLike whose __fspath__ gives neither str nor bytes is a TypeError of os.fspath's.
    let text = py.import("os")?.call_method1("fsdecode", (value,)).map_err(|e| {
        if e.is_instance_of::<PyTypeError>(py) { PyTypeError::new_err(format!("{name}: {}", e.value(py))) } else { e }
    })?;
    let path: PathBuf = text.extract()?;
    if path.as_os_str().as_encoded_bytes().contains(&0) {
        return Err(PyValueError::new_err(format!("{name}={}: a path cannot hold a NUL byte", short_repr(value))));
    }
    Ok(Some(path))
}

/// The path of argument `name` ([`path_or_none`]), a `TypeError` naming it for anything else.
pub(crate) fn path_arg(value: &Bound<'_, PyAny>, name: &str) -> PyResult<PathBuf> {
    path_or_none(value, name)?.ok_or_else(|| {
        let type_name = value.get_type().name().map(|n| n.to_string()).unwrap_or_default();
        PyTypeError::new_err(format!("{name}: expected a path (str, bytes or os.PathLike), got {type_name}"))
    })
}

/// The scene of a `scene` argument: a `Scene`, or the path of a scene file ([`path_arg`]: str,
/// bytes or os.PathLike).
pub(crate) fn scene_arg(scene: &Bound<'_, PyAny>) -> PyResult<Scene> {
    if let Ok(s) = scene.cast::<PyScene>() {
        Ok(s.get().inner.clone())
    } else if let Some(path) = path_or_none(scene, "scene")? {
        load(&path)
    } else {
        Err(PyTypeError::new_err(format!(
            "scene: expected a fogplanes.Scene or the path of a scene file (str, bytes or os.PathLike), got {}",
            scene.get_type().name()?
        )))
    }
}

/// The worker pool of `threads` resolved (None: rayon's global pool).
pub(crate) fn pool(threads: Option<usize>) -> PyResult<Option<rayon::ThreadPool>> {
    let Some(t) = threads else { return Ok(None) };
    rayon::ThreadPoolBuilder::new()
        .num_threads(t)
        .thread_name(|i| format!("fogplanes-{i}"))
        .build()
        .map(Some)
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start the worker threads: {e}")))
}

/// Which function's keyword arguments [`render_overrides`] parses.
#[derive(Clone, Copy, PartialEq)]
pub(crate) enum Front {
    /// `render`: also `time_budget` and `return_stats`.
    Render,
    /// The chunked functions (`plan_render`, `render_chunk`, `finish_render`): a plane count.
    Chunks,
}

/// The keyword argument `name`, a flag (None: false): True or False, else a `TypeError`
/// naming it.
pub(crate) fn flag(name: &str, value: &Option<Bound<'_, PyAny>>) -> PyResult<bool> {
    let Some(v) = value else { return Ok(false) };
    v.extract().map_err(|_| wrong_type(name, v, "True or False"))
}

/// What `render` returns and shows besides the image (its own keywords).
#[derive(Clone, Copy, Default)]
pub(crate) struct Returns {
    pub(crate) stats: bool,
    pub(crate) stderr: bool,
    pub(crate) progress: bool,
}

/// The render settings of `**kwargs`: the keyword arguments of `render`, by the same names,
/// parsed in one place for every function that takes them; and what `render` alone takes:
/// `time_budget`, `target_error`, `return_stats`, `return_stderr`, `progress`.
pub(crate) fn render_overrides(
    kwargs: Option<&Bound<'_, PyDict>>,
    given: &mut Given,
    front: Front,
) -> PyResult<(Overrides, Returns)> {
    let (mut o, mut returns) = (Overrides::default(), Returns::default());
    let Some(kwargs) = kwargs else { return Ok((o, returns)) };
    for (key, value) in kwargs.iter() {
        let key: String = key.extract()?;
        let value = (!value.is_none()).then_some(value);
        match key.as_str() {
            "estimator" => o.estimator = given.named(Setting::Estimator, value.as_ref())?,
            "orientations" => o.orientations = given.uint32(Setting::Orientations, value.as_ref())?,
            "planes" => o.planes = given.uint(Setting::Planes, value.as_ref())?,
            "seed" => o.seed = given.uint(Setting::Seed, value.as_ref())?,
            "sampler" => o.sampler = given.named(Setting::Sampler, value.as_ref())?,
            "lobes" => o.lobes = given.float(Setting::Lobes, value.as_ref())?,
            "spp" => o.spp = given.uint32(Setting::Spp, value.as_ref())?,
            "pixel_center" => o.pixel_center = flag("pixel_center", &value)?,
            "accelerator" => o.accelerator = given.named(Setting::Accelerator, value.as_ref())?,
            "kernel" => o.kernel = given.named(Setting::Kernel, value.as_ref())?,
            "device" => o.device = given.named(Setting::Device, value.as_ref())?,
            "resolution" => o.resolution = given.resolution(value.as_ref())?,
            "threads" => o.threads = given.threads(value.as_ref())?,
            "time_budget" if front == Front::Render => {
                o.time_budget = given.float(Setting::TimeBudget, value.as_ref())?;
            }
            "target_error" if front == Front::Render => {
                o.target_error = given.float(Setting::TargetError, value.as_ref())?;
            }
            "return_stats" if front == Front::Render => returns.stats = flag("return_stats", &value)?,
            "return_stderr" if front == Front::Render => {
                returns.stderr = flag("return_stderr", &value)?;
                o.stderr = returns.stderr;
            }
            "progress" if front == Front::Render => returns.progress = flag("progress", &value)?,
            "time_budget" | "target_error" if value.is_some() => {
                return Err(PyValueError::new_err(format!(
                    "{key}: a render in chunks has a plane count; give planes= instead"
                )));
            }
            "time_budget" | "target_error" => {}
            other => return Err(PyTypeError::new_err(format!("unexpected keyword argument '{other}'"))),
        }
    }
    Ok((o, returns))
}

/// The render `scene` and `**kwargs` describe, resolved as `render` resolves it.
pub(crate) fn resolve_chunked(
    scene: &Bound<'_, PyAny>,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<(settings::ResolvedRender, Given)> {
    let scene = scene_arg(scene)?;
    let mut given = Given::default();
    let (overrides, _) = render_overrides(kwargs, &mut given, Front::Chunks)?;
    let r = settings::resolve_render(&scene, &overrides).map_err(|e| given.error(e))?;
    Ok((r, given))
}

/// The keyword arguments of `reference` (and of `reference_rows`, with `counts`).
pub(crate) const REFERENCE_KEYWORDS: [&str; 5] = ["pixel_center", "resolution", "seed", "uniform", "threads"];

/// The reference resolved from `spp` and the keyword arguments of `reference`, by the same
/// names, parsed in one place for every function that takes them; `accepted` are the keywords
/// the caller takes (besides `spp`).
pub(crate) fn resolve_reference_args(
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
            "pixel_center" => o.pixel_center = flag("pixel_center", &value)?,
            "uniform" => o.uniform = flag("uniform", &value)?,
            "resolution" => o.resolution = given.resolution(value.as_ref())?,
            "seed" => o.seed = given.uint(Setting::Seed, value.as_ref())?,
            _ => o.threads = given.threads(value.as_ref())?,
        }
    }
    let r = settings::resolve_reference(&scene, &o).map_err(|e| given.error(e))?;
    Ok((r, given))
}

/// A `(start, end)` pair of argument `name`, as Python ints checked before any conversion: a
/// `TypeError` for anything but a pair of integers, a `ValueError` for a negative one or one of
/// 2**64 or more, both naming the argument (`what` the integers are).
pub(crate) fn index_pair(value: &Bound<'_, PyAny>, name: &str, what: &str) -> PyResult<(usize, usize)> {
    let repr = value.repr()?;
    let not_a_pair = || PyTypeError::new_err(format!("{name}={repr}: expected a (start, end) pair of {what}"));
    let (start, end): (Bound<'_, PyAny>, Bound<'_, PyAny>) = value.extract().map_err(|_| not_a_pair())?;
    let index = |v: &Bound<'_, PyAny>| match v.extract::<i128>() {
        _ if v.is_instance_of::<PyBool>() => Err(not_a_pair()),
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
