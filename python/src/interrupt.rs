//! Long calls (a simulation, an estimation over a long capture) run on a
//! worker thread while the calling thread, without the GIL, checks for
//! Ctrl-C: other Python threads run meanwhile, and a KeyboardInterrupt
//! returns control at once (the worker finishes in the background and its
//! result is dropped; the library crates have no cancellation point).

use std::sync::mpsc;
use std::time::Duration;

use pyo3::prelude::*;

/// How often the waiting thread looks for a signal.
const POLL: Duration = Duration::from_millis(50);

/// `work`'s result, or the signal handler's exception (KeyboardInterrupt on Ctrl-C).
pub fn run_interruptible<T, F>(py: Python<'_>, work: F) -> PyResult<T>
where
    T: Send + 'static,
    F: FnOnce() -> T + Send + 'static,
{
    let (tx, rx) = mpsc::channel();
    std::thread::Builder::new()
        .name("hammer_monitor".into())
        .spawn(move || {
            // The receiver is gone only after an interrupt: nothing to tell.
            let _ = tx.send(work());
        })
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("cannot start a worker thread: {e}")))?;
    py.detach(move || loop {
        match rx.recv_timeout(POLL) {
            Ok(result) => return Ok(result),
            Err(mpsc::RecvTimeoutError::Timeout) => Python::attach(|py| py.check_signals())?,
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                return Err(pyo3::exceptions::PyRuntimeError::new_err(
                    "the worker thread stopped without a result (a panic in the library)",
                ))
            }
        }
    })
}
