//! References in row bands: rows of the reference, its pilot pass and the per-pixel counts.

use crate::args::*;
use crate::arrays::*;
use crate::errors::py_error;
use crate::interrupt::*;
use crate::*;
use fogplanes::control::Control;
use fogplanes::reference::{self as refs};
use numpy::{AllowTypeChange, PyArray2, PyArrayLike2};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The `rows` argument, (j0, j1), as Python ints checked before any conversion ([`index_pair`]).
fn row_pair(rows: &Bound<'_, PyAny>) -> PyResult<(u32, u32)> {
    let (j0, j1) = index_pair(rows, "rows", "row indices")?;
    let row = |j: usize| {
        u32::try_from(j).map_err(|_| {
            PyValueError::new_err(format!(
                "rows={}: row indices must be below 2**32",
                rows.repr().map(|r| r.to_string()).unwrap_or_default()
            ))
        })
    };
    Ok((row(j0)?, row(j1)?))
}

/// The `counts` argument: an array (height, width) of whole numbers of samples (any real dtype,
/// checked before converting: a negative or fractional count is no count, and a cast to uint32
/// would wrap it). Their range is the core's to check ([`refs::check_counts`]).
fn counts_arg(counts: &Bound<'_, PyAny>, (w, h): (usize, usize)) -> PyResult<Vec<u32>> {
    // An array of another number of dimensions is a wrong shape, as a wrong 2-d one is (it was
    // a TypeError, "got ndarray"); an array of bools holds no counts (True counted one sample).
    if let Ok(shape) = counts.getattr("shape").and_then(|s| s.extract::<Vec<usize>>())
        && shape.len() != 2
    {
        return Err(PyValueError::new_err(format!("counts: expected shape ({h}, {w}), got {}", shape_text(&shape))));
    }
    if counts
        .getattr("dtype")
        .and_then(|d| d.getattr("kind"))
        .and_then(|k| k.extract::<String>())
        .is_ok_and(|k| k == "b")
    {
        return Err(PyTypeError::new_err("counts: expected whole numbers of samples, got an array of bools"));
    }
    let c: PyArrayLike2<'_, f64, AllowTypeChange> = counts.extract().map_err(|_| {
        let type_name = counts.get_type().name().map(|n| n.to_string()).unwrap_or_default();
        PyTypeError::new_err(format!("counts: expected an array of shape ({h}, {w}), got {type_name}"))
    })?;
    let view = c.as_array();
    if view.shape() != [h, w] {
        return Err(PyValueError::new_err(format!(
            "counts: expected shape ({h}, {w}), got {}",
            shape_text(view.shape())
        )));
    }
    view.iter()
        .enumerate()
        .map(|(i, &c)| {
            if c.fract() == 0.0 && (0.0..=u32::MAX as f64).contains(&c) {
                Ok(c as u32)
            } else {
                Err(PyValueError::new_err(format!(
                    "counts: pixel (x {}, y {}) holds {c}, not a whole number of samples",
                    i % w.max(1),
                    i / w.max(1)
                )))
            }
        })
        .collect()
}

/// Rows `rows` = (j0, j1) of the reference: (mean, stderr), float32 (j1 - j0, width, 3),
/// bit-identical to those rows of `reference(...)` with the same arguments. The adaptive
/// reference (`uniform=False`) needs `counts`, the per-pixel sample counts from
/// `reference_counts` (uint32 (height, width)).
#[pyfunction]
#[pyo3(signature = (scene, rows, spp = None, counts = None, **kwargs))]
#[pyo3(text_signature = "(scene, rows, spp=None, counts=None, *, seed=None, pixel_center=False, uniform=False, \
    resolution=None, threads=None)")]
pub(crate) fn reference_rows<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    rows: &Bound<'py, PyAny>,
    spp: Option<&Bound<'py, PyAny>>,
    counts: Option<&Bound<'py, PyAny>>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Image<'py>, Image<'py>)> {
    let rows = row_pair(rows)?;
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
        (Some(c), false) => Some(counts_arg(c, (w, h))?),
    };
    if let Some(c) = &counts {
        // What reference_counts can make: at least one sample and at most its cap per pixel.
        refs::check_counts(&r.scene, &r.options, c).map_err(py_error)?;
    }
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
#[pyo3(text_signature = "(scene, rows, spp=None, *, seed=None, pixel_center=False, resolution=None, threads=None)")]
pub(crate) fn reference_pilot_rows<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    rows: &Bound<'py, PyAny>,
    spp: Option<&Bound<'py, PyAny>>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<Image<'py>> {
    let rows = row_pair(rows)?;
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
#[pyo3(text_signature = "(scene, pilot, spp=None, *, seed=None, pixel_center=False, resolution=None)")]
pub(crate) fn reference_counts<'py>(
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
    let counts = refs::reference_counts(&r.options, &pilot.pixels, w).map_err(py_error)?;
    let array = numpy::ndarray::Array2::from_shape_vec((h as usize, w as usize), counts)
        .unwrap_or_else(|_| numpy::ndarray::Array2::zeros((h as usize, w as usize)));
    Ok(PyArray2::from_owned_array(py, array))
}
