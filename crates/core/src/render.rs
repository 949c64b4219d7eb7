//! The render drivers: a render of N planes in canonical chunks, a chunk range for another
//! machine, a render on a time budget in plane passes, and the table's renders of several
//! weightings over one prepared plane set.
//!
//! Every one of them goes through `Gatherer::gather`, the one loop over plane groups and ray
//! sets: a list of pieces of the plane set, each gathered along its ray set
//! (docs/mathematics.md section 8.1) from the one cache of ray sets ([`RaySets`]), each plane
//! weighted 1; and every image is finished by [`Film::finish`] (the division by N and the
//! direct emission, [`crate::emission`]). The options come resolved and checked from
//! [`crate::settings`]: nothing here checks them again.

use crate::accel::{
    Accelerator, CpuSide, GatherPiece, GpuPiece, OnGpu, PreparedPlanes, RaySet, gather_pieces, gather_pieces_on_gpu,
};
use crate::camera::CameraRay;
use crate::control::Control;
use crate::emission::direct_emission_and_variance_in;
use crate::error::{Error, Result, Setting};
use crate::film::Film;
use crate::gather::GatherStats;
use crate::limits::{BYTES_PER_PLANE, CHUNK_PLANES, MAX_PLANES, check_memory};
use crate::options::{Devices, RenderOptions, RenderStats};
use crate::partial::{
    Partial, Resume, chunk_indices, chunk_planes, chunks, combine_in, fingerprint, frontier, halves, pieces,
};
use crate::pixel::{Keep, RaySets, plane_group};
use crate::raster::Tiling;
use crate::scene::Scene;
use crate::schedule;
use crate::spread::{GroupSpread, relative_rms_error};
use crate::weights::Weighting;
use glam::{DVec3, Vec3};
use std::ops::Range;
use std::sync::Arc;
use std::time::Instant;

/// The one loop over plane groups and ray sets, with the cache of ray sets and what it measured.
struct Gatherer<'a> {
    scene: &'a Scene,
    opts: &'a RenderOptions,
    control: Control<'a>,
    rays: RaySets,
    stats: RenderStats,
    /// The plane groups' spread, for the error image ([`crate::spread`]), when it is asked.
    spread: Option<GroupSpread>,
}

/// A piece of planes `(k, planes, quarter, half)`: gathered along ray set `k`, in `quarter` of
/// the render and `half` (0 or 1) of its group, for the error image.
type PieceSpec = (u32, Range<usize>, usize, usize);

/// A window's pieces, chunk by chunk, with the seconds spent sampling their planes and building
/// their structures.
type Window = (Vec<Vec<Piece>>, (f64, f64));

/// A piece ready to gather: its planes prepared.
struct Piece {
    spec: PieceSpec,
    planes: Arc<PreparedPlanes>,
}

/// The most ray sets one gathering on the CPU holds (its pieces' sets, each tile taking the pieces in
/// turn): so that a chunk of many small pieces (small renders, many ray sets) holds two sets at
/// a time, not all of its own.
const RAY_SETS_PER_GATHERING: usize = 2;

/// Where the preparation of pieces finds what it needs (the other side of a chunk's gathering).
struct Preparer<'g> {
    scene: &'g Scene,
    opts: &'g RenderOptions,
    prepared: &'g [(Range<usize>, Arc<PreparedPlanes>)],
    /// Whether the pieces are gathered in windows of chunks ([`Tiling::for_window`]), else one
    /// at a time ([`Tiling::new`]).
    windowed: bool,
    /// Seconds spent sampling planes and building their structures.
    seconds_sampling: f64,
    seconds_build: f64,
}

impl<'g> Preparer<'g> {
    fn new(scene: &'g Scene, opts: &'g RenderOptions, prepared: &'g [(Range<usize>, Arc<PreparedPlanes>)]) -> Self {
        Preparer { scene, opts, prepared, windowed: false, seconds_sampling: 0.0, seconds_build: 0.0 }
    }

    /// Each piece's planes taken from `prepared` if they are there, else sampled and prepared
    /// now, the pieces side by side.
    fn pieces(&mut self, specs: impl IntoIterator<Item = PieceSpec>, control: Control) -> Result<Vec<Piece>> {
        let specs: Vec<PieceSpec> = specs.into_iter().collect();
        let (ready, (sampling, build)) = self.side_by_side(&specs, control);
        self.seconds_sampling += sampling;
        self.seconds_build += build;
        ready
    }

    /// The pieces of `specs`, two halves at a time (the two sides of a join: a chunk's pieces
    /// are small, about 1,200 planes on the benchmark (a group's half), and each one's parallel loops leave most
    /// of a many-core machine idle between them), with the seconds spent sampling and building.
    fn side_by_side(&self, specs: &[PieceSpec], control: Control) -> (Result<Vec<Piece>>, (f64, f64)) {
        match specs {
            [] => (Ok(Vec::new()), (0.0, 0.0)),
            [spec] => match self.piece(spec, control) {
                Ok((piece, seconds)) => (Ok(vec![piece]), seconds),
                Err(e) => (Err(e), (0.0, 0.0)),
            },
            _ => {
                let (left, right) = specs.split_at(specs.len() / 2);
                let ((a, sa), (b, sb)) = control.join(|c| self.side_by_side(left, c), |c| self.side_by_side(right, c));
                let ready = a.and_then(|mut a| {
                    a.extend(b?);
                    Ok(a)
                });
                (ready, (sa.0 + sb.0, sa.1 + sb.1))
            }
        }
    }

    /// One piece, with the seconds spent sampling and building its planes (none where they
    /// were prepared before).
    fn piece(&self, spec: &PieceSpec, control: Control) -> Result<(Piece, (f64, f64))> {
        if let Some((_, p)) = self.prepared.iter().find(|(r, _)| *r == spec.1) {
            return Ok((Piece { spec: spec.clone(), planes: p.clone() }, (0.0, 0.0)));
        }
        let set = self.opts.plane_set();
        let (w, h, workers) = (self.scene.camera.width, self.scene.camera.height, schedule::workers());
        let tiling = if self.windowed { Tiling::for_window(w, h, workers) } else { Tiling::new(w, h, workers) };
        let side = CpuSide::prepare(self.scene, set, spec.1.clone(), self.opts.structure(), tiling, control)?;
        let p = PreparedPlanes::from_cpu_side(self.scene, side, control)?;
        let seconds = (p.seconds_sampling, p.seconds_build);
        Ok((Piece { spec: spec.clone(), planes: Arc::new(p) }, seconds))
    }
}

/// What gathers prepared pieces: the options, the cache of ray sets and the error image's
/// spread (borrowed apart from the preparation of the next window of chunks).
struct GatherSide<'g> {
    scene: &'g Scene,
    opts: &'g RenderOptions,
    weighting: Weighting,
    rays: &'g mut RaySets,
    spread: &'g mut Option<GroupSpread>,
}

impl GatherSide<'_> {
    /// Gathers the pieces of each chunk of `chunks` in order, adding into the chunk's `sums`
    /// (f32, each plane weighted 1), in gatherings of consecutive pieces ([`gatherings`]:
    /// [`gather_pieces`], on the raster each tile of each chunk taking the chunk's pieces in
    /// turn), their ray sets made first; with an error image, each piece's sums going to the
    /// group spread. Returns what each chunk's pieces found and the wall seconds.
    fn gather(
        &mut self,
        chunks: &[Vec<Piece>],
        sums: &mut [&mut [Vec3]],
        control: Control,
    ) -> Result<(Vec<GatherStats>, f64)> {
        let t = Instant::now();
        let mut found = vec![GatherStats::default(); chunks.len()];
        let (weighting, kernel) = (self.weighting, self.opts.kernel);
        let all: Vec<(usize, &Piece)> =
            chunks.iter().enumerate().flat_map(|(c, pieces)| pieces.iter().map(move |p| (c, p))).collect();
        // On the GPU the chunks' sums stay there from gathering to gathering and cross back once,
        // added to the sums as they were; with an error image, a copy of a chunk's sums is taken
        // there after each of its pieces (a snapshot, in order with the work) and read back
        // with the others, so that the spread sees each piece's sums (and the image is the same
        // bits with it or without) without a round trip a piece.
        let mut on_gpu = matches!(self.opts.structure(), Accelerator::Gpu(_)).then(|| OnGpu::new(chunks.len()));
        let mut snapshots = Snapshots::new(chunks.len());
        // Each chunk's hits and GPU time, counted when its sums are read back.
        let mut read = vec![GatherStats::default(); chunks.len()];
        // On the GPU a gathering holds every ray set of its pieces: they are made there from
        // their records and kept until the sums are read (up to a bound,
        // `gpu::PENDING_RAY_BYTES`), and the pieces of one gathering record side by side.
        let sets_at_once = if on_gpu.is_some() { usize::MAX } else { RAY_SETS_PER_GATHERING };
        let apart = match (&self.spread, &on_gpu) {
            (None, _) => Apart::No,
            (Some(_), Some(_)) => Apart::Pieces,
            (Some(_), None) => Apart::Group,
        };
        for group in gatherings(&all, |&(c, p)| (c, &p.spec), sets_at_once, apart) {
            let each = match on_gpu.as_mut() {
                Some(on_gpu) => {
                    let pieces: Vec<GpuPiece> = group
                        .iter()
                        .map(|&(target, p)| GpuPiece { planes: &p.planes, set: p.spec.0, target })
                        .collect();
                    // Each set made on the GPU from its record; or, where asked
                    // (`rays_on_cpu`), made here straight into the GPU's upload buffer.
                    let (rays, scene, on) = (&mut *self.rays, self.scene, !self.opts.rays_on_cpu());
                    let mut make = |k: u32, g: &crate::gpu::GpuPlanes| {
                        if on {
                            let (record, panels) = rays.gpu_record(scene, k);
                            return Ok(RaySet::Record(record, panels));
                        }
                        let mut made = None;
                        rays.make_rows(scene, k, control, |row| made = Some(g.make_rays(row)));
                        made.expect("the maker gives the set's rows").map(RaySet::Made)
                    };
                    let each = gather_pieces_on_gpu(&pieces, weighting, on_gpu, &mut make, control)?;
                    // With an error image each piece is its chunk's only one in the gathering:
                    // a snapshot after it holds its chunk's sums after it.
                    if let Some(spread) = self.spread.as_mut() {
                        for &(c, p) in group {
                            on_gpu.snapshot(c)?;
                            snapshots.pieces[c].push(p.spec.clone());
                        }
                        if on_gpu.snapshot_bytes() > MAX_SNAPSHOT_BYTES {
                            snapshots.tell(on_gpu, sums, spread, control)?;
                        }
                    }
                    each
                }
                None => {
                    let rays: Vec<Arc<Vec<CameraRay>>> =
                        group.iter().map(|(_, p)| self.rays.rays(self.scene, p.spec.0, control)).collect();
                    // With an error image, the gathering's pieces are of one group: each adds its
                    // own sums to its half's (the spread's open group, a tap).
                    let tap = |p: &Piece| (apart == Apart::Group).then_some(p.spec.3.min(1));
                    let pieces: Vec<GatherPiece> = group
                        .iter()
                        .zip(&rays)
                        .map(|(&(target, p), r)| GatherPiece {
                            planes: &p.planes,
                            rays: r.as_slice(),
                            target,
                            tap: tap(p),
                        })
                        .collect();
                    match self.spread.as_mut() {
                        Some(spread) => {
                            let (k, _, quarter, _) = group[0].1.spec;
                            let mut taps = spread.open_group(k, quarter, control);
                            let each = gather_pieces(&pieces, weighting, kernel, sums, &mut taps, control)?;
                            let mut planes = [0; 2];
                            for (_, p) in group {
                                planes[p.spec.3.min(1)] += p.spec.1.len();
                            }
                            spread.add_planes(planes);
                            each
                        }
                        None => gather_pieces(&pieces, weighting, kernel, sums, &mut [], control)?,
                    }
                }
            };
            for (f, e) in found.iter_mut().zip(each) {
                *f += e;
            }
        }
        if let Some(mut on_gpu) = on_gpu {
            // Every chunk's work goes to the GPU before the first is read back, its snapshots'
            // copies and the sums' in one submission.
            if sums.len() > 1 || self.spread.is_some() {
                on_gpu.submit_all()?;
            }
            if let Some(spread) = self.spread.as_mut() {
                snapshots.tell(&mut on_gpu, sums, spread, control)?;
            }
            for (c, sums) in sums.iter_mut().enumerate() {
                read[c] += on_gpu.read_into(c, sums)?;
            }
        }
        for (f, r) in found.iter_mut().zip(read) {
            *f += r;
        }
        Ok((found, t.elapsed().as_secs_f64()))
    }
}

/// The most bytes of snapshots of a render's sums on the GPU before they are read back.
const MAX_SNAPSHOT_BYTES: u64 = 256 << 20;

/// The pieces whose snapshots are taken on the GPU and not read yet, chunk by chunk (each its
/// pieces in order), and each chunk's sums after the pieces read before (the sums as they were,
/// before any).
struct Snapshots {
    pieces: Vec<Vec<PieceSpec>>,
    after: Vec<Option<Vec<Vec3>>>,
}

impl Snapshots {
    fn new(chunks: usize) -> Self {
        Snapshots { pieces: vec![Vec::new(); chunks], after: vec![None; chunks] }
    }

    /// Reads the snapshots back, chunk after chunk (the pieces' order), and tells the spread
    /// each piece's sums: its chunk's sums as they were plus the GPU's after it, less those
    /// before it, added pixel by pixel as the chunk's one reading back adds them (the same
    /// bits as a reading after each piece).
    fn tell(
        &mut self,
        on_gpu: &mut OnGpu,
        sums: &[&mut [Vec3]],
        spread: &mut GroupSpread,
        control: Control,
    ) -> Result<()> {
        for (c, pieces) in self.pieces.iter_mut().enumerate() {
            if pieces.is_empty() {
                continue;
            }
            let before = self.after[c].get_or_insert_with(|| sums[c].to_vec());
            let mut after = vec![Vec3::ZERO; before.len()];
            let mut next = pieces.drain(..);
            on_gpu.read_snapshots(c, &mut |bits| {
                let Some((k, planes, quarter, half)) = next.next() else { return };
                for ((a, s), v) in after.iter_mut().zip(sums[c].iter()).zip(bits) {
                    *a = *s + crate::gpu::sums_of_bits(v);
                }
                spread.add((k, quarter, half, planes.len()), before, &after, control);
                std::mem::swap(before, &mut after);
            })?;
            debug_assert!(next.next().is_none(), "a snapshot for every piece");
        }
        Ok(())
    }
}

/// How the error image tells a gathering's pieces apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Apart {
    /// Not at all: no error image.
    No,
    /// Each piece its chunk's only one in the gathering, its sums its chunk's after less before
    /// (on the GPU, where the sums stay until read back).
    Pieces,
    /// The pieces of one group in one chunk, each adding its own sums to its half's as it adds
    /// them to the chunk's (the taps of [`gather_pieces`]: on the CPU).
    Group,
}

/// The gatherings of `pieces` (each its chunk and spec by `key`), in order: runs of consecutive
/// pieces that hold at most `sets_at_once` ray sets, told apart for the error image as `apart`
/// says.
fn gatherings<T>(
    pieces: &[T],
    key: impl Fn(&T) -> (usize, &PieceSpec),
    sets_at_once: usize,
    apart: Apart,
) -> Vec<&[T]> {
    let mut out = Vec::new();
    let mut start = 0;
    let (mut sets, mut chunks) = (Vec::new(), Vec::new());
    for (i, piece) in pieces.iter().enumerate() {
        let (c, spec) = key(piece);
        let new_set = !sets.contains(&spec.0);
        let split = match apart {
            Apart::No => false,
            Apart::Pieces => chunks.contains(&c),
            Apart::Group => {
                let (first_chunk, first) = key(&pieces[start]);
                (first_chunk, first.0, first.2) != (c, spec.0, spec.2)
            }
        };
        if (new_set && sets.len() == sets_at_once) || split {
            out.push(&pieces[start..i]);
            start = i;
            sets.clear();
            chunks.clear();
        }
        if !sets.contains(&spec.0) {
            sets.push(spec.0);
        }
        chunks.push(c);
    }
    if start < pieces.len() {
        out.push(&pieces[start..]);
    }
    out
}

/// The windows of a render's chunks `chunks`, each gathered at once, every chunk into its own
/// sums. On the raster, [`crate::raster::chunks_at_once`] chunks a window, in one parallel
/// loop (several on many workers and a small image). On the GPU, one chunk, then each window
/// twice the one before, up to [`GPU_CHUNKS_AT_ONCE`] ([`gpu_windows`]). One chunk a window on
/// the other structures.
fn windows(scene: &Scene, opts: &RenderOptions, chunks: Range<usize>) -> Vec<Range<usize>> {
    let cam = &scene.camera;
    let at_once = match opts.structure() {
        Accelerator::Raster => crate::raster::chunks_at_once(crate::schedule::workers(), cam.width, cam.height),
        Accelerator::Gpu(_) => {
            let most = crate::limits::MAX_WINDOW_PIXELS / (cam.width as usize * cam.height as usize).max(1);
            return gpu_windows(chunks, GPU_CHUNKS_AT_ONCE.min(most));
        }
        _ => 1,
    };
    chunks.clone().step_by(at_once).map(|c| c..(c + at_once).min(chunks.end)).collect()
}

/// The most chunks of a window on the GPU. Each window costs about a millisecond that nothing
/// hides (its sums widened and added into the canonical tree, the join of its gathering and
/// the next window's preparation): 40 windows of one chunk in a render of 655,360 planes on an
/// H200 (docs/measurements/2026-11-28-h200-trace.log).
const GPU_CHUNKS_AT_ONCE: usize = 4;

/// The GPU's windows of `chunks`: one chunk (its preparation is hidden by nothing: the render
/// starts gathering soon), then each window twice the one before (its preparation hidden by
/// the gathering of the window before, of half its chunks), up to `most` chunks.
fn gpu_windows(chunks: Range<usize>, most: usize) -> Vec<Range<usize>> {
    let (mut out, mut size, mut start) = (Vec::new(), 1, chunks.start);
    while start < chunks.end {
        let end = (start + size).min(chunks.end);
        out.push(start..end);
        (start, size) = (end, (2 * size).min(most.max(1)));
    }
    out
}

/// `buf` as `f(i)` for `i` in `0..n`, written in parallel ([`Control::map_units`]): in place
/// where it has that length (an earlier chunk's buffer, whose pages are already faulted in),
/// else a fresh one (`vec![Vec3::ZERO; n]` writes every value on one thread: 9 ms for a window
/// of eight chunks at 640x360).
fn filled<T: Send>(buf: &mut Vec<T>, n: usize, unit: usize, control: Control, f: impl Fn(usize) -> T + Sync + Send) {
    if buf.len() == n {
        control.fill_units("partial", buf, unit, f);
    } else {
        *buf = control.map_units("partial", n, unit, f);
    }
}

/// The pieces of a window's chunks (`specs`, chunk by chunk) taken from `prepared` if they are
/// there, else sampled and prepared now, the chunks side by side (two halves at a time: the
/// two sides of a join, so that a chunk's serial steps run beside another's), with the seconds
/// spent sampling and building.
fn prepare_window(
    scene: &Scene,
    opts: &RenderOptions,
    prepared: &[(Range<usize>, Arc<PreparedPlanes>)],
    specs: &[Vec<PieceSpec>],
    control: Control,
) -> (Result<Vec<Vec<Piece>>>, (f64, f64)) {
    if specs.len() <= 1 {
        let mut preparer = Preparer { windowed: true, ..Preparer::new(scene, opts, prepared) };
        let ready = specs.first().map(|s| preparer.pieces(s.clone(), control).map(|p| vec![p]));
        return (ready.unwrap_or(Ok(Vec::new())), (preparer.seconds_sampling, preparer.seconds_build));
    }
    let (left, right) = specs.split_at(specs.len() / 2);
    let ((a, sa), (b, sb)) = control.join(
        |control| prepare_window(scene, opts, prepared, left, control),
        |control| prepare_window(scene, opts, prepared, right, control),
    );
    let ready = a.and_then(|mut a| {
        a.extend(b?);
        Ok(a)
    });
    (ready, (sa.0 + sb.0, sa.1 + sb.1))
}

impl<'a> Gatherer<'a> {
    fn new(scene: &'a Scene, opts: &'a RenderOptions, control: Control<'a>, keep: Keep) -> Self {
        let rays = RaySets::new(opts.seed, opts.ray_sets(), opts.pixel_center, keep);
        let pixels = scene.camera.width as usize * scene.camera.height as usize;
        let spread = opts.stderr.then(|| GroupSpread::new(pixels));
        Gatherer { scene, opts, control, rays, stats: RenderStats::new(opts), spread }
    }

    /// The preparer of pieces, with `prepared` pieces to take.
    fn preparer<'g>(&self, prepared: &'g [(Range<usize>, Arc<PreparedPlanes>)]) -> Preparer<'g>
    where
        'a: 'g,
    {
        Preparer::new(self.scene, self.opts, prepared)
    }

    /// The gathering side, with `weighting`.
    fn gather_side(&mut self, weighting: Weighting) -> GatherSide<'_> {
        GatherSide { scene: self.scene, opts: self.opts, weighting, rays: &mut self.rays, spread: &mut self.spread }
    }

    /// Gathers each piece along its ray set with the options' weighting, adding into `sums`
    /// (f32, each plane weighted 1), one piece prepared at a time (its planes sampled now).
    fn gather(&mut self, specs: impl IntoIterator<Item = PieceSpec>, sums: &mut [Vec3]) -> Result<()> {
        let control = self.control;
        for spec in specs {
            let mut preparer = self.preparer(&[]);
            let pieces = preparer.pieces([spec], control)?;
            let (sampling, build) = (preparer.seconds_sampling, preparer.seconds_build);
            self.stats.seconds_sampling += sampling;
            self.stats.seconds_build += build;
            let (s, seconds) = self.gather_side(self.opts.weighting).gather(&[pieces], &mut [&mut *sums], control)?;
            self.stats.add_gather(s[0], seconds);
        }
        self.count_rays();
        Ok(())
    }

    /// The rays of the sets asked for so far, and the time spent making sets, into the
    /// statistics.
    fn count_rays(&mut self) {
        (self.stats.rays, self.stats.seconds_rays) = (self.rays.camera_rays, self.rays.seconds);
    }
}

/// Renders canonical chunks of one render ([`crate::partial`]) and adds them along the
/// canonical tree: the render, the chunk ranges of other machines, and the table's renders.
pub struct ChunkRenderer<'a> {
    gatherer: Gatherer<'a>,
    fingerprint: String,
    /// Pieces prepared ahead (the table's, gathered with several weightings), in plane order.
    prepared: Vec<(Range<usize>, Arc<PreparedPlanes>)>,
}

impl<'a> ChunkRenderer<'a> {
    /// A renderer that samples each chunk's planes while it gathers the chunk before, and keeps
    /// the last two ray sets (chunks go in plane order, so each set is made once).
    pub fn new(scene: &'a Scene, opts: &'a RenderOptions, control: Control<'a>) -> Self {
        ChunkRenderer {
            gatherer: Gatherer::new(scene, opts, control, Keep::Last),
            fingerprint: fingerprint(scene, opts),
            prepared: Vec::new(),
        }
    }

    /// A renderer with every piece of the render's planes prepared now and every ray set kept,
    /// for gathering them with several weightings ([`ChunkRenderer::render_with`]).
    /// [`Error::Cancelled`] once `control` is cancelled.
    pub fn prepared(scene: &'a Scene, opts: &'a RenderOptions, control: Control<'a>) -> Result<Self> {
        let mut r = ChunkRenderer {
            gatherer: Gatherer::new(scene, opts, control, Keep::All),
            fingerprint: fingerprint(scene, opts),
            prepared: Vec::new(),
        };
        let specs: Vec<_> = chunks(opts.planes).into_iter().flat_map(|c| r.chunk_pieces(c)).collect();
        let mut preparer = Preparer { windowed: true, ..r.gatherer.preparer(&[]) };
        let ready = preparer.pieces(specs, control)?;
        let (sampling, build) = (preparer.seconds_sampling, preparer.seconds_build);
        r.gatherer.stats.seconds_sampling += sampling;
        r.gatherer.stats.seconds_build += build;
        // Every ray set now, as the planes: the table counts them as shared work, not as the
        // first weighting's gathering.
        for piece in &ready {
            r.gatherer.rays.rays(scene, piece.spec.0, control);
        }
        r.prepared = ready.into_iter().map(|p| (p.spec.1, p.planes)).collect();
        r.gatherer.count_rays();
        Ok(r)
    }

    /// What the renderer measured so far.
    pub fn stats(&self) -> &RenderStats {
        &self.gatherer.stats
    }

    /// The pieces of the planes `range` (a chunk): each its share of a plane group.
    fn chunk_pieces(&self, range: Range<usize>) -> Vec<PieceSpec> {
        let opts = self.gatherer.opts;
        let sets = opts.ray_sets();
        pieces(opts.planes, sets, range).map(|(k, half, p)| (k, p, quarter_of(k, sets), half)).collect()
    }

    /// The planes of canonical chunk `c`.
    fn chunk_range(&self, c: usize) -> Range<usize> {
        c * CHUNK_PLANES..((c + 1) * CHUNK_PLANES).min(self.gatherer.opts.planes)
    }

    /// The partial of planes `range`, a union of consecutive canonical chunks, added along the
    /// canonical tree restricted to them (a node of the whole tree when the range is one).
    pub fn render(&mut self, range: Range<usize>) -> Result<Partial> {
        self.render_with(self.gatherer.opts.weighting, range)
    }

    /// [`ChunkRenderer::render`] with another weighting than the options' (the same planes,
    /// the same rays: the table).
    pub fn render_with(&mut self, weighting: Weighting, range: Range<usize>) -> Result<Partial> {
        self.render_from(weighting, range, Vec::new(), &mut |_, _| Ok(()), None)
    }

    /// [`ChunkRenderer::render_with`] resumed from `held`, the nodes an earlier render of the
    /// same planes held after its first chunks (what its `observer` was last given; empty to
    /// start afresh), telling `observer` the nodes held after each further chunk (with an error
    /// image, after each window of chunks, whose end alone the spread agrees with). The chunks
    /// go in order and each node is added as soon as its right child is (the canonical tree's
    /// post-order, [`frontier`]), so wherever the render was resumed the result is the bits
    /// of one uninterrupted render. `beside_last` runs beside the last window's gathering, on
    /// the side that has no next window to prepare (not at all where no window is left).
    fn render_from(
        &mut self,
        weighting: Weighting,
        range: Range<usize>,
        mut held: Vec<Partial>,
        observer: ChunkObserver,
        mut beside_last: Beside,
    ) -> Result<Partial> {
        let root = chunk_indices(self.gatherer.opts.planes, &range)?;
        let control = self.gatherer.control;
        control.check()?;
        let done = self.resumed_chunks(&root, &held)?;
        let (scene, opts) = (self.gatherer.scene, self.gatherer.opts);
        let pixels = scene.camera.width as usize * scene.camera.height as usize;
        // The chunks go in windows ([`windows`]), each gathered at once (every chunk into its
        // own sums: the same bits) while the next window is prepared (its planes sampled,
        // projected and binned, its chunks side by side): the two sides of a join, so that the
        // workers a window's last tiles leave idle prepare the next.
        let windows = windows(scene, opts, done..root.end);
        let specs: Vec<Vec<Vec<PieceSpec>>> =
            windows.iter().map(|w| w.clone().map(|c| self.chunk_pieces(self.chunk_range(c))).collect()).collect();
        let first = crate::trace::span("first window prepared");
        let mut next = match specs.first() {
            Some(first) => Some(self.prepare(first, control)?),
            None => None,
        };
        drop(first);
        // The buffers of the chunks' f32 and f64 sums, reused from window to window.
        let mut spare: (Vec<Vec<Vec3>>, Vec<Vec<DVec3>>) = (Vec::new(), Vec::new());
        for (w, window) in windows.iter().enumerate() {
            let start = Instant::now();
            let (work, (sampling, build)) = next.take().expect("the window's pieces, prepared before");
            let following = specs.get(w + 1);
            let beside = if w + 1 == windows.len() { beside_last.take() } else { None };
            let prepared = &self.prepared;
            let mut side = self.gatherer.gather_side(weighting);
            let width = scene.camera.width as usize;
            let mut sums: Vec<Vec<Vec3>> = (0..window.len()).map(|_| spare.0.pop().unwrap_or_default()).collect();
            let mut wide: Vec<Vec<DVec3>> = (0..window.len()).map(|_| spare.1.pop().unwrap_or_default()).collect();
            let (gathered, upcoming) = control.join(
                |control| {
                    for s in &mut sums {
                        filled(s, pixels, width * 16, control, |_| Vec3::ZERO);
                    }
                    let mut targets: Vec<&mut [Vec3]> = sums.iter_mut().map(|s| s.as_mut_slice()).collect();
                    let gathering = crate::trace::span("window gathered");
                    let found = side.gather(&work, &mut targets, control)?;
                    drop(gathering);
                    // The window's planes freed and its sums widened to f64 here, beside the
                    // next window's preparation, not between the windows; and the two beside
                    // each other (on lavapipe at 640x360, freeing the GPU buffers of a render's
                    // 16 pieces took 3 to 6 ms, nearly all in the one drop that empties a block
                    // of the allocator's memory; widening one chunk's sums about 4 ms).
                    control.join(
                        |_| {
                            let _s = crate::trace::span("window's planes freed");
                            drop(work);
                        },
                        |control| {
                            let _s = crate::trace::span("window's sums widened");
                            for (wide, sums) in wide.iter_mut().zip(&sums) {
                                filled(wide, pixels, width * 16, control, |p| sums[p].as_dvec3());
                            }
                        },
                    );
                    Ok::<_, Error>(found)
                },
                |control| {
                    let next = {
                        let _s = crate::trace::span("next window prepared");
                        following.map(|specs| prepare_window(scene, opts, prepared, specs, control))
                    };
                    if let Some(beside) = beside {
                        beside(control);
                    }
                    next
                },
            );
            let (stats, seconds) = gathered?;
            spare.0 = sums;
            self.gatherer.stats.seconds_sampling += sampling;
            self.gatherer.stats.seconds_build += build;
            let total = stats.iter().fold(GatherStats::default(), |mut a, &b| {
                a += b;
                a
            });
            self.gatherer.stats.add_gather(total, seconds);
            self.gatherer.count_rays();
            let seconds = start.elapsed().as_secs_f64() / window.len() as f64;
            for ((c, sums), stats) in window.clone().zip(wide).zip(stats) {
                let range = self.chunk_range(c);
                held.push(Partial {
                    width: scene.camera.width,
                    height: scene.camera.height,
                    sums,
                    start: range.start,
                    end: range.end,
                    planes_total: opts.planes,
                    fingerprint: self.fingerprint.clone(),
                    hits: stats.hits,
                    seconds,
                    devices: Devices::one(opts.device_label()),
                });
                // The nodes this chunk completes, the innermost first.
                let alive = frontier(root.clone(), c + 1).len();
                while held.len() > alive {
                    let right = held.pop().expect("a right child");
                    let left = held.pop().expect("its left sibling");
                    held.push(combine_in(left, &right, control)?);
                    // Its buffer is a later chunk's (fresh pages cost their faults again).
                    spare.1.push(right.sums);
                }
                // With an error image the nodes are told at the window's end alone: its
                // gathering added every chunk's groups to the spread, which only then is the
                // nodes' (told after each chunk, a checkpoint saved a spread a window ahead of
                // its nodes, and a kill between two chunks' files left one the resume refused).
                if self.gatherer.spread.is_none() || c + 1 == window.end {
                    observer(&held, self.gatherer.spread.as_ref())?;
                }
            }
            // The next window's preparation failed (cancelled) only now that this one's chunks
            // are told.
            next = match upcoming {
                Some((ready, seconds)) => Some((ready?, seconds)),
                None => None,
            };
        }
        Ok(held.pop().expect("the root node, checked or made above"))
    }

    /// Prepares a window's chunks now (not beside a gathering), with the seconds it spent
    /// sampling and building.
    fn prepare(&mut self, specs: &[Vec<PieceSpec>], control: Control) -> Result<Window> {
        let (scene, opts) = (self.gatherer.scene, self.gatherer.opts);
        let (ready, seconds) = prepare_window(scene, opts, &self.prepared, specs, control);
        Ok((ready?, seconds))
    }

    /// The end of the chunks that `held` covers, if it is what this render of chunks `root`
    /// holds after them: partials of this render and image size over exactly the nodes of
    /// [`frontier`].
    fn resumed_chunks(&self, root: &Range<usize>, held: &[Partial]) -> Result<usize> {
        let (planes, cam) = (self.gatherer.opts.planes, &self.gatherer.scene.camera);
        let done = held.last().map_or(root.start, |p| p.end.div_ceil(CHUNK_PLANES));
        let expected = frontier(root.clone(), done);
        let pixels = cam.width as usize * cam.height as usize;
        let ours = |p: &Partial, chunks: &Range<usize>| {
            p.fingerprint == self.fingerprint
                && p.planes_total == planes
                && (p.width, p.height) == (cam.width, cam.height)
                && p.sums.len() == pixels
                && (p.start..p.end) == chunk_planes(planes, chunks)
        };
        if held.len() != expected.len() || !held.iter().zip(&expected).all(|(p, c)| ours(p, c)) {
            let planes_range = chunk_planes(planes, root);
            return Err(Error::Partial(format!(
                "the partials to resume from are not what a render of planes {}:{} holds after its first chunks",
                planes_range.start, planes_range.end
            )));
        }
        Ok(done)
    }
}

/// What runs beside a render's last window's gathering, with the control of its side
/// ([`ChunkRenderer::render_from`]).
type Beside<'b> = Option<&'b mut (dyn FnMut(Control) + Send)>;

/// What a render tells its caller after each finished chunk (with an error image, after each
/// window of chunks gathered at once, where the spread is the nodes'): the nodes it holds then
/// ([`frontier`]: consecutive partials from its first plane), for a checkpoint to save or a
/// running image to add up ([`crate::partial::RunningImage`]), and the spread of its plane
/// groups so far when it makes an error image. An error stops the render.
pub type ChunkObserver<'o> = &'o mut dyn FnMut(&[Partial], Option<&GroupSpread>) -> Result<()>;

/// Renders the scene: the mean over each pixel of the direct emission (integrated over the
/// pixel, [`crate::emission`]) plus the photon-plane estimate of single scattering, each plane
/// gathered with one of the `spp` ray sets (docs/mathematics.md section 8). Reports each tile
/// and piece of planes (or chunk of rays) to `control`; once another thread cancels it, the work stops within
/// a plane (or a ray) and the result is [`Error::Cancelled`].
///
/// The planes are rendered in the canonical chunks of [`crate::partial`] and added along its
/// canonical tree, so that the same chunks rendered anywhere and merged give this image bit for
/// bit; two windows of chunks' planes exist at a time (one gathered while the next is prepared:
/// [`crate::raster::chunks_at_once`]).
pub fn render(scene: &Scene, opts: &RenderOptions, control: Control) -> Result<(Film, RenderStats)> {
    render_from(scene, opts, control, Resume::default(), &mut |_, _| Ok(()))
}

/// [`render`] resumed from `resume` (nothing: from the start), telling `observer` the nodes it
/// holds after each further chunk (with an error image, after each window of chunks gathered
/// at once, where the spread is theirs) and the spread of its plane groups (a checkpoint,
/// [`crate::partial::checkpoint`]; a live view). The image is [`render`]'s bit for bit,
/// wherever it was resumed, and so is the error image when the spread was kept; the
/// statistics count this call's planes and work. Refuses held nodes that are not what this
/// render holds after some chunks, and a resumed render with an error image but no spread (or
/// a spread of other planes) to resume it from.
pub fn render_from(
    scene: &Scene,
    opts: &RenderOptions,
    control: Control,
    resume: Resume,
    observer: ChunkObserver,
) -> Result<(Film, RenderStats)> {
    let start = Instant::now();
    let resumed = resume.held.last().map_or(0, |p| p.end);
    let mut chunks = ChunkRenderer::new(scene, opts, control);
    if opts.stderr && resumed > 0 {
        let pixels = scene.camera.width as usize * scene.camera.height as usize;
        match resume.spread {
            Some(s) if s.check(pixels, opts.ray_sets(), resumed).is_ok() => chunks.gatherer.spread = Some(s),
            _ => {
                return Err(Error::Partial(format!(
                    "an error image cannot be resumed after {resumed} planes without the spread of their plane groups"
                )));
            }
        }
    }
    // The direct emission (its own parallel loop over the pixels) beside the last window's
    // gathering: on the GPU in the CPU's wait for the GPU, on the CPU in the workers that the
    // window's last tiles leave idle (it was a serial phase after the chunks). On the GPU the
    // gather's pipelines are made beside the first window's preparation (one task: the
    // preparation keeps the other workers).
    let emission = |control: Control| {
        let t = Instant::now();
        let _s = crate::trace::span("direct emission");
        let e = direct_emission_and_variance_in(scene, opts.seed, opts.spp, opts.pixel_center, control);
        (e, t.elapsed().as_secs_f64())
    };
    let (mut emitted, mut compiled) = (None, Ok(()));
    let chunks_rendered = crate::trace::span("chunks rendered");
    let mut emit = |control: Control| emitted = Some(emission(control));
    let partial = if matches!(opts.structure(), Accelerator::Gpu(_)) {
        rayon::in_place_scope(|s| {
            s.spawn(|_| compiled = opts.structure().compile(opts.weighting));
            chunks.render_from(opts.weighting, 0..opts.planes, resume.held, observer, Some(&mut emit))
        })
    } else {
        chunks.render_from(opts.weighting, 0..opts.planes, resume.held, observer, Some(&mut emit))
    };
    drop(chunks_rendered);
    let partial = partial?;
    compiled?;
    let ((emission, emission_variance), seconds_emission) = emitted.unwrap_or_else(|| emission(control));
    let (mut stats, spread) = (chunks.gatherer.stats, chunks.gatherer.spread);
    stats.planes = opts.planes - resumed;
    stats.devices = partial.devices.clone();
    stats.seconds_rays += seconds_emission;
    let t = Instant::now();
    let film = {
        let _s = crate::trace::span("image finished");
        crate::partial::finish_with(scene, opts, &partial, &emission)?
    };
    if let Some(mut spread) = spread {
        spread.close(control);
        stats.add_error_image(&film, spread.variance(&emission_variance), &emission_variance)?;
    }
    stats.seconds_rays += t.elapsed().as_secs_f64();
    stats.seconds_total = start.elapsed().as_secs_f64();
    crate::trace::print();
    Ok((film, stats))
}

/// Which quarter of a render's plane groups group `g` of `groups` (in plane order) is in
/// (section 10.2): consecutive groups make each quarter, so that the first half of the planes
/// is the first two. With fewer than four groups, each half's groups go to its first quarter.
fn quarter_of(g: u32, groups: u32) -> usize {
    let groups = groups.max(1);
    if groups >= 4 { (4 * g / groups) as usize } else { (2 * (2 * g / groups)) as usize }
}

/// Renders planes `range` of the render `opts` describes (a union of consecutive canonical
/// chunks) into a [`Partial`], with what it measured. `control` as for [`render`].
pub fn render_chunk(
    scene: &Scene,
    opts: &RenderOptions,
    range: Range<usize>,
    control: Control,
) -> Result<(Partial, RenderStats)> {
    let start = Instant::now();
    let mut r = ChunkRenderer::new(scene, opts, control);
    let partial = r.render(range)?;
    let mut stats = r.gatherer.stats;
    stats.planes = partial.end - partial.start;
    stats.devices = partial.devices.clone();
    stats.seconds_total = start.elapsed().as_secs_f64();
    crate::trace::print();
    Ok((partial, stats))
}

/// Progress units of a render of planes `range` (a union of chunks; `0..opts.planes` for a
/// whole [`render`]): one per unit of work of every gathering over the image, one gathering per
/// piece of every chunk ([`crate::partial::gatherings`]).
pub fn progress_units(scene: &Scene, opts: &RenderOptions, range: Range<usize>) -> u64 {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let per_gathering = match opts.structure() {
        Accelerator::Raster => Tiling::for_window(w, h, schedule::workers()).count() as u64,
        other => other.units_per_gathering(w, h),
    };
    per_gathering * crate::partial::gatherings(opts.planes, opts.ray_sets(), range)
}

/// The first pass of a render on a time budget, small so that even the slowest estimator
/// measures its speed early; each further pass doubles the plane count (the passes before
/// the last keep the Sobol sampler's counts at powers of two) until the budget runs short, and
/// the last is sized from the measured time per plane.
const FIRST_PASS_PLANES: usize = 256;

/// Renders the scene within `budget` of wall time: [`render_until`] with the budget alone.
pub fn render_for(
    scene: &Scene,
    opts: &RenderOptions,
    budget: std::time::Duration,
    control: Control,
) -> Result<(Film, RenderStats)> {
    render_until(scene, opts, Until { budget: Some(budget), target_error: None }, control)
}

/// When a render in passes stops ([`render_until`]): whichever comes first.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Until {
    /// Wall time of the whole render.
    pub budget: Option<std::time::Duration>,
    /// The estimated relative RMS error of the image (docs/mathematics.md section 10.2); needs
    /// `opts.stderr`.
    pub target_error: Option<f64>,
}

/// Renders the scene in plane passes until `until`: each pass extends the plane set by the
/// next points of the sampler (for Sobol, further points of the same sequence), until the time
/// budget would not fit the next pass, or the image's estimated relative RMS error falls below
/// the target, or the target is shown to be out of reach (below the error's floor, the direct
/// emission's error, which planes do not lower; or undefined, the image being black), or the
/// plane limit is reached; [`RenderStats::stopped_by`] says which. The passes double the
/// planes; the last on a budget is sized from the measured time per plane to use what remains,
/// and with a target error no pass is larger than the decay of the planes' part of the error
/// (`1/sqrt(N)` above the floor) says is needed. The image is the estimate of the N planes gathered, N = the total over
/// passes: the same planes as a render of N planes; each pass splits its planes among the
/// `opts.spp` ray sets (fewer for small passes, taken in turn), so every plane is still
/// gathered with a ray set uniform over the pixel, and the estimate is unbiased
/// (docs/mathematics.md section 8.1). (Stopping at an error estimated from the image itself
/// can bias it by the correlation of the estimate with the image; the stopping rule only sees
/// the image-wide error, whose noise is small, section 10.2.) `opts.planes` is ignored.
/// `control` as for [`render`]: cancelled, it stops mid-pass.
pub fn render_until(
    scene: &Scene,
    opts: &RenderOptions,
    until: Until,
    control: Control,
) -> Result<(Film, RenderStats)> {
    let start = Instant::now();
    let deadline = until.budget.map(|b| b.as_secs_f64());
    let mut stopped_by = "plane limit";
    let (film, mut stats) = render_in_passes(scene, opts, control, &mut |pass| {
        if pass.planes == 0 {
            return FIRST_PASS_PLANES;
        }
        let mut next = pass.planes.min(MAX_PASS_PLANES);
        if let Some(target) = until.target_error {
            if pass.black {
                stopped_by = "black image";
                return 0;
            }
            if let Some(error) = pass.relative_error {
                if error <= target {
                    stopped_by = "target error";
                    return 0;
                }
                // The direct emission's error does not fall with the planes: below it, the
                // target is out of reach, whatever the planes (section 10.3).
                let floor = pass.error_floor.unwrap_or(0.0);
                if floor >= target {
                    stopped_by = "error floor";
                    return 0;
                }
                // The planes' part of the variance falls as 1/N, error^2 = floor^2 + c / N:
                // the planes still needed, and a tenth more.
                let ratio = (error * error - floor * floor) / (target * target - floor * floor);
                let needed = pass.planes as f64 * (ratio - 1.0) * 1.1;
                next = next.min(needed.ceil().max(FIRST_PASS_PLANES as f64) as usize);
            }
        }
        if let Some(deadline) = deadline {
            // A pass's cost is close to proportional to its planes; keep a tenth in hand.
            let remaining = deadline - start.elapsed().as_secs_f64();
            let affordable = (0.9 * remaining / pass.seconds_per_plane.max(1e-12)).floor().max(0.0) as usize;
            next = next.min(affordable);
            if next < FIRST_PASS_PLANES / 4 {
                stopped_by = "time budget";
                return 0;
            }
        }
        next
    })?;
    stats.stopped_by = Some(stopped_by);
    Ok((film, stats))
}

/// The fewest planes a pass of a render on a time budget gives each ray set it gathers with:
/// smaller passes use fewer ray sets.
const MIN_PASS_GROUP: usize = 1024;

/// The largest pass of a render on a time budget (a pass's planes are held at once; this keeps
/// them near 0.5 GB whatever the budget).
const MAX_PASS_PLANES: usize = 1 << 20;

/// Where a render in passes stands after a pass: what sizes the next.
#[derive(Clone, Copy, Debug)]
pub struct PassReport {
    /// Planes gathered so far (0 before the first pass).
    pub planes: usize,
    /// Seconds per plane of the last pass.
    pub seconds_per_plane: f64,
    /// The image's estimated relative RMS error now, with an error image
    /// (docs/mathematics.md section 10.2).
    pub relative_error: Option<f64>,
    /// The part of it that planes do not lower, the direct emission's (section 10.3).
    pub error_floor: Option<f64>,
    /// Whether the image has an error image but is black, so that its relative error is
    /// undefined (0/0).
    pub black: bool,
}

/// Renders planes in passes, each extending the set by the next planes of the sampler:
/// `next_pass(where the render stands)` sizes the next pass, 0 ends the render. The image is
/// the estimate of all the planes gathered, the same set as a render of that many planes
/// (with one pass of at least 1024 planes per ray set, the same image up to f32 summation
/// order). The ray sets are made when first needed and kept. `opts.planes` is ignored.
/// `control` as for [`render`]: cancelled, it stops mid-pass (while sampling or gathering) and
/// no further pass starts.
pub fn render_in_passes(
    scene: &Scene,
    opts: &RenderOptions,
    control: Control,
    next_pass: &mut dyn FnMut(PassReport) -> usize,
) -> Result<(Film, RenderStats)> {
    let start = Instant::now();
    let (width, height) = (scene.camera.width, scene.camera.height);
    let ray_sets = opts.ray_sets();
    // The ray sets are kept for every pass: their memory counts as that many planes'.
    let rays_as_planes = RaySets::bytes(width, height, ray_sets) / BYTES_PER_PLANE;
    check_memory(width, height, rays_as_planes).map_err(|m| Error::option(Setting::Spp, m))?;
    let mut gatherer = Gatherer::new(scene, opts, control, Keep::All);
    gatherer.stats.plane_passes = 0;
    let pixels = width as usize * height as usize;
    let t = Instant::now();
    let (emission, emission_variance) =
        direct_emission_and_variance_in(scene, opts.seed, opts.spp, opts.pixel_center, control);
    let seconds_emission = t.elapsed().as_secs_f64();
    // Each pass sums its planes in f32 weighted 1 (N is known only at the end); the passes add
    // up in f64, so that the sums stay as far from f32 overflow as a single pass's.
    let mut total = vec![DVec3::ZERO; pixels];
    let mut report =
        PassReport { planes: 0, seconds_per_plane: 0.0, relative_error: None, error_floor: None, black: false };
    let mut next_set = 0u32;
    loop {
        control.check()?;
        let next = next_pass(report).min(MAX_PLANES as usize - report.planes);
        if next == 0 {
            break;
        }
        let done = report.planes;
        check_memory(width, height, next as u64 + rays_as_planes).map_err(|m| Error::option(Setting::TimeBudget, m))?;
        let pass_start = Instant::now();
        // The pass's planes split into groups, each gathered along the next ray set in turn
        // (section 8.1): as many groups as ray sets once a pass has MIN_PASS_GROUP planes per
        // set, fewer before (a gather costs something per pixel). For the error image, the
        // pass's groups are the last two quarters, its first and second half; the passes
        // before it, the first two (section 10.2).
        let used = (next / MIN_PASS_GROUP).clamp(1, ray_sets as usize) as u32;
        if let Some(spread) = &mut gatherer.spread {
            spread.next_pass(control);
        }
        let pass = (0..used).flat_map(|g| {
            let group = plane_group(g, next, used);
            let quarter = if 2 * g < used { 2 } else { 3 };
            let set = (next_set + g) % ray_sets;
            halves(done + group.start..done + group.end)
                .into_iter()
                .filter(|(_, planes)| !planes.is_empty())
                .map(move |(half, planes)| (set, planes, quarter, half))
        });
        let mut sums = vec![Vec3::ZERO; pixels];
        gatherer.gather(pass, &mut sums)?;
        next_set = (next_set + used) % ray_sets;
        for (t, s) in total.iter_mut().zip(&sums) {
            *t += s.as_dvec3();
        }
        gatherer.stats.plane_passes += 1;
        report.planes += next;
        report.seconds_per_plane = pass_start.elapsed().as_secs_f64() / next as f64;
        if let Some(spread) = &mut gatherer.spread {
            spread.close(control);
            let image = Film::finish(width, height, &total, report.planes, &emission)?;
            let error = spread.variance(&emission_variance).map(|v| relative_rms_error(&image, &v, &emission_variance));
            report.black = matches!(error, Some(None));
            (report.relative_error, report.error_floor) = match error.flatten() {
                Some(e) => (Some(e.total), Some(e.floor)),
                None => (None, None),
            };
        }
    }
    if report.planes == 0 {
        return Err(Error::option(Setting::TimeBudget, "no plane pass was made"));
    }
    let (mut stats, spread) = (gatherer.stats, gatherer.spread);
    stats.planes = report.planes;
    let film = Film::finish(width, height, &total, report.planes, &emission)?;
    if let Some(spread) = spread {
        // Too few planes for two groups: the budget's doing here, not a plane count's.
        let variance = spread.variance(&emission_variance).ok_or_else(|| {
            Error::option(
                Setting::TimeBudget,
                format!(
                    "an error image needs planes in at least two groups, and the budget ended after {} planes in one: give a longer budget",
                    report.planes
                ),
            )
        })?;
        stats.add_error_image(&film, Some(variance), &emission_variance)?;
    }
    stats.seconds_rays += seconds_emission;
    stats.seconds_total = start.elapsed().as_secs_f64();
    crate::trace::print();
    Ok((film, stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::Accelerator;
    use crate::settings::Overrides;
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

    fn small_scene() -> Scene {
        Scene::parse(crate::scene::tests::MINIMAL, "test.toml", "test").unwrap().with_resolution(128, 96).unwrap()
    }

    /// The GPU's windows start with one chunk and double up to the most, covering the chunks
    /// once, in order.
    #[test]
    fn gpu_windows_double_from_one_chunk() {
        assert_eq!(gpu_windows(0..3, 4), [0..1, 1..3]);
        assert_eq!(gpu_windows(5..6, 4), vec![Range { start: 5, end: 6 }]);
        assert_eq!(gpu_windows(2..2, 4), []);
        assert_eq!(gpu_windows(0..4, 0), [0..1, 1..2, 2..3, 3..4], "a large image: one chunk at a time");
        for (chunks, most) in [(0..40, 4), (3..100, 4), (0..7, 2)] {
            let w = gpu_windows(chunks.clone(), most);
            assert_eq!(w.first().unwrap().len(), 1);
            assert!(w.windows(2).all(|p| p[0].end == p[1].start && p[1].len() <= (2 * p[0].len()).min(most)));
            assert_eq!((w[0].start, w.last().unwrap().end), (chunks.start, chunks.end));
        }
        assert_eq!(gpu_windows(0..40, 4).len(), 12, "655,360 planes: 12 windows, not 40");
    }

    /// A render's pieces (four chunks, three ray sets: groups that cross chunks) in gatherings:
    /// every piece once, in order; with an error image on the CPU, each gathering the whole run
    /// of one group's pieces in one chunk; on the GPU, no chunk twice; without, at most two ray
    /// sets.
    #[test]
    fn gatherings_hold_what_each_way_of_telling_pieces_apart_needs() {
        let (planes, sets) = (4 * CHUNK_PLANES, 3);
        let all: Vec<(usize, PieceSpec)> = chunks(planes)
            .into_iter()
            .enumerate()
            .flat_map(|(c, range)| {
                pieces(planes, sets, range).map(move |(k, half, p)| (c, (k, p, quarter_of(k, sets), half)))
            })
            .collect();
        let key = |(c, spec): &(usize, PieceSpec)| (*c, (spec.0, spec.2));
        assert!(all.windows(2).any(|w| key(&w[0]).1 == key(&w[1]).1 && w[0].0 != w[1].0), "a group crosses chunks");
        for apart in [Apart::No, Apart::Pieces, Apart::Group] {
            let runs = gatherings(&all, |(c, spec)| (*c, spec), RAY_SETS_PER_GATHERING, apart);
            assert_eq!(runs.concat(), all, "{apart:?}: every piece once, in order");
            for run in &runs {
                let sets: std::collections::BTreeSet<u32> = run.iter().map(|(_, s)| s.0).collect();
                let chunks: Vec<usize> = run.iter().map(|(c, _)| *c).collect();
                match apart {
                    Apart::No => assert!(sets.len() <= RAY_SETS_PER_GATHERING),
                    Apart::Pieces => assert!(chunks.iter().enumerate().all(|(i, c)| !chunks[..i].contains(c))),
                    Apart::Group => assert!(run.iter().all(|p| key(p) == key(&run[0])), "{run:?}"),
                }
            }
            if apart == Apart::Group {
                assert!(runs.windows(2).all(|w| key(w[0].last().unwrap()) != key(&w[1][0])), "whole runs");
            }
        }
    }

    #[test]
    fn cancelling_stops_a_render_after_the_work_under_way() {
        let scene = small_scene();
        let given = Overrides { planes: Some(3000), spp: Some(3), ..Overrides::default() };
        let opts = given.resolve(&scene).unwrap().options;
        // Never set: the same image as without a flag.
        let (a, _) = render(&scene, &opts, Control::none()).unwrap();
        let (b, _) = render(&scene, &opts, Control::with_cancel(&AtomicBool::new(false))).unwrap();
        assert_eq!(a, b);
        // Set before: nothing runs.
        let e = render(&scene, &opts, Control::with_cancel(&AtomicBool::new(true))).unwrap_err();
        assert!(matches!(e, Error::Cancelled) && !e.is_input(), "{e}");
        // Set when the first tile (or chunk of rays) ends: the other thread's stops within a
        // plane (or a ray), and no further unit starts.
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        for accelerator in Accelerator::ALL {
            let opts = Overrides { accelerator: Some(accelerator), ..given.clone() }.resolve(&scene).unwrap().options;
            let (cancel, units) = (AtomicBool::new(false), AtomicUsize::new(0));
            let progress = || {
                units.fetch_add(1, Ordering::Relaxed);
                cancel.store(true, Ordering::Relaxed);
            };
            let e = pool.install(|| render(&scene, &opts, Control::new(&progress, &cancel))).unwrap_err();
            assert!(matches!(e, Error::Cancelled));
            let per_pass = accelerator.units_per_gathering(scene.camera.width, scene.camera.height) as usize;
            assert!(per_pass >= 3, "{accelerator}: {per_pass} units a pass");
            assert!(
                units.load(Ordering::Relaxed) <= 2,
                "{accelerator}: {} of {per_pass} units ran",
                units.into_inner()
            );
        }
    }

    /// Resumed from what it held after any number of chunks, a render gives the bits of one
    /// uninterrupted render; what it holds is the canonical tree's frontier; anything else to
    /// resume from is refused.
    #[test]
    fn a_render_resumed_after_any_chunk_is_the_uninterrupted_render() {
        let scene = small_scene().with_resolution(24, 16).unwrap();
        let planes = 5 * CHUNK_PLANES + 100;
        let opts = Overrides { planes: Some(planes as u64), spp: Some(4), ..Overrides::default() }
            .resolve(&scene)
            .unwrap()
            .options;
        let mut snapshots: Vec<Vec<Partial>> = Vec::new();
        let (whole, _) = render_from(&scene, &opts, Control::none(), Resume::default(), &mut |held, _| {
            snapshots.push(held.to_vec());
            Ok(())
        })
        .unwrap();
        assert!(whole == render(&scene, &opts, Control::none()).unwrap().0);
        assert_eq!(snapshots.len(), 6);
        for (i, held) in snapshots.iter().enumerate() {
            let ranges: Vec<_> = held.iter().map(|p| p.start..p.end).collect();
            let nodes: Vec<_> = frontier(0..6, i + 1).iter().map(|c| chunk_planes(planes, c)).collect();
            assert_eq!(ranges, nodes, "after chunk {i}");
            let mut later = 0;
            let resume = Resume { held: held.clone(), spread: None };
            let (resumed, stats) = render_from(&scene, &opts, Control::none(), resume, &mut |_, _| {
                later += 1;
                Ok(())
            })
            .unwrap();
            assert!(resumed == whole, "resumed after chunk {i}");
            assert_eq!((later, stats.planes), (5 - i, planes - held.last().unwrap().end));
        }
        // Not a frontier: a node missing, a node of another render, a node of another size.
        let other = Overrides { seed: Some(9), planes: Some(planes as u64), spp: Some(4), ..Overrides::default() };
        let other = other.resolve(&scene).unwrap().options;
        let mut foreign = snapshots[2].clone();
        foreign[0].fingerprint = fingerprint(&scene, &other);
        let mut small = snapshots[2].clone();
        small[1].sums.pop();
        for held in [snapshots[2][1..].to_vec(), foreign, small] {
            let resume = Resume { held, spread: None };
            let e = render_from(&scene, &opts, Control::none(), resume, &mut |_, _| Ok(())).unwrap_err();
            assert!(e.to_string().contains("not what a render of planes 0:82020 holds"), "{e}");
        }
        // An observer's error stops the render with it.
        let e = render_from(&scene, &opts, Control::none(), Resume::default(), &mut |_, _| Err(Error::Cancelled))
            .unwrap_err();
        assert!(matches!(e, Error::Cancelled));
    }

    /// A render in passes, and so a render on a time budget, stops in the middle of a pass.
    #[test]
    fn cancelling_stops_a_render_in_passes_mid_pass() {
        let scene = small_scene();
        let opts = Overrides::default().resolve(&scene).unwrap().options;
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let (cancel, units) = (AtomicBool::new(false), AtomicUsize::new(0));
        let progress = || {
            units.fetch_add(1, Ordering::Relaxed);
            cancel.store(true, Ordering::Relaxed);
        };
        let control = Control::new(&progress, &cancel);
        // Passes of 4096 planes, each of 12 tiles: set after the first tile of the first pass.
        let mut passes = 0;
        let mut next = |_: PassReport| {
            passes += 1;
            4096
        };
        let e = pool.install(|| render_in_passes(&scene, &opts, control, &mut next)).unwrap_err();
        assert!(matches!(e, Error::Cancelled), "{e}");
        assert_eq!((passes, units.load(Ordering::Relaxed)), (1, 1));
        // Set between passes: the next pass gathers nothing.
        let (cancel, units) = (AtomicBool::new(false), AtomicUsize::new(0));
        let count = || {
            units.fetch_add(1, Ordering::Relaxed);
        };
        let mut next = |pass: PassReport| {
            if pass.planes > 0 {
                cancel.store(true, Ordering::Relaxed);
            }
            256
        };
        let e = render_in_passes(&scene, &opts, Control::new(&count, &cancel), &mut next).unwrap_err();
        assert!(matches!(e, Error::Cancelled));
        // The first pass's one group, in its two halves: two gatherings.
        assert_eq!(
            units.into_inner() as u64,
            2 * Accelerator::Raster.units_per_gathering(scene.camera.width, scene.camera.height)
        );
        // On a budget of an hour: the first tile ends it.
        let (cancel, units) = (AtomicBool::new(false), AtomicUsize::new(0));
        let progress = || {
            units.fetch_add(1, Ordering::Relaxed);
            cancel.store(true, Ordering::Relaxed);
        };
        let control = Control::new(&progress, &cancel);
        let hour = std::time::Duration::from_secs(3600);
        let e = pool.install(|| render_for(&scene, &opts, hour, control)).unwrap_err();
        assert!(matches!(e, Error::Cancelled) && units.into_inner() == 1, "{e}");
    }
}
