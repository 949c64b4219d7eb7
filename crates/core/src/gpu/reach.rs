//! The tiles a plane reaches on the GPU: the specification ([`tile_reach`], in f64 on the CPU)
//! and what crosses for the GPU to find it there ([`ScreenReach`]: the plane's screen polygon in
//! f32, the rows of tiles to fill), which `reach.wgsl` does in f32 with [`SLACK`] more margin,
//! so that its reach holds this one (tests/gpu.rs, `gpu_reach_holds_the_cpus`).

use super::TILE;
use crate::photon_plane::Polygon;
use glam::{DVec2, Vec2};

/// Pixel rows of a group: a row of tiles' test region is an x-range per group of 4 pixel rows
/// (4 groups a tile, whose ranges within a tile, 4 bits a bound, fill the u32 that `bin.wgsl`
/// writes per list entry). Counted on the benchmark's planes: groups of 4 rows are tested at
/// 1.19 pixels per hit, of 8 at 1.28, of 1 at 1.13, and a box of pixels per row of tiles at 1.39.
pub const GROUP_ROWS: u32 = 4;

/// Groups of pixel rows in a row of tiles.
pub const GROUPS: usize = (TILE / GROUP_ROWS) as usize;

/// The tiles a plane's screen polygon ([`crate::raster::screen_polygon`]) can touch, row of
/// tiles by row: from row `first_row`, for each row the first and last column of tiles
/// (inclusive; `[1, 0]` where none) whose pixels' squares come within a pixel of the polygon
/// (far above its rounding). What `bin.wgsl`'s `covers` tests: binning to these spans, not to
/// the polygon's box, keeps a thin diagonal plane out of the tiles its box crosses but it does
/// not (the benchmark's tests per hit: 4.2 with boxes). Per row of tiles, too, per group of
/// [`GROUP_ROWS`] pixel rows within it, the pixel columns whose squares come within a pixel of
/// the polygon (`groups`): the gather tests only a tile's pixels in them, so a thin diagonal
/// plane is tested near its diagonal only (a tile's 256 pixels tested per plane were 1.79
/// tests per hit on the benchmark, a box of pixels per row of tiles 1.39, these ranges 1.19).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TileReach {
    pub first_row: u32,
    pub spans: Vec<[u32; 2]>,
    /// Per row of tiles, per group of pixel rows in it (top down): its first and last pixel
    /// column, packed `first | last << 16` (`1`, first 1 and last 0, where none), within the
    /// row's span of tiles.
    pub groups: Vec<[u32; GROUPS]>,
}

/// A group's columns, `first | last << 16`, as a first and last (first > last where none).
fn unpack(packed: u32) -> (u32, u32) {
    (packed & 0xffff, packed >> 16)
}

impl TileReach {
    /// The (tile, plane) pairs: how many tiles the plane is binned to.
    pub fn tiles(&self) -> u64 {
        self.spans.iter().map(|&[a, b]| (b + 1).saturating_sub(a) as u64).sum()
    }

    /// The pixels the gather tests the plane at in an image of `height` rows: each group's
    /// columns at its rows within the image.
    pub fn tests(&self, height: u32) -> u64 {
        let mut tests = 0;
        for (j, groups) in self.groups.iter().enumerate() {
            for (k, &packed) in groups.iter().enumerate() {
                let (first, last) = unpack(packed);
                let top = (self.first_row + j as u32) * TILE + k as u32 * GROUP_ROWS;
                let rows = height.saturating_sub(top).min(GROUP_ROWS);
                tests += (last + 1).saturating_sub(first) as u64 * rows as u64;
            }
        }
        tests
    }

    /// The warps of 32 lanes that test the plane in an image of `width` x `height` pixels: a
    /// warp takes a plane's test, and its hit's arithmetic, if any of its pixels is in the
    /// plane's columns, and its other lanes wait (`gather.wgsl`'s `pixel_of`). By rows a warp is
    /// two pixel rows of a tile's 16 columns, by `blocks` 8 columns of a group of 4 rows. The
    /// share of their lanes that the plane's columns fill is [`TileReach::tests`] over 32 times
    /// this (`cargo run --release -p fogplanes-bench --example screen_reach`).
    pub fn warps(&self, width: u32, height: u32, blocks: bool) -> u64 {
        let mut warps = 0;
        for (j, (&[a, b], groups)) in self.spans.iter().zip(&self.groups).enumerate() {
            for (k, &packed) in groups.iter().enumerate() {
                let (first, last) = unpack(packed);
                let top = (self.first_row + j as u32) * TILE + k as u32 * GROUP_ROWS;
                let rows = height.saturating_sub(top).min(GROUP_ROWS);
                if rows == 0 || first > last {
                    continue;
                }
                for tile in a..=b {
                    let (x0, x1) =
                        (first.max(tile * TILE), last.min(tile * TILE + TILE - 1).min(width.saturating_sub(1)));
                    if x0 > x1 {
                        continue;
                    }
                    warps += if blocks {
                        let half = tile * TILE + TILE / 2;
                        (x0 < half) as u64 + (x1 >= half) as u64
                    } else {
                        rows.div_ceil(2) as u64
                    };
                }
            }
        }
        warps
    }
}

/// Per strip `first + k` of `lo.len()`, strips of `rows` pixel rows (a row of tiles, or a group
/// of pixel rows), the x-range of the polygon of `points` within the strip grown by a pixel,
/// `[rows (first + k) - 1, rows (first + k + 1) + 1]` (infinite, lo > hi, where it has none):
/// the x-ranges of its edges' parts inside the strip (a convex polygon's part in a strip is
/// bounded by its edges' parts there). An edge's x at a height from its slope, one division an
/// edge (the rounding is far below the pixel of margin); minima and maxima by comparisons (no
/// NaN arises from finite points).
fn strip_ranges(points: &[DVec2], rows: u32, first: u32, lo: &mut [f64], hi: &mut [f64]) {
    const M: f64 = 1.0;
    let (s, n) = (rows as f64, lo.len());
    for (&p, &q) in points.iter().zip(points.iter().cycle().skip(1)) {
        let (ymin, ymax) = (p.y.min(q.y), p.y.max(q.y));
        let (xlo, xhi) = (p.x.min(q.x), p.x.max(q.x));
        // The strips the edge can meet (each checked below).
        let j0 = (((ymin - s - M) / s).ceil() - first as f64).clamp(0.0, n as f64) as usize;
        let j1 = (((ymax + M) / s).floor() - first as f64 + 1.0).clamp(0.0, n as f64) as usize;
        let slope = (q.x - p.x) / (q.y - p.y);
        // Kept on the edge; not called for a horizontal edge (whose slope is not finite).
        let at = |y: f64| {
            let x = p.x + (y - p.y) * slope;
            if x < xlo {
                xlo
            } else if x > xhi {
                xhi
            } else {
                x
            }
        };
        let mut top = (first as usize + j0) as f64 * s - M;
        for (lo, hi) in lo[j0..j1].iter_mut().zip(&mut hi[j0..j1]) {
            let bottom = top + s + 2.0 * M;
            if !(ymax < top || ymin > bottom) {
                // The edge's x at the ends of its part inside the strip; a horizontal edge's
                // two ends.
                let (xa, xb) = if q.y == p.y { (xlo, xhi) } else { (at(ymin.max(top)), at(ymax.min(bottom))) };
                let (xa, xb) = if xa < xb { (xa, xb) } else { (xb, xa) };
                if xa < *lo {
                    *lo = xa;
                }
                if xb > *hi {
                    *hi = xb;
                }
            }
            top += s;
        }
    }
}

/// The pixel columns whose squares `[px, px + 1]` come within a pixel of the x-range
/// `[lo, hi]` (`lo - 2 <= px <= hi + 1`), kept in `[0, width)`: `None` where there are none.
fn columns(lo: f64, hi: f64, width: u32) -> Option<(u32, u32)> {
    let a = (lo - 2.0).ceil().max(0.0);
    let b = (hi + 1.0).floor().min(width as f64 - 1.0);
    (a <= b).then_some((a as u32, b as u32))
}

/// The plane's [`TileReach`] in a `width x height` image; no rows for a polygon that shows
/// nothing. A row of tiles `r` holds pixel rows `16 r .. 16 r + 15`, whose squares span
/// `y in [16 r, 16 r + 16]`: its span is the polygon's x-range within the strip
/// `[16 r - 1, 16 r + 17]`, grown by a pixel, kept in the image, in tiles. A group of pixel
/// rows `4 g .. 4 g + 3` likewise takes the x-range within `[4 g - 1, 4 g + 5]`, kept within
/// its row's span (which holds it but for rounding), and none where its rows are all more
/// than a pixel above or below the polygon.
pub fn tile_reach(poly: &Polygon<DVec2>, width: u32, height: u32) -> TileReach {
    const M: f64 = 1.0;
    let t = TILE as f64;
    let none = TileReach::default();
    if poly.len < 3 || poly.points().iter().any(|v| !(v.x.is_finite() && v.y.is_finite())) {
        return none;
    }
    let (mut ylo, mut yhi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in poly.points() {
        (ylo, yhi) = (ylo.min(v.y), yhi.max(v.y));
    }
    // Pixel row py's square [py, py + 1] comes within a pixel of [ylo, yhi] where
    // ylo - 2 <= py <= yhi + 1; its row of tiles is py / 16.
    let (row_lo, row_hi) = ((ylo - 2.0 * M).ceil().max(0.0), (yhi + M).floor().min(height as f64 - 1.0));
    let (first, last) = ((row_lo / t).floor(), (row_hi / t).floor());
    if !(first <= last) {
        return none;
    }
    let (first, last, row_lo, row_hi) = (first as u32, last as u32, row_lo as u32, row_hi as u32);
    let n = (last - first + 1) as usize;
    // The strips of the rows of tiles, then of their groups.
    let mut lo = vec![f64::INFINITY; n * (1 + GROUPS)];
    let mut hi = vec![f64::NEG_INFINITY; n * (1 + GROUPS)];
    let (tile_lo, group_lo) = lo.split_at_mut(n);
    let (tile_hi, group_hi) = hi.split_at_mut(n);
    strip_ranges(poly.points(), TILE, first, tile_lo, tile_hi);
    // Only the groups with a row within [row_lo, row_hi]: the others' rows are all too far.
    // (A polygon just below the image can have a row of tiles and no row: then no groups.)
    if row_lo <= row_hi {
        let at = |row: u32| (row / GROUP_ROWS - first * GROUPS as u32) as usize;
        let groups = at(row_lo)..at(row_hi) + 1;
        let (lo, hi) = (&mut group_lo[groups.clone()], &mut group_hi[groups]);
        strip_ranges(poly.points(), GROUP_ROWS, row_lo / GROUP_ROWS, lo, hi);
    }
    let (mut spans, mut packed) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for j in 0..n {
        let Some((a, b)) = columns(tile_lo[j], tile_hi[j], width) else {
            spans.push([1, 0]);
            packed.push([1; GROUPS]);
            continue;
        };
        spans.push([a / TILE, b / TILE]);
        // Each group's columns ([`columns`]) kept in the row's: the bounds in [a, b] first, so
        // that `as` truncates a non-negative value (ceil and floor are library calls here).
        let (fa, fb) = (a as f64, b as f64);
        packed.push(std::array::from_fn(|k| {
            let g = j * GROUPS + k;
            let (x, y) = ((group_lo[g] - 2.0).max(fa), (group_hi[g] + 1.0).min(fb));
            if !(x <= y) {
                return 1;
            }
            let (left, right) = (x as u32 + ((x as u32 as f64) < x) as u32, y as u32);
            if left <= right { left | right << 16 } else { 1 }
        }));
    }
    TileReach { first_row: first, spans, groups: packed }
}

/// The GPU's margin beyond the specification's pixel, in pixels (`reach.wgsl`'s `SLACK`): far
/// above its f32 rounding (below 0.01 of a pixel in an image of 2^15 pixels a side), so that the
/// reach it finds holds [`tile_reach`]'s. The rows and the bound of [`ScreenReach`] take twice
/// it, and so hold the GPU's.
pub const SLACK: f64 = 1.0 / 32.0;

/// `n` convex polygons for testing a reach in a `width x height` image (from `seed`, the same
/// ones every time): points on ellipses, up to three quarters of the width long, a third of
/// them thin (up to 2 pixels across), tilted every way, 3 to 10 vertices, some past the image's
/// edges or outside it.
#[doc(hidden)]
pub fn test_polygons(seed: u64, n: usize, width: f64, height: f64) -> Vec<Polygon<DVec2>> {
    let mut state = seed;
    let mut next = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|case| {
            let (cx, cy) = (next() * width * 1.3 - 0.15 * width, next() * height * 1.5 - 0.25 * height);
            let a = next() * 0.75 * width + 0.5;
            let b = if case % 3 == 0 { next() * 2.0 + 0.01 } else { next() * 0.5 * height + 0.5 };
            let (tilt, k) = (next() * std::f64::consts::PI, 3 + case % 8);
            let points: Vec<DVec2> = (0..k)
                .map(|i| {
                    let u = i as f64 / k as f64 * std::f64::consts::TAU;
                    let (x, y) = (a * u.cos(), b * u.sin());
                    DVec2::new(cx + x * tilt.cos() - y * tilt.sin(), cy + x * tilt.sin() + y * tilt.cos())
                })
                .collect();
            Polygon::from_slice(&points)
        })
        .collect()
}

/// A plane's screen polygon as it crosses for the GPU to find its reach (`reach.wgsl`): the
/// polygon in f32, the rows of tiles the GPU fills for it (those [`tile_reach`] finds, grown by
/// twice [`SLACK`], and none where no pixel row comes near), and a bound on its (tile, plane)
/// pairs, which size the binning's buffers: its rows times the tiles of its x-range (grown
/// likewise). On the benchmark the bound is 2.4 times the pairs; 4.2 vertices a plane cross
/// instead of 11.5 rows of tiles (20 bytes each).
#[derive(Clone, Copy, Debug)]
pub struct ScreenReach {
    pub polygon: Polygon<Vec2>,
    pub first_row: u32,
    pub rows: u32,
    pub pairs: u64,
}

impl Default for ScreenReach {
    /// No rows, no polygon.
    fn default() -> Self {
        ScreenReach { polygon: Polygon::empty(), first_row: 0, rows: 0, pairs: 0 }
    }
}

/// The [`ScreenReach`] of screen polygon `poly` in a `width x height` image; none for a
/// polygon that shows nothing.
pub fn screen_reach(poly: &Polygon<DVec2>, width: u32, height: u32) -> ScreenReach {
    let none = ScreenReach::default();
    if poly.len < 3 || poly.points().iter().any(|v| !(v.x.is_finite() && v.y.is_finite())) {
        return none;
    }
    let (mut lo, mut hi) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
    for &v in poly.points() {
        (lo, hi) = (lo.min(v), hi.max(v));
    }
    // Pixel (px, py)'s square comes within m of [lo, hi] where lo - 1 - m <= (px, py) <= hi + m.
    let m = 1.0 + 2.0 * SLACK;
    let first = (lo - 1.0 - m).ceil().max(DVec2::ZERO);
    let last = (hi + m).floor().min(DVec2::new(width as f64 - 1.0, height as f64 - 1.0));
    if !(first.x <= last.x && first.y <= last.y) {
        return none;
    }
    let (first, last) = (first.as_uvec2() / TILE, last.as_uvec2() / TILE);
    let rows = last.y - first.y + 1;
    let mut polygon = Polygon::<Vec2>::empty();
    for &v in poly.points() {
        polygon.vertices[polygon.len] = v.as_vec2();
        polygon.len += 1;
    }
    ScreenReach { polygon, first_row: first.y, rows, pairs: rows as u64 * (last.x - first.x + 1) as u64 }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pixel whose square comes within a pixel of a polygon is in a tile of its reach and
    /// in its group's columns (the pixels near points of the polygon: its vertices, points of
    /// its edges, among them where they cross each line between pixel rows, which bound the
    /// groups' ranges, and inside it); `tests` counts the pixels of the ranges in the image; a
    /// thin diagonal polygon reaches far fewer tiles than its box, and is tested at far fewer
    /// pixels than its rows of tiles' boxes; one outside the image or degenerate reaches none.
    #[test]
    fn a_reach_holds_every_tile_the_polygon_comes_near() {
        let (w, h) = (200u32, 120u32);
        for (case, poly) in test_polygons(7, 300, w as f64, h as f64).into_iter().enumerate() {
            let (points, k) = (poly.points().to_vec(), poly.len);
            let reach = tile_reach(&poly, w, h);
            assert_eq!(reach.spans.len(), reach.groups.len(), "case {case}: a group's ranges per row of tiles");
            // Whether the gather tests pixel (px, py): its tile binned (`covers`) and its
            // column in its group's range (`gather.wgsl`).
            let covered = |px: u32, py: u32| {
                let (tx, ty) = (px / TILE, py / TILE);
                let row = (ty >= reach.first_row).then(|| (ty - reach.first_row) as usize);
                let (Some(&[f, l]), Some(groups)) =
                    (row.and_then(|r| reach.spans.get(r)), row.and_then(|r| reach.groups.get(r)))
                else {
                    return false;
                };
                let (first, last) = unpack(groups[(py % TILE / GROUP_ROWS) as usize]);
                f <= tx && tx <= l && first <= px && px <= last
            };
            let tested = (0..h).flat_map(|py| (0..w).map(move |px| (px, py))).filter(|&(x, y)| covered(x, y));
            assert_eq!(reach.tests(h), tested.count() as u64, "case {case}: the pixels tested");
            // The warps that test it, by rows (two rows of a tile) and by blocks (8 x 4), each
            // counted once if any of its pixels is tested.
            for blocks in [false, true] {
                let warp = |px: u32, py: u32| {
                    let (tx, ty) = (px / TILE, py / TILE);
                    let (lx, ly) = (px % TILE, py % TILE);
                    let within = if blocks { (ly / 4) * 2 + lx / 8 } else { ly / 2 };
                    (tx, ty, within)
                };
                let mut seen: Vec<_> = (0..h)
                    .flat_map(|py| (0..w).map(move |px| (px, py)))
                    .filter(|&(x, y)| covered(x, y))
                    .map(|(x, y)| warp(x, y))
                    .collect();
                seen.sort_unstable();
                seen.dedup();
                assert_eq!(reach.warps(w, h, blocks), seen.len() as u64, "case {case}: the warps, blocks {blocks}");
            }
            // Points of the polygon: along each edge, and where it crosses y = integer.
            let mut near = Vec::new();
            for i in 0..k {
                let (p, q) = (points[i], points[(i + 1) % k]);
                for s in 0..=40 {
                    let on = p + (q - p) * (s as f64 / 40.0);
                    // And a point inside, between it and another vertex.
                    near.extend([on, on + (points[(i + 2) % k] - on) * ((s * 7 % 40) as f64 / 40.0)]);
                }
                let (ya, yb) = (p.y.min(q.y), p.y.max(q.y));
                if ya == yb {
                    continue;
                }
                let lines = (ya.ceil().max(-3.0) as i64..=yb.floor().min(h as f64 + 3.0) as i64).map(|y| y as f64);
                near.extend(lines.map(|y| p + (q - p) * ((y - p.y) / (q.y - p.y)).clamp(0.0, 1.0)));
            }
            // Pixel (px, py)'s square comes within a pixel of v where v - 2 <= (px, py) <= v + 1.
            for v in near {
                let (x0, x1) = ((v.x - 2.0).ceil().max(0.0), (v.x + 1.0).floor().min(w as f64 - 1.0));
                let (y0, y1) = ((v.y - 2.0).ceil().max(0.0), (v.y + 1.0).floor().min(h as f64 - 1.0));
                for py in (y0 as i64..=y1 as i64).map(|y| y as u32) {
                    for px in (x0 as i64..=x1 as i64).map(|x| x as u32) {
                        assert!(covered(px, py), "case {case}: pixel ({px}, {py}) near {v} not reached");
                    }
                }
            }
        }
        // Thin and diagonal: from corner to corner of a 200 x 120 image.
        let thin = Polygon::from_slice(&[DVec2::new(0.0, 0.0), DVec2::new(200.0, 119.0), DVec2::new(200.0, 120.0)]);
        let reach = tile_reach(&thin, w, h);
        assert!(reach.tiles() * 3 <= 13 * 8, "{} of the box's 104 tiles", reach.tiles());
        // A box of pixels per row of tiles would hold about 33 columns a pixel row (its x-range
        // in a strip of 18 rows, 1.67 columns a row, and 3 of margin: 4,000 pixels); its
        // groups' ranges, in strips of 6 rows, hold 1,656.
        assert!(reach.tests(h) <= 15 * 120, "{} pixels tested", reach.tests(h));
        let outside = Polygon::from_slice(&[DVec2::new(-9.0, -9.0), DVec2::new(-3.0, -9.0), DVec2::new(-9.0, -3.0)]);
        assert_eq!(tile_reach(&outside, w, h).tiles(), 0);
        let right = Polygon::from_slice(&[DVec2::new(202.0, 5.0), DVec2::new(209.0, 5.0), DVec2::new(202.0, 9.0)]);
        assert_eq!(tile_reach(&right, w, h).tiles(), 0);
        assert_eq!(tile_reach(&Polygon::from_slice(&[DVec2::ZERO, DVec2::ONE]), w, h).tiles(), 0);
        let nan = Polygon::from_slice(&[DVec2::ZERO, DVec2::new(f64::NAN, 1.0), DVec2::ONE]);
        assert_eq!(tile_reach(&nan, w, h), TileReach::default());
    }

    /// A screen reach's rows hold the specification's rows with pixels in them, and its bound
    /// its pairs; none for a polygon outside the image or degenerate.
    #[test]
    fn a_screen_reach_holds_the_rows_and_bounds_the_pairs() {
        let (w, h) = (200u32, 120u32);
        let shapes = [
            vec![DVec2::new(0.0, 0.0), DVec2::new(200.0, 119.0), DVec2::new(200.0, 120.0)],
            vec![DVec2::new(-1.0, 50.0), DVec2::new(30.0, 17.5), DVec2::new(47.9, 63.2), DVec2::new(5.0, 121.0)],
            vec![DVec2::new(100.0, 100.0), DVec2::new(100.5, 100.0), DVec2::new(100.0, 100.5)],
        ];
        for points in shapes {
            let poly = Polygon::from_slice(&points);
            let (spec, screen) = (tile_reach(&poly, w, h), screen_reach(&poly, w, h));
            assert_eq!(screen.polygon.len, points.len());
            let rows = screen.first_row..screen.first_row + screen.rows;
            for (j, groups) in spec.groups.iter().enumerate() {
                if groups.iter().any(|&g| unpack(g).0 <= unpack(g).1) {
                    assert!(rows.contains(&(spec.first_row + j as u32)), "{points:?}: row {j} of {spec:?}");
                }
            }
            assert!(spec.tiles() <= screen.pairs, "{points:?}: {} pairs, bound {}", spec.tiles(), screen.pairs);
        }
        let outside = Polygon::from_slice(&[DVec2::new(-9.0, -9.0), DVec2::new(-3.0, -9.0), DVec2::new(-9.0, -3.0)]);
        assert_eq!(screen_reach(&outside, w, h).rows, 0);
        let nan = Polygon::from_slice(&[DVec2::ZERO, DVec2::new(f64::NAN, 1.0), DVec2::ONE]);
        assert_eq!((screen_reach(&nan, w, h).rows, screen_reach(&nan, w, h).polygon.len), (0, 0));
    }
}
