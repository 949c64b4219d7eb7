//! The library's errors: what went wrong, typed, so that a caller (the command line, Python)
//! can tell bad input from a failure of the machine and word both its own way.

use std::fmt;
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
    /// An input file (an image, a part) that cannot be read or used.
    #[error("{}: {message}", one_line(&path.display().to_string()))]
    BadInput { path: PathBuf, message: String },
    /// Two images that cannot be compared.
    #[error("the images differ in size: {}x{} against a {}x{} reference", image.0, image.1, reference.0, reference.1)]
    SizeMismatch { image: (u32, u32), reference: (u32, u32) },
    /// An image holding NaN or infinity where numbers are needed (a metric would hide it).
    #[error("the {image} holds a value that is not a finite number: {pixel}")]
    NonFinitePixel { image: &'static str, pixel: NonFinitePixel },
    /// An output that cannot be written (the destination keeps its old contents).
    #[error("{}: {message}", one_line(&path.display().to_string()))]
    Write { path: PathBuf, message: String },
    /// Partial renders that do not make up one render (another scene or other settings,
    /// overlapping or missing plane ranges), a plane range that is not one of a render's
    /// chunks, or sums no render can make (see [`crate::partial::Partial::check`]).
    #[error("{0}")]
    Partial(String),
    /// An array the library made and was given back (a reference's pilot pass, its per-pixel
    /// sample counts) holding what the library never makes: `name` is the array as the caller
    /// passes it (`pilot`, `counts`).
    #[error("{name}: {message}")]
    BadArray { name: &'static str, message: String },
    /// An image and a reference that were made to measure different things (another pixel
    /// filter), as their recorded metadata says ([`crate::film::ImageInfo`]).
    #[error("{0}")]
    NotComparable(String),
    /// The caller stopped the work (through the flag of its [`crate::control::Control`]).
    #[error("cancelled")]
    Cancelled,
    /// The GPU failed while working (a validation error, out of memory, a lost device).
    #[error("the GPU: {0}")]
    Device(String),
}

impl Error {
    /// Whether the error is the caller's input (exit code 2 on the command line) rather than a
    /// failure while working.
    pub fn is_input(&self) -> bool {
        !matches!(self, Error::Write { .. } | Error::Cancelled | Error::Device(_))
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

    /// What is wrong with the input file `path`; whatever of the file the message quotes
    /// stays on its line ([`one_line`]).
    pub(crate) fn bad_input(path: &Path, message: impl Into<String>) -> Self {
        Error::BadInput { path: path.to_path_buf(), message: one_line(&message.into()) }
    }

    pub(crate) fn write(path: &Path, message: impl std::fmt::Display) -> Self {
        Error::Write { path: path.to_path_buf(), message: message.to_string() }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// `text` on one line: control characters (a newline in a file's name, or in a string a file
/// holds and an error quotes) and text-direction overrides written as escapes, so that an error
/// is always one line, read in its own order.
pub fn one_line(text: &str) -> String {
    if !text.chars().any(acts_on_terminal) {
        return text.to_string();
    }
    text.chars().map(|c| if acts_on_terminal(c) { c.escape_default().to_string() } else { c.to_string() }).collect()
}

/// A character that acts on a terminal rather than showing: a control character (an escape
/// sequence's start, a newline), Unicode's line and paragraph separators (which a terminal or
/// an editor may break the line at), or one of its bidirectional formatting characters
/// (embeddings, overrides, isolates, marks), which `char::is_control` does not count and which
/// reorder the text after them.
pub fn acts_on_terminal(c: char) -> bool {
    c.is_control()
        || matches!(
            c,
            '\u{2028}' | '\u{2029}' | '\u{200E}' | '\u{200F}' | '\u{061C}' | '\u{202A}'..='\u{202E}' | '\u{2066}'..='\u{2069}'
        )
}

/// A problem with a scene file or with the render settings derived from it.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneError {
    pub file: String,
    /// 1-based line and column, when the problem has a place in the text.
    pub position: Option<(usize, usize)>,
    /// Dotted path of the field, e.g. `light[2].edge_v`; empty for the file as a whole.
    pub field: String,
    pub message: String,
}

impl fmt::Display for SceneError {
    /// One line ([`one_line`]), whatever it quotes of the file: the TOML reader's messages and
    /// paths quote keys as they are (an unknown key holding an escape sequence reached the
    /// terminal raw).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", one_line(&self.file))?;
        if let Some((line, col)) = self.position {
            write!(f, ":{line}:{col}")?;
        }
        if !self.field.is_empty() {
            write!(f, ": {}", one_line(&self.field))?;
        }
        write!(f, ": {}", one_line(&self.message))
    }
}

impl std::error::Error for SceneError {}

/// A setting a user may give, named neutrally; [`Setting::flag`] and [`Setting::keyword`] are
/// its names on the command line and in Python.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Setting {
    Estimator,
    Orientations,
    Planes,
    Seed,
    Sampler,
    /// The share of each light's planes swept along the phase function's lobe.
    Lobes,
    Spp,
    Accelerator,
    Kernel,
    /// The processor that gathers: cpu, gpu or auto.
    Device,
    TimeBudget,
    /// The relative RMS error a render in passes stops at.
    TargetError,
    Resolution,
    Threads,
    Exposure,
    /// The plane counts of the table's error-versus-time sweep.
    Sweep,
    SweepSeeds,
    EqualTime,
    /// The plane samplers the table measures.
    Samplers,
    /// The image sizes a scaling run measures.
    Resolutions,
}

impl Setting {
    pub const ALL: [Setting; 20] = [
        Setting::Estimator,
        Setting::Orientations,
        Setting::Planes,
        Setting::Seed,
        Setting::Sampler,
        Setting::Lobes,
        Setting::Spp,
        Setting::Accelerator,
        Setting::Kernel,
        Setting::Device,
        Setting::TimeBudget,
        Setting::TargetError,
        Setting::Resolution,
        Setting::Threads,
        Setting::Exposure,
        Setting::Sweep,
        Setting::SweepSeeds,
        Setting::EqualTime,
        Setting::Samplers,
        Setting::Resolutions,
    ];

    /// The name as a keyword argument (Python): `time_budget`.
    pub fn keyword(self) -> &'static str {
        match self {
            Setting::Estimator => "estimator",
            Setting::Orientations => "orientations",
            Setting::Planes => "planes",
            Setting::Seed => "seed",
            Setting::Sampler => "sampler",
            Setting::Lobes => "lobes",
            Setting::Spp => "spp",
            Setting::Accelerator => "accelerator",
            Setting::Kernel => "kernel",
            Setting::Device => "device",
            Setting::TimeBudget => "time_budget",
            Setting::TargetError => "target_error",
            Setting::Resolution => "resolution",
            Setting::Threads => "threads",
            Setting::Exposure => "exposure",
            Setting::Sweep => "sweep",
            Setting::SweepSeeds => "sweep_seeds",
            Setting::EqualTime => "equal_time",
            Setting::Samplers => "samplers",
            Setting::Resolutions => "resolutions",
        }
    }

    /// The name as a command-line flag: `--time-budget`.
    pub fn flag(self) -> String {
        format!("--{}", self.keyword().replace('_', "-"))
    }

    /// The field of a scene file that gives the setting's default, if any.
    pub fn scene_field(self) -> Option<&'static str> {
        Some(match self {
            Setting::Estimator => "render.estimator",
            Setting::Orientations => "render.orientations",
            Setting::Planes => "render.planes",
            Setting::Seed => "render.seed",
            Setting::Sampler => "render.sampler",
            Setting::Lobes => "render.lobes",
            Setting::Spp => "render.spp",
            Setting::Resolution => "camera.resolution",
            _ => return None,
        })
    }
}

/// Where the value of a setting came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Origin {
    /// The caller gave it (a flag, a keyword argument).
    Given,
    /// The scene file gave it (its `[render]` table or its camera).
    Scene,
}

impl Origin {
    /// How an error names a value of `setting` from this origin when no front end words it.
    pub fn describe(self, setting: Setting) -> String {
        match (self, setting.scene_field()) {
            (Origin::Scene, Some(field)) => format!("the scene's {field}"),
            _ => setting.keyword().to_string(),
        }
    }
}

/// A pixel channel that is not a finite number: where it is and what it holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NonFinitePixel {
    pub x: u32,
    pub y: u32,
    /// 0, 1, 2 for R, G, B.
    pub channel: usize,
    pub value: f32,
}

/// A pixel channel holding what it cannot hold (not a number, infinite, negative, or beyond
/// what the image's making allows): where it is and what it holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelValue {
    pub x: u32,
    pub y: u32,
    /// 0, 1, 2 for R, G, B.
    pub channel: usize,
    pub value: f64,
}

impl std::fmt::Display for PixelValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let channel = ["R", "G", "B"][self.channel];
        write!(f, "pixel (x {}, y {}) channel {channel} is {}", self.x, self.y, Number(self.value))
    }
}

/// A number as a person reads it: 1e308 as `1e308` and 5e-324 as `5e-324`, not as their 309
/// and 324 digits (Rust's `{}` of an f64 writes every digit); in between as `{}` does. Either
/// way the shortest digits that read back as the same number.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Number(pub f64);

impl std::fmt::Display for Number {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = self.0;
        if v.is_finite() && v != 0.0 && !(1e-4..1e16).contains(&v.abs()) {
            write!(f, "{v:e}")
        } else {
            write!(f, "{v}")
        }
    }
}

/// A number to the decimals of the format's precision, as `{:.6}` writes it, but from 1e9 in
/// magnitude in scientific form with as many decimals: `{:.6}` of 7.6e19 writes 20 digits before
/// the point, of 1e300 301 (a scene of radiance 1e22 gives such a mean, a noise of 0 such a
/// ratio). The format's width, alignment and `+` apply to the whole.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fixed(pub f64);

impl std::fmt::Display for Fixed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (v, digits) = (self.0, f.precision().unwrap_or(6));
        let body = if v.is_finite() && v.abs() >= 1e9 { format!("{v:.digits$e}") } else { format!("{v:.digits$}") };
        let body = if f.sign_plus() && !body.starts_with('-') { format!("+{body}") } else { body };
        let width = f.width().unwrap_or(0);
        match f.align() {
            Some(std::fmt::Alignment::Left) => write!(f, "{body:<width$}"),
            Some(std::fmt::Alignment::Center) => write!(f, "{body:^width$}"),
            _ => write!(f, "{body:>width$}"),
        }
    }
}

impl std::fmt::Display for NonFinitePixel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let channel = ["R", "G", "B"][self.channel];
        write!(f, "pixel (x {}, y {}) channel {channel} is {}", self.x, self.y, self.value)
    }
}

#[cfg(test)]
mod tests {
    use super::Fixed;

    /// Fixed decimals below 1e9, scientific from there, with the format's width, alignment
    /// and sign.
    #[test]
    fn a_fixed_number_keeps_its_decimals_and_turns_scientific_when_large() {
        assert_eq!(format!("{:.6}", Fixed(0.074484)), "0.074484");
        assert_eq!(format!("{:.4}", Fixed(999_999_999.0)), "999999999.0000");
        assert_eq!(format!("{:.6}", Fixed(7.6e19)), "7.600000e19");
        assert_eq!(format!("{:.4}", Fixed(-2e9)), "-2.0000e9");
        assert_eq!(format!("{:+.1}", Fixed(5.93e300)), "+5.9e300");
        assert_eq!(format!("{:>+7.2}", Fixed(1.5)), "  +1.50");
        assert_eq!(format!("{:>+7.2}", Fixed(-1.5)), "  -1.50");
        assert_eq!(format!("{:<6.1}|", Fixed(2.0)), "2.0   |");
        assert_eq!(format!("{:.2}", Fixed(f64::INFINITY)), "inf");
    }
}
