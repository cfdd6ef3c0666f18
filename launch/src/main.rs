//! `fdi-launch`: the one user-facing command of fdi-mas. `main` owns the stop (SIGINT and
//! SIGTERM raise it) and the exit status; [`cli`] is the command line's types, [`commands`] what
//! each command does, over the libraries `fdi-orchestrator` (runs) and `fdi-report` (what runs
//! leave, made readable).

mod cli;
mod commands;
mod terminal;

use clap::Parser;
use fdi_common::stop::{Interrupted, Stop, SIGINT, SIGTERM};
use std::process::ExitCode;

use anyhow::Result;
use cli::{Command, ProcessRole, RunsCommand, TraceCommand};

fn main() -> ExitCode {
    // Before any thread or Zenoh session exists (runs across hosts; no cost otherwise).
    fdi_net::choose_zenoh_threads();
    let cli = cli::Cli::parse();
    terminal::install(match cli.command {
        Command::Serve(_) => "fdi-launch serve",
        _ => "fdi-launch",
    });
    let stop = Stop::new();
    if handles_interrupts(&cli.command) {
        for sig in [SIGINT, SIGTERM] {
            // Registering only fails for a forbidden signal (SIGKILL, ...); these are not.
            let number = usize::try_from(sig).unwrap_or(1);
            if let Err(e) = signal_hook::flag::register_usize(sig, stop.cell(), number) {
                eprintln!("fdi-launch: warning: cannot handle signal {sig}: {e}");
            }
        }
    }
    // What runs killed outright left (SIGKILL of their launcher) goes at the next command.
    if !matches!(
        cli.command,
        Command::Process { .. } | Command::BenchPeer { .. }
    ) {
        fdi_orchestrator::run::runtime::reap_stale_runs();
        // Whatever a run's processes start, and orphan, stays below this process, which ends
        // it with the run (a program taking a role that detaches a child twice, say).
        if let Err(e) = fdi_orchestrator::run::program::contain_descendants() {
            eprintln!(
                "fdi-launch: warning: cannot become the subreaper of the run's processes ({e}): \
                 a child that a role's program detaches twice may outlive the run"
            );
        }
    }
    match dispatch(cli.command, &stop) {
        Ok(code) => code,
        Err(e) => {
            eprintln!(
                "fdi-launch: error: {}",
                fdi_report::output::describe_error(&e)
            );
            match e.downcast_ref::<Interrupted>() {
                Some(i) => ExitCode::from(i.exit_code()),
                None => ExitCode::FAILURE,
            }
        }
    }
}

/// Runs `command`; `stop` is raised by SIGINT/SIGTERM for the commands that run or report
/// ([`handles_interrupts`]).
fn dispatch(command: Command, stop: &Stop) -> Result<ExitCode> {
    match command {
        Command::Run(args) => commands::run::run(&args, stop),
        Command::Serve(args) => commands::serve::serve(&args, stop),
        Command::Certs(args) => commands::certs::certs(&args),
        Command::Validate { scenario } => commands::validate::validate(&scenario),
        Command::Sweep(args) => commands::sweep::sweep(&args, stop),
        Command::Schema { format } => commands::validate::schema(format),
        Command::Model(args) => commands::model::model(&args),
        Command::Layout(args) => commands::layout::layout(&args),
        Command::Table1(args) => commands::tables::table1(&args, stop),
        Command::Table2(args) => commands::tables::table2(&args, stop),
        Command::Attacks(args) => commands::tables::attacks(&args, stop),
        Command::Score(args) => commands::score::score(&args, stop),
        Command::Report { run_dir, robots } => {
            commands::report::report(&run_dir, &robots.unwrap_or_default(), stop)
        }
        Command::Detect(args) => commands::detect::detect(&args, stop),
        Command::Trace(TraceCommand::Export { run_dir, format }) => {
            commands::report::export(&run_dir, format)
        }
        Command::Runs(RunsCommand::List { out, json }) => commands::runs::list(&out, json),
        Command::Runs(RunsCommand::Prune { keep, out, dry_run }) => {
            commands::runs::prune(&out, keep, dry_run)
        }
        Command::Bench(b) => commands::bench::bench(&b, stop),
        Command::BenchPeer { args } => commands::bench::peer(&args),
        Command::Process { role, args } => {
            let ended = match role {
                ProcessRole::Agent => fdi_agent::run_process(args),
                ProcessRole::Attacker => fdi_attacker::run_process(args),
                ProcessRole::ControlCenter => fdi_control_center::run_process(args),
                ProcessRole::Replayer => fdi_orchestrator::run::replayer::run_process(&args),
            };
            Ok(if ended.is_ok() {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            })
        }
    }
}

/// True for the commands that run or report: they handle SIGINT/SIGTERM from the first
/// moment (every phase checks the stop, so an interrupt stops at once, keeps what is done and
/// says so).
fn handles_interrupts(command: &Command) -> bool {
    matches!(
        command,
        Command::Run(_)
            | Command::Sweep(_)
            | Command::Report { .. }
            | Command::Detect(_)
            | Command::Table1(_)
            | Command::Table2(_)
            | Command::Attacks(_)
            | Command::Score(_)
            | Command::Serve(_)
            | Command::Bench(_)
    )
}
