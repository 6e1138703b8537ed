//! Tetrahedral meshes for mdtf: reading, per-vertex gradients, cell ranges,
//! pre-integration tables.
//!
//! Placeholder: filled by the tetra issue. It holds no functions yet.
