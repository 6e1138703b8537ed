//! Pipeline files (TOML): the input, the stages with their parameters (the
//! very serde structs the stages and subcommands use, so names and defaults
//! are one set), what to keep, and the pack profile.

use mdtf_boundary::{AlphaMap, BoundaryParams};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// A built-in phantom used when the pipeline names no input file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum PhantomKind {
    /// The erf sphere of DESIGN.md.
    #[default]
    ErfSphere,
    /// Nested tooth-like shells.
    Shells,
    /// Three erf spheres as three fields.
    Multifield,
}

/// `[input]`: a file, or a built-in phantom.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InputSection {
    /// Volume file or folder (NIfTI, NRRD, MetaImage, TIFF, DICOM series or
    /// DICOMDIR, OME-Zarr store); relative paths are relative to the pipeline file.
    pub file: Option<PathBuf>,
    /// DICOM: the series to read (SeriesNumber or SeriesInstanceUID) when the
    /// input holds several; `series = 3` and `series = "1.2.840..."` both work.
    #[serde(deserialize_with = "number_or_text")]
    pub series: Option<String>,
    /// DICOM: interpolate a stack with unequal slice gaps or a gantry tilt
    /// onto a regular grid instead of refusing it (reported in the run report).
    pub resample: bool,
    /// OME-Zarr: the multiscale level to read, 0 (full resolution) by default.
    pub level: usize,
    /// NaN or infinite samples: "refuse" the file (default), "zero" them, or
    /// "keep" them (the stages then refuse them).
    pub nan: mdtf_volume::NanPolicy,
    /// Values that are scanner padding, not data: one value or an inclusive
    /// range `[low, high]`, input units (after the file's rescaling). Every
    /// derivative whose kernel reads one is NaN, so padding is in no
    /// histogram, statistic or trace. A DICOM series' Pixel Padding Value
    /// (and Range Limit) is used when this is not given.
    pub padding: Option<Padding>,
    /// Phantom to synthesise when there is no file.
    pub phantom: PhantomKind,
    /// Phantom grid size (cube).
    pub size: usize,
    /// Phantom boundary blur, world units.
    pub sigma: f64,
    /// Gaussian noise added to the phantom (value units), 0 for none.
    pub noise: f64,
}

/// Scanner padding values: one value or an inclusive range.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Padding {
    /// One value, e.g. -2000.
    Value(f64),
    /// An inclusive range [low, high].
    Range([f64; 2]),
}

impl Padding {
    /// The inclusive range of padding values (low first).
    pub fn range(self) -> [f64; 2] {
        match self {
            Padding::Value(v) => [v, v],
            Padding::Range([a, b]) => [a.min(b), a.max(b)],
        }
    }
}

/// An optional value given either as a TOML integer or as a string.
fn number_or_text<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<String>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum NumberOrText {
        Number(i64),
        Text(String),
    }
    Ok(Option::<NumberOrText>::deserialize(d)?.map(|v| match v {
        NumberOrText::Number(n) => n.to_string(),
        NumberOrText::Text(t) => t,
    }))
}

impl Default for InputSection {
    fn default() -> Self {
        InputSection {
            file: None,
            series: None,
            resample: false,
            level: 0,
            nan: mdtf_volume::NanPolicy::Refuse,
            padding: None,
            phantom: PhantomKind::ErfSphere,
            size: 128,
            sigma: 3.0,
            noise: 0.0,
        }
    }
}

/// `[derive]`: the derivative kernel used by every stage that needs derivatives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct DeriveSection {
    /// Kernel (central4, central, bspline3, catmull-rom, gauss:SIGMA), checked
    /// when the file is read; default [`mdtf_derive::DEFAULT_KERNEL`].
    pub kernel: mdtf_derive::Kernel,
}

/// `[histogram]`: which pictures to make.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HistogramSection {
    /// The joint (v, g) histogram.
    pub joint: bool,
    /// The stretched (v, g_hit) histogram and the normal | stretched figure.
    pub stretched: bool,
    /// The histogram volume and the default opacity.
    pub hvol: bool,
}

impl Default for HistogramSection {
    fn default() -> Self {
        HistogramSection { joint: true, stretched: false, hvol: false }
    }
}

/// `[pack]`: the renderer family and its transfer function.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PackSection {
    /// Profile: slicer-3dtf, distance-tf, gaussian-tf, peak-finding or projected-tetrahedra.
    pub profile: mdtf_pack::Profile,
    /// Transfer-function file (relative to the pipeline file).
    #[serde(default)]
    pub tf: Option<PathBuf>,
    /// distance-tf: the alpha map of distance (default: linear, a = 1).
    #[serde(default)]
    pub alpha: AlphaMap,
    /// gaussian-tf without a TF file: fit the Gaussian to the voxels where
    /// this mask volume (relative to the pipeline file) is positive.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gtf_from_mask: Option<PathBuf>,
    /// Also write every texture as NIfTI-1.
    #[serde(default)]
    pub nifti: bool,
}

/// The file format of kept channels (`keep_format`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum KeepFormat {
    /// gzip NIfTI-1, `volumes/<channel>.nii.gz` (3D Slicer, ITK-SNAP, nibabel).
    #[default]
    #[serde(rename = "nii.gz")]
    NiiGz,
    /// OME-Zarr 0.5, `volumes/<channel>.ome.zarr` (napari, zarr-python, Dask).
    #[serde(rename = "ome-zarr")]
    OmeZarr,
}

impl KeepFormat {
    /// The file name of kept channel `channel`, e.g. "g.nii.gz".
    pub fn file_name(self, channel: &str) -> String {
        match self {
            KeepFormat::NiiGz => format!("{channel}.nii.gz"),
            KeepFormat::OmeZarr => format!("{channel}.ome.zarr"),
        }
    }
}

/// A whole pipeline file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pipeline {
    /// One line saying what the pipeline is for.
    #[serde(default)]
    pub description: String,
    /// The input.
    #[serde(default)]
    pub input: InputSection,
    /// Derivatives.
    #[serde(default)]
    pub derive: DeriveSection,
    /// `[prefilter]`: optional bilateral pre-filter of g and f'' before
    /// tracing, with the bilateral stage's parameters (sigma_d in world
    /// units; sigma_r by default a fraction of each channel's own range).
    #[serde(default)]
    pub prefilter: Option<mdtf_bilateral::BilateralParams>,
    /// Boundary tracing (runs when a later stage needs its channels).
    #[serde(default)]
    pub boundary: BoundaryParams,
    /// Histograms.
    #[serde(default)]
    pub histogram: Option<HistogramSection>,
    /// The pack.
    pub pack: PackSection,
    /// `[tetra]`: meshing and tables of the projected-tetrahedra profile.
    #[serde(default)]
    pub tetra: mdtf_tetra::TetraParams,
    /// Channels to write as volumes too (e.g. ["g", "f2", "distance"]).
    #[serde(default)]
    pub keep: Vec<String>,
    /// How the kept channels are written: "nii.gz" (default) or "ome-zarr".
    #[serde(default)]
    pub keep_format: KeepFormat,
    /// Render preview.png from the pack (profiles with a preview: slicer-3dtf, distance-tf).
    #[serde(default = "yes")]
    pub preview: bool,
}

fn yes() -> bool {
    true
}

/// Parses a pipeline file after applying `overrides` ("section.key=value",
/// the value parsed as TOML, else taken as a string). Errors name the file's field.
pub fn parse(text: &str, overrides: &[String]) -> Result<Pipeline, String> {
    if overrides.is_empty() {
        // straight from the text, so that errors point at the file's own lines
        return toml::from_str(text).map_err(|e| e.to_string());
    }
    let mut doc: toml::Table = toml::from_str(text).map_err(|e| e.to_string())?;
    apply_overrides(&mut doc, overrides)?;
    toml::Value::Table(doc).try_into().map_err(|e: toml::de::Error| {
        let message = e.to_string().split_whitespace().collect::<Vec<_>>().join(" ");
        format!("{message} (with the --set overrides applied)")
    })
}

/// A settings table as TOML text (a pipeline file).
pub fn to_toml(table: &toml::Table) -> Result<String, String> {
    toml::to_string_pretty(table).map_err(|e| e.to_string())
}

/// Sets "section.key=value" overrides (any depth; the value parsed as TOML,
/// else taken as a string) in a TOML document.
pub fn apply_overrides(doc: &mut toml::Table, overrides: &[String]) -> Result<(), String> {
    for o in overrides {
        let (key, value) = o.split_once('=').ok_or_else(|| format!("--set {o}: expected section.key=value"))?;
        let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {value}"))
            .ok()
            .and_then(|t| t.get("v").cloned())
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        let mut parts: Vec<&str> = key.split('.').collect();
        let last = parts.pop().ok_or_else(|| format!("--set {o}: empty key"))?;
        let mut table = &mut *doc;
        for p in parts {
            table = table
                .entry(p.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                .as_table_mut()
                .ok_or_else(|| format!("--set {o}: {p} is not a section"))?;
        }
        table.insert(last.to_string(), value);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overrides_patch_nested_keys_with_typed_values() {
        let text = "[pack]\nprofile = \"slicer-3dtf\"\n[input]\nsize = 64\n";
        let p = parse(text, &["input.size=32".into(), "boundary.g_min=2.5".into(), "derive.kernel=central".into()])
            .unwrap();
        assert_eq!(p.input.size, 32);
        assert_eq!(p.boundary.g_min, Some(2.5));
        assert_eq!(p.derive.kernel, mdtf_derive::Kernel::Central);
        let e = parse(text, &["input.sise=3".into()]).unwrap_err();
        assert!(e.contains("sise") && e.contains("--set"), "{e}");
    }

    #[test]
    fn the_prefilter_and_the_nan_policy_take_the_stages_own_parameters() {
        let text =
            "[pack]\nprofile = \"distance-tf\"\n[input]\nnan = \"zero\"\n[prefilter]\nsigma_d = 2.0\nmode = \"fast\"\n";
        let p = parse(text, &[]).unwrap();
        assert_eq!(p.input.nan, mdtf_volume::NanPolicy::Zero);
        let pf = p.prefilter.unwrap();
        assert_eq!((pf.sigma_d, pf.sigma_r, pf.mode), (2.0, 0.05, mdtf_bilateral::Mode::Fast));
        let e = parse("[pack]\nprofile = \"distance-tf\"\n[input]\nnan = \"drop\"\n", &[]).unwrap_err();
        assert!(e.contains("line 4") && e.contains("drop"), "{e}");
    }

    #[test]
    fn an_unknown_key_is_shown_at_its_own_line_of_the_file() {
        let text = "[pack]\nprofile = \"slicer-3dtf\"\n[input]\nsize = 64\nbogus=1\n";
        let e = parse(text, &[]).unwrap_err();
        assert!(e.contains("line 5") && e.contains("bogus=1"), "{e}");
    }

    #[test]
    fn a_kernel_or_profile_typo_is_shown_at_its_line() {
        let e = parse("[pack]\nprofile = \"slicer-3dtf\"\n[derive]\nkernel = \"gauss:-1\"\n", &[]).unwrap_err();
        assert!(e.contains("line 4") && e.contains("unknown kernel 'gauss:-1'"), "{e}");
        let e = parse("[pack]\nprofile = \"peak\"\n", &[]).unwrap_err();
        assert!(e.contains("line 2") && e.contains("unknown profile 'peak'"), "{e}");
        let p = parse("[pack]\nprofile = \"peak-finding\"\n[derive]\nkernel = \"gauss:1.5\"\n", &[]).unwrap();
        assert_eq!(
            (p.pack.profile, p.derive.kernel),
            (mdtf_pack::Profile::PeakFinding, mdtf_derive::Kernel::Gauss { sigma: 1.5 })
        );
    }
}
