//! The parts of OME-Zarr's `multiscales` metadata mdtf reads and writes
//! (NGFF 0.4 and 0.5 share them), and mdtf's own attributes beside them.
//!
//! Scales and translations are kept as f64: a spacing of 0.7 mm written by
//! another tool reads back as 0.7, not as its nearest f32.

use serde::{Deserialize, Serialize};

/// One axis of a multiscale image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Axis {
    /// "x", "y", "z", "c", "t" or the writer's own name.
    pub name: String,
    /// "space", "channel", "time" or a custom type.
    #[serde(rename = "type", default, skip_serializing_if = "Option::is_none")]
    pub kind: Option<String>,
    /// Unit of the axis, e.g. "micrometer" or "millimeter".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
}

/// A coordinate transformation: indices to physical coordinates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum Transform {
    /// No change.
    Identity,
    /// Multiply each axis by its factor.
    Scale {
        /// One factor per axis.
        scale: Vec<f64>,
    },
    /// Add an offset to each axis.
    Translation {
        /// One offset per axis.
        translation: Vec<f64>,
    },
}

/// One resolution level: its array and its transformations.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Dataset {
    /// The array's path within the group.
    pub path: String,
    /// Scale, then an optional translation.
    #[serde(rename = "coordinateTransformations")]
    pub transforms: Vec<Transform>,
}

/// One multiscale image: its axes and its levels, finest first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Multiscale {
    /// NGFF 0.4 names its version here; 0.5 in the `ome` object around it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub version: Option<String>,
    /// The image's name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The axes, slowest first (t, c, z, y, x).
    pub axes: Vec<Axis>,
    /// The resolution levels.
    pub datasets: Vec<Dataset>,
    /// Transformations applied after each level's own.
    #[serde(rename = "coordinateTransformations", default, skip_serializing_if = "Option::is_none")]
    pub transforms: Option<Vec<Transform>>,
}

/// What mdtf records beside the OME metadata (`attributes.mdtf`): OME-Zarr
/// has scale and translation only, so the full orientation is kept here.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MdtfAttributes {
    /// Voxel (i, j, k, 1) to world (RAS) of level 0, row-major 4x4.
    pub world_from_voxel: [[f64; 4]; 4],
    /// The fields' names, in the order of the channel axis.
    pub fields: Vec<String>,
}

impl Multiscale {
    /// Per axis, the scale and translation of level `level` composed with
    /// the image-wide ones (index -> physical: `scale * i + translation`).
    pub fn scale_and_translation(&self, level: usize) -> Result<(Vec<f64>, Vec<f64>), String> {
        let n = self.axes.len();
        let (mut scale, mut shift) = (vec![1.0; n], vec![0.0; n]);
        let own = self.datasets.get(level).map(|d| d.transforms.as_slice()).unwrap_or(&[]);
        for t in own.iter().chain(self.transforms.iter().flatten()) {
            match t {
                Transform::Identity => {}
                Transform::Scale { scale: s } if s.len() == n => {
                    for a in 0..n {
                        scale[a] *= s[a];
                        shift[a] *= s[a];
                    }
                }
                Transform::Translation { translation: t } if t.len() == n => {
                    for a in 0..n {
                        shift[a] += t[a];
                    }
                }
                _ => return Err(format!("a coordinate transformation does not have {n} values, one per axis")),
            }
        }
        if let Some(a) = (0..n).find(|&a| !(scale[a].is_finite() && scale[a] > 0.0 && shift[a].is_finite())) {
            return Err(format!(
                "axis {} has scale {} and translation {}: the scale must be positive and both finite",
                self.axes[a].name, scale[a], shift[a]
            ));
        }
        Ok((scale, shift))
    }
}

/// The multiscales of a group's attributes, NGFF 0.5 (`ome.multiscales`)
/// or 0.4 (`multiscales`), with the version found.
pub fn multiscales_of(
    attributes: &serde_json::Map<String, serde_json::Value>,
) -> Option<Result<(Vec<Multiscale>, String), String>> {
    let (value, version) = match attributes.get("ome") {
        Some(ome) => {
            let version = ome.get("version").and_then(|v| v.as_str()).unwrap_or("0.5").to_string();
            (ome.get("multiscales")?, version)
        }
        None => {
            let m = attributes.get("multiscales")?;
            let version = m.get(0).and_then(|m| m.get("version")).and_then(|v| v.as_str()).unwrap_or("0.4");
            (m, version.to_string())
        }
    };
    Some(Vec::<Multiscale>::deserialize(value).map(|m| (m, version)).map_err(|e| format!("bad multiscales: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_and_image_transformations_compose_in_order() {
        let m: Multiscale = serde_json::from_value(serde_json::json!({
            "axes": [{"name": "z", "type": "space"}, {"name": "y", "type": "space"}, {"name": "x", "type": "space"}],
            "datasets": [{"path": "0", "coordinateTransformations": [
                {"type": "scale", "scale": [2.0, 0.7, 0.7]}, {"type": "translation", "translation": [1.0, 0.0, -3.0]}]}],
            "coordinateTransformations": [{"type": "scale", "scale": [10.0, 1.0, 1.0]}]
        }))
        .unwrap();
        // z: 10 * (2 i + 1) = 20 i + 10
        let (s, t) = m.scale_and_translation(0).unwrap();
        assert_eq!((s, t), (vec![20.0, 0.7, 0.7], vec![10.0, 0.0, -3.0]));
    }

    #[test]
    fn both_versions_are_found_and_a_bad_scale_is_named() {
        let axes = serde_json::json!([{"name": "y"}, {"name": "x"}]);
        let ds =
            serde_json::json!([{"path": "s0", "coordinateTransformations": [{"type": "scale", "scale": [1.0, 0.0]}]}]);
        let v4 = serde_json::json!({"multiscales": [{"version": "0.4", "axes": axes, "datasets": ds}]});
        let v5 = serde_json::json!({"ome": {"version": "0.5", "multiscales": [{"axes": axes, "datasets": ds}]}});
        for (attrs, version) in [(v4, "0.4"), (v5, "0.5")] {
            let (m, v) = multiscales_of(attrs.as_object().unwrap()).unwrap().unwrap();
            assert_eq!(v, version);
            let e = m[0].scale_and_translation(0).unwrap_err();
            assert!(e.contains("axis x has scale 0"), "{e}");
        }
        assert!(multiscales_of(serde_json::json!({"other": 1}).as_object().unwrap()).is_none());
    }
}
