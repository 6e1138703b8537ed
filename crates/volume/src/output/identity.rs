//! Files by identity (device and inode), so that no output can be an input
//! under another name: a relative path, a symbolic link, a hard link, or the
//! detached data file of a header.

use crate::error::{Result, VolumeError};
use std::path::{Path, PathBuf};

/// How many files a folder input may contribute before the walk stops; a
/// folder of inputs is a pack or a stage's output, never a whole disk.
const MAX_FOLDER_FILES: usize = 100_000;

/// The identity of a file on this machine: (device, inode) on Unix, the
/// canonical path elsewhere.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct FileId(Id);

#[cfg(unix)]
type Id = (u64, u64);
#[cfg(not(unix))]
type Id = PathBuf;

impl FileId {
    #[cfg(unix)]
    pub(crate) fn from_dev_ino(dev: u64, ino: u64) -> FileId {
        FileId((dev, ino))
    }

    /// The identity of the file at `path` (symbolic links followed), or
    /// `None` when nothing is there.
    pub fn of(path: &Path) -> Option<FileId> {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            std::fs::metadata(path).ok().map(|m| FileId((m.dev(), m.ino())))
        }
        #[cfg(not(unix))]
        {
            path.canonicalize().ok().map(FileId)
        }
    }
}

/// Every file a command reads: volumes, their detached data files, manifests,
/// textures, transfer-function and pipeline files. Writers check each file
/// they will write against this set.
#[derive(Debug, Default, Clone)]
pub struct Inputs {
    files: Vec<(FileId, PathBuf)>,
}

impl Inputs {
    /// An empty set (a command that reads nothing, such as `synth`).
    pub fn new() -> Inputs {
        Inputs::default()
    }

    /// The set of `paths`, each added with [`Inputs::add`].
    pub fn of(paths: &[&Path]) -> Inputs {
        let mut set = Inputs::new();
        for p in paths {
            set.add(p);
        }
        set
    }

    /// Adds a file and the data files its header names (a `.nhdr`) or its
    /// pair partner (a `.hdr` or `.img`), or every
    /// file under a folder. A path that does not exist adds nothing: the
    /// reader reports it.
    pub fn add(&mut self, path: &Path) {
        if path.is_dir() {
            self.add_folder(path);
            return;
        }
        self.add_file(path);
        let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
        let data_files = match ext.as_str() {
            "nhdr" | "nrrd" => crate::nrrd::detached_data_files(path),
            "mhd" | "mha" => crate::metaimage::metaimage_data_files(path),
            _ if crate::nifti::is_pair_name(path) => crate::nifti::pair_files(path),
            _ => Vec::new(),
        };
        for data in data_files {
            self.add_file(&data);
        }
    }

    /// Adds one file as it is.
    pub fn add_file(&mut self, path: &Path) {
        if let Some(id) = FileId::of(path)
            && !self.files.iter().any(|(i, _)| *i == id)
        {
            self.files.push((id, path.to_path_buf()));
        }
    }

    fn add_folder(&mut self, dir: &Path) {
        let mut stack = vec![dir.to_path_buf()];
        let mut seen = 0usize;
        while let Some(d) = stack.pop() {
            let Ok(entries) = std::fs::read_dir(&d) else { continue };
            for entry in entries.flatten() {
                seen += 1;
                if seen > MAX_FOLDER_FILES {
                    return;
                }
                let p = entry.path();
                match entry.file_type() {
                    Ok(t) if t.is_dir() => stack.push(p),
                    Ok(_) => self.add_file(&p),
                    Err(_) => {}
                }
            }
        }
    }

    /// The input that `path` is (by identity), if any.
    pub fn find(&self, path: &Path) -> Option<&Path> {
        let id = FileId::of(path)?;
        self.files.iter().find(|(i, _)| *i == id).map(|(_, p)| p.as_path())
    }

    /// Refuses `target` when it is one of the inputs.
    pub fn refuse_target(&self, target: &Path) -> Result<()> {
        match self.find(target) {
            Some(input) => {
                Err(VolumeError::WouldOverwriteInput { path: target.to_path_buf(), input: input.to_path_buf() })
            }
            None => Ok(()),
        }
    }

    /// True when no file was added.
    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_input_is_found_under_any_name() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.nii");
        std::fs::write(&input, b"x").unwrap();
        let set = Inputs::of(&[&input]);
        assert!(set.refuse_target(&dir.path().join(".").join("in.nii")).is_err());
        assert!(set.refuse_target(&dir.path().join("new.nii")).is_ok());
        let linked = dir.path().join("hard.nii");
        std::fs::hard_link(&input, &linked).unwrap();
        assert_eq!(set.find(&linked), Some(input.as_path()));
    }

    #[test]
    fn a_detached_header_brings_its_data_file() {
        let dir = tempfile::tempdir().unwrap();
        let hdr = dir.path().join("a.nhdr");
        std::fs::write(&hdr, "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1 1 1\nencoding: raw\ndata file: b.raw\n")
            .unwrap();
        std::fs::write(dir.path().join("b.raw"), [7u8]).unwrap();
        let set = Inputs::of(&[&hdr]);
        assert!(set.find(&dir.path().join("b.raw")).is_some());
    }

    #[test]
    fn a_folder_brings_every_file_under_it() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        std::fs::write(dir.path().join("sub/t.raw"), b"x").unwrap();
        let set = Inputs::of(&[dir.path()]);
        assert!(set.find(&dir.path().join("sub/t.raw")).is_some());
    }
}
