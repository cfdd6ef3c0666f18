//! `fdi-launch`: the one user-facing command of fdi-mas.

mod bench;
mod cli;
mod export;
mod floor;
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
            eprintln!("fdi-launch: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
