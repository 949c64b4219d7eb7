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

fn gauss_kronrod(f: &mut impl FnMut(f64) -> f64, a: f64, b: f64) -> Quadrature {
    let (c, h) = (0.5 * (a + b), 0.5 * (b - a));
    let fc = f(c);
    let (mut kronrod, mut gauss) = (fc * WGK[7], fc * WG[3]);
    for j in 0..7 {
        let x = h * XGK[j];
        let pair = f(c - x) + f(c + x);
        kronrod += WGK[j] * pair;
        if j % 2 == 1 {
            gauss += WG[j / 2] * pair;
        }
    }
    Quadrature { value: kronrod * h, error: ((kronrod - gauss) * h).abs() }
}

/// Adaptive Gauss-Kronrod quadrature of `f` over `[a, b]` to `max(rel_tol |I|, abs_tol)`.
/// The interval with the largest error is bisected until the total error is small enough or
/// 4000 intervals are in use (then the best estimate is returned with its error).
pub fn integrate(mut f: impl FnMut(f64) -> f64, a: f64, b: f64, rel_tol: f64, abs_tol: f64) -> Quadrature {
    if a == b {
        return Quadrature { value: 0.0, error: 0.0 };
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
        let value: f64 = pieces.iter().map(|p| p.2.value).sum();
        let error: f64 = pieces.iter().map(|p| p.2.error).sum();
        let worst = pieces.iter().enumerate().max_by(|x, y| x.1.2.error.total_cmp(&y.1.2.error)).map(|(i, _)| i);
        let done = error <= (rel_tol * value.abs()).max(abs_tol) || pieces.len() >= 4000;
        let Some(worst) = worst.filter(|_| !done) else {
            return Quadrature { value, error };
        };
        let (lo, hi, _) = pieces.swap_remove(worst);
        let mid = 0.5 * (lo + hi);
        if !(mid > lo && mid < hi) {
            // The interval cannot be split further in floating point.
            return Quadrature { value, error };
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
/// (unit `we`), by nested adaptive quadrature to about `rel_tol`.
pub fn single_scattering(scene: &Scene, o: DVec3, we: DVec3, rel_tol: f64) -> DVec3 {
    let Some((t0, t1)) = scene.camera_segment(o, we).0 else {
        return DVec3::ZERO;
    };
    let sigma_t = scene.medium.sigma_t();
    let mut out = DVec3::ZERO;
    let mut per_light = vec![[0.0f64; 3]; scene.lights.len()];
    for channel in 0..3 {
        let st = sigma_t[channel];
        // Channels with the same extinction share the geometric integral.
        if let Some(done) = (0..channel).find(|&c| sigma_t[c] == st) {
            for (li, light) in scene.lights.iter().enumerate() {
                let value = per_light[li][done];
                per_light[li][channel] = value;
                out[channel] += value * scene.medium.sigma_s[channel] * light.radiance[channel];
            }
            continue;
        }
        for (li, light) in scene.lights.iter().enumerate() {
            // Unoccluded geometry, then visibility through the other panels.
            let inner = |x: DVec3| {
                let per_q = |p: f64| {
                    let f = |q: f64| {
                        let y = light.point(p, q);
                        let to_x = x - y;
                        let d2 = to_x.length_squared();
                        let d = d2.sqrt();
                        let cos = light.n.dot(to_x) / d;
                        if !(cos > 0.0) || d == 0.0 {
                            return 0.0;
                        }
                        if scene.blocked(y, x, li) {
                            return 0.0;
                        }
                        // The phase function at the scattering angle between the light's
                        // travel (y to x) and the way to the eye (-we): section 1.1.
                        (-st * d).exp() * cos / d2 * scene.medium.phase(to_x / d, -we)
                    };
                    integrate(f, 0.0, light.height, rel_tol * 0.1, 0.0).value
                };
                integrate(per_q, 0.0, light.width, rel_tol * 0.3, 0.0).value
            };
            let outer = |t: f64| (-st * (t - t0)).exp() * inner(o + t * we);
            let value = integrate(outer, t0, t1, rel_tol, 0.0).value;
            per_light[li][channel] = value;
            out[channel] += value * scene.medium.sigma_s[channel] * light.radiance[channel];
        }
    }
    out
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
