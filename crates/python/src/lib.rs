//! The native part of the `mdtf` Python package (`mdtf._mdtf`): the stages
//! on numpy arrays, volume files, pipeline runs and the thread count. The
//! Python layer (`python/mdtf/__init__.py`) gives them their public
//! signatures, converts arrays to C-contiguous float32 and documents them.

mod call;
mod convert;
mod error;
mod io;
mod pipeline;
mod reach;
mod stages;

use pyo3::prelude::*;

/// Uses `threads` worker threads for every later call (0: one per core).
#[pyfunction]
fn set_threads(threads: usize) -> PyResult<()> {
    call::set_threads(threads)
}

/// The number of worker threads calls use.
#[pyfunction]
fn threads() -> usize {
    call::threads()
}

/// mdtf's version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

/// The module `mdtf._mdtf`.
#[pymodule]
fn _mdtf(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("MdtfError", m.py().get_type::<error::MdtfError>())?;
    m.add_function(wrap_pyfunction!(set_threads, m)?)?;
    m.add_function(wrap_pyfunction!(threads, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(io::read, m)?)?;
    m.add_function(wrap_pyfunction!(io::write, m)?)?;
    m.add_function(wrap_pyfunction!(stages::derive, m)?)?;
    m.add_function(wrap_pyfunction!(stages::bilateral, m)?)?;
    m.add_function(wrap_pyfunction!(stages::boundary, m)?)?;
    m.add_function(wrap_pyfunction!(stages::histogram, m)?)?;
    m.add_function(wrap_pyfunction!(stages::quantise, m)?)?;
    m.add_function(wrap_pyfunction!(pipeline::run, m)?)?;
    m.add_function(wrap_pyfunction!(pipeline::plan, m)?)?;
    m.add_function(wrap_pyfunction!(pipeline::slab_task, m)?)?;
    m.add_function(wrap_pyfunction!(reach::kernel_reach, m)?)?;
    m.add_function(wrap_pyfunction!(reach::bilateral_reach, m)?)?;
    m.add_function(wrap_pyfunction!(reach::default_epsilon, m)?)?;
    m.add_function(wrap_pyfunction!(reach::derive_components, m)?)?;
    m.add_function(wrap_pyfunction!(reach::trace_reach, m)?)?;
    m.add_function(wrap_pyfunction!(reach::boundary_thresholds, m)?)?;
    Ok(())
}
