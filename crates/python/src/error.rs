//! mdtf's errors as Python exceptions: every typed error of a stage is
//! raised as `mdtf.MdtfError` with the message mdtf prints; bad arguments
//! (an unknown item, kernel or mode) are `ValueError`.

use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use serde::de::DeserializeOwned;
use std::fmt::Display;

pyo3::create_exception!(
    _mdtf,
    MdtfError,
    PyException,
    "An mdtf stage failed (the message is the one the mdtf command prints)."
);

/// `e` as an [`MdtfError`].
pub fn mdtf_error(e: impl Display) -> PyErr {
    MdtfError::new_err(e.to_string())
}

/// `e` as a `ValueError`.
pub fn value_error(e: impl Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// A parameter given as a string, parsed as a pipeline file spells it
/// (`"exact"`, `"fraction"`, ...); `name` is the parameter's, `valid` lists the choices.
pub fn parse_choice<T: DeserializeOwned>(name: &str, text: &str, valid: &str) -> PyResult<T> {
    serde_json::from_value(serde_json::Value::String(text.to_string()))
        .map_err(|_| PyValueError::new_err(format!("{name}: unknown value '{text}' (valid: {valid})")))
}
