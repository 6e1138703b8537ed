//! `mdtf derive`: derivative measures, one file per item.

use crate::args::DeriveArgs;
use crate::input::{print_plan, read_input, read_options};
use crate::progress::Progress;
use anyhow::{Context, Result, bail};
use mdtf_pipeline::blocks::{self, SlabSize};
use mdtf_pipeline::boundary_chain::BoundaryChainParams;
use mdtf_pipeline::channels;
use mdtf_pipeline::plan::Plan;
use mdtf_pipeline::stages::derive::Item;
use mdtf_volume::{Inputs, MultiField, OutputFolder, WriteOptions, human_bytes, write};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The items asked for and how they are derived (kernel, border, epsilon).
fn params(args: &DeriveArgs) -> Result<(Vec<Item>, BoundaryChainParams)> {
    let items = args.items.iter().map(|s| s.parse::<Item>()).collect::<Result<Vec<_>, _>>()?;
    let chain =
        BoundaryChainParams { kernel: args.kernel, border: args.border, epsilon: args.epsilon, ..Default::default() };
    Ok((items, chain))
}

/// Reads the inputs, derives through the plan of the items' channels, writes one file per item.
pub fn run(args: &DeriveArgs, progress: &Progress) -> Result<()> {
    let (items, chain) = params(args)?;
    if let Some(budget) = slab_budget(args, &items, progress)? {
        return run_by_slabs(args, &items, &chain, budget, progress);
    }
    let given: Vec<&Path> = args.inputs.iter().map(PathBuf::as_path).collect();
    let inputs = Inputs::of(&given);
    let folder = if args.plan { None } else { Some(OutputFolder::begin(&args.output, &inputs)?) };
    let opts = read_options(&args.read);
    let input = progress.step("reading", || read_inputs(args, &opts))?;
    let input = select_field(input, args.field.as_deref())?;
    let fields: Vec<String> = input.fields.iter().map(|f| f.name.clone()).collect();
    let per_item = channels::item_channels(&items, &fields)?;
    let Some(folder) = folder else {
        let names: Vec<String> = per_item.iter().flat_map(|(_, n)| n.iter().cloned()).collect();
        let plan = Plan::for_channels(&names, &fields, &input.geometry, &chain)?;
        let given: Vec<String> = given.iter().map(|p| p.display().to_string()).collect();
        print_plan(&args.items.join(", "), &given.join(", "), &input.geometry, &plan);
        return Ok(());
    };
    let start = Instant::now();
    let nz = input.geometry.dims[2] as u64;
    let out = progress
        .counted("deriving", nz, |tick| channels::derive(&input, &items, &chain, tick))
        .context("cannot derive")?;
    let seconds = start.elapsed().as_secs_f64();

    progress.step("writing", || -> Result<()> {
        for (item, mf) in &out {
            let path = folder.path().join(format!("{}{}", item.name(), args.format.extension()));
            write(&path, mf, &WriteOptions::default(), &given).context("cannot write the output")?;
        }
        Ok(())
    })?;
    folder.publish(&inputs)?;
    progress.note(&format!(
        "derived {} with {} in {:.2} s ({:.0} Mvoxel/s) into {}",
        out.iter().map(|(i, _)| i.name()).collect::<Vec<_>>().join(", "),
        args.kernel,
        seconds,
        input.geometry.voxel_count() as f64 / seconds / 1e6,
        args.output.display()
    ));
    Ok(())
}

/// The budget of a slab-by-slab derive: `--memory-budget`, or one of its
/// own when the whole volume would not fit in memory (said in a note); None
/// for a whole-volume derive (and for `--plan`).
fn slab_budget(args: &DeriveArgs, items: &[Item], progress: &Progress) -> Result<Option<u64>> {
    let one_file = args.inputs.len() == 1 && args.read.raw_dims.is_none() && args.field.is_none();
    match args.memory_budget {
        _ if args.plan => Ok(None),
        Some(_) if !one_file => bail!(
            "--memory-budget derives one input file with a header, slab by slab: without --raw-dims or --field, \
             and one file (several fields do not go by slabs)"
        ),
        Some(b) => Ok(Some(b)),
        None if !one_file => Ok(None),
        None => {
            let opts = read_options(&args.read);
            let available = mdtf_volume::available_memory();
            let auto = blocks::automatic_item_budget(&args.inputs[0], &opts, items, available);
            Ok(crate::input::announce_slabs(progress, "deriving", auto))
        }
    }
}

/// Derives slab by slab within `budget` bytes: the input read by planes,
/// each item's file written slab by slab (see `--memory-budget`).
fn run_by_slabs(
    args: &DeriveArgs,
    items: &[Item],
    chain: &BoundaryChainParams,
    budget: u64,
    progress: &Progress,
) -> Result<()> {
    let input = args.inputs[0].as_path();
    let inputs = Inputs::of(&[input]);
    let folder = OutputFolder::begin(&args.output, &inputs)?;
    let (opts, ext, size) = (read_options(&args.read), args.format.extension(), SlabSize::Budget(budget));
    let start = Instant::now();
    let made = progress
        .counted("reading, then deriving, slab by slab", 0, |tick| {
            blocks::derive_item_files(input, &opts, items, chain, size, folder.path(), ext, tick)
        })
        .context("cannot derive")?;
    let seconds = start.elapsed().as_secs_f64();
    folder.publish(&inputs)?;
    progress.note(&format!(
        "derived {} with {} in {seconds:.2} s, {} slabs of {} planes within {}, into {}",
        made.files.iter().map(|(i, _)| i.name()).collect::<Vec<_>>().join(", "),
        args.kernel,
        made.slabs,
        made.height,
        human_bytes(budget as u128),
        args.output.display()
    ));
    Ok(())
}

fn read_inputs(args: &DeriveArgs, opts: &mdtf_volume::ReadOptions) -> Result<MultiField> {
    if args.inputs.len() == 1 {
        return Ok(read_input(&args.inputs[0], &args.read, opts)?.0);
    }
    let mut named = Vec::new();
    let mut seen = Vec::new();
    for path in &args.inputs {
        // the same file twice would be two identical fields (a ||G|| of one field, named twice)
        let real = std::fs::canonicalize(path).unwrap_or_else(|_| path.clone());
        if seen.contains(&real) {
            bail!("{} is given twice: each field of a multi-field input is a file of its own", path.display());
        }
        seen.push(real);
        let mf = read_input(path, &args.read, opts)?.0;
        let stem = path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let stem = stem.split('.').next().unwrap_or("field").to_string();
        for (n, f) in mf.fields.into_iter().enumerate() {
            let name = if n == 0 { stem.clone() } else { format!("{stem}{n}") };
            named.push((name, mdtf_volume::Volume { geometry: mf.geometry.clone(), data: f.data }));
        }
    }
    MultiField::from_volumes(named).context("the input files do not form one multi-field volume")
}

fn select_field(input: MultiField, field: Option<&str>) -> Result<MultiField> {
    let Some(want) = field else { return Ok(input) };
    let names: Vec<String> = input.fields.iter().map(|f| f.name.clone()).collect();
    let index =
        names.iter().position(|n| n == want).or_else(|| want.parse::<usize>().ok().filter(|&i| i < names.len()));
    let Some(index) = index else {
        bail!("--field {want}: no such field (the input has {})", names.join(", "));
    };
    let v = input.field_volume(index).context("field index")?;
    Ok(MultiField::from(v))
}
