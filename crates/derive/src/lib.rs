//! Derivative stage of mdtf: reconstruction kernels and derivative measures
//! (gradient, g, Hessian, f'', Laplacian, normals, multi-field ||G||).
//!
//! Placeholder: filled by the derive issue. It holds no functions yet.
