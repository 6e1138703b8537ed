//! The tracing of a one-field file slab by slab under a memory budget, into
//! one file per channel (`mdtf boundary --memory-budget`): the bytes of the
//! whole-volume tracing's files, whatever the slab height.
//!
//! It runs the input, derive, pre-filter and tracing passes of a
//! slab-by-slab run ([`SlabPasses`]) planned to make every traced channel
//! ([`SlabWork::Traced`]), then writes the traced channels from the store
//! slab by slab, with the flipped distance and the alpha maps made from them.

use super::SlabSize;
use super::passes::{SlabPasses, SlabWork};
use crate::boundary_chain::BoundaryChainParams;
use crate::channel::Channel;
use crate::error::{RunError, at, fail};
use crate::progress::Progress;
use crate::report::BoundarySummary;
use crate::run::RunOptions;
use crate::settings::InputSettings;
use mdtf_volume::{ReadOptions, SampleType, SlabWriter};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// What [`trace_files`] wrote and found.
#[derive(Debug)]
pub struct TracedFiles {
    /// Each file by its name (`distance`, `g_hit`, `hit`, `dot`, then
    /// `flipped` and the alpha maps when the tracing's parameters ask for them).
    pub files: Vec<(String, PathBuf)>,
    /// The thresholds the tracing used and the voxels per hit code.
    pub summary: BoundarySummary,
    /// One sentence per boundary the thresholds took out.
    pub warnings: Vec<String>,
    /// The Fig. 2 report, over the g the tracing read (pre-filtered when the chain pre-filters).
    pub report: mdtf_boundary::Report,
    /// Planes per slab (the last may hold fewer).
    pub height: usize,
    /// How many slabs.
    pub slabs: usize,
}

/// Bytes a whole-volume `mdtf boundary` holds per voxel at its peak
/// (measured: 651 MiB on a 256^3 volume, about 41), rounded up.
const WHOLE_TRACE_BYTES_PER_VOXEL: u64 = 44;

/// The budget `mdtf boundary` on the file `input` takes without
/// `--memory-budget`, and the file's grid: three quarters of `available`
/// bytes when the whole-volume tracing would need more and the file is read
/// by planes; None otherwise.
pub fn automatic_trace_budget(
    input: &Path,
    read: &ReadOptions,
    available: u64,
) -> Option<(u64, mdtf_volume::Geometry)> {
    super::automatic_file_budget(input, read, WHOLE_TRACE_BYTES_PER_VOXEL, available)
}

/// Traces the one-field volume in `input` (read by planes where its format
/// allows, else whole) as `chain` says (kernel, pre-filter, tracing
/// parameters; its border and epsilon are the defaults), slab by slab in
/// slabs of `size`, into `dir`/`{channel}{ext}` (`.nii`, `.nii.gz`,
/// `.nrrd` or `.ome.zarr`), byte-identical to the whole-volume tracing's files; the Fig. 2
/// report is returned, not written. The channels wait in a
/// store in `dir`/`.slabs`, removed at the end. `on_stage(name)` is called
/// as each pass starts, `on_slab(k, of)` as it starts its slab k (from 1).
#[allow(clippy::too_many_arguments)]
pub fn trace_files(
    input: &Path,
    read: &ReadOptions,
    chain: &BoundaryChainParams,
    size: SlabSize,
    dir: &Path,
    ext: &str,
    on_stage: &(dyn Fn(&str) + Sync),
    on_slab: &(dyn Fn(usize, usize) + Sync),
) -> Result<TracedFiles, RunError> {
    if chain.border.is_some() || chain.epsilon.is_some() {
        return Err(fail("plan")("a slab-by-slab tracing derives with the default border and epsilon".into()));
    }
    // a format that cannot be written by slabs is refused before any work
    mdtf_volume::SlabWriter::check_format(&dir.join(format!("distance{ext}"))).map_err(at("write"))?;
    let input = InputSettings::of_file(input, read);
    let opts = RunOptions { output: dir.to_path_buf(), ..RunOptions::default() };
    let progress = Progress::new(&opts, on_stage, on_slab);
    let work = SlabWork::Traced { input: &input, chain };
    let (mut run, store) = SlabPasses::read_input(work, &opts, size, (dir, false), progress)?;
    let (mut chans, derived) = run.derive(store)?;
    let traced = run.trace(&mut chans, &derived)?;
    // the passes write the report into the run's folder (`dir`/boundary, made by them); it is returned instead
    std::fs::remove_dir_all(dir.join("boundary")).map_err(at("boundary"))?;
    let (Some(summary), Some(report)) = (traced.boundary, traced.report) else {
        return Err(fail("boundary")("the plan did not trace".into()));
    };
    run.progress.stage("write")?;
    let maps = mdtf_boundary::hit_maps(&chain.boundary, summary.resolved.d_max);
    let traced: Vec<Channel> = crate::channel::traced().collect();
    let names: Vec<String> = traced.iter().map(|c| c.name(&[])).chain(maps.iter().map(|m| m.name.clone())).collect();
    let index =
        |c: Channel| traced.iter().position(|&t| t == c).ok_or_else(|| fail("write")("no traced channel".into()));
    let (distance_at, hit_at) = (index(Channel::Distance)?, index(Channel::Hit)?);
    let mut writers = Vec::with_capacity(names.len());
    let mut files = Vec::with_capacity(names.len());
    for name in names {
        let path = dir.join(format!("{name}{ext}"));
        let w = SlabWriter::create(&path, &run.geo, &["value".to_string()], SampleType::F32).map_err(at("write"))?;
        writers.push((w, Vec::new()));
        files.push((name, path));
    }
    for (k, z) in run.slabs.iter().enumerate() {
        run.progress.slab(k + 1, run.slabs.len())?;
        // the stored channels, then each map from the distance and hit
        for (&c, (_, samples)) in traced.iter().zip(writers.iter_mut()) {
            chans.samples_into(c, z.clone(), samples).map_err(at("write"))?;
        }
        let (stored, made) = writers.split_at_mut(traced.len());
        let (distance, hit) = (&stored[distance_at].1, &stored[hit_at].1);
        for (map, (_, out)) in maps.iter().zip(made.iter_mut()) {
            out.clear();
            out.extend(distance.iter().zip(hit).map(|(&d, &h)| map.at(d, h)));
        }
        // the files are encoded (and compressed) side by side
        writers.par_iter_mut().try_for_each(|(w, samples)| w.put(z.start, &[samples]).map_err(at("write")))?;
    }
    for (w, _) in writers {
        w.finish().map_err(at("write"))?;
    }
    chans.release();
    chans.store.clear();
    // the tracing's own warnings, without the run's "boundary: " prefix
    let warnings = run.warnings.iter().map(|w| w.strip_prefix("boundary: ").unwrap_or(w).to_string()).collect();
    Ok(TracedFiles { files, summary, warnings, report, height: run.height, slabs: run.slabs.len() })
}
