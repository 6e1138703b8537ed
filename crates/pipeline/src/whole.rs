//! The passes of a whole-volume run, in the order they run, over the
//! channels they share ([`WholeRun`]): derive, pre-filter and tracing, kept
//! volumes, histograms, pack. Every channel lives in the run once; each pass
//! borrows what it reads, frees what the plan says no later pass reads, and
//! the pack takes the rest at the end.

use crate::channel::Channel;
use crate::error::{RunError, at, fail};
use crate::hist_files::{Counted, Written};
use crate::plan::{Plan, Step};
use crate::progress::Progress;
use crate::report::{BoundarySummary, Stages, Traced};
use crate::settings::{Histograms, Settings};
use mdtf_boundary::BoundaryInput;
use mdtf_derive::{DeriveParams, Item};
use mdtf_histogram::{Axis, AxisSpec, Histogram, HvolParams, count, histogram_volume, stretched_pair};
use mdtf_pack::{GaussianPrimitive, Lut, PackParams, PackWriter, Profile, Provenance, TfFile};
use mdtf_volume::{Geometry, MultiField, Volume, WriteOptions};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

/// A whole-volume run between its input and its end.
pub(crate) struct WholeRun<'a> {
    s: &'a Settings,
    /// The staging output folder.
    dir: PathBuf,
    geo: Geometry,
    plan: Plan,
    /// How the value is derived wherever it is (kernel, scanner padding); its items are each call's.
    derive: DeriveParams,
    /// The input's name in the figures, the manifest and the report.
    pub(crate) input_name: String,
    /// The units the input states.
    pub(crate) units: mdtf_volume::Units,
    pub(crate) progress: Progress<'a>,
    pub(crate) stages: Stages,
    pub(crate) warnings: Vec<String>,
    /// The channels made so far and still read.
    chans: BTreeMap<Channel, Volume>,
    /// The normal, until the tracing has read it.
    normal: Option<MultiField>,
    /// The pre-filtered g and f'', until the tracing has read them.
    prefiltered: Option<(Volume, Volume)>,
    /// The value as derive's input; its volume moves into the channels, or
    /// stays here while the deferred normals still need it.
    value: MultiField,
    /// A several-field input, until its fields move into the channels.
    input: Option<MultiField>,
    /// The input value's finite range, value units.
    pub(crate) finite_range: Option<[f64; 2]>,
}

/// What the pack stage leaves for the report.
pub(crate) struct Packed {
    /// The pack's lookup tables, by name (the preview reads them).
    pub(crate) table_names: Vec<String>,
    /// The boundaries the histogram volume shows.
    pub(crate) boundaries: Vec<mdtf_histogram::DetectedBoundary>,
    /// Whether the histograms built a histogram volume.
    pub(crate) hvol_built: bool,
}

impl<'a> WholeRun<'a> {
    /// The run of `s` on the `input` it read (with its name and the
    /// reader's warnings, as [`crate::inputs::load_input`] gives them; read
    /// from `started` on), planned as `plan`, writing into the staging
    /// folder `dir`: records the input stage.
    pub(crate) fn new(
        s: &'a Settings,
        plan: Plan,
        (input, meta): (MultiField, crate::inputs::InputMeta),
        started: Instant,
        dir: PathBuf,
        progress: Progress<'a>,
    ) -> Result<WholeRun<'a>, RunError> {
        let geo = input.geometry.clone();
        let mut stages = Stages::default();
        stages.done("input", started, geo.voxel_count(), vec![]);
        let padded = match (meta.padding, input.fields.first()) {
            (Some(range), Some(f)) => f.data.as_slice().map_or(0, |s| crate::inputs::count_padding(s, range)),
            _ => 0,
        };
        let padding_note = meta.padding_note(padded, geo.voxel_count());
        let mut warnings = meta.warnings;
        warnings.extend(padding_note);
        warnings.extend(first_field_note(s.profile(), &plan.fields));
        let (value, input) = if plan.fields.is_empty() {
            (input.into_scalar().map_err(at("input"))?, None)
        } else {
            let value = input.field_volume(0).ok_or_else(|| fail("input")("no fields".into()))?;
            (value, Some(input))
        };
        Ok(WholeRun {
            s,
            dir,
            finite_range: value.finite_range().map(|(lo, hi)| [lo as f64, hi as f64]),
            geo,
            plan,
            derive: DeriveParams {
                kernel: s.chain.kernel,
                padding: meta.padding.map(|r| r.map(|x| x as f32)),
                ..Default::default()
            },
            input_name: meta.name,
            units: meta.units,
            progress,
            stages,
            warnings,
            chans: BTreeMap::new(),
            normal: None,
            prefiltered: None,
            // the value volume goes into derive as a one-field MultiField and comes back out: no copy
            value: MultiField::from(value),
            input,
        })
    }

    /// The input's field names (empty for one field).
    pub(crate) fn fields(&self) -> &[String] {
        &self.plan.fields
    }

    fn needs(&self, c: Channel) -> bool {
        self.plan.wanted.contains(&c)
    }

    /// Takes in the volumes a stage crate made, by the names it gives them
    /// (the table's, or a Jacobian component's `d{field}/d{axis}`).
    fn take_named(&mut self, volumes: Vec<(String, Volume)>) {
        for (name, v) in volumes {
            if let Some(c) = Channel::of_store(&name).or_else(|| Channel::parse(&name, &self.plan.fields)) {
                self.chans.insert(c, v);
            }
        }
    }

    fn voxels(&self) -> usize {
        self.geo.voxel_count()
    }

    /// Runs the plan's steps in their order, from the derivatives to the
    /// pack (the input is read before, the preview rendered at the run's
    /// end); what the pack and the tracing leave for the report.
    pub(crate) fn run_steps(&mut self) -> Result<(Traced, Packed), RunError> {
        let steps: Vec<Step> = self.plan.steps.iter().map(|s| s.step).collect();
        let (mut traced, mut packed) = (Traced::default(), None);
        let mut hists = (Written::default(), Vec::new());
        let mut settled = false;
        for step in steps {
            // every step after the derivatives reads the channels as the plan wants them
            if !settled && step > Step::DeriveFields {
                self.settle_derived();
                settled = true;
            }
            match step {
                Step::Input | Step::Preview => {}
                Step::Derive => self.derive_value()?,
                Step::DeriveFields => self.derive_fields()?,
                Step::Prefilter => self.prefilter()?,
                Step::Trace => traced = self.trace()?,
                Step::Keep => self.keep()?,
                Step::Histogram => hists = self.histograms()?,
                Step::Pack => packed = Some(self.pack(&traced, std::mem::take(&mut hists.0), &hists.1)?),
            }
        }
        let packed = packed.ok_or_else(|| fail("plan")("the plan has no pack step".into()))?;
        Ok((traced, packed))
    }

    /// The derive step over the value (only the items the later steps use).
    fn derive_value(&mut self) -> Result<(), RunError> {
        let items = self.plan.derive.clone();
        if !items.is_empty() {
            self.progress.stage("derive")?;
            let t = Instant::now();
            let d = DeriveParams { items, ..self.derive.clone() };
            let out = mdtf_derive::run(&self.value, &d).map_err(at("derive"))?;
            // every component is a channel of its own name (g, f2, gx, hxx, ...)
            for (item, mf) in out.items {
                match item {
                    Item::Normal => self.normal = Some(mf),
                    _ => self.take_named(mf.into_volumes()),
                }
            }
            self.stages.done("derive", t, self.voxels(), vec![]);
        }
        Ok(())
    }

    /// The derive step over all fields together (gnorm, inv_g, the Jacobian's components).
    fn derive_fields(&mut self) -> Result<(), RunError> {
        let multi_items = self.plan.derive_fields.clone();
        if let Some(mf) = &self.input
            && !multi_items.is_empty()
        {
            self.progress.stage("derive (multi-field)")?;
            let t = Instant::now();
            let d = DeriveParams { items: multi_items, padding: None, ..self.derive.clone() };
            let out = mdtf_derive::run(mf, &d).map_err(at("derive"))?;
            // gnorm, inv_g, and the Jacobian's d{field}/d{axis}
            self.take_named(out.items.into_iter().flat_map(|(_, m)| m.into_volumes()).collect());
            self.stages.done("derive (multi-field)", t, self.voxels(), vec![]);
        }
        Ok(())
    }

    /// After the derivatives: the input's fields and the value move into
    /// the channels the plan wants, and without a tracing (which reads the
    /// normal first) the normal's components too.
    fn settle_derived(&mut self) {
        // the input's fields move into the channels once the multi-field derive is done with them
        if let Some(mf) = self.input.take() {
            for (k, f) in mf.fields.into_iter().enumerate() {
                if self.needs(Channel::Field(k)) {
                    self.chans.insert(Channel::Field(k), Volume { geometry: self.geo.clone(), data: f.data });
                }
            }
        }
        if self.needs(Channel::Value) && !self.chans.contains_key(&Channel::Value) {
            let field = self.value.fields.remove(0);
            self.chans.insert(Channel::Value, Volume { geometry: self.geo.clone(), data: field.data });
        }
        if !self.plan.defer_normals {
            // nothing reads the value volume from here on unless it is a channel
            self.value.fields.clear();
        }
        if !self.plan.trace {
            self.settle_normals();
        }
    }

    /// The normal's components join the channels the plan wants.
    fn settle_normals(&mut self) {
        let normals = self.normal.take().map(MultiField::into_volumes).unwrap_or_default();
        self.take_named(
            normals.into_iter().filter(|(n, _)| Channel::of_store(n).is_some_and(|c| self.needs(c))).collect(),
        );
    }

    /// The pre-filter step: g and f'' filtered for the tracing.
    fn prefilter(&mut self) -> Result<(), RunError> {
        let (Some(pf), Some(g), Some(f2)) =
            (&self.s.chain.prefilter, self.chans.get(&Channel::G), self.chans.get(&Channel::F2))
        else {
            return Err(fail("prefilter")("the pre-filter's parameters or derivatives are missing".into()));
        };
        self.progress.stage("prefilter")?;
        let t = Instant::now();
        let filter = |v: &Volume| crate::boundary_chain::prefilter(v, pf).map_err(at("prefilter"));
        self.prefiltered = Some((filter(g)?, filter(f2)?));
        self.stages.done("prefilter", t, self.voxels(), vec![]);
        Ok(())
    }

    /// The tracing step (of the pre-filtered g and f'' when the plan
    /// pre-filters); then the normal's components join the channels.
    fn trace(&mut self) -> Result<Traced, RunError> {
        let value_range = self.finite_range.map_or(0.0, |[lo, hi]| hi - lo);
        let traced = self.trace_derived(value_range)?;
        self.settle_normals();
        Ok(traced)
    }

    fn trace_derived(&mut self, value_range: f64) -> Result<Traced, RunError> {
        let n = self.voxels();
        let (Some(g0), Some(f20), Some(nm)) =
            (self.chans.get(&Channel::G), self.chans.get(&Channel::F2), self.normal.as_ref())
        else {
            return Err(fail("boundary")("derivatives missing".into()));
        };
        let filtered = self.prefiltered.take();
        let (g, f2) = match &filtered {
            Some((g, f2)) => (g, f2),
            None => (g0, f20),
        };
        self.progress.stage("boundary")?;
        let t = Instant::now();
        // the boundaries of the (v, g) histogram of the unfiltered g, as the default TF reads them
        let detected = match (self.plan.detects_before_tracing(), self.chans.get(&Channel::Value)) {
            (true, Some(v)) => crate::pre_detect::detected_of(v.samples(), g0.samples(), v.geometry.min_spacing())
                .map_err(at("boundary"))?,
            _ => mdtf_boundary::Detected::default(),
        };
        let input = BoundaryInput { g, f2, normal: nm, value_range };
        let mut out = mdtf_boundary::run_detected(&input, &self.s.chain.boundary, &detected).map_err(at("boundary"))?;
        self.warnings.extend(out.warnings.iter().map(|w| format!("boundary: {w}")));
        let traced = Traced {
            d_max: Some(out.resolved.d_max),
            boundary: Some(BoundarySummary { resolved: out.resolved, counts: out.counts, lost: out.lost.clone() }),
            report: None,
        };
        let report = out.report(g);
        let rdir = self.dir.join("boundary");
        std::fs::create_dir_all(&rdir).map_err(at("boundary"))?;
        report.write(&rdir).map_err(at("boundary"))?;
        drop(filtered);
        let traced_volumes = crate::boundary_chain::take_traced(&mut out);
        self.take_named(
            traced_volumes.into_iter().filter(|(n, _)| Channel::of_store(n).is_some_and(|c| self.needs(c))).collect(),
        );
        // derived only for the tracing: free them now
        for c in self.plan.freed_after(Step::Trace) {
            self.chans.remove(&c);
        }
        let outputs = vec!["boundary/boundary_report.csv".into(), "boundary/boundary_report.png".into()];
        self.stages.done("boundary", t, n, outputs);
        Ok(traced)
    }

    /// The kept channels, written as volumes.
    fn keep(&mut self) -> Result<(), RunError> {
        if self.s.outputs.keep.is_empty() {
            return Ok(());
        }
        self.progress.stage("keep")?;
        let t = Instant::now();
        let (chans, fields) = (&self.chans, &self.plan.fields);
        let written = crate::run::write_kept(&self.s.outputs, fields, &self.dir, |c, file| {
            let v = chans.get(&Channel::parse(c, fields)?)?;
            Some(mdtf_volume::write_volume(file, v, &WriteOptions::default(), &[]).map_err(at("keep")))
        })?;
        self.stages.done("keep", t, self.voxels(), written);
        Ok(())
    }

    /// The histograms, when asked for (the histogram volume is kept for the
    /// pack's default opacity; it comes first so that the boundaries it
    /// shows are drawn on the others), and the field pairs' joint
    /// histograms, which the Gaussian TF figures draw over.
    fn histograms(&mut self) -> Result<(Written, Vec<Histogram>), RunError> {
        let h = self.s.outputs.histograms;
        if !h.counted {
            return Ok((Written::default(), Vec::new()));
        }
        self.progress.stage("histogram")?;
        let t = Instant::now();
        let hdir = self.dir.join("histogram");
        std::fs::create_dir_all(&hdir).map_err(at("histogram"))?;
        let err = |e: String| fail("histogram")(e);
        let mut counted = self.count(&h)?;
        counted.set_units(&self.units);
        // the default TF's histogram volume is an output only when the histograms ask for it
        let default_hvol = if h.hvol { None } else { counted.hvol.take() };
        let mut hists =
            crate::hist_files::write(&hdir, counted, default_hvol.as_ref(), &self.input_name, &mut self.warnings)
                .map_err(err)?;
        if default_hvol.is_some() {
            hists.hvol = default_hvol;
        }
        let mut field_pair_hists = Vec::new();
        if h.joint && !self.plan.fields.is_empty() {
            let (written, pairs) =
                crate::figures::write_field_pair_histograms(&self.plan.fields, &self.chans, &hdir, &self.input_name)
                    .map_err(err)?;
            hists.outputs.extend(written);
            field_pair_hists = pairs;
        }
        self.stages.done("histogram", t, self.voxels(), hists.outputs.clone());
        Ok((hists, field_pair_hists))
    }

    /// The counts the histogram section `h` asks for.
    fn count(&self, h: &Histograms) -> Result<Counted, RunError> {
        let get = |c: Channel| self.chans.get(&c);
        let (Some(v), Some(g)) = (get(Channel::Value), get(Channel::G)) else {
            return Err(fail("histogram")("v and g missing".into()));
        };
        let axis =
            |name: &str, data: &Volume| AxisSpec::qbert(name).resolve(name, data.samples()).map_err(at("histogram"));
        let axes: Vec<Axis> = vec![axis("v", v)?, axis("g", g)?];
        let without_g = {
            use rayon::prelude::*;
            g.samples().par_iter().filter(|x| !x.is_finite()).count() as u64
        };
        let mut counted = Counted { voxels: self.voxels(), without_g, ..Default::default() };
        // asked for, or read by the default TF (no TF file given); once the
        // tracing has freed f'', of v derived again, as the pack would
        if h.hvol || self.s.outputs.pack.tf.is_none() {
            counted.hvol = Some(match get(Channel::F2) {
                Some(f2) => histogram_volume(
                    v.samples(),
                    g.samples(),
                    f2.samples(),
                    v.plane_len(),
                    &HvolParams::on_grid(v.geometry.spacing),
                )
                .map_err(at("histogram"))?,
                None => crate::pack_inputs::hvol_of(v, &self.derive).map_err(at("histogram"))?,
            });
        }
        if h.joint {
            counted.joint = Some(count(&[v.samples(), g.samples()], axes.clone(), None).map_err(at("histogram"))?);
            // peak finding's TF domain: (v, 1/g); for several fields 1/g is of
            // their normalised ||G||, so its axis comes from the gradient it inverts
            let inverted: Option<Vec<f32>> = (!self.plan.fields.is_empty())
                .then(|| get(Channel::InvG).map(|i| i.samples().iter().map(|&x| 1.0 / x).collect()))
                .flatten();
            if let Some(inv_g) = get(Channel::InvG)
                && let Some(ia) = Axis::inverse_gradient(inverted.as_deref().unwrap_or(g.samples()), 256)
            {
                // several fields: the value is the first field, named as the pack's TF axis names it
                let mut va = axes[0].clone();
                if let Some(first) = self.plan.fields.first() {
                    va.name = first.clone();
                }
                counted.inv_g =
                    Some(count(&[v.samples(), inv_g.samples()], vec![va, ia], None).map_err(at("histogram"))?);
            }
        }
        if h.stretched
            && let (Some(g_hit), Some(hit)) = (get(Channel::GHit), get(Channel::Hit))
        {
            let channels = [v.samples(), g.samples(), g_hit.samples()];
            let pair = stretched_pair(channels, hit.samples(), &axes, None).map_err(at("histogram"))?;
            counted.stretched = Some(pair);
        }
        Ok(counted)
    }

    /// The pack (for meshes: the tetra stage, which writes the pack itself),
    /// from the histograms' outputs `hists` and `field_pair_hists`.
    fn pack(&mut self, traced: &Traced, hists: Written, field_pair_hists: &[Histogram]) -> Result<Packed, RunError> {
        let Written { boundaries, arches, figure_hists, hvol, .. } = hists;
        let profile = self.s.profile();
        let stage = if profile == Profile::ProjectedTetrahedra { "tetra + pack" } else { "pack" };
        self.progress.stage(stage)?;
        let t = Instant::now();
        let tf = crate::inputs::read_tf(&self.s.outputs.pack)?;
        let pdir = self.dir.join("pack");
        std::fs::create_dir_all(&pdir).map_err(at("pack"))?;
        let provenance = crate::inputs::provenance(self.s, self.geo.dims, &self.units);
        let mut table_names = Vec::new();
        let mut outputs: Vec<String> = vec!["pack/manifest.json".into()];
        let hvol = hvol.as_ref();
        if profile == Profile::ProjectedTetrahedra {
            let gaussians = self.pack_mesh(tf.as_ref(), hvol, provenance)?;
            // the mesh pack's files, named in the report as every stage's are
            let mut files: Vec<String> = std::fs::read_dir(&pdir)
                .map_err(at("pack"))?
                .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
                .filter(|name| name != "manifest.json")
                .map(|name| format!("pack/{name}"))
                .collect();
            files.sort();
            outputs.extend(files);
            // the (s, g) TF over the (v, g) histogram, as scalar gaussian-tf draws its own
            let written = crate::figures::write_gaussian_figures(
                &self.dir.join("histogram"),
                &gaussians,
                &figure_hists,
                &[],
                &self.input_name,
            )
            .map_err(at("pack"))?;
            outputs.extend(written.into_iter().map(|f| format!("histogram/{f}")));
        } else {
            let (luts, gaussians) = self.pack_textures(tf.as_ref(), hvol, traced, provenance)?;
            table_names = luts.iter().map(|l| l.name.clone()).collect();
            let hdir = self.dir.join("histogram");
            if !figure_hists.is_empty() {
                let hists: Vec<&Histogram> = figure_hists.iter().collect();
                let written = crate::figures::write_tf_figures(&hdir, &luts, &hists, &self.input_name, &arches)
                    .map_err(at("pack"))?;
                outputs.extend(written.into_iter().map(|f| format!("histogram/{f}")));
            }
            if let Some(g) = &gaussians {
                crate::gaussians::write(&pdir, g).map_err(at("pack"))?;
                // scalar data: over the (v, g) histogram; several fields: over their pairs'
                let hists = if self.plan.fields.is_empty() { &figure_hists[..] } else { field_pair_hists };
                let written =
                    crate::figures::write_gaussian_figures(&hdir, g, hists, &self.plan.fields, &self.input_name)
                        .map_err(at("pack"))?;
                outputs.extend(written.into_iter().map(|f| format!("histogram/{f}")));
            }
        }
        self.stages.done(stage, t, self.voxels(), outputs);
        Ok(Packed { table_names, boundaries, hvol_built: hvol.is_some() })
    }

    /// The mesh pack: the value tetrahedralised, its tables, and the (s, g)
    /// TF the preview draws and a renderer can start from: the TF file's
    /// Gaussians, else a TGTF at each boundary found (as gaussian-tf's
    /// default). Returns that TF's primitives.
    fn pack_mesh(
        &mut self,
        tf: Option<&TfFile>,
        hvol: Option<&mdtf_histogram::HistogramVolume>,
        provenance: Provenance,
    ) -> Result<Vec<GaussianPrimitive>, RunError> {
        let pdir = self.dir.join("pack");
        let value = self.chans.get(&Channel::Value).ok_or_else(|| fail("pack")("no value volume".into()))?;
        let tetra = &self.s.outputs.tetra;
        let (mesh, grid, coarsened) =
            mdtf_tetra::tetrahedralise_within(value, tetra.tets, tetra.max_tetrahedra, "v").map_err(at("pack"))?;
        let every_voxel = "--set tetra.max_tetrahedra=0 meshes every voxel";
        self.warnings.extend(coarsened.map(|c| format!("tetra: {} ({every_voxel})", c.note())));
        let out = mdtf_tetra::run(&mesh, tetra, tf).map_err(at("pack"))?;
        self.warnings.extend(out.notes.iter().map(|n| format!("tetra: {n}")));
        let report = mdtf_tetra::MeshReport::default();
        mdtf_tetra::write_pack(&pdir, &mesh, &report, &out, Some(&grid), provenance).map_err(at("pack"))?;
        drop(mesh);
        let value_and_g: Vec<(String, Volume)> = [Channel::Value, Channel::G]
            .into_iter()
            .filter_map(|c| self.chans.remove(&c).map(|v| (c.name(&[]), v)))
            .collect();
        let tf_gaussians = tf.filter(|t| !t.gaussians().is_empty());
        let g = crate::gaussians::gaussians(tf_gaussians, None, &value_and_g, &["v".into()], "g", (hvol, &self.derive))
            .map_err(fail("pack"))?;
        crate::gaussians::write(&pdir, &g).map_err(at("pack"))?;
        Ok(g)
    }

    /// The pack's textures and tables from the channels, which move into it
    /// (it is the last stage to read them): its lookup tables and, for
    /// gaussian-tf, its Gaussians (made before the textures free the channels).
    fn pack_textures(
        &mut self,
        tf: Option<&TfFile>,
        hvol: Option<&mdtf_histogram::HistogramVolume>,
        traced: &Traced,
        provenance: Provenance,
    ) -> Result<(Vec<Lut>, Option<Vec<GaussianPrimitive>>), RunError> {
        let profile = self.s.profile();
        let pdir = self.dir.join("pack");
        let fields = &self.plan.fields;
        let mut pack_chans: Vec<(String, Volume)> = profile
            .channels(fields)
            .into_iter()
            .filter_map(|name| Channel::parse(&name, fields).and_then(|c| self.chans.remove(&c)).map(|v| (name, v)))
            .collect();
        let ranges = crate::pack_inputs::ranges(&pack_chans, &BTreeMap::new(), traced.d_max).map_err(at("pack"))?;
        let alpha = self.s.outputs.pack.alpha;
        let luts = crate::pack_inputs::luts(profile, tf, &alpha, &pack_chans, &ranges, hvol, &self.derive)
            .map_err(at("pack"))?;
        let gaussians = self.gaussians(tf, hvol, &pack_chans)?;
        let params = PackParams {
            profile,
            ranges,
            fields: self.plan.fields.clone(),
            dtype: None,
            nifti: self.s.outputs.pack.nifti,
        };
        let sources = BTreeMap::new();
        let layouts = mdtf_pack::texture_layouts(&params);
        let mut writer = PackWriter::new(&pdir, &params, self.geo.clone(), &sources);
        let mut normals_pending = self.plan.defer_normals;
        for (i, layout) in layouts.iter().enumerate() {
            let uses = |l: &mdtf_pack::TextureLayout, c: &str| l.components.iter().flatten().any(|x| x == c);
            if normals_pending && crate::channel::NORMAL.iter().any(|c| uses(layout, &c.name(&[]))) {
                // the value volume is in the pack's channels, the others, or still in derive's input
                let taken = pack_chans.iter().position(|(c, _)| c == "v").map(|k| pack_chans.remove(k).1);
                let value = match taken.or_else(|| self.chans.remove(&Channel::Value)) {
                    Some(v) => MultiField::from(v),
                    None => MultiField { geometry: self.geo.clone(), fields: std::mem::take(&mut self.value.fields) },
                };
                pack_chans.extend(derive_normals(&value, &self.derive)?);
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
        Ok((luts, gaussians))
    }

    /// gaussian-tf's primitives (None for the other profiles) from the
    /// pack's channels `pack_chans`: the TF file's, else fitted to the mask,
    /// else a TGTF at each boundary found.
    fn gaussians(
        &self,
        tf: Option<&TfFile>,
        hvol: Option<&mdtf_histogram::HistogramVolume>,
        pack_chans: &[(String, Volume)],
    ) -> Result<Option<Vec<GaussianPrimitive>>, RunError> {
        if self.s.profile() != Profile::GaussianTf {
            return Ok(None);
        }
        let err = |e: String| fail("pack")(e);
        let mask = match &self.s.outputs.pack.gtf_from_mask {
            Some(path) => {
                let v = mdtf_volume::read_scalar(path, &mdtf_volume::ReadOptions::default())
                    .map_err(|e| err(format!("gtf_from_mask {}: {e}", path.display())))?;
                Some(v)
            }
            None => None,
        };
        let (axes, gradient) = if self.plan.fields.is_empty() {
            (vec!["v".to_string()], "g")
        } else {
            (self.plan.fields.clone(), "gnorm")
        };
        let g = crate::gaussians::gaussians(tf, mask.as_ref(), pack_chans, &axes, gradient, (hvol, &self.derive))
            .map_err(err)?;
        Ok(Some(g))
    }
}

/// What a profile that reads one value makes of an input of several
/// `fields` (None for one field, and for gaussian-tf, which reads them all).
fn first_field_note(profile: Profile, fields: &[String]) -> Option<String> {
    let (first, n) = (fields.first()?, fields.len());
    let list = fields.join(", ");
    match profile {
        Profile::GaussianTf => None,
        Profile::PeakFinding => Some(format!(
            "input: {n} fields ({list}): peak-finding's value axis is the first, '{first}', and its 1/g comes from \
             the gradient of all of them (||G||); gaussian-tf classifies every field"
        )),
        _ => Some(format!(
            "input: {n} fields ({list}): {profile} reads one value and uses the first, '{first}'; gaussian-tf \
             classifies every field (for another field, give it as a volume of its own)"
        )),
    }
}

/// The unit normals (nx, ny, nz) of a one-field `value`, named.
fn derive_normals(value: &MultiField, derive: &DeriveParams) -> Result<Vec<(String, Volume)>, RunError> {
    let d = DeriveParams { items: vec![Item::Normal], ..derive.clone() };
    let out = mdtf_derive::run(value, &d).map_err(at("derive"))?;
    Ok(out.items.into_iter().flat_map(|(_, mf)| mf.into_volumes()).collect())
}
