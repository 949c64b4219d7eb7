//! `cmis-exact` evaluates its closed form in f32 (vectorised); this measures it against the f64
//! closed form on the benchmark scene's own hits: the relative error hit by hit, and its mean,
//! which is the relative bias it adds to the image (a hit contributes eta / (N P_l D), so a
//! relative error e in D is one of -e in the contribution).

use fogplanes::gather::GatherContext;
use fogplanes::photon_plane::sample_planes;
use fogplanes::pixel::ray_set_rays;
use fogplanes::sampling::Sampler;
use fogplanes::scene::Scene;
use fogplanes::weights::{CmisExact, Denominator, HitLocal, cmis_exact_mean};

#[test]
fn cmis_exact_in_f32_matches_f64_on_the_benchmark_hits() {
    let s = Scene::load(std::path::Path::new("media_scenes/six_lights.toml")).unwrap().with_resolution(32, 18).unwrap();
    let planes = sample_planes(&s, Sampler::default(), 40_960, 3);
    let ctx = GatherContext::new(&s, &planes, s.camera.position);
    let rays = ray_set_rays(&s, 3, 0, false);
    let mut errors = Vec::new();
    for ray in &rays {
        for v in &ctx.views {
            let c = v.crossing(ray.dir.to_array(), ray.t0, ray.t1);
            if !c.hit {
                continue;
            }
            let hit = HitLocal { det: c.det, det_perp: ray.dir.dot(v.normal_perp), a: c.a };
            let f = &v.frame;
            // The f64 form on the same f32 inputs (the rotation to (a_u, a_v) and the vertex
            // as the kernel makes them).
            let (a_u, a_v) = (f.cos_a * hit.det - f.sin_a * hit.det_perp, f.sin_a * hit.det + f.cos_a * hit.det_perp);
            let (p, q) = f.vertex(hit.a);
            let want = cmis_exact_mean(f.light_w as f64, f.light_h as f64, p as f64, q as f64, a_u as f64, a_v as f64);
            let got = CmisExact.denominator(f, &hit) as f64;
            if want > 0.0 {
                errors.push((got - want) / want);
            }
        }
    }
    assert!(errors.len() > 500_000, "{} hits", errors.len());
    let bias = errors.iter().sum::<f64>() / errors.len() as f64;
    let mut abs: Vec<f64> = errors.iter().map(|e| e.abs()).collect();
    abs.sort_by(f64::total_cmp);
    let at = |q: f64| abs[((abs.len() - 1) as f64 * q) as usize];
    println!(
        "{} hits: relative error median {:.1e}, 99% {:.1e}, 99.99% {:.1e}, largest {:.1e}; mean (the bias) {bias:.1e}",
        abs.len(),
        at(0.5),
        at(0.99),
        at(0.9999),
        at(1.0)
    );
    assert!(at(0.5) < 2e-7 && at(0.99) < 1e-6 && at(1.0) < 1e-5, "the f32 closed form strays from the f64 one");
    assert!(bias.abs() < 1e-7, "mean relative error {bias:e}");
}
