//! MetaImage (ITK's native format): `.mha` (header and data in one file) and
//! `.mhd` + data file. Read: every `MET_` type mdtf knows, both byte orders,
//! `ElementNumberOfChannels` (interleaved per voxel, as fields),
//! `CompressedData = True` (zlib), `ElementDataFile = LIST` of 2D slices,
//! `TransformMatrix`, `Offset`, `ElementSpacing`, `HeaderSize`. Write: f32,
//! u8 or u16, little-endian, uncompressed.
//!
//! MetaImage world space is ITK's LPS; mdtf's is RAS, so x and y of every
//! position and direction are negated on read and on write. `TransformMatrix`
//! lists the axis directions one after another (ITK's direction matrix,
//! column by column).

use crate::dtype::{Endian, SampleType, first_unrepresentable};
use crate::error::{Result, VolumeError};
use crate::geometry::Geometry;
use crate::limits::check_dims;
use crate::output::{OutputLock, StagedFile, publish_pair, sweep, write_file_atomically};
use crate::samples::{FieldAxis, FileInfo, ReadOptions, SampleLayout, drain_rest, read_decoded, write_fields};
use crate::volume::{Field, MultiField};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};

/// Longest MetaImage header read before giving up (it is a few hundred bytes).
const MAX_HEADER_BYTES: u64 = 1 << 20;

/// A parsed MetaImage header.
#[derive(Debug, Clone, PartialEq)]
struct MetaHeader {
    dims: Vec<u64>,
    ty: SampleType,
    endian: Endian,
    channels: u64,
    spacing: [f64; 3],
    offset: [f64; 3],
    /// Axis directions (LPS), one per axis.
    directions: [[f64; 3]; 3],
    compressed: bool,
    /// `LOCAL`, a file name, or `LIST` with the slice files.
    data: DataFile,
    header_size: i64,
}

#[derive(Debug, Clone, PartialEq)]
enum DataFile {
    Local,
    File(String),
    List(Vec<String>),
}

fn met_type(name: &str) -> Option<SampleType> {
    Some(match name {
        "MET_UCHAR" => SampleType::U8,
        "MET_CHAR" => SampleType::I8,
        "MET_USHORT" => SampleType::U16,
        "MET_SHORT" => SampleType::I16,
        "MET_UINT" => SampleType::U32,
        "MET_INT" => SampleType::I32,
        "MET_FLOAT" => SampleType::F32,
        "MET_DOUBLE" => SampleType::F64,
        _ => return None,
    })
}

fn met_name(ty: SampleType) -> &'static str {
    match ty {
        SampleType::U8 => "MET_UCHAR",
        SampleType::I8 => "MET_CHAR",
        SampleType::U16 => "MET_USHORT",
        SampleType::I16 => "MET_SHORT",
        SampleType::U32 => "MET_UINT",
        SampleType::I32 => "MET_INT",
        SampleType::F32 => "MET_FLOAT",
        SampleType::F64 => "MET_DOUBLE",
    }
}

/// Whether the first bytes of a file are a MetaImage header: the first
/// non-empty line is `Key = value` with a key MetaImage defines.
pub fn looks_like_metaimage(head: &[u8]) -> bool {
    const KEYS: &[&str] = &[
        "ObjectType",
        "NDims",
        "DimSize",
        "ElementType",
        "Comment",
        "ObjectSubType",
        "TransformType",
        "BinaryData",
        "BinaryDataByteOrderMSB",
        "ElementByteOrderMSB",
        "CompressedData",
    ];
    let text = String::from_utf8_lossy(head);
    let Some(line) = text.lines().map(str::trim).find(|l| !l.is_empty()) else { return false };
    line.split_once('=').is_some_and(|(key, _)| KEYS.contains(&key.trim()))
}

/// Reads `key = value` lines up to and including `ElementDataFile` (always
/// the last key) and, for `LIST`, the slice names after it.
fn read_header(path: &Path, src: &mut dyn BufRead) -> Result<MetaHeader> {
    let bad = |m: String| VolumeError::header(path, m);
    let mut keys: Vec<(String, String)> = Vec::new();
    let mut total = 0u64;
    let mut data = None;
    loop {
        let mut line = Vec::new();
        let n = src.read_until(b'\n', &mut line).map_err(|e| VolumeError::io(path, e))?;
        total += n as u64;
        if n == 0 {
            break;
        }
        if total > MAX_HEADER_BYTES {
            return Err(bad("no ElementDataFile line within 1 MiB (is this a MetaImage file?)".into()));
        }
        let text =
            String::from_utf8(line).map_err(|_| bad("the header is not text (is this a MetaImage file?)".into()))?;
        let text = text.trim();
        if text.is_empty() {
            continue;
        }
        let Some((key, value)) = text.split_once('=') else {
            return Err(bad(format!("line '{text}' is not 'Key = Value'")));
        };
        let (key, value) = (key.trim().to_string(), value.trim().to_string());
        if key == "ElementDataFile" {
            data = Some(value);
            break;
        }
        keys.push((key, value));
    }
    let get = |k: &str| keys.iter().find(|(key, _)| key == k).map(|(_, v)| v.as_str());
    let data = data.ok_or_else(|| bad("no ElementDataFile line (is this a MetaImage file?)".into()))?;
    if let Some(t) = get("ObjectType")
        && t != "Image"
    {
        return Err(bad(format!("ObjectType = {t}: only images are volumes")));
    }
    let numbers = |k: &str| -> Result<Vec<f64>> {
        get(k)
            .unwrap_or("")
            .split_whitespace()
            .map(|s| {
                s.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| bad(format!("{k}: '{s}' is not a finite number")))
            })
            .collect()
    };
    let ndims: usize =
        get("NDims").and_then(|s| s.parse().ok()).ok_or_else(|| bad("NDims is missing or not 1 to 3".into()))?;
    if !(1..=3).contains(&ndims) {
        return Err(bad(format!(
            "NDims = {ndims}: mdtf reads 1 to 3 dimensions (channels go in ElementNumberOfChannels)"
        )));
    }
    let dims: Vec<u64> = get("DimSize")
        .unwrap_or("")
        .split_whitespace()
        .map(|s| s.parse::<u64>().map_err(|_| bad(format!("DimSize: '{s}' is not a whole number"))))
        .collect::<Result<_>>()?;
    if dims.len() != ndims {
        return Err(bad(format!("DimSize has {} sizes for NDims = {ndims}", dims.len())));
    }
    let ty_name = get("ElementType").ok_or_else(|| bad("ElementType is missing".into()))?;
    let ty = met_type(ty_name).ok_or_else(|| VolumeError::UnsupportedType {
        path: path.to_path_buf(),
        name: ty_name.to_string(),
        supported: "MET_UCHAR, MET_CHAR, MET_USHORT, MET_SHORT, MET_UINT, MET_INT, MET_FLOAT, MET_DOUBLE",
    })?;
    let yes = |k: &str| get(k).is_some_and(|v| v.eq_ignore_ascii_case("true"));
    let endian = if yes("BinaryDataByteOrderMSB") || yes("ElementByteOrderMSB") { Endian::Big } else { Endian::Little };
    if get("BinaryData").is_some_and(|v| v.eq_ignore_ascii_case("false")) {
        return Err(bad("BinaryData = False (ASCII samples) is not supported".into()));
    }
    let channels: u64 = match get("ElementNumberOfChannels") {
        None => 1,
        Some(s) => s
            .parse()
            .ok()
            .filter(|&c| (1..=64).contains(&c))
            .ok_or_else(|| bad(format!("ElementNumberOfChannels = {s}: need 1 to 64")))?,
    };
    let mut spacing = [1.0; 3];
    let given = if get("ElementSpacing").is_some() { numbers("ElementSpacing")? } else { numbers("ElementSize")? };
    for (s, v) in spacing.iter_mut().zip(&given) {
        *s = *v;
    }
    if given.len() > ndims || spacing.iter().any(|&s| s <= 0.0) {
        return Err(bad(format!("ElementSpacing {given:?}: need {ndims} positive numbers")));
    }
    let mut offset = [0.0; 3];
    let key = if get("Offset").is_some() {
        "Offset"
    } else if get("Origin").is_some() {
        "Origin"
    } else {
        "Position"
    };
    for (o, v) in offset.iter_mut().zip(numbers(key)?) {
        *o = v;
    }
    let mut directions = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let key = if get("TransformMatrix").is_some() { "TransformMatrix" } else { "Rotation" };
    let m = numbers(key)?;
    if !m.is_empty() {
        if m.len() != ndims * ndims {
            return Err(bad(format!("{key} has {} numbers, NDims = {ndims} needs {}", m.len(), ndims * ndims)));
        }
        for axis in 0..ndims {
            for r in 0..ndims {
                directions[axis][r] = m[axis * ndims + r];
            }
            for r in ndims..3 {
                directions[axis][r] = 0.0;
            }
        }
    }
    let header_size: i64 = match get("HeaderSize") {
        None => 0,
        Some(s) => s
            .parse()
            .ok()
            .filter(|&h| h >= -1)
            .ok_or_else(|| bad(format!("HeaderSize = {s} is not -1 or a byte count")))?,
    };
    let data = if data == "LOCAL" {
        DataFile::Local
    } else if let Some(rest) = data.strip_prefix("LIST") {
        if !rest.trim().is_empty() && rest.trim() != "2D" && rest.trim() != "2" {
            return Err(bad(format!("ElementDataFile = LIST{rest}: only lists of 2D slices are read")));
        }
        let mut names = Vec::new();
        for line in src.lines() {
            let line = line.map_err(|e| VolumeError::io(path, e))?;
            if !line.trim().is_empty() {
                names.push(line.trim().to_string());
            }
            if names.len() as u64 > dims.last().copied().unwrap_or(1) {
                break;
            }
        }
        DataFile::List(names)
    } else if data.contains('%') {
        return Err(bad(format!("ElementDataFile = {data}: numbered file patterns are not supported (use LIST)")));
    } else {
        DataFile::File(data)
    };
    Ok(MetaHeader {
        dims,
        ty,
        endian,
        channels,
        spacing,
        offset,
        directions,
        compressed: yes("CompressedData"),
        data,
        header_size,
    })
}

/// Reads a `.mha` or `.mhd` file (with its data file or slice list).
pub fn read_metaimage_with_info(path: &Path, opts: &ReadOptions) -> Result<(MultiField, FileInfo)> {
    let file = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    if file.metadata().map_err(|e| VolumeError::io(path, e))?.len() == 0 {
        return Err(VolumeError::Empty { path: path.to_path_buf() });
    }
    let mut reader = BufReader::new(file);
    let h = read_header(path, &mut reader)?;
    let mut dims3 = [1u64; 3];
    dims3[..h.dims.len()].copy_from_slice(&h.dims);
    check_dims(path, &dims3, h.channels)?;
    let layout = SampleLayout {
        ty: h.ty,
        endian: h.endian,
        dims: dims3.map(|d| d as usize),
        fields: h.channels as usize,
        field_axis: FieldAxis::Fastest,
        scale: None,
    };
    let beside = |name: &str| path.parent().unwrap_or(Path::new(".")).join(name);
    let open = |p: &Path| -> Result<BufReader<std::fs::File>> {
        std::fs::File::open(p)
            .map(BufReader::new)
            .map_err(|e| VolumeError::header(path, format!("cannot open its data file {}: {e}", p.display())))
    };
    let (data_path, mut data): (PathBuf, Box<dyn BufRead>) = match &h.data {
        DataFile::Local => (path.to_path_buf(), Box::new(reader)),
        DataFile::File(name) => {
            let p = beside(name);
            let r = open(&p)?;
            (p, Box::new(r))
        }
        DataFile::List(names) => {
            if h.compressed {
                return Err(VolumeError::header(path, "compressed LIST slices are not supported"));
            }
            if names.len() as u64 != dims3[2] {
                return Err(VolumeError::header(
                    path,
                    format!("ElementDataFile = LIST names {} slice files for {} slices", names.len(), dims3[2]),
                ));
            }
            let mut chain: Box<dyn Read> = Box::new(std::io::empty());
            for n in names {
                chain = Box::new(chain.chain(open(&beside(n))?));
            }
            (path.to_path_buf(), Box::new(BufReader::new(chain)))
        }
    };
    if h.header_size == -1 {
        return Err(VolumeError::header(path, "HeaderSize = -1 (samples at the end of the file) is not supported"));
    }
    let skipped = std::io::copy(&mut (&mut data).take(h.header_size as u64), &mut std::io::sink())
        .map_err(|e| VolumeError::io(&data_path, e))?;
    if skipped < h.header_size as u64 {
        return Err(VolumeError::Truncated { path: data_path, expected: layout.byte_len(), found: 0 });
    }
    let arrays = if h.compressed {
        let mut z = flate2::bufread::ZlibDecoder::new(data);
        let arrays = read_decoded(&data_path, &mut z, &layout, true, opts)?;
        drain_rest(&data_path, &mut z, true)?;
        arrays
    } else {
        let arrays = read_decoded(&data_path, &mut data, &layout, false, opts)?;
        let extra = drain_rest(&data_path, &mut data, false)?;
        if extra > 0 {
            return Err(VolumeError::SizeMismatch {
                path: data_path,
                expected: layout.byte_len(),
                found: layout.byte_len() + extra,
            });
        }
        arrays
    };
    // LPS -> RAS: negate x and y of the origin and of every direction
    let ras = |v: [f64; 3]| [-v[0], -v[1], v[2]];
    let mut geometry = Geometry::new(layout.dims, h.spacing).with_origin(ras(h.offset));
    geometry.directions = h.directions.map(|d| {
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        ras(if n > 0.0 { [d[0] / n, d[1] / n, d[2] / n] } else { d })
    });
    if h.directions.iter().any(|d| d.iter().all(|&c| c == 0.0)) {
        return Err(VolumeError::header(path, "TransformMatrix has an all-zero axis"));
    }
    let fields = arrays
        .into_iter()
        .enumerate()
        .map(|(i, data)| Field { name: if h.channels == 1 { "value".into() } else { format!("field{i}") }, data })
        .collect();
    let format = match h.data {
        DataFile::Local => "MetaImage",
        _ => "MetaImage (detached header)",
    };
    Ok((MultiField::new(geometry, fields)?, FileInfo::new(format, &layout, h.compressed)))
}

/// The data files a `.mhd` header names (none for LOCAL data or a file that
/// is not MetaImage).
pub fn metaimage_data_files(header: &Path) -> Vec<PathBuf> {
    let Ok(file) = std::fs::File::open(header) else { return Vec::new() };
    let mut reader = BufReader::new(file.take(MAX_HEADER_BYTES + 1));
    let Ok(h) = read_header(header, &mut reader) else { return Vec::new() };
    let beside = |n: &String| header.parent().unwrap_or(Path::new(".")).join(n);
    match &h.data {
        DataFile::Local => Vec::new(),
        DataFile::File(n) => vec![beside(n)],
        DataFile::List(names) => names.iter().map(beside).collect(),
    }
}

/// A `.mhd` header's text with its data file line naming `data_file`.
pub(crate) fn with_metaimage_data_file(text: &str, data_file: &str) -> String {
    let mut out = String::with_capacity(text.len() + data_file.len());
    for line in text.lines() {
        if line.split('=').next().is_some_and(|k| k.trim() == "ElementDataFile") {
            out.push_str("ElementDataFile = ");
            out.push_str(data_file);
            out.push('\n');
            break;
        }
        out.push_str(line);
        out.push('\n');
    }
    out
}

/// The data file mdtf writes beside a `.mhd` header (none for `.mha`).
pub fn metaimage_planned_data_file(path: &Path) -> Option<PathBuf> {
    let detached = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("mhd"));
    detached.then(|| {
        let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "data".into());
        path.parent().unwrap_or(Path::new("")).join(format!("{stem}.raw"))
    })
}

fn header_text(mf: &MultiField, ty: SampleType, data_file: &str) -> String {
    let g = &mf.geometry;
    let lps = |v: [f64; 3]| [-v[0], -v[1], v[2]];
    let fmt = |v: &[f64]| v.iter().map(|x| format!("{x}")).collect::<Vec<_>>().join(" ");
    let dirs: Vec<f64> = g.directions.iter().flat_map(|d| lps(*d)).collect();
    let mut t = String::from("ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n");
    t.push_str("CompressedData = False\n");
    t.push_str(&format!("TransformMatrix = {}\n", fmt(&dirs)));
    t.push_str(&format!("Offset = {}\n", fmt(&lps(g.origin))));
    t.push_str(&format!("ElementSpacing = {}\n", fmt(&g.spacing)));
    t.push_str(&format!("DimSize = {} {} {}\n", g.dims[0], g.dims[1], g.dims[2]));
    if mf.fields.len() > 1 {
        t.push_str(&format!("ElementNumberOfChannels = {}\n", mf.fields.len()));
    }
    t.push_str(&format!("ElementType = {}\nElementDataFile = {data_file}\n", met_name(ty)));
    t
}

/// Writes `mf` as MetaImage with samples stored as `ty`: `.mha` with the data
/// after the header, `.mhd` with the data in `<stem>.raw` (published with its
/// header as one unit). Several fields become interleaved channels.
pub fn write_metaimage(path: &Path, mf: &MultiField, ty: SampleType) -> Result<()> {
    for f in &mf.fields {
        if let Some((index, value)) = f.data.as_slice().and_then(|s| first_unrepresentable(s, ty)) {
            return Err(VolumeError::NotRepresentable { path: path.to_path_buf(), value, index, target: ty.name() });
        }
    }
    let slices: Vec<&[f32]> = mf.fields.iter().map(|f| f.data.as_slice().unwrap_or(&[])).collect();
    let samples = |w: &mut dyn Write| write_fields(w, &slices, FieldAxis::Fastest, ty);
    match metaimage_planned_data_file(path) {
        None => write_file_atomically(path, |w| {
            w.write_all(header_text(mf, ty, "LOCAL").as_bytes())?;
            samples(w)
        }),
        Some(data_path) => {
            let name = data_path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            let _lock = OutputLock::acquire(path)?;
            let old = crate::output::old_pair_data(path, &data_path, &metaimage_data_files(path))?;
            let data = StagedFile::write(&data_path, samples)?;
            let header = StagedFile::write(path, |w| w.write_all(header_text(mf, ty, &name).as_bytes()))?;
            publish_pair(header, data, old.as_deref(), with_metaimage_data_file)?;
            sweep(path);
            sweep(&data_path);
            Ok(())
        }
    }
}
