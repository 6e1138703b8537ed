//! Product TFs (Kniss et al. 9.5.2; the peak-finding paper's section 5.3):
//! the renderer's product of factor tables against one brute-force table of
//! the product, and chordal peak finding through the product's domain.

use mdtf_datagen::erf_sphere;
use mdtf_pack::parse_tf;
use mdtf_preview::{Camera, Classifier, Table, render, render_without_skipping};
use mdtf_volume::{Geometry, Volume};
use ndarray::Array3;
use std::collections::BTreeMap;

fn to_table(l: &mdtf_pack::Lut) -> Table {
    Table {
        axes: l.axes.iter().map(|a| (a.channel.clone(), a.size, a.min, a.max)).collect(),
        components: l.components,
        values: l.values.clone(),
    }
}

/// The sphere's v and g (truth), 1/g, and w, the x coordinate in voxels.
fn channels() -> (BTreeMap<String, Volume>, f64) {
    let truth = erf_sphere(Geometry::new([48; 3], [1.0; 3]), 14.0, 2.0, 0.0, 255.0, None).truth();
    let g_max = truth.g.finite_range().unwrap().1 as f64;
    let geo = truth.v.geometry.clone();
    let inv_g = truth.g.data.mapv(|g| if (g as f64) > 0.01 * g_max { 1.0 / g } else { (100.0 / g_max) as f32 });
    let w = Array3::from_shape_fn(geo.shape(), |(_, _, i)| i as f32);
    let out = [
        ("v".to_string(), truth.v.clone()),
        ("g".to_string(), truth.g.clone()),
        ("inv_g".to_string(), Volume { geometry: geo.clone(), data: inv_g }),
        ("w".to_string(), Volume { geometry: geo, data: w }),
    ];
    (out.into_iter().collect(), g_max)
}

#[test]
fn a_2d_tf_times_a_ramp_renders_as_the_brute_force_3d_table_of_the_product() {
    let (channels, g_max) = channels();
    // Kniss et al.'s meteorological TF: a 2D TF (here over v and g) times a ramp over a third channel
    let tf = parse_tf(&format!(
        r#"{{"product": [
          {{"channels": ["v", "g"], "ranges": [[0, 255], [0, {g_max}]], "widgets": [{{"type": "rectangle",
            "centre": [128, {c}], "half_size": [60, {h}], "falloff": "tent", "alpha": 0.6, "colour": [1, 0.5, 0.2]}}]}},
          {{"channels": ["w"], "ranges": [[0, 47]], "ramp": [16, 32]}}]}}"#,
        c = 0.5 * g_max,
        h = 0.5 * g_max
    ))
    .unwrap();
    let product = tf.product.as_ref().unwrap();
    let luts = product.luts(&["v".into(), "g".into(), "w".into()], 64).unwrap();
    let factors: Vec<Table> = luts.iter().map(to_table).collect();
    // the reference: one 64 x 64 x 256 table over (v, g, w), the product filled in cell by cell
    let (f0, f1) = (&luts[0], &luts[1]);
    let mut values = Vec::with_capacity(64 * 64 * 256 * 4);
    for k in 0..256 {
        for ij in 0..64 * 64 {
            let c = &f0.values[4 * ij..4 * ij + 4];
            values.extend([c[0], c[1], c[2], c[3] * f1.values[k]]);
        }
    }
    let mut axes = factors[0].axes.clone();
    axes.push(factors[1].axes[0].clone());
    let brute = Classifier::Lut(Table { axes, components: 4, values });
    let classify = Classifier::Product { factors, cells_per_sample: 2.0, find_peaks: false };
    let cam = Camera { azimuth: 30.0, elevation: 20.0, size: 64, step: 0.5, shaded: true };
    let got = render(&channels, &classify, &cam);
    assert_eq!(got, render(&channels, &brute, &cam));
    assert_eq!(got, render_without_skipping(&channels, &classify, &cam), "skipping changes no pixel");
    let lit = got.chunks_exact(3).filter(|px| px[0] > 20).count();
    assert!(lit > 300, "{lit}");
}

#[test]
fn chordal_peak_finding_in_a_product_finds_the_thin_feature_coarse_sampling_misses() {
    let (channels, g_max) = channels();
    // the peak-finding paper's 4D TF rho = v(f0, f1) mu(f2): a feature thin in v over (v, 1/g), gated by w
    let tf = parse_tf(&format!(
        r#"{{"product": [
          {{"channels": ["v", "inv_g"], "ranges": [[0, 255], [0, {top}]], "widgets": [{{"type": "rectangle",
            "centre": [128, {c}], "half_size": [1.5, {h}], "falloff": "constant", "alpha": 0.9, "colour": [1, 0.6, 0.3]}}]}},
          {{"channels": ["w"], "ranges": [[0, 47]], "ramp": [10, 20]}}]}}"#,
        top = 100.0 / g_max,
        c = 1.0 / g_max,
        h = 0.5 / g_max
    ))
    .unwrap();
    let luts = tf.product.as_ref().unwrap().luts(&["v".into(), "inv_g".into(), "w".into()], 1024).unwrap();
    let factors: Vec<Table> = luts.iter().map(to_table).collect();
    let classify = |find_peaks| Classifier::Product { factors: factors.clone(), cells_per_sample: 2.0, find_peaks };
    let cam = |step| Camera { azimuth: 30.0, elevation: 20.0, size: 64, step, shaded: true };
    let lit = |img: &[u8]| img.chunks_exact(3).map(|px| px[0] > 30).collect::<Vec<bool>>();
    let reference = lit(&render(&channels, &classify(false), &cam(0.05)));
    let cover = |img: &[u8]| {
        let l = lit(img);
        l.iter().zip(&reference).filter(|(a, b)| **a && **b).count() as f64
            / reference.iter().filter(|b| **b).count().max(1) as f64
    };
    let post = cover(&render(&channels, &classify(false), &cam(2.0)));
    let peak = cover(&render(&channels, &classify(true), &cam(2.0)));
    let n_ref = reference.iter().filter(|b| **b).count();
    eprintln!(
        "product TF, step 2 vs step 0.05 ({n_ref} pixels): post-classification {post:.3}, chordal peaks {peak:.3}"
    );
    assert!(n_ref > 200, "{n_ref}");
    assert!(peak >= 0.95, "{peak}");
    assert!(post <= 0.5 * peak, "{post}");
    assert_eq!(
        render(&channels, &classify(true), &cam(2.0)),
        render_without_skipping(&channels, &classify(true), &cam(2.0)),
        "skipping changes no pixel"
    );
}
