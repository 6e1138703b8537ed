//! `mdtf histogram`: joint and stretched histograms, pictures, the histogram volume.

use crate::args::{HistogramArgs, ScaleArg};
use crate::input::{read_input, read_options};
use crate::progress::Progress;
use anyhow::{Context, Result, bail};
use mdtf_pipeline::boundary_chain::BoundaryChainParams;
use mdtf_pipeline::channel::Channel;
use mdtf_pipeline::channels;
use mdtf_pipeline::stages::derive::DeriveParams;
use mdtf_pipeline::stages::histogram::{
    Axis, AxisSpec, HvolParams, Scale, count, stretched_pair, write_histogram, write_hvol, write_stretched,
};
use mdtf_volume::{Inputs, MultiField, OutputFolder, Volume};
use std::path::{Path, PathBuf};

fn spec_for(args: &HistogramArgs, i: usize, name: &str) -> Result<AxisSpec> {
    let mut spec = AxisSpec::qbert(name);
    let pick = |list: &[String]| if list.len() == 1 { list.first().cloned() } else { list.get(i).cloned() };
    if let Some(r) = pick(&args.range)
        && r != "auto"
    {
        let (a, b) = r.split_once(':').with_context(|| format!("--range: expected MIN:MAX or auto, got '{r}'"))?;
        let (a, b): (f64, f64) = (a.trim().parse()?, b.trim().parse()?);
        spec.range = Some((a, b));
    }
    let bins = if args.bins.len() == 1 { args.bins.first() } else { args.bins.get(i) };
    if let Some(&b) = bins {
        if b == 0 {
            bail!("--bins: zero bins for axis {name}");
        }
        spec.bins = Some(b);
    }
    Ok(spec)
}

/// Computes and writes the requested histograms.
pub fn run(args: &HistogramArgs, progress: &Progress) -> Result<()> {
    check_axes(args)?;
    let chain = BoundaryChainParams { kernel: args.kernel.unwrap_or_default(), ..Default::default() };
    if args.plan {
        return crate::input::print_channel_plan(&args.input, &args.read, &|_| wanted(args), &chain);
    }
    let scale = if args.scale == ScaleArg::Linear { Scale::Linear } else { Scale::Log };
    let given: Vec<&Path> =
        [Some(&args.input), args.mask.as_ref()].into_iter().flatten().map(PathBuf::as_path).collect();
    let inputs = Inputs::of(&given);
    let folder = OutputFolder::begin(&args.output, &inputs)?;
    let (input, _) = progress.step("reading", || read_input(&args.input, &args.read, &read_options(&args.read)))?;
    // planned and run on the whole volume
    let chans = progress.step("computing channels", || channels::compute(&input, &wanted(args), &chain))?;
    let counted = Counting {
        args,
        chans,
        mask: read_mask(args, &input)?,
        title: args
            .input
            .file_name()
            .map_or_else(|| args.input.display().to_string(), |n| n.to_string_lossy().into_owned()),
        scale,
        out: folder.path(),
    };
    counted.joint(progress)?;
    if args.stretched {
        counted.stretched()?;
    }
    if args.hvol {
        counted.histogram_volume(&input, progress)?;
    }
    folder.publish(&inputs)?;
    Ok(())
}

/// The channels the histograms read: the axes, and v, g, g_hit and hit for the stretched pair.
fn wanted(args: &HistogramArgs) -> Vec<String> {
    let mut wanted: Vec<String> = args.axes.clone();
    let stretched_pair = [Channel::Value, Channel::G, Channel::GHit, Channel::Hit];
    for extra in stretched_pair.into_iter().filter(|_| args.stretched).map(|c| c.name(&[])) {
        if !wanted.contains(&extra) {
            wanted.push(extra);
        }
    }
    wanted
}

/// Refuses 0 or more than 3 axes, and lists of bins or ranges that are neither one nor one per axis.
fn check_axes(args: &HistogramArgs) -> Result<()> {
    if args.axes.is_empty() || args.axes.len() > 3 {
        bail!("--axes: give 1 to 3 channels, got {}", args.axes.len());
    }
    for (flag, given) in [("--bins", args.bins.len()), ("--range", args.range.len())] {
        if given > 1 && given != args.axes.len() {
            bail!(
                "{flag}: give one value (for all axes) or one per axis ({} axes: {}), got {given}",
                args.axes.len(),
                args.axes.join(", ")
            );
        }
    }
    Ok(())
}

/// The voxels `--mask` keeps (its nonzero ones), on the input's grid.
fn read_mask(args: &HistogramArgs, input: &MultiField) -> Result<Option<Vec<bool>>> {
    let Some(p) = &args.mask else { return Ok(None) };
    let m = read_input(p, &args.read, &read_options(&args.read))?.0.into_scalar()?;
    if !m.geometry.same_grid(&input.geometry) {
        bail!("--mask {} is on another grid than the input", p.display());
    }
    Ok(Some(m.samples().iter().map(|&x| x != 0.0).collect()))
}

/// What the histograms of one command count and where they go.
struct Counting<'a> {
    args: &'a HistogramArgs,
    /// The channels the axes (and the stretched pair) read.
    chans: Vec<(String, Volume)>,
    mask: Option<Vec<bool>>,
    /// The input's file name, the figures' title.
    title: String,
    scale: Scale,
    out: &'a Path,
}

impl Counting<'_> {
    fn get(&self, name: &str) -> Option<&Volume> {
        self.chans.iter().find(|(c, _)| c == name).map(|(_, v)| v)
    }

    /// The axes of channels `names`, with the command's bins and ranges.
    fn axes_of(&self, names: &[String]) -> Result<Vec<Axis>> {
        let axis = |(i, n): (usize, &String)| {
            let data = self.get(n).map(Volume::samples).unwrap_or(&[]);
            spec_for(self.args, i, n)?.resolve(n, data).map_err(anyhow::Error::from)
        };
        names.iter().enumerate().map(axis).collect()
    }

    /// The histogram of `--axes` (and its 2D projections when it has three), with its picture.
    fn joint(&self, progress: &Progress) -> Result<()> {
        let axes = self.axes_of(&self.args.axes)?;
        let data: Vec<&[f32]> = self.args.axes.iter().filter_map(|n| self.get(n).map(Volume::samples)).collect();
        let h = progress.step("counting", || count(&data, axes, self.mask.as_deref()))?;
        write_histogram(self.out, &h, self.scale, &self.title)?;
        if h.axes.len() == 3 {
            for (a, b) in [(0, 1), (0, 2), (1, 2)] {
                write_histogram(self.out, &h.project(a, b), self.scale, &self.title)?;
            }
        }
        progress.note(&format!("{}: {} voxels counted", h.describe(self.scale), h.total()));
        Ok(())
    }

    /// The (v, g) histogram of the traced voxels beside their (v, g_hit) one.
    fn stretched(&self) -> Result<()> {
        let (v, g, g_hit, hit) = (self.get("v"), self.get("g"), self.get("g_hit"), self.get("hit"));
        let (Some(v), Some(g), Some(g_hit), Some(hit)) = (v, g, g_hit, hit) else {
            bail!("stretched histogram: missing channels")
        };
        let shared = self.axes_of(&["v".to_string(), "g".to_string()])?;
        let channels = [v.samples(), g.samples(), g_hit.samples()];
        let (normal, stretched) = stretched_pair(channels, hit.samples(), &shared, self.mask.as_deref())?;
        write_stretched(self.out, &normal, &stretched, self.scale, &self.title, &[])?;
        Ok(())
    }

    /// The histogram volume of the input's (first field's) value, with g
    /// and f'' derived slice by slice and counted as they come, never stored whole.
    fn histogram_volume(&self, input: &MultiField, progress: &Progress) -> Result<()> {
        let args = self.args;
        let p = HvolParams {
            g_thresh: args.g_thresh,
            tent_width: args.tent_width,
            ..HvolParams::on_grid(input.geometry.spacing)
        };
        let kernel = args.kernel.unwrap_or_default();
        let d = DeriveParams { kernel, ..DeriveParams::default() };
        let value;
        let values = if input.fields.len() == 1 {
            input
        } else {
            value = MultiField::from(input.field_volume(0).context("the input has no fields")?);
            &value
        };
        let hv = progress
            .step("histogram volume", || mdtf_pipeline::hvol_streamed::histogram_volume_derived(values, &d, &p))?;
        let arches = mdtf_pipeline::figures::boundary_arches(&mdtf_pipeline::stages::histogram::detect_boundaries(&hv));
        write_hvol(self.out, &hv, &self.title, &arches)?;
        progress.note(&format!("histogram volume: sigma {:.4} world units, g_thresh {:.4}", hv.sigma, hv.g_thresh));
        Ok(())
    }
}
