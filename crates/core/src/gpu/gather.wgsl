// The GPU gather: the per-hit arithmetic of docs/mathematics.md sections 2.3, 2.4 and 3, a second
// implementation of crates/core/src/gather.rs, weights/denominators.rs and weights/closed_form.rs
// (the same operations in the same order, fused multiply-adds where the CPU fuses them). One
// workgroup per work item: a 16 x 16 tile's pixels against at most `item_planes` planes of the
// tile's list (bin.wgsl made the lists); each thread keeps its pixel's sum in registers and writes
// it to `partial`, and `reduce` adds a tile's items in order. No atomics, no float atomics: one
// writer per value, so an image is the same bits from run to run.
//
// Nothing here relies on IEEE infinities or NaN, which Vulkan does not promise: every division
// whose divisor can be 0 is guarded by a select, a chord direction along an axis carries 0 for
// its infinite reciprocal (gather.rs's `PlaneRecord`), and a contribution too large for f32 is
// dropped by a comparison made before the division could overflow.

// 0 unweighted, 1 cmis-cosine, 2 smis-cosine (pair), 3 smis-exact (pair), 4 cmis-exact,
// 5 smis-cosine with K orientations, 6 smis-exact with K orientations (gpu/mod.rs `estimator_id`).
override ESTIMATOR: u32 = 0u;
// The driver's exp, log, atan and atan2 instead of the CPU's polynomials below (gpu/mod.rs
// `Tuning::native_math`, for measuring them on a device): not the CPU's bits. Each is given
// an argument where WGSL defines it (log of at least the least normal f32, atan2 of (0, 0)
// as 0, as the polynomials give), so that what the polynomials keep finite stays finite.
override NATIVE_MATH: bool = false;
// K orientations read from the table `orient` made once a gathering (`orients`) rather than made
// at each hit (gpu/mod.rs `Tuning::orientation_table`, for measuring it on a device): the same
// operations, the same bits.
override ORIENTATION_TABLE: bool = false;
// K of smis-cosine and smis-exact with K orientations (ESTIMATOR 5 and 6) made a pipeline's own
// constant (gpu/mod.rs `Tuning::k_constant`, for measuring it on a device: a driver can unroll
// the loop over the orientations), or 0: K read from `params` (the default). The same bits.
override ORIENTATIONS: u32 = 0u;
// A tile's pixels taken by a workgroup's invocations in blocks of 8 columns by 4 rows, each
// block 32 consecutive invocations (a warp of 32 lanes, half a wave of 64), so that a warp lies
// within one group of rows of a plane's column ranges and within one half of the tile's
// columns: `pixel_of` (gpu/mod.rs `Tuning::row_lanes`). Or false: invocation i takes the
// tile's pixel i in row order, a warp two whole rows. The same pixels, each added to in the same
// order: the same bits either way.
override LANE_BLOCKS: bool = true;

// gather.rs `PlaneRecord`, 144 bytes (nine rows of 16).
struct Plane {
    normal: vec3<f32>,
    t_det: f32,
    a_axis: vec3<f32>,
    width: f32,
    r_axis: vec3<f32>,
    occluders_start: u32,
    normal_perp: vec3<f32>,
    occluders_end: u32,
    scale: vec3<f32>,
    scale_max: f32,
    cos_a: f32,
    sin_a: f32,
    p0: f32,
    q0: f32,
    light_w: f32,
    light_h: f32,
    perp_inv_abs_cos: f32,
    perp_inv_sin: f32,
    perp_cos_positive: u32,
    unit: f32,
    inv_unit: f32,
    light: u32,
    toward: vec3<f32>,
    phase_scale: f32,
};

// occlusion.rs `Occluder`.
struct Occluder {
    t0: f32,
    t_a: f32,
    p0: f32,
    p_a: f32,
    q0: f32,
    q_a: f32,
    width: f32,
    height: f32,
};

// A camera ray is camera.rs's `CameraRay` as it is, five f32 (no padding: 20 bytes, uploaded
// without a copy): unit direction (x, y, z) and segment [t0, t1], empty when t0 > t1.
const RAY_FLOATS: u32 = 5u;

// gpu/records.rs `GatherParams`.
struct Params {
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles: u32,
    sigma_t: vec3<f32>,
    grey: u32,
    orientations: u32,
    inv_orientations: f32,
    phase_h: f32,
    phase_floor: f32,
    pad0: u32,
    phase_hg: u32,
    // The gathering's planes (`orient`'s table holds K - 1 rows for each).
    planes: u32,
    // The batches of the round (bin.wgsl's regions of `item_offsets`).
    regions: u32,
};

@group(0) @binding(0) var<uniform> params: Params;
// The planes as rows of four words, PLANE_ROWS a plane (each a `Plane` as it is laid out), so
// that a workgroup's threads stage a batch of planes row by row, neighbours reading neighbouring
// rows (`plane_at` reads a staged plane back as a `Plane`). Words, not floats: the u32 fields
// never pass through an f32, whose small values a back end may flush to zero.
@group(0) @binding(1) var<storage, read> plane_rows: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> occluders: array<Occluder>;
@group(0) @binding(3) var<storage, read> rays: array<f32>;
// (cos, sin) of k pi / K for k = 1 .. K - 1 (weights/denominators.rs `StratifiedK`).
@group(0) @binding(4) var<storage, read> rotations: array<vec2<f32>>;
// The tiles' plane lists; the round's grid of work items and their number, then per batch of the
// round each tile's first work item (bin.wgsl).
@group(0) @binding(5) var<storage, read> list: array<u32>;
@group(0) @binding(6) var<storage, read> item_offsets: array<u32>;
// Work items: (tile, first list entry, end, where the ray set begins in `rays`, in floats).
@group(0) @binding(7) var<storage, read> items: array<vec4<u32>>;
// Each work item's 256 pixel sums: (rgb, hits + 1024 tests).
@group(0) @binding(8) var<storage, read_write> partial: array<vec4<f32>>;
// The image (sums.rs `GpuSums`): each pixel's sum (rgb, the bits of f32, three words a pixel),
// then each tile's hits and tests (two u64, each two words, low first), added to by every batch of every
// gathering into it, and read back once.
@group(0) @binding(9) var<storage, read_write> image: array<u32>;
// Per list entry, the plane's pixel columns within the tile per group of pixel rows (bin.wgsl).
@group(0) @binding(10) var<storage, read> ranges: array<u32>;
// With K orientations (estimators 5 and 6), each plane's K - 1 further orientations, made once a
// gathering by `orient`: (cos, sin, 1 / |cos|, 1 / sin) of beta, 0 for an infinite reciprocal.
@group(0) @binding(11) var<storage, read_write> orients: array<vec4<f32>>;

const TILE: u32 = 16u;
// The rows of 16 bytes of a `Plane` (144 bytes).
const PLANE_ROWS: u32 = 9u;
// Pixel rows per group of `ranges` (gpu/reach.rs `GROUP_ROWS`): 4 groups a tile, a byte each.
const GROUP_ROWS: u32 = 4u;
const THREADS: u32 = 256u;
// Planes loaded into workgroup memory at a time: 64 x 144 bytes = 9 KiB (`batch_rows`, 64 x
// PLANE_ROWS rows).
const BATCH: u32 = 64u;
const F32_MAX: f32 = 3.4028234e38;
// Stands in for an infinite chord length (a line along an axis is not bounded by that axis).
const BIG: f32 = 3.0e38;
const PI: f32 = 3.14159265358979;
const HALF_PI: f32 = 1.57079632679490;
const FRAC_1_PI: f32 = 0.318309886183791;
const FRAC_2_PI: f32 = 0.636619772367581;

// ---------------------------------------------------------------------------------------------
// numeric.rs, in the same operations.

// `dir . v`, summed x, y, z in that order (gather.rs `RayBlock::dot`).
fn dot3(d: vec3<f32>, v: vec3<f32>) -> f32 {
    return fma(d.z, v.z, fma(d.y, v.y, d.x * v.x));
}

// The CPU's compare-and-select minimum and maximum (simd.rs `Lanes::min`, `max`).
fn min_sel(a: f32, b: f32) -> f32 {
    return select(b, a, a < b);
}
fn max_sel(a: f32, b: f32) -> f32 {
    return select(b, a, a > b);
}

// numeric.rs `exp_lanes`: Cody-Waite reduction, Taylor to r^7 by Estrin's scheme, 2^k written
// into the exponent bits; 0 below -87. k is rounded by `round` (to nearest, ties to even, as the
// CPU's 1.5 * 2^23 trick): llvmpipe folds (x c + R) - R into x c, which loses the rounding.
fn exp_f(x: f32) -> f32 {
    if (NATIVE_MATH) {
        return select(exp(x), 0.0, x < -87.0);
    }
    let LN2_HI = 0.69314575;
    let LN2_LO = 1.4286068e-6;
    let k = round(x * 1.44269504088896);
    let r = fma(k, -LN2_LO, fma(k, -LN2_HI, x));
    let r2 = r * r;
    let r4 = (r * r) * (r * r);
    let low = fma(r2, fma(r, 1.0 / 6.0, 0.5), 1.0 + r);
    let high = fma(r2, fma(r, 1.0 / 5040.0, 1.0 / 720.0), fma(r, 1.0 / 120.0, 1.0 / 24.0));
    let p = fma(r4, high, low);
    // 2^k, k kept where the exponent field holds it (x < -87 gives 0 below).
    let scale = bitcast<f32>(u32(clamp(i32(k), -126, 127) + 127) << 23u);
    return select(p * scale, 0.0, x < -87.0);
}

// numeric.rs `atan_unit_lanes`: atan(t) for t in [0, 1].
fn atan_unit(t: f32) -> f32 {
    if (NATIVE_MATH) {
        return atan(t);
    }
    let t2 = t * t;
    let t4 = t2 * t2;
    let t8 = (t2 * t2) * (t2 * t2);
    let p01 = fma(t2, -0.33333093, 1.0);
    let p23 = fma(t2, -0.14207134, 0.19993055);
    let p45 = fma(t2, -0.07533678, 0.10654679);
    let p67 = fma(t2, -0.016283017, 0.043039385);
    let p = fma(t8, fma(t8, 0.002903554, fma(t4, p67, p45)), fma(t4, p23, p01));
    return t * p;
}

// `small / large`, 0 where `large` is not positive (no division by zero).
fn ratio_or_zero(small: f32, large: f32) -> f32 {
    return select(0.0, small / select(1.0, large, large > 0.0), large > 0.0);
}

// numeric.rs `atan2_lanes`.
fn atan2_f(y: f32, x: f32) -> f32 {
    if (NATIVE_MATH) {
        return select(atan2(y, x), 0.0, x == 0.0 && y == 0.0);
    }
    let ax = abs(x);
    let ay = abs(y);
    let steep = ay > ax;
    let small = select(ay, ax, steep);
    let large = select(ax, ay, steep);
    var a = atan_unit(ratio_or_zero(small, large));
    a = select(a, HALF_PI - a, steep);
    a = select(a, PI - a, x < 0.0);
    return select(a, -a, y < 0.0);
}

// numeric.rs `ln_lanes`: x = m 2^e from the bits, m in [sqrt(1/2), sqrt(2)), a degree-6 fit.
fn ln_f(x: f32) -> f32 {
    if (NATIVE_MATH) {
        return log(max(x, 1.17549435e-38));
    }
    let LN2_HI = 0.69314575;
    let LN2_LO = 1.4286068e-6;
    let bits = bitcast<u32>(x);
    var m = bitcast<f32>((bits & 0x007fffffu) | 0x3f800000u);
    var e = f32(i32((bits >> 23u) & 0xffu) - 127);
    let big = m > 1.41421356237310;
    m = select(m, m * 0.5, big);
    e = select(e, e + 1.0, big);
    let f = m - 1.0;
    let f2 = f * f;
    let f4 = (f * f) * (f * f);
    let low = fma(f2, fma(f, -0.1657758, 0.19963062), fma(f, -0.25001338, 0.3333391));
    let high = fma(f2, 0.08700456, fma(f, -0.14267519, 0.14914776));
    let p = fma(f4, high, low);
    let sum = fma(f2 * f, p, fma(f2, -0.5, f));
    return fma(e, LN2_HI, fma(e, LN2_LO, sum));
}

// ---------------------------------------------------------------------------------------------
// The chord (section 2.2) and the denominators (section 2.4): weights/denominators.rs.

// 1 / x for x >= 0, with 0 standing for infinity (x = 0 or too small for a finite reciprocal).
fn reciprocal_or_zero(x: f32) -> f32 {
    return select(0.0, 1.0 / select(1.0, x, x > 1e-30), x > 1e-30);
}

// x / (1 / inv): x times a reciprocal, BIG where the reciprocal is infinite (0).
fn over(x: f32, inv: f32) -> f32 {
    return select(x * inv, BIG, inv == 0.0);
}

// light.rs `chord_width` for a point (p, q) of a w x h light along the direction given by
// cos > 0 and the reciprocals of |cos| and sin.
fn chord_width(w: f32, h: f32, p: f32, q: f32, cos_positive: bool, inv_abs_cos: f32, inv_sin: f32) -> f32 {
    let fx = select(p, w - p, cos_positive);
    let bx = select(w - p, p, cos_positive);
    let forward = min_sel(over(fx, inv_abs_cos), over(h - q, inv_sin));
    let backward = min_sel(over(bx, inv_abs_cos), over(q, inv_sin));
    return max_sel(backward, 0.0) + max_sel(forward, 0.0);
}

// The light vertex y' of chord parameter a in light-local coordinates, kept inside
// (denominators.rs `PlaneFrame::vertex_lanes`).
fn vertex(pl: Plane, a: f32) -> vec2<f32> {
    let p = min_sel(max_sel(fma(a, pl.cos_a, pl.p0), 0.0), pl.light_w);
    let q = min_sel(max_sel(fma(a, pl.sin_a, pl.q0), 0.0), pl.light_h);
    return vec2<f32>(p, q);
}

// (a_u, a_v) from det(alpha) and det(alpha_perp) (denominators.rs `a_uv`, section 2.4).
fn a_uv(pl: Plane, det: f32, det_perp: f32) -> vec2<f32> {
    return vec2<f32>(fma(det, pl.cos_a, -(pl.sin_a * det_perp)), fma(det, pl.sin_a, pl.cos_a * det_perp));
}

// beta = alpha + k pi / K of a plane at alpha, turned by `rot` (cos, sin of k pi / K) and
// reduced to [0, pi) so that sin(beta) >= 0: (cos, sin, 1 / |cos|, 1 / sin) of beta, 0 for an
// infinite reciprocal (denominators.rs `StratifiedK::prepare`).
fn orientation(cos_a: f32, sin_a: f32, rot: vec2<f32>) -> vec4<f32> {
    var c = cos_a * rot.x - sin_a * rot.y;
    var s = sin_a * rot.x + cos_a * rot.y;
    let flip = s < 0.0;
    c = select(c, -c, flip);
    s = select(s, -s, flip);
    return vec4<f32>(c, s, reciprocal_or_zero(abs(c)), reciprocal_or_zero(s));
}

// smis-cosine and smis-exact with K orientations (denominators.rs `StratifiedK`), the
// orientations summed in the order k = 0, 1, .., K - 1; a plane's further orientations made
// here, or read from `orients[at..]` (`orient`).
fn stratified(pl: Plane, det: f32, det_perp: f32, a: f32, exact: bool, at: u32) -> f32 {
    let uv = a_uv(pl, det, det_perp);
    let pq = vertex(pl, a);
    var sum = select(abs(det), pl.width * abs(det), exact);
    let orientations = select(params.orientations, ORIENTATIONS, ORIENTATIONS > 0u);
    for (var k = 0u; k + 1u < orientations; k++) {
        var o: vec4<f32>;
        if (ORIENTATION_TABLE) {
            o = orients[at + k];
        } else {
            o = orientation(pl.cos_a, pl.sin_a, rotations[k]);
        }
        let d = abs(fma(uv.x, o.x, o.y * uv.y));
        if (exact) {
            let w = chord_width(pl.light_w, pl.light_h, pq.x, pq.y, o.x > 0.0, o.z, o.w);
            sum = fma(w, d, sum);
        } else {
            sum = sum + d;
        }
    }
    let mean = sum * params.inv_orientations;
    return select(pl.width * mean, mean, exact);
}

// ---------------------------------------------------------------------------------------------
// cmis-exact: the closed form of section 3 in f32 (weights/closed_form.rs
// `cmis_exact_mean_lanes`, `zero_correction`, `ln_ratio`, `corner_angles`).

// ln(1 + x) for ratio = 1 + x: from x where |x| < 1/2 (its rounding added back), else the ratio.
fn ln_ratio(x: f32, ratio: f32) -> f32 {
    let near_one = abs(x) < 0.5;
    let u = 1.0 + x;
    let argument = select(ratio, u, near_one);
    let rounding = select(0.0, x - (u - 1.0), near_one);
    return ln_f(argument) + rounding;
}

// A corner's angles from the normals of the edges at distances y and x.
fn corner_angles(x: f32, y: f32) -> vec2<f32> {
    let steep = x > y;
    let small = select(x, y, steep);
    let large = select(y, x, steep);
    let a = atan_unit(ratio_or_zero(small, large));
    let b = HALF_PI - a;
    return vec2<f32>(select(a, b, steep), select(b, a, steep));
}

// What the zero of det in direction (zx, zy) adds: 2 min(|arc_1|, |dF_e - arc_1|) on the edge the
// direction leaves through. dists: left, right, bottom, top; values: the sectors' dF_e.
fn zero_correction(zx: f32, zy: f32, z2: f32, dists: vec4<f32>, values: vec4<f32>) -> f32 {
    let x0 = dists.x;
    let x1 = dists.y;
    let y0 = dists.z;
    let y1 = dists.w;
    let east = zx > 0.0;
    let north = zy > 0.0;
    let dx = select(x0, x1, east);
    let dy = select(y0, y1, north);
    let vertical = (dx * abs(zy)) < (dy * abs(zx));
    let d = select(dy, dx, vertical);
    let z_n = select(abs(zy), abs(zx), vertical);
    let z_t = select(select(zx, -zx, north), select(-zy, zy, east), vertical);
    let t_s = -select(select(x0, x1, north), select(y1, y0, east), vertical);
    let value = select(select(values.x, values.z, north), select(values.w, values.y, east), vertical);
    let cross = fma(d, z_t, -(t_s * z_n));
    let dot = fma(d, z_n, t_s * z_t);
    let turn = atan2_f(cross, dot);
    let gap = -cross * fma(z_n, t_s, d * z_t);
    let d2 = d * d;
    let den = d2 * z2;
    // d = 0 (no arc) or z = 0 (a = 0, D = 0): the CPU's infinite reciprocal comes out as a
    // correction of 0 either way; here the reciprocal is 0 instead.
    let inv = select(0.0, 1.0 / select(1.0, den, den > 0.0), den > 0.0);
    let small = gap * inv;
    let ratio = (z_n * z_n) * fma(t_s, t_s, d2) * inv;
    let ell = 0.5 * ln_ratio(small, ratio);
    let arc = d * fma(z_t, turn, z_n * ell);
    let correction = 2.0 * min_sel(abs(arc), abs(value - arc));
    return select(0.0, correction, d > 0.0);
}

// A sector's dF_e (section 3): the edge at distance `dist`, z in its frame (z_t, z_n), its turn,
// |r_start|^2 - |r_end|^2 as `delta` and both squared distances; 0 on an edge through the vertex.
fn sector(dist: f32, z_t: f32, z_n: f32, turn: f32, delta: f32, start: f32, end: f32) -> f32 {
    // The end corner is the vertex only on an edge through it (d_e = 0, masked below).
    let inv = select(0.0, 1.0 / select(1.0, end, end > 0.0), end > 0.0);
    let ell = 0.5 * ln_ratio(delta * inv, start * inv);
    let value = dist * fma(z_t, turn, z_n * ell);
    return select(0.0, value, dist > 0.0);
}

// (1/pi) integral_0^pi g(beta) d beta for the vertex (p, q) of a w x h light (section 3).
fn cmis_exact_mean(w: f32, h: f32, p: f32, q: f32, a_u: f32, a_v: f32) -> f32 {
    let zx = -a_v;
    let zy = a_u;
    let x0 = p;
    let x1 = w - p;
    let y0 = q;
    let y1 = h - q;
    let c0 = corner_angles(x0, y0);
    let c1 = corner_angles(x1, y0);
    let c2 = corner_angles(x1, y1);
    let c3 = corner_angles(x0, y1);
    // Corners counter-clockwise from (0, 0), relative to the vertex, and their squared
    // distances; edge e runs from corner e to corner e + 1. The four sectors written out (no
    // array indexed in a loop, which a compiler may keep in memory rather than registers).
    let cx0 = -p;
    let cy0 = -q;
    let r2_0 = fma(cx0, cx0, cy0 * cy0);
    let r2_1 = fma(x1, x1, cy0 * cy0);
    let r2_2 = fma(x1, x1, y1 * y1);
    let r2_3 = fma(cx0, cx0, y1 * y1);
    let values = vec4<f32>(
        sector(y0, zx, -zy, c0.x + c1.x, -w * (cx0 + x1), r2_0, r2_1),
        sector(x1, zy, zx, c1.y + c2.y, -h * (cy0 + y1), r2_1, r2_2),
        sector(y1, -zx, zy, c2.x + c3.x, w * (x1 + cx0), r2_2, r2_3),
        sector(x0, -zy, -zx, c3.y + c0.y, h * (y1 + cy0), r2_3, r2_0),
    );
    let total = ((abs(values.x) + abs(values.y)) + abs(values.z)) + abs(values.w);
    let z2 = fma(zx, zx, zy * zy);
    let dists = vec4<f32>(x0, x1, y0, y1);
    let plus = zero_correction(zx, zy, z2, dists, values);
    let minus = zero_correction(-zx, -zy, z2, dists, -values);
    let mean = (total + plus + minus) * FRAC_1_PI;
    return select(0.0, mean, mean > 0.0);
}

// D of a hit (section 2.4, the table's rows); `at`: where the plane's further orientations are
// in `orients` (estimators 5 and 6).
fn denominator(pl: Plane, det: f32, det_perp: f32, a: f32, at: u32) -> f32 {
    switch ESTIMATOR {
        case 0u: {
            return pl.width * abs(det);
        }
        case 1u: {
            return pl.width * FRAC_2_PI * sqrt(fma(det, det, det_perp * det_perp));
        }
        case 2u: {
            return pl.width * 0.5 * (abs(det) + abs(det_perp));
        }
        case 3u: {
            let pq = vertex(pl, a);
            let wp = chord_width(pl.light_w, pl.light_h, pq.x, pq.y, pl.perp_cos_positive != 0u, pl.perp_inv_abs_cos, pl.perp_inv_sin);
            return 0.5 * fma(wp, abs(det_perp), pl.width * abs(det));
        }
        case 4u: {
            let uv = a_uv(pl, det, det_perp);
            let pq = vertex(pl, a);
            let u = pl.inv_unit;
            return cmis_exact_mean(pl.light_w * u, pl.light_h * u, pq.x * u, pq.y * u, uv.x, uv.y) * pl.unit;
        }
        case 5u: {
            return stratified(pl, det, det_perp, a, false, at);
        }
        default: {
            return stratified(pl, det, det_perp, a, true, at);
        }
    }
}

// Whether a panel blocks the light path from chord parameter a to plane distance r
// (occlusion.rs `Occluder::blocks_lanes`, section 2.3).
fn blocked(pl: Plane, a: f32, r: f32) -> bool {
    for (var o = pl.occluders_start; o < pl.occluders_end; o++) {
        let oc = occluders[o];
        let t = oc.t0 + a * oc.t_a;
        let p = oc.p0 + a * oc.p_a;
        let q = oc.q0 + a * oc.q_a;
        if (t > 1e-6 * r && t < r * (1.0 - 1e-6) && p >= 0.0 && p <= oc.width && q >= 0.0 && q <= oc.height) {
            return true;
        }
    }
    return false;
}

// C of a hit with its scale, `power Tr / (N D)` per channel (gather.rs `PlaneView::contribution`):
// zero where D is not positive, where a channel's value would not be a finite f32 (checked as
// exp(-sigma_t length) scale <= F32_MAX D, before any division), or where a panel blocks.
fn contribution(pl: Plane, length: f32, d: f32) -> vec3<f32> {
    if (!(d > 0.0)) {
        return vec3<f32>(0.0);
    }
    var e: vec3<f32>;
    if (params.grey != 0u) {
        e = vec3<f32>(exp_f(-params.sigma_t.x * length));
    } else {
        e = vec3<f32>(exp_f(-params.sigma_t.x * length), exp_f(-params.sigma_t.y * length), exp_f(-params.sigma_t.z * length));
    }
    // e <= 1 and scale is finite: the products are finite; the bound falls below 1 only where d
    // is small, and then d * F32_MAX is finite.
    let bound = max(e.x * pl.scale.x, max(e.y * pl.scale.y, e.z * pl.scale.z));
    if (!(d >= 1.0 || bound <= d * F32_MAX)) {
        return vec3<f32>(0.0);
    }
    return pl.scale * (e / d);
}

// 1 / (4 pi rho m) of the Henyey-Greenstein phase function for a hit seen along dir on a plane
// swept along pl.toward / sign(g), m the weight of the way its direction was drawn (gather.rs
// `Phase::inverse_lanes`, docs/mathematics.md sections 1.1 and 2.5): bracket^(3/2) times
// pl.phase_scale = 1 / ((1 - g^2) m), bracket = (1 - |g|)^2 + |g| |dir + toward|^2, in
// [(1 - |g|)^2, (1 + |g|)^2]: positive and finite.
fn inverse_phase(dir: vec3<f32>, toward: vec3<f32>, scale: f32) -> f32 {
    let v = dir + toward;
    let squared = fma(v.z, v.z, fma(v.y, v.y, v.x * v.x));
    let bracket = fma(params.phase_h, squared, params.phase_floor);
    return bracket * sqrt(bracket) * scale;
}

// ---------------------------------------------------------------------------------------------
// The gather over work items, and the reduction of a tile's items.

var<workgroup> batch_rows: array<vec4<u32>, BATCH * PLANE_ROWS>;
var<workgroup> batch_ranges: array<u32, BATCH>;
// The staged planes' indices (where their orientations are in `orients`).
var<workgroup> batch_planes: array<u32, BATCH>;

// Row `k` of the staged planes as floats.
fn row(k: u32) -> vec4<f32> {
    return bitcast<vec4<f32>>(batch_rows[k]);
}

// The staged plane whose first row is `base`, as the record's layout reads (gather.rs
// `PlaneRecord`: the f32 fields are the bits of their words).
fn plane_at(base: u32) -> Plane {
    let r0 = row(base);
    let r1 = row(base + 1u);
    let r2 = batch_rows[base + 2u];
    let r3 = batch_rows[base + 3u];
    let r4 = row(base + 4u);
    let r5 = row(base + 5u);
    let r6 = row(base + 6u);
    let r7 = batch_rows[base + 7u];
    let r8 = batch_rows[base + 8u];
    return Plane(
        r0.xyz, r0.w, r1.xyz, r1.w, bitcast<vec3<f32>>(r2.xyz), r2.w, bitcast<vec3<f32>>(r3.xyz), r3.w,
        r4.xyz, r4.w, r5.x, r5.y, r5.z, r5.w, r6.x, r6.y, r6.z, r6.w,
        r7.x, bitcast<f32>(r7.y), bitcast<f32>(r7.z), r7.w, bitcast<vec4<f32>>(r8).xyz, bitcast<f32>(r8.w),
    );
}
var<workgroup> wg_item: vec4<u32>;
var<workgroup> wg_total: u32;

// The pixel of the tile that invocation `li` takes, in `gather` and `reduce` alike (`partial`
// holds a work item's sums by invocation). With LANE_BLOCKS, li's bits 0-2 are the column
// within a block of 8, bits 3-4 the row within a group of 4 (GROUP_ROWS, which the bits
// follow), bit 5 the block's half of the tile and bits 6-7 the group: a warp of 32
// consecutive invocations is 8 x 4 pixels. A warp takes a plane's hit path if any of its
// pixels is in the plane's columns, and every lane waits for it; counted on the benchmark's
// 40,960 planes (gpu::TileReach::warps), the pixels in range are 79% of the lanes of the warps
// that test a plane when a warp is two rows of 16, and 89% in blocks of 8 x 4.
fn pixel_of(li: u32) -> vec2<u32> {
    if (LANE_BLOCKS) {
        return vec2<u32>((li & 7u) | ((li >> 2u) & 8u), ((li >> 3u) & 3u) | ((li >> 4u) & 12u));
    }
    return vec2<u32>(li % TILE, li / TILE);
}

@compute @workgroup_size(16, 16, 1)
fn gather(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) li: u32) {
    let index = wid.y * nwg.x + wid.x;
    if (li == 0u) {
        wg_total = item_offsets[3];
        wg_item = items[min(index, max(item_offsets[3], 1u) - 1u)];
    }
    // The dispatch is sized by a bound on the items; those past the count do nothing.
    if (index >= workgroupUniformLoad(&wg_total)) {
        return;
    }
    let item = workgroupUniformLoad(&wg_item);
    let tile = item.x;
    let local = pixel_of(li);
    let px = (tile % params.tiles_x) * TILE + local.x;
    let py = (tile / params.tiles_x) * TILE + local.y;
    let valid = px < params.width && py < params.height;
    // The item's ray set's first float, less the segment's mark in the top two bits (bin.wgsl).
    let at = (item.w & 0x3fffffffu) + (min(py, params.height - 1u) * params.width + min(px, params.width - 1u)) * RAY_FLOATS;
    let dir = vec3<f32>(rays[at], rays[at + 1u], rays[at + 2u]);
    let t0 = rays[at + 3u];
    // A pixel outside the image has an empty segment, and is tested at no plane: column 16 is
    // in no range (the CPU's count of tests leaves it out).
    let t1 = select(-1.0, rays[at + 4u], valid);
    let col = select(TILE, local.x, valid);
    // Where this pixel's group's byte is in a list entry's ranges.
    let shift = local.y / GROUP_ROWS * 8u;
    var sum = vec3<f32>(0.0);
    // The planes tested at this pixel and those hit (each at most the item's planes, 512).
    var tests = 0u;
    var hits = 0u;
    for (var b = item.y; b < item.z; b += BATCH) {
        let n = min(BATCH, item.z - b);
        workgroupBarrier();
        // Every thread stages rows: thread i the rows i, i + 256, ... of the batch's planes, so
        // that a plane's nine rows are read by nine neighbouring threads at once.
        for (var k = li; k < n * PLANE_ROWS; k += THREADS) {
            let p = k / PLANE_ROWS;
            batch_rows[k] = plane_rows[list[b + p] * PLANE_ROWS + (k - p * PLANE_ROWS)];
        }
        if (li < n) {
            batch_ranges[li] = ranges[b + li];
        }
        if (ORIENTATION_TABLE && li < n) {
            batch_planes[li] = list[b + li];
        }
        workgroupBarrier();
        for (var j = 0u; j < n; j++) {
            // Only the pixels in the plane's columns for their group of rows (bin.wgsl's
            // `ranges`): the others are more than a pixel from its screen polygon.
            let g = batch_ranges[j] >> shift;
            if (col < (g & 15u) || col > ((g >> 4u) & 15u)) {
                continue;
            }
            tests += 1u;
            // Section 2.3: Cramer's rule with det = we . n_P; a hit needs det != 0 (tested as
            // |det| > 1e-30, so that 1/det is finite), t in [t0, t1], a on the chord, r > 0.
            // The test reads the plane's first three rows only, the hit the whole plane.
            let base = j * PLANE_ROWS;
            let n_t = row(base);
            let a_w = row(base + 1u);
            let det = dot3(dir, n_t.xyz);
            let crosses = abs(det) > 1e-30;
            let inv = 1.0 / select(1.0, det, crosses);
            let t = n_t.w * inv;
            let a = dot3(dir, a_w.xyz) * inv;
            let r = dot3(dir, row(base + 2u).xyz) * inv;
            if (crosses && t >= t0 && t <= t1 && a >= 0.0 && a <= a_w.w && r > 0.0) {
                hits += 1u;
                let pl = plane_at(base);
                if (!blocked(pl, a, r)) {
                    let det_perp = dot3(dir, pl.normal_perp);
                    let at = select(0u, batch_planes[j] * (params.orientations - 1u), ORIENTATION_TABLE);
                    var d = denominator(pl, det, det_perp, a, at);
                    // The phase value divides D (section 1.1); D > 0 is tested after, as the
                    // CPU's D > 0 and finite test drop the same hits.
                    if (params.phase_hg != 0u && d > 0.0) {
                        d = d * inverse_phase(dir, pl.toward, pl.phase_scale);
                    }
                    sum += contribution(pl, (t - t0) + r, d);
                }
            }
        }
    }
    // Both counts in one float, exactly: hits + 1024 tests < 2^24.
    partial[index * THREADS + li] = vec4<f32>(sum, f32(hits | (tests << 10u)));
}

// With K orientations and ORIENTATION_TABLE, each plane's K - 1 further orientations, once a
// gathering rather than at every hit (denominators.rs `StratifiedK::prepare` makes them once a
// plane): a thread per (plane, k), `orientation` as at a hit.
@compute @workgroup_size(256, 1, 1)
fn orient(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) li: u32) {
    let others = params.orientations - 1u;
    let i = (wid.y * nwg.x + wid.x) * THREADS + li;
    if (others == 0u || i >= params.planes * others) {
        return;
    }
    let plane = i / others;
    let k = i - plane * others;
    // `Plane`'s sixth row: cos_a, sin_a, p0, q0.
    let alpha = bitcast<vec4<f32>>(plane_rows[plane * PLANE_ROWS + 5u]);
    orients[i] = orientation(alpha.x, alpha.y, rotations[k]);
}

var<workgroup> tile_hits: atomic<u32>;
var<workgroup> tile_tests: atomic<u32>;

// Adds each pixel's work items to the image in order, batch by batch and a batch's segments one
// by one (each one's sum added to the pixel's as it would be alone: the same bits however a
// gathering's pieces are cut into batches and rounds, given the work items' size), and the tile's hits and tests (integer sums: the same in any order) to its counts.
@compute @workgroup_size(16, 16, 1)
fn reduce(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    if (li == 0u) {
        atomicStore(&tile_hits, 0u);
        atomicStore(&tile_tests, 0u);
    }
    workgroupBarrier();
    let local = pixel_of(li);
    let px = wid.x * TILE + local.x;
    let py = wid.y * TILE + local.y;
    let tile = wid.y * params.tiles_x + wid.x;
    // No early return: every invocation reaches the barrier below.
    if (px < params.width && py < params.height) {
        let at = 3u * (py * params.width + px);
        var held = vec3<f32>(bitcast<f32>(image[at]), bitcast<f32>(image[at + 1u]), bitcast<f32>(image[at + 2u]));
        var hits = 0u;
        var tests = 0u;
        for (var r = 0u; r < params.regions; r++) {
            let region = 4u + r * (params.tiles + 1u) + tile;
            let lo = item_offsets[region];
            let hi = item_offsets[region + 1u];
            var sum = vec3<f32>(0.0);
            // A batch's segments (a join's pieces, each along its ray set) added one by one,
            // each as it would be alone: its items' ray set and mark tell where the next begins.
            var rays = 0u;
            if (lo < hi) {
                rays = items[lo].w;
            }
            for (var k = lo; k < hi; k++) {
                let w = items[k].w;
                if (w != rays) {
                    held = held + sum;
                    sum = vec3<f32>(0.0);
                    rays = w;
                }
                let v = partial[k * THREADS + li];
                sum += v.xyz;
                let counts = u32(v.w);
                hits += counts & 1023u;
                tests += counts >> 10u;
            }
            held = held + sum;
        }
        let added = bitcast<vec3<u32>>(held);
        image[at] = added.x;
        image[at + 1u] = added.y;
        image[at + 2u] = added.z;
        atomicAdd(&tile_hits, hits);
        atomicAdd(&tile_tests, tests);
    }
    workgroupBarrier();
    if (li == 0u) {
        // A round adds at most 256 pixels x ROUND_PLANES (2^22) planes hits (and tests) to a
        // tile: within a u32, and the tile's totals carried into their high words.
        let at = 3u * params.width * params.height + 4u * tile;
        let added = vec2<u32>(atomicLoad(&tile_hits), atomicLoad(&tile_tests));
        for (var c = 0u; c < 2u; c++) {
            let low = image[at + 2u * c] + added[c];
            image[at + 2u * c + 1u] += select(0u, 1u, low < image[at + 2u * c]);
            image[at + 2u * c] = low;
        }
    }
}
