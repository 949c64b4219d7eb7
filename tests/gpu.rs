//! The GPU gather held to the CPU's on every machine (lavapipe, Mesa's Vulkan on the CPU, where
//! there is no GPU; `.ci/run` installs it):
//!
//! - every estimator (K = 2 and K = 4 where it applies), whole pixels and pixel centres, a grey
//!   medium with panels that shadow planes and an RGB one: the fog's relative MSE against the
//!   CPU's at most 1e-8 (f32 rounding apart from grazing hits) and the hit counts within 1e-6;
//! - the thirteen hard scenes (media_scenes/hard/), five weightings and both filters in turn:
//!   the same bound, or a grazing hit's pixels alone beyond it;
//! - the ray sets the GPU makes (`gpu/rays.wgsl`) are the CPU's within f32 rounding, ray by ray,
//!   and the tiles and pixels it finds each plane near (`gpu/reach.wgsl`) hold the CPU's;
//! - no plane lost in long tile lists with the heaviest per-hit loops (llvmpipe silently ends
//!   an invocation's loops after about 65,000 iterations): hits against the CPU's;
//! - the same bits from run to run;
//! - unbiased: images match the independent reference renderer (tests/whole_pixels.rs's test);
//! - chunks rendered apart and merged, and a render resumed after its first chunk, give the
//!   render bit for bit.
//!
//! Where no adapter exists at all, each test says so loudly (SKIPPED) and passes.

use crate::common::{TWO_LIGHTS, options};
use crate::whole_pixels::against_reference;
use fogplanes::control::Control;
use fogplanes::emission::direct_emission;
use fogplanes::film::Film;
use fogplanes::gpu::Device;
use fogplanes::limits::CHUNK_PLANES;
use fogplanes::options::RenderStats;
use fogplanes::partial::{Partial, Resume, chunks, finish, merge_in_canonical_order};
use fogplanes::render::{render, render_chunk, render_from};
use fogplanes::scene::Scene;
use fogplanes::settings::Overrides;
use fogplanes::weights::{Estimator, Weighting};
use glam::DVec3;

/// Whether a GPU adapter exists; if not, says so on stderr for `test`, which then skips, unless
/// `FOGPLANES_REQUIRE_GPU=1` (CI sets it where it installed lavapipe): then the test fails.
pub fn have_gpu(test: &str) -> bool {
    match fogplanes::gpu::adapter() {
        Ok(g) => {
            eprintln!("{test}: on {}", g.name());
            true
        }
        Err(why) if std::env::var("FOGPLANES_REQUIRE_GPU").is_ok_and(|v| v == "1") => {
            panic!("{test}: FOGPLANES_REQUIRE_GPU=1 but there is no Vulkan adapter: {why}")
        }
        Err(why) => {
            eprintln!("SKIPPED: no Vulkan adapter for {test}: {why}");
            false
        }
    }
}

fn scene(file: &str, w: u32, h: u32) -> Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
    Scene::load(&path).unwrap().with_resolution(w, h).unwrap()
}

/// `given` on `device`: on the CPU without `rays_on_cpu`, which moves a GPU render's ray sets
/// and is refused for the CPU (a CPU render makes its own there).
fn on(given: &Overrides, device: Device) -> Overrides {
    let rays_on_cpu = given.rays_on_cpu && device != Device::Cpu;
    Overrides { device: Some(device), rays_on_cpu, ..given.clone() }
}

/// `planes` planes of `weighting` along the CPU's rays (the GPU gathering the rays the CPU
/// made, so that only the gather's arithmetic differs), 4 ray sets, seed 3.
fn along_the_cpus_rays(planes: u64, weighting: &Weighting, pixel_center: bool) -> Overrides {
    Overrides {
        planes: Some(planes),
        estimator: Some(weighting.estimator),
        orientations: Some(weighting.orientations),
        seed: Some(3),
        spp: Some(4),
        pixel_center,
        rays_on_cpu: true,
        ..Overrides::default()
    }
}

/// The render of `given` on `device`.
fn render_on(s: &Scene, given: &Overrides, device: Device) -> (Film, RenderStats) {
    render(s, &options(s, on(given, device)), Control::none()).unwrap()
}

/// The fog of an image: the image less its direct emission (the same on both devices).
fn fog(s: &Scene, given: &Overrides, film: &Film) -> Vec<DVec3> {
    let opts = options(s, given.clone());
    let e = direct_emission(s, opts.seed(), opts.spp(), opts.pixel_center());
    film.pixels.iter().zip(&e).map(|(p, e)| p.as_dvec3() - e.as_dvec3()).collect()
}

/// Relative MSE of `got` against `want`: the sum of squared differences over the sum of
/// squares; and the worst pixel.
fn relative_mse(got: &[DVec3], want: &[DVec3]) -> (f64, usize) {
    let (mut num, mut den, mut worst, mut worst_d) = (0.0, 0.0, 0, 0.0);
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        let d = (*g - *w).length_squared();
        (num, den) = (num + d, den + w.length_squared());
        if d > worst_d {
            (worst, worst_d) = (i, d);
        }
    }
    (num / den.max(1e-300), worst)
}

/// The GPU's gather along the CPU's rays (`rays_on_cpu`: uploaded, the same bits), so that the
/// per-hit arithmetic alone is held to the CPU's (the GPU's own rays are held to the CPU's in
/// `gpu_rays_are_the_cpus_within_f32_rounding`, and the two together in
/// `gpu_renders_along_its_own_rays_differ_from_the_cpus_only_at_grazing_hits`).
/// Every estimator, both pixel filters, a grey medium with shadowing panels at 160x90 and an RGB
/// one at 80x45 (few planes: lavapipe gathers at about 1 us a hit), along 4 ray sets (the hits
/// are the same as along 16: each plane is gathered along one set; a set's pieces are the GPU's
/// dispatches, a few milliseconds each on lavapipe). Each render's fog within 1e-8
/// relative MSE; the hits of all renders together within 1e-6 of the CPU's (a grazing hit,
/// counted on one side of a boundary to rounding, is 2e-6 of one render's 500,000 hits: the
/// prototype measured 1.2e-7 over 320 million).
#[test]
fn gpu_agrees_with_the_cpu_for_every_estimator_and_filter() {
    if !have_gpu("gpu_agrees_with_the_cpu_for_every_estimator_and_filter") {
        return;
    }
    let mut failures = Vec::new();
    let (mut hits_cpu, mut hits_apart) = (0u64, 0u64);
    // The RGB scene sees many more planes per pixel: a smaller image, so that as many planes
    // cost as much (a grazing hit's weight falls with 1 / N).
    for (file, (w, h)) in
        [("media_scenes/six_lights.toml", (160, 90)), ("media_scenes/hard/camera_inside_box.toml", (80, 45))]
    {
        let (s, planes) = (scene(file, w, h), 2048);
        for weighting in Weighting::all(&[4]) {
            for pixel_center in [false, true] {
                let given = along_the_cpus_rays(planes, &weighting, pixel_center);
                let (c, cs) = render_on(&s, &given, Device::Cpu);
                let (g, gs) = render_on(&s, &given, Device::GPU);
                let (fc, fg) = (fog(&s, &given, &c), fog(&s, &given, &g));
                let (rel, worst) = relative_mse(&fg, &fc);
                hits_cpu += cs.hits;
                hits_apart += gs.hits.abs_diff(cs.hits);
                let line = format!(
                    "{file} {weighting} {}: hits {} (CPU {}), fog relative MSE {rel:.2e} (worst pixel {worst}: {} against {})",
                    if pixel_center { "pixel centres" } else { "whole pixels" },
                    gs.hits,
                    cs.hits,
                    fg[worst],
                    fc[worst]
                );
                println!("{line}");
                assert!(cs.hits > 100_000, "{line}");
                if !(rel <= 1e-8) || !g.all_finite_non_negative() {
                    failures.push(line);
                }
            }
        }
    }
    println!("hits: {hits_apart} of the CPU's {hits_cpu} counted differently");
    assert!(failures.is_empty(), "the GPU differs from the CPU:\n{}", failures.join("\n"));
    assert!(hits_apart as f64 <= 1e-6 * hits_cpu as f64, "{hits_apart} of {hits_cpu} hits counted differently");
}

/// The Henyey-Greenstein phase function on the GPU (docs/mathematics.md section 1.1), along the
/// CPU's rays as above: at
/// g = 0.9, three estimators' fog within 1e-8 relative MSE of the CPU's (f32 rounding, as at
/// g = 0), whole pixels, the benchmark's lights at 160x90; at g = +-0.99, where the phase
/// value spans more than six orders of magnitude, smis-exact the same, and every pixel finite.
#[test]
fn gpu_agrees_with_the_cpu_in_forward_scattering_fog() {
    if !have_gpu("gpu_agrees_with_the_cpu_in_forward_scattering_fog") {
        return;
    }
    let mut failures = Vec::new();
    // The phase value enters every estimator's contribution in one place of gather.wgsl (D' in
    // `contribution`), after the weights: three estimators at g = 0.9 (no weight, the closed
    // form, the pairs), whose own arithmetic the test above holds for all nine at g = 0.
    let w = |e: Estimator| Weighting::new(e, None).unwrap();
    let mut cases: Vec<(f64, Weighting)> =
        [Estimator::Unweighted, Estimator::CmisExact, Estimator::SmisExact].map(|e| (0.9, w(e))).to_vec();
    cases.extend([-0.99, 0.99].map(|g| (g, w(Estimator::SmisExact))));
    for (g, weighting) in cases {
        let mut s = scene("media_scenes/six_lights.toml", 160, 90);
        s.medium.g = g;
        let given = Overrides {
            planes: Some(2048),
            estimator: Some(weighting.estimator),
            orientations: Some(weighting.orientations),
            seed: Some(5),
            rays_on_cpu: true,
            ..Overrides::default()
        };
        let (c, cs) = render_on(&s, &given, Device::Cpu);
        let (gp, gs) = render_on(&s, &given, Device::GPU);
        let (fc, fg) = (fog(&s, &given, &c), fog(&s, &given, &gp));
        let (rel, worst) = relative_mse(&fg, &fc);
        let line = format!(
            "g {g} {weighting}: hits {} (CPU {}), fog relative MSE {rel:.2e} (worst pixel {worst}: {} against {})",
            gs.hits, cs.hits, fg[worst], fc[worst]
        );
        println!("{line}");
        assert!(cs.hits > 100_000, "{line}");
        if !(rel <= 1e-8) || !gp.all_finite_non_negative() || !c.all_finite_non_negative() {
            failures.push(line);
        }
    }
    assert!(failures.is_empty(), "the GPU differs from the CPU:\n{}", failures.join("\n"));
}

/// The default GPU render, its rays made on the GPU (within f32 rounding of the CPU's, ray by
/// ray): every pixel the CPU's within f32 rounding but where a hit grazes a plane's edge, a
/// light's outline or a panel's, to rounding, and is counted on one side on one device and on
/// the other on the other. Such a pixel moves by one hit's share of it; the test counts the
/// pixels that differ by more than f32 rounding (1e-4 relative, several hundred roundings) and
/// holds them to a small fraction, and every pixel finite. A ray made wrong (a jitter hashed
/// differently, a segment cut at another face) moves most pixels by far more.
#[test]
fn gpu_renders_along_its_own_rays_differ_from_the_cpus_only_at_grazing_hits() {
    if !have_gpu("gpu_renders_along_its_own_rays_differ_from_the_cpus_only_at_grazing_hits") {
        return;
    }
    let mut failures = Vec::new();
    let s = scene("media_scenes/six_lights.toml", 160, 90);
    for weighting in [Weighting::new(Estimator::SmisExact, None).unwrap()] {
        for pixel_center in [false, true] {
            let given = Overrides {
                planes: Some(2048),
                estimator: Some(weighting.estimator),
                orientations: Some(weighting.orientations),
                seed: Some(3),
                pixel_center,
                ..Overrides::default()
            };
            let (c, cs) = render_on(&s, &given, Device::Cpu);
            let (g, gs) = render_on(&s, &given, Device::GPU);
            let (fc, fg) = (fog(&s, &given, &c), fog(&s, &given, &g));
            let (rel, worst) = relative_mse(&fg, &fc);
            let moved = fc.iter().zip(&fg).filter(|(c, g)| (**g - **c).length() > 1e-4 * c.length().max(1e-30)).count();
            let line = format!(
                "{weighting} {}: hits {} (CPU {}), fog relative MSE {rel:.2e}, {moved} of {} pixels beyond f32 rounding (worst {worst}: {} against {})",
                if pixel_center { "pixel centres" } else { "whole pixels" },
                gs.hits,
                cs.hits,
                fc.len(),
                fg[worst],
                fc[worst]
            );
            println!("{line}");
            // Measured on lavapipe: 1 to 3 pixels of 14,400 and one hit of a million.
            if moved * 1000 > fc.len() || gs.hits.abs_diff(cs.hits) * 100_000 > cs.hits || !g.all_finite_non_negative()
            {
                failures.push(line);
            }
        }
    }
    assert!(
        failures.is_empty(),
        "the GPU's render along its own rays differs from the CPU's:\n{}",
        failures.join("\n")
    );
}

/// The GPU's ray sets (`gpu/rays.wgsl`, made where they are gathered: no ray crosses) held to
/// the CPU's, the specification (docs/mathematics.md section 8.1), ray by ray: the direction
/// within 1e-6 (a few f32 roundings of a unit vector; a jitter hashed differently moves it by up
/// to a pixel, 1e-2 here), each end of the segment within 1e-5 of its length, and empty where
/// the CPU's is. A ray that grazes a box face or a panel's edge may differ more, from the f32
/// rounding of its inputs: such a ray is held to the spread of the CPU's own segment under turns
/// of its direction by 2e-6, and there are few of them. Both pixel filters, two ray sets, a
/// scene with panels in view and one whose camera stands inside the box.
#[test]
fn gpu_rays_are_the_cpus_within_f32_rounding() {
    use fogplanes::camera::CameraRay;
    use fogplanes::pixel::{ray_set_rays, ray_set_record};
    if !have_gpu("gpu_rays_are_the_cpus_within_f32_rounding") {
        return;
    }
    let gpu = fogplanes::gpu::adapter().unwrap();
    // Sets made together (one dispatch, each record saying where its panels and rays are; here
    // of two scenes of one image size, whose panels differ: the second set's, six_lights', end
    // some of its rays and follow forward_fog's, and read from the first they fail this) are
    // each the set made alone, bit for bit.
    let two =
        [scene("media_scenes/six_lights.toml", 80, 45), scene("media_scenes/hard/camera_inside_box.toml", 80, 45)];
    let records: Vec<_> = [(1, 0u32, false), (0, 5, false), (0, 9, true)]
        .map(|(s, k, centre)| ray_set_record(&two[s], 7, k, centre))
        .into();
    assert_ne!(records[0].1, records[1].1, "the scenes' panels differ");
    let sets: Vec<_> = records.iter().map(|(r, p)| (r, p.as_slice())).collect();
    let together = fogplanes::gpu::GpuRays::sets_on_gpu(&gpu, &sets).unwrap();
    let bits = |r: &CameraRay| [r.dir.x, r.dir.y, r.dir.z, r.t0, r.t1].map(f32::to_bits);
    for (i, (record, panels)) in records.iter().enumerate() {
        let alone = fogplanes::gpu::GpuRays::on_gpu(&gpu, record, panels).unwrap().read().unwrap();
        let made = together.read_set(i as u32).unwrap();
        assert!(alone.iter().map(bits).eq(made.iter().map(bits)), "set {i} made together");
    }
    let (mut rays, mut grazing, mut same) = (0usize, 0usize, 0usize);
    for (file, (w, h)) in
        [("media_scenes/six_lights.toml", (160, 90)), ("media_scenes/hard/camera_inside_box.toml", (80, 45))]
    {
        let s = scene(file, w, h);
        let o = s.camera.position;
        let segment = |d: DVec3| {
            let first = s.first_light_among(o, d, f64::INFINITY, 0..s.lights.len());
            s.segment_before(o, d, first.map_or(f64::INFINITY, |(t, _)| t))
        };
        let empty = |r: &CameraRay| !(r.t0 <= r.t1);
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-5 * b.abs().max(1.0);
        for pixel_center in [false, true] {
            for k in [0u32, 5] {
                let cpu = ray_set_rays(&s, 7, k, pixel_center);
                let (record, panels) = ray_set_record(&s, 7, k, pixel_center);
                let got = fogplanes::gpu::GpuRays::on_gpu(&gpu, &record, &panels).unwrap().read().unwrap();
                assert_eq!(got.len(), cpu.len());
                for (p, (g, c)) in got.iter().zip(&cpu).enumerate() {
                    let at = format!("{file} set {k} pixel centres {pixel_center} pixel {p}: GPU {g:?}, CPU {c:?}");
                    assert!((g.dir - c.dir).abs().max_element() <= 1e-6, "{at}");
                    assert!([g.t0, g.t1].iter().all(|t| t.is_finite()), "{at}");
                    rays += 1;
                    same += (g.dir == c.dir && g.t0.to_bits() == c.t0.to_bits() && g.t1.to_bits() == c.t1.to_bits())
                        as usize;
                    let (g0, g1, c0, c1) = (g.t0 as f64, g.t1 as f64, c.t0 as f64, c.t1 as f64);
                    if empty(g) == empty(c) && (empty(c) || (close(g0, c0) && close(g1, c1))) {
                        continue;
                    }
                    // Grazing: the GPU's segment among the CPU's under turns of the direction.
                    grazing += 1;
                    let d = c.dir.as_dvec3();
                    let turned: Vec<Option<(f64, f64)>> = (0..27)
                        .filter(|&n| n != 13)
                        .map(|n| {
                            let e = DVec3::new((n % 3) as f64 - 1.0, (n / 3 % 3) as f64 - 1.0, (n / 9) as f64 - 1.0);
                            segment((d + 2e-6 * e).normalize())
                        })
                        .collect();
                    let within = |v: f64, ends: &mut dyn Iterator<Item = f64>| {
                        let (lo, hi) = ends.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), t| (l.min(t), h.max(t)));
                        lo - 1e-5 * lo.abs().max(1.0) <= v && v <= hi + 1e-5 * hi.abs().max(1.0)
                    };
                    let held = if empty(g) {
                        turned.iter().any(|t| t.is_none())
                    } else {
                        turned.iter().any(|t| t.is_some())
                            && within(g0, &mut turned.iter().flatten().map(|t| t.0))
                            && within(g1, &mut turned.iter().flatten().map(|t| t.1))
                    };
                    assert!(held, "{at}: not within rounding of the CPU's, even grazing");
                }
            }
        }
    }
    println!("{rays} rays, {same} the same bits, {grazing} grazing a face or an edge to rounding");
    assert!(grazing * 1000 <= rays, "{grazing} of {rays} rays differ by more than rounding");
}

/// The reach the GPU finds from each plane's screen polygon (`gpu/reach.wgsl`, in f32) holds the
/// specification's (`gpu::tile_reach`, in f64 on the CPU): every pixel column of every group of
/// pixel rows there, in a tile of the row's span; within its bound of pairs; and only a little
/// more (its slack: a thirty-second of a pixel). On the benchmark's planes at 640x360, random
/// convex polygons (thin, tilted, past the image's edges) at 200x120, and large ones in an image
/// of 30,000 x 20,000 pixels, where f32 rounds at a few thousandths of a pixel.
#[test]
fn gpu_reach_holds_the_cpus() {
    use fogplanes::gpu::{TileReach, screen_reach, test_polygons, tile_reach};
    use fogplanes::photon_plane::{Polygon, sample_planes};
    use glam::DVec2;
    if !have_gpu("gpu_reach_holds_the_cpus") {
        return;
    }
    let gpu = fogplanes::gpu::adapter().unwrap();
    let s = scene("media_scenes/six_lights.toml", 640, 360);
    let planes = sample_planes(&s, Default::default(), 4096, 3);
    let benchmark: Vec<Polygon<DVec2>> =
        planes.iter().map(|p| fogplanes::raster::screen_polygon(&s.camera, p, &s.medium)).collect();
    let cases = [
        (benchmark, (640, 360)),
        (test_polygons(11, 3000, 200.0, 120.0), (200, 120)),
        (test_polygons(12, 40, 3e4, 2e4), (30_000, 20_000)),
    ];
    for (polygons, (w, h)) in cases {
        let spec: Vec<TileReach> = polygons.iter().map(|p| tile_reach(p, w, h)).collect();
        let screen: Vec<_> = polygons.iter().map(|p| screen_reach(p, w, h)).collect();
        let found = fogplanes::gpu::reach_on_gpu(&gpu, &screen, w, h).unwrap();
        let (mut tests, mut spec_tests) = (0u64, 0u64);
        for (i, ((want, got), bound)) in spec.iter().zip(&found).zip(&screen).enumerate() {
            let at = format!("{w}x{h} polygon {i} {:?}", &polygons[i].points());
            assert!(got.tiles() <= bound.pairs, "{at}: {} pairs, bound {}", got.tiles(), bound.pairs);
            (tests, spec_tests) = (tests + got.tests(h), spec_tests + want.tests(h));
            for (j, groups) in want.groups.iter().enumerate() {
                let row = want.first_row + j as u32;
                for (k, &g) in groups.iter().enumerate() {
                    let (first, last) = (g & 0xffff, g >> 16);
                    if first > last {
                        continue;
                    }
                    let r = row.checked_sub(got.first_row).map(|r| r as usize).filter(|&r| r < got.spans.len());
                    let r = r.unwrap_or_else(|| panic!("{at}: row of tiles {row} not found: {got:?}"));
                    let [a, b] = got.spans[r];
                    let (f, l) = (got.groups[r][k] & 0xffff, got.groups[r][k] >> 16);
                    assert!(
                        a <= first / 16 && last / 16 <= b && f <= first && last <= l,
                        "{at}: row {row} group {k}: the CPU's columns {first}..={last}, the GPU's {f}..={l} in tiles {a}..={b}"
                    );
                }
            }
        }
        let more = tests as f64 / spec_tests.max(1) as f64;
        println!(
            "{w}x{h}: {} polygons, the GPU's reach tests {tests} pixels, the CPU's {spec_tests} ({more:.4} times)",
            polygons.len()
        );
        assert!(more <= 1.01, "{w}x{h}: the GPU's reach tests {more} times the CPU's pixels");
    }
}

/// Long tile lists (40,000 planes over a 48x32 image: a few thousand planes per tile, cut into
/// many work items) with the heaviest per-hit work (64 orientations, cmis-exact; six panels, planes that
/// several shadow): every hit the CPU finds, none silently dropped by llvmpipe's loop limit.
#[test]
fn gpu_loses_no_plane_in_long_tile_lists() {
    if !have_gpu("gpu_loses_no_plane_in_long_tile_lists") {
        return;
    }
    let s = scene("media_scenes/six_lights.toml", 48, 32);
    for w in [
        Weighting { estimator: Estimator::SmisExact, orientations: 64 },
        Weighting { estimator: Estimator::CmisExact, orientations: 2 },
    ] {
        let given = Overrides {
            planes: Some(40_000),
            estimator: Some(w.estimator),
            orientations: Some(w.orientations),
            pixel_center: true,
            ..Overrides::default()
        };
        let (c, cs) = render_on(&s, &given, Device::Cpu);
        let (g, gs) = render_on(&s, &given, Device::GPU);
        let (rel, _) = relative_mse(&fog(&s, &given, &g), &fog(&s, &given, &c));
        println!("{w}: {} hits on the GPU, {} on the CPU; fog relative MSE {rel:.2e}", gs.hits, cs.hits);
        assert!((gs.hits as f64 - cs.hits as f64).abs() <= 1e-6 * cs.hits as f64, "{} vs {}", gs.hits, cs.hits);
        assert!(rel <= 1e-8, "{rel}");
    }
}

/// The same bits from run to run: binning keeps plane order in every tile, and each pixel's
/// sum has one writer.
#[test]
fn gpu_images_are_the_same_bits_from_run_to_run() {
    if !have_gpu("gpu_images_are_the_same_bits_from_run_to_run") {
        return;
    }
    let s = scene("media_scenes/six_lights.toml", 64, 36);
    let given = Overrides { planes: Some(3000), estimator: Some(Estimator::CmisExact), ..Overrides::default() };
    let (a, sa) = render_on(&s, &given, Device::GPU);
    let (b, sb) = render_on(&s, &given, Device::GPU);
    assert!(a.pixels == b.pixels, "two GPU renders differ");
    assert_eq!(sa.hits, sb.hits);
    assert!(sa.device.starts_with("gpu") && sa.seconds_device > 0.0, "{} {}", sa.device, sa.seconds_device);
    assert!(sa.seconds_upload > 0.0 && sa.summary().contains("the uploads' own"), "{}", sa.summary());
    // The CPU waited for the GPU's work at least while its sums were read back.
    assert!(sa.seconds_waited > 0.0 && sa.summary().contains("it waited for the GPU"), "{}", sa.summary());
    // Where the GPU has timestamps, its time is split: the gather's share is a part of it, and
    // the summary names both parts.
    if fogplanes::gpu::adapter().unwrap().has_timestamps() {
        assert!(0.0 < sa.seconds_device_gather && sa.seconds_device_gather < sa.seconds_device, "{}", sa.summary());
        assert!(sa.summary().contains("(the reach and the binning "), "{}", sa.summary());
    }
}

/// Unbiased on the GPU: images against the independent reference renderer (whole pixels in the
/// grey six-light scene, pixel centres in an RGB medium), the test of tests/whole_pixels.rs
/// with fewer seeds.
#[test]
fn gpu_images_match_the_reference() {
    if !have_gpu("gpu_images_match_the_reference") {
        return;
    }
    let mut failures = Vec::new();
    let two = Scene::parse(TWO_LIGHTS, "two.toml", "two").unwrap().with_resolution(24, 18).unwrap();
    for (s, pixel_center) in [(scene("media_scenes/six_lights.toml", 32, 18), false), (two, true)] {
        failures.extend(against_reference("gpu", &s, pixel_center, 24, &|seed| {
            let given = Overrides { planes: Some(1500), seed: Some(40 + seed), pixel_center, ..Overrides::default() };
            render_on(&s, &given, Device::GPU).0
        }));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The benchmark's plane count (three chunks, 34 pieces) goes to the GPU in at most six
/// submissions, with an error image too: each piece's sums are told apart by copies taken on
/// the GPU in order with the work and read back with the chunk's sums (a submission and a
/// read back a piece before, 34 here), and the images are those without it.
#[test]
fn a_gpu_render_is_few_submissions_with_an_error_image_too() {
    if !have_gpu("a_gpu_render_is_few_submissions_with_an_error_image_too") {
        return;
    }
    let s = scene("media_scenes/six_lights.toml", 32, 18);
    let given = Overrides { planes: Some(40_960), seed: Some(3), device: Some(Device::GPU), ..Overrides::default() };
    let (plain, plain_stats) = render(&s, &options(&s, given.clone()), Control::none()).unwrap();
    let (with, stats) = render(&s, &options(&s, Overrides { stderr: true, ..given }), Control::none()).unwrap();
    assert!(with.pixels == plain.pixels, "the error image changed the image");
    assert!(stats.stderr.as_ref().is_some_and(|se| se.all_finite_non_negative() && se.max() > 0.0));
    assert!(plain_stats.submissions <= 6, "{} submissions without an error image", plain_stats.submissions);
    assert!(stats.submissions <= 6, "{} submissions with an error image", stats.submissions);
}

/// Chunks rendered apart on the GPU and merged in any order give its render bit for bit; so does
/// a render resumed from the nodes it held after its first chunk (a checkpoint), with its error
/// image; and the render without the error image (whose pieces' sums cross back once a chunk,
/// not once a piece).
#[test]
fn gpu_chunks_merges_and_a_resumed_render_give_the_render() {
    if !have_gpu("gpu_chunks_merges_and_a_resumed_render_give_the_render") {
        return;
    }
    let s = scene("media_scenes/six_lights.toml", 32, 18);
    let planes = 2 * CHUNK_PLANES + 3000;
    let given = Overrides {
        planes: Some(planes as u64),
        seed: Some(5),
        stderr: true,
        device: Some(Device::GPU),
        ..Overrides::default()
    };
    let opts = options(&s, given.clone());
    let mut after_first: Option<(Vec<Partial>, Option<fogplanes::spread::GroupSpread>)> = None;
    let (whole, stats) = render_from(&s, &opts, Control::none(), Resume::default(), &mut |held, spread| {
        if after_first.is_none() {
            after_first = Some((held.to_vec(), spread.cloned()));
        }
        Ok(())
    })
    .unwrap();
    assert!(stats.device.starts_with("gpu"));
    let parts: Vec<_> =
        chunks(planes).into_iter().rev().map(|c| render_chunk(&s, &opts, c, Control::none()).unwrap().0).collect();
    let merged = merge_in_canonical_order(parts).unwrap();
    assert!(finish(&s, &opts, &merged).unwrap().pixels == whole.pixels, "merged chunks differ from the render");
    let (held, spread) = after_first.unwrap();
    let (resumed, resumed_stats) =
        render_from(&s, &opts, Control::none(), Resume { held, spread }, &mut |_, _| Ok(())).unwrap();
    assert!(resumed.pixels == whole.pixels, "the resumed render differs");
    assert!(resumed_stats.stderr.unwrap().pixels == stats.stderr.unwrap().pixels, "its error image differs");
    let plain = options(&s, Overrides { stderr: false, ..given });
    let (without, plain_stats) = render(&s, &plain, Control::none()).unwrap();
    assert!(without.pixels == whole.pixels, "the image without the error image differs");
    assert_eq!(plain_stats.hits, stats.hits);
    // The render's rays: each of its 16 sets once, as on the CPU, though the GPU makes set 7
    // (the first chunk's last and the second's first, gathered in windows apart) twice.
    let (_, cpu_stats) = render(&s, &options(&s, on(&given, Device::Cpu)), Control::none()).unwrap();
    assert_eq!((plain_stats.rays, stats.rays, cpu_stats.rays), (16 * 32 * 18, 16 * 32 * 18, 16 * 32 * 18));
}

/// A render in passes counts each ray set once on either device: two sets, three passes of one
/// set each (sets 0, 1 and 0 again, which the CPU keeps and the GPU makes again).
#[test]
fn a_render_in_passes_counts_its_rays_as_the_cpu_does() {
    if !have_gpu("a_render_in_passes_counts_its_rays_as_the_cpu_does") {
        return;
    }
    let s = scene("media_scenes/six_lights.toml", 32, 18);
    let given = Overrides { spp: Some(2), seed: Some(5), ..Overrides::default() };
    let counted = |device| {
        let mut passes = 0;
        let mut next = |_: fogplanes::render::PassReport| {
            passes += 1;
            if passes <= 3 { 1024 } else { 0 }
        };
        let opts = options(&s, on(&given, device));
        let (_, stats) = fogplanes::render::render_in_passes(&s, &opts, Control::none(), &mut next).unwrap();
        (stats.plane_passes, stats.rays, stats.hits)
    };
    let (cpu, gpu) = (counted(Device::Cpu), counted(Device::GPU));
    assert_eq!((cpu.0, cpu.1), (3, 2 * 32 * 18), "the CPU's passes and rays");
    assert_eq!((gpu.0, gpu.1), (cpu.0, cpu.1), "the GPU's passes and rays against the CPU's");
    assert!(gpu.2.abs_diff(cpu.2) * 100_000 <= cpu.2, "hits: GPU {} against the CPU's {}", gpu.2, cpu.2);
}

/// On the command line: a part gathered on the CPU and one on the GPU merge, and the merge says
/// that the devices differ (each part records its device); the merged image agrees with the
/// CPU's render within f32 rounding.
#[test]
fn gpu_parts_record_their_device_and_a_mixed_merge_says_so() {
    if !have_gpu("gpu_parts_record_their_device_and_a_mixed_merge_says_so") {
        return;
    }
    let dir = std::env::temp_dir().join(format!("fogplanes-gpu-parts-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let common = ["render", "media_scenes/six_lights.toml", "--resolution", "32x18", "--planes", "20000", "-q"];
    let run = |extra: &[&str]| {
        let args: Vec<&str> = common.iter().chain(extra).copied().collect();
        let o = crate::common::fogplanes(&args);
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    };
    run(&["-o", &p("cpu.exr")]);
    run(&["--plane-range", "0:16384", "--partial", &p("a.npz")]);
    run(&["--plane-range", "16384:20000", "--partial", &p("b.npz"), "--device", "gpu", "--rays-on-cpu"]);
    let part = fogplanes::partial::parts::read_part(std::path::Path::new(&p("b.npz"))).unwrap();
    assert!(part.meta.render.unwrap().devices[0].starts_with("gpu: "));
    let o = crate::common::fogplanes(&["merge", &p("a.npz"), &p("b.npz"), "-o", &p("merged.exr")]);
    let out = String::from_utf8_lossy(&o.stdout).to_string() + &String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success() && out.contains("different devices (cpu; gpu: "), "{out}");
    let (a, b) = (Film::load_exr(&dir.join("merged.exr")).unwrap(), Film::load_exr(&dir.join("cpu.exr")).unwrap());
    let to64 = |f: &Film| f.pixels.iter().map(|v| v.as_dvec3()).collect::<Vec<_>>();
    let (rel, _) = relative_mse(&to64(&a), &to64(&b));
    assert!(rel <= 1e-8, "{rel}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--device gpu` where no Vulkan driver can be found: one line naming the flag, exit 2; `auto`
/// falls back to the CPU. (The loader is pointed at a driver file that does not exist.)
#[test]
fn gpu_without_an_adapter_is_one_line_and_exit_2() {
    let run = |device: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_fogplanes"))
            .args(["render", "media_scenes/six_lights.toml", "--resolution", "16x9", "--planes", "64", "-q"])
            .args(["--device", device, "-o"])
            .arg(std::env::temp_dir().join(format!("fogplanes-no-gpu-{}.exr", std::process::id())))
            .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
            .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .unwrap()
    };
    let o = run("gpu");
    let err = String::from_utf8_lossy(&o.stderr);
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("error: --device")).collect();
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(lines.len() == 1 && lines[0].contains("no GPU adapter"), "{err}");
    assert!(run("auto").status.success());
}

/// An image whose rays do not fit one of the GPU's buffer bindings is refused in one line that
/// names the limit, before any work (not by the driver's validation, nor a panic).
#[test]
fn an_image_larger_than_the_gpu_binds_is_a_clear_error() {
    if !have_gpu("an_image_larger_than_the_gpu_binds_is_a_clear_error") {
        return;
    }
    let most = fogplanes::gpu::adapter().unwrap().max_binding();
    // The rays take the most bytes a pixel (a `CameraRay` each, as it is): the image just over
    // the limit, if that is a size to test here.
    let pixels = most / std::mem::size_of::<fogplanes::camera::CameraRay>() as u64 + 1;
    if pixels > 20_000_000 {
        eprintln!("SKIPPED: this adapter binds {most} bytes: an image over it is too large to test here");
        return;
    }
    let width = 2048u32;
    let height = pixels.div_ceil(width as u64) as u32;
    let s = scene("media_scenes/six_lights.toml", width, height);
    let given = Overrides { planes: Some(64), device: Some(Device::GPU), ..Overrides::default() };
    let Err(err) = render(&s, &options(&s, given), Control::none()) else {
        panic!("an image over the binding rendered")
    };
    let text = err.to_string();
    assert!(text.contains("more than the GPU binds at once") && !text.contains('\n'), "{text}");
}

/// A GPU render cancelled after its second piece stops with `Cancelled` (its submissions are not
/// waited for, and some may still be under way), and leaves nothing behind: the next render on
/// the same GPU is the bits of one never interrupted.
#[test]
fn a_cancelled_gpu_render_stops_and_leaves_the_next_render_whole() {
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    if !have_gpu("a_cancelled_gpu_render_stops_and_leaves_the_next_render_whole") {
        return;
    }
    let s = scene("media_scenes/six_lights.toml", 48, 27);
    let given =
        Overrides { planes: Some(CHUNK_PLANES as u64 + 2000), device: Some(Device::GPU), ..Overrides::default() };
    let opts = options(&s, given);
    let (whole, _) = render(&s, &opts, Control::none()).unwrap();
    let (cancel, units) = (AtomicBool::new(false), AtomicUsize::new(0));
    let progress = || {
        // The second piece gathered (submitted): cancel.
        if units.fetch_add(1, Ordering::Relaxed) > 0 {
            cancel.store(true, Ordering::Relaxed);
        }
    };
    let err = render(&s, &opts, Control::new(&progress, &cancel)).unwrap_err();
    assert!(matches!(err, fogplanes::Error::Cancelled), "{err}");
    let (again, _) = render(&s, &opts, Control::none()).unwrap();
    assert!(again.pixels == whole.pixels, "the render after a cancelled one differs");
}

/// A prepared render's pieces are gathered once a weighting (the equal-time table's
/// `ChunkRenderer::render_with`), on the GPU joined afresh each time (gpu/planes.rs
/// `GpuPlanes::join`): every weighting's sums are the bits of a render of that weighting alone,
/// the first weighting's again at the end. (The join had moved its parts' planes into the whole,
/// and the second weighting's gathering panicked.)
#[test]
fn gpu_prepared_pieces_are_gathered_again_for_each_weighting() {
    use fogplanes::render::ChunkRenderer;
    if !have_gpu("gpu_prepared_pieces_are_gathered_again_for_each_weighting") {
        return;
    }
    let s = scene("media_scenes/six_lights.toml", 40, 24);
    let given = |estimator| Overrides {
        planes: Some(4096),
        device: Some(Device::GPU),
        estimator: Some(estimator),
        ..Overrides::default()
    };
    let opts = options(&s, given(Estimator::SmisExact));
    let planes = 4096;
    let mut prepared = ChunkRenderer::prepared(&s, &opts, Control::none()).unwrap();
    for estimator in [Estimator::SmisExact, Estimator::Unweighted, Estimator::SmisExact] {
        let weighting = Weighting::new(estimator, None).unwrap();
        let again = prepared.render_with(weighting, 0..planes).unwrap();
        let alone_opts = options(&s, given(estimator));
        let alone = ChunkRenderer::new(&s, &alone_opts, Control::none()).render(0..planes).unwrap();
        assert!(again.sums.iter().any(|v| v.x > 0.0), "{estimator:?}: a black image says nothing");
        assert!(again.sums == alone.sums, "{estimator:?}: the prepared pieces gathered again differ");
    }
}

/// The hard scenes (media_scenes/hard/: the camera inside or on the box, along a normal, in a
/// light's plane, edge-on lights, facing and touching panels, dense fog and near vacuum, scales
/// 1e-3 and 1e4, a 1000:1 strip, a tiny bright light) gathered on the GPU along the CPU's rays,
/// each scene with two of five weightings in turn (no weight, smis-cosine at K = 3, the exact
/// pair, smis-exact at K = 4, the closed form: each weighting on five or six scenes) and the
/// pixel filters in turn: every pixel finite, at most two hits counted apart, and the fog within
/// 1e-8 relative MSE of the CPU's, or, where hits were counted apart (a hit grazing a chord's end
/// or the segment's to rounding, which may be most of a pixel with few hits: docs/gpu.md,
/// Precision), the pixels that moved beyond f32 rounding (1e-4 relative) at most two for each
/// such hit and the others within 1e-8. A sweep of every hard scene, estimator and filter at
/// 8,192 planes measured 1e-15 to 3.3e-11 with every hit alike (lavapipe, 2026-12-03:
/// docs/gpu_measurements.md, Precision on lavapipe).
#[test]
fn gpu_agrees_with_the_cpu_on_the_hard_scenes() {
    if !have_gpu("gpu_agrees_with_the_cpu_on_the_hard_scenes") {
        return;
    }
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("media_scenes/hard");
    let mut files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    assert!(files.len() >= 13, "the hard scenes: {files:?}");
    let weightings = [
        Weighting::new(Estimator::Unweighted, None).unwrap(),
        Weighting::new(Estimator::SmisCosine, Some(3)).unwrap(),
        Weighting::new(Estimator::SmisExact, None).unwrap(),
        Weighting::new(Estimator::SmisExact, Some(4)).unwrap(),
        Weighting::new(Estimator::CmisExact, None).unwrap(),
    ];
    let mut failures = Vec::new();
    for (n, file) in files.iter().enumerate() {
        let s = Scene::load(file).unwrap();
        let name = file.file_name().unwrap().to_string_lossy().into_owned();
        for m in [2 * n, 2 * n + 1] {
            let weighting = &weightings[m % weightings.len()];
            let pixel_center = m % 3 == 1;
            let given = along_the_cpus_rays(1024, weighting, pixel_center);
            let (c, cs) = render_on(&s, &given, Device::Cpu);
            let (g, gs) = render_on(&s, &given, Device::GPU);
            let (fc, fg) = (fog(&s, &given, &c), fog(&s, &given, &g));
            let moved: Vec<bool> =
                fc.iter().zip(&fg).map(|(c, g)| (*g - *c).length() > 1e-4 * c.length().max(1e-30)).collect();
            let kept =
                |f: &[DVec3]| f.iter().zip(&moved).map(|(p, m)| if *m { DVec3::ZERO } else { *p }).collect::<Vec<_>>();
            let (rel, worst) = relative_mse(&fg, &fc);
            let (rel_kept, _) = relative_mse(&kept(&fg), &kept(&fc));
            let (moved, apart) = (moved.iter().filter(|m| **m).count() as u64, gs.hits.abs_diff(cs.hits));
            let line = format!(
                "{name} {weighting} {}: hits {} (CPU {}), fog relative MSE {rel:.2e} (worst pixel {worst}: {} against {}), {moved} pixels moved, the others' {rel_kept:.2e}",
                if pixel_center { "pixel centres" } else { "whole pixels" },
                gs.hits,
                cs.hits,
                fg[worst],
                fc[worst]
            );
            println!("{line}");
            let grazing = apart > 0 && moved <= 2 * apart && rel_kept <= 1e-8;
            if !(rel <= 1e-8 || grazing) || apart > 2 || !g.all_finite_non_negative() || !c.all_finite_non_negative() {
                failures.push(line);
            }
        }
    }
    assert!(failures.is_empty(), "the GPU differs from the CPU on the hard scenes:\n{}", failures.join("\n"));
}
