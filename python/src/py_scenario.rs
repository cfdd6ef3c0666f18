//! `fdi_mas.Scenario`: a validated scenario with its attack resolved, and the command line's
//! overrides as keyword arguments.

use std::path::PathBuf;

use fdi_common::overrides::{Overrides, SOURCE_NAME};

/// The name the problems of the keywords of `Scenario.paper`, `load` and `replace` are reported
/// under (the command line's are [`SOURCE_NAME`]).
const KEYWORDS_SOURCE: &str = "keyword arguments";
use fdi_common::problem::Problem;
use fdi_common::scenario::{self, ClockMode, Resolved, ScenarioError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::scenario_error;

/// A scenario as it will run: validated, its attack profile resolved.
#[pyclass(module = "fdi_mas._core", frozen, skip_from_py_object)]
#[derive(Debug, Clone)]
pub struct Scenario {
    pub resolved: Resolved,
}

/// The keyword arguments a scenario takes: the command line's overrides, by their flags'
/// names with `_` for `-`.
const KEYWORDS: &[&str] = &[
    "attack",
    "controller",
    "duration_s",
    "seed",
    "residual",
    "clock",
    "observer_input",
    "leakage_w_per_s",
    "dead_zone_rad_s",
    "innovation_time_constant_s",
];

fn problem(path: &str, message: impl Into<String>) -> ScenarioError {
    ScenarioError {
        source_name: KEYWORDS_SOURCE.into(),
        problems: vec![Problem {
            path: path.into(),
            message: message.into(),
        }],
    }
}

/// A value of keyword `key` parsed from its string form.
fn parsed<T: std::str::FromStr>(key: &str, v: &Bound<'_, PyAny>) -> Result<T, ScenarioError>
where
    T::Err: std::fmt::Display,
{
    let s: String = v
        .extract()
        .map_err(|_| problem(key, format!("expected a string, got {}", type_name(v))))?;
    s.parse::<T>().map_err(|e| problem(key, e.to_string()))
}

fn type_name(v: &Bound<'_, PyAny>) -> String {
    v.get_type()
        .name()
        .map_or_else(|_| "a value".into(), |n| n.to_string())
}

fn number(key: &str, v: &Bound<'_, PyAny>) -> Result<f64, ScenarioError> {
    if v.is_instance_of::<pyo3::types::PyBool>() {
        return Err(problem(key, "expected a number, got bool"));
    }
    v.extract::<f64>()
        .map_err(|_| problem(key, format!("expected a number, got {}", type_name(v))))
}

/// The overrides of `kwargs`: every unknown keyword and every value of the wrong type named.
fn overrides(kwargs: Option<&Bound<'_, PyDict>>) -> Result<Overrides, ScenarioError> {
    let mut o = Overrides::default();
    let mut problems = Vec::new();
    let Some(kwargs) = kwargs else {
        return Ok(o);
    };
    for (k, v) in kwargs.iter() {
        let key: String = k.extract().unwrap_or_else(|_| "?".into());
        let set = match key.as_str() {
            "attack" => v
                .extract::<String>()
                .map(|s| o.attack = Some(s))
                .map_err(|_| problem(&key, format!("expected a string, got {}", type_name(&v)))),
            "controller" => parsed(&key, &v).map(|c| o.controller = Some(c)),
            "clock" => parsed(&key, &v).map(|c| o.clock = Some(c)),
            "residual" => parsed(&key, &v).map(|c| o.residual = Some(c)),
            "observer_input" => parsed(&key, &v).map(|c| o.numerics.observer_input = Some(c)),
            "duration_s" => number(&key, &v).map(|x| o.duration_s = Some(x)),
            "seed" => v.extract::<u64>().map(|s| o.seed = Some(s)).map_err(|_| {
                problem(
                    &key,
                    "expected a whole number from 0 to 2^64 - 1".to_string(),
                )
            }),
            "leakage_w_per_s" => number(&key, &v).map(|x| o.numerics.leakage_w_per_s = Some(x)),
            "dead_zone_rad_s" => number(&key, &v).map(|x| o.numerics.dead_zone_rad_s = Some(x)),
            "innovation_time_constant_s" => {
                number(&key, &v).map(|x| o.numerics.innovation_time_constant_s = Some(x))
            }
            _ => Err(problem(
                &key,
                format!(
                    "no such keyword{}; the scenario's keywords are {}",
                    fdi_common::collect::nearest(&key, KEYWORDS.iter().copied())
                        .map(|n| format!(" (did you mean `{n}`?)"))
                        .unwrap_or_default(),
                    KEYWORDS.join(", ")
                ),
            )),
        };
        if let Err(e) = set {
            problems.extend(e.problems);
        }
    }
    if problems.is_empty() {
        Ok(o)
    } else {
        Err(ScenarioError {
            source_name: KEYWORDS_SOURCE.into(),
            problems,
        })
    }
}

/// A problem of the overrides in Python's words: reported under [`KEYWORDS_SOURCE`], each
/// flag's path (`--attack`, `--duration-s`) as its keyword (`attack`, `duration_s`). A problem
/// inside an attack file given as `attack` keeps its file's name and paths.
fn in_keywords(mut e: ScenarioError) -> ScenarioError {
    let flagged = e.problems.iter().any(|p| p.path.starts_with("--"));
    if e.source_name == SOURCE_NAME || flagged {
        // A flag's problem reported under the value given (`--attack frezee`) names it.
        let value = (e.source_name != SOURCE_NAME).then(|| e.source_name.clone());
        e.source_name = KEYWORDS_SOURCE.into();
        for p in &mut e.problems {
            if let Some(flag) = p.path.strip_prefix("--") {
                p.path = flag.replace('-', "_");
                if let Some(v) = &value {
                    p.message = format!("{v:?}: {}", p.message);
                }
            }
        }
    }
    e
}

/// `r` with the overrides of `kwargs` applied and validated; the realtime clock refused (the
/// package runs the in-process engine, lockstep only).
pub fn with_overrides(
    r: Resolved,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> Result<Resolved, ScenarioError> {
    let r = overrides(kwargs)?.apply(r).map_err(in_keywords)?;
    if r.scenario.clock == ClockMode::Realtime {
        return Err(problem(
            "clock",
            "the realtime clock needs the ipc engine of the command line (`fdi-launch run`); \
             the package runs the in-process engine, lockstep only",
        ));
    }
    Ok(r)
}

#[pymethods]
impl Scenario {
    /// The paper's scenario (embedded), with the overrides given as keywords.
    #[staticmethod]
    #[pyo3(signature = (**overrides))]
    fn paper(py: Python<'_>, overrides: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        scenario::paper()
            .and_then(|r| with_overrides(r, overrides))
            .map(|resolved| Self { resolved })
            .map_err(|e| scenario_error(py, &e))
    }

    /// The scenario file at `path`, with the overrides given as keywords.
    #[staticmethod]
    #[pyo3(signature = (path, **overrides))]
    fn load(
        py: Python<'_>,
        path: PathBuf,
        overrides: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        scenario::load_file(&path)
            .and_then(|r| with_overrides(r, overrides))
            .map(|resolved| Self { resolved })
            .map_err(|e| scenario_error(py, &e))
    }

    /// This scenario with more overrides.
    #[pyo3(signature = (**overrides))]
    fn replace(&self, py: Python<'_>, overrides: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        with_overrides(self.resolved.clone(), overrides)
            .map(|resolved| Self { resolved })
            .map_err(|e| scenario_error(py, &e))
    }

    /// The scenario's name.
    #[getter]
    fn name(&self) -> String {
        self.resolved.scenario.name.clone()
    }

    /// The robots' ids, in the scenario's order.
    #[getter]
    fn agents(&self) -> Vec<u32> {
        self.resolved.scenario.agents.iter().map(|a| a.id).collect()
    }

    /// The most joints of a robot of the team: the tick table has a column per joint of it (a
    /// smaller arm's other columns are NaN).
    #[getter]
    fn links(&self) -> usize {
        (self.resolved.scenario.joint_counts().last().copied()).unwrap_or(0)
    }

    /// Each robot's joints, by id.
    #[getter]
    fn joint_counts(&self) -> std::collections::BTreeMap<u32, usize> {
        self.resolved.scenario.agent_dofs()
    }

    #[getter]
    fn duration_s(&self) -> f64 {
        self.resolved.scenario.duration_s
    }

    /// The control period Δ, s.
    #[getter]
    fn control_period_s(&self) -> f64 {
        self.resolved.scenario.control_period_s
    }

    /// Control ticks of a run: `round(duration_s / control_period_s)`.
    #[getter]
    fn ticks(&self) -> u64 {
        self.resolved.ticks()
    }

    #[getter]
    fn seed(&self) -> u64 {
        self.resolved.scenario.seed
    }

    /// The residual the χ², CUSUM and windowed-mean detectors test.
    #[getter]
    fn residual(&self) -> &'static str {
        self.resolved.scenario.detectors.residual.as_str()
    }

    /// The attack profile's name.
    #[getter]
    fn attack(&self) -> String {
        self.resolved.attack.name.clone()
    }

    #[getter]
    fn controller(&self) -> &'static str {
        self.resolved.scenario.controller.mode.as_str()
    }

    /// The scenario as TOML with its attack inlined (what a run directory stores as its
    /// scenario).
    fn to_toml(&self) -> String {
        self.resolved.to_toml()
    }

    fn __repr__(&self) -> String {
        let s = &self.resolved.scenario;
        format!(
            "Scenario(name={:?}, agents={}, duration_s={}, seed={}, attack={:?}, controller={:?})",
            s.name,
            s.agents.len(),
            s.duration_s,
            s.seed,
            self.resolved.attack.name,
            s.controller.mode.as_str()
        )
    }
}

/// The names of the shipped attack profiles (`attack=` takes them, or a profile file).
#[pyfunction]
pub fn presets() -> Vec<&'static str> {
    fdi_common::attack::presets::names()
}

/// The detectors' names, in the order of every table: the paper's `s_hat_norm`, then the
/// detectors on the observer's residual.
#[pyfunction]
pub fn detectors() -> Vec<&'static str> {
    fdi_common::detect::names()
}
