//! The integration tests, one binary: each file of `tests/` is a module of this crate (cargo's
//! automatic discovery is off in Cargo.toml), so that `cargo test --release` compiles and links
//! one test program instead of one per file. A new file in `tests/` must be declared below;
//! `every_test_file_is_declared` fails if one is not.

mod common;
mod craft;

mod benchmark_scene;
mod cli;
mod cmis_f32;
mod devices;
mod doors;
mod error_image;
mod fuzz_exr;
mod fuzz_parts;
mod fuzz_scene;
mod gpu;
mod hard_scenes;
mod hostile;
mod hostile_parts;
mod live;
mod mitsuba_export;
mod page;
mod partials;
mod reference;
mod sampling;
mod scene_docs;
mod structures;
mod unbiasedness;
mod whole_pixels;

/// Every `tests/*.rs` file (other than this one) is a module above: a file added to `tests/`
/// and not declared here would never run.
#[test]
fn every_test_file_is_declared() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");
    let this = include_str!("all.rs");
    let mut missing = Vec::new();
    for entry in std::fs::read_dir(&dir).expect("tests/ is readable") {
        let path = entry.expect("a directory entry").path();
        let Some(stem) = path.file_stem().and_then(|s| s.to_str()) else { continue };
        if path.extension().is_some_and(|e| e == "rs") && stem != "all" && !this.contains(&format!("\nmod {stem};\n")) {
            missing.push(stem.to_string());
        }
    }
    assert!(missing.is_empty(), "tests/all.rs does not declare: {missing:?}");
}
