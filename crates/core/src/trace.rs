//! Where an end-to-end time goes: with `FOGPLANES_TRACE=1` in the environment, each [`span`] (a
//! step of a render: a piece's preparation, a gathering's encoding, a wait for the GPU) is
//! recorded with its start, end and thread, and [`print`] writes the timeline on stderr at the
//! end of the render, in milliseconds since the first span (the process's start, in the command
//! line). Made for device sessions, whose minutes are few: one run shows what the summary's
//! totals cannot, such as a first gathering that waits 20 ms for memory or a step that runs
//! alone while the other cores are idle (docs/gpu_measurements.md, "Where the end to end
//! goes"). Off, a span costs a load of a flag.
//!
//! With the trace on, the GPU also times each of its passes by its timestamps, where the
//! adapter has them ([`device_pass`]), and [`print`] ends with a table of them: each pass's runs
//! and GPU time, and the time between consecutive passes of a recording, in which the GPU ends
//! one pass before it begins the next. The summary's totals split the GPU's time in two (the
//! binning, the gather); the table says which pass, and how much a pass's fixed cost is.

use std::sync::{Mutex, OnceLock};
use std::time::Instant;

/// The variable that turns the timeline on.
pub const VARIABLE: &str = "FOGPLANES_TRACE";

/// Whether the trace is on: its spans recorded, and the GPU's passes timed one by one.
pub fn on() -> bool {
    static ON: OnceLock<bool> = OnceLock::new();
    *ON.get_or_init(|| std::env::var(VARIABLE).is_ok_and(|v| !v.is_empty() && v != "0"))
}

/// When the first span began: the timeline's zero.
static ZERO: OnceLock<Instant> = OnceLock::new();

/// The spans ended so far: (start, end, thread, step).
static ENDED: Mutex<Vec<(Instant, Instant, String, &'static str)>> = Mutex::new(Vec::new());

/// The GPU's passes timed so far, in the order each was first timed: (pass, runs, nanoseconds).
static PASSES: Mutex<Vec<(&'static str, u64, u64)>> = Mutex::new(Vec::new());

/// The name under which [`device_pass`] adds the time between two consecutive passes of a
/// recording: from one's end to the next one's start, by their timestamps.
pub const BETWEEN_PASSES: &str = "between passes";

/// Adds one run of the GPU's pass `pass`, `ns` nanoseconds by its timestamps, to the table that
/// [`print`] writes (nothing when the trace is off).
pub fn device_pass(pass: &'static str, ns: u64) {
    if !on() {
        return;
    }
    let mut passes = PASSES.lock().unwrap_or_else(|p| p.into_inner());
    match passes.iter_mut().find(|(p, _, _)| *p == pass) {
        Some((_, runs, total)) => {
            *runs += 1;
            *total += ns;
        }
        None => passes.push((pass, 1, ns)),
    }
}

/// The GPU's passes timed since the last [`print`] (pass, runs, nanoseconds), as [`print`] writes
/// them.
pub fn device_passes() -> Vec<(&'static str, u64, u64)> {
    PASSES.lock().unwrap_or_else(|p| p.into_inner()).clone()
}

/// A step under way: recorded when it is dropped.
pub struct Span(Option<(&'static str, Instant)>);

/// Begins a span named `step`, which ends when the value returned is dropped.
pub fn span(step: &'static str) -> Span {
    if !on() {
        return Span(None);
    }
    let now = Instant::now();
    ZERO.get_or_init(|| now);
    Span(Some((step, now)))
}

impl Drop for Span {
    fn drop(&mut self) {
        if let Some((step, start)) = self.0 {
            let thread = format!("{:?}", std::thread::current().id());
            ENDED.lock().unwrap_or_else(|p| p.into_inner()).push((start, Instant::now(), thread, step));
        }
    }
}

/// Writes the spans ended so far on stderr, in the order they ended (start, end and length in
/// milliseconds, thread, step), then the GPU's passes timed (runs, milliseconds in all,
/// microseconds a run, share of their sum), and forgets both.
pub fn print() {
    if !on() {
        return;
    }
    let ended = std::mem::take(&mut *ENDED.lock().unwrap_or_else(|p| p.into_inner()));
    let passes = std::mem::take(&mut *PASSES.lock().unwrap_or_else(|p| p.into_inner()));
    if let Some(&zero) = ZERO.get() {
        let ms = |t: Instant| t.duration_since(zero).as_secs_f64() * 1e3;
        for (start, end, thread, step) in ended {
            eprintln!("{:>9.3} {:>9.3} {:>8.3} {thread} {step}", ms(start), ms(end), ms(end) - ms(start));
        }
    }
    for line in pass_table(&passes) {
        eprintln!("{line}");
    }
}

/// The lines of [`print`]'s table of the GPU's passes: none where none was timed.
fn pass_table(passes: &[(&'static str, u64, u64)]) -> Vec<String> {
    if passes.is_empty() {
        return Vec::new();
    }
    let all: u64 = passes.iter().map(|p| p.2).sum();
    let mut lines = vec![format!(
        "GPU passes by their timestamps, {:.3} ms in all:{:>7} {:>10} {:>11} {:>6}",
        all as f64 * 1e-6,
        "runs",
        "ms",
        "us a run",
        "share"
    )];
    for &(pass, runs, ns) in passes {
        lines.push(format!(
            "  {pass:<44} {runs:>7} {:>10.3} {:>11.2} {:>5.1}%",
            ns as f64 * 1e-6,
            ns as f64 * 1e-3 / runs.max(1) as f64,
            100.0 * ns as f64 / all.max(1) as f64
        ));
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pass_table_gives_each_pass_its_runs_time_and_share() {
        assert!(pass_table(&[]).is_empty());
        let lines = pass_table(&[("gather", 3, 3_000_000), (BETWEEN_PASSES, 2, 1_000_000)]);
        assert_eq!(lines.len(), 3);
        assert!(lines[0].contains("4.000 ms in all"), "{}", lines[0]);
        let cells = |l: &str| l.split_whitespace().map(str::to_owned).collect::<Vec<_>>();
        assert_eq!(cells(&lines[1]), ["gather", "3", "3.000", "1000.00", "75.0%"]);
        assert_eq!(cells(&lines[2]), ["between", "passes", "2", "1.000", "500.00", "25.0%"]);
    }
}
