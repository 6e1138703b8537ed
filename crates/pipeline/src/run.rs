//! The in-process runner of pipeline files: input -> derive -> (pre-filter,
//! boundary) -> histograms -> pack, with per-stage timings and a report.
//! Everything is written into a temporary folder beside the output and
//! renamed into place at the end, so a failed run leaves the output folder
//! as it was.

use crate::file::{PhantomKind, Pipeline};
use crate::plan::{Plan, Step};
use mdtf_boundary::{AlphaMap, BoundaryInput};
use mdtf_datagen::{MultiFieldPhantom, RadialPhantom, add_gaussian_noise, erf_sphere, min_extent};
use mdtf_derive::{DeriveParams, Item, Kernel};
use mdtf_histogram::{Axis, AxisSpec, HvolParams, count, histogram_volume, hit_mask};
use mdtf_pack::{PackParams, PackWriter, Profile, Provenance, parse_tf};
use mdtf_volume::dicom::DicomOptions;
use mdtf_volume::{
    Geometry, Inputs, MultiField, OutputFolder, ReadOptions, Volume, WriteOptions, write_file_atomically,
};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub use crate::error::RunError;
pub(crate) use crate::error::{at, fail};

/// One stage's line of the run report.
#[derive(Debug, Clone, Serialize)]
pub struct StageReport {
    /// Stage name.
    pub stage: String,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Voxels per second (of the input grid).
    pub mvoxel_per_s: f64,
    /// Peak resident memory of the process after the stage, MiB (Linux; 0 elsewhere).
    pub peak_mib: f64,
    /// Files written by the stage, relative to the output folder.
    pub outputs: Vec<String>,
}

/// The run report, written as run_report.json.
#[derive(Debug, Clone, Serialize)]
pub struct RunReport {
    /// Pipeline file.
    pub pipeline: String,
    /// Output folder.
    pub output: String,
    /// Input (file or phantom).
    pub input: String,
    /// Grid size.
    pub dims: [usize; 3],
    /// Grid spacing, world units.
    pub spacing: [f64; 3],
    /// The input's fields, when it has more than one.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub fields: Vec<String>,
    /// Finite range of the (first) field, input units.
    pub value_range: Option<[f64; 2]>,
    /// What the reader assumed or repaired (e.g. a DICOM series resampled
    /// onto a regular grid), and what a stage left out (e.g. a boundary below
    /// the tracing thresholds).
    pub warnings: Vec<String>,
    /// The boundary tracing's thresholds and counts, when it ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub boundary: Option<BoundarySummary>,
    /// The boundaries found in the histogram volume, when it was built
    /// (`[histogram] hvol`): the materials they separate and their peak g.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub boundaries: Vec<mdtf_histogram::DetectedBoundary>,
    /// Whether the histogram volume was built (so `boundaries` says what was found).
    pub hvol_built: bool,
    /// How the run was cut into z-slabs, when it ran slab by slab.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub slabs: Option<SlabRun>,
    /// The stages, in order.
    pub stages: Vec<StageReport>,
    /// Total wall time, seconds.
    pub total_seconds: f64,
    /// The settings the run used, every default filled in ([`resolved_settings`]).
    pub settings: toml::Table,
}

/// The slabs of a slab-by-slab run.
#[derive(Debug, Clone, Serialize)]
pub struct SlabRun {
    /// z-planes per slab (the last may hold fewer).
    pub planes: usize,
    /// Number of slabs.
    pub count: usize,
    /// The memory budget they were sized for, bytes (None: the height was given).
    pub budget: Option<u64>,
}

impl RunReport {
    /// The report of a run of `opts` on `input` (its grid `geo`), with nothing done yet.
    pub(crate) fn of(opts: &RunOptions, input: String, geo: &Geometry) -> RunReport {
        RunReport {
            pipeline: opts.pipeline_path.display().to_string(),
            output: opts.output.display().to_string(),
            input,
            dims: geo.dims,
            spacing: geo.spacing,
            fields: Vec::new(),
            value_range: None,
            warnings: Vec::new(),
            boundary: None,
            boundaries: Vec::new(),
            hvol_built: false,
            slabs: None,
            stages: Vec::new(),
            total_seconds: 0.0,
            settings: toml::Table::new(),
        }
    }
}

/// What the boundary tracing used and found.
#[derive(Debug, Clone, Serialize)]
pub struct BoundarySummary {
    /// Thresholds and sampling after defaults.
    pub resolved: mdtf_boundary::ResolvedParams,
    /// Voxels per hit code.
    pub counts: mdtf_boundary::TraceCounts,
    /// Boundaries the thresholds took out of the outputs.
    pub lost: Vec<mdtf_boundary::LostBoundary>,
}

/// Peak resident set size of this process in MiB (VmHWM), 0 where unknown.
pub(crate) fn peak_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// Where a run reads from and writes to.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// The pipeline file (relative paths inside it are relative to its folder).
    pub pipeline_path: PathBuf,
    /// Input file replacing the pipeline's.
    pub input: Option<PathBuf>,
    /// Output folder.
    pub output: PathBuf,
    /// Set to stop the run at its next stage or slab, leaving no output
    /// (the Python package sets it on Ctrl-C).
    pub cancel: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

impl RunOptions {
    /// An error when [`RunOptions::cancel`] is set: the run stops there,
    /// and its partial output folder is removed.
    pub fn check_cancelled(&self) -> Result<(), RunError> {
        match &self.cancel {
            Some(c) if c.load(std::sync::atomic::Ordering::Relaxed) => Err(fail("run")("cancelled".into())),
            _ => Ok(()),
        }
    }
}

/// Runs `p`; `on_stage(name)` is called as each stage starts.
pub fn run(p: &Pipeline, opts: &RunOptions, on_stage: &dyn Fn(&str)) -> Result<RunReport, RunError> {
    let start = Instant::now();
    let base = opts.pipeline_path.parent().map(Path::to_path_buf).unwrap_or_default();
    let inputs = run_inputs(p, opts, &base);
    let out = OutputFolder::begin(&opts.output, &inputs).map_err(at("output"))?;
    let dir = out.path();
    let mut stages = Stages::default();

    // input
    on_stage("input");
    opts.check_cancelled()?;
    let t = Instant::now();
    let (input, input_name, mut warnings) = load_input(p, opts, &base)?;
    let mut boundary = None;
    let mut d_max = None;
    let geo = input.geometry.clone();
    let n = geo.voxel_count();
    stages.done("input", t, n, vec![]);

    // what the outputs need: derive items, tracing, when each channel is freed
    let profile = p.pack.profile;
    let field_names: Vec<String> = input.fields.iter().map(|f| f.name.clone()).collect();
    let plan = Plan::resolve(p, &field_names, &geo).map_err(at("plan"))?;
    let fields = plan.fields.clone();
    let needs = |c: &str| plan.wants(c);
    let tracing = plan.trace;
    let defer_normals = plan.defer_normals;
    // Every channel lives here once; stages borrow them and the pack takes them at the end.
    let mut chans: BTreeMap<String, Volume> = BTreeMap::new();
    let multi = !fields.is_empty();
    let (value, input) = if multi {
        let value = input.field_volume(0).ok_or_else(|| fail("input")("no fields".into()))?;
        (value, Some(input))
    } else {
        (input.into_scalar().map_err(at("input"))?, None)
    };
    let finite_range = value.finite_range().map(|(lo, hi)| [lo as f64, hi as f64]);
    let value_range = finite_range.map_or(0.0, |[lo, hi]| hi - lo);

    // derive (only the items the later stages use)
    let kernel: Kernel = p.derive.kernel.unwrap_or(mdtf_derive::DEFAULT_KERNEL);
    let items = plan.derive.clone();
    let mut normal: Option<MultiField> = None;
    // the value volume goes into derive as a one-field MultiField and comes back out: no copy
    let mut value_mf = MultiField::from(value);
    if !items.is_empty() {
        on_stage("derive");
        opts.check_cancelled()?;
        let t = Instant::now();
        let d = DeriveParams { items, kernel, ..Default::default() };
        let out = mdtf_derive::run(&value_mf, &d).map_err(at("derive"))?;
        for (item, mf) in out.items {
            match item {
                Item::Normal => normal = Some(mf),
                other => {
                    let v = mf.into_scalar().map_err(at("derive"))?;
                    chans.insert(other.name().to_string(), v);
                }
            }
        }
        stages.done("derive", t, n, vec![]);
    }
    let multi_items = plan.derive_fields.clone();
    if let Some(mf) = &input
        && !multi_items.is_empty()
    {
        on_stage("derive (multi-field)");
        opts.check_cancelled()?;
        let t = Instant::now();
        let d = DeriveParams { items: multi_items, kernel, ..Default::default() };
        let out = mdtf_derive::run(mf, &d).map_err(at("derive"))?;
        for (item, m) in out.items {
            chans.insert(item.name().into(), m.into_scalar().map_err(at("derive"))?);
        }
        stages.done("derive (multi-field)", t, n, vec![]);
    }
    // the input's fields move into the channels once the multi-field derive is done with them
    if let Some(mf) = input {
        for f in mf.fields {
            if needs(&f.name) {
                chans.insert(f.name, Volume { geometry: geo.clone(), data: f.data });
            }
        }
    }
    if needs("v") && !chans.contains_key("v") {
        let field = value_mf.fields.remove(0);
        chans.insert("v".into(), Volume { geometry: geo.clone(), data: field.data });
    }
    if !defer_normals {
        // nothing reads the value volume from here on unless it is a channel
        value_mf.fields.clear();
    }

    // pre-filter and boundary
    if tracing {
        let (Some(g0), Some(f20), Some(nm)) = (chans.get("g"), chans.get("f2"), normal.as_ref()) else {
            return Err(fail("boundary")("derivatives missing".into()));
        };
        let filtered = match &p.prefilter {
            Some(pf) => {
                on_stage("prefilter");
                opts.check_cancelled()?;
                let t = Instant::now();
                let filter = |v: &Volume| crate::boundary_chain::prefilter(v, pf).map_err(at("prefilter"));
                let pair = (filter(g0)?, filter(f20)?);
                stages.done("prefilter", t, n, vec![]);
                Some(pair)
            }
            None => None,
        };
        let (g, f2) = match &filtered {
            Some((g, f2)) => (g, f2),
            None => (g0, f20),
        };
        on_stage("boundary");
        opts.check_cancelled()?;
        let t = Instant::now();
        let out = mdtf_boundary::run(&BoundaryInput { g, f2, normal: nm, value_range }, &p.boundary)
            .map_err(at("boundary"))?;
        warnings.extend(out.warnings.iter().map(|w| format!("boundary: {w}")));
        d_max = Some(out.resolved.d_max);
        boundary = Some(BoundarySummary { resolved: out.resolved, counts: out.counts, lost: out.lost.clone() });
        let report = out.report(g);
        let rdir = dir.join("boundary");
        std::fs::create_dir_all(&rdir).map_err(at("boundary"))?;
        report.write(&rdir).map_err(at("boundary"))?;
        drop(filtered);
        for (c, v) in [("g_hit", out.g_hit), ("hit", out.hit), ("distance", out.distance)] {
            if needs(c) {
                chans.insert(c.into(), v);
            }
        }
        // derived only for the tracing: free them now
        for c in plan.freed_after(Step::Trace) {
            chans.remove(&c.name(&fields));
        }
        stages.done(
            "boundary",
            t,
            n,
            vec!["boundary/boundary_report.csv".into(), "boundary/boundary_report.png".into()],
        );
    }
    for (c, v) in normal.map(MultiField::into_volumes).unwrap_or_default() {
        if needs(&c) {
            chans.insert(c, v);
        }
    }
    let get = |c: &str| chans.get(c);

    // kept intermediates
    if !p.keep.is_empty() {
        on_stage("keep");
        opts.check_cancelled()?;
        let t = Instant::now();
        let kdir = dir.join("volumes");
        std::fs::create_dir_all(&kdir).map_err(at("keep"))?;
        let mut written = Vec::new();
        for c in &p.keep {
            let v = get(c).ok_or_else(|| fail("keep")(format!("no channel '{c}' was computed")))?;
            let name = p.keep_format.file_name(c);
            mdtf_volume::write_volume(&kdir.join(&name), v, &WriteOptions::default(), &[]).map_err(at("keep"))?;
            written.push(format!("volumes/{name}"));
        }
        stages.done("keep", t, n, written);
    }

    // histograms (the histogram volume is kept for the pack's default opacity;
    // it comes first so that the boundaries it shows are drawn on the others)
    let mut hists = crate::hist_files::Written::default();
    if let Some(h) = &p.histogram {
        on_stage("histogram");
        opts.check_cancelled()?;
        let t = Instant::now();
        let hdir = dir.join("histogram");
        std::fs::create_dir_all(&hdir).map_err(at("histogram"))?;
        let err = |e: String| fail("histogram")(e);
        let (Some(v), Some(g)) = (get("v"), get("g")) else { return Err(err("v and g missing".into())) };
        let axis =
            |name: &str, data: &Volume| AxisSpec::qbert(name).resolve(name, data.samples()).map_err(at("histogram"));
        let axes: Vec<Axis> = vec![axis("v", v)?, axis("g", g)?];
        let mut counted = crate::hist_files::Counted { voxels: n, ..Default::default() };
        if h.hvol
            && let Some(f2) = get("f2")
        {
            counted.hvol = Some(
                histogram_volume(v.samples(), g.samples(), f2.samples(), v.plane_len(), &HvolParams::default())
                    .map_err(at("histogram"))?,
            );
        }
        if h.joint {
            counted.joint = Some(count(&[v.samples(), g.samples()], axes.clone(), None).map_err(at("histogram"))?);
            // peak finding's TF domain: (v, 1/g); for several fields 1/g is of
            // their normalised ||G||, so its axis comes from the gradient it inverts
            let inverted: Option<Vec<f32>> = (!fields.is_empty())
                .then(|| get("inv_g").map(|i| i.samples().iter().map(|&x| 1.0 / x).collect()))
                .flatten();
            if let Some(inv_g) = get("inv_g")
                && let Some(ia) = Axis::inverse_gradient(inverted.as_deref().unwrap_or(g.samples()), 256)
            {
                // several fields: the value is the first field, named as the pack's TF axis names it
                let mut va = axes[0].clone();
                if let Some(first) = fields.first() {
                    va.name = first.clone();
                }
                counted.inv_g =
                    Some(count(&[v.samples(), inv_g.samples()], vec![va, ia], None).map_err(at("histogram"))?);
            }
        }
        if h.stretched
            && let (Some(g_hit), Some(hit)) = (get("g_hit"), get("hit"))
        {
            let traced = hit_mask(hit.samples());
            let normal = count(&[v.samples(), g.samples()], axes.clone(), Some(&traced)).map_err(at("histogram"))?;
            let mut sa = axes.clone();
            sa[1].name = "g_hit".into();
            let stretched = count(&[v.samples(), g_hit.samples()], sa, Some(&traced)).map_err(at("histogram"))?;
            counted.stretched = Some((normal, stretched));
        }
        hists = crate::hist_files::write(&hdir, counted, &input_name, &mut warnings).map_err(err)?;
        if h.joint && !fields.is_empty() {
            hists
                .outputs
                .extend(crate::figures::write_field_pair_histograms(&fields, &chans, &hdir, &input_name).map_err(err)?);
        }
        stages.done("histogram", t, n, hists.outputs.clone());
    }
    let crate::hist_files::Written { boundaries, arches, figure_hists, hvol: hvol_kept, .. } = hists;

    // pack (for meshes: the tetra stage, which writes the pack itself)
    let pack_stage = if profile == Profile::ProjectedTetrahedra { "tetra + pack" } else { "pack" };
    on_stage(pack_stage);
    opts.check_cancelled()?;
    let t = Instant::now();
    let err = |e: String| fail("pack")(e);
    let tf = read_tf(p, &base)?;
    let pdir = dir.join("pack");
    std::fs::create_dir_all(&pdir).map_err(at("pack"))?;
    let provenance = provenance(p, opts, &base, &input_name);
    let mut table_names: Vec<String> = Vec::new();
    let mut pack_outputs: Vec<String> = vec!["pack/manifest.json".into()];
    if profile == Profile::ProjectedTetrahedra {
        let value = get("v").ok_or_else(|| err("no value volume".into()))?;
        let mesh = mdtf_tetra::tetrahedralise(value, p.tetra.tets, "v").map_err(at("pack"))?;
        let out = mdtf_tetra::run(&mesh, &p.tetra, tf.as_ref()).map_err(at("pack"))?;
        warnings.extend(out.notes.iter().map(|n| format!("tetra: {n}")));
        let report = mdtf_tetra::MeshReport::default();
        mdtf_tetra::write_pack(&pdir, &mesh, &report, &out, Some(&geo), provenance).map_err(at("pack"))?;
        drop(mesh);
        // the (s, g) TF the preview draws and a renderer can start from: the TF
        // file's Gaussians, else a TGTF at each boundary found (as gaussian-tf's default)
        let value_and_g: Vec<(String, Volume)> =
            ["v", "g"].into_iter().filter_map(|c| chans.remove(c).map(|v| (c.to_string(), v))).collect();
        let tf_gaussians = tf.as_ref().filter(|t| !t.gaussians().is_empty());
        let g = crate::gaussians::gaussians(
            tf_gaussians,
            None,
            &value_and_g,
            &["v".into()],
            "g",
            (hvol_kept.as_ref(), kernel),
        )
        .map_err(err)?;
        let json = serde_json::to_string_pretty(&g).map_err(at("pack"))?;
        write_file_atomically(&pdir.join("gaussians.json"), |w| w.write_all(json.as_bytes())).map_err(at("pack"))?;
        pack_outputs.push("pack/gaussians.json".into());
    } else {
        // the pack is the last stage to read the channels: they move into it
        let mut pack_chans: Vec<(String, Volume)> =
            profile.channels(&fields).into_iter().filter_map(|c| chans.remove(&c).map(|v| (c, v))).collect();
        let ranges = crate::pack_inputs::ranges(&pack_chans, &BTreeMap::new(), d_max).map_err(at("pack"))?;
        let alpha = p.pack.alpha.unwrap_or(AlphaMap::Linear { a: 1.0, dc: None });
        let luts =
            crate::pack_inputs::luts(profile, tf.as_ref(), &alpha, &pack_chans, &ranges, hvol_kept.as_ref(), kernel)
                .map_err(at("pack"))?;
        table_names = luts.iter().map(|l| l.name.clone()).collect();
        let gaussians = if profile == Profile::GaussianTf {
            let mask = match &p.pack.gtf_from_mask {
                Some(m) => {
                    let path = base.join(m);
                    let v = mdtf_volume::read_scalar(&path, &mdtf_volume::ReadOptions::default())
                        .map_err(|e| err(format!("gtf_from_mask {}: {e}", path.display())))?;
                    Some(v)
                }
                None => None,
            };
            let (axes, gradient) =
                if fields.is_empty() { (vec!["v".to_string()], "g") } else { (fields.clone(), "gnorm") };
            let boundaries_from = (hvol_kept.as_ref(), kernel);
            Some(
                crate::gaussians::gaussians(tf.as_ref(), mask.as_ref(), &pack_chans, &axes, gradient, boundaries_from)
                    .map_err(err)?,
            )
        } else {
            None
        };
        let params = PackParams { profile, ranges, fields: fields.clone(), dtype: None, nifti: p.pack.nifti };
        let sources = BTreeMap::new();
        let layouts = mdtf_pack::texture_layouts(&params);
        let mut writer = PackWriter::new(&pdir, &params, geo.clone(), &sources);
        let mut normals_pending = defer_normals;
        for (i, layout) in layouts.iter().enumerate() {
            let uses = |l: &mdtf_pack::TextureLayout, c: &str| l.components.iter().flatten().any(|x| x == c);
            if normals_pending && ["nx", "ny", "nz"].iter().any(|c| uses(layout, c)) {
                // the value volume is in the pack's channels, the others, or still in derive's input
                let taken = pack_chans.iter().position(|(c, _)| c == "v").map(|k| pack_chans.remove(k).1);
                let value = match taken.or_else(|| chans.remove("v")) {
                    Some(v) => MultiField::from(v),
                    None => MultiField { geometry: geo.clone(), fields: std::mem::take(&mut value_mf.fields) },
                };
                pack_chans.extend(derive_normals(&value, kernel)?);
                if layouts[i..].iter().any(|l| uses(l, "v")) {
                    pack_chans.push(("v".into(), value.into_scalar().map_err(at("pack"))?));
                }
                normals_pending = false;
            }
            writer
                .add(layout, &|c: &str| pack_chans.iter().find(|(n, _)| n == c).map(|(_, v)| v))
                .map_err(at("pack"))?;
            // free what no later texture reads (the value stays while the normals are still to make)
            pack_chans.retain(|(c, _)| layouts[i + 1..].iter().any(|l| uses(l, c)) || (normals_pending && c == "v"));
        }
        writer.finish(&luts, provenance).map_err(at("pack"))?;
        if !figure_hists.is_empty() {
            let hists: Vec<&mdtf_histogram::Histogram> = figure_hists.iter().collect();
            let written = crate::figures::write_tf_figures(&dir.join("histogram"), &luts, &hists, &input_name, &arches)
                .map_err(at("pack"))?;
            pack_outputs.extend(written.into_iter().map(|f| format!("histogram/{f}")));
        }
        if let Some(g) = &gaussians {
            let json = serde_json::to_string_pretty(g).map_err(at("pack"))?;
            write_file_atomically(&pdir.join("gaussians.json"), |w| w.write_all(json.as_bytes()))
                .map_err(at("pack"))?;
        }
    }
    stages.done(pack_stage, t, n, pack_outputs);

    let report = RunReport {
        fields,
        value_range: finite_range,
        warnings,
        boundary,
        boundaries,
        hvol_built: hvol_kept.is_some(),
        stages: stages.0,
        ..RunReport::of(opts, input_name, &geo)
    };
    finish(p, opts, out, report, &table_names, start, on_stage)
}

/// The end of every run: the preview and the contact sheet (when asked for
/// and the pack can be previewed: `table_names` are its lookup tables),
/// run_report.json (`report` gets the preview's stage and the total time
/// since `start`), report.html, and the output folder published.
pub(crate) fn finish(
    p: &Pipeline,
    opts: &RunOptions,
    out: OutputFolder,
    mut report: RunReport,
    table_names: &[String],
    start: Instant,
    on_stage: &dyn Fn(&str),
) -> Result<RunReport, RunError> {
    let dir = out.path();
    let pdir = dir.join("pack");
    let previewable = match p.pack.profile {
        Profile::Slicer3dtf | Profile::DistanceTf => true,
        Profile::GaussianTf => true,
        // with a TF, or the default one from the boundaries found
        Profile::PeakFinding => table_names.iter().any(|l| ["tf2d", "peak_table", "product_0"].contains(&l.as_str())),
        // the mesh resampled onto a grid, with the TF of its gaussians.json
        Profile::ProjectedTetrahedra => true,
    };
    if p.preview && previewable {
        on_stage("preview");
        opts.check_cancelled()?;
        let t = Instant::now();
        let cam = mdtf_preview::Camera::default();
        mdtf_preview::preview_named(&pdir, &dir.join("preview.png"), &cam, true, &opts.output.join("pack"))
            .map_err(at("preview"))?;
        // the contact sheet: every picture of the run side by side, named
        let pictures: Vec<(PathBuf, String)> =
            crate::report_page::figures_in(dir).into_iter().map(|f| (dir.join(&f.file), f.file)).collect();
        let refs: Vec<(&Path, &str)> = pictures.iter().map(|(p, c)| (p.as_path(), c.as_str())).collect();
        mdtf_preview::contact_sheet(&refs, 3, 384, &dir.join("contact_sheet.png")).map_err(at("preview"))?;
        let mut stages = Stages(std::mem::take(&mut report.stages));
        stages.done("preview", t, 512 * 512, vec!["preview.png".into(), "contact_sheet.png".into()]);
        report.stages = stages.0;
    }
    report.total_seconds = start.elapsed().as_secs_f64();
    report.settings = resolved_settings(p, opts).map_err(fail("report"))?;
    let json = serde_json::to_string_pretty(&report).map_err(at("report"))?;
    write_file_atomically(&dir.join("run_report.json"), |w| w.write_all(json.as_bytes())).map_err(at("report"))?;
    write_report_page(&report, dir).map_err(fail("report"))?;
    let base = opts.pipeline_path.parent().map(Path::to_path_buf).unwrap_or_default();
    out.publish(&run_inputs(p, opts, &base)).map_err(at("output"))?;
    Ok(report)
}

/// The stage lines of a run report, as the stages finish.
#[derive(Default)]
pub(crate) struct Stages(pub Vec<StageReport>);

impl Stages {
    /// Records stage `name`, started at `t`, over `voxels` voxels, that wrote `outputs`.
    pub(crate) fn done(&mut self, name: &str, t: Instant, voxels: usize, outputs: Vec<String>) {
        let seconds = t.elapsed().as_secs_f64();
        self.0.push(StageReport {
            stage: name.into(),
            seconds,
            mvoxel_per_s: voxels as f64 / seconds.max(1e-9) / 1e6,
            peak_mib: peak_mib(),
            outputs,
        });
    }
}

/// The plan [`run`] follows for `p`, with the input's name and grid. It reads
/// the input (or builds the phantom) to learn its fields and grid, and
/// writes nothing.
pub fn plan(p: &Pipeline, opts: &RunOptions) -> Result<(Plan, String, Geometry), RunError> {
    let base = opts.pipeline_path.parent().map(Path::to_path_buf).unwrap_or_default();
    let (input, name, _) = load_input(p, opts, &base)?;
    let fields: Vec<String> = input.fields.iter().map(|f| f.name.clone()).collect();
    let plan = Plan::resolve(p, &fields, &input.geometry).map_err(at("plan"))?;
    Ok((plan, name, input.geometry))
}

/// The settings of a run of `p` with every default filled in, as the run
/// uses them: `--input` in place of the pipeline's input (and then no phantom
/// keys), and no meshing section unless the profile meshes. `mdtf run
/// --print-settings` prints them; the run report and report.html record them.
pub fn resolved_settings(p: &Pipeline, opts: &RunOptions) -> Result<toml::Table, String> {
    let mut resolved = p.clone();
    if let Some(f) = &opts.input {
        resolved.input.file = Some(f.clone());
    }
    resolved.derive.kernel.get_or_insert(mdtf_derive::DEFAULT_KERNEL);
    let mut table = toml::Table::try_from(&resolved).map_err(|e| e.to_string())?;
    if resolved.pack.profile != Profile::ProjectedTetrahedra {
        table.remove("tetra");
    }
    if let Some(toml::Value::Table(input)) = table.get_mut("input")
        && input.contains_key("file")
    {
        for k in ["phantom", "size", "sigma", "noise"] {
            input.remove(k);
        }
    }
    Ok(table)
}

/// Writes report.html into the staging folder `dir` from the report, the
/// settings and the pack's manifest (absent for mesh packs).
fn write_report_page(report: &RunReport, dir: &Path) -> Result<(), String> {
    let settings = crate::file::to_toml(&report.settings)?;
    let manifest: Option<mdtf_pack::Manifest> =
        std::fs::read_to_string(dir.join("pack/manifest.json")).ok().and_then(|t| serde_json::from_str(&t).ok());
    let figures = crate::report_page::figures_in(dir);
    let page =
        crate::report_page::PageInputs { report, settings: &settings, manifest: manifest.as_ref(), figures: &figures };
    crate::report_page::write(dir, &page).map_err(|e| e.to_string())
}

/// The pack's provenance: mdtf's version, the input and its digest, the settings.
pub(crate) fn provenance(p: &Pipeline, opts: &RunOptions, base: &Path, input_name: &str) -> Provenance {
    Provenance {
        mdtf_version: env!("CARGO_PKG_VERSION").into(),
        input: Some(input_name.to_string()),
        input_sha256: input_file(p, opts, base).and_then(|f| mdtf_pack::sha256_file(&f).ok()),
        stages: serde_json::to_value(p).unwrap_or(serde_json::Value::Null),
    }
}

/// The pack's TF file, read and parsed, when the pipeline names one.
pub(crate) fn read_tf(p: &Pipeline, base: &Path) -> Result<Option<mdtf_pack::TfFile>, RunError> {
    let err = |e: String| fail("pack")(e);
    match &p.pack.tf {
        Some(f) => {
            let path = base.join(f);
            let text = std::fs::read_to_string(&path).map_err(|e| err(format!("{}: {e}", path.display())))?;
            Ok(Some(parse_tf(&text).map_err(|e| err(format!("{}: {e}", path.display())))?))
        }
        None => Ok(None),
    }
}

/// Every file a run reads: the pipeline file, the input and the TF file.
pub(crate) fn run_inputs(p: &Pipeline, opts: &RunOptions, base: &Path) -> Inputs {
    let mut inputs = Inputs::of(&[&opts.pipeline_path]);
    if let Some(f) = input_file(p, opts, base) {
        inputs.add(&f);
    }
    if let Some(tf) = &p.pack.tf {
        inputs.add(&base.join(tf));
    }
    if let Some(mask) = &p.pack.gtf_from_mask {
        inputs.add(&base.join(mask));
    }
    inputs
}

/// The unit normals (nx, ny, nz) of a one-field `value`, named.
fn derive_normals(value: &MultiField, kernel: Kernel) -> Result<Vec<(String, Volume)>, RunError> {
    let d = DeriveParams { items: vec![Item::Normal], kernel, ..Default::default() };
    let out = mdtf_derive::run(value, &d).map_err(at("derive"))?;
    Ok(out.items.into_iter().flat_map(|(_, mf)| mf.into_volumes()).collect())
}

/// The input file of a run: `--input` as given, else the pipeline's, relative to its folder.
pub(crate) fn input_file(p: &Pipeline, opts: &RunOptions, base: &Path) -> Option<PathBuf> {
    opts.input.clone().or_else(|| p.input.file.as_ref().map(|f| base.join(f)))
}

/// How the pipeline's `[input]` asks for its file to be read.
pub(crate) fn read_options(p: &Pipeline) -> ReadOptions {
    ReadOptions {
        nan: p.input.nan,
        dicom: DicomOptions { series: p.input.series.clone(), resample: p.input.resample },
        level: p.input.level,
    }
}

/// The input volume, its name for the report, and what its reader warned of.
pub(crate) fn load_input(
    p: &Pipeline,
    opts: &RunOptions,
    base: &Path,
) -> Result<(MultiField, String, Vec<String>), RunError> {
    if let Some(f) = input_file(p, opts, base) {
        let (mf, info) = mdtf_volume::read_with_info(&f, &read_options(p)).map_err(at("input"))?;
        return Ok((mf, f.display().to_string(), info.warnings));
    }
    let i = &p.input;
    if i.size < 8 || i.size > 1024 {
        return Err(fail("input")(format!("phantom size {} must be 8 to 1024", i.size)));
    }
    if !(i.sigma.is_finite() && i.sigma > 0.0) {
        return Err(fail("input")(format!("phantom sigma {} must be a positive number of voxels", i.sigma)));
    }
    if !(i.noise.is_finite() && i.noise >= 0.0) {
        return Err(fail("input")(format!("phantom noise {} must be zero or a positive standard deviation", i.noise)));
    }
    let geo = Geometry::new([i.size; 3], [1.0; 3]);
    let name = format!("built-in {:?} phantom, {}^3, sigma {}", i.phantom, i.size, i.sigma);
    let mut mf = match i.phantom {
        PhantomKind::ErfSphere => {
            let r = 0.3 * min_extent(&geo);
            MultiField::from(erf_sphere(geo, r, i.sigma, 0.0, 255.0, None).volume())
        }
        PhantomKind::Shells => MultiField::from(RadialPhantom::tooth(geo, i.sigma).volume()),
        PhantomKind::Multifield => MultiFieldPhantom::new(geo, i.sigma).volume(),
    };
    if i.noise > 0.0 {
        let g = mf.geometry.clone();
        for (k, f) in mf.fields.iter_mut().enumerate() {
            let mut v = Volume { geometry: g.clone(), data: std::mem::take(&mut f.data) };
            add_gaussian_noise(&mut v, i.noise, 1 + k as u64);
            f.data = v.data;
        }
    }
    Ok((mf, name, Vec::new()))
}
