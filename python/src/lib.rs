//! The `fdi_mas._core` extension module: the engine of fdi-mas for Python. Thin: every number
//! comes from `fdi-common` (the engine, the metrics, the detectors) and `fdi-report` (the join of
//! a run's traces, the metrics table), the same code the command line runs. The Python package
//! `fdi_mas` (beside this crate) wraps it in numpy arrays and Gymnasium / PettingZoo
//! environments.

use pyo3::prelude::*;

mod columns;
mod episode;
mod errors;
mod memory;
mod py_episode;
mod py_run;
mod py_scenario;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("ScenarioError", py.get_type::<errors::ScenarioError>())?;
    m.add("EngineError", py.get_type::<errors::EngineError>())?;
    m.add_class::<py_scenario::Scenario>()?;
    m.add_class::<py_run::RunResult>()?;
    m.add_class::<py_episode::Episode>()?;
    m.add_class::<py_episode::Batch>()?;
    m.add_function(wrap_pyfunction!(py_run::run, m)?)?;
    m.add_function(wrap_pyfunction!(py_run::open_run, m)?)?;
    m.add_function(wrap_pyfunction!(py_scenario::presets, m)?)?;
    m.add_function(wrap_pyfunction!(py_scenario::detectors, m)?)?;
    m.add_function(wrap_pyfunction!(py_episode::attacker_reward, m)?)?;
    m.add_function(wrap_pyfunction!(py_episode::defender_reward, m)?)?;
    m.add_function(wrap_pyfunction!(errors::panic_for_test, m)?)?;
    Ok(())
}
