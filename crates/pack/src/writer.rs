//! One texture at a time: quantising a texture's channels into its bytes,
//! writing it (raw + detached NRRD header, optionally NIfTI), and the
//! manifest at the end. [`PackWriter`] lets a caller make each texture's
//! channels just before it is written and free them right after, so a pack
//! never needs every channel and every texture in memory together.

use crate::by_tasks::TextureTarget;
use crate::manifest::{ChannelEntry, ChannelSource, Manifest, ManifestGeometry, Provenance, SCHEMA_ID, TextureEntry};
use crate::profile::{Profile, TextureLayout, describe};
use crate::quantise::{Decode, Dtype, decode_for};
use crate::{Lut, PackError, PackParams};
use mdtf_volume::{AtomicWriter, Geometry, Volume, VolumeError, write_file_atomically};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::io::Write;
use std::ops::Range;
use std::path::Path;

/// The textures of `params.profile`, in order, with `params.dtype` applied.
pub fn texture_layouts(params: &PackParams) -> Vec<TextureLayout> {
    let mut layouts = params.profile.layout(&params.fields);
    if let Some(d) = params.dtype {
        for layout in &mut layouts {
            layout.dtype = d;
        }
    }
    layouts
}

/// Quantises textures one by one, collecting the manifest's channel entries.
pub(crate) struct TextureEncoder<'a> {
    params: &'a PackParams,
    geometry: Geometry,
    sources: &'a BTreeMap<String, ChannelSource>,
    /// Each channel's data range, measured once even when it sits in two textures.
    measured: BTreeMap<String, [f64; 2]>,
    /// One entry per (channel, texture, component) encoded so far.
    pub entries: Vec<ChannelEntry>,
}

impl<'a> TextureEncoder<'a> {
    pub fn new(
        params: &'a PackParams,
        geometry: Geometry,
        sources: &'a BTreeMap<String, ChannelSource>,
    ) -> TextureEncoder<'a> {
        TextureEncoder { params, geometry, sources, measured: BTreeMap::new(), entries: Vec::new() }
    }

    /// Checks texture `layout`'s channels (from `get`), measures their ranges
    /// and records their manifest entries: what encoding the texture needs.
    fn prepare<'v>(
        &mut self,
        layout: &TextureLayout,
        get: &dyn Fn(&str) -> Option<&'v Volume>,
    ) -> Result<Prepared<'v>, PackError> {
        let mut decodes = Vec::with_capacity(layout.components.len());
        for (ci, c) in layout.components.iter().enumerate() {
            let Some(c) = c else {
                decodes.push(None);
                continue;
            };
            let v = get(c).ok_or_else(|| self.missing(c))?;
            if !v.geometry.same_grid(&self.geometry) {
                return Err(PackError::Geometry(format!("channel {c} is not on the grid of the pack")));
            }
            let range = match self.known_range(c) {
                Some(r) => r,
                None => *self
                    .measured
                    .entry(c.clone())
                    .or_insert_with(|| v.finite_range().map_or([0.0, 0.0], |(lo, hi)| [lo as f64, hi as f64])),
            };
            let d = self.record(layout, ci, c, range)?;
            decodes.push(Some((v.samples(), d)));
        }
        Ok(Prepared { dtype: layout.dtype, dims: self.geometry.dims, decodes })
    }

    /// Records the manifest entries of texture `layout` whose channels all
    /// have known ranges (given, or the normals'), for a texture fed slab by
    /// slab: its decodes per component (None: unused).
    fn prepare_ranged(&mut self, layout: &TextureLayout) -> Result<Vec<Option<Decode>>, PackError> {
        let mut decodes = Vec::with_capacity(layout.components.len());
        for (ci, c) in layout.components.iter().enumerate() {
            let Some(c) = c else {
                decodes.push(None);
                continue;
            };
            let Some(range) = self.known_range(c) else {
                return Err(PackError::Geometry(format!(
                    "channel {c} of texture {} has no code range: a texture written slab by slab needs each \
                     channel's range before its first slab",
                    layout.name
                )));
            };
            decodes.push(Some(self.record(layout, ci, c, range)?));
        }
        Ok(decodes)
    }

    /// The code range of channel `c` known without reading it: given, or [-1, 1] for unit normals.
    fn known_range(&self, c: &str) -> Option<[f64; 2]> {
        match self.params.ranges.get(c) {
            Some(r) => Some(*r),
            None if matches!(c, "nx" | "ny" | "nz") => Some([-1.0, 1.0]),
            None => None,
        }
    }

    fn missing(&self, c: &str) -> PackError {
        PackError::MissingChannels {
            profile: self.params.profile.to_string(),
            missing: format!("{c} (made by the {} stage)", describe(c, !self.params.fields.is_empty()).stage),
        }
    }

    /// Records component `ci` (channel `c`, coded over `[min, max]`) of
    /// texture `layout` in the manifest; returns its decode.
    fn record(
        &mut self,
        layout: &TextureLayout,
        ci: usize,
        c: &str,
        [min, max]: [f64; 2],
    ) -> Result<Decode, PackError> {
        let text = describe(c, !self.params.fields.is_empty());
        let d = decode_for(c, min, max, layout.dtype, text.signed)?;
        let top = layout.dtype.max_code().unwrap_or(0.0);
        self.entries.push(ChannelEntry {
            name: c.to_string(),
            meaning: text.meaning.into(),
            units: text.units.into(),
            texture: layout.name.clone(),
            component: ci,
            decode: d,
            range: [d.offset, d.offset + d.scale * top],
            source: self
                .sources
                .get(c)
                .cloned()
                .unwrap_or(ChannelSource { stage: text.stage.into(), params: serde_json::Value::Null }),
        });
        Ok(d)
    }

    /// Quantises texture `layout` into `sink`, a slab of z-slices at a time
    /// (the bytes of [`TextureEncoder::encode`], in order).
    pub fn stream<'v>(
        &mut self,
        layout: &TextureLayout,
        get: &dyn Fn(&str) -> Option<&'v Volume>,
        sink: &mut dyn FnMut(&[u8]) -> std::io::Result<()>,
    ) -> Result<(), PackError> {
        let p = self.prepare(layout, get)?;
        p.stream(sink).map_err(|e| PackError::Io(VolumeError::Fields(format!("texture {}: {e}", layout.name))))
    }

    /// The bytes of texture `layout` (components fastest, then x, y, z,
    /// little-endian), its channels taken from `get`.
    pub fn encode<'v>(
        &mut self,
        layout: &TextureLayout,
        get: &dyn Fn(&str) -> Option<&'v Volume>,
    ) -> Result<Vec<u8>, PackError> {
        let p = self.prepare(layout, get)?;
        let mut bytes = vec![0u8; p.plane_bytes() * p.dims[2]];
        p.encode_planes(0, &mut bytes);
        Ok(bytes)
    }
}

/// z-slices quantised per write when a texture is streamed (4 MiB of RGBA8 at 256^2).
const SLAB_PLANES: usize = 16;

/// A texture ready to quantise: each component's samples and decode (None: unused, code 0).
pub(crate) struct Prepared<'v> {
    pub(crate) dtype: Dtype,
    pub(crate) dims: [usize; 3],
    pub(crate) decodes: Vec<Option<(&'v [f32], Decode)>>,
}

impl<'v> Prepared<'v> {
    /// Texture `layout` on the planes `z` (of `plane` voxels: x, y) of a slab
    /// whose channels are `chans`, ready to quantise with its components'
    /// `decodes`; `missing(c)` is the error when channel `c` is not among them.
    pub(crate) fn of_slab(
        layout: &TextureLayout,
        decodes: &[Option<Decode>],
        [nx, ny]: [usize; 2],
        z: &Range<usize>,
        chans: &'v [(String, Volume)],
        missing: &dyn Fn(&str) -> PackError,
    ) -> Result<Prepared<'v>, PackError> {
        let mut slab_decodes = Vec::with_capacity(decodes.len());
        for (c, d) in layout.components.iter().zip(decodes) {
            let (Some(c), Some(d)) = (c, d) else {
                slab_decodes.push(None);
                continue;
            };
            let Some((_, v)) = chans.iter().find(|(n, _)| n == c) else { return Err(missing(c)) };
            if v.geometry.dims != [nx, ny, z.len()] {
                return Err(PackError::Geometry(format!(
                    "channel {c} of planes {z:?} has {} voxels, not {nx} x {ny} x {}",
                    v.geometry.dims_string(),
                    z.len()
                )));
            }
            slab_decodes.push(Some((v.samples(), *d)));
        }
        Ok(Prepared { dtype: layout.dtype, dims: [nx, ny, z.len()], decodes: slab_decodes })
    }

    pub(crate) fn plane_bytes(&self) -> usize {
        self.dims[0] * self.dims[1] * self.decodes.len() * self.dtype.size()
    }

    /// Quantises z-slices `first..` into `out` (whole slices), in parallel over slices.
    pub(crate) fn encode_planes(&self, first: usize, out: &mut [u8]) {
        let (size, comps) = (self.dtype.size(), self.decodes.len());
        let [nx, ny, _] = self.dims;
        let plane = nx * ny;
        out.par_chunks_mut(self.plane_bytes().max(1)).enumerate().for_each_init(
            || vec![vec![0u32; nx]; comps],
            |codes, (dk, out)| {
                let k = first + dk;
                for j in 0..ny {
                    let row = (k * plane + j * nx)..(k * plane + (j + 1) * nx);
                    for (ci, dec) in self.decodes.iter().enumerate() {
                        match dec {
                            Some((data, d)) => encode_row(&data[row.clone()], d, self.dtype, &mut codes[ci]),
                            None => codes[ci].fill(0),
                        }
                    }
                    interleave(codes, size, &mut out[j * nx * comps * size..(j + 1) * nx * comps * size]);
                }
            },
        );
    }

    /// Every slice into `out`, a slab of [`SLAB_PLANES`] at a time.
    pub(crate) fn stream(&self, out: &mut dyn FnMut(&[u8]) -> std::io::Result<()>) -> std::io::Result<()> {
        let nz = self.dims[2];
        let mut slab = vec![0u8; self.plane_bytes() * SLAB_PLANES.min(nz)];
        for first in (0..nz).step_by(SLAB_PLANES) {
            let planes = SLAB_PLANES.min(nz - first);
            let bytes = &mut slab[..planes * self.plane_bytes()];
            self.encode_planes(first, bytes);
            out(bytes)?;
        }
        Ok(())
    }
}

/// What [`PackWriter::add_slabs`] reads a slab's channels from: called
/// with the slab's planes and the slab before's channels (done with: their
/// memory can hold the next's), it gives the slab's channels by name.
pub type SlabSource<'a> =
    dyn FnMut(Range<usize>, Vec<(String, Volume)>) -> Result<Vec<(String, Volume)>, PackError> + Send + 'a;

/// Writes a pack into a folder one texture at a time: [`PackWriter::add`]
/// quantises and writes a texture and drops its bytes; [`PackWriter::finish`]
/// writes the lookup tables and the manifest.
pub struct PackWriter<'a> {
    dir: &'a Path,
    encoder: TextureEncoder<'a>,
    textures: Vec<TextureEntry>,
}

impl<'a> PackWriter<'a> {
    /// A writer of a `params` pack on `geometry` into `dir` (which must exist);
    /// `sources` names the stage that made each channel (default: the usual one).
    pub fn new(
        dir: &'a Path,
        params: &'a PackParams,
        geometry: Geometry,
        sources: &'a BTreeMap<String, ChannelSource>,
    ) -> PackWriter<'a> {
        PackWriter { dir, encoder: TextureEncoder::new(params, geometry, sources), textures: Vec::new() }
    }

    /// Quantises texture `layout` from the channels `get` gives and writes it,
    /// a slab of z-slices at a time through one reused buffer (the whole
    /// texture in memory only when NIfTI copies are asked for).
    pub fn add<'v>(
        &mut self,
        layout: &TextureLayout,
        get: &dyn Fn(&str) -> Option<&'v Volume>,
    ) -> Result<(), PackError> {
        if self.encoder.params.nifti {
            // the NIfTI copy holds the components slowest: it needs the whole texture
            let bytes = self.encoder.encode(layout, get)?;
            let geometry = &self.encoder.geometry;
            self.textures.push(write_texture(self.dir, geometry, layout, TextureBytes::Whole(&bytes), true)?);
            return Ok(());
        }
        let prepared = self.encoder.prepare(layout, get)?;
        let geometry = &self.encoder.geometry;
        self.textures.push(write_texture(self.dir, geometry, layout, TextureBytes::Streamed(&prepared), false)?);
        Ok(())
    }

    /// Quantises the textures `layouts` together, a slab of z-slices at a
    /// time, and writes them: `slab(z)` gives every channel the textures read
    /// on planes `z` (each a volume of those planes), for each range of
    /// `slabs` in turn (in order, covering every plane once), so each slab's
    /// channels are made once for all the textures. Every channel needs its
    /// code range in the pack's parameters (unit normals excepted), since no
    /// slab sees the whole channel; the bytes equal [`PackWriter::add`]'s
    /// with those ranges. On an error no texture of `layouts` is written.
    /// `slab(z, spent)` is also handed the channels of the slab before
    /// (empty for the first), done with, so it can make the next slab's in
    /// their memory.
    pub fn add_slabs(
        &mut self,
        layouts: &[TextureLayout],
        slabs: &[Range<usize>],
        slab: &mut SlabSource<'_>,
    ) -> Result<(), PackError> {
        let nz = self.encoder.geometry.dims[2];
        let covered = slabs.first().is_some_and(|s| s.start == 0)
            && slabs.last().is_some_and(|s| s.end == nz)
            && slabs.windows(2).all(|w| w[0].end == w[1].start)
            && slabs.iter().all(|s| s.start < s.end);
        if !covered {
            return Err(PackError::Geometry(format!("the slabs {slabs:?} do not cover the {nz} planes in order")));
        }
        if self.encoder.params.nifti {
            return Err(PackError::Geometry(
                "NIfTI copies of the textures hold the components slowest and need each whole texture; \
                 they cannot be written slab by slab"
                    .into(),
            ));
        }
        let decodes =
            layouts.iter().map(|layout| self.encoder.prepare_ranged(layout)).collect::<Result<Vec<_>, _>>()?;
        let mut files = layouts
            .iter()
            .map(|layout| AtomicWriter::create(&self.dir.join(format!("{}.raw", layout.name))))
            .collect::<Result<Vec<_>, _>>()?;
        let this = &*self;
        // the memory of the slab before's channels and written textures is
        // reused: fresh memory of this size page-faults, at a cost like the quantising's
        let mut spent_channels = Vec::new();
        // a slab's channels are made and quantised while the slab before is written
        let mut make = |k: usize, written: Option<Vec<Vec<u8>>>| -> Result<Vec<Vec<u8>>, PackError> {
            let z = &slabs[k];
            let chans = slab(z.clone(), std::mem::take(&mut spent_channels))?;
            let mut written = written.unwrap_or_default().into_iter();
            let mut textures = Vec::with_capacity(layouts.len());
            for (layout, decodes) in layouts.iter().zip(&decodes) {
                let p = this.slab_of(layout, decodes, z, &chans)?;
                let mut bytes = written.next().unwrap_or_default();
                // every byte is encoded over
                bytes.resize(p.plane_bytes() * z.len(), 0);
                p.encode_planes(0, &mut bytes);
                textures.push(bytes);
            }
            spent_channels = chans;
            Ok(textures)
        };
        let mut write = |textures: Vec<Vec<u8>>| -> Result<Option<Vec<Vec<u8>>>, PackError> {
            for ((layout, file), bytes) in layouts.iter().zip(&mut files).zip(&textures) {
                file.write_all(bytes).map_err(|cause| {
                    PackError::Io(VolumeError::Io { path: this.dir.join(format!("{}.raw", layout.name)), cause })
                })?;
            }
            Ok(Some(textures))
        };
        mdtf_volume::overlapped(slabs.len(), &mut |_| Ok(()), &mut make, &mut write)?;
        for (layout, file) in layouts.iter().zip(files) {
            file.publish()?;
            self.textures.push(write_header(self.dir, &self.encoder.geometry, layout, None)?);
        }
        Ok(())
    }

    /// The textures `layouts`, for tasks (in any process, in any order) to
    /// write plane range by plane range ([`TextureTarget::write_planes`]):
    /// their manifest entries recorded from the code ranges in the pack's
    /// parameters, their data files created empty in the pack's folder
    /// (itself inside a staging folder: a failed run publishes none of
    /// them; a file already there is refused, never truncated, unless
    /// `resumed`: then the pack's folder is a killed run's, whose files
    /// are taken as they are, for the tasks to find their planes written).
    /// [`PackWriter::adopt_task_textures`] takes them in once every plane
    /// is written.
    pub fn task_textures(&mut self, layouts: &[TextureLayout], resumed: bool) -> Result<Vec<TextureTarget>, PackError> {
        let geometry = &self.encoder.geometry;
        let plane = [geometry.dims[0], geometry.dims[1]];
        let mut targets = Vec::with_capacity(layouts.len());
        for layout in layouts {
            let decodes = self.encoder.prepare_ranged(layout)?;
            let file = self.dir.join(format!("{}.raw", layout.name));
            // a new file only: the pack's folder is a staging folder, and nothing there is replaced
            let created = match resumed {
                true => std::fs::File::options().write(true).create(true).truncate(false).open(&file),
                false => std::fs::File::create_new(&file),
            };
            created.map_err(|cause| PackError::Io(VolumeError::Io { path: file.clone(), cause }))?;
            targets.push(TextureTarget { file, layout: layout.clone(), decodes, plane });
        }
        Ok(targets)
    }

    /// Takes in the textures of [`PackWriter::task_textures`], every plane
    /// written: checks each data file's length and writes its header.
    pub fn adopt_task_textures(&mut self, targets: &[TextureTarget]) -> Result<(), PackError> {
        let nz = self.encoder.geometry.dims[2];
        for t in targets {
            let want = (t.plane_bytes() * nz) as u64;
            let got = std::fs::metadata(&t.file)
                .map_err(|cause| PackError::Io(VolumeError::Io { path: t.file.clone(), cause }))?
                .len();
            if got != want {
                return Err(PackError::Geometry(format!(
                    "texture {} holds {got} bytes after its tasks, not {want}: a task did not write its planes",
                    t.layout.name
                )));
            }
            self.textures.push(write_header(self.dir, &self.encoder.geometry, &t.layout, None)?);
        }
        Ok(())
    }

    /// Texture `layout` on the planes `z` of a slab whose channels are
    /// `chans`, ready to quantise with its components' `decodes`.
    fn slab_of<'v>(
        &self,
        layout: &TextureLayout,
        decodes: &[Option<Decode>],
        z: &Range<usize>,
        chans: &'v [(String, Volume)],
    ) -> Result<Prepared<'v>, PackError> {
        let [nx, ny, _] = self.encoder.geometry.dims;
        Prepared::of_slab(layout, decodes, [nx, ny], z, chans, &|c| self.encoder.missing(c))
    }

    /// Writes the lookup tables and `manifest.json`; returns the manifest.
    pub fn finish(self, luts: &[Lut], provenance: Provenance) -> Result<Manifest, PackError> {
        let e = self.encoder;
        write_manifest(self.dir, e.params.profile, &e.geometry, self.textures, e.entries, luts, provenance)
    }
}

/// A texture's bytes: encoded already, or quantised slab by slab as they are written.
pub(crate) enum TextureBytes<'a, 'v> {
    Whole(&'a [u8]),
    Streamed(&'a Prepared<'v>),
}

/// Writes one texture's bytes as `<name>.raw` with a detached NRRD header
/// (and `<name>.nii` when `nifti`, which needs [`TextureBytes::Whole`]);
/// returns its manifest entry.
pub(crate) fn write_texture(
    dir: &Path,
    geometry: &Geometry,
    layout: &TextureLayout,
    bytes: TextureBytes,
    nifti: bool,
) -> Result<TextureEntry, PackError> {
    let mut bytes = bytes;
    write_file_atomically(&dir.join(format!("{}.raw", layout.name)), |w| match &mut bytes {
        TextureBytes::Whole(b) => w.write_all(b),
        TextureBytes::Streamed(p) => p.stream(&mut |b| w.write_all(b)),
    })?;
    let nifti = match (nifti, &bytes) {
        (true, TextureBytes::Whole(b)) => {
            let file = format!("{}.nii", layout.name);
            write_nifti_texture(&dir.join(&file), geometry, &layout.components, layout.dtype, b)?;
            Some(file)
        }
        _ => None,
    };
    write_header(dir, geometry, layout, nifti)
}

/// Writes the detached NRRD header `<name>.nhdr` of texture `layout`, whose
/// data `<name>.raw` (and NIfTI copy `nifti`) is written; returns its manifest entry.
fn write_header(
    dir: &Path,
    geometry: &Geometry,
    layout: &TextureLayout,
    nifti: Option<String>,
) -> Result<TextureEntry, PackError> {
    let comps = layout.components.len();
    let data_file = format!("{}.raw", layout.name);
    let header_file = format!("{}.nhdr", layout.name);
    let type_name = match layout.dtype {
        Dtype::U8 => "uint8",
        Dtype::U16 | Dtype::F16 => "uint16",
        Dtype::F32 => "float",
    };
    let order: Vec<String> = layout.components.iter().map(|c| c.clone().unwrap_or_else(|| "-".into())).collect();
    let extra = [("mdtf_components", order.join(" ")), ("mdtf_dtype", format!("{:?}", layout.dtype).to_lowercase())];
    let header = mdtf_volume::nrrd::texture_header(geometry, comps, type_name, &data_file, &extra);
    write_file_atomically(&dir.join(&header_file), |w| w.write_all(header.as_bytes()))?;
    Ok(TextureEntry {
        name: layout.name.clone(),
        header: header_file,
        data: data_file,
        dims: geometry.dims,
        components: comps,
        component_order: layout.components.clone(),
        dtype: layout.dtype,
        nifti,
    })
}

/// Writes the lookup tables and `manifest.json` of a pack whose textures are written.
pub(crate) fn write_manifest(
    dir: &Path,
    profile: Profile,
    geometry: &Geometry,
    textures: Vec<TextureEntry>,
    channels: Vec<ChannelEntry>,
    luts: &[Lut],
    provenance: Provenance,
) -> Result<Manifest, PackError> {
    let manifest = Manifest {
        schema: SCHEMA_ID.into(),
        profile: profile.to_string(),
        geometry: ManifestGeometry {
            dims: geometry.dims,
            spacing: geometry.spacing,
            origin: geometry.origin,
            world_from_voxel: geometry.world_from_voxel(),
        },
        textures,
        channels,
        luts: luts.iter().map(|l| l.write(dir)).collect::<Result<_, _>>()?,
        mesh: None,
        provenance,
    };
    let json = serde_json::to_string_pretty(&manifest)
        .map_err(|e| PackError::Io(VolumeError::Fields(format!("manifest: {e}"))))?;
    write_file_atomically(&dir.join("manifest.json"), |w| w.write_all(json.as_bytes()))?;
    Ok(manifest)
}

/// Codes of one row of one component. Integer codes are rounded in f64 (so
/// every code is within half a step whatever the range) in a branch-free
/// loop that vectorises; compiled for AVX-512/AVX2 too, picked at run time.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512vl+avx2", "x86_64+avx2"))]
fn encode_row(src: &[f32], d: &Decode, dtype: Dtype, codes: &mut [u32]) {
    match dtype.max_code() {
        Some(top) => {
            let (off, inv) = (d.offset, 1.0 / d.scale);
            // Adding 2^52 leaves the rounded (to nearest, ties to even: still within half a
            // step) integer in the low mantissa bits: no float-to-int conversion, so no
            // per-lane NaN handling, and the loop stays in SIMD registers.
            const MAGIC: f64 = 4_503_599_627_370_496.0;
            for (c, &v) in codes.iter_mut().zip(src) {
                let x = (v as f64 - off) * inv;
                let x = if x > 0.0 { x } else { 0.0 }; // NaN fails the comparison: code 0
                let x = if x < top { x } else { top };
                *c = (x + MAGIC).to_bits() as u32;
            }
        }
        None => {
            for (c, &v) in codes.iter_mut().zip(src) {
                *c = d.code(v, dtype);
            }
        }
    }
}

/// Interleaves per-component codes (each one row) into little-endian texture bytes.
fn interleave(codes: &[Vec<u32>], size: usize, out: &mut [u8]) {
    let comps = codes.len();
    match (size, comps) {
        (1, 4) => {
            let n = out.len() / 4;
            let (c0, c1, c2, c3) = (&codes[0][..n], &codes[1][..n], &codes[2][..n], &codes[3][..n]);
            // one little-endian u32 per texel: shifts and ors that vectorise
            for (i, px) in out.chunks_exact_mut(4).enumerate() {
                let word = (c0[i] & 0xff) | (c1[i] & 0xff) << 8 | (c2[i] & 0xff) << 16 | (c3[i] & 0xff) << 24;
                px.copy_from_slice(&word.to_le_bytes());
            }
        }
        _ => {
            for (i, px) in out.chunks_exact_mut(comps * size).enumerate() {
                for (ci, code) in codes.iter().enumerate() {
                    px[ci * size..(ci + 1) * size].copy_from_slice(&code[i].to_le_bytes()[..size]);
                }
            }
        }
    }
}

/// Writes one texture as NIfTI-1: a 4D volume with one component per
/// volume (named after its channel), the stored codes as u8, u16 or f32.
fn write_nifti_texture(
    path: &Path,
    geometry: &mdtf_volume::Geometry,
    components: &[Option<String>],
    dtype: Dtype,
    bytes: &[u8],
) -> Result<(), PackError> {
    use mdtf_volume::{Field, MultiField, SampleType, WriteOptions};
    let (size, ty) = match dtype {
        Dtype::U8 => (1, SampleType::U8),
        Dtype::U16 | Dtype::F16 => (2, SampleType::U16),
        Dtype::F32 => (4, SampleType::F32),
    };
    let comps = components.len();
    let mut fields = Vec::with_capacity(comps);
    for (c, name) in components.iter().enumerate() {
        let values: Vec<f32> = bytes
            .chunks_exact(comps * size)
            .map(|px| {
                let b = &px[c * size..(c + 1) * size];
                match size {
                    1 => b[0] as f32,
                    2 => u16::from_le_bytes([b[0], b[1]]) as f32,
                    _ => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                }
            })
            .collect();
        let data = ndarray::Array3::from_shape_vec(geometry.shape(), values)
            .map_err(|e| PackError::Geometry(format!("{}: {e}", path.display())))?;
        fields.push(Field { name: name.clone().unwrap_or_else(|| "unused".into()), data });
    }
    let mf = MultiField { geometry: geometry.clone(), fields };
    mdtf_volume::write(path, &mf, &WriteOptions { ty, gzip: false }, &[])?;
    Ok(())
}
