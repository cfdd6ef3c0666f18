//! The command line: its types only (clap). What each command does is in `commands/`.

use std::path::PathBuf;

use clap::{Parser, Subcommand, ValueEnum};

use crate::commands::bench::BenchCommand;
use crate::commands::certs::CertsArgs;
use crate::commands::layout::LayoutArgs;
use crate::commands::model::ModelArgs;
use crate::commands::report::ExportFormat;
use crate::commands::serve::ServeArgs;
use crate::commands::sweep::SweepArgs;
use crate::commands::tables::{AttacksArgs, TableArgs};
use crate::commands::{detect::DetectArgs, run::RunArgs, validate::SchemaFormat};
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
    /// A robot from its URDF file: its moving joints (the order of q), their limits, the links'
    /// masses, and at one state its inertia M(q), Coriolis matrix V(q, q̇), gravity G(q) and
    /// friction F(q̇) — what to check before a run, or compare with another tool (--json).
    Model(ModelArgs),
    /// Print the layout of a run's figures for a viewer (Foxglove or PlotJuggler), made for the
    /// robots of a scenario: one tab per figure, one plot per robot, one series per joint.
    Layout(LayoutArgs),
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
    /// The scored benchmark (docs/score.md): a controller on the shipped teams under every
    /// attack class at held-out seeds, judged by a detector, scored into one row (`--compare`
    /// prints two side by side); a campaign, run whole or in shards (`--shard`, `--aggregate`).
    Score(crate::commands::score::ScoreArgs),
    /// Make the report of a run directory: figures (PNG, SVG), RMSE table, detection metrics,
    /// `report.md`. `run` does this by itself at the end of every run.
    Report {
        /// A run directory (`runs/<timestamp>-<name>`).
        run_dir: PathBuf,
        /// The robots that get their own figures: ids separated by commas (`3,7`) or `all`.
        /// By default every robot of a team of at most 8, none of a larger team, which gets the
        /// team figure (every robot's error on one plot) instead.
        #[arg(long, value_name = "IDS")]
        robots: Option<fdi_report::team::PerRobot>,
    },
    /// ROC and detection delay: sweep every detector's threshold over one recorded run (the
    /// detectors replay its records, nothing is simulated again) and write `roc.csv`, `roc.svg`/`.png`
    /// and `delay.svg`/`.png`.
    Detect(DetectArgs),
    /// Work with the binary traces of a run.
    #[command(subcommand)]
    Trace(TraceCommand),
    /// The output folders of a folder: list them (every kind), remove the older run directories.
    #[command(subcommand)]
    Runs(RunsCommand),
    /// Measurements: latency of the realtime runtime, the transport floor, lockstep speed.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Run a share of split runs on this host: wait for a coordinating `fdi-launch run
    /// --hosts FILE`, run the processes it places here, bridge them over Zenoh, hand it their
    /// traces (docs/multi-host.md).
    Serve(ServeArgs),
    /// Make the lab's certificates for the hosts of a deployment file: a CA (or the one
    /// there) and, for each host, a certificate and key for the TLS between hosts
    /// (docs/security.md).
    Certs(CertsArgs),
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
        #[arg(long, value_enum, default_value_t = ExportFormat::Csv)]
        format: ExportFormat,
    },
}

#[derive(Debug, Subcommand)]
pub enum RunsCommand {
    /// Every output folder of the folder, newest first: name, kind (run, table1, table2,
    /// attacks, bench-lockstep, campaign, detect), date, size on disk (as `du -s` counts it),
    /// status; then what else is there, and the total.
    List {
        /// The folder (`--out` of the commands).
        #[arg(long, default_value = "runs")]
        out: PathBuf,
        /// Print one JSON object (every folder with its kind and size in bytes) instead.
        #[arg(long)]
        json: bool,
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

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ProcessRole {
    Agent,
    Attacker,
    ControlCenter,
    /// Plays a recorded attacker trace (its `--trace`) back to the control center
    /// (`run --replay`).
    Replayer,
}

#[cfg(test)]
mod tests {
    /// The run directory says what the command line changed, in a fixed order.
    #[test]
    fn a_run_is_named_after_its_scenario_and_what_the_command_line_changed() {
        use clap::Parser;
        let name = |argv: &[&str]| {
            let cli = super::Cli::try_parse_from(argv).expect("parses");
            let super::Command::Run(args) = cli.command else {
                panic!("not a run")
            };
            let request = fdi_orchestrator::RunRequest::new(None, &args.overrides, args.engine)
                .expect("valid overrides");
            request.name
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
