//! Atomic output: write to a temporary file beside the target, then rename.
//! A failed write leaves no partial file and the old target, if any, intact.

use crate::error::{Result, VolumeError};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The folder a file lives in ("." for a bare file name).
fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Refuses `target` if it is the same file as any of `inputs`.
pub fn refuse_overwriting_inputs(target: &Path, inputs: &[&Path]) -> Result<()> {
    let Ok(t) = target.canonicalize() else {
        return Ok(()); // the target does not exist yet
    };
    for input in inputs {
        if input.canonicalize().is_ok_and(|i| i == t) {
            return Err(VolumeError::WouldOverwriteInput { path: target.to_path_buf() });
        }
    }
    Ok(())
}

/// Writes `bytes` produced by `fill` to `path` atomically.
pub fn write_file_atomically(path: &Path, fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> Result<()> {
    let dir = parent_dir(path);
    let mut tmp =
        tempfile::Builder::new().prefix(".mdtf-partial-").tempfile_in(&dir).map_err(|e| VolumeError::io(path, e))?;
    {
        let mut w = std::io::BufWriter::new(tmp.as_file_mut());
        fill(&mut w).map_err(|e| VolumeError::io(path, e))?;
        w.flush().map_err(|e| VolumeError::io(path, e))?;
    }
    publish_permissions(tmp.path(), path);
    tmp.persist(path).map_err(|e| VolumeError::io(path, e.error))?;
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

/// A temporary folder beside `output` to build a whole output folder in;
/// hand it to [`publish_dir`] when everything is written. Dropped without
/// publishing, it is removed and `output` is untouched.
pub fn staging_dir(output: &Path) -> Result<tempfile::TempDir> {
    let parent = parent_dir(output);
    std::fs::create_dir_all(&parent).map_err(|e| VolumeError::io(&parent, e))?;
    tempfile::Builder::new().prefix(".mdtf-partial-").tempdir_in(&parent).map_err(|e| VolumeError::io(output, e))
}

/// Moves a finished staging folder to `output`, replacing an older `output` only now.
pub fn publish_dir(staging: tempfile::TempDir, output: &Path) -> Result<()> {
    let tmp_path = staging.keep();
    let io = |e: std::io::Error| VolumeError::io(output, e);
    if output.exists() {
        let old = output.with_extension(format!("old-{}", std::process::id()));
        std::fs::rename(output, &old).map_err(io)?;
        std::fs::rename(&tmp_path, output).map_err(io)?;
        std::fs::remove_dir_all(&old).map_err(io)?;
    } else {
        std::fs::rename(&tmp_path, output).map_err(io)?;
    }
    Ok(())
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

    #[cfg(unix)]
    #[test]
    fn outputs_are_readable_by_others_like_any_new_file() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("new.bin");
        write_file_atomically(&target, |w| w.write_all(b"x")).unwrap();
        assert_eq!(std::fs::metadata(&target).unwrap().permissions().mode() & 0o777, 0o644);
    }

    #[test]
    fn an_input_is_never_a_target() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.nii");
        std::fs::write(&input, b"x").unwrap();
        let same = dir.path().join(".").join("in.nii");
        assert!(refuse_overwriting_inputs(&same, &[&input]).is_err());
        assert!(refuse_overwriting_inputs(&dir.path().join("new.nii"), &[&input]).is_ok());
    }
}
