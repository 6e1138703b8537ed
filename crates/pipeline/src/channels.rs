//! Named per-voxel channels computed in process from a value volume: what
//! `mdtf derive`, `mdtf boundary`, `mdtf histogram` and `mdtf pack` ask
//! for by name, planned ([`Plan::for_channels`]) and run on the whole volume.

use crate::boundary_chain::{self, BoundaryChainParams, ChainError};
use crate::channel::Channel;
use crate::plan::Plan;
use crate::report::BoundarySummary;
use mdtf_derive::{DeriveError, Item};
use mdtf_volume::{MultiField, Volume};
use std::collections::BTreeMap;

pub use crate::channel::channel_names;

/// Called as the derive pass finishes z-slices: (done, of).
pub type Ticks<'a> = &'a (dyn Fn(usize, usize) + Sync);

/// What a command's channels came with.
#[derive(Debug)]
pub struct Computed {
    /// The channels asked for, in the order asked.
    pub channels: Vec<(String, Volume)>,
    /// What the tracing found, when it ran.
    pub tracing: Option<Tracing>,
}

/// What the tracing found besides its channels.
#[derive(Debug)]
pub struct Tracing {
    /// The thresholds it used and the voxels per hit code.
    pub summary: BoundarySummary,
    /// One sentence per boundary the thresholds took out.
    pub warnings: Vec<String>,
    /// d_max - d where a boundary was kept (when the tracing's `flipped` asks for it).
    pub flipped: Option<Volume>,
    /// (file name, alpha volume) per alpha map the tracing's parameters ask for.
    pub alpha: Vec<(String, Volume)>,
    /// The Fig. 2 report, over the g the tracing read (pre-filtered when the chain pre-filters).
    pub report: mdtf_boundary::Report,
}

/// Computes the named channels of `input`: its fields by name (`v` is the
/// first field), the derivatives by the derive stage, `g_hit`, `hit`,
/// `distance` and `dot` by the boundary chain. Unknown names are an error
/// listing the valid ones, before any work.
pub fn compute(
    input: &MultiField,
    names: &[String],
    chain: &BoundaryChainParams,
) -> Result<Vec<(String, Volume)>, ChainError> {
    Ok(compute_all(input, names, chain, &|_, _| {})?.channels)
}

/// [`compute`], with what the tracing found, calling `ticks` as the derive pass goes.
pub fn compute_all(
    input: &MultiField,
    names: &[String],
    chain: &BoundaryChainParams,
    ticks: Ticks,
) -> Result<Computed, ChainError> {
    let field_names: Vec<String> = input.fields.iter().map(|f| f.name.clone()).collect();
    let plan = Plan::for_channels(names, &field_names, &input.geometry, chain)
        .map_err(|e| ChainError::Unknown(e.to_string()))?;
    execute(&plan, input, names, chain, ticks)
}

/// The derive stage's `items` of `input`, each a multi-field volume of its
/// components (as [`mdtf_derive::run`] gives them), made as `chain` says
/// (kernel, border, epsilon) through the plan of their channels.
pub fn derive(
    input: &MultiField,
    items: &[Item],
    chain: &BoundaryChainParams,
    ticks: Ticks,
) -> Result<Vec<(Item, MultiField)>, ChainError> {
    let fields: Vec<String> = input.fields.iter().map(|f| f.name.clone()).collect();
    let per_item = item_channels(items, &fields)?;
    let names: Vec<String> = per_item.iter().flat_map(|(_, n)| n.iter().cloned()).collect();
    let mut made = compute_all(input, &names, chain, ticks)?.channels.into_iter();
    per_item
        .into_iter()
        .map(|(item, n)| {
            let mf = MultiField::from_volumes(made.by_ref().take(n.len()).collect());
            Ok((item, mf.map_err(|e| ChainError::Unknown(e.to_string()))?))
        })
        .collect()
}

/// The channels that hold the derive stage's `items` (each once, in the
/// order asked) of an input with these `fields` (several: the Jacobian's
/// components are named after them), item by item. Derive's rules on field
/// counts are checked here, before any input is derived.
pub fn item_channels(items: &[Item], fields: &[String]) -> Result<Vec<(Item, Vec<String>)>, ChainError> {
    let mut unique: Vec<Item> = Vec::with_capacity(items.len());
    for &i in items {
        if !unique.contains(&i) {
            unique.push(i);
        }
    }
    if unique.is_empty() {
        return Err(DeriveError::NoItems.into());
    }
    mdtf_derive::check_field_count(&unique, fields.len())?;
    let several: Vec<&str> = unique.iter().filter(|i| i.is_multi_field()).map(|i| i.name()).collect();
    if !several.is_empty() && fields.len() < 2 {
        let e = format!("items {} need several fields, the input has one", several.join(", "));
        return Err(DeriveError::FieldCount(e).into());
    }
    let names_of = |item: Item| -> Vec<String> {
        match item {
            Item::Jacobian => (0..fields.len())
                .flat_map(|field| (0..3).map(move |axis| Channel::Jacobian { field, axis }))
                .map(|c| c.name(fields))
                .collect(),
            other => other.components().iter().map(|c| c.to_string()).collect(),
        }
    };
    Ok(unique.into_iter().map(|i| (i, names_of(i))).collect())
}

/// Runs `plan` (from [`Plan::for_channels`] with `names` and `chain`) on the
/// whole of `input`: the channels `names`, in that order, and what the tracing found.
fn execute(
    plan: &Plan,
    input: &MultiField,
    names: &[String],
    chain: &BoundaryChainParams,
    ticks: Ticks,
) -> Result<Computed, ChainError> {
    let Some(first) = input.fields.first() else {
        return Err(ChainError::Unknown("the input has no fields".into()));
    };
    let geometry = &input.geometry;
    let value_range =
        mdtf_volume::finite_sample_range(first.data.as_slice().unwrap_or(&[])).map_or(0.0, |(lo, hi)| (hi - lo) as f64);
    if plan.trace {
        // the tracing's parameters are checked before the expensive stages
        let floor = mdtf_boundary::noise_floor(&[], value_range, geometry.min_spacing());
        mdtf_boundary::resolve(&chain.boundary, geometry, value_range, floor)?;
    }
    let needs = |n: &str| names.iter().any(|x| x == n);
    // one derive pass serves both the derivative channels and the tracing,
    // computing only the items the plan asks for; its outputs are named
    // after their components (g, f2, nx, gx, hxy, d{field}/dx, ...)
    let mut derived: BTreeMap<String, Volume> = BTreeMap::new();
    if !plan.derive.is_empty() {
        let one_field;
        let value_input = if input.fields.len() == 1 {
            input
        } else {
            one_field = MultiField { geometry: geometry.clone(), fields: vec![first.clone()] };
            &one_field
        };
        let out = mdtf_derive::run_with_progress(value_input, &chain.derive(plan.derive.clone()), None, ticks)?;
        derived.extend(out.items.into_iter().flat_map(|(_, mf)| mf.into_volumes()));
    }
    // ||G||, 1/g from it and the Jacobian, in one pass over all the fields
    if !plan.derive_fields.is_empty() {
        let out = mdtf_derive::run_with_progress(input, &chain.derive(plan.derive_fields.clone()), None, ticks)?;
        derived.extend(out.items.into_iter().flat_map(|(_, mf)| mf.into_volumes()));
    }
    let mut traced: BTreeMap<String, Volume> = BTreeMap::new();
    let tracing = match plan.trace {
        true => Some(trace(&mut derived, &needs, value_range, chain, &mut traced)?),
        false => None,
    };
    // a several-field input's fields by name (one field is "v": its name is not a channel's)
    let fields = &plan.fields;
    let mut channels: Vec<(String, Volume)> = Vec::with_capacity(names.len());
    for name in names {
        let v = if let Some((_, v)) = channels.iter().find(|(c, _)| c == name) {
            Some(v.clone())
        } else if let Some(i) = fields.iter().position(|f| f == name) {
            input.field_volume(i)
        } else if name == "v" {
            input.field_volume(0)
        } else {
            derived.remove(name).or_else(|| traced.remove(name))
        };
        let v = v.ok_or_else(|| match Channel::named(name, fields) {
            Err(unknown) => ChainError::Unknown(unknown.to_string()),
            Ok(_) => ChainError::Unknown(format!("the plan made no channel '{name}'")),
        })?;
        channels.push((name.clone(), v));
    }
    Ok(Computed { channels, tracing })
}

/// Traces the `derived` g, f'' and normal (taken out of it unless `needs`
/// them as channels too) as `chain` says, its volumes into `traced` by name.
fn trace(
    derived: &mut BTreeMap<String, Volume>,
    needs: &dyn Fn(&str) -> bool,
    value_range: f64,
    chain: &BoundaryChainParams,
    traced: &mut BTreeMap<String, Volume>,
) -> Result<Tracing, ChainError> {
    let mut take = |c: &str| {
        let v = if needs(c) { derived.get(c).cloned() } else { derived.remove(c) };
        v.ok_or_else(|| ChainError::Unknown(format!("derive gave no {c}")))
    };
    let (g, f2) = (take("g")?, take("f2")?);
    let normal: Vec<(String, Volume)> = crate::channel::NORMAL
        .map(|c| c.name(&[]))
        .into_iter()
        .map(|c| take(&c).map(|v| (c, v)))
        .collect::<Result<_, _>>()?;
    let normal = MultiField::from_volumes(normal).map_err(|e| ChainError::Unknown(e.to_string()))?;
    let out = boundary_chain::trace_derived(g, f2, normal, value_range, chain)?;
    let report = out.boundary.report(&out.g);
    let mut b = out.boundary;
    traced.extend(boundary_chain::take_traced(&mut b));
    let summary = BoundarySummary { resolved: b.resolved, counts: b.counts, lost: b.lost };
    Ok(Tracing { summary, warnings: b.warnings, flipped: b.flipped, alpha: b.alpha, report })
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
        let d = mdtf_derive::DeriveParams { items: vec![Item::G, Item::F2, Item::Normal], ..Default::default() };
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

    #[test]
    fn derived_items_through_the_plan_equal_a_direct_derive_call_bit_for_bit() {
        let geo = Geometry::new([20, 18, 16], [1.0, 1.2, 0.9]);
        let v = erf_sphere(geo.clone(), 6.0, 1.5, 0.0, 100.0, None).volume();
        let chain = BoundaryChainParams {
            kernel: mdtf_derive::Kernel::BSpline3,
            border: Some(mdtf_derive::Border::Mirror),
            epsilon: Some(0.5),
            ..Default::default()
        };
        let one = MultiField::from(v.clone());
        let items = [Item::Hessian, Item::Value, Item::Grad, Item::G, Item::Laplacian, Item::Shade, Item::Normal];
        let mut items = items.to_vec();
        items.extend([Item::F2, Item::InvG, Item::G]);
        let planned = derive(&one, &items, &chain, &|_, _| {}).unwrap();
        let direct = mdtf_derive::run(&one, &chain.derive(items.clone())).unwrap();
        assert_eq!(planned.len(), 9, "each item once, in the order asked");
        for ((pi, pm), (di, dm)) in planned.iter().zip(&direct.items) {
            assert_eq!(pi, di);
            assert_eq!(pm.fields.len(), dm.fields.len(), "{pi}");
            for (pf, df) in pm.fields.iter().zip(&dm.fields) {
                assert_eq!((&pf.name, &pf.data), (&df.name, &df.data), "{pi}");
            }
        }
        // several fields: the Jacobian's components named after the fields, and ||G||
        let w = Volume { geometry: geo.clone(), data: v.data.mapv(|x| (x * 0.07).sin()) };
        let two = MultiField::from_volumes(vec![("a".into(), v), ("b".into(), w)]).unwrap();
        let planned = derive(&two, &[Item::Jacobian, Item::Gnorm], &chain, &|_, _| {}).unwrap();
        let direct = mdtf_derive::run(&two, &chain.derive(vec![Item::Jacobian, Item::Gnorm])).unwrap();
        let names: Vec<&str> = planned[0].1.fields.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["da/dx", "da/dy", "da/dz", "db/dx", "db/dy", "db/dz"]);
        for ((_, pm), (_, dm)) in planned.iter().zip(&direct.items) {
            for (pf, df) in pm.fields.iter().zip(&dm.fields) {
                assert_eq!((&pf.name, &pf.data), (&df.name, &df.data));
            }
        }
        // derive's own rules on field counts
        let e = derive(&two, &[Item::G], &chain, &|_, _| {}).unwrap_err().to_string();
        assert!(e.contains("need one field, the input has 2"), "{e}");
        let e = derive(&one, &[Item::Gnorm], &chain, &|_, _| {}).unwrap_err().to_string();
        assert!(e.contains("gnorm need several fields"), "{e}");
    }

    #[test]
    fn the_tracing_s_summary_report_and_channels_come_with_what_was_asked() {
        let ph = erf_sphere(Geometry::new([32; 3], [1.0; 3]), 10.0, 1.5, 0.0, 255.0, None);
        let input = MultiField::from(ph.volume());
        let chain = BoundaryChainParams::default();
        let names: Vec<String> = ["distance", "dot", "hit", "v"].iter().map(|s| s.to_string()).collect();
        let all = compute_all(&input, &names, &chain, &|_, _| {}).unwrap();
        let t = all.tracing.expect("traced");
        let hits = all.channels[2].1.samples().iter().filter(|&&h| h == 1.0).count();
        assert_eq!(hits as u64, t.summary.counts.hits);
        // the report counts the hits past its own thresholds
        assert!(t.report.hits > 1000 && t.report.hits <= t.summary.counts.hits, "{}", t.report.hits);
        // the same tracing as the chain's own run
        let chained = boundary_chain::run(&ph.volume(), &chain).unwrap();
        assert_eq!(all.channels[0].1.data, chained.boundary.distance.data);
        assert_eq!(all.channels[1].1.data, chained.boundary.dot.data);
        assert!((t.report.mean_dot - chained.boundary.report(&chained.g).mean_dot).abs() < 1e-12);
        // the sphere's normals at a voxel and at its hit agree
        assert!(t.report.mean_dot > 0.99, "{}", t.report.mean_dot);
        assert!(compute_all(&input, &names[3..], &chain, &|_, _| {}).unwrap().tracing.is_none());
    }
}
