//! A bounding volume hierarchy over photon planes, for rays from one origin.
//!
//! The general-purpose structure: it answers any ray from the gathering origin, at the cost of
//! a traversal per ray. Planes are long and thin, so their boxes overlap a lot; the screen-space
//! [`crate::raster`] is the fast path for camera images, this one the baseline it is measured
//! against (and a second independent path for the hit-equality tests).

use crate::camera::CameraRay;
use crate::control::Control;
use crate::error::Result;
use crate::gather::{GatherContext, GatherStats};
use crate::kernel::{Aggregate, Gathering, gather_per_ray};
use crate::medium::Medium;
use crate::photon_plane::PhotonPlane;
use crate::weights::Denominator;
use glam::{DVec3, Vec3};

const LEAF_SIZE: usize = 4;

#[derive(Clone, Copy, Debug)]
struct Node {
    min: Vec3,
    max: Vec3,
    /// Leaf: planes `first..first + count` of `order`; inner: children at `first`, `first + 1`.
    first: u32,
    count: u32,
}

pub struct PlaneBvh {
    nodes: Vec<Node>,
    order: Vec<u32>,
}

impl PlaneBvh {
    /// Builds over the planes' polygons inside the box, relative to `origin` (median split on the
    /// longest axis of the centroids). [`crate::Error::Cancelled`] once `control` is cancelled
    /// (checked every few thousand planes and at every node).
    pub fn build(planes: &[PhotonPlane], medium: &Medium, origin: DVec3, control: Control) -> Result<Self> {
        let margin = 1e-6 * medium.diagonal();
        let plane_box = |p: &PhotonPlane| {
            let poly = p.polygon_in_box(medium, margin);
            let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
            for &v in poly.points() {
                lo = lo.min(v - origin);
                hi = hi.max(v - origin);
            }
            // Grow by the f32 rounding of the coordinates.
            let pad = 1e-5 * (hi - lo).max_element().max(1e-30) + 1e-6 * (lo.abs().max(hi.abs())).max_element();
            ((lo - pad).as_vec3(), (hi + pad).as_vec3())
        };
        let mut boxes: Vec<(Vec3, Vec3)> = Vec::with_capacity(planes.len());
        for chunk in planes.chunks(4096) {
            control.check()?;
            boxes.extend(chunk.iter().map(plane_box));
        }
        let order: Vec<u32> = (0..planes.len() as u32).filter(|&i| boxes[i as usize].0.x.is_finite()).collect();
        let len = order.len();
        let nodes = vec![Node { min: Vec3::ZERO, max: Vec3::ZERO, first: 0, count: 0 }];
        let mut builder = Builder { nodes, order, boxes: &boxes, control };
        builder.node(0, 0, len)?;
        Ok(PlaneBvh { nodes: builder.nodes, order: builder.order })
    }

    /// One ray's estimate, testing only planes whose boxes the ray's segment crosses. Compiled
    /// with FMA where the CPU has it, as [`GatherContext::gather_brute_force`] is (the same bits).
    pub fn gather_ray<D: Denominator>(&self, ctx: &GatherContext, weights: &D, ray: &CameraRay) -> (Vec3, GatherStats) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU has FMA, checked above.
            return unsafe { self.gather_ray_fma(ctx, weights, ray) };
        }
        self.gather_ray_body(ctx, weights, ray)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "fma")]
    fn gather_ray_fma<D: Denominator>(&self, ctx: &GatherContext, weights: &D, ray: &CameraRay) -> (Vec3, GatherStats) {
        self.gather_ray_body(ctx, weights, ray)
    }

    #[inline(always)]
    fn gather_ray_body<D: Denominator>(
        &self,
        ctx: &GatherContext,
        weights: &D,
        ray: &CameraRay,
    ) -> (Vec3, GatherStats) {
        let (mut sum, mut stats) = (Vec3::ZERO, GatherStats::default());
        if self.order.is_empty() || !(ray.t0 <= ray.t1) {
            return (sum, stats);
        }
        let inv = ray.dir.recip();
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            // Slab test (the origin is the gathering origin, so the box is already relative).
            let (a, b) = (node.min * inv, node.max * inv);
            let (near, far) = (a.min(b).max_element().max(ray.t0), a.max(b).min_element().min(ray.t1));
            if !(near <= far) {
                continue;
            }
            if node.count > 0 {
                for &i in &self.order[node.first as usize..(node.first + node.count) as usize] {
                    let view = &ctx.views[i as usize];
                    stats.tests += 1;
                    if let Some(c) = ctx.gather_one(weights, view, ray) {
                        stats.hits += 1;
                        sum += view.scale * c;
                    }
                }
            } else if top + 2 <= stack.len() {
                stack[top] = node.first;
                stack[top + 1] = node.first + 1;
                top += 2;
            }
        }
        (sum, stats)
    }
}

/// A traversal per ray ([`gather_per_ray`]).
impl Aggregate for PlaneBvh {
    fn gather<D: Denominator>(
        &self,
        with: Gathering<D>,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        control: Control,
    ) -> GatherStats {
        gather_per_ray(rays, sums, control, |ray| self.gather_ray(with.ctx, with.weights, ray))
    }
}

/// The hierarchy under construction.
struct Builder<'a> {
    nodes: Vec<Node>,
    order: Vec<u32>,
    boxes: &'a [(Vec3, Vec3)],
    control: Control<'a>,
}

impl Builder<'_> {
    /// Fills node `index` with the planes `order[start..end]`, splitting it further if need be.
    fn node(&mut self, index: usize, start: usize, end: usize) -> Result<()> {
        self.control.check()?;
        let boxes = self.boxes;
        let items = &mut self.order[start..end];
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        let (mut clo, mut chi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for &i in items.iter() {
            let (a, b) = boxes[i as usize];
            lo = lo.min(a);
            hi = hi.max(b);
            clo = clo.min(a + b);
            chi = chi.max(a + b);
        }
        if items.len() <= LEAF_SIZE || self.nodes.len() > (1 << 30) {
            self.nodes[index] = Node { min: lo, max: hi, first: start as u32, count: items.len() as u32 };
            return Ok(());
        }
        let extent = chi - clo;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |&i, &j| {
            let (ci, cj) = (boxes[i as usize].0 + boxes[i as usize].1, boxes[j as usize].0 + boxes[j as usize].1);
            ci[axis].total_cmp(&cj[axis])
        });
        let first = self.nodes.len();
        self.nodes.push(Node { min: Vec3::ZERO, max: Vec3::ZERO, first: 0, count: 0 });
        self.nodes.push(Node { min: Vec3::ZERO, max: Vec3::ZERO, first: 0, count: 0 });
        self.nodes[index] = Node { min: lo, max: hi, first: first as u32, count: 0 };
        self.node(first, start, start + mid)?;
        self.node(first + 1, start + mid, end)
    }
}
