//! Composition of mdtf stages, run in process without intermediate files.
//! The stage crates never call each other; chains live here (and, with the
//! pipelines issue, pipeline files and their runner).

pub mod boundary_chain;
pub mod channels;
pub mod pack_inputs;
