//! Deterministic quadrature: the ground truth that the estimators are checked against.
//!
//! [`integrate`] is adaptive Gauss-Kronrod (7/15 points). [`single_scattering`] evaluates the
//! scattering integral of docs/mathematics.md section 1 for one camera ray by nested adaptive quadrature over
//! the camera distance and both light coordinates. It uses only the scene description (lights,
//! medium); nothing of the photon planes, their weights or the reference renderer.

use crate::scene::Scene;
use glam::DVec3;

/// The result of a quadrature: value and estimated absolute error.
#[derive(Clone, Copy, Debug)]
pub struct Quadrature {
    pub value: f64,
    pub error: f64,
}

#[allow(clippy::excessive_precision)] // the published 33-digit values, verbatim
const XGK: [f64; 8] = [
    0.991455371120812639206854697526329,
    0.949107912342758524526189684047851,
    0.864864423359769072789712788640926,
    0.741531185599394439863864773280788,
    0.586087235467691130294144845693013,
    0.405845151377397166906606412076961,
    0.207784955007898467600689403773245,
    0.000000000000000000000000000000000,
];
#[allow(clippy::excessive_precision)]
const WGK: [f64; 8] = [
    0.022935322010529224963732008058970,
    0.063092092629978553290700663189204,
    0.104790010322250183839876322541518,
    0.140653259715525918745189590510238,
    0.169004726639267902826583426598550,
    0.190350578064785409913256402421014,
    0.204432940075298892414161999234649,
    0.209482141084727828012999174891714,
];
#[allow(clippy::excessive_precision)]
const WG: [f64; 4] = [
    0.129484966168869693270611432679082,
    0.279705391489276667901467771423780,
    0.381830050505118944950369775488975,
    0.417959183673469387755102040816327,
];

/// `N` integrands' Gauss-Kronrod estimates over `[a, b]` from the same 15 nodes: values, and
/// absolute errors from the embedded 7-point Gauss rule.
fn gauss_kronrod<const N: usize>(f: &mut impl FnMut(f64) -> [f64; N], a: f64, b: f64) -> ([f64; N], [f64; N]) {
    let (c, h) = (0.5 * (a + b), 0.5 * (b - a));
    let fc = f(c);
    let (mut kronrod, mut gauss) = (fc.map(|v| v * WGK[7]), fc.map(|v| v * WG[3]));
    for j in 0..7 {
        let x = h * XGK[j];
        let (left, right) = (f(c - x), f(c + x));
        for k in 0..N {
            let pair = left[k] + right[k];
            kronrod[k] += WGK[j] * pair;
            if j % 2 == 1 {
                gauss[k] += WG[j / 2] * pair;
            }
        }
    }
    (kronrod.map(|v| v * h), std::array::from_fn(|k| ((kronrod[k] - gauss[k]) * h).abs()))
}

/// Adaptive Gauss-Kronrod quadrature of `f` over `[a, b]` to `max(rel_tol |I|, abs_tol)`.
/// The interval with the largest error is bisected until the total error is small enough or
/// 4000 intervals are in use (then the best estimate is returned with its error).
pub fn integrate(mut f: impl FnMut(f64) -> f64, a: f64, b: f64, rel_tol: f64, abs_tol: f64) -> Quadrature {
    let [q] = integrate_each(|x| [f(x)], a, b, rel_tol, abs_tol);
    q
}

/// [`integrate`] of `N` integrands at once, on the same intervals: each to its own
/// `max(rel_tol |I_k|, abs_tol)`, the interval bisected next the one whose error is the largest
/// share of its integrand's tolerance. Integrands that share their costly part (a ray's three
/// channels share the geometry and the shadows; only the extinction differs) evaluate it once
/// per node.
pub fn integrate_each<const N: usize>(
    mut f: impl FnMut(f64) -> [f64; N],
    a: f64,
    b: f64,
    rel_tol: f64,
    abs_tol: f64,
) -> [Quadrature; N] {
    if a == b {
        return [Quadrature { value: 0.0, error: 0.0 }; N];
    }
    // Start from a few pieces, so that one lucky estimate cannot end the work.
    const START: usize = 8;
    let mut pieces: Vec<_> = (0..START)
        .map(|k| {
            let (lo, hi) = (a + (b - a) * k as f64 / START as f64, a + (b - a) * (k + 1) as f64 / START as f64);
            (lo, hi, gauss_kronrod(&mut f, lo, hi))
        })
        .collect();
    loop {
        let total = |k: usize| Quadrature {
            value: pieces.iter().map(|p| p.2.0[k]).sum(),
            error: pieces.iter().map(|p| p.2.1[k]).sum(),
        };
        let totals: [Quadrature; N] = std::array::from_fn(total);
        // Each integrand's tolerance; a zero one (a zero integral, no absolute tolerance) as the
        // smallest positive, so that its errors still rank.
        let tolerance = totals.map(|q| (rel_tol * q.value.abs()).max(abs_tol));
        let share =
            |errors: &[f64; N]| (0..N).map(|k| errors[k] / tolerance[k].max(f64::MIN_POSITIVE)).fold(0.0, f64::max);
        let worst =
            pieces.iter().enumerate().max_by(|x, y| share(&x.1.2.1).total_cmp(&share(&y.1.2.1))).map(|(i, _)| i);
        let done = (0..N).all(|k| totals[k].error <= tolerance[k]) || pieces.len() >= 4000;
        let Some(worst) = worst.filter(|_| !done) else {
            return totals;
        };
        let (lo, hi, _) = pieces.swap_remove(worst);
        let mid = 0.5 * (lo + hi);
        if !(mid > lo && mid < hi) {
            // The interval cannot be split further in floating point.
            return totals;
        }
        pieces.push((lo, mid, gauss_kronrod(&mut f, lo, mid)));
        pieces.push((mid, hi, gauss_kronrod(&mut f, mid, hi)));
    }
}

/// [`integrate`] over `[a, b]` split at `breaks` (QUADPACK's QAGP): a kink of the integrand that
/// falls between an interval's end and its outermost node is invisible to any Gauss-Kronrod
/// error estimate, so the places where the integrand may have kinks are given.
pub fn integrate_with_breaks(
    mut f: impl FnMut(f64) -> f64,
    a: f64,
    b: f64,
    breaks: &[f64],
    rel_tol: f64,
    abs_tol: f64,
) -> Quadrature {
    let mut cuts: Vec<f64> = breaks.iter().copied().filter(|x| *x > a && *x < b).collect();
    cuts.push(a);
    cuts.push(b);
    cuts.sort_by(f64::total_cmp);
    let mut total = Quadrature { value: 0.0, error: 0.0 };
    for w in cuts.windows(2) {
        let q = integrate(&mut f, w[0], w[1], rel_tol, abs_tol / (cuts.len() - 1) as f64);
        total.value += q.value;
        total.error += q.error;
    }
    total
}

/// The chord width of a `w x h` rectangle through `(p, q)` along angle `beta`, by clipping the
/// line with each pair of edge lines: a computation independent of [`crate::light::chord_extent`].
pub fn chord_width_by_clipping(w: f64, h: f64, p: f64, q: f64, beta: f64) -> f64 {
    let (c, s) = (beta.cos(), beta.sin());
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for (origin, dir, limit) in [(p, c, w), (q, s, h)] {
        if dir.abs() < 1e-300 {
            continue;
        }
        let (t0, t1) = ((0.0 - origin) / dir, (limit - origin) / dir);
        lo = lo.max(t0.min(t1));
        hi = hi.min(t0.max(t1));
    }
    (hi - lo).max(0.0)
}

/// The single-scattering radiance (docs/mathematics.md section 1, the integral term) along the ray `o + t we`
/// (unit `we`), by nested adaptive quadrature to about `rel_tol`: light by light, over the
/// camera distance and both light coordinates, the three channels on the same nodes (each to
/// its own tolerance), so that the geometry and the shadows are evaluated once for all three.
pub fn single_scattering(scene: &Scene, o: DVec3, we: DVec3, rel_tol: f64) -> DVec3 {
    let Some((t0, t1)) = scene.camera_segment(o, we).0 else {
        return DVec3::ZERO;
    };
    let extinction = Extinction::of(scene);
    let mut out = DVec3::ZERO;
    for (li, light) in scene.lights.iter().enumerate() {
        let outer = |t: f64| -> [f64; 3] {
            let at = LightAt { scene, extinction, light: li, x: o + t * we, we };
            let (tr, value) = (extinction.transmittance(t - t0), at.integral(rel_tol, Shadows::Culled));
            std::array::from_fn(|c| tr[c] * value[c])
        };
        let values = integrate_each(outer, t0, t1, rel_tol, 0.0);
        for (c, q) in values.iter().enumerate() {
            out[c] += q.value * scene.medium.sigma_s[c] * light.radiance[c];
        }
    }
    out
}

/// The medium's extinction channel by channel, read once for a ray's integrals.
#[derive(Clone, Copy, Debug)]
struct Extinction {
    sigma_t: [f64; 3],
    grey: bool,
}

impl Extinction {
    fn of(scene: &Scene) -> Self {
        let sigma_t = scene.medium.sigma_t().to_array();
        Extinction { sigma_t, grey: sigma_t[0] == sigma_t[1] && sigma_t[1] == sigma_t[2] }
    }

    /// `exp(-sigma_t s)` channel by channel; one exponential where the medium is grey.
    fn transmittance(self, s: f64) -> [f64; 3] {
        if self.grey { [(-self.sigma_t[0] * s).exp(); 3] } else { self.sigma_t.map(|st| (-st * s).exp()) }
    }
}

/// Which panels [`LightAt::integral`] tests for the light's shadows at its point.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Shadows {
    /// Those that may block the light's way to the point ([`possible_blockers`]).
    Culled,
    /// Every other panel (the same values: tests compare the two).
    #[cfg_attr(not(test), allow(dead_code))]
    All,
}

/// One light seen from a point `x` of a camera ray of direction `we`.
struct LightAt<'a> {
    scene: &'a Scene,
    extinction: Extinction,
    light: usize,
    x: DVec3,
    we: DVec3,
}

impl LightAt<'_> {
    /// The light's in-scattered radiance at `x` per unit radiance and scattering coefficient,
    /// channel by channel: the integral over the light of transmittance, the cosine at the
    /// light over the squared distance, visibility through the other panels, and the phase
    /// function, by nested adaptive quadrature over its two coordinates.
    fn integral(&self, rel_tol: f64, shadows: Shadows) -> [f64; 3] {
        let &LightAt { scene, extinction, light: li, x, we } = self;
        let light = &scene.lights[li];
        let others = match shadows {
            Shadows::Culled => possible_blockers(scene, li, x),
            Shadows::All => (0..scene.lights.len()).filter(|&k| k != li).collect(),
        };
        let per_p = |p: f64| {
            let f = |q: f64| {
                let y = light.point(p, q);
                let to_x = x - y;
                let d2 = to_x.length_squared();
                let d = d2.sqrt();
                let cos = light.n.dot(to_x) / d;
                if !(cos > 0.0) || d == 0.0 || scene.blocked_by(y, x, others.iter().copied()) {
                    return [0.0; 3];
                }
                // The phase function at the scattering angle between the light's travel (y to
                // x) and the way to the eye (-we): section 1.1.
                let phase = scene.medium.phase(to_x / d, -we);
                extinction.transmittance(d).map(|tr| tr * cos / d2 * phase)
            };
            integrate_each(f, 0.0, light.height, rel_tol * 0.1, 0.0).map(|q| q.value)
        };
        integrate_each(per_p, 0.0, light.width, rel_tol * 0.3, 0.0).map(|q| q.value)
    }
}

/// The panels other than light `li` that may block its light on the way to `x`. Every segment
/// from a point of the light to `x` lies in the pyramid over the light with apex `x`, so a panel
/// (a rectangle, convex) all of whose corners lie outside one face of the pyramid meets no such
/// segment. Outside by a margin of a billionth of the lengths involved, so that rounding keeps
/// every panel that [`Scene::blocked`]'s crossing test could find; a face that `x`'s place makes
/// ill-defined (`x` in the light's plane, or on an edge's line) is not used. Found once for each
/// point of the ray, for the hundreds of points of the light that its integral visits there.
fn possible_blockers(scene: &Scene, li: usize, x: DVec3) -> Vec<usize> {
    let light = &scene.lights[li];
    let corners = light.corners();
    let centre = 0.5 * (corners[0] + corners[2]);
    let scale = (x - centre).length() + light.width + light.height;
    // Each face as a point of it and its outward unit normal.
    let mut faces: Vec<(DVec3, DVec3)> = Vec::with_capacity(5);
    let height = light.n.dot(x - centre);
    if height.abs() > 1e-9 * scale {
        // The light's own plane: outward is away from x.
        faces.push((centre, -light.n * height.signum()));
    }
    for e in 0..4 {
        let (a, b) = (corners[e], corners[(e + 1) % 4]);
        let normal = (b - a).cross(x - a);
        let inward = normal.dot(centre - a);
        // The face's normal from a cross product of sines near 0 is rounding, not a direction.
        if normal.length() > 1e-6 * (b - a).length() * (x - a).length() && inward != 0.0 {
            faces.push((a, -normal.normalize() * inward.signum()));
        }
    }
    (0..scene.lights.len())
        .filter(|&k| k != li)
        .filter(|&k| {
            let panel = &scene.lights[k];
            let others = panel.corners();
            let margin = 1e-9 * (scale + (others[0] - centre).length() + panel.width + panel.height);
            !faces.iter().any(|&(point, out)| others.iter().all(|&c| out.dot(c - point) > margin))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integrates_polynomials_exactly_and_kinks_adaptively() {
        let q = integrate(|x| x.powi(5) - 2.0 * x, -1.0, 2.0, 1e-14, 0.0);
        assert!((q.value - (64.0 / 6.0 - 1.0 / 6.0 - 3.0)).abs() < 1e-12);
        let q = integrate(|x: f64| (x - 0.3).abs(), 0.0, 1.0, 1e-12, 0.0);
        assert!((q.value - (0.045 + 0.245)).abs() < 1e-11, "{}", q.value);
        let q = integrate(|x: f64| 1.0 / x.sqrt(), 0.0, 1.0, 1e-10, 0.0);
        assert!((q.value - 2.0).abs() < 1e-8, "{}", q.value);
    }

    /// Every scene of media_scenes, loaded.
    fn all_scenes() -> Vec<(String, Scene)> {
        let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../../media_scenes");
        let mut files: Vec<_> = std::fs::read_dir(root).unwrap().map(|e| e.unwrap().path()).collect();
        files.extend(std::fs::read_dir(format!("{root}/hard")).unwrap().map(|e| e.unwrap().path()));
        files.retain(|p| p.extension().is_some_and(|e| e == "toml"));
        files.sort();
        assert!(files.len() >= 10, "the scenes of media_scenes: {files:?}");
        files.iter().map(|f| (f.display().to_string(), Scene::load(f).unwrap())).collect()
    }

    /// [`possible_blockers`] keeps every panel that blocks a way from a light to a point: on
    /// every scene of media_scenes, points in the fog box, in each light's plane and on its
    /// edges' lines (where faces of the pyramid are left out), and near them, each with 24
    /// points of each light, every other panel tested by [`Scene::blocked`]'s own test. It
    /// leaves panels out too, or it would save nothing.
    #[test]
    fn every_panel_that_blocks_a_way_to_a_light_is_kept() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(11);
        let (mut blocked, mut left_out, mut culled, mut tested) = (0usize, 0usize, 0usize, 0usize);
        for (name, scene) in all_scenes() {
            let m = &scene.medium;
            for li in 0..scene.lights.len() {
                let light = &scene.lights[li];
                let corners = light.corners();
                for i in 0..240 {
                    let mut x =
                        m.min + DVec3::from_array(std::array::from_fn(|_| rng.random::<f64>())) * (m.max - m.min);
                    if i % 4 == 1 {
                        // In the light's plane, or just off it.
                        let off = [0.0, 1e-12, -1e-7][i / 4 % 3] * m.diagonal();
                        x -= (light.n.dot(x - light.corner) - off) * light.n;
                    } else if i % 4 == 2 {
                        // On an edge's line, or near it.
                        let e = i / 4 % 4;
                        let (a, b) = (corners[e], corners[(e + 1) % 4]);
                        let off = [0.0, 1e-10][i / 16 % 2] * m.diagonal();
                        x = a + (rng.random::<f64>() * 3.0 - 1.0) * (b - a) + off * light.n;
                    }
                    let kept = possible_blockers(&scene, li, x);
                    tested += scene.lights.len() - 1;
                    culled += scene.lights.len() - 1 - kept.len();
                    for _ in 0..24 {
                        let y = light.point(rng.random::<f64>() * light.width, rng.random::<f64>() * light.height);
                        for k in (0..scene.lights.len()).filter(|&k| k != li) {
                            if scene.blocked_by(y, x, std::iter::once(k)) {
                                blocked += 1;
                                left_out += !kept.contains(&k) as usize;
                            }
                        }
                    }
                }
            }
            println!("{name}: {blocked} blocked ways so far, {left_out} by a panel left out");
        }
        println!("{culled} of {tested} panels left out");
        assert_eq!(left_out, 0, "a panel that blocks a way to a light is left out");
        assert!(blocked > 1000, "{blocked} blocked ways: too few to test");
        assert!(culled > tested / 4, "{culled} of {tested} panels left out: the culling saves little");
    }

    /// A light's integral at a point with the panels culled is the one with every panel, bit
    /// for bit: at 40 points of the fog box of each scene where panels shadow lights (the
    /// benchmark at 10,000 times its size among them), for every light, to 1e-4.
    #[test]
    fn culled_shadows_change_no_bit() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(12);
        let shadowed = ["six_lights.toml", "two_lights_one_blocker.toml", "scaled_1e4.toml"];
        let mut lit = 0;
        for (name, scene) in all_scenes().into_iter().filter(|(n, _)| shadowed.iter().any(|s| n.ends_with(s))) {
            let m = &scene.medium;
            for _ in 0..40 {
                let x = m.min + DVec3::from_array(std::array::from_fn(|_| rng.random::<f64>())) * (m.max - m.min);
                let we = (scene.camera.position - x).normalize();
                for light in 0..scene.lights.len() {
                    let at = LightAt { scene: &scene, extinction: Extinction::of(&scene), light, x, we };
                    let (culled, all) = (at.integral(1e-4, Shadows::Culled), at.integral(1e-4, Shadows::All));
                    assert_eq!(
                        culled.map(f64::to_bits),
                        all.map(f64::to_bits),
                        "{name}, light {light} at {x}: {culled:?} against {all:?}"
                    );
                    lit += (culled[0] > 0.0) as usize;
                }
            }
        }
        assert!(lit > 100, "{lit} lit points");
    }

    /// Three channels on the same nodes, each to its own tolerance, agree with each channel
    /// integrated alone (every integrand at 1e-9 here).
    #[test]
    fn channels_on_the_same_nodes_agree_with_each_alone() {
        let f = |x: f64| [(-3.0 * x).exp(), (x - 0.3).abs(), 1.0 / (1e-3 + x * x)];
        let each = integrate_each(f, 0.0, 2.0, 1e-9, 0.0);
        for (k, q) in each.iter().enumerate() {
            let alone = integrate(|x| f(x)[k], 0.0, 2.0, 1e-9, 0.0);
            assert!((q.value - alone.value).abs() <= 2e-9 * alone.value, "{k}: {} against {}", q.value, alone.value);
            assert!(q.error <= 1e-9 * q.value.abs(), "{k}: error {}", q.error);
        }
    }

    /// The Henyey-Greenstein phase function integrates to 1 over the sphere, to 1e-6, even at
    /// g = +-0.99 where it spans more than six orders of magnitude: `2 pi` times its integral over
    /// `mu`, taken in panels that double in width away from the peak (at `mu = sign(g)`), each by
    /// adaptive Gauss-Kronrod. Shares nothing with the phase function but its value.
    #[test]
    fn the_phase_function_integrates_to_one() {
        use crate::medium::henyey_greenstein;
        for g in [-0.99, -0.5, 0.0, 0.3, 0.8, 0.99] {
            let s: f64 = if g < 0.0 { -1.0 } else { 1.0 };
            // x = 1 - s mu, from the peak (x = 0) to the far side (x = 2).
            let f = |x: f64| henyey_greenstein(g, s * (1.0 - x));
            let (mut total, mut lo, mut hi) = (0.0, 0.0, 1e-9f64);
            while lo < 2.0 {
                total += integrate(f, lo, hi.min(2.0), 1e-12, 0.0).value;
                (lo, hi) = (hi, 2.0 * hi);
            }
            let integral = 2.0 * std::f64::consts::PI * total;
            assert!((integral - 1.0).abs() < 1e-6, "g = {g}: {integral}");
            // The span of the values, and the f32 form the gather uses, at the hard ends.
            let (peak, tail) = (f(0.0), f(2.0));
            if g.abs() == 0.99 {
                assert!(peak / tail > 1e6, "g = {g}: {peak} / {tail}");
            }
        }
    }
}
