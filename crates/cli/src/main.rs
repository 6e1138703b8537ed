//! `mdtf`: prepares volume data for direct volume rendering with
//! multidimensional transfer functions. This binary parses arguments, shows
//! progress and reports errors; the work is done by the stage libraries.

mod args;
mod commands;
mod input;
mod progress;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = args::Cli::parse();
    if let Some(n) = cli.global.threads
        && let Err(e) = rayon::ThreadPoolBuilder::new().num_threads(n as usize).build_global()
    {
        eprintln!("error: cannot start {n} worker threads: {e}");
        return ExitCode::FAILURE;
    }
    let progress = progress::Progress::new(cli.global.quiet);
    match commands::run(cli.command, &progress) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            progress.clear();
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
