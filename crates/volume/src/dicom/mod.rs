//! DICOM in: a series as scanners hand it over, assembled into one volume.
//!
//! dicom-rs parses files and decodes pixel data (uncompressed, RLE, JPEG
//! baseline/extended/lossless, JPEG 2000); it has no series assembly, so this
//! module adds it:
//!
//! * input: a folder (searched recursively), a DICOMDIR, a `.txt` list of
//!   files, or one file (single- or multi-frame, enhanced CT/MR included);
//! * files are grouped by SeriesInstanceUID; with several series one must be
//!   chosen ([`DicomOptions::series`]), and the error lists them without any
//!   patient attribute;
//! * slices are ordered by ImagePositionPatient projected on the slice normal
//!   (never by file name or InstanceNumber), and checked: one image size, one
//!   orientation, no two images at one position, equal gaps, no gantry tilt;
//!   an irregular or tilted stack is refused unless [`DicomOptions::resample`]
//!   asks for interpolation onto a regular grid;
//! * samples: BitsStored, PixelRepresentation, then each slice's own
//!   RescaleSlope and RescaleIntercept (Hounsfield units for CT);
//! * geometry: PixelSpacing and the slice positions give the spacing,
//!   ImageOrientationPatient the axes, the first slice the origin, all
//!   converted from DICOM's LPS to mdtf's RAS.
//!
//! Siemens MOSAIC frames are untiled into their slices ([`mosaic`]). JPEG-LS
//! goes through CharLS (dicom-rs's `charls` feature, built with CMake).

mod bounds;
mod header;
pub mod mosaic;
mod pixels;
mod resample;
mod rle;
mod scan;
mod series;

use crate::error::{Result, VolumeError};
use crate::samples::{FileInfo, ReadOptions};
use crate::volume::{MultiField, Volume};
use crate::{Endian, SampleType};
use ndarray::Array3;
use rayon::prelude::*;
use std::path::Path;

pub use header::has_dicom_magic;
pub use scan::{is_dicomdir_name, is_list_name};
pub use series::SeriesSummary;

/// How to read a DICOM input.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DicomOptions {
    /// The series to read, by SeriesNumber or SeriesInstanceUID; needed when the input holds several.
    pub series: Option<String>,
    /// Interpolate a stack with unequal slice gaps or a gantry tilt onto a
    /// regular grid instead of refusing it.
    pub resample: bool,
}

/// Whether a folder holds DICOM: a DICOMDIR, a file with the DICM signature
/// or a `.dcm` / `.ima` name at its top level, or (without TIFF slices
/// beside them) a folder inside that is DICOM by the same rule.
pub fn folder_is_dicom(dir: &Path) -> bool {
    if dir.join("DICOMDIR").is_file() {
        return true;
    }
    let Ok(entries) = std::fs::read_dir(dir) else { return false };
    let (mut subfolders, mut has_tiff) = (Vec::new(), false);
    for e in entries.flatten().take(4096) {
        let p = e.path();
        if p.is_dir() {
            subfolders.push(p);
        } else if has_dicom_magic(&p) || crate::io::Format::from_path(&p) == Some(crate::io::Format::Dicom) {
            return true;
        } else {
            has_tiff |= crate::tiff_stack::is_tiff_name(&p);
        }
    }
    // scanner exports nest series in folders (PATIENT/STUDY/SERIES)
    !has_tiff && subfolders.iter().take(64).any(|d| folder_is_dicom(d))
}

/// The series an input holds, for a listing.
pub fn list_series(input: &Path) -> Result<Vec<SeriesSummary>> {
    let (headers, _) = read_headers(input)?;
    Ok(series::group(headers).iter().map(|g| SeriesSummary::of(g)).collect())
}

/// The image headers of the files at `input`, and a sentence on the files
/// left out, when some were.
fn read_headers(input: &Path) -> Result<(Vec<header::ImageHeader>, Option<String>)> {
    let (files, others) = scan::dicom_files(input)?;
    let headers: Vec<Option<header::ImageHeader>> =
        files.par_iter().map(|f| header::read_header(f)).collect::<Result<_>>()?;
    let without_pixels = headers.iter().filter(|h| h.is_none()).count();
    let headers: Vec<header::ImageHeader> = headers.into_iter().flatten().collect();
    if headers.is_empty() {
        return Err(VolumeError::header(
            input,
            "no DICOM image found (the files hold no pixel data: reports or a DICOMDIR alone?)",
        ));
    }
    Ok((headers, skipped_note(input, others, without_pixels)))
}

/// What the reading of `input` left out, in words (None when nothing was).
fn skipped_note(input: &Path, not_dicom: usize, without_pixels: usize) -> Option<String> {
    let files = |n: usize, what: &str| if n == 1 { format!("1 {what}file") } else { format!("{n} {what}files") };
    let mut parts = Vec::new();
    if not_dicom > 0 {
        parts.push(format!(
            "{} not DICOM (no 'DICM' at byte 128: empty files, notes, thumbnails)",
            files(not_dicom, "")
        ));
    }
    if without_pixels > 0 {
        parts.push(format!(
            "{} without pixel data (structured reports, presentation states)",
            files(without_pixels, "DICOM ")
        ));
    }
    (!parts.is_empty()).then(|| format!("{}: left out {}", input.display(), parts.join(" and ")))
}

/// Reads a DICOM series (see the module docs) as a one-field volume named
/// "value". Integer samples scaled by finite factors (checked per slice) are
/// always finite, so the NaN policy has nothing to act on.
pub fn read_dicom_with_info(input: &Path, opts: &ReadOptions) -> Result<(MultiField, FileInfo)> {
    let (headers, skipped) = read_headers(input)?;
    let files = series::choose(input, series::group(headers), opts.dicom.series.as_deref())?;
    let mut checked: Vec<&str> = Vec::new();
    for h in &files {
        if !checked.contains(&h.transfer_syntax.as_str()) {
            header::check_decodable(h)?;
            checked.push(&h.transfer_syntax);
        }
    }
    let mut layout = series::layout(input, &files, opts.dicom.resample)?;
    layout.warnings.extend(skipped);
    pixels::check_native_sizes(&files)?;
    let first = &files[0];
    let (cols, rows) = first.slice_dims();
    let samples = crate::limits::check_dims(input, &[cols as u64, rows as u64, layout.slices.len() as u64], 1)?;
    // zeroed pages come from the allocator untouched, so the first writes
    // (by the parallel decoders) are what maps them, not one thread here
    let mut stack = vec![0.0f32; samples];
    pixels::decode_into(&files, &layout.slices, &mut stack)?;
    let samples = match &layout.resampling {
        Some(plan) => {
            crate::limits::check_dims(input, &[cols as u64, rows as u64, plan.nz as u64], 2)?;
            resample::resample(&stack, cols, rows, &layout.slices, plan)
        }
        None => stack,
    };
    let data = Array3::from_shape_vec(layout.geometry.shape(), samples)
        .map_err(|e| VolumeError::header(input, e.to_string()))?;
    let volume = Volume::new(layout.geometry.clone(), data)?;
    let info = file_info(&files, &layout);
    Ok((MultiField::from(volume), info))
}

/// The units of a series: lengths in mm (DICOM's), values in the Rescale
/// Type when given, else HU for a CT (PS3.3 C.8.2.1: a CT's rescaled
/// values are Hounsfield units), else unstated.
fn units_of(first: &header::ImageHeader) -> crate::Units {
    let rescale_type = first.rescale_type.trim();
    let value = if !rescale_type.is_empty() {
        Some(rescale_type.to_string())
    } else if first.modality.trim() == "CT" {
        Some("HU".to_string())
    } else {
        None
    };
    crate::Units { value, length: Some("mm".into()) }
}

/// The values a series' Pixel Padding Value (and Range Limit) stand for
/// once rescaled, over every slice's rescale (`scales`: slope, intercept):
/// the smallest range holding them all.
fn padding_of(first: &header::ImageHeader, scales: &[(f64, f64)]) -> Option<[f64; 2]> {
    let (value, limit) = first.padding?;
    let ends = [value, limit.unwrap_or(value)];
    let rescaled = scales.iter().flat_map(|&(slope, intercept)| ends.map(|v| slope * v as f64 + intercept));
    let (lo, hi) = rescaled.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(v), h.max(v)));
    (lo <= hi).then_some([lo, hi])
}

/// What `mdtf info` shows of a series: never a patient attribute.
fn file_info(files: &[header::ImageHeader], layout: &series::Layout) -> FileInfo {
    let first = &files[0];
    let sample_type = match (first.bits_allocated, first.signed) {
        (1 | 8, false) => SampleType::U8,
        (8, true) => SampleType::I8,
        (16, false) => SampleType::U16,
        (16, true) => SampleType::I16,
        (_, false) => SampleType::U32,
        (_, true) => SampleType::I32,
    };
    let scales: Vec<(f64, f64)> = layout.slices.iter().map(|s| s.rescale).collect();
    let constant = scales.windows(2).all(|w| w[0] == w[1]);
    let scale = (constant && scales[0] != (1.0, 0.0)).then_some(scales[0]);
    // `compressed` means zlib; JPEG and RLE are named by the transfer syntax line
    let compressed = first.transfer_syntax == bounds::DEFLATED;
    let what = if files.len() == 1 && first.frames.len() > 1 {
        format!("DICOM, one file of {} frames", first.frames.len())
    } else if files.len() == 1 {
        "DICOM, one image".to_string()
    } else {
        format!("DICOM series of {} files", files.len())
    };
    let mut details = vec![
        ("modality".to_string(), if first.modality.is_empty() { "unknown".into() } else { first.modality.clone() }),
        ("series".to_string(), SeriesSummary::of(files).line()),
        ("transfer syntax".to_string(), first.transfer_syntax_name()),
        ("bits stored".to_string(), format!("{} of {}", first.bits_stored, first.bits_allocated)),
    ];
    if first.bits_allocated == 1 {
        details.push(("binary".to_string(), "1-bit samples (a segmentation mask): read as 0 and 1".to_string()));
    }
    if let Some(m) = &first.mosaic {
        details.push((
            "mosaic".to_string(),
            format!(
                "Siemens MOSAIC of {} slices in {} x {} tiles of {}x{}",
                m.count, m.tiles_per_side, m.tiles_per_side, m.tile_cols, m.tile_rows
            ),
        ));
    }
    if let Some((value, limit)) = first.padding {
        let stored = limit.map_or(format!("{value}"), |l| format!("{value} to {l}"));
        details.push(("pixel padding".to_string(), format!("stored {stored}: no data (left out by mdtf run)")));
    }
    if let Some(t) = first.slice_thickness {
        details.push(("slice thickness".to_string(), format!("{} mm", series::mm(t))));
    }
    if !constant {
        let (lo_s, hi_s) = scales.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), s| (l.min(s.0), h.max(s.0)));
        let (lo_i, hi_i) = scales.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), s| (l.min(s.1), h.max(s.1)));
        details.push(("rescale".to_string(), format!("per slice: slope {lo_s}..{hi_s}, intercept {lo_i}..{hi_i}")));
    }
    FileInfo {
        format: what,
        sample_type,
        // the file's byte order: only Explicit VR Big Endian (retired) stores big-endian
        endian: if first.transfer_syntax == pixels::EXPLICIT_VR_BIG_ENDIAN { Endian::Big } else { Endian::Little },
        compressed,
        scale,
        warnings: layout.warnings.clone(),
        details,
        units: units_of(first),
        padding: padding_of(first, &scales),
    }
}
