//! The value range of a volume, checked for NaN and infinities in the same pass.

use rayon::prelude::*;

/// (min, max) of `data`, or None if any sample is NaN or infinite; in parallel
/// over blocks (min and max do not depend on the order, so neither does the result).
pub fn finite_range(data: &[f32]) -> Option<(f32, f32)> {
    data.par_chunks(1 << 16)
        .map(block_range)
        .reduce(|| Some((f32::INFINITY, f32::NEG_INFINITY)), |a, b| Some((a?.0.min(b?.0), a?.1.max(b?.1))))
}

/// [`finite_range`] of one block, in eight lanes so that the loop vectorises.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512vl+avx2", "x86_64+avx2"))]
fn block_range(data: &[f32]) -> Option<(f32, f32)> {
    let mut lo = [f32::INFINITY; 8];
    let mut hi = [f32::NEG_INFINITY; 8];
    let mut poison = [0.0f32; 8]; // v * 0 is NaN exactly for NaN and infinities
    let (chunks, tail) = data.as_chunks::<8>();
    for c in chunks {
        for l in 0..8 {
            lo[l] = if c[l] < lo[l] { c[l] } else { lo[l] };
            hi[l] = if c[l] > hi[l] { c[l] } else { hi[l] };
            poison[l] += c[l] * 0.0;
        }
    }
    for &v in tail {
        lo[0] = lo[0].min(v);
        hi[0] = hi[0].max(v);
        poison[0] += v * 0.0;
    }
    if poison.iter().any(|p| p.is_nan()) {
        return None;
    }
    Some((lo.iter().copied().fold(f32::INFINITY, f32::min), hi.iter().copied().fold(f32::NEG_INFINITY, f32::max)))
}
