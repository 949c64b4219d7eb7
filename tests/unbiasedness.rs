//! Every estimator is unbiased: for single camera rays in a small scene, the mean over many
//! independent plane sets agrees with deterministic quadrature of docs/mathematics.md section 1 within 4
//! standard errors, with a standard error below 1% of the value.
//!
//! The ground truth (`fogplanes::quadrature::single_scattering`) shares only the scene
//! description with the estimators.

use fogplanes::gather::{CameraRay, GatherContext};
use fogplanes::photon_plane::sample_planes;
use fogplanes::quadrature::single_scattering;
use fogplanes::sampling::Sampler;
use fogplanes::scene::Scene;
use fogplanes::weights::{Denominator, Weighting, WithDenominator};
use glam::{DVec3, Vec3};

use crate::common::MeanRgb;

/// A small fog box with two lights that cannot shadow each other (each lies behind the other's
/// plane): a ceiling panel facing down, and a small panel tilted in the slab above it facing +x
/// and down. RGB coefficients so that each channel is checked on its own.
const SCENE: &str = r#"
[camera]
position = [0.0, 1.5, 6.0]
look_at = [0.0, 1.5, 0.0]
up = [0.0, 1.0, 0.0]
vfov_deg = 50.0
resolution = [64, 48]

[medium]
min = [-2.0, 0.0, -2.0]
max = [2.0, 3.0, 2.0]
sigma_s = [0.5, 0.3, 0.2]
sigma_a = [0.1, 0.2, 0.05]

[[light]]
name = "ceiling"
corner = [-0.5, 2.9, -0.25]
edge_u = [1.0, 0.0, 0.0]
edge_v = [0.0, 0.0, 0.5]
radiance = [4.0, 3.0, 2.0]

[[light]]
name = "tilted"
corner = [1.2, 2.9, -0.5]
edge_u = [0.2, 0.1, 0.0]
edge_v = [0.0, 0.0, 1.0]
radiance = [1.0, 2.0, 6.0]
"#;

struct Case {
    name: &'static str,
    origin: DVec3,
    dir: DVec3,
}

fn cases() -> Vec<Case> {
    vec![
        // Horizontal, just under the ceiling light and along its u edge: parallel to the chords
        // of every plane with alpha near 0 and nearly inside many planes.
        Case { name: "nearly parallel", origin: DVec3::new(-3.0, 2.85, 0.0), dir: DVec3::new(1.0, 0.0, 0.001) },
        // Straight up into the ceiling light: along its normal.
        Case { name: "along the normal", origin: DVec3::new(0.1, 0.5, 0.05), dir: DVec3::new(0.0, 1.0, 0.0) },
        // Along the tilted light's surface, 0.01 in front of its centre.
        Case { name: "close to a light", origin: DVec3::new(1.3045, 2.9411, 1.5), dir: DVec3::new(0.0, -0.005, -1.0) },
        // An ordinary camera ray through the middle.
        Case { name: "generic", origin: DVec3::new(0.0, 1.5, 6.0), dir: DVec3::new(0.1, 0.05, -1.0) },
    ]
}

/// The estimate of one weighting for a ray, from a set of prepared planes.
struct Estimate<'a> {
    ctx: &'a GatherContext,
    ray: &'a CameraRay,
}

impl WithDenominator for Estimate<'_> {
    type Output = Vec3;
    fn run<D: Denominator>(self, weights: &D) -> Vec3 {
        self.ctx.gather_brute_force(weights, self.ray).0
    }
}

fn run(sampler: Sampler, weightings: &[Weighting], batches: u64, batch_size: usize) {
    let scene = Scene::parse(SCENE, "unbiasedness.toml", "unbiasedness").unwrap();
    let mut failures = Vec::new();
    for case in cases() {
        let we = case.dir.normalize();
        let (t0, t1) = scene.camera_segment(case.origin, we).0.expect("the ray crosses the medium");
        let ray = CameraRay { dir: we.as_vec3(), t0: t0 as f32, t1: t1 as f32 };
        let truth = single_scattering(&scene, case.origin, we, 1e-7);
        let mut tallies = vec![MeanRgb::default(); weightings.len()];
        for batch in 0..batches {
            let planes = sample_planes(&scene, sampler, batch_size, 1000 + batch);
            let ctx = GatherContext::new(&scene, &planes, case.origin);
            for (tally, w) in tallies.iter_mut().zip(weightings) {
                tally.add(w.dispatch(Estimate { ctx: &ctx, ray: &ray }));
            }
        }
        for (tally, w) in tallies.iter().zip(weightings) {
            for c in 0..3 {
                let (estimate, want) = (tally.0[c], truth[c]);
                let (mean, se, z) = (estimate.mean(), estimate.stderr(), estimate.z(want, 0.0));
                let line = format!(
                    "{sampler:>11} {:>16} {:>18} ch{c}: quadrature {want:.6e}, estimate {mean:.6e} +- {se:.2e} ({:.2}%), z = {z:+.2}",
                    case.name,
                    w.label(),
                    100.0 * se / want
                );
                println!("{line}");
                if !(z.abs() <= 4.0) || !(se < 0.01 * want) {
                    failures.push(line);
                }
            }
        }
    }
    assert!(failures.is_empty(), "outside 4 standard errors, or standard error above 1%:\n{}", failures.join("\n"));
}

/// Over independent scramble seeds (randomised quasi-Monte Carlo) and over independent planes.
#[test]
fn every_estimator_matches_quadrature() {
    for sampler in Sampler::ALL {
        run(sampler, &Weighting::all(&[]), 400, 10_000);
    }
}

#[test]
fn k_orientations_match_quadrature() {
    let extra: Vec<Weighting> = Weighting::all(&[3, 4, 8]).into_iter().filter(|w| w.orientations != 2).collect();
    assert_eq!(extra.len(), 6);
    run(Sampler::default(), &extra, 400, 10_000);
}
