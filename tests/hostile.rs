//! The hostile-input corpus of tests/hostile/: crafted files that once made the command line
//! allocate gigabytes for a 313-byte file, score an image of NaN as perfect, or read without
//! end. Each gives exit code 2 and one error line, no panic and no output. The files are made
//! by the recipes below (tests/craft/ writes EXR byte by byte); `cargo test --release --test
//! all -- --ignored hostile::write_the_corpus` writes them again after a recipe changes.

use crate::common::fogplanes;
use crate::craft;
use crate::craft::{HALF, Header};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const DIR: &str = "tests/hostile";

/// As [`fogplanes`], but a run longer than `seconds` is killed and fails the test (the table
/// once hung after rendering against a NaN reference).
fn fogplanes_within(seconds: u64, args: &[&str]) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_fogplanes"));
    command.args(args);
    crate::common::output_within(seconds, command, &format!("{args:?}"))
}

fn scratch(name: &str) -> PathBuf {
    crate::common::scratch_dir(&format!("hostile-{name}"))
}

fn assert_refused(o: &Output, what: &str, expected: &str) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{what}: {err}");
    assert_eq!(err.lines().count(), 1, "{what}: one line expected, got:\n{err}");
    assert!(!err.contains("panicked"), "{what}: {err}");
    assert!(err.contains(expected), "{what}: expected {expected:?} in:\n{err}");
    assert!(o.stdout.is_empty(), "{what}: {}", String::from_utf8_lossy(&o.stdout));
}

/// 4x3 float RGB, every value finite: the partner of every comparison.
fn good() -> Vec<u8> {
    craft::rgb_file(4, 3, &ramp(12))
}

fn ramp(n: usize) -> Vec<[f32; 3]> {
    (0..n).map(|i| [0.1 * i as f32, 0.05 * i as f32, 1.0]).collect()
}

fn with_value(x: usize, y: usize, channel: usize, value: f32) -> Vec<u8> {
    let mut pixels = ramp(12);
    pixels[y * 4 + x][channel] = value;
    craft::rgb_file(4, 3, &pixels)
}

/// A valid 8x6 file, cut.
fn cut(keep: impl Fn(usize) -> usize) -> Vec<u8> {
    let mut bytes = craft::rgb_file(8, 6, &ramp(48));
    bytes.truncate(keep(bytes.len()));
    bytes
}

/// A 4x3 header changed by `edit`, followed by a zeroed offset table and pixel data (the
/// sizes an uncompressed 4x3 file would have), so that only the header is wrong.
fn edited(edit: impl Fn(&mut Header)) -> Vec<u8> {
    let mut h = Header::rgb(4, 3);
    edit(&mut h);
    let mut bytes = h.bytes();
    bytes.resize(bytes.len() + 3 * 8 + 3 * (8 + 48), 0);
    bytes
}

/// A crafted file, how it is made, and what the error line says about it (which also tells
/// whether it is to be refused as the image or as the reference).
struct Case {
    file: &'static str,
    make: fn() -> Vec<u8>,
    expected: &'static str,
}

const CORPUS: &[Case] = &[
    // 313 bytes claiming 32768x32768 float RGB: 12.9 GB were allocated before the refusal.
    Case {
        file: "huge_header_32768.exr",
        make: || craft::header_only(&Header::rgb(32768, 32768), 0),
        expected: "truncated or crafted",
    },
    // 8192x8192: 772 MB before the refusal.
    Case {
        file: "huge_header_8192.exr",
        make: || craft::header_only(&Header::rgb(8192, 8192), 0),
        expected: "truncated or crafted",
    },
    // The same claim under ZIP, whose chunks may shrink 1032 times.
    Case {
        file: "huge_zip_header.exr",
        make: || craft::header_only(&Header { compression: craft::ZIP, ..Header::rgb(32768, 32768) }, 0),
        expected: "truncated or crafted",
    },
    // One-pixel tiles: an offset table of 2^30 entries.
    Case {
        file: "one_pixel_tiles.exr",
        make: || craft::header_only(&Header { tiles: Some((1, 1, 0)), ..Header::rgb(32768, 32768) }, 0),
        expected: "truncated or crafted",
    },
    // Half of a valid file, then all of it but its last ten bytes.
    Case { file: "truncated_half.exr", make: || cut(|n| n / 2), expected: "truncated_half.exr" },
    Case { file: "truncated_end.exr", make: || cut(|n| n - 10), expected: "truncated_end.exr" },
    Case { file: "empty.exr", make: Vec::new, expected: "empty.exr" },
    Case {
        file: "not_an_exr.exr",
        make: || b"P3\n4 3\n255\nnot an image at all\n".to_vec(),
        expected: "not_an_exr.exr",
    },
    // Luminance only: no R, G, B to read.
    Case {
        file: "luminance_only.exr",
        make: || edited(|h| h.channels = vec![craft::Channel::new("Y", HALF)]),
        expected: "luminance_only.exr",
    },
    Case {
        file: "inverted_window.exr",
        make: || edited(|h| h.data_window = [3, 2, 0, 0]),
        expected: "inverted_window.exr",
    },
    Case {
        file: "window_at_the_integer_limits.exr",
        make: || edited(|h| h.data_window = [i32::MIN, i32::MIN, i32::MAX, i32::MAX]),
        expected: "window_at_the_integer_limits.exr",
    },
    Case {
        file: "zero_sampling.exr",
        make: || edited(|h| h.channels[1].sampling = (0, 0)),
        expected: "zero_sampling.exr",
    },
    Case { file: "htj2k.exr", make: || edited(|h| h.compression = 10), expected: "htj2k.exr" },
    Case {
        file: "unknown_sample_type.exr",
        make: || edited(|h| h.channels[0].sample_type = 7),
        expected: "unknown_sample_type.exr",
    },
    // Readable images that no metric may take: an error metric skipped their NaN (SMAPE 0).
    Case {
        file: "nan_pixel.exr",
        make: || with_value(2, 1, 1, f32::NAN),
        expected: "pixel (x 2, y 1) channel G is NaN",
    },
    Case {
        file: "infinite_pixel.exr",
        make: || with_value(0, 2, 2, f32::INFINITY),
        expected: "pixel (x 0, y 2) channel B is inf",
    },
    Case {
        file: "all_nan.exr",
        make: || craft::rgb_file(4, 3, &[[f32::NAN; 3]; 12]),
        expected: "pixel (x 0, y 0) channel R is NaN",
    },
];

fn corpus_path(file: &str) -> String {
    format!("{DIR}/{file}")
}

/// Writes the corpus from its recipes (run by hand after changing one).
#[test]
#[ignore]
fn write_the_corpus() {
    std::fs::write(corpus_path("good_4x3.exr"), good()).unwrap();
    for case in CORPUS {
        std::fs::write(corpus_path(case.file), (case.make)()).unwrap();
    }
}

#[test]
fn the_corpus_is_what_its_recipes_make() {
    assert_eq!(std::fs::read(corpus_path("good_4x3.exr")).unwrap(), good());
    for case in CORPUS {
        assert_eq!(std::fs::read(corpus_path(case.file)).unwrap(), (case.make)(), "{}", case.file);
    }
    let len = |f: &str| std::fs::metadata(corpus_path(f)).unwrap().len();
    assert_eq!((len("huge_header_32768.exr"), len("huge_header_8192.exr")), (313, 313));
}

/// Every crafted file is refused by `compare`, as the image and as the reference, with one
/// line; the good file compares with itself at zero error.
#[test]
fn compare_refuses_every_crafted_file_with_one_line() {
    let good = corpus_path("good_4x3.exr");
    let o = fogplanes(&["compare", &good, &good, "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!((m["smape"].as_f64(), m["max_abs_error"].as_f64()), (Some(0.0), Some(0.0)));
    for case in CORPUS {
        let bad = corpus_path(case.file);
        assert_refused(&fogplanes(&["compare", &bad, &good]), &format!("compare {bad} good"), case.expected);
        assert_refused(&fogplanes(&["compare", &good, &bad]), &format!("compare good {bad}"), case.expected);
        if case.expected.starts_with("pixel") {
            // Which of the two holds the bad value is said, by its file.
            assert_refused(&fogplanes(&["compare", &bad, &good]), &bad, &format!("{bad}: the image holds"));
            assert_refused(&fogplanes(&["compare", &good, &bad]), &bad, &format!("{bad}: the reference holds"));
        }
    }
}

/// A standard error of another size is named by its file and as what it is: `--ref-stderr` or
/// `--stderr` of another size was "the images differ in size: 4x3 against a 8x6 reference",
/// naming neither the file nor the standard error; a reference of another size is named too.
#[test]
fn compare_names_the_file_of_another_size() {
    let dir = scratch("compare-size");
    let good = corpus_path("good_4x3.exr");
    let other = dir.join("8x6.exr");
    std::fs::write(&other, craft::rgb_file(8, 6, &ramp(48))).unwrap();
    let other = other.to_str().unwrap();
    let o = fogplanes(&["compare", &good, other]);
    assert_refused(&o, "compare good 8x6", &format!("{other}: the images differ in size"));
    let o = fogplanes(&["compare", &good, &good, "--ref-stderr", other]);
    assert_refused(
        &o,
        "--ref-stderr 8x6",
        &format!("{other}: the reference's standard error is 8x6 pixels, the image 4x3"),
    );
    let o = fogplanes(&["compare", &good, &good, "--ref-stderr", &good, "--stderr", other]);
    assert_refused(&o, "--stderr 8x6", &format!("{other}: the image's standard error is 8x6 pixels, the image 4x3"));
    let nan = corpus_path("nan_pixel.exr");
    let o = fogplanes(&["compare", &good, &good, "--ref-stderr", &nan]);
    assert_refused(&o, "--ref-stderr nan", &format!("{nan}: the reference's standard error holds pixel (x 2, y 1)"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A reference holding NaN is refused before anything is rendered or written: every table row
/// scored SMAPE 0 against it.
#[test]
fn table_refuses_a_non_finite_reference_before_any_work() {
    let dir = scratch("table");
    let out = dir.join("out");
    let o = fogplanes_within(
        60,
        &[
            "table",
            "media_scenes/six_lights.toml",
            "--reference",
            &corpus_path("all_nan.exr"),
            "--resolution",
            "4x3",
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert_refused(&o, "table --reference all_nan.exr", "the reference holds a value that is not a finite number");
    assert!(!out.exists() || std::fs::read_dir(&out).unwrap().next().is_none(), "an output was written");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The scene-size limit holds for files whose size says nothing: /dev/zero was read until
/// memory ran out.
#[cfg(unix)]
#[test]
fn endless_scene_files_are_refused_after_the_limit() {
    let o = fogplanes(&["render", "/dev/zero", "--quiet", "-o", "never.exr"]);
    assert_refused(&o, "render /dev/zero", "/dev/zero: the file holds more than 1048576 bytes");
    assert!(!Path::new("never.exr").exists());
}

/// A pipe reports size 0: whatever came through one was read whole. Now the read stops one
/// byte past the limit, and the writer finds the pipe closed long before its 16 MiB are out.
#[cfg(unix)]
#[test]
fn a_pipe_longer_than_the_limit_is_refused() {
    let dir = scratch("pipe");
    let fifo = dir.join("scene.toml");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let writer = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            use std::io::Write;
            let mut f = std::fs::OpenOptions::new().write(true).open(&fifo).unwrap();
            let lines = b"# a comment line that is long enough to fill the pipe quickly\n".repeat(64);
            let mut written = 0;
            while written < 16 << 20 {
                match f.write(&lines) {
                    Ok(n) => written += n,
                    Err(_) => break, // the reader is gone
                }
            }
            written
        })
    };
    let e = fogplanes::scene::Scene::load(&fifo).unwrap_err().to_string();
    let written = writer.join().unwrap();
    assert!(e.contains("holds more than 1048576 bytes"), "{e}");
    // The limit, plus what the pipe and one write hold.
    assert!(written < 2 << 20, "{written} bytes went through the pipe");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A valid 12.7 MB file of 8192x8192 float pixels (RLE) under a 600 MB address-space limit:
/// the 768 MiB pixel buffer is refused with one line where the allocation used to abort the
/// process (SIGABRT). Not in the corpus for its size; written to a scratch directory.
#[cfg(unix)]
#[test]
fn an_image_beyond_a_memory_limit_is_refused_not_aborted() {
    let dir = scratch("memory");
    let path = dir.join("rle_8192.exr");
    std::fs::write(&path, craft::rle_file(8192, 8192)).unwrap();
    let o = Command::new("sh")
        .args(["-c", "ulimit -v 600000 && exec \"$0\" compare \"$1\" \"$1\"", env!("CARGO_BIN_EXE_fogplanes")])
        .arg(&path)
        .output()
        .unwrap();
    assert_refused(
        &o,
        "compare under ulimit -v",
        "8192x8192 pixels need 0.8 GiB, which this machine cannot allocate now",
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Guards the recipes themselves: what tests/craft/ writes as a valid file reads back whole.
#[test]
fn the_crafted_good_file_reads_back() {
    let film = fogplanes::film::Film::load_exr(Path::new(&corpus_path("good_4x3.exr"))).unwrap();
    assert_eq!((film.width, film.height), (4, 3));
    let expected: Vec<_> = ramp(12).into_iter().map(glam::Vec3::from_array).collect();
    assert_eq!(film.pixels, expected);
}
