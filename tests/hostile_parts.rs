//! The doors that partial renders opened (issue 26: "trust nothing that comes from a file, a
//! pickle, a worker or a caller"): options that were silently ignored, part files holding sums
//! no render makes, forged reference bands, pilots that give a pixel no sample, files without
//! end, counts that wrap, and references of another pixel filter. Each kind is refused with
//! exit code 2 and one line naming the file (and the pixel) before any output is written; the
//! same files unforged merge as before. The parts are written here through the library's own
//! format (`fogplanes::partial::file`), changed where a hostile user would change them. The
//! Python doors are held by tests/python/test_hostile.py, the reader and the merge under random
//! damage by tests/fuzz_parts.rs.

use crate::common::fogplanes;
use crate::common::options;
use fogplanes::control::Control;
use fogplanes::film::Film;
use fogplanes::limits::CHUNK_PLANES;
use fogplanes::options::RenderOptions;
use fogplanes::partial::Partial;
use fogplanes::partial::file::{Array, PartKind, PartMeta, ReferenceRecord, write_npz};
use fogplanes::partial::parts::{meta_of, reference_fingerprint, render_record};
use fogplanes::reference::{ReferenceOptions, reference_pilot_rows, reference_rows};
use fogplanes::render::render_chunk;
use fogplanes::scene::Scene;
use fogplanes::settings::Overrides;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const SCENE: &str = "media_scenes/six_lights.toml";
/// Two chunks: 0:16384 and 16384:20000.
const PLANES: usize = 20_000;

/// `fogplanes args` under an address-space limit of about 1 GB, killed (and the test failed)
/// after `seconds`: a read without end fails instead of filling the machine's memory.
fn fogplanes_bounded(seconds: u64, args: &[&str]) -> Output {
    let mut command = Command::new("sh");
    command.args(["-c", "ulimit -v 1000000 && exec \"$@\"", "sh", env!("CARGO_BIN_EXE_fogplanes")]).args(args);
    crate::common::output_within(seconds, command, &format!("{args:?}"))
}

fn scratch(name: &str) -> PathBuf {
    crate::common::scratch_dir(&format!("hostile-parts-{name}"))
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Exit code 2, one line on stderr holding every one of `expected`, nothing on stdout, no
/// panic.
fn assert_refused(o: &Output, what: &str, expected: &[&str]) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{what}: {err}");
    assert_eq!(err.lines().count(), 1, "{what}: one line expected, got:\n{err}");
    assert!(!err.contains("panicked"), "{what}: {err}");
    for e in expected {
        assert!(err.contains(e), "{what}: expected {e:?} in:\n{err}");
    }
    assert!(o.stdout.is_empty(), "{what}: {}", String::from_utf8_lossy(&o.stdout));
}

fn assert_ok(o: &Output, what: &str) {
    assert!(o.status.success(), "{what}: {}", String::from_utf8_lossy(&o.stderr));
}

fn scene() -> Scene {
    Scene::load(Path::new(SCENE)).unwrap().with_resolution(8, 6).unwrap()
}

fn render_options(scene: &Scene) -> RenderOptions {
    options(scene, Overrides { planes: Some(PLANES as u64), ..Overrides::default() })
}

fn meta(kind: PartKind, fingerprint: String, scene: &Scene, range: (usize, usize, usize)) -> PartMeta {
    meta_of(kind, fingerprint, scene, range).unwrap()
}

/// The part file of a render partial, as `render --plane-range --partial` writes it.
fn render_part(scene: &Scene, o: &RenderOptions, p: &Partial) -> (PartMeta, Vec<f64>) {
    let mut m = meta(PartKind::Render, p.fingerprint.clone(), scene, (p.start, p.end, p.planes_total));
    m.hits = p.hits;
    m.render = Some(render_record(o, &fogplanes::options::Devices::one("cpu")));
    (m, p.sums.iter().flat_map(|v| v.to_array()).collect())
}

fn write_render_part(path: &Path, m: &PartMeta, sums: &[f64], shape: Vec<usize>) {
    let meta = Array::text("meta", &serde_json::to_string(m).unwrap());
    write_npz(path, &[meta, Array::f64s("sums", shape, sums.iter().copied())]).unwrap();
}

fn write_band(path: &Path, m: &PartMeta, films: &[(&str, &Film)], width: usize) {
    let mut arrays = vec![Array::text("meta", &serde_json::to_string(m).unwrap())];
    for (name, film) in films {
        let shape = vec![film.pixels.len() / width, width, 3];
        arrays.push(Array::f32s(name, shape, film.pixels.iter().flat_map(|p| p.to_array())));
    }
    write_npz(path, &arrays).unwrap();
}

/// The two chunks of the render, each with its part file's metadata and sums.
fn two_chunks(scene: &Scene, o: &RenderOptions) -> [(PartMeta, Vec<f64>); 2] {
    [0..CHUNK_PLANES, CHUNK_PLANES..PLANES]
        .map(|r| render_part(scene, o, &render_chunk(scene, o, r, Control::none()).unwrap().0))
}

/// Kind 1. Every option is used or refused: clap skips a `requires` when an option that
/// conflicts with the required one is given, so `--plane-range` and `--rows` with `-o` were
/// ignored (the whole image rendered, exit 0), and `--exposure` meant nothing for an EXR.
#[test]
fn every_option_is_used_or_refused() {
    let dir = scratch("unused");
    let out = dir.join("x.exr");
    let small = ["--resolution", "8x6", "--quiet"];
    for (args, names) in [
        (vec!["render", SCENE, "--planes", "20000", "--plane-range", "0:16384", "-o", s(&out)], "--plane-range"),
        (vec!["reference", SCENE, "--spp", "16", "--uniform", "--rows", "0:3", "-o", s(&out)], "--rows"),
        (vec!["reference", SCENE, "--spp", "16", "--pilot-pass", "-o", s(&out)], "--pilot-pass"),
        (vec!["render", SCENE, "--planes", "200", "--exposure", "1", "-o", s(&out)], "--exposure"),
        (vec!["render", SCENE, "--planes", "200", "--exposure", "1", "--partial", "p.npz"], "--exposure"),
        (vec!["reference", SCENE, "--spp", "16", "--exposure", "1", "-o", s(&out)], "--exposure"),
        (vec!["merge", "a.npz", "b.npz", "--exposure", "1", "-o", s(&out)], "--exposure"),
        (vec!["render", SCENE, "--planes", "200", "--device", "cpu", "--rays-on-cpu", "-o", s(&out)], "--rays-on-cpu"),
    ] {
        let args = if args[0] == "merge" { args } else { [&args[..], &small].concat() };
        assert_refused(&fogplanes(&args), &format!("{args:?}"), &[names]);
        assert!(!out.exists(), "{args:?}: an output was written");
    }
    // Options of the table's sweep with the sweep turned off (clap's own refusal).
    for sweep in [["--sweep", "100"], ["--sweep-seeds", "2"]] {
        let args = [&["table", SCENE, "--reference", "r.exr", "--no-sweep", "--out", s(&dir)][..], &sweep].concat();
        let o = fogplanes(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    }
    // Used, they are not refused.
    let png = dir.join("x.png");
    assert_ok(
        &fogplanes(&[&["render", SCENE, "--planes", "200", "--exposure", "1", "-o", s(&png)][..], &small].concat()),
        "png",
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Kind 2. A part's sums are checked when read: a NaN, an infinity, 1e308 (finite, but beyond
/// what one chunk gathered in f32 can sum to, and infinite once divided by N and rounded to
/// f32) or a negative sum merged into an image holding NaN or infinity with exit code 0.
#[test]
fn a_part_holding_sums_no_render_makes_is_refused_naming_the_file_and_the_pixel() {
    let dir = scratch("sums");
    let scene = scene();
    let o = render_options(&scene);
    let [(ma, sa), (mb, sb)] = two_chunks(&scene, &o);
    let (a, b, out) = (dir.join("a.npz"), dir.join("b.npz"), dir.join("x.exr"));
    write_render_part(&b, &mb, &sb, vec![6, 8, 3]);
    write_render_part(&a, &ma, &sa, vec![6, 8, 3]);
    assert_ok(&fogplanes(&["merge", s(&a), s(&b), "-o", s(&out), "-q"]), "the parts as written");
    std::fs::remove_file(&out).unwrap();
    // Pixel (x 2, y 1), channel G.
    let at = (8 + 2) * 3 + 1;
    for value in [f64::NAN, f64::INFINITY, 1e308, -1.0] {
        let mut bad = sa.clone();
        bad[at] = value;
        write_render_part(&a, &ma, &bad, vec![6, 8, 3]);
        let o = fogplanes(&["merge", s(&b), s(&a), "-o", s(&out)]);
        assert_refused(&o, &format!("sums holding {value}"), &["a.npz", "pixel (x 2, y 1) channel G"]);
        assert!(!out.exists());
    }
    // A reference band whose mean holds NaN.
    let ro = ReferenceOptions { spp: 16, uniform: true, seed: 1, pixel_center: false };
    let fingerprint = reference_fingerprint(&scene, &ro, false);
    for (rows, name) in [(0..3u32, "r0.npz"), (3..6, "r1.npz")] {
        let (mut mean, stderr) = reference_rows(&scene, &ro, rows.clone(), None, Control::none()).unwrap();
        if rows.start == 3 {
            mean.pixels[8 + 5].y = f32::NAN;
        }
        let mut m = meta(PartKind::Reference, fingerprint.clone(), &scene, (rows.start as usize, rows.end as usize, 6));
        m.reference = Some(ReferenceRecord { spp: 16, seed: 1, pixel_center: false, uniform: true });
        write_band(&dir.join(name), &m, &[("mean", &mean), ("stderr", &stderr)], 8);
    }
    let o = fogplanes(&["merge", s(&dir.join("r0.npz")), s(&dir.join("r1.npz")), "-o", s(&out)]);
    assert_refused(&o, "a band holding NaN", &["r1.npz", "pixel (x 5, y 1) channel G is NaN"]);
    assert!(!out.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Kind 3. Each band's recorded scene is checked against the first's: a band recording
/// another width indexed past the image (a panic, exit code 101) or, wider, was stacked as it
/// was and shifted every later row.
#[test]
fn a_reference_band_recording_another_width_is_refused() {
    let dir = scratch("bands");
    let scene = scene();
    let ro = ReferenceOptions { spp: 16, uniform: true, seed: 1, pixel_center: false };
    let fingerprint = reference_fingerprint(&scene, &ro, false);
    let band = |rows: std::ops::Range<u32>, width: u32| -> (PartMeta, Film, Film) {
        let at = scene.with_resolution(width, 6).unwrap();
        let (mean, stderr) = reference_rows(&at, &ro, rows.clone(), None, Control::none()).unwrap();
        let mut m = meta(PartKind::Reference, fingerprint.clone(), &at, (rows.start as usize, rows.end as usize, 6));
        m.reference = Some(ReferenceRecord { spp: 16, seed: 1, pixel_center: false, uniform: true });
        (m, mean, stderr)
    };
    let (m0, mean0, err0) = band(0..3, 8);
    write_band(&dir.join("r0.npz"), &m0, &[("mean", &mean0), ("stderr", &err0)], 8);
    let out = dir.join("x.exr");
    for width in [8, 7, 9] {
        let (m1, mean1, err1) = band(3..6, width);
        write_band(&dir.join("r1.npz"), &m1, &[("mean", &mean1), ("stderr", &err1)], width as usize);
        for order in [["r0.npz", "r1.npz"], ["r1.npz", "r0.npz"]] {
            let (first, second) = (dir.join(order[0]), dir.join(order[1]));
            let args = ["merge", s(&first), s(&second), "-o", s(&out), "-q"];
            let o = fogplanes(&args);
            if width == 8 {
                assert_ok(&o, "the bands as written");
                assert_eq!(Film::load_exr(&out).unwrap().pixels.len(), 48);
                std::fs::remove_file(&out).unwrap();
            } else {
                assert_refused(&o, &format!("a band {width} wide"), &["different images"]);
                assert!(!out.exists());
            }
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Kind 4. A pilot is checked when read: a negative (or NaN) standard error gave its pixel a
/// count of 0 and the band a NaN (0/0), written with exit code 0.
#[test]
fn a_pilot_that_would_give_a_pixel_no_sample_is_refused() {
    let dir = scratch("pilot");
    let scene = scene();
    let ro = ReferenceOptions { spp: 64, uniform: false, seed: 1, pixel_center: false };
    let pilot = reference_pilot_rows(&scene, &ro, 0..6, Control::none()).unwrap();
    let mut m = meta(PartKind::Pilot, reference_fingerprint(&scene, &ro, true), &scene, (0, 6, 6));
    m.reference = Some(ReferenceRecord { spp: 64, seed: 1, pixel_center: false, uniform: false });
    let (path, out) = (dir.join("pilot.npz"), dir.join("band.npz"));
    let args = ["reference", SCENE, "--resolution", "8x6", "--spp", "64", "--rows", "0:3", "--pilot", s(&path)];
    let run = || fogplanes(&[&args[..], &["--partial", s(&out), "-q"]].concat());
    write_band(&path, &m, &[("pilot", &pilot)], 8);
    assert_ok(&run(), "the pilot as written");
    std::fs::remove_file(&out).unwrap();
    for value in [-1.0, f32::NAN, f32::INFINITY] {
        let mut bad = pilot.clone();
        bad.pixels[2 * 8 + 1].x = value;
        write_band(&path, &m, &[("pilot", &bad)], 8);
        assert_refused(&run(), &format!("a pilot holding {value}"), &["pilot.npz", "pixel (x 1, y 2) channel R"]);
        assert!(!out.exists());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Kind 6. Every read is bounded by what a valid file of its kind can be: `merge /dev/zero`
/// and `--pilot /dev/zero` read until memory ran out; a file larger than any part, and a part
/// claiming a huge image, are refused before their bytes are read.
#[cfg(unix)]
#[test]
fn part_files_without_end_or_beyond_any_part_are_refused_before_reading() {
    let dir = scratch("endless");
    let out = dir.join("x.exr");
    let o = fogplanes_bounded(20, &["merge", "/dev/zero", "-o", s(&out)]);
    assert_refused(&o, "merge /dev/zero", &["/dev/zero: not a regular file"]);
    let o = fogplanes_bounded(
        20,
        &[
            "reference",
            SCENE,
            "--resolution",
            "8x6",
            "--rows",
            "0:3",
            "--pilot",
            "/dev/zero",
            "--partial",
            s(&dir.join("p.npz")),
        ],
    );
    assert_refused(&o, "--pilot /dev/zero", &["/dev/zero: not a regular file"]);
    // 5 GiB of nothing (a sparse file).
    let huge = dir.join("huge.npz");
    std::fs::File::create(&huge).unwrap().set_len(5 << 30).unwrap();
    assert_refused(&fogplanes_bounded(20, &["merge", s(&huge), "-o", s(&out)]), "a 5 GiB file", &["huge.npz", "4 GiB"]);
    // A part whose metadata claims 32768x32768 pixels (24 GiB of sums) and holds a few bytes.
    let scene = scene();
    let o = render_options(&scene);
    let [(mut m, sums), _] = two_chunks(&scene, &o);
    m.scene.resolution = [32768, 32768];
    let claim = dir.join("claim.npz");
    write_render_part(&claim, &m, &sums, vec![6, 8, 3]);
    assert_refused(&fogplanes_bounded(20, &["merge", s(&claim), "-o", s(&out)]), "a huge claim", &["claim.npz"]);
    assert!(!out.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Kind 7. Counts taken from a file are checked before any arithmetic: a part claiming planes
/// 0:2^64-1 was "no partial renders to merge" (the chunk tree's bound wrapped), and two parts
/// claiming 2^64-1 hits each added to a wrapped count.
#[test]
fn a_part_claiming_counts_beyond_any_render_is_refused() {
    let dir = scratch("wrap");
    let scene = scene();
    let o = render_options(&scene);
    let [(ma, sa), (mb, sb)] = two_chunks(&scene, &o);
    let (a, b, out) = (dir.join("a.npz"), dir.join("b.npz"), dir.join("x.exr"));
    let mut m = ma.clone();
    (m.start, m.end, m.total) = (0, usize::MAX, usize::MAX);
    write_render_part(&a, &m, &sa, vec![6, 8, 3]);
    assert_refused(&fogplanes(&["merge", s(&a), "-o", s(&out)]), "planes 0:2^64-1", &["a.npz", "plane count"]);
    for (path, m, sums) in [(&a, &ma, &sa), (&b, &mb, &sb)] {
        let mut m = m.clone();
        m.hits = u64::MAX;
        write_render_part(path, &m, sums, vec![6, 8, 3]);
    }
    let o = fogplanes(&["merge", s(&a), s(&b), "-o", s(&out)]);
    assert_refused(&o, "2^64-1 hits", &["18446744073709551615 hits, more than one per plane and pixel"]);
    assert!(!out.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Kind 9. Images record how they were made; `compare` and `table` refuse a reference of
/// another pixel filter (a whole-pixel render scored against a pixel-centre reference: MSE
/// 4.1e-2 instead of ~3.6e-6, exit code 0), warn when the scenes differ, and still compare
/// images that record nothing; `info` prints the record.
#[test]
fn a_reference_of_another_pixel_filter_is_refused_and_images_record_how_they_were_made() {
    let dir = scratch("filter");
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let small = ["--resolution", "16x9", "--quiet"];
    let run = |args: &[&str]| assert_ok(&fogplanes(&[args, &small].concat()), &format!("{args:?}"));
    run(&["render", SCENE, "--planes", "500", "-o", &p("whole.exr")]);
    run(&["reference", SCENE, "--spp", "16", "--pixel-center", "-o", &p("pc_ref.exr")]);
    run(&["reference", SCENE, "--spp", "16", "-o", &p("ref.exr")]);
    run(&["render", "media_scenes/two_lights_one_blocker.toml", "--planes", "500", "-o", &p("other.exr")]);
    let o = fogplanes(&["compare", &p("whole.exr"), &p("pc_ref.exr")]);
    assert_refused(&o, "compare whole pc_ref", &["pc_ref.exr", "pixel filter center", "with box"]);
    let report = dir.join("report");
    let table = ["table", SCENE, "--reference", &p("pc_ref.exr"), "--planes", "200", "--no-sweep", "--out", s(&report)];
    assert_refused(&fogplanes(&[&table[..], &small].concat()), "table against pc_ref", &["pixel filter center"]);
    assert!(!report.exists() || std::fs::read_dir(&report).unwrap().next().is_none());
    // The same filter compares; another scene is said, on one line of stderr.
    assert_ok(&fogplanes(&["compare", &p("whole.exr"), &p("ref.exr")]), "compare whole ref");
    let o = fogplanes(&["compare", &p("other.exr"), &p("ref.exr")]);
    assert_ok(&o, "compare other ref");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.starts_with("warning: ") && err.lines().count() == 1 && err.contains("different scenes"), "{err}");
    // An image without a record (as Mitsuba writes them) compares with anything of its size.
    let film = Film::load_exr(Path::new(&p("pc_ref.exr"))).unwrap();
    film.save_exr(Path::new(&p("bare.exr"))).unwrap();
    assert_ok(&fogplanes(&["compare", &p("whole.exr"), &p("bare.exr")]), "compare whole bare");
    let info = |name: &str| String::from_utf8(fogplanes(&["info", &p(name)]).stdout).unwrap();
    let whole = info("whole.exr");
    for line in
        ["image: render", "pixel_filter: box", "resolution: 16x9", "estimator: smis-exact", "planes: 500", "seed: 1"]
    {
        assert!(whole.lines().any(|l| l == line), "{line:?} in:\n{whole}");
    }
    assert!(info("pc_ref.exr").lines().any(|l| l == "pixel_filter: center"));
    assert!(info("bare.exr").contains("16x9, no record"), "{}", info("bare.exr"));
    // An error image where an image goes, or an image where an error image goes, is refused
    // naming the file (an image scored against a standard error gave an MSE and exit code 0).
    run(&["render", SCENE, "--planes", "500", "-o", &p("x.exr"), "--stderr-image", &p("x_se.exr")]);
    run(&["reference", SCENE, "--spp", "16", "-o", &p("r.exr"), "--stderr-image", &p("r_se.exr")]);
    for (args, why) in [
        (
            vec!["compare", &p("x.exr"), &p("r_se.exr")],
            ["r_se.exr", "records a reference standard error, not an image"],
        ),
        (vec!["compare", &p("x_se.exr"), &p("r.exr")], ["x_se.exr", "records a render standard error, not an image"]),
        (vec!["compare", &p("x.exr"), &p("r.exr"), "--ref-stderr", &p("r.exr")], ["r.exr", "not a standard error"]),
        (
            vec!["compare", &p("x.exr"), &p("r.exr"), "--ref-stderr", &p("pc_ref.exr")],
            ["pc_ref.exr", "not a standard error"],
        ),
    ] {
        assert_refused(&fogplanes(&args), &format!("{args:?}"), &why);
    }
    let table = ["table", SCENE, "--reference", &p("r_se.exr"), "--planes", "200", "--no-sweep", "--out", s(&report)];
    assert_refused(&fogplanes(&[&table[..], &small].concat()), "table against r_se", &["r_se.exr", "not an image"]);
    let both = ["compare", &p("x.exr"), &p("r.exr"), "--ref-stderr", &p("r_se.exr"), "--stderr", &p("x_se.exr")];
    assert_ok(&fogplanes(&both), "compare with both standard errors");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Kind 10. A part's kernel is checked when read, as its other settings are: a part recording
/// a kernel no fogplanes has ("bogus", or a name holding an escape sequence) merged with exit
/// code 0, since nothing reads the kernel. Parts recording different kernels are parts of one
/// image (every kernel gives the same bits, and `auto` takes each node's widest): an AVX2
/// node's part and an AVX-512 node's were refused as "parts of different images".
#[test]
fn a_parts_kernel_is_checked_and_parts_of_different_kernels_merge() {
    let dir = scratch("kernel");
    let scene = scene();
    let o = render_options(&scene);
    let [(ma, sa), (mb, sb)] = two_chunks(&scene, &o);
    let (a, b, out, whole) = (dir.join("a.npz"), dir.join("b.npz"), dir.join("x.exr"), dir.join("whole.exr"));
    write_render_part(&a, &ma, &sa, vec![6, 8, 3]);
    write_render_part(&b, &mb, &sb, vec![6, 8, 3]);
    assert_ok(&fogplanes(&["merge", s(&a), s(&b), "-o", s(&whole), "-q"]), "the parts as written");
    let with_kernel = |m: &PartMeta, kernel: &str| {
        let mut m = m.clone();
        m.render.as_mut().unwrap().kernel = kernel.into();
        m
    };
    for kernel in ["bogus", "", "AVX2", "avx2\u{1b}[2J"] {
        write_render_part(&b, &with_kernel(&mb, kernel), &sb, vec![6, 8, 3]);
        for order in [[&a, &b], [&b, &a]] {
            let o = fogplanes(&["merge", s(order[0]), s(order[1]), "-o", s(&out)]);
            assert_refused(&o, &format!("kernel {kernel:?}"), &["b.npz: its kernel: unknown kernel"]);
            assert!(!String::from_utf8_lossy(&o.stderr).contains('\u{1b}'));
            assert!(!out.exists());
        }
    }
    for kernel in ["portable", "per-hit", "avx2", "avx512", "auto"] {
        write_render_part(&b, &with_kernel(&mb, kernel), &sb, vec![6, 8, 3]);
        assert_ok(&fogplanes(&["merge", s(&a), s(&b), "-o", s(&out), "-q"]), &format!("a part of kernel {kernel}"));
        assert_eq!(Film::load_exr(&out).unwrap().pixels, Film::load_exr(&whole).unwrap().pixels, "{kernel}");
        std::fs::remove_file(&out).unwrap();
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
