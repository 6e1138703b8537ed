//! What the pack stage needs besides the channels: code ranges with Teem
//! qbert's percentile clipping, and the profile's lookup tables from a TF
//! file or the defaults (the histogram volume's opacity, a distance alpha map).

use mdtf_boundary::AlphaMap;
use mdtf_histogram::{
    AxisSpec, ChannelStats, HistogramError, HistogramVolume, HvolParams, detect_boundaries, histogram_volume,
};
use mdtf_pack::{
    BoundaryArch, Lut, LutAxis, Profile, Tent, TfFile, boundary_alpha_u, boundary_isosurface_tf, boundary_tf,
    multi_field_isosurface_tf,
};
use mdtf_volume::Volume;
use std::collections::BTreeMap;

/// `hvol` when the caller has it, else the histogram volume of `v` (derived as `derive` says: kernel, padding).
fn hvol_or_computed<'a>(
    hvol: Option<&'a HistogramVolume>,
    v: &Volume,
    derive: &mdtf_derive::DeriveParams,
) -> Result<std::borrow::Cow<'a, HistogramVolume>, crate::error::StageError> {
    Ok(match hvol {
        Some(h) => std::borrow::Cow::Borrowed(h),
        None => std::borrow::Cow::Owned(hvol_of(v, derive)?),
    })
}

/// The histogram volume of the value volume `v`, its g and f'' derived
/// as `derive` says, slice by slice (the default TFs' source when the run has
/// no f'' left).
pub(crate) fn hvol_of(
    v: &Volume,
    derive: &mdtf_derive::DeriveParams,
) -> Result<HistogramVolume, crate::error::StageError> {
    let input = mdtf_volume::MultiField::from(v.clone());
    crate::hvol_streamed::histogram_volume_derived(&input, derive, &HvolParams::on_grid(v.geometry.spacing))
}

/// The arches of the boundaries found in the histogram volume of the value
/// volume `v` (`hvol` when the caller has it, else derived as `derive` says),
/// strongest first; with `fallback`, the fallback boundary when none is
/// found (see [`arches_of`]).
pub fn detected_arches(
    v: &Volume,
    hvol: Option<&HistogramVolume>,
    derive: &mdtf_derive::DeriveParams,
    fallback: bool,
) -> Result<Vec<BoundaryArch>, crate::error::StageError> {
    let hv = hvol_or_computed(hvol, v, derive)?;
    Ok(if fallback { arches_of(&hv) } else { arches_from(&detect_boundaries(&hv)) })
}

/// The arches of the boundaries found in `hv`, strongest first; when none
/// is found, the one fallback boundary placed by percentiles
/// ([`mdtf_histogram::fallback_boundary`]), so that every default TF shows
/// something (none only for a volume without a span of values).
fn arches_of(hv: &HistogramVolume) -> Vec<BoundaryArch> {
    let found = arches_from(&detect_boundaries(hv));
    if !found.is_empty() {
        return found;
    }
    mdtf_histogram::fallback_boundary(hv).map(|b| BoundaryArch { fallback: true, ..arch_of(&b) }).into_iter().collect()
}

/// The pack's arches of detected boundaries, in the same order.
pub fn arches_from(boundaries: &[mdtf_histogram::DetectedBoundary]) -> Vec<BoundaryArch> {
    boundaries.iter().map(arch_of).collect()
}

/// The pack's arch of one detected boundary (found, not a fallback).
fn arch_of(b: &mdtf_histogram::DetectedBoundary) -> BoundaryArch {
    BoundaryArch {
        v_low: b.v_low,
        v_high: b.v_high,
        g_peak: b.g_peak,
        core_voxels: b.core_voxels,
        g_floor: b.g_floor,
        meets_background: b.meets_background,
        v_low_spread: b.v_low_spread,
        v_high_spread: b.v_high_spread,
        fallback: false,
    }
}

/// Code ranges: the explicit ones; for g, f2 and g_hit the data range with
/// qbert's percentile clipping (0.002 % / 0.004 % each end); for distance
/// [-1, d_max] when the tracing's d_max is known (-1: no boundary), so that
/// its codes mean the same distances in every pack; for inv_g
/// [0, 100 / g_max] (1/g down to g = 1 % of its maximum: the boundaries
/// peak finding looks for keep their precision, homogeneous voxels, where
/// 1/g runs to 1/epsilon, share the top code); other channels are left to
/// the pack stage (their min and max).
pub fn ranges(
    chans: &[(String, Volume)],
    explicit: &BTreeMap<String, [f64; 2]>,
    d_max: Option<f64>,
) -> Result<BTreeMap<String, [f64; 2]>, HistogramError> {
    let mut out = explicit.clone();
    for (name, v) in chans {
        if out.contains_key(name) {
            continue;
        }
        let stats = || ChannelStats::of(v.samples(), AxisSpec::qbert(name).clip_percent);
        if let Some(r) = range_of(name, stats, d_max)? {
            out.insert(name.clone(), r);
        }
        if name == "inv_g" {
            let smallest = smallest_positive(v.samples());
            if smallest.is_finite() {
                out.insert(name.clone(), inv_g_range(smallest));
            }
        }
    }
    Ok(out)
}

/// The smallest positive finite sample of `data` (infinity without one).
pub fn smallest_positive(data: &[f32]) -> f32 {
    data.iter().copied().filter(|&x| x > 0.0 && x.is_finite()).fold(f32::INFINITY, f32::min)
}

/// The code range of 1/g from its smallest positive sample (world units):
/// [0, 100 x smallest], so that g down to a hundredth of its largest keeps codes.
pub fn inv_g_range(smallest: f32) -> [f64; 2] {
    [0.0, 100.0 * smallest as f64]
}

/// [`ranges`]' rule for channel `name` from its statistics (`stats()`,
/// gathered with qbert's clip for the channel, asked for only when the rule
/// reads them): g, f2 and g_hit clipped, distance [-1, d_max]; None for the
/// channels whose range needs their samples (inv_g) or is the pack's.
pub fn range_of(
    name: &str,
    stats: impl FnOnce() -> ChannelStats,
    d_max: Option<f64>,
) -> Result<Option<[f64; 2]>, HistogramError> {
    Ok(match name {
        "distance" => d_max.map(|d| [mdtf_boundary::NO_BOUNDARY as f64, d]),
        "g" | "f2" | "g_hit" => {
            let axis = stats().axis(&AxisSpec { bins: Some(256), ..AxisSpec::qbert(name) }, name)?;
            Some([axis.min, axis.max])
        }
        _ => None,
    })
}

/// The lookup tables of `profile`: from `tf` when given; otherwise for
/// slicer-3dtf the default TF of the boundaries found in the histogram
/// volume (`hvol` when the caller already has it, else computed, with
/// derivatives as `derive` says; see [`mdtf_pack::boundary_tf`]), or its plain
/// tent opacity where none is found. distance-tf always gets `alpha_d` from
/// `alpha` over [0, d_max], the paper's domain (the top of the distance's
/// code range; without one, the largest distance measured), and `alpha_u`
/// from `tf`, or without one from the boundaries found
/// ([`mdtf_pack::boundary_alpha_u`]). gaussian-tf gets the IGauss and
/// erf-difference tables. A product TF in `tf` gets one table per factor,
/// `product_k`, whichever the profile (its channels must be among `chans`).
/// Peak-finding packs without a TF get a tf2d over (v, 1/g) of thin
/// widgets at the boundaries found ([`mdtf_pack::boundary_isosurface_tf`]);
/// multi-field ones over (first field, 1/sqrt(||G||)), at the boundaries of
/// the first field ([`mdtf_pack::multi_field_isosurface_tf`]).
pub fn luts(
    profile: Profile,
    tf: Option<&TfFile>,
    alpha: &AlphaMap,
    chans: &[(String, Volume)],
    ranges: &BTreeMap<String, [f64; 2]>,
    hvol: Option<&HistogramVolume>,
    derive: &mdtf_derive::DeriveParams,
) -> Result<Vec<Lut>, crate::error::StageError> {
    let from = LutSources { tf, chans, ranges, hvol, derive };
    let mut out = match profile {
        Profile::Slicer3dtf => slicer_luts(&from)?,
        Profile::DistanceTf => distance_luts(&from, alpha)?,
        // the mesh pack's tables come from mdtf-tetra
        Profile::ProjectedTetrahedra => return Ok(Vec::new()),
        Profile::GaussianTf | Profile::PeakFinding => table_profile_luts(&from, profile)?,
    };
    // a product TF over any of the pack's channels, each factor a table
    // (peak finding's 2D factors at the 1024^2 its paper recommends)
    if let Some(product) = tf.and_then(|t| t.product.as_ref()) {
        let packed: Vec<String> = chans.iter().map(|(c, _)| c.clone()).collect();
        let cells = if profile == Profile::PeakFinding { 1024 } else { 256 };
        out.extend(product.luts(&packed, cells).map_err(HistogramError::BadAxis)?);
    }
    Ok(out)
}

/// What a profile's tables are made from (see [`luts`]).
#[derive(Clone, Copy)]
struct LutSources<'a> {
    tf: Option<&'a TfFile>,
    chans: &'a [(String, Volume)],
    ranges: &'a BTreeMap<String, [f64; 2]>,
    hvol: Option<&'a HistogramVolume>,
    derive: &'a mdtf_derive::DeriveParams,
}

/// Channel `n` of `chans`, if there.
fn named<'v>(chans: &'v [(String, Volume)], n: &str) -> Option<&'v Volume> {
    chans.iter().find(|(c, _)| c == n).map(|(_, v)| v)
}

/// slicer-3dtf's tables: the TF file's, else the default opacity over
/// (v, g) from the histogram volume (`hvol`, or counted from `chans`),
/// coloured at the boundaries it shows.
fn slicer_luts(from: &LutSources) -> Result<Vec<Lut>, crate::error::StageError> {
    let LutSources { tf, chans, hvol, .. } = *from;
    let get = |n: &str| named(chans, n);
    let mut out = Vec::new();
    match tf {
        Some(tf) => out.extend(tf.slicer_luts()),
        None => {
            let computed;
            let hv = match hvol {
                Some(h) => h,
                None => {
                    let (Some(v), Some(g), Some(f2)) = (get("v"), get("g"), get("f2")) else {
                        return Err(HistogramError::Degenerate("the default opacity needs v, g and f2".into()).into());
                    };
                    computed = histogram_volume(
                        v.samples(),
                        g.samples(),
                        f2.samples(),
                        v.plane_len(),
                        &HvolParams::on_grid(v.geometry.spacing),
                    )?;
                    &computed
                }
            };
            let [av, ag] = &hv.vg_axes;
            let axis =
                |c: &str, a: &mdtf_histogram::Axis| LutAxis { channel: c.into(), size: a.bins, min: a.min, max: a.max };
            let (v_axis, g_axis) = (axis("v", av), axis("g", ag));
            let arches = arches_of(hv);
            if arches.is_empty() {
                out.push(Lut {
                            name: "tf2d_default".into(),
                            meaning: format!(
                                "opacity over (v, g): tent of half-width {:.4} around p(v, g) = 0 (Kindlmann-Durkin, sigma {:.4}); colour white (no boundary found to colour)",
                                hv.tent_width, hv.sigma
                            ),
                            axes: vec![v_axis, g_axis],
                            components: 4,
                            values: hv.opacity.iter().flat_map(|&a| [1.0, 1.0, 1.0, a]).collect(),
                            unit_range: true,
                            u16_range: None,
                        });
            } else {
                let spacing = chans.first().map_or(1.0, |(_, v)| v.geometry.min_spacing());
                let tent =
                    Tent { opacity: &hv.opacity, peak: hv.max_opacity, half_width_voxels: hv.tent_width / spacing };
                out.push(boundary_tf(&v_axis, &g_axis, tent, &arches));
            }
        }
    }
    Ok(out)
}

/// distance-tf's tables: `alpha_d` from `alpha`, and `alpha_u` from the
/// TF file or, without one, from the boundaries the histogram volume shows.
fn distance_luts(from: &LutSources, alpha: &AlphaMap) -> Result<Vec<Lut>, crate::error::StageError> {
    let LutSources { tf, chans, ranges, hvol, derive } = *from;
    let get = |n: &str| named(chans, n);
    let mut out = Vec::new();

    let d_max = ranges
        .get("distance")
        .map(|r| r[1])
        .or_else(|| get("distance").and_then(|d| d.finite_range()).map(|r| r.1 as f64));
    let d_max = d_max.filter(|d| *d > 0.0).unwrap_or(15.0);
    out.push(Lut {
        name: "alpha_d".into(),
        meaning: format!("opacity over the distance to the boundary: {alpha} (distance paper eqs. 9-11)"),
        axes: vec![LutAxis { channel: "distance".into(), size: 256, min: 0.0, max: d_max }],
        components: 1,
        values: (0..256).map(|k| alpha.eval((k as f64 + 0.5) * d_max / 256.0, d_max) as f32).collect(),
        unit_range: true,
        u16_range: None,
    });
    if let Some(tf) = tf {
        out.push(tf.distance_alpha_u());
    } else if let Some(v) = get("v") {
        // without a TF: alpha_u from the boundaries the histogram volume shows
        let hv = hvol_or_computed(hvol, v, derive)?;
        let arches = arches_of(&hv);
        if !arches.is_empty() {
            let spacing = v.geometry.min_spacing();
            let cells = 256;
            let step = d_max / cells as f64;
            let alpha_d_voxels =
                2.0 * (0..cells).map(|k| alpha.eval((k as f64 + 0.5) * step, d_max) * step).sum::<f64>() / spacing;
            let [av, _] = &hv.vg_axes;
            let g_top = arches.iter().map(|a| 1.3 * a.g_peak).fold(0.0, f64::max);
            let v_axis = LutAxis { channel: "v".into(), size: 256, min: av.min, max: av.max };
            let g_axis = LutAxis { channel: "g_hit".into(), size: 256, min: 0.0, max: g_top };
            out.push(boundary_alpha_u(&v_axis, &g_axis, alpha_d_voxels, &arches));
        }
    }

    Ok(out)
}

/// gaussian-tf's and peak-finding's tables: the analytic integration
/// tables (gaussian-tf), the TF file's tables, and peak-finding's tf2d over
/// (v, 1/g): the TF file's, else the default at the boundaries found.
fn table_profile_luts(from: &LutSources, profile: Profile) -> Result<Vec<Lut>, crate::error::StageError> {
    let LutSources { tf, chans, ranges, hvol, derive } = *from;
    let get = |n: &str| named(chans, n);
    let mut out = Vec::new();

    if profile == Profile::GaussianTf {
        out.extend(crate::gaussians::analytic_integration_tables());
    }
    if let Some(tf) = tf {
        let step = chans.first().map_or(1.0, |(_, v)| v.geometry.min_spacing());
        out.extend(tf.table_luts(step));
        // peak-finding: the widgets over (v, 1/g) for multidimensional peak finding
        if profile == Profile::PeakFinding
            && let Some(r) = ranges.get("inv_g")
            && let Some(lut) = tf.peak_finding_tf2d(*r, [1024, 1024])
        {
            out.push(lut);
        }
    } else if profile == Profile::PeakFinding
        && let (Some(v), Some(r)) = (get("v"), ranges.get("inv_g"))
    {
        // scalar data without a TF: a thin widget at each boundary the histogram volume shows
        let hv = hvol_or_computed(hvol, v, derive)?;
        let arches = arches_of(&hv);
        let default = boundary_isosurface_tf(&arches, [hv.vg_axes[0].min, hv.vg_axes[0].max]);
        if let Some(mut lut) = default.peak_finding_tf2d(*r, [1024, 1024]) {
            lut.meaning = format!(
                "{}; the default TF: a thin constant rectangle at the centre value of each boundary found in the \
                 histogram volume ({} found), its colour and surface opacity as slicer-3dtf's default gives them",
                lut.meaning,
                arches.len()
            );
            out.push(lut);
        }
    } else if profile == Profile::PeakFinding
        && let Some(r) = ranges.get("inv_g")
        && let Some((name, first)) = chans.first().filter(|(c, _)| c != "inv_g")
        && let Some((lo, hi)) = first.finite_range()
    {
        // multi-field data without a TF: thin widgets at the boundaries of the first field
        let arches = detected_arches(first, None, derive, true)?;
        let (lo, hi) = (lo as f64, hi as f64);
        let default = multi_field_isosurface_tf(&arches, [lo, hi], hi - lo);
        if let Some(mut lut) = default.peak_finding_tf2d(*r, [1024, 1024]) {
            lut.axes[0].channel = name.clone();
            lut.meaning = format!(
                "RGBA over ({name}, inv_g), for multidimensional peak finding; the default TF: a thin constant \
                 rectangle at the centre value of each boundary found in the histogram volume of {name} ({} \
                 found), open towards small inv_g (the other fields only raise ||G||), its colour and surface \
                 opacity as slicer-3dtf's default gives them",
                arches.len()
            );
            out.push(lut);
        }
    }
    Ok(out)
}
