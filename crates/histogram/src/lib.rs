//! Histogram stage of mdtf: joint and stretched histograms, histogram volume
//! and position function, images of them.
//!
//! Placeholder: filled by the histogram issue. It holds no functions yet.
