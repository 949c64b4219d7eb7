//! The intersection structure for the pinhole camera: planes rasterised in screen space.
//!
//! Every camera ray starts at the camera, so the rays that can hit a plane are exactly those
//! whose image point lies in the projection of the plane's polygon (clipped to the box). Each
//! polygon is projected once, clipped to the image, and binned into tiles of rows and columns
//! ([`Tiling`]). A tile walks its planes light by light, each light's in index order; for every
//! row it covers, the conservative span of pixels whose squares meet the polygon, cut to the
//! tile's columns, is tested exactly with [`crate::gather::PlaneJob::gather_block`]. The exact
//! test decides; the span only has to contain every pixel that can hit, whatever the jitter.
//!
//! Each pixel's sum runs over planes in that order whatever the thread count and the tiles
//! ([the sums light by light](crate::gather#sums-light-by-light)), so images are bit-identical
//! for a seed. Several pieces of planes (a chunk's, each along its own ray set) are gathered in
//! one parallel loop over the tiles, each tile taking the pieces in order ([`gather_pieces`]).

use crate::camera::Camera;
use crate::camera::CameraRay;
use crate::control::Control;
use crate::gather::{GatherContext, GatherStats, RayBlock};
use crate::kernel::{self, Aggregate, Band, Gathering, HALF_LANES, Kernel, LANES, Span};
use crate::limits::{MAX_CHUNKS_AT_ONCE, MAX_WINDOW_PIXELS, PLANE_UNIT};
use crate::medium::Medium;
use crate::photon_plane::{PhotonPlane, Polygon};
use crate::weights::{Denominator, Unweighted};
use glam::{DVec2, DVec3, Vec2, Vec3};
use rayon::prelude::*;
use std::ops::Range;

/// Rows per tile: a tile's rays and sums stay in cache while its planes stream by, its spans
/// computed with its rows as lanes. At most this many: see [`Tiling`].
pub const BAND_ROWS: u32 = 16;

/// Tiles a gathering aims at per worker: enough that the tiles' unequal work evens out (a
/// worker's last tile is a small part of its share), few enough that a plane's set-up and span
/// walk, made once per tile it crosses, stay a small part of its work.
pub const TILES_PER_WORKER: usize = 4;

/// Parts of tiles a gathering aims at per worker, the heavy tiles cut into parts of rows
/// ([`gather_pieces`]).
const SPLIT_PER_WORKER: usize = 8;

/// Chunks of planes a render gathers at once on `workers` workers at `width x height`, each
/// into its own sums ([`gather_pieces`]'s targets): as many as give the workers
/// [`TILES_PER_WORKER`] tiles each with the image's bands of [`BAND_ROWS`] rows whole, at most
/// [`MAX_CHUNKS_AT_ONCE`] and [`MAX_WINDOW_PIXELS`]. A plane's set-up and span walk are made
/// once per tile it crosses: one chunk of the benchmark (640x360) cut into tiles for 64 workers
/// took 47% more CPU than in bands, eight at once in tiles for eight workers 19% (the schedule
/// model's records); a small image on many cores gathers several chunks, a large one one.
pub fn chunks_at_once(workers: usize, width: u32, height: u32) -> usize {
    let bands = height.div_ceil(BAND_ROWS).max(1) as usize;
    let pixels = (width as usize * height as usize).max(1);
    let most = (MAX_WINDOW_PIXELS / pixels).clamp(1, MAX_CHUNKS_AT_ONCE);
    (TILES_PER_WORKER * workers.max(1)).div_ceil(bands).clamp(1, most)
}

/// The narrowest tile, in pixels.
const MIN_TILE_COLS: u32 = 32;

/// The fewest rows of a tile.
const MIN_TILE_ROWS: u32 = 4;

/// How an image is cut into tiles, the raster's units of work: `rows` x `cols` pixels each (the
/// last row and column of tiles smaller), row-major. The image is the same bits whatever the
/// tiles: a pixel adds its planes light by light, each light's in index order, within its tile
/// either way (and the lights' sums in light order, the pieces' in piece order).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tiling {
    pub rows: u32,
    pub cols: u32,
    pub width: u32,
    pub height: u32,
}

impl Tiling {
    /// The tiles of an image for `threads` workers gathering one chunk at a time: bands of 16
    /// rows across the whole image while they are [`TILES_PER_WORKER`] per worker (23 bands make
    /// a 640x360 image: up to 5 workers), else each band cut into as few runs of columns as make
    /// that many (at least 32 wide, a multiple of 8), and then bands of 8 or 4 rows (640x360 for
    /// 16 workers: 23 x 3 tiles of 16 x 216). The heavy tiles are cut further into parts of
    /// rows when gathered ([`gather_pieces`]).
    pub fn new(width: u32, height: u32, threads: usize) -> Self {
        Self::with_tiles(width, height, TILES_PER_WORKER * threads.max(1))
    }

    /// The tiles of an image for `threads` workers gathering a window of [`chunks_at_once`]
    /// chunks: as [`Tiling::new`], the [`TILES_PER_WORKER`] tiles a worker wants shared by the
    /// window's chunks (640x360: whole bands up to 32 workers; for 64, eight chunks at once,
    /// 23 x 2 tiles of 16 x 320).
    pub fn for_window(width: u32, height: u32, threads: usize) -> Self {
        let want = (TILES_PER_WORKER * threads.max(1)).div_ceil(chunks_at_once(threads, width, height));
        Self::with_tiles(width, height, want)
    }

    /// At least `want` tiles (or bands of [`MIN_TILE_ROWS`] cut into columns of
    /// [`MIN_TILE_COLS`]): bands of 16 rows, cut into runs of columns, then bands of 8 or 4.
    fn with_tiles(width: u32, height: u32, want: usize) -> Self {
        let widest = width.max(1);
        let mut rows = BAND_ROWS;
        loop {
            let down = height.div_ceil(rows).max(1) as usize;
            let most = width.div_ceil(MIN_TILE_COLS).max(1) as usize;
            let across = want.div_ceil(down).clamp(1, most) as u32;
            let cols = if across == 1 { widest } else { width.div_ceil(across).next_multiple_of(HALF_LANES as u32) };
            let tiling = Tiling { rows, cols: cols.min(widest), width, height };
            if tiling.count() >= want || rows <= MIN_TILE_ROWS {
                return tiling;
            }
            rows /= 2;
        }
    }

    /// Tiles across the image.
    pub fn across(&self) -> u32 {
        self.width.div_ceil(self.cols.max(1)).max(1)
    }

    /// Tiles down the image.
    pub fn down(&self) -> u32 {
        self.height.div_ceil(self.rows.max(1)).max(1)
    }

    pub fn count(&self) -> usize {
        self.across() as usize * self.down() as usize
    }

    /// The rows and columns of tile `t`.
    pub fn tile(&self, t: usize) -> (Range<u32>, Range<u32>) {
        let (down, across) = ((t / self.across() as usize) as u32, (t % self.across() as usize) as u32);
        let rows = down * self.rows..((down + 1) * self.rows).min(self.height);
        let cols = across * self.cols..((across + 1) * self.cols).min(self.width);
        (rows, cols)
    }
}

/// Slack in pixels around a projected polygon, far above the rounding of the projection.
const SPAN_MARGIN: f32 = 1e-2;

/// The raster's unit of work is a tile: one progress report each ([`gather_pieces`] with one
/// piece).
impl Aggregate for ScreenRaster {
    fn gather<D: Denominator>(
        &self,
        with: Gathering<D>,
        rays: &[CameraRay],
        sums: &mut [Vec3],
        control: Control,
    ) -> GatherStats {
        let piece = RasterPiece { raster: self, ctx: with.ctx, rays, target: 0, tap: None };
        gather_pieces::<D, true>(&[piece], with.weights, with.kernel, &mut [sums], &mut [], control)[0]
    }
}

/// Projected, image-clipped polygons of all planes, binned into tiles.
pub struct ScreenRaster {
    /// The tiles its planes are binned into.
    tiling: Tiling,
    pub width: u32,
    pub height: u32,
    /// Vertices of polygon `i` are `vertices[offsets[i]..offsets[i + 1]]`, in pixel units.
    vertices: Vec<Vec2>,
    offsets: Vec<u32>,
    /// Per band of rows, the planes that may cover it with their spans there.
    bands: Vec<BandBins>,
    /// Per tile, the indices of its band's records whose spans reach its columns, by light,
    /// each light's planes ascending.
    tiles: Vec<Vec<u32>>,
    /// The light of each plane.
    lights: Vec<u32>,
    /// Each plane's bounding box on the screen, `[x0, x1, y0, y1]` in pixels.
    bounds: Vec<[f32; 4]>,
    /// Per tile, an estimate of its work: pixels tested (its planes' boxes or spans in it) plus
    /// [`PLANE_WORK`] per plane, for cutting the heavy tiles ([`gather_pieces`]).
    work: Vec<u64>,
}

/// A plane's set-up in a tile, in pixels tested (its job, its spans), for estimating the tiles'
/// work.
const PLANE_WORK: u64 = 32;

/// The plane's polygon as seen from the camera, clipped to the image grown by one pixel, in
/// pixel coordinates; empty if the camera cannot see it.
pub fn screen_polygon(camera: &Camera, plane: &PhotonPlane, medium: &Medium) -> Polygon<DVec2> {
    screen_polygon_of(camera, &box_polygon(plane, medium), medium)
}

/// The plane's polygon in the medium box grown by a millionth of its diagonal, which
/// [`screen_polygon`] projects (so that a ray along the box's faces still finds the planes it
/// hits) and the plane's possible occluders are found from
/// ([`crate::occlusion::occluders_of_polygon`]).
pub fn box_polygon(plane: &PhotonPlane, medium: &Medium) -> Polygon<DVec3> {
    plane.polygon_in_box(medium, 1e-6 * medium.diagonal())
}

/// [`screen_polygon`] of the plane's box polygon `world` ([`box_polygon`]).
pub fn screen_polygon_of(camera: &Camera, world: &Polygon<DVec3>, medium: &Medium) -> Polygon<DVec2> {
    let mut cam = Polygon::<DVec3>::empty();
    for &v in world.points() {
        cam.vertices[cam.len] = camera.to_camera(v);
        cam.len += 1;
    }
    // Only points in front of the camera can be hit; a tiny positive depth keeps the
    // projection finite (points closer than this lie within it of the camera).
    let near = 1e-9 * medium.diagonal().max(1e-30);
    let mut scratch = Polygon::<DVec3>::empty();
    cam.clip_in_place(&mut scratch, |v| v.z - near, |p, q, s| p + (q - p) * s);
    let (mut screen, mut other) = (Polygon::<DVec2>::empty(), Polygon::<DVec2>::empty());
    for &v in cam.points() {
        let (x, y) = camera.project(v);
        screen.vertices[screen.len] = DVec2::new(x, y);
        screen.len += 1;
    }
    let (w, h) = (camera.width as f64, camera.height as f64);
    let lerp = |p: DVec2, q: DVec2, s: f64| p + (q - p) * s;
    screen.clip_in_place(&mut other, |v| v.x + 1.0, lerp);
    screen.clip_in_place(&mut other, |v| w + 1.0 - v.x, lerp);
    screen.clip_in_place(&mut other, |v| v.y + 1.0, lerp);
    screen.clip_in_place(&mut other, |v| h + 1.0 - v.y, lerp);
    screen
}

impl ScreenRaster {
    pub fn build(camera: &Camera, planes: &[PhotonPlane], medium: &Medium) -> Self {
        let mut raster = ScreenRaster::empty(camera);
        raster.push_planes(camera, planes, medium);
        raster
    }

    /// A raster with no planes yet, for [`ScreenRaster::push_planes`], in tiles sized for the
    /// workers of the current thread pool gathering one chunk at a time ([`Tiling::new`],
    /// [`crate::schedule::workers`]).
    pub fn empty(camera: &Camera) -> Self {
        Self::empty_in(camera, Tiling::new(camera.width, camera.height, crate::schedule::workers()))
    }

    /// A raster with no planes yet, in `tiling` (its image the camera's).
    pub fn empty_in(camera: &Camera, tiling: Tiling) -> Self {
        assert_eq!((tiling.width, tiling.height), (camera.width, camera.height), "the camera's tiles");
        ScreenRaster {
            tiling,
            width: camera.width,
            height: camera.height,
            vertices: Vec::new(),
            offsets: vec![0],
            bands: (0..tiling.down()).map(|_| BandBins::default()).collect(),
            tiles: vec![Vec::new(); tiling.count()],
            lights: Vec::new(),
            bounds: Vec::new(),
            work: vec![0; tiling.count()],
        }
    }

    /// The tiles of its planes.
    pub fn tiling(&self) -> Tiling {
        self.tiling
    }

    /// Projects, clips and bins the next planes of the set (their indices continue the count).
    pub fn push_planes(&mut self, camera: &Camera, planes: &[PhotonPlane], medium: &Medium) {
        self.push_planes_in(camera, planes, medium, Control::none())
    }

    /// [`ScreenRaster::push_planes`] with its parallel loops recorded on `control`'s strand
    /// ([`crate::schedule`]).
    pub fn push_planes_in(&mut self, camera: &Camera, planes: &[PhotonPlane], medium: &Medium, control: Control) {
        let polygons =
            control.map_units("polygons", planes.len(), PLANE_UNIT, |i| screen_polygon(camera, &planes[i], medium));
        self.push_projected_in(planes, |i| &polygons[i], control);
    }

    /// [`ScreenRaster::push_planes_in`] with plane `i`'s screen polygon `polygon(i)`
    /// ([`screen_polygon`], made where the plane's box polygon serves its occluders too), read
    /// twice.
    pub fn push_projected_in<'p>(
        &mut self,
        planes: &[PhotonPlane],
        polygon: impl Fn(usize) -> &'p Polygon<DVec2> + Sync + Send,
        control: Control,
    ) {
        let tiling = self.tiling;
        let (down, across) = (tiling.down(), tiling.across());
        // Each new plane's bands of rows it may cover (none: invisible) and its bounding box
        // (for estimating the tiles' work); not its polygon, which the caller keeps (a copy of
        // each, 264 bytes a plane, was a piece's largest block of fresh memory).
        let extents: Vec<(Range<u32>, [f32; 4])> = control.map_units("extents", planes.len(), PLANE_UNIT, |i| {
            let poly = polygon(i);
            if poly.len < 3 {
                return (0..0, [0.0; 4]);
            }
            let (lo, hi) = poly
                .points()
                .iter()
                .fold((DVec2::INFINITY, DVec2::NEG_INFINITY), |(lo, hi), v| (lo.min(*v), hi.max(*v)));
            let rows = tiling.rows;
            let first = (lo.y - SPAN_MARGIN as f64).floor().max(0.0) as u32 / rows;
            let last = ((hi.y + SPAN_MARGIN as f64).floor().max(0.0) as u32 / rows).min(down - 1);
            (first..last + 1, [lo.x as f32, hi.x as f32, lo.y as f32, hi.y as f32])
        });
        let first_new = (self.offsets.len() - 1) as u32;
        let mut reach = Vec::with_capacity(extents.len());
        for (i, (rows, bounds)) in extents.iter().enumerate() {
            let poly = polygon(i);
            if poly.len >= 3 {
                self.vertices.extend(poly.points().iter().map(|v| v.as_vec2()));
            }
            self.offsets.push(self.vertices.len() as u32);
            self.bounds.push(*bounds);
            reach.push(rows.clone());
        }
        self.lights.extend(planes.iter().map(|p| p.light as u32));
        // Binned band by band in parallel: each plane's spans in the band's rows, walked once
        // (not once per tile: a plane crosses several tiles of a band), kept light by light (a
        // stable sort: each light's planes stay in index order), and the band's tiles listed
        // from them.
        let old = std::mem::take(&mut self.bands);
        let lights = &self.lights;
        let section = control.section("bin");
        let me = &*self;
        let bins: Vec<(BandBins, Vec<Vec<u32>>, Vec<u64>)> = (0..down)
            .into_par_iter()
            .zip(old)
            .map(|(band, mut bins)| {
                section.unit(|| {
                    let first_row = band * tiling.rows;
                    let rows = tiling.rows.min(tiling.height - first_row);
                    for (i, reach) in reach.iter().enumerate() {
                        if !reach.contains(&band) {
                            continue;
                        }
                        let plane = first_new + i as u32;
                        if across == 1 {
                            // A band is one tile: its spans are walked where they are used, once.
                            let light = lights[plane as usize];
                            bins.records.push(Record { plane, light, row: 0, rows: 0, spans: 0, cols: (0, 0) });
                            continue;
                        }
                        let spans = me.spans(plane as usize, first_row, rows);
                        let spans = &spans[..rows as usize];
                        let Some(first_j) = spans.iter().position(Option::is_some) else {
                            continue;
                        };
                        let last_j = spans.iter().rposition(Option::is_some).expect("one span, found above");
                        let start = bins.spans.len() as u32;
                        let (mut lo, mut hi) = (u32::MAX, 0);
                        for span in &spans[first_j..=last_j] {
                            bins.spans.push(match *span {
                                Some((f, l)) => {
                                    (lo, hi) = (lo.min(f), hi.max(l));
                                    (f as u16, l as u16)
                                }
                                None => (1, 0),
                            });
                        }
                        bins.records.push(Record {
                            plane,
                            light: lights[plane as usize],
                            row: first_j as u8,
                            rows: (last_j - first_j + 1) as u8,
                            spans: start,
                            cols: (lo as u16, hi as u16),
                        });
                    }
                    bins.records.sort_by_key(|r| r.light);
                    let mut tiles = vec![Vec::new(); across as usize];
                    let mut work = vec![0u64; across as usize];
                    let band_rows = (first_row as f32, (first_row + rows) as f32);
                    for (k, r) in bins.records.iter().enumerate() {
                        if across == 1 {
                            tiles[0].push(k as u32);
                            // The box's part in the band.
                            let [x0, x1, y0, y1] = me.bounds[r.plane as usize];
                            let h = (y1.min(band_rows.1) - y0.max(band_rows.0)).max(0.0) + 1.0;
                            work[0] += PLANE_WORK + (h * (x1 - x0 + 1.0)) as u64;
                            continue;
                        }
                        let col = |x: u16| (x as u32 / tiling.cols).min(across - 1) as usize;
                        for c in col(r.cols.0)..=col(r.cols.1) {
                            tiles[c].push(k as u32);
                            let (c0, c1) = (c as u32 * tiling.cols, (c as u32 + 1) * tiling.cols - 1);
                            let wide = (r.cols.1 as u32).min(c1) + 1 - (r.cols.0 as u32).max(c0).min(c1 + 1);
                            work[c] += PLANE_WORK + wide as u64 * r.rows as u64;
                        }
                    }
                    (bins, tiles, work)
                })
            })
            .collect();
        section.close();
        for (band, (bins, tiles, work)) in bins.into_iter().enumerate() {
            self.bands.push(bins);
            for (c, (tile, work)) in tiles.into_iter().zip(work).enumerate() {
                self.tiles[band * across as usize + c] = tile;
                self.work[band * across as usize + c] = work;
            }
        }
    }

    /// For each row of `first_row..first_row + rows` (at most [`BAND_ROWS`]), the columns
    /// `[first, last]` whose pixel squares may meet polygon `i`, if any: the polygon's x-range
    /// within the row's strip `[row - m, row + 1 + m]`, grown by m = [`SPAN_MARGIN`]. One walk
    /// over the edges serves all the rows, as lanes: the scalar walk, row by row, took a tenth of
    /// the gathering's instructions. As many lanes as the rows need, 4, 8 or 16 (half an AVX
    /// register, one or two): a part of a heavy band (4 to 8 rows, [`gather_pieces`]) walks each
    /// plane's edges once per part, and in all 16 lanes for its 4 to 8 rows the walk was 9.7% of
    /// the render's samples with 16 workers' cuts, against 6.9% with one's (655,360 planes). Each
    /// lane is its own row's arithmetic: the same spans whatever the lanes.
    fn spans(&self, i: usize, first_row: u32, rows: u32) -> [Option<(u32, u32)>; BAND_ROWS as usize] {
        #[cfg(target_arch = "x86_64")]
        if Kernel::Avx2.is_available() {
            // SAFETY: the CPU has the features of `spans_avx2`, just checked.
            return unsafe { self.spans_avx2(i, first_row, rows) };
        }
        self.spans_sized(i, first_row, rows)
    }

    /// [`ScreenRaster::spans`] with the rows in AVX registers (the same operations: the same
    /// bits); with SSE's four lanes for a band's sixteen rows it took 7% of the benchmark's CPU
    /// time.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn spans_avx2(&self, i: usize, first_row: u32, rows: u32) -> [Option<(u32, u32)>; BAND_ROWS as usize] {
        self.spans_sized(i, first_row, rows)
    }

    /// [`ScreenRaster::spans_in_lanes`] in the fewest of 4, 8 and 16 lanes that hold `rows`.
    #[inline(always)]
    fn spans_sized(&self, i: usize, first_row: u32, rows: u32) -> [Option<(u32, u32)>; BAND_ROWS as usize] {
        match rows {
            0..=4 => self.spans_in_lanes::<4>(i, first_row, rows),
            5..=8 => self.spans_in_lanes::<8>(i, first_row, rows),
            _ => self.spans_in_lanes::<{ BAND_ROWS as usize }>(i, first_row, rows),
        }
    }

    /// The walk of [`ScreenRaster::spans`] with `R` rows as lanes, `rows` of them wanted (at
    /// most `R`).
    #[inline(always)]
    fn spans_in_lanes<const R: usize>(
        &self,
        i: usize,
        first_row: u32,
        rows: u32,
    ) -> [Option<(u32, u32)>; BAND_ROWS as usize] {
        debug_assert!(rows as usize <= R && R <= BAND_ROWS as usize, "{rows} rows in {R} lanes");
        let poly = &self.vertices[self.offsets[i] as usize..self.offsets[i + 1] as usize];
        let mut lo = [f32::INFINITY; R];
        let mut hi = [f32::NEG_INFINITY; R];
        // Each row's strip.
        let top: [f32; R] = std::array::from_fn(|j| (first_row as usize + j) as f32 - SPAN_MARGIN);
        let bottom: [f32; R] = std::array::from_fn(|j| (first_row as usize + j) as f32 + 1.0 + SPAN_MARGIN);
        let (band_top, band_bottom) = (top[0], (first_row + rows) as f32 + SPAN_MARGIN);
        // Each edge p -> q, the last closing the polygon (a rotated iterator: an index modulo
        // the length was an integer division per edge).
        for (&p, &q) in poly.iter().zip(poly.iter().cycle().skip(1)) {
            let (ymin, ymax) = (min(p.y, q.y), max(p.y, q.y));
            if ymax < band_top || ymin > band_bottom {
                continue;
            }
            let dy = q.y - p.y;
            let flat = dy == 0.0;
            let slope = (q.x - p.x) / dy;
            let (xlo, xhi) = (min(p.x, q.x), max(p.x, q.x));
            for j in 0..R {
                // The edge's x at the ends of its part inside the strip, kept on the edge; a
                // horizontal edge's two ends.
                let (ya, yb) = (max(ymin, top[j]), min(ymax, bottom[j]));
                let xa = if flat { xlo } else { min(max(p.x + (ya - p.y) * slope, xlo), xhi) };
                let xb = if flat { xhi } else { min(max(p.x + (yb - p.y) * slope, xlo), xhi) };
                let meets = (bottom[j] >= ymin) & (top[j] <= ymax);
                lo[j] = if meets { min(lo[j], min(xa, xb)) } else { lo[j] };
                hi[j] = if meets { max(hi[j], max(xa, xb)) } else { hi[j] };
            }
        }
        let mut out = [None; BAND_ROWS as usize];
        for j in 0..rows as usize {
            if lo[j] > hi[j] || hi[j] + SPAN_MARGIN < 0.0 {
                continue;
            }
            // Truncation is floor for the non-negative values it is given.
            let first = max(lo[j] - SPAN_MARGIN, 0.0) as u32;
            let last = ((hi[j] + SPAN_MARGIN) as u32).min(self.width - 1);
            out[j] = (first <= last).then_some((first, last));
        }
        out
    }

    pub fn count_hits(&self, ctx: &GatherContext, kernel: Kernel, rays: &[CameraRay]) -> GatherStats {
        let mut out = vec![Vec3::ZERO; rays.len()];
        let piece = RasterPiece { raster: self, ctx, rays, target: 0, tap: None };
        gather_pieces::<Unweighted, false>(&[piece], &Unweighted, kernel, &mut [&mut out], &mut [], Control::none())[0]
    }

    /// One piece's planes in one tile (its rows from `skip` on, as many as `sums` holds: a part
    /// of a heavy tile): its planes light by light, each against its spans
    /// (clipped to the tile's columns), each light's sums folded into the tile's totals when its
    /// planes end ([`kernel::fold`]), the totals added to `sums` (the tile's rows) at the end,
    /// and what that added to each pixel, `after - before` in f64 of the f32 sums (as
    /// [`crate::spread::GroupSpread::add`] takes it from copies), to `tap`'s rows where there is
    /// one: the piece's own sums, as the render's error image needs them (section 10.1), with no
    /// copy of the image. The cancel flag is read before each plane (a relaxed load, nothing
    /// beside a plane's work), so that even a tile of millions of planes stops within
    /// milliseconds.
    fn gather_tile<D: Denominator, const CONTRIBUTE: bool>(
        &self,
        with: Gathering<D>,
        prepared: &[D::Plane],
        (tile, skip): (usize, u32),
        soa: &PaddedRays,
        (sums, tap): (&mut [&mut [Vec3]], Option<&mut [&mut [DVec3]]>),
        control: Control,
    ) -> GatherStats {
        let Gathering { ctx, weights, kernel } = with;
        let (tile_rows, cols) = self.tiling.tile(tile);
        let row_range = tile_rows.start + skip..tile_rows.start + skip + sums.len() as u32;
        let first_row = row_range.start;
        let stride = soa.stride;
        let mut acc = PaddedSums::new(soa.x.len());
        let mut folded = PaddedSums::new(soa.x.len());
        let mut totals = kernel::BandTotals { r: &mut folded.r, g: &mut folded.g, b: &mut folded.b };
        let mut stats = GatherStats::default();
        let mut kernel_band = Band {
            rays: kernel::BandRays { x: &soa.x, y: &soa.y, z: &soa.z, t0: &soa.t0, t1: &soa.t1 },
            sums: kernel::BandSums { r: &mut acc.r, g: &mut acc.g, b: &mut acc.b },
        };
        let mut spans = Vec::with_capacity(BAND_ROWS as usize);
        let mut light: Option<LightSum> = None;
        // The per-hit kernel's sums are folded by the portable one (a fold has no per-hit form;
        // its lanes do the same operations).
        let fold_kernel = if kernel == Kernel::PerHit { Kernel::Portable } else { kernel };
        let grey = ctx.extinction.grey;
        let fold = |sums: &mut kernel::BandSums, totals: &mut kernel::BandTotals, done: LightSum| {
            // Counting hits alone writes no sums.
            if CONTRIBUTE {
                kernel::fold(fold_kernel, done.scale, grey, sums, totals, blocks(done.touched));
            }
        };
        let (c0, c1) = (cols.start, cols.end - 1);
        let bins = &self.bands[tile / self.tiling.across() as usize];
        let band_row = tile_rows.start;
        // Spans kept by the binning when bands are cut into tiles ([`BandBins`]), else walked.
        let stored = self.tiling.across() > 1;
        let list = &self.tiles[tile];
        // What a plane a few places on will read first, asked of memory now, where the piece's
        // views outgrow a core's cache: a tile's planes are a sparse pick of the piece's, and
        // the first read of each one's view missed the caches (half of this loop's own time at
        // 655,360 planes, `perf annotate`). Below that (the benchmark's pieces of 2,560 planes,
        // 350 kB of views) the prefetches cost 4% and found the views there already. Its
        // polygon's vertices, asked for too, made the render slower (a fifth of the span walk's
        // time is their first read; cause not found).
        let far = std::mem::size_of_val(&ctx.views[..]) > PREFETCH_VIEWS_FROM;
        for (n, &k) in list.iter().enumerate() {
            if control.is_cancelled() {
                return stats;
            }
            if let Some(&ahead) = list.get(n + PREFETCH_AHEAD).filter(|_| far) {
                let plane = bins.records[ahead as usize].plane as usize;
                prefetch(&ctx.views[plane]);
                prefetch(&prepared[plane]);
            }
            let record = &bins.records[k as usize];
            let plane = record.plane;
            let view = &ctx.views[plane as usize];
            spans.clear();
            let mut add = |row: u32, first: u32, last: u32| {
                let (first, last) = (first.max(c0), last.min(c1));
                if first <= last {
                    // Whole half blocks: the span grown to a multiple of HALF_LANES, into the
                    // row's padding if need be (padding rays never hit). Every kernel tests the
                    // same pixels.
                    let len = (last - first + 1).next_multiple_of(HALF_LANES as u32);
                    spans.push(Span { start: (row - first_row) * stride as u32 + (first - c0), len });
                    stats.tests += len as u64;
                }
            };
            if stored {
                let record_rows = band_row + record.row as u32..band_row + record.row as u32 + record.rows as u32;
                let stored = &bins.spans[record.spans as usize..record.spans as usize + record.rows as usize];
                for (row, &(first, last)) in record_rows.zip(stored) {
                    if row_range.contains(&row) {
                        add(row, first as u32, last as u32);
                    }
                }
            } else {
                let walked = self.spans(plane as usize, first_row, row_range.len() as u32);
                for (row, span) in row_range.clone().zip(walked) {
                    if let Some((first, last)) = span {
                        add(row, first, last);
                    }
                }
            }
            if spans.is_empty() {
                continue;
            }
            let (first, end) = spans
                .iter()
                .fold((usize::MAX, 0), |(lo, hi), s| (lo.min(s.start as usize), hi.max((s.start + s.len) as usize)));
            match &mut light {
                Some(current) if current.light == view.light => {
                    debug_assert_eq!(current.scale, view.scale, "one scale per light");
                    current.touched = current.touched.start.min(first)..current.touched.end.max(end);
                }
                _ => {
                    if let Some(done) = light.take() {
                        fold(&mut kernel_band.sums, &mut totals, done);
                    }
                    light = Some(LightSum { light: view.light, scale: view.scale, touched: first..end });
                }
            }
            let job = ctx.job(weights, view, &prepared[plane as usize]);
            if kernel == Kernel::PerHit {
                let (rays, sums) = (&kernel_band.rays, &mut kernel_band.sums);
                for k in spans.iter().flat_map(|s| s.start as usize..(s.start + s.len) as usize) {
                    let one = RayBlock { x: rays.x[k], y: rays.y[k], z: rays.z[k], t0: rays.t0[k], t1: rays.t1[k] };
                    let sums = [
                        std::array::from_mut(&mut sums.r[k]),
                        std::array::from_mut(&mut sums.g[k]),
                        std::array::from_mut(&mut sums.b[k]),
                    ];
                    stats.hits += job.gather_block_in::<1, f32, CONTRIBUTE>(&one, sums) as u64;
                }
            } else {
                stats.hits += kernel::gather_plane::<D, CONTRIBUTE>(kernel, &job, &spans, &mut kernel_band);
            }
        }
        if let Some(done) = light {
            fold(&mut kernel_band.sums, &mut totals, done);
        }
        let total = |i: usize| Vec3::new(totals.r[i], totals.g[i], totals.b[i]);
        match tap {
            None => {
                for (row, sums) in sums.iter_mut().enumerate() {
                    for (k, s) in sums.iter_mut().enumerate() {
                        *s += total(row * stride + k);
                    }
                }
            }
            Some(tap) => {
                for (row, (sums, tap)) in sums.iter_mut().zip(tap.iter_mut()).enumerate() {
                    for (k, (s, t)) in sums.iter_mut().zip(tap.iter_mut()).enumerate() {
                        let before = *s;
                        *s += total(row * stride + k);
                        *t += s.as_dvec3() - before.as_dvec3();
                    }
                }
            }
        }
        stats
    }
}

/// One piece of planes for [`gather_pieces`]: its raster, its planes' constants, the ray set it
/// is gathered along (one ray per pixel, row-major), the sums it adds to and the tap, if any,
/// that its own sums also go to.
#[derive(Clone, Copy)]
pub struct RasterPiece<'a> {
    pub raster: &'a ScreenRaster,
    pub ctx: &'a GatherContext,
    pub rays: &'a [CameraRay],
    pub target: usize,
    pub tap: Option<usize>,
}

/// A tile's rows (or a part's: some of them) of a target's sums, and of its taps, by tap.
struct PartRows<'s> {
    sums: Vec<&'s mut [Vec3]>,
    taps: Vec<(usize, Vec<&'s mut [DVec3]>)>,
}

impl<'s> PartRows<'s> {
    /// The rows from `at` on, taken from these.
    fn split_off(&mut self, at: usize) -> PartRows<'s> {
        let taps = self.taps.iter_mut().map(|(tap, rows)| (*tap, rows.split_off(at))).collect();
        PartRows { sums: self.sums.split_off(at), taps }
    }

    /// The rows a piece with `tap` adds to: the sums', and its tap's.
    fn for_piece(&mut self, tap: Option<usize>) -> (&mut [&'s mut [Vec3]], Option<&mut [&'s mut [DVec3]]>) {
        let tap =
            tap.map(|t| self.taps.iter_mut().find(|(tap, _)| *tap == t).expect("the target's tap").1.as_mut_slice());
        (&mut self.sums, tap)
    }
}

/// Each tile's rows of an image `buf` (row-major), tile by tile: the tiles cut every row into
/// disjoint runs.
fn tiles_rows<T>(buf: &mut [T], tiling: Tiling) -> Vec<Vec<&mut [T]>> {
    let (w, across) = (tiling.width as usize, tiling.across() as usize);
    let mut tiles: Vec<Vec<&mut [T]>> = (0..tiling.count()).map(|_| Vec::new()).collect();
    for (j, mut row) in buf.chunks_mut(w).enumerate() {
        let down = j / tiling.rows as usize;
        for a in 0..across {
            let take = (tiling.cols as usize).min(row.len());
            let (run, rest) = row.split_at_mut(take);
            tiles[down * across + a].push(run);
            row = rest;
        }
    }
    tiles
}

/// Gathers `pieces` with `weights`, adding each ray's estimate of each piece to `sums[target]`
/// (an image's, row-major; the piece's target), with `kernel` (resolved); returns what each
/// target's pieces found. The pieces' rasters share one [`Tiling`]: a tile of a target is a unit
/// of work (one parallel loop over them all, the heaviest first), which takes the target's
/// pieces in their order (no barrier between pieces, nor between targets: a render gathers
/// several chunks at once, each into its own sums). A pixel of a target lies in one tile, which
/// adds each piece to it as a whole-image gathering of that piece alone would: the same bits.
/// One progress report per tile and piece; cancelled, each tile stops before its next plane.
///
/// A piece with a tap also adds what it added to each pixel to `taps[tap]` (f64, the image's
/// size; [`ScreenRaster::gather_tile`]), in piece order. A tap takes the pieces of one target
/// only: a pixel's tap is written by the tile that holds the pixel in that target.
pub fn gather_pieces<D: Denominator, const CONTRIBUTE: bool>(
    pieces: &[RasterPiece],
    weights: &D,
    kernel: Kernel,
    sums: &mut [&mut [Vec3]],
    taps: &mut [&mut [DVec3]],
    control: Control,
) -> Vec<GatherStats> {
    // The kernels' target features are the CPU's: checked once here, for every plane and fold
    // of the gathering (a `Gathering` can be made with any kernel).
    assert!(kernel.is_available(), "the {kernel} kernel is not available on this CPU");
    let mut found = vec![GatherStats::default(); sums.len()];
    let Some(first) = pieces.first() else {
        return found;
    };
    let tiling = first.raster.tiling;
    let pixels = tiling.width as usize * tiling.height as usize;
    assert!(
        pieces.iter().all(|p| p.raster.tiling == tiling && p.rays.len() == pixels && p.target < sums.len())
            && sums.iter().all(|s| s.len() == pixels),
        "the pieces of a gathering share one image and its tiles"
    );
    // Each tap's target: the one of every piece that adds to it.
    let tap_target: Vec<Option<usize>> = (0..taps.len())
        .map(|t| {
            let mut targets = pieces.iter().filter(|p| p.tap == Some(t)).map(|p| p.target);
            let first = targets.next();
            assert!(targets.all(|c| Some(c) == first), "a tap takes the pieces of one target");
            first
        })
        .collect();
    assert!(
        taps.iter().all(|t| t.len() == pixels) && pieces.iter().all(|p| p.tap.is_none_or(|t| t < taps.len())),
        "a gathering's taps are its image's size"
    );
    // What the weights need of each plane, once per piece (a plane crosses many tiles); stopped,
    // like the gathering, by a cancel.
    let mut prepared: Vec<Vec<D::Plane>> = Vec::with_capacity(pieces.len());
    for piece in pieces {
        let views = &piece.ctx.views;
        let planes = control.map_units("weights", views.len(), PLANE_UNIT, |i| {
            (!control.is_cancelled()).then(|| weights.prepare(&views[i].frame))
        });
        if control.is_cancelled() {
            return found;
        }
        prepared.push(planes.into_iter().map(|p| p.expect("not cancelled")).collect());
    }
    // A target of the window that no piece of this gathering adds to has no work here.
    let busy: Vec<bool> = (0..sums.len()).map(|c| pieces.iter().any(|p| p.target == c)).collect();
    // Each target's tiles' rows of its sums, and of its taps.
    let mut tiles: Vec<(usize, usize, PartRows)> = Vec::with_capacity(sums.len() * tiling.count());
    for (target, sums) in sums.iter_mut().enumerate() {
        tiles.extend(
            tiles_rows(sums, tiling)
                .into_iter()
                .enumerate()
                .map(|(t, sums)| (target, t, PartRows { sums, taps: Vec::new() })),
        );
    }
    for (tap, buf) in taps.iter_mut().enumerate() {
        let Some(target) = tap_target[tap] else { continue };
        for (t, rows) in tiles_rows(buf, tiling).into_iter().enumerate() {
            tiles[target * tiling.count() + t].2.taps.push((tap, rows));
        }
    }
    // A tile with more work than its share is cut into parts of at least MIN_TILE_ROWS whole
    // rows, each taking the tile's planes over its own rows (their spans kept by the binning,
    // or walked for the part's rows where a band is one tile), so that no part outweighs a
    // worker's share of the gathering (the tiles' work is uneven: 7 times the mean for the
    // heaviest of 640x360's 540 tiles for 64 workers), at the cost of a plane's set-up and
    // span walk per part: 9% more CPU at 4 workers, whose bands are cut where one would be a
    // quarter of a worker's share (the schedule model's records: 3.7x predicted against 3.8x
    // uncut), but 14.0x at 16 against 13.0x.
    let load = |target: usize, t: usize| {
        pieces.iter().filter(|p| p.target == target).map(|p| p.raster.work[t] as usize).sum::<usize>()
    };
    let per_worker = if tiling.across() > 1 { SPLIT_PER_WORKER } else { 4 };
    let share = (tiles.iter().map(|(target, t, _)| load(*target, *t)).sum::<usize>()
        / (per_worker * crate::schedule::workers()))
    .max(1);
    let mut parts = Vec::with_capacity(tiles.len());
    for (target, tile, mut rows) in tiles.into_iter().filter(|(target, _, _)| busy[*target]) {
        let load = load(target, tile);
        let n = load.div_ceil(share).clamp(1, rows.sums.len().div_ceil(MIN_TILE_ROWS as usize).max(1));
        let per = rows.sums.len().div_ceil(n).max(1);
        let mut skip = 0;
        while !rows.sums.is_empty() {
            let rest = rows.split_off(per.min(rows.sums.len()));
            parts.push((target, tile, skip as u32, load / n, rows));
            skip += per;
            rows = rest;
        }
    }
    // The heaviest first: the last a worker takes are then small ones, and the workers finish
    // together (with 23 bands of rows for 2 workers, in image order one of them idled for 5% of
    // the gathering's wall time).
    parts.sort_by_key(|&(target, tile, skip, load, _)| (std::cmp::Reverse(load), target, tile, skip));
    let section = control.section("tiles");
    let each = parts
        .into_par_iter()
        .with_max_len(1)
        .map(|(target, tile, skip, _, mut rows)| {
            let stats = section.unit(|| {
                let mut stats = GatherStats::default();
                // The part's rays, laid out once for the consecutive pieces along one ray set (a
                // group's two halves): the same data, made once.
                let mut padded: Option<(*const CameraRay, PaddedRays)> = None;
                for (piece, prepared) in pieces.iter().zip(&prepared).filter(|(p, _)| p.target == target) {
                    if control.is_cancelled() {
                        break;
                    }
                    if padded.as_ref().is_none_or(|(along, _)| *along != piece.rays.as_ptr()) {
                        let (tile_rows, cols) = tiling.tile(tile);
                        let part = tile_rows.start + skip..tile_rows.start + skip + rows.sums.len() as u32;
                        let soa = PaddedRays::new(piece.rays, piece.raster.width as usize, part, cols);
                        padded = Some((piece.rays.as_ptr(), soa));
                    }
                    let soa = &padded.as_ref().expect("made above").1;
                    let with = Gathering { ctx: piece.ctx, weights, kernel };
                    stats += piece.raster.gather_tile::<D, CONTRIBUTE>(
                        with,
                        prepared,
                        (tile, skip),
                        soa,
                        rows.for_piece(piece.tap),
                        control,
                    );
                    // One report per tile (its first part) and piece, whatever the parts.
                    if skip == 0 && !control.is_cancelled() {
                        control.progress();
                    }
                }
                stats
            });
            (target, stats)
        })
        .collect::<Vec<_>>();
    section.close();
    for (target, stats) in each {
        found[target] += stats;
    }
    found
}

/// How many planes of a tile's list ahead of the one gathered [`ScreenRaster::gather_tile`]
/// asks memory for: its view and its weights' constants.
const PREFETCH_AHEAD: usize = 4;

/// The size of a piece's views from which [`ScreenRaster::gather_tile`] prefetches (1 MiB:
/// about 7,700 planes).
const PREFETCH_VIEWS_FROM: usize = 1 << 20;

/// Asks for the cache lines of `value` (a hint: no fault, no effect on any value); nothing
/// for a zero-sized one, whose address is no memory's.
#[inline(always)]
fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let (start, len) = (value as *const T as *const u8, std::mem::size_of::<T>());
        // A byte in every line from the first byte's to the last's.
        let skew = start as usize % 64;
        for offset in (0..if len == 0 { 0 } else { skew + len }).step_by(64) {
            let line = start.wrapping_sub(skew).wrapping_add(offset);
            // SAFETY: a prefetch reads nothing the program sees and cannot fault; SSE is part
            // of x86_64's baseline.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(line as *const i8) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}

/// The planes that may cover a band of rows, each with its spans there: what the band's tiles
/// gather.
#[derive(Default)]
struct BandBins {
    /// By light, each light's planes in index order.
    records: Vec<Record>,
    /// Each record's spans, row after row.
    spans: Vec<(u16, u16)>,
}

/// A plane in a band: its spans, `[first, last]` columns of the rows `row..row + rows` of the
/// band ([`ScreenRaster::spans`]; an empty span `first > last`), from `spans` on, and the columns
/// they reach.
struct Record {
    plane: u32,
    light: u32,
    row: u8,
    rows: u8,
    spans: u32,
    cols: (u16, u16),
}

/// The light whose planes a tile is summing: its index, its scale and the pixels its planes
/// touched.
struct LightSum {
    light: u32,
    scale: Vec3,
    touched: Range<usize>,
}

/// `range` grown to whole blocks of [`LANES`] (a tile's rows are padded to whole blocks).
fn blocks(range: Range<usize>) -> Range<usize> {
    range.start / LANES * LANES..range.end.next_multiple_of(LANES)
}

/// Compare-and-select: one instruction each (f32::min and max spend several on NaN, which only
/// the unused slope of a horizontal edge is). Functions, not closures: a closure is compiled
/// without the caller's target features.
#[inline(always)]
fn min(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

#[inline(always)]
fn max(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// The camera rays of one tile as a structure of arrays, so that a span vectorises. Each row is
/// followed by at least LANES - 1 padding rays that never hit anything (zero direction, empty
/// segment), so that a span grown to whole blocks stays in its row.
struct PaddedRays {
    stride: usize,
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    t0: Vec<f32>,
    t1: Vec<f32>,
}

impl PaddedRays {
    /// The rays of the tile `rows` x `cols` of an image `width` pixels wide (`rays` row-major).
    fn new(rays: &[CameraRay], width: usize, rows: Range<u32>, cols: Range<u32>) -> Self {
        let (c0, c1) = (cols.start as usize, cols.end as usize);
        let tile = c1 - c0;
        let stride = (tile + LANES - 1).next_multiple_of(LANES);
        let n = rows.len() * stride;
        let field = |get: fn(&CameraRay) -> f32, pad: f32| -> Vec<f32> {
            // Each row and its padding written once (not the whole tile filled first).
            let mut v = Vec::with_capacity(n);
            for j in rows.clone() {
                let row = &rays[j as usize * width + c0..j as usize * width + c1];
                v.extend(row.iter().map(get));
                v.resize(v.len() + stride - tile, pad);
            }
            v
        };
        PaddedRays {
            stride,
            x: field(|r| r.dir.x, 0.0),
            y: field(|r| r.dir.y, 0.0),
            z: field(|r| r.dir.z, 0.0),
            t0: field(|r| r.t0, 1.0),
            t1: field(|r| r.t1, 0.0),
        }
    }
}

/// Per-pixel sums of one tile (rows padded like [`PaddedRays`]), a structure of arrays.
struct PaddedSums {
    r: Vec<f32>,
    g: Vec<f32>,
    b: Vec<f32>,
}

impl PaddedSums {
    fn new(n: usize) -> Self {
        PaddedSums { r: vec![0.0; n], g: vec![0.0; n], b: vec![0.0; n] }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The occluders found from the box polygon the raster projects (grown by its margin) hold
    /// those of the exact polygon in the box, plane by plane: a light left out would be a
    /// shadow missed. Scenes where lights lie on the box's faces, face each other closely, are
    /// seen edge-on or block each other, and the benchmark.
    #[test]
    fn occluders_from_the_box_polygon_hold_the_exact_ones() {
        use crate::occlusion::{occluders_of_polygon, possible_occluders};
        use crate::photon_plane::sample_planes;
        let scenes = [
            ("six_lights", include_str!("../../../media_scenes/six_lights.toml")),
            ("light_on_box_face", include_str!("../../../media_scenes/hard/light_on_box_face.toml")),
            ("facing_lights_close", include_str!("../../../media_scenes/hard/facing_lights_close.toml")),
            ("edge_on_light", include_str!("../../../media_scenes/hard/edge_on_light.toml")),
            ("two_lights_one_blocker", include_str!("../../../media_scenes/two_lights_one_blocker.toml")),
        ];
        for (name, text) in scenes {
            let scene = crate::scene::Scene::parse(text, name, name).unwrap();
            let (mut shadowing, mut extra) = (0, 0);
            for p in sample_planes(&scene, Default::default(), 20_000, 11) {
                let exact = possible_occluders(&scene, &p);
                let grown = occluders_of_polygon(&scene, &p, &box_polygon(&p, &scene.medium));
                assert_eq!(grown & exact, exact, "{name}: a light left out");
                shadowing += (exact != 0) as usize;
                extra += (grown != exact) as usize;
            }
            println!("{name}: {shadowing} of 20,000 planes may be shadowed, {extra} masks grown");
            assert!(shadowing > 0, "{name}: no plane to test");
        }
    }

    /// The span walk gives each row the same columns whatever the lanes it runs in: a part's
    /// rows in 4 or 8 lanes, a band's in 16, and each row alone, for the benchmark's planes
    /// over every start row of the image and every count of rows; and the rows asked for only.
    #[test]
    fn spans_are_the_same_in_every_width() {
        use crate::photon_plane::sample_planes;
        let text = include_str!("../../../media_scenes/six_lights.toml");
        let scene =
            crate::scene::Scene::parse(text, "six_lights", "six_lights").unwrap().with_resolution(96, 54).unwrap();
        let camera = &scene.camera;
        let planes = sample_planes(&scene, Default::default(), 300, 5);
        let raster = ScreenRaster::build(camera, &planes, &scene.medium);
        let mut found = 0;
        for i in 0..planes.len() {
            for first_row in 0..camera.height {
                let most = BAND_ROWS.min(camera.height - first_row);
                // Row by row, in the widest lanes: the reference for every width.
                let single: Vec<_> = (0..most).map(|j| raster.spans_in_lanes::<16>(i, first_row + j, 1)[0]).collect();
                found += single.iter().flatten().count();
                for rows in 1..=most {
                    let want: Vec<_> = single[..rows as usize]
                        .iter()
                        .copied()
                        .chain(std::iter::repeat_n(None, (BAND_ROWS - rows) as usize))
                        .collect();
                    assert_eq!(raster.spans(i, first_row, rows).to_vec(), want, "plane {i} rows {first_row} + {rows}");
                    assert_eq!(
                        raster.spans_sized(i, first_row, rows).to_vec(),
                        want,
                        "plane {i} rows {first_row} + {rows}"
                    );
                    if rows <= 8 {
                        assert_eq!(raster.spans_in_lanes::<8>(i, first_row, rows).to_vec(), want);
                    }
                }
            }
        }
        assert!(found > 1000, "{found} spans");
    }

    /// Every pixel lies in exactly one tile, whatever the image and the workers; the benchmark's
    /// image is tiled as the docs say, one chunk at a time and in windows.
    #[test]
    fn tiles_cover_the_image_once() {
        for (w, h) in [(640, 360), (96, 54), (7, 3), (1, 1), (1000, 17), (33, 700)] {
            for t in
                [1, 2, 3, 7, 16, 64, 1024].into_iter().flat_map(|n| [Tiling::new(w, h, n), Tiling::for_window(w, h, n)])
            {
                let threads = t.count();
                let mut seen = vec![0u8; (w * h) as usize];
                for k in 0..t.count() {
                    let (rows, cols) = t.tile(k);
                    assert!(!rows.is_empty() && !cols.is_empty(), "{w}x{h} {threads}: tile {k} {t:?}");
                    assert!(rows.len() <= BAND_ROWS as usize);
                    for j in rows {
                        for i in cols.clone() {
                            seen[(j * w + i) as usize] += 1;
                        }
                    }
                }
                assert!(seen.iter().all(|&n| n == 1), "{w}x{h} {threads}: {t:?}");
            }
        }
        // (tiles down, across, rows, columns) for 2, 16 and 64 workers: one chunk at a time,
        // then in windows of chunks.
        let shapes = |tiling: fn(u32, u32, usize) -> Tiling| {
            [2, 16, 64].map(|n| tiling(640, 360, n)).map(|t| (t.down(), t.across(), t.rows, t.cols))
        };
        assert_eq!(shapes(Tiling::new), [(23, 1, 16, 640), (23, 3, 16, 216), (23, 12, 16, 56)]);
        assert_eq!(shapes(Tiling::for_window), [(23, 1, 16, 640), (23, 1, 16, 640), (23, 2, 16, 320)]);
        // A large image gathers one chunk at a time, in tiles for every worker.
        assert_eq!(chunks_at_once(64, 3840, 2160), 1);
        assert_eq!(Tiling::for_window(3840, 2160, 64), Tiling::new(3840, 2160, 64));
        assert_eq!([2, 16, 32, 64].map(|w| chunks_at_once(w, 640, 360)), [1, 3, 6, 8]);
    }
}
