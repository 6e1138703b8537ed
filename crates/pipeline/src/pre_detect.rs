//! The boundaries found in the (v, g) histogram before the tracing, which
//! set its defaults (`mdtf_boundary::Detected`): the least peak g among
//! them bounds g_hit_min, so that no boundary found loses its crossings to
//! a noise floor raised by a noisy material, and the span of their
//! materials is the range the Fig. 2 thresholds scale by (the min-max
//! range of a noisy scan is wider than its materials').
//!
//! The histogram is the one the default transfer function reads, of every
//! voxel's v and g on qbert's axes of [`HVOL_BINS`] bins, counted whole or
//! piece by piece (the counts add up exactly, so a slab run finds what a
//! whole run does).

use mdtf_boundary::Detected;
use mdtf_histogram::{Axis, HistogramError, HvolAxes, MIN_SIGMA_SPACINGS, count, detect_in};

/// Bins of each axis (the histogram volume's).
pub const HVOL_BINS: usize = 256;

/// The (v, g) counts of the voxels seen so far, v fastest (serialisable:
/// a cluster's tasks count their slabs and the run merges them).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VgCounts {
    axes: [Axis; 2],
    counts: Vec<u64>,
}

impl VgCounts {
    /// No voxels yet, over the (v, g) axes of the histogram volume: `v`
    /// and `g` with [`HVOL_BINS`] bins each (from [`HvolAxes::spec`]).
    pub fn new(v: Axis, g: Axis) -> VgCounts {
        let counts = vec![0; v.bins * g.bins];
        VgCounts { axes: [v, g], counts }
    }

    /// The qbert axes of whole `v` and `g` volumes' samples.
    pub fn axes_of(v: &[f32], g: &[f32]) -> Result<(Axis, Axis), HistogramError> {
        Ok((HvolAxes::spec("v", HVOL_BINS).resolve("v", v)?, HvolAxes::spec("g", HVOL_BINS).resolve("g", g)?))
    }

    /// Adds the voxels of a piece (its v and g samples; a NaN is left out).
    pub fn add(&mut self, v: &[f32], g: &[f32]) -> Result<(), HistogramError> {
        let piece = count(&[v, g], self.axes.to_vec(), None)?;
        for (total, n) in self.counts.iter_mut().zip(piece.counts) {
            *total += n;
        }
        Ok(())
    }

    /// Adds the counts of `other`, over the same axes (voxels counted elsewhere).
    pub fn merge(&mut self, other: &VgCounts) -> Result<(), HistogramError> {
        if other.axes != self.axes || other.counts.len() != self.counts.len() {
            return Err(HistogramError::Geometry("(v, g) counts over other axes".into()));
        }
        self.counts.iter_mut().zip(&other.counts).for_each(|(a, b)| *a += b);
        Ok(())
    }

    /// What detection finds in the counts on a grid whose least spacing is
    /// `spacing` (world units).
    pub fn detected(&self, spacing: f64) -> Detected {
        let found = detect_in(&self.counts, &self.axes, MIN_SIGMA_SPACINGS * spacing).boundaries;
        let least_g_peak = found.iter().map(|b| b.g_peak).min_by(f64::total_cmp);
        let lowest = found.iter().map(|b| b.v_low).min_by(f64::total_cmp);
        let highest = found.iter().map(|b| b.v_high).max_by(f64::total_cmp);
        Detected { least_g_peak, material_range: lowest.zip(highest).map(|(lo, hi)| [lo, hi]) }
    }
}

/// [`VgCounts::detected`] of whole `v` and `g` volumes' samples.
pub fn detected_of(v: &[f32], g: &[f32], spacing: f64) -> Result<Detected, HistogramError> {
    let (av, ag) = VgCounts::axes_of(v, g)?;
    let mut counts = VgCounts::new(av, ag);
    counts.add(v, g)?;
    Ok(counts.detected(spacing))
}
