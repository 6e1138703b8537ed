//! Pack stage of mdtf: quantisation, texture packs per renderer, manifests,
//! transfer-function lookup tables.
//!
//! Placeholder: filled by the pack issue. It holds no functions yet.
