//! OME-Zarr images, read and written by chunk with the `zarrs` crate.
//!
//! * Read: NGFF 0.4 (Zarr v2) and 0.5 (Zarr v3) multiscale images, any
//!   level (`ReadOptions::level`, 0 = full resolution), and plain Zarr
//!   arrays without OME metadata (spacing 1, with a warning). Axes may be
//!   `[t] [c] [z] y x`: a channel axis gives the fields, a time or other
//!   axis must hold one point. Any codec `zarrs` builds here (zstd, blosc,
//!   gzip, crc32c, sharding), chunks that do not divide the shape included.
//! * Geometry: physical = scale * index + translation per axis (the level's
//!   transformations, then the image's), x/y/z to mdtf's spacing and origin.
//!   OME-Zarr has no orientation, so mdtf also writes its full
//!   `world_from_voxel` under `attributes.mdtf`; it is used on read when it
//!   agrees with the scale and translation (a store edited by another tool
//!   keeps the OME placement).
//! * Write: NGFF 0.5 on Zarr v3, one level, sharded, zstd with its frame
//!   checksum (every chunk's content is checked on read; the shard index
//!   has its CRC32C), axes `c z y x` (`c` only for several fields). The OME translation is the world origin
//!   in the grid's own axes (`directions^T origin`), the origin itself for
//!   an axis-aligned grid. Integer types need exact values, as every writer.

mod metadata;
mod stored;

pub use metadata::{Axis, Dataset, MdtfAttributes, Multiscale, Transform, multiscales_of};
pub use stored::Unstored;

use crate::dtype::{Endian, SampleType, decode_samples, encode_samples, first_unrepresentable};
use crate::error::{Result, VolumeError};
use crate::geometry::Geometry;
use crate::samples::{FileInfo, NanPolicy};
use crate::volume::{Field, MultiField};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use zarrs::array::{Array, ArrayBuilder, ArrayBytes, ArrayShardedExt, ArraySubset, data_type};
use zarrs::filesystem::FilesystemStore;

/// Planes of a written chunk along z, and its edge in y and x.
const CHUNK_EDGE: u64 = 64;
/// The edge in y and x of a written shard (a whole number of chunks).
const SHARD_EDGE: u64 = 512;
/// zstd's level for written chunks (its own default).
const ZSTD_LEVEL: i32 = 3;

/// Whether `path` is a Zarr store or array (a folder holding `zarr.json`,
/// `.zgroup` or `.zarray`).
pub fn is_store(path: &Path) -> bool {
    path.is_dir() && ["zarr.json", ".zgroup", ".zarray"].iter().any(|m| path.join(m).is_file())
}

/// What each axis of the stored array is to mdtf.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    /// A time or other axis of one point: index 0 is read.
    Single,
    /// The fields.
    Channel,
    /// Grid axis 0 (x), 1 (y) or 2 (z).
    Space(usize),
}

/// An OME-Zarr image (or plain Zarr array) open for reading by planes.
pub struct ZarrImage {
    path: PathBuf,
    array: Array<FilesystemStore>,
    roles: Vec<Role>,
    geometry: Geometry,
    fields: Vec<String>,
    ty: SampleType,
    info: FileInfo,
}

fn boxed<E: std::error::Error + Send + Sync + 'static>(e: E) -> Box<dyn std::error::Error + Send + Sync> {
    Box::new(e)
}

impl ZarrImage {
    /// Opens the image at `path` (an OME-Zarr group or a plain array), at
    /// multiscale level `level`.
    pub fn open(path: &Path, level: usize) -> Result<ZarrImage> {
        let store =
            Arc::new(FilesystemStore::new(path).map_err(|e| VolumeError::zarr(path, "opening the store")(boxed(e)))?);
        let mut warnings = Vec::new();
        let mut details = Vec::new();
        let (array, axes, scale, shift, attrs, format) = match zarrs::group::Group::open(store.clone(), "/") {
            Ok(group) => {
                let found = multiscales_of(group.attributes()).ok_or_else(|| {
                    VolumeError::header(
                        path,
                        "a Zarr group without OME multiscales metadata: give the path of one of its arrays",
                    )
                })?;
                let (multiscales, version) = found.map_err(|m| VolumeError::header(path, m))?;
                let m = multiscales.into_iter().next().ok_or_else(|| VolumeError::header(path, "empty multiscales"))?;
                let levels = m.datasets.len();
                let ds = m.datasets.get(level).ok_or_else(|| {
                    VolumeError::header(
                        path,
                        format!(
                            "input.level {level}: the image has {levels} level(s), 0 to {}",
                            levels.saturating_sub(1)
                        ),
                    )
                })?;
                let array_path = format!("/{}", ds.path.trim_matches('/'));
                let array = Array::open(store.clone(), &array_path)
                    .map_err(|e| VolumeError::zarr(path, format!("opening level {level} ({})", ds.path))(boxed(e)))?;
                let (scale, shift) = m.scale_and_translation(level).map_err(|e| VolumeError::header(path, e))?;
                details.push(("levels".to_string(), level_list(&store, &m)));
                details.push(("level read".to_string(), format!("{level} (array {})", ds.path)));
                let attrs = group.attributes().get("mdtf").cloned();
                (array, m.axes, scale, shift, attrs, format!("OME-Zarr {version}"))
            }
            Err(_) => {
                let array = Array::open(store.clone(), "/")
                    .map_err(|e| VolumeError::zarr(path, "opening the array")(boxed(e)))?;
                let n = array.dimensionality();
                let names: &[&str] = match n {
                    2 => &["y", "x"],
                    3 => &["z", "y", "x"],
                    4 => &["c", "z", "y", "x"],
                    5 => &["t", "c", "z", "y", "x"],
                    _ => return Err(VolumeError::header(path, format!("a {n}-dimensional array: mdtf reads 2 to 5"))),
                };
                let axes = names.iter().map(|&a| Axis { name: a.into(), kind: None, unit: None }).collect();
                warnings.push(format!(
                    "{}: a plain Zarr array without OME metadata: axes taken as {}, spacing 1",
                    path.display(),
                    names.join(" ")
                ));
                (array, axes, vec![1.0; n], vec![0.0; n], None, "Zarr array".to_string())
            }
        };
        let zarr_version = match array.metadata() {
            zarrs::array::ArrayMetadata::V2(_) => "Zarr v2",
            zarrs::array::ArrayMetadata::V3(_) => "Zarr v3",
        };
        let shape = array.shape().to_vec();
        if axes.len() != shape.len() {
            return Err(VolumeError::header(
                path,
                format!("{} axes named for an array of {} dimensions", axes.len(), shape.len()),
            ));
        }
        let roles = roles_of(path, &axes, &shape)?;
        let ty = sample_type_of(path, array.data_type())?;
        check_chunk_shapes(path, &array, ty)?;
        let at = |role: Role| roles.iter().position(|&r| r == role);
        let mut dims = [1usize; 3];
        let (mut spacing, mut origin) = ([1.0f64; 3], [0.0f64; 3]);
        for g in 0..3 {
            if let Some(a) = at(Role::Space(g)) {
                dims[g] = usize::try_from(shape[a]).map_err(|_| VolumeError::header(path, "the array is too large"))?;
                (spacing[g], origin[g]) = (scale[a], shift[a]);
            }
        }
        let mut geometry = Geometry::new(dims, spacing).with_origin(origin);
        let channels = at(Role::Channel).map_or(1, |a| shape[a] as usize);
        let mut fields: Vec<String> = match channels {
            1 => vec!["value".into()],
            n => (0..n).map(|i| format!("field{i}")).collect(),
        };
        if let Some(value) = attrs {
            match serde_json::from_value::<MdtfAttributes>(value) {
                Ok(m) => {
                    if m.fields.len() == channels {
                        fields = m.fields;
                    }
                    let oriented = Geometry::from_affine(
                        dims,
                        [m.world_from_voxel[0], m.world_from_voxel[1], m.world_from_voxel[2]],
                    );
                    match oriented.filter(|o| level == 0 && agrees(o, &geometry)) {
                        Some(o) => geometry = o,
                        None if level == 0 => warnings.push(format!(
                            "{}: attributes.mdtf.world_from_voxel disagrees with the OME scale and translation: using those (no orientation)",
                            path.display()
                        )),
                        None => {}
                    }
                }
                Err(e) => warnings.push(format!("{}: attributes.mdtf ignored: {e}", path.display())),
            }
        }
        let units: Vec<&str> =
            (0..3).filter_map(|g| at(Role::Space(g))).filter_map(|a| axes[a].unit.as_deref()).collect();
        // the length unit, when every space axis states the same one
        let mut space_unit = None;
        if let Some(u) = units.first() {
            let same = units.iter().all(|v| v == u);
            if same && units.len() == 3 {
                space_unit = Some(u.to_string());
            }
            details.push(("space unit".into(), if same { u.to_string() } else { units.join(", ") }));
            if !same {
                warnings.push(format!(
                    "{}: the axes have different units ({}): mdtf takes each as it is",
                    path.display(),
                    units.join(", ")
                ));
            }
        }
        details.push(("axes".into(), axes.iter().map(|a| a.name.as_str()).collect::<Vec<_>>().join(" ")));
        if let Some(chunk) = array.chunk_grid().chunk_shape(&vec![0; shape.len()]).ok().flatten() {
            let chunk: Vec<String> = chunk.iter().rev().map(|c| c.to_string()).collect();
            details.push(("chunk or shard".into(), format!("{} (x first)", chunk.join("x"))));
        }
        let codecs = codec_names(&serde_json::to_value(array.metadata()).unwrap_or_default());
        details.push(("codecs".into(), if codecs.is_empty() { "none".into() } else { codecs.join(", ") }));
        let info = FileInfo {
            format: format!("{format} ({zarr_version})"),
            sample_type: ty,
            endian: Endian::native(),
            compressed: false,
            scale: None,
            warnings,
            details,
            units: crate::Units { value: None, length: space_unit.map(|u| crate::units::ngff_length_unit(&u)) },
            padding: None,
        };
        Ok(ZarrImage { path: path.to_path_buf(), array, roles, geometry, fields, ty, info })
    }

    /// The grid of the level read.
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// How many fields (channels) the image has.
    pub fn field_count(&self) -> usize {
        self.fields.len()
    }

    /// Refuses an image whose claimed grid (every field's f32 samples) would
    /// not fit in memory, before anything is allocated for it: a store may
    /// claim any shape, its missing chunks being the fill value.
    pub fn check_size(&self) -> Result<()> {
        let dims = self.geometry.dims.map(|d| d as u64);
        crate::limits::check_dims(&self.path, &dims, self.fields.len() as u64).map(|_| ())
    }

    /// The names of the fields (channels), in order.
    pub fn field_names(&self) -> &[String] {
        &self.fields
    }

    /// What the store says about its samples, for `mdtf info`.
    pub fn info(&self) -> &FileInfo {
        &self.info
    }

    /// Planes `z` (clamped to the grid) of every field, placed where they lie,
    /// with `nan` applied.
    pub fn read(&self, z: Range<usize>, nan: NanPolicy) -> Result<MultiField> {
        let nz = self.geometry.dims[2];
        let (z0, z1) = (z.start.min(nz), z.end.min(nz).max(z.start.min(nz)));
        let shape = self.array.shape();
        let ranges: Vec<Range<u64>> = self
            .roles
            .iter()
            .zip(shape)
            .map(|(role, &n)| match role {
                Role::Single => 0..1,
                Role::Space(2) => z0 as u64..z1 as u64,
                Role::Channel | Role::Space(_) => 0..n,
            })
            .collect();
        let what = || format!("reading planes {z0}..{z1}");
        let subset = ArraySubset::new_with_ranges(&ranges);
        let bytes: ArrayBytes<'static> = self
            .array
            .retrieve_array_subset(&subset)
            .map_err(|e| VolumeError::zarr(&self.path, self.failing_chunk(&subset).unwrap_or_else(what))(boxed(e)))?;
        let raw = bytes.into_fixed().map_err(|e| VolumeError::zarr(&self.path, what())(boxed(e)))?;
        let mut samples = vec![0.0f32; raw.len() / self.ty.size()];
        decode_samples(&raw, self.ty, Endian::native(), &mut samples);
        crate::samples::apply_nan_policy(&self.path, nan, &mut samples)?;
        let geometry = self.geometry.z_slab(z0..z1);
        let per_field = geometry.voxel_count();
        let fields = self
            .fields
            .iter()
            .zip(samples.chunks_exact(per_field.max(1)))
            .map(|(name, s)| {
                let data = ndarray::Array3::from_shape_vec(geometry.shape(), s.to_vec())
                    .map_err(|e| VolumeError::header(&self.path, format!("planes {z0}..{z1}: {e}")))?;
                Ok(Field { name: name.clone(), data })
            })
            .collect::<Result<Vec<Field>>>()?;
        MultiField::new(geometry, fields)
    }
}

impl ZarrImage {
    /// "reading chunk KEY" for the first chunk (or shard) of `subset` that
    /// does not decode (a checksum that does not match, a cut file), to
    /// name the file a failed read came from.
    fn failing_chunk(&self, subset: &ArraySubset) -> Option<String> {
        let chunks = self.array.chunks_in_array_subset(subset).ok().flatten()?;
        let bad = chunks
            .indices()
            .into_iter()
            .find(|c| self.array.retrieve_chunk_if_exists::<ArrayBytes<'static>>(c).is_err())?;
        Some(format!("reading chunk {} (its file in the store)", self.array.chunk_key(&bad).as_str()))
    }
}

/// The most bytes one chunk (or subchunk) may decode to: far above any
/// store's chunks (OME-Zarr writers use megabytes), far below a product that
/// overflows the codecs' arithmetic.
const MAX_CHUNK_BYTES: u64 = 1 << 36;

/// Refuses chunk (and subchunk) shapes whose decoded size is absurd, before a
/// codec multiplies them out (a shape of 2^64 - 1 overflowed inside zarrs).
fn check_chunk_shapes(path: &Path, array: &Array<FilesystemStore>, ty: SampleType) -> Result<()> {
    let origin = vec![0u64; array.dimensionality()];
    let chunk: Option<Vec<u64>> =
        array.chunk_grid().chunk_shape(&origin).ok().flatten().map(|c| c.iter().map(|n| n.get()).collect());
    let sub: Option<Vec<u64>> = array.subchunk_shape().map(|c| c.iter().map(|n| n.get()).collect());
    for (what, shape) in [("chunk", chunk), ("subchunk", sub)] {
        let Some(shape) = shape else { continue };
        let bytes = shape.iter().try_fold(ty.size() as u64, |acc, &n| acc.checked_mul(n));
        if bytes.is_none_or(|b| b > MAX_CHUNK_BYTES) {
            return Err(VolumeError::header(
                path,
                format!(
                    "a {what} shape of {shape:?} ({} bytes of {}): not a shape a store holds (at most {MAX_CHUNK_BYTES} bytes a {what})",
                    bytes.map_or("over 2^64".to_string(), |b| b.to_string()),
                    ty.name()
                ),
            ));
        }
    }
    Ok(())
}

/// Whether the oriented geometry `o` (from mdtf's attributes) places the
/// grid as the OME scale and translation `g` do (spacing, and the origin
/// in the grid's axes).
fn agrees(o: &Geometry, g: &Geometry) -> bool {
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * (1.0 + a.abs().max(b.abs()));
    (0..3).all(|a| close(o.spacing[a], g.spacing[a]) && close(grid_translation(o)[a], g.origin[a]))
}

/// The world origin of `g` in the grid's own axes: OME-Zarr's translation.
fn grid_translation(g: &Geometry) -> [f64; 3] {
    std::array::from_fn(|a| (0..3).map(|r| g.directions[a][r] * g.origin[r]).sum())
}

/// Each axis's role: the space axes (by name when they are x, y and z,
/// else by position) must be the last, in z y x order.
fn roles_of(path: &Path, axes: &[Axis], shape: &[u64]) -> Result<Vec<Role>> {
    let is_space = |a: &Axis| match a.kind.as_deref() {
        Some(k) => k == "space",
        None => matches!(a.name.as_str(), "x" | "y" | "z"),
    };
    let space: Vec<usize> = (0..axes.len()).filter(|&i| is_space(&axes[i])).collect();
    if !(2..=3).contains(&space.len()) || space.iter().enumerate().any(|(k, &i)| i != axes.len() - space.len() + k) {
        return Err(VolumeError::header(
            path,
            format!(
                "axes {}: mdtf reads images whose last two or three axes are space (z y x)",
                axes.iter().map(|a| a.name.as_str()).collect::<Vec<_>>().join(" ")
            ),
        ));
    }
    let names: Vec<&str> = space.iter().map(|&i| axes[i].name.as_str()).collect();
    let expected: &[&str] = if space.len() == 3 { &["z", "y", "x"] } else { &["y", "x"] };
    let named = names.iter().all(|n| ["x", "y", "z"].contains(n));
    if named && names != expected {
        return Err(VolumeError::header(
            path,
            format!("space axes {}: mdtf reads them in the order {}", names.join(" "), expected.join(" ")),
        ));
    }
    let mut roles = Vec::with_capacity(axes.len());
    let mut channel = false;
    for (i, a) in axes.iter().enumerate() {
        let role = if let Some(k) = space.iter().position(|&s| s == i) {
            Role::Space(space.len() - 1 - k)
        } else if (a.kind.as_deref() == Some("channel") || (a.kind.is_none() && a.name == "c")) && !channel {
            channel = true;
            Role::Channel
        } else if shape[i] == 1 {
            Role::Single
        } else {
            return Err(VolumeError::header(
                path,
                format!(
                    "axis {} ({}) has {} points: mdtf reads one 3D image (of one or more channels); write the one wanted as a store of its own",
                    a.name,
                    a.kind.as_deref().unwrap_or("no type"),
                    shape[i]
                ),
            ));
        };
        roles.push(role);
    }
    Ok(roles)
}

/// mdtf's sample type of a Zarr data type.
fn sample_type_of(path: &Path, dt: &zarrs::array::DataType) -> Result<SampleType> {
    use zarrs::array::data_type::*;
    let ty = if dt.is::<UInt8DataType>() {
        SampleType::U8
    } else if dt.is::<Int8DataType>() {
        SampleType::I8
    } else if dt.is::<UInt16DataType>() {
        SampleType::U16
    } else if dt.is::<Int16DataType>() {
        SampleType::I16
    } else if dt.is::<UInt32DataType>() {
        SampleType::U32
    } else if dt.is::<Int32DataType>() {
        SampleType::I32
    } else if dt.is::<Float32DataType>() {
        SampleType::F32
    } else if dt.is::<Float64DataType>() {
        SampleType::F64
    } else {
        return Err(VolumeError::UnsupportedType {
            path: path.to_path_buf(),
            name: format!("{dt:?}"),
            supported: crate::dtype::SAMPLE_TYPE_NAMES,
        });
    };
    Ok(ty)
}

/// The codecs of an array's metadata (v3 `codecs`, those inside a shard in
/// brackets; v2 `filters` and `compressor`), e.g. "sharding_indexed(bytes, zstd)".
fn codec_names(meta: &serde_json::Value) -> Vec<String> {
    let name = |c: &serde_json::Value| -> String {
        let own = c.get("name").or_else(|| c.get("id")).and_then(|n| n.as_str()).unwrap_or("?").to_string();
        match c.pointer("/configuration/codecs") {
            Some(inner) => format!("{own}({})", codec_names(&serde_json::json!({ "codecs": inner })).join(", ")),
            None => match c.get("cname").and_then(|n| n.as_str()) {
                Some(cname) => format!("{own}/{cname}"),
                None => own,
            },
        }
    };
    match meta.get("codecs").and_then(|c| c.as_array()) {
        Some(list) => list.iter().map(name).collect(),
        None => {
            let filters = meta.get("filters").and_then(|f| f.as_array()).cloned().unwrap_or_default();
            filters.iter().chain(meta.get("compressor").filter(|c| !c.is_null())).map(name).collect()
        }
    }
}

/// The levels of a multiscale image as "path: NXxNYxNZ, ...", for `mdtf info`.
fn level_list(store: &Arc<FilesystemStore>, m: &Multiscale) -> String {
    m.datasets
        .iter()
        .map(|d| match Array::open(store.clone(), &format!("/{}", d.path.trim_matches('/'))) {
            Ok(a) => {
                let s: Vec<String> = a.shape().iter().rev().map(u64::to_string).collect();
                format!("{}: {}", d.path, s.join("x"))
            }
            Err(_) => format!("{}: (cannot be opened)", d.path),
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The Zarr data type of an mdtf sample type.
fn zarr_data_type(ty: SampleType) -> zarrs::array::DataType {
    match ty {
        SampleType::U8 => data_type::uint8(),
        SampleType::I8 => data_type::int8(),
        SampleType::U16 => data_type::uint16(),
        SampleType::I16 => data_type::int16(),
        SampleType::U32 => data_type::uint32(),
        SampleType::I32 => data_type::int32(),
        SampleType::F32 => data_type::float32(),
        SampleType::F64 => data_type::float64(),
    }
}

/// An OME-Zarr 0.5 image being written plane by plane into a new folder
/// (see the module docs). Publishing the folder is the caller's:
/// [`write_ome_zarr`] writes one atomically.
pub struct ZarrWriter {
    dir: PathBuf,
    array: Array<FilesystemStore>,
    ty: SampleType,
    geometry: Geometry,
    fields: usize,
    bytes: Vec<u8>,
}

impl ZarrWriter {
    /// Creates the store in `dir` (made if missing; it should be empty)
    /// for `fields` on `geometry`, stored as `ty`.
    pub fn create(dir: &Path, geometry: &Geometry, fields: &[String], ty: SampleType) -> Result<ZarrWriter> {
        std::fs::create_dir_all(dir).map_err(|e| VolumeError::io(dir, e))?;
        let err = |what: &str| VolumeError::zarr(dir, what.to_string());
        let store = Arc::new(FilesystemStore::new(dir).map_err(|e| err("creating the store")(boxed(e)))?);
        let [nx, ny, nz] = geometry.dims.map(|d| d as u64);
        let several = fields.len() > 1;
        let mut shape = vec![nz, ny, nx];
        let mut chunk = vec![nz.min(CHUNK_EDGE), ny.min(CHUNK_EDGE), nx.min(CHUNK_EDGE)];
        let round_up = |n: u64, c: u64| n.min(SHARD_EDGE).div_ceil(c) * c;
        let mut shard = vec![chunk[0], round_up(ny, chunk[1]), round_up(nx, chunk[2])];
        let space = |n: &str| Axis { name: n.into(), kind: Some("space".into()), unit: None };
        let mut axes = vec![space("z"), space("y"), space("x")];
        let t = grid_translation(geometry);
        let mut scale = vec![geometry.spacing[2], geometry.spacing[1], geometry.spacing[0]];
        let mut translation = vec![t[2], t[1], t[0]];
        if several {
            shape.insert(0, fields.len() as u64);
            chunk.insert(0, 1);
            shard.insert(0, 1);
            axes.insert(0, Axis { name: "c".into(), kind: Some("channel".into()), unit: None });
            scale.insert(0, 1.0);
            translation.insert(0, 0.0);
        }
        let names: Vec<String> = axes.iter().map(|a| a.name.clone()).collect();
        let zero = zarrs::array::FillValue::new(vec![0u8; ty.size()]);
        let mut builder = ArrayBuilder::new(shape, shard, zarr_data_type(ty), zero);
        builder
            .subchunk_shape(chunk)
            .bytes_to_bytes_codecs(vec![Arc::new(zarrs::array::codec::ZstdCodec::new(ZSTD_LEVEL, true))])
            .dimension_names(Some(names));
        let array = builder.build(store.clone(), "/0").map_err(|e| err("creating array 0")(boxed(e)))?;
        array.store_metadata().map_err(|e| err("writing array 0's metadata")(boxed(e)))?;
        let multiscale = Multiscale {
            version: None,
            name: None,
            axes,
            datasets: vec![Dataset {
                path: "0".into(),
                transforms: vec![Transform::Scale { scale }, Transform::Translation { translation }],
            }],
            transforms: None,
        };
        let mdtf = MdtfAttributes { world_from_voxel: geometry.world_from_voxel(), fields: fields.to_vec() };
        let json = |v: serde_json::Result<serde_json::Value>| v.map_err(|e| err("writing the metadata")(boxed(e)));
        let mut attributes = serde_json::Map::new();
        attributes.insert(
            "ome".into(),
            serde_json::json!({"version": "0.5", "multiscales": [json(serde_json::to_value(&multiscale))?]}),
        );
        attributes.insert("mdtf".into(), json(serde_json::to_value(&mdtf))?);
        zarrs::group::GroupBuilder::new()
            .attributes(attributes)
            .build(store, "/")
            .map_err(|e| err("creating the group")(boxed(e)))?
            .store_metadata()
            .map_err(|e| err("writing the group's metadata")(boxed(e)))?;
        Ok(ZarrWriter {
            dir: dir.to_path_buf(),
            array,
            ty,
            geometry: geometry.clone(),
            fields: fields.len(),
            bytes: Vec::new(),
        })
    }

    /// Writes planes `z0..` of every field: `fields[f]` holds whole planes
    /// of field f, x fastest, the same number for each.
    pub fn write_planes(&mut self, z0: usize, fields: &[&[f32]]) -> Result<()> {
        let plane = self.geometry.dims[0] * self.geometry.dims[1];
        let planes = fields.first().map_or(0, |f| f.len() / plane.max(1));
        if fields.len() != self.fields
            || fields.iter().any(|f| f.len() != planes * plane)
            || z0 + planes > self.geometry.dims[2]
        {
            return Err(VolumeError::Fields(format!(
                "{}: planes {z0}.. of {} field(s) do not fit the store's {} field(s) of {}",
                self.dir.display(),
                fields.len(),
                self.fields,
                self.geometry.dims_string()
            )));
        }
        if planes == 0 {
            return Ok(());
        }
        self.bytes.clear();
        for f in fields {
            if let Some((index, value)) = first_unrepresentable(f, self.ty) {
                return Err(VolumeError::NotRepresentable {
                    path: self.dir.clone(),
                    value,
                    index: z0 * plane + index,
                    target: self.ty.name(),
                });
            }
            encode_samples(f, self.ty, Endian::native(), &mut self.bytes);
        }
        let [nx, ny, _] = self.geometry.dims.map(|d| d as u64);
        let mut ranges = vec![z0 as u64..(z0 + planes) as u64, 0..ny, 0..nx];
        if self.fields > 1 {
            ranges.insert(0, 0..self.fields as u64);
        }
        let data = ArrayBytes::new_flen(std::mem::take(&mut self.bytes));
        let what = format!("writing planes {z0}..{}", z0 + planes);
        self.array
            .store_array_subset(&ArraySubset::new_with_ranges(&ranges), data)
            .map_err(|e| VolumeError::zarr(&self.dir, what)(boxed(e)))
    }
}

/// Writes `mf` as an OME-Zarr 0.5 store at `path`, atomically: built
/// beside it and swapped in whole; an existing `path` is replaced only if
/// mdtf made it and it holds none of `inputs`.
pub fn write_ome_zarr(path: &Path, mf: &MultiField, ty: SampleType, inputs: &crate::output::Inputs) -> Result<()> {
    let out = crate::output::OutputFolder::begin(path, inputs)?;
    let names: Vec<String> = mf.fields.iter().map(|f| f.name.clone()).collect();
    let mut w = ZarrWriter::create(out.path(), &mf.geometry, &names, ty)?;
    let samples: Vec<&[f32]> = mf
        .fields
        .iter()
        .map(|f| f.data.as_slice().ok_or_else(|| VolumeError::Fields("a field is not contiguous".into())))
        .collect::<Result<_>>()?;
    w.write_planes(0, &samples)?;
    drop(w);
    out.publish(inputs)
}
