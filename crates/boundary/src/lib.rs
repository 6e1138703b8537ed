//! Distance-to-boundary stage of mdtf: tracing to the zero crossing of f'',
//! g at the hit, alpha maps of distance.
//!
//! Placeholder: filled by the boundary issue. It holds no functions yet.
