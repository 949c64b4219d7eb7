// Binning a batch of planes to 16 x 16 pixel tiles on the GPU (docs/gpu.md): count, prefix sum,
// scatter, as tiled splatting rasterizers do, without atomics and without a sort, in two tiers.
//
// Each plane comes with the tiles its screen polygon can touch, row of tiles by row (found from
// the polygon by reach.wgsl before a chunk's first binning; gpu/reach.rs `tile_reach` is its
// specification). First to **blocks** of 4 x 4 tiles (`block_count`, `block_scan`,
// `block_scatter`): a workgroup per block lists the batch's planes that reach one of its tiles,
// in plane order. Then to tiles (`count`, `scan`, `scatter`): a workgroup per tile takes its
// candidates from its block's list, not from every plane of the batch, so that the binning's
// tests are about 3.5 times the (tile, plane) pairs on the benchmark rather than the tiles
// times the planes (16.8 times the pairs at 640x360, and growing with the image).
// `Params::blocked` = 0 skips the first tier (gpu/mod.rs `Tuning::flat_binning`, for measuring
// it): every plane of the batch is then each tile's candidate. A tile's list is the same either
// way. `count`: a workgroup per tile counts the planes that reach the tile. `scan`:
// one workgroup turns the counts into each tile's first list entry and first work item (a tile
// of n planes is cut into ceil(n / item_planes) work items), and writes the gather's grid of
// work items, which it is dispatched from. `scatter`: a workgroup per tile writes its list in
// plane order (a prefix sum of the hits of 1,024 candidates at a time, 4 a thread) and its
// work items. Plane order within a tile is what makes the gather's sums the same bits from run
// to run; a scatter by atomic cursors would not keep it.
//
// The batches of a round (gpu/batches.rs) are binned one after another into one list and one
// array of work items, each batch's after the one's before it (`scan` reads where that one
// ended), so that the gather takes the whole round's items in one dispatch. Each batch keeps its
// own tiles' first entries and first items, a region of `offsets` and `item_offsets` of tiles + 1
// words, for the scatter and for the reduction, which adds a tile's items batch by batch.
//
// Every loop of an invocation runs at most count / 256 (<= 64), tiles / 256 or blocks x
// segments / 256 times, well within llvmpipe's silent limit of about 65,000 loop iterations
// per invocation.

struct Params {
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles: u32,
    // Planes in this batch, and the index of its first plane in `reach` (and the planes buffer).
    count: u32,
    first: u32,
    item_planes: u32,
    // The batch's index in its round: its region of `offsets` and `item_offsets`.
    region: u32,
    // Its segments (gpu/batches.rs `Batch::segments`: a join's pieces, each along its ray set):
    // a tile's planes of each segment are cut into work items of their own, which carry where
    // its ray set begins in the gathering's rays.
    segments: u32,
    // 1: the tiles' candidates from their blocks' lists; 0: every plane of the batch.
    blocked: u32,
    pad1: u32,
    pad2: u32,
    // Per segment its first plane (from the batch's first) and its ray set's first float, two
    // segments a row (BATCH_SEGMENTS = 32).
    segs: array<vec4<u32>, 16>,
};

@group(0) @binding(0) var<uniform> params: Params;
// Per plane (gpu/polygons.rs `Polygons`): its first row of tiles, its rows, where its rows start
// in `spans` and `groups`, and its first vertex (read by reach.wgsl only).
@group(0) @binding(1) var<storage, read> reach: array<vec4<u32>>;
// Per tile, per segment, the segment's planes that reach the tile.
@group(0) @binding(2) var<storage, read_write> tile_counts: array<u32>;
// Per batch of the round (`region`), per tile its first list entry, then the batch's end.
@group(0) @binding(3) var<storage, read_write> offsets: array<u32>;
// The gather's grid (x, y, 1) of the round's work items so far and their number (4 words), then
// per batch of the round, per tile its first work item, then the batch's end.
@group(0) @binding(4) var<storage, read_write> item_offsets: array<u32>;
@group(0) @binding(5) var<storage, read_write> list: array<u32>;
// Work items: (tile, first list entry, end, where the batch's ray set begins).
@group(0) @binding(6) var<storage, read_write> items: array<vec4<u32>>;
// Per plane and row of tiles: its first and last column of tiles (inclusive; empty when first >
// last), packed `first | last << 16`.
@group(0) @binding(7) var<storage, read> spans: array<u32>;
// Per list entry, the plane's pixel columns within the tile for each group of 4 pixel rows
// (gather.wgsl tests only those): group k's first and last column relative to the tile, 4 bits
// each, in bits 8 k .. 8 k + 7; first 15 and last 0 where it has none.
@group(0) @binding(8) var<storage, read_write> ranges: array<u32>;
// Per plane and row of tiles (as `spans`): for each group of 4 pixel rows in it, its first and
// last pixel column, packed `first | last << 16`, first > last where none (gpu/reach.rs
// `TileReach::groups`).
@group(0) @binding(9) var<storage, read> groups: array<vec4<u32>>;
// The blocks' lists: per block, per segment, its first entry (from `block_scan`, where
// `block_count` wrote the counts), then the batch's end (blocks x segments + 1 words); from
// there, per block its planes (indices into `reach`) that reach one of its tiles, segment by
// segment in plane order.
@group(0) @binding(10) var<storage, read_write> blocks: array<u32>;

const THREADS: u32 = 256u;
const TILE: u32 = 16u;
// Tiles across and down a block (gpu/mod.rs `BLOCK_TILES`).
const BLOCK: u32 = 4u;
// Consecutive candidates a thread flags per step of a scatter, and a step's candidates: one
// prefix sum (8 rounds of barriers) serves 1,024 of them, not 256.
const PER_THREAD: u32 = 4u;
const STEP: u32 = THREADS * PER_THREAD;

var<workgroup> scratch: array<u32, 256>;
var<workgroup> scratch_items: array<u32, 256>;
// A tile's candidates, read by one thread and given to all (loops with barriers inside need
// bounds the whole workgroup is known to share).
var<workgroup> shared_lo: u32;
var<workgroup> shared_hi: u32;

// Segment s's first plane (from the batch's first), its end, and its ray set's first float.
fn seg_first(s: u32) -> u32 {
    let v = params.segs[s / 2u];
    return select(v.x, v.z, (s & 1u) == 1u);
}
fn seg_end(s: u32) -> u32 {
    return select(params.count, seg_first(min(s + 1u, 31u)), s + 1u < params.segments);
}
fn seg_rays(s: u32) -> u32 {
    let v = params.segs[s / 2u];
    return select(v.y, v.w, (s & 1u) == 1u);
}

// A tile's planes of every segment, and its work items (each segment's cut on its own).
fn tile_total(t: u32) -> vec2<u32> {
    var c = 0u;
    var n = 0u;
    for (var s = 0u; s < params.segments; s++) {
        let k = tile_counts[t * params.segments + s];
        c += k;
        n += (k + params.item_planes - 1u) / params.item_planes;
    }
    return vec2<u32>(c, n);
}

// The first word of this batch's region of `offsets`, and of `item_offsets` (after the grid).
fn list_region() -> u32 {
    return params.region * (params.tiles + 1u);
}
fn item_region() -> u32 {
    return 4u + params.region * (params.tiles + 1u);
}

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
    return (span & 0xffffu) <= col && col <= (span >> 16u);
}

// Blocks across, and in all.
fn blocks_x() -> u32 {
    return (params.tiles_x + BLOCK - 1u) / BLOCK;
}
fn block_count_all() -> u32 {
    return blocks_x() * ((params.tiles / params.tiles_x + BLOCK - 1u) / BLOCK);
}
// Where the blocks' lists begin in `blocks` (after their offsets).
fn block_lists() -> u32 {
    return block_count_all() * params.segments + 1u;
}
// The block that holds tile `tile`.
fn block_of(tile: u32) -> u32 {
    return (tile / params.tiles_x / BLOCK) * blocks_x() + (tile % params.tiles_x) / BLOCK;
}

// Whether plane `plane` reaches one of block `block`'s tiles: a span of one of its rows of
// tiles within the block meets the block's columns.
fn reaches_block(plane: u32, block: u32) -> bool {
    let r = reach[plane];
    let row0 = (block / blocks_x()) * BLOCK;
    let col0 = (block % blocks_x()) * BLOCK;
    let lo = max(row0, r.x);
    let hi = min(row0 + BLOCK, r.x + r.y);
    var meets = false;
    for (var row = lo; row < hi; row++) {
        let span = spans[r.z + row - r.x];
        let a = span & 0xffffu;
        let b = span >> 16u;
        meets = meets || (a <= b && a < col0 + BLOCK && b >= col0);
    }
    return meets;
}

// Segment s's candidates for tile `tile`, as a range of candidate indices ([`candidate`]):
// its part of the tile's block's list, or (flat) the segment's planes.
fn seg_candidates(tile: u32, s: u32) -> vec2<u32> {
    if (params.blocked == 0u) {
        return vec2<u32>(seg_first(s), seg_end(s));
    }
    let at = block_of(tile) * params.segments + s;
    return vec2<u32>(blocks[at], blocks[at + 1u]);
}
// The plane of candidate index i.
fn candidate(i: u32) -> u32 {
    if (params.blocked == 0u) {
        return params.first + i;
    }
    return blocks[block_lists() + i];
}

// The pixel columns of plane `plane` within tile `tile` (which it reaches) per group of pixel
// rows, packed for `ranges`: each group's columns kept in the tile's, 15 and 0 (no column)
// where they miss it.
fn ranges_in(plane: u32, tile: u32) -> u32 {
    let r = reach[plane];
    let row = tile / params.tiles_x;
    let g = groups[r.z + row - r.x];
    let first = g & vec4<u32>(0xffffu);
    let last = g >> vec4<u32>(16u);
    let x = (tile % params.tiles_x) * TILE;
    let meets = (first <= last) & (first < vec4<u32>(x + TILE)) & (last >= vec4<u32>(x));
    // Where it misses, these wrap (unsigned) and are not taken.
    let a = max(first, vec4<u32>(x)) - x;
    let b = min(last, vec4<u32>(x + TILE - 1u)) - x;
    let v = select(vec4<u32>(15u), a | (b << vec4<u32>(4u)), meets);
    return v.x | (v.y << 8u) | (v.z << 16u) | (v.w << 24u);
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

// The sum of every thread's `c`, by a tree in `scratch`, in uniform control flow: thread 0's
// result (the others' is 0). Its caller barriers before `scratch` is written again (thread 0
// reads it last).
fn sum_to_first(li: u32, c: u32) -> u32 {
    scratch[li] = c;
    for (var h = THREADS / 2u; h > 0u; h >>= 1u) {
        workgroupBarrier();
        if (li < h) {
            scratch[li] += scratch[li + h];
        }
    }
    if (li == 0u) {
        return scratch[0];
    }
    return 0u;
}

// A scatter's step, in uniform control flow: this thread's `hits` (a bit for each of its
// PER_THREAD candidates) placed among the workgroup's: where its first goes from the step's
// first, and the step's hits in all.
fn place_hits(li: u32, hits: u32) -> vec2<u32> {
    let mine = countOneBits(hits);
    workgroupBarrier();
    scratch[li] = mine;
    scan_scratch(li);
    return vec2<u32>(scratch[li] - mine, scratch[THREADS - 1u]);
}

@compute @workgroup_size(256, 1, 1)
fn count(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) li: u32) {
    let tile = wid.y * nwg.x + wid.x;
    if (tile >= params.tiles) {
        return;
    }
    for (var s = 0u; s < params.segments; s++) {
        var c = 0u;
        let range = seg_candidates(tile, s);
        for (var i = range.x + li; i < range.y; i += THREADS) {
            c += select(0u, 1u, covers(candidate(i), tile));
        }
        let total = sum_to_first(li, c);
        if (li == 0u) {
            tile_counts[tile * params.segments + s] = total;
        }
        workgroupBarrier();
    }
}

@compute @workgroup_size(256, 1, 1)
fn scan(@builtin(local_invocation_index) li: u32) {
    let tiles = params.tiles;
    let per = (tiles + THREADS - 1u) / THREADS;
    let lo = min(li * per, tiles);
    let hi = min(lo + per, tiles);
    // This batch's list and items begin where the round's batch before it ended.
    var list_base = 0u;
    var item_base = 0u;
    if (params.region > 0u) {
        list_base = offsets[list_region() - 1u];
        item_base = item_offsets[item_region() - 1u];
    }
    var c = 0u;
    var n_items = 0u;
    for (var t = lo; t < hi; t++) {
        let k = tile_total(t);
        c += k.x;
        n_items += k.y;
    }
    // Both prefix sums through `scratch`, one after the other.
    scratch[li] = c;
    scan_scratch(li);
    var run = list_base + scratch[li] - c;
    let total = list_base + scratch[THREADS - 1u];
    workgroupBarrier();
    scratch[li] = n_items;
    scan_scratch(li);
    var run_items = item_base + scratch[li] - n_items;
    let total_items = item_base + scratch[THREADS - 1u];
    let lr = list_region();
    let ir = item_region();
    for (var t = lo; t < hi; t++) {
        let k = tile_total(t);
        offsets[lr + t] = run;
        item_offsets[ir + t] = run_items;
        run += k.x;
        run_items += k.y;
    }
    if (li == 0u) {
        offsets[lr + tiles] = total;
        item_offsets[ir + tiles] = total_items;
        // A workgroup per item of the round so far, as gpu/device.rs `grid` lays them out (none
        // where there are none); the round's last batch writes its grid.
        let x = min(total_items, 65535u);
        item_offsets[0] = x;
        item_offsets[1] = select(1u, (total_items + x - 1u) / max(x, 1u), x > 0u);
        item_offsets[2] = 1u;
        item_offsets[3] = total_items;
    }
}

@compute @workgroup_size(256, 1, 1)
fn scatter(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) li: u32) {
    let tile = wid.y * nwg.x + wid.x;
    if (tile >= params.tiles) {
        return;
    }
    let base = offsets[list_region() + tile];
    // Each segment's part of the tile's list (the list is in plane order, so segment by
    // segment) cut into work items of its own.
    var item_at = item_offsets[item_region() + tile];
    var list_at = base;
    for (var s = 0u; s < params.segments; s++) {
        let n = tile_counts[tile * params.segments + s];
        let n_items = (n + params.item_planes - 1u) / params.item_planes;
        // Where its ray set begins (in floats, below 2^30: a binding holds under 2^32 bytes),
        // with the segment's index modulo 4 in the top two bits, so that `reduce` tells two
        // segments along one ray set apart (a group's two halves, side by side in a join).
        let rays = seg_rays(s) | ((s & 3u) << 30u);
        for (var k = li; k < n_items; k += THREADS) {
            let st = list_at + k * params.item_planes;
            items[item_at + k] = vec4<u32>(tile, st, min(st + params.item_planes, list_at + n), rays);
        }
        item_at += n_items;
        list_at += n;
    }
    // The tile's candidates, all its segments', as bounds the workgroup shares.
    if (li == 0u) {
        shared_lo = seg_candidates(tile, 0u).x;
        shared_hi = seg_candidates(tile, params.segments - 1u).y;
    }
    let lo = workgroupUniformLoad(&shared_lo);
    let hi = workgroupUniformLoad(&shared_hi);
    var written = 0u;
    for (var b = lo; b < hi; b += STEP) {
        let i0 = b + li * PER_THREAD;
        var hits = 0u;
        for (var k = 0u; k < PER_THREAD; k++) {
            let i = i0 + k;
            if (i < hi && covers(candidate(i), tile)) {
                hits |= 1u << k;
            }
        }
        let placed = place_hits(li, hits);
        var at = base + written + placed.x;
        for (var k = 0u; k < PER_THREAD; k++) {
            if ((hits & (1u << k)) != 0u) {
                let plane = candidate(i0 + k);
                list[at] = plane;
                ranges[at] = ranges_in(plane, tile);
                at++;
            }
        }
        written += placed.y;
    }
}

// The first tier: a workgroup per block counts each segment's planes that reach the block.
@compute @workgroup_size(256, 1, 1)
fn block_count(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
               @builtin(local_invocation_index) li: u32) {
    let block = wid.y * nwg.x + wid.x;
    if (block >= block_count_all()) {
        return;
    }
    for (var s = 0u; s < params.segments; s++) {
        var c = 0u;
        let end = seg_end(s);
        for (var i = seg_first(s) + li; i < end; i += THREADS) {
            c += select(0u, 1u, reaches_block(params.first + i, block));
        }
        let total = sum_to_first(li, c);
        if (li == 0u) {
            blocks[block * params.segments + s] = total;
        }
        workgroupBarrier();
    }
}

// One workgroup turns the blocks' counts (block by block, segment by segment) into their first
// entries, in place, and writes the batch's end after them.
@compute @workgroup_size(256, 1, 1)
fn block_scan(@builtin(local_invocation_index) li: u32) {
    let n = block_count_all() * params.segments;
    let per = (n + THREADS - 1u) / THREADS;
    let lo = min(li * per, n);
    let hi = min(lo + per, n);
    var c = 0u;
    for (var k = lo; k < hi; k++) {
        c += blocks[k];
    }
    scratch[li] = c;
    scan_scratch(li);
    var run = scratch[li] - c;
    for (var k = lo; k < hi; k++) {
        let v = blocks[k];
        blocks[k] = run;
        run += v;
    }
    if (li == 0u) {
        blocks[n] = scratch[THREADS - 1u];
    }
}

// A workgroup per block writes its list: the batch's planes that reach it, in plane order (so
// segment by segment), by a prefix sum of the hits of 1,024 planes at a time.
@compute @workgroup_size(256, 1, 1)
fn block_scatter(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                 @builtin(local_invocation_index) li: u32) {
    let block = wid.y * nwg.x + wid.x;
    if (block >= block_count_all()) {
        return;
    }
    let base = block_lists() + blocks[block * params.segments];
    var written = 0u;
    for (var b = 0u; b < params.count; b += STEP) {
        let i0 = b + li * PER_THREAD;
        var hits = 0u;
        for (var k = 0u; k < PER_THREAD; k++) {
            let i = i0 + k;
            if (i < params.count && reaches_block(params.first + i, block)) {
                hits |= 1u << k;
            }
        }
        let placed = place_hits(li, hits);
        var at = base + written + placed.x;
        for (var k = 0u; k < PER_THREAD; k++) {
            if ((hits & (1u << k)) != 0u) {
                blocks[at] = params.first + i0 + k;
                at++;
            }
        }
        written += placed.y;
    }
}
