//! Helpers of the end-to-end tests: the `mdtf` binary and a Python with
//! nibabel and pynrrd for cross-tool checks.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The folder of the shipped pipeline files.
pub fn pipelines_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().map_or_else(PathBuf::new, Path::to_path_buf).join("pipelines")
}

/// The shipped pipeline file `pipelines/<name>.toml`.
pub fn shipped_pipeline(name: &str) -> PathBuf {
    pipelines_dir().join(format!("{name}.toml"))
}

/// Path of the `mdtf` binary of this build, building it if `cargo test` has not.
pub fn mdtf_path() -> PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        // target/<profile>/deps/<test-binary> -> target/<profile>/mdtf
        let exe = std::env::current_exe().expect("test binary path");
        let dir = exe.parent().and_then(|d| d.parent()).expect("target profile folder").to_path_buf();
        let bin = dir.join(format!("mdtf{}", std::env::consts::EXE_SUFFIX));
        // Always ask cargo: a no-op when the binary is current, a rebuild when
        // only this test crate was asked for and the binary is stale.
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let profile = if dir.ends_with("release") { vec!["--release"] } else { vec![] };
        let status = Command::new(cargo)
            .args(["build", "--quiet", "-p", "mdtf-cli", "--bin", "mdtf"])
            .args(profile)
            .status()
            .expect("run cargo build for the mdtf binary");
        assert!(status.success(), "building the mdtf binary failed");
        assert!(bin.exists(), "no mdtf binary at {}", bin.display());
        bin
    })
    .clone()
}

/// Runs `mdtf` with `args`.
pub fn mdtf(args: &[&str]) -> Output {
    Command::new(mdtf_path()).args(args).output().expect("run mdtf")
}

/// Runs `mdtf` and asserts success, returning stdout.
pub fn mdtf_ok(args: &[&str]) -> String {
    let out = mdtf(args);
    assert!(out.status.success(), "mdtf {args:?} failed:\n{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Runs `mdtf`, asserts it failed with exit code 1, and returns stderr.
pub fn mdtf_err(args: &[&str]) -> String {
    let out = mdtf(args);
    assert_eq!(
        out.status.code(),
        Some(1),
        "mdtf {args:?} should fail; stdout: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The Python interpreter for interop tests: `$MDTF_PYTHON`, else `python3`.
/// Panics with instructions if nibabel, pynrrd or meshio is missing: the
/// interop tests must run, not skip (CI installs them).
pub fn python() -> String {
    let py = std::env::var("MDTF_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&py)
        .args(["-c", "import nibabel, nrrd, numpy, meshio, SimpleITK, tifffile, zarr, ome_zarr_models"])
        .output();
    match ok {
        Ok(o) if o.status.success() => py,
        _ => panic!(
            "{py} lacks nibabel, pynrrd, numpy, meshio, SimpleITK, tifffile, zarr or ome-zarr-models, the reference readers of the interop tests: run the tests with \
             `bash tests/run.sh`, which installs them (tests/requirements.txt) into target/test-venv, or set MDTF_PYTHON to a \
             Python that has them"
        ),
    }
}

/// Runs a Python script with arguments and returns its stdout, asserting success.
pub fn run_python(script: &str, args: &[&str]) -> String {
    let out = Command::new(python()).arg("-c").arg(script).args(args).output().expect("run python");
    assert!(out.status.success(), "python failed:\n{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// An 8-bit RGB PNG's (width, height, pixels).
pub fn read_rgb_png(path: &Path) -> (u32, u32, Vec<u8>) {
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap_or(0)];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb, "{}", path.display());
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

/// A pack's `manifest.json`, parsed.
pub fn manifest(pack: &Path) -> serde_json::Value {
    let text =
        std::fs::read_to_string(pack.join("manifest.json")).unwrap_or_else(|e| panic!("{}: {e}", pack.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", pack.display()))
}

/// The samples of an NRRD file with an attached header written by mdtf (raw
/// encoding: the header ends at the first blank line).
pub fn nrrd_payload(path: &Path) -> Vec<u8> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let at = bytes.windows(2).position(|w| w == b"\n\n").expect("NRRD header end") + 2;
    bytes[at..].to_vec()
}

/// Little-endian f32 samples of an attached-header NRRD.
pub fn nrrd_f32(path: &Path) -> Vec<f32> {
    nrrd_payload(path).chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
}

/// Little-endian u32 samples of an attached-header NRRD.
pub fn nrrd_u32(path: &Path) -> Vec<u32> {
    nrrd_payload(path).chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
}

/// One explicit-VR little-endian element, its value padded to even length.
pub fn dicom_element(group: u16, element: u16, vr: &str, value: &[u8]) -> Vec<u8> {
    let mut v = value.to_vec();
    if v.len() % 2 == 1 {
        v.push(if vr == "UI" || vr == "OB" { 0 } else { b' ' });
    }
    let mut out = Vec::new();
    out.extend(group.to_le_bytes());
    out.extend(element.to_le_bytes());
    out.extend(vr.as_bytes());
    if matches!(vr, "OB" | "OW" | "SQ" | "UN" | "UT") {
        out.extend([0, 0]);
        out.extend((v.len() as u32).to_le_bytes());
    } else {
        out.extend((v.len() as u16).to_le_bytes());
    }
    out.extend(v);
    out
}

/// A CT slice of `cols` x `rows` 16-bit pixels as a DICOM file (Part 10), with
/// `pixels` bytes of pixel data, at z = `z` (no position when None).
pub fn dicom_slice(syntax: &str, cols: u16, rows: u16, z: Option<f64>, pixels: usize) -> Vec<u8> {
    let us = |v: u16| v.to_le_bytes().to_vec();
    let mut meta = dicom_element(0x0002, 0x0001, "OB", &[0, 1]);
    meta.extend(dicom_element(0x0002, 0x0002, "UI", b"1.2.840.10008.5.1.4.1.1.2"));
    meta.extend(dicom_element(0x0002, 0x0003, "UI", format!("1.2.3.{}", z.unwrap_or(0.0) as i64 + 10).as_bytes()));
    meta.extend(dicom_element(0x0002, 0x0010, "UI", syntax.as_bytes()));
    let mut out = vec![0u8; 128];
    out.extend(b"DICM");
    out.extend(dicom_element(0x0002, 0x0000, "UL", &(meta.len() as u32).to_le_bytes()));
    out.extend(meta);
    out.extend(dicom_element(0x0008, 0x0016, "UI", b"1.2.840.10008.5.1.4.1.1.2"));
    out.extend(dicom_element(0x0008, 0x0018, "UI", format!("1.2.3.{}", z.unwrap_or(0.0) as i64 + 10).as_bytes()));
    out.extend(dicom_element(0x0008, 0x0060, "CS", b"CT"));
    out.extend(dicom_element(0x0020, 0x000E, "UI", b"1.2.3.4"));
    if let Some(z) = z {
        out.extend(dicom_element(0x0020, 0x0032, "DS", format!("0\\0\\{z}").as_bytes()));
    }
    out.extend(dicom_element(0x0020, 0x0037, "DS", b"1\\0\\0\\0\\1\\0"));
    out.extend(dicom_element(0x0028, 0x0002, "US", &us(1)));
    out.extend(dicom_element(0x0028, 0x0004, "CS", b"MONOCHROME2"));
    out.extend(dicom_element(0x0028, 0x0010, "US", &us(rows)));
    out.extend(dicom_element(0x0028, 0x0011, "US", &us(cols)));
    out.extend(dicom_element(0x0028, 0x0030, "DS", b"1\\1"));
    out.extend(dicom_element(0x0028, 0x0100, "US", &us(16)));
    out.extend(dicom_element(0x0028, 0x0101, "US", &us(16)));
    out.extend(dicom_element(0x0028, 0x0102, "US", &us(15)));
    out.extend(dicom_element(0x0028, 0x0103, "US", &us(1)));
    out.extend(dicom_element(0x7FE0, 0x0010, "OW", &vec![7u8; pixels]));
    out
}

/// Transfer syntax UID of explicit-VR little-endian DICOM.
pub const EXPLICIT_LE: &str = "1.2.840.10008.1.2.1";

/// A file or folder of the shared test data: `$MDTF_SHARED_DATA/rel` when
/// that is set, else `../shared/data/rel` beside the checkout.
pub fn shared_data(rel: &str) -> PathBuf {
    let base = std::env::var_os("MDTF_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"));
    base.join(rel)
}

/// A real scan that ships in a registry package, fetched by tests/run.sh
/// into `$MDTF_REAL_DATA` (default `target/real-data`): `ch2.nii.gz` is
/// Colin Holmes' T1 MRI (the average of 27 scans, 181 x 217 x 181 at 1 mm,
/// uint8, with scalp and skull) from Debian's `mricron-data`. Panics with
/// the command that fetches it when it is missing: these tests must run.
pub fn real_scan(name: &str) -> PathBuf {
    let dir = std::env::var_os("MDTF_REAL_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/real-data"));
    let path = dir.join(name);
    assert!(
        path.is_file(),
        "{} is missing: run the tests with `bash tests/run.sh`, which fetches it (Debian's mricron-data), \
         or set MDTF_REAL_DATA to a folder holding it",
        path.display()
    );
    path
}
