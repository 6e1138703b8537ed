//! `mdtf histogram`: joint and stretched histograms, pictures, the histogram volume.

use crate::args::{HistogramArgs, ScaleArg};
use crate::input::{read_input, read_options};
use crate::progress::Progress;
use anyhow::{Context, Result, bail};
use mdtf_pipeline::boundary_chain::BoundaryChainParams;
use mdtf_pipeline::channels;
use mdtf_pipeline::stages::derive::DeriveParams;
use mdtf_pipeline::stages::histogram::{
    Axis, AxisSpec, HvolParams, Scale, count, hit_mask, write_histogram, write_hvol, write_stretched,
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
    let scale = if args.scale == ScaleArg::Linear { Scale::Linear } else { Scale::Log };
    let given: Vec<&Path> =
        [Some(&args.input), args.mask.as_ref()].into_iter().flatten().map(PathBuf::as_path).collect();
    let inputs = Inputs::of(&given);
    let folder = OutputFolder::begin(&args.output, &inputs)?;
    let out = folder.path();
    let (input, _) = progress.step("reading", || read_input(&args.input, &args.read, &read_options(&args.read)))?;
    let kernel = args.kernel;
    let mut wanted: Vec<String> = args.axes.clone();
    for extra in [&["v", "g"][..], &["g_hit", "hit"][..]].into_iter().filter(|_| args.stretched).flatten() {
        if !wanted.iter().any(|w| w == extra) {
            wanted.push(extra.to_string());
        }
    }
    let chans = progress.step("computing channels", || {
        channels::compute(&input, &wanted, &BoundaryChainParams { kernel, ..Default::default() })
    })?;
    let get = |n: &str| chans.iter().find(|(c, _)| c == n).map(|(_, v)| v);
    let mask: Option<Vec<bool>> = match &args.mask {
        Some(p) => {
            let m = read_input(p, &args.read, &read_options(&args.read))?.0.into_scalar()?;
            if !m.geometry.same_grid(&input.geometry) {
                bail!("--mask {} is on another grid than the input", p.display());
            }
            Some(m.samples().iter().map(|&x| x != 0.0).collect())
        }
        None => None,
    };

    let axes_of = |names: &[String]| -> Result<Vec<Axis>> {
        names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let data = get(n).map(Volume::samples).unwrap_or(&[]);
                spec_for(args, i, n)?.resolve(n, data).map_err(anyhow::Error::from)
            })
            .collect()
    };
    let axes = axes_of(&args.axes)?;
    let title =
        args.input.file_name().map_or_else(|| args.input.display().to_string(), |n| n.to_string_lossy().into_owned());
    let data: Vec<&[f32]> = args.axes.iter().filter_map(|n| get(n).map(Volume::samples)).collect();
    let h = progress.step("counting", || count(&data, axes, mask.as_deref()))?;
    write_histogram(out, &h, scale, &title)?;
    if h.axes.len() == 3 {
        for (a, b) in [(0, 1), (0, 2), (1, 2)] {
            write_histogram(out, &h.project(a, b), scale, &title)?;
        }
    }
    progress.note(&format!("{}: {} voxels counted", h.describe(scale), h.total()));

    if args.stretched {
        let (v, g, g_hit, hit) = (get("v"), get("g"), get("g_hit"), get("hit"));
        let (Some(v), Some(g), Some(g_hit), Some(hit)) = (v, g, g_hit, hit) else {
            bail!("stretched histogram: missing channels")
        };
        let mut traced = hit_mask(hit.samples());
        if let Some(m) = &mask {
            traced.iter_mut().zip(m).for_each(|(t, &m)| *t &= m);
        }
        let names = ["v".to_string(), "g".to_string()];
        let shared = axes_of(&names)?;
        let normal = count(&[v.samples(), g.samples()], shared.clone(), Some(&traced))?;
        let mut stretched_axes = shared;
        stretched_axes[1].name = "g_hit".into();
        let stretched = count(&[v.samples(), g_hit.samples()], stretched_axes, Some(&traced))?;
        write_stretched(out, &normal, &stretched, scale, &title, &[])?;
    }
    if args.hvol {
        let p = HvolParams { g_thresh: args.g_thresh, tent_width: args.tent_width, ..HvolParams::default() };
        let d = DeriveParams {
            kernel: kernel.unwrap_or(mdtf_pipeline::stages::derive::DEFAULT_KERNEL),
            ..DeriveParams::default()
        };
        // g and f'' are derived slice by slice and counted as they come, never stored whole
        let value;
        let values = if input.fields.len() == 1 {
            &input
        } else {
            value = MultiField::from(input.field_volume(0).context("the input has no fields")?);
            &value
        };
        let hv = progress
            .step("histogram volume", || mdtf_pipeline::hvol_streamed::histogram_volume_derived(values, &d, &p))?;
        let arches = mdtf_pipeline::figures::boundary_arches(&mdtf_pipeline::stages::histogram::detect_boundaries(&hv));
        write_hvol(out, &hv, &title, &arches)?;
        progress.note(&format!("histogram volume: sigma {:.4} world units, g_thresh {:.4}", hv.sigma, hv.g_thresh));
    }
    folder.publish(&inputs)?;
    Ok(())
}
