//! The settings a caller gave, as Python shows them: what every argument parser fills in and
//! every error is worded by.

use crate::errors::*;
use fogplanes::Error;
use fogplanes::settings::Setting;
use pyo3::exceptions::{PyOverflowError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBool;

/// The settings a caller gave, as Python shows them, so that an error names a setting the way
/// the caller wrote it (`planes=0: ...`), and never a command-line flag.
#[derive(Default)]
pub(crate) struct Given {
    pub(crate) reprs: Vec<(Setting, String)>,
}

impl Given {
    /// `keyword=value` of a setting given, the keyword alone of one not given.
    pub(crate) fn name(&self, setting: Setting) -> String {
        match self.reprs.iter().rev().find(|(s, _)| *s == setting) {
            Some((_, repr)) => format!("{}={repr}", setting.keyword()),
            None => setting.keyword().to_string(),
        }
    }

    pub(crate) fn error(&self, e: Error) -> PyErr {
        py_error_named(e, |s| self.name(s))
    }

    pub(crate) fn invalid(&self, setting: Setting, message: impl std::fmt::Display) -> PyErr {
        PyValueError::new_err(format!("{}: {message}", self.name(setting)))
    }

    pub(crate) fn note(&mut self, setting: Setting, value: &Bound<'_, PyAny>) -> PyResult<()> {
        self.reprs.push((setting, short_repr(value)));
        Ok(())
    }

    /// A non-negative integer: a Python int out of range is a `ValueError` naming the setting,
    /// anything but an int (a bool too: `spp=True` is no count; a float too: `planes=2048.0`)
    /// a `TypeError` naming it.
    pub(crate) fn uint(&mut self, setting: Setting, value: Option<&Bound<'_, PyAny>>) -> PyResult<Option<u64>> {
        let Some(v) = value else { return Ok(None) };
        self.note(setting, v)?;
        match integer(setting.keyword(), v)? {
            Some(n) => Ok(Some(n)),
            None => Err(self.invalid(setting, "out of range (a non-negative integer below 2**64)")),
        }
    }

    /// A `u32` (out of range as in [`Given::uint`]).
    pub(crate) fn uint32(&mut self, setting: Setting, value: Option<&Bound<'_, PyAny>>) -> PyResult<Option<u32>> {
        self.uint(setting, value)?
            .map(|n| u32::try_from(n).map_err(|_| self.invalid(setting, "out of range (an integer below 2**32)")))
            .transpose()
    }

    /// A number of seconds or stops (a float, or an int; not a bool): anything else a
    /// `TypeError` naming the setting, an int past a float's range a `ValueError`.
    pub(crate) fn float(&mut self, setting: Setting, value: Option<&Bound<'_, PyAny>>) -> PyResult<Option<f64>> {
        let Some(v) = value else { return Ok(None) };
        self.note(setting, v)?;
        if v.is_instance_of::<PyBool>() {
            return Err(wrong_type(setting.keyword(), v, "a number"));
        }
        match v.extract::<f64>() {
            Ok(x) => Ok(Some(x)),
            Err(e) if e.is_instance_of::<PyOverflowError>(v.py()) => Err(self.invalid(setting, "out of range")),
            Err(_) => Err(wrong_type(setting.keyword(), v, "a number")),
        }
    }

    /// A name from a closed list (estimator, sampler, ...): a `str`, else a `TypeError` naming
    /// the setting.
    pub(crate) fn named<T: std::str::FromStr<Err = String>>(
        &mut self,
        setting: Setting,
        value: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Option<T>> {
        let Some(v) = value else { return Ok(None) };
        if !v.is_instance_of::<pyo3::types::PyString>() {
            return Err(wrong_type(setting.keyword(), v, "a name (a str)"));
        }
        let v = text(setting.keyword(), v)?;
        self.reprs.push((setting, py_str(&v)));
        v.parse().map(Some).map_err(|m| self.invalid(setting, m))
    }

    /// `(width, height)`.
    pub(crate) fn resolution(&mut self, value: Option<&Bound<'_, PyAny>>) -> PyResult<Option<(u32, u32)>> {
        let Some(v) = value else { return Ok(None) };
        let (w, h): (Bound<PyAny>, Bound<PyAny>) =
            v.extract().map_err(|_| wrong_type("resolution", v, "(width, height)"))?;
        let (w, h) = (self.uint32(Setting::Resolution, Some(&w))?, self.uint32(Setting::Resolution, Some(&h))?);
        self.note(Setting::Resolution, v)?;
        Ok(w.zip(h))
    }

    /// A thread count (its range is the core's to check).
    pub(crate) fn threads(&mut self, value: Option<&Bound<'_, PyAny>>) -> PyResult<Option<usize>> {
        self.uint(Setting::Threads, value)?
            .map(|t| usize::try_from(t).map_err(|_| self.invalid(Setting::Threads, "out of range")))
            .transpose()
    }
}

/// An integer argument `name` (a Python int, or anything with `__index__`; not a bool): `None`
/// for one below 0 or of 2**64 or more (its range is the caller's to word), a `TypeError`
/// naming the argument for anything else (a float too: `planes=2048.0`).
pub(crate) fn integer(name: &str, v: &Bound<'_, PyAny>) -> PyResult<Option<u64>> {
    if v.is_instance_of::<PyBool>() {
        return Err(wrong_type(name, v, "an integer"));
    }
    match v.extract::<u64>() {
        Ok(n) => Ok(Some(n)),
        Err(e) if e.is_instance_of::<PyOverflowError>(v.py()) => Ok(None),
        Err(_) => Err(wrong_type(name, v, "an integer")),
    }
}

/// A text argument `name`: a `str`, else the `TypeError` of [`wrong_type`]; a `str` that is no
/// valid Unicode (a lone surrogate, which Python's str may hold) a `ValueError` saying so, not
/// "expected a str, got str".
pub(crate) fn text(name: &str, v: &Bound<'_, PyAny>) -> PyResult<String> {
    if !v.is_instance_of::<pyo3::types::PyString>() {
        return Err(wrong_type(name, v, "a str"));
    }
    v.extract::<String>().map_err(|_| {
        PyValueError::new_err(format!("{name}: not valid Unicode text (it holds a lone surrogate, such as '\\ud800')"))
    })
}

/// The `TypeError` for argument `name` given `v` where `what` is asked: `name=repr: expected
/// what, got type` (`spp=True: expected an integer, got bool`).
pub(crate) fn wrong_type(name: &str, v: &Bound<'_, PyAny>, what: &str) -> PyErr {
    let type_name = v.get_type().name().map(|n| n.to_string()).unwrap_or_default();
    PyTypeError::new_err(format!("{name}={}: expected {what}, got {type_name}", short_repr(v)))
}

/// `repr(v)`, cut to 80 characters (an error message names a value, it does not print it).
pub(crate) fn short_repr(v: &Bound<'_, PyAny>) -> String {
    let repr = v.repr().map(|r| r.to_string()).unwrap_or_else(|_| "<unprintable>".into());
    if repr.chars().count() <= 80 { repr } else { format!("{}...", repr.chars().take(77).collect::<String>()) }
}

/// A string as Python's repr writes it (for names without quotes or escapes, which is all of them
/// in practice; others are shown Rust's way).
pub(crate) fn py_str(s: &str) -> String {
    if s.chars().all(|c| c != '\'' && c != '\\' && !c.is_control()) { format!("'{s}'") } else { format!("{s:?}") }
}
