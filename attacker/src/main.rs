//! `fdi-attacker`: started by `fdi-launch`.

use clap::Parser;
use fdi_runtime::process::ProcessArgs;

#[derive(Debug, Parser)]
#[command(
    name = "fdi-attacker",
    about = "fdi-mas attacker process (started by fdi-launch)"
)]
struct Cli {
    #[command(flatten)]
    args: ProcessArgs,
}

fn main() -> std::process::ExitCode {
    fdi_attacker::main_with(Cli::parse().args)
}
