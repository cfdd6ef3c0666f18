//! `fdi-launch`: the one user-facing command of fdi-mas. `main` owns the stop (SIGINT and
//! SIGTERM raise it) and the exit status; [`cli`] is the command line's types, [`commands`] what
//! each command does, over the libraries `fdi-orchestrator` (runs) and `fdi-report` (what runs
//! leave, made readable).

mod cli;
mod commands;

use clap::Parser;
use fdi_common::stop::{Interrupted, Stop, SIGINT, SIGTERM};

fn main() -> std::process::ExitCode {
    let cli = cli::Cli::parse();
    let stop = Stop::new();
    if commands::handles_interrupts(&cli.command) {
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
        cli::Command::Process { .. } | cli::Command::BenchPeer { .. }
    ) {
        fdi_orchestrator::run::runtime::reap_stale_runs();
    }
    match commands::dispatch(cli.command, &stop) {
        Ok(code) => code,
        Err(e) => {
            eprintln!(
                "fdi-launch: error: {}",
                fdi_report::output::describe_error(&e)
            );
            match e.downcast_ref::<Interrupted>() {
                Some(i) => std::process::ExitCode::from(i.exit_code()),
                None => std::process::ExitCode::FAILURE,
            }
        }
    }
}
