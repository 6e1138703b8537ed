//! Where a run reports its progress and may be stopped: every stage and
//! every slab starts through [`Progress`], so each start is shown and is a
//! point at which a cancelled run ends.

use crate::error::{RunError, fail};
use crate::run::RunOptions;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// A run's progress callbacks and its cancel flag ([`RunOptions::cancel`]).
pub(crate) struct Progress<'a> {
    opts: &'a RunOptions,
    on_stage: &'a (dyn Fn(&str) + Sync),
    on_slab: &'a (dyn Fn(usize, usize) + Sync),
}

impl<'a> Progress<'a> {
    /// Progress of a run of `opts`: `on_stage(name)` as each stage or pass
    /// starts, `on_slab(k, slabs)` as it starts its slab k (from 1).
    pub(crate) fn new(
        opts: &'a RunOptions,
        on_stage: &'a (dyn Fn(&str) + Sync),
        on_slab: &'a (dyn Fn(usize, usize) + Sync),
    ) -> Self {
        Progress { opts, on_stage, on_slab }
    }

    /// Reports that stage `name` starts; an error if the run was cancelled.
    pub(crate) fn stage(&self, name: &str) -> Result<(), RunError> {
        (self.on_stage)(name);
        self.check()
    }

    /// Reports that slab `k` of `slabs` starts; an error if the run was cancelled.
    pub(crate) fn slab(&self, k: usize, slabs: usize) -> Result<(), RunError> {
        (self.on_slab)(k, slabs);
        self.check()
    }

    /// Reports that slab `k` of `slabs` starts, where the run does not stop
    /// (its reads fail once it is cancelled).
    pub(crate) fn report_slab(&self, k: usize, slabs: usize) {
        (self.on_slab)(k, slabs);
    }

    /// An error when the run was cancelled: it stops there, and its partial
    /// output folder is removed.
    pub(crate) fn check(&self) -> Result<(), RunError> {
        if self.opts.is_cancelled() { Err(cancelled()) } else { Ok(()) }
    }
}

/// Whether a cancel flag is set (None: the run cannot be cancelled).
pub(crate) fn is_set(flag: &Option<Arc<AtomicBool>>) -> bool {
    flag.as_ref().is_some_and(|c| c.load(Ordering::Relaxed))
}

/// The error a cancelled run ends with.
pub(crate) fn cancelled() -> RunError {
    fail("run")("cancelled".into())
}
