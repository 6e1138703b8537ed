//! NIfTI-1 (`.nii`, `.nii.gz`): reading every common sample type with
//! scl_slope/scl_inter applied and the sform/qform affine kept; writing f32,
//! u8 and u16 with both sform and qform set from the geometry.
//!
//! The header is parsed and written by the `nifti` crate; the sample bytes are
//! read and decoded here, so that a truncated or hostile file is an error
//! with numbers rather than an allocation or a panic.

use crate::dtype::{Endian, SampleType, first_unrepresentable};
use crate::error::{Result, VolumeError};
use crate::geometry::Geometry;
use crate::limits::check_dims;
use crate::output::write_file_atomically;
use crate::samples::{
    FieldAxis, FileInfo, ReadOptions, SampleLayout, SampleStream, drain_rest, open_maybe_gz, read_decoded, write_fields,
};
use crate::volume::{Field, MultiField};
use nifti::NiftiHeader;
use std::io::{Read, Write};
use std::path::Path;

const HEADER_BYTES: usize = 348;

/// NIfTI-1 datatype codes (nifti1.h DT_*) of the supported sample types.
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

/// Reads a `.nii` or `.nii.gz` file. A 3D file gives one field; the 4th (and
/// higher) dimensions become fields named field0, field1 ...
pub fn read_nifti(path: &Path, opts: &ReadOptions) -> Result<MultiField> {
    read_nifti_with_info(path, opts).map(|(mf, _)| mf)
}

/// [`read_nifti`], also returning how the file stores its samples.
pub fn read_nifti_with_info(path: &Path, opts: &ReadOptions) -> Result<(MultiField, FileInfo)> {
    let (mut stream, geometry) = open_samples(path)?;
    let (layout, compressed, units) = (stream.layout, stream.compressed, stream.units.clone());
    let arrays = read_decoded(path, &mut stream.src, &layout, compressed, opts)?;
    // Trailing bytes are allowed in NIfTI; draining still checks a gzip CRC.
    drain_rest(path, &mut stream.src, compressed)?;
    let fields = arrays
        .into_iter()
        .enumerate()
        .map(|(i, data)| Field { name: if layout.fields == 1 { "value".into() } else { format!("field{i}") }, data })
        .collect();
    let info = FileInfo { units, ..FileInfo::new("NIfTI-1", &layout, compressed) };
    Ok((MultiField::new(geometry, fields)?, info))
}

/// The samples of a NIfTI-1 file as a stream at its first sample, with their layout and grid.
pub(crate) fn open_samples(path: &Path) -> Result<(SampleStream, Geometry)> {
    let (mut src, compressed) = open_maybe_gz(path)?;
    let mut head = vec![0u8; HEADER_BYTES];
    let got = read_up_to(&mut src, &mut head).map_err(|e| stream_error(path, e, compressed))?;
    if got < HEADER_BYTES {
        return Err(VolumeError::header(path, format!("only {got} bytes, a NIfTI-1 header needs 348")));
    }
    let sizeof_hdr = [
        i32::from_le_bytes([head[0], head[1], head[2], head[3]]),
        i32::from_be_bytes([head[0], head[1], head[2], head[3]]),
    ];
    if !sizeof_hdr.contains(&(HEADER_BYTES as i32)) {
        return Err(VolumeError::header(
            path,
            format!(
                "not a NIfTI-1 file: its first 4 bytes (sizeof_hdr) read {} (little-endian), not 348{}",
                sizeof_hdr[0],
                if sizeof_hdr.contains(&540) { "; this looks like NIfTI-2, which is not supported" } else { "" }
            ),
        ));
    }
    // (checked before the nifti crate, whose word for a bad magic is "Invalid NIfTI-1 file")
    let magic = &head[344..348];
    if magic != b"n+1\0" {
        let shown: String = magic.iter().map(|&b| std::ascii::escape_default(b).to_string()).collect();
        let pair = if magic == b"ni1\0" { ": 'ni1' is a .hdr/.img pair" } else { "" };
        return Err(VolumeError::header(
            path,
            format!(
                "not a single-file NIfTI-1: the magic at byte 344 reads '{shown}', not 'n+1'{pair} (.hdr/.img pairs \
                 and NIfTI-2 are not supported; nibabel or fslchfiletype NIFTI converts them)"
            ),
        ));
    }
    let header =
        NiftiHeader::from_reader(&head[..]).map_err(|e| VolumeError::Nifti { path: path.to_path_buf(), cause: e })?;
    let layout = layout_of(path, &header)?;
    let geometry = geometry_of(path, &header, layout.dims)?;

    let vox_offset = header.vox_offset;
    if !(vox_offset.is_finite() && vox_offset >= HEADER_BYTES as f32 && vox_offset < 1e12) {
        return Err(VolumeError::header(path, format!("vox_offset {vox_offset} is not a valid data offset")));
    }
    let skip = vox_offset as u64 - HEADER_BYTES as u64;
    let skipped = std::io::copy(&mut (&mut src).take(skip), &mut std::io::sink())
        .map_err(|e| stream_error(path, e, compressed))?;
    if skipped < skip {
        return Err(VolumeError::Truncated { path: path.to_path_buf(), expected: layout.byte_len(), found: 0 });
    }
    let units = crate::Units { value: None, length: crate::units::nifti_length_unit(header.xyzt_units) };
    Ok((SampleStream { src, layout, compressed, units }, geometry))
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

fn layout_of(path: &Path, h: &NiftiHeader) -> Result<SampleLayout> {
    let rank = h.dim[0] as usize;
    if !(1..=7).contains(&rank) {
        // The byte order is guessed from dim[0], so an out-of-range rank shows byte-swapped.
        let (a, b) = (h.dim[0], h.dim[0].swap_bytes());
        let (as_stored, other) = if b < a { (b, a) } else { (a, b) };
        return Err(VolumeError::header(
            path,
            format!(
                "dim[0] (the number of dimensions) is {as_stored} ({other} in the other byte order); it must be 1 to 7"
            ),
        ));
    }
    let raw: Vec<u64> = h.dim[1..=rank].iter().map(|&d| d as u64).collect();
    // dim is stored as i16 on disk; the crate reads it as u16, so negative values show as > 32767.
    if raw.iter().any(|&d| d > i16::MAX as u64) {
        return Err(VolumeError::BadDimensions {
            path: path.to_path_buf(),
            dims: format!("{:?}", &h.dim[1..=rank]),
            message: "negative dimension".into(),
        });
    }
    let mut dims3 = [1u64; 3];
    dims3[..rank.min(3)].copy_from_slice(&raw[..rank.min(3)]);
    let fields: u64 = raw.iter().skip(3).product();
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
    let slope = h.scl_slope as f64;
    let scale = (slope != 0.0 && slope.is_finite() && (slope != 1.0 || h.scl_inter != 0.0))
        .then_some((slope, if h.scl_inter.is_finite() { h.scl_inter as f64 } else { 0.0 }));
    Ok(SampleLayout {
        ty,
        endian: if h.endianness == nifti::Endianness::Big { Endian::Big } else { Endian::Little },
        dims: dims3.map(|d| d as usize),
        fields: fields.max(1) as usize,
        field_axis: FieldAxis::Slowest,
        scale,
    })
}

/// The voxel-to-world affine by the NIfTI rules: sform if its code is set,
/// else qform if its code is set, else the pixdim scaling with origin 0.
fn geometry_of(path: &Path, h: &NiftiHeader, dims: [usize; 3]) -> Result<Geometry> {
    let pix = [h.pixdim[1] as f64, h.pixdim[2] as f64, h.pixdim[3] as f64];
    let affine: [[f64; 4]; 3] = if h.sform_code > 0 {
        [h.srow_x, h.srow_y, h.srow_z].map(|r| r.map(|v| v as f64))
    } else if h.qform_code > 0 {
        let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
        let r = quaternion_to_rotation(h.quatern_b as f64, h.quatern_c as f64, h.quatern_d as f64);
        let s = [pix[0].abs(), pix[1].abs(), pix[2].abs() * qfac];
        let t = [h.quatern_x as f64, h.quatern_y as f64, h.quatern_z as f64];
        [0, 1, 2].map(|row| [r[row][0] * s[0], r[row][1] * s[1], r[row][2] * s[2], t[row]])
    } else {
        let s = pix.map(f64::abs);
        [[s[0], 0.0, 0.0, 0.0], [0.0, s[1], 0.0, 0.0], [0.0, 0.0, s[2], 0.0]]
    };
    Geometry::from_affine(dims, affine).ok_or_else(|| {
        VolumeError::header(
            path,
            format!("degenerate voxel-to-world transform {affine:?} (a zero or non-finite spacing)"),
        )
    })
}

/// Rotation matrix of the unit quaternion (a, b, c, d) with a >= 0 implied (NIfTI-1 qform).
fn quaternion_to_rotation(b: f64, c: f64, d: f64) -> [[f64; 3]; 3] {
    let (mut a, mut b, mut c, mut d) = (1.0 - (b * b + c * c + d * d), b, c, d);
    if a < 1e-7 {
        let n = (b * b + c * c + d * d).sqrt().max(f64::MIN_POSITIVE);
        (a, b, c, d) = (0.0, b / n, c / n, d / n);
    } else {
        a = a.sqrt();
    }
    [
        [a * a + b * b - c * c - d * d, 2.0 * (b * c - a * d), 2.0 * (b * d + a * c)],
        [2.0 * (b * c + a * d), a * a + c * c - b * b - d * d, 2.0 * (c * d - a * b)],
        [2.0 * (b * d - a * c), 2.0 * (c * d + a * b), a * a + d * d - c * c - b * b],
    ]
}

/// Quaternion (b, c, d) and qfac of the rotation whose columns are the
/// geometry's directions (NIfTI-1's mat44_to_quatern for an orthonormal matrix).
fn rotation_to_quaternion(dirs: &[[f64; 3]; 3]) -> ([f64; 3], f64) {
    // r[row][col], columns are the axis directions
    let mut r = [[0.0; 3]; 3];
    for (col, d) in dirs.iter().enumerate() {
        for row in 0..3 {
            r[row][col] = d[row];
        }
    }
    let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1]) - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
        + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
    let qfac = if det < 0.0 { -1.0 } else { 1.0 };
    if qfac < 0.0 {
        for row in &mut r {
            row[2] = -row[2];
        }
    }
    let trace = r[0][0] + r[1][1] + r[2][2] + 1.0;
    let (mut a, mut b, mut c, mut d);
    if trace > 0.5 {
        a = 0.5 * trace.sqrt();
        b = 0.25 * (r[2][1] - r[1][2]) / a;
        c = 0.25 * (r[0][2] - r[2][0]) / a;
        d = 0.25 * (r[1][0] - r[0][1]) / a;
    } else {
        let xd = 1.0 + r[0][0] - (r[1][1] + r[2][2]);
        let yd = 1.0 + r[1][1] - (r[0][0] + r[2][2]);
        let zd = 1.0 + r[2][2] - (r[0][0] + r[1][1]);
        if xd > 1.0 {
            b = 0.5 * xd.sqrt();
            c = 0.25 * (r[0][1] + r[1][0]) / b;
            d = 0.25 * (r[0][2] + r[2][0]) / b;
            a = 0.25 * (r[2][1] - r[1][2]) / b;
        } else if yd > 1.0 {
            c = 0.5 * yd.sqrt();
            b = 0.25 * (r[0][1] + r[1][0]) / c;
            d = 0.25 * (r[1][2] + r[2][1]) / c;
            a = 0.25 * (r[0][2] - r[2][0]) / c;
        } else {
            d = 0.5 * zd.sqrt();
            b = 0.25 * (r[0][2] + r[2][0]) / d;
            c = 0.25 * (r[1][2] + r[2][1]) / d;
            a = 0.25 * (r[1][0] - r[0][1]) / d;
        }
        if a < 0.0 {
            (b, c, d) = (-b, -c, -d);
            a = -a;
        }
    }
    let _ = a;
    ([b, c, d], qfac)
}

/// The header mdtf writes: spacing in pixdim, sform = the exact affine,
/// qform = its rotation part, both with code 1 (scanner anatomical), mm units.
fn header_for(geometry: &Geometry) -> NiftiHeader {
    let m = geometry.world_from_voxel();
    let ([b, c, d], qfac) = rotation_to_quaternion(&geometry.directions);
    let mut h = NiftiHeader { pixdim: [qfac as f32, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0], ..Default::default() };
    for a in 0..3 {
        h.pixdim[a + 1] = geometry.spacing[a] as f32;
    }
    h.xyzt_units = 2; // NIFTI_UNITS_MM
    h.qform_code = 1;
    h.sform_code = 1;
    (h.quatern_b, h.quatern_c, h.quatern_d) = (b as f32, c as f32, d as f32);
    (h.quatern_x, h.quatern_y, h.quatern_z) = (m[0][3] as f32, m[1][3] as f32, m[2][3] as f32);
    h.srow_x = m[0].map(|v| v as f32);
    h.srow_y = m[1].map(|v| v as f32);
    h.srow_z = m[2].map(|v| v as f32);
    let mut descrip = b"mdtf".to_vec();
    descrip.resize(80, 0);
    h.descrip = descrip;
    h
}

/// NIfTI-1 datatype code and bits per sample of the types mdtf writes.
fn datatype_code(ty: SampleType) -> Option<(i16, i16)> {
    Some(match ty {
        SampleType::U8 => (2, 8),
        SampleType::I16 => (4, 16),
        SampleType::U16 => (512, 16),
        SampleType::F32 => (16, 32),
        _ => return None,
    })
}

/// The 348-byte header plus the 4-byte empty extension flag, little-endian,
/// laid out as nifti1.h defines it.
fn header_bytes(h: &NiftiHeader, dims: &[usize], ty: SampleType) -> Option<Vec<u8>> {
    let (code, bitpix) = datatype_code(ty)?;
    let mut b = vec![0u8; 352];
    let put_i16 = |b: &mut Vec<u8>, at: usize, v: i16| b[at..at + 2].copy_from_slice(&v.to_le_bytes());
    let put_f32 = |b: &mut Vec<u8>, at: usize, v: f32| b[at..at + 4].copy_from_slice(&v.to_le_bytes());
    b[0..4].copy_from_slice(&348i32.to_le_bytes());
    b[38] = b'r'; // "regular", as nibabel writes it
    put_i16(&mut b, 40, dims.len() as i16);
    for (n, &d) in dims.iter().enumerate() {
        put_i16(&mut b, 42 + 2 * n, i16::try_from(d).ok()?);
    }
    for n in dims.len() + 1..8 {
        put_i16(&mut b, 40 + 2 * n, 1);
    }
    put_i16(&mut b, 70, code);
    put_i16(&mut b, 72, bitpix);
    for (n, &p) in h.pixdim.iter().enumerate() {
        put_f32(&mut b, 76 + 4 * n, p);
    }
    put_f32(&mut b, 108, 352.0); // vox_offset
    put_f32(&mut b, 112, 1.0); // scl_slope
    b[123] = h.xyzt_units;
    let descrip = &h.descrip[..h.descrip.len().min(79)];
    b[148..148 + descrip.len()].copy_from_slice(descrip);
    put_i16(&mut b, 252, h.qform_code);
    put_i16(&mut b, 254, h.sform_code);
    for (n, v) in [h.quatern_b, h.quatern_c, h.quatern_d, h.quatern_x, h.quatern_y, h.quatern_z].into_iter().enumerate()
    {
        put_f32(&mut b, 256 + 4 * n, v);
    }
    for (r, row) in [h.srow_x, h.srow_y, h.srow_z].iter().enumerate() {
        for (c, &v) in row.iter().enumerate() {
            put_f32(&mut b, 280 + 16 * r + 4 * c, v);
        }
    }
    b[344..348].copy_from_slice(b"n+1\0");
    Some(b)
}

/// The header bytes (with the `n+1` extension block) of a NIfTI at `path`
/// holding `fields` fields on `geometry` as `ty`: 3D for one field, 4D for several.
pub(crate) fn header_of(path: &Path, geometry: &Geometry, fields: usize, ty: SampleType) -> Result<Vec<u8>> {
    let mut dims = geometry.dims.to_vec();
    if fields > 1 {
        dims.push(fields);
    }
    header_bytes(&header_for(geometry), &dims, ty).ok_or_else(|| {
        if datatype_code(ty).is_none() {
            VolumeError::UnsupportedType {
                path: path.to_path_buf(),
                name: ty.name().into(),
                supported: "f32, u8, u16, i16 for writing",
            }
        } else {
            VolumeError::header(path, format!("dims {dims:?} exceed NIfTI-1's limit of 32767 per axis"))
        }
    })
}

/// Writes `mf` as `.nii` or `.nii.gz` (by the path's extension) with samples
/// stored as `ty` (f32, u8, u16 or i16). One field gives a 3D file, several a
/// 4D file with one volume per field. Integer targets require exactly
/// representable values. Streams the samples (no copy of the volume) and is
/// atomic: the target appears only when complete.
pub fn write_nifti(path: &Path, mf: &MultiField, ty: SampleType) -> Result<()> {
    for f in &mf.fields {
        if let Some((index, value)) = f.data.as_slice().and_then(|s| first_unrepresentable(s, ty)) {
            return Err(VolumeError::NotRepresentable { path: path.to_path_buf(), value, index, target: ty.name() });
        }
    }
    let header = header_of(path, &mf.geometry, mf.fields.len(), ty)?;
    let fields: Vec<&[f32]> = mf.fields.iter().map(|f| f.data.as_slice().unwrap_or(&[])).collect();
    let gz = path.to_string_lossy().to_ascii_lowercase().ends_with(".gz");
    write_file_atomically(path, |w| {
        if gz {
            let mut enc = flate2::write::GzEncoder::new(w, flate2::Compression::fast());
            enc.write_all(&header)?;
            write_fields(&mut enc, &fields, FieldAxis::Slowest, ty)?;
            enc.finish()?;
            Ok(())
        } else {
            w.write_all(&header)?;
            write_fields(w, &fields, FieldAxis::Slowest, ty)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_round_trips_axis_permutations_and_flips() {
        let cases = [
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]],
            [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]],
            [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        ];
        for dirs in cases {
            let ([b, c, d], qfac) = rotation_to_quaternion(&dirs);
            let r = quaternion_to_rotation(b, c, d);
            for (col, dir) in dirs.iter().enumerate() {
                let f = if col == 2 { qfac } else { 1.0 };
                for row in 0..3 {
                    assert!((r[row][col] * f - dir[row]).abs() < 1e-9, "{dirs:?}");
                }
            }
        }
    }
}
