//! Mutation fuzzing of every reader, in process: NIfTI (plain, gzip,
//! NIfTI-2, .hdr/.img pair, Analyze 7.5),
//! NRRD (attached, detached, gzip, ascii), MetaImage (attached, zlib,
//! detached), TIFF, DICOM, OME-Zarr (group and array metadata, a shard;
//! read as `mdtf info` reads a store), raw, legacy VTK, VTU, pack
//! manifests (read as the preview reads them), pipeline TOML and TF JSON.
//!
//! Each case mutates a valid seed file (bit flips, interesting integers and
//! numbers, insertions, deletions, truncations, duplicated lines) and reads
//! it. A case fails on a panic, on taking more than [`MAX_CASE`], or on a
//! peak of live heap above [`ALLOCATION_FACTOR`] x its size (for gzip
//! files, x its largest decoded size) plus [`FIXED_BUFFERS`] for the
//! readers' fixed-size buffers.
//!
//! `cargo test` runs a short round ([`SHORT_CASES`] per reader, proptest
//! seeds); `cargo test --release -p mdtf-e2e --test fuzz -- --ignored
//! --nocapture` runs the long one, `MDTF_FUZZ_CASES` per reader
//! (1,000,000 by default), and prints cases and time per reader
//! (`MDTF_FUZZ_ONLY=VTK` runs the readers whose name holds "VTK").

use peak_alloc::PeakAlloc;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

#[global_allocator]
static PEAK: PeakAlloc = PeakAlloc;

/// The heap peak is the process's: tests that measure it run one at a time,
/// or one's allocations (building its seeds: packs, tables) count against the other's cases.
static HEAP_MEASURED: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn heap_measured_alone() -> std::sync::MutexGuard<'static, ()> {
    HEAP_MEASURED.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Longest a case may run.
const MAX_CASE: Duration = Duration::from_secs(5);
/// Peak live heap allowed per byte of input.
const ALLOCATION_FACTOR: usize = 64;
/// Heap allowed whatever the input: read buffers of fixed size (a chunk of
/// 64 Ki samples, buffered readers, the parsers' tables).
const FIXED_BUFFERS: usize = 2 << 20;
/// Largest expansion of a deflate stream.
const DEFLATE_MAX_RATIO: usize = 1032;
/// The window libzstd allocates at most for a frame (its default limit,
/// 2^27 bytes): a frame header may claim it whatever the frame's size.
const ZSTD_MAX_WINDOW: usize = 1 << 27;
/// Cases per reader in `cargo test`.
const SHORT_CASES: usize = 300;

/// Reads one input (writing it to a file first where the reader needs one).
type ReadOne = Box<dyn Fn(&[u8]) + Send + Sync>;

/// One reader under test: seeds, and how to read one input.
struct Reader {
    name: &'static str,
    seeds: Vec<Vec<u8>>,
    text: bool,
    gzip: bool,
    /// Heap a decoder may take whatever the input (beyond [`FIXED_BUFFERS`]).
    window: usize,
    read: ReadOne,
}

const INTERESTING_TEXT: &[&str] = &[
    "0",
    "-1",
    "1",
    "2",
    "3",
    "4",
    "7",
    "255",
    "65536",
    "2147483648",
    "4294967296",
    "999999999999",
    "18446744073709551615",
    "-9223372036854775808",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "1e-308",
    "-0",
    "0.5",
    "",
    "LIST",
    "../x",
    "(nan,0,0)",
    "none",
];
const INTERESTING_INT: &[i64] =
    &[0, -1, 1, 2, 3, 4, 7, 8, 9, 127, 128, 255, 256, 348, 540, 32767, -32768, 65535, 1 << 31, -(1 << 31), 1 << 40];

/// Applies 1 to 4 random mutations to `seed`.
fn mutate(seed: &[u8], rng: &mut ChaCha8Rng, text: bool) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..rng.random_range(1..=4) {
        let len = b.len();
        let at = if len == 0 { 0 } else { rng.random_range(0..len) };
        match rng.random_range(0..9) {
            0 if len > 0 => b[at] ^= 1 << rng.random_range(0..8),
            1 if len > 0 => b[at] = [0u8, 0xff, 0x7f, 0x80, b'\n', b' ', b':', b'-'][rng.random_range(0..8)],
            2 => {
                let n = rng.random_range(1..16);
                let bytes: Vec<u8> = (0..n).map(|_| rng.random()).collect();
                b.splice(at..at, bytes);
            }
            3 if len > 0 => {
                let end = (at + rng.random_range(1..64)).min(len);
                b.drain(at..end);
            }
            4 => b.truncate(at),
            5 if len > 0 => {
                let end = (at + rng.random_range(1..128)).min(len);
                let piece = b[at..end].to_vec();
                let to = rng.random_range(0..=b.len());
                b.splice(to..to, piece);
            }
            6 if !text && len >= 4 => {
                let v = INTERESTING_INT[rng.random_range(0..INTERESTING_INT.len())];
                let width = [2usize, 4, 8][rng.random_range(0..3)].min(len);
                let at = rng.random_range(0..=len - width);
                let bytes = if rng.random() { v.to_le_bytes() } else { v.to_be_bytes() };
                b[at..at + width].copy_from_slice(&bytes[..width]);
            }
            7 | 6 => replace_number(&mut b, rng),
            _ => {
                // duplicate or drop a line
                let lines: Vec<&[u8]> = b.split(|&c| c == b'\n').collect();
                if lines.len() > 1 {
                    let i = rng.random_range(0..lines.len());
                    let mut out: Vec<Vec<u8>> = lines.iter().map(|l| l.to_vec()).collect();
                    if rng.random() {
                        out.insert(i, out[i].clone());
                    } else {
                        out.remove(i);
                    }
                    b = out.join(&b'\n');
                }
            }
        }
    }
    b
}

/// Replaces one run of digits (a number in a text header) by an interesting text.
fn replace_number(b: &mut Vec<u8>, rng: &mut ChaCha8Rng) {
    let starts: Vec<usize> =
        (0..b.len()).filter(|&i| b[i].is_ascii_digit() && (i == 0 || !b[i - 1].is_ascii_digit())).collect();
    if starts.is_empty() {
        return;
    }
    let s = starts[rng.random_range(0..starts.len())];
    let e = (s..b.len()).find(|&i| !(b[i].is_ascii_digit() || b[i] == b'.')).unwrap_or(b.len());
    let with = INTERESTING_TEXT[rng.random_range(0..INTERESTING_TEXT.len())].as_bytes().to_vec();
    b.splice(s..e, with);
}

/// A folder in memory-backed storage where it exists, for the case files.
fn scratch() -> tempfile::TempDir {
    let shm = Path::new("/dev/shm");
    if shm.is_dir()
        && let Ok(d) = tempfile::tempdir_in(shm)
    {
        return d;
    }
    tempfile::tempdir().unwrap()
}

/// Valid small volume files of every kind mdtf writes, as bytes, and the pack folder.
struct Seeds {
    dir: tempfile::TempDir,
}

impl Seeds {
    fn new() -> Seeds {
        use mdtf_volume::{MultiField, WriteOptions, write};
        let dir = tempfile::tempdir().unwrap();
        let geo = mdtf_volume::Geometry::new([6, 5, 5], [1.0, 0.5, 2.0]);
        let v = mdtf_datagen::erf_sphere(geo, 2.0, 0.7, 0.0, 255.0, None).volume();
        let mf = MultiField::from(v.clone());
        let u8v = MultiField::from(mdtf_volume::Volume {
            geometry: v.geometry.clone(),
            data: v.data.mapv(|x| x.round().clamp(0.0, 255.0)),
        });
        let f32o = WriteOptions::default();
        let u8o = WriteOptions { ty: mdtf_volume::SampleType::U8, gzip: false };
        for (name, m, o) in [
            ("a.nii", &mf, f32o),
            ("b.nii", &u8v, u8o),
            ("a.nii.gz", &mf, f32o),
            ("a.nrrd", &mf, f32o),
            ("b.nrrd", &u8v, u8o),
            ("g.nrrd", &mf, WriteOptions { gzip: true, ..f32o }),
            ("d.nhdr", &mf, f32o),
            ("a.mha", &mf, f32o),
            ("b.mha", &u8v, u8o),
            ("m.mhd", &mf, f32o),
            ("p.hdr", &u8v, u8o),
            ("s.ome.zarr", &mf, f32o),
        ] {
            write(&dir.path().join(name), m, &o, &[]).unwrap();
        }
        let pack = mdtf_pack::PackParams {
            profile: mdtf_pack::Profile::Slicer3dtf,
            ranges: Default::default(),
            fields: Vec::new(),
            dtype: None,
            nifti: false,
        };
        let chans = mdtf_pipeline::channels::compute(
            &mf,
            &mdtf_pack::Profile::Slicer3dtf.channels(&[]),
            &mdtf_pipeline::boundary_chain::BoundaryChainParams::default(),
        )
        .unwrap();
        let ranges = mdtf_pipeline::pack_inputs::ranges(&chans, &Default::default(), None).unwrap();
        let pack = mdtf_pack::PackParams { ranges, ..pack };
        let luts = mdtf_pipeline::pack_inputs::luts(
            mdtf_pack::Profile::Slicer3dtf,
            None,
            &mdtf_boundary::AlphaMap::Linear { a: 1.0, dc: Some(3.0) },
            &chans,
            &pack.ranges,
            None,
            &mdtf_derive::DeriveParams::default(),
        )
        .unwrap();
        let provenance = mdtf_pack::Provenance {
            mdtf_version: "fuzz".into(),
            input: None,
            input_sha256: None,
            stages: serde_json::Value::Null,
            ..Default::default()
        };
        std::fs::create_dir(dir.path().join("pk")).unwrap();
        mdtf_pack::pack(&chans, &pack, &luts, &dir.path().join("pk"), provenance, &Default::default()).unwrap();
        Seeds { dir }
    }

    fn bytes(&self, name: &str) -> Vec<u8> {
        std::fs::read(self.dir.path().join(name)).unwrap()
    }

    /// `b.nii` (u8, 6 x 5 x 5) with a NIfTI-2 header (nifti2.h offsets) in place of its NIfTI-1 one.
    fn nifti2(&self) -> Vec<u8> {
        let one = self.bytes("b.nii");
        let (i16_at, f32_at) = (
            |at: usize| i16::from_le_bytes([one[at], one[at + 1]]),
            |at: usize| f32::from_le_bytes([one[at], one[at + 1], one[at + 2], one[at + 3]]),
        );
        let mut h = vec![0u8; 544];
        let mut put = |at: usize, b: &[u8]| h[at..at + b.len()].copy_from_slice(b);
        put(0, &540i32.to_le_bytes());
        put(4, b"n+2\0\r\n\x1a\n");
        put(12, &i16_at(70).to_le_bytes());
        put(14, &i16_at(72).to_le_bytes());
        for k in 0..8 {
            put(16 + 8 * k, &i64::from(i16_at(40 + 2 * k)).to_le_bytes());
            put(104 + 8 * k, &f64::from(f32_at(76 + 4 * k)).to_le_bytes());
        }
        put(168, &544i64.to_le_bytes());
        put(176, &1.0f64.to_le_bytes());
        put(344, &i32::from(i16_at(252)).to_le_bytes());
        put(348, &i32::from(i16_at(254)).to_le_bytes());
        for k in 0..18 {
            put(352 + 8 * k, &f64::from(f32_at(256 + 4 * k)).to_le_bytes());
        }
        put(500, &i32::from(one[123]).to_le_bytes());
        [h, one[352..].to_vec()].concat()
    }
}

const TET_VTK: &str = "# vtk DataFile Version 4.2\nmesh\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 5 float\n\
0 0 0 1 0 0 0 1 0 0 0 1 1 1 1\nCELLS 2 10\n4 0 1 2 3\n4 1 2 3 4\nCELL_TYPES 2\n10\n10\n\
POINT_DATA 5\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2 3 4 5\n";

const TET_VTU: &str = r#"<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">
<UnstructuredGrid>
<Piece NumberOfPoints="4" NumberOfCells="1">
<PointData Scalars="s"><DataArray type="Float32" Name="s" format="ascii">1 2 3 4</DataArray></PointData>
<Points><DataArray type="Float32" NumberOfComponents="3" format="ascii">0 0 0 1 0 0 0 1 0 0 0 1</DataArray></Points>
<Cells>
<DataArray type="Int64" Name="connectivity" format="ascii">0 1 2 3</DataArray>
<DataArray type="Int64" Name="offsets" format="ascii">4</DataArray>
<DataArray type="UInt8" Name="types" format="ascii">10</DataArray>
</Cells>
</Piece>
</UnstructuredGrid>
</VTKFile>
"#;

/// A small valid 3-page grayscale TIFF (uncompressed, 16-bit, little-endian).
fn tiff_seed() -> Vec<u8> {
    let (w, h, pages) = (4u32, 3u32, 3u32);
    let mut b = b"II*\0".to_vec();
    b.extend(8u32.to_le_bytes());
    for p in 0..pages {
        let data_at = b.len() as u32 + 2 + 9 * 12 + 4;
        let next = if p + 1 < pages { data_at + w * h * 2 } else { 0 };
        let entry = |tag: u16, ty: u16, value: u32| {
            let mut e = tag.to_le_bytes().to_vec();
            e.extend(ty.to_le_bytes());
            e.extend(1u32.to_le_bytes());
            e.extend(value.to_le_bytes());
            e
        };
        b.extend(9u16.to_le_bytes());
        for e in [
            entry(256, 4, w),
            entry(257, 4, h),
            entry(258, 3, 16),
            entry(259, 3, 1),
            entry(262, 3, 1),
            entry(273, 4, data_at),
            entry(277, 3, 1),
            entry(278, 4, h),
            entry(279, 4, w * h * 2),
        ] {
            b.extend(e);
        }
        b.extend(next.to_le_bytes());
        for i in 0..w * h {
            b.extend(((p * 100 + i) as u16).to_le_bytes());
        }
    }
    b
}

/// Copies the files of folder `from` (recursively) into `to`.
fn copy_folder(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_folder(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

/// A reader of files: writes each case to `dir/name` and reads it with `f`.
fn file_reader(
    name: &'static str,
    file: &'static str,
    seeds: Vec<Vec<u8>>,
    text: bool,
    gzip: bool,
    dir: &Path,
    f: impl Fn(&Path) + Send + Sync + 'static,
) -> Reader {
    let path = dir.join(file);
    Reader {
        name,
        seeds,
        text,
        gzip,
        window: 0,
        read: Box::new(move |bytes| {
            std::fs::write(&path, bytes).unwrap();
            f(&path);
        }),
    }
}

fn readers(seeds: &Seeds, dir: &Path) -> Vec<Reader> {
    use mdtf_volume::{Endian, RawSpec, ReadOptions, SampleType, read, read_raw};
    let read_volume = |p: &Path| {
        let _ = read(p, &ReadOptions::default());
    };
    // a detached header's data file stays valid; the header is mutated
    std::fs::copy(seeds.dir.path().join("d.raw"), dir.join("d.raw")).unwrap();
    std::fs::copy(seeds.dir.path().join("m.raw"), dir.join("m.raw")).unwrap();
    std::fs::copy(seeds.dir.path().join("p.img"), dir.join("p.img")).unwrap();
    std::fs::copy(seeds.dir.path().join("p.img"), dir.join("q.img")).unwrap();
    // three copies of a store, in each of which one file is mutated: the group's and the array's
    // metadata and the one shard
    for copy in ["z1", "z2", "z3"] {
        copy_folder(&seeds.dir.path().join("s.ome.zarr"), &dir.join(copy));
    }
    let store_of = |levels: usize| {
        move |p: &Path| {
            let store = p.ancestors().nth(levels).unwrap();
            // what `mdtf info` does: bounded by the chunks the store holds, whatever grid it claims
            if let Ok(image) = mdtf_volume::ome_zarr::ZarrImage::open(store, 0)
                && image.check_size().is_ok()
            {
                let _ = image.visit_stored(|_, _| {});
            }
        }
    };
    // the pair's header without its NIfTI magic is an Analyze 7.5 header
    let mut analyze = seeds.bytes("p.hdr");
    analyze[344..348].fill(0);
    let zlib_mha = {
        let raw = std::fs::read(seeds.dir.path().join("m.raw")).unwrap();
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut z, &raw).unwrap();
        let packed = z.finish().unwrap();
        let head =
            String::from_utf8(seeds.bytes("m.mhd")).unwrap().replace("CompressedData = False", "CompressedData = True");
        [head.replace("ElementDataFile = m.raw", "ElementDataFile = LOCAL").into_bytes(), packed].concat()
    };
    let pack_dir = dir.join("pk");
    std::fs::create_dir(&pack_dir).unwrap();
    for e in std::fs::read_dir(seeds.dir.path().join("pk")).unwrap().flatten() {
        std::fs::copy(e.path(), pack_dir.join(e.file_name())).unwrap();
    }
    let ascii = b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2 2 1\nspacings: 1 1 2\nencoding: ascii\n\n1 2\n3 4.5\n";
    let raw_spec = RawSpec {
        dims: [4, 3, 2],
        ty: SampleType::U16,
        endian: Endian::Big,
        spacing: [1.0; 3],
        origin: [0.0; 3],
        byte_skip: 0,
    };
    vec![
        file_reader("NIfTI", "c.nii", vec![seeds.bytes("a.nii"), seeds.bytes("b.nii")], false, false, dir, read_volume),
        file_reader("NIfTI gzip", "c.nii.gz", vec![seeds.bytes("a.nii.gz")], false, true, dir, read_volume),
        file_reader(
            "NRRD attached",
            "c.nrrd",
            vec![seeds.bytes("a.nrrd"), seeds.bytes("b.nrrd")],
            false,
            false,
            dir,
            read_volume,
        ),
        file_reader("NRRD gzip", "g.nrrd", vec![seeds.bytes("g.nrrd")], false, true, dir, read_volume),
        file_reader("NRRD ascii", "t.nrrd", vec![ascii.to_vec()], true, false, dir, read_volume),
        file_reader("NRRD detached", "d.nhdr", vec![seeds.bytes("d.nhdr")], true, false, dir, read_volume),
        file_reader(
            "MetaImage",
            "c.mha",
            vec![seeds.bytes("a.mha"), seeds.bytes("b.mha")],
            false,
            false,
            dir,
            read_volume,
        ),
        file_reader("MetaImage zlib", "z.mha", vec![zlib_mha], false, true, dir, read_volume),
        file_reader("MetaImage .mhd", "m.mhd", vec![seeds.bytes("m.mhd")], true, false, dir, read_volume),
        file_reader("TIFF", "t.tif", vec![tiff_seed()], false, false, dir, read_volume),
        file_reader(
            "DICOM",
            "s.dcm",
            vec![mdtf_e2e::dicom_slice(mdtf_e2e::EXPLICIT_LE, 4, 3, Some(2.5), 24)],
            false,
            false,
            dir,
            read_volume,
        ),
        file_reader("NIfTI-2", "n2.nii", vec![seeds.nifti2()], false, false, dir, read_volume),
        // a pair's and an Analyze header's data file stays valid; the header is mutated
        file_reader("NIfTI pair", "p.hdr", vec![seeds.bytes("p.hdr")], false, false, dir, read_volume),
        file_reader("Analyze", "q.hdr", vec![analyze], false, false, dir, read_volume),
        file_reader(
            "OME-Zarr group metadata",
            "z1/zarr.json",
            vec![seeds.bytes("s.ome.zarr/zarr.json")],
            true,
            false,
            dir,
            store_of(1),
        ),
        file_reader(
            "OME-Zarr array metadata",
            "z2/0/zarr.json",
            vec![seeds.bytes("s.ome.zarr/0/zarr.json")],
            true,
            false,
            dir,
            store_of(2),
        ),
        // a zstd frame header may claim a window of up to 128 MiB, which libzstd allocates
        Reader {
            window: ZSTD_MAX_WINDOW,
            ..file_reader(
                "OME-Zarr shard",
                "z3/0/c/0/0/0",
                vec![seeds.bytes("s.ome.zarr/0/c/0/0/0")],
                false,
                false,
                dir,
                store_of(5),
            )
        },
        file_reader("raw", "r.raw", vec![vec![7u8; 48]], false, false, dir, move |p| {
            let _ = read_raw(p, &raw_spec, &ReadOptions::default());
        }),
        file_reader("VTK legacy", "m.vtk", vec![TET_VTK.as_bytes().to_vec()], true, false, dir, |p| {
            let _ = mdtf_tetra::read_mesh(p, None);
        }),
        file_reader("VTU", "m.vtu", vec![TET_VTU.as_bytes().to_vec()], true, false, dir, |p| {
            let _ = mdtf_tetra::read_mesh(p, None);
        }),
        file_reader(
            "pack manifest",
            "pk/manifest.json",
            vec![seeds.bytes("pk/manifest.json")],
            true,
            false,
            dir,
            move |p| {
                let _ = mdtf_preview::load(p.parent().unwrap());
            },
        ),
        Reader {
            name: "pipeline TOML",
            seeds: ["slicer-3dtf", "distance-tf", "peak-finding"]
                .iter()
                .map(|n| std::fs::read(mdtf_e2e::shipped_pipeline(n)).unwrap())
                .collect(),
            text: true,
            gzip: false,
            window: 0,
            read: Box::new(|b| {
                let _ = mdtf_pipeline::file::parse(&String::from_utf8_lossy(b), &[]);
            }),
        },
        Reader {
            name: "TF JSON",
            seeds: vec![std::fs::read(mdtf_e2e::pipelines_dir().join("peak-finding-tf.json")).unwrap()],
            text: true,
            gzip: false,
            window: 0,
            read: Box::new(|b| {
                let _ = mdtf_pack::parse_tf(&String::from_utf8_lossy(b));
            }),
        },
    ]
}

/// What one reader's round found.
struct Round {
    cases: usize,
    seconds: f64,
    /// The largest peak of live heap as a share of its case's budget, with its peak and input size.
    worst: (f64, usize, usize),
    failures: Vec<String>,
}

/// Runs `cases` mutated inputs through `reader`, seeded by `seed`.
fn fuzz(reader: &Reader, cases: usize, seed: u64) -> Round {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let started = Instant::now();
    let current: Arc<Mutex<(Instant, Vec<u8>)>> = Arc::new(Mutex::new((Instant::now(), Vec::new())));
    let done = Arc::new(AtomicU64::new(0));
    // the watchdog: a case stuck past MAX_CASE ends the process with its input
    let watch = {
        let current = Arc::clone(&current);
        let done = Arc::clone(&done);
        let name = reader.name;
        std::thread::spawn(move || {
            while done.load(Ordering::Relaxed) == 0 {
                std::thread::sleep(Duration::from_millis(200));
                let (t, bytes) = &*current.lock().unwrap();
                if t.elapsed() > MAX_CASE && !bytes.is_empty() {
                    eprintln!("{name}: a case ran over {MAX_CASE:?}; its input ({} bytes): {bytes:?}", bytes.len());
                    std::process::exit(3);
                }
            }
        })
    };
    let mut failures = Vec::new();
    let mut worst = (0.0f64, 0usize, 0usize);
    for _ in 0..cases {
        let seed_bytes = &reader.seeds[rng.random_range(0..reader.seeds.len())];
        let input = mutate(seed_bytes, &mut rng, reader.text);
        *current.lock().unwrap() = (Instant::now(), input.clone());
        let base = PEAK.current_usage();
        PEAK.reset_peak_usage();
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| (reader.read)(&input)));
        let peak = PEAK.peak_usage().saturating_sub(base);
        current.lock().unwrap().1.clear();
        let size = input.len().max(1) * if reader.gzip { DEFLATE_MAX_RATIO } else { 1 };
        let budget = ALLOCATION_FACTOR * size + FIXED_BUFFERS + reader.window;
        if peak as f64 / budget as f64 > worst.0 {
            worst = (peak as f64 / budget as f64, peak, input.len());
        }
        if result.is_err() {
            failures.push(format!("panic on {} bytes: {:?}", input.len(), String::from_utf8_lossy(&input)));
        } else if peak > budget {
            if let Ok(keep) = std::env::var("MDTF_FUZZ_KEEP") {
                let _ = std::fs::write(format!("{keep}-{}-{}", reader.name.replace(' ', "_"), failures.len()), &input);
            }
            failures.push(format!("{peak} bytes of heap for {} input bytes", input.len()));
        }
        if failures.len() >= 5 {
            break;
        }
    }
    done.store(1, Ordering::Relaxed);
    let _ = watch.join();
    Round { cases, seconds: started.elapsed().as_secs_f64(), worst, failures }
}

fn run_all(cases: usize, print: bool) {
    let seeds = Seeds::new();
    let dir = scratch();
    let readers = readers(&seeds, dir.path());
    // panics are caught and counted; their messages would only flood the output
    std::panic::set_hook(Box::new(|_| {}));
    let mut failed = Vec::new();
    let only = std::env::var("MDTF_FUZZ_ONLY").unwrap_or_default();
    for (k, reader) in readers.iter().enumerate().filter(|(_, r)| r.name.contains(only.as_str())) {
        let round = fuzz(reader, cases, 0x6d64_7466 + k as u64);
        if print {
            println!(
                "{:<16} {:>9} cases in {:>7.1} s ({:>6.1} us/case); largest heap peak {:>5.1} % of its budget ({} bytes for {} input bytes); {} failures",
                reader.name,
                round.cases,
                round.seconds,
                round.seconds / round.cases as f64 * 1e6,
                round.worst.0 * 100.0,
                round.worst.1,
                round.worst.2,
                round.failures.len()
            );
        }
        for f in round.failures {
            failed.push(format!("{}: {f}", reader.name));
        }
    }
    let _ = std::panic::take_hook();
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}

#[test]
fn mutated_files_never_panic_hang_or_allocate_beyond_their_size() {
    let _alone = heap_measured_alone();
    run_all(SHORT_CASES, false);
}

/// The long round: `MDTF_FUZZ_CASES` per reader (1,000,000 by default).
#[test]
#[ignore = "long: run with --ignored --nocapture"]
fn long_fuzz_round() {
    let _alone = heap_measured_alone();
    let cases = std::env::var("MDTF_FUZZ_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(1_000_000);
    run_all(cases, true);
}

/// Heap a reader may take for a small file claiming a huge grid.
const CLAIM_BOUND: usize = 64 << 20;

#[test]
fn a_small_file_claiming_800_cubed_costs_little_memory() {
    let _alone = heap_measured_alone();
    use mdtf_volume::{Endian, RawSpec, ReadOptions, SampleType, read, read_raw};
    let seeds = Seeds::new();
    let dir = scratch();
    let mut nii = seeds.bytes("a.nii");
    for (k, v) in [3i16, 800, 800, 800].iter().enumerate() {
        nii[40 + 2 * k..42 + 2 * k].copy_from_slice(&v.to_le_bytes());
    }
    nii.resize(16 * 1024, 0);
    let mut gz_nrrd =
        b"NRRD0004\ntype: float\ndimension: 3\nsizes: 800 800 800\nendian: little\nencoding: gzip\n\n".to_vec();
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut enc, &[0u8; 16]).unwrap();
    gz_nrrd.extend(enc.finish().unwrap());
    let cases: [(&str, Vec<u8>); 3] = [("claim.nii", nii), ("claim.nrrd", gz_nrrd), ("claim.raw", vec![0u8; 4096])];
    for (name, bytes) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, &bytes).unwrap();
        let base = PEAK.current_usage();
        PEAK.reset_peak_usage();
        let result = if name.ends_with(".raw") {
            let spec = RawSpec {
                dims: [800; 3],
                ty: SampleType::F32,
                endian: Endian::Little,
                spacing: [1.0; 3],
                origin: [0.0; 3],
                byte_skip: 0,
            };
            read_raw(&path, &spec, &ReadOptions::default()).map(|_| ())
        } else {
            read(&path, &ReadOptions::default()).map(|_| ())
        };
        let peak = PEAK.peak_usage().saturating_sub(base);
        let e = result.expect_err(name).to_string();
        assert!(e.contains("truncated"), "{name}: {e}");
        assert!(peak < CLAIM_BOUND, "{name} ({} bytes) took {peak} bytes of heap", bytes.len());
    }
}
