//! `mdtf validate`: measured errors against documented tolerances.

use crate::args::ValidateArgs;
use crate::progress::Progress;
use anyhow::{Result, bail};
use mdtf_pipeline::validate::{ValidateParams, validate};
use mdtf_volume::{Inputs, OutputFolder};

/// Runs the checks and prints the table on stdout.
pub fn run(args: &ValidateArgs, progress: &Progress) -> Result<()> {
    let params = ValidateParams::from_overrides(&args.set).map_err(anyhow::Error::msg)?;
    let inputs = Inputs::new();
    let folder = OutputFolder::begin(&args.output, &inputs)?;
    let checks =
        progress.step("validating", || validate(args.size, folder.path(), &params)).map_err(anyhow::Error::msg)?;
    folder.publish(&inputs)?;
    progress.clear();
    println!("{:<48} {:>12} {:>14}  result", "check", "measured", "tolerance");
    for c in &checks {
        let bound = format!("{} {:.3e}", if c.at_most { "<=" } else { ">=" }, c.tolerance);
        println!(
            "{:<48} {:>12.4e} {:>14}  {}",
            c.name,
            c.measured,
            bound,
            if c.ok() { "ok" } else { "OUT OF TOLERANCE" }
        );
    }
    println!("pictures: {}/boundary, {}/histogram", args.output.display(), args.output.display());
    let failed = checks.iter().filter(|c| !c.ok()).count();
    if failed > 0 {
        bail!("{failed} of {} checks out of tolerance", checks.len());
    }
    Ok(())
}
