//! `fdi-launch`: the one user-facing command of fdi-mas.

mod bench;
mod campaign;
mod cli;
mod detect;
mod reporting;
mod run;

// Short paths for the modules the jobs share.
use bench::{floor, probe};
use reporting::{export, output, plot, report, tables};
use run::{hosts, interrupt, join, relay, remote, replayer, runtime, supervisor};

#[cfg(test)]
mod damage_tests;

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = cli::Cli::parse();
    match cli::dispatch(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("fdi-launch: error: {}", cli::describe_error(&e));
            match e.downcast_ref::<runtime::Interrupted>() {
                Some(i) => std::process::ExitCode::from(i.exit_code()),
                None => std::process::ExitCode::FAILURE,
            }
        }
    }
}
