//! The Gaussian-TF paper's Fig. 1 claim, measured: with a narrow Gaussian
//! TF and a coarse step, the analytic segment integral is closer to a very
//! fine Riemann reference than the Riemann sum at the same coarse step.

use mdtf_datagen::erf_sphere;
use mdtf_pack::GaussianPrimitive;
use mdtf_preview::{Camera, Classifier, render};
use mdtf_volume::{Geometry, Volume};
use std::collections::BTreeMap;

#[test]
fn analytic_integration_beats_the_riemann_sum_at_a_coarse_step() {
    let v = erf_sphere(Geometry::new([48; 3], [1.0; 3]), 14.0, 2.0, 0.0, 255.0, None).volume();
    let channels: BTreeMap<String, Volume> = [("v".to_string(), v)].into_iter().collect();
    // a narrow peak around v = 128 (width ~ 4 of 255): a thin shell at the boundary
    let gp = GaussianPrimitive {
        centre: vec![128.0],
        k: vec![vec![0.25]],
        alpha_max: 0.8,
        colour: [1.0, 0.6, 0.3],
        triangular: false,
    };
    let classify = |analytic| Classifier::Gaussian {
        primitives: vec![gp.clone()],
        channels: vec!["v".into()],
        analytic,
        sqrt_last: false,
    };
    let cam = |step| Camera { azimuth: 30.0, elevation: 20.0, size: 64, step, shaded: true };
    let reference = render(&channels, &classify(false), &cam(0.02));
    let riemann = render(&channels, &classify(false), &cam(1.5));
    let analytic = render(&channels, &classify(true), &cam(1.5));
    let err = |img: &[u8]| {
        img.iter().zip(&reference).map(|(a, b)| (*a as f64 - *b as f64).abs()).sum::<f64>() / img.len() as f64
    };
    let (er, ea) = (err(&riemann), err(&analytic));
    eprintln!("mean |error| vs the fine reference at step 1.5: Riemann {er:.3}, analytic {ea:.3} (of 255)");
    assert!(reference.iter().filter(|&&x| x > 10).count() > 500, "the shell is visible");
    assert!(ea < er, "analytic {ea} should beat Riemann {er}");
}

/// Without normal channels the preview shades by the value's gradient (central
/// differences): on the erf sphere that matches shading by its exact normals.
#[test]
fn shading_by_the_value_gradient_matches_the_true_normals() {
    let t = erf_sphere(Geometry::new([48; 3], [1.0; 3]), 14.0, 2.0, 0.0, 255.0, None).truth();
    let mut channels: BTreeMap<String, Volume> =
        [("v".to_string(), t.v.clone()), ("g".to_string(), t.g.clone())].into_iter().collect();
    let classify = Classifier::Gaussian {
        primitives: vec![GaussianPrimitive {
            centre: vec![128.0],
            k: vec![vec![0.25]],
            alpha_max: 0.8,
            colour: [1.0, 0.6, 0.3],
            triangular: false,
        }],
        channels: vec!["v".into()],
        analytic: true,
        sqrt_last: false,
    };
    let cam = Camera { azimuth: 30.0, elevation: 20.0, size: 64, step: 0.5, shaded: true };
    let from_gradient = render(&channels, &classify, &cam);
    for (i, name) in ["nx", "ny", "nz"].iter().enumerate() {
        channels
            .insert(name.to_string(), Volume { geometry: t.v.geometry.clone(), data: t.normal.fields[i].data.clone() });
    }
    let from_normals = render(&channels, &classify, &cam);
    // g = 0 makes the shading weight 0: the unshaded picture
    let mut flat = channels.clone();
    flat.retain(|c, _| c == "v");
    flat.insert("g".into(), Volume::new(t.v.geometry.clone(), ndarray::Array3::zeros((48, 48, 48))).unwrap());
    let unshaded = render(&flat, &classify, &cam);
    let lit: Vec<usize> = (0..64 * 64).filter(|&p| from_normals[3 * p] > 30).collect();
    let red = |img: &[u8], p: usize| img[3 * p] as f64;
    let mean_diff =
        |a: &[u8], b: &[u8]| lit.iter().map(|&p| (red(a, p) - red(b, p)).abs()).sum::<f64>() / lit.len() as f64;
    let (to_normals, to_unshaded) = (mean_diff(&from_gradient, &from_normals), mean_diff(&from_gradient, &unshaded));
    eprintln!(
        "{} lit pixels; shaded by the gradient vs by the true normals: mean |diff| {to_normals:.2} of 255, vs unshaded {to_unshaded:.1}",
        lit.len()
    );
    assert!(lit.len() > 300, "{}", lit.len());
    assert!(to_unshaded > 20.0, "the gradient shades: {to_unshaded}");
    assert!(to_normals < 2.0, "{to_normals}");
    // shading off: the same unlit picture, with the normals present
    assert_eq!(render(&channels, &classify, &Camera { shaded: false, ..cam }), unshaded);
}

/// Empty-space skipping of the Gaussian classifier: blocks whose TF box keeps
/// every primitive's exponent beyond the far cutoff (where a whole ray of
/// them adds under 1e-3 of a level) are skipped; the pictures equal the
/// renderer's without skipping to within one level where a value lies on a
/// rounding edge, with analytic segments (which resume from the skipped
/// sample before) and without, for a full and a triangular primitive over
/// (v, sqrt g).
#[test]
fn skipping_far_blocks_changes_no_pixel() {
    let t = erf_sphere(Geometry::new([40, 36, 32], [1.0, 1.2, 0.9]), 11.0, 1.5, 10.0, 240.0, None).truth();
    let channels: BTreeMap<String, Volume> =
        [("v".to_string(), t.v.clone()), ("g".to_string(), t.g.clone())].into_iter().collect();
    let primitives = vec![
        GaussianPrimitive {
            centre: vec![125.0, 6.0],
            k: vec![vec![0.05, 0.0], vec![0.0, 0.6]],
            alpha_max: 1.5,
            colour: [1.0, 0.6, 0.3],
            triangular: false,
        },
        GaussianPrimitive {
            centre: vec![200.0],
            k: vec![vec![0.02]],
            alpha_max: 0.7,
            colour: [0.2, 0.5, 1.0],
            triangular: true,
        },
    ];
    for analytic in [true, false] {
        let classify = Classifier::Gaussian {
            primitives: primitives.clone(),
            channels: vec!["v".into(), "g".into()],
            analytic,
            sqrt_last: true,
        };
        for (azimuth, elevation, step) in [(30.0, 20.0, 0.5), (200.0, -40.0, 1.0), (90.0, 0.0, 0.25)] {
            let cam = Camera { azimuth, elevation, size: 72, step, shaded: true };
            let skipped = render(&channels, &classify, &cam);
            assert!(skipped.iter().filter(|&&x| x > 20).count() > 300, "the surfaces show");
            let every = mdtf_preview::render_without_skipping(&channels, &classify, &cam);
            let differ = skipped.iter().zip(&every).filter(|(a, b)| a != b).count();
            let most = skipped.iter().zip(&every).map(|(a, b)| a.abs_diff(*b)).max().unwrap_or(0);
            assert!(
                most <= 1 && differ <= 2,
                "analytic {analytic}, view {azimuth},{elevation}, step {step}: {differ} values differ, by up to {most}"
            );
        }
    }
}
