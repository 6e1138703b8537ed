//! `mdtf synth`: phantoms with analytic ground truth.

use crate::args::{OutType, Phantom, SynthArgs};
use crate::input::{parse_size, parse_spacing, parse_triple, sample_type};
use crate::progress::Progress;
use anyhow::{Context, Result, bail};
use mdtf_pipeline::stages::datagen::{
    CtHead, MultiFieldPhantom, RadialPhantom, add_gaussian_noise, erf_sphere, min_extent,
};
use mdtf_volume::{
    Format, Geometry, Inputs, MultiField, OutputFolder, SampleType, Volume, WriteOptions, write, write_volume,
};
use std::path::Path;

/// Generates the phantom and, if asked, its truth.
pub fn run(args: &SynthArgs, progress: &Progress) -> Result<()> {
    let format = Format::from_path(&args.output).with_context(|| {
        format!("{}: unknown extension (use .nii, .nii.gz, .nrrd, .nhdr, .mha or .mhd)", args.output.display())
    })?;
    let geometry = geometry(args)?;
    let opts = WriteOptions { ty: sample_type(args.out_type), gzip: args.gzip };
    let truth_folder = args.truth.as_deref().map(|d| OutputFolder::begin(d, &Inputs::new())).transpose()?;
    let truth = Truth { dir: truth_folder.as_ref().map(OutputFolder::path), extension: format.extension(), args };
    match args.phantom {
        Phantom::ErfSphere | Phantom::Shells => radial(args, geometry, &opts, &truth, progress)?,
        Phantom::Multifield => multifield(args, geometry, &opts, &truth, progress)?,
        Phantom::CtHead => ct_head(args, geometry, &opts, progress)?,
    }
    progress.note(&format!("wrote {}", args.output.display()));
    if let (Some(folder), Some(shown)) = (truth_folder, &args.truth) {
        folder.publish(&Inputs::new())?;
        progress.note(&format!("wrote analytic truth into {}", shown.display()));
    }
    Ok(())
}

/// The grid `--size`, `--spacing` and `--origin` give (with `--sigma` checked).
fn geometry(args: &SynthArgs) -> Result<Geometry> {
    let dims = parse_size(&args.size, "--size")?;
    let spacing = parse_spacing(&args.spacing, "--spacing")?;
    let origin = parse_triple(&args.origin, "--origin")?;
    let sigma = sigma(args);
    if !(sigma.is_finite() && sigma > 0.0) {
        bail!("--sigma must be positive (world units), got {sigma}");
    }
    Ok(Geometry::new(dims, spacing).with_origin(origin))
}

/// `--sigma`, or the phantom's default blur (world units).
fn sigma(args: &SynthArgs) -> f64 {
    args.sigma.unwrap_or(if args.phantom == Phantom::CtHead { 1.0 } else { 3.0 })
}

/// Where the analytic truth goes (`--truth`), when asked for.
struct Truth<'a> {
    /// The staging folder of the truth; None: not asked for.
    dir: Option<&'a Path>,
    /// The output's file extension, which the truth files take too.
    extension: &'a str,
    args: &'a SynthArgs,
}

impl Truth<'_> {
    /// Writes truth volume `name` as f32 (nothing when the truth is not asked for).
    fn write(&self, name: &str, mf: MultiField) -> Result<()> {
        if let Some(dir) = self.dir {
            let p = dir.join(format!("{name}{}", self.extension));
            write(&p, &mf, &WriteOptions { ty: SampleType::F32, gzip: self.args.gzip }, &[])
                .context("cannot write the truth")?;
        }
        Ok(())
    }
}

/// The erf sphere or the nested shells, with v, g, f'', x, p and the normal as truth.
fn radial(args: &SynthArgs, geometry: Geometry, opts: &WriteOptions, truth: &Truth, progress: &Progress) -> Result<()> {
    let ph = if args.phantom == Phantom::ErfSphere {
        let radius = args.radius.unwrap_or(0.3 * min_extent(&geometry));
        if !(radius.is_finite() && radius > 0.0) {
            bail!("--radius must be positive (world units), got {radius}");
        }
        let centre = args.centre.as_deref().map(|c| parse_triple(c, "--centre")).transpose()?;
        erf_sphere(geometry, radius, sigma(args), args.vmin, args.vmax, centre)
    } else {
        RadialPhantom::tooth(geometry, sigma(args))
    };
    let mut vol = progress.step("generating", || ph.volume());
    add_noise(&mut vol, args)?;
    quantise(&mut vol, args.out_type);
    progress.step("writing", || write_volume(&args.output, &vol, opts, &[])).context("cannot write the output")?;
    if truth.dir.is_some() {
        let t = progress.step("computing truth", || ph.truth());
        progress.step("writing truth", || -> Result<()> {
            for (name, v) in [("v", t.v), ("g", t.g), ("f2", t.f2), ("x", t.x), ("p", t.p)] {
                truth.write(name, MultiField::from(v))?;
            }
            truth.write("normal", t.normal)
        })?;
    }
    Ok(())
}

/// Three overlapping erf spheres as three fields, with the Jacobian and ||G|| as truth.
fn multifield(
    args: &SynthArgs,
    geometry: Geometry,
    opts: &WriteOptions,
    truth: &Truth,
    progress: &Progress,
) -> Result<()> {
    let ph = MultiFieldPhantom::new(geometry, sigma(args));
    let mut mf = progress.step("generating", || ph.volume());
    if truth.dir.is_some() {
        // Truth belongs to the noise-free fields' ranges.
        let t = progress.step("computing truth", || ph.truth(&mf));
        truth.write("jacobian", t.jacobian)?;
        truth.write("gnorm", MultiField::from(t.gnorm))?;
    }
    for (n, f) in mf.fields.iter_mut().enumerate() {
        let mut v = Volume { geometry: ph.geometry.clone(), data: std::mem::take(&mut f.data) };
        add_noise_seeded(&mut v, args, n as u64)?;
        quantise(&mut v, args.out_type);
        f.data = v.data;
    }
    progress.step("writing", || write(&args.output, &mf, opts, &[])).context("cannot write the output")?;
    Ok(())
}

/// The head CT: the scan as a scanner stores it (no analytic truth fields:
/// its truth is the table of tissues in `mdtf synth --help`).
fn ct_head(args: &SynthArgs, geometry: Geometry, opts: &WriteOptions, progress: &Progress) -> Result<()> {
    if args.truth.is_some() {
        bail!("ct-head has no --truth fields: its tissues and boundaries are listed in `mdtf synth --help`");
    }
    let mut head = CtHead::new(geometry);
    head.sigma = sigma(args);
    head.noise = args.noise.unwrap_or(head.noise);
    if !(head.noise.is_finite() && head.noise >= 0.0) {
        bail!("--noise must be a non-negative standard deviation, got {}", head.noise);
    }
    head.seed = args.seed;
    let vol = progress.step("generating", || head.scan());
    if args.out_type != OutType::F32 {
        bail!("ct-head is written as int16, as scanners store CT: leave out --type");
    }
    let opts = WriteOptions { ty: SampleType::I16, ..*opts };
    progress.step("writing", || write_volume(&args.output, &vol, &opts, &[])).context("cannot write the output")?;
    Ok(())
}

fn add_noise(v: &mut Volume, args: &SynthArgs) -> Result<()> {
    add_noise_seeded(v, args, 0)
}

fn add_noise_seeded(v: &mut Volume, args: &SynthArgs, stream: u64) -> Result<()> {
    if let Some(std) = args.noise {
        if !(std.is_finite() && std >= 0.0) {
            bail!("--noise must be a non-negative standard deviation, got {std}");
        }
        add_gaussian_noise(v, std, args.seed.wrapping_add(stream.wrapping_mul(0x9E37_79B9_7F4A_7C15)));
    }
    Ok(())
}

/// Rounds and clamps to the integer output type, as an 8/16-bit scanner would store it.
fn quantise(v: &mut Volume, t: OutType) {
    if let Some(samples) = v.data.as_slice_mut() {
        mdtf_volume::round_to_type(samples, sample_type(t));
    }
}
