//! `mdtf histogram`: joint and stretched histograms, pictures, the histogram volume.

use crate::args::{HistogramArgs, ScaleArg};
use crate::input::{read_input, read_options};
use crate::progress::Progress;
use anyhow::{Context, Result, bail};
use mdtf_histogram::{
    Axis, AxisSpec, Histogram, HvolParams, Scale, count, histogram_volume, hit_mask, side_by_side, write_png,
};
use mdtf_pipeline::channels;
use mdtf_volume::nrrd::{TableAxis, write_counts_nrrd, write_table_nrrd};
use mdtf_volume::{Volume, write_file_atomically};
use std::path::Path;

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
    let scale = if args.scale == ScaleArg::Linear { Scale::Linear } else { Scale::Log };
    let (input, _) = progress.step("reading", || read_input(&args.input, &args.read, &read_options(&args.read)))?;
    let kernel = args.kernel.as_deref().map(str::parse).transpose()?;
    let mut wanted: Vec<String> = args.axes.clone();
    for extra in [&["v", "g"][..], &["g_hit", "hit"][..]].into_iter().filter(|_| args.stretched).flatten() {
        if !wanted.iter().any(|w| w == extra) {
            wanted.push(extra.to_string());
        }
    }
    if args.hvol {
        for c in ["v", "g", "f2"] {
            if !wanted.iter().any(|w| w == c) {
                wanted.push(c.to_string());
            }
        }
    }
    let chans = progress.step("computing channels", || channels::compute(&input, &wanted, kernel))?;
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
    std::fs::create_dir_all(&args.output).with_context(|| format!("cannot create {}", args.output.display()))?;

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
    let data: Vec<&[f32]> = args.axes.iter().filter_map(|n| get(n).map(Volume::samples)).collect();
    let h = progress.step("counting", || count(&data, axes, mask.as_deref()))?;
    write_histogram(&args.output, &h, scale)?;
    if h.axes.len() == 3 {
        for (a, b) in [(0, 1), (0, 2), (1, 2)] {
            write_histogram(&args.output, &h.project(a, b), scale)?;
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
        write_histogram(&args.output, &stretched, scale)?;
        let both = side_by_side(&normal.image(scale), &stretched.image(scale));
        let text =
            format!("left: normal (v, g) of traced voxels; right: stretched (v, g_hit); {}", normal.describe(scale));
        write_png(&args.output.join("normal_vs_stretched.png"), &both, &text)?;
    }
    if args.hvol {
        let (Some(v), Some(g), Some(f2)) = (get("v"), get("g"), get("f2")) else { bail!("hvol: missing channels") };
        let p = HvolParams { g_thresh: args.g_thresh, tent_width: args.tent_width, ..HvolParams::default() };
        let hv = progress.step("histogram volume", || histogram_volume(v.samples(), g.samples(), f2.samples(), &p))?;
        write_counts_nrrd(&args.output.join("hvol.nrrd"), &table_axes(&hv.hist.axes), &hv.hist.counts)?;
        let vg = table_axes(&hv.vg_axes);
        write_table_nrrd(&args.output.join("position.nrrd"), &vg, &hv.position)?;
        write_table_nrrd(&args.output.join("opacity.nrrd"), &vg, &hv.opacity)?;
        let (w, hgt) = (hv.vg_axes[0].bins, hv.vg_axes[1].bins);
        let mut pixels = vec![0u8; w * hgt];
        for y in 0..hgt {
            for x in 0..w {
                pixels[(hgt - 1 - y) * w + x] = (hv.opacity[y * w + x].clamp(0.0, 1.0) * 255.0).round() as u8;
            }
        }
        let text = format!("opacity alpha(v, g) = tent(p(v, g)), half-width {}; sigma {}", hv.tent_width, hv.sigma);
        write_png(&args.output.join("opacity.png"), &mdtf_histogram::Grey { width: w, height: hgt, pixels }, &text)?;
        let mut csv = String::from("v,voxels,mean_g,mean_f2\n");
        for b in 0..hv.count_v.len() {
            csv += &format!("{},{},{},{}\n", hv.vg_axes[0].centre(b), hv.count_v[b], hv.mean_g_v[b], hv.mean_h_v[b]);
        }
        write_file_atomically(&args.output.join("hvol_per_v.csv"), |w| w.write_all(csv.as_bytes()))?;
        let json = serde_json::json!({
            "sigma": hv.sigma, "g_thresh": hv.g_thresh, "tent_width": hv.tent_width,
            "axes": hv.hist.axes, "sigma_formula": "2 max g(v) / (sqrt(e) (max h(v) - min h(v)))",
        });
        write_json(&args.output.join("hvol.json"), &json)?;
        progress.note(&format!("histogram volume: sigma {:.4} world units, g_thresh {:.4}", hv.sigma, hv.g_thresh));
    }
    Ok(())
}

fn table_axes(axes: &[Axis]) -> Vec<TableAxis> {
    axes.iter().map(|a| TableAxis { label: a.name.clone(), size: a.bins, min: a.min, max: a.max }).collect()
}

fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    write_file_atomically(path, |w| w.write_all(text.as_bytes()))?;
    Ok(())
}

fn write_histogram(dir: &Path, h: &Histogram, scale: Scale) -> Result<()> {
    let stem: Vec<&str> = h.axes.iter().map(|a| a.name.as_str()).collect();
    let stem = format!("hist_{}", stem.join("_"));
    write_counts_nrrd(&dir.join(format!("{stem}.nrrd")), &table_axes(&h.axes), &h.counts)?;
    write_json(
        &dir.join(format!("{stem}.json")),
        &serde_json::json!({ "axes": h.axes, "total": h.total(), "max": h.max(), "scale": format!("{scale:?}"),
            "png": "first axis to the right, second axis upward" }),
    )?;
    if h.axes.len() <= 2 {
        write_png(&dir.join(format!("{stem}.png")), &h.image(scale), &h.describe(scale))?;
    }
    if h.axes.len() == 2 {
        mdtf_histogram::write_exr(&dir.join(format!("{stem}.exr")), h)?;
    }
    Ok(())
}
