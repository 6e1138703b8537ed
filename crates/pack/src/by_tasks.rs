//! A pack texture written by tasks, each its own z-planes, in any process
//! and any order (a cluster run's pack pass): what a task needs to quantise
//! its planes exactly as [`PackWriter::add_slabs`](crate::PackWriter::add_slabs)
//! would, and to write them at their place in the texture's data file.

use crate::PackError;
use crate::profile::TextureLayout;
use crate::quantise::Decode;
use crate::writer::Prepared;
use mdtf_volume::{Volume, VolumeError};
use serde::{Deserialize, Serialize};
use std::io::{Seek, SeekFrom, Write};
use std::ops::Range;
use std::path::PathBuf;

/// One texture of a pack written plane range by plane range elsewhere
/// (made by [`PackWriter::task_textures`](crate::PackWriter::task_textures)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TextureTarget {
    /// The texture's data file: its planes one after another, each plane
    /// x-fastest with the components interleaved, little-endian.
    pub file: PathBuf,
    /// The texture's channels per component and storage type.
    pub layout: TextureLayout,
    /// Each component's decode (None: unused, code 0), from the pack's code ranges.
    pub decodes: Vec<Option<Decode>>,
    /// Voxels per row and rows per plane.
    pub plane: [usize; 2],
}

impl TextureTarget {
    /// Bytes of one z-plane of the texture.
    pub fn plane_bytes(&self) -> usize {
        self.plane[0] * self.plane[1] * self.decodes.len() * self.layout.dtype.size()
    }

    /// Quantises planes `z` of the texture from `chans` (each channel's
    /// samples on those planes) and writes them at their place in the data
    /// file, through `bytes` (reused from call to call: fresh memory of a
    /// slab's size page-faults at a cost like the quantising's); a rerun of
    /// the same planes writes the same bytes.
    pub fn write_planes(
        &self,
        z: Range<usize>,
        chans: &[(String, Volume)],
        bytes: &mut Vec<u8>,
    ) -> Result<(), PackError> {
        let missing = |c: &str| PackError::Geometry(format!("texture {}: channel {c} was not given", self.layout.name));
        let prepared = Prepared::of_slab(&self.layout, &self.decodes, self.plane, &z, chans, &missing)?;
        // every byte is encoded over
        bytes.resize(prepared.plane_bytes() * z.len(), 0);
        prepared.encode_planes(0, bytes);
        let io = |cause| PackError::Io(VolumeError::Io { path: self.file.clone(), cause });
        let mut file = std::fs::OpenOptions::new().write(true).open(&self.file).map_err(io)?;
        file.seek(SeekFrom::Start((self.plane_bytes() * z.start) as u64)).map_err(io)?;
        file.write_all(bytes).map_err(io)
    }
}
