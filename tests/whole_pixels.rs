//! Whole pixels (docs/mathematics.md section 8) stay unbiased:
//!
//! - plane groups gathered each with its own ray (a ray set per plane group) match quadrature
//!   of the rays' single scattering, weighted by the groups' sizes, within 4 standard errors;
//! - the direct emission over a pixel fully covered by a light, half covered and at a light's
//!   corner matches its closed form (1, 1/2, 1/4 of the radiance) within 4 standard errors;
//! - whole images (box filter, and pixel centres) match the independent reference renderer's in
//!   the image mean and in blocks of pixels within 4.5 standard errors (both errors combined),
//!   for a fixed plane count and for a render in plane passes, and every estimator's image (K =
//!   4 and 64 too) in the same way;
//! - plane ranges rendered apart add up to the render of the whole set.
//!
//! Fixed seeds throughout; every tolerance is in standard errors measured from the samples.

use crate::common::options;
use fogplanes::accel::PreparedPlanes;
use fogplanes::camera::CameraRay;
use fogplanes::control::Control;
use fogplanes::film::Film;
use fogplanes::gather::GatherContext;
use fogplanes::limits::CHUNK_PLANES;
use fogplanes::partial::{chunks, finish, merge_in_canonical_order};
use fogplanes::photon_plane::{PlaneSet, sample_plane_range};
use fogplanes::pixel::{plane_group, ray_set_of_plane, ray_set_rays};
use fogplanes::quadrature::single_scattering;
use fogplanes::reference::{ReferenceImage, ReferenceOptions, render_reference};
use fogplanes::render::{render, render_chunk, render_in_passes};
use fogplanes::sampling::Sampler;
use fogplanes::scene::Scene;
use fogplanes::settings::Overrides;
use fogplanes::weights::Weighting;
use glam::{DVec3, Vec3};

use crate::common::{BruteForce, MeanEstimate, MeanRgb, Memo, TWO_LIGHTS};

/// Two panels crossing each other (the line where they meet is an outline), and a strip reaching
/// from the far wall to behind the camera (its outline crosses the camera's plane).
const CROSSING: &str = r#"
[camera]
position = [1.0, 1.8, 6.0]
look_at = [0.0, 1.5, 0.0]
up = [0.0, 1.0, 0.0]
vfov_deg = 60.0
resolution = [32, 18]

[medium]
min = [-3.0, 0.0, -3.0]
max = [3.0, 3.0, 8.0]
sigma_s = [0.3, 0.25, 0.2]
sigma_a = 0.05

[[light]]
name = "upright"          # x = 0.2, facing +x (towards the camera)
corner = [0.2, 0.5, 1.0]
edge_u = [0.0, 0.0, -2.0]
edge_v = [0.0, 2.0, 0.0]
radiance = [5.0, 4.0, 3.0]

[[light]]
name = "floor"            # y = 1.2, facing up, crossing the upright one
corner = [-1.0, 1.2, -0.8]
edge_u = [0.0, 0.0, 1.6]
edge_v = [2.0, 0.0, 0.0]
radiance = [1.0, 2.0, 4.0]

[[light]]
name = "strip"            # from z = -2 to z = 7, past the camera at z = 6
corner = [-2.5, 0.3, -2.0]
edge_u = [0.0, 0.0, 9.0]
edge_v = [0.5, 0.0, 0.0]
radiance = [2.0, 6.0, 2.0]
"#;

/// N planes in J groups (N not a multiple of J, so the groups differ in size and start off the
/// Sobol sequence's powers of two), group k gathered along ray k alone, every plane weighted
/// 1/N: the expectation is sum_k |G_k|/N L(ray k), with L by quadrature.
#[test]
fn a_ray_set_per_plane_group_matches_quadrature() {
    let scene = Scene::parse(TWO_LIGHTS, "fog.toml", "fog").unwrap();
    let o = scene.camera.position;
    let dirs: Vec<DVec3> =
        [(-0.1, 0.05), (0.12, 0.2), (0.25, 0.3)].iter().map(|&(x, y)| DVec3::new(x, y, -1.0).normalize()).collect();
    let (planes, ray_sets) = (2001usize, dirs.len() as u32);
    let rays: Vec<CameraRay> = dirs
        .iter()
        .map(|&we| {
            let (t0, t1) = scene.camera_segment(o, we).0.unwrap();
            CameraRay { dir: we.as_vec3(), t0: t0 as f32, t1: t1 as f32 }
        })
        .collect();
    let mut truth = DVec3::ZERO;
    for (k, &we) in dirs.iter().enumerate() {
        let share = plane_group(k as u32, planes, ray_sets).len() as f64 / planes as f64;
        truth += share * single_scattering(&scene, o, we, 1e-7);
    }
    let weighting = Weighting::default();
    let mut failures = Vec::new();
    for sampler in Sampler::ALL {
        let mut tally = MeanRgb::default();
        for seed in 0..400u64 {
            let mut sum = Vec3::ZERO;
            for (k, ray) in rays.iter().enumerate() {
                let group = plane_group(k as u32, planes, ray_sets);
                let mut ctx = GatherContext::empty(&scene, o);
                ctx.push_planes(&scene, &sample_plane_range(&scene, PlaneSet::new(sampler, 500 + seed), group), planes);
                sum += weighting.dispatch(BruteForce { ctx: &ctx, ray });
            }
            tally.add(sum);
        }
        for c in 0..3 {
            let e = &tally.0[c];
            let z = e.z(truth[c], 0.0);
            let line = format!(
                "{sampler} ch{c}: quadrature {:.6e}, estimate {:.6e} +- {:.2e}, z = {z:+.2}",
                truth[c],
                e.mean(),
                e.stderr()
            );
            println!("{line}");
            if !(z.abs() <= 4.0) || !(e.stderr() < 0.02 * truth[c]) {
                failures.push(line);
            }
        }
    }
    assert!(failures.is_empty(), "outside 4 standard errors or above 2%:\n{}", failures.join("\n"));
}

/// A camera looking down -z at a light in the plane z = 0 (facing it), in a medium that neither
/// scatters nor absorbs: a pixel's value is the light's radiance times the fraction of the pixel
/// it covers. The light's edges are turned by 0.3 rad against the pixel grid, so a straight edge
/// through the pixel's centre covers exactly half of it and a corner there a quarter (a right
/// angle at the centre of a square covers a quarter of it whatever its turn). Alone, the light's
/// coverage is computed exactly; with a black panel (its back to the camera) behind it, filling
/// the rest of the pixel, the pixel is sampled by its jittered grid.
#[test]
fn emission_over_a_pixel_matches_its_coverage() {
    let light = |corner: DVec3, u: DVec3, v: DVec3, radiance: f64| {
        format!(
            "[[light]]\ncorner = [{}, {}, {}]\nedge_u = [{}, {}, {}]\nedge_v = [{}, {}, {}]\nradiance = [{}, {}, {}]\n",
            corner.x,
            corner.y,
            corner.z,
            u.x,
            u.y,
            u.z,
            v.x,
            v.y,
            v.z,
            3.0 * radiance,
            2.0 * radiance,
            radiance
        )
    };
    let camera = r#"
[camera]
position = [0.0, 0.0, 5.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
vfov_deg = 40.0
resolution = [8, 8]

[medium]
min = [-10.0, -10.0, -10.0]
max = [10.0, 10.0, 10.0]
sigma_s = 0.0
sigma_a = 0.0
"#;
    let probe =
        Scene::parse(&format!("{camera}{}", light(DVec3::ZERO, DVec3::X, DVec3::Y, 1.0)), "c.toml", "c").unwrap();
    let cam = &probe.camera;
    // Pixel (3, 4)'s centre on the plane z = 0 (directions have forward component 1), and on
    // the plane z = -1.
    let centre = cam.position + 5.0 * cam.direction(3.5, 4.5);
    assert!(centre.z.abs() < 1e-12);
    let behind = cam.position + 6.0 * cam.direction(3.5, 4.5);
    let black = light(behind - 2.0 * DVec3::X + 2.0 * DVec3::Y, 4.0 * DVec3::X, -4.0 * DVec3::Y, 1.0);
    let (u, v) = (DVec3::new(0.3f64.cos(), 0.3f64.sin(), 0.0), DVec3::new(-0.3f64.sin(), 0.3f64.cos(), 0.0));
    let cases = [
        ("fully covered", centre - 2.0 * u - 2.0 * v, 1.0),
        ("half covered", centre - 2.0 * u, 0.5),
        ("a corner", centre, 0.25),
    ];
    let le = DVec3::new(3.0, 2.0, 1.0);
    let mut failures = Vec::new();
    for with_black in [false, true] {
        for (name, corner, fraction) in cases {
            let lights = light(corner, 4.0 * u, 4.0 * v, 1.0) + if with_black { black.as_str() } else { "" };
            let scene = Scene::parse(&format!("{camera}{lights}"), "c.toml", "c").unwrap();
            let mut tally = MeanRgb::default();
            for seed in 0..100 {
                let opts = options(&scene, Overrides { planes: Some(16), seed: Some(seed), ..Overrides::default() });
                let (film, _) = render(&scene, &opts, Control::none()).unwrap();
                tally.add(film.get(3, 4));
            }
            for c in 0..3 {
                let (e, want) = (&tally.0[c], le[c] * fraction);
                // Exact but for rounding when nothing is sampled.
                let exact = e.stderr() == 0.0;
                let z = if exact { (e.mean() - want) / (1e-6 * want) } else { e.z(want, 0.0) };
                let name = format!("{name}{}", if with_black { ", black panel behind" } else { "" });
                let line =
                    format!("{name} ch{c}: {want:.6} wanted, {:.6} +- {:.2e}, z = {z:+.2}", e.mean(), e.stderr());
                println!("{line}");
                // The stratified samples keep one estimate within 1% of the radiance.
                let spread = e.stderr() * (e.count() as f64).sqrt();
                if !(z.abs() <= 4.0) || !(spread < 0.01 * le[c]) {
                    failures.push(line);
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A light projected into less than a billionth of a pixel keeps its emission: in a medium that
/// neither scatters nor absorbs, the pixels hold its radiance times its projected area, whole
/// in one pixel and split between two when it straddles their edge (exact: one panel's
/// coverage is computed, nothing sampled). A bound of a billionth of the pixel alone dropped
/// it, all of its emission.
#[test]
fn a_light_smaller_than_a_billionth_of_a_pixel_keeps_its_emission() {
    let camera = "[camera]\nposition = [0.0, 0.0, 5.0]\nlook_at = [0.0, 0.0, 0.0]\nup = [0.0, 1.0, 0.0]\nvfov_deg = 40.0\nresolution = [8, 8]\n\n[medium]\nmin = [-10.0, -10.0, -10.0]\nmax = [10.0, 10.0, 10.0]\nsigma_s = 0.0\nsigma_a = 0.0\n";
    let probe = Scene::parse(&format!("{camera}{}", light_at(DVec3::ZERO, 1.0, 1.0)), "t.toml", "t").unwrap();
    let cam = &probe.camera;
    // A pixel's side on the plane z = 0 (directions have forward component 1), and the light's:
    // a 1e-5 of it, 1e-10 of the pixel's area.
    let pixel = 5.0 * (cam.direction(1.0, 0.0) - cam.direction(0.0, 0.0)).length();
    let side = 1e-5 * pixel;
    let le = 1e10;
    let want = le * (side / pixel).powi(2);
    for (name, x, pixels) in
        [("inside pixel (3, 4)", 3.5, vec![(3, 4)]), ("across pixels (3, 4) and (4, 4)", 4.0, vec![(3, 4), (4, 4)])]
    {
        let centre = cam.position + 5.0 * cam.direction(x, 4.5);
        let corner = centre - DVec3::new(0.5 * side, 0.5 * side, 0.0);
        let scene = Scene::parse(&format!("{camera}{}", light_at(corner, side, le)), "t.toml", "t").unwrap();
        let opts = options(&scene, Overrides { planes: Some(16), seed: Some(1), ..Overrides::default() });
        let (film, _) = render(&scene, &opts, Control::none()).unwrap();
        let total: f64 = film.pixels.iter().map(|p| p.x as f64).sum();
        let held: f64 = pixels.iter().map(|&(i, j)| film.get(i, j).x as f64).sum();
        println!("{name}: {want:.9e} wanted, {total:.9e} in the image, {held:.9e} in its pixels");
        // Each pixel is an f32 (a rounding of 6e-8 relative) of Le a computed in f64; before
        // the areas about a region's first vertex it was 1.8e-5 off, and before the bound
        // relative to the projection, 0.
        assert!((total - want).abs() <= 2e-7 * want, "{name}: {total:e} in the image, {want:e} wanted");
        assert!((held - total).abs() <= 1e-6 * want, "{name}: {held:e} in its pixels of {total:e}");
        for &(i, j) in &pixels {
            assert!(film.get(i, j).x > 0.0, "{name}: pixel ({i}, {j}) lost its part");
        }
    }
}

/// A square light facing the camera (down +z, towards it) with its corner at `corner`.
fn light_at(corner: DVec3, side: f64, radiance: f64) -> String {
    format!(
        "[[light]]\ncorner = [{:e}, {:e}, {:e}]\nedge_u = [{side:e}, 0.0, 0.0]\nedge_v = [0.0, {side:e}, 0.0]\nradiance = {radiance:e}\n",
        corner.x, corner.y, corner.z
    )
}

/// The reference that [`against_reference`] holds renders to (4,096 samples a pixel, seed
/// 17), rendered once per scene and pixel filter in this process and shared: the reference
/// renderer gives the same bits each time, and the benchmark at 32x18 is the reference of a
/// dozen tests here and in tests/gpu.rs (about a CPU second each).
fn reference_of(scene: &Scene, pixel_center: bool) -> &'static ReferenceImage {
    // A scene by its description (every field, printed), and the filter.
    static REFERENCES: Memo<(String, bool), ReferenceImage> = Memo::new();
    REFERENCES.get((format!("{scene:?}"), pixel_center), || {
        let opts = ReferenceOptions { spp: 4096, uniform: false, seed: 17, pixel_center };
        render_reference(scene, &opts, Control::none()).unwrap()
    })
}

/// The image mean and the means of blocks of pixels over `seeds` plane sets, against the
/// reference's (its standard errors from its replicates): every |z| within 4.5. Returns the
/// lines printed.
pub(crate) fn against_reference(
    name: &str,
    scene: &Scene,
    pixel_center: bool,
    seeds: u64,
    image: &dyn Fn(u64) -> Film,
) -> Vec<String> {
    let reference = reference_of(scene, pixel_center);
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    const BLOCK: usize = 8;
    let blocks_x = w.div_ceil(BLOCK);
    let block_of = |k: usize| (k / w / BLOCK) * blocks_x + (k % w) / BLOCK;
    let blocks = blocks_x * h.div_ceil(BLOCK);
    // Per region (the whole image, then each block) and channel: the renders' means over seeds,
    // and the reference's mean with its standard error.
    let mut renders = vec![[MeanEstimate::default(); 3]; blocks + 1];
    let mut refs = vec![[(0.0f64, 0.0f64); 3]; blocks + 1];
    let mut sizes = vec![0.0f64; blocks + 1];
    for k in 0..w * h {
        for region in [0, 1 + block_of(k)] {
            sizes[region] += 1.0;
            let (mean, stderr) = (reference.mean.pixels[k], reference.stderr.pixels[k]);
            for (c, r) in refs[region].iter_mut().enumerate() {
                r.0 += mean[c] as f64;
                r.1 += (stderr[c] as f64).powi(2);
            }
        }
    }
    for seed in 0..seeds {
        let film = image(seed);
        assert!(film.all_finite_non_negative(), "{name}: seed {seed}");
        let mut sums = vec![[0.0f64; 3]; blocks + 1];
        for (k, p) in film.pixels.iter().enumerate() {
            for region in [0, 1 + block_of(k)] {
                for c in 0..3 {
                    sums[region][c] += p[c] as f64;
                }
            }
        }
        for (r, s) in renders.iter_mut().zip(&sums) {
            for c in 0..3 {
                r[c].add(s[c]);
            }
        }
    }
    let mut failures = Vec::new();
    for region in 0..=blocks {
        for c in 0..3 {
            let n = sizes[region];
            let (ref_mean, ref_se) = (refs[region][c].0 / n, refs[region][c].1.sqrt() / n);
            let e = &renders[region][c];
            // Pixels are f32: means agree no closer than about 1e-6 relative.
            let scale = (e.stderr() / n).hypot(ref_se).hypot(1e-6 * ref_mean);
            // Blocks that see nothing (no fog, no light) are exactly zero in both.
            let z = if scale == 0.0 && e.mean() == 0.0 && ref_mean == 0.0 {
                0.0
            } else {
                (e.mean() / n - ref_mean) / scale
            };
            let label = if region == 0 { "image".to_string() } else { format!("block {}", region - 1) };
            let line = format!(
                "{name} {label} ch{c}: {:.6e} +- {:.1e}, reference {ref_mean:.6e} +- {ref_se:.1e}, z = {z:+.2}",
                e.mean() / n,
                e.stderr() / n
            );
            if region == 0 {
                println!("{line}");
            }
            if !(z.abs() <= 4.5) {
                failures.push(line);
            }
        }
    }
    failures
}

fn scene(file: &str, w: u32, h: u32) -> Scene {
    Scene::load(std::path::Path::new(file)).unwrap().with_resolution(w, h).unwrap()
}

/// Whole pixels and pixel centres, on the benchmark and on hard camera placements (inside the
/// box, a light edge-on, two lights facing each other close by), against the reference.
#[test]
fn whole_pixel_images_match_the_reference() {
    let mut failures = Vec::new();
    let crossing = Scene::parse(CROSSING, "crossing.toml", "crossing").unwrap();
    for (file, pixel_center) in [
        ("media_scenes/six_lights.toml", false),
        ("media_scenes/six_lights.toml", true),
        ("media_scenes/hard/camera_inside_box.toml", false),
        ("media_scenes/hard/edge_on_light.toml", false),
        ("media_scenes/hard/facing_lights_close.toml", false),
        ("crossing", false),
    ] {
        let s = if file == "crossing" { crossing.clone() } else { scene(file, 32, 18) };
        let name = format!("{file}{}", if pixel_center { " (pixel centres)" } else { "" });
        failures.extend(against_reference(&name, &s, pixel_center, 64, &|seed| {
            let opts = options(
                &s,
                Overrides { planes: Some(1500), seed: Some(40 + seed), pixel_center, ..Overrides::default() },
            );
            render(&s, &opts, Control::none()).unwrap().0
        }));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Every estimator's image against the reference, block by block as above: the tests above
/// render the default, smis-exact with the pair; here the other four, and the two with
/// orientations at K = 4 and K = 64, through the raster, the vector kernel and the pixel filter
/// as a render takes them (tests/unbiasedness.rs holds each weight to quadrature ray by ray, and
/// tests/hard_scenes.rs each image's mean alone). 64 plane sets each: unweighted's and the
/// cosine weights' tails are heavy near the lights' corners (their variance is infinite there), so
/// fewer sets would understate their standard errors.
#[test]
fn every_estimators_image_matches_the_reference() {
    let s = scene("media_scenes/six_lights.toml", 32, 18);
    let mut failures = Vec::new();
    for weighting in Weighting::all(&[4, 64]).into_iter().filter(|w| *w != Weighting::default()) {
        failures.extend(against_reference(&weighting.label(), &s, false, 64, &|seed| {
            let given = Overrides {
                planes: Some(1500),
                estimator: Some(weighting.estimator),
                orientations: Some(weighting.orientations),
                seed: Some(40 + seed),
                ..Overrides::default()
            };
            render(&s, &options(&s, given), Control::none()).unwrap().0
        }));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A render in plane passes (the mechanism of `--time-budget`) splits each pass among the ray
/// sets: unbiased too.
#[test]
fn a_render_in_passes_matches_the_reference() {
    let s = scene("media_scenes/six_lights.toml", 32, 18);
    let failures = against_reference("passes", &s, false, 24, &|seed| {
        let opts = options(&s, Overrides { seed: Some(70 + seed), ..Overrides::default() });
        let mut schedule = [256usize, 256, 512, 3000, 0].into_iter();
        render_in_passes(&s, &opts, Control::none(), &mut |_| schedule.next().unwrap()).unwrap().0
    });
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Each plane meets the ray set of its group (floor(i J / N)) in whatever chunk it is rendered:
/// chunks that cut the groups anywhere, rendered apart and merged, give the render bit for bit,
/// and their sums equal each group gathered alone along its own ray set (made here, apart from
/// the chunks' code), up to f32 summation order.
#[test]
fn plane_ranges_rendered_apart_add_up_to_the_render() {
    let s = scene("media_scenes/six_lights.toml", 48, 27);
    let planes = 2 * CHUNK_PLANES + 5000;
    let opts = options(&s, Overrides { planes: Some(planes as u64), seed: Some(9), ..Overrides::default() });
    assert_eq!(ray_set_of_plane(planes - 1, planes, opts.spp()), opts.spp() - 1);
    // The groups (of 2360 or 2361 planes) straddle the chunk boundaries.
    assert!(chunks(planes).iter().any(|c| (0..opts.spp()).any(|k| {
        let g = plane_group(k, planes, opts.spp());
        g.start < c.start && c.start < g.end
    })));
    let parts: Vec<_> =
        chunks(planes).into_iter().rev().map(|c| render_chunk(&s, &opts, c, Control::none()).unwrap().0).collect();
    let merged = merge_in_canonical_order(parts).unwrap();
    let (film, _) = render(&s, &opts, Control::none()).unwrap();
    assert_eq!(finish(&s, &opts, &merged).unwrap(), film);
    // Each group alone, along its ray set.
    let kernel = opts.kernel();
    let mut groups = vec![DVec3::ZERO; 48 * 27];
    for k in 0..opts.spp() {
        let group = plane_group(k, planes, opts.spp());
        let prepared = PreparedPlanes::new(&s, opts.plane_set(), group, opts.accelerator(), Control::none()).unwrap();
        let rays = ray_set_rays(&s, opts.seed(), k, false);
        let mut sums = vec![Vec3::ZERO; groups.len()];
        prepared.gather(opts.weighting(), kernel, &rays, &mut sums, Control::none()).unwrap();
        groups.iter_mut().zip(&sums).for_each(|(g, s)| *g += s.as_dvec3());
    }
    let largest = groups.iter().map(|v| v.max_element()).fold(0.0f64, f64::max);
    assert!(largest > 0.0);
    for (a, b) in merged.sums.iter().zip(&groups) {
        assert!((*a - *b).abs().max_element() <= 1e-5 * largest, "{a} vs {b}");
    }
    // The render is those sums over N plus the emission.
    let emission = fogplanes::emission::direct_emission(&s, opts.seed(), opts.spp(), false);
    for ((f, g), e) in film.pixels.iter().zip(&groups).zip(&emission) {
        let expected = (*g / planes as f64).as_vec3() + *e;
        assert!((*f - expected).abs().max_element() <= 1e-5 * f.max_element().max(1e-3), "{f} vs {expected}");
    }
}
