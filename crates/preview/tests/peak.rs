//! Peak finding (1D): with a narrow TF peak and a coarse step, sampling at the
//! data points misses the feature, while classifying at the TF peak crossed
//! between two samples finds it on every ray that crosses it (the
//! peak-finding paper's motivation).

use mdtf_datagen::erf_sphere;
use mdtf_pack::parse_tf;
use mdtf_preview::{Camera, Classifier, Table, render};
use mdtf_volume::{Geometry, Volume};
use std::collections::BTreeMap;

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
    let tf =
        parse_tf(&format!(r#"{{"v_range": [0, 255], "g_range": [0, 1], "tf1d": [{}]}}"#, samples.join(","))).unwrap();
    let mut luts = tf.table_luts(1.0);
    let to_table = |l: mdtf_pack::Lut| Table {
        axes: l.axes.iter().map(|a| (a.channel.clone(), a.size, a.min, a.max)).collect(),
        components: l.components,
        values: l.values,
    };
    let preintegration = to_table(luts.remove(1));
    let peak_table = to_table(luts.remove(0));
    let classify = |find_peaks| Classifier::Peak {
        peak_table: peak_table.clone(),
        preintegration: preintegration.clone(),
        find_peaks,
    };
    let cam = |step| Camera { azimuth: 30.0, elevation: 20.0, size: 64, step };
    let post = render(&channels, &classify(false), &cam(2.0));
    let peak = render(&channels, &classify(true), &cam(2.0));
    let lit = |img: &[u8]| img.chunks_exact(3).filter(|px| px[0] > 30).count();
    let (lp, lk) = (lit(&post), lit(&peak));
    eprintln!("pixels showing the v = 128 shell at step 2: post-classification {lp}, peak finding {lk} of {}", 64 * 64);
    // the shell projects to a disc of about pi (14 / (48 sqrt 3 / 2 / 32))^2 ~ 400 pixels
    assert!(lk > 300, "{lk}");
    assert!(lp * 5 < lk, "post-classification should miss most of the shell: {lp} vs {lk}");
}
