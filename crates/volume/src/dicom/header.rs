//! What one DICOM file says about its image, read without its pixel data.
//!
//! Only the attributes that place and scale an image are read. Patient
//! attributes (name, ID, birth date) are never read, so no message or report
//! can print them.

use super::mosaic::{Mosaic, csa_values};
use crate::error::{Result, VolumeError};
use dicom_core::{Tag, VR};
use dicom_dictionary_std::tags;
use dicom_object::mem::InMemDicomObject;
use dicom_object::{DefaultDicomObject, OpenFileOptions};
use dicom_transfer_syntax_registry::TransferSyntaxIndex;
use std::path::{Path, PathBuf};

/// The placement and scaling of one frame (a single-frame file has one).
#[derive(Debug, Clone, PartialEq)]
pub struct FramePlane {
    /// ImagePositionPatient: world position (LPS, mm) of the first pixel's centre.
    pub position: Option<[f64; 3]>,
    /// ImageOrientationPatient: row direction then column direction (LPS unit vectors).
    pub orientation: Option<[f64; 6]>,
    /// PixelSpacing: (between rows, between columns), mm.
    pub pixel_spacing: Option<[f64; 2]>,
    /// RescaleSlope and RescaleIntercept (1, 0 when absent).
    pub rescale: (f64, f64),
}

/// The header of one DICOM image file.
#[derive(Debug, Clone)]
pub struct ImageHeader {
    /// The file.
    pub path: PathBuf,
    /// SeriesInstanceUID (empty when missing).
    pub series_uid: String,
    /// SeriesNumber.
    pub series_number: Option<i64>,
    /// SeriesDescription (may be empty).
    pub description: String,
    /// Modality, e.g. "CT" or "MR".
    pub modality: String,
    /// Rescale Type (0028,1054), e.g. "HU" (empty when absent).
    pub rescale_type: String,
    /// Pixel Padding Value (0028,0120) and Pixel Padding Range Limit
    /// (0028,0121), stored values (before rescaling), read with the pixels' sign.
    pub padding: Option<(i64, Option<i64>)>,
    /// SOPInstanceUID: tells a copied file from another image at the same place.
    pub instance_uid: String,
    /// Transfer syntax UID of the file.
    pub transfer_syntax: String,
    /// Rows (pixels along y).
    pub rows: u32,
    /// Columns (pixels along x).
    pub cols: u32,
    /// BitsAllocated: 8, 16 or 32.
    pub bits_allocated: u16,
    /// BitsStored.
    pub bits_stored: u16,
    /// HighBit.
    pub high_bit: u16,
    /// PixelRepresentation 1: two's complement samples.
    pub signed: bool,
    /// SamplesPerPixel (1 for the grayscale images mdtf reads).
    pub samples_per_pixel: u16,
    /// PhotometricInterpretation, e.g. "MONOCHROME2" ("PALETTE COLOR" is colour in one sample).
    pub photometric: String,
    /// SliceThickness, mm.
    pub slice_thickness: Option<f64>,
    /// SpacingBetweenSlices, mm.
    pub spacing_between_slices: Option<f64>,
    /// One entry per frame.
    pub frames: Vec<FramePlane>,
    /// Whether ImageType says MOSAIC (Siemens: several slices tiled in one frame).
    pub is_mosaic: bool,
    /// The tiling of a MOSAIC frame, when its CSA header gives the slice count.
    pub mosaic: Option<Mosaic>,
}

impl ImageHeader {
    /// Bytes of one stored sample.
    pub fn sample_bytes(&self) -> usize {
        usize::from(self.bits_allocated / 8)
    }

    /// Bytes of pixel data `frames` frames hold: 1-bit samples are packed
    /// across frames (PS3.5 8.1.1), the others a whole number of bytes each.
    pub fn pixel_bytes(&self, frames: usize) -> u64 {
        let samples = self.rows as u64 * self.cols as u64 * frames as u64;
        if self.bits_allocated == 1 { samples.div_ceil(8) } else { samples * self.sample_bytes() as u64 }
    }

    /// Columns and rows of one slice: a mosaic's tile, else the image.
    pub fn slice_dims(&self) -> (usize, usize) {
        match &self.mosaic {
            Some(m) => (m.tile_cols, m.tile_rows),
            None => (self.cols as usize, self.rows as usize),
        }
    }

    /// The transfer syntax's name, as the registry knows it.
    pub fn transfer_syntax_name(&self) -> String {
        transfer_syntax_name(&self.transfer_syntax)
    }
}

/// A transfer syntax UID with its name, e.g. "JPEG 2000 (Lossless Only) (1.2.840.10008.1.2.4.90)".
pub fn transfer_syntax_name(uid: &str) -> String {
    let name = dicom_transfer_syntax_registry::TransferSyntaxRegistry.get(uid).map(|ts| ts.name().to_string());
    match name {
        Some(n) => format!("{n} ({uid})"),
        None => format!("unknown transfer syntax {uid}"),
    }
}

/// Whether the file starts like DICOM: "DICM" after the 128-byte preamble.
pub fn has_dicom_magic(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 132];
    std::fs::File::open(path).and_then(|mut f| f.read_exact(&mut head)).is_ok() && &head[128..132] == b"DICM"
}

/// Opens a DICOM file, reading up to its pixel data when `header_only`.
pub fn open(path: &Path, header_only: bool) -> Result<DefaultDicomObject> {
    let opts = OpenFileOptions::new();
    let opts = if header_only { opts.read_until(tags::PIXEL_DATA) } else { opts };
    opts.open_file(path).map_err(|e| VolumeError::header(path, format!("not a readable DICOM file: {e}")))
}

fn text(obj: &InMemDicomObject, tag: Tag) -> Option<String> {
    let e = obj.element_opt(tag).ok()??;
    let s = if e.vr() == VR::UN {
        String::from_utf8_lossy(&e.to_bytes().ok()?).into_owned()
    } else {
        e.to_str().ok()?.into_owned()
    };
    let s = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
    (!s.is_empty()).then(|| s.to_string())
}

fn floats(obj: &InMemDicomObject, tag: Tag) -> Option<Vec<f64>> {
    let e = obj.element_opt(tag).ok()??;
    // some converters store decimal strings with VR UN: their bytes are still the text
    let v = if e.vr() == VR::UN {
        text(obj, tag)?.split('\\').map(|p| p.trim().parse::<f64>().ok()).collect::<Option<Vec<f64>>>()?
    } else {
        e.to_multi_float64().ok()?
    };
    v.iter().all(|x| x.is_finite()).then_some(v)
}

fn float(obj: &InMemDicomObject, tag: Tag) -> Option<f64> {
    floats(obj, tag)?.first().copied()
}

fn uint(obj: &InMemDicomObject, tag: Tag) -> Option<u32> {
    obj.element_opt(tag).ok()??.to_int::<u32>().ok()
}

fn int(obj: &InMemDicomObject, tag: Tag) -> Option<i64> {
    let e = obj.element_opt(tag).ok()??;
    if e.vr() == VR::UN { text(obj, tag)?.parse().ok() } else { e.to_int::<i64>().ok() }
}

/// The first item of sequence `seq` inside `obj`.
fn first_item(obj: &InMemDicomObject, seq: Tag) -> Option<&InMemDicomObject> {
    obj.element_opt(seq).ok()??.items()?.first()
}

/// An attribute of an enhanced multi-frame image: the frame's own functional
/// group first, then the shared one (PS3.3 C.7.6.16).
fn functional<'a>(
    shared: Option<&'a InMemDicomObject>,
    per_frame: Option<&'a InMemDicomObject>,
    macro_seq: Tag,
) -> Option<&'a InMemDicomObject> {
    per_frame.and_then(|f| first_item(f, macro_seq)).or_else(|| shared.and_then(|s| first_item(s, macro_seq)))
}

fn array<const N: usize>(v: Option<Vec<f64>>) -> Option<[f64; N]> {
    v.and_then(|v| v.get(..N).and_then(|s| <[f64; N]>::try_from(s).ok()))
}

/// Reads the header of `path`. Returns `Ok(None)` for a DICOM file that holds
/// no image (a DICOMDIR, a structured report, a presentation state).
pub fn read_header(path: &Path) -> Result<Option<ImageHeader>> {
    if std::fs::metadata(path).is_ok_and(|m| m.len() == 0) {
        return Err(VolumeError::Empty { path: path.to_path_buf() });
    }
    super::bounds::check_declared_lengths(path)?;
    let obj = open(path, true)?;
    let transfer_syntax = obj.meta().transfer_syntax().trim_end_matches('\0').to_string();
    let Some(rows) = uint(&obj, tags::ROWS) else { return Ok(None) };
    let bad = |m: String| VolumeError::header(path, m);
    let cols = uint(&obj, tags::COLUMNS).ok_or_else(|| bad("Rows is present but Columns is missing".into()))?;
    let bits_allocated = uint(&obj, tags::BITS_ALLOCATED).unwrap_or(16) as u16;
    if !matches!(bits_allocated, 1 | 8 | 16 | 32) {
        return Err(bad(format!("BitsAllocated {bits_allocated} is not 1, 8, 16 or 32")));
    }
    let bits_stored = uint(&obj, tags::BITS_STORED).map_or(bits_allocated, |b| b as u16);
    let high_bit = uint(&obj, tags::HIGH_BIT).map_or(bits_stored.saturating_sub(1), |b| b as u16);
    if bits_stored == 0 || bits_stored > bits_allocated || high_bit >= bits_allocated || high_bit + 1 < bits_stored {
        return Err(bad(format!(
            "BitsStored {bits_stored} / HighBit {high_bit} do not fit in BitsAllocated {bits_allocated}"
        )));
    }
    if rows == 0 || cols == 0 {
        return Err(bad(format!("the image is {cols} x {rows} pixels")));
    }
    let frame_count = match (int(&obj, tags::NUMBER_OF_FRAMES), obj.element_opt(tags::NUMBER_OF_FRAMES).ok().flatten())
    {
        (Some(n), _) => n,
        (None, None) => 1,
        (None, Some(_)) => {
            let said = text(&obj, tags::NUMBER_OF_FRAMES).unwrap_or_default();
            return Err(bad(format!("NumberOfFrames (0028,0008) reads '{said}', not a whole number")));
        }
    };
    if !(1..=1 << 20).contains(&frame_count) {
        return Err(bad(format!("NumberOfFrames {frame_count} is not a positive count")));
    }
    let shared = first_item(&obj, tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE);
    let per_frame: Vec<&InMemDicomObject> = obj
        .element_opt(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .ok()
        .flatten()
        .and_then(|e| e.items())
        .map(|items| items.iter().collect())
        .unwrap_or_default();
    // RT Dose scales its samples by DoseGridScaling instead of a rescale
    let slope = float(&obj, tags::RESCALE_SLOPE).or_else(|| float(&obj, tags::DOSE_GRID_SCALING)).unwrap_or(1.0);
    let top_rescale = (slope, float(&obj, tags::RESCALE_INTERCEPT).unwrap_or(0.0));
    let top = FramePlane {
        position: array(floats(&obj, tags::IMAGE_POSITION_PATIENT)),
        orientation: array(floats(&obj, tags::IMAGE_ORIENTATION_PATIENT)),
        pixel_spacing: array(floats(&obj, tags::PIXEL_SPACING)),
        rescale: top_rescale,
    };
    // RT Dose (and some NM) place their frames by offsets along the normal
    let grid_offsets = floats(&obj, tags::GRID_FRAME_OFFSET_VECTOR).filter(|g| g.len() == frame_count as usize);
    let frames = (0..frame_count as usize)
        .map(|f| {
            if shared.is_none() && per_frame.is_empty() {
                let mut plane = top.clone();
                if let (Some(g), Some(p), Some(o)) = (&grid_offsets, top.position, top.orientation) {
                    let n = super::series::cross([o[0], o[1], o[2]], [o[3], o[4], o[5]]);
                    plane.position = Some([p[0] + g[f] * n[0], p[1] + g[f] * n[1], p[2] + g[f] * n[2]]);
                }
                return plane;
            }
            let own = per_frame.get(f).copied();
            let pos = functional(shared, own, tags::PLANE_POSITION_SEQUENCE);
            let ori = functional(shared, own, tags::PLANE_ORIENTATION_SEQUENCE);
            let px = functional(shared, own, tags::PIXEL_MEASURES_SEQUENCE);
            let scale = functional(shared, own, tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE);
            FramePlane {
                position: pos.and_then(|o| array(floats(o, tags::IMAGE_POSITION_PATIENT))).or(top.position),
                orientation: ori.and_then(|o| array(floats(o, tags::IMAGE_ORIENTATION_PATIENT))).or(top.orientation),
                pixel_spacing: px.and_then(|o| array(floats(o, tags::PIXEL_SPACING))).or(top.pixel_spacing),
                rescale: scale
                    .map(|o| {
                        (float(o, tags::RESCALE_SLOPE).unwrap_or(1.0), float(o, tags::RESCALE_INTERCEPT).unwrap_or(0.0))
                    })
                    .unwrap_or(top_rescale),
            }
        })
        .collect();
    let thickness = float(&obj, tags::SLICE_THICKNESS).or_else(|| {
        shared.and_then(|s| first_item(s, tags::PIXEL_MEASURES_SEQUENCE)).and_then(|o| float(o, tags::SLICE_THICKNESS))
    });
    let image_type =
        obj.element_opt(tags::IMAGE_TYPE).ok().flatten().and_then(|e| e.to_multi_str().ok().map(|v| v.to_vec()));
    let is_mosaic = image_type.is_some_and(|t| t.iter().any(|s| s.trim() == "MOSAIC"));
    let mosaic = if is_mosaic && frame_count == 1 { siemens_mosaic(&obj, cols, rows) } else { None };
    Ok(Some(ImageHeader {
        path: path.to_path_buf(),
        series_uid: text(&obj, tags::SERIES_INSTANCE_UID).unwrap_or_default(),
        series_number: int(&obj, tags::SERIES_NUMBER),
        description: text(&obj, tags::SERIES_DESCRIPTION).unwrap_or_default(),
        modality: text(&obj, tags::MODALITY).unwrap_or_default(),
        rescale_type: text(&obj, tags::RESCALE_TYPE).unwrap_or_default(),
        padding: {
            // US or SS as the pixels are: an implicit-VR file gives US, so a signed one is wrapped back
            let signed = uint(&obj, tags::PIXEL_REPRESENTATION) == Some(1);
            let bits = uint(&obj, tags::BITS_ALLOCATED).unwrap_or(16).min(63);
            let stored = |v: i64| if signed && v >= 1 << (bits - 1) && v < 1 << bits { v - (1 << bits) } else { v };
            let value = int(&obj, tags::PIXEL_PADDING_VALUE).map(stored);
            value.map(|v| (v, int(&obj, tags::PIXEL_PADDING_RANGE_LIMIT).map(stored)))
        },
        instance_uid: text(&obj, tags::SOP_INSTANCE_UID).unwrap_or_default(),
        transfer_syntax,
        rows,
        cols,
        bits_allocated,
        bits_stored,
        high_bit,
        signed: uint(&obj, tags::PIXEL_REPRESENTATION) == Some(1),
        samples_per_pixel: uint(&obj, tags::SAMPLES_PER_PIXEL).unwrap_or(1) as u16,
        photometric: text(&obj, tags::PHOTOMETRIC_INTERPRETATION).unwrap_or_default(),
        slice_thickness: thickness.filter(|t| *t > 0.0),
        spacing_between_slices: float(&obj, tags::SPACING_BETWEEN_SLICES).filter(|t| *t > 0.0),
        frames,
        is_mosaic,
        mosaic,
    }))
}

/// The tiling of a Siemens MOSAIC from its CSA image header (0029,1010).
fn siemens_mosaic(obj: &InMemDicomObject, cols: u32, rows: u32) -> Option<Mosaic> {
    let csa = obj.element_opt(Tag(0x0029, 0x1010)).ok()??.to_bytes().ok()?;
    let found = csa_values(&csa, &["NumberOfImagesInMosaic", "SliceNormalVector"]);
    let count: usize = found[0].as_ref()?.first()?.parse().ok()?;
    let normal = found[1].as_ref().and_then(|v| {
        let n: Vec<f64> = v.iter().filter_map(|x| x.parse().ok()).collect();
        <[f64; 3]>::try_from(n.as_slice()).ok()
    });
    Mosaic::new(cols as usize, rows as usize, count, normal)
}

/// Refuses what the decoders cannot read, naming the transfer syntax and a way out.
pub fn check_decodable(h: &ImageHeader) -> Result<()> {
    let known = dicom_transfer_syntax_registry::TransferSyntaxRegistry.get(&h.transfer_syntax);
    match known {
        Some(ts) if ts.can_decode_all() => {}
        _ => {
            return Err(VolumeError::header(
                &h.path,
                format!(
                    "mdtf cannot decode pixel data stored as {}; convert it to an uncompressed syntax first, e.g. `gdcmconv --raw IN OUT`",
                    h.transfer_syntax_name()
                ),
            ));
        }
    }
    if h.photometric.trim() == "PALETTE COLOR" {
        return Err(VolumeError::header(
            &h.path,
            "the image is PALETTE COLOR: its samples index a colour table, they are not intensities; \
             mdtf reads grayscale DICOM (CT, MR, PET, microscopy) only",
        ));
    }
    if h.samples_per_pixel != 1 {
        return Err(VolumeError::header(
            &h.path,
            format!(
                "the image has {} samples per pixel (colour); mdtf reads grayscale DICOM (CT, MR, PET, microscopy) only",
                h.samples_per_pixel
            ),
        ));
    }
    Ok(())
}
