//! `mdtf`: prepares volume data for direct volume rendering with
//! multidimensional transfer functions. This binary parses arguments, shows
//! progress and reports errors; the work is done by the stage libraries.

mod args;
mod commands;
mod flags;
mod input;
mod progress;
mod values;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = args::Cli::parse();
    clean_up_on_signals();
    if let Some(n) = cli.global.threads
        && let Err(e) = rayon::ThreadPoolBuilder::new().num_threads(n as usize).build_global()
    {
        eprintln!("error: cannot start {n} worker threads: {e}");
        return ExitCode::FAILURE;
    }
    let progress = progress::Progress::new(cli.global.quiet, flags::of(&cli.command));
    match commands::run(cli.command, &progress) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            progress.clear();
            eprintln!("error: {}", progress.with_flags(&format!("{e:#}")));
            ExitCode::FAILURE
        }
    }
}

/// On SIGINT, SIGTERM or SIGHUP: remove every partial output of this run and
/// exit with 128 + the signal number (130, 143, 129), as shells expect. The
/// old outputs stay as they were; nothing half-written is left behind.
fn clean_up_on_signals() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let mut signals = match signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("warning: cannot watch for interrupts ({e}); an interrupted run may leave partial outputs");
            return;
        }
    };
    std::thread::spawn(move || {
        if let Some(signal) = signals.forever().next() {
            let removed = mdtf_volume::output::remove_partial_outputs();
            let name = match signal {
                SIGINT => "interrupted",
                SIGTERM => "terminated",
                _ => "hung up",
            };
            eprintln!(
                "\n{name}: stopped; {} partial output(s) removed, earlier outputs left as they were",
                removed.len()
            );
            std::process::exit(128 + signal);
        }
    });
}
