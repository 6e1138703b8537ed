//! Parsing list options and reading an input volume as the user described it.

use crate::args::{EndianArg, InputArgs, NanArg, OutType};
use anyhow::{Context, Result, bail};
use mdtf_volume::dicom::DicomOptions;
use mdtf_volume::{
    Endian, FileInfo, MultiField, NanPolicy, RawSpec, ReadOptions, SAMPLE_TYPE_NAMES, SampleType, read_raw,
    read_with_info,
};
use std::path::Path;

/// Parses "a,b,c" into three finite numbers; `what` names the option in errors.
pub fn parse_triple(text: &str, what: &str) -> Result<[f64; 3]> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        bail!("{what}: expected three comma-separated numbers like 1,1,2, got '{text}'");
    }
    let mut out = [0.0; 3];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p.parse::<f64>().with_context(|| format!("{what}: '{p}' is not a number"))?;
        if !o.is_finite() {
            bail!("{what}: '{p}' is not finite");
        }
    }
    Ok(out)
}

/// Parses a positive spacing triple.
pub fn parse_spacing(text: &str, what: &str) -> Result<[f64; 3]> {
    let s = parse_triple(text, what)?;
    if s.iter().any(|&v| v <= 0.0) {
        bail!("{what}: every spacing must be positive, got {text}");
    }
    Ok(s)
}

/// Parses "N" (a cube) or "NX,NY,NZ" grid sizes, each at least 1.
pub fn parse_size(text: &str, what: &str) -> Result<[usize; 3]> {
    let dims = parse_dims(text, what)?;
    let bytes = dims.iter().map(|&d| d as u128).product::<u128>() * 4;
    let available = mdtf_volume::available_memory() as u128;
    if bytes > available {
        bail!(
            "{what}: a {}x{}x{} volume needs {} as f32, more than the {} available",
            dims[0],
            dims[1],
            dims[2],
            mdtf_volume::human_bytes(bytes),
            mdtf_volume::human_bytes(available)
        );
    }
    Ok(dims)
}

/// A grid size, N for N^3 or NX,NY,NZ, each at least 1 (of any size: nothing is allocated).
pub fn parse_dims(text: &str, what: &str) -> Result<[usize; 3]> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let nums: Vec<usize> = parts
        .iter()
        .map(|p| p.parse::<usize>().with_context(|| format!("{what}: '{p}' is not a whole number")))
        .collect::<Result<_>>()?;
    let dims = match nums.as_slice() {
        [n] => [*n; 3],
        [x, y, z] => [*x, *y, *z],
        _ => bail!("{what}: expected N or NX,NY,NZ, got '{text}'"),
    };
    if dims.contains(&0) {
        bail!("{what}: every size must be at least 1, got '{text}'");
    }
    Ok(dims)
}

/// The sample type of an `--type` option.
pub fn sample_type(t: OutType) -> SampleType {
    match t {
        OutType::F32 => SampleType::F32,
        OutType::U8 => SampleType::U8,
        OutType::U16 => SampleType::U16,
    }
}

/// Reader options from the command line.
pub fn read_options(args: &InputArgs) -> ReadOptions {
    ReadOptions {
        nan: if args.nan == NanArg::Zero { NanPolicy::Zero } else { NanPolicy::Refuse },
        dicom: DicomOptions { series: args.series.clone(), resample: args.resample },
        level: args.level,
    }
}

/// Reads `path` by its extension, or as raw samples when `--raw-dims` is given.
pub fn read_input(path: &Path, args: &InputArgs, opts: &ReadOptions) -> Result<(MultiField, FileInfo)> {
    let Some(dims) = &args.raw_dims else {
        let (mf, info) = read_with_info(path, opts).context("cannot read the input")?;
        for w in &info.warnings {
            eprintln!("warning: {w}");
        }
        return Ok((mf, info));
    };
    let dims = parse_size(dims, "--raw-dims")?;
    let ty = SampleType::parse(&args.raw_type)
        .with_context(|| format!("--raw-type: unknown type '{}' (valid: {SAMPLE_TYPE_NAMES})", args.raw_type))?;
    let endian = if args.raw_endian == EndianArg::Big { Endian::Big } else { Endian::Little };
    let spec = RawSpec {
        dims,
        ty,
        endian,
        spacing: parse_spacing(&args.raw_spacing, "--raw-spacing")?,
        origin: [0.0; 3],
        byte_skip: args.raw_skip,
    };
    let v = read_raw(path, &spec, opts).context("cannot read the raw input")?;
    let info = FileInfo {
        format: "raw".into(),
        sample_type: ty,
        endian,
        compressed: false,
        scale: None,
        warnings: Vec::new(),
        details: Vec::new(),
        units: Default::default(),
        padding: None,
    };
    Ok((MultiField::from(v), info))
}

/// The transfer function file `path` names (`--tf`), parsed; None without one.
pub fn read_tf(path: Option<&Path>) -> Result<Option<mdtf_pipeline::stages::pack::TfFile>> {
    let Some(p) = path else { return Ok(None) };
    let text = std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?;
    let tf = mdtf_pipeline::stages::pack::parse_tf(&text).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?;
    Ok(Some(tf))
}

/// Prints the plan of the channels `names(fields)` of the input at `path`
/// (read as `read` says, to learn its fields and grid), made as `chain`
/// says: a command's `--plan`. Writes nothing.
pub fn print_channel_plan(
    path: &Path,
    read: &InputArgs,
    names: &dyn Fn(&[String]) -> Vec<String>,
    chain: &mdtf_pipeline::boundary_chain::BoundaryChainParams,
) -> Result<()> {
    let (mf, _) = read_input(path, read, &read_options(read))?;
    let fields: Vec<String> = mf.fields.iter().map(|f| f.name.clone()).collect();
    let names = names(if fields.len() > 1 { &fields } else { &[] });
    let plan = mdtf_pipeline::plan::Plan::for_channels(&names, &fields, &mf.geometry, chain)?;
    print_plan(&names.join(", "), &path.display().to_string(), &mf.geometry, &plan);
    Ok(())
}

/// Prints the plan of `what` on the input named `input` on `geometry` (a `--plan`).
pub fn print_plan(what: &str, input: &str, geometry: &mdtf_volume::Geometry, plan: &mdtf_pipeline::plan::Plan) {
    let ([nx, ny, nz], [sx, sy, sz]) = (geometry.dims, geometry.spacing);
    println!("plan of {what} on {input} ({nx} x {ny} x {nz}, spacing {sx} x {sy} x {sz})");
    println!("{plan}");
}

/// The budget of a run that goes slab by slab on its own (`auto`: the
/// budget and the grid that would not fit in memory whole), said in a note
/// naming what it is `doing` ("deriving", "tracing", ...).
pub fn announce_slabs(
    progress: &crate::progress::Progress,
    doing: &str,
    auto: Option<(u64, mdtf_volume::Geometry)>,
) -> Option<u64> {
    auto.map(|(budget, geo)| {
        let [nx, ny, nz] = geo.dims;
        progress.note(&format!(
            "{nx} x {ny} x {nz} voxels do not fit in memory at once: {doing} slab by slab within {} \
             (--memory-budget sets it)",
            mdtf_volume::human_bytes(budget as u128)
        ));
        budget
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_triples_parse_or_say_why_not() {
        assert_eq!(parse_size("64", "--size").unwrap(), [64, 64, 64]);
        assert_eq!(parse_size("4,5,6", "--size").unwrap(), [4, 5, 6]);
        assert!(parse_size("4,5", "--size").unwrap_err().to_string().contains("NX,NY,NZ"));
        assert!(parse_size("0", "--size").is_err());
        assert!(parse_size("100000", "--size").unwrap_err().to_string().contains("needs"));
        assert_eq!(parse_triple("-1, 2.5,3", "--origin").unwrap(), [-1.0, 2.5, 3.0]);
        assert!(parse_spacing("1,0,1", "--spacing").is_err());
        assert!(parse_triple("1,nan,1", "--origin").is_err());
    }
}
