//! Images as numpy arrays (float32, (height, width, 3)), checked at the door.

use crate::*;
use fogplanes::film::Film;
use fogplanes::options::RenderStats;
use numpy::ndarray::Array3;
use numpy::{AllowTypeChange, PyArray3, PyArrayLike3};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

pub(crate) fn film_to_array<'py>(py: Python<'py>, film: &Film) -> Image<'py> {
    let (w, h) = (film.width as usize, film.height as usize);
    let flat: Vec<f32> = film.pixels.iter().flat_map(|p| p.to_array()).collect();
    let array = Array3::from_shape_vec((h, w, 3), flat).unwrap_or_else(|_| Array3::zeros((h, w, 3)));
    PyArray3::from_owned_array(py, array)
}

/// The shape of an array as Python writes it: `(2, 3)`, `(5,)`.
pub(crate) fn shape_text(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!("({})", shape.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", ")),
    }
}

/// The image of an array-like argument (any real dtype), its shape checked against the
/// renderer's limits before anything is converted: a broadcast or float64 array that claims a
/// huge shape costs nothing until converted to float32.
pub(crate) fn image_arg(image: &Bound<'_, PyAny>, what: &str) -> PyResult<Film> {
    let py = image.py();
    let not_an_array = || {
        let type_name = image.get_type().name().map(|n| n.to_string()).unwrap_or_default();
        PyTypeError::new_err(format!("{what}: expected an array, got {type_name}"))
    };
    // Arrays keep their own shape (no copy); nested lists become one to have one (a ragged one
    // is numpy's ValueError, named), and anything else (a number, a str, None) is no array.
    let array = match image.getattr("shape") {
        Ok(_) => image.clone(),
        Err(_) => {
            let array = py.import("numpy")?.call_method1("asarray", (image,)).map_err(|e| {
                let message = format!("{what}: {}", e.value(py));
                if e.is_instance_of::<PyValueError>(py) {
                    PyValueError::new_err(message)
                } else {
                    PyTypeError::new_err(message)
                }
            })?;
            if array.getattr("ndim")?.extract::<usize>()? == 0 {
                return Err(not_an_array());
            }
            array
        }
    };
    let Ok(shape) = array.getattr("shape").and_then(|s| s.extract::<Vec<usize>>()) else {
        return Err(not_an_array());
    };
    let [h, w, 3] = shape[..] else {
        return Err(PyValueError::new_err(format!(
            "{what}: expected an array of shape (height, width, 3), got {}",
            shape_text(&shape)
        )));
    };
    let side = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
    fogplanes::limits::check_resolution(side(w), side(h)).map_err(|m| PyValueError::new_err(format!("{what}: {m}")))?;
    // Converted, it is held twice (the float32 array and the image): within the memory budget.
    let bytes = (w as u64 * h as u64).saturating_mul(2 * 12);
    if bytes > fogplanes::limits::MEMORY_BUDGET_BYTES {
        return Err(PyValueError::new_err(format!(
            "{what}: an image of {w}x{h} pixels would take about {:.1} GiB to read; the limit is {} GiB",
            bytes as f64 / (1u64 << 30) as f64,
            fogplanes::limits::MEMORY_BUDGET_BYTES >> 30
        )));
    }
    // A real dtype: numpy would drop a complex value's imaginary part (with only a warning) and
    // convert an object array element by element.
    if let Ok(kind) = array.getattr("dtype").and_then(|d| d.getattr("kind")).and_then(|k| k.extract::<String>())
        && !matches!(kind.as_str(), "b" | "i" | "u" | "f")
    {
        let dtype = array.getattr("dtype")?.str()?.to_string();
        return Err(PyTypeError::new_err(format!("{what}: expected an array of a real dtype, got dtype {dtype}")));
    }
    // A float wider than float32 holding a finite value beyond float32's range: named as such
    // before the conversion, which would make it an infinity (with numpy's RuntimeWarning) and
    // have it refused as one, a value the caller never gave.
    if array
        .getattr("dtype")
        .and_then(|d| d.getattr("kind"))
        .and_then(|k| k.extract::<String>())
        .is_ok_and(|k| k == "f")
        && array
            .getattr("dtype")
            .and_then(|d| d.getattr("itemsize"))
            .and_then(|n| n.extract::<usize>())
            .is_ok_and(|n| n > 4)
    {
        let np = py.import("numpy")?;
        // From f32::MAX and half its last place up a value rounds to an infinity; below, to a
        // finite float32 (3.40282347e38, FLT_MAX as written, is one).
        let rounds_to_infinity = f32::MAX as f64 + 2f64.powi(103);
        let large = np.call_method1("greater_equal", (np.call_method1("abs", (&array,))?, rounds_to_infinity))?;
        let beyond = np.call_method1("logical_and", (np.call_method1("isfinite", (&array,))?, large))?;
        if beyond.call_method0("any")?.extract::<bool>()? {
            let at: Vec<usize> =
                np.call_method1("argwhere", (beyond,))?.get_item(0)?.call_method0("tolist")?.extract()?;
            let beyond =
                || PyValueError::new_err(format!("{what}: holds a value beyond float32's range (about 3.4e38)"));
            let [y, x, c] = at[..] else { return Err(beyond()) };
            let value: f64 = array.get_item((y, x, c))?.extract()?;
            return Err(PyValueError::new_err(format!(
                "{what}: pixel (x {x}, y {y}) channel {} is {}, beyond float32's range (about 3.4e38)",
                ["R", "G", "B"][c],
                fogplanes::error::Number(value)
            )));
        }
    }
    // Something with a shape that numpy cannot read (a Partial has one) is no array either.
    let array = array.extract::<PyArrayLike3<'_, f32, AllowTypeChange>>().map_err(|e: PyErr| {
        if e.is_instance_of::<PyTypeError>(py) || e.is_instance_of::<PyValueError>(py) { not_an_array() } else { e }
    })?;
    let view = array.as_array();
    let mut film = Film::new(w as u32, h as u32);
    for ((y, x), p) in (0..h).flat_map(|y| (0..w).map(move |x| (y, x))).zip(film.pixels.iter_mut()) {
        *p = glam::Vec3::new(view[[y, x, 0]], view[[y, x, 1]], view[[y, x, 2]]);
    }
    Ok(film)
}

pub(crate) fn stats_dict<'py>(py: Python<'py>, s: &RenderStats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("estimator", &s.estimator)?;
    d.set_item("kernel", &s.kernel)?;
    d.set_item("device", &s.device)?;
    d.set_item("devices", s.devices.names().to_vec())?;
    d.set_item("seconds_device", s.seconds_device)?;
    d.set_item("seconds_device_gather", s.seconds_device_gather)?;
    d.set_item("seconds_upload", s.seconds_upload)?;
    d.set_item("seconds_waited", s.seconds_waited)?;
    d.set_item("bytes_crossed", s.bytes_crossed)?;
    d.set_item("submissions", s.submissions)?;
    d.set_item("gather_dispatches", s.dispatches)?;
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
    d.set_item("relative_error", s.relative_error)?;
    d.set_item("error_floor", s.error_floor)?;
    d.set_item("relative_error_text", s.relative_error_text())?;
    d.set_item("stopped_by", s.stopped_by)?;
    d.set_item("summary", s.summary())?;
    Ok(d)
}
