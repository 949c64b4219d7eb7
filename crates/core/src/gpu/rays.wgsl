// The camera rays of ray sets, made on the GPU where they are gathered (docs/mathematics.md
// section 8.1): `pixel::RayRow::block`'s operations in f32, a thread a pixel, a gathering's sets
// in one dispatch (a workgroup's z its set). The CPU's rays are
// the specification; tests/gpu.rs holds these to them ray by ray. What differs:
//
// - the pixel's jitter is the same integer hash, bit for bit (splitmix64 on pairs of u32 words,
//   WGSL having no u64; the Owen scramble of the set's Sobol point);
// - the arithmetic after it is f32, relative to the camera (the CPU's f64, rounded once at the
//   end): each value within a few f32 roundings of the CPU's, apart from a ray that grazes a
//   light panel's edge to rounding (crossing it on one side and not on the other);
// - no IEEE infinity or division by zero (Vulkan promises neither): an axis the ray is parallel
//   to is not divided by, and "no end yet" is F32_MAX.

// Floats of a ray in `rays`: direction x, y, z, t0, t1 (`CameraRay`, as gather.wgsl reads it).
const RAY_FLOATS: u32 = 5u;
const F32_MAX: f32 = 3.40282347e38;

// `pixel::RaySetRecord`: what every ray of the set shares.
struct RaySet {
    forward: vec3<f32>,
    tan_x: f32,
    right: vec3<f32>,
    tan_y: f32,
    up: vec3<f32>,
    width: u32,
    // The box's corners less the camera's position.
    lo: vec3<f32>,
    height: u32,
    hi: vec3<f32>,
    // Bit a: the camera lies outside the box's slab along axis a.
    outside: u32,
    // splitmix64(seed ^ RAY_SET_STREAM), as (low, high) words.
    scramble: vec2<u32>,
    // The set's 2D Sobol point before its per-pixel scramble.
    sobol: vec2<u32>,
    pixel_center: u32,
    // Its panels: how many, and where the first is in `panels`.
    panels: u32,
    first_panel: u32,
    // Where its rays begin in `rays`, in floats.
    first_float: u32,
}

// `pixel::PanelRecord`: a light panel's rectangle relative to the camera.
struct Panel {
    corner: vec3<f32>,
    to_plane: f32,
    n: vec3<f32>,
    width: f32,
    u: vec3<f32>,
    height: f32,
    v: vec3<f32>,
    pad: u32,
    // The pixels it can cover: first and last column, first and last row.
    footprint: vec4<i32>,
}

// gpu/rays.rs `Dispatch`: the dispatch's first set in `sets` (a workgroup's z its set from there).
struct Dispatch {
    first_set: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> dispatch: Dispatch;
// The sets made together, one dispatch for (up to 65,535 of) them, their panels one after
// another, and the buffer that holds all their rays.
@group(0) @binding(1) var<storage, read> sets: array<RaySet>;
@group(0) @binding(2) var<storage, read> panels: array<Panel>;
@group(0) @binding(3) var<storage, read_write> rays: array<f32>;

// --- 64-bit integers as (low, high) words ---

fn add64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}

// a >> s for 0 < s < 32.
fn shr64(a: vec2<u32>, s: u32) -> vec2<u32> {
    return vec2<u32>((a.x >> s) | (a.y << (32u - s)), a.y >> s);
}

// The high word of a * b: the four 16-bit partial products, their carries added.
fn mul_hi32(a: u32, b: u32) -> u32 {
    let a0 = a & 0xffffu;
    let a1 = a >> 16u;
    let b0 = b & 0xffffu;
    let b1 = b >> 16u;
    let p01 = a0 * b1;
    let p10 = a1 * b0;
    let mid = ((a0 * b0) >> 16u) + (p01 & 0xffffu) + (p10 & 0xffffu);
    return a1 * b1 + (p01 >> 16u) + (p10 >> 16u) + (mid >> 16u);
}

// The low 64 bits of a * b (wrapping, as u64's wrapping_mul).
fn mul64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    return vec2<u32>(a.x * b.x, mul_hi32(a.x, b.x) + a.x * b.y + a.y * b.x);
}

// `sampling::splitmix64`: one SplitMix64 step and its output function.
fn splitmix64(z0: vec2<u32>) -> vec2<u32> {
    var z = add64(z0, vec2<u32>(0x7f4a7c15u, 0x9e3779b9u));
    z = mul64(z ^ shr64(z, 30u), vec2<u32>(0x1ce4e5b9u, 0xbf58476du));
    z = mul64(z ^ shr64(z, 27u), vec2<u32>(0x133111ebu, 0x94d049bbu));
    return z ^ shr64(z, 31u);
}

// `sampling::sobol::nested_uniform_scramble`: the Laine-Karras permutation of the reversed bits.
fn nested_uniform_scramble(x: u32, seed: u32) -> u32 {
    var v = reverseBits(x);
    v ^= v * 0x3d20adeau;
    v += seed;
    v *= (seed >> 16u) | 1u;
    v ^= v * 0x05526c56u;
    v ^= v * 0x53a22864u;
    return reverseBits(v);
}

// A 32-bit fraction as a point of [0, 1): the CPU's (x + 0.5) 2^-32 within 2^-25 (f32's rounding
// of x).
fn coordinate(x: u32) -> f32 {
    return f32(x) * (1.0 / 4294967296.0);
}

@compute @workgroup_size(16, 16)
fn rays_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let ray_set = sets[dispatch.first_set + id.z];
    let i = id.x;
    let j = id.y;
    if i >= ray_set.width || j >= ray_set.height {
        return;
    }
    let p = j * ray_set.width + i;
    var s = vec2<f32>(0.5, 0.5);
    if ray_set.pixel_center == 0u {
        // `pixel::ray_set_position`: the pixel's own scramble of the set's point (the pixel's
        // index fits the low word: the rays of an image fit one binding).
        let scramble = splitmix64(ray_set.scramble ^ vec2<u32>(p, 0u));
        s = vec2<f32>(
            coordinate(nested_uniform_scramble(ray_set.sobol.x, scramble.x)),
            coordinate(nested_uniform_scramble(ray_set.sobol.y, scramble.y)),
        );
    }
    // `Camera::direction`: X = 2 x / w - 1 and Y = 1 - 2 y / h, the integer parts exact.
    let w = f32(ray_set.width);
    let h = f32(ray_set.height);
    let sx = (f32(2 * i32(i) - i32(ray_set.width)) + 2.0 * s.x) / w * ray_set.tan_x;
    let sy = (f32(i32(ray_set.height) - 2 * i32(j)) - 2.0 * s.y) / h * ray_set.tan_y;
    let v = (ray_set.forward + sx * ray_set.right) + sy * ray_set.up;
    let d = v / sqrt(dot(v, v));
    // `Medium::clip_ray`: the box's slabs; an axis the ray is parallel to only rules the ray
    // out when the camera lies outside its slab.
    var t0 = 0.0;
    var t1 = F32_MAX;
    var inside = true;
    for (var a = 0u; a < 3u; a++) {
        let da = d[a];
        if da == 0.0 {
            inside = inside && ((ray_set.outside >> a) & 1u) == 0u;
        } else {
            let near = ray_set.lo[a] / da;
            let far = ray_set.hi[a] / da;
            t0 = max(t0, min(near, far));
            t1 = min(t1, max(near, far));
        }
    }
    // `Scene::first_light_among`: the nearest panel crossed, among those whose box holds the
    // pixel, edges inside.
    var surface = F32_MAX;
    let column = i32(i);
    let row = i32(j);
    for (var k = 0u; k < ray_set.panels; k++) {
        let r = panels[ray_set.first_panel + k];
        let b = r.footprint;
        if column < b.x || column > b.y || row < b.z || row > b.w {
            continue;
        }
        let denom = dot(d, r.n);
        if denom == 0.0 {
            continue;
        }
        let t = r.to_plane / denom;
        let rel = t * d - r.corner;
        let pu = dot(rel, r.u);
        let qv = dot(rel, r.v);
        if t > 0.0 && t < surface && pu >= 0.0 && pu <= r.width && qv >= 0.0 && qv <= r.height {
            surface = t;
        }
    }
    // `Scene::segment_before`: the segment in the box before the panel, or an empty one.
    let end = min(surface, t1);
    let any = inside && t0 <= t1 && t0 < end;
    let at = ray_set.first_float + p * RAY_FLOATS;
    rays[at] = d.x;
    rays[at + 1u] = d.y;
    rays[at + 2u] = d.z;
    rays[at + 3u] = select(1.0, t0, any);
    rays[at + 4u] = select(0.0, end, any);
}
