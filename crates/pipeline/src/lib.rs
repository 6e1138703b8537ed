//! Pipeline files and the in-process runner of mdtf.
//!
//! Placeholder: filled by the pipelines issue. It holds no functions yet.
