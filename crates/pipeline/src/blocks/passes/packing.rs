//! The pack pass: every histogram counted and every texture quantised in
//! one pass over the slabs (or by tasks), then the tables, the manifest,
//! the Gaussians and the TF figures.

use super::{Derived, SlabPasses, io};
use crate::blocks::remote::SlabPass;
use crate::blocks::slab_histograms::SlabHistograms;
use crate::blocks::{SlabChannels, by_name, channels_named, medians};
use crate::channel::Channel;
use crate::hist_files::Written;
use crate::report::Traced;
use crate::run::{RunError, at, fail};
use mdtf_histogram::{ChannelStats, Histogram};
use mdtf_pack::{PackParams, PackWriter, Profile};
use mdtf_volume::Volume;
use std::collections::BTreeMap;
use std::time::Instant;

impl SlabPasses<'_> {
    /// The pack's code ranges: the whole run's rule; the channels it leaves
    /// to the pack's own measure (the value) get their finite range here,
    /// since no slab sees the whole channel.
    fn pack_params(&self, derived: &Derived, traced: &Traced) -> Result<PackParams, RunError> {
        let profile = self.settings()?.profile();
        let mut ranges = BTreeMap::new();
        for name in &profile.channels(&[]) {
            let unknown = || fail("pack")(format!("the {profile} pack reads an unknown channel '{name}'"));
            let c = Channel::of_store(name).ok_or_else(unknown)?;
            let whole = || self.stats.0.get(&c).cloned().unwrap_or_else(|| ChannelStats::new((0.0, 0.0), 0));
            let r = match crate::pack_inputs::range_of(name, whole, traced.d_max).map_err(at("pack"))? {
                Some(r) => Some(r),
                None if c == Channel::InvG && derived.smallest_inv_g.is_finite() => {
                    Some(crate::pack_inputs::inv_g_range(derived.smallest_inv_g))
                }
                None if matches!(c, Channel::Nx | Channel::Ny | Channel::Nz) => None,
                None => self.stats.range(c).map(|(lo, hi)| [lo as f64, hi as f64]),
            };
            if let Some(r) = r {
                ranges.insert(name.clone(), r);
            }
        }
        Ok(PackParams { profile, ranges, fields: vec![], dtype: None, nifti: false })
    }

    /// The pack (with the histograms counted in the same pass): its
    /// textures, tables, manifest and figures; the names of the tables and
    /// the boundaries the histogram volume shows.
    pub(in crate::blocks) fn pack(
        &mut self,
        chans: &mut SlabChannels,
        derived: &Derived,
        traced: &Traced,
    ) -> Result<(Vec<String>, Vec<mdtf_histogram::DetectedBoundary>), RunError> {
        let params = self.pack_params(derived, traced)?;
        let pdir = self.dir.join("pack");
        std::fs::create_dir_all(&pdir).map_err(io("pack"))?;
        let sources = BTreeMap::new();
        let mut writer = PackWriter::new(&pdir, &params, self.geo.clone(), &sources);
        let started = Instant::now();
        let hists = self.histograms_and_textures(chans, derived, &params, &mut writer)?;
        self.finish_pack(chans, derived, &params, writer, hists, started)
    }

    /// One pass over the slabs that counts every histogram and quantises
    /// every texture, so each slab's channels are made once; its time is
    /// the pack stage's (the histogram stage's is writing the histogram
    /// files, which this writes too).
    fn histograms_and_textures(
        &mut self,
        chans: &mut SlabChannels,
        derived: &Derived,
        params: &PackParams,
        writer: &mut PackWriter,
    ) -> Result<Written, RunError> {
        let counting = self.histograms.counted || self.hvol_needed;
        let what = if counting { "histogram and pack" } else { "pack" };
        self.progress.stage(&format!("{what}{}", if self.tasks.is_some() { " (tasks)" } else { "" }))?;
        let n = self.geo.voxel_count();
        let mut histograms = match counting {
            true => {
                let inv_g = match SlabHistograms::counts_inverse_gradient(&self.histograms, chans) {
                    true => medians::inverse_gradient_axis(
                        &mut |pass| self.select(chans, pass),
                        derived.g_buckets.as_ref(),
                    )?,
                    false => None,
                };
                let (stats, slabs, hvol) = (&self.stats, &self.slabs, self.hvol_needed);
                Some(SlabHistograms::new(&self.histograms, chans, stats, slabs, n, hvol, inv_g)?)
            }
            false => None,
        };
        let layouts = mdtf_pack::texture_layouts(params);
        let components: Vec<&String> = layouts.iter().flat_map(|l| l.components.iter().flatten()).collect();
        let mut read: Vec<Channel> = histograms.as_ref().map(|h| h.axes().channels()).unwrap_or_default();
        for c in channels_named(&components).map_err(at("pack"))? {
            if !read.contains(&c) {
                read.push(c);
            }
        }
        if let Some(tasks) = self.tasks {
            let targets = writer.task_textures(&layouts, self.resumed).map_err(at("pack"))?;
            let axes = histograms.as_ref().map(|h| h.axes().clone());
            // a task counting the histogram volume holds whole fixed parts of its slices
            let task_slabs = match axes.as_ref().is_some_and(|a| a.counts_hvol()) {
                true => mdtf_histogram::fixed_parts(self.geo.dims[2]).into_iter().filter(|p| !p.is_empty()).collect(),
                false => self.slabs.clone(),
            };
            let pass = SlabPass::Pack { textures: targets.clone(), histograms: axes, read, height: self.height };
            for part in self.on_tasks(tasks, pass, &mut chans.store, &task_slabs)? {
                if let (Some(h), Some(counts)) = (&mut histograms, part.histograms) {
                    h.merge(counts)?;
                }
            }
            writer.adopt_task_textures(&targets).map_err(at("pack"))?;
            return match histograms {
                Some(h) => self.write_histograms(h),
                None => Ok(Written::default()),
            };
        }
        let mut counting_failed = None;
        let (progress, height, count) = (&self.progress, self.height, self.slabs.len());
        let written = writer.add_slabs(&layouts, &self.slabs, &mut |z, spent| {
            progress.report_slab(z.end.div_ceil(height), count);
            chans.give_back(spent);
            let slab = chans
                .volumes(z.clone(), &read)
                .map_err(|e| mdtf_pack::PackError::Io(mdtf_volume::VolumeError::Fields(e.to_string())))?;
            if let Some(h) = &mut histograms
                && let Err(e) = h.add(z.start, &slab)
            {
                counting_failed = Some(e);
                return Err(mdtf_pack::PackError::Geometry("the histograms could not count a slab".into()));
            }
            Ok(by_name(slab))
        });
        if let Some(e) = counting_failed {
            return Err(e);
        }
        written.map_err(at("pack"))?;
        chans.release();
        match histograms {
            Some(h) => self.write_histograms(h),
            None => Ok(Written::default()),
        }
    }

    /// The histogram files (when the pipeline asks for histograms), and
    /// the histogram volume the default TF reads.
    fn write_histograms(&mut self, h: SlabHistograms) -> Result<Written, RunError> {
        let t = Instant::now();
        let mut counted = h.finish(self.geo.spacing)?;
        counted.set_units(&self.units);
        counted.without_g = self.stats.not_finite(Channel::G);
        // the default TF's histogram volume is an output only when the histograms ask for it
        let default_hvol = if self.hvol_asked { None } else { counted.hvol.take() };
        let mut hists = Written::default();
        if self.histograms.counted {
            let hdir = self.dir.join("histogram");
            std::fs::create_dir_all(&hdir).map_err(io("histogram"))?;
            hists =
                crate::hist_files::write(&hdir, counted, default_hvol.as_ref(), &self.input_name, &mut self.warnings)
                    .map_err(fail("histogram"))?;
            self.stages.done("histogram", t, self.geo.voxel_count(), hists.outputs.clone());
        }
        if default_hvol.is_some() {
            hists.hvol = default_hvol;
        }
        Ok(hists)
    }

    /// The pack's lookup tables, manifest, Gaussians and TF figures, after
    /// its textures (`writer`, started at `started`).
    fn finish_pack(
        &mut self,
        chans: &mut SlabChannels,
        derived: &Derived,
        params: &PackParams,
        writer: PackWriter,
        hists: Written,
        started: Instant,
    ) -> Result<(Vec<String>, Vec<mdtf_histogram::DetectedBoundary>), RunError> {
        let Written { arches, figure_hists, hvol, boundaries, .. } = hists;
        let profile = params.profile;
        // the tables read the channels' names and grid (their data only without a histogram volume)
        let stubs: Vec<(String, Volume)> =
            profile.channels(&[]).into_iter().map(|c| (c, Volume::zeros(self.geo.z_slab(0..1)))).collect();
        let s = self.settings()?;
        let alpha = s.outputs.pack.alpha;
        let tf = self.tf.as_ref();
        let luts =
            crate::pack_inputs::luts(profile, tf, &alpha, &stubs, &params.ranges, hvol.as_ref(), &derived.derive)
                .map_err(at("pack"))?;
        let provenance = crate::inputs::provenance(s, self.geo.dims, &self.units);
        writer.finish(&luts, provenance).map_err(at("pack"))?;
        let mut outputs: Vec<String> = vec!["pack/manifest.json".into()];
        if profile == Profile::GaussianTf {
            let gaussians = self.write_gaussians(chans, derived, hvol.as_ref())?;
            let hdir = self.dir.join("histogram");
            let written =
                crate::figures::write_gaussian_figures(&hdir, &gaussians, &figure_hists, &[], &self.input_name)
                    .map_err(at("pack"))?;
            outputs.extend(written.into_iter().map(|f| format!("histogram/{f}")));
        }
        if !figure_hists.is_empty() {
            let hists: Vec<&Histogram> = figure_hists.iter().collect();
            let hdir = self.dir.join("histogram");
            let written = crate::figures::write_tf_figures(&hdir, &luts, &hists, &self.input_name, &arches)
                .map_err(at("pack"))?;
            outputs.extend(written.into_iter().map(|f| format!("histogram/{f}")));
        }
        self.stages.done("pack", started, self.geo.voxel_count(), outputs);
        Ok((luts.into_iter().map(|l| l.name).collect(), boundaries))
    }

    /// gaussian-tf's primitives: the TF file's, else a TGTF at each boundary
    /// the histogram volume shows, else the paper's median default; written
    /// into the pack and returned.
    fn write_gaussians(
        &mut self,
        chans: &mut SlabChannels,
        derived: &Derived,
        hvol: Option<&mdtf_histogram::HistogramVolume>,
    ) -> Result<Vec<mdtf_pack::GaussianPrimitive>, RunError> {
        let gaussians = match (self.tf.as_ref(), hvol) {
            (Some(tf), _) => tf.gaussians(),
            (None, Some(hv)) => {
                let arches = crate::pack_inputs::arches_from(&mdtf_histogram::detect_boundaries(hv));
                match arches.is_empty() {
                    false => crate::gaussians::boundary_tgtfs(&arches, &self.geo),
                    true => {
                        let n = self.geo.voxel_count();
                        let mut run = |pass| self.select(chans, pass);
                        let tgtf = medians::median_tgtf(&mut run, derived.g_buckets.as_ref(), n)?;
                        vec![tgtf.ok_or_else(|| fail("pack")("channel 'v' has no finite sample".into()))?]
                    }
                }
            }
            (None, None) => return Err(fail("pack")("the default Gaussians need the histogram volume".into())),
        };
        crate::gaussians::write(&self.dir.join("pack"), &gaussians).map_err(at("pack"))?;
        Ok(gaussians)
    }
}
