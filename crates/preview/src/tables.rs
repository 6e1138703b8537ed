//! What a transfer function's tables give at a point of their domain: the
//! nearest cell's entry, opacities corrected for the ray's step, a product
//! of factor tables, the peaks composited along a segment and the chord
//! search of multidimensional peak finding.

use crate::load::Table;

/// The highest-opacity RGBA of `eval` on the chord from `f0` to `f1` in the
/// domain of `axes` (a table's, or a product's axes one after another),
/// sampled every `cells_per_sample` cells (both ends included), and the chord
/// parameter s in [0, 1) of that peak when it is not at `f1` (the sample
/// itself). `opacity` is `eval`'s opacity alone (what the search compares;
/// the colour is looked up once, at the peak).
pub(crate) fn chord_peak(
    axes: &[(String, usize, f64, f64)],
    eval: &dyn Fn(&[f32]) -> [f32; 4],
    opacity: &dyn Fn(&[f32]) -> f32,
    f0: &[f32],
    f1: &[f32],
    cells_per_sample: f64,
) -> ([f32; 4], Option<f32>) {
    let cells: f64 = axes
        .iter()
        .enumerate()
        .map(|(k, (_, n, min, max))| ((f1[k] - f0[k]) as f64 / (max - min) * *n as f64).powi(2))
        .sum::<f64>()
        .sqrt();
    let samples = ((cells / cells_per_sample).ceil() as usize).clamp(1, 4096);
    let mut best = opacity(f1);
    let mut at = None;
    // (chords have 2 to 4 coordinates: no allocation per sample)
    let mut point = [0f32; 4];
    let point = &mut point[..f0.len()];
    let mut peak = [0f32; 4];
    for k in 0..samples {
        let s = k as f32 / samples as f32;
        for (p, (a, b)) in point.iter_mut().zip(f0.iter().zip(f1)) {
            *p = a + s * (b - a);
        }
        let alpha = opacity(point);
        if alpha > best {
            best = alpha;
            at = Some(s);
            peak[..point.len()].copy_from_slice(point);
        }
    }
    match at {
        Some(_) => (eval(&peak[..f0.len()]), at),
        None => (eval(f1), None),
    }
}

/// The peaks `pk` (v values in ray order, -1 for none) composited front to
/// back, each with the TF's colour and opacity (`preintegration`'s diagonal)
/// at its value: one colour and opacity for the segment.
pub(crate) fn composite_peaks(preintegration: &Table, pk: &[f32; 4]) -> ([f32; 3], f64) {
    let (mut rgb, mut alpha) = ([0f64; 3], 0f64);
    for &v in pk.iter().filter(|v| **v >= 0.0) {
        let (colour, a) = unpremultiplied(lookup(preintegration, &[v, v]));
        let a = a.min(0.999);
        for (acc, c) in rgb.iter_mut().zip(colour) {
            *acc += (1.0 - alpha) * a * c as f64;
        }
        alpha += (1.0 - alpha) * a;
    }
    let colour = if alpha > 0.0 { rgb.map(|c| (c / alpha) as f32) } else { [0.0; 3] };
    (colour, alpha)
}

/// RGBA of a product TF at `coords` (each factor's coordinates one after
/// another): the opacities multiply, the colour is the first factor's.
pub(crate) fn product_lookup(factors: &[Table], coords: &[f32]) -> [f32; 4] {
    let (mut at, mut out) = (0, [0.0, 0.0, 0.0, 1.0]);
    for (k, t) in factors.iter().enumerate() {
        let n = t.axes.len();
        let rgba = lookup(t, &coords[at..at + n]);
        at += n;
        if k == 0 {
            out[..3].copy_from_slice(&rgba[..3]);
        }
        out[3] *= rgba[3];
    }
    out
}

/// A pre-integration entry (colour premultiplied by its opacity) as colour and opacity.
pub(crate) fn unpremultiplied([r, g, b, a]: [f32; 4]) -> ([f32; 3], f64) {
    if a > 0.0 { ([r / a, g / a, b / a], a as f64) } else { ([0.0; 3], 0.0) }
}

pub(crate) fn lookup(t: &Table, coords: &[f32]) -> [f32; 4] {
    lookup_entry(t, table_index(t, coords))
}

/// RGBA of entry `idx` of `t` (white for a table of opacities).
pub(crate) fn lookup_entry(t: &Table, idx: usize) -> [f32; 4] {
    let c = t.components;
    if c == 4 {
        [t.values[idx * 4], t.values[idx * 4 + 1], t.values[idx * 4 + 2], t.values[idx * 4 + 3]]
    } else {
        [1.0, 1.0, 1.0, t.values[idx]]
    }
}

/// The opacity of a table's entry (per voxel of path) corrected for a step
/// of `step_vox` voxels: 1 - (1 - a)^step, with a capped at 0.999.
pub(crate) fn corrected_opacity(a: f32, step_vox: f64) -> f64 {
    1.0 - (1.0 - (a as f64).min(0.999)).powf(step_vox)
}

/// [`corrected_opacity`] of every entry of `t`, by entry index.
pub(crate) fn corrected_opacities(t: &Table, step_vox: f64) -> Vec<f64> {
    let alpha = |e: usize| if t.components == 4 { t.values[e * 4 + 3] } else { t.values[e] };
    (0..t.values.len() / t.components.max(1)).map(|e| corrected_opacity(alpha(e), step_vox)).collect()
}

/// The index of the entry of `t` at `coords` (the nearest cell, clamped).
pub(crate) fn table_index(t: &Table, coords: &[f32]) -> usize {
    let mut idx = 0usize;
    let mut stride = 1usize;
    for (k, (_, cells, min, max)) in t.axes.iter().enumerate() {
        let x = (coords[k] as f64 - min) / (max - min) * *cells as f64;
        // clamped first, so truncation is floor (NaN casts to cell 0)
        let i = x.clamp(0.0, (*cells - 1) as f64) as usize;
        idx += i * stride;
        stride *= cells;
    }
    idx
}
