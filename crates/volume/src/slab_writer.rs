//! Volume files written slab by slab, in z order, and published whole: for
//! runs that never hold a whole volume. The bytes equal those of
//! [`write`](crate::write) of the whole (multi-field) volume with the
//! default [`WriteOptions`](crate::WriteOptions) and `ty`, whatever the slabs.
//!
//! NIfTI stores several fields one after another, so the first field goes
//! straight into the file and the others wait in partial files beside it
//! (removed on any failure or signal), appended when the last slab is in.
//! A `.nii.gz` is written as gzip members, one a plane, as the whole
//! writer writes it ([`crate::gz_members`]): each slab's planes compress
//! side by side.
//! NRRD interleaves the fields per voxel and OME-Zarr chunks them, so both
//! take each slab as it comes.

use crate::SampleType;
use crate::dtype::first_unrepresentable;
use crate::error::{Result, VolumeError};
use crate::geometry::Geometry;
use crate::io::Format;
use crate::ome_zarr::ZarrWriter;
use crate::output::{AtomicWriter, Inputs, OutputFolder, StagedFile};
use crate::samples::{FieldAxis, write_fields};
use std::io::{BufWriter, Write};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// A volume file being written slab by slab (see the module docs). Dropped
/// before [`SlabWriter::finish`], it leaves nothing behind and the target as it was.
pub struct SlabWriter {
    path: PathBuf,
    geometry: Geometry,
    ty: SampleType,
    fields: usize,
    /// The next plane expected.
    next: usize,
    sink: Sink,
}

/// Where the samples go, by format.
enum Sink {
    /// The first field into the file, the others into partial files
    /// (encoded, and compressed as the file is) until the end.
    /// `gz`: the header and every plane a gzip member of its own, as the whole writer writes them.
    Nifti { out: AtomicWriter, gz: bool, rest: Vec<(StagedFile, BufWriter<std::fs::File>)> },
    /// Fields interleaved per voxel, after the header.
    Nrrd(AtomicWriter),
    /// A store in a folder published whole.
    Zarr { writer: Box<ZarrWriter>, folder: OutputFolder },
}

/// Writes one field's planes (`plane` samples each) as `ty`, as gzip members when `gz`.
fn put_field(w: &mut dyn Write, samples: &[f32], plane: usize, ty: SampleType, gz: bool) -> std::io::Result<()> {
    match gz {
        true => crate::gz_members::write_plane_members(w, samples, plane, ty),
        false => write_fields(w, &[samples], FieldAxis::Slowest, ty),
    }
}

impl SlabWriter {
    /// Starts writing `path` (`.nii`, `.nii.gz`, `.nrrd` or `.ome.zarr`,
    /// by its extension) on `geometry` with the fields `names` (their names
    /// go into the file where the format keeps them), samples stored as `ty`.
    pub fn create(path: &Path, geometry: &Geometry, names: &[String], ty: SampleType) -> Result<SlabWriter> {
        if names.is_empty() {
            return Err(VolumeError::Fields(format!("{}: a volume needs at least one field", path.display())));
        }
        let gz = path.to_string_lossy().to_ascii_lowercase().ends_with(".gz");
        let sink = match Format::from_path(path) {
            Some(Format::Nifti | Format::NiftiGz) => {
                let header = match gz {
                    true => crate::nifti::nifti_gz_header(path, geometry, names.len(), ty)?,
                    false => crate::nifti::header_of(path, geometry, names.len(), ty)?,
                };
                let mut out = AtomicWriter::create(path)?;
                out.write_all(&header).map_err(|e| VolumeError::io(path, e))?;
                let rest = (1..names.len())
                    .map(|k| {
                        let (staged, file) = StagedFile::open(&field_file(path, k))?;
                        Ok((staged, BufWriter::new(file)))
                    })
                    .collect::<Result<_>>()?;
                Sink::Nifti { out, gz, rest }
            }
            Some(Format::Nrrd) => {
                let header = crate::nrrd::header_of(geometry, names, ty);
                let mut out = AtomicWriter::create(path)?;
                out.write_all(header.as_bytes()).map_err(|e| VolumeError::io(path, e))?;
                Sink::Nrrd(out)
            }
            Some(Format::OmeZarr) => {
                let folder = OutputFolder::begin(path, &Inputs::new())?;
                let writer = Box::new(ZarrWriter::create(folder.path(), geometry, names, ty)?);
                Sink::Zarr { writer, folder }
            }
            _ => return Err(not_by_slabs(path)),
        };
        Ok(SlabWriter { path: path.to_path_buf(), geometry: geometry.clone(), ty, fields: names.len(), next: 0, sink })
    }

    /// Whether `path`'s format can be written slab by slab (`.nii`,
    /// `.nii.gz`, `.nrrd` or `.ome.zarr`): an error naming them if not.
    pub fn check_format(path: &Path) -> Result<()> {
        match Format::from_path(path) {
            Some(Format::Nifti | Format::NiftiGz | Format::Nrrd | Format::OmeZarr) => Ok(()),
            _ => Err(not_by_slabs(path)),
        }
    }

    /// Adds the planes from `first` on: one x-fastest slice per field, each
    /// of the same whole number of planes. Slabs come in z order, each
    /// starting where the one before ended.
    pub fn put(&mut self, first: usize, fields: &[&[f32]]) -> Result<()> {
        let plane = self.geometry.dims[0] * self.geometry.dims[1];
        let planes = fields.first().map_or(0, |f| f.len() / plane.max(1));
        if first != self.next
            || fields.len() != self.fields
            || fields.iter().any(|f| f.len() != planes * plane)
            || first + planes > self.geometry.dims[2]
        {
            return Err(VolumeError::header(
                &self.path,
                format!(
                    "slab of {} field(s) at planes {first}..{} does not follow plane {} of {} field(s) on {}",
                    fields.len(),
                    first + planes,
                    self.next,
                    self.fields,
                    self.geometry.dims_string()
                ),
            ));
        }
        for f in fields {
            if let Some((index, value)) = first_unrepresentable(f, self.ty) {
                let (path, target) = (self.path.clone(), self.ty.name());
                return Err(VolumeError::NotRepresentable { path, value, index: first * plane + index, target });
            }
        }
        let io = |e| VolumeError::io(&self.path, e);
        match &mut self.sink {
            Sink::Nifti { out, gz, rest } => {
                put_field(out, fields[0], plane, self.ty, *gz).map_err(io)?;
                for ((_, w), f) in rest.iter_mut().zip(&fields[1..]) {
                    put_field(w, f, plane, self.ty, *gz).map_err(io)?;
                }
            }
            Sink::Nrrd(out) => write_fields(out, fields, FieldAxis::Fastest, self.ty).map_err(io)?,
            Sink::Zarr { writer, .. } => writer.write_planes(first, fields)?,
        }
        self.next = first + planes;
        Ok(())
    }

    /// Publishes the file once every plane is in.
    pub fn finish(self) -> Result<()> {
        let SlabWriter { path, geometry, next, sink, .. } = self;
        if next != geometry.dims[2] {
            let what = format!("only planes 0..{next} of {} were written", geometry.dims[2]);
            return Err(VolumeError::header(&path, what));
        }
        match sink {
            Sink::Nifti { mut out, rest, .. } => {
                for (staged, w) in rest {
                    let file = w.into_inner().map_err(|e| VolumeError::io(&path, e.into_error()))?;
                    drop(file);
                    let mut field = std::fs::File::open(staged.partial()).map_err(|e| VolumeError::io(&path, e))?;
                    std::io::copy(&mut field, &mut out).map_err(|e| VolumeError::io(&path, e))?;
                }
                out.publish()
            }
            Sink::Nrrd(out) => out.publish(),
            Sink::Zarr { writer, folder } => {
                drop(writer);
                folder.publish(&Inputs::new())
            }
        }
    }
}

/// The error of a format [`SlabWriter`] does not write.
fn not_by_slabs(path: &Path) -> VolumeError {
    VolumeError::header(path, "volumes are written slab by slab as .nii, .nii.gz, .nrrd (attached) or .ome.zarr")
}

/// Where field `k` of a NIfTI being written waits (its partial file is made beside this name).
fn field_file(path: &Path, k: usize) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".field{k}"));
    path.with_file_name(name)
}

/// Writes a one-field volume slab by slab (see [`SlabWriter`]):
/// `slab(z, samples)` sets `samples` to those of planes `z` for each of
/// `slabs`, which must cover the planes in order.
pub fn write_slabs(
    path: &Path,
    geometry: &Geometry,
    ty: SampleType,
    slabs: &[Range<usize>],
    slab: &mut crate::io::SlabSamples<'_>,
) -> Result<()> {
    let nz = geometry.dims[2];
    if slabs.first().map(|s| s.start) != Some(0)
        || slabs.last().map(|s| s.end) != Some(nz)
        || slabs.windows(2).any(|w| w[0].end != w[1].start)
    {
        return Err(VolumeError::header(path, format!("the slabs {slabs:?} do not cover the {nz} planes in order")));
    }
    let mut w = SlabWriter::create(path, geometry, &["value".to_string()], ty)?;
    let mut data = Vec::new();
    for z in slabs {
        slab(z.clone(), &mut data).map_err(|e| VolumeError::io(path, e))?;
        w.put(z.start, &[&data])?;
    }
    w.finish()
}
