//! The closed form of `cmis-exact` (docs/mathematics.md section 3): the mean over orientations
//! of g(beta) = width(beta) |det(beta)|, in f64 (the reference) and in f32 without branches (the
//! one the renderer gathers with).

use crate::numeric::{atan_unit_lanes, atan2_lanes, ln_lanes};
use crate::simd::Lanes;
use std::f64::consts::PI;

/// (1/pi) times the integral over beta in [0, pi) of g(beta) = width(beta, (p, q)) |det(beta)|,
/// det(beta) = cos(beta) a_u + sin(beta) a_v, for the light vertex at local (p, q) of a `w x h`
/// light: the marginal density of paper eq. (24) that the paper calls non-integrable.
///
/// The mathematics (section 3) splits [0, pi) at pi/2, the corner directions and the zero of det. The same
/// pieces are summed here over the full circle, which needs fewer transcendental calls:
/// width(beta) = fwd(beta) + fwd(beta + pi), with fwd(phi) the distance from (p, q) to the
/// boundary along direction phi, and |det| has period pi, so
///
///   int_0^pi g = int_0^{2 pi} fwd(phi) |det(phi)| d phi.
///
/// The directions to the four corners cut the circle into four sectors, one per edge e, with
/// outward normal n_e, tangent t_e (n_e turned a quarter counter-clockwise) and distance d_e.
/// In sector e, with psi the angle from n_e, fwd = d_e / cos(psi) and
/// det = A_n cos(psi) + A_t sin(psi), A_n = a . n_e, A_t = a . t_e, so
///
///   int fwd det d phi = d_e [A_n psi - A_t ln cos(psi)],
///
/// and at a corner r_k (offset from (p, q)) cos(psi) = d_e / |r_k|: between two corners the
/// logarithms leave ln|r_start| - ln|r_end|. A zero of det (directions +-(-a_v, a_u)) inside a
/// sector splits it, so that |det| is det times one sign on each arc. A sector whose edge
/// passes through the vertex (d_e = 0) contributes nothing and is skipped, avoiding 0 * inf.
/// Matches adaptive quadrature to ~1e-14 relative (tests below).
pub fn cmis_exact_mean(w: f64, h: f64, p: f64, q: f64, a_u: f64, a_v: f64) -> f64 {
    if a_u == 0.0 && a_v == 0.0 {
        return 0.0;
    }
    let cross = |a: (f64, f64), b: (f64, f64)| a.0 * b.1 - a.1 * b.0;
    let dot = |a: (f64, f64), b: (f64, f64)| a.0 * b.0 + a.1 * b.1;
    let det = |b: (f64, f64)| a_u * b.0 + a_v * b.1;
    // Corners counter-clockwise from (0, 0); edge e runs from corner e to corner e + 1.
    let corners = [(-p, -q), (w - p, -q), (w - p, h - q), (-p, h - q)];
    let edges = [((0.0, -1.0), q), ((1.0, 0.0), w - p), ((0.0, 1.0), h - q), ((-1.0, 0.0), p)];
    let zero = (-a_v, a_u);
    let mut total = 0.0;
    for (e, &(n, d)) in edges.iter().enumerate() {
        if !(d > 0.0) {
            continue;
        }
        let (a_n, a_t) = (det(n), det((-n.1, n.0)));
        let (start, end) = (corners[e], corners[(e + 1) % 4]);
        // The integral over an arc on which det keeps one sign, from the turn angle and the
        // change of ln cos(psi). On such an arc det(b0) and det(b1) share that sign or vanish,
        // and cannot both vanish (the arc is shorter than pi), so their sum carries it.
        let arc = |b0: (f64, f64), b1: (f64, f64), turn: f64, delta_ln_cos: f64| {
            d * (a_n * turn - a_t * delta_ln_cos) * (det(b0) + det(b1)).signum()
        };
        let turn = cross(start, end).atan2(dot(start, end));
        // ln cos(psi_end) - ln cos(psi_start) = ln |r_start| - ln |r_end|.
        let delta = 0.5 * (dot(start, start) / dot(end, end)).ln();
        // A zero of det strictly inside the sector (which spans less than pi) splits it.
        match [zero, (-zero.0, -zero.1)].into_iter().find(|&z| cross(start, z) > 0.0 && cross(z, end) > 0.0) {
            Some(z) => {
                let first_turn = cross(start, z).atan2(dot(start, z));
                // cos(psi) is d / |r_start| at the corner and n . z / |z| at the zero.
                let first_delta = 0.5 * (dot(n, z).powi(2) * dot(start, start) / (dot(z, z) * d * d)).ln();
                total += arc(start, z, first_turn, first_delta) + arc(z, end, turn - first_turn, delta - first_delta);
            }
            None => total += arc(start, end, turn, delta),
        }
    }
    // The integral of a non-negative function; rounding can leave a hair below zero.
    (total / PI).max(0.0)
}

/// [`cmis_exact_mean`] in f32 and without branches, so that the lanes of a block run as vector
/// instructions: the same sectors and arcs (section 3), with the choices made by selects and
/// every quantity written so that f32 keeps it accurate:
///
/// - the turn of sector e is the sum of its two corners' angles from n_e, each corner's angles
///   from its two edges' normals being atan(min / max) of its distances to them and a quarter
///   turn less that (one arc tangent per corner serves two sectors; two positive terms, no
///   cancellation, so the small angles of long thin lights stay exact);
/// - its change of ln cos(psi), ln|r_start| - ln|r_end|, is (1/2) ln(1 + delta / |r_end|^2) with
///   delta = |r_start|^2 - |r_end|^2 = -E_e . (r_start + r_end) (E_e the edge vector: one
///   product, no cancellation) when that ratio is near 1, and (1/2) ln(|r_start|^2 / |r_end|^2)
///   otherwise;
/// - the sectors' |dF_e| = |d_e (A_n turn - A_t delta ln cos)| are summed as if det kept its
///   sign on each; the sector holding a zero of det (z = (-a_v, a_u) and -z; the one its
///   direction leaves through, from z's signs and one comparison) is the two arcs either side of
///   it, of opposite signs, so it adds 2 min(|arc_1|, |dF_e - arc_1|), arc_1 from the start
///   corner to the zero: atan2(r_start x z, r_start . z) and (1/2) ln((n_e . z)^2 |r_start|^2 /
///   (|z|^2 d_e^2)), both in the edge's frame.
///
/// Four arc tangents in [0, pi/4], two atan2, six logarithms and twelve divisions per hit (the
/// corners' arc tangents took 3% off cmis-exact's render, against one atan2 per sector; the
/// arcs' logarithms from 1 + x added 6%, and cut the largest error on long thin lights from
/// 3.8e-5 to 2.8e-7; a correction per zero on the edge it leaves through, rather than each
/// sector split by selects, 4% with AVX-512 and 14% with AVX2). Agrees with the f64 form to a
/// few 1e-7 relative on the benchmark's hits and on random inputs (tests below).
#[inline(always)]
pub fn cmis_exact_mean_f32(w: f32, h: f32, p: f32, q: f32, a_u: f32, a_v: f32) -> f32 {
    cmis_exact_mean_lanes::<1, f32>(w, h, p, q, a_u, a_v)
}

/// [`cmis_exact_mean_f32`] for a block of hits on one light (`w`, `h`), lane by lane, for any
/// width ([`Lanes`]): the same operations.
///
/// A sector e contributes |F_e(end) - F_e(start)| = |dF_e| when det keeps its sign on it. The
/// sector holding a zero of det contributes |arc_1| + |arc_2| with arc_1 + arc_2 = dF_e and the
/// arcs of opposite signs, which is |dF_e| + 2 min(|arc_1|, |dF_e - arc_1|). So the total is the
/// four |dF_e| plus one such correction per zero, each computed on the edge its direction
/// leaves through (found from z's signs and one comparison, not from the four sectors). A zero
/// on a corner's direction gives arc_1 = 0 or dF_e, a correction of zero: the edge it is
/// charged to does not matter.
#[inline(always)]
pub fn cmis_exact_mean_lanes<const L: usize, V: Lanes<L>>(w: f32, h: f32, p: V, q: V, a_u: V, a_v: V) -> V {
    let (s, zero) = (V::splat, V::splat(0.0));
    let (zx, zy) = (a_v.neg(), a_u);
    // The vertex's distances to the left, right, bottom and top edges.
    let (x0, x1, y0, y1) = (p, s(w) - p, q, s(h) - q);
    // Each corner's angle from the vertical edges' normals and from the horizontal ones; a
    // sector's turn is the sum of its two corners' angles from its own normal.
    let corners = [corner_angles::<L, V>(x0, y0), corner_angles(x1, y0), corner_angles(x1, y1), corner_angles(x0, y1)];
    let turns = [
        corners[0].0 + corners[1].0,
        corners[1].1 + corners[2].1,
        corners[2].0 + corners[3].0,
        corners[3].1 + corners[0].1,
    ];
    // Corners counter-clockwise from (0, 0), relative to the vertex; edge e runs from corner e
    // to corner e + 1.
    let (cx, cy) = ([p.neg(), x1, x1, p.neg()], [q.neg(), q.neg(), y1, y1]);
    let r2: [V; 4] = std::array::from_fn(|k| cx[k].mul_add(cx[k], cy[k] * cy[k]));
    // |r_start|^2 - |r_end|^2 = -E_e . (r_start + r_end), E_e the edge vector: one product.
    let deltas = [s(-w) * (cx[0] + cx[1]), s(-h) * (cy[1] + cy[2]), s(w) * (cx[2] + cx[3]), s(h) * (cy[3] + cy[0])];
    let dist = [y0, x1, y1, x0];
    // z in each edge's frame (z . n_e, z . t_e); a . n_e = z . t_e and a . t_e = -z . n_e.
    let frames = [(zy.neg(), zx), (zx, zy), (zy, zx.neg()), (zx.neg(), zy.neg())];
    let mut values = [zero; 4];
    let mut total = zero;
    for e in 0..4 {
        // ln(|r_start|^2 / |r_end|^2) = ln(1 + x), x = delta / |r_end|^2.
        let inv = s(1.0) / r2[(e + 1) % 4];
        let ell = s(0.5) * ln_ratio::<L, V>(deltas[e] * inv, r2[e] * inv);
        let (z_n, z_t) = frames[e];
        let value = dist[e] * z_t.mul_add(turns[e], z_n * ell);
        // A sector whose edge passes through the vertex contributes nothing (its logarithm
        // may not be finite there).
        values[e] = V::select(dist[e].gt(zero), value, zero);
        total = total + values[e].abs();
    }
    let z2 = zx.mul_add(zx, zy * zy);
    let dists = [x0, x1, y0, y1];
    let plus = zero_correction::<L, V>(zx, zy, z2, dists, values);
    // For -z, a = (z_y, -z_x) is unchanged while z's frame turns over: its arcs come out
    // negated, and so are the sectors' values for it.
    let minus = zero_correction::<L, V>(zx.neg(), zy.neg(), z2, dists, values.map(V::neg));
    let mean = (total + plus + minus) * s(std::f32::consts::FRAC_1_PI);
    V::select(mean.gt(zero), mean, zero)
}

/// What a zero of det in direction (zx, zy) adds to the sum of the sectors' |dF_e|:
/// 2 min(|arc_1|, |dF_e - arc_1|) on the edge e the direction leaves through, arc_1 the arc from
/// the sector's start corner to the zero. `dists` are the vertex's distances to the left, right, bottom and
/// top edges; `values` the sectors' dF_e, for a = (zy, -zx). (A function, not a closure: a
/// closure is compiled without the kernel's target features, and the intrinsics in it would not
/// be inlined.)
#[inline(always)]
fn zero_correction<const L: usize, V: Lanes<L>>(zx: V, zy: V, z2: V, dists: [V; 4], values: [V; 4]) -> V {
    let (s, zero) = (V::splat, V::splat(0.0));
    let [x0, x1, y0, y1] = dists;
    let (east, north) = (zx.gt(zero), zy.gt(zero));
    // The direction leaves through a vertical edge (right if east, else left) when it reaches
    // its line first: dx / |zx| < dy / |zy|.
    let (dx, dy) = (V::select(east, x1, x0), V::select(north, y1, y0));
    let vertical = (dx * zy.abs()).lt(dy * zx.abs());
    // The edge's distance d, z in its frame (z_n = z . n_e > 0, z_t = z . t_e), the start
    // corner's coordinate along it (t_s <= 0) and its sector's dF_e: right, left, top, bottom.
    let d = V::select(vertical, dx, dy);
    let z_n = V::select(vertical, zx.abs(), zy.abs());
    let z_t = V::select(vertical, V::select(east, zy, zy.neg()), V::select(north, zx.neg(), zx));
    let t_s = V::select(vertical, V::select(east, y0, y1), V::select(north, x1, x0)).neg();
    let value = V::select(vertical, V::select(east, values[1], values[3]), V::select(north, values[2], values[0]));
    // The arc from the start corner (d, t_s) to z: its turn, and its change of ln cos(psi),
    // (1/2) ln of (z_n^2 |r_start|^2) / (d^2 |z|^2) = 1 + gap / (d^2 |z|^2), with
    // gap = (z_n t_s)^2 - (d z_t)^2 = -cross (z_n t_s + d z_t) as a product (no cancellation;
    // from 1 + x where x is small: a zero near the start corner of a far edge, on a long thin
    // light, where the ratio would round away its difference from 1).
    let cross = d.mul_add(z_t, (t_s * z_n).neg());
    let dot = d.mul_add(z_n, t_s * z_t);
    let turn = atan2_lanes::<L, V>(cross, dot);
    let gap = cross.neg() * z_n.mul_add(t_s, d * z_t);
    let d2 = d * d;
    let inv = s(1.0) / (d2 * z2);
    let (small, ratio) = (gap * inv, (z_n * z_n) * t_s.mul_add(t_s, d2) * inv);
    let ell = s(0.5) * ln_ratio::<L, V>(small, ratio);
    let arc = d * z_t.mul_add(turn, z_n * ell);
    let correction = s(2.0) * arc.abs().min((value - arc).abs());
    // No arc on an edge through the vertex (d = 0), where inv is infinite and the logarithm's
    // argument not finite. For z = 0 (a = 0: D is 0) inv is infinite too; z_n = z_t = 0 and
    // ln_lanes is finite for any input, so the correction is 0 (tested, with the mean's final
    // clamp behind it). Guarding d^2 |z|^2 > 0 here instead made cmis-exact 2% slower.
    V::select(d.gt(zero), correction, zero)
}

/// ln(1 + x) for `ratio` = 1 + x, from x where that is accurate (|x| < 1/2: the ratio would
/// round away its difference from 1), else from the ratio (x near -1: 1 + x would cancel). One
/// logarithm of the chosen argument (branch-free): ln_1p_f32(x) is ln_f32(1 + x) plus the
/// rounding of 1 + x, added here (the same bits).
#[inline(always)]
fn ln_ratio<const L: usize, V: Lanes<L>>(x: V, ratio: V) -> V {
    let (s, zero) = (V::splat, V::splat(0.0));
    let near_one = x.abs().lt(s(0.5));
    let u = s(1.0) + x;
    let argument = V::select(near_one, u, ratio);
    let rounding = V::select(near_one, x - (u - s(1.0)), zero);
    ln_lanes::<L, V>(argument) + rounding
}

/// The angles of a corner at distances `x` and `y` (both >= 0) from the edges through it, seen
/// from the vertex: from the normal of the edge at distance `y` (atan(x / y)) and from the other
/// normal (the rest of a quarter turn), the smaller one from the polynomial and the larger one a
/// quarter turn less it, so that each keeps f32's relative precision; a sector's turn is a sum of
/// two such angles (no cancellation).
#[inline(always)]
fn corner_angles<const L: usize, V: Lanes<L>>(x: V, y: V) -> (V, V) {
    let (s, zero) = (V::splat, V::splat(0.0));
    let steep = x.gt(y);
    let (small, large) = (V::select(steep, y, x), V::select(steep, x, y));
    let a = atan_unit_lanes::<L, V>(V::select(large.gt(zero), small / large, zero));
    let b = s(std::f32::consts::FRAC_PI_2) - a;
    (V::select(steep, b, a), V::select(steep, a, b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quadrature::{chord_width_by_clipping, integrate_with_breaks};
    use rand::{Rng, SeedableRng};

    /// g(beta) computed directly (chord by clipping), independently of the closed form.
    fn g(w: f64, h: f64, p: f64, q: f64, a_u: f64, a_v: f64, beta: f64) -> f64 {
        chord_width_by_clipping(w, h, p, q, beta) * (beta.cos() * a_u + beta.sin() * a_v).abs()
    }

    /// Where g may have kinks: the zero of det and the directions to the four corners (mod pi).
    fn kinks(w: f64, h: f64, p: f64, q: f64, a_u: f64, a_v: f64) -> Vec<f64> {
        let corners = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)];
        let mut out: Vec<f64> = corners.iter().map(|&(x, y)| (y - q).atan2(x - p).rem_euclid(PI)).collect();
        out.push((-a_u).atan2(a_v).rem_euclid(PI));
        out
    }

    fn quadrature_mean(w: f64, h: f64, p: f64, q: f64, a_u: f64, a_v: f64) -> f64 {
        let scale = (w + h) * (a_u.abs() + a_v.abs());
        let f = |b| g(w, h, p, q, a_u, a_v, b);
        integrate_with_breaks(f, 0.0, PI, &kinks(w, h, p, q, a_u, a_v), 1e-13, 1e-15 * scale).value / PI
    }

    #[test]
    fn analytic_cosine_integral_matches_quadrature() {
        let check = |a_u: f64, a_v: f64| {
            let closed = std::f64::consts::FRAC_2_PI * (a_u * a_u + a_v * a_v).sqrt();
            let scale = a_u.abs() + a_v.abs();
            let zero = [(-a_u).atan2(a_v).rem_euclid(PI)];
            let det = |b: f64| (b.cos() * a_u + b.sin() * a_v).abs();
            let numeric = integrate_with_breaks(det, 0.0, PI, &zero, 1e-13, 1e-300).value / PI;
            if scale == 0.0 {
                assert_eq!(closed, 0.0);
                assert_eq!(numeric, 0.0);
            } else {
                assert!((closed - numeric).abs() <= 1e-10 * closed, "a_u={a_u} a_v={a_v}: {closed} vs {numeric}");
            }
        };
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        for _ in 0..1000 {
            check(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        }
        check(0.0, 0.0);
        for x in [1e-12, 0.3, -2.0, 1e6] {
            check(x, 0.0);
            check(0.0, x);
        }
        for e in 0..=12 {
            let r = 10f64.powi(e);
            check(1.0, r);
            check(-r, 1.0);
            check(1e-6, 1e-6 * r);
        }
    }

    #[test]
    fn cmis_exact_matches_quadrature_on_random_inputs() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(11);
        let mut worst = 0.0f64;
        for i in 0..10_000 {
            let (w, h) = (rng.random_range(0.01..5.0), rng.random_range(0.01..5.0));
            let (p, q) = (rng.random::<f64>() * w, rng.random::<f64>() * h);
            let (a_u, a_v) = (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let closed = cmis_exact_mean(w, h, p, q, a_u, a_v);
            let numeric = quadrature_mean(w, h, p, q, a_u, a_v);
            assert!(
                (closed - numeric).abs() <= 1e-9 * numeric,
                "#{i} w={w} h={h} p={p} q={q} a=({a_u},{a_v}): {closed} vs {numeric}"
            );
            worst = worst.max((closed - numeric).abs() / numeric);
        }
        println!("largest relative difference: {worst:.2e}");
    }

    #[test]
    fn cmis_exact_hard_cases() {
        let (w, h) = (3.0f64, 2.0f64);
        let vertices = [
            (0.0, 0.0),
            (w, 0.0),
            (w, h),
            (0.0, h),
            (0.0, 0.7),
            (w, 1.1),
            (1.3, 0.0),
            (2.2, h),
            (1.5, 1.0),
            (1e-14, 1e-14),
            (w - 1e-14, 0.5),
        ];
        let dets =
            [(1.0, 0.0), (0.0, 1.0), (-0.3, 0.0), (0.0, -2.0), (1.0, 1e-12), (1e-12, -1.0), (0.6, 0.8), (-0.6, 0.8)];
        for &(p, q) in &vertices {
            for &(a_u, a_v) in &dets {
                let closed = cmis_exact_mean(w, h, p, q, a_u, a_v);
                let numeric = quadrature_mean(w, h, p, q, a_u, a_v);
                assert!(closed.is_finite());
                assert!(
                    (closed - numeric).abs() <= 1e-9 * numeric,
                    "p={p} q={q} a=({a_u},{a_v}): {closed} vs {numeric}"
                );
            }
        }
        assert_eq!(cmis_exact_mean(w, h, 1.0, 1.0, 0.0, 0.0), 0.0);
        // Very thin lights, both ways round.
        for &(w, h) in &[(1.0, 1e-3), (1e-3, 1.0), (1000.0, 1.0), (1.0, 1e-6)] {
            for &(fp, fq) in &[(0.5, 0.5), (0.0, 0.3), (1.0, 1.0), (0.999, 0.001)] {
                for &(a_u, a_v) in &dets {
                    let (p, q) = (fp * w, fq * h);
                    let closed = cmis_exact_mean(w, h, p, q, a_u, a_v);
                    let numeric = quadrature_mean(w, h, p, q, a_u, a_v);
                    assert!(
                        (closed - numeric).abs() <= 1e-9 * numeric,
                        "w={w} h={h} p={p} q={q} a=({a_u},{a_v}): {closed} vs {numeric}"
                    );
                }
            }
        }
    }

    /// The f32 closed form against the f64 one: relative error over random vertices, light
    /// shapes (aspect ratios to 1e4) and hit directions, and on the hard cases.
    #[test]
    fn cmis_exact_f32_matches_the_f64_closed_form() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(12);
        let relative = |w: f32, h: f32, p: f32, q: f32, a_u: f32, a_v: f32| {
            let want = cmis_exact_mean(w as f64, h as f64, p as f64, q as f64, a_u as f64, a_v as f64);
            let got = cmis_exact_mean_f32(w, h, p, q, a_u, a_v) as f64;
            assert!(got.is_finite());
            if want == 0.0 { got.abs() } else { (got - want).abs() / want }
        };
        let mut errors = Vec::new();
        for _ in 0..200_000 {
            let aspect = 10f32.powf(rng.random_range(-2.0..2.0));
            let (w, h) = (1.0 / (1.0 + aspect), aspect / (1.0 + aspect));
            let (p, q) = (rng.random::<f32>() * w, rng.random::<f32>() * h);
            let (a_u, a_v) = (rng.random_range(-1.0f32..1.0), rng.random_range(-1.0f32..1.0));
            errors.push(relative(w, h, p, q, a_u, a_v));
        }
        errors.sort_by(f64::total_cmp);
        let (median, p999, worst) =
            (errors[errors.len() / 2], errors[errors.len() * 999 / 1000], errors[errors.len() - 1]);
        println!("f32 closed form, relative error: median {median:.1e}, 99.9% {p999:.1e}, largest {worst:.1e}");
        assert!(median < 1e-7 && p999 < 5e-7 && worst < 1e-6, "median {median:e}, 99.9% {p999:e}, largest {worst:e}");
        // Long thin lights, to aspect ratios of 1e4 either way, where a sector's turn is tiny and
        // its edge far: the turns and logarithms must keep their relative precision there.
        let mut thin = Vec::new();
        for _ in 0..100_000 {
            let aspect = 10f32.powf(rng.random_range(2.0..4.0)).powi(if rng.random::<bool>() { 1 } else { -1 });
            let (w, h) = (1.0 / (1.0 + aspect), aspect / (1.0 + aspect));
            let (p, q) = (rng.random::<f32>() * w, rng.random::<f32>() * h);
            let (a_u, a_v) = (rng.random_range(-1.0f32..1.0), rng.random_range(-1.0f32..1.0));
            thin.push(relative(w, h, p, q, a_u, a_v));
        }
        thin.sort_by(f64::total_cmp);
        let (median, p999, worst) = (thin[thin.len() / 2], thin[thin.len() * 999 / 1000], thin[thin.len() - 1]);
        println!("thin lights (aspect 1e2 to 1e4): median {median:.1e}, 99.9% {p999:.1e}, largest {worst:.1e}");
        assert!(median < 1e-7 && p999 < 5e-7 && worst < 1e-6, "median {median:e}, 99.9% {p999:e}, largest {worst:e}");
        // Vertices on edges and corners, axis-aligned and near-zero directions.
        let (w, h) = (0.6f32, 0.4f32);
        for &(p, q) in &[(0.0, 0.0), (w, 0.0), (w, h), (0.0, h), (0.0, 0.2), (w, 0.1), (0.3, 0.0), (0.2, h), (0.3, 0.2)]
        {
            for &(a_u, a_v) in
                // The last two put z and -z on corners' directions from (0.3, 0.2): a zero
                // charged to either edge.
                &[
                    (1.0, 0.0),
                    (0.0, 1.0),
                    (-0.3, 0.0),
                    (0.0, -2.0),
                    (1.0, 1e-7),
                    (1e-7, -1.0),
                    (0.6, 0.8),
                    (0.2, -0.3),
                    (-0.2, 0.3),
                ]
            {
                let e = relative(w, h, p, q, a_u, a_v);
                assert!(e < 1e-5, "p={p} q={q} a=({a_u},{a_v}): relative error {e:e}");
            }
        }
        assert_eq!(cmis_exact_mean_f32(w, h, 0.3, 0.2, 0.0, 0.0), 0.0);
        // A zero of det adds exactly nothing on an edge through the vertex, at a corner, and
        // for z = 0.
        let values = [0.1f32, -0.2, 0.3, -0.4];
        assert_eq!(zero_correction::<1, f32>(1.0, 0.0, 1.0, [0.3, 0.0, 0.2, 0.2], values), 0.0);
        assert_eq!(zero_correction::<1, f32>(1.0, 1.0, 2.0, [0.3, 0.0, 0.2, 0.0], values), 0.0);
        assert_eq!(zero_correction::<1, f32>(0.0, 0.0, 0.0, [0.3, 0.3, 0.2, 0.2], values), 0.0);
    }
}
