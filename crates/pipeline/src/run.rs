//! The in-process runner of pipeline files: input -> derive -> (pre-filter,
//! boundary) -> histograms -> pack, with per-stage timings and a report.
//! Everything is written into a temporary folder beside the output and
//! renamed into place at the end, so a failed run leaves the output folder
//! as it was.

use crate::file::Pipeline;
use crate::plan::{Plan, Step};
use crate::progress::Progress;
use mdtf_boundary::{AlphaMap, BoundaryInput};
use mdtf_derive::{DeriveParams, Item, Kernel};
use mdtf_histogram::{Axis, AxisSpec, HvolParams, count, histogram_volume, hit_mask};
use mdtf_pack::{PackParams, PackWriter, Profile};
use mdtf_volume::{MultiField, OutputFolder, Volume, WriteOptions, write_file_atomically};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub use crate::error::RunError;
pub(crate) use crate::error::{at, fail};
use crate::inputs::{load_input, provenance, read_tf, run_inputs};
pub use crate::inputs::{plan, resolved_settings};
use crate::report::Stages;
pub use crate::report::{BoundarySummary, RunReport, SlabRun, StageReport};

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
    /// Where a slab-by-slab run's derive, pre-filter and tracing passes
    /// run: None in this process, else as tasks the runner hands out (see
    /// [`crate::blocks::SlabTasks`]; a whole-volume run ignores it).
    pub tasks: Option<std::sync::Arc<dyn crate::blocks::SlabTasks>>,
}

impl RunOptions {
    /// Whether [`RunOptions::cancel`] is set.
    pub fn is_cancelled(&self) -> bool {
        crate::progress::is_set(&self.cancel)
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
    let progress = Progress::new(opts, on_stage, &|_, _| {});

    // input
    progress.stage("input")?;
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
        progress.stage("derive")?;
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
        progress.stage("derive (multi-field)")?;
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
                progress.stage("prefilter")?;
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
        progress.stage("boundary")?;
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
        progress.stage("keep")?;
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
    // the field pairs' joint histograms, which the Gaussian TF figures draw over
    let mut field_pair_hists = Vec::new();
    if let Some(h) = &p.histogram {
        progress.stage("histogram")?;
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
            let (written, pairs) =
                crate::figures::write_field_pair_histograms(&fields, &chans, &hdir, &input_name).map_err(err)?;
            hists.outputs.extend(written);
            field_pair_hists = pairs;
        }
        stages.done("histogram", t, n, hists.outputs.clone());
    }
    let crate::hist_files::Written { boundaries, arches, figure_hists, hvol: hvol_kept, .. } = hists;

    // pack (for meshes: the tetra stage, which writes the pack itself)
    let pack_stage = if profile == Profile::ProjectedTetrahedra { "tetra + pack" } else { "pack" };
    progress.stage(pack_stage)?;
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
            let hdir = dir.join("histogram");
            let written = crate::figures::write_gaussian_figures(&hdir, g, &field_pair_hists, &fields, &input_name)
                .map_err(at("pack"))?;
            pack_outputs.extend(written.into_iter().map(|f| format!("histogram/{f}")));
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
    finish(p, opts, out, report, &table_names, start, &progress)
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
    progress: &Progress,
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
        progress.stage("preview")?;
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

/// Writes report.html into the staging folder `dir` from the report, the
/// settings, the pack's manifest (absent for mesh packs) and its Gaussians (gaussian-tf).
fn write_report_page(report: &RunReport, dir: &Path) -> Result<(), String> {
    let settings = crate::file::to_toml(&report.settings)?;
    let manifest: Option<mdtf_pack::Manifest> =
        std::fs::read_to_string(dir.join("pack/manifest.json")).ok().and_then(|t| serde_json::from_str(&t).ok());
    let gaussians: Option<Vec<mdtf_pack::GaussianPrimitive>> =
        std::fs::read_to_string(dir.join("pack/gaussians.json")).ok().and_then(|t| serde_json::from_str(&t).ok());
    let figures = crate::report_page::figures_in(dir);
    let page = crate::report_page::PageInputs {
        report,
        settings: &settings,
        manifest: manifest.as_ref(),
        gaussians: gaussians.as_deref(),
        figures: &figures,
    };
    crate::report_page::write(dir, &page).map_err(|e| e.to_string())
}

/// The unit normals (nx, ny, nz) of a one-field `value`, named.
fn derive_normals(value: &MultiField, kernel: Kernel) -> Result<Vec<(String, Volume)>, RunError> {
    let d = DeriveParams { items: vec![Item::Normal], kernel, ..Default::default() };
    let out = mdtf_derive::run(value, &d).map_err(at("derive"))?;
    Ok(out.items.into_iter().flat_map(|(_, mf)| mf.into_volumes()).collect())
}
