//! Composition of mdtf stages, run in process without intermediate files:
//! the stage crates never call each other; chains, pipeline files
//! ([`file`]) and their runner ([`run`]) live here.

pub mod boundary_chain;
pub mod channels;
pub mod figures;
pub mod file;
pub mod gaussians;
pub mod pack_inputs;
pub mod report_page;
pub mod run;
pub mod validate;
