//! The Gaussian primitives of a gaussian-tf pack (`gaussians.json`) and the
//! lookup tables a GPU renderer of the Gaussian-TF paper reads.
//!
//! The primitives come from, in order: the TF file's `gaussian` widgets; a
//! GTF fitted to the voxels of a mask (the paper's section 6: the mean and
//! covariance of a probed region); on scalar data, the boundaries found in
//! the histogram volume: one triangular GTF of the paper's form (K = 1) at
//! each boundary's isovalue ([`mdtf_pack::isovalue`]: its centre value, or
//! where fewer other boundaries pass), in its colour, with the extinction per
//! voxel that accumulates the boundary's surface opacity over the two world
//! units of path a head-on ray spends in it (see
//! [`mdtf_pack::boundary_opacities`]); on multi-field data, one Gaussian per
//! material found in the fields' joint histogram (see [`material_gaussians`]);
//! else the paper's default TF (section 3.2,
//! Fig. 5): one triangular GTF centred at each field's median, of width one
//! (K = 1 on scalar data, where v and g share value units, so it selects the
//! voxels within about one world unit of the median's isosurface;
//! K = diag(1 / range) on multi-field data, whose gradient measure is of the
//! fields normalised to [0, 1]), extinction 1 per voxel, white.
//!
//! The medians are taken over the voxels whose gradient (g, or gnorm) is
//! above twice its median, where there are at least 1 % of them. The
//! paper's weather simulation has structure everywhere, so there this is
//! nearly every voxel; in a scan or a phantom most voxels are homogeneous
//! background, and the plain median is the background's value: its
//! isosurface lies in the boundaries' far tails, where (v - c) / g stays
//! near 1 and the TGTF fills the volume with fog.

use mdtf_histogram::HistogramVolume;
use mdtf_pack::{
    BoundaryArch, ERF_DOMAIN, ERF_SIZE, GaussianPrimitive, IGAUSS_DOMAIN, IGAUSS_SIZE, Lut, LutAxis, TfFile,
    erf_difference_table, igauss_table,
};
use mdtf_volume::{Geometry, Volume};

/// World units of path a ray crossing a boundary head-on spends inside its
/// triangular GTF of width 1: |v - c| / g < 1 holds within about one world
/// unit on each side of the isosurface v = c.
pub const BOUNDARY_TGTF_PATH: f64 = 2.0;

/// The primitives of the pack: see the module docs. `fields` names the TF
/// axes (the input's fields, or "v" for scalar data), each a channel in `chans`.
/// `gradient` names the gradient channel (g or gnorm), used to pick the voxels the medians are over.
/// `boundaries_from` is the histogram volume when the caller has one (else
/// it is derived from the value, with the kernel) for the boundaries' TGTFs.
pub fn gaussians(
    tf: Option<&TfFile>,
    mask: Option<&Volume>,
    chans: &[(String, Volume)],
    fields: &[String],
    gradient: &str,
    boundaries_from: (Option<&HistogramVolume>, &mdtf_derive::DeriveParams),
) -> Result<Vec<GaussianPrimitive>, String> {
    if let Some(tf) = tf {
        return Ok(tf.gaussians());
    }
    let get = |n: &str| chans.iter().find(|(c, _)| c == n).map(|(_, v)| v).ok_or(format!("no channel '{n}'"));
    let data: Vec<&Volume> = fields.iter().map(|f| get(f)).collect::<Result<_, _>>()?;
    let samples: Vec<&[f32]> = data.iter().map(|v| v.samples()).collect();
    if let Some(mask) = mask {
        if !data.first().is_some_and(|v| v.geometry.same_grid(&mask.geometry)) {
            return Err(format!(
                "the mask ({}) is not on the input's grid ({})",
                mask.geometry.dims_string(),
                data.first().map_or_else(String::new, |v| v.geometry.dims_string())
            ));
        }
        let m = mask.samples();
        let p = GaussianPrimitive::fit(&samples, |i| m[i] > 0.0, 1.0, [1.0, 1.0, 1.0])
            .map_err(|e| format!("fitting a Gaussian to the mask: {e}"))?;
        return Ok(vec![p]);
    }
    if let [value] = &data[..] {
        let (hvol, derive) = boundaries_from;
        let arches = crate::pack_inputs::detected_arches(value, hvol, derive, false).map_err(|e| e.to_string())?;
        if !arches.is_empty() {
            return Ok(boundary_tgtfs(&arches, &value.geometry));
        }
    } else if let Some(first) = data.first() {
        let materials = material_gaussians(&samples, &first.geometry)?;
        if !materials.is_empty() {
            return Ok(materials);
        }
    }
    let g = get(gradient)?.samples();
    let mut centre = Vec::new();
    let mut ranges = Vec::new();
    for (a, s) in samples.iter().enumerate() {
        let m = median_at_large_g(s, g).ok_or(format!("channel '{}' has no finite sample", fields[a]))?;
        centre.push(m as f64);
        ranges.push(mdtf_volume::finite_sample_range(s).map_or(1.0, |(lo, hi)| (hi - lo) as f64));
    }
    Ok(vec![median_tgtf(centre, &ranges)])
}

/// The median of `values` over the samples whose gradient `g` exceeds twice
/// the gradient's median (over all samples when fewer than 1 % do): the
/// centre of the paper's default TGTF. None without a finite value.
pub(crate) fn median_at_large_g(values: &[f32], g: &[f32]) -> Option<f32> {
    let g_cut = 2.0 * mdtf_volume::median(g).unwrap_or(0.0);
    let structured = g.iter().filter(|&&x| x > g_cut).count();
    if structured * 100 < g.len() {
        return mdtf_volume::median(values);
    }
    let picked: Vec<f32> = values.iter().zip(g).filter(|(_, gv)| **gv > g_cut).map(|(v, _)| *v).collect();
    mdtf_volume::median(&picked)
}

/// The (s, g) TF of a mesh read from a file (no volume, no grid): the TF
/// file's Gaussians, else a TGTF at each boundary found in the (s, g)
/// histogram of its points (`s`, `g` per point; `spacing`, a typical edge
/// length in world units, turns the surface opacities into per-unit ones),
/// else the paper's median TGTF ([`median_at_large_g`] of the points).
pub fn mesh_gaussians(tf: Option<&TfFile>, s: &[f32], g: &[f32], spacing: f64) -> Vec<GaussianPrimitive> {
    if let Some(tf) = tf.filter(|t| !t.gaussians().is_empty()) {
        return tf.gaussians();
    }
    let axes = ["v", "g"].map(|name| mdtf_histogram::HvolAxes::spec(name, 256));
    let counted = match (axes[0].resolve("v", s), axes[1].resolve("g", g)) {
        (Ok(av), Ok(ag)) => mdtf_histogram::count(&[s, g], vec![av, ag], None).ok(),
        _ => None,
    };
    if let Some(h) = counted {
        let axes = [h.axes[0].clone(), h.axes[1].clone()];
        let found = mdtf_histogram::detect_in(&h.counts, &axes, 0.0).boundaries;
        if !found.is_empty() {
            let grid = Geometry::new([2, 2, 2], [spacing; 3]);
            return boundary_tgtfs(&crate::pack_inputs::arches_from(&found), &grid);
        }
    }
    vec![median_tgtf(vec![median_at_large_g(s, g).unwrap_or(0.0) as f64], &[1.0])]
}

/// Writes `g` as `gaussians.json` in the pack folder `pdir`, atomically.
pub fn write(pdir: &std::path::Path, g: &[GaussianPrimitive]) -> Result<(), mdtf_volume::VolumeError> {
    mdtf_volume::write_file_atomically(&pdir.join("gaussians.json"), |w| {
        serde_json::to_writer_pretty(w, g).map_err(std::io::Error::other)
    })
}

/// The paper's default triangular GTF, white and opaque at its centre: the
/// centre is each field's median over the voxels whose gradient exceeds
/// twice the gradient's median (over all voxels when fewer than 1 % do);
/// for several fields each axis is scaled by its field's finite range
/// (`ranges`, value units), for one field K = 1.
pub fn median_tgtf(centre: Vec<f64>, ranges: &[f64]) -> GaussianPrimitive {
    let m = centre.len();
    let mut k = vec![vec![0.0; m]; m];
    for (a, &range) in ranges.iter().enumerate().take(m) {
        k[a][a] = if m > 1 && range > 0.0 { 1.0 / range } else { 1.0 };
    }
    GaussianPrimitive { centre, k, alpha_max: 1.0, colour: [1.0, 1.0, 1.0], triangular: true }
}

/// One triangular GTF per boundary (see the module docs).
pub(crate) fn boundary_tgtfs(arches: &[BoundaryArch], geometry: &mdtf_volume::Geometry) -> Vec<GaussianPrimitive> {
    let spacing = geometry.spacing.iter().copied().fold(f64::INFINITY, f64::min);
    let per_voxel =
        mdtf_pack::per_voxel_opacities(&mdtf_pack::boundary_opacities(arches), BOUNDARY_TGTF_PATH / spacing.max(1e-12));
    arches
        .iter()
        .zip(per_voxel)
        .enumerate()
        .map(|(k, (_, alpha_max))| GaussianPrimitive {
            centre: vec![mdtf_pack::isovalue(arches, k)],
            k: vec![vec![1.0]],
            alpha_max,
            colour: mdtf_pack::boundary_colour(k, arches.len()),
            triangular: true,
        })
        .collect()
}

/// How many of a material Gaussian's standard deviations (Mahalanobis
/// distance) at least separate its centre from every other material's.
pub const SEPARATION_SIGMAS: f64 = 4.0;

/// One full Gaussian per material of a multi-field volume (`fields`: each
/// field's samples on `geometry`'s grid), largest material first; empty
/// when the data show no material but the background. The rule:
/// * the materials are the clusters of the fields' joint histogram
///   ([`mdtf_histogram::joint_clusters`]);
/// * the background, the material holding more than half of the voxels on
///   the volume's six faces (the air around a head, which every ray from
///   outside crosses first), gets no Gaussian;
/// * each other material's Gaussian has the spread of the voxels of its
///   core ([`GaussianPrimitive::fit_with_floor`]), each field's variance at
///   least that of a uniform spread over one histogram bin (width^2 / 12),
///   so a field that is constant in a material (0 outside a mask) still
///   gives a Gaussian; its centre is the mean of the voxels of its top;
///   where another material's centre (the background's too) lies within
///   [`SEPARATION_SIGMAS`] of its deviations, it is narrowed (K scaled)
///   until none does: a wide material (the tissues around a brain, from
///   fat to bone) would otherwise tint the background, which fills most
///   of the volume, as fog;
/// * its colour is [`mdtf_pack::boundary_colour`]'s k-th (white when alone);
/// * its opacity lets the materials inside show through: what a ray
///   crossing it accumulates is [`mdtf_pack::MAX_BOUNDARY_OPACITY`] for the
///   innermost materials (the deepest layer below the outside, see
///   [`crate::materials::MaterialShapes`]) and
///   [`mdtf_pack::OUTER_BOUNDARY_OPACITY`] for those around them, spread
///   per voxel over the material's mean chord
///   ([`crate::materials::MaterialShapes::mean_chord`]) times the
///   Gaussian's mean density over its own voxels, 2^(-m/2) for m fields.
pub fn material_gaussians(fields: &[&[f32]], geometry: &Geometry) -> Result<Vec<GaussianPrimitive>, String> {
    use mdtf_histogram::{CLUSTER_MASK, CORE_BIT};
    let clusters = mdtf_histogram::joint_clusters(fields).map_err(|e| e.to_string())?;
    let labels = clusters.labels(fields);
    let shapes = crate::materials::MaterialShapes::of(&labels, geometry.dims, clusters.clusters.len());
    let floor: Vec<f64> = clusters.bin_widths().iter().map(|w| w * w / 12.0).collect();
    let is =
        |k: usize, bit: u8| move |l: u8| l != mdtf_histogram::NO_CLUSTER && l & (CLUSTER_MASK | bit) == k as u8 | bit;
    let tops = top_means(fields, &labels, clusters.clusters.len());
    let mut fitted = Vec::new();
    for k in (0..clusters.clusters.len()).filter(|&k| Some(k) != shapes.background) {
        let in_core = is(k, CORE_BIT);
        let mut g = GaussianPrimitive::fit_with_floor(fields, |i| in_core(labels[i]), 1.0, [1.0; 3], &floor)
            .map_err(|e| format!("fitting a Gaussian to material {k}: {e}"))?;
        g.centre = tops[k].clone();
        // narrowed until every other material's centre lies SEPARATION_SIGMAS of its deviations away
        let nearest = (0..tops.len()).filter(|&j| j != k).map(|j| g.density(&tops[j])).fold(0.0, f64::max);
        let limit = (-SEPARATION_SIGMAS * SEPARATION_SIGMAS / 2.0).exp();
        if nearest > limit {
            // density exp(-q) at the nearest centre; K scaled by f gives exp(-f^2 q)
            let f = (limit.ln() / nearest.ln().min(-f64::MIN_POSITIVE)).sqrt();
            g.k.iter_mut().flatten().for_each(|x| *x *= f);
        }
        fitted.push((k, g));
    }
    let mean_density = 0.5f64.powf(fields.len() as f64 / 2.0);
    let count = fitted.len();
    Ok(fitted
        .into_iter()
        .enumerate()
        .map(|(j, (k, mut g))| {
            let surface = match shapes.innermost(k) {
                true => mdtf_pack::MAX_BOUNDARY_OPACITY,
                false => mdtf_pack::OUTER_BOUNDARY_OPACITY,
            };
            let path = shapes.mean_chord(k) * mean_density;
            g.alpha_max = mdtf_pack::per_voxel_opacities(&[surface], path)[0];
            g.colour = mdtf_pack::boundary_colour(j, count);
            g
        })
        .collect())
}

/// Each of the `count` clusters' mean of every field over the voxels of
/// its top (`labels` as [`mdtf_histogram::JointClusters::labels`] gives
/// them; 0 for a cluster without such a voxel), in one pass.
fn top_means(fields: &[&[f32]], labels: &[u8], count: usize) -> Vec<Vec<f64>> {
    use mdtf_histogram::{CLUSTER_MASK, NO_CLUSTER, TOP_BIT};
    let mut sums = vec![vec![0.0f64; fields.len()]; count];
    let mut voxels = vec![0usize; count];
    for (i, &l) in labels.iter().enumerate() {
        if l == NO_CLUSTER || l & TOP_BIT == 0 {
            continue;
        }
        let k = (l & CLUSTER_MASK) as usize;
        voxels[k] += 1;
        sums[k].iter_mut().zip(fields).for_each(|(s, f)| *s += f[i] as f64);
    }
    sums.into_iter().zip(voxels).map(|(s, n)| s.into_iter().map(|x| x / n.max(1) as f64).collect()).collect()
}

/// The IGauss table (eq. 16, 128^2 over [-10, 10]^2) and the erf-difference
/// table (section 5.2.2, 256^2 over [-3.6, 3.6]^2), each also as 16-bit codes.
pub fn analytic_integration_tables() -> Vec<Lut> {
    let axes = |size: usize, [min, max]: [f64; 2], a: &str, b: &str| {
        vec![LutAxis { channel: a.into(), size, min, max }, LutAxis { channel: b.into(), size, min, max }]
    };
    vec![
        Lut {
            name: "igauss".into(),
            meaning: "IGauss(x1, x2) = sqrt(pi)/2 (erf(x1) - erf(x2)) / (x1 - x2), exp(-x1^2) where x1 = x2: the mean \
                      of exp(-x^2) over [x2, x1] (Gaussian-TF paper eq. 16), at the cell centres"
                .into(),
            axes: axes(IGAUSS_SIZE, IGAUSS_DOMAIN, "x1", "x2"),
            components: 1,
            values: igauss_table(),
            unit_range: true,
            u16_range: Some([0.0, 1.0]),
        },
        Lut {
            name: "erf_difference".into(),
            meaning: "erf(x) - erf(y) at the cell centres (Gaussian-TF paper section 5.2.2); clamp x and y to the \
                      domain, erf is +-1 beyond it to 2e-7"
                .into(),
            axes: axes(ERF_SIZE, ERF_DOMAIN, "x", "y"),
            components: 1,
            values: erf_difference_table(),
            unit_range: false,
            u16_range: Some([-2.0, 2.0]),
        },
    ]
}
