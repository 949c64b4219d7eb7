//! How a caller follows and stops a long job: one [`Control`] (a progress callback and a cancel
//! flag) goes to every render, reference and gathering call.
//!
//! The flag is read with a relaxed load (a plain memory read) between small units of work: per
//! plane in a band of rows, per ray on the per-ray paths, per chunk of planes while sampling,
//! per pixel in the reference. So a job stops within a few milliseconds of the flag being set,
//! at any plane count (the promise is under a second), and a read costs nothing beside a
//! plane's or a pixel's work.

use crate::error::{Error, Result};
use std::sync::atomic::{AtomicBool, Ordering};

/// A progress callback: called once per finished unit of work (a band of rows, a chunk of rays,
/// a row of the reference); see [`crate::accel::Accelerator::units_per_gathering`].
pub type Progress<'a> = &'a (dyn Fn() + Sync);

/// Progress reporting and cancellation of one job. Cheap to copy; pass it by value.
#[derive(Clone, Copy)]
pub struct Control<'a> {
    progress: Progress<'a>,
    cancel: &'a AtomicBool,
}

/// The flag of a job nobody can cancel: private, so never set.
static NEVER: AtomicBool = AtomicBool::new(false);

fn no_progress() {}

impl<'a> Control<'a> {
    /// Progress reported to `progress`; the job stops once another thread sets `cancel`.
    pub fn new(progress: Progress<'a>, cancel: &'a AtomicBool) -> Self {
        Control { progress, cancel }
    }

    /// No progress reported, never cancelled.
    pub fn none() -> Control<'static> {
        Control { progress: &no_progress, cancel: &NEVER }
    }

    /// Progress reported to `progress`, never cancelled.
    pub fn with_progress(progress: Progress<'a>) -> Self {
        Control { progress, cancel: &NEVER }
    }

    /// No progress reported; the job stops once another thread sets `cancel`.
    pub fn with_cancel(cancel: &'a AtomicBool) -> Self {
        Control { progress: &no_progress, cancel }
    }

    /// Reports one finished unit of work.
    #[inline]
    pub fn progress(&self) {
        (self.progress)()
    }

    /// Whether the job should stop.
    #[inline(always)]
    pub fn is_cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }

    /// [`Error::Cancelled`] once the job should stop.
    #[inline]
    pub fn check(&self) -> Result<()> {
        if self.is_cancelled() { Err(Error::Cancelled) } else { Ok(()) }
    }
}

impl std::fmt::Debug for Control<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Control").field("cancelled", &self.is_cancelled()).finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    #[test]
    fn a_control_reports_progress_and_its_flag() {
        assert!(Control::none().check().is_ok());
        let (units, cancel) = (AtomicUsize::new(0), AtomicBool::new(false));
        let progress = || {
            units.fetch_add(1, Ordering::Relaxed);
        };
        let control = Control::new(&progress, &cancel);
        control.progress();
        control.progress();
        assert_eq!(units.load(Ordering::Relaxed), 2);
        assert!(!control.is_cancelled() && control.check().is_ok());
        cancel.store(true, Ordering::Relaxed);
        assert!(control.is_cancelled() && matches!(control.check(), Err(Error::Cancelled)));
        assert!(Control::with_cancel(&cancel).is_cancelled() && !Control::with_progress(&progress).is_cancelled());
    }
}
