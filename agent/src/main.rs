//! `fdi-agent`: one agent process, started by `fdi-launch`.

use clap::Parser;
use fdi_runtime::process::ProcessArgs;

#[derive(Debug, Parser)]
#[command(
    name = "fdi-agent",
    about = "fdi-mas agent process (started by fdi-launch)"
)]
struct Cli {
    #[command(flatten)]
    args: ProcessArgs,
}

fn main() -> std::process::ExitCode {
    fdi_agent::main_with(Cli::parse().args)
}
