//! `mdtf convert IN OUT`: any reader to any writer, by extension.

use crate::args::ConvertArgs;
use crate::input::{read_input, read_options, sample_type};
use crate::progress::Progress;
use anyhow::{Context, Result};
use mdtf_volume::{SampleType, WriteOptions, write};

/// Converts one file.
pub fn run(args: &ConvertArgs, progress: &Progress) -> Result<()> {
    let (mf, info) = progress.step("reading", || read_input(&args.input, &args.read, &read_options(&args.read)))?;
    // the input's own integer type when its values are those integers, as every writer stores them
    let own = match (info.sample_type, info.scale) {
        (SampleType::U8 | SampleType::U16, None) => Some(info.sample_type),
        _ => None,
    };
    let ty = args.out_type.map(sample_type).or(own).unwrap_or(SampleType::F32);
    let opts = WriteOptions { ty, gzip: args.gzip };
    progress.step("writing", || write(&args.output, &mf, &opts, &[&args.input])).context("cannot write the output")?;
    progress.note(&format!(
        "wrote {} ({} field(s), {}, {})",
        args.output.display(),
        mf.fields.len(),
        mf.geometry.dims_string(),
        opts.ty
    ));
    Ok(())
}
