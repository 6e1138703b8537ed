//! `mdtf pack`: quantised textures and manifest.

use crate::args::PackArgs;
use crate::input::{read_input, read_options};
use crate::progress::Progress;
use anyhow::{Context, Result, bail};
use mdtf_histogram::AxisSpec;
use mdtf_pack::{MANIFEST_SCHEMA, PackParams, Profile, Provenance, pack, sha256_file};
use mdtf_pipeline::channels;
use mdtf_volume::Volume;
use std::collections::BTreeMap;
use std::path::Path;

/// Packs, or prints the schema.
pub fn run(args: &PackArgs, progress: &Progress) -> Result<()> {
    if args.schema {
        print!("{MANIFEST_SCHEMA}");
        return Ok(());
    }
    let (Some(input), Some(output)) = (&args.input, &args.output) else { bail!("give an input and -o PACK_DIR") };
    let profile: Profile = args.profile.parse().map_err(anyhow::Error::msg)?;
    let names: Vec<String> = profile.channels().iter().map(|s| s.to_string()).collect();
    let chans = progress.step("reading channels", || -> Result<Vec<(String, Volume)>> {
        if input.is_dir() { from_folder(input, &names, args) } else { from_value(input, &names, args) }
    })?;
    let mut ranges = BTreeMap::new();
    for r in &args.range {
        let (name, span) = r.split_once('=').with_context(|| format!("--range: expected NAME=MIN:MAX, got '{r}'"))?;
        let (a, b) = span.split_once(':').with_context(|| format!("--range: expected NAME=MIN:MAX, got '{r}'"))?;
        ranges.insert(name.to_string(), [a.trim().parse::<f64>()?, b.trim().parse::<f64>()?]);
    }
    for (name, v) in &chans {
        if !ranges.contains_key(name) && matches!(name.as_str(), "g" | "f2" | "g_hit") {
            // qbert's percentile clipping of the tails
            let axis = AxisSpec { bins: Some(256), ..AxisSpec::qbert(name) }.resolve(name, v.samples())?;
            ranges.insert(name.clone(), [axis.min, axis.max]);
        }
    }
    std::fs::create_dir_all(output).with_context(|| format!("cannot create {}", output.display()))?;
    let provenance = Provenance {
        mdtf_version: env!("CARGO_PKG_VERSION").into(),
        input: Some(input.display().to_string()),
        input_sha256: if input.is_file() { sha256_file(input).ok() } else { None },
        stages: serde_json::json!({ "pack": { "profile": profile.to_string(), "ranges": ranges },
            "derive": { "kernel": args.kernel.clone().unwrap_or_else(|| mdtf_derive::DEFAULT_KERNEL.to_string()) } }),
    };
    let params = PackParams { profile, ranges };
    let m = progress.step("packing", || pack(&chans, &params, output, provenance, &BTreeMap::new()))?;
    progress.note(&format!(
        "packed {} textures ({}) and manifest.json into {}",
        m.textures.len(),
        m.textures.iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", "),
        output.display()
    ));
    Ok(())
}

fn from_value(input: &Path, names: &[String], args: &PackArgs) -> Result<Vec<(String, Volume)>> {
    let (mf, _) = read_input(input, &args.read, &read_options(&args.read))?;
    let kernel = args.kernel.as_deref().map(str::parse).transpose()?;
    Ok(channels::compute(&mf, names, kernel)?)
}

/// Reads stage outputs by name from a folder: value (or v), g, f2, normal (3 fields), g_hit, distance.
fn from_folder(dir: &Path, names: &[String], args: &PackArgs) -> Result<Vec<(String, Volume)>> {
    let find = |stem: &str| -> Option<std::path::PathBuf> {
        [".nii.gz", ".nii", ".nrrd", ".nhdr"].iter().map(|e| dir.join(format!("{stem}{e}"))).find(|p| p.exists())
    };
    let opts = read_options(&args.read);
    let mut out = Vec::new();
    for name in names {
        let (stem, field) = match name.as_str() {
            "nx" => ("normal", 0),
            "ny" => ("normal", 1),
            "nz" => ("normal", 2),
            other => (other, 0),
        };
        let path = find(stem).or_else(|| if stem == "v" { find("value") } else { None }).with_context(|| {
            format!("{}: no {stem} file (.nii.gz, .nii, .nrrd, .nhdr) for channel {name}", dir.display())
        })?;
        let mf = read_input(&path, &args.read, &opts)?.0;
        let v = mf.field_volume(field).with_context(|| format!("{}: no field {field}", path.display()))?;
        out.push((name.clone(), v));
    }
    Ok(out)
}
