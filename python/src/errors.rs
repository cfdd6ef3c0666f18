//! The exceptions of the module, and how Rust errors become them.

use pyo3::create_exception;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyList;

create_exception!(
    _core,
    ScenarioError,
    PyValueError,
    "A scenario, an attack profile or an override is invalid: every problem, with its field's path (line and column for a file), as the command line prints them. `.problems`: the list of `(path, message)`."
);
create_exception!(
    _core,
    EngineError,
    PyRuntimeError,
    "The engine could not run a scenario (or failed inside: a bug, reported with its message, never an abort)."
);

/// A [`fdi_common::scenario::ScenarioError`] as a Python `ScenarioError` with `.problems`.
pub fn scenario_error(py: Python<'_>, e: &fdi_common::scenario::ScenarioError) -> PyErr {
    let err = ScenarioError::new_err(e.to_string());
    let problems: Vec<(String, String)> = e
        .problems
        .iter()
        .map(|p| (p.path.clone(), p.message.clone()))
        .collect();
    if let Ok(list) = PyList::new(py, problems) {
        // A failure to attach the list leaves the message, which names every problem.
        let _ = err.value(py).setattr("problems", list);
    }
    err
}

/// An error of the engine or of a run directory, with its whole chain of causes.
pub fn engine_error(e: impl std::fmt::Display) -> PyErr {
    EngineError::new_err(e.to_string())
}

/// An [`anyhow::Error`]: a `ScenarioError` when a scenario's problems are its cause, an
/// `EngineError` otherwise (with the chain of causes).
pub fn from_anyhow(py: Python<'_>, e: &anyhow::Error) -> PyErr {
    match e.downcast_ref::<fdi_common::scenario::ScenarioError>() {
        Some(s) => scenario_error(py, s),
        None => engine_error(format!("{e:#}")),
    }
}

/// Panics inside Rust: what a test calls to see that a panic reaches Python as an exception.
#[pyfunction]
pub fn panic_for_test() {
    panic!("a panic raised on purpose by fdi_mas._core.panic_for_test");
}
