//! Lookup tables for 1D transfer functions: Engel et al.'s pre-integration
//! table and the peak table of peak finding.
//!
//! A 1D TF is `n` RGBA samples over the scalar range s in [0, 1] (sample k at
//! s = k / (n - 1)), linearly interpolated: RGB is the emitted colour (0..1),
//! A the extinction tau (per world unit).

use rayon::prelude::*;

/// A sampled 1D transfer function.
#[derive(Debug, Clone, PartialEq)]
pub struct Tf1d {
    /// (r, g, b, tau) at s = k / (n - 1).
    pub samples: Vec<[f64; 4]>,
}

impl Tf1d {
    /// Linear interpolation at s in [0, 1] (clamped).
    pub fn at(&self, s: f64) -> [f64; 4] {
        let n = self.samples.len();
        if n == 1 {
            return self.samples[0];
        }
        let x = s.clamp(0.0, 1.0) * (n - 1) as f64;
        let k = (x.floor() as usize).min(n - 2);
        let t = x - k as f64;
        let (a, b) = (self.samples[k], self.samples[k + 1]);
        [0, 1, 2, 3].map(|c| a[c] + t * (b[c] - a[c]))
    }

    /// An example TF with two extinction peaks (tau = 4 at s = 0.3, width
    /// 0.05; tau = 1.5 at s = 0.7, width 0.1) and colour (s, 1 - s, 0.5),
    /// sampled at `n` >= 2 points. The self-check, the tests and the
    /// benchmarks use it as a TF with narrow features.
    pub fn two_peaks(n: usize) -> Tf1d {
        let last = n.max(2) - 1;
        Tf1d {
            samples: (0..=last)
                .map(|k| {
                    let s = k as f64 / last as f64;
                    let tau =
                        4.0 * (-((s - 0.3) / 0.05f64).powi(2)).exp() + 1.5 * (-((s - 0.7) / 0.1f64).powi(2)).exp();
                    [s, 1.0 - s, 0.5, tau]
                })
                .collect(),
        }
    }
}

/// The same integrals as [`segment`] by `steps` midpoint steps with the
/// optical depth accumulated step by step: a slow, independent reference
/// for checking [`segment`] and [`preintegration_table`].
pub fn segment_by_midpoint(tf: &Tf1d, sf: f64, sb: f64, d: f64, steps: usize) -> [f64; 4] {
    let steps = steps.max(1);
    let h = 1.0 / steps as f64;
    let (mut depth, mut c) = (0.0, [0.0; 3]);
    for k in 0..steps {
        let t = (k as f64 + 0.5) * h;
        let v = tf.at(sf + t * (sb - sf));
        let mid_depth = depth + 0.5 * d * v[3] * h;
        for ch in 0..3 {
            c[ch] += v[ch] * d * v[3] * (-mid_depth).exp() * h;
        }
        depth += d * v[3] * h;
    }
    [c[0], c[1], c[2], 1.0 - (-depth).exp()]
}

/// Gauss-Legendre nodes and weights on [0, 1] (2 points: exact for degree 3;
/// on pieces where the TF is linear and the attenuation below e^-1/2 this
/// is within 1e-5 of the exact integral, see the tests).
const GL: [(f64, f64); 2] = [(0.211_324_865_405_187_1, 0.5), (0.788_675_134_594_812_9, 0.5)];

/// Colour (premultiplied, emission-absorption with attenuation inside the
/// segment) and opacity of a segment of length `d` along which s goes
/// linearly from `sf` to `sb`:
/// alpha = 1 - exp(-d int_0^1 tau dt), C = d int_0^1 c tau exp(-d int_0^t tau) dt.
/// The segment is cut where s crosses a TF sample (tau is linear in t on
/// each piece, so its integral is exact) and each piece is integrated with
/// 2-point Gauss-Legendre, subdivided so that no piece attenuates by more than e^-1/2.
pub fn segment(tf: &Tf1d, sf: f64, sb: f64, d: f64) -> [f64; 4] {
    segment_in_pieces(tf, sf, sb, d, 2.0)
}

/// [`segment`] with every piece attenuating by at most e^(-1 / `pieces_per_depth`)
/// (2: [`segment`]; 4 for about eight times less error at twice the work).
///
/// Compiled for AVX-512 and AVX2 as well as the baseline (rounding is an
/// instruction there, not a library call), picked at run time; no FMA, so
/// every path gives the same bits.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512vl+avx2", "x86_64+avx2"))]
pub(crate) fn segment_in_pieces(tf: &Tf1d, sf: f64, sb: f64, d: f64, pieces_per_depth: f64) -> [f64; 4] {
    let n = tf.samples.len().max(2);
    let span = (n - 1) as f64;
    // the t of each sample position strictly between sf and sb, in increasing t
    let (klo, khi) = ((sf.min(sb) * span).floor() as usize + 1, (sf.max(sb) * span).ceil() as usize);
    let inner = khi.saturating_sub(klo);
    let inv = if sb != sf { 1.0 / ((sb - sf) * span) } else { 0.0 };
    // (t, TF value) at cut m: the m-th sample crossed, or the back end
    let cut = |m: usize| -> (f64, [f64; 4]) {
        if m > inner {
            return (1.0, tf.at(sb));
        }
        let k = if sb > sf { klo + m - 1 } else { khi - m };
        ((k as f64 - sf * span) * inv, tf.samples[k])
    };
    // optical depth so far, and exp(-optical) kept as a running product
    let (mut optical, mut transmitted, mut colour) = (0.0f64, 1.0f64, [0.0f64; 3]);
    let mut va = tf.at(sf);
    let mut t0 = 0.0;
    for m in 1..=inner + 1 {
        let (t1, vb) = cut(m);
        if t1 <= t0 {
            continue;
        }
        // the TF is linear on this piece: interpolate instead of looking it up
        let depth = 0.5 * pieces_per_depth * d * (va[3] + vb[3]) * (t1 - t0);
        // (NaN: one piece)
        let pieces = if depth > 1.0 { depth.ceil() as usize } else { 1 };
        let dv = [vb[0] - va[0], vb[1] - va[1], vb[2] - va[2], vb[3] - va[3]];
        // one piece is the common case (a short piece of a long segment): no divisions
        let (h, df) = if pieces == 1 { (t1 - t0, 1.0) } else { ((t1 - t0) / pieces as f64, 1.0 / pieces as f64) };
        for p in 0..pieces {
            let fa = p as f64 * df;
            let tau_a = va[3] + fa * dv[3];
            for &(x, wgt) in &GL {
                let f = fa + x * df;
                let tau = va[3] + f * dv[3];
                let local = 0.5 * d * (tau_a + tau) * x * h; // <= 1/2 for pieces_per_depth >= 2
                let w = d * tau * transmitted * exp_neg_small(local) * wgt * h;
                colour[0] += (va[0] + f * dv[0]) * w;
                colour[1] += (va[1] + f * dv[1]) * w;
                colour[2] += (va[2] + f * dv[2]) * w;
            }
            let piece = 0.5 * d * (tau_a + va[3] + (fa + df) * dv[3]) * h;
            optical += piece;
            transmitted *= exp_neg_small(piece);
        }
        va = vb;
        t0 = t1;
    }
    [colour[0], colour[1], colour[2], 1.0 - (-optical).exp()]
}

/// exp(-y) for 0 <= y <= 1/2 by its Taylor polynomial of degree 7
/// (relative error below 1e-7 there, 3e-5 over the 256 pieces of the
/// longest segment; no library call in the inner loop).
#[inline(always)]
fn exp_neg_small(y: f64) -> f64 {
    const INV: [f64; 7] = [1.0, 1.0 / 2.0, 1.0 / 3.0, 1.0 / 4.0, 1.0 / 5.0, 1.0 / 6.0, 1.0 / 7.0];
    // Horner: 1 - y (1 - y/2 (1 - y/3 (... (1 - y/7))))
    let mut acc = 1.0;
    for k in (0..7).rev() {
        acc = 1.0 - y * INV[k] * acc;
    }
    acc
}

/// The n x n pre-integration table (Engel et al. 2001) for segment length
/// `d`: entry (i, j), i = front fastest, is [`segment`] from s = i/(n-1) to s = j/(n-1).
pub fn preintegration_table(tf: &Tf1d, n: usize, d: f64) -> Vec<[f32; 4]> {
    let mut table = vec![[0f32; 4]; n * n];
    let step = 1.0 / (n.max(2) - 1) as f64;
    table.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
        for (i, e) in row.iter_mut().enumerate() {
            *e = segment(tf, i as f64 * step, j as f64 * step, d).map(|x| x as f32);
        }
    });
    table
}

/// Local maxima of the opacity (tau) samples: k with tau[k] > tau[k-1] (or
/// k = 0) and tau[k] >= tau[k+1] (or k = n-1), plateaus counted at their first sample.
pub fn peaks(tf: &Tf1d) -> Vec<usize> {
    let tau: Vec<f64> = tf.samples.iter().map(|s| s[3]).collect();
    let n = tau.len();
    (0..n)
        .filter(|&k| (k == 0 || tau[k] > tau[k - 1]) && (k + 1 == n || tau[k] >= tau[k + 1]) && tau[k] > 0.0)
        .collect()
}

/// Peaks one entry of the peak table holds (one per RGBA component).
pub const PEAKS_PER_ENTRY: usize = 4;

/// The n x n peak table of 1D peak finding (Knoll et al. 2009, the
/// peak-finding paper's ref. [12]; its section 3: "storing the peak isovalue
/// (or isovalues) between [f0, f1]"). Entry (i, j), front i fastest, holds the
/// s of the TF's peaks (see [`peaks`]) between the front value s_i = i/(n-1)
/// and the back value s_j, both included, in the order a ray going from s_i
/// to s_j crosses them (the one nearest s_i first), up to
/// [`PEAKS_PER_ENTRY`]; -1 fills the rest. The first component is the first
/// isosurface the segment meets, which is what a renderer that finds one
/// peak per segment needs.
pub fn peak_table(tf: &Tf1d, n: usize) -> Vec<[f32; PEAKS_PER_ENTRY]> {
    let m = tf.samples.len().max(2);
    let pk: Vec<f64> = peaks(tf).into_iter().map(|k| k as f64 / (m - 1) as f64).collect();
    let step = 1.0 / (n.max(2) - 1) as f64;
    let mut table = vec![[-1f32; PEAKS_PER_ENTRY]; n * n];
    table.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
        for (i, e) in row.iter_mut().enumerate() {
            let (sf, sb) = (i as f64 * step, j as f64 * step);
            let (lo, hi) = (sf.min(sb) - 1e-12, sf.max(sb) + 1e-12);
            let inside = pk.iter().copied().filter(|s| *s >= lo && *s <= hi);
            // pk ascends: a rising segment meets them in that order, a falling one in reverse
            let ordered: Vec<f64> = if sb >= sf { inside.collect() } else { inside.rev().collect() };
            for (slot, s) in e.iter_mut().zip(ordered) {
                *slot = s as f32;
            }
        }
    });
    table
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_entries_match_fine_quadrature() {
        let tf = Tf1d::two_peaks(256);
        let n = 40;
        let table = preintegration_table(&tf, n, 1.7);
        let mut worst = 0.0f64;
        for j in 0..n {
            for i in 0..n {
                let want = segment_by_midpoint(&tf, i as f64 / (n - 1) as f64, j as f64 / (n - 1) as f64, 1.7, 4_000);
                for c in 0..4 {
                    worst = worst.max((table[j * n + i][c] as f64 - want[c]).abs());
                }
            }
        }
        eprintln!("pre-integration: worst difference to the fine quadrature {worst:e}");
        assert!(worst < 1e-4, "{worst:e}");
    }

    #[test]
    fn peak_table_lists_the_peaks_a_segment_crosses_in_ray_order_as_a_brute_force_scan_does() {
        // five peaks (s = 0.1, 0.3, 0.5, 0.7, 0.9), so some entries have more than four
        let n = 101;
        let tf = Tf1d {
            samples: (0..n)
                .map(|k| {
                    let tau = if k % 20 == 10 { 1.0 + (k / 20) as f64 } else { 0.0 };
                    [1.0, 1.0, 1.0, tau]
                })
                .collect(),
        };
        let table = peak_table(&tf, n);
        let tau: Vec<f64> = tf.samples.iter().map(|s| s[3]).collect();
        let mut seen_full = false;
        for j in 0..n {
            for i in 0..n {
                // brute force: walk the samples from i towards j, collecting local maxima
                let path: Vec<usize> = if j >= i { (i..=j).collect() } else { (j..=i).rev().collect() };
                let mut want = [-1f32; PEAKS_PER_ENTRY];
                let mut slot = 0;
                for k in path {
                    let is_peak =
                        (k == 0 || tau[k] > tau[k - 1]) && (k == n - 1 || tau[k] >= tau[k + 1]) && tau[k] > 0.0;
                    if is_peak && slot < PEAKS_PER_ENTRY {
                        want[slot] = k as f32 / (n - 1) as f32;
                        slot += 1;
                    }
                }
                seen_full |= slot == PEAKS_PER_ENTRY;
                assert_eq!(table[j * n + i], want, "({i}, {j})");
            }
        }
        assert!(seen_full);
        assert_eq!(peaks(&tf), vec![10, 30, 50, 70, 90]);
        // falling segment from s = 1 to 0: the first peak met is the one at 0.9
        assert_eq!(table[n - 1], [0.9, 0.7, 0.5, 0.3]);
    }
}
