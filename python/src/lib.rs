//! kinegen in Python (`import kinegen`): the same specs, logs, analysis and
//! kernels as the command line, without symbolica. The Python package
//! (`python/kinegen/`) re-exports this extension module, `kinegen._kinegen`.
//!
//! ```text
//! Model.from_file / from_str -> Model (spec -> IR by automatic differentiation)
//!   .step / .step_jac_x / .step_jac_p / .observe   over NumPy rows, GIL released
//!   .compare / .fit / .diagnose (logs from read_log) -> typed results, .to_json()
//! ```
mod analysis;
mod errors;
mod localization;
mod model;
mod results;
mod simulation;

use pyo3::prelude::*;

#[pymodule]
fn _kinegen(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<model::PyModel>()?;
    m.add_class::<model::Parameter>()?;
    m.add_class::<model::Input>()?;
    m.add_class::<analysis::PyLog>()?;
    m.add_class::<results::PyErrors>()?;
    m.add_class::<analysis::PyComparison>()?;
    m.add_class::<results::PyFit>()?;
    m.add_class::<results::PyEstimate>()?;
    m.add_class::<results::PyDiagnosis>()?;
    m.add_class::<results::PyVerdict>()?;
    m.add_class::<localization::PyLocalization>()?;
    m.add_class::<localization::PyRunLocalization>()?;
    m.add_class::<simulation::PySimulation>()?;
    m.add_function(wrap_pyfunction!(analysis::read_log, m)?)?;
    m.add("Error", py.get_type::<errors::Error>())?;
    m.add("SpecError", py.get_type::<errors::SpecError>())?;
    m.add("LogError", py.get_type::<errors::LogError>())?;
    m.add("UsageError", py.get_type::<errors::UsageError>())?;
    m.add("AnalysisError", py.get_type::<errors::AnalysisError>())?;
    Ok(())
}
