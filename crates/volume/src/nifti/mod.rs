//! NIfTI-1 and NIfTI-2 (`.nii`, `.nii.gz`, and `.hdr` + `.img` pairs) and
//! Analyze 7.5 (`.hdr` + `.img`): reading every common sample type with the
//! scaling applied and the sform/qform affine kept; writing f32, u8, u16 and
//! i16 with both sform and qform set from the geometry, as NIfTI-1 where every
//! axis fits its 16-bit dims and as NIfTI-2 where one does not.
//!
//! Headers are parsed and written in [`header`]; the sample bytes are read
//! and decoded in `samples`, so that a truncated or hostile file is an error
//! with numbers rather than an allocation or a panic.

pub mod header;
mod pair;
pub(crate) mod quaternion;

use crate::dtype::{SampleType, first_unrepresentable};
use crate::error::{Result, VolumeError};
use crate::geometry::Geometry;
use crate::limits::check_dims;
use crate::output::write_file_atomically;
use crate::samples::{
    FieldAxis, FileInfo, ReadOptions, SampleLayout, SampleStream, drain_rest, open_maybe_gz, read_decoded, write_fields,
};
use crate::volume::{Field, MultiField};
use header::{Header, Kind, NIFTI2_BYTES};
use std::io::Read;
use std::path::Path;

pub use header::NIFTI1_MAX_AXIS;
pub(crate) use pair::{is_pair_name, pair_files};

/// NIfTI datatype codes (nifti1.h DT_*) of the supported sample types.
fn sample_type_of(code: i16) -> Option<SampleType> {
    Some(match code {
        2 => SampleType::U8,
        256 => SampleType::I8,
        512 => SampleType::U16,
        4 => SampleType::I16,
        768 => SampleType::U32,
        8 => SampleType::I32,
        16 => SampleType::F32,
        64 => SampleType::F64,
        _ => return None,
    })
}

/// Reads a NIfTI-1 or NIfTI-2 file (`.nii`, `.nii.gz`), a `.hdr`/`.img` pair
/// (either name) or an Analyze 7.5 pair. A 3D file gives one field; the 4th
/// (and higher) dimensions become fields named field0, field1 ...
pub fn read_nifti(path: &Path, opts: &ReadOptions) -> Result<MultiField> {
    read_nifti_with_info(path, opts).map(|(mf, _)| mf)
}

/// [`read_nifti`], also returning how the file stores its samples.
pub fn read_nifti_with_info(path: &Path, opts: &ReadOptions) -> Result<(MultiField, FileInfo)> {
    let Opened { mut stream, geometry, header, data_path } = open(path)?;
    let (layout, compressed, units) = (stream.layout, stream.compressed, stream.units.clone());
    let arrays = read_decoded(&data_path, &mut stream.src, &layout, compressed, opts)?;
    // Trailing bytes are allowed in NIfTI; draining still checks a gzip CRC.
    drain_rest(&data_path, &mut stream.src, compressed)?;
    let fields = arrays
        .into_iter()
        .enumerate()
        .map(|(i, data)| Field { name: if layout.fields == 1 { "value".into() } else { format!("field{i}") }, data })
        .collect();
    let mut info = FileInfo { units, ..FileInfo::new(header.kind.name(header.pair), &layout, compressed) };
    if header.kind == Kind::Analyze {
        info.warnings.push(
            "Analyze 7.5 states no orientation: x is taken as flipped (radiological) and the origin from SPM's \
             'originator' or the grid's centre, as SPM and nibabel read it"
                .into(),
        );
    }
    Ok((MultiField::new(geometry, fields)?, info))
}

/// The samples of a NIfTI file as a stream at its first sample, with their layout and grid.
pub(crate) fn open_samples(path: &Path) -> Result<(SampleStream, Geometry)> {
    open(path).map(|o| (o.stream, o.geometry))
}

/// A NIfTI or Analyze file opened at its first sample.
struct Opened {
    stream: SampleStream,
    geometry: Geometry,
    header: Header,
    /// The file the samples are read from (the `.img` of a pair).
    data_path: std::path::PathBuf,
}

fn open(path: &Path) -> Result<Opened> {
    let header_path = pair::header_file(path)?;
    let (mut src, compressed) = open_maybe_gz(&header_path)?;
    let mut head = vec![0u8; NIFTI2_BYTES];
    let got = read_up_to(&mut src, &mut head[..4]).map_err(|e| stream_error(&header_path, e, compressed))?;
    let len = header::header_len(&head[..got]).unwrap_or(header::NIFTI1_BYTES);
    let more = read_up_to(&mut src, &mut head[4..len]).map_err(|e| stream_error(&header_path, e, compressed))?;
    head.truncate(got + more);
    let analyze_allowed = pair::is_pair_name(&header_path);
    let h = header::parse(&head, analyze_allowed).map_err(|m| VolumeError::header(&header_path, m))?;
    if (3000..=3099).contains(&h.intent_code) {
        return Err(VolumeError::header(
            &header_path,
            format!(
                "a CIFTI-2 file (intent code {}): a matrix over surface vertices and voxels, not a volume; \
                 wb_command -cifti-separate takes the volume out of it",
                h.intent_code
            ),
        ));
    }
    let layout = layout_of(&header_path, &h)?;
    let geometry = geometry_of(&header_path, &h, layout.dims)?;
    let vox_offset = h.vox_offset;
    let least = if h.pair { 0.0 } else { len as f64 };
    if !(vox_offset.is_finite() && vox_offset >= least && vox_offset < 1e12) {
        return Err(VolumeError::header(&header_path, format!("vox_offset {vox_offset} is not a valid data offset")));
    }
    if h.pair && !analyze_allowed {
        return Err(VolumeError::header(
            &header_path,
            format!(
                "the header's magic says its samples are in a separate .img ({}), but the file is not named .hdr: \
                 name it .hdr with its .img beside it",
                h.kind.name(true)
            ),
        ));
    }
    let (mut src, compressed, skip, data_path) = if h.pair {
        let data_path = pair::data_file(&header_path).ok_or_else(|| {
            VolumeError::header(
                &header_path,
                format!(
                    "the samples of this {} are in {}, which is missing",
                    h.kind.name(true),
                    pair::expected_partner_name(&header_path)
                ),
            )
        })?;
        let (src, compressed) = open_maybe_gz(&data_path)?;
        (src, compressed, vox_offset as u64, data_path)
    } else {
        (src, compressed, vox_offset as u64 - len as u64, header_path.clone())
    };
    let skipped = std::io::copy(&mut (&mut src).take(skip), &mut std::io::sink())
        .map_err(|e| stream_error(&data_path, e, compressed))?;
    if skipped < skip {
        return Err(VolumeError::Truncated { path: data_path, expected: layout.byte_len(), found: 0 });
    }
    let units = crate::Units { value: None, length: crate::units::nifti_length_unit(h.xyzt_units) };
    Ok(Opened { stream: SampleStream { src, layout, compressed, units }, geometry, header: h, data_path })
}

fn read_up_to(src: &mut dyn Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match src.read(&mut buf[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n)
}

fn stream_error(path: &Path, e: std::io::Error, compressed: bool) -> VolumeError {
    if compressed { VolumeError::Gzip { path: path.to_path_buf(), cause: e } } else { VolumeError::io(path, e) }
}

fn layout_of(path: &Path, h: &Header) -> Result<SampleLayout> {
    let rank = h.dim[0];
    if !(1..=7).contains(&rank) {
        return Err(VolumeError::header(
            path,
            format!("dim[0] (the number of dimensions) is {rank}; it must be 1 to 7"),
        ));
    }
    let rank = rank as usize;
    if h.dim[1..=rank].iter().any(|&d| d < 0) {
        return Err(VolumeError::BadDimensions {
            path: path.to_path_buf(),
            dims: format!("{:?}", &h.dim[1..=rank]),
            message: "negative dimension".into(),
        });
    }
    let raw: Vec<u64> = h.dim[1..=rank].iter().map(|&d| d as u64).collect();
    let mut dims3 = [1u64; 3];
    dims3[..rank.min(3)].copy_from_slice(&raw[..rank.min(3)]);
    let fields = raw.iter().skip(3).try_fold(1u64, |acc, &d| acc.checked_mul(d)).unwrap_or(u64::MAX);
    let mut all_dims = dims3.to_vec();
    if fields > 1 {
        all_dims.push(fields);
    }
    check_dims(path, &all_dims, fields.max(1))?;
    let ty = sample_type_of(h.datatype).ok_or_else(|| VolumeError::UnsupportedType {
        path: path.to_path_buf(),
        name: format!("NIfTI datatype code {}", h.datatype),
        supported: "uint8, int8, uint16, int16, uint32, int32, float32, float64",
    })?;
    let slope = h.scl_slope;
    let scale = (slope != 0.0 && slope.is_finite() && (slope != 1.0 || h.scl_inter != 0.0))
        .then_some((slope, if h.scl_inter.is_finite() { h.scl_inter } else { 0.0 }));
    Ok(SampleLayout {
        ty,
        endian: h.endian,
        dims: dims3.map(|d| d as usize),
        fields: fields.max(1) as usize,
        field_axis: FieldAxis::Slowest,
        scale,
    })
}

/// The grid of the header's affine (see [`Header::affine`]).
fn geometry_of(path: &Path, h: &Header, dims: [usize; 3]) -> Result<Geometry> {
    let affine = h.affine(dims);
    Geometry::from_affine(dims, affine).ok_or_else(|| {
        VolumeError::header(
            path,
            format!("degenerate voxel-to-world transform {affine:?} (a zero or non-finite spacing)"),
        )
    })
}

/// The header bytes (with the empty extension flag) of a NIfTI at `path`
/// holding `fields` fields on `geometry` as `ty`: 3D for one field, 4D for
/// several; NIfTI-2 when an axis exceeds [`NIFTI1_MAX_AXIS`]. A `.hdr` or
/// `.img` path gets a pair's header.
pub(crate) fn header_of(path: &Path, geometry: &Geometry, fields: usize, ty: SampleType) -> Result<Vec<u8>> {
    let mut dims = geometry.dims.to_vec();
    if fields > 1 {
        dims.push(fields);
    }
    header::encode(geometry, &dims, ty, is_pair_name(path)).map(|(_, bytes)| bytes).ok_or_else(|| {
        VolumeError::UnsupportedType {
            path: path.to_path_buf(),
            name: ty.name().into(),
            supported: "f32, u8, u16, i16 for writing",
        }
    })
}

/// The first gzip member of the `.nii.gz` that [`write_nifti`] writes to
/// `path` for `fields` fields on `geometry` stored as `ty`: the header. The
/// planes' members follow ([`crate::gz_members::plane_members`]), field
/// after field, so that a file's parts can be made apart and put together.
pub fn nifti_gz_header(path: &Path, geometry: &Geometry, fields: usize, ty: SampleType) -> Result<Vec<u8>> {
    Ok(crate::gz_members::member(&header_of(path, geometry, fields, ty)?))
}

/// The NIfTI version mdtf writes for `geometry` with `fields` fields: 1, or
/// 2 when an axis exceeds NIfTI-1's 16-bit dims.
pub fn nifti_version_for(geometry: &Geometry, fields: usize) -> u8 {
    match header::kind_for(&[geometry.dims[0], geometry.dims[1], geometry.dims[2], fields]) {
        Kind::Nifti2 => 2,
        _ => 1,
    }
}

/// Writes `mf` as `.nii` or `.nii.gz` (by the path's extension), or as a
/// `.hdr` + `.img` pair (by either name), samples stored as `ty` (f32, u8,
/// u16 or i16). One field gives a 3D file, several a 4D file with one volume
/// per field. NIfTI-1, or NIfTI-2 where an axis exceeds 32767 voxels
/// ([`nifti_version_for`]). Integer targets require exactly representable
/// values. A `.nii.gz` holds one gzip member for the header and one per
/// plane of each field ([`crate::gz_members`]), compressed side by side.
/// Streams the samples (no copy of the volume) and is atomic: each
/// file appears only when complete (a pair: its `.img`, then its `.hdr`).
pub fn write_nifti(path: &Path, mf: &MultiField, ty: SampleType) -> Result<()> {
    for f in &mf.fields {
        if let Some((index, value)) = f.data.as_slice().and_then(|s| first_unrepresentable(s, ty)) {
            return Err(VolumeError::NotRepresentable { path: path.to_path_buf(), value, index, target: ty.name() });
        }
    }
    let header = header_of(path, &mf.geometry, mf.fields.len(), ty)?;
    let fields: Vec<&[f32]> = mf.fields.iter().map(|f| f.data.as_slice().unwrap_or(&[])).collect();
    if is_pair_name(path) {
        return pair::write(path, &header, |w| write_fields(w, &fields, FieldAxis::Slowest, ty));
    }
    let gz = path.to_string_lossy().to_ascii_lowercase().ends_with(".gz");
    let plane = mf.geometry.dims[0] * mf.geometry.dims[1];
    write_file_atomically(path, |w| {
        if gz {
            // one gzip member for the header, then one a plane (see `gz_members`)
            w.write_all(&crate::gz_members::member(&header))?;
            fields.iter().try_for_each(|f| crate::gz_members::write_plane_members(w, f, plane, ty))
        } else {
            w.write_all(&header)?;
            write_fields(w, &fields, FieldAxis::Slowest, ty)
        }
    })
}

/// The other file a pair write to `path` makes (the `.img` of a `.hdr`, the
/// `.hdr` of a `.img`); None for a single-file name.
pub(crate) fn planned_partner(path: &Path) -> Option<std::path::PathBuf> {
    let (header, data) = pair::planned_files(path)?;
    Some(if header == path { data } else { header })
}
