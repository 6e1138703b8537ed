//! Reading and writing by file name. On read the content picks the format
//! (DICM preamble, NRRD and NIfTI magic, MetaImage keys, TIFF byte order
//! mark), the extension where the content does not tell; on write the
//! extension does.

use crate::dicom::read_dicom_with_info;
use crate::dtype::SampleType;
use crate::error::{Result, VolumeError};
use crate::metaimage::{read_metaimage_with_info, write_metaimage};
use crate::nifti::{read_nifti_with_info, write_nifti};
use crate::nrrd::{Encoding, read_nrrd_with_info, write_nrrd};
use crate::output::Inputs;
use crate::samples::{FileInfo, ReadOptions};
use crate::tiff_stack::read_tiff_with_info;
use crate::volume::{MultiField, Volume};
use std::path::Path;

/// A file format mdtf reads and writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// `.nii`
    Nifti,
    /// `.nii.gz`
    NiftiGz,
    /// `.hdr` + `.img` (a NIfTI-1 or NIfTI-2 pair, or Analyze 7.5 on read; `.gz` on both allowed)
    NiftiPair,
    /// `.nrrd` (attached header, raw encoding)
    Nrrd,
    /// `.nhdr` + `.raw` (detached header)
    Nhdr,
    /// `.mha` (MetaImage, header and data in one file)
    Mha,
    /// `.mhd` + `.raw` (MetaImage, detached header)
    Mhd,
    /// `.tif` / `.tiff` (a stack of pages; read only; a folder of TIFF slices is read too)
    Tiff,
    /// DICOM (`.dcm`, `.ima`, a DICOMDIR, a folder, or a `.txt` list of files; read only)
    Dicom,
    /// OME-Zarr (`.ome.zarr`, `.zarr`: a folder; NGFF 0.4 and 0.5 read, 0.5 written)
    OmeZarr,
}

impl Format {
    /// The format a path's extension names, if any.
    pub fn from_path(path: &Path) -> Option<Format> {
        let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
        if name.ends_with(".nii.gz") {
            Some(Format::NiftiGz)
        } else if name.ends_with(".nii") {
            Some(Format::Nifti)
        } else if crate::nifti::is_pair_name(path) {
            Some(Format::NiftiPair)
        } else if name.ends_with(".nrrd") {
            Some(Format::Nrrd)
        } else if name.ends_with(".nhdr") {
            Some(Format::Nhdr)
        } else if name.ends_with(".mha") {
            Some(Format::Mha)
        } else if name.ends_with(".mhd") {
            Some(Format::Mhd)
        } else if name.ends_with(".tif") || name.ends_with(".tiff") {
            Some(Format::Tiff)
        } else if name.ends_with(".dcm") || name.ends_with(".ima") || name == "dicomdir" {
            Some(Format::Dicom)
        } else if name.ends_with(".zarr") {
            Some(Format::OmeZarr)
        } else {
            None
        }
    }

    /// The format the first bytes of a file show, if they show one. Gzip
    /// data shows none (it may be NIfTI or anything else compressed).
    pub fn from_content(path: &Path) -> Option<Format> {
        use std::io::Read;
        let mut head = Vec::with_capacity(512);
        std::fs::File::open(path).ok()?.take(512).read_to_end(&mut head).ok()?;
        let at = |range: std::ops::Range<usize>| head.get(range);
        if at(128..132) == Some(b"DICM") {
            return Some(Format::Dicom);
        }
        if head.starts_with(b"NRRD000") {
            return Some(Format::Nrrd);
        }
        if [b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"].iter().any(|m| head.starts_with(*m)) {
            return Some(Format::Tiff);
        }
        if crate::nifti::header::has_nifti_magic(&head) {
            // a pair's header (ni1, ni2) is named .hdr: the extension tells which
            return Some(if crate::nifti::is_pair_name(path) { Format::NiftiPair } else { Format::Nifti });
        }
        if crate::metaimage::looks_like_metaimage(&head) {
            return Some(Format::Mha);
        }
        None
    }

    /// The extension including its dot, e.g. ".nii.gz".
    pub fn extension(self) -> &'static str {
        match self {
            Format::Nifti => ".nii",
            Format::NiftiGz => ".nii.gz",
            Format::NiftiPair => ".hdr",
            Format::Nrrd => ".nrrd",
            Format::Nhdr => ".nhdr",
            Format::Mha => ".mha",
            Format::Mhd => ".mhd",
            Format::Tiff => ".tif",
            Format::Dicom => ".dcm",
            Format::OmeZarr => ".ome.zarr",
        }
    }

    /// The format's usual name, e.g. "NIfTI" or "OME-Zarr".
    pub fn name(self) -> &'static str {
        match self {
            Format::Nifti | Format::NiftiGz | Format::NiftiPair => "NIfTI",
            Format::Nrrd | Format::Nhdr => "NRRD",
            Format::Mha | Format::Mhd => "MetaImage",
            Format::Tiff => "TIFF",
            Format::Dicom => "DICOM",
            Format::OmeZarr => "OME-Zarr",
        }
    }

    /// The format [`read`] reads `path` as (None: none it reads): an
    /// OME-Zarr store, a folder of DICOM or TIFF slices, a DICOM file list,
    /// else by content, else by extension.
    pub fn of_input(path: &Path) -> Option<Format> {
        if crate::ome_zarr::is_store(path) {
            Some(Format::OmeZarr)
        } else if path.is_dir() {
            let named_zarr = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("zarr"));
            Some(if crate::dicom::folder_is_dicom(path) {
                Format::Dicom
            } else if named_zarr {
                // read_with_info names what a store lacks
                Format::OmeZarr
            } else {
                Format::Tiff
            })
        } else if crate::dicom::is_list_name(path) {
            Some(Format::Dicom)
        } else {
            Format::from_content(path).or_else(|| Format::from_path(path))
        }
    }
}

/// Reads any supported file (by content, else extension) as a multi-field volume.
pub fn read(path: &Path, opts: &ReadOptions) -> Result<MultiField> {
    read_with_info(path, opts).map(|(mf, _)| mf)
}

/// [`read`], also returning how the file stores its samples.
pub fn read_with_info(path: &Path, opts: &ReadOptions) -> Result<(MultiField, FileInfo)> {
    let is_store = crate::ome_zarr::is_store(path);
    match Format::of_input(path) {
        Some(Format::OmeZarr) if is_store => {
            let image = crate::ome_zarr::ZarrImage::open(path, opts.level)?;
            image.check_size()?;
            let mf = image.read(0..image.geometry().dims[2], opts.nan)?;
            Ok((mf, image.info().clone()))
        }
        Some(Format::Nifti | Format::NiftiGz | Format::NiftiPair) => read_nifti_with_info(path, opts),
        Some(Format::Dicom) => read_dicom_with_info(path, opts),
        Some(Format::Nrrd | Format::Nhdr) => read_nrrd_with_info(path, opts),
        Some(Format::Mha | Format::Mhd) => read_metaimage_with_info(path, opts),
        Some(Format::Tiff) => read_tiff_with_info(path, opts),
        Some(Format::OmeZarr) => Err(VolumeError::header(
            path,
            "not a Zarr store (a folder holding zarr.json, or .zgroup/.zarray for Zarr v2)",
        )),
        None => Err(VolumeError::UnknownFormat { path: path.to_path_buf() }),
    }
}

/// Reads any supported file as a scalar volume; a multi-field file is an error.
pub fn read_scalar(path: &Path, opts: &ReadOptions) -> Result<Volume> {
    read(path, opts)?.into_scalar().map_err(|e| VolumeError::header(path, e.to_string()))
}

/// How to store samples on write.
#[derive(Debug, Clone, Copy)]
pub struct WriteOptions {
    /// Sample type on disk (f32, u8, u16; integer types need exact values).
    pub ty: SampleType,
    /// Gzip the NRRD data (NIfTI compresses by the `.gz` extension instead).
    pub gzip: bool,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions { ty: SampleType::F32, gzip: false }
    }
}

/// Writes a (multi-field) volume by extension, atomically, refusing to
/// overwrite any of `inputs` (compared by identity, detached data files
/// included, on both sides).
pub fn write(path: &Path, mf: &MultiField, opts: &WriteOptions, inputs: &[&Path]) -> Result<()> {
    let inputs = Inputs::of(inputs);
    inputs.refuse_target(path)?;
    let data_file = match Format::from_path(path) {
        Some(Format::Mhd) => crate::metaimage::metaimage_planned_data_file(path),
        Some(Format::NiftiPair) => crate::nifti::planned_partner(path),
        _ => crate::nrrd::planned_data_file(path, opts.gzip),
    };
    if let Some(data) = data_file {
        inputs.refuse_target(&data)?;
    }
    let encoding = if opts.gzip { Encoding::Gzip } else { Encoding::Raw };
    match Format::from_path(path) {
        Some(Format::Nifti | Format::NiftiGz | Format::NiftiPair) => write_nifti(path, mf, opts.ty),
        Some(Format::Nrrd | Format::Nhdr) => write_nrrd(path, mf, opts.ty, encoding),
        Some(Format::Mha | Format::Mhd) => write_metaimage(path, mf, opts.ty),
        Some(Format::OmeZarr) => crate::ome_zarr::write_ome_zarr(path, mf, opts.ty, &inputs),
        Some(Format::Tiff) => Err(VolumeError::header(
            path,
            "mdtf reads TIFF stacks but does not write them: write .nrrd, .nii.gz or .mha (Fiji opens all three)",
        )),
        Some(Format::Dicom) => Err(VolumeError::header(
            path,
            "mdtf reads DICOM but does not write it: write .nii.gz, .nrrd or .mha (3D Slicer and ITK-SNAP open all three)",
        )),
        None => Err(VolumeError::UnwritableFormat { path: path.to_path_buf() }),
    }
}

/// Writes a scalar volume by extension (see [`write`]).
pub fn write_volume(path: &Path, v: &Volume, opts: &WriteOptions, inputs: &[&Path]) -> Result<()> {
    let mf = MultiField::from(v.clone());
    write(path, &mf, opts, inputs)
}

/// Where a writer by slabs gets each slab's samples: `slab(z, samples)`
/// sets `samples` (x-fastest) to those of planes `z`. `samples` holds the
/// slab before's, whose memory it can reuse (fresh memory of a slab's size
/// page-faults, which costs about as much as writing it).
pub type SlabSamples<'a> = dyn FnMut(std::ops::Range<usize>, &mut Vec<f32>) -> std::io::Result<()> + 'a;
