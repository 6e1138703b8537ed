//! Peak finding (1D): with a narrow TF peak and a coarse step, sampling at the
//! data points misses the feature, while classifying at the TF peak crossed
//! between two samples finds it on every ray that crosses it (the
//! peak-finding paper's motivation).

use mdtf_datagen::erf_sphere;
use mdtf_pack::parse_tf;
use mdtf_preview::{Camera, Classifier, Table, render};
use mdtf_volume::{Geometry, Volume};
use std::collections::BTreeMap;

/// The peak table and pre-integration table (segment of 1 voxel) of a tf1d
/// over v in [0, 255] given as its JSON samples "[r, g, b, tau]".
fn peak_tables(samples: &[String]) -> (Table, Table) {
    let tf =
        parse_tf(&format!(r#"{{"v_range": [0, 255], "g_range": [0, 1], "tf1d": [{}]}}"#, samples.join(","))).unwrap();
    let mut luts = tf.table_luts(1.0);
    let to_table = |l: mdtf_pack::Lut| Table {
        axes: l.axes.iter().map(|a| (a.channel.clone(), a.size, a.min, a.max)).collect(),
        components: l.components,
        values: l.values,
    };
    let preintegration = to_table(luts.remove(1));
    (to_table(luts.remove(0)), preintegration)
}

#[test]
fn peak_finding_finds_the_feature_that_coarse_sampling_misses() {
    let v = erf_sphere(Geometry::new([48; 3], [1.0; 3]), 14.0, 2.0, 0.0, 255.0, None).volume();
    let channels: BTreeMap<String, Volume> = [("v".to_string(), v)].into_iter().collect();
    // 256 TF samples over v in [0, 255]: one narrow peak at v = 128
    let samples: Vec<String> = (0..256)
        .map(|k| {
            format!(
                "[1, 0.7, 0.4, {}]",
                if k == 128 {
                    0.9
                } else if k == 127 || k == 129 {
                    0.2
                } else {
                    0.0
                }
            )
        })
        .collect();
    let (peak_table, preintegration) = peak_tables(&samples);
    let classify = |find_peaks| Classifier::Peak {
        peak_table: peak_table.clone(),
        preintegration: preintegration.clone(),
        find_peaks,
    };
    let cam = |step| Camera { azimuth: 30.0, elevation: 20.0, size: 64, step, shaded: true };
    let post = render(&channels, &classify(false), &cam(2.0));
    let peak = render(&channels, &classify(true), &cam(2.0));
    let lit = |img: &[u8]| img.chunks_exact(3).filter(|px| px[0] > 30).count();
    let (lp, lk) = (lit(&post), lit(&peak));
    eprintln!("pixels showing the v = 128 shell at step 2: post-classification {lp}, peak finding {lk} of {}", 64 * 64);
    // the shell projects to a disc of about pi (14 / (48 sqrt 3 / 2 / 32))^2 ~ 400 pixels
    assert!(lk > 300, "{lk}");
    assert!(lp * 5 < lk, "post-classification should miss most of the shell: {lp} vs {lk}");
    // empty-space skipping (blocks whose v box holds no peak and no opacity; a sample after
    // another block's never skipped) changes no pixel, peak finding on or off, at several steps
    for find_peaks in [true, false] {
        for step in [0.5, 2.0, 3.0] {
            assert_eq!(
                render(&channels, &classify(find_peaks), &cam(step)),
                mdtf_preview::render_without_skipping(&channels, &classify(find_peaks), &cam(step)),
                "find_peaks {find_peaks}, step {step}"
            );
        }
    }
}

#[test]
fn peak_finding_composites_every_peak_a_segment_crosses_in_ray_order() {
    // two narrow peaks 16 values apart (a third of a voxel on this sphere's
    // boundary, so one step of 2 crosses both): red, weak, at v = 120, met
    // first by a ray entering the sphere; blue, dense, at v = 136
    let v = erf_sphere(Geometry::new([48; 3], [1.0; 3]), 14.0, 2.0, 0.0, 255.0, None).volume();
    // g = 0 everywhere: the shading weight 1 - (1 - g / g_max)^2 is 0, so the colours composite unshaded
    let flat = Volume::new(v.geometry.clone(), ndarray::Array3::zeros((48, 48, 48))).unwrap();
    let channels: BTreeMap<String, Volume> = [("v".to_string(), v), ("g".to_string(), flat)].into_iter().collect();
    let (tau_red, tau_blue) = (-(1.0f64 - 0.3).ln(), -(1.0f64 - 0.9).ln()); // opacities 0.3 and 0.9 at d = 1
    let samples: Vec<String> = (0..256)
        .map(|k| match k {
            120 => format!("[1, 0, 0, {tau_red}]"),
            136 => format!("[0, 0, 1, {tau_blue}]"),
            _ => "[0, 0, 0, 0]".to_string(),
        })
        .collect();
    let (peak_table, preintegration) = peak_tables(&samples);
    let img = render(
        &channels,
        &Classifier::Peak { peak_table, preintegration, find_peaks: true },
        &Camera { azimuth: 30.0, elevation: 20.0, size: 64, step: 2.0, shaded: true },
    );
    // a ray through the shell: red 0.3 first, then blue (1 - 0.3) 0.9 = 0.63;
    // the exit meets blue first, then red: (1 - 0.93) (0.9 blue + 0.1 x 0.3 red);
    // unshaded (see g above). Highest peak only: no red; the wrong order: red 0.03
    let (want_red, want_blue) = (0.3 + 0.07 * 0.03, 0.63 + 0.07 * 0.9);
    let lit: Vec<&[u8]> = img.chunks_exact(3).filter(|px| px[2] > 30).collect();
    let near = |got: u8, want: f64| (got as f64 / 255.0 - want).abs() < 0.03;
    let right = lit.iter().filter(|px| near(px[0], want_red) && near(px[2], want_blue)).count();
    eprintln!("{right} of {} lit pixels show red {want_red:.3} and blue {want_blue:.3}", lit.len());
    assert!(lit.len() > 300, "{}", lit.len());
    assert!(right as f64 >= 0.9 * lit.len() as f64, "{right} of {}", lit.len());
}

/// Pixels whose red channel shows the feature.
fn lit_pixels(img: &[u8]) -> Vec<bool> {
    img.chunks_exact(3).map(|px| px[0] > 30).collect()
}

/// Share of the reference's lit pixels that `img` lights too.
fn coverage(img: &[u8], reference: &[bool]) -> f64 {
    let lit = lit_pixels(img);
    let both = lit.iter().zip(reference).filter(|(a, b)| **a && **b).count();
    both as f64 / reference.iter().filter(|b| **b).count().max(1) as f64
}

#[test]
fn chordal_peak_finding_finds_a_thin_2d_feature_that_coarse_sampling_misses() {
    // the sphere's v and 1/g; a TF feature thin in v (3 of 255) and limited to g >= 0.5 g_max
    let phantom = erf_sphere(Geometry::new([48; 3], [1.0; 3]), 14.0, 2.0, 0.0, 255.0, None);
    let truth = phantom.truth();
    let g_max = truth.g.finite_range().unwrap().1 as f64;
    let inv_g = truth.g.data.mapv(|g| if (g as f64) > 0.01 * g_max { 1.0 / g } else { (100.0 / g_max) as f32 });
    let channels: BTreeMap<String, Volume> = [
        ("v".to_string(), truth.v.clone()),
        ("inv_g".to_string(), Volume { geometry: truth.v.geometry.clone(), data: inv_g }),
    ]
    .into_iter()
    .collect();
    let table_with = |alpha: f64| {
        let tf = parse_tf(&format!(
            r#"{{"v_range": [0, 255], "g_range": [0, {g_max}], "widgets": [{{"type": "rectangle",
            "centre": [128, {c}], "half_size": [1.5, {h}], "falloff": "constant", "alpha": {alpha}, "colour": [1, 0.6, 0.3]}}]}}"#,
            c = 0.775 * g_max,
            h = 0.275 * g_max
        ))
        .unwrap();
        let lut = tf.peak_finding_tf2d([0.0, 100.0 / g_max], [256, 1024]).unwrap();
        Table {
            axes: lut.axes.iter().map(|a| (a.channel.clone(), a.size, a.min, a.max)).collect(),
            components: lut.components,
            values: lut.values,
        }
    };
    let table = table_with(0.9);
    let classify = |find_peaks| Classifier::Chord { tf: table.clone(), cells_per_sample: 2.0, find_peaks };
    let cam = |step| Camera { azimuth: 30.0, elevation: 20.0, size: 64, step, shaded: true };
    let reference = lit_pixels(&render(&channels, &classify(false), &cam(0.05)));
    let post = coverage(&render(&channels, &classify(false), &cam(2.0)), &reference);
    let peak = coverage(&render(&channels, &classify(true), &cam(2.0)), &reference);
    let n_ref = reference.iter().filter(|b| **b).count();
    eprintln!(
        "thin 2D feature, step 2 vs a step-0.05 reference ({n_ref} pixels): post-classification covers {post:.3}, chordal peak finding {peak:.3}"
    );
    assert!(n_ref > 300, "{n_ref}");
    // empty-space skipping changes no pixel, with the chord search on or off
    for find_peaks in [true, false] {
        assert_eq!(
            render(&channels, &classify(find_peaks), &cam(2.0)),
            mdtf_preview::render_without_skipping(&channels, &classify(find_peaks), &cam(2.0)),
            "find_peaks {find_peaks}"
        );
    }
    assert!(peak >= 0.95, "peak finding coverage {peak}");
    assert!(post <= 0.5 * peak, "post-classification should miss most of it: {post}");

    // a peak keeps the TF's opacity whatever the step: the feature, a thin
    // shell crossed twice by each ray, is as bright at step 1 as at step 2
    // (with opacity 0.3 per crossing: 1 - 0.7^2 = 0.51 of the colour; a step
    // correction would make it 0.51 per crossing at step 2)
    let faint = Classifier::Chord { tf: table_with(0.3), cells_per_sample: 2.0, find_peaks: true };
    let brightness = |img: &[u8]| {
        let lit: Vec<f64> =
            img.chunks_exact(3).zip(&reference).filter(|(_, r)| **r).map(|(px, _)| px[0] as f64).collect();
        lit.iter().sum::<f64>() / lit.len().max(1) as f64
    };
    let (b1, b2) =
        (brightness(&render(&channels, &faint, &cam(1.0))), brightness(&render(&channels, &faint, &cam(2.0))));
    eprintln!("mean red over the feature: step 1 {b1:.1}, step 2 {b2:.1}");
    assert!((b1 - b2).abs() <= 0.05 * b1 && b1 < 200.0, "{b1} vs {b2}");
}
