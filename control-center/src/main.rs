//! `fdi-control-center`: started by `fdi-launch`.

use std::process::ExitCode;

use clap::Parser;
use fdi_runtime::process::ProcessArgs;

#[derive(Debug, Parser)]
#[command(
    name = "fdi-control-center",
    about = "fdi-mas control-center process (started by fdi-launch)"
)]
struct Cli {
    #[command(flatten)]
    args: ProcessArgs,
}

fn main() -> ExitCode {
    match fdi_control_center::run_process(Cli::parse().args) {
        Ok(_) => ExitCode::SUCCESS,
        Err(_) => ExitCode::FAILURE,
    }
}
