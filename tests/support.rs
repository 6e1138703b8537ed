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
    let ok = Command::new(&py).args(["-c", "import nibabel, nrrd, numpy, meshio, SimpleITK, tifffile"]).output();
    match ok {
        Ok(o) if o.status.success() => py,
        _ => panic!(
            "{py} lacks nibabel, pynrrd, numpy, meshio, SimpleITK or tifffile, the reference readers of the interop tests: run the tests with \
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
