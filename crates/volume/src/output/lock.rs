//! An advisory lock per output target, so that a second run into an output
//! that is being written is refused at once instead of racing the first.
//! The lock is `flock` on a small file `.<name>.mdtf-lock` beside the target,
//! removed again when the lock is released.

use crate::error::{Result, VolumeError};
use crate::output::identity::FileId;
use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};

/// A held lock on one output target; released (and its file removed) on drop.
#[derive(Debug)]
pub struct OutputLock {
    path: PathBuf,
    file: File,
}

impl OutputLock {
    /// Takes the lock of `target` (a file or folder that may not exist yet)
    /// or says who holds it.
    pub fn acquire(target: &Path) -> Result<OutputLock> {
        let (parent, name) = super::parent_and_name(target)?;
        let path = parent.join(format!(".{}.mdtf-lock", name.to_string_lossy()));
        // Another run may remove the file between our open and our lock; then
        // the lock we hold is on a file nobody else can find: open again.
        for _ in 0..16 {
            let file = OpenOptions::new()
                .create(true)
                .truncate(false)
                .write(true)
                .open(&path)
                .map_err(|e| VolumeError::io(&path, e))?;
            match rustix::fs::flock(&file, rustix::fs::FlockOperation::NonBlockingLockExclusive) {
                Ok(()) => {}
                Err(rustix::io::Errno::WOULDBLOCK) => {
                    return Err(VolumeError::OutputBusy { path: target.to_path_buf() });
                }
                // A file system without flock: go on unlocked rather than refuse every run.
                Err(_) => return Ok(OutputLock { path, file }),
            }
            if still_named(&file, &path) {
                // listed, so that a signal handler removes it with the partial outputs
                super::staging::register(&path);
                return Ok(OutputLock { path, file });
            }
        }
        Err(VolumeError::OutputBusy { path: target.to_path_buf() })
    }
}

/// Whether `path` still names the open `file`.
fn still_named(file: &File, path: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let Ok(m) = file.metadata() else { return false };
        FileId::of(path).is_some_and(|id| id == FileId::from_dev_ino(m.dev(), m.ino()))
    }
    #[cfg(not(unix))]
    {
        let _ = file;
        FileId::of(path).is_some()
    }
}

impl Drop for OutputLock {
    fn drop(&mut self) {
        // Unlink while still holding the lock; a waiting run then re-opens.
        let mut live = super::staging::live();
        // lock files are empty: one with content is somebody's file that happens to have this name
        let empty = self.file.metadata().is_ok_and(|m| m.len() == 0);
        if empty && still_named(&self.file, &self.path) {
            let _ = std::fs::remove_file(&self.path);
        }
        super::staging::unregister_locked(&mut live, &self.path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_writer_is_refused_until_the_first_is_done() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out");
        let first = OutputLock::acquire(&target).unwrap();
        let e = OutputLock::acquire(&target).unwrap_err();
        assert!(matches!(e, VolumeError::OutputBusy { .. }), "{e}");
        drop(first);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "the lock file is removed");
        OutputLock::acquire(&target).unwrap();
    }
}
