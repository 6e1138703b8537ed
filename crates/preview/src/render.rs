//! The ray caster: orthographic rays through the volume, samples every
//! `step` voxels by trilinear interpolation, classification by the pack's
//! transfer function, Blinn-Phong shading weighted by the surface-shading
//! weight 1 - (1 - g/g_max)^2 (Kniss et al. 9.5.4), front-to-back
//! emission-absorption compositing with opacity correction for the step.

use crate::load::Table;
use mdtf_volume::Volume;
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
    },
    /// Peak finding on v (1D): between consecutive samples, when the TF has a peak
    /// between their values (the pack's peak table), classify at the peak; else (or
    /// with `find_peaks` off: plain post-classification) at the sample. Colour and
    /// opacity come from the pre-integration table's diagonal (a segment at one value).
    Peak {
        /// v of the highest TF peak between (v_front, v_back); -1 for none.
        peak_table: Table,
        /// RGBA of a segment of one L_min between (v_front, v_back).
        preintegration: Table,
        /// Look for peaks between samples.
        find_peaks: bool,
    },
    /// Multidimensional peak finding by chordal ray marching (peak-finding paper
    /// section 4.3): between consecutive samples f0, f1 the chord from f0 to f1 in
    /// the TF's domain is sampled every `cells_per_sample` TF cells (Delta s) and
    /// the sample is classified at the chord point of highest opacity; with
    /// `find_peaks` off, plain post-classification at the samples.
    Chord {
        /// RGBA LUT over any channels of the pack (e.g. v and inv_g).
        tf: Table,
        /// Delta s: chord samples per TF cell travelled, inverted (2: every second cell).
        cells_per_sample: f64,
        /// Search the chord between samples.
        find_peaks: bool,
    },
}

/// The highest-opacity RGBA on the chord from `f0` to `f1` in `t`'s domain,
/// sampled every `cells_per_sample` cells (both ends included).
fn chord_peak(t: &Table, f0: &[f32], f1: &[f32], cells_per_sample: f64) -> [f32; 4] {
    let cells: f64 = t
        .axes
        .iter()
        .enumerate()
        .map(|(k, (_, n, min, max))| ((f1[k] - f0[k]) as f64 / (max - min) * *n as f64).powi(2))
        .sum::<f64>()
        .sqrt();
    let samples = ((cells / cells_per_sample).ceil() as usize).clamp(1, 4096);
    let mut best = lookup(t, f1);
    let mut point = vec![0f32; f0.len()];
    for k in 0..samples {
        let s = k as f32 / samples as f32;
        for (p, (a, b)) in point.iter_mut().zip(f0.iter().zip(f1)) {
            *p = a + s * (b - a);
        }
        let rgba = lookup(t, &point);
        if rgba[3] > best[3] {
            best = rgba;
        }
    }
    best
}

fn lookup(t: &Table, coords: &[f32]) -> [f32; 4] {
    let mut idx = 0usize;
    let mut stride = 1usize;
    for (k, (_, cells, min, max)) in t.axes.iter().enumerate() {
        let x = ((coords[k] as f64 - min) / (max - min) * *cells as f64).floor();
        let i = if x.is_nan() { 0 } else { x.clamp(0.0, (*cells - 1) as f64) as usize };
        idx += i * stride;
        stride *= cells;
    }
    let c = t.components;
    if c == 4 {
        [t.values[idx * 4], t.values[idx * 4 + 1], t.values[idx * 4 + 2], t.values[idx * 4 + 3]]
    } else {
        [1.0, 1.0, 1.0, t.values[idx]]
    }
}

fn trilinear(v: &Volume, p: [f64; 3]) -> f32 {
    let [nx, ny, nz] = v.geometry.dims;
    let d = v.samples();
    let dims = [nx, ny, nz];
    let mut i0 = [0usize; 3];
    let mut t = [0f32; 3];
    for a in 0..3 {
        let x = p[a].clamp(0.0, (dims[a] - 1) as f64);
        let f = (x.floor() as usize).min(dims[a].saturating_sub(2));
        i0[a] = f;
        t[a] = (x - f as f64) as f32;
    }
    let at = |i: usize, j: usize, k: usize| d[(k.min(nz - 1) * ny + j.min(ny - 1)) * nx + i.min(nx - 1)];
    let l = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let [i, j, k] = i0;
    let c00 = l(at(i, j, k), at(i + 1, j, k), t[0]);
    let c10 = l(at(i, j + 1, k), at(i + 1, j + 1, k), t[0]);
    let c01 = l(at(i, j, k + 1), at(i + 1, j, k + 1), t[0]);
    let c11 = l(at(i, j + 1, k + 1), at(i + 1, j + 1, k + 1), t[0]);
    l(l(c00, c10, t[1]), l(c01, c11, t[1]), t[2])
}

/// Renders `channels` (decoded or float, by name) with `classifier`; RGB8 pixels, rows from the top.
pub fn render(channels: &BTreeMap<String, Volume>, classifier: &Classifier, cam: &Camera) -> Vec<u8> {
    let Some(any) = channels.values().next() else { return vec![0; cam.size * cam.size * 3] };
    let g = &any.geometry;
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
    let l_min = g.min_spacing();
    let step_world = cam.step * l_min;
    let steps = (2.0 * radius / step_world).ceil() as usize;
    let get = |n: &str| channels.get(n);
    let (nx, ny, nz, gch) = (get("nx"), get("ny"), get("nz"), get("g"));
    let g_max = gch.and_then(|v| v.finite_range()).map_or(1.0, |r| r.1.max(1e-12) as f64);
    let light = [-dir[0] + 0.3 * up[0], -dir[1] + 0.3 * up[1], -dir[2] + 0.3 * up[2]];
    let ll = (light.iter().map(|x| x * x).sum::<f64>()).sqrt();
    let light = light.map(|x| x / ll);
    let half = [(light[0] - dir[0]) / 2.0, (light[1] - dir[1]) / 2.0, (light[2] - dir[2]) / 2.0];
    let hl = (half.iter().map(|x| x * x).sum::<f64>()).sqrt().max(1e-12);
    let half = half.map(|x| x / hl);
    let mut img = vec![0u8; cam.size * cam.size * 3];
    img.par_chunks_mut(cam.size * 3).enumerate().for_each(|(row, out)| {
        for col in 0..cam.size {
            let (u, v) = (
                ((col as f64 + 0.5) / cam.size as f64 * 2.0 - 1.0) * radius,
                (1.0 - (row as f64 + 0.5) / cam.size as f64 * 2.0) * radius,
            );
            let origin = [0, 1, 2].map(|a| centre[a] + u * right[a] + v * up[a] - radius * dir[a]);
            let (mut rgb, mut alpha) = ([0f64; 3], 0f64);
            let mut previous: Option<Vec<f64>> = None;
            for s in 0..steps {
                let pw = [0, 1, 2].map(|a| origin[a] + (s as f64 + 0.5) * step_world * dir[a]);
                if (0..3).any(|a| pw[a] < 0.0 || pw[a] > ext[a]) {
                    previous = None;
                    continue;
                }
                let p = [0, 1, 2].map(|a| pw[a] / g.spacing[a]);
                let sample = |n: &str| get(n).map_or(0.0, |v| trilinear(v, p));
                let ([r, gr, b], a) = match classifier {
                    Classifier::Lut(t) => {
                        let coords: Vec<f32> = t.axes.iter().map(|(c, ..)| sample(c)).collect();
                        let [r, gr, b, a] = lookup(t, &coords);
                        // opacity correction: the TF's opacity is per voxel (L_min) of path
                        ([r, gr, b], 1.0 - (1.0 - (a as f64).min(0.999)).powf(cam.step))
                    }
                    Classifier::Distance { alpha_u, alpha_d } => {
                        let d = sample("distance");
                        let ad = if d >= 0.0 { lookup(alpha_d, &[d])[3] } else { 0.0 };
                        let u = alpha_u
                            .as_ref()
                            .map_or([1.0, 1.0, 1.0, 1.0], |t| lookup(t, &[sample("v"), sample("g_hit")]));
                        ([u[0], u[1], u[2]], 1.0 - (1.0 - ((u[3] * ad) as f64).min(0.999)).powf(cam.step))
                    }
                    Classifier::Peak { peak_table, preintegration, find_peaks } => {
                        let v1 = sample("v");
                        let v0 =
                            if *find_peaks { previous.replace(vec![v1 as f64]).map(|p| p[0] as f32) } else { None };
                        let at = match v0 {
                            Some(v0) => {
                                let peak = lookup(peak_table, &[v0, v1])[3];
                                if peak >= 0.0 { peak } else { v1 }
                            }
                            None => v1,
                        };
                        let [r, gr, b, a] = lookup(preintegration, &[at, at]);
                        ([r, gr, b], 1.0 - (1.0 - (a as f64).min(0.999)).powf(cam.step))
                    }
                    Classifier::Chord { tf, cells_per_sample, find_peaks } => {
                        let f1: Vec<f32> = tf.axes.iter().map(|(c, ..)| sample(c)).collect();
                        let f0 =
                            if *find_peaks { previous.replace(f1.iter().map(|&x| x as f64).collect()) } else { None };
                        let [r, gr, b, a] = match f0 {
                            Some(f0) => {
                                let f0: Vec<f32> = f0.iter().map(|&x| x as f32).collect();
                                chord_peak(tf, &f0, &f1, *cells_per_sample)
                            }
                            None => lookup(tf, &f1),
                        };
                        ([r, gr, b], 1.0 - (1.0 - (a as f64).min(0.999)).powf(cam.step))
                    }
                    Classifier::Gaussian { primitives, channels: names, analytic } => {
                        let v: Vec<f64> = names.iter().map(|c| sample(c) as f64).collect();
                        let from = if *analytic { previous.replace(v.clone()) } else { None };
                        let (mut depth, mut c) = (0.0, [0.0f64; 3]);
                        for gp in primitives {
                            let rho = match &from {
                                Some(v0) => gp.segment_integral(v0, &v),
                                None => gp.density(&v),
                            };
                            depth += gp.alpha_max * rho;
                            for k in 0..3 {
                                c[k] += gp.alpha_max * rho * gp.colour[k];
                            }
                        }
                        let colour = if depth > 0.0 { c.map(|x| (x / depth) as f32) } else { [0.0; 3] };
                        // eq. 15: alpha = 1 - exp(-l sum tau_i rho'_i), l = the step in voxels
                        (colour, 1.0 - (-depth * cam.step).exp())
                    }
                };
                if a <= 0.0 {
                    continue;
                }
                let mut colour = [r as f64, gr as f64, b as f64];
                if let (Some(nxv), Some(nyv), Some(nzv)) = (nx, ny, nz) {
                    let n = [trilinear(nxv, p) as f64, trilinear(nyv, p) as f64, trilinear(nzv, p) as f64];
                    let nl = (n.iter().map(|x| x * x).sum::<f64>()).sqrt();
                    if nl > 1e-6 {
                        let n = n.map(|x| x / nl);
                        let diffuse = (n[0] * light[0] + n[1] * light[1] + n[2] * light[2]).abs();
                        let spec = (n[0] * half[0] + n[1] * half[1] + n[2] * half[2]).abs().powi(32);
                        let w = gch.map_or(1.0, |gv| {
                            let t = 1.0 - (trilinear(gv, p) as f64 / g_max).clamp(0.0, 1.0);
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
