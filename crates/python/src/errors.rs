//! The exceptions a call raises: one mapping from the library's errors and from I/O errors.

use fogplanes::Error;
use fogplanes::settings::Setting;
use pyo3::exceptions::{
    PyFileNotFoundError, PyIsADirectoryError, PyNotADirectoryError, PyOSError, PyPermissionError, PyRuntimeError,
    PyValueError,
};
use pyo3::prelude::*;
use std::io::ErrorKind;
use std::path::Path;

/// The exception for a library error, a setting named by `name`: `ValueError` for the
/// caller's input, `OSError` for a write that failed, `RuntimeError` for cancelled work.
pub(crate) fn py_error_named(e: Error, name: impl Fn(Setting) -> String) -> PyErr {
    match e {
        Error::Write { .. } => PyOSError::new_err(e.to_string()),
        Error::Cancelled => PyRuntimeError::new_err("the work was cancelled"),
        e => PyValueError::new_err(e.worded(name)),
    }
}

/// [`py_error_named`] with settings named by their keyword alone.
pub(crate) fn py_error(e: Error) -> PyErr {
    py_error_named(e, |s| s.keyword().to_string())
}

/// The `OSError` subclass Python raises for an I/O error of this kind.
pub(crate) fn os_error(kind: ErrorKind, message: String) -> PyErr {
    match kind {
        ErrorKind::NotFound => PyFileNotFoundError::new_err(message),
        ErrorKind::PermissionDenied => PyPermissionError::new_err(message),
        ErrorKind::IsADirectory => PyIsADirectoryError::new_err(message),
        _ => PyOSError::new_err(message),
    }
}

/// The exception for a file that `read` failed on with `message`: an `OSError` if the file
/// itself cannot be opened (missing, a directory, unreadable), else `ValueError` (its content,
/// or what it is: a pipe, a device or a socket, which the library refuses unread and which is
/// not opened here either: opening a pipe waits for a writer, and `load_image` of one hung,
/// deaf to Ctrl-C).
pub(crate) fn file_error(path: &Path, message: String) -> PyErr {
    match std::fs::metadata(path) {
        Err(e) => os_error(e.kind(), message),
        Ok(m) if m.is_dir() => PyIsADirectoryError::new_err(message),
        Ok(m) if !m.is_file() => PyValueError::new_err(message),
        Ok(_) => match std::fs::File::open(path) {
            Err(e) => os_error(e.kind(), message),
            Ok(_) => PyValueError::new_err(message),
        },
    }
}

/// The exception for an image output `path` that the library's check of outputs refused with
/// `e`: a name of no image format the caller's `ValueError` (the library checks it first, and
/// its message says so), else the `OSError` of why the file system will not take it (its
/// directory missing, or not a directory; a directory where the file would go; else its
/// directory refused the probe's write: permissions, a read-only file system).
pub(crate) fn output_error(path: &Path, e: Error) -> PyErr {
    if fogplanes::film::ImageFormat::from_path(path).is_err() {
        return py_error(e);
    }
    let message = e.to_string();
    if path.is_dir() {
        return PyIsADirectoryError::new_err(message);
    }
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    match std::fs::metadata(parent) {
        Err(io) => os_error(io.kind(), message),
        Ok(m) if !m.is_dir() => PyNotADirectoryError::new_err(message),
        Ok(_) => PyOSError::new_err(message),
    }
}
