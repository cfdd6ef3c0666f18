//! `fdi-launch sweep CAMPAIGN`: a campaign, a shard of it, its aggregation or its status
//! (`fdi_campaign`), printed.

use std::num::NonZeroUsize;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::Args;
use fdi_campaign::{self as campaign, shard::ShardArg, Ended, SweepOptions};
use fdi_common::stop::Stop;
use fdi_orchestrator::Engine;
use fdi_report::traces::Traces;

/// `sweep`.
#[derive(Debug, Args)]
pub struct SweepArgs {
    /// Campaign TOML file: a base scenario and axes (see `scenarios/campaigns/`).
    pub campaign: PathBuf,
    /// Runs at a time (default: the number of CPUs).
    #[arg(long)]
    pub jobs: Option<NonZeroUsize>,
    /// The engine of every run: in-process (one thread per run) or ipc (processes per run).
    #[arg(long, value_parser = super::values::engine(), default_value_t = Engine::Inproc)]
    pub engine: Engine,
    /// The campaign folder; default `runs/campaigns/<name>`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// What each run keeps: `none` (the summary only; no run directory), `full` (a run
    /// directory per run under `<out>/runs/`), `decimate=K`.
    #[arg(long, default_value_t = Traces::None)]
    pub traces: Traces,
    /// Run only shard K of N (`K/N`, from 1): a part of the campaign's runs that depends on the
    /// campaign alone, balanced by expected cost; every shard stores its results in one `--out`
    /// (a shared folder), and `--aggregate` makes the tables. `auto`: K and N from a Slurm
    /// array job (`SLURM_ARRAY_TASK_*`) or a Kubernetes Indexed Job (`JOB_COMPLETION_INDEX`,
    /// with `FDI_SHARD_COUNT`).
    #[arg(long, value_name = "K/N|auto", conflicts_with_all = ["aggregate", "status"])]
    pub shard: Option<ShardArg>,
    /// Run nothing: make the tables and figures from the results in `--out`, and name the runs
    /// missing with the shard that owns each (exit status 1 when some are).
    #[arg(long, conflicts_with = "status")]
    pub aggregate: bool,
    /// Run nothing: per shard, its runs done of its total, its failures with their errors, and
    /// the time left estimated from the finished runs.
    #[arg(long)]
    pub status: bool,
}

/// `sweep`: what the campaign says goes to the standard output; exit status 1 when runs
/// failed or are missing.
pub fn sweep(args: &SweepArgs, stop: &Stop) -> Result<ExitCode> {
    let options = SweepOptions {
        campaign: args.campaign.clone(),
        jobs: args.jobs,
        engine: args.engine,
        out: args.out.clone(),
        traces: args.traces,
        shard: args.shard,
        aggregate: args.aggregate,
        status: args.status,
        progress: crate::terminal::progress(true),
    };
    Ok(
        match campaign::sweep(&options, stop, &mut |line| println!("{line}"))? {
            Ended::Whole => ExitCode::SUCCESS,
            Ended::Incomplete => ExitCode::FAILURE,
        },
    )
}
