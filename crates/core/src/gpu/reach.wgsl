// The tiles and pixels each plane's screen polygon comes near, found on the GPU from the polygon
// (docs/gpu.md): gpu/reach.rs `tile_reach` in f32, with SLACK more margin than its pixel, so that
// what it finds holds the CPU's (tests/gpu.rs). A thread per row of tiles of the chunk's planes
// (the CPU gives each plane its rows, gpu/reach.rs `ScreenReach`) writes the row's span of tiles
// and, per group of 4 pixel rows in it, the pixel columns whose squares come within a pixel of
// the polygon: what bin.wgsl's `covers` and `ranges_in` read. The polygon's vertices cross (4.2 a
// plane on the benchmark, 8 bytes each), not its rows (11.5 a plane, 20 bytes each).
//
// Loops: a binary search over the planes (at most 32 steps) and the polygon's edges (at most 16)
// times 5 strips, well within llvmpipe's silent limit of about 65,000 iterations.

struct Params {
    width: u32,
    height: u32,
    // The chunk's planes, and their rows of tiles in all.
    planes: u32,
    rows: u32,
};

@group(0) @binding(0) var<uniform> params: Params;
// Per plane, and one more after the last: its first row of tiles, its rows, its first row's index
// among all the rows, its first vertex (its vertices end where the next plane's begin).
@group(0) @binding(1) var<storage, read> reach: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> vertices: array<vec2<f32>>;
// Per row: its first and last column of tiles, packed `first | last << 16` (1 where none).
@group(0) @binding(3) var<storage, read_write> spans: array<u32>;
// Per row: per group of 4 pixel rows, its first and last pixel column, packed likewise.
@group(0) @binding(4) var<storage, read_write> groups: array<vec4<u32>>;

const TILE: u32 = 16u;
const GROUP_ROWS: u32 = 4u;
// gpu/reach.rs `SLACK`, and the margin: the specification's pixel and the slack.
const SLACK: f32 = 0.03125;
const M: f32 = 1.0 + SLACK;
// No strip's range yet (Vulkan promises no infinities).
const FAR: f32 = 3.0e38;
// Edges flatter than this take their whole x-range in a strip they meet (more than their part
// there: still a superset), which keeps the slope finite.
const FLAT: f32 = 1e-3;

@compute @workgroup_size(256, 1, 1)
fn reach_rows(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
              @builtin(local_invocation_index) li: u32) {
    let i = (wid.y * nwg.x + wid.x) * 256u + li;
    if (i >= params.rows) {
        return;
    }
    // The plane: the last whose first row's index is at most i (planes without rows share their
    // index with the next).
    var lo = 0u;
    var hi = params.planes;
    while (hi - lo > 1u) {
        let mid = (lo + hi) / 2u;
        if (reach[mid].z <= i) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let r = reach[lo];
    let row = r.x + (i - r.z);
    let first = r.w;
    let n = reach[lo + 1u].w - first;
    // Strip 0 is the row of tiles, pixel rows [16 row, 16 row + 16] grown by M; strips 1 to 4 its
    // groups, [4 g, 4 g + 4] grown by M: each strip's x-range of the polygon, from the parts of its
    // edges inside (gpu/reach.rs `strip_ranges`).
    var xlo = array<f32, 5>(FAR, FAR, FAR, FAR, FAR);
    var xhi = array<f32, 5>(-FAR, -FAR, -FAR, -FAR, -FAR);
    var ylo = FAR;
    var yhi = -FAR;
    for (var e = 0u; e < n; e++) {
        let p = vertices[first + e];
        let q = vertices[first + select(e + 1u, 0u, e + 1u == n)];
        ylo = min(ylo, p.y);
        yhi = max(yhi, p.y);
        let ymin = min(p.y, q.y);
        let ymax = max(p.y, q.y);
        let ex = vec2<f32>(min(p.x, q.x), max(p.x, q.x));
        let sloped = ymax - ymin > FLAT;
        let slope = (q.x - p.x) / select(1.0, q.y - p.y, sloped);
        for (var s = 0u; s < 5u; s++) {
            // Strip 0 starts at the row's first pixel row, strip s > 0 at its group s - 1's.
            let top = f32(row * TILE + max(s, 1u) * GROUP_ROWS - GROUP_ROWS) - M;
            let bottom = top + f32(select(TILE, GROUP_ROWS, s > 0u)) + 2.0 * M;
            if (ymax < top || ymin > bottom) {
                continue;
            }
            var x = ex;
            if (sloped) {
                let xa = clamp(p.x + (max(ymin, top) - p.y) * slope, ex.x, ex.y);
                let xb = clamp(p.x + (min(ymax, bottom) - p.y) * slope, ex.x, ex.y);
                x = vec2<f32>(min(xa, xb), max(xa, xb));
            }
            xlo[s] = min(xlo[s], x.x);
            xhi[s] = max(xhi[s], x.y);
        }
    }
    // The pixel columns whose squares come within M of a strip's x-range [lo, hi]:
    // lo - 1 - M <= px <= hi + M, in the image. The row's first.
    let a = max(ceil(xlo[0] - 1.0 - M), 0.0);
    let b = min(floor(xhi[0] + M), f32(params.width - 1u));
    if (!(a <= b)) {
        spans[i] = 1u;
        groups[i] = vec4<u32>(1u);
        return;
    }
    spans[i] = (u32(a) / TILE) | ((u32(b) / TILE) << 16u);
    // The pixel rows within M of the polygon: a group with none of them has no columns.
    let row_lo = max(ceil(ylo - 1.0 - M), 0.0);
    let row_hi = min(floor(yhi + M), f32(params.height - 1u));
    var g = vec4<u32>(1u);
    for (var k = 0u; k < 4u; k++) {
        let top = f32(row * TILE + k * GROUP_ROWS);
        // Each group's columns kept in the row's.
        let x = max(xlo[k + 1u] - 1.0 - M, a);
        let y = min(xhi[k + 1u] + M, b);
        if (top > row_hi || top + f32(GROUP_ROWS - 1u) < row_lo || !(x <= y)) {
            continue;
        }
        let left = u32(ceil(x));
        let right = u32(floor(y));
        if (left <= right) {
            g[k] = left | (right << 16u);
        }
    }
    groups[i] = g;
}
