//! The pinhole camera (docs/mathematics.md section 7).

use glam::{DVec3, Vec3};

/// A camera ray: unit direction (f32, origin at the camera) and its segment `[t0, t1]` inside
/// the medium before the first light panel (empty, `t0 > t1`, when there is none). Both ends
/// are finite (the medium is a bounded box): the hit test relies on it. Plain data: it crosses
/// to the GPU as it is (`gpu/gather.wgsl`'s `RAY_FLOATS`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct CameraRay {
    pub dir: Vec3,
    pub t0: f32,
    pub t1: f32,
}

/// Writes a row of camera rays: `row(j, out)` fills `out` with row `j` of a ray set (made by
/// `pixel::with_ray_rows`, written where the caller keeps them: a slice, or the GPU's upload
/// buffer).
pub type RayRowFn<'r> = &'r (dyn Fn(usize, &mut [CameraRay]) + Sync);

#[derive(Clone, Debug)]
pub struct Camera {
    pub position: DVec3,
    /// Orthonormal frame: forward f, right r = normalize(f x up), true up up' = r x f.
    pub forward: DVec3,
    pub right: DVec3,
    pub up: DVec3,
    /// tan(vfov / 2).
    pub tan_half_fov: f64,
    pub width: u32,
    pub height: u32,
}

/// `v` ready for glam's `normalize`, which squares it and so fails beyond about 1e154 or below
/// 1e-154 (an `up` of [0, 1e308, 0] is the direction [0, 1, 0], and was refused as zero): `v`
/// itself where its largest component lies in [1e-150, 1e150] (the same bits for every
/// ordinary vector), else `v` over that component. None for zero or a vector not finite.
pub(crate) fn tamed(v: DVec3) -> Option<DVec3> {
    let m = v.abs().max_element();
    if !(m > 0.0 && m.is_finite()) {
        return None;
    }
    Some(if (1e-150..=1e150).contains(&m) { v } else { v / m })
}

impl Camera {
    /// The scene validates that `look_at != position` and that `up` is not parallel to the view.
    pub fn new(position: DVec3, look_at: DVec3, up: DVec3, vfov_deg: f64, width: u32, height: u32) -> Self {
        let view = look_at - position;
        let forward = tamed(view).unwrap_or(view).normalize();
        let right = tamed(forward.cross(tamed(up).unwrap_or(up))).unwrap_or(DVec3::ZERO).normalize();
        Camera {
            position,
            forward,
            right,
            up: right.cross(forward),
            tan_half_fov: (vfov_deg.to_radians() * 0.5).tan(),
            width,
            height,
        }
    }

    pub fn aspect(&self) -> f64 {
        self.width as f64 / self.height as f64
    }

    /// The unnormalised direction through image point `(x, y)` in pixel units (pixel (i, j)
    /// covers `[i, i+1] x [j, j+1]`): f + X tan_h aspect r + Y tan_h up', X = 2x/w - 1,
    /// Y = 1 - 2y/h. Its component along f is exactly 1.
    pub fn direction(&self, x: f64, y: f64) -> DVec3 {
        let sx = (2.0 * x / self.width as f64 - 1.0) * self.tan_half_fov * self.aspect();
        let sy = (1.0 - 2.0 * y / self.height as f64) * self.tan_half_fov;
        self.forward + sx * self.right + sy * self.up
    }

    /// Camera-space coordinates (along r, up', f) of a world point.
    pub fn to_camera(&self, p: DVec3) -> DVec3 {
        let d = p - self.position;
        DVec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.forward))
    }

    /// Image point (pixel units) of a camera-space point with positive depth: the inverse of
    /// [`Camera::direction`].
    pub fn project(&self, c: DVec3) -> (f64, f64) {
        let sx = c.x / (c.z * self.tan_half_fov * self.aspect());
        let sy = c.y / (c.z * self.tan_half_fov);
        ((sx + 1.0) * 0.5 * self.width as f64, (1.0 - sy) * 0.5 * self.height as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_inverts_direction_and_centre_looks_forward() {
        let cam = Camera::new(DVec3::new(0.0, 3.0, 11.0), DVec3::new(0.0, 2.5, 0.0), DVec3::Y, 45.0, 640, 360);
        let centre = cam.direction(320.0, 180.0).normalize();
        assert!((centre - cam.forward).length() < 1e-12);
        for &(x, y) in &[(0.0, 0.0), (12.25, 300.5), (639.9, 1.0)] {
            let p = cam.position + 7.0 * cam.direction(x, y);
            let (px, py) = cam.project(cam.to_camera(p));
            approx::assert_abs_diff_eq!(px, x, epsilon = 1e-9);
            approx::assert_abs_diff_eq!(py, y, epsilon = 1e-9);
        }
        // Row 0 is the top of the image, column 0 the left.
        assert!(cam.direction(0.0, 0.0).dot(cam.up) > 0.0);
        assert!(cam.direction(0.0, 0.0).dot(cam.right) < 0.0);
    }
}
