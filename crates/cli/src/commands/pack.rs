//! `mdtf pack`: quantised textures and manifest.

use crate::args::PackArgs;
use crate::input::{read_input, read_options, read_tf};
use crate::progress::Progress;
use anyhow::{Context, Result, bail};
use mdtf_pipeline::boundary_chain::BoundaryChainParams;
use mdtf_pipeline::stages::boundary::AlphaMap;
use mdtf_pipeline::stages::derive::Kernel;
use mdtf_pipeline::stages::pack::{
    Dtype, GaussianPrimitive, MANIFEST_SCHEMA, PackParams, Profile, Provenance, TfFile, pack, sha256_path,
};
use mdtf_pipeline::{channels, gaussians, pack_inputs};
use mdtf_volume::{Inputs, OutputFolder, Volume};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Named channels, and the field names of a multi-field input (empty for a scalar one).
type ChannelsAndFields = (Vec<(String, Volume)>, Vec<String>);

/// Packs, or prints the schema.
pub fn run(args: &PackArgs, progress: &Progress) -> Result<()> {
    if args.schema {
        print!("{MANIFEST_SCHEMA}");
        return Ok(());
    }
    let profile: Profile = args.profile.parse().map_err(anyhow::Error::msg)?;
    if let (Some(input), true) = (&args.input, args.plan) {
        return plan_only(input, profile, args);
    }
    let (Some(input), Some(output)) = (&args.input, &args.output) else { bail!("give an input and -o PACK_DIR") };
    refuse_meshes(input, profile)?;
    let given: Vec<&Path> = [Some(input), args.tf.as_ref(), args.gtf_from_mask.as_ref()]
        .into_iter()
        .flatten()
        .map(PathBuf::as_path)
        .collect();
    let inputs = Inputs::of(&given);
    let folder = OutputFolder::begin(output, &inputs)?;
    let ((chans, fields), d_max) = read_channels(input, profile, args, progress)?;
    let ranges = pack_inputs::ranges(&chans, &given_ranges(args)?, d_max)?;
    let kernel = args.kernel.unwrap_or_default();
    let provenance = provenance(input, profile, &ranges, kernel);
    let tf = read_tf(args.tf.as_deref())?;
    let alpha: AlphaMap = args.alpha.parse().map_err(anyhow::Error::msg)?;
    let luts = progress.step("lookup tables", || {
        pack_inputs::luts(profile, tf.as_ref(), &alpha, &chans, &ranges, None, &derive_with(kernel))
    })?;
    let gaussians = gaussians_of(args, profile, tf.as_ref(), &chans, &fields, kernel, progress)?;
    let params = PackParams { profile, ranges, fields, dtype: dtype(args)?, nifti: args.nifti };
    let m = progress.step("packing", || pack(&chans, &params, &luts, folder.path(), provenance, &BTreeMap::new()))?;
    if let Some(g) = &gaussians {
        mdtf_pipeline::gaussians::write(folder.path(), g)?;
    }
    folder.publish(&inputs)?;
    let names: Vec<&str> = m.textures.iter().map(|t| t.name.as_str()).collect();
    let (count, listed) = (names.len(), names.join(", "));
    progress.note(&format!("packed {count} textures ({listed}) and manifest.json into {}", output.display()));
    Ok(())
}

/// Refuses the mesh profile, whose packs `mdtf tetra` makes.
fn refuse_meshes(input: &Path, profile: Profile) -> Result<()> {
    if profile == Profile::ProjectedTetrahedra {
        bail!(
            "projected-tetrahedra packs hold a tetrahedral mesh: make them with `mdtf tetra MESH.vtu -o DIR` or `mdtf tetra --from-volume {} -o DIR`",
            input.display()
        );
    }
    Ok(())
}

/// `--plan`: prints the plan of the channels the profile packs, made from a value volume.
fn plan_only(input: &Path, profile: Profile, args: &PackArgs) -> Result<()> {
    refuse_meshes(input, profile)?;
    if input.is_dir() {
        bail!("--plan: {} is a folder of stage outputs, which the pack reads as they are", input.display());
    }
    let chain = BoundaryChainParams { kernel: args.kernel.unwrap_or_default(), ..Default::default() };
    crate::input::print_channel_plan(input, &args.read, &|fields| profile.channels(fields), &chain)
}

/// The channels the profile packs, from a folder of stage outputs or made
/// from a value volume; a multi-field input's field names; the tracing's
/// d_max when the channels were made here (stage outputs leave theirs to
/// the distance's measured range).
fn read_channels(
    input: &Path,
    profile: Profile,
    args: &PackArgs,
    progress: &Progress,
) -> Result<(ChannelsAndFields, Option<f64>)> {
    if input.is_dir() {
        let chans = progress.step("reading channels", || from_folder(input, &profile.channels(&[]), args))?;
        return Ok(((chans, Vec::new()), None));
    }
    let (chans, fields) = progress.step("computing channels", || from_value(input, profile, args))?;
    let d_max = chans.first().map(|(_, v)| mdtf_pipeline::stages::boundary::default_d_max(&v.geometry));
    Ok(((chans, fields), d_max))
}

/// The code ranges `--range NAME=MIN:MAX` gives, by channel.
fn given_ranges(args: &PackArgs) -> Result<BTreeMap<String, [f64; 2]>> {
    let mut ranges = BTreeMap::new();
    for r in &args.range {
        let bad = || format!("--range: expected NAME=MIN:MAX, got '{r}'");
        let (name, span) = r.split_once('=').with_context(bad)?;
        let (a, b) = span.split_once(':').with_context(bad)?;
        ranges.insert(name.to_string(), [a.trim().parse::<f64>()?, b.trim().parse::<f64>()?]);
    }
    Ok(ranges)
}

/// Derive's parameters with `kernel` (for what the pack derives again: the default TFs' histogram volume).
fn derive_with(kernel: Kernel) -> mdtf_pipeline::stages::derive::DeriveParams {
    mdtf_pipeline::stages::derive::DeriveParams { kernel, ..Default::default() }
}

/// The manifest's provenance: the input (with its checksum), the profile, ranges and kernel.
fn provenance(input: &Path, profile: Profile, ranges: &BTreeMap<String, [f64; 2]>, kernel: Kernel) -> Provenance {
    Provenance {
        mdtf_version: env!("CARGO_PKG_VERSION").into(),
        input: Some(input.display().to_string()),
        input_sha256: sha256_path(input).ok(),
        stages: serde_json::json!({ "pack": { "profile": profile.to_string(), "ranges": ranges },
            "derive": { "kernel": kernel.to_string() } }),
        ..Default::default()
    }
}

/// The texture sample type `--dtype` asks for (None: the profile's).
fn dtype(args: &PackArgs) -> Result<Option<Dtype>> {
    Ok(match args.dtype.as_deref() {
        None => None,
        Some("u8") => Some(Dtype::U8),
        Some("u16") => Some(Dtype::U16),
        Some("f16") => Some(Dtype::F16),
        Some("f32") => Some(Dtype::F32),
        Some(other) => bail!("--dtype: unknown type '{other}' (u8, u16, f16, f32)"),
    })
}

/// gaussian-tf's primitives (the TF's, else fitted to `--gtf-from-mask`,
/// else the default); None for the other profiles, which refuse a mask.
fn gaussians_of(
    args: &PackArgs,
    profile: Profile,
    tf: Option<&TfFile>,
    chans: &[(String, Volume)],
    fields: &[String],
    kernel: Kernel,
    progress: &Progress,
) -> Result<Option<Vec<GaussianPrimitive>>> {
    if profile != Profile::GaussianTf {
        if args.gtf_from_mask.is_some() {
            bail!("--gtf-from-mask applies to --profile gaussian-tf");
        }
        return Ok(None);
    }
    let mask = match &args.gtf_from_mask {
        Some(m) => Some(
            read_input(m, &args.read, &read_options(&args.read))?
                .0
                .into_scalar()
                .with_context(|| format!("--gtf-from-mask {} must hold one field", m.display()))?,
        ),
        None => None,
    };
    let (axes, gradient) = if fields.is_empty() { (vec!["v".to_string()], "g") } else { (fields.to_vec(), "gnorm") };
    let primitives = progress.step("Gaussian primitives", || {
        gaussians::gaussians(tf, mask.as_ref(), chans, &axes, gradient, (None, &derive_with(kernel)))
            .map_err(anyhow::Error::msg)
    })?;
    Ok(Some(primitives))
}

/// Channels of a value volume computed in process; a multi-field input's field names are the fields.
fn from_value(input: &Path, profile: Profile, args: &PackArgs) -> Result<ChannelsAndFields> {
    let (mf, _) = read_input(input, &args.read, &read_options(&args.read))?;
    let kernel = args.kernel.unwrap_or_default();
    let fields: Vec<String> =
        if mf.fields.len() > 1 { mf.fields.iter().map(|f| f.name.clone()).collect() } else { Vec::new() };
    let names = profile.channels(&fields);
    Ok((channels::compute(&mf, &names, &BoundaryChainParams { kernel, ..Default::default() })?, fields))
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
