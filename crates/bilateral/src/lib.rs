//! Bilateral filter stage of mdtf (exact and fast approximation).
//!
//! Placeholder: filled by the bilateral issue. It holds no functions yet.
