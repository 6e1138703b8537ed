//! Finding the DICOM files of an input: a folder (searched recursively), a
//! DICOMDIR, a text file listing files, or one file.

use super::header::{has_dicom_magic, open};
use crate::error::{Result, VolumeError};
use dicom_dictionary_std::tags;
use std::path::{Path, PathBuf};

/// How many files one input may name.
const MAX_FILES: usize = 1 << 20;
/// How deep a folder search goes.
const MAX_DEPTH: usize = 32;

/// Whether `path` is a DICOMDIR (by name; its content is checked on read).
pub fn is_dicomdir_name(path: &Path) -> bool {
    path.file_name().is_some_and(|n| n.eq_ignore_ascii_case("DICOMDIR"))
}

/// Whether `path` is a text file listing DICOM files, one per line.
pub fn is_list_name(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("txt") || e.eq_ignore_ascii_case("lst"))
}

/// The DICOM files of `input`, and how many files a folder's walk left out
/// as not DICOM (no 'DICM' at byte 128: empty files, notes, thumbnails).
pub fn dicom_files(input: &Path) -> Result<(Vec<PathBuf>, usize)> {
    if input.is_dir() {
        let dicomdir = input.join("DICOMDIR");
        if dicomdir.is_file() {
            return Ok((dicomdir_files(&dicomdir)?, 0));
        }
        let mut files = Vec::new();
        let mut others = 0usize;
        walk(input, 0, &mut files, &mut others)?;
        if files.is_empty() {
            return Err(VolumeError::header(
                input,
                format!("the folder holds no DICOM files ({others} other files; DICOM files carry 'DICM' at byte 128)"),
            ));
        }
        files.sort();
        return Ok((files, others));
    }
    if is_dicomdir_name(input) {
        return Ok((dicomdir_files(input)?, 0));
    }
    if is_list_name(input) {
        return Ok((listed_files(input)?, 0));
    }
    Ok((vec![input.to_path_buf()], 0))
}

fn walk(dir: &Path, depth: usize, files: &mut Vec<PathBuf>, others: &mut usize) -> Result<()> {
    if depth > MAX_DEPTH {
        return Err(VolumeError::header(dir, format!("folders nest deeper than {MAX_DEPTH} levels")));
    }
    let mut entries: Vec<_> = std::fs::read_dir(dir).map_err(|e| VolumeError::io(dir, e))?.flatten().collect();
    entries.sort_by_key(|e| e.file_name());
    for e in entries {
        let name = e.file_name();
        // mdtf's own partial outputs and hidden files are never inputs
        if name.to_string_lossy().starts_with('.') {
            continue;
        }
        let Ok(kind) = e.file_type() else { continue };
        let path = e.path();
        if kind.is_dir() {
            walk(&path, depth + 1, files, others)?;
        } else if (kind.is_file() || (kind.is_symlink() && path.is_file())) && !is_dicomdir_name(&path) {
            if has_dicom_magic(&path) {
                files.push(path);
                if files.len() > MAX_FILES {
                    return Err(VolumeError::header(dir, format!("more than {MAX_FILES} DICOM files")));
                }
            } else {
                *others += 1;
            }
        }
    }
    Ok(())
}

/// The image files a DICOMDIR references, relative to its folder.
fn dicomdir_files(dicomdir: &Path) -> Result<Vec<PathBuf>> {
    let obj = open(dicomdir, false)?;
    let base = dicomdir.parent().unwrap_or(Path::new("."));
    let records = obj
        .element_opt(tags::DIRECTORY_RECORD_SEQUENCE)
        .ok()
        .flatten()
        .and_then(|e| e.items())
        .ok_or_else(|| VolumeError::header(dicomdir, "not a DICOMDIR: no DirectoryRecordSequence"))?;
    let mut files = Vec::new();
    for r in records {
        let Some(id) = r.element_opt(tags::REFERENCED_FILE_ID).ok().flatten() else { continue };
        let Ok(parts) = id.to_multi_str() else { continue };
        let mut path = base.to_path_buf();
        for p in parts.iter() {
            let p = p.trim();
            if p.is_empty() || p == ".." || p.contains('/') {
                return Err(VolumeError::header(
                    dicomdir,
                    format!("ReferencedFileID '{}' leaves its folder", parts.join("\\")),
                ));
            }
            path.push(p);
        }
        // media written on case-insensitive systems may list upper-case names
        if !path.exists() {
            let lower = PathBuf::from(path.to_string_lossy().to_lowercase());
            if lower.exists() {
                path = lower;
            }
        }
        if !path.is_file() {
            return Err(VolumeError::header(
                dicomdir,
                format!("it references {}, which does not exist", path.display()),
            ));
        }
        files.push(path);
    }
    if files.is_empty() {
        return Err(VolumeError::header(dicomdir, "the DICOMDIR references no files"));
    }
    Ok(files)
}

/// The files a text list names, one per line, relative to the list's folder.
fn listed_files(list: &Path) -> Result<Vec<PathBuf>> {
    let text = std::fs::read_to_string(list).map_err(|e| VolumeError::io(list, e))?;
    let base = list.parent().unwrap_or(Path::new("."));
    let mut files = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let path = base.join(line);
        if !path.is_file() {
            return Err(VolumeError::header(list, format!("line {}: {} is not a file", n + 1, path.display())));
        }
        files.push(path);
        if files.len() > MAX_FILES {
            return Err(VolumeError::header(list, format!("more than {MAX_FILES} files")));
        }
    }
    if files.is_empty() {
        return Err(VolumeError::header(list, "the list names no files"));
    }
    Ok(files)
}
