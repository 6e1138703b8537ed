//! Flag values parsed as the libraries' own types, by the names a pipeline
//! file gives them (their kebab-case serde names), so that the CLI keeps no
//! mirror enums and no copies of the libraries' defaults.

use serde::de::{DeserializeOwned, IntoDeserializer, value::StrDeserializer};

/// A library enum from its settings-file name, e.g. `fast` for
/// `mdtf_pipeline::stages::bilateral::Mode::Fast` (a clap value parser).
pub fn named<T: DeserializeOwned>(text: &str) -> Result<T, String> {
    let d: StrDeserializer<'_, serde::de::value::Error> = text.into_deserializer();
    T::deserialize(d).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_the_settings_files_and_a_typo_lists_the_choices() {
        assert_eq!(
            named::<mdtf_pipeline::stages::bilateral::Mode>("fast"),
            Ok(mdtf_pipeline::stages::bilateral::Mode::Fast)
        );
        assert_eq!(
            named::<mdtf_pipeline::stages::derive::Border>("mirror"),
            Ok(mdtf_pipeline::stages::derive::Border::Mirror)
        );
        let e = named::<mdtf_pipeline::stages::bilateral::RangeUnits>("percent").unwrap_err();
        assert!(e.contains("percent") && e.contains("fraction") && e.contains("value"), "{e}");
    }
}
