//! The default 2D transfer function from the boundaries found in the data:
//! each boundary its own colour, and opacities that let the surfaces
//! behind a large one show through.
//!
//! Kindlmann and Durkin's semi-automatic opacity (a tent of the position
//! function p(v, g) around p = 0) marks every boundary at once, all alike:
//! on a head CT the skin, met first by every ray, hides the bone. Here each
//! (v, g) cell is given to the boundary whose arch it lies on, the arch of
//! a boundary between v_low and v_high with peak gradient G being
//! g(v) = G exp(-x^2 / 2 sigma^2) at v = v_low + (v_high - v_low) Phi(x / sigma):
//! * a cell belongs to the boundary whose v span holds its v and whose arch
//!   g(v) is nearest its g by ratio, if that ratio is within a factor of
//!   [`ARCH_RATIO`]; other cells stay transparent;
//! * cells with g below a boundary's noise floor (twice its materials'
//!   noise g, as detection takes it), or whose v lies within [`NOISE_SPREADS`]
//!   spreads of one of its materials' values, are noise inside a material, and
//!   transparent: near its two materials an arch's g falls to the noise's;
//! * boundary k's surface opacity, what a ray crossing it accumulates: a
//!   lone boundary is opaque ([`MAX_BOUNDARY_OPACITY`]); of several, one
//!   that meets the background (the value most voxels hold: air around a
//!   head, which every ray from outside crosses first, e.g. the skin) gets
//!   at most [`OUTER_BOUNDARY_OPACITY`] (less if the n_min / n_k rule over
//!   all the boundaries gives less), and the others A_k =
//!   [`MAX_BOUNDARY_OPACITY`] n_min / n_k, at least
//!   [`MIN_BOUNDARY_OPACITY`], with n_k the voxels in its core and n_min
//!   the fewest among them: a larger surface (most often an outer one) is
//!   more transparent, the smallest is the most opaque. When every
//!   boundary meets the background, the n_min / n_k rule covers them all;
//! * a cell's opacity, per voxel of path as the renderers take it, is
//!   a_k = 1 - (1 - A_k)^(1 / w) times the tent of p (the histogram
//!   volume's default opacity divided by its peak), w being the tent's
//!   half-width in voxels: a ray crossing the boundary head-on spends about
//!   w voxels' worth of full tent in it, so it accumulates about A_k;
//! * its colour is [`BOUNDARY_PALETTE`]'s k-th, boundaries in the order
//!   given (strongest first); a lone boundary, with nothing to tell it
//!   from, is white (the classic look of the plain tent).

use crate::lut::{Lut, LutAxis};
use crate::tf::{Falloff, PlacedWidget, Rectangle, TfFile, Widget};

/// A boundary's arch in the (v, g) plane, as detected in the histogram volume.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundaryArch {
    /// Value of the material on the low side.
    pub v_low: f64,
    /// Value of the material on the high side.
    pub v_high: f64,
    /// Peak gradient magnitude G, value units per world unit.
    pub g_peak: f64,
    /// Voxels in its core (what sets its opacity).
    pub core_voxels: u64,
    /// g below which a cell is noise inside a material, not this boundary.
    pub g_floor: f64,
    /// One of its materials is the background (what rays from outside cross first).
    pub meets_background: bool,
    /// Standard deviation of the low material's values: cells within
    /// [`NOISE_SPREADS`] of them of its value are that material's noise, not the boundary.
    pub v_low_spread: f64,
    /// The same for the high material.
    pub v_high_spread: f64,
    /// Placed by percentiles because no boundary was found: shown at
    /// [`FALLBACK_OPACITY`], so that what lies inside it shows through.
    pub fallback: bool,
}

/// Colours of the detected boundaries, in order (then repeated).
pub const BOUNDARY_PALETTE: [[f64; 3]; 6] =
    [[1.0, 0.55, 0.1], [0.2, 0.55, 1.0], [0.3, 0.9, 0.3], [0.9, 0.3, 0.8], [1.0, 0.9, 0.2], [0.2, 0.9, 0.9]];
/// Surface opacity of the boundary with the fewest core voxels: opaque at its
/// centre, as Kindlmann and Durkin's plain tent makes every boundary.
pub const MAX_BOUNDARY_OPACITY: f64 = 1.0;
/// Least opacity of any boundary.
pub const MIN_BOUNDARY_OPACITY: f64 = 0.1;
/// Surface opacity of a boundary that meets the background, when there are
/// others: faint enough that the ones inside show through it.
pub const OUTER_BOUNDARY_OPACITY: f64 = 0.3;
/// Standard deviations of a material's values within which a cell is its noise.
pub const NOISE_SPREADS: f64 = 3.0;
/// Surface opacity of a fallback boundary (placed by percentiles, not found).
pub const FALLBACK_OPACITY: f64 = 0.5;
/// How far (as a ratio) a cell's g may be from a boundary's arch to belong to it.
pub const ARCH_RATIO: f64 = 2.0;

impl BoundaryArch {
    /// The arch's g at value `v` (None outside the open span (v_low, v_high)).
    pub fn g_at(&self, v: f64) -> Option<f64> {
        mdtf_volume::arch_g(self.v_low, self.v_high, self.g_peak, v)
    }

    /// [`BoundaryArch::g_at`] where `v` lies more than [`NOISE_SPREADS`] spreads from
    /// either material (None within a material's noise).
    pub fn g_beyond_noise(&self, v: f64) -> Option<f64> {
        let clear =
            v > self.v_low + NOISE_SPREADS * self.v_low_spread && v < self.v_high - NOISE_SPREADS * self.v_high_spread;
        if clear { self.g_at(v) } else { None }
    }
}

/// The colour of boundary `k` of `count` (see the module docs).
pub fn boundary_colour(k: usize, count: usize) -> [f64; 3] {
    if count == 1 { [1.0; 3] } else { BOUNDARY_PALETTE[k % BOUNDARY_PALETTE.len()] }
}

/// The surface opacity A_k of each boundary (see the module docs).
pub fn boundary_opacities(arches: &[BoundaryArch]) -> Vec<f64> {
    let all_outer = arches.iter().all(|a| a.meets_background);
    let inner = |a: &BoundaryArch| all_outer || !a.meets_background;
    let least_of = |keep: &dyn Fn(&BoundaryArch) -> bool| {
        arches.iter().filter(|a| keep(a)).map(|a| a.core_voxels.max(1)).min().unwrap_or(1) as f64
    };
    let (least_inner, least_all) = (least_of(&inner), least_of(&|_| true));
    let by_size = |least: f64, a: &BoundaryArch| {
        (MAX_BOUNDARY_OPACITY * least / a.core_voxels.max(1) as f64).max(MIN_BOUNDARY_OPACITY)
    };
    arches
        .iter()
        .map(|a| match () {
            _ if a.fallback => FALLBACK_OPACITY,
            _ if inner(a) => by_size(least_inner, a),
            _ => by_size(least_all, a).min(OUTER_BOUNDARY_OPACITY),
        })
        .collect()
}

/// The tent and its size, as the histogram volume gives them.
#[derive(Debug, Clone, Copy)]
pub struct Tent<'a> {
    /// The histogram volume's opacity over (v, g), first axis fastest.
    pub opacity: &'a [f32],
    /// Its value at p = 0.
    pub peak: f64,
    /// Its half-width in voxels (the tent width over the smallest spacing).
    pub half_width_voxels: f64,
}

/// `tf2d_default` over (`v`, `g`): see the module docs.
pub fn boundary_tf(v: &LutAxis, g: &LutAxis, tent: Tent, arches: &[BoundaryArch]) -> Lut {
    let opacity = boundary_opacities(arches);
    let per_voxel = per_voxel_opacities(&opacity, tent.half_width_voxels);
    // each arch's g at every v cell centre, once
    let arch_g: Vec<Vec<Option<f64>>> =
        (0..v.size).map(|i| arches.iter().map(|a| a.g_beyond_noise(v.centre(i))).collect()).collect();
    let mut values = Vec::with_capacity(4 * v.size * g.size);
    for j in 0..g.size {
        let gc = g.centre(j);
        for (i, column) in arch_g.iter().enumerate() {
            let above_noise = column.iter().zip(arches).map(|(g_arch, a)| g_arch.filter(|_| gc >= a.g_floor));
            let owner = nearest_by_ratio(gc, above_noise);
            match owner {
                Some(k) if tent.peak > 0.0 => {
                    let c = boundary_colour(k, arches.len());
                    let a = per_voxel[k] * (tent.opacity[j * v.size + i] as f64 / tent.peak).clamp(0.0, 1.0);
                    values.extend([c[0] as f32, c[1] as f32, c[2] as f32, a as f32]);
                }
                _ => values.extend([0.0; 4]),
            }
        }
    }
    let listed: Vec<String> = arches
        .iter()
        .zip(&opacity)
        .enumerate()
        .map(|(k, (a, o))| {
            let c = boundary_colour(k, arches.len());
            format!(
                "{:.4}..{:.4} (peak g {:.4}) colour [{}, {}, {}] surface opacity {o:.3}",
                a.v_low, a.v_high, a.g_peak, c[0], c[1], c[2]
            )
        })
        .collect();
    Lut {
        name: "tf2d_default".into(),
        meaning: format!(
            "RGBA over (v, g) from the boundaries found in the histogram volume: each cell on a boundary's arch \
             has its colour and opacity times the tent of p(v, g) (Kindlmann-Durkin); boundaries: {}",
            listed.join("; ")
        ),
        axes: vec![v.clone(), g.clone()],
        components: 4,
        values,
        unit_range: true,
        u16_range: None,
    }
}

/// The value at which a one-value (isosurface) TF shows boundary `k` of
/// `arches`: its centre, unless that lies within the span of another
/// boundary sharing one of its materials (an engine's dense inserts meet
/// the air, 0 to 229, and the cast block meets it too, 0 to 144: at 114.5
/// both surfaces lie), then halfway between the two other materials (186.5:
/// only the inserts' surface), where that lies in fewer other spans.
pub fn isovalue(arches: &[BoundaryArch], k: usize) -> f64 {
    let a = &arches[k];
    let centre = 0.5 * (a.v_low + a.v_high);
    let others = || arches.iter().enumerate().filter(move |&(j, _)| j != k).map(|(_, b)| b);
    let spans_holding = |v: f64| others().filter(|b| b.v_low < v && v < b.v_high).count();
    let nested = others().filter(|b| b.v_low < centre && centre < b.v_high);
    let shifted = nested
        .filter_map(|b| match (b.v_low == a.v_low, b.v_high == a.v_high) {
            (true, false) if b.v_high < a.v_high => Some(0.5 * (b.v_high + a.v_high)),
            (false, true) if b.v_low > a.v_low => Some(0.5 * (a.v_low + b.v_low)),
            _ => None,
        })
        .min_by_key(|&v| spans_holding(v));
    match shifted {
        Some(v) if spans_holding(v) < spans_holding(centre) => v,
        _ => centre,
    }
}

/// A TF of thin widgets, one per boundary, at its [`isovalue`]: the
/// isosurfaces multidimensional peak finding renders (through
/// [`TfFile::peak_finding_tf2d`]). Each is a constant rectangle
/// [`ISOSURFACE_HALF_WIDTH`] of the boundary's value span wide on each side
/// of that value (at least one of the 1024 cells of `v_range`), over g from
/// 0.3 to 1.3 times its peak g, with the boundary's colour and its surface
/// opacity as the widget's opacity (peak finding keeps a peak's opacity
/// whatever the step, so that is what a ray crossing it accumulates).
pub fn boundary_isosurface_tf(arches: &[BoundaryArch], v_range: [f64; 2]) -> TfFile {
    let opacity = boundary_opacities(arches);
    let cell = (v_range[1] - v_range[0]) / 1024.0;
    let widgets = arches
        .iter()
        .zip(&opacity)
        .enumerate()
        .map(|(k, (a, &alpha))| PlacedWidget {
            shape: Widget::Rectangle(Rectangle {
                centre: [isovalue(arches, k), 0.8 * a.g_peak],
                half_size: [(ISOSURFACE_HALF_WIDTH * (a.v_high - a.v_low)).max(cell), 0.5 * a.g_peak],
                falloff: Falloff::Constant,
                alpha,
                colour: boundary_colour(k, arches.len()),
            }),
            f2: None,
            boundary_emphasis: None,
        })
        .collect();
    let g_top = arches.iter().map(|a| 1.3 * a.g_peak).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    TfFile {
        v_range,
        g_range: [0.0, g_top],
        f2_range: [-1.0, 1.0],
        boundary_emphasis: 1.0,
        widgets,
        tf1d: None,
        product: None,
    }
}

/// How far above a boundary's peak the rectangles of
/// [`multi_field_isosurface_tf`] reach (a bound, not a limit any data meets).
const OPEN_ABOVE: f64 = 1e6;

/// [`boundary_isosurface_tf`] for a multi-field pack, whose peak-finding TF
/// is over (field 0, 1/sqrt(||G||)) with every field normalised to [0, 1]
/// by its range: `arches` are field 0's boundaries (in its units), `span`
/// the width of the range field 0 is normalised by. sqrt(||G||) is at least
/// field 0's |grad f| / `span`, and the other fields only raise it, so each
/// rectangle runs in g from 0.3 times its peak (in normalised units per
/// world unit) up without a practical bound (a million times the peak).
pub fn multi_field_isosurface_tf(arches: &[BoundaryArch], v_range: [f64; 2], span: f64) -> TfFile {
    let scale = if span > 0.0 { 1.0 / span } else { 0.0 };
    let normalised: Vec<BoundaryArch> =
        arches.iter().map(|a| BoundaryArch { g_peak: a.g_peak * scale, g_floor: a.g_floor * scale, ..*a }).collect();
    let mut tf = boundary_isosurface_tf(&normalised, v_range);
    for (w, a) in tf.widgets.iter_mut().zip(&normalised) {
        if let Widget::Rectangle(r) = &mut w.shape {
            let (low, high) = (0.3 * a.g_peak, OPEN_ABOVE * a.g_peak);
            r.centre[1] = (low + high) / 2.0;
            r.half_size[1] = (high - low) / 2.0;
        }
    }
    tf.g_range[1] = normalised.iter().map(|a| OPEN_ABOVE * a.g_peak).fold(tf.g_range[1], f64::max);
    tf
}

/// alpha_u over (v, g_hit) for the distance-TF renderer, from the
/// boundaries: every voxel traced to boundary k reads g_hit near its peak g
/// (the stretched histogram's rows), so a cell whose v lies in boundary k's
/// span and whose g_hit is within a factor [`ARCH_RATIO`] of its G (the
/// nearest by ratio, if several) has k's colour and a per-voxel opacity
/// 1 - (1 - A_k)^(1 / w), w being the voxels' worth of full alpha_d a ray
/// crosses (the integral of alpha_d over both sides of the boundary, in
/// voxels), so that the surface accumulates about A_k. `v` and `g_hit` are
/// the table's axes (256 cells each is the renderer's size).
pub fn boundary_alpha_u(v: &LutAxis, g_hit: &LutAxis, alpha_d_voxels: f64, arches: &[BoundaryArch]) -> Lut {
    let per_voxel = per_voxel_opacities(&boundary_opacities(arches), alpha_d_voxels);
    let mut values = Vec::with_capacity(4 * v.size * g_hit.size);
    for j in 0..g_hit.size {
        let g = g_hit.centre(j);
        for i in 0..v.size {
            let x = v.centre(i);
            // every voxel traced to a boundary reads its peak g: the reference is G, wherever v is in its span
            let peaks = arches.iter().map(|a| (x > a.v_low && x < a.v_high && a.g_peak > 0.0).then_some(a.g_peak));
            match nearest_by_ratio(g, peaks) {
                Some(k) => {
                    let c = boundary_colour(k, arches.len());
                    let a = per_voxel[k];
                    values.extend([c[0] as f32, c[1] as f32, c[2] as f32, a as f32]);
                }
                None => values.extend([0.0; 4]),
            }
        }
    }
    Lut {
        name: "alpha_u".into(),
        meaning: format!(
            "RGBA over (v, g_hit): the default user TF alpha_u from the {} boundaries found in the histogram volume \
             (each its colour where v is in its span and g_hit within a factor {ARCH_RATIO} of its peak g)",
            arches.len()
        ),
        axes: vec![v.clone(), g_hit.clone()],
        components: 4,
        values,
        unit_range: true,
        u16_range: None,
    }
}

/// Half-width of a boundary's isosurface widget, as a share of its value span.
pub const ISOSURFACE_HALF_WIDTH: f64 = 0.01;

/// The index of the reference g (None: not a candidate) nearest `g` by
/// ratio, if within a factor [`ARCH_RATIO`] of it.
fn nearest_by_ratio(g: f64, references: impl Iterator<Item = Option<f64>>) -> Option<usize> {
    references
        .enumerate()
        .filter_map(|(k, r)| r.map(|r| (k, (g / r).ln().abs())))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .filter(|(_, miss)| *miss <= ARCH_RATIO.ln())
        .map(|(k, _)| k)
}

/// Per-voxel opacities 1 - (1 - A)^(1 / w) that accumulate the surface
/// opacities A over `w` voxels of full weight.
pub fn per_voxel_opacities(surface: &[f64], w: f64) -> Vec<f64> {
    let w = w.max(1e-3);
    surface.iter().map(|a| 1.0 - (1.0 - a).powf(1.0 / w)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_boundary_that_meets_the_background_is_faint_and_the_smallest_inner_one_opaque() {
        let arch = |core_voxels, meets_background| BoundaryArch {
            v_low: 0.0,
            v_high: 1.0,
            g_peak: 1.0,
            core_voxels,
            g_floor: 0.0,
            meets_background,
            v_low_spread: 0.0,
            v_high_spread: 0.0,
            fallback: false,
        };
        // skin (outer), bone, a small inner boundary; then an outer surface much larger than the rest
        let head = [arch(40_000, true), arch(60_000, false), arch(20_000, false)];
        assert_eq!(boundary_opacities(&head), vec![OUTER_BOUNDARY_OPACITY, 1.0 / 3.0, 1.0]);
        let large_outer = [arch(100_000, true), arch(60_000, false), arch(20_000, false)];
        assert_eq!(boundary_opacities(&large_outer), vec![0.2, 1.0 / 3.0, 1.0]);
        // alone, the outer one is opaque; all outer: by core voxels among them
        assert_eq!(boundary_opacities(&[arch(40_000, true)]), vec![1.0]);
        assert_eq!(boundary_opacities(&[arch(40_000, true), arch(10_000, true)]), vec![0.25, 1.0]);
        // the least is a floor
        assert_eq!(boundary_opacities(&[arch(1_000_000, false), arch(1_000, false)]), vec![MIN_BOUNDARY_OPACITY, 1.0]);
    }

    #[test]
    fn an_isovalue_leaves_the_span_of_a_boundary_sharing_a_material_where_fewer_pass() {
        let arch = |v_low, v_high| BoundaryArch {
            v_low,
            v_high,
            g_peak: 1.0,
            core_voxels: 1,
            g_floor: 0.0,
            meets_background: false,
            v_low_spread: 0.0,
            v_high_spread: 0.0,
            fallback: false,
        };
        // an engine: the block (0 | 144) and the inserts (0 | 229) meet the air; the inserts'
        // centre, 114.5, lies on the block's surface too: halfway between 144 and 229 only theirs
        let engine = [arch(0.0, 144.0), arch(0.0, 229.0)];
        assert_eq!((isovalue(&engine, 0), isovalue(&engine, 1)), (72.0, 186.5));
        // sharing the high material: halfway between the two low ones
        let shared_high = [arch(60.0, 200.0), arch(0.0, 200.0)];
        assert_eq!(isovalue(&shared_high, 1), 30.0);
        // a head: the holder (-1000 | 250) around the skin's centre (-1000 | 40) would move to 145,
        // on the skull's span (40 | 1400) instead: as many other boundaries pass there, it stays
        let head = [arch(-1000.0, 40.0), arch(-1000.0, 250.0), arch(40.0, 1400.0)];
        assert_eq!(isovalue(&head, 1), -375.0);
        // nested without a shared material (a sinus's air | bone around everything): the centre
        let nested = [arch(-1000.0, 1400.0), arch(40.0, 600.0)];
        assert_eq!(isovalue(&nested, 1), 320.0);
    }

    #[test]
    fn the_arch_is_the_erf_boundarys_g_as_a_function_of_v() {
        // an erf boundary from 20 to 230, sigma 2: at distance x, v = 20 + 210 Phi(x / 2), g = G exp(-x^2 / 8)
        let arch = BoundaryArch {
            v_low: 20.0,
            v_high: 230.0,
            g_peak: 210.0 / (2.0 * (2.0 * std::f64::consts::PI).sqrt()),
            core_voxels: 1,
            g_floor: 0.0,
            meets_background: true,
            v_low_spread: 0.0,
            v_high_spread: 0.0,
            fallback: false,
        };
        for x in [-3.0f64, -1.0, -0.2, 0.0, 0.7, 2.5] {
            let phi = 0.5 * (1.0 + libm::erf(x / 2.0 / std::f64::consts::SQRT_2));
            let v = 20.0 + 210.0 * phi;
            let want = arch.g_peak * (-x * x / 8.0).exp();
            let got = arch.g_at(v).unwrap();
            assert!((got - want).abs() < 1e-9 * arch.g_peak, "x {x}: {got} vs {want}");
        }
        assert_eq!((arch.g_at(20.0), arch.g_at(231.0)), (None, None));
    }

    #[test]
    fn cells_go_to_the_nearest_arch_with_its_colour_and_the_larger_surface_is_more_transparent() {
        let arch = |v_low, v_high, g_peak, core_voxels| BoundaryArch {
            v_low,
            v_high,
            g_peak,
            core_voxels,
            g_floor: 5.0,
            meets_background: false,
            v_low_spread: 0.0,
            v_high_spread: 0.0,
            fallback: false,
        };
        let arches = [arch(0.0, 200.0, 40.0, 40_000), arch(50.0, 150.0, 10.0, 10_000)];
        assert_eq!(boundary_opacities(&arches), vec![0.25, 1.0]);
        let (v, g) = (
            LutAxis { channel: "v".into(), size: 100, min: 0.0, max: 200.0 },
            LutAxis { channel: "g".into(), size: 50, min: 0.0, max: 50.0 },
        );
        // a tent at its peak everywhere, 2 voxels wide: per voxel 1 - (1 - A)^(1/2)
        let tent = vec![0.5f32; 100 * 50];
        let lut = boundary_tf(&v, &g, Tent { opacity: &tent, peak: 0.5, half_width_voxels: 2.0 }, &arches);
        let (a0, a1) = ((1.0 - 0.75f64.sqrt()) as f32, 1.0);
        let at = |i: usize, j: usize| &lut.values[4 * (j * 100 + i)..4 * (j * 100 + i) + 4];
        // v = 101 (cell 50), g = 39.5 (cell 39): on the first arch (g 40 there)
        assert_eq!(at(50, 39), &[1.0, 0.55, 0.1, a0]);
        // g = 9.5: the second arch's apex (10), a ratio of 1.05; the first's is 4.2
        assert_eq!(at(50, 9), &[0.2, 0.55, 1.0, a1]);
        // g = 2.5: four times below the second arch, sixteen below the first: nobody's
        assert_eq!(at(50, 2), &[0.0; 4]);
        // v = 53 (cell 26): the second arch's leg, g 1.7 there; g = 1.5 and 2.5 are
        // within its ratio but lie below the noise floor (5): noise, not the boundary
        let leg = arches[1].g_at(53.0).unwrap();
        assert!((1.6..1.8).contains(&leg) && arches[0].g_at(53.0).unwrap() > 30.0, "{leg}");
        assert_eq!((at(26, 1), at(26, 2)), (&[0.0; 4][..], &[0.0; 4][..]));
        assert!(
            lut.meaning.contains("0.0000..200.0000 (peak g 40.0000) colour [1, 0.55, 0.1] surface opacity 0.250"),
            "{}",
            lut.meaning
        );
    }

    #[test]
    fn the_multi_field_isosurfaces_are_over_normalised_g_and_open_above() {
        // field 0 from 0 to 400 (span 400), a boundary 100..300 of peak g 40 per mm: 0.1 normalised
        let arch = BoundaryArch {
            v_low: 100.0,
            v_high: 300.0,
            g_peak: 40.0,
            core_voxels: 1000,
            g_floor: 4.0,
            meets_background: false,
            v_low_spread: 0.0,
            v_high_spread: 0.0,
            fallback: false,
        };
        let tf = multi_field_isosurface_tf(&[arch], [0.0, 400.0], 400.0);
        let alpha = |v, g| tf.eval2(v, g)[3];
        // at the centre value: from 0.3 of the normalised peak (0.03) up, however much the other fields add
        assert_eq!((alpha(200.0, 0.029), alpha(200.0, 0.031), alpha(200.0, 0.1)), (0.0, 1.0, 1.0));
        assert_eq!((alpha(200.0, 1000.0), alpha(200.0, 0.99e5)), (1.0, 1.0));
        // thin in value: 1 % of the boundary's span (2) each side
        assert_eq!((alpha(201.9, 0.1), alpha(202.1, 0.1), alpha(197.9, 0.1)), (1.0, 0.0, 0.0));
        // its 2D peak-finding table over inv_g in [0, 100]: at v = 200 every cell whose centre (j + 1/2)
        // lies below 1/0.03 = 33.3 is opaque
        let lut = tf.peak_finding_tf2d([0.0, 100.0], [400, 100]).unwrap();
        let a = |j: usize| lut.values[4 * (j * 400 + 200) + 3];
        assert_eq!((a(0), a(32), a(33), a(99)), (1.0, 1.0, 0.0, 0.0));
    }
}
