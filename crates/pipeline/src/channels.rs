//! Named per-voxel channels computed in process from a value volume: what
//! `mdtf histogram` and later the pack stage ask for by name.

use crate::boundary_chain::{self, BoundaryChainParams, ChainError};
use mdtf_derive::{DeriveParams, Item};
use mdtf_volume::{MultiField, Volume};

/// Channel names computed from a value volume (fields of a multi-field input are channels too).
pub const CHANNEL_NAMES: &str = "v, g, f2, nx, ny, nz, inv_g, gnorm, g_hit, hit, distance";

/// Computes the named channels of `input`: its fields by name (`v` is the
/// first field), `g` and `f2` by the derive stage, `g_hit`, `hit` and
/// `distance` by the boundary chain. Unknown names are an error listing the valid ones.
pub fn compute(
    input: &MultiField,
    names: &[String],
    chain: &BoundaryChainParams,
) -> Result<Vec<(String, Volume)>, ChainError> {
    let kernel = chain.kernel;
    let value = input.field_volume(0).ok_or_else(|| ChainError::Unknown("the input has no fields".into()))?;
    let needs = |n: &str| names.iter().any(|x| x == n);
    let tracing = needs("g_hit") || needs("hit") || needs("distance");
    // one derive pass serves both the derivative channels and the tracing,
    // computing only the items asked for (each is a full volume)
    let mut items = Vec::new();
    for (item, wanted) in [
        (Item::G, tracing || needs("g")),
        (Item::F2, tracing || needs("f2")),
        (Item::Normal, tracing || ["nx", "ny", "nz"].iter().any(|n| needs(n))),
        (Item::InvG, needs("inv_g")),
    ] {
        if wanted {
            items.push(item);
        }
    }
    let derived = if !items.is_empty() {
        let d = DeriveParams { items, kernel: kernel.unwrap_or(mdtf_derive::DEFAULT_KERNEL), ..Default::default() };
        Some(mdtf_derive::run(&MultiField::from(value.clone()), &d)?)
    } else {
        None
    };
    let gnorm = if needs("gnorm") && input.fields.len() > 1 {
        let d = DeriveParams {
            items: vec![Item::Gnorm],
            kernel: kernel.unwrap_or(mdtf_derive::DEFAULT_KERNEL),
            ..Default::default()
        };
        mdtf_derive::run(input, &d)?.items.into_iter().next().and_then(|(_, m)| m.field_volume(0))
    } else {
        None
    };
    let traced = match &derived {
        Some(d) if tracing => {
            let field = |item: Item, i: usize| {
                d.get(item)
                    .and_then(|m| m.field_volume(i))
                    .ok_or_else(|| ChainError::Unknown(format!("derive gave no {item}")))
            };
            let normal =
                d.get(Item::Normal).cloned().ok_or_else(|| ChainError::Unknown("derive gave no normal".into()))?;
            let range = value.finite_range().map_or(0.0, |(lo, hi)| (hi - lo) as f64);
            Some(boundary_chain::trace_derived(field(Item::G, 0)?, field(Item::F2, 0)?, normal, range, chain)?)
        }
        _ => None,
    };
    let mut out = Vec::new();
    for name in names {
        let v = if let Some(i) = input.fields.iter().position(|f| &f.name == name) {
            input.field_volume(i)
        } else {
            match (name.as_str(), &derived, &traced) {
                ("v", _, _) => Some(value.clone()),
                ("g", Some(d), _) => d.get(Item::G).and_then(|m| m.field_volume(0)),
                ("f2", Some(d), _) => d.get(Item::F2).and_then(|m| m.field_volume(0)),
                ("nx", Some(d), _) => d.get(Item::Normal).and_then(|m| m.field_volume(0)),
                ("ny", Some(d), _) => d.get(Item::Normal).and_then(|m| m.field_volume(1)),
                ("nz", Some(d), _) => d.get(Item::Normal).and_then(|m| m.field_volume(2)),
                ("inv_g", Some(d), _) => d.get(Item::InvG).and_then(|m| m.field_volume(0)),
                ("gnorm", _, _) => gnorm.clone(),
                ("g_hit", _, Some(t)) => Some(t.boundary.g_hit.clone()),
                ("hit", _, Some(t)) => Some(t.boundary.hit.clone()),
                ("distance", _, Some(t)) => Some(t.boundary.distance.clone()),
                _ => None,
            }
        };
        let fields: Vec<&str> = input.fields.iter().map(|f| f.name.as_str()).collect();
        let v = v.ok_or_else(|| {
            ChainError::Unknown(format!(
                "unknown channel '{name}' (valid: {CHANNEL_NAMES}, or a field: {})",
                fields.join(", ")
            ))
        })?;
        out.push((name.clone(), v));
    }
    Ok(out)
}
