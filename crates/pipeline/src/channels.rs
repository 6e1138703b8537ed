//! Named per-voxel channels computed in process from a value volume: what
//! `mdtf histogram` and later the pack stage ask for by name.

use crate::boundary_chain::{self, BoundaryChainParams, ChainError};
use crate::plan::Plan;
use mdtf_derive::DeriveParams;
use mdtf_volume::{MultiField, Volume};
use std::collections::BTreeMap;

pub use crate::channel::CHANNEL_NAMES;

/// Computes the named channels of `input`: its fields by name (`v` is the
/// first field), `g` and `f2` by the derive stage, `g_hit`, `hit` and
/// `distance` by the boundary chain: plans them ([`Plan::for_channels`])
/// and runs the plan on the whole volume. Unknown names are
/// an error listing the valid ones, before any work.
pub fn compute(
    input: &MultiField,
    names: &[String],
    chain: &BoundaryChainParams,
) -> Result<Vec<(String, Volume)>, ChainError> {
    let field_names: Vec<String> = input.fields.iter().map(|f| f.name.clone()).collect();
    let plan = Plan::for_channels(names, &field_names, &input.geometry, chain)
        .map_err(|e| ChainError::Unknown(e.to_string()))?;
    execute(&plan, input, names, chain)
}

/// Runs `plan` (from [`Plan::for_channels`] with `names` and `chain`) on the
/// whole of `input`: the channels `names`, in that order.
fn execute(
    plan: &Plan,
    input: &MultiField,
    names: &[String],
    chain: &BoundaryChainParams,
) -> Result<Vec<(String, Volume)>, ChainError> {
    let kernel = chain.kernel;
    let Some(first) = input.fields.first() else {
        return Err(ChainError::Unknown("the input has no fields".into()));
    };
    let geometry = &input.geometry;
    let multi = input.fields.len() > 1;
    // one derive pass serves both the derivative channels and the tracing,
    // computing only the items the plan asks for (each is a full volume)
    let (items, multi_items, tracing) = (plan.derive.clone(), plan.derive_fields.clone(), plan.trace);
    let needs = |n: &str| names.iter().any(|x| x == n);
    // derived channels by name, moved out of the derive output (no copies)
    let mut derived: BTreeMap<String, Volume> = BTreeMap::new();
    if !items.is_empty() {
        let d = DeriveParams { items, kernel: kernel.unwrap_or(mdtf_derive::DEFAULT_KERNEL), ..Default::default() };
        let one_field;
        let value_input = if input.fields.len() == 1 {
            input
        } else {
            one_field = MultiField { geometry: geometry.clone(), fields: vec![first.clone()] };
            &one_field
        };
        // every output field is named after its component: g, f2, nx, ny, nz, inv_g
        derived.extend(mdtf_derive::run(value_input, &d)?.items.into_iter().flat_map(|(_, mf)| mf.into_volumes()));
    }
    // several fields: ||G|| and 1/g (from ||G||) in one pass over all of them
    if multi && !multi_items.is_empty() {
        let d = DeriveParams {
            items: multi_items,
            kernel: kernel.unwrap_or(mdtf_derive::DEFAULT_KERNEL),
            ..Default::default()
        };
        derived.extend(mdtf_derive::run(input, &d)?.items.into_iter().flat_map(|(_, mf)| mf.into_volumes()));
    }
    let traced = if tracing {
        // the tracing consumes g, f'' and the normal: copied only if they are asked for too
        let mut take = |c: &str| {
            let v = if needs(c) { derived.get(c).cloned() } else { derived.remove(c) };
            v.ok_or_else(|| ChainError::Unknown(format!("derive gave no {c}")))
        };
        let (g, f2) = (take("g")?, take("f2")?);
        let normal: Vec<(String, Volume)> =
            ["nx", "ny", "nz"].into_iter().map(|c| take(c).map(|v| (c.to_string(), v))).collect::<Result<_, _>>()?;
        let normal = MultiField::from_volumes(normal).map_err(|e| ChainError::Unknown(e.to_string()))?;
        let range = mdtf_volume::finite_sample_range(first.data.as_slice().unwrap_or(&[]))
            .map_or(0.0, |(lo, hi)| (hi - lo) as f64);
        Some(boundary_chain::trace_derived(g, f2, normal, range, chain)?.boundary)
    } else {
        None
    };
    let mut out: Vec<(String, Volume)> = Vec::with_capacity(names.len());
    for name in names {
        if let Some((_, v)) = out.iter().find(|(c, _)| c == name) {
            let v = v.clone();
            out.push((name.clone(), v));
            continue;
        }
        let v = if let Some(i) = input.fields.iter().position(|f| &f.name == name) {
            input.field_volume(i)
        } else {
            match (name.as_str(), &traced) {
                ("v", _) => input.field_volume(0),
                ("g_hit", Some(t)) => Some(t.g_hit.clone()),
                ("hit", Some(t)) => Some(t.hit.clone()),
                ("distance", Some(t)) => Some(t.distance.clone()),
                (other, _) => derived.remove(other),
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

#[cfg(test)]
mod tests {
    use super::*;
    use mdtf_datagen::erf_sphere;
    use mdtf_derive::Item;
    use mdtf_volume::Geometry;

    #[test]
    fn channels_equal_their_stages_outputs_in_the_order_asked() {
        let v = erf_sphere(Geometry::new([24; 3], [1.0; 3]), 7.0, 1.5, 0.0, 100.0, None).volume();
        let input = MultiField::from(v.clone());
        let names: Vec<String> = ["nz", "g", "v", "distance", "g", "f2"].iter().map(|s| s.to_string()).collect();
        let out = compute(&input, &names, &BoundaryChainParams::default()).unwrap();
        assert_eq!(out.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>(), names);
        // the same items from a direct derive call
        let d = DeriveParams { items: vec![Item::G, Item::F2, Item::Normal], ..Default::default() };
        let direct = mdtf_derive::run(&input, &d).unwrap();
        let comp = |item: Item, c: usize| direct.get(item).unwrap().fields[c].data.clone();
        assert_eq!(out[0].1.data, comp(Item::Normal, 2));
        assert_eq!(out[1].1.data, comp(Item::G, 0));
        assert_eq!(out[4].1.data, comp(Item::G, 0), "a channel asked for twice");
        assert_eq!(out[5].1.data, comp(Item::F2, 0));
        assert_eq!(out[2].1.data, v.data);
        // the tracing ran (its accuracy is mdtf-boundary's tests' business)
        assert!(out[3].1.data.iter().any(|&d| d > 0.0));
        let e = compute(&input, &["nope".to_string()], &BoundaryChainParams::default()).unwrap_err().to_string();
        assert!(e.contains("unknown channel 'nope'") && e.contains("distance"), "{e}");
    }
}
