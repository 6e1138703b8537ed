//! How mdtf writes its outputs, for every command alike.
//!
//! * A file is written beside its target under a partial name and renamed
//!   over it ([`write_file_atomically`]); a `.nhdr` and its data file are
//!   published as one unit.
//! * A folder is built as a fresh sibling and swapped in with one atomic
//!   step ([`OutputFolder`]): `renameat2(RENAME_EXCHANGE)` on Linux, so at
//!   no moment is there no output. The folder replaced must be one mdtf made
//!   (it holds the marker [`MARKER_NAME`] listing every file mdtf wrote) and
//!   hold no input of the run; anything else is refused.
//! * No output is ever an input: files are compared by identity
//!   (device + inode), including detached data files ([`Inputs`]).
//! * One run at a time per output: an advisory lock ([`OutputLock`]);
//!   partial outputs of killed runs are removed by the next run into the same
//!   place, and [`remove_partial_outputs`] serves signal handlers.

mod file;
mod folder;
mod identity;
mod lock;
mod staging;

pub use file::{AtomicWriter, write_file_atomically};
pub(crate) use file::{StagedFile, old_pair_data, publish_pair, sweep};
pub use folder::{MARKER_NAME, OutputFolder, RESUME_NAME};
pub use identity::{FileId, Inputs};
pub use lock::OutputLock;
pub use staging::{PARTIAL_PREFIX, remove_any, remove_partial_outputs};

use crate::error::{Result, VolumeError};
use std::ffi::OsString;
use std::path::{Component, Path, PathBuf};

/// The absolute folder a target lives in and the target's own name. The
/// folder is resolved (links, `..`); the name is kept as given, so a link at
/// the target is replaced, not followed. `.` and `..` are resolved first.
pub(crate) fn parent_and_name(target: &Path) -> Result<(PathBuf, OsString)> {
    let ends_in_dots = matches!(target.components().next_back(), Some(Component::CurDir | Component::ParentDir) | None);
    let target = if ends_in_dots {
        target.canonicalize().map_err(|e| VolumeError::io(target, e))?
    } else {
        target.to_path_buf()
    };
    let Some(name) = target.file_name() else {
        return Err(VolumeError::OutputNotAFolder { path: target.clone() });
    };
    let parent = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let parent = parent.canonicalize().map_err(|e| VolumeError::io(&parent, e))?;
    Ok((parent, name.to_os_string()))
}
