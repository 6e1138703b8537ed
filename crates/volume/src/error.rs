//! Typed errors of volume I/O. Every variant names the file it is about.

use std::path::{Path, PathBuf};

/// Everything that can go wrong reading, converting or writing a volume.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    /// The operating system refused to open, read or write the file.
    #[error("{path}: {cause}")]
    Io {
        /// The file concerned.
        path: PathBuf,
        /// The underlying I/O error.
        cause: std::io::Error,
    },
    /// The file has no bytes at all.
    #[error("{path}: the file is empty")]
    Empty {
        /// The file concerned.
        path: PathBuf,
    },
    /// The header is malformed or inconsistent.
    #[error("{path}: bad header: {message}")]
    Header {
        /// The file concerned.
        path: PathBuf,
        /// What is wrong, in words.
        message: String,
    },
    /// A DICOM stack whose slices do not form a regular grid (uneven gaps,
    /// a gantry tilt): read only with resampling.
    #[error(
        "{path}: bad header: {found}; the slices do not form a regular grid, which mdtf will not guess at: read it with resampling to interpolate it onto a regular grid of {gap_mm} mm (`--resample` for mdtf info, convert and the stage commands; `--set input.resample=true` for mdtf run, or `resample = true` in the pipeline's [input])"
    )]
    NeedsResampling {
        /// The series (folder, list or file) concerned.
        path: PathBuf,
        /// What makes it irregular, e.g. "gantry tilt 14.0 degrees (...)".
        found: String,
        /// The slice gap of the regular grid resampling would make, mm, as text.
        gap_mm: String,
    },
    /// Fewer sample bytes than the header promises.
    #[error(
        "{path}: truncated data: the header (or the raw layout given) promises {expected} bytes of samples, the file holds {found}"
    )]
    Truncated {
        /// The file concerned.
        path: PathBuf,
        /// Bytes the header promises.
        expected: u64,
        /// Bytes actually present.
        found: u64,
    },
    /// More sample bytes than the header describes (raw data only).
    #[error(
        "{path}: header/data size mismatch: the header describes {expected} bytes of samples, the file holds {found}"
    )]
    SizeMismatch {
        /// The file concerned.
        path: PathBuf,
        /// Bytes the header describes.
        expected: u64,
        /// Bytes actually present.
        found: u64,
    },
    /// The sample type is not one mdtf reads or writes.
    #[error("{path}: unsupported data type {name} (supported: {supported})")]
    UnsupportedType {
        /// The file concerned.
        path: PathBuf,
        /// The type as the file names it.
        name: String,
        /// The types that are supported here.
        supported: &'static str,
    },
    /// NRRD encoding other than raw, gzip or ascii.
    #[error("{path}: unsupported NRRD encoding '{encoding}' (supported: raw, gzip, ascii)")]
    UnsupportedEncoding {
        /// The file concerned.
        path: PathBuf,
        /// The encoding the header names.
        encoding: String,
    },
    /// A dimension is zero, negative, or the volume is not 3D / 4D.
    #[error("{path}: bad dimensions {dims}: {message}")]
    BadDimensions {
        /// The file concerned.
        path: PathBuf,
        /// The dimensions as read.
        dims: String,
        /// Why they are refused.
        message: String,
    },
    /// The volume would not fit in memory.
    #[error("{path}: the volume {dims} would need {needed} of memory as f32 but only {available} is available")]
    TooLarge {
        /// The file concerned.
        path: PathBuf,
        /// The dimensions as read.
        dims: String,
        /// Bytes needed, human readable.
        needed: String,
        /// Bytes available, human readable.
        available: String,
    },
    /// NaN or infinite samples, refused unless the caller asked to zero them.
    #[error("{path}: {count} samples are NaN or infinite (set input.nan = \"zero\" to replace them with 0)")]
    NonFinite {
        /// The file concerned.
        path: PathBuf,
        /// How many samples are not finite.
        count: u64,
    },
    /// The gzip stream is corrupt.
    #[error("{path}: corrupt gzip data: {cause}")]
    Gzip {
        /// The file concerned.
        path: PathBuf,
        /// What the decompressor reported.
        cause: std::io::Error,
    },
    /// The file name does not say which format to use.
    #[error(
        "{path}: neither the content nor the extension names a format mdtf reads (NIfTI .nii/.nii.gz, NRRD .nrrd/.nhdr, MetaImage .mha/.mhd, TIFF .tif, DICOM .dcm or a folder; raw data needs its layout given explicitly)"
    )]
    UnknownFormat {
        /// The file concerned.
        path: PathBuf,
    },
    /// An output's extension names no format mdtf writes.
    #[error(
        "{path}: the extension names no format mdtf writes: .nii, .nii.gz, .nrrd, .nhdr, .mha, .mhd or .ome.zarr (pictures come from mdtf preview and the histogram figures)"
    )]
    UnwritableFormat {
        /// The file concerned.
        path: PathBuf,
    },
    /// Writing would overwrite an input of the run.
    #[error("{path}: refusing to overwrite {input}, an input of this run (choose another output name)")]
    WouldOverwriteInput {
        /// The file that would be written.
        path: PathBuf,
        /// The input it is (the same file under this name).
        input: PathBuf,
    },
    /// Another run holds the lock of this output.
    #[error("{path}: another mdtf run is writing this output now; wait for it to finish or choose another output")]
    OutputBusy {
        /// The output concerned.
        path: PathBuf,
    },
    /// The output folder exists and has no mdtf marker.
    #[error(
        "{path}: the folder exists and was not made by mdtf (it holds {entries}); mdtf replaces only folders it made: choose a new output folder, or empty this one yourself"
    )]
    OutputNotOurs {
        /// The output folder.
        path: PathBuf,
        /// Some of the files it holds.
        entries: String,
    },
    /// An mdtf output folder to which someone added files.
    #[error(
        "{path}: this mdtf output folder also holds files mdtf did not write ({entries}); move them out or choose another output folder"
    )]
    OutputHasForeignFiles {
        /// The output folder.
        path: PathBuf,
        /// Some of the files mdtf did not write.
        entries: String,
    },
    /// The output folder holds an input of the run.
    #[error(
        "{path}: the output folder holds {input}, an input of this run; mdtf never deletes an input: choose another output folder"
    )]
    OutputHoldsInput {
        /// The output folder.
        path: PathBuf,
        /// The input inside it.
        input: PathBuf,
    },
    /// The output folder is the working folder or one of its parents.
    #[error("{path}: the output folder is the current folder or holds it; choose a new folder")]
    OutputHoldsWorkingDir {
        /// The output folder.
        path: PathBuf,
    },
    /// The output path names a file or a link where a folder is needed.
    #[error("{path}: exists and is not a folder (a file or a link); choose another output folder")]
    OutputNotAFolder {
        /// The output path.
        path: PathBuf,
    },
    /// A detached data file would overwrite a file that is not the data of the header being replaced.
    #[error(
        "{path}: the data file exists and does not belong to {header}; mdtf will not overwrite it (choose another output name)"
    )]
    DataFileInTheWay {
        /// The data file.
        path: PathBuf,
        /// The header to be written.
        header: PathBuf,
    },
    /// A sample cannot be stored exactly in the requested integer type.
    #[error(
        "{path}: sample {value} at index {index} is not exactly representable as {target}; quantise first (mdtf pack) or write f32"
    )]
    NotRepresentable {
        /// The file concerned.
        path: PathBuf,
        /// The offending value.
        value: f32,
        /// Its linear index in x-fastest order.
        index: usize,
        /// The requested sample type.
        target: &'static str,
    },
    /// Fields of a multi-field volume differ in geometry, or an operation needs one field.
    #[error("{0}")]
    Fields(String),
    /// The Zarr library refused the store, an array's metadata or a chunk.
    #[error("{path}: {what}: {cause}")]
    Zarr {
        /// The store concerned.
        path: PathBuf,
        /// What mdtf was doing, e.g. "reading planes 0..16 of array 0".
        what: String,
        /// The library's error.
        cause: Box<dyn std::error::Error + Send + Sync>,
    },
}

impl VolumeError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        VolumeError::Io { path: path.to_path_buf(), cause: source }
    }
    pub(crate) fn header(path: &Path, message: impl Into<String>) -> Self {
        VolumeError::Header { path: path.to_path_buf(), message: message.into() }
    }
    pub(crate) fn zarr(
        path: &Path,
        what: impl Into<String>,
    ) -> impl FnOnce(Box<dyn std::error::Error + Send + Sync>) -> Self {
        let (path, what) = (path.to_path_buf(), what.into());
        move |cause| VolumeError::Zarr { path, what, cause }
    }
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, VolumeError>;
