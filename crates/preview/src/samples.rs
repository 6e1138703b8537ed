//! A channel's samples as the ray caster reads them: float volumes, or one
//! component of a pack's texture read in place, each code looked up in a
//! table of every code's value (the values decoding would give, so the
//! pictures are the same bit for bit, from a third to a sixteenth of the
//! memory and no decoding pass).

use crate::PreviewError;
use crate::load::pack_file;
use mdtf_pack::{ChannelEntry, Dtype, Manifest, TextureEntry};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

/// One channel's samples, x fastest.
#[derive(Debug, Clone, Copy)]
pub enum Samples<'a> {
    /// Float samples.
    Floats(&'a [f32]),
    /// 8-bit codes every `texel` bytes from the start of `bytes`, each
    /// standing for its entry of `values`.
    Codes8 {
        /// The texture's bytes from this component's first code.
        bytes: &'a [u8],
        /// Bytes per texel.
        texel: usize,
        /// Every code's value.
        values: &'a [f32; 256],
    },
    /// 16-bit little-endian codes (integers or half floats), likewise.
    Codes16 {
        /// The texture's bytes from this component's first code.
        bytes: &'a [u8],
        /// Bytes per texel.
        texel: usize,
        /// Every code's value.
        values: &'a [f32; 65536],
    },
    /// Little-endian f32 samples every `texel` bytes.
    Float32 {
        /// The texture's bytes from this component's first sample.
        bytes: &'a [u8],
        /// Bytes per texel.
        texel: usize,
    },
}

impl Samples<'_> {
    /// Sample `i` (x-fastest index).
    #[inline(always)]
    pub fn at(&self, i: usize) -> f32 {
        match *self {
            Samples::Floats(d) => d[i],
            Samples::Codes8 { bytes, texel, values } => values[usize::from(bytes[i * texel])],
            Samples::Codes16 { bytes, texel, values } => {
                let at = i * texel;
                values[usize::from(u16::from_le_bytes([bytes[at], bytes[at + 1]]))]
            }
            Samples::Float32 { bytes, texel } => {
                let at = i * texel;
                f32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
            }
        }
    }

    /// The largest finite sample of the first `n`, if any.
    pub fn finite_max(&self, n: usize) -> Option<f32> {
        (0..n).into_par_iter().with_min_len(1 << 16).map(|i| self.at(i)).filter(|v| v.is_finite()).reduce_with(f32::max)
    }
}

/// How a channel's codes become values: for 8- and 16-bit codes a table
/// of every code's value as decoding gives it (`Decode::value`, so the same
/// bits), for f32 texels the float itself.
#[derive(Debug, Clone)]
pub(crate) enum CodeTable {
    Bits8(Box<[f32; 256]>),
    Bits16(Box<[f32; 65536]>),
    Float32,
}

impl CodeTable {
    /// The table of channel `ch` of a texture of `dtype`.
    pub(crate) fn of(ch: &ChannelEntry, dtype: Dtype) -> CodeTable {
        let value = |code: u32| ch.decode.value(code, dtype) as f32;
        match dtype {
            Dtype::U8 => CodeTable::Bits8(Box::new(std::array::from_fn(|c| value(c as u32)))),
            Dtype::U16 | Dtype::F16 => {
                let mut values = Box::new([0f32; 65536]);
                values.iter_mut().enumerate().for_each(|(c, v)| *v = value(c as u32));
                CodeTable::Bits16(values)
            }
            Dtype::F32 => CodeTable::Float32,
        }
    }

    /// The channel's samples in `bytes` (from its first code on, `texel`
    /// bytes a texel).
    pub(crate) fn samples<'a>(&'a self, bytes: &'a [u8], texel: usize) -> Samples<'a> {
        match self {
            CodeTable::Bits8(values) => Samples::Codes8 { bytes, texel, values },
            CodeTable::Bits16(values) => Samples::Codes16 { bytes, texel, values },
            CodeTable::Float32 => Samples::Float32 { bytes, texel },
        }
    }
}

/// Refuses channels `entries` of texture `tex` that name a component it lacks.
pub(crate) fn check_components(tex: &TextureEntry, entries: &[&ChannelEntry]) -> Result<(), PreviewError> {
    match entries.iter().find(|c| c.component >= tex.components) {
        Some(ch) => Err(PreviewError::Pack(format!(
            "channel {} is component {} of texture {}, which has {}",
            ch.name, ch.component, tex.name, tex.components
        ))),
        None => Ok(()),
    }
}

/// The textures of a pack that hold the channels a renderer reads, as
/// their files' bytes, and how each channel is read from them.
#[derive(Debug)]
pub struct PackTextures {
    /// Each texture's bytes, by name.
    bytes: BTreeMap<String, Vec<u8>>,
    /// Each channel: its texture, the byte of its first code, bytes per texel, its codes' values.
    channels: BTreeMap<String, (String, usize, usize, CodeTable)>,
}

impl PackTextures {
    /// Reads the textures of the pack in `dir` (described by `manifest`,
    /// of `voxels` texels each) holding the channels `wanted` accepts,
    /// each channel from the first texture that holds it.
    pub fn read(
        dir: &Path,
        manifest: &Manifest,
        voxels: usize,
        wanted: &dyn Fn(&str) -> bool,
    ) -> Result<PackTextures, PreviewError> {
        let mut out = PackTextures { bytes: BTreeMap::new(), channels: BTreeMap::new() };
        for tex in &manifest.textures {
            let entries: Vec<&ChannelEntry> = manifest
                .channels
                .iter()
                .filter(|c| c.texture == tex.name && wanted(&c.name) && !out.channels.contains_key(&c.name))
                .collect();
            if entries.is_empty() {
                continue;
            }
            let size = tex.dtype.size();
            let texel = tex.components * size;
            check_components(tex, &entries)?;
            let path = pack_file(dir, &tex.data)?;
            let bytes = read_in_parallel(&path, voxels, texel, &tex.data)?;
            for ch in entries {
                let table = CodeTable::of(ch, tex.dtype);
                out.channels.insert(ch.name.clone(), (tex.name.clone(), ch.component * size, texel, table));
            }
            out.bytes.insert(tex.name.clone(), bytes);
        }
        Ok(out)
    }

    /// Every channel's samples, by name.
    pub fn samples(&self) -> BTreeMap<String, Samples<'_>> {
        let mut out = BTreeMap::new();
        for (name, (texture, first, texel, table)) in &self.channels {
            let Some(bytes) = self.bytes.get(texture) else { continue };
            out.insert(name.clone(), table.samples(&bytes[*first..], *texel));
        }
        out
    }
}

/// Bytes read by one thread at a time.
const READ_PIECE: usize = 8 << 20;

/// The whole texture file `path` (named `name` in errors), which must hold
/// exactly `texels` of `texel` bytes, read by pieces in parallel.
fn read_in_parallel(path: &Path, texels: usize, texel: usize, name: &str) -> Result<Vec<u8>, PreviewError> {
    use std::os::unix::fs::FileExt;
    let fail = |e: std::io::Error| PreviewError::Pack(format!("{}: {e}", path.display()));
    let file = std::fs::File::open(path).map_err(fail)?;
    let len = file.metadata().map_err(fail)?.len();
    let expected = texels.checked_mul(texel).filter(|&n| u64::try_from(n).is_ok_and(|n| n == len));
    let Some(n) = expected else {
        return Err(PreviewError::Pack(format!(
            "{name}: {len} bytes, the manifest describes {texels} texels of {texel} bytes"
        )));
    };
    let mut bytes = vec![0u8; n];
    bytes
        .par_chunks_mut(READ_PIECE)
        .enumerate()
        .try_for_each(|(k, piece)| file.read_exact_at(piece, (k * READ_PIECE) as u64))
        .map_err(fail)?;
    Ok(bytes)
}
