//! Block execution gives the whole-volume run's outputs byte for byte: every
//! shipped pipeline it takes, run slab by slab with slabs of 1, 7 and 33
//! planes and under a budget that forces at least 8 slabs, writes the same
//! files (pack textures and tables, manifest, kept volumes, histogram counts
//! and figures, the boundary report, the preview) as the whole-volume run,
//! on the 64^3 phantom and on a noisy anisotropic file read by planes with
//! the pre-filter on. The run report differs only in its timings. So do
//! runs whose derive, pre-filter and tracing passes go to tasks (run out of
//! order, on several threads, one of them twice, each from the job's JSON,
//! as `mdtf.dask` hands them to a cluster).

use mdtf_pipeline::blocks::{SlabJob, SlabPass, SlabSize, SlabTasks, TaskFailed, TaskOutcome, run_task};
use mdtf_pipeline::file::{Pipeline, parse};
use mdtf_pipeline::run::{RunError, RunOptions, RunReport};
use mdtf_pipeline::settings::Settings;
use mdtf_volume::{Geometry, SampleType, Volume, WriteOptions, write_volume};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// The whole-volume run of `p` with `opts`.
fn run_whole(p: &Pipeline, opts: &RunOptions, on_stage: &(dyn Fn(&str) + Sync)) -> Result<RunReport, RunError> {
    mdtf_pipeline::run::run(&Settings::new(p, opts), opts, on_stage)
}

/// The run of `p` with `opts` by slabs of `size`.
fn run_blocks(
    p: &Pipeline,
    opts: &RunOptions,
    size: SlabSize,
    on_stage: &(dyn Fn(&str) + Sync),
    on_slab: &(dyn Fn(usize, usize) + Sync),
) -> Result<RunReport, RunError> {
    mdtf_pipeline::blocks::run(&Settings::new(p, opts), opts, size, on_stage, on_slab)
}

fn pipelines_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pipelines")
}

/// Every file under `dir` (relative path -> bytes), with the run report's
/// timings and the report page (which prints them) left out.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let path = e.unwrap().path();
            let rel = path.strip_prefix(root).unwrap().to_string_lossy().into_owned();
            if path.is_dir() {
                walk(root, &path, out);
            } else if rel == "run_report.json" {
                let mut r: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
                for s in r["stages"].as_array_mut().unwrap() {
                    for k in ["seconds", "mvoxel_per_s", "peak_mib"] {
                        s.as_object_mut().unwrap().remove(k);
                    }
                }
                for k in ["total_seconds", "peak_mib"] {
                    r.as_object_mut().unwrap().remove(k);
                }
                // how the run was cut is recorded by slab-by-slab runs only
                r.as_object_mut().unwrap().remove("slabs");
                out.insert(rel, serde_json::to_vec_pretty(&keys_sorted(r)).unwrap());
            } else if rel != "report.html" && rel != ".mdtf-output" {
                out.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

/// `v` with every object's keys in sorted order: serde_json keeps insertion
/// order when a dependency enables its `preserve_order` feature (zarrs does),
/// and `remove` then moves the last key into the gap, so the order of keys
/// would depend on which keys were removed rather than on the report.
fn keys_sorted(v: serde_json::Value) -> serde_json::Value {
    match v {
        serde_json::Value::Object(map) => {
            let sorted: BTreeMap<String, serde_json::Value> =
                map.into_iter().map(|(k, v)| (k, keys_sorted(v))).collect();
            serde_json::Value::Object(sorted.into_iter().collect())
        }
        serde_json::Value::Array(items) => serde_json::Value::Array(items.into_iter().map(keys_sorted).collect()),
        other => other,
    }
}

/// The names of the files that differ between two runs (or exist in one only).
fn differing(a: &BTreeMap<String, Vec<u8>>, b: &BTreeMap<String, Vec<u8>>) -> Vec<String> {
    let names: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    names.into_iter().filter(|n| a.get(*n) != b.get(*n)).cloned().collect()
}

/// Runs `p` whole, then slab by slab with each of `sizes`, into the same
/// output path (the preview names it); asserts every run's files equal the
/// whole run's and returns how many files were compared.
fn assert_slab_runs_equal_the_whole(name: &str, p: &Pipeline, input: Option<PathBuf>, sizes: &[SlabSize]) -> usize {
    assert_runs_equal_the_whole(name, p, input, sizes, None)
}

/// [`assert_slab_runs_equal_the_whole`], the slab runs handing their passes to `tasks`.
fn assert_runs_equal_the_whole(
    name: &str,
    p: &Pipeline,
    input: Option<PathBuf>,
    sizes: &[SlabSize],
    tasks: Option<Arc<dyn SlabTasks>>,
) -> usize {
    let dir = tempfile::tempdir().unwrap();
    let mut opts = RunOptions {
        pipeline_path: pipelines_dir().join(format!("{name}.toml")),
        input,
        output: dir.path().join("out"),
        ..Default::default()
    };
    run_whole(p, &opts, &|_| {}).unwrap();
    let whole = files(&opts.output);
    std::fs::remove_dir_all(&opts.output).unwrap();
    opts.tasks = tasks;
    for &size in sizes {
        run_blocks(p, &opts, size, &|_| {}, &|_, _| {}).unwrap_or_else(|e| panic!("{name} {size:?}: {e}"));
        let slabbed = files(&opts.output);
        assert_eq!(differing(&whole, &slabbed), Vec::<String>::new(), "{name}, {size:?}");
        assert!(!opts.output.join(".slabs").exists(), "the channel store is gone");
        std::fs::remove_dir_all(&opts.output).unwrap();
    }
    whole.len()
}

fn shipped(name: &str, sets: &[&str]) -> Pipeline {
    let text = std::fs::read_to_string(pipelines_dir().join(format!("{name}.toml"))).unwrap();
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    parse(&text, &sets).unwrap()
}

/// The shipped distance-tf as the README advises for clean data: without its
/// pre-filter, derived with central4.
fn distance_tf_for_clean_data(sets: &[&str]) -> Pipeline {
    let text = std::fs::read_to_string(pipelines_dir().join("distance-tf.toml")).unwrap();
    let text = text.replace("[prefilter]\nsigma_d = 1.0\nsigma_r = 0.1\nmode = \"fast\"\n", "");
    let mut sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    sets.push("derive.kernel=\"central4\"".into());
    let p = parse(&text, &sets).unwrap();
    assert!(p.prefilter.is_none(), "the shipped pre-filter section changed");
    p
}

/// A budget that gives the clean-data distance-tf on 64 x 64 planes slabs of 8 planes (8 slabs of 64) when its
/// tracing reads whole planes: the fixed costs (48 MiB, 88 MiB for the histogram volume) and 402
/// planes, of which the tracing needs 17 per slab plane (7 arrays over the block, and 10 outputs:
/// two blocks' five) and 7 x (2 x 17 + 2 x 2) = 266 for its halo.
const EIGHT_SLAB_BUDGET: u64 = 48 * 1024 * 1024 + 88 * 1024 * 1024 + 402 * 64 * 64 * 4;

#[test]
fn the_shipped_pipelines_give_the_same_files_slab_by_slab() {
    for name in ["slicer-3dtf", "distance-tf", "peak-finding", "gaussian-tf"] {
        // gaussian-tf ships on the three-field phantom; slabs take one field
        let p = shipped(name, &["input.size=64", "input.phantom=\"shells\""]);
        let sizes = [
            SlabSize::Planes(1),
            SlabSize::Planes(7),
            SlabSize::Planes(33),
            SlabSize::Budget(EIGHT_SLAB_BUDGET),
            // the tracing in strips of rows, as a budget too small for its halo on whole planes makes it
            SlabSize::Strips { planes: 7, rows: 5 },
            SlabSize::Strips { planes: 1, rows: 33 },
        ];
        let compared = assert_slab_runs_equal_the_whole(name, &p, None, &sizes);
        assert!(compared >= 15, "{name}: {compared} files compared");
    }
}

#[test]
fn the_budget_sets_the_slab_height_and_a_budget_too_small_is_refused_before_any_output() {
    let p = distance_tf_for_clean_data(&["input.size=64"]);
    let geo = Geometry::new([64; 3], [1.0; 3]);
    let plan = mdtf_pipeline::plan::Plan::resolve(&Settings::new(&p, &Default::default()), &[], &geo).unwrap();
    let h = mdtf_pipeline::blocks::slab_height(EIGHT_SLAB_BUDGET, &geo, &plan, true).unwrap();
    assert_eq!(h, 8, "8 slabs of 64 planes");
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions {
        pipeline_path: pipelines_dir().join("distance-tf.toml"),
        input: None,
        output: dir.path().join("out"),
        ..Default::default()
    };
    let e = run_blocks(&p, &opts, SlabSize::Budget(64 << 20), &|_| {}, &|_, _| {}).unwrap_err().to_string();
    assert!(e.contains("too small") && e.contains("needs"), "{e}");
    assert!(!opts.output.exists(), "nothing is published");
}

#[test]
fn an_anisotropic_noisy_file_read_by_planes_gives_the_same_files_with_and_without_the_prefilter() {
    // the tooth phantom on 1 x 0.8 x 1.3 mm voxels, noisy, stored as u16 NRRD (read by planes)
    let geo = Geometry::new([44, 40, 50], [1.0, 0.8, 1.3]);
    let mut v = mdtf_datagen::RadialPhantom::tooth(geo, 1.5).volume();
    mdtf_datagen::add_gaussian_noise(&mut v, 3.0, 5);
    let v = Volume { geometry: v.geometry.clone(), data: v.data.mapv(|x| x.round().clamp(0.0, 65535.0)) };
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("tooth.nrrd");
    write_volume(&input, &v, &WriteOptions { ty: SampleType::U16, gzip: false }, &[]).unwrap();
    let text = "keep = [\"distance\", \"g_hit\", \"hit\", \"g\"]\n[derive]\nkernel = \"gauss:1\"\n\
                [prefilter]\nsigma_d = 1.0\nsigma_r = 0.1\n[histogram]\njoint = true\nstretched = true\nhvol = true\n\
                [pack]\nprofile = \"distance-tf\"\nalpha = { kind = \"linear\", a = 1.0, dc = 3.0 }\n";
    let p = parse(text, &[]).unwrap();
    let sizes = [SlabSize::Planes(1), SlabSize::Planes(7), SlabSize::Planes(33)];
    let compared = assert_slab_runs_equal_the_whole("distance-tf", &p, Some(input.clone()), &sizes);
    assert!(compared >= 20, "{compared} files compared");
    // gzip NRRD input, streamed
    let gz = dir.path().join("tooth-gz.nrrd");
    write_volume(&gz, &v, &WriteOptions { ty: SampleType::U16, gzip: true }, &[]).unwrap();
    let slicer = parse("[histogram]\njoint = true\nhvol = true\n[pack]\nprofile = \"slicer-3dtf\"\n", &[]).unwrap();
    // the tracing by strips of rows, deriving its channels, or with the pre-filter reading the
    // filtered g and f'' over each strip from the store
    let no_prefilter = parse(&text.replace("[prefilter]\nsigma_d = 1.0\nsigma_r = 0.1\n", ""), &[]).unwrap();
    assert!(no_prefilter.prefilter.is_none());
    let strips = [SlabSize::Strips { planes: 6, rows: 7 }, SlabSize::Strips { planes: 11, rows: 1 }];
    assert_slab_runs_equal_the_whole("distance-tf", &no_prefilter, Some(input.clone()), &strips);
    assert_slab_runs_equal_the_whole("distance-tf", &p, Some(input.clone()), &strips);
    assert_slab_runs_equal_the_whole("slicer-3dtf", &slicer, Some(gz), &[SlabSize::Planes(7)]);
}

#[test]
fn on_pure_noise_gaussian_tf_takes_the_median_default_slab_by_slab_as_whole() {
    // no boundary is found: the default TGTF comes from medians over the whole volume
    let geo = Geometry::new([40, 36, 45], [1.0, 1.0, 1.5]);
    let mut v = Volume::from_samples(geo.clone(), vec![1000.0; geo.voxel_count()]).unwrap();
    mdtf_datagen::add_gaussian_noise(&mut v, 40.0, 9);
    let v = Volume { geometry: geo, data: v.data.mapv(|x| x.round().clamp(0.0, 65535.0)) };
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("noise.nrrd");
    write_volume(&input, &v, &WriteOptions { ty: SampleType::U16, gzip: false }, &[]).unwrap();
    let p = parse("[histogram]\njoint = true\n[pack]\nprofile = \"gaussian-tf\"\n", &[]).unwrap();
    let sizes = [SlabSize::Planes(1), SlabSize::Planes(7), SlabSize::Planes(33)];
    assert_slab_runs_equal_the_whole("gaussian-tf", &p, Some(input.clone()), &sizes);
    // as tasks, whose select passes after the pack's take the medians: g's (its second pass), then v's
    // over the voxels above twice it (both passes)
    let tasks = Arc::new(ThreadTasks::default());
    assert_runs_equal_the_whole("gaussian-tf", &p, Some(input.clone()), &[SlabSize::Planes(7)], Some(tasks.clone()));
    let passes: Vec<String> = tasks.ran.lock().unwrap().iter().map(|(p, _)| p.clone()).collect();
    assert_eq!(passes, ["Derive", "Pack", "Select", "Select", "Select"].map(String::from));
    let out = dir.path().join("check");
    let opts = RunOptions {
        pipeline_path: pipelines_dir().join("gaussian-tf.toml"),
        input: Some(input),
        output: out,
        ..Default::default()
    };
    run_blocks(&p, &opts, SlabSize::Planes(5), &|_| {}, &|_, _| {}).unwrap();
    let g: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(opts.output.join("pack/gaussians.json")).unwrap()).unwrap();
    let g = g.as_array().unwrap();
    assert_eq!(g.len(), 1, "one white TGTF: {g:?}");
    let centre = g[0]["centre"][0].as_f64().unwrap();
    assert!((centre - 1000.0).abs() < 5.0, "centre {centre} at the noise's median");
}

#[test]
fn pipelines_it_cannot_run_by_slabs_are_refused_with_the_reason_and_no_output() {
    for (name, set, why) in [
        ("gaussian-tf", "input.size=32", "the input has 3 fields"),
        ("gaussian-tf", "pack.gtf_from_mask=\"mask.nii\"", "reads the whole mask"),
        ("projected-tetrahedra", "input.size=32", "does not run slab by slab"),
    ] {
        let p = shipped(name, &["input.size=32", set]);
        let dir = tempfile::tempdir().unwrap();
        let opts = RunOptions {
            pipeline_path: pipelines_dir().join(format!("{name}.toml")),
            input: None,
            output: dir.path().join("out"),
            ..Default::default()
        };
        let e = run_blocks(&p, &opts, SlabSize::Planes(4), &|_| {}, &|_, _| {}).unwrap_err().to_string();
        assert!(e.contains(why), "{name}: {e}");
        assert!(!opts.output.exists(), "{name}: nothing is written");
    }
}

#[test]
fn a_cancelled_run_stops_and_leaves_no_output() {
    let p = shipped("distance-tf", &["input.size=24", "preview=false"]);
    let dir = tempfile::tempdir().unwrap();
    let cancel = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let opts = RunOptions {
        pipeline_path: pipelines_dir().join("distance-tf.toml"),
        input: None,
        output: dir.path().join("out"),
        cancel: Some(cancel),
        ..Default::default()
    };
    let whole = run_whole(&p, &opts, &|_| {}).unwrap_err().to_string();
    let slabs = run_blocks(&p, &opts, SlabSize::Planes(4), &|_| {}, &|_, _| {}).unwrap_err().to_string();
    for e in [whole, slabs] {
        assert!(e.contains("cancelled"), "{e}");
    }
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(left.is_empty(), "no output and no partial folder: {left:?}");
}

#[test]
fn a_run_cancelled_inside_each_pass_stops_there_and_leaves_no_output() {
    use std::sync::atomic::{AtomicBool, Ordering};
    let p = shipped("distance-tf", &["input.size=24", "preview=false"]);
    for pass in ["input", "derive", "boundary", "histogram and pack"] {
        let dir = tempfile::tempdir().unwrap();
        let cancel = std::sync::Arc::new(AtomicBool::new(false));
        let opts = RunOptions {
            pipeline_path: pipelines_dir().join("distance-tf.toml"),
            input: None,
            output: dir.path().join("out"),
            cancel: Some(cancel.clone()),
            ..Default::default()
        };
        let current = std::sync::Mutex::new(String::new());
        let later_stages = std::sync::Mutex::new(Vec::new());
        let on_stage = |s: &str| {
            if cancel.load(Ordering::Relaxed) {
                later_stages.lock().unwrap().push(s.to_string());
            }
            *current.lock().unwrap() = s.to_string();
        };
        // the flag is set as the pass's second slab starts (Ctrl-C in the middle of it)
        let on_slab = |k: usize, _| {
            if k == 2 && current.lock().unwrap().starts_with(pass) {
                cancel.store(true, Ordering::Relaxed);
            }
        };
        let e = run_blocks(&p, &opts, SlabSize::Planes(4), &on_stage, &on_slab).unwrap_err().to_string();
        assert!(e.contains("cancelled"), "{pass}: {e}");
        assert!(later_stages.lock().unwrap().is_empty(), "{pass}: went on to {:?}", later_stages.lock().unwrap());
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert!(left.is_empty(), "{pass}: no output and no partial folder: {left:?}");
    }
}

/// Runs each pass's tasks on threads, the last slab first, then the first
/// slab's task again without its partial (a rerun after a worker lost
/// between writing its planes and publishing), each from the job's JSON;
/// counts them.
#[derive(Debug, Default)]
struct ThreadTasks {
    ran: Mutex<Vec<(String, usize)>>,
}

impl SlabTasks for ThreadTasks {
    fn run(&self, job: &SlabJob, slabs: &[Range<usize>]) -> Result<(), TaskFailed> {
        let (pass, ran) = run_on_threads(job, slabs)?;
        let first = slabs.first().cloned().unwrap_or(0..0);
        std::fs::remove_file(job.partial_file(first.start)).map_err(|e| e.to_string())?;
        // without its partial the slab is not done: the task runs again
        let again = run_task(job, first.clone()).map_err(|e| e.to_string())?;
        assert_eq!(again, TaskOutcome::Ran);
        // with it, a task finds its slab done
        assert_eq!(run_task(job, first).map_err(|e| e.to_string())?, TaskOutcome::FoundDone);
        self.ran.lock().unwrap().push((pass, ran + 1));
        Ok(())
    }
}

/// Runs `job`'s tasks of `slabs` on threads, the last slab first, each
/// from the job's JSON: the pass's name in the JSON and the tasks run.
fn run_on_threads(job: &SlabJob, slabs: &[Range<usize>]) -> Result<(String, usize), TaskFailed> {
    let json = serde_json::to_string(job).map_err(|e| e.to_string())?;
    let value: serde_json::Value = serde_json::from_str(&json).map_err(|e| e.to_string())?;
    let pass = value["pass"].as_object().and_then(|o| o.keys().next().cloned()).unwrap_or_default();
    let order: Vec<Range<usize>> = slabs.iter().rev().cloned().collect();
    let results: Vec<Result<(), String>> = std::thread::scope(|s| {
        let handles: Vec<_> = order
            .chunks(3)
            .map(|group| {
                let json = &json;
                s.spawn(move || {
                    let job: SlabJob = serde_json::from_str(json).map_err(|e| e.to_string())?;
                    group.iter().try_for_each(|z| run_task(&job, z.clone()).map(drop).map_err(|e| e.to_string()))
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    results.into_iter().collect::<Result<(), String>>()?;
    Ok((pass, order.len()))
}

#[test]
fn runs_whose_passes_go_to_tasks_give_the_same_files() {
    for name in ["slicer-3dtf", "distance-tf", "peak-finding", "gaussian-tf"] {
        let p = shipped(name, &["input.size=48", "input.phantom=\"shells\""]);
        let tasks = Arc::new(ThreadTasks::default());
        let compared = assert_runs_equal_the_whole(name, &p, None, &[SlabSize::Planes(7)], Some(tasks.clone()));
        assert!(compared >= 15, "{name}: {compared} files compared");
        let ran = tasks.ran.lock().unwrap().clone();
        let passes: Vec<&str> = ran.iter().map(|(p, _)| p.as_str()).collect();
        let want = match name {
            // the select: the second pass of the traced g's median, with the detection's (v, g) counts
            // then the kept distance and g_hit, written by the tasks
            "distance-tf" => vec!["Derive", "Prefilter", "Select", "Trace", "Keep", "Pack"],
            // the (v, 1/g) axis: the second pass of g's median, then both of the median above twice it
            "peak-finding" => vec!["Derive", "Select", "Select", "Select", "Pack"],
            _ => vec!["Derive", "Pack"],
        };
        assert_eq!(passes, want, "{name}");
        // one task per slab, the first twice; the pack's one per fixed part of the histogram volume when it counts it
        let slabs = 48usize.div_ceil(7) + 1;
        let parts = mdtf_histogram::HVOL_PARTS + 1;
        assert!(ran.iter().all(|(p, n)| *n == slabs || (p == "Pack" && *n == parts)), "{name}: {ran:?}");
    }
    // the pre-filter's pass too, on an anisotropic noisy file read by planes
    let geo = Geometry::new([30, 28, 33], [1.0, 0.8, 1.3]);
    let mut v = mdtf_datagen::RadialPhantom::tooth(geo, 1.5).volume();
    mdtf_datagen::add_gaussian_noise(&mut v, 3.0, 5);
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("tooth.nrrd");
    write_volume(&input, &v, &WriteOptions { ty: SampleType::F32, gzip: false }, &[]).unwrap();
    let text = "keep = [\"distance\", \"g\"]\n[prefilter]\nsigma_d = 1.0\nsigma_r = 0.1\n\
                [histogram]\njoint = true\nstretched = true\n[pack]\nprofile = \"distance-tf\"\n";
    let p = parse(text, &[]).unwrap();
    let tasks = Arc::new(ThreadTasks::default());
    assert_runs_equal_the_whole("distance-tf", &p, Some(input), &[SlabSize::Planes(5)], Some(tasks.clone()));
    let passes: Vec<String> = tasks.ran.lock().unwrap().iter().map(|(p, _)| p.clone()).collect();
    // the kept g is remade from the value by the keep tasks, not stored by the derive tasks
    assert_eq!(passes, ["Derive", "Prefilter", "Select", "Trace", "Keep", "Pack"]);
}

#[test]
fn a_zarr_input_is_read_by_the_tasks_with_the_same_files() {
    // an OME-Zarr store reads any planes: each task reads its own slab of the input (chunks of 8
    // planes, slabs of 5: a task reads parts of two chunks), counting the scanner padding too
    let geo = Geometry::new([30, 28, 33], [1.0, 0.8, 1.3]);
    let mut v = mdtf_datagen::RadialPhantom::tooth(geo, 1.5).volume();
    mdtf_datagen::add_gaussian_noise(&mut v, 3.0, 9);
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("tooth.ome.zarr");
    write_volume(&input, &v, &WriteOptions { ty: SampleType::F32, gzip: false }, &[]).unwrap();
    let text = "keep = [\"distance\", \"g\", \"nx\", \"f2\"]\n[input]\npadding = [14.0, 16.0]\n[prefilter]\nsigma_d = 1.0\n\
                sigma_r = 0.1\n[histogram]\njoint = true\nstretched = true\n[pack]\nprofile = \"distance-tf\"\n";
    let p = parse(text, &[]).unwrap();
    let tasks = Arc::new(ThreadTasks::default());
    assert_runs_equal_the_whole("distance-tf", &p, Some(input), &[SlabSize::Planes(5)], Some(tasks.clone()));
    let passes: Vec<String> = tasks.ran.lock().unwrap().iter().map(|(p, _)| p.clone()).collect();
    assert_eq!(passes, ["Input", "Derive", "Prefilter", "Select", "Trace", "Keep", "Pack"]);
    // the padding the tasks counted is in the report the runs agree on
    let out = dir.path().join("whole");
    let opts = RunOptions { input: Some(dir.path().join("tooth.ome.zarr")), output: out.clone(), ..Default::default() };
    let warnings = run_whole(&p, &opts, &|_| {}).unwrap().warnings;
    let want = v.samples().iter().filter(|&&x| (14.0..=16.0).contains(&x)).count();
    assert!(want > 100, "{want}");
    assert!(warnings.iter().any(|w| w.contains(&format!("{want} "))), "{want}: {warnings:?}");
}

#[test]
fn tracing_tasks_cut_their_slabs_in_strips_of_rows_with_the_same_files() {
    // the budget of a task decides its strips as the run's own: slabs of 6 planes, strips of 9 rows of 28
    let p = shipped("distance-tf", &["input.size=28", "input.phantom=\"shells\"", "keep=[\"distance\", \"dot\"]"]);
    let tasks = Arc::new(ThreadTasks::default());
    let strips = SlabSize::Strips { planes: 6, rows: 9 };
    assert_runs_equal_the_whole("distance-tf", &p, None, &[strips], Some(tasks.clone()));
    let ran = tasks.ran.lock().unwrap().clone();
    let trace = ran.iter().find(|(p, _)| p == "Trace").map(|(_, n)| *n);
    assert_eq!(trace, Some(28usize.div_ceil(6) + 1), "{ran:?}");
    // without the pre-filter the median's first pass is the derive tasks' count of g
    let mut unfiltered = p.clone();
    unfiltered.prefilter = None;
    assert_runs_equal_the_whole("distance-tf", &unfiltered, None, &[strips], Some(Arc::new(ThreadTasks::default())));
    // the report counts each pass's tasks and the rerun of its first
    let passes: Vec<(String, usize, u64)> = task_passes(&p, Arc::new(ThreadTasks::default()), strips)
        .into_iter()
        .map(|t| (t.pass, t.tasks, t.retries))
        .collect();
    let slabs = 28usize.div_ceil(6);
    let want: Vec<(String, usize, u64)> = [
        ("derive", slabs),
        ("prefilter", slabs),
        ("select", slabs),
        ("boundary", slabs),
        ("keep", slabs),
        ("pack", mdtf_histogram::HVOL_PARTS),
    ]
    .into_iter()
    .map(|(p, n)| (p.to_string(), n, 1))
    .collect();
    assert_eq!(passes, want);
}

/// Runs each pass's tasks on threads, then, when the first slab's task
/// wrote something, damages its first byte (a write the disk lost) and
/// runs every task again: only that one is made again.
#[derive(Debug, Default)]
struct DamagingTasks;

impl SlabTasks for DamagingTasks {
    fn run(&self, job: &SlabJob, slabs: &[Range<usize>]) -> Result<(), TaskFailed> {
        run_on_threads(job, slabs)?;
        let written = job.partial(slabs[0].start).map_err(|e| e.to_string())?.written;
        if let Some(piece) = written.first() {
            let mut bytes = std::fs::read(&piece.file).map_err(|e| e.to_string())?;
            bytes[piece.bytes.start as usize] ^= 0x5a;
            std::fs::write(&piece.file, bytes).map_err(|e| e.to_string())?;
        }
        run_on_threads(job, slabs).map(drop)
    }
}

#[test]
fn a_task_whose_slab_is_done_does_nothing_and_one_whose_bytes_were_damaged_is_run_again() {
    let p = shipped("distance-tf", &["input.size=28", "input.phantom=\"shells\"", "preview=false"]);
    let size = SlabSize::Planes(6);
    assert_runs_equal_the_whole("distance-tf", &p, None, &[size], Some(Arc::new(DamagingTasks)));
    let passes: Vec<(String, u64, usize)> =
        task_passes(&p, Arc::new(DamagingTasks), size).into_iter().map(|t| (t.pass, t.retries, t.reused)).collect();
    // the select pass, and the derive pass of a run that keeps no derived channel, write no planes: nothing to damage
    let want: Vec<(String, u64, usize)> =
        [("derive", 0), ("prefilter", 1), ("select", 0), ("boundary", 1), ("keep", 1), ("pack", 1)]
            .into_iter()
            .map(|(p, r)| (p.to_string(), r, 0))
            .collect();
    assert_eq!(passes, want);
}

/// Runs each pass's tasks on threads (each once).
#[derive(Debug, Default)]
struct PlainTasks;

impl SlabTasks for PlainTasks {
    fn run(&self, job: &SlabJob, slabs: &[Range<usize>]) -> Result<(), TaskFailed> {
        run_on_threads(job, slabs).map(drop)
    }
}

/// Runs each pass's tasks on threads up to the tracing, whose first half
/// of the slabs' tasks run before the process dies as `kill -9` kills it.
#[derive(Debug, Default)]
struct DyingTasks;

impl SlabTasks for DyingTasks {
    fn run(&self, job: &SlabJob, slabs: &[Range<usize>]) -> Result<(), TaskFailed> {
        if matches!(job.pass, SlabPass::Trace { .. }) {
            run_on_threads(job, &slabs[..slabs.len() / 2])?;
            std::process::abort();
        }
        run_on_threads(job, slabs).map(drop)
    }
}

/// The environment variable that makes [`a_killed_run_resumes_running_only_its_unfinished_tasks_with_the_same_files`]
/// the run that dies (in a process of its own), into the output it names.
const DIE_INTO: &str = "MDTF_TEST_RUN_DIES_INTO";

#[test]
fn a_killed_run_resumes_running_only_its_unfinished_tasks_with_the_same_files() {
    let p = shipped("distance-tf", &["input.size=28", "input.phantom=\"shells\"", "preview=false"]);
    let size = SlabSize::Planes(6);
    let opts = |output: PathBuf, tasks: Arc<dyn SlabTasks>| RunOptions {
        pipeline_path: pipelines_dir().join("distance-tf.toml"),
        output,
        tasks: Some(tasks),
        resume: true,
        ..Default::default()
    };
    if let Some(out) = std::env::var_os(DIE_INTO) {
        let e = run_blocks(&p, &opts(out.into(), Arc::new(DyingTasks)), size, &|_| {}, &|_, _| {});
        panic!("the run was to die in its tracing: {e:?}");
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let name = "a_killed_run_resumes_running_only_its_unfinished_tasks_with_the_same_files";
    let status = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", name, "--test-threads=1"])
        .env(DIE_INTO, &out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(!status.success(), "the first run died");
    let left: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(left.iter().any(|n| n.starts_with(".mdtf-partial-out-")) && !out.exists(), "{left:?}");
    let report = run_blocks(&p, &opts(out.clone(), Arc::new(PlainTasks)), size, &|_| {}, &|_, _| {}).unwrap();
    let slabs = report.slabs.unwrap();
    assert!(slabs.resumed);
    let passes: Vec<(String, usize, u64, usize)> =
        slabs.tasks.into_iter().map(|t| (t.pass, t.tasks, t.retries, t.reused)).collect();
    // every pass before the tracing was done, and half the tracing's slabs
    let n = 28usize.div_ceil(6);
    let want: Vec<(String, usize, u64, usize)> = [
        ("derive", n, n),
        ("prefilter", n, n),
        ("select", n, n),
        ("boundary", n, n / 2),
        ("keep", n, 0),
        ("pack", mdtf_histogram::HVOL_PARTS, 0),
    ]
    .into_iter()
    .map(|(p, tasks, reused)| (p.to_string(), tasks, 0, reused))
    .collect();
    assert_eq!(passes, want);
    let resumed = files(&out);
    assert!(!resumed.contains_key(mdtf_volume::output::RESUME_NAME), "the resume key is not an output");
    let left: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(left, ["out"], "no partial folder is left");
    // the whole run into the same output (the report names it)
    std::fs::remove_dir_all(&out).unwrap();
    run_whole(&p, &RunOptions { tasks: None, ..opts(out.clone(), Arc::new(PlainTasks)) }, &|_| {}).unwrap();
    assert_eq!(differing(&files(&out), &resumed), Vec::<String>::new());
}

/// The passes' tasks, as the report counts them, of a run of the distance-tf `p` with `tasks` in slabs of `size`.
fn task_passes(p: &Pipeline, tasks: Arc<dyn SlabTasks>, size: SlabSize) -> Vec<mdtf_pipeline::report::TaskPass> {
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions {
        pipeline_path: pipelines_dir().join("distance-tf.toml"),
        output: dir.path().join("out"),
        tasks: Some(tasks),
        ..Default::default()
    };
    run_blocks(p, &opts, size, &|_| {}, &|_, _| {}).unwrap().slabs.unwrap().tasks
}

/// Runs each pass's tasks on threads, but the pack pass's, which fail (a
/// worker out of memory) until `healed` is set.
#[derive(Debug, Default)]
struct FailingPackTasks {
    healed: std::sync::atomic::AtomicBool,
}

impl SlabTasks for FailingPackTasks {
    fn run(&self, job: &SlabJob, slabs: &[Range<usize>]) -> Result<(), TaskFailed> {
        if matches!(job.pass, SlabPass::Pack { .. }) && !self.healed.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(TaskFailed("KilledWorker: the worker ran out of memory".into()));
        }
        run_on_threads(job, slabs).map(drop)
    }
}

#[test]
fn a_resumable_run_whose_tasks_failed_keeps_what_they_did_for_the_rerun() {
    let p = shipped("distance-tf", &["input.size=28", "input.phantom=\"shells\"", "preview=false"]);
    let size = SlabSize::Planes(6);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let tasks = Arc::new(FailingPackTasks::default());
    let opts = RunOptions {
        pipeline_path: pipelines_dir().join("distance-tf.toml"),
        output: out.clone(),
        tasks: Some(tasks.clone()),
        resume: true,
        ..Default::default()
    };
    let e = run_blocks(&p, &opts, size, &|_| {}, &|_, _| {}).unwrap_err().to_string();
    let left: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(left.len() == 1 && left[0].starts_with(".mdtf-partial-out-"), "{left:?}");
    assert!(
        e.starts_with("pack: a task failed: KilledWorker")
            && e.contains(&format!("kept in {}", dir.path().join(&left[0]).display())),
        "{e}"
    );
    tasks.healed.store(true, std::sync::atomic::Ordering::Relaxed);
    let slabs = run_blocks(&p, &opts, size, &|_| {}, &|_, _| {}).unwrap().slabs.unwrap();
    let reused: Vec<(String, usize)> = slabs.tasks.into_iter().map(|t| (t.pass, t.reused)).collect();
    let n = 28usize.div_ceil(6);
    let want: Vec<(String, usize)> =
        [("derive", n), ("prefilter", n), ("select", n), ("boundary", n), ("keep", n), ("pack", 0)]
            .map(|(p, k)| (p.to_string(), k))
            .into();
    assert!(slabs.resumed);
    assert_eq!(reused, want);
    let resumed = files(&out);
    std::fs::remove_dir_all(&out).unwrap();
    run_whole(&p, &RunOptions { tasks: None, ..opts }, &|_| {}).unwrap();
    assert_eq!(differing(&files(&out), &resumed), Vec::<String>::new());
}

/// Tasks that fail as a lost store would make them.
#[derive(Debug)]
struct FailingTasks;

impl SlabTasks for FailingTasks {
    fn run(&self, job: &SlabJob, slabs: &[Range<usize>]) -> Result<(), TaskFailed> {
        let mut job = job.clone();
        job.store = job.store.join("gone");
        run_task(&job, slabs[0].clone()).map(drop).map_err(|e| TaskFailed(e.to_string()))
    }
}

#[test]
fn a_failed_task_fails_the_run_with_its_message_and_no_output() {
    let p = shipped("distance-tf", &["input.size=24", "preview=false"]);
    let dir = tempfile::tempdir().unwrap();
    // resumable, but no task had finished: nothing is kept
    let opts = RunOptions {
        pipeline_path: pipelines_dir().join("distance-tf.toml"),
        output: dir.path().join("out"),
        tasks: Some(Arc::new(FailingTasks)),
        resume: true,
        ..Default::default()
    };
    let e = run_blocks(&p, &opts, SlabSize::Planes(4), &|_| {}, &|_, _| {}).unwrap_err().to_string();
    // the task names the store folder it cannot find
    assert!(e.starts_with("derive: a task failed: ") && e.contains("gone"), "{e}");
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(left.is_empty(), "no output and no partial folder: {left:?}");
    // a slab outside the volume is refused
    let job = SlabJob {
        store: dir.path().to_path_buf(),
        geometry: Geometry::new([4, 4, 4], [1.0; 3]),
        stored: vec![mdtf_pipeline::channel::Channel::Value],
        groups: vec![],
        kernel_reach: 1,
        pass: mdtf_pipeline::blocks::SlabPass::Derive { summarise: vec![], store: vec![] },
        token: String::new(),
    };
    let e = run_task(&job, 2..9).unwrap_err().to_string();
    assert!(e.contains("not a slab of the volume's 4"), "{e}");
}

/// Runs the first slab's task as a killed driver's would, its run token
/// not the current one; then the pass as it should.
#[derive(Debug, Default)]
struct OrphanTasks {
    refused: Mutex<Vec<String>>,
}

impl SlabTasks for OrphanTasks {
    fn run(&self, job: &SlabJob, slabs: &[Range<usize>]) -> Result<(), TaskFailed> {
        let orphan = SlabJob { token: format!("{}-before", job.token), ..job.clone() };
        let e = run_task(&orphan, slabs[0].clone()).expect_err("an orphaned task is refused");
        // it published nothing: the slab is not done
        assert!(!orphan.partial_file(slabs[0].start).exists());
        self.refused.lock().unwrap().push(e.to_string());
        run_on_threads(job, slabs).map(drop)
    }
}

#[test]
fn a_task_of_a_run_that_was_taken_over_publishes_nothing() {
    let p = shipped("slicer-3dtf", &["input.size=20", "preview=false"]);
    let tasks = Arc::new(OrphanTasks::default());
    assert_runs_equal_the_whole("slicer-3dtf", &p, None, &[SlabSize::Planes(7)], Some(tasks.clone()));
    let refused = tasks.refused.lock().unwrap().clone();
    assert_eq!(refused.len(), 2, "derive and pack: {refused:?}");
    assert!(refused.iter().all(|e| e.contains("taken over by a later run")), "{refused:?}");
}

#[test]
fn every_derivative_channel_and_dot_are_kept_right_and_the_same_slab_by_slab() {
    let keep = ["v", "value", "g", "f2", "nx", "ny", "nz", "gx", "gy", "gz", "hxx", "hxy", "hxz", "hyy", "hyz"];
    let keep: Vec<String> =
        keep.iter().chain(&["hzz", "laplacian", "curvature", "dot", "hit"]).map(|s| s.to_string()).collect();
    let keep_set = format!("keep={keep:?}");
    let p = distance_tf_for_clean_data(&["input.size=40", "input.sigma=2.0", &keep_set, "preview=false"]);
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions {
        pipeline_path: pipelines_dir().join("distance-tf.toml"),
        output: dir.path().join("out"),
        ..Default::default()
    };
    run_whole(&p, &opts, &|_| {}).unwrap();
    let read = |c: &str| -> Vec<f32> {
        let path = opts.output.join(format!("volumes/{c}.nii.gz"));
        let mf = mdtf_volume::read(&path, &Default::default()).unwrap_or_else(|e| panic!("{c}: {e}"));
        mf.into_scalar().unwrap().data.iter().copied().collect()
    };
    let k: BTreeMap<&str, Vec<f32>> = keep.iter().map(|c| (c.as_str(), read(c))).collect();
    let g_max = k["g"].iter().fold(0.0f32, |a, &b| a.max(b));
    let f2_max = k["f2"].iter().fold(0.0f32, |a, &b| a.max(b.abs()));
    let (mut dots, mut hits) = (0.0f64, 0usize);
    let (mut curvature_error, mut near) = (0.0f64, 0usize);
    for i in 0..k["v"].len() {
        let n = [k["nx"][i], k["ny"][i], k["nz"][i]];
        // the gradient is g along the normal
        for (c, &na) in ["gx", "gy", "gz"].iter().zip(&n) {
            assert!((k[c][i] - k["g"][i] * na).abs() < 1e-4 * g_max, "{c} at {i}");
        }
        // the Hessian's components in place: f'' = n^T H n, the Laplacian its trace
        let h = |c: &str| k[c][i];
        let nhn = n[0] * n[0] * h("hxx")
            + n[1] * n[1] * h("hyy")
            + n[2] * n[2] * h("hzz")
            + 2.0 * (n[0] * n[1] * h("hxy") + n[0] * n[2] * h("hxz") + n[1] * n[2] * h("hyz"));
        if k["g"][i] > 0.05 * g_max {
            assert!((nhn - k["f2"][i]).abs() < 1e-3 * f2_max, "n^T H n {nhn} vs f2 {} at {i}", k["f2"][i]);
        }
        assert!((h("hxx") + h("hyy") + h("hzz") - k["laplacian"][i]).abs() < 1e-4 * f2_max, "laplacian at {i}");
        // central4 interpolates: the reconstructed value is the input's
        assert!((k["value"][i] - k["v"][i]).abs() <= 1e-3 * k["v"][i].abs().max(1.0), "value at {i}");
        if k["hit"][i] == 1.0 {
            dots += k["dot"][i] as f64;
            hits += 1;
        }
        // every isosurface of the sphere is a sphere: its mean curvature is 1 / rho
        if k["g"][i] > 0.2 * g_max {
            let (x, y, z) = (i % 40, i / 40 % 40, i / 1600);
            let rho = [x, y, z].iter().map(|&c| (c as f64 - 19.5).powi(2)).sum::<f64>().sqrt();
            curvature_error += (k["curvature"][i] as f64 * rho - 1.0).abs();
            near += 1;
        }
    }
    // on a sphere the normals at a voxel and at its boundary hit are both radial
    assert!(hits > 1000 && dots / hits as f64 > 0.99, "mean dot {} over {hits} hits", dots / hits as f64);
    let curvature_error = curvature_error / near as f64;
    assert!(near > 1000 && curvature_error < 0.01, "curvature x rho: mean |error| {curvature_error} over {near}");
    // the sidecar says what each kept file is, in its units
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(opts.output.join("volumes/channels.json")).unwrap()).unwrap();
    let listed = sidecar["volumes"].as_array().unwrap();
    assert_eq!(listed.iter().map(|e| e["channel"].as_str().unwrap()).collect::<Vec<_>>(), keep);
    let entry = |c: &str| listed.iter().find(|e| e["channel"] == c).unwrap();
    for (c, units, signed, stage) in [
        ("v", "input units", false, "input"),
        ("g", "value units per world unit", false, "derive"),
        ("gx", "value units per world unit", true, "derive"),
        ("laplacian", "value units per world unit^2", true, "derive"),
        ("curvature", "per world unit", true, "derive"),
        ("dot", "1", true, "boundary"),
        ("hit", "code", false, "boundary"),
    ] {
        let e = entry(c);
        assert_eq!(
            (e["units"].as_str(), e["signed"].as_bool(), e["stage"].as_str()),
            (Some(units), Some(signed), Some(stage)),
            "{c}"
        );
        assert_eq!(e["file"], format!("{c}.nii.gz"));
    }
    let sizes = [SlabSize::Planes(7), SlabSize::Strips { planes: 5, rows: 9 }];
    assert_slab_runs_equal_the_whole("distance-tf", &p, None, &sizes);
    // the shading weight divides by the largest g of the whole volume: not by slabs
    let shade = shipped("distance-tf", &["input.size=24", "keep=[\"shade\"]"]);
    let e = run_blocks(&shade, &opts, SlabSize::Planes(4), &|_| {}, &|_, _| {}).unwrap_err().to_string();
    assert!(e.contains("largest g of the whole volume"), "{e}");
}
