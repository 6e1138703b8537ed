//! Separable product transfer functions: a TF over several channels built
//! as the product of lower-dimensional factors.
//!
//! Two papers use one:
//! * Kniss, Kindlmann and Hansen, section 9.5.2: the meteorological
//!   simulation is classified by "a 2D transfer function" over temperature
//!   and humidity and "a 1D transfer function" over the multi-derivative
//!   ||G||, the latter "a linear ramp" between two sliders, so that only
//!   regions of high ||G|| show;
//! * the peak-finding paper, section 5.3: a 4D TF over four fields as the
//!   product rho(f0, f1, f2, f3) = v(f0, f1) mu(f2, f3) of two 2D TFs.
//!
//! In a TF file, `"product"` lists the factors. A 2D factor names two
//! channels, their ranges and widgets (the top-level widget types, with v
//! read as the first channel and g as the second); a 1D factor names one
//! channel, its range and a `ramp` [begin, end]: opacity 0 at begin, 1 at
//! end, linear between and clamped outside (begin > end ramps down). The
//! product's opacity is the product of the factors' opacities; its colour
//! is the first factor's (the chapter colours by temperature and humidity
//! and uses ||G|| only to gate). Each factor is written as its own table,
//! `product_k`, so a renderer multiplies at most four lookups per sample.

use crate::lut::{Lut, LutAxis};
use crate::tf::{Widget, combine};

/// At most this many channels over all factors (one RGBA texel of coordinates).
pub const PRODUCT_MAX_CHANNELS: usize = 4;

/// What a factor of a product TF is.
#[derive(Debug, Clone, PartialEq)]
pub enum FactorShape {
    /// Widgets over two channels (first read as v, second as g), combined
    /// as the top-level widgets are (opacities add, clamped; colours are the
    /// opacity-weighted mean).
    Widgets(Vec<Widget>),
    /// A linear opacity ramp over one channel: 0 at `[0]`, 1 at `[1]`.
    Ramp([f64; 2]),
}

/// One factor of a product TF.
#[derive(Debug, Clone, PartialEq)]
pub struct ProductFactor {
    /// The channels it is a function of (two for widgets, one for a ramp).
    pub channels: Vec<String>,
    /// The range of each channel its table covers (channel units).
    pub ranges: Vec<[f64; 2]>,
    /// Its widgets or ramp.
    pub shape: FactorShape,
}

/// A product TF: the opacity is the product of the factors', the colour the first factor's.
#[derive(Debug, Clone, PartialEq)]
pub struct ProductTf {
    /// The factors, in the file's order.
    pub factors: Vec<ProductFactor>,
}

impl ProductFactor {
    /// RGBA of this factor at `x` (one coordinate per channel); a ramp is white.
    pub fn eval(&self, x: &[f64]) -> [f64; 4] {
        match &self.shape {
            FactorShape::Widgets(widgets) => combine(widgets.iter().map(|w| w.eval(x[0], x[1]))),
            FactorShape::Ramp([begin, end]) => {
                let t = if end != begin { ((x[0] - begin) / (end - begin)).clamp(0.0, 1.0) } else { 1.0 };
                [1.0, 1.0, 1.0, t]
            }
        }
    }

    /// The factor rasterised at its cell centres: `cells` per axis, first
    /// channel fastest; RGBA for widgets, opacity alone for a ramp.
    pub fn table(&self, k: usize, cells: usize) -> Lut {
        let axes: Vec<LutAxis> = self
            .channels
            .iter()
            .zip(&self.ranges)
            .map(|(c, r)| LutAxis { channel: c.clone(), size: cells, min: r[0], max: r[1] })
            .collect();
        let (values, components, what) = match &self.shape {
            FactorShape::Widgets(_) => {
                let mut v = Vec::with_capacity(4 * cells * cells);
                for j in 0..cells {
                    for i in 0..cells {
                        let x = [axes[0].centre(i), axes[1].centre(j)];
                        v.extend(self.eval(&x).map(|x| x as f32));
                    }
                }
                (v, 4, "RGBA of its widgets".to_string())
            }
            FactorShape::Ramp([b, e]) => (
                (0..cells).map(|i| self.eval(&[axes[0].centre(i)])[3] as f32).collect(),
                1,
                format!("opacity ramp from 0 at {b} to 1 at {e}"),
            ),
        };
        Lut {
            name: format!("product_{k}"),
            meaning: format!(
                "factor {k} of a product TF over ({}): {what}; the TF's opacity is the product of every \
                 product_* table's opacity, its colour product_0's (Kniss et al. 9.5.2, peak-finding paper 5.3)",
                self.channels.join(", ")
            ),
            axes,
            components,
            values,
            unit_range: true,
            u16_range: None,
        }
    }
}

impl ProductTf {
    /// Every channel the factors read, in order (a channel used by two factors appears twice).
    pub fn channels(&self) -> Vec<&str> {
        self.factors.iter().flat_map(|f| f.channels.iter().map(String::as_str)).collect()
    }

    /// RGBA of the product at `x`, the factors' coordinates one after another
    /// (as [`ProductTf::channels`] lists them).
    pub fn eval(&self, x: &[f64]) -> [f64; 4] {
        let mut at = 0;
        let mut out = [0.0, 0.0, 0.0, 1.0];
        for (k, f) in self.factors.iter().enumerate() {
            let n = f.channels.len();
            let rgba = f.eval(&x[at..at + n]);
            at += n;
            if k == 0 {
                out[..3].copy_from_slice(&rgba[..3]);
            }
            out[3] *= rgba[3];
        }
        out
    }

    /// One table per factor: 2D factors `cells_2d` per axis, ramps 256 cells.
    /// `packed`: the channels the pack holds; a factor over another channel is refused.
    pub fn luts(&self, packed: &[String], cells_2d: usize) -> Result<Vec<Lut>, String> {
        for (k, f) in self.factors.iter().enumerate() {
            if let Some(c) = f.channels.iter().find(|c| !packed.contains(c)) {
                return Err(format!(
                    "product[{k}] reads channel '{c}', which this pack does not hold (it holds: {})",
                    packed.join(", ")
                ));
            }
        }
        Ok(self
            .factors
            .iter()
            .enumerate()
            .map(|(k, f)| f.table(k, if f.channels.len() == 1 { 256 } else { cells_2d }))
            .collect())
    }
}

/// Checks a parsed factor: channel count matching its shape, increasing
/// finite ranges, a ramp with finite ends; the message starts with the key at fault.
pub(crate) fn check_factor(f: &ProductFactor) -> Result<(), String> {
    let want = match f.shape {
        FactorShape::Widgets(_) => 2,
        FactorShape::Ramp(_) => 1,
    };
    if f.channels.len() != want {
        return Err(format!(
            "channels: a {} factor is over {want} channel(s), got {}",
            if want == 2 { "widget" } else { "ramp" },
            f.channels.len()
        ));
    }
    if f.ranges.len() != want {
        return Err(format!("ranges: give one [min, max] per channel ({want}), got {}", f.ranges.len()));
    }
    for (c, r) in f.channels.iter().zip(&f.ranges) {
        if !(r[0].is_finite() && r[1].is_finite() && r[0] < r[1]) {
            return Err(format!("ranges: [{}, {}] for {c} must be increasing", r[0], r[1]));
        }
    }
    if let FactorShape::Ramp([b, e]) = f.shape
        && !(b.is_finite() && e.is_finite())
    {
        return Err(format!("ramp: [{b}, {e}] must be finite"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::tf::parse_tf;

    const METEO: &str = r#"{
      "product": [
        {"channels": ["temperature", "humidity"], "ranges": [[0, 40], [0, 100]],
         "widgets": [{"type": "rectangle", "centre": [30, 70], "half_size": [5, 20], "falloff": "tent",
                      "alpha": 0.8, "colour": [1, 0.2, 0]}]},
        {"channels": ["gnorm"], "ranges": [[0, 2]], "ramp": [0.5, 1.5]}
      ]}"#;

    #[test]
    fn the_product_is_the_2d_widget_times_the_ramp_at_every_cell_centre() {
        let tf = parse_tf(METEO).unwrap();
        let p = tf.product.as_ref().unwrap();
        assert_eq!(p.channels(), ["temperature", "humidity", "gnorm"]);
        let packed: Vec<String> = ["temperature", "humidity", "gnorm"].map(String::from).to_vec();
        let luts = p.luts(&packed, 64).unwrap();
        assert_eq!(luts.len(), 2);
        let (t2, ramp) = (&luts[0], &luts[1]);
        assert_eq!(
            (t2.components, t2.axes[0].size, t2.axes[1].size, ramp.components, ramp.axes[0].size),
            (4, 64, 64, 1, 256)
        );
        // the formulas written out: a tent 1 - |dt| inside |dt|, |dh| <= 1; the ramp (x - 0.5) / 1 clamped
        for (i, j) in [(48, 44), (45, 40), (52, 60), (10, 10), (47, 57)] {
            let (t, h) = ((i as f64 + 0.5) * 40.0 / 64.0, (j as f64 + 0.5) * 100.0 / 64.0);
            let (dt, dh) = ((t - 30.0) / 5.0, (h - 70.0) / 20.0);
            let want = if dt.abs() <= 1.0 && dh.abs() <= 1.0 { 0.8 * (1.0 - dt.abs()) } else { 0.0 };
            let got = t2.values[4 * (j * 64 + i) + 3] as f64;
            assert!((got - want).abs() < 1e-6, "({i}, {j}): {got} vs {want}");
            for g in [0.2, 0.75, 1.0, 1.9] {
                let r = ((g - 0.5) / 1.0f64).clamp(0.0, 1.0);
                let rgba = p.eval(&[t, h, g]);
                assert!((rgba[3] - want * r).abs() < 1e-12, "{rgba:?}");
                if want > 0.0 {
                    assert!(rgba[..3].iter().zip([1.0, 0.2, 0.0]).all(|(a, b)| (a - b).abs() < 1e-12), "{rgba:?}");
                }
            }
        }
        for k in [0usize, 60, 64, 128, 200, 255] {
            let g = (k as f64 + 0.5) * 2.0 / 256.0;
            assert!((ramp.values[k] as f64 - ((g - 0.5) / 1.0f64).clamp(0.0, 1.0)).abs() < 1e-6, "{k}");
        }
    }

    #[test]
    fn bad_factors_are_refused_at_their_key_and_unpacked_channels_by_name() {
        let bad = |text: &str| parse_tf(text).unwrap_err();
        let e = bad(r#"{"product": [{"channels": ["a"], "ranges": [[0, 1]], "widgets": []}]}"#);
        assert!(e.contains("product[0].channels: a widget factor is over 2 channel(s), got 1"), "{e}");
        let e = bad(r#"{"product": [{"channels": ["a"], "ranges": [[1, 0]], "ramp": [0, 1]}]}"#);
        assert!(e.contains("product[0].ranges: [1, 0] for a must be increasing"), "{e}");
        let e = bad(r#"{"product": [{"channels": ["a"], "ranges": [[0, 1]], "ramp": [0, 1], "widgets": []}]}"#);
        assert!(e.contains("product[0]: give either widgets or ramp"), "{e}");
        let e = bad(
            r#"{"product": [{"channels": ["a", "b"], "ranges": [[0, 1], [0, 1]], "widgets": [{"type": "blob"}]}]}"#,
        );
        assert!(e.contains("product[0].widgets[0].type: unknown widget 'blob'"), "{e}");
        let e = bad(r#"{"product": [{"channels": ["a", "b"], "ranges": [[0, 1], [0, 1]], "widgets": []},
                            {"channels": ["c", "d"], "ranges": [[0, 1], [0, 1]], "widgets": []},
                            {"channels": ["e"], "ranges": [[0, 1]], "ramp": [0, 1]}]}"#);
        assert!(e.contains("at product: 5 channels in all; at most 4"), "{e}");
        let tf = parse_tf(METEO).unwrap();
        let e = tf.product.unwrap().luts(&["temperature".into(), "humidity".into(), "g".into()], 8).unwrap_err();
        assert!(
            e.contains(
                "product[1] reads channel 'gnorm', which this pack does not hold (it holds: temperature, humidity, g)"
            ),
            "{e}"
        );
    }
}
