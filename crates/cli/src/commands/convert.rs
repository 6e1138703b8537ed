//! `mdtf convert IN OUT`: any reader to any writer, by extension.

use crate::args::ConvertArgs;
use crate::input::{read_input, read_options, sample_type};
use crate::progress::Progress;
use anyhow::{Context, Result};
use mdtf_volume::{WriteOptions, write};

/// Converts one file.
pub fn run(args: &ConvertArgs, progress: &Progress) -> Result<()> {
    let (mf, _) = progress.step("reading", || read_input(&args.input, &args.read, &read_options(&args.read)))?;
    let opts = WriteOptions { ty: sample_type(args.out_type), gzip: args.gzip };
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
