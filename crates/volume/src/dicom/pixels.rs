//! Decoding the pixel data of a series into f32 slices, one file per task.
//!
//! Uncompressed pixel data is read in place; encapsulated data (RLE, JPEG,
//! JPEG 2000) goes through dicom-pixeldata's decoders, but for 32-bit RLE,
//! which they refuse (see `rle`). Each stored sample is
//! masked to BitsStored, sign-extended when PixelRepresentation is 1, then
//! scaled by its own slice's RescaleSlope and RescaleIntercept (they may vary
//! from slice to slice, as on many CT scanners).

use super::header::{ImageHeader, open};
use super::rle;
use super::series::SliceRef;
use crate::error::{Result, VolumeError};
use dicom_core::value::Value;
use dicom_dictionary_std::tags;
use dicom_pixeldata::PixelDecoder;
use dicom_transfer_syntax_registry::TransferSyntaxIndex;
use rayon::prelude::*;
use std::borrow::Cow;

/// One frame to decode and the plane of f32 it goes to.
struct Target<'a> {
    frame: usize,
    rescale: (f64, f64),
    plane: &'a mut [f32],
}

/// Decodes every slice of `slices` into `out` (one plane of cols x rows per
/// slice, in the order of `slices`), reading each file once, files in parallel.
pub fn decode_into(files: &[ImageHeader], slices: &[SliceRef], out: &mut [f32]) -> Result<()> {
    let (cols, rows) = files[0].slice_dims();
    let plane = cols * rows;
    let mut by_file: Vec<Vec<Target>> = (0..files.len()).map(|_| Vec::new()).collect();
    for (s, chunk) in slices.iter().zip(out.chunks_mut(plane)) {
        by_file[s.file].push(Target { frame: s.frame, rescale: s.rescale, plane: chunk });
    }
    by_file
        .into_par_iter()
        .enumerate()
        .filter(|(_, t)| !t.is_empty())
        .try_for_each(|(f, targets)| decode_file(&files[f], targets))
}

/// Refuses an uncompressed file too short for the pixels its header
/// declares, before the volume is allocated for them.
pub fn check_native_sizes(files: &[ImageHeader]) -> Result<()> {
    for h in files {
        // a deflated file holds its pixels compressed: its length says nothing of them
        let known = dicom_transfer_syntax_registry::TransferSyntaxRegistry.get(&h.transfer_syntax).is_some();
        let native = known && !encapsulated(h) && h.transfer_syntax != super::bounds::DEFLATED;
        let needed = h.pixel_bytes(h.frames.len());
        let len = std::fs::metadata(&h.path).map_err(|e| VolumeError::io(&h.path, e))?.len();
        if native && len < needed {
            return Err(pixel_shortage(h, len, needed));
        }
    }
    Ok(())
}

fn pixel_shortage(h: &ImageHeader, held: u64, needed: u64) -> VolumeError {
    VolumeError::header(
        &h.path,
        format!(
            "the pixel data holds {held} bytes, fewer than Columns x Rows x frames x bytes = {} x {} x {} x {} = {needed}",
            h.cols,
            h.rows,
            h.frames.len(),
            h.sample_bytes()
        ),
    )
}

fn decode_file(h: &ImageHeader, targets: Vec<Target>) -> Result<()> {
    let obj = open(&h.path, false)?;
    let element = obj
        .element_opt(tags::PIXEL_DATA)
        .ok()
        .flatten()
        .ok_or_else(|| VolumeError::header(&h.path, "the file has no PixelData (7FE0,0010)"))?;
    let plane = h.rows as usize * h.cols as usize;
    let bytes: Cow<[u8]> = match element.value() {
        Value::Primitive(_) if encapsulated(h) => {
            return Err(VolumeError::header(
                &h.path,
                format!(
                    "the transfer syntax, {}, says the pixel data is compressed in fragments, but it is stored \
                     uncompressed: the file is damaged or mislabelled",
                    h.transfer_syntax_name()
                ),
            ));
        }
        Value::Primitive(p) => little_endian_samples(h, element.vr(), p.to_bytes()),
        Value::PixelSequence(seq) if h.transfer_syntax == rle::RLE_LOSSLESS && h.bits_allocated == 32 => Cow::Owned(
            rle::decode_frames(seq.fragments(), h.frames.len(), plane, 4)
                .map_err(|m| VolumeError::header(&h.path, format!("the RLE Lossless pixel data: {m}")))?,
        ),
        _ => Cow::Owned(
            obj.decode_pixel_data()
                .map_err(|e| {
                    VolumeError::header(
                        &h.path,
                        format!(
                            "cannot decode the {} pixel data: {e}; convert it to an uncompressed syntax first, e.g. `gdcmconv --raw IN OUT`",
                            h.transfer_syntax_name()
                        ),
                    )
                })?
                .into_data(),
        ),
    };
    let frame_bytes = plane * h.sample_bytes();
    let needed = h.pixel_bytes(h.frames.len());
    if (bytes.len() as u64) < needed {
        return Err(pixel_shortage(h, bytes.len() as u64, needed));
    }
    if h.bits_allocated == 1 {
        // a binary mask (a segmentation): bit k of the stream, least significant first, is sample k
        for t in targets {
            let first = t.frame * plane;
            for (p, d) in t.plane.iter_mut().enumerate() {
                let bit = first + p;
                let stored = (bytes[bit / 8] >> (bit % 8)) & 1;
                *d = (f64::from(stored) * t.rescale.0 + t.rescale.1) as f32;
            }
        }
        return Ok(());
    }
    for t in targets {
        match &h.mosaic {
            // a mosaic has one frame; the target's frame names its tile
            Some(m) => {
                let rows = m.tile(&bytes[..frame_bytes], t.frame, h.sample_bytes());
                for (src, dst) in rows.zip(t.plane.chunks_mut(m.tile_cols)) {
                    convert(h, src, t.rescale, dst);
                }
            }
            None => convert(h, &bytes[t.frame * frame_bytes..(t.frame + 1) * frame_bytes], t.rescale, t.plane),
        }
    }
    Ok(())
}

/// Whether the file's transfer syntax keeps pixel data in fragments (JPEG, RLE, ...).
fn encapsulated(h: &ImageHeader) -> bool {
    dicom_transfer_syntax_registry::TransferSyntaxRegistry
        .get(&h.transfer_syntax)
        .is_some_and(|ts| ts.is_encapsulated_pixel_data())
}

/// Explicit VR Big Endian (retired), the one big-endian transfer syntax.
pub(crate) const EXPLICIT_VR_BIG_ENDIAN: &str = "1.2.840.10008.1.2.2";

/// Native pixel data as little-endian samples. The parser hands OW data as
/// 16-bit words in the machine's (little-endian) order, whatever the
/// transfer syntax's, and OB data as the file's bytes. So under Explicit VR
/// Big Endian a 32-bit sample stored as OW arrives as two swapped words in
/// big-endian order (its halves must trade places), and a sample wider than
/// a byte stored as OB arrives big-endian (its bytes must be reversed).
fn little_endian_samples<'a>(h: &ImageHeader, vr: dicom_core::VR, bytes: Cow<'a, [u8]>) -> Cow<'a, [u8]> {
    let width = h.sample_bytes();
    // already little-endian: any other syntax, single bytes, 16-bit words as OW
    if h.transfer_syntax != EXPLICIT_VR_BIG_ENDIAN || width < 2 || (vr == dicom_core::VR::OW && width == 2) {
        return bytes;
    }
    let mut le = bytes.into_owned();
    if vr == dicom_core::VR::OW {
        le.chunks_exact_mut(4).for_each(|s| {
            s.swap(0, 2);
            s.swap(1, 3);
        });
    } else {
        le.chunks_exact_mut(width).for_each(|s| s.reverse());
    }
    Cow::Owned(le)
}

/// Stored samples (little-endian, as the parser and decoders hand them) to
/// scaled f32. Each width has its own loop so that the masking and sign
/// extension stay in the sample's own integer type and vectorise.
fn convert(h: &ImageHeader, src: &[u8], (slope, intercept): (f64, f64), dst: &mut [f32]) {
    let scale = |stored: f64| (stored * slope + intercept) as f32;
    // bits above the high bit are dropped by shifting left, then the stored
    // bits are brought down with an arithmetic (signed) or logical shift
    let up = |width: u16| u32::from(width - 1 - h.high_bit);
    let down = |width: u16| u32::from(width - h.bits_stored);
    match h.bits_allocated {
        8 => {
            let (l, r) = (up(8), down(8));
            if h.signed {
                dst.iter_mut().zip(src).for_each(|(d, &b)| *d = scale(f64::from(((b << l) as i8) >> r)));
            } else {
                dst.iter_mut().zip(src).for_each(|(d, &b)| *d = scale(f64::from((b << l) >> r)));
            }
        }
        16 => {
            let (l, r) = (up(16), down(16));
            let word = |b: &[u8]| u16::from_le_bytes([b[0], b[1]]) << l;
            if h.signed {
                dst.iter_mut().zip(src.chunks_exact(2)).for_each(|(d, b)| *d = scale(f64::from((word(b) as i16) >> r)));
            } else {
                dst.iter_mut().zip(src.chunks_exact(2)).for_each(|(d, b)| *d = scale(f64::from(word(b) >> r)));
            }
        }
        _ => {
            let (l, r) = (up(32), down(32));
            let word = |b: &[u8]| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) << l;
            if h.signed {
                dst.iter_mut().zip(src.chunks_exact(4)).for_each(|(d, b)| *d = scale(f64::from((word(b) as i32) >> r)));
            } else {
                dst.iter_mut().zip(src.chunks_exact(4)).for_each(|(d, b)| *d = scale(f64::from(word(b) >> r)));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dicom::header::FramePlane;

    fn header(bits_allocated: u16, bits_stored: u16, high_bit: u16, signed: bool) -> ImageHeader {
        ImageHeader {
            path: "x.dcm".into(),
            series_uid: String::new(),
            series_number: None,
            description: String::new(),
            modality: String::new(),
            rescale_type: String::new(),
            padding: None,
            instance_uid: String::new(),
            transfer_syntax: String::new(),
            rows: 1,
            cols: 4,
            bits_allocated,
            bits_stored,
            high_bit,
            signed,
            samples_per_pixel: 1,
            photometric: "MONOCHROME2".into(),
            slice_thickness: None,
            spacing_between_slices: None,
            frames: vec![FramePlane { position: None, orientation: None, pixel_spacing: None, rescale: (1.0, 0.0) }],
            is_mosaic: false,
            mosaic: None,
        }
    }

    /// The stored value by the standard's definition (PS3.5 8.1.1), bit by bit.
    fn by_definition(raw: u64, h: &ImageHeader) -> f64 {
        let low = u32::from(h.high_bit + 1 - h.bits_stored);
        let v = (raw >> low) & ((1u64 << h.bits_stored) - 1);
        if h.signed && v >> (h.bits_stored - 1) & 1 == 1 { v as f64 - (1u64 << h.bits_stored) as f64 } else { v as f64 }
    }

    #[test]
    fn masking_and_sign_extension_follow_the_standard() {
        // 12 bits in 16 with junk (an overlay) above the high bit, and shifted layouts
        for (ba, bs, hb) in [(16, 12, 11), (16, 16, 15), (16, 12, 15), (16, 10, 13), (8, 8, 7), (8, 6, 5), (32, 20, 19)]
        {
            for signed in [false, true] {
                let h = header(ba, bs, hb, signed);
                let raws: Vec<u64> = match ba {
                    8 => vec![0x00, 0x7f, 0xc5, 0xff],
                    16 => vec![0x0000, 0xf7ff, 0x0800, 0xabcd],
                    _ => vec![0x0000_0000, 0xfff8_0000, 0x0007_ffff, 0x89ab_cdef],
                };
                let bytes: Vec<u8> =
                    raws.iter().flat_map(|&r| r.to_le_bytes()[..usize::from(ba / 8)].to_vec()).collect();
                let mut got = [0.0f32; 4];
                convert(&h, &bytes, (2.0, -3.0), &mut got);
                for (g, &r) in got.iter().zip(&raws) {
                    let want = by_definition(r, &h) * 2.0 - 3.0;
                    assert_eq!(*g as f64, want, "{ba}/{bs}/{hb} signed {signed} raw {r:#x}");
                }
            }
        }
    }
}
