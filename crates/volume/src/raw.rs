//! Headerless raw volumes: the caller says what the bytes are.

use crate::dtype::{Endian, SampleType};
use crate::error::{Result, VolumeError};
use crate::geometry::Geometry;
use crate::limits::check_dims;
use crate::samples::{FieldAxis, ReadOptions, SampleLayout, drain_rest, open_maybe_gz, read_decoded};
use crate::volume::Volume;
use std::io::Read;
use std::path::Path;

/// Layout of a raw file, as given by the caller.
#[derive(Debug, Clone)]
pub struct RawSpec {
    /// (nx, ny, nz).
    pub dims: [usize; 3],
    /// Sample type.
    pub ty: SampleType,
    /// Byte order.
    pub endian: Endian,
    /// Spacing (sx, sy, sz) in world units.
    pub spacing: [f64; 3],
    /// World position of the first sample.
    pub origin: [f64; 3],
    /// Bytes to skip at the start of the file (a foreign header).
    pub byte_skip: u64,
}

/// Reads a raw (optionally gzipped) file laid out as `spec` says. The file must
/// hold exactly `byte_skip` + the samples: any other size is an error, since it
/// means the layout given is wrong.
pub fn read_raw(path: &Path, spec: &RawSpec, opts: &ReadOptions) -> Result<Volume> {
    if spec.spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(VolumeError::header(path, format!("spacing {:?} must be positive", spec.spacing)));
    }
    check_dims(path, &spec.dims.map(|d| d as u64), 1)?;
    let layout = SampleLayout {
        ty: spec.ty,
        endian: spec.endian,
        dims: spec.dims,
        fields: 1,
        field_axis: FieldAxis::Slowest,
        scale: None,
    };
    let (mut src, gz) = open_maybe_gz(path)?;
    let skipped = std::io::copy(&mut (&mut src).take(spec.byte_skip), &mut std::io::sink())
        .map_err(|e| VolumeError::io(path, e))?;
    if skipped < spec.byte_skip {
        return Err(VolumeError::Truncated { path: path.to_path_buf(), expected: layout.byte_len(), found: 0 });
    }
    let mut arrays = read_decoded(path, &mut src, &layout, gz, opts)?;
    let extra = drain_rest(path, &mut src, gz)?;
    if extra > 0 {
        return Err(VolumeError::SizeMismatch {
            path: path.to_path_buf(),
            expected: layout.byte_len(),
            found: layout.byte_len() + extra,
        });
    }
    let geometry = Geometry::new(spec.dims, spec.spacing).with_origin(spec.origin);
    Volume::new(geometry, arrays.pop().unwrap_or_default())
}
