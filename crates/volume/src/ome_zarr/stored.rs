//! Walking the chunks a store holds, without the ones it does not.
//!
//! Zarr leaves a chunk that holds only the fill value unwritten, so a store
//! of a few kilobytes may claim a volume of gigabytes. Statistics (`mdtf
//! info`) need only the stored chunks, each read by its subchunks when the
//! array is sharded (bounded memory), and the count of voxels the missing
//! chunks fill.

use super::{Role, ZarrImage, boxed};
use crate::dtype::{Endian, decode_samples};
use crate::error::{Result, VolumeError};
use std::ops::Range;
use zarrs::array::{ArrayBytes, ArrayShardedExt, ArraySubset};

/// What [`ZarrImage::visit_stored`] found besides the stored samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Unstored {
    /// Per field, the voxels in chunks the store does not hold.
    pub voxels: Vec<u64>,
    /// The value those voxels have (the array's fill value, as f32).
    pub fill: f32,
}

impl ZarrImage {
    /// Calls `visit(field, samples)` with the samples of every chunk the
    /// store holds (sharded arrays by subchunk, so that memory stays at one
    /// subchunk), in chunk order, and returns the voxels of the chunks it
    /// does not hold. Samples are as stored, converted to f32 (NaN kept).
    pub fn visit_stored(&self, mut visit: impl FnMut(usize, &[f32])) -> Result<Unstored> {
        let array = &self.array;
        let grid: Vec<u64> = array.chunk_grid_shape().to_vec();
        let sub: Option<Vec<u64>> =
            array.effective_subchunk_shape().map(|s| s.iter().map(|n| n.get()).collect::<Vec<u64>>());
        let channel_axis = self.roles.iter().position(|&r| r == Role::Channel);
        let fields = self.fields.len();
        let mut missing = vec![0u64; fields];
        let mut samples = Vec::new();
        let what = |key: &str| format!("reading chunk {key} (its file in the store)");
        for index in GridIndices::new(&grid) {
            let region = array
                .chunk_subset_bounded(&index)
                .map_err(|e| VolumeError::zarr(&self.path, format!("chunk {index:?}"))(boxed(e)))?;
            let key = array.chunk_key(&index);
            // the store is a folder: a chunk is stored when its file exists (asked without reading it)
            let stored = self.path.join(key.as_str()).is_file();
            let ranges = region.to_ranges();
            if !stored {
                let per_channel = region.num_elements() / channel_count(&ranges, channel_axis);
                for f in channel_range(&ranges, channel_axis) {
                    missing[f] += per_channel;
                }
                continue;
            }
            for piece in pieces(&ranges, sub.as_deref()) {
                let subset = ArraySubset::new_with_ranges(&piece);
                let bytes: ArrayBytes<'static> = array
                    .retrieve_array_subset(&subset)
                    .map_err(|e| VolumeError::zarr(&self.path, what(key.as_str()))(boxed(e)))?;
                let raw =
                    bytes.into_fixed().map_err(|e| VolumeError::zarr(&self.path, what(key.as_str()))(boxed(e)))?;
                samples.resize(raw.len() / self.ty.size(), 0.0);
                decode_samples(&raw, self.ty, Endian::native(), &mut samples);
                // the channel axis comes before the space axes: each channel's samples are contiguous
                let channels = channel_range(&piece, channel_axis);
                let per_channel = samples.len() / channels.len().max(1);
                for (f, part) in channels.zip(samples.chunks(per_channel.max(1))) {
                    visit(f, part);
                }
            }
        }
        let mut fill = [0.0f32];
        decode_samples(array.fill_value().as_ne_bytes(), self.ty, Endian::native(), &mut fill);
        Ok(Unstored { voxels: missing, fill: fill[0] })
    }
}

/// The fields (channels) a region covers.
fn channel_range(ranges: &[Range<u64>], channel_axis: Option<usize>) -> Range<usize> {
    channel_axis.map_or(0..1, |a| ranges[a].start as usize..ranges[a].end as usize)
}

fn channel_count(ranges: &[Range<u64>], channel_axis: Option<usize>) -> u64 {
    channel_range(ranges, channel_axis).len().max(1) as u64
}

/// A chunk's region cut into subchunk boxes (the region itself when unsharded).
fn pieces(ranges: &[Range<u64>], sub: Option<&[u64]>) -> Vec<Vec<Range<u64>>> {
    let Some(sub) = sub.filter(|s| s.len() == ranges.len()) else { return vec![ranges.to_vec()] };
    let counts: Vec<u64> = ranges.iter().zip(sub).map(|(r, &s)| (r.end - r.start).div_ceil(s.max(1))).collect();
    GridIndices::new(&counts)
        .map(|at| {
            ranges
                .iter()
                .zip(sub)
                .zip(&at)
                .map(|((r, &s), &k)| {
                    let start = r.start + k * s;
                    start..(start + s).min(r.end)
                })
                .collect()
        })
        .collect()
}

/// Every index of a grid of `shape`, last axis fastest.
struct GridIndices {
    shape: Vec<u64>,
    next: Option<Vec<u64>>,
}

impl GridIndices {
    fn new(shape: &[u64]) -> GridIndices {
        let empty = shape.contains(&0);
        GridIndices { shape: shape.to_vec(), next: (!empty).then(|| vec![0; shape.len()]) }
    }
}

impl Iterator for GridIndices {
    type Item = Vec<u64>;

    fn next(&mut self) -> Option<Vec<u64>> {
        let current = self.next.take()?;
        let mut following = current.clone();
        for a in (0..following.len()).rev() {
            following[a] += 1;
            if following[a] < self.shape[a] {
                self.next = Some(following);
                break;
            }
            following[a] = 0;
        }
        Some(current)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_indices_cover_the_grid_once_in_order() {
        let all: Vec<Vec<u64>> = GridIndices::new(&[2, 1, 3]).collect();
        assert_eq!(all, [[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1], [1, 0, 2]]);
        assert_eq!(GridIndices::new(&[]).count(), 1);
        assert_eq!(GridIndices::new(&[3, 0]).count(), 0);
    }

    #[test]
    fn a_shard_is_cut_into_its_subchunks_and_the_edge_ones_are_short() {
        let p = pieces(&[0..1, 64..130, 0..100], Some(&[1, 64, 64]));
        assert_eq!(
            p,
            [
                vec![0..1, 64..128, 0..64],
                vec![0..1, 64..128, 64..100],
                vec![0..1, 128..130, 0..64],
                vec![0..1, 128..130, 64..100]
            ]
        );
        let whole = vec![0..5, 0..3];
        assert_eq!(pieces(&whole, None), std::slice::from_ref(&whole));
    }
}
