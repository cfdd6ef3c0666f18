//! One file per command that does more than call a library function; [`dispatch`] wires every
//! command of [`Cli`] to its code.

pub mod detect;
pub mod run;
pub mod validate;

use std::process::ExitCode;

use anyhow::Result;
use fdi_common::stop::Stop;
use fdi_orchestrator::{attacks, bench, campaign, run::runs, run::serve, tables};
use fdi_report::{export, report};

use crate::cli::{Command, ProcessRole, RunsCommand, TraceCommand};

/// Runs `command`; `stop` is raised by SIGINT/SIGTERM for the commands that run or report.
pub fn dispatch(command: Command, stop: &Stop) -> Result<ExitCode> {
    let done = |r: Result<()>| r.map(|()| ExitCode::SUCCESS);
    match command {
        Command::Run(args) => run::run(&args, stop),
        Command::Serve(args) => serve::serve(&args, stop),
        Command::Validate { scenario } => validate::validate(&scenario),
        Command::Sweep(args) => campaign::sweep(&args, stop),
        Command::Schema { format } => validate::schema(format),
        Command::Table1(args) => tables::table1(&args, stop),
        Command::Table2(args) => tables::table2(&args, stop),
        Command::Attacks(args) => attacks::attacks(&args, stop),
        Command::Report { run_dir } => done(report::report(&run_dir, stop)),
        Command::Detect(args) => detect::detect(&args, stop),
        Command::Trace(TraceCommand::Export { run_dir, format }) => {
            done(export::export(&run_dir, format))
        }
        Command::Runs(RunsCommand::List { out }) => done(runs::print_list(&out)),
        Command::Runs(RunsCommand::Prune { keep, out, dry_run }) => {
            done(runs::print_prune(&out, keep, dry_run))
        }
        Command::Bench(b) => bench::bench(&b, stop),
        Command::BenchPeer { args } => done(bench::floor::peer_main(&args)),
        Command::Process { role, args } => Ok(match role {
            ProcessRole::Agent => fdi_agent::main_with(args),
            ProcessRole::Attacker => fdi_attacker::main_with(args),
            ProcessRole::ControlCenter => fdi_control_center::main_with(args),
            ProcessRole::Replayer => fdi_orchestrator::run::replayer::main_with(&args),
        }),
    }
}

/// True for the commands that run or report: they handle SIGINT/SIGTERM from the first
/// moment (every phase checks the stop, so an interrupt stops at once, keeps what is done and
/// says so).
pub fn handles_interrupts(command: &Command) -> bool {
    matches!(
        command,
        Command::Run(_)
            | Command::Sweep(_)
            | Command::Report { .. }
            | Command::Detect(_)
            | Command::Table1(_)
            | Command::Table2(_)
            | Command::Attacks(_)
            | Command::Serve(_)
            | Command::Bench(_)
    )
}
