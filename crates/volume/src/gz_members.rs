//! gzip files written as one member per z-plane of each field, after a
//! member holding the header. RFC 1952 makes a gzip file a series of
//! members one after another; gzip, zlib's `gzread` (ITK, FSL, Slicer),
//! Python's `gzip` (nibabel), indexed_gzip and mdtf's own readers take them
//! as one stream. Planes so compress side by side on every core, and a
//! process that holds only some planes (a slab, a cluster task) makes the
//! very bytes of those planes that a whole-volume write makes: the file's
//! bytes do not depend on how the volume was cut.
//!
//! A member holds at least one plane; the deflate window is 32 KiB, so
//! planes of 64 KiB and more compress as well as one stream does.

use crate::dtype::{Endian, SampleType, encode_samples};
use flate2::Compression;
use rayon::prelude::*;
use std::io::Write;

/// Planes compressed at once by [`write_plane_members`], per thread: enough
/// to keep every core busy, few enough that memory holds a few planes.
const PLANES_PER_THREAD: usize = 2;

/// One gzip member holding `bytes`: deflate at the fast level, no file
/// name, modification time 0 (so the bytes depend on `bytes` alone).
pub fn member(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::GzBuilder::new().write(Vec::with_capacity(bytes.len() / 2 + 64), Compression::fast());
    // writes into a Vec cannot fail
    let _ = enc.write_all(bytes);
    enc.finish().unwrap_or_default()
}

/// The whole planes of `samples` (x-fastest, `plane` samples a plane)
/// stored as `ty` little-endian, one gzip member a plane, compressed side
/// by side, in z order.
pub fn plane_members(samples: &[f32], plane: usize, ty: SampleType) -> Vec<Vec<u8>> {
    samples
        .par_chunks(plane.max(1))
        .map(|p| {
            let mut bytes = Vec::with_capacity(p.len() * ty.size());
            encode_samples(p, ty, Endian::Little, &mut bytes);
            member(&bytes)
        })
        .collect()
}

/// Writes the planes of `samples` to `w` as [`plane_members`] makes them,
/// a few planes per thread at a time (the bytes do not depend on how many).
pub fn write_plane_members(w: &mut dyn Write, samples: &[f32], plane: usize, ty: SampleType) -> std::io::Result<()> {
    let at_once = PLANES_PER_THREAD * rayon::current_num_threads().max(1);
    for batch in samples.chunks(plane.max(1) * at_once) {
        for m in plane_members(batch, plane, ty) {
            w.write_all(&m)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    #[test]
    fn the_members_read_back_as_one_stream_whatever_the_cut() {
        let plane = 6 * 5;
        let samples: Vec<f32> = (0..plane * 7).map(|i| ((i * 37) % 251) as f32).collect();
        let mut file = member(b"header");
        write_plane_members(&mut file, &samples, plane, SampleType::U16).unwrap();
        // a reader of one stream (flate2's, as zlib's gzread) reads every member
        let mut back = Vec::new();
        flate2::read::MultiGzDecoder::new(&file[..]).read_to_end(&mut back).unwrap();
        assert_eq!(&back[..6], b"header");
        let values: Vec<f32> = back[6..].chunks(2).map(|b| u16::from_le_bytes([b[0], b[1]]) as f32).collect();
        assert_eq!(values, samples);
        // planes 0..3 and 3..7 made apart are the bytes of the whole
        let mut cut = member(b"header");
        for part in [&samples[..3 * plane], &samples[3 * plane..]] {
            cut.extend(plane_members(part, plane, SampleType::U16).concat());
        }
        assert_eq!(cut, file);
        // and `gzip -t` takes the file as it is
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("members.gz");
        std::fs::write(&path, &file).unwrap();
        if let Ok(out) = std::process::Command::new("gzip").arg("-t").arg(&path).output() {
            assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        }
    }
}
