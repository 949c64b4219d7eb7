//! Rectangular lights (docs/mathematics.md section 1) and their chords (docs/mathematics.md section 2).
//!
//! A light is the rectangle `corner + p U/|U| + q V/|V|`, `p` in `[0, W]`, `q` in `[0, H]`. It
//! emits constant radiance one-sided into the hemisphere of `n = normalize(U x V)`, and it is an
//! opaque panel: both faces block rays, the back face is black.

use crate::numeric::{Real, V3, dot};
use glam::DVec3;

/// A validated rectangular light.
#[derive(Clone, Debug)]
pub struct RectLight {
    pub name: String,
    pub corner: DVec3,
    /// Unit edge directions u, v and the normal n = u x v.
    pub u: DVec3,
    pub v: DVec3,
    pub n: DVec3,
    /// Side lengths W = |U| and H = |V|.
    pub width: f64,
    pub height: f64,
    pub radiance: DVec3,
}

impl RectLight {
    /// Builds a light from its corner and (orthogonal, non-zero) edges; the scene validates them.
    pub fn new(name: &str, corner: DVec3, edge_u: DVec3, edge_v: DVec3, radiance: DVec3) -> Self {
        let u = edge_u.normalize();
        let v = edge_v.normalize();
        RectLight {
            name: name.to_string(),
            corner,
            u,
            v,
            n: u.cross(v).normalize(),
            width: edge_u.length(),
            height: edge_v.length(),
            radiance,
        }
    }

    pub fn area(&self) -> f64 {
        self.width * self.height
    }

    /// The power used to choose lights: A * luminance(Le) (docs/mathematics.md section 2, step 1).
    pub fn power(&self) -> f64 {
        self.area() * luminance(self.radiance)
    }

    /// The world point at local coordinates (p, q).
    pub fn point(&self, p: f64, q: f64) -> DVec3 {
        self.corner + p * self.u + q * self.v
    }

    /// Local coordinates (p, q) of a world point (projected onto the light's plane).
    pub fn local(&self, y: DVec3) -> (f64, f64) {
        let d = y - self.corner;
        (d.dot(self.u), d.dot(self.v))
    }

    /// The four corners, counter-clockwise seen from the front.
    pub fn corners(&self) -> [DVec3; 4] {
        let (eu, ev) = (self.u * self.width, self.v * self.height);
        [self.corner, self.corner + eu, self.corner + eu + ev, self.corner + ev]
    }

    /// Where the ray `o + t d` crosses the panel with `t` in `(t_min, t_max)`, if it does.
    pub fn intersect(&self, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<f64> {
        self.rectangle().crossing(o.to_array(), d.to_array(), t_min, t_max)
    }

    /// The panel as a ray sees it, in f64.
    pub fn rectangle(&self) -> Rectangle<f64> {
        Rectangle {
            corner: self.corner.to_array(),
            u: self.u.to_array(),
            v: self.v.to_array(),
            n: self.n.to_array(),
            width: self.width,
            height: self.height,
        }
    }
}

/// Luminance of a linear RGB triple (Rec. 709 weights), used to choose lights by power.
pub fn luminance(rgb: DVec3) -> f64 {
    0.2126 * rgb.x + 0.7152 * rgb.y + 0.0722 * rgb.z
}

/// A rectangle as a ray sees it, in f64 (scene queries) or f32 (light panels as occluders while
/// gathering): `corner + p u + q v`, `p` in `[0, width]`, `q` in `[0, height]`, normal `n`.
#[derive(Clone, Copy, Debug)]
pub struct Rectangle<T> {
    pub corner: V3<T>,
    pub u: V3<T>,
    pub v: V3<T>,
    pub n: V3<T>,
    pub width: T,
    pub height: T,
}

impl<T: Real> Rectangle<T> {
    /// Where the ray `o + t d` crosses the rectangle with `t` in the open interval
    /// `(t_min, t_max)`, if it does; edges count as inside. A ray parallel to the rectangle's
    /// plane never crosses it.
    #[inline]
    pub fn crossing(&self, o: V3<T>, d: V3<T>, t_min: T, t_max: T) -> Option<T> {
        let denom = dot(d, self.n);
        if denom == T::ZERO {
            return None;
        }
        let c = self.corner;
        let towards = dot([c[0] - o[0], c[1] - o[1], c[2] - o[2]], self.n);
        // Behind the origin (t <= 0) is outside any range from t_min >= 0, before the division:
        // most panels a ray is tested against lie behind it. The same result.
        let behind = (towards <= T::ZERO && denom > T::ZERO) || (towards >= T::ZERO && denom < T::ZERO);
        if t_min >= T::ZERO && behind {
            return None;
        }
        let t = towards / denom;
        if !(t > t_min && t < t_max) {
            return None;
        }
        let rel = [(o[0] + t * d[0]) - c[0], (o[1] + t * d[1]) - c[1], (o[2] + t * d[2]) - c[2]];
        let (p, q) = (dot(rel, self.u), dot(rel, self.v));
        (p >= T::ZERO && p <= self.width && q >= T::ZERO && q <= self.height).then_some(t)
    }
}

/// A chord direction `(cos beta, sin beta)`, `beta` in `[0, pi)`, prepared for repeated use:
/// the reciprocals `1/|cos beta|` and `1/sin beta` (infinite on the axes).
#[derive(Clone, Copy, Debug)]
pub struct ChordDirection<T> {
    pub cos_positive: bool,
    pub inv_abs_cos: T,
    pub inv_sin: T,
}

impl ChordDirection<f64> {
    /// The direction at angle `beta`, reduced to `[0, pi)` (a chord has no orientation sign).
    pub fn from_angle(beta: f64) -> Self {
        let beta = beta.rem_euclid(std::f64::consts::PI);
        Self::from_cos_sin(beta.cos(), beta.sin())
    }

    /// `sin` must be `>= 0`, i.e. the angle lies in `[0, pi)`.
    pub fn from_cos_sin(cos: f64, sin: f64) -> Self {
        ChordDirection { cos_positive: cos > 0.0, inv_abs_cos: 1.0 / cos.abs(), inv_sin: 1.0 / sin }
    }
}

impl ChordDirection<f32> {
    /// `sin` must be `>= 0`.
    pub fn from_cos_sin(cos: f32, sin: f32) -> Self {
        ChordDirection { cos_positive: cos > 0.0, inv_abs_cos: 1.0 / cos.abs(), inv_sin: 1.0 / sin }
    }
}

/// The chord of the `w x h` rectangle through the local point `(p, q)` along `dir`: the lengths
/// `(backward, forward)` from the point to the rectangle's boundary (docs/mathematics.md section 2, closed form).
///
/// forward = min(fx / |cos|, (h - q) / sin), backward = min(bx / |cos|, q / sin), with
/// (fx, bx) = (w - p, p) when cos > 0 and (p, w - p) otherwise. On an axis one reciprocal is
/// infinite; a zero distance times it is NaN, which `min_num` ignores: exactly right, because a
/// line parallel to an edge is not bounded by it. The point must lie in the rectangle.
#[inline(always)]
pub fn chord_extent<T: Real>(w: T, h: T, p: T, q: T, dir: &ChordDirection<T>) -> (T, T) {
    let (fx, bx) = if dir.cos_positive { (w - p, p) } else { (p, w - p) };
    let forward = (fx * dir.inv_abs_cos).min_num((h - q) * dir.inv_sin);
    let backward = (bx * dir.inv_abs_cos).min_num(q * dir.inv_sin);
    // Rounding can put a point a hair outside; a chord length is never negative.
    let clamp = |x: T| if x > T::ZERO { x } else { T::ZERO };
    (clamp(backward), clamp(forward))
}

/// The chord width `width(beta, (p, q))` of docs/mathematics.md section 2.
#[inline(always)]
pub fn chord_width<T: Real + std::ops::Add<Output = T>>(w: T, h: T, p: T, q: T, dir: &ChordDirection<T>) -> T {
    let (b, f) = chord_extent(w, h, p, q, dir);
    b + f
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::PI;

    use crate::quadrature::chord_width_by_clipping as chord_by_clipping;

    #[test]
    fn chord_width_matches_clipping_at_random_points() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        for _ in 0..100_000 {
            let (w, h) = (rng.random_range(0.01..10.0), rng.random_range(0.01..10.0));
            let (p, q) = (rng.random::<f64>() * w, rng.random::<f64>() * h);
            let beta = rng.random::<f64>() * PI;
            let got = chord_width(w, h, p, q, &ChordDirection::from_angle(beta));
            let want = chord_by_clipping(w, h, p, q, beta);
            assert!((got - want).abs() <= 1e-9 * (w + h), "w={w} h={h} p={p} q={q} beta={beta}: {got} vs {want}");
        }
    }

    #[test]
    fn chord_width_on_edges_corners_and_axes() {
        let (w, h) = (3.0f64, 2.0f64);
        let points = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h), (0.0, 1.0), (w, 1.5), (1.2, 0.0), (2.5, h)];
        let angles = [0.0, PI / 2.0, PI / 4.0, 3.0 * PI / 4.0, 1e-12, PI - 1e-12, (h / w).atan(), PI - (h / w).atan()];
        for &(p, q) in &points {
            for &beta in &angles {
                let got = chord_width(w, h, p, q, &ChordDirection::from_angle(beta));
                let want = chord_by_clipping(w, h, p, q, beta);
                assert!(got.is_finite() && got >= 0.0);
                assert!((got - want).abs() <= 1e-9, "p={p} q={q} beta={beta}: {got} vs {want}");
            }
        }
        // A line exactly along an edge spans the whole edge (min_num ignores 0 * inf). At the
        // rounded angle pi/2 (cos = 6e-17) the line leaves at once, as clipping agrees above.
        assert_eq!(chord_width(w, h, 0.0, 0.7, &ChordDirection::<f64>::from_cos_sin(0.0, 1.0)), h);
        assert_eq!(chord_width(w, h, 1.0, 0.0, &ChordDirection::<f64>::from_cos_sin(1.0, 0.0)), w);
    }

    #[test]
    fn chord_width_f32_agrees_with_f64() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(8);
        for _ in 0..10_000 {
            let (w, h) = (rng.random_range(0.01..10.0), rng.random_range(0.01..10.0));
            let (p, q) = (rng.random::<f64>() * w, rng.random::<f64>() * h);
            let beta = rng.random::<f64>() * PI;
            let d64 = chord_width(w, h, p, q, &ChordDirection::from_angle(beta));
            let dir32 = ChordDirection::<f32>::from_cos_sin(beta.cos() as f32, beta.sin() as f32);
            let d32 = chord_width(w as f32, h as f32, p as f32, q as f32, &dir32) as f64;
            assert!((d64 - d32).abs() <= 1e-4 * (w + h) + 1e-5 * d64);
        }
    }

    #[test]
    fn ray_hits_panel_from_both_sides() {
        let l = RectLight::new("l", DVec3::ZERO, DVec3::X * 2.0, DVec3::Z, DVec3::ONE);
        // n = x cross z = -y.
        assert!((l.n - DVec3::NEG_Y).length() < 1e-12);
        let t = l.intersect(DVec3::new(1.0, 3.0, 0.5), DVec3::NEG_Y, 0.0, f64::INFINITY);
        assert_eq!(t, Some(3.0));
        let t = l.intersect(DVec3::new(1.0, -2.0, 0.5), DVec3::Y, 0.0, f64::INFINITY);
        assert_eq!(t, Some(2.0));
        assert_eq!(l.intersect(DVec3::new(3.0, -2.0, 0.5), DVec3::Y, 0.0, f64::INFINITY), None);
        assert_eq!(l.intersect(DVec3::new(1.0, -2.0, 0.5), DVec3::Y, 0.0, 1.5), None);
    }

    /// The crossing that rejects a panel behind the ray before dividing gives what dividing
    /// first gives, bit for bit: random rays from both sides, on the panel's plane, grazing it,
    /// from tiny and huge distances, with signed zeros, against f64 and f32 panels.
    #[test]
    fn rejecting_before_the_division_changes_no_crossing() {
        fn dividing_first<T: Real>(r: &Rectangle<T>, o: V3<T>, d: V3<T>, t_min: T, t_max: T) -> Option<T> {
            let denom = dot(d, r.n);
            if denom == T::ZERO {
                return None;
            }
            let c = r.corner;
            let t = dot([c[0] - o[0], c[1] - o[1], c[2] - o[2]], r.n) / denom;
            if !(t > t_min && t < t_max) {
                return None;
            }
            let rel = [(o[0] + t * d[0]) - c[0], (o[1] + t * d[1]) - c[1], (o[2] + t * d[2]) - c[2]];
            let (p, q) = (dot(rel, r.u), dot(rel, r.v));
            (p >= T::ZERO && p <= r.width && q >= T::ZERO && q <= r.height).then_some(t)
        }
        let l = RectLight::new("l", DVec3::new(-1.0, 0.5, 2.0), DVec3::new(2.0, 0.0, 1.0), DVec3::Z * 0.5, DVec3::ONE);
        let (r64, r32) = (l.rectangle(), {
            let r = l.rectangle();
            let f = |v: [f64; 3]| v.map(|x| x as f32);
            Rectangle {
                corner: f(r.corner),
                u: f(r.u),
                v: f(r.v),
                n: f(r.n),
                width: r.width as f32,
                height: r.height as f32,
            }
        });
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(9);
        let (mut hits, mut cases) = (0, 0);
        for i in 0..200_000 {
            let scale = [1e-200, 1e-8, 1.0, 1e8][i % 4];
            let mut o: [f64; 3] = std::array::from_fn(|_| rng.random_range(-3.0..3.0));
            let mut d: [f64; 3] = std::array::from_fn(|_| rng.random_range(-1.0..1.0) * scale);
            match i % 7 {
                0 => o = [0.0, 0.5, 2.0],                 // on the panel's plane (its corner's)
                1 => d = [2.0 * scale, 0.0, 1.0 * scale], // along the panel
                2 => d = [-0.0, 0.0, -0.0],
                _ => {}
            }
            let (t_min, t_max) = [(0.0, f64::INFINITY), (1e-9, 2.0), (0.0, 0.0), (-1.0, 5.0)][i % 4];
            let got = r64.crossing(o, d, t_min, t_max);
            assert_eq!(
                got.map(f64::to_bits),
                dividing_first(&r64, o, d, t_min, t_max).map(f64::to_bits),
                "{o:?} {d:?}"
            );
            let (o, d) = (o.map(|x| x as f32), d.map(|x| x as f32));
            let (t_min, t_max) = (t_min as f32, t_max as f32);
            let got32 = r32.crossing(o, d, t_min, t_max);
            assert_eq!(got32.map(f32::to_bits), dividing_first(&r32, o, d, t_min, t_max).map(f32::to_bits));
            hits += got.is_some() as usize;
            cases += 1;
        }
        assert!(hits > cases / 50, "{hits} crossings of {cases}: the rays reach the panel");
    }
}
