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

use crate::error::{Error, Result};
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
    pub spp: u32,
    pub pixel_center: bool,
    pub accelerator: String,
    pub kernel: String,
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
            return Err(format!("{}: expected a string, got {} of shape {:?}", self.name, self.descr, self.shape));
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

    fn check(&self, descr: &str, shape: &[usize]) -> std::result::Result<(), String> {
        if self.descr != descr || self.shape != shape {
            return Err(format!(
                "{}: expected {descr} of shape {shape:?}, got {} of shape {:?}",
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
        d if d.starts_with("<U") => 4 * d[2..].parse::<usize>().map_err(|_| bad("a bad dtype"))?,
        d => return Err(bad(&format!("dtype {d} is not supported"))),
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

/// Reads every array of an `.npz` file whose entries are stored (numpy's `savez`, and what
/// [`write_npz`] writes; not `savez_compressed`).
pub fn read_npz(path: &Path) -> Result<Vec<Array>> {
    let bytes = std::fs::read(path).map_err(|e| Error::bad_input(path, format!("cannot read: {e}")))?;
    parse_npz(&bytes).map_err(|m| Error::bad_input(path, m))
}

fn parse_npz(b: &[u8]) -> std::result::Result<Vec<Array>, String> {
    let not_zip = || "not a partial file (.npz): no zip directory".to_string();
    if b.len() < 22 {
        return Err(not_zip());
    }
    // The end of the central directory: its signature, searched back over a comment.
    let eocd = (0..=b.len() - 22)
        .rev()
        .take(22 + 65_535)
        .find(|&i| b[i..i + 4] == 0x0605_4b50u32.to_le_bytes())
        .ok_or_else(not_zip)?;
    let entries = u16_at(b, eocd + 10).ok_or_else(not_zip)?;
    let mut at = u32_at(b, eocd + 16).ok_or_else(not_zip)?;
    let truncated = || "truncated or damaged zip entry".to_string();
    let mut arrays = Vec::with_capacity(entries);
    for _ in 0..entries {
        if u32_at(b, at) != Some(0x0201_4b50) {
            return Err(truncated());
        }
        let method = u16_at(b, at + 10).ok_or_else(truncated)?;
        let crc = u32_at(b, at + 16).ok_or_else(truncated)? as u32;
        let size = u32_at(b, at + 20).ok_or_else(truncated)?;
        let stored = u32_at(b, at + 24).ok_or_else(truncated)?;
        let (name_len, extra_len, comment_len) = (
            u16_at(b, at + 28).ok_or_else(truncated)?,
            u16_at(b, at + 30).ok_or_else(truncated)?,
            u16_at(b, at + 32).ok_or_else(truncated)?,
        );
        let local = u32_at(b, at + 42).ok_or_else(truncated)?;
        let name = b.get(at + 46..at + 46 + name_len).ok_or_else(truncated)?;
        let name = String::from_utf8_lossy(name).into_owned();
        at += 46 + name_len + extra_len + comment_len;
        if method != 0 || size != stored {
            return Err(format!("{name}: compressed entries are not supported (numpy.savez, not savez_compressed)"));
        }
        if u32_at(b, local) != Some(0x0403_4b50) {
            return Err(truncated());
        }
        let start =
            local + 30 + u16_at(b, local + 26).ok_or_else(truncated)? + u16_at(b, local + 28).ok_or_else(truncated)?;
        let data = b.get(start..start.checked_add(size).ok_or_else(truncated)?).ok_or_else(truncated)?;
        if crc32fast::hash(data) != crc {
            return Err(format!("{name}: damaged (its checksum does not match)"));
        }
        let name = name.strip_suffix(".npy").unwrap_or(&name).to_string();
        arrays.push(parse_npy(&name, data)?);
    }
    Ok(arrays)
}

/// The array named `name` of a part.
pub fn entry<'a>(arrays: &'a [Array], name: &str) -> std::result::Result<&'a Array, String> {
    arrays.iter().find(|a| a.name == name).ok_or_else(|| format!("no '{name}' array: not a fogplanes partial file"))
}

/// The metadata of a part read with [`read_npz`].
pub fn meta(arrays: &[Array]) -> std::result::Result<PartMeta, String> {
    let text = entry(arrays, "meta")?.as_text()?;
    let meta: PartMeta =
        serde_json::from_str(&text).map_err(|e| format!("its metadata is not a fogplanes partial's: {e}"))?;
    if meta.format != FORMAT || meta.version != VERSION {
        return Err(format!(
            "format {} version {}: not a partial file this fogplanes reads",
            meta.format, meta.version
        ));
    }
    if meta.start >= meta.end || meta.end > meta.total {
        return Err(format!("its range {}:{} of {} is empty or out of bounds", meta.start, meta.end, meta.total));
    }
    Ok(meta)
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
        let back = read_npz(&path).unwrap();
        assert_eq!(back, arrays);
        assert_eq!(back[0].as_text().unwrap(), "{\"é\": 1}");
        assert_eq!(back[3].as_text().unwrap(), "");
        assert_eq!(back[1].as_f64s(&[2, 3, 3]).unwrap()[17], 8.5);
        assert!(back[1].as_f64s(&[3, 2, 3]).is_err() && back[1].as_f32s(&[2, 3, 3]).is_err());
        // Damaged bytes are found, not read.
        let mut bytes = std::fs::read(&path).unwrap();
        let n = bytes.len();
        bytes[n / 2] ^= 1;
        assert!(parse_npz(&bytes).is_err());
        assert!(parse_npz(&bytes[..n - 30]).is_err() && parse_npz(b"").is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
