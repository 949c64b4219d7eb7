//! The intersection structures and the gathering kernels find exactly the same hits with the
//! same weights: every kernel this CPU has, the per-hit path and the brute-force loop give
//! bit-identical images for every estimator and K; the BVH the same hits; images do not depend
//! on the thread count.

use crate::common::options;
use fogplanes::accel::{Accelerator, PreparedPlanes};
use fogplanes::control::Control;
use fogplanes::kernel::Kernel;
use fogplanes::options::RenderOptions;
use fogplanes::photon_plane::PlaneSet;
use fogplanes::pixel::ray_set_rays;
use fogplanes::render::{render, render_in_passes};
use fogplanes::sampling::Sampler;
use fogplanes::scene::Scene;
use fogplanes::settings::Overrides;
use fogplanes::weights::{Estimator, Weighting};

fn scene(file: &str, w: u32, h: u32) -> Scene {
    Scene::load(std::path::Path::new(file)).unwrap().with_resolution(w, h).unwrap()
}

fn with(s: &Scene, weighting: Weighting, accelerator: Accelerator, kernel: Kernel, planes: usize) -> RenderOptions {
    let given = Overrides {
        planes: Some(planes as u64),
        estimator: Some(weighting.estimator),
        orientations: Some(weighting.orientations),
        seed: Some(5),
        accelerator: Some(accelerator),
        kernel: Some(kernel),
        ..Overrides::default()
    };
    options(s, given)
}

/// Every estimator and K through every kernel path: the six-light scene (grey, with planes that
/// other panels shadow) and a scene with an RGB medium (three exponentials per hit).
#[test]
fn every_kernel_gives_bit_identical_images() {
    let kernels = Kernel::available();
    eprintln!("kernels this CPU runs: {kernels:?}");
    assert!(kernels.len() >= 2);
    for file in ["media_scenes/six_lights.toml", "media_scenes/hard/camera_inside_box.toml"] {
        let s = scene(file, 64, 36);
        for w in Weighting::all(&[1, 3, 4, 8]) {
            let (reference, rs) =
                render(&s, &with(&s, w, Accelerator::BruteForce, Kernel::Auto, 1500), Control::none()).unwrap();
            assert!(rs.hits > 10_000, "{file} {w}: {} hits", rs.hits);
            for &k in &kernels {
                let (image, st) = render(&s, &with(&s, w, Accelerator::Raster, k, 1500), Control::none()).unwrap();
                assert_eq!(st.hits, rs.hits, "{file} {w} {k}: hit counts differ");
                assert!(image.pixels == reference.pixels, "{file} {w} {k}: the image differs from brute force");
            }
        }
    }
}

/// Planes prepared in several pieces (`PreparedPlanes` samples 16,384 at a time; a render's
/// chunks never hold more), so that the raster's bands and the brute-force loop's order are each
/// merged from several, light by light: the same bits, in a grey medium and an RGB one.
#[test]
fn planes_prepared_in_pieces_give_the_brute_force_image() {
    for file in ["media_scenes/six_lights.toml", "media_scenes/hard/camera_inside_box.toml"] {
        let s = scene(file, 20, 12);
        let set = PlaneSet { sampler: Sampler::default(), seed: 3 };
        let rays = ray_set_rays(&s, 3, 0, false);
        let gather = |accelerator| {
            let planes = PreparedPlanes::new(&s, set, 0..40_000, accelerator, Control::none()).unwrap();
            let mut sums = vec![glam::Vec3::ZERO; rays.len()];
            let kernel = Kernel::Auto.resolve().unwrap();
            let stats = planes.gather(Weighting::default(), kernel, &rays, &mut sums, Control::none()).unwrap();
            (sums, stats.hits)
        };
        let ((fast, fast_hits), (slow, slow_hits)) = (gather(Accelerator::Raster), gather(Accelerator::BruteForce));
        assert!(slow_hits > 10_000, "{file}: {slow_hits} hits");
        assert_eq!(fast_hits, slow_hits, "{file}: hit counts differ");
        assert!(fast == slow, "{file}: the raster's sums differ from brute force");
    }
}

/// FNV-1a over the bits of every pixel's three channels.
fn image_hash(pixels: &[glam::Vec3]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for c in pixels.iter().flat_map(|v| v.to_array()) {
        h = (h ^ c.to_bits() as u64).wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// The images of every estimator and K are those recorded, bit for bit: the hashes below are of
/// the EXR files of `fogplanes render SCENE --resolution 64x36 --planes 1500 --seed 5 -e E
/// [--orientations K]`. A change of arithmetic that is meant changes them, and says so; the last
/// was cmis-exact's sum of its sectors' |dF| with a correction per zero of det, on the edge its
/// direction leaves through (docs/mathematics.md section 3; 1e-16 relative on the benchmark
/// image), and before it its logarithm of the arcs up to the zeros of det taken from 1 + x (docs/mathematics.md
/// section 3: its largest error on long thin lights from 3.8e-5 to 2.8e-7), with its sector
/// turns from its corners' angles before it (9e-17 relative on the benchmark image); before, issue
/// 27's sums light by light (a light's hits summed without its power, multiplied once:
/// [`fogplanes::gather`]) moved every estimator's by 6e-16 (f32 rounding), and its fused
/// multiply-adds moved them by 2e-10 to 3e-9 (cmis-exact to unweighted; a millionth of their
/// noise), hits on a segment's or chord's very end being counted or not. Every kernel still
/// gives these bits, and the brute-force loop too.
#[test]
fn images_are_those_recorded() {
    type Expected<'a> = (&'a str, &'a [(Estimator, u32, u64)]);
    let want: [Expected; 2] = [
        (
            "media_scenes/six_lights.toml",
            &[
                (Estimator::Unweighted, 2, 0x37ec_1175_f963_f1d2),
                (Estimator::CmisCosine, 2, 0x401b_dca1_1280_68ae),
                (Estimator::SmisCosine, 2, 0x7edd_f045_600d_9f94),
                (Estimator::SmisExact, 2, 0x0ee2_4851_e255_c372),
                (Estimator::CmisExact, 2, 0xafe6_bb4f_b5ca_8859),
                (Estimator::SmisCosine, 4, 0xa74b_affb_4877_781e),
                (Estimator::SmisExact, 4, 0xef3e_415f_d213_6e0c),
                (Estimator::SmisCosine, 8, 0xaf21_a391_ac8c_3f9b),
                (Estimator::SmisExact, 8, 0x3d5c_268c_3ad1_b390),
            ],
        ),
        (
            "media_scenes/hard/camera_inside_box.toml",
            &[
                (Estimator::Unweighted, 2, 0xdd52_7add_b8f7_52b7),
                (Estimator::CmisCosine, 2, 0x0a30_b58d_2e36_c606),
                (Estimator::SmisCosine, 2, 0x7a41_213c_12f3_8851),
                (Estimator::SmisExact, 2, 0xfacf_7dbf_10d8_c37a),
                (Estimator::CmisExact, 2, 0x8412_71bd_01a0_8dca),
                (Estimator::SmisCosine, 4, 0x34ca_e79a_ef7b_d499),
                (Estimator::SmisExact, 4, 0x5fb4_4f4c_1189_f3c4),
                (Estimator::SmisCosine, 8, 0xf995_b69d_4a1e_a65a),
                (Estimator::SmisExact, 8, 0x1930_d155_c418_4909),
            ],
        ),
    ];
    for (file, cases) in want {
        let s = scene(file, 64, 36);
        for &(estimator, orientations, hash) in cases {
            let w = Weighting { estimator, orientations };
            let (image, _) =
                render(&s, &with(&s, w, Accelerator::Raster, Kernel::Auto, 1500), Control::none()).unwrap();
            assert_eq!(image_hash(&image.pixels), hash, "{file} {w}: the image changed");
        }
    }
}

#[test]
fn a_kernel_the_cpu_lacks_is_a_clear_error() {
    let s = scene("media_scenes/six_lights.toml", 16, 9);
    for k in Kernel::ALL.into_iter().filter(|k| !k.is_available()) {
        let e = Overrides { kernel: Some(k), ..Overrides::default() }.resolve(&s).unwrap_err();
        // Named neutrally by the library, as each front end spells it by them.
        assert!(e.to_string().starts_with("kernel: this CPU cannot run"), "{e}");
        assert!(e.worded(|s| s.flag()).starts_with("--kernel: "), "{e}");
    }
}

#[test]
fn bvh_finds_the_same_hits() {
    let s = scene("media_scenes/six_lights.toml", 64, 36);
    let w = Weighting::default();
    let (bvh, bs) = render(&s, &with(&s, w, Accelerator::Bvh, Kernel::Auto, 2000), Control::none()).unwrap();
    let (slow, ss) = render(&s, &with(&s, w, Accelerator::BruteForce, Kernel::Auto, 2000), Control::none()).unwrap();
    assert_eq!(bs.hits, ss.hits);
    assert!(bs.tests < ss.tests / 2, "the BVH should prune: {} tests against {}", bs.tests, ss.tests);
    // Same hits in another order: equal up to float summation order.
    for (a, b) in bvh.pixels.iter().zip(&slow.pixels) {
        assert!((*a - *b).abs().max_element() <= 1e-4 * b.max_element() + 1e-7, "{a} vs {b}");
    }
}

/// Nor on the thread count: the images of every estimator, with whole pixels (16 ray sets, so
/// that a chunk has several pieces) and at pixel centres, are main's before issue 38 bit for
/// bit (the hashes below, made at 868acbd), with pools of 1, 2, 3, 7, 16 and 64 workers, which
/// cut the image into different tiles (`raster::Tiling`). Three chunks of planes, so that a
/// chunk's planes are prepared while the one before is gathered; the error image too.
#[test]
fn images_are_main_s_at_every_thread_count_and_pixel_filter() {
    let s = scene("media_scenes/six_lights.toml", 96, 54);
    let planes = 2 * fogplanes::limits::CHUNK_PLANES + 3000;
    // (estimator, whole pixels, pixel centres)
    let want: [(Estimator, u64, u64); 5] = [
        (Estimator::Unweighted, 0xbfe3_ad5e_3c88_6b36, 0x291d_bfc2_dc03_6c28),
        (Estimator::CmisCosine, 0x3fd5_da52_7f3c_62c1, 0x8fd5_5186_4850_0352),
        (Estimator::SmisCosine, 0x09f0_488c_023d_da23, 0xf2f9_2efa_4d37_df52),
        (Estimator::SmisExact, 0x67d0_4033_0f67_7063, 0x8c2d_3ea4_c8f3_f0b5),
        (Estimator::CmisExact, 0x1b8f_a62d_86dc_aeea, 0x8492_624f_686b_ba27),
    ];
    let pools: Vec<_> =
        [1, 2, 3, 7, 16, 64].map(|t| rayon::ThreadPoolBuilder::new().num_threads(t).build().unwrap()).into();
    let mut got = Vec::new();
    for (estimator, whole, centre) in want {
        for (pixel_center, hash) in [(false, whole), (true, centre)] {
            let mut opts = Overrides {
                planes: Some(planes as u64),
                estimator: Some(estimator),
                seed: Some(5),
                pixel_center,
                ..Overrides::default()
            };
            opts.stderr = !pixel_center && estimator == Estimator::SmisExact;
            let opts = options(&s, opts);
            for pool in &pools {
                let (image, stats) = pool.install(|| render(&s, &opts, Control::none()).unwrap());
                let mut h = image_hash(&image.pixels);
                if let Some(se) = &stats.stderr {
                    h ^= image_hash(&se.pixels).rotate_left(1);
                }
                let mark = if h == hash { "" } else { "  <- not main's" };
                got.push(format!(
                    "{estimator}, centres {pixel_center}, {} workers: {h:#018x}{mark}",
                    pool.current_num_threads()
                ));
            }
        }
    }
    assert!(!got.iter().any(|g| g.ends_with("main's")), "{}", got.join("\n"));
}

/// The raster's near-plane and image clipping, with the camera inside the box, on its boundary,
/// in a light's plane and looking down a light's normal: still exactly the brute force's hits.
#[test]
fn raster_matches_brute_force_in_the_hard_camera_placements() {
    for file in [
        "camera_inside_box",
        "camera_on_boundary",
        "edge_on_light",
        "ray_in_light_plane",
        "camera_along_normal",
        "facing_lights_close",
    ] {
        let s = scene(&format!("media_scenes/hard/{file}.toml"), 48, 31);
        for e in [Estimator::Unweighted, Estimator::SmisExact] {
            let w = Weighting::new(e, None).unwrap();
            let (fast, fs) =
                render(&s, &with(&s, w, Accelerator::Raster, Kernel::Auto, 2000), Control::none()).unwrap();
            let (slow, ss) =
                render(&s, &with(&s, w, Accelerator::BruteForce, Kernel::Auto, 2000), Control::none()).unwrap();
            assert_eq!(fs.hits, ss.hits, "{file} {e}: hit counts differ");
            assert!(fast.pixels == slow.pixels, "{file} {e}: images differ");
        }
    }
}

/// Planes gathered in passes (the mechanism of `--time-budget`, here with a fixed schedule so
/// that nothing depends on timing) give the render of the same number of planes, up to f32
/// summation order, for both samplers: with one ray set, whatever the passes; with 16 (a pass
/// splits its planes among them, all 16 once it has 1024 planes for each), in one pass.
#[test]
fn a_render_in_passes_is_the_render_of_its_planes() {
    let s = scene("media_scenes/six_lights.toml", 64, 36);
    for sampler in Sampler::ALL {
        for (spp, schedule) in [(1, vec![256usize, 256, 512, 1000, 0]), (16, vec![16_400, 0])] {
            let opts = Overrides { seed: Some(3), sampler: Some(sampler), spp: Some(spp), ..Overrides::default() };
            let mut pass = schedule.iter();
            let (passes, ps) =
                render_in_passes(&s, &options(&s, opts.clone()), Control::none(), &mut |_| *pass.next().unwrap())
                    .unwrap();
            let planes = schedule.iter().sum();
            assert_eq!((ps.planes, ps.plane_passes), (planes, schedule.len() as u32 - 1));
            let (fixed, fs) =
                render(&s, &options(&s, Overrides { planes: Some(planes as u64), ..opts }), Control::none()).unwrap();
            assert_eq!(ps.hits, fs.hits, "{sampler}");
            for (a, b) in passes.pixels.iter().zip(&fixed.pixels) {
                assert!((*a - *b).abs().max_element() <= 1e-5 * b.max_element() + 1e-9, "{sampler}: {a} vs {b}");
            }
        }
    }
}
