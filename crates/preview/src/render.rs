//! The ray caster: orthographic rays through the volume, samples every
//! `step` voxels by trilinear interpolation, classification by the pack's
//! transfer function, Blinn-Phong shading weighted by the surface-shading
//! weight 1 - (1 - g/g_max)^2 (Kniss et al. 9.5.4), front-to-back
//! emission-absorption compositing with opacity correction for the step.

use crate::empty_space;
use crate::load::Table;
use crate::samples::Samples;
use crate::tables::{
    chord_peak, composite_peaks, corrected_opacities, corrected_opacity, lookup, lookup_entry, product_lookup,
    table_index, unpremultiplied,
};
use mdtf_volume::{Geometry, Volume};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// View and sampling.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Rotation about the volume's z axis, degrees.
    pub azimuth: f64,
    /// Rotation up from the xy plane, degrees.
    pub elevation: f64,
    /// Image width and height, pixels.
    pub size: usize,
    /// Distance between samples, voxels (of the smallest spacing).
    pub step: f64,
    /// Blinn-Phong shading (from the normal channel, else the value's
    /// gradient); `false` composites the TF's colours unlit.
    pub shaded: bool,
}

impl Default for Camera {
    /// The view of every `mdtf run` preview: 30 degrees round, 20 up, 512 pixels, half-voxel steps, shaded.
    fn default() -> Self {
        Camera { azimuth: 30.0, elevation: 20.0, size: 512, step: 0.5, shaded: true }
    }
}

impl Camera {
    /// Refuses views that would render nothing meaningful or take hours:
    /// non-finite angles, a size outside 8 to 4096 pixels, a step outside
    /// 0.01 to 16 voxels (a ray of a 256^3 volume at 0.01 already takes
    /// 90 000 samples).
    pub fn check(&self) -> Result<(), String> {
        for (name, v) in [("azimuth", self.azimuth), ("elevation", self.elevation)] {
            if !v.is_finite() {
                return Err(format!("preview.{name} must be a finite number of degrees, got {v}"));
            }
        }
        if !(8..=4096).contains(&self.size) {
            return Err(format!("preview.size {} must be 8 to 4096 pixels", self.size));
        }
        if !(self.step.is_finite() && (0.01..=16.0).contains(&self.step)) {
            return Err(format!("preview.step must be 0.01 to 16 voxels, got {}", self.step));
        }
        Ok(())
    }
}

/// How samples become colour and opacity.
#[derive(Debug, Clone)]
pub enum Classifier {
    /// A LUT over 1 to 3 channels (RGBA), looked up at the nearest cell.
    Lut(Table),
    /// Distance TF: alpha_u(v, g_hit) (RGBA; white and opaque when absent) times alpha_d(d).
    Distance {
        /// alpha_u over (v, g_hit), if the pack has one.
        alpha_u: Option<Table>,
        /// alpha_d over d.
        alpha_d: Table,
    },
    /// Gaussian primitives over the named channels (their alpha_max is the extinction per
    /// voxel of path): a Riemann sum of the density at the samples, or the analytic integral
    /// of each primitive along the segment from the previous sample (Gaussian-TF paper eqs. 11-15).
    Gaussian {
        /// The primitives.
        primitives: Vec<mdtf_pack::GaussianPrimitive>,
        /// Channel of each TF axis, in order.
        channels: Vec<String>,
        /// Integrate analytically between samples instead of sampling the density.
        analytic: bool,
        /// The last channel is ||D^T D|| (`gnorm`), whose square root is the
        /// triangular GTF's gradient coordinate.
        sqrt_last: bool,
    },
    /// Peak finding on v (1D, the peak-finding paper's section 3): between
    /// consecutive samples, when the TF has peaks between their values (the
    /// pack's peak table), each peak is an isosurface the segment crosses: the
    /// peaks are composited in the order the ray meets them, each with the
    /// TF's opacity whatever the step (constant opacity at peaks), and shaded
    /// at the first one's crossing, found by the secant between the two
    /// samples. Else (or with `find_peaks` off: plain post-classification) the
    /// sample is classified with the step's opacity. Colour and opacity come
    /// from the pre-integration table's diagonal (a segment at one value).
    Peak {
        /// v of up to four TF peaks between (v_front, v_back) in ray order; -1 for none.
        peak_table: Table,
        /// RGBA of a segment of one L_min between (v_front, v_back).
        preintegration: Table,
        /// Look for peaks between samples.
        find_peaks: bool,
    },
    /// Multidimensional peak finding by chordal ray marching (peak-finding paper
    /// section 4.3): between consecutive samples f0, f1 the chord from f0 to f1 in
    /// the TF's domain is sampled every `cells_per_sample` TF cells (Delta s) and
    /// the sample is classified at the chord point of highest opacity. A peak
    /// strictly between the samples is an isosurface crossing: it keeps the
    /// TF's opacity whatever the step (the paper's constant-opacity rule) and
    /// is shaded at R(t_peak), the ray point at the peak's chord parameter
    /// (section 4.6); elsewhere the opacity is corrected for the step. With
    /// `find_peaks` off, plain post-classification at the samples.
    Chord {
        /// RGBA LUT over any channels of the pack (e.g. v and inv_g).
        tf: Table,
        /// Delta s: chord samples per TF cell travelled, inverted (2: every second cell).
        cells_per_sample: f64,
        /// Search the chord between samples.
        find_peaks: bool,
    },
    /// A separable product TF (Kniss et al. 9.5.2; the peak-finding paper's
    /// section 5.3 4D TF v(f0, f1) mu(f2, f3)): the opacity is the product of
    /// the factor tables' opacities, the colour the first factor's. With
    /// `find_peaks`, chordal peak finding as [`Classifier::Chord`] does, on
    /// the chord through all the factors' axes; else post-classification.
    Product {
        /// The factor tables (`product_0`, `product_1`, ...), each over its own channels.
        factors: Vec<Table>,
        /// Delta s, as for [`Classifier::Chord`].
        cells_per_sample: f64,
        /// Search the chord between samples.
        find_peaks: bool,
    },
}

/// Where a sample falls in the grid: the base voxel and the weights along
/// x, y, z; computed once per sample and used for every channel.
#[derive(Clone, Copy)]
struct Cell {
    /// Index of the (i, j, k) corner.
    base: usize,
    /// Steps to the +x, +y, +z neighbours (0 on a one-sample axis).
    stride: [usize; 3],
    /// Weights of the +x, +y, +z neighbours.
    t: [f32; 3],
}

impl Cell {
    /// The cell of voxel-space position `p` in a grid of `dims` (clamped to the grid).
    fn at(dims: [usize; 3], p: [f64; 3]) -> Cell {
        let mut i0 = [0usize; 3];
        let mut t = [0f32; 3];
        for a in 0..3 {
            let x = p[a].clamp(0.0, (dims[a] - 1) as f64);
            // x >= 0 (or NaN, which casts to 0 either way): truncation is floor
            let f = (x as usize).min(dims[a].saturating_sub(2));
            i0[a] = f;
            t[a] = (x - f as f64) as f32;
        }
        let [nx, ny, _] = dims;
        let step = |a: usize, s: usize| if dims[a] > 1 { s } else { 0 };
        Cell { base: (i0[2] * ny + i0[1]) * nx + i0[0], stride: [step(0, 1), step(1, nx), step(2, nx * ny)], t }
    }

    /// Trilinear interpolation of `d` (x-fastest samples of the grid).
    #[inline(always)]
    fn sample(&self, d: Samples) -> f32 {
        let [sx, sy, sz] = self.stride;
        let b = self.base;
        let l = |a: f32, c: f32, t: f32| a + (c - a) * t;
        let c00 = l(d.at(b), d.at(b + sx), self.t[0]);
        let c10 = l(d.at(b + sy), d.at(b + sy + sx), self.t[0]);
        let c01 = l(d.at(b + sz), d.at(b + sz + sx), self.t[0]);
        let c11 = l(d.at(b + sz + sy), d.at(b + sz + sy + sx), self.t[0]);
        l(l(c00, c10, self.t[1]), l(c01, c11, self.t[1]), self.t[2])
    }
}

/// The samples s (at origin + (s + 1/2) step dir) that can lie inside the
/// box [0, ext], by the slab test: from one before the ray's entry to one
/// after its exit (the caller still tests every sample), none if it misses.
fn sample_span(origin: [f64; 3], dir: [f64; 3], ext: &[f64], step: f64) -> std::ops::Range<usize> {
    let (mut t_enter, mut t_exit) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        if dir[a] != 0.0 {
            let (t1, t2) = ((0.0 - origin[a]) / dir[a], (ext[a] - origin[a]) / dir[a]);
            t_enter = t_enter.max(t1.min(t2));
            t_exit = t_exit.min(t1.max(t2));
        } else if origin[a] < 0.0 || origin[a] > ext[a] {
            return 0..0;
        }
    }
    let first = (t_enter / step - 0.5).floor() - 1.0;
    let first = if first.is_finite() && first > 0.0 { first as usize } else { 0 };
    let end = (t_exit / step - 0.5).ceil() + 2.0;
    let end = if end.is_finite() { end.max(0.0) as usize } else { usize::MAX };
    first..end.max(first)
}

/// Samples per ray allowed per voxel of the grid's diagonal and per unit of
/// step: more than any grid with spacings within a ratio of 8 needs.
const MAX_STEPS_PER_DIAGONAL_VOXEL: f64 = 8.0;

/// The sampling of every ray: step in world units and in units of the
/// smallest spacing (for the opacity correction), and samples per ray.
#[derive(Debug, Clone, Copy, PartialEq)]
struct RaySteps {
    world: f64,
    voxels: f64,
    count: usize,
}

/// A ray crosses at most the diagonal (2 `radius`, world units). In voxels
/// that is bounded by the grid, but in steps of the smallest spacing it grows
/// with the spacings' ratio, which a manifest may claim to be anything. The
/// samples per ray are capped at a fixed multiple of the voxel diagonal,
/// widening the step (and its opacity correction) only for grids more
/// anisotropic than that.
fn ray_steps(g: &mdtf_volume::Geometry, radius: f64, step: f64) -> RaySteps {
    let l_min = g.min_spacing();
    let max_steps = (MAX_STEPS_PER_DIAGONAL_VOXEL * dims_diagonal(g.dims) / step).ceil();
    let world = (step * l_min).max(2.0 * radius / max_steps);
    RaySteps { world, voxels: world / l_min, count: (2.0 * radius / world).ceil() as usize }
}

/// Length of the grid's diagonal in voxels (at least 1).
fn dims_diagonal(dims: [usize; 3]) -> f64 {
    dims.iter().map(|&d| (d.max(1) as f64 - 1.0).powi(2)).sum::<f64>().sqrt().max(1.0)
}

/// The samples of the channels a table is indexed by (None: the pack lacks it, read as 0).
fn table_channels<'a>(t: &Table, channels: &BTreeMap<String, Samples<'a>>) -> Vec<Option<Samples<'a>>> {
    t.axes.iter().map(|(c, ..)| channels.get(c).copied()).collect()
}

/// Up to four table coordinates at `cell` (tables have at most 3 axes; the chord's 2 to 4).
fn coords(cell: &Cell, chans: &[Option<Samples>]) -> [f32; 4] {
    let mut out = [0f32; 4];
    for (o, c) in out.iter_mut().zip(chans) {
        *o = c.map_or(0.0, |d| cell.sample(d));
    }
    out
}

/// Channels the renderer reads besides the classifier's: shading (normals
/// and g), the value, and the distance-tf pair.
const SHADING_AND_PROFILE_CHANNELS: [&str; 7] = ["nx", "ny", "nz", "g", "v", "distance", "g_hit"];

/// Names of every channel [`render`] reads with `classifier` (a pack may lack some).
pub fn channels_read(classifier: &Classifier) -> Vec<String> {
    let mut names: Vec<String> = SHADING_AND_PROFILE_CHANNELS.iter().map(|c| c.to_string()).collect();
    match classifier {
        Classifier::Lut(t) | Classifier::Chord { tf: t, .. } => names.extend(t.axes.iter().map(|(c, ..)| c.clone())),
        Classifier::Product { factors, .. } => {
            names.extend(factors.iter().flat_map(|t| t.axes.iter().map(|(c, ..)| c.clone())))
        }
        Classifier::Gaussian { channels, .. } => names.extend(channels.iter().cloned()),
        Classifier::Distance { .. } | Classifier::Peak { .. } => {}
    }
    names
}

/// Renders `channels` (decoded or float, by name) with `classifier`; RGB8 pixels, rows from the top.
pub fn render(channels: &BTreeMap<String, Volume>, classifier: &Classifier, cam: &Camera) -> Vec<u8> {
    render_floats(channels, classifier, cam, true)
}

/// [`render`] without empty-space skipping: every sample classified (the
/// reference the skipping is tested against; the same pixels, slower).
pub fn render_without_skipping(channels: &BTreeMap<String, Volume>, classifier: &Classifier, cam: &Camera) -> Vec<u8> {
    render_floats(channels, classifier, cam, false)
}

/// [`render`] of channels read in place (e.g. a pack's textures, see
/// [`crate::PackTextures`]) on the grid `g`.
pub fn render_samples(
    channels: &BTreeMap<String, Samples>,
    g: &Geometry,
    classifier: &Classifier,
    cam: &Camera,
) -> Vec<u8> {
    render_impl(channels, g, classifier, cam, true)
}

fn render_floats(channels: &BTreeMap<String, Volume>, classifier: &Classifier, cam: &Camera, skip: bool) -> Vec<u8> {
    let Some(any) = channels.values().next() else { return vec![0; cam.size * cam.size * 3] };
    let samples = channels.iter().map(|(n, v)| (n.clone(), Samples::Floats(v.samples()))).collect();
    render_impl(&samples, &any.geometry, classifier, cam, skip)
}

fn render_impl(
    channels: &BTreeMap<String, Samples>,
    g: &Geometry,
    classifier: &Classifier,
    cam: &Camera,
    skip_empty: bool,
) -> Vec<u8> {
    let ext: Vec<f64> = (0..3).map(|a| (g.dims[a] as f64 - 1.0) * g.spacing[a]).collect();
    let centre = [ext[0] / 2.0, ext[1] / 2.0, ext[2] / 2.0];
    let radius = (ext[0] * ext[0] + ext[1] * ext[1] + ext[2] * ext[2]).sqrt() / 2.0;
    let (az, el) = (cam.azimuth.to_radians(), cam.elevation.to_radians());
    let dir = [-(el.cos() * az.cos()), -(el.cos() * az.sin()), -el.sin()];
    let right = [-az.sin(), az.cos(), 0.0];
    let up = [
        dir[1] * right[2] - dir[2] * right[1],
        dir[2] * right[0] - dir[0] * right[2],
        dir[0] * right[1] - dir[1] * right[0],
    ];
    let up = [-up[0], -up[1], -up[2]];
    let RaySteps { world: step_world, voxels: step_vox, count: steps } = ray_steps(g, radius, cam.step);
    let data = |n: &str| channels.get(n).copied();
    let (nx, ny, nz, gch) = (data("nx"), data("ny"), data("nz"), data("g"));
    let (v_data, distance, g_hit) = (data("v"), data("distance"), data("g_hit"));
    let dims = g.dims;
    let table_chans = match classifier {
        Classifier::Lut(t) | Classifier::Chord { tf: t, .. } => table_channels(t, channels),
        Classifier::Product { factors, .. } => factors.iter().flat_map(|t| table_channels(t, channels)).collect(),
        Classifier::Gaussian { channels: names, .. } => names.iter().map(|c| data(c)).collect(),
        _ => Vec::new(),
    };
    // what is shaded by its gradient where the pack has no normals: the value, else the TF's first channel
    let shading_scalar = v_data.or_else(|| table_chans.first().copied().flatten());
    let g_max = gch.and_then(|d| d.finite_max(g.voxel_count())).map_or(1.0, |m| m.max(1e-12) as f64);
    let light = [-dir[0] + 0.3 * up[0], -dir[1] + 0.3 * up[1], -dir[2] + 0.3 * up[2]];
    let ll = (light.iter().map(|x| x * x).sum::<f64>()).sqrt();
    let light = light.map(|x| x / ll);
    let half = [(light[0] - dir[0]) / 2.0, (light[1] - dir[1]) / 2.0, (light[2] - dir[2]) / 2.0];
    let hl = (half.iter().map(|x| x * x).sum::<f64>()).sqrt().max(1e-12);
    let half = half.map(|x| x / hl);
    let mut img = vec![0u8; cam.size * cam.size * 3];
    // the LUT's opacities corrected for the step once, not at every sample
    let lut_opacity = match classifier {
        Classifier::Lut(t) | Classifier::Chord { tf: t, .. } => corrected_opacities(t, step_vox),
        _ => Vec::new(),
    };
    let skip = if skip_empty {
        empty_space::visible_blocks_of(classifier, &table_chans, distance, v_data, dims, steps as f64 * step_vox)
    } else {
        None
    };
    // how far the empty space around each invisible block reaches, blocks
    let reach = skip.as_ref().map_or(Vec::new(), |(visible, nb)| empty_space::empty_reach(visible, *nb));
    // the chord (or the peak segment) from the previous sample leaves a block's value box unless both samples are in it
    let chord_search = matches!(
        classifier,
        Classifier::Chord { find_peaks: true, .. }
            | Classifier::Product { find_peaks: true, .. }
            | Classifier::Peak { find_peaks: true, .. }
    );
    // the chord classifiers' domain and TF: one table, or a product of tables
    let chord_axes: Vec<(String, usize, f64, f64)> = match classifier {
        Classifier::Chord { tf, .. } => tf.axes.clone(),
        Classifier::Product { factors, .. } => factors.iter().flat_map(|t| t.axes.iter().cloned()).collect(),
        _ => Vec::new(),
    };
    // the chord classifier's opacities alone, a quarter of its table's bytes for the search
    let chord_alpha: Vec<f32> = match classifier {
        Classifier::Chord { tf, find_peaks: true, .. } => {
            (0..tf.values.len() / tf.components.max(1)).map(|e| lookup_entry(tf, e)[3]).collect()
        }
        _ => Vec::new(),
    };
    let chord_opacity = |x: &[f32]| match classifier {
        Classifier::Chord { tf, .. } => chord_alpha[table_index(tf, x)],
        Classifier::Product { factors, .. } => product_lookup(factors, x)[3],
        _ => 0.0,
    };
    // where a chord can meet no opacity, the search is skipped (its answer is the sample's own)
    let chord_boxes = match classifier {
        Classifier::Chord { tf, .. } if skip_empty => Some(empty_space::ChordBoxes::new(&[tf])),
        Classifier::Product { factors, .. } if skip_empty => {
            Some(empty_space::ChordBoxes::new(&factors.iter().collect::<Vec<_>>()))
        }
        _ => None,
    };
    let chord_eval = |x: &[f32]| match classifier {
        Classifier::Chord { tf, .. } => lookup(tf, x),
        Classifier::Product { factors, .. } => product_lookup(factors, x),
        _ => [0.0; 4],
    };
    // a sample's advance along the ray, voxels per axis
    let per_sample = [0, 1, 2].map(|a| step_world * dir[a] / g.spacing[a]);
    let nb_of = |skip: &Option<(Vec<bool>, [usize; 3])>| skip.as_ref().map_or([1; 3], |(_, nb)| *nb);
    img.par_chunks_mut(cam.size * 3).enumerate().for_each(|(row, out)| {
        for col in 0..cam.size {
            let (u, v) = (
                ((col as f64 + 0.5) / cam.size as f64 * 2.0 - 1.0) * radius,
                (1.0 - (row as f64 + 0.5) / cam.size as f64 * 2.0) * radius,
            );
            let origin = [0, 1, 2].map(|a| centre[a] + u * right[a] + v * up[a] - radius * dir[a]);
            // sample s's voxel-space position
            let position =
                |s: usize| [0, 1, 2].map(|a| (origin[a] + (s as f64 + 0.5) * step_world * dir[a]) / g.spacing[a]);
            let (mut rgb, mut alpha) = ([0f64; 3], 0f64);
            // the previous sample's TF coordinates (analytic Gaussian segments)
            // (two buffers swapped each sample: no allocation per sample)
            let (mut previous, mut has_previous, mut here): (Vec<f64>, bool, Vec<f64>) =
                (Vec::new(), false, Vec::new());
            // the previous sample's cell and block (chord and peak classifiers),
            // and its TF coordinates once the chord classifier computed them
            let mut prev: Option<(Cell, usize, [f64; 3])> = None;
            let mut prev_coords: Option<[f32; 4]> = None;
            // the sample before this one was skipped: an analytic Gaussian segment starts there
            let mut skipped_before = false;
            let mut entered = false;
            let span = sample_span(origin, dir, &ext, step_world);
            let steps = steps.min(span.end);
            let mut next = span.start;
            while next < steps {
                let s = next;
                next += 1;
                let pw = [0, 1, 2].map(|a| origin[a] + (s as f64 + 0.5) * step_world * dir[a]);
                if (0..3).any(|a| pw[a] < 0.0 || pw[a] > ext[a]) {
                    // the samples inside the box are one run of s (it is convex,
                    // and pw is monotone in s per axis): once out, done
                    if entered {
                        break;
                    }
                    continue;
                }
                entered = true;
                let p = position(s);
                let block = skip.as_ref().map_or(0, |(_, nb)| empty_space::block_at(*nb, p));
                if let Some((visible, _)) = &skip
                    && !visible[block]
                    && !chord_search
                {
                    // (only the chord search reads the previous sample across a skip)
                    prev = None;
                    skipped_before = true;
                    // the later samples in the empty space around would be skipped alike: past them at once
                    next = empty_space::last_sample_in_reach(nb_of(&skip), p, per_sample, s, reach[block])
                        .saturating_add(1);
                    continue;
                }
                let resumed = std::mem::take(&mut skipped_before);
                let cell = Cell::at(dims, p);
                let prev_here = prev.replace((cell, block, p));
                let prev_coords_here = prev_coords.take();
                if let Some((visible, _)) = &skip
                    && !visible[block]
                    && prev_here.is_none_or(|(_, pb, _)| pb == block)
                {
                    // the block's later samples would be skipped alike, each the next one's
                    // previous sample: on to the last of them
                    let last = empty_space::last_sample_in_reach(nb_of(&skip), p, per_sample, s, 1);
                    if last > s && last < steps {
                        let p_last = position(last);
                        prev = Some((Cell::at(dims, p_last), block, p_last));
                        next = last + 1;
                    } else if last >= steps {
                        next = steps;
                    }
                    continue;
                }
                let sample = |d: Option<Samples>| d.map_or(0.0, |d| cell.sample(d));
                // where the sample is shaded: at the sample, or at a peak found between samples
                let (mut shade, mut shade_at) = (cell, p);
                let ([r, gr, b], a) = match classifier {
                    Classifier::Lut(t) => {
                        let at = table_index(t, &coords(&cell, &table_chans));
                        let [r, gr, b, _] = lookup_entry(t, at);
                        // opacity correction: the TF's opacity is per voxel (L_min) of path
                        ([r, gr, b], lut_opacity[at])
                    }
                    Classifier::Distance { alpha_u, alpha_d } => {
                        let d = sample(distance);
                        let ad = if d >= 0.0 { lookup(alpha_d, &[d])[3] } else { 0.0 };
                        let u = alpha_u
                            .as_ref()
                            .map_or([1.0, 1.0, 1.0, 1.0], |t| lookup(t, &[sample(v_data), sample(g_hit)]));
                        ([u[0], u[1], u[2]], corrected_opacity(u[3] * ad, step_vox))
                    }
                    Classifier::Peak { peak_table, preintegration, find_peaks } => {
                        let v1 = sample(v_data);
                        let v0 = if *find_peaks {
                            prev_here.map(|(c, _, p0)| (v_data.map_or(0.0, |d| c.sample(d)), p0))
                        } else {
                            None
                        };
                        let peaks = v0.map(|(v0, p0)| (v0, p0, lookup(peak_table, &[v0, v1])));
                        match peaks.filter(|(_, _, pk)| pk[0] >= 0.0) {
                            Some((v0, p0, pk)) => {
                                // the secant's root of v(t) = first peak on the segment
                                let t = if v1 != v0 { ((pk[0] - v0) / (v1 - v0)).clamp(0.0, 1.0) as f64 } else { 1.0 };
                                shade_at = [0, 1, 2].map(|k| p0[k] + t * (p[k] - p0[k]));
                                shade = Cell::at(dims, shade_at);
                                composite_peaks(preintegration, &pk)
                            }
                            None => {
                                let (colour, a) = unpremultiplied(lookup(preintegration, &[v1, v1]));
                                (colour, 1.0 - (1.0 - a.min(0.999)).powf(step_vox))
                            }
                        }
                    }
                    Classifier::Chord { cells_per_sample, find_peaks, .. }
                    | Classifier::Product { cells_per_sample, find_peaks, .. } => {
                        let f1_all = coords(&cell, &table_chans);
                        prev_coords = Some(f1_all);
                        let n_axes = chord_axes.len();
                        let f1 = &f1_all[..n_axes];
                        let f0 = if *find_peaks {
                            prev_here
                                .map(|(c, _, p0)| (prev_coords_here.unwrap_or_else(|| coords(&c, &table_chans)), p0))
                        } else {
                            None
                        };
                        let ([r, gr, b, a], peak) = match f0 {
                            Some((f0, _))
                                if chord_boxes.as_ref().is_some_and(|c| c.all_transparent(&f0[..n_axes], f1)) =>
                            {
                                (chord_eval(f1), None)
                            }
                            Some((f0, p0)) => {
                                let (rgba, s) = chord_peak(
                                    &chord_axes,
                                    &chord_eval,
                                    &chord_opacity,
                                    &f0[..n_axes],
                                    f1,
                                    *cells_per_sample,
                                );
                                (rgba, s.map(|s| (s as f64, p0)))
                            }
                            None => (chord_eval(f1), None),
                        };
                        match peak {
                            // a peak between the samples: an isosurface at R(t_peak), shaded
                            // there, with the TF's opacity whatever the step (the paper's
                            // section 3: constant opacity at peaks)
                            Some((s, p0)) => {
                                shade_at = [0, 1, 2].map(|k| p0[k] + s * (p[k] - p0[k]));
                                shade = Cell::at(dims, shade_at);
                                ([r, gr, b], (a as f64).min(0.999))
                            }
                            // (the sample's own entry: a single table's corrected once)
                            None => match classifier {
                                Classifier::Chord { tf, .. } => ([r, gr, b], lut_opacity[table_index(tf, f1)]),
                                _ => ([r, gr, b], corrected_opacity(a, step_vox)),
                            },
                        }
                    }
                    Classifier::Gaussian { primitives, channels: _, analytic, sqrt_last } => {
                        let coords_at = |cell: &Cell, out: &mut Vec<f64>| {
                            out.clear();
                            out.extend(table_chans.iter().map(|&c| c.map_or(0.0, |d| cell.sample(d)) as f64));
                            if *sqrt_last && let Some(last) = out.last_mut() {
                                *last = last.max(0.0).sqrt();
                            }
                        };
                        if *analytic && resumed {
                            // the segment starts at the skipped sample before: its coordinates, as
                            // the renderer without skipping had them
                            let pw0 = [0, 1, 2].map(|a| origin[a] + (s as f64 - 0.5) * step_world * dir[a]);
                            coords_at(&Cell::at(dims, [0, 1, 2].map(|a| pw0[a] / g.spacing[a])), &mut previous);
                            has_previous = true;
                        }
                        coords_at(&cell, &mut here);
                        let from_previous = *analytic && has_previous;
                        let (mut depth, mut c) = (0.0, [0.0f64; 3]);
                        for gp in primitives {
                            let rho = match from_previous {
                                true => gp.segment_integral(&previous, &here),
                                false => gp.density(&here),
                            };
                            depth += gp.alpha_max * rho;
                            for k in 0..3 {
                                c[k] += gp.alpha_max * rho * gp.colour[k];
                            }
                        }
                        if *analytic {
                            std::mem::swap(&mut previous, &mut here);
                            has_previous = true;
                        }
                        let colour = if depth > 0.0 { c.map(|x| (x / depth) as f32) } else { [0.0; 3] };
                        // eq. 15: alpha = 1 - exp(-l sum tau_i rho'_i), l = the step in voxels
                        (colour, 1.0 - (-depth * step_vox).exp())
                    }
                };
                if a <= 0.0 {
                    continue;
                }
                let mut colour = [r as f64, gr as f64, b as f64];
                let normal = match (nx, ny, nz, shading_scalar) {
                    (Some(nxv), Some(nyv), Some(nzv), _) => {
                        Some([shade.sample(nxv) as f64, shade.sample(nyv) as f64, shade.sample(nzv) as f64])
                    }
                    // no normals in the pack: the gradient of its value, by central differences
                    (_, _, _, Some(f)) => Some([0, 1, 2].map(|a| {
                        let mut ahead = shade_at;
                        let mut behind = shade_at;
                        ahead[a] += 1.0;
                        behind[a] -= 1.0;
                        (Cell::at(dims, ahead).sample(f) - Cell::at(dims, behind).sample(f)) as f64 / g.spacing[a]
                    })),
                    _ => None,
                };
                if let Some(n) = normal.filter(|_| cam.shaded) {
                    let nl = (n.iter().map(|x| x * x).sum::<f64>()).sqrt();
                    if nl > 1e-6 {
                        let n = n.map(|x| x / nl);
                        let diffuse = (n[0] * light[0] + n[1] * light[1] + n[2] * light[2]).abs();
                        let spec = (n[0] * half[0] + n[1] * half[1] + n[2] * half[2]).abs().powi(32);
                        let w = gch.map_or(1.0, |gv| {
                            let t = 1.0 - (shade.sample(gv) as f64 / g_max).clamp(0.0, 1.0);
                            1.0 - t * t
                        });
                        let shaded = colour.map(|c| c * (0.25 + 0.75 * diffuse) + 0.3 * spec);
                        colour = [0, 1, 2].map(|k| w * shaded[k] + (1.0 - w) * colour[k]);
                    }
                }
                for k in 0..3 {
                    rgb[k] += (1.0 - alpha) * a * colour[k];
                }
                alpha += (1.0 - alpha) * a;
                if alpha > 0.99 {
                    break;
                }
            }
            for k in 0..3 {
                out[col * 3 + k] = (rgb[k].clamp(0.0, 1.0) * 255.0).round() as u8;
            }
        }
    });
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sample_span_holds_every_sample_inside_the_box() {
        let mut state = 11u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let ext = [40.0, 17.0, 25.0];
        for _ in 0..2000 {
            let origin = [0, 1, 2].map(|a| (next() * 2.0 - 0.5) * ext[a]);
            let mut dir = [0, 1, 2].map(|_| next() * 2.0 - 1.0);
            // axis-parallel rays too
            if next() < 0.2 {
                dir[(next() * 3.0) as usize % 3] = 0.0;
            }
            let step = 0.1 + next();
            let span = sample_span(origin, dir, &ext, step);
            for s in 0..2000usize {
                let p = [0, 1, 2].map(|a| origin[a] + (s as f64 + 0.5) * step * dir[a]);
                let inside = (0..3).all(|a| p[a] >= 0.0 && p[a] <= ext[a]);
                assert!(!inside || span.contains(&s), "{origin:?} {dir:?} {step}: sample {s} outside {span:?}");
            }
        }
    }

    #[test]
    fn rays_take_the_asked_step_and_a_bounded_count_on_any_grid() {
        let radius = |g: &mdtf_volume::Geometry| {
            (0..3).map(|a| ((g.dims[a] as f64 - 1.0) * g.spacing[a]).powi(2)).sum::<f64>().sqrt() / 2.0
        };
        let iso = mdtf_volume::Geometry::new([64, 64, 64], [0.5, 0.5, 0.5]);
        let r = ray_steps(&iso, radius(&iso), 0.5);
        assert_eq!((r.world, r.voxels), (0.25, 0.5));
        // spacings 1 : 8 still sample at the asked step
        let aniso = mdtf_volume::Geometry::new([64, 64, 64], [1.0, 1.0, 8.0]);
        assert_eq!(ray_steps(&aniso, radius(&aniso), 0.5).voxels, 0.5);
        // a claimed spacing of 1e7 (or 1e19) beside 1 no longer means 1e7 times the samples
        for big in [1e7, 1e19] {
            let g = mdtf_volume::Geometry::new([16, 16, 16], [big, 1.0, 1.0]);
            let r = ray_steps(&g, radius(&g), 0.5);
            let bound = MAX_STEPS_PER_DIAGONAL_VOXEL * dims_diagonal(g.dims) / 0.5 + 1.0;
            assert!(r.count as f64 <= bound, "{big}: {} samples per ray", r.count);
        }
    }
}
