//! The pack's transfer function as one 2D RGBA table, the form VTK's 2D
//! transfer-function mode and its marginals (Slicer) can use.

use mdtf_preview::{LoadedPack, Table};

/// One axis of the 2D table: the channel and the range its cells cover
/// (cell i spans [min + i w, min + (i + 1) w), w = (max - min) / cells).
#[derive(Debug, Clone, PartialEq)]
pub struct TfAxis {
    /// Channel name in the pack (e.g. "v", "g", "g_hit", "inv_g").
    pub channel: String,
    /// Cells along the axis.
    pub cells: usize,
    /// Lower edge of the first cell, channel units.
    pub min: f64,
    /// Upper edge of the last cell, channel units.
    pub max: f64,
}

impl TfAxis {
    /// Width of one cell, channel units.
    pub fn cell_width(&self) -> f64 {
        (self.max - self.min) / self.cells as f64
    }

    /// Centre of cell `i`, channel units.
    pub fn centre(&self, i: usize) -> f64 {
        self.min + (i as f64 + 0.5) * self.cell_width()
    }
}

/// A 2D RGBA transfer function: colour in [0, 1], opacity in [0, 1] per
/// smallest grid spacing (L_min) of path, as the pack's tables define it.
#[derive(Debug, Clone, PartialEq)]
pub struct Tf2d {
    /// The pack table it comes from.
    pub source: String,
    /// X axis (VTK's scalar array).
    pub x: TfAxis,
    /// Y axis (VTK's second array of the 2D mode).
    pub y: TfAxis,
    /// RGBA per cell, x fastest.
    pub rgba: Vec<[f32; 4]>,
    /// What of the pack's classification the table leaves out, if anything.
    pub approximation: Option<String>,
}

impl Tf2d {
    /// RGBA of cell (i, j).
    pub fn at(&self, i: usize, j: usize) -> [f32; 4] {
        self.rgba[j * self.x.cells + i]
    }
}

/// Tables tried in order: those that are 2D RGBA (or opacity) tables by construction.
const TWO_D_TABLES: [&str; 3] = ["tf2d", "tf2d_default", "alpha_u"];

/// The 2D transfer function of `pack`: its (v, g) table (slicer-3dtf: tf2d, the
/// separable part of tf3d, or the histogram volume's tf2d_default), its
/// alpha_u over (v, g_hit) (distance-tf), or its tf2d over (v, inv_g)
/// (peak-finding); a 3D table alone is reduced to its first two axes by the
/// most opaque cell along the third. None when the pack has no such table.
pub fn pack_tf2d(pack: &LoadedPack) -> Option<Tf2d> {
    let profile = pack.manifest.profile.as_str();
    for name in TWO_D_TABLES {
        let Some(t) = pack.tables.get(name).filter(|t| t.axes.len() == 2) else { continue };
        let approximation = match (profile, name) {
            ("slicer-3dtf", "tf2d") if pack.tables.contains_key("tf3d") && !emphasis_is_constant(pack) => Some(
                "the boundary emphasis over f2 (tf_f2, the third axis of tf3d) is left out: VTK has no 3D transfer function"
                    .to_string(),
            ),
            ("distance-tf", _) => Some(
                "alpha_d(distance) is left out: VTK's 2D mode has one table over two arrays, so only alpha_u(v, g_hit) \
                 classifies"
                    .to_string(),
            ),
            _ => None,
        };
        return Some(from_table(name, t, approximation));
    }
    if let Some(t) = pack.tables.get("tf3d").filter(|t| t.axes.len() == 3) {
        return Some(reduce_third_axis("tf3d", t));
    }
    let alpha_d = pack.tables.get("alpha_d").filter(|t| t.axes.len() == 1)?;
    let v = pack.manifest.channels.iter().find(|e| e.name == "v")?;
    Some(distance_only(alpha_d, TfAxis { channel: v.name.clone(), cells: 1, min: v.range[0], max: v.range[1] }))
}

/// A distance-tf pack without alpha_u classifies white with opacity
/// alpha_d(d) where d >= 0 and 0 elsewhere (d < 0: no boundary found): a
/// table constant along `x` (v, whose gradient VTK shades with, as the
/// pack's normals are) and over d along Y, with one zero cell prepended
/// below 0 (values further below take it too, as edge cells do).
fn distance_only(alpha_d: &Table, x: TfAxis) -> Tf2d {
    let d = axis(&alpha_d.axes[0]);
    let w = d.cell_width();
    let y = TfAxis { channel: d.channel.clone(), cells: d.cells + 1, min: d.min - w, max: d.max };
    let rgba = std::iter::once([1.0, 1.0, 1.0, 0.0]).chain((0..d.cells).map(|i| rgba_of(alpha_d, i))).collect();
    Tf2d { source: "alpha_d".into(), x, y, rgba, approximation: None }
}

/// Whether the slicer pack's f'' factor (tf_f2) is 1 everywhere, so that its
/// tf3d is its tf2d repeated along f''.
fn emphasis_is_constant(pack: &LoadedPack) -> bool {
    pack.tables.get("tf_f2").is_some_and(|t| t.values.iter().all(|&v| v == 1.0))
}

fn axis((channel, cells, min, max): &(String, usize, f64, f64)) -> TfAxis {
    TfAxis { channel: channel.clone(), cells: *cells, min: *min, max: *max }
}

fn rgba_of(t: &Table, cell: usize) -> [f32; 4] {
    if t.components == 4 {
        [t.values[cell * 4], t.values[cell * 4 + 1], t.values[cell * 4 + 2], t.values[cell * 4 + 3]]
    } else {
        // an opacity-only table is white, as the preview draws it
        [1.0, 1.0, 1.0, t.values[cell * t.components]]
    }
}

fn from_table(name: &str, t: &Table, approximation: Option<String>) -> Tf2d {
    let (x, y) = (axis(&t.axes[0]), axis(&t.axes[1]));
    let rgba = (0..x.cells * y.cells).map(|c| rgba_of(t, c)).collect();
    Tf2d { source: name.into(), x, y, rgba, approximation }
}

/// A 3D table to its first two axes: per (x, y) cell the RGBA of the most
/// opaque cell along the third axis.
fn reduce_third_axis(name: &str, t: &Table) -> Tf2d {
    let (x, y) = (axis(&t.axes[0]), axis(&t.axes[1]));
    let third = &t.axes[2];
    let plane = x.cells * y.cells;
    let rgba = (0..plane)
        .map(|c| {
            (0..third.1)
                .map(|k| rgba_of(t, k * plane + c))
                .fold([1.0, 1.0, 1.0, 0.0], |best, v| if v[3] > best[3] { v } else { best })
        })
        .collect();
    Tf2d {
        source: name.into(),
        x,
        y,
        rgba,
        approximation: Some(format!(
            "{name} over ({}, {}, {}) reduced to ({}, {}) by the most opaque {} cell: VTK has no 3D transfer function",
            t.axes[0].0, t.axes[1].0, third.0, t.axes[0].0, t.axes[1].0, third.0
        )),
    }
}

/// The separable approximation of a 2D TF over (v, g) for a volume property
/// of separable functions (3D Slicer): per X cell the scalar opacity
/// `max_j alpha(i, j)` and the opacity-weighted colour `sum_j alpha c / sum_j
/// alpha` (white where the column is transparent); per Y cell the gradient
/// opacity `max_i alpha(i, j) / max alpha` (0 for a transparent table).
#[derive(Debug, Clone, PartialEq)]
pub struct Marginals {
    /// Scalar opacity at each X cell centre.
    pub scalar_opacity: Vec<f64>,
    /// Colour at each X cell centre.
    pub colour: Vec<[f64; 3]>,
    /// Gradient opacity at each Y cell centre.
    pub gradient_opacity: Vec<f64>,
}

/// The marginals of `tf` (see [`Marginals`]).
pub fn marginals(tf: &Tf2d) -> Marginals {
    let (nx, ny) = (tf.x.cells, tf.y.cells);
    let mut scalar_opacity = vec![0.0; nx];
    let mut colour = vec![[1.0; 3]; nx];
    for (i, (s, c)) in scalar_opacity.iter_mut().zip(colour.iter_mut()).enumerate() {
        let (mut weight, mut sum) = (0.0f64, [0.0f64; 3]);
        for j in 0..ny {
            let p = tf.at(i, j);
            let a = p[3] as f64;
            *s = f64::max(*s, a);
            weight += a;
            for k in 0..3 {
                sum[k] += a * p[k] as f64;
            }
        }
        if weight > 0.0 {
            *c = sum.map(|x| x / weight);
        }
    }
    let peak = scalar_opacity.iter().copied().fold(0.0, f64::max);
    let gradient_opacity = (0..ny)
        .map(|j| {
            let m = (0..nx).map(|i| tf.at(i, j)[3] as f64).fold(0.0, f64::max);
            if peak > 0.0 { m / peak } else { 0.0 }
        })
        .collect();
    Marginals { scalar_opacity, colour, gradient_opacity }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(axes: &[(&str, usize)], f: impl Fn(&[usize]) -> [f32; 4]) -> Table {
        let sizes: Vec<usize> = axes.iter().map(|a| a.1).collect();
        let cells: usize = sizes.iter().product();
        let mut values = Vec::new();
        for c in 0..cells {
            let mut idx = Vec::new();
            let mut rest = c;
            for &n in &sizes {
                idx.push(rest % n);
                rest /= n;
            }
            values.extend(f(&idx));
        }
        Table { axes: axes.iter().map(|(n, s)| (n.to_string(), *s, 0.0, 1.0)).collect(), components: 4, values }
    }

    #[test]
    fn a_3d_table_keeps_the_most_opaque_cell_along_its_third_axis() {
        let t = table(&[("v", 3), ("g", 2), ("f2", 4)], |i| {
            [i[2] as f32 / 4.0, 0.0, 0.0, ((i[0] + i[2]) % 4) as f32 / 4.0]
        });
        let tf = reduce_third_axis("tf3d", &t);
        for i in 0..3 {
            for j in 0..2 {
                // brute force: alpha (i + k) % 4 / 4 is largest where (i + k) % 4 == 3
                let k = (3 + 4 - i) % 4;
                assert_eq!(tf.at(i, j), [k as f32 / 4.0, 0.0, 0.0, 0.75], "cell {i},{j}");
            }
        }
        assert!(tf.approximation.is_some());
    }

    #[test]
    fn marginals_are_column_maxima_weighted_colours_and_normalised_row_maxima() {
        // alpha(i, j) = (i + 1) (j + 1) / 12 over 3 x 4 cells; red where j is odd
        let t = table(&[("v", 3), ("g", 4)], |i| {
            let red = if i[1] % 2 == 1 { 1.0 } else { 0.0 };
            [red, 1.0 - red, 0.0, ((i[0] + 1) * (i[1] + 1)) as f32 / 12.0]
        });
        let m = marginals(&from_table("tf2d", &t, None));
        for i in 0..3 {
            assert!((m.scalar_opacity[i] - (i + 1) as f64 * 4.0 / 12.0).abs() < 1e-6);
            // weights (j + 1) over j = 0..3: red share (2 + 4) / 10
            assert!((m.colour[i][0] - 0.6).abs() < 1e-6 && (m.colour[i][1] - 0.4).abs() < 1e-6);
        }
        for j in 0..4 {
            assert!((m.gradient_opacity[j] - (j + 1) as f64 / 4.0).abs() < 1e-6);
        }
    }
}
