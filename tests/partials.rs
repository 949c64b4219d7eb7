//! Renders and references in parts (the cluster's and the job array's work units): chunks
//! merged in any order give the whole render bit for bit, merges refuse parts that do not make
//! one image, reference bands give the whole reference, and the command line round-trips.

use crate::common::options;
use crate::common::{fogplanes, refused};
use fogplanes::control::Control;
use fogplanes::film::Film;
use fogplanes::limits::CHUNK_PLANES;
use fogplanes::options::RenderOptions;
use fogplanes::partial::{Partial, chunks, combine, finish, merge_in_canonical_order};
use fogplanes::reference::{
    ReferenceOptions, reference_counts, reference_pilot_rows, reference_rows, render_reference,
};
use fogplanes::render::render;
use fogplanes::render::render_chunk;
use fogplanes::scene::Scene;
use fogplanes::settings::Overrides;
use std::path::PathBuf;

fn scene(w: u32, h: u32) -> Scene {
    Scene::load(std::path::Path::new("media_scenes/six_lights.toml")).unwrap().with_resolution(w, h).unwrap()
}

fn chunk(s: &Scene, o: &RenderOptions, range: std::ops::Range<usize>) -> Partial {
    render_chunk(s, o, range, Control::none()).unwrap().0
}

/// A fixed permutation of `0..n` for each `k` (no randomness in the test).
fn order(n: usize, k: usize) -> Vec<usize> {
    let mut v: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        v.swap(i, (i * 7 + k * 13 + 3) % (i + 1));
    }
    v
}

/// Six chunks (the last short) rendered one by one, merged in several completion orders, and
/// aligned runs of chunks rendered together: every merge is the render's image, bit for bit;
/// with 16 ray sets (the default, whose plane groups straddle the chunks), with one, and at
/// pixel centres. Each ray set is made once.
#[test]
fn chunks_merged_in_any_order_equal_the_whole_render_bit_for_bit() {
    let s = scene(40, 24);
    for (planes, spp, pixel_center) in
        [(5 * CHUNK_PLANES + 1000, 16, false), (CHUNK_PLANES + 77, 1, false), (CHUNK_PLANES + 77, 16, true)]
    {
        let o = options(
            &s,
            Overrides {
                planes: Some(planes as u64),
                spp: Some(spp),
                seed: Some(5),
                pixel_center,
                ..Overrides::default()
            },
        );
        let (whole, stats) = render(&s, &o, Control::none()).unwrap();
        // Each ray set is made once, though its group of planes may straddle two chunks.
        assert_eq!(stats.rays, 40 * 24 * o.ray_sets() as u64);
        let parts: Vec<Partial> = chunks(planes).into_iter().map(|c| chunk(&s, &o, c)).collect();
        assert_eq!(parts.iter().map(|p| p.hits).sum::<u64>(), stats.hits);
        for k in 0..4 {
            let shuffled: Vec<Partial> = order(parts.len(), k).into_iter().map(|i| parts[i].clone()).collect();
            let merged = merge_in_canonical_order(shuffled).unwrap();
            assert!(finish(&s, &o, &merged).unwrap().pixels == whole.pixels, "{planes} planes, order {k}");
        }
        if parts.len() == 6 {
            // Nodes of the canonical tree rendered whole: chunks 0..4, then 4..6.
            let a = chunk(&s, &o, 0..4 * CHUNK_PLANES);
            let b = chunk(&s, &o, 4 * CHUNK_PLANES..planes);
            let merged = merge_in_canonical_order(vec![b.clone(), a.clone()]).unwrap();
            assert!(finish(&s, &o, &merged).unwrap().pixels == whole.pixels);
            assert!(finish(&s, &o, &combine(a.clone(), &b).unwrap()).unwrap().pixels == whole.pixels);
            // Not a node (chunks 1..3 of the first four): added in another order, within one
            // f32 rounding of the whole (the f64 sums differ by ~1e-16 relative).
            let odd = vec![parts[0].clone(), chunk(&s, &o, CHUNK_PLANES..3 * CHUNK_PLANES), parts[3].clone()];
            let merged = merge_in_canonical_order(odd.into_iter().chain(parts[4..].iter().cloned()).collect()).unwrap();
            let image = finish(&s, &o, &merged).unwrap();
            for (a, b) in image.pixels.iter().zip(&whole.pixels) {
                assert!((*a - *b).abs().max_element() <= b.abs().max_element() * f32::EPSILON, "{a} vs {b}");
            }
        }
    }
}

#[test]
fn merges_refuse_parts_that_do_not_make_one_render() {
    let s = scene(16, 9);
    let planes = 2 * CHUNK_PLANES + 10;
    let o = options(&s, Overrides { planes: Some(planes as u64), seed: Some(2), ..Overrides::default() });
    let c: Vec<Partial> = chunks(planes).into_iter().map(|r| chunk(&s, &o, r)).collect();
    let message = |parts: Vec<Partial>| merge_in_canonical_order(parts).unwrap_err().to_string();
    // Another seed: another render.
    let other = chunk(
        &s,
        &options(&s, Overrides { planes: Some(planes as u64), seed: Some(3), ..Overrides::default() }),
        2 * CHUNK_PLANES..planes,
    );
    let m = message(vec![c[0].clone(), c[1].clone(), other.clone()]);
    assert!(m.contains("different renders"), "{m}");
    assert!(combine(c[1].clone(), &other).unwrap_err().to_string().contains("different renders"));
    // Another resolution: another render too.
    let small = chunk(&scene(8, 9), &o, 2 * CHUNK_PLANES..planes);
    assert!(message(vec![c[0].clone(), c[1].clone(), small]).contains("different renders"));
    // Overlap, gap, missing ends, nothing.
    let both = chunk(&s, &o, 0..2 * CHUNK_PLANES);
    assert!(message(vec![c[0].clone(), both, c[2].clone()]).contains("overlap"));
    let m = message(vec![c[0].clone(), c[2].clone()]);
    assert!(m.contains(&format!("planes {}:{} are missing", CHUNK_PLANES, 2 * CHUNK_PLANES)), "{m}");
    assert!(message(vec![c[1].clone(), c[2].clone()]).contains("planes 0:16384 are missing"));
    assert!(message(vec![c[0].clone(), c[1].clone()]).contains("are missing"));
    assert!(message(vec![]).contains("no partial"));
    assert!(combine(c[0].clone(), &c[2]).unwrap_err().to_string().contains("not adjacent"));
    assert!(combine(c[1].clone(), &c[0]).is_err());
    // Finishing: all planes, of this render.
    assert!(finish(&s, &o, &c[0]).unwrap_err().to_string().contains("do not cover"));
    let all = merge_in_canonical_order(c.clone()).unwrap();
    assert!(
        finish(
            &s,
            &options(&s, Overrides { planes: Some(planes as u64), seed: Some(3), ..Overrides::default() }),
            &all
        )
        .is_err()
    );
    // A range that is not the chunks'.
    for bad in [1..CHUNK_PLANES, 0..planes + 1, 5..5] {
        let e = render_chunk(&s, &o, bad.clone(), Control::none()).unwrap_err();
        assert!(e.is_input() && e.to_string().contains("not a union of the render's chunks"), "{bad:?}: {e}");
    }
}

/// Bands of rows, rendered apart and stacked, are the whole reference: mean and standard
/// error, uniform and adaptive (its pilot in bands, the counts from the stacked pilot).
#[test]
fn reference_bands_equal_the_whole_reference() {
    let s = scene(20, 14);
    let bands = [0..5, 5..6, 6..14];
    for uniform in [true, false] {
        let o = ReferenceOptions { spp: 48, uniform, seed: 4, pixel_center: false };
        let whole = render_reference(&s, &o, Control::none()).unwrap();
        let counts = (!uniform).then(|| {
            let mut pilot = Vec::new();
            for b in bands.clone() {
                pilot.extend(reference_pilot_rows(&s, &o, b, Control::none()).unwrap().pixels);
            }
            reference_counts(&o, &pilot, s.camera.width).unwrap()
        });
        let (mut mean, mut stderr) = (Vec::new(), Vec::new());
        for b in bands.clone() {
            let (m, e) = reference_rows(&s, &o, b.clone(), counts.as_deref(), Control::none()).unwrap();
            assert_eq!((m.width, m.height), (20, b.len() as u32));
            mean.extend(m.pixels);
            stderr.extend(e.pixels);
        }
        assert!(mean == whole.mean.pixels && stderr == whole.stderr.pixels, "uniform {uniform}");
    }
    let o = ReferenceOptions { spp: 8, uniform: true, seed: 1, pixel_center: false };
    #[allow(clippy::reversed_empty_ranges)]
    for bad in [3..3, 0..15, 9..4] {
        assert!(reference_rows(&s, &o, bad.clone(), None, Control::none()).is_err(), "{bad:?}");
    }
}

fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fogplanes-partials-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn run(args: &[&str]) {
    let o = fogplanes(args);
    assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn the_command_line_renders_in_parts_and_merges_them_into_the_render() {
    let dir = scratch("render");
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let common = ["media_scenes/six_lights.toml", "--resolution", "32x18", "--planes", "40000", "-q"];
    let with = |extra: &[&str]| -> Vec<String> {
        ["render"].iter().chain(&common).chain(extra).map(|s| s.to_string()).collect()
    };
    run(&strs(&with(&["-o", &p("whole.exr")])));
    run(&strs(&with(&["--plane-range", "32768:40000", "--partial", &p("b.npz")])));
    run(&strs(&with(&["--plane-range", "0:32768", "--partial", &p("a.npz")])));
    run(&["merge", &p("b.npz"), &p("a.npz"), "-o", &p("merged.exr"), "-q"]);
    let load = |name: &str| Film::load_exr(&dir.join(name)).unwrap();
    assert!(load("merged.exr").pixels == load("whole.exr").pixels);
    // Refused: another seed, an overlap, a gap, a range off the chunks, a file that is no part.
    run(&strs(&with(&["--seed", "9", "--plane-range", "32768:40000", "--partial", &p("other.npz")])));
    assert!(refused(&["merge", &p("a.npz"), &p("other.npz"), "-o", &p("x.exr")]).contains("different images"));
    run(&strs(&with(&["--plane-range", "16384:40000", "--partial", &p("c.npz")])));
    assert!(refused(&["merge", &p("a.npz"), &p("c.npz"), "-o", &p("x.exr")]).contains("overlap"));
    assert!(refused(&["merge", &p("b.npz"), "-o", &p("x.exr")]).contains("planes 0:32768 are missing"));
    assert!(refused(&strs(&with(&["--plane-range", "1:40000", "--partial", &p("y.npz")]))).contains("chunks"));
    assert!(refused(&["merge", &p("whole.exr"), "-o", &p("x.exr")]).contains("not a partial file"));
    assert!(!dir.join("x.exr").exists() && !dir.join("y.npz").exists());
    // In isotropic fog the lobes' share changes no plane: a part at another share is a part of
    // the same image (it was refused as one of another).
    run(&strs(&with(&["--lobes", "0.3", "--plane-range", "32768:40000", "--partial", &p("lobes.npz")])));
    run(&["merge", &p("a.npz"), &p("lobes.npz"), "-o", &p("merged-lobes.exr"), "-q"]);
    assert!(load("merged-lobes.exr").pixels == load("whole.exr").pixels);
}

/// Forward-scattering fog in parts: the merge is the whole render, bit for bit, and a part of
/// the same scene file at another g (docs/mathematics.md section 1.1) is refused as a part of
/// another image, as another seed is.
#[test]
fn parts_of_forward_scattering_fog_merge_and_another_g_is_refused() {
    let dir = scratch("forward");
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let text = std::fs::read_to_string("media_scenes/forward_fog.toml").unwrap();
    std::fs::create_dir_all(dir.join("other")).unwrap();
    std::fs::write(dir.join("other/forward_fog.toml"), text.replace("g = 0.85", "g = 0.5")).unwrap();
    let render = |scene: &str, extra: &[&str]| {
        let common = ["render", scene, "--resolution", "24x15", "--planes", "20000", "-q"];
        run(&[&common[..], extra].concat());
    };
    render("media_scenes/forward_fog.toml", &["-o", &p("whole.exr")]);
    render("media_scenes/forward_fog.toml", &["--plane-range", "0:16384", "--partial", &p("a.npz")]);
    render("media_scenes/forward_fog.toml", &["--plane-range", "16384:20000", "--partial", &p("b.npz")]);
    render(&p("other/forward_fog.toml"), &["--plane-range", "16384:20000", "--partial", &p("other.npz")]);
    run(&["merge", &p("a.npz"), &p("b.npz"), "-o", &p("merged.exr"), "-q"]);
    let load = |name: &str| Film::load_exr(&dir.join(name)).unwrap();
    assert!(load("merged.exr").pixels == load("whole.exr").pixels);
    assert!(refused(&["merge", &p("a.npz"), &p("other.npz"), "-o", &p("x.exr")]).contains("different images"));
    assert!(!dir.join("x.exr").exists());
    // Where the fog scatters forward the lobes' share is the image's: another is refused, and
    // -0 is 0 (it was another share in the part and the fingerprint).
    let share = |lobes: &str, range: &str, name: &str| {
        render("media_scenes/forward_fog.toml", &["--lobes", lobes, "--plane-range", range, "--partial", &p(name)])
    };
    share("0.3", "16384:20000", "share.npz");
    assert!(refused(&["merge", &p("a.npz"), &p("share.npz"), "-o", &p("x.exr")]).contains("different images"));
    share("0", "0:16384", "zero-a.npz");
    share("-0", "16384:20000", "zero-b.npz");
    run(&["merge", &p("zero-a.npz"), &p("zero-b.npz"), "-o", &p("zero.exr"), "-q"]);
    render("media_scenes/forward_fog.toml", &["--lobes", "0", "-o", &p("zero-whole.exr")]);
    assert!(load("zero.exr").pixels == load("zero-whole.exr").pixels);
    assert!(!dir.join("x.exr").exists());
}

#[test]
fn the_command_line_renders_reference_bands_and_merges_them_into_the_reference() {
    let dir = scratch("reference");
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let common = ["reference", "media_scenes/six_lights.toml", "--resolution", "16x10", "--spp", "32", "-q"];
    let cmd = |extra: &[&str]| -> Vec<String> { common.iter().chain(extra).map(|s| s.to_string()).collect() };
    let go = |v: Vec<String>| run(&strs(&v));
    let load = |name: &str| Film::load_exr(&dir.join(name)).unwrap();
    // Uniform: bands straight away.
    go(cmd(&["--uniform", "-o", &p("u.exr"), "--stderr-image", &p("u_err.exr")]));
    go(cmd(&["--uniform", "--rows", "4:10", "--partial", &p("u2.npz")]));
    go(cmd(&["--uniform", "--rows", "0:4", "--partial", &p("u1.npz")]));
    run(&["merge", &p("u2.npz"), &p("u1.npz"), "-o", &p("um.exr"), "--stderr-image", &p("um_err.exr"), "-q"]);
    assert!(load("um.exr").pixels == load("u.exr").pixels && load("um_err.exr").pixels == load("u_err.exr").pixels);
    // Adaptive: pilot bands, merged pilot, bands with it.
    go(cmd(&["-o", &p("a.exr")]));
    let v = cmd(&["--rows", "0:4", "--partial", &p("nopilot.npz")]);
    assert!(refused(&strs(&v)).contains("--pilot"));
    go(cmd(&["--rows", "0:7", "--pilot-pass", "--partial", &p("p1.npz")]));
    go(cmd(&["--rows", "7:10", "--pilot-pass", "--partial", &p("p2.npz")]));
    run(&["merge", &p("p1.npz"), &p("p2.npz"), "-o", &p("pilot.npz"), "-q"]);
    go(cmd(&["--rows", "0:4", "--pilot", &p("pilot.npz"), "--partial", &p("a1.npz")]));
    go(cmd(&["--rows", "4:10", "--pilot", &p("pilot.npz"), "--partial", &p("a2.npz")]));
    run(&["merge", &p("a1.npz"), &p("a2.npz"), "-o", &p("am.exr"), "-q"]);
    assert!(load("am.exr").pixels == load("a.exr").pixels);
    // Bands of different references, and a missing band.
    assert!(refused(&["merge", &p("a1.npz"), &p("u2.npz"), "-o", &p("x.exr")]).contains("different images"));
    assert!(refused(&["merge", &p("a1.npz"), "-o", &p("x.exr")]).contains("rows 4:10 are missing"));
    // A pilot that does not cover the image is not the pilot.
    let v = cmd(&["--rows", "0:4", "--pilot", &p("p1.npz"), "--partial", &p("x.npz")]);
    assert!(refused(&strs(&v)).contains("merge the pilot"));
}
