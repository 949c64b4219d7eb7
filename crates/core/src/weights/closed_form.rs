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
/// - each zero of det (z = (-a_v, a_u) and -z) lies in one sector, found by two cross-product
///   signs; the sector is split there into arcs on which det keeps its sign, and each arc
///   contributes |d_e (A_n turn - A_t delta ln cos)| (a sector without a zero is one arc: its
///   second arc is empty). The arc up to the zero turns by atan2(r_start x z, r_start . z) and
///   changes ln cos by (1/2) ln((n_e . z)^2 |r_start|^2 / (|z|^2 d_e^2)).
///
/// Four arc tangents in [0, pi/4], two atan2, six logarithms and twelve divisions per hit (the
/// corners' arc tangents took 3% off cmis-exact's render, against one atan2 per sector; the
/// arcs' logarithms from 1 + x added 6%, and cut the largest error on long thin lights from
/// 3.8e-5 to 2.8e-7). Agrees with the f64 form to a
/// few 1e-7 relative on the benchmark's hits and on random inputs (tests below).
#[inline(always)]
pub fn cmis_exact_mean_f32(w: f32, h: f32, p: f32, q: f32, a_u: f32, a_v: f32) -> f32 {
    cmis_exact_mean_lanes::<1, f32>(w, h, p, q, a_u, a_v)
}

/// [`cmis_exact_mean_f32`] for a block of hits on one light (`w`, `h`), lane by lane, for any
/// width ([`Lanes`]): the same operations.
#[inline(always)]
pub fn cmis_exact_mean_lanes<const L: usize, V: Lanes<L>>(w: f32, h: f32, p: V, q: V, a_u: V, a_v: V) -> V {
    let (s, zero) = (V::splat, V::splat(0.0));
    let (zx, zy) = (a_v.neg(), a_u);
    // Each corner's angle from the vertical edges' normals and from the horizontal ones; a
    // sector's turn is the sum of its two corners' angles from its own normal.
    let (wp, hq) = (s(w) - p, s(h) - q);
    let corners = [corner_angles::<L, V>(p, q), corner_angles(wp, q), corner_angles(wp, hq), corner_angles(p, hq)];
    let turns = [
        corners[0].0 + corners[1].0,
        corners[1].1 + corners[2].1,
        corners[2].0 + corners[3].0,
        corners[3].1 + corners[0].1,
    ];
    let sectors = [
        sector::<0, L, V>(w, h, p, q, zx, zy, turns[0]),
        sector::<1, L, V>(w, h, p, q, zx, zy, turns[1]),
        sector::<2, L, V>(w, h, p, q, zx, zy, turns[2]),
        sector::<3, L, V>(w, h, p, q, zx, zy, turns[3]),
    ];
    // The start corner, (n_e . z)^2 and d_e^2 of the sectors holding z and -z, by selects.
    let (mut at_z, mut at_neg) = ([zero; 5], [zero; 5]);
    for t in &sectors {
        let fields = [t.start.0, t.start.1, t.nz2, t.dist * t.dist, t.cos2_gap];
        for k in 0..5 {
            at_z[k] = V::select(t.has_z, fields[k], at_z[k]);
            at_neg[k] = V::select(t.has_neg, fields[k], at_neg[k]);
        }
    }
    let z2 = zx.mul_add(zx, zy * zy);
    let (z_turn, z_ell) = to_zero::<L, V>(at_z, 1.0, zx, zy, z2);
    let (n_turn, n_ell) = to_zero::<L, V>(at_neg, -1.0, zx, zy, z2);
    let mut total = zero;
    for t in &sectors {
        let first_turn = V::select(t.has_z, z_turn, V::select(t.has_neg, n_turn, t.turn));
        let first_ell = V::select(t.has_z, z_ell, V::select(t.has_neg, n_ell, t.ell));
        let first = t.a_n.mul_add(first_turn, (t.a_t * first_ell).neg());
        let second = t.a_n.mul_add(t.turn - first_turn, (t.a_t * (t.ell - first_ell)).neg());
        let value = t.dist * (first.abs() + second.abs());
        // A sector whose edge passes through the vertex contributes nothing.
        total = total + V::select(t.dist.gt(zero), value, zero);
    }
    let mean = total * s(std::f32::consts::FRAC_1_PI);
    V::select(mean.gt(zero), mean, zero)
}

/// The arc from a sector's start corner (x, y) to the zero `sign` z: its turn and change of ln
/// cos. (A function, not a closure: a closure is compiled without the kernel's target features,
/// and the intrinsics in it would not be inlined.)
#[inline(always)]
fn to_zero<const L: usize, V: Lanes<L>>([x, y, nz2, d2, gap]: [V; 5], sign: f32, zx: V, zy: V, z2: V) -> (V, V) {
    let s = V::splat;
    let (cross, dot) = (x.mul_add(zy, (y * zx).neg()), x.mul_add(zx, y * zy));
    let turn = atan2_lanes::<L, V>(s(sign) * cross, s(sign) * dot);
    // ln of (n_e . z)^2 |r_start|^2 / (d_e^2 |z|^2) = 1 + gap / (d_e^2 |z|^2), as the sectors'
    // logarithm: from 1 + x where x is small (an arc to a zero near the start corner of a far
    // edge, on a long thin light, where the ratio would round away its difference from 1).
    let inv = s(1.0) / (d2 * z2);
    let (small, ratio) = (gap * inv, nz2 * x.mul_add(x, y * y) * inv);
    (turn, s(0.5) * ln_ratio::<L, V>(small, ratio))
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

/// One sector of [`cmis_exact_mean_lanes`]: the part of the circle of directions from the
/// vertex that meets edge E.
#[derive(Clone, Copy)]
struct Sector<V, M> {
    /// Its turn and the change of ln cos(psi) across it.
    turn: V,
    ell: V,
    /// Whether z or -z lies strictly inside.
    has_z: M,
    has_neg: M,
    /// Its start corner relative to the vertex, (n_e . z)^2, and (n_e . z)^2 |r_start|^2 -
    /// d_e^2 |z|^2.
    start: (V, V),
    nz2: V,
    cos2_gap: V,
    /// d_e, A_n = a . n_e and A_t = a . t_e (a = (a_u, a_v) = (z_y, -z_x)).
    dist: V,
    a_n: V,
    a_t: V,
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

#[inline(always)]
fn sector<const E: usize, const L: usize, V: Lanes<L>>(
    w: f32,
    h: f32,
    p: V,
    q: V,
    zx: V,
    zy: V,
    turn: V,
) -> Sector<V, V::Mask> {
    let (s, zero) = (V::splat, V::splat(0.0));
    let (a_u, a_v) = (zy, zx.neg());
    // Corners counter-clockwise from (0, 0), relative to the vertex; edge E runs from corner E
    // to corner E + 1, with outward normal n_E, tangent t_E = n_E turned a quarter, distance
    // d_E and length len_E.
    let cx = [p.neg(), s(w) - p, s(w) - p, p.neg()];
    let cy = [q.neg(), q.neg(), s(h) - q, s(h) - q];
    let (start, end) = ((cx[E], cy[E]), (cx[(E + 1) % 4], cy[(E + 1) % 4]));
    let dist = [q, s(w) - p, s(h) - q, p][E];
    let (a_n, a_t) = [(a_v.neg(), a_u), (a_u, a_v), (a_v, a_u.neg()), (a_u.neg(), a_v.neg())][E];
    // |r_start|^2 - |r_end|^2 = -E_e . (r_start + r_end).
    let delta =
        [s(-w) * (start.0 + end.0), s(-h) * (start.1 + end.1), s(w) * (start.0 + end.0), s(h) * (start.1 + end.1)][E];
    let nz = [zy.neg(), zx, zy, zx.neg()][E];
    // (n_e . z)^2 |r_start|^2 - d_e^2 |z|^2 = (z_n t_s)^2 - (d_e z_t)^2 (|r_start|^2 = d_e^2 +
    // t_s^2, |z|^2 = z_n^2 + z_t^2), as a product: no cancellation. The same for -z.
    let zt = [zx, zy, zx.neg(), zy.neg()][E];
    let ts = [start.0, start.1, start.0.neg(), start.1.neg()][E];
    let cos2_gap = nz.mul_add(ts, (dist * zt).neg()) * nz.mul_add(ts, dist * zt);
    let r2_end = end.0.mul_add(end.0, end.1 * end.1);
    // ln(|r_start|^2 / |r_end|^2) = ln(1 + x), x = delta / |r_end|^2.
    let inv = s(1.0) / r2_end;
    let (x, ratio) = (delta * inv, start.0.mul_add(start.0, start.1 * start.1) * inv);
    let ell = s(0.5) * ln_ratio::<L, V>(x, ratio);
    let c_start = start.0.mul_add(zy, (start.1 * zx).neg());
    let c_end = zx.mul_add(end.1, (zy * end.0).neg());
    Sector {
        turn,
        ell,
        has_z: c_start.gt(zero) & c_end.gt(zero),
        has_neg: c_start.lt(zero) & c_end.lt(zero),
        start,
        nz2: nz * nz,
        cos2_gap,
        dist,
        a_n,
        a_t,
    }
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
                &[(1.0, 0.0), (0.0, 1.0), (-0.3, 0.0), (0.0, -2.0), (1.0, 1e-7), (1e-7, -1.0), (0.6, 0.8)]
            {
                let e = relative(w, h, p, q, a_u, a_v);
                assert!(e < 1e-5, "p={p} q={q} a=({a_u},{a_v}): relative error {e:e}");
            }
        }
        assert_eq!(cmis_exact_mean_f32(w, h, 0.3, 0.2, 0.0, 0.0), 0.0);
    }
}
