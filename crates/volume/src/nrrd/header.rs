//! NRRD header text: parsing the subset mdtf reads and formatting what it writes.
//! Reference: the NRRD format definition (teem.sourceforge.net/nrrd/format.html).

use crate::dtype::{Endian, SampleType};
use crate::error::{Result, VolumeError};
use std::path::Path;

/// NRRD data encodings mdtf reads and writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// Samples as bytes in the stated endianness.
    Raw,
    /// Raw bytes, gzip-compressed.
    Gzip,
    /// Whitespace-separated decimal numbers.
    Ascii,
}

/// The parsed fields of a NRRD header that mdtf uses.
#[derive(Debug, Clone, PartialEq)]
pub struct NrrdHeader {
    /// Sample type.
    pub ty: SampleType,
    /// Axis sizes, fastest first.
    pub sizes: Vec<u64>,
    /// Byte order (None when the header omits it, allowed for 1-byte types and ascii).
    pub endian: Option<Endian>,
    /// Data encoding.
    pub encoding: Encoding,
    /// Per-axis spacing (`spacings`), NaN for non-spatial axes.
    pub spacings: Option<Vec<f64>>,
    /// Per-axis world direction vectors (`space directions`), None for "none".
    pub directions: Option<Vec<Option<[f64; 3]>>>,
    /// World position of the first sample (`space origin`).
    pub origin: Option<[f64; 3]>,
    /// The `space` field, lower-cased.
    pub space: Option<String>,
    /// Per-axis kinds, lower-cased.
    pub kinds: Option<Vec<String>>,
    /// Detached data file name, as written in the header.
    pub data_file: Option<String>,
    /// Bytes to skip before the data (-1: the data ends the file; raw only).
    pub byte_skip: i64,
    /// Lines to skip before the data.
    pub line_skip: u64,
    /// Field names stored by mdtf (`mdtf_fields:=` key/value).
    pub field_names: Option<Vec<String>>,
    /// `space units`, as written (a quoted unit per space axis).
    pub space_units: Option<String>,
    /// `sample units`: the unit of the values.
    pub sample_units: Option<String>,
}

impl NrrdHeader {
    /// The units the header states: `sample units` for the values, `space
    /// units` (when every axis has the same) for the lengths.
    pub fn units(&self) -> crate::Units {
        let value = self.sample_units.as_deref().map(|u| u.trim().trim_matches('"').trim().to_string());
        crate::Units {
            value: value.filter(|u| !u.is_empty()),
            length: self.space_units.as_deref().and_then(crate::units::nrrd_common_unit),
        }
    }
}

pub(crate) const MAX_HEADER_BYTES: usize = 1 << 20;

fn sample_type_of(name: &str) -> Option<SampleType> {
    let t = match name.trim() {
        "signed char" | "int8" | "int8_t" => SampleType::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => SampleType::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => SampleType::I16,
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => SampleType::U16,
        "int" | "signed int" | "int32" | "int32_t" => SampleType::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => SampleType::U32,
        "float" => SampleType::F32,
        "double" => SampleType::F64,
        _ => return None,
    };
    Some(t)
}

/// The NRRD name mdtf writes for a sample type.
pub fn nrrd_type_name(ty: SampleType) -> &'static str {
    match ty {
        SampleType::U8 => "uint8",
        SampleType::I8 => "int8",
        SampleType::U16 => "uint16",
        SampleType::I16 => "int16",
        SampleType::U32 => "uint32",
        SampleType::I32 => "int32",
        SampleType::F32 => "float",
        SampleType::F64 => "double",
    }
}

fn parse_vector(path: &Path, s: &str) -> Result<Option<[f64; 3]>> {
    let s = s.trim();
    if s == "none" {
        return Ok(None);
    }
    let inner = s
        .strip_prefix('(')
        .and_then(|t| t.strip_suffix(')'))
        .ok_or_else(|| VolumeError::header(path, format!("'{s}' is not a vector like (1,0,0)")))?;
    let parts: Vec<&str> = inner.split(',').collect();
    if parts.len() != 3 {
        return Err(VolumeError::header(path, format!("vector '{s}' must have 3 components (3D space only)")));
    }
    let mut v = [0.0f64; 3];
    for (o, p) in v.iter_mut().zip(parts) {
        *o = p.trim().parse().map_err(|_| VolumeError::header(path, format!("bad number '{p}' in vector '{s}'")))?;
        if !o.is_finite() {
            return Err(VolumeError::header(path, format!("non-finite component in vector '{s}'")));
        }
    }
    Ok(Some(v))
}

/// Splits "(1,0,0) (0,1,0) none" into its items.
fn split_vectors(s: &str) -> Vec<&str> {
    let mut items = Vec::new();
    let mut depth = 0i32;
    let mut start = None;
    for (i, ch) in s.char_indices() {
        match ch {
            '(' => {
                if depth == 0 {
                    start = Some(i);
                }
                depth += 1;
            }
            ')' => {
                depth -= 1;
                if depth == 0
                    && let Some(st) = start.take()
                {
                    items.push(&s[st..=i]);
                }
            }
            c if c.is_whitespace() && depth == 0 => {
                if let Some(st) = start.take() {
                    items.push(&s[st..i]);
                }
            }
            _ => {
                if depth == 0 && start.is_none() {
                    start = Some(i);
                }
            }
        }
    }
    if let Some(st) = start {
        items.push(&s[st..]);
    }
    items
}

/// Reads header lines from `src` up to the blank line that ends them (or the
/// end of a detached header) and parses them.
pub fn read_header(path: &Path, src: &mut dyn std::io::BufRead) -> Result<NrrdHeader> {
    let mut lines = Vec::new();
    let mut total = 0usize;
    loop {
        let mut line = Vec::new();
        let n = src.read_until(b'\n', &mut line).map_err(|e| VolumeError::io(path, e))?;
        total += n;
        if n == 0 || total > MAX_HEADER_BYTES {
            if total > MAX_HEADER_BYTES {
                return Err(VolumeError::header(path, "no end of header within 1 MiB (is this a NRRD file?)"));
            }
            break;
        }
        let text = String::from_utf8(line)
            .map_err(|_| VolumeError::header(path, "header is not text (is this a NRRD file?)"))?;
        let text = text.trim_end_matches(['\n', '\r']).to_string();
        if text.is_empty() {
            break;
        }
        lines.push(text);
    }
    parse_header(path, &lines)
}

fn parse_header(path: &Path, lines: &[String]) -> Result<NrrdHeader> {
    let magic = lines.first().map(String::as_str).unwrap_or("");
    if !(magic.starts_with("NRRD000") && magic.len() == 8) {
        return Err(VolumeError::header(path, "missing the NRRD000x magic line (is this a NRRD file?)"));
    }
    let mut ty = None;
    let mut dimension = None;
    let mut h = NrrdHeader {
        ty: SampleType::U8,
        sizes: Vec::new(),
        endian: None,
        encoding: Encoding::Raw,
        spacings: None,
        directions: None,
        origin: None,
        space: None,
        kinds: None,
        data_file: None,
        byte_skip: 0,
        line_skip: 0,
        field_names: None,
        space_units: None,
        sample_units: None,
    };
    let mut encoding = None;
    for line in &lines[1..] {
        if line.starts_with('#') {
            continue;
        }
        if let Some((key, value)) = line.split_once(":=") {
            if key.trim() == "mdtf_fields" {
                h.field_names = Some(value.split_whitespace().map(str::to_string).collect());
            }
            continue;
        }
        let Some((key, value)) = line.split_once(": ") else {
            return Err(VolumeError::header(path, format!("line '{line}' is not 'field: value'")));
        };
        let value = value.trim();
        let bad = |what: &str| VolumeError::header(path, format!("bad {what} '{value}'"));
        match key.trim().to_ascii_lowercase().as_str() {
            "type" => {
                ty = Some(sample_type_of(value).ok_or_else(|| VolumeError::UnsupportedType {
                    path: path.to_path_buf(),
                    name: value.to_string(),
                    supported: "int8, uint8, int16, uint16, int32, uint32, float, double",
                })?)
            }
            "dimension" => dimension = Some(value.parse::<usize>().map_err(|_| bad("dimension"))?),
            "sizes" => {
                h.sizes = value
                    .split_whitespace()
                    .map(|s| s.parse::<u64>())
                    .collect::<std::result::Result<_, _>>()
                    .map_err(|_| bad("sizes"))?
            }
            "endian" => {
                h.endian = Some(match value {
                    "little" => Endian::Little,
                    "big" => Endian::Big,
                    _ => return Err(bad("endian")),
                })
            }
            "encoding" => {
                encoding = Some(match value {
                    "raw" => Encoding::Raw,
                    "gzip" | "gz" => Encoding::Gzip,
                    "ascii" | "text" | "txt" => Encoding::Ascii,
                    other => {
                        return Err(VolumeError::UnsupportedEncoding {
                            path: path.to_path_buf(),
                            encoding: other.to_string(),
                        });
                    }
                })
            }
            "spacings" => {
                h.spacings = Some(
                    value
                        .split_whitespace()
                        .map(|s| if s.eq_ignore_ascii_case("nan") { Ok(f64::NAN) } else { s.parse::<f64>() })
                        .collect::<std::result::Result<_, _>>()
                        .map_err(|_| bad("spacings"))?,
                )
            }
            "space directions" => {
                h.directions =
                    Some(split_vectors(value).into_iter().map(|v| parse_vector(path, v)).collect::<Result<Vec<_>>>()?)
            }
            "space origin" => h.origin = parse_vector(path, value)?,
            "space" => h.space = Some(value.to_ascii_lowercase()),
            "space dimension" if value != "3" => {
                return Err(VolumeError::header(
                    path,
                    format!("space dimension {value}: only 3D spaces are supported"),
                ));
            }
            "kinds" => h.kinds = Some(value.split_whitespace().map(|s| s.to_ascii_lowercase()).collect()),
            "space units" => h.space_units = Some(value.to_string()),
            "sample units" | "sampleunits" => h.sample_units = Some(value.to_string()),
            "data file" | "datafile" => {
                h.data_file = Some(value.to_string());
                if value.starts_with("LIST") {
                    // the remaining lines are the data files' names, not fields
                    break;
                }
            }
            "byte skip" | "byteskip" => h.byte_skip = value.parse().map_err(|_| bad("byte skip"))?,
            "line skip" | "lineskip" => h.line_skip = value.parse().map_err(|_| bad("line skip"))?,
            _ => {} // content, units, centers, labels ...: informative only
        }
    }
    h.ty = ty.ok_or_else(|| VolumeError::header(path, "missing 'type' field"))?;
    h.encoding = encoding.ok_or_else(|| VolumeError::header(path, "missing 'encoding' field"))?;
    let dimension = dimension.ok_or_else(|| VolumeError::header(path, "missing 'dimension' field"))?;
    if h.sizes.len() != dimension {
        return Err(VolumeError::header(
            path,
            format!("'sizes' lists {} axes but dimension is {dimension}", h.sizes.len()),
        ));
    }
    for (what, n) in [
        ("spacings", h.spacings.as_ref().map(Vec::len)),
        ("space directions", h.directions.as_ref().map(Vec::len)),
        ("kinds", h.kinds.as_ref().map(Vec::len)),
    ] {
        if let Some(n) = n
            && n != dimension
        {
            return Err(VolumeError::header(path, format!("'{what}' lists {n} axes but dimension is {dimension}")));
        }
    }
    if h.byte_skip < -1 {
        return Err(VolumeError::header(path, format!("byte skip {} must be -1 or more", h.byte_skip)));
    }
    if h.byte_skip == -1 && h.encoding != Encoding::Raw {
        return Err(VolumeError::header(path, "byte skip -1 is only allowed with raw encoding"));
    }
    if h.endian.is_none() && h.ty.size() > 1 && h.encoding != Encoding::Ascii {
        return Err(VolumeError::header(path, format!("missing 'endian' field, required for {}", h.ty)));
    }
    Ok(h)
}

/// Formats a 3-vector the way NRRD writes it, with shortest round-trip numbers.
pub fn format_vector(v: [f64; 3]) -> String {
    format!("({},{},{})", v[0], v[1], v[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<NrrdHeader> {
        let lines: Vec<String> = text.lines().map(str::to_string).collect();
        parse_header(Path::new("t.nhdr"), &lines)
    }

    #[test]
    fn teem_style_header_with_space_directions_and_kinds() {
        let h = parse(
            "NRRD0004\n# Complete NRRD file format specification at:\ntype: short\ndimension: 4\nspace: left-posterior-superior\n\
             sizes: 3 4 5 6\nspace directions: none (0.5,0,0) (0,0.5,0) (0,0,2)\nkinds: vector domain domain domain\n\
             endian: big\nencoding: gzip\nspace origin: (-1,2.5,3)\ndata file: d.raw.gz\nbyte skip: 4\n",
        )
        .unwrap();
        assert_eq!(h.ty, SampleType::I16);
        assert_eq!(h.sizes, vec![3, 4, 5, 6]);
        assert_eq!(h.endian, Some(Endian::Big));
        assert_eq!(h.encoding, Encoding::Gzip);
        let d = h.directions.unwrap();
        assert_eq!(d[0], None);
        assert_eq!(d[3], Some([0.0, 0.0, 2.0]));
        assert_eq!(h.origin, Some([-1.0, 2.5, 3.0]));
        assert_eq!(h.kinds.unwrap()[0], "vector");
        assert_eq!(h.data_file.as_deref(), Some("d.raw.gz"));
        assert_eq!(h.byte_skip, 4);
    }

    #[test]
    fn inconsistent_headers_are_refused() {
        assert!(parse("NRRD0004\ntype: float\ndimension: 3\nsizes: 2 2\nencoding: raw\nendian: little\n").is_err());
        assert!(parse("NRRD0004\ntype: float\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n").is_err());
        assert!(parse("NRRD0004\ntype: long\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n").is_err());
        let e = parse("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: bzip2\n").unwrap_err();
        assert!(matches!(e, VolumeError::UnsupportedEncoding { .. }));
        assert!(parse("P6\n").is_err());
    }

    #[test]
    fn vectors_split_even_with_spaces_inside() {
        assert_eq!(split_vectors("none (1, 0, 0) (0,1,0)"), vec!["none", "(1, 0, 0)", "(0,1,0)"]);
    }
}
