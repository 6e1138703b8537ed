//! Faults while writing: `kill -9` at many moments of a run and of a
//! conversion onto an existing output, interrupts, and two runs into one
//! output. At every moment the old output or the new one is complete and
//! present, and nothing partial survives the next run.

use mdtf_e2e::{mdtf_path, shipped_pipeline};
use mdtf_volume::{ReadOptions, read_scalar};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Moments of a run at which it is killed.
const KILLS: usize = 10;

fn spawn(args: &[&str], dir: &Path) -> Child {
    Command::new(mdtf_path()).args(args).current_dir(dir).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap()
}

/// Partial outputs and lock files left in `dir`.
fn leftovers(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".mdtf-partial-") || n.ends_with(".mdtf-lock"))
        .collect()
}

/// An output folder is complete: its marker lists files that all exist, and
/// its run report parses.
fn assert_complete_run_output(out: &Path, moment: &str) {
    let marker = std::fs::read_to_string(out.join(".mdtf-output"))
        .unwrap_or_else(|e| panic!("{moment}: no complete output folder ({e})"));
    let files: Vec<&str> = marker.lines().skip(1).collect();
    assert!(files.contains(&"run_report.json") && files.contains(&"pack/manifest.json"), "{moment}: {files:?}");
    for f in files {
        assert!(out.join(f).is_file(), "{moment}: {f} listed but missing");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run_report.json")).unwrap()).unwrap();
    assert!(report["stages"].as_array().is_some_and(|s| !s.is_empty()), "{moment}");
}

/// How long a command takes here, seconds.
fn duration_of(args: &[&str], dir: &Path) -> f64 {
    let t = Instant::now();
    let out = Command::new(mdtf_path()).args(args).current_dir(dir).output().unwrap();
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    t.elapsed().as_secs_f64()
}

fn kill_at(args: &[&str], dir: &Path, after: Duration) {
    let mut child = spawn(args, dir);
    std::thread::sleep(after);
    let _ = child.kill();
    let _ = child.wait();
}

#[test]
fn a_run_killed_at_any_moment_leaves_the_old_or_the_new_output_whole() {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = shipped_pipeline("distance-tf");
    let args = ["run", pipeline.to_str().unwrap(), "-o", "out", "--set", "input.size=32", "-q"];
    let seconds = duration_of(&args, dir.path());
    assert_complete_run_output(&dir.path().join("out"), "first run");
    for k in 0..KILLS {
        // from the start to just past the end of a typical run
        let after = Duration::from_secs_f64(seconds * (k as f64 + 0.5) / KILLS as f64 * 1.1);
        kill_at(&args, dir.path(), after);
        let moment = format!("killed after {:.0} ms of {:.0}", after.as_secs_f64() * 1e3, seconds * 1e3);
        assert_complete_run_output(&dir.path().join("out"), &moment);
    }
    let mut again = spawn(&args, dir.path());
    assert!(again.wait().unwrap().success());
    assert_complete_run_output(&dir.path().join("out"), "after the kills");
    assert_eq!(leftovers(dir.path()), Vec::<String>::new(), "the next run sweeps what killed runs left");
}

#[test]
fn a_conversion_killed_at_any_moment_leaves_a_header_with_its_own_data() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (name, radius) in [("a.nii", "5"), ("b.nii", "9")] {
        let out = Command::new(mdtf_path())
            .args(["synth", "erf-sphere", "-o", name, "--size", "96", "--radius", radius, "-q"])
            .current_dir(d)
            .output()
            .unwrap();
        assert!(out.status.success());
    }
    let a = read_scalar(&d.join("a.nii"), &ReadOptions::default()).unwrap();
    let b = read_scalar(&d.join("b.nii"), &ReadOptions::default()).unwrap();
    let seconds = duration_of(&["convert", "a.nii", "out.nhdr", "-q"], d);
    for k in 0..KILLS {
        let src = if k % 2 == 0 { "b.nii" } else { "a.nii" };
        let after = Duration::from_secs_f64(seconds * (k as f64 + 0.5) / KILLS as f64 * 1.1);
        kill_at(&["convert", src, "out.nhdr", "-q"], d, after);
        let now = read_scalar(&d.join("out.nhdr"), &ReadOptions::default())
            .unwrap_or_else(|e| panic!("killed after {after:?}: {e}"));
        assert!(now.samples() == a.samples() || now.samples() == b.samples(), "killed after {after:?}: mixed data");
    }
    let out = Command::new(mdtf_path()).args(["convert", "b.nii", "out.nhdr", "-q"]).current_dir(d).output().unwrap();
    assert!(out.status.success());
    assert_eq!(read_scalar(&d.join("out.nhdr"), &ReadOptions::default()).unwrap().samples(), b.samples());
    assert_eq!(leftovers(d), Vec::<String>::new());
}

#[cfg(unix)]
#[test]
fn an_interrupt_removes_the_partial_output_and_exits_130_or_143() {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = shipped_pipeline("distance-tf");
    let args = ["run", pipeline.to_str().unwrap(), "-o", "out", "--set", "input.size=64", "-q"];
    let seconds = duration_of(&args, dir.path());
    let before = std::fs::read(dir.path().join("out/run_report.json")).unwrap();
    for (signal, code) in [("-INT", 130), ("-TERM", 143), ("-HUP", 129)] {
        let mut child = spawn(&args, dir.path());
        std::thread::sleep(Duration::from_secs_f64(seconds * 0.4));
        let status = Command::new("kill").args([signal, &child.id().to_string()]).status().unwrap();
        assert!(status.success());
        let exit = child.wait().unwrap();
        if exit.success() {
            continue; // finished before the signal: nothing to check
        }
        assert_eq!(exit.code(), Some(code), "{signal}");
        let mut err = String::new();
        std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
        assert!(err.contains("partial output(s) removed") && !err.contains("panicked"), "{signal}: {err}");
        assert_eq!(leftovers(dir.path()), Vec::<String>::new(), "{signal}: partial output left");
        assert_eq!(std::fs::read(dir.path().join("out/run_report.json")).unwrap(), before, "{signal}");
    }
}

#[test]
fn a_second_run_into_an_output_being_written_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = shipped_pipeline("distance-tf");
    let args = ["run", pipeline.to_str().unwrap(), "-o", "out", "--set", "input.size=64", "-q"];
    let mut first = spawn(&args, dir.path());
    std::thread::sleep(Duration::from_millis(300));
    let second = Command::new(mdtf_path()).args(args).current_dir(dir.path()).output().unwrap();
    let first_ok = first.wait().unwrap().success();
    assert!(first_ok);
    let err = String::from_utf8_lossy(&second.stderr);
    assert_eq!(second.status.code(), Some(1), "{err}");
    assert!(err.contains("another mdtf run is writing this output"), "{err}");
    assert_complete_run_output(&dir.path().join("out"), "after both");
    assert_eq!(leftovers(dir.path()), Vec::<String>::new());
}

/// Mounts a small tmpfs at `dir`; false where mounting is not permitted.
fn mount_small_disk(dir: &Path, mib: usize) -> bool {
    Command::new("mount")
        .args(["-t", "tmpfs", "-o", &format!("size={mib}m"), "tmpfs", dir.to_str().unwrap()])
        .output()
        .is_ok_and(|o| o.status.success())
}

#[test]
fn a_full_disk_leaves_the_old_output_and_nothing_partial() {
    let dir = tempfile::tempdir().unwrap();
    let disk = dir.path().join("disk");
    std::fs::create_dir(&disk).unwrap();
    if !mount_small_disk(&disk, 4) {
        eprintln!("skipped: this machine does not permit mounting a tmpfs (needs root)");
        return;
    }
    let pipeline = shipped_pipeline("distance-tf");
    let run = |size: &str| {
        Command::new(mdtf_path())
            .args(["run", pipeline.to_str().unwrap(), "-o", "out", "--set", &format!("input.size={size}"), "-q"])
            .current_dir(&disk)
            .output()
            .unwrap()
    };
    let small = run("16");
    let result = std::panic::catch_unwind(|| {
        assert!(small.status.success(), "{}", String::from_utf8_lossy(&small.stderr));
        let before = std::fs::read(disk.join("out/run_report.json")).unwrap();
        let big = run("96");
        let err = String::from_utf8_lossy(&big.stderr);
        assert_eq!(big.status.code(), Some(1), "{err}");
        assert!(err.contains("No space left"), "{err}");
        assert_eq!(std::fs::read(disk.join("out/run_report.json")).unwrap(), before);
        assert_complete_run_output(&disk.join("out"), "after the full disk");
        assert_eq!(leftovers(&disk), Vec::<String>::new());
        // a new folder that cannot be filled is not left behind, half or empty
        let derive = Command::new(mdtf_path())
            .args(["synth", "erf-sphere", "-o", "big.nii", "--size", "160", "-q"])
            .current_dir(&disk)
            .output()
            .unwrap();
        assert_eq!(derive.status.code(), Some(1));
        assert!(!disk.join("big.nii").exists());
        assert_eq!(leftovers(&disk), Vec::<String>::new());
    });
    let _ = Command::new("umount").arg(&disk).status();
    if let Err(e) = result {
        std::panic::resume_unwind(e);
    }
}
