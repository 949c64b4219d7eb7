//! The partial file: what one job of a job array writes and `fogplanes merge` reads.
//!
//! A numpy `.npz` (`numpy.load` opens it, no pickle needed): a zip archive whose entries are
//! stored uncompressed, each a `.npy` array (format version 1.0, little-endian, C order):
//!
//! | entry | dtype, shape | part kinds |
//! |---|---|---|
//! | `meta` | `<U*`, `()`: a JSON string ([`PartMeta`]) | all |
//! | `sums` | `<f8`, `(h, w, 3)`: the unnormalised sums of planes `start:end` | `render` |
//! | `mean`, `stderr` | `<f4`, `(j1 - j0, w, 3)`: rows `start:end` of the reference | `reference` |
//! | `pilot` | `<f4`, `(j1 - j0, w, 3)`: rows of the adaptive reference's pilot (standard errors) | `pilot` |
//!
//! The metadata carries the scene's text and the resolved settings, so that a part is
//! self-contained: `merge` remakes the scene and the settings from it, checks that they give the
//! part's fingerprint, and refuses parts of different renders, overlapping ranges and gaps.
//! Without zip64, an entry is at most 4 GiB (a 16,000 x 11,000 image of sums).
//!
//! A part is read as a file of unknown origin ([`Npz`], [`meta`]): a regular file, its directory
//! from its end, its metadata first and checked, then only the arrays its metadata says it holds,
//! each refused before it is read if its entry is larger than their recorded shape needs.

use crate::error::{Error, Result};
use crate::limits::{MAX_SCENE_FILE_BYTES, check_planes, check_recorded_seconds, check_resolution};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// What a part holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PartKind {
    /// Plane range `start:end` of a render: `sums`.
    Render,
    /// Rows `start:end` of a reference: `mean`, `stderr`.
    Reference,
    /// Rows `start:end` of an adaptive reference's pilot pass: `pilot`.
    Pilot,
}

/// The scene a part belongs to, as text.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneRecord {
    pub name: String,
    pub file: String,
    pub text: String,
    pub resolution: [u32; 2],
}

/// The resolved settings of a render.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderRecord {
    pub planes: usize,
    pub estimator: String,
    pub orientations: u32,
    pub seed: u64,
    pub sampler: String,
    /// The share of each light's planes swept along its lobe (absent in a part written before
    /// the share could be set: the default, [`crate::limits::DEFAULT_LOBES`]).
    #[serde(default = "default_lobes")]
    pub lobes: f64,
    pub spp: u32,
    pub pixel_center: bool,
    pub accelerator: String,
    pub kernel: String,
    /// The devices whose gathering the part holds (`cpu`, or `gpu: ` and the adapter): one, or
    /// several for a node of a checkpoint resumed on another device. Not in the fingerprint:
    /// parts of different devices merge, and the merge records and says so
    /// ([`crate::options::Devices`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub devices: Vec<String>,
    /// What parts written before `devices` recorded: the one device that gathered (absent
    /// before there was a GPU path: the CPU). Read, never written.
    #[serde(default, skip_serializing)]
    pub device: Option<String>,
}

fn default_lobes() -> f64 {
    crate::limits::DEFAULT_LOBES
}

impl RenderRecord {
    /// The devices the part records, checked ([`crate::options::Devices::from_names`]).
    pub fn devices(&self) -> std::result::Result<crate::options::Devices, String> {
        let names = match (&self.devices[..], &self.device) {
            ([], Some(d)) => vec![d.clone()],
            ([], None) => vec!["cpu".to_string()],
            (names, _) => names.to_vec(),
        };
        crate::options::Devices::from_names(names).map_err(|e| format!("its devices: {e}"))
    }
}

/// The resolved settings of a reference.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceRecord {
    pub spp: u32,
    pub seed: u64,
    pub pixel_center: bool,
    pub uniform: bool,
}

/// The metadata of a part (the `meta` entry).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PartMeta {
    /// Always [`FORMAT`].
    pub format: String,
    pub version: u32,
    /// The fogplanes version that wrote it.
    pub fogplanes: String,
    pub kind: PartKind,
    /// Identifies the image the part belongs to (scene and settings).
    pub fingerprint: String,
    pub scene: SceneRecord,
    /// Planes (render) or rows (reference, pilot) `start:end` of `total`.
    pub start: usize,
    pub end: usize,
    pub total: usize,
    pub hits: u64,
    pub seconds: f64,
    pub render: Option<RenderRecord>,
    pub reference: Option<ReferenceRecord>,
}

pub const FORMAT: &str = "fogplanes-partial";
pub const VERSION: u32 = 1;

/// One array of an `.npz`: its name (without `.npy`), numpy dtype string, shape and raw bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct Array {
    pub name: String,
    pub descr: String,
    pub shape: Vec<usize>,
    pub data: Vec<u8>,
}

impl Array {
    pub fn f64s(name: &str, shape: Vec<usize>, values: impl Iterator<Item = f64>) -> Array {
        Array { name: name.into(), descr: "<f8".into(), shape, data: values.flat_map(f64::to_le_bytes).collect() }
    }

    pub fn f32s(name: &str, shape: Vec<usize>, values: impl Iterator<Item = f32>) -> Array {
        Array { name: name.into(), descr: "<f4".into(), shape, data: values.flat_map(f32::to_le_bytes).collect() }
    }

    /// A 0-d unicode array holding `text` (UTF-32, as numpy stores `str`).
    pub fn text(name: &str, text: &str) -> Array {
        let data: Vec<u8> = text.chars().flat_map(|c| (c as u32).to_le_bytes()).collect();
        Array { name: name.into(), descr: format!("<U{}", text.chars().count().max(1)), shape: vec![], data: pad(data) }
    }

    /// The values of an `<f8` array of `shape`.
    pub fn as_f64s(&self, shape: &[usize]) -> std::result::Result<Vec<f64>, String> {
        self.check("<f8", shape)?;
        Ok(self.data.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes"))).collect())
    }

    /// The values of an `<f4` array of `shape`.
    pub fn as_f32s(&self, shape: &[usize]) -> std::result::Result<Vec<f32>, String> {
        self.check("<f4", shape)?;
        Ok(self.data.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes"))).collect())
    }

    /// The string of a 0-d unicode array.
    pub fn as_text(&self) -> std::result::Result<String, String> {
        if !self.descr.starts_with("<U") || !self.shape.is_empty() {
            return Err(format!("{}: expected a string, got {:?} of shape {:?}", self.name, self.descr, self.shape));
        }
        let chars: std::result::Result<String, String> = self
            .data
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
            .take_while(|&c| c != 0)
            .map(|c| char::from_u32(c).ok_or_else(|| format!("{}: not text", self.name)))
            .collect();
        chars
    }

    /// Refuses an array of another dtype or shape, naming both.
    pub fn check(&self, descr: &str, shape: &[usize]) -> std::result::Result<(), String> {
        if self.descr != descr || self.shape != shape {
            return Err(format!(
                "{}: expected {descr} of shape {shape:?}, got {:?} of shape {:?}",
                self.name, self.descr, self.shape
            ));
        }
        Ok(())
    }
}

/// A 0-d unicode array of an empty string still holds one (zero) code point.
fn pad(mut data: Vec<u8>) -> Vec<u8> {
    if data.is_empty() {
        data.extend([0; 4]);
    }
    data
}

/// The bytes of `array` as a `.npy` file (format 1.0; the header padded to 64 bytes).
fn npy_bytes(array: &Array) -> Vec<u8> {
    let shape = match array.shape[..] {
        [] => "()".to_string(),
        [n] => format!("({n},)"),
        _ => format!("({})", array.shape.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", ")),
    };
    let mut header = format!("{{'descr': '{}', 'fortran_order': False, 'shape': {shape}, }}", array.descr);
    // Magic (6) + version (2) + length (2) + header + newline: a multiple of 64.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = Vec::with_capacity(10 + header.len() + array.data.len());
    bytes.extend(b"\x93NUMPY\x01\x00");
    bytes.extend((header.len() as u16).to_le_bytes());
    bytes.extend(header.as_bytes());
    bytes.extend(&array.data);
    bytes
}

/// Reads a `.npy` file's bytes.
fn parse_npy(name: &str, bytes: &[u8]) -> std::result::Result<Array, String> {
    let bad = |m: &str| format!("{name}.npy: {m}");
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(bad("not a numpy array file"));
    }
    let (len, at) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes")) as usize, 12),
        v => return Err(bad(&format!("numpy format version {v} is not supported"))),
    };
    let header =
        bytes.get(at..at + len).and_then(|h| std::str::from_utf8(h).ok()).ok_or_else(|| bad("truncated header"))?;
    let field = |key: &str| -> Option<&str> {
        let rest = &header[header.find(&format!("'{key}':"))? + key.len() + 3..];
        Some(rest.trim_start())
    };
    let descr = field("descr")
        .and_then(|r| r.strip_prefix('\''))
        .and_then(|r| r.split('\'').next())
        .ok_or_else(|| bad("no dtype in the header"))?
        .to_string();
    if !field("fortran_order").is_some_and(|r| r.starts_with("False")) {
        return Err(bad("only C-ordered arrays are supported"));
    }
    let shape_text = field("shape")
        .and_then(|r| r.strip_prefix('('))
        .and_then(|r| r.split(')').next())
        .ok_or_else(|| bad("no shape in the header"))?;
    let shape = shape_text
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>().map_err(|_| bad("a bad shape")))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    let item = match descr.as_str() {
        "<f8" => 8,
        "<f4" => 4,
        d if d.starts_with("<U") => {
            d[2..].parse::<usize>().ok().and_then(|n| n.checked_mul(4)).ok_or_else(|| bad("a bad dtype"))?
        }
        d => return Err(bad(&format!("dtype {d:?} is not supported"))),
    };
    let data = &bytes[at + len..];
    let expected = shape.iter().try_fold(item, |a: usize, &n| a.checked_mul(n));
    if expected != Some(data.len()) {
        return Err(bad("the data does not match the shape"));
    }
    Ok(Array { name: name.to_string(), descr, shape, data: data.to_vec() })
}

/// The largest entry or archive a zip without zip64 holds.
const ZIP_LIMIT: u64 = u32::MAX as u64;

/// Writes `arrays` as an `.npz` file, whole or not at all.
pub fn write_npz(path: &Path, arrays: &[Array]) -> Result<()> {
    let mut zip = Vec::new();
    let mut central = Vec::new();
    let too_large = || Error::write(path, "the partial file would exceed 4 GiB (zip without zip64)");
    for array in arrays {
        let data = npy_bytes(array);
        let name = format!("{}.npy", array.name);
        let (offset, size) = (zip.len() as u64, data.len() as u64);
        if offset > ZIP_LIMIT || size > ZIP_LIMIT {
            return Err(too_large());
        }
        let crc = crc32fast::hash(&data);
        // Version 2.0, no flags, stored, 1980-01-01 00:00.
        let common = |out: &mut Vec<u8>| {
            for v in [20u16, 0, 0, 0, 0x21] {
                out.extend(v.to_le_bytes());
            }
            out.extend(crc.to_le_bytes());
            out.extend((size as u32).to_le_bytes());
            out.extend((size as u32).to_le_bytes());
            out.extend((name.len() as u16).to_le_bytes());
            out.extend(0u16.to_le_bytes()); // extra field length
        };
        zip.extend(0x0403_4b50u32.to_le_bytes());
        common(&mut zip);
        zip.extend(name.as_bytes());
        zip.extend(&data);
        central.extend(0x0201_4b50u32.to_le_bytes());
        central.extend(20u16.to_le_bytes()); // made by
        common(&mut central);
        for v in [0u16, 0, 0] {
            central.extend(v.to_le_bytes()); // comment length, disk, internal attributes
        }
        central.extend(0u32.to_le_bytes()); // external attributes
        central.extend((offset as u32).to_le_bytes());
        central.extend(name.as_bytes());
    }
    let (cd_offset, cd_size) = (zip.len() as u64, central.len() as u64);
    if cd_offset + cd_size > ZIP_LIMIT {
        return Err(too_large());
    }
    zip.extend(central);
    zip.extend(0x0605_4b50u32.to_le_bytes());
    for v in [0u16, 0, arrays.len() as u16, arrays.len() as u16] {
        zip.extend(v.to_le_bytes());
    }
    zip.extend((cd_size as u32).to_le_bytes());
    zip.extend((cd_offset as u32).to_le_bytes());
    zip.extend(0u16.to_le_bytes()); // comment length
    crate::film::write_file_atomically(path, &zip)
}

fn u16_at(b: &[u8], at: usize) -> Option<usize> {
    Some(u16::from_le_bytes(b.get(at..at + 2)?.try_into().ok()?) as usize)
}

fn u32_at(b: &[u8], at: usize) -> Option<usize> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?) as usize)
}

/// The largest central directory read: a part has three entries, numpy's archives a few
/// (each entry's record is 46 bytes and its name).
const MAX_DIRECTORY_BYTES: usize = 1 << 20;

/// The most bytes of a `.npy` header (format 1.0 counts them in 16 bits) and its preamble.
pub const MAX_NPY_HEADER_BYTES: u64 = 12 + u16::MAX as u64;

/// One stored entry of an `.npz`, as its directory describes it.
struct Entry {
    name: String,
    local: u64,
    size: u64,
    crc: u32,
}

/// An `.npz` opened for reading: its directory read from its end, each array read when asked
/// for and no larger than the caller allows, so that what a file claims is never allocated
/// before it is checked. Entries must be stored (numpy's `savez`, and what [`write_npz`]
/// writes; not `savez_compressed`), the archive without zip64.
pub struct Npz<R> {
    source: R,
    len: u64,
    entries: Vec<Entry>,
}

impl Npz<std::fs::File> {
    /// Opens the `.npz` at `path`: a regular file (an archive is read from its end, which a
    /// pipe or a device has not; `/dev/zero` was read until memory ran out) of at most 4 GiB.
    pub fn open(path: &Path) -> Result<Self> {
        let bad = |m: String| Error::bad_input(path, m);
        let info = std::fs::metadata(path).map_err(|e| bad(format!("cannot read: {e}")))?;
        if !info.is_file() {
            return Err(bad("not a regular file: a partial file (.npz) is read from its end".into()));
        }
        if info.len() > ZIP_LIMIT {
            return Err(bad(format!("{} bytes: a partial file (.npz, without zip64) holds at most 4 GiB", info.len())));
        }
        let file = std::fs::File::open(path).map_err(|e| bad(format!("cannot read: {e}")))?;
        Npz::new(file, info.len()).map_err(bad)
    }
}

impl<R: std::io::Read + std::io::Seek> Npz<R> {
    /// Reads the directory of the archive of `len` bytes that `source` holds.
    pub fn new(mut source: R, len: u64) -> std::result::Result<Self, String> {
        let not_zip = || "not a partial file (.npz): no zip directory".to_string();
        let truncated = || "truncated or damaged zip entry".to_string();
        // The end of the central directory: its signature, searched back over a comment.
        let tail_len = len.min(22 + 65_535);
        let tail = read_at(&mut source, len - tail_len, tail_len).map_err(|_| not_zip())?;
        if tail.len() < 22 {
            return Err(not_zip());
        }
        let eocd = (0..=tail.len() - 22)
            .rev()
            .find(|&i| tail[i..i + 4] == 0x0605_4b50u32.to_le_bytes())
            .ok_or_else(not_zip)?;
        let count = u16_at(&tail, eocd + 10).ok_or_else(not_zip)?;
        let (cd_size, cd_offset) =
            (u32_at(&tail, eocd + 12).ok_or_else(not_zip)?, u32_at(&tail, eocd + 16).ok_or_else(not_zip)? as u64);
        if cd_size > MAX_DIRECTORY_BYTES || cd_offset + cd_size as u64 > len {
            return Err(truncated());
        }
        let b = read_at(&mut source, cd_offset, cd_size as u64).map_err(|_| truncated())?;
        let mut entries = Vec::with_capacity(count.min(cd_size / 46));
        let mut at = 0;
        for _ in 0..count {
            if u32_at(&b, at) != Some(0x0201_4b50) {
                return Err(truncated());
            }
            let method = u16_at(&b, at + 10).ok_or_else(truncated)?;
            let crc = u32_at(&b, at + 16).ok_or_else(truncated)? as u32;
            let size = u32_at(&b, at + 20).ok_or_else(truncated)?;
            let stored = u32_at(&b, at + 24).ok_or_else(truncated)?;
            let (name_len, extra_len, comment_len) = (
                u16_at(&b, at + 28).ok_or_else(truncated)?,
                u16_at(&b, at + 30).ok_or_else(truncated)?,
                u16_at(&b, at + 32).ok_or_else(truncated)?,
            );
            let local = u32_at(&b, at + 42).ok_or_else(truncated)? as u64;
            let name = b.get(at + 46..at + 46 + name_len).ok_or_else(truncated)?;
            let name = String::from_utf8_lossy(name).into_owned();
            at += 46 + name_len + extra_len + comment_len;
            if method != 0 || size != stored {
                return Err(format!(
                    "{name}: compressed entries are not supported (numpy.savez, not savez_compressed)"
                ));
            }
            // Two entries of one name are read as different arrays by different readers (the
            // first here, the last by numpy): refused, as no writer of a part makes them.
            if entries.iter().any(|e: &Entry| e.name == name) {
                return Err(format!("{name}: two entries of that name (a crafted or damaged archive)"));
            }
            entries.push(Entry { name, local, size: size as u64, crc });
        }
        Ok(Npz { source, len, entries })
    }

    /// The names of its arrays (without `.npy`).
    pub fn names(&self) -> Vec<String> {
        self.entries.iter().map(|e| e.name.strip_suffix(".npy").unwrap_or(&e.name).to_string()).collect()
    }

    /// The array `name` (without `.npy`), if its entry holds at most `most` bytes: read,
    /// checked against its checksum, parsed.
    pub fn read(&mut self, name: &str, most: u64) -> std::result::Result<Array, String> {
        let truncated = || "truncated or damaged zip entry".to_string();
        let file_name = format!("{name}.npy");
        let e = self
            .entries
            .iter()
            .find(|e| e.name == file_name)
            .ok_or_else(|| format!("no '{name}' array: not a fogplanes partial file"))?;
        if e.size > most {
            return Err(format!("{name}: its entry holds {} bytes, more than the {most} such an array can", e.size));
        }
        let (local, size, crc) = (e.local, e.size, e.crc);
        let header = read_at(&mut self.source, local, 30).map_err(|_| truncated())?;
        if u32_at(&header, 0) != Some(0x0403_4b50) {
            return Err(truncated());
        }
        let skip =
            30 + u16_at(&header, 26).ok_or_else(truncated)? as u64 + u16_at(&header, 28).ok_or_else(truncated)? as u64;
        if local + skip + size > self.len {
            return Err(truncated());
        }
        let data = read_at(&mut self.source, local + skip, size).map_err(|_| truncated())?;
        if crc32fast::hash(&data) != crc {
            return Err(format!("{file_name}: damaged (its checksum does not match)"));
        }
        parse_npy(name, &data)
    }
}

/// `len` bytes of `source` from `offset`, all of them, in a buffer reserved fallibly.
fn read_at<R: std::io::Read + std::io::Seek>(source: &mut R, offset: u64, len: u64) -> std::io::Result<Vec<u8>> {
    use std::io::{Read, SeekFrom};
    let n = usize::try_from(len).map_err(|_| std::io::Error::other("too large"))?;
    let mut data = Vec::new();
    data.try_reserve_exact(n).map_err(|_| std::io::Error::other("cannot allocate"))?;
    source.seek(SeekFrom::Start(offset))?;
    source.take(len).read_to_end(&mut data)?;
    if data.len() != n {
        return Err(std::io::ErrorKind::UnexpectedEof.into());
    }
    Ok(data)
}

/// Every array of an `.npz` held in memory, each at most `most` bytes.
pub fn parse_npz(bytes: &[u8], most: u64) -> std::result::Result<Vec<Array>, String> {
    let mut npz = Npz::new(std::io::Cursor::new(bytes), bytes.len() as u64)?;
    npz.names().iter().map(|name| npz.read(name, most)).collect()
}

/// The most bytes of a part's `meta` entry: its JSON holds the scene's text (at most
/// [`MAX_SCENE_FILE_BYTES`], each byte at most 6 once escaped, `\u00XX`) and a few short
/// fields (under 1 MiB), each character stored in 4 bytes.
pub const MAX_META_BYTES: u64 = MAX_NPY_HEADER_BYTES + 4 * (6 * MAX_SCENE_FILE_BYTES + (1 << 20));

/// The metadata of a part from its `meta` array, checked before any other array is read:
/// this format and version, a range `start:end` within `total`, a resolution within the
/// limits, its kind's settings, and `total` within what its kind can count (a render's planes
/// within the plane limit, a band's rows the image's), so that no count taken from it can
/// wrap ([`super::Partial::check`] checks the rest of a render part).
pub fn meta(array: &Array) -> std::result::Result<PartMeta, String> {
    let text = array.as_text()?;
    let meta: PartMeta =
        serde_json::from_str(&text).map_err(|e| format!("its metadata is not a fogplanes partial's: {e}"))?;
    if meta.format != FORMAT || meta.version != VERSION {
        return Err(format!(
            "format {:?} version {}: not a partial file this fogplanes reads",
            meta.format, meta.version
        ));
    }
    if meta.start >= meta.end || meta.end > meta.total {
        return Err(format!("its range {}:{} of {} is empty or out of bounds", meta.start, meta.end, meta.total));
    }
    let [w, h] = meta.scene.resolution;
    check_resolution(w, h).map_err(|m| format!("its resolution: {m}"))?;
    check_recorded_seconds(meta.seconds).map_err(|m| format!("its seconds of rendering: {m}"))?;
    match meta.kind {
        PartKind::Render => {
            let Some(render) = &meta.render else {
                return Err("a render part without render settings".into());
            };
            // The kernel is needed by no merge (every kernel gives the same bits, and parts of
            // different kernels merge), so nothing else reads it: a name no fogplanes writes
            // was taken without a word.
            render.kernel.parse::<crate::kernel::Kernel>().map_err(|m| format!("its kernel: {m}"))?;
            check_planes(meta.total as u64).map_err(|m| format!("its plane count: {m}"))?;
        }
        PartKind::Reference | PartKind::Pilot => {
            if meta.reference.is_none() {
                return Err("a reference part without reference settings".into());
            }
            if meta.total != h as usize {
                return Err(format!("its rows {}:{} of {}: the image has {h} rows", meta.start, meta.end, meta.total));
            }
        }
    }
    Ok(meta)
}

/// The arrays a part of `meta` holds besides `meta`, each with its dtype and shape.
pub fn expected_arrays(meta: &PartMeta) -> Vec<(&'static str, &'static str, Vec<usize>)> {
    let [w, h] = meta.scene.resolution.map(|n| n as usize);
    let band = vec![meta.end - meta.start, w, 3];
    match meta.kind {
        PartKind::Render => vec![("sums", "<f8", vec![h, w, 3])],
        PartKind::Reference => vec![("mean", "<f4", band.clone()), ("stderr", "<f4", band)],
        PartKind::Pilot => vec![("pilot", "<f4", band)],
    }
}

/// The most bytes of the entry of an array of `descr` and `shape` (its `.npy` header and data).
pub fn entry_bytes(descr: &str, shape: &[usize]) -> u64 {
    let item = if descr == "<f8" { 8u64 } else { 4 };
    shape.iter().fold(item, |a, &n| a.saturating_mul(n as u64)).saturating_add(MAX_NPY_HEADER_BYTES)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arrays_survive_the_round_trip() {
        let dir = std::env::temp_dir().join(format!("fogplanes-npz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.npz");
        let arrays = vec![
            Array::text("meta", "{\"é\": 1}"),
            Array::f64s("sums", vec![2, 3, 3], (0..18).map(|i| i as f64 * 0.5)),
            Array::f32s("mean", vec![1, 1, 3], [1.0f32, 2.0, 3.0].into_iter()),
            Array::text("empty", ""),
        ];
        write_npz(&path, &arrays).unwrap();
        let mut npz = Npz::open(&path).unwrap();
        let back: Vec<Array> = npz.names().iter().map(|n| npz.read(n, 1 << 20).unwrap()).collect();
        assert_eq!(back, arrays);
        assert_eq!(back[0].as_text().unwrap(), "{\"é\": 1}");
        assert_eq!(back[3].as_text().unwrap(), "");
        assert_eq!(back[1].as_f64s(&[2, 3, 3]).unwrap()[17], 8.5);
        assert!(back[1].as_f64s(&[3, 2, 3]).is_err() && back[1].as_f32s(&[2, 3, 3]).is_err());
        // Damaged bytes are found, not read.
        let mut bytes = std::fs::read(&path).unwrap();
        assert_eq!(parse_npz(&bytes, 1 << 20).unwrap(), arrays);
        // An entry larger than the caller allows is refused before it is read.
        assert!(parse_npz(&bytes, 100).unwrap_err().contains("more than the 100"));
        let n = bytes.len();
        bytes[n / 2] ^= 1;
        assert!(parse_npz(&bytes, 1 << 20).is_err());
        assert!(parse_npz(&bytes[..n - 30], 1 << 20).is_err() && parse_npz(b"", 1 << 20).is_err());
        // Two entries of one name (numpy reads the last, this reader the first): refused.
        let twice = dir.join("twice.npz");
        write_npz(&twice, &[Array::text("meta", "{}"), Array::text("meta", "{\"x\": 1}")]).unwrap();
        let e = parse_npz(&std::fs::read(&twice).unwrap(), 1 << 20).unwrap_err();
        assert!(e.contains("meta.npy: two entries of that name"), "{e}");
        // Not a regular file: refused before anything is read.
        #[cfg(unix)]
        assert!(Npz::open(Path::new("/dev/zero")).err().unwrap().to_string().contains("not a regular file"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
