//! One camera ray against one photon plane: the hit test and the weighted contribution
//! `C = eta / (N P_l D)` of docs/mathematics.md section 2, summed without its factor `power / N`,
//! which is the same for every plane of a light and is applied once per light. Everything here
//! is f32 and relative to the ray origin, prepared once per plane so that a hit costs a few dot
//! products and one exponential.
//!
//! The per-hit arithmetic is written once, here, branch-free, for a block of rays at a time as
//! a vector of lanes ([`crate::simd::Lanes`]): [`PlaneJob::gather_block`] runs
//! [`PlaneView::cross`] (where the rays meet the plane and which of them hit), the visibility
//! test of planes another panel can shadow ([`Occluder::blocks_lanes`]), the estimator's D
//! ([`Denominator::denominators_of`]) and [`PlaneView::contribution`] (the transmittance and the
//! finite check). The vector kernels of [`crate::kernel`] call it with 16 lanes in AVX-512 or
//! AVX2 registers (or an array, for the portable kernel); the per-hit paths with one lane, `f32`:
//! the BVH and the brute-force loop through [`GatherContext::gather_one`], the raster's
//! `per-hit` kernel through [`PlaneJob::gather_block_in`]. Every lane does the same operations
//! in the same order whatever the width, so a hit's contribution is the same bits whichever
//! path found it, and the raster's kernels and the brute-force loop, which also sum in one
//! order, give bit-identical images (the BVH sums in the order of its traversal).
//!
//! Multiply-adds are fused where written ([`Lanes::mul_add`]: 5-7% of the gathering time of the
//! fast estimators, 10% of cmis-exact's); fused multiply-adds are exactly rounded, so the paths
//! still agree, but where the code is compiled without FMA (the portable kernel and the per-hit
//! paths on x86-64, whose baseline lacks it) each is a library call: the portable kernel, chosen
//! only on x86-64 CPUs without AVX2 (before 2013), became 10x slower.
//!
//! # Sums light by light
//!
//! The raster's kernels and the brute-force loop sum a ray's hits in one order, so that they
//! agree bit for bit: light by light in index order, and within a light its planes in index
//! order, each hit's contribution without the light's power `power / N`
//! ([`PlaneView::contribution`], in f32); then, light by light, that sum times the light's
//! `scale` is added to the ray's RGB sum ([`add_light`], in f32; a light without hits adds
//! exactly zero). The raster ([`crate::raster`]) keeps its bands' planes in that order, and
//! [`GatherContext::gather_brute_force`] takes them so; the BVH multiplies each hit by its
//! scale. Every plane of a light has the same scale, so in a grey medium a block of hits loads,
//! adds and stores one sum instead of three, and multiplies by no scale: 8-9% of the
//! benchmark's CPU time.

use crate::camera::CameraRay;
use crate::control::Control;
use crate::limits::PLANE_UNIT;
use crate::numeric::exp_lanes;
use crate::occlusion::{Occluder, possible_occluders};
use crate::photon_plane::PhotonPlane;
use crate::scene::Scene;
use crate::simd::{Lanes, Mask};
use crate::weights::{Denominator, PlaneFrame};
use glam::{DVec3, Vec3};

/// A plane prepared for rays from one origin `o`.
///
/// With b = y0 - o and the plane normal n_P = d x wl, the hit `o + t we = y0 + a d + r wl` solves
/// by Cramer's rule with the common determinant det = we . n_P (det(alpha) of section 2):
/// t det = b . n_P, a det = we . (wl x b), r det = we . (b x d).
#[derive(Clone, Copy, Debug)]
pub struct PlaneView {
    pub normal: Vec3,
    /// (d(alpha_perp) x wl) with d(alpha_perp) = -sin(alpha) u + cos(alpha) v: det(alpha_perp).
    pub normal_perp: Vec3,
    pub a_axis: Vec3,
    pub r_axis: Vec3,
    pub t_det: f32,
    /// The sweep direction wl times the sign of g (+1 for g = 0), for the phase function
    /// ([`Phase`]): the same for every orientation that makes a hit, like the hit's path.
    pub toward: Vec3,
    /// `1 / ((1 - g^2) m)`, m the plane's [`PhotonPlane::direction_weight`]: the phase factor's
    /// constant ([`Phase`]) with the weight of the way the plane's direction was drawn, which
    /// only a medium that is not isotropic has (docs/mathematics.md section 2.5).
    pub phase_scale: f32,
    pub frame: PlaneFrame,
    /// power / N: the hit-independent factor of C, the same for every plane of a light (the
    /// raster and the brute-force loop apply it once per light, see [`PlaneJob::gather_block`]).
    pub scale: Vec3,
    /// The largest component of `scale`.
    pub scale_max: f32,
    /// The plane's light.
    pub light: u32,
    /// The panels that may shadow the plane: `GatherContext::occluders[start..end]`, empty for
    /// most planes.
    pub occluders_start: u32,
    pub occluders_end: u32,
}

/// A [`PlaneView`] as the GPU reads it: the one definition of what crosses for a plane
/// (`gpu/gather.wgsl`'s `Plane`, nine rows of 16 bytes; the occluders cross as [`Occluder`]s).
/// The same f32 values as the view, except that a reciprocal the CPU lets be infinite (a chord
/// direction along an axis) is 0 here, and the shader reads 0 as infinite: Vulkan does not
/// promise IEEE infinities.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PlaneRecord {
    pub normal: [f32; 3],
    pub t_det: f32,
    pub a_axis: [f32; 3],
    pub width: f32,
    pub r_axis: [f32; 3],
    pub occluders_start: u32,
    pub normal_perp: [f32; 3],
    pub occluders_end: u32,
    pub scale: [f32; 3],
    pub scale_max: f32,
    pub cos_a: f32,
    pub sin_a: f32,
    pub p0: f32,
    pub q0: f32,
    pub light_w: f32,
    pub light_h: f32,
    /// 1 / |cos(alpha_perp)| and 1 / sin(alpha_perp), 0 for infinite (or above 1e30).
    pub perp_inv_abs_cos: f32,
    pub perp_inv_sin: f32,
    pub perp_cos_positive: u32,
    /// cmis-exact's unit of length, W + H, and its reciprocal (weights `CmisPlane`).
    pub unit: f32,
    pub inv_unit: f32,
    pub light: u32,
    /// [`PlaneView::toward`] and [`PlaneView::phase_scale`], for the phase function.
    pub toward: [f32; 3],
    pub phase_scale: f32,
}

impl From<&PlaneView> for PlaneRecord {
    fn from(v: &PlaneView) -> Self {
        let f = &v.frame;
        let finite = |x: f32| if x.is_finite() && x <= 1e30 { x } else { 0.0 };
        let unit = f.light_w + f.light_h;
        PlaneRecord {
            normal: v.normal.to_array(),
            t_det: v.t_det,
            a_axis: v.a_axis.to_array(),
            width: f.width,
            r_axis: v.r_axis.to_array(),
            occluders_start: v.occluders_start,
            normal_perp: v.normal_perp.to_array(),
            occluders_end: v.occluders_end,
            scale: v.scale.to_array(),
            scale_max: v.scale_max,
            cos_a: f.cos_a,
            sin_a: f.sin_a,
            p0: f.p0,
            q0: f.q0,
            light_w: f.light_w,
            light_h: f.light_h,
            perp_inv_abs_cos: finite(f.perp.inv_abs_cos),
            perp_inv_sin: finite(f.perp.inv_sin),
            perp_cos_positive: f.perp.cos_positive as u32,
            unit,
            inv_unit: finite(1.0 / unit),
            light: v.light,
            toward: v.toward.to_array(),
            phase_scale: v.phase_scale,
        }
    }
}

/// A block of camera rays, one per lane: unit directions and segments `[t0, t1]`.
#[derive(Clone, Copy, Debug)]
pub struct RayBlock<V> {
    pub x: V,
    pub y: V,
    pub z: V,
    pub t0: V,
    pub t1: V,
}

impl<V> RayBlock<V> {
    /// `dir . v`, summed x, y, z in that order.
    #[inline(always)]
    pub fn dot<const L: usize>(&self, v: Vec3) -> V
    where
        V: Lanes<L>,
    {
        self.z.mul_add(V::splat(v.z), self.y.mul_add(V::splat(v.y), self.x * V::splat(v.x)))
    }
}

impl RayBlock<f32> {
    pub fn one(ray: &CameraRay) -> Self {
        RayBlock { x: ray.dir.x, y: ray.dir.y, z: ray.dir.z, t0: ray.t0, t1: ray.t1 }
    }
}

/// Where rays meet a plane, computed whether or not they hit (the values are then harmless
/// and unused): camera distance t, chord parameter a, plane distance r (section 2) and
/// det(alpha), with the lanes that hit.
#[derive(Clone, Copy, Debug)]
pub struct Crossing<V, M = bool> {
    pub hit: M,
    pub det: V,
    pub t: V,
    pub a: V,
    pub r: V,
}

impl PlaneView {
    /// `occluders`: the plane's range in [`GatherContext::occluders`].
    pub fn new(plane: &PhotonPlane, scene: &Scene, origin: DVec3, planes_total: usize, occluders: (u32, u32)) -> Self {
        let light = &scene.lights[plane.light];
        let sign = if scene.medium.g < 0.0 { -1.0 } else { 1.0 };
        let b = plane.origin - origin;
        let normal = plane.chord.cross(plane.direction);
        let (sin_a, cos_a) = (plane.sin_alpha, plane.cos_alpha);
        let chord_perp = -sin_a * light.u + cos_a * light.v;
        PlaneView {
            normal: normal.as_vec3(),
            normal_perp: chord_perp.cross(plane.direction).as_vec3(),
            a_axis: plane.direction.cross(b).as_vec3(),
            r_axis: b.cross(plane.chord).as_vec3(),
            t_det: b.dot(normal) as f32,
            toward: (sign * plane.direction).as_vec3(),
            phase_scale: (1.0 / ((1.0 - scene.medium.g * scene.medium.g) * plane.direction_weight)) as f32,
            frame: PlaneFrame::from_cos_sin(plane.width, cos_a, sin_a, plane.p0, plane.q0, light.width, light.height),
            scale: (plane.power / planes_total as f64).as_vec3(),
            scale_max: (plane.power / planes_total as f64).as_vec3().max_element(),
            light: plane.light as u32,
            occluders_start: occluders.0,
            occluders_end: occluders.1,
        }
    }

    /// Whether another panel may shadow the plane.
    pub fn may_be_shadowed(&self) -> bool {
        self.occluders_end > self.occluders_start
    }

    /// Where the ray with unit direction `dir` meets the plane: [`PlaneView::cross`] with one
    /// lane.
    #[inline(always)]
    pub fn crossing(&self, dir: [f32; 3], t0: f32, t1: f32) -> Crossing<f32> {
        self.cross::<1, f32>(&RayBlock { x: dir[0], y: dir[1], z: dir[2], t0, t1 })
    }

    /// Where each ray of a block meets the plane, and whether that is a hit: inside `[t0, t1]`,
    /// on the chord (`0 <= a <= width`) and strictly in front of the light (r > 0).
    ///
    /// A hit at r = 0 lies on the light itself: only a camera ray lying in the light's own plane
    /// meets planes there, and along such a ray cos(theta_y) = 0, so the integrand of section 1
    /// vanishes; counting the hit would add light that is not there.
    #[inline(always)]
    pub fn cross<const L: usize, V: Lanes<L>>(&self, ray: &RayBlock<V>) -> Crossing<V, V::Mask> {
        let s = V::splat;
        let det = ray.dot(self.normal);
        let inv = s(1.0) / det;
        let t = s(self.t_det) * inv;
        let a = ray.dot(self.a_axis) * inv;
        let r = ray.dot(self.r_axis) * inv;
        // det = 0 needs no test of its own: t is then infinite or NaN, outside the finite
        // segment [t0, t1].
        let hit = t.ge(ray.t0) & t.le(ray.t1) & a.ge(s(0.0)) & a.le(s(self.frame.width)) & r.gt(s(0.0));
        Crossing { hit, det, t, a, r }
    }

    /// The contribution C of hits (section 2), `power Tr_cam(t) Tr(x, y') / (N D)`, without
    /// its factor `power / N` ([`PlaneView::scale`]): `Tr_cam(t) Tr(x, y') / D` per channel,
    /// with `Tr_cam(t) Tr(x, y') = exp(-sigma_t length)`, `length = (t - t0) + r` (both segments
    /// lie inside the box). Zero unless `lit` (a hit whose light path no panel blocks) with D > 0
    /// and a finite C: D vanishes, or underflows to a denormal, only on a set of probability ~0,
    /// and such a hit adds nothing rather than an infinity. In a grey medium the three channels
    /// are one value.
    ///
    /// In a medium that is not isotropic, `d` is `D' = D / (4 pi rho)`, the phase value divided
    /// into D ([`Phase::divide`]; section 1.1: one more division avoided), positive and finite
    /// wherever D is.
    #[inline(always)]
    pub fn contribution<const L: usize, V: Lanes<L>, const GREY: bool>(
        &self,
        sigma_t: Vec3,
        length: V,
        d: V,
        lit: V::Mask,
    ) -> [V; 3] {
        let (s, scale, zero) = (V::splat, self.scale, V::splat(0.0));
        let lit = lit & d.gt(zero);
        if GREY {
            // One check serves the three channels: the scales are finite and non-negative, so
            // every scale * q is finite exactly when the largest is (rounding is monotone).
            let q = exp_lanes::<L, V>(s(-sigma_t.x) * length) / d;
            let q = V::select(lit & (s(self.scale_max) * q).is_finite(), q, zero);
            return [q, q, q];
        }
        let (qr, qg, qb) = (
            exp_lanes::<L, V>(s(-sigma_t.x) * length) / d,
            exp_lanes::<L, V>(s(-sigma_t.y) * length) / d,
            exp_lanes::<L, V>(s(-sigma_t.z) * length) / d,
        );
        let keep = lit & (s(scale.x) * qr).is_finite() & (s(scale.y) * qg).is_finite() & (s(scale.z) * qb).is_finite();
        [V::select(keep, qr, zero), V::select(keep, qg, zero), V::select(keep, qb, zero)]
    }
}

/// The Henyey-Greenstein phase function as the gather evaluates it, in f32 (docs/mathematics.md
/// section 1.1): for a hit on a plane with sweep direction `wl` seen along `we`, the ratio to the
/// isotropic `1 / (4 pi)` already in the plane's power is
///
/// ```text
/// 4 pi rho = (1 - g^2) / (1 + g^2 + 2 g (we . wl))^(3/2)
///          = (1 - g^2) / ((1 - |g|)^2 + |g| |we + sign(g) wl|^2)^(3/2)
/// ```
///
/// The second form has no cancellation at the peak (`we = -sign(g) wl`), where the first
/// subtracts numbers near `(1 + |g|)^2` to leave `(1 - |g|)^2`, 1e-4 at |g| = 0.99: both vectors
/// are unit, so `|we + w|^2 = 2 + 2 we . w`, a sum of squares that is never negative.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Phase {
    /// g, as the scene gives it, in f32.
    pub g: f32,
    /// `abs(g)`.
    pub h: f32,
    /// `(1 - abs(g))^2`, the smallest value of the bracket.
    pub floor: f32,
    /// Whether the scene's g (f64) is 0: then the gather takes its isotropic path. Not `g` in
    /// f32, which is 0 for a valid g of 1e-300 whose lights still have lobes: their planes'
    /// direction weights, in `phase_scale`, would be dropped (the bracket is 1 there).
    isotropic: bool,
}

impl Phase {
    pub fn new(g: f64) -> Self {
        let h = g.abs();
        Phase { g: g as f32, h: h as f32, floor: ((1.0 - h) * (1.0 - h)) as f32, isotropic: g == 0.0 }
    }

    pub fn is_isotropic(&self) -> bool {
        self.isotropic
    }

    /// `D' = D / (4 pi rho m)` for each ray of the block against a plane whose
    /// [`PlaneView::toward`] is `toward` and [`PlaneView::phase_scale`] `scale` (sections 1.1
    /// and 2.5), or `d` itself, untouched, in an isotropic medium. D' is positive and finite
    /// wherever D is (4 pi rho lies in `[(1 - |g|) / (1 + |g|)^2, (1 + |g|) / (1 - |g|)^2]`,
    /// and m in `(0, 1 / (1 - share)]`).
    #[inline(always)]
    pub fn divide<const L: usize, V: Lanes<L>>(&self, d: V, ray: &RayBlock<V>, toward: Vec3, scale: f32) -> V {
        if self.is_isotropic() { d } else { d * self.inverse_lanes::<L, V>(ray, toward, scale) }
    }

    /// `1 / (4 pi rho m)` for each ray of the block against a plane whose
    /// [`PlaneView::toward`] is `toward`: `bracket^(3/2) scale`, `scale = 1 / ((1 - g^2) m)`, with
    /// `bracket = (1 - |g|)^2 + |g| |we + toward|^2`, in `[(1 - |g|)^2, (1 + |g|)^2]` (to
    /// rounding), so the result is positive and finite for |g| <= 0.99.
    #[inline(always)]
    pub fn inverse_lanes<const L: usize, V: Lanes<L>>(&self, ray: &RayBlock<V>, toward: Vec3, scale: f32) -> V {
        let s = V::splat;
        let (x, y, z) = (ray.x + s(toward.x), ray.y + s(toward.y), ray.z + s(toward.z));
        let squared = z.mul_add(z, y.mul_add(y, x * x));
        let bracket = s(self.h).mul_add(squared, s(self.floor));
        bracket * bracket.sqrt() * s(scale)
    }
}

/// One plane ready for the per-hit arithmetic: everything it reads that is the same for every
/// ray, gathered by [`GatherContext::job`]. A new per-plane constant is one field here.
pub struct PlaneJob<'a, D: Denominator> {
    pub weights: &'a D,
    /// `weights.prepare(&view.frame)`: what D needs of the plane, made once per plane and
    /// gathering call (the raster's planes cross many bands).
    pub prepared: &'a D::Plane,
    pub view: PlaneView,
    /// The panels that may shadow the plane (empty for most planes).
    pub occluders: &'a [Occluder],
    pub extinction: Extinction,
    pub phase: Phase,
}

impl<D: Denominator> Clone for PlaneJob<'_, D> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<D: Denominator> Copy for PlaneJob<'_, D> {}

impl<D: Denominator> PlaneJob<'_, D> {
    /// A block of rays against the plane: the per-hit arithmetic, once for every path that
    /// gathers. Adds each lane's contribution without the plane's `scale` (zero where a panel
    /// blocks the light path, [`PlaneView::contribution`]) to `sums` unless `CONTRIBUTE` is off,
    /// and returns how many lanes hit. `GREY`: one exponential serves the three channels (the
    /// caller has checked `extinction.grey`), and the one value goes to `sums[0]` alone.
    ///
    /// Every plane of a light has the same `scale`, so the caller sums a light's planes and
    /// multiplies once ([the sums light by light](self#sums-light-by-light)).
    ///
    /// In a medium that scatters anisotropically, each hit's contribution carries its phase
    /// value ([`Phase`]): a branch per block, not a copy of the kernel, whose isotropic side is
    /// the arithmetic it always was, bit for bit.
    #[inline(always)]
    pub fn gather_block<const L: usize, V: Lanes<L>, const GREY: bool, const CONTRIBUTE: bool>(
        &self,
        ray: &RayBlock<V>,
        sums: [&mut [f32; L]; 3],
    ) -> u32 {
        let view = &self.view;
        let c = view.cross::<L, V>(ray);
        // A block without a hit adds nothing (adding +0.0 would not change a sum either).
        if !CONTRIBUTE || !c.hit.any() {
            return c.hit.count();
        }
        let mut lit = c.hit;
        for o in self.occluders {
            lit = lit.and_not(o.blocks_lanes::<L, V>(c.a, c.r));
        }
        let det_perp = ray.dot(view.normal_perp);
        let d = self.weights.denominators_of::<L, V>(self.prepared, c.det, det_perp, c.a);
        let length = (c.t - ray.t0) + c.r;
        // The hit's path (y', x, the eye) is the same for every orientation that makes it, so
        // its phase value is a factor of C and no weight changes (section 1.1).
        let d = self.phase.divide::<L, V>(d, ray, view.toward, view.phase_scale);
        let contribution = view.contribution::<L, V, GREY>(self.extinction.sigma_t, length, d, lit);
        let channels = if GREY { 1 } else { 3 };
        for (sum, value) in sums.into_iter().zip(contribution).take(channels) {
            (V::load(sum) + value).store(sum);
        }
        c.hit.count()
    }

    /// [`PlaneJob::gather_block`] with the grey or RGB case of the medium's extinction chosen at
    /// run time (the vector kernels choose it once per plane instead).
    #[inline(always)]
    pub fn gather_block_in<const L: usize, V: Lanes<L>, const CONTRIBUTE: bool>(
        &self,
        ray: &RayBlock<V>,
        sums: [&mut [f32; L]; 3],
    ) -> u32 {
        if !CONTRIBUTE {
            // Counting hits needs neither the channels nor the phase function.
            return self.gather_block::<L, V, true, false>(ray, sums);
        }
        if self.extinction.grey {
            self.gather_block::<L, V, true, CONTRIBUTE>(ray, sums)
        } else {
            self.gather_block::<L, V, false, CONTRIBUTE>(ray, sums)
        }
    }
}

/// Extinction, with the common grey case (one exponential per hit) recognised.
#[derive(Clone, Copy, Debug)]
pub struct Extinction {
    pub sigma_t: Vec3,
    pub grey: bool,
}

impl Extinction {
    pub fn new(sigma_t: DVec3) -> Self {
        Extinction { sigma_t: sigma_t.as_vec3(), grey: sigma_t.x == sigma_t.y && sigma_t.y == sigma_t.z }
    }
}

/// Counters from one gathering pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GatherStats {
    /// Ray-plane tests made and hits found.
    pub tests: u64,
    pub hits: u64,
    /// Nanoseconds the device spent gathering, where one did (the GPU: its timestamps, or the
    /// wall time from a chunk's first submission to its sums read back where it has none); 0 on
    /// the CPU.
    pub device_ns: u64,
    /// Of `device_ns`, the gather's and its reduction's (the rest: the planes' reach and their
    /// binning), where the GPU has timestamps; else 0.
    pub device_gather_ns: u64,
    /// Nanoseconds of wall time spent uploading to the GPU (planes, ray sets' records or rays);
    /// 0 on the CPU.
    pub upload_ns: u64,
    /// Nanoseconds of wall time the CPU waited for the GPU's work to end (a chunk's sums read
    /// back, a ray set's gatherings before another is made); 0 on the CPU.
    pub wait_ns: u64,
    /// Bytes that crossed between the CPU and the GPU (planes and parameters up, sums and
    /// timestamps back), and the GPU's queue submissions; 0 on the CPU.
    pub bytes_crossed: u64,
    pub submissions: u64,
    /// The GPU's gather dispatches (a round of batches each, gpu/batches.rs); 0 on the CPU.
    pub dispatches: u64,
}

impl std::ops::AddAssign for GatherStats {
    fn add_assign(&mut self, o: Self) {
        self.tests += o.tests;
        self.hits += o.hits;
        self.device_ns += o.device_ns;
        self.device_gather_ns += o.device_gather_ns;
        self.upload_ns += o.upload_ns;
        self.wait_ns += o.wait_ns;
        self.bytes_crossed += o.bytes_crossed;
        self.submissions += o.submissions;
        self.dispatches += o.dispatches;
    }
}

/// All planes prepared for rays from one origin.
pub struct GatherContext {
    pub origin: DVec3,
    pub views: Vec<PlaneView>,
    /// The shadowing panels of every plane that may be shadowed, plane after plane (see
    /// [`PlaneView::occluders_start`]).
    pub occluders: Vec<Occluder>,
    pub extinction: Extinction,
    pub phase: Phase,
    /// The N of the set the planes belong to, once some are pushed: one N, so that every plane
    /// of a light has one scale (what the sums light by light rely on).
    planes_total: Option<usize>,
    /// The planes' indices light by light, each light's ascending: the brute-force loop's order,
    /// made by its first call after the last push (a counting sort of every view: made per
    /// push, it was a serial pass over all the context's views in every piece of every render).
    by_light: std::sync::OnceLock<Vec<u32>>,
}

impl GatherContext {
    /// Prepares `planes` (a set of N = planes.len()) for rays from `origin`.
    pub fn new(scene: &Scene, planes: &[PhotonPlane], origin: DVec3) -> Self {
        let mut ctx = GatherContext::empty(scene, origin);
        ctx.push_planes(scene, planes, planes.len());
        ctx
    }

    /// A context with no planes yet, for [`GatherContext::push_planes`].
    pub fn empty(scene: &Scene, origin: DVec3) -> Self {
        let extinction = Extinction::new(scene.medium.sigma_t());
        GatherContext {
            origin,
            views: Vec::new(),
            occluders: Vec::new(),
            extinction,
            phase: Phase::new(scene.medium.g),
            planes_total: None,
            by_light: std::sync::OnceLock::new(),
        }
    }

    /// Room for `planes` more planes' views, so that a context filled piece by piece is not
    /// copied as it grows.
    pub fn reserve(&mut self, planes: usize) {
        self.views.reserve(planes);
    }

    /// Prepares and appends the next planes of a set of `planes_total` planes (the same for every
    /// push: a context holds planes of one set).
    pub fn push_planes(&mut self, scene: &Scene, planes: &[PhotonPlane], planes_total: usize) {
        self.push_planes_in(scene, planes, planes_total, Control::none());
    }

    /// [`GatherContext::push_planes`] with its parallel loops recorded on `control`'s strand
    /// ([`crate::schedule`]), in units of [`PLANE_UNIT`] planes.
    pub fn push_planes_in(&mut self, scene: &Scene, planes: &[PhotonPlane], planes_total: usize, control: Control) {
        let masks = control.map_units("occluders", planes.len(), PLANE_UNIT, |i| possible_occluders(scene, &planes[i]));
        self.push_planes_with_occluders_in(scene, planes, &masks, planes_total, control);
    }

    /// [`GatherContext::push_planes`] with the lights that may shadow each plane given (a bit
    /// per light).
    pub fn push_planes_with_occluders(
        &mut self,
        scene: &Scene,
        planes: &[PhotonPlane],
        masks: &[u64],
        planes_total: usize,
    ) {
        self.push_planes_with_occluders_in(scene, planes, masks, planes_total, Control::none());
    }

    /// [`GatherContext::push_planes_with_occluders`] with its parallel loops recorded on
    /// `control`'s strand.
    pub fn push_planes_with_occluders_in(
        &mut self,
        scene: &Scene,
        planes: &[PhotonPlane],
        masks: &[u64],
        planes_total: usize,
        control: Control,
    ) {
        assert_eq!(planes.len(), masks.len(), "a mask per plane");
        let total = *self.planes_total.get_or_insert(planes_total);
        assert_eq!(total, planes_total, "the planes of a context belong to one set (one N)");
        // Each block of planes' panels made in parallel, then added in plane order.
        let blocks = control.map_units("occluders", planes.len().div_ceil(PLANE_UNIT), 1, |b| {
            let (mut panels, mut ends) = (Vec::new(), Vec::with_capacity(PLANE_UNIT));
            for i in b * PLANE_UNIT..((b + 1) * PLANE_UNIT).min(planes.len()) {
                let mut mask = masks[i];
                while mask != 0 {
                    let k = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    panels.extend(Occluder::new(&planes[i], &scene.lights[k]));
                }
                ends.push(panels.len() as u32);
            }
            (panels, ends)
        });
        let mut ranges = Vec::with_capacity(planes.len());
        for (panels, ends) in blocks {
            let base = self.occluders.len() as u32;
            let mut start = base;
            for end in ends {
                ranges.push((start, base + end));
                start = base + end;
            }
            self.occluders.extend(panels);
        }
        let origin = self.origin;
        control.extend_units("views", &mut self.views, planes.len(), PLANE_UNIT, |i| {
            PlaneView::new(&planes[i], scene, origin, planes_total, ranges[i])
        });
        self.by_light = std::sync::OnceLock::new();
    }

    /// Every plane by light, each light's in index order: a counting sort (a stable one).
    fn by_light(&self) -> &[u32] {
        self.by_light.get_or_init(|| {
            let lights = self.views.iter().map(|v| v.light as usize + 1).max().unwrap_or(0);
            let mut next = vec![0u32; lights + 1];
            for v in &self.views {
                next[v.light as usize + 1] += 1;
            }
            for l in 1..next.len() {
                next[l] += next[l - 1];
            }
            let mut order = vec![0u32; self.views.len()];
            for (i, v) in self.views.iter().enumerate() {
                order[next[v.light as usize] as usize] = i as u32;
                next[v.light as usize] += 1;
            }
            order
        })
    }

    /// The panels that may shadow a plane.
    #[inline(always)]
    pub fn occluders_of(&self, view: &PlaneView) -> &[Occluder] {
        &self.occluders[view.occluders_start as usize..view.occluders_end as usize]
    }

    /// The job of gathering `view` (one of this context's planes) with `weights`, which were
    /// prepared for it (`weights.prepare(&view.frame)`).
    #[inline(always)]
    pub fn job<'a, D: Denominator>(
        &'a self,
        weights: &'a D,
        view: &PlaneView,
        prepared: &'a D::Plane,
    ) -> PlaneJob<'a, D> {
        PlaneJob {
            weights,
            prepared,
            view: *view,
            occluders: self.occluders_of(view),
            extinction: self.extinction,
            phase: self.phase,
        }
    }

    /// The per-hit path: one ray against one plane. `None` if it misses; otherwise its
    /// contribution without the plane's `scale` ([`PlaneView::contribution`]), zero when another
    /// panel blocks the light path: [`PlaneJob::gather_block`] with one lane.
    #[inline(always)]
    pub fn gather_one<D: Denominator>(&self, weights: &D, view: &PlaneView, ray: &CameraRay) -> Option<Vec3> {
        let rays = RayBlock::one(ray);
        if !view.cross::<1, f32>(&rays).hit {
            return None;
        }
        let (mut r, mut g, mut b) = ([0.0f32], [0.0f32], [0.0f32]);
        let prepared = weights.prepare(&view.frame);
        self.job(weights, view, &prepared).gather_block_in::<1, f32, true>(&rays, [&mut r, &mut g, &mut b]);
        Some(if self.extinction.grey { Vec3::splat(r[0]) } else { Vec3::new(r[0], g[0], b[0]) })
    }

    /// The estimate for one ray by testing every plane (the reference path for tests), with the
    /// number of hits, summed as the raster sums them ([light by light](self#sums-light-by-light)).
    ///
    /// Compiled with FMA where the CPU has it: `f32::mul_add` is otherwise a call to the
    /// library's `fmaf` (the same bits, both correctly rounded), about a fifth of the brute
    /// force's time in tests/unbiasedness.rs.
    pub fn gather_brute_force<D: Denominator>(&self, weights: &D, ray: &CameraRay) -> (Vec3, u64) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU has FMA, checked above.
            return unsafe { self.gather_brute_force_fma(weights, ray) };
        }
        self.brute_force_body(weights, ray)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "fma")]
    fn gather_brute_force_fma<D: Denominator>(&self, weights: &D, ray: &CameraRay) -> (Vec3, u64) {
        self.brute_force_body(weights, ray)
    }

    #[inline(always)]
    fn brute_force_body<D: Denominator>(&self, weights: &D, ray: &CameraRay) -> (Vec3, u64) {
        let (mut sum, mut hits) = (Vec3::ZERO, 0);
        // The light being summed: its index, its scale and its hits' sum.
        let mut light: Option<(u32, Vec3, Vec3)> = None;
        for &i in self.by_light() {
            let view = &self.views[i as usize];
            let Some(c) = self.gather_one(weights, view, ray) else {
                continue;
            };
            hits += 1;
            match &mut light {
                Some((l, _, light_sum)) if *l == view.light => *light_sum += c,
                _ => {
                    if let Some((_, scale, light_sum)) = light.take() {
                        sum = add_light(sum, scale, light_sum);
                    }
                    light = Some((view.light, view.scale, c));
                }
            }
        }
        if let Some((_, scale, light_sum)) = light {
            sum = add_light(sum, scale, light_sum);
        }
        (sum, hits)
    }
}

/// `sum + scale * light_sum` channel by channel (a separate multiply and add), a channel whose
/// scale is 0 left as it is: a light's sum of hits without its power can overflow to infinity
/// where the scaled hits would not, and 0 times that is NaN. The raster's [`crate::kernel::fold`]
/// does the same.
pub fn add_light(sum: Vec3, scale: Vec3, light_sum: Vec3) -> Vec3 {
    let add = |s: f32, k: f32, l: f32| if k == 0.0 { s } else { s + k * l };
    Vec3::new(add(sum.x, scale.x, light_sum.x), add(sum.y, scale.y, light_sum.y), add(sum.z, scale.z, light_sum.z))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photon_plane::sample_planes;
    use crate::sampling::Sampler;

    /// The benchmark scene, from the repository's file.
    fn six_lights() -> Scene {
        Scene::parse(include_str!("../../../media_scenes/six_lights.toml"), "six_lights.toml", "s").unwrap()
    }

    /// A camera ray of the tests' grid: its pixel, its direction and entry into the fog box in
    /// f64, and the ray the gather takes (clipped to the box).
    struct GridRay {
        pixel: (f64, f64),
        we: DVec3,
        t0: f64,
        ray: CameraRay,
    }

    /// The rays through the centres of an n x n grid of cells over the image, row by row, those
    /// that cross the fog box.
    fn grid_rays(scene: &Scene, n: usize) -> Vec<GridRay> {
        let o = scene.camera.position;
        let cell = |i: usize, size: u32| size as f64 * (i as f64 + 0.5) / n as f64;
        let pixels = (0..n).flat_map(|j| (0..n).map(move |i| (i, j)));
        let pixels = pixels.map(|(i, j)| (cell(i, scene.camera.width), cell(j, scene.camera.height)));
        pixels
            .filter_map(|(x, y)| {
                let we = scene.camera.direction(x, y).normalize();
                let (t0, t1) = scene.camera_segment(o, we).0?;
                Some(GridRay {
                    pixel: (x, y),
                    we,
                    t0,
                    ray: CameraRay { dir: we.as_vec3(), t0: t0 as f32, t1: t1 as f32 },
                })
            })
            .collect()
    }

    /// Culling occluders per plane never drops one that blocks: the same images as testing
    /// every other light at every hit.
    #[test]
    fn occluder_culling_keeps_every_blocking_light() {
        for file in ["media_scenes/six_lights.toml", "media_scenes/hard/facing_lights_close.toml"] {
            let scene =
                Scene::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(file)).unwrap();
            let planes = sample_planes(&scene, Sampler::Independent, 4000, 8);
            let o = scene.camera.position;
            let culled = GatherContext::new(&scene, &planes, o);
            let mut all = GatherContext::empty(&scene, o);
            let every_other: Vec<u64> =
                planes.iter().map(|p| ((1u64 << scene.lights.len()) - 1) & !(1 << p.light)).collect();
            all.push_planes_with_occluders(&scene, &planes, &every_other, planes.len());
            let shadowed = culled.views.iter().filter(|v| v.may_be_shadowed()).count();
            if file.contains("six_lights") {
                assert!(shadowed < planes.len() / 4, "{file}: culling should drop most planes");
            }
            let w = crate::weights::Unweighted;
            for GridRay { pixel, ray, .. } in grid_rays(&scene, 40) {
                assert_eq!(
                    culled.gather_brute_force(&w, &ray),
                    all.gather_brute_force(&w, &ray),
                    "{file} pixel {pixel:?}"
                );
            }
        }
    }

    /// The linear form of the shadow test against the direct one: the f64 ray-rectangle
    /// crossing of the panel (`RectLight::intersect`, which shares no code with it) from the
    /// light vertex along the sweep direction. Only points within a hair of a panel edge or of
    /// the segment's ends, where f32 rounding decides, may disagree. The scene's square panels,
    /// and the same scene with panels of unequal sides, one turned about its normal, so that a
    /// width taken for a height or `u` for `v` shows.
    #[test]
    fn occluders_block_exactly_where_the_panels_are() {
        let text = include_str!("../../../media_scenes/hard/facing_lights_close.toml");
        let oblong = text
            .replace("corner = [-0.5, 1.55, -0.5]", "corner = [-0.5, 1.55, -0.2]")
            .replace("edge_u = [1.0, 0.0, 0.0]", "edge_u = [0.9, 0.0, 0.3]")
            .replace("edge_v = [0.0, 0.0, 1.0]", "edge_v = [-0.1, 0.0, 0.3]")
            .replace("edge_v = [0.0, 0.0, -0.8]", "edge_v = [0.0, 0.0, -0.3]");
        for (text, sides_apart) in [(text.to_string(), false), (oblong, true)] {
            let scene = Scene::parse(&text, "facing_lights_close.toml", "s").unwrap();
            let apart = scene.lights.iter().all(|l| (l.width - l.height).abs() > 0.2 * l.width);
            assert_eq!(apart, sides_apart, "the panels' sides: {:?}", scene.lights);
            occluders_block_where_the_panels_of(&scene);
        }
    }

    fn occluders_block_where_the_panels_of(scene: &Scene) {
        use rand::{Rng, SeedableRng};
        let planes = sample_planes(scene, Sampler::Independent, 4000, 3);
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(4);
        let (mut blocked, mut checked, mut near) = (0, 0, 0);
        for p in &planes {
            for (k, light) in scene.lights.iter().enumerate() {
                if k == p.light {
                    continue;
                }
                let Some(o) = Occluder::new(p, light) else { continue };
                for _ in 0..20 {
                    let a = rng.random::<f64>() * p.width;
                    let r = rng.random::<f64>() * 2.0 * scene.medium.diagonal();
                    let y = p.origin + a * p.chord;
                    let want = light.intersect(y, p.direction, 1e-6 * r, r * (1.0 - 1e-6));
                    let got = o.blocks(a as f32, r as f32);
                    // How close the f64 crossing of the panel's plane is to an edge or an end.
                    let denom = p.direction.dot(light.n);
                    let s = (light.corner - y).dot(light.n) / denom;
                    let (pp, qq) = light.local(y + s * p.direction);
                    let margin = pp.abs().min((pp - light.width).abs()).min(qq.abs()).min((qq - light.height).abs());
                    let scale = scene.medium.diagonal();
                    if margin < 1e-4 * scale || (s - r).abs() < 1e-4 * scale || s.abs() < 1e-4 * scale {
                        near += 1;
                        continue;
                    }
                    assert_eq!(got, want.is_some(), "plane of light {} against light {k}: a={a} r={r} s={s}", p.light);
                    checked += 1;
                    blocked += got as u32;
                }
            }
        }
        println!("{checked} paths checked, {blocked} blocked, {near} within 1e-4 of an edge or end skipped");
        assert!(checked > 10_000 && blocked > 500 && near < checked / 50, "{checked} {blocked} {near}");
    }

    /// A light's sum scaled and added channel by channel; an overflowed sum under a scale of 0
    /// leaves its channel as it was (not NaN).
    #[test]
    fn a_light_is_added_without_nan_from_a_zero_scale() {
        let got = add_light(Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.5, 0.0, 2.0), Vec3::new(4.0, f32::INFINITY, 1.0));
        assert_eq!(got, Vec3::new(3.0, 2.0, 5.0));
    }

    /// The record that crosses to the GPU is 144 bytes, the layout `gpu/gather.wgsl`'s `Plane`
    /// declares, and carries the view's values, an infinite reciprocal as 0.
    #[test]
    fn a_plane_record_carries_the_view_and_no_infinity() {
        assert_eq!(std::mem::size_of::<PlaneRecord>(), 144);
        assert_eq!(std::mem::size_of::<Occluder>(), 32);
        let scene = six_lights();
        let planes = sample_planes(&scene, Sampler::default(), 200, 2);
        let ctx = GatherContext::new(&scene, &planes, scene.camera.position);
        for v in &ctx.views {
            let r = PlaneRecord::from(v);
            assert_eq!((r.normal, r.t_det, r.width, r.light), (v.normal.to_array(), v.t_det, v.frame.width, v.light));
            let bytes: &[u8] = bytemuck::bytes_of(&r);
            let words: &[f32] = bytemuck::cast_slice(bytes);
            assert!(words.iter().all(|w| !w.is_infinite()), "{r:?}");
        }
        let mut v = ctx.views[0];
        v.frame.perp = crate::light::ChordDirection::<f32>::from_cos_sin(0.0, 1.0);
        let r = PlaneRecord::from(&v);
        assert_eq!((r.perp_inv_abs_cos, r.perp_inv_sin, r.perp_cos_positive), (0.0, 1.0, 0));
    }

    /// The gather's f32 phase factor against the f64 Henyey-Greenstein function of the medium
    /// (docs/mathematics.md section 1.1): within 2e-5 relative for every g up to +-0.99 and every
    /// angle, the exact peak and its opposite included, positive and finite throughout (the
    /// values span more than six orders of magnitude at +-0.99). Also that the sign of g picks
    /// the peak: forward (g > 0) is the eye looking against the light's travel.
    #[test]
    fn the_phase_factor_is_henyey_greenstein_in_f32() {
        use crate::medium::{PHASE, henyey_greenstein};
        for g in [-0.99, -0.9, -0.5, 0.3, 0.8, 0.9, 0.99] {
            let phase = Phase::new(g);
            let sign = if g < 0.0 { -1.0 } else { 1.0 };
            let wl = DVec3::new(0.3, -0.8, 0.52).normalize();
            let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
            for k in 0..=2000 {
                // Directions from we = -wl (looking into the light's travel) to we = wl.
                let theta = std::f64::consts::PI * k as f64 / 2000.0;
                let side = wl.any_orthonormal_vector();
                let we = (-wl * theta.cos() + side * theta.sin()).normalize();
                let ray = RayBlock::one(&CameraRay { dir: we.as_vec3(), t0: 0.0, t1: 1.0 });
                let inverse = phase.inverse_lanes::<1, f32>(&ray, (sign * wl).as_vec3(), (1.0 / (1.0 - g * g)) as f32);
                let want = henyey_greenstein(g, wl.dot(-we)) / PHASE;
                let got = 1.0 / inverse as f64;
                assert!(inverse.is_finite() && inverse > 0.0, "g {g} theta {theta}: {inverse}");
                assert!((got - want).abs() <= 2e-5 * want, "g {g} theta {theta}: {got} against {want}");
                (lo, hi) = (lo.min(got), hi.max(got));
            }
            let (forward, backward) = (henyey_greenstein(g, 1.0) / PHASE, henyey_greenstein(g, -1.0) / PHASE);
            assert_eq!(forward > backward, g > 0.0, "g {g}");
            if g.abs() == 0.99 {
                assert!(hi / lo > 1e6, "g {g}: the values span {lo} to {hi}");
            }
        }
        assert!(
            Phase::new(0.0).is_isotropic() && !Phase::new(1e-3).is_isotropic() && !Phase::new(1e-300).is_isotropic()
        );
    }

    /// A g too small for f32 (a scene may give 1e-300, docs/mathematics.md section 2.5) still has
    /// lobes, and each hit on a lobe's plane must carry its direction weight m: there
    /// 4 pi rho = 1 to within 1e-300, so C is m times the isotropic C of the same hit (sections
    /// 1.1 and 2.5), to f32 rounding. Taking g as f32, 0, for isotropic dropped m.
    #[test]
    fn a_phase_function_too_faint_for_f32_keeps_the_direction_weights() {
        let isotropic = six_lights();
        for g in [1e-300, -1e-300] {
            let mut faint = isotropic.clone();
            faint.medium.g = g;
            let planes = sample_planes(&faint, Sampler::default(), 2000, 4);
            let o = faint.camera.position;
            let (ctx, iso) = (GatherContext::new(&faint, &planes, o), GatherContext::new(&isotropic, &planes, o));
            let w = crate::weights::SmisExactPair;
            let mut weighted = 0;
            for GridRay { ray, .. } in grid_rays(&faint, 20) {
                for ((p, v), v0) in planes.iter().zip(&ctx.views).zip(&iso.views) {
                    let (Some(c), Some(c0)) = (ctx.gather_one(&w, v, &ray), iso.gather_one(&w, v0, &ray)) else {
                        continue;
                    };
                    let want = c0.as_dvec3() * p.direction_weight;
                    assert!(
                        (c.as_dvec3() - want).abs().max_element() <= 1e-5 * want.max_element(),
                        "g {g:e}, weight {}: {c} against {want}",
                        p.direction_weight
                    );
                    weighted += (p.direction_weight != 1.0 && c0.max_element() > 0.0) as usize;
                }
            }
            assert!(weighted > 1000, "g {g:e}: {weighted} hits on the lobes' planes");
        }
    }

    /// Each channel's contribution carries its own transmittance exp(-sigma_t length) (section
    /// 2.3), whichever two channels share an extinction: the ratio of two channels of a hit is
    /// exp(-(sigma_k - sigma_j) length), with the length (t - t0) + r from the hit solved in f64
    /// here. Only a medium whose three channels are equal may take the grey path's one value.
    #[test]
    fn each_channel_keeps_its_extinction_when_two_are_equal() {
        let base = six_lights();
        let planes = sample_planes(&base, Sampler::default(), 500, 6);
        let o = base.camera.position;
        for sigma_t in [[0.4, 0.4, 0.9], [0.4, 0.9, 0.4], [0.9, 0.4, 0.4], [0.4, 0.4, 0.4]] {
            let mut scene = base.clone();
            scene.medium.sigma_s = DVec3::splat(0.3);
            scene.medium.sigma_a = DVec3::from(sigma_t) - 0.3;
            let sigma_t = scene.medium.sigma_t();
            let ctx = GatherContext::new(&scene, &planes, o);
            let w = crate::weights::Unweighted;
            let mut checked = 0;
            for GridRay { we, t0, ray, .. } in grid_rays(&scene, 20) {
                for (p, v) in planes.iter().zip(&ctx.views) {
                    let Some(c) = ctx.gather_one(&w, v, &ray) else { continue };
                    // o + t we = y0 + a d + r wl: t from the plane's normal, then r from the
                    // offset's components along the unit d and wl.
                    let n = p.chord.cross(p.direction);
                    let t = (p.origin - o).dot(n) / we.dot(n);
                    let e = o + t * we - p.origin;
                    let cos = p.chord.dot(p.direction);
                    let r = (e.dot(p.direction) - cos * e.dot(p.chord)) / (1.0 - cos * cos);
                    let length = (t - t0) + r;
                    if !(c.x > 0.0) || length > 20.0 {
                        continue;
                    }
                    let c = c.as_dvec3();
                    for (i, j) in [(1, 0), (2, 0), (2, 1)] {
                        let want = (-(sigma_t[i] - sigma_t[j]) * length).exp();
                        let got = c[i] / c[j];
                        assert!(
                            (got - want).abs() <= 1e-4 * want,
                            "sigma_t {sigma_t}: channel {i} over {j} {got}, want {want}"
                        );
                    }
                    checked += 1;
                }
            }
            assert!(checked > 1000, "sigma_t {sigma_t}: {checked} hits");
        }
    }

    #[test]
    fn hit_solves_the_plane_equation() {
        let scene = six_lights();
        let planes = sample_planes(&scene, Sampler::default(), 300, 2);
        let o = scene.camera.position;
        let ctx = GatherContext::new(&scene, &planes, o);
        let mut found = 0;
        for (p, v) in planes.iter().zip(&ctx.views) {
            for k in 0..50 {
                let we = scene.camera.direction(12.8 * k as f64, 7.2 * k as f64).normalize();
                let ray = CameraRay { dir: we.as_vec3(), t0: 0.0, t1: 1e9 };
                let h = v.crossing(ray.dir.to_array(), ray.t0, ray.t1);
                if h.hit {
                    found += 1;
                    let x = o + h.t as f64 * we;
                    let on_plane = p.origin + h.a as f64 * p.chord + h.r as f64 * p.direction;
                    assert!((x - on_plane).length() < 1e-3 * (1.0 + h.t as f64), "{x} vs {on_plane}");
                }
            }
        }
        assert!(found > 100);
    }
}
