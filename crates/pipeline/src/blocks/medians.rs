//! The medians a whole run takes of whole channels (the (v, 1/g)
//! histogram's axis, gaussian-tf's default TGTF), taken exactly slab by
//! slab ([`mdtf_volume::median_of_pieces`]: the two passes of a radix
//! select over the selection, the first also counting it; one pass for g's
//! median when the derive pass counted its first).

use super::{ChannelError, SlabChannels};
use crate::channel::Channel;
use mdtf_histogram::Axis;
use mdtf_pack::GaussianPrimitive;
use mdtf_volume::KeyBuckets;
use std::ops::Range;

/// The lower median of the finite samples `piece(z)` gives over `slabs`
/// (as [`mdtf_volume::median`] of the whole), or None without any.
fn median_of_slabs(
    slabs: &[Range<usize>],
    piece: &mut dyn FnMut(Range<usize>) -> Result<Vec<f32>, ChannelError>,
) -> Result<Option<f32>, ChannelError> {
    mdtf_volume::median_of_pieces(|visit| {
        for z in slabs {
            visit(&piece(z.clone())?);
        }
        Ok(())
    })
}

/// The lower median of g over `slabs`, one pass when `buckets` counted every g already.
fn median_of_g(
    chans: &mut SlabChannels,
    slabs: &[Range<usize>],
    buckets: Option<&KeyBuckets>,
) -> Result<Option<f32>, ChannelError> {
    match buckets {
        Some(b) => mdtf_volume::median_from_buckets(b, |visit| {
            for z in slabs {
                visit(chans.samples(Channel::G, z.clone())?);
            }
            Ok(())
        }),
        None => median_of_slabs(slabs, &mut |z| chans.samples(Channel::G, z).map(<[f32]>::to_vec)),
    }
}

/// [`Axis::inverse_gradient`] of the whole g, 256 bins; `g_buckets`: the
/// first radix pass over g, if a pass that derived it took it.
pub(super) fn inverse_gradient_axis(
    chans: &mut SlabChannels,
    slabs: &[Range<usize>],
    g_buckets: Option<&KeyBuckets>,
) -> Result<Option<Axis>, ChannelError> {
    let Some(median) = median_of_g(chans, slabs, g_buckets)? else { return Ok(None) };
    let cut = 2.0 * median;
    let above = median_of_slabs(slabs, &mut |z| {
        Ok(chans.samples(Channel::G, z)?.iter().copied().filter(|&x| x > cut && x.is_finite()).collect())
    })?;
    Ok(above.and_then(|g_b| Axis::inverse_gradient_at(g_b, 256)))
}

/// gaussian-tf's default TGTF of a one-field volume where no boundary is
/// found ([`crate::gaussians::median_tgtf`]); `g_buckets` as for [`inverse_gradient_axis`].
pub(super) fn median_tgtf(
    chans: &mut SlabChannels,
    slabs: &[Range<usize>],
    g_buckets: Option<&KeyBuckets>,
) -> Result<GaussianPrimitive, ChannelError> {
    let g_cut = 2.0 * median_of_g(chans, slabs, g_buckets)?.unwrap_or(0.0);
    let (mut structured, mut voxels) = (0usize, 0usize);
    for z in slabs {
        let g = chans.samples(Channel::G, z.clone())?;
        structured += g.iter().filter(|&&x| x > g_cut).count();
        voxels += g.len();
    }
    let use_all = structured * 100 < voxels;
    let centre = median_of_slabs(slabs, &mut |z| {
        let v = chans.samples(Channel::Value, z.clone())?.to_vec();
        if use_all {
            return Ok(v);
        }
        let g = chans.samples(Channel::G, z)?;
        Ok(v.into_iter().zip(g).filter(|(_, g)| **g > g_cut).map(|(v, _)| v).collect())
    })?
    .ok_or(ChannelError::Missing("channel 'v' has no finite sample"))?;
    Ok(crate::gaussians::median_tgtf(vec![centre as f64], &[1.0]))
}
