//! Materials found in the joint histogram of several fields: the clusters
//! a multi-field volume's voxels form in field space, from which the
//! default Gaussian transfer function of a multi-field input is built (one
//! Gaussian per material, Kniss et al.'s primitive fitted to its voxels).
//!
//! A homogeneous material is a blob of voxels around its fields' values
//! (spread by noise); the voxels between two materials (partial volume)
//! lie on a thin arc joining their blobs. So the materials are the modes
//! of the joint histogram, and each voxel belongs to the mode whose basin
//! holds its cell. The rule, in full:
//! 1. the m fields (1 to 4) are binned over their finite ranges into
//!    [`CLUSTER_BINS`]`[m - 1]` bins per axis; voxels with a non-finite field
//!    are left out;
//! 2. the counts are smoothed by the binomial filter (1, 2, 1) / 4 along
//!    each axis (nothing beyond the range);
//! 3. the cells are grouped into basins around peaks by persistence (as
//!    ToMATo clusters a density): taken from the highest smoothed count
//!    down, a cell joins the basin of its highest neighbour already taken
//!    (of its 3^m - 1 neighbours), or starts a basin of its own; where it touches two
//!    basins, it is their saddle, and they become one when it holds at
//!    least [`MERGE_RATIO`] of the lower peak's count. So the bumps that
//!    noise leaves along a ridge (the arc of partial-volume voxels between
//!    two materials) are not materials, while two blobs with a clear dip
//!    between them stay two;
//! 4. a basin holding at least [`MIN_CLUSTER_SHARE`] of the voxels is a
//!    cluster; the [`MAX_CLUSTERS`] largest are kept, largest first
//!    (ties: the peak first in memory order);
//! 5. a cluster's core is the cells of its basin whose smoothed count is
//!    at least [`CORE_DENSITY`] of its peak's: for a normal blob, the
//!    voxels within about two standard deviations, without the arcs to
//!    its neighbours; its top is the cells at or above [`TOP_DENSITY`] of
//!    the peak's, the voxels around the mode, which the arcs do not shift
//!    (a thin material, such as a skin, has nearly as many voxels on its
//!    arcs as in its blob). Fits take the spread from the core and the
//!    centre from the top; the basin tells where the material lies in the
//!    volume.
//!
//! Counts are integers summed in a fixed order, so the clusters do not
//! depend on the thread count.

use crate::HistogramError;
use rayon::prelude::*;

/// Bins per axis of the joint histogram for 1, 2, 3 and 4 fields (at most
/// 65536 cells: fine enough to tell materials apart, coarse enough that a
/// material's blob holds thousands of voxels per cell).
pub const CLUSTER_BINS: [usize; 4] = [256, 64, 32, 16];
/// A saddle at least this share of the lower of the two peaks it joins
/// merges their basins: between two equal normal blobs 3 standard
/// deviations apart the dip falls to 0.64 of the peaks, at 4 to 0.27.
pub const MERGE_RATIO: f64 = 0.7;
/// Least share of all voxels in a cluster's basin.
pub const MIN_CLUSTER_SHARE: f64 = 0.01;
/// Most clusters kept (the largest).
pub const MAX_CLUSTERS: usize = 8;
/// A core cell's least smoothed count, as a share of its peak's: exp(-2),
/// where a normal blob's density falls at two standard deviations.
pub const CORE_DENSITY: f64 = 0.135_335_283_236_612_7;
/// A voxel's label when its cell belongs to no cluster, or a field is not finite.
pub const NO_CLUSTER: u8 = u8::MAX;
/// The bit set in a voxel's label when its cell lies in its cluster's core.
pub const CORE_BIT: u8 = 0x80;
/// A top cell's least smoothed count, as a share of its peak's (half the maximum).
pub const TOP_DENSITY: f64 = 0.5;
/// The bit set in a voxel's label when its cell lies in its cluster's top.
pub const TOP_BIT: u8 = 0x40;
/// The bits of a voxel's label that hold its cluster's index.
pub const CLUSTER_MASK: u8 = 0x3f;

/// Voxels binned per parallel part (their counts are summed in part order).
const PART: usize = 1 << 20;

/// One material: a basin of the smoothed joint histogram around its peak.
#[derive(Debug, Clone, PartialEq)]
pub struct Cluster {
    /// The peak cell's centre, one value per field (the fields' units).
    pub peak: Vec<f64>,
    /// Voxels whose cells lie in its basin.
    pub voxels: u64,
    /// Voxels whose cells lie in its core.
    pub core_voxels: u64,
}

/// The clusters of the fields' joint histogram and which cells belong to each.
#[derive(Debug, Clone)]
pub struct JointClusters {
    /// Per field: the lower end of its finite range and its bin width.
    axes: Vec<(f64, f64)>,
    bins: usize,
    /// Per cell (first field fastest): its cluster's index with [`CORE_BIT`]
    /// and [`TOP_BIT`] where they apply, or [`NO_CLUSTER`].
    cell_label: Vec<u8>,
    /// The clusters, largest first.
    pub clusters: Vec<Cluster>,
}

impl JointClusters {
    /// The cell of the voxel whose fields hold `values`, if all are finite.
    fn cell(&self, values: impl Iterator<Item = f32>) -> Option<usize> {
        let mut cell = 0;
        let mut stride = 1;
        for ((lo, width), x) in self.axes.iter().zip(values) {
            if !x.is_finite() {
                return None;
            }
            let b = if *width > 0.0 { ((x as f64 - lo) / width).floor() } else { 0.0 };
            cell += (b.clamp(0.0, (self.bins - 1) as f64) as usize) * stride;
            stride *= self.bins;
        }
        Some(cell)
    }

    /// Each field's bin width in the joint histogram (the fields' units).
    pub fn bin_widths(&self) -> Vec<f64> {
        self.axes.iter().map(|a| a.1).collect()
    }

    /// Each voxel's label: its cluster's index ([`CLUSTER_MASK`] bits),
    /// `| CORE_BIT` in the core and `| TOP_BIT` in the top, or
    /// [`NO_CLUSTER`]. `fields` as given to [`joint_clusters`].
    pub fn labels(&self, fields: &[&[f32]]) -> Vec<u8> {
        let n = fields.first().map_or(0, |f| f.len());
        let mut labels = vec![NO_CLUSTER; n];
        labels.par_chunks_mut(PART).enumerate().for_each(|(part, out)| {
            let first = part * PART;
            for (k, l) in out.iter_mut().enumerate() {
                let i = first + k;
                *l = self.cell(fields.iter().map(|f| f[i])).map_or(NO_CLUSTER, |c| self.cell_label[c]);
            }
        });
        labels
    }
}

/// The clusters of the joint histogram of `fields` (one slice of samples
/// per field, all of one length; 1 to 4 fields): see the module docs.
pub fn joint_clusters(fields: &[&[f32]]) -> Result<JointClusters, HistogramError> {
    let m = fields.len();
    if !(1..=4).contains(&m) {
        return Err(HistogramError::BadAxis(format!("clusters are found among 1 to 4 fields, got {m}")));
    }
    let n = fields[0].len();
    if fields.iter().any(|f| f.len() != n) {
        return Err(HistogramError::Geometry("the fields hold different numbers of voxels".into()));
    }
    let bins = CLUSTER_BINS[m - 1];
    let mut axes = Vec::with_capacity(m);
    for (a, f) in fields.iter().enumerate() {
        let (lo, hi) = mdtf_volume::finite_sample_range(f)
            .ok_or_else(|| HistogramError::Degenerate(format!("field {a} has no finite sample")))?;
        axes.push((lo as f64, (hi as f64 - lo as f64) / bins as f64));
    }
    let cells = bins.pow(m as u32);
    let mut found = JointClusters { axes, bins, cell_label: vec![NO_CLUSTER; cells], clusters: Vec::new() };
    let counts = count_cells(&found, fields, cells);
    let total: u64 = counts.iter().sum();
    let smooth = smoothed(&counts, bins, m);
    let peak_of = basins(&smooth, bins, m);

    let mut mass: std::collections::BTreeMap<usize, u64> = std::collections::BTreeMap::new();
    for (c, &count) in counts.iter().enumerate() {
        if count > 0 {
            *mass.entry(peak_of[c]).or_default() += count;
        }
    }
    let mut peaks: Vec<(usize, u64)> =
        mass.into_iter().filter(|&(_, v)| v as f64 >= MIN_CLUSTER_SHARE * total as f64).collect();
    peaks.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    peaks.truncate(MAX_CLUSTERS);

    for (k, &(peak, voxels)) in peaks.iter().enumerate() {
        let (floor, top) = (CORE_DENSITY * smooth[peak], TOP_DENSITY * smooth[peak]);
        let mut core_voxels = 0;
        for c in (0..cells).filter(|&c| counts[c] > 0 && peak_of[c] == peak) {
            let core = smooth[c] >= floor;
            let bits = if core { CORE_BIT } else { 0 } | if smooth[c] >= top { TOP_BIT } else { 0 };
            found.cell_label[c] = k as u8 | bits;
            core_voxels += if core { counts[c] } else { 0 };
        }
        let centre = (0..m)
            .map(|a| {
                let b = (peak / bins.pow(a as u32)) % bins;
                let (lo, width) = found.axes[a];
                lo + (b as f64 + 0.5) * width
            })
            .collect();
        found.clusters.push(Cluster { peak: centre, voxels, core_voxels });
    }
    Ok(found)
}

/// The joint histogram's counts per cell, counted in parts summed in order.
fn count_cells(clusters: &JointClusters, fields: &[&[f32]], cells: usize) -> Vec<u64> {
    let n = fields[0].len();
    let parts: Vec<Vec<u64>> = (0..n.div_ceil(PART))
        .into_par_iter()
        .map(|part| {
            let mut counts = vec![0u64; cells];
            for i in part * PART..((part + 1) * PART).min(n) {
                if let Some(c) = clusters.cell(fields.iter().map(|f| f[i])) {
                    counts[c] += 1;
                }
            }
            counts
        })
        .collect();
    let mut counts = vec![0u64; cells];
    for p in parts {
        counts.iter_mut().zip(p).for_each(|(a, b)| *a += b);
    }
    counts
}

/// The counts smoothed by (1, 2, 1) / 4 along each of the m axes (zero beyond the ends).
fn smoothed(counts: &[u64], bins: usize, m: usize) -> Vec<f64> {
    let mut s: Vec<f64> = counts.iter().map(|&c| c as f64).collect();
    for a in 0..m {
        let stride = bins.pow(a as u32);
        let prev = s.clone();
        for (c, out) in s.iter_mut().enumerate() {
            let b = (c / stride) % bins;
            let below = if b > 0 { prev[c - stride] } else { 0.0 };
            let above = if b + 1 < bins { prev[c + stride] } else { 0.0 };
            *out = 0.25 * below + 0.5 * prev[c] + 0.25 * above;
        }
    }
    s
}

/// For every cell, the peak of the basin it belongs to (see the module
/// docs, step 3): cells are taken from the highest smoothed count down
/// (ties in memory order); a cell with no taken neighbour starts a basin,
/// else it joins the neighbouring basin with the highest peak, and two
/// basins it touches become one when its count (their saddle) is at least
/// [`MERGE_RATIO`] of the lower peak's.
fn basins(smooth: &[f64], bins: usize, m: usize) -> Vec<usize> {
    let cells = smooth.len();
    let offsets: Vec<Vec<i64>> = (0..3usize.pow(m as u32))
        .map(|k| (0..m).map(|a| (k / 3usize.pow(a as u32)) as i64 % 3 - 1).collect())
        .filter(|o: &Vec<i64>| o.iter().any(|&d| d != 0))
        .collect();
    let strides: Vec<usize> = (0..m).map(|a| bins.pow(a as u32)).collect();
    let mut order: Vec<usize> = (0..cells).filter(|&c| smooth[c] > 0.0).collect();
    order.sort_by(|&a, &b| smooth[b].total_cmp(&smooth[a]).then(a.cmp(&b)));
    // union-find over cells; a root is its basin's peak
    let mut parent: Vec<usize> = (0..cells).collect();
    let mut taken = vec![false; cells];
    fn root(parent: &mut [usize], mut c: usize) -> usize {
        while parent[c] != c {
            parent[c] = parent[parent[c]];
            c = parent[c];
        }
        c
    }
    // the higher of two peaks (the earlier in memory order on a tie)
    let higher = |a: usize, b: usize| if smooth[a] > smooth[b] || (smooth[a] == smooth[b] && a < b) { a } else { b };
    let mut roots = Vec::with_capacity(offsets.len());
    for &c in &order {
        roots.clear();
        let coords: Vec<i64> = strides.iter().map(|s| ((c / s) % bins) as i64).collect();
        for o in &offsets {
            let mut at = 0usize;
            let mut inside = true;
            for a in 0..m {
                let x = coords[a] + o[a];
                inside &= (0..bins as i64).contains(&x);
                at += x.max(0) as usize * strides[a];
            }
            if inside && taken[at] {
                let r = root(&mut parent, at);
                if !roots.contains(&r) {
                    roots.push(r);
                }
            }
        }
        taken[c] = true;
        let Some(&first) = roots.first() else { continue };
        let mut top = roots.iter().copied().fold(first, higher);
        parent[c] = top;
        // the other basins meet the highest here: those whose peak this saddle nearly reaches join it
        let mut rest: Vec<usize> = roots.iter().copied().filter(|&r| r != top).collect();
        rest.sort_by(|&a, &b| smooth[b].total_cmp(&smooth[a]).then(a.cmp(&b)));
        for r in rest {
            let low = if higher(top, r) == top { r } else { top };
            if smooth[c] >= MERGE_RATIO * smooth[low] {
                let high = higher(top, r);
                parent[low] = high;
                top = high;
            }
        }
    }
    (0..cells).map(|c| root(&mut parent, c)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples of `n` voxels in each of the blobs at `means` (one value per
    /// field), spread by `sd`, from a fixed sequence.
    fn blobs(means: &[[f32; 2]], n: usize, sd: f64) -> Vec<Vec<f32>> {
        let mut state = 12345u64;
        let mut uniform = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let mut normal = move || (-2.0 * uniform().ln()).sqrt() * (2.0 * std::f64::consts::PI * uniform()).cos();
        let mut fields = vec![Vec::new(), Vec::new()];
        for m in means {
            for _ in 0..n {
                for a in 0..2 {
                    fields[a].push((m[a] as f64 + sd * normal()) as f32);
                }
            }
        }
        fields
    }

    #[test]
    fn three_blobs_are_three_clusters_at_their_means() {
        let means = [[0.0, 0.0], [100.0, 0.0], [60.0, 80.0]];
        let fields = blobs(&means, 40_000, 4.0);
        let views: Vec<&[f32]> = fields.iter().map(Vec::as_slice).collect();
        let c = joint_clusters(&views).unwrap();
        assert_eq!(c.clusters.len(), 3, "{:?}", c.clusters);
        let width = [c.axes[0].1, c.axes[1].1];
        for m in means {
            let found = c.clusters.iter().filter(|k| (0..2).all(|a| (k.peak[a] - m[a] as f64).abs() <= width[a]));
            assert_eq!(found.count(), 1, "{m:?}: {:?}", c.clusters);
        }
        // each blob's voxels carry its cluster's label; the core holds most of them (about
        // 1 - exp(-2) = 86 % of a 2-D normal lies within two standard deviations)
        let labels = c.labels(&views);
        for (b, m) in means.iter().enumerate() {
            let k = c.clusters.iter().position(|k| (k.peak[0] - m[0] as f64).abs() <= width[0]).unwrap() as u8;
            let own = &labels[b * 40_000..(b + 1) * 40_000];
            assert!(own.iter().all(|&l| l & CLUSTER_MASK == k));
            assert!(own.iter().all(|&l| l & TOP_BIT == 0 || l & CORE_BIT != 0), "the top lies in the core");
            // within sqrt(2 ln 2) standard deviations: half of a 2-D normal
            let top = own.iter().filter(|&&l| l & TOP_BIT != 0).count() as f64 / 40_000.0;
            assert!((0.35..0.65).contains(&top), "blob {b}: top share {top}");
            let core = own.iter().filter(|&&l| l & CORE_BIT != 0).count() as f64 / 40_000.0;
            assert!((0.75..0.97).contains(&core), "blob {b}: core share {core}");
        }
    }

    #[test]
    fn one_blob_of_noise_is_one_cluster_and_tiny_ones_are_dropped() {
        let mut fields = blobs(&[[10.0, 20.0]], 100_000, 3.0);
        // 0.5 % of the voxels far away: a basin below the least share
        for (a, v) in [(0, 500.0f32), (1, 500.0)] {
            fields[a].extend(std::iter::repeat_n(v, 500));
        }
        let views: Vec<&[f32]> = fields.iter().map(Vec::as_slice).collect();
        let c = joint_clusters(&views).unwrap();
        assert_eq!(c.clusters.len(), 1, "{:?}", c.clusters);
        assert_eq!(c.clusters[0].voxels, 100_000);
        let labels = c.labels(&views);
        assert!(labels[100_000..].iter().all(|&l| l == NO_CLUSTER));
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(joint_clusters(&[]).is_err());
        let nan = [f32::NAN; 4];
        assert!(joint_clusters(&[&nan[..], &nan[..]]).is_err());
        assert!(joint_clusters(&[&[1.0, 2.0][..], &[1.0][..]]).is_err());
    }
}
