//! A run asked for: a scenario, the command line's overrides, the engine and what to keep; and
//! [`execute`], which runs it into a run directory.

use std::path::Path;

use anyhow::{bail, Result};
use fdi_common::attack::Attacker;
use fdi_common::engine::RunSummary;
pub use fdi_common::overrides::{NumericsArgs, Overrides, SetArgs};
use fdi_common::run_dir::RunDir;
use fdi_common::scenario::{self, ClockMode, Resolved};
use fdi_common::stop::{Stop, BEFORE_THE_START};

use crate::run::runtime::Placement;
use crate::run::split::Split;
use crate::run::RunError;
use crate::run::{Engine, Traces};

/// The command line's overrides on an engine: [`Overrides::apply`], and a name for the run.
pub trait OverridesOn {
    /// Applies the overrides to `r` and re-validates it (every problem named as the command
    /// line's), then refuses what `engine` cannot run (the realtime clock in-process).
    fn apply_on(&self, r: Resolved, engine: Engine) -> Result<Resolved>;

    /// The name of a run's directory: the scenario's, then what the overrides changed —
    /// `attack-<preset or file stem>`, the controller, the engine (in-process), the clock, the
    /// seed, the duration, the numerics flags, each `--set` edit (`controller.beta=10`, made
    /// `controller_beta_10` by the rule of run folders) — so that runs of one scenario tell
    /// apart in `runs/`.
    fn run_name(&self, r: &Resolved, engine: Engine) -> String;
}

impl OverridesOn for Overrides {
    fn apply_on(&self, r: Resolved, engine: Engine) -> Result<Resolved> {
        let r = self.apply(r)?;
        if r.scenario.clock == ClockMode::Realtime && engine == Engine::Inproc {
            bail!(
                "the realtime clock needs the ipc engine (the in-process engine is lockstep only)"
            );
        }
        Ok(r)
    }

    fn run_name(&self, r: &Resolved, engine: Engine) -> String {
        let mut parts = vec![r.scenario.name.clone()];
        if let Some(a) = &self.attack {
            let path = Path::new(a);
            let stem = if path.extension().is_some_and(|x| x == "toml") {
                path.file_stem()
                    .map_or(a.clone(), |s| s.to_string_lossy().into_owned())
            } else {
                a.clone()
            };
            parts.push(format!("attack-{stem}"));
        }
        if let Some(c) = self.controller {
            parts.push(c.as_str().into());
        }
        if engine == Engine::Inproc {
            parts.push("inproc".into());
        }
        if self.clock.is_some() {
            parts.push(r.scenario.clock.as_str().into());
        }
        if let Some(seed) = self.seed {
            parts.push(format!("seed{seed}"));
        }
        if let Some(k) = self.residual {
            parts.push(format!("residual-{}", k.as_str()));
        }
        if let Some(d) = self.duration_s {
            parts.push(format!("{d}s"));
        }
        parts.extend(
            self.numerics
                .given()
                .into_iter()
                .map(|flag| flag.trim_start_matches('-').to_string()),
        );
        parts.extend(self.set.name_parts());
        parts.join("-")
    }
}

/// Loads a scenario file or the embedded paper scenario.
pub fn load(path: Option<&Path>) -> Result<Resolved> {
    Ok(match path {
        Some(p) => scenario::load_file(p)?,
        None => scenario::paper()?,
    })
}

/// A run to execute: the scenario as it will run, its directory's name, the engine and what
/// the run directory keeps.
#[derive(Debug, Clone)]
pub struct RunRequest {
    /// The scenario, overrides applied and validated.
    pub resolved: Resolved,
    /// The run directory's name (after its timestamp).
    pub name: String,
    pub engine: Engine,
    /// What the run directory keeps of the traces.
    pub traces: Traces,
    /// Real-time priority and CPUs of the ipc engine's processes.
    pub placement: Placement,
    /// The hosts a split run runs on (`--hosts FILE`).
    pub split: Option<std::sync::Arc<dyn Split>>,
    /// Told the run's ticks (ipc runs; a bar on the command line).
    pub progress: fdi_common::observe::Observer,
    /// Serve the run live (`--live`).
    pub live: Option<crate::run::LiveServe>,
    /// A lockstep run slowed to this factor of real time (`--pace`).
    pub pace: Option<f64>,
}

impl RunRequest {
    /// The scenario at `path` (the embedded paper scenario without one) with `overrides`, on
    /// `engine`, keeping full traces.
    pub fn new(path: Option<&Path>, overrides: &Overrides, engine: Engine) -> Result<Self> {
        let resolved = overrides.apply_on(load(path)?, engine)?;
        let name = overrides.run_name(&resolved, engine);
        Ok(Self::of(resolved, name, engine))
    }

    /// A resolved scenario as it is, under `name`.
    pub fn of(resolved: Resolved, name: String, engine: Engine) -> Self {
        Self {
            resolved,
            name,
            engine,
            traces: Traces::Full,
            placement: Placement::default(),
            split: None,
            progress: fdi_common::observe::Observer::quiet(),
            live: None,
            pace: None,
        }
    }

    /// Splits the run over the hosts of `split` (`--hosts`); its directory's name says so
    /// (`<name>-hosts`), apart from the same scenario's runs on one host.
    pub fn over_hosts(mut self, split: std::sync::Arc<dyn Split>) -> Self {
        self.split = Some(split);
        self.name.push_str("-hosts");
        self
    }

    /// Changes the scenario through `edit` and validates it again (every problem named, as the
    /// command line's overrides are).
    pub fn edit(mut self, edit: impl FnOnce(&mut fdi_common::scenario::Scenario)) -> Result<Self> {
        edit(&mut self.resolved.scenario);
        self.resolved = crate::run::check_overrides(self.resolved)?;
        Ok(self)
    }

    /// Makes the run's directory under `out` (`<timestamp>-<name>`, the scenario written into
    /// it).
    pub fn create_run_dir(&self, out: &Path) -> Result<RunDir> {
        crate::run_dirs::create_named_run_dir(out, &self.resolved, &self.name).map(RunDir::new)
    }
}

/// Runs `request` into `dir` (made by [`RunRequest::create_run_dir`]): traces and
/// `summary.json` there, the summary returned. A run refused before its start removes `dir`.
/// A raised `stop` stops the run at once: the summary then says it is partial.
pub fn execute(request: &RunRequest, dir: &RunDir, stop: &Stop) -> Result<RunSummary> {
    let opts = crate::run::Options {
        progress: request.progress.clone(),
        placement: request.placement.clone(),
        traces: request.traces,
        stop: stop.clone(),
        live: request.live.clone(),
        pace: request.pace,
    };
    let run = stop
        .check(BEFORE_THE_START)
        .map_err(RunError::not_started)
        .and_then(|()| {
            crate::run::execute_on(
                &request.resolved,
                request.engine,
                Some(dir.path()),
                &opts,
                request.split.as_ref(),
            )
        });
    crate::run_dirs::discard_if_not_started(dir.path(), run)
}

/// [`execute`] with `attacker` in place of the scenario's attack profile
/// ([`fdi_common::attack::Attacker`]), on the in-process engine only: the request's engine must
/// be [`Engine::Inproc`] and it must not be split over hosts (a request that asks otherwise is
/// refused before the start, and `dir` removed). The run directory holds what [`execute`]
/// writes for an in-process run; the summary's `attack` is the attacker's name. The
/// in-process engine runs to the end: a raised `stop` stops it only before its start.
pub fn execute_with<A: Attacker>(
    request: &RunRequest,
    dir: &RunDir,
    stop: &Stop,
    attacker: &mut A,
) -> Result<RunSummary> {
    let run = if request.engine != Engine::Inproc || request.split.is_some() {
        Err(RunError::NotStarted(
            anyhow::anyhow!(crate::run::runtime::DID_NOT_START).context(format!(
                "a run with an attacker of its own needs the in-process engine on one host, not \
             the {} engine{}",
                request.engine.as_str(),
                if request.split.is_some() {
                    " over hosts"
                } else {
                    ""
                }
            )),
        ))
    } else {
        stop.check(BEFORE_THE_START)
            .map_err(RunError::not_started)
            .and_then(|()| {
                crate::run::execute_inproc_with(
                    &request.resolved,
                    dir.path(),
                    request.traces,
                    attacker,
                )
            })
    };
    crate::run_dirs::discard_if_not_started(dir.path(), run)
}
