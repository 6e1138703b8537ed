//! Reading a pack back from its manifest alone: every channel decoded to
//! f32 volumes, every lookup table to its values.

use crate::PreviewError;
use mdtf_pack::{Dtype, Manifest};
use mdtf_volume::{Geometry, Volume};
use std::collections::BTreeMap;
use std::path::Path;

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

fn read(path: &Path) -> Result<Vec<u8>, PreviewError> {
    std::fs::read(path).map_err(|e| PreviewError::Pack(format!("{}: {e}", path.display())))
}

/// Reads `dir/manifest.json` and decodes everything it lists.
pub fn load(dir: &Path) -> Result<LoadedPack, PreviewError> {
    let text = String::from_utf8(read(&dir.join("manifest.json"))?)
        .map_err(|_| PreviewError::Pack("manifest.json is not UTF-8".into()))?;
    let manifest: Manifest =
        serde_json::from_str(&text).map_err(|e| PreviewError::Pack(format!("manifest.json: {e}")))?;
    let g = &manifest.geometry;
    let geometry = Geometry::from_affine(g.dims, [g.world_from_voxel[0], g.world_from_voxel[1], g.world_from_voxel[2]])
        .ok_or_else(|| PreviewError::Pack("manifest.json: degenerate world_from_voxel".into()))?;
    let n = geometry.voxel_count();
    let mut channels = BTreeMap::new();
    for tex in &manifest.textures {
        let bytes = read(&dir.join(&tex.data))?;
        let size = match tex.dtype {
            Dtype::U8 => 1,
            Dtype::U16 | Dtype::F16 => 2,
            Dtype::F32 => 4,
        };
        if bytes.len() != n * tex.components * size {
            return Err(PreviewError::Pack(format!(
                "{}: {} bytes, the manifest describes {}",
                tex.data,
                bytes.len(),
                n * tex.components * size
            )));
        }
        for ch in manifest.channels.iter().filter(|c| c.texture == tex.name) {
            if channels.contains_key(&ch.name) {
                continue;
            }
            let mut data = vec![0f32; n];
            for (i, o) in data.iter_mut().enumerate() {
                let at = (i * tex.components + ch.component) * size;
                let code = match size {
                    1 => bytes[at] as u32,
                    2 => u16::from_le_bytes([bytes[at], bytes[at + 1]]) as u32,
                    _ => u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]),
                };
                *o = ch.decode.value(code, tex.dtype) as f32;
            }
            let array = ndarray::Array3::from_shape_vec(geometry.shape(), data)
                .map_err(|e| PreviewError::Pack(e.to_string()))?;
            channels.insert(ch.name.clone(), Volume { geometry: geometry.clone(), data: array });
        }
    }
    let mut tables = BTreeMap::new();
    for lut in &manifest.luts {
        // attached raw NRRD: the samples are the file's last cells x components x 4 bytes
        let bytes = read(&dir.join(&lut.file_f32))?;
        let cells: usize = lut.axes.iter().map(|a| a.size).product();
        let comps = lut.components;
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
