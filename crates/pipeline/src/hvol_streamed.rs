//! The histogram volume straight from a value volume: g and f'' are derived
//! slice by slice and counted as they come, never stored whole.
//!
//! Two streamed derive passes: the first finds the g and f'' axes (range and
//! exact percentile tails, [`ChannelStats`]), the second counts and sums.
//! Computing g and f'' twice costs less than writing them to fresh memory
//! once (page faults of 2 x 4 bytes a voxel), and peak memory is the input
//! plus the histogram.

//!
//! It lives here, not in the histogram crate, because it drives the derive
//! stage: the stage crates never call each other.

use crate::error::StageError;
use mdtf_derive::{DeriveParams, Item};
use mdtf_histogram::{
    ChannelStats, HistogramError, HistogramVolume, HvolAccumulator, HvolAxes, HvolParams, fixed_parts, part_groups,
};
use mdtf_volume::MultiField;
use std::ops::Range;

/// The histogram volume of a one-field `input` with g and f'' derived by
/// `derive`'s kernel, border and epsilon (its items are ignored). Equals
/// [`mdtf_histogram::histogram_volume`] on stored g and f'' up to
/// the rounding of the sums (the counts are the same); the result does not
/// depend on the thread count.
pub fn histogram_volume_derived(
    input: &MultiField,
    derive: &DeriveParams,
    params: &HvolParams,
) -> Result<HistogramVolume, StageError> {
    let Some(value) = input.fields.first() else {
        return Err(HistogramError::Geometry("the input has no fields".into()).into());
    };
    let v = value.data.as_slice().unwrap_or(&[]);
    let [nx, ny, nz] = input.geometry.dims;
    let (plane, n) = (nx * ny, v.len());
    let d = DeriveParams { items: vec![Item::G, Item::F2], ..derive.clone() };
    let parts = fixed_parts(nz);
    let slabs = task_slabs(&parts, rayon::current_num_threads());

    // pass 1: the g and f'' axes
    let (g_spec, h_spec) = (HvolAxes::spec("g", params.bins[1]), HvolAxes::spec("f2", params.bins[2]));
    let stats = mdtf_derive::stream_slices(
        input,
        &d,
        &slabs,
        |_| (ChannelStats::new(g_spec.clip_percent, n), ChannelStats::new(h_spec.clip_percent, n)),
        |(g, h), _, slice| {
            g.add(&slice[0]);
            h.add(&slice[1]);
        },
    )?;
    let Some((g_stats, h_stats)) = stats.into_iter().reduce(|(g, h), (g2, h2)| (g.merge(g2), h.merge(h2))) else {
        return Err(HistogramError::Degenerate("the volume has no slices".into()).into());
    };
    let axes = HvolAxes {
        v: HvolAxes::spec("v", params.bins[0]).resolve("v", v)?,
        g: g_stats.axis(&g_spec, "g")?,
        h: h_stats.axis(&h_spec, "f2")?,
    };

    // pass 2: counts and sums, each fixed part's slices in order within one task
    let tasks = mdtf_derive::stream_slices(
        input,
        &d,
        &slabs,
        |_| HvolAccumulator::new(&axes),
        |acc, k, slice| {
            if let Ok(acc) = acc {
                acc.add_slice(k, nz, &v[k * plane..(k + 1) * plane], &slice[0], &slice[1]);
            }
        },
    )?;
    Ok(HvolAccumulator::finish(tasks.into_iter().collect::<Result<_, _>>()?, params)?)
}

/// One slab of z-slices per thread, each a run of whole `parts`, so that no
/// part's sums are split between tasks.
fn task_slabs(parts: &[Range<usize>], threads: usize) -> Vec<Range<usize>> {
    part_groups(threads).into_iter().map(|group| parts[group.start].start..parts[group.end - 1].end).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use mdtf_histogram::HVOL_PARTS;

    #[test]
    fn parts_cover_the_slices_once_and_groups_never_split_a_part() {
        for nz in [1, 5, 16, 30, 257] {
            let parts = fixed_parts(nz);
            assert_eq!(parts.iter().map(|p| p.len()).sum::<usize>(), nz);
            assert!(parts.windows(2).all(|w| w[0].end == w[1].start));
            for threads in [1, 2, 3, 7, 64] {
                let groups = part_groups(threads);
                assert_eq!(groups.first().map(|g| g.start), Some(0));
                assert_eq!(groups.last().map(|g| g.end), Some(HVOL_PARTS));
                assert!(groups.windows(2).all(|w| w[0].end == w[1].start), "threads {threads}");
                assert!(groups.len() <= threads.max(1), "threads {threads}");
                let slabs = task_slabs(&parts, threads);
                assert_eq!(slabs.first().map(|s| s.start), Some(0));
                assert_eq!(slabs.last().map(|s| s.end), Some(nz));
                for p in parts.iter().filter(|p| !p.is_empty()) {
                    assert!(slabs.iter().any(|s| s.start <= p.start && p.end <= s.end), "nz {nz} threads {threads}");
                }
            }
        }
    }
}
