//! Command-line interface.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand, ValueEnum};
use fdi_common::engine::{run_inproc, RunSummary};
use fdi_common::scenario::{self, ControllerMode, Resolved};

use crate::tables;

/// Testbed for false-data-injection attacks on a multi-agent robot system (Sargolzaei et al.).
#[derive(Debug, Parser)]
#[command(name = "fdi-launch", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a scenario (default: the embedded paper experiment).
    Run(RunArgs),
    /// Parse and validate a scenario file; lists every problem with its field path.
    Validate {
        /// Scenario TOML file.
        scenario: PathBuf,
    },
    /// Reproduce the paper's Table I (RMSE, traditional vs proposed controller).
    Table1(TableArgs),
    /// Reproduce the paper's Table II (robot 1 under four time-varying delays).
    Table2(TableArgs),
}

/// Which engine runs the scenario.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Engine {
    /// Everything on one thread, no IPC (the oracle).
    Inproc,
}

impl Engine {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Inproc => "inproc",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Controller {
    Proposed,
    Traditional,
}

impl From<Controller> for ControllerMode {
    fn from(c: Controller) -> Self {
        match c {
            Controller::Proposed => Self::Proposed,
            Controller::Traditional => Self::Traditional,
        }
    }
}

#[derive(Debug, Args)]
pub struct RunArgs {
    /// Scenario TOML file; without it the embedded paper scenario runs.
    pub scenario: Option<PathBuf>,
    #[arg(long, value_enum, default_value_t = Engine::Inproc)]
    pub engine: Engine,
    /// Replace the scenario's attack: a preset (paper, paper-linkwise, none) or a profile file.
    #[arg(long)]
    pub attack: Option<String>,
    /// Replace the scenario's controller mode.
    #[arg(long, value_enum)]
    pub controller: Option<Controller>,
    /// Replace the scenario's duration, s.
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// Replace the scenario's seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct TableArgs {
    #[arg(long, value_enum, default_value_t = Engine::Inproc)]
    pub engine: Engine,
    /// Print JSON instead of markdown.
    #[arg(long)]
    pub json: bool,
    /// Shorten every run to this many seconds (the paper's tables use 40 s).
    #[arg(long)]
    pub duration_s: Option<f64>,
}

pub fn dispatch(cli: Cli) -> Result<ExitCode> {
    match cli.command {
        Command::Run(args) => run(&args),
        Command::Validate { scenario } => validate(&scenario),
        Command::Table1(args) => tables::table1(&args),
        Command::Table2(args) => tables::table2(&args),
    }
}

/// Loads a scenario file or the embedded paper scenario.
pub fn load(path: Option<&Path>) -> Result<Resolved> {
    Ok(match path {
        Some(p) => scenario::load_file(p)?,
        None => scenario::paper()?,
    })
}

/// Applies command-line overrides and re-validates.
pub fn apply_overrides(mut r: Resolved, args: &RunArgs) -> Result<Resolved> {
    if let Some(a) = &args.attack {
        let profile = scenario::attack_from_arg(a, &r.scenario)?;
        r = r.with_attack(profile)?;
    }
    if let Some(c) = args.controller {
        r.scenario.controller.mode = c.into();
    }
    if let Some(d) = args.duration_s {
        r.scenario.duration_s = d;
    }
    if let Some(s) = args.seed {
        r.scenario.seed = s;
    }
    let problems = r.scenario.validate();
    if !problems.is_empty() {
        bail!(scenario::ScenarioError {
            source_name: "command-line overrides".into(),
            problems
        });
    }
    Ok(r)
}

/// Runs a resolved scenario on an engine.
pub fn execute(r: &Resolved, engine: Engine) -> Result<RunSummary> {
    match engine {
        Engine::Inproc => run_inproc::<2>(r, |_| {}).context("in-process engine"),
    }
}

fn run(args: &RunArgs) -> Result<ExitCode> {
    let r = apply_overrides(load(args.scenario.as_deref())?, args)?;
    let summary = execute(&r, args.engine)?;
    if args.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        print_summary(&summary);
    }
    Ok(ExitCode::SUCCESS)
}

fn print_summary(s: &RunSummary) {
    println!(
        "scenario {} | engine {} | clock {} | controller {} | attack {} | {} agents | {:.1} s simulated in {:.2} s wall",
        s.scenario, s.engine, s.clock, s.controller, s.attack, s.agents, s.sim_s, s.wall_s
    );
    println!(
        "| robot | RMSE (rad) | max abs error (rad) | onsets: time to detect (s) | false alarms |"
    );
    println!("|---|---|---|---|---|");
    for (id, m) in &s.metrics {
        let onsets: Vec<String> = m
            .onsets
            .iter()
            .map(|o| {
                format!(
                    "{:.1}: {}",
                    o.t_s,
                    o.time_to_detect_s
                        .map_or("never".into(), |d| format!("{d:.3}"))
                )
            })
            .collect();
        println!(
            "| {id} | {:.4} | {:.4} | {} | {} |",
            m.rmse_rad,
            m.max_abs_error_rad,
            onsets.join(", "),
            m.false_alarms
        );
    }
    println!("trace digest {}", s.trace_digest);
}

fn validate(path: &Path) -> Result<ExitCode> {
    match scenario::load_file(path) {
        Ok(r) => {
            println!(
                "{}: valid ({} agents, {} ticks, attack `{}`)",
                path.display(),
                r.agent_count(),
                r.ticks(),
                r.attack.name
            );
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            eprintln!("{e}");
            Ok(ExitCode::from(2))
        }
    }
}
