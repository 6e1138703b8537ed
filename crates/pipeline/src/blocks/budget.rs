//! How many z-planes a slab of a slab-by-slab run may hold under a memory
//! budget: the largest height whose costliest pass (derive, pre-filter,
//! tracing, pack), with its halo, fits beside the fixed costs. The tracing,
//! whose halo (d_max and the interpolation's support) is the widest, may
//! cut its slabs into strips of rows as well ([`fit_trace`]) when whole
//! planes with that halo do not fit.

use crate::plan::Plan;
use mdtf_volume::{Geometry, human_bytes};

/// What the process holds whatever the slab: code, thread stacks, figures (bytes).
const BASE_BYTES: u64 = 48 << 20;
/// The histogram volume ([`mdtf_histogram::HvolBySlabs`]): its counts
/// (256^3 u32 at most, one array whatever its lanes) and the sums of its 16
/// fixed parts (three 8-byte sums on each of 256^2 (v, g) bins).
const HVOL_BYTES: u64 = (64 << 20) + 16 * 3 * 8 * 256 * 256;
/// The histogram volume's u64 totals, which its u32 counts spill into on a
/// grid of more than 2^32 - 1 voxels (256^3 u64 at most).
const HVOL_SPILL_BYTES: u64 = 128 << 20;

/// Block-sized f32 arrays the tracing holds: the value and its five
/// derivatives over the block grown by the halo and the kernel's support,
/// and one more for what the process holds besides (measured: the peak of a
/// 1024^3 run in strips exceeds the six by about a block).
const TRACE_BLOCK_ARRAYS: u64 = 7;

/// f32 arrays over a block's own voxels the tracing holds: distance, g_hit,
/// hit, dot and the report's g, of two blocks (one is made while the one
/// before is written).
const TRACE_OUTPUTS: u64 = 10;

/// f32 planes each pass holds per plane of its slab (`h`) and of its halo
/// read on both sides (`halo`), counted from what it reads, makes and copies;
/// the tracing's only when it reads whole planes (`trace_whole_planes`; else
/// [`fit_trace`] sizes its blocks on their own).
fn pass_planes(h: u64, plan: &Plan, trace_whole_planes: bool) -> u64 {
    let p = planes_by_pass(h, plan, trace_whole_planes);
    p.derive.max(p.prefilter).max(p.trace).max(p.pack)
}

/// f32 planes of a slab of `h` planes each pass holds (see [`pass_planes`]).
pub(super) struct PassPlanes {
    pub derive: u64,
    pub prefilter: u64,
    /// 0 when the tracing goes in strips (sized by [`fit_trace`]).
    pub trace: u64,
    pub pack: u64,
}

/// [`pass_planes`], pass by pass.
pub(super) fn planes_by_pass(h: u64, plan: &Plan, trace_whole_planes: bool) -> PassPlanes {
    let k = plan.reach.kernel[2] as u64;
    // derive reads at least a kernel's width of planes
    let read = (h + 2 * k).max(2 * k + 1);
    // every derive of a slab makes all the plan's items (kept gradients and Hessians too)
    let outputs = derived_components(plan).max(5);
    // the value, the outputs (at least g, f'', three normals), the derive's own scratch; the
    // interiors copied out, of two slabs (one is derived while the one before is summarised)
    let derive = (outputs + 3) * read + 2 * outputs * h;
    let pf = plan.reach.prefilter[2] as u64;
    let prefilter = if plan.prefilter { 4 * (h + 2 * pf) + 2 * h } else { 0 };
    let t = plan.reach.trace[2] as u64;
    // the value and its five derivatives over the block grown by the kernel, and its outputs
    let trace = match plan.trace && trace_whole_planes {
        true => TRACE_BLOCK_ARRAYS * (h + 2 * t + 2 * k) + TRACE_OUTPUTS * h,
        false => 0,
    };
    // the histograms and the textures from one pass: a derive's planes, the slab's channels
    // copied out (at most eight: distance-tf reads v, g, three normals, g_hit, hit and distance)
    // and the textures' bytes of two slabs, one quantised while the other is written (at most
    // 8 bytes a voxel: two f32 planes a plane)
    let pack = (outputs + 3) * read + 12 * h;
    PassPlanes { derive, prefilter, trace, pack }
}

/// Bytes a process holds whatever its slab, and the histogram volume's
/// when `hvol` (of a grid of `voxels`).
pub(super) fn fixed_bytes(hvol: bool, voxels: u64) -> u64 {
    let spill = if voxels > u64::from(u32::MAX) { HVOL_SPILL_BYTES } else { 0 };
    BASE_BYTES + if hvol { HVOL_BYTES + spill } else { 0 }
}

/// Bytes the tracing holds for a block of `h` planes and `r` rows, with the fixed costs.
pub(super) fn trace_block_bytes(h: usize, r: usize, geometry: &Geometry, plan: &Plan) -> u64 {
    BASE_BYTES + trace_bytes(h, r, geometry, plan)
}

/// f32 components one derivation of a slab makes: the components of every
/// item the plan derives (the value is a component of none).
fn derived_components(plan: &Plan) -> u64 {
    plan.derive.iter().map(|i| i.components().len() as u64).sum()
}

/// Why a memory budget cannot hold the smallest piece of a run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BudgetError {
    /// A slab of one plane with its halo needs more than the budget.
    #[error(
        "a memory budget of {} is too small for planes of {} x {}: a slab of one plane with its halo needs {}",
        human(.budget), .plane[0], .plane[1], human(.needs)
    )]
    Slab {
        /// The budget, bytes.
        budget: u64,
        /// The planes' size (x, y voxels).
        plane: [usize; 2],
        /// What one plane with its halo needs, bytes.
        needs: u64,
    },
    /// The tracing's block of one plane and one row with its halo needs more than the budget.
    #[error(
        "a memory budget of {} is too small for the tracing of planes of {} x {}: a block of one plane and one \
         row with its halo needs {}",
        human(.budget), .plane[0], .plane[1], human(.needs)
    )]
    Trace {
        /// The budget, bytes.
        budget: u64,
        /// The planes' size (x, y voxels).
        plane: [usize; 2],
        /// What the smallest block needs, bytes.
        needs: u64,
    },
}

/// Bytes as a person reads them ("1.5 GiB").
fn human(bytes: &u64) -> String {
    human_bytes(u128::from(*bytes))
}

/// The slab height of a run within `budget`, with the histogram volume's
/// counts when `hvol`. With `trace_in_strips` the tracing's cost is left to
/// [`fit_trace`].
pub fn fit_slabs(
    budget: u64,
    geometry: &Geometry,
    plan: &Plan,
    hvol: bool,
    trace_in_strips: bool,
) -> Result<usize, BudgetError> {
    slab_height_with(budget, geometry, plan, hvol, !trace_in_strips)
}

/// The tallest slab (planes, at most the volume's) whose passes fit in
/// `budget` bytes with the plan's halos and the histogram volume's counts
/// when `hvol`, the tracing's on whole planes, or why none does.
pub fn slab_height(budget: u64, geometry: &Geometry, plan: &Plan, hvol: bool) -> Result<usize, BudgetError> {
    slab_height_with(budget, geometry, plan, hvol, true)
}

/// [`slab_height`], the tracing counted only with `trace_whole_planes`.
fn slab_height_with(
    budget: u64,
    geometry: &Geometry,
    plan: &Plan,
    hvol: bool,
    trace_whole_planes: bool,
) -> Result<usize, BudgetError> {
    let plane_bytes = (geometry.dims[0] * geometry.dims[1] * 4) as u64;
    let fixed = fixed_bytes(hvol, geometry.voxel_count() as u64);
    let cost = |h: u64| fixed + pass_planes(h, plan, trace_whole_planes) * plane_bytes;
    let nz = geometry.dims[2] as u64;
    if cost(1) > budget {
        return Err(BudgetError::Slab { budget, plane: [geometry.dims[0], geometry.dims[1]], needs: cost(1) });
    }
    // cost grows with h: the tallest that fits, by bisection
    let (mut lo, mut hi) = (1u64, nz.max(1));
    while lo < hi {
        let mid = (lo + hi).div_ceil(2);
        if cost(mid) <= budget { lo = mid } else { hi = mid - 1 }
    }
    Ok(lo as usize)
}

/// How the tracing pass cuts the volume: z-slabs of `planes` planes, each
/// visited in strips of `rows` rows (all of them: whole planes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TraceBlocks {
    /// Planes per slab (the last may hold fewer).
    pub planes: usize,
    /// Rows per strip (the last may hold fewer).
    pub rows: usize,
}

/// Bytes the tracing holds for a block of `h` planes and `r` rows:
/// [`TRACE_BLOCK_ARRAYS`] over the block grown by the halo and the kernel's
/// support, and [`TRACE_OUTPUTS`] over the block.
fn trace_bytes(h: usize, r: usize, geometry: &Geometry, plan: &Plan) -> u64 {
    let [nx, ny, nz] = geometry.dims;
    let (t, k) = (plan.reach.trace, plan.reach.kernel);
    let planes = (h + 2 * t[2] + 2 * k[2]).min(nz.max(h));
    let rows = if r >= ny { ny } else { (r + 2 * t[1] + 2 * k[1]).min(ny) };
    4 * nx as u64 * (TRACE_BLOCK_ARRAYS * (planes * rows) as u64 + TRACE_OUTPUTS * (h * r) as u64)
}

/// The tracing's blocks within `budget`: whole planes in the other passes'
/// slabs of `planes` when they fit; else strips of rows, in slabs of up to
/// `2 threads` planes (the tracing spreads a block's planes over the
/// threads; at least 8), each strip as tall as fits, at least twice its
/// halo so that remaking the derivatives of its halo rows costs at most as
/// much as its own. Strips only when `strips_allowed` (the tracing derives
/// its channels; it reads stored ones by whole planes).
pub fn fit_trace(
    budget: u64,
    geometry: &Geometry,
    plan: &Plan,
    planes: usize,
    threads: usize,
    strips_allowed: bool,
) -> Result<TraceBlocks, BudgetError> {
    let [_, ny, nz] = geometry.dims;
    let fits = |h: usize, r: usize| BASE_BYTES + trace_bytes(h, r, geometry, plan) <= budget;
    if !plan.trace || !strips_allowed || fits(planes, ny) {
        return Ok(TraceBlocks { planes, rows: ny });
    }
    let tallest_strip = |h: usize| {
        // bytes grow with r: the tallest that fits, by bisection
        let (mut lo, mut hi) = (1usize, ny.max(1));
        while lo < hi {
            let mid = (lo + hi).div_ceil(2);
            if fits(h, mid) { lo = mid } else { hi = mid - 1 }
        }
        fits(h, lo).then_some(lo)
    };
    let wanted_rows = ny.min(2 * (plan.reach.trace[1] + plan.reach.kernel[1]));
    let preferred = (2 * threads).clamp(8, 64).min(nz.max(1));
    let mut lowest = None;
    for h in (1..=preferred).rev() {
        if let Some(r) = tallest_strip(h) {
            if r >= wanted_rows {
                return Ok(TraceBlocks { planes: h, rows: r });
            }
            lowest = Some(TraceBlocks { planes: h, rows: r });
        }
    }
    lowest.ok_or_else(|| BudgetError::Trace {
        budget,
        plane: [geometry.dims[0], ny],
        needs: BASE_BYTES + trace_bytes(1, 1, geometry, plan),
    })
}

/// Peak memory of a whole-volume run per voxel, bytes, as measured at 256^3
/// (`run_report.json`'s peak, preview left out): slicer-3dtf 21, distance-tf
/// 46; rounded up.
fn whole_run_bytes_per_voxel(profile: mdtf_pack::Profile) -> u64 {
    match profile {
        mdtf_pack::Profile::Slicer3dtf => 24,
        _ => 48,
    }
}

/// The memory a run may take of `available` bytes when not told: three quarters.
pub fn usable_memory(available: u64) -> u64 {
    available / 4 * 3
}

/// The budget a run without `--memory-budget` takes: None (the whole
/// volume at once) when the whole run of `voxels` voxels with `profile`
/// fits in three quarters of `available` bytes, else those three quarters
/// (slab by slab).
pub fn automatic_budget(profile: mdtf_pack::Profile, voxels: u64, available: u64) -> Option<u64> {
    let usable = usable_memory(available);
    (whole_run_bytes_per_voxel(profile).saturating_mul(voxels) > usable).then_some(usable)
}

/// The budget a single-stage command takes on the file `input` without
/// `--memory-budget`, and the file's grid: three quarters of `available`
/// bytes when its whole-volume run, holding `bytes_per_voxel`, would need
/// more and the file is read by planes (its header tells the grid without
/// reading the samples); None otherwise.
pub fn automatic_file_budget(
    input: &std::path::Path,
    read: &mdtf_volume::ReadOptions,
    bytes_per_voxel: u64,
    available: u64,
) -> Option<(u64, Geometry)> {
    let reader = mdtf_volume::PlaneReader::open(input, read).ok()??;
    let geo = reader.geometry().clone();
    let usable = usable_memory(available);
    (bytes_per_voxel.saturating_mul(geo.voxel_count() as u64) > usable).then_some((usable, geo))
}

/// The slabs of height `h` covering `nz` planes, in order.
pub fn slabs(nz: usize, h: usize) -> Vec<std::ops::Range<usize>> {
    (0..nz).step_by(h.max(1)).map(|z| z..(z + h.max(1)).min(nz)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::file::parse;
    use crate::settings::Settings;

    #[test]
    fn the_slab_fits_the_budget_and_one_more_plane_would_not() {
        let geo = Geometry::new([256; 3], [1.0; 3]);
        let text = "[derive]\nkernel = \"central4\"\n[pack]\nprofile = \"distance-tf\"\n";
        let plan = Plan::resolve(&Settings::new(&parse(text, &[]).unwrap(), &Default::default()), &[], &geo).unwrap();
        let plane = 256 * 256 * 4;
        let budget = 256u64 << 20;
        let h = slab_height(budget, &geo, &plan, false).unwrap() as u64;
        assert!(BASE_BYTES + pass_planes(h, &plan, true) * plane <= budget);
        assert!(BASE_BYTES + pass_planes(h + 1, &plan, true) * plane > budget);
        // the tracing's value and derivatives over its halo-grown block, and its outputs, are counted
        let (t, k) = (plan.reach.trace[2] as u64, plan.reach.kernel[2] as u64);
        assert!(pass_planes(h, &plan, true) >= 6 * (h + 2 * t + 2 * k) + 5 * h);
        assert_eq!(slabs(10, 4), vec![0..4, 4..8, 8..10]);
        let e = slab_height(1 << 20, &geo, &plan, false).unwrap_err();
        assert!(matches!(e, BudgetError::Slab { budget: 1048576, plane: [256, 256], needs } if needs > 1 << 20), "{e}");
        let e = e.to_string();
        assert!(e.contains("too small") && e.contains("1.0 MiB"), "{e}");
        assert_eq!(slab_height(1 << 40, &geo, &plan, true).unwrap(), 256, "a large budget: one slab");
        // the histogram volume's counts come off the slabs' share, once whatever its lanes
        let h2 = slab_height(budget, &geo, &plan, true).unwrap() as u64;
        assert!(BASE_BYTES + HVOL_BYTES + pass_planes(h2, &plan, true) * plane <= budget);
        assert!(BASE_BYTES + HVOL_BYTES + pass_planes(h2 + 1, &plan, true) * plane > budget);
        assert_eq!(fit_slabs(budget, &geo, &plan, true, false).unwrap(), h2 as usize);
        // over 2^32 - 1 voxels the counts' u64 totals come off it too
        let huge = Geometry::new([4096, 4096, 4096], [1.0; 3]);
        assert_eq!(fixed_bytes(true, huge.voxel_count() as u64), BASE_BYTES + HVOL_BYTES + HVOL_SPILL_BYTES);
        assert_eq!(fixed_bytes(true, geo.voxel_count() as u64), BASE_BYTES + HVOL_BYTES);
        assert_eq!(fit_slabs(budget, &geo, &plan, false, false).unwrap(), h as usize);
    }

    #[test]
    fn kept_derivatives_count_in_every_derivation_of_a_slab() {
        let geo = Geometry::new([256; 3], [1.0; 3]);
        let plan_of = |keep: &str| {
            let text = format!("keep = [{keep}]\n[derive]\nkernel = \"central4\"\n[pack]\nprofile = \"distance-tf\"\n");
            Plan::resolve(&Settings::new(&parse(&text, &[]).unwrap(), &Default::default()), &[], &geo).unwrap()
        };
        let plain = plan_of("");
        // g, f'', three normals, three gradient and six Hessian components, the Laplacian
        let many = plan_of("\"gx\", \"hxx\", \"laplacian\"");
        assert_eq!(derived_components(&plain), 5);
        assert_eq!(derived_components(&many), 15);
        let k = many.reach.kernel[2] as u64;
        // the value, the 15 outputs and the scratch over the read planes, two slabs' interiors copied
        assert!(pass_planes(20, &many, true) >= 18 * (20 + 2 * k) + 30 * 20);
        let budget = 400u64 << 20;
        let (h_plain, h_many) = (slab_height(budget, &geo, &plain, true), slab_height(budget, &geo, &many, true));
        assert!(h_many.unwrap() < h_plain.unwrap(), "the kept derivatives make slabs shorter");
    }

    #[test]
    fn the_tracing_goes_by_strips_of_rows_only_when_whole_planes_do_not_fit() {
        let geo = Geometry::new([1024; 3], [1.0; 3]);
        let text = "[derive]\nkernel = \"central4\"\n[pack]\nprofile = \"distance-tf\"\n";
        let plan = Plan::resolve(&Settings::new(&parse(text, &[]).unwrap(), &Default::default()), &[], &geo).unwrap();
        let gib = 1u64 << 30;
        // 1 GiB: the other passes' slabs fit, the tracing's halo on whole planes does not
        let h = fit_slabs(gib, &geo, &plan, true, true).unwrap();
        assert!(slab_height(gib, &geo, &plan, true).is_err(), "whole planes with the tracing's halo do not fit");
        let b = fit_trace(gib, &geo, &plan, h, 2, true).unwrap();
        assert!(b.rows < 1024 && b.planes >= 1, "{b:?}");
        assert!(BASE_BYTES + trace_bytes(b.planes, b.rows, &geo, &plan) <= gib, "{b:?}");
        // the strips are as tall as fits, and at least twice their halo
        assert!(BASE_BYTES + trace_bytes(b.planes, b.rows + 1, &geo, &plan) > gib);
        assert!(b.rows >= 2 * (plan.reach.trace[1] + plan.reach.kernel[1]), "{b:?}");
        // with room, or when strips are not allowed, whole planes in the other passes' slabs
        assert_eq!(fit_trace(64 * gib, &geo, &plan, 9, 2, true).unwrap(), TraceBlocks { planes: 9, rows: 1024 });
        assert_eq!(fit_trace(gib, &geo, &plan, h, 2, false).unwrap(), TraceBlocks { planes: h, rows: 1024 });
        let e = fit_trace(50 << 20, &geo, &plan, 1, 2, true).unwrap_err();
        assert!(matches!(e, BudgetError::Trace { needs, .. } if needs > 50 << 20), "{e}");
        let e = e.to_string();
        assert!(e.contains("too small") && e.contains("tracing"), "{e}");
    }

    #[test]
    fn runs_go_by_slabs_on_their_own_only_when_the_whole_run_would_not_fit() {
        use mdtf_pack::Profile;
        let gib = 1u64 << 30;
        // 256^3 distance-tf needs about 0.75 GiB: whole on a 24 GiB machine
        assert_eq!(automatic_budget(Profile::DistanceTf, 1 << 24, 24 * gib), None);
        // 1024^3 needs about 48 GiB: slab by slab within three quarters of what is available
        assert_eq!(automatic_budget(Profile::DistanceTf, 1 << 30, 24 * gib), Some(18 * gib));
        // slicer-3dtf at 1024^3 needs about 24 GiB: more than 18 GiB
        assert_eq!(automatic_budget(Profile::Slicer3dtf, 1 << 30, 24 * gib), Some(18 * gib));
        assert_eq!(automatic_budget(Profile::Slicer3dtf, 1 << 30, 64 * gib), None);
    }
}
