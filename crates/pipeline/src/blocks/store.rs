//! Where a slab-by-slab run keeps its channels between passes: each channel
//! a file of f32 samples (the hit codes, 0 to 3, of one byte each; x-fastest,
//! the writer's byte order: the run's own processes read them, on machines
//! of one kind) in a folder inside the
//! run's staging folder, written and read by z-planes. Only the planes a
//! pass asks for are ever in memory; the files go with the staging folder.
//! Tasks of a run spread over processes ([`super::remote`]) open the same
//! folder ([`ChannelStore::open`]) and each writes only its own planes.

use crate::channel::Channel;
use mdtf_volume::{Geometry, SampleType, Volume};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::ops::Range;
use std::path::PathBuf;

/// The store's folder inside a run's staging folder.
pub(crate) const STORE_DIR: &str = ".slabs";

/// How channel `c` is kept in its file: the hit codes (small integers) as
/// u8, every other channel as f32.
pub(crate) fn stored_type(c: Channel) -> SampleType {
    match c {
        Channel::Hit => SampleType::U8,
        _ => SampleType::F32,
    }
}

/// The file in the store folder holding channel `c` (e.g. `g.f32`, `hit.u8`).
pub(crate) fn file_name(c: Channel) -> String {
    format!("{}.{}", c.name(&[]), stored_type(c).name())
}

/// The bytes channel `c`'s `samples` take in its file.
pub(crate) fn stored_bytes(c: Channel, samples: &[f32]) -> Cow<'_, [u8]> {
    match stored_type(c) {
        SampleType::F32 => Cow::Borrowed(bytemuck::cast_slice(samples)),
        // the hit codes are exact small integers
        _ => Cow::Owned(samples.iter().map(|&x| x as u8).collect()),
    }
}

/// The channels of a run, on disk (see the module docs).
pub struct ChannelStore {
    dir: PathBuf,
    geometry: Geometry,
    files: BTreeMap<Channel, File>,
}

impl ChannelStore {
    /// A store for channels on `geometry`, in the folder `dir`, which must
    /// not exist yet (it is the store's alone: [`ChannelStore::clear`]
    /// removes it whole).
    pub fn create(dir: PathBuf, geometry: Geometry) -> std::io::Result<ChannelStore> {
        std::fs::create_dir(&dir)?;
        Ok(ChannelStore { dir, geometry, files: BTreeMap::new() })
    }

    /// The store a killed run left in `dir` for channels on `geometry`,
    /// taken over by the run resuming it: its files are taken in as the
    /// passes write them again (or find them written by their tasks), none
    /// before. A missing folder is created.
    pub fn resume(dir: PathBuf, geometry: Geometry) -> std::io::Result<ChannelStore> {
        std::fs::create_dir_all(&dir)?;
        Ok(ChannelStore { dir, geometry, files: BTreeMap::new() })
    }

    /// The store a run created in `dir` for channels on `geometry`, for a
    /// task of the run in another process: with the channels `reads` (the
    /// ones its pass reads; those it writes are created or joined on write,
    /// and a rerun task must not take its own half-written ones for stored).
    pub fn open(dir: PathBuf, geometry: Geometry, reads: &[Channel]) -> std::io::Result<ChannelStore> {
        let mut store = ChannelStore { dir, geometry, files: BTreeMap::new() };
        for &c in reads {
            store.adopt(c)?;
        }
        Ok(store)
    }

    /// Takes in channel `c`, written into the folder by another process.
    pub fn adopt(&mut self, c: Channel) -> std::io::Result<()> {
        let path = self.dir.join(file_name(c));
        let file = File::options()
            .read(true)
            .write(true)
            .open(&path)
            .map_err(|e| std::io::Error::new(e.kind(), format!("channel store file {}: {e}", path.display())))?;
        self.files.insert(c, file);
        Ok(())
    }

    /// The folder of the store.
    pub fn dir(&self) -> &std::path::Path {
        &self.dir
    }

    /// The grid of the channels.
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// Voxels per z-plane.
    pub fn plane_len(&self) -> usize {
        self.geometry.dims[0] * self.geometry.dims[1]
    }

    /// The channels the store holds.
    pub fn channels(&self) -> Vec<Channel> {
        self.files.keys().copied().collect()
    }

    /// Whether the store holds channel `c`.
    pub fn has(&self, c: Channel) -> bool {
        self.files.contains_key(&c)
    }

    /// Writes the samples of planes `first..` of channel `c` (whole
    /// planes), creating the channel on its first write (or taking the file
    /// another task of the run created).
    pub fn put(&mut self, c: Channel, first: usize, samples: &[f32]) -> std::io::Result<()> {
        self.put_stored_bytes(c, first, &stored_bytes(c, samples))
    }

    /// [`ChannelStore::put`] of samples already in their file's form
    /// ([`stored_bytes`]), for a writer that also hashes them.
    pub fn put_stored_bytes(&mut self, c: Channel, first: usize, bytes: &[u8]) -> std::io::Result<()> {
        let offset = (first * self.plane_len() * stored_type(c).size()) as u64;
        self.create_channel(c)?;
        let Some(file) = self.files.get_mut(&c) else { return Err(missing(c)) };
        write_sparse(file, offset, bytes)
    }

    /// Writes a volume of planes `first..` of channel `c`.
    pub fn put_volume(&mut self, c: Channel, first: usize, v: &Volume) -> std::io::Result<()> {
        self.put(c, first, v.samples())
    }

    /// Writes `v`, rows `rows` of planes `first..` of channel `c` (a
    /// strip of a blocked pass), creating the channel on its first write.
    pub fn put_rows(&mut self, c: Channel, first: usize, rows: Range<usize>, v: &Volume) -> std::io::Result<()> {
        self.create_channel(c)?;
        let Some(file) = self.files.get_mut(&c) else { return Err(missing(c)) };
        write_rows(file, c, &self.geometry, first, rows, v)
    }

    /// A writer of channels `channels` (created here when new) that works
    /// beside this store's reads: a pass hands it one block's outputs while
    /// it makes the next block's.
    pub fn writer(&mut self, channels: &[Channel]) -> std::io::Result<StoreWriter> {
        let mut files = BTreeMap::new();
        for &c in channels {
            self.create_channel(c)?;
            // its own handle: its own position in the file
            let file = File::options().write(true).open(self.dir.join(file_name(c)))?;
            files.insert(c, file);
        }
        Ok(StoreWriter { geometry: self.geometry.clone(), files })
    }

    /// Creates channel `c`'s file, or takes the one another task of the run created.
    fn create_channel(&mut self, c: Channel) -> std::io::Result<()> {
        if !self.files.contains_key(&c) {
            let path = self.dir.join(file_name(c));
            let file = File::options().read(true).write(true).create(true).truncate(false).open(path)?;
            self.files.insert(c, file);
        }
        Ok(())
    }

    /// Rows `rows` of planes `z` of channel `c` into `samples` (resized;
    /// its memory reused), planes clamped to the grid.
    pub fn rows_into(
        &mut self,
        c: Channel,
        z: Range<usize>,
        rows: Range<usize>,
        samples: &mut Vec<f32>,
    ) -> std::io::Result<()> {
        let [nx, _, nz] = self.geometry.dims;
        let (z0, z1) = (z.start.min(nz), z.end.min(nz).max(z.start.min(nz)));
        samples.resize((z1 - z0) * nx * rows.len(), 0.0);
        self.rows_into_slice(c, z0..z1, rows, samples)
    }

    /// Rows `rows` of planes `z` (within the grid) of channel `c` into
    /// `samples`, which holds exactly that many.
    pub fn rows_into_slice(
        &mut self,
        c: Channel,
        z: Range<usize>,
        rows: Range<usize>,
        samples: &mut [f32],
    ) -> std::io::Result<()> {
        let [nx, ny, _] = self.geometry.dims;
        let chunk = nx * rows.len();
        if samples.len() != z.len() * chunk {
            let what = format!("{} samples for {} planes of {chunk}", samples.len(), z.len());
            return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, what));
        }
        let Some(file) = self.files.get_mut(&c) else { return Err(missing(c)) };
        let size = stored_type(c).size();
        let mut read = |offset: usize, out: &mut [f32]| -> std::io::Result<()> {
            file.seek(SeekFrom::Start((offset * size) as u64))?;
            if size == 4 {
                return file.read_exact(bytemuck::cast_slice_mut(out));
            }
            // one-byte codes read into the samples' own memory and widened from the
            // last, so that no code is overwritten before it is read
            let n = out.len();
            let bytes: &mut [u8] = bytemuck::cast_slice_mut(out);
            file.read_exact(&mut bytes[..n])?;
            for i in (0..n).rev() {
                let sample = f32::from(bytes[i]).to_ne_bytes();
                bytes[4 * i..4 * i + 4].copy_from_slice(&sample);
            }
            Ok(())
        };
        if rows.start == 0 && rows.end == ny {
            return read(z.start * chunk, samples);
        }
        for (k, plane) in samples.chunks_mut(chunk.max(1)).enumerate() {
            read(((z.start + k) * ny + rows.start) * nx, plane)?;
        }
        Ok(())
    }

    /// The samples of planes `z` (clamped to the grid) of channel `c`.
    pub fn samples(&mut self, c: Channel, z: Range<usize>) -> std::io::Result<Vec<f32>> {
        let mut samples = Vec::new();
        self.samples_into(c, z, &mut samples)?;
        Ok(samples)
    }

    /// [`ChannelStore::samples`] into `samples` (resized; its memory reused).
    pub fn samples_into(&mut self, c: Channel, z: Range<usize>, samples: &mut Vec<f32>) -> std::io::Result<()> {
        self.rows_into(c, z, 0..self.geometry.dims[1], samples)
    }

    /// Planes `z` (clamped to the grid) of channel `c` as a volume placed where they lie.
    pub fn volume(&mut self, c: Channel, z: Range<usize>) -> std::io::Result<Volume> {
        let nz = self.geometry.dims[2];
        let (z0, z1) = (z.start.min(nz), z.end.min(nz).max(z.start.min(nz)));
        let data = self.samples(c, z0..z1)?;
        Volume::from_samples(self.geometry.z_slab(z0..z1), data).map_err(std::io::Error::other)
    }

    /// Drops channel `c` and its file.
    pub fn remove(&mut self, c: Channel) {
        if self.files.remove(&c).is_some() {
            let _ = std::fs::remove_file(self.dir.join(file_name(c)));
        }
    }

    /// Removes every channel and the folder.
    pub fn clear(mut self) {
        self.files.clear();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Writes channels of a [`ChannelStore`] on handles of their own (see [`ChannelStore::writer`]).
pub struct StoreWriter {
    geometry: Geometry,
    files: BTreeMap<Channel, File>,
}

impl StoreWriter {
    /// [`ChannelStore::put_volume`], for one of the writer's channels.
    pub fn put_volume(&mut self, c: Channel, first: usize, v: &Volume) -> std::io::Result<()> {
        self.put_rows(c, first, 0..self.geometry.dims[1], v)
    }

    /// [`ChannelStore::put_rows`], for one of the writer's channels.
    pub fn put_rows(&mut self, c: Channel, first: usize, rows: Range<usize>, v: &Volume) -> std::io::Result<()> {
        let Some(file) = self.files.get_mut(&c) else { return Err(missing(c)) };
        write_rows(file, c, &self.geometry, first, rows, v)
    }
}

/// Writes `v`, rows `rows` of planes `first..` of channel `c` on `geometry`, into its `file`.
fn write_rows(
    file: &mut File,
    c: Channel,
    geometry: &Geometry,
    first: usize,
    rows: Range<usize>,
    v: &Volume,
) -> std::io::Result<()> {
    let [nx, ny, _] = geometry.dims;
    let size = stored_type(c).size();
    if rows.start == 0 && rows.end == ny {
        return write_sparse(file, (first * nx * ny * size) as u64, &stored_bytes(c, v.samples()));
    }
    for (k, plane) in v.samples().chunks((nx * rows.len()).max(1)).enumerate() {
        let offset = (((first + k) * ny + rows.start) * nx * size) as u64;
        write_sparse(file, offset, &stored_bytes(c, plane))?;
    }
    Ok(())
}

/// Bytes of a block [`write_sparse`] leaves as a hole when it is all zero.
const HOLE_BLOCK: usize = 64 << 10;

/// Writes `bytes` at `offset` of `file`, leaving blocks of zero bytes as holes
/// (punched where the file already has data there), so that a channel of a
/// sparse input, mostly its fill value 0, costs the disk of what it holds
/// rather than of its grid. Holes read back as zeros. Where the file system
/// cannot punch holes, the zeros are written.
fn write_sparse(file: &mut File, offset: u64, bytes: &[u8]) -> std::io::Result<()> {
    let mut at = 0;
    let mut punched_last = false;
    while at < bytes.len() {
        let zero = |b: &[u8]| b.iter().all(|&x| x == 0);
        let block = |k: usize| &bytes[k..(k + HOLE_BLOCK).min(bytes.len())];
        let is_zero = zero(block(at));
        let mut run_end = (at + HOLE_BLOCK).min(bytes.len());
        while run_end < bytes.len() && zero(block(run_end)) == is_zero {
            run_end = (run_end + HOLE_BLOCK).min(bytes.len());
        }
        let run = &bytes[at..run_end];
        punched_last = is_zero && punch_hole(file, offset + at as u64, run.len() as u64);
        if !punched_last {
            file.seek(SeekFrom::Start(offset + at as u64))?;
            file.write_all(run)?;
        }
        at = run_end;
    }
    // a hole punched past the end does not lengthen the file: its last byte
    // written does (never set_len, which could cut what another task of the
    // run wrote further on meanwhile)
    if punched_last && let Some(last) = bytes.len().checked_sub(1) {
        file.seek(SeekFrom::Start(offset + last as u64))?;
        file.write_all(&bytes[last..])?;
    }
    Ok(())
}

/// Makes `len` bytes at `offset` of `file` a hole (zeros on read); false
/// where the file system or the platform cannot.
fn punch_hole(file: &File, offset: u64, len: u64) -> bool {
    #[cfg(target_os = "linux")]
    {
        use rustix::fs::{FallocateFlags, fallocate};
        fallocate(file, FallocateFlags::PUNCH_HOLE | FallocateFlags::KEEP_SIZE, offset, len).is_ok()
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (file, offset, len);
        false
    }
}

fn missing(c: Channel) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::NotFound, format!("channel {} is not in the store", c.name(&[])))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_blocks_are_holes_that_read_back_as_zeros_even_over_old_data() {
        use std::os::unix::fs::MetadataExt;
        let dir = tempfile::tempdir().unwrap();
        let g = Geometry::new([256, 256, 8], [1.0; 3]);
        let mut store = ChannelStore::create(dir.path().join("s"), g.clone()).unwrap();
        let plane = 256 * 256;
        // planes 0..8 of a sparse channel: a few non-zero samples in plane 2, -0.0 (not zero bits) in plane 5
        let mut samples = vec![0.0f32; 8 * plane];
        samples[2 * plane + 7] = 3.5;
        samples[5 * plane + 100] = -0.0;
        store.put(Channel::Value, 0, &samples).unwrap();
        let back = store.samples(Channel::Value, 0..8).unwrap();
        assert_eq!(
            back.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            samples.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        let file = dir.path().join("s/v.f32");
        let meta = std::fs::metadata(&file).unwrap();
        assert_eq!(meta.len(), (8 * plane * 4) as u64, "full length");
        // 2 MiB of samples, of which two 64 KiB blocks hold data (where the file system punches holes)
        let on_disk = meta.blocks() * 512;
        if on_disk < meta.len() {
            assert!(on_disk <= 4 * (64 << 10), "{on_disk} bytes on disk");
        }
        // rewriting data with zeros punches it out: it reads back as zeros
        store.put(Channel::Value, 2, &vec![0.0f32; plane]).unwrap();
        assert!(store.samples(Channel::Value, 2..3).unwrap().iter().all(|v| v.to_bits() == 0));
        // a zero block at the end of a later write still lengthens the file
        let mut tail = vec![0.0f32; 2 * plane];
        tail[10] = 1.0;
        let mut longer = ChannelStore::create(dir.path().join("t"), Geometry::new([256, 256, 10], [1.0; 3])).unwrap();
        longer.put(Channel::Hit, 8, &tail).unwrap();
        // the hit codes take one byte a voxel
        assert_eq!(std::fs::metadata(dir.path().join("t/hit.u8")).unwrap().len(), (10 * plane) as u64);
        assert_eq!(longer.samples(Channel::Hit, 8..10).unwrap(), tail);
        assert!(longer.samples(Channel::Hit, 0..8).unwrap().iter().all(|&v| v == 0.0));
    }

    #[test]
    fn hit_codes_come_back_from_their_bytes_by_strips_of_rows() {
        let dir = tempfile::tempdir().unwrap();
        let geo = Geometry::new([4, 6, 3], [1.0; 3]);
        let mut s = ChannelStore::create(dir.path().join("s"), geo.clone()).unwrap();
        let codes: Vec<f32> = (0..4 * 6 * 3).map(|i| ((i * 7) % 4) as f32).collect();
        let strip = |rows: std::ops::Range<usize>| -> Vec<f32> {
            (0..3).flat_map(|z| codes[(z * 6 + rows.start) * 4..(z * 6 + rows.end) * 4].to_vec()).collect()
        };
        for rows in [0..2, 2..6] {
            let v = Volume::from_samples(Geometry::new([4, rows.len(), 3], [1.0; 3]), strip(rows.clone())).unwrap();
            s.put_rows(Channel::Hit, 0, rows, &v).unwrap();
        }
        assert_eq!(s.samples(Channel::Hit, 0..3).unwrap(), codes);
        let mut part = Vec::new();
        s.rows_into(Channel::Hit, 1..3, 3..5, &mut part).unwrap();
        let want: Vec<f32> = (1..3).flat_map(|z| codes[(z * 6 + 3) * 4..(z * 6 + 5) * 4].to_vec()).collect();
        assert_eq!(part, want);
        assert_eq!(std::fs::metadata(dir.path().join("s/hit.u8")).unwrap().len(), 4 * 6 * 3);
    }

    #[test]
    fn planes_come_back_as_written_in_any_order_of_writes() {
        let dir = tempfile::tempdir().unwrap();
        let geo = Geometry::new([3, 2, 5], [1.0, 1.0, 2.0]);
        let mut s = ChannelStore::create(dir.path().join("store"), geo.clone()).unwrap();
        let all: Vec<f32> = (0..30).map(|i| i as f32 * 0.5 - 3.0).collect();
        s.put(Channel::G, 3, &all[18..]).unwrap();
        s.put(Channel::G, 0, &all[..18]).unwrap();
        assert_eq!(s.samples(Channel::G, 0..5).unwrap(), all);
        let v = s.volume(Channel::G, 1..3).unwrap();
        assert_eq!(v.samples(), &all[6..18]);
        assert_eq!(v.geometry, geo.z_slab(1..3));
        assert!(s.samples(Channel::F2, 0..1).is_err());
        // a strip of rows 1..2 of planes 2..5, written over the planes, reads back
        let strip: Vec<f32> = (0..9).map(|i| 100.0 + i as f32).collect();
        s.put_rows(Channel::G, 2, 1..2, &Volume::from_samples(geo.z_slab(2..5).y_rows(1..2), strip.clone()).unwrap())
            .unwrap();
        let mut back = Vec::new();
        s.rows_into(Channel::G, 2..5, 1..2, &mut back).unwrap();
        assert_eq!(back, strip);
        s.rows_into(Channel::G, 0..5, 0..1, &mut back).unwrap();
        let first_rows: Vec<f32> = (0..5).flat_map(|k| all[6 * k..6 * k + 3].to_vec()).collect();
        assert_eq!(back, first_rows, "the other rows are as written first");
        let whole = s.samples(Channel::G, 0..5).unwrap();
        assert_eq!(&whole[21..24], &strip[3..6], "plane 3's row 1 holds the strip's second plane");
        // a writer's channels, written on its own handles while the store reads others, read back
        let mut w = s.writer(&[Channel::F2]).unwrap();
        w.put_volume(Channel::F2, 3, &Volume::from_samples(geo.z_slab(3..5), all[18..].to_vec()).unwrap()).unwrap();
        assert_eq!(s.samples(Channel::G, 0..1).unwrap(), &all[..6]);
        w.put_rows(Channel::F2, 0, 1..2, &Volume::from_samples(geo.z_slab(0..3).y_rows(1..2), strip.clone()).unwrap())
            .unwrap();
        s.rows_into(Channel::F2, 0..3, 1..2, &mut back).unwrap();
        assert_eq!(back, strip);
        assert_eq!(s.samples(Channel::F2, 3..5).unwrap(), &all[18..]);
        assert!(w.put_volume(Channel::G, 0, &v).is_err(), "only the writer's own channels");
        s.remove(Channel::G);
        assert!(!s.has(Channel::G) && !dir.path().join("store/g.f32").exists());
        s.clear();
        assert!(!dir.path().join("store").exists());
    }
}
