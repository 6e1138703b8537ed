//! The pack manifest: everything a renderer needs to decode the textures.

use crate::quantise::{Decode, Dtype};
use serde::{Deserialize, Serialize};

/// Schema identifier written into every manifest.
pub const SCHEMA_ID: &str = "mdtf-pack/1";

/// Grid geometry of the packed volume.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestGeometry {
    /// Samples along x, y, z.
    pub dims: [usize; 3],
    /// Spacing in world units.
    pub spacing: [f64; 3],
    /// World position of voxel (0, 0, 0).
    pub origin: [f64; 3],
    /// 4x4 voxel-to-world matrix (RAS), rows.
    pub world_from_voxel: [[f64; 4]; 4],
}

/// One texture file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TextureEntry {
    /// Texture name.
    pub name: String,
    /// Detached NRRD header, relative to the manifest.
    pub header: String,
    /// Raw samples, relative to the manifest: components fastest, then x, y, z, little-endian.
    pub data: String,
    /// Samples along x, y, z.
    pub dims: [usize; 3],
    /// Components per sample.
    pub components: usize,
    /// Channel in each component, in order (null: unused).
    pub component_order: Vec<Option<String>>,
    /// Storage type of every component.
    pub dtype: Dtype,
    /// The same codes as NIfTI-1 (one volume per component), when asked for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nifti: Option<String>,
}

/// Where a channel came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelSource {
    /// The mdtf stage that made it ("input", "derive", "boundary", ...).
    pub stage: String,
    /// That stage's parameters.
    pub params: serde_json::Value,
}

/// One channel: what it is and how to decode it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelEntry {
    /// Channel name.
    pub name: String,
    /// What it measures.
    pub meaning: String,
    /// Its units.
    pub units: String,
    /// Texture holding it.
    pub texture: String,
    /// Component index within the texture.
    pub component: usize,
    /// value = offset + scale * code (float dtypes: scale 1, offset 0, code = the stored float).
    pub decode: Decode,
    /// The range the codes cover, [decode(0), decode(max code)].
    pub range: [f64; 2],
    /// Its origin.
    pub source: ChannelSource,
}

/// Provenance of the pack.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Provenance {
    /// mdtf version that wrote the pack.
    pub mdtf_version: String,
    /// Input file or folder, as given (None: a built-in phantom, named in `stages`).
    pub input: Option<String>,
    /// SHA-256 of the input, hex (of a folder: see [`crate::sha256_path`]).
    pub input_sha256: Option<String>,
    /// The input's format as read, e.g. "NIfTI", "DICOM", "OME-Zarr".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_format: Option<String>,
    /// The input's grid, voxels (x, y, z).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_dims: Option<[usize; 3]>,
    /// The units the input states for its values and lengths (the
    /// channels' units follow: g in value units per length unit...).
    #[serde(default, skip_serializing_if = "mdtf_volume::Units::is_unknown")]
    pub input_units: mdtf_volume::Units,
    /// The pipeline file the run followed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pipeline: Option<String>,
    /// Parameters of every stage that ran (a run's pipeline with its
    /// `--set` overrides; its `input` says what was read).
    pub stages: serde_json::Value,
}

/// The whole manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`SCHEMA_ID`].
    pub schema: String,
    /// Profile name.
    pub profile: String,
    /// Geometry of the volume textures.
    pub geometry: ManifestGeometry,
    /// Texture files.
    pub textures: Vec<TextureEntry>,
    /// Channels.
    pub channels: Vec<ChannelEntry>,
    /// Lookup tables (transfer-function textures, 1D tables).
    #[serde(default)]
    pub luts: Vec<crate::lut::LutEntry>,
    /// The tetrahedral mesh of a `projected-tetrahedra` pack (absent for volume packs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<MeshEntry>,
    /// Provenance.
    pub provenance: Provenance,
}

/// The tetrahedral mesh of a `projected-tetrahedra` pack.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshEntry {
    /// Number of points (vertices).
    pub points: usize,
    /// Number of tetrahedra kept.
    pub tetrahedra: usize,
    /// Cells of other types skipped when reading, by VTK cell type.
    pub skipped_cells: std::collections::BTreeMap<String, usize>,
    /// Zero-volume tetrahedra skipped.
    pub degenerate_tetrahedra: usize,
    /// Longest edge (world units).
    pub max_edge_length: f64,
    /// How the per-vertex gradients were computed.
    pub gradient_method: String,
    /// The mesh with its point arrays (s, g, gradient) as VTK XML, relative to the manifest.
    pub vtu: String,
    /// The binary arrays.
    pub arrays: Vec<MeshArrayEntry>,
}

/// One binary array of a mesh pack: an NRRD file with an attached header,
/// components along the first (fastest) axis, one sample per point or cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshArrayEntry {
    /// Array name.
    pub name: String,
    /// What it holds, component by component.
    pub meaning: String,
    /// Units.
    pub units: String,
    /// "point" or "cell".
    pub association: String,
    /// Components per point or cell.
    pub components: usize,
    /// "f32", "u32" or "u8", little-endian.
    pub dtype: String,
    /// The NRRD file, relative to the manifest.
    pub file: String,
}

/// JSON Schema (draft 2020-12) of the manifest, printed by `mdtf pack --schema`.
pub const MANIFEST_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "$id": "mdtf-pack/1",
  "title": "mdtf texture pack manifest",
  "type": "object",
  "required": ["schema", "profile", "geometry", "textures", "channels", "luts", "provenance"],
  "properties": {
    "schema": {"const": "mdtf-pack/1"},
    "profile": {"enum": ["slicer-3dtf", "distance-tf", "gaussian-tf", "peak-finding", "projected-tetrahedra"]},
    "geometry": {
      "type": "object",
      "description": "the grid of the volume textures; projected-tetrahedra packs: the grid the mesh was made from, or for meshes read from files their bounding box as a 2x2x2 grid",
      "required": ["dims", "spacing", "origin", "world_from_voxel"],
      "properties": {
        "dims": {"type": "array", "items": {"type": "integer", "minimum": 1}, "minItems": 3, "maxItems": 3},
        "spacing": {"type": "array", "items": {"type": "number", "exclusiveMinimum": 0}, "minItems": 3, "maxItems": 3},
        "origin": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3},
        "world_from_voxel": {"type": "array", "minItems": 4, "maxItems": 4,
          "items": {"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4}}
      }
    },
    "textures": {"type": "array", "items": {
      "type": "object",
      "required": ["name", "header", "data", "dims", "components", "component_order", "dtype"],
      "properties": {
        "name": {"type": "string"},
        "header": {"type": "string", "description": "detached NRRD header (.nhdr), relative to the manifest"},
        "data": {"type": "string", "description": "raw little-endian samples, components fastest, then x, y, z"},
        "dims": {"type": "array", "items": {"type": "integer", "minimum": 1}},
        "components": {"type": "integer", "minimum": 1, "maximum": 4},
        "component_order": {"type": "array", "items": {"type": ["string", "null"]}},
        "dtype": {"enum": ["u8", "u16", "f16", "f32"]},
        "nifti": {"type": "string", "description": "optional NIfTI-1 copy: a 4D volume, one component per volume, the same codes"}
      }
    }},
    "channels": {"type": "array", "items": {
      "type": "object",
      "required": ["name", "meaning", "units", "texture", "component", "decode", "range", "source"],
      "properties": {
        "name": {"type": "string"},
        "meaning": {"type": "string"},
        "units": {"type": "string"},
        "texture": {"type": "string"},
        "component": {"type": "integer", "minimum": 0},
        "decode": {"type": "object", "required": ["offset", "scale"],
          "description": "value = offset + scale * code; for f16/f32 textures the code is the stored float, offset 0, scale 1",
          "properties": {"offset": {"type": "number"}, "scale": {"type": "number"}}},
        "range": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2},
        "source": {"type": "object", "required": ["stage", "params"],
          "properties": {"stage": {"type": "string"}, "params": {}}}
      }
    }},
    "luts": {"type": "array", "items": {
      "type": "object",
      "required": ["name", "meaning", "axes", "components", "file_f32"],
      "properties": {
        "name": {"type": "string"},
        "meaning": {"type": "string"},
        "axes": {"type": "array", "description": "first axis fastest; cell i covers [min + i w, min + (i + 1) w)",
          "items": {"type": "object", "required": ["channel", "size", "min", "max"],
            "properties": {"channel": {"type": "string"}, "size": {"type": "integer", "minimum": 1},
              "min": {"type": "number"}, "max": {"type": "number"}}}},
        "components": {"type": "integer", "description": "4: RGBA (colour 0..1, opacity 0..1), 1: one value"},
        "file_u8": {"type": ["string", "null"], "description": "NRRD, uint8, value = code / 255, leading rgba axis when components = 4; null for tables not in [0, 1]"},
        "file_f32": {"type": "string", "description": "NRRD, float, the same values"},
        "u16": {"type": "object", "required": ["file", "offset", "scale"],
          "description": "optional 16-bit version: NRRD, uint16, value = offset + scale * code",
          "properties": {"file": {"type": "string"}, "offset": {"type": "number"}, "scale": {"type": "number"}}}
      }
    }},
    "mesh": {"type": "object", "description": "projected-tetrahedra packs only",
      "required": ["points", "tetrahedra", "skipped_cells", "degenerate_tetrahedra", "max_edge_length", "gradient_method", "vtu", "arrays"],
      "properties": {
        "points": {"type": "integer", "minimum": 0},
        "tetrahedra": {"type": "integer", "minimum": 1},
        "skipped_cells": {"type": "object", "additionalProperties": {"type": "integer"}},
        "degenerate_tetrahedra": {"type": "integer", "minimum": 0},
        "max_edge_length": {"type": "number"},
        "gradient_method": {"type": "string"},
        "vtu": {"type": "string"},
        "arrays": {"type": "array", "items": {"type": "object",
          "required": ["name", "meaning", "units", "association", "components", "dtype", "file"],
          "properties": {"name": {"type": "string"}, "meaning": {"type": "string"}, "units": {"type": "string"},
            "association": {"enum": ["point", "cell"]}, "components": {"type": "integer", "minimum": 1},
            "dtype": {"enum": ["f32", "u32", "u8"]}, "file": {"type": "string"}}}}
      }
    },
    "provenance": {"type": "object", "required": ["mdtf_version", "stages"],
      "properties": {
        "mdtf_version": {"type": "string"},
        "input": {"type": ["string", "null"]},
        "input_sha256": {"type": ["string", "null"]},
        "input_format": {"type": "string"},
        "input_dims": {"type": "array", "items": {"type": "integer", "minimum": 1}, "minItems": 3, "maxItems": 3},
        "input_units": {"type": "object", "properties": {"value": {"type": "string"}, "length": {"type": "string"}}},
        "pipeline": {"type": "string"},
        "stages": {"type": "object"}
      }}
  }
}
"##;
