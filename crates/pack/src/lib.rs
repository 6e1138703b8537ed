//! Pack stage of mdtf: quantised textures and a manifest that tells a
//! renderer, with nothing else, how to decode every channel.
//!
//! A pack is a folder: `manifest.json` plus, per texture, raw samples
//! (components fastest, then x, y, z; little-endian) and a detached NRRD
//! header that Teem, ParaView and 3D Slicer open. Every code decodes as
//! value = offset + scale * code; signed channels (f'', normals) keep 0
//! exactly representable.

mod gaussian;
mod lut;
mod manifest;
mod profile;
mod quantise;
mod tables;
mod tet_tables;
mod tf;

pub use gaussian::GaussianPrimitive;
pub use lut::{Lut, LutAxis, LutEntry};
pub use manifest::{
    ChannelEntry, ChannelSource, MANIFEST_SCHEMA, Manifest, ManifestGeometry, MeshArrayEntry, MeshEntry, Provenance,
    SCHEMA_ID, TextureEntry,
};
pub use profile::{PROFILE_NAMES, Profile, TextureLayout, describe};
pub use quantise::{Decode, Dtype, QuantiseError, decode_for};
pub use tables::{Tf1d, peak_table, peaks, preintegration_table, segment, segment_by_midpoint};
pub use tet_tables::{
    TetTable, TetTableParams, front_back_tables, front_back_weights, gaussian_segment, gaussian_table,
    gaussian_widget_integral, lookup_gaussian, preintegration_1d_table, sinusoid_integral, sinusoid_table,
    triangle_flank_integral, triangle_tables,
};
pub use tf::{Falloff, TfFile, Widget, parse_tf, to_rgba8};

use mdtf_volume::{Volume, VolumeError, write_file_atomically};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

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

/// Quantises `channels` (name, volume) into the textures of `params.profile`, in memory.
pub fn encode(
    channels: &[(String, Volume)],
    params: &PackParams,
    sources: &BTreeMap<String, ChannelSource>,
) -> Result<Encoded, PackError> {
    let get = |n: &str| channels.iter().find(|(c, _)| c == n).map(|(_, v)| v);
    let missing: Vec<String> = params
        .profile
        .channels(&params.fields)
        .into_iter()
        .filter(|c| get(c).is_none())
        .map(|c| format!("{c} (made by the {} stage)", describe(&c).2))
        .collect();
    if !missing.is_empty() {
        return Err(PackError::MissingChannels { profile: params.profile.to_string(), missing: missing.join(", ") });
    }
    let Some((_, first)) = channels.first() else {
        return Err(PackError::Geometry("no channels to pack".into()));
    };
    let geometry = first.geometry.clone();
    for (name, v) in channels {
        if !v.geometry.same_grid(&geometry) {
            return Err(PackError::Geometry(format!("channel {name} is not on the grid of {}", channels[0].0)));
        }
    }
    let n = geometry.voxel_count();
    let plane = geometry.dims[0] * geometry.dims[1];
    let mut textures = Vec::new();
    let mut entries = Vec::new();
    // each channel's data range, measured once even when it sits in two textures
    let mut measured: BTreeMap<String, [f64; 2]> = BTreeMap::new();
    for mut layout in params.profile.layout(&params.fields) {
        if let Some(d) = params.dtype {
            layout.dtype = d;
        }
        let comps = layout.components.len();
        let mut decodes = Vec::with_capacity(comps);
        for (ci, c) in layout.components.iter().enumerate() {
            let Some(c) = c else {
                decodes.push(None);
                continue;
            };
            let v = get(c).ok_or_else(|| PackError::Geometry(format!("channel {c} vanished")))?;
            let [min, max] = match params.ranges.get(c) {
                Some(r) => *r,
                // unit normals: the range is known, no pass over the data
                None if matches!(c.as_str(), "nx" | "ny" | "nz") => [-1.0, 1.0],
                None => *measured
                    .entry(c.clone())
                    .or_insert_with(|| v.finite_range().map_or([0.0, 0.0], |(lo, hi)| [lo as f64, hi as f64])),
            };
            let (meaning, units, stage, signed) = describe(c);
            let d = decode_for(c, min, max, layout.dtype, signed)?;
            let top = layout.dtype.max_code().unwrap_or(0.0);
            entries.push(ChannelEntry {
                name: c.to_string(),
                meaning: meaning.into(),
                units: units.into(),
                texture: layout.name.clone(),
                component: ci,
                decode: d,
                range: [d.offset, d.offset + d.scale * top],
                source: sources
                    .get(c)
                    .cloned()
                    .unwrap_or(ChannelSource { stage: stage.into(), params: serde_json::Value::Null }),
            });
            decodes.push(Some((v.samples(), d)));
        }
        let size = layout.dtype.size();
        let mut bytes = vec![0u8; n * comps * size];
        let nx = geometry.dims[0];
        bytes.par_chunks_mut(plane * comps * size).enumerate().for_each_init(
            || vec![vec![0u32; nx]; comps],
            |codes, (k, out)| {
                for j in 0..geometry.dims[1] {
                    let row = (k * plane + j * nx)..(k * plane + (j + 1) * nx);
                    for (ci, dec) in decodes.iter().enumerate() {
                        match dec {
                            Some((data, d)) => encode_row(&data[row.clone()], d, layout.dtype, &mut codes[ci]),
                            None => codes[ci].fill(0),
                        }
                    }
                    interleave(codes, size, &mut out[j * nx * comps * size..(j + 1) * nx * comps * size]);
                }
            },
        );
        textures.push((layout, bytes));
    }
    Ok(Encoded { profile: params.profile, geometry, textures, channels: entries, nifti: params.nifti })
}

/// Codes of one row of one component. Integer codes are rounded in f64 (so
/// every code is within half a step whatever the range) in a branch-free
/// loop that vectorises; compiled for AVX-512/AVX2 too, picked at run time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512vl+avx2", "x86_64+avx2"))]
fn encode_row(src: &[f32], d: &Decode, dtype: Dtype, codes: &mut [u32]) {
    match dtype.max_code() {
        Some(top) => {
            let (off, inv) = (d.offset, 1.0 / d.scale);
            // Adding 2^52 leaves the rounded (to nearest, ties to even: still within half a
            // step) integer in the low mantissa bits: no float-to-int conversion, so no
            // per-lane NaN handling, and the loop stays in SIMD registers.
            const MAGIC: f64 = 4_503_599_627_370_496.0;
            for (c, &v) in codes.iter_mut().zip(src) {
                let x = (v as f64 - off) * inv;
                let x = if x > 0.0 { x } else { 0.0 }; // NaN fails the comparison: code 0
                let x = if x < top { x } else { top };
                *c = (x + MAGIC).to_bits() as u32;
            }
        }
        None => {
            for (c, &v) in codes.iter_mut().zip(src) {
                *c = d.code(v, dtype);
            }
        }
    }
}

/// Interleaves per-component codes (each one row) into little-endian texture bytes.
fn interleave(codes: &[Vec<u32>], size: usize, out: &mut [u8]) {
    let comps = codes.len();
    match (size, comps) {
        (1, 4) => {
            let n = out.len() / 4;
            let (c0, c1, c2, c3) = (&codes[0][..n], &codes[1][..n], &codes[2][..n], &codes[3][..n]);
            // one little-endian u32 per texel: shifts and ors that vectorise
            for (i, px) in out.chunks_exact_mut(4).enumerate() {
                let word = (c0[i] & 0xff) | (c1[i] & 0xff) << 8 | (c2[i] & 0xff) << 16 | (c3[i] & 0xff) << 24;
                px.copy_from_slice(&word.to_le_bytes());
            }
        }
        _ => {
            for (i, px) in out.chunks_exact_mut(comps * size).enumerate() {
                for (ci, code) in codes.iter().enumerate() {
                    px[ci * size..(ci + 1) * size].copy_from_slice(&code[i].to_le_bytes()[..size]);
                }
            }
        }
    }
}

/// Writes encoded textures (raw + detached NRRD header each), the lookup
/// tables and `manifest.json` into `dir`. Returns the manifest.
pub fn write(encoded: &Encoded, luts: &[Lut], dir: &Path, provenance: Provenance) -> Result<Manifest, PackError> {
    let geometry = &encoded.geometry;
    let mut textures = Vec::new();
    for (layout, bytes) in &encoded.textures {
        let comps = layout.components.len();
        let data_file = format!("{}.raw", layout.name);
        let header_file = format!("{}.nhdr", layout.name);
        write_file_atomically(&dir.join(&data_file), |w| w.write_all(bytes))?;
        let type_name = match layout.dtype {
            Dtype::U8 => "uint8",
            Dtype::U16 | Dtype::F16 => "uint16",
            Dtype::F32 => "float",
        };
        let order: Vec<String> = layout.components.iter().map(|c| c.clone().unwrap_or_else(|| "-".into())).collect();
        let extra =
            [("mdtf_components", order.join(" ")), ("mdtf_dtype", format!("{:?}", layout.dtype).to_lowercase())];
        let header = mdtf_volume::nrrd::texture_header(geometry, comps, type_name, &data_file, &extra);
        write_file_atomically(&dir.join(&header_file), |w| w.write_all(header.as_bytes()))?;
        let nifti = if encoded.nifti {
            let file = format!("{}.nii", layout.name);
            write_nifti_texture(&dir.join(&file), geometry, &layout.components, layout.dtype, bytes)?;
            Some(file)
        } else {
            None
        };
        textures.push(TextureEntry {
            name: layout.name.clone(),
            header: header_file,
            data: data_file,
            dims: geometry.dims,
            components: comps,
            component_order: layout.components.clone(),
            dtype: layout.dtype,
            nifti,
        });
    }
    let manifest = Manifest {
        schema: SCHEMA_ID.into(),
        profile: encoded.profile.to_string(),
        geometry: ManifestGeometry {
            dims: geometry.dims,
            spacing: geometry.spacing,
            origin: geometry.origin,
            world_from_voxel: geometry.world_from_voxel(),
        },
        textures,
        channels: encoded.channels.clone(),
        luts: luts.iter().map(|l| l.write(dir)).collect::<Result<_, _>>()?,
        mesh: None,
        provenance,
    };
    let json = serde_json::to_string_pretty(&manifest)
        .map_err(|e| PackError::Io(VolumeError::Fields(format!("manifest: {e}"))))?;
    write_file_atomically(&dir.join("manifest.json"), |w| w.write_all(json.as_bytes()))?;
    Ok(manifest)
}

/// Writes one texture as NIfTI-1: a 4D volume with one component per
/// volume (named after its channel), the stored codes as u8, u16 or f32.
fn write_nifti_texture(
    path: &Path,
    geometry: &mdtf_volume::Geometry,
    components: &[Option<String>],
    dtype: Dtype,
    bytes: &[u8],
) -> Result<(), PackError> {
    use mdtf_volume::{Field, MultiField, SampleType, WriteOptions};
    let (size, ty) = match dtype {
        Dtype::U8 => (1, SampleType::U8),
        Dtype::U16 | Dtype::F16 => (2, SampleType::U16),
        Dtype::F32 => (4, SampleType::F32),
    };
    let comps = components.len();
    let mut fields = Vec::with_capacity(comps);
    for (c, name) in components.iter().enumerate() {
        let values: Vec<f32> = bytes
            .chunks_exact(comps * size)
            .map(|px| {
                let b = &px[c * size..(c + 1) * size];
                match size {
                    1 => b[0] as f32,
                    2 => u16::from_le_bytes([b[0], b[1]]) as f32,
                    _ => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                }
            })
            .collect();
        let data = ndarray::Array3::from_shape_vec(geometry.shape(), values)
            .map_err(|e| PackError::Geometry(format!("{}: {e}", path.display())))?;
        fields.push(Field { name: name.clone().unwrap_or_else(|| "unused".into()), data });
    }
    let mf = MultiField { geometry: geometry.clone(), fields };
    mdtf_volume::write(path, &mf, &WriteOptions { ty, gzip: false }, &[])?;
    Ok(())
}

/// [`encode`] then [`write`].
pub fn pack(
    channels: &[(String, Volume)],
    params: &PackParams,
    luts: &[Lut],
    dir: &Path,
    provenance: Provenance,
    sources: &BTreeMap<String, ChannelSource>,
) -> Result<Manifest, PackError> {
    write(&encode(channels, params, sources)?, luts, dir, provenance)
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
