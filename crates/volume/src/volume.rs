//! The `Volume` (one scalar field) and `MultiField` (several fields on one grid).

use crate::error::{Result, VolumeError};
use crate::geometry::Geometry;
use ndarray::Array3;

/// A scalar volume: f32 samples in x-fastest order, ndarray shape (nz, ny, nx),
/// index `[[k, j, i]]`, with the geometry that places it in the world.
#[derive(Debug, Clone, PartialEq)]
pub struct Volume {
    /// Where the samples are.
    pub geometry: Geometry,
    /// The samples, shape (nz, ny, nx), standard layout.
    pub data: Array3<f32>,
}

impl Volume {
    /// Wraps samples with their geometry; the shapes must agree.
    pub fn new(geometry: Geometry, data: Array3<f32>) -> Result<Volume> {
        let (nz, ny, nx) = geometry.shape();
        if data.dim() != (nz, ny, nx) {
            return Err(VolumeError::Fields(format!(
                "sample array of shape {:?} does not match dims {}",
                data.dim(),
                geometry.dims_string()
            )));
        }
        let data = if data.is_standard_layout() { data } else { data.as_standard_layout().into_owned() };
        Ok(Volume { geometry, data })
    }

    /// Wraps x-fastest samples with their geometry; their count must be the grid's.
    pub fn from_samples(geometry: Geometry, samples: Vec<f32>) -> Result<Volume> {
        let (nz, ny, nx) = geometry.shape();
        let len = samples.len();
        let data = Array3::from_shape_vec((nz, ny, nx), samples).map_err(|_| {
            VolumeError::Fields(format!("{len} samples do not fill the grid of {}", geometry.dims_string()))
        })?;
        Ok(Volume { geometry, data })
    }

    /// A volume of zeros on the given grid.
    pub fn zeros(geometry: Geometry) -> Volume {
        let data = Array3::zeros(geometry.shape());
        Volume { geometry, data }
    }

    /// Voxels per z-slice (nx * ny).
    pub fn plane_len(&self) -> usize {
        self.geometry.dims[0] * self.geometry.dims[1]
    }

    /// The samples as one slice in x-fastest order.
    pub fn samples(&self) -> &[f32] {
        // Constructors keep the array in standard layout.
        self.data.as_slice().unwrap_or(&[])
    }

    /// Smallest and largest finite sample, or None if there is none.
    pub fn finite_range(&self) -> Option<(f32, f32)> {
        crate::range::finite_sample_range(self.samples())
    }

    /// Number of NaN or infinite samples.
    pub fn non_finite_count(&self) -> u64 {
        self.data.iter().filter(|v| !v.is_finite()).count() as u64
    }

    /// A copy of the planes `z` (a z-slab, clamped to the grid), placed in the
    /// world where they are in this volume: the block a slab-by-slab run reads.
    pub fn z_slab(&self, z: std::ops::Range<usize>) -> Volume {
        self.part(2, z)
    }

    /// A copy of rows `y` (clamped to the grid) of every plane, placed in
    /// the world where they are in this volume: a strip of a blocked run.
    pub fn y_rows(&self, y: std::ops::Range<usize>) -> Volume {
        self.part(1, y)
    }

    /// A copy of indices `r` (clamped to the grid) along grid `axis` (0 = x, 1 = y, 2 = z), placed where they lie.
    fn part(&self, axis: usize, r: std::ops::Range<usize>) -> Volume {
        let n = self.geometry.dims[axis];
        let (a, b) = (r.start.min(n), r.end.min(n).max(r.start.min(n)));
        let geometry = self.geometry.part(axis, a..b);
        // the array's axes are (z, y, x)
        let data = self.data.slice_axis(ndarray::Axis(2 - axis), ndarray::Slice::from(a..b)).to_owned();
        Volume { geometry, data }
    }
}

/// One named field of a [`MultiField`].
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    /// The field's name (a file's own name, or "field0", "field1" ... when it has none).
    pub name: String,
    /// The samples, shape (nz, ny, nx), standard layout.
    pub data: Array3<f32>,
}

/// Several scalar fields sampled on one grid (a 4D NIfTI, a NRRD with a field
/// axis, or a set of co-registered files). A scalar volume is a multi-field
/// volume with one field.
#[derive(Debug, Clone, PartialEq)]
pub struct MultiField {
    /// The grid every field shares.
    pub geometry: Geometry,
    /// The fields, in file order.
    pub fields: Vec<Field>,
}

impl MultiField {
    /// Builds a multi-field volume, checking that every field has the grid's shape.
    pub fn new(geometry: Geometry, fields: Vec<Field>) -> Result<MultiField> {
        if fields.is_empty() {
            return Err(VolumeError::Fields("a multi-field volume needs at least one field".into()));
        }
        for f in &fields {
            Volume::new(geometry.clone(), f.data.clone()).map_err(|_| {
                VolumeError::Fields(format!(
                    "field '{}' has shape {:?}, the grid is {}",
                    f.name,
                    f.data.dim(),
                    geometry.dims_string()
                ))
            })?;
        }
        Ok(MultiField { geometry, fields })
    }

    /// Joins scalar volumes into one multi-field volume; their grids must match.
    pub fn from_volumes(named: Vec<(String, Volume)>) -> Result<MultiField> {
        let Some((_, first)) = named.first() else {
            return Err(VolumeError::Fields("a multi-field volume needs at least one field".into()));
        };
        let geometry = first.geometry.clone();
        let mut fields = Vec::with_capacity(named.len());
        for (name, v) in named {
            if !v.geometry.same_grid(&geometry) {
                return Err(VolumeError::Fields(format!(
                    "field '{name}' has geometry {} spacing {:?} origin {:?}, the first field has {} spacing {:?} origin {:?}",
                    v.geometry.dims_string(),
                    v.geometry.spacing,
                    v.geometry.origin,
                    geometry.dims_string(),
                    geometry.spacing,
                    geometry.origin
                )));
            }
            fields.push(Field { name, data: v.data });
        }
        Ok(MultiField { geometry, fields })
    }

    /// The single field as a scalar volume; an error if there are several.
    pub fn into_scalar(self) -> Result<Volume> {
        if self.fields.len() != 1 {
            return Err(VolumeError::Fields(format!(
                "expected a scalar volume, found {} fields ({})",
                self.fields.len(),
                self.fields.iter().map(|f| f.name.as_str()).collect::<Vec<_>>().join(", ")
            )));
        }
        let geometry = self.geometry;
        let data = self.fields.into_iter().next().map(|f| f.data).unwrap_or_default();
        Volume::new(geometry, data)
    }

    /// Every field as a named scalar volume, moved (the inverse of [`MultiField::from_volumes`]).
    pub fn into_volumes(self) -> Vec<(String, Volume)> {
        let geometry = self.geometry;
        self.fields.into_iter().map(|f| (f.name, Volume { geometry: geometry.clone(), data: f.data })).collect()
    }

    /// Field `index` as a scalar volume (a copy).
    pub fn field_volume(&self, index: usize) -> Option<Volume> {
        self.fields.get(index).map(|f| Volume { geometry: self.geometry.clone(), data: f.data.clone() })
    }

    /// A copy of planes `z` (clamped to the grid) of field `index`, placed
    /// where they lie: [`Volume::z_slab`] without copying the whole field first.
    pub fn field_z_slab(&self, index: usize, z: std::ops::Range<usize>) -> Option<Volume> {
        let nz = self.geometry.dims[2];
        let (z0, z1) = (z.start.min(nz), z.end.min(nz).max(z.start.min(nz)));
        let f = self.fields.get(index)?;
        let data = f.data.slice_axis(ndarray::Axis(0), ndarray::Slice::from(z0..z1)).to_owned();
        Some(Volume { geometry: self.geometry.z_slab(z0..z1), data })
    }
}

impl From<Volume> for MultiField {
    fn from(v: Volume) -> MultiField {
        MultiField { geometry: v.geometry, fields: vec![Field { name: "value".into(), data: v.data }] }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_z_slab_holds_the_planes_where_the_volume_has_them() {
        let mut geometry = Geometry::new([3, 2, 5], [0.5, 0.7, 1.5]).with_origin([10.0, -4.0, 2.0]);
        let (c, s) = (0.6_f64, 0.8_f64);
        geometry.directions = [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]];
        geometry.directions.swap(1, 2); // an oblique z axis: (0, 0, 1) and (-s, c, 0) exchanged
        let data = Array3::from_shape_fn((5, 2, 3), |(k, j, i)| (100 * k + 10 * j + i) as f32);
        let v = Volume::new(geometry.clone(), data).unwrap();
        let slab = v.z_slab(2..4);
        assert_eq!(slab.geometry.dims, [3, 2, 2]);
        assert_eq!(slab.data[[0, 1, 2]], 212.0);
        assert_eq!(slab.data[[1, 0, 0]], 300.0);
        let world = |g: &Geometry, ijk: [f64; 3]| {
            let m = g.world_from_voxel();
            [0, 1, 2].map(|r| m[r][0] * ijk[0] + m[r][1] * ijk[1] + m[r][2] * ijk[2] + m[r][3])
        };
        let (a, b) = (world(&slab.geometry, [1.0, 1.0, 1.0]), world(&geometry, [1.0, 1.0, 3.0]));
        for r in 0..3 {
            assert!((a[r] - b[r]).abs() < 1e-12, "{a:?} vs {b:?}");
        }
        assert_eq!(v.z_slab(4..9).geometry.dims[2], 1, "clamped to the grid");
        assert_eq!(v.z_slab(7..9).geometry.dims[2], 0);
    }

    #[test]
    fn a_strip_of_rows_lies_where_the_grid_has_those_rows() {
        let mut geometry = Geometry::new([3, 6, 2], [0.5, 0.7, 1.5]).with_origin([10.0, -4.0, 2.0]);
        let (c, s) = (0.6_f64, 0.8_f64);
        geometry.directions = [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]];
        let strip = geometry.z_slab(1..2).y_rows(2..5);
        assert_eq!(strip.dims, [3, 3, 1]);
        let world = |g: &Geometry, ijk: [f64; 3]| {
            let m = g.world_from_voxel();
            [0, 1, 2].map(|r| m[r][0] * ijk[0] + m[r][1] * ijk[1] + m[r][2] * ijk[2] + m[r][3])
        };
        // voxel (2, 1, 0) of the strip is voxel (2, 3, 1) of the grid: -0.7 * 0.8 * 3 + ... by hand
        let (a, b) = (world(&strip, [2.0, 1.0, 0.0]), world(&geometry, [2.0, 3.0, 1.0]));
        let by_hand = [10.0 + 2.0 * 0.5 * c - 3.0 * 0.7 * s, -4.0 + 2.0 * 0.5 * s + 3.0 * 0.7 * c, 2.0 + 1.5];
        for r in 0..3 {
            assert!((a[r] - b[r]).abs() < 1e-12 && (a[r] - by_hand[r]).abs() < 1e-12, "{a:?} {b:?} {by_hand:?}");
        }
        assert_eq!(geometry.y_rows(5..9).dims[1], 1, "clamped to the grid");
        let data = Array3::from_shape_fn((2, 6, 3), |(k, j, i)| (100 * k + 10 * j + i) as f32);
        let v = Volume::new(geometry.clone(), data).unwrap();
        let rows = v.y_rows(2..5);
        assert_eq!((rows.geometry.clone(), rows.data[[1, 2, 1]]), (geometry.y_rows(2..5), 141.0));
    }
}
