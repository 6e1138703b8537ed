//! `mdtf info FILE`: what a volume holds, on stdout.

use crate::args::InfoArgs;
use crate::input::{read_input, read_options};
use crate::progress::Progress;
use anyhow::{Context, Result};
use mdtf_volume::{FileInfo, Geometry, NanPolicy, ReadOptions, VolumeError};
use rayon::prelude::*;
use std::fmt::Write;

/// Prints the description of one file.
pub fn run(args: &InfoArgs, progress: &Progress) -> Result<()> {
    let ext = args.input.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext == "vtu" || ext == "vtk" {
        let m = progress.step("reading", || mdtf_pipeline::stages::tetra::mesh_summary(&args.input))?;
        progress.clear();
        print!("{}", describe_mesh(&args.input.display().to_string(), &m));
        return Ok(());
    }
    // Keep NaN/Inf so they can be counted; info never passes them on.
    let opts = ReadOptions { nan: NanPolicy::Keep, ..read_options(&args.read) };
    if args.read.raw_dims.is_none() && mdtf_volume::ome_zarr::is_store(&args.input) {
        return describe_store(args, &opts, progress);
    }
    let read = progress.step("reading", || -> Result<_> {
        if args.read.raw_dims.is_some() {
            return Ok(Ok(read_input(&args.input, &args.read, &opts)?));
        }
        Ok(mdtf_volume::read_with_info(&args.input, &opts))
    })?;
    let (mf, info, irregular) = match read {
        Ok((mf, info)) => (mf, info, None),
        // a tilted or unevenly spaced series: described as resampling would make it
        Err(VolumeError::NeedsResampling { found, gap_mm, .. }) => {
            let mut resampling = opts.clone();
            resampling.dicom.resample = true;
            let (mf, info) =
                progress.step("reading with resampling", || read_input(&args.input, &args.read, &resampling))?;
            (mf, info, Some((found, gap_mm)))
        }
        Err(e) => return Err(anyhow::Error::new(e).context("cannot read the input")),
    };
    if irregular.is_none() {
        for w in &info.warnings {
            eprintln!("warning: {w}");
        }
    }
    progress.clear();
    if let Some((found, gap_mm)) = irregular {
        println!(
            "irregular:   {found}; not a regular grid: mdtf reads it only with resampling (--resample; for mdtf \
             run --set input.resample=true), onto {gap_mm} mm slices as described below"
        );
    }
    let bins = args.bins as usize;
    let summaries: Vec<FieldSummary> = mf
        .fields
        .iter()
        .map(|f| {
            let values = f.data.as_slice().unwrap_or(&[]);
            let stats = FieldStats::of(values);
            let counts = stats.range.map(|(lo, hi)| histogram_counts(values, lo, hi, bins));
            FieldSummary { name: f.name.clone(), stats, counts }
        })
        .collect();
    print!("{}", describe(&args.input.display().to_string(), &mf.geometry, &info, &summaries));
    Ok(())
}

/// An OME-Zarr store, described from the chunks it holds: the chunks it
/// leaves out hold the fill value and are counted, not read, so that a small
/// store claiming a large grid is described at the cost of what it holds.
fn describe_store(args: &InfoArgs, opts: &ReadOptions, progress: &Progress) -> Result<()> {
    let what = "cannot read the input";
    let image = mdtf_volume::ome_zarr::ZarrImage::open(&args.input, opts.level).context(what)?;
    image.check_size().context(what)?;
    let fields = image.field_count();
    let mut stats: Vec<FieldStats> = (0..fields).map(|_| FieldStats::default()).collect();
    let unstored = progress
        .step("reading the stored chunks", || image.visit_stored(|f, values| stats[f].add(&FieldStats::of(values))))
        .context(what)?;
    for (f, &n) in unstored.voxels.iter().enumerate() {
        stats[f].add(&FieldStats::constant(unstored.fill, n));
    }
    let bins = args.bins as usize;
    let mut counts: Vec<Option<Vec<u64>>> = stats.iter().map(|s| s.range.map(|_| vec![0u64; bins])).collect();
    progress
        .step("counting the histograms", || {
            image.visit_stored(|f, values| {
                if let (Some((lo, hi)), Some(c)) = (stats[f].range, counts[f].as_mut()) {
                    c.iter_mut().zip(histogram_counts(values, lo, hi, bins)).for_each(|(a, b)| *a += b);
                }
            })
        })
        .context(what)?;
    for (f, &n) in unstored.voxels.iter().enumerate() {
        if let (Some((lo, hi)), Some(c)) = (stats[f].range, counts[f].as_mut())
            && n > 0
            && unstored.fill.is_finite()
        {
            c[bin_of(unstored.fill, lo, hi, bins)] += n;
        }
    }
    let mut info = image.info().clone();
    let stored_share = |f: usize| {
        let total = image.geometry().voxel_count() as f64;
        100.0 * (1.0 - unstored.voxels[f] as f64 / total.max(1.0))
    };
    info.details.push((
        "chunks held".into(),
        format!("{:.1} % of the grid; the rest is the fill value {}", stored_share(0), unstored.fill),
    ));
    for w in &info.warnings {
        eprintln!("warning: {w}");
    }
    progress.clear();
    let summaries: Vec<FieldSummary> = image
        .field_names()
        .iter()
        .zip(stats)
        .zip(counts)
        .map(|((name, stats), counts)| FieldSummary { name: name.clone(), stats, counts })
        .collect();
    print!("{}", describe(&args.input.display().to_string(), image.geometry(), &info, &summaries));
    Ok(())
}

/// One field's statistics and histogram counts, as `describe` prints them.
struct FieldSummary {
    name: String,
    stats: FieldStats,
    /// Counts per bin over the finite range (None without finite samples).
    counts: Option<Vec<u64>>,
}

fn describe_mesh(name: &str, m: &mdtf_pipeline::stages::tetra::MeshSummary) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "file:        {name}");
    let _ = writeln!(s, "format:      VTK unstructured grid");
    let _ = writeln!(s, "points:      {}", m.points);
    let cells: Vec<String> = m.cells.iter().map(|(k, n)| format!("{n} {k}")).collect();
    let _ = writeln!(s, "cells:       {}", if cells.is_empty() { "none".into() } else { cells.join(", ") });
    let (lo, hi) = m.bounds;
    let _ = writeln!(s, "bounds:      x [{}, {}], y [{}, {}], z [{}, {}]", lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]);
    for (what, arrays) in [("point", &m.arrays), ("cell", &m.cell_arrays)] {
        let _ = writeln!(s, "{what} arrays: {}", arrays.len());
        for (name, comps, lo, hi) in arrays {
            let _ = writeln!(s, "  {name}: {comps} component(s), range [{lo}, {hi}]");
        }
    }
    let _ = writeln!(
        s,
        "(mdtf tetra keeps the tetrahedra; a one-component point array is the scalar s, else a one-component \
         cell array carried to the points)"
    );
    s
}

fn describe(name: &str, g: &Geometry, info: &FileInfo, fields: &[FieldSummary]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "file:        {name}");
    let endian =
        if info.sample_type.size() > 1 { format!(", {:?} endian", info.endian).to_lowercase() } else { String::new() };
    let gz = if info.compressed { ", gzip" } else { "" };
    let _ = writeln!(s, "format:      {}{gz}", info.format);
    let _ = writeln!(s, "stored type: {}{endian}", info.sample_type);
    if let Some((slope, inter)) = info.scale {
        let _ = writeln!(s, "scaling:     value = {slope} * stored + {inter}");
    }
    for (key, value) in &info.details {
        let _ = writeln!(s, "{:<12} {value}", format!("{key}:"));
    }

    let _ = writeln!(s, "dims:        {} ({} voxels)", g.dims_string(), g.voxel_count());
    let length = info.units.length.as_deref().unwrap_or("world units, unit not stated");
    let _ = writeln!(s, "spacing:     {} {} {} ({length})", g.spacing[0], g.spacing[1], g.spacing[2]);
    let _ = writeln!(s, "value unit:  {}", info.units.value.as_deref().unwrap_or("not stated"));
    let _ = writeln!(s, "origin:      {} {} {}", g.origin[0], g.origin[1], g.origin[2]);
    let m = g.world_from_voxel();
    let _ = writeln!(s, "world_from_voxel (RAS):");
    for row in &m[..3] {
        let _ = writeln!(s, "  [{:>10.4} {:>10.4} {:>10.4} {:>12.4}]", row[0], row[1], row[2], row[3]);
    }
    let _ = writeln!(s, "fields:      {}", fields.len());
    for f in fields {
        let stats = &f.stats;
        let _ = writeln!(s, "\nfield '{}':", f.name);
        let _ = writeln!(s, "  NaN/Inf:   {}", stats.non_finite);
        let (Some((lo, hi)), Some(counts)) = (stats.range, &f.counts) else {
            let _ = writeln!(s, "  no finite samples");
            continue;
        };
        let _ = writeln!(s, "  range:     {lo} .. {hi}");
        let _ = writeln!(s, "  mean:      {:.6}", stats.sum / stats.finite as f64);
        s += &render_histogram(counts, lo, hi);
    }
    s
}

/// Range, sum and counts of one field, in one parallel pass.
#[derive(Default)]
struct FieldStats {
    range: Option<(f32, f32)>,
    sum: f64,
    finite: u64,
    non_finite: u64,
}

impl FieldStats {
    fn of(values: &[f32]) -> FieldStats {
        let one = |chunk: &[f32]| {
            let (mut lo, mut hi, mut sum, mut n) = (f32::INFINITY, f32::NEG_INFINITY, 0.0f64, 0u64);
            for &v in chunk.iter().filter(|v| v.is_finite()) {
                lo = lo.min(v);
                hi = hi.max(v);
                sum += f64::from(v);
                n += 1;
            }
            (lo, hi, sum, n)
        };
        // fixed chunks, summed in order: the mean does not depend on the thread count
        let parts: Vec<(f32, f32, f64, u64)> = values.par_chunks(1 << 16).map(one).collect();
        let (lo, hi, sum, finite) = parts.into_iter().fold((f32::INFINITY, f32::NEG_INFINITY, 0.0, 0), |a, b| {
            (a.0.min(b.0), a.1.max(b.1), a.2 + b.2, a.3 + b.3)
        });
        FieldStats { range: (finite > 0).then_some((lo, hi)), sum, finite, non_finite: values.len() as u64 - finite }
    }

    /// The statistics of `count` samples of `value`.
    fn constant(value: f32, count: u64) -> FieldStats {
        if count == 0 {
            return FieldStats::default();
        }
        if value.is_finite() {
            FieldStats {
                range: Some((value, value)),
                sum: f64::from(value) * count as f64,
                finite: count,
                non_finite: 0,
            }
        } else {
            FieldStats { non_finite: count, ..Default::default() }
        }
    }

    /// Adds the samples `other` describes.
    fn add(&mut self, other: &FieldStats) {
        self.range = match (self.range, other.range) {
            (Some((a, b)), Some((c, d))) => Some((a.min(c), b.max(d))),
            (r, None) | (None, r) => r,
        };
        self.sum += other.sum;
        self.finite += other.finite;
        self.non_finite += other.non_finite;
    }
}

/// The bin of `v` (finite, within lo..=hi) among `bins` equal bins; a value at `hi` lands in the last.
fn bin_of(v: f32, lo: f32, hi: f32, bins: usize) -> usize {
    let width = (hi as f64 - lo as f64) / bins as f64;
    let per_unit = if width > 0.0 { (1.0 / width) as f32 } else { 0.0 };
    // a float-to-int cast saturates
    (((v - lo) * per_unit) as usize).min(bins - 1)
}

/// Counts per bin of the finite values of `values` among `bins` equal bins over lo..=hi.
fn histogram_counts(values: &[f32], lo: f32, hi: f32, bins: usize) -> Vec<u64> {
    let count = |chunk: &[f32]| {
        let mut counts = vec![0u64; bins];
        for &v in chunk.iter().filter(|v| v.is_finite()) {
            counts[bin_of(v, lo, hi, bins)] += 1;
        }
        counts
    };
    values.par_chunks(1 << 18).map(count).reduce(
        || vec![0u64; bins],
        |mut a, b| {
            a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
            a
        },
    )
}

/// Counts per bin with a bar of '#' (linear, 40 characters for the fullest bin).
fn render_histogram(counts: &[u64], lo: f32, hi: f32) -> String {
    let width = (hi as f64 - lo as f64) / counts.len().max(1) as f64;
    let max = counts.iter().copied().max().unwrap_or(1).max(1);
    let mut s = String::from("  histogram:\n");
    for (b, &c) in counts.iter().enumerate() {
        let from = lo as f64 + b as f64 * width;
        let bar = "#".repeat(((c as f64 / max as f64) * 40.0).ceil() as usize);
        let _ = writeln!(s, "  {from:>12.4} | {c:>10} {bar}");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_counts_every_value_once() {
        let v: Vec<f32> = (0..100).map(|i| i as f32).collect();
        let h = render_histogram(&histogram_counts(&v, 0.0, 99.0, 4), 0.0, 99.0);
        let total: u64 = h
            .lines()
            .skip(1)
            .map(|l| l.split('|').nth(1).unwrap().split_whitespace().next().unwrap().parse::<u64>().unwrap())
            .sum();
        assert_eq!(total, 100);
        assert!(h.lines().nth(1).unwrap().contains(" 25 "));
    }
}
