//! `fdi-launch detect TARGET`: a run directory is swept as it is; a scenario is run first, by
//! `run`'s own code path, then its run directory is swept (`fdi_report::detect`).

use fdi_common::run_dir::RunDir;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use fdi_orchestrator::run::runtime::Placement;
use fdi_orchestrator::{Engine, Overrides};
use fdi_report::traces::Traces;

use anyhow::{bail, Context, Result};
use fdi_common::stop::Stop;
use fdi_report::detect::{sweep_run, WHILE_SWEEPING};

use super::run::RunArgs;

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
    #[arg(long, value_parser = super::values::engine())]
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
            live_addr: None,
            engine: self.engine.unwrap_or(Engine::Ipc),
            overrides: self.overrides.clone(),
            out: self.runs.clone(),
            json: false,
            traces: Traces::Full,
            max_trace_size: bytesize::ByteSize::gb(10),
            no_space_check: false,
            hosts: None,
            placement: Placement::default(),
            live: None,
            live_rate: fdi_live::Options::DEFAULT_RATE_HZ,
            live_wait: None,
            pace: None,
            replay: None,
            run_by: Some("detect"),
        }
    }
}

/// `detect`.
pub fn detect(args: &DetectArgs, stop: &Stop) -> Result<ExitCode> {
    let target = &args.target;
    let meta = std::fs::metadata(target).with_context(|| format!("{}", target.display()))?;
    let (run_dir, run_code) = if meta.is_dir() {
        let flags = args.run_flags();
        if !flags.is_empty() {
            bail!(
                "{} apply to a scenario TARGET; {} is a run directory, whose recorded run is swept as it is",
                flags.join(", "),
                target.display()
            );
        }
        (target.clone(), None)
    } else {
        eprintln!(
            "fdi-launch: detect: running {} once (as `run` does), then sweeping its records",
            target.display()
        );
        let done = super::run::run_scenario(&args.run_args(), stop)?;
        stop.check(WHILE_SWEEPING)?;
        if !done.clean {
            eprintln!(
                "fdi-launch: detect: the run of {} was not a clean success; its records are swept all the same, and the run's exit status is kept",
                target.display()
            );
        }
        (done.dir, Some(done.code))
    };
    for written in sweep_run(
        &RunDir::new(&run_dir),
        args.out.as_deref(),
        args.points,
        stop,
    )? {
        println!("{}", written.display());
    }
    Ok(run_code.unwrap_or(ExitCode::SUCCESS))
}
