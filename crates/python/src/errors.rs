//! The exceptions a call raises: one mapping from the library's errors and from I/O errors.

use fogplanes::Error;
use fogplanes::settings::Setting;
use pyo3::exceptions::{
    PyFileNotFoundError, PyIsADirectoryError, PyOSError, PyPermissionError, PyRuntimeError, PyValueError,
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
/// itself cannot be opened (missing, a directory, unreadable), else `ValueError` (its content).
pub(crate) fn file_error(path: &Path, message: String) -> PyErr {
    match std::fs::metadata(path) {
        Err(e) => os_error(e.kind(), message),
        Ok(m) if m.is_dir() => PyIsADirectoryError::new_err(message),
        Ok(_) => match std::fs::File::open(path) {
            Err(e) => os_error(e.kind(), message),
            Ok(_) => PyValueError::new_err(message),
        },
    }
}
