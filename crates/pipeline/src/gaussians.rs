//! The Gaussian primitives of a gaussian-tf pack (`gaussians.json`) and the
//! lookup tables a GPU renderer of the Gaussian-TF paper reads.
//!
//! The primitives come from, in order: the TF file's `gaussian` widgets; a
//! GTF fitted to the voxels of a mask (the paper's section 6: the mean and
//! covariance of a probed region); on scalar data, the boundaries found in
//! the histogram volume: one triangular GTF of the paper's form (K = 1) at
//! each boundary's centre value, in its colour, with the extinction per
//! voxel that accumulates the boundary's surface opacity over the two world
//! units of path a head-on ray spends in it (see
//! [`mdtf_pack::boundary_opacities`]); else the paper's default TF (section 3.2,
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
use mdtf_volume::Volume;

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
    boundaries_from: (Option<&HistogramVolume>, mdtf_derive::Kernel),
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
        let (hvol, kernel) = boundaries_from;
        let arches = crate::pack_inputs::detected_arches(value, hvol, kernel).map_err(|e| e.to_string())?;
        if !arches.is_empty() {
            return Ok(boundary_tgtfs(&arches, &value.geometry));
        }
    }
    let g = get(gradient)?.samples();
    let median = mdtf_volume::median;
    let g_cut = 2.0 * median(g).unwrap_or(0.0);
    let structured = g.iter().filter(|&&x| x > g_cut).count();
    let use_all = structured * 100 < g.len();
    let mut centre = Vec::new();
    let mut ranges = Vec::new();
    for (a, s) in samples.iter().enumerate() {
        let picked: Vec<f32>;
        let over = if use_all {
            *s
        } else {
            picked = s.iter().zip(g).filter(|(_, gv)| **gv > g_cut).map(|(v, _)| *v).collect();
            &picked[..]
        };
        let m = median(over).ok_or(format!("channel '{}' has no finite sample", fields[a]))?;
        centre.push(m as f64);
        ranges.push(mdtf_volume::finite_sample_range(s).map_or(1.0, |(lo, hi)| (hi - lo) as f64));
    }
    Ok(vec![median_tgtf(centre, &ranges)])
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
        .map(|(k, (a, alpha_max))| GaussianPrimitive {
            centre: vec![0.5 * (a.v_low + a.v_high)],
            k: vec![vec![1.0]],
            alpha_max,
            colour: mdtf_pack::boundary_colour(k, arches.len()),
            triangular: true,
        })
        .collect()
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
