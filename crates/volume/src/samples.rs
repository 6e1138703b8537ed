//! Turning a block of file bytes into f32 fields, shared by every reader.

use crate::dtype::{Endian, SampleType, decode_samples};
use crate::error::{Result, VolumeError};
use ndarray::Array3;
use std::io::Read;
use std::path::Path;

/// What to do with NaN or infinite samples on read (`nan = "zero"` in a
/// pipeline's `[input]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NanPolicy {
    /// Refuse the file, reporting how many samples are not finite (the default).
    #[default]
    Refuse,
    /// Replace every NaN or infinite sample with 0.
    Zero,
    /// Keep them as they are (for inspection, e.g. `mdtf info`; stages refuse them).
    Keep,
}

/// Options common to every reader.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// Policy for NaN / infinite samples.
    pub nan: NanPolicy,
    /// Which DICOM series to read and whether to resample it (DICOM input only).
    pub dicom: crate::dicom::DicomOptions,
    /// The multiscale level of an OME-Zarr input: 0 (the default) is full resolution.
    pub level: usize,
}

/// What a file says about how it stores its samples (for `mdtf info`).
#[derive(Debug, Clone, PartialEq)]
pub struct FileInfo {
    /// Format name, e.g. "NIfTI-1" or "NRRD (detached)".
    pub format: String,
    /// Sample type on disk.
    pub sample_type: SampleType,
    /// Byte order on disk.
    pub endian: Endian,
    /// Whether the samples are gzip-compressed.
    pub compressed: bool,
    /// Linear scaling applied on read (slope, intercept), if any.
    pub scale: Option<(f64, f64)>,
    /// What the reader had to assume (e.g. a spacing the file does not record).
    pub warnings: Vec<String>,
    /// Further facts of the format, as (name, value) lines (e.g. a DICOM
    /// series' modality and transfer syntax; never a patient attribute).
    pub details: Vec<(String, String)>,
    /// The units the file states for its values and lengths.
    pub units: crate::Units,
    /// Values that are scanner padding, not data (inclusive range, in the
    /// values as read, rescaled): DICOM's Pixel Padding Value (and Range Limit).
    pub padding: Option<[f64; 2]>,
}

impl FileInfo {
    pub(crate) fn new(format: &str, layout: &SampleLayout, compressed: bool) -> FileInfo {
        FileInfo {
            format: format.to_string(),
            sample_type: layout.ty,
            endian: layout.endian,
            compressed,
            scale: layout.scale,
            warnings: Vec::new(),
            details: Vec::new(),
            units: crate::Units::default(),
            padding: None,
        }
    }
}

/// Where the field index sits in the file's sample order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FieldAxis {
    /// Fields are the slowest axis: each field's 3D block is contiguous (NIfTI 4D).
    Slowest,
    /// Fields are the fastest axis: interleaved per voxel (NRRD with a leading field axis).
    Fastest,
}

/// How the samples of one file are laid out.
#[derive(Debug, Clone, Copy)]
pub struct SampleLayout {
    /// Sample type on disk.
    pub ty: SampleType,
    /// Byte order on disk.
    pub endian: Endian,
    /// (nx, ny, nz).
    pub dims: [usize; 3],
    /// Number of fields.
    pub fields: usize,
    /// Position of the field axis.
    pub field_axis: FieldAxis,
    /// Linear map applied after decoding: value = slope * stored + intercept.
    pub scale: Option<(f64, f64)>,
}

impl SampleLayout {
    /// Total bytes of sample data.
    pub fn byte_len(&self) -> u64 {
        self.dims.iter().map(|&d| d as u64).product::<u64>() * self.fields as u64 * self.ty.size() as u64
    }
}

/// A file's samples as a stream positioned at the first one.
pub(crate) struct SampleStream {
    /// The bytes from the first sample on (decompressed when `compressed`).
    pub src: Box<dyn Read + Send>,
    /// How they are laid out.
    pub layout: SampleLayout,
    /// Whether the file stores them gzip-compressed.
    pub compressed: bool,
    /// The units the header states.
    pub units: crate::Units,
}

/// Reads exactly the samples of `layout` from `src` and decodes them, in
/// chunks (no second copy of the volume as bytes), into one array per field
/// with the scale and the NaN policy applied. A short stream is reported as
/// truncated with the counts.
pub fn read_decoded(
    path: &Path,
    src: &mut dyn Read,
    layout: &SampleLayout,
    compressed: bool,
    opts: &ReadOptions,
) -> Result<Vec<Array3<f32>>> {
    let [nx, ny, nz] = layout.dims;
    let total = nx * ny * nz * layout.fields;
    // The array grows with the samples actually read: a short file that
    // claims a huge grid fails as truncated before much is allocated.
    let mut all: Vec<f32> = Vec::new();
    let size = layout.ty.size();
    let chunk = 1 << 16;
    let mut buf = vec![0u8; chunk * size];
    while all.len() < total {
        let done = all.len();
        let n = chunk.min(total - done);
        let bytes = &mut buf[..n * size];
        let got = read_fully(src, bytes).map_err(|e| {
            if compressed { VolumeError::Gzip { path: path.to_path_buf(), cause: e } } else { VolumeError::io(path, e) }
        })?;
        if got < bytes.len() {
            return Err(VolumeError::Truncated {
                path: path.to_path_buf(),
                expected: layout.byte_len(),
                found: (done * size + got) as u64,
            });
        }
        all.try_reserve(n).map_err(|_| VolumeError::TooLarge {
            path: path.to_path_buf(),
            dims: format!("{nx}x{ny}x{nz}"),
            needed: crate::limits::human_bytes(total as u128 * 4),
            available: "less".into(),
        })?;
        all.resize(done + n, 0.0);
        decode_samples(bytes, layout.ty, layout.endian, &mut all[done..done + n]);
    }
    finish_fields(path, all, layout, opts)
}

/// Reads until `buf` is full or the stream ends; returns the bytes read.
fn read_fully(src: &mut dyn Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match src.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// Decodes sample bytes into one array per field, applying the scale and the NaN policy.
pub fn decode_fields(path: &Path, bytes: &[u8], layout: &SampleLayout, opts: &ReadOptions) -> Result<Vec<Array3<f32>>> {
    let [nx, ny, nz] = layout.dims;
    let mut all = vec![0.0f32; nx * ny * nz * layout.fields];
    decode_samples(bytes, layout.ty, layout.endian, &mut all);
    finish_fields(path, all, layout, opts)
}

/// Applies `policy` to the NaN and infinite samples among `samples` (of the file `path`).
pub(crate) fn apply_nan_policy(path: &Path, policy: NanPolicy, samples: &mut [f32]) -> Result<()> {
    let bad = samples.iter().filter(|v| !v.is_finite()).count() as u64;
    if bad > 0 {
        match policy {
            NanPolicy::Refuse => return Err(VolumeError::NonFinite { path: path.to_path_buf(), count: bad }),
            NanPolicy::Zero => samples.iter_mut().filter(|v| !v.is_finite()).for_each(|v| *v = 0.0),
            NanPolicy::Keep => {}
        }
    }
    Ok(())
}

/// Applies scale and NaN policy to decoded samples and splits them into fields.
fn finish_fields(
    path: &Path,
    mut all: Vec<f32>,
    layout: &SampleLayout,
    opts: &ReadOptions,
) -> Result<Vec<Array3<f32>>> {
    let [nx, ny, nz] = layout.dims;
    let per_field = nx * ny * nz;
    if let Some((slope, inter)) = layout.scale {
        for v in &mut all {
            *v = (*v as f64 * slope + inter) as f32;
        }
    }
    apply_nan_policy(path, opts.nan, &mut all)?;
    let shape = (nz, ny, nx);
    let fields = match layout.field_axis {
        _ if layout.fields == 1 => vec![all],
        FieldAxis::Slowest => all.chunks_exact(per_field).map(|c| c.to_vec()).collect(),
        FieldAxis::Fastest => {
            (0..layout.fields).map(|f| all.iter().skip(f).step_by(layout.fields).copied().collect()).collect()
        }
    };
    fields
        .into_iter()
        .map(|v| Array3::from_shape_vec(shape, v).map_err(|e| VolumeError::header(path, e.to_string())))
        .collect()
}

/// Opens a file for reading, transparently un-gzipping it when it starts
/// with the gzip magic bytes. Returns the reader and whether it is compressed.
pub fn open_maybe_gz(path: &Path) -> Result<(Box<dyn Read + Send>, bool)> {
    let file = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    let len = file.metadata().map_err(|e| VolumeError::io(path, e))?.len();
    if len == 0 {
        return Err(VolumeError::Empty { path: path.to_path_buf() });
    }
    let mut reader = std::io::BufReader::new(file);
    let head = std::io::BufRead::fill_buf(&mut reader).map_err(|e| VolumeError::io(path, e))?;
    if head.starts_with(&[0x1f, 0x8b]) {
        Ok((Box::new(flate2::bufread::MultiGzDecoder::new(reader)), true))
    } else {
        Ok((Box::new(reader), false))
    }
}

/// Reads whatever follows the samples to the end of the stream and returns
/// its length. Draining a gzip stream is what checks its CRC, so a corrupt
/// file is caught even when the samples themselves decompressed.
pub fn drain_rest(path: &Path, src: &mut dyn Read, compressed: bool) -> Result<u64> {
    std::io::copy(src, &mut std::io::sink()).map_err(|e| {
        if compressed { VolumeError::Gzip { path: path.to_path_buf(), cause: e } } else { VolumeError::io(path, e) }
    })
}

/// Streams the samples of `fields` (each x-fastest, all the same length) to
/// `w` encoded as `ty`, little-endian: one field after another (`Slowest`) or
/// interleaved per voxel (`Fastest`). Encodes through a small buffer, so
/// writing never copies a whole volume.
pub fn write_fields(
    w: &mut dyn std::io::Write,
    fields: &[&[f32]],
    axis: FieldAxis,
    ty: SampleType,
) -> std::io::Result<()> {
    const CHUNK: usize = 1 << 14;
    let mut bytes = Vec::with_capacity(CHUNK * ty.size() * fields.len().max(1));
    let mut staged = Vec::with_capacity(CHUNK * fields.len().max(1));
    match axis {
        FieldAxis::Slowest => {
            for f in fields {
                for c in f.chunks(CHUNK) {
                    bytes.clear();
                    crate::dtype::encode_samples(c, ty, Endian::Little, &mut bytes);
                    w.write_all(&bytes)?;
                }
            }
        }
        FieldAxis::Fastest => {
            let n = fields.first().map_or(0, |f| f.len());
            let mut start = 0;
            while start < n {
                let end = (start + CHUNK).min(n);
                staged.clear();
                for i in start..end {
                    staged.extend(fields.iter().map(|f| f[i]));
                }
                bytes.clear();
                crate::dtype::encode_samples(&staged, ty, Endian::Little, &mut bytes);
                w.write_all(&bytes)?;
                start = end;
            }
        }
    }
    Ok(())
}
