//! `.hdr` + `.img` pairs (NIfTI-1, NIfTI-2 and Analyze 7.5): which file is
//! which, and writing both.
//!
//! A pair's header does not name its data file: the two share a stem. So the
//! two files cannot be swapped in as one unit, as a `.nhdr` and the data file
//! it names are. Each is written to a partial file and renamed into place
//! when complete, the `.img` first and the `.hdr` last, under the output
//! lock: a failed write leaves the old pair, and a kill between the two
//! renames leaves the new samples beside the old header.

use crate::error::{Result, VolumeError};
use crate::output::{OutputLock, StagedFile, sweep};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The name's extensions of a pair's header and data file, with and without gzip.
const HEADER_EXTS: [&str; 2] = [".hdr", ".hdr.gz"];
const DATA_EXTS: [&str; 2] = [".img", ".img.gz"];

/// The path's name split at a pair extension: (stem, extension as written, is a header).
fn split(path: &Path) -> Option<(String, String, bool)> {
    let name = path.file_name()?.to_string_lossy().into_owned();
    let lower = name.to_ascii_lowercase();
    for (exts, is_header) in [(HEADER_EXTS, true), (DATA_EXTS, false)] {
        // the longer (gzip) extension first
        for ext in exts.iter().rev() {
            if lower.ends_with(ext) && lower.len() > ext.len() {
                let cut = name.len() - ext.len();
                return Some((name[..cut].to_string(), name[cut..].to_string(), is_header));
            }
        }
    }
    None
}

/// Whether `path` names a pair's header or data file (`.hdr`, `.img`, or either `.gz`).
pub(crate) fn is_pair_name(path: &Path) -> bool {
    split(path).is_some()
}

/// `ext` (".hdr", ".IMG.gz", ...) turned into the partner's extension, in the same case.
fn partner_ext(ext: &str) -> String {
    let swap = |s: &str| match s {
        "hdr" => "img",
        "img" => "hdr",
        "HDR" => "IMG",
        "IMG" => "HDR",
        "Hdr" => "Img",
        "Img" => "Hdr",
        other if other.eq_ignore_ascii_case("hdr") => "img",
        _ => "hdr",
    };
    let body = &ext[1..4];
    format!(".{}{}", swap(body), &ext[4..])
}

/// The partner files `path` may have, the likeliest first (same case and
/// compression, then the other compression).
fn partners(path: &Path) -> Vec<PathBuf> {
    let Some((stem, ext, _)) = split(path) else { return Vec::new() };
    let dir = path.parent().unwrap_or(Path::new(""));
    let same = partner_ext(&ext);
    let other = if same.to_ascii_lowercase().ends_with(".gz") {
        same[..same.len() - 3].to_string()
    } else {
        format!("{same}.gz")
    };
    vec![dir.join(format!("{stem}{same}")), dir.join(format!("{stem}{other}"))]
}

/// The header of the pair `path` belongs to: `path` itself unless it names a
/// `.img`, whose `.hdr` must exist beside it.
pub(crate) fn header_file(path: &Path) -> Result<PathBuf> {
    match split(path) {
        Some((_, _, false)) => partners(path).into_iter().find(|p| p.is_file()).ok_or_else(|| {
            VolumeError::header(
                path,
                format!(
                    "the header of this .img is missing: a NIfTI or Analyze pair keeps it in {} beside it",
                    expected_partner_name(path)
                ),
            )
        }),
        _ => Ok(path.to_path_buf()),
    }
}

/// The data file beside the pair header `header`, if it exists.
pub(crate) fn data_file(header: &Path) -> Option<PathBuf> {
    partners(header).into_iter().find(|p| p.is_file())
}

/// The name the partner file of `path` would have (the `.img` of a `.hdr`).
pub(crate) fn expected_partner_name(path: &Path) -> String {
    partners(path).first().and_then(|p| p.file_name()).map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
}

/// The partner files of `path` that exist (for the input set a
/// writer checks its targets against).
pub(crate) fn pair_files(path: &Path) -> Vec<PathBuf> {
    partners(path).into_iter().filter(|p| p.is_file()).collect()
}

/// The (header, data) files a write to `path` makes: `x.hdr` and `x.img`,
/// both gzip-compressed when `path` ends in `.gz`.
pub(crate) fn planned_files(path: &Path) -> Option<(PathBuf, PathBuf)> {
    let (stem, ext, is_header) = split(path)?;
    let dir = path.parent().unwrap_or(Path::new(""));
    let partner = dir.join(format!("{stem}{}", partner_ext(&ext)));
    Some(if is_header { (path.to_path_buf(), partner) } else { (partner, path.to_path_buf()) })
}

/// Writes a pair at `path` (either name): `header` bytes to the `.hdr`, the
/// samples `fill` writes to the `.img`, gzip-compressed when the names end
/// in `.gz`; the `.img` is put in place first, the `.hdr` last.
pub(crate) fn write(
    path: &Path,
    header: &[u8],
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    let (header_path, data_path) =
        planned_files(path).ok_or_else(|| VolumeError::UnwritableFormat { path: path.to_path_buf() })?;
    let gz = |p: &Path| p.to_string_lossy().to_ascii_lowercase().ends_with(".gz");
    let _lock = OutputLock::acquire(&header_path)?;
    sweep(&header_path);
    sweep(&data_path);
    let data = StagedFile::write(&data_path, |w| {
        if gz(&data_path) {
            let mut enc = flate2::write::GzEncoder::new(w, flate2::Compression::fast());
            fill(&mut enc)?;
            enc.finish().map(|_| ())
        } else {
            fill(w)
        }
    })?;
    let head = StagedFile::write(&header_path, |w| {
        if gz(&header_path) {
            let mut enc = flate2::write::GzEncoder::new(w, flate2::Compression::fast());
            enc.write_all(header)?;
            enc.finish().map(|_| ())
        } else {
            w.write_all(header)
        }
    })?;
    data.publish()?;
    head.publish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pair_is_named_by_either_file_in_its_own_case_and_compression() {
        let (h, d) = planned_files(Path::new("dir/brain.HDR")).unwrap();
        assert_eq!((h, d), (PathBuf::from("dir/brain.HDR"), PathBuf::from("dir/brain.IMG")));
        let (h, d) = planned_files(Path::new("t1.img.gz")).unwrap();
        assert_eq!((h, d), (PathBuf::from("t1.hdr.gz"), PathBuf::from("t1.img.gz")));
        assert!(planned_files(Path::new("t1.nii")).is_none() && !is_pair_name(Path::new(".hdr")));
        assert_eq!(partners(Path::new("a.hdr")), [PathBuf::from("a.img"), PathBuf::from("a.img.gz")]);
    }
}
