//! The stage libraries name their parameters as a settings file does
//! (`boundary.d_max`); a user of a stage subcommand typed a flag (`--d-max`).
//! This is the one place that maps the one to the other, when an error is printed.

use crate::args::Command;

/// Settings-file names shared by the input options of every subcommand that reads a volume.
const INPUT: &[(&str, &str)] = &[("input.nan = \"zero\"", "--nan zero"), ("input.level", "--level")];

const BOUNDARY: &[(&str, &str)] = &[
    ("boundary.step", "--step"),
    ("boundary.d_max", "--d-max"),
    ("boundary.tolerance", "--tolerance"),
    ("boundary.g_min", "--g-min"),
    ("boundary.g_hit_min", "--g-hit-min"),
    ("boundary.alpha", "--alpha"),
    ("bilateral.sigma_d", "--prefilter's SIGMA_D"),
    ("bilateral.sigma_r", "--prefilter's SIGMA_R"),
];

const BILATERAL: &[(&str, &str)] = &[("bilateral.sigma_d", "--sigma-d"), ("bilateral.sigma_r", "--sigma-r")];

const PREVIEW: &[(&str, &str)] = &[
    ("preview.azimuth", "--view's azimuth"),
    ("preview.elevation", "--view's elevation"),
    ("preview.size", "--size"),
    ("preview.step", "--step"),
];

const TETRA: &[(&str, &str)] = &[
    ("tetra.tets", "--tets"),
    ("tetra.scalar", "--scalar"),
    ("pack.tf", "--tf"),
    ("tables.d_max", "--d-max"),
    ("tables.tau_max", "--tau-max"),
];

const PACK: &[(&str, &str)] = &[("pack.tf", "--tf")];

/// The (parameter name, flag) pairs of `command`'s flags; empty for the
/// commands driven by a settings file (`run`, `validate`), whose users see
/// the file's names.
pub fn of(command: &Command) -> Vec<(&'static str, &'static str)> {
    let own: &[(&str, &str)] = match command {
        Command::Boundary(_) => BOUNDARY,
        Command::Bilateral(_) => BILATERAL,
        Command::Preview(_) => PREVIEW,
        Command::Tetra(_) => TETRA,
        Command::Pack(_) => PACK,
        Command::Run(_) | Command::Validate(_) => return Vec::new(),
        _ => &[],
    };
    INPUT.iter().chain(own).copied().collect()
}

/// `message` with each parameter name of `flags` that stands as a whole
/// word (not part of a longer name) replaced by its flag.
pub fn with_flags(message: &str, flags: &[(&str, &str)]) -> String {
    let mut out = message.to_string();
    for (name, flag) in flags {
        let mut result = String::with_capacity(out.len());
        let mut rest = out.as_str();
        while let Some(at) = rest.find(name) {
            let before = if at > 0 { rest[..at].chars().last() } else { result.chars().last() };
            let after = rest[at + name.len()..].chars().next();
            let word = |c: char| c.is_alphanumeric() || c == '_';
            let inside = before.is_some_and(|c| word(c) || c == '.') || after.is_some_and(word);
            result.push_str(&rest[..at]);
            result.push_str(if inside { name } else { flag });
            rest = &rest[at + name.len()..];
        }
        result.push_str(rest);
        out = result;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_names_become_flags_and_longer_names_are_left_alone() {
        let flags = [("boundary.step", "--step"), ("boundary.d_max", "--d-max")];
        assert_eq!(
            with_flags("boundary.step 3 is larger than boundary.d_max 2", &flags),
            "--step 3 is larger than --d-max 2"
        );
        assert_eq!(with_flags("boundary.steps and xboundary.step", &flags), "boundary.steps and xboundary.step");
        assert_eq!(with_flags("(boundary.step).", &flags), "(--step).");
        assert_eq!(with_flags("nothing to map", &flags), "nothing to map");
    }
}
