//! Pixel buffers and image files: linear float EXR, tone-mapped sRGB PNG.
//!
//! Every file is written to a temporary name beside its destination and renamed over it, so a
//! destination holds either its old contents or the complete new image, never part of one.
//! An EXR written by fogplanes records how it was made in its header ([`ImageInfo`]).

use crate::error::{Error, NonFinitePixel, PixelValue, Result};
use glam::{DVec3, Vec3};
use std::io::Write;
use std::path::{Path, PathBuf};

/// A linear RGB image, row-major, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Vec3>,
}

impl Film {
    pub fn new(width: u32, height: u32) -> Self {
        Film { width, height, pixels: vec![Vec3::ZERO; width as usize * height as usize] }
    }

    pub fn get(&self, x: u32, y: u32) -> Vec3 {
        self.pixels[y as usize * self.width as usize + x as usize]
    }

    /// Mean over pixels and channels.
    pub fn mean(&self) -> f64 {
        self.pixels.iter().map(|p| (p.x + p.y + p.z) as f64).sum::<f64>() / (3.0 * self.pixels.len().max(1) as f64)
    }

    /// Largest channel value.
    pub fn max(&self) -> f32 {
        self.pixels.iter().map(|p| p.max_element()).fold(0.0, f32::max)
    }

    pub fn all_finite_non_negative(&self) -> bool {
        self.pixels.iter().all(|p| p.is_finite() && p.min_element() >= 0.0)
    }

    /// The first pixel channel (in row-major order, then R, G, B) that is NaN or infinite.
    pub fn first_non_finite(&self) -> Option<NonFinitePixel> {
        let w = self.width.max(1) as usize;
        self.pixels.iter().enumerate().find_map(|(i, p)| {
            let channel = (0..3).find(|&c| !p[c].is_finite())?;
            Some(NonFinitePixel { x: (i % w) as u32, y: (i / w) as u32, channel, value: p[channel] })
        })
    }

    /// The image of a photon-plane render (docs/mathematics.md section 8), the one place an
    /// image is finished: per pixel, the sum of every plane's contribution (each weighted 1,
    /// added in f64) divided by the plane count N in f64, rounded to f32 once, plus the direct
    /// emission over the pixel. Refuses an image that would hold a value that is not a finite
    /// number (f32 overflow, where sums divided by N come near `f32::MAX`), naming the pixel:
    /// no image holds NaN or infinity.
    pub fn finish(width: u32, height: u32, sums: &[DVec3], planes: usize, emission: &[Vec3]) -> Result<Film> {
        let n = planes as f64;
        use rayon::prelude::*;
        let pixels = sums.par_iter().zip(emission).map(|(s, e)| (*s / n).as_vec3() + *e).collect();
        let film = Film { width, height, pixels };
        film.check_finite("image")?;
        Ok(film)
    }

    /// The first pixel channel that is not a number in `[0, max]` (see [`first_outside`]).
    pub fn first_outside(&self, max: f64) -> Option<PixelValue> {
        first_outside(self.pixels.iter().map(|p| p.as_dvec3().to_array()), self.width, max)
    }

    /// Refuses an image holding a NaN or infinite value, naming the first one; `image` says
    /// which image it is ("image", "reference"). The pixels are scanned in parallel, and again
    /// in order only to name the first one (serial, the scan was 0.4 ms of a 640x360 image's
    /// finishing, on the path of every render).
    pub fn check_finite(&self, image: &'static str) -> Result<()> {
        use rayon::prelude::*;
        if self.pixels.par_iter().all(|p| p.is_finite()) {
            return Ok(());
        }
        match self.first_non_finite() {
            Some(pixel) => Err(Error::NonFinitePixel { image, pixel }),
            None => Ok(()),
        }
    }
}

/// The first pixel channel of `pixels` (row-major, `width` wide; R, G, B) that is not a number
/// in `[0, max]`: what every array of pixels the library reads back from a file or a caller
/// is held to (NaN, infinities and negative values included).
pub fn first_outside(pixels: impl IntoIterator<Item = [f64; 3]>, width: u32, max: f64) -> Option<PixelValue> {
    let w = width.max(1) as usize;
    pixels.into_iter().enumerate().find_map(|(i, p)| {
        let channel = (0..3).find(|&c| !(p[c] >= 0.0 && p[c] <= max))?;
        Some(PixelValue { x: (i % w) as u32, y: (i / w) as u32, channel, value: p[channel] })
    })
}

/// How an image was made, recorded in its EXR header as pbrt-v4 records a render's settings:
/// named text fields, in the order given, each written as the header attribute `fogplanes.KEY`.
/// fogplanes writes them into every EXR of a render or a reference ([`Film::save_with_info`]),
/// and `compare` and `table` read them back ([`Film::load_exr_with_info`]) to refuse a
/// reference of another pixel filter. An image made elsewhere (Mitsuba's) has none.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImageInfo {
    pub fields: Vec<(String, String)>,
}

impl ImageInfo {
    /// The prefix of the header attributes that hold the fields.
    pub const PREFIX: &'static str = "fogplanes.";
    /// What the image is: `render`, `reference`, `render standard error`, `reference standard
    /// error` or [`ImageInfo::Z_IMAGE`].
    pub const IMAGE: &'static str = "image";
    /// What `compare --z-image` writes: the difference over its noise, per pixel and channel.
    pub const Z_IMAGE: &'static str = "compare z-image";
    /// `box` (the mean over the pixel's square) or `center` (the pixel's centre).
    pub const PIXEL_FILTER: &'static str = "pixel_filter";
    /// `WIDTHxHEIGHT`.
    pub const RESOLUTION: &'static str = "resolution";
    /// [`crate::scene::Scene::fingerprint`]: the scene's content.
    pub const SCENE: &'static str = "scene";
    /// The order fields are printed in; others follow, sorted.
    const ORDER: [&'static str; 20] = [
        "image",
        "fogplanes",
        "scene_name",
        "scene",
        "medium_g",
        "resolution",
        "pixel_filter",
        "estimator",
        "orientations",
        "planes",
        "seed",
        "sampler",
        "lobes",
        "spp",
        "ray_sets",
        "accelerator",
        "samples",
        "seconds",
        "hits",
        "compared",
    ];

    /// The fields every image of fogplanes records: what it is, the fogplanes version, the
    /// scene (name and fingerprint), the resolution and the pixel filter.
    pub fn new(image: &str, scene_name: &str, scene: String, (width, height): (u32, u32), pixel_center: bool) -> Self {
        ImageInfo::default()
            .with(Self::IMAGE, image)
            .with("fogplanes", env!("CARGO_PKG_VERSION"))
            .with("scene_name", scene_name)
            .with(Self::SCENE, scene)
            .with(Self::RESOLUTION, format!("{width}x{height}"))
            .with(Self::PIXEL_FILTER, pixel_filter_name(pixel_center))
    }

    /// The record of `compare --z-image`'s image: what it is, the fogplanes version, what the
    /// image compared records of its scene, resolution and pixel filter (its `image` record,
    /// if it has one; else the resolution alone), and the files compared.
    pub fn z_image(image: Option<&ImageInfo>, (width, height): (u32, u32), compared: &str) -> Self {
        let mut info =
            ImageInfo::default().with(Self::IMAGE, Self::Z_IMAGE).with("fogplanes", env!("CARGO_PKG_VERSION"));
        for key in ["scene_name", Self::SCENE, Self::PIXEL_FILTER] {
            if let Some(v) = image.and_then(|i| i.get(key)) {
                info = info.with(key, v);
            }
        }
        info.with(Self::RESOLUTION, format!("{width}x{height}")).with("compared", compared)
    }

    /// The fields with the medium's Henyey-Greenstein `g` recorded as `medium_g`, where it is not
    /// 0 (an isotropic scene's record is what it was before g; the fingerprint holds g too).
    pub fn with_medium_g(self, g: f64) -> Self {
        if g == 0.0 { self } else { self.with("medium_g", g) }
    }

    /// The fields with `key` set to `value` (replaced if present).
    pub fn with(mut self, key: &str, value: impl std::fmt::Display) -> Self {
        let value = value.to_string();
        match self.fields.iter_mut().find(|(k, _)| k == key) {
            Some(field) => field.1 = value,
            None => self.fields.push((key.to_string(), value)),
        }
        self
    }

    pub fn get(&self, key: &str) -> Option<&str> {
        self.fields.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    /// The fields in the order of [`ImageInfo::ORDER`], then the others by name.
    fn sorted(mut self) -> Self {
        let rank = |k: &str| Self::ORDER.iter().position(|o| *o == k).unwrap_or(Self::ORDER.len());
        self.fields.sort_by(|(a, _), (b, _)| (rank(a), a).cmp(&(rank(b), b)));
        self
    }

    /// The header attributes that record the fields (text, UTF-8).
    fn attributes(
        &self,
    ) -> std::collections::HashMap<exr::meta::attribute::Text, exr::meta::attribute::AttributeValue> {
        use exr::meta::attribute::{AttributeValue, Text};
        self.fields
            .iter()
            .map(|(k, v)| {
                let name = Text::from_slice_unchecked(format!("{}{k}", Self::PREFIX).as_bytes());
                (name, AttributeValue::Text(Text::from_slice_unchecked(v.as_bytes())))
            })
            .collect()
    }

    /// The fields an EXR header records, if it records any.
    fn of_header(header: &exr::meta::header::Header) -> Option<ImageInfo> {
        use exr::meta::attribute::AttributeValue;
        let fields: Vec<(String, String)> = header
            .own_attributes
            .other
            .iter()
            .filter_map(|(name, value)| {
                let key = std::str::from_utf8(name.as_slice()).ok()?.strip_prefix(Self::PREFIX)?;
                let AttributeValue::Text(text) = value else { return None };
                Some((key.to_string(), String::from_utf8_lossy(text.as_slice()).into_owned()))
            })
            .collect();
        (!fields.is_empty()).then(|| ImageInfo { fields }.sorted())
    }

    /// Whether `reference` can be the reference of `image`, as far as what they record says
    /// (an image without a record says nothing): refuses another pixel filter or resolution;
    /// returns a warning when they record different scenes.
    pub fn check_reference(image: Option<&ImageInfo>, reference: Option<&ImageInfo>) -> Result<Option<String>> {
        ImageInfo::check_is_image(image, "--stderr")?;
        ImageInfo::check_is_image(reference, "--ref-stderr")?;
        let (Some(image), Some(reference)) = (image, reference) else { return Ok(None) };
        let differ = |key: &str| match (image.get(key), reference.get(key)) {
            (Some(a), Some(b)) if a != b => Some((a.to_string(), b.to_string())),
            _ => None,
        };
        if let Some((a, b)) = differ(Self::PIXEL_FILTER) {
            return Err(Error::NotComparable(format!(
                "the reference was made with the pixel filter {b}, the image with {a}: an error between them \
                 measures the filters (make both with --pixel-center, or neither)"
            )));
        }
        if let Some((a, b)) = differ(Self::RESOLUTION) {
            return Err(Error::NotComparable(format!("the reference is {b} pixels, the image {a}")));
        }
        Ok(match (image.get(Self::SCENE), reference.get(Self::SCENE)) {
            (Some(a), Some(b)) if a != b => {
                let (name_a, name_b) =
                    (image.get("scene_name").unwrap_or("?"), reference.get("scene_name").unwrap_or("?"));
                // Where the names agree, what tells the scenes apart that the record holds: the
                // medium's g (recorded where it is not 0).
                let (g_a, g_b) = (image.get("medium_g").unwrap_or("0"), reference.get("medium_g").unwrap_or("0"));
                let g = if g_a != g_b { format!(", of medium g {g_a} and {g_b}") } else { String::new() };
                let warning = format!("the image and the reference record different scenes ({name_a} and {name_b}{g})");
                Some(crate::error::one_line(&warning))
            }
            _ => None,
        })
    }
}

impl ImageInfo {
    /// Refuses an error image where an image is measured (`flag`: where its standard error
    /// goes instead), as far as its record says.
    pub fn check_is_image(info: Option<&ImageInfo>, flag: &str) -> Result<()> {
        match info.and_then(|i| i.get(Self::IMAGE)) {
            Some(kind) if kind.ends_with("standard error") => Err(Error::NotComparable(format!(
                "it records a {kind}, not an image: measure an image (a standard error goes to compare's {flag})"
            ))),
            Some(kind) if kind == Self::Z_IMAGE => Err(Error::NotComparable(format!(
                "it records a {kind} (the difference of two images over its noise), not an image to measure"
            ))),
            _ => Ok(()),
        }
    }

    /// Whether `stderr` can be the standard error of an image that records `image`, as far as
    /// their records say: it must record a standard error (a render's or a reference's), of the
    /// same resolution and pixel filter.
    pub fn check_stderr(stderr: Option<&ImageInfo>, image: Option<&ImageInfo>) -> Result<()> {
        let Some(stderr) = stderr else { return Ok(()) };
        if let Some(kind) = stderr.get(Self::IMAGE).filter(|k| !k.ends_with("standard error")) {
            return Err(Error::NotComparable(format!(
                "it records a {kind}, not a standard error (`render --stderr-image` or `reference --stderr-image` writes one)"
            )));
        }
        for key in [Self::RESOLUTION, Self::PIXEL_FILTER] {
            if let (Some(a), Some(b)) = (stderr.get(key), image.and_then(|i| i.get(key)))
                && a != b
            {
                return Err(Error::NotComparable(format!("it records {key} {a}, its image {b}")));
            }
        }
        Ok(())
    }
}

impl std::fmt::Display for ImageInfo {
    /// One `key: value` line per field, each on its line whatever it holds
    /// ([`crate::error::one_line`]: a scene named after a file whose name holds an escape
    /// sequence or a newline, or a record forged in a part file, reached the terminal raw).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use crate::error::one_line;
        for (k, v) in &self.fields {
            writeln!(f, "{}: {}", one_line(k), one_line(v))?;
        }
        Ok(())
    }
}

/// The pixel filter as images record it.
pub fn pixel_filter_name(pixel_center: bool) -> &'static str {
    if pixel_center { "center" } else { "box" }
}

/// The image formats, chosen by file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    Exr,
    Png,
}

impl ImageFormat {
    pub fn from_path(path: &Path) -> Result<Self> {
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("exr") => Ok(ImageFormat::Exr),
            Some("png") => Ok(ImageFormat::Png),
            _ => Err(Error::bad_input(path, "the output must end in .exr (linear float) or .png (tone-mapped sRGB)")),
        }
    }
}

/// Checks before any work that an image can be written to `path`: a known extension and a
/// writable place ([`check_writable`]).
pub fn check_image_output(path: &Path) -> Result<()> {
    ImageFormat::from_path(path)?;
    check_writable(path)
}

/// Checks before any work that `path` can be written: an existing, writable directory (probed
/// by creating and removing a temporary file), and not a directory itself. Through a symbolic
/// link, the link's target is checked ([`destination`]); a device or a pipe is written into as
/// it is, not probed (opening a pipe for writing waits for its reader).
pub fn check_writable(path: &Path) -> Result<()> {
    let path = &destination(path);
    if is_special(path) {
        return Ok(());
    }
    let dir = parent_dir(path);
    if !dir.is_dir() {
        return Err(Error::bad_input(path, format!("the output directory {} does not exist", dir.display())));
    }
    if path.is_dir() {
        return Err(Error::bad_input(path, "is a directory"));
    }
    // Made and removed under the lock of the unfinished files: an interruption never finds it.
    let _unfinished = unfinished();
    let probe = temporary_path(path);
    std::fs::File::create(&probe)
        .map_err(|e| Error::bad_input(path, format!("cannot write to {}: {e}", dir.display())))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// A hidden temporary name beside `path`, unique to this process and this call (two threads
/// writing the same destination, as Python may, never share one).
pub fn temporary_path(path: &Path) -> PathBuf {
    temporary_in(&parent_dir(path), path)
}

/// [`temporary_path`]'s name for `path`, in `dir`.
fn temporary_in(dir: &Path, path: &Path) -> PathBuf {
    static COUNT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    dir.join(format!(".{name}.{}.{n}.tmp", std::process::id()))
}

/// The files of this process's writes: those being written now (temporary), for
/// [`remove_unfinished_files`], and those moved into place. A temporary file is created and
/// registered, and renamed and unregistered, under this lock, which the removal keeps until the
/// process ends: a file is either registered (and removed) or never made, and the files moved
/// into place are all there are.
struct Files {
    unfinished: Vec<PathBuf>,
    written: Vec<PathBuf>,
}

impl Files {
    /// Records a file moved into place, as its writer named it: each once, the latest thousand
    /// (what an interruption's note names: a command's outputs come after the files of its
    /// checkpoint, of which a long job writes more than that).
    fn wrote(&mut self, path: &Path) {
        self.written.retain(|p| p != path);
        if self.written.len() == 1000 {
            self.written.remove(0);
        }
        self.written.push(path.to_path_buf());
    }
}

static FILES: std::sync::Mutex<Files> = std::sync::Mutex::new(Files { unfinished: Vec::new(), written: Vec::new() });

fn unfinished() -> std::sync::MutexGuard<'static, Files> {
    FILES.lock().unwrap_or_else(|e| e.into_inner())
}

/// Removes every temporary file still being written, for a process about to exit on an
/// interruption (Ctrl-C, SIGTERM): the destinations keep their old contents, and no write can
/// start or finish after this (they wait for a lock that is never released). Gives the files
/// this process wrote whole before it, in order, so that the interruption can say so.
pub fn remove_unfinished_files() -> Vec<PathBuf> {
    let files = unfinished();
    for p in &files.unfinished {
        let _ = std::fs::remove_file(p);
    }
    let written = files.written.clone();
    std::mem::forget(files);
    written
}

/// Where a write to `path` goes: through symbolic links to the file they name (a link is
/// written through, not replaced by a file), else `path` itself. A device or a pipe is opened
/// as named (`/dev/stdout` is a link to a link whose target is no path).
fn destination(path: &Path) -> PathBuf {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf()),
        Ok(_) => path.to_path_buf(),
        // A link to nothing yet: its target, made by the write (one step: a chain of such links,
        // or a loop, is left to the write to refuse).
        Err(_) => match std::fs::read_link(path) {
            Ok(target) => parent_dir(path).join(target),
            Err(_) => path.to_path_buf(),
        },
    }
}

/// Whether `path` exists and is neither a file nor a directory: a device, a pipe or a socket,
/// written into as it is (a temporary file renamed over it would replace it).
fn is_special(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// The writes of [`written_together`] on this thread, renamed into place together at its end:
/// each one's temporary file, its destination and the path its writer named.
type Staged = Vec<(PathBuf, PathBuf, PathBuf)>;

thread_local! {
    static TOGETHER: std::cell::RefCell<Option<Staged>> = const { std::cell::RefCell::new(None) };
}

/// Runs `writes`, whose [`write_atomically`] calls on this thread each write their temporary
/// file, and moves them all into place at the end, under one hold of the lock an interruption
/// takes: a command's outputs (an image and its error image) are then all written or none of
/// them, and where one fails, none is moved.
pub fn written_together<T>(writes: impl FnOnce() -> Result<T>) -> Result<T> {
    /// Should `writes` panic: its temporary files removed, and this thread's writes immediate
    /// again.
    struct Unwound;
    impl Drop for Unwound {
        fn drop(&mut self) {
            if let Some(staged) = TOGETHER.with(|t| t.borrow_mut().take()) {
                let mut files = unfinished();
                for (tmp, _, _) in staged {
                    let _ = std::fs::remove_file(&tmp);
                    files.unfinished.retain(|p| p != &tmp);
                }
            }
        }
    }
    let outer = TOGETHER.with(|t| t.borrow_mut().replace(Vec::new()));
    assert!(outer.is_none(), "written_together does not nest");
    let unwound = Unwound;
    let result = writes();
    let staged = TOGETHER.with(|t| t.borrow_mut().take()).unwrap_or_default();
    drop(unwound);
    let mut files = unfinished();
    let mut result = result;
    for (tmp, target, path) in &staged {
        if result.is_ok() {
            match std::fs::rename(tmp, target) {
                Ok(()) => files.wrote(path),
                Err(e) => result = Err(Error::write(path, format!("cannot move the finished file into place: {e}"))),
            }
        }
        if result.is_err() {
            let _ = std::fs::remove_file(tmp);
        }
        files.unfinished.retain(|p| p != tmp);
    }
    result
}

/// Writes through `write` to a new temporary file, then renames it to `path` (inside
/// [`written_together`], at its end with the others); on any failure the temporary file is
/// removed and `path` is untouched. Through a symbolic link the link's target is written; a
/// device or a pipe ([`is_special`]) is sent the finished file, written first to a temporary
/// file of the system's (an EXR is written with seeks, which a pipe has not).
pub fn write_atomically(path: &Path, write: impl FnOnce(&mut std::fs::File) -> Result<()>) -> Result<()> {
    let target = destination(path);
    let special = is_special(&target);
    let (tmp, mut file) = {
        let mut files = unfinished();
        let tmp = if special { temporary_in(&std::env::temp_dir(), path) } else { temporary_path(&target) };
        // Readable too: an EXR's header is read back and its attributes put in order
        // ([`sort_exr_attributes`]).
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(&tmp)
            .map_err(|e| Error::write(path, format!("cannot write: {e}")))?;
        files.unfinished.push(tmp.clone());
        (tmp, file)
    };
    let result = write(&mut file).and_then(|()| {
        // On disk before the rename.
        file.sync_all().map_err(|e| Error::write(path, format!("cannot write: {e}")))
    });
    drop(file);
    if special {
        // Sent whole once finished; a device has no old contents to keep, so it takes no part
        // in written_together.
        let result = result.and_then(|()| {
            let mut from = std::fs::File::open(&tmp).map_err(|e| Error::write(path, format!("cannot write: {e}")))?;
            let mut to = std::fs::OpenOptions::new()
                .write(true)
                .open(&target)
                .map_err(|e| Error::write(path, format!("cannot write: {e}")))?;
            std::io::copy(&mut from, &mut to).map(drop).map_err(|e| Error::write(path, format!("cannot write: {e}")))
        });
        let mut files = unfinished();
        let _ = std::fs::remove_file(&tmp);
        files.unfinished.retain(|p| p != &tmp);
        if result.is_ok() {
            files.wrote(path);
        }
        return result;
    }
    if result.is_ok() {
        let deferred = TOGETHER.with(|t| {
            t.borrow_mut().as_mut().map(|staged| staged.push((tmp.clone(), target.clone(), path.to_path_buf())))
        });
        if deferred.is_some() {
            return Ok(());
        }
    }
    let mut files = unfinished();
    let result = result.and_then(|()| {
        std::fs::rename(&tmp, &target)
            .map_err(|e| Error::write(path, format!("cannot move the finished file into place: {e}")))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    } else {
        files.wrote(path);
    }
    files.unfinished.retain(|p| p != &tmp);
    result
}

/// Writes bytes whole or not at all.
pub fn write_file_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomically(path, |f| f.write_all(bytes).map_err(|e| Error::write(path, format!("cannot write: {e}"))))
}

/// sRGB encoding of a linear value in [0, 1].
pub fn srgb_encode(x: f32) -> f32 {
    if x <= 0.003_130_8 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 }
}

/// 8-bit sRGB of a linear value scaled by 2^exposure, clamped.
pub fn to_srgb8(x: f32, exposure: f32) -> u8 {
    let v = (x * exposure.exp2()).clamp(0.0, 1.0);
    (srgb_encode(v) * 255.0 + 0.5) as u8
}

impl Film {
    /// Writes the image by the path's extension; PNG is tone-mapped by `exposure` stops.
    pub fn save(&self, path: &Path, exposure: f32) -> Result<()> {
        self.save_with_info(path, exposure, None)
    }

    /// [`Film::save`], an EXR recording `info` in its header (a PNG records nothing).
    pub fn save_with_info(&self, path: &Path, exposure: f32, info: Option<&ImageInfo>) -> Result<()> {
        self.check_size(path)?;
        match ImageFormat::from_path(path)? {
            ImageFormat::Exr => self.write_exr(path, info),
            ImageFormat::Png => self.save_png(path, exposure),
        }
    }

    pub fn save_exr(&self, path: &Path) -> Result<()> {
        self.check_size(path)?;
        self.write_exr(path, None)
    }

    /// A film assembled from pieces (bands of rows) that do not make it up is refused before it
    /// is written, not found by an index past its end.
    fn check_size(&self, path: &Path) -> Result<()> {
        if self.pixels.len() != self.width as usize * self.height as usize {
            return Err(Error::write(
                path,
                format!("{} pixels for an image of {}x{}", self.pixels.len(), self.width, self.height),
            ));
        }
        Ok(())
    }

    fn write_exr(&self, path: &Path, info: Option<&ImageInfo>) -> Result<()> {
        use exr::prelude::{Encoding, Image, Layer, LayerAttributes, SpecificChannels, Vec2, WritableImage};
        write_atomically(path, |file| {
            let w = self.width as usize;
            // What exr::prelude::write_rgb_file writes, into the file already open, with the
            // record of how the image was made among the layer's attributes.
            let rgb = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
                let p = self.pixels[y * w + x];
                (p.x, p.y, p.z)
            });
            let mut attributes = LayerAttributes::default();
            if let Some(info) = info {
                attributes.other = info.attributes();
            }
            // The blocks in increasing order: under `Unspecified` (the default) the crate writes
            // each block as its thread finishes compressing it, so that a render's EXR of
            // 640x360 came out in other bytes at every run (the offset table and the blocks in
            // another order; the same pixels).
            let encoding = Encoding { line_order: exr::meta::attribute::LineOrder::Increasing, ..Encoding::default() };
            Image::from_layer(Layer::new((w, self.height as usize), attributes, encoding, rgb))
                .write()
                .to_unbuffered(&mut *file)
                .map_err(|e| Error::write(path, format!("cannot write EXR: {e}")))?;
            sort_exr_attributes(file).map_err(|e| Error::write(path, format!("cannot write EXR: {e}")))
        })
    }

    /// The tone-mapped 8-bit sRGB image.
    pub fn to_rgb8(&self, exposure: f32) -> image::RgbImage {
        image::RgbImage::from_fn(self.width, self.height, |x, y| {
            let p = self.get(x, y);
            image::Rgb([to_srgb8(p.x, exposure), to_srgb8(p.y, exposure), to_srgb8(p.z, exposure)])
        })
    }

    pub fn save_png(&self, path: &Path, exposure: f32) -> Result<()> {
        save_rgb8_png(&self.to_rgb8(exposure), path)
    }

    /// Reads the first RGB(A) layer of an EXR file.
    ///
    /// The header is read and checked first ([`check_exr_headers`]): a small file claiming a
    /// huge image is refused before any pixel buffer exists. The buffer is then reserved
    /// fallibly, so that an image the machine cannot hold (under a memory limit) is an input
    /// error, not an abort.
    pub fn load_exr(path: &Path) -> Result<Film> {
        Film::load_exr_with_info(path).map(|(film, _)| film)
    }

    /// [`Film::load_exr`], with what the header records of how the image was made, if it
    /// records anything ([`ImageInfo`]).
    pub fn load_exr_with_info(path: &Path) -> Result<(Film, Option<ImageInfo>)> {
        let bad = |e: &dyn std::fmt::Display| Error::bad_input(path, format!("cannot read as an EXR image: {e}"));
        let meta = read_exr_headers(path)?;
        let info = meta.headers.first().and_then(ImageInfo::of_header);
        let unavailable = |size: (usize, usize)| {
            let gib = (size.0 * size.1 * std::mem::size_of::<Vec3>()) as f64 / (1u64 << 30) as f64;
            bad(&format!("{}x{} pixels need {gib:.1} GiB, which this machine cannot allocate now", size.0, size.1))
        };
        // Probed (and given back) before decoding, which would otherwise run to the file's end
        // before the failure could be told; for the layer the reader takes, so that a file
        // without one is refused before anything is reserved for its pixels.
        let h = rgb_layer(&meta.headers).map_err(|m| bad(&m))?;
        let size = (h.layer_size.width(), h.layer_size.height());
        Vec::<Vec3>::new().try_reserve_exact(size.0 * size.1).map_err(|_| unavailable(size))?;
        let image = exr::prelude::read_first_rgba_layer_from_file(
            path,
            |resolution, _| {
                let n = resolution.width() * resolution.height();
                // Left empty if the memory is not there: checked after reading.
                let mut pixels = Vec::new();
                if pixels.try_reserve_exact(n).is_ok() {
                    pixels.resize(n, Vec3::ZERO);
                }
                Film { width: resolution.width() as u32, height: resolution.height() as u32, pixels }
            },
            |film: &mut Film, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                let w = film.width as usize;
                if let Some(p) = film.pixels.get_mut(pos.y() * w + pos.x()) {
                    *p = Vec3::new(r, g, b);
                }
            },
        )
        .map_err(|e| bad(&e))?;
        let film = image.layer_data.channel_data.pixels;
        let size = (film.width as usize, film.height as usize);
        if film.pixels.len() != size.0 * size.1 {
            return Err(unavailable(size));
        }
        Ok((film, info))
    }
}

/// The layer [`Film::load_exr`] reads: the first with channels named R, G and B, as the exr
/// crate's reader of the first RGBA layer takes it. Its pixel buffer is then bounded by the
/// file's size: each of its pixels takes the file at least three half samples over the codec's
/// expansion ([`check_exr_headers`]; subsampled channels are refused with the headers), where a
/// layer of one channel would claim an image of 12 bytes a pixel for a third of that.
fn rgb_layer(headers: &[exr::meta::header::Header]) -> std::result::Result<&exr::meta::header::Header, &'static str> {
    let has = |h: &exr::meta::header::Header, name: &str| h.channels.list.iter().any(|c| c.name == *name);
    headers
        .iter()
        .find(|h| ["R", "G", "B"].iter().all(|n| has(h, n)))
        .ok_or("no layer has channels named R, G and B (fogplanes reads a linear RGB image)")
}

/// The headers of an EXR file, read and checked ([`check_exr_headers`]) before any pixel.
fn read_exr_headers(path: &Path) -> Result<exr::meta::MetaData> {
    let bad = |e: &dyn std::fmt::Display| Error::bad_input(path, format!("cannot read as an EXR image: {e}"));
    let file = std::fs::metadata(path).map_err(|e| bad(&e))?;
    if !file.is_file() {
        return Err(Error::bad_input(path, "not a regular file"));
    }
    // A PNG is the tone-mapped picture, not the radiance: say what to give instead.
    let mut magic = [0u8; 8];
    if std::fs::File::open(path).and_then(|mut f| std::io::Read::read_exact(&mut f, &mut magic)).is_ok()
        && magic == *b"\x89PNG\r\n\x1a\n"
    {
        return Err(Error::bad_input(
            path,
            "a PNG, which holds a tone-mapped picture: images are read and measured as EXR (linear radiance), as `-o NAME.exr` writes them",
        ));
    }
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| bad(&e))?;
    exr::meta::MetaData::validate(&meta.headers, false).map_err(|e| bad(&e))?;
    check_exr_headers(&meta.headers, file.len()).map_err(|m| bad(&m))?;
    Ok(meta)
}

/// What an EXR file's header records of how the image was made ([`ImageInfo`], `None` if
/// nothing), and its size; the file is read whole, every layer and channel decoded, so that a
/// file whose pixels are incomplete (truncated) or damaged is refused, not described as an
/// image.
pub fn read_image_info(path: &Path) -> Result<(Option<ImageInfo>, (u32, u32))> {
    let meta = read_exr_headers(path)?;
    let header = meta.headers.first().ok_or_else(|| Error::bad_input(path, "an EXR file without a header"))?;
    let size = (header.layer_size.width() as u32, header.layer_size.height() as u32);
    exr::prelude::read_all_flat_layers_from_file(path).map_err(|e| {
        Error::bad_input(path, format!("its header reads, but its pixel data is incomplete or damaged: {e}"))
    })?;
    Ok((ImageInfo::of_header(header), size))
}

/// The most bytes of samples that one byte of a chunk can decode to under `compression`, or
/// `None` for a codec this reader cannot decode. Each figure is the codec's worst case, so that
/// no valid file is refused:
///
/// - none: 1; RLE: 64 (a run of 128 bytes is coded in 2);
/// - ZIP, ZIPS: 1032, deflate's limit (a 258-byte match coded in 2 bits);
/// - PXR24: 1376, deflate of floats kept as 24 bits that decode to 32 (1032 x 4 / 3);
/// - PIZ: 454, Huffman codes of at least one bit and 8-bit run lengths (255 values of 16 bits
///   in 9 bits), the wavelet keeping the size;
/// - B44, B44A: 11 (a flat 4x4 block of halves, 32 bytes, coded in 3);
/// - DWAA, DWAB: 66048, deflate over a run-length or DC stream that is itself at most 64:1 (one
///   16-bit DC value per 8x8 block of halves).
fn exr_max_expansion(compression: exr::compression::Compression) -> Option<u64> {
    use exr::compression::Compression::*;
    Some(match compression {
        Uncompressed => 1,
        RLE => 64,
        ZIP1 | ZIP16 => 1032,
        PXR24 => 1376,
        PIZ => 454,
        B44 | B44A => 11,
        DWAA(_) | DWAB(_) => 66_048,
        HTJ2K32 | HTJ2K256 => return None,
    })
}

/// Checks EXR headers against the size of the file that holds them, before anything is
/// allocated for pixels: each chunk takes at least 16 bytes (its offset-table entry, its line
/// or tile number and its size), and the samples at least their uncompressed size over the
/// codec's worst-case expansion ([`exr_max_expansion`]). A header claiming more than the file
/// can hold is refused as truncated or crafted. Also refuses what this reader cannot decode
/// (deep data, HTJ2K) and sizes beyond [`crate::limits::check_resolution`].
pub fn check_exr_headers(headers: &[exr::meta::header::Header], file_bytes: u64) -> Result<(), String> {
    let mut needed: u128 = 0;
    for header in headers {
        let (w, h) = (header.layer_size.width(), header.layer_size.height());
        let side = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
        crate::limits::check_resolution(side(w), side(h))?;
        if header.deep {
            return Err("deep data is not supported".into());
        }
        let ratio =
            exr_max_expansion(header.compression).ok_or_else(|| format!("{} is not supported", header.compression))?;
        // Samples of the largest level alone (mip levels and rounding up only add), per
        // channel as subsampled.
        let samples: u128 = header
            .channels
            .list
            .iter()
            .map(|c| {
                let (sx, sy) = (c.sampling.x().max(1), c.sampling.y().max(1));
                (w / sx) as u128 * (h / sy) as u128 * c.sample_type.bytes_per_sample() as u128
            })
            .sum();
        needed += 16 * header.chunk_count as u128 + samples.div_ceil(ratio as u128);
    }
    if needed > file_bytes as u128 {
        let size = headers.first().map_or((0, 0), |h| (h.layer_size.width(), h.layer_size.height()));
        return Err(format!(
            "the header claims {}x{} pixels, which need at least {needed} bytes, but the file has {file_bytes}: it is truncated or crafted",
            size.0, size.1
        ));
    }
    Ok(())
}

/// Encodes a PNG in memory, then writes it whole.
pub fn save_rgb8_png(img: &image::RgbImage, path: &Path) -> Result<()> {
    let mut bytes = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png)
        .map_err(|e| Error::write(path, format!("cannot encode PNG: {e}")))?;
    write_file_atomically(path, &bytes)
}

/// The attributes of a written single-part EXR's header put in the order of their names. The
/// `exr` crate writes the custom ones (the record of how an image was made, [`ImageInfo`]) in a
/// hash map's order, which differs from process to process, so that two runs of one command
/// wrote the same pixels in files of different bytes. The header keeps its length (the same
/// attributes, in another order), so the offset table after it stays true; the format leaves
/// the order free.
fn sort_exr_attributes(file: &mut std::fs::File) -> std::io::Result<()> {
    use std::io::{Read, Seek, SeekFrom};
    fn bad(what: &str) -> std::io::Error {
        std::io::Error::other(format!("its header as written: {what}"))
    }
    /// The file's first `need` bytes in `head`, read 4 KB at a time.
    fn more(file: &mut std::fs::File, head: &mut Vec<u8>, need: usize) -> std::io::Result<()> {
        while head.len() < need {
            let before = head.len();
            Read::by_ref(file).take(4096).read_to_end(head)?;
            if head.len() == before {
                return Err(bad("it ends inside an attribute"));
            }
        }
        Ok(())
    }
    /// The place of the first NUL from `from`.
    fn nul(file: &mut std::fs::File, head: &mut Vec<u8>, from: usize) -> std::io::Result<usize> {
        loop {
            if let Some(k) = head.get(from..).and_then(|rest| rest.iter().position(|&b| b == 0)) {
                return Ok(from + k);
            }
            let len = head.len().max(from);
            more(file, head, len + 1)?;
        }
    }
    // Magic number and version field, then the attributes: name NUL, type NUL, size (i32, little
    // endian), value; an empty name ends the header.
    let mut head = Vec::new();
    file.seek(SeekFrom::Start(0))?;
    more(file, &mut head, 8)?;
    if head[..4] != [0x76, 0x2f, 0x31, 0x01] || head[5] & 0x10 != 0 {
        return Err(bad("not a single-part EXR"));
    }
    let (mut at, mut spans) = (8usize, Vec::new());
    loop {
        let name_end = nul(file, &mut head, at)?;
        if name_end == at {
            break;
        }
        let type_end = nul(file, &mut head, name_end + 1)?;
        more(file, &mut head, type_end + 5)?;
        let size = i32::from_le_bytes(head[type_end + 1..type_end + 5].try_into().expect("four bytes"));
        let size = usize::try_from(size).map_err(|_| bad("a negative size"))?;
        let end = type_end + 5 + size;
        more(file, &mut head, end)?;
        spans.push((at, name_end, end));
        at = end;
    }
    // By name; names are unique in a header.
    spans.sort_by(|a, b| head[a.0..a.1].cmp(&head[b.0..b.1]));
    let attributes: Vec<u8> = spans.iter().flat_map(|&(from, _, to)| head[from..to].iter().copied()).collect();
    debug_assert_eq!(attributes.len(), at - 8);
    file.seek(SeekFrom::Start(8))?;
    file.write_all(&attributes)?;
    file.seek(SeekFrom::End(0)).map(drop)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Files written together are moved into place together, or none where one fails; a link
    /// is written through (its target replaced, the link kept), a dangling one makes its
    /// target; a device is written into, not replaced by a file.
    #[cfg(unix)]
    #[test]
    fn outputs_written_together_links_written_through_and_devices_into() {
        let dir = std::env::temp_dir().join(format!("fogplanes-together-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let (a, b) = (dir.join("a.txt"), dir.join("b.txt"));
        for p in [&a, &b] {
            std::fs::write(p, "old").unwrap();
        }
        let read = |p: &Path| std::fs::read_to_string(p).unwrap();
        // The second write fails: neither file changes, and no temporary file is left.
        let e = written_together(|| {
            write_file_atomically(&a, b"new")?;
            assert_eq!(read(&a), "old", "moved before the end of the group");
            write_atomically(&b, |_| Err(Error::write(&b, "refused")))
        });
        assert!(e.is_err());
        assert_eq!((read(&a), read(&b)), ("old".to_string(), "old".to_string()));
        written_together(|| {
            write_file_atomically(&a, b"new")?;
            write_file_atomically(&b, b"new")
        })
        .unwrap();
        assert_eq!((read(&a), read(&b)), ("new".to_string(), "new".to_string()));
        // Through a link, and through a link to a file not yet there.
        let (link, dangling, target) = (dir.join("link.txt"), dir.join("dangling.txt"), dir.join("target.txt"));
        std::os::unix::fs::symlink("a.txt", &link).unwrap();
        std::os::unix::fs::symlink("target.txt", &dangling).unwrap();
        write_file_atomically(&link, b"through").unwrap();
        write_file_atomically(&dangling, b"made").unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert!(std::fs::symlink_metadata(&dangling).unwrap().file_type().is_symlink());
        assert_eq!((read(&a), read(&target)), ("through".to_string(), "made".to_string()));
        check_writable(&link).unwrap();
        // A device: written into (/dev/null takes anything), still a device.
        write_file_atomically(Path::new("/dev/null"), b"gone").unwrap();
        check_writable(Path::new("/dev/null")).unwrap();
        assert!(!std::fs::metadata("/dev/null").unwrap().is_file());
        // A pipe: sent the whole EXR (written with seeks), which reads back as the image.
        let fifo = dir.join("pipe.exr");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(&fifo).unwrap())
        };
        let film = Film { width: 3, height: 2, pixels: (0..6).map(|i| Vec3::splat(i as f32)).collect() };
        film.save_exr(&fifo).unwrap();
        let (got, copy) = (reader.join().unwrap(), dir.join("copy.exr"));
        std::fs::write(&copy, got).unwrap();
        assert_eq!(Film::load_exr(&copy).unwrap().pixels, film.pixels);
        assert!(!std::fs::metadata(&fifo).unwrap().is_file());
        for f in [&fifo, &copy] {
            std::fs::remove_file(f).unwrap();
        }
        let mut left: Vec<String> =
            std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        left.sort();
        assert_eq!(left, ["a.txt", "b.txt", "dangling.txt", "link.txt", "target.txt"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn exr_round_trips_and_leaves_no_temporary_file() {
        let dir = std::env::temp_dir().join(format!("fogplanes-film-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut film = Film::new(5, 3);
        for (i, p) in film.pixels.iter_mut().enumerate() {
            *p = Vec3::new(i as f32, 0.5 * i as f32, 1e-3);
        }
        let path = dir.join("a.exr");
        film.save(&path, 0.0).unwrap();
        assert_eq!(Film::load_exr(&path).unwrap(), film);
        film.save(&dir.join("a.png"), 0.0).unwrap();
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 2, "{names:?}");
        // A PNG where an EXR is read is named as one ("file identifier missing" before).
        let e = Film::load_exr(&dir.join("a.png")).unwrap_err().to_string();
        assert!(e.contains("a.png: a PNG, which holds a tone-mapped picture"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// What an EXR records of how it was made comes back in order, UTF-8 included; an image
    /// without a record has none; the pixels are the same bits either way.
    #[test]
    fn an_exr_records_how_it_was_made() {
        let dir = std::env::temp_dir().join(format!("fogplanes-film-info-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut film = Film::new(3, 2);
        film.pixels[4] = Vec3::new(0.1, 2.0, 1e-30);
        let info = ImageInfo::new("render", "brouillard é", "0123abcd".into(), (3, 2), false)
            .with("planes", 40960)
            .with("zz_extra", "kept");
        let (with, without) = (dir.join("with.exr"), dir.join("without.exr"));
        film.save_with_info(&with, 0.0, Some(&info)).unwrap();
        film.save(&without, 0.0).unwrap();
        let short = Film { pixels: film.pixels[1..].to_vec(), ..film.clone() };
        assert!(
            short.save(&dir.join("short.exr"), 0.0).unwrap_err().to_string().contains("5 pixels for an image of 3x2")
        );
        let (back, read) = Film::load_exr_with_info(&with).unwrap();
        assert_eq!((back, read.as_ref()), (film.clone(), Some(&info)));
        // The same image and record are the same bytes, whatever order the exr crate's hash
        // map gives its attributes (a new one for each file) and its threads finish the blocks
        // (64 x 64 tiles: 60 of them here), and the header is in name order.
        let bytes = std::fs::read(&with).unwrap();
        let mut large = Film::new(640, 360);
        for (k, p) in large.pixels.iter_mut().enumerate() {
            *p = Vec3::new((k % 977) as f32 * 1e-3, (k % 13) as f32, 0.5);
        }
        let first = dir.join("large.exr");
        large.save_with_info(&first, 0.0, Some(&info)).unwrap();
        let large_bytes = std::fs::read(&first).unwrap();
        for k in 0..4 {
            let again = dir.join(format!("again{k}.exr"));
            film.save_with_info(&again, 0.0, Some(&info)).unwrap();
            assert!(std::fs::read(&again).unwrap() == bytes, "write {k} differs from the first");
            large.save_with_info(&again, 0.0, Some(&info)).unwrap();
            assert!(std::fs::read(&again).unwrap() == large_bytes, "the large image's write {k} differs");
        }
        assert_eq!(Film::load_exr(&first).unwrap(), large);
        let names: Vec<String> = exr::meta::MetaData::read_from_file(&with, false).unwrap().headers[0]
            .own_attributes
            .other
            .keys()
            .map(|k| k.to_string())
            .collect();
        assert!(names.len() >= 8, "{names:?}");
        let at =
            |name: &str| bytes.windows(name.len() + 1).position(|w| w == [name.as_bytes(), &[0]].concat()).unwrap();
        let mut order: Vec<&String> = names.iter().collect();
        order.sort_by_key(|n| at(n));
        assert!(order.windows(2).all(|w| w[0] < w[1]), "{order:?}");
        assert_eq!(read_image_info(&with).unwrap(), (Some(info.clone()), (3, 2)));
        assert_eq!(Film::load_exr_with_info(&without).unwrap(), (film, None));
        assert_eq!(info.to_string().lines().next(), Some("image: render"));
        // A reference is checked against the image's record, when both have one.
        let centre = ImageInfo::new("reference", "brouillard é", "0123abcd".into(), (3, 2), true);
        let e = ImageInfo::check_reference(Some(&info), Some(&centre)).unwrap_err();
        assert!(e.is_input() && e.to_string().contains("pixel filter center, the image with box"), "{e}");
        let bigger = ImageInfo::new("reference", "x", "0123abcd".into(), (6, 4), false);
        assert!(ImageInfo::check_reference(Some(&info), Some(&bigger)).unwrap_err().to_string().contains("6x4"));
        let other = ImageInfo::new("reference", "other", "ffff".into(), (3, 2), false);
        let warning = ImageInfo::check_reference(Some(&info), Some(&other)).unwrap().unwrap();
        assert!(warning.contains("different scenes (brouillard é and other)"), "{warning}");
        // Two files of one name that differ in g: the warning says so.
        let forward = ImageInfo::new("reference", "brouillard é", "ffff".into(), (3, 2), false).with_medium_g(0.5);
        let warning = ImageInfo::check_reference(Some(&info), Some(&forward)).unwrap().unwrap();
        assert!(warning.ends_with("(brouillard é and brouillard é, of medium g 0 and 0.5)"), "{warning}");
        assert_eq!(ImageInfo::check_reference(Some(&info), None).unwrap(), None);
        assert_eq!(ImageInfo::check_reference(None, Some(&centre)).unwrap(), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn unknown_extensions_and_missing_directories_are_refused() {
        assert!(check_image_output(Path::new("out.jpg")).is_err());
        assert!(check_writable(Path::new("/no/such/dir/out.exr")).is_err());
    }

    #[test]
    fn srgb_endpoints() {
        assert_eq!(to_srgb8(0.0, 0.0), 0);
        assert_eq!(to_srgb8(1.0, 0.0), 255);
        assert_eq!(to_srgb8(0.25, 2.0), 255);
        assert_eq!(to_srgb8(f32::NAN, 0.0), 0);
    }
}
