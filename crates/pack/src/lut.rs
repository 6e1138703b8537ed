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
        Ok(LutEntry {
            name: self.name.clone(),
            meaning: self.meaning.clone(),
            axes: self.axes.clone(),
            components: self.components,
            file_u8,
            file_f32,
        })
    }
}
