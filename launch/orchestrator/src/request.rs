//! A run asked for: a scenario, the command line's overrides, the engine and what to keep; and
//! [`execute`], which runs it into a run directory.

use std::path::Path;

use anyhow::{bail, Context, Result};
use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::Args;
use fdi_common::attack::Attacker;
use fdi_common::engine::RunSummary;
use fdi_common::run_dir::RunDir;
use fdi_common::scenario::{self, ClockMode, ControllerMode, Resolved};
use fdi_common::stop::{Stop, BEFORE_THE_START};

use crate::run::hosts::Deployment;
use crate::run::runtime::{DidNotStart, Placement};
use crate::run::{Engine, Traces};

/// `--clock`: the scenario's clock modes by their names, listed in the help.
fn clock_parser() -> impl TypedValueParser<Value = ClockMode> {
    PossibleValuesParser::new(ClockMode::ALL.map(ClockMode::as_str))
        .try_map(|s| s.parse::<ClockMode>())
}

/// `--controller`: the controller's modes by their names, listed in the help.
fn controller_parser() -> impl TypedValueParser<Value = ControllerMode> {
    PossibleValuesParser::new(ControllerMode::ALL.map(ControllerMode::as_str))
        .try_map(|s| s.parse::<ControllerMode>())
}

/// The controller's numerics options of the command line: each replaces the scenario's value
/// (`[controller]`; docs/model.md, "Numerics of the delayed input" and "Long horizons").
#[derive(Debug, Clone, Default, Args)]
pub struct NumericsArgs {
    /// Replace `controller.observer_input`: `sample` (the paper's default, SPEC §4.6) or
    /// `step-mean`.
    #[arg(long, value_name = "INPUT")]
    pub observer_input: Option<fdi_common::control::ObserverInput>,
    /// Replace `controller.update_law.leakage_w_per_s` (1/s; 0 = the paper's law).
    #[arg(long, value_name = "PER_S", allow_negative_numbers = true)]
    pub leakage_w_per_s: Option<f64>,
    /// Replace `controller.update_law.dead_zone_rad_s` (rad/s; 0 = the paper's law).
    #[arg(long, value_name = "RAD_S", allow_negative_numbers = true)]
    pub dead_zone_rad_s: Option<f64>,
    /// Replace `controller.update_law.innovation_time_constant_s` (s; 0 = the paper's law).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub innovation_time_constant_s: Option<f64>,
}

impl NumericsArgs {
    /// Writes the given options into the scenario (validated by the caller).
    pub fn apply(&self, s: &mut fdi_common::scenario::Scenario) {
        let c = &mut s.controller;
        if let Some(v) = self.observer_input {
            c.observer_input = v;
        }
        if let Some(v) = self.leakage_w_per_s {
            c.update_law.leakage_w_per_s = v;
        }
        if let Some(v) = self.dead_zone_rad_s {
            c.update_law.dead_zone_rad_s = v;
        }
        if let Some(v) = self.innovation_time_constant_s {
            c.update_law.innovation_time_constant_s = v;
        }
    }

    /// The flags given, by name.
    pub fn given(&self) -> Vec<&'static str> {
        [
            ("--observer-input", self.observer_input.is_some()),
            ("--leakage-w-per-s", self.leakage_w_per_s.is_some()),
            ("--dead-zone-rad-s", self.dead_zone_rad_s.is_some()),
            (
                "--innovation-time-constant-s",
                self.innovation_time_constant_s.is_some(),
            ),
        ]
        .into_iter()
        .filter_map(|(name, given)| given.then_some(name))
        .collect()
    }
}

/// What the command line changes in a scenario: one struct for `run`, `detect` and the API.
#[derive(Debug, Clone, Default, Args)]
pub struct Overrides {
    /// Replace the scenario's clock (realtime needs the ipc engine).
    #[arg(long, value_parser = clock_parser())]
    pub clock: Option<ClockMode>,
    /// Replace the scenario's attack: a preset (the profiles in scenarios/attacks/, see
    /// docs/attacks.md; an unknown name lists them) or a profile file.
    #[arg(long)]
    pub attack: Option<String>,
    /// Replace the scenario's controller mode.
    #[arg(long, value_parser = controller_parser())]
    pub controller: Option<ControllerMode>,
    /// Replace the scenario's duration, s.
    #[arg(long, allow_negative_numbers = true)]
    pub duration_s: Option<f64>,
    /// Replace the scenario's seed.
    #[arg(long, allow_negative_numbers = true)]
    pub seed: Option<u64>,
    #[command(flatten)]
    pub numerics: NumericsArgs,
}

impl Overrides {
    /// Applies the overrides to `r` and re-validates it (every problem named as the command
    /// line's).
    pub fn apply(&self, mut r: Resolved, engine: Engine) -> Result<Resolved> {
        if let Some(a) = &self.attack {
            let profile = scenario::attack_from_arg(a, &r.scenario)?;
            r = r.with_attack(profile)?;
        }
        if let Some(c) = self.controller {
            r.scenario.controller.mode = c;
        }
        if let Some(d) = self.duration_s {
            r.scenario.duration_s = d;
        }
        if let Some(s) = self.seed {
            r.scenario.seed = s;
        }
        self.numerics.apply(&mut r.scenario);
        if let Some(c) = self.clock {
            r.scenario.clock = c;
        }
        if r.scenario.clock == ClockMode::Realtime && engine == Engine::Inproc {
            bail!(
                "the realtime clock needs the ipc engine (the in-process engine is lockstep only)"
            );
        }
        crate::run::check_overrides(r)
    }

    /// The flags given, by name.
    pub fn given(&self) -> Vec<&'static str> {
        [
            ("--clock", self.clock.is_some()),
            ("--attack", self.attack.is_some()),
            ("--controller", self.controller.is_some()),
            ("--duration-s", self.duration_s.is_some()),
            ("--seed", self.seed.is_some()),
        ]
        .into_iter()
        .filter_map(|(name, given)| given.then_some(name))
        .chain(self.numerics.given())
        .collect()
    }

    /// The name of a run's directory: the scenario's, then what the overrides changed —
    /// `attack-<preset or file stem>`, the controller, the engine (in-process), the clock, the
    /// seed, the duration — so that runs of one scenario tell apart in `runs/`.
    pub fn run_name(&self, r: &Resolved, engine: Engine) -> String {
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
        if let Some(d) = self.duration_s {
            parts.push(format!("{d}s"));
        }
        parts.extend(
            self.numerics
                .given()
                .into_iter()
                .map(|flag| flag.trim_start_matches('-').to_string()),
        );
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
    pub deployment: Option<Deployment>,
    /// Show a progress bar (ipc runs).
    pub progress: bool,
}

impl RunRequest {
    /// The scenario at `path` (the embedded paper scenario without one) with `overrides`, on
    /// `engine`, keeping full traces.
    pub fn new(path: Option<&Path>, overrides: &Overrides, engine: Engine) -> Result<Self> {
        let resolved = overrides.apply(load(path)?, engine)?;
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
            deployment: None,
            progress: false,
        }
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
        progress: request.progress,
        placement: request.placement.clone(),
        traces: request.traces,
        stop: stop.clone(),
    };
    let run = stop
        .check(BEFORE_THE_START)
        .map_err(anyhow::Error::from)
        .context(DidNotStart)
        .and_then(|()| {
            crate::run::execute_on(
                &request.resolved,
                request.engine,
                Some(dir.path()),
                &opts,
                request.deployment.as_ref(),
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
    let run = if request.engine != Engine::Inproc || request.deployment.is_some() {
        Err(anyhow::anyhow!(DidNotStart).context(format!(
            "a run with an attacker of its own needs the in-process engine on one host, not \
             the {} engine{}",
            request.engine.as_str(),
            if request.deployment.is_some() {
                " over hosts"
            } else {
                ""
            }
        )))
    } else {
        stop.check(BEFORE_THE_START)
            .map_err(anyhow::Error::from)
            .context(DidNotStart)
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
