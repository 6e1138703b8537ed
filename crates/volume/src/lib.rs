//! The volume type of mdtf and its file I/O.
//!
//! * [`Volume`]: f32 samples, x fastest (ndarray shape (nz, ny, nx)), with a
//!   [`Geometry`] (dims, spacing and origin in world units, axis directions,
//!   `world_from_voxel`). [`MultiField`]: named fields on one grid.
//! * Readers: NIfTI-1 (`.nii`, `.nii.gz`, every common type, scl_slope and
//!   scl_inter applied, sform/qform kept), NRRD (`.nrrd`, `.nhdr`; raw, gzip,
//!   ascii; both endiannesses), MetaImage (`.mha`, `.mhd`; zlib, channels,
//!   LIST slices), TIFF stacks, DICOM series ([`dicom`]: folders, DICOMDIR,
//!   multi-frame; sorted and checked), raw with a caller-given [`RawSpec`].
//!   The content picks the reader, the extension where the content is silent.
//! * Writers: NIfTI, NRRD and MetaImage for f32, u8, u16, atomically; NIfTI,
//!   NRRD and OME-Zarr also slab by slab ([`SlabWriter`]), with the same bytes
//!   ([`output`]: temporary file, then rename; folders swapped in whole),
//!   never over an input.
//!
//! Every error is a [`VolumeError`] naming the file; no reader panics on a
//! malformed file.

pub mod dicom;
mod dtype;
mod erf_edge;
mod error;
mod geometry;
pub mod gz_members;
mod io;
mod limits;
pub mod metaimage;
mod nifti;
pub mod nrrd;
pub mod ome_zarr;
pub mod output;
mod overlap;
mod planes;
mod png_out;
mod range;
mod raw;
mod samples;
mod slab_writer;
mod tiff_stack;
pub mod units;
mod volume;

pub use dtype::{Endian, SAMPLE_TYPE_NAMES, SampleType, round_to_type};
pub use erf_edge::{arch_g, arch_shape, normal_quantile};
pub use error::{Result, VolumeError};
pub use geometry::Geometry;
pub use io::{Format, SlabSamples, WriteOptions, read, read_scalar, read_with_info, write, write_volume};
pub use limits::{available_memory, human_bytes, parse_size};
pub use nifti::{NIFTI1_MAX_AXIS, nifti_gz_header, nifti_version_for, read_nifti, read_nifti_with_info, write_nifti};
pub use output::{AtomicWriter, Inputs, OutputFolder, write_file_atomically};
pub use overlap::overlapped;
pub use planes::PlaneReader;
pub use png_out::{PngColour, register_figure_font, write_png};
pub use range::{
    KeyBuckets, finite_range, finite_sample_range, median, median_from_buckets, median_of_pieces, order_statistic,
    order_statistic_from_buckets, order_statistic_from_counts, order_statistic_of_pieces, upper_bucket_of,
};
pub use raw::{RawSpec, read_raw};
pub use samples::{FileInfo, NanPolicy, ReadOptions};
pub use slab_writer::{SlabWriter, write_slabs};
pub use units::Units;
pub use volume::{Field, MultiField, Volume};
