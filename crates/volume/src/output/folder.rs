//! Output folders: built as a fresh sibling, published in one atomic step,
//! and only ever replacing a folder that mdtf made and that holds no input.

use super::identity::Inputs;
use super::lock::OutputLock;
use super::staging::{self, prefix_for, register};
use crate::error::{Result, VolumeError};
use std::path::{Path, PathBuf};

/// The marker file in every output folder mdtf makes: its first line names
/// the format, every further line one file mdtf wrote (relative, `/`).
pub const MARKER_NAME: &str = ".mdtf-output";
const MARKER_MAGIC: &str = "mdtf output folder 1";
/// Files listed by name in a refusal message.
const NAMES_SHOWN: usize = 3;
/// Entries looked at when searching a foreign folder for an input.
const FOREIGN_ENTRIES_WALKED: usize = 10_000;

/// An output folder being built: write into [`OutputFolder::path`], then
/// [`OutputFolder::publish`]. Dropped unpublished (an error, a panic), the
/// partial folder is removed and the old output stays as it was.
#[derive(Debug)]
pub struct OutputFolder {
    target: PathBuf,
    staging: PathBuf,
    published: bool,
    resumed: bool,
    _lock: OutputLock,
}

/// The file in the partial folder of a run that can be resumed
/// ([`OutputFolder::begin_resumable`]): its content is the run's key.
pub const RESUME_NAME: &str = ".mdtf-resume";

impl OutputFolder {
    /// Checks that `target` may be written (it is new, empty, or an mdtf
    /// output folder holding no input, and no other run is writing it) and
    /// makes the partial folder beside it; leftovers of killed runs into the
    /// same target are removed.
    pub fn begin(target: &Path, inputs: &Inputs) -> Result<OutputFolder> {
        Self::begin_with(target, inputs, None)
    }

    /// [`OutputFolder::begin`] for a run that can pick up where a killed
    /// run of the same `key` (the run's settings and input, as its caller
    /// names them) stopped: the partial folder such a run left beside
    /// `target` is taken as this one's, whatever it holds
    /// ([`OutputFolder::resumed`] says so; the caller decides what of it to
    /// keep), instead of being removed. Otherwise a new folder, marked
    /// with `key` ([`RESUME_NAME`], removed again on publishing).
    pub fn begin_resumable(target: &Path, inputs: &Inputs, key: &str) -> Result<OutputFolder> {
        Self::begin_with(target, inputs, Some(key))
    }

    fn begin_with(target: &Path, inputs: &Inputs, key: Option<&str>) -> Result<OutputFolder> {
        if let Some(parent) = target.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|e| VolumeError::io(parent, e))?;
        }
        let (parent, name) = super::parent_and_name(target)?;
        let absolute = parent.join(&name);
        let lock = OutputLock::acquire(&absolute)?;
        let name = name.to_string_lossy();
        // holding the lock, every partial folder of the target is a killed run's
        let resumable = key.and_then(|key| {
            staging::leftovers(&parent, &name)
                .into_iter()
                // a folder, not a link to one
                .find(|dir| {
                    std::fs::symlink_metadata(dir).is_ok_and(|m| m.is_dir())
                        && std::fs::read_to_string(dir.join(RESUME_NAME)).is_ok_and(|k| k == key)
                })
        });
        staging::sweep_leftovers(&parent, &name, resumable.as_deref());
        check_replaceable(&absolute, target, inputs)?;
        let resumed = resumable.is_some();
        let staging = match resumable {
            Some(dir) => dir,
            None => {
                staging::builder(&prefix_for(&name)).tempdir_in(&parent).map_err(|e| VolumeError::io(target, e))?.keep()
            }
        };
        register(&staging);
        let folder = OutputFolder { target: absolute, staging, published: false, resumed, _lock: lock };
        if let Some(key) = key {
            let path = folder.staging.join(RESUME_NAME);
            std::fs::write(&path, key).map_err(|e| VolumeError::io(&path, e))?;
        }
        Ok(folder)
    }

    /// Leaves the partial folder where it is, for a later run of the same
    /// key to resume ([`OutputFolder::begin_resumable`]), instead of removing
    /// it: a run that failed after work worth keeping. Returns its path.
    pub fn keep_for_resume(mut self) -> PathBuf {
        let mut live = staging::live();
        staging::unregister_locked(&mut live, &self.staging);
        drop(live);
        // not published: but no longer this folder's to remove
        self.published = true;
        std::mem::take(&mut self.staging)
    }

    /// Whether this folder is the partial folder of an earlier, killed run
    /// of the same key ([`OutputFolder::begin_resumable`]), as it left it.
    pub fn resumed(&self) -> bool {
        self.resumed
    }

    /// The partial folder to write every output into.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// The folder the outputs will be published as (absolute).
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Marks the folder as mdtf's and puts it in place of the target in one
    /// step; the replaced folder, if any, is then removed.
    pub fn publish(mut self, inputs: &Inputs) -> Result<()> {
        let resume = self.staging.join(RESUME_NAME);
        if resume.exists() {
            std::fs::remove_file(&resume).map_err(|e| VolumeError::io(&resume, e))?;
        }
        write_marker(&self.staging)?;
        // Checked again: the user may have put a file into the old output meanwhile.
        check_replaceable(&self.target, &self.target, inputs)?;
        let mut live = staging::live();
        let replaced = swap_into_place(&self.staging, &self.target)?;
        staging::unregister_locked(&mut live, &self.staging);
        drop(live);
        self.published = true;
        if let Some(old) = replaced {
            // A failure here leaves a partial name that the next run sweeps.
            let _ = std::fs::remove_dir_all(old);
        }
        Ok(())
    }
}

impl Drop for OutputFolder {
    fn drop(&mut self) {
        if !self.published {
            let mut live = staging::live();
            let _ = std::fs::remove_dir_all(&self.staging);
            staging::unregister_locked(&mut live, &self.staging);
        }
    }
}

/// Moves `staging` to `target`. Returns where the replaced folder now is.
fn swap_into_place(staging: &Path, target: &Path) -> Result<Option<PathBuf>> {
    use rustix::fs::{CWD, RenameFlags, renameat_with};
    let io = |e: std::io::Error| VolumeError::io(target, e);
    if std::fs::symlink_metadata(target).is_err() {
        return match renameat_with(CWD, staging, CWD, target, RenameFlags::NOREPLACE) {
            Ok(()) => Ok(None),
            Err(rustix::io::Errno::INVAL | rustix::io::Errno::NOSYS) => {
                std::fs::rename(staging, target).map_err(io).map(|()| None)
            }
            Err(e) => Err(io(e.into())),
        };
    }
    match renameat_with(CWD, staging, CWD, target, RenameFlags::EXCHANGE) {
        Ok(()) => Ok(Some(staging.to_path_buf())),
        // A file system without the exchange: keep the old folder under a
        // partial name until the new one is in place.
        Err(rustix::io::Errno::INVAL | rustix::io::Errno::NOSYS) => {
            let parent = target.parent().unwrap_or(Path::new("."));
            let name = target.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            let old = staging::builder(&prefix_for(&name)).tempdir_in(parent).map_err(io)?.keep();
            std::fs::rename(target, &old).map_err(io)?;
            std::fs::rename(staging, target).map_err(io)?;
            Ok(Some(old))
        }
        Err(e) => Err(io(e.into())),
    }
}

/// Writes the marker listing every file under `dir`.
fn write_marker(dir: &Path) -> Result<()> {
    let mut text = format!("{MARKER_MAGIC}\n");
    for file in files_under(dir, usize::MAX)? {
        text.push_str(&file);
        text.push('\n');
    }
    let path = dir.join(MARKER_NAME);
    std::fs::write(&path, text).map_err(|e| VolumeError::io(&path, e))
}

/// The files (and links) under `dir`, relative with `/`, sorted; at most `limit`.
fn files_under(dir: &Path, limit: usize) -> Result<Vec<String>> {
    let mut out = Vec::new();
    let mut stack = vec![PathBuf::new()];
    while let Some(rel) = stack.pop() {
        let here = dir.join(&rel);
        for entry in std::fs::read_dir(&here).map_err(|e| VolumeError::io(&here, e))? {
            let entry = entry.map_err(|e| VolumeError::io(&here, e))?;
            let rel_entry = rel.join(entry.file_name());
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                stack.push(rel_entry);
            } else {
                out.push(rel_entry.to_string_lossy().replace('\\', "/"));
                if out.len() >= limit {
                    return Ok(out);
                }
            }
        }
    }
    out.sort();
    Ok(out)
}

/// Whether the folder at `target` may be replaced by a new output.
fn check_replaceable(target: &Path, shown: &Path, inputs: &Inputs) -> Result<()> {
    let meta = match std::fs::symlink_metadata(target) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(VolumeError::io(shown, e)),
    };
    if !meta.is_dir() {
        return Err(VolumeError::OutputNotAFolder { path: shown.to_path_buf() });
    }
    if let Ok(cwd) = std::env::current_dir().and_then(|c| c.canonicalize())
        && target.canonicalize().is_ok_and(|t| cwd.starts_with(t))
    {
        return Err(VolumeError::OutputHoldsWorkingDir { path: shown.to_path_buf() });
    }
    let listed = read_marker(target);
    let limit = if listed.is_some() { usize::MAX } else { FOREIGN_ENTRIES_WALKED };
    let files = files_under(target, limit)?;
    if let Some(input) = files.iter().find_map(|f| inputs.find(&target.join(f))) {
        return Err(VolumeError::OutputHoldsInput { path: shown.to_path_buf(), input: input.to_path_buf() });
    }
    if files.is_empty() {
        return Ok(());
    }
    let Some(listed) = listed else {
        return Err(VolumeError::OutputNotOurs { path: shown.to_path_buf(), entries: name_some(&files) });
    };
    let mut nested = NestedMarkers::default();
    let foreign: Vec<String> = files
        .into_iter()
        .filter(|f| f != MARKER_NAME && listed.binary_search(f).is_err() && !nested.owns(target, f))
        .collect();
    if foreign.is_empty() {
        Ok(())
    } else {
        Err(VolumeError::OutputHasForeignFiles { path: shown.to_path_buf(), entries: name_some(&foreign) })
    }
}

/// Markers of mdtf output folders nested inside another (e.g. `mdtf
/// validate`'s default `out/validate`): their files are mdtf's too.
#[derive(Default)]
struct NestedMarkers {
    read: std::collections::HashMap<String, Option<Vec<String>>>,
}

impl NestedMarkers {
    /// Whether a marker in one of the folders above `file` (relative to `root`) lists it.
    fn owns(&mut self, root: &Path, file: &str) -> bool {
        // partial outputs and locks of runs into a nested folder are mdtf's
        let left_by_mdtf = |c: &str| {
            c.starts_with(super::staging::PARTIAL_PREFIX) || (c.starts_with('.') && c.ends_with(".mdtf-lock"))
        };
        if file.split('/').any(left_by_mdtf) {
            return true;
        }
        let mut cut = file.len();
        while let Some(slash) = file[..cut].rfind('/') {
            let (dir, rest) = (&file[..slash], &file[slash + 1..]);
            let listed = self.read.entry(dir.to_string()).or_insert_with(|| read_marker(&root.join(dir)));
            if rest == MARKER_NAME && listed.is_some() {
                return true;
            }
            if listed.as_ref().is_some_and(|l| l.binary_search(&rest.to_string()).is_ok()) {
                return true;
            }
            cut = slash;
        }
        false
    }
}

/// The sorted file list of a folder's marker, if it has a valid one.
fn read_marker(dir: &Path) -> Option<Vec<String>> {
    let text = std::fs::read_to_string(dir.join(MARKER_NAME)).ok()?;
    let mut lines = text.lines();
    if lines.next() != Some(MARKER_MAGIC) {
        return None;
    }
    let mut files: Vec<String> = lines.map(str::to_string).collect();
    files.sort();
    Some(files)
}

/// "a, b, c and 4 more".
fn name_some(files: &[String]) -> String {
    let shown: Vec<&str> = files.iter().take(NAMES_SHOWN).map(String::as_str).collect();
    let rest = files.len().saturating_sub(NAMES_SHOWN);
    if rest == 0 { shown.join(", ") } else { format!("{} and {rest} more", shown.join(", ")) }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn publish_with(target: &Path, inputs: &Inputs, file: &str, bytes: &[u8]) -> Result<()> {
        let out = OutputFolder::begin(target, inputs)?;
        std::fs::write(out.path().join(file), bytes).unwrap();
        out.publish(inputs)
    }

    #[test]
    fn an_mdtf_folder_is_replaced_whole_and_anything_else_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out");
        publish_with(&target, &Inputs::new(), "a.txt", b"1").unwrap();
        publish_with(&target, &Inputs::new(), "b.txt", b"2").unwrap();
        assert!(!target.join("a.txt").exists());
        assert_eq!(std::fs::read(target.join("b.txt")).unwrap(), b"2");
        // Only the output and nothing partial beside it.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);

        std::fs::write(target.join("mine.txt"), b"user").unwrap();
        let e = publish_with(&target, &Inputs::new(), "c.txt", b"3").unwrap_err();
        assert!(matches!(e, VolumeError::OutputHasForeignFiles { .. }), "{e}");
        assert!(e.to_string().contains("mine.txt"), "{e}");
        assert_eq!(std::fs::read(target.join("mine.txt")).unwrap(), b"user");

        let user = dir.path().join("user");
        std::fs::create_dir(&user).unwrap();
        std::fs::write(user.join("scan.nii"), b"scan").unwrap();
        let e = publish_with(&user, &Inputs::new(), "c.txt", b"3").unwrap_err();
        assert!(matches!(e, VolumeError::OutputNotOurs { .. }), "{e}");
        let e = publish_with(&user, &Inputs::of(&[&user.join("scan.nii")]), "c.txt", b"3").unwrap_err();
        assert!(matches!(e, VolumeError::OutputHoldsInput { .. }), "{e}");
        assert_eq!(std::fs::read(user.join("scan.nii")).unwrap(), b"scan");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2, "no partial folder is left");
    }

    #[test]
    fn an_mdtf_folder_inside_an_mdtf_folder_is_mdtf_s_too() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out");
        publish_with(&target, &Inputs::new(), "a.txt", b"1").unwrap();
        publish_with(&target.join("validate"), &Inputs::new(), "v.txt", b"2").unwrap();
        publish_with(&target, &Inputs::new(), "b.txt", b"3").unwrap();
        assert!(!target.join("validate").exists());
        // but a file of the user's beside the nested marker is not
        publish_with(&target.join("validate"), &Inputs::new(), "v.txt", b"2").unwrap();
        std::fs::write(target.join("validate/mine.txt"), b"user").unwrap();
        let e = publish_with(&target, &Inputs::new(), "c.txt", b"4").unwrap_err();
        assert!(e.to_string().contains("validate/mine.txt"), "{e}");
    }

    #[test]
    fn an_unpublished_folder_leaves_the_old_output() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out");
        publish_with(&target, &Inputs::new(), "a.txt", b"1").unwrap();
        {
            let out = OutputFolder::begin(&target, &Inputs::new()).unwrap();
            std::fs::write(out.path().join("b.txt"), b"2").unwrap();
        }
        assert_eq!(std::fs::read(target.join("a.txt")).unwrap(), b"1");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    /// A partial folder of `target` as a killed resumable run of `key` leaves it, holding `file`.
    fn killed_run(target: &Path, key: &str, file: &str) -> PathBuf {
        let name = target.file_name().unwrap().to_string_lossy();
        let dir = staging::builder(&prefix_for(&name)).tempdir_in(target.parent().unwrap()).unwrap().keep();
        std::fs::write(dir.join(RESUME_NAME), key).unwrap();
        std::fs::write(dir.join(file), file).unwrap();
        dir
    }

    #[test]
    fn a_resumable_run_takes_over_the_partial_folder_of_a_killed_run_of_its_key_only() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out");
        let same = killed_run(&target, "key-1", "done.bin");
        let other = killed_run(&target, "key-2", "other.bin");
        let out = OutputFolder::begin_resumable(&target, &Inputs::new(), "key-1").unwrap();
        assert!(out.resumed());
        assert_eq!(out.path(), same);
        assert_eq!(std::fs::read(out.path().join("done.bin")).unwrap(), b"done.bin");
        assert!(!other.exists(), "another key's leftovers are removed");
        out.publish(&Inputs::new()).unwrap();
        assert!(target.join("done.bin").exists());
        assert!(!target.join(RESUME_NAME).exists(), "the key is not an output");
        let marker = std::fs::read_to_string(target.join(MARKER_NAME)).unwrap();
        assert!(!marker.contains(RESUME_NAME), "{marker}");
        // a different key starts afresh, marked with its own key; a plain begin never resumes
        let stale = killed_run(&target, "key-1", "stale.bin");
        let fresh = OutputFolder::begin_resumable(&target, &Inputs::new(), "key-3").unwrap();
        assert!(!fresh.resumed() && !stale.exists());
        assert_eq!(std::fs::read_to_string(fresh.path().join(RESUME_NAME)).unwrap(), "key-3");
        drop(fresh);
        let stale = killed_run(&target, "key-1", "stale.bin");
        let plain = OutputFolder::begin(&target, &Inputs::new()).unwrap();
        assert!(!plain.resumed() && !stale.exists());
        drop(plain);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "only the output is left");
    }

    #[test]
    fn an_empty_folder_may_be_used_and_a_file_may_not() {
        let dir = tempfile::tempdir().unwrap();
        let empty = dir.path().join("empty");
        std::fs::create_dir(&empty).unwrap();
        publish_with(&empty, &Inputs::new(), "a.txt", b"1").unwrap();
        assert!(empty.join(MARKER_NAME).exists());
        let file = dir.path().join("file");
        std::fs::write(&file, b"x").unwrap();
        let e = publish_with(&file, &Inputs::new(), "a.txt", b"1").unwrap_err();
        assert!(matches!(e, VolumeError::OutputNotAFolder { .. }), "{e}");
        assert_eq!(std::fs::read(&file).unwrap(), b"x");
    }
}
