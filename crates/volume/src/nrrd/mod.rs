//! NRRD: attached `.nrrd` and detached `.nhdr` + data file; raw, gzip and
//! ascii encodings; both endiannesses; `spacings` or `space directions`; 3D
//! scalar volumes and 4D volumes with a field axis (leading, as Teem and
//! Slicer write vectors, or trailing).
//!
//! World space is RAS: a header in left-posterior-superior (Slicer, ITK) has
//! its x and y negated on read. mdtf writes `space: right-anterior-superior`.

mod header;
mod table;

pub use header::{Encoding, NrrdHeader, read_header};
pub use table::{TableAxis, write_counts_nrrd, write_table_bytes, write_table_nrrd};

use crate::dtype::{Endian, SampleType, encode_samples, first_unrepresentable};
use crate::error::{Result, VolumeError};
use crate::geometry::Geometry;
use crate::limits::check_dims;
use crate::output::{OutputLock, StagedFile, old_pair_data, publish_pair, sweep, write_file_atomically};
use crate::samples::{
    FieldAxis, FileInfo, ReadOptions, SampleLayout, SampleStream, decode_fields, drain_rest, read_decoded, write_fields,
};
use crate::volume::{Field, MultiField};
use header::format_vector;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};

/// Reads a `.nrrd` or `.nhdr` file (with its data file).
pub fn read_nrrd(path: &Path, opts: &ReadOptions) -> Result<MultiField> {
    read_nrrd_with_info(path, opts).map(|(mf, _)| mf)
}

/// [`read_nrrd`], also returning how the file stores its samples.
pub fn read_nrrd_with_info(path: &Path, opts: &ReadOptions) -> Result<(MultiField, FileInfo)> {
    let DataStart { header: h, layout, geometry, data_path, data } = open_data(path)?;
    let arrays = match h.encoding {
        Encoding::Raw => read_raw_encoded(&data_path, data, &h, &layout, opts)?,
        Encoding::Gzip => {
            let mut gz = flate2::bufread::MultiGzDecoder::new(data);
            skip_bytes(&data_path, &mut gz, h.byte_skip as u64, &layout, true)?;
            let arrays = read_decoded(&data_path, &mut gz, &layout, true, opts)?;
            let extra = drain_rest(&data_path, &mut gz, true)?;
            refuse_extra(&data_path, &layout, extra)?;
            arrays
        }
        Encoding::Ascii => {
            let (bytes, ascii_layout) = read_ascii(&data_path, data, &layout)?;
            decode_fields(&data_path, &bytes, &ascii_layout, opts)?
        }
    };
    let names = match &h.field_names {
        Some(n) if n.len() == arrays.len() => n.clone(),
        _ if arrays.len() == 1 => vec!["value".to_string()],
        _ => (0..arrays.len()).map(|i| format!("field{i}")).collect(),
    };
    let fields = names.into_iter().zip(arrays).map(|(name, data)| Field { name, data }).collect();
    let format = if h.data_file.is_some() { "NRRD (detached header)" } else { "NRRD" };
    let info = FileInfo { units: h.units(), ..FileInfo::new(format, &layout, h.encoding == Encoding::Gzip) };
    Ok((MultiField::new(geometry, fields)?, info))
}

/// A NRRD's header, layout and grid, and its data stream after the skipped lines.
struct DataStart {
    header: NrrdHeader,
    layout: SampleLayout,
    geometry: Geometry,
    /// The file the samples are in (the header itself when attached).
    data_path: PathBuf,
    data: Box<dyn BufRead + Send>,
}

fn open_data(path: &Path) -> Result<DataStart> {
    let file = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    if file.metadata().map_err(|e| VolumeError::io(path, e))?.len() == 0 {
        return Err(VolumeError::Empty { path: path.to_path_buf() });
    }
    let mut reader = BufReader::new(file);
    let h = read_header(path, &mut reader)?;
    let (layout, geometry) = layout_and_geometry(path, &h)?;

    // Attached data continue in the same file; detached data live beside the header.
    let (data_path, mut data): (PathBuf, Box<dyn BufRead + Send>) = match &h.data_file {
        None => (path.to_path_buf(), Box::new(reader)),
        Some(name) => {
            if name.starts_with("LIST") || name.contains('%') {
                return Err(VolumeError::header(
                    path,
                    format!("multi-file data ('data file: {name}') is not supported"),
                ));
            }
            let dp = path.parent().unwrap_or(Path::new(".")).join(name);
            let f = std::fs::File::open(&dp)
                .map_err(|e| VolumeError::header(path, format!("cannot open its data file {}: {e}", dp.display())))?;
            (dp, Box::new(BufReader::new(f)))
        }
    };
    for _ in 0..h.line_skip {
        let mut skipped = Vec::new();
        if data.read_until(b'\n', &mut skipped).map_err(|e| VolumeError::io(&data_path, e))? == 0 {
            return Err(VolumeError::Truncated { path: data_path, expected: layout.byte_len(), found: 0 });
        }
    }
    Ok(DataStart { header: h, layout, geometry, data_path, data })
}

/// The samples of a raw or gzip NRRD (attached or detached) as a stream at
/// its first sample, with their layout and grid; None for encodings read
/// only whole (ascii, or raw samples located from the file's end).
pub(crate) fn open_samples(path: &Path) -> Result<Option<(SampleStream, Geometry)>> {
    let DataStart { header: h, layout, geometry, data_path, data } = open_data(path)?;
    if h.encoding == Encoding::Ascii || (h.encoding == Encoding::Raw && h.byte_skip == -1) {
        return Ok(None);
    }
    let gzip = h.encoding == Encoding::Gzip;
    let mut src: Box<dyn Read + Send> =
        if gzip { Box::new(flate2::bufread::MultiGzDecoder::new(data)) } else { Box::new(data) };
    skip_bytes(&data_path, &mut src, h.byte_skip.max(0) as u64, &layout, gzip)?;
    Ok(Some((SampleStream { src, layout, compressed: gzip, units: h.units() }, geometry)))
}

fn refuse_extra(path: &Path, layout: &SampleLayout, extra: u64) -> Result<()> {
    if extra > 0 {
        return Err(VolumeError::SizeMismatch {
            path: path.to_path_buf(),
            expected: layout.byte_len(),
            found: layout.byte_len() + extra,
        });
    }
    Ok(())
}

fn skip_bytes(path: &Path, src: &mut dyn Read, n: u64, layout: &SampleLayout, gz: bool) -> Result<()> {
    let got = std::io::copy(&mut src.take(n), &mut std::io::sink()).map_err(|e| {
        if gz { VolumeError::Gzip { path: path.to_path_buf(), cause: e } } else { VolumeError::io(path, e) }
    })?;
    if got < n {
        return Err(VolumeError::Truncated { path: path.to_path_buf(), expected: layout.byte_len(), found: 0 });
    }
    Ok(())
}

fn read_raw_encoded(
    path: &Path,
    mut data: Box<dyn BufRead + Send>,
    h: &NrrdHeader,
    layout: &SampleLayout,
    opts: &ReadOptions,
) -> Result<Vec<ndarray::Array3<f32>>> {
    if h.byte_skip == -1 {
        // The samples are the last bytes of the file.
        let mut all = Vec::new();
        data.read_to_end(&mut all).map_err(|e| VolumeError::io(path, e))?;
        let n = layout.byte_len() as usize;
        if all.len() < n {
            return Err(VolumeError::Truncated {
                path: path.to_path_buf(),
                expected: n as u64,
                found: all.len() as u64,
            });
        }
        return decode_fields(path, &all[all.len() - n..], layout, opts);
    }
    skip_bytes(path, &mut data, h.byte_skip as u64, layout, false)?;
    let arrays = read_decoded(path, &mut data, layout, false, opts)?;
    let extra = drain_rest(path, &mut data, false)?;
    refuse_extra(path, layout, extra)?;
    Ok(arrays)
}

/// Parses ascii samples; returns them as little-endian f32 bytes and the layout that decodes them.
fn read_ascii(
    path: &Path,
    mut data: Box<dyn BufRead + Send>,
    layout: &SampleLayout,
) -> Result<(Vec<u8>, SampleLayout)> {
    let mut text = String::new();
    data.read_to_string(&mut text).map_err(|e| VolumeError::io(path, e))?;
    let n = (layout.byte_len() / layout.ty.size() as u64) as usize;
    let values: Vec<f32> = text
        .split(|c: char| c.is_whitespace() || c == ',')
        .filter(|s| !s.is_empty())
        .enumerate()
        .map(|(k, s)| {
            s.parse::<f64>().map(|v| v as f32).map_err(|_| {
                let shown: String = s.chars().take(40).collect();
                VolumeError::header(path, format!("ascii data: sample {} is '{shown}', not a number", k + 1))
            })
        })
        .collect::<Result<_>>()?;
    if values.len() != n {
        let expected = layout.byte_len();
        let found = (values.len() * layout.ty.size()) as u64;
        return Err(if values.len() < n {
            VolumeError::Truncated { path: path.to_path_buf(), expected, found }
        } else {
            VolumeError::SizeMismatch { path: path.to_path_buf(), expected, found }
        });
    }
    // Re-encode as little-endian f32 so the common decoder applies.
    let mut bytes = Vec::new();
    encode_samples(&values, SampleType::F32, Endian::Little, &mut bytes);
    Ok((bytes, SampleLayout { ty: SampleType::F32, endian: Endian::Little, ..*layout }))
}

/// Works out which axis holds fields and the grid's geometry.
fn layout_and_geometry(path: &Path, h: &NrrdHeader) -> Result<(SampleLayout, Geometry)> {
    let dim = h.sizes.len();
    if !(1..=4).contains(&dim) {
        return Err(VolumeError::BadDimensions {
            path: path.to_path_buf(),
            dims: format!("{:?}", h.sizes),
            message: "mdtf reads 1D to 3D scalar and 4D multi-field NRRDs".into(),
        });
    }
    let non_spatial = |a: usize| {
        let by_kind = h.kinds.as_ref().is_some_and(|k| !matches!(k[a].as_str(), "domain" | "space" | "???" | "none"));
        let by_dir = h.directions.as_ref().is_some_and(|d| d[a].is_none());
        by_kind || by_dir
    };
    let field_axis = if dim == 4 {
        match (non_spatial(0), non_spatial(3)) {
            (false, true) => Some(3),
            (true, false) | (false, false) => Some(0),
            (true, true) => {
                return Err(VolumeError::header(path, "two non-spatial axes: only one field axis is supported"));
            }
        }
    } else {
        None
    };
    let spatial: Vec<usize> = (0..dim).filter(|&a| Some(a) != field_axis).collect();
    let mut dims = [1u64; 3];
    for (slot, &a) in spatial.iter().enumerate() {
        dims[slot] = h.sizes[a];
    }
    let fields = field_axis.map_or(1, |a| h.sizes[a]);
    check_dims(path, &h.sizes, fields)?;
    let dims = dims.map(|d| d as usize);

    // RAS from the header's space: negate the axes that point the other way.
    let flip = match h.space.as_deref() {
        Some("left-posterior-superior" | "lps") => [-1.0, -1.0, 1.0],
        Some("left-anterior-superior" | "las") => [-1.0, 1.0, 1.0],
        _ => [1.0, 1.0, 1.0],
    };
    let origin = h.origin.unwrap_or([0.0; 3]);
    let origin = [origin[0] * flip[0], origin[1] * flip[1], origin[2] * flip[2]];
    let mut affine = [[0.0; 4]; 3];
    for (row, o) in origin.iter().enumerate() {
        affine[row][3] = *o;
    }
    for slot in 0..3 {
        let column = match (spatial.get(slot), &h.directions, &h.spacings) {
            (Some(&a), Some(dirs), _) => {
                let v = dirs[a].ok_or_else(|| {
                    VolumeError::header(path, format!("spatial axis {a} has no space direction ('none')"))
                })?;
                [v[0] * flip[0], v[1] * flip[1], v[2] * flip[2]]
            }
            (Some(&a), None, Some(sp)) => {
                let s = if sp[a].is_finite() { sp[a] } else { 1.0 };
                if s <= 0.0 {
                    return Err(VolumeError::header(path, format!("spacing {s} of axis {a} must be positive")));
                }
                let mut c = [0.0; 3];
                c[slot] = s;
                c
            }
            _ => {
                let mut c = [0.0; 3];
                c[slot] = 1.0;
                c
            }
        };
        for row in 0..3 {
            affine[row][slot] = column[row];
        }
    }
    let geometry = Geometry::from_affine(dims, affine)
        .ok_or_else(|| VolumeError::header(path, "degenerate space directions (a zero-length axis)"))?;
    let layout = SampleLayout {
        ty: h.ty,
        endian: h.endian.unwrap_or(Endian::Little),
        dims,
        fields: fields as usize,
        field_axis: if field_axis == Some(3) { FieldAxis::Slowest } else { FieldAxis::Fastest },
        scale: None,
    };
    Ok((layout, geometry))
}

/// Writes `mf` as NRRD with samples stored as `ty`: attached for `.nrrd`,
/// detached for `.nhdr` (data in `<stem>.raw`, or `.raw.gz` when gzipped).
/// Several fields go on a leading `list` axis (interleaved per voxel), as
/// Teem and Slicer expect; their names are kept in an `mdtf_fields:=` line.
pub fn write_nrrd(path: &Path, mf: &MultiField, ty: SampleType, encoding: Encoding) -> Result<()> {
    if encoding == Encoding::Ascii {
        return Err(VolumeError::UnsupportedEncoding {
            path: path.to_path_buf(),
            encoding: "ascii (for writing)".into(),
        });
    }
    for f in &mf.fields {
        if let Some((index, value)) = f.data.as_slice().and_then(|s| first_unrepresentable(s, ty)) {
            return Err(VolumeError::NotRepresentable { path: path.to_path_buf(), value, index, target: ty.name() });
        }
    }
    let data_name = data_file_name(path, encoding == Encoding::Gzip);
    let names: Vec<&str> = mf.fields.iter().map(|f| f.name.as_str()).collect();
    let header = header_text(&mf.geometry, &names, ty, encoding, data_name.as_deref());
    let slices: Vec<&[f32]> = mf.fields.iter().map(|f| f.data.as_slice().unwrap_or(&[])).collect();
    let write_samples = |w: &mut dyn Write| -> std::io::Result<()> {
        match encoding {
            Encoding::Gzip => {
                let mut gz = flate2::write::GzEncoder::new(w, flate2::Compression::fast());
                write_fields(&mut gz, &slices, FieldAxis::Fastest, ty)?;
                gz.finish()?;
                Ok(())
            }
            _ => write_fields(w, &slices, FieldAxis::Fastest, ty),
        }
    };
    match data_name {
        None => write_file_atomically(path, |w| {
            w.write_all(header.as_bytes())?;
            write_samples(w)
        }),
        Some(name) => {
            let data_path = path.parent().unwrap_or(Path::new("")).join(name);
            let _lock = OutputLock::acquire(path)?;
            let old_data = old_pair_data(path, &data_path, &detached_data_files(path))?;
            let data = StagedFile::write(&data_path, write_samples)?;
            let staged_header = StagedFile::write(path, |w| w.write_all(header.as_bytes()))?;
            publish_pair(staged_header, data, old_data.as_deref(), with_data_file)?;
            sweep(path);
            sweep(&data_path);
            Ok(())
        }
    }
}

/// The name of the data file mdtf writes beside a `.nhdr` header (none for
/// an attached `.nrrd`).
fn data_file_name(path: &Path, gzip: bool) -> Option<String> {
    let detached = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("nhdr"));
    detached.then(|| {
        let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "data".into());
        format!("{stem}{}", if gzip { ".raw.gz" } else { ".raw" })
    })
}

/// The data file that writing `path` as NRRD would also write, if any.
pub fn planned_data_file(path: &Path, gzip: bool) -> Option<PathBuf> {
    data_file_name(path, gzip).map(|n| path.parent().unwrap_or(Path::new("")).join(n))
}

/// The data files a detached header names (empty for an attached header, a
/// file that is not NRRD, or multi-file data that mdtf does not read).
pub fn detached_data_files(header: &Path) -> Vec<PathBuf> {
    let Ok(file) = std::fs::File::open(header) else { return Vec::new() };
    let mut reader = BufReader::new(file.take(header::MAX_HEADER_BYTES as u64 + 1));
    let Ok(h) = read_header(header, &mut reader) else { return Vec::new() };
    match h.data_file {
        Some(name) if !name.starts_with("LIST") && !name.contains('%') => {
            vec![header.parent().unwrap_or(Path::new(".")).join(name)]
        }
        _ => Vec::new(),
    }
}

/// A detached header's text with its data file line naming `data_file`.
pub(crate) fn with_data_file(text: &str, data_file: &str) -> String {
    let mut out = String::with_capacity(text.len() + data_file.len());
    for line in text.lines() {
        let key = line.split(':').next().unwrap_or("").trim().to_ascii_lowercase();
        if key == "data file" || key == "datafile" {
            out.push_str("data file: ");
            out.push_str(data_file);
        } else {
            out.push_str(line);
        }
        out.push('\n');
    }
    out
}

/// The header of an attached raw NRRD holding the fields `names` on
/// `geometry` as `ty`, as [`write_nrrd`] writes it (for writers by slabs).
pub(crate) fn header_of(geometry: &Geometry, names: &[String], ty: SampleType) -> String {
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    header_text(geometry, &names, ty, Encoding::Raw, None)
}

/// The header of fields `names` on `g` as `ty`, with `encoding` and the detached `data_file` if any.
fn header_text(g: &Geometry, names: &[&str], ty: SampleType, encoding: Encoding, data_file: Option<&str>) -> String {
    let m = (names.len() > 1).then_some(names.len());
    let dirs: Vec<String> =
        (0..3).map(|a| format_vector([0, 1, 2].map(|r| g.directions[a][r] * g.spacing[a]))).collect();
    let mut s = String::from("NRRD0005\n# written by mdtf\n");
    s += &format!("type: {}\n", header::nrrd_type_name(ty));
    s += &format!("dimension: {}\n", 3 + usize::from(m.is_some()));
    s += "space: right-anterior-superior\n";
    let sizes = format!("{} {} {}", g.dims[0], g.dims[1], g.dims[2]);
    match m {
        Some(n) => {
            s += &format!("sizes: {n} {sizes}\n");
            s += &format!("space directions: none {}\n", dirs.join(" "));
            s += "kinds: list domain domain domain\n";
        }
        None => {
            s += &format!("sizes: {sizes}\n");
            s += &format!("space directions: {}\n", dirs.join(" "));
            s += "kinds: domain domain domain\n";
        }
    }
    s += "endian: little\n";
    s += &format!("encoding: {}\n", if encoding == Encoding::Gzip { "gzip" } else { "raw" });
    s += &format!("space origin: {}\n", format_vector(g.origin));
    if let Some(df) = data_file {
        s += &format!("data file: {df}\n");
    }
    if names.len() > 1 || names.first() != Some(&"value") {
        s += &format!("mdtf_fields:={}\n", names.join(" "));
    }
    if data_file.is_none() {
        s += "\n";
    }
    s
}

/// The detached header (.nhdr) of a texture: `components` interleaved
/// samples (a leading `kinds: vector` axis when more than one) of the named
/// NRRD type (e.g. "uint8") per voxel of `geometry`, data in `data_file`.
/// Lines after the blank-free header body are key/value pairs from `extra`.
pub fn texture_header(
    geometry: &Geometry,
    components: usize,
    type_name: &str,
    data_file: &str,
    extra: &[(&str, String)],
) -> String {
    let g = geometry;
    let dirs: Vec<String> =
        (0..3).map(|a| format_vector([0, 1, 2].map(|r| g.directions[a][r] * g.spacing[a]))).collect();
    let mut s = String::from("NRRD0005\n# written by mdtf\n");
    s += &format!("type: {type_name}\n");
    let sizes = format!("{} {} {}", g.dims[0], g.dims[1], g.dims[2]);
    if components > 1 {
        s += "dimension: 4\nspace: right-anterior-superior\n";
        s += &format!("sizes: {components} {sizes}\nspace directions: none {}\n", dirs.join(" "));
        s += "kinds: vector domain domain domain\n";
    } else {
        s += "dimension: 3\nspace: right-anterior-superior\n";
        s += &format!("sizes: {sizes}\nspace directions: {}\nkinds: domain domain domain\n", dirs.join(" "));
    }
    s += &format!("endian: little\nencoding: raw\nspace origin: {}\ndata file: {data_file}\n", format_vector(g.origin));
    for (k, v) in extra {
        s += &format!("{k}:={v}\n");
    }
    s
}
