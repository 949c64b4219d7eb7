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
        let set = PlaneSet::new(Sampler::default(), 3);
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
/// was each plane group gathered in two halves for the error image (docs/mathematics.md section
/// 10.1: f32 rounding, 8e-16 relative MSE on the benchmark's image), and before it cmis-exact's sum of its sectors' |dF| with a correction per zero of det, on the edge its
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
                (Estimator::Unweighted, 2, 0x4e5c_a215_af01_1835),
                (Estimator::CmisCosine, 2, 0x80f6_3340_d2b1_aa70),
                (Estimator::SmisCosine, 2, 0xdb6b_a5a1_1a44_a834),
                (Estimator::SmisExact, 2, 0x6e4e_6deb_fd2e_a407),
                (Estimator::CmisExact, 2, 0x25b6_8e8c_f263_2620),
                (Estimator::SmisCosine, 4, 0x8e3b_f949_9d46_07c7),
                (Estimator::SmisExact, 4, 0xb1e4_dfc4_7b3b_9ea2),
                (Estimator::SmisCosine, 8, 0x29ba_914f_1006_5b55),
                (Estimator::SmisExact, 8, 0xb545_5b2e_8226_41f9),
            ],
        ),
        (
            "media_scenes/hard/camera_inside_box.toml",
            &[
                (Estimator::Unweighted, 2, 0x6bf2_0022_efce_3b3e),
                (Estimator::CmisCosine, 2, 0x2602_faff_26e5_e685),
                (Estimator::SmisCosine, 2, 0xcd97_e34c_7cdb_249b),
                (Estimator::SmisExact, 2, 0xcf85_def6_41b6_ead7),
                (Estimator::CmisExact, 2, 0xf1be_bd3f_56cf_4d6b),
                (Estimator::SmisCosine, 4, 0x1cdf_2fa4_1971_bb22),
                (Estimator::SmisExact, 4, 0x8db3_7792_62f1_eee6),
                (Estimator::SmisCosine, 8, 0x65be_4a50_6b0c_5545),
                (Estimator::SmisExact, 8, 0xfbc5_bae4_4516_f5e7),
            ],
        ),
    ];
    // Every image that changed, reported at once with its hash.
    let mut changed = Vec::new();
    for (file, cases) in want {
        let s = scene(file, 64, 36);
        for &(estimator, orientations, hash) in cases {
            let w = Weighting { estimator, orientations };
            let (image, _) =
                render(&s, &with(&s, w, Accelerator::Raster, Kernel::Auto, 1500), Control::none()).unwrap();
            let got = image_hash(&image.pixels);
            if got != hash {
                changed.push(format!("{file} {w}: the image changed, to {got:#018x}"));
            }
        }
    }
    assert!(changed.is_empty(), "{}", changed.join("\n"));
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
/// that a chunk has several pieces) and at pixel centres, are main's bit for bit (the hashes
/// below, made when each group came to be gathered in two halves, 2026-12-02), with pools of 1, 2, 3, 7, 16 and 64 workers, which
/// cut the image into different tiles (`raster::Tiling`). Three chunks of planes, so that a
/// chunk's planes are prepared while the one before is gathered; the error image too.
#[test]
fn images_are_main_s_at_every_thread_count_and_pixel_filter() {
    let s = scene("media_scenes/six_lights.toml", 96, 54);
    let planes = 2 * fogplanes::limits::CHUNK_PLANES + 3000;
    // (estimator, whole pixels, pixel centres)
    let want: [(Estimator, u64, u64); 5] = [
        (Estimator::Unweighted, 0x9333_650c_c7fd_5a58, 0xfadc_a9d0_8940_44b0),
        (Estimator::CmisCosine, 0x3d5a_6bcc_a05e_7982, 0x2203_53cf_d5a3_7e49),
        (Estimator::SmisCosine, 0x9dbc_5ab1_b2dd_c14f, 0x6310_76fb_124a_5248),
        // Its error image's since 2026-12-04, the direct emission's variance added in f64 (it
        // was rounded to f32 first: 0xf151_2147_e07f_8dbb); the image's own bits as they were.
        (Estimator::SmisExact, 0x1e79_94f0_d85c_fa0e, 0x84cd_85fa_1080_be85),
        (Estimator::CmisExact, 0x971b_c0e0_006b_9c98, 0x9d5f_05c5_5d93_4a79),
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
