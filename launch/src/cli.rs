//! The command line: its types only (clap). What each command does is in `commands/`.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use fdi_orchestrator::attacks::AttacksArgs;
use fdi_orchestrator::bench::BenchCommand;
use fdi_orchestrator::campaign::SweepArgs;
use fdi_orchestrator::run::runtime::Placement;
use fdi_orchestrator::run::serve::ServeArgs;
use fdi_orchestrator::tables::TableArgs;
use fdi_orchestrator::{Engine, Overrides};
use fdi_report::export;
use fdi_report::traces::Traces;
use fdi_runtime::process::ProcessArgs;

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
    Sweep(SweepArgs),
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
    Bench(BenchCommand),
    /// Run a share of split runs on this host: wait for a coordinating `fdi-launch run
    /// --hosts FILE`, run the processes it places here, bridge them over Zenoh, hand it their
    /// traces (docs/multi-host.md).
    Serve(ServeArgs),
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

/// `run`: a scenario, its overrides, the engine and what the run directory keeps.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Scenario TOML file; without it the embedded paper scenario runs.
    pub scenario: Option<PathBuf>,
    #[arg(long, value_enum, default_value_t = Engine::Ipc)]
    pub engine: Engine,
    #[command(flatten)]
    pub overrides: Overrides,
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
    pub placement: Placement,
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

/// `detect`: a run directory, or a scenario run first as `run` runs it.
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
    /// A scenario TARGET: its overrides (as `run`).
    #[command(flatten)]
    pub overrides: Overrides,
    /// A scenario TARGET: the folder that receives its run directory (as `run --out`).
    #[arg(long, default_value = "runs")]
    pub runs: PathBuf,
}

impl DetectArgs {
    /// The flags that only a scenario TARGET takes, by name, when given.
    pub fn run_flags(&self) -> Vec<&'static str> {
        self.engine
            .map(|_| "--engine")
            .into_iter()
            .chain(self.overrides.given())
            .collect()
    }

    /// The `run` of a scenario TARGET, with these flags.
    pub fn run_args(&self) -> RunArgs {
        RunArgs {
            scenario: Some(self.target.clone()),
            engine: self.engine.unwrap_or(Engine::Ipc),
            overrides: self.overrides.clone(),
            out: self.runs.clone(),
            json: false,
            traces: Traces::Full,
            max_trace_size: bytesize::ByteSize::gb(10),
            no_space_check: false,
            hosts: None,
            placement: Placement::default(),
            replay: None,
        }
    }
}
