//! What a reader may rely on in a manifest, checked before any file it names
//! is opened: the schema version, file paths that stay inside the pack
//! folder, channels that name existing texture components, decodes that do
//! not collapse every code to one value, finite geometry, and table and
//! texture sizes whose products fit in memory arithmetic.

use crate::manifest::{Manifest, SCHEMA_ID};
use std::path::{Component, Path};

/// A manifest that a reader must not trust, with the reason in words.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("manifest.json: {0}")]
pub struct ManifestError(pub String);

fn bad(message: String) -> Result<(), ManifestError> {
    Err(ManifestError(message))
}

/// Refuses a path that is absolute or climbs out of the pack folder.
fn inside_pack(what: &str, path: &str) -> Result<(), ManifestError> {
    let p = Path::new(path);
    let escapes = p.components().any(|c| !matches!(c, Component::Normal(_) | Component::CurDir));
    if path.is_empty() || escapes {
        return bad(format!("{what} '{path}' is not a file name inside the pack folder"));
    }
    Ok(())
}

impl Manifest {
    /// Checks the manifest as a renderer would need it (see the module doc).
    pub fn check(&self) -> Result<(), ManifestError> {
        if self.schema != SCHEMA_ID {
            return bad(format!("schema '{}' is not one this mdtf reads ('{SCHEMA_ID}')", self.schema));
        }
        let g = &self.geometry;
        if g.dims.contains(&0) {
            return bad(format!("geometry dims {:?} hold no voxel", g.dims));
        }
        if g.dims.iter().try_fold(1usize, |n, &d| n.checked_mul(d)).is_none() {
            return bad(format!("geometry dims {:?} hold more voxels than this machine can count", g.dims));
        }
        if !g.spacing.iter().all(|s| s.is_finite() && *s > 0.0) {
            return bad(format!("geometry spacing {:?} must be positive and finite", g.spacing));
        }
        if !(g.origin.iter().all(|v| v.is_finite()) && g.world_from_voxel.iter().flatten().all(|v| v.is_finite())) {
            return bad("geometry origin and world_from_voxel must be finite numbers".into());
        }
        for t in &self.textures {
            inside_pack(&format!("texture {} header", t.name), &t.header)?;
            inside_pack(&format!("texture {} data", t.name), &t.data)?;
            if let Some(n) = &t.nifti {
                inside_pack(&format!("texture {} nifti", t.name), n)?;
            }
            if !(1..=4).contains(&t.components) || t.component_order.len() != t.components {
                return bad(format!(
                    "texture {} has {} components and {} names in component_order (need 1 to 4, one name each)",
                    t.name,
                    t.components,
                    t.component_order.len()
                ));
            }
            if self.textures.iter().filter(|o| o.name == t.name).count() > 1 {
                return bad(format!("texture name {} appears twice", t.name));
            }
        }
        for c in &self.channels {
            let Some(t) = self.textures.iter().find(|t| t.name == c.texture) else {
                return bad(format!(
                    "channel {} names texture {}, which the manifest does not list",
                    c.name, c.texture
                ));
            };
            if c.component >= t.components {
                return bad(format!(
                    "channel {} is component {} of texture {}, which has {}",
                    c.name, c.component, t.name, t.components
                ));
            }
            let d = &c.decode;
            if !(d.offset.is_finite() && d.scale.is_finite() && d.scale != 0.0) {
                return bad(format!(
                    "channel {} decodes with offset {} and scale {}: the scale must be a non-zero finite number",
                    c.name, d.offset, d.scale
                ));
            }
        }
        for l in &self.luts {
            inside_pack(&format!("table {} file_f32", l.name), &l.file_f32)?;
            if let Some(f) = &l.file_u8 {
                inside_pack(&format!("table {} file_u8", l.name), f)?;
            }
            if let Some(u) = &l.u16 {
                inside_pack(&format!("table {} u16 file", l.name), &u.file)?;
            }
            let cells = l.axes.iter().try_fold(1usize, |n, a| n.checked_mul(a.size));
            let bytes = cells.and_then(|c| c.checked_mul(l.components)).and_then(|c| c.checked_mul(4));
            if l.axes.is_empty() || l.axes.iter().any(|a| a.size == 0) || bytes.is_none() {
                return bad(format!(
                    "table {} has axes of sizes {:?}: each must be at least 1 and their product must fit in memory",
                    l.name,
                    l.axes.iter().map(|a| a.size).collect::<Vec<_>>()
                ));
            }
            if !(1..=4).contains(&l.components) {
                return bad(format!("table {} has {} components (need 1 to 4)", l.name, l.components));
            }
            if let Some(a) = l.axes.iter().find(|a| !(a.min.is_finite() && a.max.is_finite() && a.max > a.min)) {
                return bad(format!(
                    "table {} axis {} spans [{}, {}]: need finite numbers with max > min",
                    l.name, a.channel, a.min, a.max
                ));
            }
        }
        if let Some(m) = &self.mesh {
            inside_pack("mesh vtu", &m.vtu)?;
            for a in &m.arrays {
                inside_pack(&format!("mesh array {}", a.name), &a.file)?;
            }
        }
        Ok(())
    }
}
