//! `mdtf bilateral`: the edge-preserving filter.

use crate::args::BilateralArgs;
use crate::input::{read_input, read_options};
use crate::progress::Progress;
use anyhow::{Context, Result};
use mdtf_pipeline::stages::bilateral::{BilateralParams, range_sigma, run as filter};
use mdtf_volume::{MultiField, WriteOptions, write};
use std::time::Instant;

/// The stage's parameters from the command line.
pub fn params(args: &BilateralArgs) -> BilateralParams {
    let defaults = BilateralParams::default();
    BilateralParams {
        sigma_d: args.sigma_d,
        sigma_r: args.sigma_r,
        range_units: args.range_units.unwrap_or(defaults.range_units),
        mode: args.mode.unwrap_or(defaults.mode),
        ..defaults
    }
}

/// Reads, filters, writes.
pub fn run(args: &BilateralArgs, progress: &Progress) -> Result<()> {
    let p = params(args);
    let (mf, _) = progress.step("reading", || read_input(&args.input, &args.read, &read_options(&args.read)))?;
    let volume = mf.into_scalar().context("the bilateral filter takes one field")?;
    let start = Instant::now();
    let out = progress.step("filtering", || filter(&volume, &p)).context("cannot filter")?;
    let seconds = start.elapsed().as_secs_f64();
    let opts = WriteOptions { gzip: args.gzip, ..WriteOptions::default() };
    progress
        .step("writing", || write(&args.output, &MultiField::from(out), &opts, &[&args.input]))
        .context("cannot write the output")?;
    progress.note(&format!(
        "filtered {} ({:?}, sigma_d {} world units, sigma_r {:.4} value units) in {:.2} s ({:.1} Mvoxel/s)",
        args.output.display(),
        p.mode,
        p.sigma_d,
        range_sigma(&volume, &p),
        seconds,
        volume.geometry.voxel_count() as f64 / seconds / 1e6
    ));
    Ok(())
}
