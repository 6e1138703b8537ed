//! Histograms against a brute-force count, the erf sphere's analytic
//! position function and sigma, and the stretched histogram of the paper's Fig. 5.

use mdtf_boundary::{BoundaryInput, BoundaryParams};
use mdtf_datagen::{RadialPhantom, erf_sphere};
use mdtf_derive::{DeriveParams, Item};
use mdtf_histogram::{
    Axis, AxisSpec, HvolAccumulator, HvolAxes, HvolBySlabs, HvolParams, HvolPart, Scale, count, fixed_parts,
    grey_level, histogram_volume, hit_mask, write_png,
};
use mdtf_volume::{Geometry, MultiField, Volume};
use std::f64::consts::PI;

struct Channels {
    v: Volume,
    g: Volume,
    f2: Volume,
    normal: MultiField,
}

fn channels(v: Volume) -> Channels {
    let d = DeriveParams { items: vec![Item::G, Item::F2, Item::Normal], ..DeriveParams::default() };
    let mut out = mdtf_derive::run(&MultiField::from(v.clone()), &d).unwrap();
    let normal = out.items.remove(2).1;
    let f2 = out.items.remove(1).1.into_scalar().unwrap();
    let g = out.items.remove(0).1.into_scalar().unwrap();
    Channels { v, g, f2, normal }
}

#[test]
fn joint_counts_equal_a_brute_force_count() {
    let mut state = 99u64;
    let mut rnd = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32 * 12.0 - 1.0
    };
    let a: Vec<f32> = (0..50_000).map(|_| rnd()).collect();
    let mut b: Vec<f32> = (0..50_000).map(|_| rnd()).collect();
    b[7] = 10.0; // exactly the maximum of the axis
    b[8] = f32::NAN;
    let axes = vec![Axis::new("a", 0.0, 10.0, 17).unwrap(), Axis::new("b", 0.0, 10.0, 9).unwrap()];
    let mask: Vec<bool> = (0..50_000).map(|i| i % 7 != 3).collect();
    let h = count(&[&a, &b], axes.clone(), Some(&mask)).unwrap();
    // brute force written here: floor((x - min) / width), max in the last bin
    let mut want = vec![0u64; 17 * 9];
    let mut inside = 0u64;
    for i in 0..a.len() {
        let (x, y) = (a[i] as f64, b[i] as f64);
        if !mask[i] || !(0.0..=10.0).contains(&x) || !(0.0..=10.0).contains(&y) {
            continue;
        }
        let bx = ((x / (10.0 / 17.0)) as usize).min(16);
        let by = ((y / (10.0 / 9.0)) as usize).min(8);
        want[by * 17 + bx] += 1;
        inside += 1;
    }
    assert_eq!(h.counts, want);
    assert_eq!(h.total(), inside);
    assert!(h.counts[h.index(&[axes[0].bin(a[7]).unwrap(), 8])] > 0, "b = max lands in the last bin");
    // same counts whatever the thread count
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| count(&[&a, &b], axes, Some(&mask)).unwrap());
    assert_eq!(one.counts, h.counts);
}

#[test]
fn position_function_recovers_the_signed_distance_and_sigma() {
    let sigma = 3.0;
    let ph = erf_sphere(Geometry::new([128; 3], [1.0; 3]), 38.4, sigma, 0.0, 255.0, None);
    let c = channels(ph.volume());
    let params = HvolParams { g_thresh: Some(0.0), ..HvolParams::default() };
    let hv = histogram_volume(c.v.samples(), c.g.samples(), c.f2.samples(), c.v.plane_len(), &params).unwrap();
    eprintln!("sigma estimate {:.4} (true {sigma})", hv.sigma);
    assert!((hv.sigma - sigma).abs() <= 0.02 * sigma, "{}", hv.sigma);
    // x as a function of v: v = 255 (1 + erf(x / (sigma sqrt 2))) / 2; compare each bin's p with
    // the mean x of its voxels (independent of the histogram code).
    let truth = ph.truth();
    let [av, ag] = &hv.vg_axes;
    let mut sum_x = vec![0.0f64; av.bins * ag.bins];
    let mut n_x = vec![0u64; av.bins * ag.bins];
    for i in 0..c.v.samples().len() {
        if let (Some(bv), Some(bg)) = (av.bin(c.v.samples()[i]), ag.bin(c.g.samples()[i])) {
            sum_x[bg * av.bins + bv] += truth.x.samples()[i] as f64;
            n_x[bg * av.bins + bv] += 1;
        }
    }
    let (mut checked, mut worst) = (0, 0.0f64);
    for i in 0..sum_x.len() {
        let x = sum_x[i] / n_x[i].max(1) as f64;
        // the boundary shell |x| <= 2 sigma, bins with at least 50 voxels
        if hv.count_vg[i] >= 50 && x.abs() <= 2.0 * sigma {
            worst = worst.max((hv.position[i] as f64 - x).abs());
            checked += 1;
        }
    }
    eprintln!("p(v,g) vs x: worst {worst:.4} voxel over {checked} bins");
    assert!(checked > 50);
    assert!(worst <= 0.1, "{worst}");
    // the one-pass counts and sums against plain loops written here
    assert_eq!(hv.hist, count(&[c.v.samples(), c.g.samples(), c.f2.samples()], hv.hist.axes.clone(), None).unwrap());
    let ah = &hv.hist.axes[2];
    let (mut n_v, mut g_v) = (vec![0u64; av.bins], vec![0.0f64; av.bins]);
    let mut n_vg = vec![0u64; av.bins * ag.bins];
    for i in 0..c.v.samples().len() {
        let (v, g, h) = (c.v.samples()[i], c.g.samples()[i], c.f2.samples()[i]);
        if let (Some(bv), Some(bg), Some(_)) = (av.bin(v), ag.bin(g), ah.bin(h)) {
            n_v[bv] += 1;
            g_v[bv] += g as f64;
            n_vg[bg * av.bins + bv] += 1;
        }
    }
    assert_eq!(hv.count_v, n_v);
    assert_eq!(hv.count_vg, n_vg);
    for b in 0..av.bins {
        let want = if n_v[b] > 0 { g_v[b] / n_v[b] as f64 } else { 0.0 };
        assert!((hv.mean_g_v[b] - want).abs() <= 1e-9 * want.abs().max(1.0), "bin {b}");
    }
    // the default opacity is the tent of p
    for i in 0..hv.opacity.len() {
        if hv.count_vg[i] > 0 && ag.centre(i / av.bins) > 1.0 {
            let want = (1.0 - (hv.position[i] as f64).abs() / hv.sigma).max(0.0);
            assert!((hv.opacity[i] as f64 - want).abs() < 1e-5);
        }
    }
}

fn g_hit_and_mask(c: &Channels, value_range: f64, params: &BoundaryParams) -> (Vec<f32>, Vec<bool>) {
    let out =
        mdtf_boundary::run(&BoundaryInput { g: &c.g, f2: &c.f2, normal: &c.normal, value_range }, params).unwrap();
    (out.g_hit.samples().to_vec(), hit_mask(out.hit.samples()))
}

#[test]
fn stretched_histogram_collapses_the_arch_to_a_line() {
    let sigma = 3.0;
    let ph = erf_sphere(Geometry::new([128; 3], [1.0; 3]), 38.4, sigma, 0.0, 255.0, None);
    let c = channels(ph.volume());
    let (g_hit, mask) = g_hit_and_mask(&c, 255.0, &BoundaryParams::default());
    let a = 255.0 / (sigma * (2.0 * PI).sqrt());
    let axes = vec![Axis::new("v", 0.0, 255.0, 256).unwrap(), Axis::new("g", 0.0, 1.2 * a, 256).unwrap()];
    let stretched = count(&[c.v.samples(), &g_hit], axes.clone(), Some(&mask)).unwrap();
    let normal = count(&[c.v.samples(), c.g.samples()], axes.clone(), Some(&mask)).unwrap();
    let share_near_a = |h: &mdtf_histogram::Histogram| {
        let mut near = 0;
        for bg in 0..256 {
            if ((axes[1].centre(bg) - a) / a).abs() <= 0.01 + axes[1].width() / a {
                near += (0..256).map(|bv| h.counts[bg * 256 + bv]).sum::<u64>();
            }
        }
        near as f64 / h.total() as f64
    };
    let (s, n) = (share_near_a(&stretched), share_near_a(&normal));
    eprintln!("share of traced voxels in the g bins within 1% of A: stretched {s:.4}, normal {n:.4}");
    assert!(s >= 0.95, "{s}");
    assert!(n < 0.3, "{n}");
}

#[test]
fn nested_shells_separate_into_rows_when_stretched() {
    let sigma = 1.5;
    let ph = RadialPhantom::tooth(Geometry::new([128; 3], [1.0; 3]), sigma);
    let c = channels(ph.volume());
    let (g_hit, mask) = g_hit_and_mask(&c, 255.0, &BoundaryParams::default());
    let peak = |jump: f64| jump / (sigma * (2.0 * PI).sqrt());
    // jumps: background->enamel 210, enamel->dentin 90, dentin->pulp 80
    let gmax = 1.1 * peak(210.0);
    let axes = vec![Axis::new("v", 0.0, 255.0, 256).unwrap(), Axis::new("g_hit", 0.0, gmax, 256).unwrap()];
    let h = count(&[c.v.samples(), &g_hit], axes.clone(), Some(&mask)).unwrap();
    // In the normal (v, g) histogram the arches of the enamel/dentin (90) and dentin/pulp (80)
    // boundaries overlap; stretched, the voxels of each boundary (the one nearest to them)
    // gather in the g row of that boundary's peak.
    let [nx, ny, _] = ph.geometry.dims;
    let c0 = ph.centre;
    let mode_row = |radius: f64| {
        let mut rows = vec![0u64; 256];
        for i in 0..g_hit.len() {
            let (x, y, z) = ((i % nx) as f64, ((i / nx) % ny) as f64, (i / (nx * ny)) as f64);
            let rho = ((x - c0[0]).powi(2) + (y - c0[1]).powi(2) + (z - c0[2]).powi(2)).sqrt();
            let nearest =
                ph.boundaries.iter().map(|b| b.radius).min_by(|a, b| (a - rho).abs().total_cmp(&(b - rho).abs()));
            if mask[i]
                && nearest == Some(radius)
                && let Some(bg) = axes[1].bin(g_hit[i])
            {
                rows[bg] += 1;
            }
        }
        (0..256).max_by_key(|&r| rows[r]).unwrap_or(0)
    };
    let (r_dentin, r_pulp) = (mode_row(ph.boundaries[1].radius), mode_row(ph.boundaries[2].radius));
    let expect = |jump: f64| peak(jump) / gmax * 256.0;
    eprintln!(
        "rows: enamel/dentin {r_dentin} (expected {:.1}), dentin/pulp {r_pulp} (expected {:.1})",
        expect(90.0),
        expect(80.0)
    );
    assert!(r_dentin.abs_diff(r_pulp) > 2, "{r_dentin} {r_pulp}");
    assert!((r_dentin as f64 - expect(90.0)).abs() <= 2.0 && (r_pulp as f64 - expect(80.0)).abs() <= 2.0);
    let _ = h.total();
}

#[test]
fn png_decodes_and_follows_the_log_mapping() {
    let v: Vec<f32> = (0..1000).map(|i| (i % 10) as f32).collect();
    let g: Vec<f32> = (0..1000).map(|i| ((i * i) % 7) as f32).collect();
    let axes = vec![Axis::new("v", 0.0, 10.0, 10).unwrap(), Axis::new("g", 0.0, 7.0, 7).unwrap()];
    let h = count(&[&v, &g], axes, None).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("h.png");
    write_png(&p, &h.image(Scale::Log), &h.describe(Scale::Log)).unwrap();
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&p).unwrap()));
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (10, 7));
    let text = reader.info().uncompressed_latin1_text.iter().map(|t| t.text.clone()).collect::<String>();
    assert!(text.contains("v horizontal: [0, 10]") && text.contains("g vertical (up): [0, 7]"), "{text}");
    let max = h.max();
    for y in 0..7 {
        for x in 0..10 {
            let c = h.counts[y * 10 + x];
            let want = (255.0 * (1.0 + c as f64).ln() / (1.0 + max as f64).ln()).round() as u8;
            assert_eq!(buf[(6 - y) * 10 + x], want, "g row {y} is drawn upward");
            assert_eq!(grey_level(c as u64, max, Scale::Log), want);
        }
    }
}

#[test]
fn bad_axes_are_refused() {
    let d = [1.0f32, 2.0, 3.0];
    assert!(Axis::new("v", 0.0, 0.0, 10).is_err());
    assert!(Axis::new("v", 0.0, 1.0, 0).is_err());
    let nan = [f32::NAN; 3];
    let e = AxisSpec::qbert("v").resolve("v", &nan).unwrap_err().to_string();
    assert!(e.contains("no finite samples"), "{e}");
    let axes = vec![Axis::new("a", 0.0, 4.0, 4).unwrap(), Axis::new("b", 0.0, 4.0, 4).unwrap()];
    assert!(count(&[&d, &d[..2]], axes, None).is_err());
}

#[test]
fn exr_holds_the_counts_as_f32() {
    use exr::prelude::*;
    let v: Vec<f32> = (0..500).map(|i| (i % 5) as f32).collect();
    let g: Vec<f32> = (0..500).map(|i| (i % 3) as f32).collect();
    let axes = vec![Axis::new("v", 0.0, 5.0, 5).unwrap(), Axis::new("g", 0.0, 3.0, 3).unwrap()];
    let h = count(&[&v, &g], axes, None).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("h.exr");
    mdtf_histogram::write_exr(&p, &h).unwrap();
    let image = read_first_flat_layer_from_file(&p).unwrap();
    let ch = &image.layer_data.channel_data.list[0];
    assert_eq!(ch.name, Text::from("Y"));
    let values: Vec<f32> = ch.sample_data.values_as_f32().collect();
    for y in 0..3 {
        for x in 0..5 {
            assert_eq!(values[(2 - y) * 5 + x], h.counts[y * 5 + x] as f32);
        }
    }
}

#[test]
fn histogram_volume_does_not_depend_on_the_thread_count() {
    // f64 sums are kept per fixed part and merged in order; threads group the parts
    let c = channels(erf_sphere(Geometry::new([48; 3], [1.0; 3]), 14.0, 2.0, 0.0, 255.0, None).volume());
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let hv = pool
            .install(|| {
                histogram_volume(c.v.samples(), c.g.samples(), c.f2.samples(), c.v.plane_len(), &HvolParams::default())
            })
            .unwrap();
        (hv.hist, hv.mean_g_v, hv.mean_h_v, hv.position, hv.sigma)
    };
    let one = run(1);
    for threads in [2, 3, 5] {
        assert_eq!(one, run(threads), "{threads} threads");
    }
}

#[test]
fn a_histogram_volume_fed_by_slabs_equals_the_whole_one_for_any_slabs_and_lanes() {
    let c = channels(erf_sphere(Geometry::new([40, 36, 48], [1.0, 1.2, 0.8]), 13.0, 2.0, 3.0, 255.0, None).volume());
    let (v, g, f2, plane) = (c.v.samples(), c.g.samples(), c.f2.samples(), c.v.plane_len());
    let params = HvolParams::default();
    let whole = histogram_volume(v, g, f2, plane, &params).unwrap();
    let axes = HvolAxes::of(v, g, f2, &params).unwrap();
    for height in [1, 7, 33, 48] {
        for lanes in [1, 2, 3, 16] {
            let mut by_slabs = HvolBySlabs::new(&axes, plane, 48, lanes).unwrap();
            for first in (0..48).step_by(height) {
                let at = first * plane..(first + height).min(48) * plane;
                by_slabs.add_slab(first, &v[at.clone()], &g[at.clone()], &f2[at]).unwrap();
            }
            let hv = by_slabs.finish(&params).unwrap();
            assert_eq!(hv.hist, whole.hist, "height {height}, lanes {lanes}");
            assert_eq!(
                (hv.mean_g_v, hv.mean_h_v, hv.position, hv.sigma),
                (whole.mean_g_v.clone(), whole.mean_h_v.clone(), whole.position.clone(), whole.sigma),
                "height {height}, lanes {lanes}"
            );
        }
    }
    let mut by_slabs = HvolBySlabs::new(&axes, plane, 48, 2).unwrap();
    assert!(by_slabs.add_slab(0, &v[..plane + 1], &g[..plane + 1], &f2[..plane + 1]).is_err(), "a partial slice");
}

#[test]
fn histogram_volume_parts_counted_by_tasks_elsewhere_give_the_whole_one() {
    // each task counts whole fixed parts, slice by slice, and goes through its stored bytes
    let c = channels(erf_sphere(Geometry::new([40, 36, 48], [1.0, 1.2, 0.8]), 13.0, 2.0, 3.0, 255.0, None).volume());
    let (v, g, f2, plane) = (c.v.samples(), c.g.samples(), c.f2.samples(), c.v.plane_len());
    let params = HvolParams::default();
    let whole = histogram_volume(v, g, f2, plane, &params).unwrap();
    let axes = HvolAxes::of(v, g, f2, &params).unwrap();
    let parts = fixed_parts(48);
    // tasks of 1, 5 and 10 parts, absorbed in reverse order by one accumulator
    let mut merged = HvolAccumulator::new(&axes).unwrap();
    let mut stored = Vec::new();
    for group in [0..1, 1..6, 6..16] {
        let mut acc = HvolAccumulator::new(&axes).unwrap();
        for k in parts[group.start].start..parts[group.end - 1].end {
            let at = k * plane..(k + 1) * plane;
            acc.add_slice(k, 48, &v[at.clone()], &g[at.clone()], &f2[at]);
        }
        let mut bytes = Vec::new();
        ciborium::into_writer(&acc.part(), &mut bytes).unwrap();
        assert!(bytes.len() < 4_000_000, "{} bytes", bytes.len());
        stored.push(bytes);
    }
    for bytes in stored.iter().rev() {
        merged.absorb(ciborium::from_reader::<HvolPart, _>(bytes.as_slice()).unwrap()).unwrap();
    }
    // a part absorbed twice is refused
    assert!(merged.absorb(ciborium::from_reader::<HvolPart, _>(stored[0].as_slice()).unwrap()).is_err());
    let hv = HvolAccumulator::finish(vec![merged], &params).unwrap();
    assert_eq!(hv.hist, whole.hist);
    assert_eq!(
        (hv.mean_g_v, hv.mean_h_v, hv.position, hv.sigma),
        (whole.mean_g_v.clone(), whole.mean_h_v.clone(), whole.position.clone(), whole.sigma)
    );
}

/// A (v, g) histogram of 8 x 6 bins with 1000 voxels in bin (2, 5) and 10 in bin (6, 1), and its samples.
fn two_bins() -> (mdtf_histogram::Histogram, Vec<f32>) {
    let mut v = vec![2.5f32; 1000];
    let mut g = vec![5.5f32; 1000];
    v.extend([6.5f32; 10]);
    g.extend([1.5f32; 10]);
    let axes = vec![Axis::new("v", 0.0, 8.0, 8).unwrap(), Axis::new("g", 0.0, 6.0, 6).unwrap()];
    (count(&[&v, &g], axes, None).unwrap(), v)
}

/// The pixels of `fig` left of its colour bar (the right 130) that have colour `c`.
fn pixels_of(fig: &mdtf_histogram::Rgb, c: [u8; 3]) -> Vec<(usize, usize)> {
    let plot_width = fig.width - 130;
    (0..fig.height)
        .flat_map(|y| (0..plot_width).map(move |x| (x, y)))
        .filter(|&(x, y)| fig.pixels[3 * (y * fig.width + x)..3 * (y * fig.width + x) + 3] == c)
        .collect()
}

#[test]
fn figures_have_axes_labels_and_a_colour_bar_and_show_each_bin_in_place() {
    // 2D: counts only in bin (2, 5) of 8 x 6 (1000) and bin (6, 1) (10)
    let (h, v) = two_bins();
    let labels = mdtf_histogram::Labels::of(&h, "test input");
    assert_eq!(labels.axes, ["v (input units)", "g = |grad v| (input units per world unit)"]);
    let fig = h.figure(Scale::Log, &labels).unwrap().unwrap();
    assert!(fig.width <= 1200 && fig.height <= 1200, "{} x {}", fig.width, fig.height);
    let at = |x: usize, y: usize| [0, 1, 2].map(|c| fig.pixels[3 * (y * fig.width + x) + c]);
    // the two filled bins by their colours (the top of the ramp, and its log level for 10), in
    // the heat map, left of the colour bar (the right 130 pixels)
    let top = mdtf_histogram::count_colour(1000, 1000, Scale::Log);
    let low = mdtf_histogram::count_colour(10, 1000, Scale::Log);
    let plot_width = mdtf_histogram::FIGURE_SIZE.0 as usize - 130;
    let where_is = |c: [u8; 3]| {
        let hits: Vec<(usize, usize)> = (0..fig.height)
            .flat_map(|y| (0..plot_width).map(move |x| (x, y)))
            .filter(|&(x, y)| at(x, y) == c)
            .collect();
        assert!(!hits.is_empty(), "colour {c:?} not drawn");
        let n = hits.len() as f64;
        (hits.iter().map(|p| p.0 as f64).sum::<f64>() / n, hits.iter().map(|p| p.1 as f64).sum::<f64>() / n, hits.len())
    };
    let (x_top, y_top, n_top) = where_is(top);
    let (x_low, y_low, n_low) = where_is(low);
    // bin (6, 1) lies right of and below bin (2, 5), 4 bin widths and heights away; the cells are alike
    assert!(x_low > x_top && y_low > y_top, "({x_low}, {y_low}) vs ({x_top}, {y_top})");
    let (bw, bh) = ((x_low - x_top) / 4.0, (y_low - y_top) / 4.0);
    assert!((n_top as f64 - bw * bh).abs() <= 0.1 * bw * bh + bw + bh, "{n_top} pixels for a {bw} x {bh} cell");
    assert!((n_low as f64 - n_top as f64).abs() <= bw + bh, "{n_low} vs {n_top}");
    // a figure without labels differs from the labelled one: the labels are drawn
    let bare = h.figure(
        Scale::Log,
        &mdtf_histogram::Labels { title: String::new(), axes: vec![String::new(); 2], note: None, arches: vec![] },
    );
    assert_ne!(bare.unwrap().unwrap().pixels, fig.pixels);
    // written with the labels in the PNG's text too
    let dir = tempfile::tempdir().unwrap();
    mdtf_histogram::write_histogram(dir.path(), &h, Scale::Log, "test input").unwrap();
    let png = std::fs::read(dir.path().join("hist_v_g.png")).unwrap();
    let text = String::from_utf8_lossy(&png);
    assert!(text.contains("hist_v_g of test input") && text.contains("g = |grad v| (input units per world unit)"));
    // 1D: bars on both scales, labelled
    let h1 = count(&[&v], vec![Axis::new("v", 0.0, 8.0, 8).unwrap()], None).unwrap();
    let f1 = h1.figure(Scale::Log, &mdtf_histogram::Labels::of(&h1, "test input")).unwrap().unwrap();
    assert!(
        f1.pixels.chunks_exact(3).any(|p| p == [0, 0, 0]) && f1.pixels.chunks_exact(3).any(|p| p == [170, 170, 170])
    );
}

/// A boundary from v 1 to 7 with peak g 5, drawn in pure blue.
fn blue_arch() -> mdtf_histogram::ArchMark {
    mdtf_histogram::ArchMark {
        v_low: 1.0,
        v_high: 7.0,
        g_peak: 5.0,
        label: "1".into(),
        colour: [0, 0, 255],
        collapsed: false,
    }
}

#[test]
fn a_table_over_the_counts_shows_its_colour_where_it_is_opaque_and_arches_follow_the_model() {
    // counts in bins (2, 5) and (6, 1) of 8 x 6; a 4 x 3 table (cells of 2 x 2
    // bins), red and opaque in its cell (1, 2) (v 2..4, g 4..6, over bin (2, 5)),
    // green at a quarter of that in (3, 0) (v 6..8, g 0..2, over bin (6, 1))
    let (h, _) = two_bins();
    let mut rgba = vec![0.0f32; 4 * 12];
    rgba[4 * (2 * 4 + 1)..4 * (2 * 4 + 1) + 4].copy_from_slice(&[1.0, 0.0, 0.0, 0.8]);
    rgba[4 * 3..4 * 3 + 4].copy_from_slice(&[0.0, 1.0, 0.0, 0.2]);
    let overlay = mdtf_histogram::Overlay { x: (0.0, 8.0, 4), y: (0.0, 6.0, 3), rgba: &rgba };
    let labels = mdtf_histogram::Labels::of(&h, "test input");
    let fig = h.figure_with(Scale::Log, &labels, Some(&overlay)).unwrap().unwrap();
    // the opaque cell is pure red (relative opacity 1) over its counts and empty bins alike
    let red = pixels_of(&fig, [255, 0, 0]);
    // the quarter-opacity cell: green mixed in by sqrt(0.25) = 0.5 over black (empty bins)
    // and over bin (6, 1)'s grey 40 + 160 * log-level
    let green = pixels_of(&fig, [0, 128, 0]);
    let grey = (40.0 + 160.0 * mdtf_histogram::grey_level(10, 1000, Scale::Log) as f64 / 255.0).round();
    let on_counts =
        pixels_of(&fig, [(grey * 0.5).round() as u8, (grey * 0.5 + 127.5).round() as u8, (grey * 0.5).round() as u8]);
    assert!(
        red.len() > 1000 && green.len() > 1000 && on_counts.len() > 100,
        "{} {} {}",
        red.len(),
        green.len(),
        on_counts.len()
    );
    // red lies above and left of green, a cell apart: 2 cells in v and 2 in g between their centres
    let mean = |p: &[(usize, usize)]| {
        let n = p.len() as f64;
        (p.iter().map(|q| q.0 as f64).sum::<f64>() / n, p.iter().map(|q| q.1 as f64).sum::<f64>() / n)
    };
    let ((xr, yr), (xg, yg)) = (mean(&red), mean(&green));
    assert!(xg > xr && yg > yr, "red ({xr}, {yr}), green ({xg}, {yg})");
    // without the table, bin (2, 5) is grey at the top of the dark ramp, 200, and empty bins black
    let bare = h
        .figure_with(Scale::Log, &labels, Some(&mdtf_histogram::Overlay { rgba: &[0.0; 48], ..overlay }))
        .unwrap()
        .unwrap();
    assert!(pixels_of(&bare, [200, 200, 200]).len() > 100 && pixels_of(&bare, [0, 0, 0]).len() > 10 * red.len());
    // an arch in pure blue, from v 1 to 7 with peak g 5: its apex column is at v = 4, right of
    // red's left edge; drawn only when asked for
    let mut arched = labels.clone();
    arched.arches = vec![blue_arch()];
    arched.note = Some("a note".into());
    let with_arch = h.figure_with(Scale::Log, &arched, Some(&overlay)).unwrap().unwrap();
    let blue = pixels_of(&with_arch, [0, 0, 255]);
    assert!(pixels_of(&fig, [0, 0, 255]).is_empty() && blue.len() > 200, "{}", blue.len());
    // the arch is symmetric about v = 4: its blue pixels' mean x is where the red cell (v 2..4) ends
    let (xb, _) = mean(&blue);
    let red_right = red.iter().map(|p| p.0).max().unwrap() as f64;
    assert!((xb - red_right).abs() < 6.0, "arch centre {xb}, v = 4 at {red_right}");
}

#[test]
fn two_histograms_side_by_side_share_one_colour_scale() {
    // the left's bins hold 1000 and 10 voxels, the right's one bin 100
    let mut v = vec![2.5f32; 1000];
    let mut g = vec![5.5f32; 1000];
    v.extend([6.5f32; 10]);
    g.extend([1.5f32; 10]);
    let axes = vec![Axis::new("v", 0.0, 8.0, 8).unwrap(), Axis::new("g", 0.0, 6.0, 6).unwrap()];
    let left = count(&[&v, &g], axes.clone(), None).unwrap();
    let right = count(&[&[4.5f32; 100][..], &[3.5f32; 100][..]], axes, None).unwrap();
    let labels = [&mdtf_histogram::Labels::of(&left, "left"), &mdtf_histogram::Labels::of(&right, "right")];
    let fig = left.figure_beside(&right, Scale::Log, labels).unwrap().unwrap();
    assert_eq!((fig.width as u32, fig.height as u32), mdtf_histogram::SIDE_BY_SIDE_SIZE);
    assert!(fig.width <= 1200 && fig.height <= 1200);
    let half = (fig.width - 130) / 2;
    let count_in = |c: [u8; 3], xs: std::ops::Range<usize>| {
        (0..fig.height)
            .flat_map(|y| xs.clone().map(move |x| (x, y)))
            .filter(|&(x, y)| fig.pixels[3 * (y * fig.width + x)..3 * (y * fig.width + x) + 3] == c)
            .count()
    };
    // one scale for both: 1000 is the top on the left, 100 has its own (lower) colour on the right only
    let (top, hundred) =
        (mdtf_histogram::count_colour(1000, 1000, Scale::Log), mdtf_histogram::count_colour(100, 1000, Scale::Log));
    assert!(count_in(top, 0..half) > 100 && count_in(top, half..fig.width - 130) == 0);
    assert!(count_in(hundred, half..fig.width - 130) > 100 && count_in(hundred, 0..half) == 0);
    // a 1D histogram has no side-by-side heat map
    let one = count(&[&v], vec![Axis::new("v", 0.0, 8.0, 8).unwrap()], None).unwrap();
    assert!(one.figure_beside(&right, Scale::Log, labels).unwrap().is_none());

    // a boundary from v 1 to 7 with peak g 5, in pure blue: an arch on the normal panel, the
    // horizontal line g_hit = 5 it collapses to on the stretched one
    let arch = blue_arch();
    let (mut l, mut r) = (labels[0].clone(), labels[1].clone());
    l.arches = vec![arch.clone()];
    r.arches = vec![arch.collapsed()];
    let marked = left.figure_beside(&right, Scale::Log, [&l, &r]).unwrap().unwrap();
    assert!(count_in([0, 0, 255], 0..fig.width) == 0, "no marks unless asked for");
    let blue: Vec<(usize, usize)> = (0..marked.height)
        .flat_map(|y| (0..marked.width - 130).map(move |x| (x, y)))
        .filter(|&(x, y)| marked.pixels[3 * (y * marked.width + x)..3 * (y * marked.width + x) + 3] == [0, 0, 255])
        .collect();
    let rows = |side: &dyn Fn(usize) -> bool| {
        let ys: Vec<usize> = blue.iter().filter(|p| side(p.0)).map(|p| p.1).collect();
        (ys.len(), ys.iter().max().unwrap_or(&0) - ys.iter().min().unwrap_or(&0))
    };
    let ((n_left, tall_left), (n_right, tall_right)) = (rows(&|x| x < half), rows(&|x| x >= half));
    // the arch rises over most of the plot's g (0 to 5 of 6); the line is a few pixels thick
    assert!(n_left > 200 && tall_left > 150, "arch: {n_left} pixels over {tall_left} rows");
    assert!(n_right > 200 && tall_right <= 4, "line: {n_right} pixels over {tall_right} rows");
}

#[test]
fn the_projections_figure_shows_each_panel_over_its_own_axes() {
    // all voxels in one bin of a 4 x 4 x 4 (v, g, f2) histogram: v 3/3, g 0/3, f2 1/3 of their ranges
    let (v, g, f2) = (vec![3.5f32; 50], vec![0.5f32; 50], vec![1.5f32; 50]);
    let axes = ["v", "g", "f2"].map(|n| Axis::new(n, 0.0, 4.0, 4).unwrap()).to_vec();
    let h = count(&[&v, &g, &f2], axes, None).unwrap();
    let fig = h.projections_figure(Scale::Linear, "test input").unwrap().unwrap();
    assert_eq!((fig.width as u32, fig.height as u32), mdtf_histogram::PROJECTIONS_SIZE);
    let lift = |x: f64| (255.0 * (0.25 + 0.75 * x)).round() as u8;
    let colour = [lift(1.0), lift(0.0), lift(1.0 / 3.0)];
    let third = fig.width / 3;
    for panel in 0..3 {
        let columns: Vec<usize> = (0..fig.height)
            .flat_map(|y| (panel * third..(panel + 1) * third).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                // within a code of the colour (its blue, 127.5, rounds either way)
                (0..3).all(|k| fig.pixels[3 * (y * fig.width + x) + k].abs_diff(colour[k]) <= 1)
            })
            .map(|(x, _)| x - panel * third)
            .collect();
        assert!(columns.len() > 500, "panel {panel}: {} pixels", columns.len());
        // the bin's column: v = 3.5 (right quarter) in the (v, g) and (v, f2) panels, g = 0.5 (left) in (g, f2)
        let mean = columns.iter().sum::<usize>() as f64 / columns.len() as f64 / third as f64;
        let right = panel < 2;
        assert!(if right { mean > 0.7 } else { mean < 0.4 }, "panel {panel}: mean column {mean} of the third");
    }
    assert!(
        count(&[&v, &g], vec![Axis::new("v", 0.0, 4.0, 4).unwrap(), Axis::new("g", 0.0, 4.0, 4).unwrap()], None)
            .unwrap()
            .projections_figure(Scale::Linear, "2D")
            .unwrap()
            .is_none()
    );
}
