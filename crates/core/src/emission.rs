//! Direct emission integrated over the pixel (docs/mathematics.md section 8.2).
//!
//! The emission `E` seen along a camera ray is discontinuous only where the ray crosses the
//! projected outline of a panel (its four edges, and the line where two panels cross each
//! other); elsewhere the same panel (or none) is first along every ray of a pixel and `E` varies
//! only through the transmittance, smoothly. So the pixels whose square an outline crosses, a
//! choice made from the geometry alone, integrate `E` with an `n x n` jittered grid of their
//! own; every other pixel averages `E` over the positions of its ray sets. Both are unbiased
//! estimates of the mean of `E` over the pixel, and pixels that no panel can cover pay nothing.

use crate::camera::Camera;
use crate::control::Control;
use crate::light::RectLight;
use crate::photon_plane::{Polygon, clip_segment};
use crate::pixel::{PanelFootprints, ray_set_position};
use crate::sampling::{rng_for, unit_f64};
use crate::scene::Scene;
use glam::{DVec2, DVec3, Vec3};
use rand::RngCore;

/// The side `n` of the jittered grid of an outline pixel (`n^2` samples): chosen by measurement
/// (docs/mathematics.md section 8.2).
pub const OUTLINE_GRID: u32 = 32;

/// The random stream of the outline pixels' jitter.
const OUTLINE_STREAM: u64 = 0xED_6E5;

/// Slack in pixels when marking the pixels an outline crosses, far above the rounding of the
/// projection (a pixel marked needlessly only costs samples).
const MARGIN: f64 = 1e-3;

/// Side of the jittered grid of points in the region one panel covers in a pixel (`n^2`
/// transmittances, which vary by about a thousandth across a pixel of the benchmark).
const SAMPLES_GRID: u32 = 4;

/// Below this fraction of a pixel, or of the panel's whole projection where that is smaller, a
/// panel's projection is taken not to meet the pixel (section 8.2): a bias of at most `1e-9 max
/// Le` times the smaller of the pixel and the projection (the panel behind it may be the
/// brighter), so that a panel projected into less than a billionth of a pixel keeps its
/// emission (a bright one lost all of it to a bound of a billionth of the pixel alone).
const TINY_AREA: f64 = 1e-9;

/// The direct emission of every pixel: the mean of `E` over the pixel (section 8.2), or `E` at
/// the pixel centre when `pixel_center`. `ray_sets` and `seed` fix the positions that pixels
/// without an outline average over (those of the render's ray sets).
pub fn direct_emission(scene: &Scene, seed: u64, ray_sets: u32, pixel_center: bool) -> Vec<Vec3> {
    emission_with_variance(scene, seed, ray_sets, pixel_center, OUTLINE_GRID, Control::none()).0
}

/// [`direct_emission`] with a `grid x grid` jittered grid in the pixels that need one.
pub fn direct_emission_with(scene: &Scene, seed: u64, ray_sets: u32, pixel_center: bool, grid: u32) -> Vec<Vec3> {
    emission_with_variance(scene, seed, ray_sets, pixel_center, grid, Control::none()).0
}

/// [`direct_emission`] and, per pixel, an estimate of its variance (docs/mathematics.md section
/// 10.3), from the differences of neighbouring strata: second differences along the lines of
/// each jittered grid, differences of consecutive pairs of the ray-set positions. 0 where the
/// value is exact (no panel, pixel centres). The variance in f64: a bright panel's square is
/// beyond f32's range where its value is not (radiance 1e22: 1e44), and it is added to the
/// spread's f64 variance before the square root of the error image.
pub fn direct_emission_and_variance(
    scene: &Scene,
    seed: u64,
    ray_sets: u32,
    pixel_center: bool,
) -> (Vec<Vec3>, Vec<DVec3>) {
    direct_emission_and_variance_in(scene, seed, ray_sets, pixel_center, Control::none())
}

/// [`direct_emission_and_variance`] with its rows, units of work, recorded on `control`'s
/// strand ([`crate::schedule`]).
pub fn direct_emission_and_variance_in(
    scene: &Scene,
    seed: u64,
    ray_sets: u32,
    pixel_center: bool,
    control: Control,
) -> (Vec<Vec3>, Vec<DVec3>) {
    emission_with_variance(scene, seed, ray_sets, pixel_center, OUTLINE_GRID, control)
}

fn emission_with_variance(
    scene: &Scene,
    seed: u64,
    ray_sets: u32,
    pixel_center: bool,
    grid: u32,
    control: Control,
) -> (Vec<Vec3>, Vec<DVec3>) {
    let cam = &scene.camera;
    let (w, h) = (cam.width, cam.height);
    let footprints = PanelFootprints::new(scene);
    let outline = if pixel_center { vec![false; (w * h) as usize] } else { outline_pixels(scene) };
    let projected = projected_panels(scene);
    let ray_sets = ray_sets.max(1);
    control.map_units_pair("emission", (w * h) as usize, w as usize, |p| {
        let p = p as u32;
        let (i, j) = (p % w, p / w);
        if !footprints.any_over(i, j) {
            return (Vec3::ZERO, DVec3::ZERO);
        }
        let lights = footprints.over(i, j);
        let at = |x: f64, y: f64| emission_at(scene, cam, x, y, lights.clone());
        let (x, y) = (i as f64, j as f64);
        if pixel_center {
            return (at(x + 0.5, y + 0.5).as_vec3(), DVec3::ZERO);
        }
        let mut jitter = Jitter { x, y, rng: rng_for(seed, OUTLINE_STREAM, p as u64) };
        let mean = match meeting(&projected, lights.clone(), i, j) {
            Meeting::None => Mean::pairs(),
            Meeting::One(l, region) => covered(scene, l, &region, &mut jitter),
            Meeting::Several if outline[p as usize] => {
                let mut m = Mean::grid(grid);
                jitter.grid(grid, |x, y| m.add(at(x, y)));
                m
            }
            // No outline crosses the pixel: the same panel is first along all its rays.
            Meeting::Several => {
                let mut m = Mean::pairs();
                for k in 0..ray_sets {
                    let (sx, sy) = ray_set_position(seed, p as u64, k);
                    m.add(at(x + sx, y + sy));
                }
                m
            }
        };
        (mean.value().as_vec3(), mean.variance())
    })
}

/// The mean of samples taken one per stratum, and its variance from the differences of
/// neighbouring strata (section 10.3): second differences along the lines of a grid, which a
/// linear trend across the pixel does not bias, or differences of consecutive pairs.
struct Mean {
    sum: DVec3,
    n: u32,
    /// Strata per line of the grid (the samples come line by line); 2 for pairs.
    line: u32,
    /// Samples so far in the current line, and the last two.
    in_line: u32,
    last: [DVec3; 2],
    /// Sum of the squared differences, each scaled to estimate one stratum's variance, and
    /// their count.
    squares: DVec3,
    terms: u32,
}

impl Mean {
    /// Samples of a grid, `line` strata per line.
    fn grid(line: u32) -> Self {
        Mean {
            sum: DVec3::ZERO,
            n: 0,
            line: line.max(2),
            in_line: 0,
            last: [DVec3::ZERO; 2],
            squares: DVec3::ZERO,
            terms: 0,
        }
    }

    /// Samples compared in consecutive pairs (strata with no line to follow).
    fn pairs() -> Self {
        Mean::grid(2)
    }

    fn add(&mut self, v: DVec3) {
        self.sum += v;
        self.n += 1;
        if self.line >= 3 && self.in_line >= 2 {
            // E (a - 2b + c)^2 = s_a^2 + 4 s_b^2 + s_c^2: six strata's worth.
            let d = self.last[0] - 2.0 * self.last[1] + v;
            self.squares += d * d / 6.0;
            self.terms += 1;
        } else if self.line == 2 && self.in_line == 1 {
            let d = self.last[1] - v;
            self.squares += d * d / 2.0;
            self.terms += 1;
        }
        self.last = [self.last[1], v];
        self.in_line = (self.in_line + 1) % self.line;
    }

    fn value(&self) -> DVec3 {
        if self.n == 0 { DVec3::ZERO } else { self.sum / self.n as f64 }
    }

    /// The mean stratum's variance over `n`: `sum of the strata's variances / n^2`.
    fn variance(&self) -> DVec3 {
        if self.terms == 0 { DVec3::ZERO } else { self.squares / self.terms as f64 / self.n as f64 }
    }

    fn scaled(mut self, by: DVec3) -> Self {
        self.sum *= by;
        self.last = self.last.map(|l| l * by);
        self.squares *= by * by;
        self
    }
}

/// Jittered samples over the pixel with corner `(x, y)`, from the pixel's own random stream.
struct Jitter {
    x: f64,
    y: f64,
    rng: rand_pcg::Pcg64Mcg,
}

impl Jitter {
    /// Calls `f` at one uniform point in each cell of an `n x n` grid over the pixel.
    fn grid(&mut self, n: u32, mut f: impl FnMut(f64, f64)) {
        let cell = 1.0 / n as f64;
        for a in 0..n {
            for b in 0..n {
                let (u, v) = (unit_f64(self.rng.next_u64()), unit_f64(self.rng.next_u64()));
                f(self.x + (a as f64 + u) * cell, self.y + (b as f64 + v) * cell);
            }
        }
    }
}

/// Which of the panels `lights` meet pixel `(i, j)` on the image.
enum Meeting {
    None,
    /// Exactly one, covering this region of the pixel (image coordinates, convex).
    One(usize, Box<Polygon<DVec2>>),
    /// Two or more, or one reaching behind the camera (whose projection is not a polygon).
    Several,
}

fn meeting(projected: &[Option<Polygon<DVec2>>], lights: impl Iterator<Item = usize>, i: u32, j: u32) -> Meeting {
    let mut found = Meeting::None;
    for l in lights {
        let Some(polygon) = &projected[l] else {
            return Meeting::Several;
        };
        let region = region_in_pixel(polygon, i, j);
        // `area` is at most 1: the smaller of the pixel and the projection.
        if area(&region) > TINY_AREA * area(polygon) {
            if !matches!(found, Meeting::None) {
                return Meeting::Several;
            }
            found = Meeting::One(l, Box::new(region));
        }
    }
    found
}

/// The emission over a pixel that only panel `l` meets, covering `region` of it (section 8.2):
/// `Le a mean Tr(s_k)`, with `a` the region's area (exact) and `s_k` points uniform in the
/// region, one per cell of a jittered grid mapped onto it ([`point_in_region`]). Every point of
/// the region sees the panel, so no term jumps at its outline: only the transmittance's
/// variation across the region is sampled. Never negative.
fn covered(scene: &Scene, l: usize, region: &Polygon<DVec2>, jitter: &mut Jitter) -> Mean {
    let (cam, light) = (&scene.camera, &scene.lights[l]);
    let o = cam.position;
    // The camera sees the panel's back (black) or its front, the same for every ray.
    let depth = (light.corner - o).dot(light.n);
    if !(depth < 0.0) {
        return Mean::pairs();
    }
    let medium = &scene.medium;
    let (x0, y0) = (jitter.x, jitter.y);
    let mut mean = Mean::grid(SAMPLES_GRID);
    jitter.grid(SAMPLES_GRID, |x, y| {
        let s = point_in_region(region, x - x0, y - y0);
        let we = cam.direction(s.x, s.y).normalize();
        // On the panel's plane (inside the panel but for rounding: the region is its image).
        let t = (depth / we.dot(light.n)).max(0.0);
        mean.add(medium.transmittance(medium.length_inside(o, o + t * we)));
    });
    mean.scaled(light.radiance * area(region))
}

/// The point of the convex `region` that `(u, v)` in `[0, 1)^2` maps to: uniform in the region
/// when `(u, v)` is uniform. `u` chooses a triangle of the fan from the first vertex by area and
/// is stretched back to `[0, 1)` within it; the triangle's point is the square-root map
/// (Shirley and Chiu): `(1 - sqrt r) A + sqrt r (1 - v) B + sqrt r v C`.
fn point_in_region(region: &Polygon<DVec2>, u: f64, v: f64) -> DVec2 {
    let p = region.points();
    let fan = |k: usize| 0.5 * (p[k] - p[0]).perp_dot(p[k + 1] - p[0]).abs();
    let last = p.len() - 2;
    let mut target = u * (1..=last).map(fan).sum::<f64>();
    let mut k = 1;
    while k < last && target >= fan(k) {
        target -= fan(k);
        k += 1;
    }
    let r = (target / fan(k).max(f64::MIN_POSITIVE)).clamp(0.0, 1.0).sqrt();
    p[0] * (1.0 - r) + p[k] * (r * (1.0 - v)) + p[k + 1] * (r * v)
}

/// Each panel's projection on the image when it lies wholly in front of the camera (a convex
/// quadrilateral, the image of the rectangle), else None.
fn projected_panels(scene: &Scene) -> Vec<Option<Polygon<DVec2>>> {
    let cam = &scene.camera;
    let near = 1e-6 * scene.medium.diagonal();
    scene
        .lights
        .iter()
        .map(|l| {
            let corners = l.corners().map(|c| cam.to_camera(c));
            corners
                .iter()
                .all(|c| c.z > near)
                .then(|| Polygon::from_slice(&corners.map(|c| DVec2::from(cam.project(c)))))
        })
        .collect()
}

/// The part of `polygon` (convex, image coordinates) inside the square of pixel `(i, j)`.
fn region_in_pixel(polygon: &Polygon<DVec2>, i: u32, j: u32) -> Polygon<DVec2> {
    let (x, y) = (i as f64, j as f64);
    let lerp = |p: DVec2, q: DVec2, s: f64| p + (q - p) * s;
    let (mut region, mut scratch) = (*polygon, Polygon::empty());
    region.clip_in_place(&mut scratch, |v| v.x - x, lerp);
    region.clip_in_place(&mut scratch, |v| x + 1.0 - v.x, lerp);
    region.clip_in_place(&mut scratch, |v| v.y - y, lerp);
    region.clip_in_place(&mut scratch, |v| y + 1.0 - v.y, lerp);
    region
}

/// The area of a region of a pixel (at most 1 but for rounding; 0 for fewer than 3 vertices).
/// The shoelace sum is taken about the first vertex: about the image's origin its terms are the
/// size of the coordinates and cancel, so that a region of 1e-10 of a pixel at x = 3.5 lost
/// 2e-5 of its area.
fn area(region: &Polygon<DVec2>) -> f64 {
    let pts = region.points();
    let Some(&first) = pts.first() else {
        return 0.0;
    };
    let twice: f64 = (1..pts.len().saturating_sub(1)).map(|k| (pts[k] - first).perp_dot(pts[k + 1] - first)).sum();
    (0.5 * twice.abs()).min(1.0)
}

/// The emission `E` along the camera ray through image point `(x, y)`, testing the panels
/// `lights` (those that can cover the pixel).
fn emission_at(scene: &Scene, cam: &Camera, x: f64, y: f64, lights: impl IntoIterator<Item = usize>) -> DVec3 {
    scene.first_surface(cam.position, cam.direction(x, y).normalize(), lights).1
}

/// Which pixels an outline crosses (one flag per pixel, row after row): the squares met by a
/// projected panel edge or by the projected line where two panels cross, each clipped to the
/// part in front of the camera.
pub fn outline_pixels(scene: &Scene) -> Vec<bool> {
    let cam = &scene.camera;
    let mut marked = vec![false; (cam.width * cam.height) as usize];
    let mut segments = Vec::new();
    for (k, l) in scene.lights.iter().enumerate() {
        let c = l.corners();
        segments.extend((0..4).map(|e| (c[e], c[(e + 1) % 4])));
        for other in &scene.lights[k + 1..] {
            segments.extend(crossing_segment(l, other));
        }
    }
    let near = 1e-6 * scene.medium.diagonal();
    for (a, b) in segments {
        if let Some((p, q)) = project_segment(cam, a, b, near) {
            mark_segment(&mut marked, cam.width, cam.height, p, q);
        }
    }
    marked
}

/// The segment where panels `a` and `b` cross, if they do (not when coplanar: then their edges
/// are the outline).
fn crossing_segment(a: &RectLight, b: &RectLight) -> Option<(DVec3, DVec3)> {
    let corners = a.corners();
    let d = corners.map(|c| (c - b.corner).dot(b.n));
    // Where a's boundary meets b's plane.
    let mut points = Vec::with_capacity(4);
    for e in 0..4 {
        let (d0, d1) = (d[e], d[(e + 1) % 4]);
        if d0 == 0.0 {
            points.push(corners[e]);
        } else if (d0 < 0.0) != (d1 < 0.0) && d1 != 0.0 {
            points.push(corners[e] + (corners[(e + 1) % 4] - corners[e]) * (d0 / (d0 - d1)));
        }
    }
    // The chord of a across b's plane: its two farthest points.
    let mut best: Option<(DVec3, DVec3)> = None;
    for (i, &p) in points.iter().enumerate() {
        for &q in &points[i + 1..] {
            if best.is_none_or(|(s, t)| (q - p).length_squared() > (t - s).length_squared()) {
                best = Some((p, q));
            }
        }
    }
    let (p, q) = best?;
    // Clipped to b, in b's local coordinates.
    let local = |y: DVec3| DVec2::from(b.local(y));
    let (s, t) = clip_segment(local(p), local(q), DVec2::ZERO, DVec2::new(b.width, b.height))?;
    let (ls, lt) = (local(p), local(q));
    let along = |u: DVec2| {
        let len = (lt - ls).length_squared();
        if len > 0.0 { (u - ls).dot(lt - ls) / len } else { 0.0 }
    };
    Some((p + (q - p) * along(s), p + (q - p) * along(t)))
}

/// The segment `a`-`b` (world) on the image: clipped to the camera-space depths above `near`,
/// projected, and clipped to the image grown by a pixel.
fn project_segment(cam: &Camera, a: DVec3, b: DVec3, near: f64) -> Option<(DVec2, DVec2)> {
    let (mut a, mut b) = (cam.to_camera(a), cam.to_camera(b));
    if !(a.z > near) && !(b.z > near) {
        return None;
    }
    if !(a.z > near) {
        a = b + (a - b) * ((b.z - near) / (b.z - a.z));
    } else if !(b.z > near) {
        b = a + (b - a) * ((a.z - near) / (a.z - b.z));
    }
    let (p, q) = (DVec2::from(cam.project(a)), DVec2::from(cam.project(b)));
    let grown = DVec2::new(cam.width as f64 + 1.0, cam.height as f64 + 1.0);
    clip_segment(p, q, DVec2::splat(-1.0), grown)
}

/// Marks every pixel whose square (grown by [`MARGIN`]) the image segment `p`-`q` meets.
fn mark_segment(marked: &mut [bool], width: u32, height: u32, p: DVec2, q: DVec2) {
    let d = q - p;
    let row_of = |y: f64| y.floor().clamp(-1.0, height as f64) as i64;
    let (first, last) = (row_of(p.y.min(q.y) - MARGIN).max(0), row_of(p.y.max(q.y) + MARGIN).min(height as i64 - 1));
    for j in first..=last {
        // The part of the segment within the row's strip.
        let (mut s0, mut s1) = (0.0f64, 1.0f64);
        if d.y != 0.0 {
            let (a, b) = ((j as f64 - MARGIN - p.y) / d.y, (j as f64 + 1.0 + MARGIN - p.y) / d.y);
            s0 = s0.max(a.min(b));
            s1 = s1.min(a.max(b));
        }
        if s0 > s1 {
            continue;
        }
        let (x0, x1) = (p.x + d.x * s0, p.x + d.x * s1);
        let col_of = |x: f64| x.floor().clamp(-1.0, width as f64) as i64;
        let (a, b) = (col_of(x0.min(x1) - MARGIN).max(0), col_of(x0.max(x1) + MARGIN).min(width as i64 - 1));
        for i in a..=b {
            marked[j as usize * width as usize + i as usize] = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dense medium (sigma_s 30) seen from below its floor, the panel's transmittance varying
    /// by orders of magnitude across a pixel (found by tests/fuzz_scene.rs: a control variate
    /// with the centre's transmittance gave -1.7e-8): no pixel is negative, and each pixel's mean
    /// over 64 seeds matches a 256 x 256 midpoint grid of `E` over the pixel within 4 standard
    /// errors (plus 1e-3 relative for the grid).
    #[test]
    fn dense_media_give_non_negative_unbiased_pixels() {
        let text = "[camera]\nposition = [0, -1.588918562444176, 0]\nlook_at = [5, 5, -2.338179085477276]\n\
                    up = [0.0, 1.0, 0.0]\nvfov_deg = 60.0\nresolution = [8, 6]\n[medium]\nmin = [-5.0, 0.0, -5.0]\n\
                    max = [5.0, 6.0, 5.0]\nsigma_s = 30\nsigma_a = 0\n[[light]]\n\
                    corner = [3.2245919206916227, 0.4214593390850432, -0.5359479761636576]\n\
                    edge_u = [-0.12802124252746314, -0.2695907150746525, 0.38499172439274865]\n\
                    edge_v = [-0.1593233554831906, 0.7598775069305682, 0.479124965142829]\nradiance = 91.88137457275919\n";
        let scene = Scene::parse(text, "dense.toml", "dense").unwrap();
        let cam = &scene.camera;
        let seeds = 64;
        let runs: Vec<Vec<Vec3>> = (0..seeds).map(|seed| direct_emission(&scene, seed, 16, false)).collect();
        let mut lit = 0;
        for p in 0..(cam.width * cam.height) as usize {
            let (x, y) = ((p as u32 % cam.width) as f64, (p as u32 / cam.width) as f64);
            let n = 256;
            let mut grid = 0.0;
            for a in 0..n {
                for b in 0..n {
                    let (sx, sy) = ((a as f64 + 0.5) / n as f64, (b as f64 + 0.5) / n as f64);
                    grid += emission_at(&scene, cam, x + sx, y + sy, 0..1).x;
                }
            }
            grid /= (n * n) as f64;
            let values: Vec<f64> = runs.iter().map(|r| r[p].x as f64).collect();
            assert!(values.iter().all(|&v| v >= 0.0), "pixel {p}: {values:?}");
            let mean = values.iter().sum::<f64>() / seeds as f64;
            let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (seeds - 1) as f64;
            let se = (var / seeds as f64).sqrt();
            assert!((mean - grid).abs() <= 4.0 * se + 1e-3 * grid + 1e-12, "pixel {p}: {mean} +- {se} against {grid}");
            lit += (grid > 0.0) as usize;
        }
        assert!(lit > 0, "no pixel sees the panel");
    }

    /// Points mapped into a region are inside it, and uniform: their mean is its centroid.
    #[test]
    fn points_in_a_region_are_uniform() {
        let square = Polygon::from_slice(&[
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(0.0, 1.0),
        ]);
        // A pentagon cut from the square: corner (1, 1) cut off along x + y = 1.5.
        let region = square.clip(|v| 1.5 - v.x - v.y, |p, q, s| p + (q - p) * s);
        assert_eq!(region.len, 5);
        let pts = region.points();
        let a = area(&region);
        assert!((a - 0.875).abs() < 1e-12);
        // Centroid by the shoelace formula.
        let mut c = DVec2::ZERO;
        for k in 0..pts.len() {
            let (p, q) = (pts[k], pts[(k + 1) % pts.len()]);
            c += (p + q) * p.perp_dot(q);
        }
        c /= 6.0 * a;
        // Uniform (u, v) from a fixed seed: the mean within 4 standard errors of the centroid.
        let mut rng = rng_for(11, 0, 0);
        let n = 1_000_000;
        let (mut sum, mut squares) = (DVec2::ZERO, DVec2::ZERO);
        for _ in 0..n {
            let (u, v) = (unit_f64(rng.next_u64()), unit_f64(rng.next_u64()));
            let s = point_in_region(&region, u, v);
            assert!(s.x >= -1e-12 && s.y >= -1e-12 && s.x + s.y <= 1.5 + 1e-12 && s.x <= 1.0 + 1e-12, "{s}");
            (sum, squares) = (sum + s, squares + s * s);
        }
        let mean = sum / n as f64;
        let se = ((squares / n as f64 - mean * mean) / n as f64).powf(0.5);
        assert!(((mean - c).abs() - 4.0 * se).max_element() <= 0.0, "{mean} +- {se} against the centroid {c}");
    }

    #[test]
    fn a_segment_marks_the_pixels_it_crosses() {
        let (w, h) = (10u32, 6u32);
        let mut m = vec![false; 60];
        mark_segment(&mut m, w, h, DVec2::new(0.5, 0.5), DVec2::new(4.5, 2.5));
        let marked: Vec<(usize, usize)> = (0..60).filter(|&k| m[k]).map(|k| (k % 10, k / 10)).collect();
        // The line y = 0.5 + (x - 0.5) / 2 crosses (0,0), (1,0), (1,1) .. ; (2,1) it meets at x
        // = 2.5, y = 1.5 on the corner of four squares, each within the margin.
        for want in [(0, 0), (1, 0), (1, 1), (2, 1), (3, 1), (3, 2), (4, 2)] {
            assert!(marked.contains(&want), "{want:?} missing from {marked:?}");
        }
        assert!(!marked.contains(&(5, 2)) && !marked.contains(&(0, 1)) && !marked.contains(&(4, 0)));
        // Off the image: nothing, and no panic.
        let mut m = vec![false; 60];
        mark_segment(&mut m, w, h, DVec2::new(-5.0, 20.0), DVec2::new(-1.0, 30.0));
        assert!(m.iter().all(|&x| !x));
    }

    #[test]
    fn crossing_panels_meet_in_a_segment() {
        let a = RectLight::new("a", DVec3::new(-1.0, 0.0, -1.0), DVec3::X * 2.0, DVec3::Z * 2.0, DVec3::ONE);
        let b = RectLight::new("b", DVec3::new(0.0, -1.0, -0.5), DVec3::Y * 2.0, DVec3::Z * 4.0, DVec3::ONE);
        let (p, q) = crossing_segment(&a, &b).unwrap();
        // x = 0, y = 0, z over a's [-1, 1] within b's [-0.5, 3.5].
        let (lo, hi) = if p.z < q.z { (p, q) } else { (q, p) };
        assert!((lo - DVec3::new(0.0, 0.0, -0.5)).length() < 1e-12, "{lo}");
        assert!((hi - DVec3::new(0.0, 0.0, 1.0)).length() < 1e-12, "{hi}");
        let far = RectLight::new("c", DVec3::new(5.0, -1.0, -0.5), DVec3::Y * 2.0, DVec3::Z * 4.0, DVec3::ONE);
        assert!(crossing_segment(&a, &far).is_none());
    }
}
