//! Lookup tables (transfer-function textures and 1D/2D tables) written
//! beside the volume textures and listed in the manifest.

use mdtf_volume::VolumeError;
use mdtf_volume::nrrd::{TableAxis, write_table_bytes};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One axis of a lookup table: the channel it is indexed by and the range its cells cover.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LutAxis {
    /// Channel (v, g, f2, g_hit, distance ...).
    pub channel: String,
    /// Cells along the axis.
    pub size: usize,
    /// Lower edge of the first cell (channel units).
    pub min: f64,
    /// Upper edge of the last cell.
    pub max: f64,
}

impl LutAxis {
    /// The centre of cell `i` (channel units).
    pub fn centre(&self, i: usize) -> f64 {
        self.min + (i as f64 + 0.5) * (self.max - self.min) / self.size as f64
    }
}

/// A lookup table in memory: RGBA in [0, 1] or a single channel, first axis fastest.
#[derive(Debug, Clone, PartialEq)]
pub struct Lut {
    /// Name (file stem).
    pub name: String,
    /// What it holds.
    pub meaning: String,
    /// Axes, first fastest.
    pub axes: Vec<LutAxis>,
    /// 4 (RGBA) or 1 (a single value per cell).
    pub components: usize,
    /// Values, components fastest; in [0, 1] when `unit_range`.
    pub values: Vec<f32>,
    /// Values lie in [0, 1], so an 8-bit version (code / 255) is written too.
    pub unit_range: bool,
    /// Also write a 16-bit version with codes spanning [min, max]
    /// (value = min + code (max - min) / 65535), for renderers that want
    /// 16-bit tables (the Gaussian-TF paper's IGauss and erf tables).
    pub u16_range: Option<[f64; 2]>,
}

/// A table's 16-bit version: the file and its decode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct U16Table {
    /// NRRD, uint16, leading rgba axis when components = 4.
    pub file: String,
    /// value = offset + scale * code.
    pub offset: f64,
    /// See `offset`.
    pub scale: f64,
}

/// A written lookup table, as the manifest lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LutEntry {
    /// Name.
    pub name: String,
    /// What it holds.
    pub meaning: String,
    /// Axes, first fastest.
    pub axes: Vec<LutAxis>,
    /// Components per cell (4: RGBA).
    pub components: usize,
    /// The 8-bit version (code / 255), NRRD with an attached header, for tables of values in [0, 1].
    pub file_u8: Option<String>,
    /// The f32 version, NRRD with an attached header.
    pub file_f32: String,
    /// The 16-bit version, when the table has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u16: Option<U16Table>,
}

impl Lut {
    /// Writes `<name>_u8.nrrd` and `<name>_f32.nrrd` into `dir`.
    pub fn write(&self, dir: &Path) -> Result<LutEntry, VolumeError> {
        let mut axes: Vec<TableAxis> = Vec::new();
        if self.components > 1 {
            axes.push(TableAxis { label: "rgba".into(), size: self.components, min: 0.0, max: self.components as f64 });
        }
        axes.extend(self.axes.iter().map(|a| TableAxis {
            label: a.channel.clone(),
            size: a.size,
            min: a.min,
            max: a.max,
        }));
        let file_f32 = format!("{}_f32.nrrd", self.name);
        let file_u8 = if self.unit_range {
            let name = format!("{}_u8.nrrd", self.name);
            let u8s: Vec<u8> = self.values.iter().map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8).collect();
            write_table_bytes(&dir.join(&name), &axes, "uint8", &u8s)?;
            Some(name)
        } else {
            None
        };
        let f32s: Vec<u8> = self.values.iter().flat_map(|x| x.to_le_bytes()).collect();
        write_table_bytes(&dir.join(&file_f32), &axes, "float", &f32s)?;
        let u16 = match self.u16_range {
            Some([lo, hi]) => {
                let file = format!("{}_u16.nrrd", self.name);
                let scale = (hi - lo) / 65535.0;
                let codes: Vec<u8> = self
                    .values
                    .iter()
                    .flat_map(|&x| (((x as f64 - lo) / scale).round().clamp(0.0, 65535.0) as u16).to_le_bytes())
                    .collect();
                write_table_bytes(&dir.join(&file), &axes, "uint16", &codes)?;
                Some(U16Table { file, offset: lo, scale })
            }
            None => None,
        };
        Ok(LutEntry {
            name: self.name.clone(),
            meaning: self.meaning.clone(),
            axes: self.axes.clone(),
            components: self.components,
            file_u8,
            file_f32,
            u16,
        })
    }
}
