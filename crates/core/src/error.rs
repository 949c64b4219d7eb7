//! The library's errors: what went wrong, typed, so that a caller (the command line, Python)
//! can tell bad input from a failure of the machine and word both its own way.

use crate::scene::SceneError;
use crate::settings::{Origin, Setting};
use std::path::{Path, PathBuf};

/// Everything the library can fail with. Nothing in the library panics on any input.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A scene file that cannot be read or does not describe a valid scene.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// A setting out of range. The setting is named neutrally (each front end words it as its
    /// user gave it: `--planes` on the command line, `planes=` in Python, see
    /// [`Error::worded`]); `origin` says whether the caller gave the value or the scene did.
    #[error("{}: {message}", origin.describe(*setting))]
    InvalidSetting { setting: Setting, origin: Origin, message: String },
    /// An input file (an image) that cannot be read or used.
    #[error("{}: {message}", path.display())]
    BadInput { path: PathBuf, message: String },
    /// Two images that cannot be compared.
    #[error("the images differ in size: {}x{} against a {}x{} reference", image.0, image.1, reference.0, reference.1)]
    SizeMismatch { image: (u32, u32), reference: (u32, u32) },
    /// An image holding NaN or infinity where numbers are needed (a metric would hide it).
    #[error("the {image} holds a value that is not a finite number: {pixel}")]
    NonFinitePixel { image: &'static str, pixel: crate::film::NonFinitePixel },
    /// An output that cannot be written (the destination keeps its old contents).
    #[error("{}: {message}", path.display())]
    Write { path: PathBuf, message: String },
    /// Partial renders that do not make up one render (another scene or other settings,
    /// overlapping or missing plane ranges), or a plane range that is not one of a render's
    /// chunks.
    #[error("{0}")]
    Partial(String),
    /// The caller stopped the work (through the flag of its [`crate::control::Control`]).
    #[error("cancelled")]
    Cancelled,
}

impl Error {
    /// Whether the error is the caller's input (exit code 2 on the command line) rather than a
    /// failure while working.
    pub fn is_input(&self) -> bool {
        !matches!(self, Error::Write { .. } | Error::Cancelled)
    }

    /// The error in one line, a setting the caller gave named by `name` (the command line
    /// passes [`Setting::flag`], Python the keyword with the value it was given); a value
    /// that came from the scene is named as the scene file names it, whoever words it.
    pub fn worded(&self, name: impl Fn(Setting) -> String) -> String {
        match self {
            Error::InvalidSetting { setting, origin: Origin::Given, message } => {
                format!("{}: {message}", name(*setting))
            }
            e => e.to_string(),
        }
    }

    /// A value the caller gave for `setting` is out of range.
    pub(crate) fn option(setting: Setting, message: impl Into<String>) -> Self {
        Error::InvalidSetting { setting, origin: Origin::Given, message: message.into() }
    }

    pub(crate) fn bad_input(path: &Path, message: impl Into<String>) -> Self {
        Error::BadInput { path: path.to_path_buf(), message: message.into() }
    }

    pub(crate) fn write(path: &Path, message: impl std::fmt::Display) -> Self {
        Error::Write { path: path.to_path_buf(), message: message.to_string() }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
