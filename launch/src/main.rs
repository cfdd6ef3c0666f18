//! `fdi-launch`: the one user-facing command of fdi-mas.

mod bench;
mod cli;
mod export;
mod floor;
mod interrupt;
mod join;
mod output;
mod plot;
mod probe;
mod relay;
mod replayer;
mod report;
mod runtime;
mod tables;

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
