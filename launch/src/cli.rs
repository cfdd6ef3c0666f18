//! Command-line interface.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Result};
use clap::{Args, Parser, Subcommand, ValueEnum};
use fdi_common::engine::RunSummary;
use fdi_common::metrics::Onset;
use fdi_common::scenario::{self, ClockMode, ControllerMode, Resolved};
use fdi_runtime::process::ProcessArgs;

use crate::reporting::attacks::AttacksArgs;
pub use crate::reporting::output::describe_error;
use crate::reporting::tables::TableArgs;
pub use crate::run::{check_placement, Engine, Traces};
use crate::{bench, export, output, report, runtime, tables};

/// Testbed for false-data-injection attacks on a multi-agent robot system (Sargolzaei et al.).
#[derive(Debug, Parser)]
#[command(name = "fdi-launch", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a scenario (default: the embedded paper experiment) and write a run directory.
    Run(RunArgs),
    /// Parse and validate a scenario or an attack-profile file (told apart by their keys);
    /// lists every problem with its field path and, in a file, its line and column.
    Validate {
        /// Scenario or attack-profile TOML file.
        scenario: PathBuf,
    },
    /// Run a campaign: a base scenario and axes of values for its fields (a parameter sweep,
    /// Monte Carlo over seeds), in parallel and resumably, with statistics and figures.
    Sweep(crate::campaign::SweepArgs),
    /// Print the JSON Schema (draft 7) of a file format: `scenario` or `attack` (a profile).
    /// The shipped copies are `scenarios/schema/*.schema.json`; docs/scenarios.md is the reference.
    Schema {
        #[arg(value_enum)]
        format: SchemaFormat,
    },
    /// Reproduce the paper's Table I (RMSE, traditional vs proposed controller).
    Table1(TableArgs),
    /// Reproduce the paper's Table II (robot 1 under four time-varying delays).
    Table2(TableArgs),
    /// The attack-class table of docs/attacks.md: every shipped attack class under the
    /// traditional and the proposed controller (in-process), RMSE and detection per detector.
    Attacks(AttacksArgs),
    /// Make the report of a run directory: figures (PNG, SVG), RMSE table, detection metrics,
    /// `report.md`. `run` does this by itself at the end of every run.
    Report {
        /// A run directory (`runs/<timestamp>-<name>`).
        run_dir: PathBuf,
    },
    /// ROC and detection delay: sweep every detector's threshold over one recorded run (the
    /// detectors replay its records, nothing is simulated again) and write `roc.csv`, `roc.svg`/`.png`
    /// and `delay.svg`/`.png`.
    Detect(DetectArgs),
    /// Work with the binary traces of a run.
    #[command(subcommand)]
    Trace(TraceCommand),
    /// The run directories of a folder: list them, remove the older ones.
    #[command(subcommand)]
    Runs(RunsCommand),
    /// Measurements: latency of the realtime runtime, the transport floor, lockstep speed.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// Run a share of split runs on this host: wait for a coordinating `fdi-launch run
    /// --hosts FILE`, run the processes it places here, bridge them over Zenoh, hand it their
    /// traces (docs/multi-host.md).
    Serve(crate::run::serve::ServeArgs),
    /// Internal: a peer process of `bench transport`.
    #[command(hide = true)]
    BenchPeer {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// Internal: run as one of the runtime's processes (used when the sibling binaries are
    /// missing or older than fdi-launch).
    #[command(hide = true)]
    Process {
        #[arg(value_enum)]
        role: ProcessRole,
        #[command(flatten)]
        args: ProcessArgs,
    },
}

#[derive(Debug, Subcommand)]
pub enum TraceCommand {
    /// Export every trace of a run directory, one file per process with a row per record.
    Export {
        run_dir: PathBuf,
        #[arg(long, value_enum, default_value_t = export::Format::Csv)]
        format: export::Format,
    },
}

#[derive(Debug, Subcommand)]
pub enum RunsCommand {
    /// Every run directory of the folder, newest first: name, date, size, status.
    List {
        /// Folder of the run directories.
        #[arg(long, default_value = "runs")]
        out: PathBuf,
    },
    /// Keep the N newest run directories of the folder and remove the others (only folders
    /// that are run directories: `scenario.toml` with `summary.json` or `traces/`).
    Prune {
        /// How many of the newest run directories stay.
        #[arg(long)]
        keep: usize,
        /// Folder of the run directories.
        #[arg(long, default_value = "runs")]
        out: PathBuf,
        /// Say what would be removed, remove nothing.
        #[arg(long)]
        dry_run: bool,
    },
}

/// A file format that `schema` describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SchemaFormat {
    /// A scenario file (`scenarios/*.toml`).
    Scenario,
    /// An attack-profile file (`scenarios/attacks/*.toml`).
    Attack,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ProcessRole {
    Agent,
    Attacker,
    ControlCenter,
    /// Plays a recorded attacker trace (its `--trace`) back to the control center
    /// (`run --replay`).
    Replayer,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Clock {
    Lockstep,
    Realtime,
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

#[derive(Debug, Args)]
pub struct RunArgs {
    /// Scenario TOML file; without it the embedded paper scenario runs.
    pub scenario: Option<PathBuf>,
    #[arg(long, value_enum, default_value_t = Engine::Ipc)]
    pub engine: Engine,
    /// Replace the scenario's clock (realtime needs the ipc engine).
    #[arg(long, value_enum)]
    pub clock: Option<Clock>,
    /// Replace the scenario's attack: a preset (the profiles in scenarios/attacks/, see
    /// docs/attacks.md; an unknown name lists them) or a profile file.
    #[arg(long)]
    pub attack: Option<String>,
    /// Replace the scenario's controller mode.
    #[arg(long, value_enum)]
    pub controller: Option<Controller>,
    /// Replace the scenario's duration, s.
    #[arg(long, allow_negative_numbers = true)]
    pub duration_s: Option<f64>,
    /// Replace the scenario's seed.
    #[arg(long, allow_negative_numbers = true)]
    pub seed: Option<u64>,
    #[command(flatten)]
    pub numerics: NumericsArgs,
    /// Folder that receives the run directory.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// What the run directory keeps of the traces: `full`, `decimate=K` (every K-th tick) or
    /// `none`; the summary's metrics and digest cover every tick either way.
    #[arg(long, default_value_t = Traces::Full)]
    pub traces: Traces,
    /// Largest trace size a run may write (what `--traces` keeps, estimated before the start):
    /// `500MB`, `2GiB`, ...; a run over it, or over the free space of `--out`, is refused.
    #[arg(long, default_value = "10GB")]
    pub max_trace_size: bytesize::ByteSize,
    /// Start even when the estimated traces exceed the free space of `--out` (space that will
    /// be freed meanwhile; a full disk then stops the run naming the trace). The
    /// `--max-trace-size` limit still holds.
    #[arg(long)]
    pub no_space_check: bool,
    #[command(flatten)]
    pub placement: runtime::Placement,
    /// Split the run over hosts: a deployment file naming each host, its Zenoh endpoint and
    /// the processes it runs (docs/multi-host.md). Each other host runs `fdi-launch serve`.
    #[arg(long, value_name = "FILE")]
    pub hosts: Option<PathBuf>,
    /// Golden regression: re-run the control center of a recorded run directory on its recorded
    /// tampered measurements and compare the trace digest with the recording's (exit status 1
    /// when they differ). The scenario comes from RUN_DIR.
    #[arg(long, value_name = "RUN_DIR", conflicts_with_all = ["scenario", "engine", "clock", "attack", "controller", "duration_s", "seed", "rt_priority", "cpus", "hosts", "observer_input", "leakage_w_per_s", "dead_zone_rad_s", "innovation_time_constant_s"])]
    pub replay: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct DetectArgs {
    /// A run directory (its recorded traces are replayed) or a scenario TOML file (run once as
    /// `run` does, then its run directory is swept).
    pub target: PathBuf,
    /// Folder that receives the outputs; default: `<run dir>/detect`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Log-spaced thresholds per detector over the range of its statistic in the run (0 and the
    /// configured threshold are added).
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u32).range(2..=100_000))]
    pub points: u32,
    /// A scenario TARGET: the engine of its run (as `run --engine`; default ipc).
    #[arg(long, value_enum)]
    pub engine: Option<Engine>,
    /// A scenario TARGET: replace its clock (as `run --clock`).
    #[arg(long, value_enum)]
    pub clock: Option<Clock>,
    /// A scenario TARGET: replace its attack (as `run --attack`).
    #[arg(long)]
    pub attack: Option<String>,
    /// A scenario TARGET: replace its controller mode (as `run --controller`).
    #[arg(long, value_enum)]
    pub controller: Option<Controller>,
    /// A scenario TARGET: replace its duration, s (as `run --duration-s`).
    #[arg(long, allow_negative_numbers = true)]
    pub duration_s: Option<f64>,
    /// A scenario TARGET: replace its seed (as `run --seed`).
    #[arg(long, allow_negative_numbers = true)]
    pub seed: Option<u64>,
    /// A scenario TARGET: its controller's numerics (as `run`).
    #[command(flatten)]
    pub numerics: NumericsArgs,
    /// A scenario TARGET: the folder that receives its run directory (as `run --out`).
    #[arg(long, default_value = "runs")]
    pub runs: PathBuf,
}

impl DetectArgs {
    /// The flags that only a scenario TARGET takes, by name, when given.
    pub fn run_flags(&self) -> Vec<&'static str> {
        [
            ("--engine", self.engine.is_some()),
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

    /// The `run` of a scenario TARGET, with these flags.
    pub fn run_args(&self) -> RunArgs {
        RunArgs {
            scenario: Some(self.target.clone()),
            engine: self.engine.unwrap_or(Engine::Ipc),
            clock: self.clock,
            attack: self.attack.clone(),
            controller: self.controller,
            duration_s: self.duration_s,
            seed: self.seed,
            numerics: self.numerics.clone(),
            out: self.runs.clone(),
            json: false,
            traces: Traces::Full,
            max_trace_size: bytesize::ByteSize::gb(10),
            no_space_check: false,
            hosts: None,
            placement: runtime::Placement::default(),
            replay: None,
        }
    }
}

pub fn dispatch(cli: Cli) -> Result<ExitCode> {
    // Commands that run or report handle SIGINT/SIGTERM from the first moment: every phase
    // checks the flag, so an interrupt stops at once, keeps what is done and says so.
    if matches!(
        cli.command,
        Command::Run(_)
            | Command::Sweep(_)
            | Command::Report { .. }
            | Command::Detect(_)
            | Command::Table1(_)
            | Command::Table2(_)
            | Command::Attacks(_)
            | Command::Serve(_)
    ) {
        crate::interrupt::install();
    }
    // What runs killed outright left (SIGKILL of their launcher) goes at the next command.
    if !matches!(
        cli.command,
        Command::Process { .. } | Command::BenchPeer { .. }
    ) {
        runtime::reap_stale_runs();
    }
    match cli.command {
        Command::Run(args) => run(&args),
        Command::Serve(args) => crate::run::serve::serve(&args),
        Command::Validate { scenario } => validate(&scenario),
        Command::Sweep(args) => crate::campaign::sweep(&args),
        Command::Schema { format } => schema(format),
        Command::Table1(args) => tables::table1(&args),
        Command::Table2(args) => tables::table2(&args),
        Command::Attacks(args) => crate::reporting::attacks::attacks(&args),
        Command::Report { run_dir } => report::report(&run_dir).map(|()| ExitCode::SUCCESS),
        Command::Detect(args) => crate::detect::detect(&args),
        Command::Trace(TraceCommand::Export { run_dir, format }) => {
            export::export(&run_dir, format).map(|()| ExitCode::SUCCESS)
        }
        Command::Runs(RunsCommand::List { out }) => {
            crate::run::runs::print_list(&out).map(|()| ExitCode::SUCCESS)
        }
        Command::Runs(RunsCommand::Prune { keep, out, dry_run }) => {
            crate::run::runs::print_prune(&out, keep, dry_run).map(|()| ExitCode::SUCCESS)
        }
        Command::Bench(b) => bench::bench(&b),
        Command::BenchPeer { args } => crate::floor::peer_main(&args).map(|()| ExitCode::SUCCESS),
        Command::Process { role, args } => Ok(match role {
            ProcessRole::Agent => fdi_agent::main_with(args),
            ProcessRole::Attacker => fdi_attacker::main_with(args),
            ProcessRole::ControlCenter => fdi_control_center::main_with(args),
            ProcessRole::Replayer => crate::replayer::main_with(&args),
        }),
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
    args.numerics.apply(&mut r.scenario);
    if let Some(c) = args.clock {
        r.scenario.clock = match c {
            Clock::Lockstep => ClockMode::Lockstep,
            Clock::Realtime => ClockMode::Realtime,
        };
    }
    if r.scenario.clock == ClockMode::Realtime && args.engine == Engine::Inproc {
        bail!("the realtime clock needs the ipc engine (the in-process engine is lockstep only)");
    }
    crate::run::check_overrides(r)
}

fn run(args: &RunArgs) -> Result<ExitCode> {
    if let Some(recorded) = &args.replay {
        return crate::replayer::replay_run(recorded, &args.out, args.json);
    }
    run_scenario(args).map(|done| done.code)
}

/// What [`run_scenario`] left: the run directory, and the exit status of the run.
#[derive(Debug)]
pub struct RunDone {
    pub dir: PathBuf,
    pub code: ExitCode,
    /// The run was a clean success (exit status 0).
    pub clean: bool,
}

/// `run` of a scenario (not `--replay`): runs it, writes the run directory and its report,
/// prints the summary.
pub fn run_scenario(args: &RunArgs) -> Result<RunDone> {
    let r = apply_overrides(load(args.scenario.as_deref())?, args)?;
    check_placement(&r, args.engine, &args.placement)?;
    crate::run::traces::check_volume(
        &r,
        args.engine == Engine::Ipc,
        args.traces,
        &args.out,
        args.max_trace_size,
        !args.no_space_check,
    )?;
    crate::interrupt::check(runtime::BEFORE_THE_START)?;
    let deployment = match &args.hosts {
        Some(path) => Some(crate::hosts::Deployment::load(path, &r)?),
        None => None,
    };
    let dir = output::create_named_run_dir(&args.out, &r, &run_name(&r, args))?;
    let summary = output::discard_if_not_started(
        &dir,
        crate::run::execute_on(
            &r,
            args.engine,
            Some(&dir),
            !args.json,
            &args.placement,
            args.traces,
            deployment.as_ref(),
        ),
    )?;
    for lost in &summary.lost_agents {
        let when = lost
            .t_s
            .map_or(String::new(), |t| format!(" after t = {t:.3} s"));
        let uncontrolled = summary
            .metrics
            .get(&lost.agent.to_string())
            .map_or(String::new(), |m| {
                format!(
                    "; it ran uncontrolled for {} of its {} ticks, with {} deadline misses; its metrics cover {}",
                    m.uncontrolled_ticks,
                    m.agent_ticks,
                    m.deadline_misses,
                    output::coverage(m.ticks, summary.planned_ticks)
                )
            });
        match lost.rejoined_t_s {
            Some(back) => eprintln!(
                "fdi-launch: agent {} was lost{when} ({}) and rejoined at t = {back:.3} s{uncontrolled}",
                lost.agent, lost.reason
            ),
            None => eprintln!(
                "fdi-launch: agent {} was lost{when}: {}{uncontrolled}",
                lost.agent, lost.reason
            ),
        }
    }
    // The report is written whole or not at all; an interrupt stops it at once.
    let report = match report::write_report(&dir, &r, &summary) {
        Err(e) if e.downcast_ref::<runtime::Interrupted>().is_some() => return Err(e),
        other => other,
    };
    if args.json {
        let mut v = serde_json::to_value(&summary)?;
        v["run_dir"] = serde_json::Value::String(dir.display().to_string());
        println!("{v}");
    } else {
        print_summary(&summary);
        println!("run directory {}", dir.display());
        let md = dir.join("report").join("report.md");
        if md.is_file() {
            println!("report {}", md.display());
        }
    }
    if let Err(e) = report {
        eprintln!(
            "fdi-launch: error: the report of {} could not be made: {}; summary.json, rmse.md and the traces are kept (`fdi-launch report {}` makes it)",
            dir.display(),
            describe_error(&e),
            dir.display()
        );
        return Ok(RunDone {
            dir,
            code: ExitCode::FAILURE,
            clean: false,
        });
    }
    let code = exit_code(&summary);
    if let Some(verdict) = verdict(&summary) {
        eprintln!("fdi-launch: {verdict}");
    }
    let clean = code == ExitCode::SUCCESS;
    Ok(RunDone { dir, code, clean })
}

/// The name of a run's directory: the scenario's, then what the command line changed —
/// `attack-<preset or file stem>`, the controller, the engine (in-process), the clock, the seed,
/// the duration — so that runs of one scenario tell apart in `runs/`.
fn run_name(r: &Resolved, args: &RunArgs) -> String {
    let mut parts = vec![r.scenario.name.clone()];
    if let Some(a) = &args.attack {
        let path = Path::new(a);
        let stem = if path.extension().is_some_and(|x| x == "toml") {
            path.file_stem()
                .map_or(a.clone(), |s| s.to_string_lossy().into_owned())
        } else {
            a.clone()
        };
        parts.push(format!("attack-{stem}"));
    }
    if let Some(c) = args.controller {
        parts.push(ControllerMode::from(c).as_str().into());
    }
    if args.engine == Engine::Inproc {
        parts.push("inproc".into());
    }
    if args.clock.is_some() {
        parts.push(r.scenario.clock.as_str().into());
    }
    if let Some(seed) = args.seed {
        parts.push(format!("seed{seed}"));
    }
    if let Some(d) = args.duration_s {
        parts.push(format!("{d}s"));
    }
    parts.extend(
        args.numerics
            .given()
            .into_iter()
            .map(|flag| flag.trim_start_matches('-').to_string()),
    );
    parts.join("-")
}

/// What a run that is not a clean success amounts to, in words (printed last), for the exit
/// codes 5 and 3: which robots ran without control and for how long.
fn verdict(s: &RunSummary) -> Option<String> {
    if s.partial.is_some() || s.lost_agents.is_empty() {
        return None;
    }
    // Per robot that was lost: the ticks the center never computed, and the steps the robot
    // itself found without the command due (late commands after a stall count there).
    let mut ids: Vec<u32> = s.lost_agents.iter().map(|l| l.agent).collect();
    ids.sort_unstable();
    ids.dedup();
    let robots: Vec<String> = ids
        .iter()
        .filter_map(|id| s.metrics.get(&id.to_string()).map(|m| (id, m)))
        .map(|(id, m)| {
            format!(
                "robot {id} {} ticks never controlled and {} deadline misses in {} steps",
                m.uncontrolled_ticks, m.deadline_misses, m.agent_ticks
            )
        })
        .collect();
    if s.lost_every_agent() {
        Some(format!(
            "run failed (exit 5): the control center lost every robot for good, none was controlled to the end ({})",
            robots.join("; ")
        ))
    } else if s.diverged().is_empty() {
        Some(format!(
            "not a clean run (exit 3): {} of {} robots were lost for a while and ran without control meanwhile ({}); the tracking metrics cover only the controlled ticks",
            ids.len(),
            s.agents,
            robots.join("; ")
        ))
    } else {
        None
    }
}

/// The exit status of a run that produced a summary: 128 + signal when interrupted, 5 when the
/// control center lost every robot for good (the run failed: none was controlled to its end),
/// 4 when a robot diverged, 3 when a realtime run lost a robot for a while, rejoined or not (it
/// ran uncontrolled meanwhile: not a clean run), else 0.
pub fn exit_code(summary: &RunSummary) -> ExitCode {
    if let Some(signal) = summary.partial.as_ref().and_then(|p| p.signal) {
        ExitCode::from(
            runtime::Interrupted {
                signal,
                phase: runtime::DURING_THE_RUN,
            }
            .exit_code(),
        )
    } else if summary.lost_every_agent() {
        ExitCode::from(5)
    } else if !summary.diverged().is_empty() {
        ExitCode::from(4)
    } else if !summary.lost_agents.is_empty() {
        ExitCode::from(3)
    } else {
        ExitCode::SUCCESS
    }
}

fn print_summary(s: &RunSummary) {
    println!(
        "scenario {} | engine {} | clock {} | controller {} | attack {} | {} agents | {:.1} s simulated in {:.2} s wall",
        s.scenario, s.engine, s.clock, s.controller, s.attack, s.agents, s.sim_s, s.wall_s
    );
    println!("numerics: {}", output::numerics_line(s));
    if let Some(p) = &s.placement {
        println!("processes: {p}");
    }
    if let Some(notice) = output::partial_notice(s) {
        println!("{}", notice.to_uppercase());
    }
    println!("| robot | RMSE (rad) | max abs error (rad) | onsets: time to detect (s) | false alarms | deadline misses | uncontrolled ticks | metrics cover |");
    println!("|---|---|---|---|---|---|---|---|");
    for (id, m) in &s.metrics {
        println!(
            "| {id} | {} | {:.4} | {} | {} | {} | {} | {} |",
            output::rmse_cell(m, 4),
            m.max_abs_error_rad,
            describe_onsets(&m.onsets),
            m.false_alarms,
            m.deadline_misses,
            m.uncontrolled_ticks,
            output::coverage(m.ticks, s.planned_ticks)
        );
    }
    for (id, t) in s.diverged() {
        eprintln!("fdi-launch: robot {id} diverged at t = {t:.3} s (its state left the bound of {} rad or became non-finite): its metrics are not results", fdi_common::metrics::DIVERGENCE_BOUND_RAD);
    }
    println!("trace digest {}", s.trace_digest);
}

/// Onsets as `t: time to detect` (`never` when undetected); a long train is summarised.
pub fn describe_onsets(onsets: &[Onset]) -> String {
    let one = |o: &Onset| {
        format!(
            "{:.1}: {}",
            o.t_s,
            o.time_to_detect_s
                .map_or("never".into(), |d| format!("{d:.3}"))
        )
    };
    if onsets.len() <= 4 {
        return onsets.iter().map(one).collect::<Vec<_>>().join(", ");
    }
    let mut detected: Vec<f64> = onsets.iter().filter_map(|o| o.time_to_detect_s).collect();
    detected.sort_by(f64::total_cmp);
    let median = detected
        .get(detected.len() / 2)
        .map_or("-".into(), |d| format!("{d:.3}"));
    format!(
        "{} onsets (first {}), {} detected, median {median}",
        onsets.len(),
        one(&onsets[0]),
        detected.len()
    )
}

/// `schema`: the JSON Schema of `format`, pretty-printed, on stdout.
fn schema(format: SchemaFormat) -> Result<ExitCode> {
    let schema = match format {
        SchemaFormat::Scenario => scenario::scenario_schema(),
        SchemaFormat::Attack => scenario::attack_schema(),
    };
    println!("{}", serde_json::to_string_pretty(&schema)?);
    Ok(ExitCode::SUCCESS)
}

/// `validate`: a scenario, or an attack profile on its own (what it holds decides).
fn validate(path: &Path) -> Result<ExitCode> {
    // A file that cannot be read is the scenario loader's to refuse (it says why).
    let kind = scenario::read_limited(path)
        .map_or(scenario::FileKind::Scenario, |t| scenario::file_kind(&t));
    if kind == scenario::FileKind::AttackProfile {
        return validate_attack(path);
    }
    match scenario::load_file(path) {
        Ok(r) => {
            println!(
                "{}: valid scenario ({} agents, {} ticks, attack `{}`)",
                path.display(),
                r.agent_count(),
                r.ticks(),
                r.attack.name
            );
            for w in r.scenario.warnings(&r.attack) {
                println!("  warning: {}: {}", w.path, w.message);
            }
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            eprintln!("{e}");
            Ok(ExitCode::from(2))
        }
    }
}

/// `validate` of an attack profile without a scenario: what it checks, and what it cannot.
fn validate_attack(path: &Path) -> Result<ExitCode> {
    match scenario::validate_attack_alone(path) {
        Ok(p) => {
            let agents: Vec<String> = p.agents().iter().map(u32::to_string).collect();
            println!(
                "{}: valid attack profile `{}` ({} channels, {} message attacks, {} covert)",
                path.display(),
                p.name,
                p.channels.len(),
                p.messages.len(),
                p.covert.len()
            );
            println!(
                "  not checked without a scenario: that {} and the links named exist, and the segments' start times against the run's duration (validate a scenario that names this file, or `run --attack {}`)",
                if agents.is_empty() {
                    "the agents".to_string()
                } else {
                    format!("agent(s) {}", agents.join(", "))
                },
                path.display()
            );
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            eprintln!("{e}");
            eprintln!("(validated as an attack profile: it has `channels`, `messages` or `covert` and no scenario key)");
            Ok(ExitCode::from(2))
        }
    }
}

#[cfg(test)]
mod tests {
    /// Regression (issue 18): an I/O error that is both the tail of its context's message and
    /// that context's source was printed twice (`No space left on device (os error 28): No
    /// space left on device (os error 28)`).
    #[test]
    fn an_error_whose_cause_is_already_in_its_message_is_described_once() {
        #[derive(Debug, thiserror::Error)]
        #[error("writing report.png: {0}")]
        struct Writing(#[source] std::io::Error);
        let io = std::io::Error::from_raw_os_error(28);
        let e = anyhow::Error::new(Writing(io)).context("figure robot1");
        let text = super::describe_error(&e);
        assert_eq!(text.matches("os error 28").count(), 1, "{text}");
        assert!(
            text.starts_with("figure robot1: writing report.png: "),
            "{text}"
        );
        let plain = anyhow::anyhow!("a").context("b");
        assert_eq!(super::describe_error(&plain), "b: a");
    }

    /// The run directory says what the command line changed, in a fixed order.
    #[test]
    fn a_run_is_named_after_its_scenario_and_what_the_command_line_changed() {
        use clap::Parser;
        let name = |argv: &[&str]| {
            let cli = super::Cli::try_parse_from(argv).expect("parses");
            let super::Command::Run(args) = cli.command else {
                panic!("not a run")
            };
            let r = super::apply_overrides(super::load(None).expect("paper"), &args)
                .expect("valid overrides");
            super::run_name(&r, &args)
        };
        assert_eq!(name(&["fdi-launch", "run"]), "paper");
        assert_eq!(
            name(&[
                "fdi-launch",
                "run",
                "--attack",
                "freeze",
                "--controller",
                "traditional",
                "--engine",
                "inproc",
                "--seed",
                "3",
                "--duration-s",
                "2.5",
            ]),
            "paper-attack-freeze-traditional-inproc-seed3-2.5s"
        );
        let file = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../scenarios/attacks/sign-flip.toml"
        );
        assert_eq!(
            name(&["fdi-launch", "run", "--attack", file, "--clock", "lockstep"]),
            "paper-attack-sign-flip-lockstep"
        );
    }
}
