//! The units a file states for its sample values and its lengths, and the
//! units of what mdtf derives from them (g in value units per length unit,
//! and so on), for figure axes, reports and manifests.

use serde::{Deserialize, Serialize};

/// The units a file states (None: it does not say).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Units {
    /// Unit of the sample values, e.g. "HU" (a CT's Hounsfield units).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<String>,
    /// Unit of the spacing and positions, e.g. "mm" or "um".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length: Option<String>,
}

impl Units {
    /// Whether the file stated neither unit.
    pub fn is_unknown(&self) -> bool {
        self.value.is_none() && self.length.is_none()
    }

    /// The value unit, or "input units" when the file does not say.
    pub fn value_name(&self) -> &str {
        self.value.as_deref().unwrap_or("input units")
    }

    /// The length unit, or "world unit" when the file does not say.
    pub fn length_name(&self) -> &str {
        self.length.as_deref().unwrap_or("world unit")
    }

    /// The length unit for amounts, or "world units" when the file does not say.
    pub fn lengths_name(&self) -> &str {
        self.length.as_deref().unwrap_or("world units")
    }

    /// The unit of the channel `name` ("v", "g", "g_hit", "f2", "inv_g",
    /// "distance", "gnorm"), e.g. "HU/mm" for g; None when the file states
    /// no unit, or for a channel not listed.
    pub fn of_channel(&self, name: &str) -> Option<String> {
        if self.is_unknown() {
            return None;
        }
        let (v, l) = (self.value_name(), self.length_name());
        match name {
            "v" => Some(v.to_string()),
            "g" | "g_hit" => Some(format!("{v}/{l}")),
            "f2" => Some(format!("{v}/{l}^2")),
            "inv_g" => Some(format!("{l}/{v}")),
            "distance" => Some(l.to_string()),
            "gnorm" => Some(format!("1/{l}^2")),
            _ => None,
        }
    }
}

/// The length unit of a NIfTI `xyzt_units` byte (its low three bits), None when unknown.
pub fn nifti_length_unit(xyzt_units: u8) -> Option<String> {
    match xyzt_units & 0x07 {
        1 => Some("m".into()),
        2 => Some("mm".into()),
        3 => Some("um".into()),
        _ => None,
    }
}

/// The short form of an OME-NGFF (UDUNITS-2) length unit, e.g. "micrometer" -> "um".
pub fn ngff_length_unit(unit: &str) -> String {
    match unit {
        "meter" => "m",
        "centimeter" => "cm",
        "millimeter" => "mm",
        "micrometer" => "um",
        "nanometer" => "nm",
        "angstrom" => "A",
        other => other,
    }
    .to_string()
}

/// The one unit of a NRRD list of quoted units (`"mm" "mm" "mm"`), None
/// when the list is empty or its units differ.
pub fn nrrd_common_unit(list: &str) -> Option<String> {
    let units: Vec<&str> = list
        .split('"')
        .enumerate()
        .filter(|(i, _)| i % 2 == 1)
        .map(|(_, u)| u.trim())
        .filter(|u| !u.is_empty())
        .collect();
    let first = *units.first()?;
    units.iter().all(|u| *u == first).then(|| first.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derived_channels_take_the_value_and_length_units() {
        let ct = Units { value: Some("HU".into()), length: Some("mm".into()) };
        assert_eq!(ct.of_channel("g").as_deref(), Some("HU/mm"));
        assert_eq!(ct.of_channel("f2").as_deref(), Some("HU/mm^2"));
        assert_eq!(ct.of_channel("distance").as_deref(), Some("mm"));
        let mm_only = Units { value: None, length: Some("mm".into()) };
        assert_eq!(mm_only.of_channel("g").as_deref(), Some("input units/mm"));
        assert_eq!(Units::default().of_channel("v"), None);
    }

    #[test]
    fn file_unit_fields_are_read_as_their_formats_define_them() {
        assert_eq!(nifti_length_unit(2 | 8).as_deref(), Some("mm"));
        assert_eq!(nifti_length_unit(3).as_deref(), Some("um"));
        assert_eq!(nifti_length_unit(0), None);
        assert_eq!(ngff_length_unit("micrometer"), "um");
        assert_eq!(nrrd_common_unit(r#""mm" "mm" "mm""#).as_deref(), Some("mm"));
        assert_eq!(nrrd_common_unit(r#""mm" "um" "mm""#), None);
        assert_eq!(nrrd_common_unit(""), None);
    }
}
