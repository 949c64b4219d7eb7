//! Renders in chunks (the cluster layer, `fogplanes.distributed`): the plan, `Partial` and its
//! canonical merge, and the finish.

use crate::args::*;
use crate::arrays::*;
use crate::errors::*;
use crate::given::{integer, short_repr};
use crate::interrupt::*;
use fogplanes::control::Control;
use fogplanes::options::RenderStats;
use fogplanes::partial::{self, Partial};
use numpy::PyArray3;
use numpy::ndarray::Array3;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyString, PyTuple};

/// The plan of a render in chunks: its resolved settings (the keyword arguments of `render`),
/// `planes` N, `chunk_planes` (a fixed power of two), `chunks` (the (start, end) plane ranges,
/// in order, covering 0..N), `fingerprint` (the scene and every setting that changes the
/// image) and `shape` (height, width, 3). Raises ValueError as `render` does.
#[pyfunction]
#[pyo3(signature = (scene, **kwargs))]
pub(crate) fn plan_render<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let (r, _) = resolve_chunked(scene, kwargs)?;
    let (scene, o) = (&r.scene, &r.options);
    let d = PyDict::new(py);
    d.set_item("planes", o.planes())?;
    d.set_item("chunk_planes", fogplanes::limits::CHUNK_PLANES)?;
    let chunks: Vec<(usize, usize)> = partial::chunks(o.planes()).into_iter().map(|c| (c.start, c.end)).collect();
    d.set_item("chunks", chunks)?;
    d.set_item("fingerprint", partial::fingerprint(scene, o))?;
    d.set_item("shape", (scene.camera.height, scene.camera.width, 3))?;
    d.set_item("estimator", o.weighting().estimator.name())?;
    d.set_item("orientations", o.weighting().orientations)?;
    d.set_item("seed", o.seed())?;
    d.set_item("sampler", o.sampler().name())?;
    d.set_item("lobes", o.lobes())?;
    d.set_item("spp", o.spp())?;
    d.set_item("pixel_center", o.pixel_center())?;
    d.set_item("accelerator", o.accelerator().name())?;
    d.set_item("kernel", o.kernel().name())?;
    d.set_item("device", o.device().to_string())?;
    d.set_item("resolution", (scene.camera.width, scene.camera.height))?;
    d.set_item("threads", r.threads)?;
    Ok(d)
}

/// A partial render: the unnormalised sums of planes `start` to `end` (excluded) of a render of
/// `planes_total`, float64 (height, width, 3). Picklable; `a + b` adds adjacent partials of one
/// render (`combine`); `merge_partials` adds many in the canonical order.
#[pyclass(frozen, module = "fogplanes", name = "Partial")]
pub(crate) struct PyPartial {
    pub(crate) inner: Partial,
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
    /// The devices whose gathering it holds ("cpu", or "gpu: " and the adapter), each once:
    /// several for a merge of partials gathered on different devices.
    #[getter]
    fn devices(&self) -> Vec<String> {
        self.inner.devices.names().to_vec()
    }
    /// (height, width, 3).
    #[getter]
    fn shape(&self) -> (u32, u32, u32) {
        (self.inner.height, self.inner.width, 3)
    }

    /// `self + other`; anything but a Partial is NotImplemented, so that Python raises its
    /// own TypeError ("unsupported operand type(s) for +: 'fogplanes.Partial' and 'int'").
    fn __add__(&self, other: &Bound<'_, PyPartial>) -> PyResult<PyPartial> {
        partial::combine(self.inner.clone(), &other.get().inner).map(|inner| PyPartial { inner }).map_err(py_error)
    }

    /// Rebuilds a pickled partial from its state, the tuple `__reduce__` gives: (width, height,
    /// sums as little-endian f64 bytes, start, end, planes_total, fingerprint, hits, seconds,
    /// devices).
    /// A state is trusted no more than a file: anything a render cannot make is a ValueError
    /// (the core's `Partial::check`, naming the pixel).
    #[staticmethod]
    fn _from_state(state: &Bound<'_, PyTuple>) -> PyResult<Self> {
        let not_a_state =
            |why: &dyn std::fmt::Display| PyValueError::new_err(format!("not the state of a fogplanes.Partial: {why}"));
        if state.len() != 10 {
            return Err(not_a_state(&format!("{} items, not 10", state.len())));
        }
        // Item `k`, named `name`, of the type of its place (a bool is no count).
        fn item<'py, T: FromPyObjectOwned<'py>>(state: &Bound<'py, PyTuple>, k: usize, name: &str) -> PyResult<T> {
            let v = state.get_item(k)?;
            let wrong = || -> PyResult<PyErr> {
                let (repr, type_name) = (v.repr()?, v.get_type().name()?);
                // The Rust type as Python names it (the state's fields are these four kinds).
                let expected = match std::any::type_name::<T>() {
                    t if t.contains("Vec<") => "a list of str",
                    t if t.ends_with("String") => "str",
                    t if t.ends_with("f64") => "float",
                    _ => "int",
                };
                // Of the right kind but not held by its place: an int out of its range, a str
                // of no valid Unicode (a lone surrogate).
                let why = match expected {
                    "int" if v.is_instance_of::<pyo3::types::PyInt>() && !v.is_instance_of::<pyo3::types::PyBool>() => {
                        "out of range".to_string()
                    }
                    "str" if v.is_instance_of::<pyo3::types::PyString>() => "not valid Unicode text".to_string(),
                    _ => format!("expected {expected}, got {type_name}"),
                };
                Ok(PyValueError::new_err(format!("not the state of a fogplanes.Partial: {name}={repr}: {why}")))
            };
            if v.is_instance_of::<pyo3::types::PyBool>() {
                return Err(wrong()?);
            }
            v.extract::<T>().or_else(|_| Err(wrong()?))
        }
        let (width, height): (u32, u32) = (item(state, 0, "width")?, item(state, 1, "height")?);
        let (start, end, planes_total): (usize, usize, usize) =
            (item(state, 3, "start")?, item(state, 4, "end")?, item(state, 5, "planes_total")?);
        let (fingerprint, hits, seconds): (String, u64, f64) =
            (item(state, 6, "fingerprint")?, item(state, 7, "hits")?, item(state, 8, "seconds")?);
        let sums = state.get_item(2)?;
        let sums = sums.cast::<PyBytes>().map_err(|_| not_a_state(&"the sums are not bytes"))?.as_bytes();
        if sums.len() as u64 != width as u64 * height as u64 * 24 {
            return Err(not_a_state(&format!("{} bytes of sums for {width}x{height} pixels", sums.len())));
        }
        let values: Vec<f64> =
            sums.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes"))).collect();
        let sums = values.chunks_exact(3).map(|c| glam::DVec3::new(c[0], c[1], c[2])).collect();
        let devices: Vec<String> = item(state, 9, "devices")?;
        let devices = fogplanes::options::Devices::from_names(devices).map_err(|e| not_a_state(&e))?;
        let inner = Partial { width, height, sums, start, end, planes_total, fingerprint, hits, seconds, devices };
        inner.check().map_err(|e| not_a_state(&e))?;
        Ok(PyPartial { inner })
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
            p.devices.names().to_vec(),
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
pub(crate) fn render_chunk(
    py: Python<'_>,
    scene: &Bound<'_, PyAny>,
    chunk: &Bound<'_, PyAny>,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyPartial> {
    let chunk = index_pair(chunk, "chunk", "plane indices")?;
    let (r, given) = resolve_chunked(scene, kwargs)?;
    let (p, _) = run_interruptible(py, pool(r.threads)?, |cancel| {
        fogplanes::render::render_chunk(&r.scene, &r.options, chunk.0..chunk.1, Control::with_cancel(cancel))
    })?
    .map_err(|e| given.error(e))?;
    Ok(PyPartial { inner: p })
}

/// The plan of a render of `chunks` canonical chunks (`len(plan_render(...)["chunks"])`) spread
/// over tasks of at most `block` chunks (a power of two): the core's steps in post-order, each a
/// tuple `(start, end, left, right)` over chunks `start..end`: `left` and `right` are None for a
/// task that renders those chunks (`render_chunk` of their planes), else the indices of the two
/// earlier steps whose partials it adds (`combine(left, right)`). The last step is the whole
/// render; following the plan gives the bits of `render`. ValueError for no chunks, more than a
/// render has, or a block that is not a power of two.
#[pyfunction]
pub(crate) fn merge_plan(chunks: &Bound<'_, PyAny>, block: &Bound<'_, PyAny>) -> PyResult<Vec<PlanTuple>> {
    let count = |v: &Bound<'_, PyAny>, name: &str| -> PyResult<usize> {
        integer(name, v)?.and_then(|n| usize::try_from(n).ok()).ok_or_else(|| {
            PyValueError::new_err(format!(
                "{name}={}: out of range (a non-negative integer below 2**64)",
                short_repr(v)
            ))
        })
    };
    let (n, b) = (count(chunks, "chunks")?, count(block, "block")?);
    let plan = partial::merge_plan(n, b).map_err(py_error)?;
    Ok(plan.into_iter().map(|s| (s.chunks.start, s.chunks.end, s.parts.map(|p| p.0), s.parts.map(|p| p.1))).collect())
}

/// A step of [`merge_plan`] for Python: (start, end, left, right).
pub(crate) type PlanTuple = (usize, usize, Option<usize>, Option<usize>);

/// The `Partial` of argument `name`, a `TypeError` naming it for anything else.
fn partial_arg<'a, 'py>(value: &'a Bound<'py, PyAny>, name: &str) -> PyResult<&'a Bound<'py, PyPartial>> {
    value.cast::<PyPartial>().map_err(|_| {
        let type_name = value.get_type().name().map(|n| n.to_string()).unwrap_or_default();
        PyTypeError::new_err(format!("{name}: expected a fogplanes.Partial, got {type_name}"))
    })
}

/// Adds two adjacent partials of one render (`a.end == b.start`): `a.sums + b.sums` in
/// float64. ValueError for partials of different renders, overlapping or not adjacent;
/// TypeError naming `a` or `b` for anything but a Partial.
#[pyfunction]
pub(crate) fn combine(a: &Bound<'_, PyAny>, b: &Bound<'_, PyAny>) -> PyResult<PyPartial> {
    let (a, b) = (partial_arg(a, "a")?, partial_arg(b, "b")?);
    partial::combine(a.get().inner.clone(), &b.get().inner).map(|inner| PyPartial { inner }).map_err(py_error)
}

/// Merges partials (any order) into one covering their union, added in the canonical order that
/// `render` uses: with the plan's chunks, the bits of `render`. ValueError for partials of
/// different renders, overlaps and gaps; TypeError naming `parts` (or the item) for anything but
/// an iterable of Partials (a list, a tuple, a generator).
#[pyfunction]
pub(crate) fn merge_partials(py: Python<'_>, parts: &Bound<'_, PyAny>) -> PyResult<PyPartial> {
    let type_name = |v: &Bound<'_, PyAny>| v.get_type().name().map(|n| n.to_string()).unwrap_or_default();
    // A str is iterable, and a Partial is not: neither is a list of partials.
    let items = (!parts.is_instance_of::<PyString>()).then(|| parts.try_iter().ok()).flatten().ok_or_else(|| {
        PyTypeError::new_err(format!("parts: expected a list of fogplanes.Partial, got {}", type_name(parts)))
    })?;
    let mut all = Vec::new();
    for (i, p) in items.enumerate() {
        let p = p?;
        let p = partial_arg(&p, &format!("parts[{i}]"))?;
        all.push(p.get().inner.clone());
    }
    py.detach(|| partial::merge_in_canonical_order(all)).map(|inner| PyPartial { inner }).map_err(|e| match e {
        // What is wrong is the list: named as `parts`.
        e @ fogplanes::Error::Partial(_) => PyValueError::new_err(format!("parts: {e}")),
        e => py_error(e),
    })
}

/// The image (float32, (height, width, 3)) of a render from the partial of all its planes:
/// divided by N, plus the direct emission (computed here). `**kwargs` are the render's, as
/// given to `plan_render`. ValueError if the partial is of another render or does not cover
/// 0..N. With `return_stats=True`: (image, stats).
#[pyfunction]
#[pyo3(signature = (scene, partial, return_stats = None, **kwargs))]
#[pyo3(text_signature = "(scene, partial, return_stats=False, **kwargs)")]
pub(crate) fn finish_render<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    partial: &Bound<'py, PyAny>,
    return_stats: Option<Bound<'py, PyAny>>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let partial = partial_arg(partial, "partial")?;
    let return_stats = flag("return_stats", &return_stats)?;
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
        estimator: o.weighting().label(),
        kernel: o.kernel().to_string(),
        planes: o.planes(),
        plane_passes: 1,
        rays: film.pixels.len() as u64 * o.ray_sets() as u64,
        hits: p.hits,
        seconds_total: p.seconds,
        // The partials' devices, where one render's stats name its own ("; " is in no name).
        device: p.devices.names().join("; "),
        devices: p.devices.clone(),
        ..Default::default()
    };
    Ok(PyTuple::new(py, [image, stats_dict(py, &stats)?.into_any()])?.into_any())
}
