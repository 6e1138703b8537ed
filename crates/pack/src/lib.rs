//! Pack stage of mdtf: quantised textures and a manifest that tells a
//! renderer, with nothing else, how to decode every channel.
//!
//! A pack is a folder: `manifest.json` plus, per texture, raw samples
//! (components fastest, then x, y, z; little-endian) and a detached NRRD
//! header that Teem, ParaView and 3D Slicer open. Every code decodes as
//! value = offset + scale * code; signed channels (f'', normals) keep 0
//! exactly representable.

mod boundary_tf;
mod by_tasks;
mod gaussian;
mod lut;
mod manifest;
mod manifest_check;
mod product_tf;
mod profile;
mod quantise;
mod tables;
mod tet_tables;
mod tf;
mod widget_support;
mod writer;

pub use boundary_tf::{
    ARCH_RATIO, BOUNDARY_PALETTE, BoundaryArch, FALLBACK_OPACITY, ISOSURFACE_HALF_WIDTH, MAX_BOUNDARY_OPACITY,
    MIN_BOUNDARY_OPACITY, OUTER_BOUNDARY_OPACITY, Tent, boundary_alpha_u, boundary_colour, boundary_isosurface_tf,
    boundary_opacities, boundary_tf, isovalue, multi_field_isosurface_tf, per_voxel_opacities,
};
pub use by_tasks::TextureTarget;
pub use gaussian::{
    ERF_DOMAIN, ERF_SIZE, FitError, GaussianPrimitive, IGAUSS_DOMAIN, IGAUSS_SIZE, erf_difference,
    erf_difference_table, igauss, igauss_table,
};
pub use lut::{Lut, LutAxis, LutEntry};
pub use manifest::{
    ChannelEntry, ChannelSource, MANIFEST_SCHEMA, Manifest, ManifestGeometry, MeshArrayEntry, MeshEntry, Provenance,
    SCHEMA_ID, TextureEntry,
};
pub use manifest_check::ManifestError;
pub use product_tf::{FactorShape, PRODUCT_MAX_CHANNELS, ProductFactor, ProductTf};
pub use profile::{ChannelText, PROFILE_NAMES, Profile, TextureLayout, describe, texts};
pub use quantise::{Decode, Dtype, QuantiseError, decode_for};
pub use tables::{PEAKS_PER_ENTRY, Tf1d, peak_table, peaks, preintegration_table, segment, segment_by_midpoint};
pub use tet_tables::{
    TetTable, TetTableParams, front_back_tables, front_back_weights, gaussian_segment, gaussian_table,
    gaussian_widget_integral, lookup_gaussian, preintegration_1d_table, sinusoid_integral, sinusoid_table,
    triangle_flank_integral, triangle_tables,
};
pub use tf::{Falloff, TfFile, Widget, parse_tf, to_rgba8};
pub use widget_support::{GAUSSIAN_SUPPORT_SIGMAS, Support};
pub use writer::{PackWriter, SlabSource, texture_layouts};

use mdtf_volume::{Geometry, Volume, VolumeError};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;
use writer::{TextureBytes, TextureEncoder, write_manifest, write_texture};

/// Parameters of the pack stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PackParams {
    /// The layout.
    pub profile: Profile,
    /// Value range per channel covered by the codes; channels not listed use their min and max.
    #[serde(default)]
    pub ranges: BTreeMap<String, [f64; 2]>,
    /// Field names of a multi-field input, for the gaussian-tf and peak-finding layouts (empty: the scalar "v").
    #[serde(default)]
    pub fields: Vec<String>,
    /// Storage type for every texture instead of the profile's (u8, u16, f16 or f32).
    #[serde(default)]
    pub dtype: Option<Dtype>,
    /// Also write every texture as NIfTI-1 (`<name>.nii`, one volume per
    /// component, the codes as stored: u8, u16 (f16 bits) or f32) for tools without NRRD.
    #[serde(default)]
    pub nifti: bool,
}

impl PackParams {
    /// `profile` with its own texture types, measured ranges (qbert clipping is the
    /// caller's), the scalar "v" as the only field and no NIfTI copies.
    pub fn new(profile: Profile) -> PackParams {
        PackParams { profile, ranges: BTreeMap::new(), fields: Vec::new(), dtype: None, nifti: false }
    }
}

/// Errors of the pack stage.
#[derive(Debug, thiserror::Error)]
pub enum PackError {
    /// Channels the profile needs are missing.
    #[error("profile {profile} needs channel(s) {missing}")]
    MissingChannels {
        /// Profile name.
        profile: String,
        /// The missing channels and the stage that makes each.
        missing: String,
    },
    /// Channels on different grids.
    #[error("{0}")]
    Geometry(String),
    /// A range would lose all precision.
    #[error(transparent)]
    Quantise(#[from] QuantiseError),
    /// Writing failed.
    #[error(transparent)]
    Io(#[from] VolumeError),
}

/// Textures quantised in memory, ready to write.
#[derive(Debug, Clone)]
pub struct Encoded {
    /// The profile.
    pub profile: Profile,
    /// Grid of every texture.
    pub geometry: mdtf_volume::Geometry,
    /// (layout, bytes: components fastest, then x, y, z, little-endian).
    pub textures: Vec<(TextureLayout, Vec<u8>)>,
    /// One entry per (channel, texture, component).
    pub channels: Vec<ChannelEntry>,
    /// Write NIfTI copies of the textures too.
    pub nifti: bool,
}

/// Checks that `channels` hold every channel of `params.profile` on one
/// grid; returns that grid.
pub fn check_channels(channels: &[(String, Volume)], params: &PackParams) -> Result<Geometry, PackError> {
    let get = |n: &str| channels.iter().find(|(c, _)| c == n).map(|(_, v)| v);
    let missing: Vec<String> = params
        .profile
        .channels(&params.fields)
        .into_iter()
        .filter(|c| get(c).is_none())
        .map(|c| format!("{c} (made by the {} stage)", describe(&c, !params.fields.is_empty()).stage))
        .collect();
    if !missing.is_empty() {
        return Err(PackError::MissingChannels { profile: params.profile.to_string(), missing: missing.join(", ") });
    }
    let Some((_, first)) = channels.first() else {
        return Err(PackError::Geometry("no channels to pack".into()));
    };
    for (name, v) in channels {
        if !v.geometry.same_grid(&first.geometry) {
            return Err(PackError::Geometry(format!("channel {name} is not on the grid of {}", channels[0].0)));
        }
    }
    Ok(first.geometry.clone())
}

/// Quantises `channels` (name, volume) into the textures of `params.profile`, in memory.
pub fn encode(
    channels: &[(String, Volume)],
    params: &PackParams,
    sources: &BTreeMap<String, ChannelSource>,
) -> Result<Encoded, PackError> {
    let geometry = check_channels(channels, params)?;
    let get = |n: &str| channels.iter().find(|(c, _)| c == n).map(|(_, v)| v);
    let mut encoder = TextureEncoder::new(params, geometry.clone(), sources);
    let mut textures = Vec::new();
    for layout in texture_layouts(params) {
        let bytes = encoder.encode(&layout, &get)?;
        textures.push((layout, bytes));
    }
    Ok(Encoded { profile: params.profile, geometry, textures, channels: encoder.entries, nifti: params.nifti })
}

/// [`encode`] without whole textures in memory: each texture's bytes go to
/// `sink(layout, bytes)` in order, a slab of z-slices at a time (for a
/// renderer that uploads textures as they come). Returns the channel
/// entries of the manifest.
pub fn encode_streamed(
    channels: &[(String, Volume)],
    params: &PackParams,
    sources: &BTreeMap<String, ChannelSource>,
    sink: &mut dyn FnMut(&TextureLayout, &[u8]) -> std::io::Result<()>,
) -> Result<Vec<ChannelEntry>, PackError> {
    let geometry = check_channels(channels, params)?;
    let get = |n: &str| channels.iter().find(|(c, _)| c == n).map(|(_, v)| v);
    let mut encoder = TextureEncoder::new(params, geometry, sources);
    for layout in texture_layouts(params) {
        encoder.stream(&layout, &get, &mut |bytes| sink(&layout, bytes))?;
    }
    Ok(encoder.entries)
}

/// Writes encoded textures (raw + detached NRRD header each), the lookup
/// tables and `manifest.json` into `dir`. Returns the manifest.
pub fn write(encoded: &Encoded, luts: &[Lut], dir: &Path, provenance: Provenance) -> Result<Manifest, PackError> {
    let textures = encoded
        .textures
        .iter()
        .map(|(layout, bytes)| write_texture(dir, &encoded.geometry, layout, TextureBytes::Whole(bytes), encoded.nifti))
        .collect::<Result<Vec<_>, _>>()?;
    write_manifest(dir, encoded.profile, &encoded.geometry, textures, encoded.channels.clone(), luts, provenance)
}

/// [`encode`] then [`write`], one texture at a time (only one texture's
/// bytes are in memory at once).
pub fn pack(
    channels: &[(String, Volume)],
    params: &PackParams,
    luts: &[Lut],
    dir: &Path,
    provenance: Provenance,
    sources: &BTreeMap<String, ChannelSource>,
) -> Result<Manifest, PackError> {
    let geometry = check_channels(channels, params)?;
    let get = |n: &str| channels.iter().find(|(c, _)| c == n).map(|(_, v)| v);
    let mut writer = PackWriter::new(dir, params, geometry, sources);
    for layout in texture_layouts(params) {
        writer.add(&layout, &get)?;
    }
    writer.finish(luts, provenance)
}

/// SHA-256 of a file, hex, streamed.
pub fn sha256_file(path: &Path) -> std::io::Result<String> {
    use sha2::Digest;
    use std::io::Read;
    let mut f = std::fs::File::open(path)?;
    let mut h = sha2::Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f.read(&mut buf)?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
    }
    Ok(h.finalize().iter().map(|b| format!("{b:02x}")).collect())
}

/// SHA-256 of an input, hex: of the file, or, for a folder (a DICOM
/// series, an OME-Zarr store), of its files' relative paths ('/'-separated)
/// and SHA-256s, one `path sha256` line each in byte order of the paths,
/// so that the same files give the same hash wherever the folder lies.
pub fn sha256_path(path: &Path) -> std::io::Result<String> {
    use sha2::Digest;
    if !path.is_dir() {
        return sha256_file(path);
    }
    let mut files = Vec::new();
    let mut pending = vec![path.to_path_buf()];
    while let Some(dir) = pending.pop() {
        for entry in std::fs::read_dir(&dir)? {
            let p = entry?.path();
            if p.is_dir() {
                pending.push(p);
            } else {
                let rel = p.strip_prefix(path).unwrap_or(&p);
                let name: Vec<String> =
                    rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
                files.push((name.join("/"), p));
            }
        }
    }
    files.sort();
    let mut h = sha2::Sha256::new();
    for (name, p) in &files {
        h.update(format!("{name} {}\n", sha256_file(p)?));
    }
    Ok(h.finalize().iter().map(|b| format!("{b:02x}")).collect())
}
