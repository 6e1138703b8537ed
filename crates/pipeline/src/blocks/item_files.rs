//! The derive stage's items of a one-field input, slab by slab under a
//! memory budget, into one file per item (`mdtf derive --memory-budget`):
//! the bytes of the whole-volume derive's files, whatever the slab height.
//!
//! Two passes: the value is copied into a [`ChannelStore`] (its finite
//! range gives the default epsilon, the same for every slab); then each
//! slab is derived over its planes grown by the kernel's support
//! ([`SlabChannels`]) and its components are handed to one
//! [`SlabWriter`] per item, while the next slab is derived.

use super::{ChannelStore, SlabChannels, SlabSize, Source, automatic_file_budget, slab_height, slabs};
use crate::boundary_chain::{BoundaryChainParams, ChainError};
use crate::channel::Channel;
use crate::error::{RunError, at, fail};
use crate::plan::Plan;
use mdtf_derive::Item;
use mdtf_volume::{ReadOptions, SampleType, SlabWriter, Volume, overlapped};
use rayon::prelude::*;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// What [`derive_item_files`] wrote, and how it cut the volume.
#[derive(Debug)]
pub struct ItemFiles {
    /// Each item asked for (once, in the order asked) and its file.
    pub files: Vec<(Item, PathBuf)>,
    /// Planes per slab (the last may hold fewer).
    pub height: usize,
    /// How many slabs.
    pub slabs: usize,
}

/// A chain error as the failure of the stage it belongs to.
fn chain_error(e: ChainError) -> RunError {
    match e {
        ChainError::Derive(e) => at("derive")(e),
        other => fail("plan")(other.to_string()),
    }
}

/// Why the derive stage's `items` cannot be written slab by slab, if they cannot.
pub fn items_unsupported(items: &[Item]) -> Option<String> {
    if items.contains(&Item::Shade) {
        return Some("the shading weight (shade) divides by the largest g of the whole volume".into());
    }
    let several: Vec<&str> = items.iter().filter(|i| i.is_multi_field()).map(|i| i.name()).collect();
    (!several.is_empty())
        .then(|| format!("{} need several fields; slab-by-slab runs take one field", several.join(", ")))
}

/// Bytes a whole-volume derive holds per voxel beyond its components: the
/// value and the derivation's scratch (measured: g, f'' and the normal of a
/// 256^3 volume peak at about 6.2 f32 a voxel).
const WHOLE_DERIVE_EXTRA_F32: u64 = 2;

/// The budget `mdtf derive` of `items` on the file `input` takes without
/// `--memory-budget`, and the file's grid: three quarters of `available`
/// bytes when the whole-volume derive would need more and the file can go
/// by slabs (one field read by planes, items that go by slabs); None otherwise.
pub fn automatic_item_budget(
    input: &Path,
    read: &ReadOptions,
    items: &[Item],
    available: u64,
) -> Option<(u64, mdtf_volume::Geometry)> {
    if items_unsupported(items).is_some() {
        return None;
    }
    let components: u64 = items.iter().map(|i| i.components().len() as u64).sum();
    automatic_file_budget(input, read, 4 * (components + WHOLE_DERIVE_EXTRA_F32), available)
}

/// Derives `items` of the one-field volume in `input` (read by planes where
/// its format allows, else whole) as `chain` says (kernel, border,
/// epsilon), slab by slab in slabs of `size`, into `dir`/`{item}{ext}`
/// (`.nii`, `.nii.gz`, `.nrrd`, `.ome.zarr`): one file per item holding
/// its components as fields, byte-identical to writing the whole-volume
/// derive's output. The value waits in a store in `dir`/`.slabs`, removed
/// at the end. `on_slab(k, of)` is called as each slab of each pass starts
/// (k from 1; `of` counts the slabs of both passes).
#[allow(clippy::too_many_arguments)]
pub fn derive_item_files(
    input: &Path,
    read: &ReadOptions,
    items: &[Item],
    chain: &BoundaryChainParams,
    size: SlabSize,
    dir: &Path,
    ext: &str,
    on_slab: &(dyn Fn(usize, usize) + Sync),
) -> Result<ItemFiles, RunError> {
    let per_item = crate::channels::item_channels(items, &["v".to_string()]).map_err(chain_error)?;
    let unique: Vec<Item> = per_item.iter().map(|(i, _)| *i).collect();
    if let Some(why) = items_unsupported(&unique) {
        return Err(fail("plan")(why));
    }
    let mut source = Source::of_file(input, read)?;
    let geo = source.geometry().clone();
    let names: Vec<String> = per_item.iter().flat_map(|(_, n)| n.iter().cloned()).collect();
    let plan = Plan::for_channels(&names, &["v".to_string()], &geo, chain).map_err(at("plan"))?;
    let nz = geo.dims[2];
    let height = match size {
        SlabSize::Budget(b) => slab_height(b, &geo, &plan, false).map_err(at("plan"))?,
        SlabSize::Planes(h) | SlabSize::Strips { planes: h, .. } => h.clamp(1, nz.max(1)),
    };
    let cut = slabs(nz, height);
    // the files are started first: a format that cannot be written by slabs is refused before any work
    let mut writers: Vec<(Item, PathBuf, Vec<String>, SlabWriter)> = Vec::with_capacity(per_item.len());
    for (item, fields) in per_item {
        let path = dir.join(format!("{}{ext}", item.name()));
        let w = SlabWriter::create(&path, &geo, &fields, SampleType::F32).map_err(at("write"))?;
        writers.push((item, path, fields, w));
    }

    let mut store = ChannelStore::create(dir.join(super::store::STORE_DIR), geo.clone()).map_err(at("input"))?;
    let n = cut.len();
    let range = copy_value(&mut source, &mut store, &cut, &|k| on_slab(k, 2 * n))?;
    drop(source);
    let mut params = chain.derive(unique);
    let span = range.map_or(0.0, |(lo, hi)| hi - lo);
    params.epsilon = params.epsilon.or(Some(mdtf_derive::default_epsilon(span, geo.min_spacing())));
    let mut chans = SlabChannels::new(store, vec![params], plan.reach.kernel[2], nz);

    let wanted: Vec<Channel> = names.iter().filter_map(|n| Channel::of_store(n)).collect();
    // a slab is derived while the one before is written
    overlapped(
        cut.len(),
        &mut |k| {
            on_slab(n + k + 1, 2 * n);
            Ok::<(), RunError>(())
        },
        &mut |k, spent: Option<(usize, Vec<(Channel, Volume)>)>| {
            chans.give_back(spent.map(|(_, v)| v).unwrap_or_default());
            Ok((cut[k].start, chans.volumes(cut[k].clone(), &wanted).map_err(at("derive"))?))
        },
        &mut |(first, volumes)| {
            // the files are encoded (and compressed) side by side
            writers.par_iter_mut().try_for_each(|(_, _, fields, w)| {
                let samples: Vec<&[f32]> = fields
                    .iter()
                    .filter_map(|f| volumes.iter().find(|(c, _)| c.name(&[]) == *f).map(|(_, v)| v.samples()))
                    .collect();
                w.put(first, &samples).map_err(at("write"))
            })?;
            Ok(Some((first, volumes)))
        },
    )?;
    chans.release();
    chans.store.clear();
    let mut files = Vec::with_capacity(writers.len());
    for (item, path, _, w) in writers {
        w.finish().map_err(at("write"))?;
        files.push((item, path));
    }
    Ok(ItemFiles { files, height, slabs: cut.len() })
}

/// Copies the value into `store` slab by slab (reading one slab while the
/// one before is stored; `on_slab(k)` as slab k starts, from 1); its finite
/// range (None without a finite value).
fn copy_value(
    source: &mut Source,
    store: &mut ChannelStore,
    cut: &[Range<usize>],
    on_slab: &(dyn Fn(usize) + Sync),
) -> Result<Option<(f32, f32)>, RunError> {
    let mut writer = store.writer(&[Channel::Value]).map_err(at("input"))?;
    let mut range: Option<(f32, f32)> = None;
    overlapped(
        cut.len(),
        &mut |k| {
            on_slab(k + 1);
            Ok::<(), RunError>(())
        },
        &mut |k, _| Ok((cut[k].start, source.read(cut[k].clone())?)),
        &mut |(first, v): (usize, Volume)| {
            if let Some((lo, hi)) = mdtf_volume::finite_sample_range(v.samples()) {
                range = Some(range.map_or((lo, hi), |(a, b)| (a.min(lo), b.max(hi))));
            }
            writer.put_volume(Channel::Value, first, &v).map_err(at("input"))?;
            Ok(None)
        },
    )?;
    Ok(range)
}
