//! `render(..., progress=True)`: a progress line on Python's standard error, drawn from the
//! Python thread while the work runs ([`crate::interrupt::run_showing`]), so that a terminal,
//! a notebook and a log file each get what fits them: on a terminal one line redrawn in place,
//! elsewhere a line per tenth of the work (or per 10 seconds when its end is unknown).

use pyo3::prelude::*;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// The work's progress: units of work ticked by the workers, shown by the Python thread.
pub(crate) struct Progress {
    shown: bool,
    label: String,
    /// Units of the whole work and the planes they stand for; `None` for a render in passes,
    /// whose end is not known.
    total: Option<(u64, u64)>,
    done: AtomicU64,
    started: Instant,
    /// The last tenth (or ten seconds) written as a line, and whether standard error is a
    /// terminal (asked once).
    last: Mutex<(u64, Option<bool>)>,
}

impl Progress {
    /// Shows nothing.
    pub(crate) fn hidden() -> Self {
        Progress::new(false, "", None)
    }

    /// `units` units of work standing for `planes` planes.
    pub(crate) fn planes(label: &str, units: u64, planes: u64) -> Self {
        Progress::new(true, label, Some((units.max(1), planes)))
    }

    /// Passes until a budget or a target error: elapsed time and work so far.
    pub(crate) fn passes(label: &str) -> Self {
        Progress::new(true, label, None)
    }

    fn new(shown: bool, label: &str, total: Option<(u64, u64)>) -> Self {
        let (done, started, last) = (AtomicU64::new(0), Instant::now(), Mutex::new((0, None)));
        Progress { shown, label: label.to_string(), total, done, started, last }
    }

    /// One unit of work done (from any thread).
    pub(crate) fn tick(&self) {
        self.done.fetch_add(1, Ordering::Relaxed);
    }

    /// The line as it stands.
    fn line(&self) -> (String, u64) {
        let (done, seconds) = (self.done.load(Ordering::Relaxed), self.started.elapsed().as_secs_f64());
        match self.total {
            Some((units, planes)) => {
                let fraction = (done as f64 / units as f64).min(1.0);
                let eta = if done > 0 { seconds * (1.0 - fraction) / fraction } else { f64::NAN };
                let eta = if eta.is_finite() { format!("{eta:.1} s") } else { "?".into() };
                let line = format!(
                    "{}: {:3.0}%, {} of {planes} planes, {seconds:.1} s, eta {eta}",
                    self.label,
                    100.0 * fraction,
                    (fraction * planes as f64).round() as u64
                );
                (line, (10.0 * fraction).floor() as u64)
            }
            None => (format!("{}: {seconds:.1} s, {done} units of work", self.label), (seconds / 10.0) as u64),
        }
    }

    /// Writes the line if it is due (`last`: the work is done); errors writing are ignored (a
    /// progress line must not fail a render).
    pub(crate) fn show(&self, py: Python<'_>, last: bool) {
        if !self.shown {
            return;
        }
        let Ok(stderr) = py.import("sys").and_then(|sys| sys.getattr("stderr")) else { return };
        let mut state = self.last.lock().unwrap_or_else(|e| e.into_inner());
        let tty = *state
            .1
            .get_or_insert_with(|| stderr.call_method0("isatty").and_then(|r| r.extract::<bool>()).unwrap_or(false));
        let (line, step) = self.line();
        let text = if tty {
            format!("\r{line}\x1b[K{}", if last { "\n" } else { "" })
        } else if step > state.0 || last {
            format!("{line}\n")
        } else {
            return;
        };
        state.0 = step;
        let _ = stderr.call_method1("write", (text,));
        let _ = stderr.call_method0("flush");
    }
}
