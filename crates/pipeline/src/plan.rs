//! The plan of a run, resolved once from what its outputs need (in the
//! spirit of Teem gage's `gageUpdate`): which derive items, whether the
//! pre-filter and the tracing run, the steps in order with the channels each
//! reads and makes, the step after which each channel is last read, the
//! whole-volume reductions each step waits for, and the halo a block of the
//! volume needs. `mdtf run --plan` prints it.
//!
//! To add a channel: a [`Channel`] variant and its row in
//! [`crate::channel::TABLE`] (producer, what it reads, units, meaning), and
//! its producer: a derive item's component, or a stage's output handed to
//! the channels. The table and the shipped pipelines' plans (kept in step
//! with the code by `tests/plans_doc.rs`):
//!
#![doc = include_str!("plans.md")]

use crate::channel::{Channel, Producer, Reach, UnknownChannel};
use crate::settings::{Histograms, Settings};
use mdtf_bilateral::BilateralParams;
use mdtf_boundary::BoundaryParams;
use mdtf_derive::{Item, Kernel};
use mdtf_pack::Profile;
use mdtf_volume::Geometry;
use std::collections::BTreeSet;
use std::fmt;

/// A step of a run, in the order they run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Step {
    /// Read the input (or build the phantom).
    Input,
    /// Derivatives of the value.
    Derive,
    /// Derivatives of all the fields together (several fields).
    DeriveFields,
    /// Bilateral pre-filter of g and f''.
    Prefilter,
    /// Distance-to-boundary tracing.
    Trace,
    /// Write the kept channels as volumes.
    Keep,
    /// Histograms and the histogram volume.
    Histogram,
    /// The texture pack (for meshes: meshing and the tetra tables).
    Pack,
    /// The preview rendered from the pack.
    Preview,
}

impl Step {
    /// The step's name in the plan and the run report.
    pub fn name(self) -> &'static str {
        match self {
            Step::Input => "input",
            Step::Derive => "derive",
            Step::DeriveFields => "derive (fields)",
            Step::Prefilter => "prefilter",
            Step::Trace => "boundary",
            Step::Keep => "keep",
            Step::Histogram => "histogram",
            Step::Pack => "pack",
            Step::Preview => "preview",
        }
    }
}

/// One planned step: what it reads and what it makes.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedStep {
    /// The step.
    pub step: Step,
    /// Channels it reads.
    pub reads: BTreeSet<Channel>,
    /// Channels it makes.
    pub makes: BTreeSet<Channel>,
}

/// A reduction over the whole volume that a step waits for (pass 1 of a
/// block execution; these merge exactly across blocks).
#[derive(Debug, Clone, PartialEq)]
pub struct Reduction {
    /// What is reduced, e.g. "finite range of v".
    pub what: String,
    /// The steps that need it.
    pub before: Vec<Step>,
}

/// The resolved plan of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// The input's field names (empty for one field).
    pub fields: Vec<String>,
    /// Channels the outputs read.
    pub wanted: BTreeSet<Channel>,
    /// Items of the derive pass over the value, in order.
    pub derive: Vec<Item>,
    /// Items of the derive pass over all fields, in order.
    pub derive_fields: Vec<Item>,
    /// The normals are derived just before the pack texture that holds them
    /// (nothing earlier reads them), so fewer volumes are held at the peak.
    pub defer_normals: bool,
    /// Whether g and f'' are pre-filtered before the tracing.
    pub prefilter: bool,
    /// Neighbours the pre-filter reads per voxel (0 without it): its cost.
    pub prefilter_taps: usize,
    /// The tetrahedral mesh the pack step makes (projected-tetrahedra), in words: its size and budget.
    pub mesh: Option<String>,
    /// Whether the tracing runs.
    pub trace: bool,
    /// The steps in order.
    pub steps: Vec<PlannedStep>,
    /// The reductions and who waits for them.
    pub reductions: Vec<Reduction>,
    /// How far each stage reaches, voxels per axis.
    pub reach: Reach,
    /// The halo a block needs (x, y, z voxels): the widest of the wanted channels'.
    pub halo: [usize; 3],
}

/// Why a pipeline cannot be planned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// `keep` names a channel that does not exist.
    #[error("keep: {0}")]
    Keep(UnknownChannel),
    /// The pack profile asks for a channel the table lacks (a bug, not a user error).
    #[error("pack: {0}")]
    Pack(UnknownChannel),
    /// A command asks for a channel that does not exist.
    #[error("{0}")]
    Channel(UnknownChannel),
}

impl Plan {
    /// Resolves the plan of a run of `s` on an input with these `fields`
    /// (empty or one: a scalar) on `geometry`.
    pub fn resolve(s: &Settings, fields: &[String], geometry: &Geometry) -> Result<Plan, PlanError> {
        let out = &s.outputs;
        let fields: Vec<String> = if fields.len() > 1 { fields.to_vec() } else { Vec::new() };
        let multi = !fields.is_empty();
        let profile = out.pack.profile;
        let mut pack = BTreeSet::new();
        for name in profile.channels(&fields) {
            pack.insert(Channel::named(&name, &fields).map_err(PlanError::Pack)?);
        }
        if profile == Profile::Slicer3dtf && out.pack.tf.is_none() {
            pack.insert(Channel::F2);
        }
        if profile == Profile::ProjectedTetrahedra {
            // the meshed scalar
            pack.insert(Channel::Value);
        }
        let mut keep = BTreeSet::new();
        for name in &out.keep {
            keep.insert(Channel::named(name, &fields).map_err(PlanError::Keep)?);
        }
        let mut hist = BTreeSet::new();
        let h = &out.histograms;
        if h.counted {
            hist.extend([Channel::Value, Channel::G]);
            if h.joint {
                hist.extend((0..fields.len().min(crate::figures::MAX_PAIRED_FIELDS)).map(Channel::Field));
                if pack.contains(&Channel::InvG) || keep.contains(&Channel::InvG) {
                    hist.insert(Channel::InvG);
                }
            }
            if h.stretched {
                hist.extend([Channel::GHit, Channel::Hit]);
            }
            if h.hvol {
                hist.insert(Channel::F2);
            }
        }
        let wanted: BTreeSet<Channel> = pack.iter().chain(&keep).chain(&hist).copied().collect();
        let normals = crate::channel::NORMAL;
        let wants_normals = normals.iter().any(|c| wanted.contains(c));
        let kept_normal = normals.iter().any(|c| keep.contains(c));
        let defer_normals =
            wants_normals && !traces(&wanted, multi) && !kept_normal && profile != Profile::ProjectedTetrahedra;
        let how = Making::of(&s.chain);
        let mut plan = Plan::making(fields, wanted, defer_normals, &how, geometry);
        let steps = &mut plan.steps;
        if !keep.is_empty() {
            steps.push(PlannedStep { step: Step::Keep, reads: keep, makes: BTreeSet::new() });
        }
        if h.counted {
            steps.push(PlannedStep { step: Step::Histogram, reads: hist, makes: BTreeSet::new() });
        }
        // the deferred normals are made inside the pack step, from the value
        let mut pack_reads = pack;
        let mut pack_makes = BTreeSet::new();
        if defer_normals {
            pack_reads.retain(|c| !normals.contains(c));
            pack_reads.insert(Channel::Value);
            pack_makes.extend(normals);
        }
        steps.push(PlannedStep { step: Step::Pack, reads: pack_reads, makes: pack_makes });
        if profile == Profile::ProjectedTetrahedra {
            plan.mesh = Some(mesh_words(geometry, &out.tetra));
        }
        let steps = &mut plan.steps;
        if out.preview {
            steps.push(PlannedStep { step: Step::Preview, reads: BTreeSet::new(), makes: BTreeSet::new() });
        }
        let later = pipeline_reductions(&out.histograms, &plan.steps, plan.detects_before_tracing());
        plan.reductions.extend(later);
        Ok(plan)
    }

    /// The plan of a command that wants the channels `names` of an input
    /// with these `fields` (empty or one: a scalar) on `geometry`, made as
    /// `chain` says (kernel, pre-filter, tracing): the steps that make them,
    /// then the command's own step reading them (shown as `keep`). The
    /// whole-volume executor is [`crate::channels::compute`].
    pub fn for_channels(
        names: &[String],
        fields: &[String],
        geometry: &Geometry,
        chain: &crate::boundary_chain::BoundaryChainParams,
    ) -> Result<Plan, PlanError> {
        let fields: Vec<String> = if fields.len() > 1 { fields.to_vec() } else { Vec::new() };
        let mut wanted = BTreeSet::new();
        for name in names {
            wanted.insert(Channel::named(name, &fields).map_err(PlanError::Channel)?);
        }
        let how = Making::of(chain);
        let mut plan = Plan::making(fields, wanted.clone(), false, &how, geometry);
        plan.steps.push(PlannedStep { step: Step::Keep, reads: wanted, makes: BTreeSet::new() });
        Ok(plan)
    }

    /// The plan of the steps that make the `wanted` channels of an input
    /// with these `fields` (none: a scalar), as `how` says, on `geometry`,
    /// with their reductions; `defer_normals`: a later step makes the
    /// normals. The caller adds the steps that read the channels.
    fn making(
        fields: Vec<String>,
        wanted: BTreeSet<Channel>,
        defer_normals: bool,
        how: &Making,
        geometry: &Geometry,
    ) -> Plan {
        let multi = !fields.is_empty();
        let trace = traces(&wanted, multi);
        let (derive, derive_fields) = derive_items(&wanted, multi, trace, defer_normals);
        let prefilter = trace && how.prefilter.is_some();
        let prefilter_taps = match (how.prefilter, prefilter) {
            (Some(pf), true) => {
                mdtf_bilateral::taps(geometry.spacing, &crate::boundary_chain::prefilter_params(pf, 1.0))
            }
            _ => 0,
        };
        let steps = channel_steps(&fields, &derive, &derive_fields, defer_normals, prefilter, trace.then_some(&wanted));
        let (reach, halo) = how.reach(&wanted, multi, prefilter, trace, geometry);
        let median_of_g = trace && how.boundary.g_min.is_none();
        let reductions = channel_reductions(&steps, median_of_g, prefilter, multi);
        Plan {
            fields,
            wanted,
            derive,
            derive_fields,
            defer_normals,
            prefilter,
            prefilter_taps,
            mesh: None,
            trace,
            steps,
            reductions,
            reach,
            halo,
        }
    }

    /// Whether the tracing's defaults take the boundaries found in the (v,
    /// g) histogram before it (`crate::pre_detect`): a pipeline run on one
    /// field that traces, keeps its value and has a histogram step (whose
    /// boundaries those are); not the tracing stage alone.
    pub fn detects_before_tracing(&self) -> bool {
        self.trace && self.fields.is_empty() && self.wants("v") && self.steps.iter().any(|s| s.step == Step::Histogram)
    }

    /// Whether some output reads the channel called `name`.
    pub fn wants(&self, name: &str) -> bool {
        Channel::parse(name, &self.fields).is_some_and(|c| self.wanted.contains(&c))
    }

    /// The tracing's outputs the run stores (those an output reads), in the
    /// channel table's order; none when it does not trace.
    pub fn traced_stored(&self) -> Vec<Channel> {
        let step = self.steps.iter().find(|s| s.step == Step::Trace);
        crate::channel::traced().filter(|c| step.is_some_and(|s| s.makes.contains(c))).collect()
    }

    /// The last step that reads `c` (after it the channel can be freed).
    pub fn last_reader(&self, c: Channel) -> Option<Step> {
        self.steps.iter().rev().find(|s| s.reads.contains(&c)).map(|s| s.step)
    }

    /// The channels no step after `step` reads, among those it or an earlier step made.
    pub fn freed_after(&self, step: Step) -> Vec<Channel> {
        let made: BTreeSet<Channel> =
            self.steps.iter().filter(|s| s.step <= step).flat_map(|s| s.makes.clone()).collect();
        made.into_iter().filter(|&c| self.last_reader(c) == Some(step)).collect()
    }
}

/// The steps that make channels, in order: the input (the value, and the
/// fields of a several-field input), the derive passes with the `derive`
/// and `derive_fields` items (the normals left out when deferred), the
/// pre-filter and the tracing when planned (`trace`: the channels the run
/// wants, of which the tracing keeps its own: it makes every traced channel
/// in one go, and one nothing reads is not stored).
fn channel_steps(
    fields: &[String],
    derive: &[Item],
    derive_fields: &[Item],
    defer_normals: bool,
    prefilter: bool,
    trace: Option<&BTreeSet<Channel>>,
) -> Vec<PlannedStep> {
    let multi = !fields.is_empty();
    let normals = crate::channel::NORMAL;
    let made_by = |item: &Item, fields_pass: bool| -> Vec<Channel> {
        let want = if fields_pass { Producer::DeriveFields(*item) } else { Producer::Derive(*item) };
        let jacobian = (0..fields.len()).flat_map(|field| (0..3).map(move |axis| Channel::Jacobian { field, axis }));
        let rows = crate::channel::TABLE.iter().map(|r| r.channel);
        rows.chain(jacobian).filter(|c| c.producer(multi) == want).collect()
    };
    let mut steps = Vec::new();
    let mut input_makes: BTreeSet<Channel> = BTreeSet::from([Channel::Value]);
    input_makes.extend((0..fields.len()).map(Channel::Field));
    steps.push(PlannedStep { step: Step::Input, reads: BTreeSet::new(), makes: input_makes });
    if !derive.is_empty() {
        let makes = derive.iter().flat_map(|i| made_by(i, false)).filter(|c| !defer_normals || !normals.contains(c));
        steps.push(PlannedStep { step: Step::Derive, reads: BTreeSet::from([Channel::Value]), makes: makes.collect() });
    }
    if !derive_fields.is_empty() {
        steps.push(PlannedStep {
            step: Step::DeriveFields,
            reads: (0..fields.len()).map(Channel::Field).collect(),
            makes: derive_fields.iter().flat_map(|i| made_by(i, true)).collect(),
        });
    }
    if prefilter {
        steps.push(PlannedStep {
            step: Step::Prefilter,
            reads: [Channel::G, Channel::F2].into(),
            makes: BTreeSet::new(),
        });
    }
    if let Some(wanted) = trace {
        let reads = Channel::Distance.row().map_or(&[][..], |r| r.prerequisites).iter().copied().collect();
        let makes = crate::channel::traced().filter(|c| wanted.contains(c)).collect();
        steps.push(PlannedStep { step: Step::Trace, reads, makes });
    }
    steps
}

/// What makes a plan's channels: the derivative kernel, the pre-filter and the tracing.
struct Making<'a> {
    /// The derivative kernel.
    kernel: Kernel,
    /// The pre-filter's parameters, when there is one.
    prefilter: Option<&'a BilateralParams>,
    /// The tracing's parameters (d_max, world units, None: the tracing's
    /// default for the grid; g_min, None: from the data's noise floor).
    boundary: &'a BoundaryParams,
}

impl Making<'_> {
    /// How `chain` makes its channels.
    fn of(chain: &crate::boundary_chain::BoundaryChainParams) -> Making<'_> {
        Making { kernel: chain.kernel, prefilter: chain.prefilter.as_ref(), boundary: &chain.boundary }
    }
}

/// Whether some of the `wanted` channels come from the tracing.
fn traces(wanted: &BTreeSet<Channel>, multi: bool) -> bool {
    wanted.iter().any(|c| c.producer(multi) == Producer::Trace)
}

impl Making<'_> {
    /// How far each stage reaches and the halo a block of the `wanted`
    /// channels needs, on `geometry`, with the pre-filter and the tracing as planned.
    fn reach(
        &self,
        wanted: &BTreeSet<Channel>,
        multi: bool,
        prefilter: bool,
        trace: bool,
        geometry: &Geometry,
    ) -> (Reach, [usize; 3]) {
        let kernel = self.kernel;
        let prefilter_radius = match (self.prefilter, prefilter) {
            (Some(pf), true) => {
                mdtf_bilateral::box_radius(geometry.spacing, &crate::boundary_chain::prefilter_params(pf, 1.0))
            }
            _ => [0; 3],
        };
        let d_max = if trace { self.boundary.d_max.unwrap_or(mdtf_boundary::default_d_max(geometry)) } else { 0.0 };
        let reach = Reach::new(kernel, prefilter_radius, d_max, geometry.spacing);
        let mut halo = [0; 3];
        for c in wanted {
            let h = c.halo(multi, &reach);
            for a in 0..3 {
                halo[a] = halo[a].max(h[a]);
            }
        }
        (reach, halo)
    }
}

/// The items of the derive pass over the value and of the pass over all
/// fields that make the `wanted` channels and, when `trace`, the tracing's
/// inputs (g, f'', normal); `defer_normals`: the normals are made later.
pub fn derive_items(
    wanted: &BTreeSet<Channel>,
    multi: bool,
    trace: bool,
    defer_normals: bool,
) -> (Vec<Item>, Vec<Item>) {
    let wants = |c: Channel| wanted.contains(&c);
    let wants_normals = crate::channel::NORMAL.into_iter().any(wants);
    let mut derive = Vec::new();
    if trace || wants(Channel::G) {
        derive.push(Item::G);
    }
    if trace || wants(Channel::F2) {
        derive.push(Item::F2);
    }
    if trace || (wants_normals && !defer_normals) {
        derive.push(Item::Normal);
    }
    // then every other item a wanted channel needs
    let made = |p: Producer| wanted_from(wanted, multi, p);
    let first = [Item::G, Item::F2, Item::Normal];
    derive.extend(Item::ALL.into_iter().filter(|i| !first.contains(i) && made(Producer::Derive(*i))));
    let fields = [Item::Gnorm, Item::InvG, Item::Jacobian].into_iter().filter(|&i| made(Producer::DeriveFields(i)));
    (derive, fields.collect())
}

/// Whether one of the `wanted` channels comes from `producer`.
fn wanted_from(wanted: &BTreeSet<Channel>, multi: bool, producer: Producer) -> bool {
    wanted.iter().any(|c| c.producer(multi) == producer)
}

/// The whole-volume reductions the steps of a pipeline's plan wait for
/// beyond those of the steps that make its channels (`detects_before_tracing`:
/// [`Plan::detects_before_tracing`]).
fn pipeline_reductions(histograms: &Histograms, steps: &[PlannedStep], detects_before_tracing: bool) -> Vec<Reduction> {
    let mut out = Vec::new();
    let mut add = |what: &str, before: Step| {
        if steps.iter().any(|x| x.step == before) {
            out.push(Reduction { what: what.to_string(), before: vec![before] });
        }
    };
    if detects_before_tracing {
        add("(v, g) counts and their boundaries (g_hit_min's cap, the Fig. 2 range)", Step::Trace);
    }
    if histograms.counted {
        add("exact percentiles of g (the histogram's g axis, as Teem's qbert clips it)", Step::Histogram);
    }
    if histograms.hvol {
        add("histogram volume (v, g, f'') counts and sums (boundaries, default opacity)", Step::Pack);
    }
    add("finite range of every packed channel (its quantisation)", Step::Pack);
    out
}

/// The whole-volume reductions the steps that make channels wait for
/// (`median_of_g`: the tracing takes its noise floor from the data).
fn channel_reductions(steps: &[PlannedStep], median_of_g: bool, prefilter: bool, multi: bool) -> Vec<Reduction> {
    let has = |s: Step| steps.iter().any(|x| x.step == s);
    let mut out = Vec::new();
    let mut add = |what: &str, before: Vec<Step>| {
        let before: Vec<Step> = before.into_iter().filter(|&s| has(s)).collect();
        if !before.is_empty() {
            out.push(Reduction { what: what.to_string(), before });
        }
    };
    let of_v = if has(Step::Trace) {
        "finite range of v (derive's epsilon, tracing thresholds)"
    } else {
        "finite range of v (derive's epsilon)"
    };
    add(of_v, vec![Step::Derive, Step::Trace]);
    if multi {
        add("finite range of each field (its [0, 1] normalisation)", vec![Step::DeriveFields]);
    }
    if prefilter {
        add("finite ranges of g and f'' (the range sigma)", vec![Step::Prefilter]);
    }
    if median_of_g {
        add("median of g (the noise floor: g_min, g_hit_min)", vec![Step::Trace]);
    }
    out
}

impl fmt::Display for Plan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names = |set: &BTreeSet<Channel>| -> String {
            set.iter().map(|c| c.name(&self.fields)).collect::<Vec<_>>().join(" ")
        };
        writeln!(f, "channels the outputs read: {}", names(&self.wanted))?;
        writeln!(f, "steps:")?;
        for (i, s) in self.steps.iter().enumerate() {
            let mut line = format!("  {} {:<16}", i + 1, s.step.name());
            if !s.reads.is_empty() {
                line += &format!(" reads {}", names(&s.reads));
            }
            if !s.makes.is_empty() {
                line += &format!(" -> {}", names(&s.makes));
            }
            let freed: BTreeSet<Channel> = self.freed_after(s.step).into_iter().collect();
            if !freed.is_empty() && s.step != Step::Pack {
                line += &format!("; frees {}", names(&freed));
            }
            match s.step {
                Step::Derive => line += &format!(" [{}]", item_names(&self.derive)),
                Step::DeriveFields => line += &format!(" [{}]", item_names(&self.derive_fields)),
                Step::Prefilter => {
                    line += &format!(
                        " [bilateral: {} taps per voxel on each of g and f'' (mode \"exact\": the whole box of \
                         k sigma_d, the costliest step; \"fast\": within 1.5 sigma_d); drop [prefilter] on clean data]",
                        self.prefilter_taps
                    );
                }
                Step::Pack => {
                    if let Some(mesh) = &self.mesh {
                        line += &format!(" [{mesh}]");
                    }
                }
                _ => {}
            }
            writeln!(f, "{}", line.trim_end())?;
        }
        writeln!(f, "whole-volume reductions (they finish before the steps that need them):")?;
        for r in &self.reductions {
            let before: Vec<&str> = r.before.iter().map(|s| s.name()).collect();
            writeln!(f, "  {} -> {}", r.what, before.join(", "))?;
        }
        let [x, y, z] = self.halo;
        let r = &self.reach;
        write!(
            f,
            "halo of a block: x {x}, y {y}, z {z} voxels (kernel {:?}, pre-filter {:?}, tracing {:?})",
            r.kernel,
            r.prefilter,
            if self.trace { r.trace } else { [0; 3] }
        )
    }
}

/// The mesh a volume of `geometry` gives under `tetra`'s scheme and budget, in words.
fn mesh_words(geometry: &Geometry, tetra: &mdtf_tetra::TetraParams) -> String {
    let (scheme, budget) = (tetra.tets, tetra.max_tetrahedra);
    let full = mdtf_tetra::tetrahedra_of(geometry.dims, scheme);
    let (block, to) = mdtf_tetra::coarsening(geometry.dims, scheme, budget);
    let budget_words = if budget == 0 { "no budget".to_string() } else { format!("budget {budget}") };
    if block == 1 {
        format!("mesh: {full} tetrahedra, one point per voxel ({budget_words}, tetra.max_tetrahedra)")
    } else {
        let [x, y, z] = to;
        format!(
            "mesh: the grid would give {full} tetrahedra, over the {budget_words} (tetra.max_tetrahedra): the value \
             averaged over {block} x {block} x {block} blocks, {x} x {y} x {z} points, {} tetrahedra",
            mdtf_tetra::tetrahedra_of(to, scheme)
        )
    }
}

fn item_names(items: &[Item]) -> String {
    items.iter().map(|i| i.name()).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped(name: &str, fields: &[&str]) -> Plan {
        let path = format!("{}/../../pipelines/{name}.toml", env!("CARGO_MANIFEST_DIR"));
        let text = std::fs::read_to_string(&path).unwrap();
        let p = crate::file::parse(&text, &[]).unwrap();
        let fields: Vec<String> = fields.iter().map(|f| f.to_string()).collect();
        Plan::resolve(&Settings::new(&p, &Default::default()), &fields, &Geometry::new([64; 3], [1.0; 3])).unwrap()
    }

    fn steps(plan: &Plan) -> Vec<&'static str> {
        plan.steps.iter().map(|s| s.step.name()).collect()
    }

    #[test]
    fn each_shipped_pipeline_derives_only_what_its_outputs_read() {
        let slicer = shipped("slicer-3dtf", &[]);
        assert_eq!(slicer.derive, [Item::G, Item::F2]);
        assert!(slicer.defer_normals && !slicer.trace && slicer.halo == [2; 3]);
        assert_eq!(steps(&slicer), ["input", "derive", "histogram", "pack", "preview"]);

        let distance = shipped("distance-tf", &[]);
        assert_eq!(distance.derive, [Item::G, Item::F2, Item::Normal]);
        assert!(distance.trace && distance.prefilter && !distance.defer_normals);
        // gauss:1's 4 voxels + the fast bilateral's 2 (1.5 sigma_d) + d_max 15 voxels + 2 for g's tricubic at the hit
        assert_eq!(distance.halo, [23; 3]);
        // f'' is read by the tracing alone: freed after it; g by the histogram too
        assert_eq!(distance.freed_after(Step::Trace), [Channel::F2]);
        assert_eq!(distance.last_reader(Channel::G), Some(Step::Histogram));

        let gaussian = shipped("gaussian-tf", &["a", "b", "c"]);
        assert_eq!(
            (gaussian.derive.as_slice(), gaussian.derive_fields.as_slice()),
            (&[Item::G][..], &[Item::Gnorm][..])
        );
        let peak = shipped("peak-finding", &[]);
        assert_eq!((peak.derive.as_slice(), peak.derive_fields.as_slice()), (&[Item::G, Item::InvG][..], &[][..]));
        // several fields: 1/g comes from ||G|| of all of them
        let peak2 = shipped("peak-finding", &["t1", "brain"]);
        assert_eq!((peak2.derive.as_slice(), peak2.derive_fields.as_slice()), (&[Item::G][..], &[Item::InvG][..]));
    }

    #[test]
    fn a_command_s_channels_are_planned_with_only_the_steps_that_make_them() {
        let chain = crate::boundary_chain::BoundaryChainParams::default();
        let geo = Geometry::new([64; 3], [1.0; 3]);
        let names = |n: &[&str]| -> Vec<String> { n.iter().map(|s| s.to_string()).collect() };
        let g = Plan::for_channels(&names(&["v", "g"]), &[], &geo, &chain).unwrap();
        assert_eq!((g.derive.as_slice(), g.trace, g.halo), (&[Item::G][..], false, [2; 3]));
        assert_eq!(steps(&g), ["input", "derive", "keep"]);
        assert_eq!(g.freed_after(Step::Keep), [Channel::Value, Channel::G]);

        let traced = Plan::for_channels(&names(&["g_hit", "hit"]), &[], &geo, &chain).unwrap();
        assert_eq!(traced.derive, [Item::G, Item::F2, Item::Normal]);
        assert!(traced.trace && !traced.prefilter);
        assert_eq!(steps(&traced), ["input", "derive", "boundary", "keep"]);
        // as distance-tf's: central4's 2 voxels + d_max 15 voxels + 2 for the tricubic g at the hit
        assert_eq!(traced.halo, [19; 3]);
        assert!(traced.reductions.iter().any(|r| r.what.starts_with("median of g")));

        let filtered = crate::boundary_chain::BoundaryChainParams {
            prefilter: Some(mdtf_bilateral::BilateralParams { sigma_d: 2.0, sigma_r: 0.1, ..Default::default() }),
            ..chain.clone()
        };
        let with = Plan::for_channels(&names(&["distance"]), &[], &geo, &filtered).unwrap();
        assert_eq!(steps(&with), ["input", "derive", "prefilter", "boundary", "keep"]);
        // the pre-filter is planned only for a tracing
        let without = Plan::for_channels(&names(&["f2"]), &[], &geo, &filtered).unwrap();
        assert_eq!((without.derive.as_slice(), without.prefilter), (&[Item::F2][..], false));

        let fields = names(&["a", "b"]);
        let multi = Plan::for_channels(&names(&["gnorm", "b"]), &fields, &geo, &chain).unwrap();
        assert_eq!((multi.derive.as_slice(), multi.derive_fields.as_slice()), (&[][..], &[Item::Gnorm][..]));
        let e = Plan::for_channels(&names(&["g", "gradient"]), &[], &geo, &chain).unwrap_err().to_string();
        assert!(e.starts_with("unknown channel 'gradient'") && e.contains("distance"), "{e}");
    }

    #[test]
    fn an_unknown_kept_channel_is_refused_when_planning() {
        let text = "keep = [\"g\", \"distanse\"]\n[pack]\nprofile = \"slicer-3dtf\"\n";
        let p = crate::file::parse(text, &[]).unwrap();
        let e = Plan::resolve(&Settings::new(&p, &Default::default()), &[], &Geometry::new([8; 3], [1.0; 3]))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("keep: unknown channel 'distanse'") && e.contains("distance"), "{e}");
        let with_prefilter = "[prefilter]\nsigma_d = 2.0\nsigma_r = 0.1\n[pack]\nprofile = \"distance-tf\"\n";
        let p = crate::file::parse(with_prefilter, &[]).unwrap();
        let plan =
            Plan::resolve(&Settings::new(&p, &Default::default()), &[], &Geometry::new([64, 64, 64], [1.0, 1.0, 2.0]))
                .unwrap();
        // pre-filter box ceil(2.5 x 2 / s): 5, 5, 3; rays of 15 mm: 15 + 2, 15 + 2, 8 + 2
        assert_eq!((plan.reach.prefilter, plan.halo), ([5, 5, 3], [2 + 5 + 17, 2 + 5 + 17, 2 + 3 + 10]));
        assert!(plan.to_string().contains("halo of a block: x 24, y 24, z 15 voxels"), "{plan}");
        // its cost: a box of 11 x 11 x 7 taps
        assert!(plan.to_string().contains("bilateral: 847 taps per voxel"), "{plan}");
    }
}
