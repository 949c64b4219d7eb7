//! Plane sampling follows its densities (docs/mathematics.md section 2): chi-square tests on light choice,
//! orientation, point and direction, with fixed seeds. Each test fails when the statistic is
//! beyond the 1e-4 upper tail of its chi-square distribution (Wilson-Hilferty approximation).

use fogplanes::photon_plane::{PhotonPlane, sample_planes};
use fogplanes::sampling::Sampler;
use fogplanes::sampling::chi_square::{critical, statistic, uniform_statistic};
use fogplanes::scene::Scene;

fn scene() -> Scene {
    Scene::load(std::path::Path::new("media_scenes/six_lights.toml")).unwrap()
}

fn assert_uniform(name: &str, values: impl Iterator<Item = f64>, bins: usize) {
    let mut counts = vec![0u64; bins];
    for v in values {
        assert!((0.0..1.0).contains(&v), "{name}: {v} outside [0, 1)");
        counts[(v * bins as f64) as usize] += 1;
    }
    let (stat, limit) = (uniform_statistic(&counts), critical(bins - 1));
    println!("{name}: chi2 = {stat:.1} (critical {limit:.1})");
    assert!(stat < limit, "{name}: chi2 = {stat:.1} beyond {limit:.1}");
}

const N: usize = 400_000;

#[test]
fn lights_are_chosen_by_power() {
    let s = scene();
    for sampler in Sampler::ALL {
        let planes = sample_planes(&s, sampler, N, 21);
        let powers: Vec<f64> = s.lights.iter().map(|l| l.power()).collect();
        let total: f64 = powers.iter().sum();
        let mut counts = vec![0u64; s.lights.len()];
        for p in &planes {
            counts[p.light] += 1;
        }
        let stat = statistic(&counts, &powers.iter().map(|p| p / total).collect::<Vec<_>>());
        assert!(stat < critical(s.lights.len() - 1), "{sampler}: chi2 = {stat}, counts {counts:?}");
    }
}

/// Each sampled quantity follows its density, for both samplers; the orientation also within
/// each light (it is the light choice's remainder), and pairs of quantities jointly (2D cells),
/// which a mapping that correlated dimensions would fail.
#[test]
fn orientation_point_and_direction_follow_their_densities() {
    let s = scene();
    for sampler in Sampler::ALL {
        let planes = sample_planes(&s, sampler, N, 22);
        let name = |q: &str| format!("{sampler}: {q}");
        let alpha = |p: &PhotonPlane| p.alpha / std::f64::consts::PI;
        assert_uniform(&name("alpha / pi"), planes.iter().map(alpha), 64);
        for l in 0..s.lights.len() {
            assert_uniform(
                &name(&format!("alpha / pi on light {l}")),
                planes.iter().filter(|p| p.light == l).map(alpha),
                16,
            );
        }
        // The point is uniform on its light: p / W and q / H uniform and independent (2D bins).
        let local = |p: &PhotonPlane| {
            let l = &s.lights[p.light];
            let (x, y) = l.local(p.point);
            ((x / l.width).clamp(0.0, 0.999_999), (y / l.height).clamp(0.0, 0.999_999))
        };
        let cell = |x: f64, y: f64| ((x * 8.0).floor() * 8.0 + (y * 8.0).floor()) / 64.0;
        assert_uniform(&name("p / W"), planes.iter().map(|p| local(p).0), 64);
        assert_uniform(&name("q / H"), planes.iter().map(|p| local(p).1), 64);
        assert_uniform(&name("2D cell of (p, q)"), planes.iter().map(|p| cell(local(p).0, local(p).1)), 64);
        // pdf cos(theta) / pi: cos^2(theta) is uniform, and so is the azimuth.
        let frame = |p: &PhotonPlane| {
            let l = &s.lights[p.light];
            let cos2 = p.direction.dot(l.n).powi(2).min(0.999_999);
            (cos2, (p.direction.dot(l.v).atan2(p.direction.dot(l.u)) / std::f64::consts::TAU).rem_euclid(1.0))
        };
        assert_uniform(&name("cos^2 theta"), planes.iter().map(|p| frame(p).0), 64);
        assert_uniform(&name("azimuth"), planes.iter().map(|p| frame(p).1), 64);
        assert_uniform(&name("2D cell of (cos^2, azimuth)"), planes.iter().map(|p| cell(frame(p).0, frame(p).1)), 64);
        assert_uniform(&name("2D cell of (alpha, p)"), planes.iter().map(|p| cell(alpha(p), local(p).0)), 64);
        assert_uniform(&name("2D cell of (alpha, cos^2)"), planes.iter().map(|p| cell(alpha(p), frame(p).0)), 64);
        assert_uniform(&name("2D cell of (q, azimuth)"), planes.iter().map(|p| cell(local(p).1, frame(p).1)), 64);
    }
}

/// Over independent scramble seeds, a plane's numbers are uniform: the first plane of 20,000
/// seeds (each alone a single uniform point) follows the densities too.
#[test]
fn the_first_plane_over_scramble_seeds_is_uniform() {
    let s = scene();
    let firsts: Vec<PhotonPlane> = (0..20_000).flat_map(|seed| sample_planes(&s, Sampler::Sobol, 1, seed)).collect();
    assert_uniform("first plane: alpha / pi", firsts.iter().map(|p| p.alpha / std::f64::consts::PI), 32);
    let powers: Vec<f64> = s.lights.iter().map(|l| l.power()).collect();
    let total: f64 = powers.iter().sum();
    let mut counts = vec![0u64; s.lights.len()];
    for p in &firsts {
        counts[p.light] += 1;
    }
    let stat = statistic(&counts, &powers.iter().map(|p| p / total).collect::<Vec<_>>());
    assert!(stat < critical(s.lights.len() - 1), "first plane: chi2 = {stat}, counts {counts:?}");
}

#[test]
fn the_chi_square_test_rejects_a_wrong_density() {
    // The same test catches a direction sampled uniformly on the hemisphere instead.
    let mut counts = vec![0u64; 64];
    let n = 400_000;
    for i in 0..n {
        let cos = (i as f64 + 0.5) / n as f64; // uniform cos: the uniform-hemisphere density
        counts[((cos * cos) * 64.0) as usize] += 1;
    }
    assert!(uniform_statistic(&counts) > critical(63));
}
