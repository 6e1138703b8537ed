//! One module per subcommand.

mod bilateral;
mod boundary;
mod convert;
mod derive;
pub mod export;
mod histogram;
mod info;
mod pack;
mod preview;
mod run;
mod run_timing;
mod synth;
mod tetra;
mod validate;

use crate::args::Command;
use crate::progress::Progress;
use anyhow::Result;

/// Runs a parsed subcommand.
pub fn run(command: Command, progress: &Progress) -> Result<()> {
    match command {
        Command::Synth(a) => synth::run(&a, progress),
        Command::Info(a) => info::run(&a, progress),
        Command::Convert(a) => convert::run(&a, progress),
        Command::Derive(a) => derive::run(&a, progress),
        Command::Bilateral(a) => bilateral::run(&a, progress),
        Command::Boundary(a) => boundary::run(&a, progress),
        Command::Histogram(a) => histogram::run(&a, progress),
        Command::Pack(a) => pack::run(&a, progress),
        Command::Run(a) => run::run(&a, progress),
        Command::Validate(a) => validate::run(&a, progress),
        Command::Preview(a) => preview::run(&a, progress),
        Command::Export(a) => export::run(&a, progress),
        Command::Tetra(a) => tetra::run(&a, progress),
    }
}
