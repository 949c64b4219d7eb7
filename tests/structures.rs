//! The intersection structures find exactly the hits that testing every plane finds, with the
//! same weights; images do not depend on the thread count.

use fogplanes::render::{Accelerator, RenderOptions, render};
use fogplanes::scene::Scene;
use fogplanes::weights::{Estimator, Weighting};

fn scene(w: u32, h: u32) -> Scene {
    Scene::load(std::path::Path::new("media_scenes/six_lights.toml")).unwrap().with_resolution(w, h).unwrap()
}

fn options(estimator: Estimator, accelerator: Accelerator, planes: usize) -> RenderOptions {
    RenderOptions {
        planes,
        weighting: Weighting::new(estimator, None).unwrap(),
        seed: 5,
        spp: 1,
        pixel_center: false,
        accelerator,
    }
}

#[test]
fn raster_and_brute_force_agree_bit_for_bit() {
    let s = scene(80, 45);
    for e in [Estimator::Unweighted, Estimator::SmisExact, Estimator::CmisExact] {
        let (fast, fs) = render(&s, &options(e, Accelerator::Raster, 3000), &|| {});
        let (slow, ss) = render(&s, &options(e, Accelerator::BruteForce, 3000), &|| {});
        assert_eq!(fs.hits, ss.hits, "{e}: hit counts differ");
        assert!(fs.hits > 100_000);
        assert!(fast.pixels == slow.pixels, "{e}: images differ");
    }
}

#[test]
fn bvh_finds_the_same_hits() {
    let s = scene(64, 36);
    let (bvh, bs) = render(&s, &options(Estimator::SmisExact, Accelerator::Bvh, 2000), &|| {});
    let (slow, ss) = render(&s, &options(Estimator::SmisExact, Accelerator::BruteForce, 2000), &|| {});
    assert_eq!(bs.hits, ss.hits);
    assert!(bs.tests < ss.tests / 2, "the BVH should prune: {} tests against {}", bs.tests, ss.tests);
    // Same hits in another order: equal up to float summation order.
    for (a, b) in bvh.pixels.iter().zip(&slow.pixels) {
        assert!((*a - *b).abs().max_element() <= 1e-4 * b.max_element() + 1e-7, "{a} vs {b}");
    }
}

#[test]
fn images_do_not_depend_on_the_thread_count() {
    let s = scene(96, 54);
    let opts = options(Estimator::SmisExact, Accelerator::Raster, 4000);
    let render_with = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| render(&s, &opts, &|| {}).0)
    };
    assert!(render_with(1).pixels == render_with(3).pixels);
}

/// The raster's near-plane and image clipping, with the camera inside the box, on its boundary,
/// in a light's plane and looking down a light's normal: still exactly the brute force's hits.
#[test]
fn raster_matches_brute_force_in_the_hard_camera_placements() {
    for file in
        ["camera_inside_box", "camera_on_boundary", "edge_on_light", "camera_along_normal", "facing_lights_close"]
    {
        let path = format!("media_scenes/hard/{file}.toml");
        let s = Scene::load(std::path::Path::new(&path)).unwrap().with_resolution(48, 32).unwrap();
        let (fast, fs) = render(&s, &options(Estimator::SmisExact, Accelerator::Raster, 2000), &|| {});
        let (slow, ss) = render(&s, &options(Estimator::SmisExact, Accelerator::BruteForce, 2000), &|| {});
        assert_eq!(fs.hits, ss.hits, "{file}: hit counts differ");
        assert!(fast.pixels == slow.pixels, "{file}: images differ");
    }
}
