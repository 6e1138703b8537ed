//! RLE Lossless (PS3.5 Annex G) for 32-bit samples, which dicom-rs's decoder
//! refuses (it decodes 8 and 16 bits; RT dose grids store 32).
//!
//! Each frame is one fragment: a 64-byte header (the segment count, then up
//! to 15 segment offsets from the fragment's start), then one PackBits
//! segment per byte of the sample, the most significant byte's first.

/// The RLE Lossless transfer syntax's UID.
pub(crate) const RLE_LOSSLESS: &str = "1.2.840.10008.1.2.5";

/// Decodes `fragments` (one per frame) of single-sample pixels `width` bytes
/// wide, `plane` pixels per frame, into little-endian samples, frame after
/// frame. The error says what is wrong with which frame.
pub(crate) fn decode_frames(
    fragments: &[Vec<u8>],
    frames: usize,
    plane: usize,
    width: usize,
) -> Result<Vec<u8>, String> {
    if fragments.len() != frames {
        return Err(format!(
            "{} fragments for {frames} frames (RLE keeps each frame in one fragment)",
            fragments.len()
        ));
    }
    // a PackBits run of 2 bytes gives at most 128: the fragments bound what the frames can hold
    let held: usize = fragments.iter().map(Vec::len).sum();
    let needed = frames.saturating_mul(plane).saturating_mul(width);
    if needed > held.saturating_mul(64) {
        return Err(format!(
            "{held} bytes of fragments cannot decode to the {needed} bytes the header declares (RLE expands at most 64 times)"
        ));
    }
    let mut out = vec![0u8; needed];
    let mut segment = Vec::with_capacity(plane);
    for (f, (fragment, dst)) in fragments.iter().zip(out.chunks_exact_mut(plane * width)).enumerate() {
        let offsets = segment_offsets(fragment).map_err(|m| format!("frame {f}: {m}"))?;
        if offsets.len() != width {
            return Err(format!("frame {f}: {} segments, a {width}-byte sample needs {width}", offsets.len()));
        }
        for (s, &start) in offsets.iter().enumerate() {
            let end = offsets.get(s + 1).copied().unwrap_or(fragment.len());
            unpack_bits(&fragment[start..end], plane, &mut segment)
                .map_err(|m| format!("frame {f}, segment {s}: {m}"))?;
            // segment 0 holds the most significant bytes, which go last in little-endian order
            let byte = width - 1 - s;
            for (sample, &b) in dst.chunks_exact_mut(width).zip(&segment) {
                sample[byte] = b;
            }
        }
    }
    Ok(out)
}

/// The segment offsets of an RLE fragment's header, checked to increase within it.
fn segment_offsets(fragment: &[u8]) -> Result<Vec<usize>, String> {
    let word = |k: usize| fragment.get(4 * k..4 * k + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
    let count = word(0).ok_or("shorter than its 64-byte RLE header")?;
    if !(1..=15).contains(&count) || fragment.len() < 64 {
        return Err(format!("an RLE header of {count} segments (1 to 15 allowed) in {} bytes", fragment.len()));
    }
    let offsets: Vec<usize> = (1..=count).filter_map(word).collect();
    let ordered = offsets.first() == Some(&64) && offsets.windows(2).all(|w| w[0] <= w[1]);
    if !ordered || offsets.last().is_some_and(|&o| o > fragment.len()) {
        return Err(format!("segment offsets {offsets:?} do not run from 64 up within {} bytes", fragment.len()));
    }
    Ok(offsets)
}

/// Expands one PackBits segment into `out`, which must come to `len` bytes
/// (a trailing pad byte beyond them is allowed).
fn unpack_bits(src: &[u8], len: usize, out: &mut Vec<u8>) -> Result<(), String> {
    out.clear();
    let mut i = 0;
    while out.len() < len && i < src.len() {
        let n = src[i] as i8;
        i += 1;
        match n {
            0..=127 => {
                let run = n as usize + 1;
                let bytes = src.get(i..i + run).ok_or("a literal run past the segment's end")?;
                out.extend_from_slice(bytes);
                i += run;
            }
            -127..=-1 => {
                let &b = src.get(i).ok_or("a repeat run past the segment's end")?;
                out.resize(out.len() + (1 - n as isize) as usize, b);
                i += 1;
            }
            -128 => {}
        }
    }
    if out.len() < len {
        return Err(format!("decodes to {} bytes, the frame needs {len}", out.len()));
    }
    out.truncate(len);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// PackBits by the simplest rule: a run of equal bytes where there are at least 3, literals elsewhere.
    fn pack_bits(src: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut i = 0;
        while i < src.len() {
            let run = src[i..].iter().take(128).take_while(|&&b| b == src[i]).count();
            if run >= 3 {
                out.extend([(1 - run as isize) as i8 as u8, src[i]]);
                i += run;
            } else {
                let lit = (i..src.len().min(i + 128))
                    .take_while(|&k| k + 2 >= src.len() || src[k] != src[k + 1] || src[k] != src[k + 2])
                    .count()
                    .max(1);
                out.push((lit - 1) as u8);
                out.extend_from_slice(&src[i..i + lit]);
                i += lit;
            }
        }
        out
    }

    #[test]
    fn thirty_two_bit_frames_decode_to_the_samples_encoded() {
        let plane = 300;
        let frames: Vec<Vec<u32>> = (0..2u32)
            .map(|f| {
                (0..plane as u32)
                    .map(|p| if p % 50 < 20 { 0x0102_0304 + f } else { p.wrapping_mul(2_654_435_761) ^ f })
                    .collect()
            })
            .collect();
        let fragments: Vec<Vec<u8>> = frames
            .iter()
            .map(|samples| {
                let segments: Vec<Vec<u8>> = (0..4)
                    .map(|s| pack_bits(&samples.iter().map(|v| v.to_be_bytes()[s]).collect::<Vec<_>>()))
                    .collect();
                let mut fragment = vec![0u8; 64];
                fragment[0..4].copy_from_slice(&4u32.to_le_bytes());
                for (s, seg) in segments.iter().enumerate() {
                    let at = fragment.len() as u32;
                    fragment[4 + 4 * s..8 + 4 * s].copy_from_slice(&at.to_le_bytes());
                    fragment.extend_from_slice(seg);
                    if fragment.len() % 2 == 1 {
                        fragment.push(0); // segments are padded to even length
                    }
                }
                fragment
            })
            .collect();
        let bytes = decode_frames(&fragments, 2, plane, 4).unwrap();
        let got: Vec<u32> = bytes.chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        assert_eq!(got, frames.concat());
        // a frame cut short is an error, not a short read
        let mut cut = fragments.clone();
        let short = cut[1].len() - 40;
        cut[1].truncate(short);
        assert!(decode_frames(&cut, 2, plane, 4).unwrap_err().starts_with("frame 1, segment 3"));
        assert!(decode_frames(&fragments[..1], 2, plane, 4).unwrap_err().contains("1 fragments for 2 frames"));
        // a header claiming far more than the fragments can hold is refused before anything is allocated
        assert!(decode_frames(&fragments, 2, 1 << 40, 4).unwrap_err().contains("cannot decode to"));
    }
}
