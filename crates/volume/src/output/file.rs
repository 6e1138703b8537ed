//! Single files, written whole or not at all: into a partial file beside the
//! target, then renamed over it. A pair (a `.nhdr` header and its data file)
//! is published so that the header always names complete data that belong
//! to it, before, during and after the replacement.

use super::identity::FileId;
use super::lock::OutputLock;
use super::staging::{self, prefix_for, register};
use crate::error::{Result, VolumeError};
use std::io::Write;
use std::path::{Path, PathBuf};

/// A file written in full beside its target and not yet published; dropped
/// unpublished, it is removed.
#[derive(Debug)]
pub(crate) struct StagedFile {
    partial: PathBuf,
    target: PathBuf,
    published: bool,
}

impl StagedFile {
    /// Writes the bytes `fill` produces into a partial file beside `target`.
    pub(crate) fn write(target: &Path, fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> Result<Self> {
        let (staged, file) = StagedFile::open(target)?;
        let mut w = std::io::BufWriter::new(file);
        fill(&mut w).map_err(|e| VolumeError::io(target, e))?;
        staged.written(w)
    }

    /// A new, empty partial file beside `target`, open for writing.
    pub(crate) fn open(target: &Path) -> Result<(Self, std::fs::File)> {
        let (parent, name) = super::parent_and_name(target)?;
        let tmp = staging::builder(&prefix_for(&name.to_string_lossy()))
            .tempfile_in(&parent)
            .map_err(|e| VolumeError::io(target, e))?;
        let (file, partial) = tmp.keep().map_err(|e| VolumeError::io(target, e.error))?;
        register(&partial);
        Ok((StagedFile { partial, target: parent.join(&name), published: false }, file))
    }

    /// Where the partial file is.
    pub(crate) fn partial(&self) -> &Path {
        &self.partial
    }

    /// The partial file with every byte of `w` in it, closed, ready to publish.
    fn written(self, w: std::io::BufWriter<std::fs::File>) -> Result<Self> {
        let file = w.into_inner().map_err(|e| VolumeError::io(&self.target, e.into_error()))?;
        drop(file);
        publish_permissions(&self.partial, &self.target);
        Ok(self)
    }

    /// Renames the partial file over the target.
    pub(crate) fn publish(mut self) -> Result<()> {
        let mut live = staging::live();
        std::fs::rename(&self.partial, &self.target).map_err(|e| VolumeError::io(&self.target, e))?;
        staging::unregister_locked(&mut live, &self.partial);
        self.published = true;
        Ok(())
    }
}

impl Drop for StagedFile {
    fn drop(&mut self) {
        if !self.published {
            let mut live = staging::live();
            let _ = std::fs::remove_file(&self.partial);
            staging::unregister_locked(&mut live, &self.partial);
        }
    }
}

/// Writes the bytes `fill` produces to `path` atomically: a failure leaves
/// the old file (if any) as it was and no partial file behind. Leftovers of
/// an earlier, killed write to the same path are removed.
pub fn write_file_atomically(path: &Path, fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> Result<()> {
    let _lock = OutputLock::acquire(path)?;
    sweep(path);
    StagedFile::write(path, fill)?.publish()
}

/// A file written piece by piece and published whole: its bytes go into a
/// partial file beside the target, renamed over it by
/// [`AtomicWriter::publish`]. Dropped unpublished (an error, a panic), the
/// partial file is removed and the target is left as it was. For writers
/// that keep several files open at once; one file written by one closure is
/// [`write_file_atomically`].
#[derive(Debug)]
pub struct AtomicWriter {
    _lock: OutputLock,
    staged: StagedFile,
    out: std::io::BufWriter<std::fs::File>,
}

impl AtomicWriter {
    /// Starts writing `path` (removing leftovers of an earlier, killed write to it).
    pub fn create(path: &Path) -> Result<AtomicWriter> {
        let lock = OutputLock::acquire(path)?;
        sweep(path);
        let (staged, file) = StagedFile::open(path)?;
        Ok(AtomicWriter { _lock: lock, staged, out: std::io::BufWriter::new(file) })
    }

    /// Puts the file in place of its target, with every byte written so far.
    pub fn publish(self) -> Result<()> {
        let AtomicWriter { _lock, staged, out } = self;
        staged.written(out)?.publish()
    }
}

impl Write for AtomicWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.out.write(buf)
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        self.out.write_all(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

/// Removes leftovers of killed writes to `path` (the caller holds its lock).
pub(crate) fn sweep(path: &Path) {
    if let Ok((parent, name)) = super::parent_and_name(path) {
        staging::sweep_leftovers(&parent, &name.to_string_lossy(), None);
    }
}

/// Whether the data file about to be written beside `header` may be: it must
/// be new, or be one of `named` (the data files the header being replaced
/// names), by identity. Returns that old data file when there is one.
pub(crate) fn old_pair_data(header: &Path, data: &Path, named: &[PathBuf]) -> Result<Option<PathBuf>> {
    let Some(data_id) = FileId::of(data) else { return Ok(None) };
    // A header left pointing at a partial link by a killed write: `data` is
    // the new data that write had already put in place.
    let at_partial_link =
        |d: &PathBuf| d.file_name().is_some_and(|n| n.to_string_lossy().starts_with(staging::PARTIAL_PREFIX));
    if !named.is_empty() && named.iter().all(at_partial_link) {
        return Ok(None);
    }
    match named.iter().find(|d| FileId::of(d).as_ref() == Some(&data_id)) {
        Some(d) => Ok(Some(d.clone())),
        None => Err(VolumeError::DataFileInTheWay { path: data.to_path_buf(), header: header.to_path_buf() }),
    }
}

/// Publishes a detached header and its data file as one unit. When an older
/// header at `header` names the data file being replaced, it is first pointed
/// at a hard link of the old data, so that at every moment the header names
/// complete data of its own; the link is removed at the end (or, after a
/// kill or a signal, by the next write to the same header).
/// `repoint(text, name)` is the old header's text naming the data file `name`.
pub(crate) fn publish_pair(
    header: StagedFile,
    data: StagedFile,
    old_header_data: Option<&Path>,
    repoint: fn(&str, &str) -> String,
) -> Result<()> {
    let mut old_link = None;
    if let Some(old_data) = old_header_data
        && old_data.exists()
    {
        let (parent, name) = super::parent_and_name(&header.target)?;
        let link = staging::builder(&prefix_for(&name.to_string_lossy()))
            .make_in(&parent, |p| std::fs::hard_link(old_data, p))
            .map_err(|e| VolumeError::io(old_data, e))?
            .into_temp_path()
            .keep()
            .map_err(|e| VolumeError::io(old_data, e.error))?;
        // Not listed for signal clean-up: once the old header names the link,
        // removing it would leave a header without data. A link left behind
        // is swept by the next write of this header, after its new header is in.
        let text = std::fs::read_to_string(&header.target).map_err(|e| VolumeError::io(&header.target, e))?;
        let link_name = link.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let repointed = repoint(&text, &link_name);
        StagedFile::write(&header.target, |w| w.write_all(repointed.as_bytes()))?.publish()?;
        old_link = Some(link);
    }
    data.publish()?;
    header.publish()?;
    if let Some(link) = old_link {
        let _ = std::fs::remove_file(&link);
    }
    Ok(())
}

/// Temporary files are created private (0600); give the output the
/// permissions of the file it replaces, or the usual 0644 for a new one.
fn publish_permissions(tmp: &Path, target: &Path) {
    let perms = match std::fs::metadata(target) {
        Ok(m) => m.permissions(),
        Err(_) => {
            #[cfg(unix)]
            {
                use std::os::unix::fs::PermissionsExt;
                std::fs::Permissions::from_mode(0o644)
            }
            #[cfg(not(unix))]
            {
                return;
            }
        }
    };
    // Best effort: a file system without permissions still gets the data.
    let _ = std::fs::set_permissions(tmp, perms);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_write_leaves_the_old_file_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.bin");
        std::fs::write(&target, b"old").unwrap();
        let r = write_file_atomically(&target, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("disk full"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        write_file_atomically(&target, |w| w.write_all(b"new")).unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
    }

    #[test]
    fn a_killed_write_is_swept_by_the_next() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.bin");
        let left = staging::builder(&prefix_for("out.bin")).tempfile_in(dir.path()).unwrap().keep().unwrap().1;
        write_file_atomically(&target, |w| w.write_all(b"new")).unwrap();
        assert!(!left.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[cfg(unix)]
    #[test]
    fn outputs_are_readable_by_others_like_any_new_file() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("new.bin");
        write_file_atomically(&target, |w| w.write_all(b"x")).unwrap();
        assert_eq!(std::fs::metadata(&target).unwrap().permissions().mode() & 0o777, 0o644);
    }
}
