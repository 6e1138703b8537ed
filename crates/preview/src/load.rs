//! Reading a pack back from its manifest alone: channels decoded to f32
//! volumes (all of them, or only those a renderer reads), every lookup
//! table to its values.

use crate::PreviewError;
use crate::samples::{CodeTable, check_components};
use mdtf_pack::{ChannelEntry, Manifest, TextureEntry};
use mdtf_volume::{Geometry, Volume};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

/// A decoded lookup table.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// (channel, cells, min, max) per axis, first fastest.
    pub axes: Vec<(String, usize, f64, f64)>,
    /// Components per cell (4: RGBA).
    pub components: usize,
    /// Values, components fastest.
    pub values: Vec<f32>,
}

/// A pack in memory.
#[derive(Debug, Clone)]
pub struct LoadedPack {
    /// The manifest.
    pub manifest: Manifest,
    /// Decoded channels by name.
    pub channels: BTreeMap<String, Volume>,
    /// Lookup tables by name.
    pub tables: BTreeMap<String, Table>,
    /// Gaussian primitives (gaussian-tf packs with a `gaussians.json`).
    pub gaussians: Option<Vec<mdtf_pack::GaussianPrimitive>>,
}

/// The grid of a pack's textures, refused when it is degenerate, holds no
/// voxel or more than this machine can count.
pub(crate) fn pack_geometry(manifest: &Manifest) -> Result<Geometry, PreviewError> {
    let g = &manifest.geometry;
    let geometry = Geometry::from_affine(g.dims, [g.world_from_voxel[0], g.world_from_voxel[1], g.world_from_voxel[2]])
        .ok_or_else(|| PreviewError::Pack("manifest.json: degenerate world_from_voxel".into()))?;
    let voxels = g.dims.iter().try_fold(1usize, |n, &d| n.checked_mul(d)).ok_or_else(|| {
        PreviewError::Pack(format!("manifest.json: dims {:?} hold more voxels than this machine can count", g.dims))
    })?;
    if voxels == 0 {
        return Err(PreviewError::Pack(format!("manifest.json: dims {:?} hold no voxel", g.dims)));
    }
    Ok(geometry)
}

/// The channels of the pack in `dir` (described by `manifest`) that
/// `wanted` accepts, decoded to f32 volumes.
pub fn decode_channels(
    dir: &Path,
    manifest: &Manifest,
    wanted: &dyn Fn(&str) -> bool,
) -> Result<BTreeMap<String, Volume>, PreviewError> {
    let geometry = pack_geometry(manifest)?;
    let voxels = geometry.voxel_count();
    let mut channels = BTreeMap::new();
    for tex in &manifest.textures {
        // each channel from the first texture that holds it
        let entries: Vec<&ChannelEntry> = manifest
            .channels
            .iter()
            .filter(|c| c.texture == tex.name && wanted(&c.name) && !channels.contains_key(&c.name))
            .collect();
        if entries.is_empty() {
            continue;
        }
        for (name, data) in decode_texture(&pack_file(dir, &tex.data)?, tex, &entries, voxels)? {
            let array = ndarray::Array3::from_shape_vec(geometry.shape(), data)
                .map_err(|e| PreviewError::Pack(e.to_string()))?;
            channels.insert(name, Volume { geometry: geometry.clone(), data: array });
        }
    }
    Ok(channels)
}

/// Texels read at a time while streaming a texture (decoded in parallel).
const TEXELS_PER_READ: usize = 1 << 20;

/// Texels one thread decodes at a time.
const TEXELS_PER_TASK: usize = 1 << 14;

/// Decodes the channels `entries` of texture `tex` (`n` texels, file `path`)
/// to f32 values, reading the file in pieces.
fn decode_texture(
    path: &Path,
    tex: &TextureEntry,
    entries: &[&ChannelEntry],
    n: usize,
) -> Result<Vec<(String, Vec<f32>)>, PreviewError> {
    let size = tex.dtype.size();
    let texel = tex.components * size;
    check_components(tex, entries)?;
    let fail = |e: std::io::Error| PreviewError::Pack(format!("{}: {e}", path.display()));
    let mut file = std::fs::File::open(path).map_err(fail)?;
    let len = file.metadata().map_err(fail)?.len();
    let expected = n.checked_mul(texel).and_then(|b| u64::try_from(b).ok());
    if expected != Some(len) {
        return Err(PreviewError::Pack(format!(
            "{}: {len} bytes, the manifest describes {n} texels of {texel} bytes",
            tex.data
        )));
    }
    let tables: Vec<CodeTable> = entries.iter().map(|c| CodeTable::of(c, tex.dtype)).collect();
    let mut out: Vec<Vec<f32>> = entries.iter().map(|_| vec![0f32; n]).collect();
    let mut buf = vec![0u8; TEXELS_PER_READ.min(n) * texel];
    for start in (0..n).step_by(TEXELS_PER_READ) {
        let count = TEXELS_PER_READ.min(n - start);
        let piece = &mut buf[..count * texel];
        file.read_exact(piece).map_err(fail)?;
        let piece = &*piece;
        for ((ch, table), data) in entries.iter().zip(&tables).zip(out.iter_mut()) {
            let samples = table.samples(&piece[ch.component * size..], texel);
            data[start..start + count].par_chunks_mut(TEXELS_PER_TASK).enumerate().for_each(|(k, o)| {
                let first = k * TEXELS_PER_TASK;
                o.iter_mut().enumerate().for_each(|(i, o)| *o = samples.at(first + i));
            });
        }
    }
    Ok(entries.iter().map(|c| c.name.clone()).zip(out).collect())
}

/// `dir/name`, refused when a link takes it outside the pack folder (the
/// manifest check already refuses names that climb out).
pub(crate) fn pack_file(dir: &Path, name: &str) -> Result<PathBuf, PreviewError> {
    let path = dir.join(name);
    let (Ok(inside), Ok(root)) = (path.canonicalize(), dir.canonicalize()) else {
        return Ok(path); // missing: opening it reports the error with the name
    };
    if !inside.starts_with(&root) {
        return Err(PreviewError::Pack(format!("{name} is a link to {}, outside the pack folder", inside.display())));
    }
    Ok(path)
}

fn read(path: &Path) -> Result<Vec<u8>, PreviewError> {
    std::fs::read(path).map_err(|e| PreviewError::Pack(format!("{}: {e}", path.display())))
}

/// Reads `dir/manifest.json` and decodes everything it lists.
pub fn load(dir: &Path) -> Result<LoadedPack, PreviewError> {
    load_channels(dir, &|_| true)
}

/// [`load`], decoding only the channels `wanted` accepts (tables and
/// primitives are always read). Textures are decoded as they stream from
/// disk, so no texture is ever held whole in memory: the pack costs its
/// wanted channels as f32 and nothing more.
pub fn load_channels(dir: &Path, wanted: &dyn Fn(&str) -> bool) -> Result<LoadedPack, PreviewError> {
    let text = String::from_utf8(read(&dir.join("manifest.json"))?)
        .map_err(|_| PreviewError::Pack("manifest.json is not UTF-8".into()))?;
    let manifest: Manifest =
        serde_json::from_str(&text).map_err(|e| PreviewError::Pack(format!("manifest.json: {e}")))?;
    manifest.check().map_err(|e| PreviewError::Pack(e.to_string()))?;
    let channels = decode_channels(dir, &manifest, wanted)?;
    let mut tables = BTreeMap::new();
    for lut in &manifest.luts {
        // attached raw NRRD: the samples are the file's last cells x components x 4 bytes
        let bytes = read(&pack_file(dir, &lut.file_f32)?)?;
        let cells: usize = lut.axes.iter().map(|a| a.size).product();
        let comps = lut.components;
        if cells == 0 || !(1..=4).contains(&comps) {
            return Err(PreviewError::Pack(format!(
                "{}: {} components over axes of sizes {:?} (need 1 to 4 components and no empty axis)",
                lut.name,
                comps,
                lut.axes.iter().map(|a| a.size).collect::<Vec<_>>()
            )));
        }
        let len = cells * comps * 4;
        if bytes.len() < len {
            return Err(PreviewError::Pack(format!("{}: shorter than its {} samples", lut.file_f32, cells * comps)));
        }
        let values: Vec<f32> =
            bytes[bytes.len() - len..].chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        let axes = lut.axes.iter().map(|a| (a.channel.clone(), a.size, a.min, a.max)).collect();
        tables.insert(lut.name.clone(), Table { axes, components: comps, values });
    }
    let gaussians = match std::fs::read_to_string(dir.join("gaussians.json")) {
        Ok(text) => Some(serde_json::from_str(&text).map_err(|e| PreviewError::Pack(format!("gaussians.json: {e}")))?),
        Err(_) => None,
    };
    Ok(LoadedPack { manifest, channels, tables, gaussians })
}
