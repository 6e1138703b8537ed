//! Transfer functions from a JSON file, rasterised into lookup tables.
//!
//! Widgets (Kniss et al. 9.4; every opacity is in [0, 1] before `alpha` scales it):
//! * `triangle` (Levoy's iso-contour widget with thresholds and shear): for
//!   g_low <= g <= g_high, centre c = v0 + shear g, half-width h = width g / g_high,
//!   opacity alpha max(0, 1 - |v - c| / h); 0 outside the g thresholds.
//! * `rectangle` with centre and half-sizes on (v, g): with dv = (v - cv)/sv and
//!   dg = (g - cg)/sg inside |dv|, |dg| <= 1: `constant` 1, `ellipsoid`
//!   max(0, 1 - dv^2 - dg^2), `ramp` (dv + 1)/2 (rising along v), `tent` 1 - |dv|,
//!   `pyramid` 1 - max(|dv|, |dg|); 0 outside the rectangle.
//! * `gaussian`: alpha_max exp(-||K ((v, g) - c)||^2) ([`GaussianPrimitive`]).
//!
//! Widgets combine as in the Gaussian-TF paper (eq. 3): opacities add
//! (clamped to 1), colours are the opacity-weighted mean. The f'' axis
//! carries the boundary-emphasis slider e in [0, 1]: the opacity is scaled
//! by 1 - (1 - e) |f''| / max|f''| (e = 0: zero at the f'' extremes; e = 1: constant).
//!
//! Along f'' each widget may also have its own extent (`"f2": [lo, hi]`,
//! the third side of the chapter's 3D box widget, section 9.4.5: it adds
//! nothing outside) and its own `boundary_emphasis` (the file's is the
//! default). The 3D table is then evaluated per widget at every cell centre,
//! a true 3D table; it is the separable product tf2d x tf_f2 only when no
//! widget has either, and the manifest says which. Its f'' axis has an odd
//! number of cells, so that on a symmetric range a cell centre is f'' = 0.

use crate::gaussian::GaussianPrimitive;
use crate::product_tf::{FactorShape, PRODUCT_MAX_CHANNELS, ProductFactor, ProductTf, check_factor};
use serde::{Deserialize, Serialize};

/// Rectangle falloff.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Falloff {
    /// 1 everywhere inside.
    Constant,
    /// max(0, 1 - dv^2 - dg^2).
    Ellipsoid,
    /// (dv + 1) / 2.
    Ramp,
    /// 1 - |dv|.
    Tent,
    /// 1 - max(|dv|, |dg|).
    Pyramid,
}

/// Levoy's triangle with g thresholds and shear.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Triangle {
    /// Data value of the apex (g = 0).
    pub v0: f64,
    /// Half-width in v at g = g_high.
    pub width: f64,
    /// Lower g threshold.
    #[serde(default)]
    pub g_low: f64,
    /// Upper g threshold (the top of the triangle).
    pub g_high: f64,
    /// Shift of the centre in v per unit g.
    #[serde(default)]
    pub shear: f64,
    /// Peak opacity.
    pub alpha: f64,
    /// RGB colour, 0..1.
    pub colour: [f64; 3],
}

/// Rectangle with a falloff.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rectangle {
    /// Centre (v, g).
    pub centre: [f64; 2],
    /// Half-sizes (v, g).
    pub half_size: [f64; 2],
    /// How opacity falls off inside.
    pub falloff: Falloff,
    /// Peak opacity.
    pub alpha: f64,
    /// RGB colour, 0..1.
    pub colour: [f64; 3],
}

/// A classification widget on the (v, g) plane; in the file, an object with
/// `"type": "triangle" | "rectangle" | "gaussian"` and that widget's fields.
#[derive(Debug, Clone, PartialEq)]
pub enum Widget {
    /// Levoy's triangle.
    Triangle(Triangle),
    /// Rectangle.
    Rectangle(Rectangle),
    /// Gaussian primitive over (v, g).
    Gaussian(GaussianPrimitive),
}

impl Widget {
    /// Opacity and colour at (v, g).
    pub fn eval(&self, v: f64, g: f64) -> (f64, [f64; 3]) {
        match self {
            Widget::Triangle(Triangle { v0, width, g_low, g_high, shear, alpha, colour }) => {
                if g < *g_low || g > *g_high || *g_high <= 0.0 {
                    return (0.0, *colour);
                }
                let (c, h) = (v0 + shear * g, width * g / g_high);
                let a = if h > 0.0 { (1.0 - (v - c).abs() / h).max(0.0) } else { 0.0 };
                (alpha * a, *colour)
            }
            Widget::Rectangle(Rectangle { centre, half_size, falloff, alpha, colour }) => {
                let (dv, dg) = ((v - centre[0]) / half_size[0], (g - centre[1]) / half_size[1]);
                if dv.abs() > 1.0 || dg.abs() > 1.0 {
                    return (0.0, *colour);
                }
                let a = match falloff {
                    Falloff::Constant => 1.0,
                    Falloff::Ellipsoid => (1.0 - dv * dv - dg * dg).max(0.0),
                    Falloff::Ramp => (dv + 1.0) / 2.0,
                    Falloff::Tent => 1.0 - dv.abs(),
                    Falloff::Pyramid => 1.0 - dv.abs().max(dg.abs()),
                };
                (alpha * a, *colour)
            }
            Widget::Gaussian(p) => (p.alpha_max * p.density(&[v, g]), p.colour),
        }
    }
}

/// Widgets' (opacity, colour) at one point combined as the Gaussian-TF
/// paper's eq. 3 does: opacities add (clamped to 1), colours are the opacity-weighted mean.
pub(crate) fn combine(parts: impl Iterator<Item = (f64, [f64; 3])>) -> [f64; 4] {
    let (mut a, mut c) = (0.0, [0.0; 3]);
    for (wa, wc) in parts {
        a += wa;
        for k in 0..3 {
            c[k] += wa * wc[k];
        }
    }
    if a > 0.0 {
        c = c.map(|x| x / a);
    }
    [c[0], c[1], c[2], a.min(1.0)]
}

/// A widget with its extent along f'' and its own boundary emphasis, as placed in a TF file.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacedWidget {
    /// The widget's shape on the (v, g) plane.
    pub shape: Widget,
    /// f'' interval [lo, hi] the widget covers (None: all of it).
    pub f2: Option<[f64; 2]>,
    /// The widget's boundary-emphasis slider (None: the file's).
    pub boundary_emphasis: Option<f64>,
}

/// Cells of the 3D table along f'' (odd: one centre at f'' = 0 on a symmetric range).
pub const TF3D_F2_CELLS: usize = 9;

/// A transfer-function file.
#[derive(Debug, Clone, PartialEq)]
pub struct TfFile {
    /// Range of v covered by the tables.
    pub v_range: [f64; 2],
    /// Range of g covered by the tables.
    pub g_range: [f64; 2],
    /// Range of f'' covered by the tables (symmetric use: |f''| / max |f''|).
    pub f2_range: [f64; 2],
    /// Boundary-emphasis slider e in [0, 1].
    pub boundary_emphasis: f64,
    /// The widgets.
    pub widgets: Vec<PlacedWidget>,
    /// Optional 1D TF over v_range: (r, g, b, tau) samples, for the peak and pre-integration tables.
    pub tf1d: Option<Vec<[f64; 4]>>,
    /// Optional separable product TF over named channels ([`crate::product_tf`]).
    pub product: Option<ProductTf>,
}

/// The file's top level, widgets still raw so each can be checked against its own type.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTf {
    #[serde(default)]
    v_range: Option<[f64; 2]>,
    #[serde(default)]
    g_range: Option<[f64; 2]>,
    #[serde(default = "default_f2_range")]
    f2_range: [f64; 2],
    #[serde(default = "one")]
    boundary_emphasis: f64,
    #[serde(default)]
    widgets: Vec<serde_json::Value>,
    #[serde(default)]
    tf1d: Option<Vec<[f64; 4]>>,
    #[serde(default)]
    product: Option<Vec<RawFactor>>,
}

/// A product factor as written, its widgets still raw.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFactor {
    channels: Vec<String>,
    ranges: Vec<[f64; 2]>,
    #[serde(default)]
    widgets: Option<Vec<serde_json::Value>>,
    #[serde(default)]
    ramp: Option<[f64; 2]>,
}

fn default_f2_range() -> [f64; 2] {
    [-1.0, 1.0]
}

fn one() -> f64 {
    1.0
}

/// Parses a TF file; errors name the JSON path of the bad field.
/// `v_range` and `g_range` may be left out only when the file has a `product`.
pub fn parse_tf(text: &str) -> Result<TfFile, String> {
    let de = &mut serde_json::Deserializer::from_str(text);
    let raw: RawTf = serde_path_to_error::deserialize(de).map_err(|e| format!("at {}: {}", e.path(), e.inner()))?;
    let mut widgets = Vec::with_capacity(raw.widgets.len());
    for (i, w) in raw.widgets.into_iter().enumerate() {
        let mut w = w;
        let at = |key: &str, e: serde_json::Error| format!("at widgets[{i}].{key}: {e}");
        let take = |w: &mut serde_json::Value, key: &str| w.as_object_mut().and_then(|o| o.remove(key));
        let f2: Option<[f64; 2]> =
            take(&mut w, "f2").map(serde_json::from_value).transpose().map_err(|e| at("f2", e))?;
        let emphasis: Option<f64> = take(&mut w, "boundary_emphasis")
            .map(serde_json::from_value)
            .transpose()
            .map_err(|e| at("boundary_emphasis", e))?;
        if let Some([lo, hi]) = f2
            && !(lo.is_finite() && hi.is_finite() && lo < hi)
        {
            return Err(format!("at widgets[{i}].f2: [{lo}, {hi}] must be increasing"));
        }
        if let Some(e) = emphasis
            && !(0.0..=1.0).contains(&e)
        {
            return Err(format!("at widgets[{i}].boundary_emphasis: {e} is not in [0, 1]"));
        }
        let shape = parse_widget(w, &format!("widgets[{i}]"))?;
        widgets.push(PlacedWidget { shape, f2, boundary_emphasis: emphasis });
    }
    let product = raw.product.map(parse_product).transpose()?;
    let range = |name: &str, r: Option<[f64; 2]>| match r {
        Some(r) => Ok(r),
        // a product-only file: the (v, g) tables are not written, any range does
        None if product.is_some() => Ok([0.0, 1.0]),
        None => Err(format!("at {name}: missing (give v_range and g_range, or a product)")),
    };
    let tf = TfFile {
        v_range: range("v_range", raw.v_range)?,
        g_range: range("g_range", raw.g_range)?,
        f2_range: raw.f2_range,
        boundary_emphasis: raw.boundary_emphasis,
        widgets,
        tf1d: raw.tf1d,
        product,
    };
    if tf.tf1d.as_ref().is_some_and(|t| t.len() < 2) {
        return Err("at tf1d: give at least 2 samples".into());
    }
    if !(0.0..=1.0).contains(&tf.boundary_emphasis) {
        return Err(format!("at boundary_emphasis: {} is not in [0, 1]", tf.boundary_emphasis));
    }
    for (name, r) in [("v_range", tf.v_range), ("g_range", tf.g_range), ("f2_range", tf.f2_range)] {
        if r[1].is_nan() || r[0].is_nan() || r[1] <= r[0] {
            return Err(format!("at {name}: [{}, {}] must be increasing", r[0], r[1]));
        }
    }
    Ok(tf)
}

/// One widget object (`"type"` and that type's fields), checked; `at` is its JSON path for messages.
fn parse_widget(mut w: serde_json::Value, at: &str) -> Result<Widget, String> {
    let kind = match w.as_object_mut().and_then(|o| o.remove("type")) {
        Some(serde_json::Value::String(k)) => k,
        _ => return Err(format!("at {at}.type: missing (triangle, rectangle or gaussian)")),
    };
    let field = |e: serde_path_to_error::Error<serde_json::Error>| format!("at {at}.{}: {}", e.path(), e.inner());
    let shape = match kind.as_str() {
        "triangle" => Widget::Triangle(serde_path_to_error::deserialize(w).map_err(field)?),
        "rectangle" => Widget::Rectangle(serde_path_to_error::deserialize(w).map_err(field)?),
        "gaussian" => Widget::Gaussian(serde_path_to_error::deserialize(w).map_err(field)?),
        other => return Err(format!("at {at}.type: unknown widget '{other}' (triangle, rectangle or gaussian)")),
    };
    check_widget(&shape).map_err(|e| format!("at {at}.{e}"))?;
    Ok(shape)
}

/// The `product` list: each factor's widgets or ramp, checked, and at most
/// [`PRODUCT_MAX_CHANNELS`] channels over all of them.
fn parse_product(raw: Vec<RawFactor>) -> Result<ProductTf, String> {
    let mut factors = Vec::with_capacity(raw.len());
    for (k, f) in raw.into_iter().enumerate() {
        let shape = match (f.widgets, f.ramp) {
            (Some(ws), None) => FactorShape::Widgets(
                ws.into_iter()
                    .enumerate()
                    .map(|(i, w)| parse_widget(w, &format!("product[{k}].widgets[{i}]")))
                    .collect::<Result<_, _>>()?,
            ),
            (None, Some(r)) => FactorShape::Ramp(r),
            _ => return Err(format!("at product[{k}]: give either widgets or ramp")),
        };
        let factor = ProductFactor { channels: f.channels, ranges: f.ranges, shape };
        check_factor(&factor).map_err(|e| format!("at product[{k}].{e}"))?;
        factors.push(factor);
    }
    if factors.is_empty() {
        return Err("at product: give at least one factor".into());
    }
    let n: usize = factors.iter().map(|f| f.channels.len()).sum();
    if n > PRODUCT_MAX_CHANNELS {
        return Err(format!("at product: {n} channels in all; at most {PRODUCT_MAX_CHANNELS}"));
    }
    Ok(ProductTf { factors })
}

/// A widget's values that would draw nothing, or something else than meant
/// (the field and why), checked once at parsing.
fn check_widget(w: &Widget) -> Result<(), String> {
    let unit = |name: &str, x: f64| {
        if (0.0..=1.0).contains(&x) { Ok(()) } else { Err(format!("{name}: {x} is not in [0, 1]")) }
    };
    let positive = |name: &str, x: f64| {
        if x.is_finite() && x > 0.0 { Ok(()) } else { Err(format!("{name}: {x} must be positive")) }
    };
    let colour = |c: &[f64; 3]| c.iter().try_for_each(|&x| unit("colour", x));
    match w {
        Widget::Triangle(t) => {
            positive("width", t.width)?;
            positive("g_high", t.g_high)?;
            if !(t.g_low.is_finite() && t.g_low >= 0.0 && t.g_low < t.g_high) {
                return Err(format!("g_low: {} must be in [0, g_high = {})", t.g_low, t.g_high));
            }
            unit("alpha", t.alpha)?;
            colour(&t.colour)
        }
        Widget::Rectangle(r) => {
            positive("half_size[0]", r.half_size[0])?;
            positive("half_size[1]", r.half_size[1])?;
            unit("alpha", r.alpha)?;
            colour(&r.colour)
        }
        Widget::Gaussian(gp) => {
            // alpha_max is an extinction per voxel of path here (it may exceed 1)
            if !(gp.alpha_max.is_finite() && gp.alpha_max >= 0.0) {
                return Err(format!("alpha_max: {} must be a non-negative number", gp.alpha_max));
            }
            colour(&gp.colour)
        }
    }
}

impl TfFile {
    /// Combined opacity and colour of all widgets at (v, g) (eq. 3 of the Gaussian-TF paper).
    pub fn eval2(&self, v: f64, g: f64) -> [f64; 4] {
        self.combine(|w| w.shape.eval(v, g))
    }

    /// Combined opacity and colour at (v, g, f''): each widget's opacity
    /// times its f'' factor (0 outside its extent, else its boundary emphasis).
    pub fn eval3(&self, v: f64, g: f64, f2: f64) -> [f64; 4] {
        self.combine(|w| {
            let (a, c) = w.shape.eval(v, g);
            let inside = w.f2.is_none_or(|[lo, hi]| (lo..=hi).contains(&f2));
            let e = w.boundary_emphasis.unwrap_or(self.boundary_emphasis);
            (if inside { a * self.emphasis_with(e, f2) } else { 0.0 }, c)
        })
    }

    /// Whether the 3D table is the product of the 2D table and the f'' factor
    /// (no widget has an f'' extent or an emphasis of its own).
    pub fn separable(&self) -> bool {
        self.widgets.iter().all(|w| w.f2.is_none() && w.boundary_emphasis.is_none())
    }

    /// Opacities add (clamped to 1), colours are the opacity-weighted mean (eq. 3).
    fn combine(&self, each: impl Fn(&PlacedWidget) -> (f64, [f64; 3])) -> [f64; 4] {
        combine(self.widgets.iter().map(each))
    }

    /// The boundary-emphasis factor at f''.
    pub fn emphasis(&self, f2: f64) -> f64 {
        self.emphasis_with(self.boundary_emphasis, f2)
    }

    /// The factor 1 - (1 - e) |f''| / max|f''| of slider value e at f''.
    fn emphasis_with(&self, e: f64, f2: f64) -> f64 {
        let m = self.f2_range[0].abs().max(self.f2_range[1].abs());
        (1.0 - (1.0 - e) * (f2.abs() / m).min(1.0)).max(0.0)
    }

    /// Centre of cell i of n over [lo, hi].
    fn at(range: [f64; 2], i: usize, n: usize) -> f64 {
        range[0] + (i as f64 + 0.5) * (range[1] - range[0]) / n as f64
    }

    /// The 2D (v, g) table, nv x ng cells (v fastest), RGBA in [0, 1] at cell centres.
    pub fn table2(&self, nv: usize, ng: usize) -> Vec<[f32; 4]> {
        let mut out = Vec::with_capacity(nv * ng);
        for j in 0..ng {
            for i in 0..nv {
                out.push(self.eval2(Self::at(self.v_range, i, nv), Self::at(self.g_range, j, ng)).map(|x| x as f32));
            }
        }
        out
    }

    /// The 1D boundary-emphasis table over f'' (n cells), the separable third axis.
    pub fn table_f2(&self, n: usize) -> Vec<f32> {
        (0..n).map(|k| self.emphasis(Self::at(self.f2_range, k, n)) as f32).collect()
    }

    /// The 3D (v, g, f'') table (v fastest) at the cell centres: the 2D table
    /// with its opacity scaled by the emphasis when [`TfFile::separable`],
    /// else [`TfFile::eval3`] per cell.
    pub fn table3(&self, nv: usize, ng: usize, nf: usize) -> Vec<[f32; 4]> {
        if !self.separable() {
            let mut out = Vec::with_capacity(nv * ng * nf);
            for k in 0..nf {
                let f2 = Self::at(self.f2_range, k, nf);
                for j in 0..ng {
                    let g = Self::at(self.g_range, j, ng);
                    for i in 0..nv {
                        out.push(self.eval3(Self::at(self.v_range, i, nv), g, f2).map(|x| x as f32));
                    }
                }
            }
            return out;
        }
        let t2 = self.table2(nv, ng);
        let e = self.table_f2(nf);
        let mut out = Vec::with_capacity(nv * ng * nf);
        for &ek in &e {
            for px in &t2 {
                out.push([px[0], px[1], px[2], px[3] * ek]);
            }
        }
        out
    }
}

impl TfFile {
    /// The 3D (v, g, f'') table 256 x 128 x 9 and the separable pair (v, g)
    /// 256 x 256 + f'' 256 of Kniss et al.'s slicer.
    pub fn slicer_luts(&self) -> Vec<crate::lut::Lut> {
        let (m3, approx) = if self.separable() {
            ("RGBA over (v, g, f2): the 2D widgets times boundary emphasis (separable: tf2d x tf_f2)", "")
        } else {
            (
                "RGBA over (v, g, f2): each widget times its f2 extent and boundary emphasis, evaluated per cell (not separable)",
                "; an approximation: the widgets' own f2 extents and emphasis are in tf3d only",
            )
        };
        use crate::lut::{Lut, LutAxis};
        let axis = |c: &str, size, r: [f64; 2]| LutAxis { channel: c.into(), size, min: r[0], max: r[1] };
        let flat = |t: Vec<[f32; 4]>| t.into_iter().flatten().collect::<Vec<f32>>();
        vec![
            Lut {
                name: "tf3d".into(),
                meaning: m3.into(),
                axes: vec![
                    axis("v", 256, self.v_range),
                    axis("g", 128, self.g_range),
                    axis("f2", TF3D_F2_CELLS, self.f2_range),
                ],
                components: 4,
                values: flat(self.table3(256, 128, TF3D_F2_CELLS)),
                unit_range: true,
                u16_range: None,
            },
            Lut {
                name: "tf2d".into(),
                meaning: format!("RGBA over (v, g), the separable 2D part{approx}"),
                axes: vec![axis("v", 256, self.v_range), axis("g", 256, self.g_range)],
                components: 4,
                values: flat(self.table2(256, 256)),
                unit_range: true,
                u16_range: None,
            },
            Lut {
                name: "tf_f2".into(),
                meaning: format!("opacity factor over f2 (boundary emphasis), the separable 1D part{approx}"),
                axes: vec![axis("f2", 256, self.f2_range)],
                components: 1,
                values: self.table_f2(256),
                unit_range: true,
                u16_range: None,
            },
        ]
    }

    /// The 2D TF of multidimensional peak finding over (v, 1/g), `n` = [cells
    /// along v, cells along 1/g] with 1/g in `inv_g_range`: the (v, g) widgets
    /// evaluated at g = 1 / (1/g) (cells at 1/g = 0 take g = the top of
    /// `g_range`). 1/g needs the finer axis: boundaries, where g is large,
    /// crowd its low end. None without widgets.
    pub fn peak_finding_tf2d(&self, inv_g_range: [f64; 2], n: [usize; 2]) -> Option<crate::lut::Lut> {
        use crate::lut::{Lut, LutAxis};
        if self.widgets.is_empty() {
            return None;
        }
        let mut values = Vec::with_capacity(4 * n[0] * n[1]);
        for j in 0..n[1] {
            let inv_g = Self::at(inv_g_range, j, n[1]);
            let g = if inv_g > 0.0 { 1.0 / inv_g } else { self.g_range[1] };
            for i in 0..n[0] {
                values.extend(self.eval2(Self::at(self.v_range, i, n[0]), g).map(|x| x as f32));
            }
        }
        Some(Lut {
            name: "tf2d".into(),
            meaning: "RGBA over (v, inv_g): the (v, g) widgets at g = 1 / inv_g, for multidimensional peak finding"
                .into(),
            axes: vec![
                LutAxis { channel: "v".into(), size: n[0], min: self.v_range[0], max: self.v_range[1] },
                LutAxis { channel: "inv_g".into(), size: n[1], min: inv_g_range[0], max: inv_g_range[1] },
            ],
            components: 4,
            values,
            unit_range: true,
            u16_range: None,
        })
    }

    /// alpha_u over (v, g_hit) of the distance-TF renderer: the 2D widgets with g read as g_hit.
    pub fn distance_alpha_u(&self) -> crate::lut::Lut {
        use crate::lut::{Lut, LutAxis};
        Lut {
            name: "alpha_u".into(),
            meaning: "RGBA over (v, g_hit): the user transfer function alpha_u".into(),
            axes: vec![
                LutAxis { channel: "v".into(), size: 256, min: self.v_range[0], max: self.v_range[1] },
                LutAxis { channel: "g_hit".into(), size: 256, min: self.g_range[0], max: self.g_range[1] },
            ],
            components: 4,
            values: self.table2(256, 256).into_iter().flatten().collect(),
            unit_range: true,
            u16_range: None,
        }
    }
}

impl TfFile {
    /// The Gaussian widgets, as written to a pack's `gaussians.json`.
    pub fn gaussians(&self) -> Vec<GaussianPrimitive> {
        self.widgets
            .iter()
            .filter_map(|w| if let Widget::Gaussian(g) = &w.shape { Some(g.clone()) } else { None })
            .collect()
    }

    /// With a `tf1d`: the 256 x 256 peak table (the v of up to four TF peaks between
    /// front and back values, in the order a ray meets them, -1 for none; see
    /// [`crate::tables::peak_table`]) and the pre-integration table for a segment of `step` world units.
    pub fn table_luts(&self, step: f64) -> Vec<crate::lut::Lut> {
        use crate::lut::{Lut, LutAxis};
        let Some(samples) = &self.tf1d else { return Vec::new() };
        let tf = crate::tables::Tf1d { samples: samples.clone() };
        let span = self.v_range[1] - self.v_range[0];
        let axes = |a: &str, b: &str| {
            vec![
                LutAxis { channel: a.into(), size: 256, min: self.v_range[0], max: self.v_range[1] },
                LutAxis { channel: b.into(), size: 256, min: self.v_range[0], max: self.v_range[1] },
            ]
        };
        let peak = crate::tables::peak_table(&tf, 256)
            .into_iter()
            .flatten()
            .map(|s| if s < 0.0 { -1.0 } else { (self.v_range[0] + s as f64 * span) as f32 })
            .collect();
        vec![
            Lut {
                name: "peak_table".into(),
                meaning: format!(
                    "v of up to {} peaks of tf1d between the front (first axis) and back values, in the order \
                     a ray from the front value meets them (component 0 first); -1: none",
                    crate::tables::PEAKS_PER_ENTRY
                ),
                axes: axes("v_front", "v_back"),
                components: crate::tables::PEAKS_PER_ENTRY,
                values: peak,
                unit_range: false,
                u16_range: None,
            },
            Lut {
                name: "preintegration".into(),
                meaning: format!("RGBA of a {step}-world-unit segment from the front to the back value (Engel et al.)"),
                axes: axes("v_front", "v_back"),
                components: 4,
                values: crate::tables::preintegration_table(&tf, 256, step).into_iter().flatten().collect(),
                unit_range: true,
                u16_range: None,
            },
        ]
    }
}

/// RGBA in [0, 1] to 8-bit codes (value = code / 255).
pub fn to_rgba8(table: &[[f32; 4]]) -> Vec<u8> {
    table.iter().flat_map(|px| px.map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = r#"{
      "v_range": [0, 255], "g_range": [0, 40], "f2_range": [-10, 10], "boundary_emphasis": 0.25,
      "widgets": [
        {"type": "triangle", "v0": 128, "width": 30, "g_low": 5, "g_high": 35, "shear": 0.5, "alpha": 0.8, "colour": [1, 0.5, 0]},
        {"type": "rectangle", "centre": [60, 10], "half_size": [20, 8], "falloff": "pyramid", "alpha": 0.6, "colour": [0, 0, 1]},
        {"type": "gaussian", "centre": [200, 25], "k": [[0.05, 0], [0, 0.2]], "alpha_max": 0.9, "colour": [0, 1, 0]}
      ]}"#;

    #[test]
    fn rasterisation_equals_the_widget_formulas_at_cell_centres() {
        let tf = parse_tf(EXAMPLE).unwrap();
        let (nv, ng) = (64, 32);
        let t = tf.table2(nv, ng);
        for (i, j) in [(32, 16), (33, 20), (15, 8), (50, 20), (10, 2), (63, 31)] {
            let (v, g) = ((i as f64 + 0.5) * 255.0 / 64.0, (j as f64 + 0.5) * 40.0 / 32.0);
            // the formulas, written out again
            let tri = if (5.0..=35.0).contains(&g) {
                let (c, h) = (128.0 + 0.5 * g, 30.0 * g / 35.0);
                0.8 * (1.0 - (v - c).abs() / h).max(0.0)
            } else {
                0.0
            };
            let (dv, dg) = ((v - 60.0) / 20.0, (g - 10.0) / 8.0);
            let rect = if dv.abs() <= 1.0 && dg.abs() <= 1.0 { 0.6 * (1.0 - dv.abs().max(dg.abs())) } else { 0.0 };
            let gau = 0.9 * (-((0.05 * (v - 200.0)).powi(2) + (0.2 * (g - 25.0)).powi(2))).exp();
            let a = tri + rect + gau;
            let got = t[j * nv + i];
            assert!((got[3] as f64 - a.min(1.0)).abs() < 1e-6, "({i}, {j})");
            if a > 0.0 {
                let red = (tri * 1.0 + rect * 0.0 + gau * 0.0) / a;
                assert!((got[0] as f64 - red).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn separable_3d_table_is_the_product_of_its_parts() {
        let tf = parse_tf(EXAMPLE).unwrap();
        let (t2, e, t3) = (tf.table2(256, 128), tf.table_f2(9), tf.table3(256, 128, 9));
        assert_eq!(t3.len(), 256 * 128 * 9);
        for k in 0..9 {
            for idx in [0, 1000, 20_000, 32_767] {
                assert_eq!(t3[k * 256 * 128 + idx][3], t2[idx][3] * e[k]);
            }
        }
        // emphasis: 1 at f'' = 0, 1 - (1 - e) at the extremes
        assert!((tf.emphasis(0.0) - 1.0).abs() < 1e-12 && (tf.emphasis(10.0) - 0.25).abs() < 1e-12);
    }

    #[test]
    fn widgets_with_an_f2_extent_make_a_true_3d_table() {
        let text = EXAMPLE.replace(
            r#""alpha": 0.8, "colour": [1, 0.5, 0]}"#,
            r#""alpha": 0.8, "colour": [1, 0.5, 0], "f2": [-10, 0], "boundary_emphasis": 1}"#,
        );
        let tf = parse_tf(&text).unwrap();
        assert!(!tf.separable() && parse_tf(EXAMPLE).unwrap().separable());
        let (nv, ng, nf) = (64, 32, TF3D_F2_CELLS);
        let t3 = tf.table3(nv, ng, nf);
        let centre = |r: [f64; 2], i: usize, n: usize| r[0] + (i as f64 + 0.5) * (r[1] - r[0]) / n as f64;
        // the middle f'' cell's centre is f'' = 0
        assert_eq!(centre([-10.0, 10.0], nf / 2, nf), 0.0);
        for (i, j) in [(32, 16), (33, 20), (15, 8), (50, 20)] {
            for k in 0..nf {
                let (v, g, f2) =
                    (centre([0.0, 255.0], i, nv), centre([0.0, 40.0], j, ng), centre([-10.0, 10.0], k, nf));
                // brute force: the triangle only for f'' in [-10, 0] with emphasis 1; the others times
                // the file's emphasis 1 - 0.75 |f''| / 10
                let tri = if (5.0..=35.0).contains(&g) && f2 <= 0.0 {
                    let (c, h) = (128.0 + 0.5 * g, 30.0 * g / 35.0);
                    0.8 * (1.0 - (v - c).abs() / h).max(0.0)
                } else {
                    0.0
                };
                let e = 1.0 - 0.75 * f2.abs() / 10.0;
                let (dv, dg) = ((v - 60.0) / 20.0, (g - 10.0) / 8.0);
                let rect = if dv.abs() <= 1.0 && dg.abs() <= 1.0 { 0.6 * (1.0 - dv.abs().max(dg.abs())) } else { 0.0 };
                let gau = 0.9 * (-((0.05 * (v - 200.0)).powi(2) + (0.2 * (g - 25.0)).powi(2))).exp();
                let a = (tri + e * (rect + gau)).min(1.0);
                assert!((t3[(k * ng + j) * nv + i][3] as f64 - a).abs() < 1e-6, "({i}, {j}, {k})");
            }
        }
        // not separable: the ratio of two f'' slices differs between cells
        let alpha = |i: usize, j: usize, k: usize| t3[(k * ng + j) * nv + i][3] as f64;
        let (lo, hi) = (0, nf - 1);
        let r1 = alpha(32, 16, hi) / alpha(32, 16, lo);
        let r2 = alpha(12, 8, hi) / alpha(12, 8, lo);
        assert!(alpha(32, 16, lo) > 0.0 && alpha(12, 8, lo) > 0.0 && (r1 - r2).abs() > 0.1, "{r1} {r2}");
        let bad = text.replace(r#""f2": [-10, 0]"#, r#""f2": [3, -3]"#);
        assert_eq!(parse_tf(&bad).unwrap_err(), "at widgets[0].f2: [3, -3] must be increasing");
    }

    #[test]
    fn malformed_files_name_the_json_path() {
        let bad = EXAMPLE.replace("\"falloff\": \"pyramid\"", "\"falloff\": \"cone\"");
        let e = parse_tf(&bad).unwrap_err();
        assert!(e.starts_with("at widgets[1].falloff") && e.contains("cone"), "{e}");
        let bad = EXAMPLE.replace("\"g_high\": 35", "\"g_high\": \"x\"");
        let e = parse_tf(&bad).unwrap_err();
        assert!(e.starts_with("at widgets[0].g_high"), "{e}");
        let bad = EXAMPLE.replace("\"type\": \"gaussian\"", "\"type\": \"blob\"");
        assert!(parse_tf(&bad).unwrap_err().starts_with("at widgets[2].type"));
        let bad = EXAMPLE.replace("\"boundary_emphasis\": 0.25", "\"boundary_emphasis\": 2");
        assert!(parse_tf(&bad).unwrap_err().contains("boundary_emphasis"));
    }

    #[test]
    fn widget_values_that_draw_nothing_or_out_of_range_are_refused() {
        for (from, to, want) in [
            ("\"width\": 30", "\"width\": -5", "at widgets[0].width: -5 must be positive"),
            ("\"g_low\": 5", "\"g_low\": 40", "at widgets[0].g_low: 40 must be in [0, g_high = 35)"),
            ("\"alpha\": 0.8", "\"alpha\": 2", "at widgets[0].alpha: 2 is not in [0, 1]"),
            ("\"colour\": [1, 0.5, 0]", "\"colour\": [1, 5, 0]", "at widgets[0].colour: 5 is not in [0, 1]"),
        ] {
            assert!(EXAMPLE.contains(from), "{from}");
            let e = parse_tf(&EXAMPLE.replacen(from, to, 1)).unwrap_err();
            assert_eq!(e, want);
        }
        assert!(parse_tf(EXAMPLE).is_ok());
    }
}
