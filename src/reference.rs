//! The independent reference renderer (SPEC section 3).
//!
//! Per pixel sample: a light chosen by power, a point uniform on it, a distance on the camera
//! segment by equiangular sampling toward that point (Kulla and Fajardo 2012), and the
//! integrand of SPEC section 1 evaluated with visibility. It shares the scene and medium code
//! with the photon planes and nothing else, and it measures its own per-pixel standard error.

use crate::film::Film;
use crate::medium::PHASE;
use crate::sampling::{Discrete, rng_for, unit_f64};
use crate::scene::Scene;
use glam::{DVec3, Vec3};
use rand::RngCore;
use rayon::prelude::*;

const REFERENCE_STREAM: u64 = 0x2EF_E2E;

/// Settings of a reference render.
#[derive(Clone, Debug)]
pub struct ReferenceOptions {
    pub spp: u32,
    pub seed: u64,
    pub pixel_center: bool,
}

/// A reference image with its per-pixel standard error.
pub struct ReferenceImage {
    pub mean: Film,
    pub stderr: Film,
    pub seconds: f64,
}

impl ReferenceImage {
    /// The mean squared standard error over pixels and channels: the MSE that the reference's
    /// own noise adds to any error measured against it.
    pub fn noise_mse(&self) -> f64 {
        let n = 3.0 * self.stderr.pixels.len().max(1) as f64;
        self.stderr.pixels.iter().map(|s| (s.as_dvec3() * s.as_dvec3()).element_sum()).sum::<f64>() / n
    }

    /// Root-mean-square standard error relative to the mean pixel value.
    pub fn relative_stderr(&self) -> f64 {
        self.noise_mse().sqrt() / self.mean.mean().max(1e-300)
    }
}

/// One sample of single scattering along the ray `o + t we`, `t` in `[t0, t1]`, from uniforms
/// `u` (light, point p, point q, distance). Equiangular sampling makes pdf(t) proportional to
/// 1 / |x - y|^2, so the estimate is cos(theta_y) (theta_b - theta_a) / D times the rest.
pub fn scattering_sample(
    scene: &Scene,
    lights: &Discrete,
    o: DVec3,
    we: DVec3,
    t0: f64,
    t1: f64,
    u: [f64; 4],
) -> DVec3 {
    let k = lights.sample(u[0]);
    let light = &scene.lights[k];
    let y = light.point(u[1] * light.width, u[2] * light.height);
    let delta = (y - o).dot(we);
    let dist = (o + delta * we - y).length();
    if !(dist > 0.0) {
        return DVec3::ZERO; // the ray passes through y: probability zero
    }
    let (theta_a, theta_b) = ((t0 - delta).atan2(dist), (t1 - delta).atan2(dist));
    let t = (delta + dist * (theta_a + u[3] * (theta_b - theta_a)).tan()).clamp(t0, t1);
    let x = o + t * we;
    let to_x = x - y;
    let d = to_x.length();
    let cos = light.n.dot(to_x) / d;
    if !(cos > 0.0) || scene.blocked(y, x, k) {
        return DVec3::ZERO;
    }
    let medium = &scene.medium;
    let tr = medium.transmittance((t - t0) + d);
    let weight = cos * (theta_b - theta_a) / dist * light.area() / lights.probability(k);
    medium.sigma_s * PHASE * light.radiance * tr * weight
}

/// Renders the reference image: `spp` samples per pixel, each its own camera ray (jittered over
/// the pixel, or through its centre) with direct emission and one scattering sample.
pub fn render_reference(scene: &Scene, opts: &ReferenceOptions, progress: &(dyn Fn() + Sync)) -> ReferenceImage {
    let start = std::time::Instant::now();
    let cam = &scene.camera;
    let w = cam.width as usize;
    let lights = crate::photon_plane::light_distribution(scene);
    let rows: Vec<(Vec<Vec3>, Vec<Vec3>)> = (0..cam.height as usize)
        .into_par_iter()
        .map(|j| {
            let mut means = Vec::with_capacity(w);
            let mut errors = Vec::with_capacity(w);
            for i in 0..w {
                let pixel = (j * w + i) as u64;
                let mut rng = rng_for(opts.seed, REFERENCE_STREAM, pixel);
                let mut next = || unit_f64(rng.next_u64());
                let (mut sum, mut sum_sq) = (DVec3::ZERO, DVec3::ZERO);
                let mut fixed = None;
                for _ in 0..opts.spp {
                    let (sx, sy) = if opts.pixel_center { (0.5, 0.5) } else { (next(), next()) };
                    let we = cam.direction(i as f64 + sx, j as f64 + sy).normalize();
                    let (segment, emission) = match (opts.pixel_center, fixed) {
                        (true, Some(f)) => f,
                        _ => scene.camera_segment(cam.position, we),
                    };
                    fixed = Some((segment, emission));
                    let mut value = emission;
                    if let Some((t0, t1)) = segment {
                        let u = [next(), next(), next(), next()];
                        value += scattering_sample(scene, &lights, cam.position, we, t0, t1, u);
                    }
                    sum += value;
                    sum_sq += value * value;
                }
                let n = opts.spp as f64;
                let mean = sum / n;
                let variance = ((sum_sq / n - mean * mean) * (n / (n - 1.0).max(1.0))).max(DVec3::ZERO);
                means.push(mean.as_vec3());
                let se = variance / n;
                errors.push(DVec3::new(se.x.sqrt(), se.y.sqrt(), se.z.sqrt()).as_vec3());
            }
            progress();
            (means, errors)
        })
        .collect();
    let mut mean = Film::new(cam.width, cam.height);
    let mut stderr = Film::new(cam.width, cam.height);
    for (j, (m, e)) in rows.into_iter().enumerate() {
        mean.pixels[j * w..(j + 1) * w].copy_from_slice(&m);
        stderr.pixels[j * w..(j + 1) * w].copy_from_slice(&e);
    }
    ReferenceImage { mean, stderr, seconds: start.elapsed().as_secs_f64() }
}
