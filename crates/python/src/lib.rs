//! The native part of the Python package `fogplanes`: scenes, the photon-plane renderer, the
//! reference and the metrics of the core library, with images as numpy arrays of shape
//! (height, width, 3) and float32.
//!
//! Everything a call can fail with is a Python exception: `ValueError` for bad input, with the
//! command line's one-line message, a setting named as the caller gave it (`planes=0: ...`
//! where the command line says `--planes: ...`); `TypeError` for an argument of the wrong type,
//! named as given (`planes=2048.0: expected an integer, got float`); `OSError` (or its subclass
//! `FileNotFoundError`, ...) for a file that cannot be read. A path is what `open()` takes: a
//! str, bytes (decoded as `os.fsdecode` decodes them) or an os.PathLike. The settings are
//! resolved by the core (`fogplanes::settings`), as for the command line: the same defaults, the
//! same checks. Renders run on a worker thread with the GIL released, while the calling thread
//! watches for signals: Ctrl-C sets the core's cancel flag and raises `KeyboardInterrupt` once
//! the work under way has stopped.

mod args;
mod arrays;
mod errors;
mod given;
mod interrupt;
mod partials;
mod progress;
mod references;
mod renders;
mod scene;

use fogplanes::accel::Accelerator;
use fogplanes::kernel::Kernel;
use fogplanes::sampling::Sampler;
use fogplanes::weights::Estimator;
use numpy::PyArray3;
use partials::*;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use pyo3::types::PyTuple;
use references::*;
use renders::*;
use scene::*;

pub(crate) type Vec3 = (f64, f64, f64);

/// What a pickled scene is rebuilt from: text, name, file, (width, height).
pub(crate) type SceneParts = (String, String, String, (u32, u32));

/// An image for Python: shape (height, width, 3), float32.
pub(crate) type Image<'py> = Bound<'py, PyArray3<f32>>;

pub(crate) fn triple(v: glam::DVec3) -> Vec3 {
    (v.x, v.y, v.z)
}

#[pymodule]
fn _fogplanes(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScene>()?;
    m.add_class::<PyCamera>()?;
    m.add_class::<PyMedium>()?;
    m.add_class::<PyLight>()?;
    m.add_class::<PyRenderDefaults>()?;
    m.add_function(wrap_pyfunction!(load_scene, m)?)?;
    m.add_function(wrap_pyfunction!(devices, m)?)?;
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
    m.add("DEVICES", PyTuple::new(m.py(), fogplanes::gpu::Device::ALL.iter().map(|d| d.name()))?)?;
    // Read-only, as the other constants are tuples.
    let allocator = pyo3::types::PyDict::new(m.py());
    for (name, bytes) in fogplanes::limits::ALLOCATOR_ENVIRONMENT {
        allocator.set_item(name, bytes.to_string())?;
    }
    m.add("ALLOCATOR_ENVIRONMENT", m.py().import("types")?.getattr("MappingProxyType")?.call1((allocator,))?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}

/// The GPU adapters wgpu finds (Vulkan, Metal, DX12), as `fogplanes devices` lists them: a
/// list of dicts with `index` (`device=f"gpu:{index}"`), `name`, `backend`, `kind` ("discrete
/// GPU", "integrated GPU", "virtual GPU", "CPU emulation", "other"), `max_binding` (bytes) and
/// `default` (the one `device="gpu"` takes). An empty list where there is none.
#[pyfunction]
fn devices(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyDict>>> {
    let all = py.detach(fogplanes::gpu::adapters).unwrap_or_default();
    all.iter()
        .map(|a| {
            let d = PyDict::new(py);
            d.set_item("index", a.index)?;
            d.set_item("name", &a.name)?;
            d.set_item("backend", &a.backend)?;
            d.set_item("kind", a.kind)?;
            d.set_item("max_binding", a.max_binding)?;
            d.set_item("default", a.default)?;
            Ok(d)
        })
        .collect()
}
