//! Where an end-to-end time goes: with `FOGPLANES_TRACE=1` in the environment, each [`span`] (a
//! step of a render: a piece's preparation, a gathering's encoding, a wait for the GPU) is
//! recorded with its start, end and thread, and [`print`] writes the timeline on stderr at the
//! end of the render, in milliseconds since the first span (the process's start, in the command
//! line). Made for device sessions, whose minutes are few: one run shows what the summary's
//! totals cannot, such as a first gathering that waits 20 ms for memory or a step that runs
//! alone while the other cores are idle (docs/gpu_measurements.md, "Where the end to end
//! goes"). Off, a span costs a load of a flag.

use std::sync::{Mutex, OnceLock};
use std::time::Instant;

/// The variable that turns the timeline on.
pub const VARIABLE: &str = "FOGPLANES_TRACE";

fn on() -> bool {
    static ON: OnceLock<bool> = OnceLock::new();
    *ON.get_or_init(|| std::env::var(VARIABLE).is_ok_and(|v| !v.is_empty() && v != "0"))
}

/// When the first span began: the timeline's zero.
static ZERO: OnceLock<Instant> = OnceLock::new();

/// The spans ended so far: (start, end, thread, step).
static ENDED: Mutex<Vec<(Instant, Instant, String, &'static str)>> = Mutex::new(Vec::new());

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
/// milliseconds, thread, step), and forgets them.
pub fn print() {
    if !on() {
        return;
    }
    let ended = std::mem::take(&mut *ENDED.lock().unwrap_or_else(|p| p.into_inner()));
    let Some(&zero) = ZERO.get() else { return };
    let ms = |t: Instant| t.duration_since(zero).as_secs_f64() * 1e3;
    for (start, end, thread, step) in ended {
        eprintln!("{:>9.3} {:>9.3} {:>8.3} {thread} {step}", ms(start), ms(end), ms(end) - ms(start));
    }
}
