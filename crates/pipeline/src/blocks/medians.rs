//! The medians a whole run takes of whole channels (the (v, 1/g)
//! histogram's axis, gaussian-tf's default TGTF), taken exactly slab by
//! slab as the two passes of a radix select ([`SelectPass`]): each pass
//! counts every slab (here, or as a cluster's tasks) into buckets that
//! merge exactly, so a run on a cluster never reads a channel back for them.
//! g's median takes one pass when the derive pass counted its first.

use super::{ChannelError, SlabChannels};
use crate::channel::Channel;
use mdtf_histogram::Axis;
use mdtf_pack::GaussianPrimitive;
use mdtf_volume::KeyBuckets;
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// One pass of an exact radix select over the finite samples of a channel,
/// of the voxels where a mask channel lies above a cut (serialisable: a
/// cluster's tasks run it on their slabs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SelectPass {
    /// The channel selected from.
    pub channel: Channel,
    /// Only the voxels where this channel's sample is above the cut, given
    /// as f32 bits (JSON, in which a task gets its job, has no infinity);
    /// None: every voxel.
    pub above: Option<(Channel, u32)>,
    /// None: the first pass (every sample by the upper half of its key);
    /// Some(b): the second (the samples in upper bucket b, by the lower half).
    pub within: Option<usize>,
}

/// What a [`SelectPass`] counted over some slabs (merged over all of them).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct SelectCounts {
    /// The samples' keys, counted.
    pub buckets: KeyBuckets,
    /// Voxels where the mask holds (every voxel without one), whatever their sample.
    pub masked: u64,
}

impl SelectCounts {
    /// Adds the counts of other slabs.
    pub fn merge(&mut self, other: &SelectCounts) {
        self.buckets.merge(&other.buckets);
        self.masked += other.masked;
    }
}

impl SelectPass {
    /// The channels a slab must hold for the pass: the selected one, then the mask's.
    pub fn reads(&self) -> Vec<Channel> {
        let mut reads = vec![self.channel];
        reads.extend(self.above.map(|(m, _)| m).filter(|&m| m != self.channel));
        reads
    }

    /// Counts a slab: `samples` of the selected channel, `mask` of the
    /// mask's (read only when the pass has one).
    pub fn count(&self, samples: &[f32], mask: &[f32], into: &mut SelectCounts) {
        let kept: Vec<f32>;
        let samples = match self.above {
            Some((_, bits)) => {
                let cut = f32::from_bits(bits);
                kept = samples.iter().zip(mask).filter(|&(_, &m)| m > cut).map(|(&s, _)| s).collect();
                &kept
            }
            None => samples,
        };
        into.masked += samples.len() as u64;
        match self.within {
            None => into.buckets.add(samples),
            Some(b) => into.buckets.add_within(b, samples),
        }
    }
}

/// Runs a [`SelectPass`] over every slab of the volume, wherever it likes.
pub(super) type Selector<'a, E> = dyn FnMut(SelectPass) -> Result<SelectCounts, E> + 'a;

/// [`SelectPass`] `pass` over `slabs`, read from `chans` in this process.
pub(super) fn select_here(
    chans: &mut SlabChannels,
    slabs: &[Range<usize>],
    pass: &SelectPass,
) -> Result<SelectCounts, ChannelError> {
    let (mut counts, mut mask) = (SelectCounts::default(), Vec::new());
    for z in slabs {
        match pass.above {
            // masked by itself: read once
            Some((m, _)) if m == pass.channel => {
                let samples = chans.samples(m, z.clone())?;
                pass.count(samples, samples, &mut counts);
            }
            above => {
                if let Some((m, _)) = above {
                    chans.samples_into(m, z.clone(), &mut mask)?;
                }
                pass.count(chans.samples(pass.channel, z.clone())?, &mask, &mut counts);
            }
        }
    }
    Ok(counts)
}

/// The lower median of the finite samples of `channel` (of the voxels
/// where `above` holds), by the two passes of a radix select run by `run`;
/// `first`: the first pass, when counted already. None without any sample.
fn median_of<E>(
    channel: Channel,
    above: Option<(Channel, f32)>,
    first: Option<&KeyBuckets>,
    run: &mut Selector<'_, E>,
) -> Result<Option<f32>, E> {
    let pass = |within| SelectPass { channel, above: above.map(|(m, cut)| (m, cut.to_bits())), within };
    let counted;
    let upper = match first {
        Some(b) => b,
        None => {
            counted = run(pass(None))?.buckets;
            &counted
        }
    };
    let Some(k) = upper.total().checked_sub(1).map(|last| last / 2) else { return Ok(None) };
    let Some(within) = mdtf_volume::upper_bucket_of(k, upper) else { return Ok(None) };
    let lower = run(pass(Some(within)))?.buckets;
    Ok(mdtf_volume::order_statistic_from_counts(k, upper, &lower))
}

/// [`Axis::inverse_gradient`] of the whole g, 256 bins: the median of g
/// above twice g's median; `g_buckets`: the first radix pass over g, if a
/// pass that derived it took it.
pub(super) fn inverse_gradient_axis<E>(
    run: &mut Selector<'_, E>,
    g_buckets: Option<&KeyBuckets>,
) -> Result<Option<Axis>, E> {
    let Some(median) = median_of(Channel::G, None, g_buckets, run)? else { return Ok(None) };
    let above = median_of(Channel::G, Some((Channel::G, 2.0 * median)), None, run)?;
    Ok(above.and_then(|g_b| Axis::inverse_gradient_at(g_b, 256)))
}

/// gaussian-tf's default TGTF of a one-field volume of `voxels` voxels
/// where no boundary is found ([`crate::gaussians::median_tgtf`]): centred
/// at the median value of the voxels whose g is above twice g's median
/// (of every voxel when fewer than 1 % are); `g_buckets` as for
/// [`inverse_gradient_axis`]. None without a finite value.
pub(super) fn median_tgtf<E>(
    run: &mut Selector<'_, E>,
    g_buckets: Option<&KeyBuckets>,
    voxels: usize,
) -> Result<Option<GaussianPrimitive>, E> {
    let g_cut = 2.0 * median_of(Channel::G, None, g_buckets, run)?.unwrap_or(0.0);
    let structured = SelectPass { channel: Channel::Value, above: Some((Channel::G, g_cut.to_bits())), within: None };
    let first = run(structured)?;
    let centre = match first.masked * 100 < voxels as u64 {
        true => median_of(Channel::Value, None, None, run)?,
        false => median_of(Channel::Value, Some((Channel::G, g_cut)), Some(&first.buckets), run)?,
    };
    Ok(centre.map(|c| crate::gaussians::median_tgtf(vec![c as f64], &[1.0])))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs each pass over `slabs` pieces of (value, g) samples, as tasks would.
    fn over_pieces(pieces: &[(Vec<f32>, Vec<f32>)]) -> impl FnMut(SelectPass) -> Result<SelectCounts, ChannelError> {
        move |pass: SelectPass| {
            let mut counts = SelectCounts::default();
            for (v, g) in pieces {
                let of = |c| if c == Channel::G { g } else { v };
                let mask = pass.above.map_or(&[][..], |(m, _)| of(m));
                pass.count(of(pass.channel), mask, &mut counts);
            }
            Ok(counts)
        }
    }

    /// (v, g) samples: g mostly small, every `structured_every`-th voxel
    /// large, with a NaN and an infinity; v from a hash.
    fn samples(structured_every: u32) -> (Vec<f32>, Vec<f32>) {
        let g = (0..10_000u32)
            .map(|i| match i {
                7 => f32::NAN,
                8 => f32::INFINITY,
                _ if i % structured_every == 0 => 5.0 + (i % 97) as f32 * 0.25,
                _ => (i % 13) as f32 * 0.1,
            })
            .collect();
        let v = (0..10_000u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 20) as f32 * 0.5).collect();
        (v, g)
    }

    #[test]
    fn medians_by_select_passes_equal_the_whole_volume_definitions() {
        for structured_every in [9, 400] {
            let (v, g) = samples(structured_every);
            let cut = |k: usize| k * 1500..(k * 1500 + 1500).min(v.len());
            let pieces: Vec<(Vec<f32>, Vec<f32>)> = (0..7).map(|k| (v[cut(k)].to_vec(), g[cut(k)].to_vec())).collect();
            let mut run = over_pieces(&pieces);
            let axis = inverse_gradient_axis(&mut run, None).unwrap().unwrap();
            assert_eq!(axis.max.to_bits(), Axis::inverse_gradient(&g, 256).unwrap().max.to_bits());
            // the first pass of g counted elsewhere gives the same
            let mut first = KeyBuckets::new();
            first.add(&g);
            let again = inverse_gradient_axis(&mut run, Some(&first)).unwrap().unwrap();
            assert_eq!(again.max.to_bits(), axis.max.to_bits());
            let tgtf = median_tgtf(&mut run, None, v.len()).unwrap().unwrap();
            let centre = crate::gaussians::median_at_large_g(&v, &g).unwrap();
            let whole = crate::gaussians::median_tgtf(vec![centre as f64], &[1.0]);
            assert_eq!(format!("{tgtf:?}"), format!("{whole:?}"), "structured every {structured_every}");
        }
    }
}
