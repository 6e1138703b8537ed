//! From image headers to one volume: grouping by series, choosing one,
//! ordering its slices along the slice normal, checking the grid they form,
//! and the geometry (LPS to mdtf's RAS).

use super::header::ImageHeader;
use crate::error::{Result, VolumeError};
use crate::geometry::Geometry;
use std::collections::BTreeMap;
use std::path::Path;

/// Slices closer than this along the normal are at the same position, mm.
const SAME_POSITION_MM: f64 = 1e-3;
/// Gaps within this fraction of the typical gap count as equal.
const GAP_TOLERANCE: f64 = 0.01;
/// In-plane drift of the slice positions, as a fraction of a pixel, above
/// which the stack is tilted (gantry tilt) rather than rounded.
const TILT_PIXELS: f64 = 0.05;
/// Directions closer than this (per component) are the same orientation.
const SAME_ORIENTATION: f64 = 1e-4;

/// One series found in the input.
#[derive(Debug, Clone)]
pub struct SeriesSummary {
    /// SeriesInstanceUID.
    pub uid: String,
    /// SeriesNumber.
    pub number: Option<i64>,
    /// SeriesDescription.
    pub description: String,
    /// Modality.
    pub modality: String,
    /// Columns x rows of its first image.
    pub size: [u32; 2],
    /// Frames in all its files.
    pub images: usize,
}

impl SeriesSummary {
    pub(super) fn of(files: &[ImageHeader]) -> SeriesSummary {
        let h = &files[0];
        SeriesSummary {
            uid: h.series_uid.clone(),
            number: h.series_number,
            description: h.description.clone(),
            modality: h.modality.clone(),
            size: [h.cols, h.rows],
            images: files.iter().map(|f| f.frames.len()).sum(),
        }
    }

    /// One line for a listing: number, description, modality, size, UID.
    pub fn line(&self) -> String {
        let number = self.number.map_or("-".to_string(), |n| n.to_string());
        let desc = if self.description.is_empty() {
            "(no description)".to_string()
        } else {
            format!("\"{}\"", self.description)
        };
        format!(
            "series {number}: {desc}, {}, {}x{} pixels, {} image{}, UID {}",
            if self.modality.is_empty() { "?" } else { &self.modality },
            self.size[0],
            self.size[1],
            self.images,
            if self.images == 1 { "" } else { "s" },
            if self.uid.is_empty() { "(none)" } else { &self.uid }
        )
    }
}

/// Groups headers by SeriesInstanceUID, ordered by series number then UID.
pub fn group(headers: Vec<ImageHeader>) -> Vec<Vec<ImageHeader>> {
    let mut by_uid: BTreeMap<String, Vec<ImageHeader>> = BTreeMap::new();
    for h in headers {
        by_uid.entry(h.series_uid.clone()).or_default().push(h);
    }
    let mut groups: Vec<Vec<ImageHeader>> = by_uid.into_values().collect();
    groups.sort_by(|a, b| (a[0].series_number, &a[0].series_uid).cmp(&(b[0].series_number, &b[0].series_uid)));
    groups
}

/// The series `choice` names (a SeriesNumber or a SeriesInstanceUID), or the
/// only one; several without a choice is an error that lists them.
pub fn choose(input: &Path, groups: Vec<Vec<ImageHeader>>, choice: Option<&str>) -> Result<Vec<ImageHeader>> {
    let listing = |groups: &[Vec<ImageHeader>]| -> String {
        groups.iter().map(|g| format!("\n  {}", SeriesSummary::of(g).line())).collect::<String>()
    };
    let Some(choice) = choice.map(str::trim) else {
        if groups.len() == 1 {
            return Ok(groups.into_iter().next().unwrap_or_default());
        }
        return Err(VolumeError::header(
            input,
            format!(
                "the input holds {} DICOM series; choose one by its number or UID (--series on the command line, `series` in a pipeline's [input]):{}",
                groups.len(),
                listing(&groups)
            ),
        ));
    };
    let by_uid: Vec<usize> = (0..groups.len()).filter(|&i| groups[i][0].series_uid == choice).collect();
    let by_number: Vec<usize> = match choice.parse::<i64>() {
        Ok(n) => (0..groups.len()).filter(|&i| groups[i][0].series_number == Some(n)).collect(),
        Err(_) => Vec::new(),
    };
    let hits = if by_uid.is_empty() { by_number } else { by_uid };
    match hits.as_slice() {
        [i] => Ok(groups.into_iter().nth(*i).unwrap_or_default()),
        [] => Err(VolumeError::header(
            input,
            format!("no DICOM series has the number or UID '{choice}'; the input holds:{}", listing(&groups)),
        )),
        _ => Err(VolumeError::header(
            input,
            format!("{} series have the number {choice}; choose one by its UID:{}", hits.len(), listing(&groups)),
        )),
    }
}

/// One image of the volume: which file and frame, where it lies, how it scales.
#[derive(Debug, Clone, Copy)]
pub struct SliceRef {
    /// Index into the series' headers.
    pub file: usize,
    /// Frame within that file.
    pub frame: usize,
    /// ImagePositionPatient (LPS, mm).
    pub position: [f64; 3],
    /// Distance along the slice normal, mm.
    pub along: f64,
    /// (slope, intercept).
    pub rescale: (f64, f64),
}

/// The regular grid an irregular or tilted stack is interpolated onto.
#[derive(Debug, Clone)]
pub struct Resampling {
    /// Output slices.
    pub nz: usize,
    /// Output slice spacing along the normal, mm.
    pub spacing: f64,
    /// In-plane offset of each input slice from the first, in pixels (x, y).
    pub offsets: Vec<[f64; 2]>,
}

/// How the sorted slices become a volume.
#[derive(Debug, Clone)]
pub struct Layout {
    /// The input slices in order along the normal.
    pub slices: Vec<SliceRef>,
    /// Geometry of the volume read (RAS).
    pub geometry: Geometry,
    /// Present when the slices must be interpolated onto `geometry`.
    pub resampling: Option<Resampling>,
    /// What was assumed or repaired, for the run report.
    pub warnings: Vec<String>,
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The cross product a x b (the slice normal of a row and a column direction).
pub(super) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn unit(a: [f64; 3]) -> Option<[f64; 3]> {
    let n = dot(a, a).sqrt();
    (n > 1e-6 && n.is_finite()).then(|| [a[0] / n, a[1] / n, a[2] / n])
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// LPS (DICOM) to RAS (mdtf): x and y change sign (a zero stays +0).
fn ras(v: [f64; 3]) -> [f64; 3] {
    [0.0 - v[0], 0.0 - v[1], v[2]]
}

/// A length in mm for messages: two decimals at most, at least one ("5.0", "1.25").
pub fn mm(v: f64) -> String {
    let s = format!("{v:.2}");
    let s = s.trim_end_matches('0');
    if s.ends_with('.') { format!("{s}0") } else { s.to_string() }
}

/// "2.5 mm x40, 1.25 mm, 5.0 mm x20": the gaps grouped by value, commonest first.
fn describe_gaps(gaps: &[f64]) -> (String, f64) {
    let mut groups: Vec<(f64, usize)> = Vec::new();
    for &g in gaps {
        match groups.iter_mut().find(|(v, _)| (g - *v).abs() <= GAP_TOLERANCE * v.abs().max(g.abs())) {
            Some(e) => e.1 += 1,
            None => groups.push((g, 1)),
        }
    }
    groups.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.total_cmp(&b.0)));
    let text = groups
        .iter()
        .map(|(v, n)| if *n > 1 { format!("{} mm x{n}", mm(*v)) } else { format!("{} mm", mm(*v)) })
        .collect::<Vec<_>>()
        .join(", ");
    (text, groups[0].0)
}

/// The slices of a Siemens MOSAIC: tile k lies k slice gaps along the
/// normal from the first tile, whose corner is half the mosaic-minus-tile
/// size in from ImagePositionPatient.
fn mosaic_layout(
    h: &ImageHeader,
    m: &super::mosaic::Mosaic,
    frame: SliceRef,
    row: [f64; 3],
    col: [f64; 3],
    pixel: [f64; 2],
    mut warnings: Vec<String>,
) -> Layout {
    // a normal layout of the format, not a repair: `mdtf info` shows it, no warning
    let mut normal = cross(row, col);
    if m.normal.is_some_and(|n| dot(n, normal) < 0.0) {
        normal = [-normal[0], -normal[1], -normal[2]];
    }
    let gap = match (h.spacing_between_slices, h.slice_thickness) {
        (Some(s), _) | (None, Some(s)) => s,
        (None, None) => {
            warnings.push("a MOSAIC without SpacingBetweenSlices or SliceThickness: 1 mm assumed along z".into());
            1.0
        }
    };
    let dx = (h.cols as usize - m.tile_cols) as f64 / 2.0 * pixel[1];
    let dy = (h.rows as usize - m.tile_rows) as f64 / 2.0 * pixel[0];
    let first: [f64; 3] = std::array::from_fn(|a| frame.position[a] + dx * row[a] + dy * col[a]);
    let slices = (0..m.count)
        .map(|k| {
            let position = std::array::from_fn(|a| first[a] + k as f64 * gap * normal[a]);
            SliceRef { frame: k, position, along: dot(position, normal), ..frame }
        })
        .collect();
    let geometry = Geometry {
        dims: [m.tile_cols, m.tile_rows, m.count],
        spacing: [pixel[1], pixel[0], gap],
        origin: ras(first),
        directions: [ras(row), ras(col), ras(normal)],
    };
    Layout { slices, geometry, resampling: None, warnings }
}

/// Orders the frames of `files` along the slice normal and checks that they
/// form a regular grid (or plans the interpolation onto one when `resample`).
pub fn layout(input: &Path, files: &[ImageHeader], resample: bool) -> Result<Layout> {
    let Some(first) = files.first() else { return Err(VolumeError::header(input, "the series holds no image")) };
    let mut warnings = Vec::new();
    for h in files {
        if (h.rows, h.cols) != (first.rows, first.cols) {
            return Err(VolumeError::header(
                &h.path,
                format!(
                    "the image is {}x{} pixels but {} is {}x{}: one series must have one image size",
                    h.cols,
                    h.rows,
                    first.path.display(),
                    first.cols,
                    first.rows
                ),
            ));
        }
        if (h.bits_allocated, h.samples_per_pixel) != (first.bits_allocated, first.samples_per_pixel) {
            return Err(VolumeError::header(
                &h.path,
                format!(
                    "BitsAllocated {} differs from {} in {}",
                    h.bits_allocated,
                    first.bits_allocated,
                    first.path.display()
                ),
            ));
        }
    }
    let frame0 = &first.frames[0];
    let mut slices: Vec<SliceRef> = Vec::new();
    let total: usize = files.iter().map(|f| f.frames.len()).sum();
    // one multi-frame file with no geometry at all (a cine, a secondary capture): its frames are
    // stacked in file order, as ITK stacks them
    let bare_stack = files.len() == 1
        && total > 1
        && first.mosaic.is_none()
        && first.frames.iter().all(|f| f.orientation.is_none() && f.position.is_none());
    let stack_gap = first.spacing_between_slices.or(first.slice_thickness).unwrap_or(1.0);
    if bare_stack {
        let said = match (first.spacing_between_slices, first.slice_thickness) {
            (Some(_), _) => "SpacingBetweenSlices",
            (None, Some(_)) => "SliceThickness",
            _ => "assumed",
        };
        warnings.push(format!(
            "no ImagePositionPatient or ImageOrientationPatient: the {total} frames are stacked in file order along the \
             world z axis, {stack_gap} mm apart ({said})"
        ));
    }
    let orientation = match frame0.orientation {
        Some(o) => o,
        None if total == 1 || bare_stack => {
            warnings.push("no ImageOrientationPatient: the image axes are taken as the world axes".into());
            [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        }
        None => {
            return Err(VolumeError::header(
                &first.path,
                "ImageOrientationPatient is missing, so the slices cannot be placed",
            ));
        }
    };
    let row = unit([orientation[0], orientation[1], orientation[2]]);
    let col = unit([orientation[3], orientation[4], orientation[5]]);
    let (Some(row), Some(col)) = (row, col) else {
        return Err(VolumeError::header(
            &first.path,
            format!("ImageOrientationPatient {orientation:?} has a zero direction"),
        ));
    };
    if dot(row, col).abs() > 1e-3 {
        return Err(VolumeError::header(
            &first.path,
            format!("ImageOrientationPatient {orientation:?}: the row and column directions are not perpendicular"),
        ));
    }
    let normal = cross(row, col);
    let pixel = match frame0.pixel_spacing {
        Some([r, c]) if r > 0.0 && c > 0.0 => [r, c],
        Some(p) => return Err(VolumeError::header(&first.path, format!("PixelSpacing {p:?} is not positive"))),
        None => {
            warnings.push("no PixelSpacing: 1 mm pixels assumed".into());
            [1.0, 1.0]
        }
    };
    for (file, h) in files.iter().enumerate() {
        for (frame, p) in h.frames.iter().enumerate() {
            let here = if h.frames.len() > 1 { format!(" (frame {})", frame + 1) } else { String::new() };
            if let Some(o) = p.orientation
                && o.iter().zip(&orientation).any(|(a, b)| (a - b).abs() > SAME_ORIENTATION)
            {
                return Err(VolumeError::header(
                    &h.path,
                    format!(
                        "ImageOrientationPatient{here} {o:?} differs from {orientation:?} of {}: a series must have one orientation (a localizer mixed in?)",
                        first.path.display()
                    ),
                ));
            }
            if let Some(s) = p.pixel_spacing
                && s.iter().zip(&pixel).any(|(a, b)| (a - b).abs() > 1e-4 * b)
            {
                return Err(VolumeError::header(
                    &h.path,
                    format!("PixelSpacing{here} {s:?} differs from {pixel:?} of {}", first.path.display()),
                ));
            }
            let position = match p.position {
                Some(pos) => pos,
                None if total == 1 => {
                    warnings.push("no ImagePositionPatient: the origin is taken as 0".into());
                    [0.0; 3]
                }
                None if bare_stack => [0.0, 0.0, frame as f64 * stack_gap],
                None => {
                    return Err(VolumeError::header(
                        &h.path,
                        format!("ImagePositionPatient is missing{here}, so the slice cannot be placed in the series"),
                    ));
                }
            };
            let (slope, intercept) = p.rescale;
            if slope == 0.0 || !slope.is_finite() || !intercept.is_finite() {
                // a zero slope maps every stored value to the intercept: a constant volume, never a scan
                return Err(VolumeError::header(
                    &h.path,
                    format!(
                        "RescaleSlope {slope}{here}: stored values would all map to {intercept}; the header is \
                         broken (RescaleSlope must be a finite, non-zero number)"
                    ),
                ));
            }
            if slope.abs() * 2f64.powi(32) + intercept.abs() > f64::from(f32::MAX) {
                return Err(VolumeError::header(
                    &h.path,
                    format!("RescaleSlope {slope} / RescaleIntercept {intercept}{here} overflow 32-bit floats"),
                ));
            }
            slices.push(SliceRef { file, frame, position, along: dot(position, normal), rescale: p.rescale });
        }
    }
    // ties broken by path so which file of a copied pair is kept does not depend
    // on the order the directory listing returned them in
    slices.sort_by(|a, b| a.along.total_cmp(&b.along).then_with(|| files[a.file].path.cmp(&files[b.file].path)));
    // the same image twice (a copied file) is read once; two images at one place are refused
    let mut kept: Vec<SliceRef> = Vec::with_capacity(slices.len());
    for s in slices {
        if let Some(prev) = kept.last()
            && (s.along - prev.along).abs() < SAME_POSITION_MM
        {
            let (a, b) = (&files[prev.file], &files[s.file]);
            if a.instance_uid == b.instance_uid && !a.instance_uid.is_empty() && a.frames.len() == 1 {
                warnings.push(format!(
                    "{} holds the same image as {} (same SOPInstanceUID); read once",
                    b.path.display(),
                    a.path.display()
                ));
                continue;
            }
            let name = |h: &ImageHeader, f: usize| {
                if h.frames.len() > 1 {
                    format!("{} frame {}", h.path.display(), f + 1)
                } else {
                    h.path.display().to_string()
                }
            };
            return Err(VolumeError::header(
                input,
                format!(
                    "two images lie at the same position ({} mm along the slice normal): {} and {}; the series holds more than one volume (echoes, time points or a repeated slice): split it, or list the files of one volume in a .txt file",
                    mm(s.along),
                    name(a, prev.frame),
                    name(b, s.frame)
                ),
            ));
        }
        kept.push(s);
    }
    let slices = kept;
    if let Some(m) = &first.mosaic {
        if files.len() > 1 {
            return Err(VolumeError::header(
                input,
                format!(
                    "{} MOSAIC files in one series (a time series of volumes?): give one file to read one volume",
                    files.len()
                ),
            ));
        }
        return Ok(mosaic_layout(first, m, slices[0], row, col, pixel, warnings));
    }
    let origin = slices[0].position;
    let mut geometry = Geometry {
        dims: [first.cols as usize, first.rows as usize, slices.len()],
        spacing: [pixel[1], pixel[0], 1.0],
        origin: ras(origin),
        directions: [ras(row), ras(col), ras(normal)],
    };
    if first.is_mosaic && first.mosaic.is_none() {
        warnings.push(
            "the image is a Siemens MOSAIC but its CSA header gives no slice count; it is read as the 2D frame it is stored as"
                .into(),
        );
    }
    if slices.len() == 1 {
        geometry.spacing[2] = match (first.spacing_between_slices, first.slice_thickness) {
            (Some(s), _) | (None, Some(s)) => s,
            (None, None) => {
                warnings.push("one slice without SliceThickness: 1 mm assumed along z".into());
                1.0
            }
        };
        return Ok(Layout { slices, geometry, resampling: None, warnings });
    }
    let gaps: Vec<f64> = slices.windows(2).map(|w| w[1].along - w[0].along).collect();
    let (gap_text, common_gap) = describe_gaps(&gaps);
    let uniform = gaps.iter().all(|g| (g - common_gap).abs() <= GAP_TOLERANCE * common_gap);
    let extent = slices[slices.len() - 1].along - slices[0].along;
    let offsets: Vec<[f64; 2]> = slices
        .iter()
        .map(|s| {
            let d = sub(s.position, origin);
            [dot(d, row) / pixel[1], dot(d, col) / pixel[0]]
        })
        .collect();
    let drift = offsets.iter().map(|o| o[0].hypot(o[1])).fold(0.0, f64::max);
    let tilted = drift > TILT_PIXELS;
    if uniform && !tilted {
        geometry.spacing[2] = extent / (slices.len() - 1) as f64;
        return Ok(Layout { slices, geometry, resampling: None, warnings });
    }
    let last = offsets[offsets.len() - 1];
    let tilt_deg = (last[0] * pixel[1]).hypot(last[1] * pixel[0]).atan2(extent).to_degrees();
    let mut found = Vec::new();
    if !uniform {
        found.push(format!("slice spacing varies: {gap_text}"));
    }
    if tilted {
        found.push(format!("gantry tilt {tilt_deg:.1} degrees (the slices drift {drift:.1} pixels in-plane)"));
    }
    let found = found.join("; ");
    if !resample {
        return Err(VolumeError::NeedsResampling { path: input.to_path_buf(), found, gap_mm: mm(common_gap) });
    }
    let nz = (extent / common_gap + 1e-6).floor() as usize + 1;
    geometry.dims[2] = nz;
    geometry.spacing[2] = common_gap;
    warnings.push(format!(
        "{found}: resampled onto a regular grid of {nz} slices at {} mm (linear between slices{})",
        mm(common_gap),
        if tilted { ", the tilt undone by shifting each slice in-plane" } else { "" }
    ));
    Ok(Layout { slices, geometry, resampling: Some(Resampling { nz, spacing: common_gap, offsets }), warnings })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gap_listing_groups_equal_gaps_commonest_first() {
        let mut gaps = vec![2.5; 40];
        gaps.push(1.25);
        gaps.extend([5.0; 20]);
        let (text, common) = describe_gaps(&gaps);
        assert_eq!(text, "2.5 mm x40, 5.0 mm x20, 1.25 mm");
        assert_eq!(common, 2.5);
    }

    #[test]
    fn lengths_print_with_one_or_two_decimals() {
        assert_eq!(mm(5.0), "5.0");
        assert_eq!(mm(1.25), "1.25");
        assert_eq!(mm(0.7), "0.7");
    }
}
