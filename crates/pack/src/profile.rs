//! Texture layouts, one per renderer family.

use crate::quantise::Dtype;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// A renderer family's pack layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Profile {
    /// Kniss et al.'s 3D-TF slicer: RGBA8 `data` (v, g, f'', unused) and RGBA8 `normal` (nx, ny, nz, g).
    Slicer3dtf,
    /// The distance-based TF renderer: RGBA8 `normal_v` (nx, ny, nz, v) and 2-component u8 `ghit_d` (g_hit, d).
    DistanceTf,
}

/// Profile names for messages.
pub const PROFILE_NAMES: &str = "slicer-3dtf, distance-tf";

/// One texture of a profile: its name, channels per component (None: unused) and type.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureLayout {
    /// Texture name (also its file stem).
    pub name: &'static str,
    /// Channel per component.
    pub components: Vec<Option<&'static str>>,
    /// Storage type.
    pub dtype: Dtype,
}

impl Profile {
    /// The textures of this profile.
    pub fn layout(self) -> Vec<TextureLayout> {
        match self {
            Profile::Slicer3dtf => vec![
                TextureLayout {
                    name: "data",
                    components: vec![Some("v"), Some("g"), Some("f2"), None],
                    dtype: Dtype::U8,
                },
                TextureLayout {
                    name: "normal",
                    components: vec![Some("nx"), Some("ny"), Some("nz"), Some("g")],
                    dtype: Dtype::U8,
                },
            ],
            Profile::DistanceTf => vec![
                TextureLayout {
                    name: "normal_v",
                    components: vec![Some("nx"), Some("ny"), Some("nz"), Some("v")],
                    dtype: Dtype::U8,
                },
                TextureLayout { name: "ghit_d", components: vec![Some("g_hit"), Some("distance")], dtype: Dtype::U8 },
            ],
        }
    }

    /// Every channel the profile needs, each once, in layout order.
    pub fn channels(self) -> Vec<&'static str> {
        let mut out: Vec<&'static str> = Vec::new();
        for t in self.layout() {
            for c in t.components.into_iter().flatten() {
                if !out.contains(&c) {
                    out.push(c);
                }
            }
        }
        out
    }
}

/// What a channel is, its units, the stage that makes it, and whether it is signed (0 kept exact).
pub fn describe(channel: &str) -> (&'static str, &'static str, &'static str, bool) {
    match channel {
        "v" => ("value", "input units", "input", false),
        "g" => ("gradient magnitude |grad f|", "value units per world unit", "derive", false),
        "f2" => ("second derivative along the gradient", "value units per world unit^2", "derive", true),
        "nx" | "ny" | "nz" => ("unit normal component along the grid axis", "1", "derive", true),
        "g_hit" => ("gradient magnitude at the boundary hit", "value units per world unit", "boundary", false),
        "distance" => ("distance to the nearest boundary (-1: none)", "world units", "boundary", false),
        _ => ("field", "field units", "input", false),
    }
}

impl FromStr for Profile {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "slicer-3dtf" => Ok(Profile::Slicer3dtf),
            "distance-tf" => Ok(Profile::DistanceTf),
            "gaussian-tf" | "peak-finding" | "projected-tetrahedra" => {
                Err(format!("profile '{s}' is not implemented yet (available: {PROFILE_NAMES})"))
            }
            _ => Err(format!("unknown profile '{s}' (available: {PROFILE_NAMES})")),
        }
    }
}

impl fmt::Display for Profile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Profile::Slicer3dtf => "slicer-3dtf",
            Profile::DistanceTf => "distance-tf",
        })
    }
}
