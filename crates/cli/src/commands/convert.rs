//! `mdtf convert IN OUT`: any reader to any writer, by extension.

use crate::args::ConvertArgs;
use crate::input::{read_input, read_options, sample_type};
use crate::progress::Progress;
use anyhow::{Context, Result};
use mdtf_volume::{Format, NIFTI1_MAX_AXIS, SampleType, WriteOptions, nifti_version_for, write};

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
    let nifti = matches!(Format::from_path(&args.output), Some(Format::Nifti | Format::NiftiGz | Format::NiftiPair));
    if nifti && nifti_version_for(&mf.geometry, mf.fields.len()) == 2 {
        progress.note(&format!(
            "warning: {}: written as NIfTI-2, since an axis ({}) exceeds NIfTI-1's {NIFTI1_MAX_AXIS} voxels; \
             nibabel, ITK, FSL 6 and AFNI read NIfTI-2, older tools may not",
            args.output.display(),
            mf.geometry.dims_string()
        ));
    }
    progress.note(&format!(
        "wrote {} ({} field(s), {}, {})",
        args.output.display(),
        mf.fields.len(),
        mf.geometry.dims_string(),
        opts.ty
    ));
    Ok(())
}
