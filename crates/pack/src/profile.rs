//! Texture layouts, one per renderer family.

use crate::quantise::Dtype;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// A renderer family's pack layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum Profile {
    /// Kniss et al.'s 3D-TF slicer: RGBA8 `data` (v, g, f'', unused) and RGBA8 `normal` (nx, ny, nz, g).
    Slicer3dtf,
    /// The distance-based TF renderer: RGBA8 `normal_v` (nx, ny, nz, v) and 2-component u8 `ghit_d` (g_hit, d).
    DistanceTf,
    /// Gaussian TFs: the fields (normalised to [0, 1] by their decode) and
    /// ||G|| (`gnorm`), or for scalar data v and g, four per u16 texture `fields_k`.
    GaussianTf,
    /// Peak finding: the fields and 1/g (for several fields 1 / sqrt(||G||)), four per u16 texture `fields_k`.
    PeakFinding,
    /// Projected tetrahedra with bivariate (s, g) TFs: no volume textures;
    /// the mesh's per-vertex and per-cell arrays and the pre-integration
    /// tables, written by `mdtf tetra` (crate mdtf-tetra).
    ProjectedTetrahedra,
}

/// Profile names for messages.
pub const PROFILE_NAMES: &str = "slicer-3dtf, distance-tf, gaussian-tf, peak-finding, projected-tetrahedra";

/// One texture of a profile: its name, channels per component (None: unused) and type.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TextureLayout {
    /// Texture name (also its file stem).
    pub name: String,
    /// Channel per component.
    pub components: Vec<Option<String>>,
    /// Storage type.
    pub dtype: Dtype,
}

fn tex(name: &str, components: &[Option<&str>], dtype: Dtype) -> TextureLayout {
    TextureLayout { name: name.into(), components: components.iter().map(|c| c.map(str::to_string)).collect(), dtype }
}

impl Profile {
    /// The textures of this profile; `fields` names the input's fields (the
    /// multi-field profiles pack them all; an empty list means the scalar "v").
    pub fn layout(self, fields: &[String]) -> Vec<TextureLayout> {
        let groups = |extra: &str| {
            let mut all: Vec<String> = if fields.is_empty() { vec!["v".into()] } else { fields.to_vec() };
            all.push(extra.into());
            all.chunks(4)
                .enumerate()
                .map(|(k, c)| TextureLayout {
                    name: format!("fields_{k}"),
                    components: c.iter().cloned().map(Some).collect(),
                    dtype: Dtype::U16,
                })
                .collect()
        };
        match self {
            Profile::Slicer3dtf => vec![
                tex("data", &[Some("v"), Some("g"), Some("f2"), None], Dtype::U8),
                tex("normal", &[Some("nx"), Some("ny"), Some("nz"), Some("g")], Dtype::U8),
            ],
            Profile::DistanceTf => vec![
                tex("normal_v", &[Some("nx"), Some("ny"), Some("nz"), Some("v")], Dtype::U8),
                tex("ghit_d", &[Some("g_hit"), Some("distance")], Dtype::U8),
            ],
            Profile::GaussianTf => groups(if fields.is_empty() { "g" } else { "gnorm" }),
            Profile::PeakFinding => groups("inv_g"),
            Profile::ProjectedTetrahedra => Vec::new(),
        }
    }

    /// Every channel the profile needs, each once, in layout order.
    pub fn channels(self, fields: &[String]) -> Vec<String> {
        let mut out: Vec<String> = Vec::new();
        for t in self.layout(fields) {
            for c in t.components.into_iter().flatten() {
                if !out.contains(&c) {
                    out.push(c);
                }
            }
        }
        out
    }
}

/// What a packed channel is: the manifest's meaning and units, the stage
/// that makes it, and whether it is signed (quantised with 0 kept exact).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChannelText {
    /// What it measures, as the manifest says it.
    pub meaning: &'static str,
    /// Its units.
    pub units: &'static str,
    /// The mdtf stage that makes it ("input", "derive", "boundary").
    pub stage: &'static str,
    /// Signed: its code keeps 0 exact.
    pub signed: bool,
}

/// The texts of the channels the profiles pack (the pipeline's channel
/// table takes its rows' texts from here, so a packed channel is described once).
pub mod texts {
    use super::ChannelText;

    const fn text(meaning: &'static str, units: &'static str, stage: &'static str, signed: bool) -> ChannelText {
        ChannelText { meaning, units, stage, signed }
    }

    /// The value.
    pub const V: ChannelText = text("value", "input units", "input", false);
    /// A field of a several-field input.
    pub const FIELD: ChannelText = text("field", "field units", "input", false);
    /// g.
    pub const G: ChannelText = text("gradient magnitude |grad f|", "value units per world unit", "derive", false);
    /// f''.
    pub const F2: ChannelText =
        text("second derivative along the gradient", "value units per world unit^2", "derive", true);
    /// A unit normal's component.
    pub const NORMAL: ChannelText = text("unit normal component along the grid axis", "1", "derive", true);
    /// g at the boundary hit.
    pub const G_HIT: ChannelText =
        text("gradient magnitude at the boundary hit", "value units per world unit", "boundary", false);
    /// The distance to the boundary.
    pub const DISTANCE: ChannelText =
        text("distance to the nearest boundary (-1: none)", "world units", "boundary", false);
    /// ||Df^T Df||.
    pub const GNORM: ChannelText =
        text("||Df^T Df|| (Frobenius) of the fields normalised to [0, 1]", "per world unit^2", "derive", false);
    /// 1/g of one field.
    pub const INV_G: ChannelText =
        text("inverse gradient magnitude 1 / max(g, epsilon)", "world units per value unit", "derive", false);
    /// 1/g of several fields.
    pub const INV_G_MULTI: ChannelText = text(
        "inverse multi-field gradient 1 / max(sqrt(||Df^T Df||), epsilon) of the fields normalised to [0, 1] \
         (for one field, 1 / g)",
        "world units",
        "derive",
        false,
    );
}

/// The text of packed channel `channel`; `multi_field`: the pack's input has
/// several fields (its 1/g then comes from ||G|| of all of them). A name
/// not listed is one of the input's fields.
pub fn describe(channel: &str, multi_field: bool) -> ChannelText {
    match channel {
        "inv_g" if multi_field => texts::INV_G_MULTI,
        "v" => texts::V,
        "g" => texts::G,
        "f2" => texts::F2,
        "nx" | "ny" | "nz" => texts::NORMAL,
        "g_hit" => texts::G_HIT,
        "distance" => texts::DISTANCE,
        "gnorm" => texts::GNORM,
        "inv_g" => texts::INV_G,
        _ => texts::FIELD,
    }
}

impl FromStr for Profile {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "slicer-3dtf" => Ok(Profile::Slicer3dtf),
            "distance-tf" => Ok(Profile::DistanceTf),
            "gaussian-tf" => Ok(Profile::GaussianTf),
            "peak-finding" => Ok(Profile::PeakFinding),
            "projected-tetrahedra" => Ok(Profile::ProjectedTetrahedra),
            _ => Err(format!("unknown profile '{s}' (available: {PROFILE_NAMES})")),
        }
    }
}

impl fmt::Display for Profile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Profile::Slicer3dtf => "slicer-3dtf",
            Profile::DistanceTf => "distance-tf",
            Profile::GaussianTf => "gaussian-tf",
            Profile::PeakFinding => "peak-finding",
            Profile::ProjectedTetrahedra => "projected-tetrahedra",
        })
    }
}

impl TryFrom<String> for Profile {
    type Error = String;
    fn try_from(s: String) -> Result<Self, Self::Error> {
        s.parse()
    }
}

impl From<Profile> for String {
    fn from(p: Profile) -> String {
        p.to_string()
    }
}
