//! The bad-input corpus: malformed files for every reader and unsafe output
//! requests for every writer. Each case asserts a non-zero exit, a message
//! that names the file and the problem, no panic text, no partial output,
//! and every file of the case folder byte for byte as it was.

use mdtf_e2e::mdtf_path;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// Every file under `dir` (relative path -> bytes); folders as empty entries.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Option<Vec<u8>>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            let rel = p.strip_prefix(dir).unwrap().to_path_buf();
            if e.file_type().unwrap().is_dir() {
                out.insert(rel, None);
                stack.push(p);
            } else {
                out.insert(rel, Some(std::fs::read(&p).unwrap_or_default()));
            }
        }
    }
    out
}

/// Valid small inputs, made once: an 8^3 sphere as NIfTI, NRRD and
/// `.nhdr`+`.raw`, a slicer-3dtf pack of it, and a one-tetrahedron mesh.
/// They live in the build's own scratch folder (a static is never dropped,
/// so a temporary folder would be left in the user's TMPDIR).
fn base() -> &'static Path {
    static BASE: OnceLock<PathBuf> = OnceLock::new();
    BASE.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("corpus-base");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let run = |args: &[&str]| {
            let out = Command::new(mdtf_path()).args(args).current_dir(&dir).output().unwrap();
            assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        };
        run(&["synth", "erf-sphere", "-o", "v.nii", "--size", "8", "--sigma", "1", "-q"]);
        run(&["convert", "v.nii", "v.nrrd", "-q"]);
        run(&["convert", "v.nii", "v.nhdr", "-q"]);
        run(&["convert", "v.nii", "v.ome.zarr", "-q"]);
        run(&["pack", "v.nii", "--profile", "slicer-3dtf", "-o", "pk", "-q"]);
        std::fs::write(dir.join("m.vtk"), tet_vtk("CELLS 1 5\n4 0 1 2 3\n")).unwrap();
        dir
    })
}

fn tet_vtk(cells: &str) -> String {
    format!(
        "# vtk DataFile Version 4.2\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\n\
         {cells}CELL_TYPES 1\n10\nPOINT_DATA 4\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2 3 4\n"
    )
}

/// Sets the shape ([z, y, x]) the base OME-Zarr store copied into `dir` claims.
fn claim_zarr_shape(dir: &Path, shape: [u64; 3]) {
    let path = dir.join("v.ome.zarr/0/zarr.json");
    let mut meta: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    meta["shape"] = serde_json::json!(shape);
    std::fs::write(&path, serde_json::to_vec_pretty(&meta).unwrap()).unwrap();
}

/// A DICOM file of `dicom_slice` with RescaleIntercept and RescaleSlope
/// (DS text) inserted before its pixel data, as the tag order wants.
fn with_rescale(slice: Vec<u8>, slope: &str, intercept: &str) -> Vec<u8> {
    let pixels = slice.windows(4).rposition(|w| w == [0xE0, 0x7F, 0x10, 0x00]).unwrap();
    let pad = |t: &str| if t.len() % 2 == 1 { format!("{t} ") } else { t.to_string() };
    let mut out = slice[..pixels].to_vec();
    out.extend(mdtf_e2e::dicom_element(0x0028, 0x1052, "DS", pad(intercept).as_bytes()));
    out.extend(mdtf_e2e::dicom_element(0x0028, 0x1053, "DS", pad(slope).as_bytes()));
    out.extend(&slice[pixels..]);
    out
}

fn base_bytes(name: &str) -> Vec<u8> {
    std::fs::read(base().join(name)).unwrap()
}

/// Copies a file or folder of the base set into `dir`.
fn copy_base(name: &str, dir: &Path) {
    let from = base().join(name);
    if from.is_dir() {
        let mut stack = vec![PathBuf::from(name)];
        while let Some(rel) = stack.pop() {
            std::fs::create_dir_all(dir.join(&rel)).unwrap();
            for e in std::fs::read_dir(base().join(&rel)).unwrap().flatten() {
                let r = rel.join(e.file_name());
                if e.file_type().unwrap().is_dir() {
                    stack.push(r);
                } else {
                    std::fs::copy(e.path(), dir.join(&r)).unwrap();
                }
            }
        }
    } else {
        std::fs::copy(from, dir.join(name)).unwrap();
    }
}

/// The valid NIfTI with bytes `at..` replaced by `patch`.
fn nii_with(at: usize, patch: &[u8]) -> Vec<u8> {
    let mut b = base_bytes("v.nii");
    b[at..at + patch.len()].copy_from_slice(patch);
    b
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

const NRRD_HEAD: &str = "NRRD0004\ntype: float\ndimension: 3\nsizes: 8 8 8\nendian: little\n";

/// The valid pack's manifest edited by `edit`.
fn manifest_edit(dir: &Path, edit: impl Fn(&mut serde_json::Value)) {
    copy_base("pk", dir);
    let p = dir.join("pk/manifest.json");
    let mut m: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    edit(&mut m);
    std::fs::write(&p, serde_json::to_string_pretty(&m).unwrap()).unwrap();
}

/// Prepares a case's folder and returns the command's arguments.
type Setup = Box<dyn Fn(&Path) -> Vec<String>>;

/// One case: prepares its folder, returns the arguments, and the words the
/// message must hold (the file's name among them).
struct Case {
    name: &'static str,
    setup: Setup,
    expect: Vec<&'static str>,
}

fn case(name: &'static str, expect: &[&'static str], setup: impl Fn(&Path) -> Vec<String> + 'static) -> Case {
    Case { name, setup: Box::new(setup), expect: expect.to_vec() }
}

fn args(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| s.to_string()).collect()
}

/// A folder `name` of DICOM slices, read by `mdtf info`.
fn dicom_folder(name: &'static str, slices: Vec<(&'static str, Vec<u8>)>, expect: &[&'static str]) -> Case {
    let mut words = vec![name];
    words.extend_from_slice(expect);
    case(name, &words, move |d| {
        std::fs::create_dir(d.join(name)).unwrap();
        for (file, bytes) in &slices {
            std::fs::write(d.join(name).join(file), bytes).unwrap();
        }
        args(&["info", name])
    })
}

/// A file `name` with `bytes`, read by `mdtf info`.
fn info_of(name: &'static str, bytes: Vec<u8>, expect: &[&'static str]) -> Case {
    let mut words = vec![name];
    words.extend_from_slice(expect);
    case(name, &words, move |d| {
        std::fs::write(d.join(name), &bytes).unwrap();
        args(&["info", name])
    })
}

/// A pipeline-file case: `text` as `p.toml`, run into `out`.
fn pipeline(name: &'static str, text: &'static str, extra: &[&'static str], expect: &[&'static str]) -> Case {
    let extra: Vec<&'static str> = extra.to_vec();
    case(name, expect, move |d| {
        std::fs::write(d.join("p.toml"), text).unwrap();
        let mut a = args(&["run", "p.toml", "-o", "out"]);
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    })
}

fn readers() -> Vec<Case> {
    let big_dims = {
        // dim[1..4] = 800 as i16 little-endian
        let mut d = Vec::new();
        for v in [3i16, 800, 800, 800] {
            d.extend(v.to_le_bytes());
        }
        d
    };
    let nii_800 = {
        let mut b = nii_with(40, &big_dims);
        b.truncate(16 * 1024.min(b.len()));
        b.resize(16 * 1024, 0);
        b
    };
    let huge_gz = {
        let mut b = "NRRD0004\ntype: float\ndimension: 3\nsizes: 800 800 800\nendian: little\nencoding: gzip\n\n"
            .as_bytes()
            .to_vec();
        b.extend(gzip(&[0u8; 16]));
        b
    };
    let nan_nrrd = {
        let mut b =
            "NRRD0004\ntype: float\ndimension: 3\nsizes: 2 1 1\nendian: little\nencoding: raw\n\n".as_bytes().to_vec();
        b.extend(f32::NAN.to_le_bytes());
        b.extend(1f32.to_le_bytes());
        b
    };
    let corrupt_gz_nii = {
        let mut g = gzip(&base_bytes("v.nii"));
        let n = g.len();
        g[n - 6] ^= 0xff; // the CRC
        g
    };
    vec![
        // NIfTI-1
        info_of("empty.nii", Vec::new(), &["empty"]),
        info_of("short.nii", vec![0; 100], &["348"]),
        info_of("sizeof.nii", nii_with(0, &[0, 0, 0, 0]), &["not a NIfTI file", "sizeof_hdr"]),
        info_of("nifti2.nii", nii_with(0, &540i32.to_le_bytes()), &["540-byte header", "not 'n+2'"]),
        info_of("pair.nii", nii_with(344, b"ni1\0"), &["magic", "separate .img", "name it .hdr"]),
        info_of("magic.nii", nii_with(344, b"xyz\0"), &["magic at byte 344", "'xyz\\x00'", "'n+1'"]),
        info_of("rank9.nii", nii_with(40, &9i16.to_le_bytes()), &["dim[0]", "is 9", "1 to 7"]),
        info_of("rank0.nii", nii_with(40, &0i16.to_le_bytes()), &["dim[0]", "1 to 7"]),
        info_of("negdim.nii", nii_with(42, &(-8i16).to_le_bytes()), &["negative dimension"]),
        info_of("zerodim.nii", nii_with(42, &0i16.to_le_bytes()), &["bad dimensions"]),
        info_of("rgb.nii", nii_with(70, &128i16.to_le_bytes()), &["unsupported data type", "128"]),
        info_of("voxnan.nii", nii_with(108, &f32::NAN.to_le_bytes()), &["vox_offset"]),
        info_of("voxsmall.nii", nii_with(108, &10f32.to_le_bytes()), &["vox_offset"]),
        info_of("claims800.nii", nii_800, &["truncated"]),
        info_of("cut.nii", base_bytes("v.nii")[..1000].to_vec(), &["truncated"]),
        info_of("cut.nii.gz", gzip(&base_bytes("v.nii"))[..200].to_vec(), &["gzip"]),
        info_of("crc.nii.gz", corrupt_gz_nii, &["gzip"]),
        info_of("garbage.nii.gz", vec![0x1f, 0x8b, 1, 2, 3, 4, 5, 6, 7, 8, 9], &["gzip"]),
        // NRRD
        info_of("empty.nrrd", Vec::new(), &["empty"]),
        info_of("nomagic.nrrd", b"HELLO\ntype: float\n\n".to_vec(), &["NRRD"]),
        info_of("magiconly.nrrd", b"NRRD0004\n\n".to_vec(), &["bad header"]),
        info_of("notype.nrrd", b"NRRD0004\ndimension: 3\nsizes: 1 1 1\nencoding: raw\n\n".to_vec(), &["type"]),
        info_of(
            "block.nrrd",
            b"NRRD0004\ntype: block\ndimension: 3\nsizes: 1 1 1\nencoding: raw\n\n".to_vec(),
            &["block"],
        ),
        info_of(
            "dim5.nrrd",
            b"NRRD0004\ntype: float\ndimension: 5\nsizes: 1 1 1 1 1\nendian: little\nencoding: raw\n\n".to_vec(),
            &["dimension"],
        ),
        info_of(
            "sizes.nrrd",
            b"NRRD0004\ntype: float\ndimension: 3\nsizes: 8 8\nencoding: raw\n\n".to_vec(),
            &["sizes"],
        ),
        info_of("zero.nrrd", b"NRRD0004\ntype: float\ndimension: 3\nsizes: 8 0 8\nendian: little\nencoding: raw\n\n".to_vec(), &["0"]),
        info_of(
            "huge.nrrd",
            b"NRRD0004\ntype: float\ndimension: 3\nsizes: 100000 100000 100000\nendian: little\nencoding: raw\n\n".to_vec(),
            &["memory"],
        ),
        info_of("bzip2.nrrd", format!("{NRRD_HEAD}encoding: bzip2\n\n").into_bytes(), &["bzip2"]),
        info_of("nodata.nhdr", format!("{NRRD_HEAD}encoding: raw\ndata file: gone.raw\n").into_bytes(), &["gone.raw"]),
        info_of(
            "list.nhdr",
            format!("{NRRD_HEAD}encoding: raw\ndata file: LIST\nx1.raw\n").into_bytes(),
            &["multi-file data", "not supported"],
        ),
        info_of("cut.nrrd", base_bytes("v.nrrd")[..600].to_vec(), &["truncated"]),
        info_of("long.nrrd", [base_bytes("v.nrrd"), vec![0; 8]].concat(), &["size mismatch"]),
        info_of("claims800gz.nrrd", huge_gz, &["truncated"]),
        info_of("badgz.nrrd", [format!("{NRRD_HEAD}encoding: gzip\n\n").into_bytes(), vec![1, 2, 3, 4]].concat(), &["gzip"]),
        info_of(
            "ascii.nrrd",
            b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2 1 1\nencoding: ascii\n\n1 x\n".to_vec(),
            &["ascii", "sample 2 is 'x'"],
        ),
        info_of(
            "asciishort.nrrd",
            b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2 1 1\nencoding: ascii\n\n1\n".to_vec(),
            &["truncated"],
        ),
        info_of(
            "negspacing.nrrd",
            [b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1 1 1\nspacings: 1 -1 1\nencoding: raw\n\n".to_vec(), vec![7]]
                .concat(),
            &["spacing"],
        ),
        info_of(
            "directions.nrrd",
            [
                b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1 1 1\nspace: RAS\nspace directions: (1,0) (0,1,0)\nencoding: raw\n\n".to_vec(),
                vec![7],
            ]
            .concat(),
            &["must have 3 components"],
        ),
        info_of(
            "byteskip.nrrd",
            [b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1 1 1\nbyte skip: 100\nencoding: raw\n\n".to_vec(), vec![7]]
                .concat(),
            &["truncated"],
        ),
        info_of("binary.nrrd", vec![b'N', b'R', b'R', b'D', b'0', b'0', b'0', b'4', b'\n', 0xff, 0xfe, b'\n'], &["header"]),
        info_of("endless.nrrd", [b"NRRD0004\n".to_vec(), vec![b'#'; 1_100_000]].concat(), &["no end of header"]),
        case("nan.nrrd", &["nan.nrrd", "NaN or infinite", "--nan zero"], move |d| {
            std::fs::write(d.join("nan.nrrd"), &nan_nrrd).unwrap();
            args(&["convert", "nan.nrrd", "out.nii"])
        }),
        info_of("what.xyz", vec![1, 2, 3], &["neither the content nor the extension names a format"]),
        case("missing.nii", &["missing.nii", "No such file"], |_| args(&["info", "missing.nii"])),
        case("detached data too short", &["h.raw", "truncated"], |d| {
            std::fs::write(d.join("h.nhdr"), format!("{NRRD_HEAD}encoding: raw\ndata file: h.raw\n")).unwrap();
            std::fs::write(d.join("h.raw"), [0u8; 10]).unwrap();
            args(&["info", "h.nhdr"])
        }),
        // MetaImage
        info_of("empty.mha", Vec::new(), &["empty"]),
        info_of("nodata.mha", b"ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n".to_vec(), &["no ElementDataFile"]),
        info_of("type.mha", b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_STRING\nElementDataFile = LOCAL\n".to_vec(), &["MET_STRING"]),
        info_of("ndims.mha", b"NDims = 5\nDimSize = 2 2 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n".to_vec(), &["NDims = 5"]),
        info_of("dimsize.mha", b"NDims = 3\nDimSize = 2 x 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n".to_vec(), &["DimSize", "'x'"]),
        info_of("cut.mha", b"NDims = 3\nDimSize = 800 800 800\nElementType = MET_FLOAT\nElementDataFile = LOCAL\n\0\0\0\0".to_vec(), &["truncated"]),
        info_of("zlib.mha", b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nCompressedData = True\nElementDataFile = LOCAL\nnot zlib".to_vec(), &["gzip"]),
        info_of("overflow.mha", b"NDims = 3\nDimSize = 18446744073709551615 5 18446744073709551615\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n".to_vec(), &["memory"]),
        info_of("gone.mhd", b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = gone.raw\n".to_vec(), &["gone.raw"]),
        info_of("list.mhd", b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LIST\na.raw\n".to_vec(), &["1 slice files for 2 slices"]),
        info_of("spacing.mha", b"NDims = 3\nDimSize = 1 1 1\nElementSpacing = 1 0 1\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n\x07".to_vec(), &["ElementSpacing"]),
        // TIFF
        info_of("empty.tif", Vec::new(), &["empty"]),
        info_of("notiff.tif", b"hello, not a tiff".to_vec(), &["cannot decode the TIFF"]),
        info_of("cut.tif", b"II*\0\x08\0\0\0\x09\0".to_vec(), &["claims 9 entries", "truncated"]),
        case("folder without slices", &["empty-folder", "no .tif", "no DICOM files", "no Zarr metadata"], |d| {
            std::fs::create_dir(d.join("empty-folder")).unwrap();
            args(&["info", "empty-folder"])
        }),
        case("a .zarr folder without metadata", &["empty.zarr", "not a Zarr store", "zarr.json"], |d| {
            std::fs::create_dir(d.join("empty.zarr")).unwrap();
            args(&["info", "empty.zarr"])
        }),
        case("a TIFF cut inside its pages", &["cut-pages.tif", "ends inside its pages"], |d| {
            // a 2-page 8 x 8 u16 stack, its second page's samples cut off
            let mut f = b"II*\0\x08\0\0\0".to_vec();
            let entry = |tag: u16, ty: u16, value: u32| {
                [&tag.to_le_bytes()[..], &ty.to_le_bytes(), &1u32.to_le_bytes(), &value.to_le_bytes()].concat()
            };
            let ifd = |data: u32, next: u32| {
                let tags = [(256, 3, 8), (257, 3, 8), (258, 3, 16), (259, 3, 1), (262, 3, 1), (273, 4, data), (277, 3, 1), (278, 3, 8), (279, 4, 128)];
                let mut b = (tags.len() as u16).to_le_bytes().to_vec();
                for (t, ty, v) in tags {
                    b.extend(entry(t, ty, v));
                }
                b.extend(next.to_le_bytes());
                b
            };
            // IFD 1 at 8 (9 entries: 2 + 108 + 4 = 114 bytes), its data at 122; IFD 2 at 250, data at 364
            f.extend(ifd(122, 250));
            f.extend(vec![1u8; 128]);
            f.extend(ifd(364, 0));
            f.extend(vec![2u8; 40]);
            std::fs::write(d.join("cut-pages.tif"), f).unwrap();
            args(&["info", "cut-pages.tif"])
        }),
        // DICOM
        info_of("cut.dcm", mdtf_e2e::dicom_slice(mdtf_e2e::EXPLICIT_LE, 4, 4, Some(0.0), 32)[..300].to_vec(), &["not a readable DICOM file"]),
        info_of("short-pixels.dcm", mdtf_e2e::dicom_slice(mdtf_e2e::EXPLICIT_LE, 4, 4, Some(0.0), 30), &["30 bytes", "Columns x Rows"]),
        info_of("syntax.dcm", mdtf_e2e::dicom_slice("1.2.3.4.5.6.7", 4, 4, Some(0.0), 32), &["1.2.3.4.5.6.7"]),
        info_of("jpegls.dcm", mdtf_e2e::dicom_slice("1.2.840.10008.1.2.4.80", 4, 4, Some(0.0), 32), &["JPEG-LS", "stored uncompressed", "mislabelled"]),
        info_of("onlymagic.dcm", [vec![0u8; 128], b"DICM".to_vec()].concat(), &["not a readable DICOM file"]),
        dicom_folder(
            "sizes",
            vec![("a.dcm", mdtf_e2e::dicom_slice(mdtf_e2e::EXPLICIT_LE, 4, 4, Some(0.0), 32)), ("b.dcm", mdtf_e2e::dicom_slice(mdtf_e2e::EXPLICIT_LE, 4, 3, Some(1.0), 24))],
            &["one image size"],
        ),
        dicom_folder(
            "noposition",
            vec![("a.dcm", mdtf_e2e::dicom_slice(mdtf_e2e::EXPLICIT_LE, 4, 4, Some(0.0), 32)), ("b.dcm", mdtf_e2e::dicom_slice(mdtf_e2e::EXPLICIT_LE, 4, 4, None, 32))],
            &["b.dcm", "ImagePositionPatient is missing"],
        ),
        dicom_folder("nodicom", vec![("a.dcm", b"not dicom".to_vec())], &["no DICOM files"]),
        info_of("empty.dcm", Vec::new(), &["the file is empty"]),
        info_of("slope0.dcm", with_rescale(mdtf_e2e::dicom_slice(mdtf_e2e::EXPLICIT_LE, 4, 4, Some(0.0), 32), "0", "-1024"), &["RescaleSlope 0", "-1024", "non-zero"]),
        info_of("list.txt", b"missing-slice.dcm\n".to_vec(), &["line 1", "missing-slice.dcm", "not a file"]),
        // arguments: a file given twice as two fields
        case("the same file as two fields", &["v.nii", "given twice"], |d| {
            std::fs::copy(base().join("v.nii"), d.join("v.nii")).unwrap();
            args(&["derive", "v.nii", "./v.nii", "--items", "gnorm", "-o", "out"])
        }),
        // OME-Zarr: a store may claim any shape (its missing chunks are the fill value), so the
        // claim is checked before anything is allocated
        case("OME-Zarr claiming 10^15 voxels", &["v.ome.zarr", "100000x100000x100000", "PiB"], |d| {
            copy_base("v.ome.zarr", d);
            claim_zarr_shape(d, [100_000; 3]);
            args(&["info", "v.ome.zarr"])
        }),
        case("OME-Zarr whose one plane exceeds memory, by slabs", &["v.ome.zarr", "one plane of 200000x200000"], |d| {
            copy_base("v.ome.zarr", d);
            claim_zarr_shape(d, [2, 200_000, 200_000]);
            args(&["derive", "v.ome.zarr", "-o", "d.nii", "--items", "g", "--memory-budget", "1GiB"])
        }),
        // raw
        case("short raw claiming 800^3", &["a.raw", "truncated"], |d| {
            std::fs::write(d.join("a.raw"), vec![0u8; 4096]).unwrap();
            args(&["info", "a.raw", "--raw-dims", "800,800,800", "--raw-type", "f32"])
        }),
        case("long raw", &["a.raw", "size mismatch"], |d| {
            std::fs::write(d.join("a.raw"), vec![0u8; 9]).unwrap();
            args(&["info", "a.raw", "--raw-dims", "2,2,2", "--raw-type", "u8"])
        }),
        case("raw type", &["--raw-type", "f24"], |d| {
            std::fs::write(d.join("a.raw"), vec![0u8; 8]).unwrap();
            args(&["info", "a.raw", "--raw-dims", "2,2,2", "--raw-type", "f24"])
        }),
        case("raw dims", &["--raw-dims", "at least 1"], |d| {
            std::fs::write(d.join("a.raw"), vec![0u8; 8]).unwrap();
            args(&["info", "a.raw", "--raw-dims", "2,0,2"])
        }),
        case("raw spacing", &["--raw-spacing", "positive"], |d| {
            std::fs::write(d.join("a.raw"), vec![0u8; 8]).unwrap();
            args(&["info", "a.raw", "--raw-dims", "2,2,2", "--raw-type", "u8", "--raw-spacing", "1,-1,1"])
        }),
        // legacy VTK and VTU meshes
        info_of("empty.vtk", Vec::new(), &["empty.vtk"]),
        info_of("notvtk.vtk", b"hello\nworld\n".to_vec(), &["first line", "legacy VTK"]),
        info_of("points.vtk", tet_vtk("CELLS 1 5\n4 0 1 2 3\n").replace("POINTS 4", "POINTS 9").into_bytes(), &["POINTS 9 needs 27 numbers"]),
        info_of("minus.vtk", tet_vtk("CELLS 1 5\n4 0 1 2 -1\n").into_bytes(), &["point index -1 is out of range"]),
        info_of("hugecount.vtk", tet_vtk("CELLS 1 5\n4 0 1 2 3\n").replace("POINTS 4", "POINTS 999999999999").into_bytes(), &["needs 2999999999997 numbers"]),
        info_of("cut.vtk", tet_vtk("CELLS 1 5\n4 0 1 2 3\n").as_bytes()[..120].to_vec(), &["ends before its CELL_TYPES"]),
        info_of("nan.vtk", tet_vtk("CELLS 1 5\n4 0 1 2 3\n").replacen("1 0 0", "nan 0 0", 1).into_bytes(), &["'nan' is not a finite number"]),
        info_of("pointdata.vtk", tet_vtk("CELLS 1 5\n4 0 1 2 3\n").replace("POINT_DATA 4", "POINT_DATA 5").into_bytes(), &["POINT_DATA 5, but the file has 4 points"]),
        info_of(
            "grid.vtk",
            b"# vtk DataFile Version 4.2\nx\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 2 2\nSPACING 1 1 1\nORIGIN 0 0 0\n".to_vec(),
            &["UNSTRUCTURED_GRID"],
        ),
        case("out-of-range cell", &["idx.vtk", "uses point 7"], |d| {
            std::fs::write(d.join("idx.vtk"), tet_vtk("CELLS 1 5\n4 0 1 2 7\n")).unwrap();
            args(&["tetra", "idx.vtk", "-o", "out"])
        }),
        info_of("cutbin.vtk", [&b"# vtk DataFile Version 4.2\nt\nBINARY\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n"[..], &[0u8; 10]].concat(), &["cutbin.vtk", "binary", "POINTS 4 needs 48 bytes", "only 10 follow"]),
        info_of("empty.vtu", Vec::new(), &["empty.vtu"]),
        info_of("count.vtu", b"<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\">\n<UnstructuredGrid>\n<Piece NumberOfPoints=\"99999999999999999999\" NumberOfCells=\"1\">\n</Piece></UnstructuredGrid></VTKFile>\n".to_vec(), &["count.vtu", "NumberOfPoints=\"99999999999999999999\" is not a count"]),
        info_of("notxml.vtu", b"<VTKFile type=\"UnstructuredGrid\"><Piece NumberOfPoints=\"x\"".to_vec(), &["NumberOfPoints=\"x\" is not a count"]),
        info_of("cut.vtu", b"<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\">\n<UnstructuredGrid>\n<Piece NumberOfPoints=\"4\" NumberOfCells=\"1\">\n<Points>\n<DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"ascii\">0 0 0 1".to_vec(), &["cut.vtu"]),
        // pack manifests, read by preview
        case("no manifest", &["manifest.json"], |d| {
            std::fs::create_dir(d.join("pk")).unwrap();
            args(&["preview", "pk", "-o", "p.png"])
        }),
        case("manifest not json", &["manifest.json"], |d| {
            copy_base("pk", d);
            std::fs::write(d.join("pk/manifest.json"), "{ not json").unwrap();
            args(&["preview", "pk", "-o", "p.png"])
        }),
        case("unknown schema", &["manifest.json", "schema", "mdtf-pack/9"], |d| {
            manifest_edit(d, |m| m["schema"] = "mdtf-pack/9".into());
            args(&["preview", "pk", "-o", "p.png"])
        }),
        case("texture outside the pack", &["manifest.json", "../../etc/passwd", "inside the pack"], |d| {
            manifest_edit(d, |m| m["textures"][0]["data"] = "../../etc/passwd".into());
            args(&["preview", "pk", "-o", "p.png"])
        }),
        case("absolute texture path", &["manifest.json", "/etc/passwd", "inside the pack"], |d| {
            manifest_edit(d, |m| m["textures"][0]["data"] = "/etc/passwd".into());
            args(&["preview", "pk", "-o", "p.png"])
        }),
        case("channel without texture", &["manifest.json", "names texture nope"], |d| {
            manifest_edit(d, |m| m["channels"][0]["texture"] = "nope".into());
            args(&["preview", "pk", "-o", "p.png"])
        }),
        case("decode scale 0", &["manifest.json", "scale", "non-zero"], |d| {
            manifest_edit(d, |m| m["channels"][0]["decode"]["scale"] = 0.0.into());
            args(&["preview", "pk", "-o", "p.png"])
        }),
        case("table axes overflow", &["manifest.json", "4611686018427387905"], |d| {
            manifest_edit(d, |m| {
                m["luts"][0]["axes"][0]["size"] = (1u64 << 62 | 1).into();
                m["luts"][0]["axes"][1]["size"] = 4.into();
            });
            args(&["preview", "pk", "-o", "p.png"])
        }),
        case("table of petabytes", &["manifest.json", "table"], |d| {
            manifest_edit(d, |m| {
                m["luts"][0]["axes"][0]["size"] = (1u64 << 48 | 1).into();
                m["luts"][0]["axes"][1]["size"] = 65536.into();
            });
            args(&["preview", "pk", "-o", "p.png"])
        }),
        case("empty table axis", &["manifest.json", "at least 1"], |d| {
            manifest_edit(d, |m| m["luts"][0]["axes"][0]["size"] = 0.into());
            args(&["preview", "pk", "-o", "p.png"])
        }),
        case("zero spacing", &["manifest.json", "spacing"], |d| {
            manifest_edit(d, |m| m["geometry"]["spacing"][1] = 0.0.into());
            args(&["preview", "pk", "-o", "p.png"])
        }),
        case("texture cut", &["bytes", "texels"], |d| {
            copy_base("pk", d);
            let m: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(d.join("pk/manifest.json")).unwrap()).unwrap();
            let data = d.join("pk").join(m["textures"][0]["data"].as_str().unwrap());
            let bytes = std::fs::read(&data).unwrap();
            std::fs::write(&data, &bytes[..bytes.len() / 2]).unwrap();
            args(&["preview", "pk", "-o", "p.png"])
        }),
        // pipeline files
        pipeline("pipeline not toml", "this is = = not toml", &[], &["p.toml"]),
        pipeline("pipeline unknown key", "[derive]\nkernal = \"central\"\n", &[], &["p.toml", "kernal"]),
        pipeline("pipeline negative sigma", "[input]\nsize = 16\n[pack]\nprofile = \"slicer-3dtf\"\n", &["--set", "input.sigma=-3"], &["sigma", "-3"]),
        pipeline("pipeline missing input", "[input]\nfile = \"gone.nii\"\n[pack]\nprofile = \"slicer-3dtf\"\n", &[], &["gone.nii"]),
        pipeline("pipeline unknown profile", "[input]\nsize = 16\n[pack]\nprofile = \"nope\"\n", &[], &["nope"]),
        pipeline("pipeline kernel typo", "[input]\nsize = 16\n[derive]\nkernel = \"centrl\"\n[pack]\nprofile = \"slicer-3dtf\"\n", &[], &["centrl"]),
        // transfer-function files
        case("tf not json", &["tf.json"], |d| {
            copy_base("v.nii", d);
            std::fs::write(d.join("tf.json"), "[1,").unwrap();
            args(&["pack", "v.nii", "--profile", "slicer-3dtf", "--tf", "tf.json", "-o", "out"])
        }),
        case("tf negative width", &["tf.json", "width"], |d| {
            copy_base("v.nii", d);
            std::fs::write(
                d.join("tf.json"),
                r#"{"v_range": [0, 255], "g_range": [0, 45], "f2_range": [-1, 1], "widgets": [
                    {"type": "triangle", "v0": 128, "width": -5, "g_low": 5, "g_high": 35, "alpha": 0.8, "colour": [1, 0.5, 0]}]}"#,
            )
            .unwrap();
            args(&["pack", "v.nii", "--profile", "slicer-3dtf", "--tf", "tf.json", "-o", "out"])
        }),
    ]
}

/// Outputs that would replace, overwrite or mix with the user's files.
fn outputs() -> Vec<Case> {
    vec![
        case("convert to a picture", &["out.png", "no format mdtf writes", ".ome.zarr", "mdtf preview"], |d| {
            copy_base("v.nii", d);
            args(&["convert", "v.nii", "out.png"])
        }),
        case("run -o a folder holding the input", &["ct", "ct/v.nii", "input"], |d| {
            std::fs::create_dir(d.join("ct")).unwrap();
            std::fs::copy(base().join("v.nii"), d.join("ct/v.nii")).unwrap();
            std::fs::write(d.join("ct/notes.txt"), "mine").unwrap();
            let p = mdtf_e2e::shipped_pipeline("distance-tf");
            args(&["run", p.to_str().unwrap(), "--input", "ct/v.nii", "-o", "ct"])
        }),
        case("run -o the current folder by its path", &["current folder"], |d| {
            copy_base("v.nii", d);
            let p = mdtf_e2e::shipped_pipeline("distance-tf");
            args(&["run", p.to_str().unwrap(), "--input", "v.nii", "-o", d.to_str().unwrap()])
        }),
        case("run -o .", &["current folder"], |d| {
            copy_base("v.nii", d);
            let p = mdtf_e2e::shipped_pipeline("distance-tf");
            args(&["run", p.to_str().unwrap(), "--input", "v.nii", "-o", "."])
        }),
        case("run -o an existing file", &["afile", "not a folder"], |d| {
            std::fs::write(d.join("afile"), "mine").unwrap();
            let p = mdtf_e2e::shipped_pipeline("slicer-3dtf");
            args(&["run", p.to_str().unwrap(), "-o", "afile"])
        }),
        case("run -o a folder of the user's", &["mine", "not made by mdtf", "notes.txt"], |d| {
            std::fs::create_dir(d.join("mine")).unwrap();
            std::fs::write(d.join("mine/notes.txt"), "mine").unwrap();
            let p = mdtf_e2e::shipped_pipeline("slicer-3dtf");
            args(&["run", p.to_str().unwrap(), "-o", "mine"])
        }),
        case("run -o the pipeline's own folder", &["input"], |d| {
            std::fs::create_dir(d.join("job")).unwrap();
            std::fs::copy(mdtf_e2e::shipped_pipeline("slicer-3dtf"), d.join("job/p.toml")).unwrap();
            args(&["run", "job/p.toml", "-o", "job"])
        }),
        case("tetra -o the mesh's folder", &["md", "md/m.vtk", "input"], |d| {
            std::fs::create_dir(d.join("md")).unwrap();
            std::fs::copy(base().join("m.vtk"), d.join("md/m.vtk")).unwrap();
            args(&["tetra", "md/m.vtk", "-o", "md"])
        }),
        case("convert a.raw a.nhdr", &["a.raw", "input"], |d| {
            std::fs::copy(base().join("v.raw"), d.join("a.raw")).unwrap();
            args(&["convert", "a.raw", "a.nhdr", "--raw-dims", "8,8,8", "--raw-type", "f32"])
        }),
        case("convert in.nhdr out.nhdr whose data is out.raw", &["out.raw", "input"], |d| {
            std::fs::write(
                d.join("in.nhdr"),
                std::fs::read_to_string(base().join("v.nhdr")).unwrap().replace("v.raw", "out.raw"),
            )
            .unwrap();
            std::fs::copy(base().join("v.raw"), d.join("out.raw")).unwrap();
            args(&["convert", "in.nhdr", "out.nhdr"])
        }),
        case("convert onto an unrelated data file", &["c.raw", "does not belong"], |d| {
            copy_base("v.nii", d);
            std::fs::write(d.join("c.raw"), "mine").unwrap();
            args(&["convert", "v.nii", "c.nhdr"])
        }),
        case("convert a file onto itself by a hard link", &["h.nii", "input"], |d| {
            copy_base("v.nii", d);
            std::fs::hard_link(d.join("v.nii"), d.join("h.nii")).unwrap();
            args(&["convert", "v.nii", "h.nii"])
        }),
        case("derive -o . --format nhdr", &["current folder"], |d| {
            std::fs::copy(base().join("v.raw"), d.join("g.raw")).unwrap();
            args(&["derive", "g.raw", "--raw-dims", "8,8,8", "--raw-type", "f32", "-o", ".", "--format", "nhdr"])
        }),
        case("pack -o the pack it reads from", &["pk", "input"], |d| {
            copy_base("pk", d);
            std::fs::copy(base().join("v.nii"), d.join("pk/data.nii")).unwrap();
            args(&["pack", "pk/data.nii", "--profile", "slicer-3dtf", "-o", "pk", "--nifti"])
        }),
        case("preview -o the manifest", &["manifest.json", "input"], |d| {
            copy_base("pk", d);
            args(&["preview", "pk", "-o", "pk/manifest.json"])
        }),
        case("histogram -o a folder of the user's", &["h", "not made by mdtf"], |d| {
            copy_base("v.nii", d);
            std::fs::create_dir(d.join("h")).unwrap();
            std::fs::write(d.join("h/mine.png"), "mine").unwrap();
            args(&["histogram", "v.nii", "--axes", "v,g", "-o", "h"])
        }),
        case("an mdtf folder the user added a file to", &["pk", "mine.txt", "did not write"], |d| {
            copy_base("v.nii", d);
            copy_base("pk", d);
            std::fs::write(d.join("pk/mine.txt"), "mine").unwrap();
            args(&["pack", "v.nii", "--profile", "slicer-3dtf", "-o", "pk"])
        }),
        case("boundary --report into a folder of the user's", &["rep", "not made by mdtf"], |d| {
            copy_base("v.nii", d);
            std::fs::create_dir(d.join("rep")).unwrap();
            std::fs::write(d.join("rep/x"), "mine").unwrap();
            args(&["boundary", "v.nii", "-o", "b", "--report", "rep"])
        }),
        case("synth --truth into a folder of the user's", &["t", "not made by mdtf"], |d| {
            std::fs::create_dir(d.join("t")).unwrap();
            std::fs::write(d.join("t/x"), "mine").unwrap();
            args(&["synth", "erf-sphere", "-o", "s.nii", "--size", "8", "--truth", "t"])
        }),
        case("validate -o a folder of the user's", &["val", "not made by mdtf"], |d| {
            std::fs::create_dir(d.join("val")).unwrap();
            std::fs::write(d.join("val/x"), "mine").unwrap();
            args(&["validate", "--size", "16", "-o", "val"])
        }),
    ]
}

fn run_cases(cases: Vec<Case>) -> usize {
    let mut failures = Vec::new();
    let count = cases.len();
    for c in cases {
        let dir = tempfile::tempdir().unwrap();
        let a = (c.setup)(dir.path());
        let before = snapshot(dir.path());
        let out = Command::new(mdtf_path()).args(&a).current_dir(dir.path()).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        let after = snapshot(dir.path());
        let mut why = Vec::new();
        if out.status.code() != Some(1) {
            why.push(format!("exit {:?}", out.status.code()));
        }
        if err.contains("panicked") || err.contains("RUST_BACKTRACE") {
            why.push("panic text".into());
        }
        for w in &c.expect {
            if !err.contains(w) {
                why.push(format!("no '{w}' in the message"));
            }
        }
        if before != after {
            let added: Vec<_> = after.keys().filter(|k| !before.contains_key(*k)).collect();
            let changed: Vec<_> = before.keys().filter(|k| after.get(*k) != before.get(*k)).collect();
            why.push(format!("files changed: added {added:?}, changed or removed {changed:?}"));
        }
        if !why.is_empty() {
            failures.push(format!("{}: {}\n  args {a:?}\n  stderr: {}", c.name, why.join("; "), err.trim()));
        }
    }
    assert!(failures.is_empty(), "{} of {count} cases failed:\n{}", failures.len(), failures.join("\n"));
    count
}

#[test]
fn every_malformed_input_is_refused_by_name_and_changes_nothing() {
    let n = run_cases(readers());
    println!("{n} reader cases, each refused by name with nothing changed");
    assert!(n >= 60, "the reader corpus has {n} cases");
}

#[test]
fn no_output_replaces_mixes_with_or_overwrites_a_users_file() {
    let n = run_cases(outputs());
    println!("{n} output cases, no user's file replaced, mixed with or overwritten");
}
