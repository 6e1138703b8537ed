//! Reading a one-field volume file a few z-planes at a time, front to back,
//! for slab-by-slab runs that never hold the whole volume: uncompressed and
//! gzip NIfTI-1 and NRRD (raw or gzip, attached or detached), read once as
//! a stream (a slab and the next may overlap, their halos, and the overlap
//! is kept, not read again), and OME-Zarr, read by chunks in any order.

use crate::dtype::decode_samples;
use crate::error::{Result, VolumeError};
use crate::geometry::Geometry;
use crate::io::Format;
use crate::samples::{NanPolicy, ReadOptions, SampleStream};
use crate::volume::Volume;
use std::io::Read as _;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Where a [`PlaneReader`] takes its planes from.
enum Source {
    /// The samples as a stream, front to back.
    Stream(SampleStream),
    /// An OME-Zarr image, read by chunks.
    Zarr(Box<crate::ome_zarr::ZarrImage>),
}

/// A one-field volume file read plane by plane (see the module docs).
pub struct PlaneReader {
    path: PathBuf,
    source: Source,
    geometry: Geometry,
    nan: NanPolicy,
    /// Decoded planes `first..next`, x-fastest.
    kept: Vec<f32>,
    first: usize,
    next: usize,
    bytes: Vec<u8>,
}

impl PlaneReader {
    /// Opens `path` for reading by planes; None when its format or encoding
    /// is read only whole (DICOM, TIFF, MetaImage, ascii NRRD, NRRD data
    /// located from the file's end) or it holds more than one field.
    pub fn open(path: &Path, opts: &ReadOptions) -> Result<Option<PlaneReader>> {
        if crate::ome_zarr::is_store(path) {
            let image = crate::ome_zarr::ZarrImage::open(path, opts.level)?;
            if image.field_count() != 1 {
                return Ok(None);
            }
            // one plane at least must fit: a store may claim any shape
            let [nx, ny, _] = image.geometry().dims;
            crate::limits::check_dims(path, &[nx as u64, ny as u64, 1], 1).map_err(|e| match e {
                VolumeError::TooLarge { needed, available, .. } => VolumeError::header(
                    path,
                    format!("one plane of {nx}x{ny} would need {needed} as f32 but only {available} is available"),
                ),
                other => other,
            })?;
            return Ok(Some(PlaneReader {
                path: path.to_path_buf(),
                geometry: image.geometry().clone(),
                source: Source::Zarr(Box::new(image)),
                nan: opts.nan,
                kept: Vec::new(),
                first: 0,
                next: 0,
                bytes: Vec::new(),
            }));
        }
        let format = Format::from_content(path).or_else(|| Format::from_path(path));
        let opened = match format {
            Some(Format::Nifti | Format::NiftiGz | Format::NiftiPair) => Some(crate::nifti::open_samples(path)?),
            Some(Format::Nrrd | Format::Nhdr) => crate::nrrd::open_samples(path)?,
            _ => None,
        };
        let Some((stream, geometry)) = opened else { return Ok(None) };
        if stream.layout.fields != 1 {
            return Ok(None);
        }
        Ok(Some(PlaneReader {
            path: path.to_path_buf(),
            source: Source::Stream(stream),
            geometry,
            nan: opts.nan,
            kept: Vec::new(),
            first: 0,
            next: 0,
            bytes: Vec::new(),
        }))
    }

    /// The file's grid.
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// The units the file states for its values and lengths.
    pub fn units(&self) -> &crate::Units {
        match &self.source {
            Source::Zarr(image) => &image.info().units,
            Source::Stream(stream) => &stream.units,
        }
    }

    /// The file or store read.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether any planes can be read in any order, by any number of
    /// readers at once (an OME-Zarr store), rather than front to back.
    pub fn reads_any_planes(&self) -> bool {
        matches!(self.source, Source::Zarr(_))
    }

    /// Planes `z` (clamped to the grid) as a volume placed where they lie.
    /// From a stream, planes before those of the previous call's start are
    /// gone: a call asking for them fails, since it reads forward only (an
    /// OME-Zarr store gives any planes).
    pub fn read(&mut self, z: Range<usize>) -> Result<Volume> {
        if let Source::Zarr(image) = &self.source {
            return image.read(z, self.nan)?.into_scalar();
        }
        let nz = self.geometry.dims[2];
        let (z0, z1) = (z.start.min(nz), z.end.min(nz).max(z.start.min(nz)));
        if z0 < self.first {
            return Err(VolumeError::header(
                &self.path,
                format!("planes from {z0} were asked for after planes from {}: it is read front to back", self.first),
            ));
        }
        let plane = self.geometry.dims[0] * self.geometry.dims[1];
        // drop what lies before z0, read what lies before z1
        let drop = (z0.min(self.next) - self.first) * plane;
        self.kept.drain(..drop);
        self.first = z0.min(self.next);
        while self.next < z0 {
            self.read_plane(plane)?;
            self.kept.clear();
            self.first = self.next;
        }
        while self.next < z1 {
            self.read_plane(plane)?;
        }
        let data = self.kept[(z0 - self.first) * plane..(z1 - self.first) * plane].to_vec();
        Volume::from_samples(self.geometry.z_slab(z0..z1), data)
    }

    /// Decodes the next plane onto the end of `kept`, with the file's
    /// scale and the NaN policy applied.
    fn read_plane(&mut self, plane: usize) -> Result<()> {
        let Source::Stream(stream) = &mut self.source else {
            return Err(VolumeError::header(&self.path, "an OME-Zarr store is read by chunks, not as a stream"));
        };
        let layout = stream.layout;
        let size = layout.ty.size();
        self.bytes.resize(plane * size, 0);
        let mut got = 0;
        while got < self.bytes.len() {
            match stream.src.read(&mut self.bytes[got..]) {
                Ok(0) => break,
                Ok(k) => got += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) if stream.compressed => {
                    return Err(VolumeError::Gzip { path: self.path.clone(), cause: e });
                }
                Err(e) => return Err(VolumeError::io(&self.path, e)),
            }
        }
        if got < self.bytes.len() {
            return Err(VolumeError::Truncated {
                path: self.path.clone(),
                expected: layout.byte_len(),
                found: (self.next * plane * size + got) as u64,
            });
        }
        let start = self.kept.len();
        self.kept.resize(start + plane, 0.0);
        let out = &mut self.kept[start..];
        decode_samples(&self.bytes, layout.ty, layout.endian, out);
        if let Some((slope, inter)) = layout.scale {
            for v in out.iter_mut() {
                *v = (*v as f64 * slope + inter) as f32;
            }
        }
        crate::samples::apply_nan_policy(&self.path, self.nan, out)?;
        self.next += 1;
        Ok(())
    }
}
