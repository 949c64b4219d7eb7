//! Fuzzing the part-file reader and the merge (proptest): valid parts of a render (two chunks),
//! of a reference (two bands) and of a pilot, changed as a hostile user or a damaged disk would
//! change them: metadata fields set to hostile values (ranges, counts, resolution, kind,
//! settings, the scene's text), numbers in the arrays set to NaN, infinities, 1e308 and
//! negatives, arrays of another shape or dtype (headers included), arrays dropped, renamed or
//! doubled, and the archive's bytes flipped, overwritten with hostile integers or cut; and
//! `Partial`s of hostile fields given to the canonical merge and the finish directly.
//!
//! Promised and checked on every case: no panic; a refusal is an input error of one line; the
//! largest single allocation stays below 8 MiB + 16 x the bytes of the files read; what is
//! merged is whole (a pixel per pixel of the recorded size) and holds no NaN, infinity or
//! negative value. CI runs 1000 cases of each in about a second;
//! `PROPTEST_CASES=100000 cargo test --release --test all -- fuzz_parts::` fuzzes for longer.

use crate::common::options;
use crate::fuzz_exr::largest_allocation;
use fogplanes::control::Control;
use fogplanes::film::Film;
use fogplanes::limits::CHUNK_PLANES;
use fogplanes::merge::{Merged, merge_parts};
use fogplanes::partial::file::{Array, PartKind, PartMeta, ReferenceRecord, write_npz};
use fogplanes::partial::parts::{meta_of, read_part, reference_fingerprint, render_record};
use fogplanes::partial::{Partial, combine, finish, merge_in_canonical_order};
use fogplanes::reference::{ReferenceOptions, reference_pilot_rows, reference_rows};
use fogplanes::render::render_chunk;
use fogplanes::scene::Scene;
use fogplanes::settings::Overrides;
use proptest::prelude::*;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

const PLANES: usize = CHUNK_PLANES + 3000;
const W: u32 = 6;
const H: u32 = 4;

fn scene() -> Scene {
    Scene::load(Path::new("media_scenes/six_lights.toml")).unwrap().with_resolution(W, H).unwrap()
}

/// A part as its arrays, `meta` first (as JSON, to be changed field by field).
#[derive(Clone, Debug)]
struct PartFile {
    meta: Value,
    arrays: Vec<Array>,
}

fn meta(kind: PartKind, fingerprint: String, scene: &Scene, range: (usize, usize, usize)) -> PartMeta {
    PartMeta { seconds: 0.5, ..meta_of(kind, fingerprint, scene, range).unwrap() }
}

fn f32s(name: &str, film: &Film) -> Array {
    let shape = vec![film.height as usize, film.width as usize, 3];
    Array::f32s(name, shape, film.pixels.iter().flat_map(|p| p.to_array()))
}

/// Valid sets of parts, each one image: the two chunks of a render, the two bands of a uniform
/// reference, the one part of a whole pilot.
fn sets() -> Vec<Vec<PartFile>> {
    let scene = scene();
    let o = options(&scene, Overrides { planes: Some(PLANES as u64), seed: Some(3), ..Overrides::default() });
    let render: Vec<PartFile> = [0..CHUNK_PLANES, CHUNK_PLANES..PLANES]
        .into_iter()
        .map(|r| {
            let p = render_chunk(&scene, &o, r, Control::none()).unwrap().0;
            let mut m = meta(PartKind::Render, p.fingerprint.clone(), &scene, (p.start, p.end, p.planes_total));
            m.hits = p.hits;
            m.render = Some(render_record(&o, &fogplanes::options::Devices::one("cpu")));
            let sums = Array::f64s("sums", vec![H as usize, W as usize, 3], p.sums.iter().flat_map(|s| s.to_array()));
            PartFile { meta: serde_json::to_value(&m).unwrap(), arrays: vec![sums] }
        })
        .collect();
    let ro = ReferenceOptions { spp: 16, uniform: true, seed: 2, pixel_center: false };
    let record = ReferenceRecord { spp: 16, seed: 2, pixel_center: false, uniform: true };
    let reference: Vec<PartFile> = [0..1u32, 1..H]
        .into_iter()
        .map(|rows| {
            let (mean, stderr) = reference_rows(&scene, &ro, rows.clone(), None, Control::none()).unwrap();
            let range = (rows.start as usize, rows.end as usize, H as usize);
            let mut m = meta(PartKind::Reference, reference_fingerprint(&scene, &ro, false), &scene, range);
            m.reference = Some(record.clone());
            PartFile {
                meta: serde_json::to_value(&m).unwrap(),
                arrays: vec![f32s("mean", &mean), f32s("stderr", &stderr)],
            }
        })
        .collect();
    let po = ReferenceOptions { uniform: false, ..ro.clone() };
    let pilot = reference_pilot_rows(&scene, &po, 0..H, Control::none()).unwrap();
    let mut m = meta(PartKind::Pilot, reference_fingerprint(&scene, &po, true), &scene, (0, H as usize, H as usize));
    m.reference = Some(ReferenceRecord { uniform: false, ..record });
    let pilot = vec![PartFile { meta: serde_json::to_value(&m).unwrap(), arrays: vec![f32s("pilot", &pilot)] }];
    vec![render, reference, pilot]
}

/// Metadata fields a change reaches (a dotted path into the JSON).
const FIELDS: &[&str] = &[
    "start",
    "end",
    "total",
    "hits",
    "seconds",
    "kind",
    "fingerprint",
    "version",
    "format",
    "scene.resolution",
    "scene.text",
    "scene.name",
    "render",
    "render.planes",
    "render.spp",
    "render.estimator",
    "render.orientations",
    "render.pixel_center",
    "reference",
    "reference.spp",
    "reference.uniform",
    "reference.pixel_center",
];

fn hostile_value() -> impl Strategy<Value = Value> {
    prop_oneof![
        Just(json!(0)),
        Just(json!(1)),
        Just(json!(-1)),
        Just(json!(3)),
        Just(json!(CHUNK_PLANES)),
        Just(json!(PLANES)),
        Just(json!(2 * CHUNK_PLANES)),
        Just(json!(1u64 << 27)),
        Just(json!(u32::MAX)),
        Just(json!(u64::MAX)),
        Just(json!(u64::MAX / CHUNK_PLANES as u64 + 1)),
        Just(json!(1e308)),
        Just(json!(-0.5)),
        Just(json!("render")),
        Just(json!("pilot")),
        Just(json!("reference")),
        Just(json!("unweighted")),
        Just(json!("[camera]\nresolution = [4, 4]\n")),
        Just(json!(null)),
        Just(json!(true)),
        Just(json!([W + 1, H])),
        Just(json!([W, H + 1])),
        Just(json!([W, 1])),
        Just(json!([0, H])),
        Just(json!([32768, 32768])),
        Just(json!([u32::MAX, 1])),
    ]
}

const NUMBERS: &[f64] = &[f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e308, -1.0, -0.0, 3.4e38, 1e39, 0.0];

const DESCRS: &[&str] = &["<f8", "<f4", ">f8", "<i8", "|u1", "<U4", "<f8', 'fortran_order': True, 'x': '"];

fn hostile_shape() -> impl Strategy<Value = Vec<usize>> {
    prop_oneof![
        Just(vec![]),
        Just(vec![0]),
        Just(vec![W as usize, H as usize, 3]),
        Just(vec![H as usize, W as usize, 4]),
        Just(vec![H as usize + 1, W as usize, 3]),
        Just(vec![1, W as usize, 3]),
        Just(vec![1 << 40, 1, 3]),
        Just(vec![usize::MAX, 2, 3]),
        Just(vec![H as usize * W as usize * 3]),
    ]
}

/// One change to a part.
#[derive(Clone, Debug)]
enum Change {
    /// A metadata field set to a value.
    Field(usize, Value),
    /// A number of array `a` (index `i` modulo its length) set to `NUMBERS[n]`.
    Number {
        a: usize,
        i: usize,
        n: usize,
    },
    /// Array `a` recorded with another shape, its data cut or padded to fit it if small.
    Shape(usize, Vec<usize>, bool),
    /// Array `a` recorded with another dtype (its bytes kept).
    Dtype(usize, usize),
    /// Array `a` dropped, renamed or doubled.
    Drop(usize),
    Rename(usize),
    Double(usize),
    /// The archive's bytes: one flipped, four overwritten with a hostile integer, or cut.
    Flip(usize, u8),
    Int(usize, u32),
    Cut(usize),
}

fn change() -> impl Strategy<Value = Change> {
    let ints = prop_oneof![Just(0u32), Just(u32::MAX), Just(1 << 31), Just(1 << 20), Just(22), Just(46)];
    prop_oneof![
        6 => (0..FIELDS.len(), hostile_value()).prop_map(|(f, v)| Change::Field(f, v)),
        5 => (0..3usize, any::<usize>(), 0..NUMBERS.len()).prop_map(|(a, i, n)| Change::Number { a, i, n }),
        2 => (0..3usize, hostile_shape(), any::<bool>()).prop_map(|(a, s, fit)| Change::Shape(a, s, fit)),
        2 => (0..3usize, 0..DESCRS.len()).prop_map(|(a, d)| Change::Dtype(a, d)),
        1 => (0..3usize).prop_map(Change::Drop),
        1 => (0..3usize).prop_map(Change::Rename),
        1 => (0..3usize).prop_map(Change::Double),
        2 => (any::<usize>(), 0..8u8).prop_map(|(p, b)| Change::Flip(p, b)),
        2 => (any::<usize>(), ints).prop_map(|(p, v)| Change::Int(p, v)),
        1 => any::<usize>().prop_map(Change::Cut),
    ]
}

fn set_field(meta: &mut Value, path: &str, value: Value) {
    let mut at = meta;
    let keys: Vec<&str> = path.split('.').collect();
    for k in &keys[..keys.len() - 1] {
        at = match at.get_mut(*k) {
            Some(v) if v.is_object() => v,
            _ => return,
        };
    }
    if let Some(obj) = at.as_object_mut() {
        obj.insert(keys[keys.len() - 1].to_string(), value);
    }
}

/// The bytes of a part after `changes`.
fn bytes_of(part: &PartFile, changes: &[Change], path: &Path) -> Vec<u8> {
    let mut part = part.clone();
    for c in changes {
        let n = part.arrays.len().max(1);
        match c {
            Change::Field(f, v) => set_field(&mut part.meta, FIELDS[*f], v.clone()),
            Change::Number { a, i, n: k } => {
                if let Some(array) = part.arrays.get_mut(a % n) {
                    let value = NUMBERS[*k];
                    let (item, bytes) = match array.descr.as_str() {
                        "<f8" => (8, value.to_le_bytes().to_vec()),
                        _ => (4, (value as f32).to_le_bytes().to_vec()),
                    };
                    let count = array.data.len() / item;
                    if count > 0 {
                        let at = (i % count) * item;
                        array.data[at..at + item].copy_from_slice(&bytes);
                    }
                }
            }
            Change::Shape(a, shape, fit) => {
                if let Some(array) = part.arrays.get_mut(a % n) {
                    array.shape = shape.clone();
                    let item = if array.descr == "<f8" { 8 } else { 4 };
                    let want = shape.iter().try_fold(item, |x: usize, &y| x.checked_mul(y));
                    if let Some(want) = want.filter(|&w| *fit && w <= 1 << 16) {
                        array.data.resize(want, 0);
                    }
                }
            }
            Change::Dtype(a, d) => {
                if let Some(array) = part.arrays.get_mut(a % n) {
                    array.descr = DESCRS[*d].into();
                }
            }
            Change::Drop(a) => {
                if !part.arrays.is_empty() {
                    part.arrays.remove(a % n);
                }
            }
            Change::Rename(a) => {
                if let Some(array) = part.arrays.get_mut(a % n) {
                    array.name = format!("{}x", array.name);
                }
            }
            Change::Double(a) => {
                if let Some(array) = part.arrays.get(a % n).cloned() {
                    part.arrays.push(array);
                }
            }
            Change::Flip(..) | Change::Int(..) | Change::Cut(_) => {}
        }
    }
    let mut arrays = vec![Array::text("meta", &part.meta.to_string())];
    arrays.extend(part.arrays);
    write_npz(path, &arrays).unwrap();
    let mut bytes = std::fs::read(path).unwrap();
    for c in changes {
        if bytes.is_empty() {
            break;
        }
        match *c {
            Change::Flip(p, b) => {
                let p = p % bytes.len();
                bytes[p] ^= 1 << b;
            }
            Change::Int(p, v) => {
                let p = p % bytes.len();
                let end = (p + 4).min(bytes.len());
                bytes[p..end].copy_from_slice(&v.to_le_bytes()[..end - p]);
            }
            Change::Cut(p) => bytes.truncate(p % bytes.len()),
            _ => {}
        }
    }
    bytes
}

/// A directory of one case, removed when the case ends however it ends.
struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn scratch() -> Scratch {
    static CASES: AtomicUsize = AtomicUsize::new(0);
    let n = CASES.fetch_add(1, Ordering::Relaxed);
    // In memory where the machine has it: every part is written whole (synced to disk) first.
    let shm = Path::new("/dev/shm");
    let base = if shm.is_dir() { shm.to_path_buf() } else { std::env::temp_dir() };
    let dir = base.join(format!("fogplanes-fuzz-parts-{}-{n}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    Scratch(dir)
}

fn check_error(e: &fogplanes::Error) -> Result<(), TestCaseError> {
    prop_assert!(e.is_input(), "{e}");
    prop_assert_eq!(e.to_string().lines().count(), 1, "{}", e);
    Ok(())
}

/// Whole, and every value a number in [0, f32::MAX].
fn check_film(film: &Film, (w, h): (u32, u32)) -> Result<(), TestCaseError> {
    prop_assert_eq!((film.width, film.height), (w, h));
    prop_assert_eq!(film.pixels.len(), w as usize * h as usize);
    prop_assert!(film.all_finite_non_negative(), "{:?}", film.pixels.iter().find(|p| !p.is_finite()));
    Ok(())
}

/// `PROPTEST_CASES` if set (a longer run), else `default` (CI).
fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn partial_field() -> impl Strategy<Value = usize> {
    prop_oneof![
        Just(0usize),
        Just(1),
        Just(CHUNK_PLANES),
        Just(PLANES),
        Just(2 * CHUNK_PLANES),
        Just(1 << 27),
        Just(usize::MAX),
        Just(usize::MAX / CHUNK_PLANES + 1),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(1000), ..ProptestConfig::default() })]

    /// One part of a set changed: read alone and merged with the others.
    #[test]
    fn changed_parts_are_refused_or_merged_whole_and_finite(
        set in 0..3usize,
        which in 0..2usize,
        changes in prop::collection::vec(change(), 1..4),
    ) {
        thread_local!(static SETS: Vec<Vec<PartFile>> = sets());
        let parts = SETS.with(|s| s[set].clone());
        let scratch = scratch();
        let dir = &scratch.0;
        let which = which % parts.len();
        let mut paths = Vec::new();
        let mut bytes = 0;
        for (i, part) in parts.iter().enumerate() {
            let path = dir.join(format!("part{i}.npz"));
            let b = if i == which { bytes_of(part, &changes, &path) } else { bytes_of(part, &[], &path) };
            bytes += b.len();
            std::fs::write(&path, &b).unwrap();
            paths.push(path);
        }
        let ((read, merged), largest) = largest_allocation(|| (read_part(&paths[which]), merge_parts(&paths)));
        prop_assert!(largest <= (8 << 20) + 16 * bytes, "{largest} bytes allocated at once for {bytes} bytes of parts");
        if let Err(e) = &read {
            check_error(e)?;
            prop_assert!(e.to_string().contains(&format!("part{which}.npz")), "{e}");
            prop_assert!(merged.is_err(), "a part that cannot be read was merged");
        }
        match merged {
            Err(e) => check_error(&e)?,
            Ok(Merged::Render { scene, image, partial, .. }) => {
                check_film(&image, (scene.camera.width, scene.camera.height))?;
                prop_assert!(partial.check().is_ok());
            }
            Ok(Merged::Reference { scene, mean, stderr, .. }) => {
                check_film(&mean, (scene.camera.width, scene.camera.height))?;
                check_film(&stderr, (scene.camera.width, scene.camera.height))?;
            }
            Ok(Merged::Pilot { scene, pilot, .. }) => check_film(&pilot, (scene.camera.width, scene.camera.height))?,
        }
    }

    /// Partials of hostile fields (as a pickle or a caller could give them) through the merge,
    /// the addition of two and the finish: refused with one line, or whole and finite.
    #[test]
    fn hostile_partials_are_refused_or_finish_finite(
        fields in prop::collection::vec((partial_field(), partial_field(), any::<u64>(), 0..NUMBERS.len(), any::<usize>()), 1..3),
        (w, h) in prop_oneof![3 => Just((W, H)), 1 => Just((W + 1, H)), 1 => Just((0, H)), 1 => Just((40_000, 1))],
    ) {
        thread_local!(static VALID: (Scene, fogplanes::options::RenderOptions, Vec<Partial>) = {
            let scene = scene();
            let o = options(&scene, Overrides { planes: Some(PLANES as u64), seed: Some(3), ..Overrides::default() });
            let parts = [0..CHUNK_PLANES, CHUNK_PLANES..PLANES].map(|r| render_chunk(&scene, &o, r, Control::none()).unwrap().0);
            (scene, o, parts.to_vec())
        });
        let (scene, o, valid) = VALID.with(|v| v.clone());
        let parts: Vec<Partial> = fields
            .iter()
            .enumerate()
            .map(|(k, &(start, end, hits, n, at))| {
                let mut p = valid[k % 2].clone();
                if k == 0 {
                    (p.start, p.end, p.planes_total, p.hits) = (start, end.max(p.end), end.max(PLANES), hits);
                }
                if (p.width, p.height) != (w, h) && w < 1000 {
                    (p.width, p.height) = (w, h);
                    p.sums.resize(w as usize * h as usize, glam::DVec3::ZERO);
                } else if w >= 1000 {
                    p.width = w;
                }
                if !p.sums.is_empty() {
                    let i = at % p.sums.len();
                    p.sums[i].y = NUMBERS[n];
                }
                p
            })
            .collect();
        match merge_in_canonical_order(parts.clone()) {
            Ok(all) => {
                prop_assert!(all.check().is_ok());
                match finish(&scene, &o, &all) {
                    Ok(film) => check_film(&film, (W, H))?,
                    Err(e) => check_error(&e)?,
                }
            }
            Err(e) => check_error(&e)?,
        }
        if let [a, b] = &parts[..] {
            match combine(a.clone(), b) {
                Ok(p) => prop_assert!(p.check().is_ok()),
                Err(e) => check_error(&e)?,
            }
        }
    }
}

/// The harness's own material merges: what it changes starts valid.
#[test]
fn the_unchanged_parts_merge() {
    for parts in sets() {
        let scratch = scratch();
        let dir = &scratch.0;
        let paths: Vec<PathBuf> = parts
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let path = dir.join(format!("part{i}.npz"));
                bytes_of(p, &[], &path);
                path
            })
            .collect();
        assert!(merge_parts(&paths).is_ok(), "{:?}", merge_parts(&paths).err().map(|e| e.to_string()));
    }
}
