//! Progress on stderr: a spinner per step when stderr is a terminal and
//! `--quiet` is not given, nothing otherwise (logs of batch jobs stay clean).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::time::{Duration, Instant};

/// Reports the steps of one command.
pub struct Progress {
    bar: Option<ProgressBar>,
    quiet: bool,
    /// The command's (parameter name, flag) pairs: notes name what the user typed ([`crate::flags`]).
    flags: Vec<(&'static str, &'static str)>,
}

impl Progress {
    /// A reporter; silent when `quiet` or when stderr is not a terminal. Its
    /// notes name parameters by `flags` where the command has them.
    pub fn new(quiet: bool, flags: Vec<(&'static str, &'static str)>) -> Progress {
        let bar = (!quiet && std::io::stderr().is_terminal()).then(|| {
            let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")
                    .unwrap_or_else(|_| ProgressStyle::default_spinner()),
            );
            bar.enable_steady_tick(Duration::from_millis(120));
            bar
        });
        Progress { bar, quiet, flags }
    }

    /// Runs `work` as a named step, showing it while it runs.
    pub fn step<T>(&self, name: &str, work: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        if let Some(bar) = &self.bar {
            bar.set_message(name.to_string());
        }
        let out = work();
        if let Some(bar) = &self.bar {
            bar.println(format!("  {name} ({:.2} s)", start.elapsed().as_secs_f64()));
        }
        out
    }

    /// Runs `work` as a named step with a bar counting to `total`; `work`
    /// receives a callback `(done, of)` that is safe to call from worker
    /// threads (`of` becomes the bar's length).
    pub fn counted<T>(&self, name: &str, total: u64, work: impl FnOnce(&(dyn Fn(usize, usize) + Sync)) -> T) -> T {
        let start = Instant::now();
        let Some(bar) = &self.bar else {
            return work(&|_, _| {});
        };
        bar.set_message(name.to_string());
        bar.set_length(total);
        bar.set_position(0);
        bar.set_style(
            ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} [{elapsed}]")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        // a step that learns its count as it goes (slabs) says it with each tick
        let out = work(&|done, of| {
            bar.set_length(of as u64);
            bar.set_position(done as u64)
        });
        bar.set_style(
            ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        bar.set_length(0);
        bar.println(format!("  {name} ({:.2} s)", start.elapsed().as_secs_f64()));
        out
    }

    /// Shows `msg` as the current step (e.g. the stage a pipeline is in).
    pub fn message(&self, msg: &str) {
        if let Some(bar) = &self.bar {
            bar.set_message(msg.to_string());
        }
    }

    /// Prints a progress line above the spinner (terminal only, like the spinner).
    pub fn line(&self, line: &str) {
        if let Some(bar) = &self.bar {
            bar.println(line);
        }
    }

    /// Prints a line of results on stderr unless quiet.
    pub fn note(&self, line: &str) {
        if self.quiet {
            return;
        }
        let line = crate::flags::with_flags(line, &self.flags);
        match &self.bar {
            Some(bar) => bar.println(line),
            None => eprintln!("{line}"),
        }
    }

    /// `message` with the parameter names the command has flags for replaced by the flags.
    pub fn with_flags(&self, message: &str) -> String {
        crate::flags::with_flags(message, &self.flags)
    }

    /// Removes the spinner (before an error message or at the end).
    pub fn clear(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.clear();
    }
}
