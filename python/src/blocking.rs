//! Calls run in a worker thread with the GIL released, interruptible.
//!
//! The caller's thread waits on the worker in slices of [`POLL`], the GIL
//! released, and asks Python for pending signals between slices: Ctrl-C
//! raises `KeyboardInterrupt` in the caller at once. The worker is then told
//! to stop: the command line's progress reports ([`plantc::host`]) unwind it
//! at the next report (fits report every iteration; `identify` between its
//! steps and in its fits, not while the diagnosis screens candidates), and
//! what it was building is dropped (identify's output directory is built
//! aside and never swapped in). A computation without progress reports (a
//! simulation, `diagnose`) finishes in the background and its result is
//! dropped.
//!
//! A panic in the worker is caught there and becomes `plantc.PlantcError`;
//! the worker has a large stack so that deeply nested model text cannot
//! overflow it.

use std::cell::RefCell;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::Duration;

use pyo3::prelude::*;

use crate::errors::{Failure, PlantcError};

/// How often the waiting caller checks for signals. Python's own default
/// switch interval is 5 ms; 20 ms keeps Ctrl-C immediate to a person
/// (under the ~100 ms a delay becomes noticeable) at a negligible cost.
const POLL: Duration = Duration::from_millis(20);

/// The worker's stack: 256 MiB of address space (only touched pages cost
/// memory). The parser and the symbolic core recurse over expressions; the
/// main thread's 8 MiB is what a fuzzed text with thousands of nested
/// parentheses could exhaust, and a stack overflow aborts the process.
const STACK: usize = 256 << 20;

thread_local! {
    /// The stop flag of the call this worker thread runs.
    static STOP: RefCell<Option<Arc<AtomicBool>>> = const { RefCell::new(None) };
}

/// The payload a stopped worker unwinds with.
struct Stopped;

/// Installed as [`plantc::host::set_progress_hook`]: unwinds the worker
/// whose call was interrupted.
pub fn progress_hook() {
    let stop = STOP.with(|s| {
        s.borrow()
            .as_ref()
            .is_some_and(|f| f.load(Ordering::Relaxed))
    });
    if stop {
        resume_unwind(Box::new(Stopped));
    }
}

/// Runs `work` in a worker thread, the GIL released; see the module docs.
pub fn run<T, F>(py: Python<'_>, work: F) -> PyResult<T>
where
    T: Send + 'static,
    F: FnOnce() -> Result<T, Failure> + Send + 'static,
{
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let (tx, rx) = mpsc::channel();
    std::thread::Builder::new()
        .name("plantc-worker".into())
        .stack_size(STACK)
        .spawn(move || {
            STOP.with(|s| *s.borrow_mut() = Some(flag));
            let r = catch_unwind(AssertUnwindSafe(work));
            let _ = tx.send(r);
        })
        .map_err(|e| PlantcError::new_err(format!("cannot start a worker thread: {e}")))?;
    let mut rx = rx;
    loop {
        // the receiver is moved in and out: `allow_threads` needs `Send`
        let (got, back) = py.allow_threads(move || (rx.recv_timeout(POLL), rx));
        rx = back;
        match got {
            Ok(Ok(Ok(v))) => return Ok(v),
            Ok(Ok(Err(f))) => return Err(f.into_py(py)),
            Ok(Err(payload)) => return Err(PlantcError::new_err(panic_text(&payload))),
            Err(mpsc::RecvTimeoutError::Timeout) => {
                if let Err(e) = py.check_signals() {
                    stop.store(true, Ordering::Relaxed);
                    return Err(e);
                }
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                return Err(PlantcError::new_err(
                    "the worker thread ended without a result",
                ))
            }
        }
    }
}

fn panic_text(payload: &Box<dyn std::any::Any + Send>) -> String {
    let what = payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".to_string());
    format!("internal error in plantc (a bug; please report it with the input): {what}")
}
