//! How a long call runs: on a worker thread inside mdtf's thread pool, with
//! the GIL released, while the calling thread wakes every few milliseconds
//! to let Python handle signals. Ctrl-C sets the cancel flag the pipeline
//! checks between stages and slabs, and raises KeyboardInterrupt once the
//! worker has stopped.

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{RecvTimeoutError, channel};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

/// How often the calling thread looks for signals.
const SIGNAL_POLL: Duration = Duration::from_millis(20);

/// The pool set by [`set_threads`]; None: rayon's global pool (one thread per core).
static POOL: Mutex<Option<Arc<rayon::ThreadPool>>> = Mutex::new(None);

/// The pool of the last thread count a cluster task asked for ([`task_pool`]).
static TASK_POOL: Mutex<Option<(usize, Arc<rayon::ThreadPool>)>> = Mutex::new(None);

/// A pool of `threads` worker threads for a cluster task (kept for the
/// next task asking for as many): a task sets its own threads, so a
/// restarted worker runs its tasks as the run asked.
pub fn task_pool(threads: usize) -> PyResult<Arc<rayon::ThreadPool>> {
    let mut kept = TASK_POOL.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some((n, pool)) = kept.as_ref()
        && *n == threads
    {
        return Ok(pool.clone());
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|k| format!("mdtf-task-{k}"))
        .build()
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start {threads} threads: {e}")))?;
    let pool = Arc::new(pool);
    *kept = Some((threads, pool.clone()));
    Ok(pool)
}

/// Uses `threads` worker threads for every later call (0: one per core).
pub fn set_threads(threads: usize) -> PyResult<()> {
    let pool = if threads == 0 {
        None
    } else {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|k| format!("mdtf-{k}"))
            .build()
            .map_err(|e| PyRuntimeError::new_err(format!("cannot start {threads} threads: {e}")))?;
        Some(Arc::new(pool))
    };
    *POOL.lock().unwrap_or_else(PoisonError::into_inner) = pool;
    Ok(())
}

/// The number of worker threads calls use.
pub fn threads() -> usize {
    match POOL.lock().unwrap_or_else(PoisonError::into_inner).as_ref() {
        Some(p) => p.current_num_threads(),
        None => rayon::current_num_threads(),
    }
}

/// Runs `work` with the GIL released. `cancel`, when given, is set on
/// Ctrl-C (or any signal handler that raises), and the signal's exception
/// is raised after `work` returns.
pub fn run_released<T, F>(py: Python<'_>, cancel: Option<&Arc<AtomicBool>>, work: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce() -> T + Send,
{
    let pool = POOL.lock().unwrap_or_else(PoisonError::into_inner).clone();
    std::thread::scope(|s| {
        let (tx, mut rx) = channel();
        let worker = s.spawn(move || {
            let out = match pool {
                Some(p) => p.install(work),
                None => work(),
            };
            // the receiver outlives the scope's threads; a failed send only means it is gone
            let _ = tx.send(out);
        });
        let mut interrupted: Option<PyErr> = None;
        let out = loop {
            // the receiver is not Sync: it moves into the detached closure and back
            let (got, back) = py.detach(move || (rx.recv_timeout(SIGNAL_POLL), rx));
            rx = back;
            match got {
                Ok(out) => break Some(out),
                Err(RecvTimeoutError::Disconnected) => break None,
                Err(RecvTimeoutError::Timeout) => {
                    if interrupted.is_none()
                        && let Err(e) = py.check_signals()
                    {
                        if let Some(c) = cancel {
                            c.store(true, Ordering::Relaxed);
                        }
                        interrupted = Some(e);
                    }
                }
            }
        };
        let joined = py.detach(|| worker.join());
        if let Some(e) = interrupted {
            return Err(e);
        }
        match (out, joined) {
            (Some(out), Ok(())) => Ok(out),
            (_, Err(panic)) => Err(PyRuntimeError::new_err(format!("mdtf failed inside: {}", panic_text(&panic)))),
            (None, Ok(())) => Err(PyRuntimeError::new_err("mdtf's worker stopped without a result")),
        }
    })
}

/// The message of a panic payload.
fn panic_text(panic: &Box<dyn std::any::Any + Send>) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic".into())
}
