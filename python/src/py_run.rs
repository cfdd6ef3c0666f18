//! `fdi_mas.run` and `fdi_mas.open_run`: a whole run on the in-process engine, or a run the
//! command line made, as a summary, a digest and every tick's columns.

use std::path::PathBuf;

use fdi_common::engine::{run_inproc_any_until, RunSummary};
use fdi_common::run_dir::RunDir;
use fdi_common::scenario;
use pyo3::prelude::*;
use pyo3::types::PyList;

use crate::columns::Columns;
use crate::errors::{engine_error, from_anyhow, scenario_error};
use crate::py_scenario::Scenario;

/// What a run gives: its summary (the fields of `summary.json`, as JSON), its trace digest,
/// the metrics table the command line prints, and its ticks as columns.
#[pyclass(module = "fdi_mas._core", frozen)]
#[derive(Debug)]
pub struct RunResult {
    /// `summary.json`'s fields, as JSON.
    #[pyo3(get)]
    summary_json: String,
    /// The trace digest (SHA-256 of every tick record, in order).
    #[pyo3(get)]
    digest: String,
    /// The metrics table `fdi-launch run` prints (markdown).
    #[pyo3(get)]
    table: String,
    /// `(name, dtype, bytes)` of every column; `None` when the ticks were not kept.
    #[pyo3(get)]
    columns: Option<Py<PyList>>,
    /// The run directory read (`open_run`), else `None`.
    #[pyo3(get)]
    run_dir: Option<PathBuf>,
    /// Problems met while reading the traces (`open_run`): damaged or short traces.
    #[pyo3(get)]
    warnings: Vec<String>,
}

impl RunResult {
    fn new(
        py: Python<'_>,
        summary: &RunSummary,
        columns: Option<Columns>,
        run_dir: Option<PathBuf>,
        warnings: Vec<String>,
    ) -> PyResult<Self> {
        Ok(Self {
            summary_json: serde_json::to_string(summary).map_err(engine_error)?,
            digest: summary.trace_digest.clone(),
            table: fdi_report::output::metrics_table(summary),
            columns: match columns {
                Some(c) => Some(c.into_py(py)?.unbind()),
                None => None,
            },
            run_dir,
            warnings,
        })
    }
}

/// Ticks between two looks at the interpreter's signals in [`run`] (a few milliseconds of a
/// paper run; the look takes the interpreter's lock).
const SIGNALS_EVERY: u32 = 512;

/// Runs `scenario` to its end on the in-process engine (the command line's `run --engine
/// inproc`, without a run directory), the interpreter released meanwhile. `ticks`: keep every
/// tick's columns.
#[pyfunction]
#[pyo3(signature = (scenario, ticks = true))]
pub fn run(py: Python<'_>, scenario: &Scenario, ticks: bool) -> PyResult<RunResult> {
    let resolved = scenario.resolved.clone();
    let routed = resolved
        .scenario
        .agents
        .iter()
        .any(|a| resolved.attack.attacks_torque_of(a.id));
    let (summary, columns, interrupt) = py
        .detach(move || {
            let mut columns = ticks.then(|| Columns::new(&resolved, routed));
            // Ctrl-C (KeyboardInterrupt) and other signals reach the run between ticks: the
            // interpreter is asked every `SIGNALS_EVERY` ticks, and the run stops there.
            let (mut ticked, mut interrupt) = (0u32, None);
            let mut attacker = resolved.profile_attacker();
            run_inproc_any_until(
                &resolved,
                &mut attacker,
                |r| {
                    if let Some(c) = &mut columns {
                        c.push(r);
                    }
                },
                || {
                    ticked = ticked.wrapping_add(1);
                    if ticked % SIGNALS_EVERY != 0 {
                        return true;
                    }
                    match Python::attach(|py| py.check_signals()) {
                        Ok(()) => true,
                        Err(e) => {
                            interrupt = Some(e);
                            false
                        }
                    }
                },
            )
            .map(|s| (s, columns, interrupt))
        })
        .map_err(engine_error)?;
    if let Some(e) = interrupt {
        return Err(e);
    }
    RunResult::new(py, &summary, columns, None, Vec::new())
}

/// Reads the run directory `run_dir` that `fdi-launch run` wrote: its summary
/// (`summary.json`) and every tick, joined from the processes' traces as the command line
/// joins them. The traces must hold every tick (`--traces full`, the default).
#[pyfunction]
#[pyo3(signature = (run_dir, ticks = true))]
pub fn open_run(py: Python<'_>, run_dir: PathBuf, ticks: bool) -> PyResult<RunResult> {
    let dir = RunDir::new(&run_dir);
    let resolved = scenario::load_written(&dir.scenario()).map_err(|e| scenario_error(py, &e))?;
    let routed = resolved
        .scenario
        .agents
        .iter()
        .any(|a| resolved.attack.attacks_torque_of(a.id));
    let run = RunDir::new(&run_dir);
    let joined = py.detach(move || -> anyhow::Result<_> {
        fdi_report::traces::require_every_tick(&run, "reading its ticks")?;
        let mut columns = ticks.then(|| Columns::new(&resolved, routed));
        let joined = fdi_report::join::join_run(&resolved, &run, f64::NAN, |r| {
            if let Some(c) = &mut columns {
                c.push(r);
            }
        })?;
        let written = std::fs::read_to_string(run.summary())
            .ok()
            .and_then(|text| serde_json::from_str::<RunSummary>(&text).ok());
        Ok((joined, written, columns))
    });
    let (joined, written, columns) = joined.map_err(|e| from_anyhow(py, &e))?;
    let mut warnings = joined.warnings;
    let summary = match written {
        Some(s) => {
            if s.trace_digest != joined.summary.trace_digest {
                warnings.push(format!(
                    "the traces' digest {} is not summary.json's {}: the traces changed after the run",
                    joined.summary.trace_digest, s.trace_digest
                ));
            }
            s
        }
        None => {
            warnings.push(
                "no readable summary.json: the summary is the one the join of the traces gives"
                    .into(),
            );
            joined.summary
        }
    };
    RunResult::new(py, &summary, columns, Some(run_dir), warnings)
}
