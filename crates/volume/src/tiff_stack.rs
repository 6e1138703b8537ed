//! TIFF stacks, as microscopy hands them over: a multi-page TIFF or BigTIFF
//! (one page per z slice), or a folder of 2D TIFF slices sorted by the number
//! in their names (`z2.tif` before `z10.tif`). Grayscale samples of 8 to 64
//! bits, integer or float; uncompressed, LZW, Deflate, Zstandard or PackBits pages (the
//! `tiff` crate's decoders).
//!
//! Spacing comes from ImageJ metadata (`spacing=` for z and the X/Y
//! resolution tags for x and y) or from OME-TIFF XML (`PhysicalSizeX/Y/Z`);
//! without either it is 1 along each axis, with a warning. The origin is 0
//! and the axes are the identity: TIFF carries no orientation.

use crate::error::{Result, VolumeError};
use crate::geometry::Geometry;
use crate::samples::{FileInfo, ReadOptions};
use crate::volume::{Field, MultiField};
use crate::{Endian, SampleType};
use std::io::BufReader;
use std::path::{Path, PathBuf};
use tiff::ColorType;
use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::Tag;

/// How many slice files a folder may hold.
const MAX_SLICES: usize = 1 << 16;

/// Whether a file name ends in `.tif` or `.tiff`.
pub fn is_tiff_name(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("tif") || e.eq_ignore_ascii_case("tiff"))
}

/// The TIFF slices of a folder, sorted by the number in their names (then by name).
fn folder_slices(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| VolumeError::io(dir, e))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_file() && is_tiff_name(p))
        .take(MAX_SLICES + 1)
        .collect();
    if files.is_empty() {
        return Err(VolumeError::header(
            dir,
            "the folder holds no .tif or .tiff slices, no DICOM files and no Zarr metadata (zarr.json, or \
             .zgroup/.zarray for Zarr v2)",
        ));
    }
    if files.len() > MAX_SLICES {
        return Err(VolumeError::header(dir, format!("more than {MAX_SLICES} slice files")));
    }
    let number = |p: &Path| -> Option<u64> {
        let name = p.file_stem()?.to_string_lossy().into_owned();
        let digits: String =
            name.chars().rev().skip_while(|c| !c.is_ascii_digit()).take_while(char::is_ascii_digit).collect();
        digits.chars().rev().collect::<String>().parse().ok()
    };
    files.sort_by(|a, b| number(a).cmp(&number(b)).then_with(|| a.cmp(b)));
    Ok(files)
}

/// Spacing and the metadata it came from, from the first page's tags.
struct PageMeta {
    spacing: [Option<f64>; 3],
    /// Channels and time points the description states (ImageJ
    /// `channels=`/`frames=`, OME `SizeC`/`SizeT`), 1 when it states none.
    channels: u64,
    frames: u64,
}

fn tag_f64_pair(d: &mut Decoder<BufReader<std::fs::File>>, tag: Tag) -> Option<f64> {
    match d.find_tag(tag).ok()?? {
        tiff::decoder::ifd::Value::Rational(n, den) if n > 0 && den > 0 => Some(n as f64 / den as f64),
        v => v.into_f64().ok().filter(|x| x.is_finite() && *x > 0.0),
    }
}

/// `key="number"` inside an XML or `key=number` in ImageJ text.
fn number_after(text: &str, key: &str) -> Option<f64> {
    let at = text.find(key)? + key.len();
    let rest = text[at..].trim_start_matches(['=', '"', ' ']);
    let end =
        rest.find(|c: char| !(c.is_ascii_digit() || matches!(c, '.' | 'e' | 'E' | '-' | '+'))).unwrap_or(rest.len());
    rest[..end].parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0)
}

fn page_meta(d: &mut Decoder<BufReader<std::fs::File>>) -> PageMeta {
    let description = d.get_tag_ascii_string(Tag::ImageDescription).unwrap_or_default();
    let mut spacing = [None; 3];
    let (mut channels, mut frames) = (1, 1);
    let count = |key: &str| number_after(&description, key).map_or(1, |n| n as u64);
    if description.contains("<OME") {
        (channels, frames) = (count("SizeC"), count("SizeT"));
        spacing = [
            number_after(&description, "PhysicalSizeX"),
            number_after(&description, "PhysicalSizeY"),
            number_after(&description, "PhysicalSizeZ"),
        ];
    } else if description.starts_with("ImageJ") {
        (channels, frames) = (count("channels"), count("frames"));
        // X and Y resolution are pixels per unit
        let per_unit = |t: Tag, d: &mut Decoder<BufReader<std::fs::File>>| tag_f64_pair(d, t).map(|r| 1.0 / r);
        spacing = [per_unit(Tag::XResolution, d), per_unit(Tag::YResolution, d), number_after(&description, "spacing")];
    }
    PageMeta { spacing, channels, frames }
}

/// Refuses a stack of several channels or time points, which would read
/// as z-slices with the axes mixed.
fn check_one_channel_and_time(path: &Path, meta: &PageMeta) -> Result<()> {
    if meta.channels <= 1 && meta.frames <= 1 {
        return Ok(());
    }
    Err(VolumeError::header(
        path,
        format!(
            "a hyperstack of {} channel(s) and {} time point(s): mdtf reads one channel at one time point, as z-slices \
             (save one, e.g. Fiji's Image > Duplicate with one channel and one frame, or give each channel as its \
             own file to mdtf derive)",
            meta.channels, meta.frames
        ),
    ))
}

/// Checks the first directory's value counts against the file length before
/// the decoder (whose limits apply only from the second page on) reads it.
fn check_first_directory(path: &Path, len: u64) -> Result<()> {
    use std::io::{Read, Seek, SeekFrom};
    let mut f = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    let mut head = [0u8; 16];
    let got = f.read(&mut head).map_err(|e| VolumeError::io(path, e))?;
    if got < 8 {
        return Ok(()); // the decoder names the problem
    }
    let le = &head[..2] == b"II";
    let u16_at = |b: &[u8]| if le { u16::from_le_bytes([b[0], b[1]]) } else { u16::from_be_bytes([b[0], b[1]]) };
    let u32_at = |b: &[u8]| {
        let a = [b[0], b[1], b[2], b[3]];
        if le { u32::from_le_bytes(a) } else { u32::from_be_bytes(a) }
    };
    let u64_at = |b: &[u8]| {
        let a = [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
        if le { u64::from_le_bytes(a) } else { u64::from_be_bytes(a) }
    };
    let big = u16_at(&head[2..4]) == 43;
    let (ifd, count_len, entry_len) =
        if big { (u64_at(&head[8..16]), 8u64, 20u64) } else { (u32_at(&head[4..8]) as u64, 2, 12) };
    if ifd >= len || f.seek(SeekFrom::Start(ifd)).is_err() {
        return Ok(());
    }
    let mut n = [0u8; 8];
    if f.read_exact(&mut n[..count_len as usize]).is_err() {
        return Ok(());
    }
    let entries = if big { u64_at(&n) } else { u16_at(&n) as u64 };
    if entries.saturating_mul(entry_len) > len {
        return Err(VolumeError::header(
            path,
            format!("the first directory claims {entries} entries, more than the file's {len} bytes hold (truncated?)"),
        ));
    }
    let mut e = vec![0u8; (entries * entry_len) as usize];
    if f.read_exact(&mut e).is_err() {
        return Ok(());
    }
    for entry in e.chunks_exact(entry_len as usize) {
        let ty = u16_at(&entry[2..4]);
        let count = if big { u64_at(&entry[4..12]) } else { u32_at(&entry[4..8]) as u64 };
        let size: u64 = match ty {
            1 | 2 | 6 | 7 => 1,
            3 | 8 => 2,
            4 | 9 | 11 | 13 => 4,
            _ => 8,
        };
        if count.saturating_mul(size) > len {
            return Err(VolumeError::header(
                path,
                format!("tag {} claims {count} values, more than the file's {len} bytes hold", u16_at(&entry[..2])),
            ));
        }
    }
    Ok(())
}

fn tiff_error(path: &Path, e: tiff::TiffError) -> VolumeError {
    match e {
        tiff::TiffError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            VolumeError::header(path, "the file ends inside its pages (truncated?)")
        }
        e => VolumeError::header(path, format!("cannot decode the TIFF: {e}")),
    }
}

/// Appends one decoded page to `out` as f32; returns the stored type
/// (64-bit integers are reported as f64: both exceed f32's precision).
fn append_page(page: DecodingResult, out: &mut Vec<f32>) -> SampleType {
    macro_rules! widen {
        ($v:expr, $ty:expr) => {{
            out.extend($v.iter().map(|&x| x as f32));
            $ty
        }};
    }
    match page {
        DecodingResult::U8(v) => widen!(v, SampleType::U8),
        DecodingResult::I8(v) => widen!(v, SampleType::I8),
        DecodingResult::U16(v) => widen!(v, SampleType::U16),
        DecodingResult::I16(v) => widen!(v, SampleType::I16),
        DecodingResult::U32(v) => widen!(v, SampleType::U32),
        DecodingResult::I32(v) => widen!(v, SampleType::I32),
        DecodingResult::F32(v) => widen!(v, SampleType::F32),
        DecodingResult::F64(v) => widen!(v, SampleType::F64),
        DecodingResult::U64(v) => widen!(v, SampleType::F64),
        DecodingResult::I64(v) => widen!(v, SampleType::F64),
        DecodingResult::F16(v) => {
            out.extend(v.iter().map(|x| x.to_f32()));
            SampleType::F32
        }
    }
}

/// Reads every page of one TIFF file into `out`; returns (width, height, pages, type, meta of page 1).
fn read_pages(
    path: &Path,
    out: &mut Vec<f32>,
    expect: Option<(u32, u32)>,
) -> Result<(u32, u32, usize, SampleType, PageMeta)> {
    let file = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    if file.metadata().map_err(|e| VolumeError::io(path, e))?.len() == 0 {
        return Err(VolumeError::Empty { path: path.to_path_buf() });
    }
    // a page may decode to at most what its file could hold compressed (deflate
    // expands at most ~1032x), so a small file cannot claim a huge page
    let len = file.metadata().map_err(|e| VolumeError::io(path, e))?.len() as usize;
    let mut limits = tiff::decoder::Limits::default();
    limits.decoding_buffer_size = len.saturating_mul(1100).clamp(1 << 20, 1 << 31);
    limits.intermediate_buffer_size = limits.decoding_buffer_size;
    // a tag's values are in the file: no more bytes than it has
    limits.ifd_value_size = len.clamp(4096, 64 << 20);
    check_first_directory(path, len as u64)?;
    let mut d = Decoder::new(BufReader::new(file)).map_err(|e| tiff_error(path, e))?.with_limits(limits);
    let meta = page_meta(&mut d);
    check_one_channel_and_time(path, &meta)?;
    let mut pages = 0usize;
    let mut first = None;
    let mut ty: Option<SampleType> = None;
    loop {
        let (w, h) = d.dimensions().map_err(|e| tiff_error(path, e))?;
        let bits = match d.colortype().map_err(|e| tiff_error(path, e))? {
            ColorType::Gray(bits) => bits as u64,
            other => {
                // tifffile.imwrite stores an array of 3 or 4 planes as one colour image unless told otherwise
                let planes = matches!(other, ColorType::RGB(_) | ColorType::RGBA(_))
                    && d.find_tag_unsigned::<u16>(Tag::PlanarConfiguration).ok().flatten() == Some(2);
                let hint = if planes {
                    "; its colour samples are stored as separate planes, as tifffile.imwrite stores a stack of 3 or \
                     4 slices unless given photometric='minisblack'"
                } else {
                    ""
                };
                return Err(VolumeError::header(
                    path,
                    format!(
                        "page {} is {other:?}, not grayscale: a volume needs one sample per pixel{hint}",
                        pages + 1
                    ),
                ));
            }
        };
        // a page cannot hold more samples than its file could encode
        let compressed = d.find_tag_unsigned::<u16>(Tag::Compression).ok().flatten().is_some_and(|c| c != 1);
        let page_bytes = w as u64 * h as u64 * bits.max(1) / 8;
        let room = if compressed { len as u64 * 1100 } else { len as u64 };
        if page_bytes > room {
            return Err(VolumeError::header(
                path,
                format!(
                    "page {} claims {w}x{h} samples of {bits} bits, more than the file's {len} bytes hold (truncated?)",
                    pages + 1
                ),
            ));
        }
        let want = expect.or(first).unwrap_or((w, h));
        if (w, h) != want {
            return Err(VolumeError::header(
                path,
                format!("page {} is {w}x{h}, the stack's slices are {}x{}", pages + 1, want.0, want.1),
            ));
        }
        first.get_or_insert((w, h));
        let page = d.read_image().map_err(|e| tiff_error(path, e))?;
        let samples = w as usize * h as usize;
        out.try_reserve(samples).map_err(|_| VolumeError::header(path, "the stack does not fit in memory"))?;
        let before = out.len();
        let page_ty = append_page(page, out);
        if out.len() - before != samples {
            return Err(VolumeError::header(
                path,
                format!("page {} decodes to the wrong number of samples", pages + 1),
            ));
        }
        if ty.is_some_and(|t| t != page_ty) {
            return Err(VolumeError::header(
                path,
                format!("page {} holds {} samples, page 1 another type", pages + 1, page_ty.name()),
            ));
        }
        ty = Some(page_ty);
        pages += 1;
        if !d.more_images() {
            break;
        }
        d.next_image().map_err(|e| tiff_error(path, e))?;
    }
    let (w, h) = first.unwrap_or((0, 0));
    Ok((w, h, pages, ty.unwrap_or(SampleType::U8), meta))
}

/// Reads a multi-page TIFF, or a folder of TIFF slices, as one volume.
/// Warnings (spacing not recorded) are in the returned [`FileInfo`].
pub fn read_tiff_with_info(path: &Path, opts: &ReadOptions) -> Result<(MultiField, FileInfo)> {
    let mut samples = Vec::new();
    let (w, h, pages, ty, meta) = if path.is_dir() {
        let files = folder_slices(path)?;
        let mut first: Option<(u32, u32, SampleType, PageMeta)> = None;
        for f in &files {
            let expect = first.as_ref().map(|(w, h, _, _)| (*w, *h));
            let (w, h, n, ty, meta) = read_pages(f, &mut samples, expect)?;
            if n != 1 {
                return Err(VolumeError::header(f, format!("{n} pages: a folder of slices needs one page per file")));
            }
            if let Some((_, _, t, _)) = &first
                && *t != ty
            {
                return Err(VolumeError::header(
                    f,
                    format!("{} samples, the other slices are {}", ty.name(), t.name()),
                ));
            }
            first.get_or_insert((w, h, ty, meta));
        }
        let (w, h, ty, meta) = first.ok_or_else(|| VolumeError::header(path, "no slices"))?;
        (w, h, files.len(), ty, meta)
    } else {
        read_pages(path, &mut samples, None)?
    };
    let dims = [w as usize, h as usize, pages];
    let mut warnings = Vec::new();
    if meta.spacing.iter().any(Option::is_none) {
        warnings.push(format!(
            "{}: no ImageJ or OME spacing for axis {}: using 1",
            path.display(),
            (0..3).filter(|&a| meta.spacing[a].is_none()).map(|a| ["x", "y", "z"][a]).collect::<Vec<_>>().join(", ")
        ));
    }
    let spacing = meta.spacing.map(|s| s.unwrap_or(1.0));
    crate::samples::apply_nan_policy(path, opts.nan, &mut samples)?;
    let data = ndarray::Array3::from_shape_vec((dims[2], dims[1], dims[0]), samples)
        .map_err(|e| VolumeError::header(path, format!("the pages do not form a volume: {e}")))?;
    let geometry = Geometry::new(dims, spacing);
    let format = if path.is_dir() { "TIFF slices (folder)" } else { "TIFF stack" };
    let info = FileInfo {
        format: format.into(),
        sample_type: ty,
        endian: Endian::Little,
        compressed: false,
        scale: None,
        warnings,
        details: Vec::new(),
        units: crate::Units::default(),
        padding: None,
    };
    Ok((MultiField::new(geometry, vec![Field { name: "value".into(), data }])?, info))
}
