//! Names and bookkeeping of partial outputs: every file or folder mdtf is
//! still writing lives beside its target as `.mdtf-partial-<name>-XXXXXX`,
//! is listed here while this process writes it, and is removed on failure,
//! on a signal ([`remove_partial_outputs`]) or, after a `kill -9`, by the
//! next run into the same target ([`sweep_leftovers`]).

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// The start of every partial output's name.
pub const PARTIAL_PREFIX: &str = ".mdtf-partial-";
/// Random characters after the target's name.
const RANDOM_LEN: usize = 6;
/// Longest part of a target's name kept in a partial name (file names are
/// at most 255 bytes).
const MAX_NAME_CHARS: usize = 96;

static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The registry, usable even after a thread panicked while holding it.
pub(crate) fn live() -> MutexGuard<'static, Vec<PathBuf>> {
    LIVE.lock().unwrap_or_else(|p| p.into_inner())
}

/// Lists `path` as a partial output of this process.
pub(crate) fn register(path: &Path) {
    live().push(path.to_path_buf());
}

/// Forgets `path` (published or removed).
pub(crate) fn unregister_locked(live: &mut Vec<PathBuf>, path: &Path) {
    live.retain(|p| p != path);
}

/// The prefix of partial outputs of the target called `name`.
pub(crate) fn prefix_for(name: &str) -> String {
    let short: String = name.chars().take(MAX_NAME_CHARS).collect();
    format!("{PARTIAL_PREFIX}{short}-")
}

/// A `tempfile` builder whose names follow [`prefix_for`].
pub(crate) fn builder(prefix: &str) -> tempfile::Builder<'_, '_> {
    let mut b = tempfile::Builder::new();
    b.prefix(prefix).rand_bytes(RANDOM_LEN);
    b
}

/// Removes a file or a folder, whichever `path` is (a link itself, never
/// what it points to; a path that is not there is no error).
pub fn remove_any(path: &Path) -> std::io::Result<()> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => std::fs::remove_dir_all(path),
        Ok(_) => std::fs::remove_file(path),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e),
    }
}

/// Removes every partial output of this process, for a signal handler that
/// is about to exit. The registry stays locked afterwards, so nothing can be
/// published once this has run. Returns the paths removed.
pub fn remove_partial_outputs() -> Vec<PathBuf> {
    let guard = live();
    let removed: Vec<PathBuf> = guard.iter().filter(|p| remove_any(p).is_ok()).cloned().collect();
    std::mem::forget(guard);
    removed
}

/// Removes partial outputs of the target `name` in `parent` that no live
/// writer owns: the caller holds the target's lock, so any such entry is
/// left from a killed run; but `keep`, which a resumed run takes over.
/// Returns the paths removed.
pub(crate) fn sweep_leftovers(parent: &Path, name: &str, keep: Option<&Path>) -> Vec<PathBuf> {
    let mine = live().clone();
    let mut removed = Vec::new();
    for path in leftovers(parent, name) {
        if !mine.contains(&path) && keep != Some(path.as_path()) && remove_any(&path).is_ok() {
            removed.push(path);
        }
    }
    removed
}

/// The partial outputs of the target `name` in `parent` (this process's
/// own included), in name order.
pub(crate) fn leftovers(parent: &Path, name: &str) -> Vec<PathBuf> {
    let prefix = prefix_for(name);
    let Ok(entries) = std::fs::read_dir(parent) else { return Vec::new() };
    let mut found = Vec::new();
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let Some(rest) = file_name.to_str().and_then(|n| n.strip_prefix(&prefix)) else { continue };
        if rest.len() == RANDOM_LEN && rest.chars().all(|c| c.is_ascii_alphanumeric()) {
            found.push(entry.path());
        }
    }
    found.sort();
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leftovers_of_one_target_are_swept_and_no_other() {
        let dir = tempfile::tempdir().unwrap();
        let a = builder(&prefix_for("a")).tempdir_in(dir.path()).unwrap().keep();
        let ab = builder(&prefix_for("a-b")).tempdir_in(dir.path()).unwrap().keep();
        std::fs::write(dir.path().join("a"), b"user").unwrap();
        let removed = sweep_leftovers(dir.path(), "a", None);
        assert_eq!(removed, vec![a.clone()]);
        assert!(!a.exists());
        assert!(ab.exists());
        assert!(dir.path().join("a").exists());
    }
}
