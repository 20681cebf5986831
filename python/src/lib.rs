//! `plantc._native`: the Rust half of the `plantc` Python package.
//!
//! Every function takes plain values (model text, names, numbers, nested
//! lists) and returns JSON text or plain tuples; the Python half
//! (`python/plantc/__init__.py`) turns them into numpy arrays and result
//! objects. The work runs on the plantc libraries (`plantc-derive`) or, for
//! the identification workflows, on the command line's in-process entry
//! point [`plantc::run`] with `--json`, so Python and the CLI give the same
//! numbers by construction.
//!
//! Every call runs in a worker thread ([`blocking`]) with the GIL released:
//! the interpreter's other threads keep running, Ctrl-C raises
//! `KeyboardInterrupt` at once, and a panic anywhere below becomes a
//! `plantc.PlantcError` instead of aborting the interpreter.

mod blocking;
mod design;
mod errors;
mod model;

use pyo3::prelude::*;

/// The module `plantc._native`.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("PlantcError", py.get_type::<errors::PlantcError>())?;
    m.add("ModelError", py.get_type::<errors::ModelError>())?;
    plantc::host::set_progress_hook(blocking::progress_hook);
    m.add_function(wrap_pyfunction!(model::load_file, m)?)?;
    m.add_function(wrap_pyfunction!(model::check_text, m)?)?;
    m.add_function(wrap_pyfunction!(model::derive, m)?)?;
    m.add_function(wrap_pyfunction!(model::linearize, m)?)?;
    m.add_function(wrap_pyfunction!(model::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(design::lqr, m)?)?;
    m.add_function(wrap_pyfunction!(design::place, m)?)?;
    m.add_function(wrap_pyfunction!(design::cli, m)?)?;
    Ok(())
}
