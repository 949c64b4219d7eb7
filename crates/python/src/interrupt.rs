//! Running work interruptibly: on a worker thread with the GIL released, Ctrl-C setting the core's cancel flag.

use crate::progress::Progress;
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

/// Runs `work` on a worker thread (inside `pool` if given) with the GIL released, checking for
/// signals on this thread every 50 ms. A signal's exception (KeyboardInterrupt for Ctrl-C) sets
/// the cancel flag, waits for the worker to stop and is raised. A panic becomes RuntimeError.
/// The work's own error is the library's, for the caller to word.
pub(crate) fn run_interruptible<T: Send>(
    py: Python<'_>,
    pool: Option<rayon::ThreadPool>,
    work: impl FnOnce(&AtomicBool) -> fogplanes::Result<T> + Send,
) -> PyResult<fogplanes::Result<T>> {
    run_showing(py, pool, work, &Progress::hidden())
}

/// [`run_interruptible`], showing `progress` (which the work ticks) on Python's standard error
/// from this thread every 50 ms: Python's own stream, so that a notebook shows it too.
pub(crate) fn run_showing<T: Send>(
    py: Python<'_>,
    pool: Option<rayon::ThreadPool>,
    work: impl FnOnce(&AtomicBool) -> fogplanes::Result<T> + Send,
    progress: &Progress,
) -> PyResult<fogplanes::Result<T>> {
    let cancel = AtomicBool::new(false);
    let (tx, rx) = mpsc::channel();
    std::thread::scope(|s| {
        let cancel = &cancel;
        std::thread::Builder::new()
            .name("fogplanes-render".into())
            .spawn_scoped(s, move || {
                let run = || work(cancel);
                let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match &pool {
                    Some(p) => p.install(run),
                    None => run(),
                }));
                let _ = tx.send(result);
            })
            .map_err(|e| PyRuntimeError::new_err(format!("cannot start the render thread: {e}")))?;
        let mut rx = rx;
        loop {
            // The receiver is not Sync: it moves into the closure that runs without the GIL.
            let (received, back) = py.detach(move || (rx.recv_timeout(Duration::from_millis(50)), rx));
            rx = back;
            match received {
                Ok(Ok(result)) => {
                    progress.show(py, true);
                    return Ok(result);
                }
                Ok(Err(panic)) => {
                    let what = panic
                        .downcast_ref::<&str>()
                        .map(|s| s.to_string())
                        .or_else(|| panic.downcast_ref::<String>().cloned())
                        .unwrap_or_else(|| "unknown".into());
                    return Err(PyRuntimeError::new_err(format!("fogplanes: internal error: {what}")));
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    progress.show(py, false);
                    if let Err(signal) = py.check_signals() {
                        cancel.store(true, Ordering::Relaxed);
                        py.detach(move || {
                            let _ = rx.recv();
                        });
                        return Err(signal);
                    }
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    return Err(PyRuntimeError::new_err("fogplanes: the render thread ended without a result"));
                }
            }
        }
    })
}
