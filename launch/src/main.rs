//! `fdi-launch`: the one user-facing command of fdi-mas.

mod cli;
mod join;
mod output;
mod runtime;
mod tables;

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
