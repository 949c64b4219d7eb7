//! The homogeneous medium (docs/mathematics.md section 1): an axis-aligned box of fog, vacuum outside.

use glam::DVec3;

/// Isotropic phase function rho = 1 / (4 pi).
pub const PHASE: f64 = 1.0 / (4.0 * std::f64::consts::PI);

/// The largest `abs(g)` a scene may ask for: at 0.99 the phase function already spans more than
/// six orders of magnitude (docs/mathematics.md section 1.1).
pub const G_MAX: f64 = 0.99;

#[derive(Clone)]
pub struct Medium {
    pub min: DVec3,
    pub max: DVec3,
    /// Scattering and absorption coefficients per unit length, RGB.
    pub sigma_s: DVec3,
    pub sigma_a: DVec3,
    /// The Henyey-Greenstein asymmetry in [-G_MAX, G_MAX]; 0 is isotropic, positive scatters
    /// forward (docs/mathematics.md section 1.1).
    pub g: f64,
}

/// As derived, with `g` written only when it is not 0: the scene's fingerprint
/// ([`crate::scene::Scene::fingerprint`]) of an isotropic medium stays what it was before `g`.
impl std::fmt::Debug for Medium {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut d = f.debug_struct("Medium");
        d.field("min", &self.min)
            .field("max", &self.max)
            .field("sigma_s", &self.sigma_s)
            .field("sigma_a", &self.sigma_a);
        if self.g != 0.0 {
            d.field("g", &self.g);
        }
        d.finish()
    }
}

/// The Henyey-Greenstein phase function (docs/mathematics.md section 1.1), per steradian:
/// `(1 - g^2) / (4 pi (1 + g^2 - 2 g mu)^(3/2))`, `mu` the cosine of the scattering angle, between
/// the direction the light travels before the scattering and the direction it leaves in (toward
/// the eye). `g = 0` is [`PHASE`]. In f64, for the reference renderer and the quadrature; the
/// gather has its own f32 form (`gather::Phase`).
pub fn henyey_greenstein(g: f64, mu: f64) -> f64 {
    if g == 0.0 {
        return PHASE;
    }
    let denom = 1.0 + g * g - 2.0 * g * mu.clamp(-1.0, 1.0);
    PHASE * (1.0 - g * g) / (denom * denom.sqrt())
}

impl Medium {
    /// Extinction sigma_t = sigma_s + sigma_a.
    pub fn sigma_t(&self) -> DVec3 {
        self.sigma_s + self.sigma_a
    }

    /// Transmittance exp(-sigma_t * length) for a length travelled inside the box.
    pub fn transmittance(&self, length: f64) -> DVec3 {
        (-self.sigma_t() * length).exp()
    }

    /// The parameter interval `[t0, t1]` of the ray `o + t d` (t >= 0) inside the box, if any.
    /// Slab test; a zero direction component is handled by comparing the origin with the slab.
    pub fn clip_ray(&self, o: DVec3, d: DVec3) -> Option<(f64, f64)> {
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for axis in 0..3 {
            let (lo, hi, oa, da) = (self.min[axis], self.max[axis], o[axis], d[axis]);
            if da == 0.0 {
                if oa < lo || oa > hi {
                    return None;
                }
                continue;
            }
            let (a, b) = ((lo - oa) / da, (hi - oa) / da);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        (t0 <= t1).then_some((t0, t1))
    }

    /// Length of the segment from `a` to `b` that lies inside the box.
    pub fn length_inside(&self, a: DVec3, b: DVec3) -> f64 {
        let len = (b - a).length();
        if len == 0.0 {
            return 0.0;
        }
        match self.clip_ray(a, (b - a) / len) {
            Some((t0, t1)) => (t1.min(len) - t0).max(0.0),
            None => 0.0,
        }
    }

    pub fn contains(&self, p: DVec3, tolerance: f64) -> bool {
        (p.cmpge(self.min - tolerance) & p.cmple(self.max + tolerance)).all()
    }

    /// The phase function for light travelling along `travel` that scatters toward `out` (both
    /// unit): [`henyey_greenstein`] with `mu = travel . out`.
    pub fn phase(&self, travel: DVec3, out: DVec3) -> f64 {
        henyey_greenstein(self.g, travel.dot(out))
    }

    /// The box diagonal: no segment inside the box is longer.
    pub fn diagonal(&self) -> f64 {
        (self.max - self.min).length()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_box() -> Medium {
        Medium { min: DVec3::ZERO, max: DVec3::ONE, sigma_s: DVec3::splat(0.5), sigma_a: DVec3::splat(0.5), g: 0.0 }
    }

    #[test]
    fn clip_ray_from_outside_inside_and_parallel() {
        let m = unit_box();
        let (t0, t1) = m.clip_ray(DVec3::new(-1.0, 0.5, 0.5), DVec3::X).unwrap();
        approx::assert_relative_eq!(t0, 1.0, max_relative = 1e-12);
        approx::assert_relative_eq!(t1, 2.0, max_relative = 1e-12);
        let (t0, t1) = m.clip_ray(DVec3::splat(0.5), DVec3::Y).unwrap();
        assert_eq!(t0, 0.0);
        approx::assert_relative_eq!(t1, 0.5, max_relative = 1e-12);
        assert!(m.clip_ray(DVec3::new(-1.0, 2.0, 0.5), DVec3::X).is_none());
        assert!(m.clip_ray(DVec3::new(2.0, 0.5, 0.5), DVec3::X).is_none());
        // On the boundary, looking along it.
        let (t0, t1) = m.clip_ray(DVec3::new(-1.0, 1.0, 0.5), DVec3::X).unwrap();
        assert!((t0 - 1.0).abs() < 1e-12 && (t1 - 2.0).abs() < 1e-12);
    }

    #[test]
    fn length_inside_and_transmittance() {
        let m = unit_box();
        let l = m.length_inside(DVec3::new(-1.0, 0.5, 0.5), DVec3::new(0.25, 0.5, 0.5));
        assert!((l - 0.25).abs() < 1e-12);
        assert!((m.transmittance(2.0) - DVec3::splat((-2.0f64).exp())).length() < 1e-15);
    }
}
