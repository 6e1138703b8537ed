//! 3D Slicer's volume property file (`.vp`): separable transfer functions
//! (scalar opacity, gradient opacity, colour) and the shading, in the layout
//! Slicer's volume-rendering module documents: one item per line
//! (interpolation type, shading on, diffuse, ambient, specular, specular
//! power), then each function as a count of numbers followed by its control
//! points ((x, opacity) pairs; (x, r, g, b) for colour).

use crate::tf2d::{Marginals, Tf2d};

/// Lighting shared by the exported scripts and the `.vp`: the preview's
/// ambient 0.25, diffuse 0.75, specular 0.3 with power 32.
pub const AMBIENT: f64 = 0.25;
/// Diffuse reflection.
pub const DIFFUSE: f64 = 0.75;
/// Specular reflection.
pub const SPECULAR: f64 = 0.3;
/// Specular power.
pub const SPECULAR_POWER: f64 = 32.0;

/// The `.vp` text of `tf`'s marginals `m`: scalar opacity and colour at the
/// X cell centres, gradient opacity at the Y cell centres; linear
/// interpolation, shading on when `shade`.
pub fn volume_property(tf: &Tf2d, m: &Marginals, shade: bool) -> String {
    let line = |items: &[f64]| items.iter().map(|&v| number(v)).collect::<Vec<_>>().join(" ") + "\n";
    let counted = |n: usize, point: &dyn Fn(usize) -> Vec<f64>| {
        let items: Vec<f64> = (0..n).flat_map(point).collect();
        format!("{} {}", items.len(), line(&items))
    };
    let mut out = String::new();
    for setting in [1.0, if shade { 1.0 } else { 0.0 }, DIFFUSE, AMBIENT, SPECULAR, SPECULAR_POWER] {
        out += &line(&[setting]);
    }
    out += &counted(tf.x.cells, &|i| vec![tf.x.centre(i), m.scalar_opacity[i]]);
    out += &counted(tf.y.cells, &|j| vec![tf.y.centre(j), m.gradient_opacity[j]]);
    out += &counted(tf.x.cells, &|i| {
        let c = m.colour[i];
        vec![tf.x.centre(i), c[0], c[1], c[2]]
    });
    out
}

/// Integers without a fraction (as Slicer writes counts and flags), other
/// numbers in their shortest round-trip form.
fn number(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 { format!("{}", v as i64) } else { format!("{v:?}") }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tf2d::{TfAxis, marginals};

    #[test]
    fn the_file_has_six_settings_then_three_counted_functions() {
        let axis = |c: &str, n| TfAxis { channel: c.into(), cells: n, min: 0.0, max: n as f64 };
        let tf = Tf2d {
            source: "tf2d".into(),
            x: axis("v", 2),
            y: axis("g", 3),
            rgba: (0..6).map(|c| [1.0, 0.5, 0.0, c as f32 / 10.0]).collect(),
            approximation: None,
        };
        let text = volume_property(&tf, &marginals(&tf), true);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(&lines[..6], ["1", "1", "0.75", "0.25", "0.3", "32"]);
        assert_eq!(lines[6], "4 0.5 0.4000000059604645 1.5 0.5");
        assert!(lines[7].starts_with("6 0.5 0.2") && lines[7].ends_with("2.5 1"), "{}", lines[7]);
        assert!(lines[8].starts_with("8 0.5 1 0.5 0 1.5"), "{}", lines[8]);
        assert_eq!(lines.len(), 9);
    }
}
