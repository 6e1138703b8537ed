//! A walk over a DICOM file's element headers that checks every declared
//! length against the bytes that remain, before dicom-rs parses it.
//!
//! dicom-rs allocates each value to its declared length before reading it,
//! so a 500-byte file that declares a 4 GiB element would cost 4 GiB. The
//! walk reads only headers (tag, VR, length) and seeks over values, so it
//! costs a few reads per element and no memory.

use crate::error::{Result, VolumeError};
use std::io::{BufReader, Read};
use std::path::Path;

const UNDEFINED: u32 = u32::MAX;
/// Explicit VRs whose length field is 2 bytes; every other VR, unknown ones
/// included (the parser reads those as UN), has 2 reserved bytes and a 4-byte length.
const SHORT_VRS: &[&[u8; 2]] = &[
    b"AE", b"AS", b"AT", b"CS", b"DA", b"DS", b"DT", b"FL", b"FD", b"IS", b"LO", b"LT", b"PN", b"SH", b"SL", b"SS",
    b"ST", b"TM", b"UI", b"UL", b"US",
];

fn long_vr(vr: &[u8; 2]) -> bool {
    !SHORT_VRS.contains(&vr)
}
/// Deflated Explicit VR Little Endian: the dataset is a zlib stream, not walkable.
pub(crate) const DEFLATED: &str = "1.2.840.10008.1.2.1.99";

struct Walker {
    src: BufReader<std::fs::File>,
    pos: u64,
    len: u64,
}

impl Walker {
    fn bytes<const N: usize>(&mut self) -> std::io::Result<[u8; N]> {
        let mut b = [0u8; N];
        self.src.read_exact(&mut b)?;
        self.pos += N as u64;
        Ok(b)
    }

    fn skip(&mut self, n: u64) -> std::io::Result<()> {
        // relative seeks keep the buffer when the target is inside it
        self.src.seek_relative(n as i64)?;
        self.pos += n;
        Ok(())
    }

    fn back(&mut self, n: u64) -> std::io::Result<()> {
        self.src.seek_relative(-(n as i64))?;
        self.pos -= n;
        Ok(())
    }
}

/// Checks that no element of `path` declares more bytes than the file holds.
/// A file without the DICM signature is left to the parser to refuse.
pub fn check_declared_lengths(path: &Path) -> Result<()> {
    let file = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    let len = file.metadata().map_err(|e| VolumeError::io(path, e))?.len();
    let mut w = Walker { src: BufReader::with_capacity(4096, file), pos: 0, len };
    let truncated = |what: String| VolumeError::header(path, format!("not a readable DICOM file: {what}"));
    let io = |e: std::io::Error| truncated(format!("it ends inside an element header ({e})"));
    if len < 132 {
        return Ok(());
    }
    let head: [u8; 132] = w.bytes().map_err(io)?;
    if &head[128..] != b"DICM" {
        return Ok(());
    }
    // the file meta group: always explicit VR little endian
    let mut syntax = String::new();
    while w.pos + 8 <= len {
        let tag: [u8; 4] = w.bytes().map_err(io)?;
        if u16::from_le_bytes([tag[0], tag[1]]) != 0x0002 {
            w.back(4).map_err(io)?;
            break;
        }
        let vr: [u8; 2] = w.bytes().map_err(io)?;
        let n = if long_vr(&vr) {
            let b: [u8; 6] = w.bytes().map_err(io)?;
            u32::from_le_bytes([b[2], b[3], b[4], b[5]])
        } else {
            let b: [u8; 2] = w.bytes().map_err(io)?;
            u32::from(u16::from_le_bytes(b))
        };
        let element = u16::from_le_bytes([tag[2], tag[3]]);
        check(&w, n, 0x0002, element).map_err(&truncated)?;
        if element == 0x0010 && n <= 64 {
            let mut v = vec![0u8; n as usize];
            w.src.read_exact(&mut v).map_err(io)?;
            w.pos += u64::from(n);
            syntax = String::from_utf8_lossy(&v).trim_end_matches(['\0', ' ']).to_string();
        } else {
            w.skip(u64::from(n)).map_err(io)?;
        }
    }
    let (explicit, big) = match syntax.as_str() {
        DEFLATED => return Ok(()),
        "1.2.840.10008.1.2" => (false, false),
        "1.2.840.10008.1.2.2" => (true, true),
        _ => (true, false),
    };
    let u16_of = |b: [u8; 2]| if big { u16::from_be_bytes(b) } else { u16::from_le_bytes(b) };
    let u32_of = |b: [u8; 4]| if big { u32::from_be_bytes(b) } else { u32::from_le_bytes(b) };
    // the dataset: values with a defined length are skipped; sequences, items
    // and encapsulated pixel data are walked into, so nested lengths are checked too
    let mut in_fragments = false;
    while w.pos + 8 <= len {
        let tag: [u8; 4] = w.bytes().map_err(io)?;
        let (group, element) = (u16_of([tag[0], tag[1]]), u16_of([tag[2], tag[3]]));
        let n = if group == 0xFFFE || !explicit {
            u32_of(w.bytes().map_err(io)?)
        } else {
            let vr: [u8; 2] = w.bytes().map_err(io)?;
            if long_vr(&vr) {
                let b: [u8; 6] = w.bytes().map_err(io)?;
                let n = u32_of([b[2], b[3], b[4], b[5]]);
                if &vr == b"UN" && n == UNDEFINED {
                    // an implicit-VR sequence inside explicit data: left to the parser
                    return Ok(());
                }
                if &vr == b"SQ" {
                    continue;
                }
                n
            } else {
                u32::from(u16_of(w.bytes().map_err(io)?))
            }
        };
        if (group, element) == (0x7FE0, 0x0010) && n == UNDEFINED {
            // encapsulated pixel data: items of compressed bytes, not elements
            in_fragments = true;
            continue;
        }
        if group == 0xFFFE && element == 0xE0DD {
            in_fragments = false;
        }
        if n == UNDEFINED || (group == 0xFFFE && element == 0xE000 && !in_fragments) {
            continue;
        }
        check(&w, n, group, element).map_err(&truncated)?;
        if !explicit && n >= 8 && starts_an_item(&mut w, big).map_err(io)? {
            continue;
        }
        w.skip(u64::from(n)).map_err(io)?;
    }
    Ok(())
}

fn check(w: &Walker, n: u32, group: u16, element: u16) -> std::result::Result<(), String> {
    let remaining = w.len.saturating_sub(w.pos);
    if u64::from(n) > remaining {
        return Err(format!(
            "element ({group:04X},{element:04X}) declares {n} bytes but only {remaining} remain (truncated or corrupt)"
        ));
    }
    Ok(())
}

/// Whether the next bytes are an item tag (an implicit-VR sequence of defined length).
fn starts_an_item(w: &mut Walker, big: bool) -> std::io::Result<bool> {
    let b: [u8; 4] = w.bytes()?;
    w.back(4)?;
    let (g, e) = if big {
        (u16::from_be_bytes([b[0], b[1]]), u16::from_be_bytes([b[2], b[3]]))
    } else {
        (u16::from_le_bytes([b[0], b[1]]), u16::from_le_bytes([b[2], b[3]]))
    };
    Ok(g == 0xFFFE && e == 0xE000)
}
