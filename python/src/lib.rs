//! The native core of the `alnlab` Python package: a run's trained model
//! over NumPy arrays ([`model`]), its scene's simulator ([`scene`]) and
//! runs found as the CLI finds them ([`runs`]), with alnlab's errors as Python exceptions carrying the
//! CLI's messages. The Python layer
//! (`python/alnlab/__init__.py`) finds a run's files and documents the API;
//! everything that predicts is here, on the same code paths as the stages.

mod arrays;
mod model;
mod runs;
mod scene;
mod threads;

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    alnlab._alnlab,
    AlnlabError,
    PyException,
    "An error of alnlab's, with the message its CLI prints after `error: `; \
     `exit_code` is the CLI's exit code for it."
);
create_exception!(
    alnlab._alnlab,
    InputError,
    AlnlabError,
    "Input the user can correct: a missing or wrong file, a bad argument \
     (the CLI's exit code 2)."
);
create_exception!(
    alnlab._alnlab,
    DamagedError,
    AlnlabError,
    "Damaged or corrupt stored data: a file failing its own checks (the \
     CLI's exit code 1)."
);

/// An alnlab error as the Python exception of its kind, with the message
/// the CLI prints.
pub(crate) fn raise(e: alnlab_common::Error) -> PyErr {
    match e.exit_code() {
        2 => InputError::new_err(e.to_string()),
        _ => DamagedError::new_err(e.to_string()),
    }
}

/// A bad argument from Python (exit code 2's kind).
pub(crate) fn invalid(message: impl Into<String>) -> PyErr {
    InputError::new_err(message.into())
}

#[pymodule]
fn _alnlab(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("AlnlabError", py.get_type::<AlnlabError>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("DamagedError", py.get_type::<DamagedError>())?;
    py.get_type::<InputError>().setattr("exit_code", 2)?;
    py.get_type::<DamagedError>().setattr("exit_code", 1)?;
    m.add_class::<model::Model>()?;
    m.add_class::<scene::Scene>()?;
    m.add_function(wrap_pyfunction!(model::reference_rollout_ns, m)?)?;
    m.add_function(wrap_pyfunction!(model::reference_predict_ns, m)?)?;
    m.add_function(wrap_pyfunction!(runs::find_artifacts, m)?)?;
    m.add_function(wrap_pyfunction!(runs::run_record, m)?)?;
    m.add_function(wrap_pyfunction!(runs::run_records, m)?)?;
    Ok(())
}
