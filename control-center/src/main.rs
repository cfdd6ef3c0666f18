//! `fdi-control-center`: started by `fdi-launch`.

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

fn main() -> std::process::ExitCode {
    fdi_control_center::main_with(Cli::parse().args)
}
