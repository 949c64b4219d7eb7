//! The independent reference renderer (docs/mathematics.md section 4).
//!
//! Per pixel sample: a light chosen by power, a point uniform on it, a distance on the camera
//! segment by equiangular sampling toward that point (Kulla and Fajardo 2012), and the
//! integrand of docs/mathematics.md section 1 evaluated with visibility. It shares with the
//! photon planes only the scene (with its light choice by power), the medium and the elementary
//! routines of [`crate::sampling`] (random streams, its low-discrepancy sequence): no plane,
//! chord, weight or gathering code. It
//! measures its own per-pixel standard error.

use crate::control::Control;
use crate::error::{Error, Result};
use crate::film::{Film, ImageInfo};
use crate::sampling::{Discrete, Kronecker, rng_for, unit_f64};
use crate::scene::Scene;
use glam::{DVec3, Vec3};
use rand::RngCore;
use std::sync::atomic::{AtomicUsize, Ordering};

const REFERENCE_STREAM: u64 = 0x2EF_E2E;

/// Settings of a reference render.
#[derive(Clone, Debug)]
pub struct ReferenceOptions {
    /// Average samples per pixel.
    pub spp: u32,
    /// Every pixel the same count, instead of counts by need.
    pub uniform: bool,
    pub seed: u64,
    pub pixel_center: bool,
}

impl ReferenceOptions {
    /// What the reference image of `scene` (its standard error with `stderr`) records of how
    /// it was made ([`ImageInfo`]).
    pub fn image_info(&self, scene: &Scene, stderr: bool) -> ImageInfo {
        let what = if stderr { "reference standard error" } else { "reference" };
        let cam = &scene.camera;
        ImageInfo::new(what, &scene.name, scene.fingerprint(), (cam.width, cam.height), self.pixel_center)
            .with_medium_g(scene.medium.g)
            .with("spp", self.spp)
            .with("seed", self.seed)
            .with("samples", if self.uniform { "uniform" } else { "adaptive" })
    }
}

/// A reference image with its per-pixel standard error.
pub struct ReferenceImage {
    pub mean: Film,
    pub stderr: Film,
    pub seconds: f64,
    /// The samples a pixel took on average, the pilot pass's included: what the asked `spp`
    /// became once each pixel's count was rounded up to its replicates (and, adaptive, after
    /// the pilot and the floor of [`reference_counts`]).
    pub samples: f64,
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
/// `u` (strategy and light, point p or the phase's cosine, point q or its azimuth, distance):
/// docs/mathematics.md section 4. In isotropic fog, a point `y` on a light chosen by power and
/// an equiangular distance toward it, whose pdf in `t` is proportional to 1 / |x - y|^2, so
/// that the estimate is cos(theta_y) (theta_b - theta_a) / D times the rest. In fog that
/// scatters forward or back (`g != 0`), one sample of two strategies weighted by the balance
/// heuristic: that one with probability `1 - c`, or (probability `c = |g| / 2`) a uniform
/// distance and a direction from the Henyey-Greenstein lobe, followed to the light it meets,
/// which finds the lobe's peak where the light's point misses it.
pub fn scattering_sample(
    scene: &Scene,
    lights: &Discrete,
    o: DVec3,
    we: DVec3,
    t0: f64,
    t1: f64,
    u: [f64; 4],
) -> DVec3 {
    let c = phase_strategy_share(scene.medium.g);
    let ray = ScatteringRay { scene, lights, o, we, segment: (t0, t1), c };
    if u[0] < c {
        ray.phase_sample([u[1], u[2], u[3]])
    } else {
        ray.light_sample([(u[0] - c) / (1.0 - c), u[1], u[2], u[3]])
    }
}

/// What both strategies of [`scattering_sample`] share: the scene, its lights' choice, the ray
/// `o + t we` over `segment` `[t0, t1]`, and the lobe's share `c` of the samples.
#[derive(Clone, Copy)]
struct ScatteringRay<'a> {
    scene: &'a Scene,
    lights: &'a Discrete,
    o: DVec3,
    we: DVec3,
    segment: (f64, f64),
    c: f64,
}

/// The share of the reference's scattering samples drawn from the phase function's lobe: none in
/// isotropic fog (or nearly: the lobe is then the sphere, which the lights' points serve
/// better), `|g| / 2` otherwise.
fn phase_strategy_share(g: f64) -> f64 {
    if g.abs() < 1e-3 { 0.0 } else { g.abs() / 2.0 }
}

/// The equiangular sampling of the distance along the ray toward a point `y`: the angles
/// `theta_a`, `theta_b` the segment's ends make at `y`, its distance `dist` from the ray's line
/// and the foot `delta` of the perpendicular.
struct Equiangular {
    theta_a: f64,
    theta_b: f64,
    dist: f64,
    delta: f64,
}

impl Equiangular {
    /// `None` where the ray passes through `y` (probability zero).
    fn toward(y: DVec3, o: DVec3, we: DVec3, (t0, t1): (f64, f64)) -> Option<Self> {
        let delta = (y - o).dot(we);
        let dist = (o + delta * we - y).length();
        if !(dist > 0.0) {
            return None;
        }
        Some(Equiangular { theta_a: (t0 - delta).atan2(dist), theta_b: (t1 - delta).atan2(dist), dist, delta })
    }

    /// `(t1 - t0) pdf_phase / pdf_light` at a sample `(t, y)` with phase value `phase` and light
    /// cosine `cos`, on a light of area over choice probability `area_over_p`: the lobe's pdf (a
    /// uniform distance, the lobe's solid angle made area at `y`, `phase cos / |x - y|^2 / (t1 -
    /// t0)`) over the light's (`P(k) / A_k` times the equiangular `dist / ((theta_b - theta_a)
    /// |x - y|^2)`), times the segment's length, which the callers cancel: the `|x - y|^2` cancel.
    fn pdf_ratio_times_length(&self, phase: f64, cos: f64, area_over_p: f64) -> f64 {
        phase * cos * (self.theta_b - self.theta_a) * area_over_p / self.dist
    }
}

impl ScatteringRay<'_> {
    /// The lights' strategy: a point on a light chosen by power, an equiangular distance toward it;
    /// weighted against the lobe's strategy (share `c`) by the balance heuristic.
    fn light_sample(&self, u: [f64; 4]) -> DVec3 {
        let ScatteringRay { scene, lights, o, we, segment, c } = *self;
        let (t0, t1) = segment;
        let k = lights.sample(u[0]);
        let light = &scene.lights[k];
        let y = light.point(u[1] * light.width, u[2] * light.height);
        let Some(e) = Equiangular::toward(y, o, we, segment) else { return DVec3::ZERO };
        let t = (e.delta + e.dist * (e.theta_a + u[3] * (e.theta_b - e.theta_a)).tan()).clamp(t0, t1);
        let x = o + t * we;
        let to_x = x - y;
        let d = to_x.length();
        let cos = light.n.dot(to_x) / d;
        if !(cos > 0.0) || scene.blocked(y, x, k) {
            return DVec3::ZERO;
        }
        let medium = &scene.medium;
        let tr = medium.transmittance((t - t0) + d);
        let weight = cos * (e.theta_b - e.theta_a) / e.dist * light.area() / lights.probability(k);
        // The phase function at the angle between the light's travel (y to x) and the way to the
        // eye (-we), section 1.1: PHASE itself when g = 0.
        let phase = medium.phase(to_x / d, -we);
        // f / pdf_light, over the balance heuristic's (1 - c) + c pdf_phase / pdf_light.
        let area_over_p = light.area() / lights.probability(k);
        let mis =
            if c > 0.0 { (1.0 - c) + c * e.pdf_ratio_times_length(phase, cos, area_over_p) / (t1 - t0) } else { 1.0 };
        // A weight past f64 (a light point all but on the ray's line) has probability zero.
        if !weight.is_finite() {
            return DVec3::ZERO;
        }
        medium.sigma_s * phase * light.radiance * tr * weight / mis
    }

    /// The lobe's strategy: a uniform distance in `[t0, t1]`, then the light's travel drawn from the
    /// Henyey-Greenstein lobe around the way to the eye (its cosine `mu` by inversion, section 1.1),
    /// followed back from `x` to the first panel it meets; weighted against the lights' strategy
    /// (share `1 - c`) by the balance heuristic. `f / pdf_phase` is `sigma_s L T (t1 - t0)`: the
    /// phase function and the geometry cancel.
    fn phase_sample(&self, u: [f64; 3]) -> DVec3 {
        let ScatteringRay { scene, lights, o, we, segment, c } = *self;
        let (t0, t1) = segment;
        let medium = &scene.medium;
        let g = medium.g;
        let t = (t0 + u[2] * (t1 - t0)).clamp(t0, t1);
        let x = o + t * we;
        // p(mu) = (1 - g^2) / (2 (1 + g^2 - 2 g mu)^(3/2)) on [-1, 1]; its inverse CDF.
        let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u[0]);
        let mu = ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0);
        let (b1, b2) = (-we).any_orthonormal_pair();
        let phi = std::f64::consts::TAU * u[1];
        let sin = (1.0 - mu * mu).max(0.0).sqrt();
        let travel = mu * -we + sin * (phi.cos() * b1 + phi.sin() * b2);
        // The light the travel came from: the nearest panel behind x along -travel (a panel's back,
        // or another panel, in front of it blocks it, as `Scene::blocked` has it).
        let toward = -travel;
        let mut nearest: Option<(f64, usize)> = None;
        for (k, light) in scene.lights.iter().enumerate() {
            if let Some(d) = light.intersect(x, toward, 0.0, f64::INFINITY)
                && nearest.is_none_or(|(best, _)| d < best)
            {
                nearest = Some((d, k));
            }
        }
        let Some((d, k)) = nearest else { return DVec3::ZERO };
        let light = &scene.lights[k];
        let y = x + d * toward;
        let cos = light.n.dot(travel);
        if !(cos > 0.0 && d > 0.0) {
            return DVec3::ZERO;
        }
        let Some(e) = Equiangular::toward(y, o, we, segment) else { return DVec3::ZERO };
        let phase = medium.phase(travel, -we);
        let q = e.pdf_ratio_times_length(phase, cos, light.area() / lights.probability(k));
        if !q.is_finite() {
            return DVec3::ZERO; // y all but on the ray's line: probability zero
        }
        let tr = medium.transmittance((t - t0) + d);
        // f / pdf_phase = sigma_s L T (t1 - t0), over c + (1 - c) pdf_light / pdf_phase, with
        // pdf_phase / pdf_light = q / (t1 - t0): the segment's length cancels, and no quotient
        // overflows where it is short.
        let len = t1 - t0;
        medium.sigma_s * light.radiance * tr * (len * q / (c * q + (1.0 - c) * len))
    }
}

/// Independent replicates per pixel: the standard error comes from their spread.
pub const REPLICATES: u32 = 16;

/// Renders the reference image with an average of `spp` samples per pixel.
///
/// Its noise is concentrated in few pixels (those that see a light panel or pass close to one,
/// where the equiangular estimate has a heavy tail), so samples are spread by need: a pilot
/// pass with an eighth of the budget measures each pixel's standard deviation, and the rest is
/// allocated in proportion to it (the allocation that minimises the summed variance), with at
/// least a quarter of the average (so that dim pixels keep a small relative error, which SMAPE
/// weighs) and at most 64 times the average. The image and its standard
/// error come from the second pass alone, whose sample counts are fixed before it runs, so
/// every pixel stays unbiased. `uniform` gives every pixel `spp` samples instead.
///
/// Reports each finished row to `control` (both passes' rows, unless `uniform`); once another
/// thread cancels it, the work stops before the next pixel and the result is
/// [`crate::Error::Cancelled`].
pub fn render_reference(scene: &Scene, opts: &ReferenceOptions, control: Control) -> Result<ReferenceImage> {
    render_reference_from(scene, opts, control, ReferenceDone::default(), &mut |_| Ok(()))
}

/// A band of rows of a reference's final pass: its mean and standard error.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceBand {
    pub rows: std::ops::Range<u32>,
    pub mean: Film,
    pub stderr: Film,
}

/// What a reference has finished: the pilot pass of an adaptive one (every row's standard
/// error) and bands of its final pass, in any order, without overlap.
#[derive(Clone, Debug, Default)]
pub struct ReferenceDone {
    pub pilot: Option<Film>,
    pub bands: Vec<ReferenceBand>,
}

/// What a reference tells its caller as it goes ([`render_reference_from`]).
pub enum ReferenceStep<'a> {
    /// The pilot pass of an adaptive reference is finished.
    Pilot(&'a Film),
    /// A band of the final pass is finished.
    Band(&'a ReferenceBand),
}

/// Rows per band of the final pass: each band is a live view's update and a checkpoint's file.
/// The threads share a band's pixels ([`render_pixels`]), so small bands cost no idle time.
pub const BAND_ROWS: u32 = 16;

/// [`render_reference`] resumed from `done` (what an earlier call with the same scene and
/// options finished; empty: from the start), rendering the final pass in bands of rows and
/// telling `observer` of the pilot pass and of each band as it finishes (a checkpoint, a live
/// view). Each pixel's samples are keyed by the seed and the pixel alone, so the image is
/// [`render_reference`]'s bit for bit however it was banded and resumed; `seconds` is this
/// call's. Refuses `done` of another size.
pub fn render_reference_from(
    scene: &Scene,
    opts: &ReferenceOptions,
    control: Control,
    done: ReferenceDone,
    observer: &mut dyn FnMut(ReferenceStep) -> Result<()>,
) -> Result<ReferenceImage> {
    let start = std::time::Instant::now();
    let (w, h) = (scene.camera.width, scene.camera.height);
    let sized = |f: &Film, rows: u32| f.width == w && f.height == rows && f.pixels.len() == (w * rows) as usize;
    let counts = match (opts.uniform, done.pilot) {
        (true, None) => None,
        (false, Some(pilot)) if sized(&pilot, h) => Some(reference_counts(opts, &pilot.pixels, w)?),
        (false, None) => {
            let pilot = reference_pilot_rows(scene, opts, 0..h, control)?;
            observer(ReferenceStep::Pilot(&pilot))?;
            Some(reference_counts(opts, &pilot.pixels, w)?)
        }
        _ => return Err(crate::Error::Partial("the pilot pass to resume from is not this reference's".into())),
    };
    let (mut mean, mut stderr) = (Film::new(w, h), Film::new(w, h));
    let mut finished = vec![false; h as usize];
    for b in &done.bands {
        let rows = b.rows.start as usize..b.rows.end as usize;
        let fits = b.rows.start < b.rows.end && b.rows.end <= h;
        if !fits || !sized(&b.mean, b.rows.len() as u32) || !sized(&b.stderr, b.rows.len() as u32) {
            return Err(crate::Error::Partial(format!(
                "rows {}:{} to resume from are not a band of this reference",
                b.rows.start, b.rows.end
            )));
        }
        if finished[rows.clone()].iter().any(|&f| f) {
            return Err(crate::Error::Partial(format!(
                "rows {}:{} to resume from overlap another band",
                b.rows.start, b.rows.end
            )));
        }
        finished[rows.clone()].fill(true);
        place(&mut mean, b.rows.start, &b.mean);
        place(&mut stderr, b.rows.start, &b.stderr);
    }
    let mut j = 0;
    while j < h {
        if finished[j as usize] {
            j += 1;
            continue;
        }
        let mut end = j + 1;
        while end < h && end - j < BAND_ROWS && !finished[end as usize] {
            end += 1;
        }
        let (m, e) = reference_rows(scene, opts, j..end, counts.as_deref(), control)?;
        place(&mut mean, j, &m);
        place(&mut stderr, j, &e);
        observer(ReferenceStep::Band(&ReferenceBand { rows: j..end, mean: m, stderr: e }))?;
        j = end;
    }
    let pixels = (w as usize * h as usize).max(1) as f64;
    let samples = match &counts {
        Some(c) => taken(pilot_spp(opts)) as f64 + c.iter().map(|&n| taken(n) as f64).sum::<f64>() / pixels,
        None => taken(opts.spp) as f64,
    };
    Ok(ReferenceImage { mean, stderr, seconds: start.elapsed().as_secs_f64(), samples })
}

/// A pixel's replicates and samples in each, for a count of `count` ([`pixel_estimate`]): as
/// many replicates as samples below [`REPLICATES`], and each of the same count, so the count is
/// rounded up to a multiple of them.
fn replicates(count: u32) -> (u32, u32) {
    let replicates = REPLICATES.min(count).max(1);
    (replicates, count.div_ceil(replicates))
}

/// The samples a pixel asked for `count` takes ([`replicates`]).
fn taken(count: u32) -> u64 {
    let (r, each) = replicates(count);
    r as u64 * each as u64
}

/// Copies `band` into `film` from row `row` on.
fn place(film: &mut Film, row: u32, band: &Film) {
    let at = row as usize * film.width as usize;
    film.pixels[at..at + band.pixels.len()].copy_from_slice(&band.pixels);
}

/// Samples per pixel of the pilot pass of the adaptive reference.
fn pilot_spp(opts: &ReferenceOptions) -> u32 {
    (opts.spp / 8).max(REPLICATES)
}

/// Rows `rows` of the reference (a band `rows.len()` high): its mean and standard error, with
/// `counts` samples in each pixel of the whole image (row-major, from [`reference_counts`]) or,
/// when `None`, `opts.spp` in every pixel (which `opts.uniform` asks for). Each pixel's random
/// stream is keyed by the seed and the pixel alone, so the bands of an image, rendered anywhere,
/// are its rows bit for bit.
pub fn reference_rows(
    scene: &Scene,
    opts: &ReferenceOptions,
    rows: std::ops::Range<u32>,
    counts: Option<&[u32]>,
    control: Control,
) -> Result<(Film, Film)> {
    check_rows(scene, &rows)?;
    match counts {
        Some(c) => {
            check_counts(scene, opts, c)?;
            render_pixels(scene, opts.seed, opts.pixel_center, rows, &|p| c[p], control)
        }
        None => render_pixels(scene, opts.seed, opts.pixel_center, rows, &|_| opts.spp, control),
    }
}

/// Rows `rows` of the adaptive reference's pilot pass: each pixel's standard error (the
/// measure of its need that [`reference_counts`] reads).
pub fn reference_pilot_rows(
    scene: &Scene,
    opts: &ReferenceOptions,
    rows: std::ops::Range<u32>,
    control: Control,
) -> Result<Film> {
    check_rows(scene, &rows)?;
    let spp = pilot_spp(opts);
    Ok(render_pixels(scene, opts.seed ^ PILOT_SEED, opts.pixel_center, rows, &|_| spp, control)?.1)
}

/// The most samples the adaptive reference gives a pixel, per sample of the average `spp`.
pub const MOST_SAMPLES_PER_SPP: u32 = 64;

/// Per-pixel sample counts given back for `scene` with `opts` (Python's `counts`) are what
/// [`reference_counts`] can make: one per pixel, each at least 1 (a pixel of none would be
/// 0/0) and at most [`MOST_SAMPLES_PER_SPP`] times `opts.spp` (its cap, which bounds the work
/// as `spp`'s own limit does).
pub fn check_counts(scene: &Scene, opts: &ReferenceOptions, counts: &[u32]) -> Result<()> {
    let (w, pixels) = (scene.camera.width as usize, scene.camera.width as usize * scene.camera.height as usize);
    let bad = |message: String| Error::BadArray { name: "counts", message };
    if counts.len() != pixels {
        return Err(bad(format!("{} sample counts for an image of {pixels} pixels", counts.len())));
    }
    let most = MOST_SAMPLES_PER_SPP.saturating_mul(opts.spp);
    if let Some((i, &c)) = counts.iter().enumerate().find(|&(_, &c)| c == 0 || c > most) {
        return Err(bad(format!(
            "pixel (x {}, y {}) has {c} samples; a pixel has between 1 and {most} ({MOST_SAMPLES_PER_SPP} x spp {})",
            i % w,
            i / w,
            opts.spp
        )));
    }
    Ok(())
}

/// The rows `rows` lie in the image and are not empty.
fn check_rows(scene: &Scene, rows: &std::ops::Range<u32>) -> Result<()> {
    band_of_rows(scene, (rows.start.into(), rows.end.into())).map(|_| ())
}

/// Rows `j0..j1` as given (a command line's `--rows J0:J1`), if they are a band of the image:
/// checked before they are narrowed to the rows' type, so that a refusal quotes them as given.
pub fn band_of_rows(scene: &Scene, (j0, j1): (u64, u64)) -> Result<std::ops::Range<u32>> {
    let h = scene.camera.height;
    if j0 >= j1 || j1 > u64::from(h) {
        return Err(crate::Error::Partial(format!(
            "rows {j0}:{j1} are not a band of the image's {h} rows (0 <= J0 < J1 <= {h})"
        )));
    }
    // Both at most h, a u32.
    Ok(j0 as u32..j1 as u32)
}

/// The adaptive reference's sample count of every pixel from the whole pilot's standard errors
/// `pilot` (row-major, `width` wide): the allocation described at [`render_reference`].
/// Refuses a pilot holding what no pilot pass makes (a standard error that is negative, NaN or
/// infinite would give its pixel no samples, or every other pixel none), naming the pixel.
pub fn reference_counts(opts: &ReferenceOptions, pilot: &[Vec3], width: u32) -> Result<Vec<u32>> {
    let values = pilot.iter().map(|p| p.as_dvec3().to_array());
    if let Some(p) = crate::film::first_outside(values, width, f32::MAX as f64) {
        return Err(Error::BadArray {
            name: "pilot",
            message: format!("{p}: a pilot pass holds standard errors, finite and non-negative"),
        });
    }
    let pixels = pilot.len();
    let pilot_spp = pilot_spp(opts);
    // Standard deviation of one sample, the mean over channels.
    let sigma: Vec<f64> = pilot.iter().map(|s| (s.x + s.y + s.z) as f64 / 3.0 * (pilot_spp as f64).sqrt()).collect();
    let total_sigma: f64 = sigma.iter().sum();
    let budget = (opts.spp as f64 - pilot_spp as f64).max(REPLICATES as f64) * pixels as f64;
    let (floor, cap) = ((opts.spp as f64 / 4.0).max(REPLICATES as f64), MOST_SAMPLES_PER_SPP as f64 * opts.spp as f64);
    // The floor is taken first; the rest goes by need.
    let budget = (budget - floor * pixels as f64).max(0.0);
    Ok(sigma
        .iter()
        .map(|&s| {
            let share = if total_sigma > 0.0 { budget * s / total_sigma } else { budget / pixels as f64 };
            (floor + share).min(cap).round() as u32
        })
        .collect())
}

/// Seed offset of the pilot pass, so that it shares no samples with the final one.
const PILOT_SEED: u64 = 0x9_11_07;

/// Pixels per unit of parallel work of the reference: a pixel is tens of microseconds.
const REFERENCE_UNIT: usize = 8;

/// Renders rows `rows` (a band of the image), pixel `p` (row-major in the whole image) with
/// `spp(p)` samples, in [`REPLICATES`] independent replicates of
/// randomised quasi-Monte Carlo: a randomly shifted low-discrepancy sequence over (jitter x,
/// jitter y, light, point p, point q, distance). Each replicate is unbiased; the pixel value is
/// their mean and its standard error comes from their spread, an honest measure of the noise.
/// The cancel flag is read before each pixel (at most 64 times the average samples, a few
/// milliseconds).
fn render_pixels(
    scene: &Scene,
    seed: u64,
    pixel_center: bool,
    rows: std::ops::Range<u32>,
    spp: &(dyn Fn(usize) -> u32 + Sync),
    control: Control,
) -> Result<(Film, Film)> {
    let cam = &scene.camera;
    let w = cam.width as usize;
    let lights = scene.light_distribution();
    let sequence = Kronecker::<6>::new();
    let band = rows.len() as u32;
    // Pixels, not rows, are the unit of parallel work: the threads run out of a band's work
    // within a pixel's time of each other, so small bands keep every thread busy. A row's last
    // pixel to finish reports the row.
    let unfinished: Vec<AtomicUsize> = (0..band).map(|_| AtomicUsize::new(w)).collect();
    let top = rows.start as usize;
    // Units of a few pixels, each a unit of the schedule's record when there is one
    // ([`crate::schedule`]).
    let values: Vec<(Vec3, Vec3)> = control.map_units("reference", band as usize * w, REFERENCE_UNIT, |i| {
        let p = top * w + i;
        if control.is_cancelled() {
            return (Vec3::ZERO, Vec3::ZERO); // the image is discarded
        }
        let v = pixel_estimate(scene, &lights, &sequence, (seed, pixel_center), (p % w, p / w), spp(p));
        if unfinished[p / w - top].fetch_sub(1, Ordering::Relaxed) == 1 {
            control.progress();
        }
        v
    });
    control.check()?;
    let mean = Film { width: cam.width, height: band, pixels: values.iter().map(|v| v.0).collect() };
    let stderr = Film { width: cam.width, height: band, pixels: values.iter().map(|v| v.1).collect() };
    Ok((mean, stderr))
}

/// Pixel `(i, j)`'s mean and standard error from `count` samples in [`REPLICATES`] replicates
/// (what [`render_pixels`] describes), its random numbers keyed by the seed and the pixel.
fn pixel_estimate(
    scene: &Scene,
    lights: &Discrete,
    sequence: &Kronecker<6>,
    (seed, pixel_center): (u64, bool),
    (i, j): (usize, usize),
    count: u32,
) -> (Vec3, Vec3) {
    let cam = &scene.camera;
    let pixel = (j * cam.width as usize + i) as u64;
    let mut rng = rng_for(seed, REFERENCE_STREAM, pixel);
    let (replicates, per_replicate) = replicates(count);
    let per_replicate = per_replicate as u64;
    let centre_dir = cam.direction(i as f64 + 0.5, j as f64 + 0.5).normalize();
    let centre = scene.camera_segment(cam.position, centre_dir);
    let (mut sum, mut sum_sq) = (DVec3::ZERO, DVec3::ZERO);
    for _ in 0..replicates {
        let shift: [f64; 6] = std::array::from_fn(|_| unit_f64(rng.next_u64()));
        let mut replicate = DVec3::ZERO;
        for k in 0..per_replicate {
            let u = sequence.point(k, &shift);
            let (we, (segment, emission)) = if pixel_center {
                (centre_dir, centre)
            } else {
                let we = cam.direction(i as f64 + u[0], j as f64 + u[1]).normalize();
                (we, scene.camera_segment(cam.position, we))
            };
            replicate += emission;
            if let Some((t0, t1)) = segment {
                replicate += scattering_sample(scene, lights, cam.position, we, t0, t1, [u[2], u[3], u[4], u[5]]);
            }
        }
        let replicate = replicate / per_replicate as f64;
        sum += replicate;
        sum_sq += replicate * replicate;
    }
    let r = replicates as f64;
    let mean = sum / r;
    let variance_of_mean = ((sum_sq / r - mean * mean) / (r - 1.0).max(1.0)).max(DVec3::ZERO);
    let stderr = DVec3::new(variance_of_mean.x.sqrt(), variance_of_mean.y.sqrt(), variance_of_mean.z.sqrt());
    (mean.as_vec3(), stderr.as_vec3())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

    /// A reference reports the samples it took: each pixel's count rounded up to its
    /// replicates, and an adaptive one's pilot and floor of 16 (below 32 spp it takes 32).
    #[test]
    fn a_reference_reports_the_samples_it_took() {
        let scene =
            Scene::parse(crate::scene::tests::MINIMAL, "test.toml", "test").unwrap().with_resolution(6, 4).unwrap();
        let taken = |spp, uniform| {
            let opts = ReferenceOptions { spp, uniform, seed: 3, pixel_center: false };
            render_reference(&scene, &opts, Control::none()).unwrap().samples
        };
        assert_eq!((taken(5, true), taken(16, true), taken(17, true)), (5.0, 16.0, 32.0));
        assert_eq!((taken(2, false), taken(20, false), taken(32, false)), (32.0, 32.0, 32.0));
        // 256: a pilot of 32, then 224 a pixel on average, each pixel's rounded up to 16s.
        let adaptive = taken(256, false);
        assert!((256.0..256.0 + 16.0).contains(&adaptive), "{adaptive}");
    }

    /// Resumed from its pilot pass and any bands, in any order, the reference is the bits of
    /// one uninterrupted run; the observer sees the pilot, then each band, covering every row.
    #[test]
    fn a_reference_resumed_from_some_bands_is_the_uninterrupted_reference() {
        let scene =
            Scene::parse(crate::scene::tests::MINIMAL, "test.toml", "test").unwrap().with_resolution(12, 40).unwrap();
        // On one thread: the bands do not depend on the threads.
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        for uniform in [false, true] {
            let opts = ReferenceOptions { spp: 32, uniform, seed: 3, pixel_center: false };
            let whole = render_reference(&scene, &opts, Control::none()).unwrap();
            let mut done = ReferenceDone::default();
            let mut rows = 0;
            let again = pool.install(|| {
                render_reference_from(&scene, &opts, Control::none(), ReferenceDone::default(), &mut |step| {
                    match step {
                        ReferenceStep::Pilot(p) => done.pilot = Some(p.clone()),
                        ReferenceStep::Band(b) => {
                            assert_eq!(b.rows.start, rows);
                            rows = b.rows.end;
                            done.bands.push(b.clone());
                        }
                    }
                    Ok(())
                })
            });
            let again = again.unwrap();
            assert!(again.mean == whole.mean && again.stderr == whole.stderr);
            assert_eq!((rows, done.bands.len(), done.pilot.is_some()), (40, 3, !uniform));
            // Bands 0 and 2 done (given out of order): the rest is rendered, nothing more.
            let kept =
                ReferenceDone { pilot: done.pilot.clone(), bands: vec![done.bands[2].clone(), done.bands[0].clone()] };
            let mut rendered = Vec::new();
            let resumed = render_reference_from(&scene, &opts, Control::none(), kept, &mut |step| {
                if let ReferenceStep::Band(b) = step {
                    rendered.push(b.rows.clone());
                }
                assert!(!matches!(step, ReferenceStep::Pilot(_)), "the pilot is done");
                Ok(())
            })
            .unwrap();
            assert!(resumed.mean == whole.mean && resumed.stderr == whole.stderr, "uniform {uniform}");
            assert_eq!(rendered, vec![16u32..32], "{rendered:?}");
            // Overlapping bands, or a band of another size, are refused.
            let overlapping =
                ReferenceDone { pilot: done.pilot.clone(), bands: vec![done.bands[1].clone(), done.bands[1].clone()] };
            assert!(render_reference_from(&scene, &opts, Control::none(), overlapping, &mut |_| Ok(())).is_err());
        }
    }

    /// Sample counts and pilots given back are what the library makes: counts of at least one
    /// sample (none was 0/0, a NaN pixel) and at most its cap (2^32 - 1 ran for 20 minutes),
    /// pilots finite and non-negative (a negative one gave its pixel no sample).
    #[test]
    fn counts_and_pilots_given_back_are_what_the_library_makes() {
        let scene =
            Scene::parse(crate::scene::tests::MINIMAL, "test.toml", "test").unwrap().with_resolution(4, 2).unwrap();
        let opts = ReferenceOptions { spp: 16, uniform: false, seed: 1, pixel_center: false };
        let pilot = reference_pilot_rows(&scene, &opts, 0..2, Control::none()).unwrap();
        let counts = reference_counts(&opts, &pilot.pixels, 4).unwrap();
        assert!(check_counts(&scene, &opts, &counts).is_ok());
        assert!(reference_rows(&scene, &opts, 0..1, Some(&counts), Control::none()).is_ok());
        for (pixel, count, says) in [
            (5, 0, "counts: pixel (x 1, y 1) has 0 samples"),
            (0, 1025, "counts: pixel (x 0, y 0) has 1025 samples; a pixel has between 1 and 1024"),
            (7, u32::MAX, "counts: pixel (x 3, y 1) has 4294967295 samples"),
        ] {
            let mut c = counts.clone();
            c[pixel] = count;
            let e = reference_rows(&scene, &opts, 0..1, Some(&c), Control::none()).unwrap_err();
            assert!(e.is_input() && e.to_string().starts_with(says), "{e}");
        }
        assert!(check_counts(&scene, &opts, &counts[1..]).unwrap_err().to_string().contains("7 sample counts"));
        for value in [-1.0, f32::NAN, f32::INFINITY] {
            let mut p = pilot.pixels.clone();
            p[6].y = value;
            let e = reference_counts(&opts, &p, 4).unwrap_err().to_string();
            assert!(e.starts_with("pilot: pixel (x 2, y 1) channel G is"), "{e}");
        }
    }

    /// Cancelled when the first row ends: on one thread no other row runs; on two, the other
    /// thread's row stops before its next pixel (it may have finished just before the flag).
    #[test]
    fn cancelling_stops_the_reference_after_the_rows_under_way() {
        let scene =
            Scene::parse(crate::scene::tests::MINIMAL, "test.toml", "test").unwrap().with_resolution(24, 16).unwrap();
        for uniform in [false, true] {
            let opts = ReferenceOptions { spp: 32, uniform, seed: 1, pixel_center: false };
            for threads in [1, 2] {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                let (cancel, rows) = (AtomicBool::new(false), AtomicUsize::new(0));
                let progress = || {
                    rows.fetch_add(1, Ordering::Relaxed);
                    cancel.store(true, Ordering::Relaxed);
                };
                let control = Control::new(&progress, &cancel);
                let e = pool.install(|| render_reference(&scene, &opts, control)).err().unwrap();
                assert!(matches!(e, Error::Cancelled) && !e.is_input());
                assert!(rows.into_inner() <= threads, "{threads} threads, uniform {uniform}");
            }
        }
    }
}
