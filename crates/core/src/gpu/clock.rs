//! The GPU's timestamps of a recording's passes, where the adapter has them ([`Clock`]): three
//! a round of a gathering (its first pass's start, its gather's start, its last pass's end),
//! which the summary's GPU time and its split come from; or, with the trace on
//! (`FOGPLANES_TRACE`, [`crate::trace`]), every pass's start and end, named, so that the trace
//! can say where the GPU's time goes pass by pass and how long the GPU takes from one pass's
//! end to the next one's start. Read with the sums ([`Timestamps::read`]).

use super::TIMESTAMPS;
use super::device::Gpu;

/// wgpu's most queries in one set.
const MAX_QUERIES: usize = 4096;

/// What a pass's timestamps mark of its round, each the round's index: the round's start (its
/// first pass, or for round 0 a pass before its first, the reach or the orientations), its
/// gather's start, the round's end (its last pass).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Mark {
    pub(super) starts: Option<u32>,
    pub(super) gather: Option<u32>,
    pub(super) ends: Option<u32>,
}

/// A recording's query set and the buffers its timestamps are resolved into and read from, and
/// which query marks what.
pub(super) struct Clock {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    readback: wgpu::Buffer,
    count: u32,
    /// Every pass timed, start and end, in the order recorded (with the trace on); else only
    /// the rounds' three.
    per_pass: bool,
    passes: Vec<&'static str>,
    rounds: Vec<[u32; 3]>,
}

/// A recording's timestamps as they are read back: the buffer, each round's three queries, and
/// with the trace on each pass's name (its start and end the queries `2 i` and `2 i + 1`).
pub(super) struct Timestamps {
    pub(super) readback: wgpu::Buffer,
    rounds: Vec<[u32; 3]>,
    passes: Vec<&'static str>,
}

impl Clock {
    /// The clock of a recording of `rounds` rounds and `passes` passes in all; `None` where the
    /// adapter has no timestamps or the queries would pass one set's (the time then comes from
    /// the wall clock). Every pass is timed where the trace is on and the set holds them.
    pub(super) fn new(gpu: &Gpu, rounds: usize, passes: usize) -> Option<Clock> {
        if !gpu.has_timestamps() {
            return None;
        }
        let per_pass = crate::trace::on() && 2 * passes <= MAX_QUERIES;
        let count = if per_pass { 2 * passes } else { TIMESTAMPS as usize * rounds };
        if count == 0 || count > MAX_QUERIES {
            return None;
        }
        let set = gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("gather time"),
            ty: wgpu::QueryType::Timestamp,
            count: count as u32,
        });
        let bytes = 8 * count as u64;
        let resolve =
            gpu.scratch("timestamps", bytes, wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC);
        let readback =
            gpu.scratch("timestamps read back", bytes, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
        let rounds = if per_pass {
            vec![[0; 3]; rounds]
        } else {
            (0..rounds as u32).map(|r| [TIMESTAMPS * r, TIMESTAMPS * r + 1, TIMESTAMPS * r + 2]).collect()
        };
        Some(Clock { set, resolve, readback, count: count as u32, per_pass, passes: Vec::new(), rounds })
    }

    /// The timestamps that pass `name` writes, given what it marks of its round: with the trace
    /// on its start and end; else the round's queries it marks, if any.
    pub(super) fn pass(&mut self, name: &'static str, mark: Mark) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let (begin, end) = if self.per_pass {
            let i = 2 * self.passes.len() as u32;
            self.passes.push(name);
            for (round, slot, query) in [(mark.starts, 0, i), (mark.gather, 1, i), (mark.ends, 2, i + 1)] {
                if let Some(r) = round {
                    self.rounds[r as usize][slot] = query;
                }
            }
            (Some(i), Some(i + 1))
        } else {
            let begin = mark.starts.map(|r| TIMESTAMPS * r).or(mark.gather.map(|r| TIMESTAMPS * r + 1));
            (begin, mark.ends.map(|r| TIMESTAMPS * r + 2))
        };
        (begin.is_some() || end.is_some()).then_some(wgpu::ComputePassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: begin,
            end_of_pass_write_index: end,
        })
    }

    /// Resolves the queries into the buffer the CPU reads, at the end of the recording.
    pub(super) fn finish(self, encoder: &mut wgpu::CommandEncoder) -> Timestamps {
        encoder.resolve_query_set(&self.set, 0..self.count, &self.resolve, 0);
        encoder.copy_buffer_to_buffer(&self.resolve, 0, &self.readback, 0, 8 * self.count as u64);
        Timestamps { readback: self.readback, rounds: self.rounds, passes: self.passes }
    }
}

impl Timestamps {
    /// From the timestamps `ts` read back (`period` nanoseconds a tick): the rounds' GPU time,
    /// and of it the gathers' and their reductions'; each pass's time, and the time between
    /// consecutive passes, added to the trace's table. A driver's timestamps out of order count
    /// 0, not 2^64 ticks.
    pub(super) fn read(&self, ts: &[u64], period: f64) -> (u64, u64) {
        let ns = |from: u32, to: u32| match (ts.get(from as usize), ts.get(to as usize)) {
            (Some(&from), Some(&to)) => (to.saturating_sub(from) as f64 * period) as u64,
            _ => 0,
        };
        let (mut all, mut gather) = (0, 0);
        for &[start, gathered, end] in &self.rounds {
            all += ns(start, end);
            gather += ns(gathered, end);
        }
        for (i, &pass) in self.passes.iter().enumerate() {
            let i = 2 * i as u32;
            crate::trace::device_pass(pass, ns(i, i + 1));
            if i > 0 {
                crate::trace::device_pass(crate::trace::BETWEEN_PASSES, ns(i - 1, i));
            }
        }
        (all, gather)
    }
}
