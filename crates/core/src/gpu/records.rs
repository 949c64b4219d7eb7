//! The data that crosses to the GPU, defined once: the shaders' source, the records of the
//! binning's and the gather's parameters, and the bytes of a work item's partial sums. The
//! planes', occluders', rays' and panels' records are defined beside the CPU's; the test at the
//! end holds every record that crosses, those and these, to its WGSL twin.

use super::TILE;

pub(super) const GATHER_WGSL: &str = include_str!("gather.wgsl");
pub(super) const BIN_WGSL: &str = include_str!("bin.wgsl");
pub(super) const RAYS_WGSL: &str = include_str!("rays.wgsl");
pub(super) const REACH_WGSL: &str = include_str!("reach.wgsl");

/// Bytes of one work item's partial sums: 256 pixels of (r, g, b, hits) in f32.
pub(super) const ITEM_BYTES: u64 = (TILE * TILE) as u64 * 16;

/// `rays.wgsl`'s `Dispatch`: the first of the ray sets that one dispatch makes (a workgroup's
/// z its set from there).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct RaysDispatch {
    pub(super) first_set: u32,
    pub(super) pad: [u32; 3],
}

/// `gather.wgsl`'s `Params`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct GatherParams {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) tiles_x: u32,
    pub(super) tiles: u32,
    pub(super) sigma_t: [f32; 3],
    pub(super) grey: u32,
    pub(super) orientations: u32,
    pub(super) inv_orientations: f32,
    /// gather.rs `Phase`: `abs(g)`, `(1 - abs(g))^2`, and whether g != 0 (`1 / (1 - g^2)` is
    /// each plane's, with its direction's weight: `PlaneRecord::phase_scale`).
    pub(super) phase_h: f32,
    pub(super) phase_floor: f32,
    pub(super) pad0: u32,
    pub(super) phase_hg: u32,
    /// The gathering's planes (`orient`'s table has K - 1 rows for each).
    pub(super) planes: u32,
    /// The batches of the round (`bin.wgsl`'s regions).
    pub(super) regions: u32,
}

/// `bin.wgsl`'s `Params`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct BinParams {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) tiles_x: u32,
    pub(super) tiles: u32,
    pub(super) count: u32,
    pub(super) first: u32,
    pub(super) item_planes: u32,
    /// The batch's index in its round: its region of the tiles' offsets.
    pub(super) region: u32,
    /// Its segments (gpu/batches.rs `Batch::segments`), at most [`super::BATCH_SEGMENTS`].
    pub(super) segments: u32,
    /// 1 where the tiles take their candidates from their blocks' lists (the first tier,
    /// [`super::BLOCK_TILES`]), 0 where every plane of the batch is each tile's candidate
    /// ([`super::Tuning::flat_binning`]).
    pub(super) blocked: u32,
    pub(super) pad: [u32; 2],
    /// Each segment's first plane (from the batch's first) and where its ray set begins in the
    /// gathering's rays (floats), two segments a row.
    pub(super) segs: [[u32; 4]; super::BATCH_SEGMENTS / 2],
}

/// `reach.wgsl`'s `Params`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct ReachParams {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) planes: u32,
    pub(super) rows: u32,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::CameraRay;
    use crate::gather::PlaneRecord;
    use crate::gpu::{GROUP_ROWS, GROUPS};
    use crate::occlusion::Occluder;
    use crate::pixel::{PanelRecord, RaySetRecord};
    use std::mem::{offset_of, size_of};
    use wgpu::naga;

    /// The size and members (name, byte offset) of WGSL struct `name` in `source`, laid out by
    /// the WGSL front end that wgpu compiles the shaders with.
    fn wgsl_layout(source: &str, name: &str) -> (usize, Vec<(String, usize)>) {
        let module = naga::front::wgsl::parse_str(source).expect("the shader parses");
        for (_, ty) in module.types.iter() {
            if let (Some(n), naga::TypeInner::Struct { members, span }) = (&ty.name, &ty.inner)
                && n == name
            {
                let members = members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize));
                return (*span as usize, members.collect());
            }
        }
        panic!("no struct {name} in the shader")
    }

    /// The value of WGSL constant `name` in `source`, a literal.
    fn wgsl_constant(source: &str, name: &str) -> naga::Literal {
        let module = naga::front::wgsl::parse_str(source).expect("the shader parses");
        let value = module
            .constants
            .iter()
            .find(|(_, c)| c.name.as_deref() == Some(name))
            .map(|(_, c)| &module.global_expressions[c.init]);
        let Some(naga::Expression::Literal(value)) = value else { panic!("the shader's {name} is a literal") };
        *value
    }

    fn wgsl_u32(source: &str, name: &str) -> u32 {
        let naga::Literal::U32(value) = wgsl_constant(source, name) else { panic!("the shader's {name} is a u32") };
        value
    }

    fn wgsl_f32(source: &str, name: &str) -> f32 {
        let naga::Literal::F32(value) = wgsl_constant(source, name) else { panic!("the shader's {name} is an f32") };
        value
    }

    /// Every record that crosses to the GPU is laid out as its WGSL twin: the same size, and
    /// each Rust field at the offset of the WGSL member of its name (padding named `pad...` on
    /// both sides). The two definitions are one by this test: a field added, moved or retyped
    /// on one side only fails here, not as wrong pixels.
    #[test]
    fn records_are_laid_out_as_the_shaders_read_them() {
        macro_rules! fields {
            ($t:ty: $($f:ident),*) => {
                (stringify!($t), size_of::<$t>(), vec![$((stringify!($f), offset_of!($t, $f))),*])
            };
        }
        let pairs = [
            (
                GATHER_WGSL,
                "Plane",
                fields!(PlaneRecord: normal, t_det, a_axis, width, r_axis, occluders_start, normal_perp,
                    occluders_end, scale, scale_max, cos_a, sin_a, p0, q0, light_w, light_h, perp_inv_abs_cos,
                    perp_inv_sin, perp_cos_positive, unit, inv_unit, light, toward, phase_scale),
            ),
            (GATHER_WGSL, "Occluder", fields!(Occluder: t0, t_a, p0, p_a, q0, q_a, width, height)),
            (
                GATHER_WGSL,
                "Params",
                fields!(GatherParams: width, height, tiles_x, tiles, sigma_t, grey, orientations, inv_orientations,
                    phase_h, phase_floor, pad0, phase_hg, planes, regions),
            ),
            (
                BIN_WGSL,
                "Params",
                fields!(BinParams: width, height, tiles_x, tiles, count, first, item_planes, region, segments,
                    blocked, pad, segs),
            ),
            (REACH_WGSL, "Params", fields!(ReachParams: width, height, planes, rows)),
            (
                RAYS_WGSL,
                "RaySet",
                fields!(RaySetRecord: forward, tan_x, right, tan_y, up, width, lo, height, hi, outside, scramble,
                    sobol, pixel_center, panels, first_panel, first_float),
            ),
            (RAYS_WGSL, "Dispatch", fields!(RaysDispatch: first_set, pad)),
            (RAYS_WGSL, "Panel", fields!(PanelRecord: corner, to_plane, n, width, u, height, v, pad, footprint)),
        ];
        // A camera ray is `RAY_FLOATS` f32 where it is made and where it is read, its fields in
        // the shaders' order.
        for source in [GATHER_WGSL, RAYS_WGSL] {
            let ray_floats = wgsl_u32(source, "RAY_FLOATS");
            assert_eq!(size_of::<CameraRay>(), 4 * ray_floats as usize, "a ray is RAY_FLOATS f32");
        }
        // The groups of pixel rows whose columns `TileReach` holds are those the gather reads,
        // a byte each of a list entry's u32 (`bin.wgsl`'s `ranges`, from a vec4 of `groups`).
        assert_eq!(wgsl_u32(GATHER_WGSL, "GROUP_ROWS"), GROUP_ROWS, "pixel rows a group");
        assert_eq!(GROUPS, 4, "4 groups a row of tiles: a vec4 of `groups`, a byte each of `ranges`");
        // Where the GPU finds the reach, with the specification's tiles and groups, and slack.
        assert_eq!(wgsl_u32(REACH_WGSL, "GROUP_ROWS"), GROUP_ROWS, "pixel rows a group");
        assert_eq!(wgsl_u32(REACH_WGSL, "TILE"), TILE, "pixels a tile's side");
        assert_eq!(wgsl_u32(BIN_WGSL, "BLOCK"), crate::gpu::BLOCK_TILES, "tiles a block's side");
        assert_eq!(wgsl_f32(REACH_WGSL, "SLACK") as f64, crate::gpu::SLACK, "the GPU's slack");
        let at = [offset_of!(CameraRay, dir), offset_of!(CameraRay, t0), offset_of!(CameraRay, t1)];
        assert_eq!(at, [0, 12, 16], "a ray's floats: x, y, z, t0, t1");
        for (source, name, (rust, size, fields)) in pairs {
            let (span, members) = wgsl_layout(source, name);
            assert_eq!(span, size, "{rust} is {size} bytes, the shader's {name} {span}");
            for (field, offset) in fields {
                let member = members.iter().find(|(_, o)| *o == offset).map(|(m, _)| m.as_str());
                let same = member == Some(field) || (field == "pad" && member.is_some_and(|m| m.starts_with("pad")));
                assert!(same, "{rust}.{field} at byte {offset}: the shader's {name} has {member:?} there");
            }
        }
    }
}
