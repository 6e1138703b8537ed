//! Borrowed input: the samples derive reads, without owning them (a numpy
//! array from the Python package, a block of a larger buffer).

use crate::DeriveError;
use mdtf_volume::{Geometry, MultiField};

/// One field's samples, x fastest then y then z, borrowed.
#[derive(Debug, Clone, Copy)]
pub struct FieldView<'a> {
    /// The field's name (names the Jacobian's components).
    pub name: &'a str,
    /// nx ny nz samples.
    pub samples: &'a [f32],
}

/// One or more fields on one grid, borrowed: what [`run_view`](crate::run_view) reads.
#[derive(Debug, Clone)]
pub struct FieldsView<'a> {
    /// The grid every field is sampled on.
    pub geometry: &'a Geometry,
    /// The fields, in order.
    pub fields: Vec<FieldView<'a>>,
}

impl<'a> FieldsView<'a> {
    /// Fields on `geometry`; an error when one does not hold its voxel count.
    pub fn new(geometry: &'a Geometry, fields: Vec<FieldView<'a>>) -> Result<FieldsView<'a>, DeriveError> {
        let n = geometry.voxel_count();
        if let Some(f) = fields.iter().find(|f| f.samples.len() != n) {
            return Err(DeriveError::FieldCount(format!(
                "field '{}' holds {} samples, the grid {} ({})",
                f.name,
                f.samples.len(),
                n,
                geometry.dims_string()
            )));
        }
        Ok(FieldsView { geometry, fields })
    }
}

impl<'a> From<&'a MultiField> for FieldsView<'a> {
    fn from(mf: &'a MultiField) -> FieldsView<'a> {
        let fields =
            mf.fields.iter().map(|f| FieldView { name: &f.name, samples: f.data.as_slice().unwrap_or(&[]) }).collect();
        FieldsView { geometry: &mf.geometry, fields }
    }
}
