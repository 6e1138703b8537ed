//! The stage libraries, as the front ends reach them.
//!
//! The CLI and the Python package depend on this crate and on
//! `mdtf-volume` only: the single-stage commands (`mdtf derive`,
//! `mdtf bilateral`, `mdtf boundary`, `mdtf histogram`, `mdtf pack`,
//! `mdtf tetra`, `mdtf preview`, `mdtf export`, `mdtf synth`) call the
//! stage entry points and take the stage parameter types from here, the
//! same types the pipeline files' sections deserialise into
//! ([`crate::file::Pipeline`]). One version of each stage and of each
//! parameter type is then what every front end and every pipeline file
//! sees, and a stage crate can change its dependencies without touching a
//! front end's.

pub use mdtf_bilateral as bilateral;
pub use mdtf_boundary as boundary;
pub use mdtf_datagen as datagen;
pub use mdtf_derive as derive;
pub use mdtf_export as export;
pub use mdtf_histogram as histogram;
pub use mdtf_pack as pack;
pub use mdtf_preview as preview;
pub use mdtf_tetra as tetra;
