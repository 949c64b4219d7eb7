//! docs/scenes.md against the loader: the keys it documents are the schema's keys (read from
//! `fogplanes::scene::SceneFile` through serde, not from a list written here), `required` where
//! the schema requires them, the `[render]` defaults and the limits are the code's, and every
//! whole scene in it, every whole scene of the guide (docs/guide.md), and every scene in
//! media_scenes/, loads.
//!
//! The convention the doc follows (and states in its section "Key tables"): a markdown table
//! whose first column is headed `key` lists keys, one per row, as a code span holding the key's
//! path from the top of the file (`camera.position`; `light[].corner` for `corner` in each
//! `[[light]]`); its `default` column says `required` or what an absent key means. A fenced
//! block opened with ```` ```toml scene ```` is a whole scene.

use fogplanes::sampling::Sampler;
use fogplanes::scene::{RenderDefaults, Scene, SceneFile};
use fogplanes::weights::Estimator;
use serde::Deserialize;
use serde::de::{self, DeserializeSeed, IntoDeserializer, MapAccess, SeqAccess, Visitor};
use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;

const DOC: &str = include_str!("../docs/scenes.md");
const GUIDE: &str = include_str!("../docs/guide.md");

// ---------------------------------------------------------------------------------------------
// The schema's keys, through serde

/// What walking the schema can fail with: a field the schema requires was left out (how a
/// required key is told from an optional one), or anything else (a type the walker does not
/// feed, which the test reports).
#[derive(Debug)]
enum WalkError {
    Missing(String),
    Other(String),
}

impl fmt::Display for WalkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WalkError::Missing(field) => write!(f, "missing field `{field}`"),
            WalkError::Other(message) => f.write_str(message),
        }
    }
}

impl std::error::Error for WalkError {}

impl de::Error for WalkError {
    fn custom<T: fmt::Display>(message: T) -> Self {
        WalkError::Other(message.to_string())
    }
    fn missing_field(field: &'static str) -> Self {
        WalkError::Missing(field.to_string())
    }
}

/// A deserializer that makes up a value of whatever type is asked for, and records the path of
/// every struct field it is asked to fill (the `fields` that serde's derive passes to
/// `deserialize_struct`): a struct's fields are each given a made-up value, so the walk
/// reaches the nested structs; an array of tables gets one element, whose fields are recorded
/// under `name[]`. The field at path `omit`, if any, is left out.
struct Walker<'a> {
    path: String,
    omit: Option<&'a str>,
    keys: &'a RefCell<BTreeSet<String>>,
}

impl<'a> Walker<'a> {
    fn at(&self, path: String) -> Walker<'a> {
        Walker { path, omit: self.omit, keys: self.keys }
    }

    fn child(&self, field: &str) -> String {
        if self.path.is_empty() { field.to_string() } else { format!("{}.{field}", self.path) }
    }
}

impl<'de> de::Deserializer<'de> for Walker<'_> {
    type Error = WalkError;

    /// A number: what an RGB value (a number or three) is asked as.
    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_f64(1.0)
    }
    fn deserialize_f64<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_f64(1.0)
    }
    fn deserialize_f32<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_f64(1.0)
    }
    fn deserialize_u64<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_u64(1)
    }
    fn deserialize_u32<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_u64(1)
    }
    fn deserialize_u16<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_u64(1)
    }
    fn deserialize_u8<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_u64(1)
    }
    fn deserialize_i64<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_i64(1)
    }
    fn deserialize_i32<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_i64(1)
    }
    fn deserialize_i16<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_i64(1)
    }
    fn deserialize_i8<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_i64(1)
    }
    fn deserialize_bool<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_bool(true)
    }
    fn deserialize_str<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_str("x")
    }
    fn deserialize_string<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_str("x")
    }
    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        visitor.visit_some(self)
    }
    fn deserialize_seq<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, WalkError> {
        let path = format!("{}[]", self.path);
        visitor.visit_seq(Elements { walker: self.at(path), left: 1 })
    }
    fn deserialize_tuple<V: Visitor<'de>>(self, len: usize, visitor: V) -> Result<V::Value, WalkError> {
        let path = format!("{}[]", self.path);
        visitor.visit_seq(Elements { walker: self.at(path), left: len })
    }
    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, WalkError> {
        let mut given = Vec::new();
        for &field in fields {
            let path = self.child(field);
            self.keys.borrow_mut().insert(path.clone());
            if self.omit != Some(path.as_str()) {
                given.push((field, path));
            }
        }
        visitor.visit_map(Fields { walker: self, fields: given.into_iter(), next: None })
    }

    serde::forward_to_deserialize_any! {
        i128 u128 char bytes byte_buf unit unit_struct newtype_struct tuple_struct map enum
        identifier ignored_any
    }
}

/// The elements of an array: `left` made-up values.
struct Elements<'a> {
    walker: Walker<'a>,
    left: usize,
}

impl<'de> SeqAccess<'de> for Elements<'_> {
    type Error = WalkError;
    fn next_element_seed<T: DeserializeSeed<'de>>(&mut self, seed: T) -> Result<Option<T::Value>, WalkError> {
        if self.left == 0 {
            return Ok(None);
        }
        self.left -= 1;
        seed.deserialize(self.walker.at(self.walker.path.clone())).map(Some)
    }
}

/// The fields of a struct, each with a made-up value.
struct Fields<'a, I> {
    walker: Walker<'a>,
    fields: I,
    next: Option<String>,
}

impl<'de, I: Iterator<Item = (&'static str, String)>> MapAccess<'de> for Fields<'_, I> {
    type Error = WalkError;
    fn next_key_seed<K: DeserializeSeed<'de>>(&mut self, seed: K) -> Result<Option<K::Value>, WalkError> {
        match self.fields.next() {
            None => Ok(None),
            Some((field, path)) => {
                self.next = Some(path);
                seed.deserialize(field.into_deserializer()).map(Some)
            }
        }
    }
    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, WalkError> {
        let path = self.next.take().expect("a key before its value");
        seed.deserialize(self.walker.at(path.clone())).map_err(|e| match e {
            WalkError::Other(m) if !m.starts_with("at ") => WalkError::Other(format!("at {path}: {m}")),
            e => e,
        })
    }
}

/// Walks `SceneFile` with the field at `omit` left out: the keys met, and the outcome.
fn walk(omit: Option<&str>) -> (BTreeSet<String>, Result<SceneFile, WalkError>) {
    let keys = RefCell::new(BTreeSet::new());
    let result = SceneFile::deserialize(Walker { path: String::new(), omit, keys: &keys });
    (keys.into_inner(), result)
}

/// Every key of the schema, and whether it is required (leaving it out is a missing field).
fn schema() -> BTreeMap<String, bool> {
    let (keys, whole) = walk(None);
    if let Err(e) = whole {
        panic!("the schema walker cannot make up a whole SceneFile: {e}");
    }
    assert!(keys.contains("camera.position") && keys.contains("light[].radiance"), "{keys:?}");
    keys.iter()
        .map(|key| {
            let field = key.rsplit('.').next().unwrap();
            let required = match walk(Some(key)).1 {
                Ok(_) => false,
                Err(WalkError::Missing(f)) if f == field => true,
                Err(e) => panic!("leaving out {key}: unexpected {e}"),
            };
            (key.clone(), required)
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// The doc

/// The cells of a markdown table row (`\|` is a `|` inside a cell).
fn cells(line: &str) -> Vec<String> {
    let inner = line.trim().trim_start_matches('|').trim_end_matches('|');
    inner.replace("\\|", "\u{0}").split('|').map(|c| c.trim().replace('\u{0}', "|")).collect()
}

/// The rows of every table whose first column is headed `header`, each as column name to cell.
fn table_rows(doc: &str, header: &str) -> Vec<BTreeMap<String, String>> {
    let lines: Vec<&str> = doc.lines().collect();
    let mut rows = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let head = cells(lines[i]);
        let is_table = lines[i].trim_start().starts_with('|')
            && head.first().is_some_and(|c| c == header)
            && lines
                .get(i + 1)
                .is_some_and(|l| l.trim_start().starts_with("|---") || l.trim_start().starts_with("| ---"));
        if !is_table {
            i += 1;
            continue;
        }
        i += 2;
        while i < lines.len() && lines[i].trim_start().starts_with('|') {
            let row = cells(lines[i]);
            assert_eq!(
                row.len(),
                head.len(),
                "docs/scenes.md line {}: {} cells under {} headers",
                i + 1,
                row.len(),
                head.len()
            );
            rows.push(head.iter().cloned().zip(row).collect());
            i += 1;
        }
    }
    rows
}

/// The text of a cell that is one code span and nothing else.
fn code_span(cell: &str) -> Option<&str> {
    let inner = cell.strip_prefix('`')?.strip_suffix('`')?;
    (!inner.contains('`')).then_some(inner)
}

/// The documented keys, each with its default cell; a key documented twice is an error.
fn documented_keys() -> BTreeMap<String, String> {
    let mut keys = BTreeMap::new();
    for row in table_rows(DOC, "key") {
        let cell = &row["key"];
        let key =
            code_span(cell).unwrap_or_else(|| panic!("docs/scenes.md: a key cell must be one code span: {cell:?}"));
        let default =
            row.get("default").unwrap_or_else(|| panic!("docs/scenes.md: {key}'s table has no default column"));
        assert!(keys.insert(key.to_string(), default.clone()).is_none(), "docs/scenes.md documents {key} twice");
    }
    keys
}

/// The fenced blocks whose info string is `info`.
fn blocks(doc: &str, info: &str) -> Vec<String> {
    let mut out = Vec::new();
    // Inside a block: its text so far if its info string is `info`, else None.
    let mut inside: Option<Option<String>> = None;
    for line in doc.lines() {
        let fence = line.trim_start().starts_with("```");
        match &mut inside {
            None if fence => {
                let wanted = line.trim_start().trim_start_matches('`').trim() == info;
                inside = Some(wanted.then(String::new));
            }
            None => {}
            Some(text) if fence => {
                out.extend(text.take());
                inside = None;
            }
            Some(Some(text)) => {
                text.push_str(line);
                text.push('\n');
            }
            Some(None) => {}
        }
    }
    assert!(inside.is_none(), "a fenced block is not closed");
    out
}

fn load_text(text: &str, what: &str) -> Scene {
    Scene::parse(text, what, "doc").unwrap_or_else(|e| panic!("{what} does not load: {e}\n{text}"))
}

// ---------------------------------------------------------------------------------------------
// The tests

#[test]
fn the_doc_names_every_key_of_the_schema_and_no_other() {
    let schema: BTreeSet<String> = schema().into_keys().collect();
    let documented: BTreeSet<String> = documented_keys().into_keys().collect();
    let missing: Vec<_> = schema.difference(&documented).collect();
    let extra: Vec<_> = documented.difference(&schema).collect();
    assert!(
        missing.is_empty() && extra.is_empty(),
        "docs/scenes.md and the scene schema differ:\n  keys the loader accepts and the doc does not name: {missing:?}\n  \
         keys the doc names and the loader does not accept: {extra:?}"
    );
}

#[test]
fn the_doc_says_required_exactly_for_the_required_keys() {
    let documented = documented_keys();
    let mut wrong = Vec::new();
    for (key, required) in schema() {
        let Some(default) = documented.get(&key) else { continue };
        if (default == "required") != required {
            wrong.push(format!(
                "{key}: the loader {} it, the doc's default is {default:?}",
                if required { "requires" } else { "does not require" }
            ));
        }
    }
    assert!(wrong.is_empty(), "docs/scenes.md:\n  {}", wrong.join("\n  "));
}

/// Writing a `[render]` key's documented default gives the settings that leaving it out does.
#[test]
fn the_documented_render_defaults_are_the_loaders() {
    let base = blocks(DOC, "toml scene").into_iter().next().expect("docs/scenes.md has a `toml scene` block");
    assert!(!base.contains("[render]"), "the doc's first whole scene is the base of this test: no [render] in it");
    let without = load_text(&base, "the doc's first scene").render;
    let same = |a: &RenderDefaults, b: &RenderDefaults| {
        (a.planes, a.weighting, a.seed, a.spp, a.sampler) == (b.planes, b.weighting, b.seed, b.spp, b.sampler)
    };
    let mut checked = 0;
    for (key, default) in documented_keys() {
        let Some(field) = key.strip_prefix("render.") else { continue };
        let value = code_span(&default).unwrap_or_else(|| {
            panic!("docs/scenes.md: {key}'s default must be one code span (a TOML value): {default:?}")
        });
        let with =
            load_text(&format!("{base}\n[render]\n{field} = {value}\n"), &format!("the scene with {key} = {value}"))
                .render;
        assert!(same(&with, &without), "{key} = {value} gives {with:?}, leaving it out {without:?}");
        checked += 1;
    }
    assert!(checked >= 6, "only {checked} render keys checked");
}

#[test]
fn the_doc_names_every_estimator_and_sampler() {
    let names = Estimator::names().into_iter().chain(Sampler::ALL.iter().map(|s| s.name()));
    let missing: Vec<_> = names.filter(|n| !DOC.contains(&format!("`\"{n}\"`"))).collect();
    assert!(missing.is_empty(), "docs/scenes.md does not list these names (as `\"name\"`): {missing:?}");
}

#[test]
fn the_doc_states_the_codes_limits() {
    use fogplanes::limits::*;
    let rows = table_rows(DOC, "limit");
    assert!(rows.len() >= 10, "docs/scenes.md's limits table has {} rows", rows.len());
    for row in rows {
        let name = code_span(&row["limit"]).unwrap_or_else(|| panic!("a limit cell must be one code span: {row:?}"));
        let cell = &row["value"];
        let value: f64 = code_span(cell)
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("{name}: the value must be one code span holding a number: {cell:?}"));
        let actual = match name {
            "MAX_SCENE_FILE_BYTES" => MAX_SCENE_FILE_BYTES as f64,
            "MAX_LIGHTS" => MAX_LIGHTS as f64,
            "MAX_RESOLUTION_SIDE" => MAX_RESOLUTION_SIDE as f64,
            "MAX_PLANES" => MAX_PLANES as f64,
            "MAX_SPP" => MAX_SPP as f64,
            "MAX_ORIENTATIONS" => MAX_ORIENTATIONS as f64,
            "MAX_TOTAL_POWER" => MAX_TOTAL_POWER,
            "MAX_VFOV_DEG" => MAX_VFOV_DEG,
            "MIN_VFOV_DEG" => MIN_VFOV_DEG,
            "MAX_BOX_DIAGONAL" => MAX_BOX_DIAGONAL,
            "MIN_BOX_DIAGONAL" => MIN_BOX_DIAGONAL,
            "MAX_CAMERA_DISTANCE_DIAGONALS" => MAX_CAMERA_DISTANCE_DIAGONALS,
            "MEMORY_BUDGET_BYTES" => MEMORY_BUDGET_BYTES as f64,
            "BYTES_PER_PIXEL" => BYTES_PER_PIXEL as f64,
            "BYTES_PER_PLANE" => BYTES_PER_PLANE as f64,
            "CHUNK_PLANES" => fogplanes::limits::CHUNK_PLANES as f64,
            other => panic!("docs/scenes.md names a limit this test does not know: {other}"),
        };
        assert_eq!(value, actual, "docs/scenes.md: {name} is {actual} in the code");
    }
}

#[test]
fn the_docs_whole_scenes_load() {
    let scenes = blocks(DOC, "toml scene");
    assert!(scenes.len() >= 2, "docs/scenes.md has {} `toml scene` blocks", scenes.len());
    for (i, text) in scenes.iter().enumerate() {
        load_text(text, &format!("docs/scenes.md's `toml scene` block {}", i + 1));
    }
}

/// The guide's own scene (which its test saves and renders) is a whole scene too.
#[test]
fn the_guides_whole_scenes_load() {
    let scenes = blocks(GUIDE, "toml scene");
    assert!(!scenes.is_empty(), "docs/guide.md has no `toml scene` block");
    for (i, text) in scenes.iter().enumerate() {
        load_text(text, &format!("docs/guide.md's `toml scene` block {}", i + 1));
    }
}

#[test]
fn the_example_scenes_load_and_are_named_in_the_doc() {
    let mut found = 0;
    for entry in std::fs::read_dir("media_scenes").unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        Scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let name = path.file_name().unwrap().to_str().unwrap();
        assert!(DOC.contains(&format!("media_scenes/{name}")), "docs/scenes.md does not name media_scenes/{name}");
        found += 1;
    }
    assert!(found >= 2);
}

/// The keys a scene file uses, read line by line: `[table]` and `[[array]]` headers and
/// `key =` lines (enough for the examples, which use no inline tables).
fn keys_used(text: &str) -> BTreeSet<String> {
    let mut keys = BTreeSet::new();
    let mut table = String::new();
    for line in text.lines() {
        let line = line.split('#').next().unwrap().trim();
        if let Some(name) = line.strip_prefix("[[").and_then(|l| l.strip_suffix("]]")) {
            keys.insert(name.trim().to_string());
            table = format!("{}[]", name.trim());
        } else if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            keys.insert(name.trim().to_string());
            table = name.trim().to_string();
        } else if let Some((key, _)) = line.split_once('=') {
            assert!(!table.is_empty(), "a top-level key {line:?}: this reader expects tables");
            keys.insert(format!("{table}.{}", key.trim()));
        }
    }
    keys
}

#[test]
fn the_two_examples_use_every_key_between_them() {
    let mut used = BTreeSet::new();
    for name in ["six_lights.toml", "two_lights_one_blocker.toml"] {
        used.extend(keys_used(&std::fs::read_to_string(format!("media_scenes/{name}")).unwrap()));
    }
    let schema: BTreeSet<String> = schema().into_keys().collect();
    let unused: Vec<_> = schema.difference(&used).collect();
    let unknown: Vec<_> = used.difference(&schema).collect();
    assert!(unknown.is_empty(), "the line reader found keys the schema does not have: {unknown:?}");
    assert!(unused.is_empty(), "no example scene uses {unused:?}");
}
