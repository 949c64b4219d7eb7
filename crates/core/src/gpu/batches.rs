//! How a gathering's planes are cut for the GPU: into batches of consecutive planes, each binned
//! on its own (`bin.wgsl`, its loops bounded by [`BATCH_PLANES`]), and the batches into rounds,
//! each round's work items gathered in one dispatch and added to the image by one reduction
//! (`gather.wgsl`), so that a gathering of many small batches (a window's pieces, joined) fills
//! the GPU with one dispatch rather than one each. Plain data, made on the CPU.

use super::records::ITEM_BYTES;
use super::{BATCH_PLANES, BATCH_SEGMENTS, item_planes};
use std::ops::Range;

/// The most planes of a round: the reduction counts a tile's hits and tests of a round in a
/// u32, at most 256 pixels times these.
pub const ROUND_PLANES: u64 = 1 << 22;

/// The most batches of a round: the reduction's loop over them (and llvmpipe's limit on a
/// loop's iterations, docs/gpu.md) stays short.
pub const ROUND_BATCHES: usize = 64;

/// One batch of planes: binned together.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Batch {
    pub(super) first: u32,
    pub(super) count: u32,
    /// A bound on its (tile, plane) pairs, the tiles' lists' total length
    /// ([`super::ScreenReach`]).
    pub(super) pairs: u64,
    /// Its segments (at most [`BATCH_SEGMENTS`]): runs of its planes along one ray set each, as
    /// (the segment's first plane, from the batch's first; where its ray set begins in the
    /// gathering's rays, in floats). One for a structure's own batch; a join's batches hold
    /// several of its parts'.
    pub(super) segments: Vec<(u32, u32)>,
}

/// `batches` (consecutive, each one segment or more) merged where they fit one batch together:
/// at most [`BATCH_PLANES`] planes and [`BATCH_SEGMENTS`] segments, whose work items fit one
/// binding alone (a join's pieces binned in one batch, not one each).
pub(super) fn merged(batches: Vec<Batch>, bounds: &Bounds) -> Vec<Batch> {
    let mut out: Vec<Batch> = Vec::new();
    for b in batches {
        match out.last_mut() {
            Some(m)
                if m.first + m.count == b.first
                    && (m.count + b.count) as usize <= BATCH_PLANES
                    && m.segments.len() + b.segments.len() <= BATCH_SEGMENTS
                    && bounds.round(&[(m.pairs + b.pairs, (m.segments.len() + b.segments.len()) as u64)]).is_some() =>
            {
                let at = m.count;
                m.segments.extend(b.segments.iter().map(|&(first, rays)| (first + at, rays)));
                m.count += b.count;
                m.pairs += b.pairs;
            }
            _ => out.push(b),
        }
    }
    out
}

/// Consecutive batches whose work items are gathered in one dispatch.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Round {
    pub(super) batches: Range<usize>,
    /// Their pairs: the round's lists' length, at most.
    pub(super) pairs: u64,
    /// The most planes of one of its work items ([`item_planes`] of its pairs).
    pub(super) item: u32,
    /// A bound on its work items.
    pub(super) items: u64,
}

/// What bounds the batches and rounds: the image's tiles, the adapter (a CPU adapter's work
/// items are at most 256 planes), the fixed size of a work item if any, and the GPU's largest
/// binding.
#[derive(Clone, Copy, Debug)]
pub(super) struct Bounds {
    pub(super) tiles: u64,
    pub(super) cpu: bool,
    pub(super) fixed: Option<u32>,
    pub(super) max_binding: u64,
}

impl Bounds {
    /// A bound on the work items of batches of (pairs, segments) each, cut into items of `item`
    /// planes: at most each tile's segments' one more each than their pairs over `item`.
    fn items(&self, batches: impl Iterator<Item = (u64, u64)>, item: u32) -> u64 {
        batches.map(|(p, segments)| p.min(self.tiles * segments) + p / item as u64).sum()
    }

    /// The most work items whose partial sums one binding holds.
    fn max_items(&self) -> u64 {
        self.max_binding / ITEM_BYTES
    }

    /// Whether a round of batches of (pairs, segments) each fits the GPU's bindings: its lists
    /// (4 bytes an entry) and its items' partial sums; with its items' size and bound.
    fn round(&self, batches: &[(u64, u64)]) -> Option<(u32, u64)> {
        let total: u64 = batches.iter().map(|b| b.0).sum();
        let item = item_planes(self.cpu, total, self.fixed);
        let items = self.items(batches.iter().copied(), item);
        (items <= self.max_items() && total * 4 <= self.max_binding).then_some((item, items))
    }
}

/// The batches of planes whose pairs are `pairs` (one per plane, in order): runs of consecutive
/// planes, at most [`BATCH_PLANES`], each of whose work items fit one binding alone.
pub(super) fn batches(pairs: impl Iterator<Item = u64>, bounds: &Bounds) -> Vec<Batch> {
    let mut batches: Vec<Batch> = Vec::new();
    for (i, p) in pairs.enumerate() {
        match batches.last_mut() {
            Some(b) if (b.count as usize) < BATCH_PLANES && bounds.round(&[(b.pairs + p, 1)]).is_some() => {
                b.count += 1;
                b.pairs += p;
            }
            _ => batches.push(Batch { first: i as u32, count: 1, pairs: p, segments: vec![(0, 0)] }),
        }
    }
    batches
}

/// `batches` cut into rounds of consecutive batches whose lists and items fit the GPU's
/// bindings (at most [`ROUND_PLANES`] planes and [`ROUND_BATCHES`] batches), or the one line
/// that says a batch does not fit alone (a plane that covers more of the image than a binding
/// holds).
pub(super) fn rounds(batches: &[Batch], bounds: &Bounds) -> Result<Vec<Round>, String> {
    let mut rounds: Vec<Round> = Vec::new();
    let mut pairs: Vec<(u64, u64)> = Vec::new();
    let mut planes = 0u64;
    for (i, b) in batches.iter().enumerate() {
        let this = (b.pairs, b.segments.len() as u64);
        pairs.push(this);
        let joins = rounds.last().is_some_and(|r| r.batches.end == i)
            && pairs.len() <= ROUND_BATCHES
            && planes + b.count as u64 <= ROUND_PLANES;
        match bounds.round(&pairs).filter(|_| joins) {
            Some((item, items)) => {
                let r = rounds.last_mut().expect("joins a round");
                (r.batches.end, r.pairs, r.item, r.items) = (i + 1, r.pairs + b.pairs, item, items);
                planes += b.count as u64;
            }
            None => {
                pairs.clear();
                pairs.push(this);
                planes = b.count as u64;
                let Some((item, items)) = bounds.round(&pairs) else {
                    return Err(format!(
                        "a plane covers more of this image than the GPU's buffers hold ({} bytes a binding)",
                        bounds.max_binding
                    ));
                };
                rounds.push(Round { batches: i..i + 1, pairs: b.pairs, item, items });
            }
        }
    }
    Ok(rounds)
}

/// The words of the binning's first tier (`bin.wgsl`'s `blocks`) for `batches` in an image of
/// `blocks` blocks, one batch's at a time: an offset per block and segment, the batch's end,
/// then its blocks' lists, which hold at most its (tile, plane) pairs (a plane that reaches a
/// block reaches one of its tiles). `None` where they would pass `max_binding` bytes (a batch
/// cut near that bound by its pairs): the batches are then binned in one tier.
pub(super) fn block_words(batches: &[Batch], blocks: u64, max_binding: u64) -> Option<u64> {
    let words = batches.iter().map(|b| blocks * b.segments.len() as u64 + 1 + b.pairs).max().unwrap_or(1);
    (words * 4 <= max_binding).then_some(words)
}

#[cfg(test)]
mod tests {
    use super::*;

    const BENCHMARK: Bounds = Bounds { tiles: 40 * 23, cpu: false, fixed: None, max_binding: 2 << 30 };

    /// Batches hold at most BATCH_PLANES planes, in order, every plane once; rounds hold
    /// consecutive batches, every batch once, within the bindings.
    #[test]
    fn batches_and_rounds_cover_the_planes_in_order() {
        let pairs: Vec<u64> = (0..40_000u64).map(|i| i % 97).collect();
        let bs = batches(pairs.iter().copied(), &BENCHMARK);
        assert_eq!(bs.iter().map(|b| b.count as usize).sum::<usize>(), pairs.len());
        let mut next = 0;
        for b in &bs {
            assert_eq!(b.first, next);
            assert!(b.count as usize <= BATCH_PLANES);
            let range = b.first as usize..(b.first + b.count) as usize;
            assert_eq!(b.pairs, pairs[range].iter().sum::<u64>());
            next += b.count;
        }
        let rs = rounds(&bs, &BENCHMARK).unwrap();
        assert_eq!(rs.len(), 1, "40,000 planes of a few pairs each: one round");
        assert_eq!(rs[0].batches, 0..bs.len());
        assert_eq!(rs[0].pairs, pairs.iter().sum::<u64>());
        assert_eq!(rs[0].item, item_planes(false, rs[0].pairs, None));
    }

    /// A binding that holds fewer items cuts the batches into more rounds, each within it; a
    /// plane that no binding holds alone is refused in one line.
    #[test]
    fn rounds_fit_the_binding_or_are_refused() {
        let small = Bounds { max_binding: 8_000 * ITEM_BYTES, ..BENCHMARK };
        let bs: Vec<Batch> =
            (0..6).map(|i| Batch { first: i * 1000, count: 1000, pairs: 400_000, segments: vec![(0, 0)] }).collect();
        let rs = rounds(&bs, &small).unwrap();
        assert!(rs.len() > 1);
        assert_eq!(rs.first().unwrap().batches.start, 0);
        assert_eq!(rs.last().unwrap().batches.end, bs.len());
        for w in rs.windows(2) {
            assert_eq!(w[0].batches.end, w[1].batches.start);
        }
        for r in &rs {
            assert!(r.items <= small.max_items() && r.pairs * 4 <= small.max_binding);
            let pairs: Vec<(u64, u64)> = bs[r.batches.clone()].iter().map(|b| (b.pairs, 1)).collect();
            assert_eq!(small.round(&pairs), Some((r.item, r.items)));
        }
        let tiny = Bounds { max_binding: 100 * ITEM_BYTES, ..BENCHMARK };
        let err = rounds(&bs, &tiny).unwrap_err();
        assert!(err.contains("covers more of this image"), "{err}");
    }

    /// Merged batches keep every plane in order and each segment where its planes are, within
    /// BATCH_PLANES planes and BATCH_SEGMENTS segments a batch.
    #[test]
    fn merged_batches_keep_their_segments_in_order() {
        let parts: Vec<Batch> = (0..40u32)
            .map(|i| Batch { first: i * 2_000, count: 2_000, pairs: 10_000, segments: vec![(0, 7 * i)] })
            .collect();
        let m = merged(parts.clone(), &BENCHMARK);
        assert!(m.len() > 1 && m.len() < parts.len());
        let mut next = 0;
        let mut all = Vec::new();
        for b in &m {
            assert_eq!(b.first, next);
            assert!(b.count as usize <= BATCH_PLANES && b.segments.len() <= BATCH_SEGMENTS);
            assert_eq!(b.segments[0].0, 0);
            all.extend(b.segments.iter().map(|&(first, rays)| (b.first + first, rays)));
            next += b.count;
        }
        assert_eq!(all, parts.iter().map(|p| (p.first, p.segments[0].1)).collect::<Vec<_>>());
        assert_eq!(m.iter().map(|b| b.pairs).sum::<u64>(), 400_000);
    }

    /// A round holds at most ROUND_BATCHES batches and ROUND_PLANES planes.
    #[test]
    fn rounds_are_bounded_in_batches_and_planes() {
        let bs: Vec<Batch> = (0..200).map(|i| Batch { first: i, count: 1, pairs: 1, segments: vec![(0, 0)] }).collect();
        let rs = rounds(&bs, &BENCHMARK).unwrap();
        assert!(rs.iter().all(|r| r.batches.len() <= ROUND_BATCHES));
        assert_eq!(rs.len(), 200usize.div_ceil(ROUND_BATCHES));
        let big: Vec<Batch> =
            (0..600).map(|i| Batch { first: i * 16_384, count: 16_384, pairs: 0, segments: vec![(0, 0)] }).collect();
        let rs = rounds(&big, &BENCHMARK).unwrap();
        for r in &rs {
            assert!(big[r.batches.clone()].iter().map(|b| b.count as u64).sum::<u64>() <= ROUND_PLANES);
        }
    }

    /// The first tier's words: a batch's offsets and lists, the largest batch's (its segments'
    /// offsets with its pairs); none past a binding, where a batch's pairs fill it (their lists
    /// fit it, their offsets do not).
    #[test]
    fn the_blocks_take_a_batch_at_a_time_within_a_binding() {
        let batch = |pairs: u64, segments: u32| Batch {
            first: 0,
            count: 100,
            pairs,
            segments: (0..segments).map(|s| (s, 0)).collect(),
        };
        let one = [batch(1_000, 1), batch(3_000, 1)];
        assert_eq!(block_words(&one, 60, 1 << 20), Some(60 + 1 + 3_000));
        let joined = [batch(2_000, 16), batch(500, 32)];
        assert_eq!(block_words(&joined, 60, 1 << 20), Some(60 * 16 + 1 + 2_000));
        // A binding of 1 MiB: lists of 262,144 words fill it, and their offsets pass it.
        let full = [batch(262_144, 16)];
        assert_eq!(block_words(&full, 60, 1 << 20), None);
        assert_eq!(block_words(&[batch(262_144 - 60 * 16 - 1, 16)], 60, 1 << 20), Some(262_144));
    }
}
