// Binning a batch of planes to 16 x 16 pixel tiles on the GPU (docs/gpu.md): count, prefix sum,
// scatter, as tiled splatting rasterizers do, without atomics and without a sort.
//
// Each plane comes with the tiles its screen polygon can touch, row of tiles by row (gpu/mod.rs
// `tile_reach`, from raster.rs `screen_polygon`, made on the CPU with the plane's other
// constants). `count`: a workgroup per tile counts the planes that reach the tile. `scan`:
// one workgroup turns the counts into each tile's first list entry and first work item (a tile
// of n planes is cut into ceil(n / item_planes) work items). `scatter`: a workgroup per tile
// writes its list in plane order (a prefix sum of the flags of 256 planes at a time) and its
// work items. Plane order within a tile is what makes the gather's sums the same bits from run
// to run; a scatter by atomic cursors would not keep it.
//
// Every loop of an invocation runs at most count / 256 (<= 64) or tiles / 256 times, well
// within llvmpipe's silent limit of about 65,000 loop iterations per invocation.

struct Params {
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles: u32,
    // Planes in this batch, and the index of its first plane in `reach` (and the planes buffer).
    count: u32,
    first: u32,
    item_planes: u32,
    pad: u32,
};

@group(0) @binding(0) var<uniform> params: Params;
// Per plane (gpu/mod.rs `TileReach`): its first row of tiles, its rows, and where its spans start.
@group(0) @binding(1) var<storage, read> reach: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read_write> tile_counts: array<u32>;
@group(0) @binding(3) var<storage, read_write> offsets: array<u32>;
@group(0) @binding(4) var<storage, read_write> item_offsets: array<u32>;
@group(0) @binding(5) var<storage, read_write> list: array<u32>;
@group(0) @binding(6) var<storage, read_write> items: array<vec4<u32>>;
// Per plane and row of tiles: its first and last column of tiles (inclusive; empty when first >
// last), and its box of pixels in the row: first and last column, first and last row, each
// pair packed `first | last << 16`.
@group(0) @binding(7) var<storage, read> spans: array<vec4<u32>>;
// Per list entry, the plane's box of pixels within the tile (gather.wgsl tests only those):
// first and last column, first and last row, relative to the tile, 4 bits each.
@group(0) @binding(8) var<storage, read_write> boxes: array<u32>;

const THREADS: u32 = 256u;
const TILE: u32 = 16u;

var<workgroup> scratch: array<u32, 256>;
var<workgroup> scratch_items: array<u32, 256>;

// Whether plane `plane` reaches tile `tile`: the tile's row among the plane's and its column in
// that row's span.
fn covers(plane: u32, tile: u32) -> bool {
    let r = reach[plane];
    let row = tile / params.tiles_x;
    if (row < r.x || row - r.x >= r.y) {
        return false;
    }
    let span = spans[r.z + row - r.x];
    let col = tile % params.tiles_x;
    return span.x <= col && col <= span.y;
}

// The box of pixels of plane `plane` within tile `tile` (which it reaches), packed for `boxes`.
fn box_in(plane: u32, tile: u32) -> u32 {
    let r = reach[plane];
    let row = tile / params.tiles_x;
    let span = spans[r.z + row - r.x];
    let x = vec2<u32>(span.z & 0xffffu, span.z >> 16u);
    let y = vec2<u32>(span.w & 0xffffu, span.w >> 16u);
    let corner = vec2<u32>((tile % params.tiles_x) * TILE, row * TILE);
    let bx = min(max(x, vec2<u32>(corner.x)), vec2<u32>(corner.x + TILE - 1u)) - corner.x;
    let by = min(max(y, vec2<u32>(corner.y)), vec2<u32>(corner.y + TILE - 1u)) - corner.y;
    return bx.x | (bx.y << 4u) | (by.x << 8u) | (by.y << 12u);
}

// Inclusive prefix sum of scratch over the workgroup (Hillis and Steele), in uniform control flow.
fn scan_scratch(li: u32) {
    for (var off = 1u; off < THREADS; off <<= 1u) {
        workgroupBarrier();
        let v = select(0u, scratch[li - select(0u, off, li >= off)], li >= off);
        workgroupBarrier();
        scratch[li] += v;
    }
    workgroupBarrier();
}

@compute @workgroup_size(256, 1, 1)
fn count(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) li: u32) {
    let tile = wid.y * nwg.x + wid.x;
    if (tile >= params.tiles) {
        return;
    }
    var c = 0u;
    for (var i = li; i < params.count; i += THREADS) {
        c += select(0u, 1u, covers(params.first + i, tile));
    }
    scratch[li] = c;
    for (var s = THREADS / 2u; s > 0u; s >>= 1u) {
        workgroupBarrier();
        if (li < s) {
            scratch[li] += scratch[li + s];
        }
    }
    if (li == 0u) {
        tile_counts[tile] = scratch[0];
    }
}

@compute @workgroup_size(256, 1, 1)
fn scan(@builtin(local_invocation_index) li: u32) {
    let tiles = params.tiles;
    let per = (tiles + THREADS - 1u) / THREADS;
    let lo = min(li * per, tiles);
    let hi = min(lo + per, tiles);
    var c = 0u;
    var n_items = 0u;
    for (var t = lo; t < hi; t++) {
        let k = tile_counts[t];
        c += k;
        n_items += (k + params.item_planes - 1u) / params.item_planes;
    }
    // Both prefix sums through `scratch`, one after the other.
    scratch[li] = c;
    scan_scratch(li);
    var run = scratch[li] - c;
    let total = scratch[THREADS - 1u];
    workgroupBarrier();
    scratch[li] = n_items;
    scan_scratch(li);
    var run_items = scratch[li] - n_items;
    let total_items = scratch[THREADS - 1u];
    for (var t = lo; t < hi; t++) {
        let k = tile_counts[t];
        offsets[t] = run;
        item_offsets[t] = run_items;
        run += k;
        run_items += (k + params.item_planes - 1u) / params.item_planes;
    }
    if (li == 0u) {
        offsets[tiles] = total;
        item_offsets[tiles] = total_items;
    }
}

@compute @workgroup_size(256, 1, 1)
fn scatter(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) li: u32) {
    let tile = wid.y * nwg.x + wid.x;
    if (tile >= params.tiles) {
        return;
    }
    let base = offsets[tile];
    let end = offsets[tile + 1u];
    let first_item = item_offsets[tile];
    let n_items = item_offsets[tile + 1u] - first_item;
    for (var k = li; k < n_items; k += THREADS) {
        let s = base + k * params.item_planes;
        items[first_item + k] = vec4<u32>(tile, s, min(s + params.item_planes, end), 0u);
    }
    var written = 0u;
    for (var b = 0u; b < params.count; b += THREADS) {
        let i = b + li;
        let hit = i < params.count && covers(params.first + min(i, params.count - 1u), tile);
        let flag = select(0u, 1u, hit);
        workgroupBarrier();
        scratch[li] = flag;
        scan_scratch(li);
        if (hit) {
            let at = base + written + scratch[li] - 1u;
            list[at] = params.first + i;
            boxes[at] = box_in(params.first + i, tile);
        }
        written += scratch[THREADS - 1u];
    }
}
