//! The distance-tf classifier, alpha_u(v, g_hit) x alpha_d(d): empty-space
//! skipping (blocks with no boundary, or only transparent distances)
//! changes no pixel, and what shows is the shell around the boundary.

use mdtf_datagen::erf_sphere;
use mdtf_preview::{Camera, Classifier, Table, render, render_without_skipping};
use mdtf_volume::{Geometry, Volume};
use std::collections::BTreeMap;

#[test]
fn distance_classifier_skips_empty_blocks_without_changing_a_pixel() {
    let n = 48;
    let (radius, sigma) = (14.0, 2.0);
    let t = erf_sphere(Geometry::new([n; 3], [1.0; 3]), radius, sigma, 0.0, 255.0, None).truth();
    let geometry = t.v.geometry.clone();
    // distance to the sphere within 2.5 voxels of it, else "no boundary" (-1)
    let mut distance = t.x.clone();
    distance.data.mapv_inplace(|x| if x.abs() <= 2.5 { x.abs() } else { -1.0 });
    let mut channels: BTreeMap<String, Volume> = BTreeMap::new();
    channels.insert("v".into(), t.v.clone());
    channels.insert("g".into(), t.g.clone());
    channels.insert("g_hit".into(), t.g.clone());
    channels.insert("distance".into(), distance);
    for (c, name) in ["nx", "ny", "nz"].iter().enumerate() {
        channels.insert(name.to_string(), Volume { geometry: geometry.clone(), data: t.normal.fields[c].data.clone() });
    }
    // alpha_d: opaque for d < 1, transparent beyond (so blocks at 1..2.5 voxels skip too)
    let alpha_d = Table {
        axes: vec![("distance".into(), 8, 0.0, 4.0)],
        components: 1,
        values: vec![0.5, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    };
    let alpha_u = Table {
        axes: vec![("v".into(), 4, 0.0, 256.0), ("g_hit".into(), 2, 0.0, 100.0)],
        components: 4,
        values: [[1.0, 0.8, 0.6, 1.0]; 8].concat(),
    };
    for classifier in [
        Classifier::Distance { alpha_u: None, alpha_d: alpha_d.clone() },
        Classifier::Distance { alpha_u: Some(alpha_u), alpha_d },
    ] {
        for (azimuth, elevation) in [(30.0, 20.0), (0.0, 0.0), (90.0, 45.0)] {
            let cam = Camera { azimuth, elevation, size: 64, step: 0.5, shaded: true };
            let skipped = render(&channels, &classifier, &cam);
            assert_eq!(skipped, render_without_skipping(&channels, &classifier, &cam), "view {azimuth},{elevation}");
            // the sphere shows and the corners of the image (outside it) stay black
            let lit = skipped.chunks(3).filter(|p| p.iter().any(|&c| c > 20)).count();
            assert!(lit > 64 * 64 / 8, "view {azimuth},{elevation}: {lit} lit pixels");
            assert!(skipped[..3].iter().all(|&c| c == 0), "corner pixel {:?}", &skipped[..3]);
        }
    }
}
