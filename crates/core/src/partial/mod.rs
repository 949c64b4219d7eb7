//! Partial renders: canonical chunks of the plane set, their f64 sums, and the canonical merge.
//!
//! The photon-plane estimate is linear in its planes: the image of N planes is the direct
//! emission plus `(1/N) sum_i c_i`, where `c_i` is what plane `i` adds to a pixel (its
//! contribution gathered along the camera rays it meets, section 2.3). So any split of the index
//! range `0..N` can be rendered apart and the sums added. To make the result independent of who
//! renders what, every split is made of the same pieces and added in the same order:
//!
//! - the **canonical chunks**: `0..C, C..2C, ...` with `C` = [`CHUNK_PLANES`](crate::limits::CHUNK_PLANES), a fixed power of
//!   two that depends on nothing (not on the workers, not on N); the last chunk is shorter;
//! - a chunk's sum is gathered in f32 (as a whole render gathers), each plane weighted 1, and
//!   kept as f64 ([`Partial`]);
//! - chunks are added in f64 along the **canonical tree** over chunk indices:
//!   `node(a..b) = node(a..m) + node(m..b)`, `m = a +` the largest power of two below `b - a`
//!   (pairs 0+1, 2+3, ..., then pairs of pairs, an odd one carried up); [`merge_in_canonical_order`];
//! - the whole is divided by `N` in f64, rounded to f32 once, and the direct emission added
//!   once ([`finish`], by [`Film::finish`]).
//!
//! [`crate::render::render`] itself is exactly these steps, so a render spread over machines is
//! bit-identical to a render on one, whatever the number of workers, the retries and the order
//! in which chunks complete.
//!
//! Each plane meets in its chunk exactly what it meets in a whole render: its sampler point
//! (the index in one sequence), its orientations, and the camera rays of its ray set (that of
//! its group of planes, docs/mathematics.md section 8.1, which depends on its index, N and the
//! ray set count alone). The renderers that gather chunks are in [`crate::render`].

pub mod checkpoint;
pub mod file;
pub mod parts;

use crate::control::Control;
use crate::emission::{direct_emission, direct_emission_and_variance};
use crate::error::{Error, Result};
use crate::film::{Film, first_outside};
use crate::limits::CHUNK_PLANES;
use crate::options::{Devices, RenderOptions};
use crate::pixel::plane_group;
pub use crate::sampling::stable_hash;
use crate::scene::Scene;
use crate::spread::{GroupSpread, stderr_film};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::ops::Range;

/// The canonical chunks of a set of `planes` planes, in order.
pub fn chunks(planes: usize) -> Vec<Range<usize>> {
    (0..planes).step_by(CHUNK_PLANES).map(|s| s..(s + CHUNK_PLANES).min(planes)).collect()
}

/// The canonical chunks' indices that `range` covers, if it is a union of consecutive ones.
pub fn chunk_indices(planes: usize, range: &Range<usize>) -> Result<Range<usize>> {
    let n = planes.div_ceil(CHUNK_PLANES);
    let on_boundary = |p: usize| p.is_multiple_of(CHUNK_PLANES) || p == planes;
    if range.start >= range.end || range.end > planes || !on_boundary(range.start) || !on_boundary(range.end) {
        return Err(Error::Partial(format!(
            "the plane range {}:{} is not a union of the render's chunks (of {CHUNK_PLANES} planes, from 0 to {planes})",
            range.start, range.end
        )));
    }
    Ok(range.start / CHUNK_PLANES..range.end.div_ceil(CHUNK_PLANES).min(n))
}

/// What identifies an image: the scene's geometry, medium, lights and camera (its name and
/// file do not change the image), every setting that changes the image (not the kernel, which
/// gives bit-identical images, nor the thread count), and the library's version.
pub fn fingerprint(scene: &Scene, opts: &RenderOptions) -> String {
    // How the planes are cut into pieces moves an image's f32 sums: a part or a checkpoint cut
    // as before 2026-12-02 (each group whole) is another image, refused rather than mixed in.
    const PIECES: &str = "pieces: each group in two halves";
    // So do the lobes' directions in fog that scatters forward or back (docs/mathematics.md
    // section 2.5, since 2026-12-02), and their share: a part made before them is another image
    // there. An isotropic medium's planes are as they were, whatever the share, and so are its
    // fingerprints.
    let lobes = if scene.medium.g != 0.0 { format!(" | lobes {}", opts.lobes) } else { String::new() };
    let description = format!(
        "fogplanes {} | {PIECES} | {:?} | {:?} | {:?} | planes {} | {} | seed {} | sampler {} | spp {} | centre {} | {}{lobes}",
        env!("CARGO_PKG_VERSION"),
        scene.camera,
        scene.medium,
        scene.lights,
        opts.planes,
        opts.weighting.label(),
        opts.seed,
        opts.sampler,
        opts.spp,
        opts.pixel_center,
        opts.accelerator,
    );
    stable_hash(&[description.as_bytes()])
}

/// The unnormalised sum of a plane range's contributions to every pixel: planes `start..end`
/// of a render of `planes_total`, each gathered with the rays it meets in that render, each
/// weighted 1 (each plane gathered with its ray set, so every pixel sums one estimate per plane).
#[derive(Clone, Debug, PartialEq)]
pub struct Partial {
    pub width: u32,
    pub height: u32,
    /// One per pixel, row-major.
    pub sums: Vec<DVec3>,
    pub start: usize,
    pub end: usize,
    pub planes_total: usize,
    /// [`fingerprint`] of the render the range belongs to.
    pub fingerprint: String,
    /// Ray-plane hits found.
    pub hits: u64,
    /// Wall-clock seconds spent rendering it (added up over merged parts).
    pub seconds: f64,
    /// The devices whose gathering it holds (the union over merged parts).
    pub devices: Devices,
}

impl Partial {
    fn describe(&self) -> String {
        format!("planes {}:{}", self.start, self.end)
    }

    /// The canonical chunks the planes `start..end` touch.
    fn chunk_count(&self) -> usize {
        self.end.div_ceil(CHUNK_PLANES).saturating_sub(self.start / CHUNK_PLANES)
    }

    /// The most a channel of one pixel's sums can hold (docs/mathematics.md section 9): each
    /// chunk's sums are gathered in f32, so a chunk adds at most `f32::MAX`, and `k` chunks at
    /// most `k f32::MAX` (exactly: the f64 sum of `k <= 8192` values below it is below it).
    pub fn most_per_channel(&self) -> f64 {
        self.chunk_count() as f64 * f32::MAX as f64
    }

    /// Checks what a partial holds against what a render can make, so that one given back by a
    /// file, a pickle or a caller is trusted no more than an argument: a size within the
    /// limits and sums for each pixel; a plane count within the limits, planes `start..end` a
    /// union of its canonical chunks; hits at most one per plane and pixel; seconds finite and
    /// non-negative; and every sum a number in `[0, most_per_channel]` (contributions are
    /// non-negative), naming the first that is not. Every count checked here is one that later
    /// arithmetic (the canonical tree, the division by N) trusts.
    pub fn check(&self) -> Result<()> {
        self.check_in(Control::none())
    }

    /// [`Partial::check`], its pass over the sums in parallel units of rows recorded on
    /// `control`'s strand ([`crate::schedule`]).
    pub fn check_in(&self, control: Control) -> Result<()> {
        let bad = |m: String| Err(Error::Partial(format!("{}: {m}", self.describe())));
        crate::limits::check_resolution(self.width, self.height).or_else(|m| bad(format!("its size: {m}")))?;
        let pixels = self.width as usize * self.height as usize;
        if self.sums.len() != pixels {
            return bad(format!("{} sums for {}x{} pixels", self.sums.len(), self.width, self.height));
        }
        crate::limits::check_planes(self.planes_total as u64).or_else(|m| bad(format!("its render: {m}")))?;
        chunk_indices(self.planes_total, &(self.start..self.end))?;
        let most_hits = (self.end - self.start) as u128 * pixels as u128;
        if self.hits as u128 > most_hits {
            return bad(format!("{} hits, more than one per plane and pixel ({most_hits})", self.hits));
        }
        crate::limits::check_recorded_seconds(self.seconds)
            .or_else(|m| bad(format!("its seconds of rendering: {m}")))?;
        self.devices.check().or_else(|m| bad(format!("its devices: {m}")))?;
        let most = self.most_per_channel();
        let rows = self.width as usize * 16;
        let fine = |s: &DVec3| s.to_array().iter().all(|&c| c >= 0.0 && c <= most);
        let all_fine = control
            .map_units("check", self.sums.len().div_ceil(rows), 1, |u| {
                self.sums[u * rows..((u + 1) * rows).min(self.sums.len())].iter().all(fine)
            })
            .into_iter()
            .all(|f| f);
        if all_fine {
            return Ok(());
        }
        if let Some(p) = first_outside(self.sums.iter().map(|s| s.to_array()), self.width, most) {
            let why = if p.value.is_nan() || p.value < 0.0 {
                "a sum of contributions is a non-negative number".to_string()
            } else {
                let k = self.chunk_count();
                format!("beyond {most:.4e}, the most {k} chunk{} of planes can sum to", if k == 1 { "" } else { "s" })
            };
            return bad(format!("sums: {p}: {why}"));
        }
        Ok(())
    }
}

/// Refuses two partials of different renders or sizes.
fn check_same_render(a: &Partial, b: &Partial) -> Result<()> {
    if a.fingerprint != b.fingerprint || a.planes_total != b.planes_total {
        return Err(Error::Partial(format!(
            "{} and {} belong to different renders (another scene or other settings)",
            a.describe(),
            b.describe()
        )));
    }
    if (a.width, a.height) != (b.width, b.height) || a.sums.len() != b.sums.len() {
        return Err(Error::Partial(format!("{} and {} differ in size", a.describe(), b.describe())));
    }
    Ok(())
}

/// Adds two adjacent partials of one render (`a.end == b.start`): `a.sums + b.sums` in f64,
/// into `a`'s buffer (a partial of a large image is tens of megabytes: no copy of it is made).
/// Each is checked first ([`Partial::check`]).
pub fn combine(a: Partial, b: &Partial) -> Result<Partial> {
    combine_in(a, b, Control::none())
}

/// [`combine`], its passes over the sums in parallel units of rows recorded on `control`'s
/// strand ([`crate::schedule`]).
pub fn combine_in(mut a: Partial, b: &Partial, control: Control) -> Result<Partial> {
    a.check_in(control)?;
    b.check_in(control)?;
    check_same_render(&a, b)?;
    if a.end != b.start {
        let how = if a.end > b.start { "overlap" } else { "leave a gap" };
        return Err(Error::Partial(format!("{} and {} are not adjacent: they {how}", a.describe(), b.describe())));
    }
    let rows = a.width as usize * 16;
    let section = control.section("combine");
    a.sums.par_chunks_mut(rows).zip(b.sums.par_chunks(rows)).for_each(|(x, y)| {
        section.unit(|| {
            for (x, y) in x.iter_mut().zip(y) {
                *x += *y;
            }
        })
    });
    section.close();
    a.devices.add(&b.devices);
    Ok(Partial { end: b.end, hits: a.hits.saturating_add(b.hits), seconds: a.seconds + b.seconds, ..a })
}

/// The largest power of two strictly below `n` (n >= 2): where the canonical tree splits.
pub(crate) fn split(n: usize) -> usize {
    1 << (usize::BITS - 1 - (n - 1).leading_zeros())
}

/// Merges partials given in any order into one covering their union, adding along the
/// canonical tree over chunk indices (module docs). Refuses parts that fail
/// [`Partial::check`], parts of different renders or sizes, overlapping parts, gaps and parts
/// that do not reach `0` or `N`, naming them, before adding anything. Parts that are nodes of the tree (a single chunk, or what [`crate::render::render_chunk`]
/// made of a node's chunks) give the bits of a whole render; where a part straddles a split of
/// the tree, the parts under that node are added left to right instead (equal within f64
/// rounding).
pub fn merge_in_canonical_order(mut parts: Vec<Partial>) -> Result<Partial> {
    if parts.is_empty() {
        return Err(Error::Partial("no partial renders to merge".into()));
    }
    for p in &parts {
        p.check()?;
    }
    parts.sort_by_key(|p| (p.start, p.end));
    let (first, last) = (&parts[0], &parts[parts.len() - 1]);
    if first.start != 0 {
        return Err(Error::Partial(format!("planes 0:{} are missing", first.start)));
    }
    for w in parts.windows(2) {
        check_same_render(&w[0], &w[1])?;
        if w[0].end < w[1].start {
            return Err(Error::Partial(format!("planes {}:{} are missing", w[0].end, w[1].start)));
        }
        if w[0].end > w[1].start {
            return Err(Error::Partial(format!("{} and {} overlap", w[0].describe(), w[1].describe())));
        }
    }
    if last.end != last.planes_total {
        return Err(Error::Partial(format!("planes {}:{} are missing", last.end, last.planes_total)));
    }
    let n = last.planes_total.div_ceil(CHUNK_PLANES);
    let mut parts = parts.into_iter().map(Some).collect::<Vec<_>>();
    merge_node(&mut parts, 0..n)
}

/// The canonical node over chunks `range` from the `parts` (sorted, adjacent, covering it)
/// that lie in it, taking them.
fn merge_node(parts: &mut [Option<Partial>], range: Range<usize>) -> Result<Partial> {
    // The plane counts are checked (Partial::check): no product here can wrap.
    let (lo, hi) = (range.start.saturating_mul(CHUNK_PLANES), range.end.saturating_mul(CHUNK_PLANES));
    let inside: Vec<usize> =
        (0..parts.len()).filter(|&i| parts[i].as_ref().is_some_and(|p| p.start >= lo && p.start < hi)).collect();
    if let [i] = inside[..] {
        return Ok(parts[i].take().expect("present"));
    }
    let m = range.start + split(range.len().max(2));
    let straddles = inside.iter().any(|&i| {
        parts[i]
            .as_ref()
            .is_some_and(|p| p.start < m.saturating_mul(CHUNK_PLANES) && p.end > m.saturating_mul(CHUNK_PLANES))
    });
    if range.len() >= 2 && !straddles {
        let left = merge_node(parts, range.start..m)?;
        let right = merge_node(parts, m..range.end)?;
        return combine(left, &right);
    }
    let mut taken = inside.iter().filter_map(|&i| parts[i].take());
    let first = taken.next().ok_or_else(|| Error::Partial("no partial renders to merge".into()))?;
    taken.try_fold(first, |a, b| combine(a, &b))
}

/// The pieces a set of `planes` splits into for gathering: the canonical chunks cut further
/// where a group of planes with its own ray set ends ([`crate::pixel::plane_group`]) and at
/// each group's middle ([`halves`]), in plane order, each with its ray set and its half of the
/// group. Each is one gathering over the image.
pub fn pieces(planes: usize, ray_sets: u32, range: Range<usize>) -> impl Iterator<Item = (u32, usize, Range<usize>)> {
    (0..ray_sets).flat_map(move |k| {
        let range = range.clone();
        halves(plane_group(k, planes, ray_sets)).into_iter().filter_map(move |(half, planes)| {
            let share = planes.start.max(range.start)..planes.end.min(range.end);
            (!share.is_empty()).then_some((k, half, share))
        })
    })
}

/// A group's planes in two halves (the first `n / 2`, then the rest), gathered apart so that
/// the error image can compare them: along the same ray, they differ by the planes alone
/// (docs/mathematics.md section 10.1, eq. 10.1b). Empty halves are the caller's to skip.
pub fn halves(group: Range<usize>) -> [(usize, Range<usize>); 2] {
    let middle = group.start + (group.end - group.start) / 2;
    [(0, group.start..middle), (1, middle..group.end)]
}

/// Gatherings over the image that planes `range` of a render of `planes` planes with
/// `ray_sets` ray sets make: one per piece of every chunk they cover (for sizing a progress
/// bar).
pub fn gatherings(planes: usize, ray_sets: u32, range: Range<usize>) -> u64 {
    chunks(planes)
        .into_iter()
        .filter(|c| c.start >= range.start && c.end <= range.end)
        .map(|c| pieces(planes, ray_sets, c).count() as u64)
        .sum()
}

/// Whether chunks `range` form a node of the canonical tree over `n` chunks.
pub fn is_canonical_node(range: &Range<usize>, n: usize) -> bool {
    let mut node = 0..n;
    loop {
        if node == *range {
            return true;
        }
        if node.len() < 2 {
            return false;
        }
        let m = node.start + split(node.len());
        node = if range.end <= m {
            node.start..m
        } else if range.start >= m {
            m..node.end
        } else {
            return false;
        };
    }
}

/// The nodes a render of chunks `root` holds once chunks `root.start..done` are finished, in
/// order: the nodes of the canonical tree over `root` (split as [`split`] splits, relative to
/// `root.start`) whose chunks are all finished and whose parent's are not. Chunks finish in
/// order and each node is added as soon as its right child finishes (post-order), so these are
/// exactly the partials alive at that moment: what a checkpoint saves and a running image adds
/// up. Empty before any chunk; `[root]` once all are finished.
pub fn frontier(root: Range<usize>, done: usize) -> Vec<Range<usize>> {
    fn descend(node: Range<usize>, done: usize, out: &mut Vec<Range<usize>>) {
        if node.end <= done {
            out.push(node);
        } else if node.start < done && node.len() >= 2 {
            let m = node.start + split(node.len());
            descend(node.start..m, done, out);
            descend(m..node.end, done, out);
        }
    }
    let mut out = Vec::new();
    descend(root, done, &mut out);
    out
}

/// The planes of chunks `chunks` of a render of `planes` planes.
pub fn chunk_planes(planes: usize, chunks: &Range<usize>) -> Range<usize> {
    chunks.start * CHUNK_PLANES..(chunks.end * CHUNK_PLANES).min(planes)
}

/// One step of the plan of a render spread over tasks ([`merge_plan`]): chunks `chunks`
/// rendered into one partial ([`crate::render::render_chunk`] of their planes) when `parts` is `None`, else
/// the partials of the two earlier steps `parts` (indices into the plan), left then right,
/// added ([`combine`]) into the node over `chunks`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlanStep {
    pub chunks: Range<usize>,
    pub parts: Option<(usize, usize)>,
}

/// The plan of a render of `chunks` canonical chunks spread over tasks that render at most
/// `block` chunks each (a power of two): the canonical tree's nodes in post-order (each step
/// after the two it adds; the last is the whole render), cut where a node has at most `block`
/// chunks, which one task renders. Every step is a node of the canonical tree (with `block` a
/// power of two, a leaf is an aligned block or the tail), so the sums are the bits of
/// [`crate::render::render`]. Refuses no chunks, more than a render can have, and a `block`
/// that is not a power of two.
pub fn merge_plan(chunks: usize, block: usize) -> Result<Vec<PlanStep>> {
    let most = (crate::limits::MAX_PLANES as usize).div_ceil(CHUNK_PLANES);
    if chunks == 0 || chunks > most {
        return Err(Error::Partial(format!("chunks: a render has between 1 and {most} chunks, got {chunks}")));
    }
    if !block.is_power_of_two() {
        return Err(Error::Partial(format!("block: the chunks per task must be a power of two, got {block}")));
    }
    fn node(range: Range<usize>, block: usize, steps: &mut Vec<PlanStep>) -> usize {
        let parts = (range.len() > block).then(|| {
            let m = range.start + split(range.len());
            (node(range.start..m, block, steps), node(m..range.end, block, steps))
        });
        steps.push(PlanStep { chunks: range, parts });
        steps.len() - 1
    }
    let mut steps = Vec::with_capacity(2 * chunks.div_ceil(block));
    node(0..chunks, block, &mut steps);
    Ok(steps)
}

/// The image of a render from the partial of all its planes: the sums divided by N in f64,
/// rounded to f32 once, plus the direct emission over each pixel (computed here,
/// [`crate::emission::direct_emission`]). Refuses a partial that fails [`Partial::check`], a
/// partial of another render or one that does not cover `0..N`, and an image that would hold a
/// value that is not a finite number (f32 overflow where a pixel's sums divided by N come near
/// `f32::MAX`), naming the pixel.
pub fn finish(scene: &Scene, opts: &RenderOptions, partial: &Partial) -> Result<Film> {
    finish_with(scene, opts, partial, &direct_emission(scene, opts.seed, opts.spp, opts.pixel_center))
}

/// [`finish`] with the direct emission already computed (by a render that also wants its
/// variance, [`crate::emission::direct_emission_and_variance`]).
pub fn finish_with(scene: &Scene, opts: &RenderOptions, partial: &Partial, emission: &[Vec3]) -> Result<Film> {
    partial.check()?;
    if partial.fingerprint != fingerprint(scene, opts) {
        return Err(Error::Partial(format!(
            "{} belong to another render (another scene or other settings) than the one to finish",
            partial.describe()
        )));
    }
    if partial.start != 0 || partial.end != opts.planes || partial.planes_total != opts.planes {
        return Err(Error::Partial(format!(
            "{} do not cover the render's {} planes (0:{})",
            partial.describe(),
            opts.planes,
            opts.planes
        )));
    }
    let cam = &scene.camera;
    if (partial.width, partial.height) != (cam.width, cam.height) {
        return Err(Error::Partial(format!(
            "the partial is {}x{}, the render {}x{}",
            partial.width, partial.height, cam.width, cam.height
        )));
    }
    Film::finish(cam.width, cam.height, &partial.sums, opts.planes, emission)
}

/// What a render resumes from ([`crate::render::render_from`]): the nodes an earlier render of
/// the same scene and options held after its first chunks (empty: from the start) and, with an
/// error image, the spread of its plane groups then ([`checkpoint`] keeps both).
#[derive(Clone, Debug, Default)]
pub struct Resume {
    pub held: Vec<Partial>,
    pub spread: Option<GroupSpread>,
}

/// The image of the first planes of a render while it runs (docs/mathematics.md section 8.1, "A
/// running image"): the sums of the nodes it holds ([`frontier`]) added in order, divided by
/// their plane count, plus the direct emission (computed once, here). Its last image, from the
/// one node of all N planes, is [`finish`]'s bit for bit.
pub struct RunningImage {
    width: u32,
    height: u32,
    emission: Vec<Vec3>,
    emission_variance: Vec<DVec3>,
}

impl RunningImage {
    pub fn new(scene: &Scene, opts: &RenderOptions) -> Self {
        let (width, height) = (scene.camera.width, scene.camera.height);
        let (emission, emission_variance) = direct_emission_and_variance(scene, opts.seed, opts.spp, opts.pixel_center);
        RunningImage { width, height, emission, emission_variance }
    }

    /// The error image of the running image of `planes` planes, from the plane groups closed
    /// so far (docs/mathematics.md section 10): their error, scaled to `planes` as the variance
    /// falls, as one over the planes. `None` before two groups are closed.
    pub fn stderr(&self, spread: &GroupSpread, planes: usize) -> Option<Film> {
        let closed = spread.planes() as f64;
        let variance = spread.variance(&self.emission_variance)?;
        let scale = closed / planes.max(1) as f64;
        let scattering: Vec<DVec3> =
            variance.iter().zip(&self.emission_variance).map(|(v, e)| (*v - *e) * scale + *e).collect();
        stderr_film(self.width, self.height, &scattering).ok()
    }

    /// The image of the planes that `held` (consecutive partials from plane 0) sum, or `None`
    /// before any (or if it would hold a value that is not a finite number: a live view shows
    /// nothing rather than that).
    pub fn image(&self, held: &[Partial]) -> Option<Film> {
        let (first, rest) = held.split_first()?;
        let mut sums = first.sums.clone();
        for p in rest {
            for (s, x) in sums.iter_mut().zip(&p.sums) {
                *s += *x;
            }
        }
        let planes = held.last().map_or(0, |p| p.end) - first.start;
        Film::finish(self.width, self.height, &sums, planes, &self.emission).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The frontier is what the post-order of the canonical tree holds after each chunk: a node
    /// is added as soon as its right child is, and nothing else is alive.
    #[test]
    fn the_frontier_is_what_the_post_order_holds() {
        fn walk(node: Range<usize>, held: &mut Vec<Range<usize>>, seen: &mut Vec<Vec<Range<usize>>>) {
            if node.len() == 1 {
                held.push(node);
                seen.push(held.clone());
                return;
            }
            let m = node.start + split(node.len());
            walk(node.start..m, held, seen);
            walk(m..node.end, held, seen);
            let (r, l) = (held.pop().unwrap(), held.pop().unwrap());
            assert_eq!((l.end, l.start, r.end), (r.start, node.start, node.end));
            held.push(node);
            // The snapshot after a chunk is taken once its additions are done.
            *seen.last_mut().unwrap() = held.clone();
        }
        for root in [0..1, 0..2, 0..7, 0..16, 3..12, 5..38] {
            let (mut held, mut seen) = (Vec::new(), Vec::new());
            walk(root.clone(), &mut held, &mut seen);
            assert_eq!(frontier(root.clone(), root.start), Vec::<Range<usize>>::new());
            for (i, snapshot) in seen.iter().enumerate() {
                assert_eq!(&frontier(root.clone(), root.start + i + 1), snapshot, "{root:?} after {i}");
            }
            assert_eq!(frontier(root.clone(), root.end), std::slice::from_ref(&root));
        }
        assert_eq!(frontier(0..7, 5), [0..4, 4..5]);
        assert_eq!(frontier(0..7, 6), [0..4, 4..6]);
        assert_eq!(chunk_planes(40_960, &(1..3)), 16_384..40_960);
    }

    #[test]
    fn the_canonical_tree_splits_at_the_largest_power_of_two_below() {
        assert_eq!([2, 3, 4, 5, 8, 9, 16, 17].map(split), [1, 2, 2, 4, 4, 8, 8, 16]);
        assert!(is_canonical_node(&(0..4), 7) && is_canonical_node(&(4..6), 7) && is_canonical_node(&(6..7), 7));
        assert!(!is_canonical_node(&(0..3), 7) && !is_canonical_node(&(1..3), 7) && !is_canonical_node(&(4..7), 8));
        assert!(is_canonical_node(&(4..7), 7) && is_canonical_node(&(0..7), 7));
    }

    #[test]
    fn the_merge_plan_is_canonical_nodes_in_post_order_covering_every_chunk() {
        for n in 1..=70 {
            for block in [1, 2, 4, 8, 64] {
                let plan = merge_plan(n, block).unwrap();
                let mut next = 0; // leaves come in chunk order, each after the last
                for (i, step) in plan.iter().enumerate() {
                    assert!(is_canonical_node(&step.chunks, n), "{n} {block}: {step:?}");
                    match step.parts {
                        None => {
                            assert!(!step.chunks.is_empty() && step.chunks.len() <= block, "{n} {block}: {step:?}");
                            assert_eq!(step.chunks.start, next, "{n} {block}");
                            next = step.chunks.end;
                        }
                        Some((l, r)) => {
                            assert!(l < r && r < i, "{n} {block}: step {i} adds {l} and {r}");
                            assert_eq!(plan[l].chunks.start, step.chunks.start);
                            assert_eq!(plan[l].chunks.end, plan[r].chunks.start);
                            assert_eq!(plan[r].chunks.end, step.chunks.end);
                            assert!(step.chunks.len() > block);
                        }
                    }
                }
                assert_eq!(next, n, "{n} {block}: the leaves cover 0..{n}");
                assert_eq!(plan.last().unwrap().chunks, 0..n);
                // Each step is added exactly once, except the last.
                let mut used = vec![0; plan.len()];
                for (l, r) in plan.iter().filter_map(|s| s.parts) {
                    used[l] += 1;
                    used[r] += 1;
                }
                assert!(used[..plan.len() - 1].iter().all(|&u| u == 1) && used[plan.len() - 1] == 0);
            }
        }
        // 7 chunks in blocks of 2: (0..2, 2..4 | 0..4), (4..6, 6..7 | 4..7), 0..7.
        let ranges: Vec<_> = merge_plan(7, 2).unwrap().into_iter().map(|s| s.chunks).collect();
        assert_eq!(ranges, [0..2, 2..4, 0..4, 4..6, 6..7, 4..7, 0..7]);
        assert_eq!(merge_plan(7, 2).unwrap()[6].parts, Some((2, 5)));
        for (chunks, block) in [(0, 1), (5, 0), (5, 3), (8193, 1)] {
            assert!(merge_plan(chunks, block).is_err(), "{chunks} {block}");
        }
        assert_eq!(merge_plan(8192, 1).unwrap().len(), 2 * 8192 - 1);
    }

    /// What a render can make passes; the first value or count beyond it is refused, named.
    #[test]
    fn a_partial_is_held_to_what_a_render_can_make() {
        let planes = 3 * CHUNK_PLANES;
        let valid = Partial {
            width: 2,
            height: 1,
            sums: vec![DVec3::ZERO; 2],
            start: CHUNK_PLANES,
            end: planes,
            planes_total: planes,
            fingerprint: "f".into(),
            hits: 2 * 2 * CHUNK_PLANES as u64,
            seconds: 0.5,
            devices: Devices::one("cpu"),
        };
        let most = 2.0 * f32::MAX as f64;
        assert_eq!(valid.most_per_channel(), most);
        let with = |f: &dyn Fn(&mut Partial)| {
            let mut p = valid.clone();
            f(&mut p);
            p.check().map_err(|e| e.to_string())
        };
        assert!(with(&|p| p.sums[1].z = most).is_ok());
        for (value, says) in [
            (f64::NAN, "channel B is NaN: a sum of contributions is a non-negative number"),
            (-1.0, "channel B is -1: "),
            (f64::INFINITY, "is inf: beyond 6.8056e38, the most 2 chunks"),
            (most.next_up(), "beyond"),
            (1e308, "channel B is 1e308: beyond"),
        ] {
            let e = with(&|p| p.sums[1].z = value).unwrap_err();
            assert!(e.starts_with("planes 16384:49152: sums: pixel (x 1, y 0) ") && e.contains(says), "{value}: {e}");
        }
        type Change = (fn(&mut Partial), &'static str);
        let changes: [Change; 8] = [
            (|p| p.hits += 1, "hits, more than one per plane and pixel"),
            (|p| p.planes_total = usize::MAX, "the plane count must be between"),
            (|p| (p.end, p.planes_total) = (usize::MAX, usize::MAX), "plane count"),
            (|p| p.start = 1, "not a union of the render's chunks"),
            (|p| p.width = 3, "2 sums for 3x1 pixels"),
            (|p| p.width = 0, "each side must be between"),
            (|p| p.seconds = f64::NAN, "its seconds of rendering: NaN"),
            (|p| p.devices = Devices::default(), "its devices: 0 devices named"),
        ];
        for (f, says) in changes {
            let e = with(&f).unwrap_err();
            assert!(e.contains(says), "{says}: {e}");
        }
        // The merge and the addition refuse one before adding anything.
        let first = Partial { start: 0, end: CHUNK_PLANES, hits: 0, ..valid.clone() };
        let mut bad = valid.clone();
        bad.sums[0].x = f64::NAN;
        assert!(merge_in_canonical_order(vec![first.clone(), bad.clone()]).unwrap_err().to_string().contains("NaN"));
        assert!(combine(first.clone(), &bad).is_err() && combine(first.clone(), &valid).is_ok());
        let wrapped = Partial { start: 0, end: usize::MAX, planes_total: usize::MAX, ..valid };
        assert!(merge_in_canonical_order(vec![wrapped]).unwrap_err().to_string().contains("plane count"));
    }

    #[test]
    fn chunks_cover_the_planes_in_order() {
        assert_eq!(chunks(40_960), vec![0..16_384, 16_384..32_768, 32_768..40_960]);
        assert_eq!(chunks(5), vec![0..5]);
        assert_eq!(chunk_indices(40_960, &(16_384..40_960)).unwrap(), 1..3);
        for bad in [0..0, 1..16_384, 0..40_961, 16_384..20_000] {
            assert!(chunk_indices(40_960, &bad).is_err(), "{bad:?}");
        }
    }
}
