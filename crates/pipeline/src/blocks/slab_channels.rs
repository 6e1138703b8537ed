//! The channels of a slab-by-slab run on any planes: those the run stored
//! (the value, the tracing's outputs, the pre-filtered g and f'') read from
//! the [`ChannelStore`], the derivatives recomputed from the stored value
//! over the planes grown by the kernel's support. Recomputing the
//! derivatives costs less than writing them to disk and reading them back,
//! and the items are derived in the groups the whole-volume run derives them
//! in, so every sample has its bits.

use super::{ChannelStore, grown};
use mdtf_derive::{DeriveOutput, DeriveParams, Item};
use mdtf_volume::{MultiField, Volume};
use std::ops::Range;

/// Stored and derivable channels (see the module docs).
pub struct SlabChannels {
    /// The stored channels.
    pub store: ChannelStore,
    /// The derive passes, each with the channels it makes.
    groups: Vec<(DeriveParams, Vec<String>)>,
    /// Planes the kernel reads on each side.
    kernel_reach: usize,
    nz: usize,
    /// Memory of the last block derived whole, for the next (see [`SlabChannels::derive_block`]).
    recycled: Option<DeriveOutput>,
    /// Memory of the last value block read for it.
    value_buffer: Vec<f32>,
}

/// The channels derive item `item` makes.
fn made_by(item: Item) -> Vec<String> {
    match item {
        Item::Normal => ["nx", "ny", "nz"].map(String::from).to_vec(),
        other => vec![other.name().to_string()],
    }
}

impl SlabChannels {
    /// Channels of `store` (holding the value, "v"), with the derive passes
    /// `groups` (each its items, kernel and epsilon); the kernel reads
    /// `kernel_reach` planes each side; the volume has `nz` planes.
    pub fn new(store: ChannelStore, groups: Vec<DeriveParams>, kernel_reach: usize, nz: usize) -> SlabChannels {
        let groups = groups
            .into_iter()
            .filter(|d| !d.items.is_empty())
            .map(|d| {
                let names = d.items.iter().flat_map(|&i| made_by(i)).collect();
                (d, names)
            })
            .collect();
        SlabChannels { store, groups, kernel_reach, nz, recycled: None, value_buffer: Vec::new() }
    }

    /// Whether channel `name` is stored or derivable.
    pub fn has(&self, name: &str) -> bool {
        self.store.has(name) || self.groups.iter().any(|(_, names)| names.iter().any(|n| n == name))
    }

    /// Channels `names` on planes `z`, in that order.
    pub fn volumes(&mut self, z: Range<usize>, names: &[&str]) -> Result<Vec<(String, Volume)>, String> {
        let mut derived: Vec<(String, Volume)> = Vec::new();
        for (d, made) in &self.groups {
            if !names.iter().any(|n| !self.store.has(n) && made.iter().any(|m| m == n)) {
                continue;
            }
            let k = self.kernel_reach;
            let read = grown(&z, k, 2 * k + 1, self.nz);
            let v = self.store.volume("v", read.clone()).map_err(|e| e.to_string())?;
            let out = mdtf_derive::run(&MultiField::from(v), d).map_err(|e| format!("derive: {e}"))?;
            let own = z.start - read.start..z.end - read.start;
            for (_, mf) in out.items {
                for (name, vol) in mf.into_volumes() {
                    if names.contains(&name.as_str()) {
                        derived.push((name, vol.z_slab(own.clone())));
                    }
                }
            }
        }
        names
            .iter()
            .map(|&n| match derived.iter().position(|(d, _)| d == n) {
                Some(i) => Ok(derived.swap_remove(i)),
                None => self.store.volume(n, z.clone()).map(|v| (n.to_string(), v)).map_err(|e| e.to_string()),
            })
            .collect()
    }

    /// The first derive pass's output over planes `z` grown by the kernel's
    /// support (clamped to the volume), and that grown range: exact on the
    /// planes of `z` (and wherever the growth reached the volume's faces),
    /// not beyond. For a pass that reads only `z`'s planes of it, this avoids
    /// copying them out; hand the output back with
    /// [`SlabChannels::recycle`] and the next block of the same height is
    /// derived into its memory, as is the value read for it (fresh memory
    /// page-faults, which costs as much as the derivation).
    pub fn derive_block(&mut self, z: Range<usize>) -> Result<(Range<usize>, DeriveOutput), String> {
        let Some((d, _)) = self.groups.first() else { return Err("nothing is derived".into()) };
        let k = self.kernel_reach;
        let read = grown(&z, k, 2 * k + 1, self.nz);
        let plane = self.store.plane_len();
        let mut buffer = std::mem::take(&mut self.value_buffer);
        buffer.resize(read.len() * plane, 0.0);
        self.store.samples_into("v", read.clone(), &mut buffer).map_err(|e| e.to_string())?;
        let geometry = self.store.geometry().z_slab(read.clone());
        let value = MultiField::from(Volume::from_samples(geometry, buffer).map_err(|e| e.to_string())?);
        let out = mdtf_derive::run_with_progress(&value, d, self.recycled.take(), &|_, _| {})
            .map_err(|e| format!("derive: {e}"))?;
        self.value_buffer =
            value.fields.into_iter().next().map(|f| f.data.into_raw_vec_and_offset().0).unwrap_or_default();
        Ok((read, out))
    }

    /// Gives back the output of [`SlabChannels::derive_block`] for reuse.
    pub fn recycle(&mut self, out: DeriveOutput) {
        self.recycled = Some(out);
    }

    /// The samples of channel `name` on planes `z`.
    pub fn samples(&mut self, name: &str, z: Range<usize>) -> Result<Vec<f32>, String> {
        if self.store.has(name) {
            return self.store.samples(name, z).map_err(|e| e.to_string());
        }
        let mut v = self.volumes(z, &[name])?;
        Ok(v.pop().map(|(_, v)| v.data.into_raw_vec_and_offset().0).unwrap_or_default())
    }
}
