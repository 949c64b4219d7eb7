//! A record of a render's units of work, for the schedule model (`scripts/scaling_model.py`):
//! how a render would run on more cores than this machine has.
//!
//! A render is recorded as *sections*: a section is a set of units that may run at once (the
//! items of one parallel loop, or one piece of serial code), and it starts when every section it
//! comes after has ended (a parallel loop's end is a barrier). Each unit's time is the CPU time
//! of the thread that ran it (`CLOCK_THREAD_CPUTIME_ID`), so that a render recorded with more
//! workers than cores still measures each unit alone. The model replays the sections on N
//! simulated workers.
//!
//! Only a job whose [`Control`] carries a [`Strand`] records (the one [`start`] returns): every
//! hook is otherwise a branch on an `Option`. The serial code of a strand is measured between its
//! parallel sections, on the thread that runs the strand.
//!
//! [`Control`]: crate::control::Control

use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

/// One section of a record: its units' CPU nanoseconds in the order they started.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Section {
    pub label: &'static str,
    /// The sections that must end before this one starts.
    pub after: Vec<usize>,
    /// (start order, CPU nanoseconds) of each unit.
    pub units: Vec<(u64, u64)>,
}

static SECTIONS: Mutex<Vec<Section>> = Mutex::new(Vec::new());
static STARTS: AtomicU64 = AtomicU64::new(0);

static WORKERS: AtomicUsize = AtomicUsize::new(0);

/// The workers a job cuts its work for: the current thread pool's, unless [`cut_for`] said
/// otherwise.
pub fn workers() -> usize {
    match WORKERS.load(Ordering::Relaxed) {
        0 => rayon::current_num_threads(),
        n => n,
    }
}

/// Jobs cut their work (the raster's tiles) as for `workers` workers whatever their pool
/// (`None`: for their pool's), so that a record made with few threads holds the units of a
/// larger machine, each measured without more threads than cores. The image is the same bits.
pub fn cut_for(workers: Option<usize>) {
    WORKERS.store(workers.unwrap_or(0), Ordering::Relaxed);
}

/// Starts a record (what was recorded before is dropped): the strand of a job driven from this
/// thread, for its [`Control`](crate::control::Control).
pub fn start() -> Strand {
    SECTIONS.lock().unwrap().clear();
    Strand::new()
}

/// The sections recorded since [`start`].
pub fn finish() -> Vec<Section> {
    std::mem::take(&mut *SECTIONS.lock().unwrap())
}

/// CPU nanoseconds of the calling thread so far.
pub fn thread_cpu_ns() -> u64 {
    #[cfg(unix)]
    {
        let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: clock_gettime writes the timespec it is given, and nothing else.
        if unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) } == 0 {
            return t.tv_sec as u64 * 1_000_000_000 + t.tv_nsec as u64;
        }
    }
    // Without a thread clock, wall time (right when the threads do not outnumber the cores).
    static EPOCH: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
    EPOCH.get_or_init(std::time::Instant::now).elapsed().as_nanos() as u64
}

fn push(label: &'static str, after: Vec<usize>, units: Vec<(u64, u64)>) -> usize {
    let mut s = SECTIONS.lock().unwrap();
    s.push(Section { label, after, units });
    s.len() - 1
}

/// Serial code shorter than this between two sections is left out of the record (the
/// bookkeeping of a loop, a microsecond or two: noise beside any unit).
const MIN_SERIAL_NS: u64 = 5_000;

/// A chain of sections run one after another by one driver: its serial code between them is
/// one unit each.
pub struct Strand {
    state: Mutex<StrandState>,
}

struct StrandState {
    /// What the strand's next section comes after.
    after: Vec<usize>,
    /// The driving thread's CPU time when its serial code was last counted (`None`: not yet
    /// started on its thread).
    mark: Option<u64>,
}

impl Strand {
    /// A strand started on this thread, after nothing.
    fn new() -> Self {
        Strand { state: Mutex::new(StrandState { after: Vec::new(), mark: Some(thread_cpu_ns()) }) }
    }

    /// Records the serial code since the last mark as a unit of its own, and marks now.
    fn close_serial(state: &mut StrandState) {
        let now = thread_cpu_ns();
        let since = now - state.mark.unwrap_or(now);
        state.mark = Some(now);
        if since >= MIN_SERIAL_NS {
            let seq = STARTS.fetch_add(1, Ordering::Relaxed);
            let id = push("serial", std::mem::take(&mut state.after), vec![(seq, since)]);
            state.after = vec![id];
        }
    }

    /// Opens a parallel section after the strand's code so far.
    pub fn open(&self, label: &'static str) -> usize {
        let mut state = self.state.lock().unwrap();
        Self::close_serial(&mut state);
        push(label, state.after.clone(), Vec::new())
    }

    /// Ends section `id`: the strand's next section comes after it (and its serial code is
    /// counted from now).
    pub fn close(&self, id: usize) {
        let mut state = self.state.lock().unwrap();
        state.after = vec![id];
        state.mark = Some(thread_cpu_ns());
    }

    /// Two strands that start where this one stands (the two sides of a `rayon::join`); each
    /// is started on its thread by [`Strand::begin`], and [`Strand::join`] ends them.
    pub fn fork(&self) -> (Strand, Strand) {
        let mut state = self.state.lock().unwrap();
        Self::close_serial(&mut state);
        let side = || Strand { state: Mutex::new(StrandState { after: state.after.clone(), mark: None }) };
        (side(), side())
    }

    /// Starts a side of a fork on the thread that runs it.
    pub fn begin(&self) {
        self.state.lock().unwrap().mark = Some(thread_cpu_ns());
    }

    /// Ends a side of a fork on its thread (its last serial code counted).
    pub fn end(&self) {
        Self::close_serial(&mut self.state.lock().unwrap());
    }

    /// This strand continues after both sides of a fork.
    pub fn join(&self, a: Strand, b: Strand) {
        let mut state = self.state.lock().unwrap();
        let mut after = a.state.into_inner().unwrap().after;
        after.extend(b.state.into_inner().unwrap().after);
        state.after = after;
        state.mark = Some(thread_cpu_ns());
    }
}

/// Records one unit of section `id`: `f`'s CPU time on this thread.
pub fn unit<R>(id: usize, f: impl FnOnce() -> R) -> R {
    let seq = STARTS.fetch_add(1, Ordering::Relaxed);
    let t = thread_cpu_ns();
    let r = f();
    let ns = thread_cpu_ns() - t;
    SECTIONS.lock().unwrap()[id].units.push((seq, ns));
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A strand's serial code, its parallel sections and a fork's two sides, in their order.
    /// (The record is global: this is the one test that makes one.)
    #[test]
    fn a_strand_records_its_sections_in_order() {
        let spin = |n: u64| (0..n).fold(0u64, |a, i| a.wrapping_mul(31).wrapping_add(std::hint::black_box(i)));
        let s = start();
        spin(4_000_000);
        let p = s.open("loop");
        for _ in 0..3 {
            unit(p, || spin(100_000));
        }
        s.close(p);
        let (a, b) = s.fork();
        a.begin();
        spin(4_000_000);
        a.end();
        b.begin();
        let q = b.open("side");
        unit(q, || spin(1000));
        b.close(q);
        s.join(a, b);
        let r = s.open("last");
        s.close(r);
        let sections = finish();
        let find = |label: &str| sections.iter().position(|x| x.label == label).unwrap();
        let (lp, side, last) = (find("loop"), find("side"), find("last"));
        // Serial code of no spin at all, between two calls, can pass the record's 5 us where the
        // thread's clock runs on while it waits (a virtual machine's stolen time: it failed so
        // once under load, the sides after such a unit rather than the loop). The serial spins
        // here take a millisecond or more; a serial unit under 200 us is that noise, and what
        // follows it is read as after what it follows.
        let noise =
            |i: usize| sections[i].label == "serial" && sections[i].units.iter().map(|u| u.1).sum::<u64>() < 200_000;
        fn after(sections: &[Section], noise: &dyn Fn(usize) -> bool, i: usize) -> Vec<usize> {
            sections[i].after.iter().flat_map(|&j| if noise(j) { after(sections, noise, j) } else { vec![j] }).collect()
        }
        let after = |i: usize| after(&sections, &noise, i);
        // The record still leaves out serial code under its 5 us: without that bound the fork,
        // the side's open and the last open would each add such a unit (three); noise adds one
        // at a time, rarely.
        let noises = (0..sections.len()).filter(|&i| noise(i)).count();
        assert!(noises < 3, "{noises} serial units under 200 us: {sections:?}");
        // The serial code before the loop, the loop's three units.
        assert_eq!(after(lp), [0], "{sections:?}");
        assert!(!noise(0), "{sections:?}");
        assert_eq!(sections[lp].units.len(), 3);
        assert!(sections[lp].units.iter().all(|&(_, ns)| ns > 0));
        // Both sides after the loop (the serial side as a unit of its own); the last section
        // after both sides.
        assert_eq!(after(side), [lp], "{sections:?}");
        let serial_side =
            (0..sections.len()).find(|&i| sections[i].label == "serial" && !noise(i) && after(i) == [lp]).unwrap();
        assert_eq!(after(last), [serial_side, side], "{sections:?}");
    }
}
