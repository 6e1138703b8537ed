//! Composition of mdtf stages, run in process without intermediate files:
//! the stage crates never call each other; chains, pipeline files
//! ([`file`]) and their runner ([`run`]) live here.
//!
//! What a run computes is decided once, by [`plan::Plan::resolve`] from what
//! its outputs read (pack profile, histograms, kept channels), over the
//! channel table [`channel::TABLE`] (each channel's producer, prerequisites
//! and halo); `mdtf run --plan` prints the plan. To add a channel: a
//! [`channel::Channel`] variant and its row (with its units and meaning;
//! a packed channel takes the manifest's text from `mdtf_pack::texts`), and
//! the derive item or stage that produces it. The [`plan`] module's docs
//! show the table and the plan of each shipped pipeline.
//!
//! The same plan runs on the whole volume ([`run::run`]) or slab by slab
//! under a memory budget ([`blocks::run`]): z-slabs grown by each pass's
//! halo, whole-volume reductions merged exactly, outputs byte-identical.

pub mod blocks;
pub mod boundary_chain;
pub mod channel;
pub mod channels;
pub mod error;
pub mod figures;
pub mod file;
pub mod gaussians;
pub mod hist_files;
pub mod hvol_streamed;
pub mod inputs;
pub mod materials;
pub mod pack_inputs;
pub mod plan;
pub mod pre_detect;
pub(crate) mod progress;
pub mod report;
pub mod report_page;
pub mod run;
pub mod settings;
pub mod stages;
pub mod validate;
mod whole;
