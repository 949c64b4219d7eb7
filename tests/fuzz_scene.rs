//! Property tests of the scene loader and the renderer on hostile input (proptest, bounded so
//! that CI runs them in seconds; `PROPTEST_CASES=100000 cargo test --release --test all --
//! fuzz_scene::` fuzzes for longer): no input panics, and every scene that loads renders only
//! finite, non-negative pixels.

use crate::common::options;
use fogplanes::control::Control;
use fogplanes::limits::MAX_SCENE_FILE_BYTES;
use fogplanes::render::render;
use fogplanes::scene::Scene;
use fogplanes::settings::Overrides;
use fogplanes::weights::Estimator;
use proptest::prelude::*;

const BASE: &str = include_str!("../media_scenes/six_lights.toml");

/// Tokens that break things when they replace a value.
const NASTY: &[&str] = &[
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "0.0",
    "-0.0",
    "1e308",
    "-1e308",
    "1e-320",
    "\"x\"",
    "[]",
    "[1]",
    "[1, 2, 3, 4]",
    "[nan, 0, 0]",
    "{}",
    "true",
    "18446744073709551615",
    "-9223372036854775808",
    "[[1]]",
    "\"\"",
    "[0, 0, 0]",
];

/// `PROPTEST_CASES` if set (a longer run), else `default` (CI). An explicit `cases` in the
/// config would override the variable.
fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn mutate(text: &str, edits: &[(usize, u8, usize)]) -> String {
    String::from_utf8_lossy(&mutate_bytes(text, edits)).into_owned()
}

fn mutate_bytes(text: &str, edits: &[(usize, u8, usize)]) -> Vec<u8> {
    let mut s: Vec<u8> = text.as_bytes().to_vec();
    for &(pos, kind, arg) in edits {
        if s.is_empty() {
            break;
        }
        let pos = pos % s.len();
        match kind % 4 {
            0 => {
                let end = (pos + arg % 40).min(s.len());
                s.drain(pos..end);
            }
            1 => s.insert(pos, b"=[]{}\"#,.\n-0123456789aez"[arg % 24]),
            2 => {
                // Replace the number (or word) at pos with a nasty token.
                let start = (0..pos).rev().find(|&i| b" =[,\n".contains(&s[i])).map_or(0, |i| i + 1);
                let end = (pos..s.len()).find(|&i| b" ],\n".contains(&s[i])).unwrap_or(s.len());
                if start <= end {
                    s.splice(start..end, NASTY[arg % NASTY.len()].bytes());
                }
            }
            _ => s[pos] = (arg % 256) as u8,
        }
    }
    s
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(512), ..ProptestConfig::default() })]

    #[test]
    fn mutated_scene_files_never_panic(edits in prop::collection::vec((any::<usize>(), any::<u8>(), any::<usize>()), 1..6)) {
        let text = mutate(BASE, &edits);
        match Scene::parse(&text, "fuzz.toml", "fuzz") {
            Ok(scene) => prop_assert!(!scene.lights.is_empty()),
            Err(e) => prop_assert!(e.to_string().starts_with("fuzz.toml")),
        }
    }

    /// The same mutations as bytes (not UTF-8 perhaps) in a file read by `Scene::load`, padded
    /// with a comment to a length either side of the size limit: loads, or fails with one line
    /// naming the file; never a panic, never more than the limit read.
    #[test]
    fn mutated_scene_files_load_or_fail_naming_the_file(
        edits in prop::collection::vec((any::<usize>(), any::<u8>(), any::<usize>()), 1..6),
        pad_to in prop_oneof![4 => Just(None), 1 => (MAX_SCENE_FILE_BYTES - 2..=MAX_SCENE_FILE_BYTES + 2).prop_map(Some)],
    ) {
        let mut bytes = mutate_bytes(BASE, &edits);
        if let Some(n) = pad_to {
            bytes.extend(b"\n#");
            bytes.resize((n as usize).max(bytes.len()), b'x');
        }
        let path = std::env::temp_dir().join(format!("fogplanes-fuzz-scene-{}.toml", std::process::id()));
        std::fs::write(&path, &bytes).unwrap();
        let loaded = Scene::load(&path);
        let _ = std::fs::remove_file(&path);
        match loaded {
            Ok(scene) => prop_assert!(bytes.len() as u64 <= MAX_SCENE_FILE_BYTES && !scene.lights.is_empty()),
            Err(e) => {
                let e = e.to_string();
                prop_assert!(e.starts_with(path.to_str().unwrap()) && e.lines().count() == 1, "{}", e);
                if bytes.len() as u64 > MAX_SCENE_FILE_BYTES {
                    prop_assert!(e.contains("scene files are limited to"), "{}", e);
                }
            }
        }
    }
}

fn coordinate() -> impl Strategy<Value = f64> {
    prop_oneof![-6.0..6.0f64, Just(0.0), Just(5.0), Just(-5.0), Just(1e-9)]
}

fn scene_text(cam: [f64; 6], lights: &[([f64; 9], f64)], sigma: (f64, f64)) -> String {
    let mut s = format!(
        "[camera]\nposition = [{}, {}, {}]\nlook_at = [{}, {}, {}]\nup = [0.0, 1.0, 0.0]\nvfov_deg = 60.0\nresolution = [8, 6]\n\
         [medium]\nmin = [-5.0, 0.0, -5.0]\nmax = [5.0, 6.0, 5.0]\nsigma_s = {}\nsigma_a = {}\n",
        cam[0], cam[1], cam[2], cam[3], cam[4], cam[5], sigma.0, sigma.1
    );
    for (g, le) in lights {
        // Edges from two angles and two lengths, orthogonal by construction: u from the angles,
        // v = u x side with side horizontal and orthogonal to u.
        let (theta, phi, w, h) = (g[3], g[4], g[5], g[6]);
        let u = [theta.cos() * phi.cos(), theta.sin(), theta.cos() * phi.sin()];
        let side = [-phi.sin(), 0.0, phi.cos()];
        let c = [u[1] * side[2] - u[2] * side[1], u[2] * side[0] - u[0] * side[2], u[0] * side[1] - u[1] * side[0]];
        s += &format!(
            "[[light]]\ncorner = [{}, {}, {}]\nedge_u = [{}, {}, {}]\nedge_v = [{}, {}, {}]\nradiance = {}\n",
            g[0],
            g[1],
            g[2],
            u[0] * w,
            u[1] * w,
            u[2] * w,
            c[0] * h,
            c[1] * h,
            c[2] * h,
            le
        );
    }
    s
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(96), ..ProptestConfig::default() })]

    /// Random valid-looking scenes (lights anywhere, any orientation and size, tiny to large
    /// coefficients, cameras inside and outside the box): loads or fails cleanly, and renders
    /// finite, non-negative pixels with every estimator.
    #[test]
    fn random_scenes_render_finite_pixels(
        cam in prop::array::uniform6(coordinate()),
        lights in prop::collection::vec((prop::array::uniform9(-4.0..4.0f64), 0.0..100.0f64), 1..4),
        sigma in (prop_oneof![Just(1e-6), 0.0..2.0f64, Just(30.0)], prop_oneof![Just(0.0), 0.0..1.0f64]),
        estimator in 0..Estimator::ALL.len(),
        seed in any::<u64>(),
    ) {
        let lights: Vec<([f64; 9], f64)> = lights.into_iter().map(|(mut g, le)| {
            g[1] = (g[1] + 4.0) * 0.75; // y in [0, 6]
            g[5] = g[5].abs() * 0.25 + 1e-4;
            g[6] = g[6].abs() * 0.25 + 1e-4;
            (g, le)
        }).collect();
        let text = scene_text(cam, &lights, sigma);
        let loaded = Scene::parse(&text, "random.toml", "random");
        if let Err(e) = &loaded {
            prop_assert!(e.to_string().starts_with("random.toml"));
        }
        if let Ok(scene) = loaded {
            let given = Overrides {
                planes: Some(300),
                estimator: Some(Estimator::ALL[estimator]),
                seed: Some(seed),
                ..Overrides::default()
            };
            let opts = options(&scene, given);
            let (film, _) = render(&scene, &opts, Control::none()).unwrap();
            prop_assert!(film.all_finite_non_negative(), "{}", text);
        }
    }
}
